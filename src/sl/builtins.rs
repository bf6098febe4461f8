//! The built-in function table: every RISpec 3.2 §15 function with its overloads.
//!
//! Signatures are written as type codes: `f` float, `s` string, `c` color, `p` point,
//! `v` vector, `n` normal, `m` matrix, `t` any triple (every `t` of one signature is the same
//! type, and a `t` result takes it), `q` a point-like triple (point, vector or normal, unified
//! like `t`), `x` any type. A `&` before a code marks an output argument; a trailing `*`
//! repeats the last argument any number of times. Functions whose arguments are free-form
//! (texture access parameters, message passing, printf) are lowered specially in `lower`.

use crate::sl::ast::BaseType;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Builtin {
    // math
    Radians,
    Degrees,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan1,
    Atan2,
    Pow,
    Exp,
    Sqrt,
    InvSqrt,
    Log,
    LogBase,
    Mod,
    Abs,
    Sign,
    Floor,
    Ceil,
    Round,
    MinF,
    MaxF,
    MinT,
    MaxT,
    ClampF,
    ClampT,
    MixF,
    MixT,
    MixTT,
    Step,
    SmoothStep,
    FilterStep,
    SplineF,
    SplineT,
    SplineBasisF,
    SplineBasisT,
    SplineArrayF,
    SplineArrayT,
    SplineBasisArrayF,
    SplineBasisArrayT,
    DuF,
    DvF,
    DuT,
    DvT,
    DerivF,
    DerivT,
    RandomF,
    RandomT,
    // noise family: dimension encoded by argument kinds
    NoiseF1,
    NoiseF2,
    NoiseF3,
    NoiseF4,
    NoiseT1,
    NoiseT2,
    NoiseT3,
    NoiseT4,
    PNoiseF1,
    PNoiseF2,
    PNoiseF3,
    PNoiseF4,
    PNoiseT1,
    PNoiseT2,
    PNoiseT3,
    PNoiseT4,
    CellF1,
    CellF2,
    CellF3,
    CellF4,
    CellT1,
    CellT2,
    CellT3,
    CellT4,
    // geometry
    XComp,
    YComp,
    ZComp,
    SetXComp,
    SetYComp,
    SetZComp,
    Length,
    Normalize,
    Distance,
    PtLineD,
    RotatePoint,
    Area,
    FaceForward2,
    FaceForward3,
    Reflect,
    Refract,
    Fresnel,
    FresnelRT,
    Depth,
    CalculateNormal,
    // colour
    Comp,
    SetComp,
    CTransform1,
    CTransform2,
    // matrix
    MComp,
    MSetComp,
    Determinant,
    MTranslate,
    MRotate,
    MScale,
    // string
    Concat,
    Format,
    Printf,
    Match,
    // shading
    Ambient,
    Diffuse,
    Specular,
    SpecularBrdf,
    Phong,
    Trace,
    // texture (free-form; lowered specially)
    TextureF,
    TextureC,
    EnvironmentF,
    EnvironmentC,
    Shadow,
    TextureInfo,
    Bump,
    // message passing (lowered specially)
    Message,
    ShaderName,
    ArrayLength,
    IsNan,
    /// BMRT/PRMan `raylevel()`: the ray depth of the grid being shaded.
    RayLevel,
    /// `isshadowray()`: arbor never shades for shadow rays (they read `Os`), so 0.
    IsShadowRay,
    // ray tracing (free-form parameters; lowered specially): shade/rayops.rs
    Occlusion,
    IndirectDiffuse,
    Transmission,
    Visibility,
    // horizon mapping (Max): src/texture/horizon.rs
    Horizon,
    HorizonHeight,
}

impl Builtin {
    /// A function of its arguments' values at each point alone, writing only its result: it
    /// may run on just the running points of a sparse mask (see `Instr::pointwise`).
    /// Functions that read neighbours (derivatives, texture filter widths), read a varying
    /// argument's first value, or write output arguments are not.
    pub fn pointwise(self) -> bool {
        matches!(
            self,
            Radians
                | Degrees
                | Sin
                | Cos
                | Tan
                | Asin
                | Acos
                | Atan1
                | Atan2
                | Pow
                | Exp
                | Sqrt
                | InvSqrt
                | Log
                | LogBase
                | Mod
                | Abs
                | Sign
                | Floor
                | Ceil
                | Round
                | IsNan
                | MinF
                | MaxF
                | MinT
                | MaxT
                | ClampF
                | ClampT
                | MixF
                | MixT
                | MixTT
                | Step
                | SmoothStep
                | RandomF
                | RandomT
                | NoiseF1
                | NoiseF2
                | NoiseF3
                | NoiseF4
                | NoiseT1
                | NoiseT2
                | NoiseT3
                | NoiseT4
                | PNoiseF1
                | PNoiseF2
                | PNoiseF3
                | PNoiseF4
                | PNoiseT1
                | PNoiseT2
                | PNoiseT3
                | PNoiseT4
                | CellF1
                | CellF2
                | CellF3
                | CellF4
                | CellT1
                | CellT2
                | CellT3
                | CellT4
                | XComp
                | YComp
                | ZComp
                | Length
                | Normalize
                | Distance
                | PtLineD
                | FaceForward2
                | FaceForward3
                | Reflect
                | Refract
                | Depth
                | Comp
        )
    }
}

/// One overload of a built-in.
#[derive(Clone, Copy, Debug)]
pub struct Sig {
    pub name: &'static str,
    pub ret: char,
    pub args: &'static str,
    pub f: Builtin,
}

use Builtin::*;

macro_rules! sigs {
    ($( $name:literal $ret:literal $args:literal $f:ident ;)*) => {
        &[ $( Sig { name: $name, ret: $ret, args: $args, f: $f } ),* ]
    };
}

/// Every overload, in preference order within a name.
pub static SIGS: &[Sig] = sigs! {
    "radians" 'f' "f" Radians;
    "degrees" 'f' "f" Degrees;
    "sin" 'f' "f" Sin;
    "cos" 'f' "f" Cos;
    "tan" 'f' "f" Tan;
    "asin" 'f' "f" Asin;
    "acos" 'f' "f" Acos;
    "atan" 'f' "f" Atan1;
    "atan" 'f' "ff" Atan2;
    "pow" 'f' "ff" Pow;
    "exp" 'f' "f" Exp;
    "sqrt" 'f' "f" Sqrt;
    "inversesqrt" 'f' "f" InvSqrt;
    "log" 'f' "f" Log;
    "log" 'f' "ff" LogBase;
    "mod" 'f' "ff" Mod;
    "abs" 'f' "f" Abs;
    "sign" 'f' "f" Sign;
    "floor" 'f' "f" Floor;
    "ceil" 'f' "f" Ceil;
    "round" 'f' "f" Round;
    "min" 'f' "ff*" MinF;
    "min" 't' "tt*" MinT;
    "max" 'f' "ff*" MaxF;
    "max" 't' "tt*" MaxT;
    "clamp" 'f' "fff" ClampF;
    "clamp" 't' "ttt" ClampT;
    "mix" 'f' "fff" MixF;
    "mix" 't' "ttf" MixT;
    "mix" 't' "ttt" MixTT;
    "step" 'f' "ff" Step;
    "smoothstep" 'f' "fff" SmoothStep;
    "spline" 'f' "ff*" SplineF;
    "spline" 't' "ft*" SplineT;
    "spline" 'f' "sff*" SplineBasisF;
    "spline" 't' "sft*" SplineBasisT;
    "Du" 'f' "f" DuF;
    "Du" 't' "t" DuT;
    "Dv" 'f' "f" DvF;
    "Dv" 't' "t" DvT;
    "Deriv" 'f' "ff" DerivF;
    "Deriv" 't' "tf" DerivT;
    "random" 'f' "" RandomF;
    "random" 'c' "" RandomT;
    "random" 'p' "" RandomT;
    "random" 'v' "" RandomT;
    "noise" 'f' "f" NoiseF1;
    "noise" 'f' "ff" NoiseF2;
    "noise" 'f' "p" NoiseF3;
    "noise" 'f' "pf" NoiseF4;
    "noise" 'c' "f" NoiseT1;
    "noise" 'p' "f" NoiseT1;
    "noise" 'v' "f" NoiseT1;
    "noise" 'c' "ff" NoiseT2;
    "noise" 'p' "ff" NoiseT2;
    "noise" 'v' "ff" NoiseT2;
    "noise" 'c' "p" NoiseT3;
    "noise" 'p' "p" NoiseT3;
    "noise" 'v' "p" NoiseT3;
    "noise" 'c' "pf" NoiseT4;
    "noise" 'p' "pf" NoiseT4;
    "noise" 'v' "pf" NoiseT4;
    "pnoise" 'f' "ff" PNoiseF1;
    "pnoise" 'f' "ffff" PNoiseF2;
    "pnoise" 'f' "pp" PNoiseF3;
    "pnoise" 'f' "pfpf" PNoiseF4;
    "pnoise" 'c' "ff" PNoiseT1;
    "pnoise" 'p' "ff" PNoiseT1;
    "pnoise" 'v' "ff" PNoiseT1;
    "pnoise" 'c' "ffff" PNoiseT2;
    "pnoise" 'p' "ffff" PNoiseT2;
    "pnoise" 'v' "ffff" PNoiseT2;
    "pnoise" 'c' "pp" PNoiseT3;
    "pnoise" 'p' "pp" PNoiseT3;
    "pnoise" 'v' "pp" PNoiseT3;
    "pnoise" 'c' "pfpf" PNoiseT4;
    "pnoise" 'p' "pfpf" PNoiseT4;
    "pnoise" 'v' "pfpf" PNoiseT4;
    "cellnoise" 'f' "f" CellF1;
    "cellnoise" 'f' "ff" CellF2;
    "cellnoise" 'f' "p" CellF3;
    "cellnoise" 'f' "pf" CellF4;
    "cellnoise" 'c' "f" CellT1;
    "cellnoise" 'p' "f" CellT1;
    "cellnoise" 'v' "f" CellT1;
    "cellnoise" 'c' "ff" CellT2;
    "cellnoise" 'p' "ff" CellT2;
    "cellnoise" 'v' "ff" CellT2;
    "cellnoise" 'c' "p" CellT3;
    "cellnoise" 'p' "p" CellT3;
    "cellnoise" 'v' "p" CellT3;
    "cellnoise" 'c' "pf" CellT4;
    "cellnoise" 'p' "pf" CellT4;
    "cellnoise" 'v' "pf" CellT4;
    "xcomp" 'f' "q" XComp;
    "ycomp" 'f' "q" YComp;
    "zcomp" 'f' "q" ZComp;
    "setxcomp" ' ' "&qf" SetXComp;
    "setycomp" ' ' "&qf" SetYComp;
    "setzcomp" ' ' "&qf" SetZComp;
    "length" 'f' "q" Length;
    "normalize" 'q' "q" Normalize;
    "distance" 'f' "pp" Distance;
    "ptlined" 'f' "ppp" PtLineD;
    "rotate" 'q' "qfpp" RotatePoint;
    "area" 'f' "p" Area;
    "faceforward" 'q' "qq" FaceForward2;
    "faceforward" 'q' "qqq" FaceForward3;
    "reflect" 'v' "vv" Reflect;
    "refract" 'v' "vvf" Refract;
    "fresnel" ' ' "vvf&f&f" Fresnel;
    "fresnel" ' ' "vvf&f&f&v&v" FresnelRT;
    "depth" 'f' "p" Depth;
    "calculatenormal" 'n' "p" CalculateNormal;
    "comp" 'f' "tf" Comp;
    "setcomp" ' ' "&tff" SetComp;
    "ctransform" 'c' "sc" CTransform1;
    "ctransform" 'c' "ssc" CTransform2;
    "comp" 'f' "mff" MComp;
    "setcomp" ' ' "&mfff" MSetComp;
    "determinant" 'f' "m" Determinant;
    "translate" 'm' "mv" MTranslate;
    "rotate" 'm' "mfv" MRotate;
    "scale" 'm' "mp" MScale;
    "concat" 's' "ss*" Concat;
    "match" 'f' "ss" Match;
    "ambient" 'c' "" Ambient;
    "diffuse" 'c' "n" Diffuse;
    "specular" 'c' "nvf" Specular;
    "specularbrdf" 'c' "vnvf" SpecularBrdf;
    "phong" 'c' "nvf" Phong;
    "trace" 'c' "pv" Trace;
    "trace" 'f' "pv" Trace;
    "isnan" 'f' "f" IsNan;
    "raylevel" 'f' "" RayLevel;
    "isshadowray" 'f' "" IsShadowRay;
    "horizon" 'f' "sffv" Horizon;
    "horizon" 'f' "sffvsf" Horizon;
    "horizon" 'f' "sffvsfsf" Horizon;
    "horizon" 'f' "sffvsfsfsf" Horizon;
    "horizon" 'f' "sffvsfsfsfsf" Horizon;
    "horizonheight" 'f' "sff" HorizonHeight;
    "horizonheight" 'f' "sffsf" HorizonHeight;
};

/// Names lowered by hand because their arguments are free-form.
pub const SPECIAL: &[&str] = &[
    "texture",
    "environment",
    "shadow",
    "textureinfo",
    "bump",
    "filterstep",
    "printf",
    "format",
    "atmosphere",
    "displacement",
    "lightsource",
    "surface",
    "incident",
    "opposite",
    "attribute",
    "option",
    "rendererinfo",
    "shadername",
    "arraylength",
    "rayinfo",
    "occlusion",
    "indirectdiffuse",
    "transmission",
    "visibility",
    "spline",
    "transform",
    "vtransform",
    "ntransform",
];

/// Whether a name is a built-in function.
pub fn is_builtin(name: &str) -> bool {
    SPECIAL.contains(&name) || SIGS.iter().any(|s| s.name == name)
}

/// The base type a type code stands for (None for `t`, `q`, `x`).
pub fn code_type(c: char) -> Option<BaseType> {
    Some(match c {
        'f' => BaseType::Float,
        's' => BaseType::String,
        'c' => BaseType::Color,
        'p' => BaseType::Point,
        'v' => BaseType::Vector,
        'n' => BaseType::Normal,
        'm' => BaseType::Matrix,
        ' ' => BaseType::Void,
        _ => return None,
    })
}

/// Parsed argument list of a signature: (code, is_output) per argument, and whether the last
/// one repeats.
pub fn parse_args(args: &str) -> (Vec<(char, bool)>, bool) {
    let mut out = Vec::new();
    let mut output = false;
    let mut repeat = false;
    for ch in args.chars() {
        match ch {
            '&' => output = true,
            '*' => repeat = true,
            c => {
                out.push((c, output));
                output = false;
            }
        }
    }
    (out, repeat)
}

/// Every overload of a name.
pub fn overloads(name: &str) -> impl Iterator<Item = &'static Sig> + '_ {
    SIGS.iter().filter(move |s| s.name == name)
}

/// One line of what each built-in does (hover and completion in `arbor lsp`), and for the
/// free-form ones (lowered by hand, not in [`SIGS`]) their signatures as RISpec writes them.
/// Every name of [`SIGS`] and [`SPECIAL`] has an entry (a test checks).
pub static DOCS: &[(&str, &[&str], &str)] = &[
    ("radians", &[], "Degrees to radians."),
    ("degrees", &[], "Radians to degrees."),
    ("sin", &[], "Sine of an angle in radians."),
    ("cos", &[], "Cosine of an angle in radians."),
    ("tan", &[], "Tangent of an angle in radians."),
    ("asin", &[], "Arc sine, in [-PI/2, PI/2]."),
    ("acos", &[], "Arc cosine, in [0, PI]."),
    ("atan", &[], "Arc tangent: atan(y/x) in [-PI/2, PI/2], or atan(y, x) in [-PI, PI]."),
    ("pow", &[], "x raised to the power y."),
    ("exp", &[], "e raised to the power x."),
    ("sqrt", &[], "Square root."),
    ("inversesqrt", &[], "1 / sqrt(x)."),
    ("log", &[], "Natural logarithm, or log(x, base) to a given base."),
    ("mod", &[], "a modulo b, always in [0, b) (unlike C's fmod for negative a)."),
    ("abs", &[], "Absolute value."),
    ("sign", &[], "-1, 0 or 1 by the sign of x."),
    ("floor", &[], "Largest integer not greater than x."),
    ("ceil", &[], "Smallest integer not less than x."),
    ("round", &[], "Nearest integer (halves away from zero)."),
    ("min", &[], "Smallest of the arguments (per component for triples)."),
    ("max", &[], "Largest of the arguments (per component for triples)."),
    ("clamp", &[], "a limited to [min, max] (per component for triples)."),
    ("mix", &[], "Linear blend (1-t)*a + t*b."),
    ("step", &[], "0 if value < min, else 1."),
    ("smoothstep", &[], "0 below min, 1 above max, a smooth Hermite ramp between."),
    ("filterstep", &["float filterstep(float edge, float s1 [, float s2] [, ...params])"], "step(edge, s) box-filtered over the width s covers on the micropolygon (anti-aliased)."),
    ("spline", &["float spline([string basis,] float value, float f0, float f1, ..., float fn)", "color spline([string basis,] float value, color c0, ..., color cn)", "float spline([string basis,] float value, float fa[])"], "Catmull-Rom (or the named basis) spline through the control values at value in [0,1]."),
    ("Du", &[], "Derivative of an expression along u (per du)."),
    ("Dv", &[], "Derivative of an expression along v (per dv)."),
    ("Deriv", &[], "Derivative of num with respect to den: Du(num)/Du(den) + Dv(num)/Dv(den)."),
    ("random", &[], "A random number (or triple) in [0,1), different at every point."),
    ("noise", &[], "Perlin noise of 1 to 4 dimensions, in [0,1], averaging 0.5."),
    ("pnoise", &[], "Periodic noise: noise with the given period in every dimension."),
    ("cellnoise", &[], "A value in [0,1) constant over each integer cell of the domain."),
    ("xcomp", &[], "x component of a point, vector or normal."),
    ("ycomp", &[], "y component of a point, vector or normal."),
    ("zcomp", &[], "z component of a point, vector or normal."),
    ("setxcomp", &[], "Sets the x component of a point, vector or normal."),
    ("setycomp", &[], "Sets the y component of a point, vector or normal."),
    ("setzcomp", &[], "Sets the z component of a point, vector or normal."),
    ("length", &[], "Euclidean length of a vector."),
    ("normalize", &[], "The vector scaled to unit length."),
    ("distance", &[], "Distance between two points."),
    ("ptlined", &[], "Distance from point Q to the segment from P0 to P1."),
    ("rotate", &[], "A point rotated by angle (radians) about the axis through P0 and P1; or a matrix rotated about an axis."),
    ("area", &[], "Area of the micropolygon around P (length of dPdu*du ^ dPdv*dv)."),
    ("faceforward", &[], "N flipped, if needed, to face against I (against Nref's side)."),
    ("reflect", &[], "I reflected about N: I - 2*(I.N)*N."),
    ("refract", &[], "I refracted through a surface with normal N and relative index eta (0 vector on total internal reflection)."),
    ("fresnel", &[], "Fresnel reflection and transmission coefficients Kr, Kt (and directions R, T) for index ratio eta."),
    ("depth", &[], "Normalized camera depth of a point: 0 at the near, 1 at the far clipping plane."),
    ("calculatenormal", &[], "Surface normal at P from its derivatives: Du(P) ^ Dv(P), oriented like N."),
    ("comp", &[], "A component of a colour or triple, or element (row, col) of a matrix."),
    ("setcomp", &[], "Sets a component of a colour, or element (row, col) of a matrix."),
    ("ctransform", &[], "A colour converted from one colour space (\"rgb\", \"hsv\", \"hsl\", \"xyz\", \"XYZ\", \"xyY\", \"YIQ\") to another."),
    ("determinant", &[], "Determinant of a matrix."),
    ("translate", &[], "The matrix followed by a translation."),
    ("scale", &[], "The matrix followed by a scale."),
    ("concat", &[], "The strings joined end to end."),
    ("format", &["string format(string pattern, ...)"], "printf-style formatting to a string (%f %d %s %c %p %m %%)."),
    ("printf", &["void printf(string pattern, ...)"], "printf-style formatting to standard error (%f %d %s %c %p %m %%)."),
    ("match", &[], "1 if the regular expression pattern matches the subject string, else 0."),
    ("ambient", &[], "Sum of the ambient light sources' Cl."),
    ("diffuse", &[], "Lambertian diffuse light on a surface with normal N: sum of Cl*(L.N)."),
    ("specular", &[], "Specular highlight (RISpec's model) for normal N, view V and roughness."),
    ("specularbrdf", &[], "The specular() term of one light direction L."),
    ("phong", &[], "Phong highlight for normal N, view V and exponent size."),
    ("trace", &[], "Colour seen along a ray from P in direction R: the hit surface's shaded Ci (black on a miss)."),
    ("occlusion", &["float occlusion(point P, normal N, float samples [, ...params])"], "Fraction of the hemisphere around N blocked by shadow-casting geometry (stratified cosine sampling); params: maxdist, coneangle, bias, samples."),
    ("indirectdiffuse", &["color indirectdiffuse(point P, normal N, float samples [, ...params])"], "Diffuse light from the surfaces around P: the mean shaded Ci of cosine-distributed rays; params: maxdist, coneangle, bias."),
    ("transmission", &["color transmission(point Psrc, point Pdst [, ...params])"], "Light passing from Psrc to Pdst through the opacity of what lies between (1: nothing in the way); params: samples, samplecone, bias."),
    ("visibility", &["color visibility(point P1, point P2)"], "BMRT: 1 where nothing blocks the segment P1–P2, through partly transparent blockers' opacity."),
    ("rayinfo", &["float rayinfo(string name, output var)"], "Ray facts: \"depth\" (0 for camera grids), \"origin\", \"direction\", \"length\" (of the ray that hit this point); 1 when known."),
    ("texture", &["float texture(string name[channel] [, float s, t [, ...4 corners]] [, ...params])", "color texture(string name[channel] [, float s, t] [, ...params])"], "Filtered texture-map lookup at (s,t) or a quadrilateral; params: blur, width, swidth, twidth, filter, fill."),
    ("environment", &["float environment(string name[channel], vector R [, ...params])", "color environment(string name[channel], vector R [, ...params])"], "Filtered environment-map lookup in direction R (lat-long or cube)."),
    ("shadow", &["float shadow(string name[channel], point P [, ...params])"], "Fraction of P in shadow in a shadow map (percentage-closer filtered): 0 lit, 1 shadowed."),
    ("textureinfo", &["float textureinfo(string name, string dataname, output type value)"], "Information about a texture file (\"resolution\", \"type\", \"channels\", \"viewingmatrix\", \"projectionmatrix\"); 1 if known."),
    ("bump", &["point bump(string name[channel], normal N, vector dPds, vector dPdt [, float s, t] [, ...params])"], "Bump-map displacement read from a bump map made with `arbor texture --bump`."),
    ("atmosphere", &["float atmosphere(string paramname, output type value)"], "Reads a parameter of the atmosphere shader; 1 if found."),
    ("displacement", &["float displacement(string paramname, output type value)"], "Reads a parameter of the displacement shader; 1 if found."),
    ("lightsource", &["float lightsource(string paramname, output type value)"], "Inside illuminance: reads a parameter of the current light; 1 if found."),
    ("surface", &["float surface(string paramname, output type value)"], "Reads a parameter of the surface shader (from a light or atmosphere); 1 if found."),
    ("incident", &["float incident(string paramname, output type value)"], "Reads a parameter of the incident volume shader; 1 if found."),
    ("opposite", &["float opposite(string paramname, output type value)"], "Reads a parameter of the opposite volume shader; 1 if found."),
    ("attribute", &["float attribute(string name, output type value)"], "Reads a graphics-state attribute (\"ShadingRate\", \"Sides\", \"identifier:name\", \"user:…\"); 1 if known."),
    ("option", &["float option(string name, output type value)"], "Reads a rendering option (\"Format\", \"FrameAspectRatio\", \"Clipping\", \"user:…\"); 1 if known."),
    ("rendererinfo", &["float rendererinfo(string name, output type value)"], "Information about the renderer (\"renderer\", \"version\", \"versionstring\"); 1 if known."),
    ("shadername", &["string shadername()", "string shadername(string shadertype)"], "Name of the current shader, or of the shader of the given type."),
    ("arraylength", &["float arraylength(type array[])"], "Number of elements of an array."),
    ("isnan", &[], "1 if x is not a number, else 0."),
    ("raylevel", &[], "Ray depth of the current shading (arbor shades camera rays only: 0)."),
    ("isshadowray", &[], "1 when shading for a shadow ray (arbor: always 0)."),
    ("horizon", &[], "Self-shadowing of a bump map from a horizon table (Max) for light direction L at (s,t): 1 lit, 0 shadowed."),
    ("horizonheight", &[], "Height read from a horizon table at (s,t)."),
    ("transform", &["point transform([string fromspace,] string tospace, point p)", "point transform([string fromspace,] matrix m, point p)", "matrix transform([string fromspace,] string tospace, matrix m)"], "A point transformed between coordinate systems (or by a matrix)."),
    ("vtransform", &["vector vtransform([string fromspace,] string tospace, vector v)", "vector vtransform([string fromspace,] matrix m, vector v)"], "A vector transformed between coordinate systems (no translation)."),
    ("ntransform", &["normal ntransform([string fromspace,] string tospace, normal n)", "normal ntransform([string fromspace,] matrix m, normal n)"], "A normal transformed between coordinate systems (by the inverse transpose)."),
];

/// The doc entry of a built-in name: (hand-written signatures, one-line description).
pub fn doc(name: &str) -> Option<(&'static [&'static str], &'static str)> {
    DOCS.iter()
        .find(|d| d.0 == name)
        .map(|&(_, sigs, line)| (sigs, line))
}

/// Every overload of a name written as RISpec does: `float noise(point)`. Hand-written
/// signatures for the free-form built-ins come first.
pub fn signatures(name: &str) -> Vec<String> {
    let mut out: Vec<String> = doc(name)
        .map(|(s, _)| s.iter().map(|s| s.to_string()).collect())
        .unwrap_or_default();
    if !out.is_empty() {
        return out;
    }
    let ty = |c: char| match c {
        't' => "type",
        'q' => "vector",
        'x' => "any",
        c => code_type(c).map(BaseType::name).unwrap_or("?"),
    };
    for s in overloads(name) {
        let (args, repeat) = parse_args(s.args);
        let mut list: Vec<String> = args
            .iter()
            .map(|&(c, o)| format!("{}{}", if o { "output " } else { "" }, ty(c)))
            .collect();
        if repeat {
            list.push("...".into());
        }
        let line = format!("{} {}({})", ty(s.ret), s.name, list.join(", "));
        if !out.contains(&line) {
            out.push(line);
        }
    }
    out
}

#[cfg(test)]
mod doc_tests {
    use super::*;

    #[test]
    fn every_builtin_has_a_doc_line() {
        for name in SIGS.iter().map(|s| s.name).chain(SPECIAL.iter().copied()) {
            let d = doc(name);
            assert!(
                d.is_some_and(|(_, l)| !l.is_empty()),
                "`{name}` has no doc line"
            );
            assert!(!signatures(name).is_empty(), "`{name}` has no signature");
        }
        for (name, ..) in DOCS {
            assert!(
                is_builtin(name),
                "doc for `{name}`, which is not a built-in"
            );
        }
    }

    #[test]
    fn signatures_read_like_rispec() {
        let s = signatures("noise");
        assert!(s.contains(&"float noise(point)".to_string()), "{s:?}");
        assert!(
            s.contains(&"color noise(point, float)".to_string()),
            "{s:?}"
        );
        let f = signatures("fresnel");
        assert_eq!(
            f[0],
            "void fresnel(vector, vector, float, output float, output float)"
        );
        assert!(signatures("texture")[0].starts_with("float texture("));
    }
}
