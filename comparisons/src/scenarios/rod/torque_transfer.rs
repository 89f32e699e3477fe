//! `torque-transfer`: a straight rod whose clamp turns about its axis with a
//! dead torque at its tip; the tip's twist is the clamp's plus `T L/(GJ)`
//! (closed form: uniform static twist).

use super::{DENSITY, DURATION, LENGTH, POISSON, RADIUS, RodCase, SEGMENTS, SETTLE, YOUNG, rod_case};
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, UsageError,
};
use std::f64::consts::PI;
use surgbench_core::frames::signed_angle;
use surgbench_core::{ControlTimeline, Family, Observation, Vec3};

/// Straight rod, base rotated by a prescribed angle: the tip must follow.
pub const TORQUE_TRANSFER: Declared<TorqueParams> = Declared {
    info: ScenarioInfo {
        id: "torque-transfer",
        description: "straight rod, clamp rotated about its axis and a torque at the tip: the tip twist is the clamp's plus T L/(GJ)",
        family: Family::Rod,
        reference: "closed form: uniform static twist, tip angle = base_twist + T L/(GJ)",
        primary_error: "twist_error_rad",
        target: crate::scenario::Target::new(
            0.0175,
            "1 degree of tip twist: what aiming a tip by base rotation tolerates",
        ),
        params: TorqueParams::SPECS,
        sweep: SEGMENTS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

params! {
    /// Parameters of `torque-transfer`.
    pub struct TorqueParams {
        length: LENGTH,
        radius: RADIUS,
        youngs_modulus: YOUNG,
        poisson_ratio: POISSON,
        density: DENSITY,
        base_twist: ParamSpec::new(
            "base_twist",
            PI / 2.0,
            "rad",
            Range::Any,
            "rotation of the clamp about the rod axis",
        ),
        // Non-zero by default so that the twist tests the torsional
        // stiffness: at the default rod (GJ/L = 0.0189 N m/rad) 0.01 N m
        // adds T L/(GJ) = 0.53 rad to the clamp's pi/2, with T L/(EI) = 0.41.
        // At T = 0 the tip only follows the clamp, which every frame
        // transport does exactly (error 0, a headline that says nothing).
        tip_torque: ParamSpec::new(
            "tip_torque",
            0.01,
            "N m",
            Range::Any,
            "dead axial torque at the tip (twist rate T/(GJ)); keep |T| L/(EI) well under pi",
        ),
        settle_tol: SETTLE,
        duration: DURATION,
    }
}

struct TorqueRun {
    length: f64,
    twist: f64,
    torque: f64,
}

/// Wrap an angle difference to (-pi, pi].
fn wrap(a: f64) -> f64 {
    let mut x = a.rem_euclid(2.0 * PI);
    if x > PI {
        x -= 2.0 * PI;
    }
    x
}

impl Pointwise for TorqueRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        let Some(r) = obs.rods.first() else {
            return m;
        };
        let f = r.tip_frame();
        let (d1, t) = (f.column(0).into_owned(), f.column(2).into_owned());
        // Twist of the tip's material frame relative to the unrotated base
        // frame (d1 = +y), about the (straight) rod axis.
        let angle = signed_angle(&Vec3::y(), &d1, &t);
        m.insert("twist_error_rad".into(), wrap(angle - self.twist).abs());
        m.insert(
            "tip_position_error_m".into(),
            (r.tip() - Vec3::new(self.length, 0.0, 0.0)).norm(),
        );
        let t_ref = Vec3::new(self.torque, 0.0, 0.0);
        m.insert("hand_torque_error_nm".into(), (obs.hand_torque - t_ref).norm());
        m.insert("max_stretch".into(), r.max_stretch.abs());
        m
    }
}

fn build(p: &TorqueParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let c = rod_case!(p);
    let base = p.base_twist;
    let torque = p.tip_torque;
    if (torque * c.length / c.ei()).abs() > 1.0 {
        return Err(UsageError(format!(
            "tip_torque: |T| L/(EI) = {:.3} > 1 approaches torsional buckling of the cantilever; the straight-rod closed form no longer applies",
            (torque * c.length / c.ei()).abs()
        )));
    }
    let mut scene = c.scene(TORQUE_TRANSFER.info.id, p.duration, p.settle_tol);
    scene.control = ControlTimeline::hold_rotation(base);
    let mut body = c.body();
    body.tip_torque = Vec3::new(torque, 0.0, 0.0);
    scene.bodies.push(body.into());
    let twist = base + torque * c.length / c.gj();
    // Twice the twist energy GJ twist^2 / (2 L), plus GJ/L: a scale at zero twist.
    let energy = (c.gj() / c.length) * (1.0 + twist * twist);
    let run = TorqueRun {
        length: c.length,
        twist,
        torque,
    };
    Ok(ScenarioRun::new(scene, run, energy, c.length).with_reference_tip([c.length, 0.0, 0.0]))
}
