//! File names that differ only in letter case: scenes written on case-insensitive file
//! systems (NeXT, classic Mac OS, Windows) name `Surface "DPCloudPlane"` for `DPCloudplane.sl`,
//! or a texture `Grid.tx` for `grid.tx`; PRMan and BMRT found them there.
//!
//! Input: a path that does not exist as written. Output: the one file in the same folder whose
//! name equals the path's last component ignoring ASCII case, if there is exactly one.
//! Invariants: the exact name always wins (callers try it first); an ambiguous match (two
//! files differing only in case) finds nothing, so the choice never depends on directory order;
//! only the last component is folded (folders must match as written).

use std::path::{Path, PathBuf};

/// The file `path` names, matching its file name without regard to ASCII case when no file of
/// exactly that name exists. None when there is no such file, or several.
pub fn find_file_ignoring_case(path: &Path) -> Option<PathBuf> {
    if path.is_file() {
        return Some(path.to_path_buf());
    }
    let want = path.file_name()?.to_str()?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut found: Option<PathBuf> = None;
    for entry in std::fs::read_dir(dir).ok()?.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if name.eq_ignore_ascii_case(want) && entry.path().is_file() {
            if found.is_some() {
                return None;
            }
            found = Some(dir.join(name));
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::find_file_ignoring_case;

    #[test]
    fn finds_a_file_whose_name_differs_in_case_only() {
        let dir = std::env::temp_dir().join(format!("arbor-pathcase-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("DPCloudplane.sl"), "surface DPCloudplane() {}").unwrap();
        let got = find_file_ignoring_case(&dir.join("DPCloudPlane.sl")).unwrap();
        assert_eq!(got.file_name().unwrap(), "DPCloudplane.sl");
        // The exact name is returned as given.
        assert_eq!(
            find_file_ignoring_case(&dir.join("DPCloudplane.sl")).unwrap(),
            dir.join("DPCloudplane.sl")
        );
        assert!(find_file_ignoring_case(&dir.join("other.sl")).is_none());
        // Two candidates that differ only in case: no guess.
        std::fs::write(dir.join("dpcloudplane.sl"), "").unwrap();
        assert!(find_file_ignoring_case(&dir.join("DPCLOUDPLANE.sl")).is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
