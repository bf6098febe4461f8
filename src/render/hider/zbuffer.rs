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
use super::super::sampler::sample_position;
use super::super::stats::Stats;
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
            for sy in 0..ys {
                for sx in 0..xs {
                    positions.push(sample_position(
                        px, py, sx, sy, xs, ys, cfg.jitter, cfg.seed,
                    ));
                }
            }
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
    second: Vec<f32>,
    points: Vec<VisPoint>,
    aovs: Vec<f32>,
    tested: u64,
    hits: u64,
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

/// Canonical edge function: the same bits for edge (a, b) and (b, a) up to sign, and whether
/// this direction owns samples exactly on the edge (exactly one of the two directions does).
#[inline]
fn edge(a: [f32; 2], b: [f32; 2], p: [f32; 2]) -> (f32, bool) {
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
fn inside(e: (f32, bool)) -> bool {
    e.0 > 0.0 || (e.0 == 0.0 && e.1)
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
            second: vec![f32::INFINITY; n],
            points: Vec::new(),
            aovs: Vec::new(),
            tested: 0,
            hits: 0,
        };
        for g in grids {
            sample_grid(&mut b, &buf, rect, g);
        }
        resolve(&b, &mut buf);
        stats.alloc(b.points.len() * std::mem::size_of::<VisPoint>() + buf.values.len() * 4);
        stats.free(b.points.len() * std::mem::size_of::<VisPoint>() + buf.values.len() * 4);
        Stats::add(&stats.samples_tested, b.tested);
        Stats::add(&stats.samples_hit, b.hits);
        buf
    }
}

/// Tests every live micropolygon of `g` against the samples its raster bound covers.
fn sample_grid(b: &mut Bucket, buf: &SampleBuffer, rect: PixelRect, g: &ShadedGrid) {
    let cfg = b.cfg;
    let [xs, ys] = cfg.spp;
    let spp = xs * ys;
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
        let (x0, y0, x1, y1) = (
            mb[0].max(wx0),
            mb[1].max(wy0),
            mb[2].min(wx1),
            mb[3].min(wy1),
        );
        if !(x0 <= x1 && y0 <= y1) {
            continue;
        }
        // Constant shading: one colour per micropolygon, the mean of its corners.
        let mut cc = [0f32; 3];
        let mut co = [0f32; 3];
        for &c in &corner {
            for q in 0..3 {
                cc[q] += g.ci[c][q] * 0.25;
                co[q] += g.oi[c][q] * 0.25;
            }
        }
        if aw > 0 {
            mean_aov.iter_mut().for_each(|v| *v = 0.0);
            for &c in &corner {
                for q in 0..aw {
                    mean_aov[q] += g.aov[c * aw + q] * 0.25;
                }
            }
        }
        // Two triangles sharing the diagonal corner[0]–corner[2].
        for (t, tri) in [
            [corner[0], corner[1], corner[2]],
            [corner[0], corner[2], corner[3]],
        ]
        .into_iter()
        .enumerate()
        {
            let mut v = [g.xy[tri[0]], g.xy[tri[1]], g.xy[tri[2]]];
            let mut idx = tri;
            let area = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1])
                - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            if area < 0.0 {
                v.swap(1, 2);
                idx.swap(1, 2);
            }
            let area = area.abs();
            let tx0 = v[0][0].min(v[1][0]).min(v[2][0]).max(x0);
            let tx1 = v[0][0].max(v[1][0]).max(v[2][0]).min(x1);
            let ty0 = v[0][1].min(v[1][1]).min(v[2][1]).max(y0);
            let ty1 = v[0][1].max(v[1][1]).max(v[2][1]).min(y1);
            if !(tx0 <= tx1 && ty0 <= ty1) {
                continue;
            }
            let px0 = floor_i32(tx0).max(rect.x0);
            let px1 = floor_i32(tx1).min(rect.x1 - 1);
            let py0 = floor_i32(ty0).max(rect.y0);
            let py1 = floor_i32(ty1).min(rect.y1 - 1);
            let sub = (m as u32) << 1 | t as u32;
            let inv_area = 1.0 / area;
            let dq = [g.depth[idx[0]], g.depth[idx[1]], g.depth[idx[2]]];
            for py in py0..=py1 {
                for px in px0..=px1 {
                    let base =
                        ((py - rect.y0) as usize * rect.width() + (px - rect.x0) as usize) * spp;
                    for s in base..base + spp {
                        let pos = buf.positions[s];
                        if pos[0] < tx0 || pos[0] > tx1 || pos[1] < ty0 || pos[1] > ty1 {
                            continue;
                        }
                        b.tested += 1;
                        let e0 = edge(v[1], v[2], pos);
                        if !inside(e0) {
                            continue;
                        }
                        let e1 = edge(v[2], v[0], pos);
                        if !inside(e1) {
                            continue;
                        }
                        let e2 = edge(v[0], v[1], pos);
                        if !inside(e2) {
                            continue;
                        }
                        let (w1, w2) = (e1.0 * inv_area, e2.0 * inv_area);
                        let w0 = 1.0 - w1 - w2;
                        // Relative to vertex 0, so a constant depth stays exact.
                        let q = dq[0] + w1 * (dq[1] - dq[0]) + w2 * (dq[2] - dq[0]);
                        let z = if cfg.perspective { 1.0 / q } else { q };
                        if !(z >= cfg.near && z <= cfg.far) {
                            continue;
                        }
                        if !cfg.clip_planes.is_empty() {
                            let p = cfg.camera_point(pos[0], pos[1], z);
                            if cfg
                                .clip_planes
                                .iter()
                                .any(|pl| pl.truncate().dot(p) + pl.w > 0.0)
                            {
                                continue;
                            }
                        }
                        let (c, o, aov): ([f32; 3], [f32; 3], &[f32]) = if g.smooth {
                            let w = [w0, w1, w2];
                            let mut c = [0f32; 3];
                            let mut o = [0f32; 3];
                            for (vi, &gi) in idx.iter().enumerate() {
                                for q in 0..3 {
                                    c[q] += w[vi] * g.ci[gi][q];
                                    o[q] += w[vi] * g.oi[gi][q];
                                }
                            }
                            for q in 0..aw {
                                interp_aov[q] = w0 * g.aov[idx[0] * aw + q]
                                    + w1 * g.aov[idx[1] * aw + q]
                                    + w2 * g.aov[idx[2] * aw + q];
                            }
                            (c, o, &interp_aov)
                        } else {
                            (cc, co, &mean_aov)
                        };
                        b.insert(s, z, g.key, sub, c, o, g.matte, aov);
                    }
                }
            }
        }
    }
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
        if cur == NONE {
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
        for &pi in &list {
            let p = &b.points[pi as usize];
            if !p.matte {
                let w = (tr[0] * p.o[0] + tr[1] * p.o[1] + tr[2] * p.o[2]) * (1.0 / 3.0);
                for q in 0..3 {
                    out[q] += tr[q] * p.c[q];
                }
                alpha += w;
                for q in 0..naov {
                    out[5 + q] += w * b.aovs[p.aov as usize + q];
                }
            }
            for q in 0..3 {
                tr[q] *= 1.0 - p.o[q];
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
