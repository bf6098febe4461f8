//! Level of detail (RISpec 3.2 §4.2.9, `Detail` and `DetailRange`): which of a model's
//! representations the camera sees.
//!
//! Input: a built [`Scene`] and the frame's [`Camera`]. Output: the scene without the
//! primitives whose representation is not the one drawn at the current detail.
//! Invariants: a primitive without a `Detail` box, or with the default range
//! `[0 0 ∞ ∞]`, is always kept. The detail is the area in pixels of the raster-space
//! rectangle bounding the `Detail` box, times `RelativeDetail`; a box reaching behind the eye
//! plane counts as infinitely detailed. A representation's importance rises linearly from 0 at
//! `minvisible` to 1 at `lowertransition`, stays 1 up to `uppertransition` and falls to 0 at
//! `maxvisible`; it is drawn when its importance exceeds ½ (exactly ½ only on its rising
//! edge), so two representations whose transitions overlap as RISpec's examples write them
//! (`[0 0 20 30]` then `[20 30 500 600]`) hand over at the middle of the transition and no
//! detail draws both or neither. PRMan dissolves between the two over the transition
//! instead; a hard hand-over keeps every pixel's value independent of the sample pattern.

use glam::Vec3;

use crate::scene::{Primitive, Scene};

use super::Camera;

/// The detail of a world-space box seen by `camera`: its raster bounding rectangle's area in
/// pixels (infinite when the box reaches behind the eye).
pub fn detail_of(corners: &[Vec3; 8], camera: &Camera) -> f32 {
    let mut lo = glam::Vec2::splat(f32::INFINITY);
    let mut hi = glam::Vec2::splat(f32::NEG_INFINITY);
    for &c in corners {
        let p = camera.camera_from_world.transform_point3(c);
        if camera.perspective && p.z <= camera.near.max(1e-6) {
            return f32::INFINITY;
        }
        let r = camera.project(p);
        lo = lo.min(r.truncate());
        hi = hi.max(r.truncate());
    }
    let size = (hi - lo).max(glam::Vec2::ZERO);
    size.x * size.y
}

/// How much of a representation with `range` is drawn at `detail` (see the module docs).
pub fn importance(range: [f32; 4], detail: f32) -> f32 {
    let [min, low, up, max] = range;
    if detail < min || detail > max {
        0.0
    } else if detail < low {
        (detail - min) / (low - min)
    } else if detail <= up {
        1.0
    } else {
        (max - detail) / (max - up)
    }
}

/// Whether `prim` is drawn at its detail (see the module docs).
fn drawn(prim: &Primitive, camera: &Camera, relative_detail: f32) -> bool {
    let a = &prim.attributes;
    let range = a.detail_range;
    if range == [0.0, 0.0, f32::INFINITY, f32::INFINITY] {
        return true;
    }
    let Some(corners) = a.detail.as_ref() else {
        return true;
    };
    let detail = detail_of(corners, camera) * relative_detail.max(0.0);
    let w = importance(range, detail);
    w > 0.5 || (w == 0.5 && detail < range[1])
}

/// [`select`] with the camera of the frame as `opts` renders it (its resolution and crop).
pub fn select_for(scene: &mut Scene, opts: &super::RenderOptions) {
    if scene
        .primitives
        .iter()
        .all(|p| p.attributes.detail.is_none())
    {
        return;
    }
    let options = super::driver::effective_options(&scene.options, opts);
    let camera = Camera::from_options(&options, scene.camera_from_world, &scene.coordinate_systems);
    select(scene, &camera);
}

/// Drops the primitives of `scene` whose representation is not drawn (see the module docs).
pub fn select(scene: &mut Scene, camera: &Camera) {
    let relative = scene.options.relative_detail;
    if scene
        .primitives
        .iter()
        .all(|p| p.attributes.detail.is_none())
    {
        return;
    }
    scene.primitives.retain(|p| drawn(p, camera, relative));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn importance_ramps_through_the_transitions() {
        let r = [10.0, 20.0, 100.0, 200.0];
        assert_eq!(importance(r, 5.0), 0.0);
        assert_eq!(importance(r, 15.0), 0.5);
        assert_eq!(importance(r, 50.0), 1.0);
        assert_eq!(importance(r, 150.0), 0.5);
        assert_eq!(importance(r, 250.0), 0.0);
        // An empty rising edge (RISpec's first range, `[0 0 20 30]`) is fully drawn from 0.
        assert_eq!(importance([0.0, 0.0, 20.0, 30.0], 0.0), 1.0);
        assert_eq!(importance([500.0, 600.0, 1e38, 1e38], 1e37), 1.0);
    }
}
