//! The built scene: plain data the renderer consumes, one [`Scene`] per frame.
//!
//! Invariants: geometry, primitive variables and shader parameters are stored as given, in the
//! space that was current when they were declared (object space for primitives, shader space
//! for shader parameters) together with the transform to world space; the renderer moves them
//! to camera space. Colours have 3 components (ColorSamples other than RGB are converted by the
//! builder). Every value count was validated by the builder.

use std::collections::HashMap;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::Span;

/// Storage class of a parameter or primitive variable (RISpec §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Class {
    Constant,
    Uniform,
    Varying,
    Vertex,
    FaceVarying,
    FaceVertex,
}

/// Type of a parameter or primitive variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamType {
    Float,
    Integer,
    String,
    Color,
    Point,
    Vector,
    Normal,
    HPoint,
    Matrix,
}

impl ParamType {
    /// Numbers per element (strings count 1).
    pub fn components(self) -> usize {
        match self {
            ParamType::Float | ParamType::Integer | ParamType::String => 1,
            ParamType::Color | ParamType::Point | ParamType::Vector | ParamType::Normal => 3,
            ParamType::HPoint => 4,
            ParamType::Matrix => 16,
        }
    }
}

/// A declaration: `"varying float[2] st"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Decl {
    pub class: Class,
    pub ty: ParamType,
    /// Array length; 1 for a plain value.
    pub array_len: usize,
}

impl Decl {
    /// Numbers (or strings) per element, including the array length.
    pub fn width(&self) -> usize {
        self.ty.components() * self.array_len
    }
}

/// The values of a parameter, flattened.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamData {
    Floats(Vec<f32>),
    Strings(Vec<String>),
}

impl ParamData {
    pub fn floats(&self) -> &[f32] {
        match self {
            ParamData::Floats(f) => f,
            ParamData::Strings(_) => &[],
        }
    }
    pub fn strings(&self) -> &[String] {
        match self {
            ParamData::Strings(s) => s,
            ParamData::Floats(_) => &[],
        }
    }
    pub fn len(&self) -> usize {
        match self {
            ParamData::Floats(f) => f.len(),
            ParamData::Strings(s) => s.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One entry of a parameter list, its declaration resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// The name; the common primitive variable and shader parameter names are static
    /// strings (no allocation per primitive), others are owned.
    pub name: ParamName,
    pub decl: Decl,
    pub data: ParamData,
    pub span: Span,
}

/// A parameter's name (see [`Param::name`]).
pub type ParamName = std::borrow::Cow<'static, str>;

/// `name` as a [`ParamName`]: a static string when it is one of the common names.
pub fn param_name(name: &str) -> ParamName {
    const COMMON: [&str; 24] = [
        "P",
        "Pw",
        "Pz",
        "N",
        "Np",
        "Cs",
        "Os",
        "s",
        "t",
        "st",
        "u",
        "v",
        "width",
        "constantwidth",
        "Ka",
        "Kd",
        "Ks",
        "roughness",
        "specularcolor",
        "intensity",
        "lightcolor",
        "from",
        "to",
        "texturename",
    ];
    match COMMON.iter().find(|c| **c == name) {
        Some(c) => std::borrow::Cow::Borrowed(c),
        None => std::borrow::Cow::Owned(name.to_string()),
    }
}

/// A parameter list (shader parameters or primitive variables).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamList(pub Vec<Param>);

impl ParamList {
    pub fn get(&self, name: &str) -> Option<&Param> {
        self.0.iter().find(|p| p.name == name)
    }
    pub fn floats(&self, name: &str) -> Option<&[f32]> {
        self.get(name).map(|p| p.data.floats())
    }
    pub fn float(&self, name: &str) -> Option<f32> {
        self.floats(name).and_then(|f| f.first().copied())
    }
    pub fn string(&self, name: &str) -> Option<&str> {
        self.get(name)
            .and_then(|p| p.data.strings().first().map(String::as_str))
    }
    pub fn iter(&self) -> impl Iterator<Item = &Param> {
        self.0.iter()
    }
}

/// A shader named by a request (Surface, LightSource, Imager, …) with its parameter values.
#[derive(Clone, Debug, PartialEq)]
pub struct ShaderRef {
    pub name: String,
    pub params: ParamList,
    /// The request that named it, for diagnostics.
    pub span: Span,
    /// "shader" space: the transform current when the shader was declared.
    pub world_from_shader: Mat4,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    Orthographic,
    Perspective { fov: f32 },
}

#[derive(Clone, Debug, PartialEq)]
pub struct PixelFilter {
    /// box, triangle, catmull-rom, gaussian, sinc, mitchell, disk, bessel.
    pub name: String,
    pub xwidth: f32,
    pub ywidth: f32,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantize {
    /// The value 0 maps to (PRMan's and Aqsis's display `"quantize" [zero one min max]`;
    /// RiQuantize has none, so 0): `round(zero + v·(one − zero) + dither)`. A display of
    /// normals writes `[128 255 0 255]` so that −1 lands on 1, not on 0.
    pub zero: f32,
    pub one: f32,
    pub min: f32,
    pub max: f32,
    pub dither: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Display {
    /// File name (the leading `+` removed).
    pub name: String,
    /// "file", "tiff", "png", "exr", "zfile", "shadow", "framebuffer", …
    pub kind: String,
    /// "rgb", "rgba", "z", "rgbaz", or an output variable name.
    pub mode: String,
    pub params: ParamList,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Hider {
    pub name: String,
    pub params: ParamList,
}

/// Search paths after `&` and `@` expansion, in search order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SearchPaths {
    pub shader: Vec<String>,
    pub texture: Vec<String>,
    pub archive: Vec<String>,
    pub procedural: Vec<String>,
}

/// Camera and image options (RISpec §4.1), with the spec's defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    pub xres: u32,
    pub yres: u32,
    pub pixel_aspect: f32,
    /// Set explicitly by FrameAspectRatio; otherwise follows Format.
    pub frame_aspect: Option<f32>,
    /// Set explicitly by ScreenWindow (left, right, bottom, top); otherwise follows the aspect.
    pub screen_window: Option<[f32; 4]>,
    /// xmin, xmax, ymin, ymax in NDC.
    pub crop_window: [f32; 4],
    pub projection: Projection,
    pub near: f32,
    pub far: f32,
    /// Clipping planes in world space: (point, normal); the +normal side is clipped.
    pub clipping_planes: Vec<(Vec3, Vec3)>,
    /// fstop, focal length, focal distance; None = pinhole.
    pub depth_of_field: Option<[f32; 3]>,
    pub shutter: [f32; 2],
    pub pixel_variance: Option<f32>,
    pub pixel_samples: [f32; 2],
    pub pixel_filter: PixelFilter,
    /// gain, gamma.
    pub exposure: [f32; 2],
    pub imager: Option<ShaderRef>,
    pub quantize_rgba: Quantize,
    pub quantize_z: Quantize,
    /// `Quantize` for other display variables (Aqsis: `Quantize "N" 0 0 0 0`), applied to
    /// displays of exactly that mode; later requests for a name replace earlier ones.
    pub quantize_named: Vec<(String, Quantize)>,
    pub displays: Vec<Display>,
    pub hider: Hider,
    pub relative_detail: f32,
    pub search_paths: SearchPaths,
    /// `Option` values not named above, keyed "category:name" (e.g. "limits:bucketsize").
    pub user: HashMap<String, Param>,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            xres: 640,
            yres: 480,
            pixel_aspect: 1.0,
            frame_aspect: None,
            screen_window: None,
            crop_window: [0.0, 1.0, 0.0, 1.0],
            projection: Projection::Orthographic,
            near: f32::EPSILON,
            far: f32::INFINITY,
            clipping_planes: Vec::new(),
            depth_of_field: None,
            shutter: [0.0, 0.0],
            pixel_variance: None,
            pixel_samples: [2.0, 2.0],
            pixel_filter: PixelFilter {
                name: "gaussian".into(),
                xwidth: 2.0,
                ywidth: 2.0,
            },
            exposure: [1.0, 1.0],
            imager: None,
            quantize_rgba: Quantize {
                zero: 0.0,
                one: 255.0,
                min: 0.0,
                max: 255.0,
                dither: 0.5,
            },
            quantize_z: Quantize {
                zero: 0.0,
                one: 0.0,
                min: 0.0,
                max: 0.0,
                dither: 0.0,
            },
            quantize_named: Vec::new(),
            displays: Vec::new(),
            hider: Hider {
                name: "hidden".into(),
                params: ParamList::default(),
            },
            relative_detail: 1.0,
            search_paths: SearchPaths::default(),
            user: HashMap::new(),
        }
    }
}

impl Options {
    /// The frame aspect ratio in force (FrameAspectRatio, else from Format).
    pub fn effective_frame_aspect(&self) -> f32 {
        self.frame_aspect
            .unwrap_or(self.xres as f32 * self.pixel_aspect / self.yres.max(1) as f32)
    }
    /// The screen window in force (ScreenWindow, else the spec's default from the aspect).
    pub fn effective_screen_window(&self) -> [f32; 4] {
        if let Some(w) = self.screen_window {
            return w;
        }
        let a = self.effective_frame_aspect();
        if a >= 1.0 {
            [-a, a, -1.0, 1.0]
        } else {
            [-1.0, 1.0, -1.0 / a, 1.0 / a]
        }
    }
    /// A numeric user option, e.g. `user_floats("limits:bucketsize")`.
    pub fn user_floats(&self, key: &str) -> Option<&[f32]> {
        self.user.get(key).map(|p| p.data.floats())
    }
}

/// Spline basis for bicubic patches: the 4×4 matrix (row-major as in RIB) and its step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Basis {
    pub matrix: [f32; 16],
    pub step: u32,
}

impl Basis {
    pub const BEZIER: Basis = Basis {
        matrix: [
            -1., 3., -3., 1., 3., -6., 3., 0., -3., 3., 0., 0., 1., 0., 0., 0.,
        ],
        step: 3,
    };
}

/// Shading attributes (RISpec §4.2) in force for a primitive.
///
/// Memory: the attributes that scenes change from one primitive to the next (colour,
/// opacity, surface and displacement shaders) are held here; every other attribute is in
/// [`AttributeState`], shared by `Arc` and reached through `Deref` (`a.shading_rate`), copied
/// only when one of them changes (`DerefMut`, copy on write). A million `Color`+`Polygon`
/// pairs thus cost a million small structs, not a million copies of the whole state.
#[derive(Clone, Debug, PartialEq)]
pub struct Attributes {
    pub color: Vec3,
    pub opacity: Vec3,
    pub surface: Option<Arc<ShaderRef>>,
    pub displacement: Option<Arc<ShaderRef>>,
    /// Everything else, shared (read through `Deref`, written through `DerefMut`).
    pub state: Arc<AttributeState>,
}

impl std::ops::Deref for Attributes {
    type Target = AttributeState;
    fn deref(&self) -> &AttributeState {
        &self.state
    }
}

impl std::ops::DerefMut for Attributes {
    /// Copies the shared state first when another primitive still holds it.
    fn deref_mut(&mut self) -> &mut AttributeState {
        Arc::make_mut(&mut self.state)
    }
}

impl Attributes {
    /// Attributes with these colour and opacity and every other attribute at its default.
    pub fn with_color(color: Vec3, opacity: Vec3) -> Attributes {
        Attributes {
            color,
            opacity,
            ..Attributes::default()
        }
    }
}

/// The attributes other than colour, opacity and the surface and displacement shaders (see
/// [`Attributes`]).
#[derive(Clone, Debug, PartialEq)]
pub struct AttributeState {
    /// s1 t1 s2 t2 s3 t3 s4 t4 for the parametric corners (0,0) (1,0) (0,1) (1,1).
    pub texture_coordinates: [f32; 8],
    pub atmosphere: Option<Arc<ShaderRef>>,
    pub interior: Option<Arc<ShaderRef>>,
    pub exterior: Option<Arc<ShaderRef>>,
    pub shading_rate: f32,
    /// ShadingInterpolation "smooth".
    pub smooth_shading: bool,
    pub matte: bool,
    pub bound: Option<[f32; 6]>,
    /// `Detail`: the bounding box given, as its eight corners in world space (the box is in
    /// the object space current at the `Detail` request).
    pub detail: Option<[Vec3; 8]>,
    /// `DetailRange`: minvisible, lowertransition, uppertransition, maxvisible.
    pub detail_range: [f32; 4],
    pub sides: u32,
    /// Orientation: true when the current orientation is "inside"/flipped relative to the
    /// handedness of the current transform (ReverseOrientation toggles it).
    pub reverse_orientation: bool,
    /// Attribute "displacementbound" "sphere" (in "coordinatesystem", default object).
    pub displacement_bound: f32,
    pub displacement_bound_space: String,
    pub identifier: Option<String>,
    pub u_basis: Basis,
    pub v_basis: Basis,
    /// Indices into `Scene::lights` of the lights switched on for this primitive.
    pub lights_on: Vec<usize>,
    /// `Attribute` values not named above, keyed "category:name".
    pub user: HashMap<String, Param>,
    /// GeometricApproximation "flatness" etc.
    pub geometric_approximation: HashMap<String, f32>,
    /// The innermost CSG solid (an index into `Scene::solids`) this primitive belongs to;
    /// None outside boolean solids (a top-level `SolidBegin "primitive"` renders as is).
    pub solid: Option<u32>,
    /// The area light (an index into `Scene::lights`) whose geometry this primitive is: set by
    /// `AreaLightSource` for the rest of its attribute block (RISpec §4.2.3).
    pub area_light: Option<usize>,
}

impl Default for Attributes {
    fn default() -> Attributes {
        thread_local! {
            /// One default state per thread, shared by every default `Attributes`.
            static DEFAULT: Arc<AttributeState> = Arc::new(AttributeState::default());
        }
        Attributes {
            color: Vec3::ONE,
            opacity: Vec3::ONE,
            surface: None,
            displacement: None,
            state: DEFAULT.with(Arc::clone),
        }
    }
}

impl Default for AttributeState {
    fn default() -> AttributeState {
        AttributeState {
            texture_coordinates: [0., 0., 1., 0., 0., 1., 1., 1.],
            atmosphere: None,
            interior: None,
            exterior: None,
            shading_rate: 1.0,
            smooth_shading: false,
            matte: false,
            bound: None,
            detail: None,
            detail_range: [0.0, 0.0, f32::INFINITY, f32::INFINITY],
            sides: 2,
            reverse_orientation: false,
            displacement_bound: 0.0,
            displacement_bound_space: "object".into(),
            identifier: None,
            u_basis: Basis::BEZIER,
            v_basis: Basis::BEZIER,
            lights_on: Vec::new(),
            user: HashMap::new(),
            geometric_approximation: HashMap::new(),
            solid: None,
            area_light: None,
        }
    }
}

/// A `SolidBegin` operation (RISpec §5.6).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolidOp {
    Primitive,
    Union,
    Intersection,
    Difference,
}

/// One `SolidBegin … SolidEnd` block inside a boolean solid; children are the nodes naming it
/// as parent, in the order they were opened (a difference keeps its first child and removes
/// the others).
#[derive(Clone, Debug, PartialEq)]
pub struct SolidNode {
    pub op: SolidOp,
    pub parent: Option<u32>,
    pub span: Span,
}

/// A light source (LightSource or AreaLightSource).
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    pub shader: Arc<ShaderRef>,
    /// The handle as written (an integer or a string).
    pub handle: String,
    pub area: bool,
    /// BMRT's `Attribute "light" "shadows" "on"` when the light was declared: the renderer
    /// traces a shadow ray for it at every lit point (whatever the light shader does).
    pub ray_shadows: bool,
    /// `Attribute "light" "nsamples"` when the light was declared (BMRT): points sampled on an
    /// area light's geometry per lit point (default 1).
    pub samples: u32,
}

/// Geometry as given by the request, in object space. Angles are in degrees as in RIB.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    Sphere {
        radius: f32,
        zmin: f32,
        zmax: f32,
        thetamax: f32,
    },
    Cone {
        height: f32,
        radius: f32,
        thetamax: f32,
    },
    Cylinder {
        radius: f32,
        zmin: f32,
        zmax: f32,
        thetamax: f32,
    },
    Hyperboloid {
        p1: Vec3,
        p2: Vec3,
        thetamax: f32,
    },
    Paraboloid {
        rmax: f32,
        zmin: f32,
        zmax: f32,
        thetamax: f32,
    },
    Disk {
        height: f32,
        radius: f32,
        thetamax: f32,
    },
    Torus {
        rmajor: f32,
        rminor: f32,
        phimin: f32,
        phimax: f32,
        thetamax: f32,
    },
    /// Polygon, GeneralPolygon, PointsPolygons and PointsGeneralPolygons in one form:
    /// per face the number of loops, per loop the number of vertices, then vertex indices.
    /// The first loop of a face is its outline, the others are holes.
    Polygons {
        nloops: Vec<u32>,
        nverts: Vec<u32>,
        verts: Vec<u32>,
        nvertices: usize,
    },
    /// Patch "bilinear"|"bicubic" and PatchMesh: control points in `primvars` ("P"/"Pw"/"Pz").
    PatchMesh {
        bicubic: bool,
        nu: usize,
        nv: usize,
        uperiodic: bool,
        vperiodic: bool,
        u_basis: Basis,
        v_basis: Basis,
    },
    NuPatch {
        nu: usize,
        uorder: usize,
        uknot: Vec<f32>,
        umin: f32,
        umax: f32,
        nv: usize,
        vorder: usize,
        vknot: Vec<f32>,
        vmin: f32,
        vmax: f32,
        trim: Option<Arc<TrimCurves>>,
    },
    SubdivisionMesh {
        scheme: String,
        nverts: Vec<u32>,
        verts: Vec<u32>,
        tags: Vec<String>,
        nargs: Vec<u32>,
        intargs: Vec<i64>,
        floatargs: Vec<f32>,
    },
    Points {
        npoints: usize,
    },
    Curves {
        cubic: bool,
        nverts: Vec<u32>,
        periodic: bool,
        v_basis: Basis,
    },
    /// `Blobby` (RISpec §5.7): the decoded field program.
    Blobby(Arc<super::blobby::BlobbyProgram>),
    /// `Geometry "name"` (teapot, fractalterrain, …) with its parameters.
    Named {
        name: String,
    },
}

/// TrimCurve data (RISpec §5.4).
#[derive(Clone, Debug, PartialEq)]
pub struct TrimCurves {
    pub ncurves: Vec<u32>,
    pub order: Vec<u32>,
    pub knot: Vec<f32>,
    pub min: Vec<f32>,
    pub max: Vec<f32>,
    pub n: Vec<u32>,
    pub u: Vec<f32>,
    pub v: Vec<f32>,
    pub w: Vec<f32>,
    /// Attribute "trimcurve" "sense": false = "inside" (default), true = "outside".
    pub sense_outside: bool,
}

/// One primitive ready to render.
#[derive(Clone, Debug)]
pub struct Primitive {
    pub geometry: Arc<Geometry>,
    /// Primitive variables (P, N, Cs, s, t, user variables), counts validated.
    pub primvars: Arc<ParamList>,
    pub attributes: Arc<Attributes>,
    /// Shared with the other primitives under the same transform (see [`Attributes`]).
    pub world_from_object: Arc<Mat4>,
    pub span: Span,
    /// Motion blur: keys over time from `MotionBegin` blocks around the primitive's
    /// transform and/or the primitive itself (None for a still primitive). The fields above
    /// hold the first key.
    pub motion: Option<Arc<Motion>>,
}

/// A primitive's motion: keys at increasing times (RISpec §5.8). Positions move linearly
/// between keys.
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    pub times: Vec<f32>,
    /// world_from_object at each time.
    pub world_from_object: Vec<Mat4>,
    /// Deformation: the primitive (same kind and shape) at each time; empty when only its
    /// transform moves.
    pub shapes: Vec<(Arc<Geometry>, Arc<ParamList>)>,
}

/// A transform given inside `MotionBegin`…`MotionEnd`: matrices at increasing times.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionTransform {
    pub times: Vec<f32>,
    pub mats: Vec<Mat4>,
}

/// Where `t` falls among increasing `times`: (segment index, fraction), clamped to the ends.
pub fn motion_segment(times: &[f32], t: f32) -> (usize, f32) {
    let n = times.len();
    if n < 2 || t <= times[0] {
        return (0, 0.0);
    }
    if t >= times[n - 1] {
        return (n - 2, 1.0);
    }
    let i = times
        .partition_point(|&x| x <= t)
        .saturating_sub(1)
        .min(n - 2);
    let d = times[i + 1] - times[i];
    (i, if d > 0.0 { (t - times[i]) / d } else { 0.0 })
}

fn lerp_mat(a: &Mat4, b: &Mat4, f: f32) -> Mat4 {
    if f == 0.0 {
        *a
    } else if f == 1.0 {
        *b
    } else {
        *a * (1.0 - f) + *b * f
    }
}

impl MotionTransform {
    /// The matrix at time `t` (linear between keys, held outside them).
    pub fn at(&self, t: f32) -> Mat4 {
        if self.mats.len() == 1 {
            return self.mats[0];
        }
        let (i, f) = motion_segment(&self.times, t);
        lerp_mat(&self.mats[i], &self.mats[i + 1], f)
    }
}

impl Motion {
    /// world_from_object at time `t`.
    pub fn world_from_object_at(&self, t: f32) -> Mat4 {
        if self.world_from_object.len() == 1 {
            return self.world_from_object[0];
        }
        let (i, f) = motion_segment(&self.times, t);
        lerp_mat(
            &self.world_from_object[i],
            &self.world_from_object[i + 1],
            f,
        )
    }
    /// The deformed primitive at time `t` (None when only the transform moves): keys
    /// interpolated linearly (primitive variables and quadric parameters).
    pub fn shape_at(&self, t: f32) -> Option<(Arc<Geometry>, Arc<ParamList>)> {
        if self.shapes.is_empty() {
            return None;
        }
        if self.shapes.len() == 1 {
            return Some(self.shapes[0].clone());
        }
        let (i, f) = motion_segment(&self.times, t);
        let (a, b) = (&self.shapes[i], &self.shapes[i + 1]);
        if f == 0.0 {
            return Some(a.clone());
        }
        if f == 1.0 {
            return Some(b.clone());
        }
        Some((
            Arc::new(lerp_geometry(&a.0, &b.0, f)),
            Arc::new(lerp_params(&a.1, &b.1, f)),
        ))
    }
}

/// Float parameters interpolated (others, and mismatched lengths, taken from `a`).
pub fn lerp_params(a: &ParamList, b: &ParamList, f: f32) -> ParamList {
    ParamList(
        a.0.iter()
            .map(|p| {
                let mut p = p.clone();
                if let (ParamData::Floats(x), Some(ParamData::Floats(y))) =
                    (&mut p.data, b.get(&p.name).map(|q| &q.data))
                {
                    if x.len() == y.len() && p.decl.ty != ParamType::Integer {
                        for (u, v) in x.iter_mut().zip(y) {
                            *u += (v - *u) * f;
                        }
                    }
                }
                p
            })
            .collect(),
    )
}

/// Quadric parameters interpolated; other geometry (whose shape lives in its primitive
/// variables) is taken from `a`.
pub fn lerp_geometry(a: &Geometry, b: &Geometry, f: f32) -> Geometry {
    let l = |x: f32, y: f32| x + (y - x) * f;
    use Geometry as G;
    match (a, b) {
        (
            G::Sphere {
                radius,
                zmin,
                zmax,
                thetamax,
            },
            G::Sphere {
                radius: r2,
                zmin: z0,
                zmax: z1,
                thetamax: t2,
            },
        ) => G::Sphere {
            radius: l(*radius, *r2),
            zmin: l(*zmin, *z0),
            zmax: l(*zmax, *z1),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Cone {
                height,
                radius,
                thetamax,
            },
            G::Cone {
                height: h2,
                radius: r2,
                thetamax: t2,
            },
        ) => G::Cone {
            height: l(*height, *h2),
            radius: l(*radius, *r2),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Cylinder {
                radius,
                zmin,
                zmax,
                thetamax,
            },
            G::Cylinder {
                radius: r2,
                zmin: z0,
                zmax: z1,
                thetamax: t2,
            },
        ) => G::Cylinder {
            radius: l(*radius, *r2),
            zmin: l(*zmin, *z0),
            zmax: l(*zmax, *z1),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Hyperboloid { p1, p2, thetamax },
            G::Hyperboloid {
                p1: q1,
                p2: q2,
                thetamax: t2,
            },
        ) => G::Hyperboloid {
            p1: p1.lerp(*q1, f),
            p2: p2.lerp(*q2, f),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Paraboloid {
                rmax,
                zmin,
                zmax,
                thetamax,
            },
            G::Paraboloid {
                rmax: r2,
                zmin: z0,
                zmax: z1,
                thetamax: t2,
            },
        ) => G::Paraboloid {
            rmax: l(*rmax, *r2),
            zmin: l(*zmin, *z0),
            zmax: l(*zmax, *z1),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Disk {
                height,
                radius,
                thetamax,
            },
            G::Disk {
                height: h2,
                radius: r2,
                thetamax: t2,
            },
        ) => G::Disk {
            height: l(*height, *h2),
            radius: l(*radius, *r2),
            thetamax: l(*thetamax, *t2),
        },
        (
            G::Torus {
                rmajor,
                rminor,
                phimin,
                phimax,
                thetamax,
            },
            G::Torus {
                rmajor: a2,
                rminor: b2,
                phimin: p0,
                phimax: p1,
                thetamax: t2,
            },
        ) => G::Torus {
            rmajor: l(*rmajor, *a2),
            rminor: l(*rminor, *b2),
            phimin: l(*phimin, *p0),
            phimax: l(*phimax, *p1),
            thetamax: l(*thetamax, *t2),
        },
        _ => a.clone(),
    }
}

/// One frame's scene.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// FrameBegin number, if any.
    pub frame: Option<i32>,
    pub options: Options,
    /// The transform current at WorldBegin.
    pub camera_from_world: Mat4,
    /// Camera motion: camera_from_world keys when the camera transform was given inside
    /// `MotionBegin` (its first key is `camera_from_world`).
    pub camera_motion: Option<Arc<MotionTransform>>,
    pub lights: Vec<Light>,
    pub primitives: Vec<Primitive>,
    /// CSG solids (`SolidBegin` blocks), referred to by `Attributes::solid`.
    pub solids: Vec<SolidNode>,
    /// CoordinateSystem names: world_from_named.
    pub coordinate_systems: HashMap<String, Mat4>,
    /// The file the scene came from (for relative search paths).
    pub source_dir: Option<std::path::PathBuf>,
    /// MakeTexture/MakeShadow/… requests given before this frame's WorldEnd (and after the
    /// previous one): the pipeline runs them, in order, before rendering the frame.
    pub texture_jobs: Vec<TextureJob>,
    /// True for the scene that only carries texture jobs given after the last world block
    /// (nothing to render).
    pub jobs_only: bool,
    /// Some primitive sets BMRT's `Attribute "render" "truedisplacement"`: the scene was
    /// written for BMRT, where a displacement shader only bends the normals of a primitive
    /// unless that attribute is 1 for it (PRMan always moves the points).
    pub bmrt_displacement: bool,
    /// Some primitive has a displacement shader but declares neither a `displacementbound`
    /// nor `truedisplacement`: how BMRT scenes were written (PRMan needs the bound to move
    /// points), so the frame is taken as written for BMRT.
    pub displaced_without_bound: bool,
}

/// Which texture-making request a [`TextureJob`] came from (RISpec §8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureJobKind {
    Texture,
    LatLongEnvironment,
    CubeFaceEnvironment,
    Shadow,
    /// MakeBump (RISpec 3.0/3.1; dropped from 3.2).
    Bump,
    /// `MakeHorizon` (arbor extension): Max horizon tables from a height picture.
    Horizon,
}

/// One MakeTexture/MakeLatLongEnvironment/MakeCubeFaceEnvironment/MakeShadow request.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureJob {
    pub kind: TextureJobKind,
    /// Picture names (6 for cube faces: px nx py ny pz nz).
    pub inputs: Vec<String>,
    pub output: String,
    pub swrap: String,
    pub twrap: String,
    pub filter: String,
    pub swidth: f32,
    pub twidth: f32,
    /// Cube-face field of view in degrees.
    pub fov: f32,
    /// Horizon-table azimuth directions (MakeHorizon: 8 or 16).
    pub directions: usize,
    pub span: Span,
}
