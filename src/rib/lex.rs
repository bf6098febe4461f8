//! Hand-written scanners under the pest grammar: numbers, number arrays, string escapes and
//! resynchronisation after a syntax error.
//!
//! Input: byte slices of ASCII RIB that the grammar already delimited (a number token, the
//! inside of a number-array token, the inside of a string token), or any text for `resync`.
//! Output: `Num`s, `Value`s, decoded strings, byte positions.
//! Invariants: reals are rounded once to the nearest f32 (exactly like `str::parse::<f32>`),
//! so printing with `{:?}` and reading back is the identity; no allocation per number.

use super::Value;

/// One scanned number.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Num {
    Int(i64),
    Float(f32),
}

/// Powers of ten that are exact in f32 (5^10 < 2^24), for the one-rounding fast path.
const P10: [f32; 11] = [1.0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10];

#[inline]
pub(crate) fn is_space(c: u8) -> bool {
    matches!(c, b' ' | b'\t' | b'\n' | b'\r' | 0x0C)
}

/// Scans one number starting at `start` following the grammar's `number` rule. Returns the
/// number and the index just past it, or `None` when no number starts there.
#[inline]
pub(crate) fn scan_number(b: &[u8], start: usize) -> Option<(Num, usize)> {
    let n = b.len();
    let mut i = start;
    let mut neg = false;
    if i < n && (b[i] == b'-' || b[i] == b'+') {
        neg = b[i] == b'-';
        i += 1;
    }
    // `nan`, `inf` and `infinity` (any case): what C's printf writes for values that are not
    // finite. RISpec has no such numbers; the scene builder warns and drops the request.
    for (word, v) in [
        (&b"infinity"[..], f32::INFINITY),
        (&b"inf"[..], f32::INFINITY),
        (&b"nan"[..], f32::NAN),
    ] {
        let end = i + word.len();
        if end <= n
            && b[i..end].eq_ignore_ascii_case(word)
            && !b
                .get(end)
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            return Some((Num::Float(if neg { -v } else { v }), end));
        }
    }
    // Up to 19 significant digits are kept exactly; the rest only move the exponent.
    let mut mant: u64 = 0;
    let mut kept = 0u32;
    let mut e10: i32 = 0;
    let mut inexact = false;
    let int_start = i;
    while i < n && b[i].is_ascii_digit() {
        let d = (b[i] - b'0') as u64;
        if kept < 19 {
            mant = mant * 10 + d;
            if mant != 0 {
                kept += 1;
            }
        } else {
            e10 += 1;
            inexact |= d != 0;
        }
        i += 1;
    }
    let int_digits = i - int_start;
    let mut real = false;
    let mut frac_digits = 0;
    if i < n && b[i] == b'.' {
        let dot = i;
        i += 1;
        let fs = i;
        while i < n && b[i].is_ascii_digit() {
            let d = (b[i] - b'0') as u64;
            if kept < 19 {
                mant = mant * 10 + d;
                if mant != 0 {
                    kept += 1;
                }
                e10 -= 1;
            } else {
                inexact |= d != 0;
            }
            i += 1;
        }
        frac_digits = i - fs;
        if int_digits + frac_digits == 0 {
            // A lone "." (or sign and ".") is not a number.
            let _ = dot;
            return None;
        }
        real = true;
    }
    if int_digits + frac_digits == 0 {
        return None;
    }
    if i < n && (b[i] == b'e' || b[i] == b'E') {
        let mut j = i + 1;
        let mut eneg = false;
        if j < n && (b[j] == b'-' || b[j] == b'+') {
            eneg = b[j] == b'-';
            j += 1;
        }
        let es = j;
        let mut exp: i32 = 0;
        while j < n && b[j].is_ascii_digit() {
            exp = exp.saturating_mul(10).saturating_add((b[j] - b'0') as i32);
            j += 1;
        }
        if j > es {
            real = true;
            i = j;
            e10 = e10.saturating_add(if eneg { -exp } else { exp });
        }
    }
    if !real {
        if int_digits <= 18 {
            let v = mant as i64;
            return Some((Num::Int(if neg { -v } else { v }), i));
        }
        // Long integers: exact when they fit, else they become reals.
        // SAFETY of from_utf8: the slice is ASCII digits and a sign.
        let s = std::str::from_utf8(&b[start..i]).ok()?;
        if let Ok(v) = s.parse::<i64>() {
            return Some((Num::Int(v), i));
        }
        return Some((Num::Float(s.parse::<f32>().ok()?), i));
    }
    if !inexact {
        while mant > (1 << 24) && mant.is_multiple_of(10) {
            mant /= 10;
            e10 += 1;
        }
        if mant <= (1 << 24) && (-10..=10).contains(&e10) {
            // Both operands exact: IEEE division/multiplication rounds once, correctly.
            let m = mant as f32;
            let f = if e10 < 0 {
                m / P10[(-e10) as usize]
            } else {
                m * P10[e10 as usize]
            };
            return Some((Num::Float(if neg { -f } else { f }), i));
        }
    }
    let s = std::str::from_utf8(&b[start..i]).ok()?;
    Some((Num::Float(s.parse::<f32>().ok()?), i))
}

/// Reads the inside of a number-array token (between `[` and `]`). Integers only give an
/// `IntArray`; any real gives a `FloatArray`. On a token that is not a number returns its
/// byte range (relative to `b`).
pub(crate) fn scan_number_array(b: &[u8]) -> Result<Value, (usize, usize)> {
    let n = b.len();
    let mut ints: Vec<i64> = Vec::new();
    let mut floats: Vec<f32> = Vec::new();
    let mut is_float = false;
    let mut i = 0;
    loop {
        while i < n && is_space(b[i]) {
            i += 1;
        }
        if i >= n {
            break;
        }
        match scan_number(b, i) {
            Some((num, j)) => {
                match (num, is_float) {
                    (Num::Int(v), false) => ints.push(v),
                    (Num::Int(v), true) => floats.push(v as f32),
                    (Num::Float(f), true) => floats.push(f),
                    (Num::Float(f), false) => {
                        is_float = true;
                        floats.reserve(ints.len() + (n - i) / 4);
                        floats.extend(ints.iter().map(|&v| v as f32));
                        ints = Vec::new();
                        floats.push(f);
                    }
                }
                i = j;
            }
            None => {
                let mut j = i + 1;
                while j < n && !is_space(b[j]) {
                    j += 1;
                }
                return Err((i, j));
            }
        }
    }
    Ok(if is_float {
        Value::FloatArray(floats)
    } else {
        Value::IntArray(ints)
    })
}

/// Decodes the escapes of a string token's inside (RISpec C.2.1): `\n \r \t \b \f \\ \"`,
/// `\ddd` octal (1–3 digits), backslash-newline (and backslash-CR-LF) continuation; any other
/// `\x` is `x`. Bytes that are not UTF-8 (from octal escapes) are replaced lossily.
pub(crate) fn unescape(s: &str) -> String {
    if !s.as_bytes().contains(&b'\\') {
        return s.to_string();
    }
    let b = s.as_bytes();
    let mut out: Vec<u8> = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c != b'\\' || i + 1 >= b.len() {
            out.push(c);
            i += 1;
            continue;
        }
        let e = b[i + 1];
        i += 2;
        match e {
            b'n' => out.push(b'\n'),
            b'r' => out.push(b'\r'),
            b't' => out.push(b'\t'),
            b'b' => out.push(0x08),
            b'f' => out.push(0x0C),
            b'\n' => {}
            b'\r' => {
                if i < b.len() && b[i] == b'\n' {
                    i += 1;
                }
            }
            b'0'..=b'7' => {
                let mut v: u32 = (e - b'0') as u32;
                let mut k = 0;
                while k < 2 && i < b.len() && (b'0'..=b'7').contains(&b[i]) {
                    v = v * 8 + (b[i] - b'0') as u32;
                    i += 1;
                    k += 1;
                }
                out.push((v & 0xFF) as u8);
            }
            other => out.push(other),
        }
    }
    match String::from_utf8(out) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    }
}

/// Writes a real so that `scan_number` reads back the same f32 and sees a real (Rust's
/// shortest round-trip form always has a `.` or an exponent). Infinities become `±1e39`
/// (which reads back as infinity); NaN, which RIB cannot spell, becomes `0.0`.
pub(crate) fn write_f32(out: &mut String, f: f32) {
    use std::fmt::Write;
    if f.is_nan() {
        out.push_str("0.0");
    } else if f.is_infinite() {
        out.push_str(if f > 0.0 { "1e39" } else { "-1e39" });
    } else {
        let _ = write!(out, "{f:?}");
    }
}

/// Writes `s` as a quoted RIB string that `unescape` reads back exactly.
pub(crate) fn escape_into(out: &mut String, s: &str) {
    out.push('"');
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{C}' => out.push_str("\\f"),
            c if (c as u32) < 0x20 || c as u32 == 0x7F => {
                out.push_str(&format!("\\{:03o}", c as u32));
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

#[inline]
fn is_name_start(c: u8) -> bool {
    c.is_ascii_alphabetic() || c == b'_'
}

/// The end of a string token whose opening quote is at `i` (index past the closing quote),
/// or `None` when it is not closed.
pub(crate) fn string_end(b: &[u8], i: usize) -> Option<usize> {
    let mut j = i + 1;
    while j < b.len() {
        match b[j] {
            b'"' => return Some(j + 1),
            b'\\' => j += 2,
            _ => j += 1,
        }
    }
    None
}

/// Resynchronisation (RISpec C.2.2): from a token boundary `from`, discards tokens (numbers,
/// strings, brackets, comments, stray characters) up to the next request name and returns
/// its position (or the end of the text).
pub(crate) fn resync(b: &[u8], from: usize) -> usize {
    let mut i = from;
    while i < b.len() {
        let c = b[i];
        if is_space(c) {
            i += 1;
        } else if c == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if c == b'"' {
            // An unclosed string: resume on the next line rather than losing the file.
            i = match string_end(b, i) {
                Some(e) => e,
                None => next_line(b, i),
            };
        } else if is_name_start(c) {
            return i;
        } else if let Some((_, j)) = scan_number(b, i) {
            i = j;
        } else {
            i += 1;
        }
    }
    b.len()
}

/// Index just past the next newline at or after `i` (or the end).
pub(crate) fn next_line(b: &[u8], i: usize) -> usize {
    match b[i.min(b.len())..].iter().position(|&c| c == b'\n') {
        Some(k) => i + k + 1,
        None => b.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num(s: &str) -> Option<Num> {
        scan_number(s.as_bytes(), 0)
            .filter(|&(_, e)| e == s.len())
            .map(|x| x.0)
    }

    #[test]
    fn every_number_form() {
        assert_eq!(num("1"), Some(Num::Int(1)));
        assert_eq!(num("-1"), Some(Num::Int(-1)));
        assert_eq!(num("+7"), Some(Num::Int(7)));
        assert_eq!(num(".5"), Some(Num::Float(0.5)));
        assert_eq!(num("-.5"), Some(Num::Float(-0.5)));
        assert_eq!(num("1."), Some(Num::Float(1.0)));
        assert_eq!(num("1e-3"), Some(Num::Float(1e-3)));
        assert_eq!(num("-2.5E+4"), Some(Num::Float(-25000.0)));
        assert_eq!(num("1E5"), Some(Num::Float(1e5)));
        assert_eq!(num("1.e2"), Some(Num::Float(100.0)));
        assert_eq!(num("."), None);
        assert_eq!(num("-"), None);
        assert_eq!(num("e5"), None);
        // "1e" is the integer 1 followed by something else.
        assert_eq!(scan_number(b"1e", 0), Some((Num::Int(1), 1)));
    }

    #[test]
    fn reals_round_like_std() {
        for s in [
            "0.1",
            "3.14159265358979",
            "123456789012345678901234567890",
            "1.000000000000000000000000001",
            "0.000000000000000000000000000000000000000001",
            "1e39",
            "16777217.0",
            "0.30000001192092896",
            "-7.0e-10",
            "340282356779733661637539395458142568448.0",
        ] {
            let want: f32 = s.parse().unwrap();
            match num(s).unwrap() {
                Num::Float(f) => assert_eq!(f.to_bits(), want.to_bits(), "{s}"),
                Num::Int(i) => assert_eq!(i as f32, want, "{s}"),
            }
        }
        // Integers that overflow i64 become reals.
        assert_eq!(
            num("99999999999999999999"),
            Some(Num::Float(99999999999999999999.0))
        );
        assert_eq!(num("-9223372036854775808"), Some(Num::Int(i64::MIN)));
    }

    #[test]
    fn number_arrays_promote_to_float() {
        assert_eq!(
            scan_number_array(b" 1 2\n3 "),
            Ok(Value::IntArray(vec![1, 2, 3]))
        );
        assert_eq!(
            scan_number_array(b"1 2.5 3"),
            Ok(Value::FloatArray(vec![1.0, 2.5, 3.0]))
        );
        assert_eq!(scan_number_array(b""), Ok(Value::IntArray(vec![])));
        assert_eq!(scan_number_array(b"1 2 WorldEnd 3"), Err((4, 12)));
    }

    #[test]
    fn every_escape() {
        assert_eq!(unescape(r"a\nb"), "a\nb");
        assert_eq!(unescape(r"\r\t\b\f"), "\r\t\u{8}\u{C}");
        assert_eq!(unescape(r#"\\ \""#), "\\ \"");
        assert_eq!(unescape(r"\101\60x\0"), "A0x\0");
        assert_eq!(unescape(r"\1012"), "A2");
        assert_eq!(unescape("ab\\\ncd"), "abcd");
        assert_eq!(unescape("ab\\\r\ncd"), "abcd");
        assert_eq!(unescape(r"C:\path\q"), "C:pathq");
        assert_eq!(unescape(r"end\"), "end\\");
    }

    #[test]
    fn escape_round_trips() {
        let s = "q\"b\\s\n\r\t\u{8}\u{C}\u{1}\u{7F}é";
        let mut o = String::new();
        escape_into(&mut o, s);
        assert_eq!(unescape(&o[1..o.len() - 1]), s);
    }

    #[test]
    fn resync_skips_to_next_name() {
        let t = b"1 2 \"str Foo\" [3] # Bar\n ] Baz 4";
        assert_eq!(resync(t, 0), 27);
        assert_eq!(resync(b"1 2", 0), 3);
        assert_eq!(resync(b"\"open\nName", 0), 6);
    }
}
