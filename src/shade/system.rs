//! Running a primitive's shaders over a grid: binding globals, parameters and primitive
//! variables, evaluating lights, then surface, atmosphere and displacement programs.
//!
//! Input: a diced [`Grid`] (camera space), the scene, the camera and the primitive.
//! Output: `grid.ci`/`grid.oi` (premultiplied, as RenderMan shaders leave them), or the
//! displaced `grid.p`/`grid.n`, plus shader output variables in `grid.outputs`.
//! Invariants: a missing or broken shader never stops the render: a warning, then the default
//! surface (or no displacement / no light); parameter values of type point/vector/normal are
//! moved from shader space to camera ("current") space when bound.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::{Diag, Diagnostics, SourceMap};
use crate::render::Camera;
use crate::scene::{Attributes, ParamData, ParamType, Primitive, Scene, ShaderRef};
use crate::shade::exec::{Env, Exec, InfoValue, LightResult, LightState, Relight, TextureLookup};
use crate::shade::value::{pooled_vf, pooled_vt, Slot};
use crate::shade::{Grid, GridVar};
use crate::sl::ast::{BaseType, ShaderKind};
use crate::sl::ir::{Instr, Program};
use crate::sl::ShaderLibrary;

/// The shading half of the renderer: compiled shaders plus where to report.
pub struct ShadeSystem<'a> {
    pub library: &'a ShaderLibrary,
    pub sources: &'a SourceMap,
    pub diags: &'a Diagnostics,
    pub textures: Option<&'a dyn TextureLookup>,
    /// Output variables the displays want (shader output parameters or globals by name).
    pub aovs: Vec<String>,
    /// The frame's ray-traceable geometry, built on the first ray a shader casts.
    pub rays: crate::ray::RayCache,
}

/// Whether any instruction, at any depth of the program, passes `pred`.
fn any_instr(instrs: &[Instr], pred: &dyn Fn(&Instr) -> bool) -> bool {
    instrs.iter().any(|i| {
        pred(i)
            || match i {
                Instr::If {
                    then, otherwise, ..
                } => any_instr(then, pred) || any_instr(otherwise, pred),
                Instr::Loop {
                    cond_code,
                    body,
                    step,
                    ..
                } => any_instr(cond_code, pred) || any_instr(body, pred) || any_instr(step, pred),
                Instr::Function { body }
                | Instr::Illuminate { body, .. }
                | Instr::Solar { body, .. } => any_instr(body, pred),
                Instr::Gather {
                    body, otherwise, ..
                } => any_instr(body, pred) || any_instr(otherwise, pred),
                Instr::Illuminance { body, .. } => any_instr(body, pred),
                _ => false,
            }
    })
}

fn uses_lights(instrs: &[Instr]) -> bool {
    use crate::sl::builtins::Builtin::*;
    any_instr(instrs, &|i| match i {
        Instr::Illuminance { .. } => true,
        Instr::Call { f, .. } => matches!(f, Ambient | Diffuse | Specular | Phong),
        _ => false,
    })
}

fn calls_ambient(instrs: &[Instr]) -> bool {
    any_instr(
        instrs,
        &|i| matches!(i, Instr::Call { f, .. } if *f == crate::sl::builtins::Builtin::Ambient),
    )
}

/// Rays per point of the radiosity lattice (BMRT's `Option "radiosity"`, see
/// [`ShadeSystem::radiosity_light`]); grids too small to thin out get fewer, down to a
/// sixteenth.
const RADIOSITY_SAMPLES: u32 = 256;
/// The radiosity lattice takes every this many grid points along u and v (and the last).
const RADIOSITY_STRIDE: usize = 4;

/// BMRT's `Option "radiosity" "steps"` above 0: the scene asks for diffuse interreflection.
fn radiosity_on(scene: &Scene) -> bool {
    scene
        .options
        .user_floats("radiosity:steps")
        .and_then(|v| v.first())
        .is_some_and(|s| *s > 0.0)
}

/// Lattice indices along a grid side of `n` points: every [`RADIOSITY_STRIDE`]th and the last.
fn lattice(n: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..n).step_by(RADIOSITY_STRIDE).collect();
    if v.last() != Some(&(n.saturating_sub(1))) && n > 0 {
        v.push(n - 1);
    }
    v
}

/// Whether a program takes derivatives (`Du`, `Dv`, `Deriv`, `area`, `calculatenormal`,
/// `filterstep`, filtered texture and map lookups, horizon maps) or casts rays: its hits are
/// then shaded with their ray differentials (see `shade::rays`).
fn uses_derivatives(instrs: &[Instr]) -> bool {
    use crate::sl::builtins::Builtin::*;
    any_instr(instrs, &|i| match i {
        Instr::Call { f, .. } => matches!(
            f,
            DuF | DvF
                | DuT
                | DvT
                | DerivF
                | DerivT
                | Area
                | CalculateNormal
                | FilterStep
                | TextureF
                | TextureC
                | Bump
                | EnvironmentF
                | EnvironmentC
                | Shadow
                | Horizon
                | HorizonHeight
                | Trace
                | IndirectDiffuse
        ),
        Instr::Gather { .. } => true,
        _ => false,
    })
}

/// Whether a light program has a `solar()` without an axis (it lights along the normal).
fn uses_bare_solar(instrs: &[Instr]) -> bool {
    instrs.iter().any(|i| match i {
        Instr::Solar { axis: None, .. } => true,
        Instr::If {
            then, otherwise, ..
        } => uses_bare_solar(then) || uses_bare_solar(otherwise),
        Instr::Loop {
            cond_code,
            body,
            step,
            ..
        } => uses_bare_solar(cond_code) || uses_bare_solar(body) || uses_bare_solar(step),
        Instr::Function { body }
        | Instr::Illuminate { body, .. }
        | Instr::Solar { body, .. }
        | Instr::Illuminance { body, .. } => uses_bare_solar(body),
        Instr::Gather {
            body, otherwise, ..
        } => uses_bare_solar(body) || uses_bare_solar(otherwise),
        _ => false,
    })
}

/// Whether a light program calls `solar()` at all.
fn uses_solar(instrs: &[Instr]) -> bool {
    instrs.iter().any(|i| match i {
        Instr::Solar { .. } => true,
        Instr::If {
            then, otherwise, ..
        } => uses_solar(then) || uses_solar(otherwise),
        Instr::Loop {
            cond_code,
            body,
            step,
            ..
        } => uses_solar(cond_code) || uses_solar(body) || uses_solar(step),
        Instr::Function { body } | Instr::Illuminate { body, .. } => uses_solar(body),
        _ => false,
    })
}

/// A light of the primitive, ready to run over its grids.
struct GridLight<'s> {
    /// Index into `Scene::lights`.
    index: usize,
    /// An area light: its sampled shape and the samples per lit point (`Attribute "light"
    /// "nsamples"`). Each sample is one light of the grid's list (illuminance runs its body
    /// once per sample, with Cl divided by the count), as BMRT did.
    area: Option<(Arc<crate::ray::AreaShape>, u32)>,
    shader: &'s ShaderRef,
    prog: Arc<Program>,
    bare_solar: bool,
    /// BMRT `Attribute "light" "shadows" "on"`: trace a shadow ray to the light.
    ray_shadows: bool,
    /// The light uses solar() (its L is a direction, the light at infinity).
    solar: bool,
}

/// Per-run facts shared by the programs of one grid.
#[derive(Clone, Copy)]
struct RunCtx<'s> {
    scene: &'s Scene,
    camera: &'s Camera,
    attrs: &'s Attributes,
    camera_from_object: Mat4,
    seed: u32,
    /// Per-point alpha for imager shaders (1 elsewhere).
    alpha: Option<&'s [f32]>,
    /// Ray depth of the grid (0: seen by the camera).
    depth: u32,
    /// The grid is a batch of ray hits: neighbouring points are unrelated, so derivatives
    /// across it read as zero (unless `triples`).
    hits: bool,
    /// The hits are laid out as `ops::TRIPLES` (each hit and its two footprint neighbours):
    /// derivatives are differences across the rays' footprints.
    triples: bool,
    /// Per point of a grid of hits: its incoming ray cone at the hit.
    cones: Option<&'s [crate::ray::Cone]>,
    /// The grid holds points sampled on this area light (a light shader's P, N, u, v, s, t
    /// are the grid's, RISpec §15.2.2); rays it casts pass through the light's own surfaces.
    area_light: Option<usize>,
    /// The space the grid's incident rays crossed, which picks its volume shader.
    medium: Medium,
    /// The surface shader's parameters as bound on the grid, for light and volume shaders
    /// that ask for them (`surface("name", var)`); empty otherwise.
    surface_params: &'s [GridVar],
    /// The atmosphere (volume) shader's parameters as bound on the grid, for surface and
    /// light shaders that ask for them (`atmosphere("name", var)`); empty otherwise.
    atmosphere_params: &'s [GridVar],
    /// Run only the program's parameter set-up (defaults, instance values, primitive
    /// variables), not its body.
    params_only: bool,
}

/// The space a grid's incident rays crossed to reach it (RISpec §4.2.6 volume shaders): the
/// camera's (the `Atmosphere`), or, for ray hits, the hit object's outside (its `Exterior`,
/// else its `Atmosphere`) or its inside (its `Interior`: the ray left the object there).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Medium {
    Camera,
    Outside,
    Inside,
}

impl<'a> ShadeSystem<'a> {
    /// Loads every light shader the scene declares, so a missing or broken one is reported
    /// even when no surface ends up asking for lights (they are otherwise loaded lazily).
    pub fn preload_lights(&self, scene: &Scene) {
        let mut seen = std::collections::HashSet::new();
        for light in &scene.lights {
            if seen.insert(light.shader.name.as_str()) {
                let _ = self.program(&light.shader, ShaderKind::Light);
            }
        }
    }

    fn program(&self, sref: &ShaderRef, kind: ShaderKind) -> Option<Arc<Program>> {
        let given: Vec<&str> = sref.params.0.iter().map(|g| &*g.name).collect();
        let p = self
            .library
            .get_for(&sref.name, &given, self.sources, self.diags)?;
        let ok = match kind {
            ShaderKind::Volume => p.kind == ShaderKind::Volume,
            k => p.kind == k || (sref.name == "null"),
        };
        if !ok {
            // A warning, reported once: the primitive goes on with the stand-in a missing
            // shader gets (Aqsis's Blobby example `repel.rib` names the displacement `lumpy`
            // as its `Surface`; an error for every grid buried the rest of the report).
            self.diags.report(
                Diag::warning(
                    "shade::kind",
                    format!(
                        "`{}` is a {} shader, used as a {} shader; it is not run",
                        sref.name,
                        p.kind.name(),
                        kind.name()
                    ),
                )
                .label(sref.span, "named here")
                .help(format!(
                    "name it in `{}` instead, or give a {} shader here",
                    p.kind.request(),
                    kind.name()
                )),
            );
            return None;
        }
        // A value for a parameter the shader lacks is dropped: say so, since it usually means
        // the scene was written for another shader of the same name (its look will differ).
        for given in &sref.params.0 {
            if !p.params.iter().any(|par| par.name == given.name) {
                self.diags.report(
                    Diag::warning(
                        "shade::param",
                        format!(
                            "shader `{}` has no parameter `{}`: the value is ignored",
                            sref.name, given.name
                        ),
                    )
                    .label(given.span, "not a parameter of this shader")
                    .help(format!(
                        "check that `{}` found on the shader path is the version this scene \
                         was written for",
                        sref.name
                    )),
                );
            }
        }
        Some(p)
    }

    /// A surface shader that could not be had (not found, or broken) is stood in for by a
    /// standard shader with the parameters the two share (`Ka`, `Kd`, …), chosen by what the
    /// scene says of it: `plastic` when its instance gives plastic's specular parameters or its
    /// name says plastic (or Maya's `blinn`/`phong`, which MayaMan, Liquid and RfM exports name
    /// their shaders after: `mms_blinn1`), `metal` when its name says metal, `matte` when its
    /// name says matte or Maya's `lambert`, or its instance gives diffuse weights (`Ka`, `Kd`). Those keep the scene's lighting design
    /// (a missing `RCMatte` under a spotlight still shows the spot). Any other shader — a
    /// custom look nothing hints at (`saturn3`, a star field) — and any sphere around the camera
    /// (a sky dome, whose shaders emit rather than reflect) get `defaultsurface`, its colour
    /// seen face-on, as Aqsis and Pixie render every missing shader: a stand-in lit from a
    /// light the real shader may ignore looked further from the published pictures.
    fn stand_in_surface(
        &self,
        s: &Arc<ShaderRef>,
        prim: &Primitive,
        camera: &Camera,
    ) -> Option<(Arc<Program>, Arc<ShaderRef>)> {
        let given = |names: &[&str]| names.iter().any(|n| s.params.get(n).is_some());
        let lower = s.name.to_ascii_lowercase();
        let name = if encloses_eye(prim, camera) {
            "defaultsurface"
        } else if given(&["Ks", "roughness", "specularcolor"])
            || ["plastic", "blinn", "phong"]
                .iter()
                .any(|w| lower.contains(w))
        {
            "plastic"
        } else if lower.contains("metal") {
            "metal"
        } else if lower.contains("matte") || lower.contains("lambert") || given(&["Ka", "Kd"]) {
            "matte"
        } else {
            "defaultsurface"
        };
        let prog = self.stand_in(s, "surface", name)?;
        Some((prog, s.clone()))
    }

    /// The standard shader `name` standing in for the `kind` shader `s` could not have, with
    /// the warning that says so.
    fn stand_in(&self, s: &ShaderRef, kind: &str, name: &str) -> Option<Arc<Program>> {
        let prog = self.library.get(name, self.sources, self.diags)?;
        self.diags.report(
            Diag::warning(
                "shade::stand-in",
                format!(
                    "{kind} `{}` is not available: `{name}` stands in for it, with the \
                     parameters they share",
                    s.name
                ),
            )
            .label(s.span, "named here"),
        );
        Some(prog)
    }

    /// A light shader that could not be had (not found, or broken) is stood in for by the
    /// standard light its instance points to, with the parameters the two share (`intensity`,
    /// `lightcolor`, `from`, `to`, the cone angles): `ambientlight` when its name says ambient,
    /// `spotlight` when it gives a cone or its name says spot, `distantlight` when its name says
    /// distant, directional or sun, `pointlight` when its name says point or it gives only a
    /// position. Left out, as Aqsis and Pixie leave it, the scene it lit renders black where
    /// its author's picture is lit (a studio's own `liquidspot`, an `uberlight` not shipped
    /// with the scene). A light nothing hints at, or one whose instance names a map that shapes
    /// its beam, stays out. An instance giving Maya's `decay`
    /// exponent gets `pointlight_decay`/`spotlight_decay`, which honour it.
    fn stand_in_light(&self, s: &ShaderRef) -> Option<Arc<Program>> {
        // Only for a shader that does not load: one of another kind stays an error.
        if self
            .library
            .get(&s.name, self.sources, self.diags)
            .is_some()
        {
            return None;
        }
        // A light shaped by a picture (a slide, gobo or blocker map; shadow maps aside) stays
        // out: a plain light would flood what the map darkens (the light-blocker paper's star
        // blocker, SSIM 0.94 left out, 0.69 as a spotlight).
        let names_a_file = |v: &String| std::path::Path::new(v).extension().is_some();
        let shaped = s.params.iter().any(|p| {
            !p.name.to_ascii_lowercase().contains("shadow")
                && p.data.strings().iter().any(names_a_file)
        });
        if shaped {
            return None;
        }
        let given = |names: &[&str]| names.iter().any(|n| s.params.get(n).is_some());
        let lower = s.name.to_ascii_lowercase();
        let has = |words: &[&str]| words.iter().any(|w| lower.contains(w));
        let name = if has(&["ambient"]) {
            "ambientlight"
        } else if given(&["coneangle", "conedeltaangle", "beamdistribution"]) || has(&["spot"]) {
            "spotlight"
        } else if has(&["distant", "direction", "sun"]) {
            "distantlight"
        } else if has(&["point"]) || given(&["from"]) {
            "pointlight"
        } else {
            return None;
        };
        // Maya's lights (and their exporters' shaders) give a `decay` exponent, often 0: the
        // variants with one keep such a light as bright at a distance as it was meant.
        let name = match name {
            "pointlight" if given(&["decay"]) => "pointlight_decay",
            "spotlight" if given(&["decay"]) => "spotlight_decay",
            n => n,
        };
        let prog = self.stand_in(s, "light", name)?;
        Some(prog)
    }

    /// The surface of a primitive that names none: RISpec's `defaultsurface` (as PRMan, Aqsis
    /// and Pixie), or `plastic` in a frame written for BMRT, whose pictures of such primitives
    /// show plastic's highlight (its displacement demos `dented`, `stucco`, `background`).
    fn default_surface(&self, scene: &Scene) -> Option<Arc<Program>> {
        let name = if scene.bmrt_displacement || scene.displaced_without_bound {
            "plastic"
        } else {
            "defaultsurface"
        };
        self.library.get(name, self.sources, self.diags)
    }

    /// Runs the displacement shader, if any: moves P, updates N and Ng — or, in a BMRT scene
    /// for a primitive without `"render" "truedisplacement"` 1, keeps P and Ng (bump mapping,
    /// see [`bump_only`]).
    pub fn displace(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid) {
        let Some(p) = scene.primitives.get(prim) else {
            return;
        };
        let Some(sref) = p.attributes.displacement.clone() else {
            return;
        };
        let Some(prog) = self.program(&sref, ShaderKind::Displacement) else {
            return;
        };
        let ctx = self.ctx(scene, camera, prim);
        // Bump mapping keeps the points, and so the geometric normal; the shader's N, s and t
        // are taken either way. The undisplaced N orients the new Ng.
        let bump = bump_only(scene, &p.attributes);
        if bump
            && prog.global("P").is_some_and(|g| g.written)
            && bump_for_want_of_bound(scene, &p.attributes)
        {
            self.diags.report(
                Diag::warning(
                    "shade::displacement",
                    format!(
                        "displacement shader `{}` moves P, but the primitive declares no \
                         displacement bound: it is bump mapped (normals only, the points stay), \
                         as BMRT-era scenes expect",
                        sref.name
                    ),
                )
                .label(sref.span, "displacement shader named here")
                .help(
                    "to move the surface, declare the largest displacement: Attribute \
                     \"displacementbound\" \"sphere\" [d] (PRMan needs it too)",
                ),
            );
        }
        let n0 = (!bump).then(|| grid.n.clone());
        let Some(mut regs) = self.run(&prog, &sref, grid, &ctx, &[], None, None, None) else {
            return;
        };
        if let Some(g) = prog.global("P").filter(|_| !bump) {
            grid.p = own_vt(&mut regs[g.reg as usize], grid.len());
        }
        if let Some(g) = prog.global("N") {
            grid.n = own_vt(&mut regs[g.reg as usize], grid.len());
        }
        // Output parameters stay with the grid: the surface shader may ask for them by
        // message passing (`displacement("hump", h)`).
        grid.displacement_outputs = prog
            .params
            .iter()
            .filter(|par| par.output && par.array.is_none())
            .filter(|par| {
                matches!(
                    par.ty,
                    BaseType::Float
                        | BaseType::Color
                        | BaseType::Point
                        | BaseType::Vector
                        | BaseType::Normal
                )
            })
            .map(|par| slot_to_gridvar(&par.name, par.ty, &regs[par.reg as usize], grid.len()))
            .collect();
        for (name, slot) in ["s", "t"]
            .iter()
            .filter_map(|n| prog.global(n).map(|g| (*n, &regs[g.reg as usize])))
        {
            let v = slot_vf(slot, grid.len());
            if name == "s" {
                grid.s = v;
            } else {
                grid.t = v;
            }
        }
        let Some(n0) = n0 else {
            return;
        };
        // Ng follows the displaced surface, oriented like the undisplaced normal.
        let ng = crate::shade::ops::deriv_t(&grid.p, grid.nu, grid.nv, 0, 1.0);
        let ng2 = crate::shade::ops::deriv_t(&grid.p, grid.nu, grid.nv, 1, 1.0);
        for i in 0..grid.len() {
            let mut c = ng[i].cross(ng2[i]);
            if c.dot(n0[i]) < 0.0 {
                c = -c;
            }
            if c.length_squared() > 0.0 {
                grid.ng[i] = c;
            }
        }
    }

    fn ctx<'s>(&self, scene: &'s Scene, camera: &'s Camera, prim: usize) -> RunCtx<'s> {
        let p = &scene.primitives[prim];
        RunCtx {
            scene,
            camera,
            attrs: &p.attributes,
            camera_from_object: camera.camera_from_world * *p.world_from_object,
            seed: crate::pattern::hash::hash_u32(prim as u32 ^ 0x9e37_79b9),
            alpha: None,
            depth: 0,
            hits: false,
            triples: false,
            cones: None,
            area_light: None,
            medium: Medium::Camera,
            surface_params: &[],
            atmosphere_params: &[],
            params_only: false,
        }
    }

    /// Runs the scene's Imager shader (other than the standard `background`, which the film
    /// applies itself) over the filtered image: Ci and alpha per pixel, P at the pixel centre
    /// in raster space. Returns false when there is no such imager.
    pub fn run_imager(&self, scene: &Scene, camera: &Camera, film: &mut crate::film::Film) -> bool {
        let Some(iref) = scene.options.imager.clone() else {
            return false;
        };
        if iref.name == "background" {
            return false;
        }
        let Some(prog) = self.program(&iref, ShaderKind::Imager) else {
            return false;
        };
        let (Some(r), Some(a)) = (film.channel("r"), film.channel("a")) else {
            return false;
        };
        let nch = film.channels();
        let attrs = Attributes::default();
        // Rows in bands so the register file stays small.
        let band = 32usize;
        let mut y0 = 0;
        while y0 < film.height {
            let rows = band.min(film.height - y0);
            let (nu, nv) = (film.width, rows);
            let mut grid = Grid::with_size(nu, nv);
            let mut alpha = vec![0f32; nu * nv];
            for j in 0..nv {
                for i in 0..nu {
                    let k = j * nu + i;
                    let px = film.pixel(i, y0 + j);
                    grid.p[k] = Vec3::new(i as f32 + 0.5, (y0 + j) as f32 + 0.5, 0.0);
                    grid.ci[k] = Vec3::new(px[r], px[r + 1], px[r + 2]);
                    grid.oi[k] = Vec3::splat(px[a]);
                    alpha[k] = px[a];
                }
            }
            let ci = grid.ci.clone();
            let oi = grid.oi.clone();
            let ctx = RunCtx {
                scene,
                camera,
                attrs: &attrs,
                camera_from_object: Mat4::IDENTITY,
                seed: 0x1a6e,
                alpha: Some(&alpha),
                depth: 0,
                hits: false,
                triples: false,
                cones: None,
                area_light: None,
                medium: Medium::Camera,
                surface_params: &[],
                atmosphere_params: &[],
                params_only: false,
            };
            if let Some(mut regs) =
                self.run(&prog, &iref, &grid, &ctx, &[], Some((&ci, &oi)), None, None)
            {
                let n = grid.len();
                let ci = prog
                    .global("Ci")
                    .map(|g| own_vt(&mut regs[g.reg as usize], n));
                // RISpec's imagers output Ci and Oi: an imager that sets Oi but not alpha
                // (Aqsis's watermark test) sets the picture's alpha to its mean opacity.
                let al = match (prog.global("alpha"), prog.global("Oi")) {
                    (Some(g), _) if g.written => Some(slot_vf(&regs[g.reg as usize], n)),
                    (_, Some(g)) if g.written => Some(
                        own_vt(&mut regs[g.reg as usize], n)
                            .iter()
                            .map(|o| (o.x + o.y + o.z) / 3.0)
                            .collect(),
                    ),
                    _ => None,
                };
                for j in 0..nv {
                    for i in 0..nu {
                        let k = j * nu + i;
                        let base = ((y0 + j) * film.width + i) * nch;
                        if let Some(c) = &ci {
                            film.data[base + r] = c[k].x;
                            film.data[base + r + 1] = c[k].y;
                            film.data[base + r + 2] = c[k].z;
                        }
                        if let Some(al) = &al {
                            film.data[base + a] = al[k];
                        }
                    }
                }
            }
            y0 += rows;
        }
        true
    }

    /// Runs surface (with lights) and atmosphere shaders; fills ci/oi.
    pub fn shade(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid) {
        let ctx = self.ctx(scene, camera, prim);
        self.shade_with(ctx, prim, grid)
    }

    /// Shades a grid of ray hits on `prim` at ray depth `depth` (see `shade::rays`), with
    /// each point's incoming ray cone; `triples`: the grid is laid out as `ops::TRIPLES`.
    #[allow(clippy::too_many_arguments)]
    pub fn shade_ray_hits(
        &self,
        scene: &Scene,
        camera: &Camera,
        prim: usize,
        grid: &mut Grid,
        depth: u32,
        medium: Medium,
        cones: &[crate::ray::Cone],
        triples: bool,
    ) {
        let mut ctx = self.ctx(scene, camera, prim);
        ctx.depth = depth;
        ctx.hits = true;
        ctx.medium = medium;
        ctx.triples = triples && grid.p.len() % 3 == 0;
        ctx.cones = (cones.len() == grid.p.len()).then_some(cones);
        self.shade_with(ctx, prim, grid)
    }

    /// Whether hits on `prim` want their ray differentials: its surface or atmosphere shader
    /// takes derivatives, filters textures or casts rays (see [`uses_derivatives`]).
    pub fn hit_wants_differentials(&self, scene: &Scene, prim: usize) -> bool {
        let Some(p) = scene.primitives.get(prim) else {
            return false;
        };
        let a = &p.attributes;
        let surface = a
            .surface
            .as_ref()
            .and_then(|s| self.program(s, ShaderKind::Surface))
            .is_some_and(|prog| uses_derivatives(&prog.body));
        surface
            || [&a.atmosphere, &a.interior, &a.exterior]
                .into_iter()
                .any(|v| {
                    v.as_ref()
                        .and_then(|s| self.program(s, ShaderKind::Volume))
                        .is_some_and(|prog| uses_derivatives(&prog.body))
                })
    }

    fn shade_with(&self, ctx: RunCtx, prim: usize, grid: &mut Grid) {
        let scene = ctx.scene;
        let Some(p) = scene.primitives.get(prim) else {
            return;
        };
        let surface = match &p.attributes.surface {
            Some(s) => self
                .program(s, ShaderKind::Surface)
                .map(|prog| (prog, s.clone()))
                .or_else(|| self.stand_in_surface(s, p, ctx.camera)),
            None => None,
        };
        let (prog, sref) = match surface {
            Some(x) => x,
            None => match self.default_surface(scene) {
                Some(prog) => (
                    prog.clone(),
                    Arc::new(ShaderRef {
                        name: prog.name.clone(),
                        params: Default::default(),
                        span: p.span,
                        world_from_shader: *p.world_from_object,
                    }),
                ),
                None => return,
            },
        };
        // Lights are evaluated once per grid, for the surface and the volume alike.
        let a = &p.attributes;
        let volume = match ctx.medium {
            Medium::Camera => a.atmosphere.clone(),
            Medium::Outside => a.exterior.clone().or_else(|| a.atmosphere.clone()),
            Medium::Inside => a.interior.clone(),
        };
        let atmosphere =
            volume.and_then(|a| self.program(&a, ShaderKind::Volume).map(|prog| (prog, a)));
        let atmosphere_lights = atmosphere
            .as_ref()
            .is_some_and(|(a, _)| uses_lights(&a.body));
        let wants_lights = uses_lights(&prog.body) || atmosphere_lights;
        let grid_lights = if wants_lights {
            self.grid_lights(&ctx)
        } else {
            Vec::new()
        };
        // Lights and volumes that read the surface's parameters (`surface("Kr", k)`) see
        // them as bound on this grid, before the surface runs (its lights run first).
        let asks_surface = grid_lights
            .iter()
            .any(|gl| asks_message(&gl.prog, "surface"))
            || atmosphere
                .as_ref()
                .is_some_and(|(a, _)| asks_message(a, "surface"));
        let surface_params = if asks_surface {
            self.param_values(&prog, &sref, grid, &ctx)
        } else {
            Vec::new()
        };
        // Surfaces and lights that read the atmosphere's parameters (`atmosphere("name",
        // v)`) see them as bound on this grid: the volume shader runs after them.
        let asks_atmosphere = asks_message(&prog, "atmosphere")
            || grid_lights
                .iter()
                .any(|gl| asks_message(&gl.prog, "atmosphere"));
        let atmosphere_params = match (&atmosphere, asks_atmosphere) {
            (Some((aprog, aref)), true) => self.param_values(aprog, aref, grid, &ctx),
            _ => Vec::new(),
        };
        let ctx = RunCtx {
            surface_params: &surface_params,
            atmosphere_params: &atmosphere_params,
            ..ctx
        };
        let lights: Vec<LightResult> = self
            .eval_lights(grid, &ctx, &grid_lights, None, None)
            .into_iter()
            .flatten()
            .collect();
        // BMRT's radiosity reaches shaders through ambient(): an ambient light for the surface.
        let mut surface_lights = lights;
        let radiosity =
            (ctx.depth == 0 && !ctx.hits && radiosity_on(scene) && calls_ambient(&prog.body))
                .then(|| self.radiosity_light(grid, &ctx))
                .flatten();
        let with_radiosity = radiosity.is_some();
        surface_lights.extend(radiosity);
        // illuminance() away from the grid's P runs the same lights again there.
        let surface_regs = {
            let g: &Grid = grid;
            let relight = |ps: &[Vec3], want: &[bool], idx: Option<&[usize]>| {
                self.relight(g, &ctx, &grid_lights, ps, want, idx)
            };
            self.run(
                &prog,
                &sref,
                g,
                &ctx,
                &surface_lights,
                None,
                None,
                Some(&relight),
            )
        };
        if with_radiosity {
            if let Some(r) = surface_lights.pop() {
                r.recycle();
            }
        }
        let lights = surface_lights;
        if let Some(mut regs) = surface_regs {
            let n = grid.len();
            if let Some(g) = prog.global("Ci") {
                grid.ci = own_vt(&mut regs[g.reg as usize], n);
            }
            if let Some(g) = prog.global("Oi") {
                grid.oi = own_vt(&mut regs[g.reg as usize], n);
            }
            // A surface shader that moves P moves the micropolygons the camera sees, where
            // the primitive declares room for it (see [`surface_moves_points`]).
            if let Some(g) = prog.global("P").filter(|g| g.written) {
                if !ctx.hits && ctx.depth == 0 && surface_moves_points(scene, &p.attributes) {
                    let moved = slot_vt(&regs[g.reg as usize], n);
                    for (p, m) in grid.p.iter_mut().zip(moved) {
                        if m.is_finite() {
                            *p = m;
                        }
                    }
                }
            }
            // Output parameters become arbitrary output variables.
            grid.outputs.clear();
            for par in prog
                .params
                .iter()
                .filter(|p| p.output && self.aovs.contains(&p.name))
            {
                grid.outputs.push(slot_to_gridvar(
                    &par.name,
                    par.ty,
                    &regs[par.reg as usize],
                    n,
                ));
            }
            for gname in ["N", "P", "s", "t", "Cs", "Os", "Ci", "Oi"] {
                if !self.aovs.iter().any(|a| a == gname) {
                    continue;
                }
                if gname == "Ci" || gname == "Oi" {
                    let v = if gname == "Ci" { &grid.ci } else { &grid.oi };
                    let floats = v.iter().flat_map(|c| c.to_array()).collect();
                    grid.outputs.push(GridVar {
                        name: gname.to_string(),
                        ty: ParamType::Color,
                        array_len: 1,
                        uniform: false,
                        floats,
                        strings: Vec::new(),
                    });
                    continue;
                }
                if let Some(g) = prog.global(gname) {
                    let ty = match gname {
                        "N" => BaseType::Normal,
                        "P" => BaseType::Point,
                        "Cs" | "Os" => BaseType::Color,
                        _ => BaseType::Float,
                    };
                    grid.outputs
                        .push(slot_to_gridvar(gname, ty, &regs[g.reg as usize], n));
                }
            }
            crate::shade::value::recycle(regs);
        } else {
            return;
        }
        // Atmosphere.
        if let Some((aprog, aref)) = atmosphere {
            {
                let ci = grid.ci.clone();
                let oi = grid.oi.clone();
                let g: &Grid = grid;
                let relight = |ps: &[Vec3], want: &[bool], idx: Option<&[usize]>| {
                    self.relight(g, &ctx, &grid_lights, ps, want, idx)
                };
                if let Some(mut regs) = self.run(
                    &aprog,
                    &aref,
                    grid,
                    &ctx,
                    &lights,
                    Some((&ci, &oi)),
                    None,
                    Some(&relight),
                ) {
                    let n = grid.len();
                    if let Some(g) = aprog.global("Ci") {
                        grid.ci = own_vt(&mut regs[g.reg as usize], n);
                    }
                    if let Some(g) = aprog.global("Oi") {
                        grid.oi = own_vt(&mut regs[g.reg as usize], n);
                    }
                    crate::shade::value::recycle(regs);
                }
            }
        }
        for l in lights {
            l.recycle();
        }
        // Guard the hider against NaN and infinities from shaders.
        let mut bad = false;
        for c in grid.ci.iter_mut().chain(grid.oi.iter_mut()) {
            if !c.is_finite() {
                *c = Vec3::ZERO;
                bad = true;
            }
        }
        if bad {
            self.diags.report(Diag::warning(
                "shade::nan",
                format!(
                    "shader `{}` produced NaN or infinite colours (rendered black)",
                    sref.name
                ),
            ));
        }
    }

    /// BMRT's radiosity as its shaders see it: the diffuse light arriving from the scene's
    /// other surfaces, returned by ambient() (so `matte` and `plastic` show it unchanged).
    /// arbor traces one bounce of it — the surfaces the rays hit are shaded with their own
    /// shaders and lights — at a lattice of the grid's points (every [`RADIOSITY_STRIDE`]th
    /// along u and v, and the last) with [`RADIOSITY_SAMPLES`] cosine-distributed rays each
    /// around the normal facing the eye, and interpolates bilinearly between them:
    /// interreflected light varies slowly, and the lattice costs a sixteenth of the rays.
    fn radiosity_light(&self, grid: &Grid, ctx: &RunCtx) -> Option<LightResult> {
        let (nu, nv, n) = (grid.nu, grid.nv, grid.len());
        if n == 0 || nu * nv != n || grid.i.len() != n {
            return None;
        }
        let (us, vs) = (lattice(nu), lattice(nv));
        let mut p = Vec::with_capacity(us.len() * vs.len());
        let mut nf = Vec::with_capacity(us.len() * vs.len());
        for &j in &vs {
            for &i in &us {
                let k = j * nu + i;
                let nn = grid.n[k].normalize_or_zero();
                p.push(grid.p[k]);
                nf.push(if nn.dot(grid.i[k]) > 0.0 { -nn } else { nn });
            }
        }
        let tracer = crate::shade::rays::Tracer {
            sys: self,
            scene: ctx.scene,
            camera: ctx.camera,
            depth: ctx.depth,
            skip_light: None,
        };
        let active = vec![true; p.len()];
        // A small grid is its own lattice: fewer rays a point there keep the cost at most
        // RADIOSITY_SAMPLES / 16 rays per shaded point (a mesh diced into many tiny grids).
        let per_point = RADIOSITY_SAMPLES / (RADIOSITY_STRIDE * RADIOSITY_STRIDE) as u32;
        let samples = (per_point as usize * n / p.len())
            .clamp(per_point as usize, RADIOSITY_SAMPLES as usize);
        let seen = crate::shade::rays::mean_radiance(
            &tracer,
            &p,
            &nf,
            &[],
            &active,
            samples as u32,
            f32::INFINITY,
            std::f32::consts::FRAC_PI_2,
            Vec3::ZERO,
            0x4ad1_0517,
        );
        // Where index x falls between lattice entries: (segment, weight of its far end).
        let place = |lat: &[usize], x: usize| -> (usize, f32) {
            let b = lat.partition_point(|&l| l <= x).saturating_sub(1);
            if b + 1 >= lat.len() {
                return (b, 0.0);
            }
            (b, (x - lat[b]) as f32 / (lat[b + 1] - lat[b]) as f32)
        };
        let w = us.len();
        let at = |a: usize, b: usize| seen[b.min(vs.len() - 1) * w + a.min(w - 1)];
        let mut cl = Vec::with_capacity(n);
        for j in 0..nv {
            let (b, fv) = place(&vs, j);
            for i in 0..nu {
                let (a, fu) = place(&us, i);
                let top = at(a, b).lerp(at(a + 1, b), fu);
                let bottom = at(a, b + 1).lerp(at(a + 1, b + 1), fu);
                cl.push(top.lerp(bottom, fv));
            }
        }
        Some(LightResult {
            ambient: true,
            lit: vec![true; n],
            l: vec![Vec3::ZERO; n],
            l_uniform: None,
            cl,
            ol: vec![Vec3::ONE; n],
            category: Arc::from(""),
            nondiffuse: false,
            nonspecular: false,
            program: None,
            outputs: Vec::new(),
        })
    }

    /// The primitive's lights that have a runnable program, in `lights_on` order, each with
    /// whether it calls `solar()` without an axis (it then needs the unit normals).
    fn grid_lights<'s>(&self, ctx: &RunCtx<'s>) -> Vec<GridLight<'s>> {
        ctx.attrs
            .lights_on
            .iter()
            .filter_map(|&li| {
                let light = ctx.scene.lights.get(li)?;
                let mut prog = self
                    .program(&light.shader, ShaderKind::Light)
                    .or_else(|| self.stand_in_light(&light.shader))?;
                let area = if light.area {
                    self.area_shape(ctx, li).map(|shape| {
                        // Shaders written for area lights read the light's surface point
                        // and normal (P, N) only where BMRT is defined (PRMan had no area
                        // lights): an area light runs the BMRT build of its shader.
                        if let Some(p) = self.library.get_variant(
                            &light.shader.name,
                            "BMRT",
                            &[("BMRT", "1")],
                            self.sources,
                        ) {
                            if p.kind == ShaderKind::Light {
                                prog = p;
                            }
                        }
                        (shape, light.samples.max(1))
                    })
                } else {
                    None
                };
                let bare_solar = uses_bare_solar(&prog.body);
                let solar = uses_solar(&prog.body);
                Some(GridLight {
                    index: li,
                    area,
                    shader: &light.shader,
                    prog,
                    bare_solar,
                    ray_shadows: light.ray_shadows,
                    solar,
                })
            })
            .collect()
    }

    /// The sampled shape of area light `li`; None (with a warning) when it has no geometry
    /// that dices: it then shines as a point light from its origin.
    fn area_shape(&self, ctx: &RunCtx, li: usize) -> Option<Arc<crate::ray::AreaShape>> {
        let (scene, camera) = (ctx.scene, ctx.camera);
        let shapes = self.rays.areas(|| {
            scene
                .lights
                .iter()
                .enumerate()
                .map(|(k, l)| {
                    l.area.then(|| {
                        Arc::new(crate::ray::AreaShape::build(scene, camera, k, self.diags))
                    })
                })
                .collect()
        });
        let shape = shapes.get(li)?.as_ref()?;
        if shape.is_empty() {
            let light = &scene.lights[li];
            self.diags.report(
                Diag::warning(
                    "shade::area-light",
                    format!(
                        "area light `{}` ({}) has no geometry: it shines from its origin as a \
                         point light",
                        light.shader.name, light.handle
                    ),
                )
                .label(light.shader.span, "this AreaLightSource")
                .help(
                    "put the light's surfaces after `AreaLightSource`, in the same attribute block",
                ),
            );
            return None;
        }
        Some(shape.clone())
    }

    /// The surface program's parameters as bound on `grid` (its defaults, then instance
    /// values and primitive variables), without running its body.
    fn param_values(
        &self,
        prog: &Program,
        sref: &ShaderRef,
        grid: &Grid,
        ctx: &RunCtx,
    ) -> Vec<GridVar> {
        let pctx = RunCtx {
            params_only: true,
            ..*ctx
        };
        let Some(regs) = self.run(prog, sref, grid, &pctx, &[], None, None, None) else {
            return Vec::new();
        };
        let vars = param_vars(prog, &regs, grid.len());
        crate::shade::value::recycle(regs);
        vars
    }

    /// The lights evaluated with the lit points at `ps`: for the whole grid, or (`idx`) for
    /// those grid points only, as a grid of just them.
    fn relight(
        &self,
        grid: &Grid,
        ctx: &RunCtx,
        lights: &[GridLight],
        ps: &[Vec3],
        want: &[bool],
        idx: Option<&[usize]>,
    ) -> Vec<Option<LightResult>> {
        match idx {
            None => self.eval_lights(grid, ctx, lights, Some(ps), Some(want)),
            Some(idx) => {
                let sub = grid.subset(idx);
                // The surface's parameters at those points, for lights that read them.
                let surface_params: Vec<GridVar> =
                    ctx.surface_params.iter().map(|v| v.pick(idx)).collect();
                let atmosphere_params: Vec<GridVar> =
                    ctx.atmosphere_params.iter().map(|v| v.pick(idx)).collect();
                let sub_ctx = RunCtx {
                    alpha: None,
                    // Its neighbours are unrelated points: derivatives read zero.
                    hits: true,
                    triples: false,
                    cones: None,
                    surface_params: &surface_params,
                    atmosphere_params: &atmosphere_params,
                    ..*ctx
                };
                let out = self.eval_lights(&sub, &sub_ctx, lights, Some(ps), Some(want));
                sub.recycle();
                out
            }
        }
    }

    /// Runs `lights` over the grid: with the lit points at the grid's P, or at `ps`
    /// (illuminance at other positions). The result is flat: one entry per light, but
    /// `samples` entries for an area light (see [`GridLight::area`]). With `want` (indexed
    /// like the result), only the wanted entries run; the others are None.
    fn eval_lights(
        &self,
        grid: &Grid,
        ctx: &RunCtx,
        lights: &[GridLight],
        ps: Option<&[Vec3]>,
        want: Option<&[bool]>,
    ) -> Vec<Option<LightResult>> {
        let n = grid.len();
        let mut out = Vec::with_capacity(lights.len());
        // The unit surface normal is needed only by solar() without an axis.
        let mut ns: Option<Arc<[Vec3]>> = None;
        let ps: Arc<[Vec3]> = ps.unwrap_or(&grid.p).into();
        for gl in lights {
            let count = gl.area.as_ref().map_or(1, |(_, s)| *s as usize);
            let first = out.len();
            let wanted = |k: usize| want.is_none_or(|w| w.get(k).copied().unwrap_or(false));
            if !(first..first + count).any(wanted) {
                out.extend((0..count).map(|_| None));
                continue;
            }
            let ns = if gl.bare_solar {
                ns.get_or_insert_with(|| grid.n.iter().map(|v| v.normalize_or_zero()).collect())
                    .clone()
            } else {
                Arc::from([])
            };
            let Some((shape, samples)) = &gl.area else {
                out.push(self.eval_light(grid, ctx, gl, ps.clone(), ns));
                continue;
            };
            // An area light: one run over every (sample, point) pair, sample-major, with the
            // light's P, N, u, v, s, t at a point of its surface sampled for that lit point.
            let s = *samples as usize;
            let m = n * s;
            let mut lg = Grid::with_size(m, 1);
            let salt = crate::pattern::hash::hash_u32(gl.index as u32 ^ 0xa7ea_1165);
            let seeds: Vec<u32> = ps
                .iter()
                .map(|&p| crate::ray::point_seed(p, salt))
                .collect();
            for k in 0..s {
                for i in 0..n {
                    let (u1, u2) = crate::ray::stratified(seeds[i], k as u32, s as u32);
                    let a = shape.sample(u1, u2);
                    let j = k * n + i;
                    lg.p[j] = a.p;
                    lg.n[j] = a.n;
                    lg.ng[j] = a.ng;
                    lg.dpdu[j] = a.dpdu;
                    lg.dpdv[j] = a.dpdv;
                    lg.u[j] = a.u;
                    lg.v[j] = a.v;
                    lg.s[j] = a.s;
                    lg.t[j] = a.t;
                    lg.i[j] = grid.i.get(i).copied().unwrap_or_default();
                }
            }
            let rep = |v: &[Vec3]| -> Arc<[Vec3]> {
                if v.is_empty() {
                    Arc::from([])
                } else {
                    (0..m).map(|j| v[j % n]).collect()
                }
            };
            let actx = RunCtx {
                hits: true,
                triples: false,
                cones: None,
                area_light: Some(gl.index),
                ..*ctx
            };
            let Some(all) = self.eval_light(&lg, &actx, gl, rep(&ps), rep(&ns)) else {
                out.extend((0..count).map(|_| None));
                continue;
            };
            let weight = 1.0 / s as f32;
            for k in 0..s {
                if !wanted(first + k) {
                    out.push(None);
                    continue;
                }
                out.push(Some(split_light(&all, k * n, n, m, weight)));
            }
            all.recycle();
        }
        out
    }

    /// Runs one light over the grid's points lit at `ps`.
    fn eval_light(
        &self,
        grid: &Grid,
        ctx: &RunCtx,
        gl: &GridLight,
        ps: Arc<[Vec3]>,
        ns: Arc<[Vec3]>,
    ) -> Option<LightResult> {
        let n = grid.len();
        let prog = &gl.prog;
        let state = LightState {
            ran: false,
            lit: vec![false; n],
            ps: ps.clone(),
            ns,
        };
        let mut st = Some(state);
        let mut regs = self.run(prog, gl.shader, grid, ctx, &[], None, Some(&mut st), None)?;
        let state = st.unwrap_or_default();
        let ambient = !state.ran;
        let mut get = |name: &str, def: Vec3| -> Vec<Vec3> {
            prog.global(name)
                .map(|g| own_vt(&mut regs[g.reg as usize], n))
                .unwrap_or_else(|| crate::shade::value::grid_vt_filled(n, def))
        };
        let mut l: Vec<Vec3> = get("L", Vec3::ZERO);
        // One pass: L points from the surface to the light, and is it the same everywhere?
        let first = l.first().map(|&v| -v);
        let mut same = true;
        for v in l.iter_mut() {
            *v = -*v;
            same &= Some(*v) == first;
        }
        let l_uniform = if same { first } else { None };
        let mut cl = get("Cl", Vec3::ZERO);
        let ol = get("Ol", Vec3::ONE);
        let lit = if ambient { vec![true; n] } else { state.lit };
        if gl.ray_shadows && !ambient {
            // The segment from each lit point to the light (along L to infinity for
            // distant lights, whose L is the same everywhere). An area light's own surfaces
            // do not shadow it.
            let tracer = crate::shade::rays::Tracer {
                sys: self,
                scene: ctx.scene,
                camera: ctx.camera,
                depth: ctx.depth,
                skip_light: gl.area.as_ref().map(|_| gl.index),
            };
            let mut to = crate::shade::value::grid_vt(n);
            for (i, o) in to.iter_mut().enumerate() {
                *o = if gl.solar {
                    ps[i] + l[i].normalize_or_zero() * 1.0e8
                } else {
                    ps[i] + l[i]
                };
            }
            let active: Vec<bool> = (0..n).map(|i| lit[i] && cl[i] != Vec3::ZERO).collect();
            let mut t = crate::shade::value::grid_vt_filled(n, Vec3::ONE);
            crate::shade::exec::RayTracer::transmission(&tracer, &ps[..], &to, &active, &mut t);
            for (c, t) in cl.iter_mut().zip(&t) {
                *c *= *t;
            }
            crate::shade::value::recycle([Slot::VT(to), Slot::VT(t)]);
        }
        if !lit.iter().all(|&b| b) {
            for (c, &on) in cl.iter_mut().zip(&lit) {
                if !on {
                    *c = Vec3::ZERO;
                }
            }
        }
        let mut category: Arc<str> = crate::shade::value::empty_str();
        let mut nondiffuse = false;
        let mut nonspecular = false;
        let mut outputs = Vec::with_capacity(prog.params.len());
        for par in &prog.params {
            // The register file is discarded after the run: move the values out.
            let slot = std::mem::take(&mut regs[par.reg as usize]);
            match par.name.as_str() {
                "__category" => category = slot.s(),
                "__nondiffuse" => nondiffuse = slot.f().first() != 0.0,
                "__nonspecular" => nonspecular = slot.f().first() != 0.0,
                _ => {}
            }
            outputs.push(slot);
        }
        crate::shade::value::recycle(regs);
        Some(LightResult {
            l_uniform,
            ambient,
            lit,
            l,
            cl,
            ol,
            category,
            nondiffuse,
            nonspecular,
            program: Some(prog.clone()),
            outputs,
        })
    }

    /// Binds and runs one program over the grid; returns its registers.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        prog: &Program,
        sref: &ShaderRef,
        grid: &Grid,
        ctx: &RunCtx,
        lights: &[LightResult],
        ci_oi: Option<(&[Vec3], &[Vec3])>,
        light_state: Option<&mut Option<LightState>>,
        relight: Option<&Relight>,
    ) -> Option<Vec<Slot>> {
        let n = grid.len();
        let camera_from_shader = ctx.camera.camera_from_world * sref.world_from_shader;
        let camera_from_object = ctx.camera_from_object;
        let camera = ctx.camera;
        let spaces = move |name: &str| -> Option<Mat4> {
            match name {
                "object" => Some(camera_from_object),
                "shader" => Some(camera_from_shader),
                _ => camera.camera_from_space(name),
            }
        };
        let attrs = ctx.attrs;
        let scene = ctx.scene;
        let depth = ctx.depth;
        let info = move |which: &str, name: &str| -> Option<InfoValue> {
            if which == "rayinfo" {
                // rayinfo("depth"): the ray level of this grid; the rest is per ray and not kept.
                return match name {
                    "depth" => Some(InfoValue::Floats(vec![depth as f32])),
                    "maxdepth" => Some(InfoValue::Floats(vec![
                        crate::shade::rays::max_depth(scene) as f32,
                    ])),
                    _ => None,
                };
            }
            info_query(scene, attrs, camera, which, name)
        };
        let flip = match (grid.ng.first(), grid.dpdu.first(), grid.dpdv.first()) {
            (Some(ng), Some(a), Some(b)) => ng.dot(a.cross(*b)) < 0.0,
            _ => false,
        };
        let tracer = crate::shade::rays::Tracer {
            sys: self,
            scene,
            camera,
            depth: ctx.depth,
            skip_light: ctx.area_light,
        };
        // A grid of ray hits has no neighbours to differentiate across (0 × 0: every
        // derivative reads zero).
        let (env_nu, env_nv) = if ctx.triples {
            (crate::shade::ops::TRIPLES, n / 3)
        } else if ctx.hits {
            (0, 0)
        } else {
            (grid.nu, grid.nv)
        };
        let env = Env {
            nu: env_nu,
            nv: env_nv,
            spaces: &spaces,
            lights,
            flip_normals: flip,
            near: camera.near,
            far: camera.far,
            shader_name: &sref.name,
            diags: self.diags,
            info: &info,
            textures: self.textures,
            seed: ctx.seed,
            rays: Some(&tracer),
            cones: ctx.cones,
            displacement_outputs: &grid.displacement_outputs,
            surface_params: ctx.surface_params,
            atmosphere_params: ctx.atmosphere_params,
        };
        let mut ex = Exec::new(prog, n, &env);
        ex.loop_limit = loop_limit(scene);
        ex.spec_scale = spec_scale(scene);
        if relight.is_some() {
            ex.relight = relight;
            ex.lights_at = Some(&grid.p);
        }
        // A light run for illuminance at other positions sees them as Ps.
        let lit_ps = light_state
            .as_ref()
            .and_then(|st| st.as_ref())
            .map(|st| st.ps.clone());
        // Globals.
        for g in &prog.globals {
            let v = match g.name {
                "P" => {
                    if prog.kind == ShaderKind::Light && ctx.area_light.is_none() {
                        Slot::T(camera_from_shader.transform_point3(Vec3::ZERO))
                    } else {
                        Slot::VT(pooled_vt(&grid.p))
                    }
                }
                "Ps" => match &lit_ps {
                    Some(ps) => Slot::VT(pooled_vt(ps)),
                    None => Slot::VT(pooled_vt(&grid.p)),
                },
                "N" => Slot::VT(pooled_vt(&grid.n)),
                "Ng" => Slot::VT(pooled_vt(&grid.ng)),
                "dPdu" => Slot::VT(pooled_vt(&grid.dpdu)),
                "dPdv" => Slot::VT(pooled_vt(&grid.dpdv)),
                "u" => Slot::VF(pooled_vf(&grid.u)),
                "v" => Slot::VF(pooled_vf(&grid.v)),
                "s" => Slot::VF(pooled_vf(&grid.s)),
                "t" => Slot::VF(pooled_vf(&grid.t)),
                "du" => Slot::F(grid.du),
                "dv" => Slot::F(grid.dv),
                "Cs" => Slot::VT(pooled_vt(&grid.cs)),
                "Os" => Slot::VT(pooled_vt(&grid.os)),
                "I" => Slot::VT(pooled_vt(&grid.i)),
                "E" => Slot::T(Vec3::ZERO),
                "Ci" => match ci_oi {
                    Some((ci, _)) => Slot::VT(pooled_vt(ci)),
                    None => {
                        // Output-only globals start as one uniform value: the grid-sized
                        // buffer is made by the first store (Mov broadcasts), not here.
                        ex.set(g.reg, Slot::T(Vec3::ZERO));
                        continue;
                    }
                },
                "Oi" => match ci_oi {
                    Some((_, oi)) => Slot::VT(pooled_vt(oi)),
                    None => Slot::VT(pooled_vt(&grid.os)),
                },
                "Cl" | "L" => {
                    ex.set(g.reg, Slot::T(Vec3::ZERO));
                    continue;
                }
                "Ol" => {
                    ex.set(g.reg, Slot::T(Vec3::ONE));
                    continue;
                }
                "ncomps" => Slot::F(3.0),
                "time" | "dtime" => Slot::F(0.0),
                "dPdtime" => Slot::VT(crate::shade::value::grid_vt_filled(n, Vec3::ZERO)),
                "alpha" => match ctx.alpha {
                    Some(a) => Slot::VF(pooled_vf(a)),
                    None => Slot::F(1.0),
                },
                _ => continue,
            };
            ex.set(g.reg, fit(v, prog.regs[g.reg as usize].varying, n));
        }
        if let Some(st) = light_state {
            ex.light = st.take();
            ex.run_init();
            bind_params(&mut ex, prog, sref, grid, camera_from_shader, self.diags);
            ex.run_body();
            *st = ex.light.take();
        } else {
            ex.run_init();
            bind_params(&mut ex, prog, sref, grid, camera_from_shader, self.diags);
            if !ctx.params_only {
                ex.run_body();
            }
        }
        Some(std::mem::take(&mut ex.regs))
    }
}

/// Whether `prog` calls message-passing function `which` (`surface`, `atmosphere`, …).
fn asks_message(prog: &Program, which: &str) -> bool {
    let named = |r: &crate::sl::ir::Reg| {
        prog.consts
            .iter()
            .any(|(c, v)| c == r && matches!(v, crate::sl::ir::Const::S(s) if &**s == which))
    };
    let found = |instrs: &[Instr]| {
        any_instr(instrs, &|i| {
            matches!(i, Instr::Call { f: crate::sl::builtins::Builtin::Message, args, .. }
                if args.first().is_some_and(named))
        })
    };
    found(&prog.init) || found(&prog.body)
}

/// A program's parameters after set-up, as message passing hands them out: one uniform
/// value or one per point, strings as strings. Array and matrix parameters are left out.
fn param_vars(prog: &Program, regs: &[Slot], n: usize) -> Vec<GridVar> {
    let mut out = Vec::new();
    for par in prog.params.iter().filter(|p| p.array.is_none()) {
        let Some(slot) = regs.get(par.reg as usize) else {
            continue;
        };
        let gv = match (par.ty, slot) {
            (BaseType::String, Slot::S(s)) => GridVar {
                name: par.name.clone(),
                ty: ParamType::String,
                array_len: 1,
                uniform: true,
                floats: Vec::new(),
                strings: vec![s.to_string()],
            },
            (BaseType::String | BaseType::Matrix, _) | (_, Slot::S(_)) => continue,
            _ => {
                // One value for a uniform parameter, one per point for a varying one.
                let points = if slot.is_varying() { n } else { 1 };
                GridVar {
                    uniform: !slot.is_varying(),
                    ..slot_to_gridvar(&par.name, par.ty, slot, points)
                }
            }
        };
        out.push(gv);
    }
    out
}

/// Points `start..start + n` of an area light's run over `m` points (one sample for every lit
/// point), with Cl scaled by `weight` (1 / samples).
fn split_light(all: &LightResult, start: usize, n: usize, m: usize, weight: f32) -> LightResult {
    let r = start..start + n;
    let l = all.l[r.clone()].to_vec();
    let l_uniform = l.first().copied().filter(|f| l.iter().all(|v| v == f));
    let outputs = all
        .outputs
        .iter()
        .map(|slot| match slot {
            Slot::VF(v) if v.len() == m => Slot::VF(v[r.clone()].to_vec()),
            Slot::VT(v) if v.len() == m => Slot::VT(v[r.clone()].to_vec()),
            Slot::VM(v) if v.len() == m => Slot::VM(v[r.clone()].to_vec()),
            other => other.clone(),
        })
        .collect();
    LightResult {
        ambient: all.ambient,
        lit: all.lit[r.clone()].to_vec(),
        l,
        l_uniform,
        cl: all.cl[r.clone()].iter().map(|c| *c * weight).collect(),
        ol: all.ol[r].to_vec(),
        category: all.category.clone(),
        nondiffuse: all.nondiffuse,
        nonspecular: all.nonspecular,
        program: all.program.clone(),
        outputs,
    }
}

/// True when the eye is inside a sphere primitive (a sky dome around the camera).
fn encloses_eye(prim: &Primitive, camera: &Camera) -> bool {
    let crate::scene::Geometry::Sphere { radius, .. } = *prim.geometry else {
        return false;
    };
    let object_from_camera = (camera.camera_from_world * *prim.world_from_object).inverse();
    let eye = object_from_camera.transform_point3(Vec3::ZERO);
    eye.is_finite() && eye.length() < radius.abs()
}

/// `Option "limits" "loopiterations"`: most iterations of one loop statement per grid.
/// Whether a displacement shader only bends this primitive's normals (its points stay where
/// they are, so the surface shader sees the undisplaced P).
///
/// BMRT moved points only with `Attribute "render" "truedisplacement" [1]`; PRMan moves them
/// within the declared `displacementbound` and loses what goes beyond it (BMRT never needed
/// one). So: a primitive that sets `truedisplacement` gets what it asks for; in a scene where
/// some primitive sets it, the others are bump mapped (the scene was written for BMRT); and
/// otherwise a primitive is displaced when it declares a displacement bound, and bump mapped
/// when it declares none (BMRT-era scenes do not; PRMan scenes that move points do).
pub(crate) fn bump_only(scene: &Scene, attrs: &Attributes) -> bool {
    match attrs
        .user
        .get("render:truedisplacement")
        .map(|p| p.data.floats())
    {
        Some([x, ..]) => *x == 0.0,
        _ => scene.bmrt_displacement || !(attrs.displacement_bound > 0.0),
    }
}

/// Whether the P a surface shader writes becomes the position the camera sees (a PRMan
/// scene's "displacement in the surface shader": `P += …; N = calculatenormal(P)`).
///
/// PRMan and Aqsis hide the micropolygons where shading left P, so fur and crater shaders
/// written as surfaces stand out of the silhouette; such scenes declare a
/// `displacementbound` for it. BMRT kept the points (its surface shaders bump only), and so
/// does a primitive without a bound, as with displacement shaders (see [`bump_only`]).
pub(crate) fn surface_moves_points(scene: &Scene, attrs: &Attributes) -> bool {
    attrs.displacement_bound > 0.0 && !scene.bmrt_displacement && !bump_only(scene, attrs)
}

/// Bump mapped only for want of a `displacementbound` (see [`bump_only`]): the case a user
/// who meant to move the surface needs to hear about.
fn bump_for_want_of_bound(scene: &Scene, attrs: &Attributes) -> bool {
    !scene.bmrt_displacement
        && !attrs.user.contains_key("render:truedisplacement")
        && !(attrs.displacement_bound > 0.0)
}

/// BMRT's `Option "render" "prmanspecular" [0]` asks for RISpec's `specular()` highlight
/// (`1/roughness`); otherwise the tight one (see [`crate::shade::ops::spec_exponent`]).
fn spec_scale(scene: &Scene) -> f32 {
    match scene.options.user_floats("render:prmanspecular") {
        Some([x, ..]) if *x == 0.0 => crate::shade::exec::SPEC_SCALE_RISPEC,
        _ => crate::shade::exec::SPEC_SCALE_TIGHT,
    }
}

fn loop_limit(scene: &Scene) -> u64 {
    match scene.options.user_floats("limits:loopiterations") {
        Some([x, ..]) if *x >= 1.0 => *x as u64,
        _ => crate::shade::exec::DEFAULT_LOOP_LIMIT,
    }
}

/// Makes a slot match a register's detail.
fn fit(v: Slot, varying: bool, n: usize) -> Slot {
    if varying && !v.is_varying() {
        crate::shade::exec::broadcast(&v, n)
    } else if !varying && v.is_varying() {
        let u = match &v {
            Slot::VF(x) => Slot::F(x.first().copied().unwrap_or(0.0)),
            Slot::VT(x) => Slot::T(x.first().copied().unwrap_or(Vec3::ZERO)),
            Slot::VM(x) => Slot::M(Box::new(x.first().copied().unwrap_or(Mat4::IDENTITY))),
            s => return s.clone(),
        };
        crate::shade::value::recycle([v]);
        u
    } else {
        v
    }
}

/// Instance values (from the Surface/LightSource request), then primitive variables of the same
/// name, override the defaults.
fn bind_params(
    ex: &mut Exec,
    prog: &Program,
    sref: &ShaderRef,
    grid: &Grid,
    camera_from_shader: Mat4,
    diags: &Diagnostics,
) {
    let n = grid.len();
    for par in &prog.params {
        let count = par.array.unwrap_or(1);
        if let Some(p) = sref.params.get(&par.name) {
            let comps = match par.ty {
                BaseType::Float => 1,
                BaseType::Matrix => 16,
                BaseType::String => 1,
                _ => 3,
            };
            match &p.data {
                ParamData::Strings(s) if par.ty == BaseType::String => {
                    for k in 0..count.min(s.len()) {
                        ex.set(par.reg + k as u32, Slot::S(Arc::from(s[k].as_str())));
                    }
                }
                ParamData::Floats(f) if par.ty != BaseType::String && f.len() >= comps => {
                    for k in 0..count.min(f.len() / comps) {
                        let x = &f[k * comps..(k + 1) * comps];
                        let slot = match par.ty {
                            BaseType::Float => Slot::F(x[0]),
                            BaseType::Matrix => {
                                let mut a = [0f32; 16];
                                a.copy_from_slice(x);
                                Slot::M(Box::new(Mat4::from_cols_array(&a)))
                            }
                            BaseType::Point => Slot::T(
                                camera_from_shader.transform_point3(Vec3::new(x[0], x[1], x[2])),
                            ),
                            BaseType::Vector => Slot::T(
                                camera_from_shader.transform_vector3(Vec3::new(x[0], x[1], x[2])),
                            ),
                            BaseType::Normal => {
                                let m = glam::Mat3::from_mat4(camera_from_shader);
                                let m = if m.determinant() != 0.0 {
                                    m.inverse().transpose()
                                } else {
                                    m
                                };
                                Slot::T(m * Vec3::new(x[0], x[1], x[2]))
                            }
                            _ => Slot::T(Vec3::new(x[0], x[1], x[2])),
                        };
                        ex.set(par.reg + k as u32, fit(slot, par.varying, n));
                    }
                }
                _ => diags.report(
                    Diag::warning(
                        "shade::param",
                        format!(
                            "value of `{}` does not fit the {} parameter of `{}` (ignored)",
                            par.name,
                            par.ty.name(),
                            sref.name
                        ),
                    )
                    .label(p.span, "value"),
                ),
            }
        }
        if let Some(gv) = grid.primvar(&par.name) {
            bind_gridvar(ex, par.reg, par.ty, count, par.varying, gv, n);
        }
    }
}

fn bind_gridvar(
    ex: &mut Exec,
    reg: u32,
    ty: BaseType,
    count: usize,
    varying: bool,
    gv: &GridVar,
    n: usize,
) {
    let w = gv.width();
    let comps = match ty {
        BaseType::Float => 1,
        BaseType::Matrix => 16,
        BaseType::String => {
            if let Some(s) = gv.strings.first() {
                ex.set(reg, Slot::S(Arc::from(s.as_str())));
            }
            return;
        }
        _ => 3,
    };
    if gv.ty.components() * gv.array_len != comps * count && w != comps * count {
        return;
    }
    for k in 0..count {
        let off = k * comps;
        let slot = if gv.uniform {
            let f = &gv.floats;
            match comps {
                1 => Slot::F(f.get(off).copied().unwrap_or(0.0)),
                3 => Slot::T(Vec3::new(f[off], f[off + 1], f[off + 2])),
                _ => {
                    let mut a = [0f32; 16];
                    a.copy_from_slice(&f[off..off + 16]);
                    Slot::M(Box::new(Mat4::from_cols_array(&a)))
                }
            }
        } else {
            match comps {
                1 => Slot::VF((0..n).map(|i| gv.floats[i * w + off]).collect()),
                3 => Slot::VT(
                    (0..n)
                        .map(|i| {
                            Vec3::new(
                                gv.floats[i * w + off],
                                gv.floats[i * w + off + 1],
                                gv.floats[i * w + off + 2],
                            )
                        })
                        .collect(),
                ),
                _ => continue,
            }
        };
        ex.set(reg + k as u32, fit(slot, varying, n));
    }
}

/// Moves a triple register's values out (the register file is discarded after a run).
fn own_vt(s: &mut Slot, n: usize) -> Vec<Vec3> {
    match std::mem::take(s) {
        Slot::VT(v) if v.len() == n => v,
        other => slot_vt(&other, n),
    }
}

fn slot_vt(s: &Slot, n: usize) -> Vec<Vec3> {
    match s {
        Slot::VT(v) if v.len() == n => pooled_vt(v),
        Slot::T(x) => crate::shade::value::grid_vt_filled(n, *x),
        other => {
            let t = other.t();
            (0..n).map(|i| t.at(i)).collect()
        }
    }
}

fn slot_vf(s: &Slot, n: usize) -> Vec<f32> {
    match s {
        Slot::VF(v) if v.len() == n => v.clone(),
        Slot::F(x) => vec![*x; n],
        other => {
            let f = other.f();
            (0..n).map(|i| f.at(i)).collect()
        }
    }
}

fn slot_to_gridvar(name: &str, ty: BaseType, s: &Slot, n: usize) -> GridVar {
    let (pty, floats) = match ty {
        BaseType::Float => (ParamType::Float, slot_vf(s, n)),
        BaseType::Color => (
            ParamType::Color,
            slot_vt(s, n).iter().flat_map(|v| v.to_array()).collect(),
        ),
        BaseType::Normal => (
            ParamType::Normal,
            slot_vt(s, n).iter().flat_map(|v| v.to_array()).collect(),
        ),
        BaseType::Vector => (
            ParamType::Vector,
            slot_vt(s, n).iter().flat_map(|v| v.to_array()).collect(),
        ),
        BaseType::Point => (
            ParamType::Point,
            slot_vt(s, n).iter().flat_map(|v| v.to_array()).collect(),
        ),
        _ => (ParamType::Float, vec![0.0; n]),
    };
    GridVar {
        name: name.to_string(),
        ty: pty,
        array_len: 1,
        uniform: false,
        floats,
        strings: Vec::new(),
    }
}

/// attribute(), option(), rendererinfo() and textureinfo() answers (RISpec Tables 15.4–15.6).
fn info_query(
    scene: &Scene,
    attrs: &Attributes,
    camera: &Camera,
    which: &str,
    name: &str,
) -> Option<InfoValue> {
    let o = &scene.options;
    let f = |v: &[f32]| Some(InfoValue::Floats(v.to_vec()));
    match which {
        "attribute" => match name {
            "ShadingRate" => f(&[attrs.shading_rate]),
            "Sides" => f(&[attrs.sides as f32]),
            "Matte" => f(&[if attrs.matte { 1.0 } else { 0.0 }]),
            "displacementbound:sphere" => f(&[attrs.displacement_bound]),
            "displacementbound:coordinatesystem" => {
                Some(InfoValue::Str(attrs.displacement_bound_space.clone()))
            }
            "identifier:name" => attrs.identifier.clone().map(InfoValue::Str),
            other => {
                let key = other
                    .strip_prefix("user:")
                    .map(|k| format!("user:{k}"))
                    .unwrap_or_else(|| other.to_string());
                attrs.user.get(&key).map(|p| match &p.data {
                    ParamData::Floats(v) => InfoValue::Floats(v.clone()),
                    ParamData::Strings(s) => InfoValue::Str(s.first().cloned().unwrap_or_default()),
                })
            }
        },
        "option" => match name {
            "Format" => f(&[o.xres as f32, o.yres as f32, o.pixel_aspect]),
            "DeviceResolution" => f(&[o.xres as f32, o.yres as f32, o.pixel_aspect]),
            "FrameAspectRatio" => f(&[o.effective_frame_aspect()]),
            "CropWindow" => f(&o.crop_window),
            "DepthOfField" => match o.depth_of_field {
                Some(d) => f(&d),
                None => f(&[f32::INFINITY, 0.0, 0.0]),
            },
            "Shutter" => f(&o.shutter),
            "Clipping" => f(&[camera.near, camera.far]),
            other => o.user.get(other).map(|p| match &p.data {
                ParamData::Floats(v) => InfoValue::Floats(v.clone()),
                ParamData::Strings(s) => InfoValue::Str(s.first().cloned().unwrap_or_default()),
            }),
        },
        "rendererinfo" => match name {
            "renderer" => Some(InfoValue::Str("arbor".into())),
            "version" => f(&[0.0, 1.0, 0.0, 0.0]),
            "versionstring" => Some(InfoValue::Str(env!("CARGO_PKG_VERSION").into())),
            _ => None,
        },
        _ => None,
    }
}

impl crate::render::GridShader for ShadeSystem<'_> {
    fn displace(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid) {
        ShadeSystem::displace(self, scene, camera, prim, grid)
    }
    fn shade(&self, scene: &Scene, camera: &Camera, prim: usize, grid: &mut Grid) {
        ShadeSystem::shade(self, scene, camera, prim, grid)
    }
}
