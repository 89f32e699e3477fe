//! The README's "Adding a scenario" walk-through, followed literally: its
//! code block is `tests/readme/scenario.rs` (checked here to the letter), and
//! the scenario it defines resolves its parameters, refuses a misspelt one,
//! and runs through the harness's runner with a registered model.

#[path = "readme/scenario.rs"]
mod example;

use example::{ROD_AT_REST, RestParams};
use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::{ParamSet, Params, Scenario};
use surgbench_core::Fidelity;

/// The README section's `rust` code block.
fn readme_block(section: &str) -> String {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md")).unwrap();
    let at = readme
        .find(section)
        .unwrap_or_else(|| panic!("README has no `{section}`"));
    let rest = &readme[at..];
    let start = rest.find("```rust\n").expect("a rust block in the section") + "```rust\n".len();
    let len = rest[start..].find("```\n").expect("the block ends");
    rest[start..start + len].to_string()
}

#[test]
fn the_readme_example_is_this_file() {
    let file = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/readme/scenario.rs")).unwrap();
    assert_eq!(
        readme_block("## Adding a scenario"),
        file,
        "README's scenario example and comparisons/tests/readme/scenario.rs differ"
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
