//! Criterion benchmark of every gated workload (`benches/gate.toml`): wall
//! time of `steps` steps from a freshly built model (build excluded), in the
//! group `workload`, and of each static solve (`static_solve = true`: the
//! first step, which solves the whole load) in the group `static_solve`.
//! For people: criterion's wall-clock numbers swing on shared machines and
//! never fail a build; the CI gate counts instructions instead
//! (`surgbench gate`).
//!
//! `static_solve` on the Lamé tube of issue 20 (mesh level 2 of a = 2 mm,
//! b = 3.5 mm: 6,300 nodes, 31,104 tets; E = 0.8 MPa, nu = 0.45, 1.6 kPa),
//! fem at its defaults: `datasets/reference/static_solve_timing.py` runs it
//! and scikit-fem (P1, direct solve) on the same mesh one after the other;
//! on a quiet 2-core Xeon, twice: 0.59 and 0.67 s of solve (one Cholesky
//! factorization, 5 Newton iterations of which 4 modified; 1.21 % RMS
//! radial error, the mesh's floor) against 7.2 and 6.3 s for scikit-fem
//! (1.48 % with its dead-load pressure), a ratio of 0.08-0.11. Against the
//! issue's scikit-fem with AMG-CG (3.0 s; pyamg is not in the reference
//! environment) it would be about 1/5. Ten fixed load steps took 14.9 s.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use surgbench_comparisons::gate::{self, Workload};
use surgbench_core::Model;

fn build(w: &Workload) -> (Box<dyn Model>, surgbench_core::Scene) {
    let run = w.resolve().expect("workload");
    (run.build().expect("build"), run.scene().clone())
}

fn bench(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/gate.toml");
    let cfg = gate::load_config(&path).expect("benches/gate.toml");
    let mut g = c.benchmark_group("workload");
    g.sample_size(20);
    for w in cfg.workload.iter().filter(|w| !w.static_solve) {
        g.bench_function(w.key(), |b| {
            b.iter_batched(
                || build(w),
                |(mut m, scene)| {
                    let dt = m.dt();
                    for k in 0..w.steps {
                        m.step(dt, &scene.control.command_at((k + 1) as f64 * dt))
                            .expect("step");
                    }
                    m
                },
                BatchSize::LargeInput,
            )
        });
    }
    g.finish();
    let mut g = c.benchmark_group("static_solve");
    g.sample_size(10);
    for w in cfg.workload.iter().filter(|w| w.static_solve) {
        g.bench_function(w.key(), |b| {
            b.iter_batched(
                || build(w),
                |(mut m, scene)| {
                    let dt = m.dt();
                    m.step(dt, &scene.control.command_at(dt)).expect("static solve");
                    m
                },
                BatchSize::LargeInput,
            )
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
