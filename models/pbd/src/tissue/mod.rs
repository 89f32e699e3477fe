//! Tetrahedral XPBD tissue (model id `pbd-tissue`).
//!
//! Constraints, solved by colour-ordered Gauss-Seidel with XPBD compliance (Macklin, Müller &
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
//! * **rollers** (`TissueBody::partial_fixed`): one hard constraint per
//!   held world component, `C = x_c - X_c = 0` (`alpha = 0`, gradient the
//!   unit axis, so `dx_c = -C`), projected after each iteration's colour
//!   passes (and after the contacts);
//! * **sphere contact** (`TissueBody::indenter`): one unilateral hard
//!   constraint per boundary particle, `C = |x - c| - R >= 0` (the collision
//!   constraint of Müller et al. 2007 sec. 4.4, with XPBD's multiplier,
//!   Macklin et al. 2016 eqs. 17-18, `alpha = 0`): with `n = (x - c) / |x -
//!   c|` and the particle's inverse mass `W = w diag(free axes)` (a roller's
//!   held axes take no correction), `dlambda = -C / (n^T W n)`, clamped so
//!   the substep's accumulated `lambda >= 0` (the sphere pushes, never
//!   pulls: a separating particle gives back what it received, no more),
//!   and `dx = W n dlambda`. Projected after each iteration's colour passes,
//!   on the caller's thread in candidate order (so bit-identical for any
//!   thread count), with the centre `c` at the substep's load factor
//!   (`SphereIndenter::centre_at(load)`).
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
//! **Hand force**: the reaction on the driven nodes is minus the gradient of
//! the constraint energy `sum C^2 / (2 alpha)` at the current positions
//! (plus the driven nodes' weight), plus the force the body exerts on the
//! sphere, `-sum n dlambda / h^2` over the substep's contact projections,
//! i.e. `-sum_j n_j lambda_j / h^2` once the normals settle (a hard constraint
//! has no energy: its multiplier is its force, Macklin et al. 2016 eq. 9;
//! the same convention as hard volume constraints below). XPBD's own estimate
//! `sum grad C lambda / h^2` (kept as [`PbdTissue::multiplier_hand_force`])
//! equals it only when the substep's solve converged: the multipliers
//! restart from zero every substep, and on a stiff mesh (`k h^2 / m >> 1`)
//! a few Gauss-Seidel iterations leave them far short (wall-indentation at
//! mesh level 1, 10 iterations: 0.004 of the reference force from the
//! multipliers, 0.11 from the energy gradient).
//!
//! **Solve order and threads** ([`crate::color`]): the constraints are cut
//! into blocks of breadth-first node levels coloured alternately, so that the
//! blocks of one colour share no node; each iteration projects the blocks of
//! colour 0, then of colour 1, each block its edges then its tets, in greedy
//! constraint-colour order. The blocks of a colour run on `threads` workers
//! (fidelity extra, default `min(2, cores)`), and because they touch disjoint
//! nodes the result is bit-identical for any thread count. This ordering is
//! a Gauss-Seidel sweep like the plain one, only in another order; XPBD's
//! fixed point depends slightly on that order (each update uses the gradient
//! at the current iterate), e.g. the converged static sag of the test column
//! moved by 1e-4 relative when the order changed.
//!
//! **Local activation** ([`crate::BoxHash`], fidelity `hash_box` > 0): only the
//! tets of the active expanded boxes are solved. The active boxes are the
//! one holding the tool tip (the centroid of the driven nodes unless set
//! with [`PbdTissue::set_tool_tip`]) or, with a coupled instrument (surface
//! forces), every box holding a loaded contact-surface node. A node moves
//! if every tet around it is active; the nodes where the active tets meet
//! the others are held, and everything outside stays where it is (a node
//! the region leaves stops). The region is the boxes' in 3D, no axis
//! privileged, so it follows a tool along any vessel.
//!
//! Units are SI throughout.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use surgbench_core::{
    BuildError, DeviceCommand, EnergyObs, Model, Observation, Settings, SimError, StepStats, TissueBody, TissueObs,
    Vec3,
};

pub use crate::factory::{PbdTissueFactory, TISSUE_KEYS};

mod build;
mod solve;
mod statics;
pub use statics::{StaticInfo, StaticParams};

use crate::color::Partition;
use crate::hash::BoxHash;
use surgbench_core::mesh::{tet_volume_gradients, tet_volume_of as tet_volume};

/// One XPBD projection of the volume constraint of a tet: with
/// `C = V(p) - rest`, `dlambda = -(C + alpha_tilde lambda) / (sum_j w_j
/// |grad_j|^2 + alpha_tilde)` and `p_i += w_i grad_i dlambda` (for
/// `alpha_tilde = 0` this is `dp_i = -C w_i grad_i / sum_j w_j |grad_j|^2`).
/// Updates `lambda` and returns the residual `|C + alpha_tilde lambda|`
/// before the update (m^3).
#[inline]
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
    /// Worker threads of the constraint solve (1 = on the caller's thread).
    pub threads: usize,
}

impl TissueSettings {
    /// The tissue's knobs from resolved `settings` (ranges declared in
    /// [`crate::factory::TISSUE_KEYS`], checked by `surgbench_core::resolve`).
    pub fn from_settings(settings: &Settings) -> Result<Self, BuildError> {
        let f = settings.fidelity();
        let dt = f.dt.unwrap_or(1e-3);
        let iterations = f.iterations.unwrap_or(10);
        let substeps = settings.number_or("substeps", 1.0);
        let damping = settings.number_or("damping", 0.0);
        let hash_box = settings.number_or("hash_box", 0.0);
        let hash_span = settings.number_or("hash_span", hash_box / 3.0);
        crate::check_solver_knobs(dt, iterations)?;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = settings.number_or("threads", cores.min(2) as f64);
        Ok(Self {
            dt,
            iterations,
            substeps: substeps as usize,
            damping,
            hash_box,
            hash_span,
            threads: threads as usize,
        })
    }
}

/// What is solved this step: all constraints, or those of the active box.
#[derive(Debug, Clone, Default)]
struct ActiveSet {
    /// Linear indices of the active boxes, sorted (`[usize::MAX]`: the
    /// whole mesh; empty: nothing loaded, nothing moves).
    key: Vec<usize>,
    edges: Vec<u32>,
    tets: Vec<u32>,
    /// Nodes that move (free and active).
    nodes: Vec<u32>,
    /// Active edges of storage block `s`: `edges[edge_split[s]..edge_split[s + 1]]`.
    edge_split: Vec<usize>,
    /// Active tets of storage block `s`: `tets[tet_split[s]..tet_split[s + 1]]`.
    tet_split: Vec<usize>,
    /// Inverse masses used by the solve (0 for held nodes).
    w: Vec<f64>,
    edge_on: Vec<bool>,
    tet_on: Vec<bool>,
}

/// Node positions as relaxed atomics (`f64` bits, three per node), so that
/// the blocks of one colour, which touch disjoint nodes, can be projected by
/// several threads without `unsafe`. Relaxed loads and stores compile to
/// plain moves; the thread joins between colours order them.
#[derive(Debug, Default)]
struct AtomicPositions(Vec<AtomicU64>);

impl AtomicPositions {
    fn new(n: usize) -> Self {
        Self((0..3 * n).map(|_| AtomicU64::new(0)).collect())
    }
}

impl Clone for AtomicPositions {
    fn clone(&self) -> Self {
        Self(self.0.iter().map(|a| AtomicU64::new(a.load(Relaxed))).collect())
    }
}

/// Read and write one node of a position buffer.
trait NodeStore {
    fn node(&self, i: usize) -> Vec3;
    fn set_node(&self, i: usize, p: &Vec3);
}

impl NodeStore for [AtomicU64] {
    #[inline]
    fn node(&self, i: usize) -> Vec3 {
        let c = &self[3 * i..3 * i + 3];
        Vec3::new(
            f64::from_bits(c[0].load(Relaxed)),
            f64::from_bits(c[1].load(Relaxed)),
            f64::from_bits(c[2].load(Relaxed)),
        )
    }
    #[inline]
    fn set_node(&self, i: usize, p: &Vec3) {
        let c = &self[3 * i..3 * i + 3];
        c[0].store(p.x.to_bits(), Relaxed);
        c[1].store(p.y.to_bits(), Relaxed);
        c[2].store(p.z.to_bits(), Relaxed);
    }
}

impl AtomicPositions {
    fn get(&self, i: usize) -> Vec3 {
        self.0.node(i)
    }
    fn set(&self, i: usize, p: &Vec3) {
        self.0.set_node(i, p)
    }
}

/// `split[s]` = first position in the sorted id list `ids` at or after block
/// `s`'s first id `start[s]`.
fn split_by_blocks(ids: &[u32], start: &[usize]) -> Vec<usize> {
    start
        .iter()
        .map(|&s0| ids.partition_point(|&i| (i as usize) < s0))
        .collect()
}

/// Everything the block solve reads (see [`crate::color`]).
struct SolveCtx<'a> {
    x: &'a [AtomicU64],
    w: &'a [f64],
    edges: &'a [[u32; 2]],
    edge_rest: &'a [f64],
    edge_alpha: &'a [f64],
    tets: &'a [[u32; 4]],
    tet_rest: &'a [f64],
    tet_alpha: &'a [f64],
    act_edges: &'a [u32],
    act_tets: &'a [u32],
    edge_split: &'a [usize],
    tet_split: &'a [usize],
    edge_start: &'a [usize],
    tet_start: &'a [usize],
    inv_h2: f64,
    parallel: bool,
}

impl SolveCtx<'_> {
    /// Project the storage blocks `blocks` (all of one colour, so they touch
    /// disjoint nodes) whose multipliers are `lam_e` / `lam_t` (the blocks'
    /// contiguous ranges). Halves go to `rayon::join` when parallel: the
    /// result does not depend on which thread runs which block. Returns the
    /// largest relative residual seen when `last`.
    fn solve_blocks(&self, blocks: std::ops::Range<usize>, lam_e: &mut [f64], lam_t: &mut [f64], last: bool) -> f64 {
        if blocks.len() == 1 {
            return self.solve_block(blocks.start, lam_e, lam_t, last);
        }
        let mid = blocks.start + blocks.len() / 2;
        let (le, re) = lam_e.split_at_mut(self.edge_start[mid] - self.edge_start[blocks.start]);
        let (lt, rt) = lam_t.split_at_mut(self.tet_start[mid] - self.tet_start[blocks.start]);
        let (a, b) = if self.parallel {
            rayon::join(
                || self.solve_blocks(blocks.start..mid, le, lt, last),
                || self.solve_blocks(mid..blocks.end, re, rt, last),
            )
        } else {
            (
                self.solve_blocks(blocks.start..mid, le, lt, last),
                self.solve_blocks(mid..blocks.end, re, rt, last),
            )
        };
        a.max(b)
    }

    /// One Gauss-Seidel sweep over block `s`: its active edges, then its
    /// active tets, each in colour order.
    fn solve_block(&self, s: usize, lam_e: &mut [f64], lam_t: &mut [f64], last: bool) -> f64 {
        let (x, w) = (self.x, self.w);
        let mut res: f64 = 0.0;
        let e_off = self.edge_start[s];
        for &e in &self.act_edges[self.edge_split[s]..self.edge_split[s + 1]] {
            let e = e as usize;
            let [a, b] = self.edges[e].map(|i| i as usize);
            let (wa, wb) = (w[a], w[b]);
            let ws = wa + wb;
            if ws == 0.0 {
                continue;
            }
            let (xa, xb) = (x.node(a), x.node(b));
            let d = xb - xa;
            let len = d.norm();
            if len == 0.0 {
                continue;
            }
            let n = d / len;
            let al = self.edge_alpha[e] * self.inv_h2;
            let c = len - self.edge_rest[e];
            let lam = &mut lam_e[e - e_off];
            let num = -(c + al * *lam);
            if last {
                res = res.max(num.abs() / self.edge_rest[e]);
            }
            let dl = num / (ws + al);
            *lam += dl;
            x.set_node(a, &(xa - n * (wa * dl)));
            x.set_node(b, &(xb + n * (wb * dl)));
        }
        let t_off = self.tet_start[s];
        for &t in &self.act_tets[self.tet_split[s]..self.tet_split[s + 1]] {
            let t = t as usize;
            let idx = self.tets[t].map(|i| i as usize);
            let wt = idx.map(|i| w[i]);
            if wt.iter().all(|&c| c == 0.0) {
                continue;
            }
            let mut p = idx.map(|i| x.node(i));
            let al = self.tet_alpha[t] * self.inv_h2;
            let r = project_volume(&mut p, wt, self.tet_rest[t], al, &mut lam_t[t - t_off]);
            if last {
                res = res.max(r / self.tet_rest[t].abs());
            }
            for k in 0..4 {
                x.set_node(idx[k], &p[k]);
            }
        }
        res
    }
}

/// A point-like body for [`PbdTissue::collide_particles`]: a catheter or
/// guidewire particle with its contact radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParticle {
    /// Position (m).
    pub x: Vec3,
    /// Inverse mass (1/kg); 0 for a kinematic (driven) particle.
    pub inv_mass: f64,
    /// Contact radius (m): the particle is kept this far on the lumen side.
    pub radius: f64,
}

/// One particle-wall contact resolved by [`PbdTissue::collide_particles`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParticleContact {
    /// Index into the particles.
    pub particle: usize,
    /// Ghost-surface triangle.
    pub triangle: usize,
    /// Barycentric weights of the contact point on the triangle.
    pub bary: [f64; 3],
    /// Unit normal into the lumen.
    pub normal: Vec3,
    /// Summed multiplier over the rounds (kg m): the mass-weighted
    /// correction the particle received along the rounds' normals, i.e. an
    /// impulse of magnitude about `lambda / h` (N s) over the last substep `h`.
    pub lambda: f64,
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
    /// Tets around each node (local activation moves a node only if all
    /// of them are active).
    tets_around: Vec<u32>,
    /// Local activation: times the active set was rebuilt (the boxes
    /// changed), and active tets summed over substeps with the count of
    /// substeps, for the mean active fraction.
    activations: usize,
    active_tets_sum: f64,
    active_samples: usize,
    active: ActiveSet,
    /// Constraint storage order and blocks ([`crate::color`]).
    part: Partition,
    /// Positions during the solve, shared by the block workers.
    xa: AtomicPositions,
    /// Worker pool when `threads > 1`.
    pool: Option<Arc<rayon::ThreadPool>>,
    tool_tip: Option<Vec3>,
    time: f64,
    last_ins: f64,
    cur_ins: f64,
    hand_force: Vec3,
    /// Hand force from the multipliers (N), see [`PbdTissue::multiplier_hand_force`].
    multiplier_force: Vec3,
    residual: f64,
    projections: u64,
    scale: f64,
    /// Length of the last substep (s); velocities of contact corrections.
    last_h: f64,
    /// Free (not fixed, not driven) nodes on rollers, with their held axes.
    rollers: Vec<(u32, [bool; 3])>,
    /// Unilateral contact with the scene's rigid sphere, if any.
    sphere: Option<SphereContact>,
    /// Force the body exerts on the sphere in the last substep (N).
    sphere_force: Vec3,
    /// The scene's contact-surface nodes (`TissueBody::surface_vertices`).
    surface: Vec<usize>,
    /// Dead force on each node from a coupled instrument (N, world frame;
    /// zero off the contact surface), set by `Model::set_surface_forces`.
    external: Vec<Vec3>,
}

/// The hard unilateral contact of the boundary particles with a rigid
/// sphere (see the module docs).
#[derive(Debug, Clone)]
struct SphereContact {
    path: surgbench_core::scene::SphereIndenter,
    /// Centre in the current substep (m).
    centre: Vec3,
    /// Candidate particles: boundary nodes that move.
    nodes: Vec<u32>,
    /// Axes each candidate may move along (1) or not (0, roller).
    free: Vec<Vec3>,
    /// Multipliers accumulated over the current substep (kg m).
    lambda: Vec<f64>,
    /// `sum n dlambda` over the substep's projections (kg m), each with the
    /// normal it was applied along: the momentum the sphere gave the body
    /// times `h` (rollers take the part along their held axes).
    impulse: Vec3,
}

impl SphereContact {
    /// Project every candidate once against the sphere (Gauss-Seidel, in
    /// candidate order), reading and writing `x`; `w` the inverse masses.
    fn project(&mut self, x: &[AtomicU64], w: &[f64]) {
        let r = self.path.radius;
        for (j, &i) in self.nodes.iter().enumerate() {
            let i = i as usize;
            let wi = w[i];
            if wi == 0.0 {
                continue;
            }
            let p = x.node(i);
            let rel = p - self.centre;
            let d = rel.norm();
            let c = d - r;
            // Outside with nothing to give back, or at the centre (no normal).
            if (c >= 0.0 && self.lambda[j] == 0.0) || d == 0.0 {
                continue;
            }
            let n = rel / d;
            let wn = n.component_mul(&self.free[j]);
            let den = wi * n.dot(&wn);
            if den == 0.0 {
                continue;
            }
            let lam = (self.lambda[j] - c / den).max(0.0);
            let dl = lam - self.lambda[j];
            self.lambda[j] = lam;
            self.impulse += n * dl;
            x.set_node(i, &(p + wn * (wi * dl)));
        }
    }

    /// Force the body exerts on the sphere (N): minus the contact forces
    /// on the particles, `-sum n dlambda / h^2` over the substep's
    /// projections (`sum_j n_j lambda_j / h^2` when the normals settle).
    fn reaction(&self, h2: f64) -> Vec3 {
        -self.impulse / h2
    }
}

/// Reset the held components of the roller nodes to their rest values
/// (hard constraints `x_c - X_c = 0`); `w` = 0 marks nodes that do not move.
fn project_rollers(rollers: &[(u32, [bool; 3])], rest: &[Vec3], x: &[AtomicU64], w: &[f64]) {
    for &(i, axes) in rollers {
        let i = i as usize;
        if w[i] == 0.0 {
            continue;
        }
        let mut p = x.node(i);
        for a in 0..3 {
            if axes[a] {
                p[a] = rest[i][a];
            }
        }
        x.set_node(i, &p);
    }
}

impl PbdTissue {
    /// Resolved settings.
    pub fn settings(&self) -> TissueSettings {
        self.set
    }

    /// Lumped node masses (kg): a quarter of each adjacent tet's.
    pub fn masses(&self) -> &[f64] {
        &self.mass
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

    /// Force the body exerts on the sphere (N) in the last substep, from the
    /// contact multipliers: `-sum_j n_j lambda_j / h^2`; zero without one.
    /// Part of both [`Self::multiplier_hand_force`] and the observed
    /// `hand_force`.
    pub fn sphere_force(&self) -> Vec3 {
        self.sphere_force
    }

    /// Reaction on the driven nodes (N) estimated from the last substep's
    /// XPBD multipliers plus the driven nodes' weight (plus the force on the
    /// sphere, [`Self::sphere_force`]); the observed `hand_force` uses the
    /// constraint energy's gradient instead (see the module docs). The two
    /// agree when the solve converged; their gap measures how far it is from
    /// converged.
    pub fn multiplier_hand_force(&self) -> Vec3 {
        self.multiplier_force
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
            e.external -= (self.mass[i] * self.gravity + self.external[i]).dot(&self.x[i]);
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
        SimError::check_dt(self.time, dt)?;
        let ns = self.set.substeps;
        let h = dt / ns as f64;
        let a = self.last_ins;
        for s in 0..ns {
            let f = (s + 1) as f64 / ns as f64;
            let ins = a + f * (cmd.load - a);
            if self.hash.is_some() {
                self.cur_ins = ins;
                self.update_active();
                self.active_tets_sum += self.active.tets.len() as f64;
                self.active_samples += 1;
            }
            self.substep(h, ins);
        }
        self.last_ins = cmd.load;
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
                rest_dihedral_deg: None,
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

    fn surface_positions(&self) -> Option<Vec<Vec3>> {
        (!self.surface.is_empty()).then(|| self.surface.iter().map(|&i| self.x[i]).collect())
    }

    /// Dead forces on the contact-surface nodes: each free node's predicted
    /// velocity gains `w f h` per substep (Macklin et al. 2016, Alg. 1: the
    /// external force in the prediction); a fixed or driven node's are
    /// carried by its support.
    fn set_surface_forces(&mut self, forces: &[Vec3]) -> Result<(), SimError> {
        surgbench_core::coupling::store_surface_forces(&self.surface, forces, &mut self.external).map_err(|e| {
            SimError::SolverFailed {
                t: self.time,
                reason: format!("pbd-tissue: {e}"),
            }
        })
    }

    /// The whole model (positions, velocities, multipliers, the active set
    /// and the surface forces): a coupling retrying a step restores it.
    fn save_state(&self) -> Option<Box<dyn std::any::Any + Send>> {
        Some(Box::new(self.clone()))
    }

    fn restore_state(&mut self, state: &(dyn std::any::Any + Send)) -> Result<(), SimError> {
        let t = self.time;
        surgbench_core::model::restore_clone(self, state, "pbd-tissue", t)
    }

    /// `static_hand_force_n`: the hand force (magnitude) at the converged
    /// static equilibrium of this model's energy with the tool where it is
    /// ([`PbdTissue::static_equilibrium`]); `xpbd_over_static_force`: the
    /// observed hand force projected on it over its magnitude (1 when XPBD
    /// has converged and settled; below 1 measures iteration error);
    /// `static_rel_residual` and `static_converged` (1 or 0) certify the solve.
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        let mut d = std::collections::BTreeMap::new();
        if self.hash.is_some() {
            d.insert("hash_activations".into(), self.activations as f64);
            let all = self.tet_alpha.iter().filter(|a| a.is_finite()).count().max(1) as f64;
            d.insert(
                "hash_active_tets_fraction_mean".into(),
                self.active_tets_sum / self.active_samples.max(1) as f64 / all,
            );
        }
        // The static equilibrium holds the fixed and driven nodes and knows
        // no surface forces: a coupled wall has no static reference.
        if !self.surface.is_empty() {
            return d;
        }
        let Ok(s) = self.static_equilibrium(&StaticParams::default()) else {
            return d;
        };
        let f2 = s.hand_force.norm_squared();
        d.insert("static_hand_force_n".into(), s.hand_force.norm());
        if f2 > 0.0 {
            d.insert("xpbd_over_static_force".into(), self.hand_force.dot(&s.hand_force) / f2);
        }
        d.insert("static_rel_residual".into(), s.rel_residual);
        d.insert("static_converged".into(), if s.converged { 1.0 } else { 0.0 });
        d
    }
}
