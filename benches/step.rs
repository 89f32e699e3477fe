//! Criterion benchmark of every gated workload (`benches/gate.toml`): wall
//! time of `steps` steps from a freshly built model (build excluded). For
//! people: criterion's wall-clock numbers swing on shared machines and never
//! fail a build; the CI gate counts instructions instead (`surgbench gate`).

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
    for w in &cfg.workload {
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
}

criterion_group!(benches, bench);
criterion_main!(benches);
