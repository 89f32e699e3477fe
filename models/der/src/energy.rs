//! Elastic energy terms of the discrete elastic rod and their exact
//! derivatives, one stencil at a time (SI units: positions in m, angles in
//! rad, energies in J).
//!
//! Notation follows Bergou et al. 2008, "Discrete Elastic Rods" (DER) and
//! Bergou et al. 2010, "Discrete Viscous Threads" (DVT), with the derivative
//! formulas of Jawed, Novelia & O'Reilly 2018, "A primer on the kinematics of
//! discrete elastic rods" (the primer), section 5:
//!
//! * edge `e^j = x_{j+1} - x_j`, unit tangent `t^j`, reference frame
//!   `(a_1^j, a_2^j = t^j x a_1^j)` carried in time by parallel transport,
//!   material frame `m_1 = cos(theta) a_1 + sin(theta) a_2`,
//!   `m_2 = -sin(theta) a_1 + cos(theta) a_2`;
//! * curvature binormal at vertex `i` (DER eq. 1):
//!   `kb = 2 e^{i-1} x e^i / (|e^{i-1}| |e^i| + e^{i-1} . e^i)`;
//! * material curvatures averaged over the two edges (DVT section 4.2,
//!   primer eq. 4.3): `kappa_1 = kb . (m_2^{i-1} + m_2^i) / 2`,
//!   `kappa_2 = -kb . (m_1^{i-1} + m_1^i) / 2`;
//! * twist (DVT eq. 5 with the reference twist of section 6):
//!   `m_i = theta^i - theta^{i-1} + m_ref,i`.
//!
//! Energies (DVT eqs. 3-6): stretch `1/2 EA |e_bar| (|e|/|e_bar| - 1)^2`, bend
//! `1/(2 l_i) sum_k B_k (kappa_k - kappa_bar_k)^2`, twist
//! `GJ/(2 l_i) (m_i - m_bar_i)^2`, with the Voronoi length
//! `l_i = (|e_bar^{i-1}| + |e_bar^i|)/2`.
//!
//! # Which derivative
//! A vertex's gradient here is the standard DER force: the exact gradient of
//! the energy when the reference frames have just been parallel-transported to
//! the current tangents (the frame's own change contributes nothing to first
//! order because `kb` is normal to both tangents). Its *Jacobian*
//! ([`VertexTerms::jac`]) is the exact derivative of that gradient function,
//! with the frames transported from the configuration where it is evaluated
//! (primer section 5, but without symmetrisation). It is not symmetric: the
//! transport term `kb (x) m_2 / |e|^2` appears on one side only. Its symmetric
//! part equals the exact Hessian of the energy `E(x; frames transported from
//! x0)` at `x0`, which is what the Newton solver uses (the primer's
//! `(kb (x) m2 + m2 (x) kb)/(4|e|^2)` terms). Both facts are checked against
//! finite differences in `tests/derivatives.rs`.

use surgbench_core::frames::{parallel_transport, signed_angle};
use surgbench_core::{Mat3, Vec3};

/// Local degrees of freedom of a bending/twisting stencil, in order:
/// `[x_{i-1} (3), theta^{i-1}, x_i (3), theta^i, x_{i+1} (3)]`.
pub const VERTEX_DOFS: usize = 11;

/// Geometry and frames of one interior vertex `i` (edges `i-1` and `i`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stencil {
    /// Node positions `x_{i-1}, x_i, x_{i+1}` (m).
    pub x: [Vec3; 3],
    /// Twist angles of edges `i-1` and `i` relative to their reference frames (rad).
    pub theta: [f64; 2],
    /// Reference directors `a_1` of edges `i-1` and `i` (unit, normal to the edge).
    pub ref_d1: [Vec3; 2],
    /// Reference twist `m_ref,i` at the vertex (rad), see [`reference_twist`].
    pub ref_twist: f64,
}

/// Material parameters of one vertex (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexParams {
    /// Bending stiffnesses `(B_1, B_2)` about `m_1` and `m_2` (N m^2).
    pub bend: [f64; 2],
    /// Rest material curvature `(kappa_bar_1, kappa_bar_2)` (dimensionless,
    /// `2 tan(phi/2)` of the rest turning angle `phi`).
    pub kappa_bar: [f64; 2],
    /// Twisting stiffness `G J` (N m^2).
    pub twist: f64,
    /// Rest twist `m_bar` (rad).
    pub twist_bar: f64,
    /// Voronoi length `l_i` (m).
    pub voronoi: f64,
}

/// Energy, gradient and Jacobian of one vertex term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexTerms {
    /// Energy (J).
    pub energy: f64,
    /// Gradient over the [`VERTEX_DOFS`] local DOFs (N or N m).
    pub grad: [f64; VERTEX_DOFS],
    /// Jacobian of the gradient, `jac[r][c] = d grad[r] / d u[c]`.
    pub jac: [[f64; VERTEX_DOFS]; VERTEX_DOFS],
}

impl Default for VertexTerms {
    fn default() -> Self {
        Self {
            energy: 0.0,
            grad: [0.0; VERTEX_DOFS],
            jac: [[0.0; VERTEX_DOFS]; VERTEX_DOFS],
        }
    }
}

/// Parallel-transport a reference director from an edge's old tangent to its
/// new one and re-orthonormalise it (DER section 5, "time-parallel" frame).
pub fn transport_director(a1: &Vec3, t_old: &Vec3, t_new: &Vec3) -> Vec3 {
    let p = parallel_transport(a1, t_old, t_new);
    let q = p - t_new * t_new.dot(&p);
    let n = q.norm();
    if n > 0.0 { q / n } else { *a1 }
}

/// Reference twist at a vertex (DVT section 6): the signed angle about `t1`
/// from the space-parallel transport of `a1_prev` (edge `i-1`) to `a1_next`
/// (edge `i`), unwrapped by multiples of `2 pi` to lie closest to `previous`
/// so that accumulated turns are not lost.
pub fn reference_twist(a1_prev: &Vec3, t0: &Vec3, a1_next: &Vec3, t1: &Vec3, previous: f64) -> f64 {
    let p = parallel_transport(a1_prev, t0, t1);
    let ang = signed_angle(&p, a1_next, t1);
    let two_pi = 2.0 * std::f64::consts::PI;
    ang + two_pi * ((previous - ang) / two_pi).round()
}

/// Material directors `(m_1, m_2)` of an edge from its tangent, reference
/// director and twist angle.
pub fn material_frame(t: &Vec3, a1: &Vec3, theta: f64) -> (Vec3, Vec3) {
    let a2 = t.cross(a1);
    let (s, c) = theta.sin_cos();
    (a1 * c + a2 * s, a2 * c - a1 * s)
}

/// Shared geometry of a vertex.
struct Geo {
    l: [f64; 2],
    t: [Vec3; 2],
    chi: f64,
    tt: Vec3,
    kb: Vec3,
    m1: [Vec3; 2],
    m2: [Vec3; 2],
}

fn geo(st: &Stencil) -> Geo {
    let a = st.x[1] - st.x[0];
    let b = st.x[2] - st.x[1];
    let (la, lb) = (a.norm(), b.norm());
    let (ta, tb) = (a / la, b / lb);
    let chi = 1.0 + ta.dot(&tb);
    let kb = ta.cross(&tb) * (2.0 / chi);
    let tt = (ta + tb) / chi;
    let (m1a, m2a) = material_frame(&ta, &st.ref_d1[0], st.theta[0]);
    let (m1b, m2b) = material_frame(&tb, &st.ref_d1[1], st.theta[1]);
    Geo {
        l: [la, lb],
        t: [ta, tb],
        chi,
        tt,
        kb,
        m1: [m1a, m1b],
        m2: [m2a, m2b],
    }
}

fn skew(v: &Vec3) -> Mat3 {
    Mat3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl Geo {
    /// Sign and "other" tangent in `f_c`: `kb` is `+2 ta x tb / chi`.
    fn other(&self, c: usize) -> (f64, Vec3) {
        if c == 0 { (1.0, self.t[1]) } else { (-1.0, self.t[0]) }
    }

    /// `f_c(w) = (d kb / d e_c)^T w` for a fixed vector `w` (primer eq. 5.7
    /// with `w` in place of the averaged director).
    fn f(&self, c: usize, w: &Vec3) -> Vec3 {
        let (sg, to) = self.other(c);
        (to.cross(w) * (2.0 * sg / self.chi) - self.tt * self.kb.dot(w)) / self.l[c]
    }

    /// `d kb / d e_d` (3x3).
    fn dkb(&self, d: usize) -> Mat3 {
        let (sg, to) = self.other(d);
        // kb = 2 t_a x t_b / chi: d/de_a = (-2 [t_b]x / chi - kb tt^T)/l_a,
        // d/de_b = (2 [t_a]x / chi - kb tt^T)/l_b.
        (skew(&to) * (-2.0 * sg / self.chi) - self.kb * self.tt.transpose()) / self.l[d]
    }

    /// Projector normal to edge `d`, divided by its length: `d t_d / d e_d`.
    fn dt(&self, d: usize) -> Mat3 {
        (Mat3::identity() - self.t[d] * self.t[d].transpose()) / self.l[d]
    }

    /// `d chi / d e_d` as a column vector.
    fn dchi(&self, d: usize) -> Vec3 {
        let to = self.t[1 - d];
        (to - self.t[d] * self.t[d].dot(&to)) / self.l[d]
    }

    /// `d f_c(w) / d e_d` for fixed `w` (second derivative of `kb . w`).
    fn df(&self, c: usize, d: usize, w: &Vec3) -> Mat3 {
        let (sg, to) = self.other(c);
        let s = self.kb.dot(w);
        let fd = self.f(d, w);
        let dchi = self.dchi(d);
        let dtt = self.dt(d) / self.chi - self.tt * dchi.transpose() / self.chi;
        let u = to.cross(w);
        // d(t_o x w)/d e_d = -[w]x d t_o / d e_d, non-zero only when d is the other edge.
        let du = if d != c { -skew(w) * self.dt(d) } else { Mat3::zeros() };
        let cross_term = (du / self.chi - u * dchi.transpose() / (self.chi * self.chi)) * (2.0 * sg);
        let mut res = (cross_term - dtt * s - self.tt * fd.transpose()) / self.l[c];
        if c == d {
            res -= self.f(c, w) * self.t[c].transpose() / self.l[c];
        }
        res
    }
}

/// Local index of edge-space component: `e_a` (edge i-1) and `e_b` (edge i)
/// enter the node DOFs with these signs: `x_{i-1}: -e_a`, `x_i: +e_a - e_b`,
/// `x_{i+1}: +e_b`.
const NODE_OFF: [usize; 3] = [0, 4, 8];
const COEF: [[f64; 2]; 3] = [[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]];
const THETA_OFF: [usize; 2] = [3, 7];

/// Edge-space accumulator: gradient over `(e_a, e_b, theta_a, theta_b)` and
/// the 8x8 Jacobian, mapped to node DOFs at the end.
struct EdgeSpace {
    ge: [Vec3; 2],
    gth: [f64; 2],
    jee: [[Mat3; 2]; 2],
    jet: [[Vec3; 2]; 2],
    jte: [[Vec3; 2]; 2],
    jtt: [[f64; 2]; 2],
}

impl EdgeSpace {
    fn new() -> Self {
        Self {
            ge: [Vec3::zeros(); 2],
            gth: [0.0; 2],
            jee: [[Mat3::zeros(); 2]; 2],
            jet: [[Vec3::zeros(); 2]; 2],
            jte: [[Vec3::zeros(); 2]; 2],
            jtt: [[0.0; 2]; 2],
        }
    }

    /// Add `k g (x) g` for an edge-space gradient `g = (ge, gth)`.
    fn add_outer(&mut self, k: f64, ge: &[Vec3; 2], gth: &[f64; 2]) {
        for c in 0..2 {
            for d in 0..2 {
                self.jee[c][d] += ge[c] * ge[d].transpose() * k;
                self.jet[c][d] += ge[c] * (gth[d] * k);
                self.jte[c][d] += ge[d] * (gth[c] * k);
                self.jtt[c][d] += gth[c] * gth[d] * k;
            }
        }
    }

    fn write(&self, out: &mut VertexTerms) {
        for p in 0..3 {
            let gp = self.ge[0] * COEF[p][0] + self.ge[1] * COEF[p][1];
            for k in 0..3 {
                out.grad[NODE_OFF[p] + k] += gp[k];
            }
        }
        for j in 0..2 {
            out.grad[THETA_OFF[j]] += self.gth[j];
        }
        for p in 0..3 {
            for q in 0..3 {
                let mut m = Mat3::zeros();
                for c in 0..2 {
                    for d in 0..2 {
                        let w = COEF[p][c] * COEF[q][d];
                        if w != 0.0 {
                            m += self.jee[c][d] * w;
                        }
                    }
                }
                for r in 0..3 {
                    for s in 0..3 {
                        out.jac[NODE_OFF[p] + r][NODE_OFF[q] + s] += m[(r, s)];
                    }
                }
            }
            for j in 0..2 {
                let et = self.jet[0][j] * COEF[p][0] + self.jet[1][j] * COEF[p][1];
                let te = self.jte[j][0] * COEF[p][0] + self.jte[j][1] * COEF[p][1];
                for r in 0..3 {
                    out.jac[NODE_OFF[p] + r][THETA_OFF[j]] += et[r];
                    out.jac[THETA_OFF[j]][NODE_OFF[p] + r] += te[r];
                }
            }
        }
        for j in 0..2 {
            for k in 0..2 {
                out.jac[THETA_OFF[j]][THETA_OFF[k]] += self.jtt[j][k];
            }
        }
    }
}

fn bend_into(g: &Geo, p: &VertexParams, acc: &mut EdgeSpace) -> f64 {
    let v1 = (g.m2[0] + g.m2[1]) * 0.5;
    let v2 = -(g.m1[0] + g.m1[1]) * 0.5;
    let kappa1 = g.kb.dot(&v1);
    let kappa2 = g.kb.dot(&v2);
    // Per-edge curvatures k1_j = kb . m2_j, k2_j = -kb . m1_j.
    let k1 = [g.kb.dot(&g.m2[0]), g.kb.dot(&g.m2[1])];
    let k2 = [-g.kb.dot(&g.m1[0]), -g.kb.dot(&g.m1[1])];
    let c1 = p.bend[0] / p.voronoi;
    let c2 = p.bend[1] / p.voronoi;
    let d1 = kappa1 - p.kappa_bar[0];
    let d2 = kappa2 - p.kappa_bar[1];
    // Gradients of kappa_1, kappa_2 (primer eqs. 5.7-5.9):
    // d kappa_1 / d theta_j = -kb . m1_j / 2, d kappa_2 / d theta_j = -kb . m2_j / 2.
    let gk1e = [g.f(0, &v1), g.f(1, &v1)];
    let gk1t = [k2[0] * 0.5, k2[1] * 0.5];
    let gk2e = [g.f(0, &v2), g.f(1, &v2)];
    let gk2t = [-k1[0] * 0.5, -k1[1] * 0.5];
    for c in 0..2 {
        acc.ge[c] += gk1e[c] * (c1 * d1) + gk2e[c] * (c2 * d2);
        acc.gth[c] += gk1t[c] * (c1 * d1) + gk2t[c] * (c2 * d2);
    }
    acc.add_outer(c1, &gk1e, &gk1t);
    acc.add_outer(c2, &gk2e, &gk2t);
    // Second-order terms, linear in the weighted director w.
    let w = v1 * (c1 * d1) + v2 * (c2 * d2);
    for c in 0..2 {
        for d in 0..2 {
            acc.jee[c][d] += g.df(c, d, &w);
        }
        // Transport of the frame of edge c with its own tangent:
        // d m_2/d e_c = -t_c m_2^T / |e_c|, and (d kb / d e_c)^T t_c = -kb / |e_c|.
        let lc2 = g.l[c] * g.l[c];
        acc.jee[c][c] += g.kb * (g.m2[c] * (c1 * d1) - g.m1[c] * (c2 * d2)).transpose() / (2.0 * lc2);
        for j in 0..2 {
            // d v1/d theta_j = -m1_j/2, d v2/d theta_j = -m2_j/2.
            let wt = -(g.m1[j] * (c1 * d1) + g.m2[j] * (c2 * d2)) * 0.5;
            let blk = g.f(c, &wt);
            acc.jet[c][j] += blk;
            acc.jte[j][c] += blk;
        }
        acc.jtt[c][c] += -(c1 * d1 * k1[c] + c2 * d2 * k2[c]) * 0.5;
    }
    0.5 * (c1 * d1 * d1 + c2 * d2 * d2)
}

fn twist_into(g: &Geo, st: &Stencil, p: &VertexParams, acc: &mut EdgeSpace) -> f64 {
    let m = st.theta[1] - st.theta[0] + st.ref_twist - p.twist_bar;
    let k = p.twist / p.voronoi;
    let mu = k * m;
    // d m / d e_c = kb / (2 |e_c|) (DER section 7, primer eq. 5.11).
    let h = [g.kb / (2.0 * g.l[0]), g.kb / (2.0 * g.l[1])];
    let ht = [-1.0, 1.0];
    for c in 0..2 {
        acc.ge[c] += h[c] * mu;
        acc.gth[c] += ht[c] * mu;
    }
    acc.add_outer(k, &h, &ht);
    for c in 0..2 {
        for d in 0..2 {
            let mut blk = g.dkb(d) / (2.0 * g.l[c]);
            if c == d {
                blk -= g.kb * g.t[c].transpose() / (2.0 * g.l[c] * g.l[c]);
            }
            acc.jee[c][d] += blk * mu;
        }
    }
    0.5 * k * m * m
}

/// Bending energy of one vertex with its gradient and Jacobian.
pub fn bend(st: &Stencil, p: &VertexParams) -> VertexTerms {
    let g = geo(st);
    let mut acc = EdgeSpace::new();
    let mut out = VertexTerms {
        energy: bend_into(&g, p, &mut acc),
        ..Default::default()
    };
    acc.write(&mut out);
    out
}

/// Twisting energy of one vertex with its gradient and Jacobian.
pub fn twist(st: &Stencil, p: &VertexParams) -> VertexTerms {
    let g = geo(st);
    let mut acc = EdgeSpace::new();
    let mut out = VertexTerms {
        energy: twist_into(&g, st, p, &mut acc),
        ..Default::default()
    };
    acc.write(&mut out);
    out
}

/// Bending plus twisting of one vertex (the solver's hot path): shares the
/// geometry between both terms and accumulates into `out` (which is zeroed).
pub fn bend_twist(st: &Stencil, p: &VertexParams, out: &mut VertexTerms) {
    let g = geo(st);
    let mut acc = EdgeSpace::new();
    out.energy = bend_into(&g, p, &mut acc) + twist_into(&g, st, p, &mut acc);
    out.grad = [0.0; VERTEX_DOFS];
    out.jac = [[0.0; VERTEX_DOFS]; VERTEX_DOFS];
    acc.write(out);
}

/// Bending plus twisting energy only (J), for line searches.
pub fn bend_twist_energy(st: &Stencil, p: &VertexParams) -> f64 {
    let g = geo(st);
    let kappa1 = g.kb.dot(&(g.m2[0] + g.m2[1])) * 0.5;
    let kappa2 = -g.kb.dot(&(g.m1[0] + g.m1[1])) * 0.5;
    let d1 = kappa1 - p.kappa_bar[0];
    let d2 = kappa2 - p.kappa_bar[1];
    let m = st.theta[1] - st.theta[0] + st.ref_twist - p.twist_bar;
    0.5 * (p.bend[0] * d1 * d1 + p.bend[1] * d2 * d2 + p.twist * m * m) / p.voronoi
}

/// Material curvature `(kappa_1, kappa_2)` of a vertex (dimensionless).
pub fn curvature(st: &Stencil) -> [f64; 2] {
    let g = geo(st);
    [
        g.kb.dot(&(g.m2[0] + g.m2[1])) * 0.5,
        -g.kb.dot(&(g.m1[0] + g.m1[1])) * 0.5,
    ]
}

/// Stretching energy of one edge `x0 -> x1` with axial stiffness `ea` (N) and
/// rest length `rest` (m): `1/2 EA |e_bar| (|e|/|e_bar| - 1)^2` (DVT eq. 3).
/// Returns the energy, the gradient with respect to `x1` (the gradient for
/// `x0` is its negative) and the exact, symmetric Hessian block `d^2E/dx1^2`.
pub fn stretch(x0: &Vec3, x1: &Vec3, ea: f64, rest: f64) -> (f64, Vec3, Mat3) {
    let e = x1 - x0;
    let l = e.norm();
    let t = e / l;
    let strain = l / rest - 1.0;
    let g = t * (ea * strain);
    let h = t * t.transpose() * (ea / rest) + (Mat3::identity() - t * t.transpose()) * (ea * strain / l);
    (0.5 * ea * rest * strain * strain, g, h)
}

/// Stretching energy only (J).
pub fn stretch_energy(x0: &Vec3, x1: &Vec3, ea: f64, rest: f64) -> f64 {
    let strain = (x1 - x0).norm() / rest - 1.0;
    0.5 * ea * rest * strain * strain
}
