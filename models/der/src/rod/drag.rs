//! Blood-flow drag on the rod (the law in the parent module docs, the
//! constants in [`surgbench_core::flow`]).

use super::*;
use surgbench_core::flow::{BLOOD_DENSITY, DRAG_NORMAL, DRAG_TANGENTIAL};
use surgbench_core::{Mat3, Vec3};

impl DerRod {
    /// Drag coefficients `(c_n, c_t)` (N s^2/m^2) of the half of free
    /// edge `j` next to a node: `rho C d l / 2` and `rho C_t pi d l / 2`
    /// with `l = |e_j| / 2`; zero for the ghost edge and out of range.
    pub(super) fn half_edge_drag(&self, j: usize) -> [f64; 2] {
        if !(j >= 1 && j < self.n - 1) {
            return [0.0; 2];
        }
        let l = 0.5 * self.rest_len[j];
        let d = self.edge_diam[j];
        [
            0.5 * BLOOD_DENSITY * DRAG_NORMAL * d * l,
            0.5 * BLOOD_DENSITY * DRAG_TANGENTIAL * std::f64::consts::PI * d * l,
        ]
    }

    /// Drag force (N) on node `k` at velocity `v` in flow `w`, with the
    /// tangents `t` of its two half-edges (edges `k-1`, `k`):
    /// `sum c_n |u_n| u_n + c_t |u_t| u_t` with `u = w - v`, and its
    /// Jacobian over `u`, `dF/du` (symmetric positive semi-definite).
    pub(super) fn node_drag(&self, k: usize, v: &Vec3, w: &Vec3, t: [Vec3; 2]) -> (Vec3, Mat3) {
        let u = w - v;
        let mut f = Vec3::zeros();
        let mut h = Mat3::zeros();
        for (i, j) in [k.wrapping_sub(1), k].into_iter().enumerate() {
            let [cn, ct] = self.half_edge_drag(j);
            if cn == 0.0 {
                continue;
            }
            let tj = t[i];
            let ut = tj * tj.dot(&u);
            let un = u - ut;
            let (nn, nt) = (un.norm(), ut.norm());
            f += un * (cn * nn) + ut * (ct * nt);
            if nn > 0.0 {
                h += ((Mat3::identity() - tj * tj.transpose()) * nn + un * un.transpose() / nn) * cn;
            }
            h += tj * tj.transpose() * (2.0 * ct * nt);
        }
        (f, h)
    }

    /// Tangents of the two half-edges of node `k` (edges `k-1` and `k`,
    /// clamped to the valid range) from `tan`.
    pub(super) fn half_edge_tangents(tan: &[Vec3], k: usize) -> [Vec3; 2] {
        let last = tan.len() - 1;
        [tan[k.saturating_sub(1).min(last)], tan[k.min(last)]]
    }

    /// Freeze the flow velocity at every node and the edge tangents for the
    /// coming step's drag.
    pub(super) fn begin_drag(&mut self, dt: f64, newmark: bool) {
        let Some(flow) = self.flow.clone() else {
            return;
        };
        self.drag_a = if newmark { 2.0 / dt } else { 1.0 / dt };
        for k in 0..self.n {
            self.drag_flow[k] = flow.velocity(&self.node(k));
        }
        self.drag_tan[..self.n - 1].copy_from_slice(&self.tan);
    }
}
