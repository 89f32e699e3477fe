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
//! non-linear Gauss-Seidel (fidelity `solver = 0`, the default) or all at
//! once by the direct banded solve of Deul, Kugelstadt, Weiler & Bender 2018
//! (`solver = 1`, [`RodSolver::Direct`]), which carries a tip load to the
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

use nalgebra::{Matrix3, Quaternion, UnitQuaternion};
use surgbench_core::band::BandMatrix;
use surgbench_core::beam::first_bending_frequency;
use surgbench_core::flow::{BLOOD_DENSITY, DRAG_NORMAL, FlowField};
use surgbench_core::motion::carried;
use surgbench_core::{
    BuildError, Capability, ContactObs, DeviceCommand, EnergyObs, Environment, Family, Fidelity, FidelityKey, Iso3,
    LoadRamp, Mat3, Model, ModelFactory, Observation, RodBody, RodObs, Scene, Sdf, SimError, StepStats, Unsupported,
    Vec3,
};

type Quat = Quaternion<f64>;

/// Upper bound on the Lipschitz constant of the scene's SDF used by the
/// contact early-out. An exact signed distance (analytic tubes, meshes) and a
/// `min` of them (unions) are 1-Lipschitz; the trilinear interpolant of a
/// 1-Lipschitz grid ([`surgbench_core::sdf::VoxelSdf`]) has each gradient
/// component bounded by 1, so `|grad| <= sqrt(3) < 2`.
pub const SDF_LIPSCHITZ_BOUND: f64 = 2.0;

/// Fidelity extras of `pbd-rod`.
pub const ROD_KEYS: &[FidelityKey] = &[
    FidelityKey {
        name: "substeps",
        doc: "XPBD substeps per step (integer >= 1; default 1)",
    },
    FidelityKey {
        name: "damping",
        doc: "velocity damping rate c (1/s): v <- v / (1 + c h) each substep; default 0, or 2 omega_1 (critical for the first bending mode) in static scenes",
    },
    FidelityKey {
        name: "solver",
        doc: "constraint solver per iteration: 0 = non-linear Gauss-Seidel over the constraints (default), 1 = direct: all rod constraints linearised and solved at once by banded Cholesky (Deul et al. 2018)",
    },
];

/// How each XPBD iteration of `pbd-rod` solves the rod constraints
/// (fidelity extra `solver`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RodSolver {
    /// `solver = 0`: non-linear Gauss-Seidel, one constraint at a time in
    /// the order `BT_0, SS_0, BT_1, SS_1, ...` (Macklin et al. 2016, eq. 18
    /// per constraint). Cheap per iteration, but information travels one
    /// segment per sweep, so a load at the tip reaches the clamp only after
    /// `O(n)` iterations.
    #[default]
    GaussSeidel,
    /// `solver = 1`: the direct solver of Deul, Kugelstadt, Weiler & Bender
    /// 2018 ("Direct Position-Based Solver for Stiff Rods", Computer Graphics
    /// Forum 37(6), sec. 4): per iteration all rod constraints are
    /// linearised at the current state and the whole XPBD system
    /// `(J W J^T + alpha~) dlambda = -(C + alpha~ lambda)` is solved exactly;
    /// the chain makes it block-banded, so a banded Cholesky costs `O(n)`.
    Direct,
}

/// Factory for the Cosserat-PBD rod (`pbd-rod`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PbdRodFactory;

const ROD_CAPS: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::LoadRamp,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
    Capability::MovingVessel,
    Capability::HapticForce,
];

impl ModelFactory for PbdRodFactory {
    fn id(&self) -> &'static str {
        "pbd-rod"
    }
    fn description(&self) -> &'static str {
        "Cosserat rod in XPBD (Kugelstadt & Schömer 2016): particles + quaternions, SDF contact with position-level friction"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn capabilities(&self) -> &'static [Capability] {
        ROD_CAPS
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        ROD_KEYS
    }
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            segments: Some(50),
            mesh_level: None,
            dt: Some(1e-3),
            iterations: Some(20),
            extras: Default::default(),
        };
        f.extras.insert("substeps".into(), 4.0);
        // A dead tip load enters the prediction as h^2 F / m_tip, which on a
        // light tip particle can be many segment lengths; the chain's
        // Gauss-Seidel then cannot carry it back to the clamp within the
        // substep and the wire over-stretches (capstan: 1 N on 2.2e-6 kg at
        // h = 0.25 ms is 29 mm against 1.1 mm segments). Default substeps keep
        // that offset below a tenth of a segment at the default segment count
        // and time step, h <= l sqrt(0.1 rho A / (2 |F|)) (measured: capstan
        // at 40 segments runs with 64 substeps, tension ratio within 1.3% of
        // exp(mu theta), stretch 1.3% = T / EA; it trips the stretch watchdog
        // with 4).
        if let (Some(rod), Some(segments), Some(dt)) = (scene.rods().next(), f.segments, f.dt) {
            let fmax = rod.tip_force.norm();
            let s = rod.section_at(rod.length);
            let l = rod.length / segments as f64;
            if fmax > 0.0 {
                let h_max = l * (0.1 * s.density * s.area() / (2.0 * fmax)).sqrt();
                let ns = (dt / h_max).ceil().clamp(4.0, 1e4);
                f.extras.insert("substeps".into(), ns);
            }
        }
        // Static scenes are run to equilibrium with the model's own damping:
        // critical damping of the first cantilever bending mode,
        // c = 2 omega_1 (`surgbench_core::beam::first_bending_frequency`).
        if scene.settle.is_some()
            && let Some(rod) = scene.rods().next()
        {
            let w1 = first_bending_frequency(&rod.sections[0], rod.length);
            f.extras.insert("damping".into(), 2.0 * w1);
        }
        f
    }
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_capabilities(self.id(), self.capabilities(), scene)?;
        match scene.rods().count() {
            1 => Ok(()),
            0 => Err(Unsupported::new("pbd-rod needs a rod in the scene")),
            k => Err(Unsupported::new(format!(
                "pbd-rod simulates one rod, the scene has {k}"
            ))),
        }
    }
    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError> {
        Ok(Box::new(PbdRod::new(scene, fidelity)?))
    }
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
    /// Resolve `fidelity` over the factory defaults, rejecting bad values.
    pub fn resolve(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        fidelity
            .check_extras(ROD_KEYS)
            .map_err(|e| BuildError::bad("fidelity", e.0))?;
        let f = PbdRodFactory.default_fidelity(scene).merged(fidelity);
        let segments = f.segments.unwrap_or(50);
        let dt = f.dt.unwrap_or(1e-3);
        let iterations = f.iterations.unwrap_or(20);
        let substeps = f.extra("substeps", 1.0);
        let damping = f.extra("damping", 0.0);
        if !(1..=100_000).contains(&segments) {
            return Err(BuildError::bad(
                "segments",
                format!("must be in 1..=100000, got {segments}"),
            ));
        }
        crate::check_solver_knobs(dt, iterations, substeps, damping)?;
        let solver = match f.extra("solver", 0.0) {
            0.0 => RodSolver::GaussSeidel,
            1.0 => RodSolver::Direct,
            v => {
                return Err(BuildError::bad(
                    "solver",
                    format!("must be 0 (Gauss-Seidel) or 1 (direct), got {v}"),
                ));
            }
        };
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

/// Add the 3x3 block `m` at block position `(bi, bj)`, `bi >= bj`, of a
/// symmetric band matrix that stores the lower triangle (on the diagonal,
/// only `m`'s lower triangle is read).
fn add_block(band: &mut BandMatrix, bi: usize, bj: usize, m: &Mat3) {
    for r in 0..3 {
        let cmax = if bi == bj { r + 1 } else { 3 };
        for c in 0..cmax {
            band.add(3 * bi + r, 3 * bj + c, m[(r, c)]);
        }
    }
}

/// `[e3]_x`: body-frame Jacobian of the stretch-shear constraint on its
/// segment's rotation (see [`PbdRod::assemble_direct`]).
fn e3_cross() -> Mat3 {
    Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
}

/// Rotation matrix of a unit quaternion: columns are the directors `(d1, d2, d3)`.
fn rotmat(q: &Quat) -> Mat3 {
    UnitQuaternion::new_unchecked(*q).to_rotation_matrix().into_inner()
}

/// Skew matrix `[v]_x` with `[v]_x u = v x u`.
fn skew(v: &Vec3) -> Mat3 {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Material frame of the clamp: `d3` along the base's local x, `(d1, d2)` =
/// local `(y, z)`. The map `(e1, e2, e3) -> (y, z, x)` is the rotation by
/// 120 degrees about `(1, 1, 1)/sqrt(3)`: quaternion `(1/2, 1/2, 1/2, 1/2)`
/// (exact in floating point, no matrix-to-quaternion iteration per substep).
fn material_of_base(rot: &UnitQuaternion<f64>) -> Quat {
    rot.into_inner() * Quat::new(0.5, 0.5, 0.5, 0.5)
}

/// `q (u, 0)`: right product with a pure quaternion. For a unit `q` with
/// rotation `R`, `(R u, 0) q = q (u, 0)`, so a world-frame rotation vector
/// `R u` applied as `q + 1/2 (R u, 0) q` is `q + 1/2 q (u, 0)` with the
/// body-frame `u`: no rotation matrix needed.
#[inline]
fn mul_pure(q: &Quat, u: &Vec3) -> Quat {
    let v = q.imag();
    Quat::from_parts(-v.dot(u), u * q.w + v.cross(u))
}

/// `normalize(q + 1/2 q (u, 0))`: the XPBD orientation update with a
/// body-frame rotation vector `u` (rad).
///
/// For a near-unit `p` (`|p|^2 = 1 + eps`, `|eps| < 1e-4`) the normalisation
/// uses one Newton step of `1/sqrt` from 1, `1 - eps/2`, which leaves
/// `||p| (1 - eps/2) - 1| <= 3/8 eps^2 < 4e-9` and, applied again at the next
/// update, contracts any norm error quadratically; larger updates use the
/// exact square root. This keeps `sqrt` and a division off the Gauss-Seidel
/// dependency chain, where almost every update is tiny. (`predict`
/// normalises exactly once per substep.)
#[inline]
fn rotate_body(q: &Quat, u: &Vec3) -> Quat {
    let p = q + mul_pure(q, &(u * 0.5));
    let eps = p.norm_squared() - 1.0;
    if eps.abs() < 1e-4 {
        p * (1.0 - 0.5 * eps)
    } else {
        p * (1.0 / p.norm())
    }
}

/// `conj(a) b` written out (the relative rotation of two frames).
#[inline]
fn conj_mul(a: &Quat, b: &Quat) -> Quat {
    let (va, vb) = (a.imag(), b.imag());
    Quat::from_parts(a.w * b.w + va.dot(&vb), vb * a.w - va * b.w - va.cross(&vb))
}

/// Solve the symmetric 3x3 system `K x = b` with the adjugate,
/// `x = adj(K) b / det(K)`: one division, so little latency on the
/// Gauss-Seidel dependency chain (an `L D L^T` solve has three in series).
/// `k = [k00, k01, k02, k11, k12, k22]`. `None` unless `K` is positive
/// definite by Sylvester's criterion (`k00 > 0`, `k00 k11 - k01^2 > 0`,
/// `det > 0`), which `J W J^T + alpha~` is whenever a constraint has a
/// moving body.
#[inline]
fn solve_spd3(k: [f64; 6], b: &Vec3) -> Option<Vec3> {
    let [k00, k01, k02, k11, k12, k22] = k;
    // Cofactors (symmetric).
    let c00 = k11 * k22 - k12 * k12;
    let c01 = k02 * k12 - k01 * k22;
    let c02 = k01 * k12 - k02 * k11;
    let c11 = k00 * k22 - k02 * k02;
    let c12 = k01 * k02 - k00 * k12;
    let c22 = k00 * k11 - k01 * k01;
    let det = k00 * c00 + k01 * c01 + k02 * c02;
    if !(k00 > 0.0 && c22 > 0.0 && det > 0.0) {
        return None;
    }
    let inv = 1.0 / det;
    Some(Vec3::new(
        (c00 * b.x + c01 * b.y + c02 * b.z) * inv,
        (c01 * b.x + c11 * b.y + c12 * b.z) * inv,
        (c02 * b.x + c12 * b.y + c22 * b.z) * inv,
    ))
}

/// Body-frame relative rotation by angle `|k| len` about the material axis `k/|k|`.
fn rest_rotation(kappa: &Vec3, len: f64) -> Quat {
    let th = kappa.norm() * len;
    if th == 0.0 {
        return Quat::identity();
    }
    UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(*kappa), th).into_inner()
}

/// Discrete Darboux vector `(2/len) Im(conj(qa) qb)` with the real part made
/// non-negative (K&S 2016 sec. 4.2); returns `(Omega, w, v)`.
fn darboux(qa: &Quat, qb: &Quat, len: f64) -> (Vec3, f64, Vec3) {
    let mut r = conj_mul(qa, qb);
    if r.w < 0.0 {
        r = -r;
    }
    let v = r.imag();
    (v * (2.0 / len), r.w, v)
}

impl PbdRod {
    /// Build the rod of `scene` (exactly one rod) at `fidelity`.
    pub fn new(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        PbdRodFactory.check(scene)?;
        scene.validate().map_err(|e| BuildError::bad("scene", e))?;
        let set = RodSettings::resolve(scene, fidelity)?;
        let rod: &RodBody = scene.rods().next().expect("checked: one rod");
        let n = set.segments;
        let l = rod.length / n as f64;

        // Per-segment properties from the section at the segment midpoint.
        let mut seg_mass = vec![0.0; n];
        let mut inertia = vec![[0.0; 2]; n];
        let mut ss_k = vec![Vec3::zeros(); n];
        let mut seg_bt = vec![Vec3::zeros(); n];
        let mut seg_kappa = vec![Vec3::zeros(); n];
        let mut seg_r = vec![0.0f64; n];
        for j in 0..n {
            let s = rod.section_at((j as f64 + 0.5) * l);
            let (a, i2, ip) = (s.area(), s.second_moment(), s.polar_moment());
            let (e, g) = (s.youngs_modulus, s.shear_modulus());
            let m = s.density * a * l;
            seg_mass[j] = m;
            // Solid cylinder: axial m r^2/2, transverse m (r^2/4 + l^2/12).
            inertia[j] = [
                m * (s.radius * s.radius / 4.0 + l * l / 12.0),
                0.5 * m * s.radius * s.radius,
            ];
            ss_k[j] = Vec3::new(g * a, g * a, e * a);
            seg_bt[j] = Vec3::new(e * i2, e * i2, g * ip);
            seg_kappa[j] = Vec3::new(s.rest_curvature[0], s.rest_curvature[1], 0.0);
            seg_r[j] = s.radius;
        }
        let ss_alpha: Vec<Vec3> = ss_k.iter().map(|k| k.map(|c| 1.0 / (l * c))).collect();
        // Joint 0: clamp frame -> segment 0 over l/2; joint j: segment j-1 -> j over l.
        let mut bt_k = Vec::with_capacity(n);
        let mut bt_len = Vec::with_capacity(n);
        let mut omega0 = Vec::with_capacity(n);
        let mut rel = Vec::with_capacity(n);
        for j in 0..n {
            let (k, kap, len) = if j == 0 {
                (seg_bt[0], seg_kappa[0], 0.5 * l)
            } else {
                (
                    0.5 * (seg_bt[j - 1] + seg_bt[j]),
                    0.5 * (seg_kappa[j - 1] + seg_kappa[j]),
                    l,
                )
            };
            let r = rest_rotation(&kap, len);
            let (om, _, _) = darboux(&Quat::identity(), &r, len);
            bt_k.push(k);
            bt_len.push(len);
            omega0.push(om);
            rel.push(r);
        }
        let bt_alpha: Vec<Vec3> = bt_k
            .iter()
            .zip(&bt_len)
            .map(|(k, len)| k.map(|c| 1.0 / (len * c)))
            .collect();

        // Rest configuration from the clamp pose.
        let base = rod.base;
        let clamp_q = material_of_base(&base.rotation);
        let clamp_pos = base.translation.vector;
        let mut q = Vec::with_capacity(n);
        let mut x = Vec::with_capacity(n + 1);
        x.push(clamp_pos);
        let mut qc = clamp_q;
        for j in 0..n {
            qc *= rel[j];
            qc = qc.normalize();
            q.push(qc);
            let d3 = rotmat(&qc).column(2).into_owned();
            x.push(x[j] + d3 * l);
        }
        let mut mass = vec![0.0; n + 1];
        let mut radius_node = vec![0.0f64; n + 1];
        for j in 0..n {
            mass[j] += 0.5 * seg_mass[j];
            mass[j + 1] += 0.5 * seg_mass[j];
            radius_node[j] = radius_node[j].max(seg_r[j]);
            radius_node[j + 1] = radius_node[j + 1].max(seg_r[j]);
        }
        let mut w: Vec<f64> = mass.iter().map(|m| 1.0 / m).collect();
        w[0] = 0.0;
        let inv_inertia: Vec<Vec3> = inertia
            .iter()
            .map(|&[it, ia]| Vec3::new(1.0 / it, 1.0 / it, 1.0 / ia))
            .collect();
        let bt_jw = (0..n)
            .map(|k| {
                let wb = inv_inertia[k];
                let wa = if k == 0 { Vec3::zeros() } else { inv_inertia[k - 1] };
                Vec3::new(wa.x + wb.x, wb.z - wb.x, wa.z - wa.x) / (bt_len[k] * bt_len[k])
            })
            .collect();
        let bt_inv_len = bt_len.iter().map(|l| 1.0 / l).collect();
        let c = scene.environment.contact;
        Ok(Self {
            set,
            n,
            l,
            inv_l: 1.0 / l,
            v: vec![Vec3::zeros(); n + 1],
            x_prev: x.clone(),
            rest: x.clone(),
            arclength: (0..=n).map(|i| i as f64 * l).collect(),
            x,
            mass,
            w,
            radius_node,
            q_prev: q.clone(),
            q,
            omega: vec![Vec3::zeros(); n],
            inv_inertia,
            inertia,
            ss_alpha,
            ss_k,
            bt_alpha,
            bt_k,
            bt_len,
            omega0,
            lambda_ss: vec![Vec3::zeros(); n],
            lambda_bt: vec![Vec3::zeros(); n],
            base,
            clamp_pos,
            clamp_q,
            gravity: scene.gravity,
            tip_force: rod.tip_force,
            tip_torque: rod.tip_torque,
            tip_ramp: rod.tip_load_ramp.clone(),
            load_scale: rod.tip_load_scale(0.0),
            vessel: scene.environment.vessel_at(0.0),
            flow: scene.environment.flow_at(0.0),
            moving: scene
                .environment
                .vessel_motion
                .as_ref()
                .map(|_| scene.environment.clone()),
            wall_t: (0.0, 0.0),
            mu_s: c.friction_static,
            mu_k: c.friction_dynamic,
            margin: c.margin,
            contacts: Vec::with_capacity(n),
            sdf_cache: vec![(Vec3::zeros(), f64::INFINITY); n + 1],
            cache_h: f64::NAN,
            ss_at: vec![Vec3::zeros(); n],
            ss_inv_den: vec![Vec3::zeros(); n],
            bt_at: vec![Vec3::zeros(); n],
            bt_jw,
            bt_inv_len,
            time: 0.0,
            last_cmd: DeviceCommand::default(),
            hand_force: Vec3::zeros(),
            hand_torque: Vec3::zeros(),
            residual: 0.0,
            projections: 0,
            last_h: set.dt / set.substeps as f64,
            band: BandMatrix::new(
                if set.solver == RodSolver::Direct { 6 * n } else { 0 },
                DIRECT_HALF_BANDWIDTH,
            ),
            dsol: Vec::new(),
            drot: Vec::new(),
            drel: Vec::new(),
        })
    }

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

    fn predict(&mut self, h: f64) {
        let damp = 1.0 / (1.0 + self.set.damping * h);
        let n = self.n;
        for i in 1..=n {
            let mut f = self.gravity * self.mass[i];
            if i == n {
                f += self.tip_force * self.load_scale;
            }
            // Damp the old velocity only, so the static load h^2 g is not scaled.
            let mut v = self.v[i] * damp + f * (h * self.w[i]);
            if let Some(flow) = &self.flow {
                // Quadratic cross-flow drag on the particle's share of the rod,
                // integrated implicitly in its linearised form for stability.
                let t = (self.x[i] - self.x[i - 1]
                    + if i < n {
                        self.x[i + 1] - self.x[i]
                    } else {
                        Vec3::zeros()
                    })
                .try_normalize(1e-300)
                .unwrap_or(Vec3::x());
                let rel = flow.velocity(&self.x[i]) - v;
                let rel_n = rel - t * t.dot(&rel);
                let share = if i == n { 0.5 * self.l } else { self.l };
                let c = 0.5 * BLOOD_DENSITY * DRAG_NORMAL * 2.0 * self.radius_node[i] * share * rel_n.norm();
                v += rel_n * (1.0 - 1.0 / (1.0 + h * c * self.w[i]));
            }
            self.v[i] = v;
            self.x_prev[i] = self.x[i];
            self.x[i] += v * h;
        }
        for j in 0..n {
            let r = rotmat(&self.q[j]);
            let [it, ia] = self.inertia[j];
            let ib = Vec3::new(it, it, ia);
            let mut wb = r.transpose() * self.omega[j] * damp;
            let mut tau = -wb.cross(&ib.component_mul(&wb));
            if j == n - 1 {
                tau += r.transpose() * (self.tip_torque * self.load_scale);
            }
            wb += tau.component_div(&ib) * h;
            self.omega[j] = r * wb;
            self.q_prev[j] = self.q[j];
            let dq = Quat::from_imag(self.omega[j] * (0.5 * h)) * self.q[j];
            self.q[j] = (self.q[j] + dq).normalize();
        }
    }

    /// Find the particles near the vessel wall and linearise the wall at
    /// those already on or past it ([`Contact`]). One `distance_gradient`
    /// query per particle at the prediction, none for a particle provably
    /// deep in the lumen: a signed distance field changes by at most `L |dx|`
    /// when the point moves by `dx` ([`SDF_LIPSCHITZ_BOUND`]), so the cached
    /// `phi` plus `L` times the distance moved since that query bounds `phi`
    /// from above. The same bound gates the re-queries of candidates during
    /// the solve ([`Self::solve_contacts`]).
    fn detect_contacts(&mut self) {
        self.contacts.clear();
        let Some(sdf) = &self.vessel else { return };
        for i in 1..=self.n {
            let xi = self.x[i];
            let r = self.radius_node[i];
            let band = 2.0 * (xi - self.x_prev[i]).norm() + r;
            let (xc, phic) = self.sdf_cache[i];
            // A moving wall may come to the particle: no early-out (the
            // cached value is of another time's lumen).
            if self.moving.is_none() && phic + SDF_LIPSCHITZ_BOUND * (xi - xc).norm() + self.margin <= -band {
                continue;
            }
            let (phi, g) = sdf.distance_gradient(&xi);
            self.sdf_cache[i] = (xi, phi);
            let d0 = phi + self.margin;
            if d0 > -band {
                let wall_dx = match self.moving.as_ref().and_then(|e| e.vessel_motion.as_ref()) {
                    Some(m) => carried(m.as_ref(), &self.x_prev[i], self.wall_t.0, self.wall_t.1) - self.x_prev[i],
                    None => Vec3::zeros(),
                };
                let mut c = Contact {
                    i,
                    live: false,
                    normal: Vec3::zeros(),
                    d0,
                    x_ref: xi,
                    dx: Vec3::zeros(),
                    wall_dx,
                };
                c.linearise(d0, &g);
                self.contacts.push(c);
            }
        }
    }

    /// Rebuild the per-substep constants (`alpha / h^2` and the stretch-shear
    /// denominators) when the substep length changes.
    fn refresh_caches(&mut self, h: f64) {
        if h == self.cache_h {
            return;
        }
        self.cache_h = h;
        let inv_h2 = 1.0 / (h * h);
        let inv_l2 = 1.0 / (self.l * self.l);
        for j in 0..self.n {
            let al = self.ss_alpha[j] * inv_h2;
            let wx = (self.w[j] + self.w[j + 1]) * inv_l2;
            let a = self.inv_inertia[j].x;
            self.ss_at[j] = al;
            self.ss_inv_den[j] = Vec3::new(1.0 / (wx + a + al.x), 1.0 / (wx + a + al.y), 1.0 / (wx + al.z));
            self.bt_at[j] = self.bt_alpha[j] * inv_h2;
        }
    }

    /// Stretch-shear constraint of segment `j` (XPBD, exact block, solved in
    /// the material frame where `J W J^T` is diagonal:
    /// `diag(wx + 1/I_t, wx + 1/I_t, wx)`, `wx = (w_j + w_{j+1}) / l^2`).
    #[inline]
    fn solve_stretch_shear(&mut self, j: usize, last: bool) {
        let inv_l = self.inv_l;
        let qj = self.q[j];
        let r = rotmat(&qj);
        let gb = r.tr_mul(&((self.x[j + 1] - self.x[j]) * inv_l)) - Vec3::z();
        let rhs = -(gb + self.ss_at[j].component_mul(&self.lambda_ss[j]));
        if last {
            self.residual = self.residual.max(rhs.amax());
        }
        let dl = rhs.component_mul(&self.ss_inv_den[j]);
        self.lambda_ss[j] += dl;
        let dw = r * dl;
        self.x[j] -= dw * (self.w[j] * inv_l);
        self.x[j + 1] += dw * (self.w[j + 1] * inv_l);
        // World rotation (d1 dl_y - d2 dl_x) / I_t, i.e. body (dl_y, -dl_x, 0) / I_t.
        let a = self.inv_inertia[j].x;
        self.q[j] = rotate_body(&qj, &Vec3::new(dl.y * a, -dl.x * a, 0.0));
    }

    /// Bend-twist constraint of joint `k` between segment `k-1` (or the clamp
    /// frame for `k = 0`) and segment `k` (XPBD, exact 3x3 block).
    ///
    /// With `r = conj(q_a) q_b = (w, v)`, `B = w I + [v]_x` and `A = B^T`, the
    /// Jacobians on world rotation vectors are `J_a = -(1/len) A R_a^T` and
    /// `J_b = (1/len) B R_b^T`, so with body-frame inverse inertias `W_a`,
    /// `W_b`: `J W J^T = (B W_b B^T + A W_a A^T) / len^2`, and the body-frame
    /// rotations are `u_b = W_b A dlambda / len`, `u_a = -W_a B dlambda / len`.
    #[inline]
    fn solve_bend_twist(&mut self, k: usize, last: bool) {
        let len = self.bt_len[k];
        let s = self.bt_inv_len[k];
        let qa = if k == 0 { self.clamp_q } else { self.q[k - 1] };
        let qb = self.q[k];
        // Darboux vector as in `darboux`, without its division.
        let mut r = conj_mul(&qa, &qb);
        if r.w < 0.0 {
            r = -r;
        }
        let (w, v) = (r.w, r.imag());
        let c = v * (2.0 * s) - self.omega0[k];
        // With W = diag(a, a, c) and |r| = 1 (so B B^T = B^T B = I - v v^T):
        // B W B^T = a (I - v v^T) + (c - a) b3 b3^T with b3 = B e3 = (v_y, -v_x, w),
        // A W A^T = a (I - v v^T) + (c - a) a3 a3^T with a3 = A e3 = (-v_y, v_x, w).
        let jc = self.bt_jw[k];
        let (b3, a3) = (Vec3::new(v.y, -v.x, w), Vec3::new(-v.y, v.x, w));
        let sv = v * jc.x;
        let tb = b3 * jc.y;
        let ta = a3 * jc.z;
        let al = self.bt_at[k];
        let kk = [
            jc.x - sv.x * v.x + tb.x * b3.x + ta.x * a3.x + al.x,
            -sv.x * v.y + tb.x * b3.y + ta.x * a3.y,
            -sv.x * v.z + tb.x * b3.z + ta.x * a3.z,
            jc.x - sv.y * v.y + tb.y * b3.y + ta.y * a3.y + al.y,
            -sv.y * v.z + tb.y * b3.z + ta.y * a3.z,
            jc.x - sv.z * v.z + tb.z * b3.z + ta.z * a3.z + al.z,
        ];
        let rhs = -(c + al.component_mul(&self.lambda_bt[k]));
        if last {
            // Dimensionless: rotation angle over the joint.
            self.residual = self.residual.max(rhs.amax() * len);
        }
        let Some(dl) = solve_spd3(kk, &rhs) else { return };
        self.lambda_bt[k] += dl;
        // A dl = w dl - v x dl, B dl = w dl + v x dl.
        let wdl = dl * w;
        let vxdl = v.cross(&dl);
        self.q[k] = rotate_body(&qb, &(self.inv_inertia[k].component_mul(&(wdl - vxdl)) * s));
        if k > 0 {
            let u = self.inv_inertia[k - 1].component_mul(&(wdl + vxdl)) * (-s);
            self.q[k - 1] = rotate_body(&qa, &u);
        }
    }

    /// Linearise every rod constraint at the current state and assemble the
    /// direct solver's system (Deul et al. 2018, sec. 4, eq. 10 with the
    /// XPBD compliance of Macklin et al. 2016, eq. 18):
    /// `(J W J^T + alpha~) dlambda = -(C + alpha~ lambda)` into
    /// `self.band` / `self.dsol`, unknowns ordered `[BT_0, SS_0, BT_1, SS_1,
    /// ...]` (joint `k` between segment `k-1`, or the clamp frame, and `k`).
    ///
    /// Generalised coordinates: the free particles `x_i` (world, inverse
    /// mass `w_i`; `w_0 = 0` at the clamp) and one body-frame rotation
    /// vector `u_j` per segment (`q_j <- q_j (1 + 1/2 (u_j, 0))`, inverse
    /// inertia `W_j = diag(a_j, a_j, c_j)`). The Jacobians are those the
    /// Gauss-Seidel path applies (see [`Self::solve_stretch_shear`] and
    /// [`Self::solve_bend_twist`]):
    ///
    /// * `SS_j` (material frame `R_j`): `-R_j^T / l` on `x_j`, `R_j^T / l`
    ///   on `x_{j+1}`, `E = [e3]_x` on `u_j` (the derivative of `-d3(q_j)`,
    ///   K&S 2016 eq. 31, expressed in the frame `R_j` of the linearisation);
    /// * `BT_k` (`r = conj(q_a) q_b = (w, v)`, `B = w I + [v]_x`):
    ///   `-B^T / len` on `u_{k-1}`, `B / len` on `u_k` (exact).
    ///
    /// Blocks of `J W J^T` (every pair sharing a body):
    /// `SS_j,SS_j = (w_j + w_{j+1}) / l^2 I + E W_j E^T`;
    /// `BT_k,BT_k = (B_k W_k B_k^T + B_k^T W_{k-1} B_k) / len_k^2`;
    /// `SS_k,BT_k = E W_k B_k^T / len_k`;
    /// `BT_k,SS_{k-1} = -B_k^T W_{k-1} E^T / len_k`;
    /// `BT_k,BT_{k-1} = -B_k^T W_{k-1} B_{k-1}^T / (len_k len_{k-1})`;
    /// `SS_k,SS_{k-1} = -w_k R_k^T R_{k-1} / l^2`. Only the lower triangle is
    /// stored. The right-hand side is `-(C + alpha~ lambda)` with the same
    /// constraint values as the Gauss-Seidel path. Sets `self.residual` to
    /// the largest residual (as [`Self::solve_stretch_shear`] /
    /// [`Self::solve_bend_twist`] do) when `last`.
    pub(crate) fn assemble_direct(&mut self, last: bool) {
        let n = self.n;
        if self.dsol.len() != 6 * n {
            self.dsol = vec![0.0; 6 * n];
            self.drot = vec![Mat3::identity(); n];
            self.drel = vec![Quat::identity(); n];
        }
        for j in 0..n {
            self.drot[j] = rotmat(&self.q[j]);
            let qa = if j == 0 { self.clamp_q } else { self.q[j - 1] };
            let mut r = conj_mul(&qa, &self.q[j]);
            if r.w < 0.0 {
                r = -r;
            }
            self.drel[j] = r;
        }
        let e = e3_cross();
        let inv_l = self.inv_l;
        let inv_l2 = inv_l * inv_l;
        let band = &mut self.band;
        band.clear();
        for k in 0..n {
            let s = self.bt_inv_len[k];
            let r = self.drel[k];
            let b = Mat3::identity() * r.w + skew(&r.imag());
            let wk = Mat3::from_diagonal(&self.inv_inertia[k]);
            // BT_k diagonal block.
            let mut kbt = b * wk * b.transpose() * (s * s) + Mat3::from_diagonal(&self.bt_at[k]);
            if k > 0 {
                let wa = Mat3::from_diagonal(&self.inv_inertia[k - 1]);
                kbt += b.transpose() * wa * b * (s * s);
            }
            add_block(band, 2 * k, 2 * k, &kbt);
            // SS_k diagonal block.
            let wx = (self.w[k] + self.w[k + 1]) * inv_l2;
            let kss = Mat3::identity() * wx + e * wk * e.transpose() + Mat3::from_diagonal(&self.ss_at[k]);
            add_block(band, 2 * k + 1, 2 * k + 1, &kss);
            // Off-diagonal blocks (row block > column block: all 9 entries).
            let mut offs: [(usize, usize, Mat3); 4] = [(0, 0, Mat3::zeros()); 4];
            let mut m = 0;
            offs[m] = (2 * k + 1, 2 * k, e * wk * b.transpose() * s);
            m += 1;
            if k > 0 {
                let wa = Mat3::from_diagonal(&self.inv_inertia[k - 1]);
                let rp = self.drel[k - 1];
                let bp = Mat3::identity() * rp.w + skew(&rp.imag());
                let sp = self.bt_inv_len[k - 1];
                offs[m] = (2 * k, 2 * k - 1, -(b.transpose() * wa * e.transpose()) * s);
                offs[m + 1] = (2 * k, 2 * k - 2, -(b.transpose() * wa * bp.transpose()) * (s * sp));
                offs[m + 2] = (
                    2 * k + 1,
                    2 * k - 1,
                    -(self.drot[k].tr_mul(&self.drot[k - 1])) * (self.w[k] * inv_l2),
                );
                m += 3;
            }
            for (bi, bj, blk) in &offs[..m] {
                add_block(band, *bi, *bj, blk);
            }
        }
        for k in 0..n {
            let r = self.drel[k];
            let c = r.imag() * (2.0 * self.bt_inv_len[k]) - self.omega0[k];
            let rbt = -(c + self.bt_at[k].component_mul(&self.lambda_bt[k]));
            let gb = self.drot[k].tr_mul(&((self.x[k + 1] - self.x[k]) * inv_l)) - Vec3::z();
            let rss = -(gb + self.ss_at[k].component_mul(&self.lambda_ss[k]));
            if last {
                self.residual = self.residual.max(rbt.amax() * self.bt_len[k]).max(rss.amax());
            }
            self.dsol[6 * k..6 * k + 3].copy_from_slice(rbt.as_slice());
            self.dsol[6 * k + 3..6 * k + 6].copy_from_slice(rss.as_slice());
        }
    }

    /// One direct iteration ([`RodSolver::Direct`]): assemble
    /// ([`Self::assemble_direct`]), factor and solve by banded Cholesky
    /// (`O(n)`, [`surgbench_core::band`]), then apply `dlambda` to the
    /// multipliers and `W J^T dlambda` to the particles and (body-frame) to
    /// the segment rotations, with the same quaternion update as the
    /// Gauss-Seidel path.
    fn solve_direct(&mut self, last: bool) -> Result<(), String> {
        self.assemble_direct(last);
        self.band.factor(0.0).map_err(|e| {
            format!(
                "direct rod solve: J W J^T + alpha~ is not positive definite at row {} of {}",
                e.row,
                6 * self.n
            )
        })?;
        self.band.solve(&mut self.dsol);
        let n = self.n;
        let inv_l = self.inv_l;
        let dl =
            |k: usize, o: usize| Vec3::new(self.dsol[6 * k + o], self.dsol[6 * k + o + 1], self.dsol[6 * k + o + 2]);
        for k in 0..n {
            self.lambda_bt[k] += dl(k, 0);
            self.lambda_ss[k] += dl(k, 3);
        }
        // Particles: dx_i = w_i (R_{i-1} dl_ss_{i-1} - R_i dl_ss_i) / l.
        for i in 1..=n {
            let mut f = self.drot[i - 1] * dl(i - 1, 3);
            if i < n {
                f -= self.drot[i] * dl(i, 3);
            }
            self.x[i] += f * (self.w[i] * inv_l);
        }
        // Segments: u_j = W_j (E^T dl_ss_j + B_j^T dl_bt_j / len_j
        // - B_{j+1} dl_bt_{j+1} / len_{j+1}); E^T d = (d_y, -d_x, 0),
        // B^T d = w d - v x d, B d = w d + v x d.
        for j in 0..n {
            let ds = dl(j, 3);
            let mut g = Vec3::new(ds.y, -ds.x, 0.0);
            let (r, db) = (self.drel[j], dl(j, 0));
            g += (db * r.w - r.imag().cross(&db)) * self.bt_inv_len[j];
            if j + 1 < n {
                let (r, db) = (self.drel[j + 1], dl(j + 1, 0));
                g -= (db * r.w + r.imag().cross(&db)) * self.bt_inv_len[j + 1];
            }
            self.q[j] = rotate_body(&self.q[j], &self.inv_inertia[j].component_mul(&g));
        }
        Ok(())
    }

    /// Contact plane constraints with position-level Coulomb friction
    /// (Macklin et al. 2014, sec. 6.1, eqs. 24-25).
    /// One projection of every live contact, with Coulomb friction; a
    /// candidate that may have reached the wall since its last query (the
    /// Lipschitz bound of [`Self::detect_contacts`]) is queried again at its
    /// current position and goes live there if it has.
    fn solve_contacts(&mut self) {
        for c in &mut self.contacts {
            let i = c.i;
            if !c.live {
                let Some(sdf) = &self.vessel else { continue };
                let xi = self.x[i];
                let (xc, phic) = self.sdf_cache[i];
                if phic + SDF_LIPSCHITZ_BOUND * (xi - xc).norm() + self.margin < 0.0 {
                    continue;
                }
                let (phi, g) = sdf.distance_gradient(&xi);
                self.sdf_cache[i] = (xi, phi);
                c.x_ref = xi;
                if !c.linearise(phi + self.margin, &g) {
                    continue;
                }
            }
            let d = c.d0 + c.normal.dot(&(self.x[i] - c.x_ref));
            if d <= 0.0 {
                continue;
            }
            let mut dx = -c.normal * d;
            let moved = self.x[i] + dx - self.x_prev[i] - c.wall_dx;
            let dt_ = moved - c.normal * c.normal.dot(&moved);
            let s = dt_.norm();
            if s > 0.0 {
                if s < self.mu_s * d {
                    dx -= dt_;
                } else {
                    dx -= dt_ * (self.mu_k * d / s).min(1.0);
                }
            }
            self.x[i] += dx;
            c.dx += dx;
        }
        self.projections += self.contacts.len() as u64;
    }

    /// One substep: predict, then `iterations` constraint solves (each
    /// followed by one contact projection), then velocities and the
    /// reaction at the clamp. Fails only if the direct solver's matrix is
    /// not positive definite (reason in the error).
    fn substep(&mut self, h: f64, clamp: (Vec3, Quat)) -> Result<(), String> {
        let old_clamp = self.clamp_pos;
        self.clamp_pos = clamp.0;
        self.clamp_q = clamp.1;
        self.last_h = h;
        self.predict(h);
        self.x_prev[0] = self.x[0];
        self.x[0] = self.clamp_pos;
        self.v[0] = (self.clamp_pos - old_clamp) / h;
        self.detect_contacts();
        self.refresh_caches(h);
        self.lambda_ss.fill(Vec3::zeros());
        self.lambda_bt.fill(Vec3::zeros());
        let h2 = h * h;
        let iters = self.set.iterations;
        for it in 0..iters {
            let last = it + 1 == iters;
            if last {
                self.residual = 0.0;
            }
            match self.set.solver {
                RodSolver::GaussSeidel => {
                    self.solve_bend_twist(0, last);
                    for j in 0..self.n {
                        self.solve_stretch_shear(j, last);
                        if j + 1 < self.n {
                            self.solve_bend_twist(j + 1, last);
                        }
                    }
                }
                RodSolver::Direct => self.solve_direct(last)?,
            }
            self.projections += 2 * self.n as u64;
            if !self.contacts.is_empty() {
                self.solve_contacts();
            }
        }
        for i in 1..=self.n {
            self.v[i] = (self.x[i] - self.x_prev[i]) / h;
        }
        for j in 0..self.n {
            let mut dq = self.q[j] * self.q_prev[j].conjugate();
            if dq.w < 0.0 {
                dq = -dq;
            }
            self.omega[j] = dq.imag() * (2.0 / h);
        }
        // Reaction on the clamp: constraint forces J^T lambda / h^2 on the
        // clamped particle (stretch-shear 0) and clamp frame (joint 0), plus the
        // weight of the clamped particle's half segment.
        let r0 = rotmat(&self.q[0]);
        self.hand_force = -(r0 * self.lambda_ss[0]) / (self.l * h2) + self.gravity * self.mass[0];
        let (_, w, v) = darboux(&self.clamp_q, &self.q[0], self.bt_len[0]);
        let rc = rotmat(&self.clamp_q);
        let a_blk_t = Mat3::identity() * w + skew(&v); // (wI - [v])^T
        self.hand_torque = -(rc * (a_blk_t * self.lambda_bt[0])) / (self.bt_len[0] * h2);
        Ok(())
    }

    fn diverged(&self) -> Option<String> {
        let lim = 4.0 * self.l * self.n as f64;
        for (i, p) in self.x.iter().enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Some(format!("particle {i} is not finite"));
            }
            if (p - self.clamp_pos).norm() > lim {
                return Some(format!(
                    "particle {i} is {:.3e} m from the clamp, rod length {:.3e} m",
                    (p - self.clamp_pos).norm(),
                    self.l * self.n as f64
                ));
            }
        }
        if !self.q.iter().all(|q| q.coords.iter().all(|c| c.is_finite())) {
            return Some("orientation is not finite".into());
        }
        None
    }

    /// Energies of the current state. The elastic part is the Cosserat strain
    /// energy of the module docs, which is exactly the XPBD compliance
    /// potential `1/2 C^T alpha^-1 C` of the constraints as solved
    /// (`C = Gamma`, `alpha_ss = 1/(l K_ss)`; `C = Omega - Omega0`,
    /// `alpha_bt = 1/(len K_bt)`): consistent, not an approximation. When the
    /// Gauss-Seidel solve is under-iterated the constraints stay violated and
    /// this energy counts the violation at full material stiffness; that is
    /// the real state, not an accounting error. Measured on a 0.5 m,
    /// 0.2 mm-radius nitinol wire falling from horizontal (100 segments,
    /// dt = 1 ms, no damping): after 0.4 s the largest shear strain is 1.7 at
    /// 2 iterations, 0.52 at 10, 0.18 at 200, 0.075 at 10 iterations x 10
    /// substeps, and the elastic energy 170 J, 2.8 J, 0.93 J, 0.29 J against
    /// ~1e-3 J of work done by gravity: the chain's Gauss-Seidel converges
    /// slowly (stiff stretch-shear against light segments), and energy
    /// watchdogs rightly trip on such runs. Substeps help more than
    /// iterations (Macklin et al. 2019, "Small Steps in Physics Simulation").
    fn energy(&self) -> EnergyObs {
        let mut e = EnergyObs::default();
        for i in 1..=self.n {
            e.kinetic += 0.5 * self.mass[i] * self.v[i].norm_squared();
            e.external -= self.mass[i] * self.gravity.dot(&self.x[i]);
        }
        // Dead-load potential -s(t) F . x_tip with the absolute tip position
        // (the harness adds the work of the load change, -int s' F . x_tip dt).
        e.external -= self.tip_scale(self.time) * self.tip_force.dot(&self.x[self.n]);
        for j in 0..self.n {
            let r = rotmat(&self.q[j]);
            let wb = r.transpose() * self.omega[j];
            let [it, ia] = self.inertia[j];
            e.kinetic += 0.5 * (it * (wb.x * wb.x + wb.y * wb.y) + ia * wb.z * wb.z);
            let gb = r.transpose() * ((self.x[j + 1] - self.x[j]) / self.l) - Vec3::z();
            e.elastic += 0.5 * self.l * gb.dot(&self.ss_k[j].component_mul(&gb));
            let qa = if j == 0 { self.clamp_q } else { self.q[j - 1] };
            let (om, _, _) = darboux(&qa, &self.q[j], self.bt_len[j]);
            let c = om - self.omega0[j];
            e.elastic += 0.5 * self.bt_len[j] * c.dot(&self.bt_k[j].component_mul(&c));
        }
        e
    }
}

impl Model for PbdRod {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(SimError::SolverFailed {
                t: self.time,
                reason: format!("time step must be > 0 s, got {dt}"),
            });
        }
        let ns = self.set.substeps;
        let h = dt / ns as f64;
        let a = self.last_cmd;
        for s in 0..ns {
            // Loads at the end of the substep, like the clamp command.
            self.load_scale = self.tip_scale(self.time + (s + 1) as f64 * h);
            let f = (s + 1) as f64 / ns as f64;
            let ins = a.insertion + f * (cmd.insertion - a.insertion);
            let rot = a.rotation + f * (cmd.rotation - a.rotation);
            let pose = self.clamp_pose(ins, rot, cmd.base_pose);
            if let Some(env) = &self.moving {
                let (t0, t1) = (self.time + s as f64 * h, self.time + (s + 1) as f64 * h);
                self.vessel = env.vessel_at(t1);
                self.flow = env.flow_at(t1);
                self.wall_t = (t0, t1);
            }
            self.substep(h, pose).map_err(|reason| SimError::SolverFailed {
                t: self.time + (s + 1) as f64 * h,
                reason,
            })?;
        }
        self.last_cmd = *cmd;
        self.time += dt;
        if let Some(reason) = self.diverged() {
            return Err(SimError::Diverged { t: self.time, reason });
        }
        Ok(StepStats {
            iterations: (self.set.iterations * ns) as u32,
            residual: self.residual,
            converged: self.residual <= 1e-6,
        })
    }

    fn observe(&self) -> Observation {
        let frames: Vec<Mat3> = self.q.iter().map(rotmat).collect();
        let mut max_stretch: f64 = 0.0;
        for j in 0..self.n {
            let s = (self.x[j + 1] - self.x[j]).norm() / self.l - 1.0;
            if s.abs() > max_stretch.abs() {
                max_stretch = s;
            }
        }
        let h = self.last_h;
        let contacts = self
            .contacts
            .iter()
            .filter(|c| c.dx != Vec3::zeros())
            .map(|c| {
                let pen = self
                    .vessel
                    .as_ref()
                    .map(|s| s.distance(&self.x[c.i]) + self.margin)
                    .unwrap_or(0.0)
                    .max(0.0);
                ContactObs {
                    point: self.x[c.i],
                    force: c.dx * (self.mass[c.i] / (h * h)),
                    penetration: pen,
                }
            })
            .collect();
        Observation {
            time: self.time,
            rods: vec![RodObs {
                arclength: self.arclength.clone(),
                rest: self.rest.clone(),
                nodes: self.x.clone(),
                velocities: self.v.clone(),
                frames,
                max_stretch,
            }],
            tissues: Vec::new(),
            contacts,
            hand_force: self.hand_force,
            hand_torque: self.hand_torque,
            energy: self.energy(),
            constraint_residual: Some(self.residual),
        }
    }

    fn dt(&self) -> f64 {
        self.set.dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        fid.extras.insert("substeps".into(), 1.0);
        fid.extras.insert("solver".into(), 1.0);
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
