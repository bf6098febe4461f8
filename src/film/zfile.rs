//! arbor's depth-image format (`Display … "zfile"` and `"shadow"`).
//!
//! Input: a width × height array of camera-space depths (+∞ where nothing was hit) and,
//! optionally, the camera's matrices. Output: bytes / a parsed [`ZFile`].
//! Layout (all little-endian), 148-byte header then the depths:
//!
//! | offset | size  | field                                                       |
//! |--------|-------|-------------------------------------------------------------|
//! | 0      | 4     | magic `b"ARBZ"`                                             |
//! | 4      | u32   | version = 1                                                 |
//! | 8      | u32   | width                                                       |
//! | 12     | u32   | height                                                      |
//! | 16     | u32   | flags: bit 0 = the two matrices are valid                   |
//! | 20     | 16×f32| `camera_from_world`, row-major (column-vector convention)   |
//! | 84     | 16×f32| `screen_from_world` (RenderMan screen space), row-major     |
//! | 148    | w·h×f32 | depths, rows top to bottom, left to right                 |
//!
//! The matrices are zero with flag 0 until the renderer hands them over (shadow maps need
//! them; `MakeShadow` converts this file later).

/// Magic bytes at the start of every zfile.
pub const ZFILE_MAGIC: [u8; 4] = *b"ARBZ";
pub const ZFILE_VERSION: u32 = 1;
pub const ZFILE_HEADER_LEN: usize = 148;

/// A depth image with its optional camera matrices (each 16 floats, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct ZFile {
    pub width: u32,
    pub height: u32,
    /// (camera_from_world, screen_from_world) when known.
    pub matrices: Option<([f32; 16], [f32; 16])>,
    pub depths: Vec<f32>,
}

impl ZFile {
    /// The depth channel (`z`) of a film, +∞ everywhere when the film has none.
    pub fn from_film(film: &super::Film, matrices: Option<([f32; 16], [f32; 16])>) -> ZFile {
        let n = film.channels();
        let depths = match film.channel("z") {
            Some(z) => film.data.chunks_exact(n).map(|px| px[z]).collect(),
            None => vec![f32::INFINITY; film.width * film.height],
        };
        ZFile {
            width: film.width as u32,
            height: film.height as u32,
            matrices,
            depths,
        }
    }

    /// Serialises to the documented layout.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(ZFILE_HEADER_LEN + self.depths.len() * 4);
        out.extend_from_slice(&ZFILE_MAGIC);
        out.extend_from_slice(&ZFILE_VERSION.to_le_bytes());
        out.extend_from_slice(&self.width.to_le_bytes());
        out.extend_from_slice(&self.height.to_le_bytes());
        let flags: u32 = u32::from(self.matrices.is_some());
        out.extend_from_slice(&flags.to_le_bytes());
        let (a, b) = self.matrices.unwrap_or(([0.0; 16], [0.0; 16]));
        for v in a.iter().chain(b.iter()).chain(self.depths.iter()) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// Parses the documented layout; errors name what is wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<ZFile, String> {
        if bytes.len() < ZFILE_HEADER_LEN {
            return Err(format!(
                "zfile too short: {} bytes, the header alone is {ZFILE_HEADER_LEN}",
                bytes.len()
            ));
        }
        if bytes[0..4] != ZFILE_MAGIC {
            return Err("not an arbor zfile (bad magic)".into());
        }
        let u = |o: usize| u32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
        let f = |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
        let version = u(4);
        if version != ZFILE_VERSION {
            return Err(format!("unsupported zfile version {version}"));
        }
        let (width, height, flags) = (u(8), u(12), u(16));
        let n = width as usize * height as usize;
        if bytes.len() != ZFILE_HEADER_LEN + 4 * n {
            return Err(format!(
                "zfile of {width}×{height} should be {} bytes, found {}",
                ZFILE_HEADER_LEN + 4 * n,
                bytes.len()
            ));
        }
        let mut a = [0.0; 16];
        let mut b = [0.0; 16];
        for i in 0..16 {
            a[i] = f(20 + 4 * i);
            b[i] = f(84 + 4 * i);
        }
        let depths = (0..n).map(|i| f(ZFILE_HEADER_LEN + 4 * i)).collect();
        Ok(ZFile {
            width,
            height,
            matrices: (flags & 1 != 0).then_some((a, b)),
            depths,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_layout() {
        let mut m = [0.0f32; 16];
        m[0] = 1.0;
        m[15] = 2.0;
        let z = ZFile {
            width: 3,
            height: 2,
            matrices: Some((m, m)),
            depths: vec![1.0, 2.0, f32::INFINITY, 4.0, 5.0, 6.5],
        };
        let b = z.to_bytes();
        assert_eq!(b.len(), 148 + 24);
        assert_eq!(&b[0..4], b"ARBZ");
        assert_eq!(u32::from_le_bytes(b[8..12].try_into().unwrap()), 3);
        assert_eq!(f32::from_le_bytes(b[148..152].try_into().unwrap()), 1.0);
        assert_eq!(ZFile::from_bytes(&b).unwrap(), z);
        let none = ZFile {
            matrices: None,
            ..z.clone()
        };
        assert_eq!(ZFile::from_bytes(&none.to_bytes()).unwrap().matrices, None);
        assert!(ZFile::from_bytes(&b[..100]).is_err());
        assert!(ZFile::from_bytes(&b[..b.len() - 4]).is_err());
    }
}
