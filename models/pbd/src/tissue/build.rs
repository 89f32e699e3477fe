//! Building a [`PbdTissue`] for a scene at a fidelity: masses, rest
//! lengths and volumes, compliances, colouring, holds and the sphere.

use super::*;
use crate::color::partition;
use crate::hash::BoxHash;
use std::collections::HashMap;
use std::sync::Arc;
use surgbench_core::material::lame;
use surgbench_core::mesh::tet_volume_of as tet_volume;
use surgbench_core::{BuildError, Fidelity, Scene, Settings, Unsupported, Vec3};

impl PbdTissue {
    /// Build the tissue of `scene` (exactly one tissue body) at
    /// `fidelity`, resolved by [`surgbench_core::resolve`].
    pub fn new(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        Self::with_settings(scene, &surgbench_core::resolve(&PbdTissueFactory, scene, fidelity)?)
    }

    /// Build the tissue of `scene` from settings resolved for it.
    pub fn with_settings(scene: &Scene, settings: &Settings) -> Result<Self, BuildError> {
        let set = TissueSettings::from_settings(settings)?;
        let body = scene.tissues().next().expect("checked: one tissue");
        check_body(body, &set)?;
        let nn = body.mesh.nodes.len();
        let m = body.material;
        let (mu, lam) = lame(m.youngs_modulus, m.poisson_ratio);
        let x: Vec<Vec3> = body.mesh.nodes.clone();
        let tets: Vec<[u32; 4]> = body.mesh.tets.iter().map(|t| t.map(|i| i as u32)).collect();
        let (part, net) = TetNetwork::new(&x, tets, m.density, mu).coloured(nn);
        let (edge_rest, edge_alpha, tet_alpha) = net.compliances(&x, lam);
        let (w, driven_mark) = inverse_masses(body, &net.mass);
        let driven_edges = touching(&net.edges, &driven_mark);
        let driven_tets = touching(&net.tets, &driven_mark);
        let hash = local_hash(body, &set, &x, &net.tets)?;
        let tets_around = tets_around(&net.tets, nn);
        let pool = thread_pool(set.threads)?;
        let xa = AtomicPositions::new(nn);
        for (i, p) in x.iter().enumerate() {
            xa.set(i, p);
        }
        let rest_volume = net.tet_rest.iter().map(|v| v.abs()).sum();
        let (held, rollers) = roller_holds(body, &w)?;
        let sphere = body.indenter.as_ref().map(|ind| sphere_contact(body, ind, &w, &held));
        let scale = bounding_diagonal(&x);
        let mut s = Self {
            set,
            rest: x.clone(),
            v: body.start_velocities(),
            x_prev: x.clone(),
            x,
            mass: net.mass,
            w,
            lambda_e: vec![0.0; net.edges.len()],
            edges: net.edges,
            edge_rest,
            edge_alpha,
            lambda_t: vec![0.0; net.tets.len()],
            tets: net.tets,
            tet_rest: net.tet_rest,
            tet_alpha,
            tet_edges: net.tet_edges,
            rest_volume,
            driven: body.driven_nodes.clone(),
            driven_mark,
            driven_edges,
            driven_tets,
            gravity: scene.gravity,
            hash,
            tets_around,
            activations: 0,
            active_tets_sum: 0.0,
            active_samples: 0,
            active: ActiveSet {
                key: vec![usize::MAX - 1],
                ..Default::default()
            },
            tool_tip: None,
            xa,
            pool,
            part,
            time: 0.0,
            last_ins: 0.0,
            cur_ins: 0.0,
            hand_force: Vec3::zeros(),
            multiplier_force: Vec3::zeros(),
            residual: 0.0,
            projections: 0,
            scale,
            last_h: set.dt / set.substeps as f64,
            rollers,
            sphere,
            sphere_force: Vec3::zeros(),
            surface: body.surface_vertices(),
            external: vec![Vec3::zeros(); body.mesh.nodes.len()],
        };
        s.update_active();
        Ok(s)
    }
}

/// Reject a tissue body this model cannot build: sphere contact with local
/// activation, no tets, out-of-range boundary nodes, non-finite drives.
fn check_body(body: &TissueBody, set: &TissueSettings) -> Result<(), BuildError> {
    if body.indenter.is_some() && set.hash_box > 0.0 {
        return Err(Unsupported::new(
            "pbd-tissue: local activation (hash_box > 0) follows the driven nodes, not the sphere; sphere contact needs hash_box = 0",
        )
        .into());
    }
    let nn = body.mesh.nodes.len();
    if body.mesh.tets.is_empty() {
        return Err(BuildError::bad("mesh", "tissue mesh has no tets"));
    }
    for &i in body.fixed_nodes.iter().chain(body.driven_nodes.iter().map(|(i, _)| i)) {
        if i >= nn {
            return Err(BuildError::bad(
                "mesh",
                format!("boundary node {i} but the mesh has {nn} nodes"),
            ));
        }
    }
    if !body.driven_nodes.iter().all(|(_, d)| d.iter().all(|c| c.is_finite())) {
        return Err(BuildError::bad("driven_nodes", "displacements must be finite"));
    }
    Ok(())
}

/// The tets' lumped masses, signed rest volumes and shared edges with their
/// spring stiffnesses `sum_t mu |V_t| / L0^2`, in mesh order.
struct TetNetwork {
    tets: Vec<[u32; 4]>,
    mass: Vec<f64>,
    tet_rest: Vec<f64>,
    edges: Vec<[u32; 2]>,
    edge_k: Vec<f64>,
    tet_edges: Vec<[u32; 6]>,
}

impl TetNetwork {
    /// Lump `density |V| / 4` on each tet's nodes and give each edge its share of `mu |V| / L0^2`.
    fn new(x: &[Vec3], tets: Vec<[u32; 4]>, density: f64, mu: f64) -> Self {
        let mut mass = vec![0.0; x.len()];
        let mut tet_rest = Vec::with_capacity(tets.len());
        let mut edge_id: HashMap<(u32, u32), u32> = HashMap::new();
        let mut edges = Vec::new();
        let mut edge_k: Vec<f64> = Vec::new();
        let mut tet_edges = Vec::with_capacity(tets.len());
        const PAIRS: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
        for t in &tets {
            let p = t.map(|i| x[i as usize]);
            let v = tet_volume(&p);
            tet_rest.push(v);
            for &i in t {
                mass[i as usize] += density * v.abs() / 4.0;
            }
            let mut te = [0u32; 6];
            for (s, &(a, b)) in PAIRS.iter().enumerate() {
                let key = (t[a].min(t[b]), t[a].max(t[b]));
                let id = *edge_id.entry(key).or_insert_with(|| {
                    edges.push([key.0, key.1]);
                    edge_k.push(0.0);
                    (edges.len() - 1) as u32
                });
                let l0 = (p[b] - p[a]).norm();
                edge_k[id as usize] += mu * v.abs() / (l0 * l0);
                te[s] = id;
            }
            tet_edges.push(te);
        }
        Self {
            tets,
            mass,
            tet_rest,
            edges,
            edge_k,
            tet_edges,
        }
    }

    /// Edge rest lengths (m), edge compliances `1 / k` and volume
    /// compliances `|V| / lambda` (infinite for `lambda <= 0`).
    fn compliances(&self, x: &[Vec3], lam: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let edge_rest: Vec<f64> = self
            .edges
            .iter()
            .map(|e| (x[e[1] as usize] - x[e[0] as usize]).norm())
            .collect();
        let edge_alpha: Vec<f64> = self.edge_k.iter().map(|k| 1.0 / k).collect();
        let tet_alpha: Vec<f64> = self
            .tet_rest
            .iter()
            .map(|v| if lam > 0.0 { v.abs() / lam } else { f64::INFINITY })
            .collect();
        (edge_rest, edge_alpha, tet_alpha)
    }

    /// The network in the storage order of the two-level colouring
    /// ([`crate::color`]), with the partition that orders it.
    fn coloured(self, nn: usize) -> (Partition, Self) {
        let part = partition(nn, &self.edges, &self.tets);
        let mut edge_new = vec![0u32; self.edges.len()];
        for (new, &old) in part.edge_perm.iter().enumerate() {
            edge_new[old as usize] = new as u32;
        }
        let net = Self {
            edges: part.edge_perm.iter().map(|&o| self.edges[o as usize]).collect(),
            edge_k: part.edge_perm.iter().map(|&o| self.edge_k[o as usize]).collect(),
            tets: part.tet_perm.iter().map(|&o| self.tets[o as usize]).collect(),
            tet_rest: part.tet_perm.iter().map(|&o| self.tet_rest[o as usize]).collect(),
            tet_edges: part
                .tet_perm
                .iter()
                .map(|&o| self.tet_edges[o as usize].map(|e| edge_new[e as usize]))
                .collect(),
            mass: self.mass,
        };
        (part, net)
    }
}

/// The elements (edges or tets) with a driven node.
fn touching<const K: usize>(elements: &[[u32; K]], driven_mark: &[bool]) -> Vec<u32> {
    (0..elements.len() as u32)
        .filter(|&e| elements[e as usize].iter().any(|&i| driven_mark[i as usize]))
        .collect()
}

/// Inverse masses (0 for fixed and driven nodes) and the driven-node marks.
fn inverse_masses(body: &TissueBody, mass: &[f64]) -> (Vec<f64>, Vec<bool>) {
    let mut w: Vec<f64> = mass.iter().map(|&m| if m > 0.0 { 1.0 / m } else { 0.0 }).collect();
    let mut driven_mark = vec![false; mass.len()];
    for &i in &body.fixed_nodes {
        w[i] = 0.0;
    }
    for &(i, _) in &body.driven_nodes {
        w[i] = 0.0;
        driven_mark[i] = true;
    }
    (w, driven_mark)
}

/// Number of tets around each of `nn` nodes.
fn tets_around(tets: &[[u32; 4]], nn: usize) -> Vec<u32> {
    let mut n = vec![0; nn];
    tets.iter().flatten().for_each(|&i| n[i as usize] += 1);
    n
}

/// The local-activation hash when `hash_box > 0` (it needs a tool to
/// follow: driven nodes, or a coupled instrument's forces on the contact
/// surface).
fn local_hash(
    body: &TissueBody,
    set: &TissueSettings,
    x: &[Vec3],
    tets: &[[u32; 4]],
) -> Result<Option<BoxHash>, BuildError> {
    if set.hash_box > 0.0 {
        if body.driven_nodes.is_empty() && body.contact_surface.is_empty() {
            return Err(BuildError::bad(
                "hash_box",
                "local activation follows the tool (driven nodes, or an instrument's forces on the contact surface); this scene has neither",
            ));
        }
        let tets_usize: Vec<[usize; 4]> = tets.iter().map(|t| t.map(|i| i as usize)).collect();
        Ok(Some(BoxHash::new(x, &tets_usize, set.hash_box, set.hash_span)))
    } else {
        Ok(None)
    }
}

/// A worker pool for the constraint solve when `threads > 1`.
fn thread_pool(threads: usize) -> Result<Option<Arc<rayon::ThreadPool>>, BuildError> {
    if threads > 1 {
        let p = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| BuildError::bad("threads", format!("cannot start {threads} threads: {e}")))?;
        Ok(Some(Arc::new(p)))
    } else {
        Ok(None)
    }
}

/// The held axes of every node and the rollers (free nodes with a held axis).
#[allow(clippy::type_complexity)]
fn roller_holds(body: &TissueBody, w: &[f64]) -> Result<(Vec<[bool; 3]>, Vec<(u32, [bool; 3])>), BuildError> {
    let nn = body.mesh.nodes.len();
    let mut held = vec![[false; 3]; nn];
    let mut rollers = Vec::new();
    for &(i, axes) in &body.partial_fixed {
        if i >= nn {
            return Err(BuildError::bad(
                "mesh",
                format!("roller node {i} but the mesh has {nn} nodes"),
            ));
        }
        if w[i] > 0.0 && axes.iter().any(|&a| a) {
            for a in 0..3 {
                held[i][a] |= axes[a];
            }
            rollers.push((i as u32, axes));
        }
    }
    Ok((held, rollers))
}

/// Contact with the indenter sphere: the moving boundary nodes, their free axes.
fn sphere_contact(
    body: &TissueBody,
    ind: &surgbench_core::SphereIndenter,
    w: &[f64],
    held: &[[bool; 3]],
) -> SphereContact {
    let mut nodes: Vec<u32> = surgbench_core::mesh::boundary_faces(&body.mesh)
        .into_iter()
        .flatten()
        .filter(|&i| w[i] > 0.0)
        .map(|i| i as u32)
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    let free = nodes
        .iter()
        .map(|&i| Vec3::from_fn(|a, _| if held[i as usize][a] { 0.0 } else { 1.0 }))
        .collect();
    SphereContact {
        path: *ind,
        centre: ind.centre,
        lambda: vec![0.0; nodes.len()],
        impulse: Vec3::zeros(),
        nodes,
        free,
    }
}

/// Length of the diagonal of the axis-aligned box around `x` (m).
fn bounding_diagonal(x: &[Vec3]) -> f64 {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in x {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (hi - lo).norm()
}
