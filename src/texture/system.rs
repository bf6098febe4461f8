//! The texture system a frame renders with: finds, opens and caches textures, and answers
//! the shading language's texture(), environment(), shadow(), bump() and textureinfo().
//!
//! Input: the frame's texture search path and memory limit. Output: [`TextureLookup`] answers.
//! Invariants: a name is resolved and opened once per frame (maps written by an earlier
//! frame are seen by later ones because each frame gets a fresh system); a raw picture or
//! zfile named directly is converted in memory on first use, with a warning; a missing or
//! unreadable texture answers `false` (the caller warns and uses the fill value).
//! Summed-area tables (`"filter" "sat"`) are built once per texture on first use, on the
//! finest level whose f64 table fits in the texture memory limit; they are held beside the
//! tile cache (not counted in its bound, but never larger than it).

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use glam::Vec3;

use crate::diag::{Diag, Diagnostics};
use crate::film::zfile::{ZFile, ZFILE_MAGIC};
use crate::shade::exec::{InfoValue, TextureLookup, TextureParams};

use super::bump::slope_channel;
use super::cache::{Fetcher, Source, Texture, TileCache};
use super::env::{cube_lookup, latlong_lookup};
use super::filter::{lookup, FilterKind, Footprint};
use super::format::{self, Header, Kind, TILE};
use super::image_in::read_image;
use super::make::{resolve, shadow_image};
use super::mipmap::{build_pyramid, Downsample, Wrap};
use super::sat::Sat;
use super::shadow::{pcf, LightView, ShadowParams};

/// Default cache size when the scene sets no `Option "limits" "texturememory"`: 256 MB.
pub const DEFAULT_MEMORY_KB: usize = 256 * 1024;

/// Folders that published scene packages keep their maps in (beside or above the scenes).
const TEXTURE_FOLDERS: [&str; 5] = ["texture", "textures", "tifftexture", "tex", "maps"];
/// Picture files a missing map may have been made from.
const PICTURE_EXTENSIONS: [&str; 8] = ["tif", "tiff", "TIF", "TIFF", "png", "exr", "jpg", "tga"];

pub struct TextureSystem<'a> {
    search: Vec<PathBuf>,
    pub cache: TileCache,
    textures: Mutex<HashMap<String, Option<Arc<Texture>>>>,
    next_id: AtomicU32,
    warned: Mutex<HashSet<String>>,
    diags: &'a Diagnostics,
}

impl<'a> TextureSystem<'a> {
    /// `search`: directories tried after the name as given; `memory_kb`: the cache bound.
    pub fn new(
        search: Vec<PathBuf>,
        memory_kb: usize,
        diags: &'a Diagnostics,
    ) -> TextureSystem<'a> {
        TextureSystem {
            search,
            cache: TileCache::new(memory_kb.max(1) * 1024),
            textures: Mutex::new(HashMap::new()),
            next_id: AtomicU32::new(1),
            warned: Mutex::new(HashSet::new()),
            diags,
        }
    }

    fn warn_once(&self, key: String, d: Diag) {
        if let Ok(mut w) = self.warned.lock() {
            if w.insert(key) {
                self.diags.report(d);
            }
        }
    }

    /// The opened texture for a name (None when it cannot be found or read; warned once).
    pub fn open(&self, name: &str) -> Option<Arc<Texture>> {
        let mut map = self.textures.lock().ok()?;
        if let Some(t) = map.get(name) {
            return t.clone();
        }
        let t = match self.load(name, &resolve(name, &self.search), true) {
            Ok(t) => Some(Arc::new(t)),
            Err(e) => match self.stand_in(name) {
                Some((path, t)) => {
                    self.diags.report(
                        Diag::warning(
                            "texture::stand-in",
                            format!(
                                "texture `{name}` is not on the texture path ({e}); using `{}`, \
                                 found where published scenes keep their maps",
                                path.display()
                            ),
                        )
                        .help(format!(
                            "make the map explicit: `arbor texture {} {name}`, or add its folder \
                             to `Option \"searchpath\" \"texture\"` (--textures)",
                            path.display()
                        )),
                    );
                    Some(Arc::new(t))
                }
                None => {
                    self.diags.report(Diag::warning("texture::open", e));
                    None
                }
            },
        };
        map.insert(name.to_string(), t.clone());
        t
    }

    /// A map for a texture name that cannot be opened as given: published scenes refer to
    /// `name.tx` made by a texture tool that was never run (the source picture `name.tiff`
    /// lies beside the RIB, or in the package folder above a scene's subfolder), or keep their
    /// maps in a `texture`/`textures`/`tifftexture` folder that an options file (`prman.opt`,
    /// `bmrt.opt`) puts on the path. Tries, in the scene's search directories, those folders
    /// beside and above them, then the folders above: the name itself, then the pictures of
    /// the same stem; the first that loads is used (a renderer's own binary format that arbor
    /// cannot read is passed over).
    fn stand_in(&self, name: &str) -> Option<(PathBuf, Texture)> {
        let given = std::path::Path::new(name);
        let file = given.file_name()?.to_str()?.to_string();
        let stem = given.file_stem()?.to_str()?.to_string();
        let mut dirs: Vec<PathBuf> = Vec::new();
        let mut push = |d: PathBuf| {
            if d.is_dir() && !dirs.contains(&d) {
                dirs.push(d);
            }
        };
        for d in &self.search {
            push(d.clone());
        }
        for d in &self.search {
            for up in [d.clone(), d.join("..")] {
                for sub in TEXTURE_FOLDERS {
                    push(up.join(sub));
                }
            }
        }
        // A scene in a subfolder of its package shares the package's maps.
        for d in &self.search {
            push(d.join(".."));
        }
        let mut names = vec![file.clone()];
        for ext in PICTURE_EXTENSIONS {
            let n = format!("{stem}.{ext}");
            if n != file {
                names.push(n);
            }
        }
        for d in &dirs {
            for n in &names {
                // A name that differs only in case is found too (scenes from case-insensitive
                // file systems); the exact name on the search path was tried already.
                let Some(c) = crate::pathcase::find_file_ignoring_case(&d.join(n)) else {
                    continue;
                };
                if c == d.join(n) && n == &file && self.search.contains(d) {
                    continue;
                }
                if let Ok(t) = self.load(name, &c, false) {
                    return Some((c, t));
                }
            }
        }
        None
    }

    /// Opens the map at `path` for `name`; `note_raw`: warn when it is a plain picture.
    fn load(&self, name: &str, path: &std::path::Path, note_raw: bool) -> Result<Texture, String> {
        let path = path.to_path_buf();
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let mut file = File::open(&path)
            .map_err(|e| format!("texture `{name}`: cannot open `{}`: {e}", path.display()))?;
        let mut head = vec![0u8; format::header_len_upper_bound()];
        let mut got = 0;
        while got < head.len() {
            match file.read(&mut head[got..]) {
                Ok(0) => break,
                Ok(k) => got += k,
                Err(e) => return Err(format!("texture `{name}`: {e}")),
            }
        }
        head.truncate(got);
        if head.starts_with(&format::MAGIC) {
            let header =
                format::parse_header(&head).map_err(|e| format!("texture `{name}`: {e}"))?;
            return Ok(Texture::new(id, header, Source::File(file)));
        }
        let blank = |kind: Kind, nchan: usize, wrap: Wrap, matrices| Header {
            kind,
            nchan,
            nfaces: 1,
            swrap: wrap,
            twrap: wrap,
            tile: TILE,
            levels: Vec::new(),
            matrices,
        };
        if head.starts_with(&ZFILE_MAGIC) {
            let bytes = std::fs::read(&path).map_err(|e| format!("texture `{name}`: {e}"))?;
            let z = ZFile::from_bytes(&bytes).map_err(|e| format!("shadow map `{name}`: {e}"))?;
            let (im, m) = shadow_image(&z).map_err(|e| format!("shadow map `{name}`: {e}"))?;
            return Ok(Texture::from_pyramids(
                id,
                blank(Kind::Shadow, 1, Wrap::Black, Some(m)),
                &[vec![im]],
            ));
        }
        if super::prman_tx::is_prman_tx(&head) {
            // Already a mip-map: its own (txmake-filtered) levels and wrap modes are used.
            let bytes = std::fs::read(&path).map_err(|e| format!("texture `{name}`: {e}"))?;
            let t = super::prman_tx::decode(&bytes).map_err(|e| {
                format!("texture `{name}`: PRMan texture `{}`: {e}", path.display())
            })?;
            let mut header = blank(Kind::Texture, t.levels[0].nchan, t.swrap, None);
            header.twrap = t.twrap;
            return Ok(Texture::from_pyramids(id, header, &[t.levels]));
        }
        let im = read_image(&path).map_err(|e| format!("texture `{name}`: {e}"))?;
        if note_raw {
            self.diags.report(
                Diag::warning(
                    "texture::raw",
                    format!(
                        "texture `{name}` is a plain picture: converted to a mip-map on first use"
                    ),
                )
                .help(format!(
                    "prepare it once with `arbor texture {name} {name}.tex`"
                )),
            );
        }
        let nchan = im.nchan;
        let (swrap, twrap) =
            super::image_in::tiff_wrap_hint(&path).unwrap_or((Wrap::Periodic, Wrap::Periodic));
        let levels = build_pyramid(im, swrap, twrap, Downsample::Box);
        let mut header = blank(Kind::Texture, nchan, swrap, None);
        header.twrap = twrap;
        Ok(Texture::from_pyramids(id, header, &[levels]))
    }

    fn filter_kind(&self, name: &str) -> FilterKind {
        FilterKind::parse(name).unwrap_or_else(|| {
            self.warn_once(
                format!("filter:{name}"),
                Diag::warning(
                    "texture::filter",
                    format!("texture filter \"{name}\" is not known; using gaussian (EWA)"),
                ),
            );
            FilterKind::Ewa
        })
    }

    /// The summed-area table of a texture's face 0 (built on first use; warned once when
    /// memory forces a coarser level, None when no level fits or the level cannot be read).
    fn sat(&self, name: &str, tex: &Texture) -> Option<Arc<Sat>> {
        tex.sat
            .get_or_init(|| {
                let h = &tex.header;
                let budget = self.cache.limit_bytes();
                let level = h.levels[0]
                    .iter()
                    .position(|l| Sat::bytes_for(l.width, l.height, h.nchan) <= budget)?;
                let l = h.levels[0][level];
                if level > 0 {
                    self.warn_once(
                        format!("sat:{name}"),
                        Diag::warning(
                            "texture::sat",
                            format!(
                                "the summed-area table of `{name}` is built on level {level} ({}×{}) to fit Option \"limits\" \"texturememory\"",
                                l.width, l.height
                            ),
                        ),
                    );
                }
                match tex.read_level(0, level) {
                    Ok(im) => Some(Arc::new(Sat::build(&im, h.swrap, h.twrap, level))),
                    Err(e) => {
                        self.diags
                            .report(Diag::warning("texture::sat", format!("`{name}`: {e}")));
                        None
                    }
                }
            })
            .clone()
    }

    fn kind_mismatch(&self, name: &str, tex: &Texture, want: &str) {
        self.warn_once(
            format!("kind:{name}:{want}"),
            Diag::warning(
                "texture::kind",
                format!(
                    "`{name}` is a {} map, used by {want}()",
                    tex.header.kind.type_name()
                ),
            ),
        );
    }
}

impl TextureLookup for TextureSystem<'_> {
    fn texture(
        &self,
        name: &str,
        first_chan: usize,
        nchan: usize,
        st: &[[f32; 8]],
        params: &TextureParams,
        out: &mut [f32],
    ) -> bool {
        let Some(tex) = self.open(name) else {
            return false;
        };
        if !matches!(tex.header.kind, Kind::Texture | Kind::Bump) {
            self.kind_mismatch(name, &tex, "texture");
        }
        let kind = self.filter_kind(&params.filter);
        if kind == FilterKind::Sat {
            if let Some(sat) = self.sat(name, &tex) {
                for (i, c) in st.iter().enumerate() {
                    let o = &mut out[i * nchan..(i + 1) * nchan];
                    o.iter_mut().for_each(|v| *v = params.fill);
                    let fp = Footprint::from_corners(c, params.swidth, params.twidth);
                    sat.lookup(&fp, params.sblur, params.tblur, first_chan, o);
                }
                return true;
            }
        }
        let mut f = Fetcher::new(&tex, &self.cache, first_chan, nchan);
        for (i, c) in st.iter().enumerate() {
            let o = &mut out[i * nchan..(i + 1) * nchan];
            o.iter_mut().for_each(|v| *v = params.fill);
            let fp = Footprint::from_corners(c, params.swidth, params.twidth);
            lookup(&mut f, 0, &fp, params.sblur, params.tblur, kind, o);
        }
        true
    }

    fn environment(
        &self,
        name: &str,
        first_chan: usize,
        nchan: usize,
        dirs: &[[Vec3; 5]],
        params: &TextureParams,
        out: &mut [f32],
    ) -> bool {
        let Some(tex) = self.open(name) else {
            return false;
        };
        let kind = self.filter_kind(&params.filter);
        if kind == FilterKind::Sat {
            self.warn_once(
                format!("envsat:{name}"),
                Diag::warning(
                    "texture::filter",
                    format!("filter \"sat\" applies to texture() and bump(); environment `{name}` is filtered trilinearly"),
                ),
            );
        }
        let blur = params.sblur.max(params.tblur);
        let mut f = Fetcher::new(&tex, &self.cache, first_chan, nchan);
        for (i, d) in dirs.iter().enumerate() {
            let o = &mut out[i * nchan..(i + 1) * nchan];
            o.iter_mut().for_each(|v| *v = params.fill);
            // swidth/twidth scale the footprint around its centre direction.
            let wdt = 0.5 * (params.swidth + params.twidth);
            let mut dd = *d;
            for k in 1..5 {
                dd[k] = d[0] + (d[k] - d[0]) * wdt;
            }
            match tex.header.kind {
                Kind::Cube => {
                    cube_lookup(&mut f, &dd, blur, o);
                }
                Kind::LatLong => latlong_lookup(&mut f, &dd, blur, kind, o),
                _ => {
                    self.kind_mismatch(name, &tex, "environment");
                    latlong_lookup(&mut f, &dd, blur, kind, o)
                }
            }
        }
        true
    }

    fn shadow(
        &self,
        name: &str,
        pts: &[[Vec3; 5]],
        params: &TextureParams,
        out: &mut [f32],
    ) -> bool {
        let Some(tex) = self.open(name) else {
            return false;
        };
        let Some((a, b)) = tex.header.matrices else {
            self.kind_mismatch(name, &tex, "shadow");
            return false;
        };
        let view = LightView::from_rows(&a, &b);
        let p = ShadowParams {
            samples: params.samples.max(1.0) as usize,
            bias: params.bias,
            blur: params.sblur.max(params.tblur),
            width: 0.5 * (params.swidth + params.twidth),
        };
        let mut f = Fetcher::new(&tex, &self.cache, 0, 1);
        for (i, q) in pts.iter().enumerate() {
            out[i] = pcf(&mut f, &view, q, &p);
        }
        true
    }

    fn bump_slopes(
        &self,
        name: &str,
        chan: usize,
        st: &[[f32; 8]],
        params: &TextureParams,
        out: &mut [f32],
    ) -> bool {
        let Some(tex) = self.open(name) else {
            return false;
        };
        let kind = self.filter_kind(&params.filter);
        let h = &tex.header;
        match h.kind {
            Kind::Bump => {
                // Filtered precomputed slopes: the derivative of the filtered height.
                let heights = h.nchan / 3;
                let first = slope_channel(h.nchan, chan);
                let sat = if kind == FilterKind::Sat {
                    self.sat(name, &tex)
                } else {
                    None
                };
                let mut f = Fetcher::new(&tex, &self.cache, first, 2);
                for (i, c) in st.iter().enumerate() {
                    let o = &mut out[2 * i..2 * i + 2];
                    o.fill(0.0);
                    if chan < heights {
                        let fp = Footprint::from_corners(c, params.swidth, params.twidth);
                        match &sat {
                            Some(t) => t.lookup(&fp, params.sblur, params.tblur, first, o),
                            None => lookup(&mut f, 0, &fp, params.sblur, params.tblur, kind, o),
                        }
                    }
                }
            }
            _ => {
                if h.kind != Kind::Texture {
                    self.kind_mismatch(name, &tex, "bump");
                }
                // A plain height texture: central differences of the filtered height across
                // the footprint (half its extent each way, one level-0 texel at least).
                let l0 = h.levels[0][0];
                let (w, ht) = (l0.width as f32, l0.height as f32);
                let mut f = Fetcher::new(&tex, &self.cache, chan, 1);
                let sat = if kind == FilterKind::Sat {
                    self.sat(name, &tex)
                } else {
                    None
                };
                let mut sample = |fp: &Footprint| {
                    let mut v = [0f32];
                    match &sat {
                        Some(t) => t.lookup(fp, params.sblur, params.tblur, chan, &mut v),
                        None => lookup(&mut f, 0, fp, params.sblur, params.tblur, kind, &mut v),
                    }
                    v[0]
                };
                for (i, c) in st.iter().enumerate() {
                    let fp = Footprint::from_corners(c, params.swidth, params.twidth);
                    let ds = (0.5 * (fp.ds1.abs() + fp.ds2.abs())).max(1.0 / w);
                    let dt = (0.5 * (fp.dt1.abs() + fp.dt2.abs())).max(1.0 / ht);
                    let at = |s: f32, t: f32| Footprint { s, t, ..fp };
                    let bs =
                        (sample(&at(fp.s + ds, fp.t)) - sample(&at(fp.s - ds, fp.t))) / (2.0 * ds);
                    let bt =
                        (sample(&at(fp.s, fp.t + dt)) - sample(&at(fp.s, fp.t - dt))) / (2.0 * dt);
                    out[2 * i] = if bs.is_finite() { bs } else { 0.0 };
                    out[2 * i + 1] = if bt.is_finite() { bt } else { 0.0 };
                }
            }
        }
        true
    }

    fn search_path(&self) -> &[PathBuf] {
        &self.search
    }

    fn info(&self, name: &str, query: &str) -> Option<InfoValue> {
        let tex = self.open(name)?;
        let h = &tex.header;
        let l = h.levels[0][0];
        match query {
            "resolution" => Some(InfoValue::Floats(vec![l.width as f32, l.height as f32])),
            "type" => Some(InfoValue::Str(h.kind.type_name().into())),
            "channels" => Some(InfoValue::Floats(vec![if h.kind == Kind::Bump {
                (h.nchan / 3) as f32
            } else {
                h.nchan as f32
            }])),
            "viewingmatrix" | "projectionmatrix" => {
                let (a, b) = h.matrices?;
                let m = if query == "viewingmatrix" { a } else { b };
                // Row-major in the file; InfoValue matrices are column-major (glam).
                let g = glam::Mat4::from_cols_array(&m).transpose();
                Some(InfoValue::Floats(g.to_cols_array().to_vec()))
            }
            _ => None,
        }
    }
}
