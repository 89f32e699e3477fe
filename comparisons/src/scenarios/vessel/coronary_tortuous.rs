//! `coronary-tortuous`: a guidewire pushed, pulled and rotated for 60 s in
//! a tortuous coronary (multi-point contact); stability, penetration,
//! progress.

use super::*;
use crate::params;
use crate::scenario::{ParamSpec, Params, Range, Scenario, ScenarioInfo, ScenarioRun, Scorer, UsageError, sweep_of};
use std::sync::Arc;
use surgbench_core::motion::VesselMotion;
use surgbench_core::vessel::{self, Vessel};
use surgbench_core::{Family, Fidelity, Scene};

/// Push, pull and rotate a guidewire for 60 s in a tortuous coronary:
/// multi-point contact along the whole wire.
pub struct CoronaryTortuous;

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
    scene: Scene,
    vessel: Arc<Vessel>,
    wire_radius: f64,
    energy: f64,
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

/// One coronary run's sums: the common ones, penetration measured against
/// the lumen at each observation's time (the moved wall when it beats).
struct CoronaryScorer<'a> {
    run: &'a CoronaryRun,
    common: Common,
}

impl Scorer for CoronaryScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        if tip(obs).is_none() {
            return;
        }
        if let Some(lumen) = self.run.scene.environment.vessel_at(obs.time) {
            self.common.add(lumen.as_ref(), obs, self.run.wire_radius);
        }
    }
    /// Progress is the tip's rest point projected on the centreline.
    fn score(&self, obs: &Observation) -> Metrics {
        let Some(tip) = tip(obs) else { return Metrics::new() };
        let env = &self.run.scene.environment;
        if env.vessel_at(obs.time).is_none() {
            return Metrics::new();
        }
        let mut m = self.common.metrics(obs);
        let rest_tip = env
            .vessel_motion
            .as_ref()
            .map_or(tip, |mo| mo.rest_point(&tip, obs.time));
        m.insert("tip_progress_m".into(), self.run.vessel.trunk.project(&rest_tip).s);
        m
    }
}

impl ScenarioRun for CoronaryRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn scorer(&self) -> Box<dyn Scorer + '_> {
        Box::new(CoronaryScorer {
            run: self,
            common: Common::default(),
        })
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.15
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

const INFO: ScenarioInfo = ScenarioInfo {
    id: "coronary-tortuous",
    description: "guidewire pushed, pulled and rotated for 60 s in a tortuous 3 mm coronary (bends down to 5 mm radius)",
    family: Family::Rod,
    reference: "stability and penetration: wire surface depth past the wall from the geometry (no reference solution)",
    primary_error: "max_penetration_m",
};

impl Scenario for CoronaryTortuous {
    fn info(&self) -> &'static ScenarioInfo {
        &INFO
    }
    fn params(&self) -> &'static [ParamSpec] {
        CoronaryParams::SPECS
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[30.0, 60.0, 120.0])
    }
    fn instantiate_at(&self, params: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        Ok(Box::new(coronary_run(INFO.id, &CoronaryParams::of(params), |_| {
            Ok(None)
        })?))
    }
}

/// The coronary scene of `coronary-tortuous` and `coronary-beating`: the
/// wire at the entry, push/pull/rotate cycles, and the vessel's motion from
/// `motion`, which is told the deepest clamp arclength (m) the feed reaches.
pub(super) fn coronary_run(
    id: &str,
    p: &CoronaryParams,
    motion: impl FnOnce(f64) -> Result<Option<Arc<dyn VesselMotion>>, UsageError>,
) -> Result<CoronaryRun, UsageError> {
    let wire = wire!(p);
    check_lumen(wire.radius, vessel::CORONARY_RADIUS, "coronary")?;
    let l0 = p.initial_length;
    if l0 + ENTRY_S > vessel::CORONARY_ENTRY {
        return Err(UsageError(format!(
            "initial_length {l0} m does not fit the {} m straight entry",
            vessel::CORONARY_ENTRY
        )));
    }
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
    clamp_stays_in_straight(ENTRY_S + advance, vessel::CORONARY_ENTRY, "coronary entry")?;
    let mut scene = Scene::empty(id);
    scene.duration = duration;
    scene.bodies.push(wire.rod(l0, cor.trunk.frame_at(ENTRY_S))?.into());
    scene.environment.vessel = Some(cor.clone());
    scene.environment.vessel_motion = motion(ENTRY_S + advance)?;
    scene.environment.contact = contact(p.friction_static, p.friction_dynamic, wire.radius)?;
    scene.control = push_pull_rotate(v, duration);
    scene.validate().map_err(UsageError)?;
    Ok(CoronaryRun {
        scene,
        // The whole wire bent to the tightest 5 mm bend.
        energy: wire.body_ei() * (l0 + advance) / 25e-6,
        vessel: cor,
        wire_radius: wire.radius,
    })
}
