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

/// How many groups of consecutive slots to test a moving micropolygon in: about one per
/// own size (plus a pixel) of travel, so each group's bound is a few pixels long; 1 (test
/// the whole-shutter bound at once) when it hardly moves. `mb` is its whole-shutter bound.
pub fn groups(g: &ShadedGrid, corner: &[usize; 4], mb: &[f32; 4], slots: usize) -> usize {
    let p = corner.map(|c| g.xy[c]);
    let (mut w, mut h) = (0f32, 0f32);
    for a in &p {
        for b in &p {
            w = w.max(a[0] - b[0]);
            h = h.max(a[1] - b[1]);
        }
    }
    let travel = (mb[2] - mb[0] - w).max(mb[3] - mb[1] - h);
    // Under callgrind on a reduced Bug1162905, half or twice as many groups cost 4-9 %
    // more instructions: the bounds' set-up against the samples they spare.
    let n = travel / (w.max(h) + 1.0);
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
    let mo = g.motion.as_deref()?;
    let mut c = CornerBox::EMPTY;
    c.add(&ends[0].0, &ends[0].1);
    c.add(&ends[1].0, &ends[1].1);
    for (k, &tk) in mo.times.iter().enumerate() {
        if tk > t0 && tk < t1 {
            c.add(
                &corner.map(|c| mo.xy[k][c]),
                &corner.map(|c| mo.depth[k][c]),
            );
        }
    }
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
    out.iter().all(|v| v.is_finite()).then_some(out)
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
        let sq = |dx: f32, dy: f32| {
            [
                [dx, dy],
                [dx + 1.0, dy],
                [dx + 1.0, dy + 1.0],
                [dx, dy + 1.0],
            ]
        };
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
        // A fast micropolygon is split into groups, a slow one is not.
        let mb = [3.0, 2.0, 104.0, 10.0];
        assert_eq!(groups(&g, &corner, &mb, 64), 50);
        assert_eq!(groups(&g, &corner, &[3.0, 2.0, 5.0, 3.0], 64), 1);
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
