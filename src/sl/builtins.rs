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
    /// BMRT/PRMan `raylevel()` and `isshadowray()`: arbor shades camera rays only, so 0.
    RayLevel,
    // horizon mapping (Max): src/texture/horizon.rs
    Horizon,
    HorizonHeight,
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
    "isshadowray" 'f' "" RayLevel;
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
