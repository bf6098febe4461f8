//! Reading PRMan 3.x texture files (the binary `.tx` maps written by Pixar's `txmake`), as
//! shipped with published RenderMan scenes of the mid-1990s.
//!
//! Input: the bytes of such a file. Output: its mip levels as float images (finest first,
//! completed down to 1×1 with arbor's box filter when the file stops earlier) and its wrap
//! modes. Invariants: never panics on bad input (every offset and length is bounds-checked,
//! allocations are capped by the header's sizes); an unsupported variant is an error naming
//! what is unsupported.
//!
//! No documentation of the format is public; this layout was worked out from sample files
//! (checked texel for texel against TIFF pyramids of the same pictures). Multi-byte fields
//! follow the magic's byte order: `fa ce` big-endian, `ce fa` little-endian.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | u16 | magic `0xface` |
//! | 2 | u16 | version: 2 (raw tiles) or 3 (coded tiles) |
//! | 4 | u16 | texels per tile (0x1000: 64×64 square tiles) |
//! | 8 | u8, u8 | bytes per sample (1), bits per sample (8) |
//! | 0xd, 0xf | u8 | log2 width, log2 height |
//! | 0x10, 0x11 | u8 | s and t wrap: 1 black (seen with a TIFF twin saying "black"), 2 clamp, 0 periodic |
//! | 0x12 | u8 | channels |
//! | 0x1c | 2 bytes × 14 | level table, coarsest first: non-zero for each level present |
//! | 0x48 + c·S + k·E | u32 | channel c, level k (coarsest first): where its data is |
//!
//! Version 2: S = 676, E = 56; a level is its tiles, row-major, each tile row-major bytes.
//! Version 3: S = 900, E = 64; a level is a record of 8 unused bytes, one u32 per tile and
//! one u16 code per tile. The code's top 3 bits say how the tile is stored, its low 13 bits
//! how many bytes it takes at the u32 offset:
//! 0 raw bytes; 1 one value for the whole tile, in the top byte of the u32 (no data);
//! 2 run-length (a control byte c < 128 repeats the next byte c+1 times, c ≥ 128 copies the
//! next c−127 bytes); 5 Huffman-coded bytes (see [`unhuff`]); 6 zlib of the tile's bytes as
//! running differences (row-major, mod 256).
//! Tiles are min(64, level size) square; channels are stored one after another (planar).

use super::image_in::Image;
use super::mipmap::{build_pyramid, Downsample, Wrap};

/// A decoded PRMan texture: mip levels (finest first, down to 1×1) and wrap modes.
#[derive(Clone, Debug, PartialEq)]
pub struct PrmanTexture {
    pub levels: Vec<Image>,
    pub swrap: Wrap,
    pub twrap: Wrap,
}

/// Whether `head` starts like a PRMan texture of either byte order.
pub fn is_prman_tx(head: &[u8]) -> bool {
    matches!(head.get(..2), Some([0xfa, 0xce]) | Some([0xce, 0xfa]))
}

/// Largest picture accepted, in texels × channels of level 0 (256 MB of floats).
const MAX_SAMPLES: usize = 1 << 26;
/// Where the level table and the channel directories start.
const LEVEL_TABLE: usize = 0x1c;
const DIRECTORY: usize = 0x48;

/// Big- or little-endian field reads, each bounds-checked.
struct Bytes<'a> {
    b: &'a [u8],
    big: bool,
}

impl Bytes<'_> {
    fn u8(&self, o: usize) -> Result<u8, String> {
        self.b
            .get(o)
            .copied()
            .ok_or_else(|| format!("truncated (needs byte {o:#x})"))
    }
    fn u16(&self, o: usize) -> Result<u16, String> {
        let x: [u8; 2] = self
            .slice(o, 2)?
            .try_into()
            .map_err(|_| "short read".to_string())?;
        Ok(if self.big {
            u16::from_be_bytes(x)
        } else {
            u16::from_le_bytes(x)
        })
    }
    fn u32(&self, o: usize) -> Result<u32, String> {
        let x: [u8; 4] = self
            .slice(o, 4)?
            .try_into()
            .map_err(|_| "short read".to_string())?;
        Ok(if self.big {
            u32::from_be_bytes(x)
        } else {
            u32::from_le_bytes(x)
        })
    }
    fn slice(&self, o: usize, n: usize) -> Result<&[u8], String> {
        o.checked_add(n)
            .and_then(|e| self.b.get(o..e))
            .ok_or_else(|| format!("truncated ({n} bytes at {o:#x} are past the end)"))
    }
}

fn wrap(code: u8) -> Result<Wrap, String> {
    match code {
        0 => Ok(Wrap::Periodic),
        1 => Ok(Wrap::Black),
        2 => Ok(Wrap::Clamp),
        c => Err(format!("unknown wrap mode code {c}")),
    }
}

/// Decodes a whole file (errors say what is wrong; the caller names the file).
pub fn decode(bytes: &[u8]) -> Result<PrmanTexture, String> {
    let big = match bytes.get(..2) {
        Some([0xfa, 0xce]) => true,
        Some([0xce, 0xfa]) => false,
        _ => return Err("not a PRMan texture (bad magic)".into()),
    };
    let r = Bytes { b: bytes, big };
    let version = r.u16(2)?;
    let (chan_stride, level_stride, max_levels) = match version {
        2 => (676, 56, 12),
        3 => (900, 64, 14),
        v => {
            return Err(format!(
                "unsupported PRMan texture version {v} (2 and 3 are known)"
            ))
        }
    };
    let tile_texels = r.u16(4)? as usize;
    let tile = (1..=12)
        .map(|k| 1usize << k)
        .find(|t| t * t == tile_texels)
        .ok_or_else(|| format!("unsupported tile size ({tile_texels} texels, not a square)"))?;
    let (bytes_per, bits) = (r.u8(8)?, r.u8(9)?);
    if (bytes_per, bits) != (1, 8) {
        return Err(format!(
            "unsupported sample format ({bytes_per} bytes, {bits} bits; only 8-bit is known)"
        ));
    }
    let (lw, lh) = (r.u8(0xd)? as u32, r.u8(0xf)? as u32);
    if lw > 16 || lh > 16 {
        return Err(format!("corrupt size (2^{lw} × 2^{lh})"));
    }
    let (width, height) = (1usize << lw, 1usize << lh);
    let (swrap, twrap) = (wrap(r.u8(0x10)?)?, wrap(r.u8(0x11)?)?);
    let nchan = r.u8(0x12)? as usize;
    if !(1..=4).contains(&nchan) {
        return Err(format!(
            "unsupported channel count {nchan} (1 to 4 are read)"
        ));
    }
    if width * height * nchan > MAX_SAMPLES {
        return Err(format!(
            "{width}×{height}×{nchan} is larger than arbor reads"
        ));
    }
    // The levels present: the finest `nlevels`, listed coarsest first.
    let mut nlevels = 0;
    for k in 0..max_levels {
        if r.u16(LEVEL_TABLE + 2 * k)? != 0 {
            nlevels += 1;
        }
    }
    let most = lw.max(lh) as usize + 1;
    if nlevels == 0 || nlevels > most {
        return Err(format!(
            "corrupt level table ({nlevels} levels for {width}×{height})"
        ));
    }
    let mut levels: Vec<Image> = (0..nlevels)
        .map(|l| Image::new((width >> l).max(1), (height >> l).max(1), nchan))
        .collect();
    for c in 0..nchan {
        for k in 0..nlevels {
            let l = nlevels - 1 - k;
            let at = r.u32(DIRECTORY + c * chan_stride + k * level_stride)? as usize;
            let im = &mut levels[l];
            let (tw, th) = (tile.min(im.width), tile.min(im.height));
            let (nx, ny) = (im.width / tw, im.height / th);
            for i in 0..nx * ny {
                let texels = if version == 2 {
                    r.slice(at + i * tw * th, tw * th)?.to_vec()
                } else {
                    tile_v3(&r, at, nx * ny, i, tw * th)
                        .map_err(|e| format!("level {l} channel {c} tile {i}: {e}"))?
                };
                let (x0, y0) = ((i % nx) * tw, (i / nx) * th);
                for (j, &v) in texels.iter().enumerate() {
                    let (x, y) = (x0 + j % tw, y0 + j / tw);
                    im.data[(y * im.width + x) * nchan + c] = f32::from(v) / 255.0;
                }
            }
        }
    }
    // A file stopping above 1×1 (version 2 keeps nothing under 4×4) is completed here.
    if let Some(last) = levels.last() {
        if last.width > 1 || last.height > 1 {
            let more = build_pyramid(last.clone(), swrap, twrap, Downsample::Box);
            levels.extend(more.into_iter().skip(1));
        }
    }
    Ok(PrmanTexture {
        levels,
        swrap,
        twrap,
    })
}

/// Tile `i` of the `ntiles` in the version-3 level record at `rec`: `n` bytes.
fn tile_v3(r: &Bytes, rec: usize, ntiles: usize, i: usize, n: usize) -> Result<Vec<u8>, String> {
    let word_at = rec + 8 + 4 * i;
    let word = r.u32(word_at)?;
    let code = r.u16(rec + 8 + 4 * ntiles + 2 * i)?;
    let len = (code & 0x1fff) as usize;
    let data = || r.slice(word as usize, len);
    let out = match code >> 13 {
        0 => data()?.to_vec(),
        1 => vec![(word >> 24) as u8; n],
        2 => unrun(data()?, n)?,
        6 => {
            let mut d = inflate(data()?, n)?;
            let mut acc = 0u8;
            for v in &mut d {
                acc = acc.wrapping_add(*v);
                *v = acc;
            }
            d
        }
        5 => unhuff(data()?, n)?,
        m => return Err(format!("unknown tile coding {m} (code {code:#06x})")),
    };
    if out.len() != n {
        return Err(format!("holds {} bytes, not {n}", out.len()));
    }
    Ok(out)
}

/// Run-length decoding (PackBits-like control bytes), stopping at `n` bytes.
fn unrun(d: &[u8], n: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(n);
    let mut j = 0;
    while j < d.len() && out.len() < n {
        let c = d[j] as usize;
        j += 1;
        if c >= 0x80 {
            let k = c - 0x7f;
            let lit = d.get(j..j + k).ok_or("a run-length literal is cut short")?;
            out.extend_from_slice(lit);
            j += k;
        } else {
            let v = *d.get(j).ok_or("a run-length repeat is cut short")?;
            out.extend(std::iter::repeat_n(v, c + 1));
            j += 1;
        }
    }
    Ok(out)
}

/// Huffman decoding: a 32-byte bitmap of the byte values present (bit 7 of byte 0 is value
/// 0), one nibble per present value (code length − 1, high nibble first), each present
/// value's code (MSB first, bit-packed in value order, padded to a byte), then the tile's
/// `n` codes (MSB first).
fn unhuff(d: &[u8], n: usize) -> Result<Vec<u8>, String> {
    let cut = || "the Huffman table is cut short".to_string();
    let bitmap = d.get(..32).ok_or_else(cut)?;
    let present: Vec<u8> = (0..=255u8)
        .filter(|&v| bitmap[v as usize / 8] >> (7 - v % 8) & 1 == 1)
        .collect();
    let nib_end = 32 + present.len().div_ceil(2);
    let nibbles = d.get(32..nib_end).ok_or_else(cut)?;
    let lens: Vec<usize> = (0..present.len())
        .map(|i| (nibbles[i / 2] >> if i % 2 == 0 { 4 } else { 0 } & 15) as usize + 1)
        .collect();
    let code_bits: usize = lens.iter().sum();
    let codes = d
        .get(nib_end..nib_end + code_bits.div_ceil(8))
        .ok_or_else(cut)?;
    let bit = |b: &[u8], i: usize| b[i / 8] >> (7 - i % 8) & 1;
    // A binary tree: node k's children at tree[k]; a leaf holds 256 + its value.
    let mut tree: Vec<[u16; 2]> = vec![[0, 0]];
    let mut at = 0;
    for (&v, &len) in present.iter().zip(&lens) {
        let mut node = 0usize;
        for j in 0..len {
            let b = bit(codes, at + j) as usize;
            let next = tree[node][b] as usize;
            if j + 1 == len {
                if next != 0 {
                    return Err("the Huffman codes are not prefix-free".into());
                }
                tree[node][b] = 256 + u16::from(v);
            } else if next == 0 {
                // Internal nodes stay below 256 (a full tree of 256 leaves has 255).
                if tree.len() >= 255 {
                    return Err("the Huffman table is malformed".into());
                }
                tree.push([0, 0]);
                let k = tree.len() - 1;
                tree[node][b] = k as u16;
                node = k;
            } else if next >= 256 {
                return Err("the Huffman codes are not prefix-free".into());
            } else {
                node = next;
            }
        }
        at += len;
    }
    let stream = &d[nib_end + code_bits.div_ceil(8)..];
    let mut out = Vec::with_capacity(n);
    let mut node = 0usize;
    for i in 0..stream.len() * 8 {
        if out.len() == n {
            break;
        }
        let next = tree[node][bit(stream, i) as usize] as usize;
        if next >= 256 {
            out.push((next - 256) as u8);
            node = 0;
        } else if next == 0 {
            return Err("a Huffman code is not in the table".into());
        } else {
            node = next;
        }
    }
    Ok(out)
}

/// zlib decoding of at most `n` bytes (a stream claiming more is an error, not an allocation).
fn inflate(d: &[u8], n: usize) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut out = Vec::with_capacity(n);
    flate2::read::ZlibDecoder::new(d)
        .take(n as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| format!("bad zlib data: {e}"))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// Writes a version-3 file of the decoded layout: one channel, 2 levels of 128×64 (tile
    /// 64: two tiles, one zlib-delta and one constant) and 64×32 (one run-length tile).
    /// Level 64×32 is the coarsest stored: the reader completes the pyramid.
    fn encode_v3(big: bool) -> (Vec<u8>, Vec<u8>, Vec<u8>) {
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
        let mut b = vec![0u8; 0x400];
        b[..2].copy_from_slice(&u16b(0xface));
        b[2..4].copy_from_slice(&u16b(3));
        b[4..6].copy_from_slice(&u16b(0x1000));
        b[8] = 1;
        b[9] = 8;
        b[0xd] = 7; // 128 wide
        b[0xf] = 6; // 64 high
        b[0x10] = 2; // clamp
        b[0x11] = 1; // black
        b[0x12] = 1;
        b[LEVEL_TABLE] = 64; // coarsest first: 64×32, then 128×64
        b[LEVEL_TABLE + 2] = 128;
        // Level 0 tile 0: a ramp, zlib of its running differences.
        let tile0: Vec<u8> = (0..4096).map(|i| ((i * 7 + i / 64) % 256) as u8).collect();
        let mut deltas = vec![tile0[0]];
        deltas.extend(tile0.windows(2).map(|w| w[1].wrapping_sub(w[0])));
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&deltas).unwrap();
        let z = z.finish().unwrap();
        // Level 1 (64×32): 1000 texels of 9 by a repeat, 1048 literal 0..=255 cycles.
        let mut rle = Vec::new();
        let mut l1 = Vec::new();
        for _ in 0..7 {
            rle.extend([127, 9]);
            l1.extend([9u8; 128]);
        }
        rle.extend([103, 9]);
        l1.extend([9u8; 104]);
        while l1.len() < 2048 {
            let k = (2048 - l1.len()).min(128);
            rle.push(0x7f + k as u8);
            for j in 0..k {
                let v = ((l1.len() + j) % 256) as u8;
                rle.push(v);
            }
            l1.extend(rle[rle.len() - k..].to_vec());
        }
        // Records: level 1 (coarsest) at 0x300, level 0 at 0x340; data from 0x400.
        let (rec1, rec0) = (0x300usize, 0x340usize);
        b[DIRECTORY..DIRECTORY + 4].copy_from_slice(&u32b(rec1 as u32));
        b[DIRECTORY + 64..DIRECTORY + 68].copy_from_slice(&u32b(rec0 as u32));
        let zat = b.len();
        b.extend(&z);
        let rat = b.len();
        b.extend(&rle);
        b[rec1 + 8..rec1 + 12].copy_from_slice(&u32b(rat as u32));
        b[rec1 + 12..rec1 + 14].copy_from_slice(&u16b(0x4000 | rle.len() as u16));
        b[rec0 + 8..rec0 + 12].copy_from_slice(&u32b(zat as u32));
        b[rec0 + 12..rec0 + 16].copy_from_slice(&u32b(0xc8 << 24)); // tile 1: all 200
        b[rec0 + 16..rec0 + 18].copy_from_slice(&u16b(0xc000 | z.len() as u16));
        b[rec0 + 18..rec0 + 20].copy_from_slice(&u16b(0x2000));
        (b, tile0, l1)
    }

    #[test]
    fn version3_tiles_decode_exactly_in_both_byte_orders() {
        for big in [true, false] {
            let (b, tile0, l1) = encode_v3(big);
            let t = decode(&b).unwrap();
            assert_eq!((t.swrap, t.twrap), (Wrap::Clamp, Wrap::Black));
            let sizes: Vec<_> = t.levels.iter().map(|l| (l.width, l.height)).collect();
            assert_eq!(
                sizes,
                vec![
                    (128, 64),
                    (64, 32),
                    (32, 16),
                    (16, 8),
                    (8, 4),
                    (4, 2),
                    (2, 1),
                    (1, 1)
                ]
            );
            let l0 = &t.levels[0];
            for y in 0..64 {
                for x in 0..64 {
                    assert_eq!(l0.px(x, y)[0], f32::from(tile0[y * 64 + x]) / 255.0);
                    assert_eq!(l0.px(64 + x, y)[0], 200.0 / 255.0);
                }
            }
            let l1im = &t.levels[1];
            for (j, &v) in l1.iter().enumerate() {
                assert_eq!(l1im.data[j], f32::from(v) / 255.0);
            }
        }
    }

    #[test]
    fn version2_raw_tiles_are_planar_and_tiled() {
        // 128×64 RGB, version 2 (little-endian): one level, two 64×64 tiles per channel.
        let mut b = vec![0u8; 0x800];
        b[..2].copy_from_slice(&[0xce, 0xfa]);
        b[2] = 2;
        b[4..6].copy_from_slice(&0x1000u16.to_le_bytes());
        b[8] = 1;
        b[9] = 8;
        b[0xd] = 7;
        b[0xf] = 6;
        b[0x10] = 1;
        b[0x11] = 1;
        b[0x12] = 3;
        b[LEVEL_TABLE] = 128;
        for c in 0..3 {
            let at = b.len() as u32;
            b[DIRECTORY + c * 676..DIRECTORY + c * 676 + 4].copy_from_slice(&at.to_le_bytes());
            for tile in 0..2 {
                for j in 0..4096 {
                    b.push(((c * 50 + tile * 100 + j / 64) % 256) as u8);
                }
            }
        }
        let t = decode(&b).unwrap();
        assert_eq!(t.levels.len(), 8);
        let l0 = &t.levels[0];
        // Texel (70, 5): tile 1, row 5.
        let want = |c: usize| ((c * 50 + 100 + 5) % 256) as f32 / 255.0;
        assert_eq!(l0.px(70, 5), &[want(0), want(1), want(2)]);
        assert_eq!(l0.px(3, 63)[2], (100 + 63) as f32 / 255.0);
    }

    #[test]
    fn truncated_and_corrupt_files_are_errors() {
        let (b, _, _) = encode_v3(true);
        for n in [0, 1, 3, 0x20, 0x49, 0x310, 0x350, 0x400, b.len() - 1] {
            assert!(decode(&b[..n]).is_err(), "truncated to {n}");
        }
        let mut bad = b.clone();
        bad[3] = 7; // version
        assert!(decode(&bad).unwrap_err().contains("version 7"));
        let mut bad = b.clone();
        bad[0x12] = 9;
        assert!(decode(&bad).unwrap_err().contains("channel count"));
        let mut bad = b.clone();
        bad[0xd] = 40;
        assert!(decode(&bad).is_err());
        let mut bad = b.clone();
        bad[0x340 + 16] = 0xa0; // Huffman code on a zlib tile
        assert!(decode(&bad).unwrap_err().contains("Huffman"));
        let mut bad = b.clone();
        bad[0x340 + 16] = 0xe0; // coding 7
        assert!(decode(&bad).unwrap_err().contains("unknown tile coding 7"));
        let mut bad = b.clone();
        bad[0x340 + 8] = 0xff; // tile offset past the end
        assert!(decode(&bad).is_err());
        let mut bad = b.clone();
        let z = u32::from_be_bytes(bad[0x348..0x34c].try_into().unwrap()) as usize;
        bad[z + 5] ^= 0xff; // damaged zlib data
        assert!(decode(&bad).is_err());
        assert!(decode(b"\x89PNG").is_err());
    }

    /// Values 3, 7, 200 coded `0`, `10`, `11`; the tile 7 3 200 200 3.
    #[test]
    fn huffman_tiles_decode_through_their_own_code_table() {
        let mut d = vec![0u8; 32];
        d[0] = 0b0001_0001; // 3 and 7
        d[25] = 0b1000_0000; // 200
        d.extend([0x01, 0x10]); // lengths 1, 2, 2 (minus one), a spare nibble
        d.push(0b0101_1000); // codes 0, 10, 11
        d.push(0b1001_1110); // 10 0 11 11 0
        assert_eq!(unhuff(&d, 5).unwrap(), vec![7, 3, 200, 200, 3]);
        // Stops at the tile's size; a short stream gives a short tile (an error upstream).
        assert_eq!(unhuff(&d, 2).unwrap(), vec![7, 3]);
        assert_eq!(unhuff(&d, 9).unwrap().len(), 5);
        // Codes that are not prefix-free (0, 00, 11) and a cut table are errors.
        let mut bad = d.clone();
        bad[34] = 0b0001_1000;
        assert!(unhuff(&bad, 5).is_err());
        assert!(unhuff(&d[..33], 5).is_err());
        assert!(unhuff(&d[..20], 5).is_err());
    }

    /// The published samples against their TIFF twins (skipped where they are absent).
    /// The largest absolute difference between two sample arrays.
    fn max_difference(a: &[f32], b: &[f32]) -> f32 {
        a.iter()
            .zip(b)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max)
    }

    #[test]
    #[ignore]
    fn published_samples_match_their_tiff_twins() {
        let root = std::path::Path::new("/work/shared/fidelity/scenes/RMR/Publications/arman");
        let tx = root.join("texture/rmemboss.tx");
        let tif = root.join("tifftexture/rmemboss.tx");
        let (Ok(a), Ok(_)) = (std::fs::read(&tx), std::fs::metadata(&tif)) else {
            eprintln!("samples absent: skipped");
            return;
        };
        let t = decode(&a).unwrap();
        let reference = super::super::image_in::read_image(&tif).unwrap();
        let l0 = &t.levels[0];
        assert_eq!((l0.width, l0.height), (reference.width, reference.height));
        let diff = max_difference(&l0.data, &reference.data);
        assert!(diff < 1e-6, "max difference {diff}");
        // mandrill.tx holds every tile coding, one Huffman tile among them.
        let t = decode(&std::fs::read(root.join("texture/mandrill.tx")).unwrap()).unwrap();
        let reference =
            super::super::image_in::read_image(&root.join("tifftexture/mandrill.tx")).unwrap();
        let diff = max_difference(&t.levels[0].data, &reference.data);
        assert!(diff < 1e-6, "mandrill max difference {diff}");
        let ori = std::path::Path::new("/work/shared/fidelity/scenes/RMR/Shaders/TLShaders");
        let t = decode(&std::fs::read(ori.join("ori2.tx")).unwrap()).unwrap();
        let reference =
            super::super::image_in::read_image(&ori.join("../../st/ori2.tiff")).unwrap();
        let diff = max_difference(&t.levels[0].data, &reference.data);
        assert!(diff < 1e-6, "ori2 max difference {diff}");
        let grid = decode(&std::fs::read(ori.join("grid2.tx")).unwrap()).unwrap();
        assert_eq!((grid.levels[0].width, grid.levels[0].nchan), (512, 3));
    }
}
