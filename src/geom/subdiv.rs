//! Subdivision surfaces (RISpec §5.5): Catmull–Clark refinement to a limit quad mesh.
//!
//! Input: `Geometry::SubdivisionMesh` (faces of any size, tags), "P" and the primitive
//! variables, `camera_from_object`.
//! Output: one polygon [`Mesh`] of limit-surface quads with a facevarying "N" (limit normals),
//! handed to the polygon code path (bilinear patches).
//! Rules: the control mesh is moved to camera space once (subdivision is affine invariant),
//! refined `levels` times with Catmull–Clark rules (the first level turns every n-gon into n
//! quads), then every vertex is pushed to its limit position. Boundary edges are always sharp
//! (B-spline curves); with `interpolateboundary` valence-2 boundary vertices are also corners
//! (kept), without it they follow the crease rule (the surface still reaches the boundary: an
//! approximation of RenderMan's open boundary). `crease` sharpness ≥ 10 is infinitely sharp;
//! fractional sharpness s uses the semi-sharp rules (sharp for ⌊s⌋ levels, the last blended).
//! `corner` with any positive sharpness pins the vertex (fractional corners are approximated
//! as infinitely sharp). `hole` faces and their children are not rendered. Vertex-class
//! variables follow the same masks as P (limit included); varying and facevarying ones are
//! subdivided linearly (bilinear within each face); uniform ones follow the parent face.
//! Limit normals: the Catmull–Clark tangent masks at smooth vertices; at crease, boundary and
//! corner vertices the average of the limit faces' normals in the vertex's sector (so normals
//! are discontinuous across sharp creases). Scheme "loop" is warned about and refined as
//! Catmull–Clark; "bilinear" refines linearly.

use std::collections::HashMap;
use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use super::polygon::{Mesh, MeshData};
use super::primvar::{resolve, ClassCounts, SourceVar};
use super::Surface;
use crate::diag::{Diag, Diagnostics};
use crate::scene::{Class, ParamType, Primitive};

/// Most quads of the refined mesh; fewer levels are used when the budget would be exceeded.
const FACE_BUDGET: usize = 150_000;
/// Most refinement levels.
const MAX_LEVELS: usize = 4;
/// Sharpness treated as infinitely sharp.
const INF_SHARP: f32 = 10.0;

/// One level of the mesh: flat per-element data of `vw` (vertex rules), `lw` (linear rules)
/// and `fw` (per face-vertex) numbers; the first three vertex numbers are the position.
#[derive(Clone, Debug, Default)]
pub(crate) struct Level {
    pub vw: usize,
    pub vtx: Vec<f32>,
    pub lw: usize,
    pub lin: Vec<f32>,
    pub fw: usize,
    pub fvar: Vec<f32>,
    /// Per face: first face-vertex; one extra entry closes the last face.
    pub start: Vec<usize>,
    pub verts: Vec<u32>,
    /// Per face: the control face it came from, and whether it is a hole.
    pub parent: Vec<u32>,
    pub hole: Vec<bool>,
    /// Edge sharpness keyed by (min, max) vertex.
    pub sharp: HashMap<(u32, u32), f32>,
    /// Corner sharpness per vertex.
    pub corner: Vec<f32>,
    /// Valence-2 boundary vertices are corners.
    pub interp_boundary: bool,
    /// Linear ("bilinear" scheme) refinement.
    pub linear: bool,
}

fn key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Edges and adjacency of a level.
struct Topo {
    /// Edge endpoints and up to two faces (u32::MAX = none); `nf` faces on the edge.
    edges: Vec<(u32, u32)>,
    efaces: Vec<[u32; 2]>,
    enf: Vec<u32>,
    /// Per face-vertex: the edge from it to the next vertex of its face.
    fv_edge: Vec<u32>,
    /// Per vertex: incident edges and faces.
    vedges: Vec<Vec<u32>>,
    vfaces: Vec<Vec<u32>>,
}

impl Level {
    fn nverts(&self) -> usize {
        self.vtx.len() / self.vw
    }
    fn nfaces(&self) -> usize {
        self.start.len() - 1
    }
    fn pos(&self, v: usize) -> Vec3 {
        Vec3::from_slice(&self.vtx[v * self.vw..v * self.vw + 3])
    }

    fn topo(&self) -> Topo {
        let nv = self.nverts();
        let mut map: HashMap<(u32, u32), u32> = HashMap::with_capacity(self.verts.len());
        let mut t = Topo {
            edges: Vec::new(),
            efaces: Vec::new(),
            enf: Vec::new(),
            fv_edge: vec![0; self.verts.len()],
            vedges: vec![Vec::new(); nv],
            vfaces: vec![Vec::new(); nv],
        };
        for f in 0..self.nfaces() {
            let (s, e) = (self.start[f], self.start[f + 1]);
            for i in s..e {
                let a = self.verts[i];
                let b = self.verts[if i + 1 == e { s } else { i + 1 }];
                t.vfaces[a as usize].push(f as u32);
                let id = *map.entry(key(a, b)).or_insert_with(|| {
                    let id = t.edges.len() as u32;
                    t.edges.push((a, b));
                    t.efaces.push([u32::MAX; 2]);
                    t.enf.push(0);
                    t.vedges[a as usize].push(id);
                    t.vedges[b as usize].push(id);
                    id
                });
                let n = t.enf[id as usize];
                if n < 2 {
                    t.efaces[id as usize][n as usize] = f as u32;
                }
                t.enf[id as usize] += 1;
                t.fv_edge[i] = id;
            }
        }
        t
    }

    fn edge_sharp(&self, t: &Topo, e: usize) -> f32 {
        if t.enf[e] != 2 {
            return f32::INFINITY; // boundary (or non-manifold) edges are sharp
        }
        let (a, b) = t.edges[e];
        self.sharp.get(&key(a, b)).copied().unwrap_or(0.0)
    }

    /// How a vertex moves: its sharp edges' other ends and their mean sharpness, or a corner.
    fn vertex_kind(&self, t: &Topo, v: usize) -> Kind {
        let mut ends = [0u32; 2];
        let (mut count, mut sum) = (0usize, 0.0f32);
        let mut boundary = false;
        for &e in &t.vedges[v] {
            let s = self.edge_sharp(t, e as usize);
            if s > 0.0 {
                if count < 2 {
                    let (a, b) = t.edges[e as usize];
                    ends[count] = if a as usize == v { b } else { a };
                }
                count += 1;
                sum += s.min(INF_SHARP);
                boundary |= t.enf[e as usize] != 2;
            }
        }
        if self.corner[v] > 0.0 || count > 2 {
            return Kind::Corner;
        }
        if boundary && self.interp_boundary && t.vfaces[v].len() == 1 {
            return Kind::Corner;
        }
        if count == 2 {
            let s = sum / 2.0;
            return Kind::Crease(ends, if s >= 1.0 { 1.0 } else { s });
        }
        Kind::Smooth
    }

    /// One Catmull–Clark (or linear) refinement: old vertices, then face points, then edge
    /// points; face f's k-th child is the quad (v_k, e_k, f, e_{k−1}).
    pub(crate) fn refine(&self) -> Level {
        let t = self.topo();
        let (nv, nf, ne) = (self.nverts(), self.nfaces(), t.edges.len());
        let (vw, lw, fw) = (self.vw, self.lw, self.fw);
        let total = nv + nf + ne;
        let mut vtx = vec![0.0f32; total * vw];
        let mut lin = vec![0.0f32; total * lw];
        let fp = nv;
        let ep = nv + nf;
        // Face points: centroids.
        for f in 0..nf {
            let (s, e) = (self.start[f], self.start[f + 1]);
            let w = 1.0 / (e - s) as f32;
            for i in s..e {
                let v = self.verts[i] as usize;
                axpy(
                    &mut vtx[(fp + f) * vw..][..vw],
                    w,
                    &self.vtx[v * vw..][..vw],
                );
                axpy(
                    &mut lin[(fp + f) * lw..][..lw],
                    w,
                    &self.lin[v * lw..][..lw],
                );
            }
        }
        // Edge points.
        let mut tmp = vec![0.0f32; vw];
        for e in 0..ne {
            let (a, b) = (t.edges[e].0 as usize, t.edges[e].1 as usize);
            let s = if self.linear {
                f32::INFINITY
            } else {
                self.edge_sharp(&t, e)
            };
            let (head, tail) = vtx.split_at_mut((ep + e) * vw);
            let out = &mut tail[..vw];
            axpy(out, 0.5, &self.vtx[a * vw..][..vw]);
            axpy(out, 0.5, &self.vtx[b * vw..][..vw]);
            if s < 1.0 {
                // Smooth rule (a + b + f0 + f1) / 4, blended with the midpoint by s.
                tmp.iter_mut().for_each(|x| *x = 0.0);
                axpy(&mut tmp, 0.25, &self.vtx[a * vw..][..vw]);
                axpy(&mut tmp, 0.25, &self.vtx[b * vw..][..vw]);
                for &f in &t.efaces[e] {
                    axpy(&mut tmp, 0.25, &head[(fp + f as usize) * vw..][..vw]);
                }
                for (o, &m) in out.iter_mut().zip(&tmp) {
                    *o = s * *o + (1.0 - s) * m;
                }
            }
            let lo = &mut lin[(ep + e) * lw..][..lw];
            axpy(lo, 0.5, &self.lin[a * lw..][..lw]);
            axpy(lo, 0.5, &self.lin[b * lw..][..lw]);
        }
        // Vertex points.
        let mut smooth = vec![0.0f32; vw];
        for v in 0..nv {
            lin[v * lw..][..lw].copy_from_slice(&self.lin[v * lw..][..lw]);
            let old = &self.vtx[v * vw..][..vw];
            let kind = if self.linear {
                Kind::Corner
            } else {
                self.vertex_kind(&t, v)
            };
            let (head, tail) = vtx.split_at_mut(nv * vw);
            let out = &mut head[v * vw..][..vw];
            let smooth_rule = |smooth: &mut [f32]| {
                // (F + 2R + (n − 3) V) / n with F, R the mean face and edge-midpoint.
                let n = t.vedges[v].len() as f32;
                smooth.iter_mut().for_each(|x| *x = 0.0);
                let nfc = t.vfaces[v].len().max(1) as f32;
                for &f in &t.vfaces[v] {
                    axpy(smooth, 1.0 / (nfc * n), &tail[f as usize * vw..][..vw]);
                }
                for &e in &t.vedges[v] {
                    let (a, b) = t.edges[e as usize];
                    axpy(smooth, 1.0 / (n * n), &self.vtx[a as usize * vw..][..vw]);
                    axpy(smooth, 1.0 / (n * n), &self.vtx[b as usize * vw..][..vw]);
                }
                axpy(smooth, (n - 3.0) / n, old);
            };
            match kind {
                Kind::Corner => out.copy_from_slice(old),
                Kind::Crease(ends, s) => {
                    axpy(out, 0.75, old);
                    for x in ends {
                        axpy(out, 0.125, &self.vtx[x as usize * vw..][..vw]);
                    }
                    if s < 1.0 {
                        smooth_rule(&mut smooth);
                        for (o, &m) in out.iter_mut().zip(&smooth) {
                            *o = s * *o + (1.0 - s) * m;
                        }
                    }
                }
                Kind::Smooth if t.vedges[v].len() >= 3 => {
                    smooth_rule(&mut smooth);
                    out.copy_from_slice(&smooth);
                }
                Kind::Smooth => out.copy_from_slice(old),
            }
        }
        // Children faces.
        let nfv = self.verts.len();
        let mut next = Level {
            vw,
            vtx,
            lw,
            lin,
            fw,
            fvar: Vec::with_capacity(nfv * 4 * fw),
            start: Vec::with_capacity(nfv + 1),
            verts: Vec::with_capacity(nfv * 4),
            parent: Vec::with_capacity(nfv),
            hole: Vec::with_capacity(nfv),
            sharp: HashMap::new(),
            corner: self.corner.clone(),
            interp_boundary: self.interp_boundary,
            linear: self.linear,
        };
        next.corner.resize(total, 0.0);
        next.start.push(0);
        let mut center = vec![0.0f32; fw];
        for f in 0..nf {
            let (s, e) = (self.start[f], self.start[f + 1]);
            let n = e - s;
            center.iter_mut().for_each(|x| *x = 0.0);
            for i in s..e {
                axpy(&mut center, 1.0 / n as f32, &self.fvar[i * fw..][..fw]);
            }
            for k in 0..n {
                let i = s + k;
                let ip = if k == 0 { e - 1 } else { i - 1 };
                let inx = if k + 1 == n { s } else { i + 1 };
                let (ek, ekp) = (t.fv_edge[i] as usize, t.fv_edge[ip] as usize);
                next.verts.extend_from_slice(&[
                    self.verts[i],
                    (ep + ek) as u32,
                    (fp + f) as u32,
                    (ep + ekp) as u32,
                ]);
                let fv = |j: usize| &self.fvar[j * fw..][..fw];
                next.fvar.extend_from_slice(fv(i));
                next.fvar
                    .extend(fv(i).iter().zip(fv(inx)).map(|(a, b)| 0.5 * (a + b)));
                next.fvar.extend_from_slice(&center);
                next.fvar
                    .extend(fv(i).iter().zip(fv(ip)).map(|(a, b)| 0.5 * (a + b)));
                next.start.push(next.verts.len());
                next.parent.push(self.parent[f]);
                next.hole.push(self.hole[f]);
            }
        }
        // Sharp edges split into two children one level less sharp.
        for (&(a, b), &s) in &self.sharp {
            let s2 = if s >= INF_SHARP { s } else { s - 1.0 };
            if s2 <= 0.0 {
                continue;
            }
            // Find the edge's id through the adjacency of a.
            if let Some(&e) = t.vedges[a as usize]
                .iter()
                .find(|&&e| key(t.edges[e as usize].0, t.edges[e as usize].1) == (a, b))
            {
                let m = (ep + e as usize) as u32;
                next.sharp.insert(key(a, m), s2);
                next.sharp.insert(key(m, b), s2);
            }
        }
        next
    }

    /// Limit positions (vertex data) and per face-vertex limit normals of a quad mesh.
    pub(crate) fn limit(&self) -> (Vec<f32>, Vec<Vec3>) {
        let t = self.topo();
        let (nv, vw) = (self.nverts(), self.vw);
        let mut out = vec![0.0f32; nv * vw];
        let mut smooth_n = vec![None::<Vec3>; nv];
        let mut ring_e = Vec::new();
        let mut ring_f = Vec::new();
        for v in 0..nv {
            let o = &mut out[v * vw..][..vw];
            let kind = if self.linear {
                Kind::Corner
            } else {
                self.vertex_kind(&t, v)
            };
            match kind {
                Kind::Corner => o.copy_from_slice(&self.vtx[v * vw..][..vw]),
                Kind::Crease(ends, _) => {
                    // The B-spline curve's limit (a + 4v + b) / 6.
                    axpy(o, 4.0 / 6.0, &self.vtx[v * vw..][..vw]);
                    for x in ends {
                        axpy(o, 1.0 / 6.0, &self.vtx[x as usize * vw..][..vw]);
                    }
                }
                Kind::Smooth => {
                    if !self.ring(&t, v, &mut ring_e, &mut ring_f) {
                        o.copy_from_slice(&self.vtx[v * vw..][..vw]);
                        continue;
                    }
                    // (n² v + 4 Σ e_i + Σ f_i) / (n (n + 5)).
                    let n = ring_e.len() as f32;
                    let d = n * (n + 5.0);
                    axpy(o, n * n / d, &self.vtx[v * vw..][..vw]);
                    for &x in &ring_e {
                        axpy(o, 4.0 / d, &self.vtx[x as usize * vw..][..vw]);
                    }
                    for &x in &ring_f {
                        axpy(o, 1.0 / d, &self.vtx[x as usize * vw..][..vw]);
                    }
                    // Tangent masks (Halstead et al. 1993).
                    let a = 1.0
                        + (2.0 * PI / n).cos()
                        + (PI / n).cos() * (2.0 * (9.0 + (2.0 * PI / n).cos())).sqrt();
                    let (mut t1, mut t2) = (Vec3::ZERO, Vec3::ZERO);
                    for i in 0..ring_e.len() {
                        let (th, th1) = (2.0 * PI * i as f32 / n, 2.0 * PI * (i + 1) as f32 / n);
                        let e = self.pos(ring_e[i] as usize);
                        let f = self.pos(ring_f[i] as usize);
                        t1 += a * th.cos() * e + (th.cos() + th1.cos()) * f;
                        t2 += a * th.sin() * e + (th.sin() + th1.sin()) * f;
                    }
                    smooth_n[v] = Some(t1.cross(t2));
                }
            }
        }
        // Limit-face normals, for orienting the mask normals and for sector averages.
        let lp = |v: u32| Vec3::from_slice(&out[v as usize * vw..][..3]);
        let nf = self.nfaces();
        let fnorm: Vec<Vec3> = (0..nf)
            .map(|f| {
                let q = &self.verts[self.start[f]..self.start[f + 1]];
                newell(q.iter().map(|&v| lp(v)))
            })
            .collect();
        let mut normals = vec![Vec3::ZERO; self.verts.len()];
        for f in 0..nf {
            let (s, e) = (self.start[f], self.start[f + 1]);
            for i in s..e {
                let v = self.verts[i] as usize;
                normals[i] = match smooth_n[v] {
                    Some(n) => {
                        let around: Vec3 = t.vfaces[v].iter().map(|&g| fnorm[g as usize]).sum();
                        if n.dot(around) < 0.0 {
                            -n
                        } else {
                            n
                        }
                    }
                    None => self.sector_normal(&t, &fnorm, f, i),
                }
                .normalize_or_zero();
            }
        }
        (out, normals)
    }

    /// The ordered one-ring of a smooth interior quad-mesh vertex: edge neighbours e_i and the
    /// face-opposite vertices f_i between e_i and e_{i+1}. False when the walk fails.
    fn ring(&self, t: &Topo, v: usize, re: &mut Vec<u32>, rf: &mut Vec<u32>) -> bool {
        re.clear();
        rf.clear();
        let Some(&f0) = t.vfaces[v].first() else {
            return false;
        };
        let mut f = f0 as usize;
        for _ in 0..t.vfaces[v].len() {
            let (s, e) = (self.start[f], self.start[f + 1]);
            if e - s != 4 {
                return false;
            }
            let Some(k) = (s..e).find(|&i| self.verts[i] as usize == v) else {
                return false;
            };
            let at = |d: usize| self.verts[s + (k - s + d) % 4];
            re.push(at(1));
            rf.push(at(2));
            // Across the edge (v, prev) to the next face around v.
            let pe = t.fv_edge[s + (k - s + 3) % 4] as usize;
            if t.enf[pe] != 2 {
                return false;
            }
            let [a, b] = t.efaces[pe];
            f = if a as usize == f { b } else { a } as usize;
            if f == f0 as usize {
                break;
            }
        }
        f == f0 as usize && re.len() == t.vfaces[v].len()
    }

    /// The mean normal of the limit faces around face-vertex `i` (of face `f`) that are reached
    /// without crossing a sharp edge.
    fn sector_normal(&self, t: &Topo, fnorm: &[Vec3], f: usize, i: usize) -> Vec3 {
        let v = self.verts[i];
        let mut sum = fnorm[f];
        for dir in [1usize, 3] {
            let mut g = f;
            let mut gi = i;
            for _ in 0..64 {
                let (s, e) = (self.start[g], self.start[g + 1]);
                let n = e - s;
                let k = gi - s;
                // The edge leaving v forward (dir 1: edge k) or backward (dir 3: edge k − 1).
                let fe = if dir == 1 { gi } else { s + (k + n - 1) % n };
                let edge = t.fv_edge[fe] as usize;
                if self.edge_sharp(t, edge) > 0.0 {
                    break;
                }
                let [a, b] = t.efaces[edge];
                let h = if a as usize == g { b } else { a } as usize;
                if h == f {
                    break;
                }
                let Some(hi) = (self.start[h]..self.start[h + 1]).find(|&j| self.verts[j] == v)
                else {
                    break;
                };
                sum += fnorm[h];
                g = h;
                gi = hi;
            }
        }
        sum
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Smooth,
    /// The two sharp edges' far ends and the sharpness weight (1 = fully sharp).
    Crease([u32; 2], f32),
    Corner,
}

#[inline]
fn axpy(out: &mut [f32], a: f32, x: &[f32]) {
    for (o, &v) in out.iter_mut().zip(x) {
        *o += a * v;
    }
}

fn newell(pts: impl Iterator<Item = Vec3> + Clone) -> Vec3 {
    let v: Vec<Vec3> = pts.collect();
    let mut n = Vec3::ZERO;
    for k in 0..v.len() {
        let (a, b) = (v[k], v[(k + 1) % v.len()]);
        n += Vec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    n
}

/// The fields of `Geometry::SubdivisionMesh`.
pub(crate) struct SubdivArgs<'a> {
    pub scheme: &'a str,
    pub nverts: &'a [u32],
    pub verts: &'a [u32],
    pub tags: &'a [String],
    pub nargs: &'a [u32],
    pub intargs: &'a [i64],
    pub floatargs: &'a [f32],
}

/// The surfaces of a subdivision mesh (see the module docs).
pub(crate) fn subdivision(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    a: SubdivArgs<'_>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let err = |msg: String| {
        diags.report(
            Diag::error("geom::invalid", msg)
                .label(prim.span, "this subdivision mesh")
                .help("check the vertex counts and indices against \"P\""),
        );
    };
    let warn = |msg: String| {
        diags.report(
            Diag::warning("geom::subdivision", msg).label(prim.span, "this subdivision mesh"),
        );
    };
    let linear = match a.scheme {
        "catmull-clark" => false,
        "bilinear" => true,
        "loop" => {
            warn(
                "the \"loop\" scheme is not implemented; the mesh is refined as \"catmull-clark\""
                    .into(),
            );
            false
        }
        other => {
            warn(format!(
                "unknown subdivision scheme \"{other}\"; \"catmull-clark\" is used"
            ));
            false
        }
    };
    let obj: Vec<Vec3> = if let Some(p) = prim.primvars.floats("P").filter(|f| !f.is_empty()) {
        p.chunks_exact(3).map(Vec3::from_slice).collect()
    } else if let Some(p) = prim.primvars.floats("Pw").filter(|f| !f.is_empty()) {
        p.chunks_exact(4)
            .map(|c| Vec3::new(c[0], c[1], c[2]) / if c[3] != 0.0 { c[3] } else { 1.0 })
            .collect()
    } else {
        err("a subdivision mesh needs \"P\"; the primitive is skipped".into());
        return Vec::new();
    };
    let nv = obj.len();
    let total: usize = a.nverts.iter().map(|&n| n as usize).sum();
    if total > a.verts.len() {
        err(format!(
            "the faces need {total} vertex indices; {} are given",
            a.verts.len()
        ));
        return Vec::new();
    }
    if a.verts[..total].iter().any(|&v| v as usize >= nv) {
        err(format!(
            "a face uses a vertex index beyond the {nv} vertices of \"P\""
        ));
        return Vec::new();
    }
    if a.nverts.iter().any(|&n| n < 3) {
        err("a subdivision face has fewer than 3 vertices".into());
        return Vec::new();
    }
    let nf = a.nverts.len();
    if nf == 0 {
        return Vec::new();
    }
    let counts = ClassCounts {
        uniform: nf,
        varying: nv,
        facevarying: total,
    };
    let vars = resolve(&prim.primvars, m, counts, diags);
    // Pack the variables by how they subdivide.
    let mut lv = Level {
        vw: 3,
        lw: 0,
        fw: 0,
        linear,
        ..Level::default()
    };
    let mut layout: Vec<(usize, usize, Class)> = Vec::new(); // (var, offset, class)
    for (k, v) in vars.iter().enumerate() {
        if v.ty == ParamType::String {
            continue;
        }
        if v.name == "N" {
            warn("\"N\" on a subdivision mesh is ignored: limit normals are computed".into());
            continue;
        }
        let w = v.width();
        match v.class {
            Class::Vertex => {
                layout.push((k, lv.vw, Class::Vertex));
                lv.vw += w;
            }
            Class::Varying => {
                layout.push((k, lv.lw, Class::Varying));
                lv.lw += w;
            }
            Class::FaceVarying | Class::FaceVertex => {
                layout.push((k, lv.fw, Class::FaceVarying));
                lv.fw += w;
            }
            _ => {}
        }
    }
    lv.vtx = vec![0.0; nv * lv.vw];
    lv.lin = vec![0.0; nv * lv.lw];
    lv.fvar = vec![0.0; total * lv.fw];
    for (i, p) in obj.iter().enumerate() {
        lv.vtx[i * lv.vw..][..3].copy_from_slice(&m.transform_point3(*p).to_array());
    }
    for &(k, off, class) in &layout {
        let v = &vars[k];
        let w = v.width();
        let (dst, stride, n) = match class {
            Class::Vertex => (&mut lv.vtx, lv.vw, nv),
            Class::Varying => (&mut lv.lin, lv.lw, nv),
            _ => (&mut lv.fvar, lv.fw, total),
        };
        for e in 0..n {
            dst[e * stride + off..][..w].copy_from_slice(&v.floats[e * w..][..w]);
        }
    }
    lv.start = std::iter::once(0)
        .chain(a.nverts.iter().scan(0usize, |s, &n| {
            *s += n as usize;
            Some(*s)
        }))
        .collect();
    lv.verts = a.verts[..total].to_vec();
    lv.parent = (0..nf as u32).collect();
    lv.hole = vec![false; nf];
    lv.corner = vec![0.0; nv];
    // Tags.
    let (mut io, mut fo) = (0usize, 0usize);
    for (ti, tag) in a.tags.iter().enumerate() {
        let ni = a.nargs.get(2 * ti).copied().unwrap_or(0) as usize;
        let nfl = a.nargs.get(2 * ti + 1).copied().unwrap_or(0) as usize;
        let (Some(ints), Some(fl)) = (a.intargs.get(io..io + ni), a.floatargs.get(fo..fo + nfl))
        else {
            err(format!("tag \"{tag}\" needs more arguments than given"));
            break;
        };
        io += ni;
        fo += nfl;
        let sharp = |s: f32| if s >= INF_SHARP { f32::INFINITY } else { s };
        match tag.as_str() {
            "interpolateboundary" => lv.interp_boundary = ints.first().map_or(true, |&i| i != 0),
            "hole" => {
                for &f in ints {
                    if let Some(h) = usize::try_from(f).ok().and_then(|f| lv.hole.get_mut(f)) {
                        *h = true;
                    }
                }
            }
            "crease" => {
                let s = sharp(fl.first().copied().unwrap_or(INF_SHARP));
                for w in ints.windows(2) {
                    if w.iter().all(|&v| v >= 0 && (v as usize) < nv) && s > 0.0 {
                        lv.sharp.insert(key(w[0] as u32, w[1] as u32), s);
                    }
                }
            }
            "corner" => {
                for (j, &v) in ints.iter().enumerate() {
                    let s = fl.get(j).or(fl.first()).copied().unwrap_or(INF_SHARP);
                    if v >= 0 && (v as usize) < nv {
                        lv.corner[v as usize] = sharp(s);
                    }
                }
            }
            other => warn(format!(
                "subdivision tag \"{other}\" is not implemented; it is ignored"
            )),
        }
    }
    // Levels: as many as the face budget allows.
    let mut faces = total;
    let mut levels = 1;
    while levels < MAX_LEVELS && faces * 4 <= FACE_BUDGET {
        faces *= 4;
        levels += 1;
    }
    for _ in 0..levels {
        lv = lv.refine();
    }
    let (limit, normals) = lv.limit();
    // Hand the limit quads to the polygon path.
    let nq = lv.nfaces();
    let nvl = limit.len() / lv.vw;
    let p: Vec<Vec3> = (0..nvl)
        .map(|v| Vec3::from_slice(&limit[v * lv.vw..][..3]))
        .collect();
    let inv = m.inverse();
    let obj_xy = p
        .iter()
        .map(|&q| {
            let o = inv.transform_point3(q);
            Vec2::new(o.x, o.y)
        })
        .collect();
    let mut out_vars = Vec::new();
    let nflat: Vec<f32> = normals
        .iter()
        .flat_map(|n| if flip { -*n } else { *n }.to_array())
        .collect();
    out_vars.push(SourceVar {
        name: "N".into(),
        ty: ParamType::Normal,
        array_len: 1,
        class: Class::FaceVarying,
        floats: nflat,
        strings: Vec::new(),
    });
    for (k, v) in vars.iter().enumerate() {
        if v.name == "N" {
            continue;
        }
        let mut nv = v.clone();
        let w = v.width();
        match layout.iter().find(|l| l.0 == k) {
            Some(&(_, off, class)) => {
                let (src, stride) = match class {
                    Class::Vertex => (&limit, lv.vw),
                    Class::Varying => (&lv.lin, lv.lw),
                    _ => (&lv.fvar, lv.fw),
                };
                let n = src.len() / stride.max(1);
                nv.floats = (0..n)
                    .flat_map(|e| src[e * stride + off..][..w].iter().copied())
                    .collect();
            }
            None if v.class == Class::Uniform && v.ty != ParamType::String => {
                nv.floats = lv
                    .parent
                    .iter()
                    .flat_map(|&f| v.floats[f as usize * w..][..w].iter().copied())
                    .collect();
            }
            None if v.class == Class::Uniform => {
                nv.strings = lv
                    .parent
                    .iter()
                    .flat_map(|&f| v.strings[f as usize * w..][..w].iter().cloned())
                    .collect();
            }
            None => {}
        }
        out_vars.push(nv);
    }
    let data = MeshData {
        index,
        p,
        obj_xy,
        nverts: vec![4; nq],
        verts: lv.verts.clone(),
        loop_start: (0..=nq).collect(),
        fv_start: (0..=nq).map(|f| 4 * f).collect(),
        valid: lv.hole.iter().map(|h| !h).collect(),
        vars: out_vars,
        flip,
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
        split_triangles: prim.attributes.displacement.is_some(),
        decomp_p: None,
    };
    vec![Box::new(Mesh {
        data: Arc::new(data),
        faces: 0..nq,
    })]
}
