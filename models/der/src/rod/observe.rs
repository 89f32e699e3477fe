//! What the rod reports: hand wrench, energies, centreline observation
//! and the conformance energy probe.

use super::*;
use surgbench_core::{EnergyObs, EnergyProbe, RodObs, Vec3};

impl DerRod {
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
