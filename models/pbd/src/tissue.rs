//! Tetrahedral XPBD tissue (model id `pbd-tissue`).
//!
//! Constraints, solved by Gauss-Seidel with XPBD compliance (Macklin, Müller &
//! Chentanez 2016, eqs. 17-18: `dlambda = -(C + alpha~ lambda) /
//! (sum_i w_i |grad_i C|^2 + alpha~)`, `dp_i = w_i grad_i C dlambda`,
//! `alpha~ = alpha / h^2`):
//!
//! * one **distance** constraint per mesh edge, `C = |p_j - p_i| - L0`
//!   (Müller et al. 2007, "Position Based Dynamics", sec. 3.3);
//! * one **volume** constraint per tet (the PBD vessel seed paper; Müller et
//!   al. 2007 sec. 3.3), `C = (1/6) ((p2-p1) x (p3-p1)) . (p4-p1) - V0` with
//!   gradients `(1/6)(p4-p2) x (p3-p2)`, `(1/6)(p3-p1) x (p4-p1)`,
//!   `(1/6)(p4-p1) x (p2-p1)`, `(1/6)(p2-p1) x (p3-p1)`; see
//!   [`tet_volume_gradients`]. Volumes are signed; `V0` is the signed rest volume.
//!
//! **Material mapping** (stated, approximate): with Lamé parameters
//! `mu = E / (2 (1 + nu))`, `lambda = E nu / ((1 + nu)(1 - 2 nu))`, each tet
//! `t` gives each of its edges a spring stiffness `mu |V_t| / L0^2` (summed over
//! the tets sharing the edge: `alpha_edge = 1 / sum_t mu |V_t| / L0^2`, N/m),
//! and its volume constraint the compliance `alpha_vol = |V_t| / lambda`
//! (m^3/Pa = 1/(N/m^5)). For a uniform dilation `eps` of any tet this gives
//! exactly the linear-elastic energy `(3 mu + 9/2 lambda) eps^2 V`
//! (springs `3 mu eps^2 V`, volume `1/2 lambda (3 eps)^2 V`); shear is only
//! approximated by the spring network, which the harness's FEM references
//! measure. `nu -> 1/2` makes the volume constraint hard; `nu = 0` drops it;
//! `nu < 0` (negative `lambda`) is unsupported.
//!
//! **Local activation** ([`crate::BoxHash`], fidelity `hash_box` > 0): only the
//! tets of the expanded box holding the tool tip are solved; particles of
//! those tets in the span bands at the box's bottom and top faces (along z,
//! the vessel-axis convention of tube scenes) are held, and everything
//! outside stays where it is. The tool tip is the centroid of the driven
//! nodes unless set with [`PbdTissue::set_tool_tip`].
//!
//! Units are SI throughout.

use std::collections::HashMap;

use surgbench_core::{
    BuildError, Capability, DeviceCommand, EnergyObs, Family, Fidelity, FidelityKey, Model, ModelFactory, Observation,
    Scene, SimError, StepStats, TissueBody, TissueObs, Unsupported, Vec3,
};

use crate::hash::BoxHash;

/// Signed volume `(1/6) ((p2-p1) x (p3-p1)) . (p4-p1)` of a tet (m^3).
pub fn tet_volume(p: &[Vec3; 4]) -> f64 {
    (p[1] - p[0]).cross(&(p[2] - p[0])).dot(&(p[3] - p[0])) / 6.0
}

/// Gradients of [`tet_volume`] with respect to `p1..p4` (m^2):
/// `(1/6)(p4-p2) x (p3-p2)`, `(1/6)(p3-p1) x (p4-p1)`,
/// `(1/6)(p4-p1) x (p2-p1)`, `(1/6)(p2-p1) x (p3-p1)`.
pub fn tet_volume_gradients(p: &[Vec3; 4]) -> [Vec3; 4] {
    let s = 1.0 / 6.0;
    [
        (p[3] - p[1]).cross(&(p[2] - p[1])) * s,
        (p[2] - p[0]).cross(&(p[3] - p[0])) * s,
        (p[3] - p[0]).cross(&(p[1] - p[0])) * s,
        (p[1] - p[0]).cross(&(p[2] - p[0])) * s,
    ]
}

/// One XPBD projection of the volume constraint of a tet: with
/// `C = V(p) - rest`, `dlambda = -(C + alpha_tilde lambda) / (sum_j w_j
/// |grad_j|^2 + alpha_tilde)` and `p_i += w_i grad_i dlambda` (for
/// `alpha_tilde = 0` this is `dp_i = -C w_i grad_i / sum_j w_j |grad_j|^2`).
/// Updates `lambda` and returns the residual `|C + alpha_tilde lambda|`
/// before the update (m^3).
pub fn project_volume(p: &mut [Vec3; 4], w: [f64; 4], rest: f64, alpha_tilde: f64, lambda: &mut f64) -> f64 {
    let g = tet_volume_gradients(p);
    let c = tet_volume(p) - rest;
    let den: f64 = (0..4).map(|k| w[k] * g[k].norm_squared()).sum::<f64>() + alpha_tilde;
    let num = -(c + alpha_tilde * *lambda);
    if den == 0.0 {
        return num.abs();
    }
    let dl = num / den;
    *lambda += dl;
    for k in 0..4 {
        p[k] += g[k] * (w[k] * dl);
    }
    num.abs()
}

/// Fidelity extras of `pbd-tissue`.
pub const TISSUE_KEYS: &[FidelityKey] = &[
    FidelityKey {
        name: "substeps",
        doc: "XPBD substeps per step (integer >= 1; default 1)",
    },
    FidelityKey {
        name: "damping",
        doc: "velocity damping rate c (1/s): v <- v / (1 + c h) each substep; default 0",
    },
    FidelityKey {
        name: "hash_box",
        doc: "local activation box edge d (m); 0 = off (default)",
    },
    FidelityKey {
        name: "hash_span",
        doc: "box expansion span (m); default d/3",
    },
];

/// Factory for the tetrahedral XPBD tissue (`pbd-tissue`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PbdTissueFactory;

const TISSUE_CAPS: &[Capability] = &[Capability::Tissue, Capability::HapticForce];

impl ModelFactory for PbdTissueFactory {
    fn id(&self) -> &'static str {
        "pbd-tissue"
    }
    fn description(&self) -> &'static str {
        "Tetrahedral XPBD tissue: edge-distance and volume constraints, optional hash-box local activation"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn capabilities(&self) -> &'static [Capability] {
        TISSUE_CAPS
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        TISSUE_KEYS
    }
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        Fidelity {
            segments: None,
            mesh_level: None,
            dt: Some(1e-3),
            iterations: Some(10),
            extras: Default::default(),
        }
    }
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_capabilities(self.id(), self.capabilities(), scene)?;
        let tissues: Vec<&TissueBody> = scene.tissues().collect();
        match tissues.len() {
            1 => {}
            0 => return Err(Unsupported::new("pbd-tissue needs a tissue body in the scene")),
            k => {
                return Err(Unsupported::new(format!(
                    "pbd-tissue simulates one tissue, the scene has {k}"
                )));
            }
        }
        if tissues[0].material.poisson_ratio < 0.0 {
            return Err(Unsupported::new(
                "pbd-tissue maps nu to the volume compliance V0/lambda; nu < 0 gives lambda < 0",
            ));
        }
        Ok(())
    }
    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError> {
        Ok(Box::new(PbdTissue::new(scene, fidelity)?))
    }
}

/// Resolved tissue knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TissueSettings {
    /// Time step (s).
    pub dt: f64,
    /// Gauss-Seidel iterations per substep.
    pub iterations: usize,
    /// Substeps per step.
    pub substeps: usize,
    /// Velocity damping rate (1/s).
    pub damping: f64,
    /// Local activation box edge (m); 0 = off.
    pub hash_box: f64,
    /// Box expansion (m).
    pub hash_span: f64,
}

impl TissueSettings {
    /// Resolve `fidelity` over the factory defaults, rejecting bad values.
    pub fn resolve(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        fidelity
            .check_extras(TISSUE_KEYS)
            .map_err(|e| BuildError::bad("fidelity", e.0))?;
        let f = PbdTissueFactory.default_fidelity(scene).merged(fidelity);
        let dt = f.dt.unwrap_or(1e-3);
        let iterations = f.iterations.unwrap_or(10);
        let substeps = f.extra("substeps", 1.0);
        let damping = f.extra("damping", 0.0);
        let hash_box = f.extra("hash_box", 0.0);
        let hash_span = f.extra("hash_span", hash_box / 3.0);
        crate::check_solver_knobs(dt, iterations, substeps, damping)?;
        if !(hash_box >= 0.0 && hash_box.is_finite()) {
            return Err(BuildError::bad("hash_box", format!("must be >= 0 m, got {hash_box}")));
        }
        if !(hash_span >= 0.0 && hash_span.is_finite()) {
            return Err(BuildError::bad("hash_span", format!("must be >= 0 m, got {hash_span}")));
        }
        Ok(Self {
            dt,
            iterations,
            substeps: substeps as usize,
            damping,
            hash_box,
            hash_span,
        })
    }
}

/// What is solved this step: all constraints, or those of the active box.
#[derive(Debug, Clone, Default)]
struct ActiveSet {
    /// Box linear index (`usize::MAX` = whole mesh).
    key: usize,
    edges: Vec<u32>,
    tets: Vec<u32>,
    /// Nodes that move (free and active).
    nodes: Vec<u32>,
    /// Inverse masses used by the solve (0 for held nodes).
    w: Vec<f64>,
    edge_on: Vec<bool>,
    tet_on: Vec<bool>,
}

/// The tetrahedral XPBD tissue. Build it through [`PbdTissueFactory`] or
/// [`PbdTissue::new`].
#[derive(Debug, Clone)]
pub struct PbdTissue {
    set: TissueSettings,
    rest: Vec<Vec3>,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    x_prev: Vec<Vec3>,
    mass: Vec<f64>,
    w: Vec<f64>,
    edges: Vec<[u32; 2]>,
    edge_rest: Vec<f64>,
    edge_alpha: Vec<f64>,
    lambda_e: Vec<f64>,
    tets: Vec<[u32; 4]>,
    tet_rest: Vec<f64>,
    /// Volume compliance per tet (`inf` = no volume constraint).
    tet_alpha: Vec<f64>,
    lambda_t: Vec<f64>,
    tet_edges: Vec<[u32; 6]>,
    rest_volume: f64,
    driven: Vec<(usize, Vec3)>,
    driven_mark: Vec<bool>,
    driven_edges: Vec<u32>,
    driven_tets: Vec<u32>,
    gravity: Vec3,
    hash: Option<BoxHash>,
    active: ActiveSet,
    tool_tip: Option<Vec3>,
    time: f64,
    last_ins: f64,
    cur_ins: f64,
    hand_force: Vec3,
    residual: f64,
    projections: u64,
    scale: f64,
}

impl PbdTissue {
    /// Build the tissue of `scene` (exactly one tissue body) at `fidelity`.
    pub fn new(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        PbdTissueFactory.check(scene)?;
        scene.validate().map_err(|e| BuildError::bad("scene", e))?;
        let set = TissueSettings::resolve(scene, fidelity)?;
        let body = scene.tissues().next().expect("checked: one tissue");
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
        let m = body.material;
        let mu = m.youngs_modulus / (2.0 * (1.0 + m.poisson_ratio));
        let lam = m.youngs_modulus * m.poisson_ratio / ((1.0 + m.poisson_ratio) * (1.0 - 2.0 * m.poisson_ratio));
        let x: Vec<Vec3> = body.mesh.nodes.clone();
        let tets: Vec<[u32; 4]> = body.mesh.tets.iter().map(|t| t.map(|i| i as u32)).collect();
        let mut mass = vec![0.0; nn];
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
                mass[i as usize] += m.density * v.abs() / 4.0;
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
        let edge_rest: Vec<f64> = edges
            .iter()
            .map(|e| (x[e[1] as usize] - x[e[0] as usize]).norm())
            .collect();
        let edge_alpha: Vec<f64> = edge_k.iter().map(|k| 1.0 / k).collect();
        let tet_alpha: Vec<f64> = tet_rest
            .iter()
            .map(|v| if lam > 0.0 { v.abs() / lam } else { f64::INFINITY })
            .collect();
        let mut w: Vec<f64> = mass.iter().map(|&m| if m > 0.0 { 1.0 / m } else { 0.0 }).collect();
        let mut driven_mark = vec![false; nn];
        for &i in &body.fixed_nodes {
            w[i] = 0.0;
        }
        for &(i, _) in &body.driven_nodes {
            w[i] = 0.0;
            driven_mark[i] = true;
        }
        let driven_edges = (0..edges.len() as u32)
            .filter(|&e| edges[e as usize].iter().any(|&i| driven_mark[i as usize]))
            .collect();
        let driven_tets = (0..tets.len() as u32)
            .filter(|&t| tets[t as usize].iter().any(|&i| driven_mark[i as usize]))
            .collect();
        let hash = if set.hash_box > 0.0 {
            if body.driven_nodes.is_empty() {
                return Err(BuildError::bad(
                    "hash_box",
                    "local activation follows the tool (the driven nodes); this scene has none",
                ));
            }
            Some(BoxHash::new(&x, &body.mesh.tets, set.hash_box, set.hash_span))
        } else {
            None
        };
        let rest_volume = tet_rest.iter().map(|v| v.abs()).sum();
        let mut lo = Vec3::repeat(f64::INFINITY);
        let mut hi = Vec3::repeat(f64::NEG_INFINITY);
        for p in &x {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let mut s = Self {
            set,
            rest: x.clone(),
            v: vec![Vec3::zeros(); nn],
            x_prev: x.clone(),
            x,
            mass,
            w,
            lambda_e: vec![0.0; edges.len()],
            edges,
            edge_rest,
            edge_alpha,
            lambda_t: vec![0.0; tets.len()],
            tets,
            tet_rest,
            tet_alpha,
            tet_edges,
            rest_volume,
            driven: body.driven_nodes.clone(),
            driven_mark,
            driven_edges,
            driven_tets,
            gravity: scene.gravity,
            hash,
            active: ActiveSet {
                key: usize::MAX - 1,
                ..Default::default()
            },
            tool_tip: None,
            time: 0.0,
            last_ins: 0.0,
            cur_ins: 0.0,
            hand_force: Vec3::zeros(),
            residual: 0.0,
            projections: 0,
            scale: (hi - lo).norm(),
        };
        s.update_active();
        Ok(s)
    }

    /// Resolved settings.
    pub fn settings(&self) -> TissueSettings {
        self.set
    }

    /// Node positions (m).
    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }

    /// Count of constraint projections since the start (work measure).
    pub fn constraint_projections(&self) -> u64 {
        self.projections
    }

    /// Constraints (edges, tets) solved per iteration in the current active set.
    pub fn active_counts(&self) -> (usize, usize) {
        (self.active.edges.len(), self.active.tets.len())
    }

    /// Override the tool tip that selects the active box (m); `None` = the
    /// centroid of the driven nodes. Only used with local activation.
    pub fn set_tool_tip(&mut self, tip: Option<Vec3>) {
        self.tool_tip = tip;
    }

    fn tool_tip(&self) -> Vec3 {
        self.tool_tip.unwrap_or_else(|| {
            self.driven
                .iter()
                .map(|(i, d)| self.rest[*i] + d * self.cur_ins)
                .sum::<Vec3>()
                / self.driven.len().max(1) as f64
        })
    }

    /// Recompute the active set if the tool moved to another box.
    fn update_active(&mut self) {
        let nn = self.x.len();
        let Some(hash) = &self.hash else {
            if self.active.key != usize::MAX {
                self.active = ActiveSet {
                    key: usize::MAX,
                    edges: (0..self.edges.len() as u32).collect(),
                    tets: (0..self.tets.len() as u32)
                        .filter(|&t| self.tet_alpha[t as usize].is_finite())
                        .collect(),
                    nodes: (0..nn as u32).filter(|&i| self.w[i as usize] > 0.0).collect(),
                    w: self.w.clone(),
                    edge_on: vec![true; self.edges.len()],
                    tet_on: vec![true; self.tets.len()],
                };
            }
            return;
        };
        let b = hash.box_of(&self.tool_tip());
        let key = hash.linear_index(b);
        if key == self.active.key {
            return;
        }
        let (lo, hi) = hash.core_bounds(b);
        let tets_in = hash.tets(b);
        let mut edge_on = vec![false; self.edges.len()];
        let mut tet_on = vec![false; self.tets.len()];
        let mut node_on = vec![false; nn];
        let mut edges = Vec::new();
        let mut tets = Vec::new();
        for &t in tets_in {
            tet_on[t as usize] = true;
            if self.tet_alpha[t as usize].is_finite() {
                tets.push(t);
            }
            for &e in &self.tet_edges[t as usize] {
                if !edge_on[e as usize] {
                    edge_on[e as usize] = true;
                    edges.push(e);
                }
            }
            for &i in &self.tets[t as usize] {
                node_on[i as usize] = true;
            }
        }
        let mut w = vec![0.0; nn];
        let mut nodes = Vec::new();
        for i in 0..nn {
            let z = self.rest[i].z;
            if node_on[i] && self.w[i] > 0.0 && z >= lo.z && z <= hi.z {
                w[i] = self.w[i];
                nodes.push(i as u32);
            }
        }
        self.active = ActiveSet {
            key,
            edges,
            tets,
            nodes,
            w,
            edge_on,
            tet_on,
        };
    }

    fn substep(&mut self, h: f64, ins: f64) {
        let damp = 1.0 / (1.0 + self.set.damping * h);
        for &i in &self.active.nodes {
            let i = i as usize;
            self.v[i] = self.v[i] * damp + self.gravity * h;
            self.x_prev[i] = self.x[i];
            self.x[i] += self.v[i] * h;
        }
        for &(i, d) in &self.driven {
            self.x_prev[i] = self.x[i];
            self.x[i] = self.rest[i] + d * ins;
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        for &e in &self.active.edges {
            self.lambda_e[e as usize] = 0.0;
        }
        for &t in &self.active.tets {
            self.lambda_t[t as usize] = 0.0;
        }
        let h2 = h * h;
        let iters = self.set.iterations;
        for it in 0..iters {
            let last = it + 1 == iters;
            let mut res: f64 = 0.0;
            let w = &self.active.w;
            let x = &mut self.x;
            for &e in &self.active.edges {
                let e = e as usize;
                let [a, b] = self.edges[e].map(|i| i as usize);
                let (wa, wb) = (w[a], w[b]);
                let ws = wa + wb;
                if ws == 0.0 {
                    continue;
                }
                let d = x[b] - x[a];
                let len = d.norm();
                if len == 0.0 {
                    continue;
                }
                let n = d / len;
                let al = self.edge_alpha[e] / h2;
                let c = len - self.edge_rest[e];
                let num = -(c + al * self.lambda_e[e]);
                if last {
                    res = res.max(num.abs() / self.edge_rest[e]);
                }
                let dl = num / (ws + al);
                self.lambda_e[e] += dl;
                x[a] -= n * (wa * dl);
                x[b] += n * (wb * dl);
            }
            for &t in &self.active.tets {
                let t = t as usize;
                let idx = self.tets[t].map(|i| i as usize);
                let wt = idx.map(|i| w[i]);
                if wt.iter().all(|&c| c == 0.0) {
                    continue;
                }
                let mut p = idx.map(|i| x[i]);
                let al = self.tet_alpha[t] / h2;
                let r = project_volume(&mut p, wt, self.tet_rest[t], al, &mut self.lambda_t[t]);
                if last {
                    res = res.max(r / self.tet_rest[t].abs());
                }
                for k in 0..4 {
                    x[idx[k]] = p[k];
                }
            }
            if last {
                self.residual = res;
            }
        }
        self.projections += (iters * (self.active.edges.len() + self.active.tets.len())) as u64;
        for &i in &self.active.nodes {
            let i = i as usize;
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        // Reaction on the driven nodes: sum of grad C lambda / h^2 of the
        // constraints acting on them, plus their weight.
        let mut f = Vec3::zeros();
        for &e in &self.driven_edges {
            let e = e as usize;
            if !self.active.edge_on[e] {
                continue;
            }
            let [a, b] = self.edges[e].map(|i| i as usize);
            let n = (self.x[b] - self.x[a]).try_normalize(0.0).unwrap_or(Vec3::zeros());
            if self.driven_mark[a] {
                f -= n * self.lambda_e[e];
            }
            if self.driven_mark[b] {
                f += n * self.lambda_e[e];
            }
        }
        for &t in &self.driven_tets {
            let t = t as usize;
            if !self.active.tet_on[t] || !self.tet_alpha[t].is_finite() {
                continue;
            }
            let idx = self.tets[t].map(|i| i as usize);
            let g = tet_volume_gradients(&idx.map(|i| self.x[i]));
            for k in 0..4 {
                if self.driven_mark[idx[k]] {
                    f += g[k] * self.lambda_t[t];
                }
            }
        }
        let weight: Vec3 = self.driven.iter().map(|(i, _)| self.gravity * self.mass[*i]).sum();
        self.hand_force = f / h2 + weight;
    }

    fn check_state(&self) -> Option<String> {
        let lim = 10.0 * self.scale;
        for &i in &self.active.nodes {
            let i = i as usize;
            let p = self.x[i];
            if !p.iter().all(|c| c.is_finite()) {
                return Some(format!("node {i} is not finite"));
            }
            if (p - self.rest[i]).norm() > lim {
                return Some(format!(
                    "node {i} moved {:.3e} m, 10x the mesh size {:.3e} m",
                    (p - self.rest[i]).norm(),
                    self.scale
                ));
            }
        }
        None
    }

    /// Signed total volume over rest volume, minus one, and the inverted count.
    fn volume_stats(&self) -> (f64, usize) {
        let mut vol = 0.0;
        let mut inv = 0;
        for (t, tet) in self.tets.iter().enumerate() {
            let v = tet_volume(&tet.map(|i| self.x[i as usize]));
            let s = self.tet_rest[t].signum();
            vol += v * s;
            if v * s <= 0.0 {
                inv += 1;
            }
        }
        (vol / self.rest_volume - 1.0, inv)
    }

    fn energy(&self) -> EnergyObs {
        let mut e = EnergyObs::default();
        for i in 0..self.x.len() {
            e.kinetic += 0.5 * self.mass[i] * self.v[i].norm_squared();
            e.external -= self.mass[i] * self.gravity.dot(&self.x[i]);
        }
        for (k, ed) in self.edges.iter().enumerate() {
            let c = (self.x[ed[1] as usize] - self.x[ed[0] as usize]).norm() - self.edge_rest[k];
            e.elastic += 0.5 * c * c / self.edge_alpha[k];
        }
        for (t, tet) in self.tets.iter().enumerate() {
            if self.tet_alpha[t].is_finite() && self.tet_alpha[t] > 0.0 {
                let c = tet_volume(&tet.map(|i| self.x[i as usize])) - self.tet_rest[t];
                e.elastic += 0.5 * c * c / self.tet_alpha[t];
            }
        }
        e
    }
}

impl Model for PbdTissue {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!("time step must be > 0 s, got {dt}"),
            });
        }
        let ns = self.set.substeps;
        let h = dt / ns as f64;
        let a = self.last_ins;
        for s in 0..ns {
            let f = (s + 1) as f64 / ns as f64;
            let ins = a + f * (cmd.insertion - a);
            if self.hash.is_some() {
                self.cur_ins = ins;
                self.update_active();
            }
            self.substep(h, ins);
        }
        self.last_ins = cmd.insertion;
        self.time += dt;
        if let Some(reason) = self.check_state() {
            return Err(SimError::Diverged { t: self.time, reason });
        }
        Ok(StepStats {
            iterations: (self.set.iterations * ns) as u32,
            residual: self.residual,
            converged: self.residual <= 1e-6,
        })
    }

    fn observe(&self) -> Observation {
        let (volume_error, inverted) = self.volume_stats();
        Observation {
            time: self.time,
            rods: Vec::new(),
            tissues: vec![TissueObs {
                rest: self.rest.clone(),
                nodes: self.x.clone(),
                velocities: self.v.clone(),
                volume_error,
                inverted,
            }],
            contacts: Vec::new(),
            hand_force: self.hand_force,
            hand_torque: Vec3::zeros(),
            energy: self.energy(),
            constraint_residual: Some(self.residual),
        }
    }

    fn dt(&self) -> f64 {
        self.set.dt
    }
}
