//! Where the data a scenario reads live (phantom data, scikit-fem
//! references, cached trajectories), and the loaders of the phantom sets.

use crate::error::UsageError;
use std::path::{Path, PathBuf};
use surgbench_core::io::truth_cube;

/// The folder surgbench reads named comparisons from (`comparisons/NAME.toml`)
/// and writes its default report into (`reports/out/latest`):
/// `$SURGBENCH_ROOT` when set; else the nearest of the current directory and
/// its ancestors that holds a `comparisons/` folder (a checkout, from
/// anywhere inside it); else the current directory. Never the source tree
/// the binary was built from: a binary copied elsewhere reads and writes
/// where it is run.
pub fn project_root() -> PathBuf {
    let cwd = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    root_from(std::env::var_os("SURGBENCH_ROOT").map(PathBuf::from), &cwd)
}

/// [`project_root`] for a given `$SURGBENCH_ROOT` and current directory.
pub fn root_from(env_root: Option<PathBuf>, cwd: &Path) -> PathBuf {
    if let Some(root) = env_root.filter(|r| !r.as_os_str().is_empty()) {
        return root;
    }
    cwd.ancestors()
        .find(|d| d.join("comparisons").is_dir())
        .unwrap_or(cwd)
        .to_path_buf()
}

/// Where the scenario reference data live: `$SURGBENCH_DATASETS` when set,
/// else `datasets/` in the [`project_root`].
pub fn datasets_dir() -> PathBuf {
    std::env::var_os("SURGBENCH_DATASETS")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| project_root().join("datasets"))
}

/// Load the Truth Cube data from `<datasets>/phantom/truth-cube/`.
pub fn load_truth_cube(datasets: &Path) -> Result<truth_cube::TruthCube, UsageError> {
    truth_cube::load(datasets.join("phantom/truth-cube/truth-cube-uniaxial.csv")).map_err(UsageError)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `$SURGBENCH_ROOT` wins; else the nearest folder up from the current
    /// one that holds `comparisons/`; else the current folder itself.
    #[test]
    fn the_root_is_found_from_the_current_directory() {
        let tmp = tempfile::tempdir().unwrap();
        let (proj, deep) = (tmp.path().join("proj"), tmp.path().join("proj/a/b"));
        std::fs::create_dir_all(proj.join("comparisons")).unwrap();
        std::fs::create_dir_all(&deep).unwrap();
        assert_eq!(root_from(None, &deep), proj);
        assert_eq!(root_from(None, &proj), proj);
        let elsewhere = tmp.path().join("elsewhere");
        std::fs::create_dir_all(&elsewhere).unwrap();
        assert_eq!(root_from(None, &elsewhere), elsewhere);
        assert_eq!(root_from(Some(elsewhere.clone()), &deep), elsewhere);
        assert_eq!(
            root_from(Some(PathBuf::new()), &deep),
            proj,
            "an empty variable is unset"
        );
    }
}
