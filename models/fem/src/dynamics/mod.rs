//! Time stepping and the harness model.
//!
//! Equation of motion with lumped mass `M`, Rayleigh damping
//! `C = alpha M + beta K` and elastic force `f_el = -dE/dx`:
//! `M a + C v = f_el(x) + f_g`. The end-of-step state `x` is found by
//! Newton iterations on `g(x) = f_el(x) + f_g - M a(x) - C v(x) = 0` where
//! `a(x)`, `v(x)` are the integrator's affine update rules:
//!
//! * Newmark (`beta_N = 1/4`, `gamma = 1/2`, average acceleration;
//!   Newmark 1959): `a = (x - x_n - dt v_n)/(beta_N dt^2) - (1/(2 beta_N) - 1) a_n`,
//!   `v = v_n + dt ((1 - gamma) a_n + gamma a)`;
//! * backward Euler: `v = (x - x_n)/dt`, `a = (v - v_n)/dt`.
//!
//! With one Newton iteration per step (the default, as in the
//! needle-insertion seed) this is the linearly implicit scheme. The Jacobian
//! is `(c_a + alpha c_v) M + (1 + beta c_v) K` with `c_a = da/dx`,
//! `c_v = dv/dx`. For the corotational law `K` is the warped stiffness
//! `R K0 R^T` (Müller and Gross 2004), and with `lazy_threshold > 0` an
//! element's block is rebuilt only when its rotation moved more than that
//! angle since the last rebuild.
//!
//! Linear solves per Newton iteration:
//! * Cholesky: while no block changed since the last numeric factorization
//!   (and the coefficients are the same), the factor is reused as is (one
//!   forward/backward solve). When blocks changed and `factor_reuse` is on
//!   (default), the stale factor preconditions a CG solve on the current
//!   matrix to the relative residual `reuse_tol` (default 1e-6: its error
//!   is five orders below the one-Newton-step scheme's own), and the matrix
//!   is refactorized on the next step once those CG solves have cost about
//!   one factorization more than one solve per step would have
//!   (`REFRESH_EXCESS`), or at once if CG does not converge in 25
//!   iterations. Otherwise the matrix is refactorized. With `reuse_f32`
//!   (default) that CG applies an `f32` copy of the stale factor, solved
//!   two-way parallel over a cut of its elimination tree
//!   ([`crate::supernodal`]); the CG stays in `f64`.
//! * CG: block-Jacobi PCG to the relative tolerance `cg_tol`, warm-started
//!   from the constant-acceleration predictor.

use crate::FemError;
use crate::assembly::{LinearSolver, System};
use crate::contact::SphereContact;
use crate::core::Solid;
use crate::element::Jacobian;
use crate::material::{Law, M3};
use crate::statics::{Constraint, Newton, StaticParams, dof_conditions, equilibrate};
use std::any::Any;
use surgbench_core::sphere_contact::DEFAULT_KAPPA;
use surgbench_core::statics::LoadStepper;
use surgbench_core::{
    DeviceCommand, EnergyObs, EnergyProbe, Model, Observation, SimError, StepStats, TissueBody, TissueObs, Vec3,
};

mod coupled;
mod linear;
mod model;

pub use coupled::LinearStep;

/// Default relative residual of the stale-factor-preconditioned CG
/// ([`DynParams::reuse_tol`]). Measured on the bench block
/// (examples/step_speed.rs): a relative residual of 1e-6 moves the nodes by
/// 7e-7 of the largest displacement, while the one-Newton-step scheme
/// itself is 6.0e-2 away from the converged implicit step: five orders of
/// magnitude below the scheme's own error.
pub const REUSE_TOL: f64 = 1e-6;
/// Refactorize on the next step once the stale-factor CG solves since the
/// last factorization exceed one per step by this many in total: a numeric
/// factorization costs about 53 forward/backward solves on the bench block
/// (520 M against 9.8 M instructions, callgrind), so refreshing when the
/// extra solves have cost one factorization keeps the total within twice
/// that of the best refresh schedule in hindsight (the ski-rental bound).
const REFRESH_EXCESS: usize = 50;
/// Iteration cap of that CG; past it the matrix is refactorized.
const REUSE_ITERS: usize = 25;

/// Time integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    /// Newmark average acceleration (`beta = 1/4`, `gamma = 1/2`).
    Newmark,
    /// Backward (implicit) Euler.
    BackwardEuler,
    /// Static equilibrium at every step (full Newton; velocities zero).
    QuasiStatic,
}

/// Settings of a [`FemModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynParams {
    /// Constitutive law.
    pub law: Law,
    /// Time integrator.
    pub integrator: Integrator,
    /// Linear solver.
    pub solver: LinearSolver,
    /// Lazy Jacobian threshold (rad); 0 rebuilds every element every step.
    pub lazy_threshold: f64,
    /// Cholesky only: when some Jacobian blocks changed since the last
    /// numeric factorization, solve with CG preconditioned by that stale
    /// factor (to the relative residual `reuse_tol`) instead of
    /// refactorizing; refactorize once its extra solves have cost about one
    /// factorization (see the module docs). `false`: refactorize whenever
    /// a block changed.
    pub factor_reuse: bool,
    /// Relative residual of that CG (default [`REUSE_TOL`]).
    pub reuse_tol: f64,
    /// That CG applies an `f32` copy of the stale factor
    /// ([`System::set_single_precision_preconditioner`], solved two-way
    /// parallel by [`crate::supernodal::SplitSolve`]); the CG stays in
    /// `f64` and reaches the same `reuse_tol`. Default `true`: on the bench
    /// block the same CG iterations and node error (6.8e-7 of the stroke
    /// against refactorizing every step) at a third of the preconditioner's
    /// wall time at 2 threads (examples/step_speed.rs, factor_cost.rs).
    /// Should an `f32` factor be too poor for some matrix, the CG misses its
    /// 25-iteration cap and the step refactorizes (no loss of accuracy).
    pub reuse_f32: bool,
    /// Rayleigh mass coefficient `alpha` (1/s).
    pub rayleigh_mass: f64,
    /// Rayleigh stiffness coefficient `beta` (s).
    pub rayleigh_stiffness: f64,
    /// Newton iterations per dynamic step (iteration cap for quasi-static).
    pub iterations: usize,
    /// Quasi-static Newton tolerance (relative force residual).
    pub tol: f64,
    /// Assembly threads.
    pub threads: usize,
    /// Penalty factor `kappa` of the sphere contact (`k_i = kappa E*
    /// sqrt(A_i)`, see [`crate::contact`]; default [`DEFAULT_KAPPA`]).
    pub contact_stiffness: f64,
}

impl Default for DynParams {
    fn default() -> Self {
        Self {
            law: Law::Corotational,
            integrator: Integrator::Newmark,
            solver: LinearSolver::default(),
            lazy_threshold: 0.0,
            factor_reuse: true,
            reuse_tol: REUSE_TOL,
            reuse_f32: true,
            rayleigh_mass: 0.0,
            rayleigh_stiffness: 0.0,
            iterations: 1,
            tol: 1e-9,
            threads: 2,
            contact_stiffness: DEFAULT_KAPPA,
        }
    }
}

/// A FEM tissue body stepping in time.
pub struct FemModel {
    solid: Solid,
    sys: System,
    p: DynParams,
    dt: f64,
    t: f64,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    a: Vec<Vec3>,
    /// Per-DOF displacement at full command (m).
    uc: Vec<f64>,
    driven: Vec<usize>,
    gravity_load: Vec<Vec3>,
    /// Forces from outside the model on nodes (N, world frame; a coupled
    /// instrument's contacts), held until replaced.
    external: Vec<Vec3>,
    /// The scene's contact-surface nodes (`TissueBody::surface_vertices`).
    surface: Vec<usize>,
    /// Pressure faces (outward node order) and pressures at full command (Pa).
    pressure: Vec<([usize; 3], f64)>,
    /// Coefficients of the cached matrix `(c_k, c_m)`.
    cached: Option<(f64, f64)>,
    hand_force: Vec3,
    inverted: usize,
    /// Some Jacobian block changed since the cached factorization.
    factor_stale: bool,
    /// Stale-factor CG solves beyond one per step since the factorization.
    excess_solves: usize,
    /// The cached factorization includes contact Hessian blocks.
    factor_has_contact: bool,
    /// Elements whose Jacobian was rebuilt in the last step.
    pub last_updated: usize,
    /// Command (load factor) of the last completed step.
    s_last: f64,
    /// Quasi-static load stepping so far (reported as diagnostics).
    statics: LoadStepping,
    /// Quasi-static: the command and external forces the current state is
    /// the equilibrium of, and that solve's relative residual (`None`
    /// before the first solve; saved and restored with the state).
    solved_for: Option<(f64, Vec<Vec3>, f64)>,
    /// The rigid sphere (its path) and its penalty contact, centred where
    /// the last step's command put it.
    contact: Option<(surgbench_core::scene::SphereIndenter, SphereContact)>,
    /// World position (m) of the local coordinates' origin: the rest mesh's
    /// bounding-box centre. `x`, the rest positions and the sphere are
    /// stored relative to it.
    origin: Vec3,
}

/// What the quasi-static load stepping did over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct LoadStepping {
    /// Load increments solved to equilibrium (a step whose command did not
    /// change solves none).
    increments: usize,
    /// Newton solves that failed and were retried with half the increment.
    failures: usize,
    /// Numeric Cholesky factorizations of the accepted increments' Newton
    /// iterations (modified Newton reuses one while it serves).
    factorizations: usize,
}

/// The integrator's affine update rules of one step:
/// `a(x) = c_a (x - x_n) + a0`, `v(x) = c_v (x - x_n) + v0`.
struct Update {
    /// `da/dx` (1/s^2).
    c_a: f64,
    /// `dv/dx` (1/s).
    c_v: f64,
    /// Acceleration at `x = x_n` (m/s^2).
    a0: Vec<Vec3>,
    /// Velocity at `x = x_n` (m/s).
    v0: Vec<Vec3>,
}

/// The contact Hessian blocks of one Newton iteration, at their diagonal
/// positions `at` in the block CSR matrix, scaled by `1 / c_k`.
struct ContactBlocks {
    at: Vec<usize>,
    blocks: Vec<(usize, M3)>,
    c_k: f64,
}

impl ContactBlocks {
    /// `kmat` plus the contact blocks over `c_k`; `None` without contact.
    fn apply(&self, kmat: &[M3]) -> Option<Vec<M3>> {
        (!self.blocks.is_empty()).then(|| {
            let mut k = kmat.to_vec();
            for (&d, (_, b)) in self.at.iter().zip(&self.blocks) {
                k[d] += b / self.c_k;
            }
            k
        })
    }
}

/// The linear solves of one dynamic step: CG iterations, the last relative
/// residual, and whether every solve met its tolerance.
struct LinearStats {
    cg_its: usize,
    res: f64,
    all_met: bool,
}

impl Default for LinearStats {
    fn default() -> Self {
        Self {
            cg_its: 0,
            res: 0.0,
            all_met: true,
        }
    }
}

impl FemModel {
    /// `dt` (s) and the settings are in range.
    fn check_settings(dt: f64, p: &DynParams) -> Result<(), FemError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(FemError::BadInput(format!("dt must be > 0 s, got {dt}")));
        }
        if p.iterations == 0
            || !(p.lazy_threshold >= 0.0)
            || !(p.rayleigh_mass >= 0.0)
            || !(p.rayleigh_stiffness >= 0.0)
            || !(0.0..1.0).contains(&p.reuse_tol)
            || p.reuse_tol == 0.0
            || !(p.contact_stiffness > 0.0 && p.contact_stiffness.is_finite())
        {
            return Err(FemError::BadInput(format!("bad dynamic settings {p:?}")));
        }
        Ok(())
    }

    /// The sphere `ind` of `body` as a path in the model's local
    /// coordinates (`origin` subtracted) and its penalty contact with the
    /// local mesh `local`, penalty factor `kappa`.
    fn sphere_contact(
        body: &TissueBody,
        ind: &surgbench_core::scene::SphereIndenter,
        local: &surgbench_core::TetMesh,
        origin: Vec3,
        kappa: f64,
    ) -> Result<(surgbench_core::scene::SphereIndenter, SphereContact), FemError> {
        ind.validate().map_err(FemError::BadInput)?;
        let c = SphereContact::new(local, &body.material, kappa, ind.centre, ind.radius);
        // The path in the model's local coordinates.
        let path = surgbench_core::scene::SphereIndenter {
            centre: ind.centre - origin,
            ..*ind
        };
        Ok((path, c))
    }

    /// Build from a tissue body (rest mesh, material, fixed and driven
    /// nodes), gravity (m/s^2), time step (s) and settings.
    pub fn new(body: &TissueBody, gravity: Vec3, dt: f64, p: DynParams) -> Result<Self, FemError> {
        // Work in coordinates relative to the rest mesh's bounding-box centre:
        // positions far from the world origin then cost no digits (the
        // penalty contact's force is k times a gap of ~1e-3 of the depth, and
        // in world coordinates 0.5 m away its rounding left a Newton floor
        // of 3e-7 of the force; rigid-motion conformance).
        let origin = if body.mesh.nodes.is_empty() {
            Vec3::zeros()
        } else {
            let (lo, hi) = surgbench_core::mesh::bounds(&body.mesh);
            (lo + hi) * 0.5
        };
        Self::build(body, gravity, dt, p, origin)
    }

    /// [`Self::new`] with the local coordinates' origin `origin` (m, world).
    fn build(body: &TissueBody, gravity: Vec3, dt: f64, p: DynParams, origin: Vec3) -> Result<Self, FemError> {
        Self::check_settings(dt, &p)?;
        let local = surgbench_core::TetMesh {
            nodes: body.mesh.nodes.iter().map(|p| p - origin).collect(),
            tets: body.mesh.tets.clone(),
        };
        let (materials, tet_material) = body.tet_materials();
        let solid = Solid::with_materials(&local, &materials, &tet_material, p.law, p.threads)?;
        let n = solid.n_nodes();
        let mut cons: Vec<Constraint> = body.fixed_nodes.iter().map(|&i| Constraint::fixed(i)).collect();
        cons.extend(body.partial_fixed.iter().map(|&(i, axes)| Constraint {
            node: i,
            axes,
            displacement: Vec3::zeros(),
        }));
        for (f, p) in &body.pressure_faces {
            if f.iter().any(|&i| i >= n) || !p.is_finite() {
                return Err(FemError::BadInput(format!(
                    "pressure face {f:?} ({p} Pa) is out of range"
                )));
            }
        }
        cons.extend(body.driven_nodes.iter().map(|&(i, d)| Constraint::displaced(i, d)));
        let (free, uc) = dof_conditions(n, &cons)?;
        let rho: Vec<f64> = materials.iter().map(|m| m.density).collect();
        let gravity_load = solid.body_loads_by_tet(&|_: &Vec3, e| gravity * rho[solid.material_index(e)]);
        let mut sys = System::new(&solid.pat, free);
        sys.set_single_precision_preconditioner(p.reuse_f32);
        let x = solid.rest.clone();
        let contact = match &body.indenter {
            None => None,
            Some(ind) => Some(Self::sphere_contact(body, ind, &local, origin, p.contact_stiffness)?),
        };
        Ok(Self {
            solid,
            sys,
            p,
            dt,
            t: 0.0,
            x,
            v: body.start_velocities(),
            a: vec![Vec3::zeros(); n],
            uc,
            driven: body.driven_nodes.iter().map(|d| d.0).collect(),
            gravity_load,
            external: vec![Vec3::zeros(); n],
            surface: body.surface_vertices(),
            pressure: body.pressure_faces.clone(),
            cached: None,
            hand_force: Vec3::zeros(),
            inverted: 0,
            factor_stale: true,
            excess_solves: 0,
            factor_has_contact: false,
            last_updated: 0,
            s_last: 0.0,
            statics: LoadStepping::default(),
            solved_for: None,
            contact,
            origin,
        })
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Elastic energy (J) of the current state, contact included: what the
    /// needle's tip remeshing measures before and after it changes the mesh.
    pub fn elastic_energy(&self) -> f64 {
        self.energies().elastic
    }

    /// The most compressed tet's volume ratio `V / V0` (see
    /// [`Solid::min_volume_ratio`]).
    pub fn min_volume_ratio(&self) -> f64 {
        self.solid.min_volume_ratio(&self.x)
    }

    /// Node velocities (m/s) and accelerations (m/s^2), in mesh order.
    pub fn motion(&self) -> (&[Vec3], &[Vec3]) {
        (&self.v, &self.a)
    }

    /// The same tissue continued on a remeshed body (needle-tip remeshing,
    /// issue 18): `body` is the body this model was built from with its
    /// rest mesh replaced, `x` (m, world), `v` and `a` the state on the new
    /// mesh (the caller interpolates it at new or moved material points).
    /// Time, load parameter, hand force and the settings carry over; the
    /// element caches, the sparsity pattern and the factorization are built
    /// anew (the next step factorizes). External forces restart at zero: a
    /// coupling sets them every step. The local coordinates keep their
    /// origin, so the nodes that stay keep their local positions exactly.
    pub fn remeshed(
        &self,
        body: &TissueBody,
        gravity: Vec3,
        x: &[Vec3],
        v: &[Vec3],
        a: &[Vec3],
    ) -> Result<Self, FemError> {
        let n = body.mesh.nodes.len();
        if x.len() != n || v.len() != n || a.len() != n {
            return Err(FemError::BadInput(format!(
                "a remeshed state needs {n} positions, velocities and accelerations, got {}, {}, {}",
                x.len(),
                v.len(),
                a.len()
            )));
        }
        let mut m = Self::build(body, gravity, self.dt, self.p, self.origin)?;
        m.t = self.t;
        m.x = x.iter().map(|p| p - m.origin).collect();
        m.v = v.to_vec();
        m.a = a.to_vec();
        m.s_last = self.s_last;
        m.hand_force = self.hand_force;
        Ok(m)
    }

    /// Current node positions (m, world coordinates).
    pub fn positions(&self) -> Vec<Vec3> {
        self.x.iter().map(|p| p + self.origin).collect()
    }

    /// Rest position (m, world coordinates) of node `i`.
    pub fn rest_position(&self, i: usize) -> Vec3 {
        self.solid.rest[i] + self.origin
    }

    /// Non-zeros of the Cholesky factor (after the first factorization).
    pub fn factor_nnz(&self) -> Option<usize> {
        self.sys.factor_nnz()
    }

    /// Numeric factorizations and CG iterations so far.
    pub fn solver_counts(&self) -> (usize, usize) {
        (self.sys.factorizations, self.sys.cg_iterations)
    }

    /// Follower pressure forces (N per DOF) on the deformed faces at `x`,
    /// scaled by `s`: each face node gets `-s p A n / 3`.
    fn pressure_forces(pressure: &[([usize; 3], f64)], s: f64, x: &[Vec3]) -> Vec<f64> {
        let mut out = vec![0.0; 3 * x.len()];
        for (f, p) in pressure {
            let [a, b, c] = f.map(|i| x[i]);
            let an = (b - a).cross(&(c - a)) * (-0.5 * s * p / 3.0);
            for &i in f {
                for k in 0..3 {
                    out[3 * i + k] += an[k];
                }
            }
        }
        out
    }

    fn set_constrained(&mut self, s: f64) {
        for d in 0..self.uc.len() {
            if !self.sys.free[d] {
                self.x[d / 3][d % 3] = self.solid.rest[d / 3][d % 3] + s * self.uc[d];
            }
        }
    }

    fn fail(&self, reason: impl Into<String>) -> SimError {
        SimError::SolverFailed {
            t: self.t,
            reason: reason.into(),
        }
    }

    /// Quasi-static step to the command `s`: equilibrium by adaptive load
    /// stepping ([`Self::load_steps`]), then the hand force (the reaction
    /// on the driven nodes plus the force on the sphere) and zero velocities.
    fn quasi_static_step(&mut self, s: f64, t_end: f64) -> Result<StepStats, SimError> {
        // The same command and external forces as the last solve: the state
        // is already their equilibrium (re-solving could only move it within
        // the Newton tolerance, and keeps a static run from ever repeating
        // its state exactly).
        if let Some((_, _, residual)) = self
            .solved_for
            .as_ref()
            .filter(|(s0, e, _)| *s0 == s && *e == self.external)
        {
            return Ok(StepStats {
                iterations: 0,
                residual: *residual,
                converged: true,
            });
        }
        let res = self.load_steps(s);
        let nt = res.map_err(|e| SimError::SolverFailed {
            t: t_end,
            reason: e.to_string(),
        })?;
        // Contact forces are in the residual `r`, so a driven node the
        // sphere touches counts once: in the contact reaction.
        let mut r = nt.r.clone();
        if let Some((_, c)) = &self.contact {
            let mut fc = vec![0.0; r.len()];
            c.add_forces(&self.x, &mut fc);
            r.iter_mut().zip(&fc).for_each(|(a, b)| *a -= b);
            self.hand_force = c.reaction(&self.x);
        } else {
            self.hand_force = Vec3::zeros();
        }
        self.hand_force += self
            .driven
            .iter()
            .map(|&i| Vec3::new(r[3 * i], r[3 * i + 1], r[3 * i + 2]))
            .sum::<Vec3>();
        self.inverted = nt.inverted;
        self.v.iter_mut().for_each(|v| *v = Vec3::zeros());
        self.a.iter_mut().for_each(|a| *a = Vec3::zeros());
        self.solved_for = Some((s, self.external.clone(), nt.residual));
        Ok(StepStats {
            iterations: nt.iterations as u32,
            residual: nt.residual,
            converged: true,
        })
    }

    /// Adaptive load stepping ([`LoadStepper`]) from the last converged
    /// command `s_last` to `s`: a Newton solve fails when it has not
    /// converged in `iterations` or inverts neo-Hookean elements, and the
    /// step returns the last failure once the stepper gives up. Leaves the
    /// positions reached in `self.x`; counts the accepted increments and
    /// the failed solves in `self.statics`.
    fn load_steps(&mut self, s: f64) -> Result<Newton, FemError> {
        let load: Vec<f64> = self
            .gravity_load
            .iter()
            .zip(&self.external)
            .flat_map(|(f, e)| [f.x + e.x, f.y + e.y, f.z + e.z])
            .collect();
        let sp = StaticParams {
            load_steps: 1,
            tol: self.p.tol,
            max_newton: self.p.iterations.max(1),
            solver: self.p.solver,
            threads: self.p.threads,
            factor_reuse: self.p.factor_reuse,
        };
        let mut x = std::mem::take(&mut self.x);
        let mut x_ok = x.clone();
        // Modified Newton reuses factorizations within this step only, so
        // that the step depends on the state alone (a restored state steps
        // bit for bit as the saved one did).
        self.sys.forget_factorization();
        let mut steps = LoadStepper::new(self.s_last, s);
        let mut its = 0;
        let res = loop {
            let hi = steps.target();
            for d in 0..self.uc.len() {
                if !self.sys.free[d] {
                    x[d / 3][d % 3] = self.solid.rest[d / 3][d % 3] + hi * self.uc[d];
                }
            }
            let pressure = &self.pressure;
            let follower = move |x: &[Vec3]| Self::pressure_forces(pressure, hi, x);
            let fol: Option<crate::statics::Follower> = if self.pressure.is_empty() {
                None
            } else {
                Some(&follower)
            };
            if let Some((ind, c)) = &mut self.contact {
                c.centre = ind.centre_at(hi);
            }
            let con = self.contact.as_ref().map(|c| &c.1);
            match equilibrate(&mut self.solid, &mut self.sys, &mut x, &load, fol, con, &sp, 1) {
                Ok(nt) => {
                    its += nt.iterations;
                    self.statics.factorizations += nt.factorizations;
                    if steps.converged(nt.iterations) {
                        break Ok(nt);
                    }
                    x_ok.clone_from(&x);
                }
                Err(FemError::NotConverged { .. } | FemError::Inverted { .. }) if steps.failed() => {
                    x.clone_from(&x_ok);
                }
                Err(e) => break Err(e),
            }
        };
        self.statics.increments += steps.increments;
        self.statics.failures += steps.failures;
        let res = res.map(|mut nt| {
            nt.iterations = its;
            nt
        });
        self.x = x;
        self.cached = None;
        res
    }

    /// One step of length `dt` (s) with the command scale `s` for the driven
    /// displacements.
    pub fn advance(&mut self, dt: f64, s: f64) -> Result<StepStats, SimError> {
        if !(dt > 0.0 && dt.is_finite() && s.is_finite()) {
            return Err(self.fail(format!("bad step dt={dt} s, command {s}")));
        }
        let t_end = self.t + dt;
        let stats = if self.p.integrator == Integrator::QuasiStatic {
            self.quasi_static_step(s, t_end)?
        } else {
            self.dynamic_step(dt, s, t_end)?
        };
        self.t = t_end;
        self.s_last = s;
        self.check_state()?;
        Ok(stats)
    }

    /// The integrator's affine update rules of this step (see [`Update`]).
    fn update_rules(&self, dt: f64) -> Update {
        let n = self.solid.n_nodes();
        let (vn, an) = (&self.v, &self.a);
        match self.p.integrator {
            Integrator::Newmark => {
                let (b, g) = (0.25, 0.5);
                let c_a = 1.0 / (b * dt * dt);
                let a0: Vec<Vec3> = (0..n).map(|i| -vn[i] / (b * dt) - an[i] * (0.5 / b - 1.0)).collect();
                let v0: Vec<Vec3> = (0..n).map(|i| vn[i] + (an[i] * (1.0 - g) + a0[i] * g) * dt).collect();
                Update {
                    c_a,
                    c_v: g / (b * dt),
                    a0,
                    v0,
                }
            }
            _ => Update {
                c_a: 1.0 / (dt * dt),
                c_v: 1.0 / dt,
                a0: vn.iter().map(|v| -v / dt).collect(),
                v0: vec![Vec3::zeros(); n],
            },
        }
    }

    /// The Newton residual `g(x) = f_el + f_g + f_p - M (a + alpha v) - beta K v`
    /// (N per DOF) at the current positions, without contact; `xn` are the
    /// positions at the start of the step. Needs `self.solid` evaluated at `x`.
    fn dynamic_residual(&self, u: &Update, xn: &[Vec3], s: f64) -> Vec<f64> {
        let n = self.solid.n_nodes();
        let (alpha, beta) = (self.p.rayleigh_mass, self.p.rayleigh_stiffness);
        let dxs: Vec<Vec3> = (0..n).map(|i| self.x[i] - xn[i]).collect();
        let vel: Vec<Vec3> = (0..n).map(|i| u.v0[i] + dxs[i] * u.c_v).collect();
        let kv = if beta > 0.0 {
            self.solid.k_times(&vel)
        } else {
            vec![Vec3::zeros(); n]
        };
        let m = &self.solid.mass;
        let pf = Self::pressure_forces(&self.pressure, s, &self.x);
        let mut r = vec![0.0; 3 * n];
        for i in 0..n {
            let acc = u.a0[i] + dxs[i] * u.c_a;
            let ri = self.solid.forces[i] + self.gravity_load[i] + self.external[i]
                - (acc + vel[i] * alpha) * m[i]
                - kv[i] * beta;
            r[3 * i] = ri.x + pf[3 * i];
            r[3 * i + 1] = ri.y + pf[3 * i + 1];
            r[3 * i + 2] = ri.z + pf[3 * i + 2];
        }
        r
    }

    /// Initial guess of the first Newton iteration's iterative solves: the
    /// constant-acceleration predictor `dx = dt v_n + dt^2/2 a_n` (Newmark)
    /// or `dt v_n` (backward Euler), exact up to O(dt^3) for a smooth motion,
    /// on the free DOFs. Later iterations solve for a correction and start
    /// from zero.
    fn predictor(&self, dt: f64) -> Vec<f64> {
        let n = self.solid.n_nodes();
        let mut guess = vec![0.0; 3 * n];
        let h = if self.p.integrator == Integrator::Newmark {
            0.5 * dt * dt
        } else {
            0.0
        };
        for i in 0..n {
            let g = self.v[i] * dt + self.a[i] * h;
            for k in 0..3 {
                if self.sys.free[3 * i + k] {
                    guess[3 * i + k] = g[k];
                }
            }
        }
        guess
    }

    /// One dynamic step: `p.iterations` Newton iterations on `g(x) = 0` (a
    /// fixed count: with one it is the linearly implicit scheme, there is no
    /// Newton tolerance), then the new velocities, accelerations and hand
    /// force. `converged` says whether every linear solve of the step met
    /// its tolerance (a direct solve always does; CG may stop at `max_iter`).
    fn dynamic_step(&mut self, dt: f64, s: f64, t_end: f64) -> Result<StepStats, SimError> {
        let n = self.solid.n_nodes();
        let xn = self.x.clone();
        let u = self.update_rules(dt);
        let (alpha, beta) = (self.p.rayleigh_mass, self.p.rayleigh_stiffness);
        let c_m = u.c_a + alpha * u.c_v;
        let c_k = 1.0 + beta * u.c_v;
        self.set_constrained(s);
        if let Some((ind, c)) = &mut self.contact {
            c.centre = ind.centre_at(s);
        }
        let jac = match self.p.law {
            Law::NeoHookean => Jacobian::Exact,
            _ => Jacobian::Warped,
        };
        let mut last_r = vec![0.0; 3 * n];
        let mut last_dx = vec![0.0; 3 * n];
        let mut lin = LinearStats::default();
        let mut updated = 0;
        for newton_it in 0..self.p.iterations {
            let st = self.solid.evaluate(&self.x, Some(jac), self.p.lazy_threshold);
            updated += st.updated;
            self.inverted = st.inverted;
            let mut r = self.dynamic_residual(&u, &xn, s);
            // The sphere contact: its forces join the residual (the
            // elastic part `r_el` gives the driven nodes' reaction), its
            // Hessian blocks join the matrix, divided by `c_k` so that the
            // system is `c_k K + H_c + c_m M`; the factor then no longer
            // matches. The blocks are projected (`k n n^T`, dropping the
            // tangential `k g / d (I - n n^T)`, negative inside the sphere):
            // a stiff penalty on a light, soft mesh otherwise makes the
            // matrix indefinite (seen on a 4^3 block: k ~ 100 x the
            // elastic and inertial terms, g / d ~ -0.04); it changes only
            // Newton's rate, not the forces or the converged state.
            let r_el = r.clone();
            let blocks = match &self.contact {
                Some((_, c)) => {
                    c.add_forces(&self.x, &mut r);
                    c.hessian_blocks(&self.x, true)
                }
                None => Vec::new(),
            };
            let hc = ContactBlocks {
                at: blocks.iter().map(|(i, _)| self.solid.pat.diag[*i]).collect(),
                blocks,
                c_k,
            };
            let guess = if newton_it == 0 {
                self.predictor(dt)
            } else {
                vec![0.0; 3 * n]
            };
            let dx = self.linear_solve(&r, guess, &hc, (c_k, c_m), st.updated, &mut lin, t_end)?;
            for i in 0..n {
                self.x[i] += Vec3::new(dx[3 * i], dx[3 * i + 1], dx[3 * i + 2]);
            }
            last_r = r_el;
            last_dx = dx;
        }
        self.last_updated = updated;
        self.finish_dynamic_step(&u, &xn, &last_r, &last_dx, c_k);
        Ok(StepStats {
            iterations: if lin.cg_its > 0 {
                lin.cg_its as u32
            } else {
                self.p.iterations as u32
            },
            residual: lin.res,
            converged: lin.all_met,
        })
    }

    /// End of a dynamic step: accelerations and velocities from the update
    /// rules, and the hand force. The reaction on the driven nodes is
    /// linearized to the end of the step, `r(x + dx) ~ r - c_k K dx` (the
    /// mass term vanishes on constrained DOFs), plus the force on the sphere
    /// at the end of the step.
    fn finish_dynamic_step(&mut self, u: &Update, xn: &[Vec3], last_r: &[f64], last_dx: &[f64], c_k: f64) {
        let n = self.solid.n_nodes();
        for i in 0..n {
            let d = self.x[i] - xn[i];
            self.a[i] = u.a0[i] + d * u.c_a;
            self.v[i] = u.v0[i] + d * u.c_v;
        }
        // The driven nodes' reaction needs `K dx` (a product over every
        // element): skipped where no node is driven.
        let kdx = if self.driven.is_empty() {
            Vec::new()
        } else {
            let dxv: Vec<Vec3> = (0..n)
                .map(|i| Vec3::new(last_dx[3 * i], last_dx[3 * i + 1], last_dx[3 * i + 2]))
                .collect();
            self.solid.k_times(&dxv)
        };
        self.hand_force = self
            .driven
            .iter()
            .map(|&i| Vec3::new(last_r[3 * i], last_r[3 * i + 1], last_r[3 * i + 2]) - kdx[i] * c_k)
            .sum::<Vec3>()
            + self
                .contact
                .as_ref()
                .map_or(Vec3::zeros(), |(_, c)| c.reaction(&self.x));
    }

    fn energies(&self) -> EnergyObs {
        let kinetic = 0.5
            * (0..self.x.len())
                .map(|i| self.solid.mass[i] * self.v[i].norm_squared())
                .sum::<f64>();
        let (elastic, _) = self.solid.energy_forces(&self.x);
        let elastic = elastic + self.contact.as_ref().map_or(0.0, |c| c.1.energy(&self.x));
        let external = -(0..self.x.len())
            .map(|i| self.gravity_load[i].dot(&(self.x[i] - self.solid.rest[i])))
            .sum::<f64>();
        EnergyObs {
            kinetic,
            elastic,
            external,
        }
    }
}
