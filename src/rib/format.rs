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
