//! Point-primitive elasticity (Müller et al. 2004, "Point based animation of
//! elastic, plastic and melting objects", SCA, Sec. 4), total Lagrangian:
//! neighbourhoods, weights and moment matrices are built once at rest.
//!
//! **Gradient by moving least squares.** For node `i` with rest neighbours
//! `j` (`|X_ij| < h_i`, `X_ij = X_j - X_i`) and poly6 weights
//! `w_ij = W(|X_ij|, h_i)` ([`crate::kernel::poly6`]), the weighted least-squares fit of the
//! displacement gives `grad u|_i = (sum_j w_ij u_ji X_ij^T) A_i^-1` with the
//! moment matrix `A_i = sum_j w_ij X_ij X_ij^T` (Müller et al. 2004, the
//! MLS derivation of Sec. 4.1). With `d_ij = A_i^-1 X_ij w_ij` and
//! `sum_j X_ij d_ij^T = I` the deformation gradient is
//! `F_i = I + grad u|_i = sum_j x_ij d_ij^T` (`x_ij` current). Any affine
//! field is reproduced exactly (each `F_i` is its matrix).
//!
//! **Per-node support radius.** Each node has its own radius `h_i` (Müller
//! et al. 2004 likewise give each phyxel a support proportional to its mean
//! distance to its nearest neighbours), so a graded mesh keeps about the
//! same neighbour count everywhere ([`crate::model`] sets
//! `h_i = support_factor l_i`, `l_i` the node's local edge length). The neighbourhoods are then not symmetric (`j` may see `i`
//! while `i` does not see `j`), which costs nothing: `F_i` depends on node
//! `i`'s own neighbourhood alone, the energy below is a sum of per-node
//! terms `U_i(x_i, x_{N(i)})`, and the forces and Hessian-vector products
//! are assembled term by term, each scattering `dU_i/dx_j` to the `j` of
//! `N(i)` and its negated sum to `i`. They stay the exact derivatives of
//! the energy whatever the radii.
//!
//! **Material.** Green strain `E = (F^T F - I) / 2`, St Venant–Kirchhoff
//! stress `S = lambda tr(E) I + 2 mu E` (Lamé parameters from `E`, `nu`),
//! energy `U_i = v_i psi(F_i)`, `psi = (1/2) E : S = mu E:E + lambda/2 tr(E)^2`
//! (Müller et al. 2004, Sec. 3-4: strain, stress, `U = 1/2 eps . sigma`).
//! With `P = F S`, `dU_i/dx_j = v_i P_i d_ij` and `dU_i/dx_i = -sum_j` of
//! those, so the forces of every node's energy sum to zero (and their torque
//! vanishes: `psi` is frame invariant).
//!
//! **Zero-energy modes and their control.** A point-wise gradient cannot see
//! displacement patterns even about every node (on a lattice, the
//! checkerboard `(-1)^(i+j+k)`): they cost no energy. We add the hourglass
//! penalty of Ganzenmüller (2015, "An hourglass control algorithm for
//! Lagrangian Smooth Particle Hydrodynamics", CMAME 286), here as an energy:
//! `U^hg_i = (k v_i / 2) sum_j a_ij |F_i X_ij - x_ij|^2` with
//! `a_ij = w_ij / (|X_ij|^2 sum_j w_ij)` and `k = gamma E` (Pa). It is zero
//! for every affine field (so it never biases homogeneous states), frame
//! invariant and quadratic in the positions; `gamma = 0` switches it off.
//!
//! Units: positions m, volumes m^3, energies J, forces N.

use surgbench_core::material::lame;
use surgbench_core::{Mat3, Vec3};

use crate::kdtree::KdTree;
use crate::kernel::poly6;

/// Why the point discretisation could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum DiscretizationError {
    /// A support radius is not usable (non-positive or not finite), or
    /// there is not one per node.
    BadRadius(String),
    /// A node's moment matrix is singular or too ill-conditioned: its
    /// neighbours (within the support radius) do not span 3D.
    SingularMoment {
        /// Node index.
        node: usize,
        /// Neighbour count.
        neighbours: usize,
        /// Smallest over largest eigenvalue of `A_i`.
        rcond: f64,
    },
}

impl std::fmt::Display for DiscretizationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadRadius(s) => f.write_str(s),
            Self::SingularMoment {
                node,
                neighbours,
                rcond,
            } => write!(
                f,
                "node {node} has {neighbours} neighbours within its support radius and a moment matrix with rcond {rcond:.2e} (they do not span 3D): raise the support radius"
            ),
        }
    }
}

/// Conditioning `lambda_min / lambda_max` of node `i`'s moment matrix
/// `A_i = sum_j w_ij X_ij X_ij^T` (poly6 weights at support `h` m) over the
/// rest positions `rest` indexed by `tree`; 0 when no neighbour has weight.
/// `found` is scratch space. [`PointElastic::new`] refuses `rcond <= 1e-8`.
pub fn moment_rcond(rest: &[Vec3], tree: &KdTree, i: usize, h: f64, found: &mut Vec<usize>) -> f64 {
    tree.within(&rest[i], h, found);
    let mut m = Mat3::zeros();
    for &j in found.iter() {
        let x = rest[j] - rest[i];
        m += x * x.transpose() * poly6(x.norm(), h);
    }
    let eig = m.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if hi > 0.0 { lo / hi } else { 0.0 }
}

/// Per-node cache of a configuration: deformation gradient `F` and second
/// Piola–Kirchhoff stress `S` (Pa), and the hourglass moments `G`.
#[derive(Debug, Clone, Default)]
pub struct StateCache {
    /// Deformation gradients.
    pub f: Vec<Mat3>,
    /// Second Piola–Kirchhoff stresses (Pa).
    pub s: Vec<Mat3>,
}

/// The point discretisation of an elastic body.
#[derive(Debug, Clone)]
pub struct PointElastic {
    /// Rest positions (m).
    pub rest: Vec<Vec3>,
    /// Node volumes (m^3).
    pub volume: Vec<f64>,
    /// Support radius `h_i` of node `i`'s poly6 weight (m).
    pub radius: Vec<f64>,
    /// Shear modulus (Pa).
    pub mu: f64,
    /// First Lamé parameter (Pa).
    pub lambda: f64,
    /// Hourglass stiffness `k = gamma E` (Pa).
    pub k_hg: f64,
    offs: Vec<usize>,
    nbr: Vec<u32>,
    d: Vec<Vec3>,
    xr: Vec<Vec3>,
    a: Vec<f64>,
}

/// One support radius per node of `rest`, each positive and finite (m).
fn check_radii(rest: &[Vec3], radius: &[f64]) -> Result<(), DiscretizationError> {
    if radius.len() != rest.len() {
        return Err(DiscretizationError::BadRadius(format!(
            "{} support radii for {} nodes",
            radius.len(),
            rest.len()
        )));
    }
    if let Some(i) = radius.iter().position(|h| !(*h > 0.0 && h.is_finite())) {
        return Err(DiscretizationError::BadRadius(format!(
            "node {i} has support radius {} m: must be > 0 and finite",
            radius[i]
        )));
    }
    Ok(())
}

impl PointElastic {
    /// Build neighbourhoods (node `i` sees the nodes closer than
    /// `radius[i]` m, found with a [`KdTree`]), poly6 weights
    /// `W(|X_ij|, h_i)` and `d_ij = A_i^-1 X_ij w_ij` for every node. `k_hg`
    /// is the hourglass stiffness (Pa). Fails if a radius is not positive
    /// and finite, if there is not one per node, or if a moment matrix has
    /// `lambda_min / lambda_max < 1e-8` (naming the node).
    pub fn new(
        rest: &[Vec3],
        volume: &[f64],
        radius: &[f64],
        youngs_modulus: f64,
        poisson_ratio: f64,
        k_hg: f64,
    ) -> Result<Self, DiscretizationError> {
        check_radii(rest, radius)?;
        let tree = KdTree::new(rest);
        let (mu, lambda) = lame(youngs_modulus, poisson_ratio);
        let n = rest.len();
        let mut offs = Vec::with_capacity(n + 1);
        offs.push(0);
        let (mut nbr, mut d, mut xr, mut a) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut found = Vec::new();
        for i in 0..n {
            let h = radius[i];
            tree.within(&rest[i], h, &mut found);
            let mut m = Mat3::zeros();
            let mut wsum = 0.0;
            let start = nbr.len();
            for &j in &found {
                if j == i {
                    continue;
                }
                let x = rest[j] - rest[i];
                let w = poly6(x.norm(), h);
                if w <= 0.0 {
                    continue;
                }
                m += x * x.transpose() * w;
                wsum += w;
                nbr.push(j as u32);
                xr.push(x);
                a.push(w);
            }
            let count = nbr.len() - start;
            let eig = m.symmetric_eigenvalues();
            let (lo, hi) = (eig.min(), eig.max());
            let rcond = if hi > 0.0 { lo / hi } else { 0.0 };
            if !(rcond > 1e-8) {
                return Err(DiscretizationError::SingularMoment {
                    node: i,
                    neighbours: count,
                    rcond,
                });
            }
            let minv = m.try_inverse().ok_or(DiscretizationError::SingularMoment {
                node: i,
                neighbours: count,
                rcond,
            })?;
            for k in start..nbr.len() {
                let w = a[k];
                d.push(minv * xr[k] * w);
                a[k] = w / (wsum * xr[k].norm_squared());
            }
            offs.push(nbr.len());
        }
        Ok(Self {
            rest: rest.to_vec(),
            volume: volume.to_vec(),
            radius: radius.to_vec(),
            mu,
            lambda,
            k_hg,
            offs,
            nbr,
            d,
            xr,
            a,
        })
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    /// Whether there are no nodes.
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// Total neighbour-pair count (work measure).
    pub fn pair_count(&self) -> usize {
        self.nbr.len()
    }

    /// Neighbours of node `i` (ascending).
    pub fn neighbours(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.nbr[self.offs[i]..self.offs[i + 1]].iter().map(|&j| j as usize)
    }

    /// Deformation gradient `F_i = sum_j (x_j - x_i) d_ij^T` at positions `x` (m).
    pub fn deformation_gradient(&self, i: usize, x: &[Vec3]) -> Mat3 {
        let mut f = Mat3::zeros();
        for k in self.offs[i]..self.offs[i + 1] {
            let j = self.nbr[k] as usize;
            f += (x[j] - x[i]) * self.d[k].transpose();
        }
        f
    }

    /// St Venant–Kirchhoff energy density (J/m^3) and second Piola–Kirchhoff stress (Pa).
    pub fn stvk(&self, f: &Mat3) -> (f64, Mat3) {
        let e = (f.transpose() * f - Mat3::identity()) * 0.5;
        let tr = e.trace();
        let s = Mat3::identity() * (self.lambda * tr) + e * (2.0 * self.mu);
        (self.mu * e.norm_squared() + 0.5 * self.lambda * tr * tr, s)
    }

    /// Fill `cache` with `F_i` and `S_i` at positions `x`.
    pub fn prepare(&self, x: &[Vec3], cache: &mut StateCache) {
        cache.f.resize(self.len(), Mat3::zeros());
        cache.s.resize(self.len(), Mat3::zeros());
        for i in 0..self.len() {
            let f = self.deformation_gradient(i, x);
            cache.f[i] = f;
            cache.s[i] = self.stvk(&f).1;
        }
    }

    /// Strain energy `sum_i v_i psi(F_i)` and hourglass energy (J) at `x`.
    pub fn energy(&self, x: &[Vec3]) -> (f64, f64) {
        let (mut u, mut hg) = (0.0, 0.0);
        for i in 0..self.len() {
            let f = self.deformation_gradient(i, x);
            u += self.volume[i] * self.stvk(&f).0;
            if self.k_hg > 0.0 {
                let mut s = 0.0;
                for k in self.offs[i]..self.offs[i + 1] {
                    let j = self.nbr[k] as usize;
                    s += self.a[k] * (f * self.xr[k] - (x[j] - x[i])).norm_squared();
                }
                hg += 0.5 * self.k_hg * self.volume[i] * s;
            }
        }
        (u, hg)
    }

    /// Add the internal forces `-dU/dx` (N) at `x` to `out`; `cache` must be
    /// [`Self::prepare`]d at `x`.
    pub fn add_forces(&self, x: &[Vec3], cache: &StateCache, out: &mut [Vec3]) {
        for i in 0..self.len() {
            let f = cache.f[i];
            let p = f * cache.s[i];
            let v = self.volume[i];
            let range = self.offs[i]..self.offs[i + 1];
            let mut m = p;
            if self.k_hg > 0.0 {
                let mut g = Mat3::zeros();
                for k in range.clone() {
                    let j = self.nbr[k] as usize;
                    let eps = f * self.xr[k] - (x[j] - x[i]);
                    g += eps * self.xr[k].transpose() * self.a[k];
                }
                m += g * self.k_hg;
            }
            let mut fi = Vec3::zeros();
            for k in range {
                let j = self.nbr[k] as usize;
                let mut gij = m * self.d[k];
                if self.k_hg > 0.0 {
                    let eps = f * self.xr[k] - (x[j] - x[i]);
                    gij -= eps * (self.k_hg * self.a[k]);
                }
                gij *= v;
                out[j] -= gij;
                fi += gij;
            }
            out[i] += fi;
        }
    }

    /// Add the Hessian-vector product `H dx` (N) at the configuration of
    /// `cache` to `out`: `dF_i = sum_j dx_ij d_ij^T`, `dE = sym(F^T dF)`,
    /// `dS = lambda tr(dE) I + 2 mu dE`, `dP = dF S + F dS`, assembled like
    /// the forces (plus the hourglass term, which is quadratic).
    pub fn add_hess_vec(&self, cache: &StateCache, dx: &[Vec3], out: &mut [Vec3]) {
        for i in 0..self.len() {
            let f = cache.f[i];
            let range = self.offs[i]..self.offs[i + 1];
            let df = self.deformation_gradient(i, dx);
            let de = (f.transpose() * df + df.transpose() * f) * 0.5;
            let ds = Mat3::identity() * (self.lambda * de.trace()) + de * (2.0 * self.mu);
            let mut m = df * cache.s[i] + f * ds;
            if self.k_hg > 0.0 {
                let mut g = Mat3::zeros();
                for k in range.clone() {
                    let j = self.nbr[k] as usize;
                    let eps = df * self.xr[k] - (dx[j] - dx[i]);
                    g += eps * self.xr[k].transpose() * self.a[k];
                }
                m += g * self.k_hg;
            }
            let v = self.volume[i];
            let mut hi = Vec3::zeros();
            for k in range {
                let j = self.nbr[k] as usize;
                let mut gij = m * self.d[k];
                if self.k_hg > 0.0 {
                    let eps = df * self.xr[k] - (dx[j] - dx[i]);
                    gij -= eps * (self.k_hg * self.a[k]);
                }
                gij *= v;
                out[j] += gij;
                hi -= gij;
            }
            out[i] += hi;
        }
    }
}
