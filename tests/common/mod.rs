//! Shared helpers for integration tests: render RIB text in memory with the stdlib from the
//! source tree, and compare images against golden references.
//!
//! Golden images live in `tests/golden/NAME.png` (8-bit sRGB-free, i.e. the film's values
//! clamped to [0,1] and quantised like the PNG display). [`check_golden`] fails when the mean
//! absolute channel error exceeds `tol.mean` or any channel differs by more than `tol.max`;
//! on failure it writes the actual image and a ×10 difference image under
//! `target/golden-failures/`. With `UPDATE_GOLDEN=1` it (re)writes the reference instead.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use arbor::diag::{Diag, Diagnostics, SourceMap};
use arbor::film::resolve::Film;
use arbor::pipeline::{render_paths, Settings};
use arbor::render::driver::{render_frame, RenderOptions};
use arbor::scene::{build_scenes, BuildContext};
use arbor::shade::system::ShadeSystem;
use arbor::sl::{CompileOptions, ShaderLibrary};

/// The crate's folder.
pub fn manifest_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Compile options that read the standard library from the source tree (so tests see the
/// shaders and headers of this checkout even if the embedded copy is stale), plus `extra`
/// shader folders searched first.
pub fn stdlib_options(extra: &[PathBuf]) -> CompileOptions {
    let root = manifest_dir().join("stdlib");
    let mut search: Vec<PathBuf> = extra.to_vec();
    search.push(root.join("shaders"));
    CompileOptions {
        include_dirs: vec![root.join("include")],
        defines: Vec::new(),
        search_paths: search,
    }
}

/// A scratch folder under target/ unique to `name`.
pub fn scratch_dir(name: &str) -> PathBuf {
    let d = manifest_dir()
        .join("target")
        .join("test-scratch")
        .join(name);
    std::fs::create_dir_all(&d).expect("create scratch dir");
    d
}

/// Renders the first frame of RIB text with `opts`; returns the film, the diagnostics (with
/// their counts) and the source map that places them. Panics if anything is an error.
pub fn render_rib_with(
    rib: &str,
    extra_shader_dirs: &[PathBuf],
    opts: &RenderOptions,
) -> (Film, Vec<(Diag, usize)>, SourceMap) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let reqs = arbor::rib::parse_bytes("scene.rib", rib.as_bytes(), &sources, &diags);
    let ctx = BuildContext::new(&sources, &diags);
    let scenes = build_scenes(reqs, &ctx);
    assert!(
        !scenes.is_empty(),
        "no scene: {}",
        diags.render_plain(&sources)
    );
    let library = ShaderLibrary::new(stdlib_options(extra_shader_dirs));
    let system = ShadeSystem {
        library: &library,
        sources: &sources,
        diags: &diags,
        textures: None,
        aovs: Vec::new(),
        rays: Default::default(),
    };
    let film = render_frame(&scenes[0], &system, opts, &diags);
    assert!(
        !diags.has_errors(),
        "render errors: {}",
        diags.render_plain(&sources)
    );
    let snapshot = diags.snapshot();
    (film, snapshot, sources)
}

/// Renders the first frame of RIB text; panics with the diagnostics if anything is an error.
pub fn render_rib(rib: &str, extra_shader_dirs: &[PathBuf]) -> Film {
    render_rib_with(rib, extra_shader_dirs, &RenderOptions::default()).0
}

/// Writes `rib` to `dir/scene.rib` and renders it through the whole pipeline, as
/// `arbor render` does (displays write their files), on one thread, with `dir` and the source
/// tree's stdlib on the shader path. Returns the plain-text diagnostics and whether any is an
/// error.
pub fn render_scene_file(dir: &Path, rib: &str) -> (String, bool) {
    let path = dir.join("scene.rib");
    std::fs::write(&path, rib).expect("write scene");
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let stdlib = manifest_dir().join("stdlib").join("shaders");
    let settings = Settings {
        threads: 1,
        shader_paths: vec![dir.display().to_string(), stdlib.display().to_string()],
        ..Default::default()
    };
    render_paths(&[path], &settings, &sources, &diags);
    (diags.render_plain(&sources), diags.has_errors())
}

/// The film's r, g, b channels as floats (row-major, 3 per pixel).
pub fn film_rgb(film: &Film) -> Vec<f32> {
    let (r, g, b) = (
        film.channel("r").expect("r channel"),
        film.channel("g").expect("g channel"),
        film.channel("b").expect("b channel"),
    );
    let mut out = Vec::with_capacity(film.width * film.height * 3);
    for y in 0..film.height {
        for x in 0..film.width {
            let p = film.pixel(x, y);
            out.extend([p[r], p[g], p[b]]);
        }
    }
    out
}

/// Mean of each channel over the film.
pub fn film_mean(film: &Film) -> [f64; 3] {
    let rgb = film_rgb(film);
    let n = (rgb.len() / 3) as f64;
    let mut m = [0.0f64; 3];
    for px in rgb.chunks_exact(3) {
        for c in 0..3 {
            m[c] += px[c] as f64;
        }
    }
    m.map(|v| v / n)
}

/// Tolerances of a golden comparison, in [0,1] channel units.
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    pub mean: f32,
    pub max: f32,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            mean: 0.01,
            max: 0.25,
        }
    }
}

fn quantise(rgb: &[f32]) -> Vec<u8> {
    rgb.iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}

/// Compares an RGB float image with `tests/golden/NAME.png` (see the module docs).
pub fn check_golden(name: &str, width: usize, height: usize, rgb: &[f32], tol: Tolerance) {
    let actual = quantise(rgb);
    let golden_path = manifest_dir()
        .join("tests/golden")
        .join(format!("{name}.png"));
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::create_dir_all(golden_path.parent().unwrap()).unwrap();
        image::save_buffer(
            &golden_path,
            &actual,
            width as u32,
            height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .expect("write golden image");
        return;
    }
    let golden = image::open(&golden_path)
        .unwrap_or_else(|e| {
            panic!(
                "missing golden image {} ({e}); run with UPDATE_GOLDEN=1 to create it",
                golden_path.display()
            )
        })
        .to_rgb8();
    assert_eq!(
        (golden.width() as usize, golden.height() as usize),
        (width, height),
        "golden image {name} has another size"
    );
    let expected = golden.as_raw();
    let mut sum = 0.0f64;
    let mut max = 0.0f32;
    let mut diff = Vec::with_capacity(actual.len());
    for (a, e) in actual.iter().zip(expected) {
        let d = (*a as f32 - *e as f32).abs() / 255.0;
        sum += d as f64;
        max = max.max(d);
        diff.push((d * 10.0 * 255.0).min(255.0) as u8);
    }
    let mean = (sum / actual.len() as f64) as f32;
    if mean > tol.mean || max > tol.max {
        let dir = manifest_dir().join("target/golden-failures");
        std::fs::create_dir_all(&dir).unwrap();
        let save = |file: &Path, data: &[u8]| {
            let _ = image::save_buffer(
                file,
                data,
                width as u32,
                height as u32,
                image::ExtendedColorType::Rgb8,
            );
        };
        let actual_path = dir.join(format!("{name}.actual.png"));
        let diff_path = dir.join(format!("{name}.diff.png"));
        save(&actual_path, &actual);
        save(&diff_path, &diff);
        panic!(
            "{name}: mean channel error {mean:.4} (limit {}), max {max:.4} (limit {}); \
             wrote {} and {} (UPDATE_GOLDEN=1 accepts the new image)",
            tol.mean,
            tol.max,
            actual_path.display(),
            diff_path.display()
        );
    }
}

/// A scratch folder in the system temp folder that is removed with its contents when the value
/// is dropped (at the end of the test, pass or fail), so test runs leave nothing behind.
/// Derefs to its path.
pub struct Scratch {
    path: PathBuf,
    _dir: tempfile::TempDir,
}

/// A new empty scratch folder whose name starts with `arbor-{prefix}-`.
pub fn scratch(prefix: &str) -> Scratch {
    let dir = tempfile::Builder::new()
        .prefix(&format!("arbor-{prefix}-"))
        .tempdir()
        .expect("create scratch folder");
    Scratch {
        path: dir.path().to_path_buf(),
        _dir: dir,
    }
}

impl std::ops::Deref for Scratch {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

/// Renders RIB text through the whole pipeline on one thread, in memory: every frame's film,
/// the plain-text diagnostics, and whether any is an error.
pub fn render_text_report(text: &str) -> (Vec<Film>, String, bool) {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let films = arbor::pipeline::render_text(
        text,
        &Settings {
            threads: 1,
            ..Default::default()
        },
        &sources,
        &diags,
    );
    (films, diags.render_plain(&sources), diags.has_errors())
}
