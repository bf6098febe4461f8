//! Film: pixel filtering of hider samples, exposure, imager, quantize/dither and display output.
//!
//! Input: per-bucket [`SampleBuffer`]s from a hider. Output: image files written to a temporary
//! name and renamed. Invariants: filtering a pixel reads only samples inside the filter support,
//! so a bucket renders its pixels plus a margin of the filter radius and the result does not
//! depend on the bucket size.

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
