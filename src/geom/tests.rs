//! Tests of the geometry module: quadric formulas, orientation, bounds under splitting, polygon
//! triangulation and primitive-variable interpolation.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::quadric::{Profile, Quadric};
use super::*;
use crate::diag::{Diagnostics, Span};
use crate::scene::{Attributes, Class, Decl, Param, ParamData, ParamList, ParamType};

fn prim(geometry: Geometry, params: Vec<Param>, attrs: Attributes, m: Mat4) -> Primitive {
    Primitive {
        geometry: Arc::new(geometry),
        primvars: Arc::new(ParamList(params)),
        attributes: Arc::new(attrs),
        world_from_object: m.into(),
        span: Span::default(),
        motion: None,
    }
}

fn param(name: &str, class: Class, ty: ParamType, data: &[f32]) -> Param {
    Param {
        name: name.to_string().into(),
        decl: Decl {
            class,
            ty,
            array_len: 1,
        },
        data: ParamData::Floats(data.to_vec()),
        span: Span::default(),
    }
}

fn one(p: &Primitive, cam: Mat4) -> Box<dyn Surface> {
    let d = Diagnostics::new();
    let mut s = surfaces_for(0, p, cam, &d);
    assert!(d.snapshot().is_empty(), "{:?}", d.snapshot());
    assert_eq!(s.len(), 1);
    s.pop().unwrap()
}

fn sphere(r: f32, zmin: f32, zmax: f32, thetamax: f32) -> Geometry {
    Geometry::Sphere {
        radius: r,
        zmin,
        zmax,
        thetamax,
    }
}

fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
    (a - b).length() <= tol
}

fn contains(outer: &Bound, inner: &Bound) -> bool {
    inner.min.cmpge(outer.min).all() && inner.max.cmple(outer.max).all()
}

/// Every quadric once, with partial sweeps and odd parameters.
fn all_quadrics() -> Vec<Geometry> {
    vec![
        sphere(1.5, -1.0, 1.2, 300.0),
        sphere(1.0, -2.0, 2.0, 360.0),
        sphere(-1.0, -0.5, 2.0, 180.0),
        Geometry::Cone {
            height: 2.0,
            radius: 1.0,
            thetamax: 270.0,
        },
        Geometry::Cylinder {
            radius: 0.5,
            zmin: -1.0,
            zmax: 2.0,
            thetamax: 120.0,
        },
        Geometry::Hyperboloid {
            p1: Vec3::new(1.0, -0.5, -1.0),
            p2: Vec3::new(0.2, 1.0, 1.0),
            thetamax: 330.0,
        },
        Geometry::Hyperboloid {
            p1: Vec3::new(-1.0, 0.0, 0.0),
            p2: Vec3::new(1.0, 0.0, 1.0),
            thetamax: 200.0,
        },
        Geometry::Paraboloid {
            rmax: 1.0,
            zmin: 0.0,
            zmax: 2.0,
            thetamax: 360.0,
        },
        Geometry::Disk {
            height: 0.5,
            radius: 1.0,
            thetamax: -250.0,
        },
        Geometry::Torus {
            rmajor: 2.0,
            rminor: 0.5,
            phimin: -30.0,
            phimax: 250.0,
            thetamax: 360.0,
        },
    ]
}

/// The RISpec §5.3 formula for each quadric, written independently of the implementation.
fn spec_point(g: &Geometry, u: f32, v: f32) -> Vec3 {
    let rot = |x: f32, y: f32, z: f32, th: f32| {
        Vec3::new(x * th.cos() - y * th.sin(), x * th.sin() + y * th.cos(), z)
    };
    match *g {
        Geometry::Sphere {
            radius: r,
            zmin,
            zmax,
            thetamax,
        } => {
            let pmin = if zmin > -r {
                (zmin / r).asin()
            } else {
                -PI / 2.0
            };
            let pmax = if zmax < r {
                (zmax / r).asin()
            } else {
                PI / 2.0
            };
            let phi = pmin + v * (pmax - pmin);
            let th = u * thetamax.to_radians();
            Vec3::new(
                r * th.cos() * phi.cos(),
                r * th.sin() * phi.cos(),
                r * phi.sin(),
            )
        }
        Geometry::Cone {
            height,
            radius,
            thetamax,
        } => {
            let th = u * thetamax.to_radians();
            Vec3::new(
                radius * (1.0 - v) * th.cos(),
                radius * (1.0 - v) * th.sin(),
                v * height,
            )
        }
        Geometry::Cylinder {
            radius,
            zmin,
            zmax,
            thetamax,
        } => {
            let th = u * thetamax.to_radians();
            Vec3::new(
                radius * th.cos(),
                radius * th.sin(),
                zmin + v * (zmax - zmin),
            )
        }
        Geometry::Hyperboloid { p1, p2, thetamax } => {
            let p = (1.0 - v) * p1 + v * p2;
            rot(p.x, p.y, p.z, u * thetamax.to_radians())
        }
        Geometry::Paraboloid {
            rmax,
            zmin,
            zmax,
            thetamax,
        } => {
            let z = zmin + v * (zmax - zmin);
            let r = rmax * (z / zmax).sqrt();
            rot(r, 0.0, z, u * thetamax.to_radians())
        }
        Geometry::Disk {
            height,
            radius,
            thetamax,
        } => rot(radius * (1.0 - v), 0.0, height, u * thetamax.to_radians()),
        Geometry::Torus {
            rmajor,
            rminor,
            phimin,
            phimax,
            thetamax,
        } => {
            let phi = (phimin + v * (phimax - phimin)).to_radians();
            let r = rminor * phi.cos();
            rot(
                rmajor + r,
                0.0,
                rminor * phi.sin(),
                u * thetamax.to_radians(),
            )
        }
        _ => unreachable!(),
    }
}

#[test]
fn sphere_points_on_sphere_and_normals_outward() {
    let cam = Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0));
    let p = prim(
        sphere(2.0, -2.0, 2.0, 360.0),
        vec![],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let g = one(&p, cam).dice(9, 7);
    let c = Vec3::new(0.0, 0.0, 10.0);
    assert_eq!(g.len(), 63);
    for k in 0..g.len() {
        assert!(((g.p[k] - c).length() - 2.0).abs() < 1e-4);
        let outward = (g.p[k] - c) / 2.0;
        // Including the poles, where dPdu vanishes.
        assert!(
            close(g.ng[k], outward, 2e-3),
            "{k}: {} vs {}",
            g.ng[k],
            outward
        );
        assert_eq!(g.n[k], g.ng[k]);
        assert_eq!(g.i[k], g.p[k]);
    }
    // u sweeps theta, v sweeps phi from the south pole up.
    assert!(close(g.p[0], c + Vec3::new(0.0, 0.0, -2.0), 1e-4));
    assert!(close(g.p[4 + 3 * 9], c + Vec3::new(-2.0, 0.0, 0.0), 1e-4));
    assert!((g.du - 0.125).abs() < 1e-6 && (g.dv - 1.0 / 6.0).abs() < 1e-6);
}

#[test]
fn orientation_rules() {
    let cam = Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0));
    let outward =
        |g: &Grid| (0..g.len()).all(|k| g.ng[k].dot(g.p[k] - Vec3::new(0.0, 0.0, 10.0)) > 0.0);
    // ReverseOrientation turns the normals inward.
    let mut a = Attributes::default();
    a.reverse_orientation = true;
    let g = one(
        &prim(sphere(1.0, -1.0, 1.0, 360.0), vec![], a, Mat4::IDENTITY),
        cam,
    )
    .dice(5, 5);
    assert!((0..g.len()).all(|k| g.ng[k].dot(g.p[k] - Vec3::new(0.0, 0.0, 10.0)) < 0.0));
    // A mirroring transform with a matching orientation keeps them outward.
    let mirror = Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0));
    let g = one(
        &prim(
            sphere(1.0, -1.0, 1.0, 360.0),
            vec![],
            Attributes::default(),
            mirror,
        ),
        cam,
    )
    .dice(5, 5);
    assert!(outward(&g));
    // Negative thetamax turns the quadric inside out (RISpec §5.3).
    let g = one(
        &prim(
            sphere(1.0, -1.0, 1.0, -360.0),
            vec![],
            Attributes::default(),
            Mat4::IDENTITY,
        ),
        cam,
    )
    .dice(5, 5);
    assert!((0..g.len()).all(|k| g.ng[k].dot(g.p[k] - Vec3::new(0.0, 0.0, 10.0)) < 0.0));
    // The disk's normal is +z for positive thetamax.
    let g = one(
        &prim(
            Geometry::Disk {
                height: 1.0,
                radius: 1.0,
                thetamax: 360.0,
            },
            vec![],
            Attributes::default(),
            Mat4::IDENTITY,
        ),
        Mat4::IDENTITY,
    )
    .dice(4, 4);
    assert!((0..g.len()).all(|k| close(g.ng[k], Vec3::Z, 1e-4)));
}

#[test]
fn partial_sweep_stays_in_quadrant() {
    let p = prim(
        sphere(1.0, -1.0, 1.0, 90.0),
        vec![],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let s = one(&p, Mat4::IDENTITY);
    let g = s.dice(8, 8);
    assert!(g.p.iter().all(|p| p.x >= -1e-6 && p.y >= -1e-6));
    let b = s.bound();
    assert!(b.min.x > -1e-3 && b.min.y > -1e-3 && b.max.x < 1.001 && b.max.y < 1.001);
    assert!(b.min.z < -0.999 && b.max.z > 0.999);
}

#[test]
fn quadric_corners_match_rispec_and_derivatives_match_differences() {
    // A non-trivial placement: the formulas are checked after it.
    let m = Mat4::from_rotation_x(0.4) * Mat4::from_scale(Vec3::new(1.0, 2.0, 0.5));
    let cam = Mat4::from_translation(Vec3::new(0.3, 0.0, 6.0));
    for geom in all_quadrics() {
        let s = one(&prim(geom.clone(), vec![], Attributes::default(), m), cam);
        let g = s.dice(3, 3);
        for (k, (u, v)) in [
            (0, (0.0, 0.0)),
            (2, (1.0, 0.0)),
            (6, (0.0, 1.0)),
            (8, (1.0, 1.0)),
            (4, (0.5, 0.5)),
        ] {
            let want = (cam * m).transform_point3(spec_point(&geom, u, v));
            assert!(
                close(g.p[k], want, 1e-4),
                "{geom:?} at ({u},{v}): {} vs {want}",
                g.p[k]
            );
            assert_eq!((g.u[k], g.v[k]), (u, v));
        }
        // dPdu, dPdv against central differences of the spec formula at the centre.
        let h = 1e-3;
        let f = |u: f32, v: f32| (cam * m).transform_point3(spec_point(&geom, u, v));
        let fu = (f(0.5 + h, 0.5) - f(0.5 - h, 0.5)) / (2.0 * h);
        let fv = (f(0.5, 0.5 + h) - f(0.5, 0.5 - h)) / (2.0 * h);
        let tol = 2e-2 * fu.length().max(fv.length()).max(1.0);
        assert!(
            close(g.dpdu[4], fu, tol),
            "{geom:?} dPdu {} vs {fu}",
            g.dpdu[4]
        );
        assert!(
            close(g.dpdv[4], fv, tol),
            "{geom:?} dPdv {} vs {fv}",
            g.dpdv[4]
        );
        // Unit normals perpendicular to the tangents.
        for k in 0..g.len() {
            assert!((g.n[k].length() - 1.0).abs() < 1e-4, "{geom:?} {k}");
            assert!(g.n[k].dot(g.dpdu[k]).abs() < 1e-3 * (1.0 + g.dpdu[k].length()));
        }
    }
}

/// A tiny deterministic generator for property-style tests.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> u32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) as u32
    }
}

#[test]
fn split_children_inside_parent_bound_and_grids_inside_bound() {
    let m = Mat4::from_rotation_y(0.7) * Mat4::from_rotation_z(0.3);
    let cam = Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0));
    let mut rng = Lcg(7);
    for geom in all_quadrics() {
        let root = one(&prim(geom.clone(), vec![], Attributes::default(), m), cam);
        for _walk in 0..6 {
            let mut cur: Box<dyn Surface> = root.split().swap_remove(0);
            let mut parent_bound = root.bound();
            for _depth in 0..10 {
                let b = cur.bound();
                assert!(
                    contains(&parent_bound, &b),
                    "{geom:?}: {b:?} not in {parent_bound:?}"
                );
                let g = cur.dice(6, 6);
                for p in &g.p {
                    assert!(
                        p.cmpge(b.min).all() && p.cmple(b.max).all(),
                        "{geom:?}: {p} outside {b:?}"
                    );
                }
                let mut kids = cur.split();
                assert_eq!(kids.len(), 2);
                parent_bound = b;
                cur = kids.swap_remove((rng.next() % 2) as usize);
            }
        }
    }
}

#[test]
fn dicing_rates_agree_on_the_surface() {
    let cam = Mat4::from_translation(Vec3::new(1.0, 0.0, 8.0));
    let torus = Geometry::Torus {
        rmajor: 2.0,
        rminor: 0.5,
        phimin: 0.0,
        phimax: 360.0,
        thetamax: 360.0,
    };
    let s = one(
        &prim(torus, vec![], Attributes::default(), Mat4::IDENTITY),
        cam,
    );
    let (a, b) = (s.dice(5, 5), s.dice(17, 9));
    for g in [&a, &b] {
        for p in &g.p {
            let q = *p - Vec3::new(1.0, 0.0, 8.0);
            let ring = (q.truncate().length() - 2.0).hypot(q.z);
            assert!((ring - 0.5).abs() < 1e-4);
        }
    }
    // Shared parameters give the same points.
    for j in 0..5 {
        for i in 0..5 {
            assert!(close(a.p[j * 5 + i], b.p[(2 * j) * 17 + 4 * i], 1e-5));
        }
    }
}

#[test]
fn quadric_texture_coordinates_and_primvars() {
    let mut a = Attributes {
        color: Vec3::new(0.5, 0.25, 1.0),
        ..Default::default()
    };
    a.texture_coordinates = [0.0, 0.0, 2.0, 0.0, 0.0, 3.0, 2.0, 3.0];
    let p = prim(
        Geometry::Cylinder {
            radius: 1.0,
            zmin: 0.0,
            zmax: 1.0,
            thetamax: 360.0,
        },
        vec![
            param(
                "temp",
                Class::Varying,
                ParamType::Float,
                &[0.0, 1.0, 2.0, 3.0],
            ),
            param("k", Class::Uniform, ParamType::Float, &[7.0]),
            param("Pref", Class::Vertex, ParamType::Point, &[0.0; 12]),
        ],
        a,
        Mat4::IDENTITY,
    );
    let cam = Mat4::from_translation(Vec3::new(0.0, 0.0, 4.0));
    let g = one(&p, cam).dice(3, 3);
    // s = 2u, t = 3v from TextureCoordinates; colour from the attribute.
    assert!((g.s[4] - 1.0).abs() < 1e-6 && (g.t[4] - 1.5).abs() < 1e-6);
    assert!((g.s[8] - 2.0).abs() < 1e-6 && (g.t[8] - 3.0).abs() < 1e-6);
    assert!(g.cs.iter().all(|&c| c == Vec3::new(0.5, 0.25, 1.0)));
    let temp = g.primvar("temp").unwrap();
    assert!(!temp.uniform);
    assert_eq!(temp.floats.len(), 9);
    // Bilinear: centre = mean of the corners; (u=1, v=0) = second corner.
    assert!((temp.floats[4] - 1.5).abs() < 1e-6 && (temp.floats[2] - 1.0).abs() < 1e-6);
    let k = g.primvar("k").unwrap();
    assert!(k.uniform && k.floats == vec![7.0]);
    // Points move to camera space.
    let pref = g.primvar("Pref").unwrap();
    assert!(pref.floats.chunks(3).all(|c| c == [0.0, 0.0, 4.0]));
    // Split halves interpolate in the global parameters.
    let half = one(&p, cam).split().swap_remove(1).dice(2, 2);
    let t2 = half.primvar("temp").unwrap();
    let lo = half.u[0];
    let want = (1.0 - lo) * 0.0 + lo * 1.0;
    assert!((t2.floats[0] - want).abs() < 1e-6);
}

#[test]
fn cs_primvar_overrides_attribute_colour() {
    let a = Attributes {
        color: Vec3::new(1.0, 0.0, 0.0),
        ..Default::default()
    };
    let p = prim(
        sphere(1.0, -1.0, 1.0, 360.0),
        vec![param(
            "Cs",
            Class::Constant,
            ParamType::Color,
            &[0.0, 1.0, 0.0],
        )],
        a.clone(),
        Mat4::IDENTITY,
    );
    let g = one(&p, Mat4::IDENTITY).dice(3, 3);
    assert!(g.cs.iter().all(|&c| c == Vec3::new(0.0, 1.0, 0.0)));
    assert!(g.primvar("Cs").is_none());
    // Varying Cs on a polygon, per vertex.
    let quad = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![4],
            verts: vec![0, 1, 2, 3],
            nvertices: 4,
        },
        vec![
            param(
                "P",
                Class::Vertex,
                ParamType::Point,
                &[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.],
            ),
            param(
                "Cs",
                Class::Varying,
                ParamType::Color,
                &[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.],
            ),
            param("Os", Class::Uniform, ParamType::Color, &[0.5, 0.5, 0.5]),
        ],
        a,
        Mat4::IDENTITY,
    );
    let patches = one(&quad, Mat4::IDENTITY).split();
    assert_eq!(patches.len(), 1);
    let g = patches[0].dice(3, 3);
    // Colour = (x, y, 0) at every point; Os the uniform value.
    for k in 0..9 {
        assert!(close(g.cs[k], Vec3::new(g.p[k].x, g.p[k].y, 0.0), 1e-6));
        assert_eq!(g.os[k], Vec3::splat(0.5));
    }
}

fn polygon_area(surfaces: &[Box<dyn Surface>]) -> f32 {
    let mut total = 0.0;
    for s in surfaces {
        let g = s.dice(2, 2);
        // Corners (0,0) (1,0) (0,1) (1,1): two triangles 0-1-3 and 0-3-2.
        let (a, b, c, d) = (g.p[0], g.p[1], g.p[2], g.p[3]);
        total += 0.5 * (b - a).cross(d - a).length() + 0.5 * (d - a).cross(c - a).length();
    }
    total
}

#[test]
fn concave_polygon_and_hole_areas() {
    // An L (area 3) in a tilted plane, and a 4×4 square with a 2×1 hole (area 14).
    let tilt = Mat4::from_rotation_x(0.6) * Mat4::from_rotation_y(-0.4);
    let l = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![6],
            verts: (0..6).collect(),
            nvertices: 6,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[
                0., 0., 0., 2., 0., 0., 2., 1., 0., 1., 1., 0., 1., 2., 0., 0., 2., 0.,
            ],
        )],
        Attributes::default(),
        tilt,
    );
    let parts = one(&l, Mat4::IDENTITY).split();
    assert_eq!(parts.len(), 4);
    assert!((polygon_area(&parts) - 3.0).abs() < 1e-4);
    let holed = prim(
        Geometry::Polygons {
            nloops: vec![2],
            nverts: vec![4, 4],
            verts: (0..8).collect(),
            nvertices: 8,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[
                0., 0., 1., 4., 0., 1., 4., 4., 1., 0., 4., 1., // outline
                1., 1., 1., 3., 1., 1., 3., 2., 1., 1., 2., 1., // hole
            ],
        )],
        Attributes::default(),
        tilt,
    );
    let parts = one(&holed, Mat4::IDENTITY).split();
    assert!((polygon_area(&parts) - 14.0).abs() < 1e-3);
    // Every patch's normal is perpendicular to the tilted plane.
    let plane_n = tilt.transform_vector3(Vec3::Z);
    for s in &parts {
        let g = s.dice(2, 2);
        assert!((g.ng[0].dot(plane_n).abs() - 1.0).abs() < 1e-5);
    }
}

#[test]
fn clockwise_polygon_faces_the_camera_and_st_are_object_xy() {
    // Seen from the camera (x right, y up, looking down +z) this runs clockwise.
    let p = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![3],
            verts: vec![0, 1, 2],
            nvertices: 3,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[0., 0., 0., 0., 1., 0., 1., 1., 0.],
        )],
        Attributes::default(),
        Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0)),
    );
    let cam = Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0));
    let parts = one(&p, cam).split();
    assert_eq!(parts.len(), 1);
    let g = parts[0].dice(4, 4);
    for k in 0..g.len() {
        assert!(close(g.ng[k], Vec3::new(0.0, 0.0, -1.0), 1e-6));
        // s, t are object x, y (RISpec §5.1), not camera x.
        assert!((g.s[k] - (g.p[k].x - 0.5)).abs() < 1e-5 && (g.t[k] - g.p[k].y).abs() < 1e-5);
        assert!((g.p[k].z - 5.0).abs() < 1e-6);
    }
}

fn two_quads(params: Vec<Param>) -> Primitive {
    // Vertices 0..6 on a 3×2 lattice; faces [0 1 4 3] and [1 2 5 4].
    let mut all = vec![param(
        "P",
        Class::Vertex,
        ParamType::Point,
        &[
            0., 0., 0., 1., 0., 0., 2., 0., 0., 0., 1., 0., 1., 1., 0., 2., 1., 0.,
        ],
    )];
    all.extend(params);
    prim(
        Geometry::Polygons {
            nloops: vec![1, 1],
            nverts: vec![4, 4],
            verts: vec![0, 1, 4, 3, 1, 2, 5, 4],
            nvertices: 6,
        },
        all,
        Attributes::default(),
        Mat4::IDENTITY,
    )
}

#[test]
fn mesh_primvar_classes() {
    let p = two_quads(vec![
        param(
            "vx",
            Class::Varying,
            ParamType::Float,
            &[0., 1., 2., 10., 11., 12.],
        ),
        param("fid", Class::Uniform, ParamType::Float, &[5., 6.]),
        param(
            "fv",
            Class::FaceVarying,
            ParamType::Float,
            &[100., 101., 102., 103., 200., 201., 202., 203.],
        ),
        param(
            "N",
            Class::Vertex,
            ParamType::Normal,
            &[
                0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1.,
            ],
        ),
    ]);
    let mesh = one(&p, Mat4::IDENTITY);
    assert!(!mesh.diceable());
    let parts = mesh.split();
    assert_eq!(parts.len(), 2);
    for (f, s) in parts.iter().enumerate() {
        assert!(s.diceable());
        assert!(contains(&mesh.bound(), &s.bound()));
        let g = s.dice(3, 3);
        // Varying = the vertex value bilinear in position: x + 10y.
        let vx = g.primvar("vx").unwrap();
        for k in 0..9 {
            assert!((vx.floats[k] - (g.p[k].x + 10.0 * g.p[k].y)).abs() < 1e-5);
            assert!(close(g.n[k], Vec3::Z, 1e-6));
        }
        let fid = g.primvar("fid").unwrap();
        assert!(fid.uniform && fid.floats == vec![5.0 + f as f32]);
        // Facevarying corners in face order: patch corners (0,0) (1,0) (0,1) (1,1) are face
        // vertices 0 1 3 2.
        let fv = g.primvar("fv").unwrap();
        let base = 100.0 * (f + 1) as f32;
        assert_eq!(fv.floats[0], base);
        assert_eq!(fv.floats[2], base + 1.0);
        assert_eq!(fv.floats[6], base + 3.0);
        assert_eq!(fv.floats[8], base + 2.0);
        assert!((fv.floats[4] - (base + 1.5)).abs() < 1e-5);
    }
    // The shared edge x = 1 dices to the same points from both faces.
    let (a, b) = (parts[0].dice(5, 5), parts[1].dice(5, 5));
    for j in 0..5 {
        assert!(close(a.p[j * 5 + 4], b.p[j * 5], 1e-6));
    }
}

#[test]
fn triangles_interpolate_linearly_and_big_meshes_split_in_halves() {
    // A pentagon (not a quad) with a varying value = 3x − y + 1.
    let pts: Vec<(f32, f32)> = (0..5)
        .map(|i| {
            let a = i as f32 * 2.0 * PI / 5.0;
            (a.cos(), a.sin())
        })
        .collect();
    let pos: Vec<f32> = pts.iter().flat_map(|&(x, y)| [x, y, 0.0]).collect();
    let val: Vec<f32> = pts.iter().map(|&(x, y)| 3.0 * x - y + 1.0).collect();
    let p = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![5],
            verts: (0..5).collect(),
            nvertices: 5,
        },
        vec![
            param("P", Class::Vertex, ParamType::Point, &pos),
            param("val", Class::Varying, ParamType::Float, &val),
        ],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let parts = one(&p, Mat4::IDENTITY).split();
    assert_eq!(parts.len(), 3);
    let want_area = 0.5 * 5.0 * (2.0 * PI / 5.0).sin();
    assert!((polygon_area(&parts) - want_area).abs() < 1e-4);
    for s in &parts {
        let g = s.dice(4, 4);
        let v = g.primvar("val").unwrap();
        for k in 0..g.len() {
            assert!((v.floats[k] - (3.0 * g.p[k].x - g.p[k].y + 1.0)).abs() < 1e-5);
        }
    }
    // 100 quads: the mesh splits into face ranges, each inside its parent's bound.
    let n = 10usize;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.extend([i as f32, j as f32, (i * j) as f32 * 0.01]);
        }
    }
    let mut verts = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = (j * (n + 1) + i) as u32;
            verts.extend([v, v + 1, v + n as u32 + 2, v + n as u32 + 1]);
        }
    }
    let big = prim(
        Geometry::Polygons {
            nloops: vec![1; n * n],
            nverts: vec![4; n * n],
            verts,
            nvertices: (n + 1) * (n + 1),
        },
        vec![param("P", Class::Vertex, ParamType::Point, &pos)],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let mut stack = vec![one(&big, Mat4::IDENTITY)];
    let mut patches = 0;
    while let Some(s) = stack.pop() {
        if s.diceable() {
            patches += 1;
            continue;
        }
        let b = s.bound();
        for k in s.split() {
            assert!(contains(&b, &k.bound()));
            stack.push(k);
        }
    }
    assert_eq!(patches, n * n);
}

#[test]
fn bad_input_reports_instead_of_panicking() {
    let d = Diagnostics::new();
    let bad_index = prim(
        Geometry::Polygons {
            nloops: vec![1, 1],
            nverts: vec![3, 3],
            verts: vec![0, 1, 2, 0, 1, 9],
            nvertices: 3,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[0., 0., 0., 1., 0., 0., 0., 1., 0.],
        )],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let s = surfaces_for(0, &bad_index, Mat4::IDENTITY, &d);
    assert_eq!(s.len(), 1);
    assert_eq!(s[0].split().len(), 1, "only the valid face");
    assert_eq!(d.error_count(), 1);
    // Too few varying values: the variable is dropped with an error.
    let d = Diagnostics::new();
    let short = prim(
        sphere(1.0, -1.0, 1.0, 360.0),
        vec![param("temp", Class::Varying, ParamType::Float, &[1.0, 2.0])],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let g = surfaces_for(0, &short, Mat4::IDENTITY, &d)[0].dice(2, 2);
    assert!(g.primvar("temp").is_none());
    assert_eq!(d.snapshot()[0].0.code, "geom::primvar_count");
    // No P at all; unsupported geometry warns.
    let d = Diagnostics::new();
    let nop = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![3],
            verts: vec![0, 1, 2],
            nvertices: 3,
        },
        vec![],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    assert!(surfaces_for(0, &nop, Mat4::IDENTITY, &d).is_empty());
    let pts = prim(
        Geometry::Points { npoints: 3 },
        vec![],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    assert!(surfaces_for(0, &pts, Mat4::IDENTITY, &d).is_empty());
    let s = d.snapshot();
    assert_eq!(s.len(), 2);
    // Points without "P" are invalid input (Points render since the subdiv/points work).
    assert_eq!(s[1].0.code, "geom::invalid");
}

#[test]
fn raster_lengths_measure_the_projected_patch() {
    // A unit square at z = 2 under a projection x/z: the u-line is 0.5 long.
    let p = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![4],
            verts: vec![0, 1, 2, 3],
            nvertices: 4,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[0., 0., 2., 1., 0., 2., 1., 1., 2., 0., 1., 2.],
        )],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let patch = one(&p, Mat4::IDENTITY).split().swap_remove(0);
    // x' = x / z, y' = y / z.
    let xz = Mat4::from_cols(
        glam::Vec4::new(1.0, 0.0, 0.0, 0.0),
        glam::Vec4::new(0.0, 1.0, 0.0, 0.0),
        glam::Vec4::new(0.0, 0.0, 0.0, 1.0),
        glam::Vec4::new(0.0, 0.0, 0.0, 0.0),
    );
    let (lu, lv) = patch.raster_lengths(&xz).unwrap();
    assert!((lu - 0.5).abs() < 1e-5 && (lv - 0.5).abs() < 1e-5);
    // Behind the eye: unknown.
    let behind = Mat4::from_translation(Vec3::new(0.0, 0.0, -5.0));
    let back = one(&p, behind).split().swap_remove(0);
    assert!(back.raster_lengths(&xz).is_none());
}

#[test]
fn quadric_profile_sphere_limits() {
    // zmin/zmax beyond the radius clamp to the poles.
    match Profile::sphere(1.0, -5.0, 0.5) {
        Profile::Sphere { phi0, phi1, .. } => {
            assert!((phi0 + PI / 2.0).abs() < 1e-6);
            assert!((phi1 - 0.5f32.asin()).abs() < 1e-6);
        }
        _ => unreachable!(),
    }
    let q = Quadric {
        profile: Profile::sphere(1.0, -1.0, 1.0),
        thetamax: 2.0 * PI,
        camera_from_object: Mat4::IDENTITY,
        flip: false,
    };
    let b = q.bound(0.0, 1.0, 0.0, 1.0);
    assert!(close(b.min, Vec3::splat(-1.0), 1e-4) && close(b.max, Vec3::splat(1.0), 1e-4));
}

#[test]
fn mirrored_polygon_front_face_is_counter_clockwise() {
    // The clockwise triangle of `clockwise_polygon_faces_the_camera…`, mirrored in x: the camera
    // now sees it counter-clockwise, and with a right-handed transform (orientation matching)
    // that is the front face, so Ng still points at the camera.
    let p = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![3],
            verts: vec![0, 1, 2],
            nvertices: 3,
        },
        vec![param(
            "P",
            Class::Vertex,
            ParamType::Point,
            &[0., 0., 0., 0., 1., 0., 1., 1., 0.],
        )],
        Attributes::default(),
        Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0))
            * Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
    );
    let g = one(&p, Mat4::IDENTITY).split()[0].dice(2, 2);
    assert!(close(g.ng[0], Vec3::new(0.0, 0.0, -1.0), 1e-6));
    // s follows object x, so it is −(camera x) here.
    assert!((0..4).all(|k| (g.s[k] + g.p[k].x).abs() < 1e-6));
}

#[test]
fn st_and_hpoint_primvars() {
    let mut st = param(
        "st",
        Class::Varying,
        ParamType::Float,
        &[0., 10., 1., 10., 0., 20., 1., 20.],
    );
    st.decl.array_len = 2;
    let hp = param(
        "Ph",
        Class::Constant,
        ParamType::HPoint,
        &[2.0, 4.0, 6.0, 2.0],
    );
    let p = prim(
        Geometry::Disk {
            height: 0.0,
            radius: 1.0,
            thetamax: 360.0,
        },
        vec![st, hp],
        Attributes::default(),
        Mat4::IDENTITY,
    );
    let g = one(&p, Mat4::from_translation(Vec3::X)).dice(3, 3);
    assert!((g.s[4] - 0.5).abs() < 1e-6 && (g.t[4] - 15.0).abs() < 1e-5);
    assert!(g.primvar("st").is_none());
    let ph = g.primvar("Ph").unwrap();
    assert_eq!(ph.ty, ParamType::Point);
    assert_eq!(ph.floats, vec![2.0, 2.0, 3.0]);
}

#[test]
fn displaced_triangles_become_three_quads_without_collapsed_rows() {
    let a = Attributes {
        displacement: Some(Arc::new(crate::scene::ShaderRef {
            name: "bumpy".into(),
            params: ParamList::default(),
            span: Span::default(),
            world_from_shader: Mat4::IDENTITY,
        })),
        ..Default::default()
    };
    let pts = [(0.0f32, 0.0f32), (3.0, 0.0), (0.0, 2.0)];
    let pos: Vec<f32> = pts.iter().flat_map(|&(x, y)| [x, y, 1.0]).collect();
    let val: Vec<f32> = pts.iter().map(|&(x, y)| 2.0 * x + y).collect();
    let p = prim(
        Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![3],
            verts: vec![0, 1, 2],
            nvertices: 3,
        },
        vec![
            param("P", Class::Vertex, ParamType::Point, &pos),
            param("val", Class::Vertex, ParamType::Float, &val),
            param("fv", Class::FaceVarying, ParamType::Float, &[1.0, 2.0, 3.0]),
        ],
        a,
        Mat4::IDENTITY,
    );
    let parts = one(&p, Mat4::IDENTITY).split();
    assert_eq!(parts.len(), 3);
    assert!((polygon_area(&parts) - 3.0).abs() < 1e-5);
    for s in &parts {
        let g = s.dice(4, 4);
        let v = g.primvar("val").unwrap();
        for k in 0..g.len() {
            assert!(g.dpdu[k].length() > 1e-3 && g.dpdv[k].length() > 1e-3);
            assert!((v.floats[k] - (2.0 * g.p[k].x + g.p[k].y)).abs() < 1e-5);
            assert!((g.s[k] - g.p[k].x).abs() < 1e-5 && (g.t[k] - g.p[k].y).abs() < 1e-5);
        }
        // The centroid corner (1,1) carries the mean face-varying value.
        assert!((g.primvar("fv").unwrap().floats[15] - 2.0).abs() < 1e-6);
    }
}

#[test]
fn a_zero_scaled_primitive_is_skipped_with_a_warning_not_an_error() {
    // Particle systems write dead particles as `Scale 0 0 0`; PRMan draws nothing, silently.
    let d = Diagnostics::new();
    let dead = prim(
        Geometry::Sphere {
            radius: 2.0,
            zmin: -2.0,
            zmax: 2.0,
            thetamax: 360.0,
        },
        vec![],
        Attributes::default(),
        Mat4::from_scale(Vec3::ZERO),
    );
    assert!(surfaces_for(0, &dead, Mat4::IDENTITY, &d).is_empty());
    assert!(!d.has_errors());
    let s = d.snapshot();
    assert_eq!(s.len(), 1);
    assert_eq!(s[0].0.code, "geom::singular");
}
