//! What arbor renders when a scene names something it cannot have, as the published scenes
//! need: a missing texture map reads as white (Aqsis and Pixie do the same), and a missing
//! surface shader is stood in for by `matte` (or `plastic`), so the scene keeps its lights.

use std::path::{Path, PathBuf};

use arbor::diag::{Diagnostics, SourceMap};
use arbor::pipeline::{render_paths, Settings};

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("arbor-fallbacks-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Renders `rib` (which writes `out.png` in `dir`) and returns the diagnostics and the
/// picture's grey levels (0–255, red channel), row-major.
fn render(dir: &Path, rib: &str, shader: Option<(&str, &str)>) -> (String, Vec<u8>, usize) {
    if let Some((name, text)) = shader {
        std::fs::write(dir.join(format!("{name}.sl")), text).unwrap();
    }
    let path = dir.join("scene.rib");
    std::fs::write(&path, rib).unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let stdlib = concat!(env!("CARGO_MANIFEST_DIR"), "/stdlib/shaders").to_string();
    let settings = Settings {
        threads: 1,
        shader_paths: vec![dir.display().to_string(), stdlib],
        ..Default::default()
    };
    render_paths(&[path], &settings, &sources, &diags);
    let img = image::open(dir.join("out.png")).expect("picture").to_rgb8();
    let w = img.width() as usize;
    let px = img.pixels().map(|p| p.0[0]).collect();
    (diags.render_plain(&sources), px, w)
}

const CAMERA: &str = "Format 32 32 1\nPixelSamples 1 1\nProjection \"orthographic\"\n\
                      ScreenWindow -1 1 -1 1\nTranslate 0 0 5\n";

#[test]
fn a_missing_texture_map_reads_as_white() {
    let dir = tmp("texture");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         Surface \"showmap\" \"string mapname\" \"no-such-map.tx\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let shader = "surface showmap(string mapname = \"\") { Oi = 1; \
                  Ci = 0.5 * color texture(mapname) + 0.25 * float texture(mapname[1]); }";
    let (log, px, _) = render(&dir, &rib, Some(("showmap", shader)));
    assert!(log.contains("no-such-map.tx"), "{log}");
    // 0.5 * 1 + 0.25 * 1 = 0.75 everywhere: 191 in 8 bits.
    assert!(
        px.iter().all(|&v| (190..=192).contains(&v)),
        "{:?}",
        &px[..8]
    );
}

#[test]
fn a_missing_surface_shader_keeps_the_scene_lit_by_its_lights() {
    let dir = tmp("surface");
    let out = dir.join("out.png").display().to_string();
    // A narrow spotlight straight down the view axis: only the middle of the plane is lit.
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         LightSource \"spotlight\" 1 \"from\" [0 0 -4] \"to\" [0 0 0] \"intensity\" 16 \
         \"coneangle\" 0.1 \"conedeltaangle\" 0.01\n\
         Surface \"NoSuchMatte\" \"Ka\" 1 \"Kd\" 1\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, px, w) = render(&dir, &rib, None);
    assert!(log.contains("`matte` stands in"), "{log}");
    // The spot's radius is 4 tan 0.1 ≈ 0.4 of the half-width 1: the centre is lit, the
    // corners (outside the cone, no ambient light) are black.
    let centre = px[(w / 2) * w + w / 2];
    assert!(centre > 200, "centre {centre}");
    assert_eq!(px[0], 0);
    assert_eq!(px[w * w - 1], 0);
}

/// A displacement that leaves the surface's displacement bound is cut off at the bound (so
/// that every bucket size gives the same picture): arbor says so once, naming the shader and
/// the attribute that fixes it; with the bound declared there is no warning and no crack.
#[test]
fn displacement_past_its_bound_is_reported() {
    let dir = tmp("dispbound");
    let out = dir.join("out.png").display().to_string();
    let shader = "displacement bumpy(float amp = 0.3) { \
                  P += amp * (noise(s * 40, t * 40) - 0.5) * normalize(N); \
                  N = calculatenormal(P); }";
    let scene = |bound: &str| {
        format!(
            "Display \"{out}\" \"png\" \"rgba\"\nFormat 64 64 1\nPixelSamples 2 2\n\
             Projection \"perspective\" \"fov\" 40\nTranslate 0 0 6\nWorldBegin\n\
             Surface \"constant\"\n{bound}Displacement \"bumpy\"\n\
             Patch \"bilinear\" \"P\" [-3 -3 0  3 -3 0  -3 3 0  3 3 0]\nWorldEnd\n"
        )
    };
    let (log, _, _) = render(&dir, &scene(""), Some(("bumpy", shader)));
    assert!(
        log.contains("render::displacementbound") && log.contains("`bumpy`"),
        "{log}"
    );
    let declared = "Attribute \"displacementbound\" \"sphere\" [0.2]\n";
    let (log, px, _) = render(&dir, &scene(declared), None);
    assert!(!log.contains("render::displacementbound"), "{log}");
    // Every pixel is covered by the (white, constant) plane: no cracks.
    assert!(
        px.iter().all(|&v| v == 255),
        "a crack: {}",
        px.iter().filter(|&&v| v < 255).count()
    );
}
