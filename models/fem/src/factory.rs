//! The harness factory of the FEM tissue: [`FemFactory`] (`id = "fem"`),
//! its capabilities, fidelity keys, defaults and their resolution into
//! [`crate::DynParams`].

use crate::assembly::{LinearSolver, Ordering};
use crate::dynamics::{DynParams, FemModel, Integrator, REUSE_TOL};
use crate::material::Law;
use surgbench_core::sphere_contact::DEFAULT_KAPPA;
use surgbench_core::{BuildError, Capability, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, TissueBody};

/// The `fem` model: corotational (default), linear or neo-Hookean tetrahedra.
pub struct FemFactory;

const KEYS: &[FidelityKey] = &[
    FidelityKey {
        name: "material_law",
        doc: "0 corotational (Irving 2004, default), 1 linear small strain, 2 neo-Hookean (Bonet-Wood)",
    },
    FidelityKey {
        name: "integrator",
        doc: "0 Newmark beta=1/4 (default for dynamic scenes), 1 backward Euler, 2 quasi-static (default when the scene settles)",
    },
    FidelityKey {
        name: "solver",
        doc: "0 sparse Cholesky (faer, default), 1 block-Jacobi PCG",
    },
    FidelityKey {
        name: "ordering",
        doc: "Cholesky fill ordering: 0 AMD, 1 reverse Cuthill-McKee, 2 geometric nested dissection, 3 whichever of AMD and nested dissection fills less (default)",
    },
    FidelityKey {
        name: "cg_tol",
        doc: "PCG relative residual tolerance (default 1e-8)",
    },
    FidelityKey {
        name: "factor_reuse",
        doc: "Cholesky: 1 (default) = while Jacobian blocks changed, CG preconditioned by the last factor (refactor when it ages), 0 = refactor whenever a block changed",
    },
    FidelityKey {
        name: "reuse_tol",
        doc: "Cholesky with factor_reuse: relative residual of the stale-factor PCG (default 1e-6)",
    },
    FidelityKey {
        name: "reuse_f32",
        doc: "Cholesky with factor_reuse: 1 (default) = the stale-factor PCG applies an f32 copy of the factor, two-way parallel (CG in f64, same tolerance), 0 = the f64 factor (faer's sequential solve)",
    },
    FidelityKey {
        name: "lazy_threshold",
        doc: "lazy Jacobian: rebuild an element's block when its rotation moved more than this (rad); default 0 = always",
    },
    FidelityKey {
        name: "rayleigh_mass",
        doc: "Rayleigh damping alpha (1/s), default 0",
    },
    FidelityKey {
        name: "rayleigh_stiffness",
        doc: "Rayleigh damping beta (s), default 0",
    },
    FidelityKey {
        name: "threads",
        doc: "assembly threads (default 2); results are identical for any count",
    },
    FidelityKey {
        name: "contact_stiffness",
        doc: "sphere contact penalty factor kappa: node stiffness kappa E/(1-nu^2) sqrt(node boundary area) (default 100; penetration ~ contact strain / kappa of the mesh size)",
    },
];

impl FemFactory {
    fn params(&self, scene: &Scene, f: &Fidelity) -> Result<(DynParams, f64), BuildError> {
        let full = self.default_fidelity(scene).merged(f);
        full.check_extras(KEYS).map_err(|e| BuildError::bad("fidelity", e.0))?;
        // `mesh_level` is the scenario's knob: it builds the scene's mesh at
        // that level (`Scenario::instantiate_at`); fem runs on that mesh.
        let code = |name: &str, max: f64| int_code(&full, name, max);
        let law = Law::from_code(code("material_law", 2.0)?).expect("range checked");
        let integrator = match code("integrator", 2.0)? as usize {
            0 => Integrator::Newmark,
            1 => Integrator::BackwardEuler,
            _ => Integrator::QuasiStatic,
        };
        let solver = linear_solver(&full)?;
        let nonneg = |name: &str| -> Result<f64, BuildError> {
            let v = full.extra(name, 0.0);
            if v >= 0.0 {
                Ok(v)
            } else {
                Err(BuildError::bad(name, format!("must be >= 0, got {v}")))
            }
        };
        let factor_reuse = switch(&full, "factor_reuse")?;
        let reuse_f32 = switch(&full, "reuse_f32")?;
        let reuse_tol = full.extra("reuse_tol", REUSE_TOL);
        if !(reuse_tol > 0.0 && reuse_tol < 1.0) {
            return Err(BuildError::bad(
                "reuse_tol",
                format!("must be in (0, 1), got {reuse_tol}"),
            ));
        }
        let threads = full.extra("threads", 2.0);
        if !(1.0..=64.0).contains(&threads) || threads.fract() != 0.0 {
            return Err(BuildError::bad(
                "threads",
                format!("must be an integer in 1..=64, got {threads}"),
            ));
        }
        let contact_stiffness = full.extra("contact_stiffness", DEFAULT_KAPPA);
        if !(contact_stiffness > 0.0 && contact_stiffness.is_finite()) {
            return Err(BuildError::bad(
                "contact_stiffness",
                format!("must be > 0 and finite, got {contact_stiffness}"),
            ));
        }
        let p = DynParams {
            contact_stiffness,
            law,
            integrator,
            solver,
            lazy_threshold: nonneg("lazy_threshold")?,
            factor_reuse,
            reuse_tol,
            reuse_f32,
            rayleigh_mass: nonneg("rayleigh_mass")?,
            rayleigh_stiffness: nonneg("rayleigh_stiffness")?,
            iterations: full.iterations.unwrap_or(1),
            tol: 1e-9,
            threads: threads as usize,
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
        ]
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        KEYS
    }
    /// `dt = 1 ms`; one Newton iteration per dynamic step, up to 30 for a
    /// settling (quasi-static) scene. The mesh is the scene's.
    fn default_fidelity(&self, scene: &Scene) -> Fidelity {
        let mut f = Fidelity {
            dt: Some(1e-3),
            ..Default::default()
        };
        if scene.settle.is_some() {
            f.iterations = Some(30);
            f.extras.insert("integrator".into(), 2.0);
        } else {
            f.iterations = Some(1);
        }
        f
    }
    fn build(&self, scene: &Scene, fidelity: &Fidelity) -> Result<Box<dyn Model>, BuildError> {
        self.check(scene)?;
        scene.validate().map_err(|e| BuildError::bad("scene", e))?;
        let tissues: Vec<&TissueBody> = scene.tissues().collect();
        if tissues.len() != 1 {
            return Err(surgbench_core::Unsupported::new(format!(
                "fem runs exactly one tissue body, the scene has {}",
                tissues.len()
            ))
            .into());
        }
        let (p, dt) = self.params(scene, fidelity)?;
        let m =
            FemModel::new(tissues[0], scene.gravity, dt, p).map_err(|e| BuildError::bad("tissue", e.to_string()))?;
        Ok(Box::new(m))
    }
}

/// The fidelity extra `name` (default 0) as an integer code in `0..=max`.
fn int_code(full: &Fidelity, name: &str, max: f64) -> Result<f64, BuildError> {
    let v = full.extra(name, 0.0);
    if v < 0.0 || v > max || v.fract() != 0.0 {
        Err(BuildError::bad(
            name,
            format!("must be an integer in 0..={max}, got {v}"),
        ))
    } else {
        Ok(v)
    }
}

/// The fidelity extra `name` (default 1 = on) as an on/off switch.
fn switch(full: &Fidelity, name: &str) -> Result<bool, BuildError> {
    match full.extra(name, 1.0) {
        0.0 => Ok(false),
        1.0 => Ok(true),
        v => Err(BuildError::bad(name, format!("must be 0 or 1, got {v}"))),
    }
}

/// The linear solver of the extras `solver`, `ordering` and `cg_tol`.
fn linear_solver(full: &Fidelity) -> Result<LinearSolver, BuildError> {
    let ordering = match full.extra("ordering", 3.0) {
        0.0 => Ordering::Amd,
        1.0 => Ordering::Rcm,
        2.0 => Ordering::NestedDissection,
        3.0 => Ordering::Auto,
        v => return Err(BuildError::bad("ordering", format!("must be 0, 1, 2 or 3, got {v}"))),
    };
    let cg_tol = full.extra("cg_tol", 1e-8);
    if !(cg_tol > 0.0 && cg_tol < 1.0) {
        return Err(BuildError::bad("cg_tol", format!("must be in (0, 1), got {cg_tol}")));
    }
    Ok(if int_code(full, "solver", 1.0)? == 1.0 {
        LinearSolver::Cg {
            tol: cg_tol,
            max_iter: 2000,
        }
    } else {
        LinearSolver::Cholesky(ordering)
    })
}
