//! Building a [`DerRod`] from a scene body: discretization, rest state and masses.

use super::*;
use crate::band::BandMatrix;
use crate::energy::{self, VertexParams, VertexTerms};
use surgbench_core::contact::LaggedFriction;
use surgbench_core::frames::rotate_about;
use surgbench_core::{BuildError, ContactParams, DeviceCommand, RodBody, Vec3};

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
}
