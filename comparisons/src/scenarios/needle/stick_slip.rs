//! `needle-stick-slip`: a stiff needle held still in a free gel block that a
//! slowly ramped pressure on its entry face pulls off the needle. Reference,
//! closed form (the seed's friction model, Chentanez et al. 2009 Sec. 3.3):
//! the coupling holds any load below the threshold `f_perlen d` (the
//! friction bounds of all coupling points together; the tip holds nothing
//! against a retreat), so the hand carries the whole applied load
//! (STATIC); the load cannot exceed it, so the hand never feels more, and
//! once every point slides the hand feels exactly `f_perlen d` (DYNAMIC).
//!
//! The harness has no force-controlled needle base; by Newton's third law a
//! block pulled off a held needle meets the same threshold as a needle
//! pulled by its base out of a held block.

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, Reference, ScenarioInfo, ScenarioRun, Scorer,
};
use surgbench_core::{
    Body, ControlKey, ControlTimeline, Family, NeedleTissue, Observation, Scene, TissueBody, Vec3, mesh,
};

params! {
    /// Parameters of `needle-stick-slip`: the gel, needle and friction of
    /// `needle-straight`; the needle starts `depth` inside the block.
    pub struct StickSlipParams {
        depth: ParamSpec::new("depth", 0.012, "m", Range::Positive, "tip depth below the entry face (the needle starts inserted)"),
        ramp_time: ParamSpec::new("ramp_time", 0.5, "s", Range::Positive, "time for the pull to reach f_perlen * depth; the run ends then"),
        friction_per_length: ParamSpec::new("friction_per_length", 20.0, "N/m", Range::Positive, "Coulomb friction per length of shaft in the tissue"),
        cutting_force: ParamSpec::new("cutting_force", 0.05, "N", Range::NonNegative, "force the tip needs to cut (the block moves away from the tip: unused)"),
        needle_length: P_NEEDLE_LENGTH,
        needle_radius: P_NEEDLE_RADIUS,
        needle_youngs_modulus: P_STEEL_NEEDLE_YOUNGS,
        youngs_modulus: P_GEL_YOUNGS,
        poisson_ratio: P_GEL_POISSON,
        density: P_GEL_DENSITY,
        block_length: P_BLOCK_LENGTH,
        block_width: P_BLOCK_WIDTH,
    }
}

/// Below this fraction of the threshold a step counts as held: far enough
/// from it that the closed form says STATIC whatever the partial slip.
const HELD_BELOW: f64 = 0.8;
/// Steps are scored while the needle is at least this fraction of `depth`
/// inside: past the breakaway the pull grows while the friction shrinks
/// with `d`, and the block runs off the needle (within ~40 ms at the
/// defaults) at a speed no quasi-static closed form describes. Partial
/// slip at the ends of the shaft before the breakaway costs less (7 % of
/// the depth at the defaults).
const SCORED_INSIDE: f64 = 0.8;

/// The closed form and what the scorer needs of the scene.
struct StickSlipRef {
    f_perlen: f64,
    depth: f64,
    /// The mesh node at the entry (rest position on the needle's axis).
    entry: usize,
}

/// Per-run samples of [`StickSlipRef`].
struct StickSlipScorer<'a> {
    r: &'a StickSlipRef,
    scene: &'a Scene,
    pressure_faces: &'a [([usize; 3], f64)],
    /// Per step while [`SCORED_INSIDE`] of the needle is inside: the pull (N), the
    /// hand force along +x (N), the length inside `d` (m).
    samples: Vec<(f64, f64, f64)>,
}

impl StickSlipScorer<'_> {
    /// The pull the pressure applies along +x now (N): the follower load on
    /// the deformed entry face, `-s p A n` summed (`n A` the face's area
    /// vector), as the scene defines it.
    fn applied(&self, obs: &Observation, nodes: &[Vec3]) -> f64 {
        let s = self.scene.control.command_at(obs.time).load;
        self.pressure_faces
            .iter()
            .map(|(f, p)| {
                let [a, b, c] = f.map(|i| nodes[i]);
                -0.5 * s * p * (b - a).cross(&(c - a)).x
            })
            .sum()
    }
}

impl Scorer for StickSlipScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        let (Some(tip), Some(tissue)) = (obs.rods.first().and_then(|r| r.nodes.last()), obs.tissues.first()) else {
            return;
        };
        let Some(entry) = tissue.nodes.get(self.r.entry) else {
            return;
        };
        let d = (tip.x - entry.x).max(0.0);
        if d >= SCORED_INSIDE * self.r.depth {
            let load = self.applied(obs, &tissue.nodes);
            self.samples.push((load, obs.hand_force.x, d));
        }
    }

    /// Held: every step whose pull is below [`HELD_BELOW`] of the threshold
    /// (error over the initial threshold). Threshold: the largest hand force
    /// against `f_perlen d` at that step. Slide: the steps after the peak.
    fn score(&self, _obs: &Observation) -> Metrics {
        let f = self.r.f_perlen;
        let mut m = Metrics::new();
        let held = self
            .samples
            .iter()
            .filter(|(load, _, d)| *load <= HELD_BELOW * f * d)
            .map(|(load, hand, _)| (hand - load).abs() / (f * self.r.depth))
            .fold(0.0, f64::max);
        m.insert("held_error_rel".into(), held);
        let Some((i, &(load, peak, d_peak))) = self.samples.iter().enumerate().max_by(|a, b| a.1.1.total_cmp(&b.1.1))
        else {
            return m;
        };
        m.insert("peak_hand_force_n".into(), peak);
        m.insert("breakaway_pull_n".into(), load);
        m.insert("breakaway_depth_m".into(), d_peak);
        m.insert("threshold_error_rel".into(), (peak - f * d_peak).abs() / (f * d_peak));
        let slide: Vec<f64> = self.samples[i + 1..]
            .iter()
            .map(|(_, hand, d)| (hand - f * d).abs() / (f * d))
            .collect();
        if !slide.is_empty() {
            m.insert("slide_error_rel".into(), slide.iter().copied().fold(0.0, f64::max));
        }
        m
    }
}

impl Reference for StickSlipRef {
    fn scorer<'a>(&'a self, scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        let pressure_faces = scene.tissues().next().map_or(&[][..], |t| &t.pressure_faces[..]);
        Box::new(StickSlipScorer {
            r: self,
            scene,
            pressure_faces,
            samples: Vec::new(),
        })
    }
}

/// A held needle in a gel block pulled off it by a ramped pressure.
pub const NEEDLE_STICK_SLIP: Declared<StickSlipParams> = Declared {
    info: ScenarioInfo {
        id: "needle-stick-slip",
        description: "stiff needle held in a free gel block pulled off it by a ramped pressure: hand force against the stick-slip threshold",
        family: Family::Coupled,
        reference: "closed form: the hand carries the whole pull below f_perlen d (held_error_rel, pull < 0.8 f_perlen d), never more than f_perlen d (threshold_error_rel at the peak), exactly f_perlen d while sliding (slide_error_rel)",
        primary_error: "threshold_error_rel",
        target: crate::scenario::Target::new(0.02, "2 % of the closed-form breakaway force f_perlen d"),
        params: StickSlipParams::SPECS,
        sweep: LEVELS,
        quick: 1,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &StickSlipParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = NEEDLE_STICK_SLIP.info.id;
    let level = mesh_level(id, inputs.fidelity)?;
    if p.depth >= p.needle_length || p.depth >= p.block_length {
        return Err(UsageError(format!(
            "{id}: depth {} m must be less than needle_length {} m and block_length {} m",
            p.depth, p.needle_length, p.block_length
        )));
    }
    let gel = [p.youngs_modulus, p.poisson_ratio, p.density];
    let block = GelBlock::new(id, level, p.block_length, p.block_width, gel)?;
    // The threshold at the initial depth is reached at load 1.
    let f0 = p.friction_per_length * p.depth;
    let pressure = f0 / (p.block_width * p.block_width);
    let mut tissue = TissueBody::new(block.mesh.clone(), block.material);
    tissue.pressure_faces = mesh::boundary_faces(&block.mesh)
        .into_iter()
        .filter(|f| f.iter().all(|&i| block.mesh.nodes[i].x.abs() < block.tol))
        .map(|f| (f, pressure))
        .collect();
    let needle = needle(p.needle_length, p.needle_radius, p.needle_youngs_modulus, p.depth);
    let mut scene = Scene::empty(id);
    scene.bodies = vec![needle.into(), Body::Tissue(tissue)];
    scene.duration = p.ramp_time;
    scene.control = ControlTimeline {
        keys: vec![ControlKey::load(0.0, 0.0), ControlKey::load(p.ramp_time, 1.0)],
    };
    scene.needle = Some(NeedleTissue {
        friction_per_length: p.friction_per_length,
        cutting_force: p.cutting_force,
        viscous_friction: 0.0,
        bevel_angle: 0.0,
    });
    let reference = StickSlipRef {
        f_perlen: p.friction_per_length,
        depth: p.depth,
        entry: block.entry,
    };
    // The pull's work over the block's length and the depth, ten times over:
    // the block slides off the needle after the breakaway.
    let energy = 10.0 * f0 * (p.block_length + p.depth);
    Ok(ScenarioRun::new(
        scene,
        reference,
        energy,
        p.needle_length + p.block_length,
    ))
}
