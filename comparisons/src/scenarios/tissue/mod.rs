//! Tissue scenes: block compression, Lamé tube, volume preservation under
//! squash and twist, the Truth Cube phantom, a spherical catheter tip
//! indenting a vessel-wall sector (frictionless contact) and its bonded
//! flat-punch companion, a rigid sphere pressed into a block (Hertz), and
//! the patch test (a homogeneous deformation on the whole boundary of the
//! built-in cube or of a user's mesh); and one dynamic scene, the free
//! vibration of a clamped block (`block-vibration`, its own conventions in
//! its module).
//!
//! Shared conventions of the static scenes (SI units: m, kg, s, N, Pa, rad):
//! * every scene holds exactly one [`TissueBody`], no gravity, and is static:
//!   the loads (driven displacements, pressures) follow the control
//!   timeline's `load` factor, ramped 0 -> 1 over `ramp_time` by
//!   a smooth cosine (`(1 - cos(pi t / T)) / 2`, sampled at 16 keys, so the
//!   loading velocity starts and ends near zero and dynamic models are not
//!   kicked), then held; `Scene::settle` asks for equilibrium (every node
//!   slower than `settle_tol`) no earlier than the end of the ramp, and
//!   `duration` bounds the wait. Quasi-static models settle at the end of
//!   the ramp; the static answer does not depend on the ramp;
//! * the mesh depends on the fidelity knob `mesh_level` (0 = coarsest): the
//!   harness calls [`Scenario::instantiate_at`], which builds the mesh at
//!   `fidelity.mesh_level.unwrap_or(DEFAULT_LEVEL)` and rejects levels above
//!   [`MAX_LEVEL`]; models take the mesh they are given;
//! * the model reports the total reaction on the driven nodes as
//!   `Observation::hand_force`: the force the body exerts on whatever drives
//!   them (N);
//! * every score also carries `inverted_elements` and `volume_change_rel`
//!   (`|V/V0 - 1|`), computed here from the observed node positions and the
//!   scene's tets, not taken from the model's own report.
//!
//! Tubes (`lame-tube`, `wall-indentation`, `wall-punch`) have their axis along z through
//! the origin; blocks occupy `[0, L]^3` with the loaded face at `z = L`.

mod block_compression;
mod block_vibration;
mod curve;
mod lame_tube;
mod patch_test;
mod sphere_indentation;
mod truth_cube;
mod volume_preservation;
mod wall_indentation;
mod wall_punch;

use curve::{Curve, ForceCurve};

pub use block_compression::{BLOCK_COMPRESSION, BlockParams};
pub use block_vibration::{BLOCK_VIBRATION, BlockVibrationParams, vibration_cells};
pub use lame_tube::{LAME_TUBE, LameParams};
pub use patch_test::{PATCH_TEST, PatchParams};
pub use sphere_indentation::{SPHERE_DT, SPHERE_INDENTATION, SphereParams, sphere_block_mesh, sphere_grading};
pub use surgbench_core::mesh::locate;
pub use truth_cube::{CubeFrame, TRUTH_CUBE, TRUTH_CUBE_EDGE, TruthParams};
pub use volume_preservation::{VOLUME_PRESERVATION, VolumeParams, squash_twist};
pub use wall_indentation::{WALL_INDENTATION, WallParams, wall_sphere_cells, wall_sphere_mesh};
pub use wall_punch::{FOOTPRINT_TOL, PunchParams, WALL_PUNCH, wall_cells, wall_clamped, wall_footprint, wall_mesh};

use crate::scenario::{Metrics, ParamSpec, Range, Scenario, Sweep, UsageError};
use std::collections::HashSet;
use std::f64::consts::PI;
use surgbench_core::mesh;
use surgbench_core::{
    Body, ControlKey, ControlTimeline, Fidelity, Observation, Scene, Settle, SolidMaterial, TetMesh, TissueBody,
    TissueObs, Vec3,
};

/// Mesh level used when the fidelity does not set `mesh_level`.
pub const DEFAULT_LEVEL: usize = 1;
/// Finest mesh level: block scenes have `4 * 2^level` cells per edge, so
/// level 3 is 32^3 cells (196,608 tets); level 4 (1.6 M tets) is beyond what
/// a 2-core CI machine or the PBD/FEM models here handle in minutes.
pub const MAX_LEVEL: usize = 3;

/// The sweep of the tissue scenes: mesh levels 0..=[`MAX_LEVEL`].
const LEVELS: Sweep = Sweep::MeshLevels {
    up_to: MAX_LEVEL,
    dt: None,
};

/// The sweep of the sphere-contact scenes: mesh levels 0..=[`MAX_LEVEL`] at
/// [`SPHERE_DT`] (8 quasi-static load steps over the default ramp).
const CONTACT_LEVELS: Sweep = Sweep::MeshLevels {
    up_to: MAX_LEVEL,
    dt: Some(SPHERE_DT),
};
/// Every tissue scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &BLOCK_COMPRESSION,
        &LAME_TUBE,
        &VOLUME_PRESERVATION,
        &TRUTH_CUBE,
        &WALL_INDENTATION,
        &WALL_PUNCH,
        &SPHERE_INDENTATION,
        &PATCH_TEST,
        &BLOCK_VIBRATION,
    ]
}

const DENSITY: ParamSpec = ParamSpec::new(
    "density",
    1000.0,
    "kg/m^3",
    Range::Positive,
    "density (statics: sets only the dynamics of the ramp)",
);
const RAMP: ParamSpec = ParamSpec::new(
    "ramp_time",
    0.25,
    "s",
    Range::Positive,
    "time over which the load factor goes 0 -> 1 (smooth cosine ramp)",
);
const DURATION: ParamSpec = ParamSpec::new(
    "duration",
    1.5,
    "s",
    Range::Positive,
    "longest simulated time to reach equilibrium (> ramp_time)",
);
const SETTLE: ParamSpec = ParamSpec::new(
    "settle_tol",
    1e-5,
    "m/s",
    Range::Positive,
    "static equilibrium when every node is slower than this (after the ramp)",
);

/// Cells per edge of the block meshes at `level`: `4 * 2^level`.
pub fn block_cells(level: usize) -> usize {
    4 << level
}

/// `fidelity.mesh_level` or [`DEFAULT_LEVEL`], rejected past [`MAX_LEVEL`].
pub fn mesh_level(scenario: &str, fidelity: &Fidelity) -> Result<usize, UsageError> {
    let level = fidelity.mesh_level.unwrap_or(DEFAULT_LEVEL);
    if level > MAX_LEVEL {
        return Err(UsageError(format!(
            "scenario `{scenario}`: mesh_level {level} is past the finest level {MAX_LEVEL} ({} cells per block edge there)",
            block_cells(MAX_LEVEL)
        )));
    }
    Ok(level)
}

/// Smooth load ramp `s(t) = (1 - cos(pi t / ramp)) / 2` for `t <= ramp`,
/// then `s = 1`, as a piecewise-linear timeline (16 segments) of the tissue
/// load factor ([`surgbench_core::DeviceCommand::load`]).
pub fn load_ramp(ramp: f64) -> ControlTimeline {
    const N: usize = 16;
    let mut keys: Vec<ControlKey> = (0..=N)
        .map(|k| {
            ControlKey::load(
                ramp * k as f64 / N as f64,
                0.5 * (1.0 - (PI * k as f64 / N as f64).cos()),
            )
        })
        .collect();
    keys[N].load = 1.0;
    ControlTimeline { keys }
}

/// A static scene with one tissue body: no gravity, the load ramp over
/// `ramp` (s), and equilibrium (every node slower than `settle_tol`, m/s)
/// read after the ramp and before `duration` (s).
fn static_scene(name: &str, body: TissueBody, ramp: f64, duration: f64, settle_tol: f64) -> Result<Scene, UsageError> {
    if !(duration > ramp) {
        return Err(UsageError(format!(
            "{name}: duration {duration} s must exceed ramp_time {ramp} s (equilibrium is read after the ramp)"
        )));
    }
    let mut s = Scene::empty(name);
    s.bodies.push(Body::Tissue(body));
    s.control = load_ramp(ramp);
    s.settle = Some(Settle {
        velocity_tol: settle_tol,
        min_time: ramp,
    });
    s.duration = duration;
    Ok(s)
}

/// The first tissue of `obs` if its node count matches `mesh`.
fn tissue_of<'a>(obs: &'a Observation, mesh: &TetMesh) -> Option<&'a TissueObs> {
    obs.tissues.first().filter(|t| t.nodes.len() == mesh.nodes.len())
}

/// Volume statistics of the deformed mesh `x` against the rest mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeStats {
    /// Total deformed volume over rest volume.
    pub ratio: f64,
    /// Largest `|V_e / V_e0 - 1|` over elements.
    pub max_element_change: f64,
    /// Smallest `V_e / V_e0`.
    pub min_element_ratio: f64,
    /// Elements with `V_e / V_e0 <= 0`.
    pub inverted: usize,
}

/// Volumes of the tets of `mesh` at node positions `x` (m) against rest.
pub fn volume_stats(mesh: &TetMesh, x: &[Vec3]) -> VolumeStats {
    let (mut v, mut v0) = (0.0, 0.0);
    let mut s = VolumeStats {
        ratio: 0.0,
        max_element_change: 0.0,
        min_element_ratio: f64::INFINITY,
        inverted: 0,
    };
    for t in &mesh.tets {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        let e0 = mesh::tet_volume(&a, &b, &c, &d);
        let [a, b, c, d] = t.map(|i| x[i]);
        let e = mesh::tet_volume(&a, &b, &c, &d);
        v += e;
        v0 += e0;
        let r = e / e0;
        s.max_element_change = s.max_element_change.max((r - 1.0).abs());
        s.min_element_ratio = s.min_element_ratio.min(r);
        if !(r > 0.0) {
            s.inverted += 1;
        }
    }
    s.ratio = v / v0;
    s
}

/// Metrics every tissue score carries, from the observed nodes.
fn common_metrics(m: &mut Metrics, mesh: &TetMesh, t: &TissueObs) {
    let v = volume_stats(mesh, &t.nodes);
    m.insert("volume_change_rel".into(), (v.ratio - 1.0).abs());
    m.insert("inverted_elements".into(), v.inverted as f64);
}

/// The force scores every indentation scene carries: the model's force `f`
/// against the reference `f_ref` (N).
fn force_metrics(m: &mut Metrics, f: f64, f_ref: f64) {
    m.insert("reaction_force_n".into(), f);
    m.insert("reference_force_n".into(), f_ref);
    m.insert("force_error_rel".into(), (f - f_ref).abs() / f_ref);
    m.insert("force_ratio".into(), f / f_ref);
}

/// The wall-profile scores of the vessel-wall scenes from `(model, reference)`
/// displacement pairs (m) at the probes: `surface_error_rel` (RMS error over
/// RMS reference) and `surface_error_max_rel` (largest error over `depth`);
/// none when every reference displacement is zero.
fn surface_metrics(m: &mut Metrics, pairs: impl IntoIterator<Item = (f64, f64)>, depth: f64) {
    let (mut e2, mut r2, mut emax) = (0.0, 0.0, 0.0f64);
    for (got, want) in pairs {
        let d = got - want;
        e2 += d * d;
        r2 += want * want;
        emax = emax.max(d.abs());
    }
    if r2 > 0.0 {
        m.insert("surface_error_rel".into(), (e2 / r2).sqrt());
        m.insert("surface_error_max_rel".into(), emax / depth);
    }
}

/// Displacement (m) of the observed body at a point located in `mesh` as
/// tet `e` with barycentric weights `w`.
fn probe_displacement(mesh: &TetMesh, t: &TissueObs, e: usize, w: &[f64; 4]) -> Vec3 {
    let tet = mesh.tets[e];
    (0..4).map(|k| (t.nodes[tet[k]] - mesh.nodes[tet[k]]) * w[k]).sum()
}

/// A cube `[0, edge]^3` (m) of `solid`, [`block_cells`]`(level)` cells a
/// side, its base `z = 0` clamped and every top node `x` (`z = edge`)
/// driven by `drive(x)` (m): the loading of the cube scenes.
fn clamped_cube(edge: f64, level: usize, solid: SolidMaterial, drive: impl Fn(&Vec3) -> Vec3) -> TissueBody {
    let n = block_cells(level);
    let mesh = mesh::block(Vec3::new(edge, edge, edge), [n, n, n]);
    let tol = 1e-9 * edge;
    let mut body = TissueBody::new(mesh.clone(), solid);
    body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
    body.driven_nodes = mesh::nodes_on_plane(&mesh, 2, edge, tol)
        .into_iter()
        .map(|i| (i, drive(&mesh.nodes[i])))
        .collect();
    body
}

/// Rollers on symmetry planes: every node of `mesh` not in `fixed` whose
/// `held(x)` holds any axis, with those axes.
fn rollers(mesh: &TetMesh, fixed: &[usize], held: impl Fn(&Vec3) -> [bool; 3]) -> Vec<(usize, [bool; 3])> {
    let fixed: HashSet<usize> = fixed.iter().copied().collect();
    (0..mesh.nodes.len())
        .filter(|i| !fixed.contains(i))
        .map(|i| (i, held(&mesh.nodes[i])))
        .filter(|(_, a)| a.iter().any(|&b| b))
        .collect()
}

/// Where the scene's sphere is at time `t` (m): its path at the control
/// timeline's load factor.
fn indenter_centre(scene: &Scene, t: f64) -> Option<Vec3> {
    let s = scene.control.command_at(t).load;
    scene.tissues().next()?.indenter.map(|i| i.centre_at(s))
}

/// Young's modulus `e` (Pa), density `rho` (kg/m^3), Poisson ratio `nu`.
fn material(e: f64, rho: f64, nu: f64) -> SolidMaterial {
    SolidMaterial {
        youngs_modulus: e,
        poisson_ratio: nu,
        density: rho,
    }
}
