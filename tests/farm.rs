//! Frames × tiles on a farm, through the real binary: `arbor render --tile`, `arbor merge`,
//! `arbor job`, and the generated Open Job Description template run by `openjd run` (the
//! `openjd-cli` Python package, installed into a virtual environment under the target folder
//! on first use; `.ci/run` installs it beforehand and sets `ARBOR_OPENJD`).
//!
//! What must hold: merged frames equal a direct render byte for byte (PNG, 16-bit TIFF, EXR
//! with rgbaz and with output variables); missing tiles, tiles of another size and tiles
//! rendered with other settings are errors with a diagnostic, and leave no picture behind.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn arbor() -> Command {
    Command::new(env!("CARGO_BIN_EXE_arbor"))
}

fn tmpdir(name: &str) -> common::Scratch {
    common::scratch(&format!("farm-{name}"))
}

/// A shader with two output variables (a colour and a float).
const SHADER: &str = r#"
surface farmaov(float Kd = 0.8; output varying color diffusecol = 0;
                output varying float facing = 0;)
{
    normal Nf = faceforward(normalize(N), I);
    diffusecol = Cs * diffuse(Nf);
    facing = abs(normalize(I) . Nf);
    Oi = Os;
    Ci = Os * (Kd * diffusecol + 0.1 * Cs);
}
"#;

/// Two 64×48 frames; a wide gaussian filter (2-pixel margins across tile borders), jittered
/// samples, dithered 8-bit PNG, 16-bit TIFF, an rgbaz EXR and output-variable EXRs.
fn scene(samples: u32) -> String {
    let frame = |n: u32, dx: f32| {
        format!(
            r#"FrameBegin {n}
Format 64 48 1
PixelSamples {samples} {samples}
PixelFilter "gaussian" 3 3
Display "farm{n}.png" "file" "rgba"
Display "+farm{n}.tif" "tiff" "rgb" "quantize" [0 65535 0 65535]
Display "+farm{n}.exr" "exr" "rgbaz"
Display "+farm{n}_diffuse.exr" "exr" "diffusecol"
Display "+farm{n}_facing.exr" "exr" "float facing" "string type" "float"
Projection "perspective" "fov" 40
Translate 0 0 5
WorldBegin
LightSource "distantlight" 1 "from" [-1 1 -1] "to" [0 0 0]
LightSource "ambientlight" 2 "intensity" 0.2
AttributeBegin
  Translate {dx} 0 0
  Color [1 0.4 0.2]
  Surface "farmaov"
  Sphere 1.1 -1.1 1.1 360
AttributeEnd
AttributeBegin
  Translate 0.8 -0.3 -1.2
  Color [0.3 0.6 1]
  Opacity [0.6 0.6 0.6]
  Surface "plastic"
  Sphere 0.45 -0.45 0.45 360
AttributeEnd
WorldEnd
FrameEnd
"#
        )
    };
    format!("{}{}", frame(1, -0.3), frame(2, 0.4))
}

fn pictures(frame: u32) -> Vec<String> {
    ["png", "tif", "exr"]
        .iter()
        .map(|e| format!("farm{frame}.{e}"))
        .chain([
            format!("farm{frame}_diffuse.exr"),
            format!("farm{frame}_facing.exr"),
        ])
        .collect()
}

fn write_scene(dir: &Path, samples: u32) {
    std::fs::write(dir.join("scene.rib"), scene(samples)).unwrap();
    std::fs::write(dir.join("farmaov.sl"), SHADER).unwrap();
}

fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    out
}

fn ok(cmd: &mut Command) -> Output {
    let out = run(cmd);
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A direct render of both frames in `dir`.
fn direct(dir: &Path) {
    write_scene(dir, 3);
    ok(arbor().current_dir(dir).args(["-q", "render", "scene.rib"]));
    for f in [1, 2] {
        for p in pictures(f) {
            assert!(dir.join(&p).exists(), "direct render wrote no {p}");
        }
    }
}

fn same_files(a: &Path, b: &Path, frames: &[u32]) {
    for &f in frames {
        for p in pictures(f) {
            let (x, y) = (
                std::fs::read(a.join(&p)).unwrap(),
                std::fs::read(b.join(&p)).unwrap(),
            );
            assert!(x == y, "{p}: merged tiles differ from the direct render");
        }
    }
}

/// Files in `dir` that are neither inputs nor tiles (pictures, temporaries).
fn outputs(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != "scene.rib" && n != "farmaov.sl" && !n.contains(".tile"))
        .collect();
    v.sort();
    v
}

#[test]
fn merged_tiles_equal_a_direct_render() {
    let a = tmpdir("direct");
    direct(&a);
    // Three tiles (3×1 strips), odd bucket sizes and one thread: nothing of it may show.
    let b = tmpdir("tiles");
    write_scene(&b, 3);
    for (i, bucket) in [(1, "5"), (2, "16"), (3, "7")] {
        ok(arbor().current_dir(&b).args([
            "-q",
            "render",
            "scene.rib",
            "--tile",
            &format!("{i}/3"),
            "--bucket",
            bucket,
            "--threads",
            "1",
        ]));
    }
    assert!(b.join("farm1.tile2of3.exr").exists());
    assert!(
        outputs(&b).is_empty(),
        "tiles wrote pictures: {:?}",
        outputs(&b)
    );
    let out = ok(arbor()
        .current_dir(&b)
        .args(["merge", "scene.rib", "--tiles", "3"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("wrote farm2_facing.exr"), "{err}");
    same_files(&a, &b, &[1, 2]);
    // The picture is not trivial: the spheres cross the tile borders.
    let png = std::fs::read(a.join("farm1.png")).unwrap();
    assert!(png.len() > 1000);
}

#[test]
fn merge_refuses_missing_tiles() {
    let d = tmpdir("missing");
    write_scene(&d, 3);
    for i in [1, 3] {
        ok(arbor().current_dir(&d).args([
            "-q",
            "render",
            "scene.rib",
            "--frames",
            "1",
            "--tile",
            &format!("{i}/4"),
        ]));
    }
    let out =
        run(arbor()
            .current_dir(&d)
            .args(["merge", "scene.rib", "--frames", "1", "--tiles", "4"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("farm::missing-tile"), "{err}");
    assert!(err.contains("2 of 4 tiles missing"), "{err}");
    assert!(
        err.contains("farm1.tile2of4.exr") && err.contains("farm1.tile4of4.exr"),
        "{err}"
    );
    assert!(
        err.contains("--tile 2/4"),
        "the help says how to render it: {err}"
    );
    assert!(outputs(&d).is_empty(), "left behind: {:?}", outputs(&d));
}

#[test]
fn merge_refuses_tiles_of_another_size() {
    let d = tmpdir("size");
    write_scene(&d, 3);
    for i in 1..=4 {
        ok(arbor().current_dir(&d).args([
            "-q",
            "render",
            "scene.rib",
            "--frames",
            "2",
            "--tile",
            &format!("{i}/4"),
        ]));
    }
    // Tile 3 again at another resolution: its pixels no longer fit the picture.
    ok(arbor().current_dir(&d).args([
        "-q",
        "render",
        "scene.rib",
        "--frames",
        "2",
        "--tile",
        "3/4",
        "--res",
        "32",
        "24",
    ]));
    let out =
        run(arbor()
            .current_dir(&d)
            .args(["merge", "scene.rib", "--frames", "2", "--tiles", "4"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("farm::tile-size"), "{err}");
    assert!(err.contains("farm2.tile3of4.exr"), "{err}");
    assert!(err.contains("32×24") && err.contains("64×48"), "{err}");
    assert!(outputs(&d).is_empty(), "left behind: {:?}", outputs(&d));
    // A tile file whose pixels were cut down (same header claims) is refused too.
    std::fs::copy(d.join("farm2.tile1of4.exr"), d.join("farm2.tile3of4.exr")).unwrap();
    let out =
        run(arbor()
            .current_dir(&d)
            .args(["merge", "scene.rib", "--frames", "2", "--tiles", "4"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("farm::tile-index"), "{err}");
    assert!(outputs(&d).is_empty(), "left behind: {:?}", outputs(&d));
}

#[test]
fn merge_refuses_tiles_rendered_with_other_settings() {
    let d = tmpdir("settings");
    write_scene(&d, 3);
    for i in [1, 2, 4] {
        ok(arbor().current_dir(&d).args([
            "-q",
            "render",
            "scene.rib",
            "--frames",
            "1",
            "--tile",
            &format!("{i}/4"),
        ]));
    }
    // Tile 3 from an edited scene (fewer pixel samples), then the scene as it was.
    write_scene(&d, 2);
    ok(arbor().current_dir(&d).args([
        "-q",
        "render",
        "scene.rib",
        "--frames",
        "1",
        "--tile",
        "3/4",
    ]));
    write_scene(&d, 3);
    let out =
        run(arbor()
            .current_dir(&d)
            .args(["merge", "scene.rib", "--frames", "1", "--tiles", "4"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("farm::tile-settings"), "{err}");
    assert!(err.contains("farm1.tile3of4.exr"), "{err}");
    assert!(
        !err.contains("farm1.tile1of4.exr"),
        "only tile 3 differs: {err}"
    );
    assert!(outputs(&d).is_empty(), "left behind: {:?}", outputs(&d));
    // A shader define given to the merge but not to the renders differs as well.
    let out = run(arbor().current_dir(&d).args([
        "merge",
        "scene.rib",
        "--frames",
        "1",
        "--tiles",
        "4",
        "-D",
        "X=1",
    ]));
    assert_eq!(out.status.code(), Some(1));
    assert!(outputs(&d).is_empty());
}

/// The `openjd` command: `$ARBOR_OPENJD`, or a virtual environment under the target folder,
/// made with `python3 -m venv` and the pinned requirements on first use. Without Python or
/// network this fails loudly: the farm test is never skipped.
fn openjd() -> PathBuf {
    if let Some(p) = std::env::var_os("ARBOR_OPENJD") {
        return PathBuf::from(p);
    }
    let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("openjd-venv");
    let bin = venv.join("bin").join("openjd");
    // Written after a complete install: an interrupted one is made again.
    let done = venv.join("arbor-installed");
    if done.exists() && bin.exists() {
        return bin;
    }
    let _ = std::fs::remove_dir_all(&venv);
    let req = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/farm/requirements.txt");
    match Command::new("python3")
        .args(["-m", "venv"])
        .arg(&venv)
        .output()
    {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "cannot make a Python virtual environment for openjd-cli (python3 -m venv): {}",
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => panic!("the farm test needs python3 (for openjd-cli): {e}"),
    }
    let pip = Command::new(venv.join("bin").join("pip"))
        .args(["install", "--quiet", "--disable-pip-version-check", "-r"])
        .arg(&req)
        .output()
        .unwrap();
    assert!(
        pip.status.success(),
        "pip could not install openjd-cli (is PyPI reachable?):\n{}",
        String::from_utf8_lossy(&pip.stderr)
    );
    assert!(
        bin.exists(),
        "pip installed openjd-cli but {} is missing",
        bin.display()
    );
    std::fs::write(&done, "").unwrap();
    bin
}

#[test]
fn openjd_runs_the_job_and_reproduces_a_direct_render() {
    let a = tmpdir("oj-direct");
    direct(&a);
    let work = tmpdir("oj-job");
    write_scene(&work, 3);
    let out_dir = work.join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let job = work.join("job.yaml");
    ok(arbor().current_dir(&work).args([
        "job",
        "scene.rib",
        "--tiles",
        "4",
        "--frames",
        "1-2",
        "--output-dir",
        "out",
        "-o",
        "job.yaml",
    ]));
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(
        text.contains("specificationVersion: 'jobtemplate-2023-09'"),
        "{text}"
    );
    let oj = openjd();
    ok(Command::new(&oj).arg("check").arg(&job));
    let out =
        ok(Command::new(&oj)
            .arg("run")
            .arg(&job)
            .args(["--step", "Merge", "--run-dependencies"]));
    let log = String::from_utf8_lossy(&out.stdout);
    // 2 frames × 4 tiles, then 2 merges.
    for f in [1, 2] {
        for t in 1..=4 {
            assert!(
                out_dir.join(format!("farm{f}.tile{t}of4.exr")).exists(),
                "no tile {t} of frame {f}:\n{log}"
            );
        }
    }
    same_files(&a, &out_dir, &[1, 2]);
}
