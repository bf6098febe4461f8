//! Scenes and shaders written for other renderers: renderer-specific options and attributes,
//! PRMan requests arbor does not implement, geometry-only archives, 8-bit source files, the
//! book headers in the standard library, and PRMan-era uniform/varying leniency. Each test is
//! a small input of our own showing one class of behaviour.

mod common;

use std::path::PathBuf;

use arbor::diag::{Diagnostics, Severity, SourceMap};
use arbor::rib::parse_bytes;
use arbor::scene::{build_scenes, BuildContext, Scene};
use arbor::sl::{compile_source, CompileOptions};

struct Built {
    scenes: Vec<Scene>,
    diags: Diagnostics,
    sources: SourceMap,
}

impl Built {
    fn of(&self, sev: Severity) -> Vec<String> {
        self.diags
            .snapshot()
            .into_iter()
            .filter(|(d, _)| d.severity == sev)
            .map(|(d, _)| d.to_line(&self.sources))
            .collect()
    }
}

fn build_bytes(bytes: &[u8]) -> Built {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = parse_bytes("scene.rib", bytes, &sources, &diags);
    let scenes = {
        let ctx = BuildContext::new(&sources, &diags);
        build_scenes(reqs, &ctx)
    };
    Built {
        scenes,
        diags,
        sources,
    }
}

fn build(text: &str) -> Built {
    build_bytes(text.as_bytes())
}

const RENDERER_SETTINGS: &str = r#"
Option "limits" "zthreshold" [0.5 0.5 0.5]
Option "radiosity" "steps" [40] "minpatchsamples" [2]
Option "render" "prmanspecular" [1]
Option "searchpath" "resource" [".:@"]
Option "shadow" "bias0" [0.1] "bias1" [0.3]
Option "statistics" "endofframe" [1]
Option "shutter" "float offset" [0.03]
Format 16 16 1
WorldBegin
Attribute "light" "shadows" "on" "nsamples" [4]
LightSource "pointlight" 1
AttributeBegin
Attribute "identifier" "name" ["ball"] "shadinggroup" ["ballSG"]
Attribute "render" "casts_shadows" "opaque" "truedisplacement" [1]
Attribute "render" "string casts_shadows" ["Os"]
Attribute "radiosity" "averagecolor" [.5 .5 .5] "patchsize" [4] "zonal" "zonal_receives"
Attribute "visibility" "camera" [1] "trace" [0] "transmission" "opaque" "photon" [0]
Attribute "trace" "bias" [0.01] "maxdiffusedepth" [2]
Attribute "displacementbound" "sphere" [0.5] "coordinatesystem" ["shader"]
Attribute "dice" "binary" [1] "rasterorient" [0]
Attribute "sides" "doubleshaded" [0]
Attribute "cull" "hidden" [0] "backfacing" [0]
Attribute "stitch" "enable" [1]
Sphere 1 -1 1 360
AttributeEnd
WorldEnd
"#;

#[test]
fn known_renderer_settings_are_typed_and_quiet() {
    let b = build(RENDERER_SETTINGS);
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    assert!(
        b.of(Severity::Warning).is_empty(),
        "{:#?}",
        b.of(Severity::Warning)
    );
    // The ignored ones are notes (shown at -v), naming the setting.
    let notes = b.of(Severity::Note);
    // (render:casts_shadows, light:shadows and visibility:trace are used by ray tracing;
    // radiosity:steps turns on the traced bounce, trace:maxdiffusedepth limits it.)
    for key in [
        "\"radiosity\" \"minpatchsamples\"",
        "\"identifier\" \"shadinggroup\"",
    ] {
        assert!(notes.iter().any(|n| n.contains(key)), "{key}: {notes:#?}");
    }
    // What arbor uses is not noted, and is applied.
    assert!(!notes.iter().any(|n| n.contains("\"radiosity\" \"steps\"")));
    assert!(!notes.iter().any(|n| n.contains("\"maxdiffusedepth\"")));
    assert!(!notes.iter().any(|n| n.contains("\"identifier\" \"name\"")));
    assert!(!notes.iter().any(|n| n.contains("\"dice\" \"binary\"")));
    let s = &b.scenes[0];
    let a = &s.primitives[0].attributes;
    assert_eq!(a.identifier.as_deref(), Some("ball"));
    assert_eq!(a.displacement_bound, 0.5);
    assert_eq!(a.displacement_bound_space, "shader");
    // Types come from the table: nsamples is an integer, averagecolor a colour.
    let ns = &s.primitives[0].attributes.user["radiosity:averagecolor"];
    assert_eq!(ns.data.floats(), &[0.5, 0.5, 0.5]);
    assert_eq!(
        s.options.user["limits:zthreshold"].data.floats(),
        &[0.5, 0.5, 0.5]
    );
    assert_eq!(s.options.user["shadow:bias0"].data.floats(), &[0.1]);
}

#[test]
fn a_token_nobody_declares_still_warns() {
    let b = build(
        "Format 8 8 1\nWorldBegin\nAttribute \"render\" \"frobnicate\" [1]\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    let w = b.of(Severity::Warning);
    assert_eq!(w.len(), 1, "{w:#?}");
    assert!(w[0].contains("\"frobnicate\" is not declared"), "{}", w[0]);
}

#[test]
fn prman_requests_arbor_lacks_warn_by_name() {
    let b = build(
        "Format 8 8 1\nWorldBegin\nGeometricRepresentation \"lines\"\nGeometricApproximation \"flatness\" 0.5\nSystem \"echo hi\"\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    let w = b.of(Severity::Warning);
    for name in [
        "`GeometricRepresentation`",
        "`GeometricApproximation \"flatness\"`",
        "`System`",
    ] {
        assert!(w.iter().any(|m| m.contains(name)), "{name}: {w:#?}");
    }
    assert_eq!(b.scenes[0].primitives.len(), 1);
}

#[test]
fn resource_saves_and_restores_the_attribute_state() {
    // PRMan's `Resource "name" "attributes"`: a look saved inside one block is put back on
    // a later object outside it, whatever the attribute stack did in between; the
    // transform stays where the restoring object is. A name saved inside
    // `ResourceBegin`/`ResourceEnd` is forgotten at its end.
    let b = build(
        "Format 8 8 1\nWorldBegin\n\
         AttributeBegin\nColor [1 0 0]\nSurface \"plastic\" \"Ks\" [0.9]\n\
         Resource \"redlook\" \"attributes\" \"string operation\" \"save\"\nAttributeEnd\n\
         Color [0 0 1]\nSurface \"matte\"\nSphere 1 -1 1 360\n\
         AttributeBegin\nTranslate 3 0 0\n\
         Resource \"redlook\" \"attributes\" \"string operation\" \"restore\"\nSphere 1 -1 1 360\nAttributeEnd\n\
         ResourceBegin\nResource \"inner\" \"attributes\" \"string operation\" \"save\"\nResourceEnd\n\
         Resource \"inner\" \"attributes\" \"string operation\" \"restore\"\n\
         Sphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    let w = b.of(Severity::Warning);
    assert!(!w.iter().any(|m| m.contains("not implemented")), "{w:#?}");
    // Restoring a name saved only inside a closed ResourceBegin block warns.
    assert!(w.iter().any(|m| m.contains("\"inner\"")), "{w:#?}");
    let prims = &b.scenes[0].primitives;
    assert_eq!(prims.len(), 3);
    let look = |i: usize| {
        let a = &prims[i].attributes;
        (a.color, a.surface.as_ref().map(|s| s.name.clone()))
    };
    assert_eq!(
        look(0),
        (glam::Vec3::new(0.0, 0.0, 1.0), Some("matte".into()))
    );
    assert_eq!(
        look(1),
        (glam::Vec3::new(1.0, 0.0, 0.0), Some("plastic".into()))
    );
    assert_eq!(look(2), look(0));
    // The restored sphere stays where its own block put it.
    let x = prims[1].world_from_object.w_axis.x;
    assert!((x - 3.0).abs() < 1e-6, "{x}");
}

#[test]
fn a_geometry_only_file_is_one_archive_warning() {
    let b = build(
        "AttributeBegin\nPatch \"bilinear\" \"P\" [0 0 0 1 0 0 0 1 0 1 1 0]\nPatch \"bilinear\" \"P\" [0 0 1 1 0 1 0 1 1 1 1 1]\nSphere 1 -1 1 360\nAttributeEnd\n",
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    let w = b.of(Severity::Warning);
    assert_eq!(w.len(), 1, "{w:#?}");
    assert!(
        w[0].contains("archive-only") && w[0].contains("3 requests"),
        "{}",
        w[0]
    );
    assert!(b.scenes.is_empty());
}

#[test]
fn geometry_before_a_world_in_a_real_scene_is_still_an_error() {
    let b = build("Sphere 1 -1 1 360\nFormat 8 8 1\nWorldBegin\nSphere 1 -1 1 360\nWorldEnd\n");
    let e = b.of(Severity::Error);
    assert_eq!(e.len(), 1, "{e:#?}");
    assert!(e[0].contains("outside `WorldBegin`"), "{}", e[0]);
    assert_eq!(b.scenes.len(), 1);
}

#[test]
fn latin1_rib_names_and_comments_decode() {
    let b = build_bytes(
        b"# sc\xe8ne d'\xe9t\xe9\nFormat 8 8 1\nWorldBegin\nAttribute \"identifier\" \"name\" [\"th\xe9i\xe8re\"]\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    assert_eq!(
        b.scenes[0].primitives[0].attributes.identifier.as_deref(),
        Some("th\u{e9}i\u{e8}re")
    );
}

#[test]
fn latin1_shaders_and_headers_compile() {
    let d = common::scratch_dir("compat_latin1");
    std::fs::write(
        d.join("accents.h"),
        b"/* fonctions utilis\xe9es */\nfloat demi(float x) { return x / 2; }\n",
    )
    .unwrap();
    std::fs::write(
        d.join("ete.sl"),
        b"/* \xe9t\xe9, \xb0C */\n#include \"accents.h\"\nsurface ete(float Kd = 1;) { Ci = demi(Kd) * Cs; }\n",
    )
    .unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let lib = arbor::sl::ShaderLibrary::new(CompileOptions {
        search_paths: vec![d.clone()],
        ..Default::default()
    });
    let p = lib.get("ete", &sources, &diags);
    assert!(p.is_some(), "{}", diags.render_plain(&sources));
    assert!(!diags.has_errors());
    let _ = std::fs::remove_dir_all(&d);
}

fn compile(name: &str, text: &str) -> (usize, String, bool) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let progs = compile_source(
        name,
        text,
        None,
        &sources,
        &diags,
        &CompileOptions::default(),
    );
    (
        progs.len(),
        diags.render_plain(&sources),
        diags.has_errors(),
    )
}

#[test]
fn rmannotes_helpers_are_in_the_standard_library() {
    let src = r#"
#include "rmannotes.h"
surface tiles(float freq = 4, fuzz = 0.02;)
{
    float ss = repeat(s, freq), tt = repeat(t, freq);
    float col = whichtile(s, freq), row = whichtile(t, freq);
    float inside = intersection(pulse(0.1, 0.9, fuzz, ss), pulse(0.1, 0.9, fuzz, tt));
    float grout = complement(inside);
    float lines = union(filteredpulse(0.45, 0.55, ss, 0.01), difference(grout, 0.5));
    float rs, rt, r, theta;
    rotate2d(ss, tt, radians(45), 0.5, 0.5, rs, rt);
    topolar2d(rs - 0.5, rt - 0.5, r, theta);
    color c = blend(color(1, 0, 0), color(0, 0, 1), inside);
    if (odd(col + row)) c = blend(c, color 1, 0.5);
    if (even(col)) c *= boxstep(0, 0.5, r);
    Ci = c * (1 - lines) + theta * 0;
}
"#;
    let (n, log, err) = compile("tiles.sl", src);
    assert!(!err && n == 1, "{log}");
    let (n, log, err) = compile(
        "t2.sl",
        "#include \"rmannotes.sl\"\nsurface t2() { Ci = blend(0, 1, repeat(s, 2)); }\n",
    );
    assert!(!err && n == 1, "{log}");
}

#[test]
fn material_functions_are_in_the_standard_library() {
    let src = r#"
#include "material.h"
surface mats(float Ka = 1, Kd = 0.5, Ks = 0.5, Kr = 0.2, roughness = 0.1;
             DECLARE_DEFAULTED_ENVPARAMS;)
{
    normal Nf = faceforward(normalize(N), I);
    color c = MaterialPlastic(Nf, Cs, Ka, Kd, Ks, roughness)
            + MaterialMatte(Nf, Cs, Ka, Kd)
            + MaterialRoughMetal(Nf, Cs, Ka, Kd, Ks, roughness)
            + MaterialClay(Nf, Cs, Ka, Kd, 0.3)
            + MaterialShinyMetal(Nf, Cs, Ka, Kd, Ks, roughness, Kr, 0, 0, ENVPARAMS);
    Oi = Os;
    Ci = Oi * c;
}
"#;
    let (n, log, err) = compile("mats.sl", src);
    assert!(!err && n == 1, "{log}");
}

#[test]
fn uniform_function_returning_varying_is_demoted() {
    // A uniform counter advanced by a uniform function called inside illuminance (as
    // lens-flare shaders do): PRMan accepts it; arbor demotes it with warnings.
    let src = r#"
surface flare(float seed = 7;)
{
    uniform float n = 0;
    uniform float next() {
        extern uniform float n, seed;
        n += 1;
        return cellnoise(n, seed);
    }
    color c = 0;
    illuminance (P) {
        n = 0;
        uniform float r = next();
        c += Cl * r;
    }
    Ci = c;
}
"#;
    let (n, log, err) = compile("flare.sl", src);
    assert!(!err && n == 1, "{log}");
    assert!(log.contains("declared to return a uniform value"), "{log}");
}

#[test]
fn option_shadow_bias_is_the_default_bias_of_shadow() {
    let dir = common::scratch_dir("compat_bias");
    // A light whose shadow() call names no bias: the scene's Option "shadow" decides.
    std::fs::write(
        dir.join("nobiaslight.sl"),
        "light nobiaslight(string shadowname = \"\";) {\n\
         solar(vector \"world\" (0, -1, 0), 0) { Cl = 1 - shadow(shadowname, Ps); } }\n",
    )
    .unwrap();
    let (z, tex) = (dir.join("l.z"), dir.join("l.tex"));
    let cam = "Projection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
               ConcatTransform [1 0 0 0  0 0 -1 0  0 1 0 0  0 0 0 1]\nTranslate 0 -10 0\n";
    let floor = "Polygon \"P\" [-2 0 -2  2 0 -2  2 0 2  -2 0 2]";
    let beauty = |n: u32, opt: &str, png: &PathBuf| {
        format!(
            "FrameBegin {n}\nDisplay \"{}\" \"png\" \"rgb\"\nFormat 8 8 1\n{opt}\n{cam}WorldBegin\n\
             LightSource \"nobiaslight\" 1 \"shadowname\" [\"{}\"]\nSurface \"matte\"\n{floor}\nWorldEnd\nFrameEnd\n",
            png.display(),
            tex.display()
        )
    };
    let (far, near) = (dir.join("far.png"), dir.join("near.png"));
    // The occluder is 1 unit above the floor: a bias of 3 lifts the shadow off the floor,
    // a bias of 0.05 keeps it.
    let rib = format!(
        "FrameBegin 1\nDisplay \"{}\" \"zfile\" \"z\"\nFormat 32 32 1\nPixelSamples 1 1\n{cam}\
         WorldBegin\nPolygon \"P\" [-1 1 -1  1 1 -1  1 1 1  -1 1 1]\n{floor}\nWorldEnd\nFrameEnd\n\
         MakeShadow \"{}\" \"{}\"\n{}{}",
        z.display(),
        z.display(),
        tex.display(),
        beauty(2, "Option \"shadow\" \"bias\" [3]", &far),
        beauty(
            3,
            "Option \"shadow\" \"bias0\" [0.04] \"bias1\" [0.06]",
            &near
        ),
    );
    let (log, failed) = common::render_scene_file(&dir, &rib);
    assert!(!failed, "{log}");
    let centre = |p: &PathBuf| image::open(p).unwrap().to_rgb8().get_pixel(4, 4)[0];
    assert!(centre(&far) > 200, "bias 3: {}", centre(&far));
    assert!(centre(&near) < 60, "bias 0.05: {}", centre(&near));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn prman3_bound_displacement_sets_the_displacement_bound_quietly() {
    // PRMan 3's spelling, used by the RenderMan Companion's scenes.
    let b = build(
        "Format 8 8 1\nWorldBegin\nAttribute \"bound\" \"displacement\" 0.1\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(
        b.of(Severity::Warning).is_empty(),
        "{:#?}",
        b.of(Severity::Warning)
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    let a = &b.scenes[0].primitives[0].attributes;
    assert_eq!(a.displacement_bound, 0.1);
    assert_eq!(a.displacement_bound_space, "object");
}

#[test]
fn rsl2_classes_and_slim_palettes_get_one_diagnostic_each() {
    let (n, text, err) = compile(
        "spot.sl",
        "class myspot(float intensity = 1;)\n{\n  public void begin() { }\n  public void light(output vector L; output color Cl) { Cl = intensity; }\n}\n",
    );
    assert!(err && n == 0);
    assert_eq!(text.matches('×').count(), 1, "{text}");
    assert!(text.contains("RenderMan Shading Language 2.0"), "{text}");
    // A class that is only its `light` method is that light shader (sl_compat tests it).
    let (n, text, err) = compile(
        "lone.sl",
        "class myspot(float intensity = 1;)\n{\n  public void light(output vector L; output color Cl) { illuminate(point(0, 0, 0)) { Cl = intensity; } }\n}\n",
    );
    assert!(!err && n == 1, "{text}");
    let (n, text, err) = compile(
        "pal.sl",
        "slim 1 appearance slim {\n instance surface \"x\" \"x.slo\" {\n  description {don't}\n }\n}\n",
    );
    assert!(err && n == 0);
    assert_eq!(text.matches('×').count(), 1, "{text}");
    assert!(text.contains("Slim appearance file"), "{text}");
}

#[test]
fn an_unknown_function_is_a_dso_shadeop_that_warns_and_returns_zero() {
    // Aqsis's sci_volumes example: `float sample_vol(samplePos)` calls a DSO shadeop. The
    // shader compiles, with one warning naming it; the call yields 0.
    let (n, text, err) = compile(
        "d.sl",
        "surface d() { float x = float sample_vol(P); color c = frobnicatebox(P); Ci = x + c; }",
    );
    assert!(!err && n == 1, "{text}");
    assert_eq!(text.matches("DSO shadeop").count(), 2, "{text}");
    assert!(
        text.contains("`sample_vol`") && text.contains("returns 0"),
        "{text}"
    );
    assert!(text.contains("returns (0, 0, 0)"), "{text}");
    // A near miss of a known name is still a typo, and an error.
    let (_, text, err) = compile("t.sl", "surface t() { Ci = nosie(P); }");
    assert!(err, "{text}");
    assert!(text.contains("did you mean `noise`?"), "{text}");
}

#[test]
fn shader_and_archive_names_that_differ_in_case_are_found() {
    // Scenes written on case-insensitive file systems (NeXT, Mac OS, Windows) name
    // `Surface "MyOrange"` for `myorange.sl`, and `ReadArchive "Quad.RIB"` for `quad.rib`.
    let dir = common::scratch_dir("name-case");
    std::fs::write(
        dir.join("myorange.sl"),
        "surface myorange() { Oi = 1; Ci = color(1, 0.5, 0); }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("quad.rib"),
        "Polygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\n",
    )
    .unwrap();
    let out = dir.join("case.tif");
    let _ = std::fs::remove_file(&out);
    let rib = format!(
        "Format 8 8 1\nPixelSamples 1 1\nDisplay \"{}\" \"file\" \"rgb\"\n\
         Projection \"perspective\" \"fov\" 40\nWorldBegin\nSurface \"MyOrange\"\n\
         ReadArchive \"Quad.RIB\"\nWorldEnd\n",
        out.display()
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err, "{text}");
    assert!(text.contains("differ only in letter case"), "{text}");
    assert!(!text.contains("not found"), "{text}");
    let img = image::open(&out).unwrap().to_rgb8();
    let p = img.get_pixel(4, 4);
    assert!(
        p[0] > 250 && (120..=136).contains(&p[1]) && p[2] < 5,
        "{p:?}"
    );
}

/// Renders `shader_src` (saved as `name.sl`) on a full-frame square lit by the given lights;
/// the colour at the centre.
fn centre_colour(name: &str, shader_src: &str, lights: &str) -> [f32; 3] {
    let dir = common::scratch_dir(name);
    std::fs::write(dir.join(format!("{name}.sl")), shader_src).unwrap();
    let rib = format!(
        "Format 8 8 1\nPixelSamples 1 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n{lights}\n\
         Surface \"{name}\"\nPolygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n"
    );
    let film = common::render_rib(&rib, &[dir]);
    let rgb = common::film_rgb(&film);
    let k = (4 * film.width + 4) * 3;
    [rgb[k], rgb[k + 1], rgb[k + 2]]
}

#[test]
fn cl_scaled_inside_illuminance_holds_for_that_light_only() {
    // Pixar's Slim templates do `Cl *= 1 - nonspec` in surface shaders (PRMan allows it).
    let c = centre_colour(
        "halfcl",
        "surface halfcl() { color c = 0; illuminance(P, N, PI) { Cl *= 0.5; c += Cl; } Oi = 1; Ci = c; }",
        "LightSource \"distantlight\" 1 \"intensity\" 1 \"from\" [0 0 0] \"to\" [0 0 1]\n\
         LightSource \"distantlight\" 2 \"intensity\" 0.5 \"from\" [0 0 0] \"to\" [0 0 1]",
    );
    // 0.5 * 1 + 0.5 * 0.5: each light's Cl is scaled once, not twice.
    for ch in c {
        assert!((ch - 0.75).abs() < 1e-4, "{c:?}");
    }
}

#[test]
fn slim_headers_are_in_the_standard_library() {
    let src = r#"
#define SLIM_TYPEID_surface 0
#define SLIM_TYPEID_displacement 1
#define SLIM_SHADERTYPEID SLIM_TYPEID_surface
#include "pxslRayUtil.h"
#include "pxslUtil.h"
surface slimmy()
{
    normal Ns = pxslUtilShadingNormal(N);
    vector v1, v2, v3, v4;
    pxslBuildEnvironmentVectors(pxslCalculateEnvSampleArea(PI, 4), vector(0, 0, 1), v1, v2, v3, v4);
    uniform float ns, ms;
    pxslShapeSamples("rectangle", pxslGetRaySamples(16), 1, 1, ns, ms);
    point q = pxslPointOnShape("disk", 1, 1, 0, ns, 0, ms);
    color n = pxslFilteredCNoise(P, dPdu * du, dPdv * dv) + pxslFilteredFNoise(P, dPdu, dPdv)
        + color pxslFilteredVNoise(P, dPdu, dPdv) + pxslVaryColor(color(0.5), 0.1, 3);
    vector e = pxslEnvDirCorrect("XtoY", vector(1, 0, 0));
    Oi = 1;
    Ci = pxslBimix(color(1, 0, 0), color(0, 1, 0), color(0, 0, 1), color(1, 1, 1), 0.25, 0.5)
        * pxslLuminance(color(1)) + 0 * (n + Ns + v1 + v4 + q + e) + pxslCmix(0, 0, 0.5);
}
"#;
    let (n, log, err) = compile("slimmy.sl", src);
    assert!(!err && n == 1, "{log}");
    // mix(mix(c2, c0, 0.5), mix(c3, c1, 0.5), 0.25) with c0..c3 red, green, blue, white.
    let c = centre_colour("slimmy", src, "");
    let want = [0.5, 0.25, 0.5];
    for (got, want) in c.iter().zip(want) {
        assert!((got - want).abs() < 1e-4, "{c:?}");
    }
}

#[test]
fn eye_space_is_camera_space() {
    // The RenderMan Companion's slideprojector light: `up = point "eye" (0,1,0)`.
    let dir = common::scratch_dir("eyespace");
    std::fs::write(
        dir.join("eyecheck.sl"),
        "surface eyecheck() { point a = transform(\"eye\", P); point b = transform(\"camera\", P);\n\
         Oi = 1; Ci = (distance(a, b) < 1e-5) ? color(0, 1, 0) : color(1, 0, 0); }\n",
    )
    .unwrap();
    let rib = "Format 8 8 1\nPixelSamples 1 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n\
               Translate 0.3 0 0\nSurface \"eyecheck\"\nPolygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n";
    let (film, diags, sources) = common::render_rib_with(rib, &[dir], &Default::default());
    let text: Vec<String> = diags.iter().map(|(d, _)| d.to_line(&sources)).collect();
    assert!(
        !text.iter().any(|t| t.contains("coordinate system")),
        "{text:#?}"
    );
    assert_eq!(common::film_mean(&film)[1], 1.0);
}

/// The value of a one-number TIFF tag (read with the `tiff` crate arbor writes with).
fn tiff_short_tag(bytes: &[u8], want: u16) -> Option<u16> {
    let mut d = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).ok()?;
    let v = d
        .find_tag(tiff::tags::Tag::from_u16_exhaustive(want))
        .ok()??;
    v.into_u16().ok()
}

#[test]
fn rgba_tiff_declares_its_premultiplied_alpha() {
    // A see-through surface (BMRT's screen shaders: `Oi = d; Ci = Oi * ...`) leaves colour
    // premultiplied by alpha, as RISpec has it. PRMan, BMRT and Aqsis mark such TIFFs
    // ExtraSamples = 1 (associated alpha); without the tag, readers take straight alpha and
    // show a half-covered pixel at a quarter of its brightness.
    let dir = common::scratch_dir("tiff-alpha");
    std::fs::write(
        dir.join("halfwhite.sl"),
        "surface halfwhite() { Oi = 0.5; Ci = Oi * color(1, 1, 1); }\n",
    )
    .unwrap();
    let (rgba, rgb) = (dir.join("rgba.tif"), dir.join("rgb.tif"));
    for (out, mode) in [(&rgba, "rgba"), (&rgb, "rgb")] {
        let _ = std::fs::remove_file(out);
        let rib = format!(
            "Format 8 8 1\nPixelSamples 1 1\nDisplay \"{}\" \"file\" \"{mode}\"\n\
             Projection \"perspective\" \"fov\" 40\nWorldBegin\nSurface \"halfwhite\"\n\
             Polygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n",
            out.display()
        );
        let (text, err) = common::render_scene_file(&dir, &rib);
        assert!(!err, "{text}");
    }
    let bytes = std::fs::read(&rgba).unwrap();
    assert_eq!(
        tiff_short_tag(&bytes, 338),
        Some(1),
        "ExtraSamples: associated alpha"
    );
    assert_eq!(tiff_short_tag(&bytes, 277), Some(4));
    let px = image::open(&rgba).unwrap().to_rgba8().get_pixel(4, 4).0;
    for v in px {
        assert!((127..=128).contains(&v), "premultiplied half white: {px:?}");
    }
    let bytes = std::fs::read(&rgb).unwrap();
    assert_eq!(tiff_short_tag(&bytes, 338), None);
    assert_eq!(tiff_short_tag(&bytes, 277), Some(3));
    assert_eq!(
        image::open(&rgb).unwrap().to_rgb8().get_pixel(4, 4).0,
        [px[0], px[1], px[2]]
    );
}

/// The mean of a white sphere of radius 0.5 whose surface shader pushes P out by 0.5 along N,
/// seen face-on through a 4×4 orthographic window; `attrs` go before the sphere.
fn swollen_sphere_coverage(attrs: &str) -> f64 {
    let dir = common::scratch_dir("swell");
    std::fs::write(
        dir.join("swell.sl"),
        "surface swell() { P += 0.5 * normalize(N); N = calculatenormal(P); Oi = 1; Ci = 1; }",
    )
    .unwrap();
    let rib = format!(
        "Format 64 64 1\nPixelSamples 4 4\nProjection \"orthographic\"\nScreenWindow -2 2 -2 2\n\
         Translate 0 0 5\nWorldBegin\n{attrs}\nSurface \"swell\"\nSphere 0.5 -0.5 0.5 360\nWorldEnd\n"
    );
    common::film_mean(&common::render_rib(&rib, &[dir]))[0]
}

#[test]
fn a_surface_shader_that_moves_p_moves_what_the_camera_sees_within_a_declared_bound() {
    // PRMan and Aqsis hide micropolygons where the surface shader left P (fur, craters): a
    // disk of radius 1 in a 4×4 window covers π/16 of it.
    let moved = swollen_sphere_coverage("Attribute \"displacementbound\" \"sphere\" [0.6]");
    assert!(
        (moved - std::f64::consts::PI / 16.0).abs() < 0.01,
        "{moved}"
    );
    // Without a bound (BMRT-era scenes) the points stay: radius 0.5, π/64 of the window.
    let kept = swollen_sphere_coverage("");
    assert!((kept - std::f64::consts::PI / 64.0).abs() < 0.005, "{kept}");
    // So does BMRT's truedisplacement 0, bound or not.
    let bmrt = swollen_sphere_coverage(
        "Attribute \"displacementbound\" \"sphere\" [0.6]\n\
         Attribute \"render\" \"truedisplacement\" [0]",
    );
    assert!((bmrt - std::f64::consts::PI / 64.0).abs() < 0.005, "{bmrt}");
}

#[test]
fn a_shader_renamed_with_its_authors_initials_is_found_by_its_old_name() {
    // The RenderMan Repository renamed bubbly.sl to IDbubbly.sl, and its scene still says
    // `Displacement "bubbly"`.
    let dir = common::scratch_dir("initials");
    std::fs::write(
        dir.join("QXgreen.sl"),
        "surface QXgreen() { Oi = 1; Ci = color(0, 1, 0); }",
    )
    .unwrap();
    let rib = "Format 8 8 1\nPixelSamples 1 1\nProjection \"perspective\" \"fov\" 40\nWorldBegin\n\
               Surface \"green\"\nPolygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n";
    let (film, diags, _) = common::render_rib_with(
        rib,
        &[dir],
        &arbor::render::driver::RenderOptions::default(),
    );
    let rgb = common::film_rgb(&film);
    let k = (4 * film.width + 4) * 3;
    assert_eq!([rgb[k], rgb[k + 1], rgb[k + 2]], [0.0, 1.0, 0.0]);
    assert!(
        diags.iter().any(|(d, _)| d.code == "shade::renamed"),
        "{:?}",
        diags.iter().map(|(d, _)| d.code).collect::<Vec<_>>()
    );
}

#[test]
fn aqsis_automatic_shadows_cast_traced_shadows_quietly() {
    // Aqsis 1.0's `Option "render" "auto_shadows"` with `Attribute "light" "shadows" "on"`,
    // and Aqsis 1.6's `Attribute "autoshadows" "shadowmapname"`: both lights cast shadows
    // (traced: arbor renders no map), and none of the settings warns as undeclared.
    let b = build(
        r#"Option "render" "auto_shadows" ["on"]
WorldBegin
Attribute "render" "shadow_shadingrate" [4]
AttributeBegin
Attribute "light" "shadows" ["on"] "shadowmapsize" [256 256] "shadowangle" [57.3] "shadowmapname" ["key.map"]
LightSource "shadowspot" 1 "string shadowname" ["key.map"]
AttributeEnd
AttributeBegin
Attribute "autoshadows" "string shadowmapname" ["autoshadow.map"] "integer res" [300]
LightSource "shadowspot" 2 "shadowname" ["autoshadow.map"]
AttributeEnd
LightSource "spotlight" 3
WorldEnd
"#,
    );
    let w = b.of(Severity::Warning);
    assert!(w.is_empty(), "{w:#?}");
    let lights = &b.scenes[0].lights;
    assert!(lights[0].ray_shadows && lights[1].ray_shadows && !lights[2].ray_shadows);
}

#[test]
fn a_shader_of_the_wrong_kind_warns_once_and_the_stand_in_renders() {
    // Aqsis's Blobby example `repel.rib` names the displacement shader `lumpy` in `Surface`.
    let dir = common::scratch_dir("wrong-kind");
    std::fs::write(
        dir.join("lumpy.sl"),
        "displacement lumpy(float a = 0.5) { P += a * noise(P) * normalize(N); N = calculatenormal(P); }\n",
    )
    .unwrap();
    let rib = format!(
        "Format 16 16 1\nDisplay \"{}\" \"file\" \"rgb\"\nProjection \"perspective\" \"fov\" 40\n\
         WorldBegin\nSurface \"lumpy\"\nPolygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n",
        dir.join("k.png").display()
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err, "{text}");
    assert_eq!(
        text.matches("is a displacement shader, used as a surface shader")
            .count(),
        1,
        "{text}"
    );
    assert!(text.contains("name it in `Displacement`"), "{text}");
}

#[test]
fn extra_array_initialisers_warn_and_are_dropped() {
    // Aqsis's regression shader `splinetst`: a colour map[4] given five colours.
    let (n, text, err) = compile(
        "splinetst.sl",
        "surface splinetst() { color map[4] = { color (1,0,0), color (1,0,0), color (1,1,0), \
         color (1,1,1), color (1,1,1) }; Ci = spline(v, map); Oi = 1; }",
    );
    assert!(!err && n == 1, "{text}");
    assert!(
        text.contains("array of 4 initialised with 5 values; the last 1 are ignored"),
        "{text}"
    );
    let (_, text, err) = compile(
        "few.sl",
        "surface few() { float a[3] = { 1, 2 }; Ci = a[0]; }",
    );
    assert!(err, "{text}");
}

#[test]
fn displacementbound_in_the_surface_shaders_space() {
    // PRMan's Blobby application note: `"coordinatesystem" "surface"` names the surface
    // shader's space; it is not an unknown space.
    let dir = common::scratch_dir("dispbound-surface");
    let rib = format!(
        "Format 16 16 1\nDisplay \"{}\" \"file\" \"rgb\"\nProjection \"perspective\" \"fov\" 40\n\
         WorldBegin\nAttribute \"displacementbound\" \"sphere\" .2 \"coordinatesystem\" \"surface\"\n\
         Surface \"matte\"\nPolygon \"P\" [-9 -9 5  9 -9 5  9 9 5  -9 9 5]\nWorldEnd\n",
        dir.join("d.png").display()
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err, "{text}");
    assert!(!text.contains("unknown coordinate system"), "{text}");
}

#[test]
fn dented_is_in_the_standard_library_and_dents_inward() {
    // Aqsis's vase scene and regression scene Bug1396028 name `Displacement "dented"`
    // without shipping it. Displaced inward, a dented sphere covers less of the frame.
    let dir = common::scratch_dir("dented");
    let coverage = |disp: &str| {
        let out = dir.join(format!("dent{}.png", disp.len()));
        let rib = format!(
            "Format 32 32 1\nDisplay \"{}\" \"file\" \"rgba\"\nProjection \"perspective\" \"fov\" 40\n\
             WorldBegin\nAttribute \"displacementbound\" \"sphere\" [0.5]\n{disp}\nSurface \"constant\"\n\
             Translate 0 0 3\nSphere 1 -1 1 360\nWorldEnd\n",
            out.display()
        );
        let (text, err) = common::render_scene_file(&dir, &rib);
        assert!(!err && !text.contains("not found"), "{text}");
        let img = image::open(&out).unwrap().to_rgba8();
        img.pixels().map(|p| p[3] as u64).sum::<u64>()
    };
    let plain = coverage("");
    let dented = coverage("Displacement \"dented\" \"Km\" [0.5]");
    assert!(dented < plain, "{dented} vs {plain}");
}

#[test]
fn the_surface_reads_the_displacement_shaders_outputs_by_message_passing() {
    // NCCA's MessagePassing example: the displacement shader leaves its bump height in an
    // output parameter and the surface colours by it (`displacement("hump", height)`).
    // Here the height is s, so the picture is a ramp across the frame; a name the
    // displacement lacks reports 0 and leaves the variable alone.
    let dir = common::scratch_dir("message-displacement");
    std::fs::write(
        dir.join("hump.sl"),
        "displacement hump(output varying float height = 0; output varying color tint = 0) \
         { height = s; tint = color(0, 1 - s, 0); }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("snow.sl"),
        "surface snow() { float h = -1; color c = 0; float none = 7; \
         float found = displacement(\"height\", h); float gone = displacement(\"nosuch\", none); \
         float col = displacement(\"tint\", c); \
         Oi = 1; Ci = color(found * h, comp(c, 1), (gone == 0 && none == 7 && col == 1) ? 1 : 0); }\n",
    )
    .unwrap();
    let out = dir.join("m.png");
    let rib = format!(
        "Format 16 4 1\nPixelSamples 1 1\nDisplay \"{}\" \"file\" \"rgb\"\nProjection \"orthographic\"\n\
         ScreenWindow -1 1 -0.25 0.25\nWorldBegin\nDisplacement \"hump\"\nSurface \"snow\"\n\
         Translate 0 0 5\nPatch \"bilinear\" \"P\" [-1 0.25 0  1 0.25 0  -1 -0.25 0  1 -0.25 0]\nWorldEnd\n",
        out.display()
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err && !text.contains("not supported"), "{text}");
    let img = image::open(&out).unwrap().to_rgb8();
    let row: Vec<[u8; 3]> = (0..16).map(|x| img.get_pixel(x, 2).0).collect();
    // s runs 0 → 1 left to right: red rises, green (1 − s) falls, blue says the misses and
    // the colour read behaved.
    for (x, p) in row.iter().enumerate() {
        let s = (x as f32 + 0.5) / 16.0;
        assert!((p[0] as f32 - 255.0 * s).abs() <= 12.0, "x {x}: {p:?}");
        assert!(
            (p[1] as f32 - 255.0 * (1.0 - s)).abs() <= 12.0,
            "x {x}: {p:?}"
        );
        assert_eq!(p[2], 255, "x {x}: {p:?}");
    }
}

#[test]
fn shadow_takes_prmans_area_source_and_a_list_of_maps() {
    // NCCA's `arealight`: `shadow("a.shad,b.shad", Ps, "source", P1, P2, P3, P4, "gapbias",
    // g)` is PRMan's soft shadow from maps rendered across an area light.
    let (n, text, err) = compile(
        "arealight.sl",
        "light arealight(string maplist = \"\"; point Pl1 = 0, Pl2 = 1, Pl3 = 2, Pl4 = 3; \
         float numsamples = 1, shadowBias = 0.01, gapBias = 0.01) { \
         illuminate((Pl1 + Pl2 + Pl3 + Pl4) * 0.25) { \
         float a = shadow(maplist, Ps, \"source\", Pl1, Pl2, Pl3, Pl4, \"samples\", numsamples, \
         \"bias\", shadowBias, \"gapbias\", gapBias); Cl = 1 - a; } }",
    );
    assert!(!err && n == 1, "{text}");
}

/// The fraction of the film `rib` covers (mean alpha).
fn coverage(rib: &str) -> f64 {
    let film = common::render_rib(rib, &[]);
    let a = film.channel("a").expect("alpha");
    let mut sum = 0.0;
    for y in 0..film.height {
        for x in 0..film.width {
            sum += film.pixel(x, y)[a] as f64;
        }
    }
    sum / (film.width * film.height) as f64
}

#[test]
fn points_that_carry_n_are_disks_across_it() {
    // PRMan draws a point given "N" as a disk facing along N (NCCA's Points.rib), not the
    // camera: tilted 60° it covers half the film a camera-facing one does, edge-on nothing.
    let scene = |n: &str| {
        format!(
            "Format 64 64 1\nPixelSamples 4 4\nDisplay \"p\" \"framebuffer\" \"rgba\"\n\
             Projection \"orthographic\"\nScreenWindow -1 1 -1 1\nWorldBegin\nTranslate 0 0 5\n\
             Surface \"constant\"\nPoints \"P\" [0 0 0] \"constantwidth\" [1.6] {n}\nWorldEnd\n"
        )
    };
    let facing = coverage(&scene(""));
    // π 0.8² / 4 of the film.
    assert!((facing - 0.5027).abs() < 0.01, "{facing}");
    let toward = coverage(&scene("\"N\" [0 0 -1]"));
    assert!((toward - facing).abs() < 0.005, "{toward} vs {facing}");
    let tilted = coverage(&scene("\"N\" [0 0.8660254 -0.5]"));
    assert!((tilted / facing - 0.5).abs() < 0.02, "{tilted} vs {facing}");
    let edge_on = coverage(&scene("\"N\" [1 0 0]"));
    assert!(edge_on < 0.01, "{edge_on}");
}

#[test]
fn lights_read_the_surface_parameters_by_message_passing() {
    // A light that scales its colour by the lit surface's `Kr` (as the SIGGRAPH 2001
    // course's softboxes light obeys its material's reflectivity: `surface("Kr", k)`),
    // takes its tint from a string parameter, and shines 0.25 where the surface has none.
    // Three squares: Kr given on the instance (0.5), Kr as a varying primitive variable
    // (s, a ramp) and a surface without Kr.
    let dir = common::scratch_dir("message-surface");
    std::fs::write(
        dir.join("obeylight.sl"),
        "light obeylight() { float k = 7; string tint = \"\"; \
         float found = surface(\"Kr\", k); float named = surface(\"tint\", tint); \
         float other = surface(\"nosuch\", k); \
         solar() { Cl = (found != 0 ? k : 0.25) * ((named != 0 && tint == \"blue\") ? color(0, 0, 1) : color(1, 1, 1)); } }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("shiny.sl"),
        "surface shiny(varying float Kr = 1; string tint = \"white\") { Oi = 1; \
         Ci = 0; illuminance(P) { Ci += Cl; } }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("dull.sl"),
        "surface dull() { Oi = 1; Ci = 0; illuminance(P) { Ci += Cl; } }\n",
    )
    .unwrap();
    let out = dir.join("m.png");
    let rib = format!(
        "Format 16 12 1\nPixelSamples 1 1\nDisplay \"{}\" \"file\" \"rgb\"\nProjection \"orthographic\"\n\
         ScreenWindow -1 1 -0.75 0.75\nWorldBegin\nLightSource \"obeylight\" 1\nTranslate 0 0 5\n\
         AttributeBegin\nSurface \"shiny\" \"Kr\" [0.5] \"tint\" \"blue\"\n{}\nAttributeEnd\n\
         AttributeBegin\nSurface \"shiny\"\nDeclare \"Kr\" \"varying float\"\n{} \"Kr\" [0 1 0 1]\nAttributeEnd\n\
         AttributeBegin\nSurface \"dull\"\n{}\nAttributeEnd\nWorldEnd\n",
        out.display(),
        band(0.5),
        band(0.0),
        band(-0.5)
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err && !text.contains("not supported"), "{text}");
    let img = image::open(&out).unwrap().to_rgb8();
    let px = |x: u32, y: u32| img.get_pixel(x, y).0;
    // Top: Kr 0.5 from the instance, tinted blue by the string parameter.
    let top = px(8, 2);
    assert!(
        top[0] == 0 && top[1] == 0 && (top[2] as i32 - 128).abs() <= 2,
        "{top:?}"
    );
    // Middle: Kr = s, a ramp left to right, white.
    for x in 0..16 {
        let p = px(x, 6);
        let s = (x as f32 + 0.5) / 16.0;
        assert!(
            (p[0] as f32 - 255.0 * s).abs() <= 12.0 && p[0].abs_diff(p[2]) <= 2,
            "x {x}: {p:?}"
        );
    }
    // Bottom: no Kr, the light's own 0.25.
    let bot = px(8, 10);
    assert!(
        (bot[0] as i32 - 64).abs() <= 2 && bot[0].abs_diff(bot[2]) <= 2,
        "{bot:?}"
    );
}

#[test]
fn surfaces_and_lights_read_the_atmosphere_parameters_by_message_passing() {
    // RISpec's `atmosphere("name", var)`: a surface that fades to its atmosphere's colour
    // by the atmosphere's `fogdist` (instance value 0.5 on the top square, a varying
    // primitive variable ramp on the middle one), and a light that dims to 0.5 when the
    // atmosphere has a `dim` flag. The bottom square has no atmosphere: not found.
    let dir = common::scratch_dir("message-atmosphere");
    std::fs::write(
        dir.join("foglook.sl"),
        "surface foglook() { float d = -1; float got = atmosphere(\"fogdist\", d); \
         float nope = atmosphere(\"nosuch\", d); Oi = 1; Ci = 0; \
         illuminance(P) { Ci += Cl; } \
         if (got != 0) Ci *= color(d, d, 1); else Ci *= color(0, 1, 0); }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("dimlight.sl"),
        "light dimlight() { float dim = 0; float got = atmosphere(\"dim\", dim); \
         solar() { Cl = (got != 0 && dim > 0) ? 0.5 : 1; } }\n",
    )
    .unwrap();
    // A volume shader that leaves the colour alone: only its parameters matter here.
    std::fs::write(
        dir.join("thinfog.sl"),
        "volume thinfog(varying float fogdist = 1; float dim = 1) { }\n",
    )
    .unwrap();
    let out = dir.join("a.png");
    let rib = format!(
        "Format 16 12 1\nPixelSamples 1 1\nDisplay \"{}\" \"file\" \"rgb\"\nProjection \"orthographic\"\n\
         ScreenWindow -1 1 -0.75 0.75\nWorldBegin\nLightSource \"dimlight\" 1\nTranslate 0 0 5\n\
         Surface \"foglook\"\n\
         AttributeBegin\nAtmosphere \"thinfog\" \"fogdist\" [0.5]\n{}\nAttributeEnd\n\
         AttributeBegin\nAtmosphere \"thinfog\" \"dim\" [0]\nDeclare \"fogdist\" \"varying float\"\n{} \"fogdist\" [0 1 0 1]\nAttributeEnd\n\
         AttributeBegin\n{}\nAttributeEnd\nWorldEnd\n",
        out.display(),
        band(0.5),
        band(0.0),
        band(-0.5)
    );
    let (text, err) = common::render_scene_file(&dir, &rib);
    assert!(!err && !text.contains("not supported"), "{text}");
    let img = image::open(&out).unwrap().to_rgb8();
    let px = |x: u32, y: u32| img.get_pixel(x, y).0;
    // Top: fogdist 0.5 from the instance, the light dimmed to 0.5 by `dim` 1.
    let top = px(8, 2);
    assert!(
        (top[0] as i32 - 64).abs() <= 2
            && top[0].abs_diff(top[1]) <= 2
            && (top[2] as i32 - 128).abs() <= 2,
        "{top:?}"
    );
    // Middle: fogdist = s, a ramp left to right, the light undimmed (`dim` 0).
    for x in 0..16 {
        let p = px(x, 6);
        let s = (x as f32 + 0.5) / 16.0;
        assert!(
            (p[0] as f32 - 255.0 * s).abs() <= 12.0 && p[2] == 255,
            "x {x}: {p:?}"
        );
    }
    // Bottom: no atmosphere, so neither call finds anything.
    assert_eq!(px(8, 10), [0, 255, 0]);
}

#[test]
fn illuminance_light_parameter_reads_each_lights_output() {
    // 3Delight's and PRMan's `illuminance(…, "light:__nondiffuse", nd)`: nd holds the
    // current light's output parameter inside the loop. Two lights of intensity 1 and 0.5;
    // the first marks itself non-diffuse, so only the second's 0.5 is added.
    let dir = common::scratch_dir("lightmsg");
    std::fs::write(
        dir.join("flaggedlight.sl"),
        "light flaggedlight(float intensity = 1; output float __nondiffuse = 0;) \
         { solar(vector(0, 0, 1), 0) { Cl = intensity; } }",
    )
    .unwrap();
    let c = centre_colour(
        "lightmsg",
        "surface lightmsg() { color c = 0; float nd = 0;\n\
         illuminance(\"\", P, N, PI, \"light:__nondiffuse\", nd) { c += Cl * (1 - nd); }\n\
         Oi = 1; Ci = c; }",
        "LightSource \"flaggedlight\" 1 \"__nondiffuse\" 1\n\
         LightSource \"flaggedlight\" 2 \"intensity\" 0.5",
    );
    for ch in c {
        assert!((ch - 0.5).abs() < 1e-4, "{c:?}");
    }
}

/// A bilinear patch across the frame, half a unit tall, centred at height `y` (the message
/// passing tests stack three of them).
fn band(y: f32) -> String {
    format!(
        "Patch \"bilinear\" \"P\" [-1 {a} 0  1 {a} 0  -1 {b} 0  1 {b} 0]",
        a = y + 0.25,
        b = y - 0.25
    )
}

/// PRMan 16's `HierarchicalSubdivisionMesh` (a `SubdivisionMesh` whose nargs are triples,
/// with string arguments for its edit tags) builds the same mesh as the plain request, and
/// PRMan's and 3Delight's further filter names (`separable-catmull-rom`, written by Ayam's
/// and K-3D's exporters, `blackman-harris`, `lanczos`) are filters, not errors.
#[test]
fn hierarchical_subdivision_meshes_and_prman_filter_names() {
    const CUBE: &str = r#"[4 4 4 4 4 4] [0 1 3 2 2 3 5 4 4 5 7 6 6 7 1 0 1 7 5 3 6 0 2 4]"#;
    const P: &str = r#""P" [-1 -1 1 1 -1 1 -1 1 1 1 1 1 -1 1 -1 1 1 -1 -1 -1 -1 1 -1 -1]"#;
    for filter in ["separable-catmull-rom", "blackman-harris", "lanczos"] {
        let b = build(&format!(
            "PixelFilter \"{filter}\" 4 4\nWorldBegin\n\
             HierarchicalSubdivisionMesh \"catmull-clark\" {CUBE} [\"interpolateboundary\" \"crease\"] \
             [1 0 0 2 1 0] [2 0 1] [10] [] {P}\n\
             SubdivisionMesh \"catmull-clark\" {CUBE} [\"interpolateboundary\" \"crease\"] \
             [1 0 2 1] [2 0 1] [10] {P}\nWorldEnd\n"
        ));
        assert!(
            b.of(Severity::Error).is_empty(),
            "{:#?}",
            b.of(Severity::Error)
        );
        let w = b.of(Severity::Warning);
        assert!(w.is_empty(), "{w:#?}");
        let s = &b.scenes[0];
        assert_eq!(s.options.pixel_filter.name, filter);
        assert_eq!(s.primitives.len(), 2);
        assert_eq!(
            format!("{:?}", s.primitives[0].geometry),
            format!("{:?}", s.primitives[1].geometry)
        );
    }
    // A triple count that does not match the tags is an error naming the request.
    let b = build(&format!(
        "WorldBegin\nHierarchicalSubdivisionMesh \"catmull-clark\" {CUBE} [\"crease\"] \
         [2 1] [0 1] [10] [] {P}\nWorldEnd\n"
    ));
    let e = b.of(Severity::Error);
    assert!(
        e.iter()
            .any(|m| m.contains("HierarchicalSubdivisionMesh") && m.contains("string counts")),
        "{e:#?}"
    );
}

/// Parameter values written without brackets (`"from" 0 0 -1`, as RIBMosaic exported before
/// 2011): a run of numbers after a name is that parameter's array, with one warning each,
/// instead of one error per extra number and a value one number short (the light lost).
#[test]
fn unbracketed_parameter_values_are_read_as_arrays() {
    let b = build(
        "WorldBegin\n\
         LightSource \"distantlight\" 1 \"from\" 0 0 -1 \"to\" 0 0 0 \"intensity\" 2\n\
         Surface \"plastic\" \"color specularcolor\" 1 0.5 0 \"Kd\" 1\n\
         Sphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(
        b.of(Severity::Error).is_empty(),
        "{:#?}",
        b.of(Severity::Error)
    );
    let w = b.of(Severity::Warning);
    assert_eq!(
        w.iter().filter(|m| m.contains("not in brackets")).count(),
        3,
        "{w:#?}"
    );
    let s = &b.scenes[0];
    let light = &s.lights[0].shader.params;
    assert_eq!(light.floats("from"), Some(&[0.0, 0.0, -1.0][..]));
    assert_eq!(light.floats("to"), Some(&[0.0, 0.0, 0.0][..]));
    assert_eq!(light.float("intensity"), Some(2.0));
    let surface = s.primitives[0].attributes.surface.as_ref().unwrap();
    assert_eq!(
        surface.params.floats("specularcolor"),
        Some(&[1.0, 0.5, 0.0][..])
    );
    assert_eq!(surface.params.float("Kd"), Some(1.0));
}

/// Pixie's default hider name, "stochastic", is the stochastic Z-buffer arbor calls "hidden":
/// no "not implemented" warning, and the hider is "hidden".
#[test]
fn pixies_stochastic_hider_is_hidden() {
    let b = build("Hider \"stochastic\"\nWorldBegin\nSphere 1 -1 1 360\nWorldEnd\n");
    let w = b.of(Severity::Warning);
    assert!(w.is_empty(), "{w:#?}");
    assert_eq!(b.scenes[0].options.hider.name, "hidden");
}
