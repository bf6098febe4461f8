//! Conditional RIB: `IfBegin`/`ElseIf`/`Else`/`IfEnd` and their expression language.
//!
//! Input: the condition strings, e.g. `"$Frame == 3 && $user:pass =~ 'shadow.*'"`.
//! Output: whether each branch's requests run.
//! Invariants: exactly one branch of a level runs (or none); an expression that cannot be
//! evaluated warns and counts as false; inside a skipped branch nothing is evaluated.
//!
//! Grammar: `or = and ('||' and)*`, `and = not ('&&' not)*`, `not = '!' not | cmp`,
//! `cmp = primary (('=='|'!='|'<'|'<='|'>'|'>='|'=~') primary)?`,
//! `primary = number | 'string' | "string" | $name | ${name} | word | '(' or ')'`.
//! Variables: `$Frame`, then "category:name" (or "user:name" for a bare name) looked up in
//! the attributes and then the options.

use crate::diag::Diag;
use crate::rib::{Request, Value};

use super::builder::{Builder, Cond};
use super::types::Param;

/// A value in a condition.
#[derive(Clone, Debug, PartialEq)]
pub enum CVal {
    Num(f64),
    Str(String),
}

impl CVal {
    fn truthy(&self) -> bool {
        match self {
            CVal::Num(n) => *n != 0.0,
            CVal::Str(s) => !s.is_empty(),
        }
    }
    fn text(&self) -> String {
        match self {
            CVal::Num(n) => format!("{n}"),
            CVal::Str(s) => s.clone(),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Str(String),
    Var(String),
    Word(String),
    Op(&'static str),
}

fn lex(s: &str) -> Result<Vec<Tok>, String> {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = s[i..].chars().next().unwrap_or(' ');
        if c.is_whitespace() {
            i += c.len_utf8();
            continue;
        }
        let two = s.get(i..i + 2).unwrap_or("");
        if let Some(op) = ["==", "!=", "<=", ">=", "=~", "&&", "||"]
            .into_iter()
            .find(|o| *o == two)
        {
            out.push(Tok::Op(op));
            i += 2;
            continue;
        }
        if let Some(op) = ["<", ">", "!", "(", ")"]
            .into_iter()
            .find(|o| o.as_bytes()[0] == b[i])
        {
            out.push(Tok::Op(op));
            i += 1;
            continue;
        }
        if c == '\'' || c == '"' {
            let end = s[i + 1..]
                .find(c)
                .ok_or_else(|| format!("unclosed {c} string"))?;
            out.push(Tok::Str(s[i + 1..i + 1 + end].to_string()));
            i += end + 2;
            continue;
        }
        if c == '$' {
            let (name, len) = if s[i + 1..].starts_with('{') {
                let end = s[i + 2..].find('}').ok_or("unclosed ${")?;
                (s[i + 2..i + 2 + end].to_string(), end + 3)
            } else {
                let n = s[i + 1..]
                    .find(|ch: char| !(ch.is_alphanumeric() || ch == '_' || ch == ':'))
                    .unwrap_or(s.len() - i - 1);
                (s[i + 1..i + 1 + n].to_string(), n + 1)
            };
            if name.is_empty() {
                return Err("`$` without a variable name".into());
            }
            out.push(Tok::Var(name));
            i += len;
            continue;
        }
        if c.is_ascii_digit()
            || c == '.'
            || (c == '-'
                && b.get(i + 1)
                    .is_some_and(|d| d.is_ascii_digit() || *d == b'.'))
        {
            let n = s[i + 1..]
                .find(|ch: char| !(ch.is_ascii_digit() || ch == '.' || ch == 'e' || ch == 'E'))
                .map_or(s.len(), |p| p + i + 1);
            let v: f64 = s[i..n]
                .parse()
                .map_err(|_| format!("bad number `{}`", &s[i..n]))?;
            out.push(Tok::Num(v));
            i = n;
            continue;
        }
        if c.is_alphanumeric() || c == '_' {
            let n = s[i..]
                .find(|ch: char| !(ch.is_alphanumeric() || ch == '_' || ch == '.' || ch == '-'))
                .map_or(s.len(), |p| p + i)
                .max(i + c.len_utf8());
            out.push(Tok::Word(s[i..n].to_string()));
            i = n;
            continue;
        }
        return Err(format!("unexpected `{c}`"));
    }
    Ok(out)
}

struct Parser<'a, F: Fn(&str) -> Option<CVal>> {
    toks: &'a [Tok],
    pos: usize,
    lookup: &'a F,
}

impl<F: Fn(&str) -> Option<CVal>> Parser<'_, F> {
    fn peek_op(&self, op: &str) -> bool {
        matches!(self.toks.get(self.pos), Some(Tok::Op(o)) if *o == op)
    }
    fn or(&mut self) -> Result<CVal, String> {
        let mut v = self.and()?;
        while self.peek_op("||") {
            self.pos += 1;
            let r = self.and()?;
            v = CVal::Num((v.truthy() || r.truthy()) as i32 as f64);
        }
        Ok(v)
    }
    fn and(&mut self) -> Result<CVal, String> {
        let mut v = self.not()?;
        while self.peek_op("&&") {
            self.pos += 1;
            let r = self.not()?;
            v = CVal::Num((v.truthy() && r.truthy()) as i32 as f64);
        }
        Ok(v)
    }
    fn not(&mut self) -> Result<CVal, String> {
        if self.peek_op("!") {
            self.pos += 1;
            let v = self.not()?;
            return Ok(CVal::Num((!v.truthy()) as i32 as f64));
        }
        self.cmp()
    }
    fn cmp(&mut self) -> Result<CVal, String> {
        let l = self.primary()?;
        let op = match self.toks.get(self.pos) {
            Some(Tok::Op(o)) if matches!(*o, "==" | "!=" | "<" | "<=" | ">" | ">=" | "=~") => *o,
            _ => return Ok(l),
        };
        self.pos += 1;
        let r = self.primary()?;
        let b = if op == "=~" {
            regex_match(&r.text(), &l.text())?
        } else {
            let ord = match (&l, &r) {
                (CVal::Num(a), CVal::Num(b)) => a.partial_cmp(b),
                _ => Some(l.text().cmp(&r.text())),
            };
            let Some(ord) = ord else {
                return Ok(CVal::Num(0.0));
            };
            use std::cmp::Ordering::*;
            match op {
                "==" => ord == Equal,
                "!=" => ord != Equal,
                "<" => ord == Less,
                "<=" => ord != Greater,
                ">" => ord == Greater,
                _ => ord != Less,
            }
        };
        Ok(CVal::Num(b as i32 as f64))
    }
    fn primary(&mut self) -> Result<CVal, String> {
        let t = self
            .toks
            .get(self.pos)
            .cloned()
            .ok_or("the expression ends too early")?;
        self.pos += 1;
        match t {
            Tok::Num(n) => Ok(CVal::Num(n)),
            Tok::Str(s) | Tok::Word(s) => Ok(CVal::Str(s)),
            Tok::Var(name) => {
                (self.lookup)(&name).ok_or_else(|| format!("unknown variable `${name}`"))
            }
            Tok::Op("(") => {
                let v = self.or()?;
                if !self.peek_op(")") {
                    return Err("missing `)`".into());
                }
                self.pos += 1;
                Ok(v)
            }
            Tok::Op(o) => Err(format!("unexpected `{o}`")),
        }
    }
}

/// Evaluates a condition; `lookup` resolves `$name` variables.
pub fn eval(expr: &str, lookup: &impl Fn(&str) -> Option<CVal>) -> Result<bool, String> {
    let toks = lex(expr)?;
    if toks.is_empty() {
        return Err("the condition is empty".into());
    }
    let mut p = Parser {
        toks: &toks,
        pos: 0,
        lookup,
    };
    let v = p.or()?;
    if p.pos != toks.len() {
        return Err(format!(
            "unexpected `{:?}` after the expression",
            toks[p.pos]
        ));
    }
    Ok(v.truthy())
}

/// A small regular-expression matcher for `=~`: literals, `.`, `*`, `+`, `?`, `^`, `$`,
/// `[…]` classes (with ranges and `^`) and `\` escapes. Unanchored unless `^`/`$` are given.
pub fn regex_match(pattern: &str, text: &str) -> Result<bool, String> {
    let pat = compile(pattern)?;
    let t: Vec<char> = text.chars().collect();
    let (anchored, items) = match pat.first() {
        Some((Atom::Start, _)) => (true, &pat[1..]),
        _ => (false, &pat[..]),
    };
    if anchored {
        return Ok(match_here(items, &t, 0));
    }
    Ok((0..=t.len()).any(|i| match_here(items, &t, i)))
}

#[derive(Clone, Debug)]
enum Atom {
    Char(char),
    Any,
    Class(Vec<(char, char)>, bool),
    Start,
    End,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Rep {
    One,
    Star,
    Plus,
    Opt,
}

fn compile(p: &str) -> Result<Vec<(Atom, Rep)>, String> {
    let c: Vec<char> = p.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let atom = match c[i] {
            '.' => Atom::Any,
            '^' if i == 0 => Atom::Start,
            '$' if i + 1 == c.len() => Atom::End,
            '\\' => {
                i += 1;
                Atom::Char(*c.get(i).ok_or("pattern ends with `\\`")?)
            }
            '[' => {
                let mut j = i + 1;
                let neg = c.get(j) == Some(&'^');
                if neg {
                    j += 1;
                }
                let mut ranges = Vec::new();
                while j < c.len() && (c[j] != ']' || ranges.is_empty()) {
                    if j + 2 < c.len() && c[j + 1] == '-' && c[j + 2] != ']' {
                        ranges.push((c[j], c[j + 2]));
                        j += 3;
                    } else {
                        ranges.push((c[j], c[j]));
                        j += 1;
                    }
                }
                if j >= c.len() {
                    return Err("unclosed `[` in pattern".into());
                }
                i = j;
                Atom::Class(ranges, neg)
            }
            ch => Atom::Char(ch),
        };
        i += 1;
        let rep = match c.get(i) {
            Some('*') => Rep::Star,
            Some('+') => Rep::Plus,
            Some('?') => Rep::Opt,
            _ => Rep::One,
        };
        if rep != Rep::One {
            i += 1;
        }
        out.push((atom, rep));
    }
    Ok(out)
}

fn atom_matches(a: &Atom, ch: char) -> bool {
    match a {
        Atom::Char(c) => *c == ch,
        Atom::Any => true,
        Atom::Class(r, neg) => r.iter().any(|&(lo, hi)| lo <= ch && ch <= hi) != *neg,
        Atom::Start | Atom::End => false,
    }
}

fn match_here(p: &[(Atom, Rep)], t: &[char], i: usize) -> bool {
    let Some(((atom, rep), rest)) = p.split_first() else {
        return true;
    };
    if let Atom::End = atom {
        return i == t.len();
    }
    let (min, max) = match rep {
        Rep::One => (1, 1),
        Rep::Star => (0, usize::MAX),
        Rep::Plus => (1, usize::MAX),
        Rep::Opt => (0, 1),
    };
    let mut n = 0;
    while n < max && i + n < t.len() && atom_matches(atom, t[i + n]) {
        n += 1;
    }
    (min..=n).rev().any(|k| match_here(rest, t, i + k))
}

fn param_val(p: &Param) -> Option<CVal> {
    if let Some(s) = p.data.strings().first() {
        return Some(CVal::Str(s.clone()));
    }
    p.data.floats().first().map(|&f| CVal::Num(f as f64))
}

impl Builder<'_> {
    fn lookup_var(&self, name: &str) -> Option<CVal> {
        if name == "Frame" {
            let n = self.frame.unwrap_or(self.world_count.max(1));
            return Some(CVal::Num(n as f64));
        }
        let key = if name.contains(':') {
            name.to_string()
        } else {
            format!("user:{name}")
        };
        self.gs
            .attrs
            .user
            .get(&key)
            .or_else(|| self.options.user.get(&key))
            .and_then(param_val)
    }

    fn eval_cond(&mut self, r: &Request) -> bool {
        let Some(Value::Str(expr)) = r.args.first().map(|a| &a.value) else {
            let d = Diag::error(
                "scene::arguments",
                format!("`{}` needs a condition string", r.name),
            )
            .label(r.span, "no condition")
            .help("e.g. IfBegin \"$Frame == 1\"");
            self.report(d);
            return false;
        };
        let span = r.args[0].span;
        match eval(expr, &|n: &str| self.lookup_var(n)) {
            Ok(b) => b,
            Err(e) => {
                let d = Diag::warning(
                    "scene::condition",
                    format!("cannot evaluate `{}` condition: {e}; the branch is skipped", r.name),
                )
                .label(span, "here")
                .help("conditions compare numbers and 'strings' with == != < <= > >= =~, joined by && || !; variables are $Frame and $category:name");
                self.report(d);
                false
            }
        }
    }

    /// Handles IfBegin/ElseIf/Else/IfEnd (called for every one, active or not).
    pub(super) fn conditional(&mut self, r: &Request) {
        let active = self.conds.last().map_or(true, |c| c.active);
        match r.name.as_str() {
            "IfBegin" => {
                let v = active && self.eval_cond(r);
                self.conds.push(Cond {
                    span: r.span,
                    parent_active: active,
                    taken: v,
                    active: v,
                    seen_else: false,
                });
            }
            "ElseIf" | "Else" => {
                let Some(top) = self.conds.last().cloned() else {
                    let d = Diag::error(
                        "scene::nesting",
                        format!("`{}` without `IfBegin`", r.name),
                    )
                    .label(r.span, "no open IfBegin")
                    .help("conditional RIB is IfBegin \"cond\" … ElseIf \"cond\" … Else … IfEnd");
                    return self.report(d);
                };
                if top.seen_else {
                    let d = Diag::error("scene::nesting", format!("`{}` after `Else`", r.name))
                        .label(r.span, "here")
                        .label(top.span, "in this IfBegin");
                    return self.report(d);
                }
                let v = if top.parent_active && !top.taken {
                    r.name == "Else" || self.eval_cond(r)
                } else {
                    false
                };
                if let Some(c) = self.conds.last_mut() {
                    c.active = v;
                    c.taken |= v;
                    c.seen_else = r.name == "Else";
                }
            }
            _ => {
                if self.conds.pop().is_none() {
                    let d = Diag::error("scene::nesting", "`IfEnd` without `IfBegin`")
                        .label(r.span, "nothing to close");
                    self.report(d);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(n: &str) -> Option<CVal> {
        match n {
            "Frame" => Some(CVal::Num(3.0)),
            "user:pass" => Some(CVal::Str("shadowpass".into())),
            _ => None,
        }
    }

    #[test]
    fn expressions() {
        assert_eq!(eval("$Frame == 3", &vars), Ok(true));
        assert_eq!(eval("$Frame > 3 || $Frame <= 1", &vars), Ok(false));
        assert_eq!(eval("!($Frame != 3) && 'a' < 'b'", &vars), Ok(true));
        assert_eq!(eval("$user:pass == 'shadowpass'", &vars), Ok(true));
        assert_eq!(eval("$user:pass =~ '^shadow.*'", &vars), Ok(true));
        assert_eq!(eval("$user:pass =~ 'beauty'", &vars), Ok(false));
        assert!(eval("$nope == 1", &vars).is_err());
        assert!(eval("$Frame ==", &vars).is_err());
        assert_eq!(eval("1", &vars), Ok(true));
    }

    #[test]
    fn regexes() {
        assert_eq!(regex_match("a.c", "xxabcx"), Ok(true));
        assert_eq!(regex_match("^ab+c$", "abbbc"), Ok(true));
        assert_eq!(regex_match("^ab+c$", "ac"), Ok(false));
        assert_eq!(regex_match("[0-9]+x", "frame12x"), Ok(true));
        assert_eq!(regex_match("[^a-z]", "abc"), Ok(false));
        assert_eq!(regex_match("colou?r", "color"), Ok(true));
    }
}
