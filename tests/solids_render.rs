//! Constructive solid geometry (`SolidBegin`) through the whole pipeline, checked against
//! analytic spheres: coverage and depth of differences, intersections, unions and nested
//! solids, and the cut faces' normals (a shader paints N·I < 0 green, otherwise red).

mod common;

use arbor::diag::{Diagnostics, SourceMap};
use arbor::film::Film;
use arbor::pipeline::{render_text, Settings};

/// Pixels across the frame; the screen window is [-1.5, 1.5]² with the camera 5 units away.
const N: usize = 60;
const PIX: f32 = 3.0 / N as f32;

const FACING: &str = "surface facing() {\n  Oi = Os;\n  Ci = Oi * ((N . I < 0) ? color(0, 1, 0) : color(1, 0, 0));\n}\n";

fn render(world: &str) -> Film {
    let dir = common::scratch("solids");
    std::fs::write(dir.join("facing.sl"), FACING).unwrap();
    let text = format!(
        "Format {N} {N} 1\nPixelSamples 4 4\nPixelFilter \"box\" 1 1\nProjection \"orthographic\"\n\
         ScreenWindow -1.5 1.5 -1.5 1.5\nShadingRate 0.25\nTranslate 0 0 5\nWorldBegin\n\
         Surface \"facing\"\n{world}WorldEnd\n"
    );
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let settings = Settings {
        threads: 1,
        shader_paths: vec![dir.display().to_string()],
        ..Default::default()
    };
    let films = render_text(&text, &settings, &sources, &diags);
    let report = diags.render_plain(&sources);
    assert!(!diags.has_errors(), "{report}");
    assert!(!report.contains("not implemented"), "{report}");
    films.into_iter().next().expect("one film")
}

/// World x, y of pixel (i, j)'s centre.
fn centre(i: usize, j: usize) -> (f32, f32) {
    (-1.5 + (i as f32 + 0.5) * PIX, 1.5 - (j as f32 + 0.5) * PIX)
}

fn pixel_at(x: f32, y: f32) -> (usize, usize) {
    (((x + 1.5) / PIX) as usize, ((1.5 - y) / PIX) as usize)
}

fn sphere(r: f32, c: [f32; 3]) -> String {
    format!(
        "SolidBegin \"primitive\"\nTransformBegin\nTranslate {} {} {}\nSphere {r} {} {r} 360\nTransformEnd\nSolidEnd\n",
        c[0], c[1], c[2], -r
    )
}

/// Distance from (x, y) to the edge of the disc of radius r about c (negative inside).
fn disc(x: f32, y: f32, r: f32, c: [f32; 3]) -> f32 {
    ((x - c[0]).powi(2) + (y - c[1]).powi(2)).sqrt() - r
}

/// Every pixel at least one pixel inside `inside` (signed distance < −PIX) is covered, every
/// pixel at least one pixel outside is empty; interior pixels are green (front-facing N). A
/// sample in 16 may slip through a crack between grids (as it does without CSG).
fn check_coverage(f: &Film, sdf: impl Fn(f32, f32) -> f32) {
    let mut checked = 0;
    for j in 0..N {
        for i in 0..N {
            let (x, y) = centre(i, j);
            let d = sdf(x, y);
            let p = f.pixel(i, j);
            if d < -PIX {
                assert!(
                    p[3] > 0.9,
                    "pixel ({i},{j}) at ({x},{y}) should be covered: {p:?}"
                );
                assert!(
                    p[0] < 0.1 && p[1] > 0.9,
                    "pixel ({i},{j}) faces away: {p:?}"
                );
                checked += 1;
            } else if d > PIX {
                assert!(
                    p[3] < 0.01,
                    "pixel ({i},{j}) at ({x},{y}) should be empty: {p:?}"
                );
            }
        }
    }
    assert!(checked > 50);
}

fn depth(f: &Film, x: f32, y: f32) -> f32 {
    let (i, j) = pixel_at(x, y);
    f.pixel(i, j)[4]
}

/// On the axis of sphere B (radius 0.7 at `b`, cut out of A): the cut face is B's back, at
/// camera depth 5 + b.z + the sphere's half-chord there, not A's front.
fn assert_cut_face(f: &Film, b: [f32; 3]) {
    let (x, y) = centre(pixel_at(0.6, 0.0).0, pixel_at(0.6, 0.0).1);
    let want = 5.0 + b[2] + (0.49 - (x - b[0]).powi(2) - y * y).sqrt();
    let z = depth(f, x, y);
    assert!(
        (z - want).abs() < 0.05,
        "cut face at depth {z}, want {want}"
    );
}

#[test]
fn a_difference_of_spheres_shows_the_cut_face_facing_out() {
    let a = [0.0, 0.0, 0.0];
    let b = [0.6, 0.0, -0.5];
    let f = render(&format!(
        "SolidBegin \"difference\"\n{}{}SolidEnd\n",
        sphere(1.0, a),
        sphere(0.7, b)
    ));
    // In A's disc, less where B's cap pokes out of A towards the eye… the silhouette is A's
    // disc (B's part outside A is removed); the cut face is B's far side, seen from inside B.
    check_coverage(&f, |x, y| disc(x, y, 1.0, a));
    // On the axis of B: the cut face, B's back, at z = −0.5 + 0.7 (camera depth 5.2), not A's
    // front (4.2).
    assert_cut_face(&f, b);
    // Away from B: A's front.
    let (x, y) = centre(pixel_at(-0.6, 0.0).0, pixel_at(-0.6, 0.0).1);
    let want = 5.0 - (1.0 - x * x - y * y).sqrt();
    assert!((depth(&f, x, y) - want).abs() < 0.05);
}

#[test]
fn intersection_and_union_cover_their_analytic_outlines() {
    let a = [-0.45, 0.0, 0.0];
    let b = [0.45, 0.1, 0.2];
    let f = render(&format!(
        "SolidBegin \"intersection\"\n{}{}SolidEnd\n",
        sphere(1.0, a),
        sphere(0.9, b)
    ));
    check_coverage(&f, |x, y| disc(x, y, 1.0, a).max(disc(x, y, 0.9, b)));
    // The lens's front at x = −0.3 is B's surface (the nearer of the two fronts is A's).
    let (x, y) = centre(pixel_at(-0.3, 0.0).0, pixel_at(-0.3, 0.0).1);
    let za = -(1.0 - (x - a[0]).powi(2) - y * y).sqrt();
    let zb = b[2] - (0.81 - (x - b[0]).powi(2) - (y - b[1]).powi(2)).sqrt();
    let want = 5.0 + za.max(zb);
    assert!(
        (depth(&f, x, y) - want).abs() < 0.05,
        "{} vs {want}",
        depth(&f, x, y)
    );
    let f = render(&format!(
        "SolidBegin \"union\"\n{}{}SolidEnd\n",
        sphere(1.0, a),
        sphere(0.9, b)
    ));
    check_coverage(&f, |x, y| disc(x, y, 1.0, a).min(disc(x, y, 0.9, b)));
}

#[test]
fn nested_solids_subtract_a_shell() {
    // A − (B − C): B − C is a shell; where C lies inside A, A keeps its material.
    let (a, b, c) = ([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]);
    let f = render(&format!(
        "SolidBegin \"difference\"\n{}SolidBegin \"difference\"\n{}{}SolidEnd\nSolidEnd\n",
        sphere(1.0, a),
        sphere(0.9, b),
        sphere(0.5, c)
    ));
    check_coverage(&f, |x, y| disc(x, y, 1.0, a));
    // At x = 0.6 (outside C's disc) the shell removes A up to B's back.
    let (x, y) = centre(pixel_at(0.6, 0.0).0, pixel_at(0.6, 0.0).1);
    let want = 5.0 + b[2] + (0.81 - x * x - y * y).sqrt();
    assert!(
        (depth(&f, x, y) - want).abs() < 0.05,
        "{} vs {want}",
        depth(&f, x, y)
    );
    // At x = 0.3, C keeps A's front.
    let (x, y) = centre(pixel_at(0.3, 0.0).0, pixel_at(0.3, 0.0).1);
    let want = 5.0 - (1.0 - x * x - y * y).sqrt();
    assert!(
        (depth(&f, x, y) - want).abs() < 0.05,
        "{} vs {want}",
        depth(&f, x, y)
    );
}

#[test]
fn a_lone_primitive_solid_renders_as_its_surfaces() {
    let plain = render(
        &sphere(1.0, [0.0; 3])
            .replace("SolidBegin \"primitive\"\n", "")
            .replace("SolidEnd\n", ""),
    );
    let solid = render(&sphere(1.0, [0.0; 3]));
    assert_eq!(plain.data, solid.data);
}

/// A − B written inside `ObjectBegin` (Aqsis's regression scene Bug1013736 cuts a groove in a
/// box this way, with the cutter itself an instanced object).
fn difference_object(a: [f32; 3], b: [f32; 3]) -> String {
    format!(
        "ObjectBegin \"cutter\"\n{}ObjectEnd\nObjectBegin \"cut\"\nSolidBegin \"difference\"\n{}\
         ObjectInstance \"cutter\"\nSolidEnd\nObjectEnd\n",
        sphere(0.7, b),
        sphere(1.0, a)
    )
}

#[test]
fn solids_inside_object_definitions_stay_solids_when_instanced() {
    let (a, b) = ([0.0, 0.0, 0.0], [0.6, 0.0, -0.5]);
    let f = render(&format!(
        "{}ObjectInstance \"cut\"\n",
        difference_object(a, b)
    ));
    // The same picture as the difference written out: B's cap outside A is removed.
    check_coverage(&f, |x, y| disc(x, y, 1.0, a));
    assert_cut_face(&f, b);
}

#[test]
fn each_instance_of_a_solid_object_is_its_own_solid() {
    // Two instances side by side, each A − B: were they one tree, the second A would be
    // subtracted from the first (a difference keeps only its first child).
    let (a, b) = ([0.0, 0.0, 0.0], [0.6, 0.0, -0.5]);
    let f = render(&format!(
        "{}Scale 0.5 0.5 0.5\nTransformBegin\nTranslate -1.2 0 0\nObjectInstance \"cut\"\n\
         TransformEnd\nTransformBegin\nTranslate 1.2 0 0\nObjectInstance \"cut\"\nTransformEnd\n",
        difference_object(a, b)
    ));
    check_coverage(&f, |x, y| {
        disc(x, y, 0.5, [-0.6, 0.0, 0.0]).min(disc(x, y, 0.5, [0.6, 0.0, 0.0]))
    });
}
