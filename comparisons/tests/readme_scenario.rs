//! The README's "Adding a scenario" walk-through, followed literally: its
//! code block is `tests/readme/scenario.rs` (checked here to the letter), and
//! the scenario it defines resolves its parameters, refuses a misspelt one,
//! and runs through the harness's runner with a registered model.

#[path = "../../tests/readme/block.rs"]
mod block;
#[path = "readme/scenario.rs"]
mod example;

use example::{ROD_AT_REST, RestParams};
use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::{ParamSet, Params, Scenario};
use surgbench_core::Fidelity;

#[test]
fn the_readme_example_is_this_file() {
    block::assert_block_is_file(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"),
        "## Adding a scenario",
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/readme/scenario.rs"),
    );
}

#[test]
fn the_example_resolves_and_refuses_a_misspelt_parameter() {
    let p = Params::resolve("rod-at-rest", ROD_AT_REST.params(), &[("length".into(), 0.2)]).unwrap();
    assert_eq!(RestParams::of(&p).length, 0.2);
    assert_eq!(RestParams::of(&p).radius, 5e-4, "unset parameters take their defaults");
    let e = Params::resolve("rod-at-rest", ROD_AT_REST.params(), &[("lenght".into(), 0.2)]).unwrap_err();
    assert!(e.0.contains("no parameter `lenght`"), "{e}");
}

#[test]
fn the_example_runs_through_the_runner() {
    let p = Params::resolve("rod-at-rest", ROD_AT_REST.params(), &[]).unwrap();
    let run = ROD_AT_REST.instantiate_at(&p, &Fidelity::default()).unwrap();
    let der = registry::model("der").unwrap();
    let s = run_single(
        &ROD_AT_REST,
        &p,
        &run,
        der,
        &Fidelity::default(),
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(s.status.to_string(), "ok", "{}", s.reason);
    // An unloaded DER rod does not move: the tip stays at (L, 0, 0) to
    // round-off of the rest configuration (1e-12 of the 0.1 m length).
    assert!(s.errors["tip_error_m"] < 1e-13, "{:?}", s.errors);
}
