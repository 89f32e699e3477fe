//! Blood flow: the [`FlowField`] a scene may carry, its implementations
//! ([`PoiseuilleFlow`], [`TransformedFlow`], [`MovingFlow`]) and the blood
//! and drag constants every rod model's flow drag uses.
//!
//! **Drag.** A rod of diameter `d` in a flow of velocity `u` relative to it
//! feels the quadratic (Morison-type) drag per unit length
//! `f = rho/2 d (C_n |u_n| u_n + pi C_t |u_t| u_t)`, `u_n`/`u_t` the parts
//! normal to and along the rod's tangent (Hoerner, "Fluid-Dynamic Drag",
//! 1965, ch. 2-3), with [`BLOOD_DENSITY`], [`DRAG_NORMAL`] and
//! [`DRAG_TANGENTIAL`]. Quadratic and not resistive-force theory (Gray &
//! Hancock 1955; Lighthill 1976): a guidewire of d = 0.89 mm in blood
//! ([`BLOOD_VISCOSITY`]) at up to 0.5 m/s has a cylinder Reynolds number
//! `rho U d / mu` ~ 135, far from the Stokes regime (Re << 1) where RFT
//! holds; cylinder drag there is dominated by pressure drag.
//!
//! Units are SI (m, s, kg).
//!
//! ```
//! use surgbench_core::flow::{FlowField, PoiseuilleFlow};
//! use surgbench_core::Vec3;
//! let f = PoiseuilleFlow { origin: Vec3::zeros(), axis: Vec3::z(), radius: 2e-3, v_max: 0.4 };
//! assert_eq!(f.velocity(&Vec3::zeros()), Vec3::new(0.0, 0.0, 0.4));
//! assert_eq!(f.velocity(&Vec3::new(2e-3, 0.0, 0.0)), Vec3::zeros());
//! ```

use crate::motion::VesselMotion;
use crate::{Iso3, Vec3};
use std::sync::Arc;

/// Density of whole blood (kg/m^3): 1050-1060 at 37 C (Kenner, "The
/// measurement of blood density and its meaning", Basic Res Cardiol 84:111,
/// 1989).
pub const BLOOD_DENSITY: f64 = 1060.0;
/// Dynamic viscosity of whole blood at high shear rates (Pa s): about
/// 3.5e-3 (Merrill, "Rheology of blood", Physiol Rev 49:863, 1969).
pub const BLOOD_VISCOSITY: f64 = 3.5e-3;
/// Normal (cross-flow) drag coefficient of a cylinder, on the projected
/// area `d` per unit length: about 1.2 for cylinder Reynolds numbers 10 to
/// 1e5 (Hoerner, "Fluid-Dynamic Drag", 1965, ch. 3). An approximation.
pub const DRAG_NORMAL: f64 = 1.2;
/// Tangential (axial skin-friction) drag coefficient of a long cylinder, on
/// the wetted area `pi d` per unit length: order 0.01-0.02 (Hoerner 1965,
/// ch. 2; the value used for cables). An approximation.
pub const DRAG_TANGENTIAL: f64 = 0.02;

/// Drag per unit length (N/m) on a rod of diameter `d` (m) with unit
/// tangent `t`, in a flow moving at `u` (m/s) relative to it: the law of
/// the module docs, `rho/2 d (C_n |u_n| u_n + pi C_t |u_t| u_t)`.
pub fn drag_per_length(u: &Vec3, t: &Vec3, d: f64) -> Vec3 {
    let ut = t * t.dot(u);
    let un = u - ut;
    0.5 * BLOOD_DENSITY * d * (DRAG_NORMAL * un.norm() * un + std::f64::consts::PI * DRAG_TANGENTIAL * ut.norm() * ut)
}

/// A blood-flow velocity field (m/s).
pub trait FlowField: Send + Sync + std::fmt::Debug {
    /// Flow velocity at `p` (m/s).
    fn velocity(&self, p: &Vec3) -> Vec3;
}

/// A flow field moved rigidly: `v'(p) = R v(T^-1 p)`.
#[derive(Debug, Clone)]
pub struct TransformedFlow {
    inner: Arc<dyn FlowField>,
    iso: Iso3,
}

impl TransformedFlow {
    /// `inner` moved by `iso`.
    pub fn new(inner: Arc<dyn FlowField>, iso: Iso3) -> Self {
        Self { inner, iso }
    }
}

impl FlowField for TransformedFlow {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        self.iso.rotation * self.inner.velocity(&q)
    }
}

/// Axial Poiseuille flow in a straight tube:
/// `v(r) = v_max (1 - r^2 / R^2)` along `axis` for `r < R`, zero outside
/// (the steady laminar solution for a pressure-driven Newtonian fluid in a
/// pipe; e.g. Batchelor, "An Introduction to Fluid Dynamics", section 4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoiseuilleFlow {
    /// A point on the axis (m).
    pub origin: Vec3,
    /// Unit flow direction.
    pub axis: Vec3,
    /// Tube radius `R` (m).
    pub radius: f64,
    /// Centreline speed `v_max` (m/s); the mean speed is `v_max / 2`.
    pub v_max: f64,
}

impl FlowField for PoiseuilleFlow {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        let d = p - self.origin;
        let r2 = (d - self.axis * d.dot(&self.axis)).norm_squared();
        let q = 1.0 - r2 / (self.radius * self.radius);
        if q > 0.0 {
            self.axis * (self.v_max * q)
        } else {
            Vec3::zeros()
        }
    }
}

/// A flow field carried by a moving vessel at time `t`: the blood at `x` is
/// the rest field at its rest point plus the wall's velocity there,
/// `v(x) = v_0(X) + du/dt (X, t)` (the paper's blood elements follow the
/// vessel by rigid virtual links; this is their continuum).
#[derive(Debug, Clone)]
pub struct MovingFlow {
    rest: Arc<dyn FlowField>,
    motion: Arc<dyn VesselMotion>,
    t: f64,
}

impl MovingFlow {
    /// `rest` carried by `motion` at time `t` (s).
    pub fn new(rest: Arc<dyn FlowField>, motion: Arc<dyn VesselMotion>, t: f64) -> Self {
        Self { rest, motion, t }
    }
}

impl FlowField for MovingFlow {
    fn velocity(&self, p: &Vec3) -> Vec3 {
        let xr = self.motion.rest_point(p, self.t);
        self.rest.velocity(&xr) + self.motion.velocity(&xr, self.t)
    }
}
