//! Time slots for motion blur: a bucket's samples binned by shutter time, and the raster
//! bound a moving micropolygon sweeps over one slot's times.
//!
//! Input: each sample's time (0…1), position and pixel. Output: per (pixel, slot) the samples
//! whose time falls in the slot, with their positions, and per slot the least and greatest
//! time of its samples in this bucket.
//! Invariants: every sample is in exactly one slot; a slot's time interval is that of the
//! samples it holds (not a nominal one), so a bound over the interval holds every position
//! any of its samples can see. Binning only chooses which samples are tested against a
//! micropolygon, never the order in which one sample meets its micropolygons, so the
//! picture cannot change.
//!
//! Why: a micropolygon sweeping D pixels during the shutter has a blurred bound D pixels
//! long, but at any one time it covers only its own size. Tested slot by slot, against the
//! bound of the times of that slot, a fast micropolygon meets about 1/slots of the samples
//! under its whole-shutter bound (Bug1162905 of the Aqsis suite, a camera pan of 240
//! pixels, tested ~300 M samples for ~1 M hits).

use crate::render::camera::Dof;

use super::sweep::{self, Sweep};
use super::{corners_at, CornerBox, ShadedGrid};

/// Slots per bucket: one per sample of a pixel up to this many, so a pixel usually holds one
/// sample per slot (its times are stratified).
pub const MAX_SLOTS: usize = 64;

/// A bucket's samples binned by (pixel, time slot).
#[derive(Default)]
pub struct TimeBins {
    slots: usize,
    /// `start[p·slots + k] .. start[p·slots + k + 1]` index the samples of pixel p in slot k.
    start: Vec<u32>,
    /// Per binned sample: its index in the bucket and its position.
    sample: Vec<u32>,
    x: Vec<f32>,
    y: Vec<f32>,
    /// Per slot: least and greatest of each value of its samples (∞, −∞ when empty): the
    /// time twice for time slots, a lens position's x and y for lens cells.
    lo: Vec<[f32; 2]>,
    hi: Vec<[f32; 2]>,
    count: Vec<u32>,
    /// Per sample: its cell (pixel · slots + slot), kept between the two passes.
    cell: Vec<u32>,
    /// Time bins only (empty for keyed ones): per slot the first slot at or after it that
    /// holds samples (`slots` when none), and one past the last at or before it (0: none).
    next: Vec<u32>,
    prev: Vec<u32>,
    /// Some time is not a number: no interval is trusted.
    nan: bool,
}

impl TimeBins {
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// Bins samples `0..times.len()` (times in [0, 1]) of a bucket of `pixels` pixels into
    /// `slots` slots; `pixel_of(s)` is sample s's pixel, `x`/`y` its position.
    pub fn build(
        &mut self,
        slots: usize,
        pixels: usize,
        times: &[f32],
        x: &[f32],
        y: &[f32],
        pixel_of: impl Fn(usize) -> usize,
    ) {
        let slots = slots.max(1);
        // NaN and negative times go to slot 0, times ≥ 1 to the last: any slot is
        // correct, as the slot's interval is measured from its samples.
        let slot_of = |s: usize| ((times[s] * slots as f32) as usize).min(slots - 1);
        self.build_keyed(
            slots,
            pixels,
            times.len(),
            slot_of,
            |s| [times[s]; 2],
            x,
            y,
            pixel_of,
        );
        // Slots are monotonic in time (a later slot's times are never earlier), so the
        // interval of a run of slots is its first full slot's least time and its last's
        // greatest: O(1) with each slot's nearest full slots either way.
        self.next.clear();
        self.next.resize(slots + 1, slots as u32);
        self.prev.clear();
        self.prev.resize(slots, 0);
        let full = |k: usize| self.lo[k][0] <= self.hi[k][0];
        for k in (0..slots).rev() {
            self.next[k] = if full(k) { k as u32 } else { self.next[k + 1] };
        }
        let mut last = 0;
        for k in 0..slots {
            if full(k) {
                last = k as u32 + 1;
            }
            self.prev[k] = last;
        }
    }

    /// The slot times `t` go to (as [`TimeBins::build`] bins them): monotonic in `t`.
    pub fn slot_of_time(&self, t: f32) -> usize {
        let slots = self.slots.max(1);
        if t.is_nan() {
            return 0;
        }
        ((t * slots as f32) as usize).min(slots - 1)
    }

    /// Bins samples `0..n` into `slots` slots by `slot_of(s)`, keeping per slot the least and
    /// greatest of each of the two numbers `value(s)` of its samples (a time twice, or a lens
    /// position's x and y).
    #[allow(clippy::too_many_arguments)]
    pub fn build_keyed(
        &mut self,
        slots: usize,
        pixels: usize,
        n: usize,
        slot_of: impl Fn(usize) -> usize,
        value: impl Fn(usize) -> [f32; 2],
        x: &[f32],
        y: &[f32],
        pixel_of: impl Fn(usize) -> usize,
    ) {
        self.slots = slots;
        self.nan = false;
        self.next.clear();
        self.prev.clear();
        let cells = pixels * slots;
        self.count.clear();
        self.count.resize(cells + 1, 0);
        self.lo.clear();
        self.lo.resize(slots, [f32::INFINITY; 2]);
        self.hi.clear();
        self.hi.resize(slots, [f32::NEG_INFINITY; 2]);
        self.cell.clear();
        for s in 0..n {
            let k = slot_of(s);
            let c = pixel_of(s) * slots + k;
            self.cell.push(c as u32);
            self.count[c + 1] += 1;
            // min/max would pass over a NaN: one poisons every interval, and the caller
            // then falls back to the whole bound.
            for (a, v) in value(s).into_iter().enumerate() {
                self.nan |= v.is_nan();
                self.lo[k][a] = self.lo[k][a].min(v);
                self.hi[k][a] = self.hi[k][a].max(v);
            }
        }
        for c in 0..cells {
            self.count[c + 1] += self.count[c];
        }
        self.start.clear();
        self.start.extend_from_slice(&self.count);
        self.sample.clear();
        self.sample.resize(n, 0);
        self.x.clear();
        self.x.resize(n, 0.0);
        self.y.clear();
        self.y.resize(n, 0.0);
        for s in 0..n {
            let c = self.cell[s] as usize;
            let at = self.count[c] as usize;
            self.count[c] += 1;
            self.sample[at] = s as u32;
            self.x[at] = x[s];
            self.y[at] = y[s];
        }
    }

    /// Whether slot intervals can be trusted (every time is a number); when not, test the
    /// whole-shutter bound.
    pub fn trusted(&self) -> bool {
        !self.nan
    }

    /// The time interval of slots `k0..=k1`: the least and greatest time of their samples
    /// (None when they hold none).
    pub fn interval(&self, k0: usize, k1: usize) -> Option<(f32, f32)> {
        if self.next.len() == self.slots + 1 {
            let a = self.next[k0] as usize;
            if a > k1 {
                return None;
            }
            let b = self.prev[k1] as usize - 1;
            return Some((self.lo[a][0], self.hi[b][0]));
        }
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for k in k0..=k1 {
            lo = lo.min(self.lo[k][0]);
            hi = hi.max(self.hi[k][0]);
        }
        (lo <= hi).then_some((lo, hi))
    }

    /// The range of both values over slots `k0..=k1`: `[lo, hi]` per value (None when they
    /// hold no sample).
    pub fn ranges(&self, k0: usize, k1: usize) -> Option<[[f32; 2]; 2]> {
        let mut r = [[f32::INFINITY, f32::NEG_INFINITY]; 2];
        for k in k0..=k1 {
            for a in 0..2 {
                r[a][0] = r[a][0].min(self.lo[k][a]);
                r[a][1] = r[a][1].max(self.hi[k][a]);
            }
        }
        (r[0][0] <= r[0][1]).then_some(r)
    }

    /// Calls `f(sample index, position)` for every sample of pixel `p` in slots `k0..=k1`.
    #[inline]
    pub fn each(&self, p: usize, k0: usize, k1: usize, mut f: impl FnMut(usize, [f32; 2])) {
        let (a, b) = (
            self.start[p * self.slots + k0] as usize,
            self.start[p * self.slots + k1 + 1] as usize,
        );
        for i in a..b {
            f(self.sample[i] as usize, [self.x[i], self.y[i]]);
        }
    }
}

/// How many groups of consecutive slots to test a moving micropolygon in; 1 (test the
/// whole-shutter bound at once) when it hardly moves. `mb` is its whole-shutter bound, `spp`
/// the samples per pixel.
///
/// A micropolygon of size S travelling T pixels, in G groups, is tested against about
/// spp·(S + 1)·(T/G + S) samples and costs G bounds: the sum is least at
/// G = √(c·spp·(S + 1)·T), c the cost of a sample test over that of a group's bound (about
/// 0.3 under callgrind). G is also at most one group per its size plus a pixel of travel
/// (shorter groups only repeat the same pixels) and at most the slots.
pub fn groups(
    g: &ShadedGrid,
    corner: &[usize; 4],
    mb: &[f32; 4],
    slots: usize,
    spp: usize,
) -> usize {
    let [x0, y0, x1, y1] = super::corner_box(&corner.map(|c| g.xy[c]));
    let (w, h) = (x1 - x0, y1 - y0);
    let travel = (mb[2] - mb[0] - w).max(mb[3] - mb[1] - h);
    let size = w.max(h);
    let n = (travel / (size + 1.0)).min((0.3 * spp as f32 * (size + 1.0) * travel).sqrt());
    if !(n >= 2.0) {
        return 1;
    }
    (n as usize).min(slots)
}

/// A micropolygon's corners (raster positions, depths) at one time, without lens shift.
pub type Corners = ([[f32; 2]; 4], [f32; 4]);

/// [`corners_at`] at time `t` through the lens centre.
#[inline]
pub fn corners(g: &ShadedGrid, corner: &[usize; 4], t: f32) -> Corners {
    corners_at(g, corner, t, [0.0, 0.0], None)
}

/// The raster bound (x0, y0, x1, y1) of micropolygon `corner` of moving grid `g` at every
/// time in [t0, t1], through every lens position when `dof` is set; None for a still grid or
/// when a position is not finite.
pub fn motion_bound(
    g: &ShadedGrid,
    corner: &[usize; 4],
    t0: f32,
    t1: f32,
    dof: Option<&Dof>,
) -> Option<[f32; 4]> {
    let ends = [corners(g, corner, t0), corners(g, corner, t1)];
    bound_between(g, corner, &ends, t0, t1, dof)
}

/// [`motion_bound`] given the corners at t0 and t1 (`ends`, from [`corners`]), so that
/// consecutive intervals share their evaluations.
///
/// Between keys a corner moves as [`corners_at`] computes it, `a + (b − a)·f` with f rising
/// with the time: monotonic in the time even as rounded, so over a segment it lies between
/// its values at the ends. The bound takes the corners at t0, t1 and at every key between,
/// and is padded (0.01 pixel plus 1e-5 of the coordinates' size) for the hair by which a
/// segment's end can round past its key, and for the lens shift's rounding.
pub fn bound_between(
    g: &ShadedGrid,
    corner: &[usize; 4],
    ends: &[Corners; 2],
    t0: f32,
    t1: f32,
    dof: Option<&Dof>,
) -> Option<[f32; 4]> {
    bound_and_pad(g, corner, ends, t0, t1, dof).map(|(bx, _)| bx)
}

/// [`bound_between`] and the pad it was grown by on each axis.
pub fn bound_and_pad(
    g: &ShadedGrid,
    corner: &[usize; 4],
    ends: &[Corners; 2],
    t0: f32,
    t1: f32,
    dof: Option<&Dof>,
) -> Option<([f32; 4], [f32; 2])> {
    let mut c = CornerBox::EMPTY;
    each_position(g, corner, ends, t0, t1, |xy, q| c.add(xy, q))?;
    if !c.finite {
        return None;
    }
    let (bx, q_lo, q_hi) = (c.bx, c.q_lo, c.q_hi);
    let size = bx.iter().fold(0f32, |m, v| m.max(v.abs()));
    let pad = 0.01 + size * 1e-5;
    let (mut rx, mut ry) = (pad, pad);
    if let Some(d) = dof {
        // |lens| ≤ 1 on either axis: the shift is at most |k|·max|1/F − q|.
        let f = (d.inv_focus - q_lo).abs().max((d.inv_focus - q_hi).abs());
        rx += d.raster_k[0].abs() * f * (1.0 + 1e-5);
        ry += d.raster_k[1].abs() * f * (1.0 + 1e-5);
    }
    let out = [bx[0] - rx, bx[1] - ry, bx[2] + rx, bx[3] + ry];
    out.iter().all(|v| v.is_finite()).then_some((out, [rx, ry]))
}

/// The region micropolygon `corner` sweeps over [t0, t1] (`ends` its corners there), grown
/// by `pad` (from [`bound_and_pad`]); None when too many keys lie between.
pub fn sweep_between(
    g: &ShadedGrid,
    corner: &[usize; 4],
    ends: &[Corners; 2],
    t0: f32,
    t1: f32,
    pad: [f32; 2],
) -> Option<Sweep> {
    let mut pts = [[0f32; 2]; sweep::MAX_POINTS];
    let mut n = 0;
    each_position(g, corner, ends, t0, t1, |xy, _| {
        for p in xy {
            if n < pts.len() {
                pts[n] = *p;
            }
            n += 1;
        }
    })?;
    (n <= pts.len())
        .then(|| Sweep::new(&pts[..n], pad[0], pad[1]))
        .flatten()
}

/// The shutter times (a conservative interval `(ta, tb)`) at which micropolygon `corner` can
/// meet window `w` (raster box; through the lens centre), or None when it never does.
///
/// Between two keys each corner moves as `a + (b − a)·f`, so the micropolygon's box at `f`
/// lies within the same mix of its boxes at the keys: per axis its low and high edges are
/// linear in `f`, and the box meets the window on one interval of `f` per segment. The window
/// is grown by a pixel (and the positions' size · 10⁻⁴) and the interval by 10⁻⁴ of the
/// segment, far beyond the rounding of the positions and of a sample's `f`.
pub fn time_window(g: &ShadedGrid, corner: &[usize; 4], w: [f32; 4]) -> Option<(f32, f32)> {
    match g.motion.as_deref() {
        Some(mo) => time_window_of(&mo.times, |k| corner.map(|c| mo.xy[k][c]), w),
        None => Some((f32::NEG_INFINITY, f32::INFINITY)),
    }
}

/// [`time_window`] of a micropolygon whose corners at key k (of `times`) are `key_xy(k)`.
pub fn time_window_of(
    times: &[f32],
    key_xy: impl Fn(usize) -> [[f32; 2]; 4],
    w: [f32; 4],
) -> Option<(f32, f32)> {
    const ALWAYS: Option<(f32, f32)> = Some((f32::NEG_INFINITY, f32::INFINITY));
    let keys = times.len();
    let boxes = |k: usize| {
        let mut c = CornerBox::EMPTY;
        c.add(&key_xy(k), &[0.0; 4]);
        c
    };
    let (mut ta, mut tb) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut a = boxes(0);
    for k in 0..keys.saturating_sub(1) {
        let b = boxes(k + 1);
        if !(a.finite && b.finite) {
            return ALWAYS;
        }
        let size = a.bx.iter().chain(&b.bx).fold(0f32, |m, v| m.max(v.abs()));
        let m = 1.0 + size as f64 * 1e-4;
        // f in [lo, hi] where lo(f) ≤ w1 + m and hi(f) ≥ w0 − m on both axes.
        let (mut f0, mut f1) = (0f64, 1f64);
        for axis in 0..2 {
            let (la, lb) = (a.bx[axis] as f64, b.bx[axis] as f64);
            let (ha, hb) = (a.bx[axis + 2] as f64, b.bx[axis + 2] as f64);
            let (w0, w1) = (w[axis] as f64 - m, w[axis + 2] as f64 + m);
            // la + (lb − la)·f ≤ w1, and ha + (hb − ha)·f ≥ w0, i.e. −ha − (hb − ha)·f ≤ −w0.
            for (alpha, beta, gamma) in [(la, lb - la, w1), (-ha, ha - hb, -w0)] {
                if beta > 0.0 {
                    f1 = f1.min((gamma - alpha) / beta);
                } else if beta < 0.0 {
                    f0 = f0.max((gamma - alpha) / beta);
                } else if alpha > gamma {
                    f1 = -1.0;
                }
            }
        }
        let (f0, f1) = (f0 - 1e-4, f1 + 1e-4);
        if f0 <= f1 && f1 >= 0.0 && f0 <= 1.0 {
            let (t0, t1) = (times[k] as f64, times[k + 1] as f64);
            // Times before the first key are the first key's; after the last, the last's.
            let lo = if k == 0 && f0 <= 0.0 {
                f64::NEG_INFINITY
            } else {
                t0 + (t1 - t0) * f0.max(0.0) - 1e-4 * (t1 - t0)
            };
            let hi = if k + 2 == keys && f1 >= 1.0 {
                f64::INFINITY
            } else {
                t0 + (t1 - t0) * f1.min(1.0) + 1e-4 * (t1 - t0)
            };
            ta = ta.min(lo);
            tb = tb.max(hi);
        }
        a = b;
    }
    if keys < 2 {
        return ALWAYS;
    }
    (ta <= tb).then_some((ta as f32, tb as f32))
}

/// The most a lens position can shift micropolygon `corner` on each axis over the whole
/// shutter (the pad of its whole-shutter bound); `[0, 0]` without a lens, None when the pad
/// cannot be had (a position not finite).
pub fn lens_pad(g: &ShadedGrid, corner: &[usize; 4], dof: Option<&Dof>) -> Option<[f32; 2]> {
    if dof.is_none() {
        return Some([0.0, 0.0]);
    }
    let ends = [corners(g, corner, 0.0), corners(g, corner, 1.0)];
    bound_and_pad(g, corner, &ends, 0.0, 1.0, dof).map(|(_, pad)| pad)
}

/// Window `w` grown by the [`lens_pad`] `pad`, for a time window through any lens position;
/// None (test all times) when there is no pad.
pub fn grown_by_lens(w: [f32; 4], pad: Option<[f32; 2]>) -> Option<[f32; 4]> {
    pad.map(|[rx, ry]| [w[0] - rx, w[1] - ry, w[2] + rx, w[3] + ry])
}

/// Calls `f` with the corners (raster positions, depths) at both ends and at every motion
/// key strictly between them: between those each corner moves on a straight segment. None
/// for a still grid.
fn each_position(
    g: &ShadedGrid,
    corner: &[usize; 4],
    ends: &[Corners; 2],
    t0: f32,
    t1: f32,
    mut f: impl FnMut(&[[f32; 2]; 4], &[f32; 4]),
) -> Option<()> {
    let mo = g.motion.as_deref()?;
    f(&ends[0].0, &ends[0].1);
    f(&ends[1].0, &ends[1].1);
    for (k, &tk) in mo.times.iter().enumerate() {
        if tk > t0 && tk < t1 {
            f(
                &corner.map(|c| mo.xy[k][c]),
                &corner.map(|c| mo.depth[k][c]),
            );
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::hider::MovingPoints;

    /// A 2 × 2 grid (one micropolygon) with the given corner positions at each key.
    fn grid(times: &[f32], keys: &[[[f32; 2]; 4]]) -> ShadedGrid {
        let xy: Vec<Vec<[f32; 2]>> = keys.iter().map(|k| k.to_vec()).collect();
        let depth = vec![vec![0.2f32; 4]; keys.len()];
        // (Field by field: a shaded grid's drop gives its buffers back, so no `..Default`.)
        let mut g = ShadedGrid::default();
        g.nu = 2;
        g.nv = 2;
        g.xy = xy[0].clone();
        g.depth = depth[0].clone();
        g.motion = Some(Box::new(MovingPoints {
            times: times.to_vec(),
            xy,
            depth,
        }));
        g
    }

    /// A unit square's corners at (dx, dy).
    fn sq(dx: f32, dy: f32) -> [[f32; 2]; 4] {
        [
            [dx, dy],
            [dx + 1.0, dy],
            [dx + 1.0, dy + 1.0],
            [dx, dy + 1.0],
        ]
    }

    #[test]
    fn the_time_window_holds_every_time_a_micropolygon_meets_the_window() {
        // Right 100 pixels and down 50 over the shutter.
        let g = grid(&[0.0, 1.0], &[sq(0.0, 0.0), sq(100.0, 50.0)]);
        let c = [0, 1, 3, 2];
        let (ta, tb) = time_window(&g, &c, [40.0, 0.0, 41.0, 100.0]).unwrap();
        // It is over x 40..41 from t = 0.39 to 0.41; a pixel's margin each way.
        assert!(ta <= 0.39 && ta > 0.37, "{ta}");
        assert!(tb >= 0.41 && tb < 0.43, "{tb}");
        // Every time at which a corner is in the window lies in the interval.
        for i in 0..=1000 {
            let t = i as f32 / 1000.0;
            let (p, _) = corners(&g, &c, t);
            let inside = p.iter().any(|q| (40.0..=41.0).contains(&q[0]));
            assert!(!inside || (ta <= t && t <= tb), "{t}");
        }
        // A window it never reaches; one below its path.
        assert_eq!(time_window(&g, &c, [200.0, 0.0, 210.0, 10.0]), None);
        assert_eq!(time_window(&g, &c, [0.0, 30.0, 10.0, 40.0]), None);
        // Still at the first key: times before it are the first key's.
        let (ta, _) = time_window(&g, &c, [0.0, 0.0, 2.0, 2.0]).unwrap();
        assert_eq!(ta, f32::NEG_INFINITY);
        // Out and back over two segments: the hull of both visits.
        let g = grid(
            &[0.0, 0.5, 1.0],
            &[sq(0.0, 0.0), sq(100.0, 0.0), sq(0.0, 0.0)],
        );
        let (ta, tb) = time_window(&g, &c, [50.0, 0.0, 51.0, 1.0]).unwrap();
        assert!(ta <= 0.245 && tb >= 0.755 && tb < 0.8, "{ta} {tb}");
    }

    #[test]
    fn bins_hold_every_sample_once_with_its_slot_interval() {
        let times: Vec<f32> = (0..40).map(|i| ((i * 37) % 40) as f32 / 40.0).collect();
        let x: Vec<f32> = (0..40).map(|i| i as f32).collect();
        let mut tb = TimeBins::default();
        tb.build(8, 4, &times, &x, &x, |s| s % 4);
        let mut seen = vec![0; 40];
        for p in 0..4 {
            for k in 0..8 {
                tb.each(p, k, k, |s, pos| {
                    seen[s] += 1;
                    assert_eq!(s % 4, p);
                    assert_eq!(pos, [s as f32, s as f32]);
                    assert_eq!((times[s] * 8.0) as usize, k);
                    let (lo, hi) = tb.interval(k, k).unwrap();
                    assert!(lo <= times[s] && times[s] <= hi);
                });
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        // Slot 0 holds times 0, 1/40 … 4/40.
        assert_eq!(tb.interval(0, 0), Some((0.0, 4.0 / 40.0)));
        assert_eq!(tb.interval(0, 7), Some((0.0, 39.0 / 40.0)));
    }

    #[test]
    fn the_slot_bound_holds_every_position_of_its_times() {
        // A unit square sliding 100 pixels right and 7 down, then back 30 (two segments).
        let g = grid(
            &[0.0, 0.6, 1.0],
            &[sq(3.0, 2.0), sq(103.0, 9.0), sq(73.0, 9.0)],
        );
        let corner = [0, 1, 3, 2];
        for (t0, t1) in [(0.0, 0.1), (0.55, 0.65), (0.9, 1.0), (0.3, 0.3)] {
            let b = motion_bound(&g, &corner, t0, t1, None).unwrap();
            for i in 0..=200 {
                let t = t0 + (t1 - t0) * i as f32 / 200.0;
                let (p, _) = corners_at(&g, &corner, t, [0.0, 0.0], None);
                for c in p {
                    assert!(c[0] >= b[0] && c[0] <= b[2] && c[1] >= b[1] && c[1] <= b[3]);
                }
            }
            // Tight: a tenth of the shutter on the first segment spans 100/6 pixels + 1.
            if (t0, t1) == (0.0, 0.1) {
                assert!((b[2] - b[0] - (1.0 + 100.0 / 6.0)).abs() < 0.05, "{b:?}");
            }
        }
        // The key at 0.6 lies inside (0.55, 0.65): the bound reaches x = 104.
        let b = motion_bound(&g, &corner, 0.55, 0.65, None).unwrap();
        assert!(b[2] >= 104.0 && b[2] < 104.1, "{b:?}");
        // A fast micropolygon is split into groups (one per 2 pixels of its 100 at 64
        // samples a pixel; √(0.3 · 1 · 2 · 100) at one, where each group holds few
        // samples), a slow one is not.
        let mb = [3.0, 2.0, 104.0, 10.0];
        assert_eq!(groups(&g, &corner, &mb, 64, 64), 50);
        assert_eq!(groups(&g, &corner, &mb, 64, 1), 7);
        assert_eq!(groups(&g, &corner, &mb, 16, 64), 16);
        assert_eq!(groups(&g, &corner, &[3.0, 2.0, 5.0, 3.0], 64, 64), 1);
    }

    #[test]
    fn random_motions_stay_in_their_bounds_through_any_lens() {
        // Many keys at uneven times, corners far from the origin (large rounding), depths
        // on both sides of the focal plane: every corner at every sampled time and lens
        // position lies in the bound of any interval holding that time.
        let mut seed = 99u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let d = Dof {
            inv_focus: 1.0 / 4.0,
            raster_k: [37.0, -29.0],
            screen_k: [0.0, 0.0],
        };
        for _ in 0..300 {
            let nk = 2 + (rnd() * 4.0) as usize;
            let mut times: Vec<f32> = (0..nk).map(|k| k as f32 / (nk - 1) as f32).collect();
            for t in times[1..nk - 1].iter_mut() {
                *t += (rnd() - 0.5) * 0.5 / nk as f32;
            }
            let base = [rnd() * 4000.0 - 2000.0, rnd() * 4000.0 - 2000.0];
            let keys: Vec<[[f32; 2]; 4]> = (0..nk)
                .map(|_| [0; 4].map(|_| [base[0] + rnd() * 300.0, base[1] + rnd() * 300.0]))
                .collect();
            let mut g = grid(&times, &keys);
            if let Some(mo) = g.motion.as_deref_mut() {
                for k in mo.depth.iter_mut() {
                    k.iter_mut().for_each(|q| *q = 1.0 / (0.5 + rnd() * 10.0));
                }
            }
            let corner = [0, 1, 3, 2];
            let (a, b) = (rnd(), rnd());
            let (t0, t1) = (a.min(b), a.max(b));
            for dof in [None, Some(&d)] {
                let bx = motion_bound(&g, &corner, t0, t1, dof).unwrap();
                for i in 0..=40 {
                    let t = t0 + (t1 - t0) * i as f32 / 40.0;
                    let t = t.clamp(t0, t1);
                    let lens = [rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0];
                    let lens = if dof.is_some() { lens } else { [0.0; 2] };
                    let (p, _) = corners_at(&g, &corner, t, lens, dof);
                    for c in p {
                        assert!(
                            c[0] >= bx[0] && c[0] <= bx[2] && c[1] >= bx[1] && c[1] <= bx[3],
                            "{c:?} outside {bx:?} at t = {t} in [{t0}, {t1}]"
                        );
                    }
                }
            }
        }
    }
}
