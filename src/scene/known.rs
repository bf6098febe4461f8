//! Renderer-specific `Option` and `Attribute` names that scenes written for PRMan, BMRT,
//! Aqsis, Pixie and 3Delight commonly carry, with their types, and whether arbor acts on them.
//!
//! Input: a "category:name" key. Output: its declaration (so the value is read with the right
//! type and never warned about as undeclared) and its [`Use`].
//! Invariants: every key is "category:name" with a valid declaration (checked by a test);
//! a [`Use::Ignored`] setting is stored (shaders can still read it with `attribute()` /
//! `option()`) and reported only as a note shown at `-v`; a name in none of these tables and
//! never `Declare`d is the only case that warns.
//!
//! Sources for the names and types: RISpec 3.2 §4.1.4/§4.2.10 examples, the PRMan application
//! notes and later attribute tables, the BMRT 2.6 user manual (§3.2), the Aqsis 1.8 options and
//! attributes reference, Pixie's and 3Delight's user manuals.

/// What arbor does with a known setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Use {
    /// Read by the scene builder or the renderer.
    Used,
    /// Recognised and kept, but has no effect on arbor's picture.
    Ignored,
}

use Use::*;

/// (key, declaration, use).
pub const KNOWN: &[(&str, &str, Use)] = &[
    // ---- Options ----
    ("searchpath:shader", "uniform string", Used),
    ("searchpath:texture", "uniform string", Used),
    ("searchpath:archive", "uniform string", Used),
    ("searchpath:procedural", "uniform string", Used),
    ("searchpath:display", "uniform string", Ignored),
    ("searchpath:resource", "uniform string", Ignored),
    ("searchpath:rixplugin", "uniform string", Ignored),
    ("searchpath:servershader", "uniform string", Ignored),
    ("searchpath:servertexture", "uniform string", Ignored),
    ("searchpath:serverarchive", "uniform string", Ignored),
    ("searchpath:dirmap", "uniform string", Ignored),
    ("limits:bucketsize", "uniform integer[2]", Used),
    ("limits:gridsize", "uniform integer", Used),
    ("limits:texturememory", "uniform integer", Used),
    ("limits:eyesplits", "uniform integer", Used),
    ("limits:othreshold", "uniform color", Used),
    ("limits:zthreshold", "uniform color", Used),
    ("limits:brickmemory", "uniform integer", Ignored),
    ("limits:geocachememory", "uniform integer", Ignored),
    ("limits:proceduralmemory", "uniform integer", Ignored),
    ("limits:deepshadowtiles", "uniform integer", Ignored),
    ("limits:deepshadowmemory", "uniform integer", Ignored),
    ("limits:shadingrate", "uniform float", Used),
    ("limits:loopiterations", "uniform integer", Used),
    ("limits:resolution", "uniform integer", Used),
    ("limits:pixelsamples", "uniform float", Used),
    ("limits:filterwidth", "uniform float", Used),
    ("limits:derivmemory", "uniform integer", Ignored),
    ("limits:extremedisplacement", "uniform integer", Ignored),
    ("limits:threads", "uniform integer", Ignored),
    ("shadow:bias", "uniform float", Used),
    ("shadow:bias0", "uniform float", Used),
    ("shadow:bias1", "uniform float", Used),
    ("shadow:sample", "uniform integer", Ignored),
    ("statistics:endofframe", "uniform integer", Ignored),
    ("statistics:filename", "uniform string", Ignored),
    ("statistics:xmlfilename", "uniform string", Ignored),
    ("statistics:shaders", "uniform string", Ignored),
    ("statistics:maxdispwarnings", "uniform integer", Ignored),
    ("statistics:renderprogress", "uniform string", Ignored),
    ("statistics:progress", "uniform integer", Ignored),
    ("render:bucketorder", "uniform string", Ignored),
    ("render:multipass", "uniform integer", Ignored),
    ("render:prmanspecular", "uniform integer", Used),
    ("render:max_raylevel", "uniform integer", Used),
    ("render:minshadowbias", "uniform float", Used),
    ("render:use_hierarchy", "uniform integer", Ignored),
    ("render:standardatmosphere", "uniform integer", Ignored),
    ("render:rendermode", "uniform string", Ignored),
    ("render:samplemotion", "uniform integer", Ignored),
    ("radiosity:steps", "uniform integer", Used),
    ("radiosity:minpatchsamples", "uniform integer", Ignored),
    ("shutter:offset", "uniform float", Ignored),
    ("shutter:clampmotion", "uniform integer", Ignored),
    ("trace:maxdepth", "uniform integer", Used),
    ("trace:specularthreshold", "uniform float", Ignored),
    ("trace:continuationbydefault", "uniform integer", Ignored),
    ("trace:worldorigin", "uniform string", Ignored),
    ("photon:emit", "uniform integer", Ignored),
    ("photon:lifetime", "uniform string", Ignored),
    ("photon:maxdiffusedepth", "uniform integer", Ignored),
    ("photon:maxspeculardepth", "uniform integer", Ignored),
    ("ribparse:varsubst", "uniform string", Ignored),
    ("bucket:order", "uniform string", Ignored),
    ("hider:jitter", "uniform integer", Ignored),
    ("shading:debug", "uniform integer", Ignored),
    ("Ri:FrameAspectRatio", "uniform float", Ignored),
    // ---- Attributes ----
    ("identifier:name", "uniform string", Used),
    ("identifier:shadinggroup", "uniform string", Ignored),
    ("identifier:id", "uniform integer", Ignored),
    ("identifier:object", "uniform string", Ignored),
    ("displacementbound:sphere", "uniform float", Used),
    ("displacementbound:coordinatesystem", "uniform string", Used),
    ("displacementbound:offscreen", "uniform integer", Ignored),
    ("bound:displacement", "uniform float", Used),
    ("trimcurve:sense", "uniform string", Used),
    ("dice:binary", "uniform integer", Used),
    ("dice:rasterorient", "uniform integer", Ignored),
    ("dice:hair", "uniform integer", Ignored),
    ("dice:strategy", "uniform string", Ignored),
    ("dice:referencecamera", "uniform string", Ignored),
    ("dice:minlength", "uniform float", Ignored),
    ("dice:minlengthspace", "uniform string", Ignored),
    ("dice:offscreenstrategy", "uniform string", Ignored),
    ("dice:watertight", "uniform integer", Ignored),
    ("render:casts_shadows", "uniform string", Used),
    ("render:truedisplacement", "uniform integer", Used),
    ("render:visibility", "uniform integer", Used),
    ("render:patch_multiplier", "uniform float", Ignored),
    ("render:patch_maxlevel", "uniform integer", Ignored),
    ("render:patch_minlevel", "uniform integer", Ignored),
    ("render:use_shadingrate", "uniform integer", Ignored),
    ("light:shadows", "uniform string", Used),
    ("light:nsamples", "uniform integer", Used),
    ("light:samplingstrategy", "uniform string", Ignored),
    // Aqsis's automatic shadow maps (`Option "render" "auto_shadows"`): arbor renders no map,
    // but a light with `"shadows" "on"` casts traced shadows (the BMRT attribute above), so
    // the picture has them; the map the light shader names is then missing (one warning).
    ("render:auto_shadows", "uniform string", Ignored),
    ("render:shadow_shadingrate", "uniform float", Ignored),
    ("light:shadowmapsize", "uniform integer[2]", Ignored),
    ("light:shadowangle", "uniform float", Ignored),
    ("light:shadowmapname", "uniform string", Ignored),
    ("light:emitphotons", "uniform string", Ignored),
    ("radiosity:averagecolor", "uniform color", Ignored),
    ("radiosity:emissioncolor", "uniform color", Ignored),
    ("radiosity:specularcolor", "uniform color", Ignored),
    ("radiosity:patchsize", "uniform float", Ignored),
    ("radiosity:elemsize", "uniform float", Ignored),
    ("radiosity:minsize", "uniform float", Ignored),
    ("radiosity:zonal", "uniform string", Ignored),
    ("radiosity:has_caustics", "uniform integer", Ignored),
    ("visibility:camera", "uniform integer", Ignored),
    ("visibility:trace", "uniform integer", Used),
    // PRMan 11–13 wrote a string ("opaque", "Os", "shader"); later versions an integer.
    ("visibility:transmission", "uniform string", Used),
    ("visibility:photon", "uniform integer", Ignored),
    ("visibility:diffuse", "uniform integer", Ignored),
    ("visibility:specular", "uniform integer", Ignored),
    ("visibility:reflection", "uniform integer", Ignored),
    ("visibility:indirect", "uniform integer", Ignored),
    ("visibility:midpoint", "uniform integer", Ignored),
    ("trace:bias", "uniform float", Used),
    // arbor: micropolygon area (pixels as the camera would see them) of the ray tessellation.
    ("trace:shadingrate", "uniform float", Used),
    ("trace:autobias", "uniform integer", Ignored),
    ("trace:displacements", "uniform integer", Ignored),
    ("trace:samplemotion", "uniform integer", Ignored),
    ("trace:maxdiffusedepth", "uniform integer", Used),
    ("trace:maxspeculardepth", "uniform integer", Ignored),
    ("trace:importancethreshold", "uniform float", Ignored),
    ("shade:diffusehitmode", "uniform string", Ignored),
    ("shade:specularhitmode", "uniform string", Ignored),
    ("shade:transmissionhitmode", "uniform string", Ignored),
    ("shade:camerahitmode", "uniform string", Ignored),
    ("shade:frequency", "uniform string", Ignored),
    ("shade:relativeshadingrate", "uniform float", Ignored),
    ("shade:strategy", "uniform string", Ignored),
    (
        "shade:volumeintersectionstrategy",
        "uniform string",
        Ignored,
    ),
    ("irradiance:shadingrate", "uniform float", Ignored),
    ("irradiance:maxerror", "uniform float", Ignored),
    ("irradiance:maxpixeldist", "uniform float", Ignored),
    ("irradiance:nsamples", "uniform integer", Ignored),
    ("irradiance:handle", "uniform string", Ignored),
    ("irradiance:filemode", "uniform string", Ignored),
    ("photon:shadingmodel", "uniform string", Ignored),
    ("photon:causticmap", "uniform string", Ignored),
    ("photon:globalmap", "uniform string", Ignored),
    ("photon:estimator", "uniform integer", Ignored),
    ("cull:hidden", "uniform integer", Used),
    ("cull:backfacing", "uniform integer", Ignored),
    ("culling:hidden", "uniform integer", Ignored),
    ("culling:backfacing", "uniform integer", Ignored),
    ("sides:doubleshaded", "uniform integer", Ignored),
    ("sides:backfacetolerance", "uniform float", Ignored),
    ("stitch:enable", "uniform integer", Ignored),
    ("stitch:traceenable", "uniform integer", Ignored),
    ("stitch:newgroup", "uniform integer", Ignored),
    ("derivatives:centered", "uniform integer", Ignored),
    ("derivatives:extrapolate", "uniform integer", Ignored),
    ("grouping:membership", "uniform string", Ignored),
    ("grouping:tracesubset", "uniform string", Ignored),
    ("autoshadows:res", "uniform integer", Ignored),
    ("autoshadows:shadowmapname", "uniform string", Used),
    ("aqsis:expandgrids", "uniform float", Ignored),
    ("motion:displacement", "uniform integer", Ignored),
];

/// The declaration and use of a known "category:name", if any.
pub fn lookup(key: &str) -> Option<(&'static str, Use)> {
    KNOWN
        .iter()
        .find(|(k, _, _)| *k == key)
        .map(|(_, d, u)| (*d, *u))
}

/// What a category is about, for the note saying why arbor ignores it.
pub fn why_ignored(category: &str) -> &'static str {
    match category {
        "render" | "light" => "a BMRT/PRMan rendering control (ray-traced shadows, true displacement, area-light sampling)",
        "radiosity" => "a BMRT radiosity meshing control (arbor traces the bounce instead)",
        "photon" | "irradiance" => "global illumination, which arbor does not compute",
        "trace" | "visibility" | "shade" | "grouping" => "a ray-tracing control arbor does not use",
        "dice" | "limits" | "stitch" | "derivatives" | "cull" | "culling" | "sides" => {
            "a dicing or memory hint"
        }
        "statistics" => "statistics output (arbor has `render --stats`)",
        "identifier" => "a name other renderers use to group objects",
        "searchpath" => "a search path for files arbor does not load",
        _ => "a renderer-specific setting",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_declaration_parses() {
        for (k, d, _) in KNOWN {
            assert!(k.contains(':'), "{k}");
            assert!(crate::scene::params::parse_decl(d).is_ok(), "{k}: {d}");
        }
    }
}
