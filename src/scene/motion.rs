//! Motion blocks (RISpec §5.8): `MotionBegin [times] … MotionEnd` around transforms and
//! around primitives.
//!
//! Input: the requests of one motion block, collected by the builder's run loop, and the
//! block's times. Output: a moving transform in the graphics state (`GState::motion`: the
//! ctm at each time, its first key also the plain ctm), or one primitive carrying a
//! [`Motion`] with a full primitive per time (deformation).
//! Invariants: a block holds exactly one request per time, all of the same request, times
//! strictly increasing; anything else is an error (miette diagnostic at the block) and the
//! first request is used, as before motion blur existed. Transform keys are rebuilt from
//! interpolated request arguments where a segment rotates far (so a spin stays a spin when
//! vertices later move linearly between keys).

use std::sync::Arc;

use glam::Mat4;

use crate::diag::{Diag, Span};
use crate::rib::{Request, Value};

use super::builder::Builder;
use super::types::*;

/// A motion block being collected.
#[derive(Clone, Debug)]
pub(super) struct MotionBlock {
    pub times: Vec<f32>,
    /// The `MotionBegin` request (its times argument is the first argument).
    pub span: Span,
    pub times_span: Span,
    pub reqs: Vec<Request>,
}

/// Transform requests that may move.
const TRANSFORMS: &[&str] = &[
    "Translate",
    "Rotate",
    "Scale",
    "Skew",
    "ConcatTransform",
    "Transform",
    "Perspective",
    "Identity",
    "CoordSysTransform",
];

/// Requests that replace the ctm rather than post-multiply it.
const REPLACING: &[&str] = &["Transform", "Identity", "CoordSysTransform"];

/// A segment of a rotation is cut into pieces of at most this many degrees.
const MAX_KEY_DEGREES: f32 = 15.0;
/// Most keys one transform motion block is refined to.
const MAX_KEYS: usize = 64;

/// Union of two increasing time lists.
pub(super) fn union_times(a: &[f32], b: &[f32]) -> Vec<f32> {
    let mut t: Vec<f32> = a.iter().chain(b).copied().collect();
    t.sort_by(f32::total_cmp);
    t.dedup();
    t
}

/// The request with its numeric arguments interpolated between `a` and `b` (None when their
/// arguments do not line up).
fn lerp_request(a: &Request, b: &Request, f: f32) -> Option<Request> {
    if a.args.len() != b.args.len() {
        return None;
    }
    let mut r = a.clone();
    for (x, y) in r.args.iter_mut().zip(&b.args) {
        let l = |u: f32, v: f32| u + (v - u) * f;
        x.value = match (&x.value, &y.value) {
            (Value::Float(_) | Value::Int(_), Value::Float(_) | Value::Int(_)) => Value::Float(l(
                x.value.as_f32().unwrap_or(0.0),
                y.value.as_f32().unwrap_or(0.0),
            )),
            (Value::FloatArray(u), Value::FloatArray(v)) if u.len() == v.len() => {
                Value::FloatArray(u.iter().zip(v).map(|(&u, &v)| l(u, v)).collect())
            }
            (Value::Str(u), Value::Str(v)) if u == v => x.value.clone(),
            (Value::StrArray(u), Value::StrArray(v)) if u == v => x.value.clone(),
            _ => return None,
        };
    }
    Some(r)
}

fn same_shape(a: &Geometry, b: &Geometry) -> bool {
    use Geometry as G;
    match (a, b) {
        (G::Sphere { .. }, G::Sphere { .. })
        | (G::Cone { .. }, G::Cone { .. })
        | (G::Cylinder { .. }, G::Cylinder { .. })
        | (G::Hyperboloid { .. }, G::Hyperboloid { .. })
        | (G::Paraboloid { .. }, G::Paraboloid { .. })
        | (G::Disk { .. }, G::Disk { .. })
        | (G::Torus { .. }, G::Torus { .. }) => true,
        (
            G::Polygons {
                nloops,
                nverts,
                verts,
                ..
            },
            G::Polygons {
                nloops: l2,
                nverts: n2,
                verts: v2,
                ..
            },
        ) => nloops == l2 && nverts == n2 && verts == v2,
        (
            G::PatchMesh {
                bicubic,
                nu,
                nv,
                uperiodic,
                vperiodic,
                ..
            },
            G::PatchMesh {
                bicubic: b2,
                nu: u2,
                nv: v2,
                uperiodic: up2,
                vperiodic: vp2,
                ..
            },
        ) => bicubic == b2 && nu == u2 && nv == v2 && uperiodic == up2 && vperiodic == vp2,
        (
            G::NuPatch {
                nu,
                nv,
                uorder,
                vorder,
                uknot,
                vknot,
                ..
            },
            G::NuPatch {
                nu: u2,
                nv: v2,
                uorder: uo2,
                vorder: vo2,
                uknot: uk2,
                vknot: vk2,
                ..
            },
        ) => nu == u2 && nv == v2 && uorder == uo2 && vorder == vo2 && uknot == uk2 && vknot == vk2,
        (
            G::SubdivisionMesh { nverts, verts, .. },
            G::SubdivisionMesh {
                nverts: n2,
                verts: v2,
                ..
            },
        ) => nverts == n2 && verts == v2,
        (G::Points { npoints }, G::Points { npoints: n2 }) => npoints == n2,
        (
            G::Curves {
                cubic,
                nverts,
                periodic,
                ..
            },
            G::Curves {
                cubic: c2,
                nverts: n2,
                periodic: p2,
                ..
            },
        ) => cubic == c2 && nverts == n2 && periodic == p2,
        (G::Named { name }, G::Named { name: n2 }) => name == n2,
        _ => false,
    }
}

/// The first primitive variable whose presence or size differs between two keys.
fn primvar_mismatch(a: &ParamList, b: &ParamList) -> Option<String> {
    for p in a.iter() {
        match b.get(&p.name) {
            None => return Some(format!("\"{}\" is missing", p.name)),
            Some(q) if q.data.len() != p.data.len() => {
                return Some(format!(
                    "\"{}\" has {} values, not {}",
                    p.name,
                    q.data.len(),
                    p.data.len()
                ))
            }
            _ => {}
        }
    }
    b.iter()
        .find(|q| a.get(&q.name).is_none())
        .map(|q| format!("\"{}\" is not in the first", q.name))
}

impl Builder<'_> {
    pub(super) fn motion_begin(&mut self, call: &super::table::Call<'_>) {
        if self.motion_block.is_some() {
            self.error(
                "scene::nesting",
                "`MotionBegin` inside another motion block",
                call.span(),
                "motion blocks do not nest",
            );
            return;
        }
        self.push_block(super::builder::BlockKind::Motion, call.span());
        self.motion_block = Some(MotionBlock {
            times: call.pos[0].floats().to_vec(),
            span: call.span(),
            times_span: call.pos_spans[0],
            reqs: Vec::new(),
        });
    }

    pub(super) fn motion_end(&mut self, call: &super::table::Call<'_>) {
        if self
            .pop_block(super::builder::BlockKind::Motion, call)
            .is_none()
        {
            return;
        }
        if let Some(block) = self.motion_block.take() {
            self.run_motion(block, call.span());
        }
    }

    /// Applies a collected motion block.
    fn run_motion(&mut self, block: MotionBlock, end: Span) {
        let MotionBlock {
            times,
            span,
            times_span,
            reqs,
        } = block;
        let Some(first) = reqs.first() else {
            self.report(
                Diag::warning("scene::motion", "empty motion block")
                    .label(span, "nothing between `MotionBegin` and `MotionEnd`"),
            );
            return;
        };
        let n = times.len();
        let fail = |b: &mut Self, d: Diag| {
            b.report(d);
            b.dispatch(first);
        };
        if reqs.len() != n {
            let d = Diag::error(
                "scene::motion",
                format!(
                    "`MotionBegin` gives {n} time{} but the block holds {} request{}",
                    if n == 1 { "" } else { "s" },
                    reqs.len(),
                    if reqs.len() == 1 { "" } else { "s" }
                ),
            )
            .label(times_span, format!("{n} time{}", if n == 1 { "" } else { "s" }))
            .label(end, format!("{} request{} before here", reqs.len(), if reqs.len() == 1 { "" } else { "s" }))
            .help("give one request per time, e.g. `MotionBegin [0 1] Translate 0 0 0 Translate 1 0 0 MotionEnd`; the first request is used");
            return fail(self, d);
        }
        if let Some(r) = reqs.iter().find(|r| r.name != first.name) {
            let d = Diag::error(
                "scene::motion",
                format!(
                    "a motion block mixes `{}` and `{}`",
                    first.name, r.name
                ),
            )
            .label(first.span, "the first key")
            .label(r.span, "a different request")
            .help("every request of a motion block is the same request at another time; the first request is used");
            return fail(self, d);
        }
        if times.windows(2).any(|w| !(w[0] < w[1])) || times.iter().any(|t| !t.is_finite()) {
            let d = Diag::error("scene::motion", "motion times must increase")
                .label(times_span, "these times")
                .help("e.g. `MotionBegin [0 0.5 1]`; the first request is used");
            return fail(self, d);
        }
        if n == 1 {
            self.dispatch(first);
            return;
        }
        let name = first.name.clone();
        if TRANSFORMS.contains(&name.as_str()) {
            self.motion_transform(&times, &reqs);
            return;
        }
        let geometry = super::table::lookup(&name).is_some_and(|s| {
            s.section.starts_with("5.") && !matches!(s.section, "5.6" | "5.7" | "5.8")
        });
        if !geometry {
            self.report(
                Diag::warning(
                    "scene::motion",
                    format!("`{name}` inside `MotionBegin`: only transforms and geometry move; the first key is used"),
                )
                .label(first.span, "does not move"),
            );
            self.dispatch(first);
            return;
        }
        self.motion_geometry(&times, &reqs);
    }

    /// A moving transform: the ctm at every key (and at extra keys inside rotating
    /// segments), composed with the motion already in the ctm.
    fn motion_transform(&mut self, times: &[f32], reqs: &[Request]) {
        let replace = REPLACING.contains(&reqs[0].name.as_str());
        let base_ctm = self.gs.ctm;
        let base_motion = self.gs.motion.clone();
        // The request's own matrix (from the identity) at each key, refined where it turns.
        let mut keys: Vec<(f32, Request)> = Vec::new();
        for i in 0..reqs.len() {
            keys.push((times[i], reqs[i].clone()));
            if i + 1 == reqs.len() {
                break;
            }
            let pieces = if reqs[i].name == "Rotate" {
                let a0 = reqs[i].args.first().and_then(|a| a.value.as_f32());
                let a1 = reqs[i + 1].args.first().and_then(|a| a.value.as_f32());
                match (a0, a1) {
                    (Some(a), Some(b)) if (b - a).is_finite() => ((b - a).abs() / MAX_KEY_DEGREES)
                        .ceil()
                        .clamp(1.0, MAX_KEYS as f32)
                        as usize,
                    _ => 1,
                }
            } else {
                1
            };
            for j in 1..pieces {
                let f = j as f32 / pieces as f32;
                if keys.len() >= MAX_KEYS {
                    break;
                }
                if let Some(r) = lerp_request(&reqs[i], &reqs[i + 1], f) {
                    keys.push((times[i] + (times[i + 1] - times[i]) * f, r));
                }
            }
        }
        let mut local = MotionTransform {
            times: Vec::with_capacity(keys.len()),
            mats: Vec::with_capacity(keys.len()),
        };
        for (t, r) in &keys {
            self.gs.ctm = Mat4::IDENTITY;
            self.gs.motion = None;
            self.dispatch(r);
            local.times.push(*t);
            local.mats.push(self.gs.ctm);
        }
        let all = match (&base_motion, replace) {
            (Some(m), false) => union_times(&local.times, &m.times),
            _ => local.times.clone(),
        };
        let mats: Vec<Mat4> = all
            .iter()
            .map(|&t| {
                let base = match (&base_motion, replace) {
                    (_, true) => Mat4::IDENTITY,
                    (Some(m), false) => m.at(t),
                    (None, false) => base_ctm,
                };
                base * local.at(t)
            })
            .collect();
        self.gs.ctm = mats[0];
        self.gs.motion = if mats.iter().all(|m| *m == mats[0]) {
            None
        } else {
            Some(Arc::new(MotionTransform { times: all, mats }))
        };
    }

    /// A deforming primitive: each request builds the primitive at its time; they must
    /// have the same kind and shape.
    fn motion_geometry(&mut self, times: &[f32], reqs: &[Request]) {
        self.capture = Some(Vec::new());
        for r in reqs {
            self.dispatch(r);
        }
        let caps = self.capture.take().unwrap_or_default();
        if caps.is_empty() {
            return; // every key was refused (and reported), or the frame is skipped
        }
        let emit_first = |b: &mut Self, d: Option<Diag>| {
            if let Some(d) = d {
                b.report(d);
            }
            let (span, g, p) = caps[0].clone();
            b.emit(span, g, p);
        };
        if caps.len() != times.len() {
            // A key was refused with an error already reported.
            return emit_first(self, None);
        }
        for (k, c) in caps.iter().enumerate().skip(1) {
            let why = if !same_shape(&caps[0].1, &c.1) {
                Some("its kind or topology differs from the first".to_string())
            } else {
                primvar_mismatch(&caps[0].2, &c.2)
            };
            if let Some(why) = why {
                let d = Diag::error(
                    "scene::motion",
                    format!("the primitives of a motion block must have the same shape: key {} {why}", k + 1),
                )
                .label(caps[0].0, "the first key")
                .label(c.0, "this key")
                .help("each key is the same primitive at another time (same vertex counts and primitive variables); the first key is used");
                return emit_first(self, Some(d));
            }
        }
        if self.defining.is_some() {
            let d = Diag::warning(
                "scene::motion",
                "a deforming primitive inside `ObjectBegin` keeps its first key",
            )
            .label(caps[0].0, "first key used");
            return emit_first(self, Some(d));
        }
        let shapes: Vec<(Arc<Geometry>, Arc<ParamList>)> = caps
            .iter()
            .map(|(_, g, p)| (g.clone(), p.clone()))
            .collect();
        let shape_motion = Motion {
            times: times.to_vec(),
            world_from_object: vec![self.gs.ctm],
            shapes,
        };
        let (span, g, p) = caps[0].clone();
        self.emit_moving(span, g, p, Some(shape_motion));
    }

    /// The motion of a primitive emitted now: the ctm's motion, merged with a deformation.
    pub(super) fn primitive_motion(&self, deform: Option<Motion>) -> Option<Motion> {
        let xf = self.gs.motion.as_ref().map(|m| {
            // An instance's part sits below the moving ctm: carry its offset.
            let local = if m.mats[0] == self.gs.ctm {
                Mat4::IDENTITY
            } else {
                m.mats[0].inverse() * self.gs.ctm
            };
            (m, local)
        });
        match (xf, deform) {
            (None, d) => d,
            (Some((m, local)), None) => Some(Motion {
                times: m.times.clone(),
                world_from_object: m.mats.iter().map(|w| *w * local).collect(),
                shapes: Vec::new(),
            }),
            (Some((m, local)), Some(d)) => {
                let times = union_times(&m.times, &d.times);
                let world_from_object = times.iter().map(|&t| m.at(t) * local).collect();
                let shapes = times
                    .iter()
                    .map(|&t| d.shape_at(t).unwrap_or_else(|| d.shapes[0].clone()))
                    .collect();
                Some(Motion {
                    times,
                    world_from_object,
                    shapes,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn union_and_segments() {
        assert_eq!(union_times(&[0.0, 1.0], &[0.5, 1.0]), vec![0.0, 0.5, 1.0]);
        assert_eq!(motion_segment(&[0.0, 1.0], 0.25), (0, 0.25));
        assert_eq!(motion_segment(&[0.0, 0.5, 1.0], 0.75), (1, 0.5));
        assert_eq!(motion_segment(&[0.0, 1.0], 2.0), (0, 1.0));
        assert_eq!(motion_segment(&[0.0, 1.0], -1.0), (0, 0.0));
    }
}
