//! A render always finishes: loops that never end are stopped with a warning naming the loop,
//! and absurd requests (`PixelSamples 1000 1000`, `Format 100000 100000`, `ShadingRate 1e-9`,
//! huge filters, buckets and grids) are clamped to a sane limit with a diagnostic saying how
//! `Option "limits"` moves it. Shaders and scenes are our own.

mod common;

use std::path::PathBuf;

use arbor::diag::Diag;

fn shader_dir(name: &str, files: &[(&str, &str)]) -> PathBuf {
    let d = common::scratch_dir(name);
    for (file, text) in files {
        std::fs::write(d.join(file), text).unwrap();
    }
    d
}

fn find<'a>(diags: &'a [(Diag, usize)], code: &str) -> Vec<&'a Diag> {
    diags
        .iter()
        .filter(|(d, _)| d.code == code)
        .map(|(d, _)| d)
        .collect()
}

/// A square facing the camera that fills a small frame, with `surface` on it.
fn square_scene(options: &str, surface: &str) -> String {
    format!(
        r#"{options}
Format 16 16 1
PixelSamples 1 1
PixelFilter "box" 1 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
Surface "{surface}"
Polygon "P" [-2 -2 1  2 -2 1  2 2 1  -2 2 1]
WorldEnd
"#
    )
}

// A varying loop whose state stops changing: `d` never reaches 1. Line 4 is the loop.
const STUCK: &str = "surface stuck(float speed = 0)
{
    float d = 0.25 * s;
    while (d < 1) {
        d += speed * s;
    }
    Ci = color(d, 1, 0);
}
";

#[test]
fn a_loop_that_stops_changing_is_stopped_and_the_grid_keeps_its_values() {
    let dir = shader_dir("hang_stuck", &[("stuck.sl", STUCK)]);
    let (film, diags, sources) =
        common::render_rib_with(&square_scene("", "stuck"), &[dir], &Default::default());
    let warns = find(&diags, "shade::runaway_loop");
    assert_eq!(warns.len(), 1, "{diags:#?}");
    let w = warns[0];
    assert!(w.message.contains("stuck"), "{}", w.message);
    assert!(
        w.message.contains("stopped making progress"),
        "{}",
        w.message
    );
    // The label is the loop statement: stuck.sl line 4.
    let span = w.primary_span().expect("a span");
    let file = sources.get(span.file).expect("file");
    assert!(file.name.ends_with("stuck.sl"), "{}", file.name);
    assert_eq!(sources.line_col(span).0, 4);
    assert!(w
        .help
        .as_deref()
        .unwrap_or("")
        .contains("\"loopiterations\""));
    // Shaded with what it had: d kept its value, green is 1, blue 0.
    let rgb = common::film_rgb(&film);
    for px in rgb.chunks_exact(3) {
        assert!(px[0].abs() < 0.5, "{px:?}");
        assert!((px[1] - 1.0).abs() < 1e-4 && px[2].abs() < 1e-4, "{px:?}");
    }
}

// A loop that changes on every iteration but cycles forever (period 2), uniform control.
const CYCLE: &str = "surface cycle()
{
    float x = 0, n = 0;
    while (x < 2) {
        x = 1 - x;
        n += 1;
        if (n > 1e30) x = 3;
    }
    Ci = color(x, 0, 1);
}
";

#[test]
fn a_loop_past_the_iteration_limit_is_stopped() {
    let dir = shader_dir("hang_cycle", &[("cycle.sl", CYCLE)]);
    let rib = square_scene(r#"Option "limits" "loopiterations" [3000]"#, "cycle");
    let (film, diags, _) = common::render_rib_with(&rib, &[dir], &Default::default());
    let warns = find(&diags, "shade::runaway_loop");
    assert_eq!(warns.len(), 1, "{diags:#?}");
    assert!(
        warns[0].message.contains("ran 3000 iterations"),
        "{}",
        warns[0].message
    );
    // 3000 passes of x = 1 - x leave x at 0.
    for px in common::film_rgb(&film).chunks_exact(3) {
        assert!(px[0].abs() < 1e-4 && (px[2] - 1.0).abs() < 1e-4, "{px:?}");
    }
}

// A long loop that does end: 20000 iterations of a uniform loop, each adding 1/20000.
const LONG: &str = "surface long()
{
    float acc = 0, i;
    for (i = 0; i < 20000; i += 1)
        acc += 1.0 / 20000;
    Ci = color(acc, acc * s, 0);
}
";

#[test]
fn long_loops_that_progress_run_to_the_end() {
    let dir = shader_dir("hang_long", &[("long.sl", LONG)]);
    let (film, diags, _) =
        common::render_rib_with(&square_scene("", "long"), &[dir], &Default::default());
    assert!(find(&diags, "shade::runaway_loop").is_empty(), "{diags:#?}");
    let m = common::film_mean(&film);
    assert!((m[0] - 1.0).abs() < 1e-3, "{m:?}");
}

// The smoke-march shape from the issue: the step is clamp(step, minstep, end - d); with
// lo > hi once d passes end - minstep. The loop must end (the built-in returns lo there).
const MARCH: &str = "surface march(float end = 1)
{
    float d = 0, ss = 0.3, steps = 0;
    while (d <= end) {
        ss = clamp(ss, 0.005, end - d);
        d += ss;
        steps += 1;
    }
    Ci = color(steps / 10, d, 0);
}
";

#[test]
fn a_clamped_march_step_ends_the_loop() {
    let dir = shader_dir("hang_march", &[("march.sl", MARCH)]);
    let (film, diags, _) =
        common::render_rib_with(&square_scene("", "march"), &[dir], &Default::default());
    assert!(find(&diags, "shade::runaway_loop").is_empty(), "{diags:#?}");
    let m = common::film_mean(&film);
    // 0.3, 0.6, 0.9, then end (clamped to end - d), then at most a zero step and one of
    // the minimum 0.005 past the end.
    let steps = m[0] * 10.0;
    assert!((4.5..6.5).contains(&steps), "{m:?}");
    assert!(m[1] > 1.0 && m[1] < 1.0051, "{m:?}");
}

// Found by fuzzing (fuzz3): an fBm whose octave count was mutated to 1e39, called at each
// step of a volume march, ran the loop limit at every call (64 times a grid: minutes for one
// sphere). A loop stopped at the limit is skipped at its later executions in the run.
const CALLED: &str = "float endless(float k)
{
    float i, s = 0;
    for (i = 0; i < k; i += 1)
        s += 1;
    return s;
}
surface called(float octaves = 1e39)
{
    float j, acc = 0;
    for (j = 0; j < 50; j += 1)
        acc += endless(octaves);
    Ci = color(acc / 1000, j / 50, 0);
}
";

#[test]
fn a_loop_stopped_at_the_limit_is_not_run_again_in_the_same_grid() {
    let dir = shader_dir("hang_called", &[("called.sl", CALLED)]);
    let rib = square_scene(r#"Option "limits" "loopiterations" [1000]"#, "called");
    let (film, diags, sources) = common::render_rib_with(&rib, &[dir], &Default::default());
    let warns: Vec<_> = diags
        .iter()
        .filter(|(d, _)| d.code == "shade::runaway_loop")
        .collect();
    // One warning, at the endless loop (line 4), once per grid: not once per call.
    assert_eq!(warns.len(), 1, "{diags:#?}");
    let (w, times) = warns[0];
    assert!(w.message.contains("ran 1000 iterations"), "{}", w.message);
    assert_eq!(sources.line_col(w.primary_span().expect("a span")).0, 4);
    let grids = 1; // a 16 x 16 square at shading rate 1 is one grid
    assert_eq!(*times, grids, "{diags:#?}");
    // The first call counted to 1000; the outer loop ran its 50 steps to the end.
    for px in common::film_rgb(&film).chunks_exact(3) {
        assert!(
            (px[0] - 1.0).abs() < 1e-4 && (px[1] - 1.0).abs() < 1e-4,
            "{px:?}"
        );
    }
}

fn limit_warnings(diags: &[(Diag, usize)]) -> Vec<String> {
    find(diags, "render::limits")
        .iter()
        .map(|d| format!("{} | {}", d.message, d.help.clone().unwrap_or_default()))
        .collect()
}

#[test]
fn absurd_pixel_samples_and_filters_are_clamped() {
    let rib = r#"Format 8 8 1
PixelSamples 1000 1000
PixelFilter "gaussian" 1000 1000
Projection "orthographic"
WorldBegin
Color 0.5 0.25 1
Surface "constant"
Polygon "P" [-2 -2 1  2 -2 1  2 2 1  -2 2 1]
WorldEnd
"#;
    let (film, diags, _) = common::render_rib_with(rib, &[], &Default::default());
    let w = limit_warnings(&diags);
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(w.iter().any(|m| m.contains("PixelSamples 1000 1000")
        && m.contains("using 16 16")
        && m.contains("\"limits\" \"pixelsamples\"")));
    assert!(w
        .iter()
        .any(|m| m.contains("PixelFilter") && m.contains("\"filterwidth\"")));
    let m = common::film_mean(&film);
    assert!(
        (m[0] - 0.5).abs() < 1e-3 && (m[2] - 1.0).abs() < 1e-3,
        "{m:?}"
    );
}

#[test]
fn a_huge_format_is_scaled_down_to_the_limit_keeping_its_shape() {
    // The default limit (8192) is checked in the unit tests; here the option moves it.
    let rib = r#"Option "limits" "resolution" [40]
Format 100000 50000 1
Projection "orthographic"
WorldBegin
Surface "constant"
Polygon "P" [-2 -2 1  2 -2 1  2 2 1  -2 2 1]
WorldEnd
"#;
    let (film, diags, _) = common::render_rib_with(rib, &[], &Default::default());
    assert_eq!((film.width, film.height), (40, 20));
    let w = limit_warnings(&diags);
    assert!(
        w.len() == 1 && w[0].contains("Format 100000 50000") && w[0].contains("40×20"),
        "{w:#?}"
    );
}

#[test]
fn a_tiny_shading_rate_is_raised_and_can_be_lowered_by_the_limit() {
    let scene = |opt: &str| {
        format!(
            r#"{opt}
Format 8 8 1
Projection "orthographic"
WorldBegin
ShadingRate 1e-9
Surface "constant"
Sphere 0.5 -0.5 0.5 360
WorldEnd
"#
        )
    };
    let (_, diags, _) = common::render_rib_with(&scene(""), &[], &Default::default());
    let w = limit_warnings(&diags);
    assert!(
        w.len() == 1 && w[0].contains("ShadingRate 1e-9") && w[0].contains("using 0.05"),
        "{w:#?}"
    );
    assert!(w[0].contains("\"limits\" \"shadingrate\""), "{w:#?}");
    let (_, diags, _) = common::render_rib_with(
        &scene(r#"Option "limits" "shadingrate" [0.02]"#),
        &[],
        &Default::default(),
    );
    let w = limit_warnings(&diags);
    assert!(w.len() == 1 && w[0].contains("using 0.02"), "{w:#?}");
}

#[test]
fn huge_buckets_and_grids_are_bounded_without_changing_the_picture() {
    let scene = |opt: &str| {
        format!(
            r#"{opt}
Format 24 24 1
Projection "perspective" "fov" [40]
Translate 0 0 3
WorldBegin
Color 1 0.5 0
Surface "matte"
LightSource "distantlight" 1
Sphere 1 -1 1 360
WorldEnd
"#
        )
    };
    let (plain, diags, _) = common::render_rib_with(&scene(""), &[], &Default::default());
    assert!(limit_warnings(&diags).is_empty());
    let (big, diags, _) = common::render_rib_with(
        &scene(r#"Option "limits" "bucketsize" [100000 100000] "gridsize" [1e12]"#),
        &[],
        &Default::default(),
    );
    let w = limit_warnings(&diags);
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(
        w.iter().all(|m| m.contains("memory use and speed")),
        "{w:#?}"
    );
    // Bucket size never changes the picture; grid size only moves grid seams.
    let (a, b) = (common::film_mean(&plain), common::film_mean(&big));
    assert!((0..3).all(|c| (a[c] - b[c]).abs() < 2e-3), "{a:?} {b:?}");
    let (bucket, _, _) = common::render_rib_with(
        &scene(r#"Option "limits" "bucketsize" [100000 100000]"#),
        &[],
        &Default::default(),
    );
    assert!(common::film_rgb(&plain) == common::film_rgb(&bucket));
}

/// A patch with a point at 1e38 (a stray number an exporter wrote): its pieces' trial dicing
/// overflows, the pieces whose projection overflows count as crossing the eye plane, and
/// either kind of split could double the pieces for 2^32 splits. With the "unlimited" eye
/// splits exporters write (Houdini: 1000) arbor holds eye splits at `MAX_EYE_SPLITS` and all
/// splits of one primitive at its split budget, drops what is left with warnings naming the
/// numbers, and renders the rest of the frame.
#[test]
fn unlimited_eye_splits_are_held_so_a_stray_huge_point_cannot_split_for_hours() {
    let rib = r#"Option "limits" "eyesplits" [1000]
Format 24 18 1
PixelSamples 1 1
Projection "perspective" "fov" [90]
Translate 0 0 2
WorldBegin
Color 1 1 1
Surface "constant"
Polygon "P" [-3 -3 1  -1 -3 1  -1 -1 1  -3 -1 1]
Patch "bilinear" "P" [-1 -1 0  1 -1 0  -1 1 0  1 -1e38 0]
WorldEnd
"#;
    let (film, diags, splits) = render_counting_splits(rib);
    let budget = arbor::render::driver::MIN_SPLIT_BUDGET;
    assert!(splits <= budget + 16, "{splits} splits");
    assert!(!find(&diags, "render::splits").is_empty(), "{diags:#?}");
    let warns = find(&diags, "render::eyesplits");
    assert!(!warns.is_empty(), "{diags:#?}");
    let help = warns[0].help.as_deref().unwrap_or("");
    assert!(help.contains("1000") && help.contains("16"), "{help}");
    // The square beside it renders.
    assert!(common::film_mean(&film)[0] > 0.01);
}

/// A stray far depth (a control point at z = 1e8) under an orthographic camera: the patch's
/// pieces shrink on screen as they split, so it dices in a few grids. The bound's rounding
/// pad was once taken from the largest coordinate on every axis (±1000 in x and y here), so
/// no piece ever looked small enough and the splitting ran to 2^32 pieces.
#[test]
fn a_far_control_point_does_not_widen_a_patch_on_screen() {
    let rib = r#"Format 32 24 1
PixelSamples 1 1
Projection "orthographic"
Translate 0 0 5
WorldBegin
Surface "constant"
Patch "bicubic" "P" [-1 -1 0  -0.3 -1 0  0.3 -1 0  1 -1 0
  -1 -0.3 0  -0.3 -0.3 0  0.3 -0.3 1e8  1 -0.3 0
  -1 0.3 0  -0.3 0.3 0  0.3 0.3 0  1 0.3 0
  -1 1 0  -0.3 1 0  0.3 1 0  1 1 0]
WorldEnd
"#;
    let (film, _, splits) = render_counting_splits(rib);
    assert!(splits < 1000, "{splits} splits");
    // The patch's corners still cover the middle of the frame.
    assert!(common::film_mean(&film)[0] > 0.1);
}

/// Renders `rib` and counts the splits its surfaces made.
fn render_counting_splits(rib: &str) -> (arbor::film::Film, Vec<(Diag, usize)>, u64) {
    let stats = arbor::render::Stats::new();
    let opts = arbor::render::RenderOptions {
        stats: Some(&stats),
        ..Default::default()
    };
    let (film, diags, _) = common::render_rib_with(rib, &[], &opts);
    let splits = stats.splits.load(std::sync::atomic::Ordering::Relaxed);
    (film, diags, splits)
}
