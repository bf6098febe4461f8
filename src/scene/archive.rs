//! Archives: `ReadArchive` (files on the archive path or inline archives) and
//! `ArchiveBegin`/`ArchiveEnd` definitions.
//!
//! Input: an archive name and the span of the request naming it. Output: the archive's
//! requests run in place, with the current graphics state.
//! Invariants: the search order is the CLI's archive paths, `Option "searchpath" "archive"`,
//! the including file's folder, then the main scene's folder; an archive that (indirectly)
//! reads itself is an error naming the chain, and is not read again.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::diag::{Diag, Span};
use crate::rib::{Request, Value};

use super::builder::Builder;
use super::table::Call;

/// An `ArchiveBegin` block being read: its requests so far.
#[derive(Debug)]
pub(super) struct Recording {
    name: String,
    open: Span,
    /// `ArchiveBegin`s nested inside it and not yet closed.
    depth: usize,
    reqs: Vec<Request>,
}

impl Builder<'_> {
    /// `open` is `ArchiveBegin`: the requests up to the matching `ArchiveEnd` are recorded
    /// (see [`Builder::feed`]) and stored under the archive's name.
    pub(super) fn begin_archive(&mut self, open: &Request) {
        let name = match open.args.first().map(|a| &a.value) {
            Some(Value::Str(s)) => s.clone(),
            _ => {
                let d = Diag::error("scene::arguments", "`ArchiveBegin` needs an archive name")
                    .label(open.span, "no name")
                    .help("`ArchiveBegin \"name\"` … `ArchiveEnd`, then `ReadArchive \"name\"`");
                self.report(d);
                String::new()
            }
        };
        self.recording = Some(Recording {
            name,
            open: open.span,
            depth: 0,
            reqs: Vec::new(),
        });
    }

    /// Records `r` into the archive being defined; false when no archive is being defined.
    pub(super) fn record(&mut self, r: &Request) -> bool {
        let Some(rec) = self.recording.as_mut() else {
            return false;
        };
        match r.name.as_str() {
            "ArchiveBegin" => rec.depth += 1,
            "ArchiveEnd" if rec.depth == 0 => {
                if let Some(rec) = self.recording.take() {
                    self.store_archive(rec);
                }
                return true;
            }
            "ArchiveEnd" => rec.depth -= 1,
            _ => {}
        }
        rec.reqs.push(r.clone());
        true
    }

    /// The input ended inside `ArchiveBegin`: reports it and keeps what was recorded.
    pub(super) fn close_recording(&mut self) {
        if let Some(rec) = self.recording.take() {
            let d = Diag::error(
                "scene::nesting",
                "`ArchiveBegin` is never closed by `ArchiveEnd`",
            )
            .label(rec.open, "opened here")
            .help("add `ArchiveEnd` after the archive's requests");
            self.report(d);
            self.store_archive(rec);
        }
    }

    fn store_archive(&mut self, rec: Recording) {
        if !rec.name.is_empty() {
            self.archives.insert(rec.name, Arc::new(rec.reqs));
        }
    }

    pub(super) fn archive_end_alone(&mut self, call: &Call<'_>) {
        let d = Diag::error("scene::nesting", "`ArchiveEnd` without `ArchiveBegin`")
            .label(call.span(), "nothing to close")
            .help("remove it, or add `ArchiveBegin \"name\"` before the archive's requests");
        self.report(d);
    }

    pub(super) fn read_archive(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str().to_string();
        self.read_archive_named(&name, call.pos_spans[0], call.span());
    }

    /// Where a file archive is found, with the folders that were searched.
    fn find_archive(&self, name: &str, from: Span) -> (Option<PathBuf>, Vec<String>) {
        let p = Path::new(name);
        if p.is_absolute() && p.is_file() {
            return (Some(p.to_path_buf()), vec![]);
        }
        if crate::foreign_path::looks_absolute(name) {
            // A path on the author's machine: the package's copy beside the scene.
            let mut bases = Vec::new();
            if let Some(f) = self.ctx.sources.get(from.file) {
                if let Some(d) = Path::new(&f.name).parent() {
                    bases.push(d.to_path_buf());
                }
            }
            if let Some(b) = &self.ctx.base_dir {
                bases.push(b.clone());
            }
            let found = crate::foreign_path::rebase(name, &bases);
            let searched = bases.iter().map(|d| d.display().to_string()).collect();
            return (found, searched);
        }
        let mut dirs: Vec<PathBuf> = Vec::new();
        dirs.extend(self.ctx.archive_paths.iter().map(PathBuf::from));
        dirs.extend(self.option_paths.archive.iter().map(PathBuf::from));
        if let Some(f) = self.ctx.sources.get(from.file) {
            let parent = Path::new(&f.name).parent().map(Path::to_path_buf);
            dirs.push(match parent {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => PathBuf::from("."),
            });
        }
        if let Some(b) = &self.ctx.base_dir {
            dirs.push(b.clone());
        }
        // Each folder once (the scene's folder is often also the base: "searched: ., .").
        let mut seen = std::collections::HashSet::new();
        dirs.retain(|d| seen.insert(d.clone()));
        let searched = dirs.iter().map(|d| d.display().to_string()).collect();
        // Exact names first; then one differing only in case (a scene written on a file system
        // that ignores case, where its `ReadArchive "Cube.rib"` found `cube.rib`).
        let found = dirs
            .iter()
            .map(|d| d.join(name))
            .find(|c| c.is_file())
            .or_else(|| {
                dirs.iter()
                    .find_map(|d| crate::pathcase::find_file_ignoring_case(&d.join(name)))
            });
        (found, searched)
    }

    pub(super) fn read_archive_named(&mut self, name: &str, arg_span: Span, req_span: Span) {
        if let Some(reqs) = self.archives.get(name).cloned() {
            let key = format!("inline archive \"{name}\"");
            if self.enter_archive(&key, req_span) {
                self.run(&reqs);
                self.include.pop();
            }
            return;
        }
        let (found, searched) = self.find_archive(name, req_span);
        let Some(path) = found else {
            let mut d = Diag::error("scene::archive", format!("cannot find archive \"{name}\""))
                .label(arg_span, "not found");
            d = if searched.is_empty() {
                d.help("check the path")
            } else if crate::foreign_path::looks_absolute(name) {
                d.help(format!(
                    "an absolute path: looked for its last folders under {} and their parents",
                    searched.join(", ")
                ))
            } else {
                d.help(format!(
                    "searched: {} (add a folder with `Option \"searchpath\" \"archive\"` or --archives)",
                    searched.join(", ")
                ))
            };
            return self.report(d);
        };
        if crate::foreign_path::looks_absolute(name) && !Path::new(name).is_file() {
            let d = Diag::warning(
                "scene::archive",
                format!(
                    "archive \"{name}\" is not on this machine; reading \"{}\"",
                    path.display()
                ),
            )
            .label(arg_span, "absolute path from another machine")
            .help("the scene's own copy, found by the path's last folders beside the scene");
            self.report(d);
        }
        let key = std::fs::canonicalize(&path)
            .unwrap_or_else(|_| path.clone())
            .display()
            .to_string();
        if !self.enter_archive(&key, req_span) {
            return;
        }
        match crate::rib::read_path(&path, self.ctx.sources, self.ctx.diags) {
            Ok(reqs) => self.run(&reqs),
            Err(d) => {
                let d = d.label(arg_span, "while reading this archive");
                self.report(d);
            }
        }
        self.include.pop();
    }

    /// Pushes `key` on the include chain, or reports the cycle it would close.
    fn enter_archive(&mut self, key: &str, span: Span) -> bool {
        if let Some(i) = self.include.iter().position(|k| k == key) {
            let chain = self.include[i..]
                .iter()
                .map(String::as_str)
                .chain(std::iter::once(key))
                .collect::<Vec<_>>()
                .join(" → ");
            let d = Diag::error(
                "scene::archive-cycle",
                format!("`ReadArchive` cycle: {chain}"),
            )
            .label(span, "reads an archive that is already being read")
            .help("an archive must not (indirectly) read itself");
            self.report(d);
            return false;
        }
        if self.include.len() >= 64 {
            let d = Diag::error("scene::archive", "archives nested more than 64 deep")
                .label(span, "here");
            self.report(d);
            return false;
        }
        self.include.push(key.to_string());
        true
    }
}
