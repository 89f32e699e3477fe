//! A moving vessel: pbd-rod measures friction slip against the moving wall.

use std::sync::Arc;
use surgbench_core::motion::CardiacMotion;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};
use surgbench_pbd::PbdRodFactory;

/// A wire lying on the bottom of a tube that slides along its axis (the
/// whole tube translates, `x(t) = A s(t)`, fastest at 1.625 s): the clamped
/// wire cannot follow, every contact slides, and the friction the wall
/// exerts is `mu_k` times the normal force, along the wall's velocity.
/// Friction anchored to a still wall would see no slip and give none.
#[test]
fn friction_is_measured_against_the_moving_wall() {
    let mut scene = Scene::empty("sliding-wall");
    scene.bodies.push(RodBody::uniform(0.2, 2e-4, 5e10, 0.3, 6450.0).into());
    scene.gravity = Vec3::new(0.0, 0.0, -9.81);
    scene.duration = 2.0;
    scene.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1e-3,
    }));
    let motion = CardiacMotion::new(Vec3::zeros(), Vec3::y(), Vec3::x(), -1.0, 0.5, 2e-3, 2.0).unwrap();
    scene.environment.vessel_motion = Some(Arc::new(motion));
    scene.environment.contact.friction_static = 0.2;
    scene.environment.contact.friction_dynamic = 0.15;
    scene.environment.contact.margin = 2e-4;
    let mut f = Fidelity {
        segments: Some(40),
        ..Default::default()
    };
    f.set_setting("solver", "direct".into()).unwrap();
    f.set("damping", 50.0).unwrap();
    let mut m = PbdRodFactory.build(&scene, &f).unwrap();
    let dt = 1e-3;
    for _ in 0..1625 {
        m.step(dt, &DeviceCommand::default()).unwrap();
    }
    let obs = m.observe();
    let (mut fx, mut fz) = (0.0, 0.0);
    for c in &obs.contacts {
        fx += c.force.x;
        fz += c.force.z;
    }
    let ratio = fx / fz;
    eprintln!(
        "{} contacts, axial {fx:e} N, normal {fz:e} N, ratio {ratio}",
        obs.contacts.len()
    );
    assert!(obs.contacts.len() >= 5, "the wire should lie on the wall");
    // Every projection slides (the wall moves 25 um per 1 ms step, the
    // normal corrections are sub-micrometre) and removes exactly mu_k times
    // its normal correction of the slip; the wire lies at the bottom, so the
    // normals are -z and the sums keep the ratio to rounding (measured 2e-16).
    assert!(
        (ratio - 0.15).abs() < 1e-12,
        "friction/normal {ratio}, expected mu_k = 0.15"
    );
}
