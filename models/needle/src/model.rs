//! [`NeedleModel`]: one coupled time step of FEM tissue and DER needle (the
//! needle seed's Algorithm 1, Chentanez et al. 2009), with embedded coupling
//! points and the friction-state LCP of [`crate::lcp`], each trial solved
//! through the Schur complement on the coupling points or, as the seed
//! does, by conjugate gradients over the whole coupled system
//! ([`LcpSolver`]).

use crate::coupling::{Embedded, OnNeedle, frame, locate, locate_within, on_needle};
use crate::gram::TissueGram;
use crate::lcp::{self, Bounds, Solution, State};
use crate::pcg::{self, Row};
use crate::regions::BuiltLabels;
use crate::remesh::{Place, Remesher, carry_over};
use nalgebra::DMatrix;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use surgbench_core::{
    DeviceCommand, Model, NeedleTissue, Observation, SimError, StepStats, TetMesh, TissueBody, Vec3, mesh,
};
use surgbench_der::DerRod;
use surgbench_fem::{FemModel, LinearStep};

/// The seed's LCP check tolerance `tau_check` (Sec. 3.3).
pub const TAU_CHECK: f64 = 1e-3;
/// The seed's trial limit of the LCP (Algorithm 3).
pub const MAX_TRIALS: usize = 10;
/// How far (barycentric) outside its nearest tet a new channel end may lie
/// and still count as inside the tissue: a quarter of a tet, so that gaps
/// the deformed mesh opens around the tip do not drop the tip point, while
/// a tip that leaves the tissue loses it within a quarter tet.
pub const TIP_SLACK: f64 = 0.25;

/// How each configuration (trial) of the LCP is solved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LcpSolver {
    /// Factor the tissue and needle blocks once per step and solve every
    /// trial through the small Schur complement `W` on the coupling points.
    Schur,
    /// The seed's solver: projected preconditioned conjugate gradients over
    /// the whole coupled system for every trial ([`crate::pcg`]), warm
    /// started from the last trial; no tissue factorization.
    Cg {
        /// Relative residual it stops at (`sqrt(r . P r) / sqrt(b . D^-1 b)`).
        tolerance: f64,
    },
}

/// CG tolerance when the settings leave `cg_tolerance` unset: the LCP's
/// checks work at `tau_check = 1e-3` of the forces, so a residual 1e-8 of
/// the right-hand side leaves them five orders of margin.
pub const CG_TOLERANCE: f64 = 1e-8;

/// A coupling point: a tissue material point held on the needle at an
/// arclength, with its friction state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// The tissue material point.
    pub tissue: Embedded,
    /// Needle arclength it sits at (m from the clamp).
    pub arclength: f64,
    /// Friction state of the last step.
    pub state: State,
}

/// LCP statistics over the run (the seed's Table 3).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LcpStats {
    /// Coupled steps (steps with at least one coupling point).
    pub steps: usize,
    /// Every step taken, coupled or not.
    pub all_steps: usize,
    /// Tet stiffness blocks rebuilt, summed over all steps (every tet every
    /// step unless the tissue's lazy Jacobian keeps some).
    pub tets_updated: usize,
    /// Numeric factorizations of the tissue matrix (a step whose blocks
    /// all stayed keeps the last; the CG solver factors none).
    pub factorizations: usize,
    /// Configurations solved over those steps.
    pub trials: usize,
    /// Most configurations in one step.
    pub max_trials: usize,
    /// Fewest configurations in one coupled step (0 before the first).
    pub min_trials: usize,
    /// Steps that ended without a consistent configuration.
    pub unresolved: usize,
    /// Cuts whose new channel end no tet of the deformed mesh contains
    /// strictly (inverted or sliver tets around the tip), found within
    /// [`TIP_SLACK`] instead.
    pub tip_fallbacks: usize,
    /// Times the tip point was dropped: the tip left the tissue.
    pub tip_lost: usize,
    /// CG iterations (products with the coupled matrix) over all steps,
    /// counting each step's unconstrained solve and every trial; 0 with the
    /// Schur solver.
    pub linear_iterations: usize,
    /// Most CG iterations in one step.
    pub max_linear_iterations: usize,
    /// CG solves (each step's unconstrained solve and one per trial).
    pub linear_solves: usize,
    /// CG solves that stopped at the iteration limit above the tolerance.
    pub linear_unconverged: usize,
}

/// Frame, needle and tissue stencils and start-of-step gap of one point.
struct Geometry {
    frame: [Vec3; 3],
    needle: OnNeedle,
    tissue: [usize; 4],
    w: [f64; 4],
    gap: Vec3,
}

impl Geometry {
    /// The world force (N) of frame components `lambda` (`[t, n1, n2]`).
    fn force(&self, lambda: &[f64]) -> Vec3 {
        (0..3).map(|r| self.frame[r] * lambda[r]).sum()
    }
}

/// Wall time of each phase of the steps so far (the needle seed's Table 2
/// columns): the tissue's linear step (assembly, factorization, update),
/// the needle's, the coupling (geometry, Delassus operator or CG solves,
/// the LCP's trials, the points' update) and the tip remeshing (operations
/// and the tissue's rebuild on the new mesh).
#[derive(Debug, Clone, Copy, Default)]
struct PhaseTimes {
    frame: Duration,
    tissue: Duration,
    needle: Duration,
    lcp: Duration,
    remesh: Duration,
}

/// The coupled needle-tissue model (module docs).
pub struct NeedleModel {
    fem: FemModel,
    rod: DerRod,
    tets: Vec<[usize; 4]>,
    coupling: NeedleTissue,
    /// Shaft points, ordered by arclength.
    shaft: Vec<Point>,
    /// The tip point: the tissue at the end of the cut channel. It takes
    /// part in the LCP only while it touches the tip (the tip pushes and
    /// cuts, it cannot pull: retracting, the channel end stays behind).
    tip: Option<Point>,
    /// Whether the channel end touches the tip.
    touching: bool,
    spacing: f64,
    dt: f64,
    /// Force on the clamped needle nodes from coupling points next to the
    /// clamp (N): the hand carries it.
    clamp_share: Vec3,
    /// The tissue material point where the needle entered (not coupled:
    /// it marks where the shaft inside the tissue begins).
    entry: Option<Embedded>,
    stats: LcpStats,
    solver: LcpSolver,
    /// Tip remeshing (`coupling = "remesh"`): every coupling point a node.
    remesh: Option<Remeshing>,
    /// The smallest tet volume ratio `V / V0` at the end of any step so
    /// far: a point-loaded node squeezes its elements towards collapse.
    volume_ratio_min: f64,
    times: PhaseTimes,
    /// Smallest and largest dihedral angle (deg) of the rest mesh as built,
    /// and now: that range widened by the tets around the remesher's nodes
    /// (every tet an operation made has one of them; the others are the
    /// mesh's own).
    dihedral_built: [f64; 2],
    dihedral: [f64; 2],
    /// The cutting force (N) in each tet (a layered body's per-region
    /// `f_cut`, [`NeedleModel::with_layers`]); empty: the interaction's
    /// `cutting_force` everywhere.
    cut_of_tet: Vec<f64>,
    /// The cutting force (N) of each material index of a layered body
    /// (`TissueBody::tet_materials`: the body's first, then its regions');
    /// empty for a uniform one.
    material_cuts: Vec<f64>,
    /// The tissue's share of `W` kept while its factor stays.
    gram: TissueGram,
}

/// The remeshed variant's state (issue 18): the remesher over the tissue's
/// rest mesh, the scene's body on the mesh the tissue was last built on
/// (to rebuild it on the next one) and which nodes stand for the entry and
/// the tip.
///
/// Stack order: the entry's operation first, then the shaft points' in the
/// order they were cut, the tip's on top (so that it can move with the
/// tip). A shaft point the retracting tip leaves keeps its node (the
/// channel stays cut) until a new shaft point within half a spacing reuses
/// it; the needle leaving the tissue takes every operation back.
struct Remeshing {
    remesher: Remesher,
    body: TissueBody,
    gravity: Vec3,
    entry_node: Option<usize>,
    tip_node: Option<usize>,
    /// Operations applied and taken back, tissue rebuilds, and points the
    /// remesher found no valid operation for (left embedded that step).
    ops: usize,
    rebuilds: usize,
    refused: usize,
    /// Elastic energy (J) the operations took out of the tissue, summed over
    /// rebuilds (negative: put in): an on-simplex split keeps it, taking a
    /// displaced node back or snapping one does not.
    released: f64,
    /// The largest change of elastic energy (J) in one rebuild, either sign.
    energy_jump_max: f64,
    /// The farthest (m, material coordinates) the tip's node moved in one
    /// step.
    tip_jump_max: f64,
    /// A layered tissue's labels as built, to label the tets operations
    /// make; `None` for a uniform tissue.
    labels: Option<BuiltLabels>,
}

/// The dihedral range (deg) of `mesh` (the remesher's, at rest) given that
/// of the mesh as built: widened by every tet around a node of the
/// remesher's operations. Every tet an operation made or reshaped has such
/// a node; the others are tets as built, whose range `built` bounds.
fn remeshed_dihedral(remesher: &Remesher, mesh: &TetMesh, built: [f64; 2]) -> [f64; 2] {
    let mut tets: Vec<usize> = remesher
        .stack()
        .iter()
        .flat_map(|o| remesher.tets_of(o.node).iter().copied())
        .collect();
    tets.sort_unstable();
    tets.dedup();
    tets.iter().fold(built, |[lo, hi], &t| {
        let a = mesh::dihedral_angles(mesh.tets[t].map(|i| mesh.nodes[i]));
        a.iter().fold([lo, hi], |[lo, hi], x| {
            let d = x.to_degrees();
            [lo.min(d), hi.max(d)]
        })
    })
}

/// The time since `mark`, and `mark` moved to now.
fn lap(mark: &mut Instant) -> Duration {
    let now = Instant::now();
    let d = now - *mark;
    *mark = now;
    d
}

/// The node `e` sits on, if its weights are one-hot.
fn node_of(tets: &[[usize; 4]], e: &Embedded) -> Option<usize> {
    let k = e.w.iter().position(|&w| w == 1.0)?;
    e.w.iter().all(|&w| w == 1.0 || w == 0.0).then(|| tets[e.tet][k])
}

impl NeedleModel {
    /// Couple a tissue and a needle (both built for the same `dt`, s) with
    /// the interaction `coupling`; a new shaft point is dropped every
    /// `spacing` (m) of cut.
    pub fn new(
        fem: FemModel,
        rod: DerRod,
        tets: Vec<[usize; 4]>,
        coupling: NeedleTissue,
        spacing: f64,
        dt: f64,
    ) -> Self {
        let built = TetMesh {
            nodes: fem.observe().tissues.swap_remove(0).rest,
            tets: tets.clone(),
        };
        let q = mesh::quality(&built);
        let dihedral = [q.min_dihedral_deg, q.max_dihedral_deg];
        Self {
            fem,
            rod,
            tets,
            coupling,
            shaft: Vec::new(),
            tip: None,
            touching: false,
            spacing,
            dt,
            clamp_share: Vec3::zeros(),
            entry: None,
            stats: LcpStats::default(),
            solver: LcpSolver::Schur,
            remesh: None,
            volume_ratio_min: f64::INFINITY,
            times: PhaseTimes::default(),
            dihedral_built: dihedral,
            dihedral,
            cut_of_tet: Vec::new(),
            material_cuts: Vec::new(),
            gram: TissueGram::default(),
        }
        .pre_inserted()
    }

    /// The same model on the layered tissue `body` (the one it was built
    /// from): each tet cuts at its region's force (N; the interaction's
    /// `cutting_force` where a region gives none), the seed's per-layer
    /// `f_cut`, large across a membrane so that the tip tents it until the
    /// force reaches it, then punctures. The tip cuts at the force of the
    /// tet its channel end lies in. Before [`NeedleModel::with_remeshing`],
    /// which carries the regions onto the tets it makes; the caller checks
    /// that the body is the model's.
    pub fn with_layers(mut self, body: &TissueBody) -> Self {
        assert!(
            body.mesh.tets.len() == self.tets.len() && self.remesh.is_none(),
            "layers: the body the model was built from ({} tets, got {}), before remeshing",
            self.tets.len(),
            body.mesh.tets.len()
        );
        let base = self.coupling.cutting_force;
        self.material_cuts = std::iter::once(base)
            .chain(body.regions.iter().map(|r| r.cutting_force.unwrap_or(base)))
            .collect();
        let (_, of) = body.tet_materials();
        self.set_cuts(&of);
        self
    }

    /// The cutting force of every tet from its material index (`labels`,
    /// as `TissueBody::tet_materials` numbers them; empty: uniform).
    fn set_cuts(&mut self, labels: &[usize]) {
        self.cut_of_tet = labels.iter().map(|&k| self.material_cuts[k]).collect();
    }

    /// The force (N) the tip needs to cut where its channel ends.
    fn tip_cutting_force(&self) -> f64 {
        match &self.tip {
            Some(p) if !self.cut_of_tet.is_empty() => self.cut_of_tet[p.tissue.tet],
            _ => self.coupling.cutting_force,
        }
    }

    /// The same model with the seed's tip remeshing (issue 18): every
    /// coupling point becomes a node of the tissue mesh, placed by the
    /// remesher ([`crate::remesh`]) and carried along as the tip cuts.
    /// `body` is the tissue the model was built from (its fixed and driven
    /// nodes are never snapped), `gravity` the scene's (m/s^2), `max_offset`
    /// the remesher's limit on field-changing operations
    /// ([`Remesher::set_max_offset`]; infinite: the seed's rule).
    pub fn with_remeshing(mut self, body: TissueBody, gravity: Vec3, max_offset: f64) -> Result<Self, SimError> {
        let mut remesher = Remesher::new(&body.mesh);
        remesher.pin(
            body.fixed_nodes
                .iter()
                .copied()
                .chain(body.driven_nodes.iter().map(|d| d.0))
                .chain(body.partial_fixed.iter().map(|p| p.0)),
        );
        remesher.set_max_offset(max_offset);
        let labels = (!body.regions.is_empty()).then(|| BuiltLabels::new(&body));
        self.remesh = Some(Remeshing {
            remesher,
            body,
            gravity,
            entry_node: None,
            tip_node: None,
            ops: 0,
            rebuilds: 0,
            refused: 0,
            released: 0.0,
            energy_jump_max: 0.0,
            tip_jump_max: 0.0,
            labels,
        });
        self.realize()?;
        Ok(self)
    }

    /// Remeshed variant: make every coupling point (and the entry) a mesh
    /// node, then continue the tissue on the new mesh. Points that are
    /// already nodes stay; new ones (the entry, a shaft point just added,
    /// the tip after it cut on) get a node at their material point; the
    /// tip's node moves with it (the top operation taken back and the best
    /// one for the new point applied). A needle that has left the tissue
    /// takes every operation back.
    fn realize(&mut self) -> Result<(), SimError> {
        let Some(mut rm) = self.remesh.take() else {
            return Ok(());
        };
        let out = self.realize_with(&mut rm);
        self.remesh = Some(rm);
        out
    }

    fn realize_with(&mut self, rm: &mut Remeshing) -> Result<(), SimError> {
        let t = self.fem.time();
        let xt = self.fem.positions();
        // The mesh the tissue is on (the remesher's until it changes below).
        let old = &rm.body.mesh;
        let material = |e: &Embedded| -> Vec3 { (0..4).map(|k| old.nodes[old.tets[e.tet][k]] * e.w[k]).sum() };
        let ops_before = rm.ops;
        // Out of the tissue (the tip a quarter spacing behind the entry,
        // along the needle's last edge; at entry the two coincide): the
        // channel closes, the mesh is the original.
        let last = self.rod.num_nodes() - 1;
        let tip_x = self.rod.node(last);
        let along = (tip_x - self.rod.node(last - 1)).normalize();
        let out = self
            .entry
            .is_some_and(|e| (tip_x - e.position(&self.tets, &xt)).dot(&along) < -0.25 * self.spacing);
        if out {
            while rm.remesher.pop().is_some() {
                rm.ops += 1;
            }
            self.entry = None;
            self.tip = None;
            self.shaft.clear();
            self.touching = false;
            rm.entry_node = None;
            rm.tip_node = None;
        }
        // Every point's material point and node (None: not a node yet).
        let entry_u = self.entry.map(|e| material(&e));
        let shaft_u: Vec<Vec3> = self.shaft.iter().map(|p| material(&p.tissue)).collect();
        let mut shaft_nodes: Vec<Option<usize>> = self.shaft.iter().map(|p| node_of(&old.tets, &p.tissue)).collect();
        let tip_u = self.tip.map(|p| material(&p.tissue));
        let tip_moved = self
            .tip
            .is_some_and(|p| rm.tip_node.is_none() || node_of(&old.tets, &p.tissue) != rm.tip_node);
        let fresh_below = (self.entry.is_some() && rm.entry_node.is_none()) || shaft_nodes.iter().any(Option::is_none);
        // The tip gets its own node only half a spacing clear of the entry
        // and the shaft points (closer, every operation leaves a sliver);
        // until then it stays embedded.
        let clear = tip_u.is_some_and(|u| {
            entry_u
                .iter()
                .chain(&shaft_u)
                .all(|c| (c - u).norm() >= 0.5 * self.spacing)
        });
        let mut tip_node = rm.tip_node;
        let tip_was = tip_node.map(|n| old.nodes[n]);
        if tip_node.is_some() && (fresh_below || !clear || self.tip.is_none()) {
            // New nodes go below the tip's, and a tip that is not clear (or
            // lost) gives its node back: take its operation back.
            rm.remesher.pop();
            rm.ops += 1;
            tip_node = None;
        }
        if let (Some(u), None) = (entry_u, rm.entry_node) {
            if let Ok(p) = rm.remesher.place(u, Place::New) {
                rm.entry_node = Some(p.node);
                rm.ops += 1;
            } else {
                rm.refused += 1;
            }
        }
        for i in 0..self.shaft.len() {
            if shaft_nodes[i].is_some() {
                continue;
            }
            let u = shaft_u[i];
            // A channel node a retraction left behind, within half a
            // spacing: couple it again instead of crowding a new one next
            // to it.
            let coupled: Vec<usize> = shaft_nodes.iter().flatten().copied().chain(rm.entry_node).collect();
            let reuse = rm
                .remesher
                .stack()
                .iter()
                .map(|o| o.node)
                .filter(|n| !coupled.contains(n))
                .map(|n| ((rm.remesher.nodes()[n] - u).norm(), n))
                .filter(|(d, _)| *d < 0.5 * self.spacing)
                .min_by(|a, b| a.0.total_cmp(&b.0));
            shaft_nodes[i] = match reuse {
                Some((_, n)) => Some(n),
                None => match rm.remesher.place(u, Place::New) {
                    Ok(p) => {
                        rm.ops += 1;
                        Some(p.node)
                    }
                    Err(_) => {
                        rm.refused += 1;
                        None
                    }
                },
            };
        }
        if let Some(u) = tip_u.filter(|_| clear && (tip_moved || tip_node.is_none()))
            && !out
        {
            let mode = if tip_node.is_some() { Place::Move } else { Place::New };
            match rm.remesher.place(u, mode) {
                Ok(p) => {
                    tip_node = Some(p.node);
                    rm.ops += 1;
                    if let Some(w) = tip_was {
                        rm.tip_jump_max = rm.tip_jump_max.max((u - w).norm());
                    }
                }
                Err(_) => {
                    // Left embedded (its old node, if it had one, taken back).
                    if tip_node.take().is_some() {
                        rm.remesher.pop();
                        rm.ops += 1;
                    }
                    rm.refused += 1;
                }
            }
        }
        rm.tip_node = tip_node;
        if rm.ops == ops_before {
            return Ok(());
        }
        // Continue the tissue on the new mesh and re-express every point
        // on it: a node's point one-hot in a tet around it, a point that is
        // not a node by its material point (slots may have changed).
        let mesh = rm.remesher.mesh();
        let (v, a) = self.fem.motion();
        let fail = |reason: String| SimError::SolverFailed { t, reason };
        let f = carry_over(&rm.body.mesh.nodes, &rm.body.mesh.tets, &mesh.nodes, &[&xt, v, a])
            .map_err(|e| fail(format!("tip remeshing: {e}")))?;
        rm.body.mesh = mesh;
        if let Some(built) = &rm.labels {
            let labels = built.labels(&rm.body.mesh);
            BuiltLabels::relabel(&mut rm.body, &labels);
            self.set_cuts(&labels);
        }
        let mesh = &rm.body.mesh;
        let before = self.fem.elastic_energy();
        self.fem = self
            .fem
            .remeshed(&rm.body, rm.gravity, &f[0], &f[1], &f[2])
            .map_err(|e| fail(format!("tissue on the remeshed mesh: {e}")))?;
        let change = before - self.fem.elastic_energy();
        rm.released += change;
        self.dihedral = remeshed_dihedral(&rm.remesher, mesh, self.dihedral_built);
        rm.energy_jump_max = rm.energy_jump_max.max(change.abs());
        rm.rebuilds += 1;
        self.tets = mesh.tets.clone();
        let at = |n: Option<usize>, u: Vec3| -> Result<Embedded, SimError> {
            match n {
                Some(n) => {
                    let tet = rm.remesher.tets_of(n)[0];
                    let mut w = [0.0; 4];
                    w[mesh.tets[tet].iter().position(|&i| i == n).expect("the node's tet")] = 1.0;
                    Ok(Embedded { tet, w })
                }
                None => locate_within(&mesh.tets, &mesh.nodes, &u, TIP_SLACK)
                    .ok_or_else(|| fail("a coupling point left the remeshed tissue".into())),
            }
        };
        if let (Some(e), Some(u)) = (&mut self.entry, entry_u) {
            *e = at(rm.entry_node, u)?;
        }
        for ((p, n), u) in self.shaft.iter_mut().zip(&shaft_nodes).zip(&shaft_u) {
            p.tissue = at(*n, *u)?;
        }
        if let (Some(tip), Some(u)) = (&mut self.tip, tip_u) {
            tip.tissue = at(rm.tip_node, u)?;
        }
        Ok(())
    }

    /// The same model with each LCP trial solved by `solver`.
    pub fn with_solver(mut self, solver: LcpSolver) -> Self {
        self.solver = solver;
        self
    }

    /// A needle that starts inside the tissue (a channel cut before the
    /// run, the tissue at rest around it): its entry is where the needle
    /// crosses the tissue surface walking from the clamp, its tip touches
    /// the channel end, and shaft points sit every `spacing` between, all
    /// guessed STATIC. A needle whose tip starts outside is left as it is.
    fn pre_inserted(mut self) -> Self {
        let xt = self.fem.positions();
        let tip_a = self.tip_arclength();
        let inside = |m: &Self, a: f64| locate(&m.tets, &xt, &m.needle_point(a));
        let Some(tip) = inside(&self, tip_a) else {
            return self;
        };
        // First inside sample walking from the clamp, then bisection on the
        // crossing to a millionth of a spacing.
        let h = self.spacing / 8.0;
        let mut hi = (0..)
            .map(|k| (k as f64 * h).min(tip_a))
            .find(|&a| inside(&self, a).is_some())
            .expect("the tip is inside");
        let mut lo = (hi - h).max(0.0);
        while hi - lo > 1e-6 * self.spacing {
            let mid = 0.5 * (lo + hi);
            if inside(&self, mid).is_some() {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        self.entry = inside(&self, hi);
        self.tip = Some(Point {
            tissue: tip,
            arclength: tip_a,
            state: State::Static,
        });
        self.touching = true;
        self.add_shaft_points(&xt, tip_a, State::Static);
        self
    }

    /// The coupling points of the next step's LCP, ordered by arclength:
    /// the shaft points and the tip point while it touches the tip.
    pub fn points(&self) -> Vec<Point> {
        let mut v = self.shaft.clone();
        v.extend(self.tip.filter(|_| self.touching));
        v
    }

    /// LCP statistics so far.
    pub fn lcp_stats(&self) -> LcpStats {
        self.stats
    }

    /// Arclength of the needle tip (m from the clamp).
    fn tip_arclength(&self) -> f64 {
        *self.rod.rest_arclength().last().expect("a rod has nodes")
    }

    /// Friction bounds of the LCP's points ([`Self::points`]): a point
    /// holds `f_perlen l_i` and feels the viscous friction `eta l_i` times
    /// its slip velocity, `l_i = (l_{i-1} + l_i) / 2` the shaft length it
    /// stands for, half the arclength gaps to its neighbours (seed Eq. 9).
    /// The tip point, while it touches the tip, is the last of them and
    /// holds the cutting force besides against the tip's advance; the first
    /// shaft point also stands for all of the shaft back to the entry, and
    /// without a touching tip the last one for all of it on to the tip, so
    /// that the lengths sum to `d`. `xt`: the tissue's node positions (m).
    fn bounds(&self, xt: &[Vec3]) -> Vec<Bounds> {
        let (f, eta) = (self.coupling.friction_per_length, self.coupling.viscous_friction);
        let a: Vec<f64> = self.shaft.iter().map(|p| p.arclength).collect();
        let m = a.len();
        let entry = self.entry_arclength_at(xt).unwrap_or(0.0);
        let tip = self.tip_arclength();
        let touching = self.tip.is_some() && self.touching;
        // The tail from the last shaft point to the tip: halved with a
        // touching tip point, whole on the last shaft point otherwise.
        let tail = |a_last: f64| (tip - a_last).max(0.0) * if touching { 1.0 } else { 2.0 };
        let mut lengths: Vec<f64> = (0..m)
            .map(|i| {
                let prev = if i > 0 {
                    a[i] - a[i - 1]
                } else {
                    2.0 * (a[0] - entry).max(0.0)
                };
                let next = if i + 1 < m { a[i + 1] - a[i] } else { tail(a[i]) };
                0.5 * (prev + next)
            })
            .collect();
        if touching {
            let last = a.last().copied().unwrap_or(entry);
            lengths.push((tip - last).max(0.0) * if m == 0 { 1.0 } else { 0.5 });
        }
        let mut out: Vec<Bounds> = lengths
            .iter()
            .map(|l| Bounds {
                forward: f * l,
                backward: f * l,
                viscous: eta * l / self.dt,
            })
            .collect();
        let cut = self.tip_cutting_force();
        if touching && let Some(tip) = out.last_mut() {
            tip.forward += cut;
        }
        out
    }

    /// Needle arclength (m) of the point of the needle nearest `x`.
    fn arclength_of(&self, x: &Vec3) -> f64 {
        let s = self.rod.rest_arclength();
        let mut best = (f64::INFINITY, 0.0);
        for k in 1..s.len() - 1 {
            let (p0, p1) = (self.rod.node(k), self.rod.node(k + 1));
            let e = p1 - p0;
            let t = ((x - p0).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
            let d = (p0 + e * t - x).norm();
            if d < best.0 {
                best = (d, s[k] + t * (s[k + 1] - s[k]));
            }
        }
        best.1
    }

    /// Arclength (m) of the needle where it enters the tissue: the entry
    /// material point projected on the needle; `None` before entry.
    pub fn entry_arclength(&self) -> Option<f64> {
        self.entry_arclength_at(&self.fem.positions())
    }

    /// [`Self::entry_arclength`] with the tissue's node positions `xt` (m)
    /// the caller already holds.
    fn entry_arclength_at(&self, xt: &[Vec3]) -> Option<f64> {
        let e = self.entry?;
        Some(self.arclength_of(&e.position(&self.tets, xt)))
    }

    /// Length of needle inside the tissue (m): tip minus entry arclength.
    pub fn inserted_length(&self) -> f64 {
        self.entry_arclength().map_or(0.0, |e| self.tip_arclength() - e)
    }

    /// The needle's position (m) at arclength `a`.
    fn needle_point(&self, a: f64) -> Vec3 {
        let on = on_needle(self.rod.rest_arclength(), a);
        self.rod.node(on.nodes[0]) * on.w[0] + self.rod.node(on.nodes[1]) * on.w[1]
    }

    /// Stencils and gaps of every point at the start of the step (needle at
    /// its warm start, tissue at `xt`).
    fn geometry(&self, xt: &[Vec3]) -> Vec<Geometry> {
        let s = self.rod.rest_arclength();
        self.points()
            .iter()
            .map(|p| {
                let on = on_needle(s, p.arclength);
                let [k0, k1] = on.nodes;
                let (x0, x1) = (self.rod.node(k0), self.rod.node(k1));
                let needle = x0 * on.w[0] + x1 * on.w[1];
                let tissue = p.tissue.position(&self.tets, xt);
                Geometry {
                    frame: frame(&(x1 - x0).normalize()),
                    needle: on,
                    tissue: self.tets[p.tissue.tet],
                    w: p.tissue.w,
                    gap: needle - tissue,
                }
            })
            .collect()
    }

    /// Add `f` (world, N) on the needle at `on` into the needle's free-DOF
    /// vector; the share on clamped nodes goes to `clamp`.
    fn add_needle(&self, on: &OnNeedle, f: &Vec3, out: &mut [f64], clamp: &mut Vec3) {
        for (k, w) in on.nodes.iter().zip(on.w) {
            match self.rod.node_dof(*k) {
                Some(d) => (0..3).for_each(|c| out[d + c] += w * f[c]),
                None => *clamp += f * w,
            }
        }
    }

    /// Displacement of the needle point `on` for a free-DOF increment `dz`.
    fn needle_motion(&self, on: &OnNeedle, dz: &[f64]) -> Vec3 {
        on.nodes
            .iter()
            .zip(on.w)
            .filter_map(|(k, w)| {
                self.rod
                    .node_dof(*k)
                    .map(|d| Vec3::new(dz[d], dz[d + 1], dz[d + 2]) * w)
            })
            .sum()
    }

    /// Displacement of a tissue point for a DOF increment `dx`.
    fn tissue_motion(g: &Geometry, dx: &[f64]) -> Vec3 {
        (0..4)
            .map(|a| Vec3::new(dx[3 * g.tissue[a]], dx[3 * g.tissue[a] + 1], dx[3 * g.tissue[a] + 2]) * g.w[a])
            .sum()
    }

    /// The Delassus matrix `W = J_n H^{-1} J_n^T + J_t A^{-1} J_t^T` in frame
    /// components. The tissue's share in world axes by sparse forward
    /// solves with its factor (each column a unit force spread over one
    /// tet's four nodes: `Y = L^-1 P J_t^T`, `W_t = Y^T Y`), kept across
    /// steps while the factor stays ([`TissueGram`]: only new points are
    /// solved), then turned into each point's frame; where the factor is
    /// simplicial, all its frame columns in one blocked full solve. The
    /// needle's by one banded solve per point and axis.
    fn delassus(&mut self, geo: &[Geometry]) -> DMatrix<f64> {
        let m = geo.len();
        let (nf, nt) = (self.rod.free_dofs(), 3 * self.fem.node_masses().len());
        let stencils: Vec<([usize; 4], [f64; 4])> = geo.iter().map(|g| (g.tissue, g.w)).collect();
        let mut w = match self.gram.world(&mut self.fem, &stencils) {
            // W_t[3j + r, 3i + d] = f_j,r^T B_ji f_i,d for world blocks B.
            Some(world) => DMatrix::from_fn(3 * m, 3 * m, |row, col| {
                let (j, r, i, d) = (row / 3, row % 3, col / 3, col % 3);
                let b = world.fixed_view::<3, 3>(3 * j, 3 * i);
                geo[j].frame[r].dot(&(b * geo[i].frame[d]))
            }),
            None => {
                // Column 3 i + d: the unit force along point i's frame
                // axis d, on the tissue DOFs of its tet.
                let columns: Vec<Vec<(usize, f64)>> = geo
                    .iter()
                    .flat_map(|gi| {
                        (0..3).map(move |d| {
                            (0..4)
                                .flat_map(|a| (0..3).map(move |c| (3 * gi.tissue[a] + c, gi.w[a] * gi.frame[d][c])))
                                .collect()
                        })
                    })
                    .collect();
                let mut w = DMatrix::zeros(3 * m, 3 * m);
                let mut yts = vec![0.0; nt * 3 * m];
                for (col, entries) in columns.iter().enumerate() {
                    for &(dof, v) in entries {
                        yts[col * nt + dof] += v;
                    }
                }
                self.fem.solve_linear_many(&mut yts, 3 * m);
                for col in 0..3 * m {
                    let yt = &yts[col * nt..(col + 1) * nt];
                    for (j, gj) in geo.iter().enumerate() {
                        let u = Self::tissue_motion(gj, yt);
                        for r in 0..3 {
                            w[(3 * j + r, col)] = gj.frame[r].dot(&u);
                        }
                    }
                }
                w
            }
        };
        let mut unused = Vec3::zeros();
        for (i, gi) in geo.iter().enumerate() {
            for d in 0..3 {
                let mut yn = vec![0.0; nf];
                self.add_needle(&gi.needle, &gi.frame[d], &mut yn, &mut unused);
                self.rod.solve_linear(&mut yn);
                for (j, gj) in geo.iter().enumerate() {
                    let u = self.needle_motion(&gj.needle, &yn);
                    for r in 0..3 {
                        w[(3 * j + r, 3 * i + d)] += gj.frame[r].dot(&u);
                    }
                }
            }
        }
        // Symmetric in exact arithmetic; average away the rounding.
        let wt = w.transpose();
        (w + wt) * 0.5
    }

    /// After the step: sliding shaft points move along the needle by their
    /// slip and leave it once the tip retracts past them; the tip point cuts
    /// on while it slides forward, stays behind as the channel end when the
    /// tip retreats and touches again when the tip comes back to it; a
    /// shaft point joins every `spacing` along the needle inside the tissue;
    /// a tip that has just entered the tissue gets its point. `slips`: each
    /// point's slip along the needle this step (m, + the needle advanced).
    fn update_points(&mut self, states: &[State], slips: &[f64]) {
        let tip_a = self.tip_arclength();
        let m = self.shaft.len();
        for ((p, st), s) in self.shaft.iter_mut().zip(states).zip(slips) {
            p.state = *st;
            if *st != State::Static {
                p.arclength -= s;
            }
        }
        // Within rounding of the tip a point stays at it.
        let slack = 1e-6 * self.spacing;
        self.shaft
            .retain(|p| p.arclength <= tip_a + slack && p.arclength >= 0.0);
        self.shaft.iter_mut().for_each(|p| p.arclength = p.arclength.min(tip_a));
        let xt = self.fem.positions();
        let last = self.rod.num_nodes() - 1;
        let tip_x = self.rod.node(last);
        let along = (tip_x - self.rod.node(last - 1)).normalize();
        // A bevel tip cuts its new channel end `h = d tan(psi)` along the tip
        // edge's material axis m_2, `d` the length it cut this step (seed
        // Sec. 3.5): the tissue then pushes the tip towards m_2.
        let cut = slips.get(m).copied().unwrap_or(0.0).max(0.0);
        let m2: Vec3 = self.rod.material_frame(last - 1).column(1).into_owned();
        let bevel_offset = m2 * (cut * self.coupling.bevel_angle.tan());
        if let Some(tip) = &mut self.tip
            && self.touching
            && states.len() > m
        {
            tip.state = states[m];
            match tip.state {
                State::DynamicPlus => {
                    let at = tip_x + bevel_offset;
                    let strict = locate(&self.tets, &xt, &at);
                    if strict.is_none() {
                        self.stats.tip_fallbacks += 1;
                    }
                    match strict.or_else(|| locate_within(&self.tets, &xt, &at, TIP_SLACK)) {
                        // It cut on: the point moves to the tissue now at the
                        // tip, beside it for a bevel tip.
                        Some(at) => {
                            tip.tissue = at;
                            tip.arclength = tip_a;
                        }
                        // The tip left the tissue (through the block's far
                        // side, or into a gap of a badly deformed mesh).
                        None => {
                            self.stats.tip_lost += 1;
                            self.tip = None;
                        }
                    }
                }
                State::DynamicMinus => self.touching = false,
                State::Static => {}
            }
        }
        if let Some(tip) = &mut self.tip
            && !self.touching
        {
            // The channel end, ahead of the tip along the needle's last edge.
            tip.arclength = tip_a + (tip.tissue.position(&self.tets, &xt) - tip_x).dot(&along);
            if tip.arclength <= tip_a {
                tip.arclength = tip_a;
                tip.state = State::Static;
                self.touching = true;
            }
        }
        if self.entry.is_none()
            && let Some(at) = locate(&self.tets, &xt, &tip_x)
        {
            self.entry = Some(at);
            self.tip = Some(Point {
                tissue: at,
                arclength: tip_a,
                state: State::DynamicPlus,
            });
            self.touching = true;
        }
        self.add_shaft_points(&xt, tip_a, State::DynamicPlus);
    }

    /// Shaft points every `spacing` behind the last one (or the entry), each
    /// placed once the tip is half a spacing past it so that no two points
    /// crowd (nearly equal rows of `W`); the tissue point is the one on the
    /// needle there, its friction state guessed `state`.
    fn add_shaft_points(&mut self, xt: &[Vec3], tip_a: f64, state: State) {
        let Some(entry) = self.entry_arclength_at(xt) else {
            return;
        };
        let mut from = self.shaft.last().map_or(entry, |p| p.arclength);
        while tip_a - from >= 1.5 * self.spacing {
            from += self.spacing;
            if let Some(tissue) = locate(&self.tets, xt, &self.needle_point(from)) {
                self.shaft.push(Point {
                    tissue,
                    arclength: from,
                    state,
                });
            }
        }
    }
}

/// CG work of one step: iterations over all its solves, and how many
/// stopped at the limit.
struct CgWork {
    iterations: usize,
    solves: usize,
    unconverged: usize,
}

impl NeedleModel {
    /// One step's LCP through the Schur complement: uncoupled increments by
    /// the two factors, the Delassus matrix, the LCP, and the final
    /// increments with the constraint forces on both sides. Returns
    /// `(dz, dx, solution)`, the solution `None` without coupling points.
    fn solve_schur(
        &mut self,
        lin: &LinearStep,
        geo: &[Geometry],
        bounds: &[Bounds],
        states: &[State],
    ) -> (Vec<f64>, Vec<f64>, Option<Solution>) {
        // The tissue's uncoupled solve in two halves where its factor is
        // supernodal: the forward half `u = L^-1 P r` gives the points'
        // motion `J A^-1 r = Y^T u` from the kept columns `Y` of the
        // Delassus matrix, and the constraint forces are subtracted before
        // the backward half, `dx = P^T L^-T (u - Y f)`: one forward and one
        // backward sweep of the factor a step instead of two full solves.
        // (Without coupling points a plain full solve: no forward half to
        // throw away.)
        let mut half = if geo.is_empty() {
            None
        } else {
            self.fem.forward_half(lin.residual()).map(|(_, u)| u)
        };
        let mut dz: Vec<f64> = self.rod.linear_residual().iter().map(|g| -g).collect();
        self.rod.solve_linear(&mut dz);
        let n_dofs = lin.residual().len();
        let mut dx = Vec::new();
        if half.is_none() {
            dx = lin.residual().to_vec();
            self.fem.solve_linear(&mut dx);
        }
        if geo.is_empty() {
            return (dz, dx, None);
        }
        let w = self.delassus(geo);
        let mut g_free = vec![0.0; 3 * geo.len()];
        for (i, g) in geo.iter().enumerate() {
            let tissue = match &half {
                Some(u) => Vec3::from(self.gram.columns(i).each_ref().map(|y| y.dot_dense(u))),
                None => Self::tissue_motion(g, &dx),
            };
            let u = g.gap + self.needle_motion(&g.needle, &dz) - tissue;
            (0..3).for_each(|r| g_free[3 * i + r] = g.frame[r].dot(&u));
        }
        let sol = lcp::solve(&w, &g_free, bounds, states, TAU_CHECK, MAX_TRIALS);
        let mut rn: Vec<f64> = self.rod.linear_residual().iter().map(|g| -g).collect();
        let mut rt = if half.is_none() {
            lin.residual().to_vec()
        } else {
            vec![0.0; n_dofs]
        };
        let mut clamp = Vec3::zeros();
        for (i, g) in geo.iter().enumerate() {
            let f = g.force(&sol.lambda[3 * i..3 * i + 3]);
            self.add_needle(&g.needle, &f, &mut rn, &mut clamp);
            match &mut half {
                Some(u) => (0..3).for_each(|c| self.gram.columns(i)[c].sub_from(f[c], u)),
                None => {
                    for a in 0..4 {
                        (0..3).for_each(|c| rt[3 * g.tissue[a] + c] -= g.w[a] * f[c]);
                    }
                }
            }
        }
        self.rod.solve_linear(&mut rn);
        match &mut half {
            Some(u) => {
                self.fem
                    .backward_half(u, &mut rt)
                    .expect("the factor of the forward half");
            }
            None => self.fem.solve_linear(&mut rt),
        }
        (rn, rt, Some(sol))
    }

    /// Row `d` (frame axis) of point `g`'s gap over the coupled unknowns
    /// `[dz; dx]` (`nf` needle DOFs first): the needle point's motion minus
    /// the tissue point's, along the axis; clamped needle nodes and
    /// constrained tissue DOFs do not move and have no entries.
    fn constraint_row(&self, g: &Geometry, d: usize, nf: usize) -> Row {
        let e = g.frame[d];
        let mut row = Row::new();
        for (k, w) in g.needle.nodes.iter().zip(g.needle.w) {
            if let Some(dof) = self.rod.node_dof(*k) {
                (0..3).for_each(|c| row.push((dof + c, w * e[c])));
            }
        }
        for a in 0..4 {
            for c in 0..3 {
                let dof = 3 * g.tissue[a] + c;
                if self.fem.is_free(dof) {
                    row.push((nf + dof, -g.w[a] * e[c]));
                }
            }
        }
        row
    }

    /// One step's LCP by the seed's solver: every trial a projected PCG
    /// over the whole coupled system `[H 0; 0 A] [dz; dx] = b + J^T lambda`
    /// ([`crate::pcg`]), the first warm started from the unconstrained
    /// solve (which also gives the free gaps the LCP scales its checks by),
    /// each next from the last. The step's increments are those of the
    /// configuration the LCP returns. Returns `(dz, dx, solution, work)`.
    fn solve_cg(
        &mut self,
        lin: &LinearStep,
        geo: &[Geometry],
        bounds: &[Bounds],
        states: &[State],
        tol: f64,
    ) -> (Vec<f64>, Vec<f64>, Option<Solution>, CgWork) {
        let nf = self.rod.free_dofs();
        let nt = 3 * self.fem.node_masses().len();
        let n = nf + nt;
        let mut b: Vec<f64> = self.rod.linear_residual().iter().map(|g| -g).collect();
        b.extend(
            lin.residual()
                .iter()
                .enumerate()
                .map(|(d, r)| if self.fem.is_free(d) { *r } else { 0.0 }),
        );
        let mut diag = self.rod.linear_diagonal();
        diag.extend(self.fem.linear_diagonal(lin));
        let rows: Vec<Row> = geo
            .iter()
            .flat_map(|g| (0..3).map(move |d| (g, d)))
            .map(|(g, d)| self.constraint_row(g, d, nf))
            .collect();
        let gap0: Vec<f64> = geo
            .iter()
            .flat_map(|g| (0..3).map(move |d| g.frame[d].dot(&g.gap)))
            .collect();
        // At most 4 n products per solve: CG ends in n in exact arithmetic;
        // the rest is room for round-off before it counts as unconverged.
        let max_iter = 4 * n;
        let mut work = CgWork {
            iterations: 0,
            solves: 0,
            unconverged: 0,
        };
        let row_dot = |r: usize, y: &[f64]| rows[r].iter().map(|&(k, a)| a * y[k]).sum::<f64>();
        let (rod, fem) = (&self.rod, &mut self.fem);
        let mut tissue_out = vec![0.0; nt];
        // `out = K x + sum over viscous rows c J_r^T (J_r x)`.
        let mut apply = |viscous: &[(usize, f64)], x: &[f64], out: &mut [f64]| {
            rod.apply_linear(&x[..nf], &mut out[..nf]);
            fem.apply_linear(lin, &x[nf..], &mut tissue_out);
            out[nf..].copy_from_slice(&tissue_out);
            for &(r, c) in viscous {
                let jx = row_dot(r, x);
                rows[r].iter().for_each(|&(k, a)| out[k] += c * a * jx);
            }
        };
        let mut y_free = vec![0.0; n];
        let free = pcg::solve(
            &mut |x, out| apply(&[], x, out),
            &diag,
            &b,
            &[],
            &[],
            &mut y_free,
            tol,
            max_iter,
        )
        .expect("no rows, nothing dependent");
        work.iterations += free.iterations;
        work.solves += 1;
        work.unconverged += usize::from(!free.converged);
        let split = |y: Vec<f64>| {
            let mut dz = y;
            let dx = dz.split_off(nf);
            (dz, dx)
        };
        if geo.is_empty() {
            let (dz, dx) = split(y_free);
            return (dz, dx, None, work);
        }
        let g_free: Vec<f64> = (0..rows.len()).map(|r| gap0[r] + row_dot(r, &y_free)).collect();
        let mut trials: Vec<Vec<f64>> = Vec::new();
        let configuration = |states: &[State]| {
            let mut lambda = vec![0.0; rows.len()];
            let mut rhs = b.clone();
            let mut diag_t = diag.clone();
            let (mut eq, mut viscous, mut sliding) = (Vec::new(), Vec::new(), Vec::new());
            for (i, st) in states.iter().enumerate() {
                let r = 3 * i;
                match lcp::coulomb(*st, &bounds[i]) {
                    // Viscous slip: lambda = f - c g with g = gap0 + J y, so
                    // (K + c J^T J) y = b + J^T (f - c gap0).
                    Some(f) => {
                        let c = bounds[i].viscous;
                        let known = f - c * gap0[r];
                        rows[r].iter().for_each(|&(k, a)| rhs[k] += a * known);
                        if c > 0.0 {
                            viscous.push((r, c));
                            rows[r].iter().for_each(|&(k, a)| diag_t[k] += c * a * a);
                        }
                        sliding.push((r, f, c));
                    }
                    None => eq.push(r),
                }
                eq.extend([r + 1, r + 2]);
            }
            let eq_rows: Vec<Row> = eq.iter().map(|&r| rows[r].clone()).collect();
            let c: Vec<f64> = eq.iter().map(|&r| -gap0[r]).collect();
            let mut y = trials.last().cloned().unwrap_or_else(|| y_free.clone());
            let out = pcg::solve(
                &mut |x, o| apply(&viscous, x, o),
                &diag_t,
                &rhs,
                &eq_rows,
                &c,
                &mut y,
                tol,
                max_iter,
            )?;
            work.iterations += out.iterations;
            work.solves += 1;
            work.unconverged += usize::from(!out.converged);
            for (&r, l) in eq.iter().zip(&out.lambda) {
                lambda[r] = *l;
            }
            let gap: Vec<f64> = (0..rows.len()).map(|r| gap0[r] + row_dot(r, &y)).collect();
            for (r, f, c) in sliding {
                lambda[r] = f - c * gap[r];
            }
            trials.push(y);
            Some((lambda, gap))
        };
        let sol = lcp::solve_by(configuration, &g_free, bounds, states, TAU_CHECK, MAX_TRIALS);
        let y = trials.get(sol.chosen).cloned().unwrap_or(y_free);
        let (dz, dx) = split(y);
        (dz, dx, Some(sol), work)
    }
}

impl Model for NeedleModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        let frame = Instant::now();
        let schur = self.solver == LcpSolver::Schur;
        self.stats.all_steps += 1;
        let factored = self.fem.solver_counts().0;
        let lin = self.fem.begin_linear_step_with(dt, cmd.load, schur)?;
        self.stats.tets_updated += self.fem.last_updated;
        self.stats.factorizations += self.fem.solver_counts().0 - factored;
        let mut mark = Instant::now();
        self.times.tissue += mark - frame;
        self.rod.begin_linear_step(dt, cmd)?;
        self.times.needle += lap(&mut mark);
        let xt = self.fem.positions();
        let geo = self.geometry(&xt);
        let mut stats = StepStats {
            iterations: 0,
            residual: 0.0,
            converged: true,
        };
        let bounds = self.bounds(&xt);
        let states: Vec<State> = self.points().iter().map(|p| p.state).collect();
        let (dz, dx, sol) = match self.solver {
            LcpSolver::Schur => self.solve_schur(&lin, &geo, &bounds, &states),
            LcpSolver::Cg { tolerance } => {
                let (dz, dx, sol, cg) = self.solve_cg(&lin, &geo, &bounds, &states, tolerance);
                self.stats.linear_iterations += cg.iterations;
                self.stats.linear_solves += cg.solves;
                self.stats.max_linear_iterations = self.stats.max_linear_iterations.max(cg.iterations);
                self.stats.linear_unconverged += cg.unconverged;
                stats.converged &= cg.unconverged == 0;
                (dz, dx, sol)
            }
        };
        self.clamp_share = Vec3::zeros();
        let mut slips = vec![0.0; geo.len()];
        let mut new_states = states;
        if let Some(sol) = sol {
            self.stats.steps += 1;
            self.stats.trials += sol.trials;
            self.stats.max_trials = self.stats.max_trials.max(sol.trials);
            self.stats.min_trials = if self.stats.steps == 1 {
                sol.trials
            } else {
                self.stats.min_trials.min(sol.trials)
            };
            self.stats.unresolved += usize::from(!sol.consistent);
            stats.iterations = sol.trials as u32;
            stats.converged &= sol.consistent;
            let mut unused = vec![0.0; self.rod.free_dofs()];
            let mut clamp = Vec3::zeros();
            for (i, g) in geo.iter().enumerate() {
                let f = g.force(&sol.lambda[3 * i..3 * i + 3]);
                self.add_needle(&g.needle, &f, &mut unused, &mut clamp);
                slips[i] = sol.gap[3 * i];
                stats.residual = stats.residual.max(sol.gap[3 * i + 1].hypot(sol.gap[3 * i + 2]));
            }
            self.clamp_share = clamp;
            new_states = sol.states;
        }
        self.times.lcp += lap(&mut mark);
        self.fem.end_linear_step(lin, &dx)?;
        self.times.tissue += lap(&mut mark);
        self.rod.end_linear_step(dt, &dz)?;
        self.times.needle += lap(&mut mark);
        self.update_points(&new_states, &slips);
        self.times.lcp += lap(&mut mark);
        self.realize()?;
        self.times.remesh += lap(&mut mark);
        self.volume_ratio_min = self.volume_ratio_min.min(self.fem.min_volume_ratio());
        self.times.frame += frame.elapsed();
        Ok(stats)
    }

    /// The needle as the one rod, the tissue as the one tissue body, and the
    /// force the needle exerts on the hand at its base (N).
    fn observe(&self) -> Observation {
        let mut obs = self.fem.observe();
        obs.rods = vec![self.rod.rod_obs()];
        if let Some(t) = obs.tissues.first_mut() {
            t.rest_dihedral_deg = Some(self.dihedral);
        }
        let (f, tq) = self.rod.hand_wrench();
        obs.hand_force = f + self.clamp_share;
        obs.hand_torque = tq;
        let e = self.rod.energies();
        obs.energy.kinetic += e.kinetic;
        obs.energy.elastic += e.elastic;
        obs.energy.external += e.external;
        obs
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    /// Coupling points, how many stick, and the LCP's trials (the seed's
    /// Table 3: min, mean and max per coupled step, steps left unresolved).
    fn diagnostics(&self) -> BTreeMap<String, f64> {
        let s = self.stats;
        let mut d = BTreeMap::new();
        let points = self.points();
        d.insert("coupling_points".into(), points.len() as f64);
        d.insert("inserted_length_m".into(), self.inserted_length());
        for (name, state) in [
            ("static_points", State::Static),
            ("forward_points", State::DynamicPlus),
            ("backward_points", State::DynamicMinus),
        ] {
            d.insert(name.into(), points.iter().filter(|p| p.state == state).count() as f64);
        }
        d.insert(
            "lcp_trials_mean".into(),
            if s.steps > 0 {
                s.trials as f64 / s.steps as f64
            } else {
                0.0
            },
        );
        d.insert("lcp_trials_max".into(), s.max_trials as f64);
        d.insert("lcp_trials_min".into(), s.min_trials as f64);
        d.insert("lcp_unresolved_steps".into(), s.unresolved as f64);
        d.insert("tip_fallback_steps".into(), s.tip_fallbacks as f64);
        // The seed's Table 1 columns: the share of tet blocks rebuilt per
        // step (of the mesh at the end, which remeshing changes), and the
        // tissue factorizations (a step keeps its factor while no block
        // changed).
        d.insert(
            "tets_updated_fraction".into(),
            s.tets_updated as f64 / (s.all_steps.max(1) * self.tets.len().max(1)) as f64,
        );
        d.insert("tissue_factorizations".into(), s.factorizations as f64);
        // Of the tissue's Delassus columns the Schur solver needed, the share
        // kept from an earlier step with the same factor (the rest solved;
        // absent where the factor is simplicial: every step solves in full).
        let (solved, reused) = (self.gram.solved, self.gram.reused);
        if solved > 0 {
            d.insert(
                "delassus_points_reused_fraction".into(),
                reused as f64 / (solved + reused).max(1) as f64,
            );
        }
        d.insert("tip_lost".into(), s.tip_lost as f64);
        // Where the tip cuts, in the tissue's rest coordinates (m), and the
        // force that takes there (N): which layer of a layered body it is in.
        if let Some(p) = &self.tip {
            let t = self.tets[p.tissue.tet];
            let x: Vec3 = (0..4).map(|a| self.fem.rest_position(t[a]) * p.tissue.w[a]).sum();
            d.insert("tip_rest_x_m".into(), x.x);
            d.insert("tip_rest_y_m".into(), x.y);
            d.insert("tip_rest_z_m".into(), x.z);
            d.insert("tip_cutting_force_n".into(), self.tip_cutting_force());
        }
        // The seed's Table 2: mean wall time per step of each phase (ms;
        // timings, not results: they change from run to run).
        let steps = s.all_steps.max(1) as f64;
        let ms = |t: Duration| t.as_secs_f64() * 1e3 / steps;
        let t = self.times;
        d.insert("frame_ms_mean".into(), ms(t.frame));
        d.insert("tissue_ms_mean".into(), ms(t.tissue));
        d.insert("needle_ms_mean".into(), ms(t.needle));
        d.insert("lcp_ms_mean".into(), ms(t.lcp));
        if self.remesh.is_some() {
            d.insert("remesh_ms_mean".into(), ms(t.remesh));
        }
        if self.volume_ratio_min.is_finite() {
            d.insert("tissue_volume_ratio_min".into(), self.volume_ratio_min);
        }
        if let Some(rm) = &self.remesh {
            d.insert("remesh_operations".into(), rm.ops as f64);
            d.insert("remesh_rebuilds".into(), rm.rebuilds as f64);
            d.insert("remesh_refused".into(), rm.refused as f64);
            d.insert("tissue_nodes".into(), rm.remesher.nodes().len() as f64);
            d.insert("remesh_depth".into(), rm.remesher.stack().len() as f64);
            d.insert("remesh_energy_released_j".into(), rm.released);
            d.insert("remesh_energy_jump_max_j".into(), rm.energy_jump_max);
            d.insert("remesh_tip_jump_max_m".into(), rm.tip_jump_max);
        }
        // The seed's Table 3 "linear-solver iterations": only the CG solver has them.
        if matches!(self.solver, LcpSolver::Cg { .. }) {
            let steps = s.all_steps.max(1) as f64;
            d.insert("cg_iterations_mean".into(), s.linear_iterations as f64 / steps);
            d.insert("cg_iterations_max".into(), s.max_linear_iterations as f64);
            d.insert(
                "cg_iterations_per_solve".into(),
                s.linear_iterations as f64 / s.linear_solves.max(1) as f64,
            );
            d.insert("cg_unconverged_solves".into(), s.linear_unconverged as f64);
        }
        d
    }
}
