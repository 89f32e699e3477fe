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
use surgbench_core::scene::FlowField;
use surgbench_core::{
    BuildError, Capability, ContactObs, DeviceCommand, EnergyObs, Family, Fidelity, FidelityKey, Iso3, Mat3, Model,
    ModelFactory, Observation, RodBody, RodObs, Scene, Sdf, SimError, StepStats, Unsupported, Vec3,
};

type Quat = Quaternion<f64>;

/// Blood density used for flow drag (kg/m^3).
pub const BLOOD_DENSITY: f64 = 1060.0;
/// Drag coefficient of a cylinder in cross flow used for flow drag
/// (order-one value for Reynolds numbers 10..1e4; Hoerner, "Fluid-Dynamic
/// Drag", 1965, ch. 3). An approximation, stated as such.
pub const CYLINDER_DRAG_COEFFICIENT: f64 = 1.2;

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
];

/// Factory for the Cosserat-PBD rod (`pbd-rod`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PbdRodFactory;

const ROD_CAPS: &[Capability] = &[
    Capability::Rod,
    Capability::Twist,
    Capability::TipForce,
    Capability::VaryingProperties,
    Capability::RestCurvature,
    Capability::Insertion,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
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
        // Static scenes are run to equilibrium with the model's own damping:
        // critical damping of the first cantilever bending mode,
        // c = 2 omega_1, omega_1 = 1.875^2 sqrt(E I / (rho A L^4)).
        if scene.settle.is_some()
            && let Some(rod) = scene.rods().next()
        {
            let s = &rod.sections[0];
            let w1 = 1.875f64.powi(2)
                * (s.youngs_modulus * s.second_moment() / (s.density * s.area() * rod.length.powi(4))).sqrt();
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
        Ok(Self {
            segments,
            dt,
            iterations,
            substeps: substeps as usize,
            damping,
        })
    }
}

/// A vessel-wall contact of one particle, linearised at the start of a substep
/// (plane constraint of Macklin et al. 2014, "Unified Particle Physics for
/// Real-Time Applications", sec. 5-6).
#[derive(Debug, Clone, Copy)]
struct Contact {
    i: usize,
    normal: Vec3,
    /// Signed gap function at `x_ref`: `phi + r + margin` (> 0 = violating).
    d0: f64,
    x_ref: Vec3,
    /// Accumulated correction this substep (m).
    dx: Vec3,
}

/// The Cosserat-PBD rod model. Build it through [`PbdRodFactory`] or
/// [`PbdRod::new`].
#[derive(Debug, Clone)]
pub struct PbdRod {
    set: RodSettings,
    n: usize,
    l: f64,
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
    tip_force: Vec3,
    tip_torque: Vec3,
    vessel: Option<Arc<dyn Sdf>>,
    flow: Option<Arc<dyn FlowField>>,
    mu_s: f64,
    mu_k: f64,
    margin: f64,
    contacts: Vec<Contact>,
    time: f64,
    last_cmd: DeviceCommand,
    hand_force: Vec3,
    hand_torque: Vec3,
    residual: f64,
    projections: u64,
    last_h: f64,
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
/// local `(y, z)`.
fn material_of_base(rot: &UnitQuaternion<f64>) -> Quat {
    let m = Matrix3::from_columns(&[Vec3::y(), Vec3::z(), Vec3::x()]);
    let q0 = UnitQuaternion::from_matrix(&m);
    (rot * q0).into_inner()
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
    let mut r = qa.conjugate() * qb;
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
        let c = scene.environment.contact;
        Ok(Self {
            set,
            n,
            l,
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
            vessel: scene.environment.vessel.clone(),
            flow: scene.environment.flow.clone(),
            mu_s: c.friction_static,
            mu_k: c.friction_dynamic,
            margin: c.margin,
            contacts: Vec::new(),
            time: 0.0,
            last_cmd: DeviceCommand::default(),
            hand_force: Vec3::zeros(),
            hand_torque: Vec3::zeros(),
            residual: 0.0,
            projections: 0,
            last_h: set.dt / set.substeps as f64,
        })
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
                f += self.tip_force;
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
                let c =
                    0.5 * BLOOD_DENSITY * CYLINDER_DRAG_COEFFICIENT * 2.0 * self.radius_node[i] * share * rel_n.norm();
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
                tau += r.transpose() * self.tip_torque;
            }
            wb += tau.component_div(&ib) * h;
            self.omega[j] = r * wb;
            self.q_prev[j] = self.q[j];
            let dq = Quat::from_imag(self.omega[j] * (0.5 * h)) * self.q[j];
            self.q[j] = (self.q[j] + dq).normalize();
        }
    }

    fn detect_contacts(&mut self) {
        self.contacts.clear();
        let Some(sdf) = &self.vessel else { return };
        for i in 1..=self.n {
            let xi = self.x[i];
            let r = self.radius_node[i];
            let d0 = sdf.distance(&xi) + r + self.margin;
            let band = 2.0 * (xi - self.x_prev[i]).norm() + r;
            if d0 > -band {
                let g = sdf.gradient(&xi);
                let gn = g.norm();
                if gn > 0.0 {
                    self.contacts.push(Contact {
                        i,
                        normal: g / gn,
                        d0,
                        x_ref: xi,
                        dx: Vec3::zeros(),
                    });
                }
            }
        }
    }

    /// Stretch-shear constraint of segment `j` (XPBD, exact block, solved in
    /// the material frame where `J W J^T` is diagonal).
    fn solve_stretch_shear(&mut self, j: usize, h2: f64, last: bool) {
        let l = self.l;
        let r = rotmat(&self.q[j]);
        let d3 = r.column(2).into_owned();
        let gamma = (self.x[j + 1] - self.x[j]) / l - d3;
        let gb = r.transpose() * gamma;
        let (w0, w1) = (self.w[j], self.w[j + 1]);
        let wx = (w0 + w1) / (l * l);
        let a = 1.0 / self.inertia[j][0];
        let al = self.ss_alpha[j] / h2;
        let lam = self.lambda_ss[j];
        let kdiag = Vec3::new(wx + a, wx + a, wx);
        let rhs = -(gb + al.component_mul(&lam));
        if last {
            self.residual = self.residual.max(rhs.amax());
        }
        let dl = rhs.component_div(&(kdiag + al));
        self.lambda_ss[j] += dl;
        let dw = r * dl;
        self.x[j] -= dw * (w0 / l);
        self.x[j + 1] += dw * (w1 / l);
        let d1 = r.column(0).into_owned();
        let d2 = r.column(1).into_owned();
        let dth = (d1 * dl.y - d2 * dl.x) * a;
        let qj = self.q[j];
        self.q[j] = (qj + Quat::from_imag(dth * 0.5) * qj).normalize();
    }

    /// Bend-twist constraint of joint `k` between segment `k-1` (or the clamp
    /// frame for `k = 0`) and segment `k` (XPBD, exact 3x3 block).
    fn solve_bend_twist(&mut self, k: usize, h2: f64, last: bool) {
        let len = self.bt_len[k];
        let qa = if k == 0 { self.clamp_q } else { self.q[k - 1] };
        let qb = self.q[k];
        let (om, w, v) = darboux(&qa, &qb, len);
        let c = om - self.omega0[k];
        let sv = skew(&v);
        let a_blk = Mat3::identity() * w - sv; // J_a = -(1/len) A R_a^T
        let b_blk = Mat3::identity() * w + sv; // J_b = (1/len) B R_b^T
        let wb = {
            let [it, ia] = self.inertia[k];
            Vec3::new(1.0 / it, 1.0 / it, 1.0 / ia)
        };
        let mut kmat = b_blk * Mat3::from_diagonal(&wb) * b_blk.transpose();
        let wa = if k == 0 {
            None
        } else {
            let [it, ia] = self.inertia[k - 1];
            let wa = Vec3::new(1.0 / it, 1.0 / it, 1.0 / ia);
            kmat += a_blk * Mat3::from_diagonal(&wa) * a_blk.transpose();
            Some(wa)
        };
        kmat /= len * len;
        let al = self.bt_alpha[k] / h2;
        kmat += Mat3::from_diagonal(&al);
        let rhs = -(c + al.component_mul(&self.lambda_bt[k]));
        if last {
            // Dimensionless: rotation angle over the joint.
            self.residual = self.residual.max(rhs.amax() * len);
        }
        let Some(chol) = kmat.cholesky() else { return };
        let dl = chol.solve(&rhs);
        self.lambda_bt[k] += dl;
        let rb = rotmat(&qb);
        let dth_b = rb * wb.component_mul(&(b_blk.transpose() * dl)) / len;
        self.q[k] = (qb + Quat::from_imag(dth_b * 0.5) * qb).normalize();
        if let Some(wa) = wa {
            let ra = rotmat(&qa);
            let dth_a = -(ra * wa.component_mul(&(a_blk.transpose() * dl))) / len;
            self.q[k - 1] = (qa + Quat::from_imag(dth_a * 0.5) * qa).normalize();
        }
    }

    /// Contact plane constraints with position-level Coulomb friction
    /// (Macklin et al. 2014, sec. 6.1, eqs. 24-25).
    fn solve_contacts(&mut self) {
        for c in &mut self.contacts {
            let i = c.i;
            let d = c.d0 + c.normal.dot(&(self.x[i] - c.x_ref));
            if d <= 0.0 {
                continue;
            }
            let mut dx = -c.normal * d;
            let moved = self.x[i] + dx - self.x_prev[i];
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

    fn substep(&mut self, h: f64, clamp: (Vec3, Quat)) {
        let old_clamp = self.clamp_pos;
        self.clamp_pos = clamp.0;
        self.clamp_q = clamp.1;
        self.last_h = h;
        self.predict(h);
        self.x_prev[0] = self.x[0];
        self.x[0] = self.clamp_pos;
        self.v[0] = (self.clamp_pos - old_clamp) / h;
        self.detect_contacts();
        for l in &mut self.lambda_ss {
            *l = Vec3::zeros();
        }
        for l in &mut self.lambda_bt {
            *l = Vec3::zeros();
        }
        let h2 = h * h;
        let iters = self.set.iterations;
        for it in 0..iters {
            let last = it + 1 == iters;
            if last {
                self.residual = 0.0;
            }
            self.solve_bend_twist(0, h2, last);
            for j in 0..self.n {
                self.solve_stretch_shear(j, h2, last);
                if j + 1 < self.n {
                    self.solve_bend_twist(j + 1, h2, last);
                }
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

    fn energy(&self) -> EnergyObs {
        let mut e = EnergyObs::default();
        for i in 1..=self.n {
            e.kinetic += 0.5 * self.mass[i] * self.v[i].norm_squared();
            e.external -= self.mass[i] * self.gravity.dot(&self.x[i]);
        }
        e.external -= self.tip_force.dot(&self.x[self.n]);
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
            let f = (s + 1) as f64 / ns as f64;
            let ins = a.insertion + f * (cmd.insertion - a.insertion);
            let rot = a.rotation + f * (cmd.rotation - a.rotation);
            let pose = self.clamp_pose(ins, rot, cmd.base_pose);
            self.substep(h, pose);
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
                    .map(|s| s.distance(&self.x[c.i]) + self.radius_node[c.i])
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
