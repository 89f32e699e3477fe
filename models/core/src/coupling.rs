//! An instrument in a deformable vessel: any rod model and any tissue model
//! composed by partitioned coupling through the contract, not a new model
//! per pair ([`PairFactory`], id `rod+tissue`, e.g. `der+fem`).
//!
//! The scene holds one rod, one tissue whose [`TissueBody::contact_surface`]
//! is the vessel's inner wall, and `Environment::vessel`: the lumen at rest,
//! bounded by that wall. Each model runs its own half of the scene:
//! - the **tissue** reports where its contact-surface nodes are
//!   ([`Model::surface_positions`]) and takes forces on them
//!   ([`Model::set_surface_forces`]) — [`Capability::SurfaceForces`];
//! - the **rod** collides with the lumen the coupling hands it before each
//!   step ([`Model::set_lumen`]) — [`Capability::DeformableLumen`] — and
//!   reports its contacts (`Observation::contacts`, the force the wall
//!   exerts on the rod at each contact point).
//!
//! The lumen the rod sees is the rest lumen with the wall moved by the
//! tissue's normal displacement ([`DisplacedLumen`]); a contact force goes
//! back to the wall nodes with the transpose of that interpolation
//! ([`WallSamples::spread`]), with the opposite sign, so what the rod
//! receives the tissue receives back to round-off.
//!
//! Schemes (fidelity key `coupling`):
//! - `staggered`: one exchange per step (Gauss-Seidel): the rod steps
//!   against the wall where the tissue left it, then the tissue steps under
//!   the rod's new contact forces. One solve of each model per step; the
//!   scheme most interactive simulators use, and unstable when a stiff
//!   contact drives a light wall with a large step.
//! - `iterated`: the same exchange repeated within the step from saved
//!   states ([`Model::save_state`]) until the wall position the rod saw and
//!   the one the tissue returned differ by less than `coupling_tol` (m),
//!   the next guess by interface quasi-Newton (IQN-ILS, the default) or
//!   Aitken's relaxation ([`Accel`]).
//!
//! Units SI. Only the coupled quantities cross: each model keeps its own
//! time integration, contact law and friction.

use crate::Vec3;
use crate::capability::{Capability, Family};
use crate::error::{BuildError, SimError, Unsupported};
use crate::fidelity::Fidelity;
use crate::model::{EnergyProbe, Model, ModelFactory, StepStats};
use crate::observation::Observation;
use crate::scene::{Body, DeviceCommand, Scene, TissueBody};
use crate::sdf::{DisplacedLumen, Sdf, WallSamples};
use crate::settings::{Choice, FidelityKey, Settings};
use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

/// Whether `forces` fit a contact surface of `nodes` nodes
/// ([`Model::set_surface_forces`]): one finite force each; the message
/// says what was expected and what came.
pub fn check_surface_forces(nodes: usize, forces: &[Vec3]) -> Result<(), String> {
    if forces.len() != nodes || !forces.iter().all(|f| f.iter().all(|c| c.is_finite())) {
        return Err(format!(
            "{nodes} surface forces (finite) expected, got {}",
            forces.len()
        ));
    }
    Ok(())
}

/// Store `forces` (one per contact-surface node, `surface[k]` the model's
/// node of the `k`-th) into the per-node `external` forces: the shared body
/// of the tissue models' [`Model::set_surface_forces`] where a surface node
/// is a model node. Forces [`check_surface_forces`] refuses are refused
/// with its message, and nothing is stored.
pub fn store_surface_forces(surface: &[usize], forces: &[Vec3], external: &mut [Vec3]) -> Result<(), String> {
    check_surface_forces(surface.len(), forces)?;
    for (&i, f) in surface.iter().zip(forces) {
        external[i] = *f;
    }
    Ok(())
}

/// Coupling schemes by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// One exchange per step.
    Staggered,
    /// Exchanges repeated to an interface tolerance.
    Iterated,
}

const SCHEMES: &[(&str, Scheme)] = &[("staggered", Scheme::Staggered), ("iterated", Scheme::Iterated)];

/// Default interface tolerance of the iterated scheme (m): a thousandth of
/// the 0.1 mm wall deflections of the vessel scenes.
pub const DEFAULT_COUPLING_TOL: f64 = 1e-7;
/// Default largest number of sweeps of the iterated scheme in one step.
pub const DEFAULT_COUPLING_MAX_ITER: usize = 50;
/// Default first relaxation factor of the iterated scheme (Aitken's factor
/// starts here in every step).
pub const DEFAULT_RELAXATION: f64 = 0.5;
/// Kernel radius of the wall interpolation over the longest rest edge of
/// the contact surface: above one so every wall point has a node within
/// reach ([`WallSamples::new`]), small so a dent stays local.
pub const KERNEL_OVER_EDGE: f64 = 1.5;

const KEYS: &[FidelityKey] = &[
    FidelityKey::choice(
        "coupling",
        "rod-tissue coupling scheme",
        &[
            Choice::new("staggered", "one exchange per step (default)"),
            Choice::new(
                "iterated",
                "exchanges repeated to coupling_tol (acceleration: iqn-ils or aitken)",
            ),
        ],
    ),
    FidelityKey::number(
        "coupling_tol",
        "iterated: largest change of the wall between sweeps at convergence (m), default 1e-7",
    )
    .above(0.0),
    FidelityKey::number(
        "coupling_max_iter",
        "iterated: most sweeps in a step before the step fails, default 50",
    )
    .whole(1.0, 1000.0),
    FidelityKey::choice(
        "acceleration",
        "iterated: next wall guess",
        &[
            Choice::new("iqn-ils", "interface quasi-Newton, least squares (default)"),
            Choice::new("aitken", "Aitken's dynamic relaxation"),
        ],
    ),
    FidelityKey::number(
        "relaxation",
        "iterated: first relaxation factor of each step (Aitken's after), default 0.5",
    )
    .between(0.0, 1.0),
];

/// A rod model and a tissue model as one model for the harness (module
/// docs). Its capabilities are the union of both, so the usual
/// [`ModelFactory::check`] against the whole scene passes only where each
/// half can run its part.
pub struct PairFactory {
    id: &'static str,
    rod: &'static dyn ModelFactory,
    tissue: &'static dyn ModelFactory,
    caps: OnceLock<&'static [Capability]>,
    keys: OnceLock<&'static [FidelityKey]>,
}

/// Prefix of a pair's fidelity keys that go to its rod (`rod.solver`).
pub const ROD_PREFIX: &str = "rod.";
/// Prefix of a pair's fidelity keys that go to its tissue
/// (`tissue.lazy_threshold`).
pub const TISSUE_PREFIX: &str = "tissue.";

impl PairFactory {
    /// The pair `id` (`rod+tissue`) of `rod` and `tissue`.
    pub const fn new(id: &'static str, rod: &'static dyn ModelFactory, tissue: &'static dyn ModelFactory) -> Self {
        Self {
            id,
            rod,
            tissue,
            caps: OnceLock::new(),
            keys: OnceLock::new(),
        }
    }

    /// The rod model.
    pub fn rod(&self) -> &'static dyn ModelFactory {
        self.rod
    }

    /// The tissue model.
    pub fn tissue(&self) -> &'static dyn ModelFactory {
        self.tissue
    }

    /// The rod's half of `scene`: no tissue, the rest lumen kept (the rod's
    /// model checks the lumen's needs: contact, friction, motion).
    pub fn rod_scene(scene: &Scene) -> Scene {
        let mut s = scene.clone();
        s.bodies.retain(|b| matches!(b, Body::Rod(_)));
        s
    }

    /// The tissue's half of `scene`: no rod, no lumen (the tissue does not
    /// collide with its own inside), no friction to model.
    pub fn tissue_scene(scene: &Scene) -> Scene {
        let mut s = scene.clone();
        s.bodies.retain(|b| matches!(b, Body::Tissue(_)));
        s.environment.vessel = None;
        s.environment.vessel_motion = None;
        s.environment.flow = None;
        s
    }

    /// The pair's request split into each half's: the rod takes the
    /// segments, the tissue the mesh level, both the time step; an extra
    /// `rod.k` goes to the rod as `k`, `tissue.k` to the tissue as `k` (each
    /// half's own key, checked by its model), the others stay the pair's.
    fn split_fidelity(f: &Fidelity) -> (Fidelity, Fidelity) {
        let half = |prefix: &str| {
            f.extras
                .iter()
                .filter_map(|(k, v)| k.strip_prefix(prefix).map(|k| (k.to_string(), v.clone())))
                .collect()
        };
        let rod = Fidelity {
            segments: f.segments,
            dt: f.dt,
            extras: half(ROD_PREFIX),
            ..Default::default()
        };
        let tissue = Fidelity {
            mesh_level: f.mesh_level,
            dt: f.dt,
            extras: half(TISSUE_PREFIX),
            ..Default::default()
        };
        (rod, tissue)
    }
}

/// `keys` of a half, each renamed `prefix` + its name and its doc prefixed
/// with the half's model id, made once per pair (the names must live as
/// long as the registry).
fn prefixed(prefix: &str, model: &str, keys: &[FidelityKey]) -> Vec<FidelityKey> {
    keys.iter()
        .map(|k| FidelityKey {
            name: Box::leak(format!("{prefix}{}", k.name).into_boxed_str()),
            doc: Box::leak(format!("{model}: {}", k.doc).into_boxed_str()),
            kind: k.kind,
        })
        .collect()
}

impl ModelFactory for PairFactory {
    fn id(&self) -> &'static str {
        self.id
    }
    fn description(&self) -> &'static str {
        "a rod model in a tissue model's deforming lumen, coupled through the contract (staggered or iterated)"
    }
    fn family(&self) -> Family {
        Family::Pair
    }
    /// Both halves' capabilities (the union is what the scene may need),
    /// made once per pair and kept for the process.
    fn capabilities(&self) -> &'static [Capability] {
        self.caps.get_or_init(|| {
            let mut c: Vec<Capability> = self.rod.capabilities().to_vec();
            c.extend_from_slice(self.tissue.capabilities());
            c.sort();
            c.dedup();
            Box::leak(c.into_boxed_slice())
        })
    }
    /// The coupling's keys, then each half's own keys under its prefix
    /// (`rod.solver`, `tissue.lazy_threshold`): a pair passes a setting to
    /// the half it names, and that half's declaration checks it.
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        self.keys.get_or_init(|| {
            let mut k = KEYS.to_vec();
            k.extend(prefixed(ROD_PREFIX, self.rod.id(), self.rod.fidelity_keys()));
            k.extend(prefixed(TISSUE_PREFIX, self.tissue.id(), self.tissue.fidelity_keys()));
            Box::leak(k.into_boxed_slice())
        })
    }
    /// The rod's segments, the tissue's mesh level, the smaller of their
    /// time steps and each half's extras under its prefix.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let r = self.rod.default_fidelity(&Self::rod_scene(scene));
        let t = self.tissue.default_fidelity(&Self::tissue_scene(scene));
        let dt = match (r.dt, t.dt) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        // Each half's own scene defaults under its prefix, so that a run's
        // settings say what each half ran with.
        let mut extras = std::collections::BTreeMap::new();
        for (prefix, half) in [(ROD_PREFIX, &r), (TISSUE_PREFIX, &t)] {
            extras.extend(half.extras.iter().map(|(k, v)| (format!("{prefix}{k}"), v.clone())));
        }
        Fidelity {
            segments: r.segments,
            mesh_level: t.mesh_level,
            dt,
            iterations: None,
            extras,
        }
    }

    /// One rod, one tissue with a contact surface; each half supported by
    /// its model; the rod takes a replaced lumen and the tissue surface
    /// forces.
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        if scene.rods().count() != 1 || scene.tissues().count() != 1 {
            return Err(Unsupported::new(format!(
                "{} couples one rod with one tissue; the scene has {} rods and {} tissues",
                self.id,
                scene.rods().count(),
                scene.tissues().count()
            )));
        }
        if scene.tissues().all(|t| t.contact_surface.is_empty()) || scene.needle.is_some() {
            return Err(Unsupported::new(format!(
                "{} needs an instrument in a tissue's lumen (a contact surface, no needle coupling)",
                self.id
            )));
        }
        if !self.rod.capabilities().contains(&Capability::DeformableLumen) {
            return Err(Unsupported::new(format!(
                "{} does not model: {}",
                self.rod.id(),
                Capability::DeformableLumen.name()
            )));
        }
        self.rod.check(&Self::rod_scene(scene))?;
        self.tissue.check(&Self::tissue_scene(scene))
    }

    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let f = settings.fidelity();
        if f.iterations.is_some() {
            return Err(BuildError::bad(
                "iterations",
                "a pair has no iteration count of its own: each model keeps its default (coupling_max_iter bounds the sweeps)",
            ));
        }
        let (rf, tf) = Self::split_fidelity(f);
        let rod = self.rod.build(&Self::rod_scene(scene), &rf)?;
        let tissue = self.tissue.build(&Self::tissue_scene(scene), &tf)?;
        let body = scene.tissues().next().expect("checked: one tissue");
        let rest = scene.environment.vessel.clone().expect("validated: a lumen at rest");
        let scheme = settings.pick("coupling", SCHEMES, Scheme::Staggered)?;
        let opts = Options {
            scheme,
            tol: settings.number_or("coupling_tol", DEFAULT_COUPLING_TOL),
            max_iter: settings.number_or("coupling_max_iter", DEFAULT_COUPLING_MAX_ITER as f64) as usize,
            relaxation: settings.number_or("relaxation", DEFAULT_RELAXATION),
            accel: settings.pick("acceleration", ACCELS, Accel::IqnIls)?,
        };
        let dt = f.dt.unwrap_or_else(|| rod.dt());
        let m = PairModel::new(rod, tissue, body, rest, opts, dt).map_err(|e| BuildError::bad("tissue", e))?;
        Ok(Box::new(m))
    }
}

/// The rest wall of `body`'s contact surface as [`WallSamples`] of the
/// lumen at rest `rest`: its nodes in [`TissueBody::surface_vertices`]
/// order, kernel radius [`KERNEL_OVER_EDGE`] times the longest surface
/// edge. The coupling hands the rod this wall moved; a scorer rebuilds the
/// same lumen from observed nodes.
pub fn wall_samples(body: &TissueBody, rest: Arc<dyn Sdf>) -> Result<WallSamples, crate::sdf::GeometryError> {
    let points: Vec<Vec3> = body.surface_vertices().iter().map(|&i| body.mesh.nodes[i]).collect();
    let longest = body
        .contact_surface
        .iter()
        .flat_map(|t| {
            let p = t.map(|i| body.mesh.nodes[i]);
            [(p[1] - p[0]).norm(), (p[2] - p[1]).norm(), (p[0] - p[2]).norm()]
        })
        .fold(0.0, f64::max);
    WallSamples::new(rest, points, KERNEL_OVER_EDGE * longest)
}

/// How the iterated scheme picks its next wall guess.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accel {
    /// Relaxation by Aitken's dynamic factor (Küttler & Wall 2008, Eq. 44):
    /// `x_{k+1} = x_k + w_k r_k`, `w_k = -w_{k-1} r_{k-1}.(r_k - r_{k-1}) /
    /// |r_k - r_{k-1}|^2`. One factor for every wall mode: slow when the
    /// modes' gains spread (a soft wall under a stiff rod).
    Aitken,
    /// Interface quasi-Newton with an approximate inverse Jacobian from a
    /// least-squares model (IQN-ILS, Degroote, Bathe & Vierendeels 2009,
    /// Comput. Struct. 87:793): `x_{k+1} = x~_k + W c` with
    /// `c = argmin |V c + r_k|`, the columns of `V` and `W` the differences
    /// of the step's residuals and returned walls; the first sweep relaxes
    /// by the `relaxation` factor.
    IqnIls,
}

const ACCELS: &[(&str, Accel)] = &[("iqn-ils", Accel::IqnIls), ("aitken", Accel::Aitken)];

/// The iterated scheme's memory within one step.
struct Accelerator {
    kind: Accel,
    w: f64,
    /// Previous residual and returned wall.
    prev: Option<(Vec<f64>, Vec<f64>)>,
    /// IQN-ILS: residual differences and returned-wall differences.
    v: Vec<Vec<f64>>,
    dw: Vec<Vec<f64>>,
}

impl Accelerator {
    fn new(kind: Accel, w: f64) -> Self {
        Self {
            kind,
            w,
            prev: None,
            v: Vec::new(),
            dw: Vec::new(),
        }
    }

    /// The next guess after the guess `x` returned the wall `xt`.
    fn next(&mut self, x: &[f64], xt: Vec<f64>) -> Vec<f64> {
        let r: Vec<f64> = xt.iter().zip(x).map(|(a, b)| a - b).collect();
        let relaxed = |w: f64| x.iter().zip(&r).map(|(a, d)| a + w * d).collect::<Vec<f64>>();
        let out = match (&self.prev, self.kind) {
            (None, _) => relaxed(self.w),
            (Some((rp, _)), Accel::Aitken) => {
                let (mut num, mut den) = (0.0, 0.0);
                for (a, b) in r.iter().zip(rp) {
                    num += b * (a - b);
                    den += (a - b) * (a - b);
                }
                if den > 0.0 {
                    self.w = -self.w * num / den;
                }
                relaxed(self.w)
            }
            (Some((rp, xp)), Accel::IqnIls) => {
                self.v.push(r.iter().zip(rp).map(|(a, b)| a - b).collect());
                self.dw.push(xt.iter().zip(xp).map(|(a, b)| a - b).collect());
                match least_squares(&self.v, &r) {
                    Some(c) => {
                        let mut next = xt.clone();
                        for (ci, col) in c.iter().zip(&self.dw) {
                            next.iter_mut().zip(col).for_each(|(n, d)| *n += ci * d);
                        }
                        next
                    }
                    None => relaxed(self.w),
                }
            }
        };
        self.prev = Some((r, xt));
        out
    }
}

/// `c = argmin |V c + r|` by a thin QR of `V` (columns `cols`); columns
/// whose pivot falls under `1e-12` of the largest are dropped (their `c`
/// entry is zero). `None` if no column is left.
fn least_squares(cols: &[Vec<f64>], r: &[f64]) -> Option<Vec<f64>> {
    let m = r.len();
    let mut keep: Vec<usize> = (0..cols.len()).collect();
    loop {
        if keep.is_empty() {
            return None;
        }
        let v = nalgebra::DMatrix::from_fn(m, keep.len(), |i, j| cols[keep[j]][i]);
        let qr = v.qr();
        let rr = qr.r();
        let big = (0..keep.len()).map(|i| rr[(i, i)].abs()).fold(0.0, f64::max);
        if let Some(bad) = (0..keep.len()).find(|&i| !(rr[(i, i)].abs() > 1e-12 * big)) {
            keep.remove(bad);
            continue;
        }
        let rhs = -(qr.q().transpose() * nalgebra::DVector::from_column_slice(r));
        let c = rr.solve_upper_triangular(&rhs)?;
        let mut out = vec![0.0; cols.len()];
        for (j, &k) in keep.iter().enumerate() {
            out[k] = c[j];
        }
        return Some(out);
    }
}

/// Settings of a [`PairModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Scheme.
    pub scheme: Scheme,
    /// Iterated: interface tolerance (m).
    pub tol: f64,
    /// Iterated: most sweeps per step.
    pub max_iter: usize,
    /// Iterated: first relaxation factor of each step.
    pub relaxation: f64,
    /// Iterated: how the next wall guess is made.
    pub accel: Accel,
}

/// What the coupling did, over the run so far.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PairStats {
    /// Steps taken.
    pub steps: usize,
    /// Sweeps over all steps (one per step when staggered).
    pub sweeps: usize,
    /// Largest sweeps in one step.
    pub max_sweeps: usize,
    /// Largest `|sum of forces on the wall + sum of contact forces on the
    /// rod|` over the steps (N): zero up to round-off unless a contact fell
    /// off the sampled wall.
    pub max_imbalance: f64,
    /// Contacts whose force found no wall node (off the sampled wall),
    /// counted in every sweep.
    pub lost_contacts: usize,
    /// Largest [`DisplacedLumen::fit_error`] over the steps (m).
    pub max_fit_error: f64,
}

/// A rod model and a tissue model stepped together (module docs).
pub struct PairModel {
    rod: Box<dyn Model>,
    tissue: Box<dyn Model>,
    wall: Arc<WallSamples>,
    /// The wall the rod steps against next: sample positions (m).
    wall_now: Vec<Vec3>,
    opts: Options,
    dt: f64,
    /// Simulated time (s).
    t: f64,
    stats: PairStats,
}

impl PairModel {
    /// Couple `rod` and `tissue` (both built for step `dt`, s) through the
    /// contact surface of `body` and the lumen at rest `rest`.
    pub fn new(
        rod: Box<dyn Model>,
        tissue: Box<dyn Model>,
        body: &TissueBody,
        rest: Arc<dyn Sdf>,
        opts: Options,
        dt: f64,
    ) -> Result<Self, String> {
        let wall = wall_samples(body, rest).map_err(|e| e.0)?;
        let wall_now = tissue
            .surface_positions()
            .ok_or("the tissue model does not report its contact surface")?;
        if wall_now.len() != wall.len() {
            return Err(format!(
                "the tissue reports {} contact-surface nodes, the scene has {}",
                wall_now.len(),
                wall.len()
            ));
        }
        Ok(Self {
            rod,
            tissue,
            wall: Arc::new(wall),
            wall_now,
            opts,
            dt,
            t: 0.0,
            stats: PairStats::default(),
        })
    }

    /// What the coupling did so far.
    pub fn stats(&self) -> PairStats {
        self.stats
    }

    /// The lumen of the wall at sample positions `x`.
    fn lumen(&self, x: &[Vec3]) -> Result<DisplacedLumen, SimError> {
        DisplacedLumen::new(self.wall.clone(), self.wall.normal_displacements(x)).map_err(|e| SimError::SolverFailed {
            t: self.time(),
            reason: e.0,
        })
    }

    fn time(&self) -> f64 {
        self.t
    }

    /// The rod's step against the wall at `x`, then the reaction of its
    /// contacts spread over the wall samples (N) and the rod's contact sum.
    fn rod_sweep(
        &mut self,
        x: &[Vec3],
        dt: f64,
        cmd: &DeviceCommand,
    ) -> Result<(StepStats, Vec<Vec3>, Vec3), SimError> {
        let lumen = self.lumen(x)?;
        let fit = lumen.fit_error(x);
        self.stats.max_fit_error = self.stats.max_fit_error.max(fit);
        self.rod.set_lumen(Arc::new(lumen))?;
        let st = self.rod.step(dt, cmd)?;
        let obs = self.rod.observe();
        let mut f = vec![Vec3::zeros(); self.wall.len()];
        let mut on_rod = Vec3::zeros();
        for c in &obs.contacts {
            let shares = self.wall.spread(&c.point);
            if shares.is_empty() {
                self.stats.lost_contacts += 1;
                continue;
            }
            on_rod += c.force;
            for (i, w) in shares {
                f[i] -= c.force * w;
            }
        }
        Ok((st, f, on_rod))
    }

    fn staggered(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<(StepStats, usize), SimError> {
        let x = self.wall_now.clone();
        let (st, f, on_rod) = self.rod_sweep(&x, dt, cmd)?;
        self.exchange(&f, on_rod)?;
        self.tissue.step(dt, cmd)?;
        self.wall_now = self.surface()?;
        Ok((st, 1))
    }

    /// Dirichlet-Neumann fixed point on the wall position: sweep `k` steps
    /// the rod against `x_k`, the tissue under the rod's forces, and reads
    /// the wall `x~_k = H(x_k)`; the residual is `r_k = x~_k - x_k`, and the
    /// step ends when its largest node entry is within the tolerance. The
    /// next guess comes from [`Accel`].
    fn iterated(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<(StepStats, usize), SimError> {
        let fail = |t: f64, what: &str| SimError::SolverFailed {
            t,
            reason: format!("iterated coupling: {what}"),
        };
        let t0 = self.time();
        let rod0 = self
            .rod
            .save_state()
            .ok_or_else(|| fail(t0, "the rod model cannot save its state"))?;
        let tis0 = self
            .tissue
            .save_state()
            .ok_or_else(|| fail(t0, "the tissue model cannot save its state"))?;
        let flat = |v: &[Vec3]| -> Vec<f64> { v.iter().flat_map(|p| [p.x, p.y, p.z]).collect() };
        let mut x = flat(&self.wall_now);
        let mut acc = Accelerator::new(self.opts.accel, self.opts.relaxation);
        let mut size = f64::INFINITY;
        for k in 1..=self.opts.max_iter {
            if k > 1 {
                self.rod.restore_state(rod0.as_ref())?;
                self.tissue.restore_state(tis0.as_ref())?;
            }
            let guess: Vec<Vec3> = x.chunks(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
            let (st, f, on_rod) = self.rod_sweep(&guess, dt, cmd)?;
            self.exchange(&f, on_rod)?;
            self.tissue.step(dt, cmd)?;
            let got = self.surface()?;
            let xt = flat(&got);
            size = xt
                .chunks(3)
                .zip(x.chunks(3))
                .map(|(a, b)| Vec3::new(a[0] - b[0], a[1] - b[1], a[2] - b[2]).norm())
                .fold(0.0, f64::max);
            if size <= self.opts.tol {
                self.wall_now = got;
                return Ok((st, k));
            }
            x = acc.next(&x, xt);
        }
        Err(fail(
            t0,
            &format!(
                "the wall did not settle to {} m in {} sweeps (last change {size:.3e} m)",
                self.opts.tol, self.opts.max_iter
            ),
        ))
    }

    /// Hand the wall forces `f` to the tissue and book their balance
    /// against the rod's contact sum `on_rod`.
    fn exchange(&mut self, f: &[Vec3], on_rod: Vec3) -> Result<(), SimError> {
        let on_wall: Vec3 = f.iter().sum();
        self.stats.max_imbalance = self.stats.max_imbalance.max((on_wall + on_rod).norm());
        self.tissue.set_surface_forces(f)
    }

    /// The tissue's contact-surface nodes now. A wall that moved along its
    /// normal by more than the kernel radius has left what the moved lumen
    /// models ([`DisplacedLumen`]: first order in `|d| / h`): the run
    /// diverged (a staggered exchange blowing up ends here).
    fn surface(&self) -> Result<Vec<Vec3>, SimError> {
        let x = self.tissue.surface_positions().ok_or_else(|| SimError::SolverFailed {
            t: self.time(),
            reason: "the tissue stopped reporting its contact surface".into(),
        })?;
        let d = self
            .wall
            .normal_displacements(&x)
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()));
        if !(d <= self.wall.radius()) {
            return Err(SimError::Diverged {
                t: self.time(),
                reason: format!(
                    "the wall moved {d:.3e} m along its normal, past the {:.3e} m the moved lumen holds for",
                    self.wall.radius()
                ),
            });
        }
        Ok(x)
    }
}

impl Model for PairModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        let (st, sweeps) = match self.opts.scheme {
            Scheme::Staggered => self.staggered(dt, cmd)?,
            Scheme::Iterated => self.iterated(dt, cmd)?,
        };
        self.t += dt;
        self.stats.steps += 1;
        self.stats.sweeps += sweeps;
        self.stats.max_sweeps = self.stats.max_sweeps.max(sweeps);
        Ok(StepStats {
            iterations: sweeps as u32,
            ..st
        })
    }

    /// The rod's observation (hand force, contacts, rod) with the tissue's
    /// bodies and energies added.
    fn observe(&self) -> Observation {
        let mut o = self.rod.observe();
        let t = self.tissue.observe();
        o.tissues = t.tissues;
        o.energy.kinetic += t.energy.kinetic;
        o.energy.elastic += t.energy.elastic;
        o.energy.external += t.energy.external;
        o
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        None
    }

    /// Sweeps per step, the force balance, lost contacts and the wall fit;
    /// then each half's own diagnostics as `rod.k` and `tissue.k`.
    fn diagnostics(&self) -> BTreeMap<String, f64> {
        let s = &self.stats;
        let mut d = BTreeMap::new();
        d.insert("coupling_sweeps_mean".into(), s.sweeps as f64 / s.steps.max(1) as f64);
        d.insert("coupling_sweeps_max".into(), s.max_sweeps as f64);
        d.insert("force_imbalance_n".into(), s.max_imbalance);
        d.insert("lost_contacts".into(), s.lost_contacts as f64);
        d.insert("wall_fit_error_m".into(), s.max_fit_error);
        // Each half's own, under its prefix.
        for (prefix, half) in [
            (ROD_PREFIX, self.rod.diagnostics()),
            (TISSUE_PREFIX, self.tissue.diagnostics()),
        ] {
            d.extend(half.into_iter().map(|(k, v)| (format!("{prefix}{k}"), v)));
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixed point of `H(x) = A x + b` with `A` = diag(-50, -5, -0.5,
    /// 0.2): the gains of a stiff rod on a soft wall spread over two orders
    /// (plain iteration diverges: |-50| > 1).
    fn map(x: &[f64]) -> Vec<f64> {
        let a = [-50.0, -5.0, -0.5, 0.2];
        let b = [1.0, -2.0, 0.5, 3.0];
        x.iter().zip(a.iter().zip(&b)).map(|(x, (a, b))| a * x + b).collect()
    }

    fn sweeps(kind: Accel, limit: usize) -> Option<usize> {
        let mut acc = Accelerator::new(kind, 0.01);
        let mut x = vec![0.0; 4];
        for k in 1..=limit {
            let xt = map(&x);
            let r = xt.iter().zip(&x).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            if r < 1e-10 {
                return Some(k);
            }
            x = acc.next(&x, xt);
        }
        None
    }

    /// IQN-ILS solves a linear interface problem of dimension n in at most
    /// n + 2 sweeps (its least-squares model is exact once n differences
    /// span the space; Degroote et al. 2009); Aitken's single factor,
    /// serving gains of -50 and +0.2 at once, takes several times as many
    /// (44 measured).
    #[test]
    fn quasi_newton_solves_a_linear_interface_faster_than_aitken() {
        let iqn = sweeps(Accel::IqnIls, 200).expect("IQN-ILS converges");
        assert!(iqn <= 4 + 2, "IQN-ILS took {iqn} sweeps");
        let aitken = sweeps(Accel::Aitken, 200).expect("Aitken converges, slowly");
        eprintln!("sweeps: IQN-ILS {iqn}, Aitken {aitken}");
        assert!(aitken > 3 * iqn, "Aitken {aitken} vs IQN-ILS {iqn}");
    }
}
