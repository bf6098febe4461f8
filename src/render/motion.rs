//! Motion blur set-up: a primitive's keys over the shutter, in camera space.
//!
//! Input: a [`Primitive`] (with its [`crate::scene::Motion`], if any), the scene's camera
//! motion, and `Shutter open close`. Output: the primitive's surfaces — still ones when nothing
//! moves while the shutter is open, else [`crate::geom::motion::MovingSurface`]s whose keys
//! are the shutter-open time, every key time strictly inside the shutter, and the close time
//! (times normalised to 0…1). Invariants: a primitive that does not move costs nothing
//! (plain surfaces); with the shutter closed (`open == close`, the default) every primitive is
//! taken at the open time; shading happens at key 0, the shutter-open time.

use glam::Mat4;

use crate::diag::Diagnostics;
use crate::geom::motion::{moving_surfaces, MotionKey};
use crate::geom::Surface;
use crate::scene::{MotionTransform, Primitive};

/// The key times of a motion over the shutter [open, close].
fn shutter_times(times: &[f32], open: f32, close: f32) -> Vec<f32> {
    let mut t = vec![open];
    t.extend(times.iter().copied().filter(|&x| x > open && x < close));
    t.push(close);
    t
}

/// The primitive at time `t`.
fn primitive_at(prim: &Primitive, t: f32) -> Primitive {
    let mut p = prim.clone();
    p.motion = None;
    if let Some(m) = &prim.motion {
        p.world_from_object = m.world_from_object_at(t).into();
        if let Some((g, v)) = m.shape_at(t) {
            p.geometry = g;
            p.primvars = v;
        }
    }
    p
}

/// The surfaces of primitive `index` over the shutter (see the module invariants).
pub fn surfaces_over_shutter(
    index: usize,
    prim: &Primitive,
    camera_from_world: Mat4,
    camera_motion: Option<&MotionTransform>,
    shutter: [f32; 2],
    raster_from_camera: Option<Mat4>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    if prim.motion.is_none() && camera_motion.is_none() {
        return crate::geom::surfaces_in_view(
            index,
            prim,
            camera_from_world,
            raster_from_camera,
            diags,
        );
    }
    let [open, close] = shutter;
    let cam_at = |t: f32| camera_motion.map_or(camera_from_world, |m| m.at(t));
    if !(open < close) {
        let p = primitive_at(prim, open);
        return crate::geom::surfaces_in_view(index, &p, cam_at(open), raster_from_camera, diags);
    }
    let mut times: Vec<f32> = Vec::new();
    if let Some(m) = &prim.motion {
        times.extend(&m.times);
    }
    if let Some(c) = camera_motion {
        times.extend(&c.times);
    }
    times.sort_by(f32::total_cmp);
    times.dedup();
    let times = shutter_times(&times, open, close);
    let keys: Vec<MotionKey> = times
        .iter()
        .map(|&t| MotionKey {
            prim: primitive_at(prim, t),
            camera_from_world: cam_at(t),
        })
        .collect();
    let deforming = prim.motion.as_ref().is_some_and(|m| !m.shapes.is_empty())
        && keys.iter().any(|k| {
            k.prim.geometry != keys[0].prim.geometry || k.prim.primvars != keys[0].prim.primvars
        });
    let m0 = keys[0].camera_from_world * *keys[0].prim.world_from_object;
    let rigid_still = keys
        .iter()
        .all(|k| k.camera_from_world * *k.prim.world_from_object == m0);
    if !deforming && rigid_still {
        return crate::geom::surfaces_for(index, &keys[0].prim, keys[0].camera_from_world, diags);
    }
    let span = close - open;
    let norm: Vec<f32> = times.iter().map(|&t| (t - open) / span).collect();
    moving_surfaces(index, &norm, &keys, deforming, diags)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_span_the_shutter() {
        assert_eq!(shutter_times(&[0.0, 1.0], 0.0, 1.0), vec![0.0, 1.0]);
        assert_eq!(
            shutter_times(&[0.0, 0.5, 1.0], 0.25, 0.75),
            vec![0.25, 0.5, 0.75]
        );
        assert_eq!(shutter_times(&[0.0, 1.0], 0.2, 0.4), vec![0.2, 0.4]);
    }
}
