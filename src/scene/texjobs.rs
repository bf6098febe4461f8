//! The texture-making requests (RISpec §8): MakeTexture, MakeBump (RISpec 3.0/3.1; 3.2
//! dropped it), MakeLatLongEnvironment, MakeCubeFaceEnvironment and MakeShadow, and arbor's
//! MakeHorizon (Max horizon tables).
//!
//! Input: a checked [`Call`]. Output: a [`TextureJob`] recorded on the scene of the next (or
//! current) world block; the pipeline runs the jobs before rendering that frame, so a
//! shadow pass's zfile written by an earlier frame is there when MakeShadow runs.
//! Invariants: nothing is read or written here; bad files are reported when the job runs.

use crate::diag::Diag;

use super::builder::Builder;
use super::params::ParamUse;
use super::table::Call;
use super::types::*;

impl Builder<'_> {
    fn record_job(&mut self, call: &Call<'_>, job: TextureJob) {
        let params = self.params(call, ParamUse::Shader);
        if !params.0.is_empty() {
            self.report(
                Diag::warning(
                    "scene::texture-param",
                    format!(
                        "`{}` takes no extra parameters in arbor; they are ignored",
                        call.name()
                    ),
                )
                .label(call.span(), "here"),
            );
        }
        match self.world.as_mut() {
            Some(w) => w.texture_jobs.push(job),
            None => self.pending_texture_jobs.push(job),
        }
    }

    fn job(
        call: &Call<'_>,
        kind: TextureJobKind,
        inputs: Vec<String>,
        output: usize,
    ) -> TextureJob {
        TextureJob {
            kind,
            inputs,
            output: call.pos[output].str().to_string(),
            swrap: String::new(),
            twrap: String::new(),
            filter: String::new(),
            swidth: 1.0,
            twidth: 1.0,
            fov: 90.0,
            directions: 8,
            span: call.full_span(),
        }
    }

    pub(super) fn make_texture(&mut self, call: &Call<'_>) {
        self.make_plain(call, TextureJobKind::Texture);
    }

    pub(super) fn make_bump(&mut self, call: &Call<'_>) {
        self.make_plain(call, TextureJobKind::Bump);
    }

    /// MakeTexture and MakeBump share their arguments:
    /// `picturename texturename swrap twrap filter swidth twidth`.
    fn make_plain(&mut self, call: &Call<'_>, kind: TextureJobKind) {
        let mut j = Self::job(call, kind, vec![call.pos[0].str().to_string()], 1);
        j.swrap = call.pos[2].str().to_string();
        j.twrap = call.pos[3].str().to_string();
        j.filter = call.pos[4].str().to_string();
        j.swidth = call.pos[5].num();
        j.twidth = call.pos[6].num();
        self.record_job(call, j);
    }

    pub(super) fn make_latlong(&mut self, call: &Call<'_>) {
        let mut j = Self::job(
            call,
            TextureJobKind::LatLongEnvironment,
            vec![call.pos[0].str().to_string()],
            1,
        );
        j.filter = call.pos[2].str().to_string();
        j.swidth = call.pos[3].num();
        j.twidth = call.pos[4].num();
        self.record_job(call, j);
    }

    pub(super) fn make_cube(&mut self, call: &Call<'_>) {
        let inputs = (0..6).map(|i| call.pos[i].str().to_string()).collect();
        let mut j = Self::job(call, TextureJobKind::CubeFaceEnvironment, inputs, 6);
        j.fov = call.pos[7].num();
        j.filter = call.pos[8].str().to_string();
        j.swidth = call.pos[9].num();
        j.twidth = call.pos[10].num();
        self.record_job(call, j);
    }

    /// `MakeHorizon picturename horizonname swrap twrap ["directions" n]` (arbor extension):
    /// the picture's luminance is the height map; tables are periodic in s and t.
    pub(super) fn make_horizon(&mut self, call: &Call<'_>) {
        let mut j = Self::job(
            call,
            TextureJobKind::Horizon,
            vec![call.pos[0].str().to_string()],
            1,
        );
        for (i, axis) in [(2, "s"), (3, "t")] {
            let w = call.pos[i].str();
            if w != "periodic" {
                self.report(
                    Diag::warning(
                        "scene::horizon-wrap",
                        format!("`MakeHorizon`: {axis} wrap \"{w}\" is not supported; horizon tables are periodic"),
                    )
                    .label(call.pos_spans[i], "used as \"periodic\"")
                    .help("horizon maps tile: give \"periodic\" \"periodic\" and a height map that tiles"),
                );
            }
        }
        j.swrap = "periodic".into();
        j.twrap = "periodic".into();
        let params = self.params(call, ParamUse::Shader);
        for p in params.iter() {
            if p.name != "directions" {
                self.report(
                    Diag::warning(
                        "scene::texture-param",
                        format!(
                            "`MakeHorizon` takes only \"directions\"; \"{}\" is ignored",
                            p.name
                        ),
                    )
                    .label(p.span, "ignored"),
                );
            }
        }
        if let Some(d) = params.float("directions") {
            if d == 8.0 || d == 16.0 {
                j.directions = d as usize;
            } else {
                self.report(
                    Diag::warning(
                        "scene::horizon-directions",
                        format!("`MakeHorizon`: {d} directions are not supported; using 8"),
                    )
                    .label(call.span(), "here")
                    .help(
                        "\"directions\" is 8 (rows, columns, diagonals) or 16 (plus knight steps)",
                    ),
                );
            }
        }
        match self.world.as_mut() {
            Some(w) => w.texture_jobs.push(j),
            None => self.pending_texture_jobs.push(j),
        }
    }

    pub(super) fn make_shadow(&mut self, call: &Call<'_>) {
        let j = Self::job(
            call,
            TextureJobKind::Shadow,
            vec![call.pos[0].str().to_string()],
            1,
        );
        self.record_job(call, j);
    }
}
