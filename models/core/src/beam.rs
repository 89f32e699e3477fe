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

/// Second root `beta_2 L` of `cos(beta L) cosh(beta L) = -1` (Blevins,
/// *Formulas for Natural Frequency and Mode Shape*, 1979, Table 8-1:
/// 4.694091).
pub const SECOND_CANTILEVER_MODE: f64 = 4.694_091_132_974_175;

/// Mode shape of a clamped-free Euler-Bernoulli beam and its slope, at
/// `xi = x / L` in `[0, 1]`, for the root `beta_l = beta_n L`
/// ([`FIRST_CANTILEVER_MODE`], [`SECOND_CANTILEVER_MODE`]):
/// `phi(xi) = cosh(b xi) - cos(b xi) - sigma (sinh(b xi) - sin(b xi))`,
/// `sigma = (cosh b + cos b) / (sinh b + sin b)` (Blevins 1979, Table 8-1;
/// `sigma_1 = 0.734096`). Returns `(phi, d phi / d xi)`; normalised as
/// Blevins writes it, `|phi(1)| = 2` and `int_0^1 phi^2 d xi = 1`.
pub fn cantilever_mode(beta_l: f64, xi: f64) -> (f64, f64) {
    let b = beta_l;
    let sigma = (b.cosh() + b.cos()) / (b.sinh() + b.sin());
    let z = b * xi;
    let phi = z.cosh() - z.cos() - sigma * (z.sinh() - z.sin());
    let dphi = b * (z.sinh() + z.sin() - sigma * (z.cosh() - z.cos()));
    (phi, dphi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The roots solve the frequency equation, sigma_1 is Blevins' 0.734096,
    /// the shapes meet the clamped-free conditions (phi(0) = phi'(0) = 0,
    /// phi''(1) = phi'''(1) = 0, checked by central differences of the
    /// slope: O(h^2) = 1e-8 at h = 1e-4, scaled by b^3) and the first two
    /// are orthonormal (Simpson on 2000 intervals: error ~1e-12).
    #[test]
    fn cantilever_modes_are_clamped_free_and_orthonormal() {
        for b in [FIRST_CANTILEVER_MODE, SECOND_CANTILEVER_MODE] {
            assert!((b.cos() * b.cosh() + 1.0).abs() < 1e-12 * b.cosh(), "root {b}");
            let (p0, d0) = cantilever_mode(b, 0.0);
            assert_eq!((p0, d0), (0.0, 0.0));
            let h = 1e-4;
            let slope = |x: f64| cantilever_mode(b, x).1;
            let curv = (slope(1.0) - slope(1.0 - h)) / h; // one-sided: O(h) b^3
            let shear = (slope(1.0) - 2.0 * slope(1.0 - h) + slope(1.0 - 2.0 * h)) / (h * h);
            assert!(curv.abs() < 10.0 * h * b.powi(3), "phi''(1) = {curv} for b = {b}");
            assert!(shear.abs() < 10.0 * h * b.powi(4), "phi'''(1) = {shear} for b = {b}");
            assert!((cantilever_mode(b, 1.0).0.abs() - 2.0).abs() < 1e-9);
        }
        let sigma1 = {
            let b = FIRST_CANTILEVER_MODE;
            (b.cosh() + b.cos()) / (b.sinh() + b.sin())
        };
        assert!((sigma1 - 0.734096).abs() < 1e-6, "sigma_1 = {sigma1}");
        let n = 2000;
        let simpson = |f: &dyn Fn(f64) -> f64| {
            let h = 1.0 / n as f64;
            (0..=n)
                .map(|i| {
                    let w = if i == 0 || i == n {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    w * f(i as f64 * h)
                })
                .sum::<f64>()
                * h
                / 3.0
        };
        let m = |b: f64, x: f64| cantilever_mode(b, x).0;
        let (b1, b2) = (FIRST_CANTILEVER_MODE, SECOND_CANTILEVER_MODE);
        assert!((simpson(&|x| m(b1, x) * m(b1, x)) - 1.0).abs() < 1e-9);
        assert!((simpson(&|x| m(b2, x) * m(b2, x)) - 1.0).abs() < 1e-9);
        assert!(simpson(&|x| m(b1, x) * m(b2, x)).abs() < 1e-9);
    }
}
