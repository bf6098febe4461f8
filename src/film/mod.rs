//! Film: pixel filtering of hider samples, exposure, imager, quantize/dither and display output.
//!
//! Input: per-bucket [`SampleBuffer`]s from a hider. Output: image files written to a temporary
//! name and renamed. Invariants: filtering a pixel reads only samples inside the filter support,
//! so a bucket renders its pixels plus a margin of the filter radius and the result does not
//! depend on the bucket size.
//!
//! Modules: [`filter`] (the RenderMan filter functions), [`resolve`] (samples → [`Film`]
//! pixels, depth filters), [`gather`] (the vectorised filter for the usual r g b a z
//! buffer), [`quantize`] (exposure, background imager, quantize/dither), [`output`] (display
//! drivers), [`tiff`] (the TIFF writer), [`zfile`] (arbor's depth-image format).

pub mod filter;
pub mod gather;
pub mod output;
pub mod quantize;
pub mod resolve;
pub mod stream;
pub mod tiff;
pub mod zfile;

pub use filter::{Filter, FilterKind};
pub use output::{write_atomically, write_displays, Format};
pub use quantize::{apply_background, apply_exposure};
pub use resolve::{filter_into, filter_region, filter_tile, DepthFilter, Film, Tile};
pub use zfile::ZFile;

/// Samples of one bucket (plus its filter margin), as the hider leaves them.
///
/// Sample `(sx, sy)` of pixel `(px, py)` (pixel coordinates relative to `x0`, `y0`) is at index
/// `((py * width + px) * spp_y + sy) * spp_x + sx`.
#[derive(Clone, Debug, Default)]
pub struct SampleBuffer {
    /// Raster pixel coordinate of the buffer's first pixel (may be negative in the margin).
    pub x0: i32,
    pub y0: i32,
    /// Size in pixels.
    pub width: usize,
    pub height: usize,
    pub spp_x: usize,
    pub spp_y: usize,
    /// Raster-space position of each sample (jittered within its stratum).
    pub positions: Vec<[f32; 2]>,
    /// Floats per sample: r g b a z, then the arbitrary output variables in `Film` order.
    pub channels: usize,
    /// `channels` floats per sample; colours are premultiplied by alpha; z is camera-space depth
    /// of the nearest visible surface (f32::INFINITY where nothing was hit).
    pub values: Vec<f32>,
}

impl SampleBuffer {
    pub fn samples_per_pixel(&self) -> usize {
        self.spp_x * self.spp_y
    }
    pub fn sample_index(&self, px: usize, py: usize, sx: usize, sy: usize) -> usize {
        ((py * self.width + px) * self.spp_y + sy) * self.spp_x + sx
    }
}

impl SampleBuffer {
    /// A buffer covering pixels `[x0, x0+width) × [y0, y0+height)` with every sample at its
    /// stratum centre and every value zero except depth (= +∞), ready for a hider to fill.
    pub fn new(
        x0: i32,
        y0: i32,
        width: usize,
        height: usize,
        spp_x: usize,
        spp_y: usize,
        channels: usize,
    ) -> SampleBuffer {
        let n = width * height * spp_x * spp_y;
        let mut positions = Vec::with_capacity(n);
        for py in 0..height {
            for px in 0..width {
                for sy in 0..spp_y {
                    for sx in 0..spp_x {
                        positions.push([
                            (x0 + px as i32) as f32 + (sx as f32 + 0.5) / spp_x as f32,
                            (y0 + py as i32) as f32 + (sy as f32 + 0.5) / spp_y as f32,
                        ]);
                    }
                }
            }
        }
        let mut values = vec![0.0; n * channels];
        if channels > 4 {
            for v in values.chunks_exact_mut(channels) {
                v[4] = f32::INFINITY;
            }
        }
        SampleBuffer {
            x0,
            y0,
            width,
            height,
            spp_x,
            spp_y,
            positions,
            channels,
            values,
        }
    }

    /// The pixel margin a bucket needs around its region for `filter`: ⌈width/2⌉ each side.
    pub fn margin(filter: &crate::scene::PixelFilter) -> (usize, usize) {
        let m = |w: f32| {
            if w.is_finite() && w > 0.0 {
                (w * 0.5).ceil() as usize
            } else {
                1
            }
        };
        (m(filter.xwidth), m(filter.ywidth))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_buffer_has_stratum_centres_and_infinite_depth() {
        let b = SampleBuffer::new(-1, 2, 3, 2, 2, 2, 6);
        assert_eq!(b.positions.len(), 3 * 2 * 4);
        assert_eq!(b.values.len(), 3 * 2 * 4 * 6);
        // pixel (1, 1) of the buffer is raster pixel (0, 3); sample (1, 0) sits at (0.75, 3.25)
        assert_eq!(b.positions[b.sample_index(1, 1, 1, 0)], [0.75, 3.25]);
        assert_eq!(b.values[4], f32::INFINITY);
        assert_eq!(b.values[3], 0.0);
        let pf = crate::scene::PixelFilter {
            name: "gaussian".into(),
            xwidth: 3.0,
            ywidth: 2.0,
        };
        assert_eq!(SampleBuffer::margin(&pf), (2, 1));
    }
}
