//! Where the data a scenario reads live (phantom data, scikit-fem
//! references, cached trajectories), and the loaders of the phantom sets.

use crate::error::UsageError;
use std::path::{Path, PathBuf};
use surgbench_core::io::truth_cube;

/// Where the scenario reference data live: `$SURGBENCH_DATASETS` or the
/// repository's `datasets/`.
pub fn datasets_dir() -> PathBuf {
    std::env::var_os("SURGBENCH_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../datasets")))
}

/// Load the Truth Cube data from `<datasets>/phantom/truth-cube/`.
pub fn load_truth_cube(datasets: &Path) -> Result<truth_cube::TruthCube, UsageError> {
    truth_cube::load(datasets.join("phantom/truth-cube/truth-cube-uniaxial.csv")).map_err(UsageError)
}
