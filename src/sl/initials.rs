//! Shaders renamed with their author's initials: the RenderMan Repository prefixed every
//! shader it collected (`brick.sl` became `DPBrick.sl`, `bubbly.sl` `IDbubbly.sl`,
//! `paper.sl` `EM_paper.sl`), but some of its scenes still name the shader as it was written
//! (`Displacement "bubbly"`). PRMan found the original name on its author's disk.
//!
//! Input: a shader name that no file on the search path matches, and the search folders.
//! Output: the one file in the first folder that has any, whose name is that name with one to
//! four capital letters (and an optional `_`) in front, ignoring the case of the rest.
//! Invariants: only tried once the name itself (and its case-folded form) is missing; an
//! ambiguous folder (two such files) gives nothing, so the choice never depends on directory
//! order.

use std::path::{Path, PathBuf};

/// Whether `file` (a file name) is `stem.sl` with an initials prefix: `IDbubbly.sl` for
/// `bubbly`, `EM_paper.sl` for `paper`.
pub fn is_initialled(file: &str, stem: &str) -> bool {
    let Some(rest) = file.strip_suffix(".sl") else {
        return false;
    };
    let caps = rest.bytes().take_while(|b| b.is_ascii_uppercase()).count();
    (1..=4).any(|k| {
        k <= caps
            && [&rest[k..], rest[k..].strip_prefix('_').unwrap_or("")]
                .iter()
                .any(|r| !r.is_empty() && r.eq_ignore_ascii_case(stem))
    })
}

/// The initialled file for `stem` (see the module doc) in the first of `dirs` holding exactly
/// one; None when no folder has one, or the first that has any has several.
pub fn find_initialled(stem: &str, dirs: &[PathBuf]) -> Option<PathBuf> {
    if stem.is_empty() || stem.contains(['/', '\\']) {
        return None;
    }
    for dir in dirs {
        let mut found: Vec<PathBuf> = Vec::new();
        for entry in read_dir_sorted(dir) {
            if entry
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| is_initialled(n, stem))
                && entry.is_file()
            {
                found.push(entry);
            }
        }
        match found.len() {
            0 => continue,
            1 => return found.pop(),
            _ => return None,
        }
    }
    None
}

fn read_dir_sorted(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn initials_prefix_one_to_four_capitals_and_an_optional_underscore() {
        assert!(is_initialled("IDbubbly.sl", "bubbly"));
        assert!(is_initialled("DPBrick.sl", "brick"));
        assert!(is_initialled("JBUMcraters.sl", "craters"));
        assert!(is_initialled("EM_paper.sl", "paper"));
        assert!(!is_initialled("bubbly.sl", "bubbly"));
        assert!(!is_initialled("XYZWVbubbly.sl", "bubbly"));
        assert!(!is_initialled("IDbubbly.slo", "bubbly"));
        assert!(!is_initialled("IDbubblier.sl", "bubbly"));
        assert!(!is_initialled("ID.sl", ""));
    }
}
