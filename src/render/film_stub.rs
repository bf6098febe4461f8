//! TEMPORARY stand-in for the `film` module's `Film` and `filter_into` (same signatures),
//! until the `film` branch is merged: a box filter over each pixel's own samples.
//! Delete this file after merging `film` and import `crate::film::{Film, filter_into, DepthFilter}`.

use crate::film::SampleBuffer;
use crate::scene::PixelFilter;

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    pub channel_names: Vec<String>,
    pub data: Vec<f32>,
}

impl Film {
    pub fn new(width: usize, height: usize, channel_names: Vec<String>) -> Film {
        let nch = channel_names.len();
        let mut data = vec![0.0; width * height * nch];
        if let Some(z) = channel_names.iter().position(|c| c == "z") {
            for px in data.chunks_exact_mut(nch.max(1)) {
                px[z] = f32::INFINITY;
            }
        }
        Film {
            width,
            height,
            channel_names,
            data,
        }
    }
    pub fn standard_channels(aovs: &[String]) -> Vec<String> {
        let mut v: Vec<String> = ["r", "g", "b", "a", "z"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        v.extend(aovs.iter().cloned());
        v
    }
    pub fn channels(&self) -> usize {
        self.channel_names.len()
    }
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let n = self.channels();
        let i = (y * self.width + x) * n;
        &self.data[i..i + n]
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DepthFilter {
    #[default]
    Min,
    Max,
    Average,
}

#[allow(clippy::too_many_arguments)]
pub fn filter_into(
    film: &mut Film,
    buf: &SampleBuffer,
    _filter: &PixelFilter,
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    depth_filter: DepthFilter,
) {
    let nch = film.channels().min(buf.channels);
    let spp = buf.samples_per_pixel();
    for y in y0..(y0 + h).min(film.height) {
        for x in x0..(x0 + w).min(film.width) {
            let (bx, by) = (x as i32 - buf.x0, y as i32 - buf.y0);
            if bx < 0 || by < 0 || bx as usize >= buf.width || by as usize >= buf.height {
                continue;
            }
            let first = buf.sample_index(bx as usize, by as usize, 0, 0);
            let mut sum = vec![0f64; nch];
            let (mut zmin, mut zmax, mut zsum, mut zn) =
                (f32::INFINITY, f32::NEG_INFINITY, 0f64, 0);
            for s in first..first + spp {
                let v = &buf.values[s * buf.channels..(s + 1) * buf.channels];
                for c in 0..nch {
                    if c != 4 {
                        sum[c] += v[c] as f64;
                    }
                }
                zmin = zmin.min(v[4]);
                zmax = zmax.max(v[4]);
                if v[4].is_finite() {
                    zsum += v[4] as f64;
                    zn += 1;
                }
            }
            let n = film.channels();
            let px = &mut film.data[(y * film.width + x) * n..(y * film.width + x + 1) * n];
            for c in 0..nch {
                px[c] = (sum[c] / spp as f64) as f32;
            }
            px[4] = match depth_filter {
                DepthFilter::Min => zmin,
                DepthFilter::Max => zmax,
                DepthFilter::Average if zn > 0 => (zsum / zn as f64) as f32,
                DepthFilter::Average => f32::INFINITY,
            };
        }
    }
}
