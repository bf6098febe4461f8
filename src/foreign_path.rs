//! Absolute paths from another machine: exporters (Blender's RenderMan exporters, MayaMan,
//! Liquid) write every `ReadArchive` as a full path into the author's home folder
//! (`/home/frigge/…/Sphere/Passes/Beauty_0001.rib`, `C:\proj\rib\obj.rib`). On the author's
//! machine the renderer found them; anywhere else the package's own copy lies beside the scene.
//!
//! Input: a path that does not exist as written, and the folders to look from (the including
//! file's folder, the scene's). Output: the file the path's trailing components name under
//! one of those folders or their parents.
//! Invariants: the longest trailing part that matches wins (`Passes/Beauty_0001.rib` before a
//! stray `Beauty_0001.rib`), then the first folder in the given order; a bare file name alone
//! is tried last; both `/` and `\` separate components and a drive letter is dropped.

use std::path::{Path, PathBuf};

/// How many folders above each starting folder are searched.
const PARENT_LEVELS: usize = 3;

/// The file `name` (an absolute path, or a Windows one, that does not exist here) stands for
/// under `bases`, matched by its trailing components. None when nothing matches.
pub fn rebase(name: &str, bases: &[PathBuf]) -> Option<PathBuf> {
    let parts: Vec<&str> = name
        .split(['/', '\\'])
        .filter(|c| !c.is_empty() && *c != "." && !is_drive(c))
        .collect();
    if parts.is_empty() || parts.contains(&"..") {
        return None;
    }
    let mut roots: Vec<PathBuf> = Vec::new();
    for b in bases {
        let mut d = Some(b.as_path());
        for _ in 0..=PARENT_LEVELS {
            let Some(dir) = d else { break };
            let dir = if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            };
            if !roots.iter().any(|r| r == dir) {
                roots.push(dir.to_path_buf());
            }
            d = dir.parent();
        }
    }
    // Longest tail first; the whole path (as a relative one) too.
    for take in (1..=parts.len()).rev() {
        let tail: PathBuf = parts[parts.len() - take..].iter().collect();
        for r in &roots {
            let c = r.join(&tail);
            if c.is_file() {
                return Some(c);
            }
        }
    }
    None
}

/// Whether `path` is written as absolute on some system: `/…`, `\…` or `X:…`.
pub fn looks_absolute(path: &str) -> bool {
    path.starts_with('/')
        || path.starts_with('\\')
        || path.split(['/', '\\']).next().is_some_and(is_drive)
}

fn is_drive(c: &str) -> bool {
    let b = c.as_bytes();
    b.len() == 2 && b[0].is_ascii_alphabetic() && b[1] == b':'
}

#[cfg(test)]
mod tests {
    use super::{looks_absolute, rebase};
    use std::path::PathBuf;

    fn tree(name: &str, files: &[&str]) -> PathBuf {
        let root =
            std::env::temp_dir().join(format!("arbor_foreign_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        for f in files {
            let p = root.join(f);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, "x").unwrap();
        }
        root
    }

    #[test]
    fn the_longest_matching_tail_under_the_scene_wins() {
        let root = tree(
            "tail",
            &[
                "pkg/Passes/Beauty.rib",
                "pkg/Beauty.rib",
                "pkg/Lights/Lamp.rib",
            ],
        );
        let scene = root.join("pkg");
        let got = rebase(
            "/home/someone/presets/pkg/Passes/Beauty.rib",
            &[scene.clone()],
        );
        assert_eq!(got, Some(scene.join("Passes/Beauty.rib")));
        // From an archive one folder down, the package root is a parent.
        let got = rebase(
            "/home/someone/presets/pkg/Lights/Lamp.rib",
            &[scene.join("Passes")],
        );
        assert_eq!(got, Some(scene.join("Lights/Lamp.rib")));
        // A Windows path with a drive letter and backslashes.
        let got = rebase(r"C:\work\pkg\Passes\Beauty.rib", &[scene.clone()]);
        assert_eq!(got, Some(scene.join("Passes/Beauty.rib")));
        assert_eq!(rebase("/home/someone/missing.rib", &[scene]), None);
        let _ = std::fs::remove_dir_all(root);
    }

    #[test]
    fn parent_references_are_not_followed() {
        let root = tree("dotdot", &["a/b.rib"]);
        assert_eq!(rebase("/x/../a/b.rib", &[root.clone()]), None);
        let _ = std::fs::remove_dir_all(root);
    }

    #[test]
    fn absolute_on_any_system() {
        assert!(looks_absolute("/home/a.rib"));
        assert!(looks_absolute(r"C:\a\b.rib"));
        assert!(looks_absolute("d:/a/b.rib"));
        assert!(!looks_absolute("a/b.rib"));
        assert!(!looks_absolute("Passes/Beauty.rib"));
    }
}
