//! One Newmark step (beta = 1/4, one Newton iteration) of a corotational
//! block of 12,960 tets / 2,704 nodes (the needle-insertion seed's prostate
//! size is 13,375 tets / 2,763 vertices), bottom fixed, top driven. The
//! Cholesky cases use the default ordering (automatic: nested dissection
//! on this block, by fewer factor non-zeros) unless named
//! `_amd`, and the stale-factor CG applies the `f32` two-way parallel copy
//! of the factor (`reuse_f32`, default) unless named `_f64`:
//! * `cholesky_reuse`: lazy threshold 0.05 rad; the factorization is reused
//!   as is while no block changed, and preconditions CG otherwise
//!   (`factor_reuse`), refactorized once that CG's extra solves have cost
//!   about one factorization;
//! * `cholesky_pcg`: every element rebuilt (lazy 0), same factor reuse: the
//!   accurate setting (5 factorizations and 278 CG iterations in 60 steps,
//!   node error 6.8e-7 of the stroke against `cholesky_refactor`, the same
//!   for `f32`/`f64` and ND/AMD; examples/step_speed.rs);
//! * `cholesky_pcg_f64`, `cholesky_pcg_amd_f64` (the previous default):
//!   the same with the `f64` factor (faer's sequential solve);
//! * `cholesky_refactor`, `cholesky_refactor_amd`: every element rebuilt,
//!   numeric refactorization every step;
//! * `cholesky_pcg_tol1e-4`: `cholesky_pcg` with the stale-factor CG to a
//!   relative residual of 1e-4 instead of 1e-6 (`reuse_tol`; node error
//!   against `cholesky_refactor` in examples/step_speed.rs);
//! * `cg`: block-Jacobi PCG to 1e-6 (warm-started), every element rebuilt;
//! * `cg_tol1e-4`: the same to 1e-4 (node error 2.4e-4 of the stroke
//!   against `cholesky_refactor` over 60 steps, 250 times below the
//!   one-Newton-step scheme's own 6.0e-2; examples/step_speed.rs).
//!
//! Each at 1 and 2 threads. Target (DESIGN.md): <= 10 ms per step.
//!
//! Measured (criterion medians, ms per step, 2-core AMD EPYC shared with
//! another build, load average 2.7-3.6: the 2-thread column is inflated by
//! that contention, e.g. `cg` ran slower at 2 threads than at 1; compare
//! cases within a column):
//!
//! | case | 1 thread | 2 threads |
//! |---|---|---|
//! | `cholesky_reuse` | 8.8 | 8.1 |
//! | `cholesky_pcg` | 12.1 | 12.7 |
//! | `cholesky_pcg_f64` | 16.0 | 17.0 |
//! | `cholesky_pcg_amd_f64` | 19.2 | 22.8 |
//! | `cholesky_refactor` | 39.8 | 41.4 |
//! | `cholesky_refactor_amd` | 55.9 | 55.8 |
//! | `cholesky_pcg_tol1e-4` | 11.4 | 12.9 |
//! | `cg` | 11.4 | 12.2 |
//! | `cg_tol1e-4` | 9.3 | 10.7 |
//!
//! `cholesky_pcg` costs what `cg` costs in the same run (ratio 1.04 at 2
//! threads), and `cg` measured 5.8-8.3 ms per step on a quieter machine; in
//! a quieter moment examples/step_speed.rs gave `cholesky_pcg` at 2
//! threads a median of 7.3 ms and a mean of 9.3 ms over the held steps
//! (the mean carries the refactorizations, about 40 ms each, one every
//! ~14 steps). `cholesky_refactor` stays far above 10 ms: one numeric
//! factorization is 339 M instructions with nested dissection (517 M with
//! AMD; examples/factor_cost.rs).
//!
//! Instructions (callgrind, 1 thread, examples/step_speed.rs with 60 held
//! steps minus with none, over 60): `cholesky_pcg` 124 M per held step, the previous default
//! (AMD, `f64` preconditioner) 135 M; both 4.65 CG iterations and one
//! refactorization per 15 steps. The wall-time gain is mostly what
//! instruction counts do not see: the triangular solves are bound by
//! reading the factor (18 MB in `f64`, 9 MB in `f32`) and the `f32` solve
//! runs its two bins on two threads.

use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;
use surgbench_core::Vec3;
use surgbench_fem::bench_support::bench_block;
use surgbench_fem::{DynParams, FemModel, LinearSolver, Ordering, REUSE_TOL};

fn bench(c: &mut Criterion) {
    let b = bench_block();
    let mut g = c.benchmark_group("fem_newmark_step_12960_tets");
    g.sample_size(20)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    let cg = |tol: f64| LinearSolver::Cg { tol, max_iter: 500 };
    // Default: automatic ordering (nested dissection here), f32 two-way preconditioner.
    let chol = LinearSolver::default();
    let amd = LinearSolver::Cholesky(Ordering::Amd);
    let cases = [
        ("cholesky_reuse", chol, 0.05, true, true),
        ("cholesky_pcg", chol, 0.0, true, true),
        ("cholesky_pcg_f64", chol, 0.0, true, false),
        ("cholesky_pcg_amd_f64", amd, 0.0, true, false),
        ("cholesky_refactor", chol, 0.0, false, true),
        ("cholesky_refactor_amd", amd, 0.0, false, true),
        ("cholesky_pcg_tol1e-4", chol, 0.0, true, true),
        ("cg", cg(1e-6), 0.0, true, true),
        ("cg_tol1e-4", cg(1e-4), 0.0, true, true),
    ];
    for threads in [1, 2] {
        for (name, solver, lazy, factor_reuse, reuse_f32) in cases {
            let p = DynParams {
                solver,
                lazy_threshold: lazy,
                factor_reuse,
                reuse_f32,
                reuse_tol: if name.ends_with("tol1e-4") { 1e-4 } else { REUSE_TOL },
                rayleigh_mass: 5.0,
                threads,
                ..Default::default()
            };
            let mut m = FemModel::new(&b, Vec3::zeros(), 1e-3, p).expect("bench model");
            // Ramp the plate to full stroke, then hold: the bench measures held steps.
            for k in 0..20 {
                m.advance(1e-3, (k + 1) as f64 / 20.0).expect("warm-up step");
            }
            g.bench_function(format!("{name}_{threads}t"), |bn| {
                bn.iter(|| m.advance(1e-3, 1.0).expect("step"))
            });
            eprintln!(
                "{name} {threads}t: factor nnz {:?}, (factorizations, CG iterations) {:?}",
                m.factor_nnz(),
                m.solver_counts()
            );
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
