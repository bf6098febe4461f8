//! Canonical ASCII RIB printer (`arbor format`).
//!
//! Input: requests. Output: ASCII RIB with one request per line, two spaces of indentation
//! per open `*Begin` block (`Else`/`ElseIf` sit at their `IfBegin`'s level), strings escaped.
//! Invariants: reading the output back gives the same names and values: reals are printed in
//! Rust's shortest round-trip form (always with `.` or an exponent, so they stay reals) and
//! integers as integers. Only an empty array has no type in RIB: it reads back as an empty
//! `IntArray`.

use std::fmt::Write;

use super::lex::{escape_into, write_f32};
use super::{Request, Value};

/// Pretty-prints requests as canonical ASCII RIB.
pub fn format_requests(reqs: &[Request]) -> String {
    let mut out = String::new();
    let mut depth = 0usize;
    for r in reqs {
        let n = r.name.as_str();
        if n.len() > 3 && n.ends_with("End") {
            depth = depth.saturating_sub(1);
        }
        let indent = if n == "Else" || n == "ElseIf" {
            depth.saturating_sub(1)
        } else {
            depth
        };
        for _ in 0..indent {
            out.push_str("  ");
        }
        out.push_str(n);
        for a in &r.args {
            out.push(' ');
            write_value(&mut out, &a.value);
        }
        out.push('\n');
        if n.len() > 5 && n.ends_with("Begin") {
            depth += 1;
        }
    }
    out
}

/// [`format_requests`] keeping the comments and blank lines of the text the requests were read
/// from (`text` is the registered source their spans point into). A comment on the line where a
/// request ends stays at that line's end; any other comment gets its own line at the next
/// request's indentation (one written between a request's arguments goes just before it);
/// runs of blank lines become one.
pub fn format_source(text: &str, reqs: &[Request]) -> String {
    let mut out = String::new();
    let mut depth = 0usize;
    let mut pos = 0usize;
    let mut first = true;
    for r in reqs {
        let start = (r.span.start as usize).min(text.len()).max(pos);
        let end = (r.full_span().end as usize).min(text.len()).max(start);
        let n = r.name.as_str();
        if n.len() > 3 && n.ends_with("End") {
            depth = depth.saturating_sub(1);
        }
        let indent = if n == "Else" || n == "ElseIf" {
            depth.saturating_sub(1)
        } else {
            depth
        };
        gap(&mut out, &text[pos..start], indent, first);
        for c in comments(&text[start..end]) {
            push_indent(&mut out, indent);
            out.push_str(c);
            out.push('\n');
        }
        push_indent(&mut out, indent);
        out.push_str(n);
        for a in &r.args {
            out.push(' ');
            write_value(&mut out, &a.value);
        }
        out.push('\n');
        if n.len() > 5 && n.ends_with("Begin") {
            depth += 1;
        }
        pos = end;
        first = false;
    }
    gap(&mut out, &text[pos.min(text.len())..], depth, first);
    out
}

fn push_indent(out: &mut String, depth: usize) {
    for _ in 0..depth {
        out.push_str("  ");
    }
}

/// Writes the comments of the whitespace-and-comment text between two requests.
fn gap(out: &mut String, gap: &str, indent: usize, at_start: bool) {
    let mut newlines = 0usize;
    let mut rest = gap;
    while let Some(i) = rest.find(|c: char| c == '#' || c == '\n') {
        if rest.as_bytes()[i] == b'\n' {
            newlines += 1;
            rest = &rest[i + 1..];
            continue;
        }
        let line_end = rest[i..].find('\n').map_or(rest.len(), |e| i + e);
        let c = rest[i..line_end].trim_end();
        if newlines == 0 && !at_start {
            // On the previous request's line: keep it there.
            if out.ends_with('\n') {
                out.pop();
            }
            out.push(' ');
        } else {
            if newlines > 1 && !out.is_empty() {
                out.push('\n');
            }
            push_indent(out, indent);
        }
        out.push_str(c);
        out.push('\n');
        newlines = 0;
        rest = &rest[line_end..];
    }
    if newlines > 1 && !out.is_empty() && !at_start {
        out.push('\n');
    }
}

/// The comments inside one request's text (outside its strings).
fn comments(text: &str) -> Vec<&str> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'"' => {
                i += 1;
                while i < b.len() && b[i] != b'"' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
            }
            b'#' => {
                let e = text[i..].find('\n').map_or(text.len(), |e| i + e);
                out.push(text[i..e].trim_end());
                i = e;
            }
            _ => i += 1,
        }
    }
    out
}

/// Writes one value in RIB syntax.
pub fn write_value(out: &mut String, v: &Value) {
    match v {
        Value::Int(i) => {
            let _ = write!(out, "{i}");
        }
        Value::Float(f) => write_f32(out, *f),
        Value::Str(s) => escape_into(out, s),
        Value::IntArray(a) => {
            out.push('[');
            for (k, i) in a.iter().enumerate() {
                if k > 0 {
                    out.push(' ');
                }
                let _ = write!(out, "{i}");
            }
            out.push(']');
        }
        Value::FloatArray(a) => {
            out.push('[');
            for (k, f) in a.iter().enumerate() {
                if k > 0 {
                    out.push(' ');
                }
                write_f32(out, *f);
            }
            out.push(']');
        }
        Value::StrArray(a) => {
            out.push('[');
            for (k, s) in a.iter().enumerate() {
                if k > 0 {
                    out.push(' ');
                }
                escape_into(out, s);
            }
            out.push(']');
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diag::Span;
    use crate::rib::Arg;

    fn req(name: &str, args: Vec<Value>) -> Request {
        Request {
            name: name.into(),
            span: Span::default(),
            args: args
                .into_iter()
                .map(|value| Arg {
                    value,
                    span: Span::default(),
                })
                .collect(),
        }
    }

    #[test]
    fn format_source_keeps_comments_and_blank_lines() {
        let text = "##RenderMan RIB\nWorldBegin # the world\n\n\n# a sphere\nSphere 1 -1 1 360 # r\nAttributeBegin\nColor [1 0 0]\n  # inside\nAttributeEnd\nWorldEnd\n# end\n";
        let sources = crate::diag::SourceMap::new();
        let diags = crate::diag::Diagnostics::new();
        let reqs = crate::rib::parse_bytes("t.rib", text.as_bytes(), &sources, &diags);
        let out = format_source(text, &reqs);
        assert_eq!(
            out,
            "##RenderMan RIB\nWorldBegin # the world\n\n  # a sphere\n  Sphere 1 -1 1 360 # r\n  AttributeBegin\n    Color [1 0 0]\n  # inside\n  AttributeEnd\nWorldEnd\n# end\n"
        );
        let again = crate::rib::parse_bytes("u.rib", out.as_bytes(), &sources, &diags);
        assert_eq!(format_source(&out, &again), out);
        assert_eq!(again.len(), reqs.len());
    }

    #[test]
    fn indents_blocks_and_prints_values() {
        let reqs = vec![
            req("WorldBegin", vec![]),
            req("IfBegin", vec![Value::Str("a\"b".into())]),
            req(
                "Color",
                vec![Value::FloatArray(vec![1.0, 0.5, 1e-7]), Value::Int(-3)],
            ),
            req("Else", vec![]),
            req("S", vec![Value::StrArray(vec!["x\ny".into()])]),
            req("IfEnd", vec![]),
            req("WorldEnd", vec![]),
        ];
        assert_eq!(
            format_requests(&reqs),
            "WorldBegin\n  IfBegin \"a\\\"b\"\n    Color [1.0 0.5 1e-7] -3\n  Else\n    \
             S [\"x\\ny\"]\n  IfEnd\nWorldEnd\n"
        );
    }
}
