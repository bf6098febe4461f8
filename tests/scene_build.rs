//! Scene builder: RIB text through `parse_bytes` and `build_scenes`, checking the built scenes
//! (options, transforms, attributes, lights, primitives, objects, archives, frames,
//! conditionals) and that each malformed input gives one clear diagnostic.

mod common;

use arbor::diag::{Diagnostics, Severity, SourceMap};
use arbor::rib::parse_bytes;
use arbor::scene::{build_scenes, BuildContext, Class, Geometry, ParamType, Projection, Scene};
use glam::{Mat4, Vec3};

struct Built {
    scenes: Vec<Scene>,
    diags: Diagnostics,
    sources: SourceMap,
}

impl Built {
    fn errors(&self) -> Vec<String> {
        self.diags
            .snapshot()
            .into_iter()
            .filter(|(d, _)| d.severity == Severity::Error)
            .map(|(d, _)| d.to_line(&self.sources))
            .collect()
    }
    fn warnings(&self) -> Vec<(String, usize)> {
        self.diags
            .snapshot()
            .into_iter()
            .filter(|(d, _)| d.severity == Severity::Warning)
            .map(|(d, n)| (d.message.clone(), n))
            .collect()
    }
    fn clean(&self) {
        let all: Vec<String> = self
            .diags
            .snapshot()
            .into_iter()
            .map(|(d, _)| d.to_line(&self.sources))
            .collect();
        assert!(all.is_empty(), "unexpected diagnostics: {all:#?}");
    }
    fn one(&self) -> &Scene {
        assert_eq!(self.scenes.len(), 1, "{:#?}", self.errors());
        &self.scenes[0]
    }
}

fn build_with(text: &str, f: impl FnOnce(&mut BuildContext)) -> Built {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = parse_bytes("scene.rib", text.as_bytes(), &sources, &diags);
    let scenes = {
        let mut ctx = BuildContext::new(&sources, &diags);
        f(&mut ctx);
        build_scenes(reqs, &ctx)
    };
    Built {
        scenes,
        diags,
        sources,
    }
}

fn build(text: &str) -> Built {
    build_with(text, |_| {})
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).length() < 1e-4
}

const COMPANION: &str = r#"##RenderMan RIB-Structure 1.1
version 3.03
Declare "Kd" "uniform float"
Declare "roughness" "uniform float"
Display "ball.tif" "file" "rgba"
Format 320 240 1
Projection "perspective" "fov" [40]
Translate 0 0 5
WorldBegin
  LightSource "ambientlight" 1 "intensity" [0.2]
  LightSource "distantlight" 2 "intensity" 1.0 "from" [0 0 -1] "to" [0 0 0]
  AttributeBegin
    Color [1 0.2 0.2]
    Surface "plastic" "Kd" .6 "roughness" [0.05]
    Translate 1 0 0
    Sphere 1 -1 1 360
  AttributeEnd
  AttributeBegin
    Illuminate 2 0
    Surface "matte"
    Polygon "P" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] "Cs" [1 0 0  0 1 0  0 0 1  1 1 1]
  AttributeEnd
WorldEnd
"#;

#[test]
fn companion_scene_builds() {
    let b = build(COMPANION);
    b.clean();
    let s = b.one();
    assert_eq!((s.options.xres, s.options.yres), (320, 240));
    assert_eq!(s.options.projection, Projection::Perspective { fov: 40.0 });
    assert_eq!(s.options.displays.len(), 1);
    assert_eq!(s.options.displays[0].name, "ball.tif");
    // Camera: the world origin is 5 units in front of the camera.
    assert!(close(
        s.camera_from_world.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 5.0)
    ));
    assert_eq!(s.lights.len(), 2);
    assert_eq!(s.lights[1].shader.name, "distantlight");
    assert_eq!(
        s.lights[1].shader.params.floats("from"),
        Some(&[0.0, 0.0, -1.0][..])
    );
    assert_eq!(s.primitives.len(), 2);
    let sphere = &s.primitives[0];
    assert!(matches!(*sphere.geometry, Geometry::Sphere { radius, .. } if radius == 1.0));
    assert!(close(
        sphere.world_from_object.transform_point3(Vec3::ZERO),
        Vec3::X
    ));
    assert_eq!(sphere.attributes.color, Vec3::new(1.0, 0.2, 0.2));
    let surf = sphere.attributes.surface.as_ref().unwrap();
    assert_eq!(surf.name, "plastic");
    assert_eq!(surf.params.float("Kd"), Some(0.6));
    assert_eq!(sphere.attributes.lights_on, vec![0, 1]);
    let poly = &s.primitives[1];
    assert_eq!(poly.attributes.lights_on, vec![0]);
    assert_eq!(poly.attributes.color, Vec3::ONE);
    assert!(matches!(
        &*poly.geometry,
        Geometry::Polygons { nvertices: 4, .. }
    ));
    assert_eq!(poly.primvars.floats("Cs").unwrap().len(), 12);
    assert_eq!(*poly.world_from_object, Mat4::IDENTITY);
}

#[test]
fn inline_declarations_and_declare() {
    let b = build(
        r#"Declare "temperature" "varying float"
WorldBegin
Patch "bilinear" "P" [0 0 0 1 0 0 0 1 0 1 1 0] "temperature" [1 2 3 4]
  "uniform color Kd2" [1 0 0] "float[2] st" [0 0 1 0 0 1 1 1]
  "constant string label" "hello"
WorldEnd
"#,
    );
    b.clean();
    let p = &b.one().primitives[0];
    let t = p.primvars.get("temperature").unwrap();
    assert_eq!(t.decl.class, Class::Varying);
    let kd = p.primvars.get("Kd2").unwrap();
    assert_eq!(
        (kd.decl.class, kd.decl.ty),
        (Class::Uniform, ParamType::Color)
    );
    let st = p.primvars.get("st").unwrap();
    assert_eq!(st.decl.array_len, 2);
    assert_eq!(p.primvars.string("label"), Some("hello"));
}

#[test]
fn value_counts_follow_the_primitive() {
    let b = build(
        r#"WorldBegin
PointsPolygons [3 3] [0 1 2 2 1 3] "P" [0 0 0 1 0 0 0 1 0 1 1 0]
  "uniform float id" [7 8] "facevarying float[2] uv" [0 0 1 0 0 1 0 1 1 0 1 1]
  "Cs" [1 1 1 1 1 1 1 1 1 1 1 1]
Sphere 1 -1 1 360 "s" [0 1 0]
Polygon "P" [0 0 0 1 0 0 1 1 0 0 1 0] "Cs" [1 0 0 0 1 0 0 0 1]
WorldEnd
"#,
    );
    let e = b.errors();
    assert_eq!(e.len(), 2, "{e:#?}");
    assert!(
        e[0].contains("`Sphere`: \"s\" (varying float) needs 4 numbers, found 3"),
        "{}",
        e[0]
    );
    assert!(e[1].contains("scene.rib:6:"), "{}", e[1]);
    assert!(e[1].contains("needs 12 numbers, found 9"), "{}", e[1]);
    let s = b.one();
    // The bad variables are dropped, the primitives kept.
    assert_eq!(s.primitives.len(), 3);
    assert_eq!(s.primitives[0].primvars.0.len(), 4);
    assert!(s.primitives[1].primvars.get("s").is_none());
}

#[test]
fn unknown_request_suggests_a_name() {
    let b = build("WorldBegin\nSphre 1 -1 1 360\nWorldEnd\n");
    let snap = b.diags.snapshot();
    assert_eq!(snap.len(), 1);
    assert_eq!(snap[0].0.help.as_deref(), Some("did you mean `Sphere`?"));
    assert!(b.errors()[0].starts_with("scene.rib:2:1:"));
}

#[test]
fn wrong_arguments_say_what_the_request_takes() {
    let b = build("WorldBegin\nSphere 1 -1 \"big\"\nWorldEnd\n");
    let snap = b.diags.snapshot();
    assert_eq!(snap.len(), 1, "{:#?}", b.errors());
    assert!(snap[0]
        .0
        .help
        .as_deref()
        .unwrap()
        .starts_with("`Sphere` takes 4 numbers: radius zmin zmax thetamax"));
    assert!(b.one().primitives.is_empty());
}

#[test]
fn bracketed_quadric_arguments() {
    let b = build("WorldBegin\nSphere [2 -2 2 180]\nTorus [1 .25 0 360 360]\nWorldEnd\n");
    b.clean();
    let s = b.one();
    assert_eq!(
        *s.primitives[0].geometry,
        Geometry::Sphere {
            radius: 2.0,
            zmin: -2.0,
            zmax: 2.0,
            thetamax: 180.0
        }
    );
    assert!(matches!(*s.primitives[1].geometry, Geometry::Torus { rminor, .. } if rminor == 0.25));
}

#[test]
fn block_nesting_errors_point_at_both_ends() {
    let b = build("WorldBegin\nAttributeEnd\nWorldEnd\n");
    let e = b.errors();
    assert_eq!(e.len(), 1);
    assert!(
        e[0].contains("scene.rib:2:1") && e[0].contains("`AttributeEnd` without `AttributeBegin`")
    );

    let b = build("WorldBegin\nAttributeBegin\nSphere 1 -1 1 360\nWorldEnd\n");
    let snap = b.diags.snapshot();
    assert_eq!(snap.len(), 1);
    let d = &snap[0].0;
    assert!(d
        .message
        .contains("`WorldEnd` closes `WorldBegin` while `AttributeBegin` is still open"));
    // The second label is the opener.
    assert_eq!(b.sources.line_col(d.labels[1].0), (2, 1));
    assert_eq!(b.one().primitives.len(), 1);

    let b = build("WorldBegin\nTransformBegin\nSphere 1 -1 1 360\n");
    let e = b.errors();
    assert_eq!(e.len(), 2, "{e:#?}");
    assert!(e[0].contains("scene.rib:2:1") && e[0].contains("never closed"));
    assert!(e[1].contains("scene.rib:1:1"));
    // The unclosed world still yields its scene.
    assert_eq!(b.one().primitives.len(), 1);
}

#[test]
fn transforms_compose_in_order() {
    let b = build(
        r#"WorldBegin
TransformBegin
  Translate 1 0 0
  Rotate 90 0 0 1
  Scale 2 2 2
  Sphere 1 -1 1 360
TransformEnd
ConcatTransform [1 0 0 0  0 1 0 0  0 0 1 0  0 0 3 1]
Sphere 1 -1 1 360
Identity
Transform [2 0 0 0  0 2 0 0  0 0 2 0  1 2 3 1]
Sphere 1 -1 1 360
WorldEnd
"#,
    );
    b.clean();
    let s = b.one();
    let m = *s.primitives[0].world_from_object;
    // Scale first, then rotate (x → y), then translate.
    assert!(close(m.transform_point3(Vec3::X), Vec3::new(1.0, 2.0, 0.0)));
    assert!(close(
        s.primitives[1]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 3.0)
    ));
    assert!(close(
        s.primitives[2]
            .world_from_object
            .transform_point3(Vec3::ONE),
        Vec3::new(3.0, 4.0, 5.0)
    ));
}

#[test]
fn coordinate_systems_are_recorded_in_world_space() {
    let b = build(
        r#"Translate 0 0 10
WorldBegin
TransformBegin
  Translate 0 2 0
  CoordinateSystem "lamp"
TransformEnd
CoordSysTransform "lamp"
Sphere 1 -1 1 360
WorldEnd
"#,
    );
    b.clean();
    let s = b.one();
    let lamp = s.coordinate_systems["lamp"];
    assert!(close(
        lamp.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 2.0, 0.0)
    ));
    assert!(close(
        s.primitives[0]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 2.0, 0.0)
    ));
}

#[test]
fn objects_are_instanced_with_the_current_transform_and_attributes() {
    let b = build(
        r#"WorldBegin
ObjectBegin "leg"
  Translate 0 0 1
  Cylinder 0.1 0 1 360
  Disk 1 0.1 360
ObjectEnd
AttributeBegin
  Color [1 0 0]
  Translate 5 0 0
  ObjectInstance "leg"
AttributeEnd
ObjectInstance "leg"
ObjectInstance "arm"
WorldEnd
"#,
    );
    let e = b.errors();
    assert_eq!(e.len(), 1, "{e:#?}");
    assert!(e[0].contains("no object has handle arm"));
    let s = b.one();
    assert_eq!(s.primitives.len(), 4);
    assert!(close(
        s.primitives[0]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(5.0, 0.0, 1.0)
    ));
    assert_eq!(s.primitives[0].attributes.color, Vec3::new(1.0, 0.0, 0.0));
    assert!(close(
        s.primitives[2]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 1.0)
    ));
    assert_eq!(s.primitives[2].attributes.color, Vec3::ONE);
}

#[test]
fn frames_give_one_scene_each_and_the_cli_filters_them() {
    let text = r#"Format 64 48 1
FrameBegin 1
  WorldBegin Sphere 1 -1 1 360 WorldEnd
FrameEnd
FrameBegin 2
  Format 100 100 1
  WorldBegin Sphere 1 -1 1 360 Cone 1 1 360 WorldEnd
FrameEnd
FrameBegin 3
  WorldBegin WorldEnd
FrameEnd
"#;
    let b = build(text);
    b.clean();
    assert_eq!(b.scenes.len(), 3);
    assert_eq!(b.scenes[1].frame, Some(2));
    assert_eq!(b.scenes[1].options.xres, 100);
    // Options set inside a frame end with it.
    assert_eq!(b.scenes[2].options.xres, 64);
    let b = build_with(text, |c| c.frames = Some((2, 3)));
    assert_eq!(
        b.scenes.iter().map(|s| s.frame).collect::<Vec<_>>(),
        vec![Some(2), Some(3)]
    );
}

#[test]
fn conditional_rib() {
    let text = r#"Option "user" "string pass" "shadow"
FrameBegin 2
WorldBegin
IfBegin "$Frame == 1"
  Sphere 1 -1 1 360
ElseIf "$user:pass =~ 'sha.*' && $Frame >= 2"
  Cone 1 1 360
  IfBegin "1"
    Disk 0 1 360
  IfEnd
Else
  Cylinder 1 0 1 360
IfEnd
IfBegin "$nothing == 1"
  Sphere 1 -1 1 360
IfEnd
WorldEnd
FrameEnd
"#;
    let b = build(text);
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    assert_eq!(w.len(), 1);
    assert!(w[0].0.contains("unknown variable `$nothing`"));
    let kinds: Vec<_> = b
        .one()
        .primitives
        .iter()
        .map(|p| match *p.geometry {
            Geometry::Cone { .. } => "cone",
            Geometry::Disk { .. } => "disk",
            _ => "other",
        })
        .collect();
    assert_eq!(kinds, vec!["cone", "disk"]);
}

#[test]
fn read_archive_from_disk_with_cycle_detection() {
    let dir = common::scratch("scene-test");
    let sub = dir.join("parts");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::write(
        sub.join("leg.rib"),
        "Cylinder 0.1 0 1 360\nReadArchive \"foot.rib\"\n",
    )
    .unwrap();
    // Found relative to the including file (parts/).
    std::fs::write(sub.join("foot.rib"), "Disk 0 0.2 360\n").unwrap();
    std::fs::write(
        dir.join("loop.rib"),
        "Sphere 1 -1 1 360\nReadArchive \"loop.rib\"\n",
    )
    .unwrap();
    let main = dir.join("main.rib");
    std::fs::write(
        &main,
        "WorldBegin\nReadArchive \"parts/leg.rib\"\nReadArchive \"loop.rib\"\nReadArchive \"missing.rib\"\nWorldEnd\n",
    )
    .unwrap();
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = arbor::rib::read_path(&main, &sources, &diags).unwrap();
    let mut ctx = BuildContext::new(&sources, &diags);
    ctx.base_dir = Some(dir.to_path_buf());
    let scenes = build_scenes(reqs, &ctx);
    let errs: Vec<String> = diags
        .snapshot()
        .into_iter()
        .map(|(d, _)| d.message)
        .collect();
    assert_eq!(errs.len(), 2, "{errs:#?}");
    assert!(
        errs[0].starts_with("`ReadArchive` cycle:") && errs[0].contains("loop.rib → "),
        "{}",
        errs[0]
    );
    assert!(errs[1].contains("cannot find archive \"missing.rib\""));
    // The scene's folder is also the base folder: named once in the help.
    let help = diags.snapshot()[1].0.help.clone().unwrap_or_default();
    let folder = dir.display().to_string();
    assert_eq!(help.matches(folder.as_str()).count(), 1, "{help}");
    assert_eq!(scenes[0].primitives.len(), 3);
    assert!(matches!(
        *scenes[0].primitives[1].geometry,
        Geometry::Disk { .. }
    ));
}

#[test]
fn inline_archives() {
    let b = build(
        r#"ArchiveBegin "pair"
  Sphere 1 -1 1 360
  Translate 2 0 0
  Sphere 1 -1 1 360
ArchiveEnd
WorldBegin
  ReadArchive "pair"
  AttributeBegin Translate 0 5 0 ReadArchive "pair" AttributeEnd
WorldEnd
"#,
    );
    b.clean();
    let s = b.one();
    assert_eq!(s.primitives.len(), 4);
    assert!(close(
        s.primitives[3]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(4.0, 5.0, 0.0)
    ));
}

#[test]
fn search_paths_expand_previous_and_default() {
    let b = build_with(
        r#"Option "searchpath" "shader" "/a:@"
Option "searchpath" "shader" "/b:&" "archive" "/arch"
WorldBegin WorldEnd
"#,
        |c| {
            c.shader_paths = vec!["/cli".into()];
            c.base_dir = Some("/scene".into());
        },
    );
    b.clean();
    let p = &b.one().options.search_paths;
    assert_eq!(p.shader, vec!["/cli", "/b", "/a", "/scene"]);
    assert_eq!(p.archive, vec!["/arch"]);
}

#[test]
fn search_paths_expand_environment_variables() {
    // PRMan/3Delight/Aqsis scenes name their installations: `${VAR}` and `$VAR` expand; an
    // entry naming an unset variable is skipped with one warning naming it.
    let b = build_with(
        r#"Option "searchpath" "shader" "${ARBOR_TEST_SURELY_UNSET}/shaders:$ARBOR_TEST_SURELY_UNSET2:/plain:&"
WorldBegin WorldEnd
"#,
        |c| c.shader_paths = vec![],
    );
    assert_eq!(b.one().options.search_paths.shader, vec!["/plain"]);
    let w = b.warnings();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].0
            .contains("ARBOR_TEST_SURELY_UNSET, ARBOR_TEST_SURELY_UNSET2"),
        "{w:?}"
    );
}

#[test]
fn lights_outside_the_world_and_illuminate_by_name() {
    // RenderMan Companion / Aqsis scenes declare lights before WorldBegin: they live in
    // camera space and shine in the world (PRMan and Aqsis accept this).
    let b = build(
        r#"Translate 0 0 5
LightSource "pointlight" 1 "from" [0 0 1]
WorldBegin
LightSource "spotlight" "key" "coneangle" 0.5
AttributeBegin
  Illuminate "key" 0
  Sphere 1 -1 1 360
AttributeEnd
Sphere 1 -1 1 360
Illuminate "fill" 1
WorldEnd
"#,
    );
    // An unknown handle has no light to switch: a warning, and the frame renders.
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    assert_eq!(w.len(), 1, "{w:#?}");
    assert!(w[0].0.contains("no light has handle fill"), "{w:#?}");
    let s = b.one();
    assert_eq!(s.lights.len(), 2);
    assert_eq!(s.lights[0].handle, "1");
    assert_eq!(s.lights[1].handle, "key");
    // camera_from_world is Translate 0 0 5 and the light was declared under the same
    // transform, so its shader space is the world: world_from_shader = identity.
    let wfs = s.lights[0].shader.world_from_shader;
    assert!(wfs.abs_diff_eq(Mat4::IDENTITY, 1e-5), "{wfs:?}");
    assert_eq!(s.primitives[0].attributes.lights_on, vec![0]);
    assert_eq!(s.primitives[1].attributes.lights_on, vec![0, 1]);
}

#[test]
fn lights_before_world_in_camera_space_and_scoped_to_their_frame() {
    let b = build(
        r#"FrameBegin 1
LightSource "distantlight" 1
Translate 0 0 5
WorldBegin
Sphere 1 -1 1 360
WorldEnd
FrameEnd
FrameBegin 2
WorldBegin
Sphere 1 -1 1 360
WorldEnd
FrameEnd
AreaLightSource "arealight" 2
"#,
    );
    let e = b.errors();
    assert_eq!(e.len(), 1, "{e:#?}");
    assert!(e[0].contains("outside `WorldBegin`"), "{e:#?}");
    assert_eq!(b.scenes.len(), 2);
    let s = &b.scenes[0];
    assert_eq!(s.lights.len(), 1);
    // Declared at camera space = identity; world_from_camera = Translate 0 0 -5.
    let p = s.lights[0]
        .shader
        .world_from_shader
        .transform_point3(Vec3::ZERO);
    assert!(close(p, Vec3::new(0.0, 0.0, -5.0)), "{p:?}");
    assert_eq!(s.primitives[0].attributes.lights_on, vec![0]);
    // The light belonged to frame 1 only.
    assert!(b.scenes[1].lights.is_empty());
    assert!(b.scenes[1].primitives[0].attributes.lights_on.is_empty());
}

#[test]
fn empty_brackets_are_empty_subdivision_tag_lists() {
    // Exporters write `[] [] [] []` for "no tags"; `[]` reads as an empty number array.
    let b = build(
        r#"WorldBegin
SubdivisionMesh "catmull-clark" [4] [0 1 2 3] [] [] [] [] "P" [0 0 0 1 0 0 1 1 0 0 1 0]
WorldEnd
"#,
    );
    b.clean();
    let s = b.one();
    assert_eq!(s.primitives.len(), 1);
    assert!(matches!(
        &*s.primitives[0].geometry,
        Geometry::SubdivisionMesh { .. }
    ));
}

#[test]
fn unimplemented_requests_warn_once_with_a_count() {
    let b = build(
        r#"WorldBegin
MotionBegin [0 1] Translate 0 0 0 Translate 1 0 0 MotionEnd
MotionBegin [0 1] Translate 0 0 0 Translate 1 0 0 MotionEnd
GeometricRepresentation "lines"
GeometricRepresentation "points"
Sphere 1 -1 1 360
WorldEnd
"#,
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    assert_eq!(w.len(), 1, "{w:#?}");
    assert!(w[0]
        .0
        .contains("`GeometricRepresentation` is not implemented"));
    // Motion blocks apply (and compose): the sphere moves from x = 0 to x = 2.
    let p = &b.one().primitives[0];
    assert_eq!(*p.world_from_object, Mat4::IDENTITY);
    let m = p.motion.as_ref().expect("a moving primitive");
    assert_eq!(m.times, vec![0.0, 1.0]);
    assert_eq!(
        m.world_from_object[1].transform_point3(glam::Vec3::ZERO),
        glam::Vec3::new(2.0, 0.0, 0.0)
    );
}

#[test]
fn error_handler_abort_stops_at_the_first_error() {
    let b = build("ErrorHandler \"abort\"\nWorldBegin\nSphre 1\nBogus\nWorldEnd\n");
    assert_eq!(b.errors().len(), 1, "{:#?}", b.errors());
    let b =
        build("ErrorHandler \"ignore\"\nWorldBegin\nSphre 1\nBogus\nSphere 1 -1 1 360 WorldEnd\n");
    assert!(b.errors().is_empty());
    assert_eq!(b.one().primitives.len(), 1);
}

#[test]
fn color_samples_convert_colors_to_rgb() {
    let b = build(
        r#"ColorSamples [0.5 0.5 0.5  0.5 0.5 0.5] [1 1 0 0 1 1]
WorldBegin
Color [0.2 0.4]
Sphere 1 -1 1 360 "Cs" [1 0  0 1  1 1  0 0]
WorldEnd
"#,
    );
    b.clean();
    let p = &b.one().primitives[0];
    assert!(close(p.attributes.color, Vec3::splat(0.3)));
    assert_eq!(p.primvars.floats("Cs").unwrap().len(), 12);
}

#[test]
fn orientation_and_sides() {
    let b = build(
        r#"WorldBegin
Sides 1
Orientation "inside"
Sphere 1 -1 1 360
ReverseOrientation
Sphere 1 -1 1 360
Scale 1 1 -1
Orientation "rh"
Sphere 1 -1 1 360
Sides 3
WorldEnd
"#,
    );
    assert_eq!(b.errors().len(), 1);
    let s = b.one();
    assert_eq!(s.primitives[0].attributes.sides, 1);
    assert!(s.primitives[0].attributes.reverse_orientation);
    assert!(!s.primitives[1].attributes.reverse_orientation);
    // Camera space is left-handed; a mirrored object space is right-handed, so "rh" is its
    // natural orientation.
    assert!(!s.primitives[2].attributes.reverse_orientation);
}

#[test]
fn patch_meshes_nurbs_curves_and_subdivision_meshes() {
    let b = build(
        r#"WorldBegin
Basis "b-spline" 1 "b-spline" 1
PatchMesh "bicubic" 5 "nonperiodic" 4 "nonperiodic" "Pz" [0 0 0 0 0  0 0 0 0 0  0 0 0 0 0  0 0 0 0 0]
  "Cs" [1 1 1  1 1 1  1 1 1  1 1 1  1 1 1  1 1 1]
NuPatch 2 2 [0 0 1 1] 0 1 2 2 [0 0 1 1] 0 1 "Pw" [0 0 0 1  1 0 0 1  0 1 0 1  1 1 0 1]
Curves "cubic" [4 5] "nonperiodic" "P" [0 0 0 1 0 0 2 0 0 3 0 0  0 1 0 1 1 0 2 1 0 3 1 0 4 1 0]
  "width" [1 1  1 1 1]
SubdivisionMesh "catmull-clark" [4] [0 1 2 3] ["interpolateboundary"] [0 0] [] [] "P" [0 0 0 1 0 0 1 1 0 0 1 0]
Points "P" [0 0 0 1 1 1] "constantwidth" 0.1
Geometry "teapot"
WorldEnd
"#,
    );
    b.clean();
    let s = b.one();
    assert_eq!(s.primitives.len(), 6);
    assert!(matches!(
        *s.primitives[0].geometry,
        Geometry::PatchMesh {
            bicubic: true,
            nu: 5,
            nv: 4,
            ..
        }
    ));
    assert!(matches!(
        *s.primitives[2].geometry,
        Geometry::Curves { cubic: true, .. }
    ));
    assert!(matches!(
        *s.primitives[4].geometry,
        Geometry::Points { npoints: 2 }
    ));
}

#[test]
fn bad_patch_mesh_sizes_are_explained() {
    let b = build(
        "WorldBegin\nPatchMesh \"bicubic\" 5 \"nonperiodic\" 4 \"nonperiodic\" \"P\" [0 0 0]\nWorldEnd\n",
    );
    let e = b.errors();
    assert_eq!(e.len(), 1);
    assert!(
        e[0].contains("nu: 5 points; a bicubic mesh needs 4 + k·3"),
        "{}",
        e[0]
    );
}

const ADVANCED: &str = r#"##RenderMan RIB
version 3.03
Option "searchpath" "shader" ["shaders:&"]
Option "limits" "bucketsize" [16 16] "gridsize" [256]
Option "render" "integer maxerror" [3]
Option "statistics" "endofframe" [1]
Display "out.tif" "tiff" "rgba"
Display "+depth.z" "zfile" "z"
Hider "hidden" "jitter" [1]
PixelFilter "catmull-rom" 3 3
Exposure 1 2.2
Quantize "rgba" 255 0 255 0.5
Clipping 0.1 100
ScreenWindow -1 1 -1 1
FrameAspectRatio 1
CropWindow 0.25 0.75 0 1
Imager "background" "background" [0.2 0.2 0.2]
Projection "perspective" "fov" 30
ClippingPlane 0 0 50 0 0 1
Scale 1 1 -1
Translate 0 -1 8
WorldBegin
  Attribute "identifier" "name" ["floor"]
  Attribute "displacementbound" "sphere" [0.25] "coordinatesystem" ["shader"]
  Attribute "user" "string pass" ["beauty"]
  Attribute "visibility" "bogus" [1]
  LightSource "spotlight" 3 "from" [0 5 0] "to" [0 0 0] "coneangle" [0.4] "intensity" [40]
    "__nonspecular" [0]
  ShadingRate 0.5
  ShadingInterpolation "smooth"
  Displacement "dented" "Km" [0.2] "frequency" [4]
  Surface "wood" "ringscale" 10 "lightwood" [0.69 0.44 0.25]
  TextureCoordinates 0 0 2 0 0 2 2 2
  GeometricApproximation "flatness" 0.5
  Matte 0
  Bound [-1 1 -1 1 -1 1]
  Patch "bicubic" "P" [0 0 0 1 0 0 2 0 0 3 0 0  0 1 0 1 1 0 2 1 0 3 1 0
                       0 2 0 1 2 0 2 2 0 3 2 0  0 3 0 1 3 0 2 3 0 3 3 0]
WorldEnd
"#;

#[test]
fn advanced_renderman_style_scene() {
    let b = build(ADVANCED);
    let w = b.warnings();
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    // Only the undeclared renderer-specific attribute and the unused approximation hint warn.
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(w[0].0.contains("\"bogus\" is not declared"));
    assert!(w[1]
        .0
        .contains("`GeometricApproximation \"flatness\"` is not used"));
    let s = b.one();
    let o = &s.options;
    assert_eq!(o.user_floats("limits:bucketsize"), Some(&[16.0, 16.0][..]));
    assert_eq!(o.user_floats("render:maxerror"), Some(&[3.0][..]));
    assert_eq!(o.displays.len(), 2);
    assert_eq!(o.displays[1].name, "depth.z");
    assert_eq!(o.pixel_filter.name, "catmull-rom");
    assert_eq!(o.frame_aspect, Some(1.0));
    assert_eq!(o.screen_window, Some([-1.0, 1.0, -1.0, 1.0]));
    assert_eq!(o.crop_window, [0.25, 0.75, 0.0, 1.0]);
    assert_eq!(o.search_paths.shader, vec!["shaders"]);
    assert_eq!(o.hider.params.float("jitter"), Some(1.0));
    let im = o.imager.as_ref().unwrap();
    assert_eq!(im.params.floats("background"), Some(&[0.2, 0.2, 0.2][..]));
    // The clipping plane was given in camera space (before any transform): its world-space
    // point and normal map back to camera z = 50 and +z.
    let (p, n) = o.clipping_planes[0];
    assert!(close(
        s.camera_from_world.transform_point3(p),
        Vec3::new(0.0, 0.0, 50.0)
    ));
    assert!(close(
        s.camera_from_world.transform_vector3(n).normalize(),
        Vec3::Z
    ));
    let a = &s.primitives[0].attributes;
    assert_eq!(a.identifier.as_deref(), Some("floor"));
    assert_eq!(a.displacement_bound, 0.25);
    assert_eq!(a.displacement_bound_space, "shader");
    assert_eq!(a.shading_rate, 0.5);
    assert!(a.smooth_shading);
    assert_eq!(a.texture_coordinates[2], 2.0);
    assert_eq!(a.geometric_approximation["flatness"], 0.5);
    assert_eq!(a.bound, Some([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0]));
    let surf = a.surface.as_ref().unwrap();
    assert_eq!(surf.params.floats("lightwood").unwrap().len(), 3);
    assert_eq!(
        a.displacement.as_ref().unwrap().params.float("Km"),
        Some(0.2)
    );
    assert_eq!(s.lights[0].handle, "3");
    assert!(a.user.contains_key("user:pass"));
}

#[test]
fn scoped_coordinate_systems_delayed_archives_and_area_lights() {
    let b = build(
        r#"ArchiveBegin "bulb"
  Sphere 0.1 -0.1 0.1 360
ArchiveEnd
# A procedural whose bound is off the image is culled: this window shows it.
ScreenWindow -5 5 -5 5
WorldBegin
AttributeBegin
  Translate 0 3 0
  ScopedCoordinateSystem "shelf"
  CoordinateSystem "table"
  AreaLightSource "arealight" "bulb1" "intensity" 2
  Procedural "DelayedReadArchive" ["bulb"] [-1 1 -1 1 -1 1]
AttributeEnd
CoordSysTransform "table"
CoordSysTransform "shelf"
Skew 45 0 1 0 1 0 0
Detail [-1 1 -1 1 -1 1]
Disk 0 1 360
WorldEnd
"#,
    );
    let e = b.errors();
    assert_eq!(e.len(), 1, "{e:#?}");
    assert!(
        e[0].contains("no coordinate system named \"shelf\""),
        "{}",
        e[0]
    );
    // `Detail` is applied at render time (level of detail), without a warning.
    assert!(b.warnings().is_empty(), "{:#?}", b.warnings());
    let s = b.one();
    assert!(s.coordinate_systems.contains_key("table"));
    assert!(!s.coordinate_systems.contains_key("shelf"));
    assert!(s.lights[0].area);
    assert_eq!(s.primitives.len(), 2);
    // The archive's sphere was lit by the area light and placed in the block's space.
    assert_eq!(s.primitives[0].attributes.lights_on, vec![0]);
    assert!(close(
        s.primitives[0]
            .world_from_object
            .transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 3.0, 0.0)
    ));
    // Disk: moved to "table" then skewed (y leans towards x).
    let m = *s.primitives[1].world_from_object;
    assert!(close(m.transform_point3(Vec3::Y), Vec3::new(1.0, 4.0, 0.0)));
}

#[test]
fn format_defaults_and_aspect_rules() {
    let b = build("Format -1 -1 -1\nWorldBegin WorldEnd\nFormat 200 100 2\nWorldBegin WorldEnd\nFormat 0 10 1\n");
    let e = b.errors();
    assert_eq!(e.len(), 1, "{e:#?}");
    assert!(e[0].contains("scene.rib:5:"));
    let o0 = &b.scenes[0].options;
    assert_eq!((o0.xres, o0.yres, o0.pixel_aspect), (640, 480, 1.0));
    assert_eq!(o0.frame_aspect, None);
    assert_eq!(
        o0.effective_screen_window(),
        [-4.0 / 3.0, 4.0 / 3.0, -1.0, 1.0]
    );
    // 200·2/100 = 4: the screen window follows the aspect.
    let o1 = &b.scenes[1].options;
    assert_eq!(o1.effective_frame_aspect(), 4.0);
    assert_eq!(o1.effective_screen_window(), [-4.0, 4.0, -1.0, 1.0]);
}

#[test]
fn attributes_inside_object_definitions_warn_by_name() {
    // K-3D writes Color/Opacity inside ObjectBegin; instances take the attributes current at
    // ObjectInstance, so the definition's Color is dropped with a warning naming it.
    let b = build(
        r#"WorldBegin
ObjectBegin 1
  AttributeBegin
    Color [0.1 0.5 0.5]
    Opacity 0.8 0.8 0.8
    Polygon "P" [0 0 0 1 0 0 1 1 0]
  AttributeEnd
ObjectEnd
Color [1 0 0]
ObjectInstance 1
WorldEnd
"#,
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(w[0].0.contains("`Color` inside `ObjectBegin`"), "{w:#?}");
    assert!(w[1].0.contains("`Opacity` inside `ObjectBegin`"), "{w:#?}");
    let s = b.one();
    assert_eq!(s.primitives.len(), 1);
    assert_eq!(s.primitives[0].attributes.color, Vec3::new(1.0, 0.0, 0.0));
}

#[test]
fn later_shading_extensions_warn_instead_of_failing() {
    // Aqsis's layered-shader example and RIS exports (PRMan 19+) use these requests.
    let b = build(
        r#"Integrator "PxrPathTracer" "spt" "int maxPathLength" [10]
WorldBegin
ShaderLayer "surface" "texmap" "layer1" "string texturename" ["grid.tex"]
ShaderLayer "surface" "matte" "layer2"
ConnectShaderLayers "surface" "layer1" "Cout" "layer2" "Cs"
Bxdf "PxrDiffuse" "d1" "color diffuseColor" [1 0 0]
Sphere 1 -1 1 360
WorldEnd
"#,
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    let names: Vec<&str> = ["Integrator", "ShaderLayer", "ConnectShaderLayers", "Bxdf"].into();
    for n in names {
        assert!(
            w.iter()
                .any(|(m, _)| m == &format!("`{n}` is not implemented yet; ignored")),
            "{n}: {w:#?}"
        );
    }
    assert_eq!(b.one().primitives.len(), 1);
}

#[test]
fn delayed_archives_out_of_view_are_never_read() {
    // Perspective camera 5 units back: the first bound is in view, the second far off to the
    // side, the third behind the eye. Only the first archive is read (the others do not
    // exist: reading them would be an error).
    let b = build(
        r#"ArchiveBegin "ball"
  Sphere 0.5 -0.5 0.5 360
ArchiveEnd
Format 64 64 1
Projection "perspective" "fov" 45
Translate 0 0 5
WorldBegin
  Procedural "DelayedReadArchive" ["ball"] [-1 1 -1 1 -1 1]
  AttributeBegin
    Translate 40 0 0
    Procedural "DelayedReadArchive" ["offscreen.rib"] [-1 1 -1 1 -1 1]
  AttributeEnd
  Translate 0 0 -10
  Procedural "DelayedReadArchive" ["behind.rib"] [-1 1 -1 1 -1 1]
WorldEnd
"#,
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    assert_eq!(b.one().primitives.len(), 1);
}

#[test]
fn programs_are_not_run_unless_allowed() {
    let b = build(
        "WorldBegin\nProcedural \"RunProgram\" [\"rm -rf /\" \"\"] [-1 1 -1 1 -1 1]\n\
         Procedural \"DynamicLoad\" [\"evil.so\" \"\"] [-1 1 -1 1 -1 1]\nWorldEnd\n",
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let w = b.warnings();
    assert_eq!(w.len(), 2, "{w:#?}");
    assert!(w[0].0.contains("`rm -rf /`") && w[0].0.contains("not run unless allowed"));
    assert!(w[1].0.contains("`evil.so`"));
    assert!(b.one().primitives.is_empty());
}

#[test]
fn a_printed_nan_or_infinity_drops_its_request_with_a_warning() {
    // Animation scripts of the era printed NaN into RIB (RenderMan Repository's terran.rib:
    // `Rotate NaN 0 1 0`). The request is left out, the rest of the frame renders.
    let b = build(
        "Rotate 0 0 1 0\nRotate NaN 0 1 0\nTranslate 0 0 5\nWorldBegin\n\
         Sphere 1 -1 1 inf\nSphere [1 -1 1 360]\nPolygon \"P\" [0 0 0 1 0 0 -nan 1 0]\nWorldEnd\n",
    );
    assert!(b.errors().is_empty(), "{:?}", b.errors());
    let w = b.warnings();
    let nf: usize = w
        .iter()
        .filter(|(m, _)| m.contains("not a finite number"))
        .map(|(_, n)| n)
        .sum();
    assert_eq!(nf, 3, "{w:?}");
    let s = &b.scenes[0];
    // Only the finite sphere is left; the camera is the translation alone.
    assert_eq!(s.primitives.len(), 1);
    assert!(s.camera_from_world.is_finite());
    assert!(close(
        s.camera_from_world.transform_point3(Vec3::ZERO),
        Vec3::new(0.0, 0.0, 5.0)
    ));
}

#[test]
fn quantize_of_a_named_display_variable_is_kept_for_that_mode() {
    // Aqsis scenes quantize arbitrary display variables (`Quantize "N" 0 0 0 0` asks for
    // floats); the name is not an error, and a later request for it replaces the earlier.
    let b = build(
        "Quantize \"N\" 255 0 255 0.5\nQuantize \"N\" 0 0 0 0\nQuantize \"rgba\" 65535 0 65535 0\n\
         Display \"a.tif\" \"file\" \"rgba\"\nWorldBegin\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    b.clean();
    let o = &b.one().options;
    assert_eq!(o.quantize_named.len(), 1);
    assert_eq!(o.quantize_named[0].0, "N");
    assert_eq!(o.quantize_named[0].1.one, 0.0);
    assert_eq!(o.quantize_named[0].1.dither, 0.0);
    assert_eq!(o.quantize_rgba.one, 65535.0);
    let b = build("Quantize \"\" 255 0 255 0.5\nWorldBegin\nWorldEnd\n");
    assert!(
        b.errors()[0].contains("empty quantizer name"),
        "{:?}",
        b.errors()
    );
}

#[test]
fn geometric_representation_primitive_is_silent() {
    // WW3DKit's RIB (the RMR SWShaders spaceship) writes `GeometricRepresentation
    // "primitive"`, PRMan's default and what arbor draws: nothing to warn about.
    let b = build(
        r#"WorldBegin
GeometricRepresentation "primitive"
Sphere 1 -1 1 360
WorldEnd
"#,
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    assert!(b.warnings().is_empty(), "{:#?}", b.warnings());
    assert_eq!(b.one().primitives.len(), 1);
}

#[test]
fn an_imager_inside_the_world_sets_the_frames_imager() {
    // Pixar's Blobby application-note scenes (shipped with Aqsis) write
    // `WorldBegin Imager "background" "color" [1 1 1]`; the imager runs after the world, so
    // it applies to that frame, quietly. It does not leak into the next frame.
    let b = build(
        "FrameBegin 1\nWorldBegin\nImager \"background\" \"color\" [1 1 1]\nSphere 1 -1 1 360\nWorldEnd\nFrameEnd\n\
         FrameBegin 2\nWorldBegin\nSphere 1 -1 1 360\nWorldEnd\nFrameEnd\n",
    );
    assert!(b.warnings().is_empty(), "{:#?}", b.warnings());
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    let im = b.scenes[0].options.imager.as_ref().expect("an imager");
    assert_eq!(im.name, "background");
    assert!(b.scenes[1].options.imager.is_none());
}

#[test]
fn degenerate_crop_windows_and_opacities_warn_and_render() {
    // Aqsis's regression scenes Bug1266044 (a CropWindow of zero size, where Aqsis crashed)
    // and Bug1326794 (`Opacity [3 3 3]`): warnings, the frame uncropped, opacity clamped.
    let b = build(
        "CropWindow 0.8 0.8 0.45 0.45\nWorldBegin\nOpacity [3 3 3]\nSphere 1 -1 1 360\n\
         Opacity [0.5 -1 0.25]\nSphere 1 -1 1 360\nWorldEnd\n",
    );
    assert!(b.errors().is_empty(), "{:#?}", b.errors());
    assert_eq!(b.warnings().len(), 3, "{:#?}", b.warnings());
    let s = b.one();
    assert_eq!(s.options.crop_window, [0.0, 1.0, 0.0, 1.0]);
    assert_eq!(s.primitives[0].attributes.opacity, Vec3::ONE);
    assert_eq!(
        s.primitives[1].attributes.opacity,
        Vec3::new(0.5, 0.0, 0.25)
    );
    // A reversed window is still an error.
    assert_eq!(
        build("CropWindow 0.8 0.2 0 1\nWorldBegin\nWorldEnd\n")
            .errors()
            .len(),
        1
    );
}
