//! Building a [`PbdRod`] for a scene at a fidelity.

use super::*;
use surgbench_core::band::BandMatrix;
use surgbench_core::{BuildError, DeviceCommand, Fidelity, RodBody, RodVelocity, Scene, Settings, Vec3};

impl PbdRod {
    /// Build the rod of `scene` (exactly one rod) at `fidelity`, resolved
    /// by [`surgbench_core::resolve`].
    pub fn new(scene: &Scene, fidelity: &Fidelity) -> Result<Self, BuildError> {
        Self::with_settings(scene, &surgbench_core::resolve(&PbdRodFactory, scene, fidelity)?)
    }

    /// Build the rod of `scene` from settings resolved for it.
    pub fn with_settings(scene: &Scene, settings: &Settings) -> Result<Self, BuildError> {
        let set = RodSettings::from_settings(settings)?;
        let rod: &RodBody = scene.rods().next().expect("checked: one rod");
        let n = set.segments;
        let g = RestRod::new(rod, n);
        let l = g.l;
        let c = scene.environment.contact;
        let mut rod_model = Self {
            set,
            n,
            l,
            inv_l: 1.0 / l,
            v: vec![Vec3::zeros(); n + 1],
            x_prev: g.x.clone(),
            rest: g.x.clone(),
            arclength: (0..=n).map(|i| i as f64 * l).collect(),
            x: g.x,
            mass: g.mass,
            w: g.w,
            radius_node: g.radius_node,
            q_prev: g.q.clone(),
            q: g.q,
            omega: vec![Vec3::zeros(); n],
            inv_inertia: g.inv_inertia,
            inertia: g.inertia,
            ss_alpha: g.ss_alpha,
            ss_k: g.ss_k,
            bt_alpha: g.bt_alpha,
            bt_k: g.bt_k,
            bt_len: g.bt_len,
            omega0: g.omega0,
            lambda_ss: vec![Vec3::zeros(); n],
            lambda_bt: vec![Vec3::zeros(); n],
            base: rod.base,
            clamp_pos: g.clamp_pos,
            clamp_q: g.clamp_q,
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
            bt_jw: g.bt_jw,
            bt_inv_len: g.bt_inv_len,
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
        };
        if let Some(field) = &rod.initial_velocity {
            rod_model.set_initial_velocity(field);
        }
        Ok(rod_model)
    }

    /// Start the rod moving with `field` (`RodBody::initial_velocity`): the
    /// free particles take its velocity at their arclength, each segment its
    /// angular velocity at the segment's midpoint (the section rotation of a
    /// bending mode, so that the stretch-shear constraints start satisfied
    /// to first order); the clamped particle stays at rest.
    pub fn set_initial_velocity(&mut self, field: &RodVelocity) {
        for i in 1..=self.n {
            self.v[i] = field.at(self.arclength[i]).0;
        }
        for j in 0..self.n {
            self.omega[j] = field.at((j as f64 + 0.5) * self.l).1;
        }
    }
}

/// Per-segment properties from the section at each segment's midpoint.
struct Sections {
    mass: Vec<f64>,
    /// Transverse and axial moments of inertia (kg m^2).
    inertia: Vec<[f64; 2]>,
    /// Shear-stretch stiffnesses `(G A, G A, E A)` (N).
    ss_k: Vec<Vec3>,
    /// Bend-twist stiffnesses `(E I, E I, G J)` (N m^2).
    bt: Vec<Vec3>,
    /// Rest curvature (1/m).
    kappa: Vec<Vec3>,
    radius: Vec<f64>,
}

impl Sections {
    /// The properties of `n` segments of length `l` along `rod`.
    fn new(rod: &RodBody, n: usize, l: f64) -> Self {
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
        Self {
            mass: seg_mass,
            inertia,
            ss_k,
            bt: seg_bt,
            kappa: seg_kappa,
            radius: seg_r,
        }
    }
}

/// The bend-twist joints: stiffness, length, rest Darboux vector and rest
/// relative rotation of each. Joint 0: clamp frame -> segment 0 over l/2;
/// joint j: segment j-1 -> j over l.
struct Joints {
    k: Vec<Vec3>,
    len: Vec<f64>,
    omega0: Vec<Vec3>,
    rel: Vec<Quat>,
}

impl Joints {
    /// The joints between the segments of `sec` (length `l`).
    fn new(sec: &Sections, l: f64) -> Self {
        let (seg_bt, seg_kappa) = (&sec.bt, &sec.kappa);
        let n = seg_bt.len();
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
        Self {
            k: bt_k,
            len: bt_len,
            omega0,
            rel,
        }
    }
}

/// Everything about the rod at rest that the solver keeps: the rest pose
/// from the clamp, masses, inertias and the constraint compliances.
struct RestRod {
    l: f64,
    x: Vec<Vec3>,
    q: Vec<Quat>,
    clamp_pos: Vec3,
    clamp_q: Quat,
    mass: Vec<f64>,
    w: Vec<f64>,
    radius_node: Vec<f64>,
    inertia: Vec<[f64; 2]>,
    inv_inertia: Vec<Vec3>,
    ss_alpha: Vec<Vec3>,
    ss_k: Vec<Vec3>,
    bt_alpha: Vec<Vec3>,
    bt_k: Vec<Vec3>,
    bt_len: Vec<f64>,
    omega0: Vec<Vec3>,
    bt_jw: Vec<Vec3>,
    bt_inv_len: Vec<f64>,
}

impl RestRod {
    /// The rest state of `rod` cut into `n` segments.
    fn new(rod: &RodBody, n: usize) -> Self {
        let l = rod.length / n as f64;
        let sec = Sections::new(rod, n, l);
        let ss_alpha: Vec<Vec3> = sec.ss_k.iter().map(|k| k.map(|c| 1.0 / (l * c))).collect();
        let joints = Joints::new(&sec, l);
        let bt_alpha: Vec<Vec3> = joints
            .k
            .iter()
            .zip(&joints.len)
            .map(|(k, len)| k.map(|c| 1.0 / (len * c)))
            .collect();
        let clamp_q = material_of_base(&rod.base.rotation);
        let clamp_pos = rod.base.translation.vector;
        let (q, x) = rest_pose(clamp_q, clamp_pos, &joints.rel, l);
        let (mass, radius_node) = lumped_nodes(&sec);
        let mut w: Vec<f64> = mass.iter().map(|m| 1.0 / m).collect();
        w[0] = 0.0;
        let inv_inertia: Vec<Vec3> = sec
            .inertia
            .iter()
            .map(|&[it, ia]| Vec3::new(1.0 / it, 1.0 / it, 1.0 / ia))
            .collect();
        let bt_jw = bend_twist_weights(&inv_inertia, &joints.len);
        let bt_inv_len = joints.len.iter().map(|l| 1.0 / l).collect();
        Self {
            l,
            x,
            q,
            clamp_pos,
            clamp_q,
            mass,
            w,
            radius_node,
            inertia: sec.inertia,
            inv_inertia,
            ss_alpha,
            ss_k: sec.ss_k,
            bt_alpha,
            bt_k: joints.k,
            bt_len: joints.len,
            omega0: joints.omega0,
            bt_jw,
            bt_inv_len,
        }
    }
}

/// Segment frames and node positions of the rest pose, chaining the joints'
/// rest rotations `rel` from the clamp.
fn rest_pose(clamp_q: Quat, clamp_pos: Vec3, rel: &[Quat], l: f64) -> (Vec<Quat>, Vec<Vec3>) {
    let n = rel.len();
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
    (q, x)
}

/// Node masses (half of each neighbouring segment) and node radii (the larger neighbour's).
fn lumped_nodes(sec: &Sections) -> (Vec<f64>, Vec<f64>) {
    let n = sec.mass.len();
    let mut mass = vec![0.0; n + 1];
    let mut radius_node = vec![0.0f64; n + 1];
    for j in 0..n {
        mass[j] += 0.5 * sec.mass[j];
        mass[j + 1] += 0.5 * sec.mass[j];
        radius_node[j] = radius_node[j].max(sec.radius[j]);
        radius_node[j + 1] = radius_node[j + 1].max(sec.radius[j]);
    }
    (mass, radius_node)
}

/// The inverse-inertia weights of each bend-twist joint over its length squared.
fn bend_twist_weights(inv_inertia: &[Vec3], bt_len: &[f64]) -> Vec<Vec3> {
    (0..bt_len.len())
        .map(|k| {
            let wb = inv_inertia[k];
            let wa = if k == 0 { Vec3::zeros() } else { inv_inertia[k - 1] };
            Vec3::new(wa.x + wb.x, wb.z - wb.x, wa.z - wa.x) / (bt_len[k] * bt_len[k])
        })
        .collect()
}
