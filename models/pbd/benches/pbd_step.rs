//! Step cost of the PBD models (criterion). Workloads from the design targets:
//! a 100-segment rod in a tube with contact (<= 0.2 ms/step), a ~20k-tet block
//! at 10 iterations (<= 10 ms/step) and the same with hash activation of one
//! box (<= 1 ms/step). The tissue runs at 1 and 2 solver threads (the
//! `threads` fidelity extra; results are bit-identical across counts). The
//! rod runs with both constraint solvers (`solver` `gauss-seidel`, or
//! `direct`: the banded solve of Deul et al. 2018) at the same iteration and
//! substep counts, so the ratio is the cost per iteration.

use std::hint::black_box;
use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use surgbench_core::Setting;
use surgbench_core::mesh;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{
    Body, DeviceCommand, Fidelity, Model, ModelFactory, RodBody, Scene, SolidMaterial, TissueBody, Vec3,
};
use surgbench_pbd::{PbdRodFactory, PbdTissueFactory};

fn rod_model(iterations: usize, substeps: usize, solver: &str) -> Box<dyn Model> {
    let mut scene = Scene::empty("rod-in-tube");
    scene.bodies.push(RodBody::uniform(0.5, 2e-4, 5e10, 0.3, 6450.0).into());
    scene.gravity = Vec3::new(0.0, 0.0, -9.81);
    scene.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1.5e-3,
    }));
    scene.environment.contact.friction_static = 0.1;
    scene.environment.contact.friction_dynamic = 0.05;
    scene.environment.contact.margin = 2e-4; // wire radius (harness convention)
    let mut f = Fidelity {
        segments: Some(100),
        dt: Some(1e-3),
        iterations: Some(iterations),
        ..Default::default()
    };
    f.extras.insert("substeps".into(), Setting::from(substeps as f64));
    f.extras.insert("solver".into(), Setting::from(solver));
    let mut m = PbdRodFactory.build(&scene, &f).unwrap();
    // Let the wire sag onto the wall first.
    for k in 0..200 {
        m.step(1e-3, &cmd(k)).unwrap();
    }
    let o = m.observe();
    eprintln!(
        "rod it={iterations} sub={substeps} solver={solver}: {} contacts after warm-up",
        o.contacts.len()
    );
    m
}

fn cmd(k: usize) -> DeviceCommand {
    DeviceCommand {
        insertion: 1e-5 * k as f64,
        rotation: 1e-3 * k as f64,
        load: 0.0,
        base_pose: None,
    }
}

fn tissue_model(hash_box: f64, threads: usize) -> Box<dyn Model> {
    // 8 x 8 x 50 cells of 5 mm = 19,200 tets; x = 0 face fixed, a tool patch
    // pushes the x = 4 cm face at mid height.
    let h = 5e-3;
    let cells = [8, 8, 50];
    let size = Vec3::new(8.0, 8.0, 50.0) * h;
    let mesh = mesh::block(size, cells);
    let fixed_nodes = (0..mesh.nodes.len()).filter(|&i| mesh.nodes[i].x == 0.0).collect();
    let driven_nodes = (0..mesh.nodes.len())
        .filter(|&i| {
            let p = mesh.nodes[i];
            p.x == size.x && (p.z - size.z / 2.0).abs() < 1.1 * h && (p.y - size.y / 2.0).abs() < 1.1 * h
        })
        .map(|i| (i, Vec3::new(-2e-3, 0.0, 0.0)))
        .collect();
    let mut scene = Scene::empty("block-20k");
    let material = SolidMaterial {
        youngs_modulus: 1e4,
        poisson_ratio: 0.45,
        density: 1000.0,
    };
    scene.bodies.push(Body::Tissue(TissueBody {
        fixed_nodes,
        driven_nodes,
        ..TissueBody::new(mesh, material)
    }));
    let mut f = Fidelity {
        dt: Some(1e-3),
        iterations: Some(10),
        ..Default::default()
    };
    if hash_box > 0.0 {
        f.extras.insert("hash_box".into(), Setting::from(hash_box));
    }
    f.extras.insert("threads".into(), Setting::from(threads as f64));
    let mut m = PbdTissueFactory.build(&scene, &f).unwrap();
    for k in 0..20 {
        m.step(
            1e-3,
            &DeviceCommand {
                load: k as f64 / 20.0,
                ..Default::default()
            },
        )
        .unwrap();
    }
    m
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("pbd");
    g.sample_size(20);
    for (it, sub, solver) in [
        (10, 1, "gauss-seidel"),
        (4, 5, "gauss-seidel"),
        (10, 1, "direct"),
        (4, 5, "direct"),
        (2, 1, "direct"),
    ] {
        let mut m = rod_model(it, sub, solver);
        let mut k = 200;
        // Gauss-Seidel keeps its historical names (the CI gate's baseline).
        let name = match solver {
            "gauss-seidel" => format!("rod100_tube_it{it}_sub{sub}"),
            _ => format!("rod100_tube_it{it}_sub{sub}_direct"),
        };
        g.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                black_box(m.step(1e-3, &cmd(k)).unwrap())
            })
        });
    }
    for (name, d, threads) in [
        ("tissue19k_it10_full_t1", 0.0, 1),
        ("tissue19k_it10_full_t2", 0.0, 2),
        ("tissue19k_it10_hash_box15mm_t1", 0.015, 1),
        ("tissue19k_it10_hash_box15mm_t2", 0.015, 2),
    ] {
        let mut m = tissue_model(d, threads);
        let full = DeviceCommand {
            load: 1.0,
            ..Default::default()
        };
        g.bench_function(name, |b| b.iter(|| black_box(m.step(1e-3, &full).unwrap())));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
