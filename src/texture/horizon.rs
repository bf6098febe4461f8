//! Horizon mapping (N. Max, "Horizon mapping: shadows for bump-mapped surfaces"; notes
//! shading.md §4): shadows cast by bumps on their own surface.
//!
//! Input: a periodic height map F(s,t) (values in map units; the map spans the unit (s,t)
//! patch, so a texel is 1/W by 1/H). Output: a [`HorizonTable`] holding, for every texel and
//! each of 8 or 16 azimuths, `tan(horizon elevation)` = max over points ahead of
//! `(F(q) − F(p)) / |q − p|`, clamped at 0. Storing the tangent (not the angle) makes a run-time
//! bump scale exact: scaling every height by k scales every tangent by k.
//!
//! Build: per direction, the texels fall into wrap-around orbits `p, p+d, p+2d, …`; each orbit is
//! a periodic height profile, swept once from far to near over two periods while a stack keeps
//! the upper convex hull of the points ahead (O(texels) per direction). Directions are integer
//! texel steps (rows, columns, diagonals, and the (2,1) knight steps for 16), so every texel
//! lies exactly on its line; knight steps also sample the interpolated midpoints between
//! texels. Their true (s,t) azimuths are stored, so the θ interpolation stays exact for
//! non-square maps.
//!
//! Besides the tangent, each entry keeps the *reach*: the (s,t) distance to the profile point
//! that sets that horizon (0 when nothing rises above the texel).
//!
//! Lookup: the light is moved into the standard patch's frame by `C⁻¹` (C's columns are
//! dP/ds, dP/dt and n̂·|dP/ds × dP/dt|^{1/2}, Max §5) and its elevation compared with the
//! horizon towards its azimuth θ; the visible fraction is Max's disc-sun penumbra function.
//! Max interpolates the horizon linearly in θ between the two nearest tabulated directions
//! ([`HorizonTable::elevation_interpolated`]). That is exact for long ridges but not for
//! isolated bumps: seen from a point in a bump's shadow, the bump spans a few degrees, so the
//! rays 45° apart on either side of the light miss it, and the shadow splits into two faint
//! copies along the tabulated directions (shadow-mask IoU 0.4–0.6 against ray-marched truth
//! between directions). [`HorizonTable::elevation`] instead uses the two neighbouring
//! directions' tables to *find* the occluders on the light's ray: a shadow cast along θ_k is
//! the shadow along θ rotated about its occluder, so the texel q = p + D(û_θ − û_k) whose θ_k
//! ray crosses p's θ ray at distance D names (by its reach) where an occluder lies; the true
//! height is sampled there on p's own ray. D runs over a doubling sequence and is refined by
//! a fixed-point step (D ← where q's occluder projects). Every sample is a point of the height
//! field on the light ray, so the estimate never exceeds the true horizon (no false shadows);
//! on tabulated directions it reduces to the table. The curvature correction of Max §6 lowers
//! (convex) or raises (concave) the horizon by γ = √(2h/R) ([`curvature_drop`]).
//!
//! File format (`.hzn`, little-endian): magic `b"ARBHZN2\0"`, u32 width, u32 height,
//! u32 ndirs, u32 flags (bit 0: periodic, always set), ndirs × f32 azimuth (radians, in
//! [0, 2π), increasing), W·H f32 heights (row-major, row = t), W·H·ndirs f32 tangents
//! (texel-major: the ndirs tangents of one texel are contiguous), W·H·ndirs f32 reaches (same
//! order). Version-1 files (`ARBHZN1`, no reaches) are rebuilt from their heights on reading.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use glam::{Mat3, Vec3};

const MAGIC: &[u8; 8] = b"ARBHZN2\0";
const MAGIC_V1: &[u8; 8] = b"ARBHZN1\0";

/// Integer texel steps of the 8 tabulated directions (E, NE, N, NW, W, SW, S, SE).
pub const DIRS8: [(i32, i32); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// The 16-direction set: the 8 above plus the knight steps between them.
pub const DIRS16: [(i32, i32); 16] = [
    (1, 0),
    (2, 1),
    (1, 1),
    (1, 2),
    (0, 1),
    (-1, 2),
    (-1, 1),
    (-2, 1),
    (-1, 0),
    (-2, -1),
    (-1, -1),
    (-1, -2),
    (0, -1),
    (1, -2),
    (1, -1),
    (2, -1),
];

/// Horizon tables of one height map (see the module header).
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonTable {
    pub width: usize,
    pub height: usize,
    /// Azimuth of each direction in the (s,t) plane, radians in [0, 2π), increasing.
    pub azimuths: Vec<f32>,
    /// Height per texel, row-major (row index follows t).
    pub heights: Vec<f32>,
    /// tan(horizon elevation) per texel and direction: `tans[texel * ndirs + k]`, ≥ 0.
    pub tans: Vec<f32>,
    /// (s,t) distance from the texel centre to the profile point that sets `tans` (same
    /// order); 0 where the horizon is flat (tan 0).
    pub reach: Vec<f32>,
    /// The largest height (bounds how far an occluder can matter).
    pub max_height: f32,
}

/// Direction steps for a direction count (8 or 16).
pub fn directions(n: usize) -> Option<&'static [(i32, i32)]> {
    match n {
        8 => Some(&DIRS8),
        16 => Some(&DIRS16),
        _ => None,
    }
}

impl HorizonTable {
    /// Builds the tables of a periodic `w`×`h` height map for 8 or 16 directions.
    pub fn build(heights: &[f32], w: usize, h: usize, ndirs: usize) -> Result<Self, String> {
        let dirs = directions(ndirs)
            .ok_or_else(|| format!("horizon maps have 8 or 16 directions, not {ndirs}"))?;
        if w == 0 || h == 0 || heights.len() != w * h {
            return Err(format!(
                "height map of {w}x{h} texels needs {} values, got {}",
                w * h,
                heights.len()
            ));
        }
        if heights.iter().any(|v| !v.is_finite()) {
            return Err("height map holds a non-finite value".into());
        }
        let mut tans = vec![0f32; w * h * ndirs];
        let mut reach = vec![0f32; w * h * ndirs];
        let mut sweep = Sweep::default();
        for (k, &(a, b)) in dirs.iter().enumerate() {
            sweep.direction(heights, w, h, a, b, |texel, tan, dist| {
                if tan > 0.0 {
                    tans[texel * ndirs + k] = tan;
                    reach[texel * ndirs + k] = dist;
                }
            });
        }
        let azimuths = dirs
            .iter()
            .map(|&(a, b)| {
                let az = (b as f32 / h as f32).atan2(a as f32 / w as f32);
                az.rem_euclid(std::f32::consts::TAU)
            })
            .collect();
        Ok(HorizonTable {
            width: w,
            height: h,
            azimuths,
            heights: heights.to_vec(),
            tans,
            reach,
            max_height: heights.iter().copied().fold(f32::MIN, f32::max),
        })
    }

    pub fn ndirs(&self) -> usize {
        self.azimuths.len()
    }

    /// The stored tangent of texel (x, y) (wrapped) in direction k.
    #[inline]
    pub fn tan_at(&self, x: i64, y: i64, k: usize) -> f32 {
        let (w, h) = (self.width as i64, self.height as i64);
        let i = (y.rem_euclid(h) * w + x.rem_euclid(w)) as usize;
        self.tans[i * self.ndirs() + k]
    }

    /// Bilinear weights and the four wrapped texel indices around (s, t).
    #[inline]
    fn corners(&self, s: f32, t: f32) -> ([usize; 4], [f32; 4]) {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = if s.is_finite() { s } else { 0.0 } * self.width as f32 - 0.5;
        let y = if t.is_finite() { t } else { 0.0 } * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (xi, yi) = (x0 as i64, y0 as i64);
        let ix =
            |dx: i64, dy: i64| ((yi + dy).rem_euclid(h) * w + (xi + dx).rem_euclid(w)) as usize;
        (
            [ix(0, 0), ix(1, 0), ix(0, 1), ix(1, 1)],
            [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ],
        )
    }

    /// Height at (s, t), bilinear with periodic wrap (texel centres at (i+½)/W).
    pub fn height_at(&self, s: f32, t: f32) -> f32 {
        let (ix, wt) = self.corners(s, t);
        (0..4).map(|c| self.heights[ix[c]] * wt[c]).sum()
    }

    /// The tabulated directions around azimuth `theta`: (k0, k1, f) with θ at fraction f of
    /// the way from azimuth k0 to k1 (wrapping past 2π).
    fn bracket(&self, theta: f32) -> (usize, usize, f32) {
        let nd = self.ndirs();
        let th = if theta.is_finite() {
            theta.rem_euclid(std::f32::consts::TAU)
        } else {
            0.0
        };
        // k0: last azimuth ≤ θ (wrapping below the first one to the last).
        let mut k0 = nd - 1;
        for (k, &a) in self.azimuths.iter().enumerate() {
            if a <= th {
                k0 = k;
            }
        }
        let k1 = (k0 + 1) % nd;
        let (a0, mut a1) = (self.azimuths[k0], self.azimuths[k1]);
        let mut x = th;
        if a1 <= a0 {
            a1 += std::f32::consts::TAU;
        }
        if x < a0 {
            x += std::f32::consts::TAU;
        }
        (k0, k1, ((x - a0) / (a1 - a0)).clamp(0.0, 1.0))
    }

    /// Max's lookup (§2): horizon elevation (radians) at (s, t) towards azimuth `theta`
    /// (radians, from +s towards +t) for heights multiplied by `scale`, bilinear in (s,t) per
    /// direction, then linear in azimuth between the two nearest tabulated directions. Exact
    /// on tabulated directions and for long ridges; isolated bumps between directions are
    /// missed (see the module header), so rendering uses [`HorizonTable::elevation`].
    pub fn elevation_interpolated(&self, s: f32, t: f32, theta: f32, scale: f32) -> f32 {
        let nd = self.ndirs();
        let (k0, k1, f) = self.bracket(theta);
        let (ix, wt) = self.corners(s, t);
        let (mut t0, mut t1) = (0.0, 0.0);
        for c in 0..4 {
            t0 += self.tans[ix[c] * nd + k0] * wt[c];
            t1 += self.tans[ix[c] * nd + k1] * wt[c];
        }
        let sc = scale.max(0.0);
        (1.0 - f) * (sc * t0).atan() + f * (sc * t1).atan()
    }

    /// Horizon elevation (radians) at (s, t) towards azimuth `theta` for heights multiplied
    /// by `scale`: the occluder search of the module header. Never above the true horizon of
    /// the (bilinear) height field; equal to the table on tabulated directions.
    pub fn elevation(&self, s: f32, t: f32, theta: f32, scale: f32) -> f32 {
        (scale.max(0.0) * self.horizon_tan(s, t, theta, 0.0, f32::INFINITY)).atan()
    }

    /// tan(horizon elevation) of the unscaled map at (s, t) towards `theta` (see
    /// [`HorizonTable::elevation`]). The caller only needs the answer between `need` and
    /// `stop`: it returns as soon as it reaches `stop` (the light is hidden), and ignores
    /// occluders too far away to rise to slope `need` (the light is seen above them).
    pub fn horizon_tan(&self, s: f32, t: f32, theta: f32, need: f32, stop: f32) -> f32 {
        let (s, t) = (
            if s.is_finite() { s } else { 0.0 },
            if t.is_finite() { t } else { 0.0 },
        );
        let theta = if theta.is_finite() { theta } else { 0.0 };
        let nd = self.ndirs();
        let (k0, k1, f) = self.bracket(theta);
        let (w, h) = (self.width as f32, self.height as f32);
        let (wi, hi) = (self.width as i64, self.height as i64);
        // One texel: the search's length unit.
        let unit = 1.0 / w.min(h);
        let u = (theta.cos(), theta.sin());
        let zp = self.height_at(s, t);
        // Nothing farther than this rises to slope `need` above p.
        let reach_max = if need > 0.0 {
            ((self.max_height - zp) / need).min(2.0)
        } else {
            2.0
        };
        let mut best = 0f32;
        let mut best_along = 0f32;
        // Height on p's own ray at distance `along`: the only thing ever compared.
        let sample = |along: f32, best: &mut f32, best_along: &mut f32| {
            if along > 0.1 * unit {
                let z = self.height_at(s + along * u.0, t + along * u.1);
                let slope = (z - zp) / along;
                if slope > *best {
                    *best = slope;
                    *best_along = along;
                }
            }
        };
        let ks: &[usize] = if f < 1e-6 {
            &[k0]
        } else if f > 1.0 - 1e-6 {
            &[k1]
        } else {
            &[k0, k1]
        };
        for &k in ks {
            let a = self.azimuths[k];
            let uk = (a.cos(), a.sin());
            let dl = (u.0 - uk.0, u.1 - uk.1);
            let spread = (dl.0 * dl.0 + dl.1 * dl.1).sqrt();
            // Candidates closer than half a texel to p all name p's own texel: start there.
            let mut d_start = 0.0f32;
            while d_start <= reach_max {
                let mut d = d_start;
                for _ in 0..3 {
                    let (qx, qy) = ((s + d * dl.0) * w, (t + d * dl.1) * h);
                    let (cx, cy) = (qx.floor(), qy.floor());
                    let i = ((cy as i64).rem_euclid(hi) * wi + (cx as i64).rem_euclid(wi)) as usize;
                    let r = self.reach[i * nd + k];
                    if r <= 0.0 {
                        break;
                    }
                    // The occluder q's θ_k ray meets, projected onto p's θ ray.
                    let (ox, oy) = ((cx + 0.5) / w + r * uk.0, (cy + 0.5) / h + r * uk.1);
                    let along = (ox - s) * u.0 + (oy - t) * u.1;
                    if along <= 0.0 || along > reach_max + unit {
                        break;
                    }
                    sample(along, &mut best, &mut best_along);
                    if best >= stop {
                        return best;
                    }
                    if (along - d).abs() < 0.5 * unit {
                        break;
                    }
                    d = along;
                }
                d_start = if d_start == 0.0 {
                    if spread * 2.0 < 1.0 {
                        unit.max(0.5 * unit / spread.max(1e-6))
                    } else {
                        unit
                    }
                } else {
                    d_start * 2.0
                };
            }
        }
        // The candidate rays cross p's near, not at, the occluder's crest: look around it.
        if best_along > 0.0 {
            let a0 = best_along;
            for dd in [-1.0f32, -0.5, 0.5, 1.0] {
                sample(a0 + dd * unit, &mut best, &mut best_along);
            }
        }
        best
    }

    /// Serialises to the `.hzn` format (module header).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            24 + 4 * (self.heights.len() + self.tans.len() + self.reach.len() + 16),
        );
        out.extend_from_slice(MAGIC);
        for v in [self.width, self.height, self.ndirs(), 1] {
            out.extend_from_slice(&(v as u32).to_le_bytes());
        }
        for v in self
            .azimuths
            .iter()
            .chain(&self.heights)
            .chain(&self.tans)
            .chain(&self.reach)
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Parses the `.hzn` format, checking sizes and values.
    pub fn from_bytes(b: &[u8]) -> Result<Self, String> {
        let v1 = b.len() >= 8 && &b[..8] == MAGIC_V1;
        if b.len() < 24 || (&b[..8] != MAGIC && !v1) {
            return Err("not an arbor horizon table (bad magic)".into());
        }
        let u = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as usize;
        let (w, h, nd) = (u(8), u(12), u(16));
        if w == 0 || h == 0 || directions(nd).is_none() {
            return Err(format!(
                "bad horizon table header ({w}x{h}, {nd} directions)"
            ));
        }
        let per_texel = if v1 { nd + 1 } else { 2 * nd + 1 };
        let n = w
            .checked_mul(h)
            .and_then(|t| t.checked_mul(per_texel))
            .and_then(|t| t.checked_add(nd))
            .ok_or("horizon table too large")?;
        if b.len() != 24 + 4 * n {
            return Err(format!(
                "horizon table truncated: {} bytes, expected {}",
                b.len(),
                24 + 4 * n
            ));
        }
        let f: Vec<f32> = b[24..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        if f.iter().any(|v| !v.is_finite()) {
            return Err("horizon table holds a non-finite value".into());
        }
        let heights = &f[nd..nd + w * h];
        if v1 {
            // No reaches stored: rebuild (fast) from the heights it carries.
            return Self::build(heights, w, h, nd);
        }
        let tans_end = nd + w * h * (nd + 1);
        Ok(HorizonTable {
            width: w,
            height: h,
            azimuths: f[..nd].to_vec(),
            heights: heights.to_vec(),
            tans: f[nd + w * h..tans_end].to_vec(),
            reach: f[tans_end..].to_vec(),
            max_height: heights.iter().copied().fold(f32::MIN, f32::max),
        })
    }

    pub fn write(&self, path: &Path) -> Result<(), String> {
        std::fs::write(path, self.to_bytes()).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn read(path: &Path) -> Result<Self, String> {
        let b = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::from_bytes(&b).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// Reusable buffers of the per-orbit hull sweep.
#[derive(Default)]
struct Sweep {
    z: Vec<f32>,
    texel: Vec<u32>,
    stack: Vec<u32>,
    visited: Vec<bool>,
}

impl Sweep {
    /// Calls `emit(texel, tan, dist)` once per texel with the max slope ahead along step
    /// (a, b) and the (s,t) distance to the point that has it.
    fn direction(
        &mut self,
        f: &[f32],
        w: usize,
        h: usize,
        a: i32,
        b: i32,
        mut emit: impl FnMut(usize, f32, f32),
    ) {
        // Knight steps sample the midpoint between texels too (sub = 2 samples per step).
        let sub = if a.abs() > 1 || b.abs() > 1 { 2 } else { 1 };
        let (dx, dy) = (a as f32 / w as f32, b as f32 / h as f32);
        let ds = (dx * dx + dy * dy).sqrt() / sub as f32;
        let (wi, hi) = (w as i64, h as i64);
        let at = |x: i64, y: i64| f[(y.rem_euclid(hi) * wi + x.rem_euclid(wi)) as usize];
        // Midpoint of a step as the mean of the two texels straddling it.
        let (ha0, ha1) = (
            (a as f32 / 2.0).floor() as i64,
            (a as f32 / 2.0).ceil() as i64,
        );
        let (hb0, hb1) = (
            (b as f32 / 2.0).floor() as i64,
            (b as f32 / 2.0).ceil() as i64,
        );
        self.visited.clear();
        self.visited.resize(w * h, false);
        for start in 0..w * h {
            if self.visited[start] {
                continue;
            }
            // Collect the orbit start, start+d, … until it wraps back.
            self.z.clear();
            self.texel.clear();
            let (mut x, mut y) = ((start % w) as i64, (start / w) as i64);
            loop {
                let i = (y * wi + x) as usize;
                if self.visited[i] {
                    break;
                }
                self.visited[i] = true;
                self.texel.push(i as u32);
                self.z.push(f[i]);
                if sub == 2 {
                    self.z
                        .push(0.5 * (at(x + ha0, y + hb0) + at(x + ha1, y + hb1)));
                }
                x = (x + a as i64).rem_euclid(wi);
                y = (y + b as i64).rem_euclid(hi);
            }
            let m = self.z.len();
            // Two periods: every point of the first sees the whole orbit ahead of it.
            self.stack.clear();
            for j in (0..2 * m).rev() {
                let zj = self.z[j % m];
                let xj = j as f32 * ds;
                let slope = |q: u32| (self.z[q as usize % m] - zj) / (q as f32 * ds - xj);
                while self.stack.len() >= 2 {
                    let top = self.stack[self.stack.len() - 1];
                    let sec = self.stack[self.stack.len() - 2];
                    if slope(top) <= slope(sec) {
                        self.stack.pop();
                    } else {
                        break;
                    }
                }
                if j < m && j % sub == 0 {
                    let (tan, dist) = self
                        .stack
                        .last()
                        .map_or((0.0, 0.0), |&q| (slope(q), (q as usize - j) as f32 * ds));
                    emit(self.texel[j / sub] as usize, tan, dist);
                }
                self.stack.push(j as u32);
            }
        }
    }
}

/// Max's visible fraction of a disc light whose centre is `alpha` half-diameters above the
/// horizon (§4.7): 0 below −1, 1 above 1, `½ + (asin α + α√(1−α²))/π` between.
pub fn penumbra_fraction(alpha: f32) -> f32 {
    if alpha.is_nan() {
        return 0.0;
    }
    if alpha <= -1.0 {
        0.0
    } else if alpha >= 1.0 {
        1.0
    } else {
        0.5 + (alpha.asin() + alpha * (1.0 - alpha * alpha).sqrt()) / std::f32::consts::PI
    }
}

/// Light direction on the standard patch: `C⁻¹ L` with C's columns `ps` (dP/ds), `pt`
/// (dP/dt) and `n̂·|ps × pt|^{1/2}`, n̂ the unit normal on the side `up` points to (the bumps
/// stand on that side). None when the frame is degenerate.
pub fn standard_light(ps: Vec3, pt: Vec3, up: Vec3, l: Vec3) -> Option<Vec3> {
    let n = ps.cross(pt);
    let len = n.length();
    if !(len > 1e-20) || !l.is_finite() {
        return None;
    }
    let side = if n.dot(up) < 0.0 { -1.0 } else { 1.0 };
    let c = Mat3::from_cols(ps, pt, n * (side / len.sqrt()));
    let det = c.determinant();
    if !det.is_finite() || det.abs() < 1e-30 {
        return None;
    }
    let r = c.inverse() * l;
    r.is_finite().then_some(r)
}

/// Visible fraction of the light along `lp` (a standard-patch direction) at (s, t).
/// `penumbra` is the light's angular diameter (radians; 0: a hard test `elevation ≥ horizon`).
pub fn visibility(
    table: &HorizonTable,
    s: f32,
    t: f32,
    lp: Vec3,
    scale: f32,
    penumbra: f32,
) -> f32 {
    visibility_curved(table, s, t, lp, scale, penumbra, 0.0, 1.0)
}

/// [`visibility`] on a real surface, comparing angles in the surface's own vertical plane
/// through the light: `rho` converts standard-patch slopes to the surface's (`tan α_surface =
/// rho · tan α_standard` along the light's azimuth, see [`grid_visibility`]), so the
/// penumbra (the light's angular diameter) and Max's §6 curvature correction — the horizon
/// lowered by `drop` radians (γ of [`curvature_drop`]; negative on concave surfaces raises
/// it) — are true angles.
#[allow(clippy::too_many_arguments)]
pub fn visibility_curved(
    table: &HorizonTable,
    s: f32,
    t: f32,
    lp: Vec3,
    scale: f32,
    penumbra: f32,
    drop: f32,
    rho: f32,
) -> f32 {
    use std::f32::consts::FRAC_PI_2;
    let rho = if rho.is_finite() && rho > 0.0 {
        rho
    } else {
        1.0
    };
    let horiz = (lp.x * lp.x + lp.y * lp.y).sqrt();
    let el = (rho * lp.z).atan2(horiz);
    if el.is_nan() {
        return 0.0;
    }
    let theta = lp.y.atan2(lp.x);
    let drop = if drop.is_finite() { drop } else { 0.0 };
    let half = if penumbra > 0.0 { 0.5 * penumbra } else { 0.0 };
    // Table elevations lie in [0, π/2): decide without searching when they cannot matter.
    let hidden_at = el + half + drop; // table elevation from which the light is fully hidden
    if hidden_at <= 0.0 {
        return 0.0;
    }
    if el - half + drop >= FRAC_PI_2 {
        return 1.0;
    }
    let sc = scale.max(0.0);
    let stop = if hidden_at >= FRAC_PI_2 || sc == 0.0 {
        f32::INFINITY
    } else {
        hidden_at.tan() / (sc * rho)
    };
    // Below this table elevation the light is fully seen: farther occluders do not matter.
    let seen_below = el - half + drop;
    let need = if seen_below > 0.0 && sc > 0.0 {
        seen_below.tan() / (sc * rho)
    } else {
        0.0
    };
    let hz = (rho * sc * table.horizon_tan(s, t, theta, need, stop)).atan() - drop;
    if penumbra > 0.0 {
        penumbra_fraction((el - hz) / half)
    } else if el >= hz {
        1.0
    } else {
        0.0
    }
}

/// Run-time options of the `horizon` shading built-in.
#[derive(Clone, Copy, Debug)]
pub struct HorizonParams {
    /// Bump height multiplier relative to the unit (s,t) patch.
    pub scale: f32,
    /// Light's angular diameter in radians (soft edge).
    pub penumbra: f32,
    /// Filter footprint multiplier (like texture's "width").
    pub width: f32,
    /// Weight of Max's §6 curvature correction (1: as the paper prescribes, 0: flat tables).
    pub curvature: f32,
}

impl Default for HorizonParams {
    fn default() -> Self {
        HorizonParams {
            scale: 1.0,
            penumbra: 0.5f32.to_radians(),
            width: 1.0,
            curvature: 1.0,
        }
    }
}

/// One grid's inputs: per point s, t, P, the outward normal and the light vector, plus the
/// per-grid-step differences of s, t, P and the unit normal along u and v (from the diced
/// grid; the normal's differences give the curvature of Max §6, empty slices: none).
pub struct GridInputs<'a> {
    pub s: &'a [f32],
    pub t: &'a [f32],
    pub l: &'a [Vec3],
    pub up: &'a [Vec3],
    pub dsdu: &'a [f32],
    pub dsdv: &'a [f32],
    pub dtdu: &'a [f32],
    pub dtdv: &'a [f32],
    pub dpdu: &'a [Vec3],
    pub dpdv: &'a [Vec3],
    pub dndu: &'a [Vec3],
    pub dndv: &'a [Vec3],
}

/// Max §6: a point raised `h` above a surface whose section in the light's vertical plane
/// has normal curvature `k` (1/R; negative = convex, with the normal on the bumps' side)
/// sees past the smooth surface's tangent plane by the central angle γ ≈ √(2h/R). Returns
/// the amount to lower the horizon elevation by: +γ on convex surfaces (β' = β + γ), −γ on
/// concave ones (β' = β − γ); 0 for h ≤ 0 or k = 0.
pub fn curvature_drop(h: f32, k: f32) -> f32 {
    if !(h > 0.0) || !k.is_finite() {
        return 0.0;
    }
    let g = (2.0 * h * k.abs()).sqrt().min(std::f32::consts::FRAC_PI_2);
    if k < 0.0 {
        g
    } else {
        -g
    }
}

/// Normal curvature of the surface along the tangent `w = a·ps + b·pt` (ps, pt = dP/ds,
/// dP/dt), from the unit normal's derivatives `ns`, `nt` (dn̂/ds, dn̂/dt): Weingarten's
/// `k = −dn̂(w)·w / w·w`. A sphere of radius R with outward n̂ gives −1/R in every direction.
pub fn normal_curvature(ps: Vec3, pt: Vec3, ns: Vec3, nt: Vec3, a: f32, b: f32) -> f32 {
    let w = ps * a + pt * b;
    let ww = w.length_squared();
    if !(ww > 1e-30) {
        return 0.0;
    }
    let k = -(ns * a + nt * b).dot(w) / ww;
    if k.is_finite() {
        k
    } else {
        0.0
    }
}

/// dP/ds and dP/dt from grid differences: solves `[Pu Pv] = [Ps Pt]·J`, J = ∂(s,t)/∂(u,v).
pub fn st_tangents(pu: Vec3, pv: Vec3, su: f32, sv: f32, tu: f32, tv: f32) -> Option<(Vec3, Vec3)> {
    let det = su * tv - sv * tu;
    if !(det.abs() > 1e-20) {
        return None;
    }
    // J⁻¹ = [[tv, −sv], [−tu, su]] / det.
    let ps = (pu * tv - pv * tu) / det;
    let pt = (pv * su - pu * sv) / det;
    (ps.is_finite() && pt.is_finite()).then_some((ps, pt))
}

/// Visible fraction per grid point. Points whose (s,t) frame is degenerate fall back to the
/// smooth surface's own test (lit iff the light is above it). Filtering: when a grid step
/// covers more than a texel, the fraction is averaged over up to 4×4 samples of the footprint.
/// With `p.curvature` > 0 and normal differences given, the horizon is corrected for the
/// surface's curvature in the light's vertical plane (Max §6, [`curvature_drop`]) using each
/// sample's raised height h = scale·F·|dP/ds × dP/dt|^{1/2}.
pub fn grid_visibility(table: &HorizonTable, g: &GridInputs, p: &HorizonParams) -> Vec<f32> {
    let n = g.s.len();
    let (w, h) = (table.width as f32, table.height as f32);
    let curved = p.curvature > 0.0 && g.dndu.len() == n && g.dndv.len() == n;
    (0..n)
        .map(|i| {
            let (su, sv, tu, tv) = (g.dsdu[i], g.dsdv[i], g.dtdu[i], g.dtdv[i]);
            let Some((ps, pt)) = st_tangents(g.dpdu[i], g.dpdv[i], su, sv, tu, tv) else {
                return if g.l[i].dot(g.up[i]) > 0.0 { 1.0 } else { 0.0 };
            };
            let Some(lp) = standard_light(ps, pt, g.up[i], g.l[i]) else {
                return if g.l[i].dot(g.up[i]) > 0.0 { 1.0 } else { 0.0 };
            };
            // C maps (lp.x, lp.y, 0) to the tangential part of L, the direction of Max's
            // section plane T, and the standard patch's unit height to |N|^½: slopes in T
            // are rho times those on the standard patch.
            let root_n = ps.cross(pt).length().sqrt();
            let wt = (ps * lp.x + pt * lp.y).length();
            let rho = if wt > 1e-30 {
                root_n * (lp.x * lp.x + lp.y * lp.y).sqrt() / wt
            } else {
                1.0
            };
            // Curvature of the section T.
            let k_n = if curved {
                let k = st_tangents(g.dndu[i], g.dndv[i], su, sv, tu, tv)
                    .map_or(0.0, |(ns, nt)| normal_curvature(ps, pt, ns, nt, lp.x, lp.y));
                k * p.curvature
            } else {
                0.0
            };
            let vis = |s: f32, t: f32| {
                let drop = if k_n != 0.0 {
                    curvature_drop(p.scale * table.height_at(s, t) * root_n, k_n)
                } else {
                    0.0
                };
                visibility_curved(table, s, t, lp, p.scale, p.penumbra, drop, rho)
            };
            let fw = p.width.max(0.0);
            let ext = ((su.abs() + sv.abs()) * w).max((tu.abs() + tv.abs()) * h) * fw;
            let k = if ext.is_finite() {
                (ext.ceil() as usize).clamp(1, 4)
            } else {
                1
            };
            if k == 1 {
                return vis(g.s[i], g.t[i]);
            }
            let mut acc = 0.0;
            for a in 0..k {
                let fu = ((a as f32 + 0.5) / k as f32 - 0.5) * fw;
                for b in 0..k {
                    let fv = ((b as f32 + 0.5) / k as f32 - 0.5) * fw;
                    let s = g.s[i] + fu * su + fv * sv;
                    let t = g.t[i] + fu * tu + fv * tv;
                    acc += vis(s, t);
                }
            }
            acc / (k * k) as f32
        })
        .collect()
}

/// Max-scaled displacement distance per grid point: `scale · F(s,t) · |dP/ds × dP/dt|^{1/2}`
/// (Max §3: P'' = P + F·N/|N|^{1/2}), in the units of P. Degenerate frames give 0.
pub fn grid_height(table: &HorizonTable, g: &GridInputs, scale: f32) -> Vec<f32> {
    (0..g.s.len())
        .map(|i| {
            let f = table.height_at(g.s[i], g.t[i]);
            match st_tangents(
                g.dpdu[i], g.dpdv[i], g.dsdu[i], g.dsdv[i], g.dtdu[i], g.dtdv[i],
            ) {
                Some((ps, pt)) => scale * f * ps.cross(pt).length().sqrt(),
                None => 0.0,
            }
        })
        .collect()
}

/// Reads a height map image (PNG, TIFF, JPEG, HDR via `image`; OpenEXR via `exr`) as
/// luminance (Rec. 709 weights; 8/16-bit images normalised to [0,1]).
pub fn read_height_image(path: &Path) -> Result<(Vec<f32>, usize, usize), String> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let lum = |r: f32, g: f32, b: f32| 0.2126 * r + 0.7152 * g + 0.0722 * b;
    if ext == "exr" {
        use exr::prelude::*;
        let img = read_first_rgba_layer_from_file(
            path,
            |res, _| {
                (
                    vec![0f32; res.width() * res.height()],
                    res.width(),
                    res.height(),
                )
            },
            move |px: &mut (Vec<f32>, usize, usize), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px.0[pos.y() * px.1 + pos.x()] = lum(r, g, b)
            },
        )
        .map_err(|e| format!("{}: {e}", path.display()))?;
        let (v, w, h) = img.layer_data.channel_data.pixels;
        return Ok((v, w, h));
    }
    let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let rgb = img.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let v = rgb.pixels().map(|p| lum(p.0[0], p.0[1], p.0[2])).collect();
    Ok((v, w, h))
}

/// Builds and writes the tables of a height picture (`MakeHorizon`, `arbor horizon`): the
/// picture's luminance is the height; written to a temporary name and renamed, so a failure
/// never leaves a half-written table.
pub fn make_horizon(input: &Path, output: &Path, directions: usize) -> Result<(), String> {
    let (f, w, h) = read_height_image(input)?;
    let t = HorizonTable::build(&f, w, h, directions)?;
    let mut tmp = output.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = std::path::PathBuf::from(tmp);
    t.write(&tmp)?;
    std::fs::rename(&tmp, output).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: {e}", output.display())
    })
}

/// Tables by path, loaded once and shared by every thread (failures are remembered too).
/// An entry is reloaded when the file's length or modification time changes, so a table
/// rewritten by a later frame's MakeHorizon is seen.
pub fn cached(path: &str) -> Result<Arc<HorizonTable>, String> {
    type Stamp = Option<(u64, std::time::SystemTime)>;
    type Cache = Mutex<HashMap<String, (Stamp, Result<Arc<HorizonTable>, String>)>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let stamp: Stamp = std::fs::metadata(path)
        .ok()
        .and_then(|m| Some((m.len(), m.modified().ok()?)));
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    let mut m = cache.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((st, r)) = m.get(path) {
        if *st == stamp {
            return r.clone();
        }
    }
    let r = HorizonTable::read(Path::new(path)).map(Arc::new);
    m.insert(path.to_string(), (stamp, r.clone()));
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ridge_map(n: usize, x: usize, h: f32) -> Vec<f32> {
        let mut f = vec![0.0; n * n];
        for y in 0..n {
            f[y * n + x] = h;
        }
        f
    }

    /// Brute force reference: max slope over one period ahead (plus midpoints for knights).
    fn brute(f: &[f32], w: usize, h: usize, a: i32, b: i32, x: usize, y: usize) -> f32 {
        let (dx, dy) = (a as f32 / w as f32, b as f32 / h as f32);
        let step = (dx * dx + dy * dy).sqrt();
        let at = |x: i64, y: i64| {
            f[(y.rem_euclid(h as i64) * w as i64 + x.rem_euclid(w as i64)) as usize]
        };
        let z0 = f[y * w + x];
        let mut best = 0f32;
        for m in 1..=(2 * w * h) as i64 {
            let (qx, qy) = (x as i64 + m * a as i64, y as i64 + m * b as i64);
            best = best.max((at(qx, qy) - z0) / (m as f32 * step));
        }
        best
    }

    #[test]
    fn single_ridge_gives_atan_h_over_d() {
        // Notes §7.4 H2: N = 64, ridge height 0.05, 8 texels east: β_E = 68.20°.
        let t = HorizonTable::build(&ridge_map(64, 18, 0.05), 64, 64, 8).unwrap();
        let tan = t.tan_at(10, 5, 0);
        assert!((tan - 0.4).abs() < 1e-5, "{tan}");
        let beta = 90.0 - tan.atan().to_degrees();
        assert!((beta - 68.20).abs() < 0.01, "{beta}");
        // Looking west the ridge is 64-8 = 56 texels away (periodic wrap).
        let west = t.tan_at(10, 5, 4);
        assert!((west - 0.05 / (56.0 / 64.0)).abs() < 1e-5, "{west}");
        // Along the ridge (north) nothing rises.
        assert_eq!(t.tan_at(10, 5, 2), 0.0);
        // Reaches: the ridge is 8 texels east, 8 diagonal steps north-east, 56 west; none north.
        let r = |k: usize| t.reach[(5 * 64 + 10) * 8 + k] * 64.0;
        assert!(
            (r(0) - 8.0).abs() < 1e-4 && (r(4) - 56.0).abs() < 1e-3,
            "{} {}",
            r(0),
            r(4)
        );
        assert!((r(1) - 8.0 * 2f32.sqrt()).abs() < 1e-4);
        assert_eq!(r(2), 0.0);
    }

    #[test]
    fn hull_sweep_matches_brute_force() {
        let (w, h) = (12, 8);
        let f: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919 % 31) as f32 / 31.0) * 0.1)
            .collect();
        for nd in [8, 16] {
            let t = HorizonTable::build(&f, w, h, nd).unwrap();
            for (k, &(a, b)) in directions(nd).unwrap().iter().enumerate() {
                if a.abs() > 1 || b.abs() > 1 {
                    continue; // brute() has no midpoints
                }
                for y in 0..h {
                    for x in 0..w {
                        let want = brute(&f, w, h, a, b, x, y);
                        let got = t.tan_at(x as i64, y as i64, k);
                        assert!(
                            (want - got).abs() < 1e-5,
                            "dir {k} ({x},{y}): {want} vs {got}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn flat_map_and_azimuths() {
        let t = HorizonTable::build(&vec![0.3; 16 * 16], 16, 16, 16).unwrap();
        assert!(t.tans.iter().all(|&v| v == 0.0));
        assert!((t.azimuths[1] - 0.5f32.atan()).abs() < 1e-6);
        assert!(t.azimuths.windows(2).all(|p| p[0] < p[1]));
        assert!(HorizonTable::build(&[0.0; 4], 2, 2, 7).is_err());
        assert!(HorizonTable::build(&[0.0; 3], 2, 2, 8).is_err());
    }

    #[test]
    fn theta_interpolation() {
        // H4: exact at tabulated azimuths, the mean of neighbours halfway (angles, scale 1).
        let t = HorizonTable::build(&ridge_map(32, 20, 0.1), 32, 32, 8).unwrap();
        let (s, tt) = (10.5 / 32.0, 3.5 / 32.0);
        let e0 = t.tan_at(10, 3, 0).atan();
        let e1 = t.tan_at(10, 3, 1).atan();
        let e7 = t.tan_at(10, 3, 7).atan();
        let d = std::f32::consts::PI / 8.0;
        let e = |th: f32| t.elevation_interpolated(s, tt, th, 1.0);
        assert!((e(0.0) - e0).abs() < 1e-6);
        assert!((e(d) - 0.5 * (e0 + e1)).abs() < 1e-6);
        assert!((e(-d) - 0.5 * (e7 + e0)).abs() < 1e-6);
    }

    #[test]
    fn round_trip_and_bad_files() {
        let t = HorizonTable::build(&ridge_map(8, 3, 0.2), 8, 8, 16).unwrap();
        let b = t.to_bytes();
        assert_eq!(HorizonTable::from_bytes(&b).unwrap(), t);
        assert!(HorizonTable::from_bytes(&b[..b.len() - 1]).is_err());
        // A version-1 file (no reaches) is rebuilt from its heights.
        let mut v1 = b"ARBHZN1\0".to_vec();
        v1.extend_from_slice(&b[8..b.len() - 4 * t.reach.len()]);
        assert_eq!(HorizonTable::from_bytes(&v1).unwrap(), t);
        assert!(HorizonTable::from_bytes(b"nonsense").is_err());
    }

    #[test]
    fn penumbra_values() {
        // Notes H12.
        for (a, f) in [
            (-1.0, 0.0),
            (-0.5, 0.19550),
            (0.0, 0.5),
            (0.5, 0.80450),
            (1.0, 1.0),
        ] {
            assert!((penumbra_fraction(a) - f).abs() < 1e-4, "{a}");
        }
        assert_eq!(penumbra_fraction(f32::NAN), 0.0);
    }

    #[test]
    fn light_transform_h9_h10() {
        // H9: P = (2u, v, 0), L = (1,0,1)/√2 → θ = 0, φ = 35.26°.
        let lp = standard_light(Vec3::X * 2.0, Vec3::Y, Vec3::Z, Vec3::new(1.0, 0.0, 1.0)).unwrap();
        let phi = (lp.z / lp.length()).acos().to_degrees();
        assert!((phi - 35.26).abs() < 0.01, "{phi}");
        assert!(lp.y.abs() < 1e-6);
        // H10: matches the closed form and C·(C⁻¹L) = L.
        let (pu, pv, l) = (
            Vec3::new(2.0, 0.3, 0.1),
            Vec3::new(0.2, 1.0, 0.4),
            Vec3::new(0.3, 0.5, 0.8),
        );
        let n = pu.cross(pv);
        let lp = standard_light(pu, pv, n, l).unwrap();
        let want = Vec3::new(0.078858, 0.684704, 0.386281);
        assert!((lp - want).length() < 1e-4, "{lp}");
        let back = pu * lp.x + pv * lp.y + n / n.length().sqrt() * lp.z;
        assert!((back - l).length() < 1e-5);
        // H11: a back-facing light lands below the standard patch.
        assert!(standard_light(pu, pv, n, -n).unwrap().z < 0.0);
        assert!(standard_light(pu, pu, n, l).is_none());
    }

    #[test]
    fn st_tangents_invert_the_jacobian() {
        // s = u + v, t = v on P = (u, v, 0): dP/ds = (1,0,0), dP/dt = (-1,1,0).
        let (ps, pt) = st_tangents(Vec3::X, Vec3::Y, 1.0, 1.0, 0.0, 1.0).unwrap();
        assert!((ps - Vec3::X).length() < 1e-6 && (pt - Vec3::new(-1.0, 1.0, 0.0)).length() < 1e-6);
        assert!(st_tangents(Vec3::X, Vec3::Y, 1.0, 1.0, 1.0, 1.0).is_none());
    }

    #[test]
    fn curvature_drop_h13() {
        // H13: a sphere of radius 1 and h = 0.005 gives γ = √0.01 = 0.1 rad (5.73°).
        assert!((curvature_drop(0.005, -1.0) - 0.1).abs() < 1e-6);
        assert!((curvature_drop(0.005, 1.0) + 0.1).abs() < 1e-6); // concave: raised
        assert_eq!(curvature_drop(0.0, -1.0), 0.0);
        assert_eq!(curvature_drop(0.005, 0.0), 0.0);
        assert_eq!(curvature_drop(f32::NAN, -1.0), 0.0);
    }

    /// Unit sphere P(u,v) = (cos u cos v, sin u cos v, sin v) at (u, v), outward normal.
    fn sphere_frame(u: f32, v: f32) -> (Vec3, Vec3, Vec3, Vec3) {
        let pu = Vec3::new(-u.sin() * v.cos(), u.cos() * v.cos(), 0.0);
        let pv = Vec3::new(-u.cos() * v.sin(), -u.sin() * v.sin(), v.cos());
        // n̂ = P on the unit sphere, so dn̂/du = P_u and dn̂/dv = P_v.
        (pu, pv, pu, pv)
    }

    #[test]
    fn normal_curvature_of_sphere_and_cylinder() {
        let (pu, pv, nu, nv) = sphere_frame(0.3, 0.4);
        for th in [0.0f32, 0.7, 1.9, 3.0, 4.4] {
            let k = normal_curvature(pu, pv, nu, nv, th.cos(), th.sin());
            assert!((k + 1.0).abs() < 1e-5, "θ {th}: {k}");
        }
        // Cylinder of radius 2: P = (2cos u, 2sin u, v), n̂ = (cos u, sin u, 0).
        let u = 0.8f32;
        let pu = Vec3::new(-2.0 * u.sin(), 2.0 * u.cos(), 0.0);
        let nu = Vec3::new(-u.sin(), u.cos(), 0.0);
        let (pv, nv) = (Vec3::Z, Vec3::ZERO);
        assert!((normal_curvature(pu, pv, nu, nv, 1.0, 0.0) + 0.5).abs() < 1e-6);
        assert!(normal_curvature(pu, pv, nu, nv, 0.0, 1.0).abs() < 1e-6);
        // Euler: k(θ) = k1 cos²ψ + k2 sin²ψ with ψ the angle from the principal direction.
        let k = normal_curvature(pu, pv, nu, nv, 0.5, 1.0); // w = (pu*0.5 + pv), |pu| = 2
        assert!((k + 0.5 * 0.5).abs() < 1e-6, "{k}"); // cos²ψ = 1/2 for w = (1,1) in lengths
                                                      // Seen from inside (normal towards the axis) the cylinder is concave.
        assert!((normal_curvature(pu, pv, -nu, nv, 1.0, 0.0) - 0.5).abs() < 1e-6);
    }

    /// Visibility at one point of a unit sphere under a flat map of height `c`, for a light
    /// `el` radians above the tangent plane towards azimuth `az` (in the (u,v) frame).
    fn sphere_vis(c: f32, scale: f32, inside: bool, el: f32, az: f32, curvature: f32) -> f32 {
        let table = HorizonTable::build(&[c; 16 * 16], 16, 16, 8).unwrap();
        // At latitude 1 rad |P_u| = cos 1 ≠ |P_v| = 1: standard-patch and true angles differ.
        let (u, v) = (0.3f32, 1.0f32);
        let (pu, pv, nu, nv) = sphere_frame(u, v);
        let n = Vec3::new(u.cos() * v.cos(), u.sin() * v.cos(), v.sin());
        let (up, dn) = if inside { (-n, -1.0) } else { (n, 1.0) };
        // Tangent direction towards the light: unit vectors along P_u and P_v.
        let tdir = pu.normalize() * az.cos() + pv.normalize() * az.sin();
        let l = up * el.sin() + tdir * el.cos();
        let one = |x: f32| [x];
        let (s, t) = (one(0.5), one(0.5));
        let (l, up) = ([l], [up]);
        // s = u, t = v: one grid step is one unit of each; tiny steps so no filtering.
        let st = 1e-3;
        let (pu, pv, nu, nv) = ([pu * st], [pv * st], [nu * st * dn], [nv * st * dn]);
        let g = GridInputs {
            s: &s,
            t: &t,
            l: &l,
            up: &up,
            dsdu: &one(st),
            dsdv: &one(0.0),
            dtdu: &one(0.0),
            dtdv: &one(st),
            dpdu: &pu,
            dpdv: &pv,
            dndu: &nu,
            dndv: &nv,
        };
        let p = HorizonParams {
            scale,
            penumbra: 0.0,
            width: 1.0,
            curvature,
        };
        grid_visibility(&table, &g, &p)[0]
    }

    #[test]
    fn curvature_correction_on_a_sphere() {
        // |P_u × P_v| = cos v, so h = scale·c·√(cos v); pick scale so h = 0.005: γ = 0.1.
        let scale = 0.005 / (0.5 * 1f32.cos().sqrt());
        for az in [0.0f32, 1.0, 2.5, 4.0] {
            // Convex: a raised point sees 0.1 rad below the tangent plane (β' = β + γ).
            assert_eq!(
                sphere_vis(0.5, scale, false, -0.095, az, 1.0),
                1.0,
                "az {az}"
            );
            assert_eq!(
                sphere_vis(0.5, scale, false, -0.105, az, 1.0),
                0.0,
                "az {az}"
            );
            // Without the correction (or at base level, h = 0) the tangent plane is the horizon.
            assert_eq!(sphere_vis(0.5, scale, false, -0.01, az, 0.0), 0.0);
            assert_eq!(sphere_vis(0.0, scale, false, -0.01, az, 1.0), 0.0);
            assert_eq!(sphere_vis(0.0, scale, false, 0.01, az, 1.0), 1.0);
            // Concave (seen from inside): the horizon rises by γ (β' = β − γ).
            assert_eq!(sphere_vis(0.5, scale, true, 0.095, az, 1.0), 0.0, "az {az}");
            assert_eq!(sphere_vis(0.5, scale, true, 0.105, az, 1.0), 1.0, "az {az}");
        }
    }
}
