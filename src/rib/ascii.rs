//! ASCII RIB reader: drives the pest grammar (`grammar/rib.pest`) over the text, a chunk of
//! requests at a time, and turns pairs into [`Request`]s.
//!
//! Input: the registered text of one file and its id. Output: the requests read; syntax
//! errors go to `Diagnostics` as `rib::syntax` (or `rib::badarray`) with a labelled span.
//! Invariants: never panics; after an error the reader resumes at the next request name, so
//! at most one request is lost (RISpec C.2.2); every span is a byte range of `text`.

use pest::iterators::Pair;
use pest::Parser;

use super::lex::{self, is_space, scan_number, string_end};
use super::{Arg, Request, Value};
use crate::diag::{Diag, Diagnostics, Span};

#[derive(pest_derive::Parser)]
#[grammar = "../grammar/rib.pest"]
pub(crate) struct RibParser;

/// Requests per `chunk` call: must equal the bound in the grammar's `chunk` rule
/// (`request{, 256}`), so a full chunk means "keep going" rather than "stopped at an error".
const CHUNK: usize = 256;

/// Why a request parsed by pest could not be turned into a `Request`.
enum BuildError {
    /// A number array held something that is not a number (absolute byte range, and the
    /// position of its `[`).
    BadToken {
        start: usize,
        end: usize,
        open: usize,
    },
    /// The request is well-formed but an argument is not (mixed array): drop only it.
    Bad(Diag),
}

/// Reads every request of `text` (file id `file`). Errors whose position is in `quiet`
/// (sorted; placeholders where the binary decoder already reported a problem) are not
/// reported again, but still resynchronise; a request whose name is there is dropped.
/// Each request goes to `sink` as soon as it is read (syntax errors are reported in between).
pub(crate) fn parse_text_into(
    text: &str,
    file: u32,
    diags: &Diagnostics,
    quiet: &[usize],
    sink: &mut dyn FnMut(Request),
) {
    let b = text.as_bytes();
    let mut pos = 0usize;
    let report = |d: Diag, at: usize| {
        if quiet.binary_search(&at).is_err() {
            diags.report(d);
        }
    };
    'outer: while pos < b.len() {
        let rest = &text[pos..];
        let chunk = match RibParser::parse(Rule::chunk, rest) {
            Ok(mut p) => p.next(),
            Err(_) => None,
        };
        let Some(chunk) = chunk else {
            // `chunk` accepts zero requests, so this cannot happen; stay safe anyway.
            break;
        };
        let mut count = 0;
        let mut end = 0;
        let mut eoi = false;
        for p in chunk.into_inner() {
            match p.as_rule() {
                Rule::request => {
                    count += 1;
                    end = p.as_span().end();
                    match build(p, pos, file) {
                        Ok(r) if quiet.binary_search(&(r.span.start as usize)).is_ok() => {}
                        Ok(r) => sink(r),
                        Err(BuildError::Bad(d)) => diags.report(d),
                        Err(BuildError::BadToken { start, end, open }) => {
                            report(bad_array_token(b, file, start, end, open), start);
                            let resume = if is_name_start(b[start]) {
                                start
                            } else {
                                lex::resync(b, start)
                            };
                            pos = resume.max(pos + 1);
                            pos = boundary(text, pos);
                            continue 'outer;
                        }
                    }
                }
                Rule::EOI => eoi = true,
                _ => {}
            }
        }
        if eoi {
            break;
        }
        pos += end;
        if count == CHUNK {
            continue;
        }
        // The chunk stopped early: the next request is malformed. Confirm with `one` (it
        // must fail too) and describe what went wrong with a small token walk.
        match RibParser::parse(Rule::one, &text[pos..]) {
            Ok(mut p) => {
                // Defensive: parse it anyway so the reader always progresses.
                if let Some(r) = p
                    .next()
                    .and_then(|one| one.into_inner().find(|q| q.as_rule() == Rule::request))
                {
                    let e = r.as_span().end();
                    if let Ok(req) = build(r, pos, file) {
                        if quiet.binary_search(&(req.span.start as usize)).is_err() {
                            sink(req);
                        }
                    }
                    pos += e.max(1);
                    pos = boundary(text, pos);
                    continue;
                }
                break;
            }
            Err(e) => {
                let pest_pos = match e.location {
                    pest::error::InputLocation::Pos(p) => pos + p,
                    pest::error::InputLocation::Span((s, _)) => pos + s,
                };
                let (d, at, resume) = diagnose(b, pos, file, pest_pos);
                report(d, at);
                let next = boundary(text, resume.max(skip_space(b, pos) + 1));
                if next <= pos {
                    break;
                }
                pos = next;
            }
        }
    }
}

/// The next char boundary at or after `i`.
fn boundary(text: &str, mut i: usize) -> usize {
    while i < text.len() && !text.is_char_boundary(i) {
        i += 1;
    }
    i.min(text.len())
}

#[inline]
fn is_name_start(c: u8) -> bool {
    c.is_ascii_alphabetic() || c == b'_'
}

fn name_end(b: &[u8], mut i: usize) -> usize {
    while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
        i += 1;
    }
    i
}

/// Skips whitespace and comments.
fn skip_space(b: &[u8], mut i: usize) -> usize {
    while i < b.len() {
        if is_space(b[i]) {
            i += 1;
        } else if b[i] == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else {
            break;
        }
    }
    i
}

/// End of a run of characters that are not whitespace or RIB specials (for labels).
fn word_end(b: &[u8], mut i: usize) -> usize {
    let s = i;
    while i < b.len() && !is_space(b[i]) && !matches!(b[i], b'"' | b'#' | b'[' | b']') {
        i += 1;
    }
    if i == s {
        s + 1
    } else {
        i
    }
}

fn snippet(b: &[u8], s: usize, e: usize) -> String {
    let e = e.min(s + 40).min(b.len());
    String::from_utf8_lossy(&b[s.min(e)..e]).into_owned()
}

fn bad_array_token(b: &[u8], file: u32, start: usize, end: usize, open: usize) -> Diag {
    let word = snippet(b, start, end);
    if is_name_start(b[start]) {
        Diag::error(
            "rib::syntax",
            format!("array is not closed before `{word}`"),
        )
        .label(
            Span::new(file, start, end),
            "this looks like the next request",
        )
        .label(Span::new(file, open, open + 1), "array opened here")
        .help("close the array with `]`; the reader skipped to the next request")
    } else {
        Diag::error("rib::syntax", format!("`{word}` is not a number"))
            .label(Span::new(file, start, end), "not a number")
            .label(Span::new(file, open, open + 1), "in this array")
            .help("arrays hold numbers or strings, separated by whitespace")
    }
}

/// Describes the malformed request that starts at (or after whitespace from) `start` by
/// walking its tokens. Returns the diagnostic, the position it is about (for `quiet`), and
/// where to resume reading.
fn diagnose(b: &[u8], start: usize, file: u32, pest_pos: usize) -> (Diag, usize, usize) {
    let span = |s: usize, e: usize| Span::new(file, s.min(b.len()), e.min(b.len()));
    let help_resync = "the reader skipped to the next request name";
    let mut i = skip_space(b, start);
    let first = i;
    // Each arm either continues the walk or returns (diag, at, resume).
    loop {
        i = skip_space(b, i);
        if i >= b.len() {
            break;
        }
        let c = b[i];
        if is_name_start(c) {
            if i == first {
                i = name_end(b, i);
                continue;
            }
            // The walk found a complete request: pest disagreed; fall back to its position.
            break;
        }
        if i == first {
            let e = word_end(b, i);
            let what = if c == b'"' {
                "a string".to_string()
            } else if c == b'[' {
                "an array".to_string()
            } else if scan_number(b, i).is_some() {
                format!("the number `{}`", snippet(b, i, e))
            } else {
                format!("`{}`", snippet(b, i, e))
            };
            let resume = if c == b'"' {
                match string_end(b, i) {
                    Some(e) => lex::resync(b, e),
                    None => lex::next_line(b, i),
                }
            } else {
                lex::resync(b, e)
            };
            let d = Diag::error(
                "rib::syntax",
                format!("expected a request name, found {what}"),
            )
            .label(span(i, e), "expected a request name here")
            .help(format!(
                "every request starts with a bare name such as `WorldBegin`; {help_resync}"
            ));
            return (d, i, resume);
        }
        match c {
            b'"' => match string_end(b, i) {
                Some(e) => i = e,
                None => {
                    let e = lex::next_line(b, i);
                    let d = Diag::error("rib::syntax", "unterminated string")
                        .label(
                            span(i, e.saturating_sub(1).max(i + 1)),
                            "string starts here",
                        )
                        .help("close the string with `\"`; the reader resumed on the next line");
                    return (d, i, e);
                }
            },
            b'[' => {
                let open = i;
                i += 1;
                loop {
                    i = skip_space(b, i);
                    if i >= b.len() {
                        let d = Diag::error("rib::syntax", "unterminated array")
                            .label(span(open, open + 1), "array opened here")
                            .help("close the array with `]`");
                        return (d, open, b.len());
                    }
                    let c = b[i];
                    if c == b']' {
                        i += 1;
                        break;
                    } else if c == b'"' {
                        match string_end(b, i) {
                            Some(e) => i = e,
                            None => {
                                let e = lex::next_line(b, i);
                                let d = Diag::error("rib::syntax", "unterminated string")
                                    .label(span(i, e.saturating_sub(1).max(i + 1)), "string starts here")
                                    .help("close the string with `\"`; the reader resumed on the next line");
                                return (d, i, e);
                            }
                        }
                    } else if let Some((_, e)) = scan_number(b, i) {
                        i = e;
                    } else {
                        let e = word_end(b, i);
                        let d = bad_array_token(b, file, i, e, open);
                        let resume = if is_name_start(c) {
                            i
                        } else {
                            lex::resync(b, e)
                        };
                        return (d, i, resume);
                    }
                }
            }
            b']' => {
                let d = Diag::error("rib::syntax", "`]` without a matching `[`")
                    .label(span(i, i + 1), "unexpected `]`")
                    .help(help_resync);
                return (d, i, lex::resync(b, i + 1));
            }
            _ => {
                if let Some((_, e)) = scan_number(b, i) {
                    i = e;
                    continue;
                }
                let e = word_end(b, i);
                let d = Diag::error("rib::syntax", format!("unexpected `{}`", snippet(b, i, e)))
                    .label(span(i, e), "not a name, number, string or array")
                    .help(help_resync);
                return (d, i, lex::resync(b, e));
            }
        }
    }
    let p = pest_pos.min(b.len());
    let e = if p < b.len() { word_end(b, p) } else { p };
    let d = Diag::error("rib::syntax", "syntax error")
        .label(span(p, e), "unexpected input here")
        .help(help_resync);
    (d, p, lex::resync(b, e))
}

/// Turns one `request` pair into a `Request` (spans offset by `base`).
fn build(pair: Pair<'_, Rule>, base: usize, file: u32) -> Result<Request, BuildError> {
    let sp = |s: pest::Span<'_>| Span::new(file, base + s.start(), base + s.end());
    let mut inner = pair.into_inner();
    let Some(name) = inner.next() else {
        return Err(BuildError::Bad(Diag::error("rib::syntax", "empty request")));
    };
    let mut req = Request {
        name: name.as_str().to_string(),
        span: sp(name.as_span()),
        args: Vec::new(),
    };
    for p in inner {
        let span = sp(p.as_span());
        let value = match p.as_rule() {
            Rule::number => number_value(p.as_str()),
            Rule::string => {
                let s = p.as_str();
                Value::Str(lex::unescape(&s[1..s.len() - 1]))
            }
            Rule::number_array => {
                let s = p.as_str().as_bytes();
                let inside = &s[1..s.len() - 1];
                let start = base + p.as_span().start() + 1;
                lex::scan_number_array(inside).map_err(|(a, e)| BuildError::BadToken {
                    start: start + a,
                    end: start + e,
                    open: start - 1,
                })?
            }
            Rule::general_array => general_array(p, &req.name, base, file)?,
            _ => continue,
        };
        req.args.push(Arg { value, span });
    }
    Ok(req)
}

fn number_value(s: &str) -> Value {
    match scan_number(s.as_bytes(), 0) {
        Some((lex::Num::Int(i), _)) => Value::Int(i),
        Some((lex::Num::Float(f), _)) => Value::Float(f),
        None => Value::Float(0.0), // unreachable: the grammar matched a number
    }
}

/// An array read element by element: all numbers, or all strings.
fn general_array(
    p: Pair<'_, Rule>,
    request: &str,
    base: usize,
    file: u32,
) -> Result<Value, BuildError> {
    let mut nums: Vec<lex::Num> = Vec::new();
    let mut strs: Vec<String> = Vec::new();
    let mut first_num: Option<pest::Span<'_>> = None;
    let mut first_str: Option<pest::Span<'_>> = None;
    for e in p.into_inner() {
        match e.as_rule() {
            Rule::number => {
                first_num.get_or_insert(e.as_span());
                if let Some((n, _)) = scan_number(e.as_str().as_bytes(), 0) {
                    nums.push(n);
                }
            }
            Rule::string => {
                first_str.get_or_insert(e.as_span());
                let s = e.as_str();
                strs.push(lex::unescape(&s[1..s.len() - 1]));
            }
            _ => {}
        }
    }
    if let (Some(n), Some(s)) = (first_num, first_str) {
        let sp = |x: pest::Span<'_>| Span::new(file, base + x.start(), base + x.end());
        return Err(BuildError::Bad(
            Diag::error(
                "rib::badarray",
                format!("array mixes numbers and strings in `{request}`"),
            )
            .label(sp(n), "a number")
            .label(sp(s), "a string")
            .help("an array holds only numbers or only strings; the request was skipped"),
        ));
    }
    if !strs.is_empty() {
        return Ok(Value::StrArray(strs));
    }
    if nums.iter().any(|n| matches!(n, lex::Num::Float(_))) {
        Ok(Value::FloatArray(
            nums.iter()
                .map(|n| match *n {
                    lex::Num::Int(i) => i as f32,
                    lex::Num::Float(f) => f,
                })
                .collect(),
        ))
    } else {
        Ok(Value::IntArray(
            nums.iter()
                .map(|n| match *n {
                    lex::Num::Int(i) => i,
                    lex::Num::Float(f) => f as i64,
                })
                .collect(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diag::SourceMap;

    fn parse(text: &str) -> (Vec<Request>, Vec<Diag>) {
        let sm = SourceMap::new();
        let f = sm.add("t.rib", text);
        let d = Diagnostics::new();
        let mut r = Vec::new();
        parse_text_into(text, f, &d, &[], &mut |q| r.push(q));
        (r, d.take().into_iter().map(|x| x.0).collect())
    }

    fn names(r: &[Request]) -> Vec<&str> {
        r.iter().map(|r| r.name.as_str()).collect()
    }

    #[test]
    fn reads_requests_with_every_value_kind() {
        let (r, d) = parse(
            "##RenderMan RIB-Structure 1.1\nversion 3.03\nFormat 640 480 1 # c\n\
             Surface \"plastic\" \"Kd\" [.5] \"st\" [0 1 2 3]\nDisplay \"a\" \"b\" [\"x\" \"y\"]\nWorldEnd",
        );
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(
            names(&r),
            ["version", "Format", "Surface", "Display", "WorldEnd"]
        );
        assert_eq!(r[0].args[0].value, Value::Float(3.03));
        assert_eq!(r[1].args[2].value, Value::Int(1));
        assert_eq!(r[2].args[2].value, Value::FloatArray(vec![0.5]));
        assert_eq!(r[2].args[4].value, Value::IntArray(vec![0, 1, 2, 3]));
        assert_eq!(
            r[3].args[2].value,
            Value::StrArray(vec!["x".into(), "y".into()])
        );
        // Spans are byte ranges of the text.
        let t = "##RenderMan RIB-Structure 1.1\nversion 3.03\n";
        assert_eq!(r[1].span.start as usize, t.len());
    }

    #[test]
    fn comments_inside_number_arrays() {
        let (r, d) = parse("P [1 2 # one\n 3.5 ]");
        assert!(d.is_empty());
        assert_eq!(r[0].args[0].value, Value::FloatArray(vec![1.0, 2.0, 3.5]));
    }

    #[test]
    fn syntax_error_loses_one_request() {
        let (r, d) = parse("A 1\nB 2 @ 3\nC 4\n");
        assert_eq!(names(&r), ["A", "C"]);
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].code, "rib::syntax");
        assert_eq!(d[0].primary_span().unwrap().start, 8);
    }

    #[test]
    fn unclosed_array_resumes_at_next_name() {
        let (r, d) = parse("A [1 2\nB 3\nC [4]");
        assert_eq!(names(&r), ["B", "C"]);
        assert_eq!(d.len(), 1);
        assert!(d[0].message.contains("not closed"), "{}", d[0].message);
        let (r, d) = parse("A [1 2");
        assert!(r.is_empty());
        assert_eq!(d[0].message, "unterminated array");
    }

    #[test]
    fn stray_values_and_brackets() {
        let (r, d) = parse("1 2 A ] B \"s\" C");
        assert_eq!(names(&r), ["B", "C"]); // `A ]` is malformed: A is lost
        assert_eq!(d.len(), 2);
        assert!(d[0].message.contains("expected a request name"));
    }

    #[test]
    fn unterminated_string_resumes_next_line() {
        let (r, d) = parse("A \"abc\nB 1\n");
        assert_eq!(names(&r), ["B"]);
        assert_eq!(d[0].message, "unterminated string");
    }

    #[test]
    fn mixed_array_is_badarray() {
        let (r, d) = parse("A [1 \"x\"] B");
        assert_eq!(names(&r), ["B"]);
        assert_eq!(d[0].code, "rib::badarray");
    }

    #[test]
    fn many_requests_cross_chunks() {
        let text: String = (0..1000).map(|i| format!("T {i}\n")).collect();
        let (r, d) = parse(&text);
        assert!(d.is_empty());
        assert_eq!(r.len(), 1000);
        assert_eq!(r[999].args[0].value, Value::Int(999));
    }
}
