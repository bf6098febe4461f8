//! The `arbor` command: argument parsing, progress and reporting; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use arbor::diag::{Diag, Diagnostics, Severity, SourceMap};
use arbor::pipeline::{self, Settings};
use arbor::sl::{compile_source, CompileOptions};

#[derive(Parser)]
#[command(
    name = "arbor",
    version,
    about = "RenderMan-style scene and shading language compiler (REYES renderer)"
)]
struct Cli {
    /// Only errors (no warnings, no progress).
    #[arg(short, long, global = true)]
    quiet: bool,
    /// More detail (every repeated warning's count, timings).
    #[arg(short, long, global = true)]
    verbose: bool,
    /// Run as if started in DIR, made if missing (relative file names, Display outputs and
    /// tiles go there; farm tasks use it for the job's output folder).
    #[arg(short = 'C', long = "directory", value_name = "DIR", global = true)]
    directory: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Render RIB files (stdin when none or "-") to the images their Display requests name.
    Render(RenderArgs),
    /// Assemble the tile files of `arbor render --tile I/N` into each Display's picture.
    Merge(MergeArgs),
    /// Write an Open Job Description template rendering a scene as frame × tile tasks on a farm.
    Job(JobArgs),
    /// Validate RIB files (parse and build) and compile shading-language files; render nothing.
    Check(CheckArgs),
    /// Print a shader's type and parameters (like sloinfo): a .sl path or a shader name.
    Info(InfoArgs),
    /// Pretty-print a RIB file in canonical form on stdout.
    Format { file: PathBuf },
    /// Render a shader on a swatch (sphere, plane or teapot) under a three-light rig.
    Shade(ShadeArgs),
    /// Build Max horizon tables (bump shadows) from a periodic height map (PNG/TIFF/EXR…).
    Horizon {
        /// Height map image (luminance is the height, the map spans the unit (s,t) patch).
        input: PathBuf,
        /// Output table file (.hzn).
        output: PathBuf,
        /// Azimuth directions: 8 or 16.
        #[arg(long, default_value_t = 8)]
        directions: usize,
    },
    /// Make a mip-mapped texture, bump, environment or shadow map (arbor's tiled .tex format).
    Texture(TextureArgs),
    /// Language server (LSP over stdin/stdout) for .sl and .rib files: diagnostics as you
    /// type, hover, completion, go-to-definition, outline, RIB formatting.
    Lsp {
        #[command(flatten)]
        paths: PathArgs,
    },
}

#[derive(Args)]
struct ShadeArgs {
    /// A shader name (search path or standard library) or a .sl file.
    shader: String,
    /// Set a shader parameter: -p Ks=0.8 -p "specularcolor=1 0.5 0" (repeatable).
    #[arg(short = 'p', value_name = "NAME=VALUE")]
    param: Vec<String>,
    /// The swatch object: sphere, plane or teapot.
    #[arg(long, default_value = "sphere")]
    object: String,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Pixel samples per side.
    #[arg(long, default_value_t = 3)]
    samples: u32,
    /// Output image (format from the extension: .png .tif .exr); default SHADER.png.
    #[arg(short, long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    paths: PathArgs,
}

#[derive(Args)]
struct TextureArgs {
    /// IN OUT: the input picture (PNG, TIFF, JPEG, HDR, EXR; a zfile with --shadow) and the
    /// output texture file; with --envcube only OUT.
    #[arg(required = true, num_args = 1..=2, value_names = ["IN", "OUT"])]
    paths: Vec<PathBuf>,
    /// Wrap mode for s and t: periodic, clamp or black.
    #[arg(long, default_value = "periodic")]
    wrap: String,
    /// Pyramid filter: box, triangle, catmull-rom, gaussian, sinc, mitchell, disk, bessel,
    /// b-spline.
    #[arg(long, default_value = "box")]
    filter: String,
    /// Filter width in s, in texels of each level made (default: the filter's own).
    #[arg(long)]
    swidth: Option<f32>,
    /// Filter width in t, in texels of each level made (default: the filter's own).
    #[arg(long)]
    twidth: Option<f32>,
    /// Make a bump map (heights and their slopes) for the shading language's bump().
    #[arg(long)]
    bump: bool,
    /// Make a lat-long environment map.
    #[arg(long)]
    envlatl: bool,
    /// Make a cube environment map from six faces: px nx py ny pz nz.
    #[arg(long, num_args = 6, value_names = ["PX", "NX", "PY", "NY", "PZ", "NZ"])]
    envcube: Option<Vec<PathBuf>>,
    /// Make a shadow map from a zfile.
    #[arg(long)]
    shadow: bool,
}

#[derive(Args)]
struct PathArgs {
    /// Shader search path (colon-separated), searched before the scene's own.
    #[arg(long, value_name = "PATH")]
    shaders: Option<String>,
    /// Texture search path (colon-separated).
    #[arg(long, value_name = "PATH")]
    textures: Option<String>,
    /// Archive search path (colon-separated).
    #[arg(long, value_name = "PATH")]
    archives: Option<String>,
    /// Include folder for shader #include (repeatable).
    #[arg(short = 'I', value_name = "DIR")]
    include: Vec<PathBuf>,
    /// Preprocessor define NAME or NAME=VALUE (repeatable).
    #[arg(short = 'D', value_name = "NAME[=VALUE]")]
    define: Vec<String>,
}

#[derive(Args)]
struct RenderArgs {
    /// RIB files ("-" or none: standard input).
    files: Vec<PathBuf>,
    #[command(flatten)]
    paths: PathArgs,
    /// Image resolution replacing Format.
    #[arg(long, num_args = 2, value_names = ["W", "H"])]
    res: Option<Vec<u32>>,
    /// Crop window in NDC replacing CropWindow.
    #[arg(long, num_args = 4, value_names = ["X0", "X1", "Y0", "Y1"], allow_negative_numbers = true)]
    crop: Option<Vec<f32>>,
    /// Frames to render: N or A-B.
    #[arg(long, value_name = "A-B")]
    frames: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Bucket size in pixels.
    #[arg(long)]
    bucket: Option<u32>,
    /// Output file replacing the first picture Display's (depth passes keep theirs; format from the extension).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Print time per stage and counts (grids, micropolygons, samples…).
    #[arg(long)]
    stats: bool,
    /// Render only tile I of N of each frame (1-based, row-major) into a tile file
    /// `DISPLAY.tileIofN.exr` next to the frame's first Display; `arbor merge` assembles them.
    #[arg(long, value_name = "I/N")]
    tile: Option<String>,
    /// Run the programs of `Procedural "RunProgram"` and load the libraries of
    /// `Procedural "DynamicLoad"` (off by default: a scene file is untrusted input; the
    /// environment variable ARBOR_ALLOW_PROGRAMS=1 does the same).
    #[arg(long)]
    allow_programs: bool,
    /// Seconds a RunProgram program may stay silent before it is killed (default 60).
    #[arg(long, value_name = "SECONDS")]
    program_timeout: Option<f32>,
}

#[derive(Args)]
struct MergeArgs {
    /// The RIB files the tiles were rendered from.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// How many tiles each frame was split into (`--tile I/N` of the renders).
    #[arg(long, value_name = "N")]
    tiles: u32,
    #[command(flatten)]
    paths: PathArgs,
    /// Image resolution replacing Format (as given to the renders).
    #[arg(long, num_args = 2, value_names = ["W", "H"])]
    res: Option<Vec<u32>>,
    /// Frames to merge: N or A-B.
    #[arg(long, value_name = "A-B")]
    frames: Option<String>,
    /// Output file replacing the first picture Display's (as given to the renders).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

#[derive(Args)]
struct JobArgs {
    /// The RIB file to render on the farm.
    scene: PathBuf,
    /// Tiles per frame.
    #[arg(long, value_name = "N", default_value_t = 1)]
    tiles: u32,
    /// Frames to render: N or A-B (default: every frame of the file).
    #[arg(long, value_name = "A-B")]
    frames: Option<String>,
    #[command(flatten)]
    paths: PathArgs,
    /// Image resolution replacing Format (passed to every render and merge task).
    #[arg(long, num_args = 2, value_names = ["W", "H"])]
    res: Option<Vec<u32>>,
    /// The arbor command on the workers (default: this executable's absolute path).
    #[arg(long, value_name = "CMD")]
    arbor: Option<String>,
    /// Folder the outputs go to on the farm (default: the current folder).
    #[arg(long, value_name = "DIR")]
    output_dir: Option<PathBuf>,
    /// Template file to write (default: standard output).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Let the render tasks run `Procedural "RunProgram"` programs and load `"DynamicLoad"`
    /// libraries (as `arbor render --allow-programs`; also used while reading the scene here).
    #[arg(long)]
    allow_programs: bool,
    /// Seconds a RunProgram program may stay silent before it is killed (render tasks).
    #[arg(long, value_name = "SECONDS")]
    program_timeout: Option<f32>,
}

#[derive(Args)]
struct CheckArgs {
    /// .rib and .sl files.
    #[arg(required = true)]
    files: Vec<PathBuf>,
    #[command(flatten)]
    paths: PathArgs,
}

#[derive(Args)]
struct InfoArgs {
    /// A .sl file or a shader name on the search path / in the standard library.
    shader: String,
    /// Also print the compiled IR listing (registers and instructions).
    #[arg(long)]
    ir: bool,
    #[command(flatten)]
    paths: PathArgs,
}

fn split_paths(p: &Option<String>) -> Vec<String> {
    p.as_deref()
        .map(|s| {
            s.split(':')
                .filter(|x| !x.is_empty())
                .map(String::from)
                .collect()
        })
        .unwrap_or_default()
}

fn defines(d: &[String]) -> Vec<(String, Option<String>)> {
    d.iter()
        .map(|s| match s.split_once('=') {
            Some((n, v)) => (n.to_string(), Some(v.to_string())),
            None => (s.clone(), None),
        })
        .collect()
}

fn settings_from(paths: &PathArgs) -> Settings {
    Settings {
        shader_paths: split_paths(&paths.shaders),
        texture_paths: split_paths(&paths.textures),
        archive_paths: split_paths(&paths.archives),
        include_dirs: paths.include.clone(),
        defines: defines(&paths.define),
        ..Settings::default()
    }
}

fn parse_frames(s: &str) -> Option<(i32, i32)> {
    match s.split_once('-') {
        Some((a, b)) => Some((a.trim().parse().ok()?, b.trim().parse().ok()?)),
        None => {
            let n = s.trim().parse().ok()?;
            Some((n, n))
        }
    }
}

/// `--frames` as a range; a bad value is a usage error (exit 2).
fn frames_arg(f: Option<&str>) -> Result<Option<(i32, i32)>, ExitCode> {
    match f {
        Some(f) => match parse_frames(f) {
            Some(r) => Ok(Some(r)),
            None => {
                eprintln!("error: --frames takes N or A-B, found `{f}`");
                Err(ExitCode::from(2))
            }
        },
        None => Ok(None),
    }
}

/// An absolute form of a path (the job runs elsewhere): canonical when it exists.
fn absolute(p: &std::path::Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| {
        std::env::current_dir()
            .map(|d| d.join(p))
            .unwrap_or_else(|_| p.to_path_buf())
    })
}

/// `arbor job`: reads the scene for its frame numbers and writes the OpenJD template.
fn job_cmd(
    a: JobArgs,
    sources: &SourceMap,
    diags: &Diagnostics,
    quiet: bool,
    verbose: bool,
) -> ExitCode {
    let mut s = settings_from(&a.paths);
    s.resolution = a.res.as_ref().and_then(|v| Some((*v.first()?, *v.get(1)?)));
    s.frames = match frames_arg(a.frames.as_deref()) {
        Ok(f) => f,
        Err(code) => return code,
    };
    if a.tiles == 0 {
        eprintln!("error: --tiles must be at least 1");
        return ExitCode::from(2);
    }
    s.allow_programs =
        a.allow_programs || std::env::var_os("ARBOR_ALLOW_PROGRAMS").is_some_and(|v| v == "1");
    s.program_timeout = a.program_timeout;
    if s.allow_programs {
        arbor::scene::ri_api::keep_exports();
    }
    let scenes = pipeline::load_scenes(&a.scene, &s, sources, diags);
    let mut frames: Vec<i32> = scenes
        .iter()
        .filter(|sc| !sc.jobs_only)
        .filter_map(|sc| sc.frame)
        .collect();
    frames.sort();
    frames.dedup();
    let unnumbered = scenes
        .iter()
        .filter(|sc| !sc.jobs_only && sc.frame.is_none())
        .count();
    if unnumbered > 0 && !frames.is_empty() {
        diags.report(Diag::warning(
            "farm::job",
            format!(
                "{unnumbered} world block(s) outside FrameBegin/FrameEnd: every task renders them"
            ),
        ));
    }
    if scenes
        .iter()
        .any(|sc| !sc.jobs_only && pipeline::depth_pass(sc))
    {
        diags.report(
            Diag::warning(
                "farm::job",
                "the scene has depth passes (zfile/shadow displays): each task renders its own \
                 frame only, so a later frame's MakeShadow does not see an earlier frame's map",
            )
            .help("render shadow maps first (arbor render) and ship them with the job"),
        );
    }
    if scenes.iter().all(|sc| sc.jobs_only) && !diags.has_errors() {
        diags.report(Diag::error(
            "farm::job",
            format!("`{}` has no frame to render", a.scene.display()),
        ));
    }
    // Settings the renders and merges must share, with absolute search paths.
    let mut args: Vec<String> = Vec::new();
    if let Some((w, h)) = s.resolution {
        args.extend(["--res".into(), w.to_string(), h.to_string()]);
    }
    let abs_list = |l: &[String]| -> String {
        l.iter()
            .map(|p| absolute(std::path::Path::new(p)).display().to_string())
            .collect::<Vec<_>>()
            .join(":")
    };
    for (flag, list) in [
        ("--shaders", &s.shader_paths),
        ("--textures", &s.texture_paths),
        ("--archives", &s.archive_paths),
    ] {
        if !list.is_empty() {
            args.extend([flag.to_string(), abs_list(list)]);
        }
    }
    for d in &s.include_dirs {
        args.extend(["-I".into(), absolute(d).display().to_string()]);
    }
    for (n, v) in &s.defines {
        args.extend([
            "-D".into(),
            match v {
                Some(v) => format!("{n}={v}"),
                None => n.clone(),
            },
        ]);
    }
    // OpenJD joins PATH defaults to the template's folder and wants them relative.
    let job_dir = match &a.output {
        Some(o) => absolute(
            o.parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(std::path::Path::new(".")),
        ),
        None => absolute(std::path::Path::new(".")),
    };
    let relative_default = |p: &std::path::Path, base: &std::path::Path| {
        arbor::farm::job::relative_to(p, base).unwrap_or_else(|| {
            diags.report(Diag::warning(
                "farm::job",
                format!(
                    "`{}` shares no root with the template's folder: its default stays \
                     absolute, which openjd refuses; pass -p with a value",
                    p.display()
                ),
            ));
            p.display().to_string()
        })
    };
    let spec = arbor::farm::job::JobSpec {
        name: arbor::farm::job::job_name(&a.scene, a.tiles),
        arbor: a.arbor.clone().unwrap_or_else(|| {
            std::env::current_exe()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|_| "arbor".into())
        }),
        scene: relative_default(&absolute(&a.scene), &job_dir),
        output_dir: relative_default(
            &absolute(a.output_dir.as_deref().unwrap_or(std::path::Path::new("."))),
            &job_dir,
        ),
        frames,
        tiles: a.tiles,
        settings_args: args,
        render_args: {
            let mut r = Vec::new();
            if s.allow_programs {
                r.push("--allow-programs".to_string());
            }
            if let Some(t) = a.program_timeout {
                r.extend(["--program-timeout".to_string(), t.to_string()]);
            }
            r
        },
    };
    let failed = report(diags, sources, quiet, verbose);
    if failed {
        return ExitCode::from(1);
    }
    let text = arbor::farm::job::template(&spec);
    match &a.output {
        Some(o) => {
            if let Err(d) = arbor::film::write_atomically(o, |f| {
                std::io::Write::write_all(f, text.as_bytes()).map_err(|e| e.to_string())
            }) {
                diags.report(d);
                report(diags, sources, quiet, verbose);
                return ExitCode::from(1);
            }
            if !quiet {
                eprintln!("wrote {}", o.display());
            }
        }
        None => emit(&text),
    }
    ExitCode::SUCCESS
}

/// Writes `text` to standard output. A reader that stops early (`arbor info x | head`) closes
/// the pipe: that ends the output quietly, as for other command-line tools, instead of
/// panicking as `print!` does.
fn emit(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes()).and_then(|_| out.flush());
}

/// Prints every diagnostic (warnings only unless quiet, notes only when verbose) and returns
/// whether errors occurred.
fn report(diags: &Diagnostics, sources: &SourceMap, quiet: bool, verbose: bool) -> bool {
    let all = diags.snapshot();
    let mut errors = 0;
    let mut warnings = 0;
    for (d, count) in &all {
        match d.severity {
            Severity::Error => errors += 1,
            Severity::Warning => {
                warnings += 1;
                if quiet {
                    continue;
                }
            }
            Severity::Note => {
                if quiet || !verbose {
                    continue;
                }
            }
        }
        // Rendered whole, then written at once: stderr is unbuffered, and the report's
        // formatter writes a character at a time (a system call each).
        let text = format!("{:?}", d.to_report(sources, *count));
        eprintln!("{text}");
    }
    if !quiet && (errors > 0 || warnings > 0) {
        eprintln!("{errors} error(s), {warnings} warning(s)");
    }
    errors > 0
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(dir) = &cli.directory {
        if let Err(e) = std::fs::create_dir_all(dir).and_then(|_| std::env::set_current_dir(dir)) {
            eprintln!(
                "error: cannot change to folder `{}` (-C): {e}",
                dir.display()
            );
            return ExitCode::from(2);
        }
    }
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    match cli.cmd {
        Cmd::Merge(a) => {
            let mut s = settings_from(&a.paths);
            s.resolution = a.res.as_ref().and_then(|v| Some((*v.first()?, *v.get(1)?)));
            s.frames = match frames_arg(a.frames.as_deref()) {
                Ok(f) => f,
                Err(code) => return code,
            };
            s.output = a.output.clone();
            if a.tiles == 0 {
                eprintln!("error: --tiles must be at least 1");
                return ExitCode::from(2);
            }
            let written = arbor::farm::merge::merge_paths(&a.files, &s, a.tiles, &sources, &diags);
            let failed = report(&diags, &sources, cli.quiet, cli.verbose);
            if !cli.quiet {
                for w in &written {
                    eprintln!("wrote {}", w.display());
                }
            }
            if failed {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Cmd::Job(a) => job_cmd(a, &sources, &diags, cli.quiet, cli.verbose),
        Cmd::Render(a) => {
            let mut s = settings_from(&a.paths);
            s.resolution = a.res.as_ref().and_then(|v| Some((*v.first()?, *v.get(1)?)));
            s.crop = a
                .crop
                .as_ref()
                .and_then(|v| (v.len() == 4).then(|| [v[0], v[1], v[2], v[3]]));
            s.frames = match frames_arg(a.frames.as_deref()) {
                Ok(f) => f,
                Err(code) => return code,
            };
            s.tile = match a.tile.as_deref().map(arbor::farm::TileSpec::parse) {
                Some(Ok(t)) => Some(t),
                Some(Err(e)) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(2);
                }
                None => None,
            };
            s.threads = a.threads;
            s.bucket_size = a.bucket.map(|b| [b.max(1), b.max(1)]);
            s.output = a.output.clone();
            s.stats = a.stats;
            s.allow_programs = a.allow_programs
                || std::env::var_os("ARBOR_ALLOW_PROGRAMS").is_some_and(|v| v == "1");
            s.program_timeout = a.program_timeout;
            // DynamicLoad libraries call back into the RI functions this binary exports.
            arbor::scene::ri_api::keep_exports();
            s.progress = !cli.quiet && std::io::IsTerminal::is_terminal(&std::io::stderr());
            if s.threads > 0 {
                let _ = rayon::ThreadPoolBuilder::new()
                    .num_threads(s.threads)
                    .build_global();
            }
            let files = if a.files.is_empty() {
                vec![PathBuf::from("-")]
            } else {
                a.files.clone()
            };
            let written = pipeline::render_paths(&files, &s, &sources, &diags);
            let failed = report(&diags, &sources, cli.quiet, cli.verbose);
            if !cli.quiet {
                for w in &written {
                    eprintln!("wrote {}", w.display());
                }
            }
            if failed {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Cmd::Check(a) => {
            let s = settings_from(&a.paths);
            for f in &a.files {
                let is_sl = f
                    .extension()
                    .map(|e| e == "sl" || e == "h")
                    .unwrap_or(false);
                if is_sl {
                    match arbor::encoding::read_text(f) {
                        Ok(text) => {
                            let opts = CompileOptions {
                                include_dirs: s.include_dirs.clone(),
                                defines: s.defines.clone(),
                                search_paths: s.shader_paths.iter().map(PathBuf::from).collect(),
                            };
                            let progs = compile_source(
                                &f.display().to_string(),
                                &text,
                                Some(f),
                                &sources,
                                &diags,
                                &opts,
                            );
                            if !cli.quiet {
                                for p in &progs {
                                    eprintln!(
                                        "{}: {} shader `{}` compiled ({} instructions)",
                                        f.display(),
                                        p.kind.name(),
                                        p.name,
                                        p.instr_count()
                                    );
                                }
                            }
                        }
                        Err(e) => diags.report(Diag::error(
                            "sl::io",
                            format!("cannot read `{}`: {e}", f.display()),
                        )),
                    }
                } else {
                    let scenes = pipeline::load_scenes(f, &s, &sources, &diags);
                    // Compile every shader the scenes name, as a render would.
                    for scene in &scenes {
                        let lib = pipeline::library_for(scene, &s);
                        for n in pipeline::shader_names(scene) {
                            lib.get(&n, &sources, &diags);
                        }
                    }
                    if !cli.quiet {
                        eprintln!("{}: {} frame(s)", f.display(), scenes.len());
                    }
                }
            }
            if report(&diags, &sources, cli.quiet, cli.verbose) {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Cmd::Info(a) => {
            let s = settings_from(&a.paths);
            let opts = CompileOptions {
                include_dirs: s.include_dirs.clone(),
                defines: s.defines.clone(),
                search_paths: s.shader_paths.iter().map(PathBuf::from).collect(),
            };
            let prog = if a.shader.ends_with(".sl") {
                match arbor::encoding::read_text(std::path::Path::new(&a.shader)) {
                    Ok(text) => compile_source(
                        &a.shader,
                        &text,
                        Some(a.shader.as_ref()),
                        &sources,
                        &diags,
                        &opts,
                    )
                    .into_iter()
                    .next(),
                    Err(e) => {
                        diags.report(Diag::error(
                            "sl::io",
                            format!("cannot read `{}`: {e}", a.shader),
                        ));
                        None
                    }
                }
            } else {
                arbor::sl::ShaderLibrary::new(opts)
                    .get(&a.shader, &sources, &diags)
                    .map(|p| (*p).clone())
            };
            let failed = report(&diags, &sources, cli.quiet, cli.verbose);
            match prog {
                Some(p) => {
                    use std::fmt::Write as _;
                    let mut text = format!("{} \"{}\"\n", p.kind.name(), p.name);
                    for par in &p.params {
                        let arr = par.array.map(|n| format!("[{n}]")).unwrap_or_default();
                        let _ = writeln!(
                            text,
                            "    \"{}\" \"{}{} {}{}\"",
                            par.name,
                            if par.output { "output " } else { "" },
                            if par.varying { "varying" } else { "uniform" },
                            par.ty.name(),
                            arr
                        );
                        let _ = writeln!(text, "\t\tDefault value: {}", par.default_text);
                    }
                    if a.ir {
                        let _ = writeln!(text, "{p}");
                    }
                    emit(&text);
                    if failed {
                        ExitCode::from(1)
                    } else {
                        ExitCode::SUCCESS
                    }
                }
                None => ExitCode::from(1),
            }
        }
        Cmd::Shade(a) => {
            let s = settings_from(&a.paths);
            let Some(object) = arbor::swatch::SwatchObject::parse(&a.object) else {
                eprintln!(
                    "error: --object takes sphere, plane or teapot, found `{}`",
                    a.object
                );
                return ExitCode::from(2);
            };
            let stem = std::path::Path::new(&a.shader)
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or_else(|| "swatch".into());
            let req = arbor::swatch::SwatchRequest {
                shader: a.shader.clone(),
                params: a.param.clone(),
                object,
                size: a.size,
                samples: a.samples,
                output: a
                    .output
                    .clone()
                    .unwrap_or_else(|| PathBuf::from(format!("{stem}.png"))),
                compile: CompileOptions {
                    include_dirs: s.include_dirs.clone(),
                    defines: s.defines.clone(),
                    search_paths: s.shader_paths.iter().map(PathBuf::from).collect(),
                },
            };
            let start = std::time::Instant::now();
            let written = arbor::swatch::render_swatch(&req, &sources, &diags);
            let failed = report(&diags, &sources, cli.quiet, cli.verbose);
            if !cli.quiet {
                for w in &written {
                    eprintln!(
                        "wrote {} ({:.2} s)",
                        w.display(),
                        start.elapsed().as_secs_f64()
                    );
                }
            }
            if failed || written.is_empty() {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            }
        }
        Cmd::Horizon {
            input,
            output,
            directions,
        } => {
            use arbor::texture::horizon::{read_height_image, HorizonTable};
            let start = std::time::Instant::now();
            let built = read_height_image(&input).and_then(|(f, w, h)| {
                HorizonTable::build(&f, w, h, directions).map(|t| (t, start.elapsed()))
            });
            match built.and_then(|(t, dt)| t.write(&output).map(|_| (t, dt))) {
                Ok((t, dt)) => {
                    if !cli.quiet {
                        eprintln!(
                            "{}: {}x{} texels, {} directions, built in {:.2} s",
                            output.display(),
                            t.width,
                            t.height,
                            t.ndirs(),
                            dt.as_secs_f64()
                        );
                    }
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    diags.report(Diag::error("texture::horizon", e).help(
                        "the input must be a readable height image; --directions is 8 or 16",
                    ));
                    report(&diags, &sources, cli.quiet, cli.verbose);
                    ExitCode::from(1)
                }
            }
        }
        Cmd::Texture(a) => texture_cmd(a),
        Cmd::Lsp { paths } => {
            let code = arbor::lsp::run_stdio(settings_from(&paths));
            ExitCode::from(code.clamp(0, 255) as u8)
        }
        Cmd::Format { file } => match arbor::rib::read_path(&file, &sources, &diags) {
            Ok(reqs) => {
                // The text the requests were read from (decoded, for binary RIB): comments kept.
                let text = sources.get(0).map(|f| f.text.clone()).unwrap_or_default();
                emit(&arbor::rib::format_source(&text, &reqs));
                if report(&diags, &sources, cli.quiet, cli.verbose) {
                    ExitCode::from(1)
                } else {
                    ExitCode::SUCCESS
                }
            }
            Err(d) => {
                diags.report(d);
                report(&diags, &sources, cli.quiet, cli.verbose);
                ExitCode::from(1)
            }
        },
    }
}

/// `arbor texture`: one conversion, errors on stderr.
fn texture_cmd(a: TextureArgs) -> ExitCode {
    use arbor::texture::make;
    use arbor::texture::mipmap::Wrap;
    let Some(wrap) = Wrap::parse(&a.wrap) else {
        eprintln!(
            "error: --wrap takes periodic, clamp or black, found `{}`",
            a.wrap
        );
        return ExitCode::from(2);
    };
    let Some(filter) = make::downsample_for(&a.filter) else {
        eprintln!(
            "error: --filter `{}` is not known (box, triangle, catmull-rom, gaussian, sinc, mitchell, disk, bessel, b-spline)",
            a.filter
        );
        return ExitCode::from(2);
    };
    for (flag, w) in [("--swidth", a.swidth), ("--twidth", a.twidth)] {
        if let Some(w) = w {
            if !(w.is_finite() && (1.0..=16.0).contains(&w)) {
                eprintln!("error: {flag} takes a width from 1 to 16 texels, found {w}");
                return ExitCode::from(2);
            }
        }
    }
    let o = make::MakeOptions {
        swrap: wrap,
        twrap: wrap,
        filter,
        swidth: a.swidth.unwrap_or(0.0),
        twidth: a.twidth.unwrap_or(0.0),
    };
    // With --envcube the six faces are the inputs and the one positional is the output.
    let output = a.paths.last().expect("clap requires a path").clone();
    let r = if let Some(faces) = &a.envcube {
        if a.paths.len() != 1 {
            eprintln!(
                "error: with --envcube give only the output file (the faces follow --envcube)"
            );
            return ExitCode::from(2);
        }
        make::make_cube(faces, &output, &o)
    } else {
        let [input, _] = a.paths.as_slice() else {
            eprintln!("error: arbor texture IN OUT needs an input picture and an output file");
            return ExitCode::from(2);
        };
        if a.shadow {
            make::make_shadow(input, &output)
        } else if a.envlatl {
            make::make_latlong(input, &output, &o)
        } else if a.bump {
            make::make_bump(input, &output, &o)
        } else {
            make::make_texture(input, &output, &o)
        }
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}
