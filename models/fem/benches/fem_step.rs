//! One Newmark step (beta = 1/4, one Newton iteration) of a corotational
//! block of 12,960 tets / 2,704 nodes (the needle-insertion seed's prostate
//! size is 13,375 tets / 2,763 vertices), bottom fixed, top driven, 2 threads:
//! * `cholesky_reuse`: lazy threshold 0.05 rad; the factorization is reused
//!   as is while no block changed, and preconditions CG otherwise
//!   (`factor_reuse`), refactorized when that CG ages past 6 iterations;
//! * `cholesky_pcg`: every element rebuilt (lazy 0), same factor reuse: the
//!   accurate setting (2 factorizations in 60 steps, node error 7e-7 of the
//!   stroke against `cholesky_refactor`, examples/step_speed.rs);
//! * `cholesky_refactor`: every element rebuilt, numeric refactorization every step;
//! * `cg`: block-Jacobi PCG to 1e-6 (warm-started), every element rebuilt.
//!
//! Each at 1 and 2 assembly threads.
//!
//! Target (DESIGN.md): <= 10 ms per step.

use criterion::{Criterion, criterion_group, criterion_main};
use std::time::Duration;
use surgbench_core::{SolidMaterial, TissueBody, Vec3, mesh};
use surgbench_fem::{DynParams, FemModel, LinearSolver};

fn body() -> TissueBody {
    let size = Vec3::new(0.04, 0.04, 0.05);
    let m = mesh::block(size, [12, 12, 15]);
    let material = SolidMaterial {
        youngs_modulus: 6e4,
        poisson_ratio: 0.45,
        density: 1050.0,
    };
    let mut b = TissueBody::new(m.clone(), material);
    b.fixed_nodes = mesh::nodes_on_plane(&m, 2, 0.0, 1e-12);
    b.driven_nodes = mesh::nodes_on_plane(&m, 2, size.z, 1e-12)
        .into_iter()
        .map(|i| (i, Vec3::new(0.0, 0.0, -0.005)))
        .collect();
    b
}

fn bench(c: &mut Criterion) {
    let b = body();
    let mut g = c.benchmark_group("fem_newmark_step_12960_tets");
    g.sample_size(20)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    let cg = LinearSolver::Cg {
        tol: 1e-6,
        max_iter: 500,
    };
    let chol = LinearSolver::default();
    let cases = [
        ("cholesky_reuse", chol, 0.05, true),
        ("cholesky_pcg", chol, 0.0, true),
        ("cholesky_refactor", chol, 0.0, false),
        ("cg", cg, 0.0, true),
    ];
    for threads in [1, 2] {
        for (name, solver, lazy, factor_reuse) in cases {
            let p = DynParams {
                solver,
                lazy_threshold: lazy,
                factor_reuse,
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
