//! The frame driver: buckets in parallel, surfaces forwarded, grids shaded once.
//!
//! Input: a [`Scene`], a [`GridShader`] and [`RenderOptions`]. Output: a filtered [`Film`].
//! Invariants:
//! * every surface is bounded, culled, split or diced with decisions that depend only on the
//!   surface and the camera; split children get keys derived from their parent's, so every
//!   grid has the same identity whatever the bucket layout;
//! * buckets are processed row by row, as a dataflow without a barrier between rows
//!   ([`Flow`]): every surface whose bound first reaches row r is split/diced/displaced (in
//!   parallel over surfaces) once row r − 1's are and row r − 2 is hidden; row r's buckets
//!   are hidden (in parallel over buckets) as soon as its grids are made, while row r − 1's
//!   last buckets may still run; grids no later row needs are freed — memory holds only the
//!   grids overlapping the open rows. A grid's
//!   surface is shaded when the first bucket hiding it asks for it (a [`LazyGrid`]): a grid
//!   behind every opaque sample of each bucket it overlaps is never shaded, and a grid's
//!   points (diced or shaded) are dropped as soon as the last bucket it overlaps is hidden
//!   (only its small record waits for the end of its last row). The tile of a bucket is
//!   filtered by the thread that hides the last bucket within its reach, and a bucket's
//!   samples are dropped once the last tile reading them is filtered; finished rows go into
//!   the film, and their scanlines to the output, in order, by one thread at a time;
//! * surfaces are made from the scene's primitives in parallel before the first row; those
//!   cheap to make again (polygons, quadrics, patches, points, curves) are then dropped and
//!   made again when their first row opens, so memory holds the scene and the open rows'
//!   surfaces, not every primitive's surfaces at once (same surfaces, keys and picture);
//! * a bucket samples its pixels plus the filter margin, and every sample sees every grid that
//!   covers it, so the image is identical for any bucket size or thread count.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, RwLock};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::diag::{Diag, Diagnostics};
use crate::geom::{Bound, Surface};
use crate::scene::{Options, Primitive, Scene};

use super::camera::{check_options, crop_region, Camera, PixelRect};
use super::dice::{decide, Decision, View};
use super::hider::csg::{CsgPrim, CsgTree};
use super::hider::{
    make_hider, orientation, Aov, DepthFilter, GridInfo, GridSource, Hider, HiderConfig, ShadedGrid,
};
use super::packed::PackedGrid;
use super::sampler::mix64;
use super::stats::{Phase, PhaseClock, Stage, Stats};
use super::GridShader;
use crate::film::stream::RowSink;
use crate::film::{DepthFilter as FilmDepthFilter, Film, SampleBuffer};

/// Default bucket size in pixels (`Option "limits" "bucketsize"` overrides).
pub const DEFAULT_BUCKET: u32 = 16;
/// Default most micropolygons per grid (`Option "limits" "gridsize"` overrides).
pub const DEFAULT_GRID: usize = 1024;
/// Default most eye-plane splits of one surface (`Option "limits" "eyesplits"` overrides).
pub const DEFAULT_EYE_SPLITS: u32 = 10;
/// Most splits of any kind along one path: a guard against surfaces that never shrink.
pub const MAX_SPLIT_DEPTH: u32 = 32;
/// Fewest splits one primitive may make before it is stopped (see [`Frame::split_budget`]).
pub const MIN_SPLIT_BUDGET: u64 = 1 << 18;

/// How to run a frame (command-line overrides and hooks).
#[derive(Clone, Default)]
pub struct RenderOptions<'a> {
    /// Worker threads; 0 = rayon's default (all cores).
    pub threads: usize,
    /// Bucket width and height in pixels; None = `Option "limits" "bucketsize"` or 16.
    pub bucket_size: Option<[u32; 2]>,
    /// Crop window (xmin, xmax, ymin, ymax in NDC) replacing the scene's.
    pub crop: Option<[f32; 4]>,
    /// Image size replacing Format's.
    pub resolution: Option<(u32, u32)>,
    /// Where to count statistics (the caller prints them); None = not kept.
    pub stats: Option<&'a Stats>,
    /// Called with (buckets done, buckets total) after each bucket, from worker threads.
    pub progress: Option<&'a (dyn Fn(usize, usize) + Sync)>,
    /// Arbitrary output variables to carry to the film, after r g b a z.
    pub aovs: Vec<Aov>,
}

/// Renders one frame of `scene` (see the module invariants).
pub fn render_frame(
    scene: &Scene,
    shader: &dyn GridShader,
    opts: &RenderOptions,
    diags: &Diagnostics,
) -> Film {
    render_frame_rows(scene, shader, opts, None, diags)
}

/// [`render_frame`], handing `rows` each band of finished scanlines (in order, scanline 0
/// first, whole-image coordinates) while later rows still render.
pub fn render_frame_rows(
    scene: &Scene,
    shader: &dyn GridShader,
    opts: &RenderOptions,
    rows: Option<&mut (dyn RowSink + Send)>,
    diags: &Diagnostics,
) -> Film {
    let mut options = effective_options(&scene.options, opts);
    super::limits::apply_frame_limits(&mut options, diags);
    check_options(&options, diags);
    let camera = Camera::from_options(&options, scene.camera_from_world, &scene.coordinate_systems);
    let raster_from_camera = camera.raster_from_camera();
    let make = |i: usize, diags: &Diagnostics| {
        super::motion::surfaces_over_shutter(
            i,
            &scene.primitives[i],
            camera.camera_from_world,
            scene.camera_motion.as_deref(),
            options.shutter,
            Some(raster_from_camera),
            diags,
        )
    };
    run_in_pool(opts, diags, || {
        render_inner(
            scene,
            &options,
            &camera,
            Surfaces::Lazy(&make),
            shader,
            opts,
            rows,
            diags,
        )
    })
}

/// Makes the surfaces of primitive `i` (the same ones every time it is called), reporting
/// problems to the sink given.
type MakeSurfaces<'m> = dyn Fn(usize, &Diagnostics) -> Vec<Box<dyn Surface>> + Sync + 'm;

/// The surfaces of one primitive.
type SurfaceList = Vec<Box<dyn Surface>>;

/// Diagnostics taken from a sink, with their counts.
type Diags = Vec<(Diag, usize)>;

/// Where a frame's surfaces come from.
enum Surfaces<'m> {
    /// Made by the caller: `v[i]` are the surfaces of primitive `i`.
    Built(Vec<Vec<Box<dyn Surface>>>),
    /// Made by the driver. A primitive cheap to make again (polygons, quadrics, patches,
    /// points, curves) is made once to find the first bucket row it reaches, dropped, and made
    /// again when that row opens: memory holds the scene, not every primitive's surfaces.
    Lazy(&'m MakeSurfaces<'m>),
}

/// Whether the surfaces of `p` are cheap enough to make twice (see [`Surfaces::Lazy`]).
fn remade_cheaply(p: &Primitive) -> bool {
    use crate::scene::Geometry as G;
    matches!(
        &*p.geometry,
        G::Polygons { .. }
            | G::Sphere { .. }
            | G::Cone { .. }
            | G::Cylinder { .. }
            | G::Hyperboloid { .. }
            | G::Paraboloid { .. }
            | G::Disk { .. }
            | G::Torus { .. }
            | G::PatchMesh { .. }
            | G::NuPatch { .. }
            | G::Points { .. }
            | G::Curves { .. }
    )
}

/// Primitives placed at a time, each chunk's diagnostics kept apart and reported in order.
const PLACE_CHUNK: usize = 256;

/// A primitive's surfaces, placed in the bucket rows they first reach.
enum Placed {
    /// Kept: each surface with its row (None: culled).
    Works(Vec<(Option<usize>, Work)>),
    /// Dropped, to be made again when row `first` opens (None: every surface culled).
    Remade {
        prim: usize,
        first: Option<usize>,
        surfaces: usize,
        culled: usize,
    },
}

/// The first surfaces of a primitive get this key (split children derive theirs from it).
fn surface_key(prim: usize, j: usize) -> u64 {
    mix64(mix64(prim as u64) ^ (j as u64).wrapping_mul(0x9E37_79B9))
}

/// The scene's options with the command-line overrides applied.
pub fn effective_options(options: &Options, opts: &RenderOptions) -> Options {
    let mut o = options.clone();
    if let Some((x, y)) = opts.resolution {
        o.xres = x.max(1);
        o.yres = y.max(1);
    }
    if let Some(c) = opts.crop {
        o.crop_window = c;
    }
    o
}

/// Per-primitive attributes the driver needs, resolved once.
#[derive(Clone, Copy, Debug)]
struct PrimInfo {
    /// Displacement bound in camera space.
    disp: f32,
    /// The bound was estimated by displacing test grids (the scene declares none).
    disp_estimated: bool,
    rate: f32,
    matte: bool,
    smooth: bool,
    one_sided: bool,
    /// Attribute "dice" "binary": grids are diced a power of two on each side (adjacent
    /// grids then share vertices more often, which hides cracks).
    binary: bool,
    /// Its place in a CSG tree (None outside boolean solids).
    csg: Option<CsgPrim>,
    /// `GeometricApproximation "motionfactor"` / `"focusfactor"` (0: off).
    motion_factor: f32,
    focus_factor: f32,
    /// The surface shader may move P, within the displacement bound (see
    /// [`crate::shade::system::surface_moves_points`]).
    moves_points: bool,
    /// `Attribute "cull" "hidden" [0]`: grids are shaded even where hidden (for shaders
    /// whose effects go beyond the picture, such as `bake3d`).
    shade_hidden: bool,
}

fn prim_info(
    scene: &Scene,
    camera: &Camera,
    prim: &Primitive,
    min_rate: f32,
    diags: &Diagnostics,
) -> PrimInfo {
    let a = &prim.attributes;
    let mut disp = 0.0;
    if a.displacement_bound > 0.0 {
        let space = a.displacement_bound_space.as_str();
        let m = match space {
            "object" => Some(camera.camera_from_world * *prim.world_from_object),
            "shader" => a
                .displacement
                .as_ref()
                .map(|d| camera.camera_from_world * d.world_from_shader)
                .or(Some(camera.camera_from_world * *prim.world_from_object)),
            // PRMan's Blobby application note writes "coordinatesystem" "surface": the
            // surface shader's space.
            "surface" => a
                .surface
                .as_ref()
                .map(|s| camera.camera_from_world * s.world_from_shader)
                .or(Some(camera.camera_from_world * *prim.world_from_object)),
            other => camera.camera_from_space(other),
        };
        let m = m.unwrap_or_else(|| {
            diags.report(
                Diag::warning(
                    "render::displacementbound",
                    format!("unknown coordinate system \"{space}\" for displacementbound; using object space"),
                )
                .label(prim.span, "this primitive"),
            );
            camera.camera_from_world * *prim.world_from_object
        });
        let scale = m
            .x_axis
            .truncate()
            .length()
            .max(m.y_axis.truncate().length())
            .max(m.z_axis.truncate().length());
        disp = a.displacement_bound * scale;
        if !disp.is_finite() {
            disp = 0.0;
        }
    }
    let factor = |k: &str| {
        a.geometric_approximation
            .get(k)
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .unwrap_or(0.0)
    };
    let rate = if a.shading_rate.is_finite() && a.shading_rate > 0.0 {
        super::limits::shading_rate(a.shading_rate, min_rate, prim.span, diags)
    } else {
        1.0
    };
    PrimInfo {
        disp,
        disp_estimated: false,
        rate,
        matte: a.matte,
        smooth: a.smooth_shading,
        one_sided: a.sides == 1,
        binary: a
            .user
            .get("dice:binary")
            .and_then(|p| p.data.floats().first().copied())
            .is_some_and(|v| v != 0.0),
        csg: None,
        motion_factor: factor("motionfactor"),
        focus_factor: factor("focusfactor"),
        moves_points: crate::shade::system::surface_moves_points(scene, a),
        shade_hidden: a
            .user
            .get("cull:hidden")
            .and_then(|p| p.data.floats().first().copied())
            .is_some_and(|v| v == 0.0),
    }
}

/// The shading rate of a blurred surface: `GeometricApproximation "motionfactor" f` multiplies
/// a moving surface's rate by 1 + f·B/16, B the distance in pixels its bound travels during
/// the shutter (so with f = 1 a surface blurred over 16 pixels gets micropolygons twice the
/// area), and `"focusfactor"` likewise with B the smallest diameter of its circle of
/// confusion. Blur hides detail smaller than itself, so fewer points need shading.
fn blurred_rate(surface: &dyn Surface, bound: &Bound, info: &PrimInfo, view: &View) -> f32 {
    let mut scale = 1.0f32;
    if info.motion_factor > 0.0 {
        let (all, still) = (
            view.raster_bound_sharp(&surface.bound()),
            view.raster_bound_sharp(&surface.still_bound()),
        );
        if let (Some(a), Some(s)) = (all, still) {
            let travel = ((a[2] - a[0]) - (s[2] - s[0])).max((a[3] - a[1]) - (s[3] - s[1]));
            if travel.is_finite() && travel > 0.0 {
                scale += info.motion_factor * travel / 16.0;
            }
        }
    }
    if let (true, Some(d)) = (info.focus_factor > 0.0, &view.dof) {
        let (z0, z1) = (bound.min.z, bound.max.z);
        if z0 > 0.0 && z1.is_finite() {
            let (a, b) = (d.inv_focus - 1.0 / z0, d.inv_focus - 1.0 / z1);
            // Zero when the focal plane passes through the bound.
            let coc = if a.signum() != b.signum() {
                0.0
            } else {
                a.abs().min(b.abs())
            };
            let diameter = 2.0 * coc * d.raster_k[0].abs().min(d.raster_k[1].abs());
            if diameter.is_finite() {
                scale += info.focus_factor * diameter / 16.0;
            }
        }
    }
    info.rate * scale
}

/// Displaced primitives that declare no displacement bound get an estimated one (see
/// [`super::dispbound`]), so their grids are not cut off at their surfaces' bounds.
fn estimate_displacement_bounds(
    scene: &Scene,
    camera: &Camera,
    view: &View,
    surfaces: &[Option<SurfaceList>],
    prims: &mut [PrimInfo],
    shader: &dyn GridShader,
) {
    let wanted: Vec<usize> = (0..prims.len().min(surfaces.len()))
        .filter(|&i| needs_estimate(scene, prims, i))
        .collect();
    let found: Vec<(usize, f32)> = wanted
        .into_par_iter()
        .map(|i| {
            let d = super::dispbound::estimate(
                scene,
                camera,
                &view.raster_from_camera,
                prims[i].rate,
                i,
                surfaces[i].as_deref().unwrap_or(&[]),
                shader,
            );
            (i, d)
        })
        .collect();
    for (i, d) in found {
        if d > 0.0 && d.is_finite() {
            prims[i].disp = d;
            prims[i].disp_estimated = true;
        }
    }
}

/// A primitive whose points are displaced (see `bump_only`) but that declares no
/// displacement bound (BMRT's `truedisplacement` never needed one).
fn needs_estimate(scene: &Scene, prims: &[PrimInfo], i: usize) -> bool {
    let a = &scene.primitives[i].attributes;
    prims[i].disp == 0.0 && a.displacement.is_some() && !crate::shade::system::bump_only(scene, a)
}

/// A surface waiting to be split or diced.
#[derive(Debug)]
struct Work {
    surface: Box<dyn Surface>,
    key: u64,
    depth: u32,
    eye_splits: u32,
}

enum Outcome {
    Nothing,
    Grid(Box<LazyGrid>),
}

/// A grid kept until the last bucket row that needs it is done.
struct Kept {
    grid: Box<LazyGrid>,
    rows: (usize, usize),
    cols: (usize, usize),
}

/// A diced and displaced grid whose surface is shaded when a bucket first asks for it (see
/// [`GridSource`]), with what is known of the shaded grid before: hiders skip a grid whose
/// bound lies behind every opaque sample of their bucket without shading it.
struct LazyGrid {
    key: u64,
    /// At most the shaded grid's [`ShadedGrid::zmin`].
    zmin: f32,
    /// Holds the shaded grid's [`ShadedGrid::bound`].
    bound: [f32; 4],
    moving: bool,
    /// Buckets overlapping the grid not yet hidden: the one that brings it to 0 releases
    /// the grid's points (no other bucket will ask for them).
    left: AtomicUsize,
    /// The grid: waiting for its shader, shaded, or released. The first bucket asking
    /// shades it holding the lock; buckets asking meanwhile wait for it.
    state: Mutex<GridState>,
}

enum GridState {
    Pending(Pending),
    /// None when nothing of it is left to hide.
    Shaded(Option<Arc<ShadedGrid>>),
    /// Every bucket overlapping it is hidden; whether it was ever shaded.
    Released {
        shaded: bool,
    },
}

/// A grid waiting for its surface shader.
struct Pending {
    grid: PackedGrid,
    prim: usize,
    /// Points cut away by trimming curves (None: untrimmed).
    trimmed: Option<Vec<bool>>,
    info: GridInfo,
    /// What the grid holds, for the memory statistic.
    bytes: usize,
}

impl GridState {
    /// Bytes held: the diced grid until it is shaded, then the shaded grid.
    fn bytes(&self) -> usize {
        match self {
            GridState::Pending(p) => p.bytes,
            GridState::Shaded(g) => g.as_ref().map_or(0, |g| g.bytes()),
            GridState::Released { .. } => 0,
        }
    }
    fn shaded(&self) -> bool {
        match self {
            GridState::Pending(_) => false,
            GridState::Shaded(_) => true,
            GridState::Released { shaded } => *shaded,
        }
    }
}

impl LazyGrid {
    /// The state, even after a panic elsewhere while it was held (it is never left half
    /// updated: each change is one assignment).
    fn state(&self) -> MutexGuard<'_, GridState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
    /// The state, for a bucket about to shade or read the grid. While another thread holds
    /// it (shading the grid: on a heavy shader, long), this thread does other pending work of
    /// the frame (other buckets, the next row's making) instead of waiting idle, and waits
    /// only when there is none. Nothing is held across that work but this bucket's own hiding
    /// state (the hider's scratch is per bucket), and the holder shades without waiting on
    /// anything, so every wait ends.
    fn state_for_bucket(&self, stats: &Stats) -> MutexGuard<'_, GridState> {
        let mut counted = false;
        loop {
            match self.state.try_lock() {
                Ok(g) => return g,
                Err(std::sync::TryLockError::Poisoned(e)) => return e.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => {}
            }
            if !counted {
                Stats::add(&stats.grid_waits, 1);
                counted = true;
            }
            let t = Instant::now();
            let before = SHADING_NS.with(Cell::get);
            // Work done meanwhile runs on this thread's stack, above this bucket: a few
            // levels at most (shading and tracing need stack of their own).
            let depth = WAITS_NESTED.with(Cell::get);
            let worked = depth < MAX_WAITS_NESTED && {
                WAITS_NESTED.with(|d| d.set(depth + 1));
                let y = rayon::yield_now();
                WAITS_NESTED.with(|d| d.set(depth));
                matches!(y, Some(rayon::Yield::Executed))
            };
            // The other work is not this bucket's hiding (its own shading counted inside).
            let ns = t.elapsed().as_nanos() as u64;
            SHADING_NS.with(|c| c.set(before + ns));
            if !worked {
                let t = Instant::now();
                let st = self.state();
                Stats::add(&stats.grid_wait_ns, t.elapsed().as_nanos() as u64);
                return st;
            }
        }
    }
    /// Bytes held (see [`GridState::bytes`]).
    fn bytes(&self) -> usize {
        self.state().bytes()
    }
    /// One more bucket overlapping the grid is hidden; after the last, its points are
    /// dropped (a bucket still holding the shaded grid keeps it until it lets go), and a
    /// grid never shaded is counted.
    fn bucket_done(&self, stats: &Stats) {
        if self.left.fetch_sub(1, Ordering::AcqRel) == 1 {
            let gone = {
                let mut st = self.state();
                stats.free(st.bytes());
                let shaded = st.shaded();
                if !shaded {
                    Stats::add(&stats.grids_unshaded, 1);
                }
                std::mem::replace(&mut *st, GridState::Released { shaded })
            };
            // Freed outside the lock, into this thread's buffer pool (a shaded grid's buffers
            // go there when its last holder lets go: `ShadedGrid`'s drop).
            if let GridState::Pending(p) = gone {
                p.grid.recycle();
            }
        }
    }
}

/// Most bucket waits for a grid (see [`LazyGrid::state_for_bucket`]) one thread does other
/// work inside at once; a deeper one waits.
const MAX_WAITS_NESTED: u32 = 3;

thread_local! {
    /// Bucket waits for a grid this thread is doing other work inside.
    static WAITS_NESTED: Cell<u32> = const { Cell::new(0) };
    /// Nanoseconds this thread spent shading grids asked for by a hider, or on other work
    /// while a bucket waited for a grid: the bucket's hiding time leaves them out.
    static SHADING_NS: Cell<u64> = const { Cell::new(0) };
}

/// A lazy grid with the frame that shades it: what a hider receives.
struct Source<'k, 'f> {
    frame: &'k Frame<'f>,
    grid: &'k LazyGrid,
    /// The shaded grid once this bucket has asked for it.
    got: OnceLock<Option<Arc<ShadedGrid>>>,
}

impl GridSource for Source<'_, '_> {
    fn key(&self) -> u64 {
        self.grid.key
    }
    fn zmin(&self) -> f32 {
        self.grid.zmin
    }
    fn bound(&self) -> [f32; 4] {
        self.grid.bound
    }
    fn moving(&self) -> bool {
        self.grid.moving
    }
    fn shaded(&self) -> Option<&ShadedGrid> {
        self.got
            .get_or_init(|| {
                let mut st = self.grid.state_for_bucket(self.frame.stats);
                match std::mem::replace(&mut *st, GridState::Shaded(None)) {
                    GridState::Pending(p) => {
                        let g = self.frame.shade(p, self.grid.zmin).map(Arc::from);
                        *st = GridState::Shaded(g.clone());
                        g
                    }
                    other => {
                        // Released gives None, but a grid is released only after its last
                        // bucket, so no bucket asks then.
                        let g = match &other {
                            GridState::Shaded(g) => g.clone(),
                            _ => None,
                        };
                        *st = other;
                        g
                    }
                }
            })
            .as_deref()
    }
}

/// A hidden bucket waiting for its row (and the rows either side) to be filtered: its
/// samples, or their filter-ready form.
enum Hidden {
    Samples(SampleBuffer),
    /// Prepared for the gather (the bucket's own tile, started by its hiding, waits beside
    /// it: see [`BucketCell`]).
    Prepared(crate::film::gather::Prepared),
}

impl Hidden {
    fn bytes(&self) -> usize {
        match self {
            Hidden::Samples(b) => b.positions.len() * 8 + b.values.len() * 4,
            Hidden::Prepared(p) => p.bytes(),
        }
    }
}

/// The samples of `parts` (buffers of whole pixels, same samples per pixel and channels)
/// that lie in `region`, as one buffer over it. The parts must hold every pixel of the
/// region (the sample regions of a bucket's neighbours do).
fn assemble(region: PixelRect, parts: &[&SampleBuffer]) -> SampleBuffer {
    let Some(first) = parts.first() else {
        return SampleBuffer::new(region.x0, region.y0, 0, 0, 1, 1, 5);
    };
    let (sx, sy, ch) = (first.spp_x, first.spp_y, first.channels);
    let spp = sx * sy;
    let (w, h) = (region.width(), region.height());
    let mut out = SampleBuffer::new(region.x0, region.y0, w, h, sx, sy, ch);
    for p in parts {
        let pr = PixelRect {
            x0: p.x0,
            y0: p.y0,
            x1: p.x0 + p.width as i32,
            y1: p.y0 + p.height as i32,
        }
        .intersect(region);
        if pr.is_empty() {
            continue;
        }
        let n = pr.width() * spp;
        for y in pr.y0..pr.y1 {
            let src = ((y - p.y0) as usize * p.width + (pr.x0 - p.x0) as usize) * spp;
            let dst = ((y - region.y0) as usize * w + (pr.x0 - region.x0) as usize) * spp;
            out.positions[dst..dst + n].copy_from_slice(&p.positions[src..src + n]);
            out.values[dst * ch..(dst + n) * ch]
                .copy_from_slice(&p.values[src * ch..(src + n) * ch]);
        }
    }
    out
}

/// The bucket layout over the crop region.
#[derive(Clone, Copy, Debug)]
struct Buckets {
    crop: PixelRect,
    image: PixelRect,
    size: [i32; 2],
    margin: [i32; 2],
    cols: usize,
    rows: usize,
}

impl Buckets {
    fn rect(&self, col: usize, row: usize) -> PixelRect {
        let x0 = self.crop.x0 + col as i32 * self.size[0];
        let y0 = self.crop.y0 + row as i32 * self.size[1];
        PixelRect {
            x0,
            y0,
            x1: (x0 + self.size[0]).min(self.crop.x1),
            y1: (y0 + self.size[1]).min(self.crop.y1),
        }
    }
    /// The pixels a bucket samples: its own, and where it lies on the edge of the crop region
    /// the filter margin beyond that edge (inside the image). These regions partition the
    /// crop region grown by the margin, so every sample is hidden once; a pixel's filter
    /// reads the samples of the neighbouring buckets.
    fn sample_rect(&self, col: usize, row: usize) -> PixelRect {
        let r = self.rect(col, row);
        let [mx, my] = self.margin;
        PixelRect {
            x0: r.x0 - if col == 0 { mx } else { 0 },
            y0: r.y0 - if row == 0 { my } else { 0 },
            x1: r.x1 + if col + 1 == self.cols { mx } else { 0 },
            y1: r.y1 + if row + 1 == self.rows { my } else { 0 },
        }
        .intersect(self.image)
    }
    /// Buckets either side whose samples a bucket's filter reads: ⌈margin / size⌉.
    fn reach(&self, axis: usize) -> usize {
        (self.margin[axis].max(0) as usize).div_ceil(self.size[axis].max(1) as usize)
    }
    /// Bucket indices whose sample regions may contain raster positions in [lo, hi] along
    /// one axis (`axis` 0 = x, 1 = y), clamped to the layout; None when there are none.
    fn span(&self, lo: f32, hi: f32, axis: usize) -> Option<(usize, usize)> {
        let (origin, end, n) = if axis == 0 {
            (self.crop.x0, self.crop.x1, self.cols)
        } else {
            (self.crop.y0, self.crop.y1, self.rows)
        };
        if n == 0 {
            return None;
        }
        let (s, m) = (self.size[axis] as i64, self.margin[axis] as i64);
        // Clamp first: huge or non-finite raster bounds must not overflow the arithmetic.
        // Samples of pixel p lie in [p, p + 1] (the right end included when the jitter
        // rounds up), so pixels ⌈lo⌉ − 1 to ⌊hi⌋ can have samples in [lo, hi].
        let p0 = lo.clamp(-1e9, 1e9).ceil() as i64 - 1;
        let p1 = hi.clamp(-1e9, 1e9).floor() as i64;
        if p1 < origin as i64 - m || p0 >= end as i64 + m {
            return None;
        }
        // The margin beyond the region belongs to the edge buckets.
        let first = (p0 - origin as i64).div_euclid(s).clamp(0, n as i64 - 1);
        let last = (p1 - origin as i64).div_euclid(s).clamp(0, n as i64 - 1);
        (first <= last).then_some((first as usize, last as usize))
    }
}

struct Frame<'a> {
    scene: &'a Scene,
    camera: &'a Camera,
    view: View,
    prims: Vec<PrimInfo>,
    shader: &'a dyn GridShader,
    hider: Box<dyn Hider>,
    buckets: Buckets,
    stats: &'a Stats,
    diags: &'a Diagnostics,
    aovs: Vec<Aov>,
    eye_split_limit: u32,
    /// `Option "limits" "eyesplits"` when it asked for more than arbor does (see
    /// `limits::MAX_EYE_SPLITS`): named in the warning when a piece is dropped at the limit.
    eye_splits_asked: Option<f32>,
    /// Splits made so far of each primitive's surfaces.
    splits: Vec<std::sync::atomic::AtomicU64>,
}

impl Frame<'_> {
    /// Most splits of one primitive's surfaces: sixteen times the grids that would tile the
    /// sampled region at its shading rate, and at least [`MIN_SPLIT_BUDGET`]. The depth limit
    /// alone allows 2^32 pieces; a surface whose pieces never get small on screen (a point at
    /// 1e30 makes every piece's trial dicing overflow) would split for hours before reaching it.
    fn split_budget(&self, rate: f32) -> u64 {
        let r = &self.view.region;
        let area = ((r[2] - r[0]) * (r[3] - r[1])).max(1.0) as f64;
        let grids = area / (rate.max(1e-6) as f64 * self.view.max_grid as f64);
        ((16.0 * grids) as u64).max(MIN_SPLIT_BUDGET)
    }

    fn widened_bound(&self, w: &Work) -> Option<Bound> {
        let prim = w.surface.primitive();
        let info = self.prims.get(prim)?;
        let b = w.surface.bound();
        // An empty bound is culled later; a NaN or infinite one is a geometry bug.
        let finite = b.min.is_finite() && b.max.is_finite();
        if !(b.is_empty() || finite) {
            self.diags.report(
                Diag::error(
                    "render::bound",
                    "a surface has a bound that is not finite; it is skipped",
                )
                .label(self.scene.primitives[prim].span, "this primitive"),
            );
            return None;
        }
        Some(if info.disp > 0.0 {
            b.grow(info.disp)
        } else {
            b
        })
    }

    /// A grid is sampled only inside the bound of the surface it was diced from (widened by
    /// the displacement bound), so that every bucket size gives the same picture. When the
    /// displacement shader moves micropolygons past it, the parts outside are cut off, which
    /// shows as cracks along grid edges: say so once per shader, with the fix.
    fn check_displacement_bound(&self, prim: usize, sg: &ShadedGrid, clip: &[f32; 4]) {
        let Some(d) = self.scene.primitives[prim].attributes.displacement.as_ref() else {
            return;
        };
        let mut b = [
            f32::INFINITY,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NEG_INFINITY,
        ];
        for rb in &sg.row_bounds {
            b = [
                b[0].min(rb[0]),
                b[1].min(rb[1]),
                b[2].max(rb[2]),
                b[3].max(rb[3]),
            ];
        }
        // Half a pixel of slack: filters and jitter hide less than that.
        let out = (clip[0] - b[0])
            .max(clip[1] - b[1])
            .max(b[2] - clip[2])
            .max(b[3] - clip[3]);
        if out > 0.5 {
            self.diags.report(
                Diag::warning(
                    "render::displacementbound",
                    if self.prims[prim].disp_estimated {
                        format!(
                            "displacement shader `{}` moves points further than arbor's \
                             estimate of its displacement bound; what lies outside is cut off \
                             (cracks along grid edges)",
                            d.name
                        )
                    } else {
                        format!(
                            "displacement shader `{}` moves points outside the surface's \
                             displacement bound; what lies outside is cut off (cracks along \
                             grid edges)",
                            d.name
                        )
                    },
                )
                .label(d.span, "displacement shader named here")
                .help("declare the largest displacement: Attribute \"displacementbound\" \"sphere\" [d] (in object space)"),
            );
        }
    }

    /// Primitive `prim`'s surfaces as top-level work, each with the bucket row it first needs
    /// (at least `min_row`; None when culled).
    fn place_all(
        &self,
        prim: usize,
        surfaces: SurfaceList,
        min_row: usize,
    ) -> Vec<(Option<usize>, Work)> {
        surfaces
            .into_iter()
            .enumerate()
            .map(|(j, surface)| {
                let w = Work {
                    surface,
                    key: surface_key(prim, j),
                    depth: 0,
                    eye_splits: 0,
                };
                (self.place(&w, min_row), w)
            })
            .collect()
    }

    /// The bucket row a surface first needs (at least `min_row`), or None when culled.
    fn place(&self, w: &Work, min_row: usize) -> Option<usize> {
        let b = self.widened_bound(w)?;
        if self.view.outside(&b) {
            return None;
        }
        match self.view.raster_bound(&b) {
            // Reaching behind the eye: split where it is (its pieces are placed again).
            None => Some(min_row),
            Some(r) => self
                .buckets
                .span(r[1], r[3], 1)
                .map(|(first, _)| first.max(min_row)),
        }
    }

    fn step(&self, w: Work, row: usize) -> (Outcome, Vec<(usize, Work)>) {
        let t0 = Instant::now();
        let prim = w.surface.primitive();
        let Some(info) = self.prims.get(prim).copied() else {
            self.diags.report(Diag::error(
                "render::surface",
                format!("a surface names primitive {prim}, which does not exist"),
            ));
            return (Outcome::Nothing, Vec::new());
        };
        let Some(bound) = self.widened_bound(&w) else {
            return (Outcome::Nothing, Vec::new());
        };
        let rate = if info.motion_factor > 0.0 || info.focus_factor > 0.0 {
            blurred_rate(w.surface.as_ref(), &bound, &info, &self.view)
        } else {
            info.rate
        };
        let mut decision = decide(w.surface.as_ref(), &bound, rate, &self.view);
        if info.binary {
            decision = crate::render::dice::binary(decision, self.view.max_grid);
        }
        match decision {
            Decision::Broken => {
                self.diags.report(
                    Diag::error(
                        "render::dice",
                        "a surface has points that are not finite (NaN or infinite); it is skipped",
                    )
                    .label(self.scene.primitives[prim].span, "this primitive"),
                );
                (Outcome::Nothing, Vec::new())
            }
            Decision::Cull => {
                Stats::add(&self.stats.culled, 1);
                self.stats.time(Stage::Dice, t0);
                (Outcome::Nothing, Vec::new())
            }
            Decision::Split { eye } => {
                let span = self.scene.primitives[prim].span;
                if eye && w.eye_splits >= self.eye_split_limit {
                    let help = match self.eye_splits_asked {
                        Some(asked) => format!(
                            "the scene asks for {asked} eye splits; arbor stops at {} (each can double the pieces): move the camera or the geometry",
                            self.eye_split_limit
                        ),
                        None => "move the camera or the geometry, or raise `Option \"limits\" \"eyesplits\"`".to_string(),
                    };
                    self.diags.report(
                        Diag::warning(
                            "render::eyesplits",
                            "a surface still crosses the eye plane after the most eye splits; the piece is dropped",
                        )
                        .label(span, "this primitive")
                        .help(help),
                    );
                    return (Outcome::Nothing, Vec::new());
                }
                if w.depth >= MAX_SPLIT_DEPTH {
                    self.diags.report(
                        Diag::warning(
                            "render::splits",
                            "a surface was split too many times without becoming small enough to dice; the piece is dropped",
                        )
                        .label(span, "this primitive"),
                    );
                    return (Outcome::Nothing, Vec::new());
                }
                let made = self.splits[prim].fetch_add(1, Ordering::Relaxed);
                let budget = self.split_budget(info.rate);
                if made >= budget {
                    if made == budget {
                        self.diags.report(
                            Diag::warning(
                                "render::splits",
                                format!("a surface was split {budget} times without its pieces becoming small enough to dice; the rest of it is dropped"),
                            )
                            .label(span, "this primitive")
                            .help("a point of this primitive may be far outside the scene (a stray huge coordinate)"),
                        );
                    }
                    return (Outcome::Nothing, Vec::new());
                }
                Stats::add(&self.stats.splits, 1);
                let children = w.surface.split();
                let mut placed = Vec::with_capacity(children.len());
                for (c, surface) in children.into_iter().enumerate() {
                    let child = Work {
                        surface,
                        key: mix64(w.key ^ mix64(c as u64 + 1)),
                        depth: w.depth + 1,
                        eye_splits: w.eye_splits + eye as u32,
                    };
                    match self.place(&child, row) {
                        Some(r) => placed.push((r, child)),
                        None => Stats::add(&self.stats.culled, 1),
                    }
                }
                self.stats.time(Stage::Dice, t0);
                (Outcome::Nothing, placed)
            }
            Decision::Dice { nu, nv } => {
                let mut grid = w.surface.dice(nu + 1, nv + 1);
                let n = grid.nu * grid.nv;
                if grid.nu < 2
                    || grid.nv < 2
                    || grid.p.len() != n
                    || grid.ci.len() != n
                    || grid.oi.len() != n
                {
                    self.diags.report(Diag::error(
                        "render::grid",
                        format!(
                            "a diced grid of primitive {prim} is malformed ({}×{} with {} points)",
                            grid.nu,
                            grid.nv,
                            grid.p.len()
                        ),
                    ));
                    return (Outcome::Nothing, Vec::new());
                }
                set_incident(&mut grid, self.camera.perspective);
                let trimmed = w.surface.trimmed(&grid);
                let orient = orientation(&grid);
                if info.csg.is_some_and(|c| c.inverted) {
                    // A subtracted solid's surface bounds the result from inside it.
                    grid.n.iter_mut().for_each(|n| *n = -*n);
                    grid.ng.iter_mut().for_each(|n| *n = -*n);
                }
                self.stats.time(Stage::Dice, t0);
                let t1 = Instant::now();
                let undisplaced = grid.motion.as_ref().map(|_| grid.p.clone());
                self.shader
                    .displace(self.scene, self.camera, prim, &mut grid);
                carry_to_motion_keys(undisplaced, &mut grid);
                set_incident(&mut grid, self.camera.perspective);
                self.stats.time(Stage::Displace, t1);
                Stats::add(&self.stats.grids, 1);
                Stats::add(&self.stats.micropolygons, (nu * nv) as u64);
                let clip = self.view.raster_bound(&bound).unwrap_or([
                    f32::NEG_INFINITY,
                    f32::NEG_INFINITY,
                    f32::INFINITY,
                    f32::INFINITY,
                ]);
                let (pre_bound, zmin) = self.pre_bound(&grid, &info, clip);
                let moving = grid.motion.is_some();
                let grid = PackedGrid::pack(grid);
                let bytes = grid.bytes();
                let info = GridInfo {
                    key: w.key,
                    matte: info.matte,
                    smooth: info.smooth,
                    one_sided: info.one_sided,
                    orientation: orient,
                    clip,
                    csg: info.csg,
                };
                let lazy = LazyGrid {
                    key: w.key,
                    zmin,
                    bound: pre_bound,
                    moving,
                    // Set when the grid is placed in its buckets.
                    left: AtomicUsize::new(0),
                    state: Mutex::new(GridState::Pending(Pending {
                        grid,
                        prim,
                        trimmed,
                        info,
                        bytes,
                    })),
                };
                (Outcome::Grid(Box::new(lazy)), Vec::new())
            }
        }
    }

    /// What is known of a displaced grid's [`ShadedGrid`] before its surface is shaded: a
    /// raster rectangle holding its bound (within `clip`, where sampling is cut off), and a
    /// lower bound of its zmin (−∞ when the grid must be shaded wherever it overlaps).
    fn pre_bound(
        &self,
        grid: &crate::shade::Grid,
        info: &PrimInfo,
        clip: [f32; 4],
    ) -> ([f32; 4], f32) {
        let keys = grid.motion.as_ref().map_or(&[][..], |m| &m.p[..]);
        let points = std::iter::once(&grid.p).chain(keys);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        // NaN propagates through the sum (and ±∞ leaves it non-finite), where the compares
        // below would pass it over: one test for all the points.
        let mut sum = 0f32;
        for p in points.flatten() {
            for (c, v) in [p.x, p.y, p.z].into_iter().enumerate() {
                lo[c] = if v < lo[c] { v } else { lo[c] };
                hi[c] = if v > hi[c] { v } else { hi[c] };
                sum += v * 0.0;
            }
        }
        let mut b = Bound {
            min: Vec3::from(lo),
            max: Vec3::from(hi),
        };
        if sum != 0.0 || b.is_empty() || !(b.min.is_finite() && b.max.is_finite()) {
            return (clip, f32::NEG_INFINITY);
        }
        if info.moves_points {
            b = b.grow(info.disp);
        }
        // The shaded grid's zmin is its points' nearest depth less 1e-5 of it (through 1/z
        // in perspective): 1e-4 covers that and the rounding.
        let z = b.min.z;
        let zmin = if info.shade_hidden {
            f32::NEG_INFINITY
        } else {
            z - z.abs() * 1e-4
        };
        // The grid's live micropolygons project inside the projected box (widened by the
        // circle of confusion over its depths); the slack covers rounding.
        let xy = match self.view.raster_bound(&b) {
            Some(r) => {
                let big = r.iter().fold(0f32, |m, v| m.max(v.abs()));
                let slack = 1.0 + big * 1e-5;
                [
                    (r[0] - slack).max(clip[0]),
                    (r[1] - slack).max(clip[1]),
                    (r[2] + slack).min(clip[2]),
                    (r[3] + slack).min(clip[3]),
                ]
            }
            None => clip,
        };
        (xy, zmin)
    }

    /// Shades a grid's surface (`zmin` the lower bound its hiders were promised) and projects
    /// it; None when nothing of it is left to hide.
    fn shade(&self, p: Pending, zmin: f32) -> Option<ShadedGrid> {
        let Pending {
            grid,
            prim,
            trimmed,
            info,
            bytes,
        } = p;
        self.stats.free(bytes);
        let mut grid = grid.unpack();
        let t2 = Instant::now();
        let n = grid.nu * grid.nv;
        // The surface shader may move P too (see `surface_moves_points`).
        let unshaded = grid.motion.as_ref().map(|_| grid.p.clone());
        self.shader.shade(self.scene, self.camera, prim, &mut grid);
        carry_to_motion_keys(unshaded, &mut grid);
        if let Some(cut) = trimmed.filter(|c| c.len() == grid.ci.len()) {
            for ((ci, oi), _) in grid
                .ci
                .iter_mut()
                .zip(&mut grid.oi)
                .zip(&cut)
                .filter(|(_, c)| **c)
            {
                *ci = Vec3::ZERO;
                *oi = Vec3::ZERO;
            }
        }
        Stats::add(&self.stats.shaded_points, n as u64);
        let done = |t: Instant| {
            self.stats.time(Stage::Shade, t);
            let ns = t.elapsed().as_nanos() as u64;
            SHADING_NS.with(|c| c.set(c.get() + ns));
        };
        if grid.ci.len() != n || grid.oi.len() != n || grid.p.len() != n {
            self.diags.report(Diag::error(
                "render::grid",
                "shading changed the size of a grid; the grid is dropped",
            ));
            done(t2);
            return None;
        }
        let sg = ShadedGrid::new(&grid, &self.view, &info, &self.aovs);
        // Its columns go to this thread's buffer pool, not back to the dicing thread's
        // allocator arena (see `crate::pool`).
        grid.recycle();
        done(t2);
        self.check_displacement_bound(prim, &sg, &info.clip);
        if !sg.is_empty() && sg.zmin < zmin {
            self.report_moved_nearer(prim);
        }
        if sg.is_empty() {
            return None;
        }
        self.stats.alloc(sg.bytes());
        Some(sg)
    }

    /// A surface shader moved points nearer the camera than the displacement bound allows:
    /// buckets may have skipped the grid as hidden where it is not.
    fn report_moved_nearer(&self, prim: usize) {
        let p = &self.scene.primitives[prim];
        let name = p
            .attributes
            .surface
            .as_ref()
            .map_or("?", |s| s.name.as_str());
        self.diags.report(
            Diag::warning(
                "render::displacementbound",
                format!(
                    "surface shader `{name}` moves points nearer the camera than the displacement \
                     bound allows; buckets may have skipped them as hidden"
                ),
            )
            .label(p.span, "this primitive")
            .help("declare the largest displacement: Attribute \"displacementbound\" \"sphere\" [d] (in object space)"),
        );
    }
}

/// A grid moved by a shader at shutter open (`before` is where its points were): every
/// motion key carries the same offset, and the first key is the moved grid.
fn carry_to_motion_keys(before: Option<Vec<Vec3>>, grid: &mut crate::shade::Grid) {
    let (Some(before), Some(m)) = (before, grid.motion.as_mut()) else {
        return;
    };
    if before != grid.p {
        for key in m.p.iter_mut().skip(1) {
            for ((k, b), a) in key.iter_mut().zip(&before).zip(&grid.p) {
                *k += *a - *b;
            }
        }
    }
    if let Some(k0) = m.p.first_mut() {
        k0.clone_from(&grid.p);
    }
}

/// I = P − E: the eye at the origin for perspective views, straight along +z for orthographic.
pub(super) fn set_incident(grid: &mut crate::shade::Grid, perspective: bool) {
    let n = grid.p.len();
    grid.i.resize(n, Vec3::ZERO);
    for (i, p) in grid.i.iter_mut().zip(&grid.p) {
        *i = if perspective {
            *p
        } else {
            Vec3::new(0.0, 0.0, p.z)
        };
    }
}

/// Renders `surfaces[i]` (the surfaces of primitive `i`) with the frame's camera: the body of
/// [`render_frame`], usable with surfaces from anywhere.
pub fn render_surfaces(
    scene: &Scene,
    options: &Options,
    camera: &Camera,
    surfaces: Vec<Vec<Box<dyn Surface>>>,
    shader: &dyn GridShader,
    opts: &RenderOptions,
    diags: &Diagnostics,
) -> Film {
    render_surfaces_rows(scene, options, camera, surfaces, shader, opts, None, diags)
}

/// [`render_surfaces`], handing `rows` the finished scanlines as [`render_frame_rows`] does.
#[allow(clippy::too_many_arguments)]
pub fn render_surfaces_rows(
    scene: &Scene,
    options: &Options,
    camera: &Camera,
    surfaces: Vec<Vec<Box<dyn Surface>>>,
    shader: &dyn GridShader,
    opts: &RenderOptions,
    rows: Option<&mut (dyn RowSink + Send)>,
    diags: &Diagnostics,
) -> Film {
    run_in_pool(opts, diags, || {
        render_inner(
            scene,
            options,
            camera,
            Surfaces::Built(surfaces),
            shader,
            opts,
            rows,
            diags,
        )
    })
}

/// Runs `run` on `opts.threads` threads (rayon's default pool for 0).
fn run_in_pool<T: Send>(
    opts: &RenderOptions,
    diags: &Diagnostics,
    run: impl FnOnce() -> T + Send,
) -> T {
    if opts.threads > 0 {
        match rayon::ThreadPoolBuilder::new()
            .num_threads(opts.threads)
            .build()
        {
            Ok(pool) => return pool.install(run),
            Err(e) => diags.report(Diag::warning(
                "render::threads",
                format!(
                    "could not start {} render threads ({e}); using the default pool",
                    opts.threads
                ),
            )),
        }
    }
    run()
}

#[allow(clippy::too_many_arguments)]
fn render_inner(
    scene: &Scene,
    options: &Options,
    camera: &Camera,
    surfaces: Surfaces,
    shader: &dyn GridShader,
    opts: &RenderOptions,
    rows_out: Option<&mut (dyn RowSink + Send)>,
    diags: &Diagnostics,
) -> Film {
    let wall = Instant::now();
    let local_stats = Stats::new();
    let stats = opts.stats.unwrap_or(&local_stats);
    // Where the wall time goes, thread by thread (`--stats` only: it reads /proc).
    let mut clock = opts.stats.map(|s| {
        let tids = super::stats::pool_threads();
        s.threads.store(tids.len() as u64, Ordering::Relaxed);
        PhaseClock::now(std::sync::Arc::new(tids))
    });
    let threads_clock = clock
        .as_ref()
        .map(|c| super::stats::ThreadClock::now(c.tids()));
    let (xres, yres) = (camera.xres, camera.yres);
    let image = PixelRect {
        x0: 0,
        y0: 0,
        x1: xres as i32,
        y1: yres as i32,
    };
    let crop = crop_region(xres, yres, options.crop_window);
    let margin_of = |w: f32| {
        if w.is_finite() && w > 0.0 {
            (w * 0.5).ceil() as i32
        } else {
            1
        }
    };
    let margin = [
        margin_of(options.pixel_filter.xwidth),
        margin_of(options.pixel_filter.ywidth),
    ];
    let size = opts
        .bucket_size
        .map(|[x, y]| [x as i32, y as i32])
        .unwrap_or_else(|| match options.user_floats("limits:bucketsize") {
            Some([x, y, ..]) => [*x as i32, *y as i32],
            Some([x]) => [*x as i32, *x as i32],
            _ => [DEFAULT_BUCKET as i32; 2],
        });
    let size = super::limits::bucket_size(size, diags);
    let buckets = Buckets {
        crop,
        image,
        size,
        margin,
        // An empty crop region renders no bucket at all.
        cols: crop.width().div_ceil(size[0] as usize),
        rows: crop.height().div_ceil(size[1] as usize),
    };
    let max_grid = options
        .user_floats("limits:gridsize")
        .and_then(|f| f.first())
        .map_or(DEFAULT_GRID, |&g| {
            super::limits::grid_size(g, DEFAULT_GRID, diags)
        });
    let (eye_split_limit, eye_splits_asked) = super::limits::eye_splits(
        options
            .user_floats("limits:eyesplits")
            .and_then(|f| f.first().copied()),
        DEFAULT_EYE_SPLITS,
    );
    let view = View::new(
        camera,
        crop.grow(margin[0], margin[1]).intersect(image),
        max_grid,
    );
    let seed = mix64(scene.frame.unwrap_or(0) as i64 as u64);
    let mut config = HiderConfig::from_options(options, camera, &opts.aovs, seed, diags);
    let (csg_tree, csg_places) = CsgTree::new(scene);
    if !csg_tree.is_empty() && options.hider.name == "abuffer" {
        diags.report(Diag::warning(
            "render::csg",
            "solid modelling (SolidBegin) needs Hider \"hidden\"; the A-buffer draws every surface of the solids",
        ));
    }
    config.csg = std::sync::Arc::new(csg_tree);
    let depth_filter = match config.depth_filter {
        DepthFilter::Max => FilmDepthFilter::Max,
        DepthFilter::Average => FilmDepthFilter::Average,
        // Midpoint is resolved per sample by the hider; the pixel keeps the nearest.
        DepthFilter::Min | DepthFilter::Midpoint => FilmDepthFilter::Min,
    };
    let hider = make_hider(options, config, diags);
    let min_rate = super::limits::min_shading_rate(options);
    let mut prims: Vec<PrimInfo> = scene
        .primitives
        .iter()
        .zip(&csg_places)
        .map(|(p, c)| PrimInfo {
            csg: *c,
            ..prim_info(scene, camera, p, min_rate, diags)
        })
        .collect();
    let (mut built, make): (Vec<Option<SurfaceList>>, Option<&MakeSurfaces>) = match surfaces {
        Surfaces::Built(v) => (v.into_iter().map(Some).collect(), None),
        Surfaces::Lazy(m) => ((0..scene.primitives.len()).map(|_| None).collect(), Some(m)),
    };
    if let Some(m) = make {
        // Displaced primitives needing an estimated bound keep their surfaces.
        for (i, slot) in built.iter_mut().enumerate() {
            if needs_estimate(scene, &prims, i) {
                *slot = Some(m(i, diags));
            }
        }
    }
    estimate_displacement_bounds(scene, camera, &view, &built, &mut prims, shader);
    let frame = Frame {
        scene,
        camera,
        view,
        prims,
        shader,
        hider,
        buckets,
        stats,
        diags,
        aovs: opts.aovs.clone(),
        eye_split_limit,
        eye_splits_asked,
        splits: (0..scene.primitives.len())
            .map(|_| std::sync::atomic::AtomicU64::new(0))
            .collect(),
    };
    let mut channel_names = Vec::new();
    for a in &opts.aovs {
        channel_names.extend(a.channel_names());
    }
    let film_channels = Film::standard_channels(&channel_names);
    // An empty film of the same channels answers the questions asked before the film is
    // made (alongside the first row's surfaces, below).
    let film_shape = Film::new(0, 0, film_channels.clone());
    let film_bytes =
        xres as usize * yres as usize * film_channels.len() * std::mem::size_of::<f32>();
    stats.alloc(film_bytes);

    // Place every surface in the first bucket row it reaches (in parallel, diagnostics in
    // primitive order); primitives cheap to make again keep only their first row.
    Stats::add(&stats.primitives, scene.primitives.len() as u64);
    let mut pending: Vec<Vec<Work>> = (0..buckets.rows).map(|_| Vec::new()).collect();
    let mut pending_prims: Vec<Vec<u32>> = (0..buckets.rows).map(|_| Vec::new()).collect();
    let placed: Vec<(Vec<Placed>, Diags)> = built
        .par_chunks_mut(PLACE_CHUNK)
        .enumerate()
        .map(|(c, slots)| {
            let local = Diagnostics::new();
            let mut out = Vec::with_capacity(slots.len());
            for (k, slot) in slots.iter_mut().enumerate() {
                let i = c * PLACE_CHUNK + k;
                let (list, remade) = match (slot.take(), make) {
                    (Some(l), _) => (l, false),
                    (None, Some(m)) => (m(i, &local), remade_cheaply(&scene.primitives[i])),
                    (None, None) => (Vec::new(), false),
                };
                let works = frame.place_all(i, list, 0);
                out.push(if remade {
                    Placed::Remade {
                        prim: i,
                        first: works.iter().filter_map(|(r, _)| *r).min(),
                        surfaces: works.len(),
                        culled: works.iter().filter(|(r, _)| r.is_none()).count(),
                    }
                } else {
                    Placed::Works(works)
                });
            }
            (out, local.take())
        })
        .collect();
    drop(built);
    for (out, ds) in placed {
        diags.absorb(ds);
        for p in out {
            match p {
                Placed::Works(works) => {
                    Stats::add(&stats.surfaces, works.len() as u64);
                    for (row, w) in works {
                        match row {
                            Some(r) => pending[r].push(w),
                            None => Stats::add(&stats.culled, 1),
                        }
                    }
                }
                Placed::Remade {
                    prim,
                    first,
                    surfaces,
                    culled,
                } => {
                    Stats::add(&stats.surfaces, surfaces as u64);
                    Stats::add(&stats.culled, culled as u64);
                    if let Some(r) = first {
                        pending_prims[r].push(prim as u32);
                    }
                }
            }
        }
    }

    let total = buckets.rows * buckets.cols;
    let done = AtomicUsize::new(0);
    let pixel_filter = crate::film::Filter::from_scene(&options.pixel_filter);
    let tables = pixel_filter.tables();
    // The usual r g b a z buffer under a narrow separable filter: each bucket's samples are
    // prepared for the vectorised gather as soon as they are hidden.
    let hcfg = frame.hider.config();
    let gather = tables
        .as_ref()
        .filter(|t| {
            crate::film::gather::applies(
                &pixel_filter,
                Some(t),
                hcfg.channels(),
                frame.hider.samples_per_pixel(),
                &film_shape,
            )
        })
        .map(|t| crate::film::gather::PrepareCtx::new(&pixel_filter, t, depth_filter));
    let (kx, ky) = (buckets.reach(0), buckets.reach(1));
    // Filters the tile of bucket (col, row) from `parts` (the hidden buckets of the rows
    // and columns within reach, row-major: see `within_reach`) and `partial` (the pixels its
    // own hiding already filtered), and counts the bucket as done.
    let filter_one = |film: &Film,
                      col: usize,
                      row: usize,
                      parts: &[&Hidden],
                      partial: Option<crate::film::gather::Partial>|
     -> crate::film::Tile {
        let t = Instant::now();
        let r = buckets.rect(col, row);
        let (x0, y0) = (r.x0 as usize, r.y0 as usize);
        let prepared: Option<Vec<&crate::film::gather::Prepared>> = parts
            .iter()
            .map(|h| match h {
                Hidden::Prepared(p) => Some(p),
                Hidden::Samples(_) => None,
            })
            .collect();
        let tile = if let Some(p) = prepared {
            let partial = partial.unwrap_or_else(|| {
                crate::film::gather::Partial::empty(film, x0, y0, r.width(), r.height())
            });
            crate::film::gather::finish_tile(film, &p, partial)
        } else {
            let region = r
                .grow(buckets.margin[0], buckets.margin[1])
                .intersect(buckets.image);
            let bufs: Vec<&SampleBuffer> = parts
                .iter()
                .filter_map(|h| match h {
                    Hidden::Samples(b) => Some(b),
                    Hidden::Prepared(..) => None,
                })
                .collect();
            let buf = assemble(region, &bufs);
            crate::film::filter_tile(
                film,
                &buf,
                &pixel_filter,
                x0,
                y0,
                r.width(),
                r.height(),
                depth_filter,
            )
        };
        stats.time(Stage::Filter, t);
        Stats::add(&stats.buckets, 1);
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(p) = opts.progress {
            p(d, total);
        }
        tile
    };
    // Splits, dices and displaces everything that starts in `row`: the surfaces of the
    // primitives first reaching it are made again (diagnostics were reported the first
    // time), then everything is split, diced and displaced. Returns the row's grids, to be
    // shaded when a bucket asks.
    let process =
        |row: usize, pending: &mut [Vec<Work>], pending_prims: &mut [Vec<u32>]| -> Vec<Kept> {
            let mut kept = Vec::new();
            let mut frontier = std::mem::take(&mut pending[row]);
            let starting = std::mem::take(&mut pending_prims[row]);
            if let (false, Some(m)) = (starting.is_empty(), make) {
                let quiet = Diagnostics::new();
                let made: Vec<Vec<(Option<usize>, Work)>> = starting
                    .into_par_iter()
                    .map(|i| {
                        let i = i as usize;
                        frame.place_all(i, m(i, &quiet), row)
                    })
                    .collect();
                for (r, w) in made.into_iter().flatten() {
                    match r {
                        Some(r) if r == row => frontier.push(w),
                        Some(r) => pending[r].push(w),
                        None => {}
                    }
                }
            }
            while !frontier.is_empty() {
                let results: Vec<(Outcome, Vec<(usize, Work)>)> = frontier
                    .into_par_iter()
                    .map(|w| frame.step(w, row))
                    .collect();
                frontier = Vec::new();
                for (outcome, children) in results {
                    for (r, w) in children {
                        if r == row {
                            frontier.push(w);
                        } else {
                            pending[r].push(w);
                        }
                    }
                    match outcome {
                        Outcome::Grid(g) => {
                            let b = g.bound;
                            let (Some(rows), Some(cols)) =
                                (buckets.span(b[1], b[3], 1), buckets.span(b[0], b[2], 0))
                            else {
                                Stats::add(&stats.grids_unshaded, 1);
                                continue;
                            };
                            stats.alloc(g.bytes());
                            let rows = (rows.0.max(row), rows.1.max(row));
                            // Every bucket of these rows and columns is given the grid.
                            let buckets = (rows.1 - rows.0 + 1) * (cols.1 - cols.0 + 1);
                            g.left.store(buckets, Ordering::Relaxed);
                            kept.push(Kept {
                                grid: g,
                                rows,
                                cols,
                            });
                        }
                        Outcome::Nothing => {}
                    }
                }
            }
            kept
        };
    clock = stats.phase(Phase::Setup, clock);
    // The film is made (its pages first touched: ~10 ms at 1280 × 960) while the first row's
    // surfaces are split, diced and shaded — before, it ran alone, the other thread idle.
    let (film, first): (Film, Vec<Kept>) = rayon::join(
        || Film::new(xres as usize, yres as usize, film_channels),
        || {
            if buckets.rows > 0 {
                process(0, &mut pending, &mut pending_prims)
            } else {
                Vec::new()
            }
        },
    );
    clock = stats.phase(Phase::FirstRow, clock);
    // Tiles are filtered against the film's shape while the film itself takes finished rows.
    let shape = film.shape();
    // Hides bucket (col, row) from the grids of `list` overlapping it, prepared for the filter
    // at once, with the pixels needing no other bucket already filtered (while hot).
    let hide_one = |col: usize, row: usize, list: &[Arc<Kept>]| -> (Hidden, Option<Partial>) {
        let t = Instant::now();
        let sources: Vec<Source> = list
            .iter()
            .filter(|k| k.rows.0 <= row && row <= k.rows.1 && k.cols.0 <= col && col <= k.cols.1)
            .map(|k| Source {
                frame: &frame,
                grid: &k.grid,
                got: OnceLock::new(),
            })
            .collect();
        let grids: Vec<&dyn GridSource> = sources.iter().map(|s| s as &dyn GridSource).collect();
        // Shading asked for by the hider counts as shading, not hiding.
        let shading_before = SHADING_NS.with(Cell::get);
        let hide_time = |t: Instant| {
            let shading = SHADING_NS.with(Cell::get) - shading_before;
            let ns = (t.elapsed().as_nanos() as u64).saturating_sub(shading);
            stats.add_time(Stage::Hide, ns);
        };
        let rect = buckets.sample_rect(col, row);
        let h = match &gather {
            Some(ctx) => {
                let mut p = match frame.hider.hide_prepared(rect, &grids, stats, ctx) {
                    Some(p) => {
                        hide_time(t);
                        p
                    }
                    None => {
                        let buf = frame.hider.hide(rect, &grids, stats);
                        hide_time(t);
                        let t = Instant::now();
                        let p = crate::film::gather::prepare(&buf, ctx);
                        stats.time(Stage::Filter, t);
                        p
                    }
                };
                let t = Instant::now();
                let out = buckets.rect(col, row);
                let partial = crate::film::gather::start_tile(
                    &shape,
                    &p,
                    out.x0 as usize,
                    out.y0 as usize,
                    out.width(),
                    out.height(),
                );
                p.keep_ring(&partial, ctx);
                stats.time(Stage::Filter, t);
                (Hidden::Prepared(p), Some(partial))
            }
            None => {
                let buf = frame.hider.hide(rect, &grids, stats);
                hide_time(t);
                (Hidden::Samples(buf), None)
            }
        };
        // This bucket is done with its grids: the last bucket of each drops it.
        drop(grids);
        for src in sources {
            let grid = src.grid;
            drop(src);
            grid.bucket_done(stats);
        }
        stats.alloc(h.0.bytes());
        h
    };
    let filter = |col: usize, row: usize, parts: &[&Hidden], partial: Option<Partial>| {
        filter_one(&shape, col, row, parts, partial)
    };
    let retire = |h: Hidden| {
        stats.free(h.bytes());
        if let (Hidden::Prepared(p), Some(ctx)) = (h, &gather) {
            ctx.recycle(p);
        }
    };
    // Scanlines handed to `rows_out`, and scanlines final in the film.
    let first_line = buckets.crop.y0.max(0) as usize;
    let flow = Flow::new(
        buckets,
        [kx, ky],
        Lane {
            film,
            rows_out,
            next: 0,
            sent: first_line,
            finished: first_line,
        },
        Chain {
            pending,
            prims: pending_prims,
            live: Vec::new(),
        },
        Steps {
            process: &process,
            hide: &hide_one,
            filter: &filter,
            retire: &retire,
        },
        stats,
    );
    if buckets.rows > 0 && buckets.cols > 0 {
        rayon::scope(|s| flow.start(s, first));
    }
    clock = stats.phase(Phase::Rows, clock);
    let Lane {
        film,
        rows_out,
        sent,
        finished,
        ..
    } = flow.finish();
    clock = stats.phase(Phase::Filter, clock);
    // Whatever scanlines are left (none: each row is handed out as it is put in the film).
    if let Some(out) = rows_out {
        out.rows(&film, sent, finished);
    }
    frame.hider.finish(diags);
    stats.phase(Phase::Other, clock);
    if let Some(t) = threads_clock {
        t.stop(stats);
    }
    stats.free(film_bytes);
    stats
        .wall_ns
        .fetch_add(wall.elapsed().as_nanos() as u64, Ordering::Relaxed);
    film
}

type Partial = crate::film::gather::Partial;
type Tile = crate::film::Tile;

/// The film and where its output stands: written by one thread at a time (the lane).
struct Lane<'o> {
    film: Film,
    rows_out: Option<&'o mut (dyn RowSink + Send)>,
    /// The next bucket row whose tiles go into the film.
    next: usize,
    /// Scanlines handed to `rows_out`, and scanlines final in the film.
    sent: usize,
    finished: usize,
}

/// What the making of bucket rows hands from one row to the next (one row is made at a time).
struct Chain {
    /// Work waiting for its first bucket row, and primitives to make again there.
    pending: Vec<Vec<Work>>,
    prims: Vec<Vec<u32>>,
    /// The grids reaching the row last made, in the order its buckets take them.
    live: Vec<Arc<Kept>>,
}

/// The frame's steps, as the driver defines them.
type Process<'a> = dyn Fn(usize, &mut [Vec<Work>], &mut [Vec<u32>]) -> Vec<Kept> + Sync + 'a;
type HideOne<'a> = dyn Fn(usize, usize, &[Arc<Kept>]) -> (Hidden, Option<Partial>) + Sync + 'a;
type FilterOne<'a> = dyn Fn(usize, usize, &[&Hidden], Option<Partial>) -> Tile + Sync + 'a;
struct Steps<'a> {
    /// Splits, dices and displaces what starts in a row (see `process` in `render_inner`).
    process: &'a Process<'a>,
    /// Hides bucket (col, row) from the grids of its row.
    hide: &'a HideOne<'a>,
    /// Filters tile (col, row) from the hidden buckets within reach, row-major.
    filter: &'a FilterOne<'a>,
    /// Gives back a hidden bucket no tile needs any more.
    retire: &'a (dyn Fn(Hidden) + Sync + 'a),
}

/// A bucket's state between its hiding and the filtering of the last tile reading it (alone
/// in its cache lines: neighbouring buckets are written by different threads).
#[repr(align(128))]
#[derive(Default)]
struct BucketCell {
    /// Set once hidden; taken when the last tile reading it is filtered.
    hidden: RwLock<Option<Hidden>>,
    /// The bucket's own tile, started by its hiding.
    partial: Mutex<Option<Partial>>,
    /// The tile of this bucket: buckets within reach hidden so far, and the tile once
    /// filtered (until it goes into the film).
    waiting: AtomicUsize,
    tile: Mutex<Option<Tile>>,
    /// Tiles within reach that have read this bucket.
    readers: AtomicUsize,
}

/// A bucket row's progress.
#[derive(Default)]
struct RowCell {
    /// What the making of this row still waits for: the row above made, and every row up
    /// to two above hidden (so only the grids of the open rows are held).
    deps: AtomicUsize,
    hidden: AtomicUsize,
    /// What this row waits for to count as hidden in order: its own buckets, and the rows
    /// above it hidden in order (rows may finish out of order).
    settle: AtomicUsize,
    filtered: AtomicUsize,
}

/// The frame as a dataflow over bucket rows, without a barrier between rows: row r's
/// surfaces are made (split, diced, displaced) once row r − 1 is made and row r − 2 is
/// hidden; row r's buckets are hidden, in parallel, as soon as its surfaces are made (a
/// thread done with row r − 1 starts on row r while the other finishes its last bucket);
/// a tile is filtered by the thread hiding the last bucket within its reach; a row's tiles
/// go into the film, and its scanlines to the output, in row order, by whichever thread
/// finds the lane free. Every step reads only what its dependencies finished, so the
/// picture is the same for any thread count and order.
struct Flow<'a, 'o> {
    buckets: Buckets,
    /// Filter reach in buckets, x and y.
    reach: [usize; 2],
    cells: Vec<BucketCell>,
    rows: Vec<RowCell>,
    chain: Mutex<Chain>,
    lane: Mutex<Lane<'o>>,
    /// `lane.next`, readable without the lane.
    lane_next: AtomicUsize,
    steps: Steps<'a>,
    stats: &'a Stats,
}

/// A lock's guard even after a panic elsewhere while it was held (the panic is re-raised by
/// the scope; nothing here is left half updated).
fn locked<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl<'a, 'o> Flow<'a, 'o> {
    fn new(
        buckets: Buckets,
        reach: [usize; 2],
        lane: Lane<'o>,
        chain: Chain,
        steps: Steps<'a>,
        stats: &'a Stats,
    ) -> Self {
        let rows = (0..buckets.rows)
            .map(|r| RowCell {
                deps: AtomicUsize::new(r.min(2)),
                settle: AtomicUsize::new(r.min(1) + 1),
                ..RowCell::default()
            })
            .collect();
        Flow {
            buckets,
            reach,
            cells: (0..buckets.rows * buckets.cols)
                .map(|_| BucketCell::default())
                .collect(),
            rows,
            chain: Mutex::new(chain),
            lane: Mutex::new(lane),
            lane_next: AtomicUsize::new(0),
            steps,
            stats,
        }
    }

    fn cell(&self, col: usize, row: usize) -> &BucketCell {
        &self.cells[row * self.buckets.cols + col]
    }

    /// The rows and columns of buckets within filter reach of (col, row): those its tile
    /// reads, and (the same) those whose tiles read it.
    fn near(&self, col: usize, row: usize) -> [std::ops::RangeInclusive<usize>; 2] {
        let [kx, ky] = self.reach;
        [
            row.saturating_sub(ky)..=(row + ky).min(self.buckets.rows - 1),
            col.saturating_sub(kx)..=(col + kx).min(self.buckets.cols - 1),
        ]
    }

    fn count_near(&self, col: usize, row: usize) -> usize {
        let [rs, cs] = self.near(col, row);
        rs.count() * cs.count()
    }

    /// Row 0 is made (`first`): everything else follows from there.
    fn start<'s>(&'s self, s: &rayon::Scope<'s>, first: Vec<Kept>) {
        let list: Vec<Arc<Kept>> = first.into_iter().map(Arc::new).collect();
        locked(&self.chain).live = list.clone();
        self.made(s, 0, list);
    }

    /// Row `row`'s surfaces are made: its buckets can be hidden, the next row made.
    fn made<'s>(&'s self, s: &rayon::Scope<'s>, row: usize, list: Vec<Arc<Kept>>) {
        self.release(s, row + 1);
        // Spawned last, so this thread takes it first (the next row's making is the older
        // job, the one another thread steals).
        s.spawn(move |s| {
            (0..self.buckets.cols)
                .into_par_iter()
                .for_each(|col| self.bucket(s, col, row, &list));
        });
    }

    /// One of the things the making of `row` waits for is done.
    fn release<'s>(&'s self, s: &rayon::Scope<'s>, row: usize) {
        if row < self.buckets.rows && self.rows[row].deps.fetch_sub(1, Ordering::AcqRel) == 1 {
            s.spawn(move |s| self.make(s, row));
        }
    }

    /// Splits, dices and displaces what starts in `row`.
    fn make<'s>(&'s self, s: &rayon::Scope<'s>, row: usize) {
        // Taken out of the lock for the work (rows are made one at a time).
        let (mut pending, mut prims, live) = {
            let mut c = locked(&self.chain);
            (
                std::mem::take(&mut c.pending),
                std::mem::take(&mut c.prims),
                std::mem::take(&mut c.live),
            )
        };
        let next = (self.steps.process)(row, &mut pending, &mut prims);
        let list: Vec<Arc<Kept>> = live
            .into_iter()
            .filter(|k| k.rows.1 >= row)
            .chain(next.into_iter().map(Arc::new))
            .collect();
        {
            let mut c = locked(&self.chain);
            c.pending = pending;
            c.prims = prims;
            c.live = list.clone();
        }
        self.made(s, row, list);
    }

    /// Hides bucket (col, row), then filters the tiles it was the last one missing for.
    fn bucket<'s>(&'s self, s: &rayon::Scope<'s>, col: usize, row: usize, list: &[Arc<Kept>]) {
        let (h, partial) = (self.steps.hide)(col, row, list);
        let cell = self.cell(col, row);
        *locked(&cell.partial) = partial;
        *cell.hidden.write().unwrap_or_else(|e| e.into_inner()) = Some(h);
        // AcqRel: the thread completing a count sees everything it counts.
        if self.rows[row].hidden.fetch_add(1, Ordering::AcqRel) + 1 == self.buckets.cols {
            self.settle(s, row);
        }
        let [rs, cs] = self.near(col, row);
        for f in rs {
            for c in cs.clone() {
                let t = self.cell(c, f);
                if t.waiting.fetch_add(1, Ordering::AcqRel) + 1 == self.count_near(c, f) {
                    self.filter(c, f);
                }
            }
        }
    }

    /// Row `row`'s buckets, or the rows above it, are all hidden: once both, the row after
    /// next may be made (every grid of the rows above it is then released), and the row
    /// below may settle in turn.
    fn settle<'s>(&'s self, s: &rayon::Scope<'s>, row: usize) {
        let mut r = row;
        while r < self.buckets.rows && self.rows[r].settle.fetch_sub(1, Ordering::AcqRel) == 1 {
            self.release(s, r + 2);
            r += 1;
        }
    }

    /// Filters tile (col, row), whose buckets within reach are all hidden.
    fn filter(&self, col: usize, row: usize) {
        let [rs, cs] = self.near(col, row);
        let tile = {
            // Row-major, the order the tile's result depends on.
            let guards: Vec<_> = rs
                .clone()
                .flat_map(|r| cs.clone().map(move |c| (c, r)))
                .map(|(c, r)| {
                    self.cell(c, r)
                        .hidden
                        .read()
                        .unwrap_or_else(|e| e.into_inner())
                })
                .collect();
            let parts: Vec<&Hidden> = guards.iter().filter_map(|g| g.as_ref()).collect();
            let partial = locked(&self.cell(col, row).partial).take();
            (self.steps.filter)(col, row, &parts, partial)
        };
        *locked(&self.cell(col, row).tile) = Some(tile);
        // The buckets this was the last reader of are given back.
        for r in rs {
            for c in cs.clone() {
                let b = self.cell(c, r);
                if b.readers.fetch_add(1, Ordering::AcqRel) + 1 == self.count_near(c, r) {
                    let h = b.hidden.write().unwrap_or_else(|e| e.into_inner()).take();
                    if let Some(h) = h {
                        (self.steps.retire)(h);
                    }
                }
            }
        }
        if self.rows[row].filtered.fetch_add(1, Ordering::AcqRel) + 1 == self.buckets.cols {
            self.drain();
        }
    }

    /// Whether the next row for the film has all its tiles.
    fn row_ready(&self) -> bool {
        let n = self.lane_next.load(Ordering::Acquire);
        n < self.buckets.rows && self.rows[n].filtered.load(Ordering::Acquire) == self.buckets.cols
    }

    /// Puts the filtered rows into the film in order and hands their scanlines out, unless
    /// another thread holds the lane (it then takes these rows too). Never waits: the
    /// holder may be inside a parallel loop, running this very task.
    fn drain(&self) {
        while self.row_ready() {
            let mut lane = match self.lane.try_lock() {
                Ok(l) => l,
                Err(std::sync::TryLockError::Poisoned(e)) => e.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => return,
            };
            let lane = &mut *lane;
            let first = lane.next;
            while lane.next < self.buckets.rows
                && self.rows[lane.next].filtered.load(Ordering::Acquire) == self.buckets.cols
            {
                let f = lane.next;
                let t = Instant::now();
                let tiles: Vec<Tile> = (0..self.buckets.cols)
                    .filter_map(|c| locked(&self.cell(c, f).tile).take())
                    .collect();
                lane.film.put_tiles(&tiles);
                // Into this thread's buffer pool, not the filtering threads' arenas.
                tiles.into_iter().for_each(|t| crate::pool::give(t.data));
                self.stats.time(Stage::Filter, t);
                lane.finished = self.buckets.rect(0, f).y1.max(0) as usize;
                lane.next = f + 1;
            }
            if lane.next > first {
                if let Some(out) = lane.rows_out.as_deref_mut() {
                    out.rows(&lane.film, lane.sent, lane.finished);
                }
                lane.sent = lane.finished;
            }
            self.lane_next.store(lane.next, Ordering::Release);
            // Unlocked here; a row finished meanwhile (its filterer found the lane taken)
            // is taken by the next round.
        }
    }

    /// After the scope: the film and where its output stands.
    fn finish(self) -> Lane<'o> {
        self.drain();
        debug_assert_eq!(self.lane_next.load(Ordering::Relaxed), self.buckets.rows);
        for c in &self.cells {
            // Every bucket is read by its own tile, so none is left (bytes counted anyway).
            if let Some(h) = c.hidden.write().unwrap_or_else(|e| e.into_inner()).take() {
                (self.steps.retire)(h);
            }
        }
        for k in &locked(&self.chain).live {
            // The last row's grids are counted when it is hidden; none is left.
            debug_assert!(k.rows.1 + 1 >= self.buckets.rows);
        }
        self.lane.into_inner().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::Mutex;

    use super::*;
    use crate::render::dice::tests::Quad;
    use crate::render::DefaultShader;
    use crate::scene::{Attributes, Geometry, PixelFilter, Projection};
    use crate::shade::Grid;

    /// `Ci = Cs·Os`, `Oi = Os` with Cs/Os from the primitive's Color/Opacity: a "constant"
    /// surface.
    struct Constant;
    impl GridShader for Constant {
        fn displace(&self, _: &Scene, _: &Camera, _: usize, _: &mut Grid) {}
        fn shade(&self, scene: &Scene, _: &Camera, prim: usize, g: &mut Grid) {
            let a = &scene.primitives[prim].attributes;
            for k in 0..g.len() {
                g.cs[k] = a.color;
                g.os[k] = a.opacity;
                g.oi[k] = a.opacity;
                g.ci[k] = a.color * a.opacity;
            }
        }
    }

    fn primitive(attributes: Attributes) -> Primitive {
        Primitive {
            geometry: Arc::new(Geometry::Points { npoints: 0 }),
            primvars: Arc::default(),
            attributes: Arc::new(attributes),
            world_from_object: glam::Mat4::IDENTITY.into(),
            span: Default::default(),
            motion: None,
        }
    }

    fn scene(xres: u32, yres: u32, projection: Projection, prims: Vec<Attributes>) -> Scene {
        let mut s = Scene::default();
        s.options.xres = xres;
        s.options.yres = yres;
        s.options.projection = projection;
        s.options.pixel_filter = PixelFilter {
            name: "box".into(),
            xwidth: 1.0,
            ywidth: 1.0,
        };
        s.primitives = prims.into_iter().map(primitive).collect();
        s
    }

    fn attrs(color: Vec3, opacity: Vec3) -> Attributes {
        Attributes {
            color,
            opacity,
            ..Attributes::default()
        }
    }

    fn render(
        scene: &Scene,
        quads: &[Quad],
        shader: &dyn GridShader,
        opts: &RenderOptions,
    ) -> (Film, Diagnostics) {
        let diags = Diagnostics::new();
        let options = effective_options(&scene.options, opts);
        let camera =
            Camera::from_options(&options, scene.camera_from_world, &scene.coordinate_systems);
        let mut surfaces: Vec<Vec<Box<dyn Surface>>> =
            (0..scene.primitives.len()).map(|_| Vec::new()).collect();
        for q in quads {
            surfaces[q.prim].push(Box::new(q.clone()));
        }
        let film = render_surfaces(scene, &options, &camera, surfaces, shader, opts, &diags);
        (film, diags)
    }

    #[test]
    fn constant_surface_over_the_frame_is_exactly_its_colour() {
        let c = Vec3::new(0.2, 0.4, 0.6);
        let s = scene(32, 24, Projection::Orthographic, vec![attrs(c, Vec3::ONE)]);
        let quads = [Quad::rect(-2.0, -2.0, 2.0, 2.0, 5.0, 0)];
        let (film, diags) = render(&s, &quads, &Constant, &RenderOptions::default());
        assert!(!diags.has_errors());
        for y in 0..24 {
            for x in 0..32 {
                let p = film.pixel(x, y);
                for ch in 0..3 {
                    assert!((p[ch] - c[ch]).abs() < 1e-6, "pixel {x},{y}: {p:?}");
                }
                assert!((p[3] - 1.0).abs() < 1e-6);
                assert_eq!(p[4], 5.0);
            }
        }
    }

    #[test]
    fn half_plane_edge_pixel_has_half_coverage() {
        // Raster pixel (8, 8) of a 16×16 image over the screen [-1,1]²: its centre is at
        // screen (0.0625, −0.0625). A half-plane whose edge passes through that centre covers
        // exactly half the pixel's area, at any angle.
        let centre = Vec3::new(0.0625, -0.0625, 3.0);
        for (deg, spp) in [(20.0f32, 4.0f32), (47.0, 8.0), (110.0, 16.0)] {
            let (sn, cs) = deg.to_radians().sin_cos();
            let rot = |x: f32, y: f32| centre + Vec3::new(cs * x - sn * y, sn * x + cs * y, 0.0);
            let q = Quad::new(
                rot(-10.0, -10.0),
                rot(0.0, -10.0),
                rot(-10.0, 10.0),
                rot(0.0, 10.0),
                0,
            );
            let mut s = scene(
                16,
                16,
                Projection::Orthographic,
                vec![attrs(Vec3::ONE, Vec3::ONE)],
            );
            s.options.pixel_samples = [spp, spp];
            let (film, _) = render(&s, &[q], &Constant, &RenderOptions::default());
            let cov = film.pixel(8, 8)[3];
            let tol = 2.0 / spp; // 2/√(spp²)
            assert!((cov - 0.5).abs() <= tol, "angle {deg}: coverage {cov}");
            assert!(cov > 0.0 && cov < 1.0, "angle {deg}: coverage {cov}");
            // Five pixels from the edge along its normal (raster y points down): fully in / out.
            let at = |d: f32| {
                let (x, y) = (8.5 + d * cs, 8.5 - d * sn);
                film.pixel(x as usize, y as usize)[3]
            };
            assert_eq!((at(-5.0), at(5.0)), (1.0, 0.0), "angle {deg}");
        }
    }

    #[test]
    fn four_half_transparent_layers_composite_front_to_back() {
        let half = Vec3::splat(0.5);
        let s = scene(
            8,
            8,
            Projection::Orthographic,
            vec![attrs(Vec3::ONE, half); 4],
        );
        let quads: Vec<Quad> = (0..4)
            .map(|i| Quad::rect(-2.0, -2.0, 2.0, 2.0, 1.0 + i as f32, i))
            .collect();
        let (film, _) = render(&s, &quads, &Constant, &RenderOptions::default());
        let expect = 1.0 - 0.5f32.powi(4);
        for y in 0..8 {
            for x in 0..8 {
                let p = film.pixel(x, y);
                assert!((p[3] - expect).abs() < 1e-6, "{p:?}");
                // Colour 1 · opacity 0.5 per layer, premultiplied: also 1 − 0.5⁴.
                assert!((p[0] - expect).abs() < 1e-6, "{p:?}");
                // No layer is opaque: nothing sets the depth.
                assert_eq!(p[4], f32::INFINITY);
            }
        }
    }

    /// A small perspective scene with overlapping, tilted, transparent and one-sided pieces.
    fn busy_scene() -> (Scene, Vec<Quad>) {
        let mut a0 = attrs(Vec3::new(1.0, 0.5, 0.25), Vec3::ONE);
        a0.shading_rate = 0.5;
        let mut a1 = attrs(Vec3::new(0.3, 0.9, 0.4), Vec3::new(0.5, 0.6, 0.7));
        a1.smooth_shading = true;
        let mut a2 = attrs(Vec3::ONE, Vec3::ONE);
        a2.sides = 1;
        let mut s = scene(
            48,
            36,
            Projection::Perspective { fov: 60.0 },
            vec![a0, a1, a2],
        );
        s.options.pixel_samples = [3.0, 3.0];
        // The default filter: its support reaches into neighbouring buckets.
        s.options.pixel_filter = PixelFilter {
            name: "gaussian".into(),
            xwidth: 2.0,
            ywidth: 2.0,
        };
        let quads = vec![
            Quad::new(
                Vec3::new(-3.0, -1.0, 2.0),
                Vec3::new(3.0, -1.0, 2.0),
                Vec3::new(-3.0, -1.0, 20.0),
                Vec3::new(3.0, -1.0, 20.0),
                0,
            ),
            Quad::new(
                Vec3::new(-1.0, -0.8, 4.0),
                Vec3::new(0.7, -0.5, 3.0),
                Vec3::new(-0.6, 0.9, 5.0),
                Vec3::new(1.2, 1.0, 4.0),
                1,
            ),
            Quad::rect(0.2, -0.3, 1.5, 0.6, 3.5, 2),
            // Facing away: culled by Sides 1.
            Quad::new(
                Vec3::new(-1.5, 0.2, 3.0),
                Vec3::new(-1.5, 1.0, 3.0),
                Vec3::new(-0.2, 0.2, 3.0),
                Vec3::new(-0.2, 1.0, 3.0),
                2,
            ),
        ];
        (s, quads)
    }

    #[test]
    fn output_is_identical_for_any_thread_count_and_bucket_size() {
        let (mut s, quads) = busy_scene();
        // A wide filter: a margin of 2 pixels around every bucket.
        s.options.pixel_filter = PixelFilter {
            name: "catmull-rom".into(),
            xwidth: 3.5,
            ywidth: 3.0,
        };
        let run = |threads, size| {
            let opts = RenderOptions {
                threads,
                bucket_size: Some(size),
                ..Default::default()
            };
            render(&s, &quads, &DefaultShader, &opts).0
        };
        let a = run(1, [16, 16]);
        let bits = |f: &Film| f.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
        let covered = (0..36)
            .flat_map(|y| (0..48).map(move |x| (x, y)))
            .filter(|&(x, y)| a.pixel(x, y)[3] > 0.0)
            .count();
        assert!(
            covered > 200,
            "the scene covers part of the frame ({covered} pixels)"
        );
        for (threads, size) in [(2, [32, 32]), (2, [16, 16]), (1, [7, 5]), (2, [64, 64])] {
            let b = run(threads, size);
            assert!(
                bits(&a) == bits(&b),
                "threads {threads}, bucket {size:?} differ"
            );
        }
    }

    /// Bucket rows overlap (a thread done with row r starts row r + 1, tiles are filtered and
    /// rows go into the film whenever their buckets are ready), so the order of everything
    /// varies from run to run: many threads over tiny buckets, again and again, must give
    /// the same bits every time (and finish: no step waits on a lock held across a parallel
    /// loop).
    #[test]
    fn overlapping_rows_give_the_same_bits_in_any_order() {
        let (mut s, quads) = busy_scene();
        s.options.pixel_filter = PixelFilter {
            name: "gaussian".into(),
            xwidth: 2.0,
            ywidth: 2.0,
        };
        let run = |threads, size| {
            let stats = Stats::new();
            let opts = RenderOptions {
                threads,
                bucket_size: Some(size),
                stats: Some(&stats),
                ..Default::default()
            };
            let film = render(&s, &quads, &DefaultShader, &opts).0;
            assert_eq!(Stats::get(&stats.live_bytes), 0, "everything was freed");
            film.data.iter().map(|v| v.to_bits()).collect::<Vec<u32>>()
        };
        let a = run(1, [16, 16]);
        for round in 0..6 {
            for (threads, size) in [(2, [1, 1]), (3, [3, 2]), (4, [5, 7]), (8, [2, 9])] {
                assert!(
                    a == run(threads, size),
                    "round {round}: threads {threads}, bucket {size:?} differ"
                );
            }
        }
    }

    /// Constant shading that takes a while per grid: buckets then ask for grids other
    /// threads are still shading.
    struct Slow;
    impl GridShader for Slow {
        fn displace(&self, _: &Scene, _: &Camera, _: usize, _: &mut Grid) {}
        fn shade(&self, scene: &Scene, camera: &Camera, prim: usize, g: &mut Grid) {
            std::thread::sleep(std::time::Duration::from_millis(2));
            Constant.shade(scene, camera, prim, g);
        }
    }

    #[test]
    fn buckets_waiting_for_a_grid_being_shaded_hide_others_meanwhile_with_the_same_bits() {
        // Small buckets: each grid spans many, so a bucket often asks for a grid another
        // thread is shading; its thread then hides other buckets (nested on its stack, each
        // with its own hider scratch) before taking the grid. The bits must not change.
        let (s, quads) = busy_scene();
        let run = |threads, size| {
            let stats = Stats::new();
            let opts = RenderOptions {
                threads,
                bucket_size: Some(size),
                stats: Some(&stats),
                ..Default::default()
            };
            let film = render(&s, &quads, &Slow, &opts).0;
            assert_eq!(Stats::get(&stats.live_bytes), 0, "everything was freed");
            let bits: Vec<u32> = film.data.iter().map(|v| v.to_bits()).collect();
            (bits, Stats::get(&stats.grid_waits))
        };
        let (a, none) = run(1, [16, 16]);
        assert_eq!(none, 0, "one thread never finds a grid being shaded");
        let mut waits = 0;
        for (threads, size) in [(2, [2, 2]), (4, [1, 1]), (3, [3, 2]), (8, [2, 3])] {
            let (b, w) = run(threads, size);
            assert!(a == b, "threads {threads}, bucket {size:?} differ");
            waits += w;
        }
        // Not asserted above 0 (scheduling decides), but shown when the test is run with
        // --nocapture.
        println!("buckets found a grid being shaded {waits} times");
    }

    /// An opaque wall at depth 2 over the whole frame, and `n` rows of quads behind it (some
    /// transparent), each primitive with `Attribute "cull" "hidden" [!cull]`.
    fn walled_scene(cull: bool) -> (Scene, Vec<Quad>) {
        let flag = |mut a: Attributes| {
            if !cull {
                let mut p = string_param("cull:hidden", "");
                p.decl.ty = crate::scene::ParamType::Integer;
                p.data = crate::scene::ParamData::Floats(vec![0.0]);
                a.user.insert("cull:hidden".into(), p);
            }
            a
        };
        let wall = flag(attrs(Vec3::new(0.8, 0.7, 0.6), Vec3::ONE));
        let behind = flag(attrs(Vec3::new(0.1, 0.9, 0.2), Vec3::ONE));
        let mut glass = flag(attrs(Vec3::new(0.9, 0.1, 0.2), Vec3::splat(0.5)));
        glass.shading_rate = 0.5;
        let mut s = scene(
            40,
            30,
            Projection::Perspective { fov: 60.0 },
            vec![wall, behind, glass],
        );
        s.options.pixel_samples = [2.0, 2.0];
        s.options.pixel_filter = PixelFilter {
            name: "gaussian".into(),
            xwidth: 2.0,
            ywidth: 2.0,
        };
        let mut quads = vec![Quad::rect(-4.0, -4.0, 4.0, 4.0, 2.0, 0)];
        for k in 0..8 {
            let z = 4.0 + k as f32;
            quads.push(Quad::rect(-3.0, -3.0, 0.5, 3.0, z, 1));
            quads.push(Quad::rect(-0.5, -3.0, 3.0, 3.0, z + 0.5, 2));
        }
        (s, quads)
    }

    #[test]
    fn grids_behind_an_opaque_wall_are_not_shaded_and_the_picture_is_the_same() {
        // `wall_only`: the wall without what lies behind it.
        let run = |cull: bool, wall_only: bool, threads: usize, size: [u32; 2]| {
            let (s, mut quads) = walled_scene(cull);
            if wall_only {
                quads.truncate(1);
            }
            let stats = Stats::new();
            let opts = RenderOptions {
                threads,
                bucket_size: Some(size),
                stats: Some(&stats),
                ..Default::default()
            };
            let (film, diags) = render(&s, &quads, &Constant, &opts);
            assert!(!diags.has_errors());
            assert_eq!(Stats::get(&stats.live_bytes), 0, "every grid was freed");
            let bits: Vec<u32> = film.data.iter().map(|v| v.to_bits()).collect();
            (bits, film, stats)
        };
        let (all_bits, all_film, all) = run(false, false, 1, [16, 16]);
        // The wall alone shows: every pixel is its colour at depth 2.
        let p = all_film.pixel(20, 15);
        assert!((p[0] - 0.8).abs() < 1e-6 && (p[3] - 1.0).abs() < 1e-6 && p[4] == 2.0);
        // Without culling every grid is shaded.
        assert_eq!(Stats::get(&all.grids_unshaded), 0);
        let grids = Stats::get(&all.grids);
        let points = Stats::get(&all.shaded_points);
        let (wall_bits, _, wall) = run(true, true, 1, [16, 16]);
        assert!(wall_bits == all_bits, "nothing behind the wall shows");
        let wall_points = Stats::get(&wall.shaded_points);
        assert!(wall_points * 3 < points, "{wall_points} of {points}");
        for (threads, size) in [(1, [16, 16]), (2, [16, 16]), (2, [7, 5]), (2, [64, 64])] {
            let (bits, _, st) = run(true, false, threads, size);
            assert!(
                bits == all_bits,
                "threads {threads}, bucket {size:?}: picture differs"
            );
            assert_eq!(Stats::get(&st.grids), grids, "the same grids are diced");
            // Only the wall's grids are shaded: the 16 quads behind it are not, in any bucket.
            assert_eq!(
                Stats::get(&st.shaded_points),
                wall_points,
                "threads {threads}, bucket {size:?}"
            );
            let behind = grids - Stats::get(&wall.grids);
            assert!(behind >= 16);
            assert_eq!(
                Stats::get(&st.grids_unshaded),
                behind + Stats::get(&wall.grids_unshaded)
            );
        }
    }

    /// The peak of the memory statistic (one thread, so the order is fixed) for a 32×32
    /// orthographic frame in 16-pixel buckets with `layers` opaque quads stacked over the
    /// middle of each bucket row in `rows`, finely diced.
    fn stacked_peak(rows: &[usize], layers: usize) -> u64 {
        let mut a = attrs(Vec3::new(0.5, 0.6, 0.7), Vec3::ONE);
        a.shading_rate = 0.25;
        let s = scene(32, 32, Projection::Orthographic, vec![a]);
        let mut quads = Vec::new();
        for &row in rows {
            // Screen y in [0.2, 0.8] or [−0.8, −0.2]: raster rows 3–13 or 19–29, one bucket
            // row each (with the box filter's 1-pixel margin).
            let (y0, y1) = if row == 0 { (0.2, 0.8) } else { (-0.8, -0.2) };
            for k in 0..layers {
                quads.push(Quad::rect(-0.9, y0, 0.9, y1, 2.0 + k as f32, 0));
            }
        }
        let stats = Stats::new();
        let opts = RenderOptions {
            threads: 1,
            bucket_size: Some([16, 16]),
            stats: Some(&stats),
            ..Default::default()
        };
        let (_, diags) = render(&s, &quads, &Constant, &opts);
        assert!(!diags.has_errors());
        assert_eq!(Stats::get(&stats.live_bytes), 0, "every grid was freed");
        Stats::get(&stats.peak_bytes)
    }

    #[test]
    fn a_bucket_rows_grids_are_gone_before_the_next_rows_are_diced() {
        let empty = stacked_peak(&[], 0);
        let one = stacked_peak(&[0], 8);
        let other = stacked_peak(&[1], 8);
        let both = stacked_peak(&[0, 1], 8);
        // What one row's grids hold at most (the film and sample buffers are in `empty`).
        let row = one.max(other) - empty;
        assert!(row > 100_000, "{row} bytes: the stack is finely diced");
        // Each grid's points are dropped by the last bucket hiding it, before the next row
        // is diced: two rows hold what the larger one does, plus the first row's hidden
        // samples (waiting for the filter), never both rows' grids.
        assert!(
            both - one.max(other) < row / 4,
            "two rows {both}, one {one} / {other}, none {empty}"
        );
    }

    #[test]
    fn finished_scanlines_are_handed_out_in_order_while_rendering() {
        /// Keeps a copy of every band as it was when handed out.
        struct Copies(Vec<(usize, usize, Vec<u32>)>);
        impl RowSink for Copies {
            fn rows(&mut self, film: &Film, y0: usize, y1: usize) {
                let n = film.width * film.channels();
                let bits = film.data[y0 * n..y1 * n].iter().map(|v| v.to_bits());
                self.0.push((y0, y1, bits.collect()));
            }
        }
        let (s, quads) = busy_scene();
        let options = effective_options(&s.options, &RenderOptions::default());
        let camera = Camera::from_options(&options, s.camera_from_world, &s.coordinate_systems);
        for (threads, size) in [(1, [16, 16]), (2, [7, 5]), (2, [64, 64]), (2, [48, 4])] {
            let opts = RenderOptions {
                threads,
                bucket_size: Some(size),
                ..Default::default()
            };
            let mut surfaces: Vec<Vec<Box<dyn Surface>>> =
                (0..s.primitives.len()).map(|_| Vec::new()).collect();
            for q in &quads {
                surfaces[q.prim].push(Box::new(q.clone()));
            }
            let mut copies = Copies(Vec::new());
            let diags = Diagnostics::new();
            let film = render_surfaces_rows(
                &s,
                &options,
                &camera,
                surfaces,
                &DefaultShader,
                &opts,
                Some(&mut copies),
                &diags,
            );
            let n = film.width * film.channels();
            let mut next = 0;
            for (y0, y1, bits) in &copies.0 {
                assert_eq!(
                    *y0, next,
                    "bands in order without gaps ({threads}, {size:?})"
                );
                let now: Vec<u32> = film.data[y0 * n..y1 * n]
                    .iter()
                    .map(|v| v.to_bits())
                    .collect();
                assert!(
                    *bits == now,
                    "scanlines {y0}..{y1} changed after they were handed out"
                );
                next = *y1;
            }
            assert_eq!(next, 36, "every scanline handed out");
            // Rows are handed out as they finish, not all at the end: on one thread a band
            // per bucket row; on more, rows finished while another thread was handing rows
            // out go together.
            let bands = copies.0.iter().filter(|(a, b, _)| b > a).count();
            let rows = 36usize.div_ceil(size[1] as usize);
            if threads == 1 {
                assert_eq!(bands, rows, "{size:?}");
            } else {
                assert!((1..=rows).contains(&bands), "{bands} bands, {size:?}");
            }
        }
    }

    #[test]
    fn crop_window_renders_only_its_region() {
        let (mut s, quads) = busy_scene();
        let full = render(&s, &quads, &DefaultShader, &RenderOptions::default()).0;
        s.options.crop_window = [0.25, 0.75, 0.5, 1.0];
        let region = crop_region(48, 36, s.options.crop_window);
        assert_eq!(
            region,
            PixelRect {
                x0: 12,
                y0: 18,
                x1: 36,
                y1: 36
            }
        );
        let cropped = render(&s, &quads, &DefaultShader, &RenderOptions::default()).0;
        let mut inside_hit = 0;
        for y in 0..36 {
            for x in 0..48 {
                let (p, q) = (full.pixel(x, y), cropped.pixel(x, y));
                if region.contains(x as i32, y as i32) {
                    assert_eq!(p, q, "pixel {x},{y}");
                    inside_hit += (q[3] > 0.0) as usize;
                } else {
                    assert_eq!(q[3], 0.0);
                    assert_eq!(q[4], f32::INFINITY);
                }
            }
        }
        assert!(inside_hit > 50);
        // The --crop override does the same.
        s.options.crop_window = [0.0, 1.0, 0.0, 1.0];
        let opts = RenderOptions {
            crop: Some([0.25, 0.75, 0.5, 1.0]),
            ..Default::default()
        };
        let over = render(&s, &quads, &DefaultShader, &opts).0;
        assert_eq!(
            over.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            cropped.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_point_lands_on_its_projected_pixel() {
        // Perspective fov 90 on 32×24: screen window [-4/3, 4/3] × [-1, 1], x_s = x/z.
        // Pixel (10, 5) spans x_s ∈ [-4/3 + 10/12, -4/3 + 11/12], y_s ∈ [1 − 6/12, 1 − 5/12].
        let z = 3.0;
        let (xs0, xs1) = (-4.0 / 3.0 + 10.0 / 12.0, -4.0 / 3.0 + 11.0 / 12.0);
        let (ys0, ys1) = (1.0 - 6.0 / 12.0, 1.0 - 5.0 / 12.0);
        let s = scene(
            32,
            24,
            Projection::Perspective { fov: 90.0 },
            vec![attrs(Vec3::ONE, Vec3::ONE)],
        );
        let q = Quad::rect(xs0 * z, ys0 * z, xs1 * z, ys1 * z, z, 0);
        let (film, _) = render(&s, &[q], &Constant, &RenderOptions::default());
        for y in 0..24 {
            for x in 0..32 {
                let a = film.pixel(x, y)[3];
                if (x, y) == (10, 5) {
                    assert!((a - 1.0).abs() < 1e-6, "{a}");
                    assert!((film.pixel(x, y)[4] - z).abs() < 1e-5);
                } else {
                    assert_eq!(a, 0.0, "pixel {x},{y}");
                }
            }
        }
    }

    #[test]
    fn one_sided_back_faces_and_mattes() {
        let mut one = attrs(Vec3::ONE, Vec3::ONE);
        one.sides = 1;
        let mut matte = attrs(Vec3::ONE, Vec3::ONE);
        matte.matte = true;
        let s = scene(
            8,
            8,
            Projection::Orthographic,
            vec![one, matte, attrs(Vec3::ONE, Vec3::ONE)],
        );
        // A rectangle facing the camera, the same one flipped (u along −x: facing away).
        let front = Quad::rect(-2.0, -2.0, 0.0, 2.0, 2.0, 0);
        let back = Quad::new(
            Vec3::new(2.0, -2.0, 2.0),
            Vec3::new(0.0, -2.0, 2.0),
            Vec3::new(2.0, 2.0, 2.0),
            Vec3::new(0.0, 2.0, 2.0),
            0,
        );
        let (film, _) = render(&s, &[front, back], &Constant, &RenderOptions::default());
        assert_eq!(film.pixel(1, 4)[3], 1.0);
        assert_eq!(film.pixel(6, 4)[3], 0.0);
        // A matte in front of a white surface: a hole with the matte's depth.
        let quads = [
            Quad::rect(-2.0, -2.0, 0.0, 2.0, 1.0, 1),
            Quad::rect(-2.0, -2.0, 2.0, 2.0, 4.0, 2),
        ];
        let (film, _) = render(&s, &quads, &Constant, &RenderOptions::default());
        let (hole, lit) = (film.pixel(1, 4), film.pixel(6, 4));
        assert_eq!(&hole[..4], &[0.0; 4]);
        assert_eq!(hole[4], 1.0);
        assert_eq!(&lit[..5], &[1.0, 1.0, 1.0, 1.0, 4.0]);
    }

    #[test]
    fn stats_and_progress_are_reported() {
        let (s, quads) = busy_scene();
        let stats = Stats::new();
        let calls = Mutex::new(Vec::new());
        let progress = |d: usize, t: usize| calls.lock().unwrap().push((d, t));
        let opts = RenderOptions {
            stats: Some(&stats),
            progress: Some(&progress),
            bucket_size: Some([16, 16]),
            ..Default::default()
        };
        render(&s, &quads, &DefaultShader, &opts);
        let calls = calls.into_inner().unwrap();
        // 48×36 in 16-pixel buckets: 3 × 3.
        assert_eq!(calls.len(), 9);
        assert_eq!(*calls.last().unwrap(), (9, 9));
        assert_eq!(Stats::get(&stats.surfaces), 4);
        assert!(Stats::get(&stats.grids) >= 4);
        assert!(Stats::get(&stats.micropolygons) > 100);
        assert!(Stats::get(&stats.shaded_points) > Stats::get(&stats.micropolygons));
        assert!(Stats::get(&stats.samples_hit) > 0);
        assert_eq!(Stats::get(&stats.live_bytes), 0, "every grid was freed");
        assert!(Stats::get(&stats.peak_bytes) > 0);
        // The phases: every render thread counted, the phases' wall times within the
        // frame's, each thread's CPU time within its share of a phase's wall time.
        let threads = Stats::get(&stats.threads);
        assert_eq!(threads as usize, rayon::current_num_threads());
        let walls: Vec<u64> = stats.phase_wall.iter().map(Stats::get).collect();
        assert!(walls[Phase::Rows as usize] > 0);
        assert!(walls.iter().sum::<u64>() <= Stats::get(&stats.wall_ns));
        let run: u64 = stats.phase_run.iter().map(Stats::get).sum();
        let wait: u64 = stats.phase_wait.iter().map(Stats::get).sum();
        // (The kernel's per-thread times run ahead of the wall clock by at most a tick.)
        let slack = 10_000_000 * threads;
        assert!(run + wait <= threads * walls.iter().sum::<u64>() + slack);
        assert!(stats.to_string().contains("hide rows"));
    }

    fn string_param(name: &str, value: &str) -> crate::scene::Param {
        crate::scene::Param {
            name: name.to_string().into(),
            decl: crate::scene::Decl {
                class: crate::scene::Class::Uniform,
                ty: crate::scene::ParamType::String,
                array_len: 1,
            },
            data: crate::scene::ParamData::Strings(vec![value.into()]),
            span: Default::default(),
        }
    }

    #[test]
    fn midpoint_depth_is_halfway_to_the_second_surface() {
        let mut s = scene(
            8,
            8,
            Projection::Orthographic,
            vec![attrs(Vec3::ONE, Vec3::ONE); 2],
        );
        s.options
            .hider
            .params
            .0
            .push(string_param("depthfilter", "midpoint"));
        let quads = [
            Quad::rect(-2.0, -2.0, 0.0, 2.0, 2.0, 0),
            Quad::rect(-2.0, -2.0, 2.0, 2.0, 6.0, 1),
        ];
        let (film, diags) = render(&s, &quads, &Constant, &RenderOptions::default());
        assert!(diags.snapshot().is_empty());
        assert_eq!(film.pixel(1, 3)[4], 4.0);
        assert_eq!(film.pixel(6, 3)[4], 6.0);
        // An unknown filter warns and keeps the nearest depth.
        s.options.hider.params.0[0] = string_param("depthfilter", "median");
        let (film, diags) = render(&s, &quads, &Constant, &RenderOptions::default());
        assert_eq!(film.pixel(1, 3)[4], 2.0);
        assert!(diags
            .snapshot()
            .iter()
            .any(|(d, _)| d.code == "render::hider"));
    }

    #[test]
    fn clipping_planes_cut_away_their_positive_side() {
        let mut s = scene(
            8,
            8,
            Projection::Orthographic,
            vec![attrs(Vec3::ONE, Vec3::ONE)],
        );
        s.options.clipping_planes.push((Vec3::ZERO, Vec3::X));
        let (film, _) = render(
            &s,
            &[Quad::rect(-2.0, -2.0, 2.0, 2.0, 3.0, 0)],
            &Constant,
            &RenderOptions::default(),
        );
        for y in 0..8 {
            for x in 0..8 {
                assert_eq!(
                    film.pixel(x, y)[3],
                    if x < 4 { 1.0 } else { 0.0 },
                    "pixel {x},{y}"
                );
            }
        }
    }

    #[test]
    fn unjittered_samples_sit_at_stratum_centres() {
        // A vertical edge at raster x = 4.5 (screen x = 0.125 on 8 pixels over [-1, 1]):
        // with "jitter" 0 and 2×2 samples, exactly the left two strata of pixel 4 are covered.
        let mut s = scene(
            8,
            8,
            Projection::Orthographic,
            vec![attrs(Vec3::ONE, Vec3::ONE)],
        );
        s.options.hider.params.0.push(crate::scene::Param {
            name: "jitter".into(),
            decl: crate::scene::Decl {
                class: crate::scene::Class::Uniform,
                ty: crate::scene::ParamType::Float,
                array_len: 1,
            },
            data: crate::scene::ParamData::Floats(vec![0.0]),
            span: Default::default(),
        });
        let (film, _) = render(
            &s,
            &[Quad::rect(-2.0, -2.0, 0.125, 2.0, 3.0, 0)],
            &Constant,
            &RenderOptions::default(),
        );
        assert_eq!(film.pixel(4, 2)[3], 0.5);
        assert_eq!(film.pixel(3, 2)[3], 1.0);
        assert_eq!(film.pixel(5, 2)[3], 0.0);
        // The null hider sees nothing.
        s.options.hider.name = "null".into();
        let (film, _) = render(
            &s,
            &[Quad::rect(-2.0, -2.0, 2.0, 2.0, 3.0, 0)],
            &Constant,
            &RenderOptions::default(),
        );
        assert!(film
            .data
            .chunks(5)
            .all(|p| p[3] == 0.0 && p[4] == f32::INFINITY));
    }

    #[test]
    fn broken_surfaces_are_reported_not_panicked_on() {
        let s = scene(
            8,
            8,
            Projection::Perspective { fov: 60.0 },
            vec![attrs(Vec3::ONE, Vec3::ONE)],
        );
        let mut bad = Quad::rect(-1.0, -1.0, 1.0, 1.0, 3.0, 0);
        bad.p[3].x = f32::NAN;
        let (film, diags) = render(&s, &[bad], &Constant, &RenderOptions::default());
        assert!(diags
            .snapshot()
            .iter()
            .any(|(d, _)| d.code == "render::dice"));
        assert!(film.data.chunks(5).all(|p| p[3] == 0.0));
        // A surface through the eye plane is split until it can be diced or culled.
        let floor = Quad::new(
            Vec3::new(-5.0, -1.0, -5.0),
            Vec3::new(5.0, -1.0, -5.0),
            Vec3::new(-5.0, -1.0, 50.0),
            Vec3::new(5.0, -1.0, 50.0),
            0,
        );
        let (film, diags) = render(&s, &[floor], &Constant, &RenderOptions::default());
        assert!(!diags.has_errors());
        assert_eq!(film.pixel(4, 7)[3], 1.0);
        assert_eq!(film.pixel(4, 0)[3], 0.0);
    }
}
