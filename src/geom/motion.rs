//! Moving surfaces (motion blur): a surface at several keys over the shutter.
//!
//! Input: a primitive's keys in camera space — one primitive per key with its
//! camera_from_object — and the keys' times normalised to the shutter (first 0, last 1).
//! Output: [`MovingSurface`]s that bound, split and dice like any surface; their grids are
//! the shutter-open key's (shaded there, as RISpec says) carrying every key's positions in
//! [`GridMotion`].
//! Invariants: the bound covers every key (positions move linearly between keys, so they
//! stay inside the union of the keys' bounds); every key splits and dices the same way as
//! the shutter-open key, so grid point `i` is the same surface point at every key. A rigid
//! motion (only transforms move) keeps one surface and per-key matrices; a deformation keeps
//! one surface per key, split in lockstep.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::{Diag, Diagnostics};
use crate::scene::{Geometry, Primitive};
use crate::shade::grid::GridMotion;
use crate::shade::Grid;

use super::{Bound, Surface};

#[derive(Debug)]
enum Keys {
    /// One surface (at key 0) and camera_from_camera0 per key (key 0 the identity).
    Rigid {
        surface: Box<dyn Surface>,
        deltas: Arc<Vec<Mat4>>,
    },
    /// One surface per key, the same piece of the same primitive.
    Deforming(Vec<Box<dyn Surface>>),
}

/// A surface that moves during the shutter.
#[derive(Debug)]
pub struct MovingSurface {
    times: Arc<Vec<f32>>,
    keys: Keys,
}

impl MovingSurface {
    fn key0(&self) -> &dyn Surface {
        match &self.keys {
            Keys::Rigid { surface, .. } => surface.as_ref(),
            Keys::Deforming(k) => k[0].as_ref(),
        }
    }
}

impl Surface for MovingSurface {
    fn bound(&self) -> Bound {
        match &self.keys {
            Keys::Rigid { surface, deltas } => {
                let b = surface.bound();
                if b.is_empty() {
                    return b;
                }
                let corners = b.corners();
                let mut out = b;
                for d in deltas.iter().skip(1) {
                    out = out.union(Bound::from_points(
                        corners.iter().map(|&c| d.transform_point3(c)),
                    ));
                }
                super::pad_transformed(out)
            }
            Keys::Deforming(k) => k.iter().fold(Bound::EMPTY, |b, s| b.union(s.bound())),
        }
    }

    fn split(&self) -> Vec<Box<dyn Surface>> {
        let wrap = |keys: Keys| -> Box<dyn Surface> {
            Box::new(MovingSurface {
                times: self.times.clone(),
                keys,
            })
        };
        match &self.keys {
            Keys::Rigid { surface, deltas } => surface
                .split()
                .into_iter()
                .map(|s| {
                    wrap(Keys::Rigid {
                        surface: s,
                        deltas: deltas.clone(),
                    })
                })
                .collect(),
            Keys::Deforming(k) => {
                let choice = k[0].split_choice();
                let parts: Vec<Vec<Box<dyn Surface>>> =
                    k.iter().map(|s| s.split_as(choice)).collect();
                let n = parts[0].len();
                if parts.iter().any(|p| p.len() != n) {
                    // The keys came apart differently: keep the shutter-open key still.
                    return parts.into_iter().next().unwrap_or_default();
                }
                let mut columns: Vec<Vec<Box<dyn Surface>>> =
                    (0..n).map(|_| Vec::with_capacity(k.len())).collect();
                for key in parts {
                    for (c, s) in key.into_iter().enumerate() {
                        columns[c].push(s);
                    }
                }
                columns
                    .into_iter()
                    .map(|c| wrap(Keys::Deforming(c)))
                    .collect()
            }
        }
    }

    fn diceable(&self) -> bool {
        self.key0().diceable()
    }

    fn splittable(&self) -> bool {
        self.key0().splittable()
    }

    fn dice(&self, nu: usize, nv: usize) -> Grid {
        let mut g = self.key0().dice(nu, nv);
        let p: Vec<Vec<Vec3>> = match &self.keys {
            Keys::Rigid { deltas, .. } => deltas
                .iter()
                .enumerate()
                .map(|(k, d)| {
                    if k == 0 {
                        g.p.clone()
                    } else {
                        g.p.iter().map(|&q| d.transform_point3(q)).collect()
                    }
                })
                .collect(),
            Keys::Deforming(keys) => {
                let mut out = vec![g.p.clone()];
                for s in &keys[1..] {
                    let gk = s.dice(nu, nv);
                    if gk.p.len() != g.p.len() || gk.nu != g.nu {
                        return g; // cannot happen for lockstep keys; stay still if it does
                    }
                    out.push(gk.p);
                }
                out
            }
        };
        g.motion = Some(Box::new(GridMotion {
            times: self.times.to_vec(),
            p,
        }));
        g
    }

    fn primitive(&self) -> usize {
        self.key0().primitive()
    }

    fn raster_lengths(&self, raster_from_camera: &Mat4) -> Option<(f32, f32)> {
        self.key0().raster_lengths(raster_from_camera)
    }

    fn split_choice(&self) -> u8 {
        self.key0().split_choice()
    }

    fn still_bound(&self) -> Bound {
        self.key0().bound()
    }
}

/// One key of a moving primitive: the primitive at that time (its transform, geometry and
/// primitive variables) and the camera at that time.
#[derive(Clone, Debug)]
pub struct MotionKey {
    pub prim: Primitive,
    pub camera_from_world: Mat4,
}

/// The surfaces of a moving primitive: `times` (normalised, first 0, last 1) and one key per
/// time; `deforming` when the keys' geometry differs (otherwise only transforms move).
pub fn moving_surfaces(
    index: usize,
    times: &[f32],
    keys: &[MotionKey],
    deforming: bool,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let Some(k0) = keys.first() else {
        return Vec::new();
    };
    let times = Arc::new(times.to_vec());
    let m0 = k0.camera_from_world * *k0.prim.world_from_object;
    if !deforming {
        let base = super::surfaces_for(index, &k0.prim, k0.camera_from_world, diags);
        if !m0.is_finite() || m0.determinant() == 0.0 {
            return base;
        }
        let inv = m0.inverse();
        let deltas = Arc::new(
            keys.iter()
                .map(|k| k.camera_from_world * *k.prim.world_from_object * inv)
                .collect::<Vec<_>>(),
        );
        return base
            .into_iter()
            .map(|surface| -> Box<dyn Surface> {
                Box::new(MovingSurface {
                    times: times.clone(),
                    keys: Keys::Rigid {
                        surface,
                        deltas: deltas.clone(),
                    },
                })
            })
            .collect();
    }
    // Deforming meshes are cut into patches as the shutter-open key is.
    let decomp = match &*k0.prim.geometry {
        Geometry::Polygons { .. } => {
            let pv = &k0.prim.primvars;
            let obj: Option<Vec<Vec3>> = pv
                .floats("P")
                .filter(|f| !f.is_empty())
                .map(|p| p.chunks_exact(3).map(Vec3::from_slice).collect())
                .or_else(|| {
                    pv.floats("Pw").filter(|f| !f.is_empty()).map(|p| {
                        p.chunks_exact(4)
                            .map(|c| {
                                Vec3::new(c[0], c[1], c[2]) / if c[3] != 0.0 { c[3] } else { 1.0 }
                            })
                            .collect()
                    })
                });
            obj.map(|o| Arc::new(o.iter().map(|&p| m0.transform_point3(p)).collect()))
        }
        _ => None,
    };
    let lists: Vec<Vec<Box<dyn Surface>>> = keys
        .iter()
        .map(|k| super::surfaces_cut_as(index, &k.prim, k.camera_from_world, decomp.clone(), diags))
        .collect();
    let n = lists[0].len();
    if lists.iter().any(|l| l.len() != n) {
        diags.report(
            Diag::warning(
                "render::motion",
                "the keys of a deforming primitive do not have the same pieces; it is rendered without motion",
            )
            .label(k0.prim.span, "this primitive"),
        );
        return lists.into_iter().next().unwrap_or_default();
    }
    let mut columns: Vec<Vec<Box<dyn Surface>>> =
        (0..n).map(|_| Vec::with_capacity(keys.len())).collect();
    for list in lists {
        for (c, s) in list.into_iter().enumerate() {
            columns[c].push(s);
        }
    }
    columns
        .into_iter()
        .map(|c| -> Box<dyn Surface> {
            Box::new(MovingSurface {
                times: times.clone(),
                keys: Keys::Deforming(c),
            })
        })
        .collect()
}
