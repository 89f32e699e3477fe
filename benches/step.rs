//! Criterion benchmark of every gated workload (`benches/gate.toml`): wall
//! time of `steps` steps from a freshly built model (build excluded). For
//! people: criterion's wall-clock numbers swing on shared machines and never
//! fail a build; the CI gate counts instructions instead (`surgbench gate`).

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use surgbench_comparisons::gate::{self, Workload};
use surgbench_comparisons::registry;
use surgbench_comparisons::scenario::Params;
use surgbench_core::{Fidelity, Model};

fn build(w: &Workload) -> (Box<dyn Model>, surgbench_core::Scene) {
    let sc = registry::scenario(&w.scenario).expect("scenario");
    let f = registry::model(&w.model).expect("model");
    let overrides: Vec<(String, f64)> = w.params.iter().map(|(k, v)| (k.clone(), *v)).collect();
    let p = Params::resolve(sc.id(), sc.params(), &overrides).expect("params");
    let mut fid = Fidelity::default();
    for (k, v) in &w.fidelity {
        fid.set(k, *v).expect("fidelity");
    }
    let run = sc.instantiate_at(&p, &fid).expect("scenario instance");
    let fid = f.default_fidelity(run.scene()).merged(&fid);
    (f.build(run.scene(), &fid).expect("build"), run.scene().clone())
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
