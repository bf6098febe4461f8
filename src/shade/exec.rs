//! The grid interpreter: runs a compiled [`Program`] over every point of a grid at once.
//!
//! Input: a program, its register file (globals and parameters already bound) and the
//! shading environment. Output: the register file after the run.
//! Invariants: computation instructions run over all points (they write temporaries);
//! stores honour the running mask; a point leaves the mask on `break`, `continue` and
//! `return` and rejoins where the language says it does. Faults never panic: they write a
//! defined value and warn once per shader.

use std::rc::Rc;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::{Diag, Diagnostics, Span};
use crate::shade::ops;
pub use crate::shade::value::Lanes;
use crate::shade::value::*;
use crate::sl::ir::*;

/// The running mask: which points execute.
///
/// When few points run (at most one in [`SPARSE_DIVISOR`]), `idx` lists them and pointwise
/// instructions compute just those (see [`Lanes`]); otherwise `idx` is empty and they compute
/// every point. Whoever changes `bits` calls [`Mask::recount`].
#[derive(Clone, Debug)]
pub struct Mask {
    pub bits: Vec<bool>,
    pub count: usize,
    idx: Vec<u32>,
    /// The bits as select masks for stores, made on first use after a change.
    sel: std::cell::RefCell<SelMasks>,
}

/// A mask's bits as `u32` select masks (all ones where a point runs): one per point (floats)
/// and one per component (triples as flat floats), so masked stores are plain vector selects.
#[derive(Clone, Debug, Default)]
struct SelMasks {
    f_ok: bool,
    t_ok: bool,
    f: Vec<u32>,
    t: Vec<u32>,
}

/// A mask with at most one running point in this many runs its pointwise instructions over
/// the running points only (a scalar loop over their indices costs about what a vectorised
/// loop over four or five points does).
pub const SPARSE_DIVISOR: usize = 4;

impl Mask {
    pub fn all(n: usize) -> Mask {
        Mask {
            bits: vec![true; n],
            count: n,
            idx: Vec::new(),
            sel: Default::default(),
        }
    }
    pub fn none(n: usize) -> Mask {
        Mask {
            bits: vec![false; n],
            count: 0,
            idx: Vec::new(),
            sel: Default::default(),
        }
    }
    pub fn from_bits(bits: Vec<bool>) -> Mask {
        let mut m = Mask {
            bits,
            count: 0,
            idx: Vec::new(),
            sel: Default::default(),
        };
        m.recount();
        m
    }
    pub fn is_all(&self) -> bool {
        self.count == self.bits.len()
    }
    pub fn is_none(&self) -> bool {
        self.count == 0
    }
    pub fn and_not(&mut self, other: &[bool]) {
        let count = and_not(&mut self.bits, other);
        if other.len() < self.bits.len() {
            // The flags past `other` stay as they were: count them all.
            self.recount();
        } else {
            self.set_count(count);
        }
    }
    /// Counts the running points (and lists them when they are few).
    pub fn recount(&mut self) {
        let count = count_true(&self.bits);
        self.set_count(count);
    }
    /// Keeps only the points where `c` is not zero (a loop's condition) and recounts, in
    /// one pass over the flags.
    fn and_nonzero(&mut self, c: &[f32]) {
        let count = and_nonzero(&mut self.bits, c);
        if c.len() < self.bits.len() {
            self.recount();
        } else {
            self.set_count(count);
        }
    }
    /// After a change of `bits`: `count` of them are set.
    fn set_count(&mut self, count: usize) {
        self.changed();
        self.count = count;
        self.idx.clear();
        if self.sparse() {
            self.idx.extend(
                self.bits
                    .iter()
                    .enumerate()
                    .filter(|(_, &b)| b)
                    .map(|(i, _)| i as u32),
            );
        }
    }
    /// No point runs any more.
    pub fn clear(&mut self) {
        self.changed();
        self.bits.iter_mut().for_each(|b| *b = false);
        self.count = 0;
        self.idx.clear();
    }
    /// Becomes a copy of `other`, reusing this mask's buffers.
    pub fn copy_from(&mut self, other: &Mask) {
        // The select masks stay valid when the bits do not change (a loop's body and step
        // usually run over the same points).
        if self.bits != other.bits {
            self.changed();
        }
        self.bits.clear();
        self.bits.extend_from_slice(&other.bits);
        self.count = other.count;
        self.idx.clear();
        self.idx.extend_from_slice(&other.idx);
    }
    /// The select masks no longer match the bits.
    fn changed(&mut self) {
        let s = self.sel.get_mut();
        s.f_ok = false;
        s.t_ok = false;
    }
    /// One select mask per point (all ones where the point runs).
    fn sel_f(&self) -> std::cell::Ref<'_, [u32]> {
        {
            let mut s = self.sel.borrow_mut();
            if !s.f_ok {
                let SelMasks { f, f_ok, .. } = &mut *s;
                f.resize(self.bits.len(), 0);
                sel_from_bits(f, &self.bits);
                *f_ok = true;
            }
        }
        std::cell::Ref::map(self.sel.borrow(), |s| &s.f[..])
    }
    /// One select mask per component of a triple (three per point).
    fn sel_t(&self) -> std::cell::Ref<'_, [u32]> {
        {
            let mut s = self.sel.borrow_mut();
            if !s.t_ok {
                let SelMasks { t, t_ok, .. } = &mut *s;
                t.resize(3 * self.bits.len(), 0);
                sel3_from_bits(t, &self.bits);
                *t_ok = true;
            }
        }
        std::cell::Ref::map(self.sel.borrow(), |s| &s.t[..])
    }
    fn sparse(&self) -> bool {
        self.count * SPARSE_DIVISOR <= self.bits.len()
    }
    /// The points pointwise instructions compute under this mask.
    pub fn lanes(&self) -> Lanes<'_> {
        if self.sparse() && self.idx.len() == self.count {
            Lanes::Some(&self.idx)
        } else {
            Lanes::All
        }
    }
}

/// The transforms, lights and information a program may ask for.
pub struct Env<'a> {
    pub nu: usize,
    pub nv: usize,
    /// camera_from_space by name ("object", "shader", "world", "camera", "screen", "NDC",
    /// "raster", and CoordinateSystem names).
    pub spaces: &'a dyn Fn(&str) -> Option<Mat4>,
    /// Lights evaluated for this grid (surface and volume shaders).
    pub lights: &'a [LightResult],
    /// Whether diced normals were flipped (calculatenormal follows the same orientation).
    pub flip_normals: bool,
    pub near: f32,
    pub far: f32,
    pub shader_name: &'a str,
    pub diags: &'a Diagnostics,
    /// attribute()/option()/rendererinfo() answers.
    pub info: &'a dyn Fn(&str, &str) -> Option<InfoValue>,
    /// Texture lookups (None: textures are unavailable and return their fill value).
    pub textures: Option<&'a dyn TextureLookup>,
    /// Seed for random(): a hash of the grid's identity so results are deterministic.
    pub seed: u32,
    /// Ray queries (None: no ray tracing here; ray functions return their miss values).
    pub rays: Option<&'a dyn RayTracer>,
    /// On a grid of ray hits: each point's incoming ray cone, its width taken at the hit
    /// (rays cast from the point start with this footprint). None elsewhere.
    pub cones: Option<&'a [crate::ray::Cone]>,
    /// The displacement shader's output parameters on this grid (message passing:
    /// `displacement("name", var)` in the surface shader).
    pub displacement_outputs: &'a [crate::shade::GridVar],
    /// The surface shader's parameters as bound for this grid (message passing:
    /// `surface("name", var)` in light and volume shaders).
    pub surface_params: &'a [crate::shade::GridVar],
    /// The atmosphere shader's parameters as bound for this grid (message passing:
    /// `atmosphere("name", var)` in surface and light shaders).
    pub atmosphere_params: &'a [crate::shade::GridVar],
}

/// Ray queries from shaders, answered by the shading system over the frame's ray geometry.
/// Points are in camera ("current") space.
pub trait RayTracer {
    /// Ray depth of the grid being shaded (0 for grids the camera sees).
    fn depth(&self) -> u32;
    /// The hit's shaded `Ci` along each active ray (black on a miss or past the depth limit;
    /// partly transparent hits are seen through) and the distance to the first hit
    /// (infinite on a miss), in units of `dir`'s length. `cones` (one per ray, or empty for
    /// rays of no width) set the footprint the hit is shaded over.
    fn trace(
        &self,
        org: &[Vec3],
        dir: &[Vec3],
        cones: &[crate::ray::Cone],
        active: &[bool],
        ci: &mut [Vec3],
        dist: &mut [f32],
    );
    /// The fraction of light passing from `from` to `to` (1: nothing in the way), through the
    /// opacity `Os` of every shadow-casting surface between.
    fn transmission(&self, from: &[Vec3], to: &[Vec3], active: &[bool], out: &mut [Vec3]);
}

/// A value answered by attribute()/option()/rendererinfo()/message passing.
#[derive(Clone, Debug)]
pub enum InfoValue {
    Floats(Vec<f32>),
    Str(String),
}

/// Texture access from shaders (implemented by the texture system).
pub trait TextureLookup: Sync {
    /// Filtered lookup; returns `nchan` channels per point starting at `first_chan`.
    #[allow(clippy::too_many_arguments)]
    fn texture(
        &self,
        name: &str,
        first_chan: usize,
        nchan: usize,
        st: &[[f32; 8]],
        params: &TextureParams,
        out: &mut [f32],
    ) -> bool;

    /// Filtered environment lookup: per point the centre direction then 4 corner
    /// directions (the map's space). Returns `nchan` channels per point.
    #[allow(clippy::too_many_arguments)]
    fn environment(
        &self,
        _name: &str,
        _first_chan: usize,
        _nchan: usize,
        _dirs: &[[Vec3; 5]],
        _params: &TextureParams,
        _out: &mut [f32],
    ) -> bool {
        false
    }

    /// Fraction in shadow per point: the centre then the 4 footprint corners, world space.
    fn shadow(
        &self,
        _name: &str,
        _pts: &[[Vec3; 5]],
        _params: &TextureParams,
        _out: &mut [f32],
    ) -> bool {
        false
    }

    /// textureinfo(): "resolution", "type", "channels", "viewingmatrix", "projectionmatrix".
    fn info(&self, _name: &str, _query: &str) -> Option<InfoValue> {
        None
    }

    /// bump(): the filtered height gradient (∂B/∂s, ∂B/∂t) of channel `chan` over each
    /// footprint (corners as for `texture`), 2 values per point.
    fn bump_slopes(
        &self,
        _name: &str,
        _chan: usize,
        _st: &[[f32; 8]],
        _params: &TextureParams,
        _out: &mut [f32],
    ) -> bool {
        false
    }

    /// The directories texture names are looked up in after the name as given (horizon
    /// maps are found on the same path).
    fn search_path(&self) -> &[std::path::PathBuf] {
        &[]
    }
}

#[derive(Clone, Debug, Default)]
pub struct TextureParams {
    /// The larger of sblur and tblur (kept for callers that read one blur).
    pub blur: f32,
    /// Blur in s and t as fractions of the texture (RISpec "sblur"/"tblur"; "blur" sets both).
    pub sblur: f32,
    pub tblur: f32,
    pub swidth: f32,
    pub twidth: f32,
    pub fill: f32,
    pub filter: String,
    pub samples: f32,
    pub bias: f32,
}

/// One light's contribution on a grid.
#[derive(Clone, Debug)]
pub struct LightResult {
    pub ambient: bool,
    /// Points the light reaches (illuminate/solar cone).
    pub lit: Vec<bool>,
    /// Direction from the surface point toward the light (length = distance for local lights).
    pub l: Vec<Vec3>,
    /// The direction when it is the same at every point (distant lights).
    pub l_uniform: Option<Vec3>,
    pub cl: Vec<Vec3>,
    pub ol: Vec<Vec3>,
    pub category: Arc<str>,
    pub nondiffuse: bool,
    pub nonspecular: bool,
    /// The light's program and its parameters' values after the run, one per
    /// `program.params` entry (for lightsource()); None: no parameters to read.
    pub program: Option<Arc<Program>>,
    pub outputs: Vec<Slot>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum FrameKind {
    Loop,
    Function,
}

struct Frame {
    kind: FrameKind,
    broken: Vec<bool>,
    outward: Vec<bool>,
}

/// State of a light shader run: what illuminate/solar produced.
#[derive(Default, Clone)]
pub struct LightState {
    pub ran: bool,
    pub lit: Vec<bool>,
    /// P of the surface points being lit (shared by every light of a grid).
    pub ps: Arc<[Vec3]>,
    /// Normal of the surface being lit (for solar() without arguments).
    pub ns: Arc<[Vec3]>,
}

pub struct Exec<'a> {
    pub prog: &'a Program,
    pub regs: Vec<Slot>,
    pub n: usize,
    pub env: &'a Env<'a>,
    frames: Vec<Frame>,
    pub light: Option<LightState>,
    /// The light whose illuminance body is running (for lightsource()).
    pub current_light: Option<usize>,
    iterations: u64,
    /// Most iterations one execution of a loop statement may run (`Option "limits"
    /// "loopiterations"`); the whole run may loop [`RUN_LOOP_FACTOR`] times that.
    pub loop_limit: u64,
    /// The loop statements the guard stopped at the limit in this run: their later executions in it
    /// (an endless fBm called at each step of a march) are skipped, so a runaway loop
    /// costs its limit once per grid, not once per call.
    runaway: Vec<Span>,
    /// The specular exponent is this over `roughness` (see [`crate::shade::ops::spec_exponent`]):
    /// [`SPEC_SCALE_TIGHT`] unless the scene asks for RISpec's highlight.
    pub spec_scale: f32,
    /// Spare mask buffers, so control flow allocates nothing per instruction.
    bits_pool: Vec<Vec<bool>>,
    idx_pool: Vec<Vec<u32>>,
    sel_pool: Vec<SelMasks>,
    /// Where `env.lights` were evaluated (the grid's P), and how to evaluate them elsewhere:
    /// `illuminance(pos)` at other positions (a volume shader marching a ray) runs the lights
    /// again, once over the whole grid. None: `env.lights` serve every position.
    pub lights_at: Option<&'a [Vec3]>,
    pub relight: Option<&'a Relight<'a>>,
    /// The last lights evaluated away from the grid's P.
    relit: Option<Rc<RelitLights>>,
    /// The light set of the running illuminance body (None: `env.lights`).
    lights_in_use: Option<Rc<RelitLights>>,
    /// True inside `solar()` (a ray-traced shadow then looks along L to infinity rather than
    /// to the point `Ps − L`).
    pub in_solar: bool,
    /// Whether pointwise instructions may compute just the running points when few run
    /// (false: every instruction computes every point; same results, for tests).
    pub sparse: bool,
    /// Instructions run over the listed running points only, so far (for tests and stats).
    pub sparse_ops: u64,
    /// Whether loops marked compactable continue over just their running points once few
    /// run (false: never; same results, for tests).
    pub compact: bool,
    /// Inside a compacted loop: the grid index of each point (see [`Exec::point_id`]).
    point_ids: Option<Vec<u32>>,
    /// Loops continued over their running points only, so far (for tests and stats).
    pub compactions: u64,
}

/// A loop statement's code (see [`Instr::Loop`]).
#[derive(Clone, Copy)]
pub struct LoopCode<'a> {
    cond_code: &'a [Instr],
    cond: Reg,
    body: &'a [Instr],
    step: &'a [Instr],
    span: Span,
    compact: Option<&'a [(Reg, CompactUse)]>,
}

/// A compactable loop with at most `COMPACT_NUM / COMPACT_DEN` of its points running continues
/// over just those points (see [`Exec::run_compacted`]): gathering costs about one or two
/// iterations, and a march whose points leave at different steps runs for many more.
pub const COMPACT_NUM: usize = 3;
pub const COMPACT_DEN: usize = 4;

/// Grids smaller than this never compact.
pub const COMPACT_MIN: usize = 8;

/// The default of [`Exec::compact`] for new executions (tests turn it off to compare).
pub static COMPACT_LOOPS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Runs the grid's lights with the lit points at `ps`, for the lights flagged in `want` (by
/// index into `env.lights`; None where not wanted or not runnable).
///
/// With `Some(idx)` only the grid points `idx` are lit (the live points of a loop): `ps` holds
/// their positions in that order and the results have `idx.len()` entries.
pub type Relight<'a> = dyn Fn(&[Vec3], &[bool], Option<&[usize]>) -> Vec<Option<LightResult>> + 'a;

/// Lights evaluated at positions other than the grid's.
pub struct RelitLights {
    ps: Vec<Vec3>,
    /// The points the lights were run for (the others read unlit).
    active: Vec<bool>,
    want: Vec<bool>,
    lights: Vec<Option<LightResult>>,
}

impl RelitLights {
    fn recycle(self) {
        crate::shade::value::recycle([Slot::VT(self.ps)]);
        for l in self.lights.into_iter().flatten() {
            l.recycle();
        }
    }
}

impl LightResult {
    /// This result, computed for the grid points `idx`, spread over a grid of `n` points
    /// (the others unlit, with zero L and Cl).
    pub fn scattered(self, idx: &[usize], n: usize) -> LightResult {
        fn fill_in<T: Copy>(mut out: Vec<T>, v: &[T], idx: &[usize], fill: T) -> Vec<T> {
            out.fill(fill);
            for (k, &i) in idx.iter().enumerate() {
                if let Some(x) = v.get(k) {
                    out[i] = *x;
                }
            }
            out
        }
        fn spread<T: Copy>(v: &[T], idx: &[usize], n: usize, fill: T) -> Vec<T> {
            fill_in(vec![fill; n], v, idx, fill)
        }
        // Grid-sized buffers from this thread's pool (they are recycled with the result),
        // and the compact ones go back to it.
        use crate::shade::value::{grid_vf, grid_vt, recycle};
        let spread_t = |v: Vec<Vec3>, fill: Vec3| -> Vec<Vec3> {
            let out = fill_in(grid_vt(n), &v, idx, fill);
            recycle([Slot::VT(v)]);
            out
        };
        let outputs = self
            .outputs
            .into_iter()
            .map(|s| match s {
                Slot::VF(v) => {
                    let out = fill_in(grid_vf(n), &v, idx, 0.0);
                    recycle([Slot::VF(v)]);
                    Slot::VF(out)
                }
                Slot::VT(v) => Slot::VT(spread_t(v, Vec3::ZERO)),
                Slot::VM(v) => Slot::VM(spread(&v, idx, n, Mat4::IDENTITY)),
                s => s,
            })
            .collect();
        LightResult {
            ambient: self.ambient,
            lit: spread(&self.lit, idx, n, false),
            l: spread_t(self.l, Vec3::ZERO),
            l_uniform: self.l_uniform,
            cl: spread_t(self.cl, Vec3::ZERO),
            ol: spread_t(self.ol, Vec3::ONE),
            category: self.category,
            nondiffuse: self.nondiffuse,
            nonspecular: self.nonspecular,
            program: self.program,
            outputs,
        }
    }

    /// Gives the grid buffers back to this thread's pool.
    pub fn recycle(self) {
        crate::shade::value::recycle([Slot::VT(self.l), Slot::VT(self.cl), Slot::VT(self.ol)]);
        crate::shade::value::recycle(self.outputs);
    }
}

/// The default of [`Exec::sparse`] for new executions (tests turn it off to compare).
pub static SPARSE_LANES: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Default for [`Exec::loop_limit`]: ten times any real shader's loop (a ray march at the
/// smallest step real shaders use runs some ten thousand steps). Each iteration runs over the
/// whole grid: an fBm whose octave count is 1e9 costs some 4 µs an iteration on a grid of 170
/// points, so a million iterations a grid made a 64 × 48 picture of 28 grids take two minutes.
pub const DEFAULT_LOOP_LIMIT: u64 = 100_000;

/// A shader run (one grid) may loop this many times [`Exec::loop_limit`] in all its loop
/// statements together. Nested loops of real shaders (a march of ten thousand steps calling
/// an fBm of a dozen octaves) stay below it; an endless loop in a function called from many
/// places must not cost the limit at each call.
pub const RUN_LOOP_FACTOR: u64 = 16;

/// `specular()`'s exponent times `roughness` by default: the tight highlight of BMRT with its
/// `"prmanspecular"` on (Aqsis's `roughness/8` emulates the same), which most published
/// pictures show (early PRMan's were broader; see README's compatibility table).
pub const SPEC_SCALE_TIGHT: f32 = 8.0;
/// RISpec's reference `specular()`: `pow(N·H, 1/roughness)`, BMRT's with
/// `Option "render" "prmanspecular" [0]`.
pub const SPEC_SCALE_RISPEC: f32 = 1.0;

/// From this iteration on, a loop is checked for a fixed point at every power of two: when a
/// whole iteration leaves every register and the running mask unchanged, it can never end.
const FIRST_PROGRESS_CHECK: u64 = 1024;

/// Spare mask buffers of a finished execution, for the next one on this thread (a volume
/// march runs its lights as a new execution at every step: their masks would otherwise be
/// allocated and freed each time). Their contents are always overwritten before use.
#[derive(Default)]
struct SpareMasks {
    bits: Vec<Vec<bool>>,
    idx: Vec<Vec<u32>>,
    sel: Vec<SelMasks>,
}

thread_local! {
    static SPARE_MASKS: std::cell::Cell<Option<SpareMasks>> = const { std::cell::Cell::new(None) };
}

/// How many spare flag buffers this thread holds for its next execution (for tests).
pub fn spare_mask_buffers() -> usize {
    SPARE_MASKS.with(|s| {
        let k = s.take();
        let n = k.as_ref().map_or(0, |k| k.bits.len());
        s.set(k);
        n
    })
}

/// At most this many spare buffers of each kind are kept for the next execution.
const SPARE_MAX: usize = 64;

impl Drop for Exec<'_> {
    fn drop(&mut self) {
        let mut bits = std::mem::take(&mut self.bits_pool);
        for f in self.frames.drain(..) {
            bits.push(f.broken);
            bits.push(f.outward);
        }
        bits.truncate(SPARE_MAX);
        let mut idx = std::mem::take(&mut self.idx_pool);
        idx.truncate(SPARE_MAX);
        let mut sel = std::mem::take(&mut self.sel_pool);
        sel.truncate(SPARE_MAX);
        let mine = SpareMasks { bits, idx, sel };
        SPARE_MASKS.with(|s| {
            // An execution running inside another (a light inside a surface's illuminance)
            // ends first and leaves its buffers; the outer one keeps those.
            let kept = s.take();
            s.set(Some(match kept {
                Some(k) if k.bits.len() >= mine.bits.len() => k,
                _ => mine,
            }));
        });
    }
}

impl<'a> Exec<'a> {
    /// Loop iterations run so far in this execution (deterministic for a program and grid):
    /// lets `random()` inside a loop give new numbers on every iteration.
    pub fn loop_iterations(&self) -> u64 {
        self.iterations
    }

    /// A register file with constants set and every other register zeroed.
    pub fn new(prog: &'a Program, n: usize, env: &'a Env<'a>) -> Exec<'a> {
        let mut regs: Vec<Slot> = prog
            .regs
            .iter()
            .map(|r| match r.kind {
                Kind::Float => Slot::F(0.0),
                Kind::Triple => Slot::T(Vec3::ZERO),
                Kind::Matrix => Slot::M(Box::new(Mat4::IDENTITY)),
                Kind::Str => Slot::S(crate::shade::value::empty_str()),
            })
            .collect();
        for (r, c) in &prog.consts {
            regs[*r as usize] = match c {
                Const::F(x) => Slot::F(*x),
                Const::T(x) => Slot::T(*x),
                Const::M(x) => Slot::M(Box::new(*x)),
                Const::S(x) => Slot::S(x.clone()),
            };
        }
        let spare = SPARE_MASKS.with(|s| s.take()).unwrap_or_default();
        Exec {
            prog,
            regs,
            n,
            env,
            frames: Vec::new(),
            in_solar: false,
            sparse: SPARSE_LANES.load(std::sync::atomic::Ordering::Relaxed),
            sparse_ops: 0,
            compact: COMPACT_LOOPS.load(std::sync::atomic::Ordering::Relaxed),
            point_ids: None,
            compactions: 0,
            light: None,
            current_light: None,
            iterations: 0,
            loop_limit: DEFAULT_LOOP_LIMIT,
            runaway: Vec::new(),
            spec_scale: SPEC_SCALE_TIGHT,
            bits_pool: spare.bits,
            idx_pool: spare.idx,
            sel_pool: spare.sel,
            lights_at: None,
            relight: None,
            relit: None,
            lights_in_use: None,
        }
    }

    /// A copy of `m` in pooled buffers (give it back with [`Exec::release_mask`]).
    fn mask_like(&mut self, m: &Mask) -> Mask {
        let mut bits = self.bits_pool.pop().unwrap_or_default();
        bits.clear();
        bits.extend_from_slice(&m.bits);
        let mut idx = self.idx_pool.pop().unwrap_or_default();
        idx.clear();
        idx.extend_from_slice(&m.idx);
        let mut sel = self.sel_pool.pop().unwrap_or_default();
        sel.f_ok = false;
        sel.t_ok = false;
        Mask {
            bits,
            count: m.count,
            idx,
            sel: std::cell::RefCell::new(sel),
        }
    }

    /// `n` flags set to `v`, in a pooled buffer.
    fn bits_filled(&mut self, v: bool) -> Vec<bool> {
        let mut bits = self.bits_pool.pop().unwrap_or_default();
        bits.clear();
        bits.resize(self.n, v);
        bits
    }

    fn release(&mut self, bits: Vec<bool>) {
        self.bits_pool.push(bits);
    }

    fn release_mask(&mut self, m: Mask) {
        self.bits_pool.push(m.bits);
        self.idx_pool.push(m.idx);
        self.sel_pool.push(m.sel.into_inner());
    }

    fn push_frame(&mut self, kind: FrameKind) {
        let broken = self.bits_filled(false);
        let outward = self.bits_filled(false);
        self.frames.push(Frame {
            kind,
            broken,
            outward,
        });
    }

    fn pop_frame(&mut self) -> Option<Frame> {
        self.frames.pop()
    }

    /// Gives a popped frame's buffers back to the pool.
    fn recycle_frame(&mut self, f: Frame) {
        self.release(f.broken);
        self.release(f.outward);
    }

    pub fn warn(&self, span: Span, msg: impl Into<String>) {
        self.env.diags.report(
            Diag::warning(
                "shade::runtime",
                format!("shader `{}`: {}", self.env.shader_name, msg.into()),
            )
            .label(span, "here"),
        );
    }

    /// Runs parameter defaults.
    pub fn run_init(&mut self) {
        let mut mask = Mask::all(self.n);
        let init = &self.prog.init;
        self.block(init, &mut mask);
    }

    /// Runs the body over every point.
    pub fn run_body(&mut self) {
        let mut mask = Mask::all(self.n);
        self.push_frame(FrameKind::Function);
        let body = &self.prog.body;
        self.block(body, &mut mask);
        if let Some(f) = self.pop_frame() {
            self.recycle_frame(f);
        }
    }

    /// Sets a register to a value (used to bind globals and parameters).
    pub fn set(&mut self, reg: Reg, v: Slot) {
        self.regs[reg as usize] = v;
    }

    fn block(&mut self, instrs: &'a [Instr], mask: &mut Mask) {
        for i in instrs {
            if mask.is_none() {
                return;
            }
            self.instr(i, mask);
        }
    }

    /// A uniform condition's value, or None when it is varying.
    fn uniform_cond(&self, reg: Reg) -> Option<bool> {
        match &self.regs[reg as usize] {
            Slot::VF(_) => None,
            s => Some(s.f().first() != 0.0),
        }
    }

    fn exit_to(&mut self, levels: usize, kind_stop: Option<FrameKind>, mask: &mut Mask) {
        // Record the exiting points in the innermost `levels` frames.
        let len = self.frames.len();
        let mut k = 0;
        while k < levels && k < len {
            let f = &mut self.frames[len - 1 - k];
            let last = k + 1 == levels;
            for (i, &b) in mask.bits.iter().enumerate() {
                if b {
                    f.broken[i] = true;
                    if !last {
                        f.outward[i] = true;
                    }
                }
            }
            if Some(f.kind) == kind_stop {
                break;
            }
            k += 1;
        }
        mask.clear();
    }

    fn instr(&mut self, ins: &'a Instr, mask: &mut Mask) {
        let n = self.n;
        match ins {
            Instr::Mov { dst, src } => self.mov(*dst, *src, mask),
            Instr::Copy { dst, src } => {
                let v = self.regs[*src as usize].clone();
                let info = self.prog.regs[*dst as usize];
                self.regs[*dst as usize] = if info.varying && !v.is_varying() {
                    broadcast(&v, n)
                } else {
                    v
                };
            }
            Instr::If {
                cond,
                then,
                otherwise,
            } => match self.uniform_cond(*cond) {
                Some(true) => self.block(then, mask),
                Some(false) => self.block(otherwise, mask),
                None => {
                    let mut t = self.mask_like(mask);
                    let mut e = self.mask_like(mask);
                    if let Slot::VF(c) = &self.regs[*cond as usize] {
                        for ((tb, eb), &c) in t.bits.iter_mut().zip(e.bits.iter_mut()).zip(c) {
                            *tb &= c != 0.0;
                            *eb &= c == 0.0;
                        }
                    }
                    t.recount();
                    e.recount();
                    if !t.is_none() {
                        self.block(then, &mut t);
                    }
                    if !e.is_none() && !otherwise.is_empty() {
                        self.block(otherwise, &mut e);
                    }
                    for ((m, &tb), &eb) in mask.bits.iter_mut().zip(&t.bits).zip(&e.bits) {
                        *m = tb || eb;
                    }
                    mask.recount();
                    self.release_mask(t);
                    self.release_mask(e);
                }
            },
            Instr::Loop {
                cond_code,
                cond,
                body,
                step,
                span,
                compact,
            } => self.run_loop(
                LoopCode {
                    cond_code,
                    cond: *cond,
                    body,
                    step,
                    span: *span,
                    compact: compact.as_deref(),
                },
                mask,
                0,
            ),
            Instr::Break(k) => self.exit_to(*k as usize, None, mask),
            Instr::Continue(k) => {
                let k = *k as usize;
                // Inner loops are left; loop k skips to its step.
                if k > 1 {
                    let mut m = self.mask_like(mask);
                    self.exit_to(k - 1, None, &mut m);
                    self.release_mask(m);
                }
                mask.clear();
            }
            Instr::Return => {
                let levels = self
                    .frames
                    .iter()
                    .rev()
                    .position(|f| f.kind == FrameKind::Function)
                    .map(|p| p + 1);
                self.exit_to(
                    levels.unwrap_or(self.frames.len()),
                    Some(FrameKind::Function),
                    mask,
                );
            }
            Instr::Function { body } => {
                self.push_frame(FrameKind::Function);
                let mut m = self.mask_like(mask);
                self.block(body, &mut m);
                self.release_mask(m);
                if let Some(f) = self.pop_frame() {
                    self.recycle_frame(f);
                }
            }
            Instr::Illuminance {
                category,
                pos,
                axis,
                body,
            } => self.illuminance(*category, *pos, *axis, body, mask),
            Instr::Illuminate { pos, axis, body } => self.illuminate(Some(*pos), *axis, body, mask),
            Instr::Solar { axis, body } => self.illuminate(None, *axis, body, mask),
            Instr::Gather {
                pos,
                dir,
                angle,
                samples,
                outputs,
                body,
                otherwise,
            } => self.gather(
                [*pos, *dir, *angle, *samples],
                outputs,
                body,
                otherwise,
                mask,
            ),
            Instr::SetIndex {
                kind: _,
                base,
                len,
                index,
                src,
                span,
            } => {
                let idx_slot = self.regs[*index as usize].clone();
                let idx = idx_slot.f();
                let mut warned = false;
                if !idx.is_varying() {
                    let i = idx.first() as i64;
                    let i = if i < 0 || i >= *len as i64 {
                        warned = true;
                        i.clamp(0, *len as i64 - 1)
                    } else {
                        i
                    };
                    self.mov(*base + i as Reg, *src, mask);
                } else {
                    for k in 0..*len {
                        let sel: Vec<bool> = (0..n)
                            .map(|p| {
                                let i = idx.at(p) as i64;
                                if i < 0 || i >= *len as i64 {
                                    warned = true;
                                }
                                mask.bits[p] && i.clamp(0, *len as i64 - 1) == k as i64
                            })
                            .collect();
                        let m = Mask::from_bits(sel);
                        if !m.is_none() {
                            self.mov(*base + k, *src, &m);
                        }
                    }
                }
                if warned {
                    self.warn(*span, "array index out of range (clamped)");
                }
            }
            other => ops::compute(self, other, mask),
        }
    }

    /// One loop statement: condition, body, step until no point is left, under the guard
    /// against loops that never end (see [`DEFAULT_LOOP_LIMIT`], [`FIRST_PROGRESS_CHECK`]).
    /// `done`: iterations this execution of the statement already ran (a compacted
    /// continuation, see [`Exec::run_compacted`]).
    fn run_loop(&mut self, code: LoopCode<'a>, mask: &mut Mask, done: u64) {
        let LoopCode {
            cond_code,
            cond,
            body,
            step,
            span,
            compact,
        } = code;
        if self.runaway.contains(&span) {
            // Stopped by the guard earlier in this run (and reported then): it would run
            // to the limit again.
            return;
        }
        self.push_frame(FrameKind::Loop);
        let mut live = self.mask_like(mask);
        let mut scratch = self.mask_like(mask);
        let total_limit = self.loop_limit.saturating_mul(RUN_LOOP_FACTOR);
        let mut count: u64 = done;
        let mut snapshot: Option<(Vec<Slot>, Vec<bool>)> = None;
        loop {
            if let Some(regs) = compact {
                if self.compact
                    && self.n >= COMPACT_MIN
                    && live.count * COMPACT_DEN <= self.n * COMPACT_NUM
                    && !live.is_none()
                {
                    // The points still looping continue in a grid of just them; every one
                    // of them leaves the loop there.
                    if self.run_compacted(code, regs, &live, count) {
                        break;
                    }
                }
            }
            self.iterations += 1;
            count += 1;
            if count > self.loop_limit || self.iterations > total_limit {
                self.runaway_loop(span, count - 1, false);
                break;
            }
            scratch.copy_from(&live);
            self.block(cond_code, &mut scratch);
            match &self.regs[cond as usize] {
                Slot::VF(c) => live.and_nonzero(c),
                s => {
                    if s.f().first() == 0.0 {
                        break;
                    }
                }
            }
            if live.is_none() {
                break;
            }
            scratch.copy_from(&live);
            self.block(body, &mut scratch);
            if let Some(f) = self.frames.last() {
                live.and_not(&f.broken);
            }
            if live.is_none() {
                break;
            }
            scratch.copy_from(&live);
            self.block(step, &mut scratch);
            if count >= FIRST_PROGRESS_CHECK {
                if count.is_power_of_two() {
                    if let Some((regs, _)) = snapshot.take() {
                        crate::shade::value::recycle(regs);
                    }
                    snapshot = Some((self.regs.clone(), live.bits.clone()));
                } else if let Some((regs, bits)) = snapshot.take() {
                    // One whole iteration since the snapshot: did anything change?
                    let stuck = bits == live.bits
                        && regs.iter().zip(&self.regs).all(|(a, b)| same_slot(a, b));
                    crate::shade::value::recycle(regs);
                    if stuck {
                        self.runaway_loop(span, count, true);
                        break;
                    }
                }
            }
        }
        if let Some((regs, _)) = snapshot.take() {
            crate::shade::value::recycle(regs);
        }
        self.release_mask(live);
        self.release_mask(scratch);
        if let Some(f) = self.pop_frame() {
            mask.and_not(&f.outward);
            self.recycle_frame(f);
        }
    }

    /// Runs the rest of a loop over the points of `live` only, gathered into a grid of just
    /// them: the loop's varying registers are cut down to those points, the loop runs there
    /// (at full vector width: no lanes of points that left are computed), and what it wrote
    /// is put back at the points' places. Only loops marked by
    /// [`Program::mark_compact_loops`] come here: everything in them is pointwise, and no
    /// value a point left behind is read, so the results are those of running over the
    /// whole grid. `random()` still sees each point's grid index ([`Exec::point_id`]).
    /// Returns false (nothing done) when a register the loop names has an unexpected size.
    fn run_compacted(
        &mut self,
        code: LoopCode<'a>,
        regs: &[(Reg, CompactUse)],
        live: &Mask,
        done: u64,
    ) -> bool {
        let n = self.n;
        let fits = regs.iter().all(|&(r, _)| match &self.regs[r as usize] {
            Slot::VF(v) => v.len() == n,
            Slot::VT(v) => v.len() == n,
            Slot::VM(v) => v.len() == n,
            _ => true,
        });
        if !fits {
            return false;
        }
        let mut idx = self.idx_pool.pop().unwrap_or_default();
        idx.clear();
        idx.extend(
            live.bits
                .iter()
                .enumerate()
                .filter(|(_, &b)| b)
                .map(|(i, _)| i as u32),
        );
        let m = idx.len();
        self.compactions += 1;
        // The loop's registers cut to the points; the whole-grid values set aside (uniform
        // values are shared: they serve any grid size). Temporaries start empty: the loop
        // computes them before reading them.
        let mut saved: Vec<Slot> = Vec::with_capacity(regs.len());
        for &(r, u) in regs {
            let slot = &mut self.regs[r as usize];
            let cut = match (u, &*slot) {
                // The loop computes it before reading it, and nothing after the loop reads
                // it: its buffer goes in as it is (a computation over every point of the
                // smaller grid shortens it in place, no new buffer, no zero-fill).
                (CompactUse::Temp, _) => {
                    saved.push(Slot::F(0.0));
                    continue;
                }
                (_, Slot::VF(v)) => {
                    let mut c = crate::shade::value::grid_vf(m);
                    for (o, &i) in c.iter_mut().zip(&idx) {
                        *o = v[i as usize];
                    }
                    Slot::VF(c)
                }
                (_, Slot::VT(v)) => {
                    let mut c = crate::shade::value::grid_vt(m);
                    for (o, &i) in c.iter_mut().zip(&idx) {
                        *o = v[i as usize];
                    }
                    Slot::VT(c)
                }
                (_, Slot::VM(v)) => Slot::VM(idx.iter().map(|&i| v[i as usize]).collect()),
                (_, other) => {
                    saved.push(other.clone());
                    continue;
                }
            };
            saved.push(std::mem::replace(slot, cut));
        }
        let outer_ids = self.point_ids.take();
        let ids: Vec<u32> = match &outer_ids {
            Some(o) => idx.iter().map(|&i| o[i as usize]).collect(),
            None => idx.clone(),
        };
        self.point_ids = Some(ids);
        self.n = m;
        let mut all = Mask::all(m);
        self.run_loop(code, &mut all, done);
        self.n = n;
        self.point_ids = outer_ids;
        // Put back what the loop stored. A register that held one value for the whole grid
        // before and varies now is spread over the grid first (the points that were not in
        // the loop keep that value). Registers only read, and temporaries, get their
        // whole-grid values back.
        for (&(r, u), old) in regs.iter().zip(saved) {
            if u == CompactUse::Temp {
                // Left as the loop left it (see above); nothing reads it.
                continue;
            }
            let new = std::mem::take(&mut self.regs[r as usize]);
            if u != CompactUse::Stored {
                crate::shade::value::recycle([new]);
                self.regs[r as usize] = old;
                continue;
            }
            self.regs[r as usize] = match new {
                Slot::VF(c) => {
                    let mut v = match old {
                        Slot::VF(v) => v,
                        s => match broadcast(&s, n) {
                            Slot::VF(v) => v,
                            _ => vec![0.0; n],
                        },
                    };
                    for (&x, &i) in c.iter().zip(&idx) {
                        v[i as usize] = x;
                    }
                    crate::shade::value::recycle([Slot::VF(c)]);
                    Slot::VF(v)
                }
                Slot::VT(c) => {
                    let mut v = match old {
                        Slot::VT(v) => v,
                        s => match broadcast(&s, n) {
                            Slot::VT(v) => v,
                            _ => vec![Vec3::ZERO; n],
                        },
                    };
                    for (&x, &i) in c.iter().zip(&idx) {
                        v[i as usize] = x;
                    }
                    crate::shade::value::recycle([Slot::VT(c)]);
                    Slot::VT(v)
                }
                Slot::VM(c) => {
                    let mut v = match old {
                        Slot::VM(v) => v,
                        s => match broadcast(&s, n) {
                            Slot::VM(v) => v,
                            _ => vec![Mat4::IDENTITY; n],
                        },
                    };
                    for (&x, &i) in c.iter().zip(&idx) {
                        v[i as usize] = x;
                    }
                    Slot::VM(v)
                }
                // A uniform result: what running over the whole grid leaves too.
                s => {
                    crate::shade::value::recycle([old]);
                    s
                }
            };
        }
        idx.clear();
        self.idx_pool.push(idx);
        true
    }

    /// The grid index of point `i` of the grid being run (they differ inside a compacted
    /// loop, see [`Exec::run_compacted`]).
    #[inline]
    pub fn point_id(&self, i: usize) -> u32 {
        match &self.point_ids {
            Some(ids) => ids[i],
            None => i as u32,
        }
    }

    /// The warning of a loop stopped by the guard; the points still in it keep their values.
    fn runaway_loop(&mut self, span: Span, count: u64, stuck: bool) {
        // A loop stopped for want of progress cost little, and may progress at its next
        // execution (other arguments); one stopped at the limit is skipped from now on.
        if !stuck && !self.runaway.contains(&span) {
            self.runaway.push(span);
        }
        let what = if stuck {
            format!("this loop stopped making progress (an iteration changed nothing) after {count} iterations")
        } else {
            format!("this loop ran {count} iterations without ending")
        };
        self.env.diags.report(
            Diag::warning(
                "shade::runaway_loop",
                format!(
                    "shader `{}`: {what}; it was stopped and the grid is shaded with the values it had",
                    self.env.shader_name
                ),
            )
            .label(span, "this loop")
            .help(format!(
                "a loop may run {} iterations per grid; a shader that needs more can raise it with `Option \"limits\" \"loopiterations\" [{}]`",
                self.loop_limit,
                self.loop_limit.saturating_mul(10)
            )),
        );
    }

    /// Masked store, broadcasting uniform sources into varying destinations.
    pub fn mov(&mut self, dst: Reg, src: Reg, mask: &Mask) {
        let n = self.n;
        let dinfo = self.prog.regs[dst as usize];
        if dst == src {
            return;
        }
        if !dinfo.varying {
            // Uniform destination: uniform source (checked at compile time).
            let v = self.regs[src as usize].clone();
            self.regs[dst as usize] = match v {
                Slot::VF(x) => Slot::F(first_active(&x, mask)),
                Slot::VT(x) => Slot::T(first_active(&x, mask)),
                Slot::VM(x) => Slot::M(Box::new(first_active(&x, mask))),
                s => s,
            };
            return;
        }
        let all = mask.is_all();
        if all
            && self
                .prog
                .movable
                .get(src as usize)
                .copied()
                .unwrap_or(false)
        {
            // A temporary read only here: hand its buffer over instead of copying the grid.
            let fits = match (&self.regs[src as usize], dinfo.kind) {
                (Slot::VF(v), Kind::Float) => v.len() == n,
                (Slot::VT(v), Kind::Triple) => v.len() == n,
                (Slot::VM(v), Kind::Matrix) => v.len() == n,
                _ => false,
            };
            if fits {
                // Swapped, not taken: the temporary keeps the variable's old buffer, which
                // its next computation (a loop's next iteration) writes in place instead of
                // allocating and zero-filling a new one. Nothing reads the temporary but this
                // store, and the old values are this run's own.
                self.regs.swap(dst as usize, src as usize);
                return;
            }
        }
        let mut out = std::mem::take(&mut self.regs[dst as usize]);
        let s = &self.regs[src as usize];
        match dinfo.kind {
            Kind::Float => {
                let a = s.f();
                let mut v = match out {
                    Slot::VF(v) if v.len() == n => v,
                    Slot::F(x) => {
                        let mut v = crate::shade::value::grid_vf(n);
                        v.fill(x);
                        v
                    }
                    // Zeros where the mask leaves it unset (never a pooled buffer's old
                    // contents, which depend on what ran before on this thread).
                    _ => {
                        let mut v = crate::shade::value::grid_vf(n);
                        v.fill(0.0);
                        v
                    }
                };
                store_f(&mut v, a, mask);
                out = Slot::VF(v);
            }
            Kind::Triple => {
                let a = s.t();
                let mut v = match out {
                    Slot::VT(v) if v.len() == n => v,
                    Slot::T(x) => crate::shade::value::grid_vt_filled(n, x),
                    _ => crate::shade::value::grid_vt_filled(n, Vec3::ZERO),
                };
                store_t(&mut v, a, mask);
                out = Slot::VT(v);
            }
            Kind::Matrix => {
                let a = s.m();
                let mut v = match out {
                    Slot::VM(v) if v.len() == n => v,
                    Slot::M(x) => vec![*x; n],
                    _ => vec![Mat4::IDENTITY; n],
                };
                for i in 0..n {
                    if all || mask.bits[i] {
                        v[i] = a.at(i);
                    }
                }
                out = Slot::VM(v);
            }
            Kind::Str => out = s.clone(),
        }
        self.regs[dst as usize] = out;
    }

    /// The points a pointwise instruction writing `dst` computes under `mask`.
    #[inline]
    pub fn lanes_for<'m>(&mut self, dst: Reg, mask: &'m Mask) -> Lanes<'m> {
        if self.sparse
            && !self
                .prog
                .full_width
                .get(dst as usize)
                .copied()
                .unwrap_or(true)
        {
            let l = mask.lanes();
            if let Lanes::Some(_) = l {
                self.sparse_ops += 1;
            }
            l
        } else {
            Lanes::All
        }
    }

    fn reg_of(&self, name: &str) -> Option<Reg> {
        self.prog.global(name).map(|g| g.reg)
    }

    /// The lights `illuminance(pos)` sees: those of the grid when `pos` is the grid's P,
    /// otherwise every wanted light run again at `pos` (cached while the positions repeat).
    /// Only the running points are lit: a volume march whose points leave its loop at
    /// different steps runs its lights (often marching loops themselves) on the points still
    /// marching, not on the whole grid. None: the grid's lights.
    fn lights_at(&mut self, pos: Reg, cat: Option<&str>, mask: &Mask) -> Option<Rc<RelitLights>> {
        let relight = self.relight?;
        let at = self.lights_at?;
        let n = self.n;
        let p = self.regs[pos as usize].t();
        let same = match p {
            T::V(v) => v.len() == at.len() && v.iter().zip(at).all(|(a, b)| a == b),
            T::U(x) => at.iter().all(|a| *a == x),
        };
        if same {
            return None;
        }
        let want: Vec<bool> = self
            .env
            .lights
            .iter()
            .map(|l| !l.ambient && cat.is_none_or(|c| category_matches(c, &l.category)))
            .collect();
        if let Some(c) = &self.relit {
            if c.want == want
                && (0..n).all(|i| !mask.bits[i] || (c.active[i] && c.ps[i] == p.at(i)))
            {
                return Some(c.clone());
            }
        }
        // Pooled: RelitLights::recycle gives it back.
        let mut ps = crate::shade::value::grid_vt(n);
        for (i, o) in ps.iter_mut().enumerate() {
            *o = p.at(i);
        }
        let lights = if mask.is_all() {
            relight(&ps, &want, None)
        } else {
            let idx: Vec<usize> = (0..n).filter(|&i| mask.bits[i]).collect();
            let sub: Vec<Vec3> = idx.iter().map(|&i| ps[i]).collect();
            relight(&sub, &want, Some(&idx))
                .into_iter()
                .map(|l| l.map(|l| l.scattered(&idx, n)))
                .collect()
        };
        if let Some(old) = self.relit.take() {
            if let Ok(old) = Rc::try_unwrap(old) {
                old.recycle();
            }
        }
        let r = Rc::new(RelitLights {
            ps,
            active: mask.bits.clone(),
            want,
            lights,
        });
        self.relit = Some(r.clone());
        Some(r)
    }

    /// The light `lightsource()` reads inside an illuminance body.
    pub fn current_light_result(&self) -> Option<&LightResult> {
        self.current_light_ref()
    }

    fn current_light_ref(&self) -> Option<&LightResult> {
        let li = self.current_light?;
        match &self.lights_in_use {
            Some(r) => r.lights.get(li)?.as_ref(),
            None => self.env.lights.get(li),
        }
    }

    fn illuminance(
        &mut self,
        category: Option<Reg>,
        pos: Reg,
        axis: Option<(Reg, Reg)>,
        body: &'a [Instr],
        mask: &mut Mask,
    ) {
        let n = self.n;
        let cat = category.map(|r| self.regs[r as usize].s());
        let (lr, clr, olr) = (self.reg_of("L"), self.reg_of("Cl"), self.reg_of("Ol"));
        let axis_vals =
            axis.map(|(a, ang)| (self.regs[a as usize].t(), self.regs[ang as usize].f()));
        let axis_vals: Option<(Vec<Vec3>, Vec<f32>)> = axis_vals.map(|(a, ang)| {
            (
                (0..n).map(|i| a.at(i)).collect(),
                (0..n).map(|i| ang.at(i)).collect(),
            )
        });
        let relit = self.lights_at(pos, cat.as_deref(), mask);
        let outer = std::mem::replace(&mut self.lights_in_use, relit.clone());
        let grid_lights = self.env.lights;
        for li in 0..grid_lights.len() {
            let light = match &relit {
                Some(r) => match &r.lights[li] {
                    Some(l) => l,
                    None => continue,
                },
                None => &grid_lights[li],
            };
            if light.ambient {
                continue;
            }
            if let Some(c) = &cat {
                if !category_matches(c, &light.category) {
                    continue;
                }
            }
            let mut m = self.mask_like(mask);
            let mut any = false;
            for (i, b) in m.bits.iter_mut().enumerate() {
                if !(*b && light.lit[i]) {
                    *b = false;
                    continue;
                }
                let ok = match &axis_vals {
                    Some((ax, ang)) => {
                        let l = light.l[i];
                        let (al, ll) = (ax[i].length(), l.length());
                        if al == 0.0 || ll == 0.0 {
                            true
                        } else {
                            let c = ax[i].dot(l) / (al * ll);
                            c >= ang[i].min(std::f32::consts::PI).cos() - 1e-6
                        }
                    }
                    None => true,
                };
                *b = ok;
                any |= ok;
            }
            if !any {
                self.release_mask(m);
                continue;
            }
            m.recount();
            for (reg, values) in [(lr, &light.l), (clr, &light.cl), (olr, &light.ol)] {
                if let Some(r) = reg {
                    let mut v = take_vt(&mut self.regs[r as usize], n);
                    v.copy_from_slice(values);
                    self.regs[r as usize] = Slot::VT(v);
                }
            }
            self.current_light = Some(li);
            self.block(body, &mut m);
            self.current_light = None;
            self.release_mask(m);
        }
        self.lights_in_use = outer;
    }

    /// gather: per sample, the rays that hit run `body`, the others `otherwise` (see
    /// [`Instr::Gather`]). Without a ray tracer every ray misses.
    fn gather(
        &mut self,
        [pos, dir, angle, samples]: [Reg; 4],
        outputs: &'a [(String, Reg)],
        body: &'a [Instr],
        otherwise: &'a [Instr],
        mask: &mut Mask,
    ) {
        let n = self.n;
        let Some(rt) = self.env.rays else {
            self.block(otherwise, mask);
            return;
        };
        let p: Vec<Vec3> = {
            let t = self.regs[pos as usize].t();
            (0..n).map(|i| t.at(i)).collect()
        };
        let d: Vec<Vec3> = {
            let t = self.regs[dir as usize].t();
            (0..n).map(|i| t.at(i).normalize_or_zero()).collect()
        };
        let cone = self.regs[angle as usize].f().first();
        let count = self.regs[samples as usize]
            .f()
            .first()
            .round()
            .clamp(1.0, 4096.0) as u32;
        let salt = crate::pattern::hash::hash_u32(pos ^ (dir << 16) ^ 0x6a7);
        let start = mask.clone();
        let mut ci = vec![Vec3::ZERO; n];
        let mut oi = vec![Vec3::ZERO; n];
        let mut dist = vec![0f32; n];
        let cones = crate::shade::ops::rayops::cones(
            self,
            &p,
            &d,
            crate::shade::ops::rayops::sample_spread(cone, count),
        );
        for k in 0..count {
            let dirs: Vec<Vec3> = (0..n)
                .map(|i| {
                    let (u1, u2) =
                        crate::ray::stratified(crate::ray::point_seed(p[i], salt), k, count);
                    crate::ray::cosine_dir(d[i], u1, u2, cone)
                })
                .collect();
            rt.trace(&p, &dirs, &cones, &start.bits, &mut ci, &mut dist);
            let _ = &mut oi;
            let hit: Vec<bool> = (0..n)
                .map(|i| start.bits[i] && dist[i].is_finite())
                .collect();
            for (name, reg) in outputs {
                let r = *reg as usize;
                let vals: Option<Vec<Vec3>> = match name.as_str() {
                    // PRMan's "volume:" forms are the hit's colour after the volumes along
                    // the ray; arbor's rays give the surface's (what 3Delight's
                    // "surface:Ci" gives the same shaders).
                    "surface:Ci" | "volume:Ci" => Some(ci.clone()),
                    "surface:Oi" | "volume:Oi" => Some(vec![Vec3::ONE; n]),
                    "ray:direction" => Some(dirs.clone()),
                    "ray:origin" => Some(p.clone()),
                    "primitive:P" | "surface:P" => {
                        Some((0..n).map(|i| p[i] + dirs[i] * dist[i].min(1e30)).collect())
                    }
                    "ray:length" => {
                        let cur = self.regs[r].f();
                        let v: Vec<f32> = (0..n)
                            .map(|i| if hit[i] { dist[i] } else { cur.at(i) })
                            .collect();
                        self.regs[r] = if self.prog.regs[r].varying {
                            Slot::VF(v)
                        } else {
                            Slot::F(v.first().copied().unwrap_or(0.0))
                        };
                        None
                    }
                    _ => None,
                };
                if let Some(vals) = vals {
                    let cur = self.regs[r].t();
                    let v: Vec<Vec3> = (0..n)
                        .map(|i| if hit[i] { vals[i] } else { cur.at(i) })
                        .collect();
                    self.regs[r] = if self.prog.regs[r].varying {
                        Slot::VT(v)
                    } else {
                        Slot::T(v.first().copied().unwrap_or(Vec3::ZERO))
                    };
                }
            }
            let miss: Vec<bool> = (0..n).map(|i| start.bits[i] && !hit[i]).collect();
            let mut hm = Mask::from_bits(hit);
            if !hm.is_none() {
                self.block(body, &mut hm);
            }
            let mut mm = Mask::from_bits(miss);
            if !mm.is_none() {
                self.block(otherwise, &mut mm);
            }
        }
    }

    fn illuminate(
        &mut self,
        pos: Option<Reg>,
        axis: Option<(Reg, Reg)>,
        body: &'a [Instr],
        mask: &mut Mask,
    ) {
        let n = self.n;
        let Some(state) = self.light.take() else {
            return;
        };
        self.in_solar = pos.is_none();
        let lreg = self.reg_of("L");
        // L reuses the register's buffer; the lit mask a pooled one.
        let mut l = match lreg {
            Some(r) => take_vt(&mut self.regs[r as usize], n),
            None => crate::shade::value::grid_vt(n),
        };
        match pos {
            Some(p) => match self.regs[p as usize].t() {
                T::U(from) => {
                    for (li, &p) in l.iter_mut().zip(state.ps.iter()) {
                        *li = p - from;
                    }
                }
                from => {
                    for (i, li) in l.iter_mut().enumerate() {
                        *li = state.ps[i] - from.at(i);
                    }
                }
            },
            None => match axis {
                Some((a, _)) => {
                    let ax = self.regs[a as usize].t();
                    for (i, li) in l.iter_mut().enumerate() {
                        *li = ax.at(i);
                    }
                }
                None => {
                    for (li, ni) in l.iter_mut().zip(state.ns.iter()) {
                        *li = -*ni;
                    }
                }
            },
        }
        let mut m = self.mask_like(mask);
        if let (Some(_), Some((a, ang))) = (pos, axis) {
            let ax = self.regs[a as usize].t();
            let an = self.regs[ang as usize].f();
            let cos_of = |x: f32| x.min(std::f32::consts::PI).cos() - 1e-6;
            // The cone's axis and angle are almost always uniform: their length and cosine
            // once per grid.
            let ax_u = match ax {
                T::U(x) => Some((x, x.length())),
                T::V(_) => None,
            };
            let cos_u = match an {
                F::U(x) => Some(cos_of(x)),
                F::V(_) => None,
            };
            for (i, b) in m.bits.iter_mut().enumerate() {
                if !*b {
                    continue;
                }
                let (a, axl) = match ax_u {
                    Some(u) => u,
                    None => (ax.at(i), ax.at(i).length()),
                };
                let ll = l[i].length();
                let c = if axl == 0.0 || ll == 0.0 {
                    1.0
                } else {
                    a.dot(l[i]) / (axl * ll)
                };
                *b = c >= cos_u.unwrap_or_else(|| cos_of(an.at(i)));
            }
            m.recount();
        }
        match lreg {
            Some(r) => self.regs[r as usize] = Slot::VT(l),
            None => crate::shade::value::recycle([Slot::VT(l)]),
        }
        let mut state = state;
        state.ran = true;
        for (a, b) in state.lit.iter_mut().zip(&m.bits) {
            *a |= *b;
        }
        self.light = Some(state);
        if !m.is_none() {
            self.block(body, &mut m);
        }
        self.release_mask(m);
    }
}

crate::shade::value::kernel! {
    /// How many of `bits` are set (a vectorised sum; `filter().count()` was a loop per flag).
    fn count_true<>(bits: &[bool]) -> usize {
        // Counted in 32-bit lanes per chunk (eight to a vector), added up per chunk.
        bits.chunks(1024)
            .map(|c| c.iter().map(|&b| b as u32).sum::<u32>() as usize)
            .sum()
    }
}

crate::shade::value::kernel! {
    /// `bits[i] &= c[i] != 0`; returns how many are set after.
    fn and_nonzero<>(bits: &mut [bool], c: &[f32]) -> usize {
        let mut count = 0usize;
        for (mc, cc) in bits.chunks_mut(1024).zip(c.chunks(1024)) {
            let mut k = 0u32;
            for (m, &c) in mc.iter_mut().zip(cc) {
                // As bytes: `bool & bool` stayed a loop per flag.
                let b = (*m as u8) & ((c != 0.0) as u8);
                *m = b != 0;
                k += b as u32;
            }
            count += k as usize;
        }
        count
    }
}

crate::shade::value::kernel! {
    /// `bits[i] &= !other[i]`; returns how many are set after.
    fn and_not<>(bits: &mut [bool], other: &[bool]) -> usize {
        let mut count = 0usize;
        for (mc, oc) in bits.chunks_mut(1024).zip(other.chunks(1024)) {
            let mut k = 0u32;
            for (m, &o) in mc.iter_mut().zip(oc) {
                let b = (*m as u8) & !(o as u8) & 1;
                *m = b != 0;
                k += b as u32;
            }
            count += k as usize;
        }
        count
    }
}

crate::shade::value::kernel! {
    /// One select mask per point: all ones where the flag is set.
    fn sel_from_bits<>(k: &mut [u32], bits: &[bool]) {
        for (o, &b) in k.iter_mut().zip(bits) {
            *o = 0u32.wrapping_sub(b as u32);
        }
    }
}

crate::shade::value::kernel! {
    /// Three select masks per point (one per component of a triple).
    fn sel3_from_bits<>(k: &mut [u32], bits: &[bool]) {
        for (o, &b) in k.chunks_exact_mut(3).zip(bits) {
            let x = 0u32.wrapping_sub(b as u32);
            o[0] = x;
            o[1] = x;
            o[2] = x;
        }
    }
}

/// `v = a` at the running points of `mask`: a copy when every point runs, the listed points
/// when few do, otherwise `select` over every point (as bit masks, which vectorise).
#[inline]
fn store<X: Copy>(v: &mut [X], a: Op<X>, mask: &Mask, select: impl FnOnce(&mut [X], Op<X>, &Mask)) {
    let n = v.len();
    if mask.is_all() {
        match a {
            Op::U(x) => v.fill(x),
            Op::V(x) => v.copy_from_slice(&x[..n]),
        }
        return;
    }
    match (mask.lanes(), a) {
        (Lanes::Some(idx), Op::U(x)) => {
            for &i in idx {
                v[i as usize] = x;
            }
        }
        (Lanes::Some(idx), Op::V(x)) => {
            for &i in idx {
                v[i as usize] = x[i as usize];
            }
        }
        (Lanes::All, a) => select(v, a, mask),
    }
}

/// [`store`] for floats.
#[inline]
fn store_f(v: &mut [f32], a: F, mask: &Mask) {
    store(v, a, mask, |v, a, m| {
        let n = v.len();
        select_f(v, a, &m.sel_f()[..n])
    })
}

crate::shade::value::kernel! {
    /// `v[i] = a[i]` where `k[i]` is all ones (a vector select).
    fn select_f<>(v: &mut [f32], a: F, k: &[u32]) {
        let n = v.len();
        let k = &k[..n];
        match a {
            Op::U(x) => {
                let x = x.to_bits();
                for (o, &k) in v.iter_mut().zip(k) {
                    *o = f32::from_bits((o.to_bits() & !k) | (x & k));
                }
            }
            Op::V(x) => {
                let x = &x[..n];
                for i in 0..n {
                    v[i] = f32::from_bits((v[i].to_bits() & !k[i]) | (x[i].to_bits() & k[i]));
                }
            }
        }
    }
}

/// [`store`] for triples.
#[inline]
fn store_t(v: &mut [Vec3], a: T, mask: &Mask) {
    store(v, a, mask, |v, a, m| {
        let n = v.len();
        select_t(v, a, &m.sel_t()[..3 * n])
    })
}

crate::shade::value::kernel! {
    /// `v[i] = a[i]` where `k` (one mask per component) is all ones: a vector select on
    /// the flat components.
    fn select_t<>(v: &mut [Vec3], a: T, k: &[u32]) {
        let o = flat_mut(v);
        let m = o.len();
        let k = &k[..m];
        let sel = |o: f32, x: f32, k: u32| f32::from_bits((o.to_bits() & !k) | (x.to_bits() & k));
        match a {
            Op::V(x) => {
                let x = &flat(x)[..m];
                for j in 0..m {
                    o[j] = sel(o[j], x[j], k[j]);
                }
            }
            Op::U(x) => {
                let p = [x.x, x.y, x.z, x.x, x.y, x.z, x.x, x.y, x.z, x.x, x.y, x.z];
                let mut oc = o.chunks_exact_mut(12);
                let mut kc = k.chunks_exact(12);
                for (oo, kk) in (&mut oc).zip(&mut kc) {
                    for j in 0..12 {
                        oo[j] = sel(oo[j], p[j], kk[j]);
                    }
                }
                for (j, (oo, &kk)) in oc
                    .into_remainder()
                    .iter_mut()
                    .zip(kc.remainder())
                    .enumerate()
                {
                    *oo = sel(*oo, p[j], kk);
                }
            }
        }
    }
}

/// Whether two register values are the same bit for bit (NaN equals NaN).
fn same_slot(a: &Slot, b: &Slot) -> bool {
    fn bits3(v: Vec3) -> [u32; 3] {
        [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]
    }
    fn bits16(m: &Mat4) -> [u32; 16] {
        m.to_cols_array().map(f32::to_bits)
    }
    match (a, b) {
        (Slot::F(x), Slot::F(y)) => x.to_bits() == y.to_bits(),
        (Slot::T(x), Slot::T(y)) => bits3(*x) == bits3(*y),
        (Slot::M(x), Slot::M(y)) => bits16(x) == bits16(y),
        (Slot::S(x), Slot::S(y)) => x == y,
        (Slot::VF(x), Slot::VF(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
        }
        (Slot::VT(x), Slot::VT(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| bits3(*p) == bits3(*q))
        }
        (Slot::VM(x), Slot::VM(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| bits16(p) == bits16(q))
        }
        _ => false,
    }
}

fn first_active<X: Copy + Default>(v: &[X], mask: &Mask) -> X {
    v.iter()
        .zip(&mask.bits)
        .find(|(_, &b)| b)
        .map(|(x, _)| *x)
        .or_else(|| v.first().copied())
        .unwrap_or_default()
}

/// A uniform slot repeated to `n` points.
pub fn broadcast(v: &Slot, n: usize) -> Slot {
    match v {
        Slot::F(x) => Slot::VF(vec![*x; n]),
        Slot::T(x) => Slot::VT(vec![*x; n]),
        Slot::M(x) => Slot::VM(vec![**x; n]),
        s => s.clone(),
    }
}

/// `illuminance("cat", …)`: the light's `__category` is a comma-separated list; a leading `-`
/// in the pattern excludes lights of that category.
pub fn category_matches(pattern: &str, category: &str) -> bool {
    let cats: Vec<&str> = category.split(',').map(str::trim).collect();
    if let Some(neg) = pattern.strip_prefix('-') {
        !cats.contains(&neg)
    } else if pattern.is_empty() {
        true
    } else {
        cats.contains(&pattern)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Flags from a simple hash, so runs of set and clear flags of every length show up.
    fn flags(n: usize, salt: u32) -> Vec<bool> {
        (0..n as u32)
            .map(|i| crate::pattern::hash::hash_u32(i ^ salt) % 3 != 0)
            .collect()
    }

    #[test]
    fn loop_mask_updates_match_one_flag_at_a_time() {
        // Lengths around the 1024-flag chunks and the 8-lane vectors.
        for n in [0, 1, 7, 8, 9, 1023, 1024, 1025, 3000] {
            let start = flags(n, 1);
            let c: Vec<f32> = flags(n, 2)
                .iter()
                .enumerate()
                .map(|(i, &b)| if b { i as f32 + 0.5 } else { 0.0 })
                .collect();
            let broken = flags(n, 3);

            let mut m = Mask::from_bits(start.clone());
            assert_eq!(m.count, start.iter().filter(|&&b| b).count());
            m.and_nonzero(&c);
            let want: Vec<bool> = start.iter().zip(&c).map(|(&b, &c)| b && c != 0.0).collect();
            assert_eq!(m.bits, want);
            assert_eq!(m.count, want.iter().filter(|&&b| b).count());

            m.and_not(&broken);
            let want: Vec<bool> = want.iter().zip(&broken).map(|(&b, &o)| b && !o).collect();
            assert_eq!(m.bits, want);
            assert_eq!(m.count, want.iter().filter(|&&b| b).count());
            // Few running points are listed; many are not.
            if m.count * SPARSE_DIVISOR <= n {
                let idx: Vec<u32> = (0..n as u32).filter(|&i| want[i as usize]).collect();
                assert_eq!(m.idx, idx);
            } else {
                assert!(m.idx.is_empty());
            }
        }
    }

    #[test]
    fn shorter_updates_leave_the_other_flags_counted() {
        let mut m = Mask::all(10);
        m.and_not(&[true, true, false]);
        assert_eq!(m.count, 8);
        m.and_nonzero(&[1.0, 1.0, 0.0, 1.0]);
        assert_eq!(m.count, 7);
        assert_eq!(m.bits[..4], [false, false, false, true]);
    }

    #[test]
    fn select_masks_follow_the_flags() {
        let mut m = Mask::from_bits(vec![true, false, true]);
        assert_eq!(&*m.sel_f(), &[u32::MAX, 0, u32::MAX]);
        assert_eq!(
            &*m.sel_t(),
            &[
                u32::MAX,
                u32::MAX,
                u32::MAX,
                0,
                0,
                0,
                u32::MAX,
                u32::MAX,
                u32::MAX
            ]
        );
        m.and_not(&[true, false, false]);
        assert_eq!(&*m.sel_f(), &[0, 0, u32::MAX]);
    }
}
