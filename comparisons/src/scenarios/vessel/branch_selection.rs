//! `branch-selection`: a J-tipped guidewire steered into one branch of a
//! Y bifurcation by rotations replayed from a recorded session.

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, Sweep, UsageError,
};
use std::sync::Arc;
use surgbench_core::Family;
use surgbench_core::haptic::Session;
use surgbench_core::vessel::{self, Vessel};

const SESSION_45: &str = include_str!("../../../../datasets/vessels/branch-selection-45.csv");
const SESSION_70: &str = include_str!("../../../../datasets/vessels/branch-selection-70.csv");

params! {
    /// Parameters of `branch-selection`.
    pub struct BranchParams {
        wire_radius: P_WIRE_RADIUS,
        body_youngs_modulus: P_BODY_E,
        tip_youngs_modulus: P_TIP_E,
        tip_length: P_TIP_LEN,
        density: P_DENSITY,
        poisson_ratio: P_POISSON,
        friction_static: P_MU_S,
        friction_dynamic: P_MU_D,
        target: ParamSpec::new(
            "target",
            0.0,
            "1",
            Range::Closed(0.0, 1.0),
            "0: branch-45 (+y), 1: branch-70 (-y); picks the recorded session",
        ),
        j_curvature: ParamSpec::new(
            "j_curvature",
            100.0,
            "1/m",
            Range::Positive,
            "rest curvature of the J (towards the clamp's local y)",
        ),
        j_length: ParamSpec::new(
            "j_length",
            0.005,
            "m",
            Range::Positive,
            "length of the curved J at the tip (within the soft tip)",
        ),
        initial_length: ParamSpec::new("initial_length", 0.032, "m", Range::Positive, "free wire length at t = 0"),
        target_depth: ParamSpec::new(
            "target_depth",
            0.005,
            "m",
            Range::Positive,
            "success: tip this far along the target branch",
        ),
        duration: ParamSpec::new("duration", 5.0, "s", Range::Positive, "simulated time (the sessions last 4.5 s)"),
    }
}

struct BranchRun {
    vessel: Arc<Vessel>,
    target: usize,
    depth: f64,
    wire_radius: f64,
    rotations: usize,
}

impl BranchRun {
    /// Arclength of the tip along the target branch (m) and whether the tip
    /// is inside it, at least `depth` deep.
    fn inside(&self, tip: &Vec3) -> (f64, bool) {
        let (lumen, phi) = self.vessel.deepest(tip);
        let along = self.vessel.branches[self.target].tube.project(tip).s;
        (along, lumen == Some(self.target) && phi < 0.0 && along >= self.depth)
    }
}

impl Trajectory for BranchRun {
    /// When the tip first stood in the target branch (s).
    type Sums = Option<f64>;
    fn wire_radius(&self) -> f64 {
        self.wire_radius
    }
    fn add(&self, reached_at: &mut Option<f64>, obs: &Observation, tip: &Vec3) {
        if self.inside(tip).1 && reached_at.is_none() {
            *reached_at = Some(obs.time);
        }
    }
    fn metrics(&self, reached_at: &Option<f64>, _: &Common, _: &Observation, tip: &Vec3, m: &mut Metrics) {
        let (along, inside) = self.inside(tip);
        m.insert("target_missed".into(), if inside { 0.0 } else { 1.0 });
        m.insert("success".into(), inside as u8 as f64);
        if let Some(r) = reached_at {
            m.insert("time_to_target_s".into(), *r);
        }
        m.insert("rotation_commands".into(), self.rotations as f64);
        m.insert("tip_along_target_m".into(), along);
    }
}

/// Select a branch of a Y bifurcation by rotating a pre-shaped J tip, as
/// replayed from a recorded session.
pub const BRANCH_SELECTION: Declared<BranchParams> = Declared {
    info: ScenarioInfo {
        id: "branch-selection",
        description: "J-tip guidewire steered into the 45 or 70 degree branch of a Y bifurcation by a recorded session",
        family: Family::Rod,
        reference: "success: tip inside the target branch past target_depth; recorded sessions datasets/vessels/branch-selection-{45,70}.csv",
        primary_error: "target_missed",
        target: crate::scenario::Target::new(0.0, "the wire must enter the target branch (0 = entered)"),
        params: BranchParams::SPECS,
        sweep: Sweep::Knob("segments", &[20.0, 40.0, 80.0]),
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &BranchParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let wire = wire!(p);
    check_lumen(wire.radius, vessel::Y_BRANCH_RADIUS, "branch")?;
    let target = p.target;
    if target.fract() != 0.0 {
        return Err(UsageError(format!("target must be 0 or 1, got {target}")));
    }
    let target = target as usize;
    let (name, text) = if target == 0 {
        ("datasets/vessels/branch-selection-45.csv", SESSION_45)
    } else {
        ("datasets/vessels/branch-selection-70.csv", SESSION_70)
    };
    let session = Session::parse(name, text).map_err(|e| UsageError(e.to_string()))?;
    let (l0, jl, kappa) = (p.initial_length, p.j_length, p.j_curvature);
    check_initial_length(l0, vessel::Y_TRUNK, "trunk")?;
    // Lateral offset of the J's end from the axis: (1 - cos(kappa j)) / kappa.
    let offset = (1.0 - (kappa * jl).min(PI).cos()) / kappa;
    if offset + wire.radius > vessel::Y_TRUNK_RADIUS {
        return Err(UsageError(format!(
            "the J (curvature {kappa} 1/m over {jl} m) sticks out {offset:.2e} m from the axis: the wire would start in the wall"
        )));
    }
    let y = Arc::new(vessel::y_bifurcation());
    // Clamp on the trunk axis, its local y (where the J bends) turned to +z.
    let base = y.trunk.frame_at(ENTRY_S) * Iso3::rotation(Vec3::x() * (PI / 2.0));
    let rod = wire.rod_with_j(l0, base, jl, kappa)?;
    let contact = contact(p.friction_static, p.friction_dynamic, wire.radius)?;
    let mut scene = wire_scene(BRANCH_SELECTION.info.id, p.duration, rod, y.clone(), contact);
    scene.control = session.timeline.clone();
    scene.validate().map_err(UsageError)?;
    // The whole wire bent at a 10 mm radius into a branch.
    let fed = session.timeline.keys.iter().map(|k| k.insertion).fold(0.0, f64::max);
    let energy = wire.body_ei() * (l0 + fed) / 1e-4;
    let run = BranchRun {
        vessel: y,
        target,
        depth: p.target_depth,
        wire_radius: wire.radius,
        rotations: session.rotation_commands(),
    };
    Ok(vessel_run(scene, run, energy, 0.1))
}
