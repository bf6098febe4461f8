//! `arbor lsp`: a Language Server Protocol server for `.sl` and `.rib` files over stdio.
//!
//! Input: JSON-RPC messages framed by `Content-Length` headers (LSP base protocol) on stdin.
//! Output: responses and `textDocument/publishDiagnostics` notifications on stdout.
//! Invariants:
//! - a malformed message (bad header, bad JSON, wrong params) gets an error response or is
//!   skipped; a panic inside a handler becomes an InternalError response. The server ends only
//!   on `exit` or end of input;
//! - documents are kept as the editor has them (incremental sync, UTF-16 positions); checks run
//!   after a burst of queued messages is handled, once per changed document, so typing fast
//!   re-checks once, not once per keystroke; a request on a changed document checks it first;
//! - diagnostics are `arbor check`'s (see [`check`]).
//!
//! The framing is written here rather than taken from the `lsp-server` crate: its stdio reader
//! ends the connection on the first message it cannot parse.

pub mod check;
pub mod index;
pub mod reparse;
pub mod rib;
pub mod sl;
pub mod text;

use std::collections::{HashMap, HashSet};
use std::io::{BufRead, Write};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Arc;

use lsp_types::*;
use serde_json::{json, Value};

use crate::pipeline::Settings;
use check::{Checked, Detail, Lang, Overlay, OverlayResolver};
use text::LineIndex;

/// JSON-RPC error codes.
const PARSE_ERROR: i64 = -32700;
const INVALID_REQUEST: i64 = -32600;
const METHOD_NOT_FOUND: i64 = -32601;
const INVALID_PARAMS: i64 = -32602;
const INTERNAL_ERROR: i64 = -32603;
const SERVER_NOT_INITIALIZED: i64 = -32002;
const REQUEST_FAILED: i64 = -32803;

/// Largest message body accepted (a 2 000-line shader is ~60 KB; a big RIB a few MB).
const MAX_BODY: usize = 256 << 20;

/// One open document.
pub struct Doc {
    pub uri: Uri,
    pub path: Option<PathBuf>,
    pub lang: Lang,
    pub version: i32,
    pub text: String,
    /// The last check (of the text as it was then).
    pub checked: Option<Checked>,
    /// The last check whose text parsed (shading language): names while the text does not.
    pub good: Option<Checked>,
    pub dirty: bool,
    /// The pieces of the last parse, reused where the text did not change.
    pub cache: reparse::ParseCache,
}

type Reply = Result<Value, (i64, String)>;

/// The server state: open documents and what was published where.
pub struct Server {
    settings: Settings,
    docs: HashMap<String, Doc>,
    /// uri → (document whose check produced them → diagnostics).
    published: HashMap<String, HashMap<String, Vec<Diagnostic>>>,
    initialized: bool,
    shutdown: bool,
    /// Set by `exit`: the process exit code.
    pub exit: Option<i32>,
    out: Box<dyn Write>,
}

impl Server {
    pub fn new(settings: Settings, out: Box<dyn Write>) -> Server {
        Server {
            settings,
            docs: HashMap::new(),
            published: HashMap::new(),
            initialized: false,
            shutdown: false,
            exit: None,
            out,
        }
    }

    fn send(&mut self, v: Value) {
        let body = v.to_string();
        let _ = write!(self.out, "Content-Length: {}\r\n\r\n{}", body.len(), body);
        let _ = self.out.flush();
    }

    fn respond(&mut self, id: Value, r: Reply) {
        let msg = match r {
            Ok(result) => json!({"jsonrpc": "2.0", "id": id, "result": result}),
            Err((code, message)) => {
                json!({"jsonrpc": "2.0", "id": id, "error": {"code": code, "message": message}})
            }
        };
        self.send(msg);
    }

    fn notify(&mut self, method: &str, params: Value) {
        self.send(json!({"jsonrpc": "2.0", "method": method, "params": params}));
    }

    /// Handles one message body (the bytes after the header).
    pub fn handle_body(&mut self, body: &[u8]) {
        let v: Value = match serde_json::from_slice(body) {
            Ok(v) => v,
            Err(e) => {
                self.respond(Value::Null, Err((PARSE_ERROR, format!("not JSON: {e}"))));
                return;
            }
        };
        let id = v.get("id").cloned();
        let method = v.get("method").and_then(Value::as_str).map(str::to_string);
        let params = v.get("params").cloned().unwrap_or(Value::Null);
        match (id, method) {
            (Some(id), Some(m)) => {
                let r = catch_unwind(AssertUnwindSafe(|| self.request(&m, params))).unwrap_or_else(
                    |_| Err((INTERNAL_ERROR, format!("`{m}` failed inside arbor"))),
                );
                self.respond(id, r);
            }
            (None, Some(m)) => {
                if catch_unwind(AssertUnwindSafe(|| self.notification(&m, params))).is_err() {
                    self.log(&format!("arbor: `{m}` failed inside arbor"));
                }
            }
            // A response to a request of ours (we send none) or a batch: nothing to do.
            (Some(_), None) if v.get("result").is_some() || v.get("error").is_some() => {}
            (id, None) => self.respond(
                id.unwrap_or(Value::Null),
                Err((INVALID_REQUEST, "a request needs a `method`".into())),
            ),
        }
    }

    fn log(&mut self, message: &str) {
        self.notify("window/logMessage", json!({"type": 2, "message": message}));
    }

    fn request(&mut self, method: &str, params: Value) -> Reply {
        if method == "initialize" {
            self.initialized = true;
            return Ok(json!({
                "capabilities": capabilities(),
                "serverInfo": {"name": "arbor", "version": env!("CARGO_PKG_VERSION")},
            }));
        }
        if !self.initialized {
            return Err((SERVER_NOT_INITIALIZED, "send `initialize` first".into()));
        }
        if self.shutdown {
            return Err((INVALID_REQUEST, "the server is shutting down".into()));
        }
        match method {
            "shutdown" => {
                self.shutdown = true;
                Ok(Value::Null)
            }
            "textDocument/hover" => {
                let p: HoverParams = parse(params)?;
                let pos = p.text_document_position_params;
                Ok(to_json(self.hover(&pos.text_document.uri, pos.position)))
            }
            "textDocument/completion" => {
                let p: CompletionParams = parse(params)?;
                let pos = p.text_document_position;
                Ok(to_json(
                    self.completion(&pos.text_document.uri, pos.position),
                ))
            }
            "textDocument/definition" => {
                let p: GotoDefinitionParams = parse(params)?;
                let pos = p.text_document_position_params;
                Ok(to_json(
                    self.definition(&pos.text_document.uri, pos.position),
                ))
            }
            "textDocument/documentSymbol" => {
                let p: DocumentSymbolParams = parse(params)?;
                Ok(to_json(self.symbols(&p.text_document.uri)))
            }
            "textDocument/formatting" => {
                let p: DocumentFormattingParams = parse(params)?;
                self.format(&p.text_document.uri).map(to_json)
            }
            _ => Err((METHOD_NOT_FOUND, format!("`{method}` is not supported"))),
        }
    }

    fn notification(&mut self, method: &str, params: Value) {
        match method {
            "exit" => self.exit = Some(if self.shutdown { 0 } else { 1 }),
            "textDocument/didOpen" => {
                let Ok(p) = serde_json::from_value::<DidOpenTextDocumentParams>(params) else {
                    return self.log("arbor: malformed didOpen");
                };
                let d = p.text_document;
                let path = check::uri_to_path(&d.uri);
                let name = path
                    .as_ref()
                    .map(|p| p.display().to_string())
                    .unwrap_or_else(|| d.uri.as_str().to_string());
                let Some(lang) = Lang::of(&name, &d.language_id) else {
                    return;
                };
                self.docs.insert(
                    d.uri.as_str().to_string(),
                    Doc {
                        uri: d.uri.clone(),
                        path,
                        lang,
                        version: d.version,
                        text: d.text,
                        checked: None,
                        good: None,
                        dirty: true,
                        cache: reparse::ParseCache::default(),
                    },
                );
            }
            "textDocument/didChange" => {
                let Ok(p) = serde_json::from_value::<DidChangeTextDocumentParams>(params) else {
                    return self.log("arbor: malformed didChange");
                };
                let key = p.text_document.uri.as_str().to_string();
                let Some(doc) = self.docs.get_mut(&key) else {
                    return;
                };
                for c in p.content_changes {
                    doc.text = text::apply_change(&doc.text, c.range, &c.text);
                }
                doc.version = p.text_document.version;
                doc.dirty = true;
                if doc.lang == Lang::SlHeader {
                    // Its includers see the unsaved text.
                    for d in self.docs.values_mut() {
                        if d.lang == Lang::Sl {
                            d.dirty = true;
                        }
                    }
                }
            }
            "textDocument/didSave" | "workspace/didChangeWatchedFiles" => {
                // Files on disk changed: shaders, headers and archives of every document.
                for d in self.docs.values_mut() {
                    d.dirty = true;
                }
            }
            "textDocument/didClose" => {
                let Ok(p) = serde_json::from_value::<DidCloseTextDocumentParams>(params) else {
                    return;
                };
                let key = p.text_document.uri.as_str().to_string();
                if self.docs.remove(&key).is_some() {
                    self.publish_for(&key, HashMap::new());
                }
            }
            _ => {}
        }
    }

    /// Checks every changed document and publishes its diagnostics.
    pub fn check_dirty(&mut self) {
        let keys: Vec<String> = self
            .docs
            .iter()
            .filter(|(_, d)| d.dirty)
            .map(|(k, _)| k.clone())
            .collect();
        for k in keys {
            if catch_unwind(AssertUnwindSafe(|| self.check_doc(&k))).is_err() {
                if let Some(d) = self.docs.get_mut(&k) {
                    d.dirty = false;
                }
                self.log("arbor: checking a document failed inside arbor");
            }
        }
    }

    fn overlay(&self) -> Overlay {
        self.docs
            .values()
            .filter_map(|d| Some((d.path.clone()?, Arc::<str>::from(d.text.as_str()))))
            .collect()
    }

    /// Checks one document now and publishes what it found.
    pub fn check_doc(&mut self, key: &str) {
        let overlay = self.overlay();
        let Some(doc) = self.docs.get_mut(key) else {
            return;
        };
        doc.dirty = false;
        let name = doc
            .path
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| doc.uri.as_str().to_string());
        let mut settings = self.settings.clone();
        let opts = check::compile_options(&settings);
        let resolver = OverlayResolver {
            search: crate::sl::library::SearchResolver { opts: &opts },
            overlay: &overlay,
        };
        let checked = match doc.lang {
            Lang::Sl | Lang::SlHeader => {
                if let Some(dir) = doc.path.as_ref().and_then(|p| p.parent()) {
                    // As `arbor check` run in the shader's folder would find its neighbours.
                    settings.shader_paths.push(dir.display().to_string());
                }
                check::check_sl(
                    &name,
                    &doc.text,
                    doc.path.as_deref(),
                    doc.lang,
                    &settings,
                    &overlay,
                    &mut doc.cache,
                )
            }
            Lang::Rib => check::check_rib(&name, &doc.text, doc.path.as_deref(), &settings),
        };
        let by_uri = {
            let path = doc.path.clone();
            let text = doc.text.as_str();
            let anchor = |fname: &str| -> Option<(usize, usize)> {
                match &checked.detail {
                    Detail::Sl(_) => sl::include_anchor(text, path.as_deref(), fname, &resolver),
                    Detail::Rib(r) => rib::anchor(r, fname, checked.file),
                }
            };
            check::lsp_diagnostics(&checked, &doc.uri, text, &anchor)
        };
        let parsed = sl_parsed(&checked);
        let prev = doc.checked.replace(checked);
        if parsed {
            doc.good = None;
        } else if let Some(p) = prev.filter(sl_parsed) {
            doc.good = Some(p);
        }
        let map: HashMap<String, Vec<Diagnostic>> = by_uri
            .into_iter()
            .map(|(u, d)| (u.as_str().to_string(), d))
            .collect();
        let k = key.to_string();
        self.publish_for(&k, map);
    }

    /// Replaces what document `source` published, and re-sends every file it touches.
    fn publish_for(&mut self, source: &str, now: HashMap<String, Vec<Diagnostic>>) {
        let mut touched: HashSet<String> = now.keys().cloned().collect();
        for (uri, by) in self.published.iter_mut() {
            if by.remove(source).is_some() {
                touched.insert(uri.clone());
            }
        }
        for (uri, d) in now {
            self.published
                .entry(uri)
                .or_default()
                .insert(source.to_string(), d);
        }
        let mut touched: Vec<String> = touched.into_iter().collect();
        touched.sort();
        for uri in touched {
            let mut all: Vec<Diagnostic> = Vec::new();
            if let Some(by) = self.published.get(&uri) {
                let mut sources: Vec<&String> = by.keys().collect();
                sources.sort();
                for s in sources {
                    for d in &by[s] {
                        if !all
                            .iter()
                            .any(|a| a.range == d.range && a.message == d.message)
                        {
                            all.push(d.clone());
                        }
                    }
                }
            }
            let version = self.docs.get(&uri).map(|d| d.version);
            self.notify(
                "textDocument/publishDiagnostics",
                json!({"uri": uri, "diagnostics": all, "version": version}),
            );
            if self.published.get(&uri).is_some_and(|b| b.is_empty()) {
                self.published.remove(&uri);
            }
        }
    }

    /// The document, checked if it changed since its last check.
    fn doc(&mut self, uri: &Uri) -> Option<&Doc> {
        let key = uri.as_str().to_string();
        if self.docs.get(&key)?.dirty {
            self.check_doc(&key);
        }
        self.docs.get(&key)
    }

    fn hover(&mut self, uri: &Uri, pos: Position) -> Option<Hover> {
        let doc = self.doc(uri)?;
        let offset = LineIndex::new(&doc.text).offset(&doc.text, pos);
        match doc.lang {
            Lang::Rib => rib::hover(&doc.text, offset, rib_state(doc)),
            _ => {
                let (idx, file) = sl_state(doc);
                sl::hover(&doc.text, offset, idx, file)
            }
        }
    }

    fn completion(&mut self, uri: &Uri, pos: Position) -> Option<CompletionResponse> {
        let doc = self.doc(uri)?;
        let offset = LineIndex::new(&doc.text).offset(&doc.text, pos);
        let items = match doc.lang {
            Lang::Rib => rib::completion(&doc.text, offset, rib_state(doc)),
            _ => {
                let (idx, file) = sl_state(doc);
                sl::completion(offset, idx, file)
            }
        };
        Some(CompletionResponse::Array(items))
    }

    fn definition(&mut self, uri: &Uri, pos: Position) -> Option<GotoDefinitionResponse> {
        let overlay = self.overlay();
        let opts = check::compile_options(&self.settings);
        let doc = self.doc(uri)?;
        let offset = LineIndex::new(&doc.text).offset(&doc.text, pos);
        let loc = match doc.lang {
            Lang::Rib => rib::definition(&doc.text, offset, rib_state(doc), doc.path.as_deref()),
            _ => {
                let resolver = OverlayResolver {
                    search: crate::sl::library::SearchResolver { opts: &opts },
                    overlay: &overlay,
                };
                let sources = sl_checked(doc).map(|c| &c.sources);
                let (idx, file) = sl_state(doc);
                let empty = crate::diag::SourceMap::new();
                sl::definition(
                    &doc.text,
                    offset,
                    idx,
                    file,
                    sources.unwrap_or(&empty),
                    doc.path.as_deref(),
                    &resolver,
                )
            }
        };
        loc.map(GotoDefinitionResponse::Scalar)
    }

    fn symbols(&mut self, uri: &Uri) -> Option<DocumentSymbolResponse> {
        let doc = self.doc(uri)?;
        let syms = match doc.lang {
            Lang::Rib => {
                let c = doc.checked.as_ref()?;
                let Detail::Rib(r) = &c.detail else {
                    return None;
                };
                rib::symbols(&doc.text, r, c.file)
            }
            _ => {
                let (idx, file) = sl_state(doc);
                sl::symbols(&doc.text, idx?, file)
            }
        };
        Some(DocumentSymbolResponse::Nested(syms))
    }

    fn format(&mut self, uri: &Uri) -> Result<Option<Vec<TextEdit>>, (i64, String)> {
        let Some(doc) = self.docs.get(uri.as_str()) else {
            return Ok(None);
        };
        if doc.lang != Lang::Rib {
            return Ok(None);
        }
        let sources = crate::diag::SourceMap::new();
        let diags = crate::diag::Diagnostics::new();
        let reqs = crate::rib::parse_bytes("format", doc.text.as_bytes(), &sources, &diags);
        if diags.has_errors() {
            return Err((
                REQUEST_FAILED,
                "the RIB has syntax errors: fix them before formatting".into(),
            ));
        }
        let Some(f) = sources.get(0) else {
            return Ok(None);
        };
        let formatted = crate::rib::format_source(&f.text, &reqs);
        if formatted == doc.text {
            return Ok(Some(Vec::new()));
        }
        let lines = LineIndex::new(&doc.text);
        Ok(Some(vec![TextEdit {
            range: lines.range(&doc.text, 0, doc.text.len()),
            new_text: formatted,
        }]))
    }
}

fn sl_parsed(c: &Checked) -> bool {
    matches!(&c.detail, Detail::Sl(s) if s.index.is_some())
}

/// The check a shading-language document answers from: the last one that parsed.
fn sl_checked(doc: &Doc) -> Option<&Checked> {
    match &doc.checked {
        Some(c) if sl_parsed(c) => Some(c),
        _ => doc.good.as_ref().or(doc.checked.as_ref()),
    }
}

/// The index a shading-language document answers from, and its file id.
fn sl_state(doc: &Doc) -> (Option<&index::Index>, u32) {
    match sl_checked(doc).map(|c| (&c.detail, c.file)) {
        Some((Detail::Sl(s), file)) => (s.index.as_ref(), file),
        _ => (None, 0),
    }
}

fn rib_state(doc: &Doc) -> Option<&check::RibChecked> {
    match &doc.checked.as_ref()?.detail {
        Detail::Rib(r) => Some(r),
        _ => None,
    }
}

fn parse<T: serde::de::DeserializeOwned>(params: Value) -> Result<T, (i64, String)> {
    serde_json::from_value(params).map_err(|e| (INVALID_PARAMS, format!("bad params: {e}")))
}

fn to_json<T: serde::Serialize>(v: T) -> Value {
    serde_json::to_value(v).unwrap_or(Value::Null)
}

fn capabilities() -> ServerCapabilities {
    ServerCapabilities {
        text_document_sync: Some(TextDocumentSyncCapability::Options(
            TextDocumentSyncOptions {
                open_close: Some(true),
                change: Some(TextDocumentSyncKind::INCREMENTAL),
                save: Some(TextDocumentSyncSaveOptions::Supported(true)),
                ..TextDocumentSyncOptions::default()
            },
        )),
        hover_provider: Some(HoverProviderCapability::Simple(true)),
        completion_provider: Some(CompletionOptions {
            trigger_characters: Some(vec!["\"".into()]),
            ..CompletionOptions::default()
        }),
        definition_provider: Some(OneOf::Left(true)),
        document_symbol_provider: Some(OneOf::Left(true)),
        document_formatting_provider: Some(OneOf::Left(true)),
        ..ServerCapabilities::default()
    }
}

/// What the reader thread hands the main loop.
enum Incoming {
    Body(Vec<u8>),
    /// A header that could not be read: the message is skipped.
    BadHeader(String),
}

/// Reads one framed message. Ok(None) at end of input.
fn read_message(r: &mut impl BufRead) -> std::io::Result<Option<Incoming>> {
    let mut length: Option<usize> = None;
    let mut bad: Option<String> = None;
    let mut line = Vec::new();
    loop {
        line.clear();
        if r.read_until(b'\n', &mut line)? == 0 {
            return Ok(None);
        }
        let l = String::from_utf8_lossy(&line);
        let l = l.trim_end_matches(['\r', '\n']);
        if l.is_empty() {
            if length.is_none() && bad.is_none() {
                // A stray blank line between messages.
                continue;
            }
            break;
        }
        match l.split_once(':') {
            Some((k, v)) if k.trim().eq_ignore_ascii_case("content-length") => {
                match v.trim().parse::<usize>() {
                    Ok(n) if n <= MAX_BODY => length = Some(n),
                    _ => bad = Some(format!("bad Content-Length `{}`", v.trim())),
                }
            }
            Some(_) => {}
            None => bad = Some(format!("bad header line `{l}`")),
        }
    }
    match (length, bad) {
        (Some(n), None) => {
            let mut body = vec![0; n];
            r.read_exact(&mut body)?;
            Ok(Some(Incoming::Body(body)))
        }
        (_, Some(b)) => Ok(Some(Incoming::BadHeader(b))),
        (None, None) => Ok(Some(Incoming::BadHeader("no Content-Length".into()))),
    }
}

/// Runs the server on stdin/stdout until `exit` or the end of input. Returns the exit code.
pub fn run_stdio(settings: Settings) -> i32 {
    let (tx, rx) = std::sync::mpsc::channel::<Incoming>();
    std::thread::spawn(move || {
        let stdin = std::io::stdin();
        let mut r = stdin.lock();
        while let Ok(Some(m)) = read_message(&mut r) {
            if tx.send(m).is_err() {
                break;
            }
        }
    });
    let mut server = Server::new(settings, Box::new(std::io::stdout()));
    while let Ok(first) = rx.recv() {
        let mut batch = vec![first];
        while let Ok(m) = rx.try_recv() {
            batch.push(m);
        }
        for m in batch {
            match m {
                Incoming::Body(b) => server.handle_body(&b),
                Incoming::BadHeader(e) => server.log(&format!("arbor: skipped a message: {e}")),
            }
            if let Some(code) = server.exit {
                return code;
            }
        }
        server.check_dirty();
    }
    // End of input without `exit`.
    if server.shutdown {
        0
    } else {
        1
    }
}
