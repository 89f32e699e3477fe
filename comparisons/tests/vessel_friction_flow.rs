//! Scoring of the stick-slip threshold with a 1-DOF Coulomb slider, and
//! of the flow drift with a kinematic wire.

mod common;
use common::params;
use common::vessel::*;

use std::f64::consts::PI;
use surgbench_comparisons::scenarios::vessel::{self, WIRE_RADIUS};
use surgbench_core::{Capability, DeviceCommand, Model, Observation, SimError, StepStats, Vec3};

/// A rigid wire on the floor tied to the clamp by a spring of stiffness k
/// (critically damped): Coulomb stick until |F| > mu_s N, then slides with
/// mu_d N. Integrated with 100 substeps per step.
struct Slider {
    k: f64,
    c: f64,
    m: f64,
    n_force: f64,
    mu_s: f64,
    mu_d: f64,
    z: f64,
    len: f64,
    xb: f64,
    vb: f64,
    xc: f64,
    vc: f64,
    stuck: bool,
    t: f64,
}

impl Slider {
    fn spring(&self) -> f64 {
        self.k * (self.xb - self.xc) + self.c * (self.vb - self.vc)
    }
}

impl Model for Slider {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        let sub = 100;
        let h = dt / sub as f64;
        let (x0, x1) = (self.xc, cmd.insertion);
        for i in 0..sub {
            self.vc = (x1 - x0) / dt;
            self.xc = x0 + (x1 - x0) * (i + 1) as f64 / sub as f64;
            let f = self.spring();
            if self.stuck {
                if f.abs() > self.mu_s * self.n_force {
                    self.stuck = false;
                } else {
                    continue;
                }
            }
            let fric = if self.vb != 0.0 {
                -self.vb.signum()
            } else {
                -(-f).signum()
            } * self.mu_d
                * self.n_force;
            let a = (-f + fric) / self.m;
            let v_new = self.vb + a * h;
            if self.vb != 0.0 && v_new.signum() != self.vb.signum() && self.spring().abs() <= self.mu_s * self.n_force {
                self.vb = 0.0;
                self.stuck = true;
            } else {
                self.vb = v_new;
                self.xb += self.vb * h;
            }
        }
        self.t += dt;
        Ok(StepStats::default())
    }
    fn observe(&self) -> Observation {
        let n = 10;
        let nodes: Vec<Vec3> = (0..=n)
            .map(|i| Vec3::new(self.xb + self.len * i as f64 / n as f64, 0.0, self.z))
            .collect();
        Observation {
            time: self.t,
            rods: vec![rod_obs(
                (0..=n).map(|i| self.len * i as f64 / n as f64).collect(),
                nodes,
                Vec3::x() * self.vb,
            )],
            hand_force: Vec3::x() * self.spring(),
            ..Default::default()
        }
    }
    fn dt(&self) -> f64 {
        1e-3
    }
}

#[test]
fn stick_slip_threshold_is_found_by_a_coulomb_slider() {
    let s = scenario("stick-slip-threshold");
    let p = params(s, &[]);
    let (r, rho, l, g, e) = (WIRE_RADIUS, 6450.0, 0.1, 9.81, 1e6);
    let (mu_s, mu_d) = (0.3, 0.2);
    let n_force = rho * PI * r * r * l * g;
    let m = rho * PI * r * r * l;
    let k = e * PI * r * r / l;
    let f = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| {
            Box::new(Slider {
                k,
                c: 2.0 * (k * m).sqrt(),
                m,
                n_force,
                mu_s,
                mu_d,
                z: -(2e-3 - r),
                len: l,
                xb: 0.0,
                vb: 0.0,
                xc: 0.0,
                vc: 0.0,
                stuck: true,
                t: 0.0,
            })
        }),
    };
    let sum = run(s, &p, &f);
    assert_eq!(sum.status, "ok", "{}", sum.reason);
    let er = &sum.errors;
    assert_eq!(er["slipped"], 1.0);
    println!(
        "slider: threshold error {:.2e} (rel), sliding force error {:.2e} (rel), creep {:.2e} m",
        er["threshold_error_rel"], er["sliding_force_error_rel"], er["creep_before_threshold_m"]
    );
    // A rigid block breaks loose at mu_s N (the scene's `rigid_threshold_n`),
    // not at the elastic wire's mu_d N the scene scores against: the scorer
    // finds the block's threshold to the resolution of the force ramp, k v
    // between samples 0.6 s / 400 apart, relative to mu_s N...
    let res = k * 1e-3 * (0.6 / 400.0) / (mu_s * n_force);
    let rigid = (er["threshold_n"] - er["rigid_threshold_n"]).abs() / er["rigid_threshold_n"];
    assert!(
        rigid <= res + 1e-9,
        "threshold off mu_s N by {rigid} > resolution {res}"
    );
    // ... and reports it off the elastic wire's threshold by (mu_s - mu_d) / mu_d.
    let off = (mu_s - mu_d) / mu_d;
    assert!(
        (er["threshold_error_rel"] - off).abs() <= mu_s / mu_d * res + 1e-9,
        "threshold error {} vs {off}",
        er["threshold_error_rel"]
    );
    assert!(
        er["creep_before_threshold_m"] <= 1e-6,
        "creep {}",
        er["creep_before_threshold_m"]
    );
    // Critically damped slider: the tail force settles at mu_d N (within
    // the damped transient, measured 0.2%).
    assert!(
        er["sliding_force_error_rel"] < 0.01,
        "sliding force error {}",
        er["sliding_force_error_rel"]
    );
    assert_eq!(er["max_penetration_m"], 0.0);

    // A frictionless wire slides at once: no force builds up.
    let free = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| Box::new(Kinematic::along(move |s| Vec3::new(s, 0.0, -(2e-3 - r)), l, 10))),
    };
    let sum = run(s, &p, &free);
    // The kinematic wire keeps its tip at L0 + insertion: it moves with the pull.
    assert_eq!(sum.errors["slipped"], 1.0);
    assert!(
        (sum.errors["threshold_error_rel"] - 1.0).abs() < 1e-12,
        "{}",
        sum.errors["threshold_error_rel"]
    );
}

#[test]
fn flow_drift_needs_flow_and_scores_drift() {
    let s = &vessel::FLOW_DRIFT;
    let p = params(s, &[]);
    let no_flow = TestFactory {
        caps: &[Capability::Rod, Capability::VesselContact, Capability::Friction],
        build: Box::new(|_| unreachable!("an unsupported scene is never built")),
    };
    let sum = run(s, &p, &no_flow);
    assert_eq!(sum.status, "unsupported");
    assert!(sum.reason.contains("flow"), "{}", sum.reason);
    // A wire swung to the perpendicular: tip drift = L (cos(pi/2) - cos(2pi/3)).
    let l = 2.8e-3;
    let f = TestFactory {
        caps: ALL_ROD_CAPS,
        build: Box::new(move |_| Box::new(Kinematic::along(|s| Vec3::new(0.0, s, 0.0), l, 10))),
    };
    let sum = run(s, &p, &f);
    let e = &sum.errors;
    assert!((e["tip_drift_m"] - l * 0.5).abs() < 1e-15, "drift {}", e["tip_drift_m"]);
    assert!((e["tip_wall_gap_m"] - (3e-3 - l - WIRE_RADIUS)).abs() < 1e-15);
    assert_eq!(
        e["reference_available"], 1.0,
        "the DER reference (datasets/reference/flow-drift) is committed"
    );
    assert_eq!(sum.end, "settled", "a motionless wire settles");
}

/// DER on `stick-slip-threshold` against the elastic wire's reference: the
/// tip first moves within 5 % of `mu_d N` at every segment count, and the
/// force-displacement curve `sqrt(2 EA mu_d n u0)` while slip spreads is
/// met at first order in the segment length.
#[test]
fn der_meets_the_elastic_wire_stick_slip_reference() {
    use surgbench_comparisons::registry;
    use surgbench_comparisons::runner::{RunOptions, run_single};
    use surgbench_core::Fidelity;
    let s = scenario("stick-slip-threshold");
    let p = params(s, &[]);
    let der = registry::model("der").unwrap();
    let mut curve = Vec::new();
    for n in [10.0, 20.0, 40.0] {
        let mut fid = Fidelity::default();
        fid.set("segments", n).unwrap();
        let r = s.instantiate_at(&p, &fid).unwrap();
        let sum = run_single(s, &p, &r, der, &fid, &RunOptions::default()).unwrap();
        assert_eq!(sum.status, "ok", "{}", sum.reason);
        let th = sum.errors["threshold_error_rel"];
        // Measured 6.8e-3, 5.5e-3, 1.7e-2 (2.2e-2 at 80): the 5 % the
        // issue asks; a chain of K nodes is (mu_s - mu_d) / (mu_d K) above.
        assert!(th < 0.05, "{n} segments: threshold error {th}");
        curve.push(sum.errors["curve_error_rel"]);
        // The series the report plots: the hand force against the bar's
        // law after settling (none before), ending on the sliding mu_d N.
        let scored: Vec<_> = sum.series.iter().filter(|x| x.force[1].is_finite()).collect();
        assert!(scored.len() > 10 && scored.len() < sum.series.len());
        for x in &scored {
            assert_eq!(x.force[0], x.hand_force[0], "t = {}", x.t);
        }
        let last = scored.last().unwrap();
        assert_eq!(last.force[1], sum.errors["threshold_ref_n"]);
    }
    // Measured 4.5e-2, 2.2e-2, 1.1e-2: order 1.02 then 1.00.
    for w in curve.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!((0.8..1.3).contains(&order), "curve errors {curve:?}");
    }
}
