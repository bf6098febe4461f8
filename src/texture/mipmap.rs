//! Building the mip-map pyramid (Williams '83; notes pipeline.md §3.7).
//!
//! Input: a level-0 [`Image`], the wrap modes and the prefilter (RISpec `MakeTexture`'s
//! filter name with its `swidth`/`twidth`). Output: every level down to 1×1.
//! Invariants: texel centres sit at (i+½)/size, so each level is the filtered 2:1 reduction
//! of the one above with no half-texel drift; odd sizes round up (the last row/column is
//! filtered with its wrapped neighbour); weights are normalised, so constants survive every
//! filter and the mean of a box-filtered power-of-two pyramid is preserved exactly.
//!
//! Filter widths are the filter's full support measured in texels of the level being made
//! (as `PixelFilter` widths are in pixels): a 1×1 box is the classic 2×2 average, a 2×2
//! triangle the [1 3 3 1]/8 kernel. Widths are clamped to [1, 16]: below one texel the 2:1
//! reduction would skip source texels. The filter shapes are the pixel filters'
//! ([`crate::film::filter`]), plus the cubic B-spline.

use crate::film::filter::{Filter, FilterKind as PixelKind};

use super::image_in::Image;

/// How lookups outside [0,1] behave (RISpec MakeTexture swrap/twrap).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Periodic,
    Clamp,
    Black,
}

impl Wrap {
    pub fn parse(s: &str) -> Option<Wrap> {
        match s.to_ascii_lowercase().as_str() {
            "periodic" | "repeat" => Some(Wrap::Periodic),
            "clamp" | "edge" => Some(Wrap::Clamp),
            "black" => Some(Wrap::Black),
            _ => None,
        }
    }
    pub fn code(self) -> u32 {
        self as u32
    }
    pub fn from_code(c: u32) -> Wrap {
        match c {
            0 => Wrap::Periodic,
            1 => Wrap::Clamp,
            _ => Wrap::Black,
        }
    }
    /// The texel index for `i` in a row of `n`, or None for black.
    #[inline]
    pub fn index(self, i: i64, n: usize) -> Option<usize> {
        let n = n as i64;
        if (0..n).contains(&i) {
            return Some(i as usize);
        }
        match self {
            Wrap::Periodic => Some(i.rem_euclid(n) as usize),
            Wrap::Clamp => Some(i.clamp(0, n - 1) as usize),
            Wrap::Black => None,
        }
    }
}

/// The prefilter used between levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Downsample {
    Box,
    Triangle,
    CatmullRom,
    Gaussian,
    Sinc,
    Mitchell,
    Disk,
    Bessel,
    SeparableCatmullRom,
    BlackmanHarris,
    Lanczos,
    /// Cubic B-spline on [−2, 2] stretched to the width.
    BSpline,
}

impl Downsample {
    /// The filter for a RenderMan filter name ("" is box); None for unknown names.
    pub fn parse(name: &str) -> Option<Downsample> {
        let n = name.trim().to_ascii_lowercase();
        Some(match n.as_str() {
            "" | "box" => Downsample::Box,
            "b-spline" | "bspline" | "radial-bspline" => Downsample::BSpline,
            _ => match PixelKind::from_name(&n)? {
                PixelKind::Box => Downsample::Box,
                PixelKind::Triangle => Downsample::Triangle,
                PixelKind::CatmullRom => Downsample::CatmullRom,
                PixelKind::Gaussian => Downsample::Gaussian,
                PixelKind::Sinc => Downsample::Sinc,
                PixelKind::Mitchell => Downsample::Mitchell,
                PixelKind::Disk => Downsample::Disk,
                PixelKind::Bessel => Downsample::Bessel,
                PixelKind::SeparableCatmullRom => Downsample::SeparableCatmullRom,
                PixelKind::BlackmanHarris => Downsample::BlackmanHarris,
                PixelKind::Lanczos => Downsample::Lanczos,
            },
        })
    }

    /// The width used when none is given (`arbor texture` without `--width`).
    pub fn natural_width(self) -> f32 {
        match self {
            Downsample::Box | Downsample::Disk => 1.0,
            Downsample::Triangle | Downsample::Gaussian => 2.0,
            Downsample::Bessel | Downsample::BlackmanHarris => 3.0,
            Downsample::CatmullRom
            | Downsample::SeparableCatmullRom
            | Downsample::Sinc
            | Downsample::Mitchell
            | Downsample::Lanczos => 4.0,
            Downsample::BSpline => 4.0,
        }
    }

    /// Weight at offset (x, y) in texels of the level being made.
    fn weight(self, x: f32, y: f32, sw: f32, tw: f32) -> f32 {
        let pixel = |k: PixelKind| Filter::new(k, sw, tw).eval(x, y);
        match self {
            Downsample::Box => pixel(PixelKind::Box),
            Downsample::Triangle => pixel(PixelKind::Triangle),
            Downsample::CatmullRom => pixel(PixelKind::CatmullRom),
            Downsample::Gaussian => pixel(PixelKind::Gaussian),
            Downsample::Sinc => pixel(PixelKind::Sinc),
            Downsample::Mitchell => pixel(PixelKind::Mitchell),
            Downsample::Disk => pixel(PixelKind::Disk),
            Downsample::Bessel => pixel(PixelKind::Bessel),
            Downsample::SeparableCatmullRom => pixel(PixelKind::SeparableCatmullRom),
            Downsample::BlackmanHarris => pixel(PixelKind::BlackmanHarris),
            Downsample::Lanczos => pixel(PixelKind::Lanczos),
            Downsample::BSpline => bspline(4.0 * x / sw) * bspline(4.0 * y / tw),
        }
    }
}

/// Uniform cubic B-spline on |t| ≤ 2.
fn bspline(t: f32) -> f32 {
    let t = t.abs();
    if t < 1.0 {
        (4.0 - 6.0 * t * t + 3.0 * t * t * t) / 6.0
    } else if t < 2.0 {
        let u = 2.0 - t;
        u * u * u / 6.0
    } else {
        0.0
    }
}

/// Normalised taps (dx, dy, weight) of one output texel: source texel (2x+dx, 2y+dy).
fn taps(filter: Downsample, swidth: f32, twidth: f32) -> Vec<(i64, i64, f32)> {
    let fix = |w: f32| {
        if w.is_finite() {
            w.clamp(1.0, 16.0)
        } else {
            1.0
        }
    };
    let (sw, tw) = (fix(swidth), fix(twidth));
    // Source centre 2x+d+½ lies (d−½)/2 output texels from the output centre 2x+1.
    let range = |w: f32| {
        let r = w.ceil() as i64 + 1;
        -r..=r + 1
    };
    let mut out = Vec::new();
    for dy in range(tw) {
        for dx in range(sw) {
            let (x, y) = ((dx as f32 - 0.5) * 0.5, (dy as f32 - 0.5) * 0.5);
            let w = filter.weight(x, y, sw, tw);
            if w != 0.0 {
                out.push((dx, dy, w));
            }
        }
    }
    let sum: f32 = out.iter().map(|t| t.2).sum();
    if !(sum.abs() > 1e-6) {
        // Cannot happen for widths ≥ 1 (the 2×2 centre taps always weigh); stay safe.
        return vec![(0, 0, 0.25), (1, 0, 0.25), (0, 1, 0.25), (1, 1, 0.25)];
    }
    out.iter_mut().for_each(|t| t.2 /= sum);
    out
}

/// All levels, finest first, ending at 1×1, with the filter's natural width.
pub fn build_pyramid(base: Image, swrap: Wrap, twrap: Wrap, filter: Downsample) -> Vec<Image> {
    let w = filter.natural_width();
    build_pyramid_with(base, swrap, twrap, filter, w, w)
}

/// All levels, finest first, ending at 1×1, filtering with widths `swidth` × `twidth`
/// (texels of the level being made).
pub fn build_pyramid_with(
    base: Image,
    swrap: Wrap,
    twrap: Wrap,
    filter: Downsample,
    swidth: f32,
    twidth: f32,
) -> Vec<Image> {
    let taps = taps(filter, swidth, twidth);
    let mut levels = vec![base];
    loop {
        let last = levels.last().expect("non-empty");
        if last.width <= 1 && last.height <= 1 {
            break;
        }
        let next = downsample(last, swrap, twrap, &taps);
        levels.push(next);
    }
    levels
}

fn downsample(src: &Image, swrap: Wrap, twrap: Wrap, taps: &[(i64, i64, f32)]) -> Image {
    let (w, h, nc) = (src.width, src.height, src.nchan);
    let nw = w.div_ceil(2).max(1);
    let nh = h.div_ceil(2).max(1);
    let mut out = Image::new(nw, nh, nc);
    // Clamp-to-edge for black borders too: the pyramid keeps the image's own colours at
    // its border, black enters only at lookup time.
    let edge = |m: Wrap| {
        if m == Wrap::Periodic {
            Wrap::Periodic
        } else {
            Wrap::Clamp
        }
    };
    let (wrap_x, wrap_y) = (edge(swrap), edge(twrap));
    let single_x = w == 1;
    let single_y = h == 1;
    let mut acc = vec![0f32; nc];
    for y in 0..nh {
        for x in 0..nw {
            acc.iter_mut().for_each(|a| *a = 0.0);
            for &(dx, dy, wgt) in taps {
                let sx = if single_x { 0 } else { 2 * x as i64 + dx };
                let sy = if single_y { 0 } else { 2 * y as i64 + dy };
                let (Some(sx), Some(sy)) = (wrap_x.index(sx, w), wrap_y.index(sy, h)) else {
                    continue;
                };
                for (a, v) in acc.iter_mut().zip(src.px(sx, sy)) {
                    *a += wgt * v;
                }
            }
            let o = (y * nw + x) * nc;
            out.data[o..o + nc].copy_from_slice(&acc);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(n: usize) -> Image {
        let mut im = Image::new(n, n, 1);
        for y in 0..n {
            for x in 0..n {
                im.data[y * n + x] = ((x + y) % 2) as f32;
            }
        }
        im
    }

    #[test]
    fn pyramid_of_512_has_10_levels_and_mean_top() {
        let levels = build_pyramid(
            checker(512),
            Wrap::Periodic,
            Wrap::Periodic,
            Downsample::Box,
        );
        assert_eq!(levels.len(), 10);
        assert_eq!(levels[9].width, 1);
        // Any level coarser than the checker period is uniform 0.5.
        assert!(levels[1].data.iter().all(|&v| (v - 0.5).abs() < 1e-6));
        assert!((levels[9].data[0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn gaussian_keeps_constants_and_odd_sizes_round_up() {
        let mut im = Image::new(5, 3, 2);
        im.data.iter_mut().for_each(|v| *v = 0.25);
        let levels = build_pyramid(im, Wrap::Clamp, Wrap::Black, Downsample::Gaussian);
        assert_eq!((levels[1].width, levels[1].height), (3, 2));
        assert_eq!(
            (levels.last().unwrap().width, levels.last().unwrap().height),
            (1, 1)
        );
        for l in &levels {
            assert!(l.data.iter().all(|&v| (v - 0.25).abs() < 1e-6));
        }
    }

    #[test]
    fn wrap_indices() {
        assert_eq!(Wrap::Periodic.index(-1, 4), Some(3));
        assert_eq!(Wrap::Periodic.index(9, 4), Some(1));
        assert_eq!(Wrap::Clamp.index(-3, 4), Some(0));
        assert_eq!(Wrap::Black.index(4, 4), None);
    }

    /// One row of a 1-D image filtered 2:1 along x with `taps` (height 1 keeps y fixed).
    fn reduce_row(v: &[f32], f: Downsample, w: f32) -> Vec<f32> {
        let im = Image {
            width: v.len(),
            height: 1,
            nchan: 1,
            data: v.to_vec(),
        };
        downsample(&im, Wrap::Periodic, Wrap::Periodic, &taps(f, w, w)).data
    }

    #[test]
    fn widths_are_texels_of_the_level_made() {
        let imp = [0.0, 0.0, 0.0, 0.0, 8.0, 0.0, 0.0, 0.0];
        // 1-wide box: the 2×2 average.
        assert_eq!(
            reduce_row(&imp, Downsample::Box, 1.0),
            vec![0.0, 0.0, 4.0, 0.0]
        );
        // 2-wide triangle: the [1 3 3 1]/8 kernel (texel 4 is tap 2 of output 1 and tap 0
        // of output 2, weight 1/8 and 3/8).
        assert_eq!(
            reduce_row(&imp, Downsample::Triangle, 2.0),
            vec![0.0, 1.0, 3.0, 0.0]
        );
        // A 2-wide box spreads one texel further than the 1-wide box: 4 taps of 1/4.
        assert_eq!(
            reduce_row(&imp, Downsample::Box, 2.0),
            vec![0.0, 2.0, 2.0, 0.0]
        );
        // Widths below one texel are raised to one.
        assert_eq!(
            reduce_row(&imp, Downsample::Box, 0.1),
            vec![0.0, 0.0, 4.0, 0.0]
        );
    }

    #[test]
    fn every_named_filter_keeps_constants_and_the_mean_of_a_ramp() {
        let names = [
            "box",
            "triangle",
            "catmull-rom",
            "gaussian",
            "sinc",
            "mitchell",
            "disk",
            "bessel",
            "separable-catmull-rom",
            "blackman-harris",
            "lanczos",
            "b-spline",
        ];
        let ramp: Vec<f32> = (0..16).map(|i| (i % 8) as f32).collect();
        for n in names {
            let f = Downsample::parse(n).unwrap_or_else(|| panic!("{n} unknown"));
            for w in [1.0, f.natural_width(), 3.5] {
                let c = reduce_row(&[0.7; 12], f, w);
                assert!(c.iter().all(|v| (v - 0.7).abs() < 1e-5), "{n} {w}: {c:?}");
                // Periodic, symmetric kernels preserve the mean.
                let r = reduce_row(&ramp, f, w);
                let mean = r.iter().sum::<f32>() / r.len() as f32;
                assert!((mean - 3.5).abs() < 1e-4, "{n} {w}: mean {mean}");
            }
        }
        assert_eq!(Downsample::parse("zmin"), None);
        // Smoother kernels blur an impulse more than the box.
        let imp = [0.0, 0.0, 0.0, 0.0, 8.0, 0.0, 0.0, 0.0];
        let b = reduce_row(&imp, Downsample::BSpline, 4.0);
        assert!(b[0] > 0.0 || b[3] > 0.0, "{b:?}");
    }
}
