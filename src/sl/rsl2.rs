//! RSL 2.0 shader classes that are an RSL 1 shader in disguise, rewritten as one.
//!
//! Input: the raw text of a `.sl` file. Output: the text with such a class replaced by the
//! shader it amounts to, or None. A class qualifies when its body holds exactly one member,
//! a `surface`, `displacement`, `light`, `volume` or `imager` method: PRMan runs that method with the class's
//! parameters in scope, which is what an RSL 1 shader of that type with the same parameters
//! and the method's body does (published light classes are often just `light()`).
//! Classes with member variables, pipeline methods (`construct`, `begin`, `prelighting` …)
//! or helpers are left alone (the caller reports them as RSL 2.0).
//! Invariants: line numbers are kept (what is dropped becomes spaces, newlines stay), and
//! only the header's keyword changes length, so diagnostics point at the written lines.

use super::foreign::strip_comments;

/// The shader kinds a lone method can stand for.
const METHODS: [&str; 5] = ["surface", "displacement", "light", "volume", "imager"];

/// The rewritten text, the shader kind and where its keyword now stands, when `text` holds
/// a one-method class.
pub fn single_method_class(text: &str) -> Option<(String, &'static str, usize)> {
    let code = strip_comments(text);
    let b = code.as_bytes();
    let (class_at, _) = class_keyword(&code)?;
    let open_paren = class_at + code[class_at..].find('(')?;
    let close_paren = matching(b, open_paren, b'(', b')')?;
    let body_open = close_paren + 1 + code[close_paren + 1..].find(|c: char| !c.is_whitespace())?;
    if b[body_open] != b'{' {
        return None;
    }
    let body_close = matching(b, body_open, b'{', b'}')?;
    // The one member: `[public] void NAME(formals) { … }`.
    let mut words = code[body_open + 1..body_close].trim_start();
    for kw in ["public", "void"] {
        if let Some(rest) = words.strip_prefix(kw) {
            if rest.starts_with(char::is_whitespace) {
                words = rest.trim_start();
            } else if kw == "void" {
                return None;
            }
        } else if kw == "void" {
            return None;
        }
    }
    let kind = METHODS.into_iter().find(|m| {
        words
            .strip_prefix(m)
            .is_some_and(|r| r.trim_start().starts_with('('))
    })?;
    // `words` is a slice of `code`: its position is its distance from code's start.
    let formals_open = (words.as_ptr() as usize - code.as_ptr() as usize) + words.find('(')?;
    let formals_close = matching(b, formals_open, b'(', b')')?;
    let block_open =
        formals_close + 1 + code[formals_close + 1..].find(|c: char| !c.is_whitespace())?;
    if b[block_open] != b'{' {
        return None;
    }
    let block_close = matching(b, block_open, b'{', b'}')?;
    // Unbalanced brackets can end the class body inside the method's formals: then the
    // method is not inside the body, and this is no one-method class (the parser reports).
    if block_close >= body_close || !code[block_close + 1..body_close].trim().is_empty() {
        return None;
    }
    let blank =
        |s: &str| -> String { s.chars().map(|c| if c == '\n' { c } else { ' ' }).collect() };
    let mut out = String::with_capacity(text.len() + 8);
    out.push_str(&text[..class_at]);
    out.push_str(kind);
    out.push_str(&text[class_at + 5..=close_paren]);
    out.push_str(&blank(&text[close_paren + 1..block_open]));
    out.push_str(&text[block_open..=block_close]);
    out.push_str(&blank(&text[block_close + 1..=body_close]));
    out.push_str(&text[body_close + 1..]);
    Some((out, kind, class_at))
}

/// Byte offset of the first `class NAME (` at the start of a line, and NAME. The caller passes
/// text with comments blanked, so a commented-out class is not seen.
pub(crate) fn class_keyword(code: &str) -> Option<(usize, &str)> {
    let mut offset = 0;
    for line in code.split_inclusive('\n') {
        let body = line.trim_start();
        let at = offset + (line.len() - body.len());
        offset += line.len();
        let Some(rest) = body.strip_prefix("class") else {
            continue;
        };
        if !rest.starts_with(char::is_whitespace) {
            continue;
        }
        let rest = rest.trim_start();
        let n = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if n > 0 && rest[n..].trim_start().starts_with('(') {
            return Some((at, &rest[..n]));
        }
    }
    None
}

/// The offset of the bracket closing the one at `open` (strings skipped), or None.
fn matching(b: &[u8], open: usize, o: u8, c: u8) -> Option<usize> {
    let mut depth = 0usize;
    let mut i = open;
    while i < b.len() {
        match b[i] {
            b'"' => {
                i += 1;
                while i < b.len() && b[i] != b'"' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
            }
            x if x == o => depth += 1,
            x if x == c => {
                depth -= 1;
                if depth == 0 {
                    return Some(i);
                }
            }
            _ => {}
        }
        i += 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::single_method_class;

    #[test]
    fn a_lone_light_method_becomes_a_light_shader_on_the_same_lines() {
        let src = "// spot\nclass spot(float intensity = 1; string __category = \"std\")\n{\n  \
                   public void light(output vector L; output color Cl;) {\n    \
                   illuminate(point(0,0,0)) { Cl = intensity; }\n  }\n}\n";
        let (out, kind, at) = single_method_class(src).expect("rewritten");
        assert_eq!(kind, "light");
        assert_eq!(&out[at..at + 5], "light");
        assert_eq!(out.lines().count(), src.lines().count());
        assert!(out.contains("light spot(float intensity = 1;"), "{out}");
        assert!(
            !out.contains("public") && !out.contains("output vector L"),
            "{out}"
        );
        assert_eq!(out.lines().nth(4), src.lines().nth(4));
    }

    #[test]
    fn a_lone_imager_method_becomes_an_imager_shader() {
        // A published vignette imager written as a PRMan class: its formals are the
        // imager's globals, so they go and the body stays.
        let src = "class vig(color background = (0,0,0))\n{\n  public void imager(\n    \
                   output varying color Ci;\n    output varying color Oi;)\n  {\n    \
                   Ci += (1 - Oi) * background;\n  }\n}\n";
        let (out, kind, at) = single_method_class(src).expect("rewritten");
        assert_eq!(kind, "imager");
        assert_eq!(&out[at..at + 6], "imager");
        assert_eq!(out.lines().count(), src.lines().count());
        assert!(
            out.contains("imager vig(color background = (0,0,0))"),
            "{out}"
        );
        assert!(!out.contains("output varying color"), "{out}");
        let vol = "class haze(float d = 1) { public void volume(output color Ci, Oi) { Oi = d; } }";
        assert_eq!(single_method_class(vol).expect("rewritten").1, "volume");
    }

    #[test]
    fn classes_with_more_than_one_member_are_left_alone() {
        for body in [
            "public void begin() { } public void surface(output color Ci, Oi) { Ci = 1; }",
            "float m; public void surface(output color Ci, Oi) { Ci = m; }",
            "public void opacity(output color Oi) { Oi = 1; }",
        ] {
            let src = format!("class c(float k = 1)\n{{\n{body}\n}}\n");
            assert!(single_method_class(&src).is_none(), "{body}");
        }
        assert!(single_method_class("surface s() { Ci = 1; }\n").is_none());
    }

    #[test]
    fn unbalanced_brackets_are_left_to_the_parser_not_a_panic() {
        // Found by mutation: the class body's `}` closes inside the method's formals.
        for src in [
            "class aw(float Kd = 1) {\n  public void surface(output color} Ci, Oi) {\n    \
             Ci = Kd;\n  }\n}\n",
            "class aw(float Kd = 1) {\n  public void surface(outp}ut color Ci) {\n  }\n}\n",
            "class aw(float Kd = 1) {\n  public void surface(output color Ci) {\n",
            "class aw(float Kd = 1) { public void surface(",
        ] {
            assert!(single_method_class(src).is_none(), "{src}");
        }
    }
}
