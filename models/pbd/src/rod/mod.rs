//! Cosserat rod in position-based dynamics (model id `pbd-rod`).
//!
//! The rod is the position-and-orientation based Cosserat rod of
//! Kugelstadt & Schömer 2016 ("Position and Orientation Based Cosserat Rods",
//! SCA 2016): `n + 1` particles `x_i` and one unit quaternion `q_j` per
//! segment, coupled by
//!
//! * a **stretch-shear** constraint per segment (K&S 2016, sec. 4.1):
//!   `Gamma_j = (x_{j+1} - x_j) / l - d3(q_j)`, a strain (dimensionless);
//! * a **bend-twist** constraint per joint (K&S 2016, sec. 4.2): the discrete
//!   Darboux vector `Omega = (2 / l) Im(conj(q_j) q_{j+1})` (material frame,
//!   1/m) minus its rest value, with the sign of the relative quaternion chosen
//!   so that its real part is >= 0 (K&S pick the nearer of `+-Omega`).
//!
//! Each constraint is solved with XPBD (Macklin, Müller & Chentanez 2016,
//! "XPBD: Position-Based Simulation of Compliant Constrained Dynamics",
//! eqs. 17-18): `dlambda = -(C + alpha~ lambda) / (J W J^T + alpha~)`,
//! `alpha~ = alpha / h^2`, so the material stiffness does not depend on the
//! time step or the iteration count (once the iteration has converged).
//! Orientation corrections live in the tangent space of the quaternion
//! (`q <- normalize(q + 1/2 (dtheta, 0) q)`, world-frame rotation vector
//! `dtheta`), and the 3x3 blocks `J W J^T` are built exactly at the current
//! state rather than with the isotropic approximation of K&S.
//!
//! Per iteration the constraints are solved either one at a time by
//! non-linear Gauss-Seidel (fidelity `solver = "gauss-seidel"`, the default) or all at
//! once by the direct banded solve of Deul, Kugelstadt, Weiler & Bender 2018
//! (`solver = "direct"`, [`RodSolver::Direct`]), which carries a tip load to the
//! clamp in one iteration (measured: a dead load P L^2/(EI) = 2 settles at one
//! substep of 1 ms with 4 iterations at 10-80 segments, residual < 1e-14,
//! where Gauss-Seidel diverges below 64 substeps).
//!
//! Compliances come from the Cosserat strain energy
//! `U = 1/2 l Gamma^T diag(GA, GA, EA) Gamma + 1/2 l (Omega - Omega0)^T
//! diag(EI, EI, GJ) (Omega - Omega0)` (shear correction factor 1), so
//! `alpha_ss = (1/(l G A), 1/(l G A), 1/(l E A))` and
//! `alpha_bt = (1/(l E I), 1/(l E I), 1/(l G J))` (units: 1/(N m) and
//! 1/(N m) * m^2 per the constraint units). Units are SI throughout.
//!
//! Boundary: particle 0 is held at the clamp point; the clamp frame acts as
//! a fixed virtual segment joined to segment 0 by a bend-twist constraint of
//! half length `l/2` (curvature at `s = 0` by the midpoint rule). Holding the
//! whole first segment rigid instead would clamp the rod half a segment too
//! far out (a first-order error in the deflection).

use std::sync::Arc;

use nalgebra::{Quaternion, UnitQuaternion};
use surgbench_core::band::BandMatrix;
use surgbench_core::flow::FlowField;
use surgbench_core::{BuildError, DeviceCommand, Environment, Iso3, LoadRamp, Mat3, Sdf, Settings, Vec3};

type Quat = Quaternion<f64>;

pub use crate::factory::{PbdRodFactory, ROD_KEYS};

mod build;
mod model;
mod quat;
mod solve;

use quat::*;

/// Upper bound on the Lipschitz constant of the scene's SDF used by the
/// contact early-out. An exact signed distance (analytic tubes, meshes) and a
/// `min` of them (unions) are 1-Lipschitz; the trilinear interpolant of a
/// 1-Lipschitz grid ([`surgbench_core::sdf::VoxelSdf`]) has each gradient
/// component bounded by 1, so `|grad| <= sqrt(3) < 2`.
pub const SDF_LIPSCHITZ_BOUND: f64 = 2.0;

/// The names of `solver`, as rod solvers.
const ROD_SOLVERS: &[(&str, RodSolver)] = &[("gauss-seidel", RodSolver::GaussSeidel), ("direct", RodSolver::Direct)];

/// How each XPBD iteration of `pbd-rod` solves the rod constraints
/// (fidelity extra `solver`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RodSolver {
    /// `solver = "gauss-seidel"`: non-linear Gauss-Seidel, one constraint at a time in
    /// the order `BT_0, SS_0, BT_1, SS_1, ...` (Macklin et al. 2016, eq. 18
    /// per constraint). Cheap per iteration, but information travels one
    /// segment per sweep, so a load at the tip reaches the clamp only after
    /// `O(n)` iterations.
    #[default]
    GaussSeidel,
    /// `solver = "direct"`: the direct solver of Deul, Kugelstadt, Weiler & Bender
    /// 2018 ("Direct Position-Based Solver for Stiff Rods", Computer Graphics
    /// Forum 37(6), sec. 4): per iteration all rod constraints are
    /// linearised at the current state and the whole XPBD system
    /// `(J W J^T + alpha~) dlambda = -(C + alpha~ lambda)` is solved exactly;
    /// the chain makes it block-banded, so a banded Cholesky costs `O(n)`.
    Direct,
}

/// Resolved rod knobs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RodSettings {
    /// Segments over the free length.
    pub segments: usize,
    /// Time step (s).
    pub dt: f64,
    /// Gauss-Seidel iterations per substep.
    pub iterations: usize,
    /// Substeps per step.
    pub substeps: usize,
    /// Velocity damping rate (1/s).
    pub damping: f64,
    /// Constraint solver per iteration.
    pub solver: RodSolver,
}

impl RodSettings {
    /// The rod's knobs from resolved `settings` (ranges declared in
    /// [`crate::factory::ROD_KEYS`], checked by `surgbench_core::resolve`).
    pub fn from_settings(settings: &Settings) -> Result<Self, BuildError> {
        let f = settings.fidelity();
        let segments = f.segments.unwrap_or(50);
        let dt = f.dt.unwrap_or(1e-3);
        let iterations = f.iterations.unwrap_or(20);
        let substeps = settings.number_or("substeps", 1.0);
        let damping = settings.number_or("damping", 0.0);
        if !(1..=100_000).contains(&segments) {
            return Err(BuildError::bad(
                "segments",
                format!("must be in 1..=100000, got {segments}"),
            ));
        }
        crate::check_solver_knobs(dt, iterations)?;
        let solver = settings.pick("solver", ROD_SOLVERS, RodSolver::GaussSeidel)?;
        Ok(Self {
            segments,
            dt,
            iterations,
            substeps: substeps as usize,
            damping,
            solver,
        })
    }
}

/// A vessel-wall contact of one particle (plane constraint of Macklin et al.
/// 2014, "Unified Particle Physics for Real-Time Applications", sec. 5-6).
///
/// The particle (a point on the centreline) is kept `margin` inside the
/// wall, `phi + margin <= 0`: the scene's contact margin, which by the
/// harness convention already is the wire radius (`ContactParams::margin`:
/// "nodes are kept this far inside the wall"), so the rod's own radius is not
/// added again (doing so made the `capstan` wire, radius 0.445 mm in a
/// 0.7 mm lumen, not fit its tube: every particle on the axis started in
/// contact, with the axis's undefined normal).
///
/// A particle near the wall at the start of a substep is a candidate; its
/// plane is linearised where the particle first reaches the wall (`phi +
/// margin >= 0`), at the prediction or during the solve, and then kept for
/// the substep. Linearising at a point still deep in the lumen would take
/// the normal where the SDF gradient may be ill-defined (on a tube's axis
/// it is zero, and a rounding-level offset turns it in an arbitrary
/// direction, so the answer would depend on the frame).
#[derive(Debug, Clone, Copy)]
struct Contact {
    i: usize,
    /// Whether the plane below is set (the particle reached the wall).
    live: bool,
    normal: Vec3,
    /// Signed gap function at `x_ref`: `phi + margin` (> 0 = violating).
    d0: f64,
    x_ref: Vec3,
    /// Accumulated correction this substep (m).
    dx: Vec3,
    /// How far the wall under the particle moves this substep (m; zero for
    /// a still vessel): friction acts on the slip relative to it.
    wall_dx: Vec3,
}

impl Contact {
    /// Set the plane from a query at `x_ref` (gap `d0`, SDF gradient `g`)
    /// if the particle is on or past the wall there and the gradient is
    /// defined; returns whether the contact is live.
    fn linearise(&mut self, d0: f64, g: &Vec3) -> bool {
        let gn = g.norm();
        if d0 >= 0.0 && gn > 0.0 {
            self.live = true;
            self.normal = g / gn;
            self.d0 = d0;
        }
        self.live
    }
}

/// The Cosserat-PBD rod model. Build it through [`PbdRodFactory`] or
/// [`PbdRod::new`].
#[derive(Debug, Clone)]
pub struct PbdRod {
    set: RodSettings,
    n: usize,
    l: f64,
    /// `1 / l` (1/m).
    inv_l: f64,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    x_prev: Vec<Vec3>,
    rest: Vec<Vec3>,
    arclength: Vec<f64>,
    mass: Vec<f64>,
    w: Vec<f64>,
    radius_node: Vec<f64>,
    q: Vec<Quat>,
    q_prev: Vec<Quat>,
    omega: Vec<Vec3>,
    /// Body-frame inertia per segment `(transverse, axial)` (kg m^2).
    inertia: Vec<[f64; 2]>,
    /// Body-frame inverse inertia per segment `(1/I_t, 1/I_t, 1/I_a)` (1/(kg m^2)).
    inv_inertia: Vec<Vec3>,
    /// Stretch-shear compliance per segment, material frame.
    ss_alpha: Vec<Vec3>,
    /// Stretch-shear stiffness `(GA, GA, EA)` per segment (N).
    ss_k: Vec<Vec3>,
    /// Bend-twist compliance per joint (joint 0 = clamp), material frame.
    bt_alpha: Vec<Vec3>,
    /// Bend-twist stiffness `(EI, EI, GJ)` per joint (N m^2).
    bt_k: Vec<Vec3>,
    /// Length over which the joint's Darboux vector is measured (m).
    bt_len: Vec<f64>,
    /// Rest Darboux vector per joint (1/m).
    omega0: Vec<Vec3>,
    lambda_ss: Vec<Vec3>,
    lambda_bt: Vec<Vec3>,
    base: Iso3,
    clamp_pos: Vec3,
    clamp_q: Quat,
    gravity: Vec3,
    /// Full tip force `F` (N, world frame); applied as `s(t) F`.
    tip_force: Vec3,
    /// Full tip torque (N m, world frame); applied as `s(t) tau`.
    tip_torque: Vec3,
    /// Time profile `s(t)` of the tip loads (`None`: `s = 1`).
    tip_ramp: Option<LoadRamp>,
    /// `s(t)` at the time of the substep being solved (set by `step`).
    load_scale: f64,
    vessel: Option<Arc<dyn Sdf>>,
    flow: Option<Arc<dyn FlowField>>,
    /// A moving vessel's environment: `vessel` and `flow` are re-frozen at
    /// the end of every substep, `wall_t` is that substep's `(t0, t1)`.
    moving: Option<Environment>,
    wall_t: (f64, f64),
    mu_s: f64,
    mu_k: f64,
    margin: f64,
    contacts: Vec<Contact>,
    /// Per particle: where the SDF was last queried and its value there
    /// (`phi = +inf` before the first query), for the contact early-out.
    sdf_cache: Vec<(Vec3, f64)>,
    /// Substep length `h` the `*_at` / `ss_inv_den` caches were built for (s).
    cache_h: f64,
    /// `alpha_ss / h^2` per segment.
    ss_at: Vec<Vec3>,
    /// `1 / (J W J^T + alpha_ss / h^2)` per segment (diagonal in the material frame).
    ss_inv_den: Vec<Vec3>,
    /// `alpha_bt / h^2` per joint.
    bt_at: Vec<Vec3>,
    /// Per joint `(a_a + a_b, c_b - a_b, c_a - a_a) / len^2` from the
    /// body-frame inverse inertias `diag(a, a, c)` of the segments before (a)
    /// and after (b) the joint (`a_a = c_a = 0` at the clamp).
    bt_jw: Vec<Vec3>,
    /// `1 / bt_len` per joint (1/m).
    bt_inv_len: Vec<f64>,
    time: f64,
    last_cmd: DeviceCommand,
    hand_force: Vec3,
    hand_torque: Vec3,
    residual: f64,
    projections: u64,
    last_h: f64,
    /// Direct solver ([`RodSolver::Direct`]): `J W J^T + alpha~` over the
    /// multipliers `[BT_0, SS_0, BT_1, SS_1, ...]` (empty for Gauss-Seidel).
    band: BandMatrix,
    /// Direct solver: right-hand side, then `dlambda`, same ordering.
    dsol: Vec<f64>,
    /// Direct solver: rotation matrix of each segment at the linearisation.
    drot: Vec<Mat3>,
    /// Direct solver: relative quaternion `conj(q_a) q_b` of each joint
    /// (real part made >= 0) at the linearisation.
    drel: Vec<Quat>,
}

/// Scalar half-bandwidth of the direct solver's matrix: 3x3 blocks ordered
/// `BT_0, SS_0, BT_1, SS_1, ...` couple their neighbours up to two blocks
/// away (`BT_k`-`BT_{k+1}` share `q_k`, `SS_j`-`SS_{j+1}` share `x_{j+1}`),
/// so entry `(i, j)` is non-zero only for `|i - j| <= 3 * 2 + 2 = 8`.
pub const DIRECT_HALF_BANDWIDTH: usize = 8;

impl PbdRod {
    /// Scale `s(t)` of the tip loads at time `t` (s); 1 without a ramp.
    fn tip_scale(&self, t: f64) -> f64 {
        self.tip_ramp.as_ref().map_or(1.0, |r| r.scale_at(t))
    }

    /// Resolved settings.
    pub fn settings(&self) -> RodSettings {
        self.set
    }

    /// Particle positions (m), clamp to tip.
    pub fn positions(&self) -> &[Vec3] {
        &self.x
    }

    /// Count of constraint projections since the start (work measure).
    pub fn constraint_projections(&self) -> u64 {
        self.projections
    }

    /// Clamp pose for a command: moved `insertion` along and rotated
    /// `rotation` about the base tangent.
    fn clamp_pose(&self, ins: f64, rot: f64, pose: Option<Iso3>) -> (Vec3, Quat) {
        let base = pose.unwrap_or(self.base);
        let t = base.rotation * Vec3::x();
        let r = base.rotation * UnitQuaternion::from_axis_angle(&Vec3::x_axis(), rot);
        (base.translation.vector + t * ins, material_of_base(&r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::{Fidelity, RodBody, Scene};

    use crate::testrng::{Rng, quat};

    #[test]
    fn body_frame_update_equals_the_world_frame_update() {
        let mut rng = Rng(1);
        for case in 0..100 {
            let q = quat(&mut rng);
            let u = rng.signed_vec() * 1e-3;
            let world = rotmat(&q) * u;
            let exact = (q + Quat::from_imag(world * 0.5) * q).normalize();
            let fast = rotate_body(&q, &u);
            // Same quaternion up to the Newton normalisation: |eps| = |u|^2/4
            // <= 7.5e-7, error <= 3/8 eps^2 ~ 2e-13, plus roundoff.
            assert!((fast - exact).norm() < 1e-12, "case {case}: {fast:?} vs {exact:?}");
            assert!(
                (conj_mul(&q, &exact) - q.conjugate() * exact).norm() < 1e-15,
                "case {case}: conj_mul"
            );
        }
        // A large update takes the exact branch.
        let q = quat(&mut rng);
        let u = Vec3::new(0.3, -0.2, 0.1);
        let exact = (q + mul_pure(&q, &(u * 0.5))).normalize();
        assert!((rotate_body(&q, &u) - exact).norm() < 1e-15);
    }

    #[test]
    fn bend_twist_block_equals_the_explicit_matrix_product() {
        // K = (B Wb B^T + A Wa A^T) / len^2 with B = w I + [v], A = B^T,
        // against the closed form used in `solve_bend_twist`.
        let mut rng = Rng(2);
        for case in 0..100 {
            let r = quat(&mut rng);
            let (w, v) = (r.w, r.imag());
            let b = Mat3::identity() * w + skew(&v);
            let (ta, aa) = (1.0 + rng.signed().abs(), 3.0 + rng.signed().abs());
            let (tb, ab) = (1.0 + rng.signed().abs(), 3.0 + rng.signed().abs());
            let wa = Vec3::new(ta, ta, aa);
            let wb = Vec3::new(tb, tb, ab);
            let len = 0.5;
            let k = (b * Mat3::from_diagonal(&wb) * b.transpose() + b.transpose() * Mat3::from_diagonal(&wa) * b)
                / (len * len);
            let jc = Vec3::new(wa.x + wb.x, wb.z - wb.x, wa.z - wa.x) / (len * len);
            let (b3, a3) = (Vec3::new(v.y, -v.x, w), Vec3::new(-v.y, v.x, w));
            let closed = Mat3::identity() * jc.x - v * v.transpose() * jc.x
                + b3 * b3.transpose() * jc.y
                + a3 * a3.transpose() * jc.z;
            // Relies on |r| = 1; roundoff of O(10) flops on O(10) entries.
            assert!((k - closed).amax() < 1e-12, "case {case}: {k} vs {closed}");
            let rhs = rng.signed_vec();
            let kk = [k[(0, 0)], k[(0, 1)], k[(0, 2)], k[(1, 1)], k[(1, 2)], k[(2, 2)]];
            let x = solve_spd3(kk, &rhs).expect("SPD");
            assert!(
                (k * x - rhs).norm() < 1e-12 * rhs.norm().max(1.0),
                "case {case}: LDL solve"
            );
        }
        // Not positive definite: refused, not garbage.
        assert!(solve_spd3([1.0, 2.0, 0.0, 1.0, 0.0, 1.0], &Vec3::x()).is_none());
    }

    /// Constraint values of the direct solver's rows at a state, with the
    /// stretch-shear rows in the fixed frames `frames` (the frames of the
    /// linearisation point, as `assemble_direct` holds them fixed).
    fn direct_constraints(rod: &PbdRod, x: &[Vec3], q: &[Quat], frames: &[Mat3]) -> Vec<f64> {
        let mut c = Vec::with_capacity(6 * rod.n);
        for k in 0..rod.n {
            let qa = if k == 0 { rod.clamp_q } else { q[k - 1] };
            let (om, _, _) = darboux(&qa, &q[k], rod.bt_len[k]);
            c.extend((om - rod.omega0[k]).iter());
            let d3 = rotmat(&q[k]).column(2).into_owned();
            let g = frames[k].tr_mul(&((x[k + 1] - x[k]) * rod.inv_l - d3));
            c.extend(g.iter());
        }
        c
    }

    #[test]
    fn direct_system_matches_a_dense_finite_difference_construction() {
        // 4-segment cantilever in a random bent, stretched and twisted state
        // with random multipliers: the banded J W J^T + alpha~ and the
        // right-hand side -(C + alpha~ lambda) of `assemble_direct` against a
        // dense J from central differences of the constraint values over
        // every free coordinate (particles 1..=n in world coordinates,
        // body-frame rotation vectors of the segments), W from the masses
        // and inertias, every entry of the 24 x 24 matrix compared (so the
        // zero blocks outside the band are checked too).
        let mut scene = Scene::empty("fd");
        scene.bodies.push(RodBody::uniform(0.1, 5e-4, 5e10, 0.3, 6450.0).into());
        let mut fid = Fidelity {
            segments: Some(4),
            dt: Some(1e-3),
            iterations: Some(1),
            ..Default::default()
        };
        fid.extras.insert("substeps".into(), 1.0.into());
        fid.extras.insert("solver".into(), "direct".into());
        let mut rod = PbdRod::new(&scene, &fid).unwrap();
        let n = rod.n;
        let h = 1e-3;
        rod.refresh_caches(h);
        let mut rng = Rng(20180601);
        for i in 1..=n {
            rod.x[i] += rng.signed_vec() * (0.3 * rod.l);
        }
        for j in 0..n {
            rod.q[j] = (rod.q[j] * UnitQuaternion::from_scaled_axis(rng.signed_vec() * 0.4).into_inner()).normalize();
            rod.lambda_ss[j] = rng.signed_vec() * 1e-8;
            rod.lambda_bt[j] = rng.signed_vec() * 1e-10;
        }
        rod.assemble_direct(false);
        let frames: Vec<Mat3> = rod.q.iter().map(rotmat).collect();
        let (x0, q0) = (rod.x.clone(), rod.q.clone());
        let c0 = direct_constraints(&rod, &x0, &q0, &frames);
        let m = 6 * n;
        // Right-hand side: same values, evaluated independently.
        let mut alpha = vec![0.0; m];
        for k in 0..n {
            for a in 0..3 {
                alpha[6 * k + a] = rod.bt_at[k][a];
                alpha[6 * k + 3 + a] = rod.ss_at[k][a];
            }
        }
        let lam: Vec<f64> = (0..n)
            .flat_map(|k| {
                rod.lambda_bt[k]
                    .iter()
                    .chain(rod.lambda_ss[k].iter())
                    .copied()
                    .collect::<Vec<_>>()
            })
            .collect();
        for r in 0..m {
            let want = -(c0[r] + alpha[r] * lam[r]);
            // Same formula, different evaluation order: roundoff on O(1) values.
            assert!(
                (rod.dsol[r] - want).abs() <= 1e-13 * want.abs().max(1.0),
                "rhs row {r}: {} vs {want}",
                rod.dsol[r]
            );
        }
        // Dense Jacobian by central differences; coordinate `3 (i - 1) + a`
        // is particle i, `3 n + 3 j + a` the rotation of segment j.
        let dofs = 6 * n;
        let mut jac = vec![vec![0.0; dofs]; m];
        let mut winv = vec![0.0; dofs];
        let (ex, eu) = (1e-6 * rod.l, 1e-6);
        for d in 0..dofs {
            let (mut xp, mut qp, mut xm, mut qm) = (x0.clone(), q0.clone(), x0.clone(), q0.clone());
            let eps = if d < 3 * n {
                let (i, a) = (d / 3 + 1, d % 3);
                xp[i][a] += ex;
                xm[i][a] -= ex;
                winv[d] = rod.w[i];
                ex
            } else {
                let (j, a) = ((d - 3 * n) / 3, d % 3);
                let mut u = Vec3::zeros();
                u[a] = eu;
                qp[j] = q0[j] * UnitQuaternion::from_scaled_axis(u).into_inner();
                qm[j] = q0[j] * UnitQuaternion::from_scaled_axis(-u).into_inner();
                winv[d] = rod.inv_inertia[j][a];
                eu
            };
            let cp = direct_constraints(&rod, &xp, &qp, &frames);
            let cm = direct_constraints(&rod, &xm, &qm, &frames);
            for r in 0..m {
                jac[r][d] = (cp[r] - cm[r]) / (2.0 * eps);
            }
        }
        let mut worst: f64 = 0.0;
        for r in 0..m {
            for c in 0..m {
                let mut dense = if r == c { alpha[r] } else { 0.0 };
                for d in 0..dofs {
                    dense += jac[r][d] * winv[d] * jac[c][d];
                }
                let got = rod.band.get(r, c);
                let scale = (rod.band.get(r, r) * rod.band.get(c, c)).sqrt();
                let e = (got - dense).abs() / scale;
                worst = worst.max(e);
                // Central differences with steps 1e-6 (relative): truncation
                // ~1e-12, cancellation ~1e-16 / 1e-6 = 1e-10 relative to the
                // Cauchy-Schwarz scale sqrt(A_rr A_cc) of an SPD entry;
                // measured worst 2.0e-9 here.
                assert!(
                    e < 1e-8,
                    "entry ({r}, {c}): band {got:e} vs dense {dense:e} (rel {e:e})"
                );
            }
        }
        println!("worst relative entry error {worst:e}");
        // And the factorisation solves it (SPD, alpha > 0).
        rod.band.factor(0.0).expect("SPD");
    }
}
