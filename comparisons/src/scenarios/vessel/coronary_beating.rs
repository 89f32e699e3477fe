//! `coronary-beating`: `coronary-tortuous` in a vessel swinging with the
//! heart beat (a prescribed motion of the wall).

use super::coronary_tortuous::{C_L0, C_MU_D, C_MU_S, C_PUSH, CoronaryParams, coronary_run};
use super::*;
use crate::params;
use crate::references::cached_reference;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::motion::CardiacMotion;

params! {
    /// Parameters of `coronary-beating`: the coronary scene's and the heart
    /// motion's.
    pub struct BeatingParams {
        wire_radius: P_WIRE_RADIUS,
        body_youngs_modulus: P_BODY_E,
        tip_youngs_modulus: P_TIP_E,
        tip_length: P_TIP_LEN,
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        friction_static: C_MU_S,
        friction_dynamic: C_MU_D,
        push_speed: C_PUSH,
        initial_length: C_L0,
        duration: ParamSpec::new(
            "duration",
            12.0,
            "s",
            Range::Positive,
            "simulated time (6 s push/pull/rotate cycles as in coronary-tortuous)",
        ),
        amplitude: ParamSpec::new(
            "amplitude",
            4e-3,
            "m",
            Range::NonNegative,
            "peak transverse swing of the moving vessel (heart motion: several mm, Shechter et al. 2004/2005)",
        ),
        heart_rate: ParamSpec::new("heart_rate", 1.2, "Hz", Range::Positive, "beats per second (72 per minute)"),
        motion_start: ParamSpec::new(
            "motion_start",
            0.025,
            "m",
            Range::Positive,
            "arclength along the entry where the swing begins (past the deepest clamp position, 20 mm by default)",
        ),
        motion_ramp: ParamSpec::new(
            "motion_ramp",
            0.025,
            "m",
            Range::Positive,
            "length over which the swing grows to full amplitude",
        ),
    }
}

impl BeatingParams {
    /// The coronary scene's parameters.
    fn coronary(&self) -> CoronaryParams {
        CoronaryParams {
            wire_radius: self.wire_radius,
            body_youngs_modulus: self.body_youngs_modulus,
            tip_youngs_modulus: self.tip_youngs_modulus,
            tip_length: self.tip_length,
            density: self.density,
            poisson_ratio: self.poisson_ratio,
            friction_static: self.friction_static,
            friction_dynamic: self.friction_dynamic,
            push_speed: self.push_speed,
            initial_length: self.initial_length,
            duration: self.duration,
        }
    }
}

/// The tortuous coronary on a beating heart: the lumen swings transversely
/// ([`CardiacMotion`]) while the guidewire is pushed, pulled and rotated as
/// in `coronary-tortuous`. The guiding catheter (the clamp) sits in the still
/// proximal entry; past `motion_start` the vessel swings by up to
/// `amplitude` along z at `heart_rate`, reaching full amplitude `motion_ramp`
/// further on. The wall pushes the wire sideways twice a beat: a test of
/// contact with a moving wall and of friction measured against it.
pub const CORONARY_BEATING: Declared<BeatingParams> = Declared {
    info: ScenarioInfo {
        id: "coronary-beating",
        description: "guidewire pushed, pulled and rotated in the tortuous coronary while the vessel swings 4 mm at 72 beats/min",
        family: Family::Rod,
        reference: "converged DER tip path cached in datasets/reference/coronary-beating/tip_trajectory.csv (default parameters only; DER at 80 and 160 segments differ by at most 9.5e-6 m); penetration against the moving wall from the geometry at each observation's time",
        primary_error: "tip_error_rms_m",
        target: crate::scenario::Target::new(
            0.001,
            "1 mm of tip position (RMS over the run): the project's default for navigation",
        ),
        params: BeatingParams::SPECS,
        sweep: Sweep::Knob("segments", &[30.0, 60.0, 120.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &BeatingParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let (start, ramp) = (p.motion_start, p.motion_ramp);
    let id = CORONARY_BEATING.info.id;
    let reference = cached_reference(id, inputs)?;
    coronary_run(
        id,
        &p.coronary(),
        |deepest| {
            if start <= deepest {
                return Err(UsageError(format!(
                    "motion_start {start} m must lie past the deepest clamp position {deepest:.3} m (the guiding catheter does not beat)"
                )));
            }
            // The entry runs along +x from the origin; the swing is across it.
            let m = CardiacMotion::new(
                Vec3::zeros(),
                Vec3::x(),
                Vec3::z(),
                start,
                ramp,
                p.amplitude,
                p.heart_rate,
            )
            .map_err(UsageError)?;
            Ok(Some(Arc::new(m)))
        },
        reference,
    )
}
