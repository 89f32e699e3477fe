//! `wall-punch`: a flat-ended punch bonded to a vessel-wall sector;
//! force and wall displacement against the scikit-fem reference.

use super::wall_indentation::{WALL_DENSITY, WALL_E};
use super::*;
use crate::params;
use crate::references::PunchReference;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Observation, Scene, TetMesh, TissueBody, Vec3};

/// Relative tolerance of the footprint rule `y^2 + (z - L/2)^2 <= r_p^2 (1 +
/// tol)`: inclusive, so nodes exactly on the punch rim count on every level
/// (the scikit-fem script applies the same rule to its DOFs).
pub const FOOTPRINT_TOL: f64 = 1e-6;

/// Cells `(n_theta, n_r, n_z)` of the wall mesh at `level`: `2^level`
/// through the wall and as many cells of that size as fit (rounded) around
/// the inner arc and along the segment, so each level has 8x the tets of
/// the one before.
pub fn wall_cells(r: &PunchReference, level: usize) -> (usize, usize, usize) {
    let t = r.outer_radius - r.inner_radius;
    let around = ((r.inner_radius * r.sector_angle / t).round() as usize).max(1);
    let along = ((r.length / t).round() as usize).max(1);
    (around << level, 1 << level, along << level)
}

/// The wall mesh at `level`: [`mesh::tube_sector`] turned about z by
/// `-angle/2`, so the sector spans `-angle/2 <= theta <= angle/2` and the
/// punch sits on the `+x` axis.
pub fn wall_mesh(r: &PunchReference, level: usize) -> TetMesh {
    let (n_t, n_r, n_z) = wall_cells(r, level);
    let m = mesh::tube_sector(r.inner_radius, r.outer_radius, r.length, r.sector_angle, n_t, n_r, n_z);
    let rot = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), -0.5 * r.sector_angle);
    TetMesh {
        nodes: m.nodes.iter().map(|x| rot * x).collect(),
        tets: m.tets,
    }
}

/// Inner-wall nodes of `mesh` inside the punch footprint:
/// `y^2 + (z - length/2)^2 <= r_p^2 (1 + FOOTPRINT_TOL)`, ascending.
pub fn wall_footprint(r: &PunchReference, mesh: &TetMesh) -> Vec<usize> {
    let zc = 0.5 * r.length;
    let rp2 = r.punch_radius * r.punch_radius * (1.0 + FOOTPRINT_TOL);
    mesh::nodes_on_cylinder(mesh, r.inner_radius, 1e-9 * r.outer_radius)
        .into_iter()
        .filter(|&i| {
            let x = mesh.nodes[i];
            x.y * x.y + (x.z - zc) * (x.z - zc) <= rp2
        })
        .collect()
}

/// Clamped nodes of the wall: both ends (`z = 0, length`) and both straight
/// edges (`|theta| = angle/2`), ascending.
pub fn wall_clamped(r: &PunchReference, mesh: &TetMesh) -> Vec<usize> {
    let tol = 1e-9 * r.outer_radius;
    let half = 0.5 * r.sector_angle - 1e-9;
    mesh::nodes_where(mesh, |x| {
        x.z.abs() <= tol || (x.z - r.length).abs() <= tol || x.y.atan2(x.x).abs() >= half
    })
}

params! {
    /// Parameters of `wall-punch`.
    ///
    /// Geometry, `E`'s reference value and `nu` come from the reference; the
    /// depth is bounded by the reference's curve (20 % of the wall thickness).
    pub struct PunchParams {
        depth: ParamSpec::new(
            "depth",
            5e-5,
            "m",
            Range::Positive,
            "punch displacement into the wall at the end of the ramp, <= 2e-4 (20 % of the 1 mm wall, the reference's range)",
        ),
        youngs_modulus: WALL_E,
        density: WALL_DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: ParamSpec::new(
            "settle_tol",
            2e-6,
            "m/s",
            Range::Positive,
            "static equilibrium when every node is slower than this (after the ramp; ~1 % of the ramp's mean speed at the default depth)",
        ),
    }
}

struct PunchRun {
    mesh: TetMesh,
    depth: f64,
    force_ref: f64,
    /// `(containing tet, weights, reference u_r)` of each profile probe (m).
    probes: Vec<(usize, [f64; 4], f64)>,
}

impl PunchRun {
    /// Indentation force (N): the body pushes the punch back along `-x`.
    fn force(obs: &Observation) -> f64 {
        -obs.hand_force.x
    }
}

impl ForceCurve for PunchRun {
    fn full_depth(&self) -> f64 {
        self.depth
    }
    fn metrics(&self, _: &Scene, obs: &Observation) -> Option<Metrics> {
        let mut m = Metrics::new();
        let t = tissue_of(obs, &self.mesh)?;
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        m.insert("stiffness_n_per_m".into(), f / self.depth);
        m.insert("lateral_force_rel".into(), obs.hand_force.yz().norm() / self.force_ref);
        // On theta = 0 the radial direction is +x.
        let radial = self
            .probes
            .iter()
            .map(|(e, w, want)| (probe_displacement(&self.mesh, t, *e, w).x, *want));
        surface_metrics(&mut m, radial, self.depth);
        common_metrics(&mut m, &self.mesh, t);
        Some(m)
    }
    fn curve_point(&self, scene: &Scene, obs: &Observation) -> Option<(f64, f64)> {
        let s = scene.control.command_at(obs.time).load;
        // Linear reference: F(t) = F_ref s(t) at load factor s(t).
        let want = self.force_ref * s;
        Some((Self::force(obs), want))
    }
}

/// A catheter tip modelled as a bonded flat punch on a vessel-wall segment.
///
/// The linear companion of [`WALL_INDENTATION`] (the sphere in unilateral
/// contact): a rigid flat-ended circular punch of the catheter's radius,
/// bonded to the inner wall (every component of the footprint nodes is
/// prescribed) and pushed radially outward (`+x`) by `depth`. It needs no
/// tissue contact, so every tissue model runs it, and it is the scene of
/// the PBD local-activation study (`comparisons/pbd-hash.toml`).
///
/// Geometry and material (from the reference's `meta.toml`): inner radius
/// 4 mm and wall thickness 1 mm (carotid / femoral artery size), a 120 deg
/// sector 8 mm long, so the punch rim is about 3 wall thicknesses from every
/// clamped boundary; punch radius 1 mm (a 6F catheter is 2 mm across);
/// `E = 1 MPa`, `nu = 0.45`, the order of magnitude of the small-strain
/// modulus of the arterial wall (Holzapfel, Gasser & Ogden 2000, J.
/// Elasticity 61; nearly incompressible), density 1060 kg/m^3.
///
/// Scores: the punch force at the final depth against the reference
/// (`force_error_rel`, primary), the force along the ramp against the linear
/// reference curve `F_ref s(t)` at every step's load factor `s(t)`
/// (`force_curve_error_rel`: RMS error over RMS reference force,
/// accumulated in [`Scorer::observe_step`](crate::Scorer::observe_step); equals the force error for
/// a linear quasi-static model) and the radial displacement of the inner
/// wall along the axial line through the punch centre, outside the footprint
/// (`surface_error_rel`: RMS error over RMS reference displacement).
pub const WALL_PUNCH: Declared<PunchParams> = Declared {
    info: ScenarioInfo {
        id: "wall-punch",
        description: "vessel-wall sector (r 4-5 mm) indented by a 1 mm flat punch BONDED to the inner wall (the linear companion of wall-indentation's sphere): force, deformed surface",
        family: Family::Tissue,
        reference: "scikit-fem P2, LINEAR elasticity, bonded flat punch (datasets/reference/wall-punch)",
        primary_error: "force_error_rel",
        target: crate::scenario::Target::new(
            0.05,
            "5 % of the reference force: the project's default for tissue forces",
        ),
        params: PunchParams::SPECS,
        sweep: LEVELS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

fn build(p: &PunchParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let level = mesh_level(WALL_PUNCH.info.id, inputs.fidelity)?;
    let r = PunchReference::load(inputs.datasets)?;
    let (depth, e) = (p.depth, p.youngs_modulus);
    let force_ref = r.force(depth, e).filter(|f| *f > 0.0).ok_or_else(|| {
        UsageError(format!(
            "wall-punch: depth {depth} m is outside the reference's (0, {}] m",
            r.max_depth()
        ))
    })?;
    let mesh = wall_mesh(&r, level);
    let foot = wall_footprint(&r, &mesh);
    if foot.is_empty() {
        return Err(UsageError(format!(
            "wall-punch: no node of mesh level {level} lies in the punch footprint"
        )));
    }
    let mut body = TissueBody::new(mesh.clone(), material(p.youngs_modulus, p.density, r.poisson_ratio));
    body.fixed_nodes = wall_clamped(&r, &mesh);
    body.driven_nodes = foot.into_iter().map(|i| (i, Vec3::new(depth, 0.0, 0.0))).collect();
    // Profile probes strictly between the clamped ends and outside the
    // footprint: inside it every model is driven exactly.
    let zc = 0.5 * r.length;
    let probes = r
        .profile
        .iter()
        .filter(|(z, _)| *z > 0.0 && *z < r.length && (z - zc).abs() > r.punch_radius * (1.0 + FOOTPRINT_TOL))
        .map(|&(z, u)| {
            let (e, w) = locate(&mesh, &Vec3::new(r.inner_radius, 0.0, z)).expect("wall mesh has tets");
            (e, w, u * depth)
        })
        .collect();
    let scene = static_scene(WALL_PUNCH.info.id, body, p.ramp_time, p.duration, p.settle_tol)?;
    let run = PunchRun {
        mesh,
        depth,
        force_ref,
        probes,
    };
    // Twice the linear work F d / 2.
    Ok(ScenarioRun::new(scene, Curve(run), force_ref * depth, r.length))
}
