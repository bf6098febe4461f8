//! Fractal sums of noise with octave truncation at the shading footprint: fBm, turbulence,
//! ridged multifractal, vector fBm, animated (flame) turbulence, and Gardner's Fourier
//! synthesis texture (notes/shading.md §3.4, §3.6, §3.7; book §4.8, §7.2–§7.3).
//!
//! Input: a point (and time), a filter width `fw` in the same units as the point (0 = no
//! filtering), and the octave parameters. Output: the pattern value.
//! Invariants: octave i has frequency `lacunarity^i` (noise has features ~1 unit) and amplitude
//! `gain^i`. Under a filter of width `fw` it is weighted by Peachey's ramp
//! `w = clamp((½ − f·fw)/¼, 0, 1)` (notes §3.4, test P9): full below ¼ cycle per sample, 0 at
//! the Nyquist limit ½, and the loop stops at the first octave with weight 0 — so a wider
//! footprint evaluates fewer octaves. A faded octave is replaced by its spatial mean (0 for
//! `snoise`, [`ABS_SNOISE3_MEAN`] for |snoise|), which is what a box filter much wider than the
//! octave returns. Each octave samples the noise with a fixed offset so lattice zeros of
//! different octaves do not line up (otherwise every octave is 0 at the origin). Inputs are
//! sanitised: octaves are clamped to [0, 32], a non-finite filter width counts as 0.

use glam::Vec3;

use super::noise::{snoise3, snoise3_x8, snoise4, vsnoise3, ABS_SNOISE3_MEAN, ABS_SNOISE4_MEAN};

/// Upper bound on the octaves any sum evaluates (guards against absurd parameters).
pub const MAX_OCTAVES: u32 = 32;

/// Octave parameters of fBm and turbulence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Octaves {
    /// Number of octaves; a fractional part weights the last octave (smooth octave animation).
    pub octaves: f32,
    /// Frequency ratio between octaves (2 in the book).
    pub lacunarity: f32,
    /// Amplitude ratio between octaves (½ in the book).
    pub gain: f32,
}

impl Default for Octaves {
    fn default() -> Self {
        Octaves {
            octaves: 6.0,
            lacunarity: 2.0,
            gain: 0.5,
        }
    }
}

impl Octaves {
    pub fn new(octaves: f32, lacunarity: f32, gain: f32) -> Self {
        Octaves {
            octaves,
            lacunarity,
            gain,
        }
    }

    fn max_octaves(&self) -> f32 {
        if self.octaves.is_finite() {
            self.octaves.clamp(0.0, MAX_OCTAVES as f32)
        } else {
            0.0
        }
    }

    /// Σ gain^i over the (unfiltered) octaves: the bound of turbulence and |fBm| when
    /// |snoise| ≤ 1.
    pub fn amplitude_sum(&self) -> f32 {
        let n = self.max_octaves();
        let mut amp = 1.0;
        let mut sum = 0.0;
        let mut i = 0;
        while (i as f32) < n {
            sum += amp * (n - i as f32).min(1.0);
            amp *= self.gain;
            i += 1;
        }
        sum
    }
}

/// Peachey's anti-aliasing weight of a component of frequency `freq` (cycles per unit) under a
/// filter of width `fw`: 1 for `freq·fw ≤ ¼`, 0 for `freq·fw ≥ ½` (Nyquist), linear between.
#[inline]
pub fn octave_weight(freq: f32, fw: f32) -> f32 {
    // NaN, ±∞, 0 and negative widths all mean "unfiltered".
    if fw.is_nan() || fw <= 0.0 || fw.is_infinite() {
        return 1.0;
    }
    ((0.5 - freq * fw) * 4.0).clamp(0.0, 1.0)
}

/// Band-limited `snoise3` for a footprint of width `fw`: faded to its mean 0 by the same
/// Peachey ramp as the octaves (the `filteredsnoise` of SL headers).
pub fn filtered_snoise3(p: Vec3, fw: f32) -> f32 {
    let w = octave_weight(1.0, fw);
    if w > 0.0 {
        w * snoise3(p)
    } else {
        0.0
    }
}

/// Band-limited `noise3`: fades to 0.5 as the footprint reaches a noise cell.
pub fn filtered_noise3(p: Vec3, fw: f32) -> f32 {
    0.5 + 0.5 * filtered_snoise3(p, fw)
}

/// Number of octaves a fractal sum actually evaluates for filter width `fw` (those with a
/// non-zero weight).
pub fn octave_count(fw: f32, o: &Octaves) -> u32 {
    let mut n = 0;
    OctaveIter::new(fw, o).for_each(|_| n += 1);
    n
}

/// Iterates (index, frequency, amplitude, filter weight) over the octaves with non-zero filter
/// weight; the amplitude includes the fractional-octave factor.
struct OctaveIter {
    i: u32,
    n: f32,
    freq: f32,
    amp: f32,
    lac: f32,
    gain: f32,
    fw: f32,
}

impl OctaveIter {
    #[inline]
    fn new(fw: f32, o: &Octaves) -> Self {
        OctaveIter {
            i: 0,
            n: o.max_octaves(),
            freq: 1.0,
            amp: 1.0,
            lac: o.lacunarity,
            gain: o.gain,
            fw: if fw.is_finite() { fw.max(0.0) } else { 0.0 },
        }
    }
}

impl Iterator for OctaveIter {
    type Item = (u32, f32, f32, f32);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.i as f32 >= self.n {
            return None;
        }
        let w = octave_weight(self.freq, self.fw);
        if w <= 0.0 {
            return None;
        }
        let item = (
            self.i,
            self.freq,
            self.amp * (self.n - self.i as f32).min(1.0),
            w,
        );
        self.i += 1;
        self.freq *= self.lac;
        self.amp *= self.gain;
        Some(item)
    }
}

/// Per-octave offset decorrelating the lattices of successive octaves.
#[inline(always)]
fn octave_offset(i: u32) -> Vec3 {
    let k = i as f32;
    Vec3::new(k * 17.31, k * -11.77, k * 7.13)
}

/// Fractional Brownian motion: Σ gain^i · snoise(p·lac^i), signed, |fBm| ≤ Σ gain^i.
pub fn fbm3(p: Vec3, fw: f32, o: &Octaves) -> f32 {
    let mut sum = 0.0;
    for (i, f, a, w) in OctaveIter::new(fw, o) {
        // A faded octave tends to its mean, 0.
        sum += a * w * snoise3(p * f + octave_offset(i));
    }
    sum
}

/// fBm over space and time: time is a fourth lattice axis, scaled with the octave frequency
/// like the spatial axes (finer octaves also evolve faster).
pub fn fbm4(p: Vec3, t: f32, fw: f32, o: &Octaves) -> f32 {
    let mut sum = 0.0;
    for (i, f, a, w) in OctaveIter::new(fw, o) {
        sum += a * w * snoise4(p * f + octave_offset(i), t * f);
    }
    sum
}

/// Vector fBm: three decorrelated fBm channels, each in [−Σgain^i, Σgain^i].
pub fn vfbm3(p: Vec3, fw: f32, o: &Octaves) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for (i, f, a, w) in OctaveIter::new(fw, o) {
        sum += (a * w) * vsnoise3(p * f + octave_offset(i));
    }
    sum
}

/// Turbulence (book L6875, with the `abs` of E8): Σ gain^i · |snoise(p·lac^i)|, in
/// [0, Σ gain^i]. Octaves beyond the footprint contribute their mean |snoise|.
pub fn turbulence3(p: Vec3, fw: f32, o: &Octaves) -> f32 {
    let mut sum = 0.0;
    let mut it = OctaveIter::new(fw, o);
    for (i, f, a, w) in &mut it {
        let v = snoise3(p * f + octave_offset(i)).abs();
        sum += a * (w * v + (1.0 - w) * ABS_SNOISE3_MEAN);
    }
    sum + tail_mean(&it, ABS_SNOISE3_MEAN)
}

/// Turbulence over space and time (book §7.2.3: time is a fourth lattice axis).
pub fn turbulence4(p: Vec3, t: f32, fw: f32, o: &Octaves) -> f32 {
    let mut sum = 0.0;
    let mut it = OctaveIter::new(fw, o);
    for (i, f, a, w) in &mut it {
        let v = snoise4(p * f + octave_offset(i), t * f).abs();
        sum += a * (w * v + (1.0 - w) * ABS_SNOISE4_MEAN);
    }
    sum + tail_mean(&it, ABS_SNOISE4_MEAN)
}

/// The mean contribution of the octaves an iterator stopped before (fully filtered ones), up to
/// the requested octave count: Σ_{i ≥ stop} gain^i · frac_i · mean.
fn tail_mean(it: &OctaveIter, mean: f32) -> f32 {
    let mut sum = 0.0;
    let mut amp = it.amp;
    let mut i = it.i;
    while (i as f32) < it.n {
        sum += amp * (it.n - i as f32).min(1.0) * mean;
        amp *= it.gain;
        i += 1;
    }
    sum
}

/// Animated turbulence for flames (book §7.2.3, L6942): turbulence over (x, t) with the
/// pattern convected upward at `rise` units per unit time. The book writes
/// `turbulence(x + (0, tΔy, 0), t)`, which (with y up, as its flame rectangle implies) moves
/// features *down*; we sample at `p − (0, t·rise, 0)` so they rise with the flame.
pub fn flame_turbulence(p: Vec3, t: f32, rise: f32, fw: f32, o: &Octaves) -> f32 {
    turbulence4(p - Vec3::new(0.0, t * rise, 0.0), t, fw, o)
}

/// Parameters of Musgrave's ridged multifractal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RidgedParams {
    pub octaves: Octaves,
    /// Spectral exponent: octave i is weighted by `lacunarity^(−i·h)` (`octaves.gain` is the
    /// feedback gain of the ridge weighting instead).
    pub h: f32,
    /// Ridge offset (1 puts the ridges where snoise = 0).
    pub offset: f32,
}

impl Default for RidgedParams {
    fn default() -> Self {
        RidgedParams {
            octaves: Octaves::new(6.0, 2.0, 2.0),
            h: 1.0,
            offset: 1.0,
        }
    }
}

/// Ridged multifractal (Musgrave): each octave is `(offset − |snoise|)²`, weighted by the
/// previous octave's signal (times `gain`, clamped to [0,1]) so ridges grow detail and valleys
/// stay smooth. Non-negative. Filtered octaves fade to 0 contribution.
pub fn ridged3(p: Vec3, fw: f32, r: &RidgedParams) -> f32 {
    let o = Octaves {
        gain: 1.0, // amplitudes come from h below
        ..r.octaves
    };
    let mut sum = 0.0;
    let mut weight = 1.0f32;
    for (i, f, _, w) in OctaveIter::new(fw, &o) {
        let s = (r.offset - snoise3(p * f + octave_offset(i)).abs()).max(0.0);
        let signal = s * s * weight;
        weight = (signal * r.octaves.gain).clamp(0.0, 1.0);
        sum += w * signal * f.powf(-r.h);
    }
    sum
}

/// Parameters of Gardner's spectral texture (book §7.3, eq. 7.1; notes §3.7 and E10).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GardnerParams {
    /// Number of terms n per axis (4–7 typical).
    pub terms: u32,
    /// First amplitude C₁.
    pub c1: f32,
    /// Amplitude ratio C_{i+1}/C_i (≈ 0.707).
    pub c_ratio: f32,
    /// First angular frequency ω₁ (radians per unit).
    pub omega1: f32,
    /// Frequency ratio ω_{i+1}/ω_i (≈ 2).
    pub omega_ratio: f32,
    /// Offset A₀ (≈ 1, which keeps every factor ≥ 0).
    pub a0: f32,
    /// Cross-coupled phases φ_{x,i+1} = π/2·cos(ω_i z), φ_{y,i+1} = π/2·cos(ω_i x),
    /// φ_{z,i+1} = π/2·cos(ω_i y) (E10's reading); false gives zero phases.
    pub coupled_phases: bool,
}

impl Default for GardnerParams {
    fn default() -> Self {
        GardnerParams {
            terms: 6,
            c1: 1.0,
            c_ratio: std::f32::consts::FRAC_1_SQRT_2,
            omega1: 1.0,
            omega_ratio: 2.0,
            a0: 1.0,
            coupled_phases: true,
        }
    }
}

impl GardnerParams {
    /// Upper bound of [`gardner`] when A₀ ≥ 1: `((1 + A₀)·ΣC_i)³` (notes §3.7, test P8).
    pub fn max_value(&self) -> f32 {
        let mut c = self.c1;
        let mut s = 0.0;
        for _ in 0..self.terms.min(MAX_OCTAVES) {
            s += c.abs();
            c *= self.c_ratio;
        }
        ((1.0 + self.a0.abs()) * s).powi(3)
    }
}

/// Gardner's Fourier-synthesis texture, the product of three sums of cosines (eq. 7.1):
/// `T = Π_{axis} Σ_i C_i (cos(ω_i·x_axis + φ_{axis,i}) + A₀)`. Each cosine is weighted by the
/// Peachey ramp at its frequency ω_i/2π; a fully filtered cosine is replaced by its mean 0.
pub fn gardner(p: Vec3, fw: f32, g: &GardnerParams) -> f32 {
    use std::f32::consts::{FRAC_PI_2, TAU};
    let fw = if fw.is_finite() { fw.max(0.0) } else { 0.0 };
    let (mut sx, mut sy, mut sz) = (0.0f32, 0.0f32, 0.0f32);
    let (mut px, mut py, mut pz) = (0.0f32, 0.0f32, 0.0f32);
    let mut c = g.c1;
    let mut om = g.omega1;
    for _ in 0..g.terms.min(MAX_OCTAVES) {
        let w = octave_weight(om.abs() / TAU, fw);
        sx += c * (w * (om * p.x + px).cos() + g.a0);
        sy += c * (w * (om * p.y + py).cos() + g.a0);
        sz += c * (w * (om * p.z + pz).cos() + g.a0);
        if g.coupled_phases {
            // The phase terms oscillate at ω_i too: fade them with the same weight.
            px = w * FRAC_PI_2 * (om * p.z).cos();
            py = w * FRAC_PI_2 * (om * p.x).cos();
            pz = w * FRAC_PI_2 * (om * p.y).cos();
        }
        c *= g.c_ratio;
        om *= g.omega_ratio;
    }
    sx * sy * sz
}

// ---------------------------------------------------------------------------------------------
// Batch forms (each processes min(len) elements)
// ---------------------------------------------------------------------------------------------

/// Shared batch kernel of [`turbulence3_slice`] and [`fbm3_slice`]: 8 points at a time through
/// the lane-parallel noise kernel. All lanes step through the same octave sequence (the
/// frequencies do not depend on the point); a lane whose footprint has stopped its octaves
/// just stops accumulating. Bit-identical to the scalar functions.
fn octave_slice(
    p: &[Vec3],
    fw: &[f32],
    o: &Octaves,
    out: &mut [f32],
    term: impl Fn(f32, f32, f32) -> f32,
    tail: impl Fn(&OctaveIter) -> f32,
    scalar: impl Fn(Vec3, f32) -> f32,
) {
    const L: usize = 8;
    let n = p.len().min(fw.len()).min(out.len());
    let full = n - n % L;
    for c in (0..full).step_by(L) {
        let mut its: [OctaveIter; L] = std::array::from_fn(|l| OctaveIter::new(fw[c + l], o));
        let mut sum = [0.0f32; L];
        loop {
            let items: [Option<(u32, f32, f32, f32)>; L] = std::array::from_fn(|l| its[l].next());
            let Some(&Some((i, f, _, _))) = items.iter().find(|it| it.is_some()) else {
                break;
            };
            let off = octave_offset(i);
            let x = std::array::from_fn(|l| p[c + l].x * f + off.x);
            let y = std::array::from_fn(|l| p[c + l].y * f + off.y);
            let z = std::array::from_fn(|l| p[c + l].z * f + off.z);
            let r = snoise3_x8(&x, &y, &z);
            for l in 0..L {
                if let Some((_, _, a, w)) = items[l] {
                    sum[l] += term(r[l], a, w);
                }
            }
        }
        for l in 0..L {
            out[c + l] = sum[l] + tail(&its[l]);
        }
    }
    for k in full..n {
        out[k] = scalar(p[k], fw[k]);
    }
}

/// `out[i] = turbulence3(p[i], fw[i], o)` (bit-identical, batched).
pub fn turbulence3_slice(p: &[Vec3], fw: &[f32], o: &Octaves, out: &mut [f32]) {
    octave_slice(
        p,
        fw,
        o,
        out,
        |v, a, w| a * (w * v.abs() + (1.0 - w) * ABS_SNOISE3_MEAN),
        |it| tail_mean(it, ABS_SNOISE3_MEAN),
        |q, w| turbulence3(q, w, o),
    );
}

/// `out[i] = fbm3(p[i], fw[i], o)` (bit-identical, batched).
pub fn fbm3_slice(p: &[Vec3], fw: &[f32], o: &Octaves, out: &mut [f32]) {
    octave_slice(
        p,
        fw,
        o,
        out,
        |v, a, w| a * w * v,
        |_| 0.0,
        |q, w| fbm3(q, w, o),
    );
}

/// `out[i] = vfbm3(p[i], fw[i], o)`.
pub fn vfbm3_slice(p: &[Vec3], fw: &[f32], o: &Octaves, out: &mut [Vec3]) {
    for ((r, &q), &w) in out.iter_mut().zip(p).zip(fw) {
        *r = vfbm3(q, w, o);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pattern::hash::hash_float;

    fn pts(n: u32, scale: f32, seed: u32) -> impl Iterator<Item = (Vec3, f32)> {
        (0..n).map(move |i| {
            let k = seed.wrapping_mul(7919).wrapping_add(i * 4);
            let r = |j: u32| (hash_float(k + j) * 2.0 - 1.0) * scale;
            (Vec3::new(r(0), r(1), r(2)), r(3))
        })
    }

    #[test]
    fn peachey_weights() {
        // P9: weight 0 at f·p ≥ ½, 1 at f·p ≤ ¼, linear between.
        assert_eq!(octave_weight(1.0, 0.0), 1.0);
        assert_eq!(octave_weight(1.0, 0.25), 1.0);
        assert_eq!(octave_weight(1.0, 0.5), 0.0);
        assert_eq!(octave_weight(2.0, 0.3), 0.0);
        assert!((octave_weight(1.0, 0.375) - 0.5).abs() < 1e-6);
        assert_eq!(octave_weight(1.0, f32::NAN), 1.0);
    }

    #[test]
    fn filtered_noise_fades() {
        let p = Vec3::new(0.3, 0.6, 0.2);
        assert_eq!(filtered_snoise3(p, 0.0), snoise3(p));
        assert_eq!(filtered_snoise3(p, 0.6), 0.0);
        assert_eq!(filtered_noise3(p, 1.0), 0.5);
        assert!((filtered_snoise3(p, 0.375) - 0.5 * snoise3(p)).abs() < 1e-6);
    }

    #[test]
    fn octave_truncation_at_footprint() {
        let o = Octaves::new(12.0, 2.0, 0.5);
        assert_eq!(octave_count(0.0, &o), 12);
        // 2^i · fw < ½: fw = 1/256 keeps i ≤ 6; fw = 0.01 keeps i ≤ 5; fw = 0.3 keeps i = 0.
        assert_eq!(octave_count(1.0 / 256.0, &o), 7);
        assert_eq!(octave_count(0.01, &o), 6);
        assert_eq!(octave_count(0.3, &o), 1);
        assert_eq!(octave_count(0.6, &o), 0);
        // Monotone: a larger footprint never evaluates more octaves.
        let mut last = u32::MAX;
        for k in 0..40 {
            let n = octave_count(1e-4 * 1.4f32.powi(k), &o);
            assert!(n <= last);
            last = n;
        }
        assert_eq!(octave_count(0.0, &Octaves::new(f32::INFINITY, 2.0, 0.5)), 0);
        assert_eq!(octave_count(0.0, &Octaves::new(1e9, 2.0, 0.5)), MAX_OCTAVES);
    }

    #[test]
    fn turbulence_bounded_by_octave_sum() {
        let o = Octaves::default();
        let bound = o.amplitude_sum();
        assert!((bound - (2.0 - 2.0f32.powi(-5))).abs() < 1e-6);
        let mut mx = 0.0f32;
        for (p, t) in pts(20_000, 20.0, 1) {
            let v = turbulence3(p, 0.0, &o);
            assert!((0.0..=bound).contains(&v), "{v}");
            assert!((0.0..=bound).contains(&turbulence4(p, t, 0.0, &o)));
            assert!(fbm3(p, 0.0, &o).abs() <= bound);
            assert!(fbm4(p, t, 0.0, &o).abs() <= bound);
            let vf = vfbm3(p, 0.0, &o);
            assert!(vf.abs().max_element() <= bound);
            assert_eq!(v, turbulence3(p, 0.0, &o)); // no hidden state (E8)
            mx = mx.max(v);
        }
        assert!(mx > 0.5 * bound);
    }

    #[test]
    fn filtering_fades_to_the_mean() {
        let o = Octaves::default();
        let p = Vec3::new(0.3, -1.2, 4.4);
        // A footprint wider than every octave: turbulence is the mean, fBm is 0.
        assert!((turbulence3(p, 10.0, &o) - o.amplitude_sum() * ABS_SNOISE3_MEAN).abs() < 1e-6);
        assert_eq!(fbm3(p, 10.0, &o), 0.0);
        // Filtering reduces the variance across space but keeps the mean.
        let stats = |fw: f32| {
            let (mut s1, mut s2, n) = (0.0f64, 0.0f64, 20_000u32);
            for (q, _) in pts(n, 30.0, 2) {
                let v = turbulence3(q, fw, &o) as f64;
                s1 += v;
                s2 += v * v;
            }
            let m = s1 / n as f64;
            (m, s2 / n as f64 - m * m)
        };
        let (m0, v0) = stats(0.0);
        let (m1, v1) = stats(0.1);
        assert!(v1 < v0);
        assert!((m1 - m0).abs() < 0.05 * m0, "means {m0} {m1}");
    }

    #[test]
    fn fractional_octaves_blend_the_last_octave() {
        let p = Vec3::new(1.1, 2.2, -0.7);
        let t2 = turbulence3(p, 0.0, &Octaves::new(2.0, 2.0, 0.5));
        let t3 = turbulence3(p, 0.0, &Octaves::new(3.0, 2.0, 0.5));
        let t25 = turbulence3(p, 0.0, &Octaves::new(2.5, 2.0, 0.5));
        // The half octave contributes half its value.
        let v = snoise3(p * 4.0 + octave_offset(2)).abs();
        assert!((t25 - (t2 + 0.25 * 0.5 * v)).abs() < 1e-6);
        assert!((t3 - (t2 + 0.25 * v)).abs() < 1e-6);
    }

    #[test]
    fn fbm_is_not_zero_at_the_origin() {
        // Octave offsets keep lattice zeros from lining up.
        assert!(fbm3(Vec3::ZERO, 0.0, &Octaves::default()).abs() > 1e-4);
    }

    #[test]
    fn ridged_is_nonnegative_and_filters() {
        let r = RidgedParams::default();
        for (p, _) in pts(5000, 10.0, 3) {
            let v = ridged3(p, 0.0, &r);
            assert!(v >= 0.0 && v.is_finite());
            assert!(ridged3(p, 0.2, &r) >= 0.0);
        }
        // Only the first octave survives fw = 0.3 (weight 0.8): a scaled single term.
        let p = Vec3::new(0.4, 0.2, 0.9);
        let s = 1.0 - snoise3(p).abs();
        assert!((ridged3(p, 0.3, &r) - 0.8 * s * s).abs() < 1e-6);
    }

    #[test]
    fn gardner_known_answers() {
        // P8: one term, no phases: T = Π C1 (cos(ω1 x_a) + A0).
        let g = GardnerParams {
            terms: 1,
            c1: 0.5,
            omega1: 3.0,
            coupled_phases: false,
            ..Default::default()
        };
        let p = Vec3::new(0.2, -0.7, 1.3);
        let f = |x: f32| 0.5 * ((3.0 * x).cos() + 1.0);
        assert!((gardner(p, 0.0, &g) - f(p.x) * f(p.y) * f(p.z)).abs() < 1e-6);
        // Bounds with A0 = 1 and the default coupled phases.
        let g = GardnerParams::default();
        let m = g.max_value();
        for (q, _) in pts(5000, 10.0, 4) {
            let v = gardner(q, 0.0, &g);
            assert!(v >= 0.0 && v <= m, "{v} > {m}");
        }
        // A footprint wider than every wavelength leaves the mean (A0·ΣC)³.
        let sum_c: f32 = (0..6).map(|i| g.c_ratio.powi(i)).sum();
        assert!((gardner(p, 1e3, &g) - sum_c.powi(3)).abs() < 1e-3);
    }

    #[test]
    fn flame_turbulence_rises() {
        // The pattern at (p, t) reappears `rise·dt` higher at t + dt (only the slow time axis
        // changes), so that correlation beats the correlation in place.
        let o = Octaves::new(3.0, 2.0, 0.5);
        let (rise, dt) = (5.0, 0.1);
        let up = Vec3::new(0.0, rise * dt, 0.0);
        let (mut same, mut moved, mut norm) = (0.0f64, 0.0f64, 0.0f64);
        let m = 0.3f64;
        for (p, t) in pts(5000, 10.0, 5) {
            let a = flame_turbulence(p, t, rise, 0.0, &o) as f64 - m;
            let b = flame_turbulence(p, t + dt, rise, 0.0, &o) as f64 - m;
            let c = flame_turbulence(p + up, t + dt, rise, 0.0, &o) as f64 - m;
            same += a * b;
            moved += a * c;
            norm += a * a;
        }
        assert!(moved / norm > 0.8, "moved {}", moved / norm);
        assert!(moved > same + 0.2 * norm);
    }

    #[test]
    fn slices_match_scalar() {
        // 203 points: 25 full batches with mixed footprints (lanes stop at different octaves,
        // some at none) plus a scalar tail; results must be bit-identical.
        let p: Vec<Vec3> = pts(203, 5.0, 6).map(|(p, _)| p).collect();
        let fw: Vec<f32> = (0..203).map(|i| (i % 13) as f32 * 0.05).collect();
        let o = Octaves::new(5.5, 2.0, 0.5);
        let mut out = vec![0.0; 203];
        turbulence3_slice(&p, &fw, &o, &mut out);
        for i in 0..203 {
            assert_eq!(
                out[i].to_bits(),
                turbulence3(p[i], fw[i], &o).to_bits(),
                "i = {i}"
            );
        }
        fbm3_slice(&p, &fw, &o, &mut out);
        for i in 0..203 {
            assert_eq!(out[i].to_bits(), fbm3(p[i], fw[i], &o).to_bits(), "i = {i}");
        }
        let mut short = vec![0.0; 5];
        turbulence3_slice(&p, &fw[..3], &o, &mut short);
        assert_eq!(short[2], turbulence3(p[2], fw[2], &o));
        assert_eq!(short[3], 0.0);
        let mut vout = vec![Vec3::ZERO; 64];
        vfbm3_slice(&p, &fw, &o, &mut vout);
        assert_eq!(vout[5], vfbm3(p[5], fw[5], &o));
    }
}
