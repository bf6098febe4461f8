//! What the film stage does where RISpec is silent and the renderers agree: an imager shader
//! reads `s` and `t` as the pixel's raster position (Aqsis binds them so, and grain imagers
//! call `noise(s, t)`), and a display's `"quantize" [zero one min max]` maps 0 to `zero`
//! (PRMan's and Aqsis's display parameter; a picture of normals puts −1..1 into 1..255).
//! A PNG's alpha is unassociated (PNG specification), so arbor's premultiplied colour is
//! divided by alpha in a PNG with an alpha channel; without one the film's values are written.

mod common;

use std::path::Path;

/// The 8-bit RGB pixels of `dir/name`.
fn pixels(dir: &Path, name: &str) -> (Vec<[u8; 3]>, usize) {
    let img = image::open(dir.join(name)).expect("picture").to_rgb8();
    let w = img.width() as usize;
    (img.pixels().map(|p| p.0).collect(), w)
}

#[test]
fn imager_s_and_t_are_the_pixel_centre_in_raster_space() {
    let dir = common::scratch_dir("film_imager_st");
    std::fs::write(
        dir.join("rasterpos.sl"),
        "imager rasterpos() { Ci = color(s / 8, t / 8, xcomp(P) - s + ycomp(P) - t); Oi = 1; }",
    )
    .unwrap();
    let out = dir.join("out.png").display().to_string();
    // No dither, so each value rounds the same way everywhere.
    let rib = format!(
        "Format 8 4 1\nQuantize \"rgba\" 255 0 255 0\nDisplay \"{out}\" \"png\" \"rgb\"\n\
         Imager \"rasterpos\"\nWorldBegin\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    // One warning each for s and t, naming what they read.
    assert_eq!(log.matches("sl::extension").count(), 2, "{log}");
    assert!(log.contains("raster x"), "{log}");
    let (px, w) = pixels(&dir, "out.png");
    for (k, p) in px.iter().enumerate() {
        let (x, y) = ((k % w) as f32, (k / w) as f32);
        let want_r = ((x + 0.5) / 8.0 * 255.0).round() as u8;
        let want_g = ((y + 0.5) / 8.0 * 255.0).round() as u8;
        assert_eq!(*p, [want_r, want_g, 0], "pixel ({x}, {y})");
    }
}

#[test]
fn a_grain_imager_varies_from_pixel_to_pixel() {
    // Aqsis' filmgrain-style imager: with s and t read as 0 every pixel got the same grain.
    let dir = common::scratch_dir("film_imager_grain");
    std::fs::write(
        dir.join("grain.sl"),
        "imager grain() { Ci = float noise(s * 0.37, t * 0.37); Oi = 1; }",
    )
    .unwrap();
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Format 16 16 1\nQuantize \"rgba\" 255 0 255 0\nDisplay \"{out}\" \"png\" \"rgb\"\n\
         Imager \"grain\"\nWorldBegin\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    let (px, _) = pixels(&dir, "out.png");
    let mut levels: Vec<u8> = px.iter().map(|p| p[0]).collect();
    levels.sort_unstable();
    levels.dedup();
    assert!(levels.len() > 20, "grain levels: {levels:?}");
}

#[test]
fn display_quantize_zero_is_the_level_of_zero() {
    let dir = common::scratch_dir("film_quantize_zero");
    let out = dir.join("cs.png").display().to_string();
    // Cs = (−1, 0, 1) through [128 255 0 255]: 128 − 127 = 1, 128, 255.
    let rib = format!(
        "Format 4 4 1\nPixelSamples 1 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\n\
         Display \"{out}\" \"png\" \"Cs\" \"quantize\" [128 255 0 255]\n\
         Translate 0 0 5\nWorldBegin\nColor -1 0 1\nSurface \"constant\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    assert!(!log.contains("zero offset"), "{log}");
    let (px, _) = pixels(&dir, "cs.png");
    assert!(px.iter().all(|p| *p == [1, 128, 255]), "{:?}", &px[..4]);
}

/// A constant white square whose right edge halves pixel column 2 of a 4×4 picture, through
/// a 1×1 box filter with 4×4 stratified samples (the edge on a stratum boundary: exactly 8 of
/// 16 samples covered), written to `name` with `mode` and `quantize`.
fn half_covered_white(dir: &Path, name: &str, mode: &str, quantize: &str) {
    let out = dir.join(name).display().to_string();
    let rib = format!(
        "Format 4 4 1\nPixelSamples 4 4\nPixelFilter \"box\" 1 1\n{quantize}\n\
         Projection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
         Display \"{out}\" \"png\" \"{mode}\"\nTranslate 0 0 5\nWorldBegin\n\
         Surface \"constant\"\nPolygon \"P\" [-3 -3 0  0.5 -3 0  0.5 3 0  -3 3 0]\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(dir, &rib);
    assert!(!failed, "{log}");
}

#[test]
fn png_alpha_is_straight_and_rgb_png_premultiplied() {
    let dir = common::scratch_dir("film_png_alpha");
    // Default Quantize: 8 bits, dither 0.5.
    half_covered_white(&dir, "rgba.png", "rgba", "");
    half_covered_white(&dir, "rgb.png", "rgb", "");
    let rgba = image::open(dir.join("rgba.png")).unwrap().to_rgba8();
    let rgb = image::open(dir.join("rgb.png")).unwrap().to_rgb8();
    for y in 0..4 {
        assert_eq!(rgba.get_pixel(0, y).0, [255; 4], "covered");
        assert_eq!(rgba.get_pixel(3, y).0, [0; 4], "uncovered");
        // Half covered: white (not grey) at half alpha; a viewer compositing it over black
        // shows 0.5, as the premultiplied film holds.
        let [r, g, b, a] = rgba.get_pixel(2, y).0;
        assert_eq!([r, g, b], [255; 3], "row {y}: straight white");
        assert!((127..=128).contains(&a), "row {y}: alpha {a}");
        // rgb: the film's (premultiplied) values, as before.
        assert_eq!(rgb.get_pixel(0, y).0, [255; 3]);
        for v in rgb.get_pixel(2, y).0 {
            assert!((127..=128).contains(&v), "row {y}: rgb {v}");
        }
        assert_eq!(rgb.get_pixel(3, y).0, [0; 3]);
    }
    // 16 bits: the same.
    half_covered_white(
        &dir,
        "rgba16.png",
        "rgba",
        "Quantize \"rgba\" 65535 0 65535 0.5",
    );
    let img = image::open(dir.join("rgba16.png")).unwrap();
    assert_eq!(img.color(), image::ColorType::Rgba16);
    let img = img.to_rgba16();
    for y in 0..4 {
        let [r, g, b, a] = img.get_pixel(2, y).0;
        assert_eq!([r, g, b], [65535; 3], "row {y}");
        assert!((32767..=32768).contains(&a), "row {y}: alpha {a}");
        assert_eq!(img.get_pixel(3, y).0, [0; 4]);
    }
}

#[test]
fn the_background_imager_takes_prman_color_parameter() {
    // PRMan's built-in background imager names its colour "color" (solidThinking and
    // mtor RIB write `Imager "background" "color" [0 0 0]`); read as unknown it left the
    // RISpec default, white, behind a black starfield. An unknown name is reported.
    let dir = common::scratch_dir("film_background_color");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Format 4 2 1\nQuantize \"rgba\" 255 0 255 0\nDisplay \"{out}\" \"png\" \"rgb\"\n\
         Declare \"color\" \"color\"\n\
         Imager \"background\" \"color\" [0.2 0.4 0.6] \"bgcolour\" [1 0 0]\n\
         WorldBegin\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    assert_eq!(log.matches("film::imager").count(), 1, "{log}");
    assert!(log.contains("no parameter `bgcolour`"), "{log}");
    let (px, _) = pixels(&dir, "out.png");
    assert!(px.iter().all(|p| *p == [51, 102, 153]), "{px:?}");
}

#[test]
fn clamptoalpha_is_a_standard_imager_that_clamps_colour_to_alpha() {
    // BMRT shipped `clamptoalpha`; exporters name it (`Imager "clamptoalpha"`) without the
    // source. A constant surface of colour (2, 0.5, 0) at opacity 0.4 leaves a premultiplied
    // (0.8, 0.2, 0) over alpha 0.4: red is clamped to 0.4, green and blue stay.
    let dir = common::scratch_dir("film_clamptoalpha");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Format 4 4 1\nPixelSamples 1 1\nQuantize \"rgba\" 255 0 255 0\n\
         Projection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
         Display \"{out}\" \"png\" \"rgb\"\nImager \"clamptoalpha\"\nTranslate 0 0 5\n\
         WorldBegin\nColor 2 0.5 0\nOpacity 0.4 0.4 0.4\nSurface \"constant\"\n\
         Polygon \"P\" [-3 -3 0  3 -3 0  3 3 0  -3 3 0]\nWorldEnd\n"
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    assert!(!log.contains("clamptoalpha"), "found and run: {log}");
    let (px, _) = pixels(&dir, "out.png");
    assert!(px.iter().all(|p| *p == [102, 51, 0]), "{:?}", &px[..4]);
}
