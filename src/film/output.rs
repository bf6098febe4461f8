//! Display output: the filtered [`Film`] → image files, one per `Display` request.
//!
//! Input: the film, the frame's [`Options`] (Exposure, Imager, Quantize, Display list) and an
//! optional CLI output path. Output: the written files' paths.
//! Pipeline (RISpec §4.1.4): exposure → imager (`background`) → quantize/dither → encode.
//! 8-bit PNG displays of a whole frame are usually encoded during the render, band by band
//! (`film::stream`, planned by [`plan_streams`]); here they are only written out.
//! Invariants: every file is written to a temporary name in its own directory and renamed, so
//! a failed write never leaves a partial image; colours stay premultiplied by alpha (TIFF says
//! so in its ExtraSamples tag, EXR is premultiplied by convention) except in a PNG with an alpha
//! channel, whose colour is straight as the PNG specification requires ([`straight_alpha`]);
//! requests this module cannot honour exactly produce a warning and the closest output, never
//! silence.
//!
//! Display types: `file` (TIFF; PNG/EXR when the name says so), `tiff`, `png`, `exr`/`openexr`,
//! `zfile`, `shadow` (zfile for now), `framebuffer` (no window: a PNG named after the display).
//! Modes: `rgb`, `rgba`, `a`, `z`, `rgbz`, `rgbaz`, `Ci`, or output-variable names
//! (comma-separated; a name `N` selects film channels `N` or `N.*`).
//! Bit depth: from the quantizer — `one` = 0 → float, `max` ≤ 255 → 8 bits, else 16 bits.
//! EXR ignores Quantize (it stores the unquantized values, half by default, `"float"` on
//! request; depth is always stored as 32-bit float).

use std::borrow::Cow;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use image::ImageEncoder;

use super::quantize::{
    apply_background, apply_exposure, is_float, quantize, quantize_row_u8, unpremultiply,
};
use super::resolve::Film;
use super::stream::{Layout, PngStream, Streams};
use super::zfile::ZFile;
use crate::diag::{Diag, Diagnostics, Span};
use crate::scene::{Display, Options, ParamList, Quantize, ShaderRef};

/// File formats the film can write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Tiff,
    Png,
    Exr,
    ZFile,
}

impl Format {
    /// The format a file extension names (`png`, `tif`/`tiff`, `exr`, `z`/`zfile`).
    pub fn from_extension(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "png" => Format::Png,
            "tif" | "tiff" => Format::Tiff,
            "exr" => Format::Exr,
            "z" | "zfile" => Format::ZFile,
            _ => return None,
        })
    }
}

/// One output file to produce.
#[derive(Clone, Debug)]
struct Target {
    path: PathBuf,
    format: Format,
    mode: String,
    params: ParamList,
    kind: String,
    span: Span,
}

/// Writes every display of the frame. Errors of individual displays are reported into `diags`
/// (after the first, which is returned) so one failing display does not stop the others.
pub fn write_displays(
    film: &Film,
    opts: &Options,
    diags: &Diagnostics,
    output_override: Option<&Path>,
) -> Result<Vec<PathBuf>, Diag> {
    write_displays_with_matrices(film, opts, diags, output_override, None)
}

/// [`write_displays`] with the camera's (camera_from_world, screen_from_world) matrices,
/// row-major, for zfile and shadow displays (screen normalised so the screen window is
/// [-1,1]²). With matrices a `"shadow"` display writes an arbor shadow texture.
pub fn write_displays_with_matrices(
    film: &Film,
    opts: &Options,
    diags: &Diagnostics,
    output_override: Option<&Path>,
    matrices: Option<([f32; 16], [f32; 16])>,
) -> Result<Vec<PathBuf>, Diag> {
    write_displays_streamed(
        film,
        opts,
        diags,
        output_override,
        matrices,
        Streams::default(),
    )
}

/// [`write_displays_with_matrices`] with the displays whose rows were encoded during the
/// render (see [`plan_streams`]): those are written from their streams, the rest from the film.
pub fn write_displays_streamed(
    film: &Film,
    opts: &Options,
    diags: &Diagnostics,
    output_override: Option<&Path>,
    matrices: Option<([f32; 16], [f32; 16])>,
    streams: Streams,
) -> Result<Vec<PathBuf>, Diag> {
    let img = prepare(film, opts, diags);
    let targets = plan(opts, diags, output_override, matrices.is_some())?;
    let mut streams = streams.displays.into_iter();
    let mut written = Vec::new();
    let mut first_err = None;
    for t in &targets {
        let stream = streams.next().flatten();
        match write_target(&img, t, opts, diags, matrices, stream) {
            Ok(()) => written.push(t.path.clone()),
            Err(e) => {
                if first_err.is_none() {
                    first_err = Some(e);
                } else {
                    diags.report(e);
                }
            }
        }
    }
    match first_err {
        Some(e) => Err(e),
        None => Ok(written),
    }
}

/// The displays of a frame that can be encoded while it renders: 8-bit PNGs of plain film
/// channels, for a film of `channel_names` and `width` × `height` written with `opts` (the
/// effective options, whole frame, no imager shader but `background`). Empty when none is.
pub fn plan_streams(
    opts: &Options,
    output_override: Option<&Path>,
    channel_names: Vec<String>,
    width: usize,
    height: usize,
) -> Streams {
    let quiet = Diagnostics::new();
    if opts.imager.as_ref().is_some_and(|i| i.name != "background") {
        return Streams::default();
    }
    let Ok(targets) = plan(opts, &quiet, output_override, true) else {
        return Streams::default();
    };
    let shape = Film::new(0, 0, channel_names);
    let displays = targets
        .iter()
        .map(|t| stream_layout(&shape, t, opts).map(|l| PngStream::new(l, width, height)))
        .collect();
    let changes = opts.exposure != [1.0, 1.0] || opts.imager.is_some();
    Streams {
        displays,
        prepare: changes.then(|| opts.clone()),
    }
}

/// The layout `write_target` gives display `t` when it is an 8-bit PNG of film channels.
fn stream_layout(film: &Film, t: &Target, opts: &Options) -> Option<Layout> {
    if t.format != Format::Png {
        return None;
    }
    let quiet = Diagnostics::new();
    let (q, _) = display_quantizers(t, opts, &quiet);
    let mut planes = select_planes(film, t, &quiet);
    if planes.len() > 1 && planes.iter().any(|p| p.depth) {
        planes.retain(|p| !p.depth);
    }
    planes.truncate(4);
    if planes.is_empty() || planes[0].depth || is_float(&q) || q.max > 255.0 {
        return None;
    }
    let src: Option<Vec<usize>> = planes.iter().map(|p| p.src).collect();
    Some(Layout {
        src: src?,
        divide_by: straight_alpha(film, t.format, &planes),
        q,
    })
}

/// Which output planes are written as straight colour, and by which film channel they are
/// divided: a PNG's alpha is unassociated (PNG specification, "Alpha channel"), while the film's
/// colour is premultiplied (RISpec: `Ci` already holds `Oi`), so a PNG whose last sample is
/// alpha (grey + alpha, or RGBA) and comes from the film's `a` gets its `r`, `g`, `b` planes
/// divided by it. Other planes (output variables, whose meaning arbor does not know) and other
/// formats keep the film's values: `None` for each.
///
/// The division comes before the quantizer (and its dither), on the float values: RISpec
/// defines `Quantize` on the values a display receives, and a PNG display receives straight
/// colour. Dividing the quantised bytes instead would multiply their rounding error by 1/alpha
/// at thin edges (one level at alpha 1/8 becomes eight).
fn straight_alpha(film: &Film, format: Format, planes: &[Plane]) -> Vec<Option<usize>> {
    let none = vec![None; planes.len()];
    let alpha = film.channel("a");
    let colour = [film.channel("r"), film.channel("g"), film.channel("b")];
    match planes.split_last() {
        Some((last, rest))
            if format == Format::Png
                && matches!(planes.len(), 2 | 4)
                && alpha.is_some()
                && last.src == alpha =>
        {
            rest.iter()
                .map(|p| p.src.filter(|c| colour.contains(&Some(*c))).and(alpha))
                .chain([None])
                .collect()
        }
        _ => none,
    }
}

/// A band of the film through [`prepare`] (for the streamed displays; the warnings are
/// reported when the frame's displays are written).
pub(super) fn prepared(band: Film, opts: &Options) -> Film {
    let quiet = Diagnostics::new();
    let changed = match prepare(&band, opts, &quiet) {
        Cow::Owned(f) => Some(f),
        Cow::Borrowed(_) => None,
    };
    changed.unwrap_or(band)
}

/// Sets the NaN and infinite values of every channel but depth (`z`, +∞ where nothing was
/// seen, by convention) to 0; returns how many there were. Shaders' NaN and infinite colours
/// are caught when shaded, but finite ones near the float range (a parameter set to 1e38) can
/// overflow the pixel filter's sums, an `Exposure` gain can carry a value past it, and an
/// imager shader writes the film directly: no picture may hold such values.
pub fn clear_non_finite(film: &mut Film) -> usize {
    let (n, z) = (film.channels(), film.channel("z"));
    let mut count = 0;
    for px in film.data.chunks_exact_mut(n.max(1)) {
        for (c, v) in px.iter_mut().enumerate() {
            if cleared(c, *v, z) {
                *v = 0.0;
                count += 1;
            }
        }
    }
    count
}

/// Whether channel `c`'s value `v` is one [`clear_non_finite`] clears (`z`: the depth
/// channel, whose +∞ is meant).
#[inline]
fn cleared(c: usize, v: f32, z: Option<usize>) -> bool {
    !v.is_finite() && Some(c) != z
}

/// Whether [`clear_non_finite`] has anything to do.
fn has_non_finite(film: &Film) -> bool {
    let (n, z) = (film.channels(), film.channel("z"));
    film.data
        .chunks_exact(n.max(1))
        .any(|px| px.iter().enumerate().any(|(c, &v)| cleared(c, v, z)))
}

/// Exposure then the imager, on a copy only when something changes; then NaN or infinite
/// values are written as 0 with a warning (see [`clear_non_finite`]).
fn prepare<'a>(film: &'a Film, opts: &Options, diags: &Diagnostics) -> Cow<'a, Film> {
    let [gain, gamma] = opts.exposure;
    let mut img = Cow::Borrowed(film);
    if gain != 1.0 || gamma != 1.0 {
        if !(gamma > 0.0 && gamma.is_finite()) {
            diags.report(
                Diag::warning(
                    "film::exposure",
                    format!("Exposure gamma {gamma} must be positive; using 1"),
                )
                .help("Exposure gain gamma, e.g. Exposure 1 2.2"),
            );
        }
        apply_exposure(img.to_mut(), gain, gamma);
    }
    if let Some(imager) = &opts.imager {
        if imager.name == "background" {
            apply_background(img.to_mut(), background_color(imager, diags));
        } else {
            diags.report(
                Diag::warning(
                    "film::imager",
                    format!(
                        "Imager shader `{}` was not run (it was not found or did not \
                         compile); the image is written without it",
                        imager.name
                    ),
                )
                .maybe_label(imager.span, "this Imager"),
            );
        }
    }
    if has_non_finite(&img) {
        let count = clear_non_finite(img.to_mut());
        diags.report(
            Diag::warning(
                "film::non_finite",
                format!("{count} pixel value(s) were NaN or infinite; they are written as 0"),
            )
            .help(
                "a shader's colours near the float range (e.g. a parameter of 1e38) overflow \
                 the pixel filter, as can an Exposure gain or an Imager shader's result",
            ),
        );
    }
    img
}

/// The names the standard `background` imager's colour goes by: RISpec 3.2's `background`,
/// BMRT's `bgcolor`, and `color`, the parameter of PRMan's built-in background imager that
/// PRMan-era RIB writes (`Imager "background" "color" [0 0 0]`).
const BACKGROUND_PARAMS: [&str; 3] = ["background", "bgcolor", "color"];

/// The colour the `background` imager composites under the image: the first of its
/// parameter names given (white when none is, as in RISpec). A parameter it does not have
/// is reported, since the image then silently keeps the white default.
fn background_color(imager: &ShaderRef, diags: &Diagnostics) -> [f32; 3] {
    for p in imager.params.iter() {
        if !BACKGROUND_PARAMS.contains(&&*p.name) {
            diags.report(
                Diag::warning(
                    "film::imager",
                    format!(
                        "the `background` imager has no parameter `{}`; ignored",
                        p.name
                    ),
                )
                .maybe_label(p.span, "this parameter")
                .help("its colour is \"background\" (also \"bgcolor\" or \"color\")"),
            );
        }
    }
    let c = BACKGROUND_PARAMS
        .iter()
        .find_map(|n| imager.params.floats(n))
        .filter(|f| !f.is_empty());
    match c {
        Some(f) if f.len() >= 3 => [f[0], f[1], f[2]],
        Some(f) => [f[0]; 3],
        None => [1.0; 3],
    }
}

/// The list of files to write, with the CLI override applied.
fn plan(
    opts: &Options,
    diags: &Diagnostics,
    output_override: Option<&Path>,
    has_matrices: bool,
) -> Result<Vec<Target>, Diag> {
    let mut displays: Vec<Display> = opts.displays.clone();
    if displays.is_empty() {
        let name = output_override
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "ri.png".into());
        if output_override.is_none() {
            diags.report(
                Diag::warning(
                    "film::display",
                    "no Display request: writing the image to `ri.png`",
                )
                .help("add e.g. Display \"image.tif\" \"file\" \"rgba\" before WorldBegin"),
            );
        }
        displays.push(Display {
            name,
            kind: "file".into(),
            mode: "rgba".into(),
            params: ParamList::default(),
            span: Span::default(),
        });
    }
    let mut out = Vec::with_capacity(displays.len());
    for (i, d) in displays.iter().enumerate() {
        if d.name.trim().is_empty() {
            return Err(
                Diag::error("film::display", "Display has an empty file name")
                    .maybe_label(d.span, "this Display")
                    .help("Display \"name.tif\" \"file\" \"rgba\""),
            );
        }
        let mut path = PathBuf::from(&d.name);
        // An exporter's absolute path into a folder of the author's machine
        // (`/home/frigge/…/images/preview.tiff`): the picture goes to the working folder
        // under its own file name rather than being lost.
        let foreign = crate::foreign_path::looks_absolute(&d.name)
            && path.parent().is_some_and(|p| !p.is_dir());
        if foreign {
            if let Some(file) = d.name.rsplit(['/', '\\']).next().filter(|f| !f.is_empty()) {
                path = PathBuf::from(file);
                diags.report(
                    Diag::warning(
                        "film::display",
                        format!(
                            "the folder of `{}` does not exist here; writing `{}`",
                            d.name,
                            path.display()
                        ),
                    )
                    .maybe_label(d.span, "this Display")
                    .help("an absolute path from the machine the scene was written on"),
                );
            }
        }
        let kind = d.kind.to_ascii_lowercase();
        let by_ext = Format::from_extension(&path);
        let format = match kind.as_str() {
            "tiff" => Format::Tiff,
            "file" => match by_ext {
                Some(Format::ZFile) | None => Format::Tiff,
                Some(f) => f,
            },
            "png" => Format::Png,
            "exr" | "openexr" => Format::Exr,
            "zfile" => Format::ZFile,
            "shadow" if has_matrices => Format::ZFile,
            "shadow" => {
                diags.report(
                    Diag::warning(
                        "film::display",
                        format!(
                            "shadow display `{}`: written as an arbor zfile for now; \
                             MakeShadow-style shadow textures come later",
                            d.name
                        ),
                    )
                    .maybe_label(d.span, "this Display"),
                );
                Format::ZFile
            }
            // PRMan's `it`, Aqsis's `piqsl`, and the X11/Windows framebuffer drivers: windows
            // too.
            "framebuffer" | "it" | "piqsl" | "x11" | "windows" => {
                path = path.with_extension("png");
                diags.report(
                    Diag::warning(
                        "film::framebuffer",
                        format!(
                            "framebuffer display `{}`: no window here, writing `{}` instead",
                            d.name,
                            path.display()
                        ),
                    )
                    .maybe_label(d.span, "this Display"),
                );
                Format::Png
            }
            other => {
                let f = match by_ext {
                    Some(f) => f,
                    None => {
                        path = path.with_extension("png");
                        Format::Png
                    }
                };
                diags.report(
                    Diag::warning(
                        "film::display",
                        format!(
                            "unknown display type `{other}`; writing `{}` as {f:?}",
                            path.display()
                        ),
                    )
                    .maybe_label(d.span, "this Display")
                    .help(
                        "display types: file, tiff, png, exr, zfile, shadow, framebuffer (it, piqsl, x11)",
                    ),
                );
                f
            }
        };
        let mut t = Target {
            path,
            format,
            mode: d.mode.clone(),
            params: d.params.clone(),
            kind,
            span: d.span,
        };
        if i == 0 {
            if let Some(o) = output_override {
                t.format = Format::from_extension(o).ok_or_else(|| {
                    Diag::error(
                        "film::output",
                        format!("cannot tell the image format of `{}`", o.display()),
                    )
                    .help("use an extension: .png, .tif, .tiff, .exr or .z")
                })?;
                t.path = o.to_path_buf();
            }
        }
        out.push(t);
    }
    Ok(out)
}

/// One output channel: where it comes from in the film and what it is called.
#[derive(Clone, Debug, PartialEq)]
struct Plane {
    /// Film channel; `None` writes zeros (an output variable the film lacks).
    src: Option<usize>,
    name: String,
    depth: bool,
}

/// The planes a display mode selects from the film.
fn select_planes(film: &Film, t: &Target, diags: &Diagnostics) -> Vec<Plane> {
    // A mode may carry a type declaration ("varying normal N"): keep its last word.
    let mode = t.mode.split_whitespace().last().unwrap_or("").to_string();
    let std = |name: &str, exr: &str| Plane {
        src: film.channel(name),
        name: exr.to_string(),
        depth: name == "z",
    };
    let standard = |rgb: bool, a: bool, z: bool| {
        let mut v = Vec::new();
        if rgb {
            v.extend([std("r", "R"), std("g", "G"), std("b", "B")]);
        }
        if a {
            v.push(std("a", "A"));
        }
        if z {
            v.push(std("z", "Z"));
        }
        v
    };
    match mode.as_str() {
        "rgb" | "Ci" => return standard(true, false, false),
        "rgba" => return standard(true, true, false),
        "a" => return standard(false, true, false),
        "z" => return standard(false, false, true),
        "rgbz" => return standard(true, false, true),
        "rgbaz" => return standard(true, true, true),
        "" => {
            diags.report(
                Diag::warning("film::display", "Display has an empty mode; using \"rgba\"")
                    .maybe_label(t.span, "this Display"),
            );
            return standard(true, true, false);
        }
        _ => {}
    }
    if mode.chars().all(|c| "rgbaz".contains(c)) {
        let rgb = mode.contains(['r', 'g', 'b']);
        let (a, z) = (mode.contains('a'), mode.contains('z'));
        let closest = format!(
            "{}{}{}",
            if rgb { "rgb" } else { "" },
            if a { "a" } else { "" },
            if z { "z" } else { "" }
        );
        diags.report(
            Diag::warning(
                "film::display",
                format!("display mode \"{mode}\" is not supported; using \"{closest}\""),
            )
            .maybe_label(t.span, "this Display")
            .help("modes: rgb, rgba, a, z, rgbz, rgbaz, or output variable names"),
        );
        return standard(rgb, a, z);
    }
    let mut planes = Vec::new();
    for name in mode.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let idx = film.aov_channels(name);
        if idx.is_empty() {
            diags.report(
                Diag::warning(
                    "film::display",
                    format!(
                        "output variable `{name}` was not rendered; its channel is written as 0"
                    ),
                )
                .maybe_label(t.span, "this Display")
                .help("the surface shader must declare it as an `output varying` parameter"),
            );
            planes.push(Plane {
                src: None,
                name: name.to_string(),
                depth: false,
            });
        } else {
            for i in idx {
                planes.push(Plane {
                    src: Some(i),
                    name: film.channel_names[i].clone(),
                    depth: film.channel_names[i] == "z",
                });
            }
        }
    }
    planes
}

/// Per-display overrides of Quantize (`"quantize" [zero one min max]`, `"dither" [d]`) and
/// warnings for parameters nobody reads.
fn display_quantizers(t: &Target, opts: &Options, diags: &Diagnostics) -> (Quantize, Quantize) {
    let (mut qc, mut qz) = (opts.quantize_rgba, opts.quantize_z);
    if let Some((_, q)) = opts.quantize_named.iter().find(|(n, _)| *n == t.mode) {
        qc = *q;
    }
    for p in t.params.iter() {
        match &*p.name {
            "quantize" => {
                let f = p.data.floats();
                if f.len() == 4 {
                    qc = Quantize {
                        zero: f[0],
                        one: f[1],
                        min: f[2],
                        max: f[3],
                        ..qc
                    };
                    qz = Quantize {
                        zero: f[0],
                        one: f[1],
                        min: f[2],
                        max: f[3],
                        ..qz
                    };
                } else {
                    diags.report(
                        Diag::warning(
                            "film::display",
                            "display \"quantize\" takes 4 numbers [zero one min max]; ignored",
                        )
                        .maybe_label(p.span, "here"),
                    );
                }
            }
            "dither" => {
                if let Some(&d) = p.data.floats().first() {
                    qc.dither = d;
                    qz.dither = d;
                }
            }
            "float" | "half" | "type" | "pixeltype" | "exrpixeltype" | "compression"
            | "exrcompression"
                if t.format == Format::Exr => {}
            // The TIFF drivers' file compression (PRMan, Aqsis: "lzw", "packbits", "deflate"…)
            // changes the file's size, not the picture.
            "compression" => diags.report(
                Diag::note(
                    "film::display",
                    format!(
                        "display parameter `compression` of the `{}` display: arbor writes \
                         {:?} files its own way; ignored",
                        t.kind, t.format
                    ),
                )
                .maybe_label(p.span, "here"),
            ),
            other => diags.report(
                Diag::warning(
                    "film::display",
                    format!(
                        "display parameter `{other}` is not used by the `{}` display; ignored",
                        t.kind
                    ),
                )
                .maybe_label(p.span, "here"),
            ),
        }
    }
    (qc, qz)
}

fn write_target(
    film: &Film,
    t: &Target,
    opts: &Options,
    diags: &Diagnostics,
    matrices: Option<([f32; 16], [f32; 16])>,
    stream: Option<PngStream>,
) -> Result<(), Diag> {
    let (qc, qz) = display_quantizers(t, opts, diags);
    let warn = |msg: String| {
        diags.report(Diag::warning("film::display", msg).maybe_label(t.span, "this Display"));
    };
    let (w, h) = (film.width, film.height);
    if t.format == Format::ZFile {
        let mode = t.mode.trim();
        if mode != "z" {
            warn(format!(
                "{} display `{}` writes depth only; mode \"{mode}\" ignored",
                t.kind,
                t.path.display()
            ));
        }
        let z = ZFile::from_film(film, matrices);
        if t.kind.eq_ignore_ascii_case("shadow") {
            if let Some(m) = matrices {
                let im = crate::texture::image_in::Image {
                    width: z.width as usize,
                    height: z.height as usize,
                    nchan: 1,
                    data: z.depths,
                };
                use crate::texture::{format, mipmap::Wrap};
                return format::write(
                    &t.path,
                    format::Kind::Shadow,
                    &[vec![im]],
                    Wrap::Black,
                    Wrap::Black,
                    Some(m),
                )
                .map_err(|e| {
                    Diag::error("film::display", format!("cannot write shadow map: {e}"))
                        .maybe_label(t.span, "this Display")
                });
            }
        }
        let bytes = z.to_bytes();
        return write_atomically(&t.path, |f| f.write_all(&bytes).map_err(|e| e.to_string()))
            .map_err(|d| d.maybe_label(t.span, "this Display"));
    }

    let mut planes = select_planes(film, t, diags);
    if t.format == Format::Exr {
        return write_exr(film, t, &planes, diags);
    }

    // PNG and TIFF: no depth next to colour, at most 4 channels.
    let fmt_name = if t.format == Format::Png {
        "png"
    } else {
        "tiff"
    };
    if planes.len() > 1 && planes.iter().any(|p| p.depth) {
        planes.retain(|p| !p.depth);
        warn(format!(
            "{fmt_name} cannot hold depth next to colour; z dropped from `{}` (use exr, or a \
             separate \"z\" display)",
            t.path.display()
        ));
    }
    if planes.len() > 4 {
        planes.truncate(4);
        warn(format!(
            "{fmt_name} holds at most 4 channels; `{}` keeps the first 4",
            t.path.display()
        ));
    }
    let depth_only = planes.len() == 1 && planes[0].depth;
    let mut q = if depth_only { qz } else { qc };
    // Float depth alone in a TIFF (`Display "z.tif" "file" "z"`, Essential RenderMan's
    // shadow chapter): a 32-bit float TIFF carrying the camera matrices in PRMan's tags, so
    // `MakeShadow` can read it like a zfile.
    if depth_only && t.format == Format::Tiff && is_float(&q) {
        let z = ZFile::from_film(film, matrices);
        return write_atomically(&t.path, |f| {
            super::tiff::write_depth(f, &z.depths, w, h, z.matrices)
        })
        .map_err(|d| d.maybe_label(t.span, "this Display"));
    }
    // Depth with a float quantizer in an integer-only image: normalise the finite range.
    let mut znorm = None;
    let float_out = is_float(&q);
    if float_out && (t.format == Format::Png || (depth_only && t.format == Format::Tiff)) {
        if depth_only {
            let zc = planes[0].src;
            let (lo, hi) = finite_range(film, zc);
            znorm = Some((lo, hi));
            warn(format!(
                "{fmt_name} cannot hold float depth in one channel; `{}` holds depth {lo}..{hi} \
                 scaled to 0..65535 (use zfile, exr, or Quantize \"z\")",
                t.path.display()
            ));
        } else {
            warn(format!(
                "png cannot hold floats (Quantize one = 0); `{}` written with 16 bits",
                t.path.display()
            ));
        }
        q = Quantize {
            zero: 0.0,
            one: 65535.0,
            min: 0.0,
            max: 65535.0,
            dither: if depth_only { 0.0 } else { q.dither },
        };
    }
    let float_out = is_float(&q);
    let nout = match planes.len() {
        2 if t.format == Format::Tiff => {
            warn(format!(
                "tiff has no 2-channel colour type; `{}` padded to 3 channels",
                t.path.display()
            ));
            3
        }
        n => n,
    };
    if nout == 0 {
        return Err(Diag::error(
            "film::display",
            format!("display `{}` selects no channels", t.path.display()),
        )
        .maybe_label(t.span, "this Display"));
    }
    // Straight colour in a PNG with alpha (a `None` for every plane of other files).
    let divide_by = straight_alpha(film, t.format, &planes[..nout.min(planes.len())]);
    let sample = |x: usize, y: usize, k: usize| -> f32 {
        let Some(p) = planes.get(k) else { return 0.0 };
        let Some(c) = p.src else { return 0.0 };
        let px = &film.data[(y * w + x) * film.channels()..];
        let v = match divide_by.get(k).copied().flatten() {
            Some(a) => unpremultiply(px[c], px[a]),
            None => px[c],
        };
        match znorm {
            Some((lo, hi)) if p.depth => {
                if v.is_finite() && hi > lo {
                    (v - lo) / (hi - lo)
                } else if v.is_finite() {
                    0.0
                } else {
                    1.0
                }
            }
            _ => v,
        }
    };

    use image::ExtendedColorType as E;
    let path = &t.path;
    let result = if float_out {
        // TIFF float: RGB/RGBA only; a single channel is replicated to RGB.
        let (ct, n, rep) = match nout {
            1 => {
                warn(format!(
                    "the tiff encoder has no 1-channel float type; `{}` repeats the channel \
                     as RGB",
                    path.display()
                ));
                (E::Rgb32F, 3, true)
            }
            3 => (E::Rgb32F, 3, false),
            _ => (E::Rgba32F, 4, false),
        };
        let mut bytes = Vec::with_capacity(w * h * n * 4);
        for y in 0..h {
            for x in 0..w {
                for k in 0..n {
                    let v = sample(x, y, if rep { 0 } else { k });
                    bytes.extend_from_slice(&v.to_ne_bytes());
                }
            }
        }
        encode(path, t.format, &bytes, w, h, ct)
    } else {
        let sixteen = q.max > 255.0;
        let ct = match (nout, sixteen) {
            (1, false) => E::L8,
            (2, false) => E::La8,
            (3, false) => E::Rgb8,
            (_, false) => E::Rgba8,
            (1, true) => E::L16,
            (2, true) => E::La16,
            (3, true) => E::Rgb16,
            (_, true) => E::Rgba16,
        };
        // Encoded while the frame rendered (the same bytes as below).
        let streamed = stream
            .filter(|s| {
                let plain: Option<Vec<usize>> = planes.iter().take(nout).map(|p| p.src).collect();
                !sixteen
                    && znorm.is_none()
                    && s.size() == (w, h)
                    && plain.as_ref() == Some(&s.layout.src)
                    && s.layout.divide_by == divide_by
                    && s.layout.q == q
            })
            .and_then(PngStream::finish);
        if let Some(zlib) = streamed {
            return write_png_zlib(path, w, h, nout, &zlib)
                .map_err(|d| d.maybe_label(t.span, "this Display"));
        }
        // Rows in parallel: this runs after the frame, on the critical path.
        let bpv = if sixteen { 2 } else { 1 };
        let mut bytes = vec![0u8; w * h * nout * bpv];
        if w > 0 {
            use rayon::prelude::*;
            bytes
                .par_chunks_mut(w * nout * bpv)
                .enumerate()
                .for_each(|(y, row)| {
                    // Plain colour planes (the usual case): read the pixel's floats directly.
                    let plain: Option<Vec<usize>> = (znorm.is_none())
                        .then(|| planes.iter().take(nout).map(|p| p.src).collect())
                        .flatten()
                        .filter(|v: &Vec<usize>| v.len() == nout);
                    if let (Some(src), false) = (&plain, sixteen) {
                        // A channel at a time through the vectorised row quantiser, the
                        // values read as the streamed path reads them.
                        let layout = Layout {
                            src: src.clone(),
                            divide_by: divide_by.clone(),
                            q,
                        };
                        let (mut vals, mut q8) = (vec![0f32; w], vec![0u8; w]);
                        for k in 0..nout {
                            layout.row_values(film, y, k, &mut vals);
                            quantize_row_u8(&vals, &q, y as u32, k as u32, &mut q8);
                            for (x, &b) in q8.iter().enumerate() {
                                row[x * nout + k] = b;
                            }
                        }
                        return;
                    }
                    for x in 0..w {
                        for k in 0..nout {
                            let v = sample(x, y, k);
                            let v = quantize(v, &q, x as u32, y as u32, k as u32);
                            let at = (x * nout + k) * bpv;
                            if sixteen {
                                row[at..at + 2]
                                    .copy_from_slice(&(v.clamp(0.0, 65535.0) as u16).to_ne_bytes());
                            } else {
                                row[at] = v.clamp(0.0, 255.0) as u8;
                            }
                        }
                    }
                });
        }
        encode(path, t.format, &bytes, w, h, ct)
    };
    result.map_err(|d| d.maybe_label(t.span, "this Display"))
}

fn finite_range(film: &Film, zc: Option<usize>) -> (f32, f32) {
    let Some(zc) = zc else { return (0.0, 0.0) };
    let n = film.channels();
    let mut lo = f32::INFINITY;
    let mut hi = f32::NEG_INFINITY;
    for px in film.data.chunks_exact(n) {
        let z = px[zc];
        if z.is_finite() {
            lo = lo.min(z);
            hi = hi.max(z);
        }
    }
    if lo > hi {
        (0.0, 0.0)
    } else {
        (lo, hi)
    }
}

fn encode(
    path: &Path,
    format: Format,
    bytes: &[u8],
    w: usize,
    h: usize,
    ct: image::ExtendedColorType,
) -> Result<(), Diag> {
    use image::ExtendedColorType as E;
    write_atomically(path, |f| match format {
        Format::Png => image::codecs::png::PngEncoder::new(f)
            .write_image(bytes, w as u32, h as u32, ct)
            .map_err(|e| e.to_string()),
        _ => {
            // The colour types `write_target` picks for TIFF (never two channels).
            let (n, sample) = match ct {
                E::L8 => (1, super::tiff::Sample::U8),
                E::La8 => (2, super::tiff::Sample::U8),
                E::Rgb8 => (3, super::tiff::Sample::U8),
                E::Rgba8 => (4, super::tiff::Sample::U8),
                E::L16 => (1, super::tiff::Sample::U16),
                E::La16 => (2, super::tiff::Sample::U16),
                E::Rgb16 => (3, super::tiff::Sample::U16),
                E::Rgba16 => (4, super::tiff::Sample::U16),
                E::Rgb32F => (3, super::tiff::Sample::F32),
                E::Rgba32F => (4, super::tiff::Sample::F32),
                other => return Err(format!("no tiff layout for {other:?}")),
            };
            super::tiff::write(f, bytes, w, h, n, sample)
        }
    })
}

/// An 8-bit PNG of `channels` samples a pixel from its zlib stream (see [`super::stream`]):
/// the header the `png` crate writes, the stream as one IDAT chunk, the end chunk.
fn write_png_zlib(
    path: &Path,
    w: usize,
    h: usize,
    channels: usize,
    zlib: &[u8],
) -> Result<(), Diag> {
    use png::ColorType as C;
    let color = match channels {
        1 => C::Grayscale,
        2 => C::GrayscaleAlpha,
        3 => C::Rgb,
        _ => C::Rgba,
    };
    write_atomically(path, |f| {
        let mut e = png::Encoder::new(f, w as u32, h as u32);
        e.set_color(color);
        e.set_depth(png::BitDepth::Eight);
        e.set_compression(png::Compression::Fast);
        e.set_filter(png::Filter::Adaptive);
        let write = || -> Result<(), png::EncodingError> {
            let mut wr = e.write_header()?;
            for chunk in zlib.chunks((u32::MAX >> 1) as usize) {
                wr.write_chunk(png::chunk::IDAT, chunk)?;
            }
            wr.finish()
        };
        write().map_err(|e| e.to_string())
    })
}

fn write_exr(film: &Film, t: &Target, planes: &[Plane], diags: &Diagnostics) -> Result<(), Diag> {
    use exr::prelude::*;
    let mut float = false;
    let mut compression = Compression::ZIP16;
    for p in t.params.iter() {
        match &*p.name {
            "float" => float = true,
            "half" => float = false,
            "type" | "pixeltype" | "exrpixeltype" => {
                match p.data.strings().first().map(|s| s.as_str()) {
                    Some("float") => float = true,
                    Some("half") => float = false,
                    other => diags.report(
                        Diag::warning(
                            "film::display",
                            format!(
                                "exr pixel type {other:?} is not \"half\" or \"float\"; using half"
                            ),
                        )
                        .maybe_label(p.span, "here"),
                    ),
                }
            }
            "compression" | "exrcompression" => {
                compression = match p
                    .data
                    .strings()
                    .first()
                    .map(|s| s.to_ascii_lowercase())
                    .as_deref()
                {
                    Some("none") => Compression::Uncompressed,
                    Some("rle") => Compression::RLE,
                    Some("zips") => Compression::ZIP1,
                    Some("zip") => Compression::ZIP16,
                    Some("piz") => Compression::PIZ,
                    Some("pxr24") => Compression::PXR24,
                    other => {
                        diags.report(
                            Diag::warning(
                                "film::display",
                                format!("exr compression {other:?} is not supported; using zip"),
                            )
                            .maybe_label(p.span, "here")
                            .help("compression: none, rle, zips, zip, piz, pxr24"),
                        );
                        Compression::ZIP16
                    }
                };
            }
            _ => {}
        }
    }
    let (w, h) = (film.width, film.height);
    let n = film.channels();
    let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    let mut seen = std::collections::HashSet::new();
    for p in planes {
        if !seen.insert(p.name.clone()) {
            continue;
        }
        let vals: Vec<f32> = match p.src {
            Some(c) => (0..w * h).map(|i| film.data[i * n + c]).collect(),
            None => vec![0.0; w * h],
        };
        // Depth keeps 32 bits: half cannot resolve camera-space distances.
        let samples = if float || p.depth {
            FlatSamples::F32(vals)
        } else {
            FlatSamples::F16(vals.into_iter().map(f16::from_f32).collect())
        };
        channels.push(AnyChannel::new(p.name.as_str(), samples));
    }
    if channels.is_empty() {
        return Err(Diag::error(
            "film::display",
            format!("display `{}` selects no channels", t.path.display()),
        )
        .maybe_label(t.span, "this Display"));
    }
    let encoding = Encoding {
        compression,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        encoding,
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);
    write_atomically(&t.path, |f| {
        image
            .write()
            .non_parallel()
            .to_buffered(f)
            .map_err(|e| e.to_string())
    })
    .map_err(|d| d.maybe_label(t.span, "this Display"))
}

/// Labels a diagnostic only with a real span (the default display has none).
trait MaybeLabel {
    fn maybe_label(self, span: Span, text: &str) -> Self;
}

impl MaybeLabel for Diag {
    fn maybe_label(self, span: Span, text: &str) -> Diag {
        if span == Span::default() {
            self
        } else {
            self.label(span, text)
        }
    }
}

static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `path` through a temporary file in the same directory, renamed into place only when
/// `write` succeeds; on any failure the temporary file is removed and `path` is untouched.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), String>,
) -> Result<(), Diag> {
    let fail = |what: String| {
        Diag::error(
            "film::write",
            format!("cannot write `{}`: {what}", path.display()),
        )
        .help("check that the folder exists and is writable")
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| fail("the path names no file".into()))?
        .to_string_lossy()
        .into_owned();
    let tmp = dir.join(format!(
        ".{file_name}.{}.{}.tmp",
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| fail(e.to_string()))?;
    let mut bw = BufWriter::new(file);
    let result = match write(&mut bw) {
        Ok(()) => bw
            .into_inner()
            .map_err(|e| e.to_string())
            .and_then(|f| f.sync_all().map_err(|e| e.to_string())),
        Err(e) => {
            drop(bw); // close before removing
            Err(e)
        }
    };
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e));
    }
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e.to_string()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Param, ParamData, ShaderRef};

    /// A fresh empty folder under the system temp dir.
    fn tmpdir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("arbor-film-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// 4×3 film: r = x/4, g = y/3, b = 0.5, a = 0.75, z = 1 + x + 10y, N = (x, y, −1).
    fn film() -> Film {
        let names = Film::standard_channels(&["N.x".into(), "N.y".into(), "N.z".into()]);
        let mut f = Film::new(4, 3, names);
        for y in 0..3 {
            for x in 0..4 {
                let p = f.pixel_mut(x, y);
                p.copy_from_slice(&[
                    x as f32 / 4.0,
                    y as f32 / 3.0,
                    0.5,
                    0.75,
                    1.0 + x as f32 + 10.0 * y as f32,
                    x as f32,
                    y as f32,
                    -1.0,
                ]);
            }
        }
        f
    }

    fn display(name: &Path, kind: &str, mode: &str) -> Display {
        Display {
            name: name.display().to_string(),
            kind: kind.into(),
            mode: mode.into(),
            params: ParamList::default(),
            span: Span::default(),
        }
    }

    fn opts(displays: Vec<Display>) -> Options {
        let mut o = Options {
            displays,
            ..Options::default()
        };
        o.quantize_rgba.dither = 0.0;
        o
    }

    fn string_param(name: &str, v: &str) -> Param {
        Param {
            name: name.to_string().into(),
            decl: crate::scene::Decl {
                class: crate::scene::Class::Uniform,
                ty: crate::scene::ParamType::String,
                array_len: 1,
            },
            data: ParamData::Strings(vec![v.into()]),
            span: Span::default(),
        }
    }

    fn q8(v: f32) -> u8 {
        (v * 255.0).round() as u8
    }

    /// A `w` × `h` film of the standard channels: a smooth picture, or noise.
    fn picture(w: usize, h: usize, noise: bool) -> Film {
        let mut f = Film::new(w, h, Film::standard_channels(&[]));
        let mut seed = 12345u32;
        for y in 0..h {
            for x in 0..w {
                let mut v = [0f32; 5];
                for (k, v) in v.iter_mut().enumerate() {
                    seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
                    *v = if noise {
                        (seed >> 8) as f32 / (1u32 << 24) as f32
                    } else {
                        ((x * (k + 1) + 3 * y) % 97) as f32 / 96.0 * 1.1 - 0.05
                    };
                }
                f.pixel_mut(x, y).copy_from_slice(&v);
            }
        }
        f
    }

    /// The display's file written from streams fed `f` in bands, and from the film alone.
    fn streamed_and_whole(f: &Film, o: &Options, dir: &Path) -> (Vec<u8>, Vec<u8>) {
        let d = Diagnostics::new();
        let mut streams = plan_streams(o, None, f.channel_names.clone(), f.width, f.height);
        assert!(streams.any(), "{:?} streams", o.displays[0].mode);
        use super::super::stream::RowSink;
        let mut y = 0;
        for band in [0, 1, 5, 2, 7, 100] {
            let y1 = (y + band).min(f.height);
            streams.rows(f, y, y1);
            y = y1;
        }
        let out = dir.join("out.png");
        write_displays_streamed(f, o, &d, Some(&out), None, streams).unwrap();
        let a = std::fs::read(&out).unwrap();
        write_displays(f, o, &d, Some(&out)).unwrap();
        (a, std::fs::read(&out).unwrap())
    }

    #[test]
    fn streamed_png_is_byte_identical_to_the_whole_image_path() {
        let dir = tmpdir("stream");
        let smooth = picture(37, 23, false);
        // `r,a`: grey + alpha, straight; the picture's alpha runs from −0.05 to 1.05.
        for mode in ["rgba", "rgb", "a", "ra", "r,a"] {
            for dither in [0.0, 0.5] {
                let mut o = opts(vec![display(&dir.join("x.png"), "png", mode)]);
                o.quantize_rgba.dither = dither;
                let (a, b) = streamed_and_whole(&smooth, &o, &dir);
                assert!(a == b, "mode {mode}, dither {dither}");
                // The stream itself was used (not the fallback from the film).
                let mut s = plan_streams(&o, None, smooth.channel_names.clone(), 37, 23);
                use super::super::stream::RowSink;
                s.rows(&smooth, 0, 23);
                let ps = s.displays.pop().flatten().unwrap();
                assert!(ps.finish().is_some(), "mode {mode}");
            }
        }
        // Exposure and the background imager are applied band by band.
        let mut o = opts(vec![display(&dir.join("x.png"), "png", "rgba")]);
        o.exposure = [1.5, 2.2];
        o.imager = Some(ShaderRef {
            name: "background".into(),
            params: ParamList::default(),
            span: Span::default(),
            world_from_shader: glam::Mat4::IDENTITY,
        });
        let (a, b) = streamed_and_whole(&smooth, &o, &dir);
        assert!(a == b, "exposure and background");
        // Noise does not compress: the png crate stores it, and so does the fallback.
        let noise = picture(64, 9, true);
        let o = opts(vec![display(&dir.join("x.png"), "png", "rgb")]);
        let (a, b) = streamed_and_whole(&noise, &o, &dir);
        assert!(a == b, "noise");
        let mut s = plan_streams(&o, None, noise.channel_names.clone(), 64, 9);
        use super::super::stream::RowSink;
        s.rows(&noise, 0, 9);
        assert!(
            s.displays.pop().flatten().unwrap().finish().is_none(),
            "stored"
        );
        let img = image::open(dir.join("out.png")).unwrap().to_rgb8();
        assert_eq!(img.get_pixel(3, 2)[1], q8(noise.pixel(3, 2)[1]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn only_8_bit_png_of_whole_films_stream() {
        let names = Film::standard_channels(&[]);
        let plan = |o: &Options| plan_streams(o, None, names.clone(), 8, 8).any();
        let p = PathBuf::from("x.png");
        assert!(plan(&opts(vec![display(&p, "png", "rgb")])));
        assert!(!plan(&opts(vec![display(&p, "png", "z")])));
        assert!(!plan(&opts(vec![display(
            &PathBuf::from("x.tif"),
            "tiff",
            "rgb"
        )])));
        assert!(!plan(&opts(vec![display(
            &PathBuf::from("x.exr"),
            "exr",
            "rgb"
        )])));
        let mut o = opts(vec![display(&p, "png", "rgb")]);
        o.quantize_rgba.max = 65535.0;
        o.quantize_rgba.one = 65535.0;
        assert!(!plan(&o), "16 bits");
        let mut o = opts(vec![display(&p, "png", "rgb")]);
        o.imager = Some(ShaderRef {
            name: "sepia".into(),
            params: ParamList::default(),
            span: Span::default(),
            world_from_shader: glam::Mat4::IDENTITY,
        });
        assert!(
            !plan(&o),
            "an imager shader changes the film after the render"
        );
        // A stream missing rows is not used.
        let f = picture(8, 8, false);
        let mut s = plan_streams(&opts(vec![display(&p, "png", "rgb")]), None, names, 8, 8);
        use super::super::stream::RowSink;
        s.rows(&f, 0, 7);
        assert!(s.displays.pop().flatten().unwrap().finish().is_none());
    }

    #[test]
    fn png_8_and_16_bit_round_trip() {
        let dir = tmpdir("png");
        let f = film();
        let p8 = dir.join("a.png");
        let d = Diagnostics::new();
        let out = write_displays(&f, &opts(vec![display(&p8, "png", "rgba")]), &d, None).unwrap();
        assert_eq!(out, vec![p8.clone()]);
        let img = image::open(&p8).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba8);
        let img = img.to_rgba8();
        // PNG alpha is straight: the film's premultiplied colour divided by its alpha 0.75.
        for y in 0..3u32 {
            for x in 0..4u32 {
                let px = img.get_pixel(x, y).0;
                assert_eq!(
                    px,
                    [
                        q8(x as f32 / 4.0 / 0.75),
                        q8(y as f32 / 3.0 / 0.75),
                        q8(0.5 / 0.75),
                        191
                    ],
                    "at {x},{y}"
                );
            }
        }
        assert_eq!(img.get_pixel(3, 2).0, [255, 227, 170, 191]);
        // rgb keeps the film's (premultiplied) values: no alpha to be straight against.
        let prgb = dir.join("c.png");
        write_displays(&f, &opts(vec![display(&prgb, "png", "rgb")]), &d, None).unwrap();
        let img = image::open(&prgb).unwrap().to_rgb8();
        assert_eq!(img.get_pixel(3, 2).0, [191, 170, 128]);
        // 16 bits with alpha: straight too.
        let sixteen = Quantize {
            zero: 0.0,
            one: 65535.0,
            min: 0.0,
            max: 65535.0,
            dither: 0.0,
        };
        let p16a = dir.join("d.png");
        let mut o = opts(vec![display(&p16a, "png", "rgba")]);
        o.quantize_rgba = sixteen;
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&p16a).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba16);
        let q16 = |v: f32| (65535.0 * v).round() as u16;
        let px = img.to_rgba16().get_pixel(1, 2).0;
        assert_eq!(
            px,
            [
                q16(0.25 / 0.75),
                q16(2.0 / 3.0 / 0.75),
                q16(0.5 / 0.75),
                49151
            ]
        );
        // 16 bits, rgb
        let p16 = dir.join("b.png");
        let mut o = opts(vec![display(&p16, "png", "rgb")]);
        o.quantize_rgba = sixteen;
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&p16).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgb16);
        let px = img.to_rgb16().get_pixel(3, 2).0;
        assert_eq!(px, [49151, 43690, 32768]);
        assert!(d.snapshot().is_empty(), "{:?}", d.snapshot());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn only_colour_planes_of_a_png_with_alpha_are_straight() {
        let names = Film::standard_channels(&["N.x".into(), "N.y".into(), "N.z".into()]);
        let f = Film::new(1, 1, names);
        let d = Diagnostics::new();
        let divide = |format: Format, mode: &str| {
            let t = Target {
                path: "x".into(),
                format,
                mode: mode.into(),
                params: ParamList::default(),
                kind: "png".into(),
                span: Span::default(),
            };
            straight_alpha(&f, format, &select_planes(&f, &t, &d))
        };
        let a = f.channel("a");
        assert_eq!(divide(Format::Png, "rgba"), [a, a, a, None]);
        assert_eq!(divide(Format::Png, "g,a"), [a, None]);
        assert_eq!(divide(Format::Png, "rgb"), [None; 3]);
        assert_eq!(divide(Format::Png, "a"), [None]);
        assert_eq!(
            divide(Format::Png, "N,a"),
            [None; 4],
            "output variables as they are"
        );
        assert_eq!(
            divide(Format::Png, "a,r"),
            [None; 2],
            "the last sample is not alpha"
        );
        assert_eq!(
            divide(Format::Tiff, "rgba"),
            [None; 4],
            "TIFF says premultiplied"
        );
        assert!(d.snapshot().is_empty(), "{:?}", d.snapshot());
    }

    #[test]
    fn half_covered_white_is_white_at_half_alpha_in_png() {
        // Premultiplied half-covered white (0.5, 0.5, 0.5, 0.5) and an uncovered pixel whose
        // colour is filter ringing: straight white at alpha 128, and nothing.
        let mut f = Film::new(2, 1, Film::standard_channels(&[]));
        f.pixel_mut(0, 0)[..4].copy_from_slice(&[0.5, 0.5, 0.5, 0.5]);
        f.pixel_mut(1, 0)[..4].copy_from_slice(&[0.01, 0.0, 0.02, 0.0]);
        let dir = tmpdir("halfwhite");
        let p = dir.join("w.png");
        let d = Diagnostics::new();
        let o = opts(vec![display(&p, "png", "rgba")]);
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&p).unwrap().to_rgba8();
        assert_eq!(img.get_pixel(0, 0).0, [255, 255, 255, 128]);
        assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0, 0]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn tiff_8_16_and_float_round_trip() {
        let dir = tmpdir("tiff");
        let f = film();
        let d = Diagnostics::new();
        let (t8, t16, tf) = (dir.join("a.tif"), dir.join("b.tiff"), dir.join("c.tif"));
        write_displays(&f, &opts(vec![display(&t8, "file", "rgb")]), &d, None).unwrap();
        let img = image::open(&t8).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgb8);
        assert_eq!(img.to_rgb8().get_pixel(2, 1).0, [128, 85, 128]);

        let mut o = opts(vec![display(&t16, "tiff", "rgba")]);
        o.quantize_rgba.one = 65535.0;
        o.quantize_rgba.max = 65535.0;
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&t16).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba16);
        assert_eq!(img.to_rgba16().get_pixel(1, 0).0, [16384, 0, 32768, 49151]);

        let mut o = opts(vec![display(&tf, "tiff", "rgba")]);
        o.quantize_rgba = Quantize {
            zero: 0.0,
            one: 0.0,
            min: 0.0,
            max: 0.0,
            dither: 0.0,
        };
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&tf).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba32F);
        let img = img.to_rgba32f();
        for y in 0..3 {
            for x in 0..4 {
                assert_eq!(img.get_pixel(x, y).0, f.pixel(x as usize, y as usize)[..4]);
            }
        }
        assert!(d.snapshot().is_empty(), "{:?}", d.snapshot());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn exr_half_float_and_output_variables() {
        use exr::prelude::*;
        let dir = tmpdir("exr");
        let f = film();
        let d = Diagnostics::new();
        let (e1, e2, e3) = (dir.join("a.exr"), dir.join("n.exr"), dir.join("z.exr"));
        let mut nd = display(&e2, "exr", "N");
        nd.params.0.push(string_param("type", "float"));
        let o = opts(vec![
            display(&e1, "exr", "rgba"),
            nd,
            display(&e3, "openexr", "rgbaz"),
        ]);
        let out = write_displays(&f, &o, &d, None).unwrap();
        assert_eq!(out.len(), 3);
        assert!(d.snapshot().is_empty(), "{:?}", d.snapshot());

        let read = |p: &Path| read_all_flat_layers_from_file(p).unwrap();
        let names = |img: &FlatImage| -> Vec<String> {
            img.layer_data[0]
                .channel_data
                .list
                .iter()
                .map(|c| c.name.to_string())
                .collect()
        };
        let img = read(&e1);
        assert_eq!(names(&img), ["A", "B", "G", "R"]);
        let ch = &img.layer_data[0].channel_data.list;
        // pixel (1, 2): index 2*4+1
        match &ch[3].sample_data {
            FlatSamples::F16(v) => assert_eq!(v[9].to_f32(), 0.25),
            other => panic!("R should be half, got {other:?}"),
        }
        match &ch[1].sample_data {
            FlatSamples::F16(v) => assert_eq!(v[9].to_f32(), 0.5),
            other => panic!("{other:?}"),
        }

        let img = read(&e2);
        assert_eq!(names(&img), ["N.x", "N.y", "N.z"]);
        let ch = &img.layer_data[0].channel_data.list;
        match (&ch[0].sample_data, &ch[1].sample_data, &ch[2].sample_data) {
            (FlatSamples::F32(x), FlatSamples::F32(y), FlatSamples::F32(z)) => {
                assert_eq!((x[9], y[9], z[9]), (1.0, 2.0, -1.0));
            }
            other => panic!("N should be float: {other:?}"),
        }

        let img = read(&e3);
        assert_eq!(names(&img), ["A", "B", "G", "R", "Z"]);
        match &img.layer_data[0].channel_data.list[4].sample_data {
            FlatSamples::F32(z) => assert_eq!(z[9], 22.0),
            other => panic!("Z should be float: {other:?}"),
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn zfile_and_shadow_hold_depth() {
        let dir = tmpdir("zfile");
        let f = film();
        let d = Diagnostics::new();
        let (z, s) = (dir.join("d.z"), dir.join("s.shd"));
        let o = opts(vec![display(&z, "zfile", "z"), display(&s, "shadow", "z")]);
        write_displays(&f, &o, &d, None).unwrap();
        for p in [&z, &s] {
            let zf = ZFile::from_bytes(&std::fs::read(p).unwrap()).unwrap();
            assert_eq!((zf.width, zf.height), (4, 3));
            assert_eq!(zf.depths[9], 22.0);
            assert_eq!(zf.matrices, None);
        }
        let w = d.snapshot();
        assert_eq!(w.len(), 1, "the shadow warning: {w:?}");
        assert!(w[0].0.message.contains("MakeShadow"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn override_framebuffer_and_unsupported_modes() {
        let dir = tmpdir("multi");
        let f = film();
        let d = Diagnostics::new();
        let first = dir.join("first.tif");
        let fb = dir.join("window");
        let it = dir.join("render.tif");
        let o = opts(vec![
            display(&first, "file", "rgba"),
            display(&fb, "framebuffer", "rgbaz"),
            display(&it, "it", "rgba"),
        ]);
        let over = dir.join("over.png");
        let out = write_displays(&f, &o, &d, Some(&over)).unwrap();
        // PRMan's `it` is a window as well: a PNG of the display's name.
        assert_eq!(
            out,
            vec![over.clone(), dir.join("window.png"), dir.join("render.png")]
        );
        assert!(!first.exists(), "the override replaces the first display");
        assert_eq!(image::open(&over).unwrap().color(), image::ColorType::Rgba8);
        let img = image::open(dir.join("window.png")).unwrap();
        assert_eq!(img.color(), image::ColorType::Rgba8, "z dropped from png");
        let msgs: Vec<String> = d.snapshot().into_iter().map(|(d, _)| d.message).collect();
        assert!(msgs.iter().any(|m| m.contains("framebuffer")), "{msgs:?}");
        assert!(msgs.iter().any(|m| m.contains("z dropped")), "{msgs:?}");
        // An override without a known extension is an error.
        let bad = write_displays(&f, &o, &d, Some(&dir.join("x.jpg")));
        assert_eq!(bad.unwrap_err().code, "film::output");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn tiff_compression_and_aqsis_piqsl_are_known() {
        let dir = tmpdir("aqsis-displays");
        let f = film();
        let d = Diagnostics::new();
        let tif = dir.join("a.tif");
        let mut file = display(&tif, "file", "rgba");
        file.params = ParamList(vec![string_param("compression", "lzw")]);
        let o = opts(vec![file, display(&dir.join("render"), "piqsl", "rgb")]);
        let out = write_displays(&f, &o, &d, None).unwrap();
        assert_eq!(out, vec![tif.clone(), dir.join("render.png")]);
        assert_eq!(image::open(&tif).unwrap().color(), image::ColorType::Rgba8);
        let warnings: Vec<String> = d
            .snapshot()
            .into_iter()
            .filter(|(w, _)| w.severity != crate::diag::Severity::Note)
            .map(|(w, _)| w.message)
            .collect();
        // Only the window's own warning (no window here); compression is a -v note.
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(warnings[0].contains("framebuffer display"), "{warnings:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn odd_modes_warn_and_pick_the_closest() {
        let f = film();
        let d = Diagnostics::new();
        let t = |mode: &str| Target {
            path: "x.exr".into(),
            format: Format::Exr,
            mode: mode.into(),
            params: ParamList::default(),
            kind: "exr".into(),
            span: Span::default(),
        };
        let names = |mode: &str| -> Vec<String> {
            select_planes(&f, &t(mode), &d)
                .into_iter()
                .map(|p| p.name)
                .collect()
        };
        assert_eq!(names("rgbz"), ["R", "G", "B", "Z"]);
        assert_eq!(names("varying normal N"), ["N.x", "N.y", "N.z"]);
        assert!(d.snapshot().is_empty());
        assert_eq!(names("az"), ["A", "Z"]);
        assert_eq!(names("bgr"), ["R", "G", "B"]);
        assert_eq!(names("P"), ["P"], "missing variable still written (zeros)");
        assert_eq!(d.snapshot().len(), 3);
    }

    #[test]
    fn no_display_defaults_to_ri_png() {
        let d = Diagnostics::new();
        let t = plan(&Options::default(), &d, None, false).unwrap();
        assert_eq!(t.len(), 1);
        assert_eq!(t[0].path, PathBuf::from("ri.png"));
        assert_eq!(t[0].format, Format::Png);
        assert_eq!(t[0].mode, "rgba");
        assert!(d.snapshot()[0].0.message.contains("no Display"));
    }

    #[test]
    fn exposure_and_background_apply_before_quantize() {
        let dir = tmpdir("expo");
        let f = film();
        let d = Diagnostics::new();
        let p = dir.join("e.tif");
        let mut o = opts(vec![display(&p, "tiff", "rgba")]);
        o.quantize_rgba = Quantize {
            zero: 0.0,
            one: 0.0,
            min: 0.0,
            max: 0.0,
            dither: 0.0,
        };
        o.exposure = [2.0, 2.0];
        o.imager = Some(ShaderRef {
            name: "background".into(),
            params: ParamList(vec![Param {
                name: "background".into(),
                decl: crate::scene::Decl {
                    class: crate::scene::Class::Uniform,
                    ty: crate::scene::ParamType::Color,
                    array_len: 1,
                },
                data: ParamData::Floats(vec![0.0, 0.0, 1.0]),
                span: Span::default(),
            }]),
            span: Span::default(),
            world_from_shader: glam::Mat4::IDENTITY,
        });
        write_displays(&f, &o, &d, None).unwrap();
        let img = image::open(&p).unwrap().to_rgba32f();
        // pixel (2, 0): r = sqrt(0.5·2) = 1, g = 0, b = sqrt(0.5·2) + 0.25·1, a = 1
        let px = img.get_pixel(2, 0).0;
        assert!((px[0] - 1.0).abs() < 1e-6);
        assert_eq!(px[1], 0.0);
        assert!((px[2] - 1.25).abs() < 1e-6);
        assert_eq!(px[3], 1.0);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn failed_writes_leave_no_file() {
        let dir = tmpdir("atomic");
        let target = dir.join("img.png");
        // The encoder fails half-way: neither the target nor a temporary file remains.
        let r = write_atomically(&target, |w| {
            w.write_all(b"partial data").unwrap();
            Err("encoder exploded".into())
        });
        let e = r.unwrap_err();
        assert_eq!(e.code, "film::write");
        assert!(e.message.contains("encoder exploded"));
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "no leftovers");
        // An existing file survives a failed rewrite untouched.
        std::fs::write(&target, b"old").unwrap();
        let _ = write_atomically(&target, |_| Err("no".into()));
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        // A display into a missing folder (named relative to the working folder; an absolute
        // one from another machine falls back to the file name): an error and no file.
        let f = film();
        let d = Diagnostics::new();
        let missing = PathBuf::from("target")
            .join("arbor-missing-display-folder")
            .join("x.tif");
        let r = write_displays(&f, &opts(vec![display(&missing, "tiff", "rgba")]), &d, None);
        assert_eq!(r.unwrap_err().code, "film::write");
        assert!(!missing.exists());
        // Success replaces the file and leaves only it.
        write_atomically(&target, |w| w.write_all(b"new").map_err(|e| e.to_string())).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
