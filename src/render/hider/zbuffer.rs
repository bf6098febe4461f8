//! The stochastic Z-buffer hider (`Hider "hidden"`), after Cook, Carpenter & Catmull (1987).
//!
//! Input: shaded micropolygon grids overlapping a bucket's sample region. Output: a
//! [`SampleBuffer`] with premultiplied r g b, alpha, camera depth z and output variables.
//! Invariants: `PixelSamples` stratified jittered samples per pixel, their positions a hash of
//! (pixel, stratum, seed); each micropolygon (two triangles) is tested only against the samples
//! inside its raster bound; shared edges follow a canonical tie rule so a sample on an edge is
//! hit exactly once; per-sample visible points are composited front to back in the total order
//! (depth, grid key, micropolygon), so results do not depend on the order grids arrive in.

// Colour loops index several parallel arrays by channel.
#![allow(clippy::needless_range_loop)]

use crate::film::SampleBuffer;
use crate::num::floor_i32;

use super::super::camera::PixelRect;
use super::super::sampler::{pixel_positions, time_and_lens};
use super::super::stats::Stats;
use super::csg::{self, CsgHit};
use super::{DepthFilter, Hider, HiderConfig, ShadedGrid};

const NONE: u32 = u32::MAX;

/// The Z-buffer hider.
pub struct ZBuffer {
    config: HiderConfig,
}

impl ZBuffer {
    pub fn new(config: HiderConfig) -> ZBuffer {
        ZBuffer { config }
    }
}

/// A sample buffer for `rect` with every sample empty (no colour, alpha 0, z = ∞) and the
/// sample positions filled in.
pub fn empty_buffer(cfg: &HiderConfig, rect: PixelRect) -> SampleBuffer {
    let [xs, ys] = cfg.spp;
    let (w, h) = (rect.width(), rect.height());
    let n = w * h * xs * ys;
    let mut positions = Vec::with_capacity(n);
    for py in rect.y0..rect.y1 {
        for px in rect.x0..rect.x1 {
            pixel_positions(px, py, cfg.spp, cfg.jitter, cfg.seed, &mut positions);
        }
    }
    let channels = cfg.channels();
    let mut values = vec![0f32; n * channels];
    for s in 0..n {
        values[s * channels + 4] = f32::INFINITY;
    }
    SampleBuffer {
        x0: rect.x0,
        y0: rect.y0,
        width: w,
        height: h,
        spp_x: xs,
        spp_y: ys,
        positions,
        channels,
        values,
    }
}

/// One surface seen by one sample.
#[derive(Clone, Copy, Debug)]
struct VisPoint {
    z: f32,
    key: u64,
    sub: u32,
    next: u32,
    matte: bool,
    c: [f32; 3],
    o: [f32; 3],
    /// Offset of this point's output variables in the bucket's aov arena.
    aov: u32,
}

/// The shading of a sample's nearest opaque point, kept beside its depth: an opaque hit is
/// written here directly instead of joining the sample's list of visible points.
#[derive(Clone, Copy, Debug, Default)]
struct Shade {
    set: bool,
    matte: bool,
    c: [f32; 3],
    o: [f32; 3],
    aov: u32,
}

/// (depth, grid key, micropolygon) total order.
#[inline]
fn before(z: f32, key: u64, sub: u32, oz: f32, okey: u64, osub: u32) -> bool {
    z < oz || (z == oz && (key, sub) < (okey, osub))
}

/// Per-bucket hiding state.
struct Bucket<'c> {
    cfg: &'c HiderConfig,
    heads: Vec<u32>,
    /// Nearest opaque point per sample (depth, key, sub), and the second nearest's depth.
    front: Vec<(f32, u64, u32)>,
    front_shade: Vec<Shade>,
    second: Vec<f32>,
    points: Vec<VisPoint>,
    aovs: Vec<f32>,
    tested: u64,
    hits: u64,
    /// Whether points behind the opaque front still matter (the midpoint depth filter).
    keep_second: bool,
    /// Samples without an opaque front yet.
    uncovered: usize,
    /// Every hit of CSG geometry (front and back faces), resolved after all grids, with
    /// their colour, opacity, matte flag and output variables.
    csg: Vec<CsgHit>,
    csg_data: Vec<([f32; 3], [f32; 3], bool)>,
    csg_aovs: Vec<f32>,
}

impl<'c> Bucket<'c> {
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn insert(
        &mut self,
        s: usize,
        z: f32,
        key: u64,
        sub: u32,
        c: [f32; 3],
        o: [f32; 3],
        matte: bool,
        aov: &[f32],
    ) {
        self.hits += 1;
        let opaque = o[0].min(o[1]).min(o[2]) >= self.cfg.zthreshold;
        let (fz, fk, fs) = self.front[s];
        if !before(z, key, sub, fz, fk, fs) {
            if opaque && z < self.second[s] {
                self.second[s] = z;
            }
            return;
        }
        if opaque {
            if fz == f32::INFINITY && z < f32::INFINITY {
                self.uncovered -= 1;
            }
            self.second[s] = fz;
            self.front[s] = (z, key, sub);
            // Drop the points the new opaque one hides.
            let mut prev = NONE;
            let mut cur = self.heads[s];
            while cur != NONE {
                let p = self.points[cur as usize];
                if before(p.z, p.key, p.sub, z, key, sub) {
                    prev = cur;
                } else if prev == NONE {
                    self.heads[s] = p.next;
                } else {
                    self.points[prev as usize].next = p.next;
                }
                cur = p.next;
            }
            // The list now holds only points before this one: it composites last.
            let aov_off = self.aovs.len() as u32;
            self.aovs.extend_from_slice(aov);
            self.front_shade[s] = Shade {
                set: true,
                matte,
                c,
                o,
                aov: aov_off,
            };
            return;
        }
        let idx = self.points.len() as u32;
        let aov_off = self.aovs.len() as u32;
        self.aovs.extend_from_slice(aov);
        self.points.push(VisPoint {
            z,
            key,
            sub,
            next: self.heads[s],
            matte,
            c,
            o,
            aov: aov_off,
        });
        self.heads[s] = idx;
    }
}

/// [`edge`] with its per-edge part done once per micropolygon: the canonical origin and
/// direction, and the sign. Evaluates to the same bits as `edge(a, b, p)` (negation and the
/// products are the same operations in the same order).
#[derive(Clone, Copy, Debug)]
struct Edge {
    o: [f32; 2],
    d: [f32; 2],
    neg: bool,
}

impl Edge {
    #[inline]
    fn new(a: [f32; 2], b: [f32; 2]) -> Edge {
        if (a[0], a[1]) < (b[0], b[1]) {
            Edge {
                o: a,
                d: [b[0] - a[0], b[1] - a[1]],
                neg: false,
            }
        } else {
            Edge {
                o: b,
                d: [a[0] - b[0], a[1] - b[1]],
                neg: true,
            }
        }
    }

    #[inline(always)]
    fn eval(&self, p: [f32; 2]) -> f32 {
        let e = self.d[0] * (p[1] - self.o[1]) - self.d[1] * (p[0] - self.o[0]);
        if self.neg {
            -e
        } else {
            e
        }
    }

    /// The sample is inside (or on the edge this direction owns).
    #[inline(always)]
    fn inside(&self, p: [f32; 2]) -> bool {
        let e = self.eval(p);
        e > 0.0 || (e == 0.0 && !self.neg)
    }
}

impl Hider for ZBuffer {
    fn config(&self) -> &HiderConfig {
        &self.config
    }

    fn hide(&self, rect: PixelRect, grids: &[&ShadedGrid], stats: &Stats) -> SampleBuffer {
        let cfg = &self.config;
        let mut buf = empty_buffer(cfg, rect);
        let n = buf.positions.len();
        let mut b = Bucket {
            cfg,
            heads: vec![NONE; n],
            front: vec![(f32::INFINITY, u64::MAX, u32::MAX); n],
            front_shade: vec![Shade::default(); n],
            second: vec![f32::INFINITY; n],
            points: Vec::new(),
            aovs: Vec::new(),
            tested: 0,
            hits: 0,
            keep_second: cfg.depth_filter == DepthFilter::Midpoint,
            uncovered: n,
            csg: Vec::new(),
            csg_data: Vec::new(),
            csg_aovs: Vec::new(),
        };
        // Front to back (ties by key), so opaque surfaces cull the grids behind them. The
        // order never changes the picture: visible points composite in a total order.
        let mut order: Vec<&ShadedGrid> = grids.to_vec();
        order.sort_by(|a, c| a.zmin.total_cmp(&c.zmin).then(a.key.cmp(&c.key)));
        // The farthest opaque front over the bucket (∞ while a sample sees none): a grid
        // entirely behind it hides nowhere. Refreshed as samples are hit; stale is safe
        // (fronts only come nearer).
        let mut far = f32::INFINITY;
        let mut hits_at_refresh = 0u64;
        // Motion blur and depth of field: each sample's time and lens position.
        let (mut times, mut lens) = (Vec::new(), Vec::new());
        if cfg.dof.is_some() || order.iter().any(|g| g.motion.is_some()) {
            let [xs, ys] = cfg.spp;
            times.reserve(n);
            lens.reserve(n);
            let mut perm = Vec::new();
            for py in rect.y0..rect.y1 {
                for px in rect.x0..rect.x1 {
                    time_and_lens(
                        px, py, xs, ys, cfg.jitter, cfg.seed, &mut perm, &mut times, &mut lens,
                    );
                }
            }
        }
        for g in order {
            if !b.keep_second
                && b.uncovered == 0
                && (far == f32::INFINITY || b.hits - hits_at_refresh >= (n as u64 / 8).max(1))
            {
                far = b.front.iter().fold(0f32, |m, f| m.max(f.0));
                hits_at_refresh = b.hits;
            }
            if g.zmin > far {
                Stats::add(&stats.grids_occluded, 1);
                continue;
            }
            if g.motion.is_some() || cfg.dof.is_some() {
                sample_grid_blurred(&mut b, &buf, rect, g, &times, &lens);
            } else {
                sample_grid(&mut b, &buf, rect, g);
            }
        }
        if !b.csg.is_empty() {
            resolve_csg(&mut b);
        }
        resolve(&b, &mut buf);
        stats.alloc(b.points.len() * std::mem::size_of::<VisPoint>() + buf.values.len() * 4);
        stats.free(b.points.len() * std::mem::size_of::<VisPoint>() + buf.values.len() * 4);
        Stats::add(&stats.samples_tested, b.tested);
        Stats::add(&stats.samples_hit, b.hits);
        buf
    }
}

/// Per micropolygon constants shared by its sample tests.
struct Micro<'a> {
    m: usize,
    /// The two triangles sharing the diagonal corner 0 – corner 2, as the old two-triangle
    /// test saw them: vertices (counter-clockwise), grid point indices, 1 / area, and the
    /// edges v2→v0 and v0→v1 whose values are the barycentric weights; None when degenerate.
    tris: [Option<Tri>; 2],
    cc: [f32; 3],
    co: [f32; 3],
    mean_aov: &'a [f32],
}

#[derive(Clone, Copy, Debug)]
struct Tri {
    v: [[f32; 2]; 3],
    idx: [usize; 3],
    inv_area: f32,
    e1: Edge,
    e2: Edge,
}

/// Candidate strata (0-based, clamped to `0..n`) of a pixel at integer coordinate
/// `p` whose samples may lie in `[t0, t1]`. Sample positions are `p + (s + j) / n` rounded, so
/// the range is widened by the rounding error; the exact test happens per sample.
#[inline]
fn strata(t0: f32, t1: f32, p: i32, n: usize) -> std::ops::Range<usize> {
    let nf = n as f32;
    let eps = (p.unsigned_abs() as f32 + 2.0) * nf * 2.5e-7 + 1e-4;
    let lo = floor_i32((t0 - p as f32) * nf - eps).max(0);
    let hi = floor_i32((t1 - p as f32) * nf + eps).min(n as i32 - 1);
    lo as usize..(hi + 1).max(lo) as usize
}

/// Tests every live micropolygon of `g` against the samples its raster bound covers: the
/// pixels under the bound and, in each, only the strata the bound reaches. A convex
/// micropolygon is one quad test (its four edges, then the diagonal picks the triangle whose
/// interpolation applies, so the result is that of the two-triangle test); others fall back to
/// two triangles.
fn sample_grid(b: &mut Bucket, buf: &SampleBuffer, rect: PixelRect, g: &ShadedGrid) {
    let cfg = b.cfg;
    let nu = g.nu;
    let aw = g.aov_width;
    // Sampling window: the bucket region clipped by the grid's own bound.
    let Some(win) = g.window(&rect) else {
        return;
    };
    let [wx0, wy0, wx1, wy1] = win;
    let mut mean_aov = vec![0f32; aw];
    let mut interp_aov = vec![0f32; aw];
    let mut visible = Vec::new();
    g.micropolygons_in(win, &mut visible);
    for &(m, k, mb) in &visible {
        let corner = [k, k + 1, k + nu + 1, k + nu];
        let bx = [
            mb[0].max(wx0),
            mb[1].max(wy0),
            mb[2].min(wx1),
            mb[3].min(wy1),
        ];
        if !(bx[0] <= bx[2] && bx[1] <= bx[3]) {
            continue;
        }
        // Constant shading: one colour per micropolygon, the mean of its corners.
        let (cc, co) = corner_means(g, &corner, &mut mean_aov);
        let p = corner.map(|c| g.xy[c]);
        let mut tris = [None, None];
        for (t, tri) in [[0, 1, 2], [0, 2, 3]].into_iter().enumerate() {
            let mut v = tri.map(|i| p[i]);
            let mut idx = tri.map(|i| corner[i]);
            let area = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1])
                - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            if area < 0.0 {
                v.swap(1, 2);
                idx.swap(1, 2);
            }
            tris[t] = Some(Tri {
                v,
                idx,
                inv_area: 1.0 / area.abs(),
                e1: Edge::new(v[2], v[0]),
                e2: Edge::new(v[0], v[1]),
            });
        }
        let mp = Micro {
            m,
            tris,
            cc,
            co,
            mean_aov: &mean_aov,
        };
        // Convex: every corner turns the same way (strictly).
        let turn = |a: [f32; 2], o: [f32; 2], c: [f32; 2]| {
            (a[0] - o[0]) * (c[1] - o[1]) - (a[1] - o[1]) * (c[0] - o[0])
        };
        let turns = [
            turn(p[1], p[0], p[3]),
            turn(p[2], p[1], p[0]),
            turn(p[3], p[2], p[1]),
            turn(p[0], p[3], p[2]),
        ];
        let ccw = turns.iter().all(|&t| t > 0.0);
        let cw = turns.iter().all(|&t| t < 0.0);
        if (ccw || cw) && mp.tris[0].is_some() && mp.tris[1].is_some() {
            // Outer edges counter-clockwise; the diagonal as triangle 0 sees it.
            let o = if ccw { [0, 1, 2, 3] } else { [0, 3, 2, 1] };
            let edges = [
                Edge::new(p[o[0]], p[o[1]]),
                Edge::new(p[o[1]], p[o[2]]),
                Edge::new(p[o[2]], p[o[3]]),
                Edge::new(p[o[3]], p[o[0]]),
            ];
            let diag0 = if ccw {
                Edge::new(p[2], p[0])
            } else {
                Edge::new(p[0], p[2])
            };
            for_samples(b, buf, rect, bx, |b, s, pos| {
                // Non-short-circuiting: four independent tests, one branch.
                let all = edges[0].inside(pos)
                    & edges[1].inside(pos)
                    & edges[2].inside(pos)
                    & edges[3].inside(pos);
                if !all {
                    return;
                }
                let t = if diag0.inside(pos) { 0 } else { 1 };
                hit(b, g, cfg, &mp, t, s, pos, &mut interp_aov);
            });
        } else {
            for t in 0..2 {
                let Some(Tri { v, .. }) = mp.tris[t] else {
                    continue;
                };
                let te = [
                    Edge::new(v[1], v[2]),
                    Edge::new(v[2], v[0]),
                    Edge::new(v[0], v[1]),
                ];
                let tb = [
                    v[0][0].min(v[1][0]).min(v[2][0]).max(bx[0]),
                    v[0][1].min(v[1][1]).min(v[2][1]).max(bx[1]),
                    v[0][0].max(v[1][0]).max(v[2][0]).min(bx[2]),
                    v[0][1].max(v[1][1]).max(v[2][1]).min(bx[3]),
                ];
                if !(tb[0] <= tb[2] && tb[1] <= tb[3]) {
                    continue;
                }
                for_samples(b, buf, rect, tb, |b, s, pos| {
                    if te[0].inside(pos) & te[1].inside(pos) & te[2].inside(pos) {
                        hit(b, g, cfg, &mp, t, s, pos, &mut interp_aov);
                    }
                });
            }
        }
    }
}

/// Tests a moving or out-of-focus grid: each sample sees the micropolygon's corners where
/// they are at its time (linear between keys), shifted by its lens position times their
/// circle of confusion, then tests the two triangles as the still path does. Only the
/// samples inside the micropolygon's bound over the whole shutter and lens are visited.
fn sample_grid_blurred(
    b: &mut Bucket,
    buf: &SampleBuffer,
    rect: PixelRect,
    g: &ShadedGrid,
    times: &[f32],
    lens: &[[f32; 2]],
) {
    let cfg = b.cfg;
    let nu = g.nu;
    let aw = g.aov_width;
    let Some(win) = g.window(&rect) else {
        return;
    };
    let [wx0, wy0, wx1, wy1] = win;
    let mut mean_aov = vec![0f32; aw];
    let mut interp_aov = vec![0f32; aw];
    let mut visible = Vec::new();
    g.micropolygons_in(win, &mut visible);
    let mo = g.motion.as_deref();
    let dof = cfg.dof;
    for &(m, k, mb) in &visible {
        let corner = [k, k + 1, k + nu + 1, k + nu];
        let bx = [
            mb[0].max(wx0),
            mb[1].max(wy0),
            mb[2].min(wx1),
            mb[3].min(wy1),
        ];
        if !(bx[0] <= bx[2] && bx[1] <= bx[3]) {
            continue;
        }
        let (cc, co) = corner_means(g, &corner, &mut mean_aov);
        for_samples(b, buf, rect, bx, |b, s, pos| {
            let mut p = [[0f32; 2]; 4];
            let mut q = [0f32; 4];
            match mo {
                Some(mo) => {
                    let (i, f) = crate::scene::motion_segment(&mo.times, times[s]);
                    let (xa, xb) = (&mo.xy[i], &mo.xy[i + 1]);
                    let (da, db) = (&mo.depth[i], &mo.depth[i + 1]);
                    for c in 0..4 {
                        let (a, e) = (xa[corner[c]], xb[corner[c]]);
                        p[c] = [a[0] + (e[0] - a[0]) * f, a[1] + (e[1] - a[1]) * f];
                        q[c] = da[corner[c]] + (db[corner[c]] - da[corner[c]]) * f;
                    }
                }
                None => {
                    for c in 0..4 {
                        p[c] = g.xy[corner[c]];
                        q[c] = g.depth[corner[c]];
                    }
                }
            }
            if let Some(d) = &dof {
                let l = lens[s];
                let (kx, ky) = (l[0] * d.raster_k[0], l[1] * d.raster_k[1]);
                for c in 0..4 {
                    let f = d.inv_focus - q[c];
                    p[c][0] += kx * f;
                    p[c][1] += ky * f;
                }
            }
            for (t, tri) in [[0usize, 1, 2], [0, 2, 3]].into_iter().enumerate() {
                let mut v = tri.map(|i| p[i]);
                let mut idx = tri.map(|i| corner[i]);
                let mut dq = tri.map(|i| q[i]);
                let area = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1])
                    - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
                if area == 0.0 || !area.is_finite() {
                    continue;
                }
                if area < 0.0 {
                    v.swap(1, 2);
                    idx.swap(1, 2);
                    dq.swap(1, 2);
                }
                if inside(edge(v[1], v[2], pos))
                    && inside(edge(v[2], v[0], pos))
                    && inside(edge(v[0], v[1], pos))
                {
                    let tri = BlurTri {
                        v,
                        idx,
                        dq,
                        inv_area: 1.0 / area.abs(),
                    };
                    let sub = (m as u32) << 1 | t as u32;
                    hit_blurred(
                        b,
                        g,
                        cfg,
                        &tri,
                        sub,
                        s,
                        pos,
                        &cc,
                        &co,
                        &mean_aov,
                        &mut interp_aov,
                    );
                    break;
                }
            }
        });
    }
}

/// Canonical edge function, for blurred micropolygons (whose corners move per sample, so
/// edges cannot be set up once) and as the reference [`Edge`] is tested against: the same bits for edge (a, b) and (b, a) up to sign, and
/// whether this direction owns samples exactly on the edge (exactly one of the two does).
#[inline]
pub(super) fn edge(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> (f32, bool) {
    if (a[0], a[1]) < (b[0], b[1]) {
        (
            (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]),
            true,
        )
    } else {
        (
            -((a[0] - b[0]) * (p[1] - b[1]) - (a[1] - b[1]) * (p[0] - b[0])),
            false,
        )
    }
}

#[inline]
pub(super) fn inside(e: (f32, bool)) -> bool {
    e.0 > 0.0 || (e.0 == 0.0 && e.1)
}

/// A triangle of a blurred micropolygon as one sample sees it.
struct BlurTri {
    v: [[f32; 2]; 3],
    idx: [usize; 3],
    /// Depth (1/z or z) at the vertices.
    dq: [f32; 3],
    inv_area: f32,
}

/// [`hit`] for a blurred micropolygon (its vertices and depths given per sample).
#[allow(clippy::too_many_arguments)]
#[inline]
fn hit_blurred(
    b: &mut Bucket,
    g: &ShadedGrid,
    cfg: &HiderConfig,
    tri: &BlurTri,
    sub: u32,
    s: usize,
    pos: [f32; 2],
    cc: &[f32; 3],
    co: &[f32; 3],
    mean_aov: &[f32],
    interp_aov: &mut [f32],
) {
    let (v, idx, dq) = (tri.v, tri.idx, tri.dq);
    let e1 = edge(v[2], v[0], pos);
    let e2 = edge(v[0], v[1], pos);
    let (w1, w2) = (e1.0 * tri.inv_area, e2.0 * tri.inv_area);
    let w0 = 1.0 - w1 - w2;
    let qz = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
    let z = if cfg.perspective { 1.0 / qz } else { qz };
    if !(z >= cfg.near && z <= cfg.far) {
        return;
    }
    if z > b.front[s].0 && !b.keep_second {
        b.hits += 1;
        return;
    }
    if !cfg.clip_planes.is_empty() {
        let p = cfg.camera_point(pos[0], pos[1], z);
        if cfg
            .clip_planes
            .iter()
            .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
        {
            return;
        }
    }
    if g.smooth {
        let (c, o) = interpolate(g, idx, [w0, w1, w2], interp_aov);
        b.insert(s, z, g.key, sub, c, o, g.matte, interp_aov);
    } else {
        b.insert(s, z, g.key, sub, *cc, *co, g.matte, mean_aov);
    }
}

/// Calls `f(bucket, sample index, position)` for every sample of `rect` inside the closed
/// box `bx` (x0, y0, x1, y1), visiting only the pixels and strata the box reaches.
#[inline]
fn for_samples(
    b: &mut Bucket,
    buf: &SampleBuffer,
    rect: PixelRect,
    bx: [f32; 4],
    mut f: impl FnMut(&mut Bucket, usize, [f32; 2]),
) {
    let [xs, ys] = b.cfg.spp;
    let spp = xs * ys;
    let px0 = floor_i32(bx[0]).max(rect.x0);
    let px1 = floor_i32(bx[2]).min(rect.x1 - 1);
    let py0 = floor_i32(bx[1]).max(rect.y0);
    let py1 = floor_i32(bx[3]).min(rect.y1 - 1);
    let w = rect.width();
    let mut tested = 0u64;
    for py in py0..=py1 {
        let sy = strata(bx[1], bx[3], py, ys);
        for px in px0..=px1 {
            let sx = strata(bx[0], bx[2], px, xs);
            let base = ((py - rect.y0) as usize * w + (px - rect.x0) as usize) * spp;
            for j in sy.clone() {
                let row = base + j * xs;
                for s in row + sx.start..row + sx.end {
                    let pos = buf.positions[s];
                    if pos[0] < bx[0] || pos[0] > bx[2] || pos[1] < bx[1] || pos[1] > bx[3] {
                        continue;
                    }
                    tested += 1;
                    f(b, s, pos);
                }
            }
        }
    }
    b.tested += tested;
}

/// Sample `s` at `pos` lies in triangle `t` of micropolygon `mp`: interpolate its depth
/// (and colour when smooth) and insert it.
#[allow(clippy::too_many_arguments)]
#[inline]
fn hit(
    b: &mut Bucket,
    g: &ShadedGrid,
    cfg: &HiderConfig,
    mp: &Micro,
    t: usize,
    s: usize,
    pos: [f32; 2],
    interp_aov: &mut [f32],
) {
    let Some(Tri {
        idx,
        inv_area,
        e1,
        e2,
        ..
    }) = mp.tris[t]
    else {
        return;
    };
    let (w1, w2) = (e1.eval(pos) * inv_area, e2.eval(pos) * inv_area);
    let w0 = 1.0 - w1 - w2;
    // Relative to vertex 0, so a constant depth stays exact.
    let dq = [g.depth[idx[0]], g.depth[idx[1]], g.depth[idx[2]]];
    let q = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
    let z = if cfg.perspective { 1.0 / q } else { q };
    if !(z >= cfg.near && z <= cfg.far) {
        return;
    }
    // Behind this sample's opaque front: nothing to do unless the second depth is kept.
    if z > b.front[s].0 && !b.keep_second {
        b.hits += 1;
        return;
    }
    if !cfg.clip_planes.is_empty() {
        let p = cfg.camera_point(pos[0], pos[1], z);
        if cfg
            .clip_planes
            .iter()
            .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
        {
            return;
        }
    }
    let sub = (mp.m as u32) << 1 | t as u32;
    if g.smooth {
        let (c, o) = interpolate(g, idx, [w0, w1, w2], interp_aov);
        put(b, g, mp.m, s, z, sub, c, o, interp_aov);
    } else {
        put(b, g, mp.m, s, z, sub, mp.cc, mp.co, mp.mean_aov);
    }
}

/// Inserts a visible point, or keeps a CSG grid's hit for [`resolve_csg`].
#[allow(clippy::too_many_arguments)]
#[inline]
fn put(
    b: &mut Bucket,
    g: &ShadedGrid,
    m: usize,
    s: usize,
    z: f32,
    sub: u32,
    c: [f32; 3],
    o: [f32; 3],
    aov: &[f32],
) {
    match &g.csg {
        None => b.insert(s, z, g.key, sub, c, o, g.matte, aov),
        Some(cg) => {
            b.hits += 1;
            b.csg.push(CsgHit {
                sample: s as u32,
                z,
                key: g.key,
                sub,
                leaf: cg.leaf,
                root: cg.root,
                entering: cg.entering.get(m).copied().unwrap_or(true),
                payload: b.csg_data.len() as u32,
            });
            b.csg_data.push((c, o, g.matte));
            b.csg_aovs.extend_from_slice(aov);
        }
    }
}

/// Keeps the CSG hits on their solids' boundaries as visible points.
fn resolve_csg(b: &mut Bucket) {
    let mut hits = std::mem::take(&mut b.csg);
    let data = std::mem::take(&mut b.csg_data);
    let aovs = std::mem::take(&mut b.csg_aovs);
    let aw = b.cfg.channels() - 5;
    let mut keep = Vec::new();
    csg::resolve(&b.cfg.csg, &mut hits, |h| keep.push(*h));
    for h in keep {
        let (c, o, matte) = data[h.payload as usize];
        let p = h.payload as usize;
        let aov = &aovs[p * aw..(p + 1) * aw];
        b.insert(h.sample as usize, h.z, h.key, h.sub, c, o, matte, aov);
        // Counted when found: this is the same hit.
        b.hits -= 1;
    }
}

/// A micropolygon's constant shading: the mean colour and opacity of its four corners (and
/// of their output variables, into `mean_aov`).
#[inline]
fn corner_means(g: &ShadedGrid, corner: &[usize; 4], mean_aov: &mut [f32]) -> ([f32; 3], [f32; 3]) {
    let aw = g.aov_width;
    let mut cc = [0f32; 3];
    let mut co = [0f32; 3];
    for &c in corner {
        for q in 0..3 {
            cc[q] += g.ci[c][q] * 0.25;
            co[q] += g.oi[c][q] * 0.25;
        }
    }
    if aw > 0 {
        mean_aov.iter_mut().for_each(|v| *v = 0.0);
        for &c in corner {
            for q in 0..aw {
                mean_aov[q] += g.aov[c * aw + q] * 0.25;
            }
        }
    }
    (cc, co)
}

/// Smooth shading at a sample: colour, opacity and output variables (into `interp_aov`)
/// interpolated from a triangle's grid points `idx` with barycentric weights `w`.
#[inline]
fn interpolate(
    g: &ShadedGrid,
    idx: [usize; 3],
    w: [f32; 3],
    interp_aov: &mut [f32],
) -> ([f32; 3], [f32; 3]) {
    let aw = g.aov_width;
    let mut c = [0f32; 3];
    let mut o = [0f32; 3];
    for (vi, &gi) in idx.iter().enumerate() {
        for q in 0..3 {
            c[q] += w[vi] * g.ci[gi][q];
            o[q] += w[vi] * g.oi[gi][q];
        }
    }
    for q in 0..aw {
        interp_aov[q] = w[0] * g.aov[idx[0] * aw + q]
            + w[1] * g.aov[idx[1] * aw + q]
            + w[2] * g.aov[idx[2] * aw + q];
    }
    (c, o)
}

/// Composites each sample's visible points front to back into the buffer.
fn resolve(b: &Bucket, buf: &mut SampleBuffer) {
    let cfg = b.cfg;
    let ch = buf.channels;
    let naov = ch - 5;
    let mut list: Vec<u32> = Vec::new();
    let stop = 1.0 - cfg.othreshold;
    for s in 0..b.heads.len() {
        let mut cur = b.heads[s];
        let front = &b.front_shade[s];
        if cur == NONE && !front.set {
            continue;
        }
        list.clear();
        while cur != NONE {
            list.push(cur);
            cur = b.points[cur as usize].next;
        }
        if list.len() > 1 {
            list.sort_unstable_by(|&x, &y| {
                let (p, q) = (&b.points[x as usize], &b.points[y as usize]);
                p.z.total_cmp(&q.z)
                    .then(p.key.cmp(&q.key))
                    .then(p.sub.cmp(&q.sub))
            });
        }
        let out = &mut buf.values[s * ch..(s + 1) * ch];
        let mut tr = [1f32; 3];
        let mut alpha = 0f32;
        // The transparent points before the opaque front, in order, then the front itself.
        let points = list.iter().map(|&pi| {
            let p = &b.points[pi as usize];
            (p.matte, p.c, p.o, p.aov)
        });
        let last = front
            .set
            .then_some((front.matte, front.c, front.o, front.aov));
        for (matte, c, o, aov) in points.chain(last) {
            if !matte {
                let w = (tr[0] * o[0] + tr[1] * o[1] + tr[2] * o[2]) * (1.0 / 3.0);
                for q in 0..3 {
                    out[q] += tr[q] * c[q];
                }
                alpha += w;
                for q in 0..naov {
                    out[5 + q] += w * b.aovs[aov as usize + q];
                }
            }
            for q in 0..3 {
                tr[q] *= 1.0 - o[q];
            }
            if tr[0] <= stop && tr[1] <= stop && tr[2] <= stop {
                break;
            }
        }
        out[3] = alpha;
        let (fz, _, _) = b.front[s];
        out[4] = match cfg.depth_filter {
            DepthFilter::Midpoint if b.second[s].is_finite() => 0.5 * (fz + b.second[s]),
            _ => fz,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precomputed_edges_give_the_reference_bits() {
        // Pseudo-random vertices and points, plus points exactly on an edge and its ends.
        let mut k = 12345u32;
        let mut r = || {
            k = k.wrapping_mul(747796405).wrapping_add(2891336453);
            (k >> 8) as f32 / (1u32 << 24) as f32 * 40.0 - 20.0
        };
        for _ in 0..2000 {
            let (a, b) = ([r(), r()], [r(), r()]);
            let on = [a[0] + 0.5 * (b[0] - a[0]), a[1] + 0.5 * (b[1] - a[1])];
            for p in [[r(), r()], a, b, on] {
                for (x, y) in [(a, b), (b, a)] {
                    let e = Edge::new(x, y);
                    let want = edge(x, y, p);
                    assert_eq!(e.eval(p).to_bits(), want.0.to_bits());
                    assert_eq!(e.inside(p), inside(want));
                }
                // Exactly one direction owns a sample lying on the edge.
                if Edge::new(a, b).eval(p) == 0.0 && a != b {
                    assert!(Edge::new(a, b).inside(p) ^ Edge::new(b, a).inside(p));
                }
            }
        }
    }
}
