//! Geometry: primitives, bounding, splitting and dicing into shading grids.
//!
//! Input: a built [`crate::scene::Primitive`] and the camera transform.
//! Output: [`Surface`]s in camera space that bound, split and dice into [`crate::shade::Grid`]s.
//! Invariants: dicing decisions depend only on the surface and the camera (never on the bucket
//! or thread); split children lie inside their parent's bound.

use glam::Vec3;

use crate::shade::Grid;

/// An axis-aligned box in camera space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bound {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bound {
    pub const EMPTY: Bound = Bound {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };
    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Bound {
        let mut b = Bound::EMPTY;
        for p in points {
            b.min = b.min.min(p);
            b.max = b.max.max(p);
        }
        b
    }
    pub fn union(self, o: Bound) -> Bound {
        Bound {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }
    pub fn grow(self, d: f32) -> Bound {
        Bound {
            min: self.min - Vec3::splat(d),
            max: self.max + Vec3::splat(d),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }
    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }
}

/// A piece of geometry in camera space that REYES can bound, split and dice.
pub trait Surface: Send + Sync + std::fmt::Debug {
    /// Camera-space bound (before displacement; the caller widens it by the displacement bound).
    fn bound(&self) -> Bound;
    /// Splits into smaller pieces (in parameter space for parametric surfaces), each inside
    /// this surface's bound.
    fn split(&self) -> Vec<Box<dyn Surface>>;
    /// False when the surface must be split before it can be diced (e.g. a whole mesh).
    fn diceable(&self) -> bool {
        true
    }
    /// Dices into a grid of `nu × nv` points (nu, nv ≥ 2) with every standard global and
    /// primitive variable filled in camera space.
    fn dice(&self, nu: usize, nv: usize) -> Grid;
    /// The primitive this surface came from (an index into `Scene::primitives`).
    fn primitive(&self) -> usize;
}
