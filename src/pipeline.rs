//! The whole pipeline behind `arbor render` and `arbor check`: read RIB, build scenes,
//! compile shaders, render each frame and write its displays.
//!
//! Input: file paths (or "-" for stdin) and command-line settings. Output: image files and
//! diagnostics in the shared sink. Invariants: an error in one frame does not stop the others;
//! a frame whose scene had errors still renders what it can (RISpec's error model), but the
//! run's exit status reports the errors.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::diag::{Diag, Diagnostics, SourceMap};
use crate::render::driver::{render_frame, render_frame_rows, RenderOptions};
use crate::render::hider::Aov;
use crate::render::stats::Stats;
use crate::scene::{build_scenes, BuildContext, Builder, ParamType, Scene};
use crate::shade::system::ShadeSystem;
use crate::sl::{CompileOptions, ShaderLibrary};

/// Settings from the command line.
#[derive(Clone, Debug, Default)]
pub struct Settings {
    pub shader_paths: Vec<String>,
    pub texture_paths: Vec<String>,
    pub archive_paths: Vec<String>,
    pub include_dirs: Vec<PathBuf>,
    pub defines: Vec<(String, Option<String>)>,
    pub resolution: Option<(u32, u32)>,
    pub crop: Option<[f32; 4]>,
    pub frames: Option<(i32, i32)>,
    pub threads: usize,
    pub bucket_size: Option<[u32; 2]>,
    pub output: Option<PathBuf>,
    /// Render only this tile of each frame (`--tile I/N`), into a tile file.
    pub tile: Option<crate::farm::TileSpec>,
    pub stats: bool,
    pub progress: bool,
    /// Run the programs and load the libraries that `Procedural "RunProgram"`/`"DynamicLoad"`
    /// name (`--allow-programs`).
    pub allow_programs: bool,
    /// How long such a program may stay silent, in seconds (None: the default, 60 s).
    pub program_timeout: Option<f32>,
}

impl Settings {
    /// The procedural settings these command-line settings give the scene builder.
    pub fn procedurals(&self) -> crate::scene::builder::ProceduralSettings {
        let mut p = crate::scene::builder::ProceduralSettings {
            allow: self.allow_programs,
            resolution: self.resolution,
            ..Default::default()
        };
        if let Some(t) = self.program_timeout.filter(|t| t.is_finite() && *t > 0.0) {
            p.timeout = std::time::Duration::from_secs_f32(t);
        }
        p
    }
}

/// Reads and builds every scene of a RIB file.
pub fn load_scenes(
    path: &Path,
    settings: &Settings,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<Scene> {
    let base_dir = if path.as_os_str() == "-" {
        std::env::current_dir().ok()
    } else {
        path.parent().map(|p| {
            if p.as_os_str().is_empty() {
                PathBuf::from(".")
            } else {
                p.to_path_buf()
            }
        })
    };
    let ctx = BuildContext {
        sources,
        diags,
        shader_paths: settings.shader_paths.clone(),
        texture_paths: settings.texture_paths.clone(),
        archive_paths: settings.archive_paths.clone(),
        base_dir,
        frames: settings.frames,
        procedurals: settings.procedurals(),
    };
    // Each request is built as soon as it is read: a file's requests are never all in memory.
    let mut builder = Builder::new(&ctx);
    if let Err(d) = crate::rib::read_path_into(path, sources, diags, &mut |r| builder.feed(&r)) {
        diags.report(d);
        return Vec::new();
    }
    builder.finish()
}

/// The shader library for a scene: CLI paths, the scene's search path, the scene's folder.
pub fn library_for(scene: &Scene, settings: &Settings) -> ShaderLibrary {
    let mut search: Vec<PathBuf> = settings.shader_paths.iter().map(PathBuf::from).collect();
    for p in &scene.options.search_paths.shader {
        let pb = PathBuf::from(p);
        let pb = match (&scene.source_dir, pb.is_relative()) {
            (Some(d), true) => d.join(pb),
            _ => pb,
        };
        if !search.contains(&pb) {
            search.push(pb);
        }
    }
    if let Some(d) = &scene.source_dir {
        if !search.contains(d) {
            search.push(d.clone());
        }
    }
    ShaderLibrary::new(CompileOptions {
        include_dirs: settings.include_dirs.clone(),
        defines: settings.defines.clone(),
        search_paths: search,
    })
}

/// Every shader a scene names (surfaces, displacements, atmospheres, lights), sorted and
/// without repeats: what `arbor check` and the editor compile to report a scene's errors.
pub fn shader_names(scene: &Scene) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for p in &scene.primitives {
        let a = &p.attributes;
        for sh in [&a.surface, &a.displacement, &a.atmosphere]
            .into_iter()
            .flatten()
        {
            names.push(sh.name.clone());
        }
    }
    names.extend(scene.lights.iter().map(|l| l.shader.name.clone()));
    names.sort();
    names.dedup();
    names
}

/// Arbitrary output variables the displays ask for (modes other than r g b a z).
pub fn aovs_for(scene: &Scene) -> Vec<Aov> {
    let mut out: Vec<Aov> = Vec::new();
    for d in &scene.options.displays {
        let mode = d.mode.trim();
        let plain = mode
            .chars()
            .all(|c| matches!(c, 'r' | 'g' | 'b' | 'a' | 'z'))
            && !mode.is_empty();
        if plain {
            continue;
        }
        // "N", "Ci", "varying color diffuse" style modes: the last word is the name.
        let words: Vec<&str> = mode.split_whitespace().collect();
        let name = words.last().copied().unwrap_or(mode).to_string();
        let ty = if words.contains(&"float") {
            ParamType::Float
        } else if words.contains(&"normal") {
            ParamType::Normal
        } else if words.contains(&"point") {
            ParamType::Point
        } else if words.contains(&"vector") {
            ParamType::Vector
        } else {
            match name.as_str() {
                "N" | "Ng" => ParamType::Normal,
                "P" => ParamType::Point,
                "s" | "t" | "u" | "v" => ParamType::Float,
                _ => ParamType::Color,
            }
        };
        if !out.iter().any(|a| a.name == name) {
            out.push(Aov::new(name, ty));
        }
    }
    out
}

/// Renders every frame of every file. Returns the files written.
pub fn render_paths(
    paths: &[PathBuf],
    settings: &Settings,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<PathBuf> {
    let mut written = Vec::new();
    let mut first_display = true;
    for path in paths {
        let first_source = sources.len() as u32;
        let mut scenes = load_scenes(path, settings, sources, diags);
        let scene_sources = first_source..sources.len() as u32;
        let archive_only = || {
            diags
                .snapshot()
                .iter()
                .any(|(d, _)| d.code == "scene::archive-only")
        };
        if scenes.is_empty() && !diags.has_errors() && !archive_only() {
            diags.report(Diag::warning(
                "render::empty",
                format!("`{}` contains no world block to render", path.display()),
            ));
        }
        for scene in &mut scenes {
            // Make* jobs first: a shadow pass's zfile from an earlier frame is there now.
            let tex_search = texture_search_for(scene, settings);
            for job in &scene.texture_jobs {
                crate::texture::make::run_job(job, &tex_search, diags);
            }
            if scene.jobs_only {
                continue;
            }
            let mem_kb = scene
                .options
                .user_floats("limits:texturememory")
                .and_then(|v| v.first().copied())
                .filter(|k| *k >= 1.0)
                .map(|k| k as usize)
                .unwrap_or(crate::texture::DEFAULT_MEMORY_KB);
            let textures = crate::texture::TextureSystem::new(tex_search, mem_kb, diags);
            let library = library_for(scene, settings);
            let aovs = aovs_for(scene);
            let system = ShadeSystem {
                library: &library,
                sources,
                diags,
                textures: Some(&textures),
                aovs: aovs.iter().map(|a| a.name.clone()).collect(),
                rays: Default::default(),
            };
            let stats = Stats::default();
            let bar = if settings.progress {
                Some(progress_bar())
            } else {
                None
            };
            let progress = |done: usize, total: usize| {
                if let Some(b) = &bar {
                    b.set_length(total as u64);
                    b.set_position(done as u64);
                }
            };
            let mut opts = RenderOptions {
                threads: settings.threads,
                bucket_size: settings.bucket_size,
                crop: settings.crop,
                resolution: settings.resolution,
                stats: if settings.stats { Some(&stats) } else { None },
                progress: if bar.is_some() { Some(&progress) } else { None },
                aovs,
            };
            let override_path = output_override(scene, settings, &mut first_display);
            // A tile renders the crop window of its pixels (with their filter margins);
            // depth passes render whole, since later frames' MakeShadow reads them.
            let tile = match settings.tile.filter(|_| !depth_pass(scene)) {
                Some(t) => match tile_plan(scene, &opts, t) {
                    Ok(plan) => {
                        opts.crop = Some(plan.window);
                        Some(plan)
                    }
                    Err(d) => {
                        diags.report(d);
                        continue;
                    }
                },
                None => None,
            };
            crate::render::lod::select_for(scene, &opts);
            system.preload_lights(scene);
            let start = Instant::now();
            // 8-bit PNG displays of a whole frame are encoded as its rows finish.
            let mut streams = match &tile {
                None => plan_streams(scene, &opts, override_path.as_deref()),
                Some(_) => Default::default(),
            };
            let film = if streams.any() {
                render_frame_rows(scene, &system, &opts, Some(&mut streams), diags)
            } else {
                render_frame(scene, &system, &opts, diags)
            };
            if let Some(b) = &bar {
                b.finish_and_clear();
            }
            let output_clock = settings.stats.then(|| {
                let me = crate::render::stats::this_thread();
                crate::render::stats::PhaseClock::now(std::sync::Arc::new(me.into_iter().collect()))
            });
            let mut options = crate::render::driver::effective_options(&scene.options, &opts);
            // Imager shaders (the film applies the standard `background` itself).
            let mut film = film;
            let imager_applied =
                system.run_imager(scene, &crate::render::Camera::new(scene), &mut film);
            if imager_applied {
                options.imager = None;
            }
            if let Some(plan) = tile {
                let display = tile_display(scene, override_path.as_deref());
                let file = crate::farm::tile::path(&display, plan.spec);
                let meta = crate::farm::tile::TileMeta {
                    frame: scene.frame,
                    tile: plan.spec,
                    xres: options.xres,
                    yres: options.yres,
                    region: plan.region,
                    rect: plan.rect,
                    settings: crate::farm::settings_hash(
                        sources,
                        scene_sources.clone(),
                        settings,
                        scene.frame,
                    ),
                    imager_applied,
                    channels: film.channel_names.clone(),
                };
                match crate::farm::tile::write(&file, &film, &meta) {
                    Ok(()) => written.push(file),
                    Err(d) => diags.report(d),
                }
            } else {
                written.extend(write_frame_streamed(
                    scene,
                    film,
                    &options,
                    override_path.as_deref(),
                    diags,
                    streams,
                ));
            }
            stats.phase(crate::render::stats::Phase::Output, output_clock);
            if settings.stats {
                eprintln!(
                    "frame {}: {:.3} s",
                    scene
                        .frame
                        .map(|f| f.to_string())
                        .unwrap_or_else(|| "-".into()),
                    start.elapsed().as_secs_f64()
                );
                eprintln!("{stats}");
            }
        }
    }
    written
}

/// True for a frame whose displays are all depth maps (zfile/shadow): a shadow pass.
pub fn depth_pass(scene: &Scene) -> bool {
    !scene.options.displays.is_empty()
        && scene
            .options
            .displays
            .iter()
            .all(|d| matches!(d.kind.to_ascii_lowercase().as_str(), "zfile" | "shadow"))
}

/// `-o` replaces the first display of the first frame that makes a picture: depth passes
/// (zfile/shadow displays) of multi-pass files keep their files, since later frames'
/// MakeShadow reads them.
pub fn output_override(
    scene: &Scene,
    settings: &Settings,
    first_display: &mut bool,
) -> Option<PathBuf> {
    let depth = scene
        .options
        .displays
        .first()
        .is_some_and(|d| matches!(d.kind.to_ascii_lowercase().as_str(), "zfile" | "shadow"));
    if *first_display && !depth {
        *first_display = false;
        settings.output.clone()
    } else {
        None
    }
}

/// The picture a frame's tile files are named after: `-o`, else its first Display, else
/// `ri.png` (as the display writer defaults).
pub fn tile_display(scene: &Scene, override_path: Option<&Path>) -> PathBuf {
    override_path
        .map(Path::to_path_buf)
        .or_else(|| {
            scene
                .options
                .displays
                .first()
                .map(|d| PathBuf::from(&d.name))
        })
        .unwrap_or_else(|| PathBuf::from("ri.png"))
}

/// Where a tile of a frame lies.
#[derive(Clone, Copy, Debug)]
pub struct TilePlan {
    pub spec: crate::farm::TileSpec,
    /// The frame's output region (its CropWindow pixels).
    pub region: crate::render::PixelRect,
    /// This tile's pixels.
    pub rect: crate::render::PixelRect,
    /// The crop window that renders exactly `rect`.
    pub window: [f32; 4],
}

/// The tile `t` of a frame rendered with `opts` (resolution override applied; the scene's own
/// CropWindow is the region the tiles split).
pub fn tile_plan(
    scene: &Scene,
    opts: &RenderOptions,
    t: crate::farm::TileSpec,
) -> Result<TilePlan, Diag> {
    if opts.crop.is_some() {
        return Err(
            Diag::error("farm::tiles", "--tile and --crop cannot be combined")
                .help("put the CropWindow in the scene; the tiles split it"),
        );
    }
    let o = crate::render::driver::effective_options(&scene.options, opts);
    let region = crate::render::crop_region(o.xres, o.yres, o.crop_window);
    let rect = crate::farm::tile::rect(region, t)?;
    Ok(TilePlan {
        spec: t,
        region,
        rect,
        window: crate::farm::tile::ndc_window(rect, o.xres, o.yres),
    })
}

/// Writes a rendered frame's displays: a cropped render writes only the crop region. `film` is
/// the full-resolution film (imager already run); `options` the effective options.
pub fn write_frame(
    scene: &Scene,
    film: crate::film::Film,
    options: &crate::scene::Options,
    override_path: Option<&Path>,
    diags: &Diagnostics,
) -> Vec<PathBuf> {
    write_frame_streamed(
        scene,
        film,
        options,
        override_path,
        diags,
        Default::default(),
    )
}

/// The displays a frame can encode while it renders (see `film::stream`): none for a
/// cropped frame or one with an imager shader (both change the film after the render).
fn plan_streams(
    scene: &Scene,
    opts: &RenderOptions,
    override_path: Option<&Path>,
) -> crate::film::stream::Streams {
    let options = crate::render::driver::effective_options(&scene.options, opts);
    let r = crate::render::crop_region(options.xres, options.yres, options.crop_window);
    let (w, h) = (options.xres as usize, options.yres as usize);
    let whole = r.x0 == 0 && r.y0 == 0 && r.width() == w && r.height() == h;
    if !whole || w == 0 || h == 0 {
        return Default::default();
    }
    let mut aovs = Vec::new();
    for a in &opts.aovs {
        aovs.extend(a.channel_names());
    }
    let channels = crate::film::Film::standard_channels(&aovs);
    crate::film::output::plan_streams(&options, override_path, channels, w, h)
}

/// [`write_frame`] with the displays encoded during the render.
pub fn write_frame_streamed(
    scene: &Scene,
    film: crate::film::Film,
    options: &crate::scene::Options,
    override_path: Option<&Path>,
    diags: &Diagnostics,
    streams: crate::film::stream::Streams,
) -> Vec<PathBuf> {
    let r = crate::render::crop_region(options.xres, options.yres, options.crop_window);
    let film = if r.width() < film.width || r.height() < film.height {
        film.cropped(
            r.x0.max(0) as usize,
            r.y0.max(0) as usize,
            r.x1.max(0) as usize,
            r.y1.max(0) as usize,
        )
    } else {
        film
    };
    match crate::film::output::write_displays_streamed(
        &film,
        options,
        diags,
        override_path,
        Some(depth_matrices(scene, options)),
        streams,
    ) {
        Ok(files) => files,
        Err(d) => {
            diags.report(d);
            Vec::new()
        }
    }
}

/// Texture search path of a scene: CLI paths, `Option "searchpath" "texture"` (relative to
/// the scene's folder), then the scene's folder.
pub fn texture_search_for(scene: &Scene, settings: &Settings) -> Vec<PathBuf> {
    let mut search: Vec<PathBuf> = settings.texture_paths.iter().map(PathBuf::from).collect();
    for p in &scene.options.search_paths.texture {
        let pb = PathBuf::from(p);
        let pb = match (&scene.source_dir, pb.is_relative()) {
            (Some(d), true) if !pb.exists() => d.join(pb),
            _ => pb,
        };
        if !search.contains(&pb) {
            search.push(pb);
        }
    }
    if let Some(d) = &scene.source_dir {
        if !search.contains(d) {
            search.push(d.clone());
        }
    }
    search
}

/// (camera_from_world, screen_from_world) row-major for zfile/shadow displays; "screen" is
/// normalised so the screen window spans [-1,1]² (x right, y up), whatever its real extent.
pub fn depth_matrices(scene: &Scene, options: &crate::scene::Options) -> ([f32; 16], [f32; 16]) {
    use glam::{Mat4, Vec4};
    let cam = crate::render::Camera::from_options(
        options,
        scene.camera_from_world,
        &scene.coordinate_systems,
    );
    let ndc_from_world = cam.ndc_from_screen * cam.screen_from_camera * cam.camera_from_world;
    // NDC (0..1, y down) → [-1,1] with y up.
    let unit = Mat4::from_cols(
        Vec4::new(2.0, 0.0, 0.0, 0.0),
        Vec4::new(0.0, -2.0, 0.0, 0.0),
        Vec4::new(0.0, 0.0, 1.0, 0.0),
        Vec4::new(-1.0, 1.0, 0.0, 1.0),
    );
    let rows = |m: Mat4| m.transpose().to_cols_array();
    (rows(cam.camera_from_world), rows(unit * ndc_from_world))
}

fn progress_bar() -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(1);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{bar:40}] {pos}/{len} buckets {elapsed}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

/// Renders RIB text in memory and returns each frame's film (no files written): for tests,
/// tools and benchmarks. Shaders are looked up in `settings.shader_paths` and the standard
/// library.
pub fn render_text(
    text: &str,
    settings: &Settings,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<crate::film::Film> {
    let requests = crate::rib::parse_bytes("<memory>", text.as_bytes(), sources, diags);
    let ctx = BuildContext {
        sources,
        diags,
        shader_paths: settings.shader_paths.clone(),
        texture_paths: settings.texture_paths.clone(),
        archive_paths: settings.archive_paths.clone(),
        base_dir: None,
        frames: settings.frames,
        procedurals: settings.procedurals(),
    };
    let mut scenes = build_scenes(requests, &ctx);
    let mut films = Vec::new();
    for scene in &mut scenes {
        let library = library_for(scene, settings);
        let aovs = aovs_for(scene);
        let system = ShadeSystem {
            library: &library,
            sources,
            diags,
            textures: None,
            aovs: aovs.iter().map(|a| a.name.clone()).collect(),
            rays: Default::default(),
        };
        system.preload_lights(scene);
        let opts = RenderOptions {
            threads: settings.threads,
            bucket_size: settings.bucket_size,
            crop: settings.crop,
            resolution: settings.resolution,
            stats: None,
            progress: None,
            aovs,
        };
        crate::render::lod::select_for(scene, &opts);
        let mut film = render_frame(scene, &system, &opts, diags);
        system.run_imager(scene, &crate::render::Camera::new(scene), &mut film);
        films.push(film);
    }
    films
}
