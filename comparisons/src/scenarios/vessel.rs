//! Vascular navigation scenarios: a guidewire pushed, pulled and rotated
//! through procedural vessels ([`surgbench_core::vessel`]). SI units.
//!
//! Conventions (shared with the rod scenarios): the rod's base clamp
//! ([`RodBody::base`]) sits on the vessel centreline 5 mm after the vessel's
//! start, the wire leaving along the base's local +x, down the lumen; the
//! operator feeds it with [`ControlTimeline`] keys `insertion` (m,
//! cumulative) and `rotation` (rad, cumulative, about the base tangent).
//! Contact margin = wire radius (the SDF acts on the wire's centreline).
//! The default guidewire is 0.89 mm (0.035") in diameter with a stiff body
//! (nitinol-like, E = 50 GPa) and a soft 3 cm tip (E = 1 GPa) as two
//! [`RodSection`]s.
//!
//! **Trajectory metrics.** The harness scores observations one at a time
//! ([`ScenarioRun::score`]). Metrics over a whole run (time to reach a
//! target, maximum penetration, mean and peak hand force, tension averaged
//! over a pulling window) are accumulated by each run from every
//! observation it is shown, in time order: an observation earlier than the
//! last one seen starts a new trajectory. Their resolution is therefore the
//! harness's sampling of the run (about 400 samples per run today).
//!
//! Scenarios: `arch-insertion`, `branch-selection`, `flow-drift`,
//! `capstan`, `stick-slip-threshold`, `coronary-tortuous`, `coronary-beating`.

use crate::scenario::{ParamSpec, Params, Range, Scenario, ScenarioRun, UsageError, sweep_of};
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use surgbench_core::flow::PoiseuilleFlow;
use surgbench_core::haptic::Session;
use surgbench_core::motion::{CardiacMotion, VesselMotion};
use surgbench_core::sdf::{CenterlineBuilder, Sdf, StraightTube, SweptTube};
use surgbench_core::vessel::{self, Vessel};
use surgbench_core::{
    ContactParams, ControlKey, ControlTimeline, Family, Fidelity, Iso3, LoadRamp, Observation, RodBody, RodSection,
    Scene, Settle, Vec3,
};

/// Every vessel scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &ArchInsertion::DEFAULT,
        &BranchSelection,
        &FlowDrift::DEFAULT,
        &Capstan,
        &StickSlipThreshold,
        &CoronaryTortuous,
        &CoronaryBeating,
    ]
}

const fn p(name: &'static str, default: f64, unit: &'static str, range: Range, doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        default,
        unit,
        range,
        doc,
    }
}

/// Guidewire radius: 0.89 mm (0.035 inch) diameter.
pub const WIRE_RADIUS: f64 = 0.445e-3;
/// Arclength of the base clamp from the vessel's start (m).
pub const ENTRY_S: f64 = 5e-3;

const P_WIRE_RADIUS: ParamSpec = p(
    "wire_radius",
    WIRE_RADIUS,
    "m",
    Range::Positive,
    "guidewire radius (0.89 mm diameter)",
);
const P_BODY_E: ParamSpec = p(
    "body_youngs_modulus",
    5e10,
    "Pa",
    Range::Positive,
    "Young's modulus of the wire body (nitinol-like)",
);
const P_TIP_E: ParamSpec = p(
    "tip_youngs_modulus",
    1e9,
    "Pa",
    Range::Positive,
    "Young's modulus of the soft tip",
);
const P_TIP_LEN: ParamSpec = p(
    "tip_length",
    0.03,
    "m",
    Range::Positive,
    "length of the soft tip section",
);
const P_DENSITY: ParamSpec = p("density", 6450.0, "kg/m^3", Range::Positive, "wire density");
const P_POISSON: ParamSpec = p("poisson_ratio", 0.3, "1", Range::Open(-1.0, 0.5), "Poisson ratio");
const P_MU_S: ParamSpec = p(
    "friction_static",
    0.1,
    "1",
    Range::NonNegative,
    "static friction coefficient wire-wall",
);
const P_MU_D: ParamSpec = p(
    "friction_dynamic",
    0.08,
    "1",
    Range::NonNegative,
    "dynamic friction coefficient (<= static)",
);
const P_GRAVITY: ParamSpec = p(
    "gravity",
    0.0,
    "m/s^2",
    Range::NonNegative,
    "gravity along -z (0: neglected)",
);

/// Guidewire material and geometry resolved from parameters.
#[derive(Debug, Clone, Copy)]
struct Wire {
    radius: f64,
    body_e: f64,
    tip_e: f64,
    tip_len: f64,
    rho: f64,
    nu: f64,
}

impl Wire {
    fn from(p: &Params) -> Self {
        Self {
            radius: p.get("wire_radius"),
            body_e: p.get("body_youngs_modulus"),
            tip_e: p.get("tip_youngs_modulus"),
            tip_len: p.get("tip_length"),
            rho: p.get("density"),
            nu: p.get("poisson_ratio"),
        }
    }
    fn section(&self, until: f64, e: f64, curvature: [f64; 2]) -> RodSection {
        RodSection {
            until,
            radius: self.radius,
            youngs_modulus: e,
            poisson_ratio: self.nu,
            density: self.rho,
            rest_curvature: curvature,
        }
    }
    /// Body + soft tip, `length` m free, clamped at `base`.
    fn rod(&self, length: f64, base: Iso3) -> Result<RodBody, UsageError> {
        if !(length > self.tip_len) {
            return Err(UsageError(format!(
                "initial free length {length} m must exceed tip_length {} m (the body section must exist)",
                self.tip_len
            )));
        }
        Ok(RodBody {
            length,
            sections: vec![
                self.section(length - self.tip_len, self.body_e, [0.0; 2]),
                self.section(length, self.tip_e, [0.0; 2]),
            ],
            base,
            tip_force: Vec3::zeros(),
            tip_torque: Vec3::zeros(),
            tip_load_ramp: None,
        })
    }
    /// [`Wire::rod`] with the last `j_len` m of the soft tip pre-curved to
    /// `kappa` (1/m) towards the clamp's local y (a J or angled tip);
    /// `kappa = 0` leaves the tip straight.
    fn rod_with_j(&self, length: f64, base: Iso3, j_len: f64, kappa: f64) -> Result<RodBody, UsageError> {
        let mut rod = self.rod(length, base)?;
        if kappa == 0.0 {
            return Ok(rod);
        }
        if !(j_len > 0.0 && j_len < self.tip_len) {
            return Err(UsageError(format!(
                "j_length {j_len} m must be in (0, tip_length = {} m)",
                self.tip_len
            )));
        }
        let tip = rod.sections.pop().expect("two sections");
        rod.sections
            .push(self.section(length - j_len, tip.youngs_modulus, [0.0; 2]));
        // Darboux component on d2 turns the tangent towards +d1 (local y).
        rod.sections
            .push(self.section(length, tip.youngs_modulus, [0.0, kappa]));
        Ok(rod)
    }
    fn body_ei(&self) -> f64 {
        self.body_e * PI * self.radius.powi(4) / 4.0
    }
}

fn contact(p: &Params, margin: f64) -> Result<ContactParams, UsageError> {
    let c = ContactParams {
        friction_static: p.get("friction_static"),
        friction_dynamic: p.get("friction_dynamic"),
        margin,
    };
    if c.friction_dynamic > c.friction_static {
        return Err(UsageError(format!(
            "friction_dynamic {} must not exceed friction_static {}",
            c.friction_dynamic, c.friction_static
        )));
    }
    Ok(c)
}

/// Insertion moves the clamp along its straight tangent: it must stay in
/// the straight segment (length `straight`, m) it starts in, or the scene
/// would drive it through the wall. `reach` = clamp start + deepest feed (m).
fn clamp_stays_in_straight(reach: f64, straight: f64, what: &str) -> Result<(), UsageError> {
    if reach > straight {
        return Err(UsageError(format!(
            "the clamp would be fed {reach:.3} m along the {straight:.3} m {what}: past its end, into the wall (shorten the push)"
        )));
    }
    Ok(())
}

fn check_lumen(wire_radius: f64, lumen: f64, what: &str) -> Result<(), UsageError> {
    if !(wire_radius < 0.9 * lumen) {
        return Err(UsageError(format!(
            "wire_radius {wire_radius} m does not fit the {what} lumen of radius {lumen} m (needs < 90%)"
        )));
    }
    Ok(())
}

/// Where the scenario reference data live: `$SURGBENCH_DATASETS` or the
/// repository's `datasets/`.
pub fn datasets_dir() -> PathBuf {
    std::env::var_os("SURGBENCH_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../datasets")))
}

/// A cached reference trajectory `t,x,y,z` (s, m).
#[derive(Debug, Clone, PartialEq)]
pub struct TipTrajectory {
    /// Samples `(t, tip)` in increasing time.
    pub samples: Vec<(f64, Vec3)>,
}

impl TipTrajectory {
    /// Parse CSV with a header naming `t,x,y,z`; errors name the line.
    pub fn parse(file: &str, text: &str) -> Result<Self, UsageError> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let (_, header) = lines
            .next()
            .ok_or_else(|| UsageError(format!("{file}: empty reference")))?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let col = |n: &str| {
            names
                .iter()
                .position(|x| *x == n)
                .ok_or_else(|| UsageError(format!("{file}: header has no `{n}` column")))
        };
        let cols = [col("t")?, col("x")?, col("y")?, col("z")?];
        let mut samples: Vec<(f64, Vec3)> = Vec::new();
        for (i, l) in lines {
            let cells: Vec<&str> = l.split(',').map(str::trim).collect();
            let mut v = [0.0; 4];
            for (k, &c) in cols.iter().enumerate() {
                v[k] = cells
                    .get(c)
                    .and_then(|s| s.parse::<f64>().ok())
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        UsageError(format!(
                            "{file}: line {}, column `{}`: not a finite number",
                            i + 1,
                            names[c]
                        ))
                    })?;
            }
            if samples.last().is_some_and(|s| !(v[0] > s.0)) {
                return Err(UsageError(format!("{file}: line {}: time does not increase", i + 1)));
            }
            samples.push((v[0], Vec3::new(v[1], v[2], v[3])));
        }
        if samples.is_empty() {
            return Err(UsageError(format!("{file}: no samples")));
        }
        Ok(Self { samples })
    }

    /// Tip at time `t` by linear interpolation (nearest sample outside).
    pub fn at(&self, t: f64) -> Vec3 {
        let s = &self.samples;
        if t <= s[0].0 {
            return s[0].1;
        }
        if t >= s[s.len() - 1].0 {
            return s[s.len() - 1].1;
        }
        let i = s.partition_point(|x| x.0 <= t) - 1;
        let w = (t - s[i].0) / (s[i + 1].0 - s[i].0);
        s[i].1 + (s[i + 1].1 - s[i].1) * w
    }
}

/// Load `<datasets>/reference/<scenario>/tip_trajectory.csv` when present
/// and the parameters are the defaults it was computed for; `datasets`
/// defaults to [`datasets_dir`].
fn cached_reference(scenario: &str, p: &Params, datasets: Option<&str>) -> Result<Option<TipTrajectory>, UsageError> {
    if !p.overrides_string().is_empty() {
        return Ok(None);
    }
    let dir = datasets.map(PathBuf::from).unwrap_or_else(datasets_dir);
    let path = dir.join("reference").join(scenario).join("tip_trajectory.csv");
    match std::fs::read_to_string(&path) {
        Ok(text) => TipTrajectory::parse(&path.display().to_string(), &text).map(Some),
        Err(_) => Ok(None),
    }
}

// ---------------------------------------------------------------------------
// Trajectory accumulation.
// ---------------------------------------------------------------------------

/// Per-run statistics accumulated over the observations shown to `score`.
#[derive(Debug, Clone, Default)]
struct Track {
    last_t: Option<f64>,
    samples: usize,
    max_penetration: f64,
    max_reported_penetration: f64,
    force_sum: f64,
    force_max: f64,
    torque_max: f64,
    max_contacts: usize,
    reached_at: Option<f64>,
    ref_err2: f64,
    ref_err_max: f64,
    // Scenario-specific sums.
    window_sum: f64,
    window_n: usize,
    tail_sum: f64,
    tail_n: usize,
    anchor: Option<Vec3>,
    slip_at: Option<(f64, f64)>,
    stick_force_max: f64,
    creep_max: f64,
    loaded: bool,
}

/// Lock the tracker and update it with `obs` unless this time was already
/// seen; a time earlier than the last one seen starts a new trajectory.
fn track<'a>(
    m: &'a Mutex<Track>,
    obs: &Observation,
    update: impl FnOnce(&mut Track),
) -> std::sync::MutexGuard<'a, Track> {
    let mut g = m.lock().unwrap_or_else(|e| e.into_inner());
    match g.last_t {
        Some(t) if obs.time < t => {
            *g = Track::default();
        }
        Some(t) if obs.time == t => return g,
        _ => {}
    }
    g.last_t = Some(obs.time);
    g.samples += 1;
    update(&mut g);
    g
}

/// Largest depth of the wire's surface past the wall: `max(phi(x) + r, 0)`
/// over every node of every rod (m), from the geometry, not from the
/// model's own contact report.
fn wall_penetration(sdf: &dyn Sdf, obs: &Observation, wire_radius: f64) -> f64 {
    obs.rods
        .iter()
        .flat_map(|r| r.arclength.iter().zip(&r.nodes))
        .filter(|(s, _)| **s >= 0.0)
        .map(|(_, x)| (sdf.distance(x) + wire_radius).max(0.0))
        .fold(0.0, f64::max)
}

/// Common metrics: penetration (geometric and reported), hand force and
/// torque, contacts, stretch.
fn common(t: &mut Track, sdf: &dyn Sdf, obs: &Observation, r: f64) {
    t.max_penetration = t.max_penetration.max(wall_penetration(sdf, obs, r));
    t.max_reported_penetration = t.max_reported_penetration.max(obs.max_penetration());
    let f = obs.hand_force.norm();
    t.force_sum += f;
    t.force_max = t.force_max.max(f);
    t.torque_max = t.torque_max.max(obs.hand_torque.norm());
    t.max_contacts = t.max_contacts.max(obs.contacts.len());
}

fn common_metrics(m: &mut BTreeMap<String, f64>, t: &Track, obs: &Observation) {
    m.insert("max_penetration_m".into(), t.max_penetration);
    m.insert("reported_penetration_m".into(), t.max_reported_penetration);
    m.insert("hand_force_mean_n".into(), t.force_sum / t.samples.max(1) as f64);
    m.insert("hand_force_max_n".into(), t.force_max);
    m.insert("hand_torque_max_nm".into(), t.torque_max);
    m.insert("contacts_max".into(), t.max_contacts as f64);
    if let Some(r) = obs.rods.first() {
        m.insert("max_stretch".into(), r.max_stretch.abs());
    }
}

fn tip(obs: &Observation) -> Option<Vec3> {
    obs.rods.first().filter(|r| !r.nodes.is_empty()).map(|r| r.tip())
}

/// Timeline from `(t, insertion, rotation)` triples.
fn timeline(keys: &[(f64, f64, f64)]) -> ControlTimeline {
    ControlTimeline {
        keys: keys
            .iter()
            .map(|&(t, insertion, rotation)| ControlKey { t, insertion, rotation })
            .collect(),
    }
}

// ---------------------------------------------------------------------------
// arch-insertion
// ---------------------------------------------------------------------------

/// Push a guidewire up the descending aorta, over the arch and down the
/// ascending aorta at constant speed with intermittent quarter turns.
pub struct ArchInsertion {
    /// Datasets folder holding `reference/arch-insertion/tip_trajectory.csv`
    /// (`None`: [`datasets_dir`]).
    pub datasets: Option<&'static str>,
}

impl ArchInsertion {
    /// The registered instance (reference from [`datasets_dir`]).
    pub const DEFAULT: Self = Self { datasets: None };
}

/// Default J length (m) of the arch wire: half a turn of the 3 mm J common
/// on 0.035-inch access guidewires (`j_curvature = 333 1/m`); the default
/// tip is straight (`j_curvature = 0`), as the scene is specified.
const ARCH_J_LENGTH: f64 = PI * 3e-3;

const ARCH_PARAMS: &[ParamSpec] = &[
    P_WIRE_RADIUS,
    P_BODY_E,
    P_TIP_E,
    P_TIP_LEN,
    P_DENSITY,
    P_POISSON,
    P_MU_S,
    P_MU_D,
    P_GRAVITY,
    p("insertion_speed", 0.02, "m/s", Range::Positive, "constant feed speed"),
    p(
        "j_curvature",
        0.0,
        "1/m",
        Range::NonNegative,
        "rest curvature of the tip's J (towards the clamp's local y; 0: straight tip)",
    ),
    p(
        "j_length",
        ARCH_J_LENGTH,
        "m",
        Range::Positive,
        "length of the curved J at the tip (within the soft tip)",
    ),
    p(
        "initial_length",
        0.2,
        "m",
        Range::Positive,
        "free wire length at t = 0: the tip starts 5 mm short of the arch (the clamp needs the 150 mm of straight below it for the push)",
    ),
    p(
        "rotation_step",
        PI / 2.0,
        "rad",
        Range::Any,
        "size of each intermittent rotation (alternating sign)",
    ),
    p(
        "rotation_interval",
        1.0,
        "s",
        Range::Positive,
        "time between rotation starts",
    ),
    p("rotation_time", 0.2, "s", Range::Positive, "duration of each rotation"),
    p(
        "target_depth",
        0.01,
        "m",
        Range::NonNegative,
        "target plane: this far into the ascending aorta",
    ),
    p("duration", 7.5, "s", Range::Positive, "simulated time"),
];

struct ArchRun {
    scene: Scene,
    vessel: Arc<Vessel>,
    wire_radius: f64,
    target_s: f64,
    reference: Option<TipTrajectory>,
    energy: f64,
    track: Mutex<Track>,
}

/// Insertion ramp with alternating rotations every `interval` seconds.
fn push_with_rotations(speed: f64, duration: f64, step: f64, interval: f64, rot_time: f64) -> ControlTimeline {
    let mut keys = vec![(0.0, 0.0, 0.0)];
    let mut rot = 0.0;
    let mut k = 1;
    loop {
        let t0 = k as f64 * interval;
        let t1 = t0 + rot_time.min(0.9 * interval);
        if t1 >= duration {
            break;
        }
        keys.push((t0, speed * t0, rot));
        rot += if k % 2 == 1 { step } else { -step };
        keys.push((t1, speed * t1, rot));
        k += 1;
    }
    keys.push((duration, speed * duration, rot));
    timeline(&keys)
}

impl ScenarioRun for ArchRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(tip) = tip(obs) else { return m };
        let (lumen, _) = self.vessel.deepest(&tip);
        let proj = self.vessel.trunk.project(&tip);
        let past = lumen.is_none() && proj.s >= self.target_s;
        let ref_err = self.reference.as_ref().map(|r| (tip - r.at(obs.time)).norm());
        let t = track(&self.track, obs, |t| {
            common(t, self.vessel.as_ref(), obs, self.wire_radius);
            if past && t.reached_at.is_none() {
                t.reached_at = Some(obs.time);
            }
            if let Some(e) = ref_err {
                t.ref_err2 += e * e;
                t.ref_err_max = t.ref_err_max.max(e);
            }
        });
        common_metrics(&mut m, &t, obs);
        m.insert("tip_progress_m".into(), proj.s);
        m.insert("reached".into(), t.reached_at.is_some() as u8 as f64);
        if let Some(r) = t.reached_at {
            m.insert("time_to_reach_s".into(), r);
        }
        m.insert("reference_available".into(), self.reference.is_some() as u8 as f64);
        if let Some(e) = ref_err {
            m.insert("tip_error_m".into(), e);
            m.insert("tip_error_rms_m".into(), (t.ref_err2 / t.samples.max(1) as f64).sqrt());
            m.insert("tip_error_max_m".into(), t.ref_err_max);
        }
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.25
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

impl Scenario for ArchInsertion {
    fn id(&self) -> &'static str {
        "arch-insertion"
    }
    fn description(&self) -> &'static str {
        "guidewire pushed over an aortic arch (25 mm lumen, 35 mm arch radius) with intermittent rotation"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        ARCH_PARAMS
    }
    fn reference(&self) -> &'static str {
        "converged DER tip trajectory cached in datasets/reference/arch-insertion/tip_trajectory.csv (default parameters only); without it only reach, time-to-reach, penetration and hand force are scored"
    }
    fn primary_error(&self) -> &'static str {
        "tip_error_m"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[25.0, 50.0, 100.0, 200.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let wire = Wire::from(p);
        check_lumen(wire.radius, vessel::AORTA_RADIUS, "aortic")?;
        let l0 = p.get("initial_length");
        if l0 + ENTRY_S > vessel::ARCH_DESCENDING {
            return Err(UsageError(format!(
                "initial_length {l0} m does not fit the {} m descending segment after the {ENTRY_S} m entry",
                vessel::ARCH_DESCENDING
            )));
        }
        let feed = p.get("insertion_speed") * p.get("duration");
        clamp_stays_in_straight(ENTRY_S + feed, vessel::ARCH_DESCENDING, "descending aorta")?;
        let arch = Arc::new(vessel::aortic_arch());
        let mut scene = Scene::empty(self.id());
        scene.duration = p.get("duration");
        scene.gravity = Vec3::new(0.0, 0.0, -p.get("gravity"));
        let (jl, kappa) = (p.get("j_length"), p.get("j_curvature"));
        scene
            .bodies
            .push(wire.rod_with_j(l0, arch.trunk.frame_at(ENTRY_S), jl, kappa)?.into());
        scene.environment.vessel = Some(arch.clone());
        scene.environment.contact = contact(p, wire.radius)?;
        scene.control = push_with_rotations(
            p.get("insertion_speed"),
            scene.duration,
            p.get("rotation_step"),
            p.get("rotation_interval"),
            p.get("rotation_time"),
        );
        scene.validate().map_err(UsageError)?;
        let total = l0 + p.get("insertion_speed") * scene.duration;
        Ok(Box::new(ArchRun {
            scene,
            target_s: vessel::ARCH_DESCENDING + PI * vessel::ARCH_RADIUS + p.get("target_depth"),
            wire_radius: wire.radius,
            reference: cached_reference(self.id(), p, self.datasets)?,
            // Bending the whole wire to the arch radius.
            energy: wire.body_ei() * total / (vessel::ARCH_RADIUS * vessel::ARCH_RADIUS),
            vessel: arch,
            track: Mutex::new(Track::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// branch-selection
// ---------------------------------------------------------------------------

/// Select a branch of a Y bifurcation by rotating a pre-shaped J tip, as
/// replayed from a recorded session.
pub struct BranchSelection;

const SESSION_45: &str = include_str!("../../../datasets/vessels/branch-selection-45.csv");
const SESSION_70: &str = include_str!("../../../datasets/vessels/branch-selection-70.csv");

const BRANCH_PARAMS: &[ParamSpec] = &[
    P_WIRE_RADIUS,
    P_BODY_E,
    P_TIP_E,
    P_TIP_LEN,
    P_DENSITY,
    P_POISSON,
    P_MU_S,
    P_MU_D,
    p(
        "target",
        0.0,
        "1",
        Range::Closed(0.0, 1.0),
        "0: branch-45 (+y), 1: branch-70 (-y); picks the recorded session",
    ),
    p(
        "j_curvature",
        100.0,
        "1/m",
        Range::Positive,
        "rest curvature of the J (towards the clamp's local y)",
    ),
    p(
        "j_length",
        0.005,
        "m",
        Range::Positive,
        "length of the curved J at the tip (within the soft tip)",
    ),
    p(
        "initial_length",
        0.032,
        "m",
        Range::Positive,
        "free wire length at t = 0",
    ),
    p(
        "target_depth",
        0.005,
        "m",
        Range::Positive,
        "success: tip this far along the target branch",
    ),
    p(
        "duration",
        5.0,
        "s",
        Range::Positive,
        "simulated time (the sessions last 4.5 s)",
    ),
];

struct BranchRun {
    scene: Scene,
    vessel: Arc<Vessel>,
    target: usize,
    depth: f64,
    wire_radius: f64,
    rotations: usize,
    energy: f64,
    track: Mutex<Track>,
}

impl ScenarioRun for BranchRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(tip) = tip(obs) else { return m };
        let (lumen, phi) = self.vessel.deepest(&tip);
        let along = self.vessel.branches[self.target].tube.project(&tip).s;
        let inside = lumen == Some(self.target) && phi < 0.0 && along >= self.depth;
        let t = track(&self.track, obs, |t| {
            common(t, self.vessel.as_ref(), obs, self.wire_radius);
            if inside && t.reached_at.is_none() {
                t.reached_at = Some(obs.time);
            }
        });
        common_metrics(&mut m, &t, obs);
        m.insert("target_missed".into(), if inside { 0.0 } else { 1.0 });
        m.insert("success".into(), inside as u8 as f64);
        if let Some(r) = t.reached_at {
            m.insert("time_to_target_s".into(), r);
        }
        m.insert("rotation_commands".into(), self.rotations as f64);
        m.insert("tip_along_target_m".into(), along);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.1
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

impl Scenario for BranchSelection {
    fn id(&self) -> &'static str {
        "branch-selection"
    }
    fn description(&self) -> &'static str {
        "J-tip guidewire steered into the 45 or 70 degree branch of a Y bifurcation by a recorded session"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        BRANCH_PARAMS
    }
    fn reference(&self) -> &'static str {
        "success: tip inside the target branch past target_depth; recorded sessions datasets/vessels/branch-selection-{45,70}.csv"
    }
    fn primary_error(&self) -> &'static str {
        "target_missed"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let wire = Wire::from(p);
        check_lumen(wire.radius, vessel::Y_BRANCH_RADIUS, "branch")?;
        let target = p.get("target");
        if target.fract() != 0.0 {
            return Err(UsageError(format!("target must be 0 or 1, got {target}")));
        }
        let target = target as usize;
        let (name, text) = if target == 0 {
            ("datasets/vessels/branch-selection-45.csv", SESSION_45)
        } else {
            ("datasets/vessels/branch-selection-70.csv", SESSION_70)
        };
        let session = Session::parse(name, text).map_err(|e| UsageError(e.to_string()))?;
        let (l0, jl, kappa) = (p.get("initial_length"), p.get("j_length"), p.get("j_curvature"));
        if l0 + ENTRY_S > vessel::Y_TRUNK {
            return Err(UsageError(format!(
                "initial_length {l0} m does not fit the {} m trunk",
                vessel::Y_TRUNK
            )));
        }
        // Lateral offset of the J's end from the axis: (1 - cos(kappa j)) / kappa.
        let offset = (1.0 - (kappa * jl).min(PI).cos()) / kappa;
        if offset + wire.radius > vessel::Y_TRUNK_RADIUS {
            return Err(UsageError(format!(
                "the J (curvature {kappa} 1/m over {jl} m) sticks out {offset:.2e} m from the axis: the wire would start in the wall"
            )));
        }
        let y = Arc::new(vessel::y_bifurcation());
        // Clamp on the trunk axis, its local y (where the J bends) turned to +z.
        let base = y.trunk.frame_at(ENTRY_S) * Iso3::rotation(Vec3::x() * (PI / 2.0));
        let rod = wire.rod_with_j(l0, base, jl, kappa)?;
        let mut scene = Scene::empty(self.id());
        scene.duration = p.get("duration");
        scene.bodies.push(rod.into());
        scene.environment.vessel = Some(y.clone());
        scene.environment.contact = contact(p, wire.radius)?;
        scene.control = session.timeline.clone();
        scene.validate().map_err(UsageError)?;
        Ok(Box::new(BranchRun {
            scene,
            vessel: y,
            target,
            depth: p.get("target_depth"),
            wire_radius: wire.radius,
            rotations: session.rotation_commands(),
            // The whole wire bent at a 10 mm radius into a branch.
            energy: wire.body_ei() * (l0 + session.timeline.keys.iter().map(|k| k.insertion).fold(0.0, f64::max))
                / 1e-4,
            track: Mutex::new(Track::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// flow-drift
// ---------------------------------------------------------------------------

/// A short soft wire tip in Poiseuille flow, clamped on the tube axis and
/// tilted upstream: the flow swings it downstream towards the wall (130 um
/// from the tip), where friction would stop it. Whether it gets there
/// depends on the model's flow law: DER's quadratic drag (Re ~ 135 here)
/// deflects the default 2.8 mm, 1 MPa tip by ~10 um (DER's reference
/// trajectory says so); the chain-mail rule moves elements with the blood.
pub struct FlowDrift {
    /// Datasets folder holding `reference/flow-drift/tip_trajectory.csv`
    /// (`None`: [`datasets_dir`]).
    pub datasets: Option<&'static str>,
}

impl FlowDrift {
    /// The registered instance (reference from [`datasets_dir`]).
    pub const DEFAULT: Self = Self { datasets: None };
}

const FLOW_PARAMS: &[ParamSpec] = &[
    P_WIRE_RADIUS,
    p(
        "youngs_modulus",
        1e6,
        "Pa",
        Range::Positive,
        "Young's modulus of the (very soft) tip",
    ),
    P_DENSITY,
    P_POISSON,
    p(
        "friction_static",
        0.3,
        "1",
        Range::NonNegative,
        "static friction coefficient",
    ),
    p(
        "friction_dynamic",
        0.25,
        "1",
        Range::NonNegative,
        "dynamic friction coefficient (<= static)",
    ),
    p(
        "tube_radius",
        3e-3,
        "m",
        Range::Positive,
        "lumen radius of the straight tube (axis along +x)",
    ),
    p(
        "flow_speed",
        0.5,
        "m/s",
        Range::Positive,
        "centreline speed v_max of the Poiseuille profile (along +x)",
    ),
    p(
        "free_length",
        2.8e-3,
        "m",
        Range::Positive,
        "free length of the clamped tip",
    ),
    p(
        "angle",
        2.0 * PI / 3.0,
        "rad",
        Range::Open(0.0, PI),
        "angle of the clamp from the flow direction (> pi/2: upstream)",
    ),
    p(
        "settle_tol",
        1e-4,
        "m/s",
        Range::Positive,
        "equilibrium when every node is slower than this",
    ),
    p("duration", 2.0, "s", Range::Positive, "longest simulated time"),
];

struct FlowRun {
    scene: Scene,
    tube: StraightTube,
    tip0: Vec3,
    wire_radius: f64,
    reference: Option<TipTrajectory>,
    energy: f64,
    track: Mutex<Track>,
}

impl ScenarioRun for FlowRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(tip) = tip(obs) else { return m };
        let t = track(&self.track, obs, |t| common(t, &self.tube, obs, self.wire_radius));
        common_metrics(&mut m, &t, obs);
        m.insert("tip_drift_m".into(), tip.x - self.tip0.x);
        m.insert("tip_wall_gap_m".into(), -self.tube.distance(&tip) - self.wire_radius);
        m.insert("reference_available".into(), self.reference.is_some() as u8 as f64);
        if let Some(r) = &self.reference {
            m.insert("tip_error_m".into(), (tip - r.at(obs.time)).norm());
        }
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.02
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

impl Scenario for FlowDrift {
    fn id(&self) -> &'static str {
        "flow-drift"
    }
    fn description(&self) -> &'static str {
        "soft wire tip tilted upstream in Poiseuille flow: how far the flow swings it towards the wall (130 um away); a drag law at Re ~ 135 moves it ~10 um, a displacement rule may carry it onto the wall, where friction holds it"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        FLOW_PARAMS
    }
    fn reference(&self) -> &'static str {
        "converged DER tip trajectory cached in datasets/reference/flow-drift/tip_trajectory.csv (default parameters only; the drag law is each model's own); otherwise drift, wall gap and penetration only"
    }
    fn primary_error(&self) -> &'static str {
        "tip_error_m"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[5.0, 10.0, 20.0, 40.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let r = p.get("wire_radius");
        let big_r = p.get("tube_radius");
        check_lumen(r, big_r, "tube")?;
        let (l, a) = (p.get("free_length"), p.get("angle"));
        let dir = Vec3::new(a.cos(), a.sin(), 0.0);
        let tip0 = dir * l;
        if tip0.y + r >= big_r {
            return Err(UsageError(format!(
                "the straight tip reaches {:.3e} m from the axis: it would start in the {big_r} m tube's wall",
                tip0.y + r
            )));
        }
        let e = p.get("youngs_modulus");
        let mut rod = RodBody::uniform(l, r, e, p.get("poisson_ratio"), p.get("density"));
        rod.base = Iso3::rotation(Vec3::z() * a);
        let tube = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: big_r,
        };
        let v = p.get("flow_speed");
        let mut scene = Scene::empty(self.id());
        scene.duration = p.get("duration");
        scene.settle = Some(Settle {
            velocity_tol: p.get("settle_tol"),
            min_time: 0.05,
        });
        scene.bodies.push(rod.into());
        scene.environment.vessel = Some(Arc::new(tube));
        scene.environment.flow = Some(Arc::new(PoiseuilleFlow {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: big_r,
            v_max: v,
        }));
        scene.environment.contact = contact(p, r)?;
        scene.validate().map_err(UsageError)?;
        // Dynamic pressure times the wire's projected area, over the length.
        let drag = 0.5 * 1060.0 * v * v * 2.0 * r * l;
        Ok(Box::new(FlowRun {
            scene,
            tube,
            tip0,
            wire_radius: r,
            reference: cached_reference(self.id(), p, self.datasets)?,
            energy: (drag * l).max(e * PI * r.powi(4) / 4.0 / l),
            track: Mutex::new(Track::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// capstan
// ---------------------------------------------------------------------------

/// A flexible wire pulled back through a curved tube against a dead tip
/// force: the capstan (Euler-Eytelwein) law `T_out / T_in = exp(mu theta)`.
pub struct Capstan;

const CAPSTAN_PARAMS: &[ParamSpec] = &[
    P_WIRE_RADIUS,
    p(
        "youngs_modulus",
        2e8,
        "Pa",
        Range::Positive,
        "wire Young's modulus (soft: bending negligible against tension)",
    ),
    P_DENSITY,
    P_POISSON,
    p(
        "friction",
        0.3,
        "1",
        Range::NonNegative,
        "friction coefficient mu (static = dynamic)",
    ),
    p(
        "wrap_angle",
        PI / 2.0,
        "rad",
        Range::Closed(0.05, PI),
        "angle theta the tube turns by",
    ),
    p(
        "tip_force",
        1.0,
        "N",
        Range::Positive,
        "dead force on the tip along the exit direction once threaded: far-end tension T_in",
    ),
    p(
        "bend_radius",
        15e-3,
        "m",
        Range::Positive,
        "centreline radius of the bend",
    ),
    p(
        "tube_radius",
        0.7e-3,
        "m",
        Range::Positive,
        "lumen radius (tight, so the wire cannot buckle)",
    ),
    p(
        "insert_speed",
        0.02,
        "m/s",
        Range::Positive,
        "feed speed while threading the wire through the bend",
    ),
    p(
        "pull_speed",
        0.01,
        "m/s",
        Range::Positive,
        "retraction speed while measuring",
    ),
    p("pull_length", 0.01, "m", Range::Positive, "length pulled back"),
];

const CAPSTAN_EXIT: f64 = 40e-3;
/// Straight before the bend beyond what the feed needs (m).
const CAPSTAN_SLACK: f64 = 10e-3;
/// How far the tip is threaded past the bend (m).
const CAPSTAN_THREAD: f64 = 15e-3;
/// Time over which the tip tension rises once the wire is threaded (s).
const CAPSTAN_RAMP: f64 = 0.1;
/// Rest at full tension before the pull (s).
const CAPSTAN_DWELL: f64 = 0.1;

struct CapstanRun {
    scene: Scene,
    tube: SweptTube,
    wire_radius: f64,
    t_in: f64,
    ratio_ref: f64,
    window: (f64, f64),
    axis: Vec3,
    bending: f64,
    energy: f64,
    track: Mutex<Track>,
}

impl ScenarioRun for CapstanRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        // Tension at the hand: the wire pulls the clamp down the lumen.
        let t_out = obs.hand_force.dot(&self.axis);
        let in_window = obs.time >= self.window.0 && obs.time <= self.window.1;
        let t = track(&self.track, obs, |t| {
            common(t, &self.tube, obs, self.wire_radius);
            if in_window {
                t.window_sum += t_out;
                t.window_n += 1;
            }
        });
        common_metrics(&mut m, &t, obs);
        let now = t_out / self.t_in;
        let ratio = if t.window_n > 0 {
            t.window_sum / t.window_n as f64 / self.t_in
        } else {
            now
        };
        m.insert("tension_ratio".into(), ratio);
        m.insert("tension_ratio_ref".into(), self.ratio_ref);
        m.insert(
            "tension_ratio_error_rel".into(),
            (ratio - self.ratio_ref).abs() / self.ratio_ref,
        );
        m.insert(
            "tension_ratio_now_error_rel".into(),
            (now - self.ratio_ref).abs() / self.ratio_ref,
        );
        m.insert("window_samples".into(), t.window_n as f64);
        m.insert("bending_over_tension".into(), self.bending);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.1
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

/// The capstan (belt friction) law `T_out / T_in = exp(mu theta)` for a
/// weightless, perfectly flexible rope sliding over a rough curve of total
/// turning angle `theta` (Euler 1762, "Remarques sur l'effet du frottement
/// dans l'equilibre", Mem. Acad. Sci. Berlin 18; independent of the curve's
/// radius).
pub fn capstan_ratio(mu: f64, theta: f64) -> f64 {
    (mu * theta).exp()
}

impl Scenario for Capstan {
    fn id(&self) -> &'static str {
        "capstan"
    }
    fn description(&self) -> &'static str {
        "soft wire threaded through a bend of wrap angle theta, loaded by a tip tension (ramped once threaded) and pulled back"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        CAPSTAN_PARAMS
    }
    fn reference(&self) -> &'static str {
        "capstan law T_out / T_in = exp(mu theta) (valid when EI / (R^2 T_in) << 1, reported as bending_over_tension)"
    }
    fn primary_error(&self) -> &'static str {
        "tension_ratio_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let r = p.get("wire_radius");
        let lumen = p.get("tube_radius");
        check_lumen(r, lumen, "tube")?;
        let (mu, theta, rc) = (p.get("friction"), p.get("wrap_angle"), p.get("bend_radius"));
        if !(rc > 2.0 * lumen) {
            return Err(UsageError(format!(
                "bend_radius {rc} m must exceed twice the tube_radius {lumen} m"
            )));
        }
        // The wire starts straight in the entry and is fed until its tip is
        // CAPSTAN_THREAD past the bend; the clamp moves with the feed, so the
        // straight must hold the clamp's whole travel (rc theta + thread +
        // the tip's start short of the bend) plus slack, and the wire starts
        // that long: the clamp ends CAPSTAN_SLACK / 2 short of the bend.
        let entry = rc * theta + CAPSTAN_THREAD + CAPSTAN_SLACK;
        let l0 = entry - CAPSTAN_SLACK / 2.0;
        // The tube starts ENTRY_S behind the clamp.
        let tube = CenterlineBuilder::new(Vec3::new(-ENTRY_S, 0.0, 0.0), Vec3::x())
            .line(ENTRY_S + entry)
            .arc(rc, theta, Vec3::y())
            .line(CAPSTAN_EXIT)
            .build_constant(lumen)
            .map_err(|e| UsageError(e.to_string()))?;
        let exit_dir = Vec3::new(theta.cos(), theta.sin(), 0.0);
        let t_in = p.get("tip_force");
        let e = p.get("youngs_modulus");
        let mut rod = RodBody::uniform(l0, r, e, p.get("poisson_ratio"), p.get("density"));
        rod.tip_force = exit_dir * t_in;
        // Thread the tip into the exit segment, dwell, pull back.
        let ins = entry + rc * theta + CAPSTAN_THREAD - l0;
        clamp_stays_in_straight(ins, entry, "entry straight")?;
        let (vi, vp, lp) = (p.get("insert_speed"), p.get("pull_speed"), p.get("pull_length"));
        if lp >= CAPSTAN_THREAD - 1e-3 {
            return Err(UsageError(format!(
                "pull_length {lp} m would pull the tip back into the bend (max {} m)",
                CAPSTAN_THREAD - 1e-3
            )));
        }
        let t1 = ins / vi;
        // The tension is applied only once the wire is threaded (a dead
        // force on the tip while it is fed would drag it across the entry
        // straight into the wall): it ramps up over CAPSTAN_RAMP, then the
        // wire dwells before the pull.
        rod.tip_load_ramp = Some(LoadRamp::linear(t1, t1 + CAPSTAN_RAMP));
        let t2 = t1 + CAPSTAN_RAMP + CAPSTAN_DWELL;
        let t3 = t2 + lp / vp;
        let mut scene = Scene::empty(self.id());
        scene.duration = t3;
        scene.bodies.push(rod.into());
        scene.environment.vessel = Some(Arc::new(tube.clone()));
        scene.environment.contact = ContactParams {
            friction_static: mu,
            friction_dynamic: mu,
            margin: r,
        };
        scene.control = timeline(&[(0.0, 0.0, 0.0), (t1, ins, 0.0), (t2, ins, 0.0), (t3, ins - lp, 0.0)]);
        scene.validate().map_err(UsageError)?;
        let ei = e * PI * r.powi(4) / 4.0;
        let ratio_ref = capstan_ratio(mu, theta);
        Ok(Box::new(CapstanRun {
            scene,
            tube,
            wire_radius: r,
            t_in,
            ratio_ref,
            // Measure over the last 60% of the pull: past the stick-to-slip transient.
            window: (t2 + 0.4 * (t3 - t2), t3),
            axis: Vec3::x(),
            bending: ei / (rc * rc * t_in),
            energy: t_in * ratio_ref * (ins + l0) + ei * (ins + l0) / (rc * rc),
            track: Mutex::new(Track::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// stick-slip-threshold
// ---------------------------------------------------------------------------

/// A wire lying on the floor of a straight tube under gravity, pulled back
/// slowly by the clamp: the tip must not move until the hand force reaches
/// `mu_s N` (N = the wire's weight) and must slide at `mu_d N` after.
pub struct StickSlipThreshold;

const STICK_PARAMS: &[ParamSpec] = &[
    P_WIRE_RADIUS,
    p(
        "youngs_modulus",
        1e6,
        "Pa",
        Range::Positive,
        "wire Young's modulus (soft, so the elastic ramp is slow)",
    ),
    P_DENSITY,
    P_POISSON,
    p("length", 0.1, "m", Range::Positive, "wire length lying in the tube"),
    p(
        "friction_static",
        0.3,
        "1",
        Range::Positive,
        "static friction coefficient mu_s",
    ),
    p(
        "friction_dynamic",
        0.2,
        "1",
        Range::NonNegative,
        "dynamic friction coefficient mu_d (<= mu_s)",
    ),
    p(
        "gravity",
        9.81,
        "m/s^2",
        Range::Positive,
        "gravity along -z presses the wire on the wall",
    ),
    p(
        "tube_radius",
        2e-3,
        "m",
        Range::Positive,
        "lumen radius (axis along +x)",
    ),
    p("settle_time", 0.3, "s", Range::Positive, "rest before pulling"),
    p("pull_speed", 1e-3, "m/s", Range::Positive, "clamp retraction speed"),
    p("pull_time", 0.3, "s", Range::Positive, "duration of the pull"),
    p(
        "slip_tol",
        1e-6,
        "m",
        Range::Positive,
        "tip displacement that counts as slipping",
    ),
];

struct StickRun {
    scene: Scene,
    tube: StraightTube,
    wire_radius: f64,
    weight: f64,
    mu_s: f64,
    mu_d: f64,
    settle: f64,
    tail_from: f64,
    slip_tol: f64,
    energy: f64,
    track: Mutex<Track>,
}

impl ScenarioRun for StickRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(tip) = tip(obs) else { return m };
        // The wire resists the pull: it pulls the clamp along +x.
        let f = obs.hand_force.x;
        let threshold = self.mu_s * self.weight;
        let t = track(&self.track, obs, |t| {
            common(t, &self.tube, obs, self.wire_radius);
            if obs.time < self.settle {
                return;
            }
            let anchor = *t.anchor.get_or_insert(tip);
            let moved = (tip - anchor).norm();
            if t.slip_at.is_none() {
                if moved > self.slip_tol {
                    t.slip_at = Some((obs.time, t.stick_force_max));
                } else {
                    t.stick_force_max = t.stick_force_max.max(f);
                }
            }
            // Creep: tip motion before the force first came near mu_s N.
            if f >= 0.95 * threshold {
                t.loaded = true;
            }
            if !t.loaded {
                t.creep_max = t.creep_max.max(moved);
            }
            if obs.time >= self.tail_from {
                t.tail_sum += f;
                t.tail_n += 1;
            }
        });
        common_metrics(&mut m, &t, obs);
        m.insert("threshold_ref_n".into(), threshold);
        m.insert("slipped".into(), t.slip_at.is_some() as u8 as f64);
        // Without a slip the threshold was never found: the error is the
        // shortfall of the largest force that held (1 if none was measured).
        let measured = t.slip_at.map_or(t.stick_force_max, |s| s.1);
        m.insert("threshold_n".into(), measured);
        m.insert("threshold_error_rel".into(), (measured - threshold).abs() / threshold);
        if let Some((ts, _)) = t.slip_at {
            m.insert("slip_time_s".into(), ts);
        }
        m.insert("creep_before_threshold_m".into(), t.creep_max);
        if t.tail_n > 0 {
            let sliding = t.tail_sum / t.tail_n as f64;
            m.insert("sliding_force_n".into(), sliding);
            if self.mu_d > 0.0 {
                let r = self.mu_d * self.weight;
                m.insert("sliding_force_error_rel".into(), (sliding - r).abs() / r);
            }
        }
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.2
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

impl Scenario for StickSlipThreshold {
    fn id(&self) -> &'static str {
        "stick-slip-threshold"
    }
    fn description(&self) -> &'static str {
        "wire resting on a tube wall under gravity, pulled slowly: static threshold mu_s N, sliding at mu_d N"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        STICK_PARAMS
    }
    fn reference(&self) -> &'static str {
        "Coulomb: no tip motion below mu_s N, sliding force mu_d N, N = rho A L g (displacement-controlled pull)"
    }
    fn primary_error(&self) -> &'static str {
        "threshold_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[10.0, 20.0, 40.0, 80.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let r = p.get("wire_radius");
        let big_r = p.get("tube_radius");
        check_lumen(r, big_r, "tube")?;
        let (mu_s, mu_d) = (p.get("friction_static"), p.get("friction_dynamic"));
        if mu_d > mu_s {
            return Err(UsageError(format!(
                "friction_dynamic {mu_d} must not exceed friction_static {mu_s}"
            )));
        }
        let (l, g, rho, e) = (
            p.get("length"),
            p.get("gravity"),
            p.get("density"),
            p.get("youngs_modulus"),
        );
        let mut rod = RodBody::uniform(l, r, e, p.get("poisson_ratio"), rho);
        // Lying on the floor: the centreline one wire radius above the wall.
        rod.base = Iso3::translation(0.0, 0.0, -(big_r - r));
        let tube = StraightTube {
            origin: Vec3::zeros(),
            axis: Vec3::x(),
            radius: big_r,
        };
        let (ts, vp, tp) = (p.get("settle_time"), p.get("pull_speed"), p.get("pull_time"));
        let weight = rho * PI * r * r * l * g;
        let ea = e * PI * r * r;
        // A uniformly loaded elastic bar slips entirely when the clamp has
        // moved mu_s w L^2 / (2 EA): the pull must go well past that.
        let needed = mu_s * weight * l / (2.0 * ea);
        if vp * tp < 3.0 * needed {
            return Err(UsageError(format!(
                "pull of {:.3e} m is shorter than 3x the elastic slack {needed:.3e} m before full slip: raise pull_speed or pull_time",
                vp * tp
            )));
        }
        let mut scene = Scene::empty(self.id());
        scene.duration = ts + tp;
        scene.gravity = Vec3::new(0.0, 0.0, -g);
        scene.bodies.push(rod.into());
        scene.environment.vessel = Some(Arc::new(tube));
        scene.environment.contact = ContactParams {
            friction_static: mu_s,
            friction_dynamic: mu_d,
            margin: r,
        };
        scene.control = timeline(&[(0.0, 0.0, 0.0), (ts, 0.0, 0.0), (ts + tp, -vp * tp, 0.0)]);
        scene.validate().map_err(UsageError)?;
        Ok(Box::new(StickRun {
            scene,
            tube,
            wire_radius: r,
            weight,
            mu_s,
            mu_d,
            settle: ts,
            tail_from: ts + 0.7 * tp,
            slip_tol: p.get("slip_tol"),
            energy: weight * (big_r + vp * tp),
            track: Mutex::new(Track::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// coronary-tortuous
// ---------------------------------------------------------------------------

/// Push, pull and rotate a guidewire for 60 s in a tortuous coronary:
/// multi-point contact along the whole wire.
pub struct CoronaryTortuous;

/// Parameters every coronary scene shares (wire, friction, feed).
const CORONARY_COMMON: [ParamSpec; 10] = [
    P_WIRE_RADIUS,
    P_BODY_E,
    P_TIP_E,
    P_TIP_LEN,
    P_DENSITY,
    P_POISSON,
    p(
        "friction_static",
        0.05,
        "1",
        Range::NonNegative,
        "static friction (coated wire)",
    ),
    p(
        "friction_dynamic",
        0.04,
        "1",
        Range::NonNegative,
        "dynamic friction (<= static)",
    ),
    p(
        "push_speed",
        5e-3,
        "m/s",
        Range::Positive,
        "feed speed of each push and pull",
    ),
    p(
        "initial_length",
        0.032,
        "m",
        Range::Positive,
        "free wire length at t = 0",
    ),
];

/// Two parameter lists joined at compile time (scenes that extend another's).
const fn joined<const A: usize, const B: usize, const N: usize>(
    a: [ParamSpec; A],
    b: [ParamSpec; B],
) -> [ParamSpec; N] {
    let mut out = [a[0]; N];
    let mut i = 0;
    while i < N {
        out[i] = if i < A { a[i] } else { b[i - A] };
        i += 1;
    }
    out
}

const CORONARY_PARAMS: &[ParamSpec] = &joined::<10, 1, 11>(
    CORONARY_COMMON,
    [p(
        "duration",
        60.0,
        "s",
        Range::Positive,
        "simulated time (6 s cycles: push 2 s, pull 1 s, turn, hold, turn back)",
    )],
);

struct CoronaryRun {
    scene: Scene,
    vessel: Arc<Vessel>,
    wire_radius: f64,
    energy: f64,
    track: Mutex<Track>,
}

/// Cycles of 6 s: push 2 s, pull 1 s, rotate +pi/2 (1 s), hold 1 s, rotate
/// -pi/4 (1 s): net advance one push-second per cycle.
fn push_pull_rotate(v: f64, duration: f64) -> ControlTimeline {
    let mut keys = vec![(0.0, 0.0, 0.0)];
    let (mut ins, mut rot, mut t) = (0.0f64, 0.0f64, 0.0f64);
    let phases = [
        (2.0, v, 0.0),
        (1.0, -v, 0.0),
        (1.0, 0.0, PI / 2.0),
        (1.0, 0.0, 0.0),
        (1.0, 0.0, -PI / 4.0),
    ];
    'outer: loop {
        for &(dt, dv, dr) in &phases {
            let end = (t + dt).min(duration);
            let w = (end - t) / dt;
            ins += dv * dt * w;
            rot += dr * w;
            t = end;
            keys.push((t, ins, rot));
            if t >= duration {
                break 'outer;
            }
        }
    }
    timeline(&keys)
}

impl ScenarioRun for CoronaryRun {
    fn observe_step(&self, obs: &Observation) {
        // Run-wide metrics accumulate in the tracker (deduplicated by time).
        let _ = self.score(obs);
    }
    fn scene(&self) -> &Scene {
        &self.scene
    }
    /// Penetration is measured from the geometry against the lumen at the
    /// observation's time (the moved wall when the vessel beats); progress
    /// is the tip's rest point projected on the centreline.
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(tip) = tip(obs) else { return m };
        let Some(lumen) = self.scene.environment.vessel_at(obs.time) else {
            return m;
        };
        let t = track(&self.track, obs, |t| common(t, lumen.as_ref(), obs, self.wire_radius));
        common_metrics(&mut m, &t, obs);
        let motion = self.scene.environment.vessel_motion.as_ref();
        let rest_tip = motion.map_or(tip, |mo| mo.rest_point(&tip, obs.time));
        m.insert("tip_progress_m".into(), self.vessel.trunk.project(&rest_tip).s);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.energy
    }
    fn length_scale(&self) -> f64 {
        0.15
    }
    fn penetration_limit(&self) -> f64 {
        0.5 * self.wire_radius
    }
}

impl Scenario for CoronaryTortuous {
    fn id(&self) -> &'static str {
        "coronary-tortuous"
    }
    fn description(&self) -> &'static str {
        "guidewire pushed, pulled and rotated for 60 s in a tortuous 3 mm coronary (bends down to 5 mm radius)"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        CORONARY_PARAMS
    }
    fn reference(&self) -> &'static str {
        "stability and penetration: wire surface depth past the wall from the geometry (no reference solution)"
    }
    fn primary_error(&self) -> &'static str {
        "max_penetration_m"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[30.0, 60.0, 120.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        Ok(Box::new(coronary_run(self.id(), p, |_| Ok(None))?))
    }
}

/// The coronary scene of `coronary-tortuous` and `coronary-beating`: the
/// wire at the entry, push/pull/rotate cycles, and the vessel's motion from
/// `motion`, which is told the deepest clamp arclength (m) the feed reaches.
fn coronary_run(
    id: &str,
    p: &Params,
    motion: impl FnOnce(f64) -> Result<Option<Arc<dyn VesselMotion>>, UsageError>,
) -> Result<CoronaryRun, UsageError> {
    let wire = Wire::from(p);
    check_lumen(wire.radius, vessel::CORONARY_RADIUS, "coronary")?;
    let l0 = p.get("initial_length");
    if l0 + ENTRY_S > vessel::CORONARY_ENTRY {
        return Err(UsageError(format!(
            "initial_length {l0} m does not fit the {} m straight entry",
            vessel::CORONARY_ENTRY
        )));
    }
    let cor = Arc::new(vessel::coronary_tortuous());
    let duration = p.get("duration");
    let v = p.get("push_speed");
    // Net advance v x 1 s per 6 s cycle, 2 v at the end of a push: the
    // deepest insertion is v (cycles + 1). Keep the tip short of the end.
    let advance = v * ((duration / 6.0).ceil() + 1.0);
    if l0 + ENTRY_S + advance > cor.trunk.length() - 5e-3 {
        return Err(UsageError(format!(
            "push_speed {v} m/s for {duration} s advances {advance:.3} m: past the end of the {:.3} m coronary",
            cor.trunk.length()
        )));
    }
    clamp_stays_in_straight(ENTRY_S + advance, vessel::CORONARY_ENTRY, "coronary entry")?;
    let mut scene = Scene::empty(id);
    scene.duration = duration;
    scene.bodies.push(wire.rod(l0, cor.trunk.frame_at(ENTRY_S))?.into());
    scene.environment.vessel = Some(cor.clone());
    scene.environment.vessel_motion = motion(ENTRY_S + advance)?;
    scene.environment.contact = contact(p, wire.radius)?;
    scene.control = push_pull_rotate(v, duration);
    scene.validate().map_err(UsageError)?;
    Ok(CoronaryRun {
        scene,
        // The whole wire bent to the tightest 5 mm bend.
        energy: wire.body_ei() * (l0 + advance) / 25e-6,
        vessel: cor,
        wire_radius: wire.radius,
        track: Mutex::new(Track::default()),
    })
}

// ---------------------------------------------------------------------------
// coronary-beating

/// The tortuous coronary on a beating heart: the lumen swings transversely
/// ([`CardiacMotion`]) while the guidewire is pushed, pulled and rotated as
/// in `coronary-tortuous`. The guiding catheter (the clamp) sits in the still
/// proximal entry; past `motion_start` the vessel swings by up to
/// `amplitude` along z at `heart_rate`, reaching full amplitude `motion_ramp`
/// further on. The wall pushes the wire sideways twice a beat: a test of
/// contact with a moving wall and of friction measured against it.
pub struct CoronaryBeating;

const BEATING_PARAMS: &[ParamSpec] = &joined::<10, 5, 15>(
    CORONARY_COMMON,
    [
        p(
            "duration",
            12.0,
            "s",
            Range::Positive,
            "simulated time (6 s push/pull/rotate cycles as in coronary-tortuous)",
        ),
        p(
            "amplitude",
            4e-3,
            "m",
            Range::NonNegative,
            "peak transverse swing of the moving vessel (heart motion: several mm, Shechter et al. 2004/2005)",
        ),
        p(
            "heart_rate",
            1.2,
            "Hz",
            Range::Positive,
            "beats per second (72 per minute)",
        ),
        p(
            "motion_start",
            0.025,
            "m",
            Range::Positive,
            "arclength along the entry where the swing begins (past the deepest clamp position, 20 mm by default)",
        ),
        p(
            "motion_ramp",
            0.025,
            "m",
            Range::Positive,
            "length over which the swing grows to full amplitude",
        ),
    ],
);

impl Scenario for CoronaryBeating {
    fn id(&self) -> &'static str {
        "coronary-beating"
    }
    fn description(&self) -> &'static str {
        "guidewire pushed, pulled and rotated in the tortuous coronary while the vessel swings 4 mm at 72 beats/min"
    }
    fn family(&self) -> Family {
        Family::Rod
    }
    fn params(&self) -> &'static [ParamSpec] {
        BEATING_PARAMS
    }
    fn reference(&self) -> &'static str {
        "stability and penetration against the moving wall (geometry at each observation's time; no reference solution)"
    }
    fn primary_error(&self) -> &'static str {
        "max_penetration_m"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        sweep_of("segments", &[30.0, 60.0, 120.0])
    }
    fn instantiate_at(&self, p: &Params, _fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let (start, ramp) = (p.get("motion_start"), p.get("motion_ramp"));
        let run = coronary_run(self.id(), p, |deepest| {
            if start <= deepest {
                return Err(UsageError(format!(
                    "motion_start {start} m must lie past the deepest clamp position {deepest:.3} m (the guiding catheter does not beat)"
                )));
            }
            // The entry runs along +x from the origin; the swing is across it.
            let m = CardiacMotion::new(
                Vec3::zeros(),
                Vec3::x(),
                Vec3::z(),
                start,
                ramp,
                p.get("amplitude"),
                p.get("heart_rate"),
            )
            .map_err(UsageError)?;
            Ok(Some(Arc::new(m)))
        })?;
        Ok(Box::new(run))
    }
}
