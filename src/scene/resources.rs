//! PRMan's `Resource` requests (RenderMan Pro Server 15+): named copies of the attribute
//! state, saved with `Resource "name" "attributes" "string operation" "save"` and put back
//! with `… "restore"`, independent of the attribute stack; `ResourceBegin`/`ResourceEnd`
//! scope the names made inside them. Input: the checked call; output: the builder's
//! current attributes. Invariant: the transform is never restored (it places the object
//! being described, not its look), so a restore inside a transformed block keeps it.

use std::sync::Arc;

use crate::diag::Diag;

use super::builder::Builder;
use super::params::ParamUse;
use super::table::Call;
use super::types::*;

/// A saved attribute state.
#[derive(Clone, Debug)]
pub(super) struct SavedAttributes {
    attrs: Arc<Attributes>,
    trim: Option<Arc<TrimCurves>>,
}

impl Builder<'_> {
    pub(super) fn resource(&mut self, call: &Call<'_>) {
        let name = call.pos[0].str().to_string();
        let kind = call.pos[1].str();
        let params = self.params(call, ParamUse::Shader);
        if kind != "attributes" {
            // "archive" and other kinds hold renderer data arbor has no use for.
            self.report(
                Diag::warning(
                    "scene::unimplemented",
                    format!("`Resource` of type \"{kind}\" is not implemented; ignored"),
                )
                .label(call.pos_spans[1], "resource type")
                .help("arbor implements \"attributes\" resources (save and restore)"),
            );
            return;
        }
        let op = params.string("operation").unwrap_or("").to_string();
        match op.as_str() {
            "save" => {
                let saved = SavedAttributes {
                    attrs: self.gs.attrs.clone(),
                    trim: self.gs.trim.clone(),
                };
                if let Some(scope) = self.resource_scopes.last_mut() {
                    scope.insert(name, saved);
                }
            }
            "restore" => {
                let found = self
                    .resource_scopes
                    .iter()
                    .rev()
                    .find_map(|s| s.get(&name))
                    .cloned();
                let Some(saved) = found else {
                    self.report(
                        Diag::warning(
                            "scene::handle",
                            format!("`Resource`: no attributes were saved as \"{name}\"; nothing restored"),
                        )
                        .label(call.pos_spans[0], "unknown resource")
                        .help("save it first with \"string operation\" \"save\""),
                    );
                    return;
                };
                // PRMan restores parts of the state by "subset" ("shading", "geometry" …);
                // arbor restores the whole attribute state and says so.
                if let Some(subset) = params.string("subset").filter(|s| *s != "all") {
                    self.report(
                        Diag::warning(
                            "scene::resource",
                            format!(
                                "`Resource` restore subset \"{subset}\": arbor restores every attribute"
                            ),
                        )
                        .label(call.span(), "whole attribute state restored")
                        .help("the transform is kept; shading, geometry and visibility attributes all come back"),
                    );
                }
                self.gs.attrs = saved.attrs;
                self.gs.trim = saved.trim;
            }
            other => self.report(
                Diag::warning(
                    "scene::arguments",
                    format!(
                        "`Resource` operation \"{other}\" is not \"save\" or \"restore\"; ignored"
                    ),
                )
                .label(call.span(), "here")
                .help("write \"string operation\" \"save\" or \"restore\""),
            ),
        }
    }

    pub(super) fn resource_begin(&mut self, _call: &Call<'_>) {
        self.resource_scopes.push(Default::default());
    }

    pub(super) fn resource_end(&mut self, call: &Call<'_>) {
        // The first scope is the file's own, outside every block.
        if self.resource_scopes.len() > 1 {
            self.resource_scopes.pop();
        } else {
            self.report(
                Diag::warning(
                    "scene::nesting",
                    "`ResourceEnd` without `ResourceBegin`; ignored",
                )
                .label(call.span(), "nothing to close"),
            );
        }
    }
}
