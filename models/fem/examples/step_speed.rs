//! Speed against accuracy of the dynamic step on the bench block
//! (12,960 tets / 2,704 nodes, corotational, Newmark, bottom fixed, top
//! pressed down 5 mm over 20 steps and then held), for every linear-solver
//! trick, against the full-update Cholesky reference (every element block
//! rebuilt and refactorized every step).
//!
//! `cargo run --release -p surgbench-fem --example step_speed -- [threads] [held_steps]`
//!
//! Prints, per configuration: median and mean wall time per step over the
//! ramp and over the held steps (ms), factorizations, CG iterations, and the
//! largest node distance to the reference over all steps divided by the
//! largest reference displacement (the relative node error).

use std::time::Instant;
use surgbench_core::{TissueBody, Vec3};
use surgbench_fem::bench_support::bench_block;
use surgbench_fem::{DynParams, FemModel, LinearSolver, Ordering};

struct Run {
    traj: Vec<Vec<Vec3>>,
    ramp_ms: Vec<f64>,
    held_ms: Vec<f64>,
    counts: (usize, usize),
}

fn run(b: &TissueBody, p: DynParams, ramp: usize, held: usize) -> Run {
    let mut m = FemModel::new(b, Vec3::zeros(), 1e-3, p).expect("model");
    let mut out = Run {
        traj: Vec::new(),
        ramp_ms: Vec::new(),
        held_ms: Vec::new(),
        counts: (0, 0),
    };
    for k in 0..ramp + held {
        let s = ((k + 1) as f64 / ramp as f64).min(1.0);
        let t0 = Instant::now();
        m.advance(1e-3, s).expect("step");
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if k < ramp {
            out.ramp_ms.push(ms);
        } else {
            out.held_ms.push(ms);
        }
        out.traj.push(m.positions().to_vec());
    }
    out.counts = m.solver_counts();
    out
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() { f64::NAN } else { s[s.len() / 2] }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The reference configuration (full Cholesky refactorization every step)
/// and every linear-solver trick measured against it, by name.
fn configs(threads: usize) -> (DynParams, Vec<(&'static str, DynParams)>) {
    let base = DynParams {
        rayleigh_mass: 5.0,
        threads,
        ..Default::default()
    };
    let cg = |tol: f64| LinearSolver::Cg { tol, max_iter: 500 };
    let base = DynParams {
        factor_reuse: false,
        ..base
    };
    let chol = |lazy: f64, reuse: bool| DynParams {
        lazy_threshold: lazy,
        factor_reuse: reuse,
        ..base
    };
    let chol_tol = |lazy: f64, reuse_tol: f64| DynParams {
        lazy_threshold: lazy,
        factor_reuse: true,
        reuse_tol,
        ..base
    };
    // Nested-dissection ordering, optionally with the f32 preconditioner.
    let nd = |p: DynParams, f32: bool| DynParams {
        solver: LinearSolver::Cholesky(Ordering::NestedDissection),
        reuse_f32: f32,
        ..p
    };
    let amd = |p: DynParams, f32: bool| DynParams {
        solver: LinearSolver::Cholesky(Ordering::Amd),
        reuse_f32: f32,
        ..p
    };
    let cgp = |tol: f64, lazy: f64| DynParams {
        solver: cg(tol),
        lazy_threshold: lazy,
        ..base
    };
    let configs: Vec<(&str, DynParams)> = vec![
        ("reference: cholesky, refactor every step", base),
        (
            "scheme error: 3 Newton iterations per step",
            DynParams { iterations: 3, ..base },
        ),
        ("cholesky, stale-factor PCG, lazy 0", chol(0.0, true)),
        ("amd, refactor every step", amd(base, false)),
        ("amd, stale-factor PCG, lazy 0", amd(chol(0.0, true), false)),
        ("amd, stale-factor PCG f32, lazy 0", amd(chol(0.0, true), true)),
        ("amd, stale-factor PCG f32, lazy 0.05", amd(chol(0.05, true), true)),
        ("nd, refactor every step", nd(base, false)),
        ("nd, stale-factor PCG, lazy 0", nd(chol(0.0, true), false)),
        ("nd, stale-factor PCG f32, lazy 0", nd(chol(0.0, true), true)),
        ("nd, stale-factor PCG, lazy 0.05", nd(chol(0.05, true), false)),
        ("nd, stale-factor PCG f32, lazy 0.05", nd(chol(0.05, true), true)),
        ("cholesky, stale-factor PCG, lazy 0.01", chol(0.01, true)),
        ("cholesky, refactor on change, lazy 0.05", chol(0.05, false)),
        ("cholesky, stale-factor PCG, lazy 0.05", chol(0.05, true)),
        ("cholesky, stale-factor PCG 1e-4, lazy 0", chol_tol(0.0, 1e-4)),
        ("cholesky, stale-factor PCG 1e-5, lazy 0", chol_tol(0.0, 1e-5)),
        ("cholesky, stale-factor PCG 1e-4, lazy 0.05", chol_tol(0.05, 1e-4)),
        ("cg 1e-3, lazy 0", cgp(1e-3, 0.0)),
        ("cg 1e-4, lazy 0", cgp(1e-4, 0.0)),
        ("cg 1e-5, lazy 0", cgp(1e-5, 0.0)),
        ("cg 1e-6, lazy 0", cgp(1e-6, 0.0)),
        ("cg 1e-8, lazy 0", cgp(1e-8, 0.0)),
        ("cg 1e-6, lazy 0.05", cgp(1e-6, 0.05)),
    ];
    (base, configs)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let threads: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(2);
    let held: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(40);
    // Third argument: one configuration name (exact), or `all`.
    let only: Option<&str> = args.get(3).map(|s| s.as_str());
    let b = bench_block();
    let (base, configs) = configs(threads);
    let ramp: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(20);
    // `skip` as the fifth argument: no reference run (profiling one configuration).
    let skip_ref = args.get(5).is_some_and(|s| s == "skip");
    let reference = if skip_ref {
        run(&b, base, 1, 0)
    } else {
        run(&b, base, ramp, held)
    };
    let scale = reference
        .traj
        .iter()
        .flat_map(|x| x.iter().zip(&b.mesh.nodes).map(|(p, q)| (p - q).norm()))
        .fold(0.0, f64::max);
    println!("threads {threads}, ramp {ramp} + held {held} steps, max reference displacement {scale:.3e} m");
    println!(
        "config | ramp ms/step median mean | held ms/step median mean | factorizations, CG iterations | max node error / max displacement"
    );
    for (name, p) in configs {
        if only.is_some_and(|o| o != "all" && o != name) {
            continue;
        }
        let r = run(&b, p, ramp, held);
        let err = r
            .traj
            .iter()
            .zip(&reference.traj)
            .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).norm()))
            .fold(0.0, f64::max)
            / scale;
        println!(
            "{name} | {:.2} {:.2} | {:.2} {:.2} | {:?} | {err:.2e}",
            median(&r.ramp_ms),
            mean(&r.ramp_ms),
            median(&r.held_ms),
            mean(&r.held_ms),
            r.counts
        );
    }
}
