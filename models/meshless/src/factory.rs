//! The harness factory of the meshless tissue: [`MeshlessFactory`]
//! (`id = "meshless"`), its capabilities, fidelity keys and defaults.

use crate::model::MeshlessTissue;
use surgbench_core::statics;
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Setting, Settings,
    Unsupported,
};

/// Fidelity extras of `meshless` (besides `dt` and `iterations` = PBD sweeps).
pub const MESHLESS_KEYS: &[FidelityKey] = &[
    FidelityKey::choice(
        "variant",
        "which configuration the other keys default to",
        &[
            Choice::new(
                "harness",
                "this harness's (default): quasi-static Newton on settling scenes, backward Euler otherwise, hourglass control 0.1, no PBD",
            ),
            Choice::new(
                "seed",
                "the vascular-tissue seed's: symplectic Euler at half the Courant step h_min / c_p, the PBD stretch and virtual-tet corrections on, no hourglass control (keys named beside it still win)",
            ),
        ],
    ),
    FidelityKey::number(
        "support_factor",
        "poly6 support radius h_i over node i's local edge length (mean edge of the tets around it; default 1.5)",
    )
    .above(0.0),
    FidelityKey::number(
        "mls_factor",
        "MLS surface-mapping radius over the local edge length of the surface node (default 2.0)",
    )
    .above(0.0),
    FidelityKey::number(
        "stabilization",
        "hourglass-control stiffness over Young's modulus, gamma (default 0.1; 0 = off)",
    )
    .at_least(0.0),
    FidelityKey::choice(
        "integrator",
        "time integrator",
        &[
            Choice::new("symplectic-euler", "symplectic (semi-implicit) Euler, explicit"),
            Choice::new("backward-euler", "backward Euler by Newton-CG (default dynamic)"),
            Choice::new(
                "quasi-static",
                "static equilibrium every step by Newton-CG with adaptive load stepping (default when the scene settles, then one step to the end of its loads)",
            ),
        ],
    ),
    FidelityKey::number(
        "damping",
        "mass-proportional damping rate c (1/s); default 0, explicit on settling scenes 2 omega_1",
    )
    .at_least(0.0),
    FidelityKey::switch(
        "pbd",
        "1 = add the seed's PBD corrections (edge stretch + virtual-tet energy), 0 = off (default)",
    ),
    FidelityKey::number("pbd_stretch", "PBD stretch stiffness (default 0.5)").within(0.0, 1.0),
    FidelityKey::number("pbd_tet", "PBD virtual-tet energy stiffness (default 0.5)").within(0.0, 1.0),
    FidelityKey::number(
        "support_floor",
        "radius floor over the longest mesh edge at the node, applied where support_factor x the local edge gives a nearly flat neighbourhood (rcond < 1e-3) (default 1.05: the support holds the node's mesh star, which spans 3D; 0 = off)",
    )
    .at_least(0.0),
    FidelityKey::number(
        "contact_stiffness",
        "sphere contact penalty factor kappa: node stiffness kappa E/(1-nu^2) sqrt(node boundary area) (default 100; penetration ~ contact strain / kappa of the node spacing)",
    )
    .above(0.0),
];

/// Fraction of the Courant step `h_min / c_p` the seed variant's explicit
/// integrator takes. The stability limit `2 / omega_max` (power iteration,
/// [`crate::MeshlessTissue::critical_dt`], at the seed variant's settings)
/// measured 1.03-1.04 `h_min / c_p` on the Truth Cube (nu = 0.499), 1.20 on
/// block compression and 2.2-2.3 on the Lamé tube at mesh levels 0-2:
/// half the Courant step leaves a factor of two or more.
pub const SEED_COURANT_FRACTION: f64 = 0.5;

/// The seed variant's explicit time step on `scene` (s):
/// [`SEED_COURANT_FRACTION`] `h_min / c_p`, `h_min` the shortest edge of the
/// tissue's mesh and `c_p = sqrt((lambda + 2 mu) / rho)` the dilatational
/// wave speed of its material; `None` without a tissue (or a degenerate
/// one, left to the build to refuse).
pub fn seed_dt(scene: &Scene) -> Option<f64> {
    let t = scene.tissues().next()?;
    let h_min = t
        .mesh
        .tets
        .iter()
        .flat_map(|e| (0..4).flat_map(move |a| (a + 1..4).map(move |b| (e[a], e[b]))))
        .map(|(a, b)| (t.mesh.nodes[a] - t.mesh.nodes[b]).norm())
        .fold(f64::INFINITY, f64::min);
    let (mu, lambda) = surgbench_core::material::lame(t.material.youngs_modulus, t.material.poisson_ratio);
    let dt = SEED_COURANT_FRACTION * h_min / ((lambda + 2.0 * mu) / t.material.density).sqrt();
    (dt.is_finite() && dt > 0.0).then_some(dt)
}

/// Factory of the point-primitive (meshless) tissue, id `meshless`.
#[derive(Debug, Clone, Copy, Default)]
pub struct MeshlessFactory;

const CAPS: &[Capability] = &[
    Capability::Tissue,
    Capability::PressureLoad,
    Capability::RollerConstraint,
    Capability::HapticForce,
    Capability::TissueContact,
    Capability::SurfaceForces,
    Capability::InitialVelocity,
];

impl ModelFactory for MeshlessFactory {
    fn id(&self) -> &'static str {
        "meshless"
    }
    fn description(&self) -> &'static str {
        "Point-primitive tissue: MLS deformation gradients (Müller 2004), StVK, hourglass control, optional PBD corrections, MLS surface mapping"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn capabilities(&self) -> &'static [Capability] {
        CAPS
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        MESHLESS_KEYS
    }
    /// `dt = 1 ms` and 5 PBD iterations; a settling scene is solved as a
    /// static problem (quasi-static, the default integrator there): one
    /// step to the time its loads stop changing
    /// ([`Scene::inputs_held_from`], at most half the duration), inside
    /// which the adaptive load stepping picks the increments.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            dt: Some(1e-3),
            iterations: Some(5),
            ..Default::default()
        };
        if let Some(dt) = statics::static_dt(scene) {
            f.dt = Some(dt);
        }
        f
    }
    /// A settling scene run with a dynamic integrator the caller picked,
    /// and no `dt`: the dynamic default `dt = 1 ms`. The seed variant with
    /// its explicit integrator and no `dt`: [`seed_dt`] (on any scene).
    fn complete_defaults(&self, scene: &Scene, requested: &Fidelity, merged: &mut Fidelity) {
        let seed = matches!(merged.extras.get("variant"), Some(Setting::Choice(c)) if c == "seed");
        let explicit = match merged.extras.get("integrator") {
            None => seed,
            Some(Setting::Choice(c)) => c == "symplectic-euler",
            Some(Setting::Number(_)) => false,
        };
        if seed
            && explicit
            && requested.dt.is_none()
            && let Some(dt) = seed_dt(scene)
        {
            merged.dt = Some(dt);
            return;
        }
        statics::keep_dynamic_dt(requested, merged, 1e-3);
    }
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        surgbench_core::model::check_capabilities(self.id(), self.capabilities(), scene)?;
        match scene.tissues().count() {
            1 => {}
            0 => return Err(Unsupported::new("meshless needs a tissue body in the scene")),
            k => {
                return Err(Unsupported::new(format!(
                    "meshless simulates one tissue, the scene has {k}"
                )));
            }
        }
        Ok(())
    }
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        Ok(Box::new(MeshlessTissue::with_settings(scene, settings)?))
    }
}
