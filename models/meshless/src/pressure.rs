//! Follower pressure loads on boundary triangles, with their exact
//! stiffness.
//!
//! A uniform pressure `p` (Pa) on a flat triangle `(a, b, c)` (outward
//! normal by the right-hand rule) pushes against the outward normal with
//! the force `-p A n = -(p / 2) (b - a) x (c - a)` (N). For linear
//! triangles the consistent nodal forces (the external virtual work
//! `dW = -int p n . dv dA` with linear shape functions, which integrate
//! to `A / 3` each) give every node one third of it (Bonet & Wood,
//! *Nonlinear Continuum Mechanics for Finite Element Analysis*, 2nd ed.,
//! Sec. 6.5, external virtual work of a pressure):
//!
//! `f_a = f_b = f_c = N := -(p / 6) (b - a) x (c - a)`.
//!
//! The load **follows** the current (deformed) configuration. Its
//! derivative (the load stiffness, the linearization of that virtual work
//! in Bonet & Wood Sec. 6.5, here for flat linear triangles) is, writing `[v]x` for the cross-product matrix and
//! cycling `(a, b, c)`:
//!
//! `dN = -(p / 6) sum_k (x_{k+2} - x_{k+1}) x dx_k`, i.e.
//! `dN/dx_a = -(p/6) [c - b]x`, `dN/dx_b = -(p/6) [a - c]x`,
//! `dN/dx_c = -(p/6) [b - a]x`,
//!
//! and every node of the face receives `dN`. On a closed surface the nodal
//! forces are `-p dV/dx` (`V` the enclosed volume) and the load stiffness
//! is the symmetric `-p d2V/dx2`; on an open surface the edges on its
//! border add a skew part (Bonet & Wood Sec. 6.5: the pressure stiffness is
//! symmetric only when the boundary of the loaded surface is closed or
//! held). [`PressureLoad::add_jacobian`] gives the exact derivative,
//! [`PressureLoad::add_sym_stiffness`] its symmetric part for a conjugate
//! gradient solve.
//!
//! Units: positions m, pressures Pa, forces N.

use surgbench_core::Vec3;

/// Pressure faces of one body (node indices into the body's positions).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PressureLoad {
    /// Faces, nodes ordered with the outward normal by the right-hand rule.
    pub faces: Vec<[usize; 3]>,
    /// Pressure on each face at full load (Pa); positive pushes into the body.
    pub pressure: Vec<f64>,
}

impl PressureLoad {
    /// Loads from `(face, pressure)` pairs as [`surgbench_core::TissueBody`]
    /// stores them.
    pub fn new(faces: &[([usize; 3], f64)]) -> Self {
        Self {
            faces: faces.iter().map(|f| f.0).collect(),
            pressure: faces.iter().map(|f| f.1).collect(),
        }
    }

    /// Whether there is no pressure face.
    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// Nodal force of one face `N = -(s p / 6) (b - a) x (c - a)` (N),
    /// received by each of its three nodes.
    fn face_force(&self, k: usize, x: &[Vec3], scale: f64) -> Vec3 {
        let [a, b, c] = self.faces[k].map(|i| x[i]);
        (b - a).cross(&(c - a)) * (-scale * self.pressure[k] / 6.0)
    }

    /// Add the nodal forces (N) at positions `x` (m), loads scaled by
    /// `scale` (the control timeline's load factor), to `out`.
    pub fn add_forces(&self, x: &[Vec3], scale: f64, out: &mut [Vec3]) {
        for k in 0..self.faces.len() {
            let n = self.face_force(k, x, scale);
            for &i in &self.faces[k] {
                out[i] += n;
            }
        }
    }

    /// Total force of all faces on the body (N): `-sum s p A n`.
    pub fn resultant(&self, x: &[Vec3], scale: f64) -> Vec3 {
        (0..self.faces.len()).map(|k| self.face_force(k, x, scale) * 3.0).sum()
    }

    /// Add `J dx` to `out`, `J = d(force)/dx` the exact (generally
    /// non-symmetric) derivative of [`Self::add_forces`] at `x` (N/m).
    pub fn add_jacobian(&self, x: &[Vec3], scale: f64, dx: &[Vec3], out: &mut [Vec3]) {
        for (f, &p) in self.faces.iter().zip(&self.pressure) {
            let c = -scale * p / 6.0;
            let dn = (0..3).fold(Vec3::zeros(), |acc, k| {
                let e = x[f[(k + 2) % 3]] - x[f[(k + 1) % 3]];
                acc + e.cross(&dx[f[k]])
            }) * c;
            for &i in f {
                out[i] += dn;
            }
        }
    }

    /// Add `J^T y` to `out` (N/m times the units of `y`).
    pub fn add_jacobian_transpose(&self, x: &[Vec3], scale: f64, y: &[Vec3], out: &mut [Vec3]) {
        for (f, &p) in self.faces.iter().zip(&self.pressure) {
            let c = -scale * p / 6.0;
            let ysum = y[f[0]] + y[f[1]] + y[f[2]];
            // (e x .)^T = -(e x .) = (. x e): node k gets c ysum x e_k.
            for k in 0..3 {
                let e = x[f[(k + 2) % 3]] - x[f[(k + 1) % 3]];
                out[f[k]] += ysum.cross(&e) * c;
            }
        }
    }

    /// Add `K_s dx` to `out`: the symmetric part of the load stiffness
    /// `K = -J`, `K_s = -(J + J^T) / 2` (N/m), for a CG solve.
    pub fn add_sym_stiffness(&self, x: &[Vec3], scale: f64, dx: &[Vec3], out: &mut [Vec3]) {
        for (f, &p) in self.faces.iter().zip(&self.pressure) {
            // -(1/2) c (sum_k e_k x dx_k) to every node, -(1/2) c dxsum x e_k to node k.
            let h = 0.5 * scale * p / 6.0;
            let dxsum = dx[f[0]] + dx[f[1]] + dx[f[2]];
            let mut dn = Vec3::zeros();
            for k in 0..3 {
                let e = x[f[(k + 2) % 3]] - x[f[(k + 1) % 3]];
                dn += e.cross(&dx[f[k]]);
                out[f[k]] += dxsum.cross(&e) * h;
            }
            for &i in f {
                out[i] += dn * h;
            }
        }
    }
}
