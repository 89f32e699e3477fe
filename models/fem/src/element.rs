//! Linear tetrahedron kinematics: deformation gradient, element energy,
//! nodal forces and 12x12 stiffness blocks.
//!
//! With rest shape gradients `g_a` (the gradients of the barycentric
//! shape functions, `sum_a g_a = 0`), `F = sum_a x_a g_a^T`, the element
//! energy is `V psi(F)`, the internal (elastic) force on node `a` is
//! `f_a = -V P g_a` and the stiffness block is
//! `K_ab[i][j] = V (dP(e_j g_b^T) g_a)_i` (e.g. Sifakis and Barbic 2012,
//! "FEM simulation of 3D deformable solids", SIGGRAPH course, Sec. 4).

use crate::material::{Kinematics, Law, M3, Material};
use surgbench_core::{TetMesh, Vec3};

/// 16 3x3 blocks `K_ab` of an element's 12x12 stiffness, index `4 a + b`.
pub type ElemBlocks = [M3; 16];

/// Which element Jacobian the assembly uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Jacobian {
    /// Exact Hessian of the energy (may be indefinite at large strain).
    Exact,
    /// Exact Hessian with each element's negative eigenvalues clamped to
    /// zero (symmetric positive semi-definite; Teran et al. 2005 idea, on
    /// the full 12x12 block).
    Projected,
    /// Warped linear stiffness `R K0 R^T` (corotational only; Müller and
    /// Gross 2004): SPD, ignores the rotation's derivative.
    Warped,
}

/// Rest-state data of every tet.
#[derive(Debug, Clone)]
pub struct Elements {
    /// Node indices.
    pub tets: Vec<[usize; 4]>,
    /// Rest shape-function gradients `g_a` (1/m).
    pub grads: Vec<[Vec3; 4]>,
    /// Rest volumes (m^3), positive.
    pub vol: Vec<f64>,
}

impl Elements {
    /// Precompute from a mesh; errors name the first degenerate or inverted tet.
    pub fn new(mesh: &TetMesh) -> Result<Self, String> {
        let mut grads = Vec::with_capacity(mesh.tets.len());
        let mut vol = Vec::with_capacity(mesh.tets.len());
        for (e, t) in mesh.tets.iter().enumerate() {
            let p = t.map(|i| mesh.nodes[i]);
            let dm = M3::from_columns(&[p[1] - p[0], p[2] - p[0], p[3] - p[0]]);
            let v = dm.determinant() / 6.0;
            if !(v > 0.0) {
                return Err(format!(
                    "tet {e} has rest volume {v} m^3 (must be positive; see mesh::orient_positive)"
                ));
            }
            let inv = dm.try_inverse().ok_or_else(|| format!("tet {e} is degenerate"))?;
            // F = Ds Dm^-1: row k of Dm^-1 is the gradient of node k+1.
            let g1: Vec3 = inv.row(0).transpose();
            let g2: Vec3 = inv.row(1).transpose();
            let g3: Vec3 = inv.row(2).transpose();
            grads.push([-(g1 + g2 + g3), g1, g2, g3]);
            vol.push(v);
        }
        Ok(Self {
            tets: mesh.tets.clone(),
            grads,
            vol,
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.tets.len()
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.tets.is_empty()
    }

    /// Deformation gradient of element `e` at positions `x`.
    pub fn deformation_gradient(&self, e: usize, x: &[Vec3]) -> M3 {
        let t = &self.tets[e];
        let g = &self.grads[e];
        let mut f = M3::zeros();
        for a in 0..4 {
            f += x[t[a]] * g[a].transpose();
        }
        f
    }

    /// Energy `V psi`, forces `f_a = -V P g_a` and kinematics of element `e`.
    pub fn energy_forces(&self, mat: &Material, e: usize, x: &[Vec3]) -> (f64, [Vec3; 4], Kinematics) {
        let k = mat.kinematics(&self.deformation_gradient(e, x));
        let p = mat.pk1(&k);
        let v = self.vol[e];
        let g = &self.grads[e];
        (mat.energy_density(&k) * v, g.map(|ga| -(p * ga) * v), k)
    }

    /// Exact stiffness blocks `K_ab = d(-f_a)/dx_b` of element `e`.
    pub fn stiffness(&self, mat: &Material, e: usize, k: &Kinematics) -> ElemBlocks {
        let g = &self.grads[e];
        let v = self.vol[e];
        let mut out = [M3::zeros(); 16];
        for b in 0..4 {
            for j in 0..3 {
                let mut df = M3::zeros();
                df.set_row(j, &g[b].transpose());
                let dp = mat.dpk1(k, &df) * v;
                for a in 0..4 {
                    let col = dp * g[a];
                    out[4 * a + b].set_column(j, &col);
                }
            }
        }
        out
    }

    /// Rest (linear-elastic) stiffness `K0` of element `e` for Lamé
    /// parameters `(mu, lambda)`.
    pub fn rest_stiffness(&self, mu: f64, lambda: f64, e: usize) -> ElemBlocks {
        let lin = Material {
            law: Law::Linear,
            mu,
            lambda,
        };
        let k = lin.kinematics(&M3::identity());
        self.stiffness(&lin, e, &k)
    }
}

impl Elements {
    /// Warped stiffness `K_ab = R K0_ab R^T` of element `e` (Müller and
    /// Gross 2004) for Lamé parameters `(mu, lambda)` (Pa), from the
    /// rotated shape gradients `h_a = R g_a`. The linear-elastic block is
    /// `K0_ab = V (mu (g_a . g_b) I + mu g_b g_a^T + lambda g_a g_b^T)`
    /// (differentiate `P = mu (F + F^T - 2 I) + lambda tr(F - I) I` along
    /// `dF = e_j g_b^T` in `f_a = -V P g_a`), so
    /// `K_ab = V (mu (g_a . g_b) I + mu h_b h_a^T + lambda h_a h_b^T)`:
    /// about a third of the arithmetic of [`warp`]. Same symmetry
    /// (`K_ba = K_ab^T` exactly, symmetric diagonal blocks).
    pub fn warped_stiffness(&self, mu: f64, lambda: f64, e: usize, r: &M3) -> ElemBlocks {
        let mut up = [M3::zeros(); 10];
        self.warped_upper(mu, lambda, e, r, &mut up);
        let mut out = [M3::zeros(); 16];
        for a in 0..4 {
            for b in a..4 {
                let k = up[UPPER[a][b]];
                out[4 * a + b] = k;
                if b != a {
                    out[4 * b + a] = k.transpose();
                }
            }
        }
        out
    }

    /// The 10 blocks `K_ab`, `a <= b`, of [`Elements::warped_stiffness`]
    /// (same formula and arithmetic), written in place at `UPPER[a][b]`:
    /// what the assembly needs (`K_ba = K_ab^T`).
    pub fn warped_upper(&self, mu: f64, lambda: f64, e: usize, r: &M3, out: &mut UpperBlocks) {
        let g = &self.grads[e];
        let v = self.vol[e];
        let h = g.map(|ga| r * ga);
        let (vm, vl) = (v * mu, v * lambda);
        for a in 0..4 {
            for b in a..4 {
                let d = vm * g[a].dot(&g[b]);
                out[UPPER[a][b]] = if a == b {
                    // mu h h^T + lambda h h^T, symmetric entry by entry.
                    let c = vm + vl;
                    M3::from_fn(|i, j| c * (h[a][i] * h[a][j]) + if i == j { d } else { 0.0 })
                } else {
                    M3::from_fn(|i, j| vm * h[b][i] * h[a][j] + vl * h[a][i] * h[b][j] + if i == j { d } else { 0.0 })
                };
            }
        }
    }
}

/// The blocks `K_ab`, `a <= b`, of a symmetric 12x12 element matrix, at
/// index [`UPPER`]`[a][b]`.
pub type UpperBlocks = [M3; 10];

/// Index of block `(a, b)`, `a <= b`, in [`UpperBlocks`] (row-major upper
/// triangle); entries below the diagonal are unused.
pub const UPPER: [[usize; 4]; 4] = [[0, 1, 2, 3], [0, 4, 5, 6], [0, 0, 7, 8], [0, 0, 0, 9]];

/// The upper blocks of a full element matrix (its lower blocks are taken
/// as the transposes: exact for the symmetric warped stiffness, the
/// symmetric part up to round-off for the exact and projected Hessians).
pub fn upper_of(k: &ElemBlocks) -> UpperBlocks {
    let mut out = [M3::zeros(); 10];
    for a in 0..4 {
        for b in a..4 {
            out[UPPER[a][b]] = k[4 * a + b];
        }
    }
    out
}

/// Warp rest stiffness blocks by `R`: `K_ab = R K0_ab R^T`. `K0` is
/// symmetric (`K0_ba = K0_ab^T`), so only the 10 blocks with `a <= b` are
/// computed and the others mirrored: the result is exactly symmetric.
pub fn warp(k0: &ElemBlocks, r: &M3) -> ElemBlocks {
    let rt = r.transpose();
    let mut out = [M3::zeros(); 16];
    for a in 0..4 {
        for b in a..4 {
            let k = r * k0[4 * a + b] * rt;
            out[4 * a + b] = k;
            if b != a {
                out[4 * b + a] = k.transpose();
            } else {
                out[4 * a + a] = (k + k.transpose()) * 0.5;
            }
        }
    }
    out
}

/// Clamp the negative eigenvalues of a 12x12 element matrix to zero.
pub fn project_psd(k: &ElemBlocks) -> ElemBlocks {
    let mut m = nalgebra::SMatrix::<f64, 12, 12>::zeros();
    for a in 0..4 {
        for b in 0..4 {
            m.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(&k[4 * a + b]);
        }
    }
    let m = (m + m.transpose()) * 0.5;
    let eig = m.symmetric_eigen();
    let d = eig.eigenvalues.map(|l| l.max(0.0));
    let p = eig.eigenvectors * nalgebra::SMatrix::<f64, 12, 12>::from_diagonal(&d) * eig.eigenvectors.transpose();
    let mut out = [M3::zeros(); 16];
    for a in 0..4 {
        for b in 0..4 {
            out[4 * a + b] = p.fixed_view::<3, 3>(3 * a, 3 * b).into_owned();
        }
    }
    out
}

/// Rotation angle (rad) between two rotation matrices.
pub fn rotation_angle(r1: &M3, r2: &M3) -> f64 {
    let c = ((r1.transpose() * r2).trace() - 1.0) * 0.5;
    c.clamp(-1.0, 1.0).acos()
}

/// Degree-2 exact 4-point rule on the reference tet (Keast 1986, rule 2):
/// barycentric weights `(a, b, b, b)` and permutations, equal weights 1/4.
pub const QUAD4: [[f64; 4]; 4] = {
    const A: f64 = 0.585_410_196_624_968_5;
    const B: f64 = 0.138_196_601_125_010_5;
    [[A, B, B, B], [B, A, B, B], [B, B, A, B], [B, B, B, A]]
};
