//! # surgbench-fem: corotational FEM tissue
//!
//! Linear tetrahedra with three constitutive laws ([`Law`]: corotational /
//! invertible after Irving et al. 2004, small-strain linear, compressible
//! neo-Hookean), lumped mass, Rayleigh damping, implicit Newmark
//! (`beta = 1/4, gamma = 1/2`) and backward Euler time stepping with a fixed
//! number of Newton iterations per step, and quasi-static solves (Newton,
//! load stepping) through [`solve_static`]; the harness model solves a
//! settling scene as one static problem, its load increments adaptive
//! (start with the whole load, halve a failing one down to 1/1024, double
//! a fast one) and its Newton modified (the last factorization reused while
//! it quarters the residual per iteration). Linear systems go to
//! faer's sparse Cholesky (symbolic analysis once, numeric factorization
//! reused while the matrix is unchanged) or to a block-Jacobi preconditioned
//! conjugate gradient. Assembly runs on a private rayon pool and is
//! bit-identical for any thread count.
//!
//! Units are SI: m, kg, s, N, Pa.
//!
//! Entry points:
//! * [`solve_static`]: quasi-static equilibrium for verification scenes;
//! * [`FemFactory`]: the `fem` model for the harness ([`surgbench_core::ModelFactory`]);
//! * [`SphereContact`]: frictionless penalty contact with a rigid sphere
//!   (`TissueBody::indenter`), in the quasi-static, Newmark and backward
//!   Euler integrators;
//! * [`error_norms`]: L2 and H1-seminorm errors against a smooth field
//!   (manufactured solutions).

pub mod assembly;
pub mod bench_support;
pub mod contact;
pub mod core;
pub mod dynamics;
pub mod element;
pub mod factory;
pub mod material;
pub mod statics;
pub mod supernodal;

pub use assembly::{LinearSolver, Ordering};
pub use contact::SphereContact;
pub use dynamics::{DynParams, FemModel, Integrator, LinearStep, REUSE_TOL};
pub use element::Jacobian;
pub use factory::FemFactory;
pub use material::{Law, Material};
pub use statics::{Constraint, Loads, StaticInfo, StaticParams, pressure_loads, solve_static, solve_static_materials};

use std::fmt;
use surgbench_core::{TetMesh, Vec3};

/// Why a solve failed.
#[derive(Debug, Clone, PartialEq)]
pub enum FemError {
    /// Mesh, material, constraint or parameter out of range.
    BadInput(String),
    /// Newton did not reach the tolerance.
    NotConverged {
        /// 1-based load step.
        step: usize,
        /// Iterations done.
        iterations: usize,
        /// Relative residual reached.
        residual: f64,
    },
    /// Elements inverted under a law that cannot represent it (neo-Hookean).
    Inverted {
        /// 1-based load step.
        step: usize,
        /// Inverted element count.
        elements: usize,
    },
    /// The linear solver failed.
    LinearSolver(String),
}

impl fmt::Display for FemError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FemError::BadInput(s) => write!(f, "bad input: {s}"),
            FemError::NotConverged {
                step,
                iterations,
                residual,
            } => {
                write!(
                    f,
                    "Newton did not converge in load step {step} after {iterations} iterations (residual {residual:.3e})"
                )
            }
            FemError::Inverted { step, elements } => write!(
                f,
                "{elements} elements inverted in load step {step} (neo-Hookean is undefined there; use more load steps or the corotational law)"
            ),
            FemError::LinearSolver(s) => write!(f, "linear solver: {s}"),
        }
    }
}

impl std::error::Error for FemError {}

/// Errors of a P1 displacement field `u_h` (nodal values, m) against a
/// smooth field `u` with gradient `grad_u` (`grad_u[i][j] = du_i/dX_j`):
/// returns `(sqrt(int |u_h - u|^2 dV), sqrt(int |grad(u_h - u)|^2 dV))`, in
/// m^(5/2) and m^(3/2). Integrated per tet with the degree-2 rule
/// [`element::QUAD4`] (`grad u_h` is constant per tet). `NaN` if the mesh
/// has a degenerate or inverted tet.
pub fn error_norms(
    mesh: &TetMesh,
    u_h: &[Vec3],
    u: impl Fn(&Vec3) -> Vec3,
    grad_u: impl Fn(&Vec3) -> material::M3,
) -> (f64, f64) {
    let (mut l2, mut h1) = (0.0, 0.0);
    let elems = match element::Elements::new(mesh) {
        Ok(e) => e,
        Err(_) => return (f64::NAN, f64::NAN),
    };
    for (e, t) in mesh.tets.iter().enumerate() {
        let p = t.map(|i| mesh.nodes[i]);
        let uh = t.map(|i| u_h[i]);
        let mut gh = material::M3::zeros();
        for a in 0..4 {
            gh += uh[a] * elems.grads[e][a].transpose();
        }
        let w = elems.vol[e] / 4.0;
        for q in element::QUAD4 {
            let xq = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3];
            let uq = uh[0] * q[0] + uh[1] * q[1] + uh[2] * q[2] + uh[3] * q[3];
            l2 += w * (uq - u(&xq)).norm_squared();
            h1 += w * (gh - grad_u(&xq)).norm_squared();
        }
    }
    (l2.sqrt(), h1.sqrt())
}
