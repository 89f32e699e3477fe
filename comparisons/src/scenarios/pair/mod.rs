//! Instruments in deformable vessels: a rod model and a tissue model run
//! together by the harness's partitioned coupling
//! ([`surgbench_core::coupling`]), scored on what any pair shows: the
//! instrument against the *deformed* wall, the wall's motion, the hand.
//!
//! Shared conventions (SI units): the vessel is a tube wall swept along a
//! centreline ([`surgbench_core::mesh::swept_wall`]), its inner wall the
//! tissue's contact surface, its outer surface held (a vessel tethered in
//! stiffer surrounding tissue: the wall compresses, the vessel does not
//! move as a whole); the scene's `Environment::vessel` is the lumen at
//! rest. The instrument is clamped on the centreline near the vessel's
//! start and fed along it.

mod compliant_vessel;

pub use compliant_vessel::{CATHETER_COMPLIANT_VESSEL, CompliantParams};

use crate::scenario::Scenario;

/// Every pair scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![&CATHETER_COMPLIANT_VESSEL]
}
