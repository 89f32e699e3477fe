//! Regression: the quasi-static Newton stayed on the projected Jacobian.
//!
//! What was slow: once the exact tangent of a Newton iterate was indefinite
//! (its Cholesky failed), `equilibrate` switched to the projected
//! (element-wise positive semi-definite) Jacobian and kept it for the rest
//! of the load step, converging linearly even after the iterates were back
//! where the exact tangent is positive definite. On the level-0 truth cube
//! (`tests/common`, 384 tets, nu = 0.499) ramped to 10 % compression with
//! the corotational law (the scenario's cosine ramp over 0.25 s, dt = 1 ms)
//! the steps past ~6 % took 6-9 Newton iterations each (1368 over 255
//! steps). Now every iteration tries the exact tangent first and falls back
//! for that iteration only: at most 3 per step (736 in all), quadratic
//! convergence.
//!
//! Not helped (measured, same ramp): neo-Hookean at 18.25 % stays at 13-16
//! iterations per step past ~10 % (was 13-17): its equilibrium there is a
//! saddle (one negative tangent eigenvalue, `truth_cube_stability.rs`), so
//! the exact tangent is never positive definite near the solution.

use surgbench_core::Vec3;
use surgbench_fem::{DynParams, FemModel, Integrator, Law};

mod common;
use common::{cosine_ramp, truth_cube_body};

/// Ramp to `strain` over 250 steps and hold 5; Newton iterations of every step
/// and the final model.
fn ramp(law: Law, strain: f64) -> (Vec<u32>, FemModel) {
    // Full Newton at every iteration: this is a test of Newton's own
    // convergence (modified Newton, the default `factor_reuse`, converges
    // linearly by design and is tested in `tests/statics_as_statics.rs`).
    let p = DynParams {
        integrator: Integrator::QuasiStatic,
        iterations: 30,
        law,
        factor_reuse: false,
        ..Default::default()
    };
    let body = truth_cube_body(strain, 4);
    let mut m = FemModel::new(&body, Vec3::zeros(), 1e-3, p).expect("truth cube");
    let (t_ramp, dt) = (0.25, 1e-3);
    let mut its = Vec::new();
    for k in 0..255 {
        let t = (k + 1) as f64 * dt;
        let s = cosine_ramp(t, t_ramp);
        let st = m
            .advance(dt, s)
            .unwrap_or_else(|e| panic!("{law:?} {strain}: step {k} (load {s:.3}): {e}"));
        // Converged to the Newton tolerance (DynParams::tol, relative force residual).
        assert!(
            st.residual <= p.tol,
            "{law:?} {strain}: step {k} residual {:e} above tol {:e}",
            st.residual,
            p.tol
        );
        its.push(st.iterations);
    }
    (its, m)
}

#[test]
fn corotational_truth_cube_10_percent_converges_quadratically() {
    let (its, _) = ramp(Law::Corotational, 0.10);
    let max = *its.iter().max().expect("steps");
    let total: u32 = its.iter().sum();
    eprintln!("corotational 10 %: max {max}, total {total} Newton iterations");
    // Quadratic convergence from the previous step's equilibrium: the load
    // increment per step is at most pi/2 * 10 % / 250 = 6.3e-4 strain, from
    // which Newton reaches 1e-9 in at most 3 iterations (measured 2-3 on every
    // step). The sticky fallback took 6-9 (max 9, 1368 in all).
    assert!(
        max <= 3,
        "max Newton iterations per step {max} (was 9 with the sticky fallback): {its:?}"
    );
}
