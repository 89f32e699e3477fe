//! Replacing a folder as a whole: build the new one in a temporary sibling
//! ([`temp_sibling`]), then move it into place ([`replace_dir`]). Until the
//! move, the folder a user has is untouched; a failure on the way removes
//! the temporary sibling and leaves it as it was.
//!
//! [`link_tree`] starts a replacement from the folder's current files
//! (hard links, so nothing large is copied): `surgbench report DIR`
//! re-renders a report that way.

use std::io;
use std::path::{Path, PathBuf};

/// A fresh, empty temporary sibling of `out` (`.NAME.tmp-PID`) for building
/// a replacement; `out`'s parent is created if needed.
pub fn temp_sibling(out: &Path) -> io::Result<PathBuf> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent)?;
    let tmp = parent.join(format!(
        ".{}.tmp-{}",
        out.file_name().and_then(|n| n.to_str()).unwrap_or("out"),
        std::process::id()
    ));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    Ok(tmp)
}

/// Move `tmp` into place at `out`, keeping `out` intact until the new one
/// is complete.
pub fn replace_dir(tmp: &Path, out: &Path) -> io::Result<()> {
    if out.exists() {
        let old = out.with_file_name(format!(
            ".{}.old-{}",
            out.file_name().and_then(|n| n.to_str()).unwrap_or("out"),
            std::process::id()
        ));
        std::fs::rename(out, &old)?;
        if let Err(e) = std::fs::rename(tmp, out) {
            let _ = std::fs::rename(&old, out);
            return Err(e);
        }
        let _ = std::fs::remove_dir_all(&old);
        Ok(())
    } else {
        std::fs::rename(tmp, out)
    }
}

/// Fills the existing folder `to` with the tree of `from`, leaving out the
/// files and links (paths relative to `from`; never a folder) for which
/// `skip` is true: sub-folders are made
/// anew with their permissions, files are hard-linked (copied where the file
/// system refuses a link), symbolic links are made again pointing where they
/// pointed. Nothing under `from` is changed.
///
/// A linked file shares its contents with the original: whoever fills `to`
/// must replace such a file (write a new one and rename it over the link),
/// never write into it. Anything that is not a file, folder or symbolic
/// link (a socket, a device) is an error, so that moving `to` into place
/// never drops it.
pub fn link_tree(from: &Path, to: &Path, skip: &dyn Fn(&Path) -> bool) -> io::Result<()> {
    link_below(from, to, Path::new(""), skip)
}

fn link_below(from: &Path, to: &Path, rel: &Path, skip: &dyn Fn(&Path) -> bool) -> io::Result<()> {
    let within = |e: io::Error, p: &Path| io::Error::new(e.kind(), format!("{}: {e}", p.display()));
    let src_dir = from.join(rel);
    let entries = std::fs::read_dir(&src_dir).map_err(|e| within(e, &src_dir))?;
    for entry in entries {
        let entry = entry.map_err(|e| within(e, &src_dir))?;
        let rel = rel.join(entry.file_name());
        let (src, dst) = (from.join(&rel), to.join(&rel));
        let kind = entry.file_type().map_err(|e| within(e, &src))?;
        if !kind.is_dir() && skip(&rel) {
            continue;
        }
        if kind.is_dir() {
            std::fs::create_dir(&dst).map_err(|e| within(e, &dst))?;
            let perms = std::fs::metadata(&src).map_err(|e| within(e, &src))?.permissions();
            link_below(from, to, &rel, skip)?;
            std::fs::set_permissions(&dst, perms).map_err(|e| within(e, &dst))?;
        } else if kind.is_symlink() {
            let target = std::fs::read_link(&src).map_err(|e| within(e, &src))?;
            std::os::unix::fs::symlink(target, &dst).map_err(|e| within(e, &dst))?;
        } else if kind.is_file() {
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst).map_err(|e| within(e, &src))?;
            }
        } else {
            return Err(io::Error::other(format!(
                "{}: neither a file, a folder nor a symbolic link; cannot carry it over",
                src.display()
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The linked tree has every file with its bytes, skips what `skip`
    /// says, and replacing a linked file in the copy leaves the original.
    #[test]
    fn link_tree_carries_files_and_leaves_the_original() {
        let tmp = tempfile::tempdir().unwrap();
        let (from, to) = (tmp.path().join("from"), tmp.path().join("to"));
        std::fs::create_dir_all(from.join("runs/a")).unwrap();
        std::fs::write(from.join("results.csv"), "x\n").unwrap();
        std::fs::write(from.join("runs/a/obs.csv"), "t\n1\n").unwrap();
        std::fs::write(from.join("index.html"), "old page").unwrap();
        std::os::unix::fs::symlink("results.csv", from.join("link")).unwrap();
        std::fs::create_dir(&to).unwrap();
        link_tree(&from, &to, &|rel| rel == Path::new("index.html")).unwrap();
        assert_eq!(std::fs::read_to_string(to.join("runs/a/obs.csv")).unwrap(), "t\n1\n");
        assert_eq!(std::fs::read_link(to.join("link")).unwrap(), Path::new("results.csv"));
        assert!(!to.join("index.html").exists(), "skipped");
        std::fs::write(to.join("new.csv"), "y\n").unwrap();
        std::fs::rename(to.join("new.csv"), to.join("results.csv")).unwrap();
        assert_eq!(std::fs::read_to_string(from.join("results.csv")).unwrap(), "x\n");
    }
}
