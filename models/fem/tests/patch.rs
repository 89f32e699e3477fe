//! Patch test: a homogeneous deformation `x = F X + c` imposed on the
//! boundary is reproduced exactly at the interior nodes, for every law
//! (a homogeneous field is in the P1 space and balances every interior node).

mod common;
use common::tissue;
use surgbench_core::{Vec3, mesh};
use surgbench_fem::{Constraint, Law, LinearSolver, Loads, StaticParams, material::M3, solve_static};

#[test]
fn homogeneous_deformation_is_reproduced() {
    let size = Vec3::new(0.02, 0.02, 0.03);
    let m = mesh::block(size, [3, 3, 4]);
    let (lo, hi) = mesh::bounds(&m);
    let on_boundary = |p: &Vec3| (0..3).any(|a| (p[a] - lo[a]).abs() < 1e-12 || (p[a] - hi[a]).abs() < 1e-12);
    let boundary = mesh::nodes_where(&m, on_boundary);
    let interior = mesh::nodes_where(&m, |p| !on_boundary(p));
    assert!(!interior.is_empty());
    for (law, f) in [
        (
            Law::Linear,
            M3::new(1.001, 0.0005, 0.0, -0.0003, 0.999, 0.0002, 0.0001, 0.0, 1.002),
        ),
        (
            Law::Corotational,
            M3::new(1.1, 0.2, 0.0, -0.1, 0.9, 0.05, 0.0, 0.1, 0.85),
        ),
        (Law::NeoHookean, M3::new(1.1, 0.2, 0.0, -0.1, 0.9, 0.05, 0.0, 0.1, 0.85)),
    ] {
        let c = Vec3::new(1e-3, -2e-3, 5e-4);
        let exact = |p: &Vec3| f * p + c - p;
        let cons: Vec<Constraint> = boundary
            .iter()
            .map(|&i| Constraint::displaced(i, exact(&m.nodes[i])))
            .collect();
        for solver in [
            LinearSolver::default(),
            LinearSolver::Cg {
                tol: 1e-12,
                max_iter: 1000,
            },
        ] {
            let params = StaticParams {
                load_steps: 2,
                tol: 1e-11,
                solver,
                ..Default::default()
            };
            let info = solve_static(&m, &tissue(0.3), law, &cons, &Loads::default(), &params).unwrap();
            let err = interior
                .iter()
                .map(|&i| (info.displacements[i] - exact(&m.nodes[i])).amax())
                .fold(0.0, f64::max);
            // Exact up to the Newton tolerance and round-off: 1e-12 m on a
            // 2 cm block (displacements ~1e-3 m).
            assert!(
                err < 1e-12,
                "{law:?} {solver:?}: interior error {err:.3e} m, iterations {:?}",
                info.newton_iterations
            );
        }
    }
}
