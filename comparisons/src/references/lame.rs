//! The Lamé solution of a thick-walled tube under internal pressure.

/// Radial displacement (m) at radius `r` of a thick-walled tube (radii
/// `a < b`, m) under internal pressure `p` (Pa), plane strain, linear
/// elasticity (Timoshenko & Goodier, *Theory of Elasticity*, 3rd ed.,
/// Sec. 28, with `E -> E/(1-nu^2)`, `nu -> nu/(1-nu)` for plane strain):
/// `u(r) = p a^2 / (E (b^2 - a^2)) ((1+nu)(1-2nu) r + (1+nu) b^2 / r)`.
pub fn lame_radial_displacement(r: f64, a: f64, b: f64, p: f64, e: f64, nu: f64) -> f64 {
    p * a * a / (e * (b * b - a * a)) * ((1.0 + nu) * (1.0 - 2.0 * nu) * r + (1.0 + nu) * b * b / r)
}
