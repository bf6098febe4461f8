//! Procedural primitives (RISpec 3.2 §5.8): `Procedural "DelayedReadArchive"`, `"RunProgram"`
//! and `"DynamicLoad"`.
//!
//! Input: the `Procedural` request (its kind, string arguments and object-space bound) and the
//! current graphics state. Output: the primitives the procedural generates, emitted as if
//! their requests stood where the `Procedural` does, inside an implicit attribute block.
//! Invariants: a procedural is expanded while the scene is built, once, in request order (so
//! the output is the same for any thread count or bucket size), unless its bound is out of
//! view: behind the eye, beyond the far clipping plane, or off the image (by more than the
//! pixel filter and the circle of confusion) when nothing moves and its attributes do not ask
//! for ray visibility (`Attribute "visibility" "trace"/"transmission"`, `"render"
//! "visibility"`/`"casts_shadows"`). The detail passed to the generator is the raster area of
//! its bound (1e38, RI_INFINITY, when the bound reaches the eye plane). RunProgram and
//! DynamicLoad run code named by the scene, so they run only when the build is allowed to
//! ([`super::builder::ProceduralSettings::allow`]); otherwise each warns and is skipped.
//! A procedural's output cannot close blocks opened outside it; blocks it leaves open are
//! closed (and reported) at its end; problems in its output are reported at the output, with
//! a help line naming the `Procedural` request.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::diag::{Diag, Span};
use crate::render::Camera;

use super::builder::{BlockKind, Builder};
use super::params::ParamUse;
use super::runprogram::format_detail;
use super::table::Call;

/// RI_INFINITY: the detail of a bound that reaches the eye plane.
pub const RI_INFINITY: f32 = 1.0e38;
/// How deep procedurals may generate procedurals.
const MAX_DEPTH: usize = 64;

/// One procedural being expanded (for diagnostics and the depth limit).
#[derive(Clone, Debug)]
pub(super) struct Expansion {
    /// `Procedural "RunProgram" "gen.py"` and the like.
    pub what: String,
    pub span: Span,
}

impl Builder<'_> {
    pub(super) fn procedural(&mut self, call: &Call<'_>) {
        let bound = call.pos[2].floats();
        if bound.len() != 6 {
            let d = Diag::error(
                "scene::geometry",
                format!(
                    "`Procedural`: the bound needs 6 numbers, found {}",
                    bound.len()
                ),
            )
            .label(call.pos_spans[2], "here")
            .help(call.spec.describe());
            return self.report(d);
        }
        let bound = [bound[0], bound[1], bound[2], bound[3], bound[4], bound[5]];
        let kind = call.pos[0].str();
        let strs = call.pos[1].strs();
        let first = strs.first().cloned();
        let (usage, what) = match kind {
            "DelayedReadArchive" => ("[\"file.rib\"]", "a file name"),
            "RunProgram" => ("[\"program args\" \"datablock\"]", "a program"),
            "DynamicLoad" => ("[\"library.so\" \"parameters\"]", "a library"),
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown procedural \"{other}\""),
                )
                .label(call.pos_spans[0], "here")
                .help("use \"DelayedReadArchive\", \"RunProgram\" or \"DynamicLoad\"");
                return self.report(d);
            }
        };
        let Some(first) = first.filter(|f| !f.trim().is_empty()) else {
            let d = Diag::error(
                "scene::geometry",
                format!("`Procedural \"{kind}\"` needs {what}"),
            )
            .label(call.pos_spans[1], "here")
            .help(format!("Procedural \"{kind}\" {usage} [bound]"));
            return self.report(d);
        };
        let data = strs.get(1).cloned().unwrap_or_default();
        if !self.geometry_wanted(call) {
            return;
        }
        if kind != "DelayedReadArchive" && !self.ctx.procedurals.allow {
            let d = Diag::warning(
                "scene::procedural-not-allowed",
                format!(
                    "`Procedural \"{kind}\"` names {what} to run (`{first}`); programs and libraries named by a scene are not run unless allowed, so it is skipped"
                ),
            )
            .label(call.pos_spans[1], "not run")
            .help(
                "a scene file is untrusted input: if you trust this one, render it with `arbor render --allow-programs` (or ARBOR_ALLOW_PROGRAMS=1)",
            );
            return self.report(d);
        }
        let Some(detail) = self.procedural_detail(&bound) else {
            return; // out of view
        };
        let span = call.full_span();
        match kind {
            "DelayedReadArchive" => {
                let what = format!("Procedural \"DelayedReadArchive\" \"{first}\"");
                self.expand(what, span, |b| {
                    b.read_archive_named(&first, call.pos_spans[1], call.req.span)
                });
            }
            "RunProgram" => self.expand_program(&first, &data, detail, span, call.pos_spans[1]),
            _ => self.expand_dynamic_load(&first, &data, detail, span, call.pos_spans[1]),
        }
    }

    /// `Procedural2 "DelayedReadArchive2" "SimpleBound" "string filename" [f] "float[6] bound"
    /// [b]` (PRMan 19 and later; RenderMan for Blender and Maya write every mesh so): the
    /// archive is read as `Procedural "DelayedReadArchive"` would, culled by its bound when one
    /// is given. Other Procedural2 plug-ins are compiled C++ and are skipped with a warning.
    pub(super) fn procedural2(&mut self, call: &Call<'_>) {
        let kind = call.pos[0].str();
        let params = self.params(call, ParamUse::Shader);
        if kind != "DelayedReadArchive2" {
            let d = Diag::warning(
                "scene::procedural-not-allowed",
                format!(
                    "`Procedural2 \"{kind}\"` is a compiled RenderMan plug-in arbor cannot run; it is skipped"
                ),
            )
            .label(call.pos_spans[0], "not run")
            .help("only \"DelayedReadArchive2\" (a RIB archive) is read");
            return self.report(d);
        }
        let Some(file) = params
            .string("filename")
            .filter(|f| !f.trim().is_empty())
            .map(str::to_string)
        else {
            let d = Diag::error(
                "scene::geometry",
                "`Procedural2 \"DelayedReadArchive2\"` needs a \"string filename\"".to_string(),
            )
            .label(call.req.span, "here")
            .help("Procedural2 \"DelayedReadArchive2\" \"SimpleBound\" \"string filename\" [\"file.rib\"] \"float[6] bound\" [x0 x1 y0 y1 z0 z1]");
            return self.report(d);
        };
        if !self.geometry_wanted(call) {
            return;
        }
        if let Some(b) = params.floats("bound").filter(|b| b.len() == 6) {
            let bound = [b[0], b[1], b[2], b[3], b[4], b[5]];
            if self.procedural_detail(&bound).is_none() {
                return; // out of view
            }
        }
        let span = call.full_span();
        let at = call.rest.first().map_or(call.req.span, |a| a.span);
        let what = format!("Procedural2 \"DelayedReadArchive2\" \"{file}\"");
        self.expand(what, span, |b| {
            b.read_archive_named(&file, at, call.req.span)
        });
    }

    /// The raster area of an object-space bound `[x0 x1 y0 y1 z0 z1]` under the current
    /// transform, or None when it is out of view (see the module invariants).
    pub(super) fn procedural_detail(&self, bound: &[f32; 6]) -> Option<f32> {
        let Some(scene) = self.world.as_ref().filter(|_| self.defining.is_none()) else {
            // Object definitions have no place in the picture yet.
            return Some(RI_INFINITY);
        };
        let mut options = scene.options.clone();
        if let Some((x, y)) = self.ctx.procedurals.resolution {
            options.xres = x.max(1);
            options.yres = y.max(1);
        }
        let camera = Camera::from_options(
            &options,
            scene.camera_from_world,
            &std::collections::HashMap::new(),
        );
        let camera_from_object = scene.camera_from_world * self.gs.ctm;
        let [x0, x1, y0, y1, z0, z1] = *bound;
        if [x0, x1, y0, y1, z0, z1].iter().any(|v| v.is_nan()) {
            return Some(RI_INFINITY);
        }
        let corners: Vec<Vec3> = (0..8)
            .map(|i| {
                let p = Vec3::new(
                    if i & 1 == 0 { x0 } else { x1 },
                    if i & 2 == 0 { y0 } else { y1 },
                    if i & 4 == 0 { z0 } else { z1 },
                );
                camera_from_object.transform_point3(p)
            })
            .collect();
        let moving = self.gs.motion.is_some() || scene.camera_motion.is_some();
        let zmin = corners.iter().map(|c| c.z).fold(f32::INFINITY, f32::min);
        let zmax = corners
            .iter()
            .map(|c| c.z)
            .fold(f32::NEG_INFINITY, f32::max);
        if !moving && (zmax < camera.near || zmin > camera.far) {
            return None;
        }
        if camera.perspective && zmin <= camera.near.max(1e-6) {
            return Some(RI_INFINITY);
        }
        let raster = camera.raster_from_camera();
        let (mut rx0, mut rx1, mut ry0, mut ry1) = (
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
        );
        for c in &corners {
            let r = raster.project_point3(*c);
            rx0 = rx0.min(r.x);
            rx1 = rx1.max(r.x);
            ry0 = ry0.min(r.y);
            ry1 = ry1.max(r.y);
        }
        let detail = (rx1 - rx0) * (ry1 - ry0);
        if !detail.is_finite() {
            return Some(RI_INFINITY);
        }
        if moving || self.ray_visible(scene) {
            return Some(detail);
        }
        let f = &options.pixel_filter;
        let coc = camera.dof.map_or(0.0, |d| {
            d.coc_factor(zmin, zmax) * d.raster_k[0].abs().max(d.raster_k[1].abs())
        });
        let mx = f.xwidth.max(1.0) * 0.5 + 1.0 + coc;
        let my = f.ywidth.max(1.0) * 0.5 + 1.0 + coc;
        let off = rx1 < -mx
            || ry1 < -my
            || rx0 > options.xres as f32 + mx
            || ry0 > options.yres as f32 + my;
        (!off).then_some(detail)
    }

    /// True when the current attributes make primitives visible to rays (so geometry out of
    /// the camera's view still matters), or a light traces shadow rays.
    fn ray_visible(&self, scene: &super::Scene) -> bool {
        let u = &self.gs.attrs.user;
        let num = |k: &str| u.get(k).and_then(|p| p.data.floats().first().copied());
        let text = |k: &str| {
            u.get(k)
                .and_then(|p| p.data.strings().first().map(|s| s.to_ascii_lowercase()))
        };
        num("visibility:trace").is_some_and(|v| v != 0.0)
            || num("visibility:transmission").is_some_and(|v| v != 0.0)
            || text("visibility:transmission").is_some_and(|s| s != "transparent")
            || num("render:visibility").is_some_and(|v| (v as i32) & 6 != 0)
            || text("render:casts_shadows").is_some_and(|s| s != "none")
            || scene.lights.iter().any(|l| l.ray_shadows)
    }

    /// Runs `f` (which issues the procedural's requests) inside an implicit attribute block
    /// that its requests cannot close, closing whatever they leave open.
    pub(super) fn expand(&mut self, what: String, span: Span, f: impl FnOnce(&mut Self)) {
        if self.expanding.len() >= MAX_DEPTH {
            let d = Diag::error(
                "scene::procedural",
                format!("procedurals nested more than {MAX_DEPTH} deep"),
            )
            .label(span, "not expanded")
            .help("a procedural that always generates itself never ends: make it stop below some detail");
            return self.report(d);
        }
        self.push_block(BlockKind::Procedural, span);
        let depth = self.blocks.len();
        let conds = self.conds.len();
        self.expanding.push(Expansion { what, span });
        f(self);
        while self.conds.len() > conds {
            if let Some(c) = self.conds.pop() {
                self.report(
                    Diag::error(
                        "scene::nesting",
                        "`IfBegin` in a procedural's output is never closed by `IfEnd`",
                    )
                    .label(c.span, "opened here"),
                );
            }
        }
        let mut unclosed = super::builder::Unclosed::default();
        while self.blocks.len() > depth {
            let Some(b) = self.blocks.pop() else { break };
            if !unclosed.report_one(&b) {
                self.unwind_block(b);
                continue;
            }
            self.report(
                Diag::error(
                    "scene::nesting",
                    format!(
                        "`{}` in a procedural's output is never closed by `{}`",
                        b.kind.begin(),
                        b.kind.end()
                    ),
                )
                .label(b.span, "opened here")
                .help(format!(
                    "a procedural's output closes its own blocks: add `{}`",
                    b.kind.end()
                )),
            );
            self.unwind_block(b);
        }
        if let Some(d) = unclosed.summary("in a procedural's output are never closed") {
            self.report(d);
        }
        self.expanding.pop();
        if let Some(b) = self.blocks.pop() {
            self.restore_attrs(b.saved);
        }
    }

    /// The help line that places a diagnostic raised while expanding a procedural.
    pub(super) fn expansion_note(&self) -> Option<String> {
        let e = self.expanding.last()?;
        let file = self
            .ctx
            .sources
            .get(e.span.file)
            .map(|f| f.name.clone())
            .unwrap_or_default();
        let (l, c) = self.ctx.sources.line_col(e.span);
        Some(format!("while expanding `{}` at {file}:{l}:{c}", e.what))
    }

    /// Runs one RunProgram request and the RIB it answers with.
    pub(super) fn expand_program(
        &mut self,
        command: &str,
        data: &str,
        detail: f32,
        span: Span,
        arg_span: Span,
    ) {
        let words: Vec<String> = command.split_whitespace().map(String::from).collect();
        let Some(program) = words.first() else {
            return;
        };
        let (found, mut searched) = self.find_procedural(program, false, span);
        // Not on the procedural path: the system's PATH finds bare names ("python3 gen.py").
        let exe = match found.or_else(|| on_path(program)) {
            Some(p) => p,
            None => {
                if !program.contains('/') {
                    searched.push("PATH".into());
                }
                let d = Diag::error(
                    "scene::procedural",
                    format!("cannot find the RunProgram program `{program}`"),
                )
                .label(arg_span, "not found")
                .help(searched_help(&searched));
                return self.report(d);
            }
        };
        let mut line = format_detail(detail).into_bytes();
        line.push(b' ');
        line.extend_from_slice(data.as_bytes());
        line.push(b'\n');
        let timeout = self.ctx.procedurals.timeout;
        let reply = self
            .programs
            .request(command, &exe, &words[1..], &line, timeout);
        let bytes = match reply {
            Ok(b) => b,
            Err(e) => {
                let d = if e.first {
                    Diag::error(
                        "scene::procedural",
                        format!("RunProgram `{command}`: {}", e.message),
                    )
                } else {
                    Diag::warning(
                        "scene::procedural",
                        format!("RunProgram `{command}` failed earlier; procedurals using it are skipped"),
                    )
                };
                return self.report(d.label(arg_span, "this program").help(e.help));
            }
        };
        self.program_replies += 1;
        let name = format!("<RunProgram {command}, reply {}>", self.program_replies);
        let tmp = crate::diag::Diagnostics::new();
        let reqs = crate::rib::parse_bytes(&name, &bytes, self.ctx.sources, &tmp);
        let what = format!("Procedural \"RunProgram\" \"{command}\"");
        self.expand(what, span, |b| {
            for (d, _) in tmp.take() {
                b.report(d);
            }
            b.run(&reqs);
        });
    }

    /// Where a procedural's program or library is: `Option "searchpath" "procedural"` (a
    /// relative entry is taken from the current folder, else the scene's), then the folder of
    /// the file naming it and the scene's folder. Libraries are also tried with the platform's
    /// suffix (`.so`). Returns the folders searched too.
    pub(super) fn find_procedural(
        &self,
        name: &str,
        library: bool,
        from: Span,
    ) -> (Option<PathBuf>, Vec<String>) {
        let mut names = vec![name.to_string()];
        if library && Path::new(name).extension().is_none() {
            names.push(format!("{name}{}", std::env::consts::DLL_SUFFIX));
        }
        let p = Path::new(name);
        if p.is_absolute() {
            let found = names.iter().map(PathBuf::from).find(|c| c.is_file());
            return (found, vec![]);
        }
        let mut dirs: Vec<PathBuf> = Vec::new();
        for d in &self.option_paths.procedural {
            let pb = PathBuf::from(d);
            let pb = match (&self.ctx.base_dir, pb.is_relative() && !pb.exists()) {
                (Some(b), true) => b.join(pb),
                _ => pb,
            };
            dirs.push(pb);
        }
        if let Some(f) = self.ctx.sources.get(from.file) {
            if let Some(parent) = Path::new(&f.name).parent() {
                if !parent.as_os_str().is_empty() && parent.is_dir() {
                    dirs.push(parent.to_path_buf());
                }
            }
        }
        if let Some(b) = &self.ctx.base_dir {
            dirs.push(b.clone());
        }
        dirs.dedup();
        let searched = dirs.iter().map(|d| d.display().to_string()).collect();
        let found = dirs
            .iter()
            .flat_map(|d| names.iter().map(move |n| d.join(n)))
            .find(|c| c.is_file());
        (found, searched)
    }

    /// Ends the build's programs (their input closes, so they exit) and reports how they
    /// ended.
    pub(super) fn close_programs(&mut self) {
        for (cmd, msg) in self.programs.close_all() {
            let d = Diag::note("scene::procedural", format!("RunProgram `{cmd}` {msg}"));
            self.ctx.diags.report(d);
        }
    }
}

/// A bare program name found on the PATH environment variable.
fn on_path(program: &str) -> Option<PathBuf> {
    if program.contains('/') || program.contains(std::path::MAIN_SEPARATOR) {
        return None;
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(program))
        .find(|c| c.is_file())
}

pub(super) fn searched_help(searched: &[String]) -> String {
    if searched.is_empty() {
        "check the path".into()
    } else {
        format!(
            "searched: {} (add a folder with `Option \"searchpath\" \"procedural\"`)",
            searched.join(", ")
        )
    }
}
