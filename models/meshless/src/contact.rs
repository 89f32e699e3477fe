//! Frictionless unilateral contact of the body's surface nodes with a rigid
//! sphere (`surgbench_core::scene::SphereIndenter`), by a node-to-sphere
//! penalty added to the Newton objective of the implicit integrators.
//!
//! The law (gap, penalty rule `k_i = kappa E* sqrt(A_i)`, energy, Hessian)
//! and its citations are in [`surgbench_core::sphere_contact`], the same as
//! the `fem` model's, so the two differ only in their elasticity. The
//! Newton-CG of [`crate::model`] uses the exact Hessian (its Steihaug guard
//! handles the negative tangential curvature).

use surgbench_core::scene::SphereIndenter;
use surgbench_core::sphere_contact::{self, node_stiffness, penetration};
use surgbench_core::{Mat3, SolidMaterial, Vec3};

/// The penalty contact of one body with one rigid sphere moving along its
/// path.
#[derive(Debug, Clone, PartialEq)]
pub struct SphereContact {
    /// Candidate nodes (ascending mesh indices): every boundary vertex.
    pub nodes: Vec<usize>,
    /// Penalty stiffness of each candidate (N/m), the rule in the module docs.
    pub stiffness: Vec<f64>,
    /// The sphere's path and radius.
    pub path: SphereIndenter,
    /// Sphere centre now (m): `path.centre_at(s)` at the last load factor.
    pub centre: Vec3,
}

impl SphereContact {
    /// Candidates and penalties for the body with rest positions `rest`
    /// (m), boundary triangles `faces` (mesh node indices) and `material`,
    /// penalty factor `kappa` (> 0), sphere `path` at load factor 0.
    pub fn new(
        rest: &[Vec3],
        faces: &[[usize; 3]],
        material: &SolidMaterial,
        kappa: f64,
        path: SphereIndenter,
    ) -> Self {
        let (nodes, stiffness) = node_stiffness(rest, faces, material, kappa);
        Self {
            nodes,
            stiffness,
            centre: path.centre,
            path,
        }
    }

    /// Move the sphere to load factor `s` (the command's `load`).
    pub fn set_load(&mut self, s: f64) {
        self.centre = self.path.centre_at(s);
    }

    /// `(node, k, g, d, n)` of candidate `j` at `x` if it penetrates. A node
    /// exactly at the centre has no normal and is skipped.
    #[inline]
    fn active(&self, j: usize, x: &[Vec3]) -> Option<(usize, f64, f64, f64, Vec3)> {
        let i = self.nodes[j];
        penetration(&x[i], &self.centre, self.path.radius).map(|(g, d, n)| (i, self.stiffness[j], g, d, n))
    }

    fn each_active(&self, x: &[Vec3]) -> impl Iterator<Item = (usize, f64, f64, f64, Vec3)> {
        (0..self.nodes.len()).filter_map(move |j| self.active(j, x))
    }

    /// Contact energy `E_c` (J) at `x` (m).
    pub fn energy(&self, x: &[Vec3]) -> f64 {
        self.each_active(x).map(|(_, k, g, _, _)| 0.5 * k * g * g).sum()
    }

    /// Add `dE_c/dx` (N) to `grad` (one entry per node).
    pub fn add_gradient(&self, x: &[Vec3], grad: &mut [Vec3]) {
        for (i, k, g, _, n) in self.each_active(x) {
            grad[i] += n * (k * g);
        }
    }

    /// Add the Hessian-vector product `(d^2E_c/dx^2) p` (N) at `x` to `out`.
    pub fn add_hess_vec(&self, x: &[Vec3], p: &[Vec3], out: &mut [Vec3]) {
        for (i, k, g, d, n) in self.each_active(x) {
            out[i] += Self::hessian_block(k, g, d, &n) * p[i];
        }
    }

    /// `k (n n^T + (g / d)(I - n n^T))` (N/m).
    pub fn hessian_block(k: f64, g: f64, d: f64, n: &Vec3) -> Mat3 {
        sphere_contact::hessian_block(k, g, d, n)
    }

    /// Force the body exerts on the sphere (N): minus the sum of the contact
    /// forces `-k_i g_i n_i` on the nodes, i.e. `sum_i k_i g_i n_i`.
    pub fn reaction(&self, x: &[Vec3]) -> Vec3 {
        self.each_active(x).map(|(_, k, g, _, n)| n * (k * g)).sum()
    }

    /// Deepest penetration `max(-g)` (m) over the candidates, 0 if none.
    pub fn max_penetration(&self, x: &[Vec3]) -> f64 {
        self.each_active(x).map(|(_, _, g, _, _)| -g).fold(0.0, f64::max)
    }

    /// Nodes inside the sphere at `x`.
    pub fn active_count(&self, x: &[Vec3]) -> usize {
        self.each_active(x).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::mesh;
    use surgbench_core::sphere_contact::DEFAULT_KAPPA;

    fn material() -> SolidMaterial {
        SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1000.0,
        }
    }

    /// A one-cube block whose four top nodes sit at depths 0.1 %, 5 %, 10 %
    /// and 30 % of the radius inside a sphere above it.
    fn pressed_cube() -> (SphereContact, Vec<Vec3>) {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let faces = mesh::boundary_faces(&m);
        let radius = 0.7;
        let path = SphereIndenter {
            centre: Vec3::new(0.45, 0.55, 1.5),
            radius,
            travel: Vec3::zeros(),
        };
        let c = SphereContact::new(&m.nodes, &faces, &material(), DEFAULT_KAPPA, path);
        let mut x = m.nodes.clone();
        let depths = [1e-3, 0.05, 0.1, 0.3];
        let mut top = 0;
        for p in x.iter_mut() {
            if p.z == 1.0 {
                let dir = (*p - c.centre).normalize();
                *p = c.centre + dir * (radius * (1.0 - depths[top]));
                top += 1;
            }
        }
        assert_eq!(top, 4);
        (c, x)
    }

    /// Gradient and Hessian-vector product against central differences of
    /// the energy and of the gradient. Every perturbed node stays inside
    /// (smooth branch), so the differences are O(h^2): with h = 1e-7 R the
    /// truncation is ~1e-14 relative and the rounding ~eps E / h ~ 1e-9 of
    /// the gradient; 1e-6 relative bounds both.
    #[test]
    fn gradient_and_hessian_vector_product_match_finite_differences() {
        let (c, x) = pressed_cube();
        assert_eq!(c.active_count(&x), 4);
        let n = x.len();
        let mut g = vec![Vec3::zeros(); n];
        c.add_gradient(&x, &mut g);
        let gscale = g.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let h = 1e-7 * c.path.radius;
        for i in 0..n {
            for a in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[i][a] += h;
                xm[i][a] -= h;
                let fd = (c.energy(&xp) - c.energy(&xm)) / (2.0 * h);
                assert!(
                    (fd - g[i][a]).abs() <= 1e-6 * gscale,
                    "node {i} axis {a}: gradient {} vs dE/dx {fd}",
                    g[i][a]
                );
            }
        }
        // H p for a seeded direction p, against (grad(x + h p) - grad(x - h p)) / 2h.
        let mut rng = surgbench_core::rng::SplitMix64(7);
        let p: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5))
            .collect();
        let mut hp = vec![Vec3::zeros(); n];
        c.add_hess_vec(&x, &p, &mut hp);
        let (mut gp, mut gm) = (vec![Vec3::zeros(); n], vec![Vec3::zeros(); n]);
        let xp: Vec<Vec3> = x.iter().zip(&p).map(|(a, b)| a + b * h).collect();
        let xm: Vec<Vec3> = x.iter().zip(&p).map(|(a, b)| a - b * h).collect();
        c.add_gradient(&xp, &mut gp);
        c.add_gradient(&xm, &mut gm);
        let hscale = hp.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..n {
            let fd = (gp[i] - gm[i]) / (2.0 * h);
            assert!(
                (fd - hp[i]).norm() <= 1e-6 * hscale,
                "node {i}: H p = {:?} vs FD {fd:?}",
                hp[i]
            );
        }
        // Newton's third law: the sphere gets minus the forces -grad on the nodes.
        let total: Vec3 = g.iter().sum();
        assert!((c.reaction(&x) - total).norm() <= 1e-12 * gscale);
        assert!((c.max_penetration(&x) - 0.3 * c.path.radius).abs() <= 1e-12);
    }

    /// Outside the sphere there is no energy, gradient or stiffness, and at
    /// the surface the energy is C^1: at gap `-eps` the force is `k eps`.
    #[test]
    fn nothing_outside_and_continuous_at_the_surface() {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let faces = mesh::boundary_faces(&m);
        let path = SphereIndenter {
            centre: Vec3::new(0.0, 0.0, 2.0),
            radius: 0.5,
            travel: Vec3::new(0.0, 0.0, -0.5),
        };
        let mut c = SphereContact::new(&m.nodes, &faces, &material(), DEFAULT_KAPPA, path);
        let x = m.nodes.clone();
        assert_eq!(c.energy(&x), 0.0);
        assert_eq!(c.reaction(&x), Vec3::zeros());
        let mut hp = vec![Vec3::zeros(); x.len()];
        c.add_hess_vec(&x, &vec![Vec3::repeat(1.0); x.len()], &mut hp);
        assert!(hp.iter().all(|v| *v == Vec3::zeros()));
        // At s = 1 - 1e-9 / 0.5 the sphere overlaps node (0, 0, 1) by 1e-9 m.
        c.set_load(1.0 + 2e-9);
        let j = c
            .nodes
            .iter()
            .position(|&i| m.nodes[i] == Vec3::new(0.0, 0.0, 1.0))
            .unwrap();
        let k = c.stiffness[j];
        let f = c.reaction(&x);
        // Rounding of |x - c| (~1e-16 m) against the 1e-9 m gap: 1e-6 relative.
        assert!((f - Vec3::new(0.0, 0.0, k * 1e-9)).norm() <= 1e-6 * k * 1e-9, "{f:?}");
    }

    /// The penalty rule `kappa E* sqrt(A_i)`: the shares `A_i` of a unit
    /// cube sum to its area, 6.
    #[test]
    fn penalty_follows_the_rule() {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [2, 2, 2]);
        let faces = mesh::boundary_faces(&m);
        let path = SphereIndenter {
            centre: Vec3::zeros(),
            radius: 1.0,
            travel: Vec3::zeros(),
        };
        let c = SphereContact::new(&m.nodes, &faces, &material(), 2.0, path);
        let e_star = 1e4 / 0.91;
        let total: f64 = c.stiffness.iter().map(|k| (k / (2.0 * e_star)).powi(2)).sum();
        assert!((total - 6.0).abs() <= 1e-12, "shares sum to {total}");
        assert_eq!(c.nodes.len(), 26, "every node of a 3x3x3 grid but the centre");
    }
}
