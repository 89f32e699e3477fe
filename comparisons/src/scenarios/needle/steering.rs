//! `needle-bevel` and `needle-double-bend`: a flexible bevel-tip needle
//! steered through a gel block (the needle seed, Chentanez et al. 2009
//! Sec. 3.5 and its double-bend figure). The bevel makes the tip cut to the
//! side of its material axis m_2, so the needle bends; half a turn of the
//! base turns the bevel and the path bends back.
//!
//! No phantom data for these scenes are held here (DESIGN.md names phantom
//! curvature and marker RMS; `../shared/datasets` has none for needles).
//! Issue 17 asks for a converged run of the finest fidelity as the
//! reference; none exists yet: the needle model's path depends on the mesh
//! (at the defaults the tip ends 2.46, 1.04 and 0.05 mm off the axis at
//! mesh levels 0, 1 and 2, and level 2 inverts tets at the tip: the
//! coupling's point forces, the cutting force among them, crush an ever
//! smaller tet, as a point load in 3D elasticity must). The scorer reports
//! the path's shape at every level, and scores it against a converged run
//! cached in `datasets/reference/<scene>/tip_trajectory.csv` (`t,x,y,z`,
//! default parameters only) once one exists.
//!
//! The scored path is the tip's, in its bend plane: `x` along the
//! insertion, `s` the lateral offset along the direction the tip has moved
//! to (the bevel's side). The kinematic bicycle model of bevel-tip needles
//! (Webster, Kim, Cowan, Chirikjian, Okamura, IJRR 25(5), 2006) says the
//! tip follows an arc of constant curvature while the base does not turn;
//! `arc_fit_residual_rel` is how far the path is from its best such arc.

use super::*;
use crate::params;
use crate::references::{TipTrajectory, cached_reference};
use crate::scenario::{
    Declared, Inputs, Metrics, ParamSet, ParamSpec, PlanePoint, Range, Reference, ScenarioInfo, ScenarioRun, Scorer,
    Target,
};
use surgbench_core::{Family, NeedleTissue, Observation, Scene};

// Parameters both steering scenes share.
/// Speed of the base (m/s).
const P_SPEED: ParamSpec = ParamSpec::new("insertion_speed", 0.01, "m/s", Range::Positive, "speed of the base");
/// Tip depth when the base stops (m).
const P_DEPTH: ParamSpec = ParamSpec::new(
    "depth",
    0.015,
    "m",
    Range::Positive,
    "tip depth below the entry face when the base stops (along the insertion)",
);
/// Tip distance outside the entry face at t = 0 (m).
const P_TIP_GAP: ParamSpec = ParamSpec::new(
    "tip_gap",
    0.001,
    "m",
    Range::Positive,
    "tip distance outside the entry face at t = 0",
);
/// Bevel angle (rad): illustrative, not a measurement.
const P_BEVEL: ParamSpec = ParamSpec::new(
    "bevel_angle",
    0.25,
    "rad",
    Range::Open(0.0, 1.5),
    "bevel angle psi: the tip cuts d tan(psi) to the side per d of advance",
);
/// The flexible needle's Young's modulus (Pa): nitinol-like, as the seed's phantom needle is nitinol.
const P_FLEXIBLE_NEEDLE_YOUNGS: ParamSpec = ParamSpec::new(
    "needle_youngs_modulus",
    50e9,
    "Pa",
    Range::Positive,
    "needle Young's modulus (flexible against the gel)",
);

params! {
    /// Parameters of `needle-bevel`: the gel, friction and cutting force of
    /// `needle-straight`; a flexible needle (50 GPa: nitinol-like, as the
    /// seed's phantom needle is nitinol) with a bevel. The bevel angle is an
    /// illustrative value of this scene, not a measurement.
    pub struct BevelParams {
        insertion_speed: P_SPEED,
        depth: P_DEPTH,
        tip_gap: P_TIP_GAP,
        bevel_angle: P_BEVEL,
        friction_per_length: P_FRICTION_PER_LENGTH,
        cutting_force: P_CUTTING_FORCE,
        needle_length: P_NEEDLE_LENGTH,
        needle_radius: P_NEEDLE_RADIUS,
        needle_youngs_modulus: P_FLEXIBLE_NEEDLE_YOUNGS,
        youngs_modulus: P_GEL_YOUNGS,
        poisson_ratio: P_GEL_POISSON,
        density: P_GEL_DENSITY,
        block_length: P_BLOCK_LENGTH,
        block_width: P_BLOCK_WIDTH,
    }
}

params! {
    /// Parameters of `needle-double-bend`: those of `needle-bevel`, and the
    /// base turned by half a turn at `base_rotation_rate` once the tip is
    /// `turn_depth` deep.
    pub struct DoubleBendParams {
        insertion_speed: P_SPEED,
        depth: P_DEPTH,
        turn_depth: ParamSpec::new("turn_depth", 0.0075, "m", Range::Positive, "tip depth (along the insertion) at which the base starts its half turn"),
        base_rotation_rate: ParamSpec::new("base_rotation_rate", 20.0 * std::f64::consts::PI, "rad/s", Range::Positive, "rate of the base's half turn (pi rad in 50 ms at the default)"),
        tip_gap: P_TIP_GAP,
        bevel_angle: P_BEVEL,
        friction_per_length: P_FRICTION_PER_LENGTH,
        cutting_force: P_CUTTING_FORCE,
        needle_length: P_NEEDLE_LENGTH,
        needle_radius: P_NEEDLE_RADIUS,
        needle_youngs_modulus: P_FLEXIBLE_NEEDLE_YOUNGS,
        youngs_modulus: P_GEL_YOUNGS,
        poisson_ratio: P_GEL_POISSON,
        density: P_GEL_DENSITY,
        block_length: P_BLOCK_LENGTH,
        block_width: P_BLOCK_WIDTH,
    }
}

/// Tip depth (m) from which the path is scored: the first coupling points
/// are joining and the bevel has cut only a few steps before it.
const SCORE_FROM_DEPTH: f64 = 2e-3;

/// Base feed (m) after the base's half turn ends that belongs to neither
/// arc: the twist reaching the tip and the path turning over.
const TURN_SETTLE: f64 = 2e-3;

/// Half width (m, along the insertion) of the window the path's local
/// curvature is fitted over to find the inflection point.
const INFLECTION_HALF_WINDOW: f64 = 1e-3;

/// The finest mesh level these scenes accept: one past the sweep's finest
/// ([`MAX_LEVEL`]), 49,152 tets, ~16 minutes a run, for a converged
/// reference (see the module docs: none converges yet).
const REFERENCE_LEVEL: usize = MAX_LEVEL + 1;

/// A path in its bend plane: `(x, s)` points (m), `x` along the insertion.
type PlanePath = Vec<(f64, f64)>;

/// A timed path in its bend plane: `(t, x, s)` (s, m, m).
type TimedPath = Vec<(f64, f64, f64)>;

/// The circle of Kasa's algebraic least-squares fit (Kasa 1976, IEEE Trans.
/// Instrum. Meas. 25(1)) through `pts`: minimises
/// `sum (x^2 + s^2 + D x + E s + F)^2`. Returns the signed curvature (1/m:
/// positive when the centre lies towards +s) and the rms distance of the
/// points from the circle (m); a straight path (the normal equations
/// singular to rounding) has curvature 0 and its rms distance from the
/// least-squares line. `None` for fewer than three points. Third: the
/// circle itself, `(x_c, s_c, r)` (m), where the fit is not a line.
fn fit_arc(pts: &[(f64, f64)]) -> Option<(f64, f64, Option<[f64; 3]>)> {
    if pts.len() < 3 {
        return None;
    }
    // Centre and scale the points so the normal equations are well posed.
    let n = pts.len() as f64;
    let (cx, cs) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let scale = pts.iter().map(|p| (p.0 - cx).hypot(p.1 - cs)).fold(0.0, f64::max);
    if scale == 0.0 {
        return None;
    }
    let q: Vec<(f64, f64)> = pts.iter().map(|p| ((p.0 - cx) / scale, (p.1 - cs) / scale)).collect();
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for &(x, s) in &q {
        let row = nalgebra::Vector3::new(x, s, 1.0);
        a += row * row.transpose();
        b -= row * (x * x + s * s);
    }
    let line_rms = || {
        // Least-squares line through the centred points: its normal is the
        // eigenvector of the smallest eigenvalue of the scatter matrix.
        let (sxx, sxs, sss) = q.iter().fold((0.0, 0.0, 0.0), |a, p| {
            (a.0 + p.0 * p.0, a.1 + p.0 * p.1, a.2 + p.1 * p.1)
        });
        let m = nalgebra::Matrix2::new(sxx, sxs, sxs, sss);
        let smallest = m.symmetric_eigenvalues().min().max(0.0);
        (smallest / n).sqrt() * scale
    };
    // The curvature of a path this flat is below rounding.
    const SINGULAR: f64 = 1e-12;
    let sol = a.lu().solve(&b);
    let Some(sol) = sol.filter(|_| a.determinant().abs() > SINGULAR * a.norm().powi(3)) else {
        return Some((0.0, line_rms(), None));
    };
    let (xc, sc) = (-0.5 * sol[0], -0.5 * sol[1]);
    let r2 = xc * xc + sc * sc - sol[2];
    if !(r2 > 0.0) || !r2.is_finite() {
        return Some((0.0, line_rms(), None));
    }
    let r = r2.sqrt();
    let rms = (q
        .iter()
        .map(|&(x, s)| ((x - xc).hypot(s - sc) - r).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    // Scaled back: radius r * scale; the centre's side of the points.
    let kappa = sc.signum() / (r * scale);
    let circle = [cx + xc * scale, cs + sc * scale, r * scale];
    Some((kappa, rms * scale, Some(circle)))
}

/// The `s` of `circle` (`(x_c, s_c, r)`, m) at `x` on the branch nearer
/// `near`; NaN where the circle does not reach `x`.
fn circle_at(circle: [f64; 3], x: f64, near: f64) -> f64 {
    let [xc, sc, r] = circle;
    let h = (r * r - (x - xc) * (x - xc)).sqrt();
    if (sc + h - near).abs() <= (sc - h - near).abs() {
        sc + h
    } else {
        sc - h
    }
}

/// The local curvature of `path` at `x0`: the second derivative of the
/// least-squares parabola `s(x)` over `|x - x0| <= half` (1/m, in the
/// small-slope limit the bicycle model's curvature); `None` when fewer than
/// five points lie in the window.
fn local_curvature(path: &[(f64, f64)], x0: f64, half: f64) -> Option<f64> {
    let w: Vec<(f64, f64)> = path
        .iter()
        .filter(|p| (p.0 - x0).abs() <= half)
        .map(|p| ((p.0 - x0) / half, p.1))
        .collect();
    if w.len() < 5 {
        return None;
    }
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for &(u, s) in &w {
        let row = nalgebra::Vector3::new(1.0, u, u * u);
        a += row * row.transpose();
        b += row * s;
    }
    let c = a.lu().solve(&b)?;
    let slope = c[1] / half;
    Some(2.0 * c[2] / (half * half) / (1.0 + slope * slope).powf(1.5))
}

/// The first `x` in `[from, to]` where the local curvature of `path`
/// ([`local_curvature`] on a grid of `half / 4`) turns from the sign of
/// `before` to the other, linearly interpolated between grid points.
fn inflection(path: &[(f64, f64)], from: f64, to: f64, before: f64) -> Option<f64> {
    let h = INFLECTION_HALF_WINDOW / 4.0;
    let mut last: Option<(f64, f64)> = None;
    let mut x = from;
    while x <= to {
        if let Some(k) = local_curvature(path, x, INFLECTION_HALF_WINDOW) {
            if let Some((x0, k0)) = last
                && k0 * before > 0.0
                && k * before <= 0.0
            {
                return Some(x0 + (x - x0) * k0 / (k0 - k));
            }
            last = Some((x, k));
        }
        x += h;
    }
    None
}

/// Tip samples `(t, tip)` (s, m) as a path in the bend plane: `x` along
/// the insertion, `s` along the lateral direction of the tip at time
/// `t_plane` (the last sample at or before it), and the largest distance of
/// a point from that plane (m). `None` when the tip never left the
/// insertion axis (no plane).
fn in_plane(tips: &[(f64, Vec3)], t_plane: f64) -> Option<(TimedPath, f64)> {
    let at = tips.iter().rev().find(|p| p.0 <= t_plane)?.1;
    let lateral = Vec3::new(0.0, at.y, at.z);
    let norm = lateral.norm();
    if !(norm > 0.0) {
        return None;
    }
    let e = lateral / norm;
    let mut off = 0.0f64;
    let path = tips
        .iter()
        .map(|&(t, p)| {
            let s = p.y * e.y + p.z * e.z;
            off = off.max((Vec3::new(0.0, p.y, p.z) - e * s).norm());
            (t, p.x, s)
        })
        .collect();
    Some((path, off))
}

/// The `(x, s)` points of a timed plane path `(t, x, s)` with `t` in
/// `[lo, hi]` (s) and the tip at least [`SCORE_FROM_DEPTH`] deep.
fn window(path: &[(f64, f64, f64)], lo: f64, hi: f64) -> PlanePath {
    path.iter()
        .filter(|p| p.0 >= lo && p.0 <= hi && p.1 >= SCORE_FROM_DEPTH)
        .map(|p| (p.1, p.2))
        .collect()
}

/// How far a time (s) may fall short of another by rounding: a run's
/// last step time against the feed's end, a reference sample against the
/// run's time.
fn rounding_slack(t: f64) -> f64 {
    1e-9 * t.abs().max(1.0)
}

/// The metric-name suffix of arc `i` (0-based): none for a single arc,
/// `_1`, `_2` for the double bend's.
fn arc_tag(single: bool, i: usize) -> String {
    if single { String::new() } else { format!("_{}", i + 1) }
}

/// What the scorer needs of a steering scene.
struct SteeringRef {
    /// The cached converged run, at the default parameters.
    reference: Option<TipTrajectory>,
    /// Arcs scored, as `[lo, hi]` times (s; of each only the samples with
    /// the tip at least [`SCORE_FROM_DEPTH`] deep): one for the single
    /// bend, two for the double bend. The tip does not reach the base's
    /// feed depth (the gel ahead of it compresses), so the arcs are set by
    /// the feed's timeline.
    arcs: Vec<[f64; 2]>,
    /// When the base's half turn starts (s), for the double bend.
    turn_at: Option<f64>,
}

/// Shape metrics of one path (the model's or the reference's).
struct PathShape {
    /// Signed curvature of each arc (1/m).
    curvature: Vec<f64>,
    /// Per arc, rms distance from its best-fit arc over the arc's largest
    /// |s| (1).
    residual_rel: Vec<f64>,
    /// The inflection point (m, along the insertion), double bend only.
    inflection: Option<f64>,
    /// The largest distance from the bend plane (m).
    out_of_plane: f64,
    /// The last point's offset along the bend plane (m).
    deflection: f64,
    /// The path in its bend plane with, inside each scored arc's window,
    /// the best-fit arc's `s` at the same `x` (m).
    plane: Vec<PlanePoint>,
}

impl SteeringRef {
    /// The shape of the tip path `tips`; `None` while the first arc has
    /// not been traversed or the tip never left the axis.
    fn shape(&self, tips: &[(f64, Vec3)]) -> Option<PathShape> {
        let first = self.arcs.first()?;
        // (The run's last time may fall a rounding short of the feed's end.)
        if tips.last()?.0 < first[1] - rounding_slack(first[1]) {
            return None;
        }
        let (path, out_of_plane) = in_plane(tips, first[1])?;
        let mut curvature = Vec::new();
        let mut residual_rel = Vec::new();
        let mut plane: Vec<PlanePoint> = path
            .iter()
            .map(|&(_, x, s)| PlanePoint { x, s, fit: f64::NAN })
            .collect();
        for &[lo, hi] in &self.arcs {
            let pts = window(&path, lo, hi);
            let Some((k, rms, circle)) = fit_arc(&pts) else {
                continue;
            };
            let span = pts.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
            curvature.push(k);
            residual_rel.push(if span > 0.0 { rms / span } else { 0.0 });
            if let Some(c) = circle {
                for (q, p) in plane.iter_mut().zip(&path) {
                    if p.0 >= lo && p.0 <= hi && p.1 >= SCORE_FROM_DEPTH {
                        q.fit = circle_at(c, q.x, q.s);
                    }
                }
            }
        }
        let inflection = self.turn_at.zip(curvature.first()).and_then(|(t0, &k1)| {
            let xy: PlanePath = path.iter().map(|p| (p.1, p.2)).collect();
            let from = path.iter().find(|p| p.0 >= t0)?.1;
            let to = xy.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
            inflection(&xy, from, to - INFLECTION_HALF_WINDOW, k1)
        });
        Some(PathShape {
            curvature,
            residual_rel,
            inflection,
            out_of_plane,
            deflection: path.last().map_or(0.0, |p| p.2),
            plane,
        })
    }
}

/// Per-run tip samples of [`SteeringRef`].
struct SteeringScorer<'a> {
    r: &'a SteeringRef,
    /// `(t, tip)` every step (s, m).
    tips: Vec<(f64, Vec3)>,
    /// The largest distance from the reference tip at the same time (m),
    /// from [`SCORE_FROM_DEPTH`] on.
    worst_path: f64,
}

impl Scorer for SteeringScorer<'_> {
    fn observe_step(&mut self, obs: &Observation) {
        let Some(tip) = obs.rods.first().and_then(|r| r.nodes.last()) else {
            return;
        };
        if let Some(reference) = &self.r.reference
            && tip.x >= SCORE_FROM_DEPTH
        {
            self.worst_path = self.worst_path.max((tip - reference.at(obs.time)).norm());
        }
        self.tips.push((obs.time, *tip));
    }

    fn score(&self, obs: &Observation) -> Metrics {
        let mut m = Metrics::new();
        m.insert("reference_available".into(), self.r.reference.is_some() as u8 as f64);
        // Samples are in time order: the ones up to `obs.time` are a prefix.
        let tips = &self.tips[..self.tips.partition_point(|s| s.0 <= obs.time)];
        let Some(shape) = self.r.shape(tips) else {
            return m;
        };
        m.insert("tip_deflection_m".into(), shape.deflection);
        m.insert("out_of_plane_m".into(), shape.out_of_plane);
        let single = shape.curvature.len() == 1;
        for (i, (k, res)) in shape.curvature.iter().zip(&shape.residual_rel).enumerate() {
            let tag = arc_tag(single, i);
            m.insert(format!("curvature{tag}_per_m"), *k);
            m.insert(format!("arc_fit_residual{tag}_rel"), *res);
        }
        if let Some(x) = shape.inflection {
            m.insert("inflection_x_m".into(), x);
        }
        let Some(reference) = &self.r.reference else {
            return m;
        };
        // (Up to the run's time and the rounding its last step may fall
        // short by.)
        let until = obs.time + rounding_slack(obs.time);
        let ref_tips = &reference.samples[..reference.samples.partition_point(|s| s.0 <= until)];
        m.insert("tip_path_error_m".into(), self.worst_path);
        let Some(want) = self.r.shape(ref_tips) else {
            return m;
        };
        if want.curvature.len() == shape.curvature.len() {
            let worst = shape
                .curvature
                .iter()
                .zip(&want.curvature)
                .map(|(k, r)| (k - r).abs() / r.abs())
                .fold(0.0, f64::max);
            m.insert("curvature_error_rel".into(), worst);
            for (i, r) in want.curvature.iter().enumerate() {
                let tag = arc_tag(single, i);
                m.insert(format!("reference_curvature{tag}_per_m"), *r);
            }
        }
        if let (Some(x), Some(xr)) = (shape.inflection, want.inflection) {
            m.insert("inflection_error_m".into(), (x - xr).abs());
        }
        m
    }

    fn plane_path(&self, obs: &Observation) -> Vec<PlanePoint> {
        let tips = &self.tips[..self.tips.partition_point(|s| s.0 <= obs.time)];
        self.r.shape(tips).map(|shape| shape.plane).unwrap_or_default()
    }

    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        let p = self.r.reference.as_ref()?.at(t);
        Some([p.x, p.y, p.z])
    }
}

impl Reference for SteeringRef {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(SteeringScorer {
            r: self,
            tips: Vec::new(),
            worst_path: 0.0,
        })
    }
}

/// The target of both scenes: the curvature a steering planner plans with
/// (our choice: a tenth of the converged curvature; no published tolerance).
const CURVATURE_TARGET: Target = Target::new(
    0.1,
    "10 % of the converged run's curvature (our choice for a steering planner: no published tolerance)",
);

/// A flexible bevel-tip needle bent by its bevel in a gel block.
pub const NEEDLE_BEVEL: Declared<BevelParams> = Declared {
    info: ScenarioInfo {
        id: "needle-bevel",
        description: "flexible bevel-tip needle inserted into a gel block at constant speed: the tip path bends towards the bevel (single bend)",
        family: Family::Coupled,
        reference: "none converged yet (the needle model's path depends on the mesh: tip 2.46, 1.04, 0.05 mm off axis at levels 0-2, tets inverted at level 2); a converged run cached in datasets/reference/needle-bevel/tip_trajectory.csv is scored when present: curvature of the tip path's best-fit arc past 2 mm (curvature_error_rel), tip distance at equal times (tip_path_error_m); always: curvature_per_m, tip_deflection_m, and the kinematic bicycle model's constant curvature as arc_fit_residual_rel (Webster et al. 2006)",
        primary_error: "curvature_error_rel",
        target: CURVATURE_TARGET,
        params: BevelParams::SPECS,
        sweep: LEVELS,
        quick: 1,
        mesh: None,
    },
    datasets: None,
    build: build_bevel,
};

/// The bevel needle with half a turn of its base halfway: two arcs.
pub const NEEDLE_DOUBLE_BEND: Declared<DoubleBendParams> = Declared {
    info: ScenarioInfo {
        id: "needle-double-bend",
        description: "flexible bevel-tip needle into a gel block, the base turned by half a turn halfway: the path bends one way, then back (double bend)",
        family: Family::Coupled,
        reference: "none converged yet (as needle-bevel); a converged run cached in datasets/reference/needle-double-bend/tip_trajectory.csv is scored when present: curvature of both arcs (curvature_error_rel, the worse), the inflection point (inflection_error_m), tip distance at equal times (tip_path_error_m); always: curvature_1/2_per_m, inflection_x_m, arc_fit_residual_1/2_rel",
        primary_error: "curvature_error_rel",
        target: CURVATURE_TARGET,
        params: DoubleBendParams::SPECS,
        sweep: LEVELS,
        quick: 1,
        mesh: None,
    },
    datasets: None,
    build: build_double_bend,
};

/// What the two scenes share, from either's parameters.
struct Steering {
    speed: f64,
    depth: f64,
    tip_gap: f64,
    bevel_angle: f64,
    f_perlen: f64,
    f_cut: f64,
    needle_length: f64,
    needle_radius: f64,
    needle_youngs: f64,
    gel: [f64; 3],
    block_length: f64,
    block_width: f64,
}

impl Steering {
    /// The scene `id` with the base's rotation `turn` (s, rad keys added to
    /// the feed), scored over `arcs` (and the inflection after `turn_at`).
    fn run(
        &self,
        id: &str,
        inputs: &Inputs,
        turn: Option<(f64, f64)>,
        arcs: Vec<[f64; 2]>,
        turn_at: Option<f64>,
    ) -> Result<ScenarioRun, UsageError> {
        let level = mesh_level_up_to(id, inputs.fidelity, REFERENCE_LEVEL)?;
        let x_in = self.tip_gap + self.depth;
        if x_in >= self.needle_length {
            return Err(UsageError(format!(
                "{id}: needle_length {} m must exceed tip_gap + depth = {x_in} m (the guide sleeve stays out of the tissue)",
                self.needle_length
            )));
        }
        if self.depth >= self.block_length || self.depth <= SCORE_FROM_DEPTH + INFLECTION_HALF_WINDOW {
            return Err(UsageError(format!(
                "{id}: depth {} m must lie between {} m (the path is scored from 2 mm) and block_length {} m",
                self.depth,
                SCORE_FROM_DEPTH + INFLECTION_HALF_WINDOW,
                self.block_length
            )));
        }
        let (_, tissue) = held_block(id, level, self.block_length, self.block_width, self.gel)?;
        let needle = needle(
            self.needle_length,
            self.needle_radius,
            self.needle_youngs,
            -self.tip_gap,
        );
        let t_end = x_in / self.speed;
        let interaction = NeedleTissue {
            friction_per_length: self.f_perlen,
            cutting_force: self.f_cut,
            viscous_friction: 0.0,
            bevel_angle: self.bevel_angle,
        };
        let mut scene = needle_scene(id, needle, tissue, &[(0.0, 0.0), (t_end, x_in)], t_end, interaction);
        if let Some((t0, t1)) = turn {
            // The feed's keys with the rotation: 0 until t0, pi from t1.
            let feed = |t: f64| self.speed * t;
            let rot = std::f64::consts::PI;
            scene.control.keys = vec![
                ControlKey::feed(0.0, 0.0, 0.0),
                ControlKey::feed(t0, feed(t0), 0.0),
                ControlKey::feed(t1, feed(t1), rot),
                ControlKey::feed(t_end, x_in, rot),
            ];
        }
        let reference = SteeringRef {
            reference: cached_reference(id, inputs)?,
            arcs,
            turn_at,
        };
        // The push's work over the stroke, ten times over (as needle-straight).
        let energy = 10.0 * (self.f_cut + self.f_perlen * self.depth) * x_in + 1e-9;
        Ok(ScenarioRun::new(
            scene,
            reference,
            energy,
            self.needle_length + self.block_length,
        ))
    }
}

/// The [`Steering`] of a parameter set with its fields (either scene's).
macro_rules! steering {
    ($p:expr) => {
        Steering {
            speed: $p.insertion_speed,
            depth: $p.depth,
            tip_gap: $p.tip_gap,
            bevel_angle: $p.bevel_angle,
            f_perlen: $p.friction_per_length,
            f_cut: $p.cutting_force,
            needle_length: $p.needle_length,
            needle_radius: $p.needle_radius,
            needle_youngs: $p.needle_youngs_modulus,
            gel: [$p.youngs_modulus, $p.poisson_ratio, $p.density],
            block_length: $p.block_length,
            block_width: $p.block_width,
        }
    };
}

fn build_bevel(p: &BevelParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let s = steering!(p);
    let t_end = (p.tip_gap + p.depth) / p.insertion_speed;
    s.run(NEEDLE_BEVEL.info.id, inputs, None, vec![[0.0, t_end]], None)
}

fn build_double_bend(p: &DoubleBendParams, inputs: &Inputs) -> Result<ScenarioRun, UsageError> {
    let id = NEEDLE_DOUBLE_BEND.info.id;
    let s = steering!(p);
    let v = p.insertion_speed;
    let t0 = (p.tip_gap + p.turn_depth) / v;
    let t1 = t0 + std::f64::consts::PI / p.base_rotation_rate;
    let t_end = (p.tip_gap + p.depth) / v;
    // The feed depth when the turn ends, and the second arc's start.
    let turned = p.turn_depth + (t1 - t0) * v;
    let second = turned + TURN_SETTLE;
    if !(p.turn_depth > SCORE_FROM_DEPTH + 2.0 * INFLECTION_HALF_WINDOW
        && second + 2.0 * INFLECTION_HALF_WINDOW < p.depth)
    {
        return Err(UsageError(format!(
            "{id}: the half turn must start past {} m of depth and leave {} m of feed after it ends plus {} m (turn_depth {} m, the turn ends at {turned} m, depth {} m)",
            SCORE_FROM_DEPTH + 2.0 * INFLECTION_HALF_WINDOW,
            2.0 * INFLECTION_HALF_WINDOW,
            TURN_SETTLE,
            p.turn_depth,
            p.depth
        )));
    }
    let t2 = (p.tip_gap + second) / v;
    s.run(id, inputs, Some((t0, t1)), vec![[0.0, t0], [t2, t_end]], Some(t0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the arc of radius `r` through the origin, tangent to +x,
    /// bending towards `side` (+1 or -1), for x in [0, len].
    fn arc(r: f64, side: f64, len: f64, n: usize) -> PlanePath {
        (0..n)
            .map(|i| {
                let x = len * i as f64 / (n - 1) as f64;
                (x, side * (r - (r * r - x * x).sqrt()))
            })
            .collect()
    }

    #[test]
    fn the_fit_recovers_an_exact_arc_and_its_side() {
        for side in [1.0, -1.0] {
            let (k, rms, circle) = fit_arc(&arc(0.05, side, 0.012, 200)).unwrap();
            // Exact data: the algebraic fit is exact to rounding.
            assert!((k - side / 0.05).abs() < 1e-9, "{k}");
            assert!(rms < 1e-12, "{rms}");
            // The circle: centre (0, side r), radius r; it gives back each
            // point's s on the branch through the points.
            let [xc, sc, r] = circle.expect("an arc, not a line");
            assert!(xc.abs() < 1e-12 && (sc - side * 0.05).abs() < 1e-12 && (r - 0.05).abs() < 1e-12);
            for (x, s) in arc(0.05, side, 0.012, 7) {
                assert!((circle_at([xc, sc, r], x, s) - s).abs() < 1e-12, "{x}");
            }
        }
        // Beyond the circle's reach: no offset.
        assert!(circle_at([0.0, 0.05, 0.05], 0.06, 0.0).is_nan());
    }

    #[test]
    fn a_straight_path_has_zero_curvature() {
        let line: PlanePath = (0..50).map(|i| (i as f64 * 1e-4, 0.1 * i as f64 * 1e-4)).collect();
        let (k, rms, circle) = fit_arc(&line).unwrap();
        // The normal equations are singular to rounding: the line's fit.
        assert!(circle.is_none(), "{circle:?}");
        assert!(k.abs() < 1e-6, "{k}");
        assert!(rms < 1e-15, "{rms}");
    }

    #[test]
    fn the_local_curvature_and_the_inflection_of_an_s_curve() {
        // Two arcs of radius 50 mm meeting tangentially at x = 6 mm (an
        // inflection point there): bend towards +s, then towards -s.
        let r: f64 = 0.05;
        let x0: f64 = 0.006;
        let s0 = r - (r * r - x0 * x0).sqrt();
        let slope = x0 / (r * r - x0 * x0).sqrt();
        // The second arc: centre a radius from the join on the -s side of
        // the tangent (1, slope), along the normal (slope, -1).
        let norm = slope.hypot(1.0);
        let (ccx, ccs) = (x0 + r * slope / norm, s0 - r / norm);
        let path: PlanePath = (0..=1200)
            .map(|i| {
                let x = 0.012 * i as f64 / 1200.0;
                if x <= x0 {
                    (x, r - (r * r - x * x).sqrt())
                } else {
                    (x, ccs + (r * r - (x - ccx).powi(2)).sqrt())
                }
            })
            .collect();
        let k = local_curvature(&path, 0.003, INFLECTION_HALF_WINDOW).unwrap();
        // A parabola through a 2 mm piece of a 50 mm arc: its curvature to
        // O((half / r)^2) = 4e-4 relative.
        assert!((k * r - 1.0).abs() < 1e-3, "{k}");
        let x = inflection(&path, 0.002, 0.011, 1.0).unwrap();
        // The window straddles the join symmetrically at x0: the sign change
        // is located to a fraction of the grid (0.25 mm).
        assert!((x - x0).abs() < 0.1e-3, "{x}");
        let second: PlanePath = path.iter().copied().filter(|p| p.0 >= 0.007).collect();
        let (k2, _, _) = fit_arc(&second).unwrap();
        assert!((k2 * r + 1.0).abs() < 1e-6, "{k2}");
    }
}
