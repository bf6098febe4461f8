//! `arbor job`: an Open Job Description template (`jobtemplate-2023-09`) for a tiled render.
//!
//! Input: the scene's frame numbers, the tile count and the command-line settings the render
//! needs. Output: YAML text. Invariants: the template follows the 2023-09 Template Schemas
//! (job parameters `Arbor` (STRING), `ScenePath` (PATH, FILE, IN), `OutputDir` (PATH,
//! DIRECTORY, OUT); a `Render` step with a task per frame × tile; a `Merge` step depending on
//! it with a task per frame); render and merge get the same settings, so the tiles' settings
//! hash matches at merge time; every string is single-quoted YAML (no escapes but `''`).

use std::path::Path;

/// What the template is made of.
#[derive(Clone, Debug)]
pub struct JobSpec {
    /// Job name (shown by the farm).
    pub name: String,
    /// Default of `Arbor`: the command (or absolute path) that runs arbor on the workers.
    pub arbor: String,
    /// Default of `ScenePath`, relative to the template's folder (OpenJD joins PATH defaults
    /// to it, and requires them relative).
    pub scene: String,
    /// Default of `OutputDir` (relative to the template's folder): the folder relative Display
    /// names are written to.
    pub output_dir: String,
    /// FrameBegin numbers; empty when the file has none (one frame, no `--frames`).
    pub frames: Vec<i32>,
    pub tiles: u32,
    /// Arguments both `arbor render` and `arbor merge` get (resolution, search paths…).
    pub settings_args: Vec<String>,
    /// Arguments only the render tasks get (`--allow-programs`, `--program-timeout`).
    pub render_args: Vec<String>,
}

/// An OpenJD `<IntRangeExpr>` for sorted, distinct numbers: runs become `a-b`.
pub fn range_expr(values: &[i32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < values.len() {
        let mut j = i;
        while j + 1 < values.len() && values[j + 1] == values[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            values[i].to_string()
        } else {
            format!("{}-{}", values[i], values[j])
        });
        i = j + 1;
    }
    parts.join(",")
}

/// A YAML single-quoted scalar.
fn q(s: &str) -> String {
    format!("'{}'", s.replace('\'', "''"))
}

fn args_list(args: &[String]) -> String {
    let items: Vec<String> = args.iter().map(|a| q(a)).collect();
    format!("[{}]", items.join(", "))
}

/// The template text.
pub fn template(spec: &JobSpec) -> String {
    let has_frames = !spec.frames.is_empty();
    let mut common = vec!["-C".to_string(), "{{Param.OutputDir}}".to_string()];
    let frame_args = |v: &mut Vec<String>| {
        if has_frames {
            v.push("--frames".into());
            v.push("{{Task.Param.Frame}}".into());
        }
    };
    common.push(String::new()); // placeholder for the subcommand
    let mut render = common.clone();
    render[2] = "render".into();
    render.push("{{Param.ScenePath}}".into());
    render.extend(spec.settings_args.iter().cloned());
    render.extend(spec.render_args.iter().cloned());
    frame_args(&mut render);
    render.push("--tile".into());
    render.push(format!("{{{{Task.Param.Tile}}}}/{}", spec.tiles));
    let mut merge = common;
    merge[2] = "merge".into();
    merge.push("{{Param.ScenePath}}".into());
    merge.extend(spec.settings_args.iter().cloned());
    frame_args(&mut merge);
    merge.push("--tiles".into());
    merge.push(spec.tiles.to_string());

    let frames = range_expr(&spec.frames);
    let mut y = String::new();
    y += "# Open Job Description job template written by `arbor job`.\n";
    y += "# Run it here: openjd run THIS.yaml --step Merge --run-dependencies\n";
    y += "# Submit it to a farm, e.g. AWS Deadline Cloud: deadline bundle submit BUNDLE_DIR\n";
    y += "specificationVersion: 'jobtemplate-2023-09'\n";
    y += &format!("name: {}\n", q(&spec.name));
    y += &format!(
        "description: {}\n",
        q(&format!(
            "arbor renders {} frame(s) in {} tiles each, then merges each frame's tiles into its \
             Display pictures.",
            spec.frames.len().max(1),
            spec.tiles
        ))
    );
    y += "parameterDefinitions:\n";
    y += "- name: Arbor\n  type: STRING\n";
    y += &format!("  default: {}\n", q(&spec.arbor));
    y +=
        "  description: 'The arbor command on the workers (a name on PATH or an absolute path).'\n";
    y += "- name: ScenePath\n  type: PATH\n  objectType: FILE\n  dataFlow: IN\n";
    y += &format!("  default: {}\n", q(&spec.scene));
    y += "  description: 'The RIB file to render.'\n";
    y += "- name: OutputDir\n  type: PATH\n  objectType: DIRECTORY\n  dataFlow: OUT\n";
    y += &format!("  default: {}\n", q(&spec.output_dir));
    y += "  description: 'Folder the scene''s relative Display names (and the tile files) are written to.'\n";
    y += "steps:\n";
    // Render: frame × tile.
    y += "- name: Render\n";
    y += "  description: 'One task per frame and tile: the tile''s pixels with their filter margins.'\n";
    y += "  parameterSpace:\n    taskParameterDefinitions:\n";
    if has_frames {
        y += &format!(
            "    - name: Frame\n      type: INT\n      range: {}\n",
            q(&frames)
        );
    }
    y += &format!(
        "    - name: Tile\n      type: INT\n      range: {}\n",
        q(&format!("1-{}", spec.tiles))
    );
    if has_frames {
        y += "    combination: 'Frame * Tile'\n";
    }
    y += "  script:\n    actions:\n      onRun:\n        command: '{{Param.Arbor}}'\n";
    y += &format!("        args: {}\n", args_list(&render));
    // Merge: one task per frame, after every tile.
    y += "- name: Merge\n";
    y += "  description: 'One task per frame: its tiles into each Display''s picture.'\n";
    y += "  dependencies:\n  - dependsOn: Render\n";
    if has_frames {
        y += "  parameterSpace:\n    taskParameterDefinitions:\n";
        y += &format!(
            "    - name: Frame\n      type: INT\n      range: {}\n",
            q(&frames)
        );
    }
    y += "  script:\n    actions:\n      onRun:\n        command: '{{Param.Arbor}}'\n";
    y += &format!("        args: {}\n", args_list(&merge));
    y
}

/// `target` relative to the folder `base` (both absolute): `../shots/a.rib`; None when they
/// share no root (another drive).
pub fn relative_to(target: &Path, base: &Path) -> Option<String> {
    use std::path::Component;
    let t: Vec<Component> = target.components().collect();
    let b: Vec<Component> = base.components().collect();
    if t.first() != b.first() {
        return None;
    }
    let common = t.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut parts: Vec<String> = vec!["..".into(); b.len() - common];
    parts.extend(
        t[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    Some(if parts.is_empty() {
        ".".into()
    } else {
        parts.join("/")
    })
}

/// A job name from the scene file name (at most 128 characters, as the schema requires).
pub fn job_name(scene: &Path, tiles: u32) -> String {
    let base = scene
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let name: String = format!("arbor {base} ({tiles} tiles)")
        .chars()
        .filter(|c| !c.is_control())
        .collect();
    name.chars().take(128).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_defaults() {
        let r = |a: &str, b: &str| relative_to(Path::new(a), Path::new(b)).unwrap();
        assert_eq!(r("/shows/a/scene.rib", "/shows/a"), "scene.rib");
        assert_eq!(
            r("/shows/a/scene.rib", "/shows/jobs/x"),
            "../../a/scene.rib"
        );
        assert_eq!(r("/shows/a", "/shows/a"), ".");
        assert_eq!(r("/shows/a/out", "/shows/a"), "out");
    }

    #[test]
    fn frame_ranges_compress_runs() {
        assert_eq!(range_expr(&[1, 2]), "1-2");
        assert_eq!(range_expr(&[1, 2, 3, 5, 7, 8]), "1-3,5,7-8");
        assert_eq!(range_expr(&[-2, -1, 0]), "-2-0");
        assert_eq!(range_expr(&[4]), "4");
    }

    #[test]
    fn template_has_both_steps_and_quotes_strings() {
        let t = template(&JobSpec {
            name: "arbor it's.rib (4 tiles)".into(),
            arbor: "/opt/arbor/bin/arbor".into(),
            scene: "/shows/it's.rib".into(),
            output_dir: "/shows/out".into(),
            frames: vec![1, 2],
            tiles: 4,
            settings_args: vec!["--res".into(), "64".into(), "48".into()],
            render_args: vec!["--allow-programs".into()],
        });
        assert!(t.contains("specificationVersion: 'jobtemplate-2023-09'\n"));
        assert!(t.contains("name: 'arbor it''s.rib (4 tiles)'\n"));
        assert!(t.contains("default: '/shows/it''s.rib'\n"));
        assert!(t.contains("      range: '1-2'\n"));
        assert!(t.contains("      range: '1-4'\n"));
        assert!(t.contains("  - dependsOn: Render\n"));
        assert!(t.contains(
            "args: ['-C', '{{Param.OutputDir}}', 'render', '{{Param.ScenePath}}', '--res', '64', \
             '48', '--allow-programs', '--frames', '{{Task.Param.Frame}}', '--tile', \
             '{{Task.Param.Tile}}/4']"
        ));
        assert!(t.contains(
            "args: ['-C', '{{Param.OutputDir}}', 'merge', '{{Param.ScenePath}}', '--res', '64', \
             '48', '--frames', '{{Task.Param.Frame}}', '--tiles', '4']"
        ));
        // Without frame numbers there is no Frame parameter and no --frames.
        let u = template(&JobSpec {
            frames: vec![],
            settings_args: vec![],
            render_args: vec![],
            ..JobSpec {
                name: "n".into(),
                arbor: "arbor".into(),
                scene: "/s.rib".into(),
                output_dir: "/o".into(),
                frames: vec![],
                tiles: 2,
                settings_args: vec![],
                render_args: vec![],
            }
        });
        assert!(!u.contains("Frame"));
        assert!(!u.contains("--frames"));
    }
}
