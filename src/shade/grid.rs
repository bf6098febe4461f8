//! The shading grid: what the dicer produces and shaders run over.
//!
//! Input: a diced surface patch of `nu × nv` points (point `(i, j)` at index `j * nu + i`,
//! `u` increasing with `i`, `v` with `j`).
//! Output: after shading, `ci`/`oi` (and output variables in `outputs`) per point.
//! Invariants: every per-point vector has exactly `nu * nv` entries; all positions, normals and
//! vectors are in camera space ("current" space, as RenderMan shades); `du`/`dv` are the
//! parametric steps between neighbouring points.

use glam::Vec3;

use crate::scene::ParamType;

/// A primitive variable (or shader output) carried on a grid.
#[derive(Clone, Debug)]
pub struct GridVar {
    pub name: String,
    pub ty: ParamType,
    pub array_len: usize,
    /// True when one value serves the whole grid (constant/uniform class).
    pub uniform: bool,
    /// Flattened: `width` numbers per point (or just `width` when uniform).
    pub floats: Vec<f32>,
    /// String values (uniform only).
    pub strings: Vec<String>,
}

impl GridVar {
    pub fn width(&self) -> usize {
        self.ty.components() * self.array_len
    }

    /// The values at points `idx` (a uniform variable is kept whole).
    pub fn pick(&self, idx: &[usize]) -> GridVar {
        if self.uniform {
            return self.clone();
        }
        let w = self.width();
        let mut floats = Vec::with_capacity(idx.len() * w);
        for &i in idx {
            floats.extend_from_slice(&self.floats[i * w..(i + 1) * w]);
        }
        GridVar {
            name: self.name.clone(),
            ty: self.ty,
            array_len: self.array_len,
            uniform: false,
            floats,
            strings: Vec::new(),
        }
    }
}

#[derive(Clone, Debug, Default)]
pub struct Grid {
    pub nu: usize,
    pub nv: usize,
    pub p: Vec<Vec3>,
    pub n: Vec<Vec3>,
    pub ng: Vec<Vec3>,
    pub dpdu: Vec<Vec3>,
    pub dpdv: Vec<Vec3>,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub s: Vec<f32>,
    pub t: Vec<f32>,
    pub du: f32,
    pub dv: f32,
    pub cs: Vec<Vec3>,
    pub os: Vec<Vec3>,
    /// Incident ray direction P − E (E is the origin for perspective views; for orthographic
    /// views I is (0,0,1) scaled to reach P).
    pub i: Vec<Vec3>,
    pub ci: Vec<Vec3>,
    pub oi: Vec<Vec3>,
    /// Primitive variables other than the standard ones, bound to shader parameters by name.
    pub primvars: Vec<GridVar>,
    /// Shader output variables after shading (for arbitrary output variables in Display).
    pub outputs: Vec<GridVar>,
    /// The displacement shader's output parameters after it ran, for the surface shader's
    /// message passing (`displacement("name", var)`, RISpec §15.8).
    pub displacement_outputs: Vec<GridVar>,
    /// Motion blur: the grid's positions at each key over the shutter (None when still).
    pub motion: Option<Box<GridMotion>>,
}

/// Where a moving grid's points are over the shutter: `p[k][i]` is point `i` at `times[k]`
/// (times normalised to the shutter: first 0, last 1). Key 0 is where the grid is shaded.
#[derive(Clone, Debug, Default)]
pub struct GridMotion {
    pub times: Vec<f32>,
    pub p: Vec<Vec<Vec3>>,
}

impl Grid {
    pub fn len(&self) -> usize {
        self.nu * self.nv
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// A grid of `nu × nv` points with every per-point field sized and zeroed
    /// (Cs and Os white, Oi opaque). Its columns come from this thread's buffer pool
    /// ([`crate::pool`]); [`Grid::recycle`] gives them back.
    pub fn with_size(nu: usize, nv: usize) -> Grid {
        use crate::pool::filled;
        let n = nu * nv;
        Grid {
            nu,
            nv,
            p: filled(n, Vec3::ZERO),
            n: filled(n, Vec3::ZERO),
            ng: filled(n, Vec3::ZERO),
            dpdu: filled(n, Vec3::ZERO),
            dpdv: filled(n, Vec3::ZERO),
            u: filled(n, 0.0),
            v: filled(n, 0.0),
            s: filled(n, 0.0),
            t: filled(n, 0.0),
            du: 0.0,
            dv: 0.0,
            cs: filled(n, Vec3::ONE),
            os: filled(n, Vec3::ONE),
            i: filled(n, Vec3::ZERO),
            ci: filled(n, Vec3::ZERO),
            oi: filled(n, Vec3::ONE),
            primvars: Vec::new(),
            outputs: Vec::new(),
            displacement_outputs: Vec::new(),
            motion: None,
        }
    }
    /// The points at `idx` as a `len × 1` grid (every per-point field and varying primitive
    /// variable picked, uniform ones kept). Neighbours in the result are unrelated points, so
    /// it serves runs that take no derivatives (lights evaluated for a volume march's live
    /// points); motion is dropped.
    pub fn subset(&self, idx: &[usize]) -> Grid {
        // From this thread's buffer pool (the caller gives them back with
        // [`Grid::recycle`]), not fresh allocations.
        fn pick<T: Copy>(v: &[T], idx: &[usize], buffer: fn(usize) -> Vec<T>) -> Vec<T> {
            if v.is_empty() {
                return Vec::new();
            }
            let mut out = buffer(idx.len());
            for (o, &i) in out.iter_mut().zip(idx) {
                *o = v[i];
            }
            out
        }
        use crate::shade::value::{grid_vf, grid_vt};
        let pick_t = |v: &[Vec3]| pick(v, idx, grid_vt);
        let pick_f = |v: &[f32]| pick(v, idx, grid_vf);
        let pick_var = |g: &GridVar| g.pick(idx);
        Grid {
            nu: idx.len(),
            nv: 1,
            p: pick_t(&self.p),
            n: pick_t(&self.n),
            ng: pick_t(&self.ng),
            dpdu: pick_t(&self.dpdu),
            dpdv: pick_t(&self.dpdv),
            u: pick_f(&self.u),
            v: pick_f(&self.v),
            s: pick_f(&self.s),
            t: pick_f(&self.t),
            du: self.du,
            dv: self.dv,
            cs: pick_t(&self.cs),
            os: pick_t(&self.os),
            i: pick_t(&self.i),
            ci: pick_t(&self.ci),
            oi: pick_t(&self.oi),
            primvars: self.primvars.iter().map(pick_var).collect(),
            outputs: Vec::new(),
            displacement_outputs: self.displacement_outputs.iter().map(pick_var).collect(),
            motion: None,
        }
    }
    /// Gives the per-point columns back to this thread's buffer pool (a [`Grid::subset`]
    /// made for one run, a diced grid once shaded).
    pub fn recycle(self) {
        use crate::pool::give;
        for v in [self.p, self.n, self.ng, self.dpdu, self.dpdv] {
            give(v);
        }
        for v in [self.u, self.v, self.s, self.t] {
            give(v);
        }
        for v in [self.cs, self.os, self.i, self.ci, self.oi] {
            give(v);
        }
    }
    pub fn primvar(&self, name: &str) -> Option<&GridVar> {
        self.primvars.iter().find(|v| v.name == name)
    }
    pub fn output(&self, name: &str) -> Option<&GridVar> {
        self.outputs.iter().find(|v| v.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recycled_grids_columns_serve_the_next_grid_freshly_filled() {
        let mut g = Grid::with_size(20, 20);
        let old: Vec<*const Vec3> = [&g.p, &g.n, &g.cs, &g.oi].map(|c| c.as_ptr()).to_vec();
        for c in [&mut g.p, &mut g.n, &mut g.cs, &mut g.oi] {
            c.fill(Vec3::splat(7.0));
        }
        g.u.fill(7.0);
        g.recycle();
        let h = Grid::with_size(19, 21);
        // The same memory (this thread's pool), none of the old values.
        let new = [
            &h.p, &h.n, &h.ng, &h.dpdu, &h.dpdv, &h.cs, &h.os, &h.i, &h.ci, &h.oi,
        ];
        assert!(old.iter().all(|p| new.iter().any(|c| c.as_ptr() == *p)));
        for (c, want) in new.iter().zip([0., 0., 0., 0., 0., 1., 1., 0., 0., 1.]) {
            assert_eq!(c.len(), 19 * 21);
            assert!(c.iter().all(|v| *v == Vec3::splat(want)));
        }
        assert!(h.u.iter().all(|v| *v == 0.0));
    }
}
