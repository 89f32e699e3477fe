//! Isotropic linear-elastic material constants shared by every tissue model:
//! [`SolidMaterial`] (Young's modulus, Poisson ratio, density), the Lamé
//! parameters ([`lame`]) and the plane-strain modulus of contact mechanics
//! ([`plane_strain_modulus`]). SI units (Pa, kg/m^3).
//!
//! ```
//! use surgbench_core::material::{lame, plane_strain_modulus};
//! let (mu, lambda) = lame(3e3, 0.25);
//! assert!((mu - 1.2e3).abs() < 1e-9 && (lambda - 1.2e3).abs() < 1e-9);
//! assert!((plane_strain_modulus(3e3, 0.5) - 4e3).abs() < 1e-9);
//! ```

/// Isotropic solid material (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolidMaterial {
    /// Young's modulus (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio (must be < 0.5).
    pub poisson_ratio: f64,
    /// Density (kg/m^3).
    pub density: f64,
}

/// Lamé parameters `(mu, lambda)` (Pa) from Young's modulus `E` (Pa) and
/// Poisson ratio `nu`: `mu = E / (2 (1 + nu))`,
/// `lambda = E nu / ((1 + nu)(1 - 2 nu))` (isotropic linear elasticity;
/// e.g. Sadd, *Elasticity*, 2nd ed. 2009, Table 4.1).
pub fn lame(youngs_modulus: f64, poisson_ratio: f64) -> (f64, f64) {
    let (e, nu) = (youngs_modulus, poisson_ratio);
    (e / (2.0 * (1.0 + nu)), e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)))
}

/// Plane-strain (contact) modulus `E* = E / (1 - nu^2)` (Pa) of an elastic
/// half-space pressed by a rigid body: a rigid flat punch of radius `a`
/// has the stiffness `2 a E*` (Johnson, *Contact Mechanics*, 1985, eq. 3.36).
pub fn plane_strain_modulus(youngs_modulus: f64, poisson_ratio: f64) -> f64 {
    youngs_modulus / (1.0 - poisson_ratio * poisson_ratio)
}
