//! RIB input: ASCII (pest grammar `grammar/rib.pest`), binary (RISpec C.1) and gzip.
//!
//! Input: bytes of a RIB stream, registered in the `SourceMap` (pure ASCII as is; a stream
//! with binary tokens as its decoded ASCII form, see `binary.rs`; gzip is decompressed first).
//! Output: a stream of [`Request`]s, each with the span of its name and of every argument;
//! [`format_requests`] prints requests back as canonical ASCII RIB.
//! Invariants: a syntax error costs at most one request (the reader resynchronises at the next
//! request name, RISpec C.2.2); numbers in arrays are read without a pest pair per number.

use crate::diag::Span;

/// One RIB argument value. Integers stay integers (nverts, handles); a number array holding
/// any real is a float array.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Int(i64),
    Float(f32),
    Str(String),
    IntArray(Vec<i64>),
    FloatArray(Vec<f32>),
    StrArray(Vec<String>),
}

impl Value {
    /// A single number (or a one-element number array) as f32.
    pub fn as_f32(&self) -> Option<f32> {
        match self {
            Value::Int(i) => Some(*i as f32),
            Value::Float(f) => Some(*f),
            Value::IntArray(a) if a.len() == 1 => Some(a[0] as f32),
            Value::FloatArray(a) if a.len() == 1 => Some(a[0]),
            _ => None,
        }
    }
    /// Every number of a number or a number array, as f32.
    pub fn to_f32s(&self) -> Option<Vec<f32>> {
        match self {
            Value::Int(i) => Some(vec![*i as f32]),
            Value::Float(f) => Some(vec![*f]),
            Value::IntArray(a) => Some(a.iter().map(|&i| i as f32).collect()),
            Value::FloatArray(a) => Some(a.clone()),
            _ => None,
        }
    }
    /// Every number as an integer; reals with a fraction are refused.
    pub fn to_ints(&self) -> Option<Vec<i64>> {
        match self {
            Value::Int(i) => Some(vec![*i]),
            Value::IntArray(a) => Some(a.clone()),
            Value::Float(f) if f.fract() == 0.0 => Some(vec![*f as i64]),
            Value::FloatArray(a) if a.iter().all(|f| f.fract() == 0.0) => {
                Some(a.iter().map(|&f| f as i64).collect())
            }
            _ => None,
        }
    }
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            Value::StrArray(a) if a.len() == 1 => Some(&a[0]),
            _ => None,
        }
    }
    pub fn to_strings(&self) -> Option<Vec<String>> {
        match self {
            Value::Str(s) => Some(vec![s.clone()]),
            Value::StrArray(a) => Some(a.clone()),
            _ => None,
        }
    }
    /// How many values this holds (1 for a scalar).
    pub fn len(&self) -> usize {
        match self {
            Value::Int(_) | Value::Float(_) | Value::Str(_) => 1,
            Value::IntArray(a) => a.len(),
            Value::FloatArray(a) => a.len(),
            Value::StrArray(a) => a.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn is_string(&self) -> bool {
        matches!(self, Value::Str(_) | Value::StrArray(_))
    }
    pub fn is_array(&self) -> bool {
        matches!(
            self,
            Value::IntArray(_) | Value::FloatArray(_) | Value::StrArray(_)
        )
    }
    /// A short description for error messages ("a string", "an array of 3 numbers").
    pub fn describe(&self) -> String {
        match self {
            Value::Int(_) | Value::Float(_) => "a number".into(),
            Value::Str(_) => "a string".into(),
            Value::IntArray(a) => format!("an array of {} numbers", a.len()),
            Value::FloatArray(a) => format!("an array of {} numbers", a.len()),
            Value::StrArray(a) => format!("an array of {} strings", a.len()),
        }
    }
}

/// One argument with the span it was read from.
#[derive(Clone, Debug, PartialEq)]
pub struct Arg {
    pub value: Value,
    pub span: Span,
}

/// One RIB request: its name as written and its arguments in order (positional arguments
/// first, then the parameter list as alternating token strings and values).
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    pub name: String,
    pub span: Span,
    pub args: Vec<Arg>,
}

impl Request {
    /// The span from the name to the last argument.
    pub fn full_span(&self) -> Span {
        self.args
            .last()
            .map(|a| self.span.to(a.span))
            .unwrap_or(self.span)
    }
}

use crate::diag::{Diag, Diagnostics, SourceMap};

mod ascii;
mod binary;
pub mod format;
mod lex;

pub use format::{format_requests, format_source};

/// Reads RIB bytes (ASCII, binary or gzip, detected from the content), registering the text
/// under `name` in `sources`. Syntax errors are reported to `diags`; the requests that could be
/// read are returned.
///
/// Gzip input (magic bytes 1f 8b) is decompressed first. Pure ASCII is registered as is; a
/// stream holding binary tokens (RISpec C.1, possibly mixed with ASCII) is registered as its
/// decoded ASCII text, and spans are byte offsets into that registered text.
pub fn parse_bytes(
    name: &str,
    bytes: &[u8],
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Vec<Request> {
    let mut out = Vec::new();
    if let Some(src) = register(name, bytes.into(), sources, diags) {
        src.parse(diags, &mut |r| out.push(r));
    }
    out
}

/// A RIB stream registered in the `SourceMap`, ready to be read.
struct Registered {
    text: std::sync::Arc<str>,
    file: u32,
    /// Positions where the binary decoder already reported a problem.
    quiet: Vec<usize>,
}

impl Registered {
    fn parse(&self, diags: &Diagnostics, sink: &mut dyn FnMut(Request)) {
        ascii::parse_text_into(&self.text, self.file, diags, &self.quiet, sink);
    }
}

/// Decompresses and decodes `bytes` (consumed, so a large file is not held twice while it is
/// read) and registers the text. None when the gzip stream is broken (reported).
fn register(
    name: &str,
    bytes: std::borrow::Cow<'_, [u8]>,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Option<Registered> {
    let mut data = bytes;
    if data.starts_with(&[0x1f, 0x8b]) {
        match gunzip(&data) {
            Ok(v) => data = v.into(),
            Err(e) => {
                let file = sources.add(name, "");
                diags.report(
                    Diag::error("rib::gzip", format!("cannot decompress `{name}`: {e}"))
                        .label(Span::new(file, 0, 0), "gzip stream starts here")
                        .help(
                            "the file starts with the gzip magic bytes 1f 8b but is not valid gzip",
                        ),
                );
                return None;
            }
        }
    }
    if data.is_ascii() {
        // Pure ASCII: always valid UTF-8.
        let text: std::sync::Arc<str> = String::from_utf8_lossy(&data).into();
        drop(data);
        let file = sources.add(name, text.clone());
        return Some(Registered {
            text,
            file,
            quiet: Vec::new(),
        });
    }
    let (decoded, issues) = binary::transcode(&data);
    drop(data);
    let text: std::sync::Arc<str> = decoded.into();
    let file = sources.add(name, text.clone());
    let mut quiet = Vec::new();
    for is in issues {
        let rest = text.as_bytes().get(is.at..).unwrap_or_default();
        let len = if rest.starts_with(binary::UNDEFINED_REQUEST.as_bytes()) {
            binary::UNDEFINED_REQUEST.len()
        } else {
            1
        };
        let end = (is.at + len).min(text.len()).max(is.at);
        let d = if is.error {
            Diag::error("rib::binary", is.message)
        } else {
            Diag::warning("rib::binary", is.message)
        };
        diags.report(d.label(Span::new(file, is.at, end), "here").help(is.help));
        if is.placeholder {
            quiet.push(is.at);
        }
    }
    quiet.sort_unstable();
    Some(Registered { text, file, quiet })
}

fn gunzip(data: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::with_capacity(data.len() * 4);
    std::io::Read::read_to_end(&mut flate2::read::MultiGzDecoder::new(data), &mut out)?;
    Ok(out)
}

/// Reads a RIB file from disk ("-" reads stdin).
pub fn read_path(
    path: &std::path::Path,
    sources: &SourceMap,
    diags: &Diagnostics,
) -> Result<Vec<Request>, Diag> {
    let mut out = Vec::new();
    read_path_into(path, sources, diags, &mut |r| out.push(r))?;
    Ok(out)
}

/// [`read_path`], handing each request to `sink` as soon as it is read: the requests of a
/// large file are never all in memory at once.
pub fn read_path_into(
    path: &std::path::Path,
    sources: &SourceMap,
    diags: &Diagnostics,
    sink: &mut dyn FnMut(Request),
) -> Result<(), Diag> {
    let bytes = if path.as_os_str() == "-" {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut std::io::stdin(), &mut v)
            .map_err(|e| Diag::error("rib::io", format!("cannot read standard input: {e}")))?;
        v
    } else {
        std::fs::read(path)
            .map_err(|e| Diag::error("rib::io", format!("cannot read `{}`: {e}", path.display())))?
    };
    if let Some(src) = register(&path.display().to_string(), bytes.into(), sources, diags) {
        src.parse(diags, sink);
    }
    Ok(())
}
