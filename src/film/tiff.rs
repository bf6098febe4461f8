//! Uncompressed TIFF 6.0 writer for display output.
//!
//! Input: interleaved 8-bit, 16-bit or float samples of 1–4 channels, rows top to bottom.
//! Output: one baseline TIFF image (chunky strips of about 64 KiB). Invariants: the pixel
//! bytes are written unchanged (same picture bytes for any thread count or bucket size as
//! the film they come from); a second or fourth channel is declared associated alpha.
//!
//! Why an own writer rather than the `image` crate's encoder: that encoder writes a fourth
//! sample without an `ExtraSamples` tag, so readers must guess what it is, and many (PIL,
//! ImageMagick) take it as unassociated alpha. A RenderMan display's colour is premultiplied by
//! its alpha (RISpec: `Ci` is already multiplied by `Oi`), and PRMan, BMRT and Aqsis mark their
//! TIFFs `ExtraSamples = 1` (associated alpha). Without the tag, a reader that converts to
//! straight colour leaves arbor's partially covered pixels darker than the same pixels of
//! theirs: a see-through wire screen looks half as dense as BMRT's render of the same scene.
//!
//! Layout: header, pixel strips, then the image file directory and the arrays its entries point
//! to. Samples are written in the machine's byte order (the header says which), so 16-bit and
//! float samples arrive here as native-endian bytes, as the `image` crate takes them.

use std::io::Write;

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

/// Target size of one strip: small enough for readers that load a strip at a time.
const STRIP_BYTES: usize = 64 * 1024;

// Field types of TIFF directory entries.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const RATIONAL: u16 = 5;

/// Write a `w`×`h` image of `channels` interleaved samples a pixel (1 grey, 2 grey+alpha,
/// 3 RGB, 4 RGBA) from `data` (rows top to bottom, native-endian samples). A second or fourth
/// channel is declared associated alpha.
pub fn write(
    out: &mut dyn Write,
    data: &[u8],
    w: usize,
    h: usize,
    channels: usize,
    sample: Sample,
) -> Result<(), String> {
    if !(1..=4).contains(&channels) {
        return Err(format!("tiff holds 1 to 4 channels, not {channels}"));
    }
    let row = w * channels * sample.bytes();
    if data.len() != row * h {
        return Err(format!(
            "tiff pixel data is {} bytes, {w}x{h}x{channels} needs {}",
            data.len(),
            row * h
        ));
    }
    let rows_per_strip = (STRIP_BYTES / row.max(1)).clamp(1, h.max(1));
    let strips = h.div_ceil(rows_per_strip).max(1);

    let mut entries: Vec<(u16, u16, Vec<u32>)> = Vec::new();
    let bits = (sample.bytes() * 8) as u32;
    let format = if sample == Sample::F32 { 3 } else { 1 };
    let photometric = if channels >= 3 { 2 } else { 1 };
    let extra = channels == 2 || channels == 4;
    // Offsets are filled in once the directory's place is known.
    entries.push((256, LONG, vec![w as u32]));
    entries.push((257, LONG, vec![h as u32]));
    entries.push((258, SHORT, vec![bits; channels]));
    entries.push((259, SHORT, vec![1])); // no compression
    entries.push((262, SHORT, vec![photometric]));
    entries.push((273, LONG, vec![0; strips])); // strip offsets
    entries.push((277, SHORT, vec![channels as u32]));
    entries.push((278, LONG, vec![rows_per_strip as u32]));
    let counts = (0..strips)
        .map(|i| (rows_per_strip.min(h - i * rows_per_strip) * row) as u32)
        .collect();
    entries.push((279, LONG, counts));
    entries.push((282, RATIONAL, vec![72, 1]));
    entries.push((283, RATIONAL, vec![72, 1]));
    entries.push((284, SHORT, vec![1])); // chunky
    entries.push((296, SHORT, vec![2])); // inch
    if extra {
        entries.push((338, SHORT, vec![1])); // associated alpha
    }
    entries.push((339, SHORT, vec![format; channels]));

    let size = |ty: u16| if ty == SHORT { 2 } else { 4 };
    // A value longer than 4 bytes lives outside the entry (rationals count two longs).
    let outside = |ty: u16, v: &Vec<u32>| v.len() * size(ty) > 4;
    let data_at = 8u64;
    let ifd_at = (data_at + data.len() as u64 + 1) & !1;
    let ifd_len = 2 + 12 * entries.len() as u64 + 4;
    let mut next = ifd_at + ifd_len;
    let mut places = Vec::with_capacity(entries.len());
    for (_, ty, v) in &entries {
        if outside(*ty, v) {
            places.push(next);
            next += ((v.len() * size(*ty)) as u64 + 1) & !1;
        } else {
            places.push(0);
        }
    }
    if next > u32::MAX as u64 {
        return Err(format!(
            "a {w}x{h} picture is too large for tiff (4 GiB); use exr"
        ));
    }
    let offsets = entries.iter_mut().find(|e| e.0 == 273).map(|e| &mut e.2);
    for (i, v) in offsets.into_iter().flatten().enumerate() {
        *v = (data_at as usize + i * rows_per_strip * row) as u32;
    }

    let mut head = Vec::with_capacity(8);
    head.extend_from_slice(if cfg!(target_endian = "little") {
        b"II"
    } else {
        b"MM"
    });
    head.extend_from_slice(&42u16.to_ne_bytes());
    head.extend_from_slice(&(ifd_at as u32).to_ne_bytes());
    // The directory and its arrays, starting with the pad byte after odd-sized pixel data;
    // `buf.len() + base` is the file offset.
    let pad = (ifd_at - data_at) as usize - data.len();
    let base = ifd_at - pad as u64;
    let mut buf: Vec<u8> = vec![0; pad];
    buf.extend_from_slice(&(entries.len() as u16).to_ne_bytes());
    let put = |buf: &mut Vec<u8>, ty: u16, v: u32| {
        if ty == SHORT {
            buf.extend_from_slice(&(v as u16).to_ne_bytes());
        } else {
            buf.extend_from_slice(&v.to_ne_bytes());
        }
    };
    for ((tag, ty, v), at) in entries.iter().zip(&places) {
        buf.extend_from_slice(&tag.to_ne_bytes());
        buf.extend_from_slice(&ty.to_ne_bytes());
        let count = if *ty == RATIONAL {
            v.len() / 2
        } else {
            v.len()
        };
        buf.extend_from_slice(&(count as u32).to_ne_bytes());
        if outside(*ty, v) {
            buf.extend_from_slice(&(*at as u32).to_ne_bytes());
        } else {
            let start = buf.len();
            for &x in v {
                put(&mut buf, *ty, x);
            }
            buf.resize(start + 4, 0);
        }
    }
    buf.extend_from_slice(&0u32.to_ne_bytes()); // no next directory
    for ((_, ty, v), at) in entries.iter().zip(&places) {
        if outside(*ty, v) {
            debug_assert_eq!(buf.len() as u64 + base, *at);
            for &x in v {
                put(&mut buf, *ty, x);
            }
            if buf.len() % 2 == 1 {
                buf.push(0);
            }
        }
    }
    let mut put_all = || -> std::io::Result<()> {
        out.write_all(&head)?;
        out.write_all(data)?;
        out.write_all(&buf)
    };
    put_all().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tag(bytes: &[u8], want: u16) -> Option<(u16, u32, [u8; 4])> {
        let le = &bytes[..2] == b"II";
        let u16_at = |i: usize| {
            let b = [bytes[i], bytes[i + 1]];
            if le {
                u16::from_le_bytes(b)
            } else {
                u16::from_be_bytes(b)
            }
        };
        let u32_at = |i: usize| {
            let b = [bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]];
            if le {
                u32::from_le_bytes(b)
            } else {
                u32::from_be_bytes(b)
            }
        };
        let ifd = u32_at(4) as usize;
        (0..u16_at(ifd) as usize).find_map(|k| {
            let e = ifd + 2 + 12 * k;
            (u16_at(e) == want).then(|| {
                (
                    u16_at(e + 2),
                    u32_at(e + 4),
                    [bytes[e + 8], bytes[e + 9], bytes[e + 10], bytes[e + 11]],
                )
            })
        })
    }

    #[test]
    fn rgba_declares_associated_alpha_and_reads_back() {
        // Premultiplied: half-covered white is (128,128,128,128).
        let px: Vec<u8> = (0..3 * 5).flat_map(|i| [i as u8, 128, 7, 128]).collect();
        let mut buf = Vec::new();
        write(&mut buf, &px, 5, 3, 4, Sample::U8).unwrap();
        let (ty, count, v) = tag(&buf, 338).expect("ExtraSamples");
        assert_eq!((ty, count), (SHORT, 1));
        assert_eq!(u16::from_ne_bytes([v[0], v[1]]), 1);
        let img = image::load_from_memory(&buf).unwrap().to_rgba8();
        assert_eq!(img.dimensions(), (5, 3));
        assert_eq!(img.get_pixel(4, 2).0, [14, 128, 7, 128]);
    }

    #[test]
    fn rgb_has_no_extra_samples_and_many_strips_read_back() {
        // 700 rows of 300 bytes: 218 rows to a 64 KiB strip, four strips, the last one short.
        let (w, h) = (100, 700);
        let px: Vec<u8> = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
        let mut buf = Vec::new();
        write(&mut buf, &px, w, h, 3, Sample::U8).unwrap();
        assert!(tag(&buf, 338).is_none());
        let (_, strips, _) = tag(&buf, 273).unwrap();
        assert_eq!(strips, 4);
        let img = image::load_from_memory(&buf).unwrap().to_rgb8();
        assert_eq!(img.into_raw(), px);
    }

    #[test]
    fn sixteen_bit_grey_and_float_rgba_read_back() {
        let g: Vec<u8> = [0u16, 1000, 65535, 7]
            .iter()
            .flat_map(|v| v.to_ne_bytes())
            .collect();
        let mut buf = Vec::new();
        write(&mut buf, &g, 2, 2, 1, Sample::U16).unwrap();
        let img = image::load_from_memory(&buf).unwrap().to_luma16();
        assert_eq!(img.into_raw(), vec![0, 1000, 65535, 7]);

        let f = [0.25f32, -1.0, 3.5, 0.5];
        let bytes: Vec<u8> = f.iter().flat_map(|v| v.to_ne_bytes()).collect();
        let mut buf = Vec::new();
        write(&mut buf, &bytes, 1, 1, 4, Sample::F32).unwrap();
        let img = image::load_from_memory(&buf).unwrap().to_rgba32f();
        assert_eq!(img.get_pixel(0, 0).0, f);
    }

    #[test]
    fn bad_sizes_are_errors_not_panics() {
        let mut buf = Vec::new();
        assert!(write(&mut buf, &[0; 5], 2, 1, 3, Sample::U8).is_err());
        assert!(write(&mut buf, &[], 0, 0, 5, Sample::U8).is_err());
        assert!(buf.is_empty());
    }
}
