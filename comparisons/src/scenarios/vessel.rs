//! Vascular navigation scenarios (work in progress).

use crate::scenario::Scenario;

/// Every vessel scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![]
}
