//! `arch-insertion`: a guidewire pushed over an aortic arch with
//! intermittent rotations; reach, time to reach, penetration, hand force and
//! (with the cached converged trajectory) tip error.

use super::*;
use crate::params;
use crate::references::{TipTrajectory, cached_reference};
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::vessel::{self, Vessel};

/// Default J length (m) of the arch wire: half a turn of the 3 mm J common
/// on 0.035-inch access guidewires (`j_curvature = 333 1/m`); the default
/// tip is straight (`j_curvature = 0`), as the scene is specified.
const ARCH_J_LENGTH: f64 = PI * 3e-3;

params! {
    /// Parameters of `arch-insertion`.
    pub struct ArchParams {
        wire_radius: P_WIRE_RADIUS,
        body_youngs_modulus: P_BODY_E,
        tip_youngs_modulus: P_TIP_E,
        tip_length: P_TIP_LEN,
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        friction_static: P_MU_S,
        friction_dynamic: P_MU_D,
        gravity: P_GRAVITY,
        insertion_speed: ParamSpec::new("insertion_speed", 0.02, "m/s", Range::Positive, "constant feed speed"),
        j_curvature: ParamSpec::new(
            "j_curvature",
            0.0,
            "1/m",
            Range::NonNegative,
            "rest curvature of the tip's J (towards the clamp's local y; 0: straight tip)",
        ),
        j_length: ParamSpec::new(
            "j_length",
            ARCH_J_LENGTH,
            "m",
            Range::Positive,
            "length of the curved J at the tip (within the soft tip)",
        ),
        initial_length: ParamSpec::new(
            "initial_length",
            0.2,
            "m",
            Range::Positive,
            "free wire length at t = 0: the tip starts 5 mm short of the arch (the clamp needs the 150 mm of straight below it for the push)",
        ),
        rotation_step: ParamSpec::new(
            "rotation_step",
            PI / 2.0,
            "rad",
            Range::Any,
            "size of each intermittent rotation (alternating sign)",
        ),
        rotation_interval: ParamSpec::new(
            "rotation_interval",
            1.0,
            "s",
            Range::Positive,
            "time between rotation starts",
        ),
        rotation_time: ParamSpec::new("rotation_time", 0.2, "s", Range::Positive, "duration of each rotation"),
        target_depth: ParamSpec::new(
            "target_depth",
            0.01,
            "m",
            Range::NonNegative,
            "target plane: this far into the ascending aorta",
        ),
        duration: ParamSpec::new("duration", 7.5, "s", Range::Positive, "simulated time"),
    }
}

struct ArchRun {
    vessel: Arc<Vessel>,
    wire_radius: f64,
    target_s: f64,
    reference: Option<TipTrajectory>,
}

/// Insertion ramp with alternating rotations every `interval` seconds.
fn push_with_rotations(speed: f64, duration: f64, step: f64, interval: f64, rot_time: f64) -> ControlTimeline {
    let mut keys = vec![(0.0, 0.0, 0.0)];
    let mut rot = 0.0;
    let mut k = 1;
    loop {
        let t0 = k as f64 * interval;
        let t1 = t0 + rot_time.min(0.9 * interval);
        if t1 >= duration {
            break;
        }
        keys.push((t0, speed * t0, rot));
        rot += if k % 2 == 1 { step } else { -step };
        keys.push((t1, speed * t1, rot));
        k += 1;
    }
    keys.push((duration, speed * duration, rot));
    timeline(&keys)
}

/// One arch run's own sums: when the tip first passed the target plane.
#[derive(Default)]
struct ArchSums {
    reached_at: Option<f64>,
}

impl ArchRun {
    /// Arclength of the tip's projection on the trunk (m) and whether it is
    /// past the target plane, outside every branch lumen.
    fn progress(&self, tip: &Vec3) -> (f64, bool) {
        let (lumen, _) = self.vessel.deepest(tip);
        let s = self.vessel.trunk.project(tip).s;
        (s, lumen.is_none() && s >= self.target_s)
    }
}

impl Trajectory for ArchRun {
    type Sums = ArchSums;
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, sums: &mut ArchSums, obs: &Observation, tip: &Vec3) {
        if self.progress(tip).1 && sums.reached_at.is_none() {
            sums.reached_at = Some(obs.time);
        }
    }
    fn metrics(&self, sums: &ArchSums, _: &Common, _: &Observation, tip: &Vec3, m: &mut Metrics) {
        m.insert("tip_progress_m".into(), self.progress(tip).0);
        m.insert("reached".into(), sums.reached_at.is_some() as u8 as f64);
        if let Some(r) = sums.reached_at {
            m.insert("time_to_reach_s".into(), r);
        }
        m.insert("reference_available".into(), self.reference.is_some() as u8 as f64);
    }
    fn reference(&self) -> Option<&TipTrajectory> {
        self.reference.as_ref()
    }
}

/// Push a guidewire up the descending aorta, over the arch and down the
/// ascending aorta at constant speed with intermittent quarter turns.
pub const ARCH_INSERTION: Declared<ArchParams> = Declared {
    info: ScenarioInfo {
        id: "arch-insertion",
        description: "guidewire pushed over an aortic arch (25 mm lumen, 35 mm arch radius) with intermittent rotation",
        family: Family::Rod,
        reference: "converged DER tip trajectory cached in datasets/reference/arch-insertion/tip_trajectory.csv (default parameters only); without it only reach, time-to-reach, penetration and hand force are scored",
        primary_error: "tip_error_m",
        target: crate::scenario::Target::new(0.001, "1 mm of tip position: the project's default for navigation"),
        params: ArchParams::SPECS,
        sweep: Sweep::Knob("segments", &[25.0, 50.0, 100.0, 200.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &ArchParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let wire = wire!(p);
    check_lumen(wire.radius, vessel::AORTA_RADIUS, "aortic")?;
    let l0 = p.initial_length;
    let what = format!("descending segment after the {ENTRY_S} m entry");
    check_initial_length(l0, vessel::ARCH_DESCENDING, &what)?;
    let feed = p.insertion_speed * p.duration;
    let feed_limit = FeedLimit {
        start: ENTRY_S,
        straight: vessel::ARCH_DESCENDING,
        what: "descending aorta",
    };
    feed_limit.check(feed)?;
    let arch = Arc::new(vessel::aortic_arch());
    let (jl, kappa) = (p.j_length, p.j_curvature);
    let rod = wire.rod_with_j(l0, arch.trunk.frame_at(ENTRY_S), jl, kappa)?;
    let contact = contact(p.friction_static, p.friction_dynamic, wire.radius)?;
    let mut scene = wire_scene(ARCH_INSERTION.info.id, p.duration, rod, arch.clone(), contact);
    scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
    scene.control = push_with_rotations(
        p.insertion_speed,
        scene.duration,
        p.rotation_step,
        p.rotation_interval,
        p.rotation_time,
    );
    scene.validate().map_err(UsageError)?;
    let total = l0 + p.insertion_speed * scene.duration;
    // Bending the whole wire to the arch radius.
    let energy = wire.body_ei() * total / (vessel::ARCH_RADIUS * vessel::ARCH_RADIUS);
    let run = ArchRun {
        target_s: vessel::ARCH_DESCENDING + PI * vessel::ARCH_RADIUS + p.target_depth,
        wire_radius: wire.radius,
        reference: cached_reference(ARCH_INSERTION.info.id, inputs)?,
        vessel: arch,
    };
    Ok(vessel_run(scene, run, energy, 0.25).with_feed_limit(feed_limit))
}
