//! The harness factories of the two PBD models: [`PbdRodFactory`]
//! (`id = "pbd-rod"`) and [`PbdTissueFactory`] (`id = "pbd-tissue"`), their
//! capabilities, fidelity keys and defaults.

use crate::rod::PbdRod;
use crate::tissue::PbdTissue;
use surgbench_core::beam::first_bending_frequency;
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, TissueBody,
    Unsupported,
};

/// Fidelity extras of `pbd-rod`.
pub const ROD_KEYS: &[FidelityKey] = &[
    FidelityKey::number("substeps", "XPBD substeps per step (default 1)").whole(1.0, 1e6),
    FidelityKey::number(
        "damping",
        "velocity damping rate c (1/s): v <- v / (1 + c h) each substep; default 0, or 2 omega_1 (critical for the first bending mode) in static scenes",
    )
    .at_least(0.0),
    FidelityKey::choice(
        "solver",
        "constraint solver per iteration",
        &[
            Choice::new(
                "gauss-seidel",
                "non-linear Gauss-Seidel over the constraints (default in dynamic scenes)",
            ),
            Choice::new(
                "direct",
                "all rod constraints linearised and solved at once by banded Cholesky (Deul et al. 2018); default in static scenes, where Gauss-Seidel at 4 substeps diverges under a dead load",
            ),
        ],
    ),
];

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
    Capability::InitialVelocity,
    Capability::VesselContact,
    Capability::Friction,
    Capability::Flow,
    Capability::MovingVessel,
    Capability::HapticForce,
    Capability::DeformableLumen,
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
        f.extras.insert("substeps".into(), 4.0.into());
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
            // The same bound for a dead tip torque, which enters the tip
            // segment's spin explicitly: h^2 |T| / I_a turns it by at most a
            // tenth of a radian per substep, I_a = m r^2 / 2 its axial
            // inertia (torque-transfer, 0.01 N m on a 50-segment wire at
            // dt = 1 ms: 281 substeps; measured 4 and 16 trip the energy
            // watchdog, 281 settles at 5.3e-3 rad against a 0.0175 target).
            let tmax = rod.tip_torque.norm();
            let mut ns = 4.0f64;
            if fmax > 0.0 {
                let h_max = l * (0.1 * s.density * s.area() / (2.0 * fmax)).sqrt();
                ns = ns.max((dt / h_max).ceil());
            }
            if tmax > 0.0 {
                let i_axial = 0.5 * s.density * s.area() * l * s.radius * s.radius;
                let h_max = (0.1 * i_axial / tmax).sqrt();
                ns = ns.max((dt / h_max).ceil());
            }
            if fmax > 0.0 || tmax > 0.0 {
                f.extras.insert("substeps".into(), ns.clamp(4.0, 1e4).into());
            }
        }
        // Static scenes are run to equilibrium with the model's own damping:
        // critical damping of the first cantilever bending mode,
        // c = 2 omega_1 (`surgbench_core::beam::first_bending_frequency`),
        // and by the direct solver, which carries a dead load to the clamp in
        // one iteration. Gauss-Seidel at 4 substeps trips the energy
        // watchdog on both cantilevers (measured at the defaults: at
        // t = 0.063 s under gravity, 0.001 s under the tip load); the direct
        // solver settles them at tip errors 4.7e-4 and 3.0e-4, and takes
        // torque-transfer from 3.2e-2 rad to 0 and flow-drift from 3.7e-4 m
        // to 6.1e-7 m. Dynamic scenes keep Gauss-Seidel: on capstan the
        // direct solver's tension error is 5.6e-2 against 5.0e-3.
        if scene.settle.is_some()
            && let Some(rod) = scene.rods().next()
        {
            let w1 = first_bending_frequency(&rod.sections[0], rod.length);
            f.extras.insert("damping".into(), (2.0 * w1).into());
            f.extras.insert("solver".into(), "direct".into());
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
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        Ok(Box::new(PbdRod::with_settings(scene, settings)?))
    }
}

/// Fidelity extras of `pbd-tissue`.
pub const TISSUE_KEYS: &[FidelityKey] = &[
    FidelityKey::number("substeps", "XPBD substeps per step (default 1)").whole(1.0, 1e6),
    FidelityKey::number(
        "damping",
        "velocity damping rate c (1/s): v <- v / (1 + c h) each substep; default 0",
    )
    .at_least(0.0),
    FidelityKey::number("hash_box", "local activation box edge d (m); 0 = off (default)").at_least(0.0),
    FidelityKey::number("hash_span", "box expansion span (m); default d/3").at_least(0.0),
    FidelityKey::number(
        "threads",
        "worker threads of the constraint solve (default min(2, available cores)); results are bit-identical for any count",
    )
    .whole(1.0, 256.0),
];

/// Factory for the tetrahedral XPBD tissue (`pbd-tissue`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PbdTissueFactory;

const TISSUE_CAPS: &[Capability] = &[
    Capability::Tissue,
    Capability::HapticForce,
    Capability::RollerConstraint,
    Capability::TissueContact,
    Capability::SurfaceForces,
    Capability::InitialVelocity,
];

impl ModelFactory for PbdTissueFactory {
    fn id(&self) -> &'static str {
        "pbd-tissue"
    }
    fn description(&self) -> &'static str {
        "Tetrahedral XPBD tissue: edge-distance and volume constraints, optional hash-box local activation"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn capabilities(&self) -> &'static [Capability] {
        TISSUE_CAPS
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        TISSUE_KEYS
    }
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        Fidelity {
            segments: None,
            mesh_level: None,
            dt: Some(1e-3),
            iterations: Some(10),
            extras: Default::default(),
        }
    }
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_capabilities(self.id(), self.capabilities(), scene)?;
        let tissues: Vec<&TissueBody> = scene.tissues().collect();
        match tissues.len() {
            1 => {}
            0 => return Err(Unsupported::new("pbd-tissue needs a tissue body in the scene")),
            k => {
                return Err(Unsupported::new(format!(
                    "pbd-tissue simulates one tissue, the scene has {k}"
                )));
            }
        }
        if tissues[0].material.poisson_ratio < 0.0 {
            return Err(Unsupported::new(
                "pbd-tissue maps nu to the volume compliance V0/lambda; nu < 0 gives lambda < 0",
            ));
        }
        Ok(())
    }
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        Ok(Box::new(PbdTissue::with_settings(scene, settings)?))
    }
}
