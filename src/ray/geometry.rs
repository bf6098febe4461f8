//! Ray-traceable geometry: every ray-visible primitive diced once into micropolygon grids at a
//! ray-appropriate rate, displaced, and put in a [`Bvh`].
//!
//! Input: the scene, the frame's camera (grids are in camera space, as shading is) and a
//! displacement hook. Output: a [`RayScene`]: the grids (every standard global and primitive
//! variable the hit shading needs, per vertex) and the BVH over their micropolygons.
//! Invariants: built sequentially in primitive order, with dicing decisions that depend only on
//! the surface and the camera, so the same scene gives the same ray geometry (and the same hits)
//! whatever the thread count or bucket size. Nothing is culled: reflections see behind the
//! camera.
//!
//! Which primitives rays see (RISpec leaves it to the renderer): BMRT made every primitive
//! visible to reflection and shadow rays; PRMan 11+ made none visible unless
//! `Attribute "visibility" "trace" 1`. arbor follows BMRT — the scenes that call `trace` are
//! mostly BMRT scenes — unless some primitive of the scene sets `"visibility" "trace"`
//! explicitly to 1: the scene is then written for PRMan, and primitives without the attribute
//! are invisible to rays, as PRMan made them. `"visibility" "trace" 0` (and BMRT's
//! `"render" "visibility"` without its reflection bit 2) always hides a primitive from
//! reflection rays; `"visibility" "transmission"` (`"opaque"`/`"Os"`/1 cast shadows,
//! `"transparent"`/0 do not) and BMRT's `"render" "casts_shadows"` (`"none"` does not) decide
//! whether it blocks shadow rays, by default yes (with its opacity `Os`).

use glam::{Mat4, Vec3};

use crate::diag::Diagnostics;
use crate::geom::{Bound, Surface};
use crate::render::Camera;
use crate::scene::{Primitive, Scene};
use crate::shade::Grid;

use super::bvh::{Bvh, Quad};

/// Most micropolygons per side of a ray grid (larger surfaces split).
const MAX_SIDE: usize = 24;
/// Most splits along one path (then the surface dices at the clamped rate).
const MAX_DEPTH: u32 = 20;

/// What hit shading interpolates at a vertex of a ray grid, side by side in one 64-byte
/// cache line: a hit reads the records of its micropolygon's four corners (two pairs of
/// neighbours: four lines, where the 88-byte records with colour and opacity took six to
/// eight) instead of ten arrays four times over (the cache misses of hit shading, on large
/// scenes). Colour and opacity are kept per grid when they are the same at every vertex
/// (see [`Tint`]).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
pub struct HitVertex {
    pub n: Vec3,
    pub ng: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    /// u, v, s, t.
    pub uvst: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<HitVertex>() == 64);

impl HitVertex {
    /// The record's sixteen numbers in field order: N, Ng, dPdu, dPdv, then u v s t (what
    /// hit shading interpolates, all at once, lane by lane).
    #[inline(always)]
    pub fn floats(&self) -> [f32; 16] {
        let [n, ng, du, dv] = [self.n, self.ng, self.dpdu, self.dpdv];
        let [u, v, s, t] = self.uvst;
        [
            n.x, n.y, n.z, ng.x, ng.y, ng.z, du.x, du.y, du.z, dv.x, dv.y, dv.z, u, v, s, t,
        ]
    }
}

/// A ray grid's `Cs` or `Os`: one value when every vertex holds the same bits (the common
/// case: a primitive's colour and opacity attributes), else per vertex in a scene-wide array
/// ([`RayScene::cs`], [`RayScene::os`]) from the grid's first vertex on. A hit interpolates
/// a uniform value with the same weights and the same sum as per-vertex values (so the same
/// bits) without reading any vertex: a shadow ray meeting an opaque blocker reads no record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tint {
    Uniform(Vec3),
    /// Index of the grid's first vertex in the scene's array.
    Varying(usize),
}

impl Tint {
    /// Keeps `values` (one per vertex) as a [`Tint`], appending them to `all` unless uniform.
    fn of(values: &[Vec3], all: &mut Vec<Vec3>) -> Tint {
        let bits = |v: &Vec3| v.to_array().map(f32::to_bits);
        match values.first() {
            Some(v0) if values.iter().all(|v| bits(v) == bits(v0)) => Tint::Uniform(*v0),
            _ => {
                let first = all.len();
                all.extend_from_slice(values);
                Tint::Varying(first)
            }
        }
    }

    /// The value at a hit: vertices `k` of the grid (indices inside it) weighted by `w`, as
    /// `v[k0]·w0 + v[k1]·w1 + v[k2]·w2 + v[k3]·w3` (uniform or not, the same expression).
    #[inline]
    pub fn at(&self, all: &[Vec3], k: &[usize; 4], w: &[f32; 4]) -> Vec3 {
        let c = match *self {
            Tint::Uniform(c) => [c; 4],
            Tint::Varying(first) => {
                let v = |i: usize| all.get(first + k[i]).copied().unwrap_or(Vec3::ZERO);
                [v(0), v(1), v(2), v(3)]
            }
        };
        c[0] * w[0] + c[1] * w[1] + c[2] * w[2] + c[3] * w[3]
    }
}

/// One diced, displaced grid of ray geometry. Its per-vertex shading data (`n`, `ng`, `dpdu`,
/// `dpdv`, `u`, `v`, `s`, `t`) lives in [`RayScene::verts`] from `first` on, its `cs` and
/// `os` in [`RayGrid::cs`] and [`RayGrid::os`] (the grid's own arrays for them are emptied);
/// `p` and the primitive variables stay.
#[derive(Debug)]
pub struct RayGrid {
    pub prim: usize,
    pub grid: Grid,
    /// Index of the grid's first vertex in [`RayScene::verts`].
    pub first: usize,
    /// Surface colour at the vertices.
    pub cs: Tint,
    /// Opacity at the vertices (what a shadow ray reads of a hit).
    pub os: Tint,
    /// Seen by reflection/refraction rays (`trace`, `gather`, `indirectdiffuse`).
    pub trace: bool,
    /// Blocks shadow rays (`transmission`, `shadow("raytrace")`, `occlusion`).
    pub shadows: bool,
    /// The area light this grid is the surface of (`Attributes::area_light`).
    pub area_light: Option<usize>,
    /// Its primitive has an `Interior` or `Exterior` shader (kept here so a hit's medium is
    /// known without reading the primitive's attributes: a cache miss per hit).
    pub media: bool,
}

/// The ray-traceable scene.
#[derive(Debug, Default)]
pub struct RayScene {
    pub grids: Vec<RayGrid>,
    /// Every grid's vertices' shading data (see [`RayGrid::first`]).
    pub verts: Vec<HitVertex>,
    /// The per-vertex colours of grids whose colour varies (see [`Tint`]).
    pub cs: Vec<Vec3>,
    /// The per-vertex opacities of grids whose opacity varies (see [`Tint`]).
    pub os: Vec<Vec3>,
    pub bvh: Bvh,
    /// Total micropolygons.
    pub micropolygons: usize,
    /// Triangles added to close cracks between neighbouring grids (see [`fill_cracks`]).
    pub crack_fills: usize,
    /// Per primitive: the primitive whose shading context its hits are shaded in (itself, or
    /// the first of the primitives that shade identically, so their hits share one grid; see
    /// `shade::rays`). Empty: every primitive shades as itself.
    pub shade_as: Vec<usize>,
    /// The bound of everything, camera space.
    pub bound: Option<Bound>,
}

/// Ray visibility of one primitive: (trace, shadows).
fn visibility(prim: &Primitive, prman_style: bool) -> (bool, bool) {
    let u = &prim.attributes.user;
    let num = |k: &str| u.get(k).and_then(|p| p.data.floats().first().copied());
    let text = |k: &str| {
        u.get(k)
            .and_then(|p| p.data.strings().first().map(|s| s.to_ascii_lowercase()))
    };
    let mut trace = !prman_style;
    let mut shadows = !prman_style;
    if let Some(v) = num("render:visibility") {
        let bits = v as i32;
        trace = bits & 2 != 0;
        shadows = bits & 4 != 0;
    }
    if let Some(v) = num("visibility:trace") {
        trace = v != 0.0;
        // PRMan 11–12: trace-visible primitives also occlude rays unless told otherwise.
        shadows = shadows || trace;
    }
    match text("visibility:transmission") {
        Some(s) => shadows = s != "transparent",
        None => {
            if let Some(v) = num("visibility:transmission") {
                shadows = v != 0.0;
            }
        }
    }
    if let Some(s) = text("render:casts_shadows") {
        shadows = s != "none";
    }
    (trace, shadows)
}

/// Builds the ray geometry (see the module invariants). `displace` runs the primitive's
/// displacement shader over a grid.
pub fn build(
    scene: &Scene,
    camera: &Camera,
    displace: &(dyn Fn(usize, &mut Grid) + Sync),
    diags: &Diagnostics,
) -> RayScene {
    let prman_style = scene.primitives.iter().any(|p| {
        p.attributes
            .user
            .get("visibility:trace")
            .and_then(|v| v.data.floats().first().copied())
            .is_some_and(|v| v != 0.0)
    });
    // The scene's size sets a floor on the distance used for the dicing rate.
    let mut all: Vec<(usize, Vec<Box<dyn Surface>>, (bool, bool))> = Vec::new();
    let mut scene_bound = Bound::EMPTY;
    for (i, prim) in scene.primitives.iter().enumerate() {
        let vis = visibility(prim, prman_style);
        if !vis.0 && !vis.1 {
            continue;
        }
        let surfs = crate::geom::surfaces_for(i, prim, camera.camera_from_world, diags);
        for s in &surfs {
            let b = s.bound();
            if !b.is_empty() && b.min.is_finite() && b.max.is_finite() {
                scene_bound = scene_bound.union(b);
            }
        }
        all.push((i, surfs, vis));
    }
    let diag = if scene_bound.is_empty() {
        1.0
    } else {
        (scene_bound.max - scene_bound.min).length().max(1e-6)
    };
    let min_dist = (0.05 * diag).max(camera.near.max(1e-6));
    let rate_of = RateModel::new(camera, diag);
    // Each primitive diced on its own (in parallel where threads are free), then joined in
    // primitive order: the same ray geometry whatever the thread count.
    let threads = rayon::current_num_threads().min(all.len()).max(1);
    let parts = dice_all(all, threads, &|prim, surfs, vis| {
        dice_primitive(
            scene, camera, &rate_of, min_dist, prim, surfs, vis, displace,
        )
    });
    let mut out = RayScene::default();
    let mut quads = Vec::with_capacity(parts.iter().map(|p| p.quads.len()).sum());
    let mut verts: Vec<Vec3> = Vec::with_capacity(parts.iter().map(|p| p.verts.len()).sum());
    for part in parts {
        let (kbase, gbase) = (verts.len() as u32, out.grids.len() as u32);
        quads.extend(part.quads.iter().map(|q| Quad {
            k: q.k + kbase,
            grid: q.grid + gbase,
            ..*q
        }));
        verts.extend_from_slice(&part.verts);
        out.grids.extend(part.grids);
        out.micropolygons += part.micropolygons;
        out.crack_fills += part.crack_fills;
    }
    // The shading data side by side (see HitVertex); the grids' own arrays are freed.
    let total: usize = out.grids.iter().map(|g| g.grid.p.len()).sum();
    out.verts.reserve_exact(total);
    // Read at random by hit shading (four corners a hit): huge pages spare a TLB miss a read.
    super::memhint::huge_pages(&mut out.verts);
    for rg in &mut out.grids {
        rg.first = out.verts.len();
        let g = &mut rg.grid;
        out.verts.extend((0..g.p.len()).map(|k| HitVertex {
            n: g.n[k],
            ng: g.ng[k],
            dpdu: g.dpdu[k],
            dpdv: g.dpdv[k],
            uvst: [g.u[k], g.v[k], g.s[k], g.t[k]],
        }));
        let n = g.p.len();
        rg.cs = Tint::of(&g.cs[..n], &mut out.cs);
        rg.os = Tint::of(&g.os[..n], &mut out.os);
        for v in [
            &mut g.n,
            &mut g.ng,
            &mut g.dpdu,
            &mut g.dpdv,
            &mut g.cs,
            &mut g.os,
            &mut g.i,
            &mut g.ci,
            &mut g.oi,
        ] {
            *v = Vec::new();
        }
        for v in [&mut g.u, &mut g.v, &mut g.s, &mut g.t] {
            *v = Vec::new();
        }
    }
    out.bound = (!scene_bound.is_empty()).then_some(scene_bound);
    out.bvh = Bvh::build(quads, verts);
    out
}

/// One primitive's ray grids, their quads and vertices (numbered from 0: the join offsets
/// them), and its counts.
#[derive(Default)]
struct Part {
    grids: Vec<RayGrid>,
    quads: Vec<Quad>,
    verts: Vec<Vec3>,
    micropolygons: usize,
    crack_fills: usize,
}

/// A primitive to dice: its index, its surfaces and its ray visibility.
type Prim = (usize, Vec<Box<dyn Surface>>, (bool, bool));

/// `dice` over every primitive on up to `threads` threads (each takes the next primitive
/// not yet taken); the parts in primitive order.
fn dice_all(
    all: Vec<Prim>,
    threads: usize,
    dice: &(dyn Fn(usize, Vec<Box<dyn Surface>>, (bool, bool)) -> Part + Sync),
) -> Vec<Part> {
    if threads < 2 {
        return all.into_iter().map(|(p, s, v)| dice(p, s, v)).collect();
    }
    // Each thread takes the next primitive not yet taken and keeps its parts numbered.
    let queue = std::sync::Mutex::new(all.into_iter().enumerate());
    let run = || {
        let mut mine = Vec::new();
        loop {
            let next = queue.lock().unwrap_or_else(|e| e.into_inner()).next();
            let Some((i, (p, s, v))) = next else {
                return mine;
            };
            mine.push((i, dice(p, s, v)));
        }
    };
    // Plain threads, not rayon: render threads wait on this build, and a rayon task taken up
    // while joining could be one of theirs, asking for the geometry being built.
    let mut parts = std::thread::scope(|sc| {
        let helpers: Vec<_> = (1..threads).map(|_| sc.spawn(run)).collect();
        let mut parts = run();
        for h in helpers {
            parts.extend(h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
        }
        parts
    });
    parts.sort_unstable_by_key(|&(i, _)| i);
    parts.into_iter().map(|(_, part)| part).collect()
}

/// Dices one primitive's surfaces for rays (depth first in a fixed order) and closes the
/// cracks between its grids.
#[allow(clippy::too_many_arguments)]
fn dice_primitive(
    scene: &Scene,
    camera: &Camera,
    rate_of: &RateModel,
    min_dist: f32,
    prim: usize,
    surfs: Vec<Box<dyn Surface>>,
    (trace, shadows): (bool, bool),
    displace: &(dyn Fn(usize, &mut Grid) + Sync),
) -> Part {
    let mut out = Part::default();
    let a = &scene.primitives[prim].attributes;
    let rate = if a.shading_rate.is_finite() && a.shading_rate > 0.0 {
        a.shading_rate.clamp(0.05, 1e4)
    } else {
        1.0
    };
    // Ray grids are coarser than camera grids: hits are shaded where they land (with the
    // interpolated normal), so the tessellation only has to hold the silhouette.
    let ray_rate = user_rate(a).unwrap_or(rate * 4.0);
    // Displacement puts detail between the diced points: such surfaces dice at the full
    // rate; others only as finely as their curvature needs.
    let displaced = a.displacement.is_some();
    let mut stack: Vec<(Box<dyn Surface>, u32)> = surfs.into_iter().map(|s| (s, 0)).collect();
    // Depth-first in a fixed order: children are visited in the order split() gives them.
    stack.reverse();
    while let Some((s, depth)) = stack.pop() {
        let b = s.bound();
        if b.is_empty() || !b.min.is_finite() || !b.max.is_finite() {
            continue;
        }
        let dice = if s.diceable() {
            rate_of.dice(&*s, &b, ray_rate, min_dist, displaced)
        } else {
            None
        };
        let (nu, nv) = match dice {
            Some((nu, nv)) if nu <= MAX_SIDE && nv <= MAX_SIDE => (nu, nv),
            Some((nu, nv)) if depth >= MAX_DEPTH => (nu.min(64), nv.min(64)),
            _ if depth >= MAX_DEPTH && s.diceable() => (8, 8),
            _ if depth >= MAX_DEPTH => continue,
            _ => {
                let mut kids = s.split();
                kids.reverse();
                stack.extend(kids.into_iter().map(|k| (k, depth + 1)));
                continue;
            }
        };
        let mut grid = s.dice(nu + 1, nv + 1);
        if grid.nu < 2 || grid.nv < 2 || grid.p.len() != grid.nu * grid.nv {
            continue;
        }
        for (i, p) in grid.i.iter_mut().zip(&grid.p) {
            *i = if camera.perspective {
                *p
            } else {
                Vec3::new(0.0, 0.0, p.z)
            };
        }
        displace(prim, &mut grid);
        if grid.p.iter().any(|p| !p.is_finite()) {
            continue;
        }
        let gi = out.grids.len() as u32;
        let (gu, gv) = (grid.nu, grid.nv);
        let base = out.verts.len();
        out.verts.extend_from_slice(&grid.p);
        for j in 0..gv - 1 {
            for i in 0..gu - 1 {
                out.quads.push(Quad {
                    k: (base + j * gu + i) as u32,
                    row: gu as u32,
                    grid: gi,
                    index: (j * (gu - 1) + i) as u32,
                });
            }
        }
        out.micropolygons += (gu - 1) * (gv - 1);
        out.grids.push(RayGrid {
            prim,
            grid,
            first: 0,
            cs: Tint::Uniform(Vec3::ONE),
            os: Tint::Uniform(Vec3::ONE),
            trace,
            shadows,
            area_light: a.area_light,
            media: a.interior.is_some() || a.exterior.is_some(),
        });
    }
    out.crack_fills = fill_cracks(&out.grids, 0, &mut out.quads, &mut out.verts);
    out
}

/// `Attribute "trace" "shadingrate"` (arbor: micropolygon area, in pixels as seen from the
/// camera, of the ray tessellation; default four times ShadingRate).
fn user_rate(a: &crate::scene::Attributes) -> Option<f32> {
    a.user
        .get("trace:shadingrate")
        .and_then(|p| p.data.floats().first().copied())
        .filter(|r| r.is_finite() && *r > 0.0)
        .map(|r| r.clamp(0.05, 1e4))
}

/// Turns camera-space lengths into "pixels" as the camera would see them at a distance.
struct RateModel {
    /// Raster pixels per camera-space unit at distance 1 (perspective) or anywhere (ortho).
    ppu: f32,
    perspective: bool,
    /// Orthographic views: the most pixels per unit rays need, those of a view that fits the
    /// whole scene across twice the image (at least 1024 pixels; see [`RateModel::dice`]).
    ortho_ppu: f32,
}

impl RateModel {
    /// The model for `camera` over a scene `diag` across (camera space).
    fn new(camera: &Camera, diag: f32) -> RateModel {
        let m: Mat4 = camera.raster_from_camera();
        let a = m.project_point3(Vec3::new(0.0, 0.0, 1.0));
        let b = m.project_point3(Vec3::new(1.0, 0.0, 1.0));
        let ppu = (b.x - a.x).abs();
        RateModel {
            ppu: if ppu.is_finite() && ppu > 0.0 {
                ppu
            } else {
                100.0
            },
            perspective: camera.perspective,
            ortho_ppu: 2.0 * camera.xres.max(camera.yres).max(512) as f32 / diag,
        }
    }

    /// Micropolygons along u and v for a surface, from a 5 × 5 trial dice: edges of about
    /// √rate pixels as the camera would see them at the surface's distance, but no finer than
    /// the surface's bending needs (a chord's sagitta shrinks with the square of the number of
    /// segments, so a flat polygon is one micropolygon however large it is). Hits are shaded
    /// at the hit with interpolated normals, so only the silhouette needs the vertices.
    fn dice(
        &self,
        s: &dyn Surface,
        b: &Bound,
        rate: f32,
        min_dist: f32,
        displaced: bool,
    ) -> Option<(usize, usize)> {
        let n = 5;
        let g = s.dice(n, n);
        if g.p.len() < n * n || g.p.iter().any(|p| !p.is_finite()) {
            return None;
        }
        let (mut ulen, mut vlen) = (0f32, 0f32);
        for j in 0..n {
            let (mut lu, mut lv) = (0f32, 0f32);
            for i in 0..n - 1 {
                lu += (g.p[j * n + i] - g.p[j * n + i + 1]).length();
                lv += (g.p[i * n + j] - g.p[(i + 1) * n + j]).length();
            }
            ulen = ulen.max(lu);
            vlen = vlen.max(lv);
        }
        let edge = if self.perspective {
            // Distance from the eye (the origin) to the bound.
            let c = Vec3::ZERO.clamp(b.min, b.max);
            rate.sqrt() * c.length().max(min_dist) / self.ppu
        } else {
            // No finer than a view that fits the whole scene across twice the image: an
            // orthographic view of a small window onto a large scene (RISpec's default
            // projection under a scene written for a perspective one) would otherwise dice
            // everything, seen only by rays, at the window's pixel size (gigabytes of
            // micropolygons).
            rate.sqrt() / self.ppu.min(self.ortho_ppu)
        };
        let mut nu = (ulen / edge).ceil().clamp(1.0, 1e6);
        let mut nv = (vlen / edge).ceil().clamp(1.0, 1e6);
        if !displaced {
            // Second differences along the trial lines: a point's distance from the middle of
            // its neighbours is the sagitta of a chord spanning half the patch.
            let mut dev_u = 0f32;
            let mut dev_v = 0f32;
            for j in 0..n {
                for i in 1..n - 1 {
                    let k = j * n + i;
                    dev_u = dev_u.max((g.p[k] - 0.5 * (g.p[k - 1] + g.p[k + 1])).length());
                    let k = i * n + j;
                    dev_v = dev_v.max((g.p[k] - 0.5 * (g.p[k - n] + g.p[k + n])).length());
                }
            }
            // A twentieth of the edge length: a tenth of a pixel where the camera sees it.
            let tol = 0.05 * edge;
            let need = |dev: f32| (2.0 * (dev / tol).sqrt()).ceil().max(1.0);
            nu = nu.min(need(dev_u));
            nv = nv.min(need(dev_v));
        }
        Some((nu as usize, nv as usize))
    }
}

/// Closes the cracks between neighbouring grids of one primitive, which are diced at different
/// rates: where a boundary vertex of one grid lies on (near) a boundary edge of another, the
/// two grids' boundary polylines part, and a ray can slip between them (a speck of light
/// inside a ray-traced shadow). For every boundary edge `a b` of every grid, the other grids'
/// boundary vertices `m1 … mk` near it (within a tenth of its length, projecting inside it,
/// with normals on the same side) are joined to it by the fan `(a m1 m2) … (a mk b)`, which
/// covers the sliver between the edge and the neighbour's polyline. Done from both sides,
/// this closes T-junctions and edges whose vertices interleave. Each fill is a quad whose
/// second triangle is degenerate, belonging to the micropolygon along the edge (its hits
/// shade with that micropolygon's values), its corners appended to `corners` (the BVH's
/// vertex array). Deterministic: candidates are sorted.
/// `grids[k]` is ray grid `first + k`; returns the number of fills added.
pub fn fill_cracks(
    grids: &[RayGrid],
    first: usize,
    quads: &mut Vec<Quad>,
    corners: &mut Vec<Vec3>,
) -> usize {
    use std::collections::HashMap;
    if grids.len() < 2 {
        return 0;
    }
    // Boundary sides of each grid: (grid, vertex indices along the side, quad index of each
    // edge's micropolygon).
    struct Side {
        grid: usize,
        verts: Vec<usize>,
        quads: Vec<u32>,
    }
    let mut sides: Vec<Side> = Vec::new();
    for (g, rg) in grids.iter().enumerate() {
        let (nu, nv) = (rg.grid.nu, rg.grid.nv);
        let qu = nu - 1;
        let row = |j: usize| (0..nu).map(|i| j * nu + i).collect::<Vec<_>>();
        let col = |i: usize| (0..nv).map(|j| j * nu + i).collect::<Vec<_>>();
        sides.push(Side {
            grid: g,
            verts: row(0),
            quads: (0..qu as u32).collect(),
        });
        sides.push(Side {
            grid: g,
            verts: row(nv - 1),
            quads: (0..qu).map(|i| ((nv - 2) * qu + i) as u32).collect(),
        });
        sides.push(Side {
            grid: g,
            verts: col(0),
            quads: (0..nv - 1).map(|j| (j * qu) as u32).collect(),
        });
        sides.push(Side {
            grid: g,
            verts: col(nu - 1),
            quads: (0..nv - 1).map(|j| (j * qu + qu - 1) as u32).collect(),
        });
    }
    // Every boundary vertex once: (grid, index) → position, normal.
    let mut verts: Vec<(usize, usize)> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut total_len = 0f64;
    let mut segs = 0usize;
    for s in &sides {
        for &v in &s.verts {
            if seen.insert((s.grid, v)) {
                verts.push((s.grid, v));
            }
        }
        for w in s.verts.windows(2) {
            let p = &grids[s.grid].grid.p;
            total_len += f64::from((p[w[1]] - p[w[0]]).length());
            segs += 1;
        }
    }
    let cell = (2.0 * total_len / segs.max(1) as f64) as f32;
    if !(cell > 0.0) || !cell.is_finite() {
        return 0;
    }
    let key = |p: Vec3| {
        let q = (p / cell).floor();
        (q.x as i32, q.y as i32, q.z as i32)
    };
    let mut hash: HashMap<(i32, i32, i32), Vec<u32>> = HashMap::new();
    for (k, &(g, v)) in verts.iter().enumerate() {
        hash.entry(key(grids[g].grid.p[v]))
            .or_default()
            .push(k as u32);
    }
    let mut added = 0;
    let mut near: Vec<(f32, u32)> = Vec::new();
    for s in &sides {
        let grid = &grids[s.grid].grid;
        for (e, w) in s.verts.windows(2).enumerate() {
            let (a, b) = (grid.p[w[0]], grid.p[w[1]]);
            let ab = b - a;
            let len2 = ab.length_squared();
            if !(len2 > 0.0) {
                continue;
            }
            let len = len2.sqrt();
            let eps = 0.1 * len;
            let nrm = grid.n[w[0]] + grid.n[w[1]];
            let (lo, hi) = (key(a.min(b) - eps), key(a.max(b) + eps));
            let cells =
                (hi.0 - lo.0 + 1) as i64 * (hi.1 - lo.1 + 1) as i64 * (hi.2 - lo.2 + 1) as i64;
            if cells > 4096 {
                continue;
            }
            near.clear();
            for x in lo.0..=hi.0 {
                for y in lo.1..=hi.1 {
                    for z in lo.2..=hi.2 {
                        let Some(list) = hash.get(&(x, y, z)) else {
                            continue;
                        };
                        for &k in list {
                            let (g, v) = verts[k as usize];
                            if g == s.grid {
                                continue;
                            }
                            let m = grids[g].grid.p[v];
                            let t = (m - a).dot(ab) / len2;
                            if !(0.0..=1.0).contains(&t) {
                                continue;
                            }
                            let off = m - (a + ab * t);
                            if off.length() > eps
                                || (m - a).length() < 1e-4 * len
                                || (m - b).length() < 1e-4 * len
                                || grids[g].grid.n[v].dot(nrm) < 0.0
                            {
                                continue;
                            }
                            near.push((t, k));
                        }
                    }
                }
            }
            if near.is_empty() {
                continue;
            }
            near.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            near.dedup_by(|x, y| {
                let (gx, vx) = verts[x.1 as usize];
                let (gy, vy) = verts[y.1 as usize];
                grids[gx].grid.p[vx] == grids[gy].grid.p[vy]
            });
            let fan: Vec<Vec3> = near
                .iter()
                .map(|&(_, k)| {
                    let (g, v) = verts[k as usize];
                    grids[g].grid.p[v]
                })
                .chain(std::iter::once(b))
                .collect();
            for pair in fan.windows(2) {
                quads.push(Quad {
                    k: corners.len() as u32,
                    row: 2,
                    grid: (first + s.grid) as u32,
                    index: s.quads[e],
                });
                corners.extend([a, pair[0], pair[1], pair[1]]);
                added += 1;
            }
        }
    }
    added
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of one colour is kept once, a varying one per vertex (from the grid's first
    /// vertex on); either way a hit's value is the per-vertex mix bit for bit.
    #[test]
    fn tints_keep_uniform_values_once_and_mix_as_per_vertex() {
        let mut all = vec![Vec3::splat(9.0)]; // another grid's values before these
        let same = vec![Vec3::new(0.3, 0.7, 0.1); 6];
        let tint = Tint::of(&same, &mut all);
        assert_eq!(tint, Tint::Uniform(Vec3::new(0.3, 0.7, 0.1)));
        assert_eq!(all.len(), 1);
        // Zero and negative zero are different bits: the grid varies.
        let signed = [
            Vec3::ZERO,
            Vec3::new(-0.0, 0.0, 0.0),
            Vec3::ZERO,
            Vec3::ZERO,
        ];
        assert_eq!(Tint::of(&signed, &mut all), Tint::Varying(1));
        assert_eq!(all.len(), 5);
        let ramp: Vec<Vec3> = (0..6).map(|k| Vec3::splat(k as f32 * 0.1)).collect();
        let varying = Tint::of(&ramp, &mut all);
        assert_eq!(varying, Tint::Varying(5));
        let mut h = 5u32;
        for _ in 0..200 {
            h = crate::pattern::hash::hash_u32(h);
            let (a, b) = (crate::ray::unit(h), crate::ray::unit(h ^ 0x55aa));
            let w = [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b];
            let k = [1, 2, 4, 5];
            let mix =
                |v: &[Vec3]| v[k[0]] * w[0] + v[k[1]] * w[1] + v[k[2]] * w[2] + v[k[3]] * w[3];
            let bits = |v: Vec3| v.to_array().map(f32::to_bits);
            assert_eq!(bits(tint.at(&all, &k, &w)), bits(mix(&same)));
            assert_eq!(bits(varying.at(&all, &k, &w)), bits(mix(&ramp)));
        }
    }
}
