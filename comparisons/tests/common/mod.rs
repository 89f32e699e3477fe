//! Helpers shared by the scenario tests (tissue here, vessel in [`vessel`]).
#![allow(dead_code)]

pub mod vessel;

use std::collections::BTreeMap;
use surgbench_comparisons::datasets::datasets_dir;
use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::{Params, Scenario, ScenarioRun};
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
    tissue_observation(t, rest, nodes, hand_force)
}

/// An observation at time `t` of one tissue at `nodes` (rest positions
/// `rest`), at rest, with the given hand force.
pub fn tissue_observation(t: f64, rest: Vec<Vec3>, nodes: Vec<Vec3>, hand_force: Vec3) -> Observation {
    Observation {
        time: t,
        tissues: vec![TissueObs {
            velocities: vec![Vec3::zeros(); rest.len()],
            rest,
            nodes,
            volume_error: 0.0,
            inverted: 0,
            rest_dihedral_deg: None,
        }],
        hand_force,
        ..Default::default()
    }
}

/// The parameters of scenario `s` with `overrides` (by name) over its defaults.
pub fn params(s: &dyn Scenario, overrides: &[(&str, f64)]) -> Params {
    let o: Vec<(String, f64)> = overrides.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    Params::resolve(s.id(), s.params(), &o).unwrap()
}

/// A copy of the committed reference `reference/<dir>` (its `files`) in a
/// temporary datasets folder, with `edit(file name, text)` applied to each.
pub fn edited_reference(dir: &str, files: &[&str], edit: impl Fn(&str, String) -> String) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let src = datasets_dir().join("reference").join(dir);
    let dst = tmp.path().join("reference").join(dir);
    std::fs::create_dir_all(&dst).unwrap();
    for name in files {
        let text = std::fs::read_to_string(src.join(name)).unwrap();
        std::fs::write(dst.join(name), edit(name, text)).unwrap();
    }
    tmp
}

/// The `fem` model's errors on scenario `id` (default parameters) at mesh
/// levels 0, 1 and 2, each run at `dt = 0.025` s: the data of a
/// convergence study. Every run must end `ok`.
pub fn fem_errors_by_level(id: &str) -> Vec<BTreeMap<String, f64>> {
    let sc = registry::scenario(id).unwrap();
    let p = params(sc, &[]);
    let f = registry::model("fem").unwrap();
    (0..=2usize)
        .map(|l| {
            let mut fid = level(l);
            fid.set("dt", 0.025).unwrap();
            let inst = sc.instantiate_at(&p, &fid).unwrap();
            let s = run_single(sc, &p, &inst, f, &fid, &RunOptions::default()).unwrap();
            assert_eq!(s.status, "ok", "level {l}: {}", s.reason);
            eprintln!("fem level {l}: {:?}", s.errors);
            s.errors
        })
        .collect()
}
