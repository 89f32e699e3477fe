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
//!   t = 0.151 s (1.8e-5). Diagnosis: from t ~ 0.18 s (12.5 %) the exact
//!   Hessian of the *converged* previous state is indefinite: the bonded,
//!   nearly incompressible corotational cube passes a bifurcation (an
//!   unstable equilibrium branch, a spurious instability of the corotational
//!   energy on this locking mesh; neo-Hookean converges on the same scene).
//!   The fallback Jacobian then crawls (warped before the fix: rate ~0.8 per
//!   iteration; projected now: ~0.5, then the state drifts along the
//!   unstable mode), and adaptive load halving does not help because the
//!   failure is not an increment size problem. That case is kept below as
//!   an ignored, failing test (`corotational_truth_cube_12_5_percent`).

use std::f64::consts::PI;
use surgbench_core::{SolidMaterial, TissueBody, Vec3, mesh};
use surgbench_fem::{DynParams, FemModel, Integrator, Law};

/// The truth-cube scene at mesh level 0 (`comparisons` builds the same).
fn truth_cube_body(strain: f64) -> TissueBody {
    let edge = 0.08;
    let m = mesh::block(Vec3::new(edge, edge, edge), [4, 4, 4]);
    let tol = 1e-9 * edge;
    let mut b = TissueBody::new(
        m.clone(),
        SolidMaterial {
            youngs_modulus: 15.3e3,
            poisson_ratio: 0.499,
            density: 980.0,
        },
    );
    b.fixed_nodes = mesh::nodes_on_plane(&m, 2, 0.0, tol);
    b.driven_nodes = mesh::nodes_on_plane(&m, 2, edge, tol)
        .into_iter()
        .map(|i| (i, Vec3::new(0.0, 0.0, -strain * edge)))
        .collect();
    b
}

/// Ramp to `strain` and hold for `steps - 250` steps; the largest Newton
/// iteration count of a step, or the error of the failing step.
fn run(law: Law, strain: f64, steps: usize) -> Result<u32, String> {
    let p = DynParams {
        integrator: Integrator::QuasiStatic,
        iterations: 30,
        law,
        ..Default::default()
    };
    let body = truth_cube_body(strain);
    let mut m = FemModel::new(&body, Vec3::zeros(), 1e-3, p).unwrap();
    let (ramp, dt) = (0.25, 1e-3);
    let mut max_iters = 0;
    for k in 0..steps {
        let t = (k + 1) as f64 * dt;
        // The scenario's cosine ramp (16 linear segments there; exact here).
        let s = if t >= ramp {
            1.0
        } else {
            0.5 * (1.0 - (PI * t / ramp).cos())
        };
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
/// turns unstable on this mesh at about 11 % compression.
#[test]
#[ignore = "known: corotational bifurcation on the level-0 truth cube at nu = 0.499"]
fn corotational_truth_cube_12_5_percent() {
    run(Law::Corotational, 0.125, 255).unwrap_or_else(|e| panic!("{e}"));
}
