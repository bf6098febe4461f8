//! `arbor merge`: tile files → each Display's final picture.
//!
//! Input: the RIB file the tiles were rendered from, the same command-line settings, and the
//! tile count N. Output: the frames' display files, written by the same code as a direct
//! render (so PNG, TIFF, EXR with every output variable, zfile and shadow all come out
//! byte-identical to it). Invariants: a frame is written only when all N tiles are present,
//! each covers exactly the pixels its index names at the scene's resolution, every tile has
//! the film channels of tile 1, and every tile's settings hash equals the one this scene and
//! these settings give; otherwise the frame gets one diagnostic per problem and no file (the
//! display writer renames finished temporary files into place, so nothing partial remains).

use std::path::{Path, PathBuf};

use super::tile::{self, TileFile, TileSpec};
use crate::diag::{Diag, Diagnostics, SourceMap, Span};
use crate::film::Film;
use crate::pipeline::{self, Settings};
use crate::render::driver::{effective_options, RenderOptions};
use crate::render::PixelRect;
use crate::scene::Scene;

/// Merges the tiles of every frame of every file. Returns the files written.
pub fn merge_paths(
    paths: &[PathBuf],
    settings: &Settings,
    count: u32,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<PathBuf> {
    let mut written = Vec::new();
    let mut first_display = true;
    for path in paths {
        let first_source = sources.len() as u32;
        let scenes = pipeline::load_scenes(path, settings, sources, diags);
        let scene_sources = first_source..sources.len() as u32;
        if scenes.iter().all(|s| s.jobs_only) && !diags.has_errors() {
            diags.report(Diag::warning(
                "farm::merge",
                format!("`{}` has no frame to merge", path.display()),
            ));
        }
        for scene in &scenes {
            if scene.jobs_only {
                continue;
            }
            let override_path = pipeline::output_override(scene, settings, &mut first_display);
            // Depth passes are rendered whole by every tile task (`arbor render --tile`).
            if pipeline::depth_pass(scene) {
                continue;
            }
            let hash = super::settings_hash(sources, scene_sources.clone(), settings, scene.frame);
            if let Some((film, imager_applied)) = assemble(
                path,
                scene,
                settings,
                count,
                hash,
                override_path.as_deref(),
                diags,
            ) {
                let opts = RenderOptions {
                    resolution: settings.resolution,
                    ..RenderOptions::default()
                };
                let mut options = effective_options(&scene.options, &opts);
                if imager_applied {
                    options.imager = None;
                }
                written.extend(pipeline::write_frame(
                    scene,
                    film,
                    &options,
                    override_path.as_deref(),
                    diags,
                ));
            }
        }
    }
    written
}

/// The frame's label in messages.
fn frame_name(scene: &Scene) -> String {
    scene
        .frame
        .map_or_else(|| "the frame".into(), |f| format!("frame {f}"))
}

/// The Display request a frame's messages point at.
fn display_span(scene: &Scene) -> Option<Span> {
    scene.options.displays.first().map(|d| d.span)
}

fn labelled(d: Diag, span: Option<Span>, text: &str) -> Diag {
    match span {
        Some(s) if s != Span::default() => d.label(s, text),
        _ => d,
    }
}

/// Reads and checks the N tiles of one frame and places them in a full-resolution film.
/// None (with diagnostics) when any tile is missing or does not belong.
fn assemble(
    file: &Path,
    scene: &Scene,
    settings: &Settings,
    count: u32,
    hash: u64,
    override_path: Option<&Path>,
    diags: &Diagnostics,
) -> Option<(Film, bool)> {
    let frame = frame_name(scene);
    let span = display_span(scene);
    let opts = RenderOptions {
        resolution: settings.resolution,
        ..RenderOptions::default()
    };
    let display = pipeline::tile_display(scene, override_path);
    let rerender = |i: u32| {
        let mut cmd = format!("arbor render {}", file.display());
        if let Some(f) = scene.frame {
            cmd += &format!(" --frames {f}");
        }
        format!("`{cmd} --tile {i}/{count}` with the other settings of this merge")
    };
    let mut tiles: Vec<(TileSpec, PathBuf, PixelRect)> = Vec::new();
    for index in 1..=count {
        let spec = TileSpec { index, count };
        match pipeline::tile_plan(scene, &opts, spec) {
            Ok(plan) => tiles.push((spec, tile::path(&display, spec), plan.rect)),
            Err(d) => {
                diags.report(d);
                return None;
            }
        }
    }
    let missing: Vec<&(TileSpec, PathBuf, PixelRect)> =
        tiles.iter().filter(|(_, p, _)| !p.exists()).collect();
    if !missing.is_empty() {
        let names: Vec<String> = missing
            .iter()
            .map(|(_, p, _)| format!("`{}`", p.display()))
            .collect();
        diags.report(labelled(
            Diag::error(
                "farm::missing-tile",
                format!(
                    "{frame}: {} of {count} tiles missing ({}); nothing written",
                    missing.len(),
                    names.join(", ")
                ),
            )
            .help(format!(
                "render them first, e.g. {}",
                rerender(missing[0].0.index)
            )),
            span,
            "the tiles are named after this Display",
        ));
        return None;
    }
    let o = effective_options(&scene.options, &opts);
    let mut film: Option<Film> = None;
    let mut imager = None;
    let mut ok = true;
    for (spec, path, rect) in &tiles {
        let t = match tile::read(path) {
            Ok(t) => t,
            Err(d) => {
                diags.report(d);
                ok = false;
                continue;
            }
        };
        if let Some(problem) = mismatch(&t, scene, *spec, *rect, (o.xres, o.yres), hash) {
            diags.report(labelled(
                Diag::error(
                    problem.0,
                    format!(
                        "{frame}: tile `{}` does not belong to this merge: {}; nothing written",
                        path.display(),
                        problem.1
                    ),
                )
                .help(format!("render it again: {}", rerender(spec.index))),
                span,
                "for this Display",
            ));
            ok = false;
            continue;
        }
        let f = film.get_or_insert_with(|| {
            Film::new(o.xres as usize, o.yres as usize, t.meta.channels.clone())
        });
        if f.channel_names != t.meta.channels {
            diags.report(labelled(
                Diag::error(
                    "farm::tile-channels",
                    format!(
                        "{frame}: tile `{}` holds channels [{}], the first tile [{}]; nothing written",
                        path.display(),
                        t.meta.channels.join(" "),
                        f.channel_names.join(" ")
                    ),
                )
                .help(format!("render it again: {}", rerender(spec.index))),
                span,
                "for this Display",
            ));
            ok = false;
            continue;
        }
        // Same scene text (the hash) → the same Imager on every tile.
        imager.get_or_insert(t.meta.imager_applied);
        place(f, &t);
    }
    if !ok {
        return None;
    }
    Some((film?, imager.unwrap_or(false)))
}

/// Why a tile does not belong to this frame's merge: (diagnostic code, what differs).
fn mismatch(
    t: &TileFile,
    scene: &Scene,
    spec: TileSpec,
    rect: PixelRect,
    res: (u32, u32),
    hash: u64,
) -> Option<(&'static str, String)> {
    let m = &t.meta;
    let frame =
        |f: Option<i32>| f.map_or_else(|| "no frame number".into(), |f| format!("frame {f}"));
    if m.frame != scene.frame {
        return Some(("farm::tile-frame", format!("it holds {}", frame(m.frame))));
    }
    if m.tile != spec {
        return Some((
            "farm::tile-index",
            format!(
                "it is tile {}/{}, not {}/{}",
                m.tile.index, m.tile.count, spec.index, spec.count
            ),
        ));
    }
    if (m.xres, m.yres) != res {
        return Some((
            "farm::tile-size",
            format!(
                "it was rendered at {}×{}, the scene is {}×{}",
                m.xres, m.yres, res.0, res.1
            ),
        ));
    }
    let stored = PixelRect {
        x0: t.position.0,
        y0: t.position.1,
        x1: t.position.0 + t.width as i32,
        y1: t.position.1 + t.height as i32,
    };
    if m.rect != rect || stored != rect {
        return Some((
            "farm::tile-size",
            format!(
                "it holds pixels {}..{} × {}..{} ({}×{}), tile {} of {count} is {}..{} × {}..{} ({}×{})",
                stored.x0,
                stored.x1,
                stored.y0,
                stored.y1,
                t.width,
                t.height,
                spec.index,
                rect.x0,
                rect.x1,
                rect.y0,
                rect.y1,
                rect.width(),
                rect.height(),
                count = spec.count,
            ),
        ));
    }
    if m.settings != hash {
        return Some((
            "farm::tile-settings",
            format!(
                "it was rendered with different settings or scene text (settings hash {:016x}, \
                 this scene and these settings give {hash:016x})",
                m.settings
            ),
        ));
    }
    None
}

/// Copies a checked tile's pixels into the full film.
fn place(film: &mut Film, t: &TileFile) {
    let n = film.channels();
    let (x0, y0) = (t.position.0 as usize, t.position.1 as usize);
    for j in 0..t.height {
        let dst = ((y0 + j) * film.width + x0) * n;
        let src = j * t.width * n;
        film.data[dst..dst + t.width * n].copy_from_slice(&t.data[src..src + t.width * n]);
    }
}
