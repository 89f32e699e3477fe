//! Scoring of the navigation scenarios (arch insertion, capstan, branch
//! selection) through the runner, with a kinematic wire whose answers are
//! known.

mod common;
use common::params;
use common::vessel::*;

use std::f64::consts::PI;
use std::sync::Arc;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenario::Declared;
use surgbench_comparisons::scenario::Scenario;
use surgbench_comparisons::scenarios::vessel::{ARCH_INSERTION, ArchParams, ENTRY_S, WIRE_RADIUS};
use surgbench_core::{DeviceCommand, Fidelity, Vec3};

#[test]
fn arch_insertion_scores_reach_time_force_and_penetration() {
    let s = scenario("arch-insertion");
    let p = params(s, &[]);
    let sum = run(s, &p, &arch_follower(L0, Vec3::new(0.0, 0.0, -0.1)));
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    let e = &sum.errors;
    // Tip on the trunk at ENTRY_S + L0 + v t: reaches the plane 10 mm into
    // the ascending aorta at t* = (210 + 35 pi + 10 - 5 - 200) mm / (20 mm/s).
    let t_star = (surgbench_core::vessel::ARCH_DESCENDING + PI * 0.035 + 0.01 - ENTRY_S - L0) / 0.02;
    // Resolution: the runner samples 400 times over 7.5 s (18.75 ms).
    let t = e["time_to_reach_s"];
    assert!(
        t >= t_star && t - t_star <= 7.5 / 400.0 + 1e-3,
        "time to reach {t} vs {t_star}"
    );
    assert_eq!(e["reached"], 1.0);
    assert!(
        e["max_penetration_m"] == 0.0,
        "centreline wire penetrates: {}",
        e["max_penetration_m"]
    );
    // The mean sums every step's force (7500 terms): n eps relative rounding.
    assert!((e["hand_force_mean_n"] - 0.1).abs() < 1e-12 && (e["hand_force_max_n"] - 0.1).abs() < 1e-15);
    // The committed DER reference (datasets/reference/arch-insertion) is
    // scored whenever it is present.
    assert_eq!(e["reference_available"], 1.0, "the DER reference is committed");
    assert!(e.contains_key("tip_error_m"), "a reference gives a tip error");
    let progress = ENTRY_S + L0 + 0.02 * 7.5;
    assert!(
        (e["tip_progress_m"] - progress).abs() < 1e-9,
        "{} vs {progress}",
        e["tip_progress_m"]
    );

    // A wire 1.2 mm too deep into the wall's side everywhere: the geometric
    // penetration is what it is, whatever the model reports.
    let off = 12.5e-3 - WIRE_RADIUS + 1.2e-3;
    let f = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| {
            let trunk = surgbench_core::vessel::aortic_arch().trunk;
            // The descending aorta runs along +z: offset along +y.
            Box::new(Kinematic::along(
                move |s| trunk.point_at(ENTRY_S + s.min(0.05)) + Vec3::y() * off,
                0.05,
                40,
            ))
        }),
    };
    let sum = run(s, &p, &f);
    assert!(
        (sum.errors["max_penetration_m"] - 1.2e-3).abs() < 1e-12,
        "{}",
        sum.errors["max_penetration_m"]
    );
    assert_eq!(sum.errors["reached"], 0.0);
}

#[test]
fn arch_insertion_uses_a_cached_reference_when_present() {
    // A reference written from the follower's own trajectory every 10 ms:
    // linear interpolation between samples on the 35 mm arch is off by at
    // most the sagitta (v dt)^2 / (8 R) = 1.4e-7 m.
    let trunk = surgbench_core::vessel::aortic_arch().trunk;
    let dir = std::env::temp_dir().join(format!("surgbench-ref-{}", std::process::id()));
    let refdir = dir.join("reference").join("arch-insertion");
    std::fs::create_dir_all(&refdir).unwrap();
    let mut csv = String::from("t,x,y,z\n");
    for k in 0..=750 {
        let t = k as f64 * 0.01;
        let x = trunk.point_at(ENTRY_S + L0 + 0.02 * t);
        csv.push_str(&format!("{t},{:?},{:?},{:?}\n", x.x, x.y, x.z));
    }
    std::fs::write(refdir.join("tip_trajectory.csv"), csv).unwrap();
    let leaked: &'static str = Box::leak(dir.display().to_string().into_boxed_str());
    let s: &'static Declared<ArchParams> = Box::leak(Box::new(Declared {
        datasets: Some(leaked),
        ..ARCH_INSERTION
    }));
    let p = params(s, &[]);
    let sum = run(s, &p, &arch_follower(L0, Vec3::zeros()));
    let e = &sum.errors;
    assert_eq!(e["reference_available"], 1.0);
    assert!(
        e["tip_error_max_m"] < 2e-7,
        "tip error max {} (interpolation bound 1.4e-7 m)",
        e["tip_error_max_m"]
    );
    // A wire whose tip advances only 90% of the insertion lags the reference.
    let slow = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| {
            let trunk = surgbench_core::vessel::aortic_arch().trunk;
            Box::new(Kinematic::along(
                move |s| trunk.point_at(ENTRY_S + if s <= L0 { s } else { L0 + 0.9 * (s - L0) }),
                L0,
                40,
            ))
        }),
    };
    let r = s.instantiate(&p).unwrap();
    // Overrides disable the reference (it was computed for the defaults).
    let p2 = params(s, &[("insertion_speed", 0.018)]);
    let r2 = s.instantiate(&p2).unwrap();
    let sum2 = run_single(s, &p2, &r2, &slow, &Fidelity::default(), &RunOptions::default()).unwrap();
    assert_eq!(sum2.errors["reference_available"], 0.0);
    // Scored against the reference, the slow wire's final tip error is the
    // 15 mm it lags along the trunk (chord <= arc; equal, up to rounding, on
    // the straight ascending aorta where both tips end).
    let sum3 = run_single(s, &p, &r, &slow, &Fidelity::default(), &RunOptions::default()).unwrap();
    let lag = 0.1 * 0.02 * 7.5;
    let err = sum3.errors["tip_error_m"];
    assert!(
        err <= lag * (1.0 + 1e-9) && err > 0.9 * lag,
        "final tip error {err} vs lag {lag}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn capstan_scores_the_tension_ratio_over_the_pull_window() {
    let s = scenario("capstan");
    let (mu, theta, t_in) = (0.3, PI / 2.0, 1.0);
    let p = params(s, &[]);
    let make = |ratio: f64| TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| {
            Box::new(Kinematic {
                // Kept in the straight entry (scoring reads only the force).
                path: Arc::new(|s| Vec3::x() * s.min(0.01)),
                hand: Arc::new(move |_, _| Vec3::x() * (t_in * ratio)),
                l0: 5e-3,
                n: 20,
                t: 0.0,
                cmd: DeviceCommand::default(),
            })
        }),
    };
    let exact = (mu * theta).exp();
    let sum = run(s, &p, &make(exact));
    let e = &sum.errors;
    assert!(e["tension_ratio_error_rel"] < 1e-14, "{e:?}");
    assert!(
        e["window_samples"] > 50.0,
        "pull window sampled {} times",
        e["window_samples"]
    );
    assert!(
        e["bending_over_tension"] < 0.05,
        "default wire is not flexible enough: {}",
        e["bending_over_tension"]
    );
    // The series the report plots: inside the pull window (and only
    // there) the hand's tension against T_in exp(mu theta).
    let scored: Vec<_> = sum.series.iter().filter(|x| x.force[1].is_finite()).collect();
    assert!(!scored.is_empty() && scored.len() < sum.series.len());
    for x in &scored {
        assert!((x.force[0] - t_in * exact).abs() < 1e-12 && (x.force[1] - t_in * exact).abs() < 1e-12);
    }
    // A frictionless answer (T_out = T_in) is off by 1 - exp(-mu theta).
    let sum = run(s, &p, &make(1.0));
    let want = 1.0 - (-mu * theta).exp();
    assert!(
        (sum.errors["tension_ratio_error_rel"] - want).abs() < 1e-14,
        "{} vs {want}",
        sum.errors["tension_ratio_error_rel"]
    );
}

#[test]
fn branch_selection_success_and_miss() {
    let s = scenario("branch-selection");
    // A wire following the trunk, then branch-45's centreline.
    let f = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(|_| {
            let y = surgbench_core::vessel::y_bifurcation();
            let (trunk, b45) = (y.trunk.clone(), y.branch("branch-45").unwrap().tube.clone());
            Box::new(Kinematic::along(
                move |s| {
                    let s = ENTRY_S + s;
                    if s <= trunk.length() {
                        trunk.point_at(s)
                    } else {
                        b45.point_at(s - trunk.length())
                    }
                },
                0.032,
                32,
            ))
        }),
    };
    let p = params(s, &[("target", 0.0)]);
    let sum = run(s, &p, &f);
    let e = &sum.errors;
    assert_eq!(e["success"], 1.0, "{e:?}");
    assert_eq!(e["target_missed"], 0.0);
    assert_eq!(
        e["rotation_commands"], 2.0,
        "two quarter-turn halves in the recorded session"
    );
    // Tip 5 mm into the branch: ENTRY_S + 0.032 + insertion = 0.040 + 0.005,
    // insertion 8 mm at 10 mm/s from t = 1.5 s: t = 2.3 s (sampled every 12.5 ms).
    let t = e["time_to_target_s"];
    // Every step is observed (observe_step): time is (k + 1) dt, which may
    // round a few ulps below 2.3.
    assert!(
        (2.3 - 1e-9..=2.3 + 5.0 / 400.0 + 1e-3).contains(&t),
        "time to target {t}"
    );
    assert_eq!(e["max_penetration_m"], 0.0);
    let sum = run(s, &params(s, &[("target", 1.0)]), &f);
    assert_eq!(sum.errors["success"], 0.0);
    assert_eq!(sum.errors["target_missed"], 1.0);
    assert!(!sum.errors.contains_key("time_to_target_s"));
}
