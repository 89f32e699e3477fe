//! The seed's CG solver of the LCP trials (`lcp_solver = "cg"`) against the
//! Schur complement (the default): the same scenes, step by step, agree to
//! the CG tolerance, and the CG does its work in a bounded number of
//! iterations.

mod common;

use surgbench_core::{Fidelity, Model, ModelFactory, Scene};
use surgbench_needle::NeedleFactory;

const V: f64 = 0.01;

/// Per step: the axial force the hand applies (N), the tip (m) and the
/// friction states `[static, forward, backward]` counts.
struct Trace {
    push: Vec<f64>,
    tip: Vec<[f64; 3]>,
    states: Vec<[f64; 3]>,
    diag: std::collections::BTreeMap<String, f64>,
}

fn run(scene: &Scene, settings: &[&str]) -> Trace {
    let mut pairs: Vec<String> = vec!["segments=20".into()];
    pairs.extend(settings.iter().map(|s| s.to_string()));
    let f = Fidelity::parse_pairs(&pairs).unwrap();
    let mut m: Box<dyn Model> = NeedleFactory.build(scene, &f).unwrap();
    let dt = m.dt();
    let n = (scene.duration / dt).round() as usize;
    let mut t = Trace {
        push: Vec::new(),
        tip: Vec::new(),
        states: Vec::new(),
        diag: Default::default(),
    };
    for i in 1..=n {
        m.step(dt, &scene.control.command_at(i as f64 * dt)).unwrap();
        let o = m.observe();
        let d = m.diagnostics();
        t.push.push(-o.hand_force.x);
        let tip = o.rods[0].tip();
        t.tip.push([tip.x, tip.y, tip.z]);
        t.states
            .push([d["static_points"], d["forward_points"], d["backward_points"]]);
        t.diag = d;
    }
    t
}

/// Insert 6 mm at `V` with viscous friction, hold, retract 4 mm: every
/// friction state, viscous rows and the tip's cutting bound are exercised.
fn scene() -> Scene {
    scene_on([8, 4, 4])
}

/// [`scene`] on a block of `cells` lattice cells.
fn scene_on(cells: [usize; 3]) -> Scene {
    let x1 = 7e-3;
    let feed = [(0.0, 0.0), (x1 / V, x1), (x1 / V + 0.1, x1), (x1 / V + 0.5, x1 - 4e-3)];
    let mut s = common::scene(&feed, cells, 20.0, 0.05);
    s.needle.as_mut().expect("a needle scene").viscous_friction = 50.0;
    s
}

/// Worst differences over the run: (force, N; tip, m; steps whose
/// friction states differ).
fn differences(a: &Trace, b: &Trace) -> (f64, f64, usize) {
    assert_eq!(a.push.len(), b.push.len());
    let (mut f, mut x, mut states) = (0.0f64, 0.0f64, 0);
    for i in 0..a.push.len() {
        f = f.max((a.push[i] - b.push[i]).abs());
        x = (0..3).fold(x, |x, c| x.max((a.tip[i][c] - b.tip[i][c]).abs()));
        states += usize::from(a.states[i] != b.states[i]);
    }
    (f, x, states)
}

#[test]
fn cg_and_schur_agree_step_by_step() {
    let s = scene();
    let schur = run(&s, &[]);
    let cg = run(&s, &["lcp_solver=cg"]);
    let fine = run(&s, &["lcp_solver=cg", "cg_tolerance=1e-10"]);
    let peak = schur.push.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    let (df, dx, ds) = differences(&schur, &cg);
    let (df_fine, dx_fine, ds_fine) = differences(&schur, &fine);
    eprintln!(
        "peak force {peak:.4e} N; CG at 1e-8: force {df:.3e} N, tip {dx:.3e} m; at 1e-10: force {df_fine:.3e} N, tip {dx_fine:.3e} m"
    );
    eprintln!("cg diagnostics {:?}", cg.diag);
    // Both solve the same trials: the same friction states every step.
    assert_eq!((ds, ds_fine), (0, 0), "steps whose friction states differ");
    // The difference is the CG's: 100x tighter, at least 10x smaller (measured
    // 1.8e-6 -> 6.8e-9 N; a modelling difference would not shrink).
    assert!(
        df_fine <= df / 10.0,
        "force difference {df:.3e} -> {df_fine:.3e} N with the tolerance"
    );
    // Measured 1.4e-5 of the peak at the default tolerance: 1e-4 bounds it
    // with the margin of a different platform's rounding.
    assert!(df <= 1e-4 * peak, "force differs by {df:.3e} N of {peak:.3e} N");
    // The stiff needle's tip is set by the feed: differences at round-off
    // of its 1e-2 m position (measured 1.4e-13 m).
    assert!(dx <= 1e-9, "tip differs by {dx:.3e} m");
    assert_eq!(cg.diag["cg_unconverged_solves"], 0.0);
    // Every step solves at least the unconstrained system.
    assert!(cg.diag["cg_iterations_mean"] >= 1.0);
    assert!(
        !schur.diag.contains_key("cg_iterations_mean"),
        "the Schur solver has no CG iterations"
    );
}

#[test]
fn a_cg_tolerance_without_the_cg_solver_is_refused() {
    let f = Fidelity::parse_pairs(&["cg_tolerance=1e-6".to_string()]).unwrap();
    let err = NeedleFactory.build(&scene(), &f).err().expect("refused");
    assert!(err.to_string().contains("cg_tolerance"), "{err}");
    let f = Fidelity::parse_pairs(&["lcp_solver=cg".to_string(), "cg_tolerance=1e-6".to_string()]).unwrap();
    assert!(NeedleFactory.build(&scene(), &f).is_ok());
}

/// With a lazy Jacobian the tissue's factor stays for many steps and the
/// Schur solver keeps the tissue's Delassus columns of earlier steps,
/// solving only new points (the tip's new channel end): its steps still
/// agree with the CG solver's, which builds nothing across steps, as
/// closely as without the lazy Jacobian. A kept column of the wrong factor
/// or point would show as a force difference of the size of the friction.
#[test]
fn kept_delassus_columns_agree_with_the_cg_solver() {
    // A block fine enough that faer picks a supernodal factor (the
    // default scene's is simplicial: no columns to keep).
    let s = scene_on([12, 6, 6]);
    let lazy = ["lazy_threshold=0.1"];
    let schur = run(&s, &lazy);
    let cg = run(&s, &["lazy_threshold=0.1", "lcp_solver=cg"]);
    let peak = schur.push.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    let (df, dx, ds) = differences(&schur, &cg);
    let reused = schur.diag["delassus_points_reused_fraction"];
    eprintln!(
        "lazy: force {df:.3e} N of {peak:.3e} N, tip {dx:.3e} m; columns reused {reused:.3}; {} factorizations in {} steps",
        schur.diag["tissue_factorizations"],
        schur.push.len()
    );
    // Most points' columns come from earlier steps (else this tests nothing).
    assert!(reused > 0.5, "reused fraction {reused}");
    assert!(schur.diag["tissue_factorizations"] < 0.5 * schur.push.len() as f64);
    assert_eq!(ds, 0, "steps whose friction states differ");
    // The same bounds as at the default (the CG's tolerance, 1e-8).
    assert!(df <= 1e-4 * peak, "force differs by {df:.3e} N of {peak:.3e} N");
    assert!(dx <= 1e-9, "tip differs by {dx:.3e} m");
}
