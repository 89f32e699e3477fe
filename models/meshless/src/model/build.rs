//! Building a [`MeshlessTissue`] for a scene at a fidelity: nodes, support
//! radii, masses, the MLS surface map, contact and loads.

use super::*;
use crate::contact::SphereContact;
use crate::elastic::{PointElastic, StateCache, moment_rcond};
use crate::kdtree::KdTree;
use crate::mls::MlsMap;
use crate::pbd::PbdConstraints;
use crate::pressure::PressureLoad;
use surgbench_core::mesh::boundary_faces;
use surgbench_core::{BuildError, Fidelity, Scene, Settings, TetMesh, TissueBody, Unsupported, Vec3};

impl MeshlessTissue {
    /// Build the tissue of `scene` (exactly one tissue body) at
    /// `fidelity`, resolved by [`surgbench_core::resolve`].
    pub fn new(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        Self::with_settings(scene, &surgbench_core::resolve(&MeshlessFactory, scene, fidelity)?)
    }

    /// Build the tissue of `scene` from settings resolved for it.
    pub fn with_settings(scene: &Scene, settings: &Settings) -> Result<Self, BuildError> {
        let set = MeshlessSettings::from_settings(scene, settings)?;
        let fidelity = settings.fidelity();
        let body: &TissueBody = scene.tissues().next().expect("checked: one tissue");
        let mesh = &body.mesh;
        let nn = mesh.nodes.len();
        if mesh.tets.is_empty() {
            return Err(BuildError::bad("mesh", "tissue mesh has no tets"));
        }
        let m = body.material;
        let (volume, rest_volume, mean_edge) = node_volumes(mesh)?;
        let local_edge = local_edge_lengths(mesh);
        let (support, raised, longest) = support_radii(mesh, &set, &local_edge);
        let el = PointElastic::new(
            &mesh.nodes,
            &volume,
            &support,
            m.youngs_modulus,
            m.poisson_ratio,
            set.stabilization * m.youngs_modulus,
        )
        .map_err(|e| refusal(fidelity, "support_factor", e.to_string()))?;
        let surface_faces_global = boundary_faces(mesh);
        let (surface_nodes, surface_faces) = surface_of(&surface_faces_global, nn);
        let mls_radius: Vec<f64> = surface_nodes
            .iter()
            .map(|&i| {
                let r = set.mls_factor * local_edge[i];
                if raised[i] {
                    r.max(set.support_floor * longest[i])
                } else {
                    r
                }
            })
            .collect();
        let targets: Vec<Vec3> = surface_nodes.iter().map(|&i| mesh.nodes[i]).collect();
        let mls = MlsMap::new(&mesh.nodes, &targets, &mls_radius)
            .map_err(|e| refusal(fidelity, "mls_factor", e.to_string()))?;
        // Every contact-surface vertex is a boundary vertex: its particle.
        let contact_particles = body
            .surface_vertices()
            .iter()
            .map(|i| surface_nodes.binary_search(i))
            .collect::<Result<Vec<usize>, usize>>()
            .map_err(|_| {
                BuildError::bad(
                    "contact_surface",
                    "a contact-surface vertex is not on the mesh boundary",
                )
            })?;
        let axis_free = free_axes(body)?;
        let mass: Vec<f64> = volume.iter().map(|v| v * m.density).collect();
        let (lo, hi) = surgbench_core::mesh::bounds(mesh);
        let damping = settle_damping(&set, scene, body, (hi - lo).max());
        let pbd = set
            .pbd
            .then(|| PbdConstraints::new(&mesh.nodes, &mesh.tets, set.pbd_stretch, set.pbd_tet));
        let contact = sphere_contact(body, &set, &surface_faces_global)?;
        let tol = local_edge.iter().map(|l| 1e-9 * m.youngs_modulus * l * l).collect();
        Ok(Self {
            set,
            cache: StateCache::default(),
            x: mesh.nodes.clone(),
            v: body.start_velocities(),
            mass,
            axis_free,
            driven: body.driven_nodes.clone(),
            gravity: scene.gravity,
            damping,
            tets: mesh.tets.clone(),
            rest_volume,
            pbd,
            pbd_residual: 0.0,
            surface_nodes,
            surface_faces,
            mls,
            mean_edge,
            local_edge,
            raised: (0..nn).filter(|&i| raised[i]).collect(),
            scale: (hi - lo).norm(),
            tol,
            time: 0.0,
            hand_force: Vec3::zeros(),
            forces: vec![Vec3::zeros(); nn],
            forces_at_x: false,
            pressure: PressureLoad::new(&body.pressure_faces),
            load_scale: 0.0,
            load_stepping: (0, 0),
            pforces: vec![Vec3::zeros(); nn],
            contact,
            el,
            contact_particles,
            external: vec![Vec3::zeros(); nn],
        })
    }
}

/// Each node's volume (a quarter of each tet around it), the total rest
/// volume and the mean tet edge length; a node in no tet is an error.
fn node_volumes(mesh: &TetMesh) -> Result<(Vec<f64>, f64, f64), BuildError> {
    let mut volume = vec![0.0; mesh.nodes.len()];
    let mut rest_volume = 0.0;
    let (mut edge_sum, mut edge_n) = (0.0, 0usize);
    for t in &mesh.tets {
        let p = t.map(|i| mesh.nodes[i]);
        let v = surgbench_core::mesh::tet_volume(&p[0], &p[1], &p[2], &p[3]).abs();
        rest_volume += v;
        for &i in t {
            volume[i] += v / 4.0;
        }
        for a in 0..4 {
            for b in a + 1..4 {
                edge_sum += (p[b] - p[a]).norm();
                edge_n += 1;
            }
        }
    }
    if let Some(i) = volume.iter().position(|&v| !(v > 0.0)) {
        return Err(BuildError::bad(
            "mesh",
            format!("node {i} belongs to no tet, so it has no volume"),
        ));
    }
    Ok((volume, rest_volume, edge_sum / edge_n as f64))
}

/// Support radii `support_factor * local edge`, raised to `support_floor *
/// longest edge` where the moment matrix would be ill-conditioned; with the
/// raised marks and the longest edges at each node.
fn support_radii(mesh: &TetMesh, set: &MeshlessSettings, local_edge: &[f64]) -> (Vec<f64>, Vec<bool>, Vec<f64>) {
    let longest = longest_edges(mesh);
    let tree = KdTree::new(&mesh.nodes);
    let mut found = Vec::new();
    let mut raised = vec![false; mesh.nodes.len()];
    let support: Vec<f64> = (0..mesh.nodes.len())
        .map(|i| {
            let (h, floor) = (set.support_factor * local_edge[i], set.support_floor * longest[i]);
            if h < floor && moment_rcond(&mesh.nodes, &tree, i, h, &mut found) < RAISE_BELOW_RCOND {
                raised[i] = true;
                floor
            } else {
                h
            }
        })
        .collect();
    (support, raised, longest)
}

/// The boundary nodes (sorted) and the boundary faces in their local numbering.
fn surface_of(faces: &[[usize; 3]], nn: usize) -> (Vec<usize>, Vec<[usize; 3]>) {
    let mut surface_nodes: Vec<usize> = faces.iter().flatten().copied().collect();
    surface_nodes.sort_unstable();
    surface_nodes.dedup();
    let mut local = vec![usize::MAX; nn];
    for (k, &i) in surface_nodes.iter().enumerate() {
        local[i] = k;
    }
    let surface_faces = faces.iter().map(|f| f.map(|i| local[i])).collect();
    (surface_nodes, surface_faces)
}

/// Per node, the axes it may move along (0 where fixed, rolled or driven).
fn free_axes(body: &TissueBody) -> Result<Vec<Vec3>, BuildError> {
    let mut axis_free = vec![Vec3::repeat(1.0); body.mesh.nodes.len()];
    for &i in &body.fixed_nodes {
        axis_free[i] = Vec3::zeros();
    }
    for (i, axes) in &body.partial_fixed {
        for a in 0..3 {
            if axes[a] {
                axis_free[*i][a] = 0.0;
            }
        }
    }
    if !body.driven_nodes.iter().all(|(_, d)| d.iter().all(|c| c.is_finite())) {
        return Err(BuildError::bad("driven_nodes", "displacements must be finite"));
    }
    for &(i, _) in &body.driven_nodes {
        axis_free[i] = Vec3::zeros();
    }
    Ok(axis_free)
}

/// The velocity damping rate (1/s): the setting, or for a settle with the
/// explicit integrator critical damping of the first axial mode of a bar of
/// length `extent`: `omega_1 = (pi / 2L) sqrt(E / rho)`, `c = 2 omega_1`.
fn settle_damping(set: &MeshlessSettings, scene: &Scene, body: &TissueBody, extent: f64) -> f64 {
    let m = body.material;
    match (set.damping, set.integrator, scene.settle) {
        (Some(c), _, _) => c,
        (None, Integrator::SymplecticEuler, Some(_)) => {
            2.0 * std::f64::consts::PI / (2.0 * extent) * (m.youngs_modulus / m.density).sqrt()
        }
        _ => 0.0,
    }
}

/// The penalty contact with the indenter sphere, if any, or why these settings cannot have it.
fn sphere_contact(
    body: &TissueBody,
    set: &MeshlessSettings,
    faces: &[[usize; 3]],
) -> Result<Option<SphereContact>, BuildError> {
    match &body.indenter {
        None => Ok(None),
        Some(ind) if set.integrator == Integrator::SymplecticEuler => Err(Unsupported::new(format!(
            "meshless: sphere contact (indenter of radius {} m) is a stiff penalty (kappa E* sqrt(A)) solved in the implicit integrators (1, 2); the explicit one (0) would need a time step below its stability limit",
            ind.radius
        ))
        .into()),
        Some(_) if set.pbd => Err(Unsupported::new(
            "meshless: the PBD corrections (pbd=1) move nodes after the contact solve and would push them into the sphere; sphere contact needs pbd=0",
        )
        .into()),
        Some(ind) => Ok(Some(SphereContact::new(
            &body.mesh.nodes,
            faces,
            &body.material,
            set.contact_stiffness,
            *ind,
        ))),
    }
}
