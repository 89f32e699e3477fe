//! The harness contract: capability checks, fidelity validation, a settle
//! scene through `Model::step`, and the energy probe (forces = -dE/dq).

use surgbench_core::{BuildError, DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Settle, Vec3};
use surgbench_der::DerFactory;

fn sag_scene() -> Scene {
    let mut s = Scene::empty("sag");
    s.bodies.push(RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).into());
    s.gravity = Vec3::new(0.0, 0.0, -9.81);
    s.settle = Some(Settle {
        velocity_tol: 1e-6,
        min_time: 0.0,
    });
    s
}

#[test]
fn check_rejects_what_der_cannot_model() {
    let f = DerFactory;
    assert!(f.check(&sag_scene()).is_ok());
    let mut two = sag_scene();
    two.bodies.push(RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).into());
    let e = f.check(&two).unwrap_err();
    assert!(e.reason.contains("exactly one rod"), "{e}");
    assert!(f.check(&Scene::empty("none")).is_err());
    #[derive(Debug)]
    struct Still;
    impl surgbench_core::flow::FlowField for Still {
        fn velocity(&self, _: &Vec3) -> Vec3 {
            Vec3::zeros()
        }
    }
    let mut flow = sag_scene();
    flow.environment.flow = Some(std::sync::Arc::new(Still));
    // Flow drag is modelled (see tests/flow.rs).
    assert!(f.check(&flow).is_ok(), "flow scene rejected: {:?}", f.check(&flow));
}

#[test]
fn bad_fidelity_is_a_value_not_a_panic() {
    let f = DerFactory;
    let scene = sag_scene();
    for pairs in [
        &["typo=1"][..],
        &["integrator=2"],
        &["integrator=newmark-beta"],
        &["dynamic_twist=2"],
        &["damping=-1"],
        &["tolerance=2"],
        &["segments=1"],
        &["friction_creep=0"],
        &["substep_depth=1.5"],
        &["friction_creep=-1e-6"],
    ] {
        let fid = Fidelity::parse_pairs(pairs).unwrap();
        match f.build(&scene, &fid) {
            Err(BuildError::BadParameter { .. }) => {}
            other => panic!("{pairs:?} should be BadParameter, got {:?}", other.map(|_| ())),
        }
    }
}

/// Statics scene through the harness path at the default fidelity: settles
/// onto the Euler-Bernoulli sag (0.5%: 40 segments measured ~6e-4 relative,
/// plus the settle tolerance) and reports the hand force = weight.
#[test]
fn settle_scene_reaches_euler_bernoulli_through_step() {
    let f = DerFactory;
    let scene = sag_scene();
    let fid = f.default_fidelity(&scene);
    let mut m = f.build(&scene, &Fidelity::default()).unwrap();
    let dt = m.dt();
    assert_eq!(Some(dt), fid.dt);
    let mut steps = 0;
    loop {
        let st = m.step(dt, &DeviceCommand::default()).unwrap();
        assert!(st.converged && st.iterations > 0, "{st:?}");
        steps += 1;
        if m.observe().max_speed() < 1e-6 || steps > 500 {
            break;
        }
    }
    let obs = m.observe();
    let s = RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).sections[0].clone();
    let q = s.density * s.area() * 9.81;
    let w = q * 0.1f64.powi(4) / (8.0 * s.youngs_modulus * s.second_moment());
    let tip = obs.rods[0].tip();
    eprintln!(
        "settled in {steps} steps of {dt:.3e} s: tip {tip:?}, EB {w:e}, hand {:?}",
        obs.hand_force
    );
    assert!(steps <= 500, "did not settle");
    assert!((-tip.z - w).abs() < 5e-3 * w, "tip {} vs EB {w}", -tip.z);
    let weight = q * 0.1;
    // Settled to 1e-6 m/s, not to rest: the remaining inertia shows up in the
    // hand force (measured 6e-6 relative); 1e-4 bounds it.
    assert!(
        (obs.hand_force.z + weight).abs() < 1e-4 * weight,
        "hand {:?} vs weight {weight}",
        obs.hand_force
    );
    assert_eq!(obs.rods[0].arclength[0], -0.1 / 40.0);
    assert!(obs.is_finite());
}

/// Conformance-style check: probe forces equal minus the central difference
/// of the probe potential on every free coordinate of a bent, twisted rod.
#[test]
fn energy_probe_forces_are_minus_gradient() {
    let f = DerFactory;
    let mut scene = sag_scene();
    if let surgbench_core::Body::Rod(r) = &mut scene.bodies[0] {
        r.tip_force = Vec3::new(0.0, 0.2, -0.3);
    }
    let mut m = f
        .build(&scene, &Fidelity::parse_pairs(&["segments=8"]).unwrap())
        .unwrap();
    for k in 0..20 {
        m.step(
            2e-3,
            &DeviceCommand {
                rotation: 0.05 * k as f64,
                ..Default::default()
            },
        )
        .unwrap();
    }
    let p = m.energy_probe().unwrap();
    let q0 = p.coords();
    let forces = p.forces();
    let mut worst: f64 = 0.0;
    let scale = p
        .free()
        .iter()
        .map(|&i| forces[i].abs() * if i % 4 == 3 { 1.0 } else { 1e-3 })
        .fold(0.0, f64::max);
    for i in p.free() {
        let h = if i % 4 == 3 { 1e-6 } else { 1e-9 };
        let mut q = q0.clone();
        q[i] += h;
        p.set_coords(&q);
        let ep = p.potential();
        q[i] -= 2.0 * h;
        p.set_coords(&q);
        let em = p.potential();
        p.set_coords(&q0);
        let fd = -(ep - em) / (2.0 * h);
        let w = if i % 4 == 3 { 1.0 } else { 1e-3 };
        worst = worst.max((fd - forces[i]).abs() * w / scale);
    }
    eprintln!("probe: worst relative force error {worst:.2e}");
    // Central differences of an energy dominated by stiff stretching:
    // rounding eps*E/h ~ 1e-7 relative; 1e-5 leaves margin.
    assert!(worst < 1e-5, "probe forces differ from -dE/dq by {worst:e} (relative)");
}
