//! Sane limits on requests that would otherwise ask for hours of work or more memory than a
//! machine has: `PixelSamples 1000 1000`, `Format 100000 100000`, `ShadingRate 1e-9`, a pixel
//! filter 1000 pixels wide, huge buckets or grids.
//!
//! Input: a frame's options (after command-line overrides) and each primitive's shading rate.
//! Output: the same values clamped to the limits below; every clamp is reported once, as a
//! warning naming the value asked for, the limit, and the `Option "limits"` entry that moves
//! it. Invariants: values inside the limits pass through unchanged (so ordinary scenes render
//! exactly as before); the limits that do not change what the picture shows (bucket and grid
//! size) have no option to raise them.

use crate::diag::{Diag, Diagnostics, Span};
use crate::scene::Options;

/// Most pixels along either axis of the image (`Option "limits" "resolution"`).
pub const MAX_RESOLUTION: u32 = 8192;
/// Most samples per pixel along either axis (`Option "limits" "pixelsamples"`).
pub const MAX_PIXEL_SAMPLES: f32 = 16.0;
/// The hider's own ceiling on samples per axis, above any `"pixelsamples"` limit.
pub const HIDER_MAX_PIXEL_SAMPLES: f32 = 64.0;
/// Smallest micropolygon area in pixels (`Option "limits" "shadingrate"`).
pub const MIN_SHADING_RATE: f32 = 0.05;
/// Widest pixel filter in pixels (`Option "limits" "filterwidth"`).
pub const MAX_FILTER_WIDTH: f32 = 16.0;
/// Largest bucket side in pixels (the picture does not depend on it).
pub const MAX_BUCKET: i32 = 1024;
/// Most micropolygons in one grid (the picture does not depend on it).
pub const MAX_GRID: usize = 65536;

/// Most eye-plane splits of one surface (`Option "limits" "eyesplits"` above it is held here).
/// Each eye split can double the pieces still crossing the eye plane — a surface through the
/// eye point, or one with a point at 1e38 — so the work grows as 2^n: 16 is about 130 000
/// pieces (well under a second), PRMan's default is 10, and exporters write "unlimited"
/// values (Houdini: 1000) that would otherwise split for hours.
pub const MAX_EYE_SPLITS: u32 = 16;

/// The eye-split limit for a frame: `requested` (`Option "limits" "eyesplits"`; None or not a
/// number: `default`), held at [`MAX_EYE_SPLITS`]. Also the value asked for when it was held,
/// for the warning given if a piece is dropped at the limit (a scene that never reaches it
/// renders as asked, so holding it is not reported up front).
pub fn eye_splits(requested: Option<f32>, default: u32) -> (u32, Option<f32>) {
    let Some(r) = requested.filter(|r| !r.is_nan()) else {
        return (default.min(MAX_EYE_SPLITS), None);
    };
    let asked = r.max(0.0);
    if asked > MAX_EYE_SPLITS as f32 {
        (MAX_EYE_SPLITS, Some(asked))
    } else {
        (asked as u32, None)
    }
}

/// A `limits` option's number, when the scene sets a usable one.
fn option_limit(options: &Options, name: &str) -> Option<f32> {
    options
        .user_floats(&format!("limits:{name}"))
        .and_then(|v| v.first().copied())
        .filter(|x| x.is_finite() && *x > 0.0)
}

/// Reports a clamp without a source position (options carry none).
fn warn(diags: &Diagnostics, message: String, help: String) {
    diags.report(Diag::warning("render::limits", message).help(help));
}

/// Clamps the frame-wide requests: image size (scaled down keeping its shape), pixel
/// samples, pixel filter width.
pub fn apply_frame_limits(options: &mut Options, diags: &Diagnostics) {
    let max_res = option_limit(options, "resolution")
        .map_or(MAX_RESOLUTION, |x| x.min(u32::MAX as f32) as u32)
        .max(1);
    let (x, y) = (options.xres.max(1), options.yres.max(1));
    if x.max(y) > max_res {
        let scale = max_res as f64 / x.max(y) as f64;
        let nx = ((x as f64 * scale).round() as u32).clamp(1, max_res);
        let ny = ((y as f64 * scale).round() as u32).clamp(1, max_res);
        warn(
            diags,
            format!(
                "Format {x} {y} is larger than arbor renders ({max_res} pixels along either \
                 side); rendering at {nx}×{ny} (same frame, fewer pixels)"
            ),
            format!(
                "`Option \"limits\" \"resolution\" [{}]` raises the limit, memory permitting",
                x.max(y)
            ),
        );
        options.xres = nx;
        options.yres = ny;
    }

    let max_spp = option_limit(options, "pixelsamples")
        .unwrap_or(MAX_PIXEL_SAMPLES)
        .clamp(1.0, HIDER_MAX_PIXEL_SAMPLES);
    let [sx, sy] = options.pixel_samples;
    if !(sx <= max_spp && sy <= max_spp) {
        let (nx, ny) = (clamp_num(sx, 1.0, max_spp), clamp_num(sy, 1.0, max_spp));
        warn(
            diags,
            format!(
                "PixelSamples {} {} is more than arbor takes ({max_spp} along either \
                 axis); using {nx} {ny}",
                num(sx),
                num(sy)
            ),
            format!(
                "`Option \"limits\" \"pixelsamples\" [{HIDER_MAX_PIXEL_SAMPLES}]` raises the \
                 limit (to at most {HIDER_MAX_PIXEL_SAMPLES})"
            ),
        );
        options.pixel_samples = [nx, ny];
    }

    let max_fw = option_limit(options, "filterwidth").unwrap_or(MAX_FILTER_WIDTH);
    let f = &mut options.pixel_filter;
    if !(f.xwidth <= max_fw && f.ywidth <= max_fw) {
        let (nx, ny) = (
            clamp_num(f.xwidth, 1.0, max_fw),
            clamp_num(f.ywidth, 1.0, max_fw),
        );
        warn(
            diags,
            format!(
                "PixelFilter \"{}\" {} {} is wider than arbor filters ({max_fw} pixels); \
                 using {nx} {ny}",
                f.name, f.xwidth, f.ywidth
            ),
            format!(
                "`Option \"limits\" \"filterwidth\" [{}]` raises the limit",
                f.xwidth.max(f.ywidth)
            ),
        );
        f.xwidth = nx;
        f.ywidth = ny;
    }
}

/// A number as a user would write it (`1e-9`, not `0.000000001`).
fn num(x: f32) -> String {
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e7) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Clamps a number into [lo, hi]; NaN becomes `lo`.
fn clamp_num(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() {
        lo
    } else {
        x.clamp(lo, hi)
    }
}

/// The smallest shading rate the frame dices to.
pub fn min_shading_rate(options: &Options) -> f32 {
    option_limit(options, "shadingrate").unwrap_or(MIN_SHADING_RATE)
}

/// A primitive's shading rate clamped to `min` (reported once per value asked for).
pub fn shading_rate(rate: f32, min: f32, span: Span, diags: &Diagnostics) -> f32 {
    if rate >= min {
        return rate;
    }
    diags.report(
        Diag::warning(
            "render::limits",
            format!(
                "ShadingRate {} asks for micropolygons smaller than arbor dices \
                 ({min} pixels in area); using {min}",
                num(rate)
            ),
        )
        .label(span, "a primitive with this shading rate")
        .help(format!(
            "`Option \"limits\" \"shadingrate\" [{}]` lowers the limit (halving the rate \
             doubles the shading work)",
            num(rate)
        )),
    );
    min
}

/// A bucket size clamped to [1, MAX_BUCKET] pixels.
pub fn bucket_size(size: [i32; 2], diags: &Diagnostics) -> [i32; 2] {
    let c = [size[0].clamp(1, MAX_BUCKET), size[1].clamp(1, MAX_BUCKET)];
    if c != size {
        warn(
            diags,
            format!(
                "bucket size {}×{} is outside 1…{MAX_BUCKET} pixels; using {}×{}",
                size[0], size[1], c[0], c[1]
            ),
            "the bucket size changes only memory use and speed, never the picture".into(),
        );
    }
    c
}

/// A grid size (most micropolygons per grid) held at MAX_GRID; one below 1 (or NaN) asks for
/// nothing a grid can be, and `default` is used. (It was clamped to 1: a mutated scene's
/// `"gridsize" [-5]` shaded 26 614 grids of one micropolygon, a volume march each, for a minute
/// at 64 × 48.)
pub fn grid_size(requested: f32, default: usize, diags: &Diagnostics) -> usize {
    if requested.is_finite() && (1.0..=MAX_GRID as f32).contains(&requested) {
        return requested as usize;
    }
    let c = if requested >= 1.0 { MAX_GRID } else { default };
    let what = if c == default { "the default " } else { "" };
    warn(
        diags,
        format!(
            "`Option \"limits\" \"gridsize\" [{}]` is outside 1…{MAX_GRID} \
             micropolygons; using {what}{c}",
            num(requested)
        ),
        "the grid size changes memory use and speed, not what the picture shows".into(),
    );
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eye_splits_are_held_at_the_limit() {
        assert_eq!(eye_splits(None, 10), (10, None));
        assert_eq!(eye_splits(Some(4.0), 10), (4, None));
        assert_eq!(eye_splits(Some(16.0), 10), (16, None));
        assert_eq!(eye_splits(Some(1000.0), 10), (16, Some(1000.0)));
        assert_eq!(
            eye_splits(Some(f32::INFINITY), 10),
            (16, Some(f32::INFINITY))
        );
        assert_eq!(eye_splits(Some(-3.0), 10), (0, None));
        assert_eq!(eye_splits(Some(f32::NAN), 10), (10, None));
    }

    #[test]
    fn ordinary_options_pass_through() {
        let mut o = Options::default();
        o.xres = 640;
        o.yres = 480;
        o.pixel_samples = [3.0, 3.0];
        let before = o.clone();
        let d = Diagnostics::new();
        apply_frame_limits(&mut o, &d);
        assert_eq!((o.xres, o.yres, o.pixel_samples), (640, 480, [3.0, 3.0]));
        assert_eq!(o.pixel_filter.xwidth, before.pixel_filter.xwidth);
        assert!(d.snapshot().is_empty());
    }

    #[test]
    fn huge_format_keeps_its_shape() {
        let mut o = Options::default();
        o.xres = 100_000;
        o.yres = 50_000;
        let d = Diagnostics::new();
        apply_frame_limits(&mut o, &d);
        assert_eq!((o.xres, o.yres), (MAX_RESOLUTION, MAX_RESOLUTION / 2));
        let msgs = d.snapshot();
        assert_eq!(msgs.len(), 1);
        assert!(msgs[0].0.message.contains("8192"), "{}", msgs[0].0.message);
    }

    #[test]
    fn tiny_shading_rate_is_raised_to_the_limit() {
        let d = Diagnostics::new();
        let r = shading_rate(1e-9, MIN_SHADING_RATE, Span::default(), &d);
        assert_eq!(r, MIN_SHADING_RATE);
        assert_eq!(
            shading_rate(0.25, MIN_SHADING_RATE, Span::default(), &d),
            0.25
        );
        assert_eq!(d.snapshot().len(), 1);
    }

    #[test]
    fn grid_and_bucket_sizes_are_bounded() {
        let d = Diagnostics::new();
        assert_eq!(grid_size(1e12, 256, &d), MAX_GRID);
        assert_eq!(grid_size(256.0, 256, &d), 256);
        assert_eq!(grid_size(1.0, 256, &d), 1);
        assert_eq!(bucket_size([100_000, 16], &d), [MAX_BUCKET, 16]);
        assert_eq!(d.snapshot().len(), 2);
        // Nothing a grid can be: the default (found by fuzzing, fuzz3).
        assert_eq!(grid_size(-5.0, 256, &d), 256);
        assert_eq!(grid_size(0.5, 256, &d), 256);
        assert_eq!(grid_size(f32::NAN, 256, &d), 256);
        assert_eq!(grid_size(f32::INFINITY, 256, &d), MAX_GRID);
        let all = d.snapshot();
        assert_eq!(all.len(), 6);
        assert!(
            all[2].0.message.contains("using the default 256"),
            "{}",
            all[2].0.message
        );
    }
}
