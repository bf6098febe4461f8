//! Ray queries for shaders: the shading system's answer to [`RayTracer`].
//!
//! Input: rays from a running shader (camera space), the frame's ray geometry (built on the
//! first ray, see [`crate::ray`]). Output: hit colours and transmissions.
//! Invariants: the hits of one call that land on one primitive are gathered, in ray order, into
//! one grid (`nu` = hits, `nv` = 1, derivatives across it read as zero) and shaded by that
//! primitive's own surface shader with its lights, one ray level deeper — the shade tree serves
//! rays as it serves micropolygons. Past `Option "trace" "maxdepth"` (default 10, as PRMan;
//! BMRT's `Option "render" "max_raylevel"` is read too) rays return black. Nothing depends on
//! the thread or the bucket: the answer for a ray is a function of the ray.

use glam::Vec3;

use crate::render::Camera;
use crate::scene::{ParamData, Scene};
use crate::shade::exec::RayTracer;
use crate::shade::system::{Medium, ShadeSystem};
use crate::shade::{Grid, GridVar};

use crate::ray::geometry::HitVertex;
use crate::ray::memhint::{prefetch, prefetch_span};
use crate::ray::{Cone, RayGrid, RayScene};

/// How many hits ahead the loops over a batch's hits prefetch what a hit will read (its ray
/// grid's fields, its corners' shading records): far enough for a miss to memory to land
/// before its hit comes up, a few dozen lines in flight at most.
const AHEAD: usize = 16;

/// Default most ray depth (PRMan's `Option "trace" "maxdepth"`).
pub const DEFAULT_MAX_DEPTH: u32 = 10;
/// Layers of partly transparent surfaces a ray passes through before it stops.
const MAX_LAYERS: usize = 16;

thread_local! {
    /// Diffuse bounces under way on this thread ([`mean_radiance`] calls): hits its rays find
    /// are shaded on the thread that traced them, so this is the diffuse depth of the grid
    /// being shaded.
    static DIFFUSE_DEPTH: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
    /// Set while this thread builds the ray geometry (a displacement shader that casts rays
    /// then sees nothing instead of waiting for itself).
    static BUILDING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

pub struct Tracer<'a, 's> {
    pub sys: &'a ShadeSystem<'a>,
    pub scene: &'s Scene,
    pub camera: &'s Camera,
    pub depth: u32,
    /// Rays pass through the surfaces of this area light (its own shadow rays).
    pub skip_light: Option<usize>,
}

/// `Option "trace" "maxdepth"` (or BMRT's `"render" "max_raylevel"`).
pub fn max_depth(scene: &Scene) -> u32 {
    let o = &scene.options;
    for key in ["trace:maxdepth", "render:max_raylevel"] {
        if let Some([x, ..]) = o.user_floats(key) {
            if x.is_finite() && *x >= 0.0 {
                return (*x as u32).min(64);
            }
        }
    }
    DEFAULT_MAX_DEPTH
}

/// The ray bias: `Attribute "trace" "bias"`, `Option "trace" "bias"` or BMRT's
/// `Option "render" "minshadowbias"`, else 0.01 (as PRMan).
pub fn bias(scene: &Scene) -> f32 {
    for key in ["trace:bias", "render:minshadowbias"] {
        if let Some([x, ..]) = scene.options.user_floats(key) {
            if x.is_finite() && *x >= 0.0 {
                return *x;
            }
        }
    }
    0.01
}

impl<'a> Tracer<'a, '_> {
    /// The frame's ray geometry (None while it is being built on this thread).
    pub fn geometry(&self) -> Option<std::sync::Arc<RayScene>> {
        if BUILDING.with(|b| b.get()) {
            return None;
        }
        let (sys, scene, camera) = (self.sys, self.scene, self.camera);
        Some(sys.rays.get_or_build(|| {
            BUILDING.with(|b| b.set(true));
            // Displacement may run on the build's own helper threads: a shader there that
            // traces must not wait for the geometry it is helping to build either.
            let displace = |prim: usize, grid: &mut Grid| {
                let was = BUILDING.with(|b| b.replace(true));
                sys.displace(scene, camera, prim, grid);
                BUILDING.with(|b| b.set(was));
            };
            let mut rs = crate::ray::geometry::build(scene, camera, &displace, sys.diags);
            rs.shade_as = shading_classes(sys, scene, &rs);
            BUILDING.with(|b| b.set(false));
            rs
        }))
    }

    fn bias_for(&self) -> f32 {
        bias(self.scene)
    }
}

/// For each primitive, the first primitive whose hits shade identically (see
/// [`RayScene::shade_as`]): equal attributes (the same shaders and instance values, colour,
/// lights…), the same primitive variables beside the standard ones (none varying by
/// primitive), and surface and atmosphere shaders that never name "object" space — the one
/// thing of a primitive's own (its transform) a shader could see. Hits on such primitives are
/// gathered into one grid: a batch of rays over a field of separately placed copies of an
/// object runs its shaders once instead of once per copy. Deterministic: classes are found
/// in primitive order.
fn shading_classes(sys: &ShadeSystem, scene: &Scene, rs: &RayScene) -> Vec<usize> {
    use crate::sl::ir::Const;
    use std::collections::HashMap;
    let n = scene.primitives.len();
    let mut shade_as: Vec<usize> = (0..n).collect();
    // The primitive-variable layout and uniform values of each primitive's first grid.
    let mut layout: Vec<Option<&[GridVar]>> = vec![None; n];
    for rg in &rs.grids {
        if layout[rg.prim].is_none() {
            layout[rg.prim] = Some(&rg.grid.primvars);
        }
    }
    let names_object = |sref: &crate::scene::ShaderRef, kind: crate::sl::ast::ShaderKind| {
        let object = |s: &str| s.eq_ignore_ascii_case("object");
        if sref
            .params
            .0
            .iter()
            .any(|p| p.data.strings().iter().any(|s| object(s)))
        {
            return true;
        }
        match sys.library.get(&sref.name, sys.sources, sys.diags) {
            Some(prog) if prog.kind == kind => prog
                .consts
                .iter()
                .any(|(_, c)| matches!(c, Const::S(s) if object(s))),
            _ => true,
        }
    };
    let same_vars = |a: &[GridVar], b: &[GridVar]| {
        a.len() == b.len()
            && a.iter().zip(b).all(|(x, y)| {
                x.name == y.name
                    && x.ty == y.ty
                    && x.array_len == y.array_len
                    && x.uniform == y.uniform
                    && (!x.uniform || (x.floats == y.floats && x.strings == y.strings))
            })
    };
    // Candidates by a cheap key: (surface name, colour, opacity).
    let mut classes: HashMap<(String, [u32; 6]), Vec<usize>> = HashMap::new();
    for prim in 0..n {
        let Some(vars) = layout[prim] else {
            continue;
        };
        let a = &scene.primitives[prim].attributes;
        let Some(surface) = &a.surface else {
            continue;
        };
        if names_object(surface, crate::sl::ast::ShaderKind::Surface)
            || a.atmosphere
                .as_ref()
                .is_some_and(|s| names_object(s, crate::sl::ast::ShaderKind::Volume))
        {
            continue;
        }
        let (c, o) = (a.color.to_array(), a.opacity.to_array());
        let key = (
            surface.name.clone(),
            [c[0], c[1], c[2], o[0], o[1], o[2]].map(f32::to_bits),
        );
        let reps = classes.entry(key).or_default();
        let found = reps.iter().copied().find(|&r| {
            let b = &scene.primitives[r].attributes;
            (std::sync::Arc::ptr_eq(a, b) || **a == **b)
                && layout[r].is_some_and(|w| same_vars(vars, w))
        });
        match found {
            Some(r) => shade_as[prim] = r,
            // Bounded search: a scene of many distinct materials of one name does not go
            // quadratic (a primitive past the bound just shades as itself).
            None if reps.len() < 64 => reps.push(prim),
            None => {}
        }
    }
    shade_as
}

/// Interpolates the per-vertex data of a ray grid at a hit.
fn lerp_weights(rg: &RayGrid, index: u32, a: f32, b: f32) -> ([usize; 4], [f32; 4]) {
    let g = &rg.grid;
    let qu = g.nu - 1;
    let (i, j) = (index as usize % qu, index as usize / qu);
    let k = j * g.nu + i;
    let a = a.clamp(0.0, 1.0);
    let b = b.clamp(0.0, 1.0);
    (
        [k, k + 1, k + g.nu, k + g.nu + 1],
        [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b],
    )
}

/// Interpolation weights at grid coordinates `(x, y)` (in micropolygons from the grid's
/// first vertex), extrapolating linearly from the boundary micropolygon beyond the grid.
fn grid_weights(g: &Grid, x: f32, y: f32) -> ([usize; 4], [f32; 4]) {
    let (qu, qv) = (g.nu - 1, g.nv - 1);
    let x = if x.is_finite() { x } else { 0.0 };
    let y = if y.is_finite() { y } else { 0.0 };
    let i = (x.floor().max(0.0) as usize).min(qu - 1);
    let j = (y.floor().max(0.0) as usize).min(qv - 1);
    let (a, b) = (x - i as f32, y - j as f32);
    let k = j * g.nu + i;
    (
        [k, k + 1, k + g.nu, k + g.nu + 1],
        [(1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b],
    )
}

/// The grid coordinates one ray footprint away from a hit along u and along v: the hit's
/// cone of width `w` along the unit direction `d` crosses the surface in an ellipse, whose
/// extent along a surface direction `e` is `w / |e⊥|` (`e⊥`: `e` less its part along the
/// ray); in micropolygons, that is `w / |∂P/∂a ⊥|` along the grid's rows (and the same down
/// its columns). Returns the two offsets' grid coordinates.
fn footprint_steps(g: &Grid, k: &[usize; 4], a: f32, b: f32, d: Vec3, w: f32) -> (f32, f32) {
    let p = &g.p;
    // The bilinear patch's derivatives at (a, b).
    let pa = (p[k[1]] - p[k[0]]) * (1.0 - b) + (p[k[3]] - p[k[2]]) * b;
    let pb = (p[k[2]] - p[k[0]]) * (1.0 - a) + (p[k[3]] - p[k[1]]) * a;
    let step = |e: Vec3| {
        let len = e.length();
        let perp = (e - d * e.dot(d)).length().max(0.05 * len);
        if perp > 0.0 && w > 0.0 {
            (w / perp).min(1e4)
        } else {
            0.0
        }
    };
    (step(pa), step(pb))
}

#[inline]
fn mix3(v: &[Vec3], k: &[usize; 4], w: &[f32; 4]) -> Vec3 {
    v[k[0]] * w[0] + v[k[1]] * w[1] + v[k[2]] * w[2] + v[k[3]] * w[3]
}

/// The shading records of a ray grid's vertices `k` (see [`HitVertex`]).
#[inline]
fn corners<'r>(rs: &'r RayScene, rg: &RayGrid, k: &[usize; 4]) -> [&'r HitVertex; 4] {
    let v = &rs.verts[rg.first..];
    [&v[k[0]], &v[k[1]], &v[k[2]], &v[k[3]]]
}

/// One hit to shade: which ray, where.
#[derive(Clone, Copy)]
struct PendingHit {
    ray: usize,
    grid: u32,
    index: u32,
    a: f32,
    b: f32,
    p: Vec3,
    /// Incident vector (hit − origin).
    i: Vec3,
    /// The space the ray crossed (picks the hit's volume shader).
    medium: Medium,
    /// The primitive whose shading context shades it (see [`RayScene::shade_as`]).
    class: usize,
    /// The ray's cone, its width taken at the hit.
    cone: Cone,
}

/// The space a ray crossed to reach its hit: the inside of the hit object when the ray leaves
/// it there (it runs along the outward geometric normal), else the outside. Only objects with
/// an `Interior` or `Exterior` shader tell the two apart (the others keep one grid of hits).
fn medium_of(
    rs: &RayScene,
    scene: &Scene,
    grid: u32,
    index: u32,
    a: f32,
    b: f32,
    d: Vec3,
) -> Medium {
    let rg = &rs.grids[grid as usize];
    // (`media` says as much as the attributes, without reading them.)
    if !rg.media || scene.primitives.get(rg.prim).is_none() {
        return Medium::Outside;
    }
    let (k, w) = lerp_weights(rg, index, a, b);
    let c = corners(rs, rg, &k);
    let ng = c[0].ng * w[0] + c[1].ng * w[1] + c[2].ng * w[2] + c[3].ng * w[3];
    if d.dot(ng) > 0.0 {
        Medium::Inside
    } else {
        Medium::Outside
    }
}

/// Asks for the fields of ray grid `grid` that a hit's gathering reads (its size, first
/// record, primitive variables, visibility and media flags: a record of about 490 bytes, so a few
/// lines). No effect on results.
#[inline(always)]
fn prefetch_grid(rs: &RayScene, grid: u32) {
    if let Some(rg) = rs.grids.get(grid as usize) {
        prefetch(&rg.grid.nu);
        prefetch(&rg.grid.primvars);
        prefetch(&rg.first);
        prefetch(&rg.trace);
        prefetch(&rg.media);
        prefetch(&rg.prim);
        prefetch(&rg.cs);
        prefetch(&rg.os);
    }
}

/// A point of a grid of hits: where on which ray grid, with its interpolation weights (and
/// the grid's first shading record, so the fill can prefetch records without reading the
/// grid).
#[derive(Clone, Copy, Default)]
struct HitPoint {
    grid: u32,
    first: usize,
    k: [usize; 4],
    w: [f32; 4],
    p: Vec3,
    i: Vec3,
}

/// Builds the grid of hits on one primitive, or on primitives that shade as one (all `hits`
/// come from grids with the same primitive-variable layout, see [`shading_classes`]). With
/// `triples`, each hit is followed by the surface one ray footprint away along u and along v
/// (`ops::TRIPLES`): the point of the ray grid that far across it, seen along the ray's
/// neighbour in the cone (the incident vector turned by the cone's spread), so derivatives
/// (and texture filter widths) at the hit follow the ray's footprint.
fn hit_grid(rs: &RayScene, hits: &[PendingHit], triples: bool) -> Grid {
    let per = if triples { 3 } else { 1 };
    let n = hits.len() * per;
    let mut g = Grid::with_size(n, 1);
    let first = &rs.grids[hits[0].grid as usize].grid;
    g.du = first.du;
    g.dv = first.dv;
    // Primitive variables: the first grid's layout (every grid of the group has the same).
    let mut pv: Vec<GridVar> = first
        .primvars
        .iter()
        .map(|v| GridVar {
            name: v.name.clone(),
            ty: v.ty,
            array_len: v.array_len,
            uniform: v.uniform,
            floats: if v.uniform {
                v.floats.clone()
            } else {
                vec![0.0; n * v.width()]
            },
            strings: v.strings.clone(),
        })
        .collect();
    let at_hit = |hit: &PendingHit| {
        let rg = &rs.grids[hit.grid as usize];
        let (k, w) = lerp_weights(rg, hit.index, hit.a, hit.b);
        HitPoint {
            grid: hit.grid,
            first: rg.first,
            k,
            w,
            p: hit.p,
            i: hit.i,
        }
    };
    if !triples {
        // One point a hit, made as the fill reaches it (no list of copies).
        fill_points(
            rs,
            &mut g,
            &mut pv,
            hits.len(),
            |h| hits[h].grid,
            |h| at_hit(&hits[h]),
        );
        g.primvars = pv;
        return g;
    }
    // The points to shade, gathered first (a hit and its two footprint neighbours).
    let mut pts: Vec<HitPoint> = Vec::with_capacity(n);
    for (h, hit) in hits.iter().enumerate() {
        if let Some(ahead) = hits.get(h + AHEAD) {
            prefetch_grid(rs, ahead.grid);
        }
        let rg = &rs.grids[hit.grid as usize];
        let pt = at_hit(hit);
        let k = pt.k;
        pts.push(pt);
        let src = &rg.grid;
        let qu = src.nu - 1;
        let (i, j) = (hit.index as usize % qu, hit.index as usize / qu);
        let (x, y) = (
            i as f32 + hit.a.clamp(0.0, 1.0),
            j as f32 + hit.b.clamp(0.0, 1.0),
        );
        let len = hit.i.length();
        let d = if len > 0.0 { hit.i / len } else { Vec3::Z };
        let width = hit.cone.width;
        let (sa, sb) = footprint_steps(src, &k, hit.a, hit.b, d, width);
        for (x, y) in [(x + sa, y), (x, y + sb)] {
            let (k2, w2) = grid_weights(src, x, y);
            let p = mix3(&src.p, &k2, &w2);
            // The neighbouring ray of the cone through p: turned by the spread per width of
            // sideways offset.
            let off = p - hit.p;
            let side = off - d * off.dot(d);
            let turn = if width > 0.0 {
                side * (hit.cone.spread / width)
            } else {
                Vec3::ZERO
            };
            pts.push(HitPoint {
                k: k2,
                w: w2,
                p,
                i: (d + turn) * len,
                ..pt
            });
        }
    }
    fill_points(rs, &mut g, &mut pv, pts.len(), |h| pts[h].grid, |h| pts[h]);
    g.primvars = pv;
    g
}

/// Fills points `0..n` of the grid of hits `g` (and its varying primitive variables `pv`)
/// from the ray grids' shading records, point `h` being `point(h)` (called once each, in
/// order, `AHEAD` points before it is filled, so its corners' records are prefetched while
/// the points before it fill) on ray grid `grid_of(h)` (asked for `AHEAD` points earlier
/// still: `point` reads the grid's size).
fn fill_points(
    rs: &RayScene,
    g: &mut Grid,
    pv: &mut [GridVar],
    n: usize,
    grid_of: impl Fn(usize) -> u32,
    mut point: impl FnMut(usize) -> HitPoint,
) {
    for h in 0..(2 * AHEAD).min(n) {
        prefetch_grid(rs, grid_of(h));
    }
    let mut ring = [HitPoint::default(); AHEAD];
    for (h, slot) in ring.iter_mut().enumerate().take(n) {
        *slot = point(h);
    }
    for h in 0..n {
        if h + 2 * AHEAD < n {
            prefetch_grid(rs, grid_of(h + 2 * AHEAD));
        }
        let pt = ring[h % AHEAD];
        if h + AHEAD < n {
            let ahead = point(h + AHEAD);
            // Its corners' records: two pairs of neighbours, a cache line each. (Colours
            // and opacities varying per vertex, rare, are not prefetched.)
            let v = rs.verts.as_ptr().wrapping_add(ahead.first);
            prefetch_span(v.wrapping_add(ahead.k[0]), 2);
            prefetch_span(v.wrapping_add(ahead.k[2]), 2);
            ring[h % AHEAD] = ahead;
        }
        let (k, w) = (pt.k, pt.w);
        let rg = &rs.grids[pt.grid as usize];
        let src = &rg.grid;
        g.p[h] = pt.p;
        g.i[h] = pt.i;
        let f = interpolate(&corners(rs, rg, &k), &w);
        g.n[h] = Vec3::new(f[0], f[1], f[2]);
        g.ng[h] = Vec3::new(f[3], f[4], f[5]);
        g.dpdu[h] = Vec3::new(f[6], f[7], f[8]);
        g.dpdv[h] = Vec3::new(f[9], f[10], f[11]);
        [g.u[h], g.v[h], g.s[h], g.t[h]] = [f[12], f[13], f[14], f[15]];
        g.cs[h] = rg.cs.at(&rs.cs, &k, &w);
        g.os[h] = rg.os.at(&rs.os, &k, &w);
        for (dst, sv) in pv.iter_mut().zip(&src.primvars) {
            if dst.uniform || sv.uniform || sv.width() != dst.width() {
                continue;
            }
            let wd = dst.width();
            for c in 0..wd {
                let mut x = 0.0;
                for q in 0..4 {
                    x += sv.floats.get(k[q] * wd + c).copied().unwrap_or(0.0) * w[q];
                }
                dst.floats[h * wd + c] = x;
            }
        }
    }
}

/// The sixteen numbers of four records (see [`HitVertex::floats`]) weighted by `w` and summed
/// as `c0·w0 + c1·w1 + c2·w2 + c3·w3`, number by number: the same operations in the same
/// order as interpolating field by field, so the same bits (on x86-64 four numbers at a
/// time, SSE being the baseline).
#[inline(always)]
fn interpolate(c: &[&HitVertex; 4], w: &[f32; 4]) -> [f32; 16] {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        let mut out = [0f32; 16];
        // SAFETY: a `HitVertex` is 16 `f32`s (repr(C), asserted 64 bytes, fields all f32), so
        // each load reads 4 of them inside the record; the stores write inside `out`.
        unsafe {
            let wv = w.map(|x| _mm_set1_ps(x));
            for q in 0..4 {
                let ld =
                    |v: &HitVertex| _mm_loadu_ps((v as *const HitVertex).cast::<f32>().add(4 * q));
                let mut acc = _mm_mul_ps(ld(c[0]), wv[0]);
                acc = _mm_add_ps(acc, _mm_mul_ps(ld(c[1]), wv[1]));
                acc = _mm_add_ps(acc, _mm_mul_ps(ld(c[2]), wv[2]));
                acc = _mm_add_ps(acc, _mm_mul_ps(ld(c[3]), wv[3]));
                _mm_storeu_ps(out.as_mut_ptr().add(4 * q), acc);
            }
        }
        out
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let f = [c[0].floats(), c[1].floats(), c[2].floats(), c[3].floats()];
        std::array::from_fn(|e| f[0][e] * w[0] + f[1][e] * w[1] + f[2][e] * w[2] + f[3][e] * w[3])
    }
}

impl RayTracer for Tracer<'_, '_> {
    fn depth(&self) -> u32 {
        self.depth
    }

    fn trace(
        &self,
        org: &[Vec3],
        dir: &[Vec3],
        cones: &[Cone],
        active: &[bool],
        ci: &mut [Vec3],
        dist: &mut [f32],
    ) {
        let n = org.len();
        for c in ci.iter_mut() {
            *c = Vec3::ZERO;
        }
        for d in dist.iter_mut() {
            *d = f32::INFINITY;
        }
        if self.depth >= max_depth(self.scene) {
            return;
        }
        let Some(rs) = self.geometry() else {
            return;
        };
        if rs.bvh.is_empty() {
            return;
        }
        let bias = self.bias_for();
        // Per ray: current origin, the weight still passing (1 − accumulated opacity).
        let mut o: Vec<Vec3> = org.to_vec();
        let mut weight = vec![Vec3::ONE; n];
        let mut live: Vec<bool> = (0..n)
            .map(|k| active.get(k).copied().unwrap_or(false) && dir[k].length_squared() > 0.0)
            .collect();
        let mut travelled = vec![0f32; n];
        // At most one hit a ray a layer: sized once (growing it copied the hits ~10 times a
        // call).
        let mut pending: Vec<PendingHit> = Vec::with_capacity(n);
        // A layer's live rays (index, origin, direction, tmin) and their hits, the lists
        // sized once a call and refilled each layer in one pass.
        let mut rays: Vec<usize> = Vec::with_capacity(n);
        let (mut ro, mut rd) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut rt: Vec<f32> = Vec::with_capacity(n);
        let mut found = Vec::with_capacity(n);
        let mut hit_cones: Vec<Cone> = Vec::new();
        for _layer in 0..MAX_LAYERS {
            pending.clear();
            // The live rays' closest hits, traced together (their walks interleave, see
            // `Bvh::closest_many`); a hit on a grid rays do not see falls back to the
            // filtered search, as `closest_where` does.
            rays.clear();
            ro.clear();
            rd.clear();
            rt.clear();
            for k in (0..n).filter(|&k| live[k]) {
                rays.push(k);
                ro.push(o[k]);
                rd.push(dir[k]);
                rt.push(bias / dir[k].length());
            }
            found.clear();
            found.resize(rays.len(), None);
            rs.bvh
                .closest_many(&ro, &rd, &rt, f32::INFINITY, &mut found);
            for (j, &k) in rays.iter().enumerate() {
                if let Some(Some(ahead)) = found.get(j + AHEAD) {
                    prefetch_grid(&rs, ahead.grid);
                }
                let d = dir[k];
                let hit = match found[j] {
                    Some(h) if !rs.grids[h.grid as usize].trace => {
                        closest_where(&rs, o[k], d, rt[j], |g| g.trace)
                    }
                    h => h,
                };
                match hit {
                    Some(h) => {
                        let p = o[k] + d * h.t;
                        if dist[k].is_infinite() {
                            dist[k] = travelled[k] + h.t;
                        }
                        travelled[k] += h.t;
                        let cone = cones.get(k).map_or(Cone::default(), |c| Cone {
                            width: c.width_at(travelled[k] * d.length()),
                            spread: c.spread,
                        });
                        let prim = rs.grids[h.grid as usize].prim;
                        pending.push(PendingHit {
                            class: rs.shade_as.get(prim).copied().unwrap_or(prim),
                            ray: k,
                            grid: h.grid,
                            index: h.index,
                            a: h.a,
                            b: h.b,
                            p,
                            i: p - org[k],
                            medium: medium_of(&rs, self.scene, h.grid, h.index, h.a, h.b, d),
                            cone,
                        });
                    }
                    None => live[k] = false,
                }
            }
            if pending.is_empty() {
                break;
            }
            // Group by the primitive whose context shades them and the space the rays crossed,
            // keeping ray order inside each group.
            let shade_as = |h: &PendingHit| (h.class, h.medium == Medium::Inside);
            // Keys are distinct (one hit per ray per layer): unstable sorting is the same order.
            pending.sort_unstable_by_key(|h| (shade_as(h), h.ray));
            let mut s = 0;
            while s < pending.len() {
                let key = shade_as(&pending[s]);
                let mut e = s + 1;
                while e < pending.len() && shade_as(&pending[e]) == key {
                    e += 1;
                }
                let group = &pending[s..e];
                let prim = key.0;
                let triples = self.sys.hit_wants_differentials(self.scene, prim);
                let mut g = hit_grid(&rs, group, triples);
                let per = if triples { 3 } else { 1 };
                hit_cones.clear();
                for h in group {
                    for _ in 0..per {
                        hit_cones.push(h.cone);
                    }
                }
                self.sys.shade_ray_hits(
                    self.scene,
                    self.camera,
                    prim,
                    &mut g,
                    self.depth + 1,
                    group[0].medium,
                    &hit_cones,
                    triples,
                );
                for (h, hit) in group.iter().enumerate() {
                    let k = hit.ray;
                    let (c, op) = (g.ci[h * per], g.oi[h * per]);
                    ci[k] += weight[k] * c;
                    weight[k] *= Vec3::ONE - op.clamp(Vec3::ZERO, Vec3::ONE);
                    o[k] = hit.p;
                    if weight[k].max_element() < 1.0 / 256.0 {
                        live[k] = false;
                    }
                }
                s = e;
            }
        }
    }

    fn transmission(&self, from: &[Vec3], to: &[Vec3], active: &[bool], out: &mut [Vec3]) {
        for v in out.iter_mut() {
            *v = Vec3::ONE;
        }
        let Some(rs) = self.geometry() else {
            return;
        };
        if rs.bvh.is_empty() {
            return;
        }
        let bias = self.bias_for();
        let skip = self.skip_light;
        // The segments worth a walk, traced together (their walks interleave, see
        // `Bvh::each_hit_many`: each ray's hits come in its lone walk's order, so each
        // product below is the lone walk's, bit for bit).
        let mut rays = Vec::new();
        let (mut ro, mut rd, mut rt0, mut rt1) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for k in 0..from.len().min(to.len()).min(out.len()) {
            if !active.get(k).copied().unwrap_or(false) {
                continue;
            }
            let d = to[k] - from[k];
            let len = d.length();
            if !(len > 2.0 * bias) || !len.is_finite() {
                continue;
            }
            rays.push(k);
            ro.push(from[k]);
            rd.push(d);
            rt0.push(bias / len);
            rt1.push(1.0 - bias / len);
        }
        rs.bvh.each_hit_many(&ro, &rd, &rt0, &rt1, &mut |j, h| {
            let rg = &rs.grids[h.grid as usize];
            if !rg.shadows || (skip.is_some() && rg.area_light == skip) {
                return false;
            }
            let t = &mut out[rays[j]];
            // (A grid of one opacity, the common case, reads no vertex here.)
            let (kk, w) = lerp_weights(rg, h.index, h.a, h.b);
            let os = rg.os.at(&rs.os, &kk, &w).clamp(Vec3::ZERO, Vec3::ONE);
            *t *= Vec3::ONE - os;
            // An opaque blocker (its interpolated opacity within rounding of 1) ends the
            // walk: nothing can pass.
            if t.max_element() < 1e-6 {
                *t = Vec3::ZERO;
                return true;
            }
            false
        });
    }
}

/// The closest hit on grids passing `keep`.
pub fn closest_where(
    rs: &RayScene,
    o: Vec3,
    d: Vec3,
    tmin: f32,
    keep: impl Fn(&RayGrid) -> bool,
) -> Option<crate::ray::Hit> {
    // Fast path: every grid kept.
    let h = rs.bvh.closest(o, d, tmin, f32::INFINITY)?;
    if keep(&rs.grids[h.grid as usize]) {
        return Some(h);
    }
    let mut best: Option<crate::ray::Hit> = None;
    rs.bvh.each_hit(o, d, tmin, f32::INFINITY, &mut |hit| {
        if keep(&rs.grids[hit.grid as usize]) && best.is_none_or(|b| hit.t < b.t) {
            best = Some(hit);
        }
        false
    });
    best
}

/// Reads a string user attribute or option value (for `visibility` and friends).
#[allow(dead_code)]
fn param_str(d: &ParamData) -> Option<&str> {
    d.strings().first().map(String::as_str)
}

/// The diffuse depth of the grid this thread is shading (0: no diffuse bounce above it).
pub fn diffuse_depth() -> u32 {
    DIFFUSE_DEPTH.with(|d| d.get())
}

/// The mean radiance arriving at each active point `p` over the hemisphere (or the cone of
/// half-angle `cone`) around unit normal `units`, cosine-weighted, from `count` stratified
/// rays (with ray `cones`, none: zero width and spread): the hits' shaded Ci, `env_color`
/// past `maxdist` or on a miss. The hits are shaded
/// one diffuse bounce deeper ([`diffuse_depth`]). `salt` decorrelates callers.
#[allow(clippy::too_many_arguments)]
pub fn mean_radiance(
    rt: &dyn RayTracer,
    p: &[Vec3],
    units: &[Vec3],
    cones: &[Cone],
    active: &[bool],
    count: u32,
    maxdist: f32,
    cone: f32,
    env_color: Vec3,
    salt: u32,
) -> Vec<Vec3> {
    use crate::ray::{cosine_dir, point_seed, stratified};
    // Restores the depth however this call ends.
    struct Deeper(u32);
    impl Drop for Deeper {
        fn drop(&mut self) {
            DIFFUSE_DEPTH.with(|d| d.set(self.0));
        }
    }
    let depth = diffuse_depth();
    DIFFUSE_DEPTH.with(|d| d.set(depth + 1));
    let _restore = Deeper(depth);
    let n = p.len();
    let mut acc = vec![Vec3::ZERO; n];
    let mut buf = vec![Vec3::ONE; n];
    let mut dist = vec![0f32; n];
    for k in 0..count {
        let dirs: Vec<Vec3> = (0..n)
            .map(|i| {
                let (u1, u2) = stratified(point_seed(p[i], salt), k, count);
                cosine_dir(units[i], u1, u2, cone)
            })
            .collect();
        rt.trace(p, &dirs, cones, active, &mut buf, &mut dist);
        for i in 0..n {
            acc[i] += if dist[i] <= maxdist {
                buf[i]
            } else {
                env_color
            };
        }
    }
    let inv = 1.0 / count.max(1) as f32;
    acc.iter().map(|a| *a * inv).collect()
}
