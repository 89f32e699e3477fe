//! Needle insertion (the needle seed: Chentanez et al., SIGGRAPH 2009).
//!
//! Shared conventions (SI units): the needle enters along +x through the
//! tissue face at `x = 0`; its tip starts `tip_gap` outside it and its base
//! (the guide sleeve) never reaches the tissue. A gel block occupies
//! `[0, block_length] x [-w/2, w/2]^2` (`w = block_width`) and is held at its
//! far face `x = block_length`; its mesh has `8 * 2^level x 4 * 2^level x
//! 4 * 2^level` cells (six tets each), so a mesh node sits on the needle's
//! axis at the entry. The model reports `Observation::hand_force` as the
//! force the needle exerts on the hand: the hand pushes with its negative.

mod straight;

pub use straight::{NEEDLE_STRAIGHT, StraightParams};

use crate::scenario::{Scenario, Sweep, UsageError};
use surgbench_core::Fidelity;

/// Every needle scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![&NEEDLE_STRAIGHT]
}

/// Finest mesh level: level 1 is 16 x 8 x 8 cells (6,144 tets); level 2
/// (49,152 tets) costs minutes per run with one tissue solve per coupling
/// point and axis per step.
pub const MAX_LEVEL: usize = 1;

/// The sweep of the needle scenes: mesh levels 0..=[`MAX_LEVEL`].
const LEVELS: Sweep = Sweep::MeshLevels {
    up_to: MAX_LEVEL,
    dt: None,
};

/// `fidelity.mesh_level` (default 0), rejected past [`MAX_LEVEL`].
fn mesh_level(scenario: &str, fidelity: &Fidelity) -> Result<usize, UsageError> {
    let level = fidelity.mesh_level.unwrap_or(0);
    if level > MAX_LEVEL {
        return Err(UsageError(format!(
            "scenario `{scenario}`: mesh_level {level} is past the finest level {MAX_LEVEL}"
        )));
    }
    Ok(level)
}
