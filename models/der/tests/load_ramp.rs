//! Time-varying tip loads (`RodBody::tip_load_ramp`): the load of a step is
//! the ramp's value at the end of the step (backward Euler and Newmark impose
//! equilibrium at `t + dt`), nothing acts before the ramp starts, a ramped
//! load settles to the same statics as the full load, and the reported
//! external energy is `-s(t) F . x_tip`.

use surgbench_core::{DeviceCommand, LoadRamp, RodBody, Vec3};
use surgbench_der::{DerRod, Integrator};

/// Nitinol cantilever, L = 0.1 m, r = 0.5 mm, tip force (0, 0.02, -0.05) N:
/// tip deflection ~ 10% of L (geometrically nonlinear).
fn body() -> RodBody {
    let mut b = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0);
    b.tip_force = Vec3::new(0.0, 0.02, -0.05);
    b
}

fn tip(rod: &DerRod) -> Vec3 {
    rod.node(rod.num_nodes() - 1)
}

/// Rounding of the rest shape: node positions are sums of 20 edges, each
/// rounded to `eps |x|`, so the unloaded rest state is in equilibrium only
/// to about `20 eps L` (4.4e-16 m; a zero-load step moved the tip by
/// 1.4e-17 m, measured).
fn rest_rounding(b: &RodBody) -> f64 {
    20.0 * f64::EPSILON * b.length
}

/// When the load acts, with `dt` = 1 ms:
/// * backward Euler: a ramp reaching 1 at `t = dt` gives the first step
///   bit-identically the un-ramped rod's first step (only the load at the
///   end of the step enters). Newmark also uses the start acceleration,
///   which is 0 under the ramp and `F/m` without it, so there the two differ
///   (as they should);
/// * both integrators: a ramp from `dt` to `2 dt` leaves the first step at
///   rest (scale 0 at its end: no load, tip stays put to rounding, external
///   energy 0), and its second step equals the first step of the ramp
///   reaching 1 at `dt` (both start at rest with zero acceleration; the
///   start states differ by that rounding).
#[test]
fn ramp_is_evaluated_at_the_end_of_each_step() {
    let dt = 1e-3;
    let cmd = DeviceCommand::default();
    for integrator in [Integrator::BackwardEuler, Integrator::Newmark] {
        let make = |ramp: Option<LoadRamp>| {
            let mut b = body();
            b.tip_load_ramp = ramp;
            let mut rod = DerRod::from_body(&b, 20).unwrap();
            rod.params.integrator = integrator;
            rod
        };
        let mut plain = make(None);
        plain.step(dt, &cmd).unwrap();
        let moved = tip(&plain);
        let rest = tip(&make(None));
        assert!(
            (moved - rest).norm() > 1e-6,
            "{integrator:?}: the full load should move the tip in one step ({moved:?} vs {rest:?})"
        );

        let mut early = make(Some(LoadRamp::linear(0.0, dt)));
        early.step(dt, &cmd).unwrap();
        if integrator == Integrator::BackwardEuler {
            assert_eq!(tip(&early), moved, "ramp (0, dt) after one step vs un-ramped");
        }
        let moved = tip(&early);

        let mut late = make(Some(LoadRamp::linear(dt, 2.0 * dt)));
        late.step(dt, &cmd).unwrap();
        let still = (tip(&late) - rest).norm();
        let b = body();
        assert!(
            still <= rest_rounding(&b),
            "{integrator:?}: before the ramp starts the tip moved {still:e} m"
        );
        let e = late.energies();
        assert_eq!(e.external, 0.0, "{integrator:?}: no load, no potential: {e:?}");
        late.step(dt, &cmd).unwrap();
        let diff = (tip(&late) - moved).norm();
        eprintln!("{integrator:?}: zero-load step moved the tip {still:.1e} m; delayed vs early step {diff:.1e} m");
        // Both solves start a rounding apart (above) and stop at the Newton
        // tolerance 1e-9 L on the last update (quadratic convergence, so the
        // error is far below): bound 1e-9 L = 1e-10 m.
        assert!(
            diff <= 1e-9 * b.length,
            "{integrator:?}: second step of ramp (dt, 2dt) differs from the first step of ramp (0, dt) by {diff:e} m"
        );
        // Full load at t = 2 dt: the potential is -F . x_tip with the
        // absolute tip position (no gravity here), to rounding of one dot
        // product.
        let f = body().tip_force;
        let e = late.energies();
        let expect = -f.dot(&tip(&late));
        assert!(
            (e.external - expect).abs() <= 1e-15 * expect.abs().max(1e-300) * 4.0,
            "{integrator:?}: external {} vs -F.x_tip {expect}",
            e.external
        );
    }
}

/// A tip load ramped from 0 to full over 0.1 s (after 0.05 s at rest),
/// stepped with backward Euler at dt = 5 ms (a fifth of the first bending
/// period, 25.7 ms: strongly damped) with mass damping 20 1/s, settles to
/// the static solution under the full load.
#[test]
fn ramped_tip_load_settles_to_the_unramped_statics() {
    let b = body();
    let mut stat = DerRod::from_body(&b, 20).unwrap();
    let st = stat.solve_static(&DeviceCommand::default()).unwrap();
    assert!(st.converged, "statics: {st:?}");
    let target = tip(&stat);

    let mut rb = b.clone();
    rb.tip_load_ramp = Some(LoadRamp::linear(0.05, 0.15));
    let mut rod = DerRod::from_body(&rb, 20).unwrap();
    rod.params.damping = 20.0;
    let (dt, steps) = (5e-3, 120);
    let rest = tip(&rod);
    for k in 1..=steps {
        let st = rod.step(dt, &DeviceCommand::default()).unwrap();
        assert!(st.converged, "step {k}: {st:?}");
        if k * 5 <= 50 {
            let moved = (tip(&rod) - rest).norm();
            assert!(
                moved <= 20.0 * f64::EPSILON * b.length,
                "step {k} (t = {} s) is before the ramp, tip moved {moved:e} m",
                rod.time()
            );
        }
    }
    let err = (tip(&rod) - target).norm();
    let defl = (target - rest).norm();
    eprintln!(
        "ramped load: tip {:?} vs statics {target:?}, diff {err:.2e} m (deflection {defl:.3e} m)",
        tip(&rod)
    );
    // After the ramp ends (0.15 s) 90 steps remain; backward Euler damps
    // the first mode by (1 + (w dt)^2)^(-1/2) = 0.63 a step (w dt = 1.22),
    // the mass damping by more: the transient is below 1e-17 of the
    // deflection. What remains is the Newton tolerance of both solves
    // (1e-9 L on the last update, quadratic convergence): 1e-10 m.
    assert!(
        err < 1e-9 * b.length,
        "ramped run settles {err:e} m away from statics (deflection {defl:e} m)"
    );
}
