//! The names of one shading-language file: what is declared where, and which use refers to
//! which declaration.
//!
//! Input: a parsed [`ast::SourceFile`] and the [`SourceMap`] its spans point into.
//! Output: an [`Index`] of declarations (shaders, functions, parameters, locals) with their
//! written type, name span, the byte range where they are visible and a doc line (the comment
//! just above a function or shader), and of references (identifier and call spans) resolved
//! by the language's lexical scoping (a user function shadows a built-in).
//! Invariants: only plain data is kept (no AST); spans are the parser's (already mapped
//! through the preprocessor, so names from an included header point into the header).

use std::collections::HashMap;

use crate::diag::{SourceMap, Span};
use crate::sl::ast::*;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeclKind {
    Shader,
    Function,
    Param,
    Formal,
    Local,
}

#[derive(Clone, Debug)]
pub struct Decl {
    pub name: String,
    pub kind: DeclKind,
    /// The declaration as written in RSL: `uniform float Kd = 0.5`, `float f(point p)`.
    pub detail: String,
    /// The name where it is declared.
    pub span: Span,
    /// The whole declaration (function body included).
    pub full: Span,
    /// Where the name can be used (same file as `span`).
    pub visible: (u32, u32),
    /// The comment right above a shader or function.
    pub doc: Option<String>,
    /// The shader or function it belongs to.
    pub parent: Option<usize>,
}

#[derive(Clone, Debug, Default)]
pub struct Index {
    pub decls: Vec<Decl>,
    /// (use span, declaration).
    pub refs: Vec<(Span, usize)>,
}

impl Index {
    /// The declaration named or used at byte `offset` of `file`.
    pub fn at(&self, file: u32, offset: u32) -> Option<&Decl> {
        let inside = |s: &Span| s.file == file && s.start <= offset && offset <= s.end;
        self.refs
            .iter()
            .filter(|(s, _)| inside(s))
            .min_by_key(|(s, _)| s.len())
            .map(|&(_, d)| &self.decls[d])
            .or_else(|| self.decls.iter().find(|d| inside(&d.span)))
    }

    /// Declarations usable at byte `offset` of `file` (innermost first, one per name).
    pub fn visible_at(&self, file: u32, offset: u32) -> Vec<&Decl> {
        let mut out: Vec<&Decl> = self
            .decls
            .iter()
            .filter(|d| {
                d.kind == DeclKind::Function && d.parent.is_none()
                    || d.span.file == file && d.visible.0 <= offset && offset <= d.visible.1
            })
            .collect();
        // Innermost (latest visible start) wins.
        out.sort_by_key(|d| std::cmp::Reverse(d.visible.0));
        let mut seen = std::collections::HashSet::new();
        out.retain(|d| seen.insert(d.name.clone()));
        out
    }
}

/// Builds the index of a parsed file.
pub fn build(ast: &SourceFile, sources: &SourceMap) -> Index {
    let mut w = Walker {
        sources,
        index: Index::default(),
        scopes: vec![HashMap::new()],
        parent: None,
    };
    // Top-level functions are visible everywhere after their definition; registering them
    // first also resolves uses written before (the compiler reports those).
    for item in &ast.items {
        if let Item::Function(f) = item {
            let id = w.function_decl(f);
            w.scopes[0].entry(f.name.clone()).or_insert(id);
        }
    }
    for item in &ast.items {
        match item {
            Item::Shader(s) => w.shader(s),
            Item::Function(f) => {
                let id = w.scopes[0][&f.name];
                w.function_body(f, id);
            }
        }
    }
    w.index
}

struct Walker<'a> {
    sources: &'a SourceMap,
    index: Index,
    scopes: Vec<HashMap<String, usize>>,
    parent: Option<usize>,
}

fn type_text(ty: &TypeSpec) -> String {
    match ty.detail {
        Some(Detail::Uniform) => format!("uniform {}", ty.base.name()),
        Some(Detail::Varying) => format!("varying {}", ty.base.name()),
        None => ty.base.name().to_string(),
    }
}

fn array_text(a: Option<ArraySpec>) -> String {
    match a {
        Some(ArraySpec::Sized(n)) => format!("[{n}]"),
        Some(ArraySpec::Unsized) => "[]".into(),
        None => String::new(),
    }
}

impl Walker<'_> {
    /// The span of `name` at the start of `span` (declarator spans start at the name).
    fn name_span(&self, span: Span, name: &str) -> Span {
        let text = self.sources.snippet(span);
        let at = if text.starts_with(name) {
            0
        } else {
            text.find(name).unwrap_or(0)
        };
        let start = span.start as usize + at;
        Span::new(
            span.file,
            start,
            (start + name.len()).min(span.end.max(span.start) as usize),
        )
    }

    fn expr_text(&self, e: &Expr) -> String {
        let t = self.sources.snippet(e.span);
        let t: String = t.split_whitespace().collect::<Vec<_>>().join(" ");
        if t.chars().count() > 60 {
            format!("{}…", t.chars().take(60).collect::<String>())
        } else {
            t
        }
    }

    /// The `//` or `/* */` comment lines right above `span` (a blank line breaks it).
    fn doc_above(&self, span: Span) -> Option<String> {
        let f = self.sources.get(span.file)?;
        let before = f.text.get(..span.start as usize)?;
        // Start of the declaration's line.
        let line_start = before.rfind('\n').map_or(0, |p| p + 1);
        let mut lines: Vec<&str> = Vec::new();
        let mut rest = &before[..line_start];
        let mut in_block = false;
        while let Some(stripped) = rest.strip_suffix('\n') {
            let start = stripped.rfind('\n').map_or(0, |p| p + 1);
            let line = stripped[start..].trim();
            rest = &stripped[..start];
            if in_block {
                let done = line.starts_with("/*");
                let l = line.trim_start_matches("/*").trim_start_matches('*').trim();
                if !l.is_empty() {
                    lines.push(l);
                }
                if done {
                    in_block = false;
                }
                continue;
            }
            if let Some(c) = line.strip_prefix("//") {
                lines.push(c.trim_start_matches('/').trim());
            } else if line.ends_with("*/") {
                let body = line.trim_end_matches("*/");
                if let Some(one) = body.trim().strip_prefix("/*") {
                    let l = one.trim_start_matches('*').trim();
                    if !l.is_empty() {
                        lines.push(l);
                    }
                } else {
                    in_block = true;
                    let l = body.trim().trim_start_matches('*').trim();
                    if !l.is_empty() {
                        lines.push(l);
                    }
                }
            } else {
                break;
            }
        }
        lines.reverse();
        let doc = lines.join("\n").trim().to_string();
        (!doc.is_empty()).then_some(doc)
    }

    fn add(&mut self, d: Decl) -> usize {
        self.index.decls.push(d);
        self.index.decls.len() - 1
    }

    fn declare(&mut self, name: &str, id: usize) {
        if let Some(s) = self.scopes.last_mut() {
            s.insert(name.to_string(), id);
        }
    }

    fn lookup(&self, name: &str) -> Option<usize> {
        self.scopes.iter().rev().find_map(|s| s.get(name).copied())
    }

    fn formal(&mut self, f: &Formal, kind: DeclKind, visible_end: u32) -> usize {
        let default = f
            .default
            .as_ref()
            .map(|e| format!(" = {}", self.expr_text(e)))
            .unwrap_or_default();
        let detail = format!(
            "{}{} {}{}{}",
            if f.output { "output " } else { "" },
            type_text(&f.ty),
            f.name,
            array_text(f.array),
            default
        );
        let span = self.name_span(f.span, &f.name);
        let id = self.add(Decl {
            name: f.name.clone(),
            kind,
            detail,
            span,
            full: f.ty.span.to(f.span),
            visible: (span.start, visible_end),
            doc: None,
            parent: self.parent,
        });
        self.declare(&f.name, id);
        id
    }

    fn signature(&self, f: &FuncDef) -> String {
        let params: Vec<String> = f
            .params
            .iter()
            .map(|p| {
                format!(
                    "{}{} {}{}",
                    if p.output { "output " } else { "" },
                    type_text(&p.ty),
                    p.name,
                    array_text(p.array)
                )
            })
            .collect();
        format!("{} {}({})", type_text(&f.ret), f.name, params.join("; "))
    }

    fn function_decl(&mut self, f: &FuncDef) -> usize {
        let detail = self.signature(f);
        let doc = self.doc_above(f.span);
        self.add(Decl {
            name: f.name.clone(),
            kind: DeclKind::Function,
            detail,
            span: f.name_span,
            full: f.span,
            visible: (f.name_span.start, u32::MAX),
            doc,
            parent: self.parent,
        })
    }

    fn function_body(&mut self, f: &FuncDef, id: usize) {
        let saved = self.parent.replace(id);
        self.scopes.push(HashMap::new());
        for p in &f.params {
            self.formal(p, DeclKind::Formal, f.span.end);
        }
        self.block(&f.body);
        self.scopes.pop();
        self.parent = saved;
    }

    fn shader(&mut self, s: &ShaderDef) {
        let params: Vec<String> = s
            .params
            .iter()
            .map(|p| format!("{} {}", type_text(&p.ty), p.name))
            .collect();
        let doc = self.doc_above(s.span);
        let id = self.add(Decl {
            name: s.name.clone(),
            kind: DeclKind::Shader,
            detail: format!("{} {}({})", s.kind.name(), s.name, params.join("; ")),
            span: s.name_span,
            full: s.span,
            visible: (s.span.start, s.span.end),
            doc,
            parent: None,
        });
        let saved = self.parent.replace(id);
        self.scopes.push(HashMap::new());
        for p in &s.params {
            self.formal(p, DeclKind::Param, s.span.end);
        }
        self.block(&s.body);
        self.scopes.pop();
        self.parent = saved;
    }

    fn block(&mut self, b: &Block) {
        self.scopes.push(HashMap::new());
        for st in &b.stmts {
            self.stmt(st, b.span.end);
        }
        self.scopes.pop();
    }

    fn stmt(&mut self, st: &Stmt, scope_end: u32) {
        match &st.kind {
            StmtKind::VarDecl {
                is_extern,
                output,
                ty,
                vars,
            } => {
                for v in vars {
                    if let Some(e) = &v.init {
                        self.expr(e);
                    }
                    // `extern` names a variable of an enclosing scope: a use, not a new one.
                    if *is_extern {
                        if let Some(id) = self.lookup(&v.name) {
                            let span = self.name_span(v.span, &v.name);
                            self.index.refs.push((span, id));
                            continue;
                        }
                    }
                    let init = v
                        .init
                        .as_ref()
                        .map(|e| format!(" = {}", self.expr_text(e)))
                        .unwrap_or_default();
                    let span = self.name_span(v.span, &v.name);
                    let id = self.add(Decl {
                        name: v.name.clone(),
                        kind: DeclKind::Local,
                        detail: format!(
                            "{}{}{} {}{}{}",
                            if *is_extern { "extern " } else { "" },
                            if *output { "output " } else { "" },
                            type_text(ty),
                            v.name,
                            array_text(v.array),
                            init
                        ),
                        span,
                        full: ty.span.to(v.span),
                        visible: (span.start, scope_end),
                        doc: None,
                        parent: self.parent,
                    });
                    self.declare(&v.name, id);
                }
            }
            StmtKind::Function(f) => {
                let id = self.function_decl(f);
                if let Some(d) = self.index.decls.get_mut(id) {
                    d.visible = (f.name_span.start, scope_end);
                }
                self.declare(&f.name, id);
                self.function_body(f, id);
            }
            StmtKind::Expr(e) => self.expr(e),
            StmtKind::Block(b) => self.block(b),
            StmtKind::If {
                cond,
                then,
                otherwise,
            } => {
                self.expr(cond);
                self.stmt(then, scope_end);
                if let Some(o) = otherwise {
                    self.stmt(o, scope_end);
                }
            }
            StmtKind::While { cond, body } => {
                self.expr(cond);
                self.stmt(body, scope_end);
            }
            StmtKind::For {
                init,
                cond,
                step,
                body,
            } => {
                for e in [init, cond, step].into_iter().flatten() {
                    self.expr(e);
                }
                self.stmt(body, scope_end);
            }
            StmtKind::Return(e) => {
                if let Some(e) = e {
                    self.expr(e);
                }
            }
            StmtKind::Illuminance { args, body }
            | StmtKind::Illuminate { args, body }
            | StmtKind::Solar { args, body } => {
                for a in args {
                    self.expr(a);
                }
                self.stmt(body, scope_end);
            }
            StmtKind::Gather {
                args,
                body,
                otherwise,
            } => {
                for a in args {
                    self.expr(a);
                }
                self.stmt(body, scope_end);
                if let Some(o) = otherwise {
                    self.stmt(o, scope_end);
                }
            }
            StmtKind::Break(_) | StmtKind::Continue(_) | StmtKind::Empty => {}
        }
    }

    fn expr(&mut self, e: &Expr) {
        match &e.kind {
            ExprKind::Float(_) | ExprKind::Str(_) => {}
            ExprKind::Ident(name) => {
                if let Some(id) = self.lookup(name) {
                    self.index.refs.push((e.span, id));
                }
            }
            ExprKind::Index { base, index } => {
                self.expr(base);
                self.expr(index);
            }
            ExprKind::Call {
                name,
                name_span,
                args,
            } => {
                if let Some(id) = self
                    .lookup(name)
                    .filter(|&id| self.index.decls[id].kind == DeclKind::Function)
                {
                    self.index.refs.push((*name_span, id));
                }
                for a in args {
                    self.expr(a);
                }
            }
            ExprKind::Tuple(items) | ExprKind::ArrayLit(items) => {
                for a in items {
                    self.expr(a);
                }
            }
            ExprKind::Cast { expr, .. } | ExprKind::Unary { expr, .. } => self.expr(expr),
            ExprKind::Binary { lhs, rhs, .. } => {
                self.expr(lhs);
                self.expr(rhs);
            }
            ExprKind::Ternary {
                cond,
                then,
                otherwise,
            } => {
                self.expr(cond);
                self.expr(then);
                self.expr(otherwise);
            }
            ExprKind::Assign { target, value, .. } => {
                self.expr(target);
                self.expr(value);
            }
        }
    }
}
