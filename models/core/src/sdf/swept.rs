//! Tubes swept along G1 centrelines of lines and circular arcs
//! ([`CenterlineBuilder`], [`SweptTube`]): closest-point projection, distance
//! and the tube surface as a triangle mesh.

use super::*;
use crate::io::TriSurface;
use crate::{Iso3, Mat3, Vec3};

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
pub(super) struct PieceHit {
    /// Arclength from the piece's start (m).
    s: f64,
    /// Closest centreline point (m).
    point: Vec3,
    /// Derivative of `s` with respect to the query point (zero at the ends).
    pub(super) ds_dp: Vec3,
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
    pub(super) profile: Vec<(f64, f64)>,
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
        frame_along(&self.point_at(s), &self.tangent_at(s))
    }

    /// Project `p` on the centreline (see the type's docs for `phi`).
    pub fn project(&self, p: &Vec3) -> Projection {
        self.project_full(p).0
    }

    /// The projection and the winning piece's closest-point data (with the
    /// derivatives of `s`).
    pub(super) fn project_full(&self, p: &Vec3) -> (Projection, PieceHit) {
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

/// A frame at `origin` (m) with local +x along the unit `tangent` and local
/// y = helper x tangent (helper: world z, or world x when the tangent is
/// within ~25 deg of z): the clamp pose of a wire entering along `tangent`.
pub fn frame_along(origin: &Vec3, tangent: &Vec3) -> Iso3 {
    let t = *tangent;
    let helper = if t.z.abs() < 0.9 { Vec3::z() } else { Vec3::x() };
    let y = helper.cross(&t).normalize();
    let z = t.cross(&y);
    let m = crate::Mat3::from_columns(&[t, y, z]);
    let rot = nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m));
    Iso3::from_parts((*origin).into(), rot)
}
