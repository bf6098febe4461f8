//! RenderMan pixel filters (RISpec §4.1 `PixelFilter`).
//!
//! Input: a [`crate::scene::PixelFilter`] (name, xwidth, ywidth). Output: a [`Filter`] that
//! evaluates the weight of a sample at offset (x, y) from a pixel centre.
//! Invariants: every filter is zero outside its support |x| ≤ xwidth/2, |y| ≤ ywidth/2, and
//! symmetric in x and in y. Weights are not normalised here: the resolver divides by the sum of
//! the weights it actually used, so a constant image stays constant whatever the filter.
//!
//! Shapes follow the spec's reference functions as Aqsis and Pixie implement them:
//! * `box` 1; `triangle` (1 − |x|/(xw/2))·(1 − |y|/(yw/2)) (the spec's misprint corrected);
//! * `gaussian` exp(−2((2x/xw)² + (2y/yw)²));
//! * `catmull-rom` radial in absolute units as in the spec (zero for r ≥ 2, so its natural
//!   width is 4; narrower widths truncate it);
//! * `sinc` separable sin(πx)/(πx) with Aqsis/Pixie's cosine window cos(πx/(2·xw));
//! * `mitchell` separable Mitchell–Netravali with B = C = 1/3, its [−2, 2] support stretched to
//!   the filter width (as pbrt does; Aqsis maps only the central lobe onto the width);
//! * `disk` 1 inside the ellipse of the widths;
//! * `bessel` 2·J₁(πr)/r inside the ellipse, with a half-cosine window (Aqsis).
//!
//! PRMan's and 3Delight's further names, which exporters write (Ayam, K-3D, RfM scripts):
//! * `separable-catmull-rom` the cubic Catmull–Rom kernel per axis in absolute units (zero
//!   from |x| = 2: natural width 4), RenderMan's `RiSeparableCatmullRomFilter`;
//! * `blackman-harris` the four-term Blackman–Harris window per axis, spread over the width;
//! * `lanczos` sinc(x)·sinc(x/a) per axis with a = width/2 lobes (width 4 is Lanczos-2).

use crate::diag::{did_you_mean, Diag, Diagnostics};
use crate::scene::PixelFilter;

/// The filter families RenderMan names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterKind {
    Box,
    Triangle,
    CatmullRom,
    Gaussian,
    Sinc,
    Mitchell,
    Disk,
    Bessel,
    SeparableCatmullRom,
    BlackmanHarris,
    Lanczos,
}

/// RenderMan names of the filters, in [`FilterKind`] order.
pub const FILTER_NAMES: [&str; 11] = [
    "box",
    "triangle",
    "catmull-rom",
    "gaussian",
    "sinc",
    "mitchell",
    "disk",
    "bessel",
    "separable-catmull-rom",
    "blackman-harris",
    "lanczos",
];

impl FilterKind {
    /// The kind for a RenderMan filter name (also accepting `catmullrom` and the `Ri…Filter`
    /// C names); `None` when unknown.
    pub fn from_name(name: &str) -> Option<FilterKind> {
        let n = name.trim().to_ascii_lowercase();
        let n = n
            .strip_prefix("ri")
            .and_then(|s| s.strip_suffix("filter"))
            .unwrap_or(&n);
        Some(match n {
            "box" => FilterKind::Box,
            "triangle" => FilterKind::Triangle,
            "catmull-rom" | "catmullrom" | "catmull_rom" => FilterKind::CatmullRom,
            "gaussian" => FilterKind::Gaussian,
            "sinc" => FilterKind::Sinc,
            "mitchell" => FilterKind::Mitchell,
            "disk" => FilterKind::Disk,
            "bessel" => FilterKind::Bessel,
            "separable-catmull-rom" | "separablecatmullrom" | "separable_catmull_rom" => {
                FilterKind::SeparableCatmullRom
            }
            "blackman-harris" | "blackmanharris" | "blackman_harris" => FilterKind::BlackmanHarris,
            "lanczos" => FilterKind::Lanczos,
            _ => return None,
        })
    }
}

/// A pixel filter ready to evaluate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filter {
    pub kind: FilterKind,
    pub xwidth: f32,
    pub ywidth: f32,
    /// Half widths: the support is |x| ≤ hx, |y| ≤ hy.
    hx: f32,
    hy: f32,
}

impl Filter {
    /// A filter of `kind`; widths below a tiny positive value are raised to it so that
    /// evaluation never divides by zero.
    pub fn new(kind: FilterKind, xwidth: f32, ywidth: f32) -> Filter {
        let fix = |w: f32| if w.is_finite() && w > 1e-4 { w } else { 1e-4 };
        let (xwidth, ywidth) = (fix(xwidth), fix(ywidth));
        Filter {
            kind,
            xwidth,
            ywidth,
            hx: 0.5 * xwidth,
            hy: 0.5 * ywidth,
        }
    }

    /// The filter a scene asks for, without diagnostics (unknown names give the gaussian).
    pub fn from_scene(pf: &PixelFilter) -> Filter {
        let kind = FilterKind::from_name(&pf.name).unwrap_or(FilterKind::Gaussian);
        Filter::new(kind, pf.xwidth, pf.ywidth)
    }

    /// The filter a scene asks for, warning about unknown names (→ gaussian) and unusable
    /// widths. Call once per frame; [`Filter::from_scene`] is the silent version.
    pub fn resolve(pf: &PixelFilter, diags: &Diagnostics) -> Filter {
        let kind = match FilterKind::from_name(&pf.name) {
            Some(k) => k,
            None => {
                let mut d = Diag::warning(
                    "film::filter",
                    format!("unknown pixel filter `{}`; using gaussian", pf.name),
                );
                d = match did_you_mean(&pf.name, FILTER_NAMES) {
                    Some(s) => d.help(format!("did you mean `{s}`?")),
                    None => d.help(format!("known filters: {}", FILTER_NAMES.join(", "))),
                };
                diags.report(d);
                FilterKind::Gaussian
            }
        };
        let ok = |w: f32| w.is_finite() && w > 0.0;
        if !ok(pf.xwidth) || !ok(pf.ywidth) {
            diags.report(
                Diag::warning(
                    "film::filter",
                    format!(
                        "PixelFilter widths {} {} must be positive; using 1 1",
                        pf.xwidth, pf.ywidth
                    ),
                )
                .help("PixelFilter \"name\" xwidth ywidth, e.g. PixelFilter \"gaussian\" 2 2"),
            );
            return Filter::new(kind, 1.0, 1.0);
        }
        Filter::new(kind, pf.xwidth, pf.ywidth)
    }

    /// Half widths (hx, hy) of the support.
    pub fn radius(&self) -> (f32, f32) {
        (self.hx, self.hy)
    }

    /// True when the weight is `eval_x(x) · eval_y(y)`.
    pub fn is_separable(&self) -> bool {
        matches!(
            self.kind,
            FilterKind::Box
                | FilterKind::Triangle
                | FilterKind::Gaussian
                | FilterKind::Sinc
                | FilterKind::Mitchell
                | FilterKind::SeparableCatmullRom
                | FilterKind::BlackmanHarris
                | FilterKind::Lanczos
        )
    }

    /// The x factor of a separable filter (0 outside the support). For non-separable filters
    /// this is the support indicator only.
    #[inline]
    pub fn eval_x(&self, x: f32) -> f32 {
        eval_1d(self.kind, x, self.xwidth, self.hx)
    }

    /// The y factor of a separable filter (see [`Filter::eval_x`]).
    #[inline]
    pub fn eval_y(&self, y: f32) -> f32 {
        eval_1d(self.kind, y, self.ywidth, self.hy)
    }

    /// Weight of a sample at offset (x, y) from the pixel centre (0 outside the support).
    #[inline]
    pub fn eval(&self, x: f32, y: f32) -> f32 {
        if x.abs() > self.hx || y.abs() > self.hy {
            return 0.0;
        }
        if self.is_separable() {
            return self.eval_x(x) * self.eval_y(y);
        }
        match self.kind {
            FilterKind::CatmullRom => {
                let r2 = x * x + y * y;
                let r = r2.sqrt();
                if r < 1.0 {
                    3.0 * r * r2 - 5.0 * r2 + 2.0
                } else if r < 2.0 {
                    -r * r2 + 5.0 * r2 - 8.0 * r + 4.0
                } else {
                    0.0
                }
            }
            FilterKind::Disk => {
                let d = (x / self.hx).powi(2) + (y / self.hy).powi(2);
                if d < 1.0 {
                    1.0
                } else {
                    0.0
                }
            }
            FilterKind::Bessel => {
                let w = (x / self.hx).powi(2) + (y / self.hy).powi(2);
                if w >= 1.0 {
                    return 0.0;
                }
                let d = ((x * x + y * y) as f64).sqrt();
                if d == 0.0 {
                    // lim 2·J1(πd)/d = π
                    return std::f32::consts::PI;
                }
                let window = (0.5 * std::f64::consts::PI * (w as f64).sqrt()).cos();
                (window * 2.0 * bessel_j1(std::f64::consts::PI * d) / d) as f32
            }
            _ => unreachable!("separable kinds handled above"),
        }
    }
}

/// Table entries per unit of the normalised offset |x|/h (at least; see [`Table1d::new`]).
const TABLE_STEPS: usize = 2048;

/// One axis of a separable filter tabulated on |x| ∈ [0, h] and read with linear
/// interpolation: a pixel filter's inner loop pays two table reads instead of an `exp`
/// (gaussian) or `sin`/`cos` (sinc) per sample and pixel.
///
/// Invariant: only offsets inside the support (|x| ≤ h) are looked up — callers find the
/// pixels a sample reaches exactly, so the table never decides the support. Error against
/// [`Filter::eval_x`]: at most Δu²/8 · max|f''| with Δu = 1/steps in units of h, plus f32
/// rounding — below 3e-6 of f(0) for every RenderMan filter at widths up to 16 (tested; most
/// are below 1e-6), some thousand times below 1/255. Box and
/// triangle are linear between nodes, so they come out exact up to rounding.
#[derive(Clone, Debug, PartialEq)]
pub struct Table1d {
    /// `steps + 2` values: f(i·h/steps) for i ≤ steps, then f(h) again (read with weight 0).
    t: Vec<f32>,
    /// steps / h.
    scale: f32,
    steps: i32,
}

impl Table1d {
    fn new(kind: FilterKind, width: f32, h: f32) -> Table1d {
        // Wider filters oscillate more (sinc): keep the node spacing at most 1/1024 pixel.
        let steps = TABLE_STEPS.max((h.min(64.0) * 1024.0).ceil() as usize);
        let mut t = Vec::with_capacity(steps + 2);
        for i in 0..=steps {
            let x = (i as f64 / steps as f64 * h as f64) as f32;
            t.push(eval_1d(kind, x.min(h), width, h));
        }
        t.push(t[steps]);
        Table1d {
            t,
            scale: steps as f32 / h,
            steps: steps as i32,
        }
    }

    /// The raw table (`steps + 2` values), `steps / h` and `steps`, for vectorised lookups that
    /// must give [`Table1d::at`]'s bits.
    pub(crate) fn parts(&self) -> (&[f32], f32, i32) {
        (&self.t, self.scale, self.steps)
    }

    /// f(x) for |x| ≤ h, interpolated.
    #[inline(always)]
    pub fn at(&self, x: f32) -> f32 {
        let u = x.abs() * self.scale;
        // u ≥ 0 and at most about `steps`: the i32 cast is one instruction (usize is not).
        let i = (u as i32).min(self.steps);
        let f = u - i as f32;
        let i = i as usize;
        // Both reads are in bounds: i ≤ steps and the table holds steps + 2 values.
        let a = self.t[i];
        let b = self.t[i + 1];
        a + f * (b - a)
    }
}

/// Both axes of a separable filter as [`Table1d`]s (one shared table when the widths agree).
#[derive(Clone, Debug, PartialEq)]
pub struct FilterTables {
    pub x: Table1d,
    pub y: Table1d,
}

impl Filter {
    /// Tabulated axes of a separable filter; `None` for the radial ones (catmull-rom, disk,
    /// bessel), which keep evaluating [`Filter::eval`] in two dimensions.
    pub fn tables(&self) -> Option<FilterTables> {
        if !self.is_separable() {
            return None;
        }
        let x = Table1d::new(self.kind, self.xwidth, self.hx);
        let y = if self.ywidth == self.xwidth {
            x.clone()
        } else {
            Table1d::new(self.kind, self.ywidth, self.hy)
        };
        Some(FilterTables { x, y })
    }
}

/// One axis of a separable filter; `h` = width/2.
#[inline]
fn eval_1d(kind: FilterKind, x: f32, width: f32, h: f32) -> f32 {
    let ax = x.abs();
    if ax > h {
        return 0.0;
    }
    match kind {
        FilterKind::Triangle => (1.0 - ax / h).max(0.0),
        FilterKind::Gaussian => {
            let u = ax / h; // 2x / width
            (-2.0 * u * u).exp()
        }
        FilterKind::Sinc => {
            if ax == 0.0 {
                1.0
            } else {
                let px = std::f32::consts::PI * ax;
                (0.5 * px / width).cos() * px.sin() / px
            }
        }
        FilterKind::Mitchell => mitchell_1d(2.0 * ax / h),
        FilterKind::SeparableCatmullRom => {
            if ax < 1.0 {
                (1.5 * ax - 2.5) * ax * ax + 1.0
            } else if ax < 2.0 {
                ((-0.5 * ax + 2.5) * ax - 4.0) * ax + 2.0
            } else {
                0.0
            }
        }
        FilterKind::BlackmanHarris => {
            // Centred on the pixel: the window's odd terms change sign, and it falls to
            // 6e-5 at the support's edge.
            let u = 2.0 * std::f64::consts::PI * (ax / width) as f64;
            (0.35875 + 0.48829 * u.cos() + 0.14128 * (2.0 * u).cos() + 0.01168 * (3.0 * u).cos())
                as f32
        }
        FilterKind::Lanczos => sinc(ax) * sinc(ax / h),
        // Box, and the support indicator of the radial filters.
        _ => 1.0,
    }
}

/// sin(πx)/(πx), 1 at 0.
#[inline]
fn sinc(x: f32) -> f32 {
    if x.abs() < 1e-6 {
        1.0
    } else {
        let px = std::f32::consts::PI * x;
        px.sin() / px
    }
}

/// Mitchell–Netravali cubic with B = C = 1/3 on |t| ≤ 2 (integrates to 1 over [−2, 2]).
#[inline]
fn mitchell_1d(t: f32) -> f32 {
    const B: f32 = 1.0 / 3.0;
    const C: f32 = 1.0 / 3.0;
    let t = t.abs();
    let v = if t < 1.0 {
        (12.0 - 9.0 * B - 6.0 * C) * t * t * t
            + (-18.0 + 12.0 * B + 6.0 * C) * t * t
            + (6.0 - 2.0 * B)
    } else if t < 2.0 {
        (-B - 6.0 * C) * t * t * t
            + (6.0 * B + 30.0 * C) * t * t
            + (-12.0 * B - 48.0 * C) * t
            + (8.0 * B + 24.0 * C)
    } else {
        0.0
    };
    v * (1.0 / 6.0)
}

/// Bessel function of the first kind, order 1: power series for |x| < 20, Hankel asymptotic
/// expansion beyond (absolute error well below 1e-6 everywhere).
pub fn bessel_j1(x: f64) -> f64 {
    let ax = x.abs();
    let v = if ax < 20.0 {
        // Σ (−1)^k (x/2)^(2k+1) / (k! (k+1)!)
        let h = 0.5 * ax;
        let h2 = h * h;
        let mut term = h;
        let mut sum = term;
        let mut k = 0.0;
        loop {
            k += 1.0;
            term *= -h2 / (k * (k + 1.0));
            sum += term;
            if term.abs() < 1e-17 * sum.abs().max(1e-300) && k > h {
                break;
            }
            if k > 200.0 {
                break;
            }
        }
        sum
    } else {
        let z = ax;
        let p = 1.0 + 0.117_187_5 / (z * z);
        let q = 0.375 / z - 0.102_539_062_5 / (z * z * z);
        let chi = z - 0.75 * std::f64::consts::PI;
        (2.0 / (std::f64::consts::PI * z)).sqrt() * (p * chi.cos() - q * chi.sin())
    };
    if x < 0.0 {
        -v
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [FilterKind; 11] = [
        FilterKind::Box,
        FilterKind::Triangle,
        FilterKind::CatmullRom,
        FilterKind::Gaussian,
        FilterKind::Sinc,
        FilterKind::Mitchell,
        FilterKind::Disk,
        FilterKind::Bessel,
        FilterKind::SeparableCatmullRom,
        FilterKind::BlackmanHarris,
        FilterKind::Lanczos,
    ];

    /// Midpoint-rule integral over the support.
    fn integral(f: &Filter, n: usize) -> f64 {
        let (hx, hy) = f.radius();
        let (dx, dy) = (2.0 * hx as f64 / n as f64, 2.0 * hy as f64 / n as f64);
        let mut s = 0.0;
        for j in 0..n {
            for i in 0..n {
                let x = -hx as f64 + (i as f64 + 0.5) * dx;
                let y = -hy as f64 + (j as f64 + 0.5) * dy;
                s += f.eval(x as f32, y as f32) as f64;
            }
        }
        s * dx * dy
    }

    #[test]
    fn names_resolve() {
        for (i, n) in FILTER_NAMES.iter().enumerate() {
            assert_eq!(FilterKind::from_name(n), Some(ALL[i]));
        }
        assert_eq!(
            FilterKind::from_name("RiCatmullRomFilter"),
            Some(FilterKind::CatmullRom)
        );
        assert_eq!(FilterKind::from_name("zmin"), None);
    }

    #[test]
    fn unknown_name_warns_and_gives_gaussian() {
        let d = Diagnostics::new();
        let pf = PixelFilter {
            name: "gausian".into(),
            xwidth: 2.0,
            ywidth: 2.0,
        };
        let f = Filter::resolve(&pf, &d);
        assert_eq!(f.kind, FilterKind::Gaussian);
        let s = d.snapshot();
        assert_eq!(s.len(), 1);
        assert!(s[0].0.message.contains("gausian"));
        assert_eq!(s[0].0.help.as_deref(), Some("did you mean `gaussian`?"));
    }

    #[test]
    fn every_filter_is_symmetric_and_zero_outside_support() {
        for &k in &ALL {
            let f = Filter::new(k, 3.0, 2.5);
            for &(x, y) in &[(0.3f32, 0.2f32), (1.1, 0.7), (0.05, 1.2), (1.4, 1.1)] {
                let v = f.eval(x, y);
                assert_eq!(v, f.eval(-x, y), "{k:?} x-symmetry");
                assert_eq!(v, f.eval(x, -y), "{k:?} y-symmetry");
                assert_eq!(v, f.eval(-x, -y), "{k:?} point symmetry");
            }
            assert_eq!(f.eval(1.51, 0.0), 0.0, "{k:?}");
            assert_eq!(f.eval(0.0, 1.26), 0.0, "{k:?}");
            assert!(f.eval(0.0, 0.0) > 0.0, "{k:?} positive at centre");
        }
    }

    #[test]
    fn separable_filters_factor() {
        for &k in &ALL {
            let f = Filter::new(k, 4.0, 3.0);
            if !f.is_separable() {
                continue;
            }
            for &(x, y) in &[(0.3f32, 0.2f32), (1.7, 0.9), (0.0, 1.4)] {
                assert!((f.eval(x, y) - f.eval_x(x) * f.eval_y(y)).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn integrals_match_analytic_values() {
        let n = 800;
        // box: the area of the support
        let f = Filter::new(FilterKind::Box, 2.0, 3.0);
        assert!((integral(&f, n) - 6.0).abs() < 1e-6);
        // triangle: (w/2)·(h/2)
        let f = Filter::new(FilterKind::Triangle, 2.0, 4.0);
        assert!((integral(&f, n) - 2.0).abs() < 1e-4);
        // gaussian: per axis (w/2)·√(π/2)·erf(√2), erf(√2) = 0.954499736…
        let g1 = (std::f64::consts::PI / 2.0).sqrt() * 0.954_499_736_103_642;
        let f = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        assert!((integral(&f, n) - g1 * g1).abs() < 1e-4);
        // mitchell: the kernel integrates to 1 over [−2, 2], stretched by width/4 per axis
        let f = Filter::new(FilterKind::Mitchell, 4.0, 2.0);
        assert!((integral(&f, n) - 0.5).abs() < 1e-4);
        // disk: the ellipse's area π·hx·hy
        let f = Filter::new(FilterKind::Disk, 2.0, 3.0);
        assert!((integral(&f, n) - std::f64::consts::PI * 1.5).abs() < 1e-2);
        // catmull-rom (radial, spec scale 2×): ∫ 2π r k(r) dr over r < 2
        //   = 2π[∫0..1 (3r⁴−5r³+2r) + ∫1..2 (−r⁴+5r³−8r²+4r)] = 2π(7/20 − 7/60) = 7π/15
        let f = Filter::new(FilterKind::CatmullRom, 4.0, 4.0);
        assert!((integral(&f, n) - 7.0 * std::f64::consts::PI / 15.0).abs() < 1e-3);
    }

    #[test]
    fn known_point_values() {
        let g = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        assert!((g.eval(1.0, 0.0) - (-2.0f32).exp()).abs() < 1e-7);
        let t = Filter::new(FilterKind::Triangle, 2.0, 2.0);
        assert_eq!(t.eval(0.0, 0.0), 1.0);
        assert!((t.eval(0.5, 0.5) - 0.25).abs() < 1e-7);
        let c = Filter::new(FilterKind::CatmullRom, 4.0, 4.0);
        assert_eq!(c.eval(0.0, 0.0), 2.0);
        assert!(c.eval(1.0, 0.0).abs() < 1e-6);
        assert!(c.eval(1.5, 0.0) < 0.0, "negative lobe");
        let m = Filter::new(FilterKind::Mitchell, 4.0, 4.0);
        assert!((m.eval(0.0, 0.0) - (8.0f32 / 9.0).powi(2)).abs() < 1e-6);
        let s = Filter::new(FilterKind::Sinc, 4.0, 4.0);
        assert!(s.eval(1.0, 0.0).abs() < 1e-6, "sinc zero at integers");
        let b = Filter::new(FilterKind::Bessel, 3.0, 3.0);
        assert!((b.eval(0.0, 0.0) - std::f32::consts::PI).abs() < 1e-6);
        // continuity at the centre: 2·J1(πd)/d → π
        assert!((b.eval(1e-3, 0.0) - std::f32::consts::PI).abs() < 1e-3);
        // PRMan's separable Catmull-Rom: 1 at the centre, 0 at ±1, −1/16 at ±1.5 per axis
        let sc = Filter::new(FilterKind::SeparableCatmullRom, 4.0, 4.0);
        assert_eq!(sc.eval(0.0, 0.0), 1.0);
        assert!(sc.eval(1.0, 0.3).abs() < 1e-6);
        assert!((sc.eval_x(1.5) + 0.0625).abs() < 1e-6);
        // Blackman-Harris: 1 at the centre (the coefficients sum to 1), ~0 at the edge
        let bh = Filter::new(FilterKind::BlackmanHarris, 3.0, 3.0);
        assert!((bh.eval(0.0, 0.0) - 1.0).abs() < 1e-6);
        assert!(bh.eval_x(1.5) < 1e-4);
        // Lanczos at width 4 (two lobes): zero at the integers, 1 at the centre
        let l = Filter::new(FilterKind::Lanczos, 4.0, 4.0);
        assert_eq!(l.eval(0.0, 0.0), 1.0);
        assert!(l.eval_x(1.0).abs() < 1e-6);
        assert!(l.eval_x(1.5) < 0.0, "negative lobe");
    }

    #[test]
    fn tables_match_the_analytic_filters() {
        // Worst interpolation error over a dense sweep of the support, relative to f(0).
        for &k in &ALL {
            for &(xw, yw) in &[
                (1.0f32, 1.0f32),
                (2.0, 2.0),
                (3.0, 2.5),
                (4.0, 4.0),
                (8.0, 6.0),
                (16.0, 16.0),
            ] {
                let f = Filter::new(k, xw, yw);
                let Some(t) = f.tables() else {
                    assert!(!f.is_separable(), "{k:?}");
                    continue;
                };
                let (hx, hy) = f.radius();
                let n = 20_011; // not a multiple of the table steps: between nodes
                let mut worst = 0f32;
                for i in 0..=n {
                    let x = hx * i as f32 / n as f32;
                    let y = hy * i as f32 / n as f32;
                    for (tab, v, exact) in [(&t.x, x, f.eval_x(x)), (&t.y, y, f.eval_y(y))] {
                        let e = (tab.at(v) - exact).abs().max((tab.at(-v) - exact).abs());
                        worst = worst.max(e);
                    }
                }
                let scale = f.eval_x(0.0).abs().max(1e-6);
                // The f32 evaluation of the closed forms themselves is good to a few 1e-7.
                assert!(worst / scale < 3e-6, "{k:?} {xw}x{yw}: {worst}");
                // The exact ends: the centre and the support's edge.
                assert!((t.x.at(0.0) - f.eval_x(0.0)).abs() <= 1e-7 * scale, "{k:?}");
                assert!((t.x.at(hx) - f.eval_x(hx)).abs() <= 1e-6 * scale, "{k:?}");
            }
        }
    }

    #[test]
    fn gaussian_table_against_exp() {
        // The common case, against the closed form itself (not eval_x).
        let f = Filter::new(FilterKind::Gaussian, 2.0, 2.0);
        let t = f.tables().unwrap();
        for i in 0..=1000 {
            let x = i as f64 / 1000.0;
            let exact = (-2.0 * x * x).exp();
            assert!((t.x.at(x as f32) as f64 - exact).abs() < 2e-7, "{x}");
        }
        // box and triangle are linear between nodes: exact.
        let b = Filter::new(FilterKind::Box, 1.0, 1.0).tables().unwrap();
        assert_eq!(b.x.at(0.37), 1.0);
        let tr = Filter::new(FilterKind::Triangle, 2.0, 2.0)
            .tables()
            .unwrap();
        assert!((tr.x.at(0.25) - 0.75).abs() < 1e-7);
        assert!(tr.x.at(1.0).abs() < 1e-7);
    }

    #[test]
    fn bessel_j1_known_values() {
        assert!((bessel_j1(1.0) - 0.440_050_585_744_933_5).abs() < 1e-12);
        assert!(
            (bessel_j1(3.831_705_970_207_512) - 0.0).abs() < 1e-10,
            "first zero"
        );
        assert!((bessel_j1(10.0) - 0.043_472_746_168_861_44).abs() < 1e-10);
        assert!((bessel_j1(25.0) - (-0.125_350_249_580_29)).abs() < 1e-6);
        assert!((bessel_j1(20.5) - 0.136_254_688_193_396).abs() < 1e-6);
        assert_eq!(bessel_j1(-1.0), -bessel_j1(1.0));
    }
}
