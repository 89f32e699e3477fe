use surgbench_core::{
    BuildError, Capability, DeviceCommand, Family, Fidelity, Mat3, Model, ModelFactory, Observation, RodBody, RodObs,
    Scene, Settings, SimError, StepStats, Vec3,
};

/// `rigid-rod`: the infinitely stiff limit of a clamped rod. It never
/// deforms, so its tip error on a cantilever is the whole deflection; its
/// hand force (the load it passes to the clamp) is exact.
pub struct RigidRodFactory;

impl ModelFactory for RigidRodFactory {
    fn id(&self) -> &'static str {
        "rigid-rod"
    }
    fn description(&self) -> &'static str {
        "rigid straight rod: the infinitely stiff limit (no deformation)"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    // What it can simulate: a scene needing anything else (twist, contact,
    // tissue...) is refused by the default `check` with the missing names.
    fn capabilities(&self) -> &'static [Capability] {
        &[Capability::Rod, Capability::TipForce]
    }
    // Knobs the caller leaves unset; the harness overlays the request.
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        Fidelity {
            segments: Some(20),
            dt: Some(1e-3),
            ..Default::default()
        }
    }
    // Built from settings resolved once (by the harness, or by the trait's
    // `build` for library callers): `check` accepted the scene, the scene is
    // valid, the fidelity is the defaults overlaid with the request and
    // every extra a declared key (this model declares none).
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let full = settings.fidelity();
        let rod = scene.rods().next().expect("check: one rod").clone();
        let segments = full.segments.unwrap_or(20);
        Ok(Box::new(RigidRod {
            obs: RigidRod::observe_rod(&rod, scene.gravity, segments),
            dt: full.dt.unwrap_or(1e-3),
        }))
    }
}

/// One rod, stepped by the harness. SI units throughout.
pub struct RigidRod {
    obs: Observation,
    dt: f64,
}

impl RigidRod {
    /// The rod on its clamp's local +x, `segments` edges, with the load it
    /// puts on the clamp: weight and tip force.
    fn observe_rod(rod: &RodBody, gravity: Vec3, segments: usize) -> Observation {
        let ds = rod.length / segments as f64;
        let arclength: Vec<f64> = (0..=segments).map(|i| i as f64 * ds).collect();
        let nodes: Vec<Vec3> = arclength
            .iter()
            .map(|&s| rod.base.transform_point(&Vec3::new(s, 0.0, 0.0).into()).coords)
            .collect();
        // Material frame columns (d1, d2, t): the clamp's local y, z and x.
        let r = rod.base.rotation;
        let frame = Mat3::from_columns(&[r * Vec3::y(), r * Vec3::z(), r * Vec3::x()]);
        // Force and torque the rod exerts on the clamp (N, N m about the
        // clamp point): each segment's weight at its midpoint, and the tip force.
        let clamp = rod.base.translation.vector;
        let (mut force, mut torque) = (rod.tip_force, (nodes[segments] - clamp).cross(&rod.tip_force));
        for i in 0..segments {
            let mid = 0.5 * (arclength[i] + arclength[i + 1]);
            let sec = rod.section_at(mid);
            let w = gravity * (sec.density * sec.area() * ds);
            force += w;
            torque += (0.5 * (nodes[i] + nodes[i + 1]) - clamp).cross(&w);
        }
        Observation {
            rods: vec![RodObs {
                rest: nodes.clone(),
                velocities: vec![Vec3::zeros(); nodes.len()],
                frames: vec![frame; segments],
                arclength,
                nodes,
                max_stretch: 0.0,
            }],
            hand_force: force,
            hand_torque: torque,
            ..Default::default()
        }
    }
}

impl Model for RigidRod {
    // The command holds the operator's hands at the end of the step; a rod
    // that cannot be fed or turned was refused those scenes by `check`.
    fn step(&mut self, dt: f64, _cmd: &DeviceCommand) -> Result<StepStats, SimError> {
        self.obs.time += dt;
        Ok(StepStats {
            iterations: 0,
            residual: 0.0,
            converged: true,
        })
    }
    fn observe(&self) -> Observation {
        self.obs.clone()
    }
    fn dt(&self) -> f64 {
        self.dt
    }
}
