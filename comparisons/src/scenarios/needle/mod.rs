//! Needle insertion (the needle seed: Chentanez et al., SIGGRAPH 2009).
//!
//! Shared conventions (SI units): the needle enters along +x through the
//! tissue face at `x = 0`; its tip starts `tip_gap` outside it (or, where a
//! scene says so, `depth` inside it) and its base (the guide sleeve) never
//! reaches the tissue. A gel block occupies `[0, block_length] x
//! [-w/2, w/2]^2` (`w = block_width`), held at its far face
//! `x = block_length` unless a scene says otherwise; its mesh has
//! `8 * 2^level x 4 * 2^level x 4 * 2^level` cells (six tets each, the
//! split mirrored cell to cell: `mesh::block_mirrored`), so a mesh node sits
//! on the needle's axis at the entry and the mesh is mirror-symmetric about
//! it (on the plain block a symmetric tip drifted sideways along the split
//! diagonal). The model reports `Observation::hand_force` as the
//! force the needle exerts on the hand: the hand pushes with its negative.

mod cycles;
mod prostate;
mod steering;
mod stick_slip;
mod straight;

pub use cycles::{CyclesParams, NEEDLE_CYCLES};
pub use prostate::{PROSTATE_LAYERS, ProstateParams};
pub use steering::{BevelParams, DoubleBendParams, NEEDLE_BEVEL, NEEDLE_DOUBLE_BEND};
pub use stick_slip::{NEEDLE_STICK_SLIP, StickSlipParams};
pub use straight::{NEEDLE_STRAIGHT, StraightParams};

use crate::scenario::{ParamSpec, Range, Scenario, Sweep, UsageError};
use surgbench_core::{
    Body, ControlKey, ControlTimeline, Fidelity, Iso3, NeedleTissue, RodBody, Scene, SolidMaterial, TetMesh,
    TissueBody, Vec3, mesh,
};

// Parameters every needle scene shares (SI units).

/// Coulomb friction per length of shaft (N/m): an illustrative value of these scenes, not a measurement.
const P_FRICTION_PER_LENGTH: ParamSpec = ParamSpec::new(
    "friction_per_length",
    20.0,
    "N/m",
    Range::NonNegative,
    "Coulomb friction per length of shaft in the tissue",
);

/// Force the tip needs to cut (N): illustrative, as the friction.
const P_CUTTING_FORCE: ParamSpec = ParamSpec::new(
    "cutting_force",
    0.05,
    "N",
    Range::NonNegative,
    "force the tip needs to cut",
);

/// Needle length out of the guide sleeve (m).
const P_NEEDLE_LENGTH: ParamSpec = ParamSpec::new(
    "needle_length",
    0.04,
    "m",
    Range::Positive,
    "needle length out of the guide sleeve",
);

/// Needle radius (m): 0.83 mm diameter, the seed's phantom needle.
const P_NEEDLE_RADIUS: ParamSpec = ParamSpec::new("needle_radius", 0.415e-3, "m", Range::Positive, "needle radius");

/// Gel Young's modulus (Pa): 10 wt% gelatin as issue 17 states it.
const P_GEL_YOUNGS: ParamSpec = ParamSpec::new("youngs_modulus", 14.8e3, "Pa", Range::Positive, "gel Young's modulus");

/// Gel Poisson ratio: 10 wt% gelatin as issue 17 states it.
const P_GEL_POISSON: ParamSpec =
    ParamSpec::new("poisson_ratio", 0.475, "1", Range::Open(-1.0, 0.5), "gel Poisson ratio");

/// Gel density (kg/m^3): that of water.
const P_GEL_DENSITY: ParamSpec = ParamSpec::new("density", 1000.0, "kg/m^3", Range::Positive, "gel density");

/// Block length along the needle (m).
const P_BLOCK_LENGTH: ParamSpec = ParamSpec::new(
    "block_length",
    0.02,
    "m",
    Range::Positive,
    "block length along the needle",
);

/// Block width and height (m).
const P_BLOCK_WIDTH: ParamSpec = ParamSpec::new("block_width", 0.01, "m", Range::Positive, "block width and height");

/// Young's modulus of a stiff (stainless steel) needle (Pa).
const P_STEEL_NEEDLE_YOUNGS: ParamSpec = ParamSpec::new(
    "needle_youngs_modulus",
    200e9,
    "Pa",
    Range::Positive,
    "needle Young's modulus",
);

/// Every needle scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &NEEDLE_STRAIGHT,
        &NEEDLE_STICK_SLIP,
        &NEEDLE_CYCLES,
        &NEEDLE_BEVEL,
        &NEEDLE_DOUBLE_BEND,
        &PROSTATE_LAYERS,
    ]
}

/// Finest mesh level: level 1 is 16 x 8 x 8 cells (6,144 tets); level 2
/// (49,152 tets) costs minutes per run with one tissue solve per coupling
/// point and axis per step.
pub const MAX_LEVEL: usize = 1;

/// The sweep of the needle scenes: mesh levels 0..=[`MAX_LEVEL`].
const LEVELS: Sweep = Sweep::MeshLevels {
    up_to: MAX_LEVEL,
    dt: None,
};

/// `fidelity.mesh_level` (default 0), rejected past [`MAX_LEVEL`].
fn mesh_level(scenario: &str, fidelity: &Fidelity) -> Result<usize, UsageError> {
    mesh_level_up_to(scenario, fidelity, MAX_LEVEL)
}

/// `fidelity.mesh_level` (default 0), rejected past `finest`.
fn mesh_level_up_to(scenario: &str, fidelity: &Fidelity, finest: usize) -> Result<usize, UsageError> {
    let level = fidelity.mesh_level.unwrap_or(0);
    if level > finest {
        return Err(UsageError(format!(
            "scenario `{scenario}`: mesh_level {level} is past the finest level {finest}"
        )));
    }
    Ok(level)
}

/// The gel block of the needle scenes at mesh `level` (module docs): its
/// mesh, the node at the entry on the needle's axis, and the gel.
struct GelBlock {
    mesh: TetMesh,
    entry: usize,
    material: SolidMaterial,
    /// Node tolerance (m) for planes of the block.
    tol: f64,
}

impl GelBlock {
    /// `length` along the needle, `width` across (m); the gel's Young's
    /// modulus (Pa), Poisson ratio and density (kg/m^3).
    fn new(scenario: &str, level: usize, length: f64, width: f64, gel: [f64; 3]) -> Result<Self, UsageError> {
        let k = 1usize << level;
        let mut mesh = mesh::block_mirrored(Vec3::new(length, width, width), [8 * k, 4 * k, 4 * k]);
        for x in &mut mesh.nodes {
            x.y -= 0.5 * width;
            x.z -= 0.5 * width;
        }
        let tol = 1e-9 * length;
        let entry = entry_node(scenario, &mesh, tol)?;
        let [youngs_modulus, poisson_ratio, density] = gel;
        let material = SolidMaterial {
            youngs_modulus,
            poisson_ratio,
            density,
        };
        Ok(Self {
            mesh,
            entry,
            material,
            tol,
        })
    }
}

/// The force a needle scene plots for the step it observed last: its time
/// (s), the hand's push (N) and the reference there (N); empty at steps
/// where the reference does not hold.
#[derive(Debug, Clone, Copy, Default)]
struct StepForce(Option<(f64, f64, f64)>);

impl StepForce {
    /// Record `(push, reference)` at time `t`.
    fn set(&mut self, t: f64, push: f64, reference: f64) {
        self.0 = Some((t, push, reference));
    }
    /// `(push, reference)` if it was recorded at time `t` (the report asks
    /// after the step it was recorded at, never later).
    fn at(&self, t: f64) -> Option<(f64, f64)> {
        self.0
            .filter(|(at, _, _)| *at == t)
            .map(|(_, push, reference)| (push, reference))
    }
}

/// The mesh node at the entry on the needle's axis (the origin, within
/// `tol` m).
fn entry_node(scenario: &str, mesh: &TetMesh, tol: f64) -> Result<usize, UsageError> {
    (0..mesh.nodes.len())
        .find(|&i| mesh.nodes[i].norm() < tol)
        .ok_or_else(|| UsageError(format!("{scenario}: no mesh node on the needle axis at the entry")))
}

/// The gel block of [`GelBlock::new`] held at its far face
/// `x = length` (m), and the tissue body of it.
fn held_block(
    scenario: &str,
    level: usize,
    length: f64,
    width: f64,
    gel: [f64; 3],
) -> Result<(GelBlock, TissueBody), UsageError> {
    let block = GelBlock::new(scenario, level, length, width, gel)?;
    let mut tissue = TissueBody::new(block.mesh.clone(), block.material);
    tissue.fixed_nodes = mesh::nodes_on_plane(&block.mesh, 0, length, block.tol);
    Ok((block, tissue))
}

/// The scene `id`: `needle` fed by the base positions `feed` (`(t, x)`,
/// s and m along +x) into `tissue` for `duration` (s), the two meeting
/// through `interaction`.
fn needle_scene(
    id: &str,
    needle: RodBody,
    tissue: TissueBody,
    feed: &[(f64, f64)],
    duration: f64,
    interaction: NeedleTissue,
) -> Scene {
    let mut scene = Scene::empty(id);
    scene.bodies = vec![needle.into(), Body::Tissue(tissue)];
    scene.duration = duration;
    scene.control = ControlTimeline {
        keys: feed.iter().map(|&(t, x)| ControlKey::feed(t, x, 0.0)).collect(),
    };
    scene.needle = Some(interaction);
    scene
}

/// A steel needle (Poisson ratio 0.3, 7,850 kg/m^3) of `length` and
/// `radius` (m), Young's modulus `youngs` (Pa), along +x with its tip at
/// `x = tip_x` (m; negative: outside the entry face) and its base (the
/// guide sleeve) `length` behind it.
fn needle(length: f64, radius: f64, youngs: f64, tip_x: f64) -> RodBody {
    let mut rod = RodBody::uniform(length, radius, youngs, 0.3, 7850.0);
    rod.base = Iso3::translation(tip_x - length, 0.0, 0.0);
    rod
}
