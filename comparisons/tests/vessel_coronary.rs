//! Scoring of the coronary scenarios: penetration over a shortened run,
//! and against the moving wall of the beating coronary.

mod common;
use common::params;
use common::vessel::*;

use std::f64::consts::PI;
use surgbench_comparisons::runner::{RunOptions, run_single};
use surgbench_comparisons::scenarios::vessel::{ENTRY_S, WIRE_RADIUS};
use surgbench_core::{DeviceCommand, Fidelity, Model, Observation, Scene, SimError, StepStats, Vec3};

#[test]
fn coronary_scores_penetration_over_a_shortened_run() {
    let s = scenario("coronary-tortuous");
    let p = params(s, &[("duration", 12.0)]);
    let r = s.instantiate(&p).unwrap();
    // Two 6 s cycles: insertion peaks at 2 v after each push.
    let keys = &r.scene().control.keys;
    let max_ins = keys.iter().map(|k| k.insertion).fold(0.0, f64::max);
    assert!((max_ins - 0.015).abs() < 1e-15, "deepest insertion {max_ins}");
    assert!((keys.last().unwrap().rotation - 2.0 * PI / 4.0).abs() < 1e-15);
    let f = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(|_| {
            let trunk = surgbench_core::vessel::coronary_tortuous().trunk;
            Box::new(Kinematic::along(move |s| trunk.point_at(ENTRY_S + s), 0.032, 60))
        }),
    };
    let sum = run(s, &p, &f);
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    assert_eq!(
        sum.errors["max_penetration_m"], 0.0,
        "the centreline stays 1.5 mm from the wall"
    );
    let progress = ENTRY_S + 0.032 + 0.01;
    assert!(
        (sum.errors["tip_progress_m"] - progress).abs() < 1e-9,
        "{}",
        sum.errors["tip_progress_m"]
    );
}

/// The wire's centreline on the coronary's entry at time `t`: either riding
/// the moving lumen (`follow`) or left where the lumen was at rest.
struct Beating {
    scene: Scene,
    follow: bool,
    n: usize,
    t: f64,
    ins: f64,
}

impl Model for Beating {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.t += dt;
        self.ins = cmd.insertion;
        Ok(StepStats::default())
    }
    fn observe(&self) -> Observation {
        let trunk = surgbench_core::vessel::coronary_tortuous().trunk;
        let motion = self.scene.environment.vessel_motion.clone().unwrap();
        let l = 0.032 + self.ins;
        let s: Vec<f64> = (0..=self.n).map(|i| l * i as f64 / self.n as f64).collect();
        let nodes: Vec<Vec3> = s
            .iter()
            .map(|&si| {
                let x = trunk.point_at(ENTRY_S + si);
                if self.follow {
                    x + motion.displacement(&x, self.t)
                } else {
                    x
                }
            })
            .collect();
        Observation {
            time: self.t,
            rods: vec![rod_obs(s, nodes, Vec3::zeros())],
            ..Default::default()
        }
    }
    fn dt(&self) -> f64 {
        1e-3
    }
}

/// Penetration is scored against the lumen where it is at each
/// observation's time: a wire riding the moving centreline never touches
/// the wall; one left on the rest centreline is reached by the swinging
/// wall and is scored by how far the wall passed it.
#[test]
fn coronary_beating_scores_penetration_against_the_moving_wall() {
    let s = scenario("coronary-beating");
    let p = params(s, &[("duration", 3.0)]);
    for follow in [true, false] {
        let f = TestFactory {
            caps: ALL_ROD_CAPS,
            build: Box::new(move |scene| {
                Box::new(Beating {
                    scene: scene.clone(),
                    follow,
                    n: 60,
                    t: 0.0,
                    ins: 0.0,
                })
            }),
        };
        let sum = run(s, &p, &f);
        if follow {
            assert_eq!(sum.status, "ok", "{}", sum.reason);
            // The exact inverse maps the moved axis back onto the rest axis:
            // every node stays R - r = 1.055 mm inside.
            assert_eq!(sum.errors["max_penetration_m"], 0.0);
            continue;
        }
        // The watchdog reads the model's own contact report (none here);
        // the geometric metric sees the wall pass the wire: at the rest
        // centreline's tip (entry along +x, x_tip = ENTRY_S + insertion +
        // L0, the node the swing reaches most) the lumen has moved
        // A s(t) w(x_tip), so the wire's surface is A s w - (R - r) past it.
        assert_eq!(sum.status, "ok", "{}", sum.reason);
        let r = s.instantiate(&p).unwrap();
        let motion = r.scene().environment.vessel_motion.clone().unwrap();
        let predicted = (1..=3000)
            .map(|k| {
                let t = k as f64 * 1e-3;
                let x = Vec3::x() * (ENTRY_S + r.scene().control.command_at(t).insertion + 0.032);
                motion.displacement(&x, t).norm() - (1.5e-3 - WIRE_RADIUS)
            })
            .fold(0.0, f64::max);
        let got = sum.errors["max_penetration_m"];
        eprintln!("left behind: max penetration {got:e} m, predicted {predicted:e} m");
        // Scored at every step on the same times; the level set of a pure
        // transverse swing measured from the rest axis is exact (rounding).
        assert!(
            (got - predicted).abs() < 1e-12,
            "penetration {got:e} m, predicted {predicted:e} m"
        );
    }
}

/// `coronary-beating` at its default parameters is scored on the cached
/// converged DER tip path (DER at 160 segments and 0.25 ms, 9.5e-6 m at
/// most from the run at 80 segments and 0.5 ms): DER at its own defaults
/// (40 segments, 1 ms) stays on it to its discretization error, measured
/// 1.39e-5 m RMS and 1.16e-4 m at worst (at every step; 2.9e-5 m between
/// the 40- and 160-segment paths at the 401 recorded samples). The bound,
/// 3e-5 m RMS, is 3 % of the 1 mm target, so the scene tells a model that
/// misses the path from one that follows it. With a parameter changed the
/// path does not apply and is not scored.
#[test]
fn coronary_beating_is_scored_on_the_converged_der_path() {
    use surgbench_comparisons::registry;
    let s = scenario("coronary-beating");
    let p = params(s, &[]);
    let r = s.instantiate(&p).unwrap();
    let der = registry::model("der").unwrap();
    let sum = run_single(s, &p, &r, der, &Fidelity::default(), &RunOptions::default()).unwrap();
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    let (rms, max) = (sum.errors["tip_error_rms_m"], sum.errors["tip_error_max_m"]);
    eprintln!("DER on the cached path: rms {rms:.3e} m, max {max:.3e} m");
    assert!(rms < 3e-5 && max < 1e-3, "rms {rms:.3e} m, max {max:.3e} m");
    let other = params(s, &[("duration", 6.0)]);
    let r = s.instantiate(&other).unwrap();
    let sum = run_single(s, &other, &r, der, &Fidelity::default(), &RunOptions::default()).unwrap();
    assert!(!sum.errors.contains_key("tip_error_rms_m"));
}
