//! The scene builder: runs requests through the table and keeps the graphics state.
//!
//! Input: `Vec<Request>` (one RIB stream; `ReadArchive` pulls in more) and a
//! [`BuildContext`]. Output: one [`Scene`] per frame (per `WorldBegin`…`WorldEnd` without
//! `FrameBegin`), filtered by the CLI's frame range.
//! Invariants: errors are collected and the build goes on (unless `ErrorHandler "abort"`);
//! every block records the span that opened it; inside the world `ctm` is world_from_object,
//! before it camera_from_current.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::{Diag, Diagnostics, Severity, SourceMap, Span};
use crate::rib::{Request, Value};

use super::params::{parse_params, validate_single, ColorMap, Dictionary, ParamUse};
use super::table::{self, Call};
use super::types::*;

/// What the builder needs from the outside world.
pub struct BuildContext<'a> {
    pub sources: &'a SourceMap,
    pub diags: &'a Diagnostics,
    /// Search paths from the command line, searched before the scene's own.
    pub shader_paths: Vec<String>,
    pub texture_paths: Vec<String>,
    pub archive_paths: Vec<String>,
    /// The folder of the main scene file.
    pub base_dir: Option<PathBuf>,
    /// Only frames in this inclusive range are built (frame numbers from `FrameBegin`, else
    /// the 1-based count of world blocks).
    pub frames: Option<(i32, i32)>,
    /// What `Procedural "RunProgram"`/`"DynamicLoad"` may do, and the image size their detail
    /// is measured in.
    pub procedurals: ProceduralSettings,
}

/// Settings for procedural primitives that run code named by the scene.
#[derive(Clone, Debug)]
pub struct ProceduralSettings {
    /// Run `RunProgram` programs and load `DynamicLoad` libraries. Off by default: a scene
    /// file is untrusted input, so only the user (`arbor render --allow-programs`) turns it on.
    pub allow: bool,
    /// How long a `RunProgram` program may stay silent before it is killed.
    pub timeout: std::time::Duration,
    /// The image size replacing Format's (`--res`), so the detail passed to a procedural is
    /// the raster area of its bound in the picture actually rendered.
    pub resolution: Option<(u32, u32)>,
}

impl Default for ProceduralSettings {
    fn default() -> ProceduralSettings {
        ProceduralSettings {
            allow: false,
            timeout: std::time::Duration::from_secs(60),
            resolution: None,
        }
    }
}

impl<'a> BuildContext<'a> {
    pub fn new(sources: &'a SourceMap, diags: &'a Diagnostics) -> BuildContext<'a> {
        BuildContext {
            sources,
            diags,
            shader_paths: Vec::new(),
            texture_paths: Vec::new(),
            archive_paths: Vec::new(),
            base_dir: None,
            frames: None,
            procedurals: ProceduralSettings::default(),
        }
    }
}

/// Builds every scene of a request stream.
pub fn build_scenes(requests: Vec<Request>, ctx: &BuildContext) -> Vec<Scene> {
    let mut b = Builder::new(ctx);
    b.run(&requests);
    b.finish()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BlockKind {
    Frame,
    World,
    Attribute,
    Transform,
    Solid,
    Object,
    Motion,
    /// The implicit attribute block around a procedural's output.
    Procedural,
}

/// Most blocks reported one by one when one request (or the end of the stream) closes many
/// at once; the rest are reported together ([`Unclosed`]). A stream of 5000
/// `AttributeBegin`s without their ends printed 5000 errors, for half a minute.
pub(super) const MAX_BLOCK_REPORTS: usize = 8;

/// The blocks closed beyond [`MAX_BLOCK_REPORTS`] at one request: how many of each kind, and
/// the outermost's opener (they are closed innermost first).
#[derive(Default)]
pub(super) struct Unclosed {
    reported: usize,
    counts: Vec<(BlockKind, usize)>,
    outermost: Option<Span>,
}

impl Unclosed {
    /// Whether the block closing now is reported on its own; if not it is counted.
    pub(super) fn report_one(&mut self, b: &Block) -> bool {
        if self.reported < MAX_BLOCK_REPORTS {
            self.reported += 1;
            return true;
        }
        match self.counts.iter_mut().find(|(k, _)| *k == b.kind) {
            Some((_, n)) => *n += 1,
            None => self.counts.push((b.kind, 1)),
        }
        self.outermost = Some(b.span);
        false
    }

    /// One error for the blocks counted, `what` saying what happened to them ("are never
    /// closed"); None when every block was reported on its own.
    pub(super) fn summary(&self, what: &str) -> Option<Diag> {
        let total: usize = self.counts.iter().map(|(_, n)| n).sum();
        let span = self.outermost?;
        let kinds = self
            .counts
            .iter()
            .map(|(k, n)| format!("{n} `{}`", k.begin()))
            .collect::<Vec<_>>()
            .join(", ");
        Some(
            Diag::error(
                "scene::nesting",
                format!("{total} more blocks ({kinds}) {what}"),
            )
            .label(span, "the outermost of them is opened here")
            .help("each `…Begin` needs its `…End`"),
        )
    }
}

impl BlockKind {
    pub(super) fn begin(self) -> &'static str {
        match self {
            BlockKind::Frame => "FrameBegin",
            BlockKind::World => "WorldBegin",
            BlockKind::Attribute => "AttributeBegin",
            BlockKind::Transform => "TransformBegin",
            BlockKind::Solid => "SolidBegin",
            BlockKind::Object => "ObjectBegin",
            BlockKind::Motion => "MotionBegin",
            BlockKind::Procedural => "Procedural",
        }
    }
    pub(super) fn end(self) -> &'static str {
        match self {
            BlockKind::Frame => "FrameEnd",
            BlockKind::World => "WorldEnd",
            BlockKind::Attribute => "AttributeEnd",
            BlockKind::Transform => "TransformEnd",
            BlockKind::Solid => "SolidEnd",
            BlockKind::Object => "ObjectEnd",
            BlockKind::Motion => "MotionEnd",
            BlockKind::Procedural => "(the end of the procedural's output)",
        }
    }
}

/// The part of the graphics state saved by attribute blocks.
#[derive(Clone, Debug)]
pub(super) struct GState {
    pub attrs: Arc<Attributes>,
    /// TrimCurve in force (an attribute).
    pub trim: Option<Arc<TrimCurves>>,
    /// World_from_object inside the world; camera_from_current before it.
    pub ctm: Mat4,
    /// The ctm at several times when a transform was given inside `MotionBegin` (its first
    /// key equals `ctm`).
    pub motion: Option<Arc<MotionTransform>>,
    /// ScopedCoordinateSystem entries made so far: (name, value it replaced).
    pub scoped: Vec<(String, Option<Mat4>)>,
}

/// Options saved by FrameBegin.
#[derive(Clone, Debug)]
pub(super) struct SavedOptions {
    pub options: Options,
    pub option_paths: SearchPaths,
    pub colors: Option<ColorMap>,
    pub clip_camera: Vec<(Vec3, Vec3)>,
}

#[derive(Clone, Debug)]
pub(super) struct Block {
    pub kind: BlockKind,
    pub span: Span,
    pub saved: GState,
    pub saved_options: Option<Box<SavedOptions>>,
}

/// A primitive kept by ObjectBegin, relative to the object's own space.
#[derive(Clone, Debug)]
pub(super) struct ObjPrim {
    pub geometry: Arc<Geometry>,
    pub primvars: Arc<ParamList>,
    pub object_from_prim: Mat4,
    pub span: Span,
    /// The innermost `SolidBegin` block of the definition around it: an index into the
    /// object's `solids` (None outside every solid of the definition).
    pub solid: Option<u32>,
}

/// A `SolidBegin` block inside an object definition. Its CSG tree is rebuilt at each
/// `ObjectInstance` under the instance's own solid, so every instance is its own solid.
#[derive(Clone, Debug)]
pub(super) struct ObjSolid {
    pub op: SolidOp,
    /// Index of the enclosing block in the same definition (None: the definition's top).
    pub parent: Option<u32>,
    pub span: Span,
}

/// What `ObjectBegin … ObjectEnd` keeps: the primitives and the solids around them.
#[derive(Debug, Default)]
pub(super) struct ObjectShape {
    pub prims: Vec<ObjPrim>,
    pub solids: Vec<ObjSolid>,
}

#[derive(Debug)]
pub(super) struct ObjectDef {
    pub handle: String,
    pub shape: ObjectShape,
    /// inverse of the ctm at ObjectBegin.
    pub object_from_ctm: Mat4,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ErrorMode {
    Print,
    Ignore,
    Abort,
}

/// One IfBegin…IfEnd level.
#[derive(Clone, Debug)]
pub(super) struct Cond {
    pub span: Span,
    /// The enclosing level was active.
    pub parent_active: bool,
    /// Some branch of this level was taken already.
    pub taken: bool,
    /// The current branch is being processed.
    pub active: bool,
    pub seen_else: bool,
}

/// The builder state (handlers live in the sibling modules as `impl Builder` blocks).
pub struct Builder<'a> {
    pub(super) ctx: &'a BuildContext<'a>,
    pub(super) dict: Dictionary,
    pub(super) options: Options,
    /// Option "searchpath" values (after `&`/`@` expansion), without the CLI paths.
    pub(super) option_paths: SearchPaths,
    pub(super) colors: Option<ColorMap>,
    pub(super) gs: GState,
    pub(super) blocks: Vec<Block>,
    /// The scene being built between WorldBegin and WorldEnd.
    pub(super) world: Option<Scene>,
    /// camera_from_named for CoordinateSystem names.
    pub(super) named: HashMap<String, Mat4>,
    /// ClippingPlane given before WorldBegin, in camera space.
    pub(super) clip_camera: Vec<(Vec3, Vec3)>,
    pub(super) scenes: Vec<Scene>,
    pub(super) frame: Option<i32>,
    pub(super) world_count: i32,
    pub(super) frame_active: bool,
    pub(super) light_handles: HashMap<String, usize>,
    pub(super) objects: HashMap<String, Arc<ObjectShape>>,
    pub(super) defining: Option<ObjectDef>,
    /// Inside MotionBegin: the block's requests so far.
    pub(super) motion_block: Option<super::motion::MotionBlock>,
    /// While a deforming motion block runs its keys: the primitives they emit.
    pub(super) capture: Option<Vec<(Span, Arc<Geometry>, Arc<ParamList>)>>,
    pub(super) archives: HashMap<String, Arc<Vec<Request>>>,
    /// `Resource … "attributes"` states by name: the first map outside any `ResourceBegin`
    /// block, then one per open block (the names saved inside it).
    pub(super) resource_scopes: Vec<HashMap<String, super::resources::SavedAttributes>>,
    /// Archives being read, outermost first, for cycle detection.
    pub(super) include: Vec<String>,
    pub(super) conds: Vec<Cond>,
    pub(super) error_mode: ErrorMode,
    pub(super) aborted: bool,
    /// Texture-making requests waiting for the next world block.
    pub(super) pending_texture_jobs: Vec<TextureJob>,
    /// LightSource requests given before WorldBegin (shader space kept as camera_from_shader).
    pub(super) pending_lights: Vec<PendingLight>,
    /// Geometry met before any `WorldBegin`: held back, because a file that never opens a
    /// world is a geometry archive (one warning at the end), not a scene with N errors.
    pub(super) orphans: Vec<Diag>,
    /// The procedurals being expanded, outermost first.
    pub(super) expanding: Vec<super::procedural::Expansion>,
    /// The RunProgram programs started so far.
    pub(super) programs: super::runprogram::Programs,
    /// Replies read from RunProgram programs (each is registered as a source).
    pub(super) program_replies: usize,
    /// DynamicLoad libraries loaded so far (or why they could not be).
    pub(super) libraries: super::ri_api::Libraries,
    /// The last world_from_object given to a primitive, shared with the next when equal.
    pub(super) last_ctm: Option<Arc<Mat4>>,
    /// The `ArchiveBegin` block being recorded.
    pub(super) recording: Option<super::archive::Recording>,
    /// The last small geometry emitted, shared with the next primitive when equal.
    pub(super) last_geometry: Option<Arc<Geometry>>,
}

/// A light declared before WorldBegin: added to every following world until its frame ends.
#[derive(Clone, Debug)]
pub(super) struct PendingLight {
    pub light: Light,
    /// Declared inside FrameBegin…FrameEnd (dropped at FrameEnd).
    pub in_frame: bool,
}

impl<'a> Builder<'a> {
    pub fn new(ctx: &'a BuildContext<'a>) -> Builder<'a> {
        Builder {
            ctx,
            dict: Dictionary::default(),
            options: Options::default(),
            option_paths: SearchPaths::default(),
            colors: None,
            gs: GState {
                attrs: Arc::new(Attributes::default()),
                trim: None,
                ctm: Mat4::IDENTITY,
                motion: None,
                scoped: Vec::new(),
            },
            blocks: Vec::new(),
            world: None,
            named: HashMap::new(),
            clip_camera: Vec::new(),
            scenes: Vec::new(),
            frame: None,
            world_count: 0,
            frame_active: true,
            light_handles: HashMap::new(),
            resource_scopes: vec![HashMap::new()],
            objects: HashMap::new(),
            defining: None,
            motion_block: None,
            capture: None,
            archives: HashMap::new(),
            include: Vec::new(),
            conds: Vec::new(),
            error_mode: ErrorMode::Print,
            aborted: false,
            pending_texture_jobs: Vec::new(),
            pending_lights: Vec::new(),
            orphans: Vec::new(),
            expanding: Vec::new(),
            programs: Default::default(),
            program_replies: 0,
            libraries: Default::default(),
            last_geometry: None,
            recording: None,
            last_ctm: None,
        }
    }

    /// Reports a diagnostic under the current ErrorHandler.
    pub(super) fn report(&mut self, mut d: Diag) {
        if let Some(note) = self.expansion_note() {
            d.help = Some(match d.help.take() {
                Some(h) => format!("{h}\n{note}"),
                None => note,
            });
        }
        match self.error_mode {
            ErrorMode::Ignore => {}
            ErrorMode::Print => self.ctx.diags.report(d),
            ErrorMode::Abort => {
                let err = d.severity == Severity::Error;
                self.ctx.diags.report(d);
                if err {
                    self.aborted = true;
                }
            }
        }
    }

    pub(super) fn error(
        &mut self,
        code: &'static str,
        msg: impl Into<String>,
        span: Span,
        label: &str,
    ) {
        self.report(Diag::error(code, msg).label(span, label));
    }

    /// The warning for a request the renderer does not implement (same text every time, so
    /// the sink shows it once with a count).
    pub(super) fn unimplemented(&mut self, call: &Call<'_>) {
        let d = Diag::warning(
            "scene::unimplemented",
            format!("`{}` is not implemented yet; ignored", call.name()),
        )
        .label(call.span(), "ignored")
        .help(if call.spec.section == "ext" {
            "a renderer extension, not part of RISpec 3.2".to_string()
        } else {
            format!("RISpec 3.2 §{}", call.spec.section)
        });
        self.report(d);
    }

    /// PRMan's `GeometricRepresentation`: `"primitive"`, its default, is what arbor draws, so
    /// it is accepted silently (modellers such as WW3DKit write it before every object); any
    /// other (`"lines"`, `"points"`, …) gets the not-implemented warning and the surface is
    /// drawn.
    pub(super) fn geometric_representation(&mut self, call: &Call<'_>) {
        if call.pos[0].str() != "primitive" {
            self.unimplemented(call);
        }
    }

    /// A note (shown at `-v`) for a known renderer-specific Option/Attribute arbor does not
    /// act on; the value is still stored for `attribute()`/`option()`.
    pub(super) fn note_if_ignored(&mut self, request: &str, cat: &str, p: &Param) {
        let key = format!("{cat}:{}", p.name);
        if let Some((_, super::known::Use::Ignored)) = super::known::lookup(&key) {
            let d = Diag::note(
                "scene::ignored-setting",
                format!(
                    "`{request} \"{cat}\" \"{}\"` is {}; arbor ignores it",
                    p.name,
                    super::known::why_ignored(cat)
                ),
            )
            .label(p.span, "recognised, no effect");
            self.report(d);
        }
    }

    /// For requests handled by the driver itself (conditionals, ArchiveBegin) or that need
    /// nothing (version).
    pub(super) fn nothing(&mut self, _call: &Call<'_>) {}

    pub(super) fn c_only(&mut self, call: &Call<'_>) {
        let d = Diag::warning(
            "scene::c-only",
            format!(
                "`{}` belongs to the C binding and has no effect in RIB",
                call.name()
            ),
        )
        .label(call.span(), "ignored");
        self.report(d);
    }

    /// Runs a request stream (the main file, an archive, or an inline archive).
    /// Runs a list of requests (a file, an archive, a procedural's output). An `ArchiveBegin`
    /// in it must end in it.
    pub fn run(&mut self, reqs: &[Request]) {
        let outer = self.recording.take();
        for r in reqs {
            if self.aborted {
                break;
            }
            self.feed(r);
        }
        self.close_recording();
        self.recording = outer;
    }

    /// Runs one request of a stream: the reader hands requests over as it parses them, so a
    /// file's requests are never all in memory at once. Call [`Builder::finish`] after the
    /// last one.
    pub fn feed(&mut self, r: &Request) {
        if self.aborted || self.record(r) {
            return;
        }
        match r.name.as_str() {
            "IfBegin" | "ElseIf" | "Else" | "IfEnd" => {
                self.conditional(r);
                return;
            }
            _ => {}
        }
        if !self.conds.last().map_or(true, |c| c.active) {
            return;
        }
        if r.name == "ArchiveBegin" {
            self.begin_archive(r);
            return;
        }
        if let Some(block) = self.motion_block.as_mut() {
            if r.name != "MotionEnd" && r.name != "MotionBegin" {
                block.reqs.push(r.clone());
                return;
            }
        }
        self.dispatch(r);
    }

    /// Checks one request against the table and calls its handler.
    pub(super) fn dispatch(&mut self, r: &Request) {
        let Some(spec) = table::lookup(&r.name) else {
            let d = table::unknown_request(r);
            self.report(d);
            return;
        };
        // `nan`/`inf` (C's printf of a broken value): the request would poison a transform
        // or a primitive's bound, so it is left out, naming the value.
        if let Some(a) = r.args.iter().find(|a| match &a.value {
            Value::Float(f) => !f.is_finite(),
            Value::FloatArray(v) => v.iter().any(|f| !f.is_finite()),
            _ => false,
        }) {
            self.report(
                Diag::warning(
                    "scene::not-finite",
                    format!(
                        "`{}` has a value that is not a finite number; the request is ignored",
                        r.name
                    ),
                )
                .label(a.span, "not a finite number")
                .help("the program that wrote this RIB printed a NaN or an infinity here"),
            );
            return;
        }
        let ncomps = self.colors.as_ref().map_or(3, |c| c.n);
        match table::check_args(r, spec, ncomps) {
            Ok(call) => {
                if self.defining.is_some()
                    && (spec.section.starts_with("4.2.") || spec.name == "Attribute")
                {
                    // Exporters (K-3D) put Color/Opacity/Surface inside object definitions;
                    // arbor keeps only geometry and transforms there, so say so.
                    let d = Diag::warning(
                        "scene::object-attribute",
                        format!(
                            "`{}` inside `ObjectBegin`…`ObjectEnd` is ignored: instances use the attributes current at `ObjectInstance`",
                            spec.name
                        ),
                    )
                    .label(call.span(), "ignored")
                    .help("set it before `ObjectInstance` instead (RISpec 3.2 §5.7)");
                    self.report(d);
                }
                (spec.handler)(self, &call)
            }
            Err(d) => self.report(d),
        }
    }

    /// Ends the stream: reports unclosed blocks (each at its opener) and closes an open world
    /// so its scene is still produced.
    pub fn finish(mut self) -> Vec<Scene> {
        self.close_recording();
        self.close_programs();
        // After an abort nothing more is reported; an open world still yields its scene.
        if self.aborted {
            self.error_mode = ErrorMode::Ignore;
        }
        self.aborted = false;
        for c in std::mem::take(&mut self.conds).into_iter().rev() {
            self.report(
                Diag::error("scene::nesting", "`IfBegin` is never closed by `IfEnd`")
                    .label(c.span, "opened here"),
            );
        }
        if let Some(def) = self.defining.take() {
            let _ = def;
        }
        let mut unclosed = Unclosed::default();
        while let Some(b) = self.blocks.pop() {
            if unclosed.report_one(&b) {
                self.report(
                    Diag::error(
                        "scene::nesting",
                        format!("`{}` is never closed by `{}`", b.kind.begin(), b.kind.end()),
                    )
                    .label(b.span, "opened here")
                    .help(format!("add `{}` at the end of the block", b.kind.end())),
                );
            }
            if b.kind == BlockKind::World {
                self.close_world(b);
            } else {
                self.gs = b.saved;
            }
        }
        if let Some(d) = unclosed.summary("are never closed") {
            self.report(d);
        }
        if let Some(first) = self.orphans.first() {
            // Aqsis and Pixie report every request here as out of context; one message says
            // what the file is.
            let n = self.orphans.len();
            let mut d = Diag::warning(
                "scene::archive-only",
                format!(
                    "this file holds geometry ({n} request{}) but never opens `WorldBegin`: it looks like an archive meant for `ReadArchive`; nothing is rendered",
                    if n == 1 { "" } else { "s" }
                ),
            )
            .help("render a scene that reads it inside its world: `WorldBegin` … `ReadArchive \"this.rib\"` … `WorldEnd`");
            if let Some(sp) = first.primary_span() {
                d = d.label(sp, "first geometry, outside any world");
            }
            self.orphans.clear();
            self.report(d);
        }
        if !self.pending_texture_jobs.is_empty() {
            // Texture jobs after the last world block: a scene that only runs them.
            let mut options = self.options.clone();
            options.search_paths.texture = self
                .ctx
                .texture_paths
                .iter()
                .chain(&self.option_paths.texture)
                .cloned()
                .collect();
            self.scenes.push(Scene {
                options,
                source_dir: self.ctx.base_dir.clone(),
                texture_jobs: std::mem::take(&mut self.pending_texture_jobs),
                jobs_only: true,
                ..Scene::default()
            });
        }
        self.scenes
    }

    // ---- helpers shared by the handlers ----

    /// The current attributes, for modification (copied on write when shared).
    pub(super) fn attrs(&mut self) -> &mut Attributes {
        Arc::make_mut(&mut self.gs.attrs)
    }

    /// world_from_current: the ctm inside the world; identity before it (shader space of
    /// shaders declared before WorldBegin is taken as world space).
    pub(super) fn world_from_current(&self) -> Mat4 {
        if self.world.is_some() {
            self.gs.ctm
        } else {
            Mat4::IDENTITY
        }
    }

    /// camera_from_current, inside or outside the world.
    pub(super) fn camera_from_current(&self) -> Mat4 {
        match &self.world {
            Some(s) => s.camera_from_world * self.gs.ctm,
            None => self.gs.ctm,
        }
    }

    /// Parses a call's parameter list.
    pub(super) fn params(&mut self, call: &Call<'_>, usage: ParamUse<'_>) -> ParamList {
        let mut ds = Vec::new();
        let l = parse_params(
            call.rest,
            &self.dict,
            usage,
            self.colors.as_ref(),
            call.name(),
            &mut |d| ds.push(d),
        );
        for d in ds {
            self.report(d);
        }
        l
    }

    /// A shader named by the call's first argument, with its parameters.
    pub(super) fn shader_ref(&mut self, call: &Call<'_>) -> ShaderRef {
        let mut params = self.params(call, ParamUse::Shader);
        let mut ds = Vec::new();
        validate_single(&mut params, call.name(), &mut |d| ds.push(d));
        for d in ds {
            self.report(d);
        }
        ShaderRef {
            name: call.pos[0].str().to_string(),
            params,
            span: call.full_span(),
            world_from_shader: self.world_from_current(),
        }
    }

    // ---- blocks ----

    pub(super) fn push_block(&mut self, kind: BlockKind, span: Span) {
        self.blocks.push(Block {
            kind,
            span,
            saved: self.gs.clone(),
            saved_options: None,
        });
    }

    /// Pops the block `kind` closed by `call`; reports a missing or mismatched opener.
    pub(super) fn pop_block(&mut self, kind: BlockKind, call: &Call<'_>) -> Option<Block> {
        let Some(pos) = self.blocks.iter().rposition(|b| b.kind == kind) else {
            let mut d = Diag::error(
                "scene::nesting",
                format!("`{}` without `{}`", kind.end(), kind.begin()),
            )
            .label(call.span(), "nothing to close");
            if let Some(top) = self.blocks.last() {
                d = d.label(
                    top.span,
                    format!("the innermost open block is this `{}`", top.kind.begin()),
                );
            }
            d = d.help(format!(
                "remove it, or add `{}` where the block should start",
                kind.begin()
            ));
            self.report(d);
            return None;
        };
        if let Some(p) = self.blocks[pos + 1..]
            .iter()
            .find(|b| b.kind == BlockKind::Procedural)
        {
            let d = Diag::error(
                "scene::nesting",
                format!(
                    "`{}` in a procedural's output would close a block opened outside it",
                    kind.end()
                ),
            )
            .label(call.span(), "ignored")
            .label(p.span, "the procedural")
            .help("a procedural's output may only close the blocks it opened");
            self.report(d);
            return None;
        }
        // Blocks opened after the one being closed are closed with it (and reported).
        let mut unclosed = Unclosed::default();
        while self.blocks.len() > pos + 1 {
            let inner = self.blocks.pop()?;
            if !unclosed.report_one(&inner) {
                self.unwind_block(inner);
                continue;
            }
            self.report(
                Diag::error(
                    "scene::nesting",
                    format!(
                        "`{}` closes `{}` while `{}` is still open",
                        kind.end(),
                        kind.begin(),
                        inner.kind.begin()
                    ),
                )
                .label(call.span(), format!("closes the `{}`", kind.begin()))
                .label(inner.span, format!("`{}` opened here", inner.kind.begin()))
                .help(format!("add `{}` before it", inner.kind.end())),
            );
            self.unwind_block(inner);
        }
        if let Some(d) = unclosed.summary(&format!("are still open; `{}` closes them", kind.end()))
        {
            self.report(d.label(call.span(), format!("closes the `{}`", kind.begin())));
        }
        self.blocks.pop()
    }

    /// Undoes a block closed implicitly.
    pub(super) fn unwind_block(&mut self, b: Block) {
        match b.kind {
            BlockKind::World => self.close_world(b),
            BlockKind::Object => {
                self.finish_object();
                self.restore_attrs(b.saved);
            }
            BlockKind::Motion => {
                self.motion_block = None;
            }
            BlockKind::Transform => {
                self.gs.ctm = b.saved.ctm;
                self.gs.motion = b.saved.motion;
            }
            BlockKind::Frame => self.restore_frame(b),
            _ => self.restore_attrs(b.saved),
        }
    }

    /// Restores the attribute state, undoing ScopedCoordinateSystem entries.
    pub(super) fn restore_attrs(&mut self, saved: GState) {
        while self.gs.scoped.len() > saved.scoped.len() {
            if let Some((name, old)) = self.gs.scoped.pop() {
                match old {
                    Some(m) => self.named.insert(name, m),
                    None => self.named.remove(&name),
                };
            }
        }
        self.gs = saved;
    }

    pub(super) fn restore_frame(&mut self, b: Block) {
        if let Some(o) = b.saved_options {
            self.options = o.options;
            self.option_paths = o.option_paths;
            self.colors = o.colors;
            self.clip_camera = o.clip_camera;
        }
        self.restore_attrs(b.saved);
        self.pending_lights.retain(|p| !p.in_frame);
        self.frame = None;
    }

    pub(super) fn frame_begin(&mut self, call: &Call<'_>) {
        if self.world.is_some() {
            self.error(
                "scene::nesting",
                "`FrameBegin` inside `WorldBegin`…`WorldEnd`",
                call.span(),
                "frames cannot start inside a world block",
            );
            return;
        }
        if let Some(b) = self.blocks.iter().find(|b| b.kind == BlockKind::Frame) {
            let sp = b.span;
            self.report(
                Diag::error("scene::nesting", "`FrameBegin` inside another frame")
                    .label(call.span(), "nested frame")
                    .label(sp, "the open frame")
                    .help("close it with `FrameEnd` first"),
            );
            return;
        }
        self.push_block(BlockKind::Frame, call.span());
        if let Some(b) = self.blocks.last_mut() {
            b.saved_options = Some(Box::new(SavedOptions {
                options: self.options.clone(),
                option_paths: self.option_paths.clone(),
                colors: self.colors.clone(),
                clip_camera: self.clip_camera.clone(),
            }));
        }
        self.frame = Some(if call.pos[0].is_absent() {
            self.world_count + 1
        } else {
            call.pos[0].int() as i32
        });
    }

    pub(super) fn frame_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::Frame, call) {
            self.restore_frame(b);
        }
    }

    pub(super) fn world_begin(&mut self, call: &Call<'_>) {
        if self.world.is_some() {
            let sp = self
                .blocks
                .iter()
                .find(|b| b.kind == BlockKind::World)
                .map(|b| b.span)
                .unwrap_or(call.span());
            self.report(
                Diag::error("scene::nesting", "`WorldBegin` inside another world block")
                    .label(call.span(), "nested world")
                    .label(sp, "the open world")
                    .help("close it with `WorldEnd` first"),
            );
            return;
        }
        self.world_count += 1;
        // The file is a scene after all: geometry before its first world was an error.
        for d in std::mem::take(&mut self.orphans) {
            self.report(d);
        }
        let number = self.frame.unwrap_or(self.world_count);
        self.frame_active = self
            .ctx
            .frames
            .map_or(true, |(a, b)| a <= number && number <= b);
        self.push_block(BlockKind::World, call.span());
        let cfw = self.gs.ctm;
        let wfc = cfw.inverse();
        let mut options = self.options.clone();
        let cli = |c: &Vec<String>, o: &Vec<String>| c.iter().chain(o).cloned().collect();
        options.search_paths = SearchPaths {
            shader: cli(&self.ctx.shader_paths, &self.option_paths.shader),
            texture: cli(&self.ctx.texture_paths, &self.option_paths.texture),
            archive: cli(&self.ctx.archive_paths, &self.option_paths.archive),
            procedural: self.option_paths.procedural.clone(),
        };
        options.clipping_planes = self
            .clip_camera
            .iter()
            .map(|&(p, n)| {
                (
                    wfc.transform_point3(p),
                    cfw.transpose().transform_vector3(n).normalize_or_zero(),
                )
            })
            .collect();
        if let Some(im) = options.imager.as_mut() {
            // Imager shader space was recorded as camera_from_shader.
            im.world_from_shader = wfc * im.world_from_shader;
        }
        self.world = Some(Scene {
            frame: self.frame,
            options,
            camera_from_world: cfw,
            camera_motion: self.gs.motion.take(),
            lights: Vec::new(),
            primitives: Vec::new(),
            solids: Vec::new(),
            coordinate_systems: HashMap::new(),
            source_dir: self.ctx.base_dir.clone(),
            texture_jobs: std::mem::take(&mut self.pending_texture_jobs),
            jobs_only: false,
            bmrt_displacement: false,
            displaced_without_bound: false,
        });
        self.light_handles.clear();
        self.gs.ctm = Mat4::IDENTITY;
        for p in self.pending_lights.clone() {
            let mut light = p.light;
            let mut shader = (*light.shader).clone();
            shader.world_from_shader = wfc * shader.world_from_shader;
            light.shader = Arc::new(shader);
            let Some(scene) = self.world.as_mut() else {
                break;
            };
            let idx = scene.lights.len();
            self.light_handles.insert(light.handle.clone(), idx);
            scene.lights.push(light);
            let a = self.attrs();
            if !a.lights_on.contains(&idx) {
                a.lights_on.push(idx);
            }
        }
    }

    pub(super) fn world_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::World, call) {
            self.close_world(b);
        }
    }

    fn close_world(&mut self, b: Block) {
        self.restore_attrs(b.saved);
        if let Some(mut scene) = self.world.take() {
            let wfc = scene.camera_from_world.inverse();
            scene.coordinate_systems = self
                .named
                .iter()
                .map(|(k, m)| (k.clone(), wfc * *m))
                .collect();
            if self.frame_active {
                self.scenes.push(scene);
            } else {
                // A skipped frame's texture jobs still run, before the next frame.
                let mut jobs = std::mem::take(&mut scene.texture_jobs);
                jobs.append(&mut self.pending_texture_jobs);
                self.pending_texture_jobs = jobs;
            }
        }
        self.frame_active = true;
        self.light_handles.clear();
    }

    pub(super) fn attribute_begin(&mut self, call: &Call<'_>) {
        self.push_block(BlockKind::Attribute, call.span());
    }

    pub(super) fn attribute_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::Attribute, call) {
            self.restore_attrs(b.saved);
        }
    }

    pub(super) fn transform_begin(&mut self, call: &Call<'_>) {
        self.push_block(BlockKind::Transform, call.span());
    }

    pub(super) fn transform_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::Transform, call) {
            self.gs.ctm = b.saved.ctm;
            self.gs.motion = b.saved.motion;
        }
    }

    pub(super) fn solid_begin(&mut self, call: &Call<'_>) {
        let op = match call.pos[0].str() {
            "primitive" => Some(SolidOp::Primitive),
            "union" => Some(SolidOp::Union),
            "intersection" => Some(SolidOp::Intersection),
            "difference" => Some(SolidOp::Difference),
            other => {
                self.report(
                    Diag::error(
                        "scene::arguments",
                        format!("unknown solid operation \"{other}\"; the block is a union"),
                    )
                    .label(call.pos_spans[0], "not a CSG operation")
                    .help("use \"primitive\", \"union\", \"intersection\" or \"difference\""),
                );
                Some(SolidOp::Union)
            }
        };
        self.push_block(BlockKind::Solid, call.span());
        let parent = self.gs.attrs.solid;
        if let Some(def) = self.defining.as_mut() {
            // Inside an object definition the attribute holds an index into the object's
            // own solids; `ObjectInstance` builds the scene's nodes from them.
            let id = def.shape.solids.len() as u32;
            def.shape.solids.push(ObjSolid {
                op: op.unwrap_or(SolidOp::Union),
                parent,
                span: call.span(),
            });
            self.attrs().solid = Some(id);
            return;
        }
        let Some(scene) = self.world.as_mut() else {
            return;
        };
        let parent_op = parent
            .and_then(|p| scene.solids.get(p as usize))
            .map(|n| n.op);
        match (op, parent_op) {
            // A lone primitive solid is just its surfaces: no CSG work at all.
            (Some(SolidOp::Primitive), None) => {}
            (_, Some(SolidOp::Primitive)) => {
                self.report(
                    Diag::warning(
                        "scene::solid",
                        "a solid inside a `SolidBegin \"primitive\"` block is part of that primitive",
                    )
                    .label(call.span(), "this block")
                    .help("primitive solids hold surfaces; put the boolean operation around them"),
                );
            }
            (Some(op), _) => {
                let id = scene.solids.len() as u32;
                scene.solids.push(SolidNode {
                    op,
                    parent,
                    span: call.span(),
                });
                self.attrs().solid = Some(id);
            }
            (None, _) => {}
        }
    }

    pub(super) fn solid_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::Solid, call) {
            self.restore_attrs(b.saved);
        }
    }

    pub(super) fn declare(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str();
        match super::params::parse_decl(call.pos[1].str()) {
            Ok(d) => {
                if name.is_empty() || name.contains(char::is_whitespace) {
                    self.error(
                        "scene::declaration",
                        format!("`Declare`: \"{name}\" is not a parameter name"),
                        call.pos_spans[0],
                        "names have no spaces",
                    );
                    return;
                }
                self.dict.declare(name, d);
            }
            Err(e) => self.report(
                Diag::error("scene::declaration", format!("`Declare \"{name}\"`: {e}"))
                    .label(call.pos_spans[1], "bad declaration")
                    .help("write it as \"[class] type[n]\", e.g. \"varying float[2]\""),
            ),
        }
    }

    pub(super) fn error_handler(&mut self, call: &Call<'_>) {
        self.error_mode = match call.pos[0].str() {
            "print" => ErrorMode::Print,
            "ignore" => ErrorMode::Ignore,
            "abort" => ErrorMode::Abort,
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown error handler \"{other}\""),
                )
                .label(call.pos_spans[0], "not a handler")
                .help("use \"print\", \"ignore\" or \"abort\"");
                self.report(d);
                return;
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rib::{Arg, Value};

    /// Builds requests by hand: `("Translate", vec![1, 2, 3])`-style numbers only.
    fn reqs(list: &[(&str, &[f32])]) -> Vec<Request> {
        list.iter()
            .map(|(n, nums)| Request {
                name: n.to_string(),
                span: Span::new(0, 0, n.len()),
                args: nums
                    .iter()
                    .map(|&f| Arg {
                        value: Value::Float(f),
                        span: Span::new(0, 0, 1),
                    })
                    .collect(),
            })
            .collect()
    }

    /// Feeds `text`'s requests one at a time, as `pipeline::load_scenes` streams a file.
    fn streamed(text: &str, sm: &SourceMap, d: &Diagnostics) -> (Vec<Scene>, Vec<Request>) {
        let reqs = crate::rib::parse_bytes("t.rib", text.as_bytes(), sm, d);
        let ctx = BuildContext::new(sm, d);
        let mut b = Builder::new(&ctx);
        for r in &reqs {
            b.feed(r);
        }
        (b.finish(), reqs)
    }

    #[test]
    fn streamed_requests_build_the_same_scene_and_share_state() {
        let text = r#"WorldBegin
ArchiveBegin "quad"
Polygon "P" [0 0 0 1 0 0 1 1 0 0 1 0]
ArchiveEnd
Color [1 0 0]
ReadArchive "quad"
Color [0 1 0]
Polygon "P" [0 0 1 1 0 1 1 1 1 0 1 1]
Sphere 1 -1 1 360
Color [0 0 1]
Sphere 1 -1 1 360
WorldEnd
"#;
        let sm = SourceMap::new();
        let d = Diagnostics::new();
        let (s, reqs) = streamed(text, &sm, &d);
        assert!(!d.has_errors(), "{:?}", d.snapshot());
        let p = &s[0].primitives;
        assert_eq!(p.len(), 4);
        assert_eq!(p[0].attributes.color, Vec3::X);
        assert_eq!(p[1].attributes.color, Vec3::Y);
        assert_eq!(p[3].attributes.color, Vec3::Z);
        // Colours differ, the rest of the attribute state is one; equal small geometry and
        // equal transforms are shared.
        assert!(Arc::ptr_eq(&p[0].attributes.state, &p[3].attributes.state));
        assert!(Arc::ptr_eq(&p[0].geometry, &p[1].geometry));
        assert!(Arc::ptr_eq(&p[2].geometry, &p[3].geometry));
        assert!(Arc::ptr_eq(
            &p[0].world_from_object,
            &p[3].world_from_object
        ));
        assert_ne!(p[0].primvars, p[1].primvars);
        // Building from the whole list gives the same primitives.
        let d2 = Diagnostics::new();
        let whole = build_scenes(reqs, &BuildContext::new(&sm, &d2));
        assert_eq!(whole[0].primitives.len(), 4);
        for (a, b) in whole[0].primitives.iter().zip(p) {
            assert_eq!(a.geometry, b.geometry);
            assert_eq!(a.attributes, b.attributes);
            assert_eq!(a.primvars, b.primvars);
            assert_eq!(a.world_from_object, b.world_from_object);
        }
    }

    #[test]
    fn a_streamed_archive_left_open_is_reported_at_the_end() {
        let sm = SourceMap::new();
        let d = Diagnostics::new();
        let (_, _) = streamed("ArchiveBegin \"a\"\nSphere 1 -1 1 360\n", &sm, &d);
        let all = d.snapshot();
        assert!(
            all.iter().any(|(x, _)| x.code == "scene::nesting"
                && x.message.contains("`ArchiveBegin` is never closed")),
            "{all:?}"
        );
    }

    #[test]
    fn setting_an_attribute_copies_the_shared_state_once() {
        let mut a = Attributes::default();
        let b = a.clone();
        a.color = Vec3::X;
        assert!(Arc::ptr_eq(&a.state, &b.state));
        a.shading_rate = 4.0;
        assert!(!Arc::ptr_eq(&a.state, &b.state));
        assert_eq!((a.shading_rate, b.shading_rate), (4.0, 1.0));
    }

    #[test]
    fn world_begin_saves_the_camera_and_resets_the_transform() {
        let sm = SourceMap::new();
        sm.add("t.rib", "");
        let d = Diagnostics::new();
        let ctx = BuildContext::new(&sm, &d);
        let r = reqs(&[
            ("Translate", &[0., 0., 5.]),
            ("WorldBegin", &[]),
            ("Translate", &[1., 0., 0.]),
            ("Sphere", &[1., -1., 1., 360.]),
            ("WorldEnd", &[]),
        ]);
        let s = build_scenes(r, &ctx);
        assert!(!d.has_errors());
        assert_eq!(s.len(), 1);
        assert_eq!(
            s[0].camera_from_world.transform_point3(Vec3::ZERO),
            Vec3::new(0., 0., 5.)
        );
        let p = &s[0].primitives[0];
        assert_eq!(p.world_from_object.transform_point3(Vec3::ZERO), Vec3::X);
    }

    #[test]
    fn attribute_changes_do_not_leak_into_emitted_primitives() {
        let sm = SourceMap::new();
        sm.add("t.rib", "");
        let d = Diagnostics::new();
        let ctx = BuildContext::new(&sm, &d);
        let r = reqs(&[
            ("WorldBegin", &[]),
            ("AttributeBegin", &[]),
            ("Color", &[1., 0., 0.]),
            ("Sphere", &[1., -1., 1., 360.]),
            ("Color", &[0., 1., 0.]),
            ("Sphere", &[1., -1., 1., 360.]),
            ("AttributeEnd", &[]),
            ("Sphere", &[1., -1., 1., 360.]),
            ("WorldEnd", &[]),
        ]);
        let s = build_scenes(r, &ctx);
        let c: Vec<Vec3> = s[0].primitives.iter().map(|p| p.attributes.color).collect();
        assert_eq!(c, vec![Vec3::X, Vec3::Y, Vec3::ONE]);
    }
}
