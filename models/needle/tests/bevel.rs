//! Bevel tip (seed Sec. 3.5): the tip cuts its new channel end
//! `d tan(psi)` to the side of the tip edge's material axis m_2, so a
//! flexible needle bends towards m_2; a symmetric tip (psi = 0) goes
//! straight.

mod common;

use surgbench_core::{Body, Fidelity, ModelFactory, Scene, Vec3};
use surgbench_needle::NeedleFactory;

/// The test scene (13 mm of insertion at 10 mm/s, the tip starting 1 mm
/// out) with a 0.83 mm needle of Young's modulus 50 GPa (nitinol-like,
/// flexible against the gel over 12 mm) and bevel angle `psi` (rad).
fn flexible_needle(psi: f64) -> Scene {
    let mut scene = common::scene(&[(0.0, 0.0), (1.3, 13e-3)], [8, 4, 4], 20.0, 0.05);
    let Body::Rod(r) = &mut scene.bodies[0] else {
        unreachable!("the needle is the first body")
    };
    r.sections.iter_mut().for_each(|s| s.youngs_modulus = 50e9);
    scene.needle.as_mut().unwrap().bevel_angle = psi;
    scene
}

/// Insert 12 mm of [`flexible_needle`] with bevel angle `psi`. Returns the
/// tip's offset from the insertion axis (m), the tip edge's m_2 at the start
/// and the model's diagnostics.
fn insert(psi: f64) -> (Vec3, Vec3, std::collections::BTreeMap<String, f64>) {
    let scene = flexible_needle(psi);
    let mut m = NeedleFactory.build(&scene, &Fidelity::default()).unwrap();
    let m2 = m.observe().rods[0].tip_frame().column(1).into_owned();
    let dt = m.dt();
    let n = (scene.duration / dt).round() as usize;
    for i in 1..=n {
        m.step(dt, &scene.control.command_at(i as f64 * dt)).unwrap();
    }
    let tip = m.observe().rods[0].tip();
    (Vec3::new(0.0, tip.y, tip.z), m2, m.diagnostics())
}

#[test]
fn a_bevel_tip_bends_a_flexible_needle_towards_m2() {
    let (straight, _, d0) = insert(0.0);
    let (bent, m2, d1) = insert(0.25);
    let (more, _, d2) = insert(0.5);
    // The block mesh is mirror-symmetric about the needle's axis
    // (`mesh::block_mirrored`): the symmetric tip goes straight to rounding
    // (measured 2e-17 m; on the plain block, whose tets all split along one
    // diagonal, it drifted 0.28 mm along that diagonal).
    assert!(straight.norm() < 1e-12, "psi = 0 went sideways: {straight:?}");
    // Measured: psi = 0.25 and 0.5 move the tip 1.81 and 1.87 mm along
    // m_2. The size of the bend is not resolved at this mesh (it was 1.99
    // and 2.34 mm on the plain block, and with the needle through the cells
    // the steeper bevel bent less), so only its side is asserted: more than
    // 1 mm along m_2.
    for tip in [bent, more] {
        let bend = tip.dot(&m2);
        assert!(
            bend > 1e-3,
            "the tip moved {bend} m to the m_2 side ({tip:?}, m_2 {m2:?})"
        );
    }
    // Every cut found its channel end and none lost the tip; psi = 0 and
    // 0.25 never needed the quarter-tet slack (psi = 0.5 may: on the plain
    // block one of its cuts did).
    for d in [&d0, &d1, &d2] {
        assert_eq!(d["tip_lost"], 0.0);
    }
    assert_eq!(d0["tip_fallback_steps"] + d1["tip_fallback_steps"], 0.0);
}

/// Insert 12 mm of the 50 GPa, psi = 0.5 needle, the base turned by
/// `turn` (rad) between 6 and 6.5 mm of insertion. Returns the tip's z (m)
/// when the turn starts and at the end, and the tip edge's m_2 at the end.
fn insert_turning(turn: f64) -> (f64, f64, Vec3) {
    use surgbench_core::ControlKey;
    let mut scene = flexible_needle(0.5);
    scene.control.keys = vec![
        ControlKey::feed(0.0, 0.0, 0.0),
        ControlKey::feed(0.7, 7e-3, 0.0),
        ControlKey::feed(0.75, 7.5e-3, turn),
        ControlKey::feed(1.3, 13e-3, turn),
    ];
    let mut m = NeedleFactory.build(&scene, &Fidelity::default()).unwrap();
    let dt = m.dt();
    let mut at_turn = 0.0;
    for i in 1..=1300 {
        m.step(dt, &scene.control.command_at(i as f64 * dt)).unwrap();
        if i == 700 {
            at_turn = m.observe().rods[0].tip().z;
        }
    }
    let o = m.observe();
    (at_turn, o.rods[0].tip().z, o.rods[0].tip_frame().column(1).into_owned())
}

#[test]
fn turning_the_base_by_pi_bends_the_needle_back() {
    // The double bend of issue 17's `needle-double-bend`: half a turn of the
    // base turns the bevel, and the path bends the other way. Measured: the
    // tip rose 0.93 mm along +z before the turn; then +0.93 mm more without
    // the turn, -2.21 mm with it.
    let (z0, z_straight_on, _) = insert_turning(0.0);
    let (z1, z_turned, m2) = insert_turning(std::f64::consts::PI);
    assert_eq!(z0, z1, "the same path up to the turn");
    assert!(z0 > 5e-4, "bent towards +z before the turn: {z0} m");
    assert!(z_straight_on > z0, "without the turn it bends on: {z_straight_on} m");
    // The twist reaches the tip: its m_2 now points along -z (a stiff tube
    // in torsion; the shaft's friction acts on positions only).
    assert!(m2.z < -0.99, "tip m_2 after the turn: {m2:?}");
    assert!(
        z_turned < z0 - 1e-3,
        "with the turn it bends back: {z_turned} m from {z0} m"
    );
}
