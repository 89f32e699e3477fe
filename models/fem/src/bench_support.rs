//! Workloads shared by the crate's criterion bench (`benches/fem_step.rs`)
//! and the speed/accuracy example (`examples/step_speed.rs`).

use surgbench_core::{SolidMaterial, TissueBody, Vec3, mesh};

/// Edge lengths of [`bench_block`] (m).
pub const BENCH_SIZE: [f64; 3] = [0.04, 0.04, 0.05];

/// Press depth of the driven top face of [`bench_block`] at full command (m).
pub const BENCH_STROKE: f64 = 0.005;

/// The speed-target workload: a 4 x 4 x 5 cm block of 12 x 12 x 15 cells
/// split in 6 tets each, 12,960 tets / 2,704 nodes, the closest block to
/// the needle-insertion seed's prostate mesh (13,375 tets / 2,763
/// vertices; 3 % fewer tets). Soft tissue (E = 60 kPa, nu = 0.45,
/// 1050 kg/m^3); bottom face fixed, top face driven down by
/// [`BENCH_STROKE`] at full command. SI units.
pub fn bench_block() -> TissueBody {
    let size = Vec3::from(BENCH_SIZE);
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
        .map(|i| (i, Vec3::new(0.0, 0.0, -BENCH_STROKE)))
        .collect();
    b
}
