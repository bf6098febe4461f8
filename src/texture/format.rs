//! arbor's prepared-texture file (`.tex`): a tiled, mip-mapped float image.
//!
//! Why an own format rather than tiled multi-resolution OpenEXR: the `exr` crate reads whole
//! levels (no single-tile random access through its public API), and shadow maps need two
//! camera matrices and cube maps six pyramids in one file. This layout is 20 lines to read,
//! gives O(1) random access to any tile with one positioned read (`read_at`, no locking), so
//! the cache can load tiles on demand from many threads.
//!
//! Layout (little-endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"ARBT"` |
//! | 4 | u32 | version = 1 |
//! | 8 | u32 | kind: 0 texture, 1 lat-long environment, 2 cube environment, 3 shadow, 4 bump |
//! | 12 | u32 | channels |
//! | 16 | u32 | faces (6 for cube maps: px nx py ny pz nz; else 1) |
//! | 20 | u32 | swrap, 24 u32 twrap (0 periodic, 1 clamp, 2 black) |
//! | 28 | u32 | tile size T (square tiles) |
//! | 32 | u32 | levels per face |
//! | 36 | u32 | flags: bit 0 = matrices valid |
//! | 40 | 16×f32 | camera_from_world, row-major (shadow maps: the light's camera) |
//! | 104 | 16×f32 | screen_from_world, row-major, screen normalised so the screen window is [-1,1]² |
//! | 168 | 16 bytes × faces × levels | per (face, level): u32 width, u32 height, u64 offset |
//! | … | | tiles: for each (face, level) row-major tiles of T×T×channels f32 (edge tiles padded) |
//!
//! Texel rows go top to bottom: t = 0 is row 0.

use std::fs::File;
use std::io::Write;
use std::path::Path;

use super::image_in::Image;
use super::mipmap::Wrap;

pub const MAGIC: [u8; 4] = *b"ARBT";
pub const VERSION: u32 = 1;
pub const TILE: usize = 32;
const FIXED_HEADER: usize = 168;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Texture,
    LatLong,
    Cube,
    Shadow,
    /// Heights then their s/t slopes (see [`super::bump`]).
    Bump,
}

impl Kind {
    fn code(self) -> u32 {
        match self {
            Kind::Texture => 0,
            Kind::LatLong => 1,
            Kind::Cube => 2,
            Kind::Shadow => 3,
            Kind::Bump => 4,
        }
    }
    fn from_code(c: u32) -> Option<Kind> {
        Some(match c {
            0 => Kind::Texture,
            1 => Kind::LatLong,
            2 => Kind::Cube,
            3 => Kind::Shadow,
            4 => Kind::Bump,
            _ => return None,
        })
    }
    /// textureinfo "type".
    pub fn type_name(self) -> &'static str {
        match self {
            Kind::Texture => "texture",
            Kind::LatLong | Kind::Cube => "environment",
            Kind::Shadow => "shadow",
            Kind::Bump => "bump",
        }
    }
}

/// One mip level of one face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelInfo {
    pub width: usize,
    pub height: usize,
    pub offset: u64,
}

impl LevelInfo {
    pub fn tiles_x(&self, tile: usize) -> usize {
        self.width.div_ceil(tile)
    }
}

/// Everything in the header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub kind: Kind,
    pub nchan: usize,
    pub nfaces: usize,
    pub swrap: Wrap,
    pub twrap: Wrap,
    pub tile: usize,
    /// levels[face][level]
    pub levels: Vec<Vec<LevelInfo>>,
    /// (camera_from_world, screen_from_world), row-major.
    pub matrices: Option<([f32; 16], [f32; 16])>,
}

/// Writes faces (each a full pyramid, finest first) to `path`, atomically.
pub fn write(
    path: &Path,
    kind: Kind,
    faces: &[Vec<Image>],
    swrap: Wrap,
    twrap: Wrap,
    matrices: Option<([f32; 16], [f32; 16])>,
) -> Result<(), String> {
    let nfaces = faces.len();
    let nlevels = faces.first().map_or(0, |f| f.len());
    if nfaces == 0 || nlevels == 0 || faces.iter().any(|f| f.len() != nlevels) {
        return Err("texture has no levels, or faces differ in their level count".into());
    }
    let nchan = faces[0][0].nchan;
    let mut buf: Vec<u8> = Vec::new();
    buf.extend_from_slice(&MAGIC);
    for v in [
        VERSION,
        kind.code(),
        nchan as u32,
        nfaces as u32,
        swrap.code(),
        twrap.code(),
        TILE as u32,
        nlevels as u32,
        u32::from(matrices.is_some()),
    ] {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    let (a, b) = matrices.unwrap_or(([0.0; 16], [0.0; 16]));
    for v in a.iter().chain(b.iter()) {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    let mut offset = (FIXED_HEADER + 16 * nfaces * nlevels) as u64;
    for face in faces {
        for l in face {
            buf.extend_from_slice(&(l.width as u32).to_le_bytes());
            buf.extend_from_slice(&(l.height as u32).to_le_bytes());
            buf.extend_from_slice(&offset.to_le_bytes());
            let ntiles = l.width.div_ceil(TILE) * l.height.div_ceil(TILE);
            offset += (ntiles * TILE * TILE * nchan * 4) as u64;
        }
    }
    for face in faces {
        for l in face {
            if l.nchan != nchan {
                return Err("every face must have the same channel count".into());
            }
            for ty in 0..l.height.div_ceil(TILE) {
                for tx in 0..l.width.div_ceil(TILE) {
                    for y in 0..TILE {
                        for x in 0..TILE {
                            let (sx, sy) = (
                                (tx * TILE + x).min(l.width - 1),
                                (ty * TILE + y).min(l.height - 1),
                            );
                            for v in l.px(sx, sy) {
                                buf.extend_from_slice(&v.to_le_bytes());
                            }
                        }
                    }
                }
            }
        }
    }
    let tmp = path.with_extension("arbor-tmp");
    let mut f =
        File::create(&tmp).map_err(|e| format!("cannot create `{}`: {e}", tmp.display()))?;
    f.write_all(&buf)
        .map_err(|e| format!("cannot write `{}`: {e}", tmp.display()))?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(|e| format!("cannot write `{}`: {e}", path.display()))
}

/// Parses the header from the start of a file (`bytes` may be longer than the header).
pub fn parse_header(bytes: &[u8]) -> Result<Header, String> {
    if bytes.len() < FIXED_HEADER || bytes[0..4] != MAGIC {
        return Err("not an arbor texture (bad magic or short header)".into());
    }
    let u = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let f = |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    if u(4) != VERSION {
        return Err(format!("unsupported arbor texture version {}", u(4)));
    }
    let kind = Kind::from_code(u(8)).ok_or("unknown texture kind")?;
    let (nchan, nfaces, tile, nlevels) = (
        u(12) as usize,
        u(16) as usize,
        u(28) as usize,
        u(32) as usize,
    );
    if nchan == 0
        || nchan > 64
        || !(1..=6).contains(&nfaces)
        || tile == 0
        || tile > 4096
        || nlevels == 0
        || nlevels > 40
    {
        return Err("corrupt arbor texture header".into());
    }
    let table_end = FIXED_HEADER + 16 * nfaces * nlevels;
    if bytes.len() < table_end {
        return Err("arbor texture header is truncated".into());
    }
    let matrices = if u(36) & 1 == 1 {
        let mut a = [0f32; 16];
        let mut b = [0f32; 16];
        for i in 0..16 {
            a[i] = f(40 + 4 * i);
            b[i] = f(104 + 4 * i);
        }
        Some((a, b))
    } else {
        None
    };
    let mut levels = Vec::with_capacity(nfaces);
    for face in 0..nfaces {
        let mut ls = Vec::with_capacity(nlevels);
        for l in 0..nlevels {
            let o = FIXED_HEADER + 16 * (face * nlevels + l);
            let off = u64::from_le_bytes(bytes[o + 8..o + 16].try_into().expect("8 bytes"));
            let (w, h) = (u(o) as usize, u(o + 4) as usize);
            if w == 0 || h == 0 || w > 1 << 20 || h > 1 << 20 {
                return Err("corrupt level size in arbor texture".into());
            }
            ls.push(LevelInfo {
                width: w,
                height: h,
                offset: off,
            });
        }
        levels.push(ls);
    }
    Ok(Header {
        kind,
        nchan,
        nfaces,
        swrap: Wrap::from_code(u(20)),
        twrap: Wrap::from_code(u(24)),
        tile,
        levels,
        matrices,
    })
}

/// Bytes of header to read before parsing (fixed part + the largest table).
pub fn header_len_upper_bound() -> usize {
    FIXED_HEADER + 16 * 6 * 40
}

/// Bytes of one tile.
pub fn tile_bytes(h: &Header) -> usize {
    h.tile * h.tile * h.nchan * 4
}

/// Reads one tile as floats (positioned read: safe to call from many threads).
pub fn read_tile(
    file: &File,
    h: &Header,
    face: usize,
    level: usize,
    tx: usize,
    ty: usize,
) -> Result<Vec<f32>, String> {
    use std::os::unix::fs::FileExt;
    let l = h.levels[face][level];
    let idx = ty * l.tiles_x(h.tile) + tx;
    let n = tile_bytes(h);
    let mut bytes = vec![0u8; n];
    file.read_exact_at(&mut bytes, l.offset + (idx * n) as u64)
        .map_err(|e| format!("texture tile read failed: {e}"))?;
    Ok(bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_header_and_tiles() {
        let mut im = Image::new(40, 3, 2);
        for (i, v) in im.data.iter_mut().enumerate() {
            *v = i as f32;
        }
        let scratch = tempfile::Builder::new()
            .prefix("arbor-fmt-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let p = dir.join("a.tex");
        let mats = Some(([1.0; 16], [2.0; 16]));
        write(
            &p,
            Kind::Shadow,
            &[vec![im.clone()]],
            Wrap::Clamp,
            Wrap::Black,
            mats,
        )
        .unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let h = parse_header(&bytes).unwrap();
        assert_eq!(
            (h.kind, h.nchan, h.nfaces, h.swrap, h.twrap),
            (Kind::Shadow, 2, 1, Wrap::Clamp, Wrap::Black)
        );
        assert_eq!(h.matrices, mats);
        assert_eq!((h.levels[0][0].width, h.levels[0][0].height), (40, 3));
        let f = File::open(&p).unwrap();
        // Texel (33, 2) lives in tile (1, 0) at (1, 2).
        let t = read_tile(&f, &h, 0, 0, 1, 0).unwrap();
        let o = (2 * TILE + 1) * 2;
        assert_eq!(&t[o..o + 2], im.px(33, 2));
        assert!(parse_header(b"nope").is_err());
    }
}
