//! The chain-mail factory's contract: what it refuses, and a non-finite
//! state reported as a divergence.

mod common;
use common::*;

use std::sync::Arc;
use surgbench_chainmail::ChainmailFactory;
use surgbench_core::flow::FlowField;
use surgbench_core::{BuildError, DeviceCommand, Fidelity, ModelFactory, SimError, Vec3};

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
