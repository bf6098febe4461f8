//! Reading source pictures into float images.
//!
//! Input: a path to anything the `image` crate reads (PNG, TIFF, JPEG, HDR) or an OpenEXR
//! file, 8/16-bit or float, any channel count. Output: an [`Image`] (linear row-major floats,
//! row 0 at the top, 8/16-bit values scaled to 0..1).
//! Invariants: never panics on bad input; errors are a sentence naming the file.

use std::path::Path;

/// A float image: `nchan` interleaved channels, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub nchan: usize,
    pub data: Vec<f32>,
}

impl Image {
    pub fn new(width: usize, height: usize, nchan: usize) -> Image {
        Image {
            width,
            height,
            nchan,
            data: vec![0.0; width * height * nchan],
        }
    }
    #[inline]
    pub fn px(&self, x: usize, y: usize) -> &[f32] {
        let i = (y * self.width + x) * self.nchan;
        &self.data[i..i + self.nchan]
    }
}

/// Reads a picture (by content for EXR, by the `image` crate otherwise).
pub fn read_image(path: &Path) -> Result<Image, String> {
    let bytes =
        std::fs::read(path).map_err(|e| format!("cannot read `{}`: {e}", path.display()))?;
    if bytes.starts_with(&[0x76, 0x2f, 0x31, 0x01]) {
        return read_exr(path);
    }
    let img = image::load_from_memory(&bytes)
        .map_err(|e| format!("cannot decode `{}`: {e}", path.display()))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let nchan = img.color().channel_count() as usize;
    let data: Vec<f32> = match nchan {
        1 => img.to_luma32f().into_raw(),
        2 => img.to_luma_alpha32f().into_raw(),
        3 => img.to_rgb32f().into_raw(),
        _ => img.to_rgba32f().into_raw(),
    };
    let nchan = nchan.min(4);
    Ok(Image {
        width: w,
        height: h,
        nchan,
        data,
    })
}

/// OpenEXR: the first layer, every channel in the file's (alphabetical) order, with R G B A
/// moved to the front in that order so colour lookups find them first.
fn read_exr(path: &Path) -> Result<Image, String> {
    use exr::prelude::{read, ReadChannels, ReadLayers};
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| format!("cannot read OpenEXR `{}`: {e}", path.display()))?;
    let layer = &img.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let chans = &layer.channel_data.list;
    let rank = |n: &str| match n {
        "R" => 0,
        "G" => 1,
        "B" => 2,
        "A" => 3,
        _ => 4,
    };
    let mut order: Vec<usize> = (0..chans.len()).collect();
    order.sort_by_key(|&i| rank(&chans[i].name.to_string()));
    let nchan = chans.len().max(1);
    let mut out = self::Image::new(w, h, nchan);
    for (k, &ci) in order.iter().enumerate() {
        let samples = &chans[ci].sample_data;
        for p in 0..w * h {
            out.data[p * nchan + k] = samples.value_by_flat_index(p).to_f32();
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_gray16_and_rgba8_read_scaled() {
        let dir = std::env::temp_dir().join(format!("arbor-imgin-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("g16.png");
        let g = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(2, 1, vec![0, 65535])
            .unwrap();
        g.save(&p).unwrap();
        let im = read_image(&p).unwrap();
        assert_eq!((im.width, im.height, im.nchan), (2, 1, 1));
        assert_eq!(im.data, vec![0.0, 1.0]);
        let p = dir.join("c8.png");
        let c = image::RgbaImage::from_raw(1, 1, vec![255, 0, 51, 255]).unwrap();
        c.save(&p).unwrap();
        let im = read_image(&p).unwrap();
        assert_eq!(im.nchan, 4);
        assert!((im.data[2] - 0.2).abs() < 1e-6);
        assert!(read_image(&dir.join("missing.png")).is_err());
    }
}
