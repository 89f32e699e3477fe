//! Closed forms of a rigid frictionless sphere pressed into an elastic
//! half-space: Hertz's paraboloid and the exact spherical profile.

/// Hertz force (N) of a rigid sphere of radius `r` (m) pressed `delta` (m)
/// into an elastic half-space (`E` Pa, `nu`), frictionless:
/// `F = (4/3) E* sqrt(R) delta^(3/2)`, `E* = E / (1 - nu^2)` (Hertz 1882;
/// Johnson, *Contact Mechanics*, 1985, eqs. 4.22-4.23). Small strain, the
/// sphere taken as a paraboloid (`a << R`).
pub fn hertz_force(r: f64, delta: f64, e: f64, nu: f64) -> f64 {
    4.0 / 3.0 * e / (1.0 - nu * nu) * r.sqrt() * delta.max(0.0).powf(1.5)
}

/// Hertz contact radius (m): `a = sqrt(R delta)` (Johnson 1985, eq. 4.22).
pub fn hertz_contact_radius(r: f64, delta: f64) -> f64 {
    (r * delta.max(0.0)).sqrt()
}

/// The same contact with the exact spherical profile instead of Hertz's
/// paraboloid, still linear elasticity on a half-space (Segedin 1957,
/// Mathematika 4; Maugis, *Contact, Adhesion and Rupture of Elastic
/// Solids*, 2000, eq. 3.103): with `L = ln((R + a)/(R - a))`,
/// `delta = (a/2) L` and `F = (E*/2) ((a^2 + R^2) L - 2 a R)`. Returns
/// `(F (N), a (m))` at `delta` (solved for `a` by bisection; `delta < R`).
/// Its ratio to [`hertz_force`] is the paraboloid bias of the Hertz
/// reference: expanding both in `a / R`, `1 - delta / (10 R) + O((delta/R)^2)`
/// (the sphere is softer: less material under it than under the paraboloid).
pub fn sphere_force_exact(r: f64, delta: f64, e: f64, nu: f64) -> (f64, f64) {
    let depth = |a: f64| 0.5 * a * ((r + a) / (r - a)).ln();
    let (mut lo, mut hi) = (0.0, r * (1.0 - 1e-12));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if depth(mid) < delta {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let a = 0.5 * (lo + hi);
    let l = ((r + a) / (r - a)).ln();
    (0.5 * e / (1.0 - nu * nu) * ((a * a + r * r) * l - 2.0 * a * r), a)
}
