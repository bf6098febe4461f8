//! Reading source pictures into float images.
//!
//! Input: a path to anything the `image` crate reads (PNG, TIFF, JPEG, HDR), an OpenEXR
//! file or a PRMan 3.x texture (its finest level), 8/16-bit or float, any channel count.
//! Output: an [`Image`] (linear row-major floats, row 0 at the top, 8/16-bit values scaled
//! to 0..1).
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
    if super::prman_tx::is_prman_tx(&bytes) {
        // A PRMan texture as a source picture: its finest level.
        let t = super::prman_tx::decode(&bytes)
            .map_err(|e| format!("cannot decode PRMan texture `{}`: {e}", path.display()))?;
        return t
            .levels
            .into_iter()
            .next()
            .ok_or_else(|| format!("PRMan texture `{}` has no levels", path.display()));
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

/// The wrap modes a BMRT-made mip-map TIFF records in its ImageDescription ("black black",
/// "periodic clamp", …: s then t), so such a map read as a plain picture wraps as made.
pub fn tiff_wrap_hint(path: &Path) -> Option<(super::mipmap::Wrap, super::mipmap::Wrap)> {
    use super::mipmap::Wrap;
    let bytes = std::fs::read(path).ok()?;
    let desc = tiff_description(&bytes)?;
    let mut words = desc.split_whitespace();
    let s = Wrap::parse(words.next()?)?;
    let t = Wrap::parse(words.next()?)?;
    Some((s, t))
}

/// Tag 270 (ImageDescription) of a TIFF's first directory.
fn tiff_description(b: &[u8]) -> Option<String> {
    let big = match b.get(..4)? {
        [b'I', b'I', 42, 0] => false,
        [b'M', b'M', 0, 42] => true,
        _ => return None,
    };
    let u16_at = |o: usize| -> Option<u32> {
        let x: [u8; 2] = b.get(o..o + 2)?.try_into().ok()?;
        Some(if big {
            u16::from_be_bytes(x)
        } else {
            u16::from_le_bytes(x)
        } as u32)
    };
    let u32_at = |o: usize| -> Option<u32> {
        let x: [u8; 4] = b.get(o..o + 4)?.try_into().ok()?;
        Some(if big {
            u32::from_be_bytes(x)
        } else {
            u32::from_le_bytes(x)
        })
    };
    let ifd = u32_at(4)? as usize;
    let count = u16_at(ifd)? as usize;
    for k in 0..count.min(512) {
        let e = ifd + 2 + 12 * k;
        if u16_at(e)? != 270 || u16_at(e + 2)? != 2 {
            continue;
        }
        let len = u32_at(e + 4)? as usize;
        let at = if len <= 4 {
            e + 8
        } else {
            u32_at(e + 8)? as usize
        };
        let text = b.get(at..at + len)?;
        let text = text.split(|&c| c == 0).next()?;
        return Some(String::from_utf8_lossy(text).into_owned());
    }
    None
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
        let scratch = tempfile::Builder::new()
            .prefix("arbor-imgin-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
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

    /// A one-entry TIFF directory holding only an ImageDescription.
    fn tiff_with_description(big: bool, text: &str) -> Vec<u8> {
        let u16b = |x: u16| {
            if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        };
        let u32b = |x: u32| {
            if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        };
        let mut b: Vec<u8> = if big {
            b"MM\0\x2a".to_vec()
        } else {
            b"II\x2a\0".to_vec()
        };
        b.extend(u32b(8));
        b.extend(u16b(1));
        let mut t = text.as_bytes().to_vec();
        t.push(0);
        b.extend(u16b(270));
        b.extend(u16b(2));
        b.extend(u32b(t.len() as u32));
        b.extend(u32b(8 + 2 + 12 + 4));
        b.extend(u32b(0));
        b.extend(t);
        b
    }

    #[test]
    fn bmrt_wrap_modes_are_read_from_the_tiff_description() {
        assert_eq!(
            tiff_description(&tiff_with_description(true, "black black")).as_deref(),
            Some("black black")
        );
        assert_eq!(
            tiff_description(&tiff_with_description(false, "periodic clamp")).as_deref(),
            Some("periodic clamp")
        );
        assert_eq!(tiff_description(b"\x89PNG...."), None);
        let scratch = tempfile::Builder::new()
            .prefix("arbor-imgin-wrap-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let p = dir.join("hint.tif");
        std::fs::write(&p, tiff_with_description(true, "periodic clamp")).unwrap();
        use super::super::mipmap::Wrap;
        assert_eq!(tiff_wrap_hint(&p), Some((Wrap::Periodic, Wrap::Clamp)));
        std::fs::write(&p, tiff_with_description(false, "the GIMP was here")).unwrap();
        assert_eq!(tiff_wrap_hint(&p), None);
    }
}
