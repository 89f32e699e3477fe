//! The harness factory of the FEM tissue: [`FemFactory`] (`id = "fem"`),
//! its capabilities, fidelity keys, defaults and their resolution into
//! [`crate::DynParams`].

use crate::assembly::{LinearSolver, Ordering};
use crate::dynamics::{DynParams, FemModel, Integrator, REUSE_TOL};
use crate::material::Law;
use surgbench_core::sphere_contact::DEFAULT_KAPPA;
use surgbench_core::statics;
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, TissueBody,
};

/// The `fem` model: corotational (default), linear or neo-Hookean tetrahedra.
pub struct FemFactory;

const KEYS: &[FidelityKey] = &[
    FidelityKey::choice(
        "material_law",
        "constitutive law of the tets",
        &[
            Choice::new("corotational", "corotational linear (Irving 2004, default)"),
            Choice::new("linear", "linear small strain"),
            Choice::new("neo-hookean", "compressible neo-Hookean (Bonet-Wood)"),
        ],
    ),
    FidelityKey::choice(
        "integrator",
        "time integrator",
        &[
            Choice::new("newmark", "Newmark beta=1/4 (default for dynamic scenes)"),
            Choice::new("backward-euler", "backward Euler"),
            Choice::new(
                "quasi-static",
                "static equilibrium every step by adaptive load stepping (default when the scene settles, then one step to the end of its loads)",
            ),
        ],
    ),
    FidelityKey::choice(
        "solver",
        "linear solver of each Newton step",
        &[
            Choice::new("direct", "sparse Cholesky (faer, default)"),
            Choice::new("cg", "block-Jacobi PCG"),
        ],
    ),
    FidelityKey::choice(
        "ordering",
        "Cholesky fill ordering",
        &[
            Choice::new("amd", "approximate minimum degree"),
            Choice::new("rcm", "reverse Cuthill-McKee"),
            Choice::new("nested-dissection", "geometric nested dissection"),
            Choice::new("auto", "whichever of AMD and nested dissection fills less (default)"),
        ],
    ),
    FidelityKey::number("cg_tol", "PCG relative residual tolerance (default 1e-8)").between(0.0, 1.0),
    FidelityKey::switch(
        "factor_reuse",
        "Cholesky: 1 (default) = dynamic steps: while Jacobian blocks changed, CG preconditioned by the last factor (refactor when it ages); quasi-static: modified Newton, the last factor while each iteration at least quarters the residual; 0 = refactor whenever a block changed / at every Newton iteration",
    ),
    FidelityKey::number(
        "reuse_tol",
        "Cholesky with factor_reuse: relative residual of the stale-factor PCG (default 1e-6)",
    ).between(0.0, 1.0),
    FidelityKey::switch(
        "reuse_f32",
        "Cholesky with factor_reuse: 1 (default) = the stale-factor PCG applies an f32 copy of the factor, two-way parallel (CG in f64, same tolerance), 0 = the f64 factor (faer's sequential solve)",
    ),
    FidelityKey::number(
        "lazy_threshold",
        "lazy Jacobian: rebuild an element's block when its rotation moved more than this (rad); default 0 = always",
    ).at_least(0.0),
    FidelityKey::number("rayleigh_mass", "Rayleigh damping alpha (1/s), default 0").at_least(0.0),
    FidelityKey::number("rayleigh_stiffness", "Rayleigh damping beta (s), default 0").at_least(0.0),
    FidelityKey::number(
        "threads",
        "assembly threads (default 2); results are identical for any count",
    ).whole(1.0, 64.0),
    FidelityKey::number(
        "contact_stiffness",
        "sphere contact penalty factor kappa: node stiffness kappa E/(1-nu^2) sqrt(node boundary area) (default 100; penetration ~ contact strain / kappa of the mesh size)",
    ).above(0.0),
];

/// The names of `material_law`, `integrator` and `ordering`, as the model's values.
const LAWS: &[(&str, Law)] = &[
    ("corotational", Law::Corotational),
    ("linear", Law::Linear),
    ("neo-hookean", Law::NeoHookean),
];
const INTEGRATORS: &[(&str, Integrator)] = &[
    ("newmark", Integrator::Newmark),
    ("backward-euler", Integrator::BackwardEuler),
    ("quasi-static", Integrator::QuasiStatic),
];
const ORDERINGS: &[(&str, Ordering)] = &[
    ("amd", Ordering::Amd),
    ("rcm", Ordering::Rcm),
    ("nested-dissection", Ordering::NestedDissection),
    ("auto", Ordering::Auto),
];

impl FemFactory {
    fn params(&self, s: &Settings) -> Result<(DynParams, f64), BuildError> {
        let full = s.fidelity();
        // `mesh_level` is the scenario's knob: it builds the scene's mesh at
        // that level (`Scenario::instantiate_at`); fem runs on that mesh.
        let law = s.pick("material_law", LAWS, Law::Corotational)?;
        let integrator = s.pick("integrator", INTEGRATORS, Integrator::Newmark)?;
        let solver = linear_solver(s)?;
        // Ranges are declared on the keys (KEYS) and checked by `resolve`.
        let reuse_tol = s.number_or("reuse_tol", REUSE_TOL);
        let threads = s.number_or("threads", 2.0) as usize;
        let contact_stiffness = s.number_or("contact_stiffness", DEFAULT_KAPPA);
        let p = DynParams {
            contact_stiffness,
            law,
            integrator,
            solver,
            lazy_threshold: s.number_or("lazy_threshold", 0.0),
            factor_reuse: s.switch("factor_reuse", true),
            reuse_tol,
            reuse_f32: s.switch("reuse_f32", true),
            rayleigh_mass: s.number_or("rayleigh_mass", 0.0),
            rayleigh_stiffness: s.number_or("rayleigh_stiffness", 0.0),
            iterations: full.iterations.unwrap_or(1),
            tol: 1e-9,
            threads,
        };
        Ok((p, full.dt.unwrap_or(1e-3)))
    }
}

impl ModelFactory for FemFactory {
    fn id(&self) -> &'static str {
        "fem"
    }
    fn description(&self) -> &'static str {
        "linear-tet FEM tissue: corotational (Irving 2004) / linear / neo-Hookean, Newmark or backward Euler, sparse Cholesky or PCG"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn capabilities(&self) -> &'static [Capability] {
        &[
            Capability::Tissue,
            Capability::HapticForce,
            Capability::PressureLoad,
            Capability::RollerConstraint,
            Capability::TissueContact,
            Capability::SurfaceForces,
            Capability::InitialVelocity,
            Capability::MaterialRegions,
        ]
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        KEYS
    }
    /// Dynamic scenes: `dt = 1 ms`, one Newton iteration per step. A
    /// settling scene is solved as a static problem: quasi-static, and one
    /// step to the time its loads stop changing
    /// ([`Scene::inputs_held_from`], at most half the duration), inside
    /// which the adaptive load stepping picks the increments (up to 30
    /// Newton iterations each); the runner's next step finds the state
    /// unchanged and ends the run as settled. The mesh is the scene's.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            dt: Some(1e-3),
            ..Default::default()
        };
        if scene.settle.is_some() {
            f.iterations = Some(30);
            f.extras.insert("integrator".into(), "quasi-static".into());
            if let Some(dt) = statics::static_dt(scene) {
                f.dt = Some(dt);
            }
        } else {
            f.iterations = Some(1);
        }
        f
    }
    /// A settling scene run with a dynamic integrator the caller picked,
    /// and no `dt`: the dynamic default `dt = 1 ms`, not the static one
    /// step to the whole load.
    fn complete_defaults(&self, _scene: &Scene, requested: &Fidelity, merged: &mut Fidelity) {
        statics::keep_dynamic_dt(requested, merged, 1e-3);
    }
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let tissues: Vec<&TissueBody> = scene.tissues().collect();
        if tissues.len() != 1 {
            return Err(surgbench_core::Unsupported::new(format!(
                "fem runs exactly one tissue body, the scene has {}",
                tissues.len()
            ))
            .into());
        }
        let (p, dt) = self.params(settings)?;
        let m =
            FemModel::new(tissues[0], scene.gravity, dt, p).map_err(|e| BuildError::bad("tissue", e.to_string()))?;
        Ok(Box::new(m))
    }
}

/// The linear solver of the extras `solver`, `ordering` and `cg_tol`.
fn linear_solver(s: &Settings) -> Result<LinearSolver, BuildError> {
    let ordering = s.pick("ordering", ORDERINGS, Ordering::Auto)?;
    let cg_tol = s.number_or("cg_tol", 1e-8);
    let cg = s.pick("solver", &[("direct", false), ("cg", true)], false)?;
    Ok(if cg {
        LinearSolver::Cg {
            tol: cg_tol,
            max_iter: 2000,
        }
    } else {
        LinearSolver::Cholesky(ordering)
    })
}
