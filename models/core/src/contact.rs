//! Contact and Coulomb friction response shared by rod models.
//!
//! A node of mass `m` (kg) ends a time step at a predicted position `x` (m)
//! with velocity `v` (m/s). If it is closer to the vessel wall than the
//! contact margin (`phi(x) > -margin`, with `phi` the [`Sdf`], negative in the
//! lumen), [`respond`] applies one inelastic contact impulse with Coulomb
//! friction (Moreau's velocity-level contact law; see Bridson, Fedkiw &
//! Anderson 2002, "Robust treatment of collisions, contact and friction for
//! cloth animation", section 7.2, for the same friction update):
//!
//! 1. project `x` back to the margin surface along the SDF normal `n`
//!    (a few Newton steps on `phi(x) + margin = 0`), depth `d > 0`;
//! 2. normal impulse `j_n = m max(v.n, d/dt)`: it stops the inward normal
//!    velocity and, for a node that was resting on the wall at the start of
//!    the step (`d = dt v.n` under backward Euler), equals `dt` times the
//!    contact force exactly;
//! 3. tangential velocity `v_t`: if the impulse needed to stop it,
//!    `m |v_t|`, is at most `mu_s j_n` the node *sticks* (`v_t -> 0`);
//!    otherwise it *slides* and loses `mu_d j_n / m` of tangential speed;
//! 4. the tangential velocity change is also applied to the position
//!    (`dx_t = dt dv_t`), consistent with `x_{n+1} = x_n + dt v_{n+1}`, so a
//!    sticking node does not creep.
//!
//! The force estimate is `impulse / dt` (N), the force the wall exerts on the
//! node. Units are SI throughout.
//!
//! # Friction inside an implicit solve
//! A post-step impulse sees only the node's own momentum: for a stiff rod
//! with light lumped nodes the impulse needed to stop a node is always tiny,
//! so a node pushed along the wall by the elastic forces "sticks" every step
//! and the rod is compressed without limit. Solvers that minimise an
//! incremental potential can instead add [`LaggedFriction`], the smoothed,
//! lagged Coulomb friction potential of Li et al. 2020 ("Incremental
//! Potential Contact", ACM TOG 39(4), section 5): with the normal force
//! `lambda` and wall normal `n` frozen at the start of the step, the
//! tangential displacement over the step `u = (I - n n^T)(x - x_start)` and
//! `y = |u|`, the potential `D(x) = mu lambda f_0(y)` has the force
//! `-mu lambda f_1(y) u / y`, where the mollifier `f_1(y) = 2y/eps - y^2/eps^2`
//! below `eps` and `1` above smooths the stick-slip switch over a slip of
//! `eps` per step (see [`friction_mollifier`]). `D` is convex and C2, so
//! Newton with a line search converges through stick-slip transitions.
//! ```
//! use surgbench_core::contact::{respond, ContactState};
//! use surgbench_core::sdf::StraightTube;
//! use surgbench_core::{ContactParams, Vec3};
//! let tube = StraightTube { origin: Vec3::zeros(), axis: Vec3::x(), radius: 1e-3 };
//! let params = ContactParams { friction_static: 0.3, friction_dynamic: 0.2, margin: 0.0 };
//! // A node 0.1 mm past the wall, moving outward and along the axis.
//! let c = respond(&tube, &params, &Vec3::new(0.0, 0.0, 1.1e-3), &Vec3::new(1e-3, 0.0, 0.1), 1e-4, 1e-3).unwrap();
//! assert!(c.position.z <= 1e-3 + 1e-15);
//! assert_eq!(c.state, ContactState::Sticking);
//! ```

use crate::scene::ContactParams;
use crate::sdf::Sdf;
use crate::{Mat3, Vec3};

/// Friction state of a contact after the response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactState {
    /// Tangential velocity removed: static friction held.
    Sticking,
    /// Tangential velocity reduced by dynamic friction.
    Sliding,
}

/// The outcome of [`respond`] for one node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeContact {
    /// Corrected position (m).
    pub position: Vec3,
    /// Corrected velocity (m/s).
    pub velocity: Vec3,
    /// Impulse the wall gave the node over the step (N s).
    pub impulse: Vec3,
    /// Unit wall normal at the contact (out of the lumen, into the wall).
    pub normal: Vec3,
    /// How far the predicted position was past the margin surface (m), >= 0.
    pub depth: f64,
    /// Stick or slip.
    pub state: ContactState,
}

impl NodeContact {
    /// Average force the wall exerted on the node over a step `dt` (N).
    pub fn force(&self, dt: f64) -> Vec3 {
        self.impulse / dt
    }
}

/// Unit normal of the SDF at `p`, or `None` where the gradient vanishes.
fn unit_normal(sdf: &dyn Sdf, p: &Vec3) -> Option<Vec3> {
    let g = sdf.gradient(p);
    let n = g.norm();
    if n > 0.0 && n.is_finite() { Some(g / n) } else { None }
}

/// Move `p` onto `phi + margin = 0` along the normal (Newton on the
/// distance, at most four steps; one for exact SDFs).
fn project(sdf: &dyn Sdf, margin: f64, p: &Vec3, n0: &Vec3) -> Vec3 {
    let mut q = *p;
    let mut n = *n0;
    for _ in 0..4 {
        let gap = sdf.distance(&q) + margin;
        if gap <= 0.0 {
            break;
        }
        q -= n * gap;
        if let Some(nn) = unit_normal(sdf, &q) {
            n = nn;
        }
    }
    q
}

/// Contact and friction response of one node (see the module docs for the
/// law). Returns `None` when the node is not in contact (`phi(x) <= -margin`)
/// or the SDF has no usable normal there. `mass` in kg, `dt` in s (> 0).
pub fn respond(sdf: &dyn Sdf, params: &ContactParams, x: &Vec3, v: &Vec3, mass: f64, dt: f64) -> Option<NodeContact> {
    respond_with_normal_impulse(sdf, params, x, v, mass, dt, 0.0)
}

/// [`respond`] for a solver that already applied a normal impulse
/// `prior_normal_impulse` (N s, >= 0) inside its step, e.g. a penalty or
/// barrier force: the friction cone uses the total normal impulse, and the
/// returned `impulse` includes the prior normal part.
pub fn respond_with_normal_impulse(
    sdf: &dyn Sdf,
    params: &ContactParams,
    x: &Vec3,
    v: &Vec3,
    mass: f64,
    dt: f64,
    prior_normal_impulse: f64,
) -> Option<NodeContact> {
    let depth = sdf.distance(x) + params.margin;
    if !(depth > 0.0) {
        return None;
    }
    let n = unit_normal(sdf, x)?;
    let mut position = project(sdf, params.margin, x, &n);
    let vn = v.dot(&n);
    // Normal: stop inward motion; at least the velocity the projection implies.
    let dvn = vn.max(depth / dt);
    let jn = mass * dvn + prior_normal_impulse.max(0.0);
    let vt = v - n * vn;
    let vt_norm = vt.norm();
    let (dvt, state) = if mass * vt_norm <= params.friction_static * jn {
        (-vt, ContactState::Sticking)
    } else {
        // Sliding: m |v_t| > mu_s j_n >= mu_d j_n, so the speed stays positive.
        (
            -vt * (params.friction_dynamic * jn / (mass * vt_norm)),
            ContactState::Sliding,
        )
    };
    let velocity = v - n * dvn + dvt;
    if dvt != Vec3::zeros() {
        position += dvt * dt;
        // Keep the node on the margin surface of a curved wall.
        position = project(sdf, params.margin, &position, &n);
    }
    Some(NodeContact {
        position,
        velocity,
        impulse: -n * jn + dvt * mass,
        normal: n,
        depth,
        state,
    })
}

/// The friction mollifier of Li et al. 2020 (IPC, section 5) for a slip `y`
/// (m, >= 0) over a step and a stick-slip width `eps` (m, > 0): returns
/// `(f_0(y), f_1(y))` with `f_1 = f_0'`,
/// `f_1(y) = 2y/eps - y^2/eps^2` for `y < eps`, `1` beyond, and
/// `f_0(y) = y^2/eps - y^3/(3 eps^2) + eps/3` for `y < eps`, `y` beyond.
/// `f_0` is C2 and convex, `f_1` rises from 0 to 1 (stick to slip).
pub fn friction_mollifier(y: f64, eps: f64) -> (f64, f64) {
    if y >= eps {
        (y, 1.0)
    } else {
        let r = y / eps;
        (y * r * (1.0 - r / 3.0) + eps / 3.0, r * (2.0 - r))
    }
}

/// Smoothed, lagged Coulomb friction of one node sliding on a wall, as a
/// dissipative potential an implicit solver adds to its incremental
/// potential (see the module docs; Li et al. 2020, section 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaggedFriction {
    /// Unit wall normal, frozen at the start of the step.
    pub normal: Vec3,
    /// Node position at the start of the step (m).
    pub anchor: Vec3,
    /// Friction force bound `mu lambda` (N), with the normal force `lambda`
    /// frozen at the start of the step; 0 switches the term off.
    pub bound: f64,
}

/// Value and derivatives of [`LaggedFriction`] at one position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionEval {
    /// Dissipated work `mu lambda f_0(y)` (J).
    pub energy: f64,
    /// Gradient over the node position (N); the friction force is its negative.
    pub gradient: Vec3,
    /// Exact Hessian (N/m), symmetric positive semi-definite.
    pub hessian: Mat3,
    /// Tangential slip `y` over the step (m); `y >= eps` is sliding.
    pub slip: f64,
}

impl LaggedFriction {
    /// No friction (bound 0).
    pub const NONE: LaggedFriction = LaggedFriction {
        normal: Vec3::new(0.0, 0.0, 0.0),
        anchor: Vec3::new(0.0, 0.0, 0.0),
        bound: 0.0,
    };

    /// Tangential displacement `u = (I - n n^T)(x - anchor)` (m).
    pub fn slip_vector(&self, x: &Vec3) -> Vec3 {
        let dx = x - self.anchor;
        dx - self.normal * self.normal.dot(&dx)
    }

    /// Potential only (J), for line searches.
    pub fn energy(&self, x: &Vec3, eps: f64) -> f64 {
        if self.bound <= 0.0 {
            return 0.0;
        }
        self.bound * friction_mollifier(self.slip_vector(x).norm(), eps).0
    }

    /// Potential, gradient and Hessian at `x` with stick-slip width `eps` (m).
    /// With `T = I - n n^T`, `b = mu lambda`: below `eps`,
    /// `H = b [(2/eps - y/eps^2) T - u u^T / (eps^2 y)]`; beyond,
    /// `H = b (T - u u^T / y^2) / y`. Both are positive semi-definite
    /// (eigenvalues `b {2/eps - 2y/eps^2, 2/eps - y/eps^2, 0}` and
    /// `b {0, 1/y, 0}`), so no projection is needed.
    pub fn eval(&self, x: &Vec3, eps: f64) -> FrictionEval {
        let u = self.slip_vector(x);
        let y = u.norm();
        if self.bound <= 0.0 {
            return FrictionEval {
                energy: 0.0,
                gradient: Vec3::zeros(),
                hessian: Mat3::zeros(),
                slip: y,
            };
        }
        let (f0, f1) = friction_mollifier(y, eps);
        let n = &self.normal;
        let t = Mat3::identity() - n * n.transpose();
        let b = self.bound;
        let (gradient, hessian) = if y >= eps {
            (u * (b / y), (t - u * u.transpose() / (y * y)) * (b / y))
        } else if y > 0.0 {
            (
                u * (b * f1 / y),
                t * (b * (2.0 / eps - y / (eps * eps))) - u * u.transpose() * (b / (eps * eps * y)),
            )
        } else {
            (Vec3::zeros(), t * (2.0 * b / eps))
        };
        FrictionEval {
            energy: b * f0,
            gradient,
            hessian,
            slip: y,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Half-space `z <= 0` is the lumen: `phi = z`, normal `+z`.
    #[derive(Debug)]
    struct Floor;
    impl Sdf for Floor {
        fn distance(&self, p: &Vec3) -> f64 {
            p.z
        }
        fn gradient(&self, _: &Vec3) -> Vec3 {
            Vec3::z()
        }
    }

    fn params(mu_s: f64, mu_d: f64) -> ContactParams {
        ContactParams {
            friction_static: mu_s,
            friction_dynamic: mu_d,
            margin: 1e-4,
        }
    }

    const M: f64 = 2e-3;
    const DT: f64 = 1e-3;

    #[test]
    fn no_contact_inside_margin() {
        assert!(
            respond(
                &Floor,
                &params(0.5, 0.4),
                &Vec3::new(0.0, 0.0, -2e-4),
                &Vec3::z(),
                M,
                DT
            )
            .is_none()
        );
    }

    #[test]
    fn frictionless_node_slides_freely() {
        let v = Vec3::new(0.3, -0.2, 0.5);
        let c = respond(&Floor, &params(0.0, 0.0), &Vec3::new(1.0, 2.0, 3e-4), &v, M, DT).unwrap();
        // Exact SDF: the projection lands on the margin surface up to roundoff.
        assert!(
            (c.position - Vec3::new(1.0, 2.0, -1e-4)).norm() < 1e-15,
            "position {:?}",
            c.position
        );
        // Inward speed 0.5 m/s exceeds depth/dt = 0.4 m/s: normal velocity zeroed.
        assert!(c.velocity.z.abs() < 1e-15, "normal velocity {}", c.velocity.z);
        assert_eq!(c.velocity.xy(), v.xy(), "tangential velocity must be untouched");
        assert!(
            (c.impulse - Vec3::new(0.0, 0.0, -M * 0.5)).norm() < 1e-15,
            "impulse {:?}",
            c.impulse
        );
        assert!((c.depth - 4e-4).abs() < 1e-15);
    }

    #[test]
    fn node_sticks_inside_friction_cone() {
        let (mu_s, mu_d) = (0.5, 0.3);
        // Tangential impulse needed m*0.2 is below mu_s * m * 0.5 = m * 0.25.
        let v = Vec3::new(0.2, 0.0, 0.5);
        let x = Vec3::new(0.0, 0.0, 5e-4);
        let c = respond(&Floor, &params(mu_s, mu_d), &x, &v, M, DT).unwrap();
        assert_eq!(c.state, ContactState::Sticking);
        assert!(c.velocity.xy().norm() < 1e-15, "tangential velocity {:?}", c.velocity);
        // Depth 6e-4 m over dt exceeds the inward speed: the node leaves the wall
        // at (depth/dt - v.n) = 0.1 m/s, consistent with the projection.
        assert!((c.velocity.z + 0.1).abs() < 1e-12, "normal velocity {}", c.velocity.z);
        // No creep: the step's tangential motion dt * v_t is undone.
        assert!((c.position.x - (x.x - DT * 0.2)).abs() < 1e-15, "x {}", c.position.x);
        let jt = c.impulse.xy().norm();
        let jn = -c.impulse.z;
        assert!(
            jt <= mu_s * jn + 1e-18,
            "friction impulse {jt} outside cone mu_s*jn = {}",
            mu_s * jn
        );
    }

    #[test]
    fn node_slides_at_cone_edge_with_dynamic_friction() {
        let (mu_s, mu_d) = (0.5, 0.3);
        let vn = 0.5;
        // Just past the cone: m |v_t| = 1.001 * mu_s * m * vn.
        let vt = 1.001 * mu_s * vn;
        let v = Vec3::new(0.0, vt, vn);
        let c = respond(&Floor, &params(mu_s, mu_d), &Vec3::new(0.0, 0.0, 1e-4), &v, M, DT).unwrap();
        assert_eq!(c.state, ContactState::Sliding);
        let expect = vt - mu_d * vn;
        assert!(
            (c.velocity.y - expect).abs() < 1e-15,
            "sliding speed {} expected {expect}",
            c.velocity.y
        );
        let jt = c.impulse.y.abs();
        assert!(
            (jt - mu_d * M * vn).abs() < 1e-15,
            "friction impulse {jt} != mu_d j_n {}",
            mu_d * M * vn
        );
        // Just inside the cone it sticks.
        let v2 = Vec3::new(0.0, 0.999 * mu_s * vn, vn);
        let c2 = respond(&Floor, &params(mu_s, mu_d), &Vec3::new(0.0, 0.0, 1e-4), &v2, M, DT).unwrap();
        assert_eq!(c2.state, ContactState::Sticking);
    }

    #[test]
    fn resting_node_force_equals_load() {
        // Backward Euler from rest on the surface under a load F into the
        // wall: x = x0 + dt^2 F/m, v = dt F/m. The force estimate must be F.
        let f = 3.0;
        let x = Vec3::new(0.0, 0.0, -1e-4 + DT * DT * f / M);
        let v = Vec3::new(0.0, 0.0, DT * f / M);
        let c = respond(&Floor, &params(0.0, 0.0), &x, &v, M, DT).unwrap();
        let fz = c.force(DT).z;
        assert!((fz + f).abs() < 1e-9 * f, "wall force {fz} for load {f}");
    }

    /// Gradient and Hessian of the lagged friction against central finite
    /// differences, in the stick band and past it; the Hessian is PSD and
    /// the force has no normal part.
    #[test]
    fn lagged_friction_derivatives_match_finite_differences() {
        let n = Vec3::new(0.3, -0.4, 0.866).normalize();
        let f = LaggedFriction {
            normal: n,
            anchor: Vec3::new(0.1, 0.2, -0.3),
            bound: 0.7,
        };
        let eps = 1e-4;
        let h = 1e-9;
        for (i, dx) in [
            Vec3::new(2e-5, -1e-5, 3e-5),
            Vec3::new(-4e-5, 6e-5, 1e-5),
            Vec3::new(3e-4, 1e-4, -2e-4),
            Vec3::new(-1e-3, 2e-3, 5e-4),
        ]
        .iter()
        .enumerate()
        {
            let x = f.anchor + dx;
            let e = f.eval(&x, eps);
            let hscale = e.hessian.norm();
            for c in 0..3 {
                let mut xp = x;
                let mut xm = x;
                xp[c] += h;
                xm[c] -= h;
                let fd = (f.energy(&xp, eps) - f.energy(&xm, eps)) / (2.0 * h);
                // Central differences with h = 1e-9 m: rounding 1e-16 |D| / h
                // ~ 1e-11 N dominates (truncation h^2 b/eps^2 ~ 1e-10 N);
                // 1e-6 of the force is far above both.
                assert!(
                    (fd - e.gradient[c]).abs() <= 1e-6 * e.gradient.norm(),
                    "case {i} grad[{c}]: fd {fd:e} vs {:e}",
                    e.gradient[c]
                );
                let (gp, gm) = (f.eval(&xp, eps).gradient, f.eval(&xm, eps).gradient);
                let col = (gp - gm) / (2.0 * h);
                for r in 0..3 {
                    // Same argument on the gradient: rounding 1e-16 |g| / h
                    // ~ 1e-7 N/m against |H| >= 1e2 N/m here.
                    assert!(
                        (col[r] - e.hessian[(r, c)]).abs() <= 1e-6 * hscale,
                        "case {i} H[{r},{c}]: fd {:e} vs {:e}",
                        col[r],
                        e.hessian[(r, c)]
                    );
                }
            }
            let ev = e.hessian.symmetric_eigenvalues();
            // PSD up to rounding of the entries (1e-15 |H|).
            assert!(
                ev.iter().all(|&l| l >= -1e-12 * hscale),
                "case {i}: Hessian not PSD {ev:?}"
            );
            // The force lies in the tangent plane up to rounding.
            assert!(
                e.gradient.dot(&n).abs() <= 1e-12 * e.gradient.norm(),
                "case {i}: friction has a normal part {:e}",
                e.gradient.dot(&n)
            );
        }
    }

    /// Under a tangential load `F` below the bound a node creeps to the
    /// equilibrium slip `y = eps (1 - sqrt(1 - F/b))` (from `b f_1(y) = F`),
    /// inside the stick band; past it the friction force saturates at `b`.
    #[test]
    fn lagged_friction_sticks_below_bound_and_saturates_above() {
        let f = LaggedFriction {
            normal: Vec3::z(),
            anchor: Vec3::zeros(),
            bound: 2.0,
        };
        let eps = 1e-6;
        for ratio in [0.1f64, 0.5, 0.99] {
            let y = eps * (1.0 - (1.0 - ratio).sqrt());
            let e = f.eval(&Vec3::new(y, 0.0, 0.0), eps);
            let force = e.gradient.x;
            // Closed form evaluated in floating point: a few ulps of b.
            assert!(
                (force - ratio * f.bound).abs() < 1e-12 * f.bound,
                "ratio {ratio}: force {force} at slip {y:e}"
            );
            assert!(e.slip < eps, "ratio {ratio}: slip {:e} not in the stick band", e.slip);
        }
        // Sliding along +y with a normal offset: force = b along the slip.
        let e = f.eval(&Vec3::new(0.0, 5e-3, 7.0), eps);
        assert!(
            (e.gradient - Vec3::new(0.0, f.bound, 0.0)).norm() < 1e-15,
            "{:?}",
            e.gradient
        );
        assert_eq!(LaggedFriction::NONE.eval(&Vec3::x(), eps).gradient, Vec3::zeros());
    }
}
