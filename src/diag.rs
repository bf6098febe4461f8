//! Diagnostics shared by every stage.
//!
//! Input: source files registered in a [`SourceMap`]; stages report [`Diag`]s (errors and
//! warnings) into a [`Diagnostics`] sink with a [`Span`] into the map.
//! Output: miette reports with file, line, column, a label on the span and a help line.
//! Invariants: a span always names a registered file; warnings with the same key are shown
//! once, with a count; reporting never panics, even for spans past the end of a file.

use std::collections::HashMap;
use std::fmt;
use std::sync::{Arc, Mutex, RwLock};

use miette::{LabeledSpan, MietteError, NamedSource, SourceCode, SourceSpan, SpanContents};

mod excerpt;
use excerpt::Excerpt;

/// A byte range in one registered source file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Span {
    pub file: u32,
    pub start: u32,
    pub end: u32,
}

impl Span {
    pub fn new(file: u32, start: usize, end: usize) -> Span {
        Span {
            file,
            start: start as u32,
            end: end as u32,
        }
    }
    /// The smallest span covering both (same file assumed; otherwise `self`).
    pub fn to(self, other: Span) -> Span {
        if self.file != other.file {
            return self;
        }
        Span {
            file: self.file,
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }
    pub fn len(&self) -> usize {
        (self.end - self.start) as usize
    }
    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }
}

/// One source file: a name for reports and its text (binary RIB keeps an empty text).
#[derive(Debug)]
pub struct SourceFile {
    pub name: String,
    pub text: Arc<str>,
}

/// All source files of one run. Shared across threads; files are only ever added.
#[derive(Debug, Default)]
pub struct SourceMap {
    files: RwLock<Vec<Arc<SourceFile>>>,
}

impl SourceMap {
    pub fn new() -> SourceMap {
        SourceMap::default()
    }
    /// Registers a file and returns its id.
    pub fn add(&self, name: impl Into<String>, text: impl Into<Arc<str>>) -> u32 {
        let mut files = self.files.write().unwrap_or_else(|e| e.into_inner());
        files.push(Arc::new(SourceFile {
            name: name.into(),
            text: text.into(),
        }));
        (files.len() - 1) as u32
    }
    /// How many files are registered (the next file's id).
    pub fn len(&self) -> usize {
        self.files.read().unwrap_or_else(|e| e.into_inner()).len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn get(&self, id: u32) -> Option<Arc<SourceFile>> {
        let files = self.files.read().unwrap_or_else(|e| e.into_inner());
        files.get(id as usize).cloned()
    }
    /// The text a span covers ("" when out of range).
    pub fn snippet(&self, span: Span) -> String {
        self.get(span.file)
            .and_then(|f| {
                f.text
                    .get(span.start as usize..span.end as usize)
                    .map(str::to_string)
            })
            .unwrap_or_default()
    }
    /// 1-based line and column of a span's start.
    pub fn line_col(&self, span: Span) -> (usize, usize) {
        let Some(f) = self.get(span.file) else {
            return (0, 0);
        };
        let pos = (span.start as usize).min(f.text.len());
        let before = &f.text.as_bytes()[..pos];
        let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
        let col = pos
            - before
                .iter()
                .rposition(|&b| b == b'\n')
                .map(|p| p + 1)
                .unwrap_or(0)
            + 1;
        (line, col)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Severity {
    /// Shown only with `-v`: something recognised and deliberately not acted on.
    Note,
    Warning,
    Error,
}

/// One diagnostic: a code like `rib::syntax`, a message, labelled spans and an optional help.
#[derive(Clone, Debug)]
pub struct Diag {
    pub severity: Severity,
    pub code: &'static str,
    pub message: String,
    pub labels: Vec<(Span, String)>,
    pub help: Option<String>,
}

impl Diag {
    pub fn error(code: &'static str, message: impl Into<String>) -> Diag {
        Diag {
            severity: Severity::Error,
            code,
            message: message.into(),
            labels: vec![],
            help: None,
        }
    }
    pub fn warning(code: &'static str, message: impl Into<String>) -> Diag {
        Diag {
            severity: Severity::Warning,
            code,
            message: message.into(),
            labels: vec![],
            help: None,
        }
    }
    /// A note: shown only at `-v` (a known renderer-specific setting arbor does not use).
    pub fn note(code: &'static str, message: impl Into<String>) -> Diag {
        Diag {
            severity: Severity::Note,
            code,
            message: message.into(),
            labels: vec![],
            help: None,
        }
    }
    pub fn label(mut self, span: Span, text: impl Into<String>) -> Diag {
        self.labels.push((span, text.into()));
        self
    }
    pub fn help(mut self, help: impl Into<String>) -> Diag {
        self.help = Some(help.into());
        self
    }
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
    /// The span of the first label, if any.
    pub fn primary_span(&self) -> Option<Span> {
        self.labels.first().map(|l| l.0)
    }
    /// A miette report with the source of the primary label's file attached.
    pub fn to_report(&self, sources: &SourceMap, count: usize) -> miette::Report {
        let file = self.primary_span().and_then(|s| sources.get(s.file));
        let len = file.as_ref().map(|f| f.text.len()).unwrap_or(0);
        let spans: Vec<(usize, usize, &String)> = self
            .labels
            .iter()
            .filter(|(s, _)| Some(s.file) == self.primary_span().map(|p| p.file))
            .map(|(s, text)| {
                let start = (s.start as usize).min(len);
                let end = (s.end as usize).min(len).max(start);
                (start, end, text)
            })
            .collect();
        // A very long line is shown as a window around the labels (see `excerpt`).
        let excerpt = file.as_ref().and_then(|f| {
            let ranges: Vec<(usize, usize)> = spans.iter().map(|s| (s.0, s.1)).collect();
            Excerpt::new(&f.name, &f.text, &ranges)
        });
        // A file offset where the report's source has it.
        let at = |p: usize| excerpt.as_ref().map_or(p, |x| x.map(p));
        let labels = spans
            .iter()
            .map(|&(start, end, text)| {
                let (a, b) = (at(start), at(end));
                LabeledSpan::new(Some(text.clone()), a, b.max(a) - a)
            })
            .collect();
        let mut message = self.message.clone();
        if count > 1 {
            message.push_str(&format!(" (reported {count} times)"));
        }
        let rep = Reportable {
            message,
            code: self.code,
            severity: self.severity,
            help: self.help.clone(),
            labels,
            source: match excerpt {
                Some(x) => Some(SourceText::Excerpt(x)),
                None => file
                    .map(|f| SourceText::Whole(NamedSource::new(f.name.clone(), f.text.clone()))),
            },
        };
        miette::Report::new(rep)
    }
    /// Plain one-line rendering: `file:line:col: error[code]: message`.
    pub fn to_line(&self, sources: &SourceMap) -> String {
        let sev = match self.severity {
            Severity::Note => "note",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        match self
            .primary_span()
            .and_then(|s| sources.get(s.file).map(|f| (s, f)))
        {
            Some((s, f)) => {
                let (l, c) = sources.line_col(s);
                format!(
                    "{}:{}:{}: {}[{}]: {}",
                    f.name, l, c, sev, self.code, self.message
                )
            }
            None => format!("{}[{}]: {}", sev, self.code, self.message),
        }
    }
}

/// A report's source: the whole file, or an excerpt of its very long lines.
#[derive(Debug)]
enum SourceText {
    Whole(NamedSource<Arc<str>>),
    Excerpt(Excerpt),
}

impl SourceCode for SourceText {
    fn read_span<'a>(
        &'a self,
        span: &SourceSpan,
        context_lines_before: usize,
        context_lines_after: usize,
    ) -> Result<Box<dyn SpanContents<'a> + 'a>, MietteError> {
        match self {
            SourceText::Whole(s) => s.read_span(span, context_lines_before, context_lines_after),
            SourceText::Excerpt(x) => x.read_span(span, context_lines_before, context_lines_after),
        }
    }
}

#[derive(Debug)]
struct Reportable {
    message: String,
    code: &'static str,
    severity: Severity,
    help: Option<String>,
    labels: Vec<LabeledSpan>,
    source: Option<SourceText>,
}

impl fmt::Display for Reportable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}
impl std::error::Error for Reportable {}

impl miette::Diagnostic for Reportable {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.code))
    }
    fn severity(&self) -> Option<miette::Severity> {
        Some(match self.severity {
            Severity::Note => miette::Severity::Advice,
            Severity::Warning => miette::Severity::Warning,
            Severity::Error => miette::Severity::Error,
        })
    }
    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|h| Box::new(h) as Box<dyn fmt::Display>)
    }
    fn source_code(&self) -> Option<&dyn SourceCode> {
        self.source.as_ref().map(|s| s as &dyn SourceCode)
    }
    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        if self.labels.is_empty() {
            None
        } else {
            Some(Box::new(self.labels.iter().cloned()))
        }
    }
}

/// The sink every stage reports into. Thread-safe; warnings are deduplicated by
/// (code, message) and counted; errors are all kept.
#[derive(Debug, Default)]
pub struct Diagnostics {
    inner: Mutex<DiagInner>,
}

#[derive(Debug, Default)]
struct DiagInner {
    list: Vec<(Diag, usize)>,
    index: HashMap<(&'static str, String), usize>,
    errors: usize,
}

impl Diagnostics {
    pub fn new() -> Diagnostics {
        Diagnostics::default()
    }
    pub fn report(&self, d: Diag) {
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        if d.is_error() {
            g.errors += 1;
            g.list.push((d, 1));
            return;
        }
        let key = (d.code, d.message.clone());
        if let Some(&i) = g.index.get(&key) {
            g.list[i].1 += 1;
        } else {
            let i = g.list.len();
            g.index.insert(key, i);
            g.list.push((d, 1));
        }
    }
    pub fn error_count(&self) -> usize {
        self.inner.lock().unwrap_or_else(|e| e.into_inner()).errors
    }
    pub fn has_errors(&self) -> bool {
        self.error_count() > 0
    }
    /// Every diagnostic so far with its count, in report order.
    pub fn snapshot(&self) -> Vec<(Diag, usize)> {
        self.inner
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .list
            .clone()
    }
    /// Reports diagnostics taken from another sink, counts kept, in their order.
    pub fn absorb(&self, taken: Vec<(Diag, usize)>) {
        for (d, n) in taken {
            let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
            if d.is_error() {
                g.errors += 1;
                g.list.push((d, n));
                continue;
            }
            let key = (d.code, d.message.clone());
            if let Some(&i) = g.index.get(&key) {
                g.list[i].1 += n;
            } else {
                let i = g.list.len();
                g.index.insert(key, i);
                g.list.push((d, n));
            }
        }
    }
    /// Removes and returns everything reported so far.
    pub fn take(&self) -> Vec<(Diag, usize)> {
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        g.index.clear();
        g.errors = 0;
        std::mem::take(&mut g.list)
    }
    /// Renders every diagnostic as plain text (no colour), for tests and snapshots.
    pub fn render_plain(&self, sources: &SourceMap) -> String {
        let mut out = String::new();
        for (d, n) in self.snapshot() {
            let handler = miette::GraphicalReportHandler::new_themed(
                miette::GraphicalTheme::unicode_nocolor(),
            )
            .with_width(100);
            let report = d.to_report(sources, n);
            let _ = handler.render_report(&mut out, report.as_ref());
        }
        out
    }
}

/// "Did you mean" helper: the closest candidate by edit distance, if close enough.
pub fn did_you_mean<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let lw = word.to_ascii_lowercase();
    let mut best: Option<(usize, &str)> = None;
    for c in candidates {
        let d = edit_distance(&lw, &c.to_ascii_lowercase());
        if best.map_or(true, |(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    best.filter(|&(d, c)| d <= (c.len().max(word.len()) / 3).max(2))
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for i in 1..=a.len() {
        cur[0] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_from_one() {
        let sm = SourceMap::new();
        let f = sm.add("a.rib", "abc\ndef\n");
        assert_eq!(sm.line_col(Span::new(f, 5, 6)), (2, 2));
        assert_eq!(sm.line_col(Span::new(f, 0, 1)), (1, 1));
    }

    #[test]
    fn warnings_are_counted_once() {
        let d = Diagnostics::new();
        d.report(Diag::warning("x::y", "same"));
        d.report(Diag::warning("x::y", "same"));
        d.report(Diag::error("x::z", "bad"));
        let s = d.snapshot();
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].1, 2);
        assert_eq!(d.error_count(), 1);
    }

    #[test]
    fn did_you_mean_finds_close_names() {
        assert_eq!(
            did_you_mean("Sphre", ["Sphere", "Cone", "Disk"]),
            Some("Sphere")
        );
        assert_eq!(did_you_mean("Zzzzzzzz", ["Sphere", "Cone"]), None);
    }
}
