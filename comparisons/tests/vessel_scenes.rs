//! Vessel scenarios: scene construction (validate, capabilities, initial
//! wire inside the lumen) and bad parameters.

mod common;
use common::params;
use common::vessel::*;

use surgbench_comparisons::scenarios::vessel::{self, WIRE_RADIUS};
use surgbench_core::{Capability, Observation, Vec3};

#[test]
fn every_scene_validates_and_asks_for_its_capabilities() {
    use Capability::*;
    let expect: &[(&str, &[Capability])] = &[
        (
            "arch-insertion",
            &[Rod, Twist, VaryingProperties, Insertion, VesselContact, Friction],
        ),
        (
            "branch-selection",
            &[
                Rod,
                Twist,
                VaryingProperties,
                RestCurvature,
                Insertion,
                VesselContact,
                Friction,
            ],
        ),
        ("flow-drift", &[Rod, VesselContact, Friction, Flow]),
        (
            "capstan",
            &[Rod, TipForce, LoadRamp, Insertion, VesselContact, Friction],
        ),
        ("stick-slip-threshold", &[Rod, Insertion, VesselContact, Friction]),
        (
            "coronary-tortuous",
            &[Rod, Twist, VaryingProperties, Insertion, VesselContact, Friction],
        ),
        (
            "coronary-beating",
            &[
                Rod,
                Twist,
                VaryingProperties,
                Insertion,
                VesselContact,
                Friction,
                MovingVessel,
            ],
        ),
        (
            "vessel-mesh-insertion",
            &[Rod, VaryingProperties, Insertion, VesselContact, Friction],
        ),
    ];
    let ids: Vec<_> = vessel::all().iter().map(|s| s.id()).collect();
    assert_eq!(ids, expect.iter().map(|e| e.0).collect::<Vec<_>>());
    for (id, caps) in expect {
        let s = scenario(id);
        let r = s.instantiate(&params(s, &[])).unwrap();
        let scene = r.scene();
        scene.validate().unwrap();
        let mut want = caps.to_vec();
        want.sort();
        assert_eq!(scene.required_capabilities(), want, "{id}");
        assert!(s.params().iter().all(|p| !p.doc.is_empty()));
        // Half a wire radius: the watchdog trips on real penetration.
        assert_eq!(r.penetration_limit(), 0.5 * WIRE_RADIUS, "{id}");
        // The straight part of the initial wire (rest-curved J excluded) is
        // inside the lumen with its surface clear of the wall.
        let rod = scene.rods().next().unwrap();
        let vessel = scene.environment.vessel.as_ref().unwrap();
        let straight = rod
            .sections
            .iter()
            .rev()
            .find(|s| s.rest_curvature == [0.0, 0.0])
            .unwrap()
            .until;
        for k in 0..=50 {
            let s = straight * k as f64 / 50.0;
            let x = rod.base.transform_point(&(Vec3::x() * s).into()).coords;
            let phi = vessel.distance(&x);
            assert!(
                phi + rod.sections[0].radius <= 1e-12,
                "{id}: initial node at s={s} has phi {phi:e} (wire surface in the wall)"
            );
        }
        // The sessions and timelines end within the scene.
        if let Some(k) = scene.control.keys.last() {
            assert!(k.t <= scene.duration + 1e-12, "{id}");
        }
    }
}

#[test]
fn branch_selection_j_tip_starts_inside_and_sessions_load() {
    let s = scenario("branch-selection");
    for target in [0.0, 1.0] {
        let r = s.instantiate(&params(s, &[("target", target)])).unwrap();
        let scene = r.scene();
        let rod = scene.rods().next().unwrap();
        let j = rod.sections.last().unwrap();
        // Darboux component on d2 turns the tangent towards d1 (local y).
        assert_eq!(j.rest_curvature[0], 0.0);
        let kappa = j.rest_curvature[1];
        let jl = j.until - rod.sections[rod.sections.len() - 2].until;
        // The J's rest arc, bending towards the clamp's local y.
        let start = rod.sections[rod.sections.len() - 2].until;
        for k in 0..=20 {
            let a = kappa * jl * k as f64 / 20.0;
            let local = Vec3::new(start + a.sin() / kappa, (1.0 - a.cos()) / kappa, 0.0);
            let x = rod.base.transform_point(&local.into()).coords;
            let phi = scene.environment.vessel.as_ref().unwrap().distance(&x);
            assert!(phi + j.radius <= 0.0, "target {target}: J point {k} phi {phi:e}");
        }
        // The clamp's local y (the J's side) starts pointing up (+z).
        assert!((rod.base.rotation * Vec3::y() - Vec3::z()).norm() < 1e-12);
        let m = r.scorer().score(&Observation::default());
        assert!(m.is_empty(), "no rod, no score");
    }
}

#[test]
fn bad_parameters_are_usage_errors() {
    type Case = (&'static str, &'static [(&'static str, f64)], &'static str);
    let cases: &[Case] = &[
        ("flow-drift", &[("free_length", 0.01)], "start in the"),
        ("capstan", &[("pull_length", 0.02)], "pull the tip back"),
        ("capstan", &[("tube_radius", 0.4e-3)], "does not fit"),
        ("branch-selection", &[("target", 0.5)], "0 or 1"),
        ("branch-selection", &[("j_curvature", 1000.0)], "start in the wall"),
        ("arch-insertion", &[("initial_length", 0.21)], "does not fit"),
        ("arch-insertion", &[("insertion_speed", 0.03)], "into the wall"),
        ("coronary-tortuous", &[("push_speed", 0.006)], "into the wall"),
        ("arch-insertion", &[("friction_dynamic", 0.5)], "must not exceed"),
        ("coronary-tortuous", &[("push_speed", 0.05)], "past the end"),
        ("stick-slip-threshold", &[("pull_time", 1e-3)], "elastic slack"),
    ];
    for (id, o, msg) in cases {
        let s = scenario(id);
        let e = s
            .instantiate(&params(s, o))
            .err()
            .unwrap_or_else(|| panic!("{id} {o:?} accepted"));
        assert!(e.0.contains(msg), "{id} {o:?}: `{e}` lacks `{msg}`");
    }
}
