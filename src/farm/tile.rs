//! Tiles of a frame: which pixels tile I of N covers, and the tile file that holds them.
//!
//! Input: the frame's output region (the CropWindow's pixels at the final resolution) and a
//! [`TileSpec`]. Output: the tile's pixel rectangle, the NDC crop window that renders exactly
//! those pixels, and a tile file (OpenEXR, 32-bit float, every film channel, positioned at the
//! tile's data window inside the full display window, with an `arbor.tile` text attribute).
//! Invariants: the N rectangles partition the region exactly (no gaps, no overlaps); tiles are
//! rendered like any crop window, i.e. with their filter margins sampled, so each pixel has
//! the bits a whole-frame render gives it; the tile file keeps the film's floats exactly
//! (before quantize and dither, which the merge applies to the whole frame).

use std::path::{Path, PathBuf};

use crate::diag::Diag;
use crate::film::Film;
use crate::render::PixelRect;

/// Tile `index` (1-based) of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileSpec {
    pub index: u32,
    pub count: u32,
}

impl TileSpec {
    /// Parses `I/N` (1 ≤ I ≤ N).
    pub fn parse(s: &str) -> Result<TileSpec, String> {
        let bad = || format!("--tile takes I/N with 1 ≤ I ≤ N (e.g. 3/4), found `{s}`");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: u32 = i.trim().parse().map_err(|_| bad())?;
        let count: u32 = n.trim().parse().map_err(|_| bad())?;
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(TileSpec { index, count })
    }
}

/// Columns × rows for `n` tiles over a `w × h` region: the factor pair whose tiles are closest
/// to square (N = 4 on 64×48 → 2×2; N = 3 → 3×1 on a wide picture).
pub fn grid(n: u32, w: usize, h: usize) -> (u32, u32) {
    let mut best = (n, 1);
    let mut best_cost = f64::INFINITY;
    for cols in 1..=n {
        if n % cols != 0 {
            continue;
        }
        let rows = n / cols;
        let aspect = (w.max(1) as f64 / cols as f64) / (h.max(1) as f64 / rows as f64);
        let cost = aspect.ln().abs();
        if cost < best_cost - 1e-12 {
            best = (cols, rows);
            best_cost = cost;
        }
    }
    best
}

/// The pixels of tile `t` inside `region` (row-major: tile 1 is top-left).
pub fn rect(region: PixelRect, t: TileSpec) -> Result<PixelRect, Diag> {
    let (w, h) = (region.width(), region.height());
    let (cols, rows) = grid(t.count, w, h);
    if cols as usize > w || rows as usize > h {
        return Err(Diag::error(
            "farm::tiles",
            format!(
                "{} tiles ({cols}×{rows}) do not fit a {w}×{h} picture",
                t.count
            ),
        )
        .help("use fewer tiles than the picture has pixels in each direction"));
    }
    let k = t.index - 1;
    let (c, r) = ((k % cols) as usize, (k / cols) as usize);
    let edge = |lo: i32, len: usize, parts: u32, i: usize| lo + (i * len / parts as usize) as i32;
    Ok(PixelRect {
        x0: edge(region.x0, w, cols, c),
        x1: edge(region.x0, w, cols, c + 1),
        y0: edge(region.y0, h, rows, r),
        y1: edge(region.y0, h, rows, r + 1),
    })
}

/// The NDC crop window whose pixels (RISpec's `ceil` rounding, [`crate::render::crop_region`])
/// are exactly `r`: every edge sits on a pixel centre, half a pixel from either rounding step.
pub fn ndc_window(r: PixelRect, xres: u32, yres: u32) -> [f32; 4] {
    let f = |v: i32, res: u32| (v as f32 - 0.5) / res.max(1) as f32;
    [f(r.x0, xres), f(r.x1, xres), f(r.y0, yres), f(r.y1, yres)]
}

/// The tile file of tile `t` for a frame whose first picture is `display` (e.g.
/// `out/beauty.png` → `out/beauty.tile3of4.exr`).
pub fn path(display: &Path, t: TileSpec) -> PathBuf {
    let stem = display
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "ri".into());
    display.with_file_name(format!("{stem}.tile{}of{}.exr", t.index, t.count))
}

/// What a tile file says about itself.
#[derive(Clone, Debug, PartialEq)]
pub struct TileMeta {
    /// FrameBegin number (None: the file has no FrameBegin).
    pub frame: Option<i32>,
    pub tile: TileSpec,
    /// Resolution of the whole picture.
    pub xres: u32,
    pub yres: u32,
    /// The frame's output region (its CropWindow pixels) and this tile's pixels.
    pub region: PixelRect,
    pub rect: PixelRect,
    /// [`super::settings_hash`] of the render.
    pub settings: u64,
    /// An Imager shader already ran over the pixels (the merge must not apply it again).
    pub imager_applied: bool,
    /// Film channel names, in film order.
    pub channels: Vec<String>,
}

const ATTRIBUTE: &str = "arbor.tile";

impl TileMeta {
    fn to_text(&self) -> String {
        let r = |p: PixelRect| format!("{} {} {} {}", p.x0, p.y0, p.x1, p.y1);
        format!(
            "version {}\nframe {}\ntile {}/{}\nresolution {} {}\nregion {}\nrect {}\n\
             settings {:016x}\nimager {}\nchannels {}\n",
            env!("CARGO_PKG_VERSION"),
            self.frame.map_or("-".into(), |f| f.to_string()),
            self.tile.index,
            self.tile.count,
            self.xres,
            self.yres,
            r(self.region),
            r(self.rect),
            self.settings,
            self.imager_applied as u8,
            self.channels.join(" ")
        )
    }

    fn from_text(text: &str) -> Option<TileMeta> {
        let mut m = std::collections::HashMap::new();
        for line in text.lines() {
            let (k, v) = line.split_once(' ').unwrap_or((line, ""));
            m.insert(k, v);
        }
        let ints = |k: &str| -> Option<Vec<i64>> {
            m.get(k)?
                .split_whitespace()
                .map(|v| v.parse().ok())
                .collect()
        };
        let rect = |k: &str| -> Option<PixelRect> {
            match ints(k)?.as_slice() {
                &[x0, y0, x1, y1] => Some(PixelRect {
                    x0: x0 as i32,
                    y0: y0 as i32,
                    x1: x1 as i32,
                    y1: y1 as i32,
                }),
                _ => None,
            }
        };
        let res = ints("resolution")?;
        Some(TileMeta {
            frame: match *m.get("frame")? {
                "-" => None,
                f => Some(f.parse().ok()?),
            },
            tile: TileSpec::parse(m.get("tile")?).ok()?,
            xres: *res.first()? as u32,
            yres: *res.get(1)? as u32,
            region: rect("region")?,
            rect: rect("rect")?,
            settings: u64::from_str_radix(m.get("settings")?, 16).ok()?,
            imager_applied: *m.get("imager")? == "1",
            channels: m.get("channels")?.split(' ').map(String::from).collect(),
        })
    }
}

/// Writes the pixels `meta.rect` of a full-resolution `film` as a tile file (atomically).
pub fn write(path: &Path, film: &Film, meta: &TileMeta) -> Result<(), Diag> {
    use exr::prelude::*;
    let r = meta.rect;
    let tile = film.cropped(r.x0 as usize, r.y0 as usize, r.x1 as usize, r.y1 as usize);
    let (w, h, n) = (tile.width, tile.height, tile.channels());
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (c, name) in tile.channel_names.iter().enumerate() {
        let vals: Vec<f32> = (0..w * h).map(|i| tile.data[i * n + c]).collect();
        channels.push(AnyChannel::new(name.as_str(), FlatSamples::F32(vals)));
    }
    let mut attributes = LayerAttributes::default();
    attributes.layer_position = Vec2(r.x0, r.y0);
    attributes.other.insert(
        Text::from(ATTRIBUTE),
        AttributeValue::Text(Text::from(meta.to_text().as_str())),
    );
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new((w, h), attributes, encoding, AnyChannels::sort(channels));
    let mut image = Image::from_layer(layer);
    image.attributes.display_window =
        IntegerBounds::new((0, 0), (meta.xres as usize, meta.yres as usize));
    crate::film::write_atomically(path, |f| {
        image
            .write()
            .non_parallel()
            .to_buffered(f)
            .map_err(|e| e.to_string())
    })
}

/// A tile read back: its metadata and its pixels (width × height of `meta.rect`, channels in
/// `meta.channels` order).
pub struct TileFile {
    pub meta: TileMeta,
    /// Size of the stored pixels (the file's data window).
    pub width: usize,
    pub height: usize,
    pub position: (i32, i32),
    pub data: Vec<f32>,
}

/// Reads a tile file. Errors name the file and what is wrong with it.
pub fn read(path: &Path) -> Result<TileFile, Diag> {
    use exr::prelude::*;
    let fail = |what: String| {
        Diag::error(
            "farm::tile-file",
            format!("`{}` is not an arbor tile: {what}", path.display()),
        )
        .help("tile files are written by `arbor render --tile I/N`; render the tile again")
    };
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| fail(e.to_string()))?;
    let layer = &image.layer_data;
    let meta = match layer.attributes.other.get(&Text::from(ATTRIBUTE)) {
        Some(AttributeValue::Text(t)) => TileMeta::from_text(&t.to_string())
            .ok_or_else(|| fail("unreadable `arbor.tile` attribute".into()))?,
        _ => return Err(fail("no `arbor.tile` attribute".into())),
    };
    let (width, height) = (layer.size.0, layer.size.1);
    let n = meta.channels.len();
    let mut data = vec![0.0f32; width * height * n];
    for (c, name) in meta.channels.iter().enumerate() {
        let ch = layer
            .channel_data
            .list
            .iter()
            .find(|ch| ch.name.to_string() == *name)
            .ok_or_else(|| fail(format!("channel `{name}` is missing")))?;
        for (i, v) in ch
            .sample_data
            .values_as_f32()
            .enumerate()
            .take(width * height)
        {
            data[i * n + c] = v;
        }
    }
    let p = layer.attributes.layer_position;
    Ok(TileFile {
        meta,
        width,
        height,
        position: (p.0, p.1),
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::crop_region;

    fn region(w: i32, h: i32) -> PixelRect {
        PixelRect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        }
    }

    #[test]
    fn tiles_partition_the_region_and_their_windows_round_to_them() {
        for (xres, yres) in [
            (64u32, 48u32),
            (641, 479),
            (1920, 1080),
            (7, 5),
            (8192, 4320),
        ] {
            for n in [1u32, 2, 3, 4, 6, 7, 12] {
                let full = region(xres as i32, yres as i32);
                let mut covered = vec![0u8; (xres * yres) as usize];
                for i in 1..=n {
                    let t = TileSpec { index: i, count: n };
                    let Ok(r) = rect(full, t) else { continue };
                    assert!(!r.is_empty(), "{xres}x{yres} {i}/{n}");
                    assert_eq!(crop_region(xres, yres, ndc_window(r, xres, yres)), r);
                    for y in r.y0..r.y1 {
                        for x in r.x0..r.x1 {
                            covered[(y as u32 * xres + x as u32) as usize] += 1;
                        }
                    }
                }
                if rect(full, TileSpec { index: 1, count: n }).is_ok() {
                    assert!(covered.iter().all(|&c| c == 1), "{xres}x{yres} n={n}");
                }
            }
        }
    }

    #[test]
    fn near_square_grids_and_parsing() {
        assert_eq!(grid(4, 64, 48), (2, 2));
        assert_eq!(grid(3, 640, 480), (3, 1));
        assert_eq!(grid(2, 48, 64), (1, 2));
        assert_eq!(TileSpec::parse("3/4"), Ok(TileSpec { index: 3, count: 4 }));
        assert!(TileSpec::parse("0/4").is_err());
        assert!(TileSpec::parse("5/4").is_err());
        assert!(TileSpec::parse("2").is_err());
        assert_eq!(
            path(Path::new("out/beauty.png"), TileSpec { index: 3, count: 4 }),
            PathBuf::from("out/beauty.tile3of4.exr")
        );
        // A tile inside a crop region.
        let reg = PixelRect {
            x0: 10,
            y0: 4,
            x1: 30,
            y1: 24,
        };
        let r = rect(reg, TileSpec { index: 4, count: 4 }).unwrap();
        assert_eq!(
            r,
            PixelRect {
                x0: 20,
                y0: 14,
                x1: 30,
                y1: 24
            }
        );
        assert!(rect(region(2, 2), TileSpec { index: 1, count: 9 }).is_err());
    }

    #[test]
    fn tile_files_keep_floats_and_metadata() {
        let dir = std::env::temp_dir().join(format!("arbor-tile-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let names: Vec<String> = ["r", "g", "b", "a", "z", "N.x"].map(String::from).to_vec();
        let mut film = Film::new(8, 6, names.clone());
        for (i, v) in film.data.iter_mut().enumerate() {
            *v = (i as f32 * 0.37).sin() * 1e3;
        }
        let meta = TileMeta {
            frame: Some(7),
            tile: TileSpec { index: 4, count: 4 },
            xres: 8,
            yres: 6,
            region: region(8, 6),
            rect: PixelRect {
                x0: 4,
                y0: 3,
                x1: 8,
                y1: 6,
            },
            settings: 0xdead_beef_0123_4567,
            imager_applied: true,
            channels: names,
        };
        let p = dir.join("t.exr");
        write(&p, &film, &meta).unwrap();
        let t = read(&p).unwrap();
        assert_eq!(t.meta, meta);
        assert_eq!((t.width, t.height, t.position), (4, 3, (4, 3)));
        for y in 0..3 {
            for x in 0..4 {
                assert_eq!(&t.data[(y * 4 + x) * 6..][..6], film.pixel(x + 4, y + 3));
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
