//! `arbor shade`: a shader on a swatch object under a three-light rig, rendered at once.
//!
//! Input: a shader (a name on the search path / in the standard library, or a `.sl` file),
//! `name=value` parameter settings, the swatch object and the image size.
//! Output: an image file, written by the ordinary pipeline (RIB text → scene → render_frame
//! with a ShadeSystem → displays), so a swatch looks exactly as the shader renders in a scene.
//! Invariants: parameter values are typed from the compiled shader's parameter list (an
//! unknown name or a value of the wrong shape is an error naming the parameter and its type);
//! the scene is fixed (camera, key/fill/rim distant lights plus ambient), so swatches of
//! different shaders compare directly.

use std::path::{Path, PathBuf};

use crate::diag::{did_you_mean, Diag, Diagnostics, SourceMap};
use crate::render::driver::{effective_options, render_frame, RenderOptions};
use crate::scene::{build_scenes, BuildContext};
use crate::shade::system::ShadeSystem;
use crate::sl::ast::{BaseType, ShaderKind};
use crate::sl::ir::Program;
use crate::sl::{CompileOptions, ShaderLibrary};

/// The object the shader is shown on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SwatchObject {
    Sphere,
    Plane,
    Teapot,
}

impl SwatchObject {
    pub fn parse(s: &str) -> Option<SwatchObject> {
        match s {
            "sphere" => Some(SwatchObject::Sphere),
            "plane" => Some(SwatchObject::Plane),
            "teapot" => Some(SwatchObject::Teapot),
            _ => None,
        }
    }
}

/// What to render.
#[derive(Clone, Debug)]
pub struct SwatchRequest {
    /// A shader name or a path to a `.sl` file.
    pub shader: String,
    /// `name=value` settings, in order (a later one wins).
    pub params: Vec<String>,
    pub object: SwatchObject,
    /// Image width and height in pixels.
    pub size: u32,
    pub output: PathBuf,
    /// Pixel samples per side (3 by default: smooth edges, still fast).
    pub samples: u32,
    pub compile: CompileOptions,
}

/// Finds and compiles the shader: returns the library to render with and the shader's name.
fn load_shader(
    req: &SwatchRequest,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Option<(ShaderLibrary, String, std::sync::Arc<Program>)> {
    let mut opts = req.compile.clone();
    let name = if req.shader.ends_with(".sl") {
        let path = Path::new(&req.shader);
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        opts.search_paths.insert(0, dir);
        path.file_stem()?.to_string_lossy().to_string()
    } else {
        req.shader.clone()
    };
    let lib = ShaderLibrary::new(opts);
    let prog = lib.get(&name, sources, diags)?;
    if !matches!(prog.kind, ShaderKind::Surface | ShaderKind::Displacement) {
        diags.report(
            Diag::error(
                "shade::kind",
                format!(
                    "`{}` is a {} shader; `arbor shade` shows surface and displacement shaders",
                    prog.name,
                    prog.kind.name()
                ),
            )
            .help("render light and volume shaders in a scene with `arbor render`"),
        );
        return None;
    }
    Some((lib, prog.name.clone(), prog))
}

/// Numbers of a value, or an error message.
fn numbers(text: &str) -> Result<Vec<f32>, String> {
    text.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|w| !w.is_empty())
        .map(|w| {
            w.parse::<f32>()
                .map_err(|_| format!("`{w}` is not a number"))
        })
        .collect()
}

/// Turns one `name=value` setting into a RIB parameter (`"uniform color Kd" [1 0.5 0]`) typed
/// from the shader's parameter list.
pub fn typed_param(prog: &Program, setting: &str) -> Result<String, Diag> {
    let Some((name, value)) = setting.split_once('=') else {
        return Err(
            Diag::error("shade::param", format!("`-p {setting}` must be name=value"))
                .help("e.g. -p Ks=0.8 -p \"specularcolor=1 0.5 0\""),
        );
    };
    let name = name.trim();
    let Some(par) = prog.params.iter().find(|p| p.name == name && !p.output) else {
        let names = prog.params.iter().map(|p| p.name.as_str());
        let mut d = Diag::error(
            "shade::param",
            format!("shader `{}` has no parameter `{name}`", prog.name),
        );
        if let Some(s) = did_you_mean(name, names) {
            d = d.help(format!("did you mean `{s}`?"));
        } else {
            let all: Vec<&str> = prog.params.iter().map(|p| p.name.as_str()).collect();
            d = d.help(format!("its parameters are: {}", all.join(", ")));
        }
        return Err(d);
    };
    let count = par.array.unwrap_or(1);
    let arr = par.array.map(|n| format!("[{n}]")).unwrap_or_default();
    let decl = format!("uniform {}{arr} {}", par.ty.name(), par.name);
    let bad = |msg: String| {
        Diag::error(
            "shade::param",
            format!("`{name}` is a {}{arr}: {msg}", par.ty.name()),
        )
    };
    if par.ty == BaseType::String {
        let v = value.trim().trim_matches('"').replace('"', "\\\"");
        return Ok(format!("\"{decl}\" [\"{v}\"]"));
    }
    let per = match par.ty {
        BaseType::Float => 1,
        BaseType::Color | BaseType::Point | BaseType::Vector | BaseType::Normal => 3,
        BaseType::Matrix => 16,
        _ => return Err(bad("cannot be set from the command line".into())),
    };
    let mut v = numbers(value).map_err(bad)?;
    // One number sets every component (as SL's float-to-triple promotion does).
    if v.len() == 1 && per == 3 {
        v = vec![v[0]; 3];
    }
    if v.len() != per * count {
        return Err(bad(format!(
            "expected {} number(s), found {}",
            per * count,
            v.len()
        )));
    }
    let list: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    Ok(format!("\"{decl}\" [{}]", list.join(" ")))
}

/// Whether the geometry module renders `Geometry "teapot"` (another part of arbor adds it).
fn teapot_supported() -> bool {
    use crate::scene::{Geometry, ParamList, Primitive};
    use std::sync::Arc;
    let prim = Primitive {
        geometry: Arc::new(Geometry::Named {
            name: "teapot".into(),
        }),
        primvars: Arc::new(ParamList::default()),
        attributes: Arc::new(Default::default()),
        world_from_object: glam::Mat4::IDENTITY.into(),
        span: Default::default(),
        motion: None,
    };
    let scratch = Diagnostics::new();
    !crate::geom::surfaces_for(
        0,
        &prim,
        glam::Mat4::from_translation(glam::Vec3::Z * 5.0),
        &scratch,
    )
    .is_empty()
}

/// The swatch scene as RIB text.
pub fn swatch_rib(
    kind: ShaderKind,
    shader: &str,
    params: &[String],
    object: SwatchObject,
    size: u32,
    samples: u32,
) -> String {
    let plist = params.join(" ");
    let shading = match kind {
        ShaderKind::Displacement => format!(
            "Attribute \"displacementbound\" \"sphere\" [0.2]\n    Surface \"plastic\"\n    Displacement \"{shader}\" {plist}"
        ),
        _ => format!("Surface \"{shader}\" {plist}"),
    };
    let object_rib = match object {
        // z up in object space shown as y up, so "latitude" patterns stand upright.
        SwatchObject::Sphere => "Rotate -90 1 0 0\n    Sphere 1 -1 1 360".to_string(),
        SwatchObject::Plane => "Rotate 55 1 0 0\n    Polygon \"P\" [-1 -1 0  1 -1 0  1 1 0  -1 1 0] \"s\" [0 1 1 0] \"t\" [1 1 0 0]".to_string(),
        SwatchObject::Teapot => "Translate 0 -0.75 0\n    Rotate -90 1 0 0\n    Scale 0.5 0.5 0.5\n    Geometry \"teapot\"".to_string(),
    };
    format!(
        r#"##RenderMan RIB
# arbor shade swatch
Format {size} {size} 1
PixelSamples {samples} {samples}
PixelFilter "gaussian" 2 2
Display "swatch.png" "file" "rgba"
Projection "perspective" "fov" [24]
Translate 0 0 5.2
WorldBegin
  LightSource "ambientlight" 1 "intensity" [0.08]
  # key: above left, in front
  LightSource "distantlight" 2 "intensity" [0.95] "from" [-2 2.2 -2.5] "to" [0 0 0]
  # fill: right, lower, softer and cooler
  LightSource "distantlight" 3 "intensity" [0.35] "lightcolor" [0.85 0.9 1] "from" [2.5 0.3 -1.5] "to" [0 0 0]
  # rim: behind, above
  LightSource "distantlight" 4 "intensity" [0.7] "from" [0.5 2 3] "to" [0 0 0]
  AttributeBegin
    Color [0.8 0.8 0.8]
    {shading}
    {object_rib}
  AttributeEnd
WorldEnd
"#
    )
}

/// Renders the swatch; returns the files written (errors are in `diags`).
pub fn render_swatch(
    req: &SwatchRequest,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<PathBuf> {
    let Some((library, name, prog)) = load_shader(req, sources, diags) else {
        return Vec::new();
    };
    let mut params = Vec::new();
    for setting in &req.params {
        match typed_param(&prog, setting) {
            Ok(p) => params.push(p),
            Err(d) => diags.report(d),
        }
    }
    if diags.has_errors() {
        return Vec::new();
    }
    let mut object = req.object;
    if object == SwatchObject::Teapot && !teapot_supported() {
        diags.report(Diag::warning(
            "shade::teapot",
            "Geometry \"teapot\" is not available in this build; showing a sphere",
        ));
        object = SwatchObject::Sphere;
    }
    let size = req.size.clamp(8, 8192);
    let rib = swatch_rib(prog.kind, &name, &params, object, size, req.samples.max(1));
    let requests = crate::rib::parse_bytes("<swatch>", rib.as_bytes(), sources, diags);
    let ctx = BuildContext {
        sources,
        diags,
        shader_paths: Vec::new(),
        texture_paths: Vec::new(),
        archive_paths: Vec::new(),
        base_dir: std::env::current_dir().ok(),
        frames: None,
        procedurals: Default::default(),
    };
    let scenes = build_scenes(requests, &ctx);
    let Some(scene) = scenes.first() else {
        return Vec::new();
    };
    let system = ShadeSystem {
        library: &library,
        sources,
        diags,
        textures: None,
        aovs: Vec::new(),
        rays: Default::default(),
    };
    let opts = RenderOptions::default();
    let film = render_frame(scene, &system, &opts, diags);
    let options = effective_options(&scene.options, &opts);
    match crate::film::output::write_displays(&film, &options, diags, Some(&req.output)) {
        Ok(files) => files,
        Err(d) => {
            diags.report(d);
            Vec::new()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plastic() -> std::sync::Arc<Program> {
        let lib = ShaderLibrary::new(CompileOptions::default());
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        lib.get("plastic", &sources, &diags).unwrap()
    }

    #[test]
    fn params_are_typed_from_the_shader() {
        let p = plastic();
        assert_eq!(
            typed_param(&p, "Ks=0.8").unwrap(),
            "\"uniform float Ks\" [0.8]"
        );
        assert_eq!(
            typed_param(&p, "specularcolor=1 0.5 0").unwrap(),
            "\"uniform color specularcolor\" [1 0.5 0]"
        );
        // one number fills a colour
        assert_eq!(
            typed_param(&p, "specularcolor=0.5").unwrap(),
            "\"uniform color specularcolor\" [0.5 0.5 0.5]"
        );
    }

    #[test]
    fn bad_params_are_errors_with_help() {
        let p = plastic();
        let d = typed_param(&p, "Kss=1").unwrap_err();
        assert!(d.message.contains("Kss"), "{}", d.message);
        assert!(typed_param(&p, "Ks=abc").is_err());
        assert!(typed_param(&p, "specularcolor=1 2").is_err());
        assert!(typed_param(&p, "Ks").is_err());
    }

    #[test]
    fn swatch_scene_parses_and_builds() {
        let rib = swatch_rib(
            ShaderKind::Surface,
            "plastic",
            &["\"uniform float Ks\" [0.8]".into()],
            SwatchObject::Plane,
            32,
            1,
        );
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let reqs = crate::rib::parse_bytes("<swatch>", rib.as_bytes(), &sources, &diags);
        let ctx = BuildContext::new(&sources, &diags);
        let scenes = build_scenes(reqs, &ctx);
        assert!(!diags.has_errors(), "{:?}", diags.snapshot());
        assert_eq!(scenes.len(), 1);
        assert_eq!(scenes[0].lights.len(), 4);
        assert_eq!(scenes[0].primitives.len(), 1);
        assert_eq!(scenes[0].options.xres, 32);
    }
}
