//! Option requests (RISpec §4.1): camera, display and renderer options, `Option` itself and
//! the search paths.
//!
//! Input: checked [`Call`]s. Output: changes to the builder's current [`Options`] (copied into
//! each scene at `WorldBegin`).
//! Invariants: options are frozen inside the world block (a warning says the request has no
//! effect there); FrameAspectRatio and ScreenWindow stay `None` unless given, so they follow
//! Format as the spec says.

use glam::Vec3;

use crate::diag::Diag;

use super::builder::Builder;
use super::params::{validate_single, ColorMap, ParamUse};
use super::table::Call;
use super::types::*;

/// The filter names the film knows (one list, so a name the builder accepts is never
/// unknown to the film).
const FILTERS: &[&str] = &crate::film::filter::FILTER_NAMES;

impl Builder<'_> {
    /// False (with a warning) inside the world block, where options are frozen.
    fn option_allowed(&mut self, call: &Call<'_>) -> bool {
        if self.world.is_none() {
            return true;
        }
        let d = Diag::warning(
            "scene::option-in-world",
            format!(
                "`{}` inside `WorldBegin`…`WorldEnd` has no effect: options are frozen at `WorldBegin`",
                call.name()
            ),
        )
        .label(call.span(), "ignored")
        .help("move it before `WorldBegin`");
        self.report(d);
        false
    }

    fn bad_arg(&mut self, call: &Call<'_>, i: usize, msg: String, help: &str) {
        let d = Diag::error("scene::arguments", format!("`{}`: {msg}", call.name()))
            .label(call.pos_spans[i], "here")
            .help(help.to_string());
        self.report(d);
    }

    pub(super) fn format(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let (x, y, a) = (call.pos[0].num(), call.pos[1].num(), call.pos[2].num());
        // RISpec §4.1.1: a negative value asks for the device default.
        let d = Options::default();
        let x = if x < 0.0 { d.xres as f32 } else { x };
        let y = if y < 0.0 { d.yres as f32 } else { y };
        if x < 1.0 || y < 1.0 || x.fract() != 0.0 || y.fract() != 0.0 {
            self.bad_arg(
                call,
                if x < 1.0 || x.fract() != 0.0 { 0 } else { 1 },
                format!("resolution {x}×{y} must be whole numbers of at least 1"),
                "e.g. `Format 640 480 1` (-1 asks for the default)",
            );
            return;
        }
        self.options.xres = x as u32;
        self.options.yres = y as u32;
        // 0 or negative: the device default (square pixels).
        self.options.pixel_aspect = if a > 0.0 { a } else { d.pixel_aspect };
    }

    pub(super) fn frame_aspect_ratio(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let r = call.pos[0].num();
        if r <= 0.0 {
            self.bad_arg(call, 0, format!("ratio {r} must be positive"), "e.g. 1.333");
            return;
        }
        self.options.frame_aspect = Some(r);
    }

    pub(super) fn screen_window(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let w = [0, 1, 2, 3].map(|i| call.pos[i].num());
        if w[0] == w[1] || w[2] == w[3] {
            self.bad_arg(
                call,
                0,
                "the window has no area".into(),
                "left must differ from right and bottom from top",
            );
            return;
        }
        self.options.screen_window = Some(w);
    }

    pub(super) fn crop_window(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let w = [0, 1, 2, 3].map(|i| call.pos[i].num().clamp(0.0, 1.0));
        if w[0] == w[1] || w[2] == w[3] {
            // Zero width or height (Aqsis's regression scene Bug1266044, where Aqsis crashed):
            // a degenerate request rather than a reversed one, so the frame renders uncropped.
            self.report(
                Diag::warning(
                    "scene::crop-window",
                    "`CropWindow` has zero width or height; it is ignored and the whole frame is rendered",
                )
                .label(call.span(), "here")
                .help("xmin < xmax and ymin < ymax, all within [0, 1]"),
            );
            return;
        }
        if w[0] > w[1] || w[2] > w[3] {
            self.bad_arg(
                call,
                0,
                "the crop window is empty".into(),
                "xmin < xmax and ymin < ymax, all within [0, 1]",
            );
            return;
        }
        self.options.crop_window = w;
    }

    pub(super) fn projection(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let mut params = self.params(call, ParamUse::Shader);
        let mut ds = Vec::new();
        validate_single(&mut params, call.name(), &mut |d| ds.push(d));
        for d in ds {
            self.report(d);
        }
        match call.pos[0].str() {
            "perspective" => {
                let fov = params.float("fov").unwrap_or(90.0);
                if !(fov > 0.0 && fov < 180.0) {
                    self.bad_arg(
                        call,
                        0,
                        format!("field of view {fov} must be between 0 and 180 degrees"),
                        "e.g. Projection \"perspective\" \"fov\" [40]",
                    );
                    return;
                }
                self.options.projection = Projection::Perspective { fov };
            }
            "orthographic" => self.options.projection = Projection::Orthographic,
            "null" => {}
            other => {
                let d = Diag::warning(
                    "scene::unimplemented",
                    format!("`Projection \"{other}\"` is not implemented; using orthographic"),
                )
                .label(call.pos_spans[0], "unknown projection")
                .help("arbor knows \"perspective\" and \"orthographic\"");
                self.report(d);
                self.options.projection = Projection::Orthographic;
            }
        }
    }

    pub(super) fn clipping(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let (n, f) = (call.pos[0].num(), call.pos[1].num());
        if !(n > 0.0) || !(f > n) {
            self.bad_arg(
                call,
                0,
                format!("near {n} and far {f} need 0 < near < far"),
                "e.g. `Clipping 0.1 1000`",
            );
            return;
        }
        self.options.near = n.max(f32::EPSILON);
        self.options.far = f;
    }

    pub(super) fn clipping_plane(&mut self, call: &Call<'_>) {
        let p = Vec3::new(call.pos[0].num(), call.pos[1].num(), call.pos[2].num());
        let n = Vec3::new(call.pos[3].num(), call.pos[4].num(), call.pos[5].num());
        if n.length_squared() == 0.0 {
            self.bad_arg(
                call,
                3,
                "the normal is zero".into(),
                "give a nonzero normal",
            );
            return;
        }
        let m = self.camera_from_current();
        let pc = m.transform_point3(p);
        let nc = m
            .inverse()
            .transpose()
            .transform_vector3(n)
            .normalize_or_zero();
        match self.world.as_mut() {
            // Inside the world (an extension): straight to world space.
            Some(scene) => {
                let wfc = scene.camera_from_world.inverse();
                let nw = scene
                    .camera_from_world
                    .transpose()
                    .transform_vector3(nc)
                    .normalize_or_zero();
                scene
                    .options
                    .clipping_planes
                    .push((wfc.transform_point3(pc), nw));
            }
            None => self.clip_camera.push((pc, nc)),
        }
    }

    pub(super) fn depth_of_field(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        if call.pos[0].is_absent() || call.pos[0].num().is_infinite() {
            self.options.depth_of_field = None;
            return;
        }
        if call.pos.iter().any(|p| p.is_absent()) {
            self.bad_arg(
                call,
                0,
                "needs all three of fstop, focallength, focaldistance (or none)".into(),
                "e.g. `DepthOfField 22 45 1200`",
            );
            return;
        }
        let v = [call.pos[0].num(), call.pos[1].num(), call.pos[2].num()];
        if v.iter().any(|&x| x <= 0.0) {
            self.bad_arg(
                call,
                0,
                "values must be positive".into(),
                "fstop focallength focaldistance > 0",
            );
            return;
        }
        self.options.depth_of_field = Some(v);
    }

    pub(super) fn shutter(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let (a, b) = (call.pos[0].num(), call.pos[1].num());
        if b < a {
            self.bad_arg(
                call,
                1,
                format!("close time {b} is before open time {a}"),
                "open <= close",
            );
            return;
        }
        self.options.shutter = [a, b];
    }

    pub(super) fn pixel_variance(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let v = call.pos[0].num();
        if v < 0.0 {
            self.bad_arg(call, 0, format!("variance {v} is negative"), "a value >= 0");
            return;
        }
        self.options.pixel_variance = Some(v);
    }

    pub(super) fn pixel_samples(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        // RISpec: values below 1 are clamped to 1.
        self.options.pixel_samples = [call.pos[0].num().max(1.0), call.pos[1].num().max(1.0)];
    }

    pub(super) fn pixel_filter(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let name = call.pos[0].str();
        let canonical = match name {
            "catmullrom" | "catmull_rom" => "catmull-rom",
            "blackmanharris" => "blackman-harris",
            "separablecatmullrom" => "separable-catmull-rom",
            n => n,
        };
        if !FILTERS.contains(&canonical) {
            let mut d = Diag::error(
                "scene::arguments",
                format!("unknown pixel filter \"{name}\""),
            )
            .label(call.pos_spans[0], "not a filter");
            d = match crate::diag::did_you_mean(name, FILTERS.iter().copied()) {
                Some(m) => d.help(format!("did you mean \"{m}\"?")),
                None => d.help(format!("filters: {}", FILTERS.join(", "))),
            };
            self.report(d);
            return;
        }
        let (xw, yw) = (call.pos[1].num(), call.pos[2].num());
        if xw <= 0.0 || yw <= 0.0 {
            self.bad_arg(call, 1, "filter widths must be positive".into(), "e.g. 2 2");
            return;
        }
        self.options.pixel_filter = PixelFilter {
            name: canonical.to_string(),
            xwidth: xw,
            ywidth: yw,
        };
    }

    pub(super) fn exposure(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let g = call.pos[1].num();
        if g <= 0.0 {
            self.bad_arg(
                call,
                1,
                format!("gamma {g} must be positive"),
                "e.g. `Exposure 1 2.2`",
            );
            return;
        }
        self.options.exposure = [call.pos[0].num(), g];
    }

    pub(super) fn imager(&mut self, call: &Call<'_>) {
        if self.world.is_some() {
            self.imager_in_world(call);
            return;
        }
        let mut s = self.shader_ref(call);
        // Before WorldBegin: keep camera_from_shader; world_begin makes it world_from_shader.
        s.world_from_shader = self.camera_from_current();
        self.options.imager = if s.name == "null" { None } else { Some(s) };
    }

    /// `Imager` inside the world block sets this frame's imager. RISpec makes it an option,
    /// but the imager runs only after the world is hidden, so nothing frozen is changed, and
    /// Pixar's Blobby application-note scenes (shipped with Aqsis) write
    /// `WorldBegin Imager "background" "color" [1 1 1]`: PRMan and Aqsis honour it.
    fn imager_in_world(&mut self, call: &Call<'_>) {
        let mut s = self.shader_ref(call);
        s.world_from_shader = self.world_from_current();
        self.report(
            Diag::note(
                "scene::imager-in-world",
                "`Imager` inside the world block applies to this frame only",
            )
            .label(call.span(), "here"),
        );
        if let Some(scene) = self.world.as_mut() {
            scene.options.imager = if s.name == "null" { None } else { Some(s) };
        }
    }

    pub(super) fn quantize(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let q = Quantize {
            zero: 0.0,
            one: call.pos[1].num(),
            min: call.pos[2].num(),
            max: call.pos[3].num(),
            dither: call.pos[4].num(),
        };
        if q.min > q.max {
            self.bad_arg(
                call,
                2,
                format!("min {} is above max {}", q.min, q.max),
                "min <= max",
            );
            return;
        }
        match call.pos[0].str() {
            "rgba" => self.options.quantize_rgba = q,
            "z" => self.options.quantize_z = q,
            "" => self.bad_arg(
                call,
                0,
                "empty quantizer name".into(),
                "use \"rgba\", \"z\" or a display variable's name",
            ),
            other => {
                let named = &mut self.options.quantize_named;
                named.retain(|(n, _)| n != other);
                named.push((other.to_string(), q));
            }
        }
    }

    pub(super) fn display(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let mut params = self.params(call, ParamUse::Shader);
        let mut ds = Vec::new();
        validate_single(&mut params, call.name(), &mut |d| ds.push(d));
        for d in ds {
            self.report(d);
        }
        let raw = call.pos[0].str();
        let (extra, name) = match raw.strip_prefix('+') {
            Some(n) => (true, n),
            None => (false, raw),
        };
        let d = Display {
            name: name.to_string(),
            kind: call.pos[1].str().to_string(),
            mode: call.pos[2].str().to_string(),
            params,
            span: call.full_span(),
        };
        if d.mode.is_empty() {
            self.bad_arg(
                call,
                2,
                "the mode is empty".into(),
                "e.g. \"rgb\", \"rgba\" or \"z\"",
            );
            return;
        }
        // A name without `+` replaces the display list (RISpec §4.1.3).
        if !extra {
            self.options.displays.clear();
        }
        self.options.displays.push(d);
    }

    pub(super) fn hider(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let params = self.params(call, ParamUse::Shader);
        // Pixie's default hider "stochastic" is the same stochastic Z-buffer as "hidden"
        // (Pixie reads either name so).
        let name = match call.pos[0].str() {
            "stochastic" => "hidden",
            n => n,
        };
        if !matches!(name, "hidden" | "null" | "abuffer" | "zbuffer") {
            let d = Diag::warning(
                "scene::unimplemented",
                format!("`Hider \"{name}\"` is not implemented; using \"hidden\""),
            )
            .label(call.pos_spans[0], "unknown hider")
            .help("arbor has \"hidden\" (Z-buffer), \"abuffer\" and \"null\"");
            self.report(d);
            self.options.hider = Hider {
                name: "hidden".into(),
                params,
            };
            return;
        }
        self.options.hider = Hider {
            name: name.to_string(),
            params,
        };
    }

    pub(super) fn color_samples(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let n_rgb = call.pos[0].floats().to_vec();
        let rgb_n = call.pos[1].floats();
        if n_rgb.is_empty() || n_rgb.len() % 3 != 0 || rgb_n.len() != n_rgb.len() {
            self.bad_arg(
                call,
                0,
                format!(
                    "nRGB has {} numbers and RGBn {}; both need 3·n",
                    n_rgb.len(),
                    rgb_n.len()
                ),
                "`ColorSamples [nRGB (n×3)] [RGBn (3×n)]`",
            );
            return;
        }
        let n = n_rgb.len() / 3;
        let identity = n == 3 && n_rgb == [1., 0., 0., 0., 1., 0., 0., 0., 1.];
        self.colors = if identity {
            None
        } else {
            Some(ColorMap { n, n_rgb })
        };
    }

    pub(super) fn relative_detail(&mut self, call: &Call<'_>) {
        if !self.option_allowed(call) {
            return;
        }
        let r = call.pos[0].num();
        if r <= 0.0 {
            self.bad_arg(call, 0, format!("{r} must be positive"), "e.g. 1");
            return;
        }
        self.options.relative_detail = r;
    }

    pub(super) fn option(&mut self, call: &Call<'_>) {
        let cat = call.pos[0].str().to_string();
        let params = self.params(call, ParamUse::Category(&cat));
        for p in params.0 {
            self.note_if_ignored("Option", &cat, &p);
            if cat == "searchpath" {
                self.set_search_path(&p);
                continue;
            }
            if self.world.is_some() {
                let d = Diag::warning(
                    "scene::option-in-world",
                    format!("`Option \"{cat}\"` inside `WorldBegin`…`WorldEnd` has no effect"),
                )
                .label(p.span, "ignored")
                .help("move it before `WorldBegin`");
                self.report(d);
                continue;
            }
            self.options.user.insert(format!("{cat}:{}", p.name), p);
        }
    }

    /// Option "searchpath" "<kind>" "a:b:&:@": `&` is the previous value, `@` the default.
    fn set_search_path(&mut self, p: &Param) {
        let Some(value) = p.data.strings().first() else {
            return;
        };
        let default = vec![self
            .ctx
            .base_dir
            .as_ref()
            .map(|d| d.display().to_string())
            .unwrap_or_else(|| ".".into())];
        let slot = match &*p.name {
            "shader" => &mut self.option_paths.shader,
            "texture" => &mut self.option_paths.texture,
            "archive" => &mut self.option_paths.archive,
            "procedural" => &mut self.option_paths.procedural,
            _ => {
                // display, resource, …: kept as a user option.
                self.options
                    .user
                    .insert(format!("searchpath:{}", p.name), p.clone());
                return;
            }
        };
        let previous = std::mem::take(slot);
        let mut out = Vec::new();
        let mut unset = Vec::new();
        for part in split_path(value) {
            match part {
                "&" => out.extend(previous.iter().cloned()),
                "@" => out.extend(default.iter().cloned()),
                "" => {}
                s => match expand_env(s, |v| std::env::var(v).ok()) {
                    Ok(e) => out.push(e),
                    Err(v) => unset.push(v),
                },
            }
        }
        *slot = out;
        if !unset.is_empty() {
            let d = Diag::warning(
                "scene::searchpath-env",
                format!(
                    "search path entries naming unset environment variables are skipped: {}",
                    unset.join(", ")
                ),
            )
            .label(p.span, "in this search path")
            .help("set the variables before rendering, or give the directories");
            self.report(d);
        }
        if let Some(scene) = self.world.as_mut() {
            let cli = |c: &Vec<String>, o: &Vec<String>| c.iter().chain(o).cloned().collect();
            scene.options.search_paths = SearchPaths {
                shader: cli(&self.ctx.shader_paths, &self.option_paths.shader),
                texture: cli(&self.ctx.texture_paths, &self.option_paths.texture),
                archive: cli(&self.ctx.archive_paths, &self.option_paths.archive),
                procedural: self.option_paths.procedural.clone(),
            };
        }
    }
}

/// Expands `$NAME` and `${NAME}` in a search path entry (PRMan, 3Delight and Aqsis scenes
/// write `${RMANTREE}/lib/shaders` and the like); `Err(NAME)` when a named variable is unset
/// (the entry is then skipped). `$` followed by anything else stays as it is.
pub fn expand_env(s: &str, var: impl Fn(&str) -> Option<String>) -> Result<String, String> {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('$') {
        out.push_str(&rest[..i]);
        let after = &rest[i + 1..];
        let (name, tail) = if let Some(body) = after.strip_prefix('{') {
            match body.find('}') {
                Some(j) => (&body[..j], &body[j + 1..]),
                None => ("", after),
            }
        } else {
            let n = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            (&after[..n], &after[n..])
        };
        if name.is_empty() {
            out.push('$');
            rest = after;
            continue;
        }
        match var(name) {
            Some(v) => out.push_str(&v),
            None => return Err(name.to_string()),
        }
        rest = tail;
    }
    out.push_str(rest);
    Ok(out)
}

/// Splits a colon-separated path, keeping Windows drive letters (`C:\x`) whole.
pub fn split_path(s: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut start = 0;
    let b = s.as_bytes();
    for i in 0..b.len() {
        if b[i] == b':' {
            let piece = &s[start..i];
            let drive = piece.len() == 1
                && piece.as_bytes()[0].is_ascii_alphabetic()
                && matches!(b.get(i + 1), Some(b'\\') | Some(b'/'));
            if drive {
                continue;
            }
            out.push(piece);
            start = i + 1;
        }
    }
    out.push(&s[start..]);
    out
}

#[cfg(test)]
mod tests {
    use super::{expand_env, split_path};

    #[test]
    fn paths_split_on_colons() {
        assert_eq!(split_path("a:b:&:@"), vec!["a", "b", "&", "@"]);
    }

    #[test]
    fn search_path_entries_expand_environment_variables() {
        let var = |n: &str| (n == "RMANTREE").then(|| "/opt/pixar".to_string());
        assert_eq!(
            expand_env("${RMANTREE}/lib/shaders", var),
            Ok("/opt/pixar/lib/shaders".into())
        );
        assert_eq!(
            expand_env("$RMANTREE/lib", var),
            Ok("/opt/pixar/lib".into())
        );
        assert_eq!(expand_env("plain/dir", var), Ok("plain/dir".into()));
        assert_eq!(expand_env("a$/b", var), Ok("a$/b".into()));
        assert_eq!(expand_env("a${x", var), Ok("a${x".into()));
        assert_eq!(expand_env("${HOME}/x", var), Err("HOME".into()));
        assert_eq!(split_path("C:\\x:/y"), vec!["C:\\x", "/y"]);
        assert_eq!(split_path(""), vec![""]);
    }
}
