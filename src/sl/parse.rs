//! Shading-language parser: preprocessed text → [`ast::SourceFile`].
//!
//! Input: the preprocessor's output text and a function mapping its byte ranges to spans in
//! the original sources. Output: the syntax tree, or `None` after syntax errors, each reported
//! as an `sl::syntax` diagnostic ("expected …, found …" in plain words, with a help line where
//! the fix is likely: a missing `;`, unbalanced braces, a reserved word as a name). After the
//! first error the parser resynchronises at statement boundaries to report up to
//! [`MAX_SYNTAX_ERRORS`] more without cascades.
//! Invariants: never panics (nesting deeper than [`MAX_NESTING`] is refused up front so neither
//! pest nor the tree builder can exhaust the stack); operator precedence lives only in
//! [`pratt`], the grammar (`grammar/sl.pest`) keeps expressions flat.

use std::sync::OnceLock;

use pest::error::{ErrorVariant, InputLocation};
use pest::iterators::Pair;
use pest::pratt_parser::{Assoc, Op, PrattParser};
use pest::Parser as _;
use pest_derive::Parser;

use super::ast::*;
use crate::diag::{Diag, Diagnostics, Span};

#[derive(Parser)]
#[grammar = "../grammar/sl.pest"]
struct SlParser;

/// Deepest bracket nesting accepted (real shaders stay far below; the limit keeps recursion
/// in the parser and the tree builder bounded).
pub const MAX_NESTING: usize = 96;

/// Deepest recursion the tree builder may need: pair nesting plus the prefix operators and
/// right-associative links (`=`, `?:`) the Pratt parser recurses through.
pub const MAX_TREE_DEPTH: usize = 600;

/// Parses preprocessed shader text. `span` maps a byte range of `text` to a Span in the
/// original source (the preprocessor provides it). Syntax errors are reported to `diags`
/// (code "sl::syntax", label, help); returns None if nothing usable could be parsed.
pub fn parse(
    text: &str,
    span: &dyn Fn(usize, usize) -> Span,
    diags: &Diagnostics,
) -> Option<SourceFile> {
    if let Some(d) = check_depth(text, span) {
        diags.report(d);
        return None;
    }
    match SlParser::parse(Rule::file, text) {
        Ok(mut pairs) => {
            let file = pairs.next()?;
            if let Some(at) = too_deep(&file) {
                diags.report(
                    Diag::error("sl::syntax", "expression or statement is nested too deeply")
                        .label(
                            span(at, at),
                            format!("more than {MAX_TREE_DEPTH} levels deep"),
                        )
                        .help("split it into several statements"),
                );
                return None;
            }
            let b = Builder { span, diags };
            Some(b.file(file))
        }
        Err(e) => {
            report_syntax_errors(text, span, diags, e);
            None
        }
    }
}

/// Most syntax errors reported for one file.
pub const MAX_SYNTAX_ERRORS: usize = 10;

fn error_pos(err: &pest::error::Error<Rule>) -> usize {
    match err.location {
        InputLocation::Pos(p) => p,
        InputLocation::Span((s, _)) => s,
    }
}

/// Reports the first syntax error, then keeps looking for more: the statement holding the
/// error is blanked out (replaced by spaces and a `;`, so offsets and lines stay put) and the
/// text is parsed again. Recovery stops at an error outside any block, at end of file, or when
/// the next error is not past the blanked statement (a likely cascade).
fn report_syntax_errors(
    text: &str,
    span: &dyn Fn(usize, usize) -> Span,
    diags: &Diagnostics,
    first: pest::error::Error<Rule>,
) {
    let mut buf: Option<String> = None;
    let mut err = first;
    for _ in 0..MAX_SYNTAX_ERRORS {
        let cur = buf.as_deref().unwrap_or(text);
        let pos = error_pos(&err).min(cur.len());
        let custom = matches!(err.variant, ErrorVariant::CustomError { .. });
        diags.report(syntax_error(cur, span, err));
        if custom || cur[pos..].trim().is_empty() {
            break;
        }
        let Some((a, b)) = statement_around(cur, pos) else {
            break;
        };
        let repaired = blank_statement(cur, a, b);
        match SlParser::parse(Rule::file, &repaired) {
            Ok(_) => break,
            Err(next) if error_pos(&next) >= b => {
                err = next;
                buf = Some(repaired);
            }
            Err(_) => break,
        }
    }
}

/// The byte range of the statement containing `pos`, inside its innermost enclosing block:
/// from just after the previous `;` / block end to just after the next `;` at bracket depth
/// zero (or up to the block's closing `}`). `None` outside any block.
fn statement_around(text: &str, pos: usize) -> Option<(usize, usize)> {
    let mut stack = Vec::new();
    scan_braces(&text[..pos], |i, open| {
        if open {
            stack.push(i);
        } else {
            stack.pop();
        }
    });
    let open = *stack.last()?;
    let b = text.as_bytes();
    let (mut paren, mut brace) = (0i32, 0i32);
    let mut start = open + 1;
    let mut i = open + 1;
    while i < b.len() {
        let mut boundary = false;
        match b[i] {
            b'"' => {
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
            }
            b'(' | b'[' => paren += 1,
            b')' | b']' => paren -= 1,
            b'{' => brace += 1,
            b'}' => {
                if brace == 0 {
                    // The enclosing block ends: the statement runs up to here.
                    return (i > pos && !text[start..i].trim().is_empty()).then_some((start, i));
                }
                brace -= 1;
                boundary = brace == 0 && paren <= 0;
            }
            // Past the error, an unclosed `(` must not swallow the rest of the block.
            b';' => boundary = brace == 0 && (paren <= 0 || i >= pos),
            _ => {}
        }
        if boundary {
            if i >= pos {
                return Some((start, (i + 1).min(text.len())));
            }
            start = i + 1;
            paren = 0;
        }
        i += 1;
    }
    None
}

/// `text` with `a..b` replaced by spaces (newlines kept) ending in a `;`.
fn blank_statement(text: &str, a: usize, b: usize) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for c in &mut bytes[a..b] {
        if *c != b'\n' {
            *c = b' ';
        }
    }
    if let Some(last) = (a..b).rev().find(|&k| bytes[k] == b' ') {
        bytes[last] = b';';
    }
    String::from_utf8(bytes).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

/// The operator table, loosest first (RISpec 3.2 / the reference compilers' yacc grammars):
/// `.` binds tighter than `*` `/`, which bind tighter than `^`, which binds tighter than `+` `-`.
fn pratt() -> &'static PrattParser<Rule> {
    static P: OnceLock<PrattParser<Rule>> = OnceLock::new();
    P.get_or_init(|| {
        PrattParser::new()
            .op(Op::infix(Rule::assign, Assoc::Right)
                | Op::infix(Rule::assign_add, Assoc::Right)
                | Op::infix(Rule::assign_sub, Assoc::Right)
                | Op::infix(Rule::assign_mul, Assoc::Right)
                | Op::infix(Rule::assign_div, Assoc::Right))
            .op(Op::infix(Rule::ternary, Assoc::Right))
            .op(Op::infix(Rule::or, Assoc::Left))
            .op(Op::infix(Rule::and, Assoc::Left))
            .op(Op::infix(Rule::eq, Assoc::Left) | Op::infix(Rule::ne, Assoc::Left))
            .op(Op::infix(Rule::lt, Assoc::Left)
                | Op::infix(Rule::gt, Assoc::Left)
                | Op::infix(Rule::le, Assoc::Left)
                | Op::infix(Rule::ge, Assoc::Left))
            .op(Op::infix(Rule::add, Assoc::Left) | Op::infix(Rule::sub, Assoc::Left))
            .op(Op::infix(Rule::cross, Assoc::Left))
            .op(Op::infix(Rule::mul, Assoc::Left) | Op::infix(Rule::div, Assoc::Left))
            .op(Op::infix(Rule::dot, Assoc::Left))
            .op(Op::prefix(Rule::neg)
                | Op::prefix(Rule::not)
                | Op::prefix(Rule::plus)
                | Op::prefix(Rule::pre_inc)
                | Op::prefix(Rule::pre_dec)
                | Op::prefix(Rule::cast))
            .op(Op::postfix(Rule::index)
                | Op::postfix(Rule::post_inc)
                | Op::postfix(Rule::post_dec))
    })
}

/// Turns pest pairs into the AST. Semantic slips the grammar lets through (a shader parameter
/// without a default, assigning to a non-variable, `break 0`) are reported here and the tree
/// is still built.
struct Builder<'a> {
    span: &'a dyn Fn(usize, usize) -> Span,
    diags: &'a Diagnostics,
}

fn is_keyword_pair(r: Rule) -> bool {
    matches!(
        r,
        Rule::kw_if
            | Rule::kw_else
            | Rule::kw_while
            | Rule::kw_for
            | Rule::kw_break
            | Rule::kw_continue
            | Rule::kw_return
            | Rule::kw_illuminance
            | Rule::kw_illuminate
            | Rule::kw_solar
            | Rule::kw_gather
    )
}

impl<'a> Builder<'a> {
    fn sp(&self, p: &Pair<Rule>) -> Span {
        let s = p.as_span();
        (self.span)(s.start(), s.end())
    }

    fn error(&self, span: Span, message: impl Into<String>, label: &str, help: Option<&str>) {
        let mut d = Diag::error("sl::syntax", message).label(span, label);
        if let Some(h) = help {
            d = d.help(h);
        }
        self.diags.report(d);
    }

    fn file(&self, pair: Pair<Rule>) -> SourceFile {
        let mut items = Vec::new();
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::shader_def => items.push(Item::Shader(self.shader(p))),
                Rule::func_def => items.push(Item::Function(self.func(p))),
                _ => {}
            }
        }
        SourceFile { items }
    }

    fn shader(&self, pair: Pair<Rule>) -> ShaderDef {
        let span = self.sp(&pair);
        let mut it = pair.into_inner();
        let mut kind = ShaderKind::Surface;
        let mut name = String::new();
        let mut name_span = span;
        let mut params = Vec::new();
        let mut body = Block {
            stmts: vec![],
            span,
        };
        for p in it.by_ref() {
            match p.as_rule() {
                Rule::shader_kind => {
                    kind = match p.as_str() {
                        "displacement" => ShaderKind::Displacement,
                        "light" => ShaderKind::Light,
                        "volume" => ShaderKind::Volume,
                        "imager" => ShaderKind::Imager,
                        "transformation" => ShaderKind::Transformation,
                        _ => ShaderKind::Surface,
                    }
                }
                Rule::ident => {
                    name = p.as_str().to_string();
                    name_span = self.sp(&p);
                }
                Rule::formals => params = self.formals(p, true),
                Rule::block => body = self.block(p),
                _ => {}
            }
        }
        ShaderDef {
            kind,
            name,
            name_span,
            params,
            body,
            span,
        }
    }

    fn func(&self, pair: Pair<Rule>) -> FuncDef {
        let span = self.sp(&pair);
        let mut detail = None;
        let mut base = BaseType::Void;
        let mut ty_span: Option<Span> = None;
        let mut name = String::new();
        let mut name_span = span;
        let mut params = Vec::new();
        let mut body = Block {
            stmts: vec![],
            span,
        };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::detail => {
                    detail = Some(detail_of(p.as_str()));
                    ty_span = Some(self.sp(&p));
                }
                Rule::base_type | Rule::void_type => {
                    base = base_of(p.as_str());
                    let s = self.sp(&p);
                    ty_span = Some(ty_span.map_or(s, |t| t.to(s)));
                }
                Rule::ident => {
                    name = p.as_str().to_string();
                    name_span = self.sp(&p);
                }
                Rule::formals => params = self.formals(p, false),
                Rule::block => body = self.block(p),
                _ => {}
            }
        }
        FuncDef {
            ret: TypeSpec {
                detail,
                base,
                span: ty_span.unwrap_or(span),
            },
            name,
            name_span,
            params,
            body,
            span,
        }
    }

    /// Parameter groups of a shader (`shader` = defaults required) or a function (no defaults).
    fn formals(&self, pair: Pair<Rule>, shader: bool) -> Vec<Formal> {
        let mut out = Vec::new();
        for group in pair.into_inner() {
            let mut output = false;
            let mut detail = None;
            let mut ty: Option<TypeSpec> = None;
            let mut ty_start: Option<Span> = None;
            for p in group.into_inner() {
                match p.as_rule() {
                    Rule::output_kw => {
                        output = true;
                        ty_start.get_or_insert(self.sp(&p));
                    }
                    Rule::detail => {
                        detail = self.set_detail(detail, &p);
                        ty_start.get_or_insert(self.sp(&p));
                    }
                    Rule::base_type => {
                        let s = self.sp(&p);
                        ty = Some(TypeSpec {
                            detail,
                            base: base_of(p.as_str()),
                            span: ty_start.map_or(s, |t| t.to(s)),
                        });
                    }
                    Rule::formal_name => {
                        let Some(ty) = ty.clone() else { continue };
                        let span = self.sp(&p);
                        let (name, name_span, array, default) = self.declarator(p);
                        // PRMan takes an output parameter without a default (it starts at
                        // zero: RSL 2.0 era shaders declare AOVs so).
                        if shader && default.is_none() && !output {
                            self.error(
                                name_span,
                                format!("shader parameter `{name}` has no default value"),
                                "needs a default",
                                Some(
                                    "every shader parameter needs a default: write `name = value`",
                                ),
                            );
                        }
                        if !shader {
                            if let Some(d) = &default {
                                self.error(
                                    d.span,
                                    format!(
                                        "function parameter `{name}` cannot have a default value"
                                    ),
                                    "not allowed here",
                                    Some("only shader parameters take defaults; remove `= …`"),
                                );
                            }
                        }
                        out.push(Formal {
                            output,
                            ty,
                            name,
                            array,
                            default,
                            span,
                        });
                    }
                    _ => {}
                }
            }
        }
        out
    }

    fn set_detail(&self, old: Option<Detail>, p: &Pair<Rule>) -> Option<Detail> {
        let d = detail_of(p.as_str());
        if old.is_some_and(|o| o != d) {
            self.error(
                self.sp(p),
                "a declaration cannot be both `uniform` and `varying`",
                "conflicting storage class",
                Some("keep only one of `uniform` and `varying`"),
            );
        }
        Some(d)
    }

    /// `name [array] [= init]` of a formal or a variable.
    fn declarator(&self, pair: Pair<Rule>) -> (String, Span, Option<ArraySpec>, Option<Expr>) {
        let mut name = String::new();
        let mut name_span = self.sp(&pair);
        let mut array = None;
        let mut init = None;
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => {
                    name = p.as_str().to_string();
                    name_span = self.sp(&p);
                }
                Rule::array_spec => array = Some(self.array_spec(p)),
                Rule::expr => init = Some(self.expr(p)),
                _ => {}
            }
        }
        (name, name_span, array, init)
    }

    fn array_spec(&self, pair: Pair<Rule>) -> ArraySpec {
        match pair.into_inner().next() {
            None => ArraySpec::Unsized,
            Some(n) => match n.as_str().parse::<usize>() {
                Ok(v) if v <= u32::MAX as usize => ArraySpec::Sized(v),
                _ => {
                    self.error(self.sp(&n), "array size is too large", "too large", None);
                    ArraySpec::Sized(0)
                }
            },
        }
    }

    fn block(&self, pair: Pair<Rule>) -> Block {
        let span = self.sp(&pair);
        let stmts = pair.into_inner().map(|p| self.stmt(p)).collect();
        Block { stmts, span }
    }

    /// The statements among a pair's children (keywords and argument lists skipped).
    fn sub_stmts<'i>(
        &self,
        pairs: impl Iterator<Item = Pair<'i, Rule>>,
    ) -> impl Iterator<Item = Box<Stmt>> {
        pairs
            .filter(|p| {
                !is_keyword_pair(p.as_rule()) && !matches!(p.as_rule(), Rule::expr | Rule::args)
            })
            .map(|p| Box::new(self.stmt(p)))
            .collect::<Vec<_>>()
            .into_iter()
    }

    fn stmt(&self, pair: Pair<Rule>) -> Stmt {
        let span = self.sp(&pair);
        let rule = pair.as_rule();
        let kind = match rule {
            Rule::block => StmtKind::Block(self.block(pair)),
            Rule::empty_stmt => StmtKind::Empty,
            Rule::expr_stmt => match pair.into_inner().next() {
                Some(e) => StmtKind::Expr(self.expr(e)),
                None => StmtKind::Empty,
            },
            Rule::func_def => StmtKind::Function(self.func(pair)),
            Rule::var_decl => self.var_decl(pair),
            Rule::if_stmt | Rule::while_stmt => {
                let cond = pair
                    .clone()
                    .into_inner()
                    .find(|p| p.as_rule() == Rule::expr)
                    .map(|e| self.expr(e))
                    .unwrap_or_else(|| float_expr(0.0, span));
                let mut subs = self.sub_stmts(pair.into_inner());
                let then = subs.next().unwrap_or_else(|| empty_stmt(span));
                if rule == Rule::if_stmt {
                    StmtKind::If {
                        cond,
                        then,
                        otherwise: subs.next(),
                    }
                } else {
                    StmtKind::While { cond, body: then }
                }
            }
            Rule::for_stmt => {
                let mut parts = Vec::with_capacity(3);
                let mut decl = None;
                let mut body = None;
                for p in pair.into_inner() {
                    match p.as_rule() {
                        Rule::for_part => parts.push(p.into_inner().next().map(|e| self.expr(e))),
                        Rule::for_decl => {
                            let decl_span = self.sp(&p);
                            parts.push(None);
                            decl = Some(Stmt {
                                kind: self.var_decl(p),
                                span: decl_span,
                            });
                        }
                        Rule::kw_for => {}
                        _ => body = Some(Box::new(self.stmt(p))),
                    }
                }
                let mut parts = parts.into_iter();
                let kind = StmtKind::For {
                    init: parts.next().flatten(),
                    cond: parts.next().flatten(),
                    step: parts.next().flatten(),
                    body: body.unwrap_or_else(|| empty_stmt(span)),
                };
                match decl {
                    None => kind,
                    // `for (float i = 0; …) body` is `{ float i = 0; for (; …) body }`: the
                    // block scopes the declared names to the loop, shadowing any outer ones.
                    Some(decl) => StmtKind::Block(Block {
                        stmts: vec![decl, Stmt { kind, span }],
                        span,
                    }),
                }
            }
            Rule::break_stmt | Rule::continue_stmt => {
                let level = match pair.into_inner().find(|p| p.as_rule() == Rule::int_lit) {
                    None => 1,
                    Some(n) => match n.as_str().parse::<u32>() {
                        Ok(v) if v >= 1 => v,
                        _ => {
                            self.error(
                                self.sp(&n),
                                "a loop level must be a whole number of at least 1",
                                "invalid level",
                                Some("`break 1` leaves the innermost loop, `break 2` the one around it"),
                            );
                            1
                        }
                    },
                };
                if rule == Rule::break_stmt {
                    StmtKind::Break(level)
                } else {
                    StmtKind::Continue(level)
                }
            }
            Rule::return_stmt => StmtKind::Return(
                pair.into_inner()
                    .find(|p| p.as_rule() == Rule::expr)
                    .map(|e| self.expr(e)),
            ),
            Rule::illuminance_stmt
            | Rule::illuminate_stmt
            | Rule::solar_stmt
            | Rule::gather_stmt => {
                let args = pair
                    .clone()
                    .into_inner()
                    .find(|p| p.as_rule() == Rule::args)
                    .map(|a| self.args(a))
                    .unwrap_or_default();
                let mut subs = self.sub_stmts(pair.into_inner());
                let body = subs.next().unwrap_or_else(|| empty_stmt(span));
                match rule {
                    Rule::illuminance_stmt => StmtKind::Illuminance { args, body },
                    Rule::illuminate_stmt => StmtKind::Illuminate { args, body },
                    Rule::solar_stmt => StmtKind::Solar { args, body },
                    _ => StmtKind::Gather {
                        args,
                        body,
                        otherwise: subs.next(),
                    },
                }
            }
            _ => StmtKind::Empty,
        };
        Stmt { kind, span }
    }

    fn var_decl(&self, pair: Pair<Rule>) -> StmtKind {
        let mut is_extern = false;
        let mut output = false;
        let mut detail = None;
        let mut ty_start: Option<Span> = None;
        let mut ty = None;
        let mut vars = Vec::new();
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::extern_kw => {
                    is_extern = true;
                    ty_start.get_or_insert(self.sp(&p));
                }
                Rule::output_kw => {
                    output = true;
                    ty_start.get_or_insert(self.sp(&p));
                }
                Rule::detail => {
                    detail = self.set_detail(detail, &p);
                    ty_start.get_or_insert(self.sp(&p));
                }
                Rule::base_type => {
                    let s = self.sp(&p);
                    ty = Some(TypeSpec {
                        detail,
                        base: base_of(p.as_str()),
                        span: ty_start.map_or(s, |t| t.to(s)),
                    });
                }
                Rule::var_init => {
                    let span = self.sp(&p);
                    let (name, _, array, init) = self.declarator(p);
                    vars.push(VarInit {
                        name,
                        array,
                        init,
                        span,
                    });
                }
                _ => {}
            }
        }
        StmtKind::VarDecl {
            is_extern,
            output,
            ty: ty.unwrap_or(TypeSpec {
                detail,
                base: BaseType::Float,
                span: ty_start.unwrap_or_default(),
            }),
            vars,
        }
    }

    fn args(&self, pair: Pair<Rule>) -> Vec<Expr> {
        pair.into_inner()
            .filter(|p| p.as_rule() == Rule::expr)
            .map(|p| self.expr(p))
            .collect()
    }

    // ------------------------------------------------------------ expressions

    fn expr(&self, pair: Pair<Rule>) -> Expr {
        pratt()
            .map_primary(|p| self.primary(p))
            .map_prefix(|op, rhs| self.prefix(op, rhs))
            .map_postfix(|lhs, op| self.postfix(lhs, op))
            .map_infix(|lhs, op, rhs| self.infix(lhs, op, rhs))
            .parse(pair.into_inner())
    }

    fn primary(&self, pair: Pair<Rule>) -> Expr {
        let span = self.sp(&pair);
        let kind = match pair.as_rule() {
            Rule::number => ExprKind::Float(parse_number(pair.as_str())),
            Rule::strings => ExprKind::Str(strings_value(pair)),
            Rule::ident => ExprKind::Ident(pair.as_str().to_string()),
            Rule::call => {
                let mut name = String::new();
                let mut name_span = span;
                let mut args = Vec::new();
                for p in pair.into_inner() {
                    match p.as_rule() {
                        Rule::call_name => {
                            name = p.as_str().to_string();
                            name_span = self.sp(&p);
                        }
                        Rule::args => args = self.args(p),
                        _ => {}
                    }
                }
                ExprKind::Call {
                    name,
                    name_span,
                    args,
                }
            }
            Rule::paren => {
                let mut items: Vec<Expr> = pair.into_inner().map(|p| self.expr(p)).collect();
                if items.len() == 1 {
                    // A parenthesised expression keeps its inner node (and span).
                    return items.pop().unwrap_or_else(|| float_expr(0.0, span));
                }
                ExprKind::Tuple(items)
            }
            Rule::array_lit => {
                ExprKind::ArrayLit(pair.into_inner().map(|p| self.expr(p)).collect())
            }
            _ => ExprKind::Float(0.0),
        };
        Expr { kind, span }
    }

    fn prefix(&self, op: Pair<Rule>, rhs: Expr) -> Expr {
        let op_span = self.sp(&op);
        let span = op_span.to(rhs.span);
        let kind = match op.as_rule() {
            // `-1` is a literal, not an operation (shader defaults stay constants).
            Rule::neg => match rhs.kind {
                ExprKind::Float(v) => ExprKind::Float(-v),
                _ => unary(UnOp::Neg, rhs),
            },
            Rule::not => unary(UnOp::Not, rhs),
            Rule::plus => unary(UnOp::Plus, rhs),
            Rule::pre_inc | Rule::pre_dec => {
                let aop = if op.as_rule() == Rule::pre_inc {
                    AssignOp::Add
                } else {
                    AssignOp::Sub
                };
                self.check_target(&rhs, op_span);
                ExprKind::Assign {
                    op: aop,
                    target: Box::new(rhs),
                    value: Box::new(float_expr(1.0, op_span)),
                }
            }
            Rule::cast => {
                let mut ty = BaseType::Float;
                let mut space = None;
                for p in op.into_inner() {
                    match p.as_rule() {
                        Rule::base_type => ty = base_of(p.as_str()),
                        Rule::strings => space = Some(strings_value(p)),
                        _ => {}
                    }
                }
                ExprKind::Cast {
                    ty,
                    space,
                    expr: Box::new(rhs),
                }
            }
            _ => return rhs,
        };
        Expr { kind, span }
    }

    fn postfix(&self, lhs: Expr, op: Pair<Rule>) -> Expr {
        let op_span = self.sp(&op);
        let span = lhs.span.to(op_span);
        let kind = match op.as_rule() {
            Rule::index => {
                let index = op
                    .into_inner()
                    .next()
                    .map(|e| self.expr(e))
                    .unwrap_or_else(|| float_expr(0.0, op_span));
                ExprKind::Index {
                    base: Box::new(lhs),
                    index: Box::new(index),
                }
            }
            Rule::post_inc | Rule::post_dec => {
                let aop = if op.as_rule() == Rule::post_inc {
                    AssignOp::Add
                } else {
                    AssignOp::Sub
                };
                self.check_target(&lhs, op_span);
                ExprKind::Assign {
                    op: aop,
                    target: Box::new(lhs),
                    value: Box::new(float_expr(1.0, op_span)),
                }
            }
            _ => return lhs,
        };
        Expr { kind, span }
    }

    fn infix(&self, lhs: Expr, op: Pair<Rule>, rhs: Expr) -> Expr {
        let span = lhs.span.to(rhs.span);
        let bin = match op.as_rule() {
            Rule::add => Some(BinOp::Add),
            Rule::sub => Some(BinOp::Sub),
            Rule::mul => Some(BinOp::Mul),
            Rule::div => Some(BinOp::Div),
            Rule::dot => Some(BinOp::Dot),
            Rule::cross => Some(BinOp::Cross),
            Rule::eq => Some(BinOp::Eq),
            Rule::ne => Some(BinOp::Ne),
            Rule::lt => Some(BinOp::Lt),
            Rule::le => Some(BinOp::Le),
            Rule::gt => Some(BinOp::Gt),
            Rule::ge => Some(BinOp::Ge),
            Rule::and => Some(BinOp::And),
            Rule::or => Some(BinOp::Or),
            _ => None,
        };
        let kind = if let Some(op) = bin {
            ExprKind::Binary {
                op,
                lhs: Box::new(lhs),
                rhs: Box::new(rhs),
            }
        } else if op.as_rule() == Rule::ternary {
            let then = op
                .into_inner()
                .next()
                .map(|e| self.expr(e))
                .unwrap_or_else(|| float_expr(0.0, span));
            ExprKind::Ternary {
                cond: Box::new(lhs),
                then: Box::new(then),
                otherwise: Box::new(rhs),
            }
        } else {
            let aop = match op.as_rule() {
                Rule::assign_add => AssignOp::Add,
                Rule::assign_sub => AssignOp::Sub,
                Rule::assign_mul => AssignOp::Mul,
                Rule::assign_div => AssignOp::Div,
                _ => AssignOp::Set,
            };
            self.check_target(&lhs, self.sp(&op));
            ExprKind::Assign {
                op: aop,
                target: Box::new(lhs),
                value: Box::new(rhs),
            }
        };
        Expr { kind, span }
    }

    /// Only variables and array elements can be assigned.
    fn check_target(&self, target: &Expr, op_span: Span) {
        let ok = match &target.kind {
            ExprKind::Ident(_) => true,
            ExprKind::Index { base, .. } => matches!(base.kind, ExprKind::Ident(_)),
            _ => false,
        };
        if !ok {
            let d = Diag::error(
                "sl::syntax",
                "only a variable or an array element can be assigned",
            )
            .label(target.span, "not a variable")
            .label(op_span, "assignment here")
            .help("assign to a variable, e.g. `x = …` or `a[i] = …`");
            self.diags.report(d);
        }
    }
}

fn unary(op: UnOp, e: Expr) -> ExprKind {
    ExprKind::Unary {
        op,
        expr: Box::new(e),
    }
}

fn float_expr(v: f32, span: Span) -> Expr {
    Expr {
        kind: ExprKind::Float(v),
        span,
    }
}

fn empty_stmt(span: Span) -> Box<Stmt> {
    Box::new(Stmt {
        kind: StmtKind::Empty,
        span,
    })
}

fn detail_of(s: &str) -> Detail {
    if s == "varying" {
        Detail::Varying
    } else {
        Detail::Uniform
    }
}

fn base_of(s: &str) -> BaseType {
    match s {
        "float" => BaseType::Float,
        "string" => BaseType::String,
        "color" => BaseType::Color,
        "point" => BaseType::Point,
        "vector" => BaseType::Vector,
        "normal" => BaseType::Normal,
        "matrix" => BaseType::Matrix,
        _ => BaseType::Void,
    }
}

/// A float literal's value (`1.5f` suffix dropped; the grammar guarantees the shape).
fn parse_number(s: &str) -> f32 {
    let s = s.trim_end_matches(['f', 'F']);
    s.parse::<f32>().unwrap_or(0.0)
}

/// The concatenated value of adjacent string literals.
fn strings_value(pair: Pair<Rule>) -> String {
    let mut out = String::new();
    for lit in pair.into_inner() {
        for inner in lit.into_inner() {
            unescape_into(inner.as_str(), &mut out);
        }
    }
    out
}

/// C escapes: `\n \t \r \a \b \f \v \\ \" \' \?`, octal `\ooo`, hex `\xhh`; an unknown
/// escape keeps its character.
fn unescape_into(s: &str, out: &mut String) {
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '\\' {
            out.push(c);
            continue;
        }
        let Some(e) = chars.next() else {
            out.push('\\');
            break;
        };
        match e {
            'n' => out.push('\n'),
            't' => out.push('\t'),
            'r' => out.push('\r'),
            'a' => out.push('\x07'),
            'b' => out.push('\x08'),
            'f' => out.push('\x0C'),
            'v' => out.push('\x0B'),
            '0'..='7' => {
                let mut v = e as u32 - '0' as u32;
                for _ in 0..2 {
                    match chars.peek() {
                        Some(&d @ '0'..='7') => {
                            v = v * 8 + (d as u32 - '0' as u32);
                            chars.next();
                        }
                        _ => break,
                    }
                }
                out.push(char::from_u32(v).unwrap_or('?'));
            }
            'x' => {
                let mut v = 0u32;
                let mut n = 0;
                while let Some(d) = chars.peek().and_then(|c| c.to_digit(16)) {
                    if n == 2 {
                        break;
                    }
                    v = v * 16 + d;
                    n += 1;
                    chars.next();
                }
                if n == 0 {
                    out.push('x');
                } else {
                    out.push(char::from_u32(v).unwrap_or('?'));
                }
            }
            other => out.push(other),
        }
    }
}

// ---------------------------------------------------------------- errors

/// Where the tree builder's recursion would exceed [`MAX_TREE_DEPTH`], found by one
/// iterative walk over the pair tokens.
fn too_deep(file: &Pair<Rule>) -> Option<usize> {
    use pest::Token;
    // Per open pair: the recursion links its operator children add.
    let mut stack: Vec<usize> = Vec::new();
    let mut links = 0usize;
    for tok in file.clone().tokens() {
        match tok {
            Token::Start { rule, pos } => {
                let recursive_op = matches!(
                    rule,
                    Rule::neg
                        | Rule::not
                        | Rule::plus
                        | Rule::pre_inc
                        | Rule::pre_dec
                        | Rule::cast
                        | Rule::assign
                        | Rule::assign_add
                        | Rule::assign_sub
                        | Rule::assign_mul
                        | Rule::assign_div
                        | Rule::ternary
                );
                if recursive_op {
                    if let Some(top) = stack.last_mut() {
                        *top += 1;
                        links += 1;
                    }
                }
                stack.push(0);
                if stack.len() + links > MAX_TREE_DEPTH {
                    return Some(pos.pos());
                }
            }
            Token::End { .. } => {
                if let Some(n) = stack.pop() {
                    links -= n;
                }
            }
        }
    }
    None
}

/// Refuses input nested too deeply for the recursive parser and tree builder.
fn check_depth(text: &str, span: &dyn Fn(usize, usize) -> Span) -> Option<Diag> {
    let b = text.as_bytes();
    let mut depth = 0usize;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        match c {
            b'"' => {
                // Skip string contents (brackets inside strings do not nest).
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
            }
            // Comments (banners of `====` or `----`) do not count either.
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                    i += 1;
                }
                i += 2;
                continue;
            }
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Some(
                        Diag::error("sl::syntax", "brackets are nested too deeply")
                            .label(
                                span(i, i + 1),
                                format!("more than {MAX_NESTING} levels deep"),
                            )
                            .help("split the expression into several statements"),
                    );
                }
            }
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
        i += 1;
    }
    None
}

/// Converts a pest error into one diagnostic in plain words.
fn syntax_error(
    text: &str,
    span: &dyn Fn(usize, usize) -> Span,
    err: pest::error::Error<Rule>,
) -> Diag {
    let mut pos = match err.location {
        InputLocation::Pos(p) => p,
        InputLocation::Span((s, _)) => s,
    }
    .min(text.len());
    let mut positives = match &err.variant {
        ErrorVariant::ParsingError { positives, .. } => positives.clone(),
        ErrorVariant::CustomError { message } => {
            return Diag::error("sl::syntax", format!("cannot parse shader: {message}"))
                .label(span(pos, pos), "here")
                .help("simplify or split the expression");
        }
    };
    // The literal tokens pest tried at the failure point, collected on a second, detailed run
    // (detail collection is slow, so the successful path never pays for it). The detailed run
    // may locate the failure further on (inside a rule pest reports as a whole).
    let (tokens, detail_pos) = detailed_tokens(text);
    // Trust the detailed position only when it moved past a whole token (attempts inside
    // the reserved-word lookahead of a name land mid-word and mean nothing to the user).
    if let Some(dp) = detail_pos.filter(|&dp| {
        dp > pos
            && dp <= text.len()
            && text.is_char_boundary(dp)
            && !text[pos..dp]
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
    }) {
        let skipped = text[dp..].len() - text[dp..].trim_start().len();
        pos = dp + skipped;
        positives.clear();
    }
    let mut expected = Expected::default();
    for r in &positives {
        expected.rule(*r);
    }
    for t in &tokens {
        expected.token(t);
    }
    let found_end = token_end(text, pos);
    let found = describe_found(text, pos, found_end);
    let at_eof = found == "end of file";
    let found_word = &text[pos..found_end];
    // Where the previous token ends: a missing `;` belongs there, not on the next line.
    let prev_end = text[..pos].trim_end().len();
    let newline_between = text[prev_end..pos].contains('\n');
    let (prev_start, prev_word) = word_before(text, prev_end);
    let (_, prev_prev_word) = word_before(text, text[..prev_start].trim_end().len());
    let (opens, closes) = count_braces(text);

    let list = expected.words();
    let mut message = if list.is_empty() {
        format!("unexpected {found}")
    } else {
        format!("expected {list}, found {found}")
    };
    let mut label_span = span(pos, found_end.max(pos));
    let mut label = if list.is_empty() {
        "unexpected here".to_string()
    } else {
        format!("expected {list}")
    };
    let mut extra: Option<(Span, String)> = None;
    let mut help: Option<String> = None;

    if let Some(q) = unterminated_string(text).filter(|&q| q < pos) {
        message = "unterminated string literal".to_string();
        let line_end = text[q..].find('\n').map_or(text.len(), |n| q + n);
        label_span = span(q, line_end);
        label = "this string has no closing `\"`".to_string();
        help = Some("close the string with `\"` on the same line".to_string());
    } else if found_word == "}" && closes > opens {
        message = "unmatched `}`".to_string();
        label = "this `}` closes no block".to_string();
        help = Some(brace_help(opens, closes));
    } else if found_word == "else" {
        help = Some("an `else` must directly follow the statement of an `if`".to_string());
    } else if at_eof && opens > closes {
        message = "unexpected end of file: a block is not closed".to_string();
        let last = text[..prev_end]
            .chars()
            .next_back()
            .map_or(0, char::len_utf8);
        let end_span = span(prev_end - last, prev_end);
        if let Some(open) = last_unclosed_brace(text) {
            label_span = span(open, open + 1);
            label = "this `{` is never closed".to_string();
            extra = Some((end_span, "the file ends here".to_string()));
        } else {
            label_span = end_span;
            label = "expected `}` after this".to_string();
        }
        help = Some(brace_help(opens, closes));
    } else if is_reserved(prev_word)
        && (is_type_word(prev_prev_word)
            || matches!(prev_prev_word, "uniform" | "varying" | "output" | "extern"))
        && !is_type_word(prev_word)
        || (is_type_word(prev_word) && is_type_word(prev_prev_word))
    {
        // `float color = 1;` parses up to the `=` as a cast; the real problem is the name.
        message = format!("expected a name, found `{prev_word}`");
        label_span = span(prev_start, prev_end);
        label = "reserved word used as a name".to_string();
        help = Some(format!(
            "`{prev_word}` is a reserved word of the shading language and cannot be used as a name"
        ));
    } else if is_type_word(found_word) && text[..prev_end].ends_with(',') {
        help = Some(
            "declarations of different types are separated by `;`, not `,` (e.g. `float a = 1; color c = 0`)"
                .to_string(),
        );
    } else if expected.has(";")
        && newline_between
        && prev_end > 0
        && !text[..prev_end].ends_with(['}', '{', ';'])
    {
        label_span = span(prev_end, prev_end);
        label = "expected `;` here".to_string();
        help = Some("add `;` at the end of this line".to_string());
    } else if expected.wants_name && is_reserved(found_word) {
        help = Some(format!(
            "`{found_word}` is a reserved word of the shading language and cannot be used as a name"
        ));
    } else if opens != closes {
        help = Some(brace_help(opens, closes));
    }

    let mut d = Diag::error("sl::syntax", message).label(label_span, label);
    if let Some((s, l)) = extra {
        d = d.label(s, l);
    }
    if let Some(h) = help {
        d = d.help(h);
    }
    d
}

fn brace_help(opens: usize, closes: usize) -> String {
    if opens > closes {
        let n = opens - closes;
        format!(
            "the braces are unbalanced: {n} `{{` {} no matching `}}`",
            if n == 1 { "has" } else { "have" }
        )
    } else {
        let n = closes - opens;
        format!(
            "the braces are unbalanced: {n} `}}` {} no matching `{{`",
            if n == 1 { "has" } else { "have" }
        )
    }
}

/// The identifier-like word ending at `end` (start and text; empty if none).
fn word_before(text: &str, end: usize) -> (usize, &str) {
    let head = &text[..end];
    // Step past the whole separator character: it may be several bytes long.
    let start = head
        .char_indices()
        .rev()
        .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_'))
        .map_or(0, |(i, c)| i + c.len_utf8());
    (start, &head[start..])
}

/// Literal tokens expected where a detailed re-parse fails, and that position.
fn detailed_tokens(text: &str) -> (Vec<String>, Option<usize>) {
    pest::set_error_detail(true);
    let res = SlParser::parse(Rule::file, text);
    pest::set_error_detail(false);
    let Err(e) = res else { return (vec![], None) };
    let Some(att) = e.parse_attempts() else {
        return (vec![], None);
    };
    let toks = att
        .expected_tokens()
        .into_iter()
        .map(|t| t.to_string())
        .collect();
    (toks, Some(att.max_position))
}

/// What the parser was looking for, in the order it is worth telling the user.
#[derive(Default)]
struct Expected {
    punct: Vec<&'static str>,
    structural: Vec<&'static str>,
    words: Vec<&'static str>,
    operand: bool,
    operator: bool,
    statement: bool,
    wants_name: bool,
}

fn push(v: &mut Vec<&'static str>, w: &'static str) {
    if !v.contains(&w) {
        v.push(w);
    }
}

impl Expected {
    fn has(&self, w: &str) -> bool {
        self.punct.iter().any(|i| i.trim_matches('`') == w)
    }
    fn token(&mut self, t: &str) {
        match t {
            ";" => push(&mut self.punct, "`;`"),
            ")" => push(&mut self.punct, "`)`"),
            "]" => push(&mut self.punct, "`]`"),
            "}" => push(&mut self.punct, "`}`"),
            "," => push(&mut self.punct, "`,`"),
            ":" => push(&mut self.punct, "`:`"),
            "else" => push(&mut self.punct, "`else`"),
            // Only meaningful where no operand or operator could stand instead.
            "(" => push(&mut self.structural, "`(`"),
            "{" => push(&mut self.structural, "`{`"),
            "[" => push(&mut self.structural, "`[`"),
            "=" => push(&mut self.structural, "`=`"),
            "a..z" | "A..Z" | "_" => {
                self.wants_name = true;
                push(&mut self.structural, "a name")
            }
            _ => {}
        }
    }
    fn rule(&mut self, r: Rule) {
        use Rule::*;
        match r {
            number | strings | string_lit | call | paren | array_lit | neg | not | plus
            | pre_inc | pre_dec | cast | expr | for_part | args => self.operand = true,
            for_decl => push(&mut self.words, "a type"),
            ident | call_name | var_init | formal_name => {
                self.wants_name = true;
                push(&mut self.words, "a name");
            }
            assign | assign_add | assign_sub | assign_mul | assign_div | ternary | or | and
            | eq | ne | lt | le | gt | ge | add | sub | mul | div | cross | dot | index
            | post_inc | post_dec => self.operator = true,
            base_type | detail | output_kw | extern_kw | void_type | formal_group => {
                push(&mut self.words, "a type")
            }
            block => push(&mut self.words, "`{`"),
            array_spec => push(&mut self.words, "`[`"),
            int_lit => push(&mut self.words, "a whole number"),
            if_stmt | while_stmt | for_stmt | break_stmt | continue_stmt | return_stmt
            | illuminance_stmt | illuminate_stmt | solar_stmt | gather_stmt | var_decl
            | empty_stmt | expr_stmt | func_def | kw_if | kw_while | kw_for | kw_break
            | kw_continue | kw_return | kw_illuminance | kw_illuminate | kw_solar | kw_gather => {
                self.statement = true
            }
            shader_kind | shader_def | file => {
                push(&mut self.words, "a shader or function definition")
            }
            EOI => push(&mut self.words, "end of file"),
            kw_else => push(&mut self.punct, "`else`"),
            _ => {}
        }
    }
    /// `a`, `a or b`, `a, b or c` (at most six entries).
    fn words(&self) -> String {
        let mut items: Vec<&str> = self.punct.clone();
        if self.statement {
            items.retain(|w| *w != "`}`");
            items.push("a statement");
            items.push("`}`");
        } else if self.operand {
            items.push("an expression");
        }
        for w in &self.words {
            let subsumed =
                (self.statement || self.operand) && matches!(*w, "a name" | "a type" | "`{`");
            if !subsumed && !items.contains(w) {
                items.push(w);
            }
        }
        if !(self.operand || self.operator || self.statement) || self.words.is_empty() {
            for w in &self.structural {
                let skip = (self.operator && matches!(*w, "`[`" | "`=`" | "`(`" | "a name"))
                    || (self.operand && matches!(*w, "`(`" | "`{`" | "a name"))
                    || (self.statement && matches!(*w, "`{`" | "a name"));
                if !skip && !items.contains(w) {
                    items.push(w);
                }
            }
        }
        if self.operator {
            items.push("an operator");
        }
        if items.contains(&"a shader or function definition") {
            items.retain(|w| *w != "`;`");
        }
        items.truncate(6);
        match items.len() {
            0 => String::new(),
            1 => items[0].to_string(),
            n => format!("{} or {}", items[..n - 1].join(", "), items[n - 1]),
        }
    }
}

fn is_type_word(w: &str) -> bool {
    matches!(
        w,
        "float" | "string" | "color" | "point" | "vector" | "normal" | "matrix"
    )
}

fn is_reserved(w: &str) -> bool {
    is_type_word(w)
        || matches!(
            w,
            "void"
                | "uniform"
                | "varying"
                | "output"
                | "extern"
                | "if"
                | "else"
                | "while"
                | "for"
                | "break"
                | "continue"
                | "return"
                | "illuminance"
                | "illuminate"
                | "solar"
                | "gather"
        )
}

/// End of the token starting at `pos` (a word, a number, a string, or one character).
fn token_end(text: &str, pos: usize) -> usize {
    let rest = &text[pos..];
    let mut chars = rest.char_indices();
    let Some((_, c)) = chars.next() else {
        return pos;
    };
    if c.is_ascii_alphanumeric() || c == '_' {
        let num = c.is_ascii_digit();
        let n = rest
            .find(|ch: char| !(ch.is_ascii_alphanumeric() || ch == '_' || (num && ch == '.')))
            .unwrap_or(rest.len());
        return pos + n;
    }
    if c == '"' {
        let n = rest[1..]
            .find(['"', '\n'])
            .map(|i| i + 2)
            .unwrap_or(rest.len());
        return pos + n.min(rest.len());
    }
    pos + c.len_utf8()
}

fn describe_found(text: &str, pos: usize, end: usize) -> String {
    if pos >= text.len() || text[pos..].trim().is_empty() {
        return "end of file".to_string();
    }
    let tok = &text[pos..end];
    let tok: String = tok.chars().take(24).collect();
    format!("`{tok}`")
}

/// Position of the first `"` whose string reaches the end of its line (comments skipped).
fn unterminated_string(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'"' => {
                let q = i;
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
                if i >= b.len() || b[i] == b'\n' {
                    return Some(q);
                }
            }
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                    i += 1;
                }
                i += 1;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// Position of the innermost `{` left open at the end of the text.
fn last_unclosed_brace(text: &str) -> Option<usize> {
    let mut stack = Vec::new();
    scan_braces(text, |i, open| {
        if open {
            stack.push(i);
        } else {
            stack.pop();
        }
    });
    stack.last().copied()
}

/// `{` and `}` outside strings and comments.
fn count_braces(text: &str) -> (usize, usize) {
    let (mut open, mut close) = (0, 0);
    scan_braces(text, |_, o| if o { open += 1 } else { close += 1 });
    (open, close)
}

/// Calls `f(position, is_open)` for every brace outside strings and comments.
fn scan_braces(text: &str, mut f: impl FnMut(usize, bool)) {
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'"' => {
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
            }
            b'/' if b.get(i + 1) == Some(&b'/') => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                    i += 1;
                }
                i += 1;
            }
            b'{' => f(i, true),
            b'}' => f(i, false),
            _ => {}
        }
        i += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sp(s: usize, e: usize) -> Span {
        Span::new(0, s, e)
    }

    #[test]
    fn escapes_follow_c() {
        let mut out = String::new();
        unescape_into(r#"a\tb\n\"\\\101\x42\q"#, &mut out);
        assert_eq!(out, "a\tb\n\"\\ABq");
    }

    #[test]
    fn numbers_accept_suffixes_and_exponents() {
        assert_eq!(parse_number("1.5"), 1.5);
        assert_eq!(parse_number(".25"), 0.25);
        assert_eq!(parse_number("2."), 2.0);
        assert_eq!(parse_number("1e-3"), 0.001);
        assert_eq!(parse_number("3.0f"), 3.0);
    }

    #[test]
    fn depth_check_ignores_strings_and_comments() {
        let deep = "(".repeat(MAX_NESTING + 1);
        assert!(check_depth(&deep, &sp).is_some());
        assert!(check_depth(&format!("\"{deep}\""), &sp).is_none());
        assert!(check_depth(&format!("/* {deep} */"), &sp).is_none());
        assert!(check_depth(&format!("// {deep}\n"), &sp).is_none());
        assert!(check_depth("a == b; c <= d; e != f", &sp).is_none());
    }

    #[test]
    fn expected_lists_read_as_words() {
        let mut e = Expected::default();
        e.token(";");
        e.rule(Rule::add);
        e.rule(Rule::ident);
        e.rule(Rule::number);
        assert_eq!(e.words(), "`;`, an expression or an operator");
        let mut e = Expected::default();
        e.rule(Rule::ident);
        assert_eq!(e.words(), "a name");
        assert!(e.wants_name);
    }

    #[test]
    fn braces_outside_strings_are_counted() {
        assert_eq!(count_braces("{ \"}\" { } // }\n"), (2, 1));
        assert_eq!(last_unclosed_brace("{ { } "), Some(0));
        assert_eq!(last_unclosed_brace("{ }"), None);
    }
}
