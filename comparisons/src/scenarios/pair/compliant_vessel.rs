//! `catheter-compliant-vessel`: a catheter pushed 30 mm into a curved
//! compliant vessel, its base held on the centreline. The catheter bends
//! through the vessel's 90 degree turn and presses the outer side of the
//! bend, which gives way.
//!
//! Vessel: lumen 4 mm across, wall 0.5 mm thick (the values),
//! `E = 1 MPa`, `nu = 0.45` (the small-strain order of magnitude of
//! arterial wall, Holzapfel, Gasser & Ogden 2000, J Elasticity 61:1, as the
//! wall scenes of the tissue family), 40 mm straight, a 15 mm-radius quarter
//! turn, 15 mm straight; outer surface held. The clamp starts 2 mm in and
//! slides 30 mm along the first straight; the catheter's tip starts 32 mm
//! in and ends 1.6 mm before the turn's end. Catheter: 1 mm across (3 F),
//! a soft polymer shaft (`E = 100 MPa`, a scene choice of the order of
//! polymer catheter shafts, not a measured product), frictionless by
//! default.
//!
//! No reference solution yet (the reference, the finest `der+fem`
//! with iterated coupling, and the rigid-wall limit are the next slice), so
//! the scores hold for any pair: `max_penetration_m` (primary): how deep the
//! catheter's surface goes past the **deformed** wall (the rest lumen moved
//! by the tissue's observed surface displacement, the same interpolation
//! the coupling hands the rod: [`DisplacedLumen`]); `wall_displacement_max_m`
//! (largest inner-wall node displacement over the run); the hand force; the
//! tip's progress along the centreline.

use crate::params;
use crate::scenario::{
    Declared, FeedLimit, Inputs, Metrics, ParamSet, ParamSpec, Range, Reference, ScenarioInfo, ScenarioRun, Scorer,
    Sweep, UsageError,
};
use crate::scenarios::vessel::wall_penetration;
use std::f64::consts::PI;
use std::sync::Arc;
use surgbench_core::coupling::wall_samples;
use surgbench_core::sdf::{CenterlineBuilder, DisplacedLumen, Sdf, SweptTube, WallSamples};
use surgbench_core::{
    Body, ContactParams, ControlKey, ControlTimeline, Family, Observation, RodBody, Scene, SolidMaterial, TissueBody,
    Vec3, mesh,
};

params! {
    /// Parameters of `catheter-compliant-vessel` (module docs).
    pub struct CompliantParams {
        lumen_radius: ParamSpec::new("lumen_radius", 2e-3, "m", Range::Positive, "lumen radius at rest"),
        wall_thickness: ParamSpec::new("wall_thickness", 0.5e-3, "m", Range::Positive, "vessel wall thickness"),
        wall_youngs_modulus: ParamSpec::new("wall_youngs_modulus", 1e6, "Pa", Range::Positive, "wall Young's modulus"),
        wall_poisson_ratio: ParamSpec::new("wall_poisson_ratio", 0.45, "1", Range::Open(-1.0, 0.5), "wall Poisson ratio"),
        wall_density: ParamSpec::new("wall_density", 1060.0, "kg/m^3", Range::Positive, "wall density"),
        bend_radius: ParamSpec::new("bend_radius", 15e-3, "m", Range::Positive, "centreline radius of the quarter turn"),
        catheter_radius: ParamSpec::new("catheter_radius", 0.5e-3, "m", Range::Positive, "catheter radius (solid section)"),
        catheter_youngs_modulus: ParamSpec::new("catheter_youngs_modulus", 1e8, "Pa", Range::Positive, "catheter Young's modulus"),
        catheter_density: ParamSpec::new("catheter_density", 1100.0, "kg/m^3", Range::Positive, "catheter density"),
        friction: ParamSpec::new("friction", 0.0, "1", Range::NonNegative, "catheter-wall friction coefficient (static = dynamic)"),
        initial_length: ParamSpec::new("initial_length", 30e-3, "m", Range::Positive, "free catheter length at t = 0, straight along the entry"),
        insertion: ParamSpec::new("insertion", 30e-3, "m", Range::Positive, "length pushed in"),
        insertion_speed: ParamSpec::new("insertion_speed", 0.02, "m/s", Range::Positive, "feed speed"),
        hold_time: ParamSpec::new("hold_time", 0.2, "s", Range::NonNegative, "time held after the push"),
        gravity: ParamSpec::new("gravity", 0.0, "m/s^2", Range::NonNegative, "gravity along -z (0: neutrally buoyant in blood)"),
    }
}

/// Straight before the turn (m): the clamp slides along it (rod models
/// feed by moving the clamp along its axis), so it must hold the whole push
/// with room between the clamp and the turn.
const STRAIGHT_IN: f64 = 40e-3;
/// Straight after the turn (m).
const STRAIGHT_OUT: f64 = 15e-3;
/// Room kept between the clamp's last position and the turn (m).
const CLAMP_ROOM: f64 = 5e-3;
/// Clamp arclength from the vessel's start (m).
const CLAMP_S: f64 = 2e-3;
/// Wall cells around, through and (per metre) along at mesh level 0.
const N_THETA: usize = 16;
const N_R: usize = 1;
const CELLS_PER_M: f64 = 1000.0;
/// Finest mesh level (level 1 has 8x the tets of level 0).
const MAX_LEVEL: usize = 1;

/// The instance's geometry for the scorer.
struct Compliant {
    wall: Arc<WallSamples>,
    /// Tissue node of each wall sample (the `surface_vertices` order).
    vertices: Vec<usize>,
    tube: SweptTube,
    radius: f64,
}

/// Per-run sums.
struct CompliantScorer<'a> {
    r: &'a Compliant,
    max_pen: f64,
    max_wall: f64,
    force_sum: f64,
    force_max: f64,
    samples: usize,
}

impl Compliant {
    /// The observed wall sample positions, if the observation has the tissue.
    fn wall_now(&self, obs: &Observation) -> Option<Vec<Vec3>> {
        let t = obs.tissues.first()?;
        self.vertices.iter().map(|&i| t.nodes.get(i).copied()).collect()
    }
}

impl Scorer for CompliantScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        let Some(x) = self.r.wall_now(obs) else {
            return;
        };
        let disp = self.r.wall.normal_displacements(&x);
        let Ok(lumen) = DisplacedLumen::new(self.r.wall.clone(), disp) else {
            return;
        };
        let pen = wall_penetration(&lumen, obs, self.r.radius);
        self.max_pen = self.max_pen.max(pen);
        let t = &obs.tissues[0];
        let moved = self
            .r
            .vertices
            .iter()
            .map(|&i| (t.nodes[i] - t.rest[i]).norm())
            .fold(0.0, f64::max);
        self.max_wall = self.max_wall.max(moved);
        let f = obs.hand_force.norm();
        self.force_sum += f;
        self.force_max = self.force_max.max(f);
        self.samples += 1;
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        m.insert("max_penetration_m".into(), self.max_pen);
        m.insert("penetration_rel".into(), self.max_pen / self.r.radius);
        m.insert("wall_displacement_max_m".into(), self.max_wall);
        m.insert("hand_force_mean_n".into(), self.force_sum / self.samples.max(1) as f64);
        m.insert("hand_force_max_n".into(), self.force_max);
        if let Some(r) = obs.rods.first() {
            m.insert("tip_progress_m".into(), self.r.tube.project(&r.tip()).s);
            m.insert("max_stretch".into(), r.max_stretch.abs());
        }
        m
    }
}

impl Reference for Compliant {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(CompliantScorer {
            r: self,
            max_pen: 0.0,
            max_wall: 0.0,
            force_sum: 0.0,
            force_max: 0.0,
            samples: 0,
        })
    }
}

/// A catheter pushed into a curved compliant vessel.
pub const CATHETER_COMPLIANT_VESSEL: Declared<CompliantParams> = Declared {
    info: ScenarioInfo {
        id: "catheter-compliant-vessel",
        description: "catheter (1 mm, 100 MPa) pushed 30 mm into a curved compliant vessel (lumen 4 mm, wall 0.5 mm, 1 MPa, outer surface held): rod x tissue pairs",
        family: Family::Pair,
        reference: "no reference solution yet: catheter surface depth past the deformed wall (geometric), wall displacement, hand force, tip progress",
        primary_error: "max_penetration_m",
        target: crate::scenario::Target::new(0.0001, "0.1 mm of penetration past the moved wall"),
        params: CompliantParams::SPECS,
        sweep: Sweep::Knob("segments", &[20.0, 40.0]),
        quick: 1,
        mesh: None,
    },
    datasets: None,
    build,
};

/// The geometry checks of `p` at mesh `level`: the vessel's length (m) and
/// how far the hand may feed the catheter, or a usage error naming the
/// parameter that does not fit.
fn check_geometry(p: &CompliantParams, level: usize) -> Result<(f64, FeedLimit), UsageError> {
    let id = CATHETER_COMPLIANT_VESSEL.info.id;
    if level > MAX_LEVEL {
        return Err(UsageError(format!(
            "scenario `{id}`: mesh_level {level} is past the finest level {MAX_LEVEL}"
        )));
    }
    let (r, t) = (p.lumen_radius, p.wall_thickness);
    if !(p.catheter_radius < 0.9 * r) {
        return Err(UsageError(format!(
            "{id}: catheter_radius {} m does not fit the lumen radius {r} m (needs < 90%)",
            p.catheter_radius
        )));
    }
    if !(p.bend_radius > r + t) {
        return Err(UsageError(format!(
            "{id}: bend_radius {} m must exceed lumen_radius + wall_thickness = {} m",
            p.bend_radius,
            r + t
        )));
    }
    let turn = p.bend_radius * PI / 2.0;
    let length = STRAIGHT_IN + turn + STRAIGHT_OUT;
    if CLAMP_S + p.initial_length >= STRAIGHT_IN {
        return Err(UsageError(format!(
            "{id}: initial_length {} m must end in the {} m straight before the turn (the catheter starts straight)",
            p.initial_length,
            STRAIGHT_IN - CLAMP_S
        )));
    }
    let feed_limit = FeedLimit {
        start: CLAMP_S,
        straight: STRAIGHT_IN - CLAMP_ROOM,
        what: "straight before the turn (less 5 mm of room)",
    };
    feed_limit.check(p.insertion)?;
    if CLAMP_S + p.initial_length + p.insertion > length - 2e-3 {
        return Err(UsageError(format!(
            "{id}: initial_length + insertion = {} m would push the tip out of the {:.4} m vessel",
            p.initial_length + p.insertion,
            length - CLAMP_S
        )));
    }
    Ok((length, feed_limit))
}

/// The vessel wall around `tube` (m) at mesh `level`: a swept tet mesh, its
/// outer surface held, its inner surface the contact surface.
fn wall_tissue(p: &CompliantParams, tube: &SweptTube, length: f64, level: usize) -> TissueBody {
    let (r, t) = (p.lumen_radius, p.wall_thickness);
    let k = 1usize << level;
    let n_s = ((length * CELLS_PER_M).ceil() as usize) * k;
    let wall_mesh = mesh::swept_wall(|s| tube.frame_at(s), length, r, r + t, N_THETA * k, N_R * k, n_s);
    let nr_nodes = N_R * k + 1;
    let material = SolidMaterial {
        youngs_modulus: p.wall_youngs_modulus,
        poisson_ratio: p.wall_poisson_ratio,
        density: p.wall_density,
    };
    let mut tissue = TissueBody::new(wall_mesh.clone(), material);
    tissue.fixed_nodes = (0..wall_mesh.nodes.len())
        .filter(|i| i % nr_nodes == nr_nodes - 1)
        .collect();
    tissue.contact_surface = mesh::boundary_faces(&wall_mesh)
        .into_iter()
        .filter(|f| f.iter().all(|i| i % nr_nodes == 0))
        .collect();
    tissue
}

fn build(p: &CompliantParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = CATHETER_COMPLIANT_VESSEL.info.id;
    let level = inputs.fidelity.mesh_level.unwrap_or(0);
    let (length, feed_limit) = check_geometry(p, level)?;
    let r = p.lumen_radius;
    let tube = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(STRAIGHT_IN)
        .arc(p.bend_radius, PI / 2.0, Vec3::y())
        .line(STRAIGHT_OUT)
        .build_constant(r)
        .map_err(|e| UsageError(format!("{id}: {e}")))?;
    let tissue = wall_tissue(p, &tube, length, level);
    let vertices = tissue.surface_vertices();
    let rest: Arc<dyn Sdf> = Arc::new(tube.clone());
    let wall = wall_samples(&tissue, rest.clone()).map_err(|e| UsageError(format!("{id}: {e}")))?;
    let mut catheter = RodBody::uniform(
        p.initial_length,
        p.catheter_radius,
        p.catheter_youngs_modulus,
        0.4,
        p.catheter_density,
    );
    catheter.base = tube.frame_at(CLAMP_S);
    let t_push = p.insertion / p.insertion_speed;
    let mut scene = Scene::empty(id);
    scene.bodies = vec![catheter.into(), Body::Tissue(tissue)];
    scene.duration = t_push + p.hold_time.max(1e-3);
    scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
    scene.environment.vessel = Some(rest);
    scene.environment.contact = ContactParams {
        friction_static: p.friction,
        friction_dynamic: p.friction,
        margin: p.catheter_radius,
    };
    scene.control = ControlTimeline {
        keys: vec![
            ControlKey::feed(0.0, 0.0, 0.0),
            ControlKey::feed(t_push, p.insertion, 0.0),
        ],
    };
    scene.validate().map_err(UsageError)?;
    // The whole catheter bent to ten radii: far tighter than the vessel allows.
    let ei = p.catheter_youngs_modulus * PI * p.catheter_radius.powi(4) / 4.0;
    let energy = ei * (p.initial_length + p.insertion) / (10.0 * p.catheter_radius).powi(2);
    let reference = Compliant {
        wall: Arc::new(wall),
        vertices,
        tube,
        radius: p.catheter_radius,
    };
    Ok(ScenarioRun::new(scene, reference, energy, length)
        .with_penetration_limit(0.5 * p.catheter_radius)
        .with_feed_limit(feed_limit))
}
