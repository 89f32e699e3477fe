//! The repeat budget (`RunOptions::repeat_budget_s`, `run-one
//! --repeat-budget`, a comparison's `repeat_budget_s`): further repeats
//! start only while the repeats so far took less than the budget, and the
//! summary counts the repeats done; the results do not depend on it.

mod common;
use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::Scenario;
use surgbench_comparisons::scenarios::tissue::BLOCK_COMPRESSION;
use surgbench_core::Fidelity;
use surgbench_reports::RunSummary;

/// fem on block compression at mesh level 0 with `repeats` and `budget`.
fn run(repeats: usize, budget: f64) -> RunSummary {
    let scenario: &dyn Scenario = &BLOCK_COMPRESSION;
    let fid = Fidelity {
        mesh_level: Some(0),
        ..Default::default()
    };
    let p = common::params(scenario, &[]);
    let inst = scenario.instantiate_at(&p, &fid).unwrap();
    let opts = RunOptions {
        repeats,
        repeat_budget_s: budget,
        ..Default::default()
    };
    let s = run_single(scenario, &p, &inst, registry::model("fem").unwrap(), &fid, &opts).unwrap();
    assert_eq!(s.status, "ok", "{}", s.reason);
    s
}

#[test]
fn repeats_stop_once_the_budget_is_spent_and_the_results_stay() {
    let all = run(3, f64::INFINITY);
    // Any first repeat takes more than a nanosecond: no second one.
    let one = run(3, 1e-9);
    assert_eq!((all.repeats, one.repeats), (3, 1));
    assert_eq!(all.errors, one.errors);
    assert_eq!(all.outcome.steps, one.outcome.steps);
}
