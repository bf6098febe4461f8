//! Polygon meshes: Polygon, GeneralPolygon, PointsPolygons and PointsGeneralPolygons.
//!
//! Input: `Geometry::Polygons` (loops per face, vertices per loop, vertex indices), "P" (or
//! "Pw") and the other primitive variables, `camera_from_object`.
//! Output: a [`Mesh`] surface (not diceable) that splits into halves of its face range and, once
//! small, into one bilinear patch per convex quad and, for every other face, per triangle
//! (ear clipping, holes bridged first, in the face's dominant plane) either one degenerate
//! bilinear patch `(a, b, c, c)` (cheap; its v = 1 row collapses to c) or, when the primitive is
//! displaced, three quads meeting at the centroid (no collapsed rows, so calculatenormal works).
//! Invariants: vertex positions are transformed once, so faces sharing an edge dice onto the
//! same straight segment (no cracks); Ng is the face's Newell normal with the orientation rule of
//! `geom` applied, N the "N" primvar when given; per RISpec §5.1 polygons do not inherit
//! TextureCoordinates: s, t default to the object-space x, y of the point. Primvar classes:
//! constant (one value), uniform (per face), varying/vertex (per vertex, via the face's
//! indices), facevarying/facevertex (per face-vertex, in face order).

use std::ops::Range;
use std::sync::Arc;

use glam::{Vec2, Vec3};

use super::patch::{ParamPatch, Shape};
use super::primvar::{patch_vars, Defaults, PatchVars, Selector, SourceVar};
use super::triangulate::triangulate;
use super::{Bound, Surface};
use crate::shade::Grid;

/// Faces per mesh piece below which a split yields patches rather than two sub-meshes.
const LEAF_FACES: usize = 32;

#[derive(Debug)]
pub(crate) struct MeshData {
    pub index: usize,
    /// Camera-space vertex positions.
    pub p: Vec<Vec3>,
    /// Object-space x, y of each vertex (default s, t).
    pub obj_xy: Vec<Vec2>,
    pub nverts: Vec<u32>,
    pub verts: Vec<u32>,
    /// Per face: its first loop (into `nverts`) and first face-vertex (into `verts`); one extra
    /// entry closes the last face.
    pub loop_start: Vec<usize>,
    pub fv_start: Vec<usize>,
    /// Faces whose indices were all valid.
    pub valid: Vec<bool>,
    pub vars: Vec<SourceVar>,
    /// Negate the camera-space Newell normal to get Ng.
    pub flip: bool,
    pub color: Vec3,
    pub opacity: Vec3,
    /// Cut triangles into three quads instead of one collapsed patch (set when the primitive
    /// has a displacement shader, which needs derivatives at every grid point).
    pub split_triangles: bool,
    /// Motion blur (deformation): the shutter-open key's camera-space positions, which decide
    /// how faces are cut into patches so every key is cut the same way.
    pub decomp_p: Option<Arc<Vec<Vec3>>>,
}

/// A range of a mesh's faces.
#[derive(Debug, Clone)]
pub struct Mesh {
    pub(crate) data: Arc<MeshData>,
    pub(crate) faces: Range<usize>,
}

impl Mesh {
    fn face_verts(&self, f: usize) -> impl Iterator<Item = usize> + '_ {
        let d = &self.data;
        d.verts[d.fv_start[f]..d.fv_start[f + 1]]
            .iter()
            .map(|&v| v as usize)
    }

    /// The patches of one face.
    pub(crate) fn face_patches(&self, f: usize, out: &mut Vec<Box<dyn Surface>>) {
        let d = &*self.data;
        if !d.valid[f] {
            return;
        }
        let fv0 = d.fv_start[f];
        let loops: Vec<Range<usize>> = {
            let mut r = Vec::new();
            let mut at = 0;
            for l in d.loop_start[f]..d.loop_start[f + 1] {
                let n = d.nverts[l] as usize;
                r.push(at..at + n);
                at += n;
            }
            r
        };
        let Some(outline) = loops.first().cloned() else {
            return;
        };
        if outline.len() < 3 {
            return;
        }
        let pos = |local: usize| d.p[d.verts[fv0 + local] as usize];
        let dpos = |local: usize| match &d.decomp_p {
            Some(q) => q[d.verts[fv0 + local] as usize],
            None => pos(local),
        };
        // Newell normal of the outline (camera space); its size is twice the projected area.
        let mut newell = Vec3::ZERO;
        for k in outline.clone() {
            let next = if k + 1 == outline.end {
                outline.start
            } else {
                k + 1
            };
            let (a, b) = (pos(k), pos(next));
            newell += Vec3::new(
                (a.y - b.y) * (a.z + b.z),
                (a.z - b.z) * (a.x + b.x),
                (a.x - b.x) * (a.y + b.y),
            );
        }
        // Same sense as (p1 − p0) × (p2 − p0) for a convex outline.
        if newell.length_squared() == 0.0 || !newell.is_finite() {
            return; // zero-area face: nothing to see
        }
        let ng = if d.flip { -newell } else { newell }.normalize();
        // Project to the dominant plane (of the shutter-open key when the mesh deforms).
        let ax = match &d.decomp_p {
            None => newell.abs(),
            Some(_) => {
                let mut nd = Vec3::ZERO;
                for k in outline.clone() {
                    let next = if k + 1 == outline.end {
                        outline.start
                    } else {
                        k + 1
                    };
                    let (a, b) = (dpos(k), dpos(next));
                    nd += Vec3::new(
                        (a.y - b.y) * (a.z + b.z),
                        (a.z - b.z) * (a.x + b.x),
                        (a.x - b.x) * (a.y + b.y),
                    );
                }
                nd.abs()
            }
        };
        let proj = |p: Vec3| {
            if ax.z >= ax.x && ax.z >= ax.y {
                Vec2::new(p.x, p.y)
            } else if ax.x >= ax.y {
                Vec2::new(p.y, p.z)
            } else {
                Vec2::new(p.z, p.x)
            }
        };
        let nfv = d.fv_start[f + 1] - fv0;
        let pts: Vec<Vec2> = (0..nfv).map(|k| proj(dpos(k))).collect();
        if loops.len() == 1 && outline.len() == 4 && convex_quad(&pts[0..4]) {
            // Bilinear corner order (0,0) (1,0) (0,1) (1,1) = polygon vertices 0 1 3 2.
            out.push(self.patch(f, [0, 1, 3, 2], ng));
            return;
        }
        let loop_ids: Vec<Vec<usize>> = loops.iter().map(|r| r.clone().collect()).collect();
        for t in triangulate(&pts, &loop_ids) {
            if d.split_triangles {
                self.triangle_quads(f, t, ng, out);
            } else {
                out.push(self.patch(f, [t[0], t[1], t[2], t[2]], ng));
            }
        }
    }

    /// A triangle as three quads (corner, edge midpoint, centroid, edge midpoint): no collapsed
    /// grid rows, so finite-difference derivatives (calculatenormal after displacement) stay
    /// defined everywhere. Bilinear interpolation reproduces the triangle's linear
    /// interpolation exactly, since positions and values use the same weights.
    fn triangle_quads(&self, f: usize, t: [usize; 3], ng: Vec3, out: &mut Vec<Box<dyn Surface>>) {
        let d = &*self.data;
        let base = self.corner_vars(f, [t[0], t[1], t[2], t[2]]);
        let p = t.map(|l| d.p[d.verts[d.fv_start[f] + l] as usize]);
        const H: f32 = 0.5;
        const G: f32 = 1.0 / 3.0;
        // Barycentric weights of the corners (0,0) (1,0) (0,1) (1,1) of each quad.
        let quads: [[[f32; 3]; 4]; 3] = [
            [[1., 0., 0.], [H, H, 0.], [H, 0., H], [G, G, G]],
            [[0., 1., 0.], [0., H, H], [H, H, 0.], [G, G, G]],
            [[0., 0., 1.], [H, 0., H], [0., H, H], [G, G, G]],
        ];
        for w in &quads {
            let corners = w.map(|w| w[0] * p[0] + w[1] * p[1] + w[2] * p[2]);
            let shape = Shape::Bilinear { p: corners, ng };
            out.push(Box::new(ParamPatch::new(d.index, shape, base.remap(w))));
        }
    }

    /// One patch whose corners are the given face-local face-vertices.
    fn patch(&self, f: usize, local: [usize; 4], ng: Vec3) -> Box<dyn Surface> {
        let d = &*self.data;
        let vx = local.map(|l| d.verts[d.fv_start[f] + l] as usize);
        let vars = self.corner_vars(f, local);
        let shape = Shape::Bilinear {
            p: vx.map(|v| d.p[v]),
            ng,
        };
        Box::new(ParamPatch::new(d.index, shape, vars))
    }

    /// Primitive variables at four face-local face-vertices.
    fn corner_vars(&self, f: usize, local: [usize; 4]) -> PatchVars {
        let d = &*self.data;
        let fv = local.map(|l| d.fv_start[f] + l);
        let vx = fv.map(|i| d.verts[i] as usize);
        let sel = Selector {
            uniform: f,
            vertex: vx,
            facevertex: fv,
        };
        let defaults = Defaults {
            s: vx.map(|v| d.obj_xy[v].x),
            t: vx.map(|v| d.obj_xy[v].y),
            color: d.color,
            opacity: d.opacity,
        };
        patch_vars(&d.vars, &sel, &defaults)
    }
}

/// Strictly convex quadrilateral (either winding) in 2D.
fn convex_quad(q: &[Vec2]) -> bool {
    let mut sign = 0.0f32;
    for i in 0..4 {
        let (a, b, c) = (q[i], q[(i + 1) % 4], q[(i + 2) % 4]);
        let z = (b - a).perp_dot(c - b);
        if z == 0.0 || (sign != 0.0 && z.signum() != sign) {
            return false;
        }
        sign = z.signum();
    }
    true
}

impl Surface for Mesh {
    fn bound(&self) -> Bound {
        let mut b = Bound::EMPTY;
        for f in self.faces.clone() {
            if !self.data.valid[f] {
                continue;
            }
            for v in self.face_verts(f) {
                let p = self.data.p[v];
                b.min = b.min.min(p);
                b.max = b.max.max(p);
            }
        }
        super::pad(b)
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        let n = self.faces.len();
        if n > LEAF_FACES {
            let mid = self.faces.start + n / 2;
            return vec![
                Box::new(Mesh {
                    data: self.data.clone(),
                    faces: self.faces.start..mid,
                }),
                Box::new(Mesh {
                    data: self.data.clone(),
                    faces: mid..self.faces.end,
                }),
            ];
        }
        let mut out = Vec::new();
        for f in self.faces.clone() {
            self.face_patches(f, &mut out);
        }
        out
    }

    fn diceable(&self) -> bool {
        false
    }

    /// A mesh is never diced directly (`diceable` is false); an empty grid is returned.
    fn dice(&self, _nu: usize, _nv: usize) -> Grid {
        Grid::default()
    }

    fn primitive(&self) -> usize {
        self.data.index
    }
}
