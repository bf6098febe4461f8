//! TIFF output whose alpha says it is premultiplied.
//!
//! Input: interleaved 8-bit, 16-bit or float samples of 1–4 channels, rows top to bottom
//! (native-endian bytes, as the `image` crate takes them). Output: one baseline uncompressed
//! TIFF, written with the `tiff` crate. The pixel bytes are written unchanged; a second or
//! fourth channel is declared associated alpha (`ExtraSamples = 1`).
//!
//! Why not the `image` crate's TIFF encoder: it writes a fourth sample without an
//! `ExtraSamples` tag, so readers must guess what it is, and many (PIL, ImageMagick) take it as
//! unassociated alpha. A RenderMan display's colour is premultiplied by its alpha (RISpec: `Ci`
//! is already multiplied by `Oi`), and PRMan, BMRT and Aqsis mark their TIFFs associated.
//! Without the tag, a reader that converts to straight colour leaves arbor's partially covered
//! pixels darker than the same pixels of theirs: a see-through wire screen looks half as dense
//! as BMRT's render of the same scene. So the colour channels are written as a grey or RGB image
//! and the alpha as its declared extra sample.

use std::io::{Seek, Write};

use tiff::encoder::{colortype, TiffEncoder, TiffValue};
use tiff::tags::ExtraSamples;

/// The sample type of an image: 8- or 16-bit unsigned integers, or 32-bit floats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sample {
    U8,
    U16,
    F32,
}

impl Sample {
    fn bytes(self) -> usize {
        match self {
            Sample::U8 => 1,
            Sample::U16 => 2,
            Sample::F32 => 4,
        }
    }
}

/// Write a `w`×`h` image of `channels` interleaved samples a pixel (1 grey, 2 grey+alpha,
/// 3 RGB, 4 RGBA) from `data` (rows top to bottom, native-endian samples). A second or fourth
/// channel is declared associated alpha.
pub fn write<W: Write + Seek>(
    out: &mut W,
    data: &[u8],
    w: usize,
    h: usize,
    channels: usize,
    sample: Sample,
) -> Result<(), String> {
    if !(1..=4).contains(&channels) {
        return Err(format!("tiff holds 1 to 4 channels, not {channels}"));
    }
    let need = w * h * channels * sample.bytes();
    if data.len() != need {
        return Err(format!(
            "tiff pixel data is {} bytes, {w}x{h}x{channels} needs {need}",
            data.len()
        ));
    }
    let (w, h) = (
        u32::try_from(w).map_err(|e| e.to_string())?,
        u32::try_from(h).map_err(|e| e.to_string())?,
    );
    let alpha = channels == 2 || channels == 4;
    let colour = channels >= 3;
    match sample {
        Sample::U8 => put(out, w, h, alpha, colour, data),
        Sample::U16 => {
            let v: Vec<u16> = data
                .chunks_exact(2)
                .map(|b| u16::from_ne_bytes([b[0], b[1]]))
                .collect();
            put(out, w, h, alpha, colour, &v)
        }
        Sample::F32 => {
            let v: Vec<f32> = data
                .chunks_exact(4)
                .map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            put(out, w, h, alpha, colour, &v)
        }
    }
}

/// The sample types the crate writes as grey or RGB of the same sample, so the alpha can be
/// added as an extra sample.
trait Samples: Sized {
    type Grey: colortype::ColorType<Inner = Self>;
    type Rgb: colortype::ColorType<Inner = Self>;
}
impl Samples for u8 {
    type Grey = colortype::Gray8;
    type Rgb = colortype::RGB8;
}
impl Samples for u16 {
    type Grey = colortype::Gray16;
    type Rgb = colortype::RGB16;
}
impl Samples for f32 {
    type Grey = colortype::Gray32Float;
    type Rgb = colortype::RGB32Float;
}

fn put<W: Write + Seek, T: Samples>(
    out: &mut W,
    w: u32,
    h: u32,
    alpha: bool,
    colour: bool,
    data: &[T],
) -> Result<(), String>
where
    [T]: TiffValue,
{
    if colour {
        put_as::<W, T::Rgb>(out, w, h, alpha, data)
    } else {
        put_as::<W, T::Grey>(out, w, h, alpha, data)
    }
}

fn put_as<W: Write + Seek, C: colortype::ColorType>(
    out: &mut W,
    w: u32,
    h: u32,
    alpha: bool,
    data: &[C::Inner],
) -> Result<(), String>
where
    [C::Inner]: TiffValue,
{
    let mut run = || -> tiff::TiffResult<()> {
        let mut enc = TiffEncoder::new(&mut *out)?;
        let mut img = enc.new_image::<C>(w, h)?;
        if alpha {
            img.extra_samples(&[ExtraSamples::AssociatedAlpha])?;
        }
        img.write_data(data)
    };
    run().map_err(|e| e.to_string())
}

/// PRMan's private TIFF tags for the camera a depth picture was rendered from: world to
/// screen and world to camera, 16 floats each (as `tiffinfo` shows them on PRMan's `z`
/// TIFFs). arbor writes them in its zfile order (row-major) so `MakeShadow` can read a depth
/// TIFF back into a shadow map.
pub const TAG_WORLD_TO_SCREEN: u16 = 33305;
pub const TAG_WORLD_TO_CAMERA: u16 = 33306;

/// Writes a one-channel 32-bit float depth TIFF (`Display "x.tif" "file" "z"`), with the
/// camera matrices `(camera_from_world, screen_from_world)` as PRMan's matrix tags.
pub fn write_depth<W: Write + Seek>(
    out: &mut W,
    depths: &[f32],
    w: usize,
    h: usize,
    matrices: Option<([f32; 16], [f32; 16])>,
) -> Result<(), String> {
    if depths.len() != w * h {
        return Err(format!(
            "depth tiff has {} values, {w}x{h} needs {}",
            depths.len(),
            w * h
        ));
    }
    let (w, h) = (
        u32::try_from(w).map_err(|e| e.to_string())?,
        u32::try_from(h).map_err(|e| e.to_string())?,
    );
    let mut run = || -> tiff::TiffResult<()> {
        let mut enc = TiffEncoder::new(&mut *out)?;
        let mut img = enc.new_image::<colortype::Gray32Float>(w, h)?;
        if let Some((camera, screen)) = matrices {
            let dir = img.encoder();
            dir.write_tag(tiff::tags::Tag::Unknown(TAG_WORLD_TO_CAMERA), &camera[..])?;
            dir.write_tag(tiff::tags::Tag::Unknown(TAG_WORLD_TO_SCREEN), &screen[..])?;
        }
        img.write_data(depths)
    };
    run().map_err(|e| e.to_string())
}

/// Reads a one-channel float depth TIFF written by [`write_depth`] (or PRMan's `z` TIFFs
/// with the same tags) as a zfile: depths and, when both tags are there, the matrices.
pub fn read_depth(bytes: &[u8]) -> Result<super::zfile::ZFile, String> {
    use tiff::decoder::{Decoder, DecodingResult};
    let mut d = Decoder::new(std::io::Cursor::new(bytes)).map_err(|e| e.to_string())?;
    let (width, height) = d.dimensions().map_err(|e| e.to_string())?;
    let matrix = |d: &mut Decoder<_>, tag: u16| -> Option<[f32; 16]> {
        let v = d
            .get_tag_f32_vec(tiff::tags::Tag::Unknown(tag))
            .ok()
            .filter(|v| v.len() == 16)?;
        let mut a = [0f32; 16];
        a.copy_from_slice(&v);
        Some(a)
    };
    let camera = matrix(&mut d, TAG_WORLD_TO_CAMERA);
    let screen = matrix(&mut d, TAG_WORLD_TO_SCREEN);
    let depths = match d.read_image().map_err(|e| e.to_string())? {
        DecodingResult::F32(v) => v,
        _ => return Err("not a float depth picture (32-bit float samples)".into()),
    };
    if depths.len() != width as usize * height as usize {
        return Err("not a one-channel depth picture".into());
    }
    Ok(super::zfile::ZFile {
        width,
        height,
        matrices: camera.zip(screen),
        depths,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value of a one-number tag, read back with the crate's decoder.
    fn tag(bytes: &[u8], want: tiff::tags::Tag) -> Option<u32> {
        let mut d = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).unwrap();
        d.find_tag(want).unwrap().map(|v| v.into_u32().unwrap())
    }

    #[test]
    fn rgba_declares_associated_alpha_and_reads_back() {
        // Premultiplied: half-covered white is (128,128,128,128).
        let px: Vec<u8> = (0..3 * 5).flat_map(|i| [i as u8, 128, 7, 128]).collect();
        let mut buf = std::io::Cursor::new(Vec::new());
        write(&mut buf, &px, 5, 3, 4, Sample::U8).unwrap();
        // ExtraSamples = 1: associated alpha.
        assert_eq!(tag(buf.get_ref(), tiff::tags::Tag::ExtraSamples), Some(1));
        let img = image::load_from_memory(buf.get_ref()).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (5, 3));
        assert_eq!(img.get_pixel(4, 2).0, [14, 128, 7, 128]);
    }

    #[test]
    fn rgb_has_no_extra_samples_and_reads_back() {
        // 700 rows of 300 bytes (the crate picks the strips).
        let (w, h) = (100, 700);
        let px: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
        let mut buf = std::io::Cursor::new(Vec::new());
        write(&mut buf, &px, w, h, 3, Sample::U8).unwrap();
        assert!(tag(buf.get_ref(), tiff::tags::Tag::ExtraSamples).is_none());
        let img = image::load_from_memory(buf.get_ref()).unwrap().to_rgb8();
        assert_eq!(img.into_raw(), px);
    }

    #[test]
    fn sixteen_bit_grey_and_float_rgba_read_back() {
        let g: Vec<u8> = [0u16, 1000, 65535, 7]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        let mut buf = std::io::Cursor::new(Vec::new());
        write(&mut buf, &g, 2, 2, 1, Sample::U16).unwrap();
        let img = image::load_from_memory(buf.get_ref()).unwrap().to_luma16();
        assert_eq!(img.into_raw(), vec![0, 1000, 65535, 7]);

        let f = [0.25f32, -1.0, 3.5, 0.5];
        let bytes: Vec<u8> = f.iter().flat_map(|v| v.to_ne_bytes()).collect();
        let mut buf = std::io::Cursor::new(Vec::new());
        write(&mut buf, &bytes, 1, 1, 4, Sample::F32).unwrap();
        let img = image::load_from_memory(buf.get_ref()).unwrap().to_rgba32f();
        assert_eq!(img.get_pixel(0, 0).0, f);
    }

    #[test]
    fn depth_tiff_keeps_floats_and_camera_matrices() {
        let mut cam = [0f32; 16];
        cam[0] = 1.0;
        cam[3] = -2.5;
        let mut scr = [0f32; 16];
        scr[5] = 3.0;
        let z = [1.5f32, f32::INFINITY, 4.25, 9.0, 0.125, 2.0];
        let mut buf = std::io::Cursor::new(Vec::new());
        write_depth(&mut buf, &z, 3, 2, Some((cam, scr))).unwrap();
        let back = read_depth(buf.get_ref()).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        assert_eq!(back.depths, z.to_vec());
        assert_eq!(back.matrices, Some((cam, scr)));
        // Without matrices it still reads, and says it has none.
        let mut buf = std::io::Cursor::new(Vec::new());
        write_depth(&mut buf, &z, 3, 2, None).unwrap();
        assert_eq!(read_depth(buf.get_ref()).unwrap().matrices, None);
        // An 8-bit picture is not a depth picture.
        let mut buf = std::io::Cursor::new(Vec::new());
        write(&mut buf, &[0; 6], 3, 2, 1, Sample::U8).unwrap();
        assert!(read_depth(buf.get_ref()).is_err());
    }

    #[test]
    fn bad_sizes_are_errors_not_panics() {
        let mut buf = std::io::Cursor::new(Vec::new());
        assert!(write(&mut buf, &[0; 5], 2, 1, 3, Sample::U8).is_err());
        assert!(write(&mut buf, &[], 0, 0, 5, Sample::U8).is_err());
        assert!(buf.get_ref().is_empty());
    }
}
