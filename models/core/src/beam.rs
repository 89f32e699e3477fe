//! Euler-Bernoulli beam constants the rod models share: the first bending
//! mode of a clamped-free (cantilever) beam, which sets the default time
//! steps and settling damping of static rod scenes.
//!
//! ```
//! use surgbench_core::beam::first_bending_frequency;
//! use surgbench_core::RodBody;
//! let rod = RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0);
//! let w = first_bending_frequency(&rod.sections[0], rod.length);
//! assert!(w > 0.0 && w.is_finite());
//! ```

use crate::scene::RodSection;

/// First root `beta_1 L` of the cantilever frequency equation
/// `cos(beta L) cosh(beta L) = -1` (Rao, *Vibration of Continuous Systems*,
/// 2007, eq. 11.69 and Table 11.3: 1.875104).
pub const FIRST_CANTILEVER_MODE: f64 = 1.875_104_068_711_961;

/// Angular frequency `omega_1 = (beta_1 L)^2 sqrt(E I / (rho A L^4))`
/// (rad/s) of the first bending mode of a cantilever of length `length` (m)
/// with the uniform cross-section `section`.
pub fn first_bending_frequency(section: &RodSection, length: f64) -> f64 {
    let s = section;
    FIRST_CANTILEVER_MODE.powi(2)
        * (s.youngs_modulus * s.second_moment() / (s.density * s.area() * length.powi(4))).sqrt()
}
