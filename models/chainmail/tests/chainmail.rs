//! Verification of the chain-mail guidewire: the paper's rules, their
//! limits, determinism, calibration and the factory contract.

use std::sync::Arc;
use surgbench_chainmail::calibration;
use surgbench_chainmail::mapping::{self, BETA_CONSTANT};
use surgbench_chainmail::rules::{self, LinkParams};
use surgbench_chainmail::{BoxFrame, ChainmailFactory, ChainmailWire, WireConfig};
use surgbench_core::flow::FlowField;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{BuildError, DeviceCommand, Fidelity, Iso3, Mat3, ModelFactory, RodBody, Scene, SimError, Vec3};

/// xorshift64* (seeded, no dependency).
use surgbench_core::rng::SplitMix64 as Rng;

fn cantilever(g: f64) -> Scene {
    let mut s = Scene::empty("cantilever");
    s.bodies.push(RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0).into());
    s.gravity = Vec3::new(0.0, 0.0, -g);
    s
}

fn cfg(dt: f64, beta: Option<f64>, frame: BoxFrame) -> WireConfig {
    WireConfig {
        segments: 20,
        iterations: 10,
        dt,
        frame,
        beta_constant: BETA_CONSTANT,
        beta_mapping: mapping::BetaMapping::Weight,
        beta_override: beta,
        haptic_k: None,
    }
}

fn wire(scene: &Scene, c: &WireConfig) -> ChainmailWire {
    ChainmailWire::new(scene.rods().next().unwrap(), scene.gravity, &scene.environment, c).unwrap()
}

fn settle(w: &mut ChainmailWire, dt: f64, steps: usize) {
    for _ in 0..steps {
        w.advance(dt, &DeviceCommand::default()).unwrap();
    }
}

#[test]
fn projection_is_nearest_point_of_the_box_both_sides() {
    let p = LinkParams {
        alpha_min: 0.9,
        alpha_max: 1.1,
        beta: 0.2,
    };
    let frame = Mat3::identity();
    let sponsor = Vec3::new(1.0, 2.0, 3.0);
    for side in [1.0, -1.0] {
        let d = Vec3::new(side * 0.1, 0.0, 0.0);
        // inside: untouched (x offset 0.1, lateral 0.01 < beta*0.1)
        let q_in = sponsor + Vec3::new(side * 0.1, 0.01, -0.01);
        let (q, moved) = rules::project_into_box(&sponsor, &q_in, &d, &frame, &p);
        assert!(!moved && q == q_in, "side {side}: inside point moved to {q:?}");
        // outside in all axes: per-axis clamp to [0.09, 0.11] (mirrored) and |lat| <= 0.02
        let q_out = sponsor + Vec3::new(side * 0.5, 0.3, -0.3);
        let (q, moved) = rules::project_into_box(&sponsor, &q_out, &d, &frame, &p);
        let expect = sponsor + Vec3::new(side * 0.11, 0.02, -0.02);
        assert!(
            moved && (q - expect).norm() < 1e-15,
            "side {side}: got {q:?}, expected {expect:?}"
        );
        // rounding of sponsor + offset - sponsor only
        assert!(rules::box_violation(&sponsor, &q, &d, &frame, &p) < 1e-15);
        // compressed below alpha_min: pushed out to 0.09
        let q_c = sponsor + Vec3::new(side * 0.05, 0.0, 0.0);
        let (q, _) = rules::project_into_box(&sponsor, &q_c, &d, &frame, &p);
        assert!(
            (q - (sponsor + Vec3::new(side * 0.09, 0.0, 0.0))).norm() < 1e-15,
            "side {side}: {q:?}"
        );
    }
}

#[test]
fn propagation_stops_at_the_first_valid_neighbour() {
    let s = cantilever(0.0);
    let beta = 0.1;
    let mut w = wire(&s, &cfg(0.01, Some(beta), BoxFrame::World));
    let d = w.delta();
    let k = 11;
    let mut x = w.nodes().to_vec();
    // a small lateral move inside the box moves nobody
    x[k].y += 0.5 * beta * d;
    w.set_nodes(&x);
    assert_eq!(w.propagate_from(k), 0, "move within the box propagated");
    // a move of 3.5 beta Delta: neighbours at 1, 2, 3 links each way end
    // at 2.5, 1.5, 0.5 beta Delta; the 4th is valid and the wave stops
    x[k].y = 3.5 * beta * d;
    w.set_nodes(&x);
    let before = w.nodes().to_vec();
    let moved = w.propagate_from(k);
    assert_eq!(moved, 6, "expected 3 elements moved each way");
    let after = w.nodes();
    for j in 0..after.len() {
        let dist = j.abs_diff(k);
        if dist >= 4 {
            assert_eq!(after[j], before[j], "node {j} beyond the wave moved");
        } else if dist > 0 {
            let expect = (3.5 - dist as f64) * beta * d;
            assert!(
                (after[j].y - expect).abs() < 1e-15,
                "node {j}: y = {} expected {expect}",
                after[j].y
            );
        }
    }
    assert!(
        w.box_residual() < 1e-12,
        "boxes violated after propagation: {}",
        w.box_residual()
    );
}

#[test]
fn relaxation_energy_never_increases() {
    let s = cantilever(0.0);
    for seed in [1u64, 7, 42] {
        let mut w = wire(&s, &cfg(0.01, Some(0.3), BoxFrame::World));
        let mut rng = Rng(seed);
        let mut x = w.nodes().to_vec();
        for p in x.iter_mut() {
            *p += rng.signed_vec() * 2e-3;
        }
        w.set_nodes(&x);
        let e0 = w.relaxation_energy();
        let mut e = e0;
        for it in 0..60 {
            w.relax_sweep();
            let e1 = w.relaxation_energy();
            // exact coordinate minimization: only rounding may raise it
            assert!(
                e1 <= e * (1.0 + 1e-12),
                "seed {seed} sweep {it}: energy rose {e} -> {e1}"
            );
            e = e1;
        }
        // Gauss-Seidel on a 20-node path converges geometrically (measured
        // factor ~0.99 per sweep, so 60 sweeps lose well over half)
        assert!(e < 0.5 * e0, "seed {seed}: energy {e0} -> {e} after 60 sweeps");
    }
}

#[test]
fn beta_zero_is_rigid_under_gravity() {
    let s = cantilever(9.81);
    let mut w = wire(&s, &cfg(0.01, Some(0.0), BoxFrame::World));
    settle(&mut w, 0.01, 2000);
    let tip = *w.nodes().last().unwrap();
    // beta = 0, alpha = 1: each box is a single point, so the answer is the
    // rest line to rounding
    assert!(
        (tip - Vec3::new(0.2, 0.0, 0.0)).norm() < 1e-14,
        "rigid wire moved: tip {tip:?}"
    );
}

#[test]
fn larger_beta_sags_more_when_boxes_bind() {
    // the paper's Figure 6 ordering (0.25, 0.35, 0.5) needs boxes that bind:
    // at dt = 1/30 s the gravity step g dt^2 = 11 mm outruns the relaxation
    let s = cantilever(9.81);
    let sag = |beta: f64, dt: f64| {
        let mut w = wire(&s, &cfg(dt, Some(beta), BoxFrame::World));
        settle(&mut w, dt, 3000);
        -w.nodes().last().unwrap().z
    };
    let fig6: Vec<f64> = [0.25, 0.35, 0.5].iter().map(|&b| sag(b, 1.0 / 30.0)).collect();
    eprintln!("tip sag at dt=1/30 s for beta 0.25, 0.35, 0.5: {fig6:?}");
    assert!(fig6[0] < fig6[1] && fig6[1] < fig6[2], "ordering broken: {fig6:?}");
    // at dt = 0.01 s the relaxation limits the sag below all three boxes:
    // beta then has no effect at all (a limit of the model, recorded here)
    let dflt: Vec<f64> = [0.25, 0.35, 0.5].iter().map(|&b| sag(b, 0.01)).collect();
    eprintln!("tip sag at dt=0.01 s for beta 0.25, 0.35, 0.5: {dflt:?}");
    assert!(
        dflt[0] == dflt[1] && dflt[1] == dflt[2],
        "expected identical relaxation-limited sags: {dflt:?}"
    );
}

#[test]
fn calibration_reproduces_the_committed_constant() {
    let c = calibration::calibrate_beta_constant().unwrap();
    eprintln!("{c:?}");
    // bisection stops at a relative bracket of 1e-6; the committed value is
    // rounded to 7 significant digits
    let rel = (c.constant - BETA_CONSTANT).abs() / BETA_CONSTANT;
    assert!(
        rel < 2e-6,
        "calibration drifted: recomputed {} vs committed {BETA_CONSTANT}",
        c.constant
    );
    assert!((c.tip_deflection - c.target).abs() < 1e-5 * c.target, "{c:?}");
}

#[test]
fn gravity_sag_depends_on_fidelity() {
    // not a pass/fail physics claim: records that the calibrated model does
    // not converge under refinement (beta ~ Delta^3, sag ~ relaxation vs g dt^2)
    let s = cantilever(9.81);
    let target = calibration::calibration_target();
    let mut out = Vec::new();
    for (n, dt, it) in [(20, 1e-2, 10), (40, 1e-2, 10), (20, 1e-3, 10), (20, 1e-2, 40)] {
        let mut c = cfg(dt, None, BoxFrame::World);
        c.segments = n;
        c.iterations = it;
        let mut w = wire(&s, &c);
        let mut steps = 0;
        while steps < 200_000 {
            w.advance(dt, &DeviceCommand::default()).unwrap();
            steps += 1;
            if w.max_speed() * dt < 1e-13 {
                break;
            }
        }
        out.push((n, dt, it, -w.nodes().last().unwrap().z / target));
    }
    eprintln!("tip sag / Euler-Bernoulli (segments, dt, iterations, ratio): {out:?}");
    // the calibration scene itself at the default fidelity hits the target
    assert!((out[0].3 - 1.0).abs() < 1e-5, "{out:?}");
}

fn rigid_answer(frame: &str) -> f64 {
    let mut s = cantilever(9.81);
    s.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::new(0.0, 0.0, 0.0),
        axis: Vec3::x(),
        radius: 2e-3,
    }));
    let iso = Iso3::new(Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.3, -0.5, 0.7));
    let st = s.transformed(&iso);
    let mut f = Fidelity::default();
    f.extras.insert("frame".into(), frame.into());
    let mut a = ChainmailFactory.build(&s, &f).unwrap();
    let mut b = ChainmailFactory.build(&st, &f).unwrap();
    for k in 0..300 {
        let cmd = DeviceCommand {
            insertion: 1e-4 * k as f64,
            ..Default::default()
        };
        a.step(0.01, &cmd).unwrap();
        b.step(0.01, &cmd).unwrap();
    }
    let (oa, ob) = (a.observe(), b.observe());
    oa.rods[0]
        .nodes
        .iter()
        .zip(&ob.rods[0].nodes)
        .map(|(p, q)| (iso.transform_point(&(*p).into()).coords - q).norm())
        .fold(0.0, f64::max)
}

#[test]
fn rigid_motion_of_the_scene_base_frame_passes_world_frame_fails() {
    let world = rigid_answer("world");
    let base = rigid_answer("clamp");
    eprintln!("max node discrepancy after a rigid motion: world axes {world:.3e} m, base axes {base:.3e} m");
    // base frame: equivariant up to rounding of the 3x3 rotations (~1e-16 m per op)
    assert!(base < 1e-12, "base-frame rule not rigid-motion invariant: {base}");
    // the paper's world-axis boxes are not: the answer changes by far more
    assert!(world > 1e-5, "world-axis rule unexpectedly invariant: {world}");
}

#[derive(Debug)]
struct Swirl;
impl FlowField for Swirl {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        Vec3::new(0.01, -p.z, p.y) * 0.5
    }
}

fn busy_scene(c_f: f64) -> Scene {
    let mut s = cantilever(9.81);
    s.environment.vessel = Some(Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1.5e-3,
    }));
    s.environment.flow = Some(Arc::new(Swirl));
    s.environment.contact.friction_static = c_f;
    s.environment.contact.margin = 1e-4;
    s
}

/// `steps` steps of 10 ms of the default chain-mail in `s`, pushing and
/// turning the wire a little every step; every observation.
fn push_and_turn(s: &Scene, steps: usize) -> Vec<surgbench_core::Observation> {
    let mut m = ChainmailFactory.build(s, &Fidelity::default()).unwrap();
    let mut obs = Vec::new();
    for k in 0..steps {
        let cmd = DeviceCommand {
            insertion: 2e-4 * k as f64,
            rotation: 0.01 * k as f64,
            load: 0.0,
            base_pose: None,
        };
        m.step(0.01, &cmd).unwrap();
        obs.push(m.observe());
    }
    obs
}

#[test]
fn reruns_are_bit_identical() {
    let run = || push_and_turn(&busy_scene(0.3), 400);
    let (a, b) = (run(), run());
    assert!(a == b, "reruns differ");
    assert!(
        !a.last().unwrap().contacts.is_empty(),
        "scene meant to exercise contacts had none"
    );
}

#[test]
fn friction_factor_limits() {
    // frictionless: all tangential motion kept
    assert_eq!(rules::friction_factor(1e-3, 5e-4, 0.0), -1.0);
    let t = Vec3::new(1e-3, 0.0, 0.0);
    assert_eq!(rules::friction_correction(&t, 5e-4, 0.0), Vec3::zeros());
    // C_f |dp_n| >= |dp_t|: sticks (no tangential motion left)
    assert_eq!(rules::friction_factor(1e-3, 2e-3, 1.0), 0.0);
    assert_eq!(rules::friction_correction(&t, 2e-3, 1.0), -t);
    // sliding: keeps |dp_t| - C_f |dp_n|
    let c = rules::friction_correction(&t, 5e-4, 0.5);
    assert!((t + c - Vec3::new(7.5e-4, 0.0, 0.0)).norm() < 1e-18, "{c:?}");
}

#[test]
fn friction_in_a_tube_slows_the_push_and_loads_the_hand() {
    // wire lying on the bottom of a horizontal tube under gravity, pushed 2 cm
    let push = |c_f: f64| {
        let mut s = busy_scene(c_f);
        s.environment.flow = None;
        let mut m = ChainmailFactory.build(&s, &Fidelity::default()).unwrap();
        let mut hand = 0.0;
        for k in 1..=200 {
            let cmd = DeviceCommand {
                insertion: 1e-4 * k as f64,
                ..Default::default()
            };
            m.step(0.01, &cmd).unwrap();
            hand += m.observe().hand_force.x;
        }
        let o = m.observe();
        (o.rods[0].tip().x, hand / 200.0, o.contacts.len())
    };
    let (free_tip, free_hand, n0) = push(0.0);
    let (stuck_tip, stuck_hand, n1) = push(1.0);
    eprintln!("C_f=0: tip x {free_tip}, mean hand force x {free_hand} N, {n0} contacts");
    eprintln!("C_f=1: tip x {stuck_tip}, mean hand force x {stuck_hand} N, {n1} contacts");
    assert!(n0 > 0 && n1 > 0, "no contacts: the test does not exercise friction");
    // frictionless: the tip advances with the push (inextensible to ~1e-6)
    assert!(
        (free_tip - 0.22).abs() < 1e-4,
        "frictionless tip at {free_tip}, expected 0.22"
    );
    assert!(
        stuck_tip < free_tip,
        "friction did not slow the push: {stuck_tip} vs {free_tip}"
    );
    // the hand feels friction against the push (force on the hand along -x)
    assert!(
        stuck_hand < free_hand,
        "hand force with friction {stuck_hand} not below frictionless {free_hand}"
    );
}

#[test]
fn insertion_feeds_elements_and_retraction_removes_them() {
    let s = cantilever(0.0);
    let mut m = ChainmailFactory.build(&s, &Fidelity::default()).unwrap();
    let n0 = m.observe().rods[0].nodes.len();
    for k in 1..=100 {
        let cmd = DeviceCommand {
            insertion: 5e-4 * k as f64,
            ..Default::default()
        };
        m.step(0.01, &cmd).unwrap();
    }
    let o = m.observe();
    let r = &o.rods[0];
    // 5 cm at Delta = 1 cm: five more elements, tip 5 cm further, short by
    // at most the compression the boxes allow: every link x (1 - alpha_min) Delta
    let slack = (r.nodes.len() - 1) as f64 * (1.0 - w_alpha_min(&s)) * 0.01;
    assert_eq!(
        r.nodes.len(),
        n0 + 5,
        "node count {} after feeding (start {n0})",
        r.nodes.len()
    );
    assert!(
        (r.tip() - Vec3::new(0.25, 0.0, 0.0)).norm() <= slack,
        "tip {:?}, slack {slack}",
        r.tip()
    );
    assert!((r.arclength.last().unwrap() - 0.25).abs() < 1e-12);
    for k in (0..100).rev() {
        let cmd = DeviceCommand {
            insertion: 5e-4 * k as f64,
            ..Default::default()
        };
        m.step(0.01, &cmd).unwrap();
    }
    let r = &m.observe().rods[0];
    assert_eq!(r.nodes.len(), n0);
    assert!(
        (r.tip() - Vec3::new(0.2, 0.0, 0.0)).norm() <= slack,
        "tip {:?}, slack {slack}",
        r.tip()
    );
}

fn w_alpha_min(s: &Scene) -> f64 {
    wire(s, &cfg(0.01, None, BoxFrame::World)).links()[3].alpha_min
}

#[test]
fn observation_frames_velocities_and_stretch() {
    let s = cantilever(9.81);
    let mut m = ChainmailFactory.build(&s, &Fidelity::default()).unwrap();
    let prev = m.observe().rods[0].nodes.clone();
    m.step(
        0.01,
        &DeviceCommand {
            rotation: 0.3,
            ..Default::default()
        },
    )
    .unwrap();
    let o = m.observe();
    let r = &o.rods[0];
    assert_eq!(r.arclength[0], -0.01);
    assert_eq!(r.arclength[1], 0.0);
    assert_eq!(r.frames.len(), r.nodes.len() - 1);
    for (j, f) in r.frames.iter().enumerate() {
        let e = (r.nodes[j + 1] - r.nodes[j]).normalize();
        assert!((f.column(2) - e).norm() < 1e-12, "frame {j} t not along its link");
        assert!(
            (f.transpose() * f - Mat3::identity()).norm() < 1e-12,
            "frame {j} not orthonormal"
        );
    }
    // base frame carries the commanded rotation about the clamp axis
    let d1 = r.frames[0].column(0);
    assert!(
        (d1 - Vec3::new(0.0, 0.3f64.cos(), 0.3f64.sin())).norm() < 1e-12,
        "d1 {d1:?}"
    );
    for j in 0..r.nodes.len() {
        assert!((r.velocities[j] - (r.nodes[j] - prev[j]) / 0.01).norm() < 1e-12);
    }
    assert!(r.max_stretch.abs() < 1e-3, "stretch {}", r.max_stretch);
    assert!(o.is_finite());
}

#[derive(Debug)]
struct NanFlow;
impl FlowField for NanFlow {
    fn velocity(&self, _p: &Vec3) -> Vec3 {
        Vec3::new(f64::NAN, 0.0, 0.0)
    }
}

#[test]
fn non_finite_state_is_a_diverged_error() {
    let mut s = cantilever(9.81);
    s.environment.flow = Some(Arc::new(NanFlow));
    let mut m = ChainmailFactory.build(&s, &Fidelity::default()).unwrap();
    match m.step(0.01, &DeviceCommand::default()) {
        Err(SimError::Diverged { t, .. }) => assert_eq!(t, 0.01),
        other => panic!("expected Diverged, got {other:?}"),
    }
}

#[test]
fn factory_refuses_what_it_cannot_do() {
    let f = ChainmailFactory;
    assert_eq!(f.id(), "chainmail");
    let base = cantilever(9.81);
    assert!(f.check(&base).is_ok());
    let mut s = base.clone();
    if let surgbench_core::Body::Rod(r) = &mut s.bodies[0] {
        r.tip_force = Vec3::new(0.0, 0.0, -1.0);
    }
    assert!(f.check(&s).unwrap_err().reason.contains("tip-force"));
    let mut s = base.clone();
    if let surgbench_core::Body::Rod(r) = &mut s.bodies[0] {
        r.tip_torque = Vec3::new(1e-3, 0.0, 0.0);
    }
    assert!(f.check(&s).unwrap_err().reason.contains("torsional"));
    let mut s = base.clone();
    if let surgbench_core::Body::Rod(r) = &mut s.bodies[0] {
        r.sections[0].rest_curvature = [10.0, 0.0];
    }
    // rest curvature: supported with the link-frame boxes (the default for a
    // curved rod), refused with the clamp- or world-axis boxes
    assert!(f.check(&s).is_ok());
    assert!(f.build(&s, &Fidelity::default()).is_ok());
    assert!(matches!(
        f.build(&s, &Fidelity::parse_pairs(&["frame=clamp"]).unwrap()),
        Err(BuildError::Unsupported(_))
    ));
    let bad = |pairs: &[&str]| {
        matches!(
            f.build(&base, &Fidelity::parse_pairs(pairs).unwrap()),
            Err(BuildError::BadParameter { .. })
        )
    };
    assert!(bad(&["typo=1"]));
    assert!(bad(&["frame=3"]));
    assert!(bad(&["beta=-1"]));
    assert!(bad(&["beta_mapping=2"]));
    assert!(bad(&["beta_mapping=calibrated"]));
    assert!(bad(&["beta_mapping=navigation", "yield_strain=0"]));
    assert!(bad(&["beta_mapping=navigation", "yield_strain=1.5"]));
    assert!(
        f.build(
            &base,
            &Fidelity::parse_pairs(&["beta_mapping=navigation", "yield_strain=0.004"]).unwrap()
        )
        .is_ok()
    );
    assert!(
        f.build(
            &base,
            &Fidelity::parse_pairs(&["segments=7", "iterations=3", "dt=0.001", "frame=clamp", "beta=0.2"]).unwrap()
        )
        .is_ok()
    );
}

#[test]
fn varying_properties_give_a_softer_tip() {
    // stiff body, soft distal 4 cm (E 100x lower): beta 100x larger there
    let mut s = cantilever(9.81);
    if let surgbench_core::Body::Rod(r) = &mut s.bodies[0] {
        let mut tip = r.sections[0].clone();
        r.sections[0].until = 0.16;
        tip.youngs_modulus *= 0.01;
        r.sections.push(tip);
    }
    let w = wire(&s, &cfg(0.01, None, BoxFrame::World));
    let l = w.links();
    let (body, tip) = (l[5].beta, l[l.len() - 1].beta);
    assert!((tip / body - 100.0).abs() < 1e-9, "beta body {body} tip {tip}");
}

/// A straight rod of length `l` whose last `j` m carry rest curvature
/// `kappa` (1/m) on `d2` (turning towards `+d1`, the clamp's local y).
fn j_tip(l: f64, j: f64, kappa: f64) -> Scene {
    let mut s = Scene::empty("j-tip");
    let mut rod = RodBody::uniform(l, 5e-4, 1e9, 0.3, 6450.0);
    let mut tip = rod.sections[0].clone();
    rod.sections[0].until = l - j;
    tip.rest_curvature = [0.0, kappa];
    rod.sections.push(tip);
    s.bodies.push(rod.into());
    s
}

#[test]
fn free_j_tip_keeps_its_rest_shape() {
    // the link-frame boxes put node i's rest turning int kappa ds over its
    // Voronoi interval; summed over the free nodes that is kappa (j - Delta/2)
    // exactly (the last half link has no node beyond it), so the last link's
    // angle is the rest tangent angle at its midpoint, and the tip angle
    // kappa j is missed by kappa Delta / 2: first order in Delta.
    let (l, j, kappa) = (0.05, 0.01, 100.0);
    let mut errs = Vec::new();
    for n in [10usize, 20, 40] {
        let s = j_tip(l, j, kappa);
        let f = Fidelity::parse_pairs(&[&format!("segments={n}")]).unwrap();
        let mut m = ChainmailFactory.build(&s, &f).unwrap();
        let x0 = m.observe().rods[0].nodes.clone();
        for _ in 0..200 {
            m.step(0.01, &DeviceCommand::default()).unwrap();
        }
        let o = m.observe();
        let r = &o.rods[0];
        let drift = r.nodes.iter().zip(&x0).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        // a rest shape is a fixed point of the boxes and the relaxation: only
        // rounding of the frame transports (~1e-16 m per operation) may move it
        assert!(drift < 1e-12, "n={n}: rest shape drifted by {drift:e} m");
        let k = r.nodes.len();
        let e = r.nodes[k - 1] - r.nodes[k - 2];
        let angle = e.y.atan2(e.x);
        let delta = l / n as f64;
        let expect = kappa * (j - 0.5 * delta);
        assert!(
            (angle - expect).abs() < 1e-12,
            "n={n}: last-link angle {angle} vs kappa (j - Delta/2) = {expect}"
        );
        assert!(e.z.abs() < 1e-15, "n={n}: J left its plane: {e:?}");
        errs.push((delta, (kappa * j - angle).abs()));
    }
    eprintln!("J tip: (Delta, |kappa j - tip angle|) = {errs:?}");
    for w in errs.windows(2) {
        let order = (w[0].1 / w[1].1).ln() / (w[0].0 / w[1].0).ln();
        // the error is kappa Delta / 2 exactly: order 1 to rounding
        assert!((order - 1.0).abs() < 1e-9, "observed order {order} from {errs:?}");
    }
}

#[test]
fn rotating_the_base_turns_the_j_towards_its_mirror() {
    // no twist dynamics: the commanded rotation reaches every link frame at
    // once; a half turn of the clamp makes the mirrored J (y -> -y) the rest
    // shape, which the boxes and the relaxation approach step by step
    let s = j_tip(0.05, 0.01, 100.0);
    let mut m = ChainmailFactory.build(&s, &Fidelity::default()).unwrap();
    let tip0 = m.observe().rods[0].tip();
    let mirror = Vec3::new(tip0.x, -tip0.y, tip0.z);
    let mut dist = Vec::new();
    for k in 1..=1100 {
        let cmd = DeviceCommand {
            rotation: std::f64::consts::PI * (k.min(100) as f64 / 100.0),
            ..Default::default()
        };
        m.step(0.01, &cmd).unwrap();
        if k % 250 == 100 {
            dist.push((m.observe().rods[0].tip() - mirror).norm());
        }
    }
    let tip = m.observe().rods[0].tip();
    eprintln!(
        "J tip before {tip0:?}, after a half turn {tip:?}; distance to the mirror at 1, 3.5, 6, 8.5, 11 s: {dist:?}"
    );
    assert!(tip0.y > 1e-3, "J does not bend towards +y: {tip0:?}");
    assert!(tip.y < 0.0, "J did not turn over: {tip:?}");
    for w in dist.windows(2) {
        assert!(w[1] < w[0], "not approaching the mirrored J: {dist:?}");
    }
}

/// The default navigation wire's sections (arch-insertion / branch-selection
/// body and soft tip: r = 0.445 mm, E = 50 GPa and 1 GPa, nitinol-like).
fn navigation_sections() -> Vec<surgbench_core::RodSection> {
    let body = RodBody::uniform(0.2, 4.45e-4, 5e10, 0.3, 6450.0).sections[0].clone();
    let mut tip = body.clone();
    tip.youngs_modulus = 1e9;
    vec![body, tip]
}

#[test]
fn navigation_box_edge_is_the_intended_bend() {
    use mapping::{BetaMapping, NITINOL_RECOVERABLE_STRAIN as EPS};
    for sec in navigation_sections() {
        // link lengths of 40 segments over the 32 mm coronary and 200 mm
        // arch wires, and one long enough to hit the 45 deg cap
        for delta in [8e-4, 5e-3, 1e-2] {
            let theta = mapping::bend_limit(&sec, delta, EPS);
            let expect = (delta * EPS / sec.radius).min(std::f64::consts::FRAC_PI_4);
            // closed form theta = Delta eps_y / r, same operations: exact to rounding
            assert!(
                (theta - expect).abs() <= 1e-15 * expect,
                "bend_limit(Delta={delta}, r={}) = {theta}, expected {expect}",
                sec.radius
            );
            let p = BetaMapping::Navigation { yield_strain: EPS }.link_params(&sec, delta, BETA_CONSTANT);
            assert_eq!(p, mapping::navigation_link_params(&sec, delta, EPS));
            p.validate().unwrap();
            // closed form of the box: the largest turning in a box plane, at
            // the edge length Delta / cos theta, is theta (tan/atan round trip:
            // a few ulps)
            let edge = mapping::max_bend_in_box(&p, delta, delta / theta.cos()).unwrap();
            assert!(
                (edge - theta).abs() < 1e-12,
                "Delta={delta}: box edge turns {edge} rad, intended {theta} rad ({p:?})"
            );
            // the rule itself: a neighbour past the edge in its bend plane
            // (lateral offset > Delta tan theta, any axial offset) projects
            // onto the edge (Delta, Delta tan theta, 0), turned by theta
            let frame = Mat3::identity();
            let rest = Vec3::new(delta, 0.0, 0.0);
            let sponsor = Vec3::new(0.1, -0.2, 0.3);
            for (ax, lat) in [(1.0, 1.01), (0.5, 1.5), (1.7, 3.0)] {
                let nb = sponsor + Vec3::new(ax * delta, lat * delta * theta.tan(), 0.0);
                let (q, moved) = rules::project_into_box(&sponsor, &nb, &rest, &frame, &p);
                let d = q - sponsor;
                let turned = d.y.atan2(d.x);
                assert!(moved, "Delta={delta}, offset ({ax}, {lat} tan theta) Delta: must move");
                // per-axis clamp: exact to rounding of ~1e-3 m offsets
                assert!(
                    (turned - theta).abs() < 1e-12 && (d.norm() - delta / theta.cos()).abs() < 1e-15,
                    "Delta={delta}, offset ({ax}, {lat} tan theta) Delta: projected link turns {turned} rad over {} m, intended {theta} rad over {} m",
                    d.norm(),
                    delta / theta.cos()
                );
            }
            // a link within the limit on its edge length is valid and stays
            let half = 0.5 * theta;
            let nb = sponsor + Vec3::new(delta, delta * half.tan(), 0.0);
            let (_, moved) = rules::project_into_box(&sponsor, &nb, &rest, &frame, &p);
            assert!(
                !moved,
                "Delta={delta}: a link turned by theta/2 = {half} rad must be valid ({p:?})"
            );
        }
    }
}

#[test]
fn navigation_mapping_allows_more_bend_than_the_weight_mapping() {
    use mapping::{BetaMapping, NITINOL_RECOVERABLE_STRAIN as EPS};
    let delta = 5e-3; // arch-insertion at 40 segments: 0.2 m / 40
    for sec in navigation_sections() {
        let p0 = BetaMapping::Weight.link_params(&sec, delta, BETA_CONSTANT);
        let p1 = BetaMapping::Navigation { yield_strain: EPS }.link_params(&sec, delta, BETA_CONSTANT);
        // the largest turning anywhere in the box: its edge, atan(beta / alpha_min)
        let (e0, e1) = (p0.beta.atan2(p0.alpha_min), p1.beta.atan2(p1.alpha_min));
        eprintln!(
            "E={:.1e} Pa: box-edge bend weight {:.4} deg, navigation {:.4} deg ({p0:?} vs {p1:?})",
            sec.youngs_modulus,
            e0.to_degrees(),
            e1.to_degrees()
        );
        assert!(
            e1 > e0,
            "E={}: navigation edge {e1} rad <= weight edge {e0} rad",
            sec.youngs_modulus
        );
        // at a fixed link stretch s: mapping 1's box is axially rigid, so an
        // exactly inextensible link (s = 0) cannot bend in it at all, while
        // mapping 0 has an axial slack 1 - alpha_min (7.7e-6 on the 50 GPa
        // body, 3.8e-4 on the 1 GPa tip). On the body (what limits
        // navigation) mapping 1 admits more bend from s = 1e-3 on; on the
        // soft tip mapping 0's slack admits slightly more up to s ~ 1 %
        // (printed, not asserted), mapping 1 more at 5 %
        let body = sec.youngs_modulus > 1e10;
        for s in [1e-3, 1e-2, 5e-2] {
            let len = delta * (1.0 + s);
            let b0 = mapping::max_bend_in_box(&p0, delta, len).unwrap_or(0.0);
            let b1 = mapping::max_bend_in_box(&p1, delta, len).unwrap_or(0.0);
            eprintln!(
                "  stretch {s}: weight {:.4} deg, navigation {:.4} deg",
                b0.to_degrees(),
                b1.to_degrees()
            );
            if body || s >= 5e-2 {
                assert!(
                    b1 > b0,
                    "E={}, stretch {s}: navigation {b1} rad <= weight {b0} rad",
                    sec.youngs_modulus
                );
            }
        }
    }
    // the whole wire: in the calibration scene the navigation boxes let the
    // weight pull the cantilever much further down than Euler-Bernoulli
    // (the navigation mapping gives up the cantilever it was not made for)
    let s = cantilever(9.81);
    let target = calibration::calibration_target();
    let mut sag = Vec::new();
    for m in [BetaMapping::Weight, BetaMapping::Navigation { yield_strain: EPS }] {
        let mut c = cfg(1e-2, None, BoxFrame::Link);
        c.beta_mapping = m;
        let mut w = wire(&s, &c);
        let mut steps = 0;
        while steps < 20_000 {
            w.advance(1e-2, &DeviceCommand::default()).unwrap();
            steps += 1;
            if w.max_speed() * 1e-2 < 1e-13 {
                break;
            }
        }
        sag.push(-w.nodes().last().unwrap().z / target);
    }
    eprintln!(
        "settled sag / Euler-Bernoulli, link frame, 20 segments: weight {}, navigation {}",
        sag[0], sag[1]
    );
    // ordering only: both are far from Euler-Bernoulli in the link frame
    // (the weight constant was fitted in world axes), and the navigation
    // wire hangs nearly straight down (sag ~ L / (EB sag) = 49 at most)
    assert!(sag[1] > sag[0], "sag / EB: weight {} navigation {}", sag[0], sag[1]);
}

#[test]
fn link_frame_friction_leaves_the_links_their_length() {
    // frame=link, navigation mapping (alpha = 1: every link exactly Delta
    // along its box axis): a wire on the bottom of a horizontal tube pushed
    // 2 cm with a sticking friction factor. Friction corrects contact
    // elements after the relaxation; the final length-restoring pass puts
    // every link back in its box, then the wall projection keeps the wire
    // inside, so links change length only by that last normal projection
    let s = {
        let mut s = busy_scene(1.0);
        s.environment.flow = None;
        s
    };
    let f = Fidelity::parse_pairs(&["frame=link", "beta_mapping=navigation"]).unwrap();
    let mut m = ChainmailFactory.build(&s, &f).unwrap();
    let (mut worst, mut pen, mut contacts): (f64, f64, usize) = (0.0, 0.0, 0);
    for k in 1..=200 {
        let cmd = DeviceCommand {
            insertion: 1e-4 * k as f64,
            ..Default::default()
        };
        m.step(0.01, &cmd).unwrap();
        let o = m.observe();
        worst = worst.max(o.rods[0].max_stretch.abs());
        contacts = contacts.max(o.contacts.len());
        pen = o.contacts.iter().map(|c| c.penetration).fold(pen, f64::max);
    }
    eprintln!("frame=link, C_f = 1: largest |stretch| {worst:e}, penetration {pen:e} m, contacts {contacts}");
    assert!(contacts > 0, "no contacts: the test does not exercise friction");
    // measured 4.8e-4 (the last normal wall projection moves nodes across
    // the links); the same run without the restoring pass gives 0.105
    assert!(worst < 1e-3, "links off their length by {worst:e} (relative)");
    // the final pass ends on the wall projection: rounding only
    assert!(pen < 1e-12, "penetration {pen:e} m after the final wall pass");
}

/// A vessel "moving" with zero amplitude goes through the volumetric
/// chain-mail (lattice, pulled-back lumen, carried flow and friction) and
/// must change nothing: every displacement it adds is exactly zero.
#[test]
fn a_still_vessel_motion_changes_nothing() {
    use surgbench_core::motion::CardiacMotion;
    let run = |moving: bool| {
        let mut s = busy_scene(0.3);
        if moving {
            let m = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.01, 0.02, 0.0, 1.2).unwrap();
            s.environment.vessel_motion = Some(Arc::new(m));
        }
        push_and_turn(&s, 200)
    };
    let (still, moving) = (run(false), run(true));
    assert!(still == moving, "a zero-amplitude motion changed the answer");
    assert!(
        !still.last().unwrap().contacts.is_empty(),
        "scene meant to exercise contacts had none"
    );
}

/// A wire lying in a tube that swings 2 mm across its axis beyond 10 mm:
/// the chain-mail keeps it in the lumen its lattice carries, so against the
/// prescribed (exact) lumen it is off by no more than that lattice's own
/// error: the wall layer's lag (reported) plus the trilinear interpolation
/// error `h^2/8 |u''|`, scaled by `|grad phi| <= 1 + |du/dX|`.
#[test]
fn wire_stays_in_a_swinging_tube() {
    use surgbench_core::Sdf;
    use surgbench_core::motion::{CardiacMotion, MovingSdf};
    let mut s = cantilever(9.81);
    let tube: Arc<dyn surgbench_core::Sdf> = Arc::new(StraightTube {
        origin: Vec3::zeros(),
        axis: Vec3::x(),
        radius: 1.5e-3,
    });
    let (amp, ramp) = (2e-3, 0.02);
    let motion = Arc::new(CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.01, ramp, amp, 1.2).unwrap());
    s.environment.vessel = Some(tube.clone());
    s.environment.vessel_motion = Some(motion.clone());
    s.environment.contact.margin = 5e-4;
    let mut f = Fidelity::default();
    f.set_setting("beta_mapping", "navigation".into()).unwrap();
    let mut m = ChainmailFactory.build(&s, &f).unwrap();
    let (mut worst, mut lag): (f64, f64) = (f64::NEG_INFINITY, 0.0);
    let dt = 0.01;
    for k in 1..=200 {
        m.step(dt, &DeviceCommand::default()).unwrap();
        let exact = MovingSdf::new(tube.clone(), motion.clone(), k as f64 * dt);
        for p in &m.observe().rods[0].nodes {
            worst = worst.max(exact.distance(p) + 5e-4);
        }
        lag = lag.max(m.diagnostics()["vessel_lag_max_m"]);
    }
    // u'' <= 6 A / L^2 = 30 1/m along the ramp, h = 0.5 mm (default spacing).
    let interp = 0.25e-6 / 8.0 * 6.0 * amp / (ramp * ramp);
    let bound = (1.0 + motion.max_strain()) * (lag + interp);
    eprintln!("deepest {worst:e} m past the exact moving margin surface; lattice lag {lag:e} m, bound {bound:e} m");
    assert!(lag > 0.0, "slack boxes should lag somewhere");
    assert!(
        worst <= bound,
        "wire {worst:e} m past the exact moving lumen, bound {bound:e} m"
    );
}
