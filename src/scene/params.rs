//! Parameter lists: declarations (`Declare` and inline), the standard predeclared names, and
//! value-count validation against a primitive.
//!
//! Input: the token/value tail of a request, the declaration dictionary, and what the
//! parameters are for. Output: a [`ParamList`] with resolved [`Decl`]s and flattened values.
//! Invariants: every kept primitive variable has exactly `count(class) * decl.width()` values;
//! colours are RGB (ColorSamples other than 3 are converted); point-like values stay in the
//! space they were given in (the renderer applies the transforms).

use std::collections::HashMap;

use crate::diag::{did_you_mean, Diag, Span};
use crate::rib::{Arg, Value};

use super::types::{param_name, Class, Decl, Param, ParamData, ParamList, ParamType};

/// Parses a declaration: `"[class] type['[' n ']']"`, e.g. `"varying float[2]"`.
pub fn parse_decl(text: &str) -> Result<Decl, String> {
    let t = text.trim();
    // `float [2]`: join a bracket written after a space to its type.
    let mut joined = String::with_capacity(t.len());
    for part in t.split_whitespace() {
        if !joined.is_empty()
            && !part.starts_with('[')
            && !part.starts_with(']')
            && !joined.ends_with('[')
        {
            joined.push(' ');
        }
        joined.push_str(part);
    }
    let words = joined
        .split(' ')
        .filter(|w| !w.is_empty())
        .collect::<Vec<_>>();
    let (class, ty_word) = match words.as_slice() {
        [ty] => (Class::Uniform, *ty),
        [class, ty] => (parse_class(class)?, *ty),
        [] => return Err("empty declaration".into()),
        _ => {
            return Err(format!(
                "`{t}` is not a declaration: expected `[class] type[n]`"
            ))
        }
    };
    let (ty_name, array_len) = match ty_word.find('[') {
        Some(b) => {
            let inner = ty_word[b + 1..]
                .strip_suffix(']')
                .ok_or_else(|| format!("unclosed `[` in `{ty_word}`"))?;
            let n: usize = inner
                .trim()
                .parse()
                .map_err(|_| format!("array length `{inner}` is not a positive integer"))?;
            if n == 0 || n > 1 << 20 {
                return Err(format!("array length {n} must be between 1 and 1048576"));
            }
            (&ty_word[..b], n)
        }
        None => (ty_word, 1),
    };
    let ty = parse_type(ty_name)?;
    Ok(Decl {
        class,
        ty,
        array_len,
    })
}

fn parse_class(w: &str) -> Result<Class, String> {
    Ok(match w {
        "constant" => Class::Constant,
        "uniform" => Class::Uniform,
        "varying" => Class::Varying,
        "vertex" => Class::Vertex,
        "facevarying" => Class::FaceVarying,
        "facevertex" => Class::FaceVertex,
        _ => {
            let classes = [
                "constant",
                "uniform",
                "varying",
                "vertex",
                "facevarying",
                "facevertex",
            ];
            let mut m = format!("unknown storage class `{w}`");
            if let Some(c) = did_you_mean(w, classes) {
                m.push_str(&format!(" (did you mean `{c}`?)"));
            }
            return Err(m);
        }
    })
}

fn parse_type(w: &str) -> Result<ParamType, String> {
    Ok(match w {
        "float" => ParamType::Float,
        "integer" | "int" => ParamType::Integer,
        "string" => ParamType::String,
        "color" => ParamType::Color,
        "point" => ParamType::Point,
        "vector" => ParamType::Vector,
        "normal" => ParamType::Normal,
        "hpoint" => ParamType::HPoint,
        // PRMan's Blobby "mpoint": a point with its own coordinate system, written as 16
        // numbers like a matrix (the blob's reference frame, e.g. "vertex mpoint Pref").
        "matrix" | "mpoint" => ParamType::Matrix,
        _ => {
            let types = [
                "float", "integer", "string", "color", "point", "vector", "normal", "hpoint",
                "matrix", "mpoint",
            ];
            let mut m = format!("unknown type `{w}`");
            if let Some(c) = did_you_mean(w, types) {
                m.push_str(&format!(" (did you mean `{c}`?)"));
            }
            return Err(m);
        }
    })
}

/// Splits a token into an inline declaration and a name: `"uniform float Kd"` →
/// (Some(decl), "Kd"); `"Kd"` → (None, "Kd").
pub fn split_token(token: &str) -> Result<(Option<Decl>, &str), String> {
    let t = token.trim();
    match t.rfind(char::is_whitespace) {
        None => Ok((None, t)),
        Some(p) => {
            let name = t[p..].trim();
            Ok((Some(parse_decl(&t[..p])?), name))
        }
    }
}

fn has_class_word(token: &str) -> bool {
    token.split_whitespace().next().is_some_and(|w| {
        matches!(
            w,
            "constant" | "uniform" | "varying" | "vertex" | "facevarying" | "facevertex"
        )
    })
}

/// The standard declarations every renderer knows (RISpec 3.2 Table 5.1, the standard
/// shaders' parameters, Display/Hider/Option/Attribute parameters).
pub const STANDARD: &[(&str, &str)] = &[
    ("P", "vertex point"),
    ("Pz", "vertex float"),
    ("Pw", "vertex hpoint"),
    ("N", "varying normal"),
    ("Np", "uniform normal"),
    ("Cs", "varying color"),
    ("Os", "varying color"),
    ("s", "varying float"),
    ("t", "varying float"),
    ("st", "varying float[2]"),
    ("width", "varying float"),
    ("constantwidth", "constant float"),
    ("constantnormal", "constant normal"),
    // Standard shader parameters (Tables 4.7-4.10, Appendix A).
    ("Ka", "uniform float"),
    ("Kd", "uniform float"),
    ("Ks", "uniform float"),
    ("Kr", "uniform float"),
    ("Km", "uniform float"),
    ("roughness", "uniform float"),
    ("specularcolor", "uniform color"),
    ("texturename", "uniform string"),
    ("intensity", "uniform float"),
    ("lightcolor", "uniform color"),
    ("from", "uniform point"),
    ("to", "uniform point"),
    ("coneangle", "uniform float"),
    ("conedeltaangle", "uniform float"),
    ("beamdistribution", "uniform float"),
    ("mindistance", "uniform float"),
    ("maxdistance", "uniform float"),
    ("background", "uniform color"),
    ("distance", "uniform float"),
    ("amplitude", "uniform float"),
    ("shadowname", "uniform string"),
    ("__category", "uniform string"),
    // Projection, Display, Hider, texture making.
    ("fov", "uniform float"),
    ("origin", "uniform integer[2]"),
    ("compression", "uniform string"),
    ("quality", "uniform float"),
    ("jitter", "uniform integer"),
    ("masksize", "uniform integer"),
    ("timeslots", "uniform integer"),
    ("lensslots", "uniform integer"),
    ("depthfilter", "uniform string"),
    // Option/Attribute "category:name" entries live in `known`.
];

/// The declaration dictionary: `Declare`d names over the standard ones.
#[derive(Clone, Debug)]
pub struct Dictionary {
    map: HashMap<String, Decl>,
}

impl Default for Dictionary {
    fn default() -> Dictionary {
        let mut map = HashMap::new();
        for (name, decl) in STANDARD
            .iter()
            .copied()
            .chain(super::known::KNOWN.iter().map(|(k, d, _)| (*k, *d)))
        {
            if let Ok(d) = parse_decl(decl) {
                map.insert(name.to_string(), d);
            }
        }
        Dictionary { map }
    }
}

impl Dictionary {
    pub fn declare(&mut self, name: &str, decl: Decl) {
        self.map.insert(name.to_string(), decl);
    }
    pub fn get(&self, name: &str) -> Option<Decl> {
        self.map.get(name).copied()
    }
    /// For `Option`/`Attribute`: "category:name" first, then the bare name.
    pub fn get_in(&self, category: &str, name: &str) -> Option<Decl> {
        self.map
            .get(&format!("{category}:{name}"))
            .or_else(|| self.map.get(name))
            .copied()
    }
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.map.keys().map(String::as_str)
    }
}

/// What a parameter list belongs to, which decides how undeclared names are handled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamUse<'a> {
    /// Primitive variables: undeclared names are errors.
    Primitive,
    /// Shader (and display/hider/projection) parameters: an undeclared name is passed with the
    /// type read from its value (`float[n]` or `string[n]`); the shader's own declaration
    /// decides how it binds.
    Shader,
    /// `Option`/`Attribute` of the given category: looked up as "category:name" first;
    /// undeclared names warn and are kept with the type read from the value.
    Category(&'a str),
}

/// Converts n-component colours to RGB (`ColorSamples`): rgb[j] = Σ c[i]·nRGB[3i+j].
#[derive(Clone, Debug, PartialEq)]
pub struct ColorMap {
    pub n: usize,
    pub n_rgb: Vec<f32>,
}

impl ColorMap {
    pub fn to_rgb(&self, c: &[f32], out: &mut Vec<f32>) {
        for j in 0..3 {
            let mut v = 0.0;
            for i in 0..self.n {
                v += c[i] * self.n_rgb[3 * i + j];
            }
            out.push(v);
        }
    }
}

/// Reads a parameter list. Errors and warnings go to `report`; bad entries are dropped.
pub fn parse_params(
    rest: &[Arg],
    dict: &Dictionary,
    usage: ParamUse<'_>,
    colors: Option<&ColorMap>,
    request: &str,
    report: &mut dyn FnMut(Diag),
) -> ParamList {
    let mut out = Vec::with_capacity(rest.len() / 2);
    let mut i = 0;
    while i < rest.len() {
        let tok = &rest[i];
        let Value::Str(token) = &tok.value else {
            report(
                Diag::error(
                    "scene::paramlist",
                    format!(
                        "`{request}`: expected a parameter name (a string), found {}",
                        tok.value.describe()
                    ),
                )
                .label(tok.span, "expected a \"name\" here")
                .help("a parameter list alternates \"name\" and value: \"Kd\" [0.5]"),
            );
            i += 1;
            continue;
        };
        let Some(first) = rest.get(i + 1) else {
            report(
                Diag::error(
                    "scene::paramlist",
                    format!("`{request}`: parameter \"{token}\" has no value"),
                )
                .label(tok.span, "no value follows")
                .help("a parameter list alternates \"name\" and value: \"Kd\" [0.5]"),
            );
            break;
        };
        let run = unbracketed_run(&rest[i + 1..]);
        let gathered;
        let val = if run > 1 {
            gathered = gather_numbers(&rest[i + 1..i + 1 + run]);
            report(
                Diag::warning(
                    "scene::paramlist",
                    format!(
                        "`{request}`: the {run} values of \"{token}\" are not in brackets; read as one array"
                    ),
                )
                .label(gathered.span, "unbracketed values")
                .help("write an array in brackets: \"from\" [0 0 -1]"),
            );
            &gathered
        } else {
            first
        };
        i += 1 + run.max(1);
        let (inline, name) = match split_token(token) {
            Ok(x) => x,
            Err(e) => {
                report(
                    Diag::error(
                        "scene::declaration",
                        format!("`{request}`: bad inline declaration \"{token}\": {e}"),
                    )
                    .label(tok.span, "bad declaration")
                    .help("write it as \"[class] type[n] name\", e.g. \"varying float[2] st\""),
                );
                continue;
            }
        };
        let known = match usage {
            ParamUse::Category(c) => dict.get_in(c, name),
            _ => dict.get(name),
        };
        // An inline declaration without a class ("float[2] st") keeps the class of the
        // standing declaration of that name, if any (else uniform, the spec's default).
        let decl = match (inline, known) {
            (Some(mut d), Some(k)) if !has_class_word(token) => {
                d.class = k.class;
                Some(d)
            }
            (Some(d), _) => Some(d),
            (None, k) => k,
        };
        let decl = match decl {
            Some(d) => d,
            None => {
                let guessed = Decl {
                    class: Class::Uniform,
                    ty: if val.value.is_string() {
                        ParamType::String
                    } else {
                        ParamType::Float
                    },
                    array_len: val.value.len().max(1),
                };
                match usage {
                    ParamUse::Shader => guessed,
                    ParamUse::Category(c) => {
                        report(
                            Diag::warning(
                                "scene::undeclared",
                                format!(
                                    "`{request} \"{c}\"`: \"{name}\" is not declared; kept as {} {}",
                                    if guessed.ty == ParamType::String { "string" } else { "float" },
                                    guessed.array_len
                                ),
                            )
                            .label(tok.span, "not declared")
                            .help(format!(
                                "give its type inline, e.g. \"integer {name}\", or `Declare \"{name}\" \"integer\"`"
                            )),
                        );
                        guessed
                    }
                    ParamUse::Primitive => {
                        let mut d = Diag::error(
                            "scene::undeclared",
                            format!("`{request}`: parameter \"{name}\" is not declared"),
                        )
                        .label(tok.span, "unknown parameter");
                        let help = format!(
                            "add `Declare \"{name}\" \"varying float\"` before it, or declare it inline: \"varying float {name}\""
                        );
                        d = match did_you_mean(name, dict.names().filter(|n| !n.contains(':'))) {
                            Some(m) => d.help(format!("did you mean \"{m}\"? otherwise {help}")),
                            None => d.help(help),
                        };
                        report(d);
                        continue;
                    }
                }
            }
        };
        let span = tok.span.to(val.span);
        let data = if decl.ty == ParamType::String {
            match val.value.to_strings() {
                Some(s) => ParamData::Strings(s),
                None => {
                    report(type_mismatch(request, name, &decl, val, tok.span));
                    continue;
                }
            }
        } else {
            match val.value.to_f32s() {
                Some(f) => {
                    let f = match (decl.ty, colors) {
                        (ParamType::Color, Some(cm)) if cm.n != 3 => {
                            if f.len() % cm.n != 0 {
                                report(
                                    Diag::error(
                                        "scene::count",
                                        format!(
                                            "`{request}`: color \"{name}\" needs a multiple of {} numbers (ColorSamples), found {}",
                                            cm.n,
                                            f.len()
                                        ),
                                    )
                                    .label(val.span, format!("{} numbers", f.len())),
                                );
                                continue;
                            }
                            let mut rgb = Vec::with_capacity(f.len() / cm.n * 3);
                            for c in f.chunks_exact(cm.n) {
                                cm.to_rgb(c, &mut rgb);
                            }
                            rgb
                        }
                        _ => f,
                    };
                    ParamData::Floats(f)
                }
                None => {
                    report(type_mismatch(request, name, &decl, val, tok.span));
                    continue;
                }
            }
        };
        out.push(Param {
            name: param_name(name),
            decl,
            data,
            span,
        });
    }
    ParamList(out)
}

/// How many single numbers open `vals` (an array or a string ends the run). Early exporters
/// (RIBMosaic before 2011) wrote `"from" 0 0 -1` for `"from" [0 0 -1]`: a run of two or more
/// is read as that parameter's array, where every later number would otherwise be an error
/// and the value one number short (the request's light or colour lost).
fn unbracketed_run(vals: &[Arg]) -> usize {
    vals.iter()
        .take_while(|a| matches!(a.value, Value::Int(_) | Value::Float(_)))
        .count()
}

/// One array argument holding the numbers of `run` (ints stay ints when all are).
fn gather_numbers(run: &[Arg]) -> Arg {
    let span = run[0].span.to(run[run.len() - 1].span);
    let value = if run.iter().all(|a| matches!(a.value, Value::Int(_))) {
        Value::IntArray(
            run.iter()
                .map(|a| match a.value {
                    Value::Int(v) => v,
                    _ => 0,
                })
                .collect(),
        )
    } else {
        Value::FloatArray(run.iter().filter_map(|a| a.value.as_f32()).collect())
    };
    Arg { value, span }
}

fn type_mismatch(request: &str, name: &str, decl: &Decl, val: &Arg, tok: Span) -> Diag {
    let want = if decl.ty == ParamType::String {
        "strings"
    } else {
        "numbers"
    };
    Diag::error(
        "scene::param-type",
        format!(
            "`{request}`: \"{name}\" is {} and needs {want}, found {}",
            decl_text(decl),
            val.value.describe()
        ),
    )
    .label(val.span, format!("expected {want}"))
    .label(tok, "declared here or by Declare")
}

/// "varying float[2]" back as text.
pub fn decl_text(d: &Decl) -> String {
    let class = match d.class {
        Class::Constant => "constant",
        Class::Uniform => "uniform",
        Class::Varying => "varying",
        Class::Vertex => "vertex",
        Class::FaceVarying => "facevarying",
        Class::FaceVertex => "facevertex",
    };
    let ty = match d.ty {
        ParamType::Float => "float",
        ParamType::Integer => "integer",
        ParamType::String => "string",
        ParamType::Color => "color",
        ParamType::Point => "point",
        ParamType::Vector => "vector",
        ParamType::Normal => "normal",
        ParamType::HPoint => "hpoint",
        ParamType::Matrix => "matrix",
    };
    if d.array_len == 1 {
        format!("{class} {ty}")
    } else {
        format!("{class} {ty}[{}]", d.array_len)
    }
}

/// How many elements each storage class takes on one primitive (RISpec §5 and Table 5.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Counts {
    pub uniform: usize,
    pub varying: usize,
    pub vertex: usize,
    pub facevarying: usize,
    pub facevertex: usize,
}

impl Counts {
    /// Quadrics and single patches: 1 uniform, 4 varying (the parametric corners).
    pub const fn corners(vertex: usize) -> Counts {
        Counts {
            uniform: 1,
            varying: 4,
            vertex,
            facevarying: 4,
            facevertex: 4,
        }
    }
    pub fn of(&self, class: Class) -> usize {
        match class {
            Class::Constant => 1,
            Class::Uniform => self.uniform,
            Class::Varying => self.varying,
            Class::Vertex => self.vertex,
            Class::FaceVarying => self.facevarying,
            Class::FaceVertex => self.facevertex,
        }
    }
}

/// Drops (with an error) every parameter whose value count does not match `counts`.
pub fn validate_counts(
    list: &mut ParamList,
    counts: &Counts,
    request: &str,
    report: &mut dyn FnMut(Diag),
) {
    list.0.retain_mut(|p| {
        let n = counts.of(p.decl.class);
        let want = n.saturating_mul(p.decl.width());
        if p.data.len() == want {
            return true;
        }
        let unit = if p.decl.ty == ParamType::String {
            "strings"
        } else {
            "numbers"
        };
        if want > 0 && p.data.len() > want {
            // Exporters leave unused vertices after the last one a mesh indexes, and hand-
            // written files a stray number; other renderers read the values they need.
            report(
                Diag::warning(
                    "scene::count",
                    format!(
                        "`{request}`: \"{}\" ({}) needs {want} {unit}, found {}; the last {} \
                         are ignored",
                        p.name,
                        decl_text(&p.decl),
                        p.data.len(),
                        p.data.len() - want
                    ),
                )
                .label(p.span, format!("{} {unit}", p.data.len())),
            );
            match &mut p.data {
                ParamData::Floats(f) => f.truncate(want),
                ParamData::Strings(v) => v.truncate(want),
            }
            return true;
        }
        if p.data.len() == p.decl.width() && p.decl.ty != ParamType::String {
            // One value where one per element was declared (PRMan's Blobby examples give
            // `"color Cs" [.1 .9 .2]` to three blobs, `Cs` being varying): one value for the
            // whole primitive, which is what other renderers make of it.
            report(
                Diag::warning(
                    "scene::count",
                    format!(
                        "`{request}`: \"{}\" ({}) needs {want} {unit}, found one value; it is \
                         read as constant",
                        p.name,
                        decl_text(&p.decl),
                    ),
                )
                .label(p.span, format!("{} {unit}", p.data.len()))
                .help("declare it \"constant\" (or \"uniform\") to say so"),
            );
            p.decl.class = Class::Constant;
            return true;
        }
        report(
            Diag::error(
                "scene::count",
                format!(
                    "`{request}`: \"{}\" ({}) needs {want} {unit}, found {}",
                    p.name,
                    decl_text(&p.decl),
                    p.data.len()
                ),
            )
            .label(p.span, format!("{} {unit}", p.data.len()))
            .help(format!(
                "{} {} value{} of {} number{} each",
                n,
                class_word(p.decl.class),
                if n == 1 { "" } else { "s" },
                p.decl.width(),
                if p.decl.width() == 1 { "" } else { "s" }
            )),
        );
        false
    });
}

fn class_word(c: Class) -> &'static str {
    match c {
        Class::Constant => "constant",
        Class::Uniform => "uniform",
        Class::Varying => "varying",
        Class::Vertex => "vertex",
        Class::FaceVarying => "facevarying",
        Class::FaceVertex => "facevertex",
    }
}

/// Checks shader-style parameters (one element each, whatever the class).
pub fn validate_single(list: &mut ParamList, request: &str, report: &mut dyn FnMut(Diag)) {
    validate_counts(
        list,
        &Counts {
            uniform: 1,
            varying: 1,
            vertex: 1,
            facevarying: 1,
            facevertex: 1,
        },
        request,
        report,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arg(v: Value, at: usize) -> Arg {
        Arg {
            value: v,
            span: Span::new(0, at, at + 1),
        }
    }

    #[test]
    fn declarations_parse() {
        let d = parse_decl("varying float[2]").unwrap();
        assert_eq!(
            d,
            Decl {
                class: Class::Varying,
                ty: ParamType::Float,
                array_len: 2
            }
        );
        assert_eq!(d.width(), 2);
        assert_eq!(parse_decl("color").unwrap().class, Class::Uniform);
        assert_eq!(parse_decl("vertex hpoint").unwrap().width(), 4);
        assert_eq!(parse_decl("float [3]").unwrap().array_len, 3);
        assert!(parse_decl("varyng float").unwrap_err().contains("varying"));
        assert!(parse_decl("colour").is_err());
    }

    #[test]
    fn inline_tokens_split() {
        let (d, n) = split_token("uniform float Kd").unwrap();
        assert_eq!(n, "Kd");
        assert_eq!(d.unwrap().ty, ParamType::Float);
        let (d, n) = split_token("Kd").unwrap();
        assert!(d.is_none());
        assert_eq!(n, "Kd");
        let (d, n) = split_token("constant string foo").unwrap();
        assert_eq!((d.unwrap().class, n), (Class::Constant, "foo"));
    }

    #[test]
    fn undeclared_primvar_is_an_error() {
        let dict = Dictionary::default();
        let rest = vec![
            arg(Value::Str("temperature".into()), 0),
            arg(Value::FloatArray(vec![1.0; 4]), 2),
        ];
        let mut errs = vec![];
        let l = parse_params(
            &rest,
            &dict,
            ParamUse::Primitive,
            None,
            "Sphere",
            &mut |d| errs.push(d),
        );
        assert!(l.0.is_empty());
        assert_eq!(errs.len(), 1);
        assert!(errs[0].help.as_ref().unwrap().contains("Declare"));
    }

    #[test]
    fn counts_are_checked() {
        let dict = Dictionary::default();
        let rest = vec![
            arg(Value::Str("P".into()), 0),
            arg(Value::FloatArray(vec![0.0; 12]), 2),
            arg(Value::Str("Cs".into()), 4),
            arg(Value::FloatArray(vec![1.0; 9]), 6),
        ];
        let mut errs = vec![];
        let mut l = parse_params(
            &rest,
            &dict,
            ParamUse::Primitive,
            None,
            "Polygon",
            &mut |d| errs.push(d),
        );
        let c = Counts {
            uniform: 1,
            varying: 4,
            vertex: 4,
            facevarying: 4,
            facevertex: 4,
        };
        validate_counts(&mut l, &c, "Polygon", &mut |d| errs.push(d));
        assert_eq!(l.0.len(), 1);
        assert_eq!(errs.len(), 1);
        assert!(
            errs[0].message.contains("needs 12 numbers, found 9"),
            "{}",
            errs[0].message
        );
    }

    #[test]
    fn one_value_for_a_varying_variable_is_read_as_constant() {
        // PRMan's Blobby example check.rib: `"color Cs" [.1 .9 .2]` on three blobs, and the
        // "mpoint" type of its `"vertex mpoint Pref"` (16 numbers per blob).
        let dict = Dictionary::default();
        let rest = vec![
            arg(Value::Str("color Cs".into()), 0),
            arg(Value::FloatArray(vec![0.1, 0.9, 0.2]), 2),
            arg(Value::Str("vertex mpoint Pref".into()), 4),
            arg(Value::FloatArray(vec![1.0; 48]), 6),
        ];
        let mut errs = vec![];
        let mut l = parse_params(
            &rest,
            &dict,
            ParamUse::Primitive,
            None,
            "Blobby",
            &mut |d| errs.push(d),
        );
        assert!(errs.is_empty(), "{errs:?}");
        let c = Counts {
            uniform: 1,
            varying: 3,
            vertex: 3,
            facevarying: 3,
            facevertex: 3,
        };
        validate_counts(&mut l, &c, "Blobby", &mut |d| errs.push(d));
        assert_eq!(l.0.len(), 2);
        assert_eq!(l.0[0].decl.class, Class::Constant);
        assert_eq!(l.0[1].decl.ty, ParamType::Matrix);
        assert_eq!(errs.len(), 1);
        assert!(!errs[0].is_error(), "{}", errs[0].message);
        assert!(errs[0].message.contains("read as constant"));
    }

    #[test]
    fn extra_values_are_ignored_with_a_warning() {
        let dict = Dictionary::default();
        let rest = vec![
            arg(Value::Str("P".into()), 0),
            arg(
                Value::FloatArray(vec![
                    0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0, 5.0, 5.0, 5.0,
                ]),
                2,
            ),
            arg(Value::Str("st".into()), 4),
            arg(
                Value::FloatArray(vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.5]),
                6,
            ),
        ];
        let mut errs = Vec::new();
        let mut l = parse_params(
            &rest,
            &dict,
            ParamUse::Primitive,
            None,
            "PointsPolygons",
            &mut |d| errs.push(d),
        );
        let c = Counts {
            uniform: 1,
            varying: 3,
            vertex: 3,
            facevarying: 3,
            facevertex: 3,
        };
        validate_counts(&mut l, &c, "PointsPolygons", &mut |d| errs.push(d));
        assert_eq!(l.0.len(), 2, "both kept");
        assert_eq!(
            l.0[0].data.floats(),
            &[0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0]
        );
        assert_eq!(l.0[1].data.floats(), &[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]);
        assert_eq!(errs.len(), 2);
        assert!(errs.iter().all(|d| !d.is_error()), "{errs:?}");
        assert!(
            errs[0].message.contains("the last 3 are ignored"),
            "{}",
            errs[0].message
        );
    }

    #[test]
    fn color_samples_convert_to_rgb() {
        let dict = Dictionary::default();
        // One-sample (grey) colours: rgb = (g, g, g).
        let cm = ColorMap {
            n: 1,
            n_rgb: vec![1.0, 1.0, 1.0],
        };
        let rest = vec![
            arg(Value::Str("Cs".into()), 0),
            arg(Value::FloatArray(vec![0.25, 0.5]), 2),
        ];
        let l = parse_params(
            &rest,
            &dict,
            ParamUse::Primitive,
            Some(&cm),
            "Points",
            &mut |_| panic!(),
        );
        assert_eq!(l.floats("Cs").unwrap(), &[0.25, 0.25, 0.25, 0.5, 0.5, 0.5]);
    }

    #[test]
    fn undeclared_shader_parameter_keeps_its_numbers() {
        let dict = Dictionary::default();
        let rest = vec![
            arg(Value::Str("frequency".into()), 0),
            arg(Value::Int(4), 2),
        ];
        let l = parse_params(
            &rest,
            &dict,
            ParamUse::Shader,
            None,
            "Surface",
            &mut |_| panic!(),
        );
        assert_eq!(l.float("frequency"), Some(4.0));
    }
}
