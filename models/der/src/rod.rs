//! [`DerRod`]: the discrete elastic rod as a plain library object (state,
//! loads, implicit time stepping, statics, contact, observation). The
//! [`crate::DerModel`] wraps it for the harness; other crates (FEM needle
//! coupling) can use it directly. SI units throughout.
//!
//! # Degrees of freedom
//! `segments + 2` nodes and one twist angle per edge, interleaved as
//! `q = [x_0, theta_0, x_1, theta_1, ..., x_{n-1}]` (4 per node, `4n - 1` in
//! all) so that the Hessian is banded with half-bandwidth 10. Node 0 sits one
//! edge *behind* the clamp (a ghost edge), node 1 at the clamp point; both
//! nodes and the ghost twist `theta_0` are prescribed by the clamp, which
//! gives the clamped end its bending moment and second-order convergence.
//!
//! # Time stepping
//! Backward Euler (default) or Newmark `beta = 1/4, gamma = 1/2`, each step a
//! full Newton solve of the incremental potential
//! `Phi(q) = inertia(q) + E(q) - F . q` with the analytic Hessian (symmetric
//! part, see [`crate::energy`]), the banded Cholesky of [`crate::band`]
//! and a backtracking (Armijo) line search on `Phi`. The matrix is the exact
//! Hessian; only if it is not positive definite (a compressed edge's
//! negative transverse stiffness, buckling) are the compressive terms
//! dropped (projected Newton) and, as a last resort, the diagonal shifted.
//! Newton starts from the constant-velocity prediction `q_n + dt v_n`. The
//! potential's linear terms are measured from the start of the step and
//! the stopping test uses Euclidean node updates, so the iteration does not
//! depend on where the scene sits or how it is oriented. Reference frames
//! are parallel-transported in time from the start of the step to every
//! Newton iterate (DER section 5). Twist is quasi-static by
//! default (no rotational inertia: `theta` is in equilibrium every step,
//! DER section 7.1), or dynamic with inertia `rho J |e|`.
//!
//! # Loads
//! Gravity on lumped node masses (half of each adjacent edge's `rho A |e|`;
//! the ghost edge is massless), a dead tip force on the last node, a dead tip
//! torque: its component along the last tangent acts on the last twist angle,
//! the transverse part as a force couple `f = tau_perp x e / |e|^2` on the
//! last edge's two nodes (evaluated at the current configuration; its
//! configuration dependence is left out of the Newton matrix, so a large
//! transverse torque converges linearly), and optional per-node dead forces
//! ([`DerRod::set_node_force`], e.g. for coupling). Tip force and torque
//! may vary in time through a ramp `s(t)` ([`DerRod::tip_load_ramp`], from
//! [`RodBody::tip_load_ramp`]): like every implicit scheme that imposes
//! equilibrium at the end of the step (backward Euler, Newmark), a (sub)step
//! from `t` to `t + dt` applies `s(t + dt) F`; statics apply `s(t)`.
//!
//! # Contact
//! Only scenes with a vessel pay for it. Contact and friction are both
//! terms of the incremental potential, so Newton resolves them together
//! with elasticity and inertia (nothing moves the nodes after the solve):
//!
//! * normal: every node past the margin surface (`phi(x) + margin = d > 0`)
//!   feels a stiff penalty `k d^2 / 2` (`k = 10 max EA/|e|`, with a C2 cubic
//!   onset over `eps_c = 1e-5 L`; Hessian `P'' n n^T + P' dn/dx`, the wall
//!   curvature `dn/dx` from the SDF's Hessian ([`Sdf::hessian`]) and kept
//!   only where it stiffens, see `DerRod::wall_curvature`). A node
//!   carrying a wall force `F` sits `sqrt(2 eps_c F / k)` past the margin
//!   surface (`F/k + eps_c/2` above `k eps_c / 2`), e.g. 1e-7 m for 0.1 N on
//!   a 0.2 m, 0.2 mm nitinol wire at 40 segments;
//! * friction: the smoothed, lagged Coulomb potential
//!   [`surgbench_core::contact::LaggedFriction`] (Li et al. 2020, "Incremental
//!   Potential Contact", section 5) with the normal force `lambda` and
//!   normal of the previous step's solution, the slip measured from the
//!   start of the step and a stick-slip width `eps = friction_creep * dt`
//!   ([`DerParams::friction_creep`]). A node that stuck in the previous step
//!   gets `mu_s`, one that slid `mu_d`. A node that first touches the wall
//!   in a step has no friction until the next step (one-step lag).
//!
//! The wall force reported for a node ([`DerRod::contacts`]) is the penalty
//! force plus the friction force at the converged state: the exact contact
//! force of the solved step, so at rest hand and wall forces balance the
//! loads to the Newton tolerance. Twist is not affected by contact (no
//! friction torque about the wire axis).
//!
//! # Step control (contact scenes) and adaptive substepping
//! Each Newton iterate in a scene with a vessel is scaled so that no node
//! moves by more than half its distance to the margin surface (the SDF is
//! 1-Lipschitz, so it cannot jump through the wall), or, for a node on the
//! wall, by more than a tenth of its shortest edge (so it can slide), and
//! never by more than half an edge (no edge flips), and so that no node
//! sliding under friction is carried past the apex of its friction cone
//! (see `step_cap`); the constant-velocity warm start is scaled by the
//! first two bounds. Then the Armijo line search runs on
//! the full incremental potential (elastic + inertia + penalty + lagged
//! friction + drag). If it finds no decrease, or Newton does not converge
//! in [`DerParams::max_iterations`], the step is retried as two half steps
//! with the clamp command interpolated, down to `dt / 2^max_substep_depth`
//! ([`DerParams::max_substep_depth`], default 6). `StepStats` has no
//! substep field: `iterations` sums all substeps and
//! [`DerRod::last_substeps`] tells how many were taken.
//!
//! Limit (measured, `tests/contact.rs`, ignored test): pushing a 0.1 m,
//! 40-segment wire 30 mm into a closed 2 mm tube (SDF = `max` of tube and
//! end plane), the tip first touches the end at 4.9 mm of push.
//! Frictionless, the run now completes the 30 mm with the nodes within
//! 1.5e-6 m of the margin surface, but the wire is compressed by 3.8e-3:
//! the helically buckled wire carries ~24 N, the helical-buckling force
//! `8 pi^2 EI / p^2` for the pitch `p` = 13.6 mm that packs 30% excess
//! length into the 1.8 mm lumen, so the test's 1e-3 stretch bound is not
//! physical at that push (frictionless numbers measured before the
//! wall-curvature Hessian and the friction-apex step cap; not re-measured).
//! With friction 0.2/0.15 Newton used to fail once the wire was wedged and
//! an edge collapsed (`Diverged`) after 7-12 mm of push; with the
//! friction-apex step cap the run completes the 30 mm (one run, 260 s on a
//! loaded machine): nodes up to 1.2e-6 m past the margin surface (the
//! penalty depth `F/k` of ~30 N on one node, `k` = 2.5e7 N/m),
//! compression 3.3e-3, peak push force 43 N, so the test's 1e-9 m depth
//! and 1e-3 stretch bounds still fail.
//!
//! # Flow drag
//! With a flow field ([`DerRod::set_flow`]), every free half-edge feels the
//! quadratic (Morison-type) drag per unit length
//! `f = rho/2 d (C_n |u_n| u_n + pi C_t |u_t| u_t)`, `u = w - v` the flow
//! velocity relative to the node, split along the edge tangent (Hoerner,
//! "Fluid-Dynamic Drag", 1965, ch. 2-3; the coefficients and blood density
//! are in [`surgbench_core::flow`]). Why
//! quadratic and not resistive-force theory (Gray & Hancock 1955; Lighthill
//! 1976): the `flow-drift` scene has a wire of d = 0.89 mm in blood
//! (viscosity ~3.5e-3 Pa s) at up to 0.5 m/s, a cylinder Reynolds number
//! `rho U d / mu` ~ 135, far from the Stokes regime (Re << 1) where RFT
//! holds; cylinder drag there is dominated by pressure drag,
//! `C_n` ~ 1.2-1.4. The drag enters the implicit solve as a convex potential of
//! the step with the flow velocity (at the node) and the edge tangents
//! frozen at the start of the step: `sum (c_n |u_n|^3 + c_t |u_t|^3)/(3a)`
//! with `v = a (x - x_0) + b` (backward Euler `a = 1/dt`), whose gradient is
//! minus the drag and whose Hessian `a dF/du` is positive semi-definite.
//! The clamped node's half-edge drag goes to the hand force. Statics
//! ([`DerRod::solve_static`]) ignore the flow.

use crate::band::BandMatrix;
use crate::energy::{self, Stencil, VertexParams, VertexTerms};
use std::sync::Arc;
use surgbench_core::contact::LaggedFriction;
use surgbench_core::flow::{BLOOD_DENSITY, DRAG_NORMAL, DRAG_TANGENTIAL, FlowField};
use surgbench_core::frames::rotate_about;
use surgbench_core::motion::carried;
use surgbench_core::{
    BuildError, ContactObs, ContactParams, DeviceCommand, EnergyObs, EnergyProbe, Environment, Iso3, LoadRamp, Mat3,
    RodBody, RodObs, Sdf, SimError, StepStats, Vec3,
};

/// Number of leading DOFs fixed by the clamp: `x_0`, `theta_0`, `x_1`.
pub const CLAMPED_DOFS: usize = 7;
/// Half-bandwidth of the interleaved Hessian.
const BAND: usize = 10;
/// Default [`DerParams::friction_creep`] (m/s): 1 um/s, so a wire held by
/// static friction creeps less than 1 um in a second of simulated time.
pub const DEFAULT_FRICTION_CREEP: f64 = 1e-6;

/// Default [`DerParams::max_substep_depth`]: down to `dt / 64`.
pub const DEFAULT_SUBSTEP_DEPTH: usize = 6;
/// Step control in contact scenes: a Newton iterate moves no node by more
/// than this fraction of its distance to the margin surface...
const CCD_FRACTION: f64 = 0.5;
/// ... or, if larger, this fraction of its shortest adjacent rest edge (so a
/// node on the wall can still slide along it) ...
const SLIDE_FRACTION: f64 = 0.1;
/// ... and never by more than this fraction of that edge (no edge flips).
const TRUST_FRACTION: f64 = 0.5;

/// The state a step may change, saved before a step so that a failed step
/// can be retried with substeps.
#[derive(Debug, Clone, Default)]
struct Snapshot {
    q: Vec<f64>,
    qdot: Vec<f64>,
    qddot: Vec<f64>,
    a1: Vec<Vec3>,
    tan: Vec<Vec3>,
    rtwist: Vec<f64>,
    lag: Vec<ContactLag>,
    accel_valid: bool,
    time: f64,
}

/// Contact state a node carries from one step to the next (lagged normal
/// force and normal for the friction of the next step).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ContactLag {
    /// Penalty normal force at the end of the step (N), 0 out of contact.
    force: f64,
    /// Unit wall normal at the end of the step.
    normal: Vec3,
    /// Whether the node slid (slip >= the stick-slip width) in the step.
    sliding: bool,
}

impl ContactLag {
    const NONE: ContactLag = ContactLag {
        force: 0.0,
        normal: Vec3::new(0.0, 0.0, 0.0),
        sliding: false,
    };
}

/// Time integrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    /// Backward (implicit) Euler: first order, strongly damped, robust.
    BackwardEuler,
    /// Newmark average acceleration (`beta = 1/4`, `gamma = 1/2`): second
    /// order, no numerical damping.
    Newmark,
}

/// How the twist angles evolve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TwistDynamics {
    /// No rotational inertia: twist is in equilibrium every step (infinite
    /// twist wave speed, Bergou 2008 section 7.1).
    QuasiStatic,
    /// Rotational inertia `rho J |e|` per edge.
    Dynamic,
}

/// Solver settings of a [`DerRod`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DerParams {
    /// Time integrator.
    pub integrator: Integrator,
    /// Quasi-static or dynamic twist.
    pub twist: TwistDynamics,
    /// Mass-proportional viscous damping coefficient (1/s): force `-c m v`.
    pub damping: f64,
    /// Largest number of Newton iterations per step.
    pub max_iterations: usize,
    /// Newton stops when the update is below `tolerance` (largest node
    /// displacement relative to the rod length, angles in rad).
    pub tolerance: f64,
    /// Stick-slip width of the smoothed friction as a speed (m/s): a node
    /// loaded below the friction bound creeps at most this fast; the slip
    /// width per step is `friction_creep * dt` (see the module docs).
    pub friction_creep: f64,
    /// Largest number of step halvings (adaptive substepping): a step whose
    /// Newton solve does not converge is retried as two steps of `dt/2`
    /// (the clamp command interpolated linearly), recursively, down to
    /// `dt / 2^max_substep_depth`; see [`DerRod::step`].
    pub max_substep_depth: usize,
}

impl Default for DerParams {
    fn default() -> Self {
        Self {
            integrator: Integrator::BackwardEuler,
            twist: TwistDynamics::QuasiStatic,
            damping: 0.0,
            max_iterations: 25,
            tolerance: 1e-9,
            friction_creep: DEFAULT_FRICTION_CREEP,
            max_substep_depth: DEFAULT_SUBSTEP_DEPTH,
        }
    }
}

/// Which parts of the incremental potential to evaluate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Eval {
    Energy,
    Full,
}

/// Inertial part of the incremental potential for one step:
/// `m [ka/2 (q - q_tilde)^2 + kc/2 (q - q_0)^2 - lin_i q]`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Inertia {
    ka: f64,
    kc: f64,
}

/// A discrete elastic rod clamped at its base (see the module docs).
#[derive(Debug, Clone)]
pub struct DerRod {
    /// Solver settings (may be changed between steps).
    pub params: DerParams,
    /// Gravity (m/s^2).
    pub gravity: Vec3,
    /// Dead force on the last node (N).
    pub tip_force: Vec3,
    /// Dead torque on the last edge (N m), see the module docs.
    pub tip_torque: Vec3,
    /// Time profile of the tip loads: both are scaled by its value at the
    /// end of each (sub)step (`None`: full loads at all times); see the
    /// module docs, "Loads".
    pub tip_load_ramp: Option<LoadRamp>,
    /// Scale of the tip loads in the current solve (the ramp at the end of
    /// the step being solved).
    load_scale: f64,
    vessel: Option<Arc<dyn Sdf>>,
    contact: ContactParams,
    contact_stiffness: f64,
    contact_onset: f64,
    n: usize,
    length: f64,
    base: Iso3,
    rest_len: Vec<f64>,
    ea: Vec<f64>,
    rot_inertia: Vec<f64>,
    vparams: Vec<VertexParams>,
    edge_bend: Vec<[f64; 2]>,
    bend_len: Vec<f64>,
    node_mass: Vec<f64>,
    node_forces: Vec<Vec3>,
    q: Vec<f64>,
    qdot: Vec<f64>,
    qddot: Vec<f64>,
    accel_valid: bool,
    a1: Vec<Vec3>,
    tan: Vec<Vec3>,
    rtwist: Vec<f64>,
    q0: Vec<f64>,
    qtilde: Vec<f64>,
    a1_0: Vec<Vec3>,
    tan_0: Vec<Vec3>,
    rtwist_0: Vec<f64>,
    grad: Vec<f64>,
    fext: Vec<f64>,
    fext_prev: Vec<f64>,
    res: Vec<f64>,
    dz: Vec<f64>,
    band: BandMatrix,
    terms: VertexTerms,
    inertia: Option<Inertia>,
    lin: Vec<f64>,
    time: f64,
    rest: Vec<Vec3>,
    arclength: Vec<f64>,
    contacts: Vec<ContactObs>,
    lag: Vec<ContactLag>,
    friction: Vec<LaggedFriction>,
    friction_eps: f64,
    line_base: Vec<f64>,
    /// `phi(x_k) + margin` of every node at the last full evaluation (m).
    gap: Vec<f64>,
    /// Shortest rest length of the edges adjacent to each node (m).
    node_len: Vec<f64>,
    /// Clamp command at the end of the last step (start of the next one).
    prev_cmd: DeviceCommand,
    /// Snapshot buffers, one per substep depth (allocated on first use).
    snaps: Vec<Snapshot>,
    /// Substeps taken by the last [`DerRod::step`] (1 = no retry).
    substeps: usize,
    /// Deepest halving used by the last [`DerRod::step`].
    substep_depth: usize,
    flow: Option<Arc<dyn FlowField>>,
    /// A moving vessel: its environment (rest lumen, motion, rest flow);
    /// `vessel` and `flow` are re-frozen at the end time of every (sub)step.
    moving: Option<Environment>,
    /// Diameter of every edge's section (m), for the drag.
    edge_diam: Vec<f64>,
    /// Lagged drag state per node: flow velocity at the start of the step.
    drag_flow: Vec<Vec3>,
    /// Edge tangents at the start of the step (for the drag).
    drag_tan: Vec<Vec3>,
    /// `v = drag_a (x - x_0) + drag_b`: BE `a = 1/dt`, `b = 0`; Newmark
    /// `a = 2/dt`, `b = -v_0` (per DOF).
    drag_a: f64,
}

impl DerRod {
    /// Discretise `body` with `segments` edges over its free length (plus the
    /// ghost edge behind the clamp). Edge properties come from
    /// [`RodBody::section_at`] at the edge midpoint; a vertex uses the average
    /// of its two edges' stiffnesses and the rest curvature of the section at
    /// its arclength, as the exact turning `kappa_bar = 2 tan(k l / 2)` of a
    /// circular arc of curvature `k` (1/m) over the Voronoi length `l`. The
    /// initial configuration is the rest (natural) shape, at rest.
    pub fn from_body(body: &RodBody, segments: usize) -> Result<Self, BuildError> {
        body.validate().map_err(|e| BuildError::bad("rod", e))?;
        if !(2..=1_000_000).contains(&segments) {
            return Err(BuildError::bad(
                "segments",
                format!("need 2..=1e6 rod segments, got {segments}"),
            ));
        }
        let n = segments + 2;
        let ne = n - 1;
        let delta = body.length / segments as f64;
        let rest_len = vec![delta; ne];
        let mut ea = Vec::with_capacity(ne);
        let mut bend = Vec::with_capacity(ne);
        let mut gj = Vec::with_capacity(ne);
        let mut rot_inertia = Vec::with_capacity(ne);
        let mut node_mass = vec![0.0; n];
        for j in 0..ne {
            let sec = body.section_at((j as f64 - 0.5) * delta);
            ea.push(sec.youngs_modulus * sec.area());
            let ei = sec.youngs_modulus * sec.second_moment();
            bend.push([ei, ei]);
            gj.push(sec.shear_modulus() * sec.polar_moment());
            rot_inertia.push(sec.density * sec.polar_moment() * delta);
            if j >= 1 {
                let m = sec.density * sec.area() * delta;
                node_mass[j] += 0.5 * m;
                node_mass[j + 1] += 0.5 * m;
            }
        }
        let mut vparams = Vec::with_capacity(n);
        let mut bend_len = Vec::with_capacity(n);
        for i in 0..n {
            if i == 0 || i == n - 1 {
                bend_len.push(delta);
                vparams.push(VertexParams {
                    bend: [0.0; 2],
                    kappa_bar: [0.0; 2],
                    twist: 0.0,
                    twist_bar: 0.0,
                    voronoi: delta,
                });
                continue;
            }
            let l = 0.5 * (rest_len[i - 1] + rest_len[i]);
            // Bending length: the clamp vertex's Voronoi region is only its
            // half inside the free rod (the ghost edge is inside the clamp and
            // does not bend). With the full region the clamp acts at -Delta/2
            // and the cantilever converges at first order only (measured).
            let lb = if i == 1 { 0.5 * rest_len[1] } else { l };
            bend_len.push(lb);
            let k = body.section_at((i as f64 - 1.0) * delta).rest_curvature;
            let km = (k[0] * k[0] + k[1] * k[1]).sqrt();
            if km * lb >= 0.9 * std::f64::consts::PI {
                return Err(BuildError::bad(
                    "segments",
                    format!(
                        "rest curvature {km} 1/m turns {:.2} rad per segment: use more segments",
                        km * lb
                    ),
                ));
            }
            let kb = if km > 0.0 {
                2.0 * (0.5 * km * lb).tan() / km
            } else {
                0.0
            };
            // Energy B (kappa - kappa_bar)^2 / (2 lb), written with the twist's
            // Voronoi length l: stiffness scaled by l / lb.
            let sc = l / lb;
            vparams.push(VertexParams {
                bend: [
                    sc * 0.5 * (bend[i - 1][0] + bend[i][0]),
                    sc * 0.5 * (bend[i - 1][1] + bend[i][1]),
                ],
                // Scene convention: Darboux components (Omega.d1, Omega.d2);
                // Bergou's material curvature is (Omega.d2, -Omega.d1).
                kappa_bar: [k[1] * kb, -k[0] * kb],
                twist: 0.5 * (gj[i - 1] + gj[i]),
                twist_bar: 0.0,
                voronoi: l,
            });
        }
        // Rest shape: integrate the rest turning from the clamp frame.
        let r = body.base.rotation.to_rotation_matrix();
        let (mut t, mut d1, mut d2) = (r * Vec3::x(), r * Vec3::y(), r * Vec3::z());
        let p = body.base.translation.vector;
        let mut x = vec![p - t * delta, p];
        let mut a1 = vec![d1];
        let mut tan = vec![t];
        for i in 1..n - 1 {
            let kbar = vparams[i].kappa_bar;
            let kb = d2 * kbar[0] - d1 * kbar[1];
            let kn = kb.norm();
            if kn > 0.0 {
                let axis = kb / kn;
                let phi = 2.0 * (0.5 * kn).atan();
                t = rotate_about(&t, &axis, phi);
                d1 = rotate_about(&d1, &axis, phi);
                d2 = rotate_about(&d2, &axis, phi);
            }
            x.push(x[i] + t * rest_len[i]);
            a1.push(d1);
            tan.push(t);
        }
        let ndof = 4 * n - 1;
        let mut q = vec![0.0; ndof];
        for (k, xk) in x.iter().enumerate() {
            q[4 * k..4 * k + 3].copy_from_slice(xk.as_slice());
        }
        let mut rtwist = vec![0.0; n];
        for i in 1..n - 1 {
            rtwist[i] = energy::reference_twist(&a1[i - 1], &tan[i - 1], &a1[i], &tan[i], 0.0);
        }
        let arclength = (0..n).map(|k| (k as f64 - 1.0) * delta).collect();
        let nfree = ndof - CLAMPED_DOFS;
        let edge_diam: Vec<f64> = (0..ne)
            .map(|j| 2.0 * body.section_at((j as f64 - 0.5) * delta).radius)
            .collect();
        let node_len: Vec<f64> = (0..n)
            .map(|k| {
                let a = if k > 0 { rest_len[k - 1] } else { f64::INFINITY };
                let b = if k < ne { rest_len[k] } else { f64::INFINITY };
                a.min(b)
            })
            .collect();
        Ok(Self {
            params: DerParams::default(),
            gravity: Vec3::zeros(),
            tip_force: body.tip_force,
            tip_torque: body.tip_torque,
            tip_load_ramp: body.tip_load_ramp.clone(),
            load_scale: body.tip_load_scale(0.0),
            vessel: None,
            contact: ContactParams::default(),
            contact_stiffness: 10.0 * (0..ne).map(|j| ea[j] / rest_len[j]).fold(0.0, f64::max),
            contact_onset: 1e-5 * body.length,
            n,
            length: body.length,
            base: body.base,
            rest_len,
            ea,
            rot_inertia,
            vparams,
            edge_bend: bend,
            bend_len,
            node_mass,
            node_forces: vec![Vec3::zeros(); n],
            qdot: vec![0.0; ndof],
            qddot: vec![0.0; ndof],
            accel_valid: false,
            q0: q.clone(),
            qtilde: q.clone(),
            a1_0: a1.clone(),
            tan_0: tan.clone(),
            rtwist_0: rtwist.clone(),
            q,
            a1,
            tan,
            rtwist,
            grad: vec![0.0; ndof],
            fext: vec![0.0; ndof],
            fext_prev: vec![0.0; ndof],
            res: vec![0.0; nfree],
            dz: vec![0.0; nfree],
            band: BandMatrix::new(nfree, BAND),
            terms: VertexTerms::default(),
            inertia: None,
            lin: vec![0.0; ndof],
            time: 0.0,
            rest: x,
            arclength,
            contacts: Vec::new(),
            lag: vec![ContactLag::NONE; n],
            friction: vec![LaggedFriction::NONE; n],
            friction_eps: 0.0,
            line_base: vec![0.0; nfree],
            gap: vec![f64::NEG_INFINITY; n],
            node_len,
            prev_cmd: DeviceCommand::default(),
            snaps: Vec::new(),
            substeps: 0,
            substep_depth: 0,
            flow: None,
            moving: None,
            edge_diam,
            drag_flow: vec![Vec3::zeros(); n],
            drag_tan: vec![Vec3::x(); n],
            drag_a: 0.0,
        })
    }

    /// Make the rod collide with a vessel (SDF, negative in the lumen).
    pub fn set_vessel(&mut self, vessel: Option<Arc<dyn Sdf>>, contact: ContactParams) {
        self.vessel = vessel;
        self.contact = contact;
        self.lag.iter_mut().for_each(|l| *l = ContactLag::NONE);
        self.friction.iter_mut().for_each(|f| *f = LaggedFriction::NONE);
    }

    /// Put the rod in a blood-flow field (see the module docs, "Flow drag").
    pub fn set_flow(&mut self, flow: Option<Arc<dyn FlowField>>) {
        self.flow = flow;
    }

    /// Put the rod in the vessel and flow of `env`, following its prescribed
    /// motion if it has one: each (sub)step solves against the lumen and
    /// flow at its end time, and friction anchors ride on the wall
    /// ([`surgbench_core::motion::carried`]), so slip is measured against the
    /// moving wall.
    pub fn set_environment(&mut self, env: &Environment) {
        self.set_vessel(env.vessel_at(self.time), env.contact);
        self.set_flow(env.flow_at(self.time));
        self.moving = env.vessel_motion.as_ref().map(|_| env.clone());
    }

    /// Drag coefficients `(c_n, c_t)` (N s^2/m^2) of the half of free
    /// edge `j` next to a node: `rho C d l / 2` and `rho C_t pi d l / 2`
    /// with `l = |e_j| / 2`; zero for the ghost edge and out of range.
    fn half_edge_drag(&self, j: usize) -> [f64; 2] {
        if !(j >= 1 && j < self.n - 1) {
            return [0.0; 2];
        }
        let l = 0.5 * self.rest_len[j];
        let d = self.edge_diam[j];
        [
            0.5 * BLOOD_DENSITY * DRAG_NORMAL * d * l,
            0.5 * BLOOD_DENSITY * DRAG_TANGENTIAL * std::f64::consts::PI * d * l,
        ]
    }

    /// Drag force (N) on node `k` at velocity `v` in flow `w`, with the
    /// tangents `t` of its two half-edges (edges `k-1`, `k`):
    /// `sum c_n |u_n| u_n + c_t |u_t| u_t` with `u = w - v`, and its
    /// Jacobian over `u`, `dF/du` (symmetric positive semi-definite).
    fn node_drag(&self, k: usize, v: &Vec3, w: &Vec3, t: [Vec3; 2]) -> (Vec3, Mat3) {
        let u = w - v;
        let mut f = Vec3::zeros();
        let mut h = Mat3::zeros();
        for (i, j) in [k.wrapping_sub(1), k].into_iter().enumerate() {
            let [cn, ct] = self.half_edge_drag(j);
            if cn == 0.0 {
                continue;
            }
            let tj = t[i];
            let ut = tj * tj.dot(&u);
            let un = u - ut;
            let (nn, nt) = (un.norm(), ut.norm());
            f += un * (cn * nn) + ut * (ct * nt);
            if nn > 0.0 {
                h += ((Mat3::identity() - tj * tj.transpose()) * nn + un * un.transpose() / nn) * cn;
            }
            h += tj * tj.transpose() * (2.0 * ct * nt);
        }
        (f, h)
    }

    /// Tangents of the two half-edges of node `k` (edges `k-1` and `k`,
    /// clamped to the valid range) from `tan`.
    fn half_edge_tangents(tan: &[Vec3], k: usize) -> [Vec3; 2] {
        let last = tan.len() - 1;
        [tan[k.saturating_sub(1).min(last)], tan[k.min(last)]]
    }

    /// Freeze the flow velocity at every node and the edge tangents for the
    /// coming step's drag.
    fn begin_drag(&mut self, dt: f64, newmark: bool) {
        let Some(flow) = self.flow.clone() else {
            return;
        };
        self.drag_a = if newmark { 2.0 / dt } else { 1.0 / dt };
        for k in 0..self.n {
            self.drag_flow[k] = flow.velocity(&self.node(k));
        }
        self.drag_tan[..self.n - 1].copy_from_slice(&self.tan);
    }

    /// Add a dead force (N) on node `k` (kept until changed); ignored for the
    /// clamped nodes 0 and 1 except in the hand force. Out-of-range `k` is
    /// ignored and reported as `false`.
    pub fn set_node_force(&mut self, k: usize, f: Vec3) -> bool {
        match self.node_forces.get_mut(k) {
            Some(slot) => {
                *slot = f;
                true
            }
            None => false,
        }
    }

    /// Override one edge's bending stiffnesses `(B_1, B_2)` (N m^2), e.g.
    /// for an anisotropic cross-section; the two vertex stiffnesses that
    /// average this edge are updated. Out-of-range edges are ignored.
    pub fn set_edge_bending(&mut self, edge: usize, b: [f64; 2]) {
        if edge >= self.edge_bend.len() {
            return;
        }
        self.edge_bend[edge] = b;
        for i in [edge, edge + 1] {
            if i >= 1 && i < self.n - 1 {
                let (p, c) = (self.edge_bend[i - 1], self.edge_bend[i]);
                let sc = self.vparams[i].voronoi / self.bend_len[i];
                self.vparams[i].bend = [sc * 0.5 * (p[0] + c[0]), sc * 0.5 * (p[1] + c[1])];
            }
        }
    }

    /// Number of nodes (`segments + 2`, ghost included).
    pub fn num_nodes(&self) -> usize {
        self.n
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Scale of the dead tip loads at time `t` (s): the value of
    /// [`DerRod::tip_load_ramp`] there, 1 without a ramp.
    pub fn tip_load_scale(&self, t: f64) -> f64 {
        self.tip_load_ramp.as_ref().map_or(1.0, |r| r.scale_at(t))
    }

    /// Generalised coordinates `[x_0, theta_0, x_1, ...]` (m, rad).
    pub fn coords(&self) -> &[f64] {
        &self.q
    }

    /// Position of node `k` (m).
    pub fn node(&self, k: usize) -> Vec3 {
        Vec3::new(self.q[4 * k], self.q[4 * k + 1], self.q[4 * k + 2])
    }

    /// Velocity of node `k` (m/s).
    pub fn node_velocity(&self, k: usize) -> Vec3 {
        Vec3::new(self.qdot[4 * k], self.qdot[4 * k + 1], self.qdot[4 * k + 2])
    }

    /// Twist angle of edge `j` relative to its reference frame (rad).
    pub fn theta(&self, j: usize) -> f64 {
        self.q[4 * j + 3]
    }

    /// Lumped mass of node `k` (kg).
    pub fn node_mass(&self, k: usize) -> f64 {
        self.node_mass[k]
    }

    /// Material frame of edge `j`: columns `(m_1, m_2, t)`.
    pub fn material_frame(&self, j: usize) -> Mat3 {
        let (m1, m2) = energy::material_frame(&self.tan[j], &self.a1[j], self.theta(j));
        Mat3::from_columns(&[m1, m2, self.tan[j]])
    }

    /// Material curvature `(kappa_1, kappa_2)` at vertex `i` (1/m: the
    /// discrete `kb`-based curvature divided by the Voronoi length).
    pub fn curvature(&self, i: usize) -> [f64; 2] {
        let k = energy::curvature(&self.stencil(i));
        let l = self.bend_len[i];
        [k[0] / l, k[1] / l]
    }

    /// Largest relative edge stretch `|e|/|e_bar| - 1`, with its sign.
    pub fn max_stretch(&self) -> f64 {
        let mut best: f64 = 0.0;
        for j in 0..self.n - 1 {
            let s = (self.node(j + 1) - self.node(j)).norm() / self.rest_len[j] - 1.0;
            if s.abs() > best.abs() {
                best = s;
            }
        }
        best
    }

    /// Contacts found in the last step.
    pub fn contacts(&self) -> &[ContactObs] {
        &self.contacts
    }

    fn dof_mass(&self, g: usize) -> f64 {
        if g % 4 == 3 {
            match self.params.twist {
                TwistDynamics::QuasiStatic => 0.0,
                TwistDynamics::Dynamic => self.rot_inertia[g / 4],
            }
        } else {
            self.node_mass[g / 4]
        }
    }

    fn stencil(&self, i: usize) -> Stencil {
        Stencil {
            x: [self.node(i - 1), self.node(i), self.node(i + 1)],
            theta: [self.theta(i - 1), self.theta(i)],
            ref_d1: [self.a1[i - 1], self.a1[i]],
            ref_twist: self.rtwist[i],
        }
    }

    /// Place the clamp for a command: node 1 at the base point advanced by
    /// `insertion` along the base tangent, node 0 one edge behind it, the
    /// ghost edge's reference director along the base's local y and its twist
    /// angle equal to `rotation`.
    fn apply_clamp(&mut self, cmd: &DeviceCommand) {
        let pose = cmd.base_pose.unwrap_or(self.base);
        let r = pose.rotation.to_rotation_matrix();
        let t = r * Vec3::x();
        let p = pose.translation.vector + t * cmd.insertion;
        let x0 = p - t * self.rest_len[0];
        self.q[0..3].copy_from_slice(x0.as_slice());
        self.q[3] = cmd.rotation;
        self.q[4..7].copy_from_slice(p.as_slice());
        self.a1[0] = r * Vec3::y();
        self.tan[0] = t;
        self.a1_0[0] = self.a1[0];
        self.tan_0[0] = t;
    }

    /// Transport every reference director from the start-of-step frames to
    /// the current tangents and recompute the reference twists.
    fn update_frames(&mut self) {
        for j in 0..self.n - 1 {
            let t = (self.node(j + 1) - self.node(j)).normalize();
            self.a1[j] = energy::transport_director(&self.a1_0[j], &self.tan_0[j], &t);
            self.tan[j] = t;
        }
        for i in 1..self.n - 1 {
            self.rtwist[i] = energy::reference_twist(
                &self.a1[i - 1],
                &self.tan[i - 1],
                &self.a1[i],
                &self.tan[i],
                self.rtwist_0[i],
            );
        }
    }

    /// Begin a frame-transport interval at the current state.
    fn anchor_frames(&mut self) {
        self.a1_0.copy_from_slice(&self.a1);
        self.tan_0.copy_from_slice(&self.tan);
        self.rtwist_0.copy_from_slice(&self.rtwist);
    }

    /// Dead loads as generalised forces at the current configuration.
    fn external_forces(&mut self) {
        let n = self.n;
        self.fext.iter_mut().for_each(|f| *f = 0.0);
        for k in 0..n {
            let f = self.gravity * self.node_mass[k] + self.node_forces[k];
            for c in 0..3 {
                self.fext[4 * k + c] += f[c];
            }
        }
        let last = n - 1;
        let e = self.node(last) - self.node(last - 1);
        let t = self.tan[last - 1];
        let (tip_force, tip_torque) = (self.tip_force * self.load_scale, self.tip_torque * self.load_scale);
        let axial = tip_torque.dot(&t);
        let perp = tip_torque - t * axial;
        let couple = perp.cross(&e) / e.norm_squared();
        for c in 0..3 {
            self.fext[4 * last + c] += tip_force[c] + couple[c];
            self.fext[4 * (last - 1) + c] -= couple[c];
        }
        self.fext[4 * (last - 1) + 3] += axial;
    }

    /// Elastic energy (J) at the current coordinates and frames.
    pub fn elastic_energy(&self) -> f64 {
        let mut e = 0.0;
        for j in 0..self.n - 1 {
            e += energy::stretch_energy(&self.node(j), &self.node(j + 1), self.ea[j], self.rest_len[j]);
        }
        for i in 1..self.n - 1 {
            e += energy::bend_twist_energy(&self.stencil(i), &self.vparams[i]);
        }
        e
    }

    /// Gradient of the elastic energy over all DOFs at the current state
    /// (N for positions, N m for angles), without the Hessian.
    pub fn elastic_gradient(&self) -> Vec<f64> {
        let mut g = vec![0.0; self.q.len()];
        let mut terms = VertexTerms::default();
        for j in 0..self.n - 1 {
            let (_, gs, _) = energy::stretch(&self.node(j), &self.node(j + 1), self.ea[j], self.rest_len[j]);
            for c in 0..3 {
                g[4 * (j + 1) + c] += gs[c];
                g[4 * j + c] -= gs[c];
            }
        }
        for i in 1..self.n - 1 {
            energy::bend_twist(&self.stencil(i), &self.vparams[i], &mut terms);
            for (k, v) in terms.grad.iter().enumerate() {
                g[4 * (i - 1) + k] += v;
            }
        }
        g
    }

    /// Evaluate the incremental potential; with [`Eval::Full`] also its
    /// gradient over the free DOFs (`self.res`) and Hessian (`self.band`).
    fn eval(&mut self, mode: Eval) -> (f64, f64) {
        let full = mode == Eval::Full;
        let n = self.n;
        let mut phi = 0.0;
        let mut mag = 0.0;
        if full {
            self.grad.iter_mut().for_each(|g| *g = 0.0);
            self.band.clear();
        }
        for j in 0..n - 1 {
            let (x0, x1) = (self.node(j), self.node(j + 1));
            if !full {
                phi += energy::stretch_energy(&x0, &x1, self.ea[j], self.rest_len[j]);
                continue;
            }
            // Exact Hessian, including the negative transverse stiffness of a
            // compressed edge; `newton` drops that part only if the matrix is
            // then not positive definite (see `drop_compressive_stiffness`).
            let (e, g, h) = energy::stretch(&x0, &x1, self.ea[j], self.rest_len[j]);
            phi += e;
            for c in 0..3 {
                self.grad[4 * (j + 1) + c] += g[c];
                self.grad[4 * j + c] -= g[c];
            }
            let (a, b) = (4 * j, 4 * (j + 1));
            for r in 0..3 {
                for c in 0..3 {
                    let v = h[(r, c)];
                    self.band_add(b + r, b + c, v);
                    self.band_add(a + r, a + c, v);
                    self.band_add(b + r, a + c, -v);
                }
            }
        }
        for i in 1..n - 1 {
            let st = self.stencil(i);
            if !full {
                phi += energy::bend_twist_energy(&st, &self.vparams[i]);
                continue;
            }
            let mut terms = std::mem::take(&mut self.terms);
            energy::bend_twist(&st, &self.vparams[i], &mut terms);
            phi += terms.energy;
            let off = 4 * (i - 1);
            for r in 0..energy::VERTEX_DOFS {
                self.grad[off + r] += terms.grad[r];
                for c in 0..=r {
                    self.band_add(off + r, off + c, 0.5 * (terms.jac[r][c] + terms.jac[c][r]));
                }
            }
            self.terms = terms;
        }
        if let Some(sdf) = self.vessel.clone() {
            let kc = self.contact_stiffness;
            // Friction only in dynamic steps (it dissipates the step's slip).
            let friction = self.inertia.is_some();
            let eps = self.friction_eps;
            for k in 2..n {
                let x = self.node(k);
                let d = sdf.distance(&x) + self.contact.margin;
                if full {
                    self.gap[k] = d;
                }
                if d > 0.0 {
                    let (e, de, dde) = penalty(kc, self.contact_onset, d);
                    phi += e;
                    if full {
                        let g = sdf.gradient(&x);
                        let gn = g.norm();
                        let nn = if gn > 0.0 { g / gn } else { g };
                        let h = nn * nn.transpose() * dde + Self::wall_curvature(sdf.as_ref(), &x, &g) * de;
                        for r in 0..3 {
                            self.grad[4 * k + r] += de * nn[r];
                            for c in 0..=r {
                                self.band_add(4 * k + r, 4 * k + c, h[(r, c)]);
                            }
                        }
                    }
                }
                let fr = self.friction[k];
                if friction && fr.bound > 0.0 {
                    if !full {
                        phi += fr.energy(&x, eps);
                        continue;
                    }
                    let fe = fr.eval(&x, eps);
                    phi += fe.energy;
                    for r in 0..3 {
                        self.grad[4 * k + r] += fe.gradient[r];
                        for c in 0..=r {
                            self.band_add(4 * k + r, 4 * k + c, fe.hessian[(r, c)]);
                        }
                    }
                }
            }
        }
        if self.flow.is_some() && self.inertia.is_some() {
            // Lagged quadratic drag as a convex potential of the step (see
            // the module docs): value `sum (c |u|^3 / 3) / a`, gradient
            // `-f`, Hessian `a dF/du`.
            let a = self.drag_a;
            let newmark = self.params.integrator == Integrator::Newmark;
            for k in 2..n {
                let x = self.node(k);
                let x0 = Vec3::new(self.q0[4 * k], self.q0[4 * k + 1], self.q0[4 * k + 2]);
                let mut v = (x - x0) * a;
                if newmark {
                    v -= self.node_velocity(k);
                }
                let w = self.drag_flow[k];
                let t = Self::half_edge_tangents(&self.drag_tan[..n - 1], k);
                let u = w - v;
                for (i, j) in [k - 1, k].into_iter().enumerate() {
                    let [cn, ct] = self.half_edge_drag(j);
                    let ut = t[i] * t[i].dot(&u);
                    let un = u - ut;
                    phi += (cn * un.norm().powi(3) + ct * ut.norm().powi(3)) / (3.0 * a);
                }
                if full {
                    let (f, h) = self.node_drag(k, &v, &w, t);
                    for r in 0..3 {
                        self.grad[4 * k + r] -= f[r];
                        for c in 0..=r {
                            self.band_add(4 * k + r, 4 * k + c, a * h[(r, c)]);
                        }
                    }
                }
            }
        }
        let elastic = phi;
        let inertia = self.inertia;
        // Linear terms are measured from the start of the step (q - q0): the
        // potential differs by a constant, but its value and rounding no
        // longer depend on where the scene sits in space.
        for g in 0..self.q.len() {
            let q = self.q[g];
            let dq = q - self.q0[g];
            phi -= self.fext[g] * dq;
            mag += (self.fext[g] * dq).abs();
            let mut r = self.grad[g] - self.fext[g];
            if let Some(Inertia { ka, kc }) = inertia {
                let m = self.dof_mass(g);
                if m > 0.0 && g >= CLAMPED_DOFS {
                    let da = q - self.qtilde[g];
                    let inert = m * (0.5 * ka * da * da + 0.5 * kc * dq * dq - self.lin[g] * dq);
                    phi += inert;
                    mag += inert.abs();
                    r += m * (ka * da + kc * dq - self.lin[g]);
                    if full {
                        self.band_add(g, g, m * (ka + kc));
                    }
                }
            }
            if full && g >= CLAMPED_DOFS {
                self.res[g - CLAMPED_DOFS] = r;
            }
        }
        (phi, mag + elastic)
    }

    /// A compressed edge has a negative transverse stiffness
    /// `EA strain / |e|` that can swamp bending and inertia (e.g. right after
    /// the clamp is pushed forward, or a wire wedged in a dead end). When the
    /// exact Newton matrix is not positive definite, remove those terms
    /// (projected Newton: the matrix becomes positive definite; the gradient
    /// is exact, so the converged state is unchanged, only the convergence
    /// rate drops to linear). With every edge in tension nothing changes.
    fn drop_compressive_stiffness(&mut self) {
        for j in 0..self.n - 1 {
            let (x0, x1) = (self.node(j), self.node(j + 1));
            let l = (x1 - x0).norm();
            let strain = l / self.rest_len[j] - 1.0;
            if !(strain < 0.0) {
                continue;
            }
            let t = (x1 - x0) / l;
            let h = (Mat3::identity() - t * t.transpose()) * (-self.ea[j] * strain / l);
            let (a, b) = (4 * j, 4 * (j + 1));
            for r in 0..3 {
                for c in 0..3 {
                    // `band_add` keeps the lower triangle only.
                    let v = h[(r, c)];
                    self.band_add(b + r, b + c, v);
                    self.band_add(a + r, a + c, v);
                    self.band_add(b + r, a + c, -v);
                }
            }
        }
    }

    #[inline]
    fn band_add(&mut self, r: usize, c: usize, v: f64) {
        if c >= CLAMPED_DOFS && r >= c {
            self.band.add(r - CLAMPED_DOFS, c - CLAMPED_DOFS, v);
        }
    }

    /// Curvature part of the penalty Hessian at a node at `x` with SDF
    /// gradient `g`: the Jacobian of the unit wall normal
    /// `n = g / |g|`, `dn/dx = (I - n n^T) Hess phi / |g|` (`Hess phi` itself
    /// for an exact SDF, 1/m), from [`Sdf::hessian`] (analytic for the
    /// tubes and vessels of `surgbench_core::sdf`, central differences
    /// otherwise), symmetrised, with its negative eigenvalues clamped to zero.
    ///
    /// Why: the gradient of the penalty `P(d(x))` is `P'(d) n`; its exact
    /// Jacobian is `P'' n n^T + P' dn/dx`. Without the second term (Gauss-Newton)
    /// a node pressed onto the concave inside of a tube has too soft a matrix
    /// across the tube (by `P'/rho`, rho the node's distance from the tube
    /// axis: 1 N / 0.26 mm = 4e3 N/m in `capstan`), and Newton overshoots that
    /// mode by a factor `1 - (P'/rho + h)/h`: with `|.| > 1` it grows instead
    /// of converging. It starts from rounding only when the scene is not
    /// aligned with the axes (identically zero out of plane otherwise), so
    /// the step converged in 3 iterations in one frame and stalled at the
    /// iteration limit in a rotated one. The clamp keeps only the stiffening
    /// (concave wall) part: the matrix is never softer than Gauss-Newton
    /// (convex obstacles keep the linear but safe Gauss-Newton convergence).
    fn wall_curvature(sdf: &dyn Sdf, x: &Vec3, g: &Vec3) -> Mat3 {
        let gn = g.norm();
        if !(gn > 0.0 && gn.is_finite()) {
            return Mat3::zeros();
        }
        let n = g / gn;
        let j = (Mat3::identity() - n * n.transpose()) * sdf.hessian(x) / gn;
        let sym = (j + j.transpose()) * 0.5;
        if !sym.iter().all(|v| v.is_finite()) {
            return Mat3::zeros();
        }
        let eig = sym.symmetric_eigen();
        let mut out = Mat3::zeros();
        for i in 0..3 {
            let l = eig.eigenvalues[i];
            if l > 0.0 {
                let v = eig.eigenvectors.column(i);
                out += v * v.transpose() * l;
            }
        }
        out
    }

    /// Largest move of node `k` in one Newton iterate in a contact scene
    /// (m): a fraction of its distance to the margin surface (`-gap`, from
    /// the last full evaluation; the SDF is 1-Lipschitz, so the node cannot
    /// cross the surface), at least a small fraction of its edge so a node
    /// on the wall can slide, at most half of the edge so no edge flips
    /// (a continuous-collision-style step bound, cf. the CCD line-search
    /// filter of Li et al. 2020, "Incremental Potential Contact", sec. 4).
    fn move_allowance(&self, k: usize) -> f64 {
        let l = self.node_len[k];
        let free = (-self.gap[k]).max(0.0) * CCD_FRACTION;
        free.max(SLIDE_FRACTION * l).min(TRUST_FRACTION * l)
    }

    /// The largest `alpha <= 1` such that `alpha dz` moves every node at
    /// most [`Self::move_allowance`] and takes no sliding node past the
    /// apex of its friction cone.
    ///
    /// Friction apex: a node sliding (slip `y >= eps`) sees a friction force
    /// of constant size along its slip, so the Newton model has no friction
    /// curvature there. If the solution sticks, the Newton step reverses the
    /// slip and carries the node through the apex `u = 0` far to the other
    /// side (measured on `capstan`: from `y` = 1e-8 m to 1e-4 m), where the
    /// same happens back: Newton cycles, and the line search cannot resolve
    /// the `eps`-wide kink (1e-9 m) above its smallest step. The step
    /// therefore stops where the node's slip `u + alpha T dz` is shortest
    /// (its closest approach to the apex); the next iterate sees the
    /// stick-regime curvature `2 mu lambda / eps` and converges.
    fn step_cap(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        let friction = self.inertia.is_some();
        for k in 2..self.n {
            let f = 4 * k - CLAMPED_DOFS;
            let d = Vec3::new(self.dz[f], self.dz[f + 1], self.dz[f + 2]);
            let dx = d.norm();
            if dx > 0.0 {
                alpha = alpha.min(self.move_allowance(k) / dx);
            }
            let fr = self.friction[k];
            if friction && fr.bound > 0.0 {
                let u = fr.slip_vector(&self.node(k));
                let w = d - fr.normal * fr.normal.dot(&d);
                let (uw, ww) = (u.dot(&w), w.norm_squared());
                if u.norm() >= self.friction_eps && uw < 0.0 && ww > 0.0 {
                    alpha = alpha.min(-uw / ww);
                }
            }
        }
        alpha
    }

    fn set_free(&mut self, base: &[f64], alpha: f64) {
        for f in 0..self.dz.len() {
            self.q[f + CLAMPED_DOFS] = base[f] + alpha * self.dz[f];
        }
        self.update_frames();
    }

    /// Newton on the incremental potential from the current coordinates.
    /// Frames are re-anchored at every accepted iterate, so the gradient and
    /// the (symmetric) Hessian are exact for the merit function of the next
    /// line search.
    fn newton(&mut self) -> Result<StepStats, SimError> {
        self.anchor_frames();
        // Dead loads are frozen during a line search (the tip torque's
        // couple depends on the configuration) and refreshed at each iterate.
        self.external_forces();
        let (mut phi, mut mag) = self.eval(Eval::Full);
        let mut base = std::mem::take(&mut self.line_base);
        let stats = self.newton_iterations(&mut base, &mut phi, &mut mag);
        self.line_base = base;
        stats
    }

    /// The Newton loop of [`Self::newton`] (`base` holds the free DOFs at the
    /// start of each line search).
    fn newton_iterations(&mut self, base: &mut [f64], phi: &mut f64, mag: &mut f64) -> Result<StepStats, SimError> {
        let tol = self.params.tolerance;
        let mut stats = StepStats::default();
        for it in 1..=self.params.max_iterations.max(1) {
            stats.iterations = it as u32;
            for f in 0..self.dz.len() {
                self.dz[f] = -self.res[f];
            }
            let mut dz = std::mem::take(&mut self.dz);
            let solved = if self.band.factor(0.0).is_ok() {
                self.band.solve(&mut dz);
                Ok(0.0)
            } else {
                self.drop_compressive_stiffness();
                self.band.factor_and_solve(&mut dz, 0.0)
            };
            self.dz = dz;
            if solved.is_err() {
                let finite = self.res.iter().all(|r| r.is_finite());
                return Err(SimError::SolverFailed {
                    t: self.time,
                    reason: format!(
                        "Newton matrix not positive definite even with a shift (iteration {it}, residual finite: {finite}, stretch {:.2e})",
                        self.max_stretch()
                    ),
                });
            }
            // Largest node displacement (Euclidean, so the test does not
            // depend on the orientation of the scene) and twist update.
            let mut size: f64 = 0.0;
            for k in 2..self.n {
                let f = 4 * k - CLAMPED_DOFS;
                let dx = (self.dz[f].powi(2) + self.dz[f + 1].powi(2) + self.dz[f + 2].powi(2)).sqrt();
                size = size.max(dx / self.length);
                if f + 3 < self.dz.len() {
                    size = size.max(self.dz[f + 3].abs());
                }
            }
            if !size.is_finite() {
                return Err(SimError::Diverged {
                    t: self.time,
                    reason: format!("non-finite Newton update at iteration {it}"),
                });
            }
            let slope: f64 = self.res.iter().zip(&self.dz).map(|(r, d)| r * d).sum();
            base.copy_from_slice(&self.q[CLAMPED_DOFS..]);
            stats.residual = size;
            if size <= tol {
                self.set_free(base, 1.0);
                stats.converged = true;
                return Ok(stats);
            }
            // Backtracking line search (Armijo) on the incremental potential,
            // skipped when the predicted decrease is at the rounding level of
            // the potential (there the full Newton step is the right one).
            let noise = 1e-13 * *mag;
            let search = slope < -1e3 * noise;
            // Step control in contact scenes: the largest fraction of the
            // Newton step that moves no node too far (see `step_cap`).
            let mut alpha = if self.vessel.is_some() { self.step_cap() } else { 1.0 };
            let alpha_min = 1e-3 * alpha;
            self.set_free(base, alpha);
            let (mut phi_new, mut mag_new) = self.eval(Eval::Full);
            let mut backtracked = false;
            let armijo = |alpha: f64, phi_new: f64| phi_new <= *phi + 1e-4 * alpha * slope + noise;
            while search && !armijo(alpha, phi_new) && alpha > alpha_min {
                alpha *= 0.5;
                self.set_free(base, alpha);
                (phi_new, mag_new) = self.eval(Eval::Energy);
                backtracked = true;
            }
            if search && !armijo(alpha, phi_new) {
                // No decrease along the Newton direction (a non-smooth
                // corner of the SDF, or a direction the projected matrix
                // gets wrong): stop at the last accepted iterate and let
                // `step` retry with a smaller time step.
                self.set_free(base, 0.0);
                self.eval(Eval::Full);
                stats.residual = size;
                return Ok(stats);
            }
            if backtracked {
                (phi_new, mag_new) = self.eval(Eval::Full);
            }
            stats.residual = size * alpha;
            if !phi_new.is_finite() {
                return Err(SimError::Diverged {
                    t: self.time,
                    reason: format!("non-finite energy in Newton iteration {it}"),
                });
            }
            // Re-anchor the frame transport at the accepted iterate and
            // refresh the dead loads there.
            self.anchor_frames();
            *phi = phi_new;
            *mag = mag_new;
            std::mem::swap(&mut self.fext, &mut self.fext_prev);
            self.external_forces();
            for g in 0..self.q.len() {
                let d = self.fext[g] - self.fext_prev[g];
                if d != 0.0 {
                    *phi -= d * (self.q[g] - self.q0[g]);
                    if g >= CLAMPED_DOFS {
                        self.res[g - CLAMPED_DOFS] -= d;
                    }
                }
            }
        }
        Ok(stats)
    }

    /// Advance by `dt` (s) with the clamp at `cmd` at the end of the step.
    ///
    /// Adaptive substepping: if the Newton solve of the step does not
    /// converge within [`DerParams::max_iterations`] (or fails, or leaves a
    /// non-finite or collapsed state), the state is restored and the step is
    /// retried as two steps of `dt/2` with the clamp command interpolated
    /// linearly between the previous command and `cmd`, recursively down to
    /// `dt / 2^max_substep_depth`. At the deepest level an unconverged
    /// substep is accepted (reported as `converged = false`) if its state is
    /// sane; a failed one ends the run with its error. The returned
    /// [`StepStats`] sums the Newton iterations over all substeps, with the
    /// largest final update and `converged` only if every substep converged;
    /// [`DerRod::last_substeps`] tells how many substeps were taken.
    pub fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!("time step must be > 0 s, got {dt}"),
            });
        }
        let c0 = self.prev_cmd;
        let mut acc = StepStats {
            iterations: 0,
            residual: 0.0,
            converged: true,
        };
        self.substeps = 0;
        self.substep_depth = 0;
        self.advance(dt, &c0, cmd, 0, &mut acc)?;
        self.prev_cmd = *cmd;
        Ok(acc)
    }

    /// Substeps taken by the last [`DerRod::step`] (1 when the step
    /// converged at once) and the deepest halving used (0 = none).
    pub fn last_substeps(&self) -> (usize, usize) {
        (self.substeps, self.substep_depth)
    }

    /// One step of `dt` from the clamp at `c0` to `c1`, retried as two
    /// half steps on failure (see [`DerRod::step`]).
    fn advance(
        &mut self,
        dt: f64,
        c0: &DeviceCommand,
        c1: &DeviceCommand,
        depth: usize,
        acc: &mut StepStats,
    ) -> Result<(), SimError> {
        if self.snaps.len() <= depth {
            self.snaps.resize_with(depth + 1, Snapshot::default);
        }
        let mut snap = std::mem::take(&mut self.snaps[depth]);
        self.save(&mut snap);
        let res = self.single_step(dt, c1);
        let retry = depth < self.params.max_substep_depth && !matches!(res, Ok(st) if st.converged);
        if retry {
            self.restore(&snap);
        }
        self.snaps[depth] = snap;
        if retry {
            let cm = interpolate_command(c0, c1, 0.5, &self.base);
            self.advance(0.5 * dt, c0, &cm, depth + 1, acc)?;
            return self.advance(0.5 * dt, &cm, c1, depth + 1, acc);
        }
        let st = res?;
        acc.iterations += st.iterations;
        acc.residual = acc.residual.max(st.residual);
        acc.converged &= st.converged;
        self.substeps += 1;
        self.substep_depth = self.substep_depth.max(depth);
        Ok(())
    }

    /// Save the state a step changes.
    fn save(&self, s: &mut Snapshot) {
        fn copy<T: Copy>(dst: &mut Vec<T>, src: &[T]) {
            dst.clear();
            dst.extend_from_slice(src);
        }
        copy(&mut s.q, &self.q);
        copy(&mut s.qdot, &self.qdot);
        copy(&mut s.qddot, &self.qddot);
        copy(&mut s.a1, &self.a1);
        copy(&mut s.tan, &self.tan);
        copy(&mut s.rtwist, &self.rtwist);
        copy(&mut s.lag, &self.lag);
        s.accel_valid = self.accel_valid;
        s.time = self.time;
    }

    /// Restore a state saved by [`Self::save`].
    fn restore(&mut self, s: &Snapshot) {
        self.q.copy_from_slice(&s.q);
        self.qdot.copy_from_slice(&s.qdot);
        self.qddot.copy_from_slice(&s.qddot);
        self.a1.copy_from_slice(&s.a1);
        self.tan.copy_from_slice(&s.tan);
        self.rtwist.copy_from_slice(&s.rtwist);
        self.lag.copy_from_slice(&s.lag);
        self.accel_valid = s.accel_valid;
        self.time = s.time;
    }

    /// One implicit step without retries.
    fn single_step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        let newmark = self.params.integrator == Integrator::Newmark;
        let c = self.params.damping;
        self.anchor_frames();
        if newmark && !self.accel_valid {
            self.init_acceleration();
        }
        // Backward Euler and Newmark both impose equilibrium at the end of
        // the step: the dead tip loads act with their value at t + dt.
        self.load_scale = self.tip_load_scale(self.time + dt);
        if let Some(env) = &self.moving {
            self.vessel = env.vessel_at(self.time + dt);
            self.flow = env.flow_at(self.time + dt);
        }
        self.q0.copy_from_slice(&self.q);
        let ndof = self.q.len();
        for g in 0..ndof {
            let (q, v, a) = (self.q[g], self.qdot[g], self.qddot[g]);
            if newmark {
                self.qtilde[g] = q + dt * v + 0.25 * dt * dt * a;
                self.lin[g] = c * v;
            } else {
                self.qtilde[g] = q + dt * v;
                self.lin[g] = 0.0;
            }
        }
        self.inertia = Some(if newmark {
            Inertia {
                ka: 4.0 / (dt * dt),
                kc: 2.0 * c / dt,
            }
        } else {
            Inertia {
                ka: 1.0 / (dt * dt),
                kc: c / dt,
            }
        });
        self.begin_friction(dt);
        self.begin_drag(dt, newmark);
        // Warm start from the constant-velocity prediction `q0 + dt v`: a
        // node sliding steadily along the wall starts past the stick band of
        // its friction, so Newton does not first treat it as stuck.
        // In contact scenes the prediction is scaled down so that no node
        // moves farther than the step control of `newton` allows (a fast
        // node would otherwise start deep in, or through, the wall).
        let beta = if self.vessel.is_some() {
            let mut beta: f64 = 1.0;
            for k in 2..self.n {
                let v = self.node_velocity(k).norm() * dt;
                if v > 0.0 {
                    beta = beta.min(self.move_allowance(k) / v);
                }
            }
            beta
        } else {
            1.0
        };
        for g in CLAMPED_DOFS..ndof {
            self.q[g] += beta * dt * self.qdot[g];
        }
        self.apply_clamp(cmd);
        self.update_frames();
        let stats = self.newton()?;
        // Velocities (and accelerations) from the solved positions.
        for g in 0..ndof {
            let m = if g < CLAMPED_DOFS { 0.0 } else { self.dof_mass(g) };
            if newmark && m > 0.0 {
                let a = 4.0 / (dt * dt) * (self.q[g] - self.q0[g] - dt * self.qdot[g]) - self.qddot[g];
                self.qdot[g] += 0.5 * dt * (self.qddot[g] + a);
                self.qddot[g] = a;
            } else {
                self.qdot[g] = (self.q[g] - self.q0[g]) / dt;
                self.qddot[g] = 0.0;
            }
        }
        self.accel_valid = newmark;
        self.time += dt;
        self.finish_contacts();
        self.check_finite()?;
        Ok(stats)
    }

    /// Static equilibrium with the clamp at `cmd` (no inertia, no friction;
    /// the normal contact penalty acts if a vessel is set; the tip loads
    /// scaled by their ramp at the current time [`DerRod::time`]):
    /// Newton on `E - F . q` from the current state (at least 100 iterations,
    /// large loads need many damped steps), velocities set to zero.
    pub fn solve_static(&mut self, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.anchor_frames();
        self.inertia = None;
        self.load_scale = self.tip_load_scale(self.time);
        self.q0.copy_from_slice(&self.q);
        self.apply_clamp(cmd);
        self.update_frames();
        let keep = self.params.max_iterations;
        self.params.max_iterations = keep.max(100);
        let stats = self.newton();
        self.params.max_iterations = keep;
        let stats = stats?;
        self.prev_cmd = *cmd;
        self.qdot.iter_mut().for_each(|v| *v = 0.0);
        self.accel_valid = false;
        self.check_finite()?;
        Ok(stats)
    }

    /// Newmark needs the acceleration at the start: `a = (F - grad E - c m v)/m`.
    fn init_acceleration(&mut self) {
        let g = self.elastic_gradient();
        self.load_scale = self.tip_load_scale(self.time);
        self.external_forces();
        for k in 0..self.q.len() {
            let m = if k < CLAMPED_DOFS { 0.0 } else { self.dof_mass(k) };
            self.qddot[k] = if m > 0.0 {
                (self.fext[k] - g[k]) / m - self.params.damping * self.qdot[k]
            } else {
                0.0
            };
        }
        self.accel_valid = true;
    }

    /// Freeze the friction of the coming step: the lagged normal force and
    /// normal of every node in contact at the end of the last step, `mu_s`
    /// for a node that stuck and `mu_d` for one that slid, anchored at the
    /// node's start-of-step position.
    fn begin_friction(&mut self, dt: f64) {
        if self.vessel.is_none() {
            return;
        }
        let motion = self.moving.as_ref().and_then(|e| e.vessel_motion.clone());
        self.friction_eps = self.params.friction_creep * dt;
        let (mu_s, mu_d) = (self.contact.friction_static, self.contact.friction_dynamic);
        for k in 2..self.n {
            let lag = self.lag[k];
            let mu = if lag.sliding { mu_d } else { mu_s };
            self.friction[k] = if lag.force > 0.0 && mu > 0.0 {
                LaggedFriction {
                    normal: lag.normal,
                    anchor: match &motion {
                        Some(m) => carried(m.as_ref(), &self.node(k), self.time, self.time + dt),
                        None => self.node(k),
                    },
                    bound: mu * lag.force,
                }
            } else {
                LaggedFriction::NONE
            };
        }
    }

    /// After the solve: the contact forces of the converged step (penalty
    /// plus friction, both part of the solve) and the lagged state for the
    /// next step's friction. Nothing is moved.
    fn finish_contacts(&mut self) {
        self.contacts.clear();
        let Some(sdf) = self.vessel.clone() else {
            return;
        };
        for k in 2..self.n {
            let x = self.node(k);
            let fr = self.friction[k];
            let mut force = Vec3::zeros();
            let mut sliding = false;
            if fr.bound > 0.0 {
                let fe = fr.eval(&x, self.friction_eps);
                force -= fe.gradient;
                sliding = fe.slip >= self.friction_eps;
            }
            let phi = sdf.distance(&x);
            let d = phi + self.contact.margin;
            let mut lag = ContactLag::NONE;
            if d > 0.0 {
                let g = sdf.gradient(&x);
                let gn = g.norm();
                if gn > 0.0 && gn.is_finite() {
                    let normal = g / gn;
                    let lambda = penalty(self.contact_stiffness, self.contact_onset, d).1;
                    force -= normal * lambda;
                    lag = ContactLag {
                        force: lambda,
                        normal,
                        sliding,
                    };
                }
            }
            self.lag[k] = lag;
            if d > 0.0 || fr.bound > 0.0 {
                self.contacts.push(ContactObs {
                    point: x,
                    force,
                    penetration: phi.max(0.0),
                });
            }
        }
    }

    fn check_finite(&self) -> Result<(), SimError> {
        // An edge at half or double its rest length is a failed simulation
        // (the wire is near-inextensible), not a state to continue from.
        if !self.q.iter().chain(&self.qdot).all(|v| v.is_finite()) {
            return Err(SimError::Diverged {
                t: self.time,
                reason: "non-finite rod state".into(),
            });
        }
        let s = self.max_stretch();
        if s.abs() > 0.5 {
            return Err(SimError::Diverged {
                t: self.time,
                reason: format!("edge stretched by {:.0}%", 100.0 * s),
            });
        }
        Ok(())
    }

    /// Force and torque (N, N m; torque about the clamp point, world frame)
    /// the rod exerts on the clamp: the internal forces on the clamped DOFs
    /// plus the dead loads applied on the clamped nodes (inertia of the
    /// clamped nodes is not included). At static equilibrium they equal the
    /// total external load and its moment about the clamp (tested).
    pub fn hand_wrench(&self) -> (Vec3, Vec3) {
        let g = self.elastic_gradient();
        let p = self.node(1);
        let mut f = Vec3::zeros();
        let mut tq = Vec3::zeros();
        for k in 0..2 {
            let fk = Vec3::new(-g[4 * k], -g[4 * k + 1], -g[4 * k + 2])
                + self.gravity * self.node_mass[k]
                + self.node_forces[k];
            f += fk;
            tq += (self.node(k) - p).cross(&fk);
        }
        tq += self.tan[0] * (-g[3]);
        if let Some(flow) = &self.flow {
            // Drag on the clamped node's half of the first free edge.
            let x1 = self.node(1);
            let t = Self::half_edge_tangents(&self.tan, 1);
            f += self.node_drag(1, &self.node_velocity(1), &flow.velocity(&x1), t).0;
        }
        (f, tq)
    }

    /// Kinetic, elastic and external energies (J) at the current state and
    /// time `t`:
    ///
    /// * `elastic`: the rod's strain energy ([`DerRod::elastic_energy`]) plus
    ///   the energy stored in the contact penalty ([`DerRod::contact_energy`]:
    ///   the wall acts as a stiff spring, so its energy is strain energy of
    ///   the wall, returned when the node leaves it);
    /// * `external`: the potential of gravity and the dead loads,
    ///   `-sum (m_k g + f_k) . x_k - s(t) F . x_tip`, with absolute positions
    ///   (world origin) and `s(t)` the tip-load ramp
    ///   ([`DerRod::tip_load_scale`]). The dead tip torque has no potential
    ///   here (it is not conservative in this discretisation).
    ///
    /// Friction and drag are dissipative and have no stored energy.
    pub fn energies(&self) -> EnergyObs {
        let mut kin = 0.0;
        for g in CLAMPED_DOFS..self.q.len() {
            kin += 0.5 * self.dof_mass(g) * self.qdot[g] * self.qdot[g];
        }
        let mut ext = 0.0;
        for k in 0..self.n {
            ext -= (self.gravity * self.node_mass[k] + self.node_forces[k]).dot(&self.node(k));
        }
        ext -= self.tip_load_scale(self.time) * self.tip_force.dot(&self.node(self.n - 1));
        EnergyObs {
            kinetic: kin,
            elastic: self.elastic_energy() + self.contact_energy(),
            external: ext,
        }
    }

    /// Energy stored in the contact penalty (J): `sum_k P(phi(x_k) + margin)`
    /// over the free nodes, with `P` the C2 penalty of the module docs
    /// (`k d^2 / 2` past the cubic onset); 0 without a vessel. Its gradient
    /// is minus the normal contact force of [`DerRod::contacts`] (exactly for
    /// a unit-gradient SDF; the solve uses the normalised SDF gradient as
    /// the normal).
    pub fn contact_energy(&self) -> f64 {
        let Some(sdf) = &self.vessel else {
            return 0.0;
        };
        (2..self.n)
            .map(|k| {
                let d = sdf.distance(&self.node(k)) + self.contact.margin;
                if d > 0.0 {
                    penalty(self.contact_stiffness, self.contact_onset, d).0
                } else {
                    0.0
                }
            })
            .sum()
    }

    /// The rod's state in the harness's format.
    pub fn rod_obs(&self) -> RodObs {
        RodObs {
            arclength: self.arclength.clone(),
            rest: self.rest.clone(),
            nodes: (0..self.n).map(|k| self.node(k)).collect(),
            velocities: (0..self.n).map(|k| self.node_velocity(k)).collect(),
            frames: (0..self.n - 1).map(|j| self.material_frame(j)).collect(),
            max_stretch: self.max_stretch(),
        }
    }
}

/// Energy access for the conformance suite. Coordinates are
/// [`DerRod::coords`]; `set_coords` transports the reference frames from the
/// current ones (as Newton does). The potential is `elastic + external` of
/// [`DerRod::energies`]: strain energy, contact penalty energy, gravity and
/// dead-force potential (tip force scaled by the ramp at the current time);
/// the forces are its exact negative gradient (the penalty force
/// `-P'(d) grad phi`). The dead tip torque is not conservative in this
/// discretisation and is left out of both the potential and the forces.
impl EnergyProbe for DerRod {
    fn coords(&self) -> Vec<f64> {
        self.q.clone()
    }
    fn set_coords(&mut self, q: &[f64]) {
        self.anchor_frames();
        let n = q.len().min(self.q.len());
        self.q[..n].copy_from_slice(&q[..n]);
        self.update_frames();
    }
    fn potential(&self) -> f64 {
        let e = self.energies();
        e.elastic + e.external
    }
    fn forces(&self) -> Vec<f64> {
        let mut f = self.elastic_gradient();
        f.iter_mut().for_each(|v| *v = -*v);
        for k in 0..self.n {
            let l = self.gravity * self.node_mass[k] + self.node_forces[k];
            for c in 0..3 {
                f[4 * k + c] += l[c];
            }
        }
        let s = self.tip_load_scale(self.time);
        for c in 0..3 {
            f[4 * (self.n - 1) + c] += s * self.tip_force[c];
        }
        if let Some(sdf) = &self.vessel {
            for k in 2..self.n {
                let x = self.node(k);
                let (phi, g) = sdf.distance_gradient(&x);
                let d = phi + self.contact.margin;
                if d > 0.0 {
                    let de = penalty(self.contact_stiffness, self.contact_onset, d).1;
                    for c in 0..3 {
                        f[4 * k + c] -= de * g[c];
                    }
                }
            }
        }
        f
    }
    fn free(&self) -> Vec<usize> {
        (CLAMPED_DOFS..self.q.len()).collect()
    }
}

/// Contact penalty energy of depth `d > 0` with stiffness `k` (N/m) and a
/// cubic onset of width `eps` (m) that makes it C2 (Newton converges instead
/// of cycling at the kink): `k d^3 / (6 eps)` below `eps`, then
/// `k (d^2/2 - eps d/2 + eps^2/6)`. Returns energy, derivative, second derivative.
fn penalty(k: f64, eps: f64, d: f64) -> (f64, f64, f64) {
    if d < eps {
        (k * d * d * d / (6.0 * eps), k * d * d / (2.0 * eps), k * d / eps)
    } else {
        (
            k * (0.5 * d * d - 0.5 * eps * d + eps * eps / 6.0),
            k * (d - 0.5 * eps),
            k,
        )
    }
}

/// The clamp command a fraction `w` of the way from `c0` to `c1`:
/// insertion and rotation linearly, the base pose (when either command has
/// one; `base` stands in for the other) by translation lerp and rotation
/// slerp.
fn interpolate_command(c0: &DeviceCommand, c1: &DeviceCommand, w: f64, base: &Iso3) -> DeviceCommand {
    let base_pose = match (c0.base_pose, c1.base_pose) {
        (None, None) => None,
        (a, b) => {
            let (a, b) = (a.unwrap_or(*base), b.unwrap_or(*base));
            Some(a.lerp_slerp(&b, w))
        }
    };
    DeviceCommand {
        insertion: c0.insertion + w * (c1.insertion - c0.insertion),
        rotation: c0.rotation + w * (c1.rotation - c0.rotation),
        base_pose,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::sdf::StraightTube;

    /// A solid cylinder obstacle (the lumen is outside): `phi = R - rho`,
    /// a convex wall.
    #[derive(Debug)]
    struct Post(StraightTube);
    impl Sdf for Post {
        fn distance(&self, p: &Vec3) -> f64 {
            -self.0.distance(p)
        }
        fn gradient(&self, p: &Vec3) -> Vec3 {
            -self.0.gradient(p)
        }
    }

    /// The wall-curvature term of the contact Hessian against the exact
    /// Hessian of a tube's distance, `(I - a a^T - n n^T) / rho`, for a
    /// tube along an oblique axis (inside: concave, kept); for a convex
    /// post the same matrix is negative and is clamped to zero.
    #[test]
    fn wall_curvature_matches_tube_hessian() {
        let axis = Vec3::new(1.0, 2.0, 3.0).normalize();
        let tube = StraightTube {
            origin: Vec3::new(0.3, -0.2, 0.5),
            axis,
            radius: 0.7e-3,
        };
        let side = axis.cross(&Vec3::x()).normalize();
        let rho = 0.26e-3;
        let x = tube.origin + axis * 0.01 + side * rho;
        let exact = (Mat3::identity() - axis * axis.transpose() - side * side.transpose()) / rho;
        let got = DerRod::wall_curvature(&tube, &x, &tube.gradient(&x));
        let err = (got - exact).norm() / exact.norm();
        // The tube's analytic `Sdf::hessian`: the same closed form, so only
        // rounding differs; the 0.5 m coordinates carry 1e-16 * 0.5 m, i.e.
        // 2e-13 relative to rho, amplified by the eigen-decomposition of the
        // clamp: 1e-10 leaves room (measured value printed below).
        assert!(
            err < 1e-10,
            "rho {rho} m: curvature {got} vs exact {exact} (rel err {err:e})"
        );
        let post = Post(tube);
        let convex = DerRod::wall_curvature(&post, &x, &post.gradient(&x));
        // The post has no analytic Hessian: the default central differences
        // over HESSIAN_FD_STEP = 1e-6 m give a negative semi-definite matrix
        // up to a truncation error (h/rho)^2 = 1.5e-5 relative, so the clamp
        // leaves (nearly) zero.
        let rel = convex.norm() / exact.norm();
        eprintln!("wall curvature: concave rel err {err:.2e}, convex clamped rel {rel:.2e}");
        assert!(
            rel < 1.5e-5,
            "convex post: curvature term {convex} should be clamped to ~0 (rel {rel:e})"
        );
    }
}
