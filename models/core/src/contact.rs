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

use crate::Vec3;
use crate::scene::ContactParams;
use crate::sdf::Sdf;

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
}
