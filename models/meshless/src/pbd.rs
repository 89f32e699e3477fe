//! Position-based corrections the point-primitive vascular-tissue seed adds
//! on top of the elastic forces, projected with the standard PBD step
//! (Müller, Heidelberger, Hennix & Ratcliff 2007, "Position based dynamics",
//! JVCI 18, eqs. 8-9: `s = C / sum_j w_j |grad_j C|^2`,
//! `dp_i = -k s w_i grad_i C`, stiffness `k` in `[0, 1]`, Gauss-Seidel):
//!
//! * **stretching** between nodes joined by a mesh edge, `C = |p_a - p_b| - L0`;
//! * **elastic potential energy of virtual tetrahedra** (the mesh tets):
//!   springs from each of the four nodes to the barycentre `b`,
//!   `C = (1/2) sum_k (|p_k - b| - r_k)^2` (m^2, the spring energy per unit
//!   stiffness), `grad_m C = e_m n_m - (1/4) sum_k e_k n_k` with
//!   `e_k = |p_k - b| - r_k`, `n_k` the unit vector from `b` to `p_k`.
//!
//! Both are satisfied at rest; they make the model stiffer than its
//! continuum material (iteration-count dependent, as PBD stiffness is).
//! Positions in metres.

use surgbench_core::Vec3;

/// The constraints, with their rest values.
#[derive(Debug, Clone)]
pub struct PbdConstraints {
    /// Mesh edges.
    pub edges: Vec<[u32; 2]>,
    /// Edge rest lengths (m).
    pub edge_rest: Vec<f64>,
    /// Virtual tetrahedra.
    pub tets: Vec<[u32; 4]>,
    /// Rest distances of each tet node to the barycentre (m).
    pub tet_rest: Vec<[f64; 4]>,
    /// Stretch stiffness in `[0, 1]`.
    pub k_stretch: f64,
    /// Tet-energy stiffness in `[0, 1]`.
    pub k_tet: f64,
}

impl PbdConstraints {
    /// Constraints of `tets` over the `rest` positions (m).
    pub fn new(rest: &[Vec3], tets: &[[usize; 4]], k_stretch: f64, k_tet: f64) -> Self {
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(tets.len() * 2);
        for t in tets {
            for a in 0..4 {
                for b in a + 1..4 {
                    let (i, j) = (t[a].min(t[b]) as u32, t[a].max(t[b]) as u32);
                    edges.push([i, j]);
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let edge_rest = edges
            .iter()
            .map(|e| (rest[e[1] as usize] - rest[e[0] as usize]).norm())
            .collect();
        let tets32: Vec<[u32; 4]> = tets.iter().map(|t| t.map(|i| i as u32)).collect();
        let tet_rest = tets
            .iter()
            .map(|t| {
                let b = t.iter().map(|&i| rest[i]).sum::<Vec3>() / 4.0;
                t.map(|i| (rest[i] - b).norm())
            })
            .collect();
        Self {
            edges,
            edge_rest,
            tets: tets32,
            tet_rest,
            k_stretch,
            k_tet,
        }
    }

    /// Largest relative violation: `|C| / L0` over edges and
    /// `sqrt(2 C) / r_mean` over tets (dimensionless).
    pub fn residual(&self, x: &[Vec3]) -> f64 {
        let mut r: f64 = 0.0;
        for (e, l0) in self.edges.iter().zip(&self.edge_rest) {
            let l = (x[e[1] as usize] - x[e[0] as usize]).norm();
            r = r.max((l - l0).abs() / l0);
        }
        for (t, r0) in self.tets.iter().zip(&self.tet_rest) {
            let (c, _) = tet_energy(&t.map(|i| x[i as usize]), r0);
            let rm = r0.iter().sum::<f64>() / 4.0;
            r = r.max((2.0 * c).sqrt() / rm);
        }
        r
    }

    /// `iterations` Gauss-Seidel sweeps over all constraints. `w` are
    /// inverse masses (0 = held), `axis_free` masks components held by
    /// rollers. Returns the residual after the sweeps.
    pub fn project(&self, x: &mut [Vec3], w: &[f64], axis_free: &[Vec3], iterations: usize) -> f64 {
        for _ in 0..iterations {
            if self.k_stretch > 0.0 {
                for (e, &l0) in self.edges.iter().zip(&self.edge_rest) {
                    let (a, b) = (e[0] as usize, e[1] as usize);
                    let ws = w[a] + w[b];
                    let d = x[b] - x[a];
                    let l = d.norm();
                    if ws == 0.0 || l == 0.0 {
                        continue;
                    }
                    let n = d / l;
                    let s = self.k_stretch * (l - l0) / ws;
                    x[a] += (n * (s * w[a])).component_mul(&axis_free[a]);
                    x[b] -= (n * (s * w[b])).component_mul(&axis_free[b]);
                }
            }
            if self.k_tet > 0.0 {
                for (t, r0) in self.tets.iter().zip(&self.tet_rest) {
                    let idx = t.map(|i| i as usize);
                    let (c, g) = tet_energy(&idx.map(|i| x[i]), r0);
                    let den: f64 = (0..4).map(|k| w[idx[k]] * g[k].norm_squared()).sum();
                    if c == 0.0 || !(den > 0.0) {
                        continue;
                    }
                    let s = self.k_tet * c / den;
                    for k in 0..4 {
                        let i = idx[k];
                        x[i] -= (g[k] * (s * w[i])).component_mul(&axis_free[i]);
                    }
                }
            }
        }
        self.residual(x)
    }
}

/// Energy constraint of one virtual tet: `C = (1/2) sum_k (|p_k - b| - r_k)^2`
/// (m^2) and its gradients (m).
pub fn tet_energy(p: &[Vec3; 4], r0: &[f64; 4]) -> (f64, [Vec3; 4]) {
    let b = (p[0] + p[1] + p[2] + p[3]) / 4.0;
    let mut c = 0.0;
    let mut en = [Vec3::zeros(); 4];
    for k in 0..4 {
        let d = p[k] - b;
        let l = d.norm();
        let e = l - r0[k];
        c += 0.5 * e * e;
        if l > 0.0 {
            en[k] = d * (e / l);
        }
    }
    let mean = (en[0] + en[1] + en[2] + en[3]) / 4.0;
    (c, en.map(|v| v - mean))
}
