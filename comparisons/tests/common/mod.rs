//! Helpers shared by the scenario tests (tissue here, vessel in [`vessel`]).
#![allow(dead_code)]

pub mod vessel;

use surgbench_comparisons::scenario::ScenarioRun;
use surgbench_core::{Fidelity, Observation, TissueBody, TissueObs, Vec3};

/// The fidelity that only picks mesh level `l`.
pub fn level(l: usize) -> Fidelity {
    Fidelity {
        mesh_level: Some(l),
        ..Default::default()
    }
}

/// The scene's one tissue body.
pub fn body(run: &ScenarioRun) -> &TissueBody {
    run.scene().tissues().next().expect("one tissue body")
}

/// An observation at time `t` with nodes at `rest + u(rest)`, at rest, and
/// the given hand force.
pub fn observe(run: &ScenarioRun, t: f64, hand_force: Vec3, u: impl Fn(&Vec3) -> Vec3) -> Observation {
    let rest = body(run).mesh.nodes.clone();
    let nodes = rest.iter().map(|x| x + u(x)).collect();
    Observation {
        time: t,
        tissues: vec![TissueObs {
            velocities: vec![Vec3::zeros(); rest.len()],
            rest,
            nodes,
            volume_error: 0.0,
            inverted: 0,
        }],
        hand_force,
        ..Default::default()
    }
}
