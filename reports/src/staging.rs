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

/// The folder holding `out` (`.` for a bare name).
fn parent_of(out: &Path) -> &Path {
    out.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// The prefix of every temporary sibling of `out`: `.NAME.tmp-`.
fn temp_prefix(out: &Path) -> String {
    format!(".{}.tmp-", out.file_name().and_then(|n| n.to_str()).unwrap_or("out"))
}

/// A fresh, empty temporary sibling of `out` (`.NAME.tmp-PID`) for building
/// a replacement; `out`'s parent is created if needed. Stale siblings left
/// by processes that died without cleaning up are removed first
/// ([`remove_stale_siblings`]).
pub fn temp_sibling(out: &Path) -> io::Result<PathBuf> {
    let parent = parent_of(out);
    std::fs::create_dir_all(parent)?;
    remove_stale_siblings(out);
    let tmp = parent.join(format!("{}{}", temp_prefix(out), std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    Ok(tmp)
}

/// Removes the temporary siblings of `out` (`.NAME.tmp-PID`, see
/// [`temp_sibling`]) whose process is no longer alive: a process killed by
/// SIGKILL cannot remove its own. A process counts as alive while
/// `/proc/PID` exists; where `/proc` cannot tell (no `/proc/self`) nothing
/// is removed, nor is a name whose tail is not a pid. The `.NAME.old-PID`
/// folder a move leaves if killed halfway is never touched: it may be the
/// only copy of the earlier output.
pub fn remove_stale_siblings(out: &Path) {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return;
    }
    let prefix = temp_prefix(out);
    let Ok(entries) = std::fs::read_dir(parent_of(out)) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(&prefix))
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if !proc.join(pid.to_string()).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
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

    /// A temporary sibling whose process is gone is removed by the next
    /// [`temp_sibling`]; a live process's sibling, a name that is not a
    /// pid, another folder's sibling and the `.old-` folder of a move stay.
    #[test]
    fn stale_temporary_siblings_are_removed() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("report");
        let mut gone = std::process::Command::new("true").spawn().unwrap();
        gone.wait().unwrap();
        let mut alive = std::process::Command::new("sleep").arg("60").spawn().unwrap();
        let names = [
            format!(".report.tmp-{}", gone.id()),
            format!(".report.tmp-{}", alive.id()),
            ".report.tmp-x".to_string(),
            format!(".other.tmp-{}", gone.id()),
            format!(".report.old-{}", gone.id()),
        ];
        for n in &names {
            std::fs::create_dir_all(tmp.path().join(n).join("runs")).unwrap();
        }
        let mine = temp_sibling(&out).unwrap();
        let _ = alive.kill();
        let _ = alive.wait();
        let left = |n: &str| tmp.path().join(n).exists();
        assert!(!left(&names[0]), "the dead process's sibling stays");
        for n in &names[1..] {
            assert!(left(n), "{n} was removed");
        }
        assert!(mine.is_dir(), "{}", mine.display());
    }

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
