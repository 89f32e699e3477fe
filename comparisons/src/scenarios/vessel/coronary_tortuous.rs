//! `coronary-tortuous`: a guidewire pushed, pulled and rotated for 60 s in
//! a tortuous coronary (multi-point contact); stability, penetration,
//! progress.

use super::*;
use crate::params;
use crate::references::TipTrajectory;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::motion::VesselMotion;
use surgbench_core::vessel::{self, Vessel};

/// Friction of the coated coronary wire, static.
pub(super) const C_MU_S: ParamSpec = ParamSpec::new(
    "friction_static",
    0.05,
    "1",
    Range::NonNegative,
    "static friction (coated wire)",
);
/// Friction of the coated coronary wire, dynamic.
pub(super) const C_MU_D: ParamSpec = ParamSpec::new(
    "friction_dynamic",
    0.04,
    "1",
    Range::NonNegative,
    "dynamic friction (<= static)",
);
/// Feed speed of the push/pull cycles.
pub(super) const C_PUSH: ParamSpec = ParamSpec::new(
    "push_speed",
    5e-3,
    "m/s",
    Range::Positive,
    "feed speed of each push and pull",
);
/// Free wire length at the start.
pub(super) const C_L0: ParamSpec = ParamSpec::new(
    "initial_length",
    0.032,
    "m",
    Range::Positive,
    "free wire length at t = 0",
);

params! {
    /// Parameters of `coronary-tortuous` (and the coronary scene
    /// `coronary-beating` moves).
    pub struct CoronaryParams {
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
            60.0,
            "s",
            Range::Positive,
            "simulated time (6 s cycles: push 2 s, pull 1 s, turn, hold, turn back)",
        ),
    }
}

pub(super) struct CoronaryRun {
    vessel: Arc<Vessel>,
    motion: Option<Arc<dyn VesselMotion>>,
    wire_radius: f64,
    /// The converged tip path (`coronary-beating` at its defaults).
    reference: Option<TipTrajectory>,
}

/// Cycles of 6 s: push 2 s, pull 1 s, rotate +pi/2 (1 s), hold 1 s, rotate
/// -pi/4 (1 s): net advance one push-second per cycle.
fn push_pull_rotate(v: f64, duration: f64) -> ControlTimeline {
    let mut keys = vec![(0.0, 0.0, 0.0)];
    let (mut ins, mut rot, mut t) = (0.0f64, 0.0f64, 0.0f64);
    let phases = [
        (2.0, v, 0.0),
        (1.0, -v, 0.0),
        (1.0, 0.0, PI / 2.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, -PI / 4.0),
    ];
    'outer: loop {
        for &(dt, dv, dr) in &phases {
            let end = (t + dt).min(duration);
            let w = (end - t) / dt;
            ins += dv * dt * w;
            rot += dr * w;
            t = end;
            keys.push((t, ins, rot));
            if t >= duration {
                break 'outer;
            }
        }
    }
    timeline(&keys)
}

impl Trajectory for CoronaryRun {
    type Sums = ();
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, _: &mut (), _: &Observation, _: &Vec3) {}
    /// Progress is the tip's rest point projected on the centreline (the
    /// moved tip pulled back through the heart's motion, if any).
    fn metrics(&self, _: &(), _: &Common, obs: &Observation, tip: &Vec3, m: &mut Metrics) {
        let rest_tip = self.motion.as_ref().map_or(*tip, |mo| mo.rest_point(tip, obs.time));
        m.insert("tip_progress_m".into(), self.vessel.trunk.project(&rest_tip).s);
    }
    fn reference(&self) -> Option<&TipTrajectory> {
        self.reference.as_ref()
    }
}

/// Push, pull and rotate a guidewire for 60 s in a tortuous coronary:
/// multi-point contact along the whole wire.
pub const CORONARY_TORTUOUS: Declared<CoronaryParams> = Declared {
    info: ScenarioInfo {
        id: "coronary-tortuous",
        description: "guidewire pushed, pulled and rotated for 60 s in a tortuous 3 mm coronary (bends down to 5 mm radius)",
        family: Family::Rod,
        reference: "stability and penetration: wire surface depth past the wall from the geometry (no reference solution)",
        primary_error: "max_penetration_m",
        target: crate::scenario::Target::new(
            0.0001,
            "0.1 mm of penetration: half the radius of a 0.014 in coronary guidewire (0.18 mm)",
        ),
        params: CoronaryParams::SPECS,
        sweep: Sweep::Knob("segments", &[30.0, 60.0, 120.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &CoronaryParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    coronary_run(CORONARY_TORTUOUS.info.id, p, |_| Ok(None), None)
}

/// The coronary scene of `coronary-tortuous` and `coronary-beating`: the
/// wire at the entry, push/pull/rotate cycles, and the vessel's motion from
/// `motion`, which is told the deepest clamp arclength (m) the feed reaches.
pub(super) fn coronary_run(
    id: &str,
    p: &CoronaryParams,
    motion: impl FnOnce(f64) -> Result<Option<Arc<dyn VesselMotion>>, UsageError>,
    reference: Option<TipTrajectory>,
) -> Result<ScenarioRun, UsageError> {
    let wire = wire!(p);
    check_lumen(wire.radius, vessel::CORONARY_RADIUS, "coronary")?;
    let l0 = p.initial_length;
    check_initial_length(l0, vessel::CORONARY_ENTRY, "straight entry")?;
    let cor = Arc::new(vessel::coronary_tortuous());
    let duration = p.duration;
    let v = p.push_speed;
    // Net advance v x 1 s per 6 s cycle, 2 v at the end of a push: the
    // deepest insertion is v (cycles + 1). Keep the tip short of the end.
    let advance = v * ((duration / 6.0).ceil() + 1.0);
    if l0 + ENTRY_S + advance > cor.trunk.length() - 5e-3 {
        return Err(UsageError(format!(
            "push_speed {v} m/s for {duration} s advances {advance:.3} m: past the end of the {:.3} m coronary",
            cor.trunk.length()
        )));
    }
    let feed_limit = FeedLimit {
        start: ENTRY_S,
        straight: vessel::CORONARY_ENTRY,
        what: "coronary entry",
    };
    feed_limit.check(advance)?;
    let rod = wire.rod(l0, cor.trunk.frame_at(ENTRY_S))?;
    let motion = motion(ENTRY_S + advance)?;
    let contact = contact(p.friction_static, p.friction_dynamic, wire.radius)?;
    let mut scene = wire_scene(id, duration, rod, cor.clone(), contact);
    scene.environment.vessel_motion = motion;
    scene.control = push_pull_rotate(v, duration);
    scene.validate().map_err(UsageError)?;
    // The whole wire bent to the tightest 5 mm bend.
    let energy = wire.body_ei() * (l0 + advance) / 25e-6;
    let run = CoronaryRun {
        vessel: cor,
        motion: scene.environment.vessel_motion.clone(),
        wire_radius: wire.radius,
        reference,
    };
    Ok(vessel_run(scene, run, energy, 0.15).with_feed_limit(feed_limit))
}
