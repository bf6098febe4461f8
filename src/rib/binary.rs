//! Binary RIB (RISpec 3.2 App. C.1): decodes encoded tokens into their ASCII form, so that
//! one grammar reads every stream and binary and ASCII may be freely interleaved.
//!
//! Input: the bytes of a stream that is not pure ASCII. Output: ASCII RIB text (this is the
//! text registered in the `SourceMap`, so spans and diagnostics point into the decoded form)
//! and the problems found, each at a byte offset of that text.
//! Invariants: ASCII bytes, strings and comments are copied unchanged (bytes >= 0200 inside a
//! quoted string or a comment are text, not binary); every decoded value reads back as the
//! same `Value` (f32 printed shortest-exact, integers as integers, strings escaped); a bad
//! token becomes ` ? ` at a recorded offset so the reader loses only that request.

use std::collections::HashMap;

use super::lex;

/// A problem found while decoding, at `at..at+1` of the decoded text.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Issue {
    pub at: usize,
    pub error: bool,
    pub message: String,
    pub help: &'static str,
    /// A placeholder was written at `at` (` ? `, or `UNDEFINED_REQUEST` for a request name):
    /// the reader must not report it again, and drops a request whose name is there.
    pub placeholder: bool,
}

/// Decodes a binary (or mixed) RIB stream to ASCII RIB text.
pub(crate) fn transcode(b: &[u8]) -> (String, Vec<Issue>) {
    let mut t = Transcoder {
        b,
        i: 0,
        out: Vec::with_capacity(b.len() + b.len() / 2),
        issues: Vec::new(),
        requests: HashMap::new(),
        strings: HashMap::new(),
    };
    t.run();
    // Always valid: ASCII, escaped strings and `copy_text`'s UTF-8.
    let text = match String::from_utf8(t.out) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    };
    (text, t.issues)
}

struct Transcoder<'a> {
    b: &'a [u8],
    i: usize,
    out: Vec<u8>,
    issues: Vec<Issue>,
    /// 0314 definitions: request code -> request name.
    requests: HashMap<u8, String>,
    /// 0315/0316 definitions: string token -> string.
    strings: HashMap<u32, String>,
}

/// The name written for a call of an undefined request code (dropped by the reader).
pub(crate) const UNDEFINED_REQUEST: &str = "_undefined_binary_request";

const HELP_SPEC: &str = "binary RIB follows RISpec 3.2 Appendix C.1";

impl<'a> Transcoder<'a> {
    fn run(&mut self) {
        let b = self.b;
        while self.i < b.len() {
            let c = b[self.i];
            match c {
                b'"' => {
                    // A quoted string is copied as is, whatever bytes it holds.
                    let end = lex::string_end(b, self.i).unwrap_or(b.len()).min(b.len());
                    self.copy_text(end);
                }
                b'#' => {
                    let end = lex::next_line(b, self.i);
                    self.copy_text(end);
                }
                0..=0x7F => {
                    self.out.push(c);
                    self.i += 1;
                }
                _ => {
                    if !self.token(c) {
                        return;
                    }
                }
            }
        }
    }

    /// Copies string or comment text up to `end`: UTF-8 when the piece is valid UTF-8, else
    /// Latin-1 (an 8-bit RIB file's accented names and comments), so the decoded text is valid
    /// UTF-8 and issue offsets (into the output) stay exact.
    fn copy_text(&mut self, end: usize) {
        let piece = &self.b[self.i..end];
        match std::str::from_utf8(piece) {
            Ok(s) => self.out.extend_from_slice(s.as_bytes()),
            Err(_) => {
                let mut buf = [0u8; 4];
                for &c in piece {
                    self.out
                        .extend_from_slice(char::from(c).encode_utf8(&mut buf).as_bytes());
                }
            }
        }
        self.i = end;
    }

    fn issue(&mut self, error: bool, message: String, help: &'static str, placeholder: bool) {
        if placeholder {
            self.out.extend_from_slice(b" ");
        }
        let at = self.out.len();
        if placeholder {
            self.out.extend_from_slice(b"? ");
        }
        self.issues.push(Issue {
            at,
            error,
            message,
            help,
            placeholder,
        });
    }

    /// `n` bytes after the current position, or `None` (with an issue) when the stream ends.
    fn take(&mut self, n: usize, what: &str) -> Option<&'a [u8]> {
        let b = self.b;
        match b.get(self.i..self.i.checked_add(n)?) {
            Some(s) => {
                self.i += n;
                Some(s)
            }
            None => {
                self.issue(
                    true,
                    format!("binary RIB ends inside {what}"),
                    "the stream is truncated",
                    false,
                );
                self.i = b.len();
                None
            }
        }
    }

    fn uint(&mut self, n: usize, what: &str) -> Option<u32> {
        let s = self.take(n, what)?;
        Some(s.iter().fold(0u32, |a, &x| (a << 8) | x as u32))
    }

    fn emit(&mut self, s: &str) {
        self.out.push(b' ');
        self.out.extend_from_slice(s.as_bytes());
        self.out.push(b' ');
    }

    fn emit_f32(&mut self, f: f32) {
        if f.is_nan() {
            self.issue(
                false,
                "binary RIB holds a NaN; read as 0".into(),
                "NaN is not a RIB number",
                false,
            );
        }
        let mut s = String::new();
        lex::write_f32(&mut s, f);
        self.emit(&s);
    }

    fn emit_string(&mut self, bytes: &[u8]) {
        self.out.push(b' ');
        self.out.push(b'"');
        for &c in bytes {
            match c {
                b'"' => self.out.extend_from_slice(b"\\\""),
                b'\\' => self.out.extend_from_slice(b"\\\\"),
                b'\n' => self.out.extend_from_slice(b"\\n"),
                0x20..=0x7E => self.out.push(c),
                _ => self
                    .out
                    .extend_from_slice(format!("\\{:03o}", c).as_bytes()),
            }
        }
        self.out.extend_from_slice(b"\" ");
    }

    /// Reads a string token (binary 0220–0243 or an ASCII quoted string) for 0314/0315.
    fn string_operand(&mut self) -> Option<Vec<u8>> {
        let b = self.b;
        while self.i < b.len() && lex::is_space(b[self.i]) {
            self.i += 1;
        }
        let c = *b.get(self.i)?;
        match c {
            0x90..=0x9F => {
                self.i += 1;
                self.take((c - 0x90) as usize, "a string")
                    .map(<[u8]>::to_vec)
            }
            0xA0..=0xA3 => {
                self.i += 1;
                let n = self.uint((c - 0xA0) as usize + 1, "a string length")? as usize;
                self.take(n, "a string").map(<[u8]>::to_vec)
            }
            b'"' => {
                let end = lex::string_end(b, self.i)?;
                let s = std::str::from_utf8(&b[self.i + 1..end - 1]).ok()?;
                self.i = end;
                Some(lex::unescape(s).into_bytes())
            }
            _ => None,
        }
    }

    /// Decodes the binary token starting with byte `c` (>= 0200). Returns false to stop.
    fn token(&mut self, c: u8) -> bool {
        self.i += 1;
        match c {
            0x80..=0x8F => {
                // 0200 + 4d + w: a signed (w+1)-byte integer with d bytes after the point.
                let w = (c & 3) as usize + 1;
                let d = ((c >> 2) & 3) as i32;
                let Some(s) = self.take(w, "a number") else {
                    return false;
                };
                let raw = s.iter().fold(0i64, |a, &x| (a << 8) | x as i64);
                let shift = 64 - 8 * w as u32;
                let v = (raw << shift) >> shift; // sign-extend
                if d == 0 {
                    self.emit(&v.to_string());
                } else {
                    self.emit_f32((v as f64 / 256f64.powi(d)) as f32);
                }
            }
            0x90..=0xA3 => {
                self.i -= 1;
                match self.string_operand() {
                    Some(s) => self.emit_string(&s),
                    None => return false,
                }
            }
            0xA4 => {
                let Some(s) = self.take(4, "a float") else {
                    return false;
                };
                self.emit_f32(f32::from_be_bytes([s[0], s[1], s[2], s[3]]));
            }
            0xA5 => {
                let Some(s) = self.take(8, "a double") else {
                    return false;
                };
                let mut a = [0u8; 8];
                a.copy_from_slice(s);
                self.emit_f32(f64::from_be_bytes(a) as f32);
            }
            0xA6 => {
                let Some(code) = self.take(1, "a request code").map(|s| s[0]) else {
                    return false;
                };
                match self.requests.get(&code).cloned() {
                    Some(name) => {
                        if self.out.last().is_some_and(|&l| l != b'\n') {
                            self.out.push(b'\n');
                        }
                        self.out.extend_from_slice(name.as_bytes());
                        self.out.push(b' ');
                    }
                    None => {
                        // A name placeholder: the reader drops this request (and its
                        // arguments) silently, keeping the previous request intact.
                        if self.out.last().is_some_and(|&l| l != b'\n') {
                            self.out.push(b'\n');
                        }
                        let at = self.out.len();
                        self.out.extend_from_slice(UNDEFINED_REQUEST.as_bytes());
                        self.out.push(b' ');
                        self.issues.push(Issue {
                            at,
                            error: true,
                            message: format!(
                                "binary request code {code} (0246 {code:03o}) was never defined"
                            ),
                            help: "define it first with 0314 <code> <name>",
                            placeholder: true,
                        });
                    }
                }
            }
            0xC8..=0xCB => {
                // 0310 + l: a float array with an (l+1)-byte count.
                let Some(n) = self.uint((c - 0xC8) as usize + 1, "an array length") else {
                    return false;
                };
                let Some(s) = (n as usize)
                    .checked_mul(4)
                    .and_then(|len| self.take(len, "a float array"))
                else {
                    return false;
                };
                self.out.extend_from_slice(b" [");
                let mut buf = String::new();
                for q in s.chunks_exact(4) {
                    let f = f32::from_be_bytes([q[0], q[1], q[2], q[3]]);
                    buf.clear();
                    buf.push(' ');
                    lex::write_f32(&mut buf, f);
                    self.out.extend_from_slice(buf.as_bytes());
                }
                self.out.extend_from_slice(b" ] ");
            }
            0xCC => {
                let Some(code) = self.take(1, "a request definition").map(|s| s[0]) else {
                    return false;
                };
                match self.string_operand() {
                    Some(name)
                        if !name.is_empty()
                            && (name[0].is_ascii_alphabetic() || name[0] == b'_')
                            && name.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_') =>
                    {
                        self.requests
                            .insert(code, String::from_utf8_lossy(&name).into_owned());
                    }
                    _ => self.issue(
                        true,
                        format!("request definition 0314 {code:03o} is not followed by a request name string"),
                        HELP_SPEC,
                        false,
                    ),
                }
            }
            0xCD | 0xCE => {
                let Some(tok) = self.uint((c - 0xCD) as usize + 1, "a string definition") else {
                    return false;
                };
                match self.string_operand() {
                    Some(s) => {
                        self.strings
                            .insert(tok, String::from_utf8_lossy(&s).into_owned());
                    }
                    None => self.issue(
                        true,
                        format!("string definition {tok} is not followed by a string"),
                        HELP_SPEC,
                        false,
                    ),
                }
            }
            0xCF | 0xD0 => {
                let Some(tok) = self.uint((c - 0xCF) as usize + 1, "a string reference") else {
                    return false;
                };
                match self.strings.get(&tok).cloned() {
                    Some(s) => self.emit_string(s.as_bytes()),
                    None => self.issue(
                        true,
                        format!("string token {tok} was never defined"),
                        "define it first with 0315 <token> <string>",
                        true,
                    ),
                }
            }
            0xFF => {
                self.issue(
                    false,
                    "byte 0377 ends the binary stream; the rest is ignored".into(),
                    "0377 marks the end of a RunProgram stream",
                    false,
                );
                return false;
            }
            _ => self.issue(
                true,
                format!("reserved binary RIB byte {c:#04x} (0{c:o})"),
                HELP_SPEC,
                true,
            ),
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_numbers() {
        // 0201: 2-byte integer 0x0102; 0200: 1-byte -1; 0205: .b (2 bytes, 1 after point).
        let (t, i) = transcode(&[0x81, 0x01, 0x02, 0x80, 0xFF, 0x85, 0x01, 0x80]);
        assert!(i.is_empty());
        assert_eq!(
            t.split_whitespace().collect::<Vec<_>>(),
            ["258", "-1", "1.5"]
        );
        let (t, _) = transcode(&[0xA4, 0x3F, 0xC0, 0x00, 0x00]);
        assert_eq!(t.trim(), "1.5");
        let mut v = vec![0xA5];
        v.extend_from_slice(&0.25f64.to_be_bytes());
        assert_eq!(transcode(&v).0.trim(), "0.25");
    }

    #[test]
    fn strings_keep_their_bytes() {
        let (t, _) = transcode(&[0x93, b'a', b'"', 0xC3]);
        assert_eq!(t.trim(), "\"a\\\"\\303\"");
    }

    #[test]
    fn reserved_and_truncated_are_reported() {
        let (t, i) = transcode(&[0xB0, 0x81, 0x01]);
        assert_eq!(i.len(), 2);
        assert!(i[0].placeholder && i[0].message.contains("reserved"));
        assert!(i[1].message.contains("ends inside"));
        assert_eq!(&t[i[0].at..i[0].at + 1], "?");
    }

    #[test]
    fn latin1_in_strings_and_comments_is_decoded() {
        let (t, i) = transcode(b"A \"caf\xE9\" # \xFE\n");
        assert!(i.is_empty());
        assert_eq!(t, "A \"caf\u{E9}\" # \u{FE}\n");
    }

    #[test]
    fn bytes_in_strings_and_comments_are_text() {
        let src = "A \"é\" # ü\n".as_bytes();
        let (t, i) = transcode(src);
        assert!(i.is_empty());
        assert_eq!(t.as_bytes(), src);
    }
}
