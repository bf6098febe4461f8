//! Geometric primitives (RISpec §5), retained objects and procedurals.
//!
//! Input: checked [`Call`]s. Output: [`Primitive`]s in the scene being built (or in the object
//! being defined), with primitive variables validated against each primitive's counts.
//! Invariants: every emitted primitive has a position variable where it needs one, index
//! arrays consistent with their counts, and every primitive variable sized for its class.

use std::sync::Arc;

use crate::diag::{Diag, Span};

use super::builder::{BlockKind, Builder, ObjPrim, ObjSolid, ObjectDef, ObjectShape};
use super::params::{validate_counts, Counts, ParamUse};
use super::table::Call;
use super::types::*;

impl Builder<'_> {
    /// False when geometry would be thrown away (before WorldBegin with no object being
    /// defined: an error; in a frame outside the CLI's range: silently skipped).
    pub(super) fn geometry_wanted(&mut self, call: &Call<'_>) -> bool {
        if self.defining.is_some() {
            return true;
        }
        if self.world.is_none() {
            let d = Diag::error(
                "scene::geometry-outside-world",
                format!("`{}` outside `WorldBegin`…`WorldEnd`", call.name()),
            )
            .label(call.span(), "geometry belongs to the world")
            .help("move it after `WorldBegin`, or into an `ObjectBegin` block");
            if self.world_count == 0 {
                self.orphans.push(d);
            } else {
                self.report(d);
            }
            return false;
        }
        self.frame_active
    }

    fn geom_error(&mut self, call: &Call<'_>, at: Span, msg: String, help: String) {
        let d = Diag::error("scene::geometry", format!("`{}`: {msg}", call.name()))
            .label(at, "here")
            .help(help);
        self.report(d);
    }

    /// Validates counts and emits.
    pub(super) fn finish_prim(
        &mut self,
        call: &Call<'_>,
        geom: Geometry,
        mut pv: ParamList,
        counts: Counts,
    ) {
        let mut ds = Vec::new();
        validate_counts(&mut pv, &counts, call.name(), &mut |d| ds.push(d));
        for d in ds {
            self.report(d);
        }
        let geom = self.shared_geometry(geom);
        self.emit(call.full_span(), geom, Arc::new(pv));
    }

    /// The geometry as an `Arc`, the previous primitive's when they are equal and small (a
    /// million `Polygon`s of four vertices share one `Polygons` topology).
    fn shared_geometry(&mut self, geom: Geometry) -> Arc<Geometry> {
        let small = match &geom {
            Geometry::Polygons { verts, .. } => verts.len() <= 64,
            Geometry::Sphere { .. }
            | Geometry::Cone { .. }
            | Geometry::Cylinder { .. }
            | Geometry::Hyperboloid { .. }
            | Geometry::Paraboloid { .. }
            | Geometry::Disk { .. }
            | Geometry::Torus { .. } => true,
            _ => false,
        };
        if !small {
            return Arc::new(geom);
        }
        if let Some(last) = &self.last_geometry {
            if **last == geom {
                return last.clone();
            }
        }
        let g = Arc::new(geom);
        self.last_geometry = Some(g.clone());
        g
    }

    pub(super) fn emit(&mut self, span: Span, geometry: Arc<Geometry>, primvars: Arc<ParamList>) {
        if let Some(c) = self.capture.as_mut() {
            c.push((span, geometry, primvars));
            return;
        }
        self.emit_moving(span, geometry, primvars, None);
    }

    /// Emits a primitive with its motion (the moving ctm's, merged with `deform`).
    pub(super) fn emit_moving(
        &mut self,
        span: Span,
        geometry: Arc<Geometry>,
        primvars: Arc<ParamList>,
        deform: Option<Motion>,
    ) {
        if let Some(def) = self.defining.as_mut() {
            def.shape.prims.push(ObjPrim {
                geometry,
                primvars,
                object_from_prim: def.object_from_ctm * self.gs.ctm,
                span,
                solid: self.gs.attrs.solid,
            });
            return;
        }
        let attributes = self.gs.attrs.clone();
        let world_from_object = match &self.last_ctm {
            Some(m) if **m == self.gs.ctm => m.clone(),
            _ => {
                let m = Arc::new(self.gs.ctm);
                self.last_ctm = Some(m.clone());
                m
            }
        };
        let motion = self.primitive_motion(deform).map(Arc::new);
        if let Some(scene) = self.world.as_mut() {
            if attributes.user.contains_key("render:truedisplacement") {
                scene.bmrt_displacement = true;
            } else if attributes.displacement.is_some() && !(attributes.displacement_bound > 0.0) {
                scene.displaced_without_bound = true;
            }
            scene.primitives.push(Primitive {
                geometry,
                primvars,
                attributes,
                world_from_object,
                span,
                motion,
            });
        }
    }

    /// The number of positions given by "P" (3 per point), "Pw" (4) or "Pz" (1).
    fn position_count(&mut self, call: &Call<'_>, pv: &ParamList, allow_pz: bool) -> Option<usize> {
        let found = [("P", 3usize), ("Pw", 4), ("Pz", 1)]
            .into_iter()
            .filter(|&(n, _)| allow_pz || n != "Pz")
            .find_map(|(n, w)| pv.get(n).map(|p| (p, w)));
        match found {
            Some((p, w)) => {
                let width = p.decl.width().max(1);
                if p.data.len() % width != 0 || p.decl.width() != w {
                    let d = Diag::error(
                        "scene::count",
                        format!(
                            "`{}`: \"{}\" has {} numbers, not a multiple of {}",
                            call.name(),
                            p.name,
                            p.data.len(),
                            width
                        ),
                    )
                    .label(p.span, "here");
                    self.report(d);
                    return None;
                }
                Some(p.data.len() / width)
            }
            None => {
                self.geom_error(
                    call,
                    call.span(),
                    "no positions: \"P\" is missing".into(),
                    if allow_pz {
                        "give \"P\" (or \"Pw\", or \"Pz\" for height fields)".into()
                    } else {
                        "give \"P\" [x y z …] (or \"Pw\")".into()
                    },
                );
                None
            }
        }
    }

    fn need_position(&mut self, call: &Call<'_>, pv: &ParamList, allow_pz: bool) -> bool {
        if ["P", "Pw"].iter().any(|n| pv.get(n).is_some()) || (allow_pz && pv.get("Pz").is_some()) {
            return true;
        }
        self.geom_error(
            call,
            call.span(),
            "no positions: \"P\" is missing".into(),
            "give \"P\" [x y z …] (or \"Pw\")".into(),
        );
        false
    }

    // ---- quadrics ----

    fn quadric(&mut self, call: &Call<'_>, g: Geometry) {
        if !self.geometry_wanted(call) {
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        self.finish_prim(call, g, pv, Counts::corners(4));
    }

    pub(super) fn sphere(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Sphere {
                radius: p[0],
                zmin: p[1],
                zmax: p[2],
                thetamax: p[3],
            },
        );
    }
    pub(super) fn cone(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Cone {
                height: p[0],
                radius: p[1],
                thetamax: p[2],
            },
        );
    }
    pub(super) fn cylinder(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Cylinder {
                radius: p[0],
                zmin: p[1],
                zmax: p[2],
                thetamax: p[3],
            },
        );
    }
    pub(super) fn hyperboloid(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Hyperboloid {
                p1: glam::Vec3::new(p[0], p[1], p[2]),
                p2: glam::Vec3::new(p[3], p[4], p[5]),
                thetamax: p[6],
            },
        );
    }
    pub(super) fn paraboloid(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Paraboloid {
                rmax: p[0],
                zmin: p[1],
                zmax: p[2],
                thetamax: p[3],
            },
        );
    }
    pub(super) fn disk(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Disk {
                height: p[0],
                radius: p[1],
                thetamax: p[2],
            },
        );
    }
    pub(super) fn torus(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(|a| a.num()).collect();
        self.quadric(
            call,
            Geometry::Torus {
                rmajor: p[0],
                rminor: p[1],
                phimin: p[2],
                phimax: p[3],
                thetamax: p[4],
            },
        );
    }

    // ---- polygons ----

    fn check_counts(
        &mut self,
        call: &Call<'_>,
        arg: usize,
        v: &[i64],
        min: i64,
        what: &str,
    ) -> Option<Vec<u32>> {
        if let Some(&bad) = v.iter().find(|&&n| n < min || n > u32::MAX as i64) {
            self.geom_error(
                call,
                call.pos_spans[arg],
                format!("{what} holds {bad}; each must be at least {min}"),
                call.spec.describe(),
            );
            return None;
        }
        Some(v.iter().map(|&n| n as u32).collect())
    }

    fn sum(v: &[u32]) -> usize {
        v.iter().map(|&n| n as usize).sum()
    }

    pub(super) fn polygon(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        let Some(n) = self.position_count(call, &pv, false) else {
            return;
        };
        if n < 3 {
            self.geom_error(
                call,
                call.span(),
                format!("a polygon needs at least 3 vertices, found {n}"),
                "\"P\" holds 3 numbers per vertex".into(),
            );
            return;
        }
        let g = Geometry::Polygons {
            nloops: vec![1],
            nverts: vec![n as u32],
            verts: (0..n as u32).collect(),
            nvertices: n,
        };
        let c = Counts {
            uniform: 1,
            varying: n,
            vertex: n,
            facevarying: n,
            facevertex: n,
        };
        self.finish_prim(call, g, pv, c);
    }

    pub(super) fn general_polygon(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let Some(nverts) = self.check_counts(call, 0, call.pos[0].ints(), 3, "nvertices") else {
            return;
        };
        if nverts.is_empty() {
            self.geom_error(
                call,
                call.pos_spans[0],
                "no loops".into(),
                call.spec.describe(),
            );
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let n = Self::sum(&nverts);
        let g = Geometry::Polygons {
            nloops: vec![nverts.len() as u32],
            nverts,
            verts: (0..n as u32).collect(),
            nvertices: n,
        };
        let c = Counts {
            uniform: 1,
            varying: n,
            vertex: n,
            facevarying: n,
            facevertex: n,
        };
        self.finish_prim(call, g, pv, c);
    }

    /// Checks a vertex index array: length `expected`, no negative index. Returns the
    /// indices and the number of vertices they address (max + 1).
    fn check_indices(
        &mut self,
        call: &Call<'_>,
        arg: usize,
        v: &[i64],
        expected: usize,
    ) -> Option<(Vec<u32>, usize)> {
        if v.len() != expected {
            self.geom_error(
                call,
                call.pos_spans[arg],
                format!(
                    "{} has {} indices but the counts before it add up to {expected}",
                    call.spec.args[arg].0,
                    v.len()
                ),
                call.spec.describe(),
            );
            return None;
        }
        if let Some(&bad) = v.iter().find(|&&i| i < 0 || i > u32::MAX as i64) {
            self.geom_error(
                call,
                call.pos_spans[arg],
                format!("vertex index {bad} is out of range"),
                "indices start at 0".into(),
            );
            return None;
        }
        let nv = v.iter().copied().max().map_or(0, |m| m as usize + 1);
        Some((v.iter().map(|&i| i as u32).collect(), nv))
    }

    pub(super) fn points_polygons(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let Some(nverts) = self.check_counts(call, 0, call.pos[0].ints(), 3, "nvertices") else {
            return;
        };
        let total = Self::sum(&nverts);
        let Some((verts, nvertices)) = self.check_indices(call, 1, call.pos[1].ints(), total)
        else {
            return;
        };
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let c = Counts {
            uniform: nverts.len(),
            varying: nvertices,
            vertex: nvertices,
            facevarying: total,
            facevertex: total,
        };
        let g = Geometry::Polygons {
            nloops: vec![1; nverts.len()],
            nverts,
            verts,
            nvertices,
        };
        self.finish_prim(call, g, pv, c);
    }

    pub(super) fn points_general_polygons(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let Some(nloops) = self.check_counts(call, 0, call.pos[0].ints(), 1, "nloops") else {
            return;
        };
        let Some(nverts) = self.check_counts(call, 1, call.pos[1].ints(), 3, "nvertices") else {
            return;
        };
        if nverts.len() != Self::sum(&nloops) {
            self.geom_error(
                call,
                call.pos_spans[1],
                format!(
                    "nvertices has {} entries but nloops adds up to {}",
                    nverts.len(),
                    Self::sum(&nloops)
                ),
                call.spec.describe(),
            );
            return;
        }
        let total = Self::sum(&nverts);
        let Some((verts, nvertices)) = self.check_indices(call, 2, call.pos[2].ints(), total)
        else {
            return;
        };
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let c = Counts {
            uniform: nloops.len(),
            varying: nvertices,
            vertex: nvertices,
            facevarying: total,
            facevertex: total,
        };
        let g = Geometry::Polygons {
            nloops,
            nverts,
            verts,
            nvertices,
        };
        self.finish_prim(call, g, pv, c);
    }

    // ---- patches ----

    fn patch_type(&mut self, call: &Call<'_>) -> Option<bool> {
        match call.pos[0].str() {
            "bilinear" => Some(false),
            "bicubic" => Some(true),
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown patch type \"{other}\""),
                )
                .label(call.pos_spans[0], "here")
                .help("use \"bilinear\" or \"bicubic\"");
                self.report(d);
                None
            }
        }
    }

    pub(super) fn patch(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let Some(bicubic) = self.patch_type(call) else {
            return;
        };
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, true) {
            return;
        }
        let n = if bicubic { 4 } else { 2 };
        let a = &self.gs.attrs;
        let g = Geometry::PatchMesh {
            bicubic,
            nu: n,
            nv: n,
            uperiodic: false,
            vperiodic: false,
            u_basis: a.u_basis,
            v_basis: a.v_basis,
        };
        self.finish_prim(call, g, pv, Counts::corners(n * n));
    }

    fn wrap(&mut self, call: &Call<'_>, i: usize) -> Option<bool> {
        match call.pos[i].str() {
            "periodic" => Some(true),
            "nonperiodic" => Some(false),
            other => {
                let d = Diag::error("scene::arguments", format!("unknown wrap mode \"{other}\""))
                    .label(call.pos_spans[i], "here")
                    .help("use \"periodic\" or \"nonperiodic\"");
                self.report(d);
                None
            }
        }
    }

    /// Sub-patches along one direction of a patch mesh, or an error text.
    fn mesh_patches(n: usize, periodic: bool, bicubic: bool, step: usize) -> Result<usize, String> {
        if !bicubic {
            return match (periodic, n) {
                (_, 0 | 1) => Err(format!("{n} points; a bilinear mesh needs at least 2")),
                (true, _) => Ok(n),
                (false, _) => Ok(n - 1),
            };
        }
        if periodic {
            if n % step != 0 || n < 4 {
                return Err(format!("{n} points; a periodic bicubic mesh needs a multiple of the basis step {step}, at least 4"));
            }
            Ok(n / step)
        } else {
            if n < 4 || (n - 4) % step != 0 {
                return Err(format!(
                    "{n} points; a bicubic mesh needs 4 + k·{step} (the basis step)"
                ));
            }
            Ok((n - 4) / step + 1)
        }
    }

    pub(super) fn patch_mesh(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let Some(bicubic) = self.patch_type(call) else {
            return;
        };
        let (Some(uper), Some(vper)) = (self.wrap(call, 2), self.wrap(call, 4)) else {
            return;
        };
        let (nu, nv) = (call.pos[1].int(), call.pos[3].int());
        if nu < 1 || nv < 1 {
            let at = if nu < 1 { 1 } else { 3 };
            self.geom_error(
                call,
                call.pos_spans[at],
                "nu and nv must be positive".into(),
                call.spec.describe(),
            );
            return;
        }
        let (nu, nv) = (nu as usize, nv as usize);
        let (us, vs) = (
            self.gs.attrs.u_basis.step as usize,
            self.gs.attrs.v_basis.step as usize,
        );
        let nup = match Self::mesh_patches(nu, uper, bicubic, us) {
            Ok(n) => n,
            Err(e) => {
                return self.geom_error(
                    call,
                    call.pos_spans[1],
                    format!("nu: {e}"),
                    call.spec.describe(),
                )
            }
        };
        let nvp = match Self::mesh_patches(nv, vper, bicubic, vs) {
            Ok(n) => n,
            Err(e) => {
                return self.geom_error(
                    call,
                    call.pos_spans[3],
                    format!("nv: {e}"),
                    call.spec.describe(),
                )
            }
        };
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, true) {
            return;
        }
        // Varying values sit at sub-patch corners.
        let (vu, vv) = if bicubic {
            (nup + usize::from(!uper), nvp + usize::from(!vper))
        } else {
            (nu, nv)
        };
        let c = Counts {
            uniform: nup.saturating_mul(nvp),
            varying: vu.saturating_mul(vv),
            vertex: nu.saturating_mul(nv),
            facevarying: nup.saturating_mul(nvp).saturating_mul(4),
            facevertex: nup.saturating_mul(nvp).saturating_mul(4),
        };
        let a = &self.gs.attrs;
        let g = Geometry::PatchMesh {
            bicubic,
            nu,
            nv,
            uperiodic: uper,
            vperiodic: vper,
            u_basis: a.u_basis,
            v_basis: a.v_basis,
        };
        self.finish_prim(call, g, pv, c);
    }

    fn check_knots(
        &mut self,
        call: &Call<'_>,
        arg: usize,
        knots: &[f32],
        n: i64,
        order: i64,
    ) -> bool {
        if order < 1 || n < order {
            self.geom_error(
                call,
                call.pos_spans[arg - 1],
                format!("order {order} with {n} control points: need 1 <= order <= n"),
                call.spec.describe(),
            );
            return false;
        }
        if knots.len() != (n + order) as usize {
            self.geom_error(
                call,
                call.pos_spans[arg],
                format!(
                    "{} knots given, n + order = {} needed",
                    knots.len(),
                    n + order
                ),
                call.spec.describe(),
            );
            return false;
        }
        if knots.windows(2).any(|w| w[1] < w[0]) {
            self.geom_error(
                call,
                call.pos_spans[arg],
                "knots must not decrease".into(),
                call.spec.describe(),
            );
            return false;
        }
        true
    }

    pub(super) fn nu_patch(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let (nu, uo, nv, vo) = (
            call.pos[0].int(),
            call.pos[1].int(),
            call.pos[5].int(),
            call.pos[6].int(),
        );
        if !self.check_knots(call, 2, call.pos[2].floats(), nu, uo)
            || !self.check_knots(call, 7, call.pos[7].floats(), nv, vo)
        {
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let (nu, uo, nv, vo) = (nu as usize, uo as usize, nv as usize, vo as usize);
        let (nus, nvs) = (nu - uo + 1, nv - vo + 1);
        let c = Counts {
            uniform: nus.saturating_mul(nvs),
            varying: (nus + 1).saturating_mul(nvs + 1),
            vertex: nu.saturating_mul(nv),
            facevarying: nus.saturating_mul(nvs).saturating_mul(4),
            facevertex: nus.saturating_mul(nvs).saturating_mul(4),
        };
        let g = Geometry::NuPatch {
            nu,
            uorder: uo,
            uknot: call.pos[2].floats().to_vec(),
            umin: call.pos[3].num(),
            umax: call.pos[4].num(),
            nv,
            vorder: vo,
            vknot: call.pos[7].floats().to_vec(),
            vmin: call.pos[8].num(),
            vmax: call.pos[9].num(),
            trim: self.gs.trim.clone(),
        };
        self.finish_prim(call, g, pv, c);
    }

    pub(super) fn trim_curve(&mut self, call: &Call<'_>) {
        let ncurves = call.pos[0].ints();
        let order = call.pos[1].ints();
        let n = call.pos[5].ints();
        let total: i64 = ncurves.iter().fold(0i64, |a, &c| a.saturating_add(c));
        let fail = |b: &mut Self, i: usize, m: String| {
            b.geom_error(call, call.pos_spans[i], m, call.spec.describe());
        };
        if ncurves.iter().any(|&c| c < 0) {
            return fail(self, 0, "negative curve count".into());
        }
        if order.len() as i64 != total || n.len() as i64 != total {
            return fail(
                self,
                1,
                format!(
                    "ncurves adds up to {total} curves but order has {} and n has {}",
                    order.len(),
                    n.len()
                ),
            );
        }
        if order.iter().zip(n).any(|(&o, &c)| o < 1 || c < o) {
            return fail(self, 1, "each curve needs 1 <= order <= n".into());
        }
        let knots: i64 = order
            .iter()
            .zip(n)
            .fold(0i64, |acc, (o, c)| acc.saturating_add(o.saturating_add(*c)));
        if call.pos[2].floats().len() as i64 != knots {
            return fail(
                self,
                2,
                format!(
                    "{} knots given, Σ(order + n) = {knots} needed",
                    call.pos[2].floats().len()
                ),
            );
        }
        if call.pos[3].floats().len() as i64 != total || call.pos[4].floats().len() as i64 != total
        {
            return fail(
                self,
                3,
                format!("min and max need one value per curve ({total})"),
            );
        }
        let pts: i64 = n.iter().fold(0i64, |a, &c| a.saturating_add(c));
        for i in 6..9 {
            if call.pos[i].floats().len() as i64 != pts {
                return fail(
                    self,
                    i,
                    format!(
                        "{} needs Σn = {pts} values, found {}",
                        call.spec.args[i].0,
                        call.pos[i].floats().len()
                    ),
                );
            }
        }
        let sense_outside = self
            .gs
            .attrs
            .user
            .get("trimcurve:sense")
            .and_then(|p| p.data.strings().first())
            .is_some_and(|s| s == "outside");
        let u32s = |v: &[i64]| v.iter().map(|&x| x as u32).collect::<Vec<_>>();
        self.gs.trim = Some(Arc::new(TrimCurves {
            ncurves: u32s(ncurves),
            order: u32s(order),
            knot: call.pos[2].floats().to_vec(),
            min: call.pos[3].floats().to_vec(),
            max: call.pos[4].floats().to_vec(),
            n: u32s(n),
            u: call.pos[6].floats().to_vec(),
            v: call.pos[7].floats().to_vec(),
            w: call.pos[8].floats().to_vec(),
            sense_outside,
        }));
    }

    // ---- subdivision, points, curves, named ----

    pub(super) fn subdivision_mesh(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let scheme = call.pos[0].str().to_string();
        if !matches!(scheme.as_str(), "catmull-clark" | "loop" | "bilinear") {
            let d = Diag::error(
                "scene::arguments",
                format!("unknown subdivision scheme \"{scheme}\""),
            )
            .label(call.pos_spans[0], "here")
            .help("use \"catmull-clark\" (or \"loop\", \"bilinear\")");
            self.report(d);
            return;
        }
        let Some(nverts) = self.check_counts(call, 1, call.pos[1].ints(), 3, "nvertices") else {
            return;
        };
        let total = Self::sum(&nverts);
        let Some((verts, nvertices)) = self.check_indices(call, 2, call.pos[2].ints(), total)
        else {
            return;
        };
        let tags = call.pos[3].strs().to_vec();
        let intargs = call.pos[5].ints().to_vec();
        let floatargs = call.pos[6].floats().to_vec();
        let hierarchical = call.name() == "HierarchicalSubdivisionMesh";
        let Some(nargs) = self.subdivision_nargs(call, tags.len(), hierarchical) else {
            return;
        };
        let nargs = &nargs[..];
        if nargs.len() != 2 * tags.len() || nargs.iter().any(|&n| n < 0) {
            return self.geom_error(
                call,
                call.pos_spans[4],
                format!(
                    "{} tags need {} nargs (an int count and a float count per tag), found {}",
                    tags.len(),
                    2 * tags.len(),
                    nargs.len()
                ),
                call.spec.describe(),
            );
        }
        let ni: i64 = nargs
            .iter()
            .step_by(2)
            .fold(0i64, |a, &c| a.saturating_add(c));
        let nf: i64 = nargs
            .iter()
            .skip(1)
            .step_by(2)
            .fold(0i64, |a, &c| a.saturating_add(c));
        if intargs.len() as i64 != ni || floatargs.len() as i64 != nf {
            return self.geom_error(
                call,
                call.pos_spans[4],
                format!(
                    "nargs asks for {ni} integers and {nf} floats; found {} and {}",
                    intargs.len(),
                    floatargs.len()
                ),
                call.spec.describe(),
            );
        }
        for (i, t) in tags.iter().enumerate() {
            if !matches!(
                t.as_str(),
                "hole"
                    | "crease"
                    | "corner"
                    | "interpolateboundary"
                    | "facevaryinginterpolateboundary"
                    | "facevaryingpropagatecorners"
                    | "creasemethod"
                    | "vertexedit"
                    | "edgeedit"
                    | "faceedit"
                    | "stitch"
                    | "smoothtriangles"
            ) {
                let d = Diag::warning(
                    "scene::subdivision-tag",
                    format!("`SubdivisionMesh`: unknown tag \"{t}\" is ignored"),
                )
                .label(call.pos_spans[3], format!("tag {i}"))
                .help("known tags: hole, crease, corner, interpolateboundary");
                self.report(d);
            }
        }
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let c = Counts {
            uniform: nverts.len(),
            varying: nvertices,
            vertex: nvertices,
            facevarying: total,
            facevertex: total,
        };
        let g = Geometry::SubdivisionMesh {
            scheme,
            nverts,
            verts,
            tags,
            nargs: nargs.iter().map(|&n| n as u32).collect(),
            intargs,
            floatargs,
        };
        self.finish_prim(call, g, pv, c);
    }

    /// The (int count, float count) pair of each tag. `HierarchicalSubdivisionMesh` (PRMan 16
    /// and later; RenderMan for Maya writes it for every mesh) gives a triple per tag — the
    /// third counts string arguments, which only its hierarchical edit tags (`vertexedit`,
    /// `edgeedit`, `faceedit`) use and the tesselator warns about anyway — so the triples
    /// become pairs and the strings are left out; otherwise the mesh is a `SubdivisionMesh`.
    fn subdivision_nargs(
        &mut self,
        call: &Call<'_>,
        ntags: usize,
        hierarchical: bool,
    ) -> Option<Vec<i64>> {
        let nargs = call.pos[4].ints();
        if !hierarchical {
            return Some(nargs.to_vec());
        }
        if nargs.len() != 3 * ntags || nargs.iter().any(|&n| n < 0) {
            self.geom_error(
                call,
                call.pos_spans[4],
                format!(
                    "{ntags} tags need {} nargs (int, float and string counts per tag), found {}",
                    3 * ntags,
                    nargs.len()
                ),
                call.spec.describe(),
            );
            return None;
        }
        let nstrings: i64 = nargs.iter().skip(2).step_by(3).sum();
        if nstrings != call.pos[7].strs().len() as i64 {
            self.geom_error(
                call,
                call.pos_spans[7],
                format!(
                    "nargs asks for {nstrings} strings; found {}",
                    call.pos[7].strs().len()
                ),
                call.spec.describe(),
            );
            return None;
        }
        Some(
            nargs
                .chunks(3)
                .flat_map(|c| [c[0], c[1]])
                .collect::<Vec<i64>>(),
        )
    }

    pub(super) fn points(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        let Some(n) = self.position_count(call, &pv, false) else {
            return;
        };
        let c = Counts {
            uniform: 1,
            varying: n,
            vertex: n,
            facevarying: n,
            facevertex: n,
        };
        self.finish_prim(call, Geometry::Points { npoints: n }, pv, c);
    }

    pub(super) fn curves(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let cubic = match call.pos[0].str() {
            "linear" => false,
            "cubic" => true,
            other => {
                let d = Diag::error(
                    "scene::arguments",
                    format!("unknown curve type \"{other}\""),
                )
                .label(call.pos_spans[0], "here")
                .help("use \"linear\" or \"cubic\"");
                return self.report(d);
            }
        };
        let Some(periodic) = self.wrap(call, 2) else {
            return;
        };
        let min = if cubic { 4 } else { 2 };
        let Some(nverts) = self.check_counts(
            call,
            1,
            call.pos[1].ints(),
            if periodic && !cubic { 3 } else { min },
            "nvertices",
        ) else {
            return;
        };
        let step = self.gs.attrs.v_basis.step as usize;
        let mut varying = 0;
        for &n in &nverts {
            let n = n as usize;
            let segs = match (cubic, periodic) {
                (false, false) => n - 1,
                (false, true) => n,
                (true, false) if (n - 4) % step == 0 => (n - 4) / step + 1,
                (true, true) if n % step == 0 => n / step,
                _ => {
                    return self.geom_error(
                        call,
                        call.pos_spans[1],
                        format!("a cubic curve of {n} vertices does not fit the basis step {step}"),
                        format!(
                            "nonperiodic: 4 + k·{step} vertices; periodic: a multiple of {step}"
                        ),
                    )
                }
            };
            varying += if periodic { segs } else { segs + 1 };
        }
        let pv = self.params(call, ParamUse::Primitive);
        if !self.need_position(call, &pv, false) {
            return;
        }
        let c = Counts {
            uniform: nverts.len(),
            varying,
            vertex: Self::sum(&nverts),
            facevarying: varying,
            facevertex: varying,
        };
        let g = Geometry::Curves {
            cubic,
            nverts,
            periodic,
            v_basis: self.gs.attrs.v_basis,
        };
        self.finish_prim(call, g, pv, c);
    }

    pub(super) fn geometry_named(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let pv = self.params(call, ParamUse::Primitive);
        let name = call.pos[0].str().to_string();
        // The named primitive sizes its own varying data; only constant/uniform are checked.
        let mut pv = pv;
        let mut ds = Vec::new();
        let (mut fixed, other): (Vec<Param>, Vec<Param>) =
            pv.0.drain(..)
                .partition(|p| matches!(p.decl.class, Class::Constant | Class::Uniform));
        let mut fixed_list = ParamList(std::mem::take(&mut fixed));
        validate_counts(
            &mut fixed_list,
            &Counts::corners(1),
            call.name(),
            &mut |d| ds.push(d),
        );
        for d in ds {
            self.report(d);
        }
        fixed_list.0.extend(other);
        self.emit(
            call.full_span(),
            Arc::new(Geometry::Named { name }),
            Arc::new(fixed_list),
        );
    }

    // ---- retained objects ----

    pub(super) fn object_begin(&mut self, call: &Call<'_>) {
        if self.defining.is_some() {
            return self.report(
                Diag::error(
                    "scene::nesting",
                    "`ObjectBegin` inside another object definition",
                )
                .label(call.span(), "objects do not nest")
                .help("close the open object with `ObjectEnd` first"),
            );
        }
        self.push_block(BlockKind::Object, call.span());
        self.defining = Some(ObjectDef {
            handle: call.pos[0].str().to_string(),
            shape: ObjectShape::default(),
            object_from_ctm: self.gs.ctm.inverse(),
        });
        // Solids of the definition are numbered within it (ObjectEnd restores the attribute).
        if self.gs.attrs.solid.is_some() {
            self.attrs().solid = None;
        }
    }

    pub(super) fn finish_object(&mut self) {
        if let Some(def) = self.defining.take() {
            self.objects.insert(def.handle, Arc::new(def.shape));
        }
    }

    pub(super) fn object_end(&mut self, call: &Call<'_>) {
        if let Some(b) = self.pop_block(BlockKind::Object, call) {
            self.finish_object();
            self.restore_attrs(b.saved);
        }
    }

    pub(super) fn object_instance(&mut self, call: &Call<'_>) {
        let handle = call.pos[0].str();
        let Some(shape) = self.objects.get(handle).cloned() else {
            let known: Vec<&str> = self.objects.keys().map(String::as_str).collect();
            let mut d = Diag::error(
                "scene::handle",
                format!("`ObjectInstance`: no object has handle {handle}"),
            )
            .label(call.pos_spans[0], "unknown object");
            d = match crate::diag::did_you_mean(handle, known.iter().copied()) {
                Some(m) => d.help(format!("did you mean {m}?")),
                None => d.help("define it first with `ObjectBegin` … `ObjectEnd`"),
            };
            return self.report(d);
        };
        if !self.geometry_wanted(call) {
            return;
        }
        // Instances take the current transform and attributes (RISpec §5.7).
        let base = self.gs.ctm;
        let outer = self.gs.attrs.solid;
        let solids = self.instance_solids(&shape.solids, outer);
        for p in shape.prims.iter() {
            let solid = p.solid.map_or(outer, |l| solids[l as usize]);
            if self.gs.attrs.solid != solid {
                self.attrs().solid = solid;
            }
            self.gs.ctm = base * p.object_from_prim;
            self.emit(p.span, p.geometry.clone(), p.primvars.clone());
        }
        if self.gs.attrs.solid != outer {
            self.attrs().solid = outer;
        }
        self.gs.ctm = base;
    }

    /// The scene's solid node for each `SolidBegin` block of an object definition, made
    /// afresh for this instance under `outer` (the instance's own solid), with the rules of
    /// `solid_begin`: a primitive solid outside any boolean needs no node, and a block inside
    /// a primitive solid is part of that primitive.
    fn instance_solids(&mut self, local: &[ObjSolid], outer: Option<u32>) -> Vec<Option<u32>> {
        let mut ids: Vec<Option<u32>> = Vec::with_capacity(local.len());
        if let Some(def) = self.defining.as_mut() {
            // An instance inside another definition: its solids join that definition's.
            for node in local {
                let parent = node.parent.map_or(outer, |p| ids[p as usize]);
                ids.push(Some(def.shape.solids.len() as u32));
                def.shape.solids.push(ObjSolid {
                    parent,
                    ..node.clone()
                });
            }
            return ids;
        }
        let Some(scene) = self.world.as_mut() else {
            return vec![outer; local.len()];
        };
        for node in local {
            let parent = node.parent.map_or(outer, |p| ids[p as usize]);
            let parent_op = parent
                .and_then(|p| scene.solids.get(p as usize))
                .map(|n| n.op);
            let id = match (node.op, parent_op) {
                (SolidOp::Primitive, None) => None,
                (_, Some(SolidOp::Primitive)) => parent,
                (op, _) => {
                    let id = scene.solids.len() as u32;
                    scene.solids.push(SolidNode {
                        op,
                        parent,
                        span: node.span,
                    });
                    Some(id)
                }
            };
            ids.push(id);
        }
        ids
    }
}
