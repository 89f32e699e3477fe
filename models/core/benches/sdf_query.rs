//! Cost of one SDF query (distance + gradient) for the vessel geometries a
//! rod model calls per node per step: the analytic aortic arch (swept tube
//! union), the tortuous coronary, a voxel grid of the arch trunk, and the
//! exact parry3d mesh query the grid is built from.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use surgbench_core::Vec3;
use surgbench_core::sdf::{MeshSdf, Sdf, VoxelSdf};
use surgbench_core::vessel;

/// 100 points along a centreline, offset towards the wall.
fn points(tube: &surgbench_core::sdf::SweptTube, offset: f64) -> Vec<Vec3> {
    (0..100)
        .map(|i| {
            let s = tube.length() * (i as f64 + 0.5) / 100.0;
            let f = tube.frame_at(s);
            tube.point_at(s) + f.rotation * Vec3::new(0.0, offset, 0.3 * offset)
        })
        .collect()
}

fn query(c: &mut Criterion, name: &str, sdf: &dyn Sdf, pts: &[Vec3]) {
    c.bench_function(name, |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for p in pts {
                let (d, g) = sdf.distance_gradient(black_box(p));
                acc += d + g.x;
            }
            black_box(acc)
        })
    });
}

fn benches(c: &mut Criterion) {
    let arch = vessel::aortic_arch();
    let cor = vessel::coronary_tortuous();
    let pa = points(&arch.trunk, 10e-3);
    let pc = points(&cor.trunk, 1.2e-3);
    query(c, "sdf_100_nodes/arch_analytic", &arch, &pa);
    query(c, "sdf_100_nodes/coronary_analytic", &cor, &pc);
    let mesh = arch.trunk.to_mesh(64, 1e-3).expect("mesh");
    let exact = MeshSdf::new(&mesh).expect("closed mesh");
    query(c, "sdf_100_nodes/arch_trunk_mesh_parry", &exact, &pa);
    let (lo, hi) = mesh.bounds();
    let grid = VoxelSdf::from_sdf(&arch.trunk, lo - Vec3::repeat(2e-3), hi + Vec3::repeat(2e-3), 0.5e-3).expect("grid");
    query(c, "sdf_100_nodes/arch_trunk_voxel_0.5mm", &grid, &pa);
}

criterion_group!(sdf, benches);
criterion_main!(sdf);
