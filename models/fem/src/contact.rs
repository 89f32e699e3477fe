//! Frictionless unilateral contact of the body's boundary nodes with a rigid
//! sphere (`surgbench_core::scene::SphereIndenter`), by a node-to-sphere
//! penalty.
//!
//! The law (gap, penalty rule `k_i = kappa E* sqrt(A_i)`, energy, Hessian)
//! and its citations are in [`surgbench_core::sphere_contact`]; this module
//! applies it to a [`TetMesh`]'s boundary faces and assembles it into the
//! block CSR stiffness. [`SphereContact::hessian_block`] can drop the
//! negative tangential term (`project`) where a positive semi-definite block
//! is needed.

use crate::material::M3;
use surgbench_core::sphere_contact::{self, node_stiffness, penetration};
use surgbench_core::{SolidMaterial, TetMesh, Vec3, mesh};

/// The penalty contact of one body with one rigid sphere.
#[derive(Debug, Clone, PartialEq)]
pub struct SphereContact {
    /// Boundary nodes (ascending): the candidates.
    pub nodes: Vec<usize>,
    /// Penalty stiffness of each candidate (N/m), the rule in the module docs.
    pub stiffness: Vec<f64>,
    /// Sphere centre now (m).
    pub centre: Vec3,
    /// Sphere radius (m).
    pub radius: f64,
}

impl SphereContact {
    /// Candidates and penalties of `mesh` (rest positions) made of
    /// `material`, with penalty factor `kappa` (> 0); sphere at `centre`
    /// with `radius`.
    pub fn new(mesh: &TetMesh, material: &SolidMaterial, kappa: f64, centre: Vec3, radius: f64) -> Self {
        let (nodes, stiffness) = node_stiffness(&mesh.nodes, &mesh::boundary_faces(mesh), material, kappa);
        Self {
            nodes,
            stiffness,
            centre,
            radius,
        }
    }

    /// `(k, g, d, n)` of candidate `j` at positions `x` if it penetrates
    /// (`g < 0`). A node exactly at the centre has no normal and is skipped
    /// (it would need a penetration of a whole radius).
    fn active(&self, j: usize, x: &[Vec3]) -> Option<(usize, f64, f64, f64, Vec3)> {
        let i = self.nodes[j];
        penetration(&x[i], &self.centre, self.radius).map(|(g, d, n)| (i, self.stiffness[j], g, d, n))
    }

    /// Contact energy `E_c` (J) at positions `x` (m).
    pub fn energy(&self, x: &[Vec3]) -> f64 {
        (0..self.nodes.len())
            .filter_map(|j| self.active(j, x))
            .map(|(_, k, g, _, _)| 0.5 * k * g * g)
            .sum()
    }

    /// Add the contact forces `-dE_c/dx` (N) to `r` (three entries per node).
    pub fn add_forces(&self, x: &[Vec3], r: &mut [f64]) {
        for j in 0..self.nodes.len() {
            if let Some((i, k, g, _, n)) = self.active(j, x) {
                let f = n * (-k * g);
                for a in 0..3 {
                    r[3 * i + a] += f[a];
                }
            }
        }
    }

    /// Hessian block `d^2E_c/dx_i^2` (N/m) of every penetrating node, in
    /// node order; `project` drops the negative tangential term (positive
    /// semi-definite blocks).
    pub fn hessian_blocks(&self, x: &[Vec3], project: bool) -> Vec<(usize, M3)> {
        (0..self.nodes.len())
            .filter_map(|j| self.active(j, x))
            .map(|(i, k, g, d, n)| (i, Self::hessian_block(k, g, d, &n, project)))
            .collect()
    }

    /// `k (n n^T + (g / d)(I - n n^T))`, without the second term when `project`.
    pub fn hessian_block(k: f64, g: f64, d: f64, n: &Vec3, project: bool) -> M3 {
        if project {
            n * n.transpose() * k
        } else {
            sphere_contact::hessian_block(k, g, d, n)
        }
    }

    /// Force the body exerts on the sphere (N): minus the sum of the
    /// contact forces on the nodes.
    pub fn reaction(&self, x: &[Vec3]) -> Vec3 {
        (0..self.nodes.len())
            .filter_map(|j| self.active(j, x))
            .map(|(_, k, g, _, n)| n * (k * g))
            .sum()
    }

    /// Deepest penetration `max(-g)` (m) over the candidates, 0 if none.
    pub fn max_penetration(&self, x: &[Vec3]) -> f64 {
        (0..self.nodes.len())
            .filter_map(|j| self.active(j, x))
            .map(|(_, _, g, _, _)| -g)
            .fold(0.0, f64::max)
    }

    /// Nodes in contact (penetrating) at `x`.
    pub fn active_count(&self, x: &[Vec3]) -> usize {
        (0..self.nodes.len()).filter(|&j| self.active(j, x).is_some()).count()
    }

    /// The block CSR matrix `kmat` (pattern `diag` gives each row's diagonal
    /// block) plus the contact Hessian at `x`; `None` when no node touches
    /// (the caller keeps using `kmat`).
    pub(crate) fn add_to(&self, kmat: &[M3], diag: &[usize], x: &[Vec3], project: bool) -> Option<Vec<M3>> {
        let blocks = self.hessian_blocks(x, project);
        if blocks.is_empty() {
            return None;
        }
        let mut k = kmat.to_vec();
        for (i, b) in blocks {
            k[diag[i]] += b;
        }
        Some(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::sphere_contact::DEFAULT_KAPPA;

    /// Gradient and Hessian against central differences of the energy and of
    /// the forces, at nodes penetrating by 0.1-30 % of the radius. Central
    /// differences with step h are O(h^2) accurate on the smooth branch
    /// (every perturbed node stays inside): with h = 1e-7 R the truncation
    /// is ~1e-14 relative and rounding ~eps E / h ~ 1e-9 of the force, so
    /// 1e-6 relative bounds both.
    #[test]
    fn contact_gradient_and_hessian_match_finite_differences() {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let mat = SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1000.0,
        };
        let radius = 0.7;
        let c = SphereContact::new(&m, &mat, DEFAULT_KAPPA, Vec3::new(0.45, 0.55, 1.5), radius);
        assert_eq!(c.nodes.len(), 8, "every node of one cube is on the boundary");
        // Top nodes (z = 1) moved to known depths inside the sphere.
        let mut x = m.nodes.clone();
        let depths = [1e-3, 0.05, 0.1, 0.3];
        let mut top = 0;
        for (i, p) in x.iter_mut().enumerate() {
            if m.nodes[i].z == 1.0 {
                let dir = (*p - c.centre).normalize();
                *p = c.centre + dir * (radius - depths[top] * radius);
                top += 1;
            }
        }
        assert_eq!(top, 4);
        assert_eq!(c.active_count(&x), 4);
        let mut f = vec![0.0; 3 * x.len()];
        c.add_forces(&x, &mut f);
        let fscale = f.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let h = 1e-7 * radius;
        let hess = c.hessian_blocks(&x, false);
        for (i, kb) in &hess {
            for a in 0..3 {
                let mut xp = x.clone();
                xp[*i][a] += h;
                let mut xm = x.clone();
                xm[*i][a] -= h;
                let fd = -(c.energy(&xp) - c.energy(&xm)) / (2.0 * h);
                assert!(
                    (fd - f[3 * i + a]).abs() <= 1e-6 * fscale,
                    "node {i} axis {a}: force {} vs -dE/dx {fd}",
                    f[3 * i + a]
                );
                let (mut fp, mut fm) = (vec![0.0; f.len()], vec![0.0; f.len()]);
                c.add_forces(&xp, &mut fp);
                c.add_forces(&xm, &mut fm);
                let kscale = kb.abs().max();
                for b in 0..3 {
                    // Hessian = -d(force)/dx.
                    let fd = -(fp[3 * i + b] - fm[3 * i + b]) / (2.0 * h);
                    assert!(
                        (fd - kb[(b, a)]).abs() <= 1e-6 * kscale,
                        "node {i} block ({b},{a}): {} vs FD {fd}",
                        kb[(b, a)]
                    );
                }
            }
        }
        // Newton's third law: the sphere gets minus the nodal forces.
        let total: Vec3 = (0..x.len())
            .map(|i| Vec3::new(f[3 * i], f[3 * i + 1], f[3 * i + 2]))
            .sum();
        assert!((c.reaction(&x) + total).norm() <= 1e-12 * fscale);
        assert!((c.max_penetration(&x) - 0.3 * radius).abs() <= 1e-12);
    }

    /// Outside the sphere nothing happens, and the energy is C^1 at the
    /// surface: force and energy vanish as the gap closes from inside.
    #[test]
    fn no_force_outside_and_continuous_at_the_surface() {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let mat = SolidMaterial {
            youngs_modulus: 1e4,
            poisson_ratio: 0.3,
            density: 1000.0,
        };
        let mut c = SphereContact::new(&m, &mat, DEFAULT_KAPPA, Vec3::new(0.0, 0.0, 2.0), 0.5);
        let x = m.nodes.clone();
        assert_eq!(c.energy(&x), 0.0);
        assert_eq!(c.reaction(&x), Vec3::zeros());
        assert!(c.hessian_blocks(&x, false).is_empty());
        // Node 4 (0,0,1) at gap -eps: force k eps, energy k eps^2 / 2.
        let i = m.nodes.iter().position(|p| *p == Vec3::new(0.0, 0.0, 1.0)).unwrap();
        let j = c.nodes.iter().position(|&n| n == i).unwrap();
        let k = c.stiffness[j];
        c.radius = 1.0 + 1e-9;
        let f = c.reaction(&x);
        assert!((f - Vec3::new(0.0, 0.0, k * 1e-9)).norm() <= 1e-6 * k * 1e-9, "{f:?}");
        assert!((c.energy(&x) - 0.5 * k * 1e-18).abs() <= 1e-6 * 0.5 * k * 1e-18);
    }

    /// The penalty rule: `kappa E* sqrt(A_i)`, with `A_i` a third of each
    /// adjacent boundary triangle. A unit cube's corner node touches three
    /// faces; each face is two triangles and the corner is in one or two of
    /// them, so its share lies between 3 * (1/2)/3 and 3 * 1/3.
    #[test]
    fn penalty_follows_the_rule() {
        let m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [1, 1, 1]);
        let mat = SolidMaterial {
            youngs_modulus: 9.1e3,
            poisson_ratio: 0.3,
            density: 1000.0,
        };
        let c = SphereContact::new(&m, &mat, 2.0, Vec3::zeros(), 1.0);
        let e_star = 9.1e3 / 0.91;
        let total_area: f64 = c.stiffness.iter().map(|k| (k / (2.0 * e_star)).powi(2)).sum();
        assert!(
            (total_area - 6.0).abs() <= 1e-12,
            "shares sum to the cube's area: {total_area}"
        );
        for k in &c.stiffness {
            let a = (k / (2.0 * e_star)).powi(2);
            assert!((0.5 - 1e-12..=1.0 + 1e-12).contains(&a), "share {a}");
        }
    }
}
