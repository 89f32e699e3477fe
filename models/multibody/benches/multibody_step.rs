//! Step time of the rapier3d rigid chain (multibody joints) for 10-80
//! links, a cantilever under gravity at 1 ms, one substep and four. Prints
//! the growth exponent of time against link count from 40 to 80 links: rapier assembles
//! and factorizes the dense generalized mass matrix each substep, `O(n^3)`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Instant;
use surgbench_core::{DeviceCommand, RodBody, Vec3};
use surgbench_multibody::{ChainParams, RigidChain};

/// The default rod scenes' wire (0.1 m nitinol, r = 0.5 mm), damped,
/// warmed up into its sag.
fn chain(links: usize, substeps: usize) -> RigidChain {
    let body = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0);
    let p = ChainParams {
        links,
        substeps,
        damping_ratio: 1.0,
        ..Default::default()
    };
    let mut c = RigidChain::new(&body, Vec3::new(0.0, 0.0, -9.81), &p, 0.0).unwrap();
    for _ in 0..20 {
        c.step(1e-3, &DeviceCommand::default()).unwrap();
    }
    c
}

fn bench(c: &mut Criterion) {
    let sizes = [10usize, 20, 40, 80];
    for substeps in [1usize, 4] {
        let mut times = Vec::new();
        for &n in &sizes {
            let mut ch = chain(n, substeps);
            let cmd = DeviceCommand::default();
            c.bench_function(&format!("multibody_step/substeps{substeps}/{n}"), |b| {
                b.iter(|| {
                    ch.step(1e-3, &cmd).unwrap();
                    black_box(ch.tip())
                })
            });
            // Own timing for the growth fit (criterion's numbers are the report).
            let reps = (2000 / (n * n / 10).max(1)).max(5);
            let t0 = Instant::now();
            for _ in 0..reps {
                ch.step(1e-3, &cmd).unwrap();
            }
            let per = t0.elapsed().as_secs_f64() / reps as f64;
            eprintln!("{substeps} substeps, {n} links: {:.1} us/step", per * 1e6);
            times.push(per);
        }
        // Growth exponent between the two largest chains.
        let growth = (times[3] / times[2]).ln() / (sizes[3] as f64 / sizes[2] as f64).ln();
        eprintln!("{substeps} substeps: time ~ links^{growth:.2} from 40 to 80 links");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
