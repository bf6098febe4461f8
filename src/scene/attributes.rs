//! Attribute requests (RISpec §4.2): colour, shaders, lights, shading controls, orientation,
//! bases and `Attribute`.
//!
//! Input: checked [`Call`]s. Output: changes to the current [`Attributes`] (copy-on-write, so
//! primitives already emitted keep theirs) and to the scene's light list.
//! Invariants: a light is only declared inside the world; its handle (integer or string)
//! names its index in `Scene::lights`; `lights_on` never holds duplicates.

use std::sync::Arc;

use glam::Vec3;

use crate::diag::Diag;

use super::builder::{BlockKind, Builder, PendingLight};
use super::params::ParamUse;
use super::table::{Call, PArg};
use super::types::*;

/// Most samples of an area light (`Attribute "light" "nsamples"`) a shaded point takes.
const MAX_LIGHT_SAMPLES: u32 = 1024;

/// The standard bases (RISpec Appendix F), row-major as in RIB.
pub fn named_basis(name: &str) -> Option<[f32; 16]> {
    Some(match name {
        "bezier" => Basis::BEZIER.matrix,
        "b-spline" | "bspline" => {
            let s = 1.0 / 6.0;
            [
                -s,
                3. * s,
                -3. * s,
                s,
                3. * s,
                -6. * s,
                3. * s,
                0.,
                -3. * s,
                0.,
                3. * s,
                0.,
                s,
                4. * s,
                s,
                0.,
            ]
        }
        "catmull-rom" | "catmullrom" => [
            -0.5, 1.5, -1.5, 0.5, 1., -2.5, 2., -0.5, -0.5, 0., 0.5, 0., 0., 1., 0., 0.,
        ],
        "hermite" => [
            2., 1., -2., 1., -3., -2., 3., -1., 0., 1., 0., 0., 1., 0., 0., 0.,
        ],
        "power" => [
            1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
        ],
        _ => return None,
    })
}

impl Builder<'_> {
    fn color_arg(&self, call: &Call<'_>) -> Vec3 {
        let f = call.pos[0].floats();
        match &self.colors {
            Some(cm) => {
                let mut rgb = Vec::with_capacity(3);
                cm.to_rgb(f, &mut rgb);
                Vec3::new(rgb[0], rgb[1], rgb[2])
            }
            None => Vec3::new(f[0], f[1], f[2]),
        }
    }

    pub(super) fn color(&mut self, call: &Call<'_>) {
        let c = self.color_arg(call);
        self.attrs().color = c;
    }

    /// Opacity is a fraction of coverage: components outside [0, 1] (Aqsis's regression scene
    /// Bug1326794 gives `Opacity [3 3 3]`) are clamped, with a warning; unclamped, the
    /// compositing `C + (1 − O)·behind` subtracted the surfaces behind and washed the colour out.
    pub(super) fn opacity(&mut self, call: &Call<'_>) {
        let c = self.color_arg(call);
        let clamped = c.clamp(glam::Vec3::ZERO, glam::Vec3::ONE);
        if clamped != c {
            self.report(
                Diag::warning(
                    "scene::opacity",
                    format!(
                        "`Opacity` {} {} {} is outside [0, 1]; clamped to {} {} {}",
                        c.x, c.y, c.z, clamped.x, clamped.y, clamped.z
                    ),
                )
                .label(call.span(), "here"),
            );
        }
        self.attrs().opacity = clamped;
    }

    pub(super) fn texture_coordinates(&mut self, call: &Call<'_>) {
        let t: [f32; 8] = std::array::from_fn(|i| call.pos[i].num());
        self.attrs().texture_coordinates = t;
    }

    fn shader_slot(&mut self, call: &Call<'_>) -> Option<Arc<ShaderRef>> {
        let s = self.shader_ref(call);
        if s.name == "null" {
            None
        } else {
            Some(Arc::new(s))
        }
    }

    pub(super) fn surface(&mut self, call: &Call<'_>) {
        let s = self.shader_slot(call);
        self.attrs().surface = s;
    }
    pub(super) fn displacement(&mut self, call: &Call<'_>) {
        let s = self.shader_slot(call);
        self.attrs().displacement = s;
    }
    pub(super) fn atmosphere(&mut self, call: &Call<'_>) {
        let s = self.shader_slot(call);
        self.attrs().atmosphere = s;
    }
    /// Interior/Exterior volume shaders run on traced rays (see `shade::system::Medium`): a
    /// ray's hit is filtered by the volume it crossed, the hit object's inside or outside.
    pub(super) fn interior(&mut self, call: &Call<'_>) {
        let s = self.shader_slot(call);
        self.attrs().interior = s;
    }
    pub(super) fn exterior(&mut self, call: &Call<'_>) {
        let s = self.shader_slot(call);
        self.attrs().exterior = s;
    }

    fn add_light(&mut self, call: &Call<'_>, area: bool) {
        if self.world.is_none() && area {
            let d = Diag::error(
                "scene::light-outside-world",
                format!("`{}` outside `WorldBegin`…`WorldEnd`", call.name()),
            )
            .label(call.span(), "lights belong to the world")
            .help("move the light after `WorldBegin`");
            self.report(d);
            return;
        }
        let handle = call.pos[1].str().to_string();
        // `LightSource "pointlight" "intensity" 5`: the handle was left out and a parameter
        // name taken for it (the list then has an odd length).
        if call.rest.len() % 2 == 1
            && matches!(
                call.req.args.get(1).map(|a| &a.value),
                Some(crate::rib::Value::Str(_))
            )
            && self.dict.get(&handle).is_some()
        {
            let d = Diag::error(
                "scene::arguments",
                format!("`{}` is missing its light handle", call.name()),
            )
            .label(call.pos_spans[1], format!("\"{handle}\" is a parameter, not a handle"))
            .help(format!(
                "`{} \"{}\" 1 \"{handle}\" …`: give a handle (a number or a string) after the shader name",
                call.name(),
                call.pos[0].str()
            ));
            self.report(d);
            return;
        }
        let mut shader = self.shader_ref(call);
        // BMRT's `Attribute "light" "shadows" "on"` (also Aqsis 1.0's automatic shadows),
        // or Aqsis's `Attribute "autoshadows" "shadowmapname"`: Aqsis renders that map before
        // the frame; arbor traces the same shadows instead (the map itself stays missing).
        let user = &self.attrs().user;
        let ray_shadows = user
            .get("light:shadows")
            .and_then(|p| p.data.strings().first().cloned())
            .is_some_and(|s| s.eq_ignore_ascii_case("on"))
            || user
                .get("autoshadows:shadowmapname")
                .and_then(|p| p.data.strings().first().cloned())
                .is_some_and(|s| !s.is_empty());
        let asked = self
            .attrs()
            .user
            .get("light:nsamples")
            .and_then(|p| p.data.floats().first().copied())
            .filter(|n| n.is_finite() && *n >= 1.0);
        let samples = asked.map_or(1, |n| n.min(MAX_LIGHT_SAMPLES as f32) as u32);
        if let Some(n) = asked.filter(|&n| n > MAX_LIGHT_SAMPLES as f32) {
            // Each sample is a light run and, with shadows, a ray per shaded point.
            let d = Diag::warning(
                "scene::limit",
                format!("`Attribute \"light\" \"nsamples\"` of {n} is held at {MAX_LIGHT_SAMPLES}"),
            )
            .label(call.span(), "this light")
            .help("BMRT scenes use 1 to 64 samples; a soft area light looks smooth at 256");
            self.report(d);
        }
        if self.world.is_none() {
            // RenderMan Companion style: a light before WorldBegin lives in camera space and
            // shines in every world of its frame (or of the whole file outside frames).
            shader.world_from_shader = self.camera_from_current();
            let in_frame = self.blocks.iter().any(|b| b.kind == BlockKind::Frame);
            self.pending_lights.push(PendingLight {
                light: Light {
                    shader: Arc::new(shader),
                    handle,
                    area,
                    ray_shadows,
                    samples,
                },
                in_frame,
            });
            return;
        }
        let shader = Arc::new(shader);
        let Some(scene) = self.world.as_mut() else {
            return;
        };
        let idx = scene.lights.len();
        scene.lights.push(Light {
            shader,
            handle: handle.clone(),
            area,
            ray_shadows,
            samples,
        });
        // A reused handle names the newest light.
        self.light_handles.insert(handle, idx);
        let a = self.attrs();
        if !a.lights_on.contains(&idx) {
            a.lights_on.push(idx);
        }
        if area {
            // The geometry that follows in this attribute block is the light's surface.
            a.area_light = Some(idx);
        }
    }

    pub(super) fn light_source(&mut self, call: &Call<'_>) {
        self.add_light(call, false);
    }

    pub(super) fn area_light_source(&mut self, call: &Call<'_>) {
        self.add_light(call, true);
    }

    pub(super) fn illuminate(&mut self, call: &Call<'_>) {
        let handle = call.pos[0].str().to_string();
        let Some(&idx) = self.light_handles.get(&handle) else {
            // A warning, not an error: there is no light to switch, and scenes leave these
            // behind when they comment a light out (NCCA's shadow-map pass keeps
            // `Illuminate "Spot1" 1` under its commented `LightSource`). Aqsis ignores an
            // unknown handle silently; the frame renders the same either way.
            let mut d = Diag::warning(
                "scene::handle",
                format!("`Illuminate`: no light has handle {handle}; ignored"),
            )
            .label(call.pos_spans[0], "unknown light handle");
            let known: Vec<&str> = self.light_handles.keys().map(String::as_str).collect();
            d = match crate::diag::did_you_mean(&handle, known.iter().copied()) {
                Some(m) => d.help(format!("did you mean {m}?")),
                None if known.is_empty() => d.help("declare a LightSource with this handle first"),
                None => d.help(format!("known handles: {}", known.join(", "))),
            };
            self.report(d);
            return;
        };
        let on = call.pos[1].int() != 0;
        let a = self.attrs();
        if on {
            if !a.lights_on.contains(&idx) {
                a.lights_on.push(idx);
            }
        } else {
            a.lights_on.retain(|&i| i != idx);
        }
    }

    pub(super) fn shading_rate(&mut self, call: &Call<'_>) {
        let r = call.pos[0].num();
        if !(r > 0.0) {
            let d = Diag::error(
                "scene::arguments",
                format!("`ShadingRate {r}` must be positive"),
            )
            .label(call.pos_spans[0], "here")
            .help("pixels per shading sample, e.g. 1");
            self.report(d);
            return;
        }
        self.attrs().shading_rate = r;
    }

    pub(super) fn shading_interpolation(&mut self, call: &Call<'_>) {
        match call.pos[0].str() {
            "smooth" => self.attrs().smooth_shading = true,
            "constant" => self.attrs().smooth_shading = false,
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown shading interpolation \"{other}\""),
                )
                .label(call.pos_spans[0], "here")
                .help("use \"constant\" or \"smooth\"");
                self.report(d);
            }
        }
    }

    pub(super) fn matte(&mut self, call: &Call<'_>) {
        let on = call.pos[0].int() != 0;
        self.attrs().matte = on;
    }

    fn six(call: &Call<'_>) -> [f32; 6] {
        std::array::from_fn(|i| call.pos[i].num())
    }

    pub(super) fn bound(&mut self, call: &Call<'_>) {
        let b = Self::six(call);
        self.attrs().bound = Some(b);
    }

    /// `Detail`: the box whose raster size picks the representation (`DetailRange`) drawn;
    /// kept as world-space corners, since the primitives after it may move further.
    pub(super) fn detail(&mut self, call: &Call<'_>) {
        let [x0, x1, y0, y1, z0, z1] = Self::six(call);
        let m = self.world_from_current();
        let corners = std::array::from_fn(|i| {
            let p = glam::Vec3::new(
                if i & 1 == 0 { x0 } else { x1 },
                if i & 2 == 0 { y0 } else { y1 },
                if i & 4 == 0 { z0 } else { z1 },
            );
            m.transform_point3(p)
        });
        self.attrs().detail = Some(corners);
    }

    pub(super) fn detail_range(&mut self, call: &Call<'_>) {
        let r: [f32; 4] = std::array::from_fn(|i| call.pos[i].num());
        if !(r[0] <= r[1] && r[1] <= r[2] && r[2] <= r[3]) {
            let d = Diag::error("scene::arguments", "`DetailRange` values must not decrease")
                .label(call.full_span(), "here")
                .help("minvisible <= lowertransition <= uppertransition <= maxvisible");
            self.report(d);
            return;
        }
        self.attrs().detail_range = r;
    }

    pub(super) fn geometric_approximation(&mut self, call: &Call<'_>) {
        let kind = call.pos[0].str().to_string();
        let v = call.pos[1].num();
        if matches!(kind.as_str(), "motionfactor" | "focusfactor") {
            // Used by the dicer: blurred surfaces get a coarser shading rate.
            self.attrs().geometric_approximation.insert(kind, v);
            return;
        }
        // Otherwise arbor dices by ShadingRate alone: flatness and the like are hints it does
        // not take (one warning per kind).
        let d = Diag::warning(
            "scene::unimplemented",
            format!("`GeometricApproximation \"{kind}\"` is not used by arbor (grids follow `ShadingRate`); ignored"),
        )
        .label(call.span(), "ignored");
        self.report(d);
        self.attrs().geometric_approximation.insert(kind, v);
    }

    /// Whether the current object space is right-handed as seen from (left-handed) camera
    /// space: its determinant is negative.
    fn current_is_rh(&self) -> bool {
        self.camera_from_current().determinant() < 0.0
    }

    pub(super) fn orientation(&mut self, call: &Call<'_>) {
        let rh = self.current_is_rh();
        let reverse = match call.pos[0].str() {
            "outside" => false,
            "inside" => true,
            "lh" => rh,
            "rh" => !rh,
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown orientation \"{other}\""),
                )
                .label(call.pos_spans[0], "here")
                .help("use \"outside\", \"inside\", \"lh\" or \"rh\"");
                self.report(d);
                return;
            }
        };
        self.attrs().reverse_orientation = reverse;
    }

    pub(super) fn reverse_orientation(&mut self, _call: &Call<'_>) {
        let a = self.attrs();
        a.reverse_orientation = !a.reverse_orientation;
    }

    pub(super) fn sides(&mut self, call: &Call<'_>) {
        let n = call.pos[0].int();
        if n != 1 && n != 2 {
            let d = Diag::error("scene::arguments", format!("`Sides {n}`: must be 1 or 2"))
                .label(call.pos_spans[0], "here");
            self.report(d);
            return;
        }
        self.attrs().sides = n as u32;
    }

    fn basis_arg(&mut self, call: &Call<'_>, i: usize) -> Option<[f32; 16]> {
        match &call.pos[i] {
            PArg::Str(name) => match named_basis(name) {
                Some(m) => Some(m),
                None => {
                    let names = ["bezier", "b-spline", "catmull-rom", "hermite", "power"];
                    let mut d = Diag::error("scene::badbasis", format!("unknown basis \"{name}\""))
                        .label(call.pos_spans[i], "not a basis");
                    d = match crate::diag::did_you_mean(name, names) {
                        Some(m) => d.help(format!("did you mean \"{m}\"?")),
                        None => d.help(format!("bases: {}, or 16 numbers", names.join(", "))),
                    };
                    self.report(d);
                    None
                }
            },
            PArg::Floats(f) if f.len() == 16 => {
                let mut m = [0.0; 16];
                m.copy_from_slice(f);
                Some(m)
            }
            _ => None,
        }
    }

    pub(super) fn basis(&mut self, call: &Call<'_>) {
        let (Some(u), Some(v)) = (self.basis_arg(call, 0), self.basis_arg(call, 2)) else {
            return;
        };
        let (us, vs) = (call.pos[1].int(), call.pos[3].int());
        if us < 1 || vs < 1 {
            let d = Diag::error("scene::badbasis", "basis steps must be at least 1")
                .label(call.pos_spans[if us < 1 { 1 } else { 3 }], "here")
                .help("bezier 3, b-spline 1, catmull-rom 1, hermite 2, power 4");
            self.report(d);
            return;
        }
        let a = self.attrs();
        a.u_basis = Basis {
            matrix: u,
            step: us as u32,
        };
        a.v_basis = Basis {
            matrix: v,
            step: vs as u32,
        };
    }

    pub(super) fn attribute(&mut self, call: &Call<'_>) {
        let cat = call.pos[0].str().to_string();
        let params = self.params(call, ParamUse::Category(&cat));
        for p in params.0 {
            self.note_if_ignored("Attribute", &cat, &p);
            let key = format!("{cat}:{}", p.name);
            match key.as_str() {
                // PRMan 3's spelling (the RenderMan Companion's scenes): the same radius,
                // in object space.
                "displacementbound:sphere" | "bound:displacement" => {
                    if let Some(&r) = p.data.floats().first() {
                        self.attrs().displacement_bound = r;
                    }
                }
                "displacementbound:coordinatesystem" => {
                    if let Some(s) = p.data.strings().first() {
                        let s = s.clone();
                        self.attrs().displacement_bound_space = s;
                    }
                }
                "identifier:name" => {
                    if let Some(s) = p.data.strings().first() {
                        let s = s.clone();
                        self.attrs().identifier = Some(s);
                    }
                }
                "trimcurve:sense" => {
                    let s = p.data.strings().first().cloned().unwrap_or_default();
                    if s != "inside" && s != "outside" {
                        let d = Diag::error(
                            "scene::arguments",
                            format!("trimcurve sense \"{s}\" must be \"inside\" or \"outside\""),
                        )
                        .label(p.span, "here");
                        self.report(d);
                        continue;
                    }
                    self.attrs().user.insert(key, p);
                }
                _ => {
                    self.attrs().user.insert(key, p);
                }
            }
        }
    }
}
