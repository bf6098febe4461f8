//! Incremental parsing of a shading-language document: only the top-level items whose text
//! changed since the last check go through the parser again.
//!
//! Input: the preprocessor's output for this check and the [`ParseCache`] of the last one.
//! Output: the same [`SourceFile`] (and the same diagnostics) a whole-text parse gives.
//! How: the preprocessed text (comments already gone) is cut after every `}` that closes a
//! top-level brace (outside strings); each piece is parsed alone, or, when the same text was
//! parsed last time without any diagnostic, its items are reused with their spans moved by
//! how far the piece moved in the file. Any piece that reports anything (a syntax error, a
//! missing default) makes the whole text be parsed at once, so diagnostics are exactly
//! `arbor check`'s. The cache is dropped when the set of files (includes) changes.

use std::collections::HashMap;

use crate::diag::{Diagnostics, SourceMap, Span};
use crate::sl::ast::*;
use crate::sl::library::parse_all;
use crate::sl::preprocess::Preprocessed;

#[derive(Default)]
pub struct ParseCache {
    /// Piece text → (its items, where its first byte mapped to).
    pieces: HashMap<String, (Vec<Item>, Span)>,
    /// Names of the registered files when the cache was filled (ids must mean the same).
    files: Vec<String>,
    /// Pieces reused by the last parse (for tests and benchmarks).
    pub reused: usize,
}

fn file_names(sources: &SourceMap) -> Vec<String> {
    (0..)
        .map_while(|i| sources.get(i).map(|f| f.name.clone()))
        .collect()
}

/// Byte ranges of the top-level pieces of preprocessed text.
fn pieces(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let (mut depth, mut start, mut i) = (0i64, 0usize, 0usize);
    while i < b.len() {
        match b[i] {
            b'"' => {
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
            }
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    out.push((start, i + 1));
                    start = i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    let start = start.min(b.len());
    if !text[start..].trim().is_empty() || out.is_empty() {
        out.push((start, b.len()));
    }
    out
}

/// Parses `pre` reusing unchanged pieces from `cache`; refills the cache.
pub fn parse(
    pre: &Preprocessed,
    sources: &SourceMap,
    diags: &Diagnostics,
    cache: &mut ParseCache,
) -> Option<SourceFile> {
    let files = file_names(sources);
    if files != cache.files {
        cache.pieces.clear();
        cache.files = files;
    }
    let mut old = std::mem::take(&mut cache.pieces);
    let mut items = Vec::new();
    let mut reused = 0;
    for (s, e) in pieces(&pre.text) {
        let text = &pre.text[s..e];
        let lead = text.len() - text.trim_start().len();
        let base = pre.span(s + lead, s + lead + 1);
        if let Some((mut got, was)) = old.remove(text) {
            if was.file == base.file {
                let delta = base.start as i64 - was.start as i64;
                for it in &mut got {
                    shift_item(it, base.file, delta);
                }
                items.extend(got.iter().cloned());
                cache.pieces.insert(text.to_string(), (got, base));
                reused += 1;
                continue;
            }
        }
        let local = Diagnostics::new();
        let span = |a: usize, b: usize| pre.span(s + a, s + b);
        match crate::sl::parse::parse(text, &span, &local) {
            Some(f) if local.snapshot().is_empty() => {
                items.extend(f.items.iter().cloned());
                cache.pieces.insert(text.to_string(), (f.items, base));
            }
            _ => {
                // Something to report: the whole text, as `arbor check` parses it.
                cache.pieces.clear();
                cache.reused = 0;
                return parse_all(pre, diags);
            }
        }
    }
    cache.reused = reused;
    Some(SourceFile { items })
}

fn shift(s: &mut Span, file: u32, delta: i64) {
    if s.file == file && delta != 0 {
        s.start = (s.start as i64 + delta).max(0) as u32;
        s.end = (s.end as i64 + delta).max(0) as u32;
    }
}

fn shift_item(it: &mut Item, f: u32, d: i64) {
    match it {
        Item::Shader(s) => {
            shift(&mut s.name_span, f, d);
            shift(&mut s.span, f, d);
            for p in &mut s.params {
                shift_formal(p, f, d);
            }
            shift_block(&mut s.body, f, d);
        }
        Item::Function(fd) => shift_func(fd, f, d),
    }
}

fn shift_func(fd: &mut FuncDef, f: u32, d: i64) {
    shift(&mut fd.ret.span, f, d);
    shift(&mut fd.name_span, f, d);
    shift(&mut fd.span, f, d);
    for p in &mut fd.params {
        shift_formal(p, f, d);
    }
    shift_block(&mut fd.body, f, d);
}

fn shift_formal(p: &mut Formal, f: u32, d: i64) {
    shift(&mut p.ty.span, f, d);
    shift(&mut p.span, f, d);
    if let Some(e) = &mut p.default {
        shift_expr(e, f, d);
    }
}

fn shift_block(b: &mut Block, f: u32, d: i64) {
    shift(&mut b.span, f, d);
    for s in &mut b.stmts {
        shift_stmt(s, f, d);
    }
}

fn shift_stmt(s: &mut Stmt, f: u32, d: i64) {
    shift(&mut s.span, f, d);
    match &mut s.kind {
        StmtKind::VarDecl { ty, vars, .. } => {
            shift(&mut ty.span, f, d);
            for v in vars {
                shift(&mut v.span, f, d);
                if let Some(e) = &mut v.init {
                    shift_expr(e, f, d);
                }
            }
        }
        StmtKind::Function(fd) => shift_func(fd, f, d),
        StmtKind::Expr(e) => shift_expr(e, f, d),
        StmtKind::Block(b) => shift_block(b, f, d),
        StmtKind::If {
            cond,
            then,
            otherwise,
        } => {
            shift_expr(cond, f, d);
            shift_stmt(then, f, d);
            if let Some(o) = otherwise {
                shift_stmt(o, f, d);
            }
        }
        StmtKind::While { cond, body } => {
            shift_expr(cond, f, d);
            shift_stmt(body, f, d);
        }
        StmtKind::For {
            init,
            cond,
            step,
            body,
        } => {
            for e in [init, cond, step].into_iter().flatten() {
                shift_expr(e, f, d);
            }
            shift_stmt(body, f, d);
        }
        StmtKind::Return(e) => {
            if let Some(e) = e {
                shift_expr(e, f, d);
            }
        }
        StmtKind::Illuminance { args, body }
        | StmtKind::Illuminate { args, body }
        | StmtKind::Solar { args, body } => {
            for a in args {
                shift_expr(a, f, d);
            }
            shift_stmt(body, f, d);
        }
        StmtKind::Gather {
            args,
            body,
            otherwise,
        } => {
            for a in args {
                shift_expr(a, f, d);
            }
            shift_stmt(body, f, d);
            if let Some(o) = otherwise {
                shift_stmt(o, f, d);
            }
        }
        StmtKind::Break(_) | StmtKind::Continue(_) | StmtKind::Empty => {}
    }
}

fn shift_expr(e: &mut Expr, f: u32, d: i64) {
    shift(&mut e.span, f, d);
    match &mut e.kind {
        ExprKind::Float(_) | ExprKind::Str(_) | ExprKind::Ident(_) => {}
        ExprKind::Index { base, index } => {
            shift_expr(base, f, d);
            shift_expr(index, f, d);
        }
        ExprKind::Call {
            name_span, args, ..
        } => {
            shift(name_span, f, d);
            for a in args {
                shift_expr(a, f, d);
            }
        }
        ExprKind::Tuple(items) | ExprKind::ArrayLit(items) => {
            for a in items {
                shift_expr(a, f, d);
            }
        }
        ExprKind::Cast { expr, .. } | ExprKind::Unary { expr, .. } => shift_expr(expr, f, d),
        ExprKind::Binary { lhs, rhs, .. } => {
            shift_expr(lhs, f, d);
            shift_expr(rhs, f, d);
        }
        ExprKind::Ternary {
            cond,
            then,
            otherwise,
        } => {
            shift_expr(cond, f, d);
            shift_expr(then, f, d);
            shift_expr(otherwise, f, d);
        }
        ExprKind::Assign { target, value, .. } => {
            shift_expr(target, f, d);
            shift_expr(value, f, d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sl::preprocess::{preprocess, MapResolver};

    fn pre(sources: &SourceMap, text: &str) -> Preprocessed {
        let f = sources.add("t.sl", text);
        preprocess(
            f,
            None,
            sources,
            &[],
            &MapResolver::default(),
            &Diagnostics::new(),
        )
    }

    #[test]
    fn reparsing_gives_the_whole_parse_with_moved_spans() {
        let a = "float f(float x) { return x * 2; }\n/* } */ string g() { return \"}{\"; }\nsurface s() { Ci = f(1) * Cs; }\n";
        // Insert text in the first function: the others move by 3 bytes.
        let b = a.replace("x * 2", "x * 2 + 1");
        let mut cache = ParseCache::default();
        let s1 = SourceMap::new();
        let p1 = pre(&s1, a);
        let d = Diagnostics::new();
        let first = parse(&p1, &s1, &d, &mut cache).unwrap();
        assert_eq!(cache.reused, 0);
        assert_eq!(first, parse_all(&p1, &d).unwrap());
        let s2 = SourceMap::new();
        let p2 = pre(&s2, &b);
        let second = parse(&p2, &s2, &d, &mut cache).unwrap();
        assert_eq!(cache.reused, 2, "two pieces did not change");
        assert_eq!(second, parse_all(&p2, &d).unwrap(), "same tree, same spans");
        assert!(d.snapshot().is_empty());
    }

    #[test]
    fn errors_come_from_the_whole_parse() {
        let mut cache = ParseCache::default();
        let s = SourceMap::new();
        let p = pre(&s, "float f() { return 1 }\nsurface s() { Ci = Cs; }\n");
        let d = Diagnostics::new();
        assert!(parse(&p, &s, &d, &mut cache).is_none());
        let whole = Diagnostics::new();
        assert!(parse_all(&p, &whole).is_none());
        assert_eq!(d.render_plain(&s), whole.render_plain(&s));
        assert!(!d.snapshot().is_empty());
    }
}
