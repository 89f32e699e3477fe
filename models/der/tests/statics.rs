//! Statics against closed forms: Euler-Bernoulli cantilever under gravity
//! (with its convergence order), torque transfer, hand force/torque balance.

use surgbench_core::frames::signed_angle;
use surgbench_core::{DeviceCommand, RodBody, Vec3};
use surgbench_der::DerRod;

/// Small-deflection cantilever: L = 0.1 m, r = 0.5 mm, E = 50 GPa (nitinol),
/// rho = 6450 kg/m^3, g = 9.81. w/L = 0.25%: the large-deflection correction
/// is O((w/L)^2) ~ 1e-5 relative, negligible against the 0.5% tolerance.
fn cantilever() -> RodBody {
    RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0)
}

fn eb_tip(body: &RodBody, g: f64) -> f64 {
    let s = &body.sections[0];
    let q = s.density * s.area() * g;
    q * body.length.powi(4) / (8.0 * s.youngs_modulus * s.second_moment())
}

fn sag(segments: usize) -> (f64, f64) {
    let body = cantilever();
    let mut rod = DerRod::from_body(&body, segments).unwrap();
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    let st = rod.solve_static(&DeviceCommand::default()).unwrap();
    assert!(st.converged, "Newton did not converge at {segments} segments: {st:?}");
    let tip = rod.node(rod.num_nodes() - 1);
    (-tip.z, rod.max_stretch())
}

#[test]
fn cantilever_matches_euler_bernoulli_with_second_order_convergence() {
    let body = cantilever();
    let w = eb_tip(&body, 9.81);
    let ns = [10usize, 20, 40, 80];
    let mut errs = Vec::new();
    for &n in &ns {
        let (d, stretch) = sag(n);
        let err = (d - w).abs() / w;
        eprintln!("segments {n}: tip {d:.9e} m, EB {w:.9e} m, rel err {err:.3e}, stretch {stretch:.2e}");
        // Stretch limit from the brief; measured ~1e-9 (gravity load / EA).
        assert!(stretch.abs() < 1e-4, "stretch {stretch:e} at {n} segments");
        errs.push(err);
    }
    let (d50, _) = sag(50);
    let e50 = (d50 - w).abs() / w;
    // 0.5% at 50 segments (the brief); measured value printed above.
    assert!(e50 < 5e-3, "50 segments: tip {d50:e} vs EB {w:e}, rel err {e50:e}");
    // Least-squares slope of log(err) against log(segments).
    let xs: Vec<f64> = ns.iter().map(|&n| (n as f64).ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let (mx, my) = (xs.iter().sum::<f64>() / 4.0, ys.iter().sum::<f64>() / 4.0);
    let slope = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum::<f64>()
        / xs.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
    eprintln!("observed order {:.3} (50 segments: rel err {e50:.3e})", -slope);
    // Second order expected (ghost-edge clamp); +-0.15 covers the measured fit.
    assert!(
        (-slope - 2.0).abs() < 0.15,
        "observed order {} from errors {errs:?}",
        -slope
    );
}

/// Straight rod, base rotated by `alpha`, dead axial tip torque `T`: the tip
/// material frame is twisted by `alpha + T L / (G J)` (closed form for a
/// uniform shaft). Checked both in statics and through time steps.
#[test]
fn torque_transfer_is_exact() {
    let body = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0);
    let s = &body.sections[0];
    let gj = s.shear_modulus() * s.polar_moment();
    let alpha = 0.7;
    let torque = 0.5 * gj / body.length; // T L / GJ = 0.5 rad
    let expect = alpha + torque * body.length / gj;
    let cmd = DeviceCommand {
        rotation: alpha,
        ..Default::default()
    };
    for segments in [7usize, 40] {
        let mut rod = DerRod::from_body(&body, segments).unwrap();
        rod.tip_torque = Vec3::new(torque, 0.0, 0.0);
        rod.solve_static(&cmd).unwrap();
        let m1 = rod.material_frame(rod.num_nodes() - 2).column(0).into_owned();
        let twist = signed_angle(&Vec3::y(), &m1, &Vec3::x());
        // 1e-6 rad from the brief; measured ~1e-12 (Newton tolerance).
        assert!(
            (twist - expect).abs() < 1e-6,
            "segments {segments}: tip twist {twist} expected {expect}"
        );
        // Same through the dynamic path: quasi-static twist equilibrates every step.
        let mut rod = DerRod::from_body(&body, segments).unwrap();
        rod.tip_torque = Vec3::new(torque, 0.0, 0.0);
        for _ in 0..3 {
            rod.step(1e-3, &cmd).unwrap();
        }
        let m1 = rod.material_frame(rod.num_nodes() - 2).column(0).into_owned();
        let twist = signed_angle(&Vec3::y(), &m1, &Vec3::x());
        assert!(
            (twist - expect).abs() < 1e-6,
            "stepped, segments {segments}: tip twist {twist} expected {expect}"
        );
    }
}

/// At static equilibrium the hand force and torque equal the total external
/// load and its moment about the clamp (moment balance of the discrete rod:
/// its energy is invariant under rigid rotations).
#[test]
fn hand_wrench_balances_external_loads() {
    let mut body = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0);
    body.base = surgbench_core::Iso3::new(Vec3::new(0.01, -0.02, 0.03), Vec3::new(0.2, -0.4, 0.3));
    body.tip_force = Vec3::new(0.01, 0.02, -0.015);
    body.tip_torque = Vec3::new(1e-4, -2e-4, 3e-4);
    let mut rod = DerRod::from_body(&body, 30).unwrap();
    rod.gravity = Vec3::new(0.0, 0.0, -9.81);
    let st = rod
        .solve_static(&DeviceCommand {
            rotation: 0.3,
            ..Default::default()
        })
        .unwrap();
    assert!(st.converged, "{st:?}");
    let (f, t) = rod.hand_wrench();
    let p = rod.node(1);
    let tip = rod.node(rod.num_nodes() - 1);
    let mut fe = body.tip_force;
    let mut te = (tip - p).cross(&body.tip_force) + body.tip_torque;
    for k in 0..rod.num_nodes() {
        let w = rod.gravity * rod.node_mass(k);
        fe += w;
        te += (rod.node(k) - p).cross(&w);
    }
    let ferr = (f - fe).norm() / fe.norm();
    let terr = (t - te).norm() / te.norm();
    eprintln!(
        "hand force {f:?} vs {fe:?} (rel {ferr:.2e}); torque rel err {terr:.2e}; stretch {:.2e}",
        rod.max_stretch()
    );
    // Equilibrium holds to the Newton tolerance (1e-9 relative updates):
    // measured ~1e-10; 1e-7 leaves margin for the stiff stretch modes.
    assert!(
        ferr < 1e-7 && terr < 1e-7,
        "hand force {f:?} vs {fe:?}, torque {t:?} vs {te:?}"
    );
    assert!(rod.max_stretch().abs() < 1e-4);
}
