//! The README's "Adding a model variant" walk-through, followed literally:
//! its code block is `tests/readme/model.rs` (checked here to the letter);
//! the model it defines passes the conformance suite and runs a catalogue
//! scenario through the runner with the results its physics predicts.

#[path = "readme/block.rs"]
mod block;
#[path = "readme/model.rs"]
mod example;

use example::RigidRodFactory;
use surgbench_comparisons::conformance;
use surgbench_comparisons::resolve::ResolvedRun;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::{Params, Scenario};
use surgbench_comparisons::scenarios::rod::CANTILEVER_GRAVITY;
use surgbench_core::{Fidelity, ModelFactory};

#[test]
fn the_readme_example_is_this_file() {
    block::assert_block_is_file(
        concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"),
        "## Adding a model variant",
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/readme/model.rs"),
    );
}

#[test]
fn the_example_passes_the_conformance_suite() {
    let f = &RigidRodFactory;
    let scenes: Vec<String> = conformance::supported(f).into_iter().map(|(id, _)| id).collect();
    assert!(
        scenes.contains(&"cantilever-gravity".to_string()) && scenes.contains(&"cantilever-tip-load".to_string()),
        "{scenes:?}"
    );
    conformance::deterministic(f).unwrap();
    conformance::rigid_motion(f, &[]).unwrap();
    assert_eq!(conformance::energy_gradient(f).unwrap(), 0, "no energy probe");
    conformance::refuses_unsupported(f).unwrap();
}

#[test]
fn the_example_scores_as_the_rigid_limit() {
    let p = Params::resolve("cantilever-gravity", CANTILEVER_GRAVITY.params(), &[]).unwrap();
    let run = CANTILEVER_GRAVITY.instantiate(&p).unwrap();
    let fid = Fidelity::default();
    let s = run_single(
        &CANTILEVER_GRAVITY,
        &p,
        &run,
        &RigidRodFactory,
        &fid,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(s.status.to_string(), "ok", "{}", s.reason);
    // The rigid tip stays at (L, 0, 0): its error is the whole deflection.
    assert!((s.errors["tip_error_rel"] - 1.0).abs() < 1e-12, "{:?}", s.errors);
    // The clamp carries the whole weight, a sum of 20 segment weights:
    // exact to rounding.
    assert!(s.errors["hand_force_error_rel"] < 1e-12, "{:?}", s.errors);
    // Twist is not in its capabilities: refused with the missing name.
    let why = RigidRodFactory
        .check(
            ResolvedRun::new("torque-transfer", "der", &[], Fidelity::default())
                .unwrap()
                .scene(),
        )
        .unwrap_err();
    assert!(why.reason.contains("twist"), "{}", why.reason);
}
