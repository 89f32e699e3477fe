//! Issue 20, item 3: static scenes solved as statics. At their defaults
//! fem and meshless take one harness step to the whole load (their own
//! adaptive load stepping inside it), the runner's second step finds the
//! state unchanged and ends the run settled, and the answer is the one ten
//! fixed load steps reach, to the solvers' tolerances.

mod common;
use surgbench_comparisons::registry;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::Scenario;
use surgbench_comparisons::scenarios::tissue::{BLOCK_COMPRESSION, LAME_TUBE};
use surgbench_core::{Fidelity, Setting};

fn fidelity(level: usize, dt: Option<f64>) -> Fidelity {
    Fidelity {
        mesh_level: Some(level),
        dt,
        ..Default::default()
    }
}

/// `(primary error, steps, diagnostics)` of `model` on `scenario` at `fid`.
fn run(scenario: &dyn Scenario, model: &str, fid: &Fidelity) -> (f64, usize, std::collections::BTreeMap<String, f64>) {
    let p = common::params(scenario, &[]);
    let inst = scenario.instantiate_at(&p, fid).unwrap();
    let s = run_single(
        scenario,
        &p,
        &inst,
        registry::model(model).unwrap(),
        fid,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(s.status, "ok", "{model} on {}: {}", scenario.id(), s.reason);
    assert_eq!(s.end, "settled", "{model} on {}", scenario.id());
    let e = s.errors[&s.primary_error];
    (e, s.steps.unwrap() as usize, s.errors.clone())
}

#[test]
fn the_default_static_solve_matches_ten_load_steps() {
    // Tolerances: fem's Newton stops at a relative force residual of 1e-9
    // (measured differences 1e-8 of the error or less); meshless's
    // Newton-CG at an absolute per-node force tolerance with CG to 1e-2
    // (measured 9e-6 of the error on the Lamé tube at level 1): 1e-6 and
    // 1e-4 of the error leave a decade of margin.
    for (model, tol) in [("fem", 1e-6), ("meshless", 1e-4)] {
        for scenario in [&BLOCK_COMPRESSION as &dyn Scenario, &LAME_TUBE] {
            let (stepped, steps_10, _) = run(scenario, model, &fidelity(1, Some(0.025)));
            let (solved, steps, diag) = run(scenario, model, &fidelity(1, None));
            let id = scenario.id();
            assert!(steps_10 >= 10, "{model} on {id}: {steps_10} steps at dt = 0.025 s");
            // One step solves the whole load, the second finds nothing to do.
            assert_eq!(steps, 2, "{model} on {id}");
            assert!(diag["diag_load_increments"] >= 1.0, "{model} on {id}: {diag:?}");
            assert!(
                (solved - stepped).abs() <= tol * stepped.abs(),
                "{model} on {id}: {solved:e} as one static solve, {stepped:e} in 10 load steps"
            );
        }
    }
}

#[test]
fn a_dynamic_integrator_on_a_static_scene_keeps_the_dynamic_time_step() {
    let p = common::params(&BLOCK_COMPRESSION, &[]);
    let inst = BLOCK_COMPRESSION.instantiate_at(&p, &fidelity(0, None)).unwrap();
    for (model, integrator) in [("fem", "newmark"), ("meshless", "backward-euler")] {
        let f = registry::model(model).unwrap();
        let settings = surgbench_core::resolve(f, inst.scene(), &Fidelity::default()).unwrap();
        assert_eq!(
            settings.fidelity().dt,
            Some(0.25),
            "{model}: one step to the end of the ramp"
        );
        let mut dynamic = Fidelity::default();
        dynamic
            .extras
            .insert("integrator".into(), Setting::Choice(integrator.into()));
        let settings = surgbench_core::resolve(f, inst.scene(), &dynamic).unwrap();
        assert_eq!(settings.fidelity().dt, Some(1e-3), "{model} with {integrator}");
        // A time step the caller names is kept.
        dynamic.dt = Some(0.01);
        let settings = surgbench_core::resolve(f, inst.scene(), &dynamic).unwrap();
        assert_eq!(settings.fidelity().dt, Some(0.01), "{model} with {integrator} and dt");
    }
}
