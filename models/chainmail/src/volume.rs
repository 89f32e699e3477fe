//! Volumetric chain-mail of a moving vessel: the paper's vessel and blood
//! elements, for scenes whose vessel beats ([`surgbench_core::motion`]).
//!
//! The lumen and the wall around it are sampled on a cubic lattice of
//! spacing `h` (m) aligned with the base clamp (so it moves rigidly with the
//! scene), flood-filled from the clamp over the points with rest level set
//! `phi_0 <= 2 h` within the wire's reach. Three kinds of element:
//!
//! - **driven** (`phi_0 > 0`, the wall tissue, two layers): moved by the
//!   heart, `x = X + u(X, t)` from the scene's prescribed motion;
//! - **wall** (`-h < phi_0 <= 0`, the lumen's boundary layer): vessel
//!   elements linked to their one-ring (six face) neighbours with the
//!   chain-mail parameters `(alpha_min, alpha_max, beta)` of the vessel: a
//!   moved sponsor pushes a neighbour that leaves its valid box to the
//!   nearest point of the box ([`crate::rules::project_into_box`]), which
//!   sponsors its own neighbours in turn (each element moves once per
//!   propagation, as in Gibson 1997); then `iterations` relaxation sweeps
//!   `P* = mean(Q_i)`, `Q_i = P_i* + delta_i` ([`crate::rules::relaxation_target`]);
//! - **blood** (`phi_0 <= -h`): linked by virtual links with parameters
//!   `(1, 1, 0)` to the element that reached them first in a breadth-first
//!   order from the wall, and moved with it: `q* = q + (p* - p)`.
//!
//! The wire collides with the lumen the lattice carries: the rest level set
//! pulled back through the lattice's displacement, interpolated trilinearly
//! over each cell ([`VesselLattice::rest_point`]); its friction measures slip
//! against the lattice's motion over the step. Where the box slack lets the
//! wall lag the heart, the wire sees the lagging wall: that lag is the
//! model's, and [`VesselLattice::tracking_error`] reports it against the
//! prescribed motion (the harness shows it as `diag_vessel_lag_*`).
//!
//! The vessel's link parameters are model knobs, not a material mapping: the
//! scene prescribes the wall's motion, so they only say how far the
//! chain-mail's wall may deviate from it (fidelity extras `vessel_slack`,
//! `vessel_beta`).

use crate::rules::{LinkParams, project_into_box};
use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Arc;
use surgbench_core::motion::VesselMotion;
use surgbench_core::{Iso3, Mat3, Sdf, Vec3};

/// What an element of the vessel lattice is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Wall tissue moved by the heart (prescribed).
    Driven,
    /// The lumen's boundary layer, moved by the chain-mail rules.
    Wall,
    /// Blood, carried by a virtual link.
    Blood,
}

/// How to build a [`VesselLattice`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeConfig {
    /// Lattice spacing `h` (m).
    pub spacing: f64,
    /// Radius around the clamp the lattice covers (m): the wire's reach.
    pub reach: f64,
    /// Link parameters between vessel (driven and wall) elements.
    pub links: LinkParams,
    /// Relaxation sweeps per step.
    pub iterations: usize,
}

/// Hasher for lattice cell indices: one multiply-rotate per word (the
/// interpolation looks up eight cells per query, thousands per step, where
/// the default SipHash dominated the cost). Fixed, so lookups are
/// deterministic; cell keys are not adversarial.
#[derive(Debug, Clone, Copy, Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_i32(&mut self, i: i32) {
        self.write_u64(i as u32 as u64);
    }
    fn write_u64(&mut self, i: u64) {
        self.0 = (self.0.rotate_left(5) ^ i).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

type CellMap = HashMap<[i32; 3], usize, BuildHasherDefault<CellHasher>>;

/// Largest lattice the model builds (elements); a finer spacing or longer
/// reach is refused with its count rather than exhausting memory.
pub const MAX_ELEMENTS: usize = 2_000_000;

/// The volumetric chain-mail of a moving vessel (see the module docs).
#[derive(Debug, Clone)]
pub struct VesselLattice {
    h: f64,
    /// Lattice frame: origin and axes (columns) of the base clamp.
    origin: Vec3,
    axes: Mat3,
    rest_sdf: Arc<dyn Sdf>,
    motion: Arc<dyn VesselMotion>,
    links: LinkParams,
    iterations: usize,
    cells: CellMap,
    kind: Vec<Kind>,
    rest: Vec<Vec3>,
    x: Vec<Vec3>,
    x_old: Vec<Vec3>,
    /// Face neighbours among driven and wall elements, compressed:
    /// element `e`'s are `ring[ring_start[e]..ring_start[e + 1]]`.
    ring_start: Vec<usize>,
    ring: Vec<usize>,
    /// Driven elements.
    driven: Vec<usize>,
    /// Wall elements with a neighbour, each with `X_e - mean_j X_j` over
    /// its ring: the relaxation target `mean_j (x_j + X_e - X_j)` is
    /// `mean_j x_j` plus this constant.
    wall: Vec<(usize, Vec3)>,
    /// Scratch: which elements this step's propagation moved, and its queue.
    moved: Vec<bool>,
    queue: VecDeque<usize>,
    /// `(blood element, sponsor)` in breadth-first order from the wall.
    blood: Vec<(usize, usize)>,
    time: f64,
}

/// The lattice cells flooded from the clamp: cell index, kind and rest
/// position of every element, in flood order.
struct Flood {
    cells: CellMap,
    ijk: Vec<[i32; 3]>,
    kind: Vec<Kind>,
    rest: Vec<Vec3>,
}

impl Flood {
    /// Flood the lumen of `rest_sdf` breadth-first from the cell at `origin`
    /// (lattice axes `axes`, spacing and reach from `cfg`), out to the
    /// driven layer beyond the wall.
    fn new(rest_sdf: &dyn Sdf, origin: Vec3, axes: Mat3, cfg: &LatticeConfig) -> Result<Self, String> {
        let h = cfg.spacing;
        let at = |k: [i32; 3]| origin + axes * Vec3::new(k[0] as f64, k[1] as f64, k[2] as f64) * h;
        let mut cells = CellMap::default();
        let (mut ijk, mut kind, mut rest) = (Vec::new(), Vec::new(), Vec::new());
        let mut queue = VecDeque::from([[0i32; 3]]);
        cells.insert([0i32; 3], 0usize);
        let classify = |phi: f64| {
            if phi > 0.0 {
                Kind::Driven
            } else if phi > -h {
                Kind::Wall
            } else {
                Kind::Blood
            }
        };
        let phi0 = rest_sdf.distance(&origin);
        ijk.push([0; 3]);
        kind.push(classify(phi0));
        rest.push(origin);
        while let Some(k) = queue.pop_front() {
            for f in FACES {
                let n = [k[0] + f[0], k[1] + f[1], k[2] + f[2]];
                if cells.contains_key(&n) {
                    continue;
                }
                let p = at(n);
                if (p - origin).norm() > cfg.reach {
                    continue;
                }
                let phi = rest_sdf.distance(&p);
                if phi > 2.0 * h {
                    continue;
                }
                if ijk.len() >= MAX_ELEMENTS {
                    return Err(format!(
                        "vessel lattice exceeds {MAX_ELEMENTS} elements at vessel_spacing {h} m: use a coarser spacing"
                    ));
                }
                cells.insert(n, ijk.len());
                ijk.push(n);
                kind.push(classify(phi));
                rest.push(p);
                // driven elements do not spread the flood further out
                if phi <= h {
                    queue.push_back(n);
                }
            }
        }
        Ok(Self { cells, ijk, kind, rest })
    }
}

/// The face neighbours among driven and wall elements, compressed: element
/// `e`'s are `ring[ring_start[e]..ring_start[e + 1]]`.
fn rings(cells: &CellMap, ijk: &[[i32; 3]], kind: &[Kind]) -> (Vec<usize>, Vec<usize>) {
    let (mut ring_start, mut ring) = (vec![0], Vec::new());
    for e in 0..ijk.len() {
        if kind[e] != Kind::Blood {
            for f in FACES {
                let k = ijk[e];
                if let Some(&j) = cells.get(&[k[0] + f[0], k[1] + f[1], k[2] + f[2]])
                    && kind[j] != Kind::Blood
                {
                    ring.push(j);
                }
            }
        }
        ring_start.push(ring.len());
    }
    (ring_start, ring)
}

/// `(blood element, sponsor)` breadth-first from the wall layer inwards:
/// each blood element's sponsor is the neighbour that reached it first.
fn blood_sponsors(cells: &CellMap, ijk: &[[i32; 3]], kind: &[Kind]) -> Vec<(usize, usize)> {
    let mut blood = Vec::new();
    let mut reached: Vec<bool> = kind.iter().map(|&k| k != Kind::Blood).collect();
    let mut q: VecDeque<usize> = (0..ijk.len()).filter(|&e| kind[e] == Kind::Wall).collect();
    while let Some(e) = q.pop_front() {
        for f in FACES {
            let k = ijk[e];
            if let Some(&j) = cells.get(&[k[0] + f[0], k[1] + f[1], k[2] + f[2]])
                && !reached[j]
            {
                reached[j] = true;
                blood.push((j, e));
                q.push_back(j);
            }
        }
    }
    blood
}

const FACES: [[i32; 3]; 6] = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];

impl VesselLattice {
    /// Sample the lumen of `rest_sdf` around the clamp pose `clamp` (the
    /// flood starts at the clamp, which must lie in the lumen).
    pub fn new(
        rest_sdf: Arc<dyn Sdf>,
        motion: Arc<dyn VesselMotion>,
        clamp: &Iso3,
        cfg: &LatticeConfig,
    ) -> Result<Self, String> {
        let h = cfg.spacing;
        if !(h > 0.0 && h.is_finite()) {
            return Err(format!("vessel_spacing must be > 0 m, got {h}"));
        }
        if !(cfg.reach > 0.0 && cfg.reach.is_finite()) {
            return Err(format!("lattice reach must be > 0 m, got {}", cfg.reach));
        }
        cfg.links.validate()?;
        let origin = clamp.translation.vector;
        let axes = clamp.rotation.to_rotation_matrix().into_inner();
        if !(rest_sdf.distance(&origin) < 0.0) {
            return Err("the clamp is not inside the vessel lumen: no lattice to flood".into());
        }
        let Flood { cells, ijk, kind, rest } = Flood::new(rest_sdf.as_ref(), origin, axes, cfg)?;
        let ne = ijk.len();
        let (ring_start, ring) = rings(&cells, &ijk, &kind);
        let driven: Vec<usize> = (0..ne).filter(|&e| kind[e] == Kind::Driven).collect();
        let wall: Vec<(usize, Vec3)> = (0..ne)
            .filter(|&e| kind[e] == Kind::Wall && ring_start[e + 1] > ring_start[e])
            .map(|e| {
                let nb = &ring[ring_start[e]..ring_start[e + 1]];
                let mean = nb.iter().map(|&j| rest[j]).sum::<Vec3>() / nb.len() as f64;
                (e, rest[e] - mean)
            })
            .collect();
        let blood = blood_sponsors(&cells, &ijk, &kind);
        if !kind.contains(&Kind::Wall) {
            return Err(format!(
                "vessel_spacing {h} m resolves no wall layer of the lumen: use a finer spacing"
            ));
        }
        let mut lat = Self {
            h,
            origin,
            axes,
            rest_sdf,
            motion,
            links: cfg.links,
            iterations: cfg.iterations,
            cells,
            kind,
            x: rest.clone(),
            x_old: rest.clone(),
            rest,
            ring_start,
            ring,
            driven,
            wall,
            moved: vec![false; ne],
            queue: VecDeque::new(),
            blood,
            time: 0.0,
        };
        lat.advance(0.0);
        lat.x_old.clone_from(&lat.x);
        Ok(lat)
    }

    /// Element positions (m) and kinds.
    pub fn elements(&self) -> impl Iterator<Item = (Vec3, Vec3, Kind)> + '_ {
        (0..self.x.len()).map(|e| (self.rest[e], self.x[e], self.kind[e]))
    }

    /// The paper's per-step volumetric chain-mail at time `t` (s): the heart
    /// moves the driven elements, they sponsor the wall by the valid boxes,
    /// the wall relaxes, the blood follows by its virtual links.
    pub fn advance(&mut self, t: f64) {
        self.x_old.clone_from(&self.x);
        self.time = t;
        self.moved.fill(false);
        self.queue.clear();
        for &e in &self.driven {
            self.x[e] = self.rest[e] + self.motion.displacement(&self.rest[e], t);
            self.moved[e] = true;
            self.queue.push_back(e);
        }
        // geometric deformation: propagate from the moved sponsors
        while let Some(s) = self.queue.pop_front() {
            for idx in self.ring_start[s]..self.ring_start[s + 1] {
                let k = self.ring[idx];
                if self.moved[k] {
                    continue;
                }
                let d = self.axes.tr_mul(&(self.rest[k] - self.rest[s]));
                let (p, m) = project_into_box(&self.x[s], &self.x[k], &d, &self.axes, &self.links);
                if m {
                    self.x[k] = p;
                    self.moved[k] = true;
                    self.queue.push_back(k);
                }
            }
        }
        // physical optimization of the wall layer: P* = mean_j (x_j + X_e -
        // X_j) (the minimiser of sum ||P* - Q_j||^2, `relaxation_target`)
        for _ in 0..self.iterations {
            for &(e, c) in &self.wall {
                let nb = &self.ring[self.ring_start[e]..self.ring_start[e + 1]];
                let sum: Vec3 = nb.iter().map(|&j| self.x[j]).sum();
                self.x[e] = sum / nb.len() as f64 + c;
            }
        }
        // blood follows its sponsor: q* = q + (p* - p)
        for &(b, s) in &self.blood {
            let d = self.x[s] - self.x_old[s];
            self.x[b] += d;
        }
    }

    /// Lattice coordinates of `p` (in cells).
    fn local(&self, p: &Vec3) -> Vec3 {
        self.axes.tr_mul(&(p - self.origin)) / self.h
    }

    /// Trilinear interpolation of `f(element)` at rest point `xr` and its
    /// gradient in world coordinates (per unit length); corners outside the
    /// lattice drop out and the weights are renormalised (zero far away).
    fn interpolate(&self, xr: &Vec3, f: impl Fn(usize) -> Vec3) -> (Vec3, Mat3) {
        let l = self.local(xr);
        let b = [l.x.floor(), l.y.floor(), l.z.floor()];
        let fr = Vec3::new(l.x - b[0], l.y - b[1], l.z - b[2]);
        let (mut v, mut dv, mut wsum, mut dwsum) = (Vec3::zeros(), Mat3::zeros(), 0.0, Vec3::zeros());
        for c in 0..8 {
            let o = [c & 1, (c >> 1) & 1, (c >> 2) & 1];
            let k = [b[0] as i32 + o[0], b[1] as i32 + o[1], b[2] as i32 + o[2]];
            let Some(&e) = self.cells.get(&k) else { continue };
            let wk = |a: usize, s: f64| if o[a] == 1 { s } else { 1.0 - s };
            let sg = |a: usize| if o[a] == 1 { 1.0 } else { -1.0 };
            let (wx, wy, wz) = (wk(0, fr.x), wk(1, fr.y), wk(2, fr.z));
            let w = wx * wy * wz;
            let dw = Vec3::new(sg(0) * wy * wz, sg(1) * wx * wz, sg(2) * wx * wy);
            let fe = f(e);
            v += fe * w;
            dv += fe * dw.transpose();
            wsum += w;
            dwsum += dw;
        }
        if wsum <= 1e-12 {
            return (Vec3::zeros(), Mat3::zeros());
        }
        // gradient of (sum w f) / (sum w), then from lattice to world units
        let val = v / wsum;
        let grad_local = (dv - val * dwsum.transpose()) / wsum;
        (val, grad_local * self.axes.transpose() / self.h)
    }

    /// The lattice's displacement `U(X)` (m) at rest point `X` and `dU/dX`.
    pub fn displacement(&self, xr: &Vec3) -> (Vec3, Mat3) {
        self.interpolate(xr, |e| self.x[e] - self.rest[e])
    }

    /// The rest point `X` with `X + U(X) = p` (fixed-point iteration
    /// `X <- p - U(X)`, a contraction while `|dU/dX| < 1`; stops at 1e-12 m).
    pub fn rest_point(&self, p: &Vec3) -> Vec3 {
        let mut xr = *p;
        for _ in 0..50 {
            let next = p - self.displacement(&xr).0;
            let done = (next - xr).norm() <= 1e-12;
            xr = next;
            if done {
                break;
            }
        }
        xr
    }

    /// Where the wall point at `p` moved over the last step (m): the
    /// lattice's displacement increment there.
    pub fn step_motion(&self, p: &Vec3) -> Vec3 {
        let xr = self.rest_point(p);
        self.interpolate(&xr, |e| self.x[e] - self.x_old[e]).0
    }

    /// RMS and max distance (m) of the wall layer from where the prescribed
    /// motion puts it at the lattice's time: the volumetric chain-mail's lag.
    pub fn tracking_error(&self) -> (f64, f64) {
        let (mut s, mut mx, mut n) = (0.0, 0.0f64, 0usize);
        for e in 0..self.x.len() {
            if self.kind[e] != Kind::Wall {
                continue;
            }
            let target = self.rest[e] + self.motion.displacement(&self.rest[e], self.time);
            let d = (self.x[e] - target).norm();
            s += d * d;
            mx = mx.max(d);
            n += 1;
        }
        ((s / n.max(1) as f64).sqrt(), mx)
    }
}

impl Sdf for VesselLattice {
    fn distance(&self, p: &Vec3) -> f64 {
        self.rest_sdf.distance(&self.rest_point(p))
    }
    /// `F^-T grad phi_0(X)` with `F = I + dU/dX` of the trilinear field.
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let xr = self.rest_point(p);
        let (d, g0) = self.rest_sdf.distance_gradient(&xr);
        let f = Mat3::identity() + self.displacement(&xr).1;
        (d, f.transpose().try_inverse().map_or(g0, |fit| fit * g0))
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use surgbench_core::motion::CardiacMotion;
    use surgbench_core::sdf::StraightTube;

    fn tube() -> Arc<dyn Sdf> {
        Arc::new(StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: 1.5e-3,
        })
    }

    fn lattice(motion: CardiacMotion, links: LinkParams, iterations: usize) -> VesselLattice {
        let cfg = LatticeConfig {
            spacing: 5e-4,
            reach: 0.03,
            links,
            iterations,
        };
        VesselLattice::new(tube(), Arc::new(motion), &Iso3::identity(), &cfg).unwrap()
    }

    /// A motion that is a pure translation beyond `x = 0`: rigid vessel
    /// links carry it through the wall layer and the blood exactly
    /// (`alpha = 1`, `beta = 0`: the valid box is one point).
    #[test]
    fn rigid_links_carry_a_translation_exactly() {
        let m = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), -1.0, 0.5, 0.3e-3, 1.0).unwrap();
        let mut lat = lattice(m, LinkParams::RIGID, 0);
        lat.advance(0.5);
        let u = Vec3::z() * 0.3e-3;
        for (xr, x, k) in lat.elements() {
            // one propagation hop per element: rounding of m-scale sums
            assert!((x - xr - u).norm() < 1e-15, "{k:?} at {xr:?} moved to {x:?}");
        }
        assert!(lat.tracking_error().1 < 1e-15);
    }

    /// With slack in the boxes the wall lags the heart; relaxation sweeps
    /// pull it back, and the lag shrinks monotonically with the sweeps.
    #[test]
    fn relaxation_reduces_the_wall_lag() {
        let links = LinkParams {
            alpha_min: 0.8,
            alpha_max: 1.2,
            beta: 0.2,
        };
        let m = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.005, 0.02, 1e-3, 1.0).unwrap();
        let mut last = f64::INFINITY;
        for it in [0, 2, 8, 32] {
            let mut lat = lattice(m.clone(), links, it);
            lat.advance(0.5);
            let (rms, max) = lat.tracking_error();
            assert!(rms < last, "{it} sweeps: rms lag {rms} not below {last}");
            assert!(
                max.is_finite() && max > 0.0,
                "{it} sweeps: slack boxes lag somewhere, got {max}"
            );
            last = rms;
        }
    }

    /// The carried lumen is the rest lumen moved by the lattice: a rest wall
    /// point moved by the (exactly tracked) motion lies on it, and its
    /// gradient matches differences of its value.
    #[test]
    fn lattice_lumen_follows_the_motion() {
        let m = CardiacMotion::new(Vec3::zeros(), Vec3::x(), Vec3::z(), 0.005, 0.02, 1e-3, 1.0).unwrap();
        let mut lat = lattice(m.clone(), LinkParams::RIGID, 0);
        let t = 0.4;
        // every element exactly where the motion puts it: what is left is
        // the interpolation
        for e in 0..lat.x.len() {
            lat.x[e] = lat.rest[e] + m.displacement(&lat.rest[e], t);
        }
        for i in 0..20 {
            let a = i as f64 * 0.3;
            // off the lattice's cell faces (x = k h), where the trilinear
            // field's gradient jumps
            let xr = Vec3::new(0.00213 + i as f64 * 0.97e-3, 1.5e-3 * a.cos(), 1.5e-3 * a.sin());
            let x = xr + m.displacement(&xr, t);
            // The lattice interpolates u trilinearly: error h^2/8 |u''| with
            // |u''| <= 6 A s / L^2 = 15 1/m here, i.e. <= 4.7e-7 m.
            assert!(lat.distance(&x).abs() < 5e-7, "wall point {x:?}: {}", lat.distance(&x));
            let hstep = 1e-7;
            let g = lat.gradient(&x);
            for k in 0..3 {
                let mut a = x;
                let mut b = x;
                a[k] += hstep;
                b[k] -= hstep;
                let dg = (lat.distance(&a) - lat.distance(&b)) / (2.0 * hstep);
                // the inverse map stops at 1e-12 m: 1e-12 / 1e-7 = 1e-5 in
                // the difference quotient (no sample straddles a cell face)
                assert!((dg - g[k]).abs() < 1e-4, "gradient {k} at {x:?}: {dg} vs {}", g[k]);
            }
        }
    }
}
