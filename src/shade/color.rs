//! Colour spaces for `color "space" (…)` and `ctransform` (RISpec Table 11.1).
//!
//! Input/output: triples. Invariants: every conversion round-trips with rgb (within float
//! precision); hue is in [0,1).

use glam::Vec3;

pub fn is_space(s: &str) -> bool {
    matches!(s, "rgb" | "hsv" | "hsl" | "xyz" | "XYZ" | "xyY" | "YIQ")
}

pub fn to_rgb(space: &str, c: Vec3) -> Vec3 {
    match space {
        "hsv" => hsv_to_rgb(c),
        "hsl" => hsl_to_rgb(c),
        "xyz" | "XYZ" => xyz_to_rgb(c),
        "xyY" => {
            if c.y == 0.0 {
                Vec3::ZERO
            } else {
                xyz_to_rgb(Vec3::new(
                    c.x * c.z / c.y,
                    c.z,
                    (1.0 - c.x - c.y) * c.z / c.y,
                ))
            }
        }
        // The exact inverse of the RGB->YIQ matrix below (the usual 3-digit inverse is off by
        // ~1e-3, so round trips drifted).
        "YIQ" => Vec3::new(
            c.x + 0.956_170_7 * c.y + 0.621_432_6 * c.z,
            c.x - 0.272_688_6 * c.y - 0.646_813_2 * c.z,
            c.x - 1.103_744_1 * c.y + 1.700_623_1 * c.z,
        ),
        _ => c,
    }
}

pub fn from_rgb(space: &str, c: Vec3) -> Vec3 {
    match space {
        "hsv" => rgb_to_hsv(c),
        "hsl" => rgb_to_hsl(c),
        "xyz" | "XYZ" => rgb_to_xyz(c),
        "xyY" => {
            let x = rgb_to_xyz(c);
            let s = x.x + x.y + x.z;
            if s == 0.0 {
                Vec3::ZERO
            } else {
                Vec3::new(x.x / s, x.y / s, x.y)
            }
        }
        "YIQ" => Vec3::new(
            0.299 * c.x + 0.587 * c.y + 0.114 * c.z,
            0.596 * c.x - 0.274 * c.y - 0.322 * c.z,
            0.211 * c.x - 0.523 * c.y + 0.312 * c.z,
        ),
        _ => c,
    }
}

fn hue_of(c: Vec3, max: f32, delta: f32) -> f32 {
    if delta == 0.0 {
        return 0.0;
    }
    let h = if c.x == max {
        (c.y - c.z) / delta
    } else if c.y == max {
        2.0 + (c.z - c.x) / delta
    } else {
        4.0 + (c.x - c.y) / delta
    };
    (h / 6.0).rem_euclid(1.0)
}

fn rgb_to_hsv(c: Vec3) -> Vec3 {
    let max = c.max_element();
    let min = c.min_element();
    let d = max - min;
    let s = if max > 0.0 { d / max } else { 0.0 };
    Vec3::new(hue_of(c, max, d), s, max)
}

fn hsv_to_rgb(c: Vec3) -> Vec3 {
    let (h, s, v) = (c.x.rem_euclid(1.0) * 6.0, c.y, c.z);
    if s == 0.0 {
        return Vec3::splat(v);
    }
    let i = h.floor();
    let f = h - i;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    match i as i32 {
        0 => Vec3::new(v, t, p),
        1 => Vec3::new(q, v, p),
        2 => Vec3::new(p, v, t),
        3 => Vec3::new(p, q, v),
        4 => Vec3::new(t, p, v),
        _ => Vec3::new(v, p, q),
    }
}

fn rgb_to_hsl(c: Vec3) -> Vec3 {
    let max = c.max_element();
    let min = c.min_element();
    let l = 0.5 * (max + min);
    let d = max - min;
    let s = if d == 0.0 {
        0.0
    } else if l <= 0.5 {
        d / (max + min)
    } else {
        d / (2.0 - max - min)
    };
    Vec3::new(hue_of(c, max, d), s, l)
}

fn hsl_to_rgb(c: Vec3) -> Vec3 {
    let (h, s, l) = (c.x.rem_euclid(1.0), c.y, c.z);
    if s == 0.0 {
        return Vec3::splat(l);
    }
    let q = if l <= 0.5 {
        l * (1.0 + s)
    } else {
        l + s - l * s
    };
    let p = 2.0 * l - q;
    let f = |t: f32| {
        let t = t.rem_euclid(1.0);
        if t < 1.0 / 6.0 {
            p + (q - p) * 6.0 * t
        } else if t < 0.5 {
            q
        } else if t < 2.0 / 3.0 {
            p + (q - p) * (2.0 / 3.0 - t) * 6.0
        } else {
            p
        }
    };
    Vec3::new(f(h + 1.0 / 3.0), f(h), f(h - 1.0 / 3.0))
}

// Rec. 709 primaries, D65 white.
fn rgb_to_xyz(c: Vec3) -> Vec3 {
    Vec3::new(
        0.412453 * c.x + 0.357580 * c.y + 0.180423 * c.z,
        0.212671 * c.x + 0.715160 * c.y + 0.072169 * c.z,
        0.019334 * c.x + 0.119193 * c.y + 0.950227 * c.z,
    )
}

fn xyz_to_rgb(c: Vec3) -> Vec3 {
    Vec3::new(
        3.240479 * c.x - 1.537150 * c.y - 0.498535 * c.z,
        -0.969256 * c.x + 1.875992 * c.y + 0.041556 * c.z,
        0.055648 * c.x - 0.204043 * c.y + 1.057311 * c.z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_spaces_round_trip() {
        let c = Vec3::new(0.8, 0.3, 0.1);
        for s in ["hsv", "hsl", "xyz", "xyY", "YIQ"] {
            let back = to_rgb(s, from_rgb(s, c));
            assert!((back - c).abs().max_element() < 2e-3, "{s}: {back:?}");
        }
        assert!((hsv_to_rgb(Vec3::new(0.0, 1.0, 1.0)) - Vec3::X).length() < 1e-6);
        assert!((hsv_to_rgb(Vec3::new(1.0 / 3.0, 1.0, 1.0)) - Vec3::Y).length() < 1e-5);
    }
}
