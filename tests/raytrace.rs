//! Ray tracing inside the REYES renderer, checked analytically: a perfect mirror, a ray-traced
//! shadow's disk, occlusion of an open plane and inside a closed box, refraction through a
//! glass slab, and determinism across thread counts and bucket sizes.

mod common;

use std::path::PathBuf;

use arbor::render::driver::RenderOptions;
use common::{film_rgb, render_rib};

fn shaders() -> PathBuf {
    common::manifest_dir().join("tests").join("raytrace")
}

/// A square polygon of half-size `h` in the plane z = `z`.
fn square(h: f32, z: f32) -> String {
    format!(
        "Polygon \"P\" [{a} {a} {z}  {h} {a} {z}  {h} {h} {z}  {a} {h} {z}]",
        a = -h
    )
}

/// Orthographic view down +z onto a square with surface `shader` at z = 5; behind the camera
/// (culled by REYES, seen only by rays) a constant wall of colour (0.2, 0.5, 0.8) at z = −5.
/// `options` go before `Projection`. Returns the RGB floats.
fn mirror_over_wall(shader: &str, options: &str) -> Vec<f32> {
    let rib = format!(
        r#"{options}
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
AttributeBegin
  Surface "{shader}"
  {mirror}
AttributeEnd
AttributeBegin
  Color [0.2 0.5 0.8]
  Surface "constant"
  {wall}
AttributeEnd
WorldEnd
"#,
        mirror = square(2.0, 5.0),
        wall = square(10.0, -5.0)
    );
    film_rgb(&render_rib(&rib, &[shaders()]))
}

#[test]
fn a_perfect_mirror_returns_the_mirrored_constant_colour_exactly() {
    // Orthographic view down +z onto a mirror at z = 5; behind the camera (culled by REYES,
    // seen only by rays) a constant-coloured wall at z = −5.
    let rgb = mirror_over_wall("mirrortest", "Format 24 24 1\nPixelSamples 2 2");
    for px in rgb.chunks_exact(3) {
        for (c, want) in px.iter().zip([0.2f32, 0.5, 0.8]) {
            assert!((c - want).abs() < 1e-6, "pixel {px:?}");
        }
    }
}

/// RISpec §4.2.6: a traced ray's hit is filtered by the volume the ray crossed — the hit
/// object's `Exterior` when the ray arrives from outside, its `Interior` when it leaves the
/// object there. A window (`Ci = trace(P, I)`) looks at a white sphere: from outside (a small
/// sphere behind the window) the exterior halves the white; from inside (a large sphere around
/// the window) the interior quarters it.
#[test]
fn interior_and_exterior_filter_traced_rays_by_the_side_they_cross() {
    for (sphere, want) in [
        ("Translate 0 0 10 Sphere 3 -3 3 360", 0.5f32),
        ("Sphere 20 -20 20 360", 0.25),
    ] {
        let rib = format!(
            r#"Format 8 8 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
AttributeBegin
  Surface "passthrough"
  {window}
AttributeEnd
AttributeBegin
  Color [1 1 1]
  Surface "constant"
  Exterior "halve"
  Interior "quarter"
  {sphere}
AttributeEnd
WorldEnd
"#,
            window = square(2.0, 5.0)
        );
        let film = render_rib(&rib, &[shaders()]);
        for c in film_rgb(&film) {
            assert!((c - want).abs() < 1e-5, "{sphere}: {c} against {want}");
        }
    }
}

#[test]
fn trace_inside_arithmetic_is_a_colour() {
    // `Kr * trace(P, R)`: the float sibling does not make trace() the grey float form (the
    // gallery's mirror sphere reflected grey stripes when it did).
    let rgb = mirror_over_wall("halfmirror", "Format 8 8 1");
    for px in rgb.chunks_exact(3) {
        for (c, want) in px.iter().zip([0.1f32, 0.25, 0.4]) {
            assert!((c - want).abs() < 1e-6, "pixel {px:?}");
        }
    }
}

/// Renders with explicit thread/bucket settings; returns the RGB floats.
fn render_with(rib: &str, threads: usize, bucket: u32) -> Vec<f32> {
    let opts = RenderOptions {
        threads,
        bucket_size: Some([bucket, bucket]),
        ..Default::default()
    };
    film_rgb(&common::render_rib_with(rib, &[shaders()], &opts).0)
}

/// A plane at z = 10 lit by a point light at the eye with ray-traced shadows, a sphere of
/// radius 1 at z = 6 between them; orthographic view over [−3, 3]².
fn shadow_scene(res: u32) -> String {
    format!(
        r#"Format {res} {res} 1
Projection "orthographic"
ScreenWindow -3 3 -3 3
PixelSamples 3 3
PixelFilter "box" 1 1
WorldBegin
LightSource "shadowpoint" 1 "intensity" 100 "from" [0 0 0] "shadowname" "raytrace"
AttributeBegin
  Surface "matte"
  {plane}
AttributeEnd
AttributeBegin
  Surface "constant"
  Color [0 0 1]
  Translate 0 0 6
  Sphere 1 -1 1 360
AttributeEnd
WorldEnd
"#,
        plane = square(8.0, 10.0)
    )
}

#[test]
fn a_ray_traced_shadow_covers_the_analytic_disk() {
    // The cone from the light at the origin tangent to the sphere (centre 6, radius 1) meets
    // the plane z = 10 in a disk of radius 10 · 1/√(6² − 1).
    let res = 120usize;
    let rgb = render_with(&shadow_scene(res as u32), 2, 16);
    let radius = 10.0 / 35f32.sqrt();
    let px = 6.0 / res as f32;
    let (mut dark_ok, mut lit_ok) = (0, 0);
    for y in 0..res {
        for x in 0..res {
            let (cx, cy) = (-3.0 + (x as f32 + 0.5) * px, 3.0 - (y as f32 + 0.5) * px);
            let r = (cx * cx + cy * cy).sqrt();
            let k = (y * res + x) * 3;
            let (red, blue) = (rgb[k], rgb[k + 2]);
            if r < 1.0 + px {
                continue; // the sphere itself (blue)
            }
            if r < radius - px {
                assert!(red < 1e-3, "({x},{y}) r={r} should be in shadow: {red}");
                dark_ok += 1;
            } else if r > radius + px && r < 2.9 {
                assert!(
                    red > 0.2 && blue > 0.2,
                    "({x},{y}) r={r} should be lit: {red}"
                );
                lit_ok += 1;
            }
        }
    }
    assert!(dark_ok > 500 && lit_ok > 1000, "{dark_ok} {lit_ok}");
}

#[test]
fn output_is_identical_for_any_thread_count_and_bucket_size() {
    let rib = shadow_scene(48);
    let a = render_with(&rib, 1, 16);
    let b = render_with(&rib, 2, 7);
    assert!(a == b, "images differ");
}

#[test]
fn displacement_that_traces_while_the_ray_geometry_is_built_on_several_threads() {
    // Twelve displaced spheres (their ray dicing shared among the build's threads) whose
    // displacement shader casts rays; ray-traced shadows make the first bucket build the ray
    // geometry. Must finish, and give the same picture on any thread count.
    let spheres: String = (0..12)
        .map(|i| {
            format!(
                "AttributeBegin\nTranslate {} {} 6\nSphere 0.4 -0.4 0.4 360\nAttributeEnd\n",
                (i % 4) as f32 - 1.5,
                (i / 4) as f32 - 1.0
            )
        })
        .collect();
    // The shadow scene's plane and light, its sphere joined by the displaced ones.
    let rib = shadow_scene(32).replace(
        "WorldEnd",
        &format!(
            "Attribute \"displacementbound\" \"float sphere\" [0.1]\n\
             Displacement \"tracedisp\"\nSurface \"matte\"\n{spheres}WorldEnd"
        ),
    );
    let one = render_with(&rib, 1, 16);
    for threads in [2, 4] {
        assert!(render_with(&rib, threads, 8) == one, "{threads} threads");
    }
}

#[test]
fn occlusion_of_an_open_plane_is_zero_and_inside_a_closed_box_one() {
    let open = format!(
        r#"Format 16 16 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
Surface "occltest"
{plane}
WorldEnd
"#,
        plane = square(1000.0, 5.0)
    );
    let rgb = film_rgb(&render_rib(&open, &[shaders()]));
    assert!(
        rgb.iter().all(|&v| v == 0.0),
        "open plane occluded: {:?}",
        &rgb[..6]
    );
    // The camera inside a closed box [−5, 5]³ (six walls), looking at the wall z = 5.
    let walls = CLOSED_BOX.join("\n");
    let closed = format!(
        r#"Format 16 16 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
Surface "occltest"
{walls}
WorldEnd
"#
    );
    let rgb = film_rgb(&render_rib(&closed, &[shaders()]));
    assert!(
        rgb.iter().all(|&v| (v - 1.0).abs() < 1e-6),
        "closed box not occluded: {:?}",
        &rgb[..6]
    );
}

#[test]
fn occlusion_from_a_map_name_is_traced_like_prman_occlusion() {
    // Aqsis's occlusion(mapname, P, N, samples, …): the map set is not read, the same
    // hemisphere is traced. One warning says so; open plane 0, closed box 1.
    let open = format!(
        "Format 16 16 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nWorldBegin\n\
         Surface \"occlmaptest\"\n{}\nWorldEnd\n",
        square(1000.0, 5.0)
    );
    let (film, diags, _) = common::render_rib_with(&open, &[shaders()], &RenderOptions::default());
    let rgb = film_rgb(&film);
    assert!(
        rgb.iter().all(|&v| v == 0.0),
        "open plane occluded: {:?}",
        &rgb[..6]
    );
    let warned: Vec<_> = diags
        .iter()
        .filter(|(d, _)| d.message.contains("from a map"))
        .collect();
    assert_eq!(warned.len(), 1, "{diags:?}");
    assert!(
        diags.iter().all(|(d, _)| !d.message.contains("\"blur\"")),
        "blur is the map lookup's, accepted quietly: {diags:?}"
    );
    let closed = format!(
        "Format 16 16 1\nProjection \"orthographic\"\nScreenWindow -1 1 -1 1\nWorldBegin\n\
         Surface \"occlmaptest\"\n{}\nWorldEnd\n",
        CLOSED_BOX.join("\n")
    );
    let rgb = film_rgb(&render_rib(&closed, &[shaders()]));
    assert!(
        rgb.iter().all(|&v| (v - 1.0).abs() < 1e-6),
        "closed box not occluded: {:?}",
        &rgb[..6]
    );
}

#[test]
fn refraction_through_a_glass_slab_shifts_a_line_by_the_slab_formula() {
    // A slab of thickness t tilted by θ about y; a vertical white line at x = 0 behind it. A
    // ray crossing the slab leaves parallel to itself, displaced sideways by
    // d = t (tan θ − tan θr) cos θ with sin θr = sin θ / n.
    let (theta, n, t) = (30f32.to_radians(), 1.5f32, 1.0f32);
    let theta_r = (theta.sin() / n).asin();
    let d = t * (theta.tan() - theta_r.tan()) * theta.cos();
    let res = 200usize;
    // Front face through (0, 0, 3) with normal (sin θ, 0, −cos θ); the back face t further.
    let (a, nrm) = (
        [theta.cos(), 0.0, theta.sin()],
        [theta.sin(), 0.0, -theta.cos()],
    );
    // The two faces wind oppositely, so both normals point out of the glass (the shader tells
    // entering from leaving by N·I).
    let face = |off: f32| {
        let c = [-nrm[0] * off, 0.0, 3.0 - nrm[2] * off];
        let sv = if off == 0.0 { -1.0 } else { 1.0 };
        let h = 3.0;
        let pt = |su: f32, sv: f32| {
            format!(
                "{} {} {}",
                c[0] + a[0] * su * h,
                c[1] + sv * h,
                c[2] + a[2] * su * h
            )
        };
        format!(
            "Polygon \"P\" [{} {} {} {}]",
            pt(-1.0, -sv),
            pt(1.0, -sv),
            pt(1.0, sv),
            pt(-1.0, sv)
        )
    };
    let rib = format!(
        r#"Format {res} 8 1
Projection "orthographic"
ScreenWindow -1 1 -0.04 0.04
PixelSamples 4 4
WorldBegin
AttributeBegin
  Surface "glasstest" "ior" {n}
  {front}
  {back}
AttributeEnd
AttributeBegin
  Surface "constant"
  Color [0 0 0]
  {wall}
AttributeEnd
AttributeBegin
  Surface "constant"
  Color [1 1 1]
  Polygon "P" [-0.02 -5 9.9  0.02 -5 9.9  0.02 5 9.9  -0.02 5 9.9]
AttributeEnd
WorldEnd
"#,
        front = face(0.0),
        back = face(t),
        wall = square(20.0, 10.0)
    );
    let rgb = film_rgb(&render_rib(&rib, &[shaders()]));
    // The line's centroid along the middle row, in screen units.
    let row = 4;
    let (mut sum, mut wsum) = (0f64, 0f64);
    for x in 0..res {
        let v = rgb[(row * res + x) * 3] as f64;
        let sx = -1.0 + (x as f64 + 0.5) * 2.0 / res as f64;
        sum += v * sx;
        wsum += v;
    }
    assert!(wsum > 0.5, "the line is not seen through the slab");
    let seen = sum / wsum;
    eprintln!("line seen at {seen}, slab formula {d}");
    let px = 2.0 / res as f64;
    assert!(
        (seen - d as f64).abs() < 0.5 * px,
        "line seen at {seen}, expected {d} (±{})",
        0.5 * px
    );
}

#[test]
fn gather_inside_a_closed_box_sees_only_its_walls() {
    // The camera inside a box whose five other walls are constant 0.5: every gather ray hits
    // one, so the mean of "surface:Ci" is 0.5 and no ray runs the else branch.
    let others = [
        "Polygon \"P\" [-5 -5 -5  5 -5 -5  5 5 -5  -5 5 -5]",
        "Polygon \"P\" [5 -5 -5  5 5 -5  5 5 5  5 -5 5]",
        "Polygon \"P\" [-5 -5 -5  -5 5 -5  -5 5 5  -5 -5 5]",
        "Polygon \"P\" [-5 5 -5  5 5 -5  5 5 5  -5 5 5]",
        "Polygon \"P\" [-5 -5 -5  5 -5 -5  5 -5 5  -5 -5 5]",
    ]
    .join("\n");
    let rib = format!(
        r#"Format 8 8 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
WorldBegin
AttributeBegin
  Surface "gathertest"
  Polygon "P" [-5 -5 5  5 -5 5  5 5 5  -5 5 5]
AttributeEnd
AttributeBegin
  Surface "constant"
  Color [0.5 0.5 0.5]
  {others}
AttributeEnd
WorldEnd
"#
    );
    let rgb = film_rgb(&render_rib(&rib, &[shaders()]));
    assert!(
        rgb.iter().all(|&v| (v - 0.5).abs() < 1e-6),
        "gather mean: {:?}",
        &rgb[..6]
    );
}

/// The six walls of the box from (−5, −5, −5) to (5, 5, 5), the camera inside it.
const CLOSED_BOX: [&str; 6] = [
    "Polygon \"P\" [-5 -5 5  5 -5 5  5 5 5  -5 5 5]",
    "Polygon \"P\" [-5 -5 -5  5 -5 -5  5 5 -5  -5 5 -5]",
    "Polygon \"P\" [5 -5 -5  5 5 -5  5 5 5  5 -5 5]",
    "Polygon \"P\" [-5 -5 -5  -5 5 -5  -5 5 5  -5 -5 5]",
    "Polygon \"P\" [-5 5 -5  5 5 -5  5 5 5  -5 5 5]",
    "Polygon \"P\" [-5 -5 -5  5 -5 -5  5 -5 5  -5 -5 5]",
];

/// indirectdiffuse() in a shader its own rays hit would recurse (samples to the power of the
/// ray depth): past `"trace" "maxdiffusedepth"` (default 1, as PRMan) it casts nothing and
/// reads black. Inside a closed box of `bounce` walls (0.5 glow + half the indirect light)
/// the camera sees 0.75 with one bounce and 0.875 with two.
#[test]
fn indirectdiffuse_stops_at_the_diffuse_depth() {
    let walls = CLOSED_BOX.join("\n");
    for (option, want) in [
        ("", 0.75f32),
        ("Option \"trace\" \"maxdiffusedepth\" 2", 0.875),
    ] {
        let rib = format!(
            r#"Format 4 4 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
{option}
WorldBegin
Surface "bounce"
{walls}
WorldEnd
"#
        );
        let rgb = film_rgb(&render_rib(&rib, &[shaders()]));
        assert!(
            rgb.iter().all(|&v| (v - want).abs() < 1e-5),
            "{option:?}: {:?} against {want}",
            &rgb[..6]
        );
    }
}

/// BMRT's radiosity (`Option "radiosity" "steps"` above 0) reaches shaders through ambient():
/// one traced bounce of the light the other surfaces send. Inside a closed box of
/// `glowambient` walls (0.5 glow + half of ambient()) every ray sees a wall lit only by the
/// ambient light (0.5 + 0.5·0.2 = 0.6), so the camera sees 0.5 + 0.5·(0.2 + 0.6) = 0.9; without
/// the option, 0.5 + 0.5·0.2 = 0.6. The lattice interpolation keeps a constant field exact.
#[test]
fn radiosity_adds_the_traced_bounce_to_ambient() {
    let walls = CLOSED_BOX.join("\n");
    for (option, want) in [("", 0.6f32), ("Option \"radiosity\" \"steps\" [10]", 0.9)] {
        let rib = format!(
            r#"Format 16 16 1
Projection "orthographic"
ScreenWindow -1 1 -1 1
{option}
WorldBegin
LightSource "ambientlight" 1 "intensity" 0.2
Surface "glowambient"
{walls}
WorldEnd
"#
        );
        let rgb = film_rgb(&render_rib(&rib, &[shaders()]));
        assert!(
            rgb.iter().all(|&v| (v - want).abs() < 1e-5),
            "{option:?}: {:?} against {want}",
            &rgb[..6]
        );
    }
}

/// Builds the first frame of `rib` with shaders compiled by `options`, and hands `f` a ray
/// tracer over it (camera depth 0, every light).
fn with_tracer<R>(
    rib: &str,
    options: arbor::sl::CompileOptions,
    f: impl FnOnce(&arbor::shade::rays::Tracer) -> R,
) -> R {
    use arbor::diag::{Diagnostics, SourceMap};
    use arbor::render::Camera;
    use arbor::scene::{build_scenes, BuildContext};
    use arbor::shade::rays::Tracer;
    use arbor::shade::system::ShadeSystem;
    use arbor::sl::ShaderLibrary;
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = arbor::rib::parse_bytes("scene.rib", rib.as_bytes(), &sources, &diags);
    let ctx = BuildContext::new(&sources, &diags);
    let scene = build_scenes(reqs, &ctx).remove(0);
    let library = ShaderLibrary::new(options);
    let camera = Camera::new(&scene);
    let sys = ShadeSystem {
        library: &library,
        sources: &sources,
        diags: &diags,
        textures: None,
        aovs: vec![],
        rays: Default::default(),
    };
    f(&Tracer {
        sys: &sys,
        scene: &scene,
        camera: &camera,
        depth: 0,
        skip_light: None,
    })
}

/// Builds the ray geometry of a one-primitive world seen by a 60° perspective camera.
fn ray_geometry(prim: &str) -> (usize, std::sync::Arc<arbor::ray::RayScene>) {
    let rib = format!(
        "Format 640 480 1\nProjection \"perspective\" \"fov\" [60]\nWorldBegin\n{prim}\nWorldEnd\n"
    );
    let rs = with_tracer(&rib, Default::default(), |t| {
        t.geometry().expect("ray geometry")
    });
    let mut rates: Vec<(usize, usize)> = rs.grids.iter().map(|g| (g.grid.nu, g.grid.nv)).collect();
    rates.sort();
    rates.dedup();
    (rates.len(), rs)
}

#[test]
fn an_orthographic_window_onto_a_large_scene_dices_it_for_rays_as_a_view_of_the_whole() {
    // RISpec's default projection under a scene written for a perspective camera: a 2-unit
    // window onto a 600-unit displaced room. Rays see the whole room; diced at the window's
    // 300 pixels per unit it was billions of micropolygons (gigabytes, minutes). Now as a
    // view fitting the room across twice the image: a million or so at most.
    let rib = r#"Format 600 600 1
WorldBegin
Attribute "displacementbound" "float sphere" [1]
Displacement "dented"
Surface "matte"
Translate 0 0 300
Polygon "P" [-300 -300 300  300 -300 300  300 300 300  -300 300 300]
Patch "bilinear" "P" [-300 -300 -300  300 -300 -300  -300 -300 300  300 -300 300]
Sphere 50 -50 50 360
WorldEnd
"#;
    let rs = with_tracer(rib, common::stdlib_options(&[]), |t| {
        t.geometry().expect("ray geometry")
    });
    assert!(
        rs.micropolygons > 1000 && rs.micropolygons < 2_000_000,
        "{} ray micropolygons",
        rs.micropolygons
    );
}

#[test]
fn ray_geometry_is_watertight_where_grids_of_different_rates_meet() {
    // A sphere close to the camera and a tilted torus split into pieces diced at different
    // rates (T-junctions along their shared edges): rays from all around aimed at points
    // inside the solid must all hit it.
    use glam::{Mat3, Vec3};
    let tilt = Mat3::from_axis_angle(Vec3::new(1.0, 1.0, 0.0).normalize(), 30f32.to_radians());
    let cases: [(&str, Box<dyn Fn(f32, f32) -> Vec3>); 2] = [
        (
            "Translate 0 0 2 Sphere 2 -2 2 360",
            Box::new(|a, b| Vec3::new(0.0, 0.0, 2.0) + Vec3::new(a, b, a * b) * 0.5),
        ),
        (
            "Translate 0 0 4 Rotate 30 1 1 0 Torus 1.5 0.7 0 360 360",
            Box::new(move |a, _| {
                let phi = a * std::f32::consts::PI;
                Vec3::new(0.0, 0.0, 4.0) + tilt * Vec3::new(1.5 * phi.cos(), 1.5 * phi.sin(), 0.0)
            }),
        ),
    ];
    for (prim, inside) in cases {
        let (rates, rs) = ray_geometry(prim);
        assert!(rates > 2, "{prim}: the test wants grids of several rates");
        let mut h = 1u32;
        let mut rnd = || {
            h = arbor::pattern::hash::hash_u32(h.wrapping_add(0x9e37_79b9));
            arbor::ray::unit(h) * 2.0 - 1.0
        };
        let mut misses = 0;
        let n = 200_000;
        for _ in 0..n {
            let d = Vec3::new(rnd(), rnd(), rnd()).normalize_or(Vec3::X);
            let target = inside(rnd(), rnd());
            let o = target + d * 50.0;
            if rs.bvh.closest(o, target - o, 0.0, 1.0).is_none() {
                misses += 1;
            }
        }
        assert_eq!(misses, 0, "{prim}: {misses} of {n} rays slipped through");
    }
}

/// Traces rays with explicit cones at a 20 × 20 bilinear patch in the plane z = 10 (s along
/// x, t along y) shaded by `footprint`; returns each ray's colour.
fn footprint_hits(rays: &[(glam::Vec3, arbor::ray::Cone)]) -> Vec<glam::Vec3> {
    use arbor::shade::exec::RayTracer;
    use glam::Vec3;
    let rib = "Format 64 64 1\nProjection \"perspective\" \"fov\" [60]\nWorldBegin\n\
               Surface \"footprint\"\n\
               Patch \"bilinear\" \"P\" [-10 -10 10  10 -10 10  -10 10 10  10 10 10]\nWorldEnd\n";
    with_tracer(rib, common::stdlib_options(&[shaders()]), |tracer| {
        let n = rays.len();
        let org = vec![Vec3::ZERO; n];
        let dir: Vec<Vec3> = rays.iter().map(|r| r.0).collect();
        let cones: Vec<arbor::ray::Cone> = rays.iter().map(|r| r.1).collect();
        let mut ci = vec![Vec3::ZERO; n];
        let mut dist = vec![0f32; n];
        tracer.trace(&org, &dir, &cones, &vec![true; n], &mut ci, &mut dist);
        ci
    })
}

#[test]
fn derivatives_at_a_ray_hit_follow_the_ray_cone() {
    // Cone of width 0.01 at the eye spreading 0.002 per unit. Head on, at distance 10 the
    // footprint is 0.03 wide: area(P) = 0.03², s and t change by 0.03 / 20 across it. At 45°
    // in x (distance 10√2) the width is w = 0.01 + 0.002·10√2 and the footprint stretches to
    // w√2 along x: area = √2·w², s changes by w√2 / 20, t by w / 20.
    use arbor::ray::Cone;
    use glam::Vec3;
    let cone = Cone {
        width: 0.01,
        spread: 0.002,
    };
    let got = footprint_hits(&[
        (Vec3::Z, cone),
        (Vec3::new(1.0, 0.0, 1.0), cone),
        (Vec3::Z, Cone::default()),
    ]);
    let close = |a: f32, b: f32| (a - b).abs() <= 0.01 * b.abs() + 1e-7;
    let head_on = Vec3::new(0.03, 0.0015, 0.0015);
    assert!(
        (0..3).all(|c| close(got[0][c], head_on[c])),
        "head on: {:?}, want {head_on:?}",
        got[0]
    );
    let w = 0.01 + 0.002 * 10.0 * std::f32::consts::SQRT_2;
    let oblique = Vec3::new(
        (std::f32::consts::SQRT_2 * w * w).sqrt(),
        w * std::f32::consts::SQRT_2 / 20.0,
        w / 20.0,
    );
    assert!(
        (0..3).all(|c| close(got[1][c], oblique[c])),
        "45°: {:?}, want {oblique:?}",
        got[1]
    );
    // A ray of no width sees a point: no derivatives.
    assert_eq!(got[2], Vec3::ZERO);
}

#[test]
fn the_footprint_seen_in_a_flat_mirror_grows_with_the_whole_path() {
    // Perspective camera at the origin, a flat mirror at z = 5 facing it, and behind the
    // camera a wall at z = −5 or z = −15 that shows its footprint's width (sqrt(area(P))).
    // The camera's pixel cone reflects off a flat mirror unchanged, so the width at the
    // wall is the pixel cone's at the whole path length: 5 + 10 against 5 + 20 (the
    // mirror's micropolygon width spreading by the angle between neighbouring reflected
    // rays).
    let render = |wall: f32| {
        let rib = format!(
            r#"Format 16 16 1
Projection "perspective" "fov" [30]
PixelSamples 2 2
WorldBegin
AttributeBegin
  Surface "mirrortest"
  Patch "bilinear" "P" [-3 -3 5  3 -3 5  -3 3 5  3 3 5]
AttributeEnd
AttributeBegin
  Surface "footprint"
  Patch "bilinear" "P" [-40 -40 {wall}  40 -40 {wall}  -40 40 {wall}  40 40 {wall}]
AttributeEnd
WorldEnd
"#
        );
        let rgb = film_rgb(&render_rib(&rib, &[shaders()]));
        // The four centre pixels' red.
        [(7, 7), (8, 7), (7, 8), (8, 8)]
            .iter()
            .map(|&(x, y)| rgb[(y * 16 + x) * 3])
            .sum::<f32>()
            / 4.0
    };
    let (near, far) = (render(-5.0), render(-15.0));
    assert!(near > 0.0, "the footprint has a width: {near}");
    // Micropolygons of ShadingRate 1 are a pixel wide: the cone is the pixel's.
    let pixel = 2.0 * 15f32.to_radians().tan() / 16.0;
    assert!(
        (near - 15.0 * pixel).abs() < 0.05 * 15.0 * pixel,
        "footprint {near}, want the pixel cone's {}",
        15.0 * pixel
    );
    let ratio = far / near;
    assert!(
        (ratio - 25.0 / 15.0).abs() < 0.03 * 25.0 / 15.0,
        "footprints {near} and {far}: ratio {ratio}, want 25/15"
    );
}

/// A hit record's sixteen numbers are its fields in order (N, Ng, dPdu, dPdv, u v s t), and
/// weighting and summing them lane by lane, as hit shading does, gives each field's
/// `c0·w0 + c1·w1 + c2·w2 + c3·w3` bit for bit (the same operations in the same order).
#[test]
fn hit_records_interpolate_lane_by_lane_as_field_by_field() {
    use arbor::ray::geometry::HitVertex;
    use glam::Vec3;
    let mut h = 5u32;
    let mut rnd = || {
        h = arbor::pattern::hash::hash_u32(h);
        (h as f32 / u32::MAX as f32) * 2.0 - 1.0
    };
    for _ in 0..200 {
        let mut v3 = || Vec3::new(rnd(), rnd(), rnd()) * 7.0;
        let c: [HitVertex; 4] = std::array::from_fn(|_| HitVertex {
            n: v3(),
            ng: v3(),
            dpdu: v3(),
            dpdv: v3(),
            uvst: [v3().x, v3().y, v3().z, v3().x],
        });
        let w = [rnd(), rnd(), rnd(), rnd()].map(f32::abs);
        let f = c.map(|v| v.floats());
        let lanes: [f32; 16] = std::array::from_fn(|e| {
            f[0][e] * w[0] + f[1][e] * w[1] + f[2][e] * w[2] + f[3][e] * w[3]
        });
        let m3 = |g: fn(&HitVertex) -> Vec3| {
            g(&c[0]) * w[0] + g(&c[1]) * w[1] + g(&c[2]) * w[2] + g(&c[3]) * w[3]
        };
        let mut want = Vec::new();
        for v in [m3(|v| v.n), m3(|v| v.ng), m3(|v| v.dpdu), m3(|v| v.dpdv)] {
            want.extend(v.to_array());
        }
        for e in 0..4 {
            want.push(
                c[0].uvst[e] * w[0]
                    + c[1].uvst[e] * w[1]
                    + c[2].uvst[e] * w[2]
                    + c[3].uvst[e] * w[3],
            );
        }
        assert_eq!(
            lanes.map(f32::to_bits).to_vec(),
            want.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(f[0][0].to_bits(), c[0].n.x.to_bits());
        assert_eq!(f[0][12].to_bits(), c[0].uvst[0].to_bits());
    }
}
