//! `prostate-layers`: a stiff symmetric-tip needle driven at constant speed
//! through a layered block to a target at the centre of a stiffer
//! inclusion: a 1 mm skin, soft tissue, and a prostate-like inclusion
//! wrapped in a 0.5 mm capsule (the seed's prostate scene, Chentanez et al.
//! 2009 Sec. 6, at its size: 13,375 tets there, 12,960 here at mesh
//! level 1). Skin and capsule take a larger cutting force than the tissue
//! around them (the seed's per-layer `f_cut`), so the tip tents each one
//! until the force reaches that bound, then punctures it: a spike in the
//! base force.
//!
//! Reference (closed form, as `needle-straight`): at each puncture the
//! base force peaks at the membrane's bound with every coupling point
//! sliding, `f_cut(membrane) + (f_perlen + eta v) d`, `d` the needle length
//! inside the tissue at that step. The scorer finds the membrane the tip is
//! cutting by locating the tip in the deformed mesh and reading its rest
//! position. Also reported, without a reference: how far the tip had
//! pushed each membrane when it gave way (tenting), and how far in the
//! tissue's own coordinates the tip stops from the target (the gland moves
//! away from the needle, the seed's point about brachytherapy).

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, Range, Reference, ScenarioInfo, ScenarioRun, Scorer,
};
use surgbench_core::mesh::locate_in;
use surgbench_core::{Family, NeedleTissue, Observation, Scene, TissueRegion};

params! {
    /// Parameters of `prostate-layers`. Every material value and cutting
    /// force is illustrative, not a measurement: skin and capsule stiffer
    /// and harder to cut than the tissue around them, the gland stiffer
    /// than the soft tissue (as the seed's scene orders them); soft tissue
    /// as the gel of the other needle scenes.
    pub struct ProstateParams {
        insertion_speed: ParamSpec::new("insertion_speed", 0.01, "m/s", Range::Positive, "speed of the base while inserting"),
        tip_gap: ParamSpec::new("tip_gap", 0.001, "m", Range::Any, "tip distance outside the skin at t = 0 (negative: the needle starts that deep, pre-inserted; the benchmarks' mid-insertion frames)"),
        friction_per_length: P_FRICTION_PER_LENGTH,
        cutting_force: P_CUTTING_FORCE,
        skin_cutting_force: ParamSpec::new("skin_cutting_force", 0.3, "N", Range::NonNegative, "force the tip needs to cut the skin"),
        capsule_cutting_force: ParamSpec::new("capsule_cutting_force", 0.3, "N", Range::NonNegative, "force the tip needs to cut the capsule"),
        viscous_friction: ParamSpec::new("viscous_friction", 0.0, "N s/m^2", Range::NonNegative, "viscous shaft friction per length"),
        needle_length: ParamSpec::new("needle_length", 0.05, "m", Range::Positive, "needle length out of the guide sleeve"),
        needle_radius: P_NEEDLE_RADIUS,
        needle_youngs_modulus: P_STEEL_NEEDLE_YOUNGS,
        youngs_modulus: P_GEL_YOUNGS,
        poisson_ratio: P_GEL_POISSON,
        density: P_GEL_DENSITY,
        skin_youngs_modulus: ParamSpec::new("skin_youngs_modulus", 100e3, "Pa", Range::Positive, "skin Young's modulus"),
        capsule_youngs_modulus: ParamSpec::new("capsule_youngs_modulus", 100e3, "Pa", Range::Positive, "capsule Young's modulus"),
        prostate_youngs_modulus: ParamSpec::new("prostate_youngs_modulus", 60e3, "Pa", Range::Positive, "gland (inclusion) Young's modulus"),
        skin_thickness: ParamSpec::new("skin_thickness", 1e-3, "m", Range::Positive, "skin thickness"),
        capsule_thickness: ParamSpec::new("capsule_thickness", 0.5e-3, "m", Range::Positive, "capsule thickness"),
        prostate_size: ParamSpec::new("prostate_size", 0.02, "m", Range::Positive, "edge of the cubic gland inside its capsule"),
        prostate_depth: ParamSpec::new("prostate_depth", 0.035, "m", Range::Positive, "depth of the gland's centre (the target) below the skin"),
        block_length: ParamSpec::new("block_length", 0.06, "m", Range::Positive, "block length along the needle"),
        block_width: ParamSpec::new("block_width", 0.05, "m", Range::Positive, "block width and height"),
    }
}

/// The finest mesh level: level 1 is the seed's size.
const PROSTATE_LEVELS: Sweep = Sweep::MeshLevels { up_to: 1, dt: None };

/// How far (m, rest coordinates) past a membrane's faces the tip still
/// counts as cutting it: the channel end sticks on the face while the tip
/// tents the membrane, a little in front of it or behind it.
const FACE_SLACK: f64 = 1e-4;

/// Where the layers are (rest coordinates, m; the needle runs along +x on
/// the block's axis `y = z = 0`).
#[derive(Clone, Copy)]
struct Layers {
    skin: f64,
    /// The capsule's outer box (`x` from, to; half-width across) and its
    /// thickness.
    capsule_x: [f64; 2],
    capsule_half: f64,
    capsule: f64,
}

impl Layers {
    /// The layer holding the rest point `p`, the membranes widened by
    /// `slack` on both faces: 0 skin, 1 capsule, 2 gland, `None` the soft
    /// tissue around them.
    fn layer_at(&self, p: &Vec3, slack: f64) -> Option<usize> {
        if p.x <= self.skin + slack {
            return Some(0);
        }
        let (lo, hi) = (self.capsule_x[0], self.capsule_x[1]);
        let h = self.capsule_half;
        let inside_outer = p.x >= lo - slack && p.x <= hi + slack && p.y.abs() <= h + slack && p.z.abs() <= h + slack;
        let c = self.capsule;
        let inside_inner =
            p.x > lo + c + slack && p.x < hi - c - slack && p.y.abs() < h - c - slack && p.z.abs() < h - c - slack;
        match (inside_outer, inside_inner) {
            (_, true) => Some(2),
            (true, false) => Some(1),
            (false, false) => None,
        }
    }

    /// [`Layers::layer_at`] for the membranes only: 0 skin, 1 capsule.
    fn membrane_at(&self, p: &Vec3, slack: f64) -> Option<usize> {
        self.layer_at(p, slack).filter(|&k| k < 2)
    }
}

/// The closed forms and where to look.
struct ProstateRef {
    layers: Layers,
    /// `f_cut` of skin and capsule (N).
    membrane_cut: [f64; 2],
    /// `f_cut` elsewhere (N).
    cut: f64,
    /// Coulomb plus viscous friction per length while sliding at `v` (N/m).
    friction: f64,
    entry: usize,
    /// The target (rest coordinates, m).
    target: Vec3,
    t_end: f64,
}

/// Per-run sums of [`ProstateRef`].
struct ProstateScorer<'a> {
    r: &'a ProstateRef,
    /// The scene's tets (a remeshing model appends nodes and splits tets
    /// it does not report: its original tets over the current positions
    /// of the original nodes stand in for its mesh, up to the splits'
    /// midside offsets).
    tets: &'a [[usize; 4]],
    /// Per membrane: the largest push (N), the closed form at that step
    /// (N) and the tip's x then (m, world).
    peak: [Option<(f64, f64, f64)>; 2],
    /// The tip's rest position at the last step (m), if inside the tissue.
    tip_rest: Option<Vec3>,
    /// The last step's time (s), push (N) and the bound of the tissue the
    /// tip cuts, `f_cut + (f_perlen + eta v) d` (N).
    last_point: StepForce,
}

impl ProstateScorer<'_> {
    /// The rest position of the tissue at the deformed point `x`, if `x`
    /// is inside the deformed mesh or within 1e-3 of a tet's size of it (a
    /// tip tenting the skin sits on the surface up to the coupling's
    /// tolerance).
    fn rest_of(&self, obs: &Observation, x: &Vec3) -> Option<Vec3> {
        let t = obs.tissues.first()?;
        let (e, w) = locate_in(&t.nodes, self.tets, x)?;
        if w.iter().any(|&v| v < -1e-3) {
            return None;
        }
        Some((0..4).map(|a| t.rest[self.tets[e][a]] * w[a]).sum())
    }
}

impl Scorer for ProstateScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        let (Some(tip), Some(entry)) = (
            obs.rods.first().and_then(|r| r.nodes.last()).copied(),
            obs.tissues.first().and_then(|t| t.nodes.get(self.r.entry)).copied(),
        ) else {
            return;
        };
        self.tip_rest = self.rest_of(obs, &tip);
        self.last_point = StepForce::default();
        let Some(rest) = self.tip_rest else { return };
        let push = -obs.hand_force.x;
        let d = (tip.x - entry.x).max(0.0);
        let membrane = self.r.layers.membrane_at(&rest, FACE_SLACK);
        let cut = membrane.map_or(self.r.cut, |k| self.r.membrane_cut[k]);
        let bound = cut + self.r.friction * d;
        self.last_point.set(obs.time, push, bound);
        if let Some(k) = membrane
            && self.peak[k].is_none_or(|(p, _, _)| push > p)
        {
            self.peak[k] = Some((push, bound, tip.x));
        }
    }

    /// The push against the bound of the tissue the tip cuts, at every step
    /// with the tip in the tissue: the push reaches it while every point
    /// slides and stays under it while the tip tents a membrane (the
    /// report's force-over-time plot shows the spikes against it).
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        self.last_point.at(obs.time)
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        m.insert("push_force_n".into(), -obs.hand_force.x);
        let mut worst: Option<f64> = None;
        let front = [0.0, self.r.layers.capsule_x[0]];
        for (k, name) in ["skin", "capsule"].iter().enumerate() {
            if let Some((push, closed, x)) = self.peak[k] {
                let e = (push - closed).abs() / closed;
                m.insert(format!("{name}_puncture_force_n"), push);
                m.insert(format!("{name}_puncture_closed_form_n"), closed);
                m.insert(format!("{name}_puncture_error_rel"), e);
                m.insert(format!("{name}_tenting_m"), x - front[k]);
                worst = Some(worst.map_or(e, |w: f64| w.max(e)));
            }
        }
        // Both membranes punctured, or no error: a run that stopped short
        // has not shown the scene.
        if let (Some(w), true) = (worst, self.peak.iter().all(Option::is_some)) {
            m.insert("puncture_force_error_rel".into(), w);
        }
        if obs.time >= self.r.t_end - 1e-9
            && let Some(rest) = self.tip_rest
        {
            m.insert("target_miss_m".into(), (rest - self.r.target).norm());
            m.insert("target_miss_x_m".into(), rest.x - self.r.target.x);
        }
        m
    }
}

impl Reference for ProstateRef {
    fn scorer<'a>(&'a self, scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        let tets = scene.tissues().next().map_or(&[][..], |t| &t.mesh.tets[..]);
        Box::new(ProstateScorer {
            r: self,
            tets,
            peak: [None, None],
            tip_rest: None,
            last_point: StepForce::default(),
        })
    }
}

/// Needle through skin and capsule into a layered block, puncture spikes.
pub const PROSTATE_LAYERS: Declared<ProstateParams> = Declared {
    info: ScenarioInfo {
        id: "prostate-layers",
        description: "stiff needle through a 1 mm skin and a 0.5 mm capsule into a stiffer gland (the seed's prostate scene at its size, 12,960 tets at level 1): puncture spikes in the base force",
        family: Family::Coupled,
        reference: "closed form at each puncture: the base force peaks at f_cut(membrane) + (f_perlen + eta v) d with every point sliding (worst relative error over skin and capsule; the tip's membrane found by locating it in the deformed mesh)",
        primary_error: "puncture_force_error_rel",
        target: crate::scenario::Target::new(0.02, "2 % of the closed-form base force, as needle-straight (issue 17)"),
        params: ProstateParams::SPECS,
        sweep: PROSTATE_LEVELS,
        quick: 1,
        mesh: None,
    },
    datasets: None,
    build,
};

/// Grid planes from `a` to `b` (m) in `n` equal cells, without `a`.
fn cells(a: f64, b: f64, n: usize) -> impl Iterator<Item = f64> {
    (1..=n).map(move |i| if i == n { b } else { a + (b - a) * i as f64 / n as f64 })
}

/// The layered block at mesh `level`: grid planes on every layer face
/// (module docs), cells per layer along x (skin 1, soft tissue `2k`,
/// capsule 1, gland `3k`, capsule 1, soft tissue `k`, `k = 2^level`) and
/// per side across (soft tissue `k`, capsule 1, half gland `k + 1`: an
/// even count, so that the axis is a grid line of even index and the mesh
/// mirror-symmetric about it).
fn layered_mesh(p: &ProstateParams, level: usize, l: &Layers) -> Result<TetMesh, UsageError> {
    let k = 1usize << level;
    let [c0, c1] = l.capsule_x;
    let mut x = vec![0.0];
    x.extend(cells(0.0, l.skin, 1));
    x.extend(cells(l.skin, c0, 2 * k));
    x.extend(cells(c0, c0 + l.capsule, 1));
    x.extend(cells(c0 + l.capsule, c1 - l.capsule, 3 * k));
    x.extend(cells(c1 - l.capsule, c1, 1));
    x.extend(cells(c1, p.block_length, k));
    let h = l.capsule_half;
    let mut side = vec![0.0];
    side.extend(cells(0.0, h - l.capsule, k + 1));
    side.extend(cells(h - l.capsule, h, 1));
    side.extend(cells(h, 0.5 * p.block_width, k));
    let mut y: Vec<f64> = side.iter().rev().map(|v| -v).collect();
    y.extend(&side[1..]);
    mesh::graded_block(&x, &y, &y).map_err(|e| UsageError(format!("prostate-layers: {e}")))
}

fn build(p: &ProstateParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = PROSTATE_LAYERS.info.id;
    let level = mesh_level_up_to(id, inputs.fidelity, 1)?;
    let half = 0.5 * p.prostate_size;
    let layers = Layers {
        skin: p.skin_thickness,
        capsule_x: [
            p.prostate_depth - half - p.capsule_thickness,
            p.prostate_depth + half + p.capsule_thickness,
        ],
        capsule_half: half + p.capsule_thickness,
        capsule: p.capsule_thickness,
    };
    if !(layers.skin < layers.capsule_x[0]
        && layers.capsule_x[1] < p.block_length
        && layers.capsule_half < 0.5 * p.block_width)
    {
        return Err(UsageError(format!(
            "{id}: the capsule ({} to {} m deep, {} m across) must lie below the skin ({} m) and inside the block ({} x {} m)",
            layers.capsule_x[0],
            layers.capsule_x[1],
            2.0 * layers.capsule_half,
            layers.skin,
            p.block_length,
            p.block_width
        )));
    }
    if p.tip_gap + p.prostate_depth <= 0.0 {
        return Err(UsageError(format!(
            "{id}: a needle pre-inserted {} m deep (tip_gap {} m) starts past the target, {} m deep",
            -p.tip_gap, p.tip_gap, p.prostate_depth
        )));
    }
    if p.tip_gap + p.prostate_depth >= p.needle_length {
        return Err(UsageError(format!(
            "{id}: needle_length {} m must exceed tip_gap + prostate_depth = {} m (the guide sleeve stays out of the tissue)",
            p.needle_length,
            p.tip_gap + p.prostate_depth
        )));
    }
    let mesh = layered_mesh(p, level, &layers)?;
    let tol = 1e-9 * p.block_length;
    let entry = entry_node(id, &mesh, tol)?;
    let soft = SolidMaterial {
        youngs_modulus: p.youngs_modulus,
        poisson_ratio: p.poisson_ratio,
        density: p.density,
    };
    let with_e = |e: f64| SolidMaterial {
        youngs_modulus: e,
        ..soft
    };
    // Each tet to its layer by its centroid: the grid planes follow the
    // layer faces, so no tet straddles one.
    let mut of_layer = [Vec::new(), Vec::new(), Vec::new()];
    for (e, t) in mesh.tets.iter().enumerate() {
        let c = t.iter().map(|&i| mesh.nodes[i]).sum::<Vec3>() / 4.0;
        if let Some(k) = layers.layer_at(&c, 0.0) {
            of_layer[k].push(e);
        }
    }
    let [skin, capsule, gland] = of_layer;
    let mut tissue = TissueBody::new(mesh, soft);
    tissue.fixed_nodes = mesh::nodes_on_plane(&tissue.mesh, 0, p.block_length, tol);
    tissue.regions = vec![
        TissueRegion {
            name: "skin".into(),
            material: with_e(p.skin_youngs_modulus),
            tets: skin,
            cutting_force: Some(p.skin_cutting_force),
        },
        TissueRegion {
            name: "capsule".into(),
            material: with_e(p.capsule_youngs_modulus),
            tets: capsule,
            cutting_force: Some(p.capsule_cutting_force),
        },
        TissueRegion {
            name: "prostate".into(),
            material: with_e(p.prostate_youngs_modulus),
            tets: gland,
            cutting_force: None,
        },
    ];
    let needle = needle(p.needle_length, p.needle_radius, p.needle_youngs_modulus, -p.tip_gap);
    let v = p.insertion_speed;
    let x_in = p.tip_gap + p.prostate_depth;
    let t_end = x_in / v;
    let interaction = NeedleTissue {
        friction_per_length: p.friction_per_length,
        cutting_force: p.cutting_force,
        viscous_friction: p.viscous_friction,
        bevel_angle: 0.0,
    };
    let scene = needle_scene(id, needle, tissue, &[(0.0, 0.0), (t_end, x_in)], t_end, interaction);
    let friction = p.friction_per_length + p.viscous_friction * v;
    let biggest_cut = p.cutting_force.max(p.skin_cutting_force).max(p.capsule_cutting_force);
    // Work of the largest push over the whole stroke, ten times over.
    let energy = 10.0 * (biggest_cut + friction * p.prostate_depth) * x_in + 1e-9;
    let reference = ProstateRef {
        layers,
        membrane_cut: [p.skin_cutting_force, p.capsule_cutting_force],
        cut: p.cutting_force,
        friction,
        entry,
        target: Vec3::new(p.prostate_depth, 0.0, 0.0),
        t_end,
    };
    Ok(ScenarioRun::new(
        scene,
        reference,
        energy,
        p.needle_length + p.block_length,
    ))
}
