//! Building the mip-map pyramid (Williams '83; notes pipeline.md §3.7).
//!
//! Input: a level-0 [`Image`] and the wrap modes. Output: every level down to 1×1.
//! Invariants: texel centres sit at (i+½)/size, so each level is the 2×2 ("box") or
//! [1 3 3 1]/8 ("gaussian") average of the one above with no half-texel drift; odd sizes
//! round up (the last row/column is filtered with its wrapped neighbour); the mean of a
//! box-filtered power-of-two pyramid is preserved exactly at every level.

use super::image_in::Image;

/// How lookups outside [0,1] behave (RISpec MakeTexture swrap/twrap).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Periodic,
    Clamp,
    Black,
}

impl Wrap {
    pub fn parse(s: &str) -> Option<Wrap> {
        match s.to_ascii_lowercase().as_str() {
            "periodic" | "repeat" => Some(Wrap::Periodic),
            "clamp" | "edge" => Some(Wrap::Clamp),
            "black" => Some(Wrap::Black),
            _ => None,
        }
    }
    pub fn code(self) -> u32 {
        self as u32
    }
    pub fn from_code(c: u32) -> Wrap {
        match c {
            0 => Wrap::Periodic,
            1 => Wrap::Clamp,
            _ => Wrap::Black,
        }
    }
    /// The texel index for `i` in a row of `n`, or None for black.
    #[inline]
    pub fn index(self, i: i64, n: usize) -> Option<usize> {
        let n = n as i64;
        if (0..n).contains(&i) {
            return Some(i as usize);
        }
        match self {
            Wrap::Periodic => Some(i.rem_euclid(n) as usize),
            Wrap::Clamp => Some(i.clamp(0, n - 1) as usize),
            Wrap::Black => None,
        }
    }
}

/// The downsampling filter used between levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Downsample {
    Box,
    Gaussian,
}

/// All levels, finest first, ending at 1×1.
pub fn build_pyramid(base: Image, swrap: Wrap, twrap: Wrap, filter: Downsample) -> Vec<Image> {
    let mut levels = vec![base];
    loop {
        let last = levels.last().expect("non-empty");
        if last.width <= 1 && last.height <= 1 {
            break;
        }
        let next = downsample(last, swrap, twrap, filter);
        levels.push(next);
    }
    levels
}

fn downsample(src: &Image, swrap: Wrap, twrap: Wrap, filter: Downsample) -> Image {
    let (w, h, nc) = (src.width, src.height, src.nchan);
    let nw = w.div_ceil(2).max(1);
    let nh = h.div_ceil(2).max(1);
    let mut out = Image::new(nw, nh, nc);
    // Taps relative to 2x: box = {0,1}, gaussian = {-1,0,1,2} with weights 1 3 3 1.
    let taps: &[(i64, f32)] = match filter {
        Downsample::Box => &[(0, 0.5), (1, 0.5)],
        Downsample::Gaussian => &[(-1, 0.125), (0, 0.375), (1, 0.375), (2, 0.125)],
    };
    let single_x = w == 1;
    let single_y = h == 1;
    let mut acc = vec![0f32; nc];
    for y in 0..nh {
        for x in 0..nw {
            acc.iter_mut().for_each(|a| *a = 0.0);
            let mut wsum = 0.0;
            for &(dy, wy) in taps {
                let sy = if single_y { 0 } else { 2 * y as i64 + dy };
                // Clamp-to-edge for black borders too: the pyramid keeps the image's own
                // colours at its border, black enters only at lookup time.
                let wrap_y = if twrap == Wrap::Periodic {
                    Wrap::Periodic
                } else {
                    Wrap::Clamp
                };
                let Some(sy) = wrap_y.index(sy, h) else {
                    continue;
                };
                for &(dx, wx) in taps {
                    let sx = if single_x { 0 } else { 2 * x as i64 + dx };
                    let wrap_x = if swrap == Wrap::Periodic {
                        Wrap::Periodic
                    } else {
                        Wrap::Clamp
                    };
                    let Some(sx) = wrap_x.index(sx, w) else {
                        continue;
                    };
                    let wgt = wx * wy;
                    wsum += wgt;
                    for (a, v) in acc.iter_mut().zip(src.px(sx, sy)) {
                        *a += wgt * v;
                    }
                }
            }
            let o = (y * nw + x) * nc;
            for c in 0..nc {
                out.data[o + c] = acc[c] / wsum;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(n: usize) -> Image {
        let mut im = Image::new(n, n, 1);
        for y in 0..n {
            for x in 0..n {
                im.data[y * n + x] = ((x + y) % 2) as f32;
            }
        }
        im
    }

    #[test]
    fn pyramid_of_512_has_10_levels_and_mean_top() {
        let levels = build_pyramid(
            checker(512),
            Wrap::Periodic,
            Wrap::Periodic,
            Downsample::Box,
        );
        assert_eq!(levels.len(), 10);
        assert_eq!(levels[9].width, 1);
        // Any level coarser than the checker period is uniform 0.5.
        assert!(levels[1].data.iter().all(|&v| (v - 0.5).abs() < 1e-6));
        assert!((levels[9].data[0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn gaussian_keeps_constants_and_odd_sizes_round_up() {
        let mut im = Image::new(5, 3, 2);
        im.data.iter_mut().for_each(|v| *v = 0.25);
        let levels = build_pyramid(im, Wrap::Clamp, Wrap::Black, Downsample::Gaussian);
        assert_eq!((levels[1].width, levels[1].height), (3, 2));
        assert_eq!(
            (levels.last().unwrap().width, levels.last().unwrap().height),
            (1, 1)
        );
        for l in &levels {
            assert!(l.data.iter().all(|&v| (v - 0.25).abs() < 1e-6));
        }
    }

    #[test]
    fn wrap_indices() {
        assert_eq!(Wrap::Periodic.index(-1, 4), Some(3));
        assert_eq!(Wrap::Periodic.index(9, 4), Some(1));
        assert_eq!(Wrap::Clamp.index(-3, 4), Some(0));
        assert_eq!(Wrap::Black.index(4, 4), None);
    }
}
