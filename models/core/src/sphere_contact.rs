//! Frictionless unilateral contact of a tissue's boundary nodes with a rigid
//! sphere (`crate::scene::SphereIndenter`) by a node-to-sphere penalty: the
//! law the penalty-based tissue models (fem, meshless) share.
//!
//! With the gap `g_i = |x_i - c| - R` of boundary node `i` (negative inside
//! the sphere of centre `c` and radius `R`) the contact energy is
//!
//! `E_c = sum_i k_i / 2 <g_i>_-^2`, `<g>_- = min(g, 0)`,
//!
//! the penalty regularisation of the Signorini conditions `g >= 0, p >= 0,
//! p g = 0` (Wriggers, *Computational Contact Mechanics*, 2nd ed. 2006,
//! Sec. 6.3, eq. 6.47). With `d = |x - c|` and `n = (x - c) / d` the
//! sphere's outward normal, a penetrating node (`g < 0`, [`penetration`])
//! has
//!
//! `dE_c/dx_i = k_i g_i n` (the force `-k_i g_i n` pushes it out along `+n`),
//! `d^2E_c/dx_i^2 = k_i (n n^T + (g_i / d)(I - n n^T))` ([`hessian_block`]),
//!
//! whose tangential part is negative (`g < 0`) but `|g| / d` times the
//! normal one. `E_c` is C^1: the Hessian jumps where a node touches the
//! surface.
//!
//! **Penalty rule** ([`node_stiffness`]). Node `i` gets
//! `k_i = kappa E* sqrt(A_i)` (N/m), `E* = E / (1 - nu^2)` the plane-strain
//! modulus ([`crate::material::plane_strain_modulus`]) and `A_i` the node's
//! share of the rest boundary area (a third of each boundary triangle it
//! belongs to). `2 E* a` is the stiffness of a rigid flat punch of radius
//! `a` on a half-space (Johnson, *Contact Mechanics*, 1985, eq. 3.36,
//! `F = 2 a E* delta`), so `E* sqrt(A_i)` is the order of the tissue's
//! stiffness under one node's patch and `kappa` (fidelity
//! `contact_stiffness`, default [`DEFAULT_KAPPA`]) says how much stiffer the
//! penalty spring is. A node carrying the contact pressure `p` penetrates by
//! `|g| = p A_i / k_i = p sqrt(A_i) / (kappa E*)`: over the local mesh size,
//! the contact strain `p / E*` divided by `kappa`.
//!
//! Units are SI (m, N, J).
//!
//! ```
//! use surgbench_core::sphere_contact::{hessian_block, penetration};
//! use surgbench_core::Vec3;
//! let (g, d, n) = penetration(&Vec3::new(0.0, 0.0, 0.9), &Vec3::zeros(), 1.0).unwrap();
//! assert!((g + 0.1).abs() < 1e-15 && (d - 0.9).abs() < 1e-15 && n == Vec3::z());
//! assert!(penetration(&Vec3::new(0.0, 0.0, 1.1), &Vec3::zeros(), 1.0).is_none());
//! let h = hessian_block(10.0, g, d, &n);
//! assert!((h[(2, 2)] - 10.0).abs() < 1e-12 && h[(0, 0)] < 0.0);
//! ```

use crate::material::{SolidMaterial, plane_strain_modulus};
use crate::{Mat3, Vec3};

/// Default penalty factor `kappa` of the rule `k_i = kappa E* sqrt(A_i)`:
/// the penetration it leaves is the contact strain over 100 of the local
/// mesh size (below 1e-3 of it for strains under 10 %).
pub const DEFAULT_KAPPA: f64 = 100.0;

/// Contact candidates and their penalty stiffnesses (the rule in the module
/// docs): every node that carries boundary area, ascending, with
/// `k_i = kappa E* sqrt(A_i)` (N/m). `rest` are the rest positions (m),
/// `faces` the boundary triangles (node indices), `kappa > 0`.
pub fn node_stiffness(
    rest: &[Vec3],
    faces: &[[usize; 3]],
    material: &SolidMaterial,
    kappa: f64,
) -> (Vec<usize>, Vec<f64>) {
    let mut area = vec![0.0; rest.len()];
    for f in faces {
        let [a, b, c] = f.map(|i| rest[i]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for &i in f {
            area[i] += third;
        }
    }
    let e_star = plane_strain_modulus(material.youngs_modulus, material.poisson_ratio);
    let nodes: Vec<usize> = (0..rest.len()).filter(|&i| area[i] > 0.0).collect();
    let stiffness = nodes.iter().map(|&i| kappa * e_star * area[i].sqrt()).collect();
    (nodes, stiffness)
}

/// `(g, d, n)` of a node at `x` against the sphere (`centre`, `radius`, m)
/// if it penetrates (`g < 0`): the gap `g = d - R`, the distance
/// `d = |x - c|` and the outward normal `n = (x - c) / d`. A node exactly at
/// the centre has no normal and gives `None` (it would need a penetration of
/// a whole radius).
#[inline]
pub fn penetration(x: &Vec3, centre: &Vec3, radius: f64) -> Option<(f64, f64, Vec3)> {
    let r = x - centre;
    let d = r.norm();
    let g = d - radius;
    (g < 0.0 && d > 0.0).then(|| (g, d, r / d))
}

/// Hessian block `d^2E_c/dx_i^2 = k (n n^T + (g / d)(I - n n^T))` (N/m) of a
/// penetrating node with stiffness `k`, gap `g`, distance `d` and normal `n`.
#[inline]
pub fn hessian_block(k: f64, g: f64, d: f64, n: &Vec3) -> Mat3 {
    let nn = n * n.transpose();
    (nn + (Mat3::identity() - nn) * (g / d)) * k
}
