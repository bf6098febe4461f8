//! Geometry: primitives, bounding, splitting and dicing into shading grids.
//!
//! Input: a built [`crate::scene::Primitive`] and the camera transform.
//! Output: [`Surface`]s in camera space that bound, split and dice into [`crate::shade::Grid`]s.
//! Invariants: dicing decisions depend only on the surface and the camera (never on the bucket
//! or thread); split children lie inside their parent's bound.
//!
//! Orientation (RISpec §4.2.14, §5): camera space is left-handed. The geometric normal Ng is
//! `dPdu × dPdv` (for polygons the Newell normal, i.e. `(p1 − p0) × (p2 − p0)` for a convex
//! outline) computed in camera coordinates, negated when `camera_from_object` has a negative
//! determinant (so it is the object-space normal carried to camera space as a normal) and
//! negated again when `Attributes::reverse_orientation` is set (the builder's "orientation does
//! not match the transform"). So with the defaults quadric normals point outward (away from z)
//! and a polygon whose vertices run clockwise as seen from the camera faces the camera. User
//! "N" values are transformed by the inverse transpose and are not flipped.
//!
//! Files: `quadric` (the seven quadrics), `polygon` (meshes), `triangulate` (ear clipping),
//! `patch` (the parametric patch both dice through), `primvar` (primitive variables),
//! `patches` (Patch/PatchMesh/NuPatch/teapot into `bezier` pieces), `spline` (basis and knot
//! mathematics), `trim` (trim curves), `teapot` (Newell's data), `blobby` (implicit surfaces
//! polygonised into meshes).

mod bezier;
mod blobby;
mod curves;
pub mod motion;
mod patch;
mod patches;
mod points;
mod polygon;
mod primvar;
mod quadric;
pub mod spline;
mod subdiv;
mod teapot;
mod terrain;
#[cfg(test)]
mod tests;
mod triangulate;
mod trim;

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use crate::diag::{Diag, Diagnostics};
use crate::scene::{Geometry, Primitive};
use crate::shade::Grid;

pub use bezier::BezierPatch;
pub use patch::ParamPatch;
pub use patches::teapot_patches;
pub use polygon::Mesh;
pub use triangulate::triangulate;

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
    /// False when [`Surface::split`] cannot make it smaller (a lone point of a `Points`
    /// primitive): such a surface is diced however large it is on screen, at a coarser rate
    /// that fits the grid size limit, instead of being split until the driver drops it.
    fn splittable(&self) -> bool {
        true
    }
    /// Dices into a grid of `nu × nv` points (nu, nv ≥ 2) with every standard global and
    /// primitive variable filled in camera space.
    fn dice(&self, nu: usize, nv: usize) -> Grid;
    /// The primitive this surface came from (an index into `Scene::primitives`).
    fn primitive(&self) -> usize;
    /// Which points of `grid` (diced from this surface) trim curves cut away; `None` when
    /// none are. Dicing gives them opacity 0, but shaders still run there and an atmosphere
    /// adds its colour even at opacity 0, so the hider drops what they wrote.
    fn trimmed(&self, grid: &Grid) -> Option<Vec<bool>> {
        let _ = grid;
        None
    }
    /// Approximate lengths of the surface along u and along v after `raster_from_camera` and
    /// the perspective divide (the longest u-line and v-line of a 5 × 5 sample), for choosing
    /// dice rates (`nu ≈ lu / sqrt(ShadingRate)`). None when unknown, or when a sample point is
    /// at or behind the eye plane (split first).
    fn raster_lengths(&self, raster_from_camera: &Mat4) -> Option<(f32, f32)> {
        let _ = raster_from_camera;
        None
    }
    /// The bound at shutter open (a moving surface's `bound` covers its whole motion).
    fn still_bound(&self) -> Bound {
        self.bound()
    }
    /// How [`Surface::split`] would split this surface, as a small number (motion blur: the
    /// other keys of a deforming surface split the way its shutter-open key does).
    fn split_choice(&self) -> u8 {
        0
    }
    /// Splits the way `choice` (from [`Surface::split_choice`] of another key) says.
    fn split_as(&self, choice: u8) -> Vec<Box<dyn Surface>> {
        let _ = choice;
        self.split()
    }
}

/// Grows a bound by a small multiple of its coordinates' size so that floating-point rounding in
/// children's bounds never pokes out of their parent's (children have smaller coordinates, so a
/// smaller pad). Each axis by its own size: a surface's camera-space points are split and
/// evaluated axis by axis, so rounding in x never involves z. (One pad from the largest
/// coordinate widened a patch with a point at z = 1e8 by ±1000 in x and y, and under an
/// orthographic camera its pieces never shrank: 2^32 splits.)
pub(crate) fn pad(b: Bound) -> Bound {
    if b.is_empty() {
        return b;
    }
    let s = b.min.abs().max(b.max.abs()) * 1e-5 + Vec3::splat(1e-12);
    Bound {
        min: b.min - s,
        max: b.max + s,
    }
}

/// [`pad`] for a bound whose corners went through a matrix: rounding in each camera axis then
/// involves every coordinate, so every axis is grown by the largest.
pub(crate) fn pad_transformed(b: Bound) -> Bound {
    if b.is_empty() {
        return b;
    }
    let s = b.min.abs().max(b.max.abs()).max_element();
    b.grow(s * 1e-5 + 1e-12)
}

/// The surfaces of one primitive, in camera space. `index` is the primitive's index in
/// `Scene::primitives` (returned by [`Surface::primitive`]). Geometry kinds not handled here
/// are reported once as warnings and produce nothing; bad data is reported as errors.
pub fn surfaces_for(
    index: usize,
    prim: &Primitive,
    camera_from_world: Mat4,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    surfaces_full(index, prim, camera_from_world, None, None, diags)
}

/// [`surfaces_for`], polygon faces cut into patches as camera-space positions `decomp`
/// would cut them (one key of a deforming mesh; see [`motion`]).
pub(crate) fn surfaces_cut_as(
    index: usize,
    prim: &Primitive,
    camera_from_world: Mat4,
    decomp: Option<Arc<Vec<Vec3>>>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    surfaces_full(index, prim, camera_from_world, None, decomp, diags)
}

/// [`surfaces_for`] knowing the frame's `raster_from_camera`: surfaces whose tessellation is
/// fixed before dicing (Blobby's polygonisation) size it from their extent on screen.
pub fn surfaces_in_view(
    index: usize,
    prim: &Primitive,
    camera_from_world: Mat4,
    raster_from_camera: Option<Mat4>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    surfaces_full(
        index,
        prim,
        camera_from_world,
        raster_from_camera,
        None,
        diags,
    )
}

fn surfaces_full(
    index: usize,
    prim: &Primitive,
    camera_from_world: Mat4,
    raster_from_camera: Option<Mat4>,
    decomp: Option<Arc<Vec<Vec3>>>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let m = camera_from_world * *prim.world_from_object;
    let invalid = |what: &str| {
        diags.report(
            Diag::error("geom::invalid", format!("{what}; the primitive is skipped"))
                .label(prim.span, "this primitive"),
        );
    };
    if !m.is_finite() {
        invalid("the primitive's transform is not finite");
        return Vec::new();
    }
    if m.determinant() == 0.0 {
        // Particle exporters write dead particles as `Scale 0 0 0`: legitimate, and nothing
        // to see, so a warning (PRMan renders them silently).
        diags.report(
            Diag::warning(
                "geom::singular",
                "the primitive's transform is singular (a zero scale flattens it); the primitive is skipped",
            )
            .label(prim.span, "this primitive"),
        );
        return Vec::new();
    }
    // Exporters (mtor, MayaMan) write camera matrices with ~1e-10 in the projective column:
    // only a bottom row that differs from (0 0 0 1) beyond float noise is projective.
    let r3 = m.row(3);
    if r3.truncate().abs().max_element() > 1e-6 || (r3.w - 1.0).abs() > 1e-5 {
        diags.report(
            Diag::warning(
                "geom::projective_transform",
                "a projective object transform (Perspective inside the world) is applied as affine",
            )
            .label(prim.span, "this primitive"),
        );
    }
    let flip = (m.determinant() < 0.0) != prim.attributes.reverse_orientation;
    // Patch, PatchMesh, NuPatch (with trim curves) and Geometry "teapot": Bézier pieces.
    if let Some(s) = patches::surfaces(index, prim, m, flip, diags) {
        return s;
    }
    use quadric::Profile;
    let deg = |a: f32| a.to_radians();
    let (profile, thetamax) = match &*prim.geometry {
        Geometry::Sphere {
            radius,
            zmin,
            zmax,
            thetamax,
        } => (Profile::sphere(*radius, *zmin, *zmax), *thetamax),
        Geometry::Cone {
            height,
            radius,
            thetamax,
        } => (
            Profile::Cone {
                h: *height,
                r: *radius,
            },
            *thetamax,
        ),
        Geometry::Cylinder {
            radius,
            zmin,
            zmax,
            thetamax,
        } => (
            Profile::Cylinder {
                r: *radius,
                z0: *zmin,
                z1: *zmax,
            },
            *thetamax,
        ),
        Geometry::Hyperboloid { p1, p2, thetamax } => {
            (Profile::Hyperboloid { p1: *p1, p2: *p2 }, *thetamax)
        }
        Geometry::Paraboloid {
            rmax,
            zmin,
            zmax,
            thetamax,
        } => (
            Profile::Paraboloid {
                rmax: *rmax,
                z0: *zmin,
                z1: *zmax,
                zmax: *zmax,
            },
            *thetamax,
        ),
        Geometry::Disk {
            height,
            radius,
            thetamax,
        } => (
            Profile::Disk {
                h: *height,
                r: *radius,
            },
            *thetamax,
        ),
        Geometry::Torus {
            rmajor,
            rminor,
            phimin,
            phimax,
            thetamax,
        } => (
            Profile::Torus {
                rmaj: *rmajor,
                rmin: *rminor,
                phi0: deg(*phimin),
                phi1: deg(*phimax),
            },
            *thetamax,
        ),
        Geometry::Polygons {
            nloops,
            nverts,
            verts,
            nvertices,
        } => {
            return polygons_cut_as(
                index,
                prim,
                m,
                flip,
                (nloops, nverts, verts, *nvertices),
                decomp,
                diags,
            )
        }
        Geometry::SubdivisionMesh {
            scheme,
            nverts,
            verts,
            tags,
            nargs,
            intargs,
            floatargs,
        } => {
            let args = subdiv::SubdivArgs {
                scheme,
                nverts,
                verts,
                tags,
                nargs,
                intargs,
                floatargs,
            };
            return subdiv::subdivision(index, prim, m, flip, args, diags);
        }
        Geometry::Points { npoints } => return points::points(index, prim, m, *npoints, diags),
        Geometry::Curves {
            cubic,
            nverts,
            periodic,
            v_basis,
        } => {
            let args = curves::CurveArgs {
                cubic: *cubic,
                nverts,
                periodic: *periodic,
                basis: *v_basis,
            };
            return curves::curves(index, prim, m, flip, args, diags);
        }
        Geometry::Blobby(program) => {
            return blobby::surfaces(index, prim, program, m, raster_from_camera, diags);
        }
        Geometry::Named { name } if name == "fractalterrain" => {
            return terrain::surfaces(index, prim, m, flip, diags);
        }
        other => {
            let name = match other {
                Geometry::PatchMesh { .. } => "Patch/PatchMesh",
                Geometry::NuPatch { .. } => "NuPatch",
                Geometry::SubdivisionMesh { .. } => "SubdivisionMesh",
                Geometry::Points { .. } => "Points",
                Geometry::Curves { .. } => "Curves",
                Geometry::Named { name } => name.as_str(),
                _ => "this geometry",
            };
            diags.report(
                Diag::warning(
                    "geom::unsupported",
                    format!("{name} is not rendered yet; it is skipped"),
                )
                .label(prim.span, "not rendered"),
            );
            return Vec::new();
        }
    };
    let thetamax = deg(thetamax);
    let q = quadric::Quadric {
        profile,
        thetamax,
        camera_from_object: m,
        flip,
    };
    let (c0, dc0) = profile.eval(0.0);
    let (c1, dc1) = profile.eval(1.0);
    if ![c0, dc0, c1, dc1].iter().all(|v| v.is_finite()) || !thetamax.is_finite() {
        invalid("the quadric's parameters are not finite");
        return Vec::new();
    }
    if thetamax == 0.0 || (dc0 == Vec3::ZERO && dc1 == Vec3::ZERO) {
        return Vec::new(); // zero area: nothing to render
    }
    let counts = primvar::ClassCounts {
        uniform: 1,
        varying: 4,
        facevarying: 4,
    };
    let vars = primvar::resolve(&prim.primvars, m, counts, diags);
    let a = &prim.attributes;
    let tc = a.texture_coordinates;
    let defaults = primvar::Defaults {
        s: [tc[0], tc[2], tc[4], tc[6]],
        t: [tc[1], tc[3], tc[5], tc[7]],
        color: a.color,
        opacity: a.opacity,
    };
    let pv = primvar::patch_vars(&vars, &primvar::Selector::QUADRIC, &defaults);
    vec![Box::new(ParamPatch::new(
        index,
        patch::Shape::Quadric(q),
        pv,
    ))]
}

type PolyTopology<'a> = (&'a [u32], &'a [u32], &'a [u32], usize);

fn polygons(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    (nloops, nverts, verts, nvertices): PolyTopology,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    polygons_cut_as(
        index,
        prim,
        m,
        flip,
        (nloops, nverts, verts, nvertices),
        None,
        diags,
    )
}

/// [`polygons`], with faces cut into patches as positions `decomp` would cut them (motion
/// blur: every key of a deforming mesh is cut as its shutter-open key).
pub(crate) fn polygons_cut_as(
    index: usize,
    prim: &Primitive,
    m: Mat4,
    flip: bool,
    (nloops, nverts, verts, nvertices): PolyTopology,
    decomp: Option<Arc<Vec<Vec3>>>,
    diags: &Diagnostics,
) -> Vec<Box<dyn Surface>> {
    let err = |msg: String| {
        diags.report(
            Diag::error("geom::invalid", msg)
                .label(prim.span, "this polygon")
                .help("check the vertex counts and indices against \"P\""),
        );
    };
    // Object-space positions from "P", or "Pw" divided by w.
    let obj: Vec<Vec3> = if let Some(p) = prim.primvars.floats("P").filter(|f| !f.is_empty()) {
        p.chunks_exact(3).map(Vec3::from_slice).collect()
    } else if let Some(p) = prim.primvars.floats("Pw").filter(|f| !f.is_empty()) {
        p.chunks_exact(4)
            .map(|c| Vec3::new(c[0], c[1], c[2]) / if c[3] != 0.0 { c[3] } else { 1.0 })
            .collect()
    } else {
        err("a polygon needs \"P\" (or \"Pw\"); the primitive is skipped".into());
        return Vec::new();
    };
    let limit = if nvertices > 0 {
        nvertices.min(obj.len())
    } else {
        obj.len()
    };
    // Per-face prefix sums, stopping at the first face the arrays cannot hold.
    let mut loop_start = vec![0usize];
    let mut fv_start = vec![0usize];
    let mut valid = Vec::with_capacity(nloops.len());
    let (mut l, mut fv) = (0usize, 0usize);
    for &nl in nloops {
        let nl = nl as usize;
        if l + nl > nverts.len() {
            err(format!(
                "{} faces need more loop counts than the {} given",
                nloops.len(),
                nverts.len()
            ));
            break;
        }
        let n: usize = nverts[l..l + nl].iter().map(|&n| n as usize).sum();
        if fv + n > verts.len() {
            err(format!(
                "the faces need more vertex indices than the {} given",
                verts.len()
            ));
            break;
        }
        let ok = verts[fv..fv + n].iter().all(|&v| (v as usize) < limit);
        if !ok {
            err(format!(
                "a face uses a vertex index beyond the {limit} vertices of \"P\""
            ));
        }
        valid.push(ok);
        l += nl;
        fv += n;
        loop_start.push(l);
        fv_start.push(fv);
    }
    let nfaces = valid.len();
    if nfaces == 0 {
        return Vec::new();
    }
    let counts = primvar::ClassCounts {
        uniform: nfaces,
        varying: limit,
        facevarying: fv,
    };
    let vars = primvar::resolve(&prim.primvars, m, counts, diags);
    let data = polygon::MeshData {
        index,
        p: obj[..limit]
            .iter()
            .map(|&p| m.transform_point3(p))
            .collect(),
        obj_xy: obj[..limit].iter().map(|p| Vec2::new(p.x, p.y)).collect(),
        nverts: nverts.to_vec(),
        verts: verts.to_vec(),
        loop_start,
        fv_start,
        valid,
        vars,
        flip,
        color: prim.attributes.color,
        opacity: prim.attributes.opacity,
        split_triangles: prim.attributes.displacement.is_some(),
        decomp_p: decomp,
    };
    vec![Box::new(Mesh {
        data: Arc::new(data),
        faces: 0..nfaces,
    })]
}
