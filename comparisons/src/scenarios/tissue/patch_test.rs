//! `tissue-patch-test`: every boundary node of a body driven by one
//! homogeneous deformation `x = X + G (X - c)`; the free interior nodes must
//! follow the same affine map. Runs on the built-in cube or on a user's
//! tetrahedral mesh (`run-one --mesh FILE`), so it is the one tissue check
//! that holds for any geometry.
//!
//! Why the answer is exact: a homogeneous deformation gradient `F = I + G`
//! gives the same stress in every point of a homogeneous body, so the stress
//! divergence vanishes and, with no body force, the affine field satisfies
//! equilibrium for ANY constitutive law and any strain size; with the whole
//! boundary prescribed the solution is unique for a stable law. A
//! discretisation that reproduces linear fields (linear tetrahedra, linear
//! MLS) passes it exactly, up to its solver tolerance: this is the patch
//! test of Irons & Razzaque (1972), the standard consistency check of
//! finite elements (Zienkiewicz & Taylor, The Finite Element Method, vol. 1,
//! ch. 10). A model that fails it does not converge to the continuum on
//! irregular meshes.

use super::*;
use crate::params;
use crate::scenario::{
    Declared, Inputs, MeshKind, ParamSet, ParamSpec, Pointwise, Range, ScenarioInfo, ScenarioRun, UsageError,
};
use nalgebra::Matrix3;
use surgbench_core::{Family, Observation, TetMesh, Vec3};

params! {
    /// Parameters of `tissue-patch-test`.
    pub struct PatchParams {
        edge: ParamSpec::new(
            "edge",
            0.01,
            "m",
            Range::Positive,
            "edge of the built-in cube (a --mesh file sets its own geometry; edge may not be given with it)",
        ),
        stretch: ParamSpec::new(
            "stretch",
            0.1,
            "1",
            Range::Open(-0.5, 1.0),
            "F_xx - 1: stretch along x of the prescribed homogeneous deformation",
        ),
        shear: ParamSpec::new(
            "shear",
            0.1,
            "1",
            Range::Closed(-0.5, 0.5),
            "F_xy: simple shear of x planes along y",
        ),
        youngs_modulus: ParamSpec::new("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
        poisson_ratio: ParamSpec::new("poisson_ratio", 0.3, "1", Range::Open(0.0, 0.5), "Poisson ratio"),
        density: DENSITY,
        ramp_time: RAMP,
        duration: DURATION,
        settle_tol: SETTLE,
    }
}

/// The prescribed map and the nodes it is checked on.
struct PatchRun {
    mesh: TetMesh,
    /// Displacement gradient `G = F - I`.
    g: Matrix3<f64>,
    /// Centre of the map (m): the mesh's bounding-box centre.
    centre: Vec3,
    /// The free nodes (not on the boundary).
    interior: Vec<usize>,
    /// Largest prescribed boundary displacement `|G (X - c)|` (m).
    scale: f64,
}

impl PatchRun {
    /// Exact displaced position of rest point `x0` (m) at full load.
    fn exact(&self, x0: &Vec3) -> Vec3 {
        x0 + self.g * (x0 - self.centre)
    }
}

impl Pointwise for PatchRun {
    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let (mut e2, mut emax) = (0.0, 0.0f64);
        for &i in &self.interior {
            let e = (t.nodes[i] - self.exact(&self.mesh.nodes[i])).norm();
            e2 += e * e;
            emax = emax.max(e);
        }
        m.insert("patch_error_rel".into(), emax / self.scale);
        m.insert(
            "patch_error_rms_rel".into(),
            (e2 / self.interior.len() as f64).sqrt() / self.scale,
        );
        // Every element of the exact field has V / V0 = det F.
        let det = (Matrix3::identity() + self.g).determinant();
        let mut jmax = 0.0f64;
        for tet in &self.mesh.tets {
            let v0 = mesh::tet_volume_of(&tet.map(|i| self.mesh.nodes[i]));
            let v = mesh::tet_volume_of(&tet.map(|i| t.nodes[i]));
            jmax = jmax.max((v / v0 - det).abs());
        }
        m.insert("element_jacobian_error".into(), jmax);
        m.insert("interior_nodes".into(), self.interior.len() as f64);
        common_metrics(&mut m, &self.mesh, t);
        m
    }
}

/// A homogeneous deformation prescribed on the whole boundary.
pub const PATCH_TEST: Declared<PatchParams> = Declared {
    info: ScenarioInfo {
        id: "tissue-patch-test",
        description: "every boundary node driven by one homogeneous deformation (stretch + shear): interior nodes must follow it; built-in cube or --mesh",
        family: Family::Tissue,
        reference: "exact: the affine field x = X + G (X - c) is the equilibrium of any homogeneous material (patch test, Irons & Razzaque 1972)",
        primary_error: "patch_error_rel",
        target: crate::scenario::Target::new(
            1e-06,
            "linear elements reproduce a homogeneous strain exactly: an error past round-off fails the patch test",
        ),
        params: PatchParams::SPECS,
        sweep: LEVELS,
        quick: 2,
        mesh: Some(MeshKind::Tets),
    },
    datasets: None,
    build,
};

/// Checks that every node of a user's mesh belongs to a tet: a node in no
/// element has no stiffness and no mass in some models.
fn check_nodes_used(mesh: &TetMesh, file: &str) -> Result<(), UsageError> {
    let mut used = vec![false; mesh.nodes.len()];
    for t in &mesh.tets {
        for &i in t {
            used[i] = true;
        }
    }
    match used.iter().position(|u| !u) {
        Some(i) => Err(UsageError(format!(
            "tissue-patch-test: node {i} of {file} belongs to no tetrahedron; remove unused nodes"
        ))),
        None => Ok(()),
    }
}

fn build(p: &PatchParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = PATCH_TEST.info.id;
    let mesh = match inputs.mesh.and_then(|m| m.tets()) {
        Some(user) => {
            if inputs.params.is_overridden("edge") {
                return Err(UsageError(format!(
                    "{id}: `edge` sizes the built-in cube; with --mesh the file sets the geometry"
                )));
            }
            check_nodes_used(
                user,
                &inputs.mesh.map(|m| m.path.display().to_string()).unwrap_or_default(),
            )?;
            user.clone()
        }
        None => {
            let n = block_cells(mesh_level(id, inputs.fidelity)?);
            mesh::block(Vec3::repeat(p.edge), [n, n, n])
        }
    };
    let on_boundary: HashSet<usize> = mesh::boundary_faces(&mesh).into_iter().flatten().collect();
    let interior: Vec<usize> = (0..mesh.nodes.len()).filter(|i| !on_boundary.contains(i)).collect();
    if interior.is_empty() {
        return Err(UsageError(format!(
            "{id}: every node of the mesh ({} nodes) is on its boundary; the patch test needs at least one interior node",
            mesh.nodes.len()
        )));
    }
    let (lo, hi) = mesh::bounds(&mesh);
    let centre = (lo + hi) / 2.0;
    let mut g = Matrix3::zeros();
    g[(0, 0)] = p.stretch;
    g[(0, 1)] = p.shear;
    let mut boundary: Vec<usize> = on_boundary.into_iter().collect();
    boundary.sort_unstable();
    let driven: Vec<(usize, Vec3)> = boundary.iter().map(|&i| (i, g * (mesh.nodes[i] - centre))).collect();
    let scale = driven.iter().map(|(_, u)| u.norm()).fold(0.0, f64::max);
    if !(scale > 0.0) {
        return Err(UsageError(format!(
            "{id}: stretch and shear are both 0: nothing is prescribed to check"
        )));
    }
    let solid = material(p.youngs_modulus, p.density, p.poisson_ratio);
    let mut body = TissueBody::new(mesh.clone(), solid);
    body.driven_nodes = driven;
    let size = (hi - lo).norm();
    let volume: f64 = mesh
        .tets
        .iter()
        .map(|t| mesh::tet_volume_of(&t.map(|i| mesh.nodes[i])).abs())
        .sum();
    let scene = static_scene(id, body, p.ramp_time, p.duration, p.settle_tol)?;
    // Elastic energy scale E V |G|^2, twice over.
    let work = 2.0 * p.youngs_modulus * volume * g.norm_squared();
    let run = PatchRun {
        mesh,
        g,
        centre,
        interior,
        scale,
    };
    Ok(ScenarioRun::new(scene, run, work, size + centre.norm()))
}
