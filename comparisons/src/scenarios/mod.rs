//! The scenario catalogue: one file per scenario under `rod/`, `tissue/`,
//! `vessel/` and `needle/`, each declaring its [`ScenarioInfo`](crate::ScenarioInfo),
//! its parameters (a `params!` struct) and its scorer.

pub mod needle;
pub mod oscillation;
pub mod pair;
pub mod rod;
pub mod tissue;
pub mod vessel;

use crate::scenario::Scenario;

/// Every scenario, in report order: the one list a new scenario joins.
pub fn all() -> Vec<&'static dyn Scenario> {
    let mut v = rod::all();
    v.extend(tissue::all());
    v.extend(vessel::all());
    v.extend(needle::all());
    v.extend(pair::all());
    v
}
