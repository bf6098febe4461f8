//! Motion blur and depth of field, checked against their analytic pictures: a moving bar
//! spreads its energy evenly over the distance it travels, an out-of-focus point images to a
//! disk of the thin-lens diameter, and blurred output stays the same bits for any bucket
//! size and thread count. Bad motion blocks are diagnosed.

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::Film;
use arbor::pipeline::{render_text, Settings};

fn render_with(text: &str, settings: &Settings) -> (Film, Diagnostics) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = render_text(text, settings, &sources, &diags);
    assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
    (films.into_iter().next().expect("one film"), diags)
}

fn render(text: &str) -> Film {
    render_with(text, &Settings::default()).0
}

/// Alpha summed over each column, averaged over the rows.
fn column_profile(f: &Film, w: usize, h: usize) -> Vec<f32> {
    (0..w)
        .map(|x| (0..h).map(|y| f.pixel(x, y)[3]).sum::<f32>() / h as f32)
        .collect()
}

/// A white bar 4 pixels wide (raster x 30…34), moved by `motion` (RIB text before it).
fn bar(shutter: &str, motion: &str, prim: &str) -> String {
    format!(
        "Format 64 16 1\nPixelSamples 8 8\nPixelFilter \"box\" 1 1\n\
         Projection \"orthographic\"\nScreenWindow -32 32 -8 8\n{shutter}\nWorldBegin\n\
         Surface \"constant\"\n{motion}\n{prim}\nWorldEnd\n"
    )
}

const BAR: &str = "Polygon \"P\" [-2 -9 5  2 -9 5  2 9 5  -2 9 5]";
const SLIDE: &str = "MotionBegin [0 1]\nTranslate 0 0 0\nTranslate 10 0 0\nMotionEnd";

fn check_spread(f: &Film, d: usize) {
    let prof = column_profile(f, 64, 16);
    let energy: f32 = prof.iter().sum();
    assert!(
        (energy - 4.0).abs() <= 0.04,
        "energy {energy}, profile {prof:?}"
    );
    // Covered from x = 30 to 34 + d, nothing outside.
    for (x, &a) in prof.iter().enumerate() {
        if x < 30 || x >= 34 + d {
            assert_eq!(a, 0.0, "column {x} outside the swept band: {prof:?}");
        }
    }
    assert!(prof[30] > 0.0 && prof[33 + d] > 0.0, "{prof:?}");
    // Where the whole bar passes, each column is covered 4/d of the time.
    for x in 34..30 + d {
        assert!(
            (prof[x] - 4.0 / d as f32).abs() < 0.05,
            "column {x}: {} (want {}), {prof:?}",
            prof[x],
            4.0 / d as f32
        );
    }
}

#[test]
fn a_moving_bar_spreads_over_its_path_keeping_its_energy() {
    check_spread(&render(&bar("Shutter 0 1", SLIDE, BAR)), 10);
    // Half the shutter: half the distance.
    check_spread(&render(&bar("Shutter 0 0.5", SLIDE, BAR)), 5);
    // Shutter closed (the default): the bar sits at its first key, sharp.
    let f = render(&bar("", SLIDE, BAR));
    let prof = column_profile(&f, 64, 16);
    assert_eq!(&prof[29..35], &[0.0, 1.0, 1.0, 1.0, 1.0, 0.0]);
}

#[test]
fn a_deforming_bar_blurs_like_a_moving_one() {
    let keys = "MotionBegin [0 1]\n\
        Polygon \"P\" [-2 -9 5  2 -9 5  2 9 5  -2 9 5]\n\
        Polygon \"P\" [8 -9 5  12 -9 5  12 9 5  8 9 5]\nMotionEnd";
    check_spread(&render(&bar("Shutter 0 1", "", keys)), 10);
    // Three keys (two segments): still a straight slide.
    let keys3 = "MotionBegin [0 0.5 1]\n\
        Polygon \"P\" [-2 -9 5  2 -9 5  2 9 5  -2 9 5]\n\
        Polygon \"P\" [3 -9 5  7 -9 5  7 9 5  3 9 5]\n\
        Polygon \"P\" [8 -9 5  12 -9 5  12 9 5  8 9 5]\nMotionEnd";
    check_spread(&render(&bar("Shutter 0 1", "", keys3)), 10);
}

fn busy(bucket: &str) -> String {
    format!(
        "Format 48 36 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" [50]\n\
         Option \"limits\" \"bucketsize\" [{bucket}]\nShutter 0 1\n\
         DepthOfField 2.8 0.5 4\nTranslate 0 0 4\nWorldBegin\n\
         LightSource \"distantlight\" 1\nSurface \"plastic\"\n\
         AttributeBegin\nMotionBegin [0 1]\nRotate 0 0 1 0\nRotate 60 0 1 0\nMotionEnd\n\
         Translate 0.6 0 0\nSphere 0.7 -0.7 0.7 360\nAttributeEnd\n\
         AttributeBegin\nColor [1 0.3 0.2]\nMotionBegin [0 0.5 1]\nTranslate -1 0 1\n\
         Translate -0.5 0.4 1\nTranslate -0.7 0.9 0\nMotionEnd\n\
         Polygon \"P\" [-0.5 -0.5 0  0.5 -0.5 0  0.5 0.5 0  -0.5 0.5 0]\nAttributeEnd\n\
         Opacity [0.5 0.5 0.5]\nMotionBegin [0 1]\nSphere 0.3 -0.3 0.3 360\n\
         Sphere 0.6 -0.6 0.6 360\nMotionEnd\nWorldEnd\n"
    )
}

#[test]
fn blurred_output_is_identical_for_any_bucket_size_and_thread_count() {
    let bits = |f: &Film| f.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let one = Settings {
        threads: 1,
        ..Settings::default()
    };
    let two = Settings {
        threads: 2,
        ..Settings::default()
    };
    let (a, _) = render_with(&busy("16 16"), &one);
    let covered = a
        .data
        .chunks(a.data.len() / (48 * 36))
        .filter(|p| p[3] > 0.0)
        .count();
    assert!(covered > 300, "{covered} pixels covered");
    for (bucket, s) in [("7 5", &two), ("32 32", &two), ("5 9", &one)] {
        let (b, _) = render_with(&busy(bucket), s);
        assert!(bits(&a) == bits(&b), "bucket {bucket} differs");
    }
}

/// A disk of raster radius 3 on the axis at depth 2.5 (fov 90 on 101², 50.5 pixels per unit
/// of x/z), seen through `DepthOfField fstop 1 10`.
fn point(fstop: &str) -> String {
    format!(
        "Format 101 101 1\nPixelSamples 16 16\nPixelFilter \"box\" 1 1\n\
         Projection \"perspective\" \"fov\" [90]\nDepthOfField {fstop} 1 10\nWorldBegin\n\
         Surface \"constant\"\nDisk 2.5 0.148515 360\nWorldEnd\n"
    )
}

/// Total alpha and the alpha-weighted mean squared distance from the image centre.
fn moments(f: &Film) -> (f64, f64) {
    let (mut e, mut r2) = (0f64, 0f64);
    for y in 0..101 {
        for x in 0..101 {
            let a = f.pixel(x, y)[3] as f64;
            let (dx, dy) = (x as f64 + 0.5 - 50.5, y as f64 + 0.5 - 50.5);
            e += a;
            r2 += a * (dx * dx + dy * dy);
        }
    }
    (e, r2 / e)
}

#[test]
fn an_out_of_focus_point_images_to_the_thin_lens_disk() {
    let p = 6.0f64; // the pinhole image's diameter in pixels
    let area = std::f64::consts::PI * p * p / 4.0;
    // Pinhole (an infinite f-stop, as real scenes write it): the sharp disk (diced into a
    // polygon a little smaller than the circle).
    let (e0, r0) = moments(&render(&point("1e38")));
    assert!((e0 - area).abs() < 0.04 * area, "energy {e0}");
    assert!((r0 - p * p / 8.0).abs() < 0.3, "{r0}");
    // f/0.5: aperture 2, circle of confusion 2·|1/2.5 − 1/10| = 0.6 of x/z = 30.3 pixels.
    let want = 0.6 * 50.5;
    let f = render(&point("0.5"));
    let (e, r2) = moments(&f);
    assert!((e - e0).abs() < 0.01 * e0, "energy {e} (sharp {e0})");
    // A uniform disk of diameter D has mean r² = D²/8; blurring adds the variances.
    let d = (8.0 * (r2 - r0)).sqrt();
    assert!((d - want).abs() < 1.0, "blur diameter {d}, want {want}");
    // Nothing beyond the blurred disk's edge (plus a pixel).
    for y in 0..101 {
        for x in 0..101 {
            let r = ((x as f64 + 0.5 - 50.5).powi(2) + (y as f64 + 0.5 - 50.5).powi(2)).sqrt();
            if r > (want + p) / 2.0 + 1.5 {
                assert_eq!(f.pixel(x, y)[3], 0.0, "pixel {x},{y} at r = {r}");
            }
        }
    }
}

#[test]
fn in_focus_stays_sharp() {
    // The disk on the focal plane: the lens changes nothing visible.
    let f = render(
        "Format 101 101 1\nPixelSamples 8 8\nPixelFilter \"box\" 1 1\n\
         Projection \"perspective\" \"fov\" [90]\nDepthOfField 0.5 1 2.5\nWorldBegin\n\
         Surface \"constant\"\nDisk 2.5 0.148515 360\nWorldEnd\n",
    );
    let (e, r2) = moments(&f);
    let area = std::f64::consts::PI * 9.0;
    assert!((e - area).abs() < 0.03 * area, "{e}");
    assert!((r2 - 36.0 / 8.0).abs() < 0.3, "{r2}");
}

fn diagnose(text: &str) -> Vec<(String, String)> {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let _ = render_text(text, &Settings::default(), &sources, &diags);
    diags
        .snapshot()
        .into_iter()
        .map(|(d, _)| (d.code.to_string(), d.message.clone()))
        .collect()
}

#[test]
fn bad_motion_blocks_are_diagnosed() {
    let base = |motion: &str| {
        format!("Format 8 8 1\nShutter 0 1\nWorldBegin\n{motion}\nSphere 1 -1 1 360\nWorldEnd\n")
    };
    let d = diagnose(&base(
        "MotionBegin [0 0.5 1]\nTranslate 0 0 5\nTranslate 1 0 5\nMotionEnd",
    ));
    assert!(
        d.iter().any(|(c, m)| c == "scene::motion"
            && m.contains("3 times")
            && m.contains("2 requests")),
        "{d:?}"
    );
    let d = diagnose(&base(
        "MotionBegin [0 1]\nTranslate 0 0 5\nRotate 1 0 0 1\nMotionEnd",
    ));
    assert!(
        d.iter()
            .any(|(c, m)| c == "scene::motion" && m.contains("mixes")),
        "{d:?}"
    );
    let d = diagnose(&base(
        "MotionBegin [1 0]\nTranslate 0 0 5\nTranslate 1 0 5\nMotionEnd",
    ));
    assert!(
        d.iter()
            .any(|(c, m)| c == "scene::motion" && m.contains("increase")),
        "{d:?}"
    );
    let d = diagnose(
        "Format 8 8 1\nShutter 0 1\nWorldBegin\nMotionBegin [0 1]\n\
         Polygon \"P\" [0 0 5 1 0 5 1 1 5]\nPolygon \"P\" [0 0 5 1 0 5 1 1 5 0 1 5]\nMotionEnd\nWorldEnd\n",
    );
    assert!(
        d.iter()
            .any(|(c, m)| c == "scene::motion" && m.contains("same shape")),
        "{d:?}"
    );
    // A good block says nothing.
    let d = diagnose(&base(
        "MotionBegin [0 1]\nTranslate 0 0 5\nTranslate 1 0 5\nMotionEnd",
    ));
    assert!(
        d.iter()
            .all(|(c, _)| c != "scene::motion" && c != "scene::unimplemented"),
        "{d:?}"
    );
}

/// `Hider "abuffer"`: each mask cell is a sample with its own time and lens position, so the
/// same analytic pictures come out.
#[test]
fn the_abuffer_blurs_and_focuses_like_the_zbuffer() {
    let ab = |text: String| text.replacen("WorldBegin", "Hider \"abuffer\"\nWorldBegin", 1);
    let (f, diags) = render_with(&ab(bar("Shutter 0 1", SLIDE, BAR)), &Settings::default());
    assert!(
        !diags
            .snapshot()
            .iter()
            .any(|(d, _)| d.message.contains("blur")),
        "the A-buffer still warns"
    );
    check_spread(&f, 10);
    let keys = "MotionBegin [0 1]\n\
        Polygon \"P\" [-2 -9 5  2 -9 5  2 9 5  -2 9 5]\n\
        Polygon \"P\" [8 -9 5  12 -9 5  12 9 5  8 9 5]\nMotionEnd";
    check_spread(&render(&ab(bar("Shutter 0 0.5", "", keys))), 5);

    // Depth of field with 16×16 masks (256 cells a pixel, like PixelSamples 16 16).
    let lens = |fstop: &str| {
        point(fstop).replacen(
            "WorldBegin",
            "Hider \"abuffer\" \"masksize\" 16\nWorldBegin",
            1,
        )
    };
    let p = 6.0f64;
    let (e0, r0) = moments(&render(&lens("1e38")));
    let area = std::f64::consts::PI * p * p / 4.0;
    assert!((e0 - area).abs() < 0.04 * area, "energy {e0}");
    let f = render(&lens("0.5"));
    let (e, r2) = moments(&f);
    assert!((e - e0).abs() < 0.01 * e0, "energy {e} (sharp {e0})");
    let want = 0.6 * 50.5;
    let d = (8.0 * (r2 - r0)).sqrt();
    assert!((d - want).abs() < 1.0, "blur diameter {d}, want {want}");

    // Same bits for any bucket size and thread count.
    let bits = |f: &Film| f.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    let one = Settings {
        threads: 1,
        ..Settings::default()
    };
    let two = Settings {
        threads: 2,
        ..Settings::default()
    };
    let (a, _) = render_with(&ab(busy("16 16")), &one);
    let (b, _) = render_with(&ab(busy("7 5")), &two);
    assert!(bits(&a) == bits(&b), "A-buffer blur depends on the buckets");
}

/// Spheres at four depths before and behind the focal plane and a floor running away
/// from the eye, far out of focus.
fn focus_rows(bucket: &str) -> String {
    format!(
        "Format 64 48 1\nPixelSamples 5 5\nProjection \"perspective\" \"fov\" [40]\n\
         Option \"limits\" \"bucketsize\" [{bucket}]\nDepthOfField 0.5 0.2 5\n\
         WorldBegin\nLightSource \"distantlight\" 1\nSurface \"plastic\"\n\
         Polygon \"P\" [-6 -0.6 1.5  6 -0.6 1.5  6 -0.6 30  -6 -0.6 30]\n\
         AttributeBegin\nTranslate -0.8 0 2.2\nSphere 0.4 -0.4 0.4 360\nAttributeEnd\n\
         AttributeBegin\nTranslate 0 0 5\nSphere 0.5 -0.5 0.5 360\nAttributeEnd\n\
         AttributeBegin\nTranslate 1.2 0.3 9\nSphere 0.6 -0.6 0.6 360\nAttributeEnd\n\
         AttributeBegin\nOpacity [0.5 0.5 0.5]\nTranslate 0.4 -0.2 3\n\
         Sphere 0.3 -0.3 0.3 360\nAttributeEnd\nWorldEnd\n"
    )
}

/// Lens cells (under depth of field the Z-buffer tests a still micropolygon's samples lens
/// cell group by group, each against its bound through that group's lens positions) skip
/// only samples that cannot be hit: the same hits and bits as testing every sample under
/// the whole-lens bound (`"lensslots" [1]`), whatever the buckets, with fewer tested.
#[test]
fn lens_cells_skip_only_samples_that_cannot_be_hit() {
    let bits = |f: &Film| f.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    binning_skips_only_misses(
        "\"lensslots\" [1]",
        [
            ("focus rows", focus_rows("16 16"), 2.0),
            ("focus rows 7x5", focus_rows("7 5"), 2.0),
            ("busy", busy("16 16"), 1.0),
        ],
    );
    // Out of focus, the picture does not depend on the buckets either.
    let (a, _) = render_stats(&focus_rows("16 16"));
    let (b, _) = render_stats(&focus_rows("7 5"));
    assert!(bits(&a) == bits(&b));
}

/// Renders the first frame with statistics kept: (film, micropolygons).
fn render_counting(text: &str) -> (Film, u64) {
    let (film, counts) = render_stats(text);
    (film, counts[0])
}

/// Renders the first frame with statistics kept: (film, [micropolygons, samples tested,
/// samples hit]).
fn render_stats(text: &str) -> (Film, [u64; 3]) {
    use arbor::render::driver::{render_frame, RenderOptions};
    use arbor::render::stats::Stats;
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = arbor::rib::parse_bytes("t.rib", text.as_bytes(), &sources, &diags);
    let ctx = arbor::scene::BuildContext::new(&sources, &diags);
    let scenes = arbor::scene::build_scenes(reqs, &ctx);
    let settings = Settings::default();
    let library = arbor::pipeline::library_for(&scenes[0], &settings);
    let system = arbor::shade::system::ShadeSystem {
        library: &library,
        sources: &sources,
        diags: &diags,
        textures: None,
        aovs: Vec::new(),
        rays: Default::default(),
    };
    let stats = Stats::default();
    let opts = RenderOptions {
        stats: Some(&stats),
        ..Default::default()
    };
    let film = render_frame(&scenes[0], &system, &opts, &diags);
    let report = diags.render_plain(&sources);
    assert!(!diags.has_errors(), "{report}");
    assert!(!report.contains("GeometricApproximation"), "{report}");
    let get = |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed);
    (
        film,
        [
            get(&stats.micropolygons),
            get(&stats.samples_tested),
            get(&stats.samples_hit),
        ],
    )
}

#[test]
fn motionfactor_shades_blurred_surfaces_coarser() {
    // The bar travels 10 pixels: "motionfactor" 16 multiplies its rate by 1 + 16·10/16 = 11.
    let plain = bar("Shutter 0 1", SLIDE, BAR);
    let coarse = plain.replacen(
        "Surface",
        "GeometricApproximation \"motionfactor\" 16\nSurface",
        1,
    );
    let (f0, n0) = render_counting(&plain);
    let (f1, n1) = render_counting(&coarse);
    let ratio = n0 as f64 / n1 as f64;
    assert!(ratio > 5.0 && ratio < 20.0, "micropolygons {n0} vs {n1}");
    // The flat bar blurs the same.
    check_spread(&f0, 10);
    check_spread(&f1, 10);
    // A still bar is not affected.
    let still = bar("", SLIDE, BAR);
    let (_, s0) = render_counting(&still);
    let (_, s1) = render_counting(&still.replacen(
        "Surface",
        "GeometricApproximation \"motionfactor\" 16\nSurface",
        1,
    ));
    assert_eq!(s0, s1);
    // "focusfactor": an out-of-focus disk (circle of confusion ≈ 30 pixels) shades fewer
    // points; one in focus does not change.
    let blurred = point("0.5");
    let ff = |t: &str| {
        t.replacen(
            "Surface",
            "GeometricApproximation \"focusfactor\" 4\nSurface",
            1,
        )
    };
    let (_, d0) = render_counting(&blurred);
    let (_, d1) = render_counting(&ff(&blurred));
    assert!(d1 * 3 < d0, "focusfactor: {d0} vs {d1}");
    let sharp = blurred.replace("DepthOfField 0.5 1 10", "DepthOfField 0.5 1 2.5");
    let (_, e0) = render_counting(&sharp);
    let (_, e1) = render_counting(&ff(&sharp));
    assert_eq!(e0, e1);
}

/// A bar 2 pixels wide and 12 tall sweeping 48 pixels right during the shutter.
const SWEEP: &str = "Format 64 16 1\nPixelSamples 8 8\nPixelFilter \"box\" 1 1\n\
    Projection \"orthographic\"\nScreenWindow -32 32 -8 8\nShutter 0 1\nWorldBegin\n\
    Surface \"constant\"\nMotionBegin [0 1]\nTranslate -24 0 0\nTranslate 24 0 0\nMotionEnd\n\
    Polygon \"P\" [-1 -6 5  1 -6 5  1 6 5  -1 6 5]\nWorldEnd\n";

/// A sphere shrinking to half its radius while it moves diagonally (as Essential RenderMan's
/// `deform.rib`).
const DIAGONAL: &str =
    "Format 96 72 1\nPixelSamples 3 3\nProjection \"perspective\" \"fov\" [30]\n\
    Shutter 0 1\nTranslate 0 0 5\nWorldBegin\nLightSource \"distantlight\" 1\nSurface \"plastic\"\n\
    MotionBegin [0 1]\nTranslate -0.6 -0.4 0\nTranslate 0.6 0.4 0\nMotionEnd\n\
    MotionBegin [0 1]\nSphere 1 -1 1 360\nSphere 0.5 -0.5 0.5 360\nMotionEnd\nWorldEnd\n";

/// Each case renders the same bits and hits with the Z-buffer's sample binning as with it
/// turned off (`off`, a `Hider "hidden"` parameter), testing at least `speedup` times fewer
/// samples.
fn binning_skips_only_misses<const N: usize>(off: &str, cases: [(&str, String, f64); N]) {
    let bits = |f: &Film| f.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
    for (name, text, speedup) in cases {
        let brute = text.replacen(
            "WorldBegin",
            &format!("Hider \"hidden\" {off}\nWorldBegin"),
            1,
        );
        let (a, [_, tested, hits]) = render_stats(&text);
        let (b, [_, tested_all, hits_all]) = render_stats(&brute);
        assert!(bits(&a) == bits(&b), "{name}: the picture changed");
        assert_eq!(hits, hits_all, "{name}");
        assert!(
            tested as f64 * speedup <= tested_all as f64,
            "{name}: {tested} samples tested, {tested_all} with {off}"
        );
    }
}

/// The A-buffer visits a moving micropolygon's pixels only across the region it sweeps, and
/// tests a pixel's cells only at the times it can be there: on the diagonal, shrinking
/// sphere about 0.76 M micropolygon-pixel visits (7.1 M over the whole-shutter boxes, 33×
/// the time), and the picture stays close to the Z-buffer's at as many samples a pixel
/// (mean difference 0.0006).
#[test]
fn the_abuffer_tests_a_moving_micropolygon_only_where_and_when_it_can_be() {
    let ab = DIAGONAL.replacen("WorldBegin", "Hider \"abuffer\"\nWorldBegin", 1);
    let (a, [_, visits, _]) = render_stats(&ab);
    assert!(visits < 1_500_000, "{visits} pixel visits");
    let (z, _) = render_stats(&DIAGONAL.replacen("PixelSamples 3 3", "PixelSamples 8 8", 1));
    // Colour and alpha (depth is infinite where nothing is).
    let nch = a.channels();
    let (mut sum, mut n) = (0f64, 0f64);
    for (p, q) in a.data.chunks(nch).zip(z.data.chunks(nch)) {
        for c in 0..4 {
            sum += (p[c] - q[c]).abs() as f64;
            n += 1.0;
        }
    }
    let mean = sum / n;
    assert!(mean < 0.003, "mean difference {mean}");
}

/// Time slots (the Z-buffer tests a fast micropolygon slot by slot, each against its bound
/// over the slot's times) skip only samples that cannot be hit: the same hits and the same
/// bits as testing every sample under the whole-shutter bound (`"timeslots" [1]`), with
/// far fewer samples tested.
#[test]
fn time_slots_skip_only_samples_that_cannot_be_hit() {
    let spin = busy("16 16").replacen("PixelSamples 3 3", "PixelSamples 5 4", 1);
    binning_skips_only_misses(
        "\"timeslots\" [1]",
        [
            ("sweep", SWEEP.to_string(), 8.0),
            // Moving diagonally while it shrinks: each slot's box is mostly empty, the
            // swept band is not (about 100×; 54× with boxes of as many slots as samples).
            ("diagonal", DIAGONAL.to_string(), 90.0),
            // Through a lens too: the time window grown by the most the lens can shift it
            // (about 88×; 46× when a lens turned the window off).
            (
                "diagonal through a lens",
                DIAGONAL.replacen("WorldBegin", "DepthOfField 2.8 0.3 5\nWorldBegin", 1),
                75.0,
            ),
            // One sample a pixel still has its 64 time slots (about 35×; there was one).
            (
                "diagonal 1x1",
                DIAGONAL.replacen("PixelSamples 3 3", "PixelSamples 1 1", 1),
                30.0,
            ),
            ("busy", busy("16 16"), 1.0),
            ("busy 5x4", spin, 1.0),
        ],
    );
    // The bar's energy (24 pixels of alpha) spreads evenly over the 50 columns it sweeps:
    // where it passes whole, each column holds 12 rows × 2/48 of the shutter.
    let (f, _) = render_stats(SWEEP);
    let prof: Vec<f32> = column_profile(&f, 64, 16)
        .iter()
        .map(|a| a * 16.0)
        .collect();
    let energy: f32 = prof.iter().sum();
    assert!((energy - 24.0).abs() < 0.24, "energy {energy}");
    // About 32 of a column's 768 samples are hit: ±30 % per column, ±3 % over all.
    for x in 9..55 {
        assert!((prof[x] - 0.5).abs() < 0.15, "column {x}: {prof:?}");
    }
    let mean = prof[9..55].iter().sum::<f32>() / 46.0;
    assert!((mean - 0.5).abs() < 0.015, "mean {mean}: {prof:?}");
    assert!(
        prof[..7].iter().chain(&prof[57..]).all(|&a| a == 0.0),
        "{prof:?}"
    );
}
