//! Step time of the discrete elastic rod for 50-400 nodes, free (cantilever
//! under gravity) and in contact (wire sagging along a tube wall, many nodes
//! touching), one thread, backward Euler at 1 ms. Prints the fitted growth
//! exponent of time against node count.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{ContactParams, DeviceCommand, RodBody, Vec3};
use surgbench_der::DerRod;

/// Guidewire-like rod: 0.2 m nitinol, r = 0.2 mm.
fn rod(nodes: usize, contact: bool) -> DerRod {
    let body = RodBody::uniform(0.2, 2e-4, 5e10, 0.3, 6450.0);
    let mut r = DerRod::from_body(&body, nodes - 2).unwrap();
    r.gravity = Vec3::new(0.0, 0.0, -9.81);
    r.params.damping = 10.0;
    if contact {
        let tube = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1e-3,
        };
        let c = ContactParams {
            friction_static: 0.1,
            friction_dynamic: 0.08,
            margin: 2e-4,
        };
        r.set_vessel(Some(Arc::new(tube)), c);
    }
    // Warm up into the steady regime (sagging onto the wall).
    for _ in 0..300 {
        r.step(1e-3, &DeviceCommand::default()).unwrap();
    }
    r
}

fn bench(c: &mut Criterion) {
    let sizes = [50usize, 100, 200, 400];
    for contact in [false, true] {
        let name = if contact { "contact" } else { "free" };
        let mut times = Vec::new();
        for &n in &sizes {
            let mut r = rod(n, contact);
            let cmd = DeviceCommand::default();
            c.bench_function(&format!("der_step/{name}/{n}"), |b| {
                b.iter(|| black_box(r.step(1e-3, &cmd).unwrap()))
            });
            // Own timing for the growth fit (criterion's numbers are the report).
            let reps = 200;
            let t0 = Instant::now();
            for _ in 0..reps {
                black_box(r.step(1e-3, &cmd).unwrap());
            }
            let per = t0.elapsed().as_secs_f64() / reps as f64;
            eprintln!(
                "{name} {n} nodes: {:.1} us/step, {} contacts",
                per * 1e6,
                r.contacts().len()
            );
            times.push(per);
        }
        let xs: Vec<f64> = sizes.iter().map(|&n| (n as f64).ln()).collect();
        let ys: Vec<f64> = times.iter().map(|t| t.ln()).collect();
        let k = xs.len() as f64;
        let (mx, my) = (xs.iter().sum::<f64>() / k, ys.iter().sum::<f64>() / k);
        let slope = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum::<f64>()
            / xs.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
        eprintln!("{name}: time ~ nodes^{slope:.2}");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
