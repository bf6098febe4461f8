//! Windows onto very long source lines for reports.
//!
//! Exporters write a whole request on one line (Houdini's and MTOR's `LightSource` with sixty
//! parameters runs to 1 500 characters), and a report quoting such a line, once per warning,
//! fills a screen with text nobody reads. Where a line a report would show is longer than
//! [`MAX_LINE`] bytes, the report's source becomes an [`Excerpt`]: just the lines around its
//! labels, each long one cut to a window around the labels on it (`…` marks a cut), while the
//! line and column numbers miette prints stay those of the file.

use miette::{MietteError, MietteSpanContents, SourceCode, SourceSpan, SpanContents};

/// Lines up to this many bytes are shown whole.
pub const MAX_LINE: usize = 200;
/// Bytes kept either side of the labels on a cut line.
const MARGIN: usize = 40;
/// The most of a cut line's labels shown (a longer label is cut at the window's end).
const MAX_WINDOW: usize = 160;
/// Lines of context miette shows around a label (its default).
const CONTEXT: usize = 1;
const ELLIPSIS: &str = "…";

/// One line of an excerpt.
#[derive(Debug)]
struct Line {
    /// Where the line starts in [`Excerpt::text`].
    start: usize,
    /// Bytes of the leading `…` (0 when the window starts at the line's start).
    marker: usize,
    /// The line's index in the file (0-based).
    line: usize,
    /// The file column (0-based, in bytes) of the window's first byte.
    col: usize,
    /// The window in the file: byte range.
    file_start: usize,
    file_end: usize,
}

/// The lines around a report's labels, with long lines cut to windows.
#[derive(Debug)]
pub struct Excerpt {
    name: String,
    text: String,
    lines: Vec<Line>,
}

/// The file line holding byte `pos`: its byte range without its line ending.
fn line_of(text: &str, pos: usize) -> (usize, usize) {
    let b = text.as_bytes();
    let pos = pos.min(b.len());
    let start = b[..pos]
        .iter()
        .rposition(|&c| c == b'\n')
        .map_or(0, |p| p + 1);
    let mut end = b[pos..]
        .iter()
        .position(|&c| c == b'\n')
        .map_or(b.len(), |p| pos + p);
    if end > start && b[end - 1] == b'\r' {
        end -= 1;
    }
    (start, end)
}

fn floor_boundary(text: &str, mut i: usize) -> usize {
    i = i.min(text.len());
    while !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

fn ceil_boundary(text: &str, mut i: usize) -> usize {
    i = i.min(text.len());
    while !text.is_char_boundary(i) {
        i += 1;
    }
    i
}

impl Excerpt {
    /// The excerpt for labels `spans` (byte ranges of `text`, clamped to it) when a line it
    /// would show is longer than [`MAX_LINE`]; `None` when the whole file serves.
    pub fn new(name: &str, text: &str, spans: &[(usize, usize)]) -> Option<Excerpt> {
        if spans.is_empty() {
            return None;
        }
        let lo = spans.iter().map(|s| s.0).min()?.min(text.len());
        let hi = spans.iter().map(|s| s.1.max(s.0)).max()?.min(text.len());
        // The file lines shown: the labels' lines and CONTEXT lines either side.
        let (mut pos, _) = line_of(text, lo);
        for _ in 0..CONTEXT {
            if pos == 0 {
                break;
            }
            pos = line_of(text, pos - 1).0;
        }
        let last = line_of(text, hi).0;
        // The first shown line's index (counted once: files can be large).
        let mut index = text.as_bytes()[..pos]
            .iter()
            .filter(|&&c| c == b'\n')
            .count();
        let mut ranges: Vec<(usize, usize, usize)> = Vec::new();
        let mut after = 0;
        loop {
            let (s, e) = line_of(text, pos);
            ranges.push((s, e, index));
            index += 1;
            if s > last {
                after += 1;
            }
            if s >= last && after >= CONTEXT {
                break;
            }
            match text[e..].find('\n').map(|p| e + p + 1) {
                Some(n) if n < text.len() => pos = n,
                _ => break,
            }
        }
        if ranges.iter().all(|&(s, e, _)| e - s <= MAX_LINE) {
            return None;
        }
        let mut out = String::new();
        let mut lines = Vec::with_capacity(ranges.len());
        for &(s, e, index) in &ranges {
            let (ws, we) = if e - s <= MAX_LINE {
                (s, e)
            } else {
                // The labels on this line (clamped to it); a context line shows its start.
                let on: Vec<(usize, usize)> = spans
                    .iter()
                    .filter(|&&(a, b)| a <= e && b.max(a) >= s)
                    .map(|&(a, b)| (a.max(s), b.max(a).min(e)))
                    .collect();
                let (a, b) = match (on.iter().map(|x| x.0).min(), on.iter().map(|x| x.1).max()) {
                    (Some(a), Some(b)) => (a, b),
                    _ => (s, s),
                };
                let ws = a.saturating_sub(MARGIN).max(s);
                let we = (b.min(a + MAX_WINDOW) + MARGIN).min(e).max(ws);
                (floor_boundary(text, ws), ceil_boundary(text, we))
            };
            let start = out.len();
            let marker = if ws > s { ELLIPSIS.len() } else { 0 };
            if marker > 0 {
                out.push_str(ELLIPSIS);
            }
            out.push_str(&text[ws..we]);
            if we < e {
                out.push_str(ELLIPSIS);
            }
            out.push('\n');
            lines.push(Line {
                start,
                marker,
                line: index,
                col: ws - s,
                file_start: ws,
                file_end: we,
            });
        }
        Some(Excerpt {
            name: name.to_string(),
            text: out,
            lines,
        })
    }

    /// A file byte offset as an offset into the excerpt's text (clamped into the window of
    /// its line, or to the nearest shown line).
    pub fn map(&self, pos: usize) -> usize {
        let l = self
            .lines
            .iter()
            .rev()
            .find(|l| l.file_start <= pos)
            .or(self.lines.first());
        match l {
            Some(l) => {
                let p = pos.clamp(l.file_start, l.file_end);
                l.start + l.marker + (p - l.file_start)
            }
            None => 0,
        }
    }

    /// The excerpt line holding excerpt offset `off`.
    fn line_at(&self, off: usize) -> Option<&Line> {
        self.lines
            .iter()
            .rev()
            .find(|l| l.start <= off)
            .or(self.lines.first())
    }
}

impl SourceCode for Excerpt {
    fn read_span<'a>(
        &'a self,
        span: &SourceSpan,
        context_lines_before: usize,
        context_lines_after: usize,
    ) -> Result<Box<dyn SpanContents<'a> + 'a>, MietteError> {
        let inner =
            self.text
                .as_bytes()
                .read_span(span, context_lines_before, context_lines_after)?;
        let first = self
            .line_at(inner.span().offset())
            .ok_or(MietteError::OutOfBounds)?;
        // The file's line; and its column where miette reads one (a span without context,
        // whose contents start at the span).
        let column = if context_lines_before == 0 {
            let l = self
                .line_at(span.offset())
                .ok_or(MietteError::OutOfBounds)?;
            l.col + span.offset().saturating_sub(l.start + l.marker)
        } else {
            0
        };
        Ok(Box::new(MietteSpanContents::new_named(
            self.name.clone(),
            inner.data(),
            *inner.span(),
            first.line,
            column,
            inner.line_count(),
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_lines_need_no_excerpt() {
        let text = "a\nbb\nccc\n";
        assert!(Excerpt::new("f", text, &[(2, 4)]).is_none());
    }

    #[test]
    fn any_spans_over_any_text_never_panic() {
        // Long and short lines, CRLF endings, multi-byte characters where cuts fall, spans
        // anywhere (across lines, empty, past the end): an excerpt or none, offsets in range.
        let mut h = 12345u32;
        let mut rnd = |n: usize| {
            h = h.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (h >> 8) as usize % n.max(1)
        };
        let pieces = ["abc ", "é", "“x”", "\r\n", "\n", "[1 2 3] ", "\"name\" "];
        for _ in 0..300 {
            let mut text = String::new();
            for _ in 0..rnd(400) {
                let p = pieces[rnd(pieces.len())];
                for _ in 0..1 + rnd(8) {
                    text.push_str(p);
                }
            }
            let spans: Vec<(usize, usize)> = (0..1 + rnd(3))
                .map(|_| {
                    let a = rnd(text.len() + 10);
                    (a, a + rnd(300))
                })
                .collect();
            let clamped: Vec<(usize, usize)> = spans
                .iter()
                .map(|&(a, b)| (a.min(text.len()), b.min(text.len())))
                .collect();
            // The whole report, through miette's renderer.
            let sm = crate::diag::SourceMap::new();
            let f = sm.add("f.rib", text.as_str());
            let sink = crate::diag::Diagnostics::new();
            let mut d = crate::diag::Diag::warning("x::y", "m");
            for &(a, b) in &spans {
                d = d.label(crate::diag::Span::new(f, a, b), "here");
            }
            sink.report(d);
            let _ = sink.render_plain(&sm);
            if let Some(e) = Excerpt::new("f", &text, &clamped) {
                for &(a, b) in &clamped {
                    let (x, y) = (e.map(a), e.map(b));
                    assert!(x <= e.text.len() && y <= e.text.len());
                    let len = y.max(x) - x;
                    let _ = e.read_span(&SourceSpan::from((x, len)), 0, 0).unwrap();
                    let _ = e.read_span(&SourceSpan::from((x, len)), 1, 1).unwrap();
                }
            }
        }
    }

    #[test]
    fn a_long_line_is_cut_around_its_label_and_keeps_file_positions() {
        let long = format!(
            "LightSource \"l\" 1 {} \"snx\" [\"a\"] {}",
            "x ".repeat(400),
            "y ".repeat(400)
        );
        let text = format!("Format 1 1 1\n{long}\nWorldEnd\n");
        let at = text.find("\"snx\"").unwrap();
        let e = Excerpt::new("s.rib", &text, &[(at, at + 5)]).expect("excerpt");
        assert!(e.text.lines().all(|l| l.len() <= MAX_LINE + 2 * MARGIN));
        assert!(e.text.contains("\"snx\""));
        assert!(e.text.starts_with("Format 1 1 1\n…"));
        assert!(e.text.trim_end().ends_with("WorldEnd"));
        let m = e.map(at);
        assert_eq!(&e.text[m..m + 5], "\"snx\"");
        // Miette's header position: line 2, the label's file column.
        let c = e.read_span(&SourceSpan::from((m, 5)), 0, 0).unwrap();
        assert_eq!(c.line(), 1);
        assert_eq!(c.column(), at - "Format 1 1 1\n".len());
        let c = e.read_span(&SourceSpan::from((m, 5)), 1, 1).unwrap();
        assert_eq!(c.line(), 0);
    }
}
