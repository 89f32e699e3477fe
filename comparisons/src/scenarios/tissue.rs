//! Tissue scenarios (work in progress).

use crate::scenario::Scenario;

/// Every tissue scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![]
}
