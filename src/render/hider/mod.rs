//! Hiders: visibility from shaded micropolygons to per-sample colour, opacity and depth.
//!
//! Input: the grids that may overlap a bucket (plus its filter margin), each a
//! [`GridSource`]: a conservative bound known before shading and the [`ShadedGrid`] on
//! demand. Output: a [`SampleBuffer`] for that region, channels r g b a z then the arbitrary
//! output variables.
//! Invariants: everything before hiding (bound, split, dice, shade, projection to a
//! `ShadedGrid`) is shared by all hiders; a hider's output for a sample depends only on the
//! grids covering it and on (pixel, sample, seed), never on the bucket or thread; a hider
//! leaves a grid unshaded only where shading it could not change a sample.

pub mod abuffer;
pub mod csg;
pub mod sweep;
pub mod timebins;
pub mod zbuffer;

use glam::{Mat4, Vec3, Vec4};

use crate::diag::{Diag, Diagnostics};
use crate::film::SampleBuffer;
use crate::pool;
use crate::scene::{Options, ParamType};
use crate::shade::Grid;

use super::camera::{Camera, PixelRect};
use super::dice::View;
use super::stats::Stats;

/// A named arbitrary output variable (e.g. `Display "+n.exr" "exr" "N"`) and its type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Aov {
    pub name: String,
    pub ty: ParamType,
}

impl Aov {
    pub fn new(name: impl Into<String>, ty: ParamType) -> Aov {
        Aov {
            name: name.into(),
            ty,
        }
    }
    /// Floats per sample.
    pub fn width(&self) -> usize {
        self.ty.components()
    }
    /// Film channel names: `name` for a float, `name.r/g/b` for a colour, `name.x/y/z` for a
    /// point, vector or normal, `name.0…` otherwise.
    pub fn channel_names(&self) -> Vec<String> {
        match (self.ty, self.width()) {
            (_, 1) => vec![self.name.clone()],
            (ParamType::Color, 3) => ["r", "g", "b"]
                .iter()
                .map(|c| format!("{}.{c}", self.name))
                .collect(),
            (_, 3) => ["x", "y", "z"]
                .iter()
                .map(|c| format!("{}.{c}", self.name))
                .collect(),
            (_, w) => (0..w).map(|c| format!("{}.{c}", self.name)).collect(),
        }
    }
}

/// A shaded grid projected to raster space: what every hider consumes.
///
/// Point `(i, j)` is at index `j * nu + i`; micropolygon `(i, j)` (i < nu − 1, j < nv − 1) has
/// corners `k`, `k + 1`, `k + nu`, `k + nu + 1` with `k = j * nu + i`.
#[derive(Clone, Debug, Default)]
pub struct ShadedGrid {
    /// Deterministic identity (primitive and split path): breaks depth ties.
    pub key: u64,
    pub nu: usize,
    pub nv: usize,
    /// Raster x, y per point.
    pub xy: Vec<[f32; 2]>,
    /// 1/z for perspective views, z for orthographic ones: affine in raster space on a
    /// planar micropolygon, so it interpolates linearly.
    pub depth: Vec<f32>,
    /// Ci (premultiplied by Oi, as shaders leave it) and Oi per point.
    pub ci: Vec<[f32; 3]>,
    pub oi: Vec<[f32; 3]>,
    /// `aov_width` floats per point.
    pub aov: Vec<f32>,
    pub aov_width: usize,
    /// Per micropolygon: false when culled (back-facing `Sides 1`, or behind the eye).
    pub live: Vec<bool>,
    pub matte: bool,
    /// ShadingInterpolation "smooth": Gouraud-interpolate colours over micropolygons;
    /// otherwise each micropolygon has one colour, the mean of its corners.
    pub smooth: bool,
    /// Raster rectangle (x0, y0, x1, y1) outside which this grid is never sampled: its live
    /// micropolygons' bound clipped to the bound of the surface it was diced from.
    pub bound: [f32; 4],
    /// Raster bound (x0, y0, x1, y1) of each micropolygon, and of each row of live
    /// micropolygons (empty rows are inverted): computed once per grid so that each bucket
    /// a grid overlaps skips whole rows and rejects micropolygons with four compares.
    pub mp_bounds: Vec<[f32; 4]>,
    pub row_bounds: Vec<[f32; 4]>,
    /// A lower bound of the camera depth of every point of the grid (0 when unknown): a
    /// bucket whose samples all see an opaque surface nearer than this skips the grid.
    pub zmin: f32,
    /// Motion blur: raster positions and depths at every key (None when still). With
    /// motion or depth of field, `mp_bounds`, `row_bounds` and `bound` cover every position
    /// a micropolygon takes during the shutter and over the lens.
    pub motion: Option<Box<MovingPoints>>,
    /// Set on grids of CSG primitives: the hider keeps all their hits and resolves them per
    /// sample (see [`csg`]).
    pub csg: Option<Box<CsgGrid>>,
}

/// A moving grid's points at each key over the shutter (key 0 equals `xy`/`depth`).
#[derive(Clone, Debug, Default)]
pub struct MovingPoints {
    /// Key times normalised to the shutter (first 0, last 1).
    pub times: Vec<f32>,
    pub xy: Vec<Vec<[f32; 2]>>,
    pub depth: Vec<Vec<f32>>,
}

/// A micropolygon's four corners (raster xy and depth) as a sample at `time` through lens
/// point `lens` sees them: moved linearly between the grid's motion keys, then shifted by the
/// lens offset times each corner's circle of confusion. Shared by both hiders' blur paths.
#[inline]
pub fn corners_at(
    g: &ShadedGrid,
    corner: &[usize; 4],
    time: f32,
    lens: [f32; 2],
    dof: Option<&super::camera::Dof>,
) -> ([[f32; 2]; 4], [f32; 4]) {
    let (mut p, q) = match g.motion.as_deref() {
        Some(mo) => {
            let (ki, f) = crate::scene::motion_segment(&mo.times, time);
            let (xa, xb) = (&mo.xy[ki], &mo.xy[ki + 1]);
            let (da, db) = (&mo.depth[ki], &mo.depth[ki + 1]);
            lerp_corners(
                &corner.map(|c| xa[c]),
                &corner.map(|c| xb[c]),
                &corner.map(|c| da[c]),
                &corner.map(|c| db[c]),
                f,
            )
        }
        None => (corner.map(|c| g.xy[c]), corner.map(|c| g.depth[c])),
    };
    lens_shift(&mut p, &q, lens, dof);
    (p, q)
}

/// Corners `a` moved towards `b` by `f` (0…1).
#[inline(always)]
fn lerp_corners(
    xa: &[[f32; 2]; 4],
    xb: &[[f32; 2]; 4],
    da: &[f32; 4],
    db: &[f32; 4],
    f: f32,
) -> ([[f32; 2]; 4], [f32; 4]) {
    let mut p = [[0f32; 2]; 4];
    let mut q = [0f32; 4];
    for c in 0..4 {
        let (a, e) = (xa[c], xb[c]);
        p[c] = [a[0] + (e[0] - a[0]) * f, a[1] + (e[1] - a[1]) * f];
        q[c] = da[c] + (db[c] - da[c]) * f;
    }
    (p, q)
}

/// Shifts corners `p` (depths `q`) by lens position `lens` times their circle of confusion.
#[inline(always)]
fn lens_shift(
    p: &mut [[f32; 2]; 4],
    q: &[f32; 4],
    lens: [f32; 2],
    dof: Option<&super::camera::Dof>,
) {
    if let Some(d) = dof {
        let (kx, ky) = (lens[0] * d.raster_k[0], lens[1] * d.raster_k[1]);
        for c in 0..4 {
            let f = d.inv_focus - q[c];
            p[c][0] += kx * f;
            p[c][1] += ky * f;
        }
    }
}

/// The box `[x0, y0, x1, y1]` of four corners (a NaN corner is passed over unless all are).
#[inline]
pub fn corner_box(p: &[[f32; 2]; 4]) -> [f32; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (p[0][0], p[0][1], p[0][0], p[0][1]);
    for c in &p[1..] {
        x0 = x0.min(c[0]);
        y0 = y0.min(c[1]);
        x1 = x1.max(c[0]);
        y1 = y1.max(c[1]);
    }
    [x0, y0, x1, y1]
}

/// Motion keys a [`KeyCorners`] holds on the stack.
const MAX_KEYS: usize = 4;

/// A micropolygon's corners at every motion key, gathered once for the many samples that
/// test it: [`KeyCorners::at`] is [`corners_at`] bit for bit without its lookups.
pub struct KeyCorners<'a> {
    /// The key times; empty for a still grid.
    times: &'a [f32],
    xy: [[[f32; 2]; 4]; MAX_KEYS],
    q: [[f32; 4]; MAX_KEYS],
}

impl<'a> KeyCorners<'a> {
    /// None when the grid has more keys than [`MAX_KEYS`] (use [`corners_at`]).
    #[inline]
    pub fn new(g: &'a ShadedGrid, corner: &[usize; 4]) -> Option<Self> {
        let mut k = KeyCorners {
            times: &[],
            xy: [[[0.0; 2]; 4]; MAX_KEYS],
            q: [[0.0; 4]; MAX_KEYS],
        };
        match g.motion.as_deref() {
            Some(mo) => {
                if mo.times.len() > MAX_KEYS || mo.times.len() < 2 {
                    return None;
                }
                k.times = &mo.times;
                for i in 0..mo.times.len() {
                    k.xy[i] = corner.map(|c| mo.xy[i][c]);
                    k.q[i] = corner.map(|c| mo.depth[i][c]);
                }
            }
            None => {
                k.xy[0] = corner.map(|c| g.xy[c]);
                k.q[0] = corner.map(|c| g.depth[c]);
            }
        }
        Some(k)
    }

    /// [`timebins::time_window`] from the gathered corners.
    pub fn time_window(&self, w: [f32; 4]) -> Option<(f32, f32)> {
        timebins::time_window_of(self.times, |k| self.xy[k], w)
    }

    /// The corners at `time` through `lens`, as [`corners_at`].
    #[inline]
    pub fn at(
        &self,
        time: f32,
        lens: [f32; 2],
        dof: Option<&super::camera::Dof>,
    ) -> ([[f32; 2]; 4], [f32; 4]) {
        let (mut p, q) = if self.times.is_empty() {
            (self.xy[0], self.q[0])
        } else {
            let (ki, f) = crate::scene::motion_segment(self.times, time);
            lerp_corners(
                &self.xy[ki],
                &self.xy[ki + 1],
                &self.q[ki],
                &self.q[ki + 1],
                f,
            )
        };
        lens_shift(&mut p, &q, lens, dof);
        (p, q)
    }
}

/// The raster box `[x0, y0, x1, y1]` and depth range of micropolygon corners gathered so far;
/// `finite` turns false for good at the first coordinate that is not a finite number.
#[derive(Clone, Copy)]
pub(crate) struct CornerBox {
    pub bx: [f32; 4],
    pub q_lo: f32,
    pub q_hi: f32,
    pub finite: bool,
}

impl CornerBox {
    pub const EMPTY: CornerBox = CornerBox {
        bx: [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ],
        q_lo: f32::INFINITY,
        q_hi: f32::NEG_INFINITY,
        finite: true,
    };

    /// Takes in four corners at raster `xy` with depths `q`.
    #[inline]
    pub fn add(&mut self, xy: &[[f32; 2]; 4], q: &[f32; 4]) {
        for (&[x, y], &qc) in xy.iter().zip(q) {
            self.finite &= x.is_finite() && y.is_finite() && qc.is_finite();
            let b = self.bx;
            self.bx = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
            self.q_lo = self.q_lo.min(qc);
            self.q_hi = self.q_hi.max(qc);
        }
    }
}

/// The bound of an out-of-focus (still) micropolygon as one lens position sees it: its
/// pinhole corners' bound widened by the range of lens shift × circle of confusion over its
/// corners. A sample outside it cannot be inside either triangle, so it is passed over before
/// the corners are moved (most of the blurred bound's samples are, for a circle of confusion
/// of a few pixels: the DOF example of the RenderMan Repository took 12× the pinhole time).
/// The products and sums round the way [`corners_at`]'s do and rounding is monotonic,
/// so the bound holds every moved corner and the picture is unchanged. Shared by both
/// hiders' blur paths.
/// Lens cells per axis at most (64 cells, as many as time slots).
pub const MAX_LENS_SLOTS: usize = 8;

pub struct LensBound {
    pin: [f32; 4],
    f_min: f32,
    f_max: f32,
    k: [f32; 2],
}

impl LensBound {
    /// None for a moving grid (its corners depend on the time too) or without depth of field.
    pub fn new(
        g: &ShadedGrid,
        corner: &[usize; 4],
        dof: Option<&crate::render::camera::Dof>,
    ) -> Option<Self> {
        let d = dof?;
        if g.motion.is_some() {
            return None;
        }
        Self::from_corners(corner.map(|c| g.xy[c]), corner.map(|c| g.depth[c]), d)
    }

    /// The bound of still corners at raster `xy` with depths `q` (1/z or z, as the grid
    /// holds them); None when one is not finite (no bound is then trusted).
    fn from_corners(
        xy: [[f32; 2]; 4],
        q: [f32; 4],
        d: &crate::render::camera::Dof,
    ) -> Option<Self> {
        let mut c = CornerBox::EMPTY;
        c.add(&xy, &q);
        // min/max would skip a NaN: refuse rather than bound the others only.
        if !c.finite {
            return None;
        }
        // Rounding is monotone, so `1/F − max q` is the least of the corners' `1/F − q`.
        let (f_min, f_max) = (d.inv_focus - c.q_hi, d.inv_focus - c.q_lo);
        if !(f_min.is_finite() && f_max.is_finite()) {
            return None;
        }
        let pin = c.bx;
        Some(LensBound {
            pin,
            f_min,
            f_max,
            k: d.raster_k,
        })
    }

    /// Whether the micropolygon, seen through lens point `lens`, surely misses `pos`.
    #[inline]
    pub fn misses(&self, lens: [f32; 2], pos: [f32; 2]) -> bool {
        let (kx, ky) = (lens[0] * self.k[0], lens[1] * self.k[1]);
        let (ax, bx) = (kx * self.f_min, kx * self.f_max);
        let (ay, by) = (ky * self.f_min, ky * self.f_max);
        pos[0] < self.pin[0] + ax.min(bx)
            || pos[0] > self.pin[2] + ax.max(bx)
            || pos[1] < self.pin[1] + ay.min(by)
            || pos[1] > self.pin[3] + ay.max(by)
    }

    /// The box (x0, y0, x1, y1) holding every position that [`misses`](Self::misses) keeps
    /// for a lens point in `[lx0, lx1] × [ly0, ly1]`. Exact, not padded: a product rounds
    /// monotonically in each factor, so `lens·k·f` for lens and `f` in their ranges lies
    /// between the products at the ranges' ends, and so does `pin + it`.
    pub fn box_for(&self, lx: [f32; 2], ly: [f32; 2]) -> [f32; 4] {
        let span = |l: [f32; 2], k: f32| {
            let (a, b) = (l[0] * k, l[1] * k);
            let p = [
                a * self.f_min,
                a * self.f_max,
                b * self.f_min,
                b * self.f_max,
            ];
            let lo = p.iter().fold(f32::INFINITY, |m, &v| m.min(v));
            let hi = p.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            (lo, hi)
        };
        let (x0, x1) = span(lx, self.k[0]);
        let (y0, y1) = span(ly, self.k[1]);
        [
            self.pin[0] + x0,
            self.pin[1] + y0,
            self.pin[2] + x1,
            self.pin[3] + y1,
        ]
    }

    /// How far (raster pixels, per axis) the micropolygon moves across the whole lens: the
    /// blur its bound adds to its size.
    pub fn travel(&self) -> [f32; 2] {
        let f = self.f_min.abs().max(self.f_max.abs());
        [2.0 * (self.k[0] * f).abs(), 2.0 * (self.k[1] * f).abs()]
    }

    /// The micropolygon's own size (raster pixels) through the lens centre.
    pub fn size(&self) -> f32 {
        (self.pin[2] - self.pin[0]).max(self.pin[3] - self.pin[1])
    }
}

/// Triangle `tri` (indices into a micropolygon's corners) of corners `p`/`q` made
/// counter-clockwise: its points, grid indices and depths, and its (positive) doubled area;
/// None when degenerate. Shared by both hiders' blur paths.
#[inline]
pub fn ccw_triangle(
    p: &[[f32; 2]; 4],
    q: &[f32; 4],
    corner: &[usize; 4],
    tri: [usize; 3],
) -> Option<([[f32; 2]; 3], [usize; 3], [f32; 3], f32)> {
    let mut v = tri.map(|t| p[t]);
    let mut idx = tri.map(|t| corner[t]);
    let mut dq = tri.map(|t| q[t]);
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0]);
    if area == 0.0 || !area.is_finite() {
        return None;
    }
    if area < 0.0 {
        v.swap(1, 2);
        idx.swap(1, 2);
        dq.swap(1, 2);
    }
    Some((v, idx, dq, area.abs()))
}

/// A CSG grid's place in its tree and, per micropolygon, whether a ray enters its primitive
/// solid there (the micropolygon faces the eye against the leaf's outward normal).
#[derive(Clone, Debug, Default)]
pub struct CsgGrid {
    pub leaf: u32,
    pub root: u32,
    pub entering: Vec<bool>,
}

/// Box `a` (x0, y0, x1, y1) clipped to box `b`; None when they do not meet (or a bound is
/// not a number).
#[inline]
pub fn clip_box(a: [f32; 4], b: [f32; 4]) -> Option<[f32; 4]> {
    let c = [
        a[0].max(b[0]),
        a[1].max(b[1]),
        a[2].min(b[2]),
        a[3].min(b[3]),
    ];
    (c[0] <= c[2] && c[1] <= c[3]).then_some(c)
}

/// Whether bound `b` (x0, y0, x1, y1) meets the window `[x0, x1] × [y0, y1]`.
#[inline]
pub fn overlaps(b: &[f32; 4], x0: f32, y0: f32, x1: f32, y1: f32) -> bool {
    b[0] <= x1 && b[2] >= x0 && b[1] <= y1 && b[3] >= y0
}

/// How a grid came to be, for [`ShadedGrid::new`].
#[derive(Clone, Copy, Debug)]
pub struct GridInfo {
    pub key: u64,
    pub matte: bool,
    pub smooth: bool,
    /// Sides 1: cull micropolygons facing away from the eye.
    pub one_sided: bool,
    /// +1 when Ng points along (P10 − P00) × (P01 − P00) on this grid, −1 when against
    /// (measured before displacement, see [`orientation`]).
    pub orientation: f32,
    /// Raster bound of the surface (widened by the displacement bound).
    pub clip: [f32; 4],
    /// The grid's CSG primitive solid (None outside CSG).
    pub csg: Option<csg::CsgPrim>,
}

/// The sign relating a grid's parametric orientation to its Ng: +1 when Ng agrees with the
/// cross product of the micropolygon diagonals, −1 otherwise (majority over the grid).
pub fn orientation(grid: &Grid) -> f32 {
    let (nu, nv) = (grid.nu, grid.nv);
    let mut sum = 0f32;
    for j in 0..nv.saturating_sub(1) {
        for i in 0..nu.saturating_sub(1) {
            let k = j * nu + i;
            let m = micro_normal(&grid.p, k, nu);
            let ng = grid.ng.get(k).copied().unwrap_or(Vec3::ZERO);
            sum += m.dot(ng).signum() * (m.length_squared() > 0.0) as i32 as f32;
        }
    }
    if sum < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Cross product of a micropolygon's diagonals: robust where one edge collapses (poles).
#[inline]
fn micro_normal(p: &[Vec3], k: usize, nu: usize) -> Vec3 {
    (p[k + nu + 1] - p[k]).cross(p[k + nu] - p[k + 1])
}

impl ShadedGrid {
    /// Projects a shaded grid. `aovs` names the output variables to carry (zeros where the
    /// grid has no such variable).
    ///
    /// Its per-point and per-micropolygon buffers come from this thread's buffer pool
    /// ([`pool`]) and go back to the pool of the thread that drops it: the bucket that
    /// hides it last, often on another thread, frees nothing into this thread's arena.
    pub fn new(grid: &Grid, view: &View, info: &GridInfo, aovs: &[Aov]) -> ShadedGrid {
        let (nu, nv) = (grid.nu, grid.nv);
        let n = nu * nv;
        let mut xy = pool::take(n);
        let mut depth = pool::take(n);
        let mut ok = pool::take(n);
        for p in &grid.p {
            let front = !view.perspective || p.z >= view.eye_epsilon;
            ok.push(front && p.is_finite());
            if front {
                xy.push(view.to_raster(*p));
                depth.push(if view.perspective { 1.0 / p.z } else { p.z });
            } else {
                xy.push([0.0, 0.0]);
                depth.push(0.0);
            }
        }
        // Motion blur: every key projected; a point behind the eye at any key kills its
        // micropolygons.
        let motion = grid
            .motion
            .as_ref()
            .filter(|m| {
                m.p.len() >= 2 && m.times.len() == m.p.len() && m.p.iter().all(|k| k.len() == n)
            })
            .map(|m| {
                let mut mp = MovingPoints {
                    times: m.times.clone(),
                    xy: vec![pool::copied(&xy)],
                    depth: vec![pool::copied(&depth)],
                };
                for key in &m.p[1..] {
                    let mut kx = pool::take(n);
                    let mut kd = pool::take(n);
                    for (i, p) in key.iter().enumerate() {
                        let front = !view.perspective || p.z >= view.eye_epsilon;
                        if front && p.is_finite() {
                            kx.push(view.to_raster(*p));
                            kd.push(if view.perspective { 1.0 / p.z } else { p.z });
                        } else {
                            ok[i] = false;
                            kx.push([0.0, 0.0]);
                            kd.push(0.0);
                        }
                    }
                    mp.xy.push(kx);
                    mp.depth.push(kd);
                }
                Box::new(mp)
            });
        let dof = view.dof.filter(|_| view.perspective);
        let blurred = motion.is_some() || dof.is_some();
        let c3 = |v: &Vec3| [v.x, v.y, v.z];
        let mut ci: Vec<[f32; 3]> = pool::take(n);
        ci.extend(grid.ci.iter().map(c3));
        let mut oi: Vec<[f32; 3]> = pool::take(n);
        oi.extend(grid.oi.iter().map(c3));
        let aov_width: usize = aovs.iter().map(|a| a.width()).sum();
        let mut aov = pool::filled(aov_width * n, 0f32);
        let mut off = 0;
        for a in aovs {
            fill_aov(grid, a, off, aov_width, &mut aov);
            off += a.width();
        }
        let nmp = (nu.max(1) - 1) * (nv.max(1) - 1);
        let mut live = pool::take(nmp);
        let mut mp_bounds = pool::take(nmp);
        let mut row_bounds = Vec::with_capacity(nv.saturating_sub(1));
        const EMPTY: [f32; 4] = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        let mut b = EMPTY;
        let mut entering = Vec::new();
        if info.csg.is_some() {
            entering.reserve(nmp);
        }
        for j in 0..nv.saturating_sub(1) {
            let mut rb = EMPTY;
            for i in 0..nu.saturating_sub(1) {
                let k = j * nu + i;
                let corners = [k, k + 1, k + nu, k + nu + 1];
                let mut alive = corners.iter().all(|&c| ok[c]);
                if info.csg.is_some() {
                    // Against the leaf's own outward normal (measured before any flip).
                    let m = micro_normal(&grid.p, k, nu) * info.orientation;
                    let view_dir = if view.perspective { grid.p[k] } else { Vec3::Z };
                    entering.push(m.dot(view_dir) < 0.0);
                } else if alive && info.one_sided {
                    let m = micro_normal(&grid.p, k, nu) * info.orientation;
                    let view_dir = if view.perspective { grid.p[k] } else { Vec3::Z };
                    // Facing the eye when Ng points against the viewing direction.
                    alive = m.dot(view_dir) < 0.0;
                }
                let mut mb = EMPTY;
                if alive && blurred {
                    // Every key, each corner widened by its circle of confusion.
                    let nkeys = motion.as_ref().map_or(1, |m| m.xy.len());
                    for &c in &corners {
                        for key in 0..nkeys {
                            let (p, q) = match &motion {
                                Some(m) => (m.xy[key][c], m.depth[key][c]),
                                None => (xy[c], depth[c]),
                            };
                            let (rx, ry) = match &dof {
                                Some(d) => {
                                    let f = (d.inv_focus - q).abs();
                                    (d.raster_k[0].abs() * f, d.raster_k[1].abs() * f)
                                }
                                None => (0.0, 0.0),
                            };
                            mb[0] = mb[0].min(p[0] - rx);
                            mb[1] = mb[1].min(p[1] - ry);
                            mb[2] = mb[2].max(p[0] + rx);
                            mb[3] = mb[3].max(p[1] + ry);
                        }
                    }
                    for q in 0..2 {
                        rb[q] = rb[q].min(mb[q]);
                        rb[q + 2] = rb[q + 2].max(mb[q + 2]);
                    }
                } else if alive {
                    for &c in &corners {
                        mb[0] = mb[0].min(xy[c][0]);
                        mb[1] = mb[1].min(xy[c][1]);
                        mb[2] = mb[2].max(xy[c][0]);
                        mb[3] = mb[3].max(xy[c][1]);
                    }
                    for q in 0..2 {
                        rb[q] = rb[q].min(mb[q]);
                        rb[q + 2] = rb[q + 2].max(mb[q + 2]);
                    }
                }
                mp_bounds.push(mb);
                live.push(alive);
            }
            for q in 0..2 {
                b[q] = b[q].min(rb[q]);
                b[q + 2] = b[q + 2].max(rb[q + 2]);
            }
            row_bounds.push(rb);
        }
        // Nearest depth over the points in front of the eye (perspective depth is 1/z), over
        // every key of a moving grid.
        let all_depths: Vec<&[f32]> = match &motion {
            Some(m) => m.depth.iter().map(Vec::as_slice).collect(),
            None => vec![&depth],
        };
        let zmin = if view.perspective {
            let q = all_depths
                .iter()
                .flat_map(|d| d.iter().zip(&ok))
                .filter(|(_, &o)| o)
                .fold(0f32, |m, (&d, _)| m.max(d));
            if q > 0.0 {
                1.0 / q
            } else {
                0.0
            }
        } else {
            all_depths
                .iter()
                .flat_map(|d| d.iter().zip(&ok))
                .filter(|(_, &o)| o)
                .fold(f32::INFINITY, |m, (&d, _)| m.min(d))
        };
        // Interpolation may round a hair outside the corners' range: keep a margin.
        let zmin = if zmin.is_finite() {
            zmin - zmin.abs() * 1e-5
        } else {
            0.0
        };
        pool::give(ok);
        let bound = [
            b[0].max(info.clip[0]),
            b[1].max(info.clip[1]),
            b[2].min(info.clip[2]),
            b[3].min(info.clip[3]),
        ];
        ShadedGrid {
            key: info.key,
            nu,
            nv,
            xy,
            depth,
            ci,
            oi,
            aov,
            aov_width,
            live,
            matte: info.matte,
            smooth: info.smooth,
            bound,
            mp_bounds,
            row_bounds,
            zmin,
            motion,
            csg: info.csg.map(|c| {
                Box::new(CsgGrid {
                    leaf: c.leaf,
                    root: c.root,
                    entering,
                })
            }),
        }
    }

    /// Where this grid is sampled in bucket `rect`: the region clipped by the grid's bound
    /// as (x0, y0, x1, y1), or None when they do not meet. Closed: a pixel's samples lie in
    /// [p, p + 1], the right end included (jitter can round up to it), so a grid whose bound
    /// starts exactly at the bucket's right edge can still cover a sample of the bucket.
    pub fn window(&self, rect: &PixelRect) -> Option<[f32; 4]> {
        let w = [
            (rect.x0 as f32).max(self.bound[0]),
            (rect.y0 as f32).max(self.bound[1]),
            (rect.x1 as f32).min(self.bound[2]),
            (rect.y1 as f32).min(self.bound[3]),
        ];
        (w[0] <= w[2] && w[1] <= w[3]).then_some(w)
    }

    /// The live micropolygons whose raster bound meets window `w`, as (micropolygon index,
    /// index of its first corner point, bound), into `out` (cleared first). Rows whose bound
    /// misses the window are skipped whole.
    pub fn micropolygons_in(&self, w: [f32; 4], out: &mut Vec<(usize, usize, [f32; 4])>) {
        out.clear();
        let [x0, y0, x1, y1] = w;
        let cols = self.nu.saturating_sub(1);
        for (j, rb) in self.row_bounds.iter().enumerate() {
            if !overlaps(rb, x0, y0, x1, y1) {
                continue;
            }
            for i in 0..cols {
                let m = j * cols + i;
                let mb = self.mp_bounds[m];
                if self.live[m] && overlaps(&mb, x0, y0, x1, y1) {
                    out.push((m, j * self.nu + i, mb));
                }
            }
        }
    }

    pub fn is_empty(&self) -> bool {
        !(self.bound[0] <= self.bound[2] && self.bound[1] <= self.bound[3])
    }

    /// Approximate heap size, for the peak-memory statistic.
    pub fn bytes(&self) -> usize {
        self.xy.len() * (8 + 4 + 24)
            + self.aov.len() * 4
            + self.live.len()
            + self
                .motion
                .as_ref()
                .map_or(0, |m| m.xy.len() * self.xy.len() * 12)
    }
}

impl Drop for ShadedGrid {
    /// The buffers go to the dropping thread's pool (see [`ShadedGrid::new`]).
    fn drop(&mut self) {
        use std::mem::take;
        pool::give(take(&mut self.xy));
        pool::give(take(&mut self.depth));
        pool::give(take(&mut self.ci));
        pool::give(take(&mut self.oi));
        pool::give(take(&mut self.aov));
        pool::give(take(&mut self.live));
        pool::give(take(&mut self.mp_bounds));
        if let Some(m) = self.motion.take() {
            let m = *m;
            m.xy.into_iter().for_each(pool::give);
            m.depth.into_iter().for_each(pool::give);
        }
    }
}

/// Copies output variable `a` of every grid point into `out` at float offset `off`.
fn fill_aov(grid: &Grid, a: &Aov, off: usize, stride: usize, out: &mut [f32]) {
    let n = grid.len();
    let vec3 = |v: &[Vec3], out: &mut [f32]| {
        for (k, x) in v.iter().enumerate().take(n) {
            for c in 0..a.width().min(3) {
                out[k * stride + off + c] = x[c];
            }
        }
    };
    let float = |v: &[f32], out: &mut [f32]| {
        for (k, x) in v.iter().enumerate().take(n) {
            out[k * stride + off] = *x;
        }
    };
    let var = grid
        .output(&a.name)
        .or_else(|| grid.primvar(&a.name))
        .filter(|v| v.ty != ParamType::String);
    if let Some(v) = var {
        let w = v.width().min(a.width());
        for k in 0..n {
            let src = if v.uniform { 0 } else { k * v.width() };
            for c in 0..w {
                if let Some(x) = v.floats.get(src + c) {
                    out[k * stride + off + c] = *x;
                }
            }
        }
        return;
    }
    match a.name.as_str() {
        "Ci" => vec3(&grid.ci, out),
        "Oi" => vec3(&grid.oi, out),
        "Cs" => vec3(&grid.cs, out),
        "Os" => vec3(&grid.os, out),
        "P" => vec3(&grid.p, out),
        "N" => vec3(&grid.n, out),
        "Ng" => vec3(&grid.ng, out),
        "I" => vec3(&grid.i, out),
        "dPdu" => vec3(&grid.dpdu, out),
        "dPdv" => vec3(&grid.dpdv, out),
        "s" => float(&grid.s, out),
        "t" => float(&grid.t, out),
        "u" => float(&grid.u, out),
        "v" => float(&grid.v, out),
        _ => {}
    }
}

/// How a pixel's depth is combined from its samples' depths (`Hider "hidden" "depthfilter"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthFilter {
    Min,
    Max,
    Average,
    /// Per sample, halfway between the nearest and the second-nearest opaque surfaces; the
    /// pixel then takes the minimum.
    Midpoint,
}

/// Everything a hider needs from the options and camera.
#[derive(Clone, Debug)]
pub struct HiderConfig {
    /// PixelSamples, rounded, at least 1.
    pub spp: [usize; 2],
    pub jitter: bool,
    pub seed: u64,
    /// Accumulated opacity at which compositing stops (`Option "limits" "othreshold"`).
    pub othreshold: f32,
    /// Opacity at which a surface counts as opaque for depth (`Option "limits" "zthreshold"`).
    pub zthreshold: f32,
    pub depth_filter: DepthFilter,
    pub aovs: Vec<Aov>,
    pub perspective: bool,
    pub near: f32,
    pub far: f32,
    /// ClippingPlanes in camera space as (n, d): points with n·p + d > 0 are clipped.
    pub clip_planes: Vec<Vec4>,
    pub camera_from_raster: Mat4,
    /// The thin lens (DepthOfField), None for a pinhole.
    pub dof: Option<super::camera::Dof>,
    /// The scene's CSG trees (empty without boolean solids).
    pub csg: std::sync::Arc<csg::CsgTree>,
    /// Time slots the Z-buffer bins a bucket's samples into when a grid moves
    /// (`Hider "hidden" "timeslots" n`; by default 64, the most; a micropolygon is tested in fewer groups of them by [`timebins::groups`]). 1
    /// tests every sample under a micropolygon's whole-shutter bound: the same picture,
    /// slower.
    pub time_slots: usize,
    /// Lens cells per axis the Z-buffer bins a bucket's samples into under depth of field
    /// (`Hider "hidden" "lensslots" n`; by default about the square root of the samples per
    /// pixel, at most 8). 1 tests every sample under a micropolygon's whole-lens bound.
    pub lens_slots: usize,
}

impl HiderConfig {
    /// Floats per sample: r g b a z then the output variables.
    pub fn channels(&self) -> usize {
        5 + self.aovs.iter().map(|a| a.width()).sum::<usize>()
    }

    pub fn from_options(
        options: &Options,
        camera: &Camera,
        aovs: &[Aov],
        seed: u64,
        diags: &Diagnostics,
    ) -> HiderConfig {
        let ps = options.pixel_samples;
        let spp = [
            ps[0].round().clamp(1.0, 64.0) as usize,
            ps[1].round().clamp(1.0, 64.0) as usize,
        ];
        let params = &options.hider.params;
        let jitter = params.float("jitter") != Some(0.0);
        let depth_filter = match params.string("depthfilter") {
            None | Some("min") => DepthFilter::Min,
            Some("max") => DepthFilter::Max,
            Some("average") => DepthFilter::Average,
            Some("midpoint") => DepthFilter::Midpoint,
            Some(other) => {
                let mut d = Diag::warning(
                    "render::hider",
                    format!("unknown depthfilter \"{other}\"; using \"min\""),
                )
                .help("depthfilter is one of \"min\", \"max\", \"average\", \"midpoint\"");
                if let Some(p) = params.get("depthfilter") {
                    d = d.label(p.span, "this depth filter");
                }
                diags.report(d);
                DepthFilter::Min
            }
        };
        let threshold = |key: &str| {
            options
                .user_floats(key)
                .filter(|f| !f.is_empty())
                .map(|f| {
                    f.iter()
                        .take(3)
                        .fold(f32::INFINITY, |a, &b| a.min(b))
                        .clamp(0.0, 1.0)
                })
                .unwrap_or(0.996)
        };
        let normal_from_world = camera.camera_from_world.inverse().transpose();
        let clip_planes = options
            .clipping_planes
            .iter()
            .map(|&(p, n)| {
                let pc = camera.camera_from_world.transform_point3(p);
                let nc = normal_from_world.transform_vector3(n).normalize_or_zero();
                nc.extend(-nc.dot(pc))
            })
            .collect();
        HiderConfig {
            spp,
            jitter,
            seed,
            othreshold: threshold("limits:othreshold"),
            zthreshold: threshold("limits:zthreshold"),
            depth_filter,
            aovs: aovs.to_vec(),
            perspective: camera.perspective,
            near: camera.near,
            far: camera.far,
            clip_planes,
            camera_from_raster: camera.raster_from_camera().inverse(),
            dof: camera.dof,
            csg: Default::default(),
            time_slots: params
                .float("timeslots")
                .map_or(timebins::MAX_SLOTS, |n| n.max(1.0) as usize)
                .clamp(1, timebins::MAX_SLOTS),
            lens_slots: params
                .float("lensslots")
                .map_or(((spp[0] * spp[1]) as f32).sqrt().round() as usize, |n| {
                    n.max(1.0) as usize
                })
                .clamp(1, MAX_LENS_SLOTS),
        }
    }

    /// A camera-space point from a raster position and its camera depth.
    #[inline]
    pub fn camera_point(&self, x: f32, y: f32, z: f32) -> Vec3 {
        if self.perspective {
            // The raster → camera map sends (x, y, z_s) on the ray; rescale to depth z.
            let p = self.camera_from_raster.project_point3(Vec3::new(x, y, 0.5));
            if p.z != 0.0 {
                p * (z / p.z)
            } else {
                p
            }
        } else {
            let p = self
                .camera_from_raster
                .transform_point3(Vec3::new(x, y, 0.0));
            Vec3::new(p.x, p.y, z)
        }
    }
}

/// A grid as hiders receive it: what is known before its surface is shaded, and the shaded
/// grid on demand (shaded once, by the first bucket that asks; later askers wait for it). A
/// hider that can tell from the bound alone that a grid changes no sample of its bucket
/// (outside it, or behind every opaque sample) need not ask, and the grid may never be
/// shaded at all.
pub trait GridSource: Sync {
    /// The grid's identity ([`ShadedGrid::key`]).
    fn key(&self) -> u64;
    /// A lower bound of the shaded grid's [`ShadedGrid::zmin`].
    fn zmin(&self) -> f32;
    /// A raster rectangle (x0, y0, x1, y1) containing the shaded grid's
    /// [`ShadedGrid::bound`].
    fn bound(&self) -> [f32; 4];
    /// Whether the shaded grid may have motion keys.
    fn moving(&self) -> bool;
    /// The shaded grid, shading it on the first call; None when nothing of it is left to hide.
    fn shaded(&self) -> Option<&ShadedGrid>;
}

/// An already shaded grid is its own source.
impl GridSource for ShadedGrid {
    fn key(&self) -> u64 {
        self.key
    }
    fn zmin(&self) -> f32 {
        self.zmin
    }
    fn bound(&self) -> [f32; 4] {
        self.bound
    }
    fn moving(&self) -> bool {
        self.motion.is_some()
    }
    fn shaded(&self) -> Option<&ShadedGrid> {
        (!self.is_empty()).then_some(self)
    }
}

/// Whether a source's bound can meet the samples of `rect` (see [`ShadedGrid::window`]).
pub fn may_meet(g: &dyn GridSource, rect: &PixelRect) -> bool {
    let b = g.bound();
    overlaps(
        &b,
        rect.x0 as f32,
        rect.y0 as f32,
        rect.x1 as f32,
        rect.y1 as f32,
    )
}

/// Shades every source meeting `rect` (hiders that cannot cull by the bound).
pub fn shade_all<'g>(grids: &[&'g dyn GridSource], rect: &PixelRect) -> Vec<&'g ShadedGrid> {
    grids
        .iter()
        .filter(|g| may_meet(**g, rect))
        .filter_map(|g| g.shaded())
        .collect()
}

/// A visibility algorithm: from the grids overlapping `rect` to its samples.
pub trait Hider: Sync {
    /// Samples `grids` in the pixels of `rect` (a bucket plus its filter margin).
    fn hide(&self, rect: PixelRect, grids: &[&dyn GridSource], stats: &Stats) -> SampleBuffer;
    /// [`Hider::hide`] straight into the gather filter's form, when the hider can: the same
    /// as `gather::prepare(&self.hide(…), ctx)`. None when it cannot (the caller then hides
    /// and prepares).
    fn hide_prepared(
        &self,
        _rect: PixelRect,
        _grids: &[&dyn GridSource],
        _stats: &Stats,
        _ctx: &crate::film::gather::PrepareCtx,
    ) -> Option<crate::film::gather::Prepared> {
        None
    }
    fn config(&self) -> &HiderConfig;
    /// Samples per pixel of the buffers [`Hider::hide`] returns.
    fn samples_per_pixel(&self) -> usize {
        self.config().spp[0] * self.config().spp[1]
    }
    /// Called once after a frame's last bucket: reports what the buckets could not (they run
    /// in parallel without diagnostics), e.g. a resource bound that was hit.
    fn finish(&self, _diags: &Diagnostics) {}
}

/// `Hider "null"`: no samples are ever covered.
pub struct NullHider(pub HiderConfig);

impl Hider for NullHider {
    fn hide(&self, rect: PixelRect, grids: &[&dyn GridSource], _stats: &Stats) -> SampleBuffer {
        // Shaded all the same: shaders may have effects beyond the picture (bake3d, printf).
        shade_all(grids, &rect);
        zbuffer::empty_buffer(&self.0, rect)
    }
    fn config(&self) -> &HiderConfig {
        &self.0
    }
}

/// The hider named by `Hider` (hidden by default). Unknown or unimplemented hiders warn and
/// fall back to "hidden".
pub fn make_hider(options: &Options, config: HiderConfig, diags: &Diagnostics) -> Box<dyn Hider> {
    match options.hider.name.as_str() {
        "hidden" | "" => Box::new(zbuffer::ZBuffer::new(config)),
        "null" => Box::new(NullHider(config)),
        "abuffer" => Box::new(abuffer::ABuffer::new(config, &options.hider.params, diags)),
        other => {
            diags.report(
                Diag::warning(
                    "render::hider",
                    format!("Hider \"{other}\" is not implemented; using \"hidden\""),
                )
                .help("the implemented hiders are \"hidden\" (stochastic Z-buffer), \"abuffer\" and \"null\""),
            );
            Box::new(zbuffer::ZBuffer::new(config))
        }
    }
}

#[cfg(test)]
mod lens_bound_tests {
    use super::*;
    use crate::render::camera::Dof;

    #[test]
    fn every_moved_corner_lies_in_the_lens_bound() {
        // Corners as `corners_at` moves them must never be rejected: the bound is exact under
        // float rounding, for either sign of lens position and of 1/F − q.
        let d = Dof {
            inv_focus: 1.0 / 7.3,
            raster_k: [41.7, -39.3],
            screen_k: [0.0, 0.0],
        };
        let mut seed = 12345u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..2000 {
            let xy = [0; 4].map(|_| [rnd() * 64.0 - 8.0, rnd() * 64.0 - 8.0]);
            let q = [0; 4].map(|_| 1.0 / (0.5 + rnd() * 20.0));
            let lb = LensBound::from_corners(xy, q, &d).unwrap();
            for _ in 0..8 {
                let lens = [rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0];
                let (kx, ky) = (lens[0] * d.raster_k[0], lens[1] * d.raster_k[1]);
                for c in 0..4 {
                    let f = d.inv_focus - q[c];
                    let p = [xy[c][0] + kx * f, xy[c][1] + ky * f];
                    assert!(!lb.misses(lens, p), "{xy:?} {q:?} {lens:?} corner {c}");
                }
                // A point well outside the moved corners is rejected.
                let far = [xy[0][0] + 1.0e4, xy[0][1]];
                assert!(lb.misses(lens, far));
            }
        }
        // A lens cell group's box holds every position `misses` keeps for a lens point in
        // the group's range: its ends and points between, corners and the keep region's edge.
        for _ in 0..2000 {
            let xy = [0; 4].map(|_| [rnd() * 64.0 - 8.0, rnd() * 64.0 - 8.0]);
            let q = [0; 4].map(|_| 1.0 / (0.5 + rnd() * 20.0));
            let lb = LensBound::from_corners(xy, q, &d).unwrap();
            let (a, b, c, e) = (
                rnd() * 2.0 - 1.0,
                rnd() * 2.0 - 1.0,
                rnd() * 2.0 - 1.0,
                rnd() * 2.0 - 1.0,
            );
            let (lx, ly) = ([a.min(b), a.max(b)], [c.min(e), c.max(e)]);
            let bx = lb.box_for(lx, ly);
            for i in 0..=6 {
                let lens = [
                    lx[0] + (lx[1] - lx[0]) * i as f32 / 6.0,
                    ly[1] - (ly[1] - ly[0]) * ((i * 5) % 7) as f32 / 6.0,
                ];
                let lens = [lens[0].clamp(lx[0], lx[1]), lens[1].clamp(ly[0], ly[1])];
                let (kx, ky) = (lens[0] * d.raster_k[0], lens[1] * d.raster_k[1]);
                let keep_x = [
                    lb.pin[0] + (kx * lb.f_min).min(kx * lb.f_max),
                    lb.pin[2] + (kx * lb.f_min).max(kx * lb.f_max),
                ];
                let keep_y = [
                    lb.pin[1] + (ky * lb.f_min).min(ky * lb.f_max),
                    lb.pin[3] + (ky * lb.f_min).max(ky * lb.f_max),
                ];
                for p in [
                    [keep_x[0], keep_y[0]],
                    [keep_x[1], keep_y[1]],
                    [keep_x[0], keep_y[1]],
                ] {
                    assert!(!lb.misses(lens, p));
                    assert!(
                        p[0] >= bx[0] && p[0] <= bx[2] && p[1] >= bx[1] && p[1] <= bx[3],
                        "{p:?} outside {bx:?} for lens {lens:?}"
                    );
                }
            }
        }
        let nan = [[0.0, 0.0], [1.0, 0.0], [f32::NAN, 1.0], [0.0, 1.0]];
        assert!(LensBound::from_corners(nan, [0.2; 4], &d).is_none());
    }
}

#[cfg(test)]
mod pool_tests {
    use super::*;

    #[test]
    fn a_shaded_grid_let_go_on_another_thread_leaves_its_buffers_there() {
        let mut g = ShadedGrid::default();
        g.xy = pool::filled(300, [0.0, 0.0]);
        g.ci = pool::filled(300, [0.0; 3]);
        g.mp_bounds = pool::filled(250, [0.0; 4]);
        g.live = pool::filled(250, true);
        let here = pool::pooled_count::<[f32; 2]>();
        let there = std::thread::spawn(move || {
            drop(g);
            (
                pool::pooled_count::<[f32; 2]>(),
                pool::pooled_count::<[f32; 3]>(),
                pool::pooled_count::<[f32; 4]>(),
                pool::pooled_count::<bool>(),
            )
        })
        .join()
        .unwrap();
        assert_eq!(there, (1, 1, 1, 1));
        assert_eq!(pool::pooled_count::<[f32; 2]>(), here);
    }
}
