//! Building a [`PbdRod`] for a scene at a fidelity.

use super::*;
use surgbench_core::band::BandMatrix;
use surgbench_core::{BuildError, DeviceCommand, Fidelity, RodBody, Scene, Settings, Vec3};

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
}
