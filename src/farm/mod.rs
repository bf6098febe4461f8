//! Render-farm support: frames × tiles as independent jobs, reassembled exactly.
//!
//! Input: a RIB file and command-line settings. Output: tile files (`arbor render --tile
//! I/N`), each Display's final picture assembled from them (`arbor merge`), and an Open Job
//! Description template running both on a farm (`arbor job`).
//! Invariants: a merged picture is byte-identical to a single-machine render of the frame
//! (tiles carry the film's floats; quantize, dither and encoding run once, on the whole frame,
//! through the same display code); a merge never writes a picture from missing, mismatched or
//! differently-rendered tiles.
//!
//! Modules: [`tile`] (tile rectangles, tile files), [`merge`] (checks and assembly),
//! [`job`] (the OpenJD template).

pub mod job;
pub mod merge;
pub mod tile;

pub use tile::TileSpec;

use crate::diag::SourceMap;
use crate::pipeline::Settings;

/// 64-bit FNV-1a: a stable hash (the same on every machine and run), unlike std's.
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Fnv {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, b: &[u8]) -> &mut Fnv {
        for &x in b {
            self.0 = (self.0 ^ x as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
        // A separator, so ("ab","c") and ("a","bc") differ.
        self.0 = (self.0 ^ 0xff).wrapping_mul(0x0000_0100_0000_01b3);
        self
    }
    fn str(&mut self, s: &str) -> &mut Fnv {
        self.bytes(s.as_bytes())
    }
}

/// The hash that tiles of one frame must share: arbor's version, the text of every RIB file
/// and archive read for the scene (source ids `ids` of `sources`: those `load_scenes` added,
/// before any shader is compiled, since tiles compile different shaders), the frame number, and
/// the command-line settings that change pixels (resolution, search paths, shader defines).
/// Not covered: shader and texture files, which are found while rendering.
pub fn settings_hash(
    sources: &SourceMap,
    ids: std::ops::Range<u32>,
    settings: &Settings,
    frame: Option<i32>,
) -> u64 {
    let mut h = Fnv::new();
    h.str(env!("CARGO_PKG_VERSION"));
    for f in ids.filter_map(|id| sources.get(id)) {
        h.str(&f.name).str(&f.text);
    }
    h.str(&format!("{frame:?} {:?}", settings.resolution));
    for list in [
        &settings.shader_paths,
        &settings.texture_paths,
        &settings.archive_paths,
    ] {
        h.str(&list.join(":"));
    }
    for d in &settings.include_dirs {
        h.str(&d.display().to_string());
    }
    for (n, v) in &settings.defines {
        h.str(n).str(v.as_deref().unwrap_or(""));
    }
    h.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hash_sees_text_and_settings() {
        let s = SourceMap::new();
        s.add("a.rib", "Sphere 1 -1 1 360");
        let base = Settings::default();
        let h = settings_hash(&s, 0..1, &base, Some(1));
        assert_eq!(h, settings_hash(&s, 0..1, &base, Some(1)));
        assert_ne!(h, settings_hash(&s, 0..1, &base, Some(2)));
        let res = Settings {
            resolution: Some((64, 48)),
            ..Settings::default()
        };
        assert_ne!(h, settings_hash(&s, 0..1, &res, Some(1)));
        let t = SourceMap::new();
        t.add("a.rib", "Sphere 1 -1 1 180");
        assert_ne!(h, settings_hash(&t, 0..1, &base, Some(1)));
        // Threads and bucket size do not change pixels.
        let b = Settings {
            threads: 3,
            bucket_size: Some([7, 7]),
            ..Settings::default()
        };
        assert_eq!(h, settings_hash(&s, 0..1, &b, Some(1)));
    }
}
