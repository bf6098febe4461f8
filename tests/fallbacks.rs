//! What arbor renders when a scene names something it cannot have, as the published scenes
//! need: a missing texture map reads as white (Aqsis and Pixie do the same), and a missing
//! surface shader is stood in for by `matte` (or `plastic`, `metal`) when its name or its
//! parameters say it is one, so the scene keeps its lights, and by `defaultsurface`
//! otherwise; a missing light shader by the standard light it resembles (`spotlight`,
//! `pointlight`, `distantlight`, `ambientlight`).

mod common;

use std::path::Path;

/// Renders `rib` (which writes `out.png` in `dir`) and returns the diagnostics and the
/// picture's grey levels (0–255, red channel), row-major.
fn render(dir: &Path, rib: &str, shader: Option<(&str, &str)>) -> (String, Vec<u8>, usize) {
    if let Some((name, text)) = shader {
        std::fs::write(dir.join(format!("{name}.sl")), text).unwrap();
    }
    let (log, _) = common::render_scene_file(dir, rib);
    let img = image::open(dir.join("out.png")).expect("picture").to_rgb8();
    let w = img.width() as usize;
    let px = img.pixels().map(|p| p.0[0]).collect();
    (log, px, w)
}

const CAMERA: &str = "Format 32 32 1\nPixelSamples 1 1\nProjection \"orthographic\"\n\
                      ScreenWindow -1 1 -1 1\nTranslate 0 0 5\n";

#[test]
fn a_missing_texture_map_reads_as_white() {
    let dir = common::scratch_dir("fallbacks_texture");
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

/// A grey picture of `level` (0–255), size 8×8, written as `path` (format from its extension).
fn grey_picture(path: &Path, level: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::from_pixel(8, 8, image::Luma([level]))
        .save(path)
        .unwrap();
}

#[test]
fn a_map_never_made_is_read_from_the_picture_beside_it_or_the_packages_texture_folder() {
    // Published scenes name `star.tx` and ship `star.tiff` (the texture tool was never run
    // here), or keep their maps in `../texture` where an options file points.
    let root = common::scratch_dir("fallbacks_texture_standin");
    let dir = root.join("scenes");
    grey_picture(&dir.join("beside.tiff"), 64);
    grey_picture(&root.join("texture").join("above.tx.png"), 0);
    grey_picture(&root.join("tifftexture").join("above.tif"), 128);
    grey_picture(&root.join("shared.tiff"), 32);
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         Surface \"twomaps\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let shader = "surface twomaps() { Oi = 1; \
                  Ci = float texture(\"beside.tx\") + float texture(\"above.tx\") \
                  + float texture(\"shared.tx\"); }";
    let (log, px, _) = render(&dir, &rib, Some(("twomaps", shader)));
    assert!(log.contains("texture::stand-in"), "{log}");
    assert!(
        log.contains("beside.tiff") && log.contains("above.tif"),
        "{log}"
    );
    // 64 + 128 (the first picture of the stem that exists in the package's folders) + 32 (the
    // package folder above the scene's).
    assert!(
        px.iter().all(|&v| (223..=225).contains(&v)),
        "{:?}",
        &px[..8]
    );
}

#[test]
fn a_missing_surface_shader_keeps_the_scene_lit_by_its_lights() {
    let dir = common::scratch_dir("fallbacks_surface");
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

/// MayaMan, Liquid and RfM name a surface after the Maya material it was exported from
/// (`mms_blinn1`, `lambert2`, `phong1SG`) and ship it compiled for one renderer only: a
/// missing one stands in as the material it was, lit by the scene's lights.
#[test]
fn a_missing_maya_material_stands_in_as_the_material_it_names() {
    let dir = common::scratch_dir("fallbacks_maya_material");
    let out = dir.join("out.png").display().to_string();
    // Lit at 45° from the left: N·L = 0.707, the highlight (exponent 80) falls far from the
    // eye. `defaultsurface` would show the plane face-on at full brightness (255).
    for (name, stand_in, level) in [
        ("sheep1/shaders/mms_blinn1", "plastic", 90),
        ("mms_sheep1_phong2", "plastic", 90),
        ("mms_lambert1", "matte", 180),
    ] {
        let rib = format!(
            "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
             LightSource \"distantlight\" 1 \"intensity\" 1 \"from\" [-1 0 -1] \"to\" [0 0 0]\n\
             Surface \"{name}\"\n\
             Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
        );
        let (log, px, w) = render(&dir, &rib, None);
        assert!(
            log.contains(&format!("`{stand_in}` stands in")),
            "{name}: {log}"
        );
        // Kd·0.707: plastic's Kd is 0.5, matte's 1.
        let centre = px[(w / 2) * w + w / 2] as i32;
        assert!(
            (centre - level).abs() <= 3,
            "{name}: centre {centre}, want {level}"
        );
    }
}

/// A missing shader that nothing marks as a lit material (no diffuse or specular parameters,
/// a name like `saturn3`) is a custom look: `defaultsurface` stands in (as in Aqsis and
/// Pixie), so the object shows its colour seen face-on, not lit by a light the real shader may
/// not have used.
#[test]
fn a_missing_custom_shader_shows_its_colour_face_on() {
    let dir = common::scratch_dir("fallbacks_custom");
    let out = dir.join("out.png").display().to_string();
    // A strong light from the left would light matte's left half only.
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         LightSource \"distantlight\" 1 \"intensity\" 4 \"from\" [-1 0 0] \"to\" [0 0 0]\n\
         Color [0.5 0.5 0.5]\nSurface \"saturn3\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, px, w) = render(&dir, &rib, None);
    assert!(log.contains("`defaultsurface` stands in"), "{log}");
    // The plane faces the eye: Cs·(Ka + Kd·facing ratio) ≈ 0.5 across, whatever the light.
    let centre = px[(w / 2) * w + w / 2];
    assert!((118..=130).contains(&centre), "centre {centre}");
}

/// A sphere around the camera with a missing shader is a sky dome (star fields, skies emit
/// light): `defaultsurface` stands in, showing its colour, not `matte` lit from inside by the
/// scene's distant light.
#[test]
fn a_missing_sky_dome_shader_shows_the_dome_colour() {
    let dir = common::scratch_dir("fallbacks_dome");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\nFormat 16 16 1\nPixelSamples 1 1\n\
         Projection \"perspective\" \"fov\" 30\nWorldBegin\n\
         LightSource \"distantlight\" 1 \"intensity\" 3 \"from\" [0 0 0] \"to\" [0 0 1]\n\
         Color [0.5 0.5 0.5]\nSurface \"nosuchstarfield\"\nSphere 1000 -1000 1000 360\nWorldEnd\n"
    );
    let (log, px, _) = render(&dir, &rib, None);
    assert!(log.contains("`defaultsurface` stands in"), "{log}");
    // Ka + Kd·(facing ratio ≈ 1) = 1 times Cs = 0.5: 128, not matte's 3·0.5 (clipped to 255).
    assert!(
        px.iter().all(|&v| (124..=130).contains(&v)),
        "{:?}",
        &px[..4]
    );
}

/// A displacement that leaves the surface's declared displacement bound is cut off at the
/// bound (so that every bucket size gives the same picture): arbor says so once, naming the
/// shader and the attribute that fixes it. BMRT's `truedisplacement` without a bound gets one
/// estimated by displacing test grids: no warning and no crack. With neither (as BMRT-era
/// scenes are written) the primitive is bump mapped, with a warning naming the shader and the
/// attribute that would move it.
#[test]
fn displacement_past_its_bound_is_reported() {
    let dir = common::scratch_dir("fallbacks_dispbound");
    let out = dir.join("out.png").display().to_string();
    let shader = "displacement bumpy(float amp = 0.5) { \
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
    let too_small = "Attribute \"displacementbound\" \"sphere\" [0.001]\n";
    let (log, _, _) = render(&dir, &scene(too_small), Some(("bumpy", shader)));
    assert!(
        log.contains("render::displacementbound") && log.contains("`bumpy`"),
        "{log}"
    );
    for bound in [
        "Attribute \"displacementbound\" \"sphere\" [0.2]\n",
        "Attribute \"render\" \"truedisplacement\" [1]\n",
        "",
    ] {
        let (log, px, _) = render(&dir, &scene(bound), None);
        assert!(!log.contains("render::displacementbound"), "{bound}: {log}");
        assert_eq!(
            log.contains("shade::displacement"),
            bound.is_empty(),
            "{bound}: {log}"
        );
        // Every pixel is covered by the (white, constant) plane: no cracks.
        assert!(
            px.iter().all(|&v| v == 255),
            "{bound}: a crack: {}",
            px.iter().filter(|&&v| v < 255).count()
        );
    }
}

/// A value for a parameter the named shader does not have (the scene was written for another
/// shader of the same name) is ignored with a warning naming both; the parameters the shader
/// has still apply.
#[test]
fn a_parameter_the_shader_lacks_is_named_in_a_warning() {
    let dir = common::scratch_dir("fallbacks_unknown_param");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         Surface \"tint\" \"float Kd\" [0.5] \"float density\" [3]\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let shader = "surface tint(float Kd = 1) { Oi = 1; Ci = Kd; }";
    let (log, px, _) = render(&dir, &rib, Some(("tint", shader)));
    assert!(
        log.contains("shader `tint` has no parameter `density`"),
        "{log}"
    );
    assert!(!log.contains("parameter `Kd`"), "{log}");
    // Kd = 0.5 still applies: 128 in 8 bits.
    assert!(
        px.iter().all(|&v| (127..=129).contains(&v)),
        "{:?}",
        &px[..4]
    );
}

#[test]
fn a_map_named_with_other_letter_case_is_found() {
    // A scene written on a case-insensitive file system names `MixedCase.tx` for the picture
    // `mixedcase.tiff` beside it.
    let dir = common::scratch_dir("fallbacks_texture_case");
    grey_picture(&dir.join("mixedcase.tiff"), 96);
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         Surface \"casemap\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let shader = "surface casemap() { Oi = 1; Ci = float texture(\"MixedCase.tx\"); }";
    let (log, px, _) = render(&dir, &rib, Some(("casemap", shader)));
    assert!(log.contains("mixedcase.tiff"), "{log}");
    assert!(px.iter().all(|&v| (95..=97).contains(&v)), "{:?}", &px[..8]);
}

/// A missing light shader is stood in for by the standard light its instance points to: here
/// a cone (`coneangle`) makes it `spotlight`, so the plane is lit exactly as by `spotlight`
/// itself. Left out (as Aqsis and Pixie leave it) the frame would be black.
#[test]
fn a_missing_light_shader_is_stood_in_for_by_the_light_it_resembles() {
    let dir = common::scratch_dir("fallbacks_light");
    let out = dir.join("out.png").display().to_string();
    let scene = |light: &str| {
        format!(
            "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
             LightSource \"{light}\" 1 \"from\" [0 0 -4] \"to\" [0 0 0] \"intensity\" 16 \
             \"coneangle\" 0.1 \"conedeltaangle\" 0.01\n\
             Surface \"matte\"\n\
             Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
        )
    };
    let (log, px, w) = render(&dir, &scene("studioKeyLight"), None);
    assert!(
        log.contains("light `studioKeyLight` is not available"),
        "{log}"
    );
    assert!(log.contains("`spotlight` stands in"), "{log}");
    let centre = px[(w / 2) * w + w / 2];
    assert!(centre > 200, "centre {centre}");
    assert_eq!(px[0], 0);
    // The same picture as the standard spotlight given the same values.
    let (_, reference, _) = render(&dir, &scene("spotlight"), None);
    assert_eq!(px, reference);
}

/// A missing light whose name and parameters hint at nothing stays out, with the warning
/// that names it; one whose name says ambient becomes `ambientlight`.
#[test]
fn a_missing_light_nothing_hints_at_stays_out() {
    let dir = common::scratch_dir("fallbacks_light_out");
    let out = dir.join("out.png").display().to_string();
    let scene = |light: &str| {
        format!(
            "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
             LightSource \"{light}\" 1 \"intensity\" 0.5\n\
             Surface \"matte\"\n\
             Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
        )
    };
    let (log, px, w) = render(&dir, &scene("mysteryglow"), None);
    assert!(log.contains("`mysteryglow` not found"), "{log}");
    assert!(!log.contains("stands in"), "{log}");
    assert_eq!(px[(w / 2) * w + w / 2], 0);
    let (log, px, w) = render(&dir, &scene("myAmbientFill"), None);
    assert!(log.contains("`ambientlight` stands in"), "{log}");
    // matte under an ambient light of 0.5: Ka·0.5 = 0.5 → grey 128 (±1 for rounding).
    let centre = px[(w / 2) * w + w / 2];
    assert!((126..=129).contains(&centre), "centre {centre}");
}

/// A missing light whose instance gives Maya's `decay` exponent (Liquid's `liquidpoint`)
/// keeps it: decay 0 is no falloff, so a plane 10 away is lit at the full intensity, where
/// `pointlight`'s squared falloff would leave it black.
#[test]
fn a_missing_maya_light_keeps_its_decay() {
    let dir = common::scratch_dir("fallbacks_light_decay");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         LightSource \"liquidpoint\" 1 \"intensity\" 0.5 \"float decay\" 0 \
         \"from\" [0 0 -10]\n\
         Surface \"matte\" \"Ka\" 0\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, px, w) = render(&dir, &rib, None);
    assert!(log.contains("`pointlight_decay` stands in"), "{log}");
    // Kd · intensity · N·L = 1 · 0.5 · 1 at the centre: grey 128 (±1 for rounding).
    let centre = px[(w / 2) * w + w / 2];
    assert!((126..=129).contains(&centre), "centre {centre}");
}

/// A missing light whose instance names a picture shaping its beam (a blocker, slide or
/// gobo map) stays out: a plain spotlight would light what the map darkens.
#[test]
fn a_missing_light_shaped_by_a_map_stays_out() {
    let dir = common::scratch_dir("fallbacks_light_map");
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         LightSource \"blockerspotlight\" 1 \"from\" [0 0 -4] \"to\" [0 0 0] \"intensity\" 16 \
         \"coneangle\" 0.1 \"string shadowname\" [\"\"] \"string blockername\" \"star.tx\"\n\
         Surface \"matte\"\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, px, w) = render(&dir, &rib, None);
    assert!(log.contains("`blockerspotlight` not found"), "{log}");
    assert!(!log.contains("stands in"), "{log}");
    assert_eq!(px[(w / 2) * w + w / 2], 0);
}

#[test]
fn a_shader_is_found_by_its_declared_name_in_a_shorter_file() {
    // The RMR ships SIG2k_srf_contact as `SIG2k_srfconta.sl` (a file name cut short); PRMan
    // names the compiled shader after its declaration, so a RIB asks for the long name.
    let dir = common::scratch_dir("fallbacks_declared_name");
    std::fs::write(
        dir.join("decoy.sl"),
        "/* surface long_grey_surface( is only mentioned here */\n\
         surface long_grey_surfaceX() { Ci = 1; Oi = 1; }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("long_gre.sl"),
        "surface\n  long_grey_surface ( float g = 0.25; )\n{ Ci = g; Oi = 1; }\n",
    )
    .unwrap();
    let out = dir.join("out.png").display().to_string();
    let rib = format!(
        "Display \"{out}\" \"png\" \"rgb\"\n{CAMERA}WorldBegin\n\
         Surface \"long_grey_surface\" \"float g\" [0.5]\n\
         Polygon \"P\" [-2 -2 0  2 -2 0  2 2 0  -2 2 0]\nWorldEnd\n"
    );
    let (log, px, _) = render(&dir, &rib, None);
    assert!(!log.contains("shade::missing"), "{log}");
    assert!(!log.contains("stand-in"), "{log}");
    // g = 0.5 from the instance (dithered ±1): the file's shader ran, not the decoy's white
    // nor a stand-in.
    assert!(px.iter().all(|&v| v.abs_diff(128) <= 1), "{px:?}");
}
