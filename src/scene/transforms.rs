//! Transformation requests (RISpec §4.3) and named coordinate systems.
//!
//! Input: checked [`Call`]s. Output: the builder's current transform (`ctm`) and its named
//! spaces.
//! Invariants: every request post-multiplies (`ctm = ctm * M`, so M acts on object points
//! first) except Identity/Transform/CoordSysTransform, which replace it; inside the world the
//! ctm is world_from_object (Identity means world space), before it camera_from_current.
//! Angles are degrees; camera space is left-handed, but the matrices are the standard ones.

use std::sync::Arc;

use glam::{Mat4, Vec3, Vec4};

use crate::diag::Diag;

use super::builder::Builder;
use super::table::{Call, PArg};

/// RiPerspective(fov): x and y scaled by cot(fov/2), w = z. The depth row maps z to
/// (z − 1)/z, which keeps the matrix invertible (near plane at 1).
pub fn perspective_matrix(fov_deg: f32) -> Mat4 {
    let cot = 1.0 / (fov_deg.to_radians() * 0.5).tan();
    Mat4::from_cols(
        Vec4::new(cot, 0.0, 0.0, 0.0),
        Vec4::new(0.0, cot, 0.0, 0.0),
        Vec4::new(0.0, 0.0, 1.0, 1.0),
        Vec4::new(0.0, 0.0, -1.0, 0.0),
    )
}

/// RiSkew: shears along `d2` so that `d1` turns by `angle` degrees towards `d2`.
/// With a = d2/|d2| and b the unit part of d1 orthogonal to a, M = I + k·a·bᵀ where
/// k = tan(φ + angle) − tan(φ) and φ is d1's angle from b towards a.
pub fn skew_matrix(angle_deg: f32, d1: Vec3, d2: Vec3) -> Option<Mat4> {
    let a = d2.try_normalize()?;
    let perp = d1 - a * d1.dot(a);
    let b = perp.try_normalize()?;
    let phi = d1.dot(a).atan2(d1.dot(b));
    let t = phi + angle_deg.to_radians();
    if t.cos() <= 1e-6 {
        return None;
    }
    let k = t.tan() - phi.tan();
    let m = glam::Mat3::from_cols(a * b.x, a * b.y, a * b.z);
    Some(Mat4::from_mat3(glam::Mat3::IDENTITY + m * k))
}

impl Builder<'_> {
    fn concat(&mut self, m: Mat4) {
        self.gs.ctm *= m;
        if let Some(mo) = self.gs.motion.as_mut() {
            for k in Arc::make_mut(mo).mats.iter_mut() {
                *k *= m;
            }
        }
    }

    pub(super) fn identity(&mut self, _call: &Call<'_>) {
        self.gs.ctm = Mat4::IDENTITY;
        self.gs.motion = None;
    }

    pub(super) fn transform(&mut self, call: &Call<'_>) {
        if let PArg::Matrix(m) = call.pos[0] {
            if !self.check_matrix(call, &m) {
                return;
            }
            self.gs.ctm = m;
            self.gs.motion = None;
        }
    }

    pub(super) fn concat_transform(&mut self, call: &Call<'_>) {
        if let PArg::Matrix(m) = call.pos[0] {
            if !self.check_matrix(call, &m) {
                return;
            }
            self.concat(m);
        }
    }

    fn check_matrix(&mut self, call: &Call<'_>, m: &Mat4) -> bool {
        let det = m.determinant();
        if !det.is_finite() || det == 0.0 {
            let d = Diag::error(
                "scene::math",
                format!("`{}`: the matrix is singular", call.name()),
            )
            .label(call.pos_spans[0], "determinant 0")
            .help("a transform must be invertible (check for a zero scale)");
            self.report(d);
            return false;
        }
        true
    }

    pub(super) fn perspective(&mut self, call: &Call<'_>) {
        let fov = call.pos[0].num();
        if !(fov > 0.0 && fov < 180.0) {
            let d = Diag::error(
                "scene::arguments",
                format!("`Perspective {fov}`: the field of view must be between 0 and 180"),
            )
            .label(call.pos_spans[0], "here");
            self.report(d);
            return;
        }
        self.concat(perspective_matrix(fov));
    }

    pub(super) fn translate(&mut self, call: &Call<'_>) {
        let v = Vec3::new(call.pos[0].num(), call.pos[1].num(), call.pos[2].num());
        self.concat(Mat4::from_translation(v));
    }

    pub(super) fn rotate(&mut self, call: &Call<'_>) {
        let angle = call.pos[0].num();
        let axis = Vec3::new(call.pos[1].num(), call.pos[2].num(), call.pos[3].num());
        let Some(axis) = axis.try_normalize() else {
            let d = Diag::error("scene::arguments", "`Rotate`: the axis is zero")
                .label(call.pos_spans[1], "axis (0, 0, 0)")
                .help("e.g. `Rotate 90 0 0 1` turns about z");
            self.report(d);
            return;
        };
        self.concat(Mat4::from_axis_angle(axis, angle.to_radians()));
    }

    pub(super) fn scale(&mut self, call: &Call<'_>) {
        let v = Vec3::new(call.pos[0].num(), call.pos[1].num(), call.pos[2].num());
        if v.x * v.y * v.z == 0.0 {
            let d = Diag::warning(
                "scene::math",
                "`Scale` by zero flattens everything after it",
            )
            .label(call.full_span(), "a zero scale");
            self.report(d);
        }
        self.concat(Mat4::from_scale(v));
    }

    pub(super) fn skew(&mut self, call: &Call<'_>) {
        let p: Vec<f32> = call.pos.iter().map(PArg::num).collect();
        let d1 = Vec3::new(p[1], p[2], p[3]);
        let d2 = Vec3::new(p[4], p[5], p[6]);
        match skew_matrix(p[0], d1, d2) {
            Some(m) => self.concat(m),
            None => {
                let d = Diag::error(
                    "scene::arguments",
                    "`Skew`: the angle must be smaller than the angle between the two axes, and neither axis zero nor parallel",
                )
                .label(call.full_span(), "here");
                self.report(d);
            }
        }
    }

    pub(super) fn coordinate_system(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str().to_string();
        let m = self.camera_from_current();
        self.named.insert(name, m);
    }

    pub(super) fn scoped_coordinate_system(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str().to_string();
        let m = self.camera_from_current();
        let old = self.named.insert(name.clone(), m);
        self.gs.scoped.push((name, old));
    }

    pub(super) fn coord_sys_transform(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str();
        let camera_from_named = match name {
            "camera" => Some(Mat4::IDENTITY),
            "world" => Some(
                self.world
                    .as_ref()
                    .map_or(Mat4::IDENTITY, |s| s.camera_from_world),
            ),
            n => self.named.get(n).copied(),
        };
        let Some(cfn) = camera_from_named else {
            let known: Vec<&str> = self.named.keys().map(String::as_str).collect();
            let mut d = Diag::error(
                "scene::coordsys",
                format!("`CoordSysTransform`: no coordinate system named \"{name}\""),
            )
            .label(call.pos_spans[0], "unknown space");
            d = match crate::diag::did_you_mean(name, known.iter().copied()) {
                Some(m) => d.help(format!("did you mean \"{m}\"?")),
                None => d.help("name a space with `CoordinateSystem` first"),
            };
            self.report(d);
            return;
        };
        self.gs.ctm = match &self.world {
            Some(s) => s.camera_from_world.inverse() * cfn,
            None => cfn,
        };
        self.gs.motion = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skew_turns_d1_by_the_angle() {
        // Skew 45 about (0,1,0) towards (1,0,0): y axis leans 45° towards x.
        let m = skew_matrix(45.0, Vec3::Y, Vec3::X).unwrap();
        let p = m.transform_point3(Vec3::Y);
        assert!((p - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-5, "{p}");
        // Points along d2 do not move.
        assert!((m.transform_point3(Vec3::X) - Vec3::X).length() < 1e-6);
        // Too large an angle is refused.
        assert!(skew_matrix(95.0, Vec3::Y, Vec3::X).is_none());
    }

    #[test]
    fn perspective_divides_by_z() {
        let m = perspective_matrix(90.0);
        let p = m.project_point3(Vec3::new(2.0, 1.0, 2.0));
        assert!((p.x - 1.0).abs() < 1e-5 && (p.y - 0.5).abs() < 1e-5);
        assert!(m.determinant() != 0.0);
    }
}
