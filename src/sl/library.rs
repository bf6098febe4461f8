//! Finding, compiling and caching shaders.
//!
//! Input: a shader name (as a scene names it) or a `.sl` path. Output: compiled programs.
//! Search order for a name: the search paths given (CLI, then the scene's
//! `Option "searchpath" "shader"`, then the scene's folder), then the standard library embedded
//! in the binary. `#include` looks in the including file's folder, `-I` folders, the search
//! paths and the embedded `stdlib/include`. Every program is compiled once per run.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crate::diag::{Diag, Diagnostics, SourceMap, Span};
use crate::sl::ast::{Item, ShaderKind, SourceFile};
use crate::sl::ir::Program;
use crate::sl::preprocess::{preprocess, IncludeResolver, Preprocessed};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/stdlib.rs"));
}

/// The standard shaders embedded in the binary: (file name, source).
pub fn stdlib_shaders() -> &'static [(&'static str, &'static str)] {
    embedded::SHADERS
}

/// The standard headers embedded in the binary: (file name, source).
pub fn stdlib_includes() -> &'static [(&'static str, &'static str)] {
    embedded::INCLUDES
}

#[derive(Clone, Debug, Default)]
pub struct CompileOptions {
    pub include_dirs: Vec<PathBuf>,
    pub defines: Vec<(String, Option<String>)>,
    /// Shader search path (also searched for includes).
    pub search_paths: Vec<PathBuf>,
}

/// The include search of a compile: the including file's folder (for `"file"`), `-I` folders,
/// the shader search path, then the embedded `stdlib/include`.
pub struct SearchResolver<'a> {
    pub opts: &'a CompileOptions,
}

impl IncludeResolver for SearchResolver<'_> {
    fn resolve(&self, name: &str, system: bool, from: Option<&Path>) -> Option<(String, String)> {
        let mut dirs: Vec<PathBuf> = Vec::new();
        if !system {
            if let Some(dir) = from.and_then(Path::parent) {
                dirs.push(dir.to_path_buf());
            }
        }
        dirs.extend(self.opts.include_dirs.iter().cloned());
        dirs.extend(self.opts.search_paths.iter().cloned());
        for d in dirs {
            let p = d.join(name);
            if let Ok(text) = crate::encoding::read_text(&p) {
                return Some((p.display().to_string(), text));
            }
        }
        let base = Path::new(name).file_name()?.to_str()?;
        stdlib_includes()
            .iter()
            .find(|(n, _)| *n == base)
            .map(|(n, t)| (format!("<stdlib>/include/{n}"), t.to_string()))
    }
}

/// Whether a diagnostic points into one of the embedded standard headers.
fn in_stdlib(sources: &SourceMap, d: &Diag) -> bool {
    d.labels.first().is_some_and(|(span, _)| {
        sources
            .get(span.file)
            .is_some_and(|f| f.name.starts_with("<stdlib>/"))
    })
}

/// Compiles every shader defined in a source text. Diagnostics go to `diags`; the programs
/// that compiled cleanly are returned.
pub fn compile_source(
    name: &str,
    text: &str,
    path: Option<&Path>,
    sources: &SourceMap,
    diags: &Diagnostics,
    opts: &CompileOptions,
) -> Vec<Program> {
    let resolver = SearchResolver { opts };
    compile_with(
        name,
        text,
        path,
        sources,
        diags,
        opts,
        &resolver,
        &mut parse_all,
    )
    .programs
}

/// How [`compile_with`] parses the preprocessed text: all of it at once (`arbor lsp` reuses
/// the items of a previous parse that did not change).
pub type ParseFn<'a> = dyn FnMut(&Preprocessed, &Diagnostics) -> Option<SourceFile> + 'a;

/// The whole preprocessed text through the parser.
pub fn parse_all(pre: &Preprocessed, diags: &Diagnostics) -> Option<SourceFile> {
    let span = |a: usize, b: usize| pre.span(a, b);
    crate::sl::parse::parse(&pre.text, &span, diags)
}

/// What compiling one source text produced, for tools that also want the syntax tree.
pub struct Compiled {
    /// The registered file id of the text.
    pub file: u32,
    /// The syntax tree (None after syntax errors or a missing include).
    pub ast: Option<crate::sl::ast::SourceFile>,
    pub programs: Vec<Program>,
}

/// [`compile_source`] with the include search and the parse given (`arbor lsp` overlays
/// unsaved editor buffers and parses incrementally) and the syntax tree kept.
#[allow(clippy::too_many_arguments)]
pub fn compile_with(
    name: &str,
    text: &str,
    path: Option<&Path>,
    sources: &SourceMap,
    diags: &Diagnostics,
    opts: &CompileOptions,
    resolver: &dyn IncludeResolver,
    parser: &mut ParseFn<'_>,
) -> Compiled {
    // An RSL 2.0 class that is one shading method is compiled as that shader (PRMan runs
    // the method with the class's parameters); the rewritten text keeps the file's lines.
    let rewritten = crate::sl::rsl2::single_method_class(text);
    let file = sources.add(name, rewritten.as_ref().map_or(text, |r| r.0.as_str()));
    if let Some((_, kind, at)) = &rewritten {
        diags.report(
            Diag::warning(
                "sl::rsl2",
                format!(
                    "RSL 2.0 class with a single `{kind}` method: compiled as {} {kind} shader \
                     with the class's parameters",
                    if kind.starts_with('i') { "an" } else { "a" }
                ),
            )
            .label(Span::new(file, *at, *at + kind.len()), "class"),
        );
    }
    let text = rewritten.as_ref().map_or(text, |r| r.0.as_str());
    let mut done = Compiled {
        file,
        ast: None,
        programs: Vec::new(),
    };
    // RSL 2.0 classes and Slim palettes get one diagnostic saying what they are.
    if let Some(d) = crate::sl::foreign::foreign_language(file, text) {
        diags.report(d);
        return done;
    }
    let before = diags.snapshot().len();
    let pre = preprocess(file, path, sources, &opts.defines, resolver, diags);
    // A missing header leaves names undefined everywhere; its one diagnostic says it all, so
    // the cascade of unknown names it would cause is not compiled and reported.
    let missing_include = diags.snapshot()[before..]
        .iter()
        .any(|(d, _)| d.is_error() && d.code == "sl::include");
    if missing_include {
        return done;
    }
    let Some(ast) = parser(&pre, diags) else {
        return done;
    };
    let functions: Vec<_> = ast
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Function(f) => Some(f.clone()),
            _ => None,
        })
        .collect();
    let mut out = Vec::new();
    let mut any_shader = false;
    for item in &ast.items {
        if let Item::Shader(def) = item {
            any_shader = true;
            match crate::sl::lower::lower_shader(def, &functions) {
                Ok((prog, warnings)) => {
                    for w in warnings {
                        // arbor's own headers use extensions on purpose (PRMan's normals.h
                        // reads `I` in lights, as PRMan allows): not the user's to fix.
                        if w.code == "sl::extension" && in_stdlib(sources, &w) {
                            continue;
                        }
                        diags.report(w);
                    }
                    out.push(prog);
                }
                Err(errs) => {
                    for e in errs {
                        diags.report(e);
                    }
                }
            }
        }
    }
    if !any_shader {
        diags.report(Diag::warning(
            "sl::empty",
            format!("`{name}` defines no shader"),
        ));
    }
    done.ast = Some(ast);
    done.programs = out;
    done
}

/// Compiled shaders by name, shared by every thread of a render.
pub struct ShaderLibrary {
    pub opts: CompileOptions,
    cache: Mutex<HashMap<String, Option<Arc<Program>>>>,
}

impl ShaderLibrary {
    pub fn new(opts: CompileOptions) -> ShaderLibrary {
        ShaderLibrary {
            opts,
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// The program for a shader name ("plastic", "myshaders/wood", "wood.sl"); None (with an
    /// error reported once) when it cannot be found or does not compile.
    pub fn get(
        &self,
        name: &str,
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<Arc<Program>> {
        if let Some(p) = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(name)
        {
            return p.clone();
        }
        let result = self.load(name, sources, diags);
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(name.to_string(), result.clone());
        result
    }

    /// The program for a shader name compiled with extra preprocessor `defines` (cached under
    /// `name` and `tag`). Its compile diagnostics are not reported: the plain program
    /// ([`ShaderLibrary::get`]) reports them; None when the variant does not compile.
    pub fn get_variant(
        &self,
        name: &str,
        tag: &str,
        defines: &[(&str, &str)],
        sources: &SourceMap,
    ) -> Option<Arc<Program>> {
        let key = format!("{name}\u{0}{tag}");
        if let Some(p) = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return p.clone();
        }
        let mut opts = self.opts.clone();
        for (k, v) in defines {
            opts.defines.push((k.to_string(), Some(v.to_string())));
        }
        let scratch = Diagnostics::new();
        let result = self
            .load_with(name, &opts, sources, &scratch)
            .filter(|_| !scratch.has_errors());
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, result.clone());
        result
    }

    /// Where a shader name may come from, in search order: `stem.sl` in each search directory,
    /// as a path of its own, then the embedded standard library.
    fn candidates(name: &str, search: &[PathBuf]) -> (String, Vec<Candidate>) {
        let stem = name
            .strip_suffix(".sl")
            .or_else(|| name.strip_suffix(".slo"))
            .or_else(|| name.strip_suffix(".slx"))
            .or_else(|| name.strip_suffix(".sdr"))
            .unwrap_or(name);
        let file_name = format!("{stem}.sl");
        let base = Path::new(stem)
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or(stem)
            .to_string();
        let mut out: Vec<Candidate> = search
            .iter()
            .map(|d| Candidate::File(d.join(&file_name)))
            .collect();
        out.push(Candidate::File(PathBuf::from(&file_name)));
        if let Some(k) = stdlib_shaders()
            .iter()
            .position(|(n, _)| n.strip_suffix(".sl") == Some(&base))
        {
            out.push(Candidate::Stdlib(k));
        }
        (base, out)
    }

    /// Compiles one candidate; None when it does not exist (Some(None): it did not compile).
    fn compile_candidate(
        &self,
        c: &Candidate,
        base: &str,
        name: &str,
        opts: &CompileOptions,
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<Option<Arc<Program>>> {
        match c {
            Candidate::File(path) => {
                let text = crate::encoding::read_text(path).ok()?;
                let progs = compile_source(
                    &path.display().to_string(),
                    &text,
                    Some(path),
                    sources,
                    diags,
                    opts,
                );
                Some(pick(progs, base, name, diags))
            }
            Candidate::Stdlib(k) => {
                let (n, text) = stdlib_shaders()[*k];
                let progs = compile_source(
                    &format!("<stdlib>/shaders/{n}"),
                    text,
                    None,
                    sources,
                    diags,
                    opts,
                );
                Some(pick(progs, base, name, diags))
            }
        }
    }

    fn load(&self, name: &str, sources: &SourceMap, diags: &Diagnostics) -> Option<Arc<Program>> {
        self.load_with(name, &self.opts, sources, diags)
    }

    fn load_with(
        &self,
        name: &str,
        opts: &CompileOptions,
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<Arc<Program>> {
        let (base, candidates) = Self::candidates(name, &opts.search_paths);
        for c in &candidates {
            if let Some(p) = self.compile_candidate(c, &base, name, opts, sources, diags) {
                return p;
            }
        }
        if let Some((c, p)) =
            self.load_ignoring_case(&candidates, &base, name, opts, sources, diags)
        {
            diags.report(
                Diag::warning(
                    "shade::name-case",
                    format!(
                        "shader `{name}` found as {}: the names differ only in letter case",
                        c.describe()
                    ),
                )
                .help("the scene was written on a file system that ignores case; rename the file or the request to match"),
            );
            return p;
        }
        if let Some((path, p)) = self.load_by_declared_name(&base, name, opts, sources, diags) {
            diags.report(
                Diag::note(
                    "shade::declared-name",
                    format!(
                        "shader `{name}` found in `{}`, which declares it under another file name",
                        path.display()
                    ),
                )
                .help(format!(
                    "PRMan names a compiled shader after its declaration, not its file; rename the file `{base}.sl` to find it directly"
                )),
            );
            return p;
        }
        if let Some(path) = crate::sl::initials::find_initialled(&base, &opts.search_paths) {
            let c = Candidate::File(path);
            if let Some(p) = self.compile_candidate(&c, &base, name, opts, sources, diags) {
                diags.report(
                    Diag::warning(
                        "shade::renamed",
                        format!(
                            "shader `{name}` not found; {} is used: the same name with its \
                             author's initials in front",
                            c.describe()
                        ),
                    )
                    .help("the RenderMan Repository renamed its shaders so; name the file's shader in the scene"),
                );
                return p;
            }
        }
        diags.report(
            Diag::warning(
                "shade::missing",
                format!("shader `{name}` not found: a surface or light falls back to a standard one it resembles, other kinds are left out"),
            )
            .help("put the .sl file in the scene's folder or on the shader search path (--shaders, Option \"searchpath\" \"shader\")"),
        );
        None
    }

    /// A `.sl` file on the search path (or in the working folder) that declares the shader
    /// `base` under another file name, compiled: shader compilers name their output after the
    /// declaration, so a RIB names `SIG2k_srf_contact` where the repository ships it as
    /// `SIG2k_srfconta.sl` (a file name cut to fit an old file system). Files are tried in
    /// name order, folders in search order; None when no file declares it.
    fn load_by_declared_name(
        &self,
        base: &str,
        name: &str,
        opts: &CompileOptions,
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<(PathBuf, Option<Arc<Program>>)> {
        let dirs = opts
            .search_paths
            .iter()
            .cloned()
            .chain(std::iter::once(PathBuf::from(".")));
        for dir in dirs {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            let mut files: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "sl"))
                .collect();
            files.sort();
            for path in files {
                let Ok(text) = crate::encoding::read_text(&path) else {
                    continue;
                };
                if !declares_shader(&text, base) {
                    continue;
                }
                let c = Candidate::File(path.clone());
                match self.compile_candidate(&c, base, name, opts, sources, diags) {
                    // Declared in a conditional part the preprocessor left out: not this one.
                    Some(Some(p)) if p.name != base => continue,
                    Some(p) => return Some((path, p)),
                    None => continue,
                }
            }
        }
        None
    }

    /// The first candidate that exists under a name differing only in ASCII case (a scene from
    /// a case-insensitive file system), compiled; None when there is none.
    fn load_ignoring_case(
        &self,
        candidates: &[Candidate],
        base: &str,
        name: &str,
        opts: &CompileOptions,
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<(Candidate, Option<Arc<Program>>)> {
        let mut alternatives: Vec<Candidate> = candidates
            .iter()
            .filter_map(|c| match c {
                Candidate::File(p) => {
                    crate::pathcase::find_file_ignoring_case(p).map(Candidate::File)
                }
                Candidate::Stdlib(_) => None,
            })
            .collect();
        if let Some(k) = stdlib_shaders().iter().position(|(n, _)| {
            n.strip_suffix(".sl")
                .is_some_and(|n| n.eq_ignore_ascii_case(base))
        }) {
            alternatives.push(Candidate::Stdlib(k));
        }
        for c in alternatives {
            if let Some(p) = self.compile_candidate(&c, base, name, opts, sources, diags) {
                return Some((c, p));
            }
        }
        None
    }

    /// The program for a shader name as an instance uses it, giving values for `given`
    /// parameters. When the first shader of that name on the path lacks several of them (the
    /// scene was written for another shader of the same name, e.g. BMRT's `smoke` where the
    /// path first holds *Advanced RenderMan*'s), a later one on the path or in the standard
    /// library that has more of them is used instead, with a warning naming both.
    pub fn get_for(
        &self,
        name: &str,
        given: &[&str],
        sources: &SourceMap,
        diags: &Diagnostics,
    ) -> Option<Arc<Program>> {
        let first = self.get(name, sources, diags)?;
        let lacks = |p: &Program| given.iter().filter(|g| p.param(g).is_none()).count();
        let missing = lacks(&first);
        if missing < 2 {
            return Some(first);
        }
        let mut key = format!("{name}\u{0}");
        for g in given {
            key.push_str(g);
            key.push('\u{0}');
        }
        if let Some(p) = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
        {
            return p.clone();
        }
        let (base, candidates) = Self::candidates(name, &self.opts.search_paths);
        // The candidates after the first that exists; compiled quietly (a broken alternative
        // is no alternative).
        let mut found_first: Option<String> = None;
        let mut best: Option<(usize, Arc<Program>, String)> = None;
        for c in &candidates {
            let exists = match c {
                Candidate::File(p) => p.is_file(),
                Candidate::Stdlib(_) => true,
            };
            if !exists {
                continue;
            }
            if found_first.is_none() {
                found_first = Some(c.describe());
                continue;
            }
            let quiet = Diagnostics::new();
            let Some(Some(p)) = self.compile_candidate(c, &base, name, &self.opts, sources, &quiet)
            else {
                continue;
            };
            if p.kind != first.kind || quiet.has_errors() {
                continue;
            }
            let m = lacks(&p);
            if m < best.as_ref().map_or(missing, |b| b.0) {
                best = Some((m, p, c.describe()));
            }
        }
        let chosen = match best {
            Some((_, p, place)) => {
                diags.report(
                    Diag::warning(
                        "shade::version",
                        format!(
                            "shader `{name}` at {} lacks {missing} of the parameters this scene \
                             gives it; the `{name}` at {place} has more of them and is used",
                            found_first.unwrap_or_default()
                        ),
                    )
                    .help("put the intended shader first on the shader search path"),
                );
                p
            }
            None => first,
        };
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, Some(chosen.clone()));
        Some(chosen)
    }
}

/// One place a shader may be loaded from.
enum Candidate {
    File(PathBuf),
    /// Index into [`stdlib_shaders`].
    Stdlib(usize),
}

impl Candidate {
    fn describe(&self) -> String {
        match self {
            Candidate::File(p) => format!("`{}`", p.display()),
            Candidate::Stdlib(k) => format!("the standard library (`{}`)", stdlib_shaders()[*k].0),
        }
    }
}

/// Whether shading-language `text` declares a shader called `name`: the name follows a shader
/// kind keyword (whitespace between) and precedes its parameter list's `(`.
fn declares_shader(text: &str, name: &str) -> bool {
    let is_ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    // A comment that mentions a shader's declaration does not declare it.
    let text = &crate::sl::foreign::strip_comments(text);
    text.match_indices(name).any(|(at, _)| {
        let before = &text[..at];
        let after = &text[at + name.len()..];
        if before.ends_with(is_ident) || !after.trim_start().starts_with('(') {
            return false;
        }
        let before = before.trim_end();
        // Past the last character that is not part of an identifier (any width: comments
        // may hold UTF-8).
        let word_start = before
            .char_indices()
            .rev()
            .find(|&(_, c)| !is_ident(c))
            .map(|(i, c)| i + c.len_utf8())
            .unwrap_or(0);
        let word = &before[word_start..];
        ShaderKind::ALL.iter().any(|k| k.name() == word)
    })
}

fn pick(progs: Vec<Program>, base: &str, name: &str, diags: &Diagnostics) -> Option<Arc<Program>> {
    if progs.is_empty() {
        diags.report(Diag::error(
            "shade::compile",
            format!("shader `{name}` did not compile"),
        ));
        return None;
    }
    let idx = progs
        .iter()
        .position(|p| p.name == base)
        .or_else(|| progs.iter().position(|p| p.name.eq_ignore_ascii_case(base)))
        .unwrap_or(0);
    progs.into_iter().nth(idx).map(Arc::new)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_names_are_found_past_whitespace_not_in_comments() {
        let text = "/* surface fur( old */ // light fur(\n\
                    #include \"x.h\"\nsurface\n  SIG2k_fur ( float a = 1; ) {}\n\
                    é surface\tsmall(){}";
        assert!(declares_shader(text, "SIG2k_fur"));
        assert!(declares_shader(text, "small"));
        assert!(!declares_shader(text, "fur"));
        assert!(!declares_shader(text, "SIG2k"));
        assert!(!declares_shader("float f() { return fur(1); }", "fur"));
    }

    #[test]
    fn every_standard_shader_compiles() {
        let sources = SourceMap::new();
        let diags = Diagnostics::new();
        let lib = ShaderLibrary::new(CompileOptions::default());
        for (n, _) in stdlib_shaders() {
            let name = n.trim_end_matches(".sl");
            let p = lib.get(name, &sources, &diags);
            assert!(p.is_some(), "{name}: {}", diags.render_plain(&sources));
        }
        assert!(!diags.has_errors(), "{}", diags.render_plain(&sources));
    }
}
