//! The chain-mail guidewire's rules (box projection, propagation,
//! relaxation), their limits, calibration and rigid-motion behaviour.

mod common;
use common::*;

use std::sync::Arc;
use surgbench_chainmail::calibration;
use surgbench_chainmail::mapping::BETA_CONSTANT;
use surgbench_chainmail::rules::{self, LinkParams};
use surgbench_chainmail::{BoxFrame, ChainmailFactory};
/// xorshift64* (seeded, no dependency).
use surgbench_core::rng::SplitMix64 as Rng;
use surgbench_core::sdf::StraightTube;
use surgbench_core::{DeviceCommand, Fidelity, Iso3, Mat3, ModelFactory, Vec3};

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
    let s = calibration::calibration_scene();
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

/// The report states the fit (`ModelFactory::fitted`): its text names the
/// committed constant and the calibration length, so it cannot drift from them.
#[test]
fn the_fitted_note_names_the_committed_fit() {
    use surgbench_core::ModelFactory;
    let note = surgbench_chainmail::ChainmailFactory
        .fitted()
        .expect("the weight mapping is fitted");
    assert!(note.contains(&format!("C = {BETA_CONSTANT}")), "{note}");
    assert!(
        note.contains(&format!("{} m gravity cantilever", calibration::CALIBRATION_LENGTH)),
        "{note}"
    );
}
