//! Editor features of RIB documents: hover, completion, go-to-definition, document symbols,
//! formatting, and where a shader's or archive's diagnostics show in the scene.
//!
//! Input: the document text, a byte offset and the last [`RibChecked`] state (requests read,
//! shaders compiled, the scene's shader search path).
//! Output: LSP answers. Request names and their positional arguments come from the request
//! table (`scene::table`), parameter names from the shader a request names (its compiled
//! parameters) or from the standard declarations (`scene::params::STANDARD`).
//! Invariants: the cursor's context is read by a small lexer over the text itself, so
//! completion works while the request being typed does not parse yet; formatting is
//! `arbor format`'s (`rib::format_source`) and is refused while the text has syntax errors.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use lsp_types::{
    CompletionItem, CompletionItemKind, DocumentSymbol, Documentation, Hover, HoverContents,
    Location, MarkupContent, MarkupKind, Range, SymbolKind,
};

use super::check::{path_to_uri, uri_of_source, RibChecked, SHADER_REQUESTS};
use super::text::LineIndex;
use crate::diag::{Diagnostics, SourceMap};
use crate::scene::params::STANDARD;
use crate::scene::table;
use crate::sl::ir::Program;
use crate::sl::{CompileOptions, ShaderLibrary};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tok {
    Word,
    Str,
    Num,
    Open,
    Close,
}

/// RIB tokens with their byte ranges (comments skipped; an unterminated string runs to the
/// end of its line).
pub fn lex(text: &str) -> Vec<(Tok, usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        match c {
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'"' => {
                let s = i;
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += if b[i] == b'\\' { 2 } else { 1 };
                }
                i = (i + usize::from(i < b.len() && b[i] == b'"')).min(b.len());
                out.push((Tok::Str, s, i));
            }
            b'[' => {
                out.push((Tok::Open, i, i + 1));
                i += 1;
            }
            b']' => {
                out.push((Tok::Close, i, i + 1));
                i += 1;
            }
            c if c.is_ascii_whitespace() => i += 1,
            c if c.is_ascii_alphabetic() => {
                let s = i;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
                out.push((Tok::Word, s, i));
            }
            _ => {
                let s = i;
                while i < b.len()
                    && !b[i].is_ascii_whitespace()
                    && !matches!(b[i], b'"' | b'[' | b']' | b'#')
                {
                    i += 1;
                }
                out.push((Tok::Num, s, i.max(s + 1).min(b.len())));
                i = i.max(s + 1);
            }
        }
    }
    out
}

/// Where the cursor is, read from the tokens.
#[derive(Debug, PartialEq)]
pub enum Context {
    /// On (or typing) a request name.
    Request {
        name: String,
    },
    /// Inside or on a string argument: its request, its argument index (arrays count once),
    /// the string's text, and the first argument's text (the shader or category name).
    Str {
        request: String,
        arg: usize,
        value: String,
        first: Option<String>,
    },
    Other,
}

fn unquote(s: &str) -> String {
    s.trim_start_matches('"').trim_end_matches('"').to_string()
}

/// The context at byte `offset`.
pub fn context(text: &str, offset: usize) -> Context {
    let mut offset = offset.min(text.len());
    while !text.is_char_boundary(offset) {
        offset -= 1;
    }
    let toks = lex(text);
    let mut request: Option<String> = None;
    let mut args: Vec<String> = Vec::new();
    let mut depth = 0usize;
    for &(k, s, e) in &toks {
        let here = s <= offset && offset <= e && !(k == Tok::Str && offset == s);
        match k {
            Tok::Word if depth == 0 => {
                if here {
                    return Context::Request {
                        name: text[s..e].to_string(),
                    };
                }
                if s >= offset {
                    break;
                }
                request = Some(text[s..e].to_string());
                args.clear();
            }
            Tok::Str if here => {
                let Some(r) = request else {
                    return Context::Other;
                };
                return Context::Str {
                    request: r,
                    arg: args.len(),
                    value: unquote(&text[s..e]),
                    first: args.first().cloned(),
                };
            }
            _ if s >= offset => break,
            Tok::Open => {
                if depth == 0 {
                    args.push(String::new());
                }
                depth += 1;
            }
            Tok::Close => depth = depth.saturating_sub(1),
            _ if depth == 0 => args.push(unquote(&text[s..e])),
            _ => {}
        }
    }
    // Between tokens: a new word starts a request name.
    let before = &text[..offset.min(text.len())];
    let line = before.rsplit('\n').next().unwrap_or("");
    if depth == 0 && (line.trim().is_empty() || line.ends_with(char::is_alphabetic)) {
        return Context::Request {
            name: String::new(),
        };
    }
    Context::Other
}

fn markdown(value: String) -> Hover {
    Hover {
        contents: HoverContents::Markup(MarkupContent {
            kind: MarkupKind::Markdown,
            value,
        }),
        range: None,
    }
}

fn request_markdown(spec: &table::ReqSpec) -> String {
    let args: Vec<String> = spec.args.iter().map(|a| a.0.to_string()).collect();
    let mut line = spec.name.to_string();
    if !args.is_empty() {
        line.push(' ');
        line.push_str(&args.join(" "));
    }
    if spec.params {
        line.push_str(" ...parameterlist");
    }
    let section = if spec.section == "ext" {
        "an extension (not in RISpec 3.2)".to_string()
    } else {
        format!("RISpec 3.2 §{}", spec.section)
    };
    format!("```rib\n{line}\n```\n\n{}\n\n*{section}*", spec.describe())
}

fn shader_markdown(p: &Program) -> String {
    let mut s = format!("```rsl\n{} {}(", p.kind.name(), p.name);
    for (k, par) in p.params.iter().enumerate() {
        s.push_str(if k == 0 { "\n" } else { ";\n" });
        s.push_str(&format!("    {}", param_text(par)));
    }
    s.push_str(")\n```");
    s
}

fn param_text(par: &crate::sl::ir::ParamInfo) -> String {
    format!(
        "{}{} {} {}{} = {}",
        if par.output { "output " } else { "" },
        if par.varying { "varying" } else { "uniform" },
        par.ty.name(),
        par.name,
        par.array.map(|n| format!("[{n}]")).unwrap_or_default(),
        par.default_text
    )
}

/// The compiled shader a name stands for: the check's, else compiled now from the search
/// path (the request naming it may not parse yet while it is being typed).
fn shader_of(checked: Option<&RibChecked>, name: &str) -> Option<Arc<Program>> {
    if let Some(p) = checked
        .and_then(|c| c.shaders.get(name))
        .and_then(|p| p.clone())
    {
        return Some(p);
    }
    let search = checked.map(|c| c.shader_paths.clone()).unwrap_or_default();
    let lib = ShaderLibrary::new(CompileOptions {
        search_paths: search,
        ..CompileOptions::default()
    });
    lib.get(name, &SourceMap::new(), &Diagnostics::new())
}

/// The standard declaration of a parameter name (`category:name` first).
fn standard(category: Option<&str>, name: &str) -> Option<&'static str> {
    let key = category.map(|c| format!("{c}:{name}"));
    STANDARD
        .iter()
        .find(|s| Some(s.0) == key.as_deref())
        .or_else(|| STANDARD.iter().find(|s| s.0 == name))
        .map(|s| s.1)
}

/// Number of positional arguments a request takes before its parameter list.
fn positional(request: &str) -> usize {
    table::lookup(request).map_or(0, |s| s.args.len())
}

fn is_category_request(r: &str) -> bool {
    matches!(r, "Option" | "Attribute")
}

pub fn hover(text: &str, offset: usize, checked: Option<&RibChecked>) -> Option<Hover> {
    match context(text, offset) {
        Context::Request { name } => table::lookup(&name).map(|s| markdown(request_markdown(s))),
        Context::Str {
            request,
            arg,
            value,
            first,
        } => {
            if SHADER_REQUESTS.contains(&request.as_str()) && arg == 0 {
                let p = shader_of(checked, &value)?;
                return Some(markdown(shader_markdown(&p)));
            }
            let npos = positional(&request);
            if arg < npos || (arg - npos) % 2 == 1 {
                return None;
            }
            // An inline declaration: "uniform float Kd".
            let bare = value.rsplit(' ').next().unwrap_or(&value);
            if SHADER_REQUESTS.contains(&request.as_str()) {
                let prog = first.as_deref().and_then(|f| shader_of(checked, f));
                if let Some(par) = prog
                    .as_ref()
                    .and_then(|p| p.params.iter().find(|q| q.name == bare))
                {
                    return Some(markdown(format!(
                        "```rsl\n{}\n```\n\n*parameter of shader `{}`*",
                        param_text(par),
                        first.unwrap_or_default()
                    )));
                }
            }
            let cat = is_category_request(&request)
                .then_some(first.as_deref())
                .flatten();
            let decl = standard(cat, bare)?;
            Some(markdown(format!(
                "```rib\n\"{decl} {bare}\"\n```\n\n*standard declaration*"
            )))
        }
        Context::Other => None,
    }
}

/// The .sl shaders in the search path folders and the standard library: (name, file).
fn shader_files(search: &[PathBuf]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = Vec::new();
    for d in search {
        let Ok(rd) = std::fs::read_dir(d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.extension().is_some_and(|x| x == "sl") {
                if let Some(stem) = p.file_stem().and_then(|s| s.to_str()) {
                    out.push((stem.to_string(), p.display().to_string()));
                }
            }
        }
    }
    for (n, _) in crate::sl::library::stdlib_shaders() {
        out.push((
            n.trim_end_matches(".sl").to_string(),
            format!("<stdlib>/shaders/{n}"),
        ));
    }
    let mut seen = std::collections::HashSet::new();
    out.retain(|(n, _)| seen.insert(n.clone()));
    out
}

fn item(
    label: &str,
    kind: CompletionItemKind,
    detail: String,
    doc: Option<String>,
) -> CompletionItem {
    CompletionItem {
        label: label.to_string(),
        kind: Some(kind),
        detail: Some(detail),
        documentation: doc.map(|value| {
            Documentation::MarkupContent(MarkupContent {
                kind: MarkupKind::Markdown,
                value,
            })
        }),
        ..CompletionItem::default()
    }
}

pub fn completion(text: &str, offset: usize, checked: Option<&RibChecked>) -> Vec<CompletionItem> {
    match context(text, offset) {
        Context::Request { .. } => table::TABLE
            .iter()
            .map(|s| {
                item(
                    s.name,
                    CompletionItemKind::KEYWORD,
                    s.describe(),
                    Some(request_markdown(s)),
                )
            })
            .collect(),
        Context::Str {
            request,
            arg,
            first,
            ..
        } => {
            let shader_req = SHADER_REQUESTS.contains(&request.as_str());
            if shader_req && arg == 0 {
                let search = checked.map(|c| c.shader_paths.clone()).unwrap_or_default();
                return shader_files(&search)
                    .into_iter()
                    .map(|(n, f)| item(&n, CompletionItemKind::FILE, f, None))
                    .collect();
            }
            if is_category_request(&request) && arg == 0 {
                let mut cats: Vec<&str> = STANDARD
                    .iter()
                    .filter_map(|s| s.0.split_once(':').map(|c| c.0))
                    .collect();
                cats.extend(["user"]);
                cats.sort();
                cats.dedup();
                return cats
                    .into_iter()
                    .map(|c| {
                        item(
                            c,
                            CompletionItemKind::MODULE,
                            format!("{request} category"),
                            None,
                        )
                    })
                    .collect();
            }
            let npos = positional(&request);
            if arg < npos || (arg - npos) % 2 == 1 {
                return Vec::new();
            }
            if shader_req {
                if let Some(p) = first.as_deref().and_then(|f| shader_of(checked, f)) {
                    return p
                        .params
                        .iter()
                        .map(|par| {
                            item(
                                &par.name,
                                CompletionItemKind::FIELD,
                                param_text(par),
                                Some(format!("parameter of shader `{}`", p.name)),
                            )
                        })
                        .collect();
                }
            }
            if is_category_request(&request) {
                let Some(cat) = first else { return Vec::new() };
                let prefix = format!("{cat}:");
                return STANDARD
                    .iter()
                    .filter_map(|s| Some((s.0.strip_prefix(&prefix)?, s.1)))
                    .map(|(n, d)| item(n, CompletionItemKind::FIELD, d.to_string(), None))
                    .collect();
            }
            STANDARD
                .iter()
                .filter(|s| !s.0.contains(':'))
                .map(|(n, d)| item(n, CompletionItemKind::FIELD, d.to_string(), None))
                .collect()
        }
        Context::Other => Vec::new(),
    }
}

/// The file a shader name stands for: the search path, then the standard library.
pub fn shader_file(name: &str, search: &[PathBuf]) -> Option<String> {
    let stem = name.strip_suffix(".sl").unwrap_or(name);
    for d in search {
        let p = d.join(format!("{stem}.sl"));
        if p.is_file() {
            return Some(p.display().to_string());
        }
    }
    let base = Path::new(stem).file_name()?.to_str()?;
    crate::sl::library::stdlib_shaders()
        .iter()
        .find(|(n, _)| n.strip_suffix(".sl") == Some(base))
        .map(|(n, _)| format!("<stdlib>/shaders/{n}"))
}

/// Go to definition: the shader file a shader request names, the file `ReadArchive` reads.
pub fn definition(
    text: &str,
    offset: usize,
    checked: Option<&RibChecked>,
    doc_path: Option<&Path>,
) -> Option<Location> {
    let Context::Str {
        request,
        arg: 0,
        value,
        ..
    } = context(text, offset)
    else {
        return None;
    };
    let target = if SHADER_REQUESTS.contains(&request.as_str()) {
        let search = checked.map(|c| c.shader_paths.clone()).unwrap_or_default();
        shader_file(&value, &search)?
    } else if request == "ReadArchive" {
        let p = Path::new(&value);
        let p = if p.is_relative() {
            doc_path.and_then(Path::parent)?.join(p)
        } else {
            p.to_path_buf()
        };
        if !p.is_file() {
            return None;
        }
        return Some(Location {
            uri: path_to_uri(&p)?,
            range: Range::default(),
        });
    } else {
        return None;
    };
    Some(Location {
        uri: uri_of_source(&target)?,
        range: Range::default(),
    })
}

/// The outline: blocks nested as written, with their lights, shaders, primitives and archives.
#[allow(deprecated)] // DocumentSymbol::deprecated must be written out
pub fn symbols(text: &str, checked: &RibChecked, file: u32) -> Vec<DocumentSymbol> {
    let lines = LineIndex::new(text);
    // Stack of open blocks: (symbol, children).
    let mut stack: Vec<(DocumentSymbol, Vec<DocumentSymbol>)> = Vec::new();
    let mut top: Vec<DocumentSymbol> = Vec::new();
    let mut count = 0usize;
    let sym = |name: String, kind: SymbolKind, r: &crate::rib::Request| {
        let full = r.full_span();
        DocumentSymbol {
            name,
            detail: None,
            kind,
            tags: None,
            deprecated: None,
            range: lines.range(text, full.start as usize, full.end as usize),
            selection_range: lines.range(text, r.span.start as usize, r.span.end as usize),
            children: None,
        }
    };
    let first_arg = |r: &crate::rib::Request| {
        r.args.first().map(|a| match &a.value {
            crate::rib::Value::Str(s) => format!(" \"{s}\""),
            v => format!(" {}", v.as_f32().map(|f| f.to_string()).unwrap_or_default()),
        })
    };
    for r in checked.requests.iter().filter(|r| r.span.file == file) {
        let n = r.name.as_str();
        if n.len() > 5 && n.ends_with("Begin") {
            let label = format!(
                "{}{}",
                n.trim_end_matches("Begin"),
                first_arg(r).unwrap_or_default()
            );
            stack.push((sym(label, SymbolKind::NAMESPACE, r), Vec::new()));
            continue;
        }
        if n.len() > 3 && n.ends_with("End") {
            if let Some((mut s, children)) = stack.pop() {
                let end = lines.position(text, r.full_span().end as usize);
                s.range.end = end;
                s.children = Some(children);
                match stack.last_mut() {
                    Some(p) => p.1.push(s),
                    None => top.push(s),
                }
            }
            continue;
        }
        let spec = table::lookup(n);
        let kind = if SHADER_REQUESTS.contains(&n) {
            if n.contains("Light") {
                SymbolKind::EVENT
            } else {
                SymbolKind::CLASS
            }
        } else if matches!(n, "ReadArchive" | "ObjectInstance" | "Display") {
            SymbolKind::FILE
        } else if spec.is_some_and(|s| s.section.starts_with("5.")) {
            SymbolKind::OBJECT
        } else if n == "Attribute"
            && r.args.first().and_then(|a| a.value.as_str()) == Some("identifier")
        {
            // Name the enclosing block after its identifier.
            if let (Some(name), Some(b)) = (
                r.args.get(2).and_then(|a| a.value.as_str()),
                stack.last_mut(),
            ) {
                b.0.name = format!("{} \"{name}\"", b.0.name);
            }
            continue;
        } else {
            continue;
        };
        count += 1;
        if count > 10_000 {
            continue;
        }
        let s = sym(format!("{n}{}", first_arg(r).unwrap_or_default()), kind, r);
        match stack.last_mut() {
            Some(p) => p.1.push(s),
            None => top.push(s),
        }
    }
    // Blocks left open (typing): close them at the end.
    while let Some((mut s, children)) = stack.pop() {
        s.children = Some(children);
        match stack.last_mut() {
            Some(p) => p.1.push(s),
            None => top.push(s),
        }
    }
    top
}

/// The byte range of the request in `text` that pulls `file` in: a shader request naming its
/// stem, or a `ReadArchive` of its file name.
pub fn anchor(checked: &RibChecked, file: &str, doc_file: u32) -> Option<(usize, usize)> {
    let p = Path::new(file);
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or(file);
    let fname = p.file_name().and_then(|s| s.to_str()).unwrap_or(file);
    checked
        .requests
        .iter()
        .filter(|r| r.span.file == doc_file)
        .find(|r| {
            let a = r.args.first().and_then(|a| a.value.as_str()).unwrap_or("");
            let a_stem = Path::new(a)
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or(a);
            (SHADER_REQUESTS.contains(&r.name.as_str()) && (a_stem == stem || a == file))
                || (r.name == "ReadArchive"
                    && Path::new(a).file_name().and_then(|s| s.to_str()) == Some(fname))
        })
        .map(|r| {
            let s = r.args.first().map_or(r.span, |a| r.span.to(a.span));
            (s.start as usize, s.end as usize)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_finds_requests_and_string_arguments() {
        let t = "WorldBegin\nSurface \"plastic\" \"Kd\" 0.5 \"\nSph";
        assert_eq!(
            context(t, 3),
            Context::Request {
                name: "WorldBegin".into()
            }
        );
        let at = t.find("plastic").unwrap() + 2;
        assert_eq!(
            context(t, at),
            Context::Str {
                request: "Surface".into(),
                arg: 0,
                value: "plastic".into(),
                first: None
            }
        );
        let at = t.find("Kd").unwrap() + 1;
        match context(t, at) {
            Context::Str { arg, first, .. } => {
                assert_eq!(arg, 1);
                assert_eq!(first.as_deref(), Some("plastic"));
            }
            c => panic!("{c:?}"),
        }
        // The unterminated string being typed: the third argument.
        let at = t.find("0.5 \"").unwrap() + 5;
        match context(t, at) {
            Context::Str { arg, value, .. } => {
                assert_eq!(arg, 3);
                assert_eq!(value, "");
            }
            c => panic!("{c:?}"),
        }
        assert_eq!(context(t, t.len()), Context::Request { name: "Sph".into() });
    }

    #[test]
    fn lexer_never_panics_on_odd_text() {
        for t in ["\"", "\"\\", "[[[", "#", "é\"ü", "1e", "\u{1F600}"] {
            let toks = lex(t);
            for (_, s, e) in toks {
                assert!(s <= e && e <= t.len(), "{t:?}");
            }
            let _ = context(t, t.len());
            let _ = context(t, 0);
        }
    }
}
