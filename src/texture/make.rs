//! Making texture files: `arbor texture` and the Make* requests.
//!
//! Input: source pictures (see [`super::image_in`]) or a zfile, wrap modes and a filter name.
//! Output: a `.tex` file (see [`super::format`]) with the full mip pyramid per face.
//! Invariants: errors are sentences naming the file; the output appears atomically.

use std::path::{Path, PathBuf};

use crate::diag::{Diag, Diagnostics};
use crate::film::zfile::ZFile;
use crate::scene::{TextureJob, TextureJobKind};

use super::format::{self, Kind};
use super::image_in::{read_image, Image};
use super::mipmap::{build_pyramid, Downsample, Wrap};

/// How to build the pyramid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MakeOptions {
    pub swrap: Wrap,
    pub twrap: Wrap,
    pub filter: Downsample,
}

impl Default for MakeOptions {
    fn default() -> Self {
        MakeOptions {
            swrap: Wrap::Periodic,
            twrap: Wrap::Periodic,
            filter: Downsample::Box,
        }
    }
}

/// Downsampling filter for a RenderMan filter name: box stays box, every smooth filter
/// (gaussian, catmull-rom, sinc, …) uses the [1 3 3 1] kernel. None for unknown names.
pub fn downsample_for(name: &str) -> Option<Downsample> {
    match name.to_ascii_lowercase().as_str() {
        "" | "box" => Some(Downsample::Box),
        "gaussian" | "triangle" | "catmull-rom" | "sinc" | "disk" | "bessel" | "mitchell" => {
            Some(Downsample::Gaussian)
        }
        _ => None,
    }
}

/// A 2-D texture.
pub fn make_texture(input: &Path, output: &Path, o: &MakeOptions) -> Result<(), String> {
    let im = read_image(input)?;
    let levels = build_pyramid(im, o.swrap, o.twrap, o.filter);
    format::write(output, Kind::Texture, &[levels], o.swrap, o.twrap, None)
}

/// A lat-long environment (s periodic, t clamped).
pub fn make_latlong(input: &Path, output: &Path, o: &MakeOptions) -> Result<(), String> {
    let im = read_image(input)?;
    let levels = build_pyramid(im, Wrap::Periodic, Wrap::Clamp, o.filter);
    format::write(
        output,
        Kind::LatLong,
        &[levels],
        Wrap::Periodic,
        Wrap::Clamp,
        None,
    )
}

/// A cube environment from six faces px nx py ny pz nz (equal square sizes).
pub fn make_cube(inputs: &[PathBuf], output: &Path, o: &MakeOptions) -> Result<(), String> {
    if inputs.len() != 6 {
        return Err(format!("a cube map takes 6 faces, {} given", inputs.len()));
    }
    let faces: Vec<Image> = inputs
        .iter()
        .map(|p| read_image(p))
        .collect::<Result<_, _>>()?;
    let (w, h, nc) = (faces[0].width, faces[0].height, faces[0].nchan);
    if let Some(bad) = faces
        .iter()
        .position(|f| (f.width, f.height, f.nchan) != (w, h, nc))
    {
        return Err(format!(
            "cube face `{}` is {}×{}×{}, the first face is {w}×{h}×{nc}",
            inputs[bad].display(),
            faces[bad].width,
            faces[bad].height,
            faces[bad].nchan
        ));
    }
    let pyr: Vec<Vec<Image>> = faces
        .into_iter()
        .map(|f| build_pyramid(f, Wrap::Clamp, Wrap::Clamp, o.filter))
        .collect();
    format::write(output, Kind::Cube, &pyr, Wrap::Clamp, Wrap::Clamp, None)
}

/// The pyramid-less shadow image of a zfile (an error when it lacks its camera matrices).
pub fn shadow_image(z: &ZFile) -> Result<(Image, ([f32; 16], [f32; 16])), String> {
    let m = z
        .matrices
        .ok_or("the zfile has no camera matrices (it was not rendered by a Display \"zfile\" or \"shadow\" of this renderer version)")?;
    let im = Image {
        width: z.width as usize,
        height: z.height as usize,
        nchan: 1,
        data: z.depths.clone(),
    };
    Ok((im, m))
}

/// A shadow map from a zfile.
pub fn make_shadow(input: &Path, output: &Path) -> Result<(), String> {
    let bytes =
        std::fs::read(input).map_err(|e| format!("cannot read `{}`: {e}", input.display()))?;
    let z = ZFile::from_bytes(&bytes).map_err(|e| format!("`{}`: {e}", input.display()))?;
    let (im, m) = shadow_image(&z).map_err(|e| format!("`{}`: {e}", input.display()))?;
    format::write(
        output,
        Kind::Shadow,
        &[vec![im]],
        Wrap::Black,
        Wrap::Black,
        Some(m),
    )
}

/// Finds an input picture: as given, then in each search directory.
pub fn resolve(name: &str, search: &[PathBuf]) -> PathBuf {
    let p = PathBuf::from(name);
    if p.is_absolute() || p.exists() {
        return p;
    }
    for d in search {
        let c = d.join(name);
        if c.exists() {
            return c;
        }
    }
    p
}

/// Runs one Make* job, reporting problems as diagnostics.
pub fn run_job(job: &TextureJob, search: &[PathBuf], diags: &Diagnostics) {
    let span = job.span;
    let warn =
        |msg: String| diags.report(Diag::warning("texture::make", msg).label(span, "this request"));
    let filter = match downsample_for(&job.filter) {
        Some(f) => f,
        None => {
            warn(format!(
                "filter \"{}\" is not known for texture making; using gaussian",
                job.filter
            ));
            Downsample::Gaussian
        }
    };
    let wrap = |s: &str| {
        if s.is_empty() {
            return Wrap::Periodic;
        }
        Wrap::parse(s).unwrap_or_else(|| {
            warn(format!(
                "wrap mode \"{s}\" is not periodic, clamp or black; using periodic"
            ));
            Wrap::Periodic
        })
    };
    let o = MakeOptions {
        swrap: wrap(&job.swrap),
        twrap: wrap(&job.twrap),
        filter,
    };
    let out = PathBuf::from(&job.output);
    let inputs: Vec<PathBuf> = job.inputs.iter().map(|n| resolve(n, search)).collect();
    let r = match job.kind {
        TextureJobKind::Texture => make_texture(&inputs[0], &out, &o),
        TextureJobKind::LatLongEnvironment => make_latlong(&inputs[0], &out, &o),
        TextureJobKind::CubeFaceEnvironment => {
            if (job.fov - 90.0).abs() > 1e-3 {
                warn(format!(
                    "cube faces rendered with fov {} are used as 90° faces (the wider border is not cropped)",
                    job.fov
                ));
            }
            make_cube(&inputs, &out, &o)
        }
        TextureJobKind::Shadow => make_shadow(&inputs[0], &out),
        TextureJobKind::Horizon => super::horizon::make_horizon(&inputs[0], &out, job.directions),
    };
    if let Err(e) = r {
        diags.report(
            Diag::error(
                "texture::make",
                format!("cannot make `{}`: {e}", job.output),
            )
            .label(span, "this request"),
        );
    }
}
