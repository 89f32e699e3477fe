//! Regressions of the quasi-static Newton on the `truth-cube` scene at mesh
//! level 0 (80 mm cube, 4x4x4 cells, 384 tets, nu = 0.499, bonded plates,
//! the scenario's cosine load ramp over 0.25 s at dt = 1 ms).
//!
//! What failed before the fix:
//! * corotational, 5 %: the first step after the ramp (load unchanged) failed
//!   with "Newton did not converge ... (residual 8.131e-1)": the residual was
//!   measured against that step's first residual, which was round-off, so
//!   the step could never converge (`hold_after_ramp_converges` failed).
//! * corotational, 12.5 % and 18.25 %: "Newton did not converge in load
//!   step 1 after 30 iterations" at t = 0.206 s (residual 7.4e-5) and
//!   t = 0.151 s (1.8e-5). Diagnosis (verified in `truth_cube_stability.rs`):
//!   the exact tangent on the free DOFs of the *converged* states turns
//!   indefinite near 10.4 % strain (smallest eigenvalue +2.2 N/m at 9.8 %,
//!   -1.9 N/m at 10.95 %; three negative, the smallest -16.0 N/m = -4.8e-5
//!   of the largest, at 12.70 %, the last converged state of the 18.25 %
//!   ramp): the equilibrium branch is a saddle of the discrete energy. The
//!   mode is lateral and mesh-scale, largest on two vertical edges one cell
//!   from a plate. It is a spurious instability of the coarse locking P1
//!   mesh at nu = 0.499, not of the corotational law alone: neo-Hookean's
//!   own equilibrium is a saddle too (one negative eigenvalue, -10.5 N/m at
//!   18.25 %; Newton still converges there), and on the 8x8x8 mesh both
//!   are stable at the same strains. The fallback Jacobian then crawls
//!   (warped before the fix: rate ~0.8 per iteration; projected now: ~0.5,
//!   then the state drifts along the unstable mode), and adaptive load
//!   halving does not help because the failure is not an increment size
//!   problem. That case is kept below as an ignored, failing test
//!   (`corotational_truth_cube_12_5_percent`).

use surgbench_core::Vec3;
use surgbench_fem::{DynParams, FemModel, Integrator, Law};

mod common;
use common::{cosine_ramp, truth_cube_body};

/// Ramp to `strain` and hold for `steps - 250` steps; the largest Newton
/// iteration count of a step, or the error of the failing step.
fn run(law: Law, strain: f64, steps: usize) -> Result<u32, String> {
    let p = DynParams {
        integrator: Integrator::QuasiStatic,
        iterations: 30,
        law,
        ..Default::default()
    };
    let body = truth_cube_body(strain, 4);
    let mut m = FemModel::new(&body, Vec3::zeros(), 1e-3, p).unwrap();
    let (ramp, dt) = (0.25, 1e-3);
    let mut max_iters = 0;
    for k in 0..steps {
        let t = (k + 1) as f64 * dt;
        // The scenario's cosine ramp (16 linear segments there; exact here).
        let s = cosine_ramp(t, ramp);
        let st = m
            .advance(dt, s)
            .map_err(|e| format!("{law:?} strain {strain}: step {k} (t = {t:.3} s, load {s:.3}): {e}"))?;
        max_iters = max_iters.max(st.iterations);
    }
    let top = body.driven_nodes[0].0;
    let z = m.positions()[top].z;
    // The driven face reached the full stroke (prescribed exactly).
    assert!(
        (z - 0.08 * (1.0 - strain)).abs() < 1e-12,
        "{law:?} strain {strain}: top node z {z}"
    );
    Ok(max_iters)
}

#[test]
fn hold_after_ramp_converges() {
    let its = run(Law::Corotational, 0.05, 255).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("corotational 5 %: max Newton iterations per step {its}");
}

#[test]
fn neo_hookean_converges_at_every_truth_cube_level() {
    for strain in [0.05, 0.125, 0.1825] {
        let its = run(Law::NeoHookean, strain, 255).unwrap_or_else(|e| panic!("{e}"));
        eprintln!("neo-Hookean {strain}: max Newton iterations per step {its}");
    }
}

/// Known failure (see the file header): the corotational equilibrium branch
/// of this mesh is a saddle from about 10.4 % compression (smallest tangent
/// eigenvalue -16.0 N/m at 12.70 %, asserted in
/// `truth_cube_stability.rs`); the quasi-static Newton fails on it. A
/// discretization artefact of the locking level-0 mesh (8x8x8 is stable),
/// so the fix belongs to the element (refinement, mixed u-p or F-bar).
#[test]
#[ignore = "known: the level-0 truth cube equilibrium is a saddle from ~10.4 % (locking mesh, nu = 0.499)"]
fn corotational_truth_cube_12_5_percent() {
    run(Law::Corotational, 0.125, 255).unwrap_or_else(|e| panic!("{e}"));
}
