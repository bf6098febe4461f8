//! Sources that are not the shading language arbor compiles, recognised before parsing so
//! that each gets one diagnostic naming what it is, instead of a cascade of syntax errors.
//!
//! Input: the raw text of a `.sl` file. Output: at most one error diagnostic.
//! Recognised: RenderMan Shading Language 2.0 shader classes (PRMan 13 and later:
//! `class name(params) { public void surface(...) … }`), and Slim appearance files
//! (`slim 1 appearance …`, the MTOR/RAT palette format some collections ship as `.sl`).
//! Invariants: only the start of a line is looked at for `class`, outside comments, so an
//! RSL 1 shader is never refused; a file is refused only for what it begins or is built with.

use crate::diag::{Diag, Span};

/// The error for a source in a language arbor does not compile, or None.
pub fn foreign_language(file: u32, text: &str) -> Option<Diag> {
    let code = strip_comments(text);
    let first = code.trim_start();
    if first.starts_with("slim") && first[4..].starts_with(char::is_whitespace) {
        let at = code.len() - first.len();
        return Some(
            Diag::error(
                "sl::not-shading-language",
                "this is a Slim appearance file (`slim … appearance`), not shading language",
            )
            .label(Span::new(file, at, at + 4), "Slim palette syntax")
            .help(
                "Slim (MTOR/RAT) writes the shader's .sl when it compiles the appearance; \
                 compile or render with that generated file",
            ),
        );
    }
    if let Some((at, name)) = super::rsl2::class_keyword(&code) {
        return Some(
            Diag::error(
                "sl::rsl2",
                format!(
                    "`class {name}` is a RenderMan Shading Language 2.0 shader class (PRMan 13 \
                     and later), which arbor does not compile"
                ),
            )
            .label(Span::new(file, at, at + 5), "RSL 2.0 class")
            .help(
                "arbor compiles the RISpec 3.2 language: write the class's `surface`, \
                 `light` or `displacement` method as a shader of that type (its parameters \
                 stay the same)",
            ),
        );
    }
    None
}

/// The text with `/* */` and `//` comments replaced by spaces (byte offsets kept).
pub(crate) fn strip_comments(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            let end = text[i + 2..].find("*/").map_or(b.len(), |e| i + 2 + e + 2);
            out.extend(
                b[i..end]
                    .iter()
                    .map(|&c| if c == b'\n' { b'\n' } else { b' ' }),
            );
            i = end;
        } else if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
            let end = text[i..].find('\n').map_or(b.len(), |e| i + e);
            out.extend(std::iter::repeat(b' ').take(end - i));
            i = end;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    // Only ASCII bytes were replaced by ASCII bytes, so the text stays valid UTF-8.
    String::from_utf8(out).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::foreign_language;

    #[test]
    fn rsl2_class_and_slim_are_named_and_rsl1_passes() {
        let d =
            foreign_language(0, "// light\nclass aw_spot(float intensity = 1;)\n{ }\n").unwrap();
        assert_eq!(d.code, "sl::rsl2");
        let d =
            foreign_language(0, "slim 1 appearance slim {\n instance surface \"x\" {}\n}").unwrap();
        assert_eq!(d.code, "sl::not-shading-language");
        // RSL 1: a variable named `class`, and the word in a comment, are not refused.
        assert!(foreign_language(0, "surface s() { float class = 1; Ci = class; }").is_none());
        assert!(foreign_language(0, "/*\nclass foo(x) */ surface s() {}").is_none());
        assert!(foreign_language(0, "/* slim shader */ surface slim() {}").is_none());
    }
}
