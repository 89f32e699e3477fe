//! [`FemModel`] behind the harness contract: the [`Model`] steps and
//! observations, surface forces for coupled runs, state save/restore, and
//! the [`EnergyProbe`] the conformance suite checks forces against.

use super::*;
use surgbench_core::coupling::store_surface_forces;

impl Model for FemModel {
    fn step(&mut self, dt: f64, cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.advance(dt, cmd.load)
    }

    /// Tissue nodes, volume error, inverted count, energies, and
    /// `hand_force`: the force the tissue exerts on whatever drives the
    /// driven nodes (N), i.e. minus the total driving force.
    fn observe(&self) -> Observation {
        Observation {
            time: self.t,
            tissues: vec![TissueObs {
                rest: self.solid.rest.iter().map(|p| p + self.origin).collect(),
                nodes: self.positions(),
                velocities: self.v.clone(),
                volume_error: self.solid.volume_error(&self.x),
                inverted: self.inverted,
                rest_dihedral_deg: None,
            }],
            hand_force: self.hand_force,
            energy: self.energies(),
            ..Default::default()
        }
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    /// Quasi-static runs: the load increments the adaptive load stepping
    /// solved (`load_increments`) and the Newton solves it retried with
    /// half the increment (`load_increment_failures`), and the Cholesky
    /// factorizations of the accepted increments (`factorizations`), over
    /// the whole run; nothing for the dynamic integrators.
    fn diagnostics(&self) -> std::collections::BTreeMap<String, f64> {
        let mut d = std::collections::BTreeMap::new();
        if self.p.integrator == Integrator::QuasiStatic {
            d.insert("load_increments".into(), self.statics.increments as f64);
            d.insert("load_increment_failures".into(), self.statics.failures as f64);
            d.insert("factorizations".into(), self.statics.factorizations as f64);
        }
        d
    }

    fn energy_probe(&mut self) -> Option<&mut dyn EnergyProbe> {
        Some(self)
    }

    fn surface_positions(&self) -> Option<Vec<Vec3>> {
        (!self.surface.is_empty()).then(|| self.surface.iter().map(|&i| self.x[i] + self.origin).collect())
    }

    /// Dead forces on the contact-surface nodes (a free node's residual
    /// gains them; a constrained node's are carried by its support).
    fn set_surface_forces(&mut self, forces: &[Vec3]) -> Result<(), SimError> {
        store_surface_forces(&self.surface, forces, &mut self.external).map_err(|e| self.fail(e))
    }

    /// Time, positions, velocities, accelerations and what the last step
    /// reported; the cached factor and lazy Jacobians stay (they are
    /// re-validated by the next step as usual).
    fn save_state(&self) -> Option<Box<dyn Any + Send>> {
        Some(Box::new(FemState {
            t: self.t,
            x: self.x.clone(),
            v: self.v.clone(),
            a: self.a.clone(),
            s_last: self.s_last,
            hand_force: self.hand_force,
            inverted: self.inverted,
            external: self.external.clone(),
            solved_for: self.solved_for.clone(),
        }))
    }

    fn restore_state(&mut self, state: &(dyn Any + Send)) -> Result<(), SimError> {
        let s = state
            .downcast_ref::<FemState>()
            .ok_or_else(|| self.fail("not a saved FEM state"))?;
        self.t = s.t;
        self.x.clone_from(&s.x);
        self.v.clone_from(&s.v);
        self.a.clone_from(&s.a);
        self.s_last = s.s_last;
        self.hand_force = s.hand_force;
        self.inverted = s.inverted;
        self.external.clone_from(&s.external);
        self.solved_for.clone_from(&s.solved_for);
        Ok(())
    }
}

/// What [`Model::save_state`] keeps of a [`FemModel`].
struct FemState {
    t: f64,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    a: Vec<Vec3>,
    s_last: f64,
    hand_force: Vec3,
    inverted: usize,
    external: Vec<Vec3>,
    solved_for: Option<(f64, Vec<Vec3>, f64)>,
}

impl EnergyProbe for FemModel {
    fn coords(&self) -> Vec<f64> {
        self.positions().iter().flat_map(|p| [p.x, p.y, p.z]).collect()
    }
    fn set_coords(&mut self, q: &[f64]) {
        let o = self.origin;
        for (i, p) in self.x.iter_mut().enumerate() {
            if 3 * i + 2 < q.len() {
                *p = Vec3::new(q[3 * i], q[3 * i + 1], q[3 * i + 2]) - o;
            }
        }
    }
    /// Elastic energy, the sphere contact's penalty energy (sphere where the
    /// last step left it) and the potential of gravity (J). Pressure faces
    /// are follower (non-conservative) loads and are in neither this nor
    /// [`EnergyProbe::forces`].
    fn potential(&self) -> f64 {
        let e = self.energies();
        e.elastic + e.external
    }
    fn forces(&self) -> Vec<f64> {
        let (_, f) = self.solid.energy_forces(&self.x);
        let mut out: Vec<f64> = f
            .iter()
            .zip(&self.gravity_load)
            .flat_map(|(a, g)| [a.x + g.x, a.y + g.y, a.z + g.z])
            .collect();
        if let Some((_, c)) = &self.contact {
            c.add_forces(&self.x, &mut out);
        }
        out
    }
    fn free(&self) -> Vec<usize> {
        (0..self.sys.free.len()).filter(|&d| self.sys.free[d]).collect()
    }
}
