//! Statics of the rigid chain (multibody joints) against Euler-Bernoulli
//! closed forms: the deflection under gravity converges at second order in
//! the link length (the midpoint rule of the bar chain), a uniform twist is
//! exact, and the clamp reads the rod's weight and the tip torque.

use std::f64::consts::PI;
use surgbench_core::frames::signed_angle;
use surgbench_core::{DeviceCommand, RodBody, Vec3};
use surgbench_multibody::{ChainParams, RigidChain};

/// The default rod scenes' wire: nitinol-like, 0.1 m, radius 0.5 mm.
fn wire() -> RodBody {
    RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0)
}

/// The wire with a dead axial tip torque of 0.01 N m, and the tip twist
/// `pi/2 + T L / (GJ)` a clamp turned by pi/2 gives it (rad).
fn twisted_wire() -> (RodBody, f64, f64) {
    let mut body = wire();
    let torque = 0.01;
    body.tip_torque = Vec3::new(torque, 0.0, 0.0);
    let s = &body.sections[0];
    let want = PI / 2.0 + torque * body.length / (s.shear_modulus() * s.polar_moment());
    (body, torque, want)
}

/// Twist of the tip's material frame from the unturned clamp's `d1 = +y`
/// about the rod axis, in [0, 2 pi) (rad).
fn tip_twist(c: &RigidChain) -> f64 {
    let f = c.rod_obs().tip_frame();
    let angle = signed_angle(&Vec3::y(), &f.column(0).into_owned(), &f.column(2).into_owned());
    if angle < 0.0 { angle + 2.0 * PI } else { angle }
}

/// A critically damped chain of `n` links at one substep (the model's
/// static defaults).
fn chain(body: &RodBody, gravity: f64, n: usize, rotation: f64) -> RigidChain {
    let p = ChainParams {
        links: n,
        damping_ratio: 1.0,
        substeps: 1,
        ..Default::default()
    };
    RigidChain::new(body, Vec3::new(0.0, 0.0, -gravity), &p, rotation).unwrap()
}

/// Step `dt` = 1 ms at the clamp's `rotation` until every node and every
/// frame is still to 1e-12 (m/s, rad/step) or `duration` s have passed.
fn run(c: &mut RigidChain, duration: f64, rotation: f64) {
    let cmd = DeviceCommand {
        rotation,
        ..Default::default()
    };
    let mut frames = c.rod_obs().frames;
    while c.time() < duration - 1e-12 {
        c.step(1e-3, &cmd).unwrap();
        let obs = c.rod_obs();
        let v = obs.velocities.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let w = obs
            .frames
            .iter()
            .zip(&frames)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        frames = obs.frames;
        if v < 1e-12 && w < 1e-12 {
            break;
        }
    }
}

/// Tip deflection under gravity against `q L^4 / (8 EI)` at 10 to 80
/// links: the error falls by 4 per halving (midpoint rule, O(h^2)).
/// Measured: -5.0e-3, -1.26e-3, -3.2e-4, -8.3e-5.
#[test]
fn gravity_deflection_converges_at_second_order() {
    let body = wire();
    let g = 9.81;
    let s = &body.sections[0];
    let (ei, q) = (s.youngs_modulus * s.second_moment(), s.density * s.area() * g);
    let eb = q * body.length.powi(4) / (8.0 * ei);
    let mut errors = Vec::new();
    for n in [10, 20, 40, 80] {
        let mut c = chain(&body, g, n, 0.0);
        run(&mut c, 1.0, 0.0);
        errors.push((-c.tip().z - eb) / eb);
        // The clamp carries the whole weight; its moment is q L^2 / 2 up to
        // the shortening of the lever arm, O((tip / L)^2) = 6e-6.
        let (f, t) = c.hand_wrench();
        let weight = q * body.length;
        assert!(
            (f.z + weight).abs() < 1e-9 * weight,
            "n={n}: hand force {f:?}, weight {weight}"
        );
        let moment = q * body.length.powi(2) / 2.0;
        assert!(
            (t.y - moment).abs() < 1e-4 * moment,
            "n={n}: hand torque {t:?}, q L^2/2 = {moment}"
        );
    }
    println!("relative tip errors at 10..80 links: {errors:?}");
    for w in errors.windows(2) {
        let order = (w[0] / w[1]).log2();
        // Midpoint rule: order 2; 1.9 allows the small-deflection closed
        // form's own O((tip/L)^2) = 6e-6 error at 80 links.
        assert!((1.9..2.1).contains(&order), "observed order {order} from {errors:?}");
    }
    assert!(errors[3].abs() < 1e-4, "80 links: {:e}", errors[3]);
}

/// A clamp turned by pi/2 and a tip torque: every joint twists by
/// `T h / (GJ)`, so the tip turns by `pi/2 + T L / (GJ)` exactly (the
/// midpoint rule is exact for a constant moment); the clamp reads `T`.
#[test]
fn uniform_twist_is_exact() {
    let (body, torque, want) = twisted_wire();
    for n in [10, 40] {
        let mut c = chain(&body, 0.0, n, PI / 2.0);
        run(&mut c, 1.0, PI / 2.0);
        let got = tip_twist(&c);
        // Round-off over n joints and the settle (to 1e-12 rad per step).
        assert!((got - want).abs() < 1e-9, "n={n}: tip twist {got}, want {want}");
        assert!((c.tip() - Vec3::new(body.length, 0.0, 0.0)).norm() < 1e-12);
        let (_, t) = c.hand_wrench();
        assert!(
            (t - Vec3::new(torque, 0.0, 0.0)).norm() < 1e-9 * torque,
            "hand torque {t:?}"
        );
    }
}

/// A pre-curved chain (rest curvature (4, 10) 1/m, a helix-free bend out of
/// both planes) with no load stays where it was built: its joint springs
/// are at rest there, so 200 steps move no node by more than round-off.
#[test]
fn a_pre_curved_chain_without_load_stays_on_its_rest_shape() {
    let mut body = wire();
    body.sections[0].rest_curvature = [4.0, 10.0];
    let mut c = chain(&body, 0.0, 20, 0.3);
    let start = c.rod_obs();
    assert_eq!(start.rest, start.nodes, "built on the rest shape");
    run(&mut c, 0.2, 0.3);
    let moved = c
        .rod_obs()
        .nodes
        .iter()
        .zip(&start.nodes)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    // Round-off of 20 joint rotations on a 0.1 m rod.
    assert!(moved < 1e-13, "a node moved {moved:e} m");
    assert!(
        c.energies().elastic < 1e-20,
        "elastic energy {:e} J",
        c.energies().elastic
    );
}

/// The clamp turned by the operator over time (a ramp to pi/2 in 0.1 s,
/// then held) with the tip torque on: the chain ends where the clamp built
/// turned from the start does (torque-transfer's answer, to the settle
/// tolerance), and the hand carries the torque.
#[test]
fn a_clamp_turned_over_time_ends_as_one_built_turned() {
    let (body, torque, want) = twisted_wire();
    let mut c = chain(&body, 0.0, 10, 0.0);
    let mut t = 0.0;
    while t < 0.1 - 1e-12 {
        t += 1e-3;
        let cmd = DeviceCommand {
            rotation: PI / 2.0 * (t / 0.1),
            ..Default::default()
        };
        c.step(1e-3, &cmd).unwrap();
    }
    run(&mut c, 1.0, PI / 2.0);
    let got = tip_twist(&c);
    // Settled to 1e-12 rad per step, as in uniform_twist_is_exact.
    assert!((got - want).abs() < 1e-9, "tip twist {got}, want {want}");
    let (_, hand) = c.hand_wrench();
    assert!(
        (hand - Vec3::new(torque, 0.0, 0.0)).norm() < 1e-9 * torque,
        "hand torque {hand:?}"
    );
}
