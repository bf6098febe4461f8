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
use super::mipmap::{build_pyramid_with, Downsample, Wrap};

/// How to build the pyramid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MakeOptions {
    pub swrap: Wrap,
    pub twrap: Wrap,
    pub filter: Downsample,
    /// Prefilter widths in texels of the level being made (RISpec swidth/twidth); 0 means
    /// the filter's natural width.
    pub swidth: f32,
    pub twidth: f32,
}

impl Default for MakeOptions {
    fn default() -> Self {
        MakeOptions {
            swrap: Wrap::Periodic,
            twrap: Wrap::Periodic,
            filter: Downsample::Box,
            swidth: 0.0,
            twidth: 0.0,
        }
    }
}

impl MakeOptions {
    fn pyramid(&self, im: Image, swrap: Wrap, twrap: Wrap) -> Vec<Image> {
        let nat = self.filter.natural_width();
        let w = |v: f32| if v > 0.0 { v } else { nat };
        build_pyramid_with(
            im,
            swrap,
            twrap,
            self.filter,
            w(self.swidth),
            w(self.twidth),
        )
    }
}

/// Downsampling filter for a RenderMan filter name (box, triangle, catmull-rom, gaussian,
/// sinc, mitchell, disk, bessel, b-spline; "" is box). None for unknown names.
pub fn downsample_for(name: &str) -> Option<Downsample> {
    Downsample::parse(name)
}

/// A 2-D texture.
pub fn make_texture(input: &Path, output: &Path, o: &MakeOptions) -> Result<(), String> {
    let im = read_image(input)?;
    let levels = o.pyramid(im, o.swrap, o.twrap);
    format::write(output, Kind::Texture, &[levels], o.swrap, o.twrap, None)
}

/// A bump map (see [`super::bump`]): heights and their s/t slopes, mip-mapped together.
pub fn make_bump(input: &Path, output: &Path, o: &MakeOptions) -> Result<(), String> {
    let im = read_image(input)?;
    let im = super::bump::bump_image(&im, o.swrap, o.twrap);
    let levels = o.pyramid(im, o.swrap, o.twrap);
    format::write(output, Kind::Bump, &[levels], o.swrap, o.twrap, None)
}

/// A lat-long environment (s periodic, t clamped).
pub fn make_latlong(input: &Path, output: &Path, o: &MakeOptions) -> Result<(), String> {
    let im = read_image(input)?;
    let levels = o.pyramid(im, Wrap::Periodic, Wrap::Clamp);
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
        .map(|f| o.pyramid(f, Wrap::Clamp, Wrap::Clamp))
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
    // A zfile, or a float depth TIFF (`Display "z.tif" "file" "z"`) with its camera
    // matrices in PRMan's tags.
    let z = if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        crate::film::tiff::read_depth(&bytes)
    } else {
        ZFile::from_bytes(&bytes)
    }
    .map_err(|e| format!("`{}`: {e}", input.display()))?;
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
    // swidth/twidth: the prefilter's support in texels of each level made.
    let width = |v: f32, which: &str| {
        if v.is_finite() && (1.0..=16.0).contains(&v) {
            return v;
        }
        let w = if v.is_finite() {
            v.clamp(1.0, 16.0)
        } else {
            1.0
        };
        warn(format!(
            "{which} {v} is outside [1, 16] texels (narrower would skip texels when halving); using {w}"
        ));
        w
    };
    // (MakeShadow has neither: its job carries 1 × 1, and a shadow map has no pyramid.)
    let (swidth, twidth) = (width(job.swidth, "swidth"), width(job.twidth, "twidth"));
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
        swidth,
        twidth,
    };
    let out = PathBuf::from(&job.output);
    let inputs: Vec<PathBuf> = job.inputs.iter().map(|n| resolve(n, search)).collect();
    let r = match job.kind {
        TextureJobKind::Texture => make_texture(&inputs[0], &out, &o),
        TextureJobKind::Bump => make_bump(&inputs[0], &out, &o),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::format::parse_header;

    fn job(kind: TextureJobKind, input: &Path, output: &Path, filter: &str, w: f32) -> TextureJob {
        TextureJob {
            kind,
            inputs: vec![input.display().to_string()],
            output: output.display().to_string(),
            swrap: "periodic".into(),
            twrap: "periodic".into(),
            filter: filter.into(),
            swidth: w,
            twidth: w,
            fov: 90.0,
            directions: 8,
            span: Default::default(),
        }
    }

    /// Level 1 of a made file, read back whole.
    fn level1(path: &Path) -> Vec<f32> {
        let bytes = std::fs::read(path).unwrap();
        let h = parse_header(&bytes).unwrap();
        let tex = crate::texture::cache::Texture::new(
            1,
            h,
            crate::texture::cache::Source::File(std::fs::File::open(path).unwrap()),
        );
        tex.read_level(0, 1).unwrap().data
    }

    #[test]
    fn requests_honour_filter_and_widths_and_make_bump_maps() {
        let scratch = tempfile::Builder::new()
            .prefix("arbor-make-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        // One bright column (x = 8) in a 16 × 4 grey-level picture.
        let png = dir.join("line.png");
        image::GrayImage::from_fn(16, 4, |x, _| image::Luma([if x == 8 { 255 } else { 0 }]))
            .save(&png)
            .unwrap();
        let out = dir.join("line.tex");
        let diags = Diagnostics::new();
        let row = |j: &TextureJob| {
            run_job(j, &[], &diags);
            level1(&out)[..8].to_vec()
        };
        // box 1 1: the 2 × 2 average; box 2 2 reaches one more texel each side; a 2-wide
        // triangle is [1 3 3 1]/8.
        let b1 = row(&job(TextureJobKind::Texture, &png, &out, "box", 1.0));
        assert_eq!(b1, [0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0]);
        let b2 = row(&job(TextureJobKind::Texture, &png, &out, "box", 2.0));
        assert_eq!(b2, [0.0, 0.0, 0.0, 0.25, 0.25, 0.0, 0.0, 0.0]);
        let t2 = row(&job(TextureJobKind::Texture, &png, &out, "triangle", 2.0));
        assert_eq!(t2, [0.0, 0.0, 0.0, 0.125, 0.375, 0.0, 0.0, 0.0]);
        assert!(diags.snapshot().is_empty(), "{:?}", diags.snapshot());
        // Widths outside [1, 16] warn by name and are clamped.
        let b0 = row(&job(TextureJobKind::Texture, &png, &out, "box", 0.25));
        assert_eq!(b0, b1);
        let msgs: Vec<String> = diags
            .snapshot()
            .iter()
            .map(|(d, _)| d.message.clone())
            .collect();
        assert!(
            msgs.iter().any(|m| m.starts_with("swidth 0.25")),
            "{msgs:?}"
        );
        assert!(
            msgs.iter().any(|m| m.starts_with("twidth 0.25")),
            "{msgs:?}"
        );
        // MakeBump: a bump-kind file with heights and slopes (3 channels for 1).
        let bump = dir.join("line.bump");
        run_job(
            &job(TextureJobKind::Bump, &png, &bump, "box", 1.0),
            &[],
            &diags,
        );
        let h = parse_header(&std::fs::read(&bump).unwrap()).unwrap();
        assert_eq!((h.kind, h.nchan), (Kind::Bump, 3));
        assert!(!diags.has_errors());
    }
}
