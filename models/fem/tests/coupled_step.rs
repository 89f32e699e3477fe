//! The coupled step's linear solves (`FemModel::begin_linear_step`,
//! `solve_linear`, `solve_linear_many`), which the needle model uses for its
//! Schur complement.

mod common;

use common::SplitMix;
use surgbench_core::{TissueBody, Vec3, mesh};
use surgbench_fem::{DynParams, FemModel, Integrator};

#[test]
fn a_blocked_solve_matches_single_solves() {
    let m = mesh::block_mirrored(Vec3::new(0.02, 0.01, 0.01), [4, 2, 2]);
    let mut body = TissueBody::new(m.clone(), common::tissue(0.475));
    body.fixed_nodes = mesh::nodes_on_plane(&m, 0, 0.02, 1e-12);
    let params = DynParams {
        integrator: Integrator::BackwardEuler,
        ..DynParams::default()
    };
    let mut fem = FemModel::new(&body, Vec3::zeros(), 1e-3, params).unwrap();
    let _step = fem.begin_linear_step(1e-3, 0.0).unwrap();
    let (n, k) = (3 * m.nodes.len(), 7);
    let mut rng = SplitMix(17);
    let b: Vec<f64> = (0..n * k).map(|_| rng.signed()).collect();
    let mut many = b.clone();
    fem.solve_linear_many(&mut many, k);
    let mut worst: f64 = 0.0;
    for (col, got) in b.chunks_exact(n).zip(many.chunks_exact(n)) {
        let mut one = col.to_vec();
        fem.solve_linear(&mut one);
        let scale = one.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        for (d, (x, y)) in one.iter().zip(got).enumerate() {
            if !fem.is_free(d) {
                assert_eq!(*y, 0.0, "constrained DOF {d} not zero");
            }
            worst = worst.max((x - y).abs() / scale);
        }
    }
    // Same factor, blocked vs one column: only the order of the triangular
    // solves' sums differs, a few ulps of the solution's scale.
    assert!(worst < 1e-13, "blocked and single solves differ by {worst:e}");
}
