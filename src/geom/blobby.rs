//! Blobby implicit surfaces (RISpec §5.7; Watt & Watt ch. 17, soft objects), polygonised.
//!
//! Input: a decoded [`BlobbyProgram`] (object space), its primitive variables (one value per
//! leaf for the varying classes), `camera_from_object`, and the frame's raster transform.
//! Output: a [`BlobbySurface`] (not diceable) whose split polygonises the field's iso-surface
//! at [`BLOBBY_THRESHOLD`] into a quad [`Mesh`] that the polygon path splits, dices and shades.
//! Invariants: the field is evaluated in camera space on an axis-aligned lattice covering every
//! leaf's support (plus a margin of untouched lattice points), so the mesh is closed; lattice
//! cells are about `4·√ShadingRate` pixels at the bound's nearest depth, capped at
//! [`MAX_CELLS`]; each surface-crossing cell gets one vertex (the mean of its edge crossings,
//! then Newton-projected onto the surface: "surface nets"), each crossing lattice edge one
//! quad, wound so the Newell normal points out of the solid (the field decreases outward). N is
//! −∇f; varying values are blended by each leaf's field value at the vertex.
//!
//! Leaf fields: ellipsoid `(1 − r²)³` for `r² = |M⁻¹p|² < 1` (so a lone identity blob is the
//! sphere of radius ½), segment the same with `r` the distance to the segment over the radius
//! (in the segment matrix's space), constant its value. The repelling plane needs a depth map
//! texture arbor cannot sample here: it adds nothing, with a warning naming the map.

use std::sync::Arc;

use glam::{Mat3, Mat4, Vec2, Vec3};

use super::polygon::{Mesh, MeshData};
use super::primvar::{self, SourceVar};
use super::{Bound, Surface};
use crate::diag::{Diag, Diagnostics};
use crate::scene::blobby::{BlobOp, BlobbyProgram, BLOBBY_THRESHOLD};
use crate::scene::{Class, ParamType, Primitive};
use crate::shade::Grid;

/// Most lattice cells of one Blobby (memory: about 9 bytes a cell).
pub const MAX_CELLS: usize = 2_000_000;
/// Lattice cell edge in pixels at ShadingRate 1.
const CELL_PIXELS: f32 = 4.0;

#[derive(Clone, Debug)]
enum Leaf {
    Constant(f32),
    /// camera → unit-blob space.
    Ellipsoid {
        a: Mat4,
        at: Mat3,
    },
    Segment {
        a: Mat4,
        at: Mat3,
        p0: Vec3,
        d: Vec3,
        inv_dd: f32,
        inv_r2: f32,
    },
    /// Not honoured (repelling plane without a depth map).
    Zero,
}

impl Leaf {
    /// Field value, and its camera-space gradient when `grad`.
    #[inline]
    fn eval(&self, p: Vec3, grad: bool) -> (f32, Vec3) {
        match self {
            Leaf::Constant(c) => (*c, Vec3::ZERO),
            Leaf::Zero => (0.0, Vec3::ZERO),
            Leaf::Ellipsoid { a, at } => {
                let q = a.transform_point3(p);
                let r2 = q.length_squared();
                if r2 >= 1.0 {
                    return (0.0, Vec3::ZERO);
                }
                let t = 1.0 - r2;
                let g = if grad {
                    *at * (q * (-6.0 * t * t))
                } else {
                    Vec3::ZERO
                };
                (t * t * t, g)
            }
            Leaf::Segment {
                a,
                at,
                p0,
                d,
                inv_dd,
                inv_r2,
            } => {
                let q = a.transform_point3(p);
                let s = ((q - *p0).dot(*d) * inv_dd).clamp(0.0, 1.0);
                let e = q - (*p0 + s * *d);
                let r2 = e.length_squared() * inv_r2;
                if r2 >= 1.0 {
                    return (0.0, Vec3::ZERO);
                }
                let t = 1.0 - r2;
                let g = if grad {
                    *at * (e * (-6.0 * t * t * inv_r2))
                } else {
                    Vec3::ZERO
                };
                (t * t * t, g)
            }
        }
    }
}

/// The field program in camera space.
#[derive(Debug)]
struct Field {
    ops: Vec<BlobOp>,
    /// Leaf number of each instruction.
    leaf_of: Vec<Option<usize>>,
    leaves: Vec<Leaf>,
    /// Camera-space box outside which each leaf is 0 (None: constant or ignored).
    support: Vec<Option<Bound>>,
    /// The field is a sum of leaves (adds only, each leaf once): the lattice accumulates
    /// each leaf over its own support.
    pure_sum: bool,
}

impl Field {
    /// Field value (and gradient) at `p`; `weights`, when given, receives every bounded
    /// leaf's value there.
    fn eval(
        &self,
        p: Vec3,
        grad: bool,
        mut weights: Option<&mut Vec<(usize, f32)>>,
    ) -> (f32, Vec3) {
        let mut v: Vec<(f32, Vec3)> = Vec::with_capacity(self.ops.len());
        for (i, op) in self.ops.iter().enumerate() {
            let r = if let Some(l) = self.leaf_of[i] {
                let r = self.leaves[l].eval(p, grad);
                if let Some(w) = weights.as_deref_mut() {
                    if self.support[l].is_some() && r.0 > 0.0 {
                        w.push((l, r.0));
                    }
                }
                r
            } else {
                let at = |k: &u32| v[*k as usize];
                match op {
                    BlobOp::Add(o) => o
                        .iter()
                        .map(at)
                        .fold((0.0, Vec3::ZERO), |s, x| (s.0 + x.0, s.1 + x.1)),
                    BlobOp::Multiply(o) => o
                        .iter()
                        .map(at)
                        .fold((1.0, Vec3::ZERO), |s, x| (s.0 * x.0, s.1 * x.0 + x.1 * s.0)),
                    BlobOp::Max(o) => {
                        o.iter()
                            .map(at)
                            .fold((f32::NEG_INFINITY, Vec3::ZERO), |s, x| {
                                if x.0 > s.0 {
                                    x
                                } else {
                                    s
                                }
                            })
                    }
                    BlobOp::Min(o) => o.iter().map(at).fold((f32::INFINITY, Vec3::ZERO), |s, x| {
                        if x.0 < s.0 {
                            x
                        } else {
                            s
                        }
                    }),
                    BlobOp::Subtract(a, b) => {
                        let (x, y) = (at(a), at(b));
                        (x.0 - y.0, x.1 - y.1)
                    }
                    BlobOp::Divide(a, b) => {
                        let (x, y) = (at(a), at(b));
                        if y.0 == 0.0 {
                            (0.0, Vec3::ZERO)
                        } else {
                            (x.0 / y.0, (x.1 * y.0 - y.1 * x.0) / (y.0 * y.0))
                        }
                    }
                    BlobOp::Negate(a) => {
                        let x = at(a);
                        (-x.0, -x.1)
                    }
                    BlobOp::Identity(a) => at(a),
                    _ => (0.0, Vec3::ZERO),
                }
            };
            v.push(r);
        }
        v.last().copied().unwrap_or((0.0, Vec3::ZERO))
    }

    /// The field where every bounded leaf is 0 (outside all supports).
    fn far_value(&self) -> f32 {
        let far = Field {
            ops: self.ops.clone(),
            leaf_of: self.leaf_of.clone(),
            leaves: self
                .leaves
                .iter()
                .map(|l| match l {
                    Leaf::Constant(c) => Leaf::Constant(*c),
                    _ => Leaf::Zero,
                })
                .collect(),
            support: self.support.clone(),
            pure_sum: false,
        };
        far.eval(Vec3::ZERO, false, None).0
    }
}

/// A Blobby waiting to be polygonised.
#[derive(Debug)]
pub struct BlobbySurface {
    index: usize,
    field: Arc<Field>,
    /// The lattice: origin, cell edge, cells per axis.
    origin: Vec3,
    cell: f32,
    dims: [usize; 3],
    vars: Arc<Vec<SourceVar>>,
    object_from_camera: Mat4,
    flip: bool,
    color: Vec3,
    opacity: Vec3,
    split_triangles: bool,
}

/// The surfaces of a Blobby primitive (one [`BlobbySurface`], or none when it is empty).
pub(crate) fn surfaces(
    index: usize,
    prim: &Primitive,
    program: &BlobbyProgram,
    m: Mat4,
    raster_from_camera: Option<Mat4>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    match build(index, prim, program, m, raster_from_camera, diags) {
        Some(s) => vec![Box::new(s)],
        None => Vec::new(),
    }
}

fn build(
    index: usize,
    prim: &Primitive,
    program: &BlobbyProgram,
    m: Mat4,
    raster_from_camera: Option<Mat4>,
    diags: &Diagnostics,
) -> Option<BlobbySurface> {
    let leaf_of = program.leaf_numbers();
    let mut leaves = Vec::new();
    let mut support = Vec::new();
    let unit = Bound {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(1.0),
    };
    let carry = |b: Bound, cam_from: Mat4| {
        Bound::from_points(b.corners().map(|p| cam_from.transform_point3(p)))
    };
    for op in &program.ops {
        match op {
            BlobOp::Constant(c) => {
                leaves.push(Leaf::Constant(*c));
                support.push(None);
            }
            BlobOp::Ellipsoid(e) => {
                let cam_from = m * *e;
                if !cam_from.is_finite() || cam_from.determinant().abs() < 1e-30 {
                    leaves.push(Leaf::Zero);
                    support.push(None);
                    continue;
                }
                let a = cam_from.inverse();
                leaves.push(Leaf::Ellipsoid {
                    a,
                    at: Mat3::from_mat4(a).transpose(),
                });
                support.push(Some(carry(unit, cam_from)));
            }
            BlobOp::Segment {
                a: p0,
                b: p1,
                radius,
                m: sm,
            } => {
                let cam_from = m * *sm;
                let r = radius.abs();
                if !cam_from.is_finite() || cam_from.determinant().abs() < 1e-30 || !(r > 0.0) {
                    leaves.push(Leaf::Zero);
                    support.push(None);
                    continue;
                }
                let a = cam_from.inverse();
                let d = *p1 - *p0;
                let dd = d.length_squared();
                leaves.push(Leaf::Segment {
                    a,
                    at: Mat3::from_mat4(a).transpose(),
                    p0: *p0,
                    d,
                    inv_dd: if dd > 0.0 { 1.0 / dd } else { 0.0 },
                    inv_r2: 1.0 / (r * r),
                });
                let local = Bound::from_points([*p0, *p1]).grow(r);
                support.push(Some(carry(local, cam_from)));
            }
            BlobOp::Repulsion { depthmap, .. } => {
                diags.report(
                    Diag::warning(
                        "geom::blobby-repulsion",
                        format!("Blobby repelling plane (opcode 1003) needs the depth map texture \"{depthmap}\", which arbor cannot sample for blobbies; the plane adds nothing to the field"),
                    )
                    .label(prim.span, "this Blobby"),
                );
                leaves.push(Leaf::Zero);
                support.push(None);
            }
            _ => {}
        }
    }
    // A pure sum: adds only, reaching each leaf once.
    let pure_sum = {
        let mut uses = vec![0usize; program.ops.len()];
        let mut ok = true;
        let last = program.ops.len() - 1;
        let mut stack = vec![last];
        while let Some(i) = stack.pop() {
            uses[i] += 1;
            match &program.ops[i] {
                BlobOp::Add(o) => stack.extend(o.iter().map(|&k| k as usize)),
                BlobOp::Identity(a) => stack.push(*a as usize),
                op if op.is_leaf() => {}
                _ => ok = false,
            }
        }
        ok && uses.iter().all(|&u| u <= 1)
    };
    let field = Field {
        ops: program.ops.clone(),
        leaf_of,
        leaves,
        support,
        pure_sum,
    };
    let mut b = Bound::EMPTY;
    for s in field.support.iter().flatten() {
        b = b.union(*s);
    }
    if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
        return None; // no bounded leaf: no surface (a constant field is all or nothing)
    }
    let extent = b.max - b.min;
    let size = extent.max_element().max(1e-12);
    // Pixels per camera unit at the nearest depth of the bound.
    let rate = prim.attributes.shading_rate.max(1e-6);
    let mut cell = size / 48.0;
    if let Some(r) = raster_from_camera {
        let perspective = r.row(3).z != 0.0;
        let z = if perspective {
            b.min.z.max(size * 0.05).max(1e-6)
        } else {
            b.min.z
        };
        let proj = |p: Vec3| r.project_point3(p);
        let c = Vec3::new(0.5 * (b.min.x + b.max.x), 0.5 * (b.min.y + b.max.y), z);
        let px = (proj(c + Vec3::X * size) - proj(c)).truncate().length() / size;
        if px.is_finite() && px > 0.0 {
            cell = CELL_PIXELS * rate.sqrt() / px;
        }
    }
    // Cap the lattice; at least a few cells across the smallest blob.
    let count = |cell: f32| (extent / cell).ceil() + Vec3::splat(3.0);
    let n = count(cell);
    let total = n.x as f64 * n.y as f64 * n.z as f64;
    if total > MAX_CELLS as f64 {
        cell *= ((total / MAX_CELLS as f64).cbrt() as f32) * 1.01;
    }
    let n = count(cell);
    let dims = [n.x as usize, n.y as usize, n.z as usize];
    // Centre the lattice on the bound: untouched points all round keep the mesh closed.
    let origin = 0.5 * (b.min + b.max)
        - 0.5 * cell * Vec3::new(dims[0] as f32, dims[1] as f32, dims[2] as f32);
    let nleaf = program.nleaf;
    let counts = primvar::ClassCounts {
        uniform: 1,
        varying: nleaf,
        facevarying: nleaf,
    };
    let mut vars = primvar::resolve(&prim.primvars, m, counts, diags);
    if let Some(pos) = vars.iter().position(|v| v.name == "N") {
        diags.report(
            Diag::warning(
                "geom::blobby-normal",
                "a Blobby's normals come from its field's gradient; the \"N\" given is ignored",
            )
            .label(prim.span, "this Blobby"),
        );
        vars.remove(pos);
    }
    Some(BlobbySurface {
        index,
        field: Arc::new(field),
        origin,
        cell,
        dims,
        vars: Arc::new(vars),
        object_from_camera: m.inverse(),
        flip: prim.attributes.reverse_orientation,
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
        split_triangles: prim.attributes.displacement.is_some(),
    })
}

const NONE: u32 = u32::MAX;

impl BlobbySurface {
    /// The lattice's field values, point (i, j, k) at `(k·(ny+1) + j)·(nx+1) + i`.
    fn lattice(&self) -> Vec<f32> {
        let [nx, ny, nz] = self.dims;
        let (px, py) = (nx + 1, ny + 1);
        let h = self.cell;
        let at = |i: usize, j: usize, k: usize| {
            self.origin + h * Vec3::new(i as f32, j as f32, k as f32)
        };
        let f = &*self.field;
        let far = f.far_value();
        let mut v = vec![far; px * py * (nz + 1)];
        let range = |lo: f32, hi: f32, o: f32, n: usize| {
            let a = ((lo - o) / h).floor().max(0.0) as usize;
            let b = (((hi - o) / h).ceil().max(0.0) as usize).min(n);
            a..b + 1
        };
        if f.pure_sum {
            for (l, s) in f.support.iter().enumerate() {
                let Some(s) = s else { continue };
                let leaf = &f.leaves[l];
                for k in range(s.min.z, s.max.z, self.origin.z, nz) {
                    for j in range(s.min.y, s.max.y, self.origin.y, ny) {
                        let row = (k * py + j) * px;
                        for i in range(s.min.x, s.max.x, self.origin.x, nx) {
                            v[row + i] += leaf.eval(at(i, j, k), false).0;
                        }
                    }
                }
            }
        } else {
            for k in 0..=nz {
                for j in 0..=ny {
                    let row = (k * py + j) * px;
                    for i in 0..=nx {
                        v[row + i] = f.eval(at(i, j, k), false, None).0;
                    }
                }
            }
        }
        v
    }

    /// Surface nets over the lattice: vertices (camera space), their normals and blended
    /// variables, and quads (vertex indices, outward winding).
    fn polygonise(&self) -> Option<MeshData> {
        let [nx, ny, nz] = self.dims;
        let (px, py) = (nx + 1, ny + 1);
        let h = self.cell;
        let t = BLOBBY_THRESHOLD;
        let field = self.lattice();
        let pidx = |i: usize, j: usize, k: usize| (k * py + j) * px + i;
        let cidx = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
        let at = |i: usize, j: usize, k: usize| {
            self.origin + h * Vec3::new(i as f32, j as f32, k as f32)
        };
        let mut cell_vertex = vec![NONE; nx * ny * nz];
        let mut p: Vec<Vec3> = Vec::new();
        let mut normals: Vec<Vec3> = Vec::new();
        let mut weights: Vec<Vec<(usize, f32)>> = Vec::new();
        const CORNERS: [[usize; 3]; 8] = [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [1, 1, 0],
            [0, 0, 1],
            [1, 0, 1],
            [0, 1, 1],
            [1, 1, 1],
        ];
        const EDGES: [[usize; 2]; 12] = [
            [0, 1],
            [2, 3],
            [4, 5],
            [6, 7],
            [0, 2],
            [1, 3],
            [4, 6],
            [5, 7],
            [0, 4],
            [1, 5],
            [2, 6],
            [3, 7],
        ];
        let f = &*self.field;
        let mut w = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let vals = CORNERS.map(|c| field[pidx(i + c[0], j + c[1], k + c[2])]);
                    let ins = vals.map(|v| v > t);
                    if ins.iter().all(|&x| x) || ins.iter().all(|&x| !x) {
                        continue;
                    }
                    let base = at(i, j, k);
                    let mut sum = Vec3::ZERO;
                    let mut n = 0.0;
                    for [a, b] in EDGES {
                        if ins[a] != ins[b] {
                            let s = ((t - vals[a]) / (vals[b] - vals[a])).clamp(0.0, 1.0);
                            let ca = Vec3::from_array(CORNERS[a].map(|x| x as f32));
                            let cb = Vec3::from_array(CORNERS[b].map(|x| x as f32));
                            sum += ca + s * (cb - ca);
                            n += 1.0;
                        }
                    }
                    let lo = base - Vec3::splat(0.5 * h);
                    let hi = base + Vec3::splat(1.5 * h);
                    let mut x = base + h * sum / n;
                    // Newton steps along the gradient onto f = t, kept near the cell.
                    for _ in 0..6 {
                        let (fx, g) = f.eval(x, true, None);
                        let gg = g.length_squared();
                        if !(gg > 1e-30) || (fx - t).abs() < 1e-6 {
                            break;
                        }
                        x = (x - g * ((fx - t) / gg)).clamp(lo, hi);
                    }
                    w.clear();
                    let (_, g) = f.eval(x, true, Some(&mut w));
                    let mut nrm = (-g).normalize_or_zero();
                    if self.flip {
                        nrm = -nrm;
                    }
                    cell_vertex[cidx(i, j, k)] = p.len() as u32;
                    p.push(x);
                    normals.push(nrm);
                    weights.push(w.clone());
                }
            }
        }
        // One quad per crossing lattice edge, around it through its four cells.
        let mut verts: Vec<u32> = Vec::new();
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    let here = field[pidx(i, j, k)] > t;
                    let c = [i, j, k];
                    for axis in 0..3 {
                        let mut o = c;
                        o[axis] += 1;
                        if o[axis] > self.dims[axis] {
                            continue;
                        }
                        let there = field[pidx(o[0], o[1], o[2])] > t;
                        if here == there {
                            continue;
                        }
                        let (b, cc) = ((axis + 1) % 3, (axis + 2) % 3);
                        if c[b] == 0
                            || c[cc] == 0
                            || c[b] > self.dims[b] - 1
                            || c[cc] > self.dims[cc] - 1
                        {
                            continue;
                        }
                        let cell = |db: usize, dc: usize| {
                            let mut q = c;
                            q[b] = q[b] + db - 1;
                            q[cc] = q[cc] + dc - 1;
                            cell_vertex[cidx(q[0], q[1], q[2])]
                        };
                        let quad = [cell(0, 0), cell(1, 0), cell(1, 1), cell(0, 1)];
                        if quad.contains(&NONE) {
                            continue;
                        }
                        // Counter-clockwise about +axis; outward is +axis when inside here.
                        let q = if here != self.flip {
                            quad
                        } else {
                            [quad[0], quad[3], quad[2], quad[1]]
                        };
                        verts.extend_from_slice(&q);
                    }
                }
            }
        }
        let nfaces = verts.len() / 4;
        if nfaces == 0 {
            return None;
        }
        let vars = self.vertex_vars(&normals, &weights);
        Some(MeshData {
            index: self.index,
            obj_xy: p
                .iter()
                .map(|&q| {
                    let o = self.object_from_camera.transform_point3(q);
                    Vec2::new(o.x, o.y)
                })
                .collect(),
            p,
            nverts: vec![4; nfaces],
            verts,
            loop_start: (0..=nfaces).collect(),
            fv_start: (0..=nfaces).map(|f| 4 * f).collect(),
            valid: vec![true; nfaces],
            vars,
            // The winding already faces outward (or inward when flipped).
            flip: false,
            decomp_p: None,
            color: self.color,
            opacity: self.opacity,
            split_triangles: self.split_triangles,
        })
    }

    /// The primitive variables per mesh vertex: per-leaf values blended by the leaves' field
    /// values; uniform ones become constant; N from the gradient.
    fn vertex_vars(&self, normals: &[Vec3], weights: &[Vec<(usize, f32)>]) -> Vec<SourceVar> {
        let mut out = Vec::new();
        for v in self.vars.iter() {
            let w = v.width();
            match v.class {
                Class::Constant => out.push(v.clone()),
                Class::Uniform => out.push(SourceVar {
                    class: Class::Constant,
                    floats: v.floats.get(..w).unwrap_or(&[]).to_vec(),
                    strings: v
                        .strings
                        .get(..w.min(v.strings.len()))
                        .unwrap_or(&[])
                        .to_vec(),
                    ..v.clone()
                }),
                _ => {
                    let mut floats = Vec::with_capacity(weights.len() * w);
                    let nvals = v.floats.len() / w.max(1);
                    for ws in weights {
                        let total: f32 = ws.iter().map(|x| x.1).sum();
                        let mut acc = vec![0f32; w];
                        if total > 0.0 {
                            for &(l, wt) in ws {
                                let l = l.min(nvals.saturating_sub(1));
                                for c in 0..w {
                                    acc[c] += wt / total * v.floats[l * w + c];
                                }
                            }
                        } else if nvals > 0 {
                            // No leaf reaches the vertex (a constant-driven surface): the mean.
                            for l in 0..nvals {
                                for c in 0..w {
                                    acc[c] += v.floats[l * w + c] / nvals as f32;
                                }
                            }
                        }
                        floats.extend_from_slice(&acc);
                    }
                    out.push(SourceVar {
                        class: Class::Vertex,
                        floats,
                        ..v.clone()
                    });
                }
            }
        }
        out.push(SourceVar {
            name: "N".into(),
            ty: ParamType::Normal,
            array_len: 1,
            class: Class::Vertex,
            floats: normals.iter().flat_map(|n| n.to_array()).collect(),
            strings: Vec::new(),
        });
        out
    }

    /// The lattice's box.
    fn lattice_bound(&self) -> Bound {
        let d = Vec3::new(
            self.dims[0] as f32,
            self.dims[1] as f32,
            self.dims[2] as f32,
        );
        Bound {
            min: self.origin,
            max: self.origin + self.cell * d,
        }
    }
}

impl Surface for BlobbySurface {
    fn bound(&self) -> Bound {
        super::pad(self.lattice_bound())
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        match self.polygonise() {
            Some(data) => {
                let n = data.valid.len();
                vec![Box::new(Mesh {
                    data: Arc::new(data),
                    faces: 0..n,
                })]
            }
            None => Vec::new(),
        }
    }

    fn diceable(&self) -> bool {
        false
    }

    fn dice(&self, _nu: usize, _nv: usize) -> Grid {
        Grid::default()
    }

    fn primitive(&self) -> usize {
        self.index
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::blobby::decode;
    use crate::scene::{Attributes, Geometry, ParamList};

    fn prim(program: BlobbyProgram) -> Primitive {
        Primitive {
            geometry: Arc::new(Geometry::Blobby(Arc::new(program))),
            primvars: Arc::new(ParamList::default()),
            attributes: Arc::new(Attributes::default()),
            world_from_object: Mat4::IDENTITY.into(),
            span: crate::diag::Span::new(0, 0, 0),
            motion: None,
        }
    }

    fn mat(s: f32, t: Vec3) -> Vec<f32> {
        Mat4::from_scale_rotation_translation(Vec3::splat(s), glam::Quat::IDENTITY, t)
            .to_cols_array()
            .to_vec()
    }

    fn mesh(code: &[i64], floats: &[f32]) -> MeshData {
        let nleaf = code.iter().filter(|&&c| c >= 1000).count() as i64;
        let (p, _) = decode(nleaf, code, floats, &[]).ok().unwrap();
        let pr = prim(p.clone());
        let d = Diagnostics::default();
        let m = Mat4::from_translation(Vec3::new(0.0, 0.0, 5.0));
        build(0, &pr, &p, m, None, &d)
            .unwrap()
            .polygonise()
            .unwrap()
    }

    #[test]
    fn a_lone_blob_is_the_sphere_of_radius_one_half() {
        let m = mesh(&[1001, 0], &mat(2.0, Vec3::ZERO));
        let c = Vec3::new(0.0, 0.0, 5.0);
        for (q, n) in m.p.iter().zip(m.vars.last().unwrap().floats.chunks(3)) {
            assert!(((*q - c).length() - 1.0).abs() < 1e-3, "{q}");
            let n = Vec3::from_slice(n);
            assert!(n.dot((*q - c).normalize()) > 0.999, "outward normal {n}");
        }
        // Every quad's Newell normal points outward.
        for f in m.verts.chunks(4) {
            let v: Vec<Vec3> = f.iter().map(|&i| m.p[i as usize]).collect();
            let nrm = (v[1] - v[0]).cross(v[2] - v[0]) + (v[2] - v[0]).cross(v[3] - v[0]);
            let mid = (v[0] + v[1] + v[2] + v[3]) * 0.25 - c;
            assert!(nrm.dot(mid) > 0.0);
        }
    }

    #[test]
    fn the_mesh_is_closed() {
        // Two blobs merging: every edge is shared by exactly two quads.
        let mut f = mat(2.0, Vec3::new(-0.6, 0.0, 0.0));
        f.extend(mat(2.0, Vec3::new(0.6, 0.0, 0.0)));
        let m = mesh(&[1001, 0, 1001, 16, 0, 2, 0, 1], &f);
        let mut edges = std::collections::HashMap::new();
        for q in m.verts.chunks(4) {
            for e in 0..4 {
                let (a, b) = (q[e], q[(e + 1) % 4]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        assert!(edges.values().all(|&n| n % 2 == 0));
        // The neck at x = 0 is filled: there the surface is at |y| ≈ 1.12, where two spheres
        // of radius 1 that did not blend would reach only 0.8.
        let neck =
            m.p.iter()
                .filter(|q| q.x.abs() < 0.15 && (q.z - 5.0).abs() < 0.3)
                .map(|q| q.y.abs())
                .fold(0f32, f32::max);
        assert!(neck > 1.0, "neck half-width {neck}");
    }
}
