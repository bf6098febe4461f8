//! Editor features of shading-language documents: hover, completion, go-to-definition,
//! document symbols, and where an included file's diagnostics show in the includer.
//!
//! Input: the document text, a byte offset, and the document's last [`Checked`] state (its
//! [`Index`] of declarations; the last one that parsed while the text does not).
//! Output: LSP answers (markdown hovers, completion items, locations, symbols).
//! Invariants: built-ins come from `sl::builtins` (signatures and doc lines), globals from
//! `sl::lower::GLOBALS`; a user declaration shadows a built-in of the same name.

use std::path::Path;

use lsp_types::{
    CompletionItem, CompletionItemKind, DocumentSymbol, Documentation, Hover, HoverContents,
    Location, MarkupContent, MarkupKind, Range, SymbolKind,
};

use super::check::{uri_of_source, OverlayResolver};
use super::index::{Decl, DeclKind, Index};
use super::text::{word_at, LineIndex};
use crate::diag::SourceMap;
use crate::sl::builtins;
use crate::sl::lower::GLOBALS;
use crate::sl::preprocess::IncludeResolver;

/// What each global variable is (RISpec 3.2 §12).
pub const GLOBAL_DOCS: &[(&str, &str)] = &[
    (
        "P",
        "Surface position (light shaders: the light's position).",
    ),
    ("dPdu", "Derivative of surface position along u."),
    ("dPdv", "Derivative of surface position along v."),
    ("N", "Surface shading normal."),
    ("Ng", "Surface geometric normal."),
    ("u", "Surface parameter u."),
    ("v", "Surface parameter v."),
    ("du", "Change in u between adjacent shading samples."),
    ("dv", "Change in v between adjacent shading samples."),
    ("s", "Surface texture coordinate s."),
    ("t", "Surface texture coordinate t."),
    ("Cs", "Surface colour (from `Color` or the primitive's Cs)."),
    (
        "Os",
        "Surface opacity (from `Opacity` or the primitive's Os).",
    ),
    ("Ci", "Incident ray colour: the surface shader's result."),
    ("Oi", "Incident ray opacity: the surface shader's result."),
    (
        "L",
        "Incoming light direction (in illuminance: from the surface to the light).",
    ),
    ("Cl", "Light colour arriving from the current light."),
    ("Ol", "Light opacity."),
    ("Ps", "Position being illuminated (light shaders)."),
    ("E", "Position of the eye (camera space origin)."),
    (
        "I",
        "Incident ray direction: from the eye to the surface point.",
    ),
    ("ncomps", "Number of colour components."),
    ("time", "Current shutter time."),
    ("dtime", "Amount of time covered by this shading sample."),
    ("dPdtime", "How the surface position changes per unit time."),
    ("alpha", "Fractional pixel coverage (imager shaders)."),
];

const KEYWORDS: &[&str] = &[
    "surface",
    "displacement",
    "light",
    "volume",
    "imager",
    "transformation",
    "float",
    "string",
    "color",
    "point",
    "vector",
    "normal",
    "matrix",
    "void",
    "uniform",
    "varying",
    "output",
    "extern",
    "if",
    "else",
    "while",
    "for",
    "break",
    "continue",
    "return",
    "illuminance",
    "illuminate",
    "solar",
    "gather",
    "texture",
    "environment",
    "shadow",
    "PI",
];

fn code_block(text: &str) -> String {
    format!("```rsl\n{text}\n```")
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

fn decl_markdown(d: &Decl) -> String {
    let what = match d.kind {
        DeclKind::Shader => "shader",
        DeclKind::Function => "function",
        DeclKind::Param => "shader parameter",
        DeclKind::Formal => "function parameter",
        DeclKind::Local => "local variable",
    };
    let mut s = format!("{}\n\n*{what}*", code_block(&d.detail));
    if let Some(doc) = &d.doc {
        s.push_str("\n\n");
        s.push_str(doc);
    }
    s
}

/// The markdown of a built-in function or a global variable.
pub fn builtin_markdown(name: &str) -> Option<String> {
    if let Some(&(n, ty, varying)) = GLOBALS.iter().find(|g| g.0 == name) {
        let doc = GLOBAL_DOCS.iter().find(|g| g.0 == n).map_or("", |g| g.1);
        return Some(format!(
            "{}\n\n*global variable* — {doc}",
            code_block(&format!(
                "{} {} {n}",
                if varying { "varying" } else { "uniform" },
                ty.name()
            ))
        ));
    }
    if builtins::is_builtin(name) {
        let sigs = builtins::signatures(name);
        let doc = builtins::doc(name).map_or("", |d| d.1);
        return Some(format!(
            "{}\n\n*built-in* — {doc}",
            code_block(&sigs.join("\n"))
        ));
    }
    None
}

/// Hover at byte `offset` of the document (file `file` in `sources`).
pub fn hover(text: &str, offset: usize, index: Option<&Index>, file: u32) -> Option<Hover> {
    let (_, _, word) = word_at(text, offset)?;
    if let Some(d) = index.and_then(|i| i.at(file, offset as u32)) {
        if d.name == word {
            return Some(markdown(decl_markdown(d)));
        }
    }
    // A user function or variable of this name in scope, then the language's own names.
    if let Some(d) = index.and_then(|i| {
        i.visible_at(file, offset as u32)
            .into_iter()
            .find(|d| d.name == word)
    }) {
        return Some(markdown(decl_markdown(d)));
    }
    builtin_markdown(word).map(markdown)
}

/// Completion items at byte `offset`: the names in scope, then globals, built-ins, keywords.
pub fn completion(offset: usize, index: Option<&Index>, file: u32) -> Vec<CompletionItem> {
    let mut items = Vec::new();
    let mut seen = std::collections::HashSet::new();
    if let Some(idx) = index {
        for d in idx.visible_at(file, offset as u32) {
            if d.kind == DeclKind::Shader || !seen.insert(d.name.clone()) {
                continue;
            }
            items.push(CompletionItem {
                label: d.name.clone(),
                kind: Some(match d.kind {
                    DeclKind::Function => CompletionItemKind::FUNCTION,
                    DeclKind::Param => CompletionItemKind::FIELD,
                    _ => CompletionItemKind::VARIABLE,
                }),
                detail: Some(d.detail.clone()),
                documentation: d.doc.clone().map(Documentation::String),
                sort_text: Some(format!("0{}", d.name)),
                ..CompletionItem::default()
            });
        }
    }
    for &(name, ty, varying) in GLOBALS {
        if !seen.insert(name.to_string()) {
            continue;
        }
        let doc = GLOBAL_DOCS.iter().find(|g| g.0 == name).map_or("", |g| g.1);
        items.push(CompletionItem {
            label: name.into(),
            kind: Some(CompletionItemKind::VARIABLE),
            detail: Some(format!(
                "{} {}",
                if varying { "varying" } else { "uniform" },
                ty.name()
            )),
            documentation: Some(Documentation::String(doc.into())),
            sort_text: Some(format!("1{name}")),
            ..CompletionItem::default()
        });
    }
    let names = builtins::SIGS
        .iter()
        .map(|s| s.name)
        .chain(builtins::SPECIAL.iter().copied());
    for name in names {
        if !seen.insert(name.to_string()) {
            continue;
        }
        let sigs = builtins::signatures(name);
        items.push(CompletionItem {
            label: name.into(),
            kind: Some(CompletionItemKind::FUNCTION),
            detail: sigs.first().cloned(),
            documentation: Some(Documentation::MarkupContent(MarkupContent {
                kind: MarkupKind::Markdown,
                value: builtin_markdown(name).unwrap_or_default(),
            })),
            sort_text: Some(format!("2{name}")),
            ..CompletionItem::default()
        });
    }
    for &k in KEYWORDS {
        if seen.insert(k.to_string()) {
            items.push(CompletionItem {
                label: k.into(),
                kind: Some(CompletionItemKind::KEYWORD),
                sort_text: Some(format!("3{k}")),
                ..CompletionItem::default()
            });
        }
    }
    items
}

/// The `#include` target named on the line around `offset`: (name, system).
fn include_at(text: &str, offset: usize) -> Option<(String, bool)> {
    let offset = offset.min(text.len());
    let start = text[..offset].rfind('\n').map_or(0, |p| p + 1);
    let end = text[offset..].find('\n').map_or(text.len(), |p| offset + p);
    include_target(&text[start..end])
}

/// `#include "name"` / `#include <name>` of one line.
fn include_target(line: &str) -> Option<(String, bool)> {
    let rest = line.trim_start().strip_prefix('#')?.trim_start();
    let rest = rest.strip_prefix("include")?.trim_start();
    let (close, system) = match rest.chars().next()? {
        '"' => ('"', false),
        '<' => ('>', true),
        _ => return None,
    };
    let body = &rest[1..];
    let end = body.find(close)?;
    Some((body[..end].to_string(), system))
}

/// Go to definition: a user function or variable, or the file an `#include` names.
pub fn definition(
    text: &str,
    offset: usize,
    index: Option<&Index>,
    file: u32,
    sources: &SourceMap,
    path: Option<&Path>,
    resolver: &OverlayResolver<'_>,
) -> Option<Location> {
    if let Some((name, system)) = include_at(text, offset) {
        let (display, _) = resolver.resolve(&name, system, path)?;
        let uri = uri_of_source(&display)?;
        return Some(Location {
            uri,
            range: Range::default(),
        });
    }
    let (_, _, word) = word_at(text, offset)?;
    let idx = index?;
    let d = idx
        .at(file, offset as u32)
        .filter(|d| d.name == word)
        .or_else(|| {
            idx.visible_at(file, offset as u32)
                .into_iter()
                .find(|d| d.name == word)
        })?;
    let f = sources.get(d.span.file)?;
    let uri = uri_of_source(&f.name)?;
    let lines = LineIndex::new(&f.text);
    Some(Location {
        uri,
        range: lines.range(&f.text, d.span.start as usize, d.span.end as usize),
    })
}

/// The outline: shaders and functions of this file with their parameters and locals.
#[allow(deprecated)] // DocumentSymbol::deprecated must be written out
pub fn symbols(text: &str, index: &Index, file: u32) -> Vec<DocumentSymbol> {
    let lines = LineIndex::new(text);
    let mk = |d: &Decl, children: Option<Vec<DocumentSymbol>>| DocumentSymbol {
        name: d.name.clone(),
        detail: Some(d.detail.clone()),
        kind: match d.kind {
            DeclKind::Shader => SymbolKind::CLASS,
            DeclKind::Function => SymbolKind::FUNCTION,
            DeclKind::Param => SymbolKind::FIELD,
            DeclKind::Formal | DeclKind::Local => SymbolKind::VARIABLE,
        },
        tags: None,
        deprecated: None,
        range: lines.range(
            text,
            d.full.start as usize,
            d.full.end.max(d.span.end) as usize,
        ),
        selection_range: lines.range(text, d.span.start as usize, d.span.end as usize),
        children,
    };
    let in_file = |d: &Decl| d.span.file == file && d.full.file == file;
    let mut out = Vec::new();
    for (i, d) in index.decls.iter().enumerate() {
        if d.parent.is_some() || !in_file(d) {
            continue;
        }
        out.push(mk(d, Some(children_of(index, i, &mk, &in_file))));
    }
    out
}

fn children_of(
    index: &Index,
    parent: usize,
    mk: &dyn Fn(&Decl, Option<Vec<DocumentSymbol>>) -> DocumentSymbol,
    in_file: &dyn Fn(&Decl) -> bool,
) -> Vec<DocumentSymbol> {
    index
        .decls
        .iter()
        .enumerate()
        .filter(|(_, d)| d.parent == Some(parent) && in_file(d))
        .map(|(i, d)| {
            if d.kind == DeclKind::Function {
                mk(d, Some(children_of(index, i, mk, in_file)))
            } else {
                mk(d, None)
            }
        })
        .collect()
}

/// The byte range of the `#include` line in `text` through which `target` (a resolved display
/// name) is reached, directly or through other headers.
pub fn include_anchor(
    text: &str,
    path: Option<&Path>,
    target: &str,
    resolver: &OverlayResolver<'_>,
) -> Option<(usize, usize)> {
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        let start = pos;
        pos += line.len();
        let Some((name, system)) = include_target(line) else {
            continue;
        };
        let Some((display, body)) = resolver.resolve(&name, system, path) else {
            if name == target || target.ends_with(&name) {
                return Some((start, start + line.trim_end().len()));
            }
            continue;
        };
        if display == target || reaches(&display, &body, target, resolver, 0) {
            return Some((start, start + line.trim_end().len()));
        }
    }
    None
}

fn reaches(
    from: &str,
    text: &str,
    target: &str,
    resolver: &OverlayResolver<'_>,
    depth: usize,
) -> bool {
    if depth > 16 {
        return false;
    }
    let from_path = (!from.starts_with('<')).then(|| Path::new(from));
    text.lines().any(|line| {
        include_target(line).is_some_and(|(name, system)| {
            resolver
                .resolve(&name, system, from_path)
                .is_some_and(|(d, body)| {
                    d == target || reaches(&d, &body, target, resolver, depth + 1)
                })
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn include_lines_are_recognised() {
        assert_eq!(
            include_target("  #  include \"noises.h\" // x"),
            Some(("noises.h".into(), false))
        );
        assert_eq!(
            include_target("#include <stdrsl.h>"),
            Some(("stdrsl.h".into(), true))
        );
        assert_eq!(include_target("#define X 1"), None);
        assert_eq!(include_target("#include \"broken"), None);
    }

    #[test]
    fn builtins_and_globals_have_hover_text() {
        let n = builtin_markdown("noise").unwrap();
        assert!(
            n.contains("float noise(point)") && n.contains("Perlin"),
            "{n}"
        );
        let p = builtin_markdown("Cs").unwrap();
        assert!(
            p.contains("varying color Cs") && p.contains("Surface colour"),
            "{p}"
        );
        assert!(builtin_markdown("notaname").is_none());
        for (g, ..) in GLOBALS {
            assert!(GLOBAL_DOCS.iter().any(|d| d.0 == *g), "{g} has no doc");
        }
    }
}
