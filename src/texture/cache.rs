//! The texture cache: tiles loaded on demand, shared by every rendering thread, bounded in
//! memory (`Option "limits" "texturememory"`, KB).
//!
//! Input: opened [`Texture`]s (a tiled file, or an in-memory pyramid for raw pictures
//! converted on first use). Output: texel values through a per-lookup [`Fetcher`].
//! Invariants: a tile is read from disk at most once while resident; when the resident bytes
//! of a shard exceed its share of the limit, the least recently used tiles are dropped (tiles
//! in use stay alive through their `Arc`), so a scene with more texture than memory still
//! renders, only slower. A failed read yields a zero tile and counts in `read_errors`.

use std::collections::HashMap;
use std::fs::File;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use super::format::{self, Header};
use super::image_in::Image;
use super::sat::Sat;

/// Where a texture's tiles come from.
pub enum Source {
    /// A prepared `.tex` file, read tile by tile.
    File(File),
    /// Tiles already in memory: [face][level][tile index].
    Memory(Vec<Vec<Vec<Arc<[f32]>>>>),
}

/// An opened texture.
pub struct Texture {
    /// Unique per texture system (cache key).
    pub id: u32,
    pub header: Header,
    pub source: Source,
    /// The summed-area table, built on the first `"filter" "sat"` lookup (None when the
    /// level could not be read).
    pub sat: OnceLock<Option<Arc<Sat>>>,
}

impl Texture {
    pub fn new(id: u32, header: Header, source: Source) -> Texture {
        Texture {
            id,
            header,
            source,
            sat: OnceLock::new(),
        }
    }

    /// A whole level of a face, read straight from the source (not through the cache, so
    /// building a summed-area table does not evict the tiles other lookups use).
    pub fn read_level(&self, face: usize, level: usize) -> Result<Image, String> {
        let h = &self.header;
        let l = h.levels[face][level];
        let (t, nc) = (h.tile, h.nchan);
        let mut im = Image::new(l.width, l.height, nc);
        for ty in 0..l.height.div_ceil(t) {
            for tx in 0..l.width.div_ceil(t) {
                let tile: Arc<[f32]> = match &self.source {
                    Source::Memory(m) => m[face][level][ty * l.tiles_x(t) + tx].clone(),
                    Source::File(f) => Arc::from(format::read_tile(f, h, face, level, tx, ty)?),
                };
                for y in ty * t..((ty + 1) * t).min(l.height) {
                    for x in tx * t..((tx + 1) * t).min(l.width) {
                        let src = (((y % t) * t) + (x % t)) * nc;
                        let dst = (y * l.width + x) * nc;
                        im.data[dst..dst + nc].copy_from_slice(&tile[src..src + nc]);
                    }
                }
            }
        }
        Ok(im)
    }

    /// Tiles a set of pyramids in memory (raw pictures converted on first use, zfiles).
    pub fn from_pyramids(id: u32, mut header: Header, faces: &[Vec<Image>]) -> Texture {
        let t = header.tile;
        header.levels = faces
            .iter()
            .map(|f| {
                f.iter()
                    .map(|l| format::LevelInfo {
                        width: l.width,
                        height: l.height,
                        offset: 0,
                    })
                    .collect()
            })
            .collect();
        let tiles = faces
            .iter()
            .map(|f| {
                f.iter()
                    .map(|l| {
                        let mut out = Vec::new();
                        for ty in 0..l.height.div_ceil(t) {
                            for tx in 0..l.width.div_ceil(t) {
                                let mut v = Vec::with_capacity(t * t * l.nchan);
                                for y in 0..t {
                                    for x in 0..t {
                                        let sx = (tx * t + x).min(l.width - 1);
                                        let sy = (ty * t + y).min(l.height - 1);
                                        v.extend_from_slice(l.px(sx, sy));
                                    }
                                }
                                out.push(Arc::from(v));
                            }
                        }
                        out
                    })
                    .collect()
            })
            .collect();
        Texture::new(id, header, Source::Memory(tiles))
    }
}

type Key = (u32, u8, u8, u32, u32);

struct Shard {
    map: HashMap<Key, (Arc<[f32]>, u64)>,
    bytes: usize,
}

const SHARDS: usize = 16;

/// Tiles of every texture of a render, shared across threads.
pub struct TileCache {
    shards: Vec<Mutex<Shard>>,
    limit_per_shard: usize,
    clock: AtomicU64,
    /// Tiles read from disk (for statistics and tests).
    pub reads: AtomicUsize,
    pub evictions: AtomicUsize,
    pub read_errors: AtomicUsize,
}

impl TileCache {
    /// A cache holding at most `limit_bytes` of tiles (at least one tile per shard).
    pub fn new(limit_bytes: usize) -> TileCache {
        TileCache {
            shards: (0..SHARDS)
                .map(|_| {
                    Mutex::new(Shard {
                        map: HashMap::new(),
                        bytes: 0,
                    })
                })
                .collect(),
            limit_per_shard: limit_bytes / SHARDS,
            clock: AtomicU64::new(0),
            reads: AtomicUsize::new(0),
            evictions: AtomicUsize::new(0),
            read_errors: AtomicUsize::new(0),
        }
    }

    /// The memory bound in bytes.
    pub fn limit_bytes(&self) -> usize {
        self.limit_per_shard * SHARDS
    }

    /// Resident bytes (approximate while other threads work).
    pub fn resident_bytes(&self) -> usize {
        self.shards
            .iter()
            .map(|s| s.lock().map(|s| s.bytes).unwrap_or(0))
            .sum()
    }

    fn tile(&self, tex: &Texture, face: usize, level: usize, tx: usize, ty: usize) -> Arc<[f32]> {
        let file = match &tex.source {
            Source::Memory(t) => {
                let l = tex.header.levels[face][level];
                return t[face][level][ty * l.tiles_x(tex.header.tile) + tx].clone();
            }
            Source::File(f) => f,
        };
        let key: Key = (tex.id, face as u8, level as u8, tx as u32, ty as u32);
        let shard_i = (key.0 as usize)
            .wrapping_mul(31)
            .wrapping_add(key.3 as usize * 7 + key.4 as usize * 13 + level * 3 + face)
            % SHARDS;
        let stamp = self.clock.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut s) = self.shards[shard_i].lock() {
            if let Some(e) = s.map.get_mut(&key) {
                e.1 = stamp;
                return e.0.clone();
            }
        }
        // Read outside the lock: two threads may read the same tile once each; harmless.
        self.reads.fetch_add(1, Ordering::Relaxed);
        let data: Arc<[f32]> = match format::read_tile(file, &tex.header, face, level, tx, ty) {
            Ok(v) => Arc::from(v),
            Err(_) => {
                self.read_errors.fetch_add(1, Ordering::Relaxed);
                Arc::from(vec![0f32; format::tile_bytes(&tex.header) / 4])
            }
        };
        if let Ok(mut s) = self.shards[shard_i].lock() {
            let nbytes = data.len() * 4;
            s.bytes += nbytes;
            s.map.insert(key, (data.clone(), stamp));
            if s.bytes > self.limit_per_shard && s.map.len() > 1 {
                // Drop the oldest tiles down to 3/4 of the share.
                let mut ages: Vec<(u64, Key)> = s.map.iter().map(|(k, v)| (v.1, *k)).collect();
                ages.sort_unstable();
                let target = self.limit_per_shard * 3 / 4;
                for (_, k) in ages {
                    if s.bytes <= target || k == key {
                        continue;
                    }
                    if let Some((v, _)) = s.map.remove(&k) {
                        s.bytes -= v.len() * 4;
                        self.evictions.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        }
        data
    }
}

/// Texel access for one lookup batch: remembers the last few tiles so the cache's locks are
/// touched once per tile, not once per texel.
pub struct Fetcher<'a> {
    pub tex: &'a Texture,
    cache: &'a TileCache,
    recent: [(Key, Option<Arc<[f32]>>); 4],
    next: usize,
    /// First channel and channel count asked for.
    pub first: usize,
    pub nchan: usize,
}

impl<'a> Fetcher<'a> {
    pub fn new(tex: &'a Texture, cache: &'a TileCache, first: usize, nchan: usize) -> Fetcher<'a> {
        Fetcher {
            tex,
            cache,
            recent: Default::default(),
            next: 0,
            first,
            nchan,
        }
    }

    /// Adds `w` × texel (x, y) of (face, level) into `acc[..nchan]`; channels the texture
    /// lacks add nothing (the caller fills them). x, y must be inside the level.
    #[inline]
    pub fn accum(
        &mut self,
        face: usize,
        level: usize,
        x: usize,
        y: usize,
        w: f32,
        acc: &mut [f32],
    ) {
        let t = self.tex.header.tile;
        let (tx, ty) = (x / t, y / t);
        let key: Key = (self.tex.id, face as u8, level as u8, tx as u32, ty as u32);
        let slot = match self
            .recent
            .iter()
            .position(|(k, v)| v.is_some() && *k == key)
        {
            Some(i) => i,
            None => {
                let tile = self.cache.tile(self.tex, face, level, tx, ty);
                let i = self.next;
                self.next = (self.next + 1) % self.recent.len();
                self.recent[i] = (key, Some(tile));
                i
            }
        };
        let tile = self.recent[slot].1.as_ref().expect("filled");
        let nc = self.tex.header.nchan;
        let base = ((y % t) * t + (x % t)) * nc;
        let last = (self.first + self.nchan).min(nc);
        for c in self.first..last {
            acc[c - self.first] += w * tile[base + c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::format::{Kind, TILE};
    use crate::texture::mipmap::Wrap;

    #[test]
    fn bounded_cache_evicts_and_still_answers() {
        let n = 256;
        let mut im = Image::new(n, n, 1);
        for (i, v) in im.data.iter_mut().enumerate() {
            *v = (i % 1000) as f32;
        }
        let scratch = tempfile::Builder::new()
            .prefix("arbor-cache-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let p = dir.join("big.tex");
        format::write(
            &p,
            Kind::Texture,
            &[vec![im.clone()]],
            Wrap::Periodic,
            Wrap::Periodic,
            None,
        )
        .unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let header = format::parse_header(&bytes).unwrap();
        let tex = Texture::new(1, header, Source::File(File::open(&p).unwrap()));
        let whole = tex.read_level(0, 0).unwrap();
        assert_eq!(whole.data, im.data);
        // Room for about 16 tiles of the 64.
        let cache = TileCache::new(16 * TILE * TILE * 4);
        for pass in 0..2 {
            let mut f = Fetcher::new(&tex, &cache, 0, 1);
            for y in (0..n).step_by(7) {
                for x in (0..n).step_by(5) {
                    let mut acc = [0f32];
                    f.accum(0, 0, x, y, 1.0, &mut acc);
                    assert_eq!(acc[0], im.px(x, y)[0], "pass {pass} texel {x},{y}");
                }
            }
        }
        assert!(cache.evictions.load(Ordering::Relaxed) > 0);
        assert!(cache.resident_bytes() <= 16 * TILE * TILE * 4 + SHARDS * TILE * TILE * 4);
    }
}
