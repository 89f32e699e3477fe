//! Output folders the harness may replace, and the marker that says so.
//!
//! `run --out` and `run-one --out` replace their folder as a whole. A folder
//! is only replaced when it is absent, empty, or one of surgbench's own
//! report or run folders, recognised by the [`MARKER`] file written into
//! each; `--force` also replaces any other folder. Anything that is not a
//! folder (a plain file) is never touched.

use crate::scenario::UsageError;
use std::path::Path;

/// The file that marks a folder as surgbench's own output.
pub const MARKER: &str = ".surgbench-output";

/// What the marker file says to a person who finds it.
const MARKER_TEXT: &str = "This folder was written by surgbench; `surgbench run --out` and \
`surgbench run-one --out` replace it as a whole.\n";

/// Checks that `out` may be replaced, touching nothing: it is absent, an
/// empty folder, a folder holding the [`MARKER`], or (with `force`) any
/// folder. A plain file, or a non-empty folder of someone else's without
/// `force`, is a [`UsageError`] naming the path.
pub fn check_replaceable(out: &Path, force: bool) -> Result<(), UsageError> {
    let meta = match std::fs::symlink_metadata(out) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(UsageError(format!("--out {}: cannot inspect it: {e}", out.display()))),
    };
    if !meta.is_dir() {
        return Err(UsageError(format!(
            "--out {} exists and is not a folder; surgbench never replaces a file, choose another path",
            out.display()
        )));
    }
    if force || out.join(MARKER).is_file() {
        return Ok(());
    }
    let empty = std::fs::read_dir(out)
        .map_err(|e| UsageError(format!("--out {}: cannot read it: {e}", out.display())))?
        .next()
        .is_none();
    if empty {
        Ok(())
    } else {
        Err(UsageError(format!(
            "--out {} is a non-empty folder that is not a surgbench report (no {MARKER} file); \
             it would be replaced as a whole. Choose another path, or pass --force to replace it",
            out.display()
        )))
    }
}

/// Writes the [`MARKER`] into `dir` (which must exist).
pub fn write_marker(dir: &Path) -> std::io::Result<()> {
    std::fs::write(dir.join(MARKER), MARKER_TEXT)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Absent and empty folders and marked folders may be replaced; a
    /// foreign folder only with `force`; a file never.
    #[test]
    fn only_own_or_empty_folders_are_replaceable() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path();
        assert!(check_replaceable(&p.join("absent"), false).is_ok());
        std::fs::create_dir(p.join("empty")).unwrap();
        assert!(check_replaceable(&p.join("empty"), false).is_ok());
        std::fs::create_dir(p.join("mine")).unwrap();
        std::fs::write(p.join("mine/thesis.tex"), "thesis").unwrap();
        let e = check_replaceable(&p.join("mine"), false).unwrap_err().0;
        assert!(e.contains("--force") && e.contains("mine"), "{e}");
        assert!(check_replaceable(&p.join("mine"), true).is_ok());
        write_marker(&p.join("mine")).unwrap();
        assert!(check_replaceable(&p.join("mine"), false).is_ok());
        std::fs::write(p.join("file"), "x").unwrap();
        for force in [false, true] {
            let e = check_replaceable(&p.join("file"), force).unwrap_err().0;
            assert!(e.contains("not a folder"), "force={force}: {e}");
        }
    }
}
