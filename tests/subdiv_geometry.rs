//! Geometry tests of Catmull–Clark subdivision through `geom::surfaces_for`: the limit
//! surface of a cube lies inside its control hull and is symmetric, interpolateboundary keeps
//! a quad's corners, and an infinitely sharp crease keeps the surface on the crease's plane.

use std::sync::Arc;

use arbor::diag::{Diagnostics, Span};
use arbor::geom::{surfaces_for, Surface};
use arbor::scene::{
    Attributes, Class, Decl, Geometry, Param, ParamData, ParamList, ParamType, Primitive,
};
use glam::{Mat4, Vec3};

const CUBE_P: [f32; 24] = [
    -1., -1., 1., 1., -1., 1., -1., 1., 1., 1., 1., 1., -1., 1., -1., 1., 1., -1., -1., -1., -1.,
    1., -1., -1.,
];
const CUBE_F: [u32; 24] = [
    0, 1, 3, 2, 2, 3, 5, 4, 4, 5, 7, 6, 6, 7, 1, 0, 1, 7, 5, 3, 6, 0, 2, 4,
];

fn mesh(
    nverts: &[u32],
    verts: &[u32],
    p: &[f32],
    tags: &[(&str, Vec<i64>, Vec<f32>)],
) -> Primitive {
    let geometry = Geometry::SubdivisionMesh {
        scheme: "catmull-clark".into(),
        nverts: nverts.to_vec(),
        verts: verts.to_vec(),
        tags: tags.iter().map(|t| t.0.to_string()).collect(),
        nargs: tags
            .iter()
            .flat_map(|t| [t.1.len() as u32, t.2.len() as u32])
            .collect(),
        intargs: tags.iter().flat_map(|t| t.1.clone()).collect(),
        floatargs: tags.iter().flat_map(|t| t.2.clone()).collect(),
    };
    let param = Param {
        name: "P".into(),
        decl: Decl {
            class: Class::Vertex,
            ty: ParamType::Point,
            array_len: 1,
        },
        data: ParamData::Floats(p.to_vec()),
        span: Span::default(),
    };
    Primitive {
        geometry: Arc::new(geometry),
        primvars: Arc::new(ParamList(vec![param])),
        attributes: Arc::new(Attributes::default()),
        world_from_object: Mat4::IDENTITY.into(),
        span: Span::default(),
        motion: None,
    }
}

/// Every diced corner point (and normal) of the limit mesh, camera = object space.
fn limit_points(prim: &Primitive) -> Vec<(Vec3, Vec3)> {
    let d = Diagnostics::new();
    let mut stack: Vec<Box<dyn Surface>> = surfaces_for(0, prim, Mat4::IDENTITY, &d);
    assert!(!d.has_errors());
    let mut out = Vec::new();
    while let Some(s) = stack.pop() {
        if s.diceable() {
            let g = s.dice(2, 2);
            out.extend(g.p.iter().copied().zip(g.n.iter().copied()));
        } else {
            stack.extend(s.split());
        }
    }
    assert!(!out.is_empty());
    out
}

#[test]
fn cube_limit_lies_in_the_hull_and_is_symmetric() {
    let pts = limit_points(&mesh(&[4; 6], &CUBE_F, &CUBE_P, &[]));
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for &(p, n) in &pts {
        assert!(p.abs().max_element() <= 1.0 + 1e-5, "{p} outside the hull");
        lo = lo.min(p);
        hi = hi.max(p);
        // Limit normals point outward (away from the centre) and are unit.
        assert!((n.length() - 1.0).abs() < 1e-3, "{n}");
        assert!(n.dot(p) > 0.0, "normal {n} at {p}");
    }
    // Strictly inside the hull (the limit of a cube is rounded), the same on every axis, and
    // symmetric about the centre.
    assert!(hi.max_element() < 0.95, "{hi}");
    for a in 0..3 {
        assert!((hi[a] + lo[a]).abs() < 1e-4, "{lo} {hi}");
        assert!((hi[a] - hi[0]).abs() < 1e-4, "{hi}");
    }
    for &(p, _) in &pts {
        assert!(
            pts.iter().any(|&(q, _)| (q + p).length() < 1e-4),
            "{p} has no mirror"
        );
    }
}

#[test]
fn interpolateboundary_keeps_a_quads_corners() {
    let p = [0., 0., 0., 2., 0., 0., 2., 2., 0., 0., 2., 0.];
    let pts = limit_points(&mesh(
        &[4],
        &[0, 1, 2, 3],
        &p,
        &[("interpolateboundary", vec![], vec![])],
    ));
    for c in p.chunks(3) {
        let c = Vec3::from_slice(c);
        assert!(
            pts.iter().any(|&(q, _)| (q - c).length() < 1e-5),
            "corner {c} lost"
        );
    }
    for &(q, _) in &pts {
        assert!(q.z.abs() < 1e-6 && q.x >= -1e-6 && q.x <= 2.0 + 1e-6);
    }
}

#[test]
fn sharp_crease_keeps_the_edge_on_the_crease_line() {
    // The loop around the top face (y = 1) is infinitely sharp: its limit curve stays in y = 1
    // and reaches the middle of each top edge.
    let crease = ("crease", vec![2, 3, 5, 4, 2], vec![10.0]);
    let pts = limit_points(&mesh(&[4; 6], &CUBE_F, &CUBE_P, &[crease]));
    let top = pts.iter().map(|p| p.0.y).fold(f32::MIN, f32::max);
    assert!((top - 1.0).abs() < 1e-5, "top {top}");
    // The limit crease is the uniform cubic B-spline of the square loop: half-way along edge
    // 2–3 it is at (P0 + 23 P1 + 23 P2 + P3) / 48 = (0, 1, 44/48).
    let near = pts
        .iter()
        .filter(|p| (p.0.y - 1.0).abs() < 1e-5)
        .map(|p| (p.0 - Vec3::new(0.0, 1.0, 44.0 / 48.0)).length())
        .fold(f32::MAX, f32::min);
    assert!(near < 1e-3, "{near}");
    // Without the crease the top is lower.
    let smooth = limit_points(&mesh(&[4; 6], &CUBE_F, &CUBE_P, &[]));
    let top_s = smooth.iter().map(|p| p.0.y).fold(f32::MIN, f32::max);
    assert!(top_s < 0.95);
}

#[test]
fn triangles_and_pentagons_subdivide() {
    // A pyramid: square base and four triangles.
    let p = [
        -1., 0., -1., 1., 0., -1., 1., 0., 1., -1., 0., 1., 0., 1.5, 0.,
    ];
    let f = [0, 3, 2, 1, 0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4];
    let pts = limit_points(&mesh(&[4, 3, 3, 3, 3], &f, &p, &[]));
    for &(q, n) in &pts {
        assert!(q.is_finite() && n.is_finite());
        assert!(q.y > 0.0 && q.y < 1.5);
    }
}
