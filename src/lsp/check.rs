//! Checking one editor document as `arbor check` would, and turning the diagnostics into LSP's.
//!
//! Input: a document (its text as the editor has it, its path when it is a file) and the
//! unsaved text of every other open document (included headers are read from there first).
//! Output: a [`Checked`] document: every [`Diag`] with the [`SourceMap`] it points into, the
//! parse results the editor features need, and the LSP diagnostics per file.
//! Invariants: `.sl` runs preprocess → parse → compile exactly as `arbor check` does; `.rib`
//! parses and builds every frame and compiles every shader the scene names, as `arbor check`
//! does. A diagnostic in another file (an included header, a shader, an archive) is also shown
//! in the checked document at the line that pulled the file in, so nothing is hidden.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use lsp_types::{
    Diagnostic, DiagnosticRelatedInformation, DiagnosticSeverity, Location, NumberOrString, Uri,
};

use super::index::{self, Index};
use super::reparse::ParseCache;
use super::text::LineIndex;
use crate::diag::{Diag, Diagnostics, Severity, SourceMap, Span};
use crate::pipeline::{library_for, Settings};
use crate::rib::Request;
use crate::scene::{build_scenes, BuildContext, Scene};
use crate::sl::ir::Program;
use crate::sl::library::{compile_with, SearchResolver};
use crate::sl::preprocess::IncludeResolver;
use crate::sl::CompileOptions;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lang {
    Sl,
    /// A shading-language header (`.h`): checked alone it defines no shader, which is fine.
    SlHeader,
    Rib,
}

impl Lang {
    /// From the file name, else the editor's language id.
    pub fn of(path: &str, language_id: &str) -> Option<Lang> {
        let ext = Path::new(path)
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match ext.as_str() {
            "sl" => return Some(Lang::Sl),
            "h" | "slh" | "slim" => return Some(Lang::SlHeader),
            "rib" | "ribz" => return Some(Lang::Rib),
            _ => {}
        }
        match language_id {
            "rsl" | "sl" | "renderman-sl" | "renderman" | "shader" => Some(Lang::Sl),
            "rib" | "renderman-rib" => Some(Lang::Rib),
            _ => None,
        }
    }
}

/// The text of the open documents by file path (unsaved edits win over the disk).
pub type Overlay = HashMap<PathBuf, Arc<str>>;

/// Looks includes up as `arbor check` does, then takes an open editor buffer's text over the
/// file's.
pub struct OverlayResolver<'a> {
    pub search: SearchResolver<'a>,
    pub overlay: &'a Overlay,
}

impl IncludeResolver for OverlayResolver<'_> {
    fn resolve(&self, name: &str, system: bool, from: Option<&Path>) -> Option<(String, String)> {
        let (display, text) = self.search.resolve(name, system, from)?;
        match self.overlay.get(Path::new(&display)) {
            Some(t) => Some((display, t.to_string())),
            None => Some((display, text)),
        }
    }
}

/// A checked shading-language document.
pub struct SlChecked {
    pub index: Option<Index>,
    pub programs: Vec<Program>,
}

/// A checked RIB document.
pub struct RibChecked {
    pub requests: Vec<Request>,
    /// Shader search path of the first scene (CLI, scene's, scene folder).
    pub shader_paths: Vec<PathBuf>,
    /// Compiled shaders by the name the scene used (None: not found / did not compile).
    pub shaders: HashMap<String, Option<Arc<Program>>>,
}

pub enum Detail {
    Sl(SlChecked),
    Rib(RibChecked),
}

/// One document after checking.
pub struct Checked {
    pub sources: SourceMap,
    /// The document's file id in `sources`.
    pub file: u32,
    pub diags: Vec<Diag>,
    pub detail: Detail,
}

/// Settings a check uses: the command line's, plus the document's folder.
pub fn compile_options(settings: &Settings) -> CompileOptions {
    CompileOptions {
        include_dirs: settings.include_dirs.clone(),
        defines: settings.defines.clone(),
        search_paths: settings.shader_paths.iter().map(PathBuf::from).collect(),
    }
}

/// Checks a shading-language document.
pub fn check_sl(
    name: &str,
    text: &str,
    path: Option<&Path>,
    lang: Lang,
    settings: &Settings,
    overlay: &Overlay,
    cache: &mut ParseCache,
) -> Checked {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let opts = compile_options(settings);
    let resolver = OverlayResolver {
        search: SearchResolver { opts: &opts },
        overlay,
    };
    let mut parser = |pre: &crate::sl::preprocess::Preprocessed, d: &Diagnostics| {
        super::reparse::parse(pre, &sources, d, cache)
    };
    let done = compile_with(
        name,
        text,
        path,
        &sources,
        &diags,
        &opts,
        &resolver,
        &mut parser,
    );
    let index = done.ast.as_ref().map(|ast| index::build(ast, &sources));
    let mut list: Vec<Diag> = diags.take().into_iter().map(|(d, _)| d).collect();
    if lang == Lang::SlHeader {
        list.retain(|d| d.code != "sl::empty");
    }
    Checked {
        sources,
        file: done.file,
        diags: list,
        detail: Detail::Sl(SlChecked {
            index,
            programs: done.programs,
        }),
    }
}

/// The shader requests of RIB and where their shader's name is.
pub const SHADER_REQUESTS: &[&str] = &[
    "Surface",
    "Displacement",
    "Atmosphere",
    "Interior",
    "Exterior",
    "LightSource",
    "AreaLightSource",
    "Imager",
    "Deformation",
];

/// Checks a RIB document: parse, build every frame, compile the shaders the scenes name.
pub fn check_rib(name: &str, text: &str, path: Option<&Path>, settings: &Settings) -> Checked {
    let sources = SourceMap::new();
    let diags = Diagnostics::new();
    let requests = crate::rib::parse_bytes(name, text.as_bytes(), &sources, &diags);
    // parse_bytes registers the text first.
    let file = 0;
    let base_dir = path.and_then(Path::parent).map(|p| {
        if p.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            p.to_path_buf()
        }
    });
    let ctx = BuildContext {
        sources: &sources,
        diags: &diags,
        shader_paths: settings.shader_paths.clone(),
        texture_paths: settings.texture_paths.clone(),
        archive_paths: settings.archive_paths.clone(),
        base_dir: base_dir.clone(),
        frames: None,
        procedurals: Default::default(),
    };
    let scenes: Vec<Scene> = build_scenes(requests.clone(), &ctx);
    let mut shaders: HashMap<String, Option<Arc<Program>>> = HashMap::new();
    let mut shader_paths: Vec<PathBuf> = Vec::new();
    for (k, scene) in scenes.iter().enumerate() {
        let lib = library_for(scene, settings);
        if k == 0 {
            shader_paths = lib.opts.search_paths.clone();
        }
        for n in crate::pipeline::shader_names(scene) {
            let p = lib.get(&n, &sources, &diags);
            shaders.entry(n).or_insert(p);
        }
    }
    if scenes.is_empty() {
        // No world block yet: the search path is the CLI's and the document's folder.
        shader_paths = settings.shader_paths.iter().map(PathBuf::from).collect();
        shader_paths.extend(base_dir);
    }
    Checked {
        sources,
        file,
        diags: diags.take().into_iter().map(|(d, _)| d).collect(),
        detail: Detail::Rib(RibChecked {
            requests,
            shader_paths,
            shaders,
        }),
    }
}

/// The URI of a registered source file: a path on disk, or an embedded standard file written
/// out read-only to a temporary folder so an editor can open it.
pub fn uri_of_source(name: &str) -> Option<Uri> {
    if let Some(rest) = name.strip_prefix("<stdlib>/") {
        let text = stdlib_text(rest)?;
        let dir = std::env::temp_dir().join("arbor-lsp-stdlib");
        let path = dir.join(rest);
        if std::fs::read_to_string(&path).ok().as_deref() != Some(text) {
            std::fs::create_dir_all(path.parent()?).ok()?;
            std::fs::write(&path, text).ok()?;
        }
        return path_to_uri(&path);
    }
    let p = Path::new(name);
    if p.is_absolute() || p.exists() {
        return path_to_uri(p);
    }
    None
}

/// The embedded text of `shaders/x.sl` or `include/x.h`.
pub fn stdlib_text(rest: &str) -> Option<&'static str> {
    use crate::sl::library::{stdlib_includes, stdlib_shaders};
    if let Some(n) = rest.strip_prefix("shaders/") {
        return stdlib_shaders().iter().find(|s| s.0 == n).map(|s| s.1);
    }
    if let Some(n) = rest.strip_prefix("include/") {
        return stdlib_includes().iter().find(|s| s.0 == n).map(|s| s.1);
    }
    None
}

/// A `file://` URI for a path (made absolute), percent-encoding what a URI may not hold.
pub fn path_to_uri(path: &Path) -> Option<Uri> {
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().ok()?.join(path)
    };
    let mut s = String::from("file://");
    for b in abs.to_str()?.bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s.parse().ok()
}

/// The path of a `file://` URI (percent-decoded), None for other schemes.
pub fn uri_to_path(uri: &Uri) -> Option<PathBuf> {
    let s = uri.as_str();
    let rest = s.strip_prefix("file://")?;
    // `file://host/path`: only local files (empty host or localhost).
    let rest = rest.strip_prefix("localhost").unwrap_or(rest);
    if !rest.starts_with('/') {
        return None;
    }
    let b = rest.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            if let Ok(v) = u8::from_str_radix(std::str::from_utf8(&b[i + 1..i + 3]).ok()?, 16) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    let mut p = String::from_utf8(out).ok()?;
    // Windows: `file:///C:/x`.
    if p.len() > 2 && p.as_bytes()[2] == b':' {
        p.remove(0);
    }
    Some(PathBuf::from(p))
}

/// LSP diagnostics of a checked document, by the file they are in. The document's own come
/// under `doc_uri`; each diagnostic in another file also appears in the document at
/// `anchor(file name)` (the `#include`, shader or archive line), or its first line.
pub fn lsp_diagnostics(
    c: &Checked,
    doc_uri: &Uri,
    doc_text: &str,
    anchor: &dyn Fn(&str) -> Option<(usize, usize)>,
) -> HashMap<Uri, Vec<Diagnostic>> {
    let doc_lines = LineIndex::new(doc_text);
    let mut out: HashMap<Uri, Vec<Diagnostic>> = HashMap::new();
    out.entry(doc_uri.clone()).or_default();
    let mut foreign_lines: HashMap<u32, (Uri, Arc<str>, LineIndex)> = HashMap::new();
    let mut range_in = |span: Span| -> Option<(Uri, lsp_types::Range)> {
        if span.file == c.file {
            return Some((
                doc_uri.clone(),
                doc_lines.range(doc_text, span.start as usize, span.end as usize),
            ));
        }
        if !foreign_lines.contains_key(&span.file) {
            let f = c.sources.get(span.file)?;
            let uri = uri_of_source(&f.name)?;
            let idx = LineIndex::new(&f.text);
            foreign_lines.insert(span.file, (uri, f.text.clone(), idx));
        }
        let (uri, text, idx) = foreign_lines.get(&span.file)?;
        Some((
            uri.clone(),
            idx.range(text, span.start as usize, span.end as usize),
        ))
    };
    for d in &c.diags {
        let severity = Some(match d.severity {
            Severity::Error => DiagnosticSeverity::ERROR,
            Severity::Warning => DiagnosticSeverity::WARNING,
            // Notes (known settings arbor ignores) are shown at -v on the command line.
            Severity::Note => DiagnosticSeverity::HINT,
        });
        let mut message = d.message.clone();
        if let Some((_, label)) = d.labels.first() {
            if !label.is_empty() && !d.message.contains(label.as_str()) {
                message.push_str(&format!(" ({label})"));
            }
        }
        if let Some(h) = &d.help {
            message.push_str(&format!("\nhelp: {h}"));
        }
        let related: Vec<DiagnosticRelatedInformation> = d
            .labels
            .iter()
            .skip(1)
            .filter_map(|(s, text)| {
                let (uri, range) = range_in(*s)?;
                Some(DiagnosticRelatedInformation {
                    location: Location { uri, range },
                    message: text.clone(),
                })
            })
            .collect();
        let mk = |range: lsp_types::Range, message: String| Diagnostic {
            range,
            severity,
            code: Some(NumberOrString::String(d.code.to_string())),
            source: Some("arbor".into()),
            message,
            related_information: (!related.is_empty()).then(|| related.clone()),
            ..Diagnostic::default()
        };
        let primary = d.primary_span();
        match primary {
            Some(s) if s.file == c.file => {
                let (uri, range) = range_in(s).expect("own file");
                out.entry(uri).or_default().push(mk(range, message));
            }
            Some(s) => {
                let fname = c
                    .sources
                    .get(s.file)
                    .map(|f| f.name.clone())
                    .unwrap_or_default();
                let (line, col) = c.sources.line_col(s);
                let at = anchor(&fname).unwrap_or((0, 0));
                let short = Path::new(&fname)
                    .file_name()
                    .map(|n| n.to_string_lossy().to_string())
                    .unwrap_or(fname.clone());
                out.entry(doc_uri.clone()).or_default().push(mk(
                    doc_lines.range(doc_text, at.0, at.1),
                    format!("in {short}:{line}:{col}: {message}"),
                ));
                if let Some((uri, range)) = range_in(s) {
                    out.entry(uri).or_default().push(mk(range, message));
                }
            }
            None => {
                let at = anchor_for_message(&d.message, anchor).unwrap_or((0, 0));
                out.entry(doc_uri.clone())
                    .or_default()
                    .push(mk(doc_lines.range(doc_text, at.0, at.1), message));
            }
        }
    }
    out
}

/// For a diagnostic without a span ("shader `wood` did not compile"): the anchor of the first
/// back-quoted name in its message.
fn anchor_for_message(
    message: &str,
    anchor: &dyn Fn(&str) -> Option<(usize, usize)>,
) -> Option<(usize, usize)> {
    let mut parts = message.split('`');
    parts.next()?;
    let name = parts.next()?;
    anchor(name)
}
