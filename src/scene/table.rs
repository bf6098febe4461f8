//! The request table: every RISpec 3.2 request with its positional arguments, its RISpec
//! section and its handler.
//!
//! Input: a [`Request`] as read from RIB. Output: a [`Call`] whose positional arguments are
//! checked and converted ([`PArg`]), with the parameter list left as raw token/value pairs.
//! Invariants: a request the table does not know, or whose positional arguments do not match,
//! never reaches a handler; the error says what the request takes.

use std::collections::HashMap;
use std::sync::OnceLock;

use glam::Mat4;

use crate::diag::{did_you_mean, Diag, Span};
use crate::rib::{Arg, Request, Value};

use super::builder::Builder;

/// What one positional argument must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArgKind {
    /// One number.
    Num,
    /// One integer.
    Int,
    /// One string.
    Str,
    /// A light or object handle: an integer or a string.
    Handle,
    /// An array of numbers (any length; a single number is accepted).
    Floats,
    /// An array of integers.
    Ints,
    /// An array of strings (a single string is accepted).
    Strs,
    /// 16 numbers (a RIB matrix, row-major).
    Matrix,
    /// A colour: `ColorSamples` numbers, as an array or loose.
    Color,
    /// A basis: a name or 16 numbers.
    Basis,
}

impl ArgKind {
    fn noun(self) -> &'static str {
        match self {
            ArgKind::Num => "number",
            ArgKind::Int => "integer",
            ArgKind::Str => "string",
            ArgKind::Handle => "handle (integer or string)",
            ArgKind::Floats => "array of numbers",
            ArgKind::Ints => "array of integers",
            ArgKind::Strs => "array of strings",
            ArgKind::Matrix => "array of 16 numbers",
            ArgKind::Color => "color",
            ArgKind::Basis => "basis name or 16 numbers",
        }
    }
}

/// A positional argument after checking.
#[derive(Clone, Debug, PartialEq)]
pub enum PArg {
    Num(f32),
    Int(i64),
    Str(String),
    Handle(String),
    Floats(Vec<f32>),
    Ints(Vec<i64>),
    Strs(Vec<String>),
    /// Already converted to glam's column-major form (`m * p` maps points).
    Matrix(Mat4),
    /// An optional argument that was not given.
    Absent,
}

impl PArg {
    pub fn num(&self) -> f32 {
        match self {
            PArg::Num(f) => *f,
            PArg::Int(i) => *i as f32,
            _ => 0.0,
        }
    }
    pub fn int(&self) -> i64 {
        match self {
            PArg::Int(i) => *i,
            PArg::Num(f) => *f as i64,
            _ => 0,
        }
    }
    pub fn str(&self) -> &str {
        match self {
            PArg::Str(s) | PArg::Handle(s) => s,
            _ => "",
        }
    }
    pub fn floats(&self) -> &[f32] {
        match self {
            PArg::Floats(f) => f,
            _ => &[],
        }
    }
    pub fn ints(&self) -> &[i64] {
        match self {
            PArg::Ints(i) => i,
            _ => &[],
        }
    }
    pub fn strs(&self) -> &[String] {
        match self {
            PArg::Strs(s) => s,
            _ => &[],
        }
    }
    pub fn is_absent(&self) -> bool {
        matches!(self, PArg::Absent)
    }
}

/// A handler applies one checked request to the builder.
pub type Handler = fn(&mut Builder<'_>, &Call<'_>);

/// One row of the table.
pub struct ReqSpec {
    pub name: &'static str,
    /// Positional arguments: (name, kind).
    pub args: &'static [(&'static str, ArgKind)],
    /// Arguments from this index on may be left out (all of them, or those before the
    /// parameter list starts).
    pub optional_from: usize,
    /// Takes a token/value parameter list after the positional arguments.
    pub params: bool,
    /// RISpec 3.2 section (or "ext" for common extensions).
    pub section: &'static str,
    pub handler: Handler,
}

impl ReqSpec {
    /// "`Sphere` takes 4 numbers: radius zmin zmax thetamax" and the like.
    pub fn describe(&self) -> String {
        let n = self.args.len();
        let names = self.args.iter().map(|a| a.0).collect::<Vec<_>>().join(" ");
        let tail = if self.params {
            ", then a parameter list"
        } else {
            ""
        };
        if n == 0 {
            return if self.params {
                format!("`{}` takes only a parameter list", self.name)
            } else {
                format!("`{}` takes no arguments", self.name)
            };
        }
        let all_same = self.args.iter().all(|a| a.1 == self.args[0].1);
        let opt = if self.optional_from < n {
            format!(" (from `{}` on optional)", self.args[self.optional_from].0)
        } else {
            String::new()
        };
        if all_same && matches!(self.args[0].1, ArgKind::Num | ArgKind::Str) {
            let noun = self.args[0].1.noun();
            if n == 1 {
                return format!("`{}` takes 1 {noun}: {names}{opt}{tail}", self.name);
            }
            return format!("`{}` takes {n} {noun}s: {names}{opt}{tail}", self.name);
        }
        let parts = self
            .args
            .iter()
            .map(|(name, k)| format!("{name} ({})", k.noun()))
            .collect::<Vec<_>>()
            .join(", ");
        format!("`{}` takes {parts}{opt}{tail}", self.name)
    }
}

/// A checked request, ready for its handler.
pub struct Call<'r> {
    pub req: &'r Request,
    pub spec: &'static ReqSpec,
    /// One entry per `spec.args` entry.
    pub pos: Vec<PArg>,
    /// The span of each positional argument (the request name when absent).
    pub pos_spans: Vec<Span>,
    /// The parameter list: alternating tokens and values, unchecked.
    pub rest: &'r [Arg],
}

impl Call<'_> {
    pub fn name(&self) -> &str {
        &self.req.name
    }
    pub fn span(&self) -> Span {
        self.req.span
    }
    pub fn full_span(&self) -> Span {
        self.req.full_span()
    }
}

/// Looks a request up by name.
pub fn lookup(name: &str) -> Option<&'static ReqSpec> {
    static INDEX: OnceLock<HashMap<&'static str, &'static ReqSpec>> = OnceLock::new();
    INDEX
        .get_or_init(|| TABLE.iter().map(|s| (s.name, s)).collect())
        .get(name)
        .copied()
}

/// Every request name in the table.
pub fn names() -> impl Iterator<Item = &'static str> {
    TABLE.iter().map(|s| s.name)
}

/// The error for a request name the table does not know.
pub fn unknown_request(req: &Request) -> Diag {
    let mut d = Diag::error(
        "scene::unknown-request",
        format!("unknown request `{}`", req.name),
    )
    .label(req.span, "not a RenderMan request");
    if let Some(m) = did_you_mean(&req.name, names()) {
        d = d.help(format!("did you mean `{m}`?"));
    } else {
        d = d.help("RIB request names are case-sensitive (RISpec 3.2 Appendix C)");
    }
    d
}

/// Checks the positional arguments of `req` against `spec`. `ncomps` is the current
/// `ColorSamples` count (for [`ArgKind::Color`]).
pub fn check_args<'r>(
    req: &'r Request,
    spec: &'static ReqSpec,
    ncomps: usize,
) -> Result<Call<'r>, Diag> {
    let args = &req.args[..];
    let bad = |span: Span, what: String| {
        Diag::error(
            "scene::arguments",
            format!("bad arguments to `{}`: {what}", spec.name),
        )
        .label(span, what)
        .help(spec.describe())
    };
    // The bracketed form of all-number requests: `Sphere [1 -1 1 360]`.
    let expanded;
    let args: &[Arg] = if spec.args.len() > 1
        && spec.args.iter().all(|a| a.1 == ArgKind::Num)
        && matches!(args.first(), Some(a) if matches!(&a.value, Value::IntArray(v) if v.len() == spec.args.len())
            || matches!(&a.value, Value::FloatArray(v) if v.len() == spec.args.len()))
    {
        let first = &args[0];
        let nums = first.value.to_f32s().unwrap_or_default();
        expanded = nums
            .into_iter()
            .map(|f| Arg {
                value: Value::Float(f),
                span: first.span,
            })
            .chain(args[1..].iter().cloned())
            .collect::<Vec<_>>();
        &expanded
    } else {
        args
    };
    let mut pos = Vec::with_capacity(spec.args.len());
    let mut spans = Vec::with_capacity(spec.args.len());
    let mut i = 0;
    for (k, &(aname, kind)) in spec.args.iter().enumerate() {
        let at_params = i >= args.len()
            || (spec.params
                && kind != ArgKind::Str
                && kind != ArgKind::Handle
                && matches!(args[i].value, Value::Str(_)));
        if at_params {
            if k >= spec.optional_from {
                pos.push(PArg::Absent);
                spans.push(req.span);
                continue;
            }
            let span = args.get(i).map(|a| a.span).unwrap_or(req.span);
            let found = args
                .get(i)
                .map(|a| a.value.describe())
                .unwrap_or_else(|| "nothing".into());
            return Err(bad(
                span,
                format!("expected {aname} ({}), found {found}", kind.noun()),
            ));
        }
        let a = &args[i];
        let v = &a.value;
        let mismatch = || {
            bad(
                a.span,
                format!("expected {aname} ({}), found {}", kind.noun(), v.describe()),
            )
        };
        let p = match kind {
            ArgKind::Num => match v {
                Value::Int(_) | Value::Float(_) => PArg::Num(v.as_f32().unwrap_or(0.0)),
                _ if v.is_array() && !v.is_string() && v.len() == 1 => {
                    PArg::Num(v.as_f32().unwrap_or(0.0))
                }
                _ => return Err(mismatch()),
            },
            ArgKind::Int => match v.to_ints() {
                Some(iv) if iv.len() == 1 => PArg::Int(iv[0]),
                _ => return Err(mismatch()),
            },
            ArgKind::Str => match v {
                Value::Str(s) => PArg::Str(s.clone()),
                Value::StrArray(a) if a.len() == 1 => PArg::Str(a[0].clone()),
                _ => return Err(mismatch()),
            },
            ArgKind::Handle => match v {
                Value::Str(s) => PArg::Handle(s.clone()),
                Value::StrArray(a) if a.len() == 1 => PArg::Handle(a[0].clone()),
                _ => match v.to_ints() {
                    Some(iv) if iv.len() == 1 => PArg::Handle(iv[0].to_string()),
                    _ => return Err(mismatch()),
                },
            },
            ArgKind::Floats => match v.to_f32s() {
                Some(f) => PArg::Floats(f),
                None => return Err(mismatch()),
            },
            ArgKind::Ints => match v.to_ints() {
                Some(iv) => PArg::Ints(iv),
                None => return Err(mismatch()),
            },
            ArgKind::Strs => match v.to_strings() {
                Some(s) => PArg::Strs(s),
                // An empty `[]` reads as a number array; as a string array it is simply
                // empty (exporters write `SubdivisionMesh ... [] [] [] []` for no tags).
                None if v.is_array() && v.len() == 0 => PArg::Strs(Vec::new()),
                None => return Err(mismatch()),
            },
            ArgKind::Matrix => {
                if let (true, Some(f)) = (v.is_array(), v.to_f32s()) {
                    if f.len() != 16 {
                        return Err(bad(
                            a.span,
                            format!("{aname} needs 16 numbers, found {}", f.len()),
                        ));
                    }
                    PArg::Matrix(mat_from_rib(&f))
                } else if !v.is_string() {
                    // 16 loose numbers.
                    let loose = loose_numbers(&args[i..], 16);
                    if loose.len() != 16 {
                        return Err(bad(
                            a.span,
                            format!("{aname} needs 16 numbers, found {}", loose.len()),
                        ));
                    }
                    i += 15;
                    PArg::Matrix(mat_from_rib(&loose))
                } else {
                    return Err(mismatch());
                }
            }
            ArgKind::Color => {
                if v.is_array() && !v.is_string() {
                    let f = v.to_f32s().unwrap_or_default();
                    if f.len() != ncomps {
                        return Err(bad(
                            a.span,
                            format!(
                                "{aname} needs {ncomps} numbers (ColorSamples), found {}",
                                f.len()
                            ),
                        ));
                    }
                    PArg::Floats(f)
                } else if !v.is_string() {
                    let loose = loose_numbers(&args[i..], ncomps);
                    if loose.len() != ncomps {
                        return Err(bad(
                            a.span,
                            format!(
                                "{aname} needs {ncomps} numbers (ColorSamples), found {}",
                                loose.len()
                            ),
                        ));
                    }
                    i += ncomps - 1;
                    PArg::Floats(loose)
                } else {
                    return Err(mismatch());
                }
            }
            ArgKind::Basis => match v {
                Value::Str(s) => PArg::Str(s.clone()),
                Value::StrArray(a) if a.len() == 1 => PArg::Str(a[0].clone()),
                _ => match v.to_f32s() {
                    Some(f) if f.len() == 16 => PArg::Floats(f),
                    _ => return Err(mismatch()),
                },
            },
        };
        pos.push(p);
        spans.push(a.span);
        i += 1;
    }
    let rest_start = i.min(args.len());
    // `rest` must borrow from the request; when the bracketed form was expanded, the
    // positional part was exactly the first array.
    let rest: &'r [Arg] = if args.len() != req.args.len() {
        let consumed_orig = rest_start + 1 - spec.args.len();
        &req.args[consumed_orig.min(req.args.len())..]
    } else {
        &req.args[rest_start..]
    };
    if !spec.params && !rest.is_empty() {
        return Err(bad(
            rest[0].span,
            format!("unexpected extra argument: {}", rest[0].value.describe()),
        ));
    }
    Ok(Call {
        req,
        spec,
        pos,
        pos_spans: spans,
        rest,
    })
}

/// Up to `n` leading single numbers.
fn loose_numbers(args: &[Arg], n: usize) -> Vec<f32> {
    args.iter()
        .take(n)
        .map_while(|a| match a.value {
            Value::Int(i) => Some(i as f32),
            Value::Float(f) => Some(f),
            _ => None,
        })
        .collect()
}

/// A RIB matrix (row vectors, row-major) as glam's column-major `Mat4` mapping `m * p`.
/// The RIB array's rows are the math matrix's columns, so it loads as columns unchanged.
pub fn mat_from_rib(f: &[f32]) -> Mat4 {
    let mut a = [0.0f32; 16];
    a.copy_from_slice(&f[..16]);
    Mat4::from_cols_array(&a)
}

macro_rules! req {
    ($name:literal, [$($an:literal : $ak:ident),*], $opt:expr, $params:expr, $sec:literal, $h:expr) => {
        ReqSpec {
            name: $name,
            args: &[$(($an, ArgKind::$ak)),*],
            optional_from: $opt,
            params: $params,
            section: $sec,
            handler: |b, c| $h(b, c),
        }
    };
}

const ALL: usize = usize::MAX;

use super::builder::Builder as B;

/// Every RISpec 3.2 request (plus common extensions, marked "ext").
pub static TABLE: &[ReqSpec] = &[
    // ---- blocks and the graphics state (§4) ----
    req!("version", ["version": Num], ALL, false, "C.2", B::nothing),
    req!("Begin", ["name": Str], 0, false, "4", B::c_only),
    req!("End", [], ALL, false, "4", B::c_only),
    req!("FrameBegin", ["frame": Int], 0, false, "4", B::frame_begin),
    req!("FrameEnd", [], ALL, false, "4", B::frame_end),
    req!("WorldBegin", [], ALL, false, "4", B::world_begin),
    req!("WorldEnd", [], ALL, false, "4", B::world_end),
    req!("AttributeBegin", [], ALL, false, "4.2", B::attribute_begin),
    req!("AttributeEnd", [], ALL, false, "4.2", B::attribute_end),
    req!("TransformBegin", [], ALL, false, "4.3", B::transform_begin),
    req!("TransformEnd", [], ALL, false, "4.3", B::transform_end),
    req!("SolidBegin", ["operation": Str], ALL, false, "5.6", B::solid_begin),
    req!("SolidEnd", [], ALL, false, "5.6", B::solid_end),
    req!("ObjectBegin", ["handle": Handle], ALL, false, "5.7", B::object_begin),
    req!("ObjectEnd", [], ALL, false, "5.7", B::object_end),
    req!("ObjectInstance", ["handle": Handle], ALL, false, "5.7", B::object_instance),
    req!("MotionBegin", ["times": Floats], 0, false, "5.8", B::motion_begin),
    req!("MotionEnd", [], ALL, false, "5.8", B::motion_end),
    req!("ArchiveBegin", ["name": Str], ALL, true, "ext", B::nothing),
    req!("ArchiveEnd", [], ALL, false, "ext", B::archive_end_alone),
    req!("IfBegin", ["condition": Str], ALL, false, "ext", B::nothing),
    req!("ElseIf", ["condition": Str], ALL, false, "ext", B::nothing),
    req!("Else", [], ALL, false, "ext", B::nothing),
    req!("IfEnd", [], ALL, false, "ext", B::nothing),
    req!("Resource", ["handle": Str, "type": Str], ALL, true, "ext", B::resource),
    req!("ResourceBegin", [], ALL, false, "ext", B::resource_begin),
    req!("ResourceEnd", [], ALL, false, "ext", B::resource_end),
    // Later PRMan / 3Delight shading requests seen in exported RIB: recognised so a scene
    // using them renders with a named warning instead of an unknown-request error.
    req!("ShaderLayer", ["type": Str, "name": Str, "layername": Str], ALL, true, "ext", B::unimplemented),
    req!("ConnectShaderLayers", ["type": Str, "layer1": Str, "variable1": Str, "layer2": Str, "variable2": Str], ALL, false, "ext", B::unimplemented),
    req!("Shader", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("Integrator", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("Bxdf", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("Pattern", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    // PRMan/3Delight requests beyond RISpec 3.2 that published RIB uses: a named warning each.
    req!("GeometricRepresentation", ["type": Str], ALL, false, "ext", B::geometric_representation),
    req!("System", ["cmdstring": Str], ALL, false, "ext", B::unimplemented),
    req!("MakeBrickMap", ["ptcnames": Strs, "bkmname": Str], ALL, true, "ext", B::unimplemented),
    req!("MakeOcclusion", ["picnames": Strs, "shadowname": Str], ALL, true, "ext", B::unimplemented),
    req!("PixelSampleImager", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("Volume", ["type": Str, "bound": Floats, "nvertices": Ints], ALL, true, "ext", B::unimplemented),
    req!("VPAtmosphere", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("VPInterior", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("VPSurface", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("HierarchicalSubdivisionMesh", ["scheme": Str, "nvertices": Ints, "vertices": Ints, "tags": Strs, "nargs": Ints, "intargs": Ints, "floatargs": Floats, "stringargs": Strs], 3, true, "ext", B::subdivision_mesh),
    req!("EditBegin", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("EditEnd", [], ALL, false, "ext", B::unimplemented),
    req!("EditAttributeBegin", ["name": Str], ALL, false, "ext", B::unimplemented),
    req!("EditAttributeEnd", [], ALL, false, "ext", B::unimplemented),
    req!("EditWorldBegin", ["name": Str], ALL, true, "ext", B::unimplemented),
    req!("EditWorldEnd", [], ALL, false, "ext", B::unimplemented),
    req!("Light", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("LightFilter", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("DisplayFilter", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("SampleFilter", ["name": Str, "handle": Str], ALL, true, "ext", B::unimplemented),
    req!("Declare", ["name": Str, "declaration": Str], ALL, false, "4", B::declare),
    req!("ErrorHandler", ["handler": Str], ALL, false, "9", B::error_handler),
    req!("ReadArchive", ["filename": Str], ALL, true, "8", B::read_archive),
    // ---- options (§4.1) ----
    req!("Format", ["xresolution": Num, "yresolution": Num, "pixelaspectratio": Num], ALL, false, "4.1.1", B::format),
    req!("FrameAspectRatio", ["frameratio": Num], ALL, false, "4.1.1", B::frame_aspect_ratio),
    req!("ScreenWindow", ["left": Num, "right": Num, "bottom": Num, "top": Num], ALL, false, "4.1.1", B::screen_window),
    req!("CropWindow", ["xmin": Num, "xmax": Num, "ymin": Num, "ymax": Num], ALL, false, "4.1.1", B::crop_window),
    req!("Projection", ["name": Str], ALL, true, "4.1.1", B::projection),
    req!("Clipping", ["near": Num, "far": Num], ALL, false, "4.1.1", B::clipping),
    req!("ClippingPlane", ["x": Num, "y": Num, "z": Num, "nx": Num, "ny": Num, "nz": Num], ALL, false, "4.1.1", B::clipping_plane),
    req!("DepthOfField", ["fstop": Num, "focallength": Num, "focaldistance": Num], 0, false, "4.1.1", B::depth_of_field),
    req!("Shutter", ["opentime": Num, "closetime": Num], ALL, false, "4.1.1", B::shutter),
    req!("Camera", ["name": Str], ALL, true, "4.1.1", B::unimplemented),
    req!("PixelVariance", ["variation": Num], ALL, false, "4.1.2", B::pixel_variance),
    req!("PixelSamples", ["xsamples": Num, "ysamples": Num], ALL, false, "4.1.2", B::pixel_samples),
    req!("PixelFilter", ["filter": Str, "xwidth": Num, "ywidth": Num], ALL, false, "4.1.2", B::pixel_filter),
    req!("Exposure", ["gain": Num, "gamma": Num], ALL, false, "4.1.2", B::exposure),
    req!("Imager", ["name": Str], ALL, true, "4.1.2", B::imager),
    req!("Quantize", ["type": Str, "one": Num, "min": Num, "max": Num, "ditheramplitude": Num], ALL, false, "4.1.2", B::quantize),
    req!("Display", ["name": Str, "type": Str, "mode": Str], ALL, true, "4.1.3", B::display),
    req!("DisplayChannel", ["channel": Str], ALL, true, "4.1.3", B::unimplemented),
    req!("Hider", ["type": Str], ALL, true, "4.1.4", B::hider),
    req!("ColorSamples", ["nRGB": Floats, "RGBn": Floats], ALL, false, "4.1.4", B::color_samples),
    req!("RelativeDetail", ["relativedetail": Num], ALL, false, "4.1.4", B::relative_detail),
    req!("Option", ["name": Str], ALL, true, "4.1.4", B::option),
    // ---- attributes (§4.2) ----
    req!("Attribute", ["name": Str], ALL, true, "4.2", B::attribute),
    req!("Color", ["color": Color], ALL, false, "4.2.1", B::color),
    req!("Opacity", ["color": Color], ALL, false, "4.2.1", B::opacity),
    req!("TextureCoordinates", ["s1": Num, "t1": Num, "s2": Num, "t2": Num, "s3": Num, "t3": Num, "s4": Num, "t4": Num], ALL, false, "4.2.2", B::texture_coordinates),
    req!("LightSource", ["name": Str, "handle": Handle], ALL, true, "4.2.3", B::light_source),
    req!("AreaLightSource", ["name": Str, "handle": Handle], ALL, true, "4.2.3", B::area_light_source),
    req!("Illuminate", ["light": Handle, "onoff": Int], ALL, false, "4.2.3", B::illuminate),
    req!("Surface", ["name": Str], ALL, true, "4.2.4", B::surface),
    req!("Displacement", ["name": Str], ALL, true, "4.2.5", B::displacement),
    req!("Atmosphere", ["name": Str], ALL, true, "4.2.6", B::atmosphere),
    req!("Interior", ["name": Str], ALL, true, "4.2.6", B::interior),
    req!("Exterior", ["name": Str], ALL, true, "4.2.6", B::exterior),
    req!("Deformation", ["name": Str], ALL, true, "4.2.5", B::unimplemented),
    req!("ShadingRate", ["size": Num], ALL, false, "4.2.7", B::shading_rate),
    req!("ShadingInterpolation", ["type": Str], ALL, false, "4.2.7", B::shading_interpolation),
    req!("Matte", ["onoff": Int], ALL, false, "4.2.8", B::matte),
    req!("Bound", ["xmin": Num, "xmax": Num, "ymin": Num, "ymax": Num, "zmin": Num, "zmax": Num], ALL, false, "4.2.9", B::bound),
    req!("Detail", ["xmin": Num, "xmax": Num, "ymin": Num, "ymax": Num, "zmin": Num, "zmax": Num], ALL, false, "4.2.9", B::detail),
    req!("DetailRange", ["minvisible": Num, "lowertransition": Num, "uppertransition": Num, "maxvisible": Num], ALL, false, "4.2.9", B::detail_range),
    req!("GeometricApproximation", ["type": Str, "value": Num], ALL, false, "4.2.10", B::geometric_approximation),
    req!("Orientation", ["orientation": Str], ALL, false, "4.2.11", B::orientation),
    req!(
        "ReverseOrientation",
        [],
        ALL,
        false,
        "4.2.11",
        B::reverse_orientation
    ),
    req!("Sides", ["sides": Int], ALL, false, "4.2.11", B::sides),
    req!("Basis", ["ubasis": Basis, "ustep": Int, "vbasis": Basis, "vstep": Int], ALL, false, "5.2", B::basis),
    // ---- transformations (§4.3) ----
    req!("Identity", [], ALL, false, "4.3", B::identity),
    req!("Transform", ["transform": Matrix], ALL, false, "4.3", B::transform),
    req!("ConcatTransform", ["transform": Matrix], ALL, false, "4.3", B::concat_transform),
    req!("Perspective", ["fov": Num], ALL, false, "4.3", B::perspective),
    req!("Translate", ["dx": Num, "dy": Num, "dz": Num], ALL, false, "4.3", B::translate),
    req!("Rotate", ["angle": Num, "dx": Num, "dy": Num, "dz": Num], ALL, false, "4.3", B::rotate),
    req!("Scale", ["sx": Num, "sy": Num, "sz": Num], ALL, false, "4.3", B::scale),
    req!("Skew", ["angle": Num, "dx1": Num, "dy1": Num, "dz1": Num, "dx2": Num, "dy2": Num, "dz2": Num], ALL, false, "4.3", B::skew),
    req!("CoordinateSystem", ["space": Str], ALL, false, "4.3.1", B::coordinate_system),
    req!("ScopedCoordinateSystem", ["space": Str], ALL, false, "ext", B::scoped_coordinate_system),
    req!("CoordSysTransform", ["space": Str], ALL, false, "4.3.1", B::coord_sys_transform),
    // ---- geometry (§5) ----
    req!("Polygon", [], ALL, true, "5.1", B::polygon),
    req!("GeneralPolygon", ["nvertices": Ints], ALL, true, "5.1", B::general_polygon),
    req!("PointsPolygons", ["nvertices": Ints, "vertices": Ints], ALL, true, "5.1", B::points_polygons),
    req!("PointsGeneralPolygons", ["nloops": Ints, "nvertices": Ints, "vertices": Ints], ALL, true, "5.1", B::points_general_polygons),
    req!("Patch", ["type": Str], ALL, true, "5.2", B::patch),
    req!("PatchMesh", ["type": Str, "nu": Int, "uwrap": Str, "nv": Int, "vwrap": Str], ALL, true, "5.2", B::patch_mesh),
    req!("NuPatch", ["nu": Int, "uorder": Int, "uknot": Floats, "umin": Num, "umax": Num, "nv": Int, "vorder": Int, "vknot": Floats, "vmin": Num, "vmax": Num], ALL, true, "5.2", B::nu_patch),
    req!("TrimCurve", ["ncurves": Ints, "order": Ints, "knot": Floats, "min": Floats, "max": Floats, "n": Ints, "u": Floats, "v": Floats, "w": Floats], ALL, false, "5.2", B::trim_curve),
    req!("SubdivisionMesh", ["scheme": Str, "nvertices": Ints, "vertices": Ints, "tags": Strs, "nargs": Ints, "intargs": Ints, "floatargs": Floats], 3, true, "5.3", B::subdivision_mesh),
    req!("Sphere", ["radius": Num, "zmin": Num, "zmax": Num, "thetamax": Num], ALL, true, "5.4", B::sphere),
    req!("Cone", ["height": Num, "radius": Num, "thetamax": Num], ALL, true, "5.4", B::cone),
    req!("Cylinder", ["radius": Num, "zmin": Num, "zmax": Num, "thetamax": Num], ALL, true, "5.4", B::cylinder),
    req!("Hyperboloid", ["x1": Num, "y1": Num, "z1": Num, "x2": Num, "y2": Num, "z2": Num, "thetamax": Num], ALL, true, "5.4", B::hyperboloid),
    req!("Paraboloid", ["rmax": Num, "zmin": Num, "zmax": Num, "thetamax": Num], ALL, true, "5.4", B::paraboloid),
    req!("Disk", ["height": Num, "radius": Num, "thetamax": Num], ALL, true, "5.4", B::disk),
    req!("Torus", ["majorradius": Num, "minorradius": Num, "phimin": Num, "phimax": Num, "thetamax": Num], ALL, true, "5.4", B::torus),
    req!("Points", [], ALL, true, "5.5", B::points),
    req!("Curves", ["type": Str, "nvertices": Ints, "wrap": Str], ALL, true, "5.5", B::curves),
    req!("Blobby", ["nleaf": Int, "code": Ints, "floats": Floats, "strings": Strs], ALL, true, "5.7", B::blobby),
    req!("Procedural", ["procname": Str, "args": Strs, "bound": Floats], ALL, false, "5.6", B::procedural),
    req!("Procedural2", ["procname": Str, "boundfunc": Str], ALL, true, "ext", B::procedural2),
    req!("Geometry", ["type": Str], ALL, true, "5.5", B::geometry_named),
    // ---- texture-making utilities (§8) ----
    req!("MakeTexture", ["picturename": Str, "texturename": Str, "swrap": Str, "twrap": Str, "filter": Str, "swidth": Num, "twidth": Num], ALL, true, "8.1", B::make_texture),
    req!("MakeBump", ["picturename": Str, "texturename": Str, "swrap": Str, "twrap": Str, "filter": Str, "swidth": Num, "twidth": Num], ALL, true, "8.1", B::make_bump),
    req!("MakeLatLongEnvironment", ["picturename": Str, "texturename": Str, "filter": Str, "swidth": Num, "twidth": Num], ALL, true, "8.2", B::make_latlong),
    req!("MakeCubeFaceEnvironment", ["px": Str, "nx": Str, "py": Str, "ny": Str, "pz": Str, "nz": Str, "texturename": Str, "fov": Num, "filter": Str, "swidth": Num, "twidth": Num], ALL, true, "8.2", B::make_cube),
    req!("MakeShadow", ["picturename": Str, "texturename": Str], ALL, true, "8.3", B::make_shadow),
    req!("MakeHorizon", ["picturename": Str, "horizonname": Str, "swrap": Str, "twrap": Str], ALL, true, "ext", B::make_horizon),
];

#[cfg(test)]
mod tests {
    use super::*;

    fn req(name: &str, vals: Vec<Value>) -> Request {
        Request {
            name: name.into(),
            span: Span::new(0, 0, name.len()),
            args: vals
                .into_iter()
                .enumerate()
                .map(|(i, value)| Arg {
                    value,
                    span: Span::new(0, 10 + i, 11 + i),
                })
                .collect(),
        }
    }

    #[test]
    fn names_are_unique() {
        let mut seen = std::collections::HashSet::new();
        for s in TABLE {
            assert!(seen.insert(s.name), "duplicate {}", s.name);
        }
        assert!(TABLE.len() > 100);
    }

    #[test]
    fn sphere_accepts_loose_and_bracketed() {
        let spec = lookup("Sphere").unwrap();
        let r = req(
            "Sphere",
            vec![
                Value::Int(1),
                Value::Int(-1),
                Value::Int(1),
                Value::Int(360),
            ],
        );
        let c = check_args(&r, spec, 3).unwrap();
        assert_eq!(c.pos[3], PArg::Num(360.0));
        let r = req(
            "Sphere",
            vec![
                Value::IntArray(vec![1, -1, 1, 360]),
                Value::Str("Cs".into()),
                Value::FloatArray(vec![1.0; 12]),
            ],
        );
        let c = check_args(&r, spec, 3).unwrap();
        assert_eq!(c.pos[1], PArg::Num(-1.0));
        assert_eq!(c.rest.len(), 2);
    }

    #[test]
    fn sphere_with_missing_number_says_what_it_takes() {
        let spec = lookup("Sphere").unwrap();
        let r = req("Sphere", vec![Value::Int(1), Value::Int(-1)]);
        let e = check_args(&r, spec, 3).err().unwrap();
        assert_eq!(
            e.help.as_deref(),
            Some("`Sphere` takes 4 numbers: radius zmin zmax thetamax, then a parameter list")
        );
    }

    #[test]
    fn matrix_is_transposed_into_glam() {
        // RIB: translation in the last row.
        let mut f = [0.0f32; 16];
        f[0] = 1.0;
        f[5] = 1.0;
        f[10] = 1.0;
        f[15] = 1.0;
        f[12] = 2.0;
        f[13] = 3.0;
        f[14] = 4.0;
        let m = mat_from_rib(&f);
        let p = m.transform_point3(glam::Vec3::ZERO);
        assert_eq!(p, glam::Vec3::new(2.0, 3.0, 4.0));
    }

    #[test]
    fn optional_trailing_arrays() {
        let spec = lookup("SubdivisionMesh").unwrap();
        let r = req(
            "SubdivisionMesh",
            vec![
                Value::Str("catmull-clark".into()),
                Value::IntArray(vec![4]),
                Value::IntArray(vec![0, 1, 2, 3]),
                Value::Str("P".into()),
                Value::FloatArray(vec![0.0; 12]),
            ],
        );
        let c = check_args(&r, spec, 3).unwrap();
        assert!(c.pos[3].is_absent());
        assert_eq!(c.rest.len(), 2);
    }

    #[test]
    fn color_takes_loose_or_array() {
        let spec = lookup("Color").unwrap();
        let r = req(
            "Color",
            vec![Value::Float(0.5), Value::Int(1), Value::Int(0)],
        );
        assert_eq!(
            check_args(&r, spec, 3).unwrap().pos[0],
            PArg::Floats(vec![0.5, 1.0, 0.0])
        );
        let r = req("Color", vec![Value::FloatArray(vec![0.5, 1.0])]);
        assert!(check_args(&r, spec, 3).is_err());
    }

    #[test]
    fn extra_arguments_are_refused() {
        let spec = lookup("Translate").unwrap();
        let r = req(
            "Translate",
            vec![Value::Int(1), Value::Int(2), Value::Int(3), Value::Int(4)],
        );
        assert!(check_args(&r, spec, 3).is_err());
    }
}
