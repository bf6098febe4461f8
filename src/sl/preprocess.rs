//! The shading-language preprocessor: the C preprocessor, as RenderMan shader libraries use it.
//!
//! Input: a file already registered in the [`SourceMap`], `-D` defines and an
//! [`IncludeResolver`] that finds `#include`d files.
//! Output: [`Preprocessed`] text for the parser plus a table from output byte offsets back to
//! (file, byte) in the registered sources, so diagnostics point at the original file and line.
//!
//! Per file: backslash-newlines are spliced and comments replaced by one space (keeping a
//! clean→original offset table); pp-tokens are lexed line by line; directives run; macros expand
//! with Prosser's hide-set algorithm (each token carries the set of macros it came out of, so a
//! macro never re-expands inside its own expansion: the "painted blue" rule).
//!
//! Invariants: one output line per input line (directive and skipped lines become blank lines;
//! lines swallowed by continuations, comments or multi-line macro calls are re-emitted after
//! their logical line); an included file's text replaces its `#include` line; macro output maps
//! to the invocation site, argument tokens to where they were written; never panics; linear work,
//! with budgets on include nesting and macro expansion so hostile input ends with an error.
//!
//! Predefined: `__FILE__`, `__LINE__`, `ARBOR` (= 1). `#pragma` is ignored except `#pragma once`;
//! `#line` changes `__LINE__`/`__FILE__` only (one warning says diagnostics keep real lines).
//! Diagnostic codes: `sl::directive`, `sl::conditional`, `sl::macro`, `sl::include`, `sl::lex`,
//! `sl::#error`, `sl::#warning`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use crate::diag::{Diag, Diagnostics, SourceMap, Span};

/// Finds included files. `from` is the path of the including file (None for the embedded stdlib
/// or a string source: for an included file it is the display name its resolver returned when
/// that names a file on disk, else None); `system` is true for `<file>`. Returns
/// (display name / path, text); the display name also keys `#pragma once` and the file cache.
pub trait IncludeResolver {
    fn resolve(&self, name: &str, system: bool, from: Option<&Path>) -> Option<(String, String)>;
}

/// An include resolver over an in-memory table of name → text (tests, embedded headers).
#[derive(Debug, Default, Clone)]
pub struct MapResolver {
    pub files: HashMap<String, String>,
}

impl IncludeResolver for MapResolver {
    fn resolve(&self, name: &str, _system: bool, _from: Option<&Path>) -> Option<(String, String)> {
        self.files.get(name).map(|t| (name.to_string(), t.clone()))
    }
}

/// Nested `#include` levels before giving up (as GCC).
const MAX_INCLUDE_DEPTH: usize = 200;
/// Files included in one run before giving up (stops exponential self-inclusion).
const MAX_INCLUDES: usize = 5_000;
/// Nesting of macro calls inside macro arguments.
const MAX_EXPAND_DEPTH: usize = 200;
/// Tokens produced by macro expansion in one run (stops exponential definitions).
const MAX_EXPANDED: usize = 2_000_000;
/// Nesting of `#if` sub-expressions.
const MAX_EXPR_DEPTH: usize = 256;

const NO_PARAM: u32 = u32::MAX;

/// One run of output text that came from one place. `identity` segments spell their source
/// byte for byte, so offsets inside them map one to one.
#[derive(Clone, Copy, Debug)]
struct Seg {
    out: u32,
    file: u32,
    start: u32,
    end: u32,
    identity: bool,
}

/// Preprocessor output: the text for the parser and the map back to the sources.
#[derive(Clone, Debug)]
pub struct Preprocessed {
    pub text: String,
    segs: Vec<Seg>,
    file: u32,
}

impl Preprocessed {
    /// Maps a byte range of the output text to a Span in the original source (registered in the
    /// SourceMap). Text from a macro expansion maps to the invocation.
    pub fn span(&self, start: usize, end: usize) -> Span {
        let Some((sa, lo, hi_a)) = self.locate(start) else {
            return Span::new(self.file, 0, 0);
        };
        if end <= start {
            return Span {
                file: sa.file,
                start: lo,
                end: if sa.identity { lo } else { hi_a },
            };
        }
        match self.locate(end - 1) {
            Some((sb, _, hi)) if sb.file == sa.file && hi >= lo => Span {
                file: sa.file,
                start: lo,
                end: hi,
            },
            _ => Span {
                file: sa.file,
                start: lo,
                end: sa.end.max(lo),
            },
        }
    }

    /// The segment holding output byte `pos` and the original range it stands for (for identity
    /// segments the one byte at `pos`).
    fn locate(&self, pos: usize) -> Option<(Seg, u32, u32)> {
        let i = self.segs.partition_point(|s| (s.out as usize) <= pos);
        let s = *self.segs.get(i.checked_sub(1)?)?;
        if s.identity {
            let o = (s.start as usize + (pos - s.out as usize)).min(s.end as usize) as u32;
            Some((s, o, o.saturating_add(1).min(s.end).max(o)))
        } else {
            Some((s, s.start, s.end))
        }
    }
}

/// Preprocesses registered file `file` (whose path, if any, is `path`) with `-D` `defines`.
pub fn preprocess(
    file: u32,
    path: Option<&Path>,
    sources: &SourceMap,
    defines: &[(String, Option<String>)],
    resolver: &dyn IncludeResolver,
    diags: &Diagnostics,
) -> Preprocessed {
    let (name, text) = match sources.get(file) {
        Some(f) => (f.name.clone(), f.text.clone()),
        None => (String::new(), "".into()),
    };
    let mut pp = Pp::new(file, sources, diags, resolver);
    pp.predefine(defines);
    let info = pp.add_info(file, name, path.map(Path::to_path_buf), &text);
    pp.push_ctx(info, 0, None);
    pp.run();
    Preprocessed {
        text: pp.out,
        segs: pp.segs,
        file,
    }
}

// ---------------------------------------------------------------------------------------------
// Tokens

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum K {
    Ident,
    Number,
    Str,
    Char,
    Punct,
    Other,
    Newline,
    Eof,
    /// An empty macro argument next to `##` (C11 6.10.3.3); never emitted.
    Placemarker,
}

/// A pp-token. Its text lives in the arena; (file, start, end) is where it maps back to.
#[derive(Clone, Copy, Debug)]
struct Tok {
    kind: K,
    /// Whitespace came before it.
    ws: bool,
    /// (file, start, end) spells exactly this token's text.
    identity: bool,
    text: u32,
    len: u32,
    /// Hide set (index into [`HideSets`]).
    hs: u32,
    /// For a newline: the source lines swallowed before it (continuations, comments).
    extra: u32,
    file: u32,
    start: u32,
    end: u32,
}

impl Tok {
    fn eof(file: u32) -> Tok {
        Tok {
            kind: K::Eof,
            ws: false,
            identity: false,
            text: 0,
            len: 0,
            hs: 0,
            extra: 0,
            file,
            start: 0,
            end: 0,
        }
    }
    fn span(&self) -> Span {
        Span {
            file: self.file,
            start: self.start,
            end: self.end,
        }
    }
}

fn is_space(c: u8) -> bool {
    matches!(c, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

fn is_ident_start(c: u8) -> bool {
    c.is_ascii_alphabetic() || c == b'_'
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

const PUNCT3: [&[u8]; 3] = [b"...", b"<<=", b">>="];
const PUNCT2: [&[u8]; 20] = [
    b"->", b"++", b"--", b"<<", b">>", b"<=", b">=", b"==", b"!=", b"&&", b"||", b"*=", b"/=",
    b"%=", b"+=", b"-=", b"&=", b"^=", b"|=", b"##",
];

/// Lexes one pp-token at `b[p]` (not whitespace). Returns (kind, length, unterminated literal).
/// Token boundaries always fall on ASCII bytes or whole UTF-8 characters.
fn lex_token(b: &[u8], p: usize) -> (K, usize, bool) {
    let c = b[p];
    let at = |q: usize| b.get(q).copied().unwrap_or(0);
    if c == b'\n' {
        return (K::Newline, 1, false);
    }
    if is_ident_start(c) {
        let mut q = p + 1;
        while q < b.len() && is_ident(b[q]) {
            q += 1;
        }
        return (K::Ident, q - p, false);
    }
    if c.is_ascii_digit() || (c == b'.' && at(p + 1).is_ascii_digit()) {
        let mut q = p + 1;
        while q < b.len() {
            let d = b[q];
            if matches!(d, b'e' | b'E' | b'p' | b'P') && matches!(at(q + 1), b'+' | b'-') {
                q += 2;
            } else if is_ident(d) || d == b'.' {
                q += 1;
            } else {
                break;
            }
        }
        return (K::Number, q - p, false);
    }
    if c == b'"' || c == b'\'' {
        let kind = if c == b'"' { K::Str } else { K::Char };
        let mut q = p + 1;
        loop {
            match b.get(q) {
                None | Some(b'\n') => return (kind, q - p, true),
                Some(b'\\') if !matches!(at(q + 1), b'\n' | 0) => q += 2,
                Some(&d) if d == c => return (kind, q + 1 - p, false),
                Some(_) => q += 1,
            }
        }
    }
    if c >= 0x80 {
        let mut q = p + 1;
        while q < b.len() && (b[q] & 0xc0) == 0x80 {
            q += 1;
        }
        return (K::Other, q - p, false);
    }
    if c.is_ascii_punctuation() {
        let rest = &b[p..];
        if PUNCT3.iter().any(|s| rest.starts_with(s)) {
            return (K::Punct, 3, false);
        }
        if PUNCT2.iter().any(|s| rest.starts_with(s)) {
            return (K::Punct, 2, false);
        }
        return (K::Punct, 1, false);
    }
    (K::Other, 1, false)
}

/// Whether two tokens written side by side would lex differently (so a space must separate them).
fn needs_space(last_kind: K, a: u8, b: u8) -> bool {
    let word = |c: u8| is_ident(c) || c >= 0x80;
    if word(a) && word(b) {
        return true;
    }
    if last_kind == K::Number
        && (b == b'.' || ((b == b'+' || b == b'-') && matches!(a, b'e' | b'E' | b'p' | b'P')))
    {
        return true;
    }
    if a == b'.' && b.is_ascii_digit() {
        return true;
    }
    matches!(
        (a, b),
        (b'+', b'+')
            | (b'-', b'-')
            | (b'-', b'>')
            | (b'<', b'<')
            | (b'>', b'>')
            | (b'&', b'&')
            | (b'|', b'|')
            | (b'#', b'#')
            | (b'.', b'.')
            | (b'/', b'/')
            | (b'/', b'*')
            | (b'*', b'/')
            | (
                b'+' | b'-' | b'*' | b'/' | b'%' | b'<' | b'>' | b'=' | b'!' | b'&' | b'|' | b'^',
                b'='
            )
    )
}

// ---------------------------------------------------------------------------------------------
// Files: splicing, comments, offset tables

/// Result of the first translation phases over one file.
struct Cleaned {
    text: String,
    /// (clean offset, original offset) breakpoints; offsets between run one to one.
    map: Vec<(u32, u32)>,
    /// Clean offsets at which a newline was removed (continuation or block comment).
    swallowed: Vec<u32>,
    /// Original offset of an unterminated block comment.
    open_comment: Option<u32>,
}

fn breakpoint(map: &mut Vec<(u32, u32)>, o: usize, i: usize) {
    let (o, i) = (o as u32, i as u32);
    let last = map[map.len() - 1];
    if last.0 == o {
        let n = map.len() - 1;
        map[n].1 = i;
    } else if i as i64 - o as i64 != last.1 as i64 - last.0 as i64 {
        map.push((o, i));
    }
}

/// Splices backslash-newlines and replaces each comment by one space (C phases 2–3).
fn clean(src: &str) -> Cleaned {
    #[derive(PartialEq)]
    enum St {
        Code,
        Line,
        Block,
        Quote(u8),
    }
    let b = src.as_bytes();
    let mut out: Vec<u8> = Vec::with_capacity(b.len());
    let mut map = vec![(0u32, 0u32)];
    let mut swallowed = Vec::new();
    let mut st = St::Code;
    let mut esc = false;
    let mut comment_start = 0;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'\\' {
            let n = match (b.get(i + 1), b.get(i + 2)) {
                (Some(b'\n'), _) => 2,
                (Some(b'\r'), Some(b'\n')) => 3,
                _ => 0,
            };
            if n > 0 {
                i += n;
                swallowed.push(out.len() as u32);
                breakpoint(&mut map, out.len(), i);
                continue;
            }
        }
        match st {
            St::Code => {
                let next = b.get(i + 1).copied();
                if c == b'/' && (next == Some(b'/') || next == Some(b'*')) {
                    breakpoint(&mut map, out.len(), i);
                    out.push(b' ');
                    comment_start = i;
                    st = if next == Some(b'/') {
                        St::Line
                    } else {
                        St::Block
                    };
                    i += 2;
                } else {
                    if c == b'"' || c == b'\'' {
                        st = St::Quote(c);
                        esc = false;
                    }
                    out.push(c);
                    i += 1;
                }
            }
            St::Line => {
                if c == b'\n' {
                    st = St::Code;
                    breakpoint(&mut map, out.len(), i);
                } else {
                    i += 1;
                }
            }
            St::Block => {
                if c == b'*' && b.get(i + 1) == Some(&b'/') {
                    i += 2;
                    st = St::Code;
                    breakpoint(&mut map, out.len(), i);
                } else {
                    if c == b'\n' {
                        swallowed.push(out.len() as u32);
                    }
                    i += 1;
                }
            }
            St::Quote(q) => {
                out.push(c);
                i += 1;
                if esc {
                    esc = false;
                } else if c == b'\\' {
                    esc = true;
                } else if c == q || c == b'\n' {
                    st = St::Code;
                }
            }
        }
    }
    let open_comment = (st == St::Block).then_some(comment_start as u32);
    let text = String::from_utf8(out)
        .unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned());
    Cleaned {
        text,
        map,
        swallowed,
        open_comment,
    }
}

/// One distinct source file seen in this run (cached across repeated includes).
struct FileInfo {
    id: u32,
    name: String,
    path: Option<PathBuf>,
    /// Start of the cleaned text in the arena.
    base: usize,
    len: usize,
    map: Vec<(u32, u32)>,
    swallowed: Vec<u32>,
    line_starts: Vec<u32>,
    /// Saw `#pragma once`.
    once: bool,
}

impl FileInfo {
    /// Original byte offset of clean offset `p`.
    fn orig(&self, p: usize) -> u32 {
        let i = self.map.partition_point(|m| m.0 as usize <= p);
        let (c, o) = self.map[i.saturating_sub(1)];
        o + (p as u32).saturating_sub(c)
    }
}

/// One file being read: a lexer position plus per-inclusion state.
struct Ctx {
    info: usize,
    /// Clean offset of the next byte.
    pos: usize,
    /// At the beginning of a line.
    bol: bool,
    /// Next entry of `swallowed` not yet emitted.
    sw: usize,
    /// `conds` entries below this belong to the including files.
    cond_base: usize,
    /// Newlines to emit when the file ends (the `#include` line's own), and where they map.
    nl_after: u32,
    ret: Option<Tok>,
    /// `#line`: added to physical line numbers for `__LINE__`, and the `__FILE__` override.
    line_delta: i64,
    file_name: Option<String>,
}

/// One open `#if` group.
struct Cond {
    loc: Span,
    /// Lines of the current branch are kept.
    active: bool,
    /// A branch was (or, when the parent is skipped, can no longer be) taken.
    taken: bool,
    else_seen: bool,
    /// The enclosing group is active.
    parent: bool,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum MKind {
    Object,
    Function { nparams: usize, variadic: bool },
    Line,
    File,
}

struct Macro {
    kind: MKind,
    body: Vec<Tok>,
    /// For each body token, the parameter it names (or NO_PARAM).
    param_at: Vec<u32>,
    loc: Span,
}

/// Macros by interned name id.
#[derive(Default)]
struct Macros(Vec<Option<Rc<Macro>>>);

impl Macros {
    fn get(&self, id: &u32) -> Option<&Rc<Macro>> {
        self.0.get(*id as usize).and_then(Option::as_ref)
    }
    fn contains_key(&self, id: &u32) -> bool {
        self.get(id).is_some()
    }
    fn insert(&mut self, id: u32, m: Rc<Macro>) {
        let i = id as usize;
        if self.0.len() <= i {
            self.0.resize(i + 1, None);
        }
        self.0[i] = Some(m);
    }
    fn remove(&mut self, id: &u32) {
        if let Some(slot) = self.0.get_mut(*id as usize) {
            *slot = None;
        }
    }
}

/// A small fast hasher for short keys (identifiers, id pairs); no HashDoS concern here
/// beyond the budgets, and SipHash dominated the profile.
#[derive(Default, Clone, Copy)]
struct FxHasher(u64);

impl std::hash::Hasher for FxHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(w));
        }
    }
    fn write_u8(&mut self, i: u8) {
        self.write_u64(i as u64);
    }
    fn write_u32(&mut self, i: u32) {
        self.write_u64(i as u64);
    }
    fn write_usize(&mut self, i: usize) {
        self.write_u64(i as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
    fn finish(&self) -> u64 {
        self.0
    }
}

type FxMap<K, V> = HashMap<K, V, std::hash::BuildHasherDefault<FxHasher>>;

/// Interned hide sets: sorted macro-name ids; 0 is the empty set. Unions are memoised, so
/// applying a macro's hide set to every token of its expansion is a hash lookup per token.
#[derive(Default)]
struct HideSets {
    sets: Vec<Box<[u32]>>,
    index: FxMap<Box<[u32]>, u32>,
    unions: FxMap<(u32, u32), u32>,
    inters: FxMap<(u32, u32), u32>,
}

impl HideSets {
    fn new() -> HideSets {
        let mut h = HideSets::default();
        h.intern(Vec::new());
        h
    }
    fn intern(&mut self, v: Vec<u32>) -> u32 {
        if let Some(&i) = self.index.get(v.as_slice()) {
            return i;
        }
        let i = self.sets.len() as u32;
        let b: Box<[u32]> = v.into_boxed_slice();
        self.sets.push(b.clone());
        self.index.insert(b, i);
        i
    }
    fn contains(&self, hs: u32, name: u32) -> bool {
        hs != 0
            && self
                .sets
                .get(hs as usize)
                .is_some_and(|s| s.binary_search(&name).is_ok())
    }
    fn add(&mut self, hs: u32, name: u32) -> u32 {
        let one = self.intern(vec![name]);
        self.union(hs, one)
    }
    fn union(&mut self, a: u32, b: u32) -> u32 {
        if a == b || b == 0 {
            return a;
        }
        if a == 0 {
            return b;
        }
        let key = (a.min(b), a.max(b));
        if let Some(&r) = self.unions.get(&key) {
            return r;
        }
        let (x, y) = (&self.sets[a as usize], &self.sets[b as usize]);
        let mut v: Vec<u32> = x.iter().chain(y.iter()).copied().collect();
        v.sort_unstable();
        v.dedup();
        let r = self.intern(v);
        self.unions.insert(key, r);
        r
    }
    fn inter(&mut self, a: u32, b: u32) -> u32 {
        if a == b {
            return a;
        }
        if a == 0 || b == 0 {
            return 0;
        }
        let key = (a.min(b), a.max(b));
        if let Some(&r) = self.inters.get(&key) {
            return r;
        }
        let y = &self.sets[b as usize];
        let v: Vec<u32> = self.sets[a as usize]
            .iter()
            .copied()
            .filter(|n| y.binary_search(n).is_ok())
            .collect();
        let r = self.intern(v);
        self.inters.insert(key, r);
        r
    }
}

// ---------------------------------------------------------------------------------------------
// The preprocessor

struct Pp<'a> {
    sources: &'a SourceMap,
    diags: &'a Diagnostics,
    resolver: &'a dyn IncludeResolver,
    main_file: u32,
    /// Cleaned file texts and generated token spellings; tokens index into it.
    arena: String,
    infos: Vec<FileInfo>,
    info_by_name: HashMap<String, usize>,
    info_by_id: HashMap<u32, usize>,
    ctxs: Vec<Ctx>,
    conds: Vec<Cond>,
    macros: Macros,
    name_ids: FxMap<Box<str>, u32>,
    hs: HideSets,
    /// Tokens to read before the lexer, last first.
    pending: Vec<Tok>,
    /// Expanding a token list on its own (macro arguments, directive lines): never read the file.
    isolated: bool,
    depth: usize,
    expanded: usize,
    /// The expansion budget ran out: macros are no longer expanded.
    disabled: bool,
    depth_reported: bool,
    include_reported: bool,
    includes: usize,
    /// Newlines consumed by a multi-line macro call, emitted at the end of its line.
    deferred: u32,
    quiet_lex: bool,
    line_warned: bool,
    one: u32,
    zero: u32,
    id_defined: u32,
    id_va_args: u32,
    out: String,
    last_kind: K,
    segs: Vec<Seg>,
}

impl<'a> Pp<'a> {
    fn new(
        main_file: u32,
        sources: &'a SourceMap,
        diags: &'a Diagnostics,
        resolver: &'a dyn IncludeResolver,
    ) -> Pp<'a> {
        let mut pp = Pp {
            sources,
            diags,
            resolver,
            main_file,
            arena: String::from("01"),
            infos: Vec::new(),
            info_by_name: HashMap::new(),
            info_by_id: HashMap::new(),
            ctxs: Vec::new(),
            conds: Vec::new(),
            macros: Macros::default(),
            name_ids: FxMap::default(),
            hs: HideSets::new(),
            pending: Vec::new(),
            isolated: false,
            depth: 0,
            expanded: 0,
            disabled: false,
            depth_reported: false,
            include_reported: false,
            includes: 0,
            deferred: 0,
            quiet_lex: false,
            line_warned: false,
            zero: 0,
            one: 1,
            id_defined: 0,
            id_va_args: 0,
            out: String::new(),
            last_kind: K::Newline,
            segs: Vec::new(),
        };
        pp.id_defined = pp.intern("defined");
        pp.id_va_args = pp.intern("__VA_ARGS__");
        pp
    }

    fn intern(&mut self, s: &str) -> u32 {
        if let Some(&i) = self.name_ids.get(s) {
            return i;
        }
        let i = self.name_ids.len() as u32;
        self.name_ids.insert(s.into(), i);
        i
    }

    fn text(&self, t: Tok) -> &str {
        self.arena
            .get(t.text as usize..(t.text + t.len) as usize)
            .unwrap_or("")
    }

    fn is(&self, t: Tok, s: &str) -> bool {
        let (i, n) = (t.text as usize, s.len());
        t.kind == K::Punct
            && t.len as usize == n
            && match n {
                1 => self.arena.as_bytes().get(i) == s.as_bytes().first(),
                _ => self.arena.as_bytes().get(i..i + n) == Some(s.as_bytes()),
            }
    }

    fn error(&self, code: &'static str, msg: impl Into<String>, span: Span, label: &str) {
        self.diags.report(Diag::error(code, msg).label(span, label));
    }

    fn warn(&self, code: &'static str, msg: impl Into<String>, span: Span, label: &str) {
        self.diags
            .report(Diag::warning(code, msg).label(span, label));
    }

    /// Appends a spelling to the arena and returns a token for it mapped to `at`.
    fn gen_tok(&mut self, kind: K, s: &str, at: Tok) -> Tok {
        let text = self.arena.len() as u32;
        self.arena.push_str(s);
        Tok {
            kind,
            ws: at.ws,
            identity: false,
            text,
            len: s.len() as u32,
            hs: 0,
            extra: 0,
            file: at.file,
            start: at.start,
            end: at.end,
        }
    }

    /// Lexes a whole string (a `-D` value) into tokens mapped to `at`.
    fn lex_str(&mut self, s: &str, at: Span) -> Vec<Tok> {
        let base = self.arena.len();
        self.arena.push_str(s);
        let b = &self.arena.as_bytes()[base..];
        let mut v = Vec::new();
        let mut p = 0;
        let mut ws = false;
        while p < b.len() {
            if is_space(b[p]) || b[p] == b'\n' {
                p += 1;
                ws = true;
                continue;
            }
            let (kind, len, _) = lex_token(b, p);
            v.push(Tok {
                kind,
                ws,
                identity: false,
                text: (base + p) as u32,
                len: len as u32,
                hs: 0,
                extra: 0,
                file: at.file,
                start: at.start,
                end: at.end,
            });
            ws = false;
            p += len;
        }
        v
    }

    fn predefine(&mut self, defines: &[(String, Option<String>)]) {
        let at = Span::new(self.main_file, 0, 0);
        for (name, kind) in [("__FILE__", MKind::File), ("__LINE__", MKind::Line)] {
            let id = self.intern(name);
            self.macros.insert(
                id,
                Rc::new(Macro {
                    kind,
                    body: Vec::new(),
                    param_at: Vec::new(),
                    loc: at,
                }),
            );
        }
        let arbor = self.lex_str("ARBOR 1", at);
        self.define(&arbor, at);
        for (name, value) in defines {
            let line = format!("{} {}", name, value.as_deref().unwrap_or("1"));
            let toks = self.lex_str(&line, at);
            if toks.first().map(|t| t.kind) != Some(K::Ident) || toks[0].ws {
                self.diags.report(
                    Diag::error(
                        "sl::macro",
                        format!("invalid macro name '{name}' in a -D option"),
                    )
                    .help("write -D NAME or -D NAME=VALUE"),
                );
                continue;
            }
            self.define(&toks, at);
        }
    }

    /// Registers the cleaned text of a file and returns its info index.
    fn add_info(&mut self, id: u32, name: String, path: Option<PathBuf>, text: &str) -> usize {
        let c = clean(text);
        if let Some(p) = c.open_comment {
            self.error(
                "sl::lex",
                "unterminated comment",
                Span::new(id, p as usize, p as usize + 2),
                "this comment is never closed",
            );
        }
        let base = self.arena.len();
        self.arena.push_str(&c.text);
        let mut line_starts = vec![0u32];
        line_starts.extend(
            text.bytes()
                .enumerate()
                .filter(|&(_, b)| b == b'\n')
                .map(|(i, _)| i as u32 + 1),
        );
        let idx = self.infos.len();
        self.infos.push(FileInfo {
            id,
            name: name.clone(),
            path,
            base,
            len: c.text.len(),
            map: c.map,
            swallowed: c.swallowed,
            line_starts,
            once: false,
        });
        self.info_by_name.insert(name, idx);
        self.info_by_id.insert(id, idx);
        idx
    }

    fn push_ctx(&mut self, info: usize, nl_after: u32, ret: Option<Tok>) {
        self.ctxs.push(Ctx {
            info,
            pos: 0,
            bol: true,
            sw: 0,
            cond_base: self.conds.len(),
            nl_after,
            ret,
            line_delta: 0,
            file_name: None,
        });
    }

    fn active(&self) -> bool {
        self.conds.last().is_none_or(|c| c.active)
    }

    // --- lexing --------------------------------------------------------------------------

    /// Lexes the next token of the current file. With `stop_at_directive`, a `#` starting a line
    /// is not consumed and Eof is returned instead.
    fn lex(&mut self, stop_at_directive: bool) -> Tok {
        let Some(ctx) = self.ctxs.last_mut() else {
            return Tok::eof(self.main_file);
        };
        let info = &self.infos[ctx.info];
        let b = &self.arena.as_bytes()[info.base..info.base + info.len];
        let mut p = ctx.pos;
        let mut ws = false;
        while p < b.len() && is_space(b[p]) {
            p += 1;
            ws = true;
        }
        ctx.pos = p;
        if p >= b.len() || (stop_at_directive && ctx.bol && b[p] == b'#') {
            return Tok::eof(info.id);
        }
        let (kind, len, unterminated) = lex_token(b, p);
        ctx.pos = p + len;
        let mut extra = 0;
        if kind == K::Newline {
            ctx.bol = true;
            while ctx.sw < info.swallowed.len() && info.swallowed[ctx.sw] as usize <= p {
                ctx.sw += 1;
                extra += 1;
            }
        } else {
            ctx.bol = false;
        }
        let start = info.orig(p);
        let end = info.orig(p + len - 1) + 1;
        let t = Tok {
            kind,
            ws,
            identity: (end - start) as usize == len,
            text: (info.base + p) as u32,
            len: len as u32,
            hs: 0,
            extra,
            file: info.id,
            start,
            end,
        };
        if unterminated && !self.quiet_lex {
            let what = if kind == K::Str { '"' } else { '\'' };
            self.error(
                "sl::lex",
                format!("missing terminating {what} character"),
                t.span(),
                "this literal is not closed on its line",
            );
        }
        t
    }

    fn next_token(&mut self, stop_at_directive: bool) -> Tok {
        if let Some(t) = self.pending.pop() {
            return t;
        }
        if self.isolated {
            return Tok::eof(self.main_file);
        }
        self.lex(stop_at_directive)
    }

    /// At the beginning of a line whose first token is `#`.
    fn at_directive(&mut self) -> bool {
        let Some(ctx) = self.ctxs.last_mut() else {
            return false;
        };
        if !ctx.bol {
            return false;
        }
        let info = &self.infos[ctx.info];
        let b = &self.arena.as_bytes()[info.base..info.base + info.len];
        let mut p = ctx.pos;
        while p < b.len() && is_space(b[p]) {
            p += 1;
        }
        ctx.pos = p;
        b.get(p) == Some(&b'#')
    }

    /// Skips the rest of the current line without lexing it and emits its newline(s).
    fn skip_line(&mut self) {
        let Some(ctx) = self.ctxs.last_mut() else {
            return;
        };
        let info = &self.infos[ctx.info];
        let b = &self.arena.as_bytes()[info.base..info.base + info.len];
        let p = ctx.pos.min(b.len());
        match b[p..].iter().position(|&c| c == b'\n') {
            Some(k) => {
                let q = p + k;
                ctx.pos = q + 1;
                ctx.bol = true;
                let mut extra = 0;
                while ctx.sw < info.swallowed.len() && info.swallowed[ctx.sw] as usize <= q {
                    ctx.sw += 1;
                    extra += 1;
                }
                let o = info.orig(q);
                let t = Tok {
                    kind: K::Newline,
                    ws: false,
                    identity: true,
                    text: (info.base + q) as u32,
                    len: 1,
                    hs: 0,
                    extra,
                    file: info.id,
                    start: o,
                    end: o + 1,
                };
                self.emit_newline(t);
            }
            None => ctx.pos = b.len(),
        }
    }

    /// The tokens up to the end of the line, and the newline (or Eof) that ends it.
    fn line_tokens(&mut self) -> (Vec<Tok>, Tok) {
        let mut v = Vec::new();
        loop {
            let t = self.lex(false);
            match t.kind {
                K::Newline | K::Eof => return (v, t),
                _ => v.push(t),
            }
        }
    }

    // --- output --------------------------------------------------------------------------

    fn push_seg(&mut self, s: Seg) {
        if let Some(l) = self.segs.last_mut() {
            if s.identity
                && l.identity
                && l.file == s.file
                && s.start >= l.end
                && s.out.wrapping_sub(l.out) == s.start.wrapping_sub(l.start)
            {
                l.end = s.end;
                return;
            }
            if l.out == s.out {
                *l = s;
                return;
            }
        }
        self.segs.push(s);
    }

    fn emit(&mut self, t: Tok) {
        let txt = self
            .arena
            .get(t.text as usize..(t.text + t.len) as usize)
            .unwrap_or("");
        if let (Some(&last), Some(&first)) = (self.out.as_bytes().last(), txt.as_bytes().first()) {
            // Tokens that touched in the source were lexed apart there, so they stay apart.
            let touching = t.identity
                && self.segs.last().is_some_and(|l| {
                    l.identity
                        && l.file == t.file
                        && l.end == t.start
                        && l.out.wrapping_add(l.end.wrapping_sub(l.start)) as usize
                            == self.out.len()
                });
            if last != b'\n' && (t.ws || (!touching && needs_space(self.last_kind, last, first))) {
                self.out.push(' ');
            }
        }
        let seg = Seg {
            out: self.out.len() as u32,
            file: t.file,
            start: t.start,
            end: t.end,
            identity: t.identity,
        };
        self.out.push_str(txt);
        self.last_kind = t.kind;
        self.push_seg(seg);
    }

    fn emit_newline(&mut self, t: Tok) {
        if t.kind != K::Newline {
            return;
        }
        let n = 1 + t.extra + std::mem::take(&mut self.deferred);
        self.push_seg(Seg {
            out: self.out.len() as u32,
            file: t.file,
            start: t.start,
            end: t.end,
            identity: true,
        });
        for _ in 0..n {
            self.out.push('\n');
        }
        self.last_kind = K::Newline;
    }

    // --- driver --------------------------------------------------------------------------

    fn run(&mut self) {
        while !self.ctxs.is_empty() {
            if self.pending.is_empty() && self.at_directive() {
                self.directive();
                continue;
            }
            if self.pending.is_empty() && !self.active() {
                self.skip_line_or_eof();
                continue;
            }
            let t = self.next_token(false);
            match t.kind {
                K::Eof => self.pop_file(),
                K::Newline => self.emit_newline(t),
                K::Ident if !self.disabled => {
                    if !self.try_expand(t) {
                        self.emit(t)
                    }
                }
                _ => self.emit(t),
            }
        }
    }

    fn skip_line_or_eof(&mut self) {
        let at_end = self
            .ctxs
            .last()
            .is_none_or(|c| c.pos >= self.infos[c.info].len);
        if at_end {
            self.pop_file();
        } else {
            self.skip_line();
        }
    }

    fn pop_file(&mut self) {
        let Some(ctx) = self.ctxs.pop() else { return };
        while self.conds.len() > ctx.cond_base {
            if let Some(c) = self.conds.pop() {
                self.diags.report(
                    Diag::error("sl::conditional", "unterminated conditional directive")
                        .label(c.loc, "this #if has no matching #endif")
                        .help("add #endif at the end of the group"),
                );
            }
        }
        let info = &self.infos[ctx.info];
        let n = (info.swallowed.len() - ctx.sw.min(info.swallowed.len())) as u32
            + ctx.nl_after
            + std::mem::take(&mut self.deferred);
        if n > 0 {
            let t = match ctx.ret {
                Some(r) => r,
                None => {
                    let o = info.orig(info.len);
                    Tok {
                        file: info.id,
                        start: o,
                        end: o,
                        ..Tok::eof(info.id)
                    }
                }
            };
            self.emit_newline(Tok {
                kind: K::Newline,
                extra: n - 1,
                ..t
            });
        }
    }

    // --- macro expansion -----------------------------------------------------------------

    /// Expands identifier `t` if it names a macro that is not in its hide set: the expansion is
    /// pushed onto `pending` for rescanning. Returns false if `t` stays as it is.
    fn try_expand(&mut self, t: Tok) -> bool {
        let Some(&id) = self.name_ids.get(self.text(t)) else {
            return false;
        };
        let Some(m) = self.macros.get(&id).cloned() else {
            return false;
        };
        if self.hs.contains(t.hs, id) {
            return false;
        }
        match m.kind {
            MKind::Line => {
                let line = self.line_number(t);
                let tok = self.gen_tok(K::Number, &line.to_string(), t);
                self.pending.push(Tok { hs: t.hs, ..tok });
                true
            }
            MKind::File => {
                let name = self.file_name(t.file);
                let tok = self.gen_tok(K::Str, &quote(&name), t);
                self.pending.push(Tok { hs: t.hs, ..tok });
                true
            }
            MKind::Object => {
                let hs = self.hs.add(t.hs, id);
                let out = self.substitute(&m, &[], t, hs);
                self.push_expansion(out);
                true
            }
            MKind::Function { nparams, variadic } => {
                // A function-like macro name not followed by '(' is an ordinary identifier.
                let mut consumed: Vec<Tok> = Vec::new();
                let mut newlines = 0;
                loop {
                    let n = self.next_token(true);
                    match n.kind {
                        K::Newline => {
                            newlines += 1 + n.extra;
                            consumed.push(n);
                        }
                        K::Eof => {
                            self.unread(consumed);
                            return false;
                        }
                        _ if self.is(n, "(") => {
                            consumed.push(n);
                            break;
                        }
                        _ => {
                            consumed.push(n);
                            self.unread(consumed);
                            return false;
                        }
                    }
                }
                let mut args: Vec<Vec<Tok>> = vec![Vec::new()];
                let mut depth = 0usize;
                let mut after_newline = false;
                let rparen = loop {
                    let mut a = self.next_token(true);
                    if a.kind == K::Eof {
                        if !self.isolated {
                            self.diags.report(
                                Diag::error(
                                    "sl::macro",
                                    format!("unterminated argument list invoking macro '{}'", self.text(t)),
                                )
                                .label(t.span(), "this call has no closing ')'")
                                .help("a call cannot run past the end of its file or into a # directive"),
                            );
                        }
                        self.unread(consumed);
                        return false;
                    }
                    consumed.push(a);
                    if a.kind == K::Newline {
                        newlines += 1 + a.extra;
                        after_newline = true;
                        continue;
                    }
                    if after_newline {
                        a.ws = true;
                        after_newline = false;
                    }
                    if self.is(a, "(") {
                        depth += 1;
                    } else if self.is(a, ")") {
                        if depth == 0 {
                            break a;
                        }
                        depth -= 1;
                    } else if depth == 0 && self.is(a, ",") && !(variadic && args.len() == nparams)
                    {
                        args.push(Vec::new());
                        continue;
                    }
                    if let Some(last) = args.last_mut() {
                        last.push(a);
                    }
                };
                let given = if args.len() == 1 && args[0].is_empty() && nparams != 1 {
                    0
                } else {
                    args.len()
                };
                let ok = if variadic {
                    if args.len() + 1 == nparams {
                        args.push(Vec::new());
                    }
                    args.len() == nparams
                } else {
                    given == nparams
                };
                if !ok {
                    let want = if variadic {
                        format!("at least {}", nparams - 1)
                    } else {
                        nparams.to_string()
                    };
                    self.diags.report(
                        Diag::error(
                            "sl::macro",
                            format!(
                                "macro '{}' takes {want} argument{}, but {given} {} given",
                                self.text(t),
                                if want == "1" { "" } else { "s" },
                                if given == 1 { "was" } else { "were" }
                            ),
                        )
                        .label(t.span().to(rparen.span()), "in this call")
                        .label(m.loc, "defined here"),
                    );
                    self.unread(consumed);
                    return false;
                }
                if nparams == 0 {
                    args.clear();
                }
                self.deferred += newlines;
                let hs = self.hs.inter(t.hs, rparen.hs);
                let hs = self.hs.add(hs, id);
                let mut inv = t;
                if rparen.file == t.file && rparen.end >= t.start {
                    inv.end = rparen.end;
                }
                let out = self.substitute(&m, &args, inv, hs);
                self.push_expansion(out);
                true
            }
        }
    }

    /// Puts tokens back so they are read next, in order.
    fn unread(&mut self, toks: Vec<Tok>) {
        self.pending.extend(toks.into_iter().rev());
    }

    fn push_expansion(&mut self, out: Vec<Tok>) {
        self.expanded += out.len();
        if self.expanded > MAX_EXPANDED && !self.disabled {
            self.disabled = true;
            let at = out.first().map(|t| t.span()).unwrap_or_default();
            self.diags.report(
                Diag::error("sl::macro", "macro expansion is too large")
                    .label(at, "expanding here")
                    .help(format!(
                        "more than {MAX_EXPANDED} tokens came out of macros; a macro probably grows exponentially; no more macros are expanded"
                    )),
            );
        }
        self.unread(out);
    }

    /// Fully macro-expands a token list on its own (a macro argument, a directive line).
    fn expand_list(&mut self, toks: Vec<Tok>) -> Vec<Tok> {
        if self.disabled {
            return toks;
        }
        let any_macro = toks.iter().any(|&t| {
            t.kind == K::Ident
                && self
                    .name_ids
                    .get(self.text(t))
                    .is_some_and(|id| self.macros.contains_key(id))
        });
        if !any_macro {
            return toks;
        }
        if self.depth >= MAX_EXPAND_DEPTH {
            if !self.depth_reported {
                self.depth_reported = true;
                let at = toks.first().map(|t| t.span()).unwrap_or_default();
                self.error(
                    "sl::macro",
                    format!("macro calls nested more than {MAX_EXPAND_DEPTH} deep in arguments"),
                    at,
                    "expanding here",
                );
            }
            return toks;
        }
        self.depth += 1;
        let saved = std::mem::replace(&mut self.pending, toks.into_iter().rev().collect());
        let saved_iso = std::mem::replace(&mut self.isolated, true);
        let mut out = Vec::new();
        loop {
            let t = self.next_token(true);
            match t.kind {
                K::Eof => break,
                K::Ident if !self.disabled && self.try_expand(t) => {}
                _ => out.push(t),
            }
        }
        self.pending = saved;
        self.isolated = saved_iso;
        self.depth -= 1;
        out
    }

    /// Replaces a macro's parameters by its arguments (C11 6.10.3.1–3): `#` stringizes, `##`
    /// pastes the unexpanded neighbours, other parameters get their fully expanded argument.
    /// Body tokens map to the invocation `inv`; every token gets hide set `hs` added.
    fn substitute(&mut self, m: &Macro, args: &[Vec<Tok>], inv: Tok, hs: u32) -> Vec<Tok> {
        let func = matches!(m.kind, MKind::Function { .. });
        let variadic = matches!(m.kind, MKind::Function { variadic: true, .. });
        let body = &m.body;
        let at = |t: Tok| Tok {
            file: inv.file,
            start: inv.start,
            end: inv.end,
            identity: false,
            ..t
        };
        let arg = |p: u32| args.get(p as usize).map(Vec::as_slice).unwrap_or(&[]);
        let placemarker = Tok {
            kind: K::Placemarker,
            ..at(inv)
        };
        let mut cache: Vec<Option<Vec<Tok>>> = vec![None; args.len()];
        let mut out: Vec<Tok> = Vec::with_capacity(body.len());
        let mut i = 0;
        while i < body.len() {
            let bt = body[i];
            let p = m.param_at[i];
            if func && self.is(bt, "#") && m.param_at.get(i + 1).is_some_and(|&q| q != NO_PARAM) {
                let s = self.stringize(arg(m.param_at[i + 1]), at(bt));
                out.push(s);
                i += 2;
                continue;
            }
            if self.is(bt, "##") && i > 0 && i + 1 < body.len() {
                i += 1;
                let rp = m.param_at[i];
                let rhs: Vec<Tok> = if rp != NO_PARAM {
                    arg(rp).to_vec()
                } else if func
                    && self.is(body[i], "#")
                    && m.param_at.get(i + 1).is_some_and(|&q| q != NO_PARAM)
                {
                    i += 1;
                    vec![self.stringize(arg(m.param_at[i]), at(body[i - 1]))]
                } else {
                    vec![at(body[i])]
                };
                let lhs = out.pop().unwrap_or(placemarker);
                if rhs.is_empty() {
                    // GNU: `, ## __VA_ARGS__` drops the comma when there are no variadic arguments.
                    let gnu_comma = variadic && rp as usize + 1 == args.len() && self.is(lhs, ",");
                    if !gnu_comma {
                        out.push(lhs);
                    }
                } else if lhs.kind == K::Placemarker
                    || (variadic && rp as usize + 1 == args.len() && self.is(lhs, ","))
                {
                    // GNU: `, ## __VA_ARGS__` with arguments is a plain comma.
                    if lhs.kind != K::Placemarker {
                        out.push(lhs);
                    }
                    out.extend(rhs);
                } else {
                    let pasted = self.paste(lhs, rhs[0], inv);
                    out.extend(pasted);
                    out.extend_from_slice(&rhs[1..]);
                }
                i += 1;
                continue;
            }
            if p != NO_PARAM {
                let start = out.len();
                if body.get(i + 1).is_some_and(|&n| self.is(n, "##")) {
                    if arg(p).is_empty() {
                        out.push(placemarker);
                    } else {
                        out.extend_from_slice(arg(p));
                    }
                } else {
                    let k = p as usize;
                    if k < cache.len() && cache[k].is_none() {
                        cache[k] = Some(self.expand_list(arg(p).to_vec()));
                    }
                    if let Some(Some(e)) = cache.get(k) {
                        out.extend_from_slice(e);
                    }
                }
                if let Some(f) = out.get_mut(start) {
                    f.ws = bt.ws;
                }
                i += 1;
                continue;
            }
            out.push(at(bt));
            i += 1;
        }
        out.retain(|t| t.kind != K::Placemarker);
        for t in &mut out {
            t.hs = self.hs.union(t.hs, hs);
        }
        if let Some(f) = out.first_mut() {
            f.ws = inv.ws;
        }
        out
    }

    /// `#x`: the argument's spelling as a string literal (C11 6.10.3.2).
    fn stringize(&mut self, arg: &[Tok], at: Tok) -> Tok {
        let mut s = String::from("\"");
        for (k, &t) in arg.iter().enumerate() {
            if k > 0 && t.ws {
                s.push(' ');
            }
            let txt = self.text(t);
            if matches!(t.kind, K::Str | K::Char) {
                for c in txt.chars() {
                    if c == '"' || c == '\\' {
                        s.push('\\');
                    }
                    s.push(c);
                }
            } else {
                s.push_str(txt);
            }
        }
        s.push('"');
        self.gen_tok(K::Str, &s, at)
    }

    /// `a ## b`: one token spelled as both; two unchanged tokens (and an error) if that is not
    /// a single pp-token.
    fn paste(&mut self, l: Tok, r: Tok, inv: Tok) -> Vec<Tok> {
        let s = format!("{}{}", self.text(l), self.text(r));
        let b = s.as_bytes();
        if b.is_empty() {
            return vec![];
        }
        let single = !is_space(b[0]) && {
            let (kind, len, bad) = lex_token(b, 0);
            len == b.len() && !bad && kind != K::Newline
        };
        if !single {
            self.diags.report(
                Diag::error(
                    "sl::macro",
                    format!(
                        "pasting \"{}\" and \"{}\" does not give a valid preprocessing token",
                        self.text(l),
                        self.text(r)
                    ),
                )
                .label(inv.span(), "in this macro expansion"),
            );
            return vec![l, r];
        }
        let (kind, _, _) = lex_token(b, 0);
        let t = self.gen_tok(kind, &s, inv);
        vec![Tok {
            ws: l.ws,
            hs: l.hs,
            ..t
        }]
    }

    fn line_number(&self, t: Tok) -> i64 {
        let Some(&i) = self.info_by_id.get(&t.file) else {
            return 0;
        };
        let line = self.infos[i].line_starts.partition_point(|&s| s <= t.start) as i64;
        let delta = self
            .ctxs
            .iter()
            .rev()
            .find(|c| c.info == i)
            .map_or(0, |c| c.line_delta);
        line.saturating_add(delta)
    }

    fn file_name(&self, file: u32) -> String {
        let Some(&i) = self.info_by_id.get(&file) else {
            return String::new();
        };
        self.ctxs
            .iter()
            .rev()
            .find(|c| c.info == i)
            .and_then(|c| c.file_name.clone())
            .unwrap_or_else(|| self.infos[i].name.clone())
    }

    // --- directives ----------------------------------------------------------------------

    fn directive(&mut self) {
        let hash = self.lex(false);
        let name = self.lex(false);
        match name.kind {
            K::Newline => return self.emit_newline(name),
            K::Eof => return,
            _ => {}
        }
        let active = self.active();
        let dspan = hash.span().to(name.span());
        let word = self.text(name).to_string();
        match word.as_str() {
            "if" | "ifdef" | "ifndef" => {
                if !active {
                    self.conds.push(Cond {
                        loc: dspan,
                        active: false,
                        taken: true,
                        else_seen: false,
                        parent: false,
                    });
                    return self.skip_line();
                }
                let (toks, nl) = self.line_tokens();
                let v = if word == "if" {
                    self.eval_if(toks, name)
                } else {
                    let d = self.ifdef(&toks, name, &word);
                    d == (word == "ifdef")
                };
                self.conds.push(Cond {
                    loc: dspan,
                    active: v,
                    taken: v,
                    else_seen: false,
                    parent: true,
                });
                self.emit_newline(nl);
            }
            "elif" | "else" | "endif" => {
                let base = self.ctxs.last().map_or(0, |c| c.cond_base);
                if self.conds.len() <= base {
                    self.error(
                        "sl::conditional",
                        format!("#{word} without #if"),
                        dspan,
                        "no #if is open here",
                    );
                    return self.skip_line();
                }
                let n = self.conds.len() - 1;
                let (parent, taken, else_seen) = {
                    let c = &self.conds[n];
                    (c.parent, c.taken, c.else_seen)
                };
                if word != "endif" && else_seen {
                    self.error(
                        "sl::conditional",
                        format!("#{word} after #else"),
                        dspan,
                        "this group already had its #else",
                    );
                    self.conds[n].active = false;
                    return self.skip_line();
                }
                match word.as_str() {
                    "elif" => {
                        if parent && !taken {
                            let (toks, nl) = self.line_tokens();
                            let v = self.eval_if(toks, name);
                            self.conds[n].active = v;
                            self.conds[n].taken = v;
                            self.emit_newline(nl);
                        } else {
                            self.conds[n].active = false;
                            self.skip_line();
                        }
                    }
                    "else" => {
                        self.conds[n].active = parent && !taken;
                        self.conds[n].taken = true;
                        self.conds[n].else_seen = true;
                        self.end_of_directive(parent, &word);
                    }
                    _ => {
                        self.conds.pop();
                        self.end_of_directive(parent, &word);
                    }
                }
            }
            _ if !active => self.skip_line(),
            "define" => {
                let (toks, nl) = self.line_tokens();
                self.define(&toks, dspan);
                self.emit_newline(nl);
            }
            "undef" => {
                let (toks, nl) = self.line_tokens();
                match toks.first() {
                    Some(&t) if t.kind == K::Ident => {
                        let id = self.intern(self.text(t).to_string().as_str());
                        if id == self.id_defined {
                            self.error(
                                "sl::macro",
                                "'defined' cannot be undefined",
                                t.span(),
                                "here",
                            );
                        } else {
                            self.macros.remove(&id);
                        }
                        if let Some(x) = toks.get(1) {
                            self.warn(
                                "sl::directive",
                                "extra tokens at end of #undef directive",
                                x.span(),
                                "ignored",
                            );
                        }
                    }
                    _ => self.error(
                        "sl::macro",
                        "#undef needs a macro name",
                        toks.first().map_or(dspan, |t| t.span()),
                        "expected an identifier",
                    ),
                }
                self.emit_newline(nl);
            }
            "include" => {
                let (toks, nl) = self.line_tokens();
                self.include(toks, nl, dspan);
            }
            "error" | "warning" => {
                self.quiet_lex = true;
                let (toks, nl) = self.line_tokens();
                self.quiet_lex = false;
                let msg = match (toks.first(), toks.last()) {
                    (Some(a), Some(b)) => self
                        .arena
                        .get(a.text as usize..(b.text + b.len) as usize)
                        .unwrap_or("")
                        .trim()
                        .to_string(),
                    _ => String::new(),
                };
                let span = dspan.to(toks.last().map_or(dspan, |t| t.span()));
                let d = if word == "error" {
                    Diag::error("sl::#error", format!("#error {msg}"))
                } else {
                    Diag::warning("sl::#warning", format!("#warning {msg}"))
                };
                self.diags
                    .report(d.label(span, "reported by this directive"));
                self.emit_newline(nl);
            }
            "line" => {
                let (toks, nl) = self.line_tokens();
                self.line_directive(toks, nl, dspan);
            }
            "pragma" => {
                self.quiet_lex = true;
                let (toks, nl) = self.line_tokens();
                self.quiet_lex = false;
                // `#pragma once`; every other pragma may legally be ignored.
                if toks.len() == 1 && self.text(toks[0]) == "once" {
                    if let Some(c) = self.ctxs.last() {
                        self.infos[c.info].once = true;
                    }
                }
                self.emit_newline(nl);
            }
            "ident" | "sccs" => {
                self.warn(
                    "sl::directive",
                    format!("#{word} is ignored"),
                    dspan,
                    "this directive has no effect in arbor",
                );
                self.skip_line();
            }
            _ if name.kind == K::Number => {
                // GNU line marker: `# 12 "file"`.
                let (mut toks, nl) = self.line_tokens();
                toks.insert(0, name);
                self.line_directive(toks, nl, dspan);
            }
            _ => {
                let known = [
                    "define", "undef", "include", "if", "ifdef", "ifndef", "elif", "else", "endif",
                    "error", "warning", "line", "pragma",
                ];
                let mut d = Diag::error(
                    "sl::directive",
                    format!("unknown preprocessor directive '#{word}'"),
                )
                .label(dspan, "not a directive");
                if let Some(s) = crate::diag::did_you_mean(&word, known) {
                    d = d.help(format!("did you mean '#{s}'?"));
                }
                self.diags.report(d);
                self.skip_line();
            }
        }
    }

    /// The end of `#else`/`#endif`: warns about extra tokens in live code, then emits the line.
    fn end_of_directive(&mut self, live: bool, word: &str) {
        if !live {
            return self.skip_line();
        }
        let (toks, nl) = self.line_tokens();
        if let Some(x) = toks.first() {
            self.warn(
                "sl::directive",
                format!("extra tokens at end of #{word} directive"),
                x.span(),
                "ignored",
            );
        }
        self.emit_newline(nl);
    }

    fn ifdef(&mut self, toks: &[Tok], name: Tok, word: &str) -> bool {
        match toks.first() {
            Some(&t) if t.kind == K::Ident => {
                if let Some(x) = toks.get(1) {
                    self.warn(
                        "sl::directive",
                        format!("extra tokens at end of #{word} directive"),
                        x.span(),
                        "ignored",
                    );
                }
                self.is_defined(t)
            }
            _ => {
                self.error(
                    "sl::conditional",
                    format!("#{word} needs a macro name"),
                    toks.first().map_or(name.span(), |t| t.span()),
                    "expected an identifier",
                );
                false
            }
        }
    }

    fn is_defined(&self, t: Tok) -> bool {
        self.name_ids
            .get(self.text(t))
            .is_some_and(|id| self.macros.contains_key(id))
    }

    fn define(&mut self, toks: &[Tok], dspan: Span) {
        let Some(&name) = toks.first().filter(|t| t.kind == K::Ident) else {
            self.error(
                "sl::macro",
                "macro name must be an identifier",
                toks.first().map_or(dspan, |t| t.span()),
                "expected a name here",
            );
            return;
        };
        let name_s = self.text(name).to_string();
        let id = self.intern(&name_s);
        if id == self.id_defined {
            self.error(
                "sl::macro",
                "'defined' cannot be used as a macro name",
                name.span(),
                "here",
            );
            return;
        }
        let mut i = 1;
        let mut params: Vec<u32> = Vec::new();
        let mut kind = MKind::Object;
        if toks.get(1).is_some_and(|&t| !t.ws && self.is(t, "(")) {
            i = 2;
            let mut variadic = false;
            let bad = |pp: &Self, t: Option<&Tok>, msg: &str| {
                pp.error(
                    "sl::macro",
                    format!("{msg} in the parameter list of macro '{name_s}'"),
                    t.map_or(name.span(), |t| t.span()),
                    "here",
                );
            };
            if toks.get(i).is_some_and(|&t| self.is(t, ")")) {
                i += 1;
            } else {
                loop {
                    let Some(&t) = toks.get(i) else {
                        return bad(self, toks.last(), "missing ')'");
                    };
                    if t.kind == K::Ident {
                        let pid = self.intern(self.text(t).to_string().as_str());
                        if pid == self.id_va_args {
                            return bad(self, Some(&t), "__VA_ARGS__ can only name '...'");
                        }
                        if params.contains(&pid) {
                            return bad(self, Some(&t), "duplicate parameter");
                        }
                        params.push(pid);
                        i += 1;
                        if toks.get(i).is_some_and(|&n| self.is(n, "...")) {
                            variadic = true; // GNU named variadic parameter `args...`
                            i += 1;
                        }
                    } else if self.is(t, "...") {
                        params.push(self.id_va_args);
                        variadic = true;
                        i += 1;
                    } else {
                        return bad(self, Some(&t), "expected a parameter name");
                    }
                    match toks.get(i) {
                        Some(&t) if self.is(t, ")") => {
                            i += 1;
                            break;
                        }
                        Some(&t) if self.is(t, ",") && !variadic => i += 1,
                        t => return bad(self, t, "expected ',' or ')'"),
                    }
                }
            }
            kind = MKind::Function {
                nparams: params.len(),
                variadic,
            };
        } else if toks.get(1).is_some_and(|t| !t.ws) {
            self.warn(
                "sl::macro",
                "missing whitespace after the macro name",
                toks[1].span(),
                "C requires a space here",
            );
        }
        let mut body: Vec<Tok> = toks[i.min(toks.len())..].to_vec();
        if let Some(f) = body.first_mut() {
            f.ws = false;
        }
        let param_at: Vec<u32> = body
            .iter()
            .map(|&t| {
                if t.kind != K::Ident || params.is_empty() {
                    return NO_PARAM;
                }
                self.name_ids
                    .get(self.text(t))
                    .and_then(|pid| params.iter().position(|p| p == pid))
                    .map_or(NO_PARAM, |k| k as u32)
            })
            .collect();
        let func = matches!(kind, MKind::Function { .. });
        for (k, &t) in body.iter().enumerate() {
            if func && self.is(t, "#") && param_at.get(k + 1).is_none_or(|&p| p == NO_PARAM) {
                self.error(
                    "sl::macro",
                    "'#' is not followed by a macro parameter",
                    t.span(),
                    "stringizing needs a parameter name",
                );
                return;
            }
            if self.is(t, "##") && (k == 0 || k + 1 == body.len()) {
                self.error(
                    "sl::macro",
                    "'##' cannot appear at either end of a macro expansion",
                    t.span(),
                    "nothing to paste with",
                );
                return;
            }
        }
        let loc = name
            .span()
            .to(toks.last().map_or(name.span(), |t| t.span()));
        if let Some(old) = self.macros.get(&id) {
            let same =
                old.kind == kind
                    && old.body.len() == body.len()
                    && old.body.iter().zip(&body).enumerate().all(|(k, (a, b))| {
                        self.text(*a) == self.text(*b) && (k == 0 || a.ws == b.ws)
                    })
                    && old.param_at == param_at;
            if !same {
                let builtin = matches!(old.kind, MKind::Line | MKind::File);
                let mut d = Diag::warning("sl::macro", format!("macro '{name_s}' redefined"))
                    .label(name.span(), "redefined here");
                if !builtin && old.loc.end > 0 {
                    d = d.label(old.loc, "previous definition");
                }
                self.diags.report(d);
            }
        }
        self.macros.insert(
            id,
            Rc::new(Macro {
                kind,
                body,
                param_at,
                loc,
            }),
        );
    }

    fn include(&mut self, toks: Vec<Tok>, nl: Tok, dspan: Span) {
        let Some((fname, system, span)) = self.header_name(toks, dspan) else {
            return self.emit_newline(nl);
        };
        if self.ctxs.len() >= MAX_INCLUDE_DEPTH || self.includes >= MAX_INCLUDES {
            // Reported once; deeper or further includes are skipped so the run ends quickly.
            if !self.include_reported {
                self.include_reported = true;
                self.diags.report(
                    Diag::error(
                        "sl::include",
                        format!(
                            "#include nested too deeply (more than {MAX_INCLUDE_DEPTH} levels) or too many includes (more than {MAX_INCLUDES})"
                        ),
                    )
                    .label(span, "including here")
                    .help("a header probably includes itself without an include guard (#ifndef X / #define X / #endif)"),
                );
            }
            return self.emit_newline(nl);
        }
        let from = self
            .ctxs
            .last()
            .and_then(|c| self.infos[c.info].path.clone());
        let Some((display, text)) = self.resolver.resolve(&fname, system, from.as_deref()) else {
            let (o, c) = if system { ('<', '>') } else { ('"', '"') };
            self.diags.report(
                Diag::error("sl::include", format!("cannot find include file {o}{fname}{c}"))
                    .label(span, "not found")
                    .help("searched the including file's folder, the -I folders, the shader path and the standard library"),
            );
            return self.emit_newline(nl);
        };
        self.includes += 1;
        let info = match self.info_by_name.get(&display) {
            Some(&i) => {
                if self.infos[i].once {
                    return self.emit_newline(nl);
                }
                i
            }
            None => {
                let id = self.sources.add(display.clone(), text.as_str());
                // A display name that is a file on disk is its path; anything else (the
                // embedded standard library) has none.
                let path = PathBuf::from(&display);
                let path = path.is_file().then_some(path);
                self.add_info(id, display.clone(), path, &text)
            }
        };
        let ret = (nl.kind == K::Newline).then_some(nl);
        self.push_ctx(info, ret.map_or(0, |t| 1 + t.extra), ret);
    }

    /// The file named by an `#include` line: `"name"`, `<name>` or macros expanding to either.
    fn header_name(&mut self, toks: Vec<Tok>, dspan: Span) -> Option<(String, bool, Span)> {
        let parse = |pp: &Self, toks: &[Tok]| -> Option<(String, bool, Span)> {
            let first = *toks.first()?;
            if first.kind == K::Str {
                let s = pp.text(first);
                let inner = s.strip_prefix('"')?.strip_suffix('"')?;
                return Some((inner.to_string(), false, first.span()));
            }
            if pp.is(first, "<") {
                let k = toks.iter().position(|&t| pp.is(t, ">"))?;
                let gt = toks[k];
                let contiguous = toks[..=k]
                    .windows(2)
                    .all(|w| w[0].text + w[0].len <= w[1].text && w[0].identity && w[1].identity);
                let name = if contiguous {
                    pp.arena
                        .get((first.text + 1) as usize..gt.text as usize)
                        .unwrap_or("")
                        .to_string()
                } else {
                    let mut s = String::new();
                    for (j, &t) in toks[1..k].iter().enumerate() {
                        if j > 0 && t.ws {
                            s.push(' ');
                        }
                        s.push_str(pp.text(t));
                    }
                    s
                };
                return Some((name.trim().to_string(), true, first.span().to(gt.span())));
            }
            None
        };
        if let Some(r) = parse(self, &toks) {
            return Some(r);
        }
        let at = toks.first().map_or(dspan, |t| t.span());
        let expanded = self.expand_list(toks);
        if let Some(r) = parse(self, &expanded) {
            return Some(r);
        }
        self.diags.report(
            Diag::error("sl::include", "#include expects \"FILENAME\" or <FILENAME>")
                .label(at, "not a file name"),
        );
        None
    }

    fn line_directive(&mut self, toks: Vec<Tok>, nl: Tok, dspan: Span) {
        let toks = self.expand_list(toks);
        let n = toks
            .first()
            .filter(|t| t.kind == K::Number)
            .and_then(|&t| self.text(t).parse::<i64>().ok());
        let Some(n) = n else {
            self.error(
                "sl::directive",
                "#line needs a line number",
                toks.first().map_or(dspan, |t| t.span()),
                "expected a positive integer",
            );
            return self.emit_newline(nl);
        };
        let fname = toks
            .get(1)
            .filter(|t| t.kind == K::Str)
            .map(|&t| unquote(self.text(t)));
        let next_line = self.line_number(nl).saturating_add(1);
        if let Some(c) = self.ctxs.last_mut() {
            c.line_delta = c.line_delta.saturating_add(n.saturating_sub(next_line));
            if fname.is_some() {
                c.file_name = fname;
            }
        }
        if !self.line_warned {
            self.line_warned = true;
            self.warn(
                "sl::directive",
                "#line changes __LINE__ and __FILE__ only; diagnostics keep pointing at the real file and line",
                dspan,
                "partly honoured",
            );
        }
        self.emit_newline(nl);
    }

    /// `#if`/`#elif`: `defined` first, then macro expansion, then the integer expression.
    fn eval_if(&mut self, toks: Vec<Tok>, dir: Tok) -> bool {
        if toks.is_empty() {
            self.error(
                "sl::conditional",
                "#if with no expression",
                dir.span(),
                "expected an expression",
            );
            return false;
        }
        let mut v = Vec::with_capacity(toks.len());
        let mut i = 0;
        while i < toks.len() {
            let t = toks[i];
            if t.kind == K::Ident && self.text(t) == "defined" {
                let (name, used) = match (toks.get(i + 1), toks.get(i + 2), toks.get(i + 3)) {
                    (Some(&n), _, _) if n.kind == K::Ident => (Some(n), 2),
                    (Some(&l), Some(&n), Some(&r))
                        if self.is(l, "(") && n.kind == K::Ident && self.is(r, ")") =>
                    {
                        (Some(n), 4)
                    }
                    _ => (None, 1),
                };
                let Some(name) = name else {
                    self.error(
                        "sl::conditional",
                        "operator 'defined' requires an identifier",
                        t.span(),
                        "write defined NAME or defined(NAME)",
                    );
                    return false;
                };
                let d = self.is_defined(name);
                v.push(Tok {
                    kind: K::Number,
                    text: if d { self.one } else { self.zero },
                    len: 1,
                    ..t
                });
                i += used;
            } else {
                v.push(t);
                i += 1;
            }
        }
        let v = self.expand_list(v);
        let defined = |s: &str| {
            self.name_ids
                .get(s)
                .is_some_and(|id| self.macros.contains_key(id))
        };
        let mut e = Eval {
            toks: &v,
            i: 0,
            arena: &self.arena,
            defined: &defined,
            depth: 0,
            end: v.last().copied().unwrap_or(dir),
        };
        let r = e.expr(true).and_then(|x| match e.toks.get(e.i) {
            None => Ok(x),
            Some(&t) => Err((format!("missing binary operator before '{}'", e.text(t)), t)),
        });
        match r {
            Ok(x) => x.v != 0,
            Err((msg, t)) => {
                self.error("sl::conditional", msg, t.span(), "in this #if expression");
                false
            }
        }
    }
}

fn quote(s: &str) -> String {
    let mut q = String::from("\"");
    for c in s.chars() {
        if c == '"' || c == '\\' {
            q.push('\\');
        }
        q.push(c);
    }
    q.push('"');
    q
}

fn unquote(s: &str) -> String {
    let inner = s
        .strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(s);
    let mut out = String::new();
    let mut esc = false;
    for c in inner.chars() {
        if esc || c != '\\' {
            out.push(c);
            esc = false;
        } else {
            esc = true;
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// #if expressions

/// An integer in a `#if` expression: intmax_t or uintmax_t (C11 6.10.1p4).
#[derive(Clone, Copy, Debug)]
struct V {
    v: i64,
    u: bool,
}

type ER = Result<V, (String, Tok)>;

struct Eval<'e> {
    toks: &'e [Tok],
    i: usize,
    arena: &'e str,
    defined: &'e dyn Fn(&str) -> bool,
    depth: usize,
    /// Where to point errors about a missing operand at the end.
    end: Tok,
}

fn prec(op: &str) -> u8 {
    match op {
        "||" => 1,
        "&&" => 2,
        "|" => 3,
        "^" => 4,
        "&" => 5,
        "==" | "!=" => 6,
        "<" | ">" | "<=" | ">=" => 7,
        "<<" | ">>" => 8,
        "+" | "-" => 9,
        "*" | "/" | "%" => 10,
        _ => 0,
    }
}

impl<'e> Eval<'e> {
    fn text(&self, t: Tok) -> &'e str {
        self.arena
            .get(t.text as usize..(t.text + t.len) as usize)
            .unwrap_or("")
    }

    fn peek_punct(&self) -> Option<&'e str> {
        self.toks
            .get(self.i)
            .filter(|t| t.kind == K::Punct)
            .map(|&t| self.text(t))
    }

    fn expect(&mut self, p: &str) -> Result<(), (String, Tok)> {
        if self.peek_punct() == Some(p) {
            self.i += 1;
            Ok(())
        } else {
            let t = self.toks.get(self.i).copied().unwrap_or(self.end);
            Err((format!("expected '{p}' in #if expression"), t))
        }
    }

    fn expr(&mut self, ev: bool) -> ER {
        let mut v = self.cond(ev)?;
        while self.peek_punct() == Some(",") {
            self.i += 1;
            v = self.cond(ev)?;
        }
        Ok(v)
    }

    fn cond(&mut self, ev: bool) -> ER {
        self.depth += 1;
        if self.depth > MAX_EXPR_DEPTH {
            let t = self.toks.get(self.i).copied().unwrap_or(self.end);
            return Err(("#if expression nested too deeply".into(), t));
        }
        let r = self.cond_inner(ev);
        self.depth -= 1;
        r
    }

    fn cond_inner(&mut self, ev: bool) -> ER {
        let c = self.binary(1, ev)?;
        if self.peek_punct() != Some("?") {
            return Ok(c);
        }
        self.i += 1;
        let t = c.v != 0;
        let a = self.expr(ev && t)?;
        self.expect(":")?;
        let b = self.cond(ev && !t)?;
        Ok(V {
            v: if t { a.v } else { b.v },
            u: a.u || b.u,
        })
    }

    fn binary(&mut self, min: u8, ev: bool) -> ER {
        let mut l = self.unary(ev)?;
        while let Some(op) = self.peek_punct() {
            let p = prec(op);
            if p == 0 || p < min {
                break;
            }
            let optok = self.toks[self.i];
            self.i += 1;
            let rev = match op {
                "&&" => ev && l.v != 0,
                "||" => ev && l.v == 0,
                _ => ev,
            };
            let r = self.binary(p + 1, rev)?;
            l = apply(op, l, r, ev).map_err(|m| (m, optok))?;
        }
        Ok(l)
    }

    fn unary(&mut self, ev: bool) -> ER {
        let Some(&t) = self.toks.get(self.i) else {
            return Err((
                "expected a value at the end of the #if expression".into(),
                self.end,
            ));
        };
        self.depth += 1;
        if self.depth > MAX_EXPR_DEPTH {
            return Err(("#if expression nested too deeply".into(), t));
        }
        self.i += 1;
        let s = self.text(t);
        let r = match t.kind {
            K::Punct => match s {
                "(" => {
                    let v = self.expr(ev)?;
                    self.expect(")")?;
                    Ok(v)
                }
                "+" => self.unary(ev),
                "-" => self.unary(ev).map(|x| V {
                    v: x.v.wrapping_neg(),
                    u: x.u,
                }),
                "~" => self.unary(ev).map(|x| V { v: !x.v, u: x.u }),
                "!" => self.unary(ev).map(|x| V {
                    v: (x.v == 0) as i64,
                    u: false,
                }),
                _ => Err((
                    format!("token '{s}' is not valid in preprocessor expressions"),
                    t,
                )),
            },
            K::Number => parse_int(s).map_err(|m| (m, t)),
            K::Char => parse_char(s).map_err(|m| (m, t)),
            K::Ident if s == "defined" => {
                let paren = self.peek_punct() == Some("(");
                if paren {
                    self.i += 1;
                }
                match self.toks.get(self.i) {
                    Some(&n) if n.kind == K::Ident => {
                        self.i += 1;
                        if paren {
                            self.expect(")")?;
                        }
                        Ok(V {
                            v: (self.defined)(self.text(n)) as i64,
                            u: false,
                        })
                    }
                    _ => Err(("operator 'defined' requires an identifier".into(), t)),
                }
            }
            // Identifiers left after macro expansion are 0 (C11 6.10.1p4).
            K::Ident => Ok(V { v: 0, u: false }),
            K::Str => Err((
                "string literals are not valid in preprocessor expressions".into(),
                t,
            )),
            _ => Err((
                format!("token '{s}' is not valid in preprocessor expressions"),
                t,
            )),
        };
        self.depth -= 1;
        r
    }
}

fn apply(op: &str, l: V, r: V, ev: bool) -> Result<V, String> {
    let u = l.u || r.u;
    let (a, b) = (l.v as u64, r.v as u64);
    let num = |v: i64| V { v, u };
    let boolean = |x: bool| V {
        v: x as i64,
        u: false,
    };
    Ok(match op {
        "*" => num(if u {
            a.wrapping_mul(b) as i64
        } else {
            l.v.wrapping_mul(r.v)
        }),
        "/" | "%" => {
            if r.v == 0 {
                if ev {
                    return Err(format!("division by zero in #if ('{op}')"));
                }
                return Ok(num(0));
            }
            num(match (op, u) {
                ("/", true) => (a / b) as i64,
                ("/", false) => l.v.wrapping_div(r.v),
                (_, true) => (a % b) as i64,
                _ => l.v.wrapping_rem(r.v),
            })
        }
        "+" => num(l.v.wrapping_add(r.v)),
        "-" => num(l.v.wrapping_sub(r.v)),
        "<<" | ">>" => {
            // The result has the left operand's type; a negative count shifts the other way.
            let left = (op == "<<") == (r.u || r.v >= 0);
            let n = if r.u || r.v >= 0 {
                b
            } else {
                r.v.unsigned_abs()
            };
            let v = if left {
                if n >= 64 {
                    0
                } else {
                    (a << n) as i64
                }
            } else if l.u {
                if n >= 64 {
                    0
                } else {
                    (a >> n) as i64
                }
            } else {
                l.v >> n.min(63)
            };
            V { v, u: l.u }
        }
        "<" => boolean(if u { a < b } else { l.v < r.v }),
        ">" => boolean(if u { a > b } else { l.v > r.v }),
        "<=" => boolean(if u { a <= b } else { l.v <= r.v }),
        ">=" => boolean(if u { a >= b } else { l.v >= r.v }),
        "==" => boolean(l.v == r.v),
        "!=" => boolean(l.v != r.v),
        "&" => num(l.v & r.v),
        "^" => num(l.v ^ r.v),
        "|" => num(l.v | r.v),
        "&&" => boolean(l.v != 0 && r.v != 0),
        "||" => boolean(l.v != 0 || r.v != 0),
        _ => return Err(format!("unknown operator '{op}'")),
    })
}

/// An integer constant with C suffixes; floating constants are errors in `#if`.
fn parse_int(s: &str) -> Result<V, String> {
    let body = s.trim_end_matches(['u', 'U', 'l', 'L']);
    let suffix = &s[body.len()..];
    let mut u = suffix.contains(['u', 'U']);
    let lower = body.to_ascii_lowercase();
    let (digits, radix) = if let Some(h) = lower.strip_prefix("0x") {
        (h.to_string(), 16)
    } else if let Some(b) = lower.strip_prefix("0b") {
        (b.to_string(), 2)
    } else if lower.len() > 1 && lower.starts_with('0') {
        (lower[1..].to_string(), 8)
    } else {
        (lower.clone(), 10)
    };
    let floating = lower.contains('.')
        || (radix == 10 && lower.contains('e'))
        || (radix == 16 && lower.contains('p'));
    if floating {
        return Err(format!(
            "floating constant '{s}' is not valid in a #if expression"
        ));
    }
    let v = u64::from_str_radix(&digits, radix)
        .map_err(|_| format!("invalid integer constant '{s}' in #if expression"))?;
    if v > i64::MAX as u64 {
        u = true;
    }
    Ok(V { v: v as i64, u })
}

/// A character constant's value (multi-character constants combine bytes as GCC does).
fn parse_char(s: &str) -> Result<V, String> {
    let bad = || format!("invalid character constant {s}");
    let inner = s
        .strip_prefix('\'')
        .and_then(|x| x.strip_suffix('\''))
        .filter(|x| !x.is_empty())
        .ok_or_else(bad)?;
    let b = inner.as_bytes();
    let mut vals: Vec<i64> = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'\\' {
            let c = inner
                .get(i..)
                .and_then(|r| r.chars().next())
                .ok_or_else(bad)?;
            vals.push(c as i64);
            i += c.len_utf8();
            continue;
        }
        i += 1;
        let e = *b.get(i).ok_or_else(bad)?;
        i += 1;
        let v = match e {
            b'n' => 10,
            b't' => 9,
            b'r' => 13,
            b'a' => 7,
            b'b' => 8,
            b'f' => 12,
            b'v' => 11,
            b'e' => 27,
            b'0'..=b'7' => {
                let mut v = (e - b'0') as i64;
                let mut k = 0;
                while k < 2 && i < b.len() && (b'0'..=b'7').contains(&b[i]) {
                    v = v * 8 + (b[i] - b'0') as i64;
                    i += 1;
                    k += 1;
                }
                v
            }
            b'x' => {
                let mut v: i64 = 0;
                let start = i;
                while i < b.len() && b[i].is_ascii_hexdigit() {
                    v = v
                        .wrapping_mul(16)
                        .wrapping_add((b[i] as char).to_digit(16).unwrap_or(0) as i64);
                    i += 1;
                }
                if i == start {
                    return Err(bad());
                }
                v
            }
            other => other as i64,
        };
        vals.push(v);
    }
    let v = if vals.len() == 1 {
        // A plain char is signed: values above 127 wrap negative.
        if vals[0] < 256 {
            vals[0] as u8 as i8 as i64
        } else {
            vals[0]
        }
    } else {
        vals.iter()
            .fold(0i64, |acc, &c| acc.wrapping_shl(8) | (c & 0xff))
    };
    Ok(V { v, u: false })
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Run {
        pre: Preprocessed,
        sources: SourceMap,
        diags: Diagnostics,
        main: u32,
    }

    fn run_with(src: &str, files: &[(&str, &str)], defines: &[(String, Option<String>)]) -> Run {
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let main = sources.add("main.sl", src);
        let resolver = MapResolver {
            files: files
                .iter()
                .map(|(n, t)| (n.to_string(), t.to_string()))
                .collect(),
        };
        let pre = preprocess(main, None, &sources, defines, &resolver, &diags);
        Run {
            pre,
            sources,
            diags,
            main,
        }
    }

    fn run(src: &str) -> Run {
        run_with(src, &[], &[])
    }

    /// The output with all whitespace removed (token content and order only).
    fn squash(s: &str) -> String {
        s.chars().filter(|c| !c.is_whitespace()).collect()
    }

    fn messages(r: &Run) -> Vec<String> {
        r.diags
            .snapshot()
            .iter()
            .map(|(d, _)| d.message.clone())
            .collect()
    }

    fn clean_run(src: &str) -> String {
        let r = run(src);
        assert_eq!(messages(&r), Vec::<String>::new(), "unexpected diagnostics");
        r.pre.text
    }

    #[test]
    fn object_macros_keep_lines() {
        let out = clean_run("#define N 3\nN + N\n#define E\nx E y\n");
        assert_eq!(out, "\n3 + 3\n\nx y\n");
    }

    #[test]
    fn function_macros_and_nested_arguments() {
        let out = clean_run(
            "#define sq(x) ((x)*(x))\n#define max2(a,b) ((a)>(b)?(a):(b))\nsq(a+1) max2(f(1,2), (3,4)) sq()\n",
        );
        assert_eq!(
            squash(&out),
            "((a+1)*(a+1))((f(1,2))>((3,4))?(f(1,2)):((3,4)))(()*())"
        );
    }

    #[test]
    fn function_macro_name_without_parens_is_plain() {
        let out = clean_run("#define f(x) x+1\nf; f (2); g(f)\n");
        assert_eq!(squash(&out), "f;2+1;g(f)");
    }

    #[test]
    fn stringize_and_paste() {
        let out = clean_run(
            "#define str(x) #x\n#define cat(a,b) a##b\nstr( a  +  \"b\\n\" ) cat(foo, bar) cat(1,2) cat(,x) cat(y,) cat(,)\n",
        );
        assert_eq!(out.trim(), r#""a + \"b\\n\"" foobar 12 x y"#);
    }

    /// C11 6.10.3.5 EXAMPLE 3: rescanning, hide sets, empty arguments, pasting.
    #[test]
    fn c_standard_example_3() {
        let src = r#"#define x 3
#define f(a) f(x * (a))
#undef x
#define x 2
#define g f
#define z z[0]
#define h g(~
#define m(a) a(w)
#define w 0,1
#define t(a) a
#define p() int
#define q(x) x
#define r(x,y) x ## y
#define str(x) # x
f(y+1) + f(f(z)) % t(t(g)(0) + t)(1);
g(x+(3,4)-w) | h 5) & m
(f)^m(m);
p() i[q()] = { q(1), r(2,3), r(4,), r(,5), r(,) };
char c[2][6] = { str(hello), str() };
"#;
        let want = r#"f(2 * (y+1)) + f(2 * (f(2 * (z[0])))) % f(2 * (0)) + t(1);
f(2 * (2+(3,4)-0,1)) | f(2 * (~ 5)) & f(2 * (0,1))^m(0,1);
int i[] = { 1, 23, 4, 5, };
char c[2][6] = { "hello", "" };"#;
        let out = clean_run(src);
        assert_eq!(squash(&out), squash(want));
        // The call spanning two lines keeps the line count.
        assert_eq!(out.lines().count(), src.lines().count());
    }

    /// C11 6.10.3.5 EXAMPLE 4: `#` and `##` with string literals.
    #[test]
    fn c_standard_example_4() {
        let src = r#"#define str(s) # s
#define xstr(s) str(s)
#define debug(s, t) printf("x" # s "= %d, x" # t "= %s", \
 x ## s, x ## t)
#define glue(a, b) a ## b
#define xglue(a, b) glue(a, b)
#define HIGHLOW "hello"
#define LOW LOW ", world"
debug(1, 2);
fputs(str(strncmp("abc\0d", "abc", '\4') // this goes away
 == 0) str(: @\n), s);
glue(HIGH, LOW);
xglue(HIGH, LOW)
"#;
        let out = clean_run(src);
        assert!(
            out.contains(r#"printf("x" "1" "= %d, x" "2" "= %s", x1, x2);"#),
            "{out}"
        );
        assert!(
            out.contains(r#""strncmp(\"abc\\0d\", \"abc\", '\\4') == 0" ": @\n""#),
            "{out}"
        );
        assert!(out.contains("\"hello\";"), "{out}");
        assert!(out.contains(r#""hello" ", world""#), "{out}");
    }

    /// C11 6.10.3.5 EXAMPLE 7: variadic macros; plus GNU `, ## __VA_ARGS__` and `args...`.
    #[test]
    fn variadic_macros() {
        let src = r#"#define debug(...) fprintf(stderr, __VA_ARGS__)
#define showlist(...) puts(#__VA_ARGS__)
#define report(test, ...) ((test)?puts(#test): printf(__VA_ARGS__))
#define e(fmt, ...) printf(fmt, ## __VA_ARGS__)
#define named(f, args...) f(args)
debug("Flag");
debug("X = %d\n", x);
showlist(The first, second, and third items.);
report(x>y, "x is %d but y is %d", x, y);
e("a") e("b", 1, 2) named(g, 1, 2)
"#;
        let out = clean_run(src);
        let want = r#"fprintf(stderr, "Flag" );
fprintf(stderr, "X = %d\n", x );
puts( "The first, second, and third items." );
((x>y)?puts("x>y"): printf("x is %d but y is %d", x, y));
printf("a") printf("b", 1, 2) g(1, 2)"#;
        assert_eq!(squash(&out), squash(want));
        assert!(out.contains("\"The first, second, and third items.\""));
    }

    #[test]
    fn self_reference_does_not_loop() {
        let out = clean_run(
            "#define foo foo + 1\n#define a b\n#define b a\n#define f(x) f(x) + g\n#define g f\nfoo; a; b; f(2)\n",
        );
        assert_eq!(squash(&out), "foo+1;a;b;f(2)+f");
    }

    #[test]
    fn conditionals_with_expressions() {
        let src = r#"#define FOO 3
#if (1 << 4) == 16 && -1 < 0 && (0 ? 1/0 : 2) == 2 && ~0 == -1 && 0xff % 16 == 15 && !defined BAR && defined(FOO) && FOO*2 == 6
yes1
#else
no1
#endif
#if -1 < 0u
no2
#elif UNDEFINED_NAME == 0 && 'a' == 97 && 010 == 8 && (2, 3) == 3 && (5 >> 1 | 1 ^ 3) == 2
yes2
#else
no3
#endif
#ifdef FOO
#ifndef FOO
no4
#else
yes3
#endif
#endif
#if 0
#unknown directives are fine when skipped
#if 1/0
#endif
no5
#elif 1
yes4
#endif
"#;
        let out = clean_run(src);
        let words: Vec<&str> = out.split_whitespace().collect();
        assert_eq!(words, ["yes1", "yes2", "yes3", "yes4"]);
        assert_eq!(out.lines().count(), src.lines().count());
    }

    #[test]
    fn include_with_guard_and_pragma_once() {
        let files = [
            (
                "guard.h",
                "#ifndef GUARD_H\n#define GUARD_H\nint g;\n#endif\n",
            ),
            ("once.h", "#pragma once\nint o;\n"),
        ];
        let r = run_with(
            "#include \"guard.h\"\n#include \"guard.h\"\n#include <once.h>\n#include \"once.h\"\nend\n",
            &files,
            &[],
        );
        assert!(messages(&r).is_empty(), "{:?}", messages(&r));
        let words: Vec<&str> = r.pre.text.split_whitespace().collect();
        assert_eq!(words, ["int", "g;", "int", "o;", "end"]);
    }

    #[test]
    fn spans_point_into_included_files() {
        let files = [("inc.h", "a\n// comment\nb OOPS c\n#error broken header\n")];
        let r = run_with("x\n#include \"inc.h\"\ny\n", &files, &[]);
        let pos = r.pre.text.find("OOPS").unwrap();
        let span = r.pre.span(pos, pos + 4);
        let inc = r.sources.get(span.file).unwrap();
        assert_eq!(inc.name, "inc.h");
        assert_eq!(r.sources.snippet(span), "OOPS");
        assert_eq!(r.sources.line_col(span), (3, 3));
        // The #error points into the header at line 4.
        let snap = r.diags.snapshot();
        assert_eq!(snap.len(), 1);
        let d = &snap[0].0;
        assert!(d.is_error() && d.message.contains("broken header"));
        let s = d.primary_span().unwrap();
        assert_eq!(s.file, span.file);
        assert_eq!(r.sources.line_col(s), (4, 1));
        let shown = r.diags.render_plain(&r.sources);
        assert!(shown.contains("inc.h:4:1"), "{shown}");
        // Text after the include maps back to the main file.
        let y = r.pre.text.find('y').unwrap();
        let sy = r.pre.span(y, y + 1);
        assert_eq!((sy.file, r.sources.line_col(sy)), (r.main, (3, 1)));
    }

    #[test]
    fn spans_of_macro_output_map_to_the_invocation() {
        let r =
            run("#define M (1 + bad)\n  x = M;\n/* a\n b */ z = sq(\n1);\n#define sq(v) v*v\nw\n");
        let t = &r.pre.text;
        let pos = t.find("bad").unwrap();
        let s = r.pre.span(pos, pos + 3);
        assert_eq!(r.sources.snippet(s), "M");
        assert_eq!(r.sources.line_col(s), (2, 7));
        let z = t.find('z').unwrap();
        let sz = r.pre.span(z, z + 1);
        assert_eq!(r.sources.line_col(sz), (4, 7));
        // Lines stay aligned after a multi-line comment and a directive.
        assert_eq!(t.lines().nth(6), Some("w"));
        let w = t.find('w').unwrap();
        assert_eq!(r.sources.line_col(r.pre.span(w, w + 1)), (7, 1));
    }

    #[test]
    fn multi_line_call_keeps_line_count() {
        let out = clean_run("#define f(a,b) a+b\nf(1,\n  2)\nz\n");
        assert_eq!(out, "\n1+2\n\nz\n");
    }

    #[test]
    fn gritz_filterwidth_and_noises_macros() {
        let header = r#"/* filterwidth.h - after Larry Gritz, Advanced RenderMan */
#ifndef FILTERWIDTH_H
#define FILTERWIDTH_H 1
#define MINFILTWIDTH 1.0e-6
#define filterwidth(x)  max (abs(Du(x)*du) + abs(Dv(x)*dv), MINFILTWIDTH)
#define filterwidthp(p) max (sqrt(area(p)), MINFILTWIDTH)
#define fadeout(g,g_avg,featuresize,fwidth) \
        mix (g, g_avg, smoothstep(.2,.6,fwidth/featuresize))
#endif
"#;
        let noises = r#"#ifndef NOISES_H
#define NOISES_H
#include "filterwidth.h"
#define snoise(x) (2*noise(x)-1)
#define boxstep(a,b,x) clamp(((x)-(a))/((b)-(a)),0,1)
#define filteredsnoise(p,width) (snoise(p) * (1-smoothstep (0.2,0.75,width)))
#endif
"#;
        let src = r#"#include "noises.h"
surface test(float freq = 4) {
    float fw = filterwidthp(P);
    float n = filteredsnoise(P*freq, filterwidth(s /* s, not t */));
    float b = boxstep(0, /* lo */ 1, mix(a, b, 0.5));
    Ci = fadeout(n, 0, 1, fw);
}
"#;
        let r = run_with(src, &[("filterwidth.h", header), ("noises.h", noises)], &[]);
        assert!(messages(&r).is_empty(), "{:?}", messages(&r));
        let out = squash(&r.pre.text);
        assert!(out.contains("floatfw=max(sqrt(area(P)),1.0e-6);"), "{out}");
        assert!(
            out.contains(
                "floatn=((2*noise(P*freq)-1)*(1-smoothstep(0.2,0.75,max(abs(Du(s)*du)+abs(Dv(s)*dv),1.0e-6))));"
            ),
            "{out}"
        );
        assert!(
            out.contains("floatb=clamp(((mix(a,b,0.5))-(0))/((1)-(0)),0,1);"),
            "{out}"
        );
        assert!(out.contains("Ci=mix(n,0,smoothstep(.2,.6,fw/1));"), "{out}");
        // A token of the shader itself still maps to the shader's own line 4.
        let t = &r.pre.text;
        let pos = t.find("float n").unwrap() + 6;
        let s = r.pre.span(pos, pos + 1);
        assert_eq!((s.file, r.sources.line_col(s)), (r.main, (4, 11)));
    }

    #[test]
    fn strings_and_chars_are_not_expanded() {
        let out = clean_run("#define X 1\n\"X // not a comment /* nor this */\" 'X' X\n");
        assert_eq!(out, "\n\"X // not a comment /* nor this */\" 'X' 1\n");
    }

    #[test]
    fn continuations_and_comments() {
        let out =
            clean_run("#define LONG a + \\\n  b\nLONG // end \\\n still comment\nc /* x */ d\n");
        assert_eq!(out, "\n\na + b\n\nc d\n");
    }

    #[test]
    fn predefined_and_command_line_macros() {
        let r = run_with(
            "#if ARBOR && FOO == 2 && defined BAR\nok __LINE__ __FILE__ BAR\n#endif\n#line 100 \"x.sl\"\n__LINE__ __FILE__\n",
            &[],
            &[("FOO".into(), Some("2".into())), ("BAR".into(), None)],
        );
        let words: Vec<&str> = r.pre.text.split_whitespace().collect();
        assert_eq!(words, ["ok", "2", "\"main.sl\"", "1", "100", "\"x.sl\""]);
        let m = messages(&r);
        assert_eq!(m.len(), 1);
        assert!(m[0].contains("#line"));
    }

    #[test]
    fn errors_are_reported_with_spans() {
        let r = run("#if 1\n#foo bar\n#ifdef X\n#warning careful\n#if 1 +\n#endif\n");
        let snap = r.diags.snapshot();
        let find = |s: &str| {
            snap.iter()
                .find(|(d, _)| d.message.contains(s))
                .map(|(d, _)| (d.is_error(), r.sources.line_col(d.primary_span().unwrap())))
        };
        assert_eq!(
            find("unknown preprocessor directive '#foo'"),
            Some((true, (2, 1)))
        );
        assert_eq!(find("#warning careful"), None, "skipped by #ifdef X");
        assert_eq!(find("expected a value"), None, "skipped by #ifdef X");
        // Two #if groups are left open: each error points at its own #if.
        let open: Vec<(usize, usize)> = snap
            .iter()
            .filter(|(d, _)| d.message.contains("unterminated conditional"))
            .map(|(d, _)| r.sources.line_col(d.primary_span().unwrap()))
            .collect();
        assert_eq!(open, [(3, 1), (1, 1)]);

        let r = run("#warning careful\n#if 1 +\n#endif\n#if\n#endif\n#endif\n");
        let snap = r.diags.snapshot();
        let find = |s: &str| {
            snap.iter()
                .find(|(d, _)| d.message.contains(s))
                .map(|(d, _)| (d.is_error(), r.sources.line_col(d.primary_span().unwrap())))
        };
        assert_eq!(find("#warning careful"), Some((false, (1, 1))));
        assert_eq!(find("expected a value"), Some((true, (2, 7))));
        assert_eq!(find("#if with no expression"), Some((true, (4, 2))));
        assert_eq!(find("#endif without #if"), Some((true, (6, 1))));
    }

    #[test]
    fn macro_argument_errors() {
        let r = run("#define f(a,b) a b\nf(1) f(1,2,3) g f(1,\n");
        let m = messages(&r);
        assert!(
            m.iter()
                .any(|s| s.contains("takes 2 arguments, but 1 was given")),
            "{m:?}"
        );
        assert!(m.iter().any(|s| s.contains("but 3 were given")), "{m:?}");
        assert!(
            m.iter().any(|s| s.contains("unterminated argument list")),
            "{m:?}"
        );
    }

    #[test]
    fn missing_and_recursive_includes() {
        let r = run_with(
            "#include \"nope.h\"\n#include \"self.h\"\nafter\n",
            &[("self.h", "#include \"self.h\"\nx\n")],
            &[],
        );
        let m = messages(&r);
        assert_eq!(m.len(), 2, "{m:?}");
        assert!(m[0].contains("cannot find include file \"nope.h\""));
        assert!(m[1].contains("nested too deeply"));
        assert!(r.pre.text.contains("after"));
    }

    #[test]
    fn exponential_macros_stop_with_an_error() {
        let mut src = String::from("#define m0 x x\n");
        for k in 1..40 {
            src.push_str(&format!("#define m{k} m{} m{}\n", k - 1, k - 1));
        }
        src.push_str("m39\n");
        let r = run(&src);
        assert!(messages(&r).iter().any(|m| m.contains("too large")));
    }

    #[test]
    fn adjacent_tokens_are_kept_apart_only_when_needed() {
        let out = clean_run(
            "#define M -1\n#define P(x) x+\n#define I a\nx=-M; y=P(+); i++ +j; I.b é-é\n",
        );
        assert_eq!(out, "\n\n\nx=- -1; y=+ +; i++ +j; a.b é-é\n");
    }

    #[test]
    fn deep_expressions_and_arguments_end_with_errors() {
        let deep = |open: &str, mid: &str, close: &str, n: usize| {
            format!("{}{}{}", open.repeat(n), mid, close.repeat(n))
        };
        let src = format!(
            "#if {}\n#endif\n#if {}\n#endif\n#if {}\n#endif\n#if {}\n#endif\n",
            deep("(", "1", ")", 100),
            deep("(", "1", ")", 5000),
            deep("- ", "1", "", 5000),
            deep("1?1:", "1", "", 5000)
        );
        let r = run(&src);
        let m = messages(&r);
        assert_eq!(m.len(), 3, "{m:?}");
        assert!(m.iter().all(|s| s.contains("nested too deeply")));
        let src = format!("#define f(x) x\n{}\n", deep("f(", "1", ")", 2000));
        let r = run(&src);
        assert!(messages(&r).iter().any(|s| s.contains("nested more than")));
    }

    #[test]
    fn odd_constants_do_not_panic() {
        let r = run("#if '\\é' || '\\xfffffffffffffffffffff' || 0xffffffffffffffff > 0 || 99999999999999999999999\n#endif\n#line 9223372036854775807\n#line 9223372036854775807\n__LINE__\n");
        let m = messages(&r);
        assert!(
            m.iter().any(|m| m.contains("invalid character constant")),
            "{m:?}"
        );
        let r = run("#if 99999999999999999999999\n#endif\n");
        assert!(messages(&r)
            .iter()
            .any(|m| m.contains("invalid integer constant")));
    }

    /// Resolves `"name"` next to the including file, as the shader compiler's resolver will.
    struct DirResolver;

    impl IncludeResolver for DirResolver {
        fn resolve(
            &self,
            name: &str,
            _system: bool,
            from: Option<&Path>,
        ) -> Option<(String, String)> {
            let dir = from?.parent()?;
            let p = dir.join(name);
            let text = std::fs::read_to_string(&p).ok()?;
            Some((p.to_string_lossy().into_owned(), text))
        }
    }

    #[test]
    fn includes_are_found_next_to_the_including_file() {
        let dir = std::env::temp_dir().join(format!("arbor-pp-{}", std::process::id()));
        let sub = dir.join("sub");
        std::fs::create_dir_all(&sub).unwrap();
        std::fs::write(sub.join("a.h"), "#include \"b.h\"\nA\n").unwrap();
        std::fs::write(sub.join("b.h"), "B\n").unwrap();
        let main_path = dir.join("main.sl");
        let src = "#include \"sub/a.h\"\nM\n";
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let main = sources.add(main_path.to_string_lossy(), src);
        let pre = preprocess(main, Some(&main_path), &sources, &[], &DirResolver, &diags);
        let _ = std::fs::remove_dir_all(&dir);
        assert!(diags.snapshot().is_empty());
        let words: Vec<&str> = pre.text.split_whitespace().collect();
        assert_eq!(words, ["B", "A", "M"]);
        let b = pre.text.find('B').unwrap();
        let name = sources.get(pre.span(b, b + 1).file).unwrap().name.clone();
        assert!(name.ends_with("b.h"), "{name}");
    }

    /// A tiny deterministic generator for the fuzz test.
    fn xorshift(state: &mut u64) -> u64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        *state
    }

    #[test]
    fn random_input_never_panics() {
        let pieces = [
            "#define ",
            "#if ",
            "#ifdef ",
            "#elif ",
            "#else",
            "#endif",
            "#undef ",
            "#include \"r.h\"",
            "#include <",
            "#line ",
            "#error x",
            "#pragma once",
            "#",
            "##",
            "(",
            ")",
            ",",
            "...",
            "\"",
            "'",
            "/*",
            "*/",
            "//",
            "\\\n",
            "\n",
            "\n",
            " ",
            " ",
            "a",
            "b",
            "f",
            "f(",
            "x",
            "1",
            "0x",
            "defined",
            "__VA_ARGS__",
            "__LINE__",
            "__FILE__",
            "<",
            ">",
            "?",
            ":",
            "/",
            "-",
            "é",
            "\t",
            "\r\n",
            "1/0",
            "'\\",
            "99999999999999999999",
            "#line 9223372036854775807\n",
            "#if '\\x",
            "0xffffffffffffffff",
            "<<",
            "%",
        ];
        let mut st = 0x9e3779b97f4a7c15u64;
        // ARBOR_PP_FUZZ=N runs more cases locally.
        let cases: u64 = std::env::var("ARBOR_PP_FUZZ")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(300);
        for case in 0..cases {
            let n = (xorshift(&mut st) % 120) as usize;
            let mut src = String::new();
            for _ in 0..n {
                src.push_str(pieces[(xorshift(&mut st) % pieces.len() as u64) as usize]);
            }
            let inc = if case % 2 == 0 {
                src.clone()
            } else {
                "#include \"r.h\"\nf(".to_string()
            };
            let r = run_with(&src, &[("r.h", &inc)], &[]);
            let len = r.pre.text.len();
            for k in 0..8 {
                let a = (xorshift(&mut st) as usize) % (len + 2);
                let b = (xorshift(&mut st) as usize) % (len + 2);
                let s = r.pre.span(a, b + k);
                let _ = r.sources.line_col(s);
            }
        }
    }

    #[test]
    fn large_macro_heavy_shader_is_fast() {
        let mut src = String::from(
            "#define MINFILTWIDTH 1.0e-6\n#define filterwidth(x) max(abs(Du(x)*du) + abs(Dv(x)*dv), MINFILTWIDTH)\n\
             #define snoise(x) (2*noise(x)-1)\n#define boxstep(a,b,x) clamp(((x)-(a))/((b)-(a)),0,1)\n\
             #define fsn(p,w) (snoise(p) * (1-smoothstep(0.2,0.75,w)))\n",
        );
        let mut k = 0;
        while src.len() < 50_000 {
            src.push_str(&format!(
                "float v{k} = fsn(P*{k}, filterwidth(s)) + boxstep(0, 1, snoise(t)); /* c */\n"
            ));
            k += 1;
        }
        let t0 = std::time::Instant::now();
        let r = run(&src);
        let dt = t0.elapsed();
        assert!(messages(&r).is_empty());
        assert_eq!(r.pre.text.lines().count(), src.lines().count());
        eprintln!("50 KB macro-heavy shader preprocessed in {dt:?}");
        // Generous bound for a dev build on a shared CI machine.
        assert!(dt.as_millis() < 1000, "took {dt:?}");
    }
}
