//! Signed distance fields: the shared collision interface. Negative inside
//! the vessel lumen (where a wire may be), positive in or beyond the wall;
//! the gradient is the unit normal pointing out of the lumen into the wall.
//! Units are SI (metres).
//!
//! Implementations:
//! - [`StraightTube`]: an infinite straight tube (closed form);
//! - [`SweptTube`]: a tube swept along a G1 centreline of straight lines and
//!   circular arcs (built with [`CenterlineBuilder`]), radius varying
//!   linearly in arclength, closed by hemispherical caps at both ends;
//! - [`SdfUnion`]: the union (pointwise `min`) of lumens, e.g. the branches
//!   of a bifurcation;
//! - [`TransformedSdf`]: any SDF moved rigidly;
//! - [`MeshSdf`]: exact distance to a closed triangle mesh through parry3d
//!   (slow: microseconds per query; for building grids and checking them);
//! - [`VoxelSdf`]: a regular grid sampled by trilinear interpolation with the
//!   interpolant's analytic gradient (the fast path for models), built from
//!   any SDF or mesh, cacheable to disk.
//!
//! ```
//! use surgbench_core::sdf::{CenterlineBuilder, Sdf};
//! use surgbench_core::Vec3;
//! // 10 mm straight, then a quarter turn of radius 20 mm towards +y; lumen radius 2 mm.
//! let tube = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
//!     .line(0.01)
//!     .arc(0.02, std::f64::consts::FRAC_PI_2, Vec3::y())
//!     .build_constant(2e-3)
//!     .unwrap();
//! assert!((tube.distance(&Vec3::new(0.005, 0.0, 0.0)) + 2e-3).abs() < 1e-15);
//! assert!((tube.distance(&Vec3::new(0.005, 0.0, 3e-3)) - 1e-3).abs() < 1e-15);
//! ```

use crate::io::TriSurface;
use crate::{Iso3, Mat3, Vec3};
use std::fmt;
use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;

/// Step (m) of the central differences of [`Sdf::gradient`] that the
/// default [`Sdf::hessian`] takes. Truncation error relative to the Hessian
/// is about `(h / rho)^2` with `rho` the smallest length of the geometry at
/// the point (distance to a tube's axis, bend radius, voxel spacing):
/// <= 1e-4 for the sub-millimetre and larger features of vessels
/// (`rho >= 0.1 mm`). Rounding: an analytic gradient is accurate to about
/// `eps |p| / rho` (1e-12 for `|p| <= 1 m`, `rho >= 0.1 mm`), giving an
/// absolute Hessian error ~1e-6 1/m against curvatures >= 1 1/m; the
/// default finite-difference gradient (step 1e-7 m, error ~1e-9) gives
/// ~1e-3 1/m, still far below the curvature of any vessel wall.
pub const HESSIAN_FD_STEP: f64 = 1e-6;

/// A signed distance `phi(p)` (m) and its gradient (unit normal pointing out
/// of the lumen, into the wall).
pub trait Sdf: Send + Sync + std::fmt::Debug {
    /// Signed distance at `p` (m).
    fn distance(&self, p: &Vec3) -> f64;
    /// Gradient of the distance at `p`; unit length where the SDF is exact.
    fn gradient(&self, p: &Vec3) -> Vec3 {
        let h = 1e-7;
        let mut g = Vec3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += h;
            b[k] -= h;
            g[k] = (self.distance(&a) - self.distance(&b)) / (2.0 * h);
        }
        g
    }
    /// Distance and gradient together (one closest-point search for the
    /// analytic vessels; the contact response needs both).
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        (self.distance(p), self.gradient(p))
    }
    /// Hessian of the distance at `p` (1/m, symmetric). For an exact SDF it
    /// is the curvature of the level set through `p` (principal curvatures
    /// across the normal, 0 along it), e.g. the stiffness a contact penalty
    /// `P(phi)` gains from a curved wall, `P'(phi) Hess phi`.
    ///
    /// Default: central differences of [`Sdf::gradient`] over
    /// [`HESSIAN_FD_STEP`] (step and error justified there), symmetrised.
    /// Within that step of a kink of the gradient (a medial axis, the seam
    /// of a union, a voxel face) it returns the jump of the gradient over
    /// the stencil, not a curvature. Analytic overrides: [`StraightTube`],
    /// [`SweptTube`], [`TransformedSdf`], [`SdfUnion`] and the vessels of
    /// [`crate::vessel`].
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let mut m = Mat3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += HESSIAN_FD_STEP;
            b[k] -= HESSIAN_FD_STEP;
            // The step actually taken (the coordinates are rounded).
            let h = a[k] - b[k];
            m.set_column(k, &((self.gradient(&a) - self.gradient(&b)) / h));
        }
        (m + m.transpose()) * 0.5
    }
}

/// A geometry could not be built: the message names the offending value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GeometryError(pub String);

impl fmt::Display for GeometryError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GeometryError {}

/// A straight tube of radius `radius` (m) along the line through `origin` with
/// direction `axis`: the simplest analytic vessel.
#[derive(Debug, Clone, Copy)]
pub struct StraightTube {
    /// A point on the axis.
    pub origin: Vec3,
    /// Unit axis direction.
    pub axis: Vec3,
    /// Lumen radius (m).
    pub radius: f64,
}

impl Sdf for StraightTube {
    fn distance(&self, p: &Vec3) -> f64 {
        let d = p - self.origin;
        (d - self.axis * d.dot(&self.axis)).norm() - self.radius
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let d = p - self.origin;
        let r = d - self.axis * d.dot(&self.axis);
        let n = r.norm();
        (n - self.radius, if n > 0.0 { r / n } else { Vec3::zeros() })
    }
    /// `(I - a a^T - n n^T) / rho`: `rho` the distance from the axis `a`,
    /// `n` the radial unit vector (zero on the axis, where `phi` has a kink).
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let d = p - self.origin;
        let r = d - self.axis * d.dot(&self.axis);
        let rho = r.norm();
        if !(rho > 0.0) {
            return Mat3::zeros();
        }
        let n = r / rho;
        (Mat3::identity() - self.axis * self.axis.transpose() - n * n.transpose()) / rho
    }
}

/// An SDF moved rigidly: `phi'(p) = phi(T^-1 p)`.
#[derive(Debug, Clone)]
pub struct TransformedSdf {
    inner: Arc<dyn Sdf>,
    iso: Iso3,
}

impl TransformedSdf {
    /// Wrap `inner`, moved by `iso`.
    pub fn new(inner: Arc<dyn Sdf>, iso: Iso3) -> Self {
        Self { inner, iso }
    }
}

impl Sdf for TransformedSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        self.inner.distance(&q)
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        self.iso.rotation * self.inner.gradient(&q)
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        let (d, g) = self.inner.distance_gradient(&q);
        (d, self.iso.rotation * g)
    }
    /// `R H(T^-1 p) R^T` with `R` the rotation of the transform.
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let q = self.iso.inverse_transform_point(&(*p).into()).coords;
        let r = self.iso.rotation.to_rotation_matrix();
        r.matrix() * self.inner.hessian(&q) * r.matrix().transpose()
    }
}

/// Union of lumens: `phi = min_i phi_i`, gradient of the minimizing part.
/// Exact outside the union; inside, `|phi|` is a lower bound of the distance
/// to the union's wall (enough for contact, which only acts near `phi = 0`).
#[derive(Debug, Clone)]
pub struct SdfUnion {
    /// The lumens joined.
    pub parts: Vec<Arc<dyn Sdf>>,
}

impl SdfUnion {
    /// Index and value of the part with the smallest distance at `p`.
    pub fn closest_part(&self, p: &Vec3) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        for (i, s) in self.parts.iter().enumerate() {
            let d = s.distance(p);
            if best.is_none_or(|(_, b)| d < b) {
                best = Some((i, d));
            }
        }
        best
    }
}

impl Sdf for SdfUnion {
    fn distance(&self, p: &Vec3) -> f64 {
        self.closest_part(p).map_or(f64::INFINITY, |(_, d)| d)
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let mut best = (f64::INFINITY, Vec3::zeros());
        for s in &self.parts {
            let dg = s.distance_gradient(p);
            if dg.0 < best.0 {
                best = dg;
            }
        }
        best
    }
    /// The Hessian of the part with the smallest distance (the one whose
    /// gradient [`Sdf::gradient`] returns); zero for an empty union.
    fn hessian(&self, p: &Vec3) -> Mat3 {
        self.closest_part(p)
            .map_or(Mat3::zeros(), |(i, _)| self.parts[i].hessian(p))
    }
}

// ---------------------------------------------------------------------------
// Swept tube along lines and arcs.
// ---------------------------------------------------------------------------

/// One piece of a centreline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Piece {
    /// Straight segment from `a` to `b` (m).
    Line {
        /// Start (m).
        a: Vec3,
        /// End (m).
        b: Vec3,
    },
    /// Circular arc `c + R (cos(phi) u + sin(phi) v)`, `phi` in `[0, angle]`:
    /// starts at `c + R u` with tangent `v`.
    Arc {
        /// Centre of curvature (m).
        center: Vec3,
        /// Radius of curvature (m).
        radius: f64,
        /// Unit vector from the centre to the start point.
        u: Vec3,
        /// Unit tangent at the start (perpendicular to `u`).
        v: Vec3,
        /// Turning angle (rad), in `(0, 2 pi)`.
        angle: f64,
    },
}

/// Closest point of a piece to a query point.
#[derive(Debug, Clone, Copy)]
struct PieceHit {
    /// Arclength from the piece's start (m).
    s: f64,
    /// Closest centreline point (m).
    point: Vec3,
    /// Derivative of `s` with respect to the query point (zero at the ends).
    ds_dp: Vec3,
}

impl Piece {
    /// Arclength of the piece (m).
    pub fn length(&self) -> f64 {
        match *self {
            Piece::Line { a, b } => (b - a).norm(),
            Piece::Arc { radius, angle, .. } => radius * angle,
        }
    }

    /// Point at arclength `s` from the piece's start (clamped to the piece).
    pub fn point(&self, s: f64) -> Vec3 {
        let s = s.clamp(0.0, self.length());
        match *self {
            Piece::Line { a, b } => a + (b - a) * (s / self.length()),
            Piece::Arc {
                center, radius, u, v, ..
            } => {
                let phi = s / radius;
                center + (u * phi.cos() + v * phi.sin()) * radius
            }
        }
    }

    /// Unit tangent at arclength `s` from the piece's start.
    pub fn tangent(&self, s: f64) -> Vec3 {
        let s = s.clamp(0.0, self.length());
        match *self {
            Piece::Line { a, b } => (b - a).normalize(),
            Piece::Arc { radius, u, v, .. } => {
                let phi = s / radius;
                v * phi.cos() - u * phi.sin()
            }
        }
    }

    /// Closest point on the piece to `p` (exact: projection on a segment;
    /// for an arc, the in-plane angle of `p` clamped to the arc's ends).
    fn closest(&self, p: &Vec3) -> PieceHit {
        match *self {
            Piece::Line { a, b } => {
                let e = b - a;
                let l = e.norm();
                let t = e / l;
                let s = (p - a).dot(&t);
                if s <= 0.0 {
                    PieceHit {
                        s: 0.0,
                        point: a,
                        ds_dp: Vec3::zeros(),
                    }
                } else if s >= l {
                    PieceHit {
                        s: l,
                        point: b,
                        ds_dp: Vec3::zeros(),
                    }
                } else {
                    PieceHit {
                        s,
                        point: a + t * s,
                        ds_dp: t,
                    }
                }
            }
            Piece::Arc {
                center,
                radius,
                u,
                v,
                angle,
            } => {
                let q = p - center;
                let (x, y) = (q.dot(&u), q.dot(&v));
                let rho = x.hypot(y);
                let start = center + u * radius;
                let end = self.point(self.length());
                let ends = |p: &Vec3| {
                    if (p - start).norm_squared() <= (p - end).norm_squared() {
                        PieceHit {
                            s: 0.0,
                            point: start,
                            ds_dp: Vec3::zeros(),
                        }
                    } else {
                        PieceHit {
                            s: self.length(),
                            point: end,
                            ds_dp: Vec3::zeros(),
                        }
                    }
                };
                if rho == 0.0 {
                    return ends(p);
                }
                let mut phi = y.atan2(x);
                if phi < 0.0 {
                    phi += 2.0 * std::f64::consts::PI;
                }
                if phi <= angle {
                    let (sn, cs) = phi.sin_cos();
                    let e_phi = v * cs - u * sn;
                    PieceHit {
                        s: radius * phi,
                        point: center + (u * cs + v * sn) * radius,
                        // d(phi)/dp = e_phi / rho (polar coordinates in the arc's plane).
                        ds_dp: e_phi * (radius / rho),
                    }
                } else {
                    ends(p)
                }
            }
        }
    }

    /// Unit tangent at `hit` and the second derivative of `s` with respect
    /// to the query point there (for [`SweptTube`]'s Hessian only, so the
    /// distance queries do not pay for it). Zero on lines and at the ends;
    /// inside an arc, with `ds/dp = e_phi R / rho`,
    /// `d2s/dp2 = -R (e_rho e_phi^T + e_phi e_rho^T) / rho^2`
    /// (`d e_phi / d phi = -e_rho`, `grad rho = e_rho`).
    fn second_order(&self, hit: &PieceHit) -> (Vec3, Mat3) {
        match *self {
            Piece::Arc { center, radius, .. } if hit.ds_dp != Vec3::zeros() => {
                let r_over_rho = hit.ds_dp.norm();
                let e_phi = hit.ds_dp / r_over_rho;
                let e_rho = (hit.point - center) / radius;
                let sym = e_rho * e_phi.transpose() + e_phi * e_rho.transpose();
                (e_phi, sym * (-r_over_rho * r_over_rho / radius))
            }
            _ => (self.tangent(hit.s), Mat3::zeros()),
        }
    }

    /// Centre and radius of a sphere enclosing the piece (m).
    fn bounding_sphere(&self) -> (Vec3, f64) {
        match *self {
            Piece::Line { a, b } => ((a + b) * 0.5, 0.5 * (b - a).norm()),
            Piece::Arc { center, radius, .. } => {
                // Every point of the arc is within half its length of the
                // arc's midpoint, and within `radius` of its centre.
                let l = self.length();
                if 0.5 * l < radius {
                    (self.point(0.5 * l), 0.5 * l)
                } else {
                    (center, radius)
                }
            }
        }
    }
}

/// Turtle-style builder of a G1 centreline: straight lines and circular
/// arcs, each starting where and in the direction the previous one ended.
#[derive(Debug, Clone)]
pub struct CenterlineBuilder {
    pos: Vec3,
    dir: Vec3,
    pieces: Vec<Piece>,
    error: Option<String>,
}

impl CenterlineBuilder {
    /// Start at `start` (m) heading along `dir` (any non-zero length).
    pub fn new(start: Vec3, dir: Vec3) -> Self {
        let n = dir.norm();
        let error = if !(n > 0.0 && n.is_finite() && start.iter().all(|x| x.is_finite())) {
            Some(format!(
                "centreline start {start:?} / direction {dir:?} must be finite and non-zero"
            ))
        } else {
            None
        };
        Self {
            pos: start,
            dir: if n > 0.0 { dir / n } else { Vec3::x() },
            pieces: Vec::new(),
            error,
        }
    }

    /// Append a straight segment of `length` (m, > 0).
    pub fn line(mut self, length: f64) -> Self {
        if !(length > 0.0 && length.is_finite()) {
            self.error
                .get_or_insert(format!("line length must be > 0 m, got {length}"));
            return self;
        }
        let b = self.pos + self.dir * length;
        self.pieces.push(Piece::Line { a: self.pos, b });
        self.pos = b;
        self
    }

    /// Append an arc of curvature radius `radius` (m, > 0) turning by
    /// `angle` (rad, in `(0, 2 pi)`) towards `toward` (projected
    /// perpendicular to the current direction; must not be parallel to it).
    pub fn arc(mut self, radius: f64, angle: f64, toward: Vec3) -> Self {
        if !(radius > 0.0 && radius.is_finite()) {
            self.error
                .get_or_insert(format!("arc radius must be > 0 m, got {radius}"));
            return self;
        }
        if !(angle > 0.0 && angle < 2.0 * std::f64::consts::PI) {
            self.error
                .get_or_insert(format!("arc angle must be in (0, 2 pi) rad, got {angle}"));
            return self;
        }
        let n = toward - self.dir * toward.dot(&self.dir);
        if !(n.norm() > 1e-9 * toward.norm().max(1e-300)) || !n.iter().all(|x| x.is_finite()) {
            self.error.get_or_insert(format!(
                "arc bend direction {toward:?} is parallel to the tangent {:?}",
                self.dir
            ));
            return self;
        }
        let n = n.normalize();
        let arc = Piece::Arc {
            center: self.pos + n * radius,
            radius,
            u: -n,
            v: self.dir,
            angle,
        };
        self.pos = arc.point(arc.length());
        self.dir = arc.tangent(arc.length());
        self.pieces.push(arc);
        self
    }

    /// Current end point (m).
    pub fn position(&self) -> Vec3 {
        self.pos
    }

    /// Current unit direction.
    pub fn direction(&self) -> Vec3 {
        self.dir
    }

    /// Finish with a constant lumen radius (m).
    pub fn build_constant(self, radius: f64) -> Result<SweptTube, GeometryError> {
        self.build(&[(0.0, radius)])
    }

    /// Finish with a lumen radius piecewise linear in arclength: `profile`
    /// lists `(s, r)` pairs (m) with increasing `s`; outside them the nearest
    /// value holds. The slope `|dr/ds|` must stay below 0.5 (the swept-sphere
    /// approximation's error grows like `d (dr/ds)^2 / 2`).
    pub fn build(self, profile: &[(f64, f64)]) -> Result<SweptTube, GeometryError> {
        if let Some(e) = self.error {
            return Err(GeometryError(e));
        }
        if self.pieces.is_empty() {
            return Err(GeometryError("centreline has no pieces".into()));
        }
        if profile.is_empty() {
            return Err(GeometryError("radius profile is empty".into()));
        }
        for (i, &(s, r)) in profile.iter().enumerate() {
            if !(r > 0.0 && r.is_finite() && s.is_finite()) {
                return Err(GeometryError(format!(
                    "radius profile point {i}: ({s}, {r}) needs finite s and r > 0 m"
                )));
            }
            if i > 0 {
                let (s0, r0) = profile[i - 1];
                if !(s > s0) {
                    return Err(GeometryError(format!(
                        "radius profile arclengths must increase: {s0} then {s}"
                    )));
                }
                let slope = (r - r0) / (s - s0);
                if slope.abs() > 0.5 {
                    return Err(GeometryError(format!(
                        "radius profile slope {slope:.3} between s={s0} and s={s} m exceeds 0.5"
                    )));
                }
            }
        }
        let mut starts = Vec::with_capacity(self.pieces.len());
        let mut s = 0.0;
        for p in &self.pieces {
            starts.push(s);
            s += p.length();
        }
        let bounds = self.pieces.iter().map(|p| p.bounding_sphere()).collect();
        let mut tube = SweptTube {
            pieces: self.pieces,
            starts,
            length: s,
            profile: profile.to_vec(),
            bounds,
            piece_rmax: Vec::new(),
        };
        tube.piece_rmax = (0..tube.pieces.len())
            .map(|i| {
                let (a, b) = (tube.starts[i], tube.starts[i] + tube.pieces[i].length());
                let mut m = tube.radius_at(a).max(tube.radius_at(b));
                for &(s, r) in &tube.profile {
                    if s > a && s < b {
                        m = m.max(r);
                    }
                }
                m
            })
            .collect();
        Ok(tube)
    }
}

/// Where a point projects on a [`SweptTube`]'s centreline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arclength of the closest centreline point from the start (m).
    pub s: f64,
    /// Closest centreline point (m).
    pub point: Vec3,
    /// Distance from the centreline (m).
    pub radial: f64,
    /// Signed distance to the wall (m): `radial - r(s)`.
    pub phi: f64,
    /// Index of the piece it lies on.
    pub piece: usize,
}

/// A tube swept along a centreline of lines and arcs (see
/// [`CenterlineBuilder`]), radius `r(s)` piecewise linear in arclength.
///
/// `phi(p) = |p - c(s*)| - r(s*)` with `c(s*)` the closest centreline point
/// (minimised over pieces of `|p - c_i| - r(s_i)`). For a constant radius it
/// is the exact signed distance wherever the closest centreline point is
/// unique and `|p - c| < ` the curvature radius (true in the lumen and the
/// wall of any tube whose radius is below its bend radius). With a varying
/// radius it differs from the exact distance to the canal surface of the
/// swept spheres by about `radial (dr/ds)^2 / 2`. The ends are closed by
/// hemispherical caps. Gradient: the analytic gradient of this `phi`,
/// `n - r'(s*) ds*/dp` with `n` the unit radial direction (unit length for a
/// constant radius).
#[derive(Debug, Clone)]
pub struct SweptTube {
    pieces: Vec<Piece>,
    starts: Vec<f64>,
    length: f64,
    profile: Vec<(f64, f64)>,
    bounds: Vec<(Vec3, f64)>,
    piece_rmax: Vec<f64>,
}

impl SweptTube {
    /// Total centreline length (m).
    pub fn length(&self) -> f64 {
        self.length
    }

    /// The pieces of the centreline.
    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }

    fn locate(&self, s: f64) -> (usize, f64) {
        let s = s.clamp(0.0, self.length);
        let i = self.starts.partition_point(|&a| a <= s).max(1) - 1;
        (i, s - self.starts[i])
    }

    /// Centreline point at arclength `s` (m, clamped to the centreline).
    pub fn point_at(&self, s: f64) -> Vec3 {
        let (i, ls) = self.locate(s);
        self.pieces[i].point(ls)
    }

    /// Unit tangent at arclength `s`.
    pub fn tangent_at(&self, s: f64) -> Vec3 {
        let (i, ls) = self.locate(s);
        self.pieces[i].tangent(ls)
    }

    /// Lumen radius at arclength `s` (m).
    pub fn radius_at(&self, s: f64) -> f64 {
        self.radius_and_slope(s).0
    }

    fn radius_and_slope(&self, s: f64) -> (f64, f64) {
        let p = &self.profile;
        // `!(s > ..)` also catches a NaN arclength (a degenerate query).
        if !(s > p[0].0) {
            return (p[0].1, 0.0);
        }
        let n = p.len();
        if s >= p[n - 1].0 {
            return (p[n - 1].1, 0.0);
        }
        let i = p.partition_point(|q| q.0 <= s) - 1;
        let ((s0, r0), (s1, r1)) = (p[i], p[i + 1]);
        let k = (r1 - r0) / (s1 - s0);
        (r0 + k * (s - s0), k)
    }

    /// A pose on the centreline at arclength `s`: origin on the centreline,
    /// local x along the tangent (a rod base clamp placed here feeds the wire
    /// along the lumen), local y/z any orthonormal completion that is fixed
    /// for a given tangent.
    pub fn frame_at(&self, s: f64) -> Iso3 {
        let t = self.tangent_at(s);
        let helper = if t.z.abs() < 0.9 { Vec3::z() } else { Vec3::x() };
        let y = helper.cross(&t).normalize();
        let z = t.cross(&y);
        let m = crate::Mat3::from_columns(&[t, y, z]);
        let rot = nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
        Iso3::from_parts(self.point_at(s).into(), rot)
    }

    /// Project `p` on the centreline (see the type's docs for `phi`).
    pub fn project(&self, p: &Vec3) -> Projection {
        self.project_full(p).0
    }

    /// The projection and the winning piece's closest-point data (with the
    /// derivatives of `s`).
    fn project_full(&self, p: &Vec3) -> (Projection, PieceHit) {
        let mut best = Projection {
            s: 0.0,
            point: Vec3::zeros(),
            radial: f64::INFINITY,
            phi: f64::INFINITY,
            piece: 0,
        };
        let mut best_hit = PieceHit {
            s: 0.0,
            point: Vec3::zeros(),
            ds_dp: Vec3::zeros(),
        };
        for (i, piece) in self.pieces.iter().enumerate() {
            let (c, r) = self.bounds[i];
            // Lower bound of this piece's phi: skip pieces that cannot win.
            if (p - c).norm() - r - self.piece_rmax[i] >= best.phi {
                continue;
            }
            let h = piece.closest(p);
            let s = self.starts[i] + h.s;
            let radial = (p - h.point).norm();
            let phi = radial - self.radius_at(s);
            if phi < best.phi {
                best = Projection {
                    s,
                    point: h.point,
                    radial,
                    phi,
                    piece: i,
                };
                best_hit = h;
            }
        }
        (best, best_hit)
    }

    /// A closed triangle mesh of the lumen surface with `around` vertices per
    /// ring (>= 3) and rings at most `max_step` (m) apart along the
    /// centreline, closed by flat end caps; outward (into the wall) facing.
    /// The caps differ from the SDF's hemispherical caps: compare the two
    /// away from the ends.
    pub fn to_mesh(&self, around: usize, max_step: f64) -> Result<TriSurface, GeometryError> {
        if around < 3 || !(max_step > 0.0) {
            return Err(GeometryError(format!(
                "mesh needs around >= 3 and max_step > 0, got {around}, {max_step}"
            )));
        }
        let rings = ((self.length / max_step).ceil() as usize).max(1) + 1;
        let mut vertices = Vec::with_capacity(rings * around + 2);
        // Frames transported along the centreline (no twist).
        let t0 = self.tangent_at(0.0);
        let helper = if t0.z.abs() < 0.9 { Vec3::z() } else { Vec3::x() };
        let mut a = helper.cross(&t0).normalize();
        let mut t_prev = t0;
        for k in 0..rings {
            let s = self.length * k as f64 / (rings - 1) as f64;
            let t = self.tangent_at(s);
            a = crate::frames::parallel_transport(&a, &t_prev, &t);
            a = (a - t * a.dot(&t)).normalize();
            t_prev = t;
            let b = t.cross(&a);
            let c = self.point_at(s);
            let r = self.radius_at(s);
            for j in 0..around {
                let th = 2.0 * std::f64::consts::PI * j as f64 / around as f64;
                vertices.push(c + (a * th.cos() + b * th.sin()) * r);
            }
        }
        let mut triangles = Vec::new();
        for k in 0..rings - 1 {
            for j in 0..around {
                let (i0, i1) = (k * around + j, k * around + (j + 1) % around);
                let (i2, i3) = (i0 + around, i1 + around);
                // Ring k+1 lies ahead along t; (a, b, t) is right-handed, so
                // these windings give normals pointing away from the axis.
                triangles.push([i0, i1, i3]);
                triangles.push([i0, i3, i2]);
            }
        }
        let c0 = vertices.len();
        vertices.push(self.point_at(0.0));
        let c1 = vertices.len();
        vertices.push(self.point_at(self.length));
        let last = (rings - 1) * around;
        for j in 0..around {
            let jn = (j + 1) % around;
            triangles.push([c0, jn, j]);
            triangles.push([c1, last + j, last + jn]);
        }
        Ok(TriSurface { vertices, triangles })
    }
}

impl Sdf for SweptTube {
    fn distance(&self, p: &Vec3) -> f64 {
        self.project(p).phi
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let (h, hit) = self.project_full(p);
        if !(h.radial > 0.0) {
            return (h.phi, Vec3::zeros());
        }
        let n = (p - h.point) / h.radial;
        let (_, slope) = self.radius_and_slope(h.s);
        (h.phi, n - hit.ds_dp * slope)
    }
    /// Analytic Hessian of `phi = |w| - r(s*)`, `w = p - c(s*)`:
    /// `(I - n n^T)(I - t ds*/dp^T) / |w| - r'(s*) d2s*/dp2` (`r` is
    /// piecewise linear, so `r'' = 0` between profile points). On an arc of
    /// radius `R`, `ds*/dp = t R / rho` with `rho` the in-plane distance from
    /// its centre, so the first term is `(I - n n^T - t t^T R / rho) / |w|`:
    /// the centreline's curvature enters through `R / rho = 1 / (1 - kappa w . N)`
    /// (`N` the principal normal); on a line it is `(I - n n^T - t t^T) / |w|`,
    /// and on the end caps `(I - n n^T) / |w|`. Zero on the centreline.
    /// Between pieces (and at profile points) it is the Hessian of the
    /// winning piece: `phi` is only C1 there.
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let (h, hit) = self.project_full(p);
        if !(h.radial > 0.0) {
            return Mat3::zeros();
        }
        let n = (p - h.point) / h.radial;
        let (_, slope) = self.radius_and_slope(h.s);
        let (tangent, dds_dp) = self.pieces[h.piece].second_order(&hit);
        let proj = Mat3::identity() - n * n.transpose();
        let dw = Mat3::identity() - tangent * hit.ds_dp.transpose();
        let m = proj * dw / h.radial - dds_dp * slope;
        (m + m.transpose()) * 0.5
    }
}

// ---------------------------------------------------------------------------
// Exact distance to a triangle mesh (parry3d).
// ---------------------------------------------------------------------------

/// Exact signed distance to a closed, outward-oriented triangle mesh through
/// parry3d's BVH point projection; the sign (negative inside the mesh, i.e.
/// in the lumen) comes from parry's pseudo-normal inside test
/// (`TriMeshFlags::ORIENTED`). A few microseconds per query: use it to build
/// and check a [`VoxelSdf`], not in a 1 kHz loop.
pub struct MeshSdf {
    mesh: parry3d_f64::shape::TriMesh,
}

impl fmt::Debug for MeshSdf {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "MeshSdf({} triangles)", self.mesh.num_triangles())
    }
}

fn gv(p: &Vec3) -> parry3d_f64::math::Vector {
    parry3d_f64::math::Vector::new(p.x, p.y, p.z)
}

impl MeshSdf {
    /// Build from a surface (checked closed and oriented by
    /// [`TriSurface::check_closed`]).
    pub fn new(surface: &TriSurface) -> Result<Self, GeometryError> {
        surface.check_closed().map_err(|e| GeometryError(e.to_string()))?;
        let vertices = surface.vertices.iter().map(gv).collect();
        let indices = surface
            .triangles
            .iter()
            .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
            .collect();
        let mesh =
            parry3d_f64::shape::TriMesh::with_flags(vertices, indices, parry3d_f64::shape::TriMeshFlags::ORIENTED)
                .map_err(|e| GeometryError(format!("parry3d rejected the mesh: {e:?}")))?;
        Ok(Self { mesh })
    }

    /// Closest surface point to `p` (m) and whether `p` is inside the mesh.
    pub fn closest(&self, p: &Vec3) -> (Vec3, bool) {
        use parry3d_f64::query::PointQuery;
        let proj = self.mesh.project_local_point(gv(p), false);
        (Vec3::new(proj.point.x, proj.point.y, proj.point.z), proj.is_inside)
    }
}

impl Sdf for MeshSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        self.distance_gradient(p).0
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let (q, inside) = self.closest(p);
        let d = p - q;
        let n = d.norm();
        let sign = if inside { -1.0 } else { 1.0 };
        (sign * n, if n > 0.0 { d * (sign / n) } else { Vec3::zeros() })
    }
}

// ---------------------------------------------------------------------------
// Voxel grid with trilinear interpolation.
// ---------------------------------------------------------------------------

/// Magic first line of the on-disk voxel format.
const VOXEL_MAGIC: &[u8] = b"SURGBENCH-VOXEL-SDF v1\n";

/// A signed distance sampled on a regular grid, read by trilinear
/// interpolation; the gradient is the interpolant's own (piecewise
/// bilinear in each component), so `distance` and `gradient` are consistent.
///
/// Grid node `(i, j, k)` sits at `origin + spacing (i, j, k)` and stores
/// `values[i + nx (j + ny k)]`. Interpolation error on a smooth field is
/// `<= spacing^2 / 8 (|phi_xx| + |phi_yy| + |phi_zz|)` (tensor-product linear
/// interpolation), i.e. second order away from the medial axis where `phi`
/// has kinks. Outside the box the field is continued by the distance to the
/// box (positive: outside the grid counts as wall).
///
/// On disk (little endian): the magic line `SURGBENCH-VOXEL-SDF v1\n`, then
/// `nx, ny, nz` as u64, `origin` (3 x f64), `spacing` (f64), then the values
/// (f64, x fastest).
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelSdf {
    /// Position of node (0, 0, 0) (m).
    pub origin: Vec3,
    /// Node spacing (m).
    pub spacing: f64,
    /// Nodes along x, y, z (each >= 2).
    pub dims: [usize; 3],
    /// Values (m), x fastest.
    pub values: Vec<f64>,
}

/// Error of a voxel SDF against the exact distance at sample points (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelError {
    /// Largest absolute error (m).
    pub max: f64,
    /// Root mean square error (m).
    pub rms: f64,
    /// Points compared.
    pub count: usize,
}

impl VoxelSdf {
    /// Sample `sdf` on the grid covering `[min, max]` (m) with `spacing` (m);
    /// the box is enlarged to a whole number of cells.
    pub fn from_sdf(sdf: &dyn Sdf, min: Vec3, max: Vec3, spacing: f64) -> Result<Self, GeometryError> {
        if !(spacing > 0.0 && spacing.is_finite()) {
            return Err(GeometryError(format!("voxel spacing must be > 0 m, got {spacing}")));
        }
        let ext = max - min;
        if !(ext.iter().all(|e| *e > 0.0 && e.is_finite())) {
            return Err(GeometryError(format!(
                "voxel box {min:?}..{max:?} is empty or not finite"
            )));
        }
        let dims = [0, 1, 2].map(|k| (ext[k] / spacing).ceil() as usize + 1);
        let total = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        if total > 200_000_000 {
            return Err(GeometryError(format!(
                "voxel grid {dims:?} has {total} nodes (> 2e8): raise the spacing"
            )));
        }
        let mut values = Vec::with_capacity(total);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = min + Vec3::new(i as f64, j as f64, k as f64) * spacing;
                    values.push(sdf.distance(&p));
                }
            }
        }
        Ok(Self {
            origin: min,
            spacing,
            dims,
            values,
        })
    }

    /// Grid over a closed mesh's bounding box grown by `padding` (m), values
    /// from the exact [`MeshSdf`].
    pub fn from_mesh(surface: &TriSurface, spacing: f64, padding: f64) -> Result<Self, GeometryError> {
        let exact = MeshSdf::new(surface)?;
        let (lo, hi) = surface.bounds();
        let pad = Vec3::repeat(padding.max(0.0));
        Self::from_sdf(&exact, lo - pad, hi + pad, spacing)
    }

    /// Upper corner of the grid (m).
    pub fn max_corner(&self) -> Vec3 {
        self.origin
            + Vec3::new(
                (self.dims[0] - 1) as f64,
                (self.dims[1] - 1) as f64,
                (self.dims[2] - 1) as f64,
            ) * self.spacing
    }

    fn at(&self, i: usize, j: usize, k: usize) -> f64 {
        self.values[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    /// Trilinear value and its analytic gradient at `p` inside the box.
    fn interp(&self, p: &Vec3) -> (f64, Vec3) {
        let g = (p - self.origin) / self.spacing;
        let mut idx = [0usize; 3];
        let mut t = [0.0; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let x = g[a].clamp(0.0, (n - 1) as f64);
            let i = (x.floor() as usize).min(n - 2);
            idx[a] = i;
            t[a] = x - i as f64;
        }
        let [i, j, k] = idx;
        let [x, y, z] = t;
        let c = |a: usize, b: usize, d: usize| self.at(i + a, j + b, k + d);
        let (c000, c100, c010, c110) = (c(0, 0, 0), c(1, 0, 0), c(0, 1, 0), c(1, 1, 0));
        let (c001, c101, c011, c111) = (c(0, 0, 1), c(1, 0, 1), c(0, 1, 1), c(1, 1, 1));
        // Interpolate along x, then y, then z.
        let c00 = c000 + x * (c100 - c000);
        let c10 = c010 + x * (c110 - c010);
        let c01 = c001 + x * (c101 - c001);
        let c11 = c011 + x * (c111 - c011);
        let c0 = c00 + y * (c10 - c00);
        let c1 = c01 + y * (c11 - c01);
        let v = c0 + z * (c1 - c0);
        // Derivatives of the same polynomial.
        let dz = c1 - c0;
        let dy = (1.0 - z) * (c10 - c00) + z * (c11 - c01);
        let dx0 = (1.0 - y) * (c100 - c000) + y * (c110 - c010);
        let dx1 = (1.0 - y) * (c101 - c001) + y * (c111 - c011);
        let dx = (1.0 - z) * dx0 + z * dx1;
        (v, Vec3::new(dx, dy, dz) / self.spacing)
    }

    fn clamp_to_box(&self, p: &Vec3) -> Vec3 {
        let hi = self.max_corner();
        Vec3::new(
            p.x.clamp(self.origin.x, hi.x),
            p.y.clamp(self.origin.y, hi.y),
            p.z.clamp(self.origin.z, hi.z),
        )
    }

    /// Error against `exact` at `count` seeded pseudo-random points of the
    /// box where `|exact| <= band` (m) and `keep(p)` holds (e.g. away from the
    /// medial axis); tries at most `50 count` points.
    pub fn error_against(
        &self,
        exact: &dyn Sdf,
        count: usize,
        seed: u64,
        band: f64,
        keep: impl Fn(&Vec3) -> bool,
    ) -> VoxelError {
        let mut rng = crate::rng::SplitMix64(seed);
        let hi = self.max_corner();
        let (mut max, mut sum2, mut n) = (0.0f64, 0.0, 0usize);
        for _ in 0..count.saturating_mul(50) {
            if n >= count {
                break;
            }
            let p = rng.in_box(self.origin, hi);
            let e = exact.distance(&p);
            if e.abs() > band || !keep(&p) {
                continue;
            }
            let d = (self.distance(&p) - e).abs();
            max = max.max(d);
            sum2 += d * d;
            n += 1;
        }
        VoxelError {
            max,
            rms: if n > 0 { (sum2 / n as f64).sqrt() } else { f64::NAN },
            count: n,
        }
    }

    /// Write the grid (format in the type's docs).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        f.write_all(VOXEL_MAGIC)?;
        for d in self.dims {
            f.write_all(&(d as u64).to_le_bytes())?;
        }
        for x in [self.origin.x, self.origin.y, self.origin.z, self.spacing] {
            f.write_all(&x.to_le_bytes())?;
        }
        for v in &self.values {
            f.write_all(&v.to_le_bytes())?;
        }
        f.flush()
    }

    /// Read a grid written by [`VoxelSdf::write`]; errors name the file and
    /// what is wrong.
    pub fn read(path: &Path) -> Result<Self, GeometryError> {
        let err = |what: String| GeometryError(format!("{}: {what}", path.display()));
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| err(e.to_string()))?;
        if !bytes.starts_with(VOXEL_MAGIC) {
            return Err(err("not a surgbench voxel SDF (bad header line)".into()));
        }
        let head = VOXEL_MAGIC.len();
        if bytes.len() < head + 56 {
            return Err(err(format!("truncated header: {} bytes", bytes.len())));
        }
        let word = |i: usize| -> [u8; 8] { bytes[head + 8 * i..head + 8 * i + 8].try_into().expect("8 bytes") };
        let dims = [0, 1, 2].map(|i| u64::from_le_bytes(word(i)) as usize);
        let f = |i: usize| f64::from_le_bytes(word(i));
        let (origin, spacing) = (Vec3::new(f(3), f(4), f(5)), f(6));
        if dims.iter().any(|&d| d < 2)
            || !(spacing > 0.0 && spacing.is_finite())
            || !origin.iter().all(|x| x.is_finite())
        {
            return Err(err(format!(
                "bad grid header: dims {dims:?}, spacing {spacing}, origin {origin:?}"
            )));
        }
        let n = dims[0]
            .checked_mul(dims[1])
            .and_then(|x| x.checked_mul(dims[2]))
            .ok_or_else(|| err("grid too large".into()))?;
        let body = &bytes[head + 56..];
        if body.len() != n * 8 {
            return Err(err(format!(
                "expected {n} values ({} bytes) after the header, found {} bytes",
                n * 8,
                body.len()
            )));
        }
        let values: Vec<f64> = body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(err(format!("value {i} is not finite")));
        }
        Ok(Self {
            origin,
            spacing,
            dims,
            values,
        })
    }
}

impl Sdf for VoxelSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        self.distance_gradient(p).0
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let q = self.clamp_to_box(p);
        let d = p - q;
        let n = d.norm();
        let (v, g) = self.interp(&q);
        if n > 0.0 { (v + n, d / n) } else { (v, g) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_tube_distance_and_gradient() {
        let t = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1.0,
        };
        assert!((t.distance(&Vec3::new(5.0, 0.0, 3.0)) - 2.0).abs() < 1e-15);
        assert!((t.gradient(&Vec3::new(5.0, 0.0, 3.0)) - Vec3::z()).norm() < 1e-15);
    }
    /// Central differences of `sdf`'s gradient over `h` (m), unsymmetrised.
    fn fd_hessian(sdf: &dyn Sdf, p: &Vec3, h: f64) -> Mat3 {
        let mut m = Mat3::zeros();
        for k in 0..3 {
            let mut a = *p;
            let mut b = *p;
            a[k] += h;
            b[k] -= h;
            m.set_column(k, &((sdf.gradient(&a) - sdf.gradient(&b)) / (a[k] - b[k])));
        }
        m
    }

    /// `p` and its six central-difference neighbours at step `h`.
    fn stencil(p: &Vec3, h: f64) -> [Vec3; 7] {
        let e = |k: usize, s: f64| {
            let mut q = *p;
            q[k] += s * h;
            q
        };
        [*p, e(0, h), e(0, -h), e(1, h), e(1, -h), e(2, h), e(2, -h)]
    }

    /// Step of the finite-difference checks (m) and the smallest distance
    /// from a centreline the samples keep (m).
    const H: f64 = 1e-6;
    const RHO_MIN: f64 = 5e-4;
    /// Tolerance of analytic vs finite-difference Hessians (relative, in
    /// the Frobenius norm): central differences err by `h^2/6 |g'''|`, and
    /// `|g'''| / |Hess| ~ c / rho^2` with `c` of order a few for a tube, so
    /// `(h / rho_min)^2` = 4e-6 covers it; rounding of the gradient
    /// (`eps |p| / rho` ~ 1e-13) over `h` adds ~1e-10. A missing term is far
    /// larger: the bend term is `|w| / R` ~ 0.1, the radius-slope term
    /// `r' R / rho^2 / (1 / |w|)` ~ 1e-3.
    const TOL: f64 = (H / RHO_MIN) * (H / RHO_MIN);

    /// Largest relative error of `sdf.hessian` against differences of
    /// `sdf.gradient` over `count` seeded samples from `sample` that `keep`
    /// accepts (it sees the stencil, to reject points whose differences
    /// straddle a kink); also checks symmetry.
    fn worst_hessian_error(
        sdf: &dyn Sdf,
        count: usize,
        seed: u64,
        sample: impl Fn(&mut crate::rng::SplitMix64) -> Vec3,
        keep: impl Fn(&[Vec3; 7]) -> bool,
    ) -> (f64, usize) {
        let mut rng = crate::rng::SplitMix64(seed);
        let (mut worst, mut n) = (0.0f64, 0usize);
        for _ in 0..count * 50 {
            if n >= count {
                break;
            }
            let p = sample(&mut rng);
            if !keep(&stencil(&p, H)) {
                continue;
            }
            let a = sdf.hessian(&p);
            let fd = fd_hessian(sdf, &p, H);
            assert!(
                (a - a.transpose()).norm() <= 1e-12 * a.norm(),
                "hessian at {p:?} not symmetric: {a}"
            );
            let err = (a - fd).norm() / a.norm();
            assert!(err.is_finite(), "hessian at {p:?}: {a} vs differences {fd}");
            worst = worst.max(err);
            n += 1;
        }
        (worst, n)
    }

    fn straight() -> StraightTube {
        StraightTube {
            origin: Vec3::new(0.3, -0.2, 0.5),
            axis: Vec3::new(1.0, 2.0, 3.0).normalize(),
            radius: 2e-3,
        }
    }

    /// Random point within `[RHO_MIN, 4 mm]` of the straight tube's axis.
    fn near_straight(t: &StraightTube, rng: &mut crate::rng::SplitMix64) -> Vec3 {
        let v = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
        let side = (v - t.axis * t.axis.dot(&v)).normalize();
        t.origin + t.axis * (0.02 * (rng.unit() - 0.5)) + side * (RHO_MIN + 3.5e-3 * rng.unit())
    }

    /// A swept tube with lines, arcs turning two ways and a varying radius.
    fn swept() -> SweptTube {
        CenterlineBuilder::new(Vec3::new(0.01, 0.02, -0.03), Vec3::new(1.0, 0.2, 0.1))
            .line(10e-3)
            .arc(15e-3, 1.2, Vec3::z())
            .line(5e-3)
            .arc(8e-3, 2.0, Vec3::y())
            .build(&[(0.0, 2e-3), (20e-3, 1.5e-3), (40e-3, 2.5e-3)])
            .unwrap()
    }

    /// Random point of the swept tube's bounding box within 2 mm of its wall,
    /// `RHO_MIN` off the centreline and inside 0.6 of the smallest bend
    /// radius (where the closest centreline point is unique).
    fn near_swept(t: &SweptTube, rng: &mut crate::rng::SplitMix64) -> Option<Vec3> {
        let s = rng.unit() * t.length();
        let c = t.point_at(s);
        let v = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 2.0 * 4.8e-3;
        let p = c + v;
        let h = t.project(&p);
        (h.radial >= RHO_MIN && h.radial <= 0.6 * 8e-3 && h.phi.abs() <= 2e-3).then_some(p)
    }

    /// The whole stencil lies on one piece, one profile segment, and on the
    /// same side of "interior hit vs end cap": no kink of the gradient in it.
    fn swept_smooth(t: &SweptTube, st: &[Vec3; 7]) -> bool {
        let key = |p: &Vec3| {
            let (h, hit) = t.project_full(p);
            let seg = t.profile.partition_point(|q| q.0 <= h.s);
            (h.piece, seg, hit.ds_dp == Vec3::zeros())
        };
        let k0 = key(&st[0]);
        st.iter().all(|p| key(p) == k0)
    }

    #[test]
    fn analytic_hessians_match_differences_of_the_gradient() {
        let t = straight();
        let (e, n) = worst_hessian_error(&t, 200, 1, |r| near_straight(&t, r), |_| true);
        eprintln!("straight tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "straight tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        let sw = swept();
        let sample = |r: &mut crate::rng::SplitMix64| loop {
            if let Some(p) = near_swept(&sw, r) {
                return p;
            }
        };
        let (e, n) = worst_hessian_error(&sw, 400, 2, sample, |st| swept_smooth(&sw, st));
        eprintln!("swept tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 400 && e < TOL,
            "swept tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        let iso = Iso3::from_parts(
            nalgebra::Translation3::new(0.3, -0.2, 0.5),
            nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(Vec3::new(1.0, 2.0, 3.0)), 0.7),
        );
        let moved = TransformedSdf::new(Arc::new(swept()), iso);
        let back = |p: &Vec3| iso.inverse_transform_point(&(*p).into()).coords;
        let sample = |r: &mut crate::rng::SplitMix64| loop {
            if let Some(p) = near_swept(&sw, r) {
                return iso.transform_point(&p.into()).coords;
            }
        };
        let (e, n) = worst_hessian_error(&moved, 200, 3, sample, |st| swept_smooth(&sw, &st.map(|p| back(&p))));
        eprintln!("transformed swept tube: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "transformed tube: rel err {e:e} (tol {TOL:e}) over {n} points"
        );

        // Two straight tubes crossing at right angles; skip the seam.
        let a = straight();
        let b = StraightTube {
            axis: a.axis.cross(&Vec3::x()).normalize(),
            ..a
        };
        let u = SdfUnion {
            parts: vec![Arc::new(a), Arc::new(b)],
        };
        let sample = |r: &mut crate::rng::SplitMix64| {
            if r.unit() < 0.5 {
                near_straight(&a, r)
            } else {
                near_straight(&b, r)
            }
        };
        let same_part = |st: &[Vec3; 7]| {
            let i = u.closest_part(&st[0]).map(|x| x.0);
            let far = a.distance(&st[0]).min(b.distance(&st[0])) > -a.radius + RHO_MIN;
            far && st.iter().all(|p| u.closest_part(p).map(|x| x.0) == i)
        };
        let (e, n) = worst_hessian_error(&u, 200, 4, sample, same_part);
        eprintln!("union: worst rel err {e:.2e} over {n} points");
        assert!(
            n == 200 && e < TOL,
            "union: rel err {e:e} (tol {TOL:e}) over {n} points"
        );
    }

    /// The swept tube's Hessian has the bend term: on an arc it differs
    /// from the straight-tube formula `(I - n n^T - t t^T) / |w|` by
    /// `t t^T (R / rho - 1) / |w|`, which the check above would catch (it is
    /// ~|w|/R relative); and for a constant radius the Hessian of the exact
    /// SDF annihilates the normal.
    #[test]
    fn swept_tube_hessian_has_the_bend_term() {
        let tube = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
            .arc(10e-3, 1.0, Vec3::y())
            .build_constant(2e-3)
            .unwrap();
        // In-plane point 1.5 mm outside the centreline (away from the centre).
        let s = 5e-3;
        let n = (tube.point_at(s) - Vec3::new(0.0, 10e-3, 0.0)).normalize();
        let p = tube.point_at(s) + n * 1.5e-3;
        let t = tube.tangent_at(s);
        let w = 1.5e-3;
        let rho = 10e-3 + w;
        let expect = (Mat3::identity() - n * n.transpose() - t * t.transpose() * (10e-3 / rho)) / w;
        let got = tube.hessian(&p);
        let err = (got - expect).norm() / expect.norm();
        // Same closed form, evaluated two ways: rounding only.
        assert!(err < 1e-12, "arc hessian {got} vs closed form {expect} (rel {err:e})");
        let hn = (got * tube.gradient(&p)).norm() * w;
        assert!(hn < 1e-12, "Hess phi n = {hn:e} (relative to 1/|w|), should vanish");
    }

    /// The default `hessian` (differences of the gradient over
    /// `HESSIAN_FD_STEP`) against the analytic one of a straight tube.
    #[test]
    fn default_hessian_matches_analytic() {
        #[derive(Debug)]
        struct GradientOnly(StraightTube);
        impl Sdf for GradientOnly {
            fn distance(&self, p: &Vec3) -> f64 {
                self.0.distance(p)
            }
            fn gradient(&self, p: &Vec3) -> Vec3 {
                self.0.gradient(p)
            }
        }
        let t = straight();
        let g = GradientOnly(t);
        let mut rng = crate::rng::SplitMix64(5);
        let mut worst = 0.0f64;
        for _ in 0..200 {
            let p = near_straight(&t, &mut rng);
            let err = (g.hessian(&p) - t.hessian(&p)).norm() / t.hessian(&p).norm();
            worst = worst.max(err);
        }
        eprintln!("default FD hessian: worst rel err {worst:.2e}");
        // Same truncation bound as above: the step is H and rho >= RHO_MIN.
        assert!(worst < TOL, "default hessian rel err {worst:e} (tol {TOL:e})");
    }
}
