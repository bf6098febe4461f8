//! `Geometry "fractalterrain"`: a midpoint-displacement landscape (book §7.1) diced as a mesh.
//!
//! Input: a `Geometry::Named { name: "fractalterrain" }` primitive whose primitive variables
//! carry the parameters (all optional, any of float/integer):
//! - `"size"` — side of the square terrain when no corners are given (default 1); the square
//!   lies in the object-space xz plane centred on the origin, heights along +y;
//! - `"P"` — four corners P(0,0) P(1,0) P(0,1) P(1,1) (RIB patch order) replacing `size`;
//!   heights then go along the corners' normal (P10 − P00) × (P01 − P00);
//! - `"levels"` — subdivision levels, 2^levels cells per side (default 6, at most 11);
//! - `"H"` — Hurst exponent in [0,1] (larger is smoother), or `"roughness"` r = 2^(−H)
//!   (the book's factor by which displacements shrink per halving; default H = 0.7);
//! - `"height"` (or `"sigma"`) — standard deviation of the coarsest displacement in object
//!   units (default 0.25 × the terrain's side);
//! - `"seed"` — integer seed (default 0);
//! - `"scheme"` — "square-square" (Miller's crease-free subdivision, the default) or
//!   "diamond-square" (the book's plain algorithm, which shows the creases it describes).
//!
//! Output: a polygon mesh ([`super::polygons`]) of 2·4^levels triangles with smooth vertex
//! normals "N" and "s", "t" running over the unit square (so texture shaders see the
//! terrain's map coordinates). Constant and uniform primitive variables (e.g. "Cs") pass
//! through; other parameters are read here and not bound to shaders.
//! Invariants: the heights come from `crate::pattern::terrain` and are deterministic per seed;
//! bad parameters are clamped with a warning, never a panic.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::Surface;
use crate::diag::{Diag, Diagnostics};
use crate::pattern::terrain::{diamond_square, square_square, TerrainParams};
use crate::scene::{Class, Decl, Geometry, Param, ParamData, ParamList, ParamType, Primitive};

/// Parameters of `Geometry "fractalterrain"` this module reads (others warn).
const KNOWN: &[&str] = &[
    "size",
    "P",
    "levels",
    "H",
    "roughness",
    "height",
    "sigma",
    "seed",
    "scheme",
];

/// The terrain's surfaces in camera space (`m` = camera_from_object).
pub(super) fn surfaces(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let pv = &prim.primvars;
    let warn = |msg: String| {
        diags.report(Diag::warning("geom::fractalterrain", msg).label(prim.span, "this terrain"));
    };
    for p in pv.iter() {
        let known =
            KNOWN.contains(&&*p.name) || matches!(p.decl.class, Class::Constant | Class::Uniform);
        if !known {
            warn(format!(
                "parameter \"{}\" is not used by fractalterrain; ignored",
                p.name
            ));
        }
    }
    let finite = |name: &str| pv.float(name).filter(|v| v.is_finite());
    let mesh = build(
        finite("size"),
        pv.floats("P"),
        finite("levels"),
        finite("H"),
        finite("roughness"),
        finite("height").or_else(|| finite("sigma")),
        finite("seed"),
        pv.string("scheme"),
        &mut |msg| warn(msg),
    );
    let Some(mesh) = mesh else {
        return Vec::new();
    };
    // The mesh as a PointsPolygons primitive, constant/uniform primvars carried over.
    let nfaces = mesh.triangles.len();
    let mut list: Vec<Param> = pv
        .iter()
        .filter(|p| {
            matches!(p.decl.class, Class::Constant | Class::Uniform) && !KNOWN.contains(&&*p.name)
        })
        .cloned()
        .collect();
    let param = |name: &str, class: Class, ty: ParamType, data: Vec<f32>| Param {
        name: name.to_string().into(),
        decl: Decl {
            class,
            ty,
            array_len: 1,
        },
        data: ParamData::Floats(data),
        span: prim.span,
    };
    list.push(param(
        "P",
        Class::Vertex,
        ParamType::Point,
        mesh.positions.iter().flat_map(|p| p.to_array()).collect(),
    ));
    list.push(param(
        "N",
        Class::Varying,
        ParamType::Normal,
        mesh.normals.iter().flat_map(|p| p.to_array()).collect(),
    ));
    list.push(param("s", Class::Varying, ParamType::Float, mesh.s));
    list.push(param("t", Class::Varying, ParamType::Float, mesh.t));
    let nverts = vec![3u32; nfaces];
    let nloops = vec![1u32; nfaces];
    let verts: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let nvertices = mesh.positions.len();
    let poly = Primitive {
        geometry: Arc::new(Geometry::Polygons {
            nloops: nloops.clone(),
            nverts: nverts.clone(),
            verts: verts.clone(),
            nvertices,
        }),
        primvars: Arc::new(ParamList(list)),
        attributes: prim.attributes.clone(),
        world_from_object: prim.world_from_object.clone(),
        span: prim.span,
        motion: None,
    };
    super::polygons(
        index,
        &poly,
        m,
        flip,
        (&nloops, &nverts, &verts, nvertices),
        diags,
    )
}

/// A terrain mesh in object space.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TerrainMesh {
    pub positions: Vec<Vec3>,
    /// Smooth (area-weighted) vertex normals, unit length.
    pub normals: Vec<Vec3>,
    pub s: Vec<f32>,
    pub t: Vec<f32>,
    pub triangles: Vec<[u32; 3]>,
}

/// Builds the terrain from its (already finiteness-checked) parameters; problems are passed to
/// `warn`. None when the corners are unusable.
#[allow(clippy::too_many_arguments)]
pub(crate) fn build(
    size: Option<f32>,
    corners: Option<&[f32]>,
    levels: Option<f32>,
    h: Option<f32>,
    roughness: Option<f32>,
    height: Option<f32>,
    seed: Option<f32>,
    scheme: Option<&str>,
    warn: &mut dyn FnMut(String),
) -> Option<TerrainMesh> {
    let corners: [Vec3; 4] = match corners {
        Some(p) if p.len() >= 12 && p.iter().all(|v| v.is_finite()) => {
            if p.len() > 12 {
                warn(format!(
                    "\"P\" has {} values; the first four corners (12 values) are used",
                    p.len()
                ));
            }
            [
                Vec3::from_slice(&p[0..3]),
                Vec3::from_slice(&p[3..6]),
                Vec3::from_slice(&p[6..9]),
                Vec3::from_slice(&p[9..12]),
            ]
        }
        Some(p) => {
            warn(format!(
                "\"P\" needs four finite corners (12 values), found {}; the terrain is skipped",
                p.len()
            ));
            return None;
        }
        None => {
            let mut s = size.unwrap_or(1.0);
            if s <= 0.0 {
                warn(format!("size {s} must be positive; 1 is used"));
                s = 1.0;
            }
            let h = 0.5 * s;
            // Wound so that (P10 − P00) × (P01 − P00) points along +y.
            [
                Vec3::new(-h, 0.0, h),
                Vec3::new(h, 0.0, h),
                Vec3::new(-h, 0.0, -h),
                Vec3::new(h, 0.0, -h),
            ]
        }
    };
    let side = (corners[1] - corners[0])
        .length()
        .max((corners[2] - corners[0]).length());
    if side == 0.0 {
        warn("the terrain's corners coincide; the terrain is skipped".into());
        return None;
    }
    let levels = levels.unwrap_or(6.0).round();
    if levels < 0.0 {
        warn(format!("levels {levels} must be >= 0; 0 is used"));
    }
    let levels = levels.max(0.0) as u32;
    let hurst = match (h, roughness) {
        (Some(h), _) => h,
        (None, Some(r)) if r > 0.0 => -r.log2(),
        (None, Some(r)) => {
            warn(format!("roughness {r} must be positive; H = 1 is used"));
            1.0
        }
        (None, None) => 0.7,
    };
    let sigma = height.unwrap_or(0.25 * side);
    let seed = seed.unwrap_or(0.0);
    let params = TerrainParams {
        levels,
        h: hurst,
        sigma,
        seed: seed as i64 as u32,
    };
    if let Some(msg) = params.validate() {
        warn(msg);
    }
    let params = params.sanitized();
    let grid = match scheme.unwrap_or("square-square") {
        "square-square" | "miller" => square_square(&params),
        "diamond-square" => diamond_square(&params),
        other => {
            warn(format!(
                "unknown scheme \"{other}\" (square-square or diamond-square); square-square is used"
            ));
            square_square(&params)
        }
    };
    let tri = grid.to_mesh(corners, None);
    let n = grid.side;
    let mut normals = vec![Vec3::ZERO; tri.positions.len()];
    for &[a, b, c] in &tri.indices {
        let (pa, pb, pc) = (
            tri.positions[a as usize],
            tri.positions[b as usize],
            tri.positions[c as usize],
        );
        let fnrm = (pb - pa).cross(pc - pa);
        for v in [a, b, c] {
            normals[v as usize] += fnrm;
        }
    }
    let up = {
        let a = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
        a.normalize_or(Vec3::Y)
    };
    for nrm in &mut normals {
        *nrm = nrm.normalize_or(up);
    }
    let mut s = Vec::with_capacity(n * n);
    let mut t = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            s.push(grid.coord(i));
            t.push(grid.coord(j));
        }
    }
    Some(TerrainMesh {
        positions: tri.positions,
        normals,
        s,
        t,
        triangles: tri.indices,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quiet() -> impl FnMut(String) {
        |_| {}
    }

    #[test]
    fn default_terrain_has_the_grid_counts_and_up_normals() {
        let m = build(
            None,
            None,
            Some(3.0),
            None,
            None,
            None,
            None,
            None,
            &mut quiet(),
        )
        .unwrap();
        // Miller's square-square puts 2^levels samples per side at cell centres.
        let n = 8;
        assert_eq!(m.positions.len(), n * n);
        assert_eq!(m.triangles.len(), 2 * (n - 1) * (n - 1));
        assert_eq!(m.s.len(), n * n);
        // Heights go along +y, so the mean normal points up.
        let mean: Vec3 = m.normals.iter().copied().sum::<Vec3>() / m.normals.len() as f32;
        assert!(mean.y > 0.7, "mean normal {mean}");
        // s, t run across the unit square, s along a row, t down the rows.
        assert!(m.s.iter().chain(&m.t).all(|&v| v > 0.0 && v < 1.0));
        assert!(m.s[1] > m.s[0] && m.t[n] > m.t[0]);
        // x, z stay on the square of side 1.
        for p in &m.positions {
            assert!(p.x.abs() <= 0.5 + 1e-6 && p.z.abs() <= 0.5 + 1e-6);
        }
    }

    #[test]
    fn same_seed_same_terrain_other_seed_differs() {
        let a = build(
            None,
            None,
            Some(4.0),
            None,
            None,
            None,
            Some(3.0),
            None,
            &mut quiet(),
        );
        let b = build(
            None,
            None,
            Some(4.0),
            None,
            None,
            None,
            Some(3.0),
            None,
            &mut quiet(),
        );
        let c = build(
            None,
            None,
            Some(4.0),
            None,
            None,
            None,
            Some(4.0),
            None,
            &mut quiet(),
        );
        assert_eq!(a, b);
        assert_ne!(a.unwrap().positions, c.unwrap().positions);
    }

    #[test]
    fn roughness_maps_to_hurst_and_smaller_roughness_is_smoother() {
        // Mean |height difference| between neighbours: rough terrain varies more at fine scale.
        let bumpiness = |r: f32| {
            let m = build(
                None,
                None,
                Some(6.0),
                None,
                Some(r),
                Some(0.2),
                Some(1.0),
                None,
                &mut quiet(),
            )
            .unwrap();
            let n = (m.positions.len() as f64).sqrt() as usize;
            assert_eq!(n * n, m.positions.len());
            let mut sum = 0.0;
            for j in 0..n {
                for i in 0..n - 1 {
                    sum += (m.positions[j * n + i + 1].y - m.positions[j * n + i].y).abs();
                }
            }
            sum
        };
        assert!(bumpiness(0.8) > 2.0 * bumpiness(0.3));
    }

    #[test]
    fn corners_orient_the_terrain_and_bad_input_warns() {
        let p = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 2.0, 0.0, 2.0, 2.0, 0.0];
        let m = build(
            None,
            Some(&p),
            Some(2.0),
            Some(0.5),
            None,
            Some(0.0),
            None,
            None,
            &mut quiet(),
        )
        .unwrap();
        // Zero height: flat on z = 0, normals along +z ((P10 − P00) × (P01 − P00)).
        assert!(m.positions.iter().all(|q| q.z == 0.0));
        assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
        let mut warnings = Vec::new();
        let bad = build(
            None,
            Some(&p[..5]),
            None,
            None,
            None,
            None,
            None,
            None,
            &mut |w| warnings.push(w),
        );
        assert!(bad.is_none());
        assert_eq!(warnings.len(), 1);
        let mut warnings = Vec::new();
        build(
            Some(-1.0),
            None,
            Some(40.0),
            None,
            None,
            None,
            None,
            Some("plasma"),
            &mut |w| warnings.push(w),
        )
        .unwrap();
        assert_eq!(warnings.len(), 3, "{warnings:?}");
    }
}
