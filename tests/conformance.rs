//! The conformance suite on every registered model
//! ([`surgbench_comparisons::conformance`], in the spirit of SOFA's
//! ForceField test harness): same inputs give bit-identical results, rigid
//! motions of the whole scene change nothing, forces equal minus the energy
//! gradient, a saved state restores bit for bit, an unsupported scene is
//! refused with a reason. A crate under
//! `models/` that is not registered fails the suite.
//!
//! One model only: `SURGBENCH_MODELS=der cargo test --test conformance`
//! (a comma-separated list of ids).

use surgbench_comparisons::conformance::{self, KnownDefect};
use surgbench_comparisons::registry;
use surgbench_core::ModelFactory;

/// Model x scenario pairs known to break rigid-motion invariance, with what
/// was measured; each is open (noted on its issue) and checked as a strict
/// expected failure, so a fix shows up here.
const KNOWN_FRAME_DEPENDENT: &[KnownDefect] = &[
    // The wall mesh moves with the scene (its grid is in the clamp's
    // frame). Likely cause, not verified: rapier solves the contacts by
    // projected Gauss-Seidel, one sweep per substep, in the order its broad
    // phase (world-axis bounding boxes) finds them, and the unconverged
    // sweep depends on that order. Only the scenes in contact within the
    // check's first steps show it.
    (
        "multibody",
        "capstan",
        "measured 5.7e-4 m (a wire threaded through a tight bend, \
         unstable later)",
    ),
    ("multibody", "stick-slip-threshold", "measured 4.8e-6 m"),
];

/// The registered models, or those `SURGBENCH_MODELS` names.
fn models() -> Vec<&'static dyn ModelFactory> {
    let only = std::env::var("SURGBENCH_MODELS").ok();
    let all: Vec<_> = registry::models().into_iter().map(|r| r.factory).collect();
    match only {
        None => all,
        Some(ids) => {
            let ids: Vec<&str> = ids.split(',').map(str::trim).collect();
            for id in &ids {
                assert!(
                    all.iter().any(|f| f.id() == *id),
                    "SURGBENCH_MODELS: unknown model `{id}`"
                );
            }
            all.into_iter().filter(|f| ids.contains(&f.id())).collect()
        }
    }
}

#[test]
fn every_model_crate_is_registered() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let registered: Vec<&str> = registry::models().iter().map(|r| r.krate).collect();
    for e in std::fs::read_dir(&dir).unwrap() {
        let e = e.unwrap();
        if !e.path().join("Cargo.toml").is_file() {
            continue;
        }
        let name = e.file_name().to_string_lossy().replace('-', "_");
        if name == "core" {
            continue;
        }
        let krate = format!("surgbench_{name}");
        assert!(
            registered.contains(&krate.as_str()),
            "models/{name} ({krate}) has no factory in registry::models(): {registered:?}"
        );
    }
}

#[test]
fn ids_are_unique_and_every_model_runs_something() {
    let ms = registry::models();
    for (i, a) in ms.iter().enumerate() {
        for b in &ms[i + 1..] {
            assert_ne!(a.factory.id(), b.factory.id(), "duplicate model id");
        }
    }
    for r in &ms {
        assert!(!r.factory.description().is_empty());
        if conformance::supported(r.factory).is_empty() {
            // A rod x tissue pair whose halves lack the coupling hooks is
            // registered for the pair matrix: it must refuse the pair scene
            // with a reason that names what is missing.
            let sc = registry::scenario("catheter-compliant-vessel").unwrap();
            let p = surgbench_comparisons::scenario::Params::resolve(sc.id(), sc.params(), &[]).unwrap();
            let run = sc.instantiate(&p).unwrap();
            let why = r.factory.check(run.scene()).err();
            assert!(
                r.factory.family() == surgbench_core::Family::Pair
                    && why.as_ref().is_some_and(|u| u.reason.contains("does not model")),
                "{} runs no scenario of the catalogue ({why:?})",
                r.factory.id()
            );
        }
    }
}

#[test]
fn same_inputs_give_bit_identical_results() {
    for f in models() {
        for note in conformance::deterministic(f).unwrap_or_else(|e| panic!("{e}")) {
            eprintln!("note: {note}");
        }
    }
}

#[test]
fn rigid_motion_of_the_scene_moves_the_answer_rigidly() {
    for f in models() {
        for note in conformance::rigid_motion(f, KNOWN_FRAME_DEPENDENT).unwrap_or_else(|e| panic!("{e}")) {
            eprintln!("note: {note}");
        }
    }
}

#[test]
fn forces_are_minus_the_energy_gradient() {
    let mut checked = 0;
    for f in models() {
        checked += conformance::energy_gradient(f).unwrap_or_else(|e| panic!("{e}"));
    }
    eprintln!("energy-gradient conformance checked on {checked} model/scenario pairs");
    // DER has an energy: with it in the run, the check must have run.
    if models().iter().any(|f| f.id() == "der") {
        assert!(checked >= 1, "no model exposed an energy probe");
    }
}

/// Every model an iterated coupling can retry a step with (DER, pbd-rod
/// and the three tissues) restores its saved state bit for bit.
#[test]
fn a_saved_state_restores_bit_for_bit() {
    let mut checked = Vec::new();
    for f in models() {
        if conformance::restores_state(f).unwrap_or_else(|e| panic!("{e}")) {
            checked.push(f.id());
        }
    }
    eprintln!("save/restore checked on {checked:?}");
    for id in ["der", "pbd-rod", "fem", "pbd-tissue", "meshless"] {
        if models().iter().any(|f| f.id() == id) {
            assert!(
                checked.contains(&id),
                "{id} saves no state, or diverged before the save"
            );
        }
    }
}

#[test]
fn unsupported_scenes_are_refused_with_a_reason() {
    for f in models() {
        conformance::refuses_unsupported(f).unwrap_or_else(|e| panic!("{e}"));
    }
}
