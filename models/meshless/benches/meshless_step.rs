//! Step time of the `meshless` model against node count (1k, 5k, 20k nodes:
//! cubes of 9^3, 16^3 and 26^3 cells), symplectic Euler (the seed's
//! integrator) with and without the PBD corrections. Fit the growth
//! exponent as `log(t2/t1) / log(n2/n1)` from the reported medians.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::time::Duration;
use surgbench_core::{Body, DeviceCommand, Fidelity, Model, Scene, SolidMaterial, TissueBody, Vec3, mesh};
use surgbench_meshless::MeshlessTissue;

fn scene(cells: usize) -> Scene {
    let l = 0.02;
    let m = mesh::block(Vec3::repeat(l), [cells; 3]);
    let mut body = TissueBody::new(
        m.clone(),
        SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1000.0,
        },
    );
    body.fixed_nodes = mesh::nodes_on_plane(&m, 2, 0.0, 1e-9);
    body.driven_nodes = mesh::nodes_on_plane(&m, 2, l, 1e-9)
        .into_iter()
        .map(|i| (i, Vec3::new(0.0, 0.0, -1e-3)))
        .collect();
    let mut s = Scene::empty("bench");
    s.bodies.push(Body::Tissue(body));
    s
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("meshless_step");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    for cells in [9, 16, 26] {
        let s = scene(cells);
        let n = (cells + 1).pow(3);
        for pbd in [0, 1] {
            let f = Fidelity::parse_pairs(&["integrator=symplectic-euler", "dt=1e-5", &format!("pbd={pbd}")]).unwrap();
            let mut m = MeshlessTissue::new(&s, &f).unwrap();
            let cmd = DeviceCommand {
                load: 0.1,
                ..Default::default()
            };
            let id = BenchmarkId::new(if pbd == 1 { "explicit+pbd" } else { "explicit" }, n);
            g.bench_function(id, |b| b.iter(|| m.step(1e-5, &cmd).unwrap()));
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
