//! Scenarios: a scene builder with named parameters, a reference, metrics
//! and a default fidelity sweep.
//!
//! A [`Scenario`] validates user parameters and returns a [`ScenarioRun`]
//! that holds the scene and its precomputed reference, so scoring a model's
//! observation is cheap and the reference is computed once per parameter
//! set, outside any timed loop.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use surgbench_core::{ControlTimeline, Family, Fidelity, Observation, Scene};

pub use crate::error::UsageError;
pub use crate::user_mesh::{MeshKind, UserMesh};
pub use surgbench_reports::{Marker, PlanePoint};

/// Admissible range of a parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    /// `v > 0`.
    Positive,
    /// `v >= 0`.
    NonNegative,
    /// Any finite value.
    Any,
    /// `lo < v < hi`.
    Open(f64, f64),
    /// `lo <= v <= hi`.
    Closed(f64, f64),
}

impl Range {
    fn check(self, v: f64) -> bool {
        v.is_finite()
            && match self {
                Range::Positive => v > 0.0,
                Range::NonNegative => v >= 0.0,
                Range::Any => true,
                Range::Open(a, b) => v > a && v < b,
                Range::Closed(a, b) => v >= a && v <= b,
            }
    }

    /// The admissible values as `surgbench list` prints them (`> 0`, `in [0, 1]`).
    pub fn describe(self) -> String {
        match self {
            Range::Positive => "> 0".into(),
            Range::NonNegative => ">= 0".into(),
            Range::Any => "finite".into(),
            Range::Open(a, b) => format!("in ({a}, {b})"),
            Range::Closed(a, b) => format!("in [{a}, {b}]"),
        }
    }
}

/// A named scenario parameter with its default, unit and range.
#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    /// Name used with `--param name=value`.
    pub name: &'static str,
    /// Default value (SI).
    pub default: f64,
    /// Unit, e.g. `m`, `Pa`, `N`, `rad`, `1`.
    pub unit: &'static str,
    /// Admissible values.
    pub range: Range,
    /// One line.
    pub doc: &'static str,
}

impl ParamSpec {
    /// A parameter: name, default (SI), unit, admissible range, one line.
    pub const fn new(name: &'static str, default: f64, unit: &'static str, range: Range, doc: &'static str) -> Self {
        Self {
            name,
            default,
            unit,
            range,
            doc,
        }
    }
}

/// `a == b` in a constant context: `params!` checks at compile time that
/// each field is named as its [`ParamSpec`].
pub const fn same_name(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// A scenario's parameters as a typed struct: one `f64` field per
/// [`ParamSpec`], named as the spec (checked at compile time), in listing
/// order, implementing [`ParamSet`]: `NAME::SPECS` is the list `surgbench
/// list` shows and [`Params::resolve`] validates against; `NAME::of(&params)`
/// reads the resolved values, so a misspelt parameter is a compile error.
///
/// ```ignore
/// params! {
///     /// Parameters of `my-scene`.
///     pub struct MyParams {
///         length: ParamSpec::new("length", 0.1, "m", Range::Positive, "free length"),
///     }
/// }
/// let p = MyParams::of(&Params::resolve("my-scene", MyParams::SPECS, &[])?);
/// assert_eq!(p.length, 0.1);
/// ```
#[macro_export]
macro_rules! params {
    ($(#[$meta:meta])* $vis:vis struct $name:ident { $($field:ident : $spec:expr),* $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq)]
        $vis struct $name {
            $(
                #[doc = concat!("`", stringify!($field), "` (SI; unit, range and default in `SPECS`).")]
                pub $field: f64,
            )*
        }
        impl $crate::scenario::ParamSet for $name {
            const SPECS: &'static [$crate::scenario::ParamSpec] = &[$($spec),*];
            fn of(p: &$crate::scenario::Params) -> Self {
                Self { $($field: p.get(stringify!($field))),* }
            }
        }
        const _: () = {
            $(assert!(
                $crate::scenario::same_name(stringify!($field), $spec.name),
                concat!("params!: field `", stringify!($field), "` is not named as its ParamSpec")
            );)*
        };
    };
}

/// Resolved parameter values: defaults overlaid with the user's overrides.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Params {
    values: BTreeMap<String, f64>,
    overridden: Vec<(String, f64)>,
}

impl Params {
    /// Resolve overrides against the specs; unknown names and out-of-range
    /// values are usage errors naming the parameter.
    pub fn resolve(scenario: &str, specs: &[ParamSpec], overrides: &[(String, f64)]) -> Result<Self, UsageError> {
        let mut values: BTreeMap<String, f64> = specs.iter().map(|s| (s.name.to_string(), s.default)).collect();
        for (k, v) in overrides {
            let Some(spec) = specs.iter().find(|s| s.name == k) else {
                let known: Vec<_> = specs.iter().map(|s| s.name).collect();
                return Err(UsageError(format!(
                    "scenario `{scenario}` has no parameter `{k}` (known: {})",
                    known.join(", ")
                )));
            };
            if !spec.range.check(*v) {
                return Err(UsageError(format!(
                    "parameter `{k}` of `{scenario}` must be {} {}, got {v}",
                    spec.range.describe(),
                    spec.unit
                )));
            }
            values.insert(k.clone(), *v);
        }
        Ok(Self {
            values,
            overridden: overrides.to_vec(),
        })
    }

    /// Value of a declared parameter. `params!` structs call it with their
    /// specs' own names, which [`Params::resolve`] always fills; any other
    /// name is a programming error and panics.
    pub fn get(&self, name: &str) -> f64 {
        match self.values.get(name) {
            Some(v) => *v,
            None => panic!("scenario asked for undeclared parameter `{name}`"),
        }
    }

    /// Whether the user gave `name` (rather than taking its default).
    pub fn is_overridden(&self, name: &str) -> bool {
        self.overridden.iter().any(|(k, _)| k == name)
    }

    /// All resolved values.
    pub fn values(&self) -> &BTreeMap<String, f64> {
        &self.values
    }

    /// The overrides as given, `k=v;k=v` (empty for defaults).
    pub fn overrides_string(&self) -> String {
        self.overridden
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(";")
    }
}

/// Parse `key=value` parameter overrides; a name given twice is an error
/// naming it (it would otherwise keep one of the two silently).
pub fn parse_overrides<S: AsRef<str>>(pairs: &[S]) -> Result<Vec<(String, f64)>, UsageError> {
    let mut out: Vec<(String, f64)> = Vec::with_capacity(pairs.len());
    for p in pairs {
        let p = p.as_ref();
        let (k, v) = p
            .split_once('=')
            .ok_or_else(|| UsageError(format!("parameter `{p}` is not of the form name=value")))?;
        let x: f64 = v
            .trim()
            .parse()
            .map_err(|_| UsageError(format!("parameter `{k}`: `{v}` is not a number")))?;
        let k = k.trim();
        if let Some((_, first)) = out.iter().find(|(name, _)| name == k) {
            return Err(UsageError(format!(
                "parameter `{k}` is given twice ({k}={first} and {k}={x}); give it once"
            )));
        }
        out.push((k.to_string(), x));
    }
    Ok(out)
}

/// Error metrics of one observation (SI; names end in their unit or `_rel`).
pub type Metrics = BTreeMap<String, f64>;

/// Scores one run of a scenario: it is shown every step's observation in
/// time order ([`Scorer::observe_step`]) and owns whatever run-wide sums
/// its metrics need (time to reach, peak force, a force curve). A fresh
/// scorer serves each run (and each repeat of it), so no state leaks
/// between runs.
///
/// A scenario whose metrics depend on one observation alone scores with a
/// closure: `Fn(&Observation) -> Metrics` is a [`Scorer`].
pub trait Scorer {
    /// Take in the observation after a step (time increases call to call).
    fn observe_step(&mut self, obs: &Observation) {
        let _ = obs;
    }
    /// Error metrics of `obs` against the reference, with the run-wide
    /// metrics accumulated from the steps observed so far.
    fn score(&self, obs: &Observation) -> Metrics;
    /// Where the reference puts the tip at time `t` (s), in m, for scenes
    /// whose reference is a trajectory (the report plots it beside the
    /// models' tips); `None` (the default) for the others.
    fn reference_tip_at(&self, t: f64) -> Option<[f64; 3]> {
        let _ = t;
        None
    }
    /// The point of the model a trajectory-scored scene without a rod
    /// follows (a tissue's probe node, m), recorded as the run's tip so
    /// that the report plots it against [`Scorer::reference_tip_at`];
    /// `None` (the default): the first rod's tip.
    fn tracked_point(&self, obs: &Observation) -> Option<[f64; 3]> {
        let _ = obs;
        None
    }
    /// For scenes scored along a force history: the force the scene scores
    /// at `obs` (N, as the scene defines it: the push on a needle, the load
    /// on a whole indenter) and the reference's value there, which the
    /// report plots over time; `None` (the default) for the other scenes,
    /// and at steps where the reference has no value.
    fn force_point(&self, obs: &Observation) -> Option<(f64, f64)> {
        let _ = obs;
        None
    }
    /// For scenes scored along a load curve (an indenter's force against
    /// its depth): the indentation depth at `obs` (m), which the report
    /// plots [`Scorer::force_point`] against; `None` (the default) for the
    /// others.
    fn force_depth(&self, obs: &Observation) -> Option<f64> {
        let _ = obs;
        None
    }
    /// For scenes scored at measured material points (the Truth Cube's
    /// beads): each point at rest, in `obs` and in the reference, which the
    /// run writes to `markers.csv` and the report maps; empty (the default)
    /// for the others.
    fn markers(&self, obs: &Observation) -> Vec<Marker> {
        let _ = obs;
        Vec::new()
    }
    /// For scenes scored on the shape of a tip path (a steered needle's):
    /// the path up to `obs` in its bend plane with the best-fit arc the
    /// scene scores it by, which the run writes to `tip_path.csv` and the
    /// report plots; empty (the default) for the others.
    fn plane_path(&self, obs: &Observation) -> Vec<PlanePoint> {
        let _ = obs;
        Vec::new()
    }
}

impl<F: Fn(&Observation) -> Metrics> Scorer for F {
    fn score(&self, obs: &Observation) -> Metrics {
        self(obs)
    }
}

/// What a scenario instance scores against: it makes a fresh [`Scorer`]
/// for each run of its scene. References whose metrics depend on one
/// observation alone implement [`Pointwise`] instead.
pub trait Reference: Send + Sync {
    /// A fresh scorer for one run of `scene`.
    fn scorer<'a>(&'a self, scene: &'a Scene) -> Box<dyn Scorer + 'a>;
}

/// A reference whose metrics depend on the observation scored alone (no
/// run-wide sums): every `Pointwise` is a [`Reference`].
pub trait Pointwise: Send + Sync {
    /// Error metrics of `obs` against the reference.
    fn score(&self, obs: &Observation) -> Metrics;
    /// As [`Scorer::markers`]: the measured points of `obs`, if any.
    fn markers(&self, obs: &Observation) -> Vec<Marker> {
        let _ = obs;
        Vec::new()
    }
}

/// The scorer of a [`Pointwise`] reference.
struct PointwiseScorer<'a, T>(&'a T);

impl<T: Pointwise> Scorer for PointwiseScorer<'_, T> {
    fn score(&self, obs: &Observation) -> Metrics {
        self.0.score(obs)
    }
    fn markers(&self, obs: &Observation) -> Vec<Marker> {
        self.0.markers(obs)
    }
}

impl<T: Pointwise> Reference for T {
    fn scorer<'a>(&'a self, _scene: &'a Scene) -> Box<dyn Scorer + 'a> {
        Box::new(PointwiseScorer(self))
    }
}

/// How far the hand may feed a wire: its clamp starts `start` (m) along a
/// straight of length `straight` (m), named `what`, and must stay on it.
/// A vessel scene checks its own timeline with it, and a replayed session
/// is checked against the same limit ([`ScenarioRun::check_control`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedLimit {
    /// Where the clamp starts along the straight (m).
    pub start: f64,
    /// Length of the straight (m).
    pub straight: f64,
    /// The straight's name, for messages.
    pub what: &'static str,
}

impl FeedLimit {
    /// `Err` when an insertion of `insertion` (m) would take the clamp off
    /// either end of the straight (a non-finite insertion included).
    pub fn check(&self, insertion: f64) -> Result<(), UsageError> {
        let (reach, straight, what) = (self.start + insertion, self.straight, self.what);
        if !(reach <= straight) {
            return Err(UsageError(format!(
                "the clamp would be fed {reach:.3} m along the {straight:.3} m {what}: past its end, into the wall (shorten the push)"
            )));
        }
        if !(reach >= 0.0) {
            return Err(UsageError(format!(
                "the clamp would be pulled back {:.3} m behind the start of the {straight:.3} m {what}, out of the vessel",
                -reach
            )));
        }
        Ok(())
    }
}

/// One instantiated scenario: the scene every model runs, the reference its
/// runs are scored against (computed once, outside any timed loop), and the
/// scales the runner's watchdogs use.
pub struct ScenarioRun {
    scene: Scene,
    reference: Box<dyn Reference>,
    energy_scale: f64,
    length_scale: f64,
    penetration_limit: f64,
    reference_tip: Option<[f64; 3]>,
    reference_centreline: Vec<[f64; 3]>,
    feed_limit: Option<FeedLimit>,
}

impl ScenarioRun {
    /// `scene` scored against `reference`; the energy watchdog trips past
    /// 10x `energy_scale` (J) of growth, the bounding one on a node 10x
    /// `length_scale` (m) from the origin. No penetration limit, no
    /// reference tip until set.
    pub fn new(scene: Scene, reference: impl Reference + 'static, energy_scale: f64, length_scale: f64) -> Self {
        Self {
            scene,
            reference: Box::new(reference),
            energy_scale,
            length_scale,
            penetration_limit: f64::INFINITY,
            reference_tip: None,
            reference_centreline: Vec::new(),
            feed_limit: None,
        }
    }
    /// The hand may feed the wire only as far as `limit` allows: a control
    /// timeline other than the scene's own (a replayed session) is checked
    /// against it by [`ScenarioRun::check_control`].
    pub fn with_feed_limit(mut self, limit: FeedLimit) -> Self {
        self.feed_limit = Some(limit);
        self
    }
    /// Whether `timeline` (e.g. a replayed session driving this scene) keeps
    /// within the limits the scenario checks its own timeline against: a
    /// usage error naming the key that would feed the wire too far.
    pub fn check_control(&self, timeline: &ControlTimeline) -> Result<(), UsageError> {
        let Some(limit) = self.feed_limit else {
            return Ok(());
        };
        for k in &timeline.keys {
            limit
                .check(k.insertion)
                .map_err(|e| UsageError(format!("at t={} s: {e}", k.t)))?;
        }
        Ok(())
    }
    /// Trip the penetration watchdog past `limit` (m).
    pub fn with_penetration_limit(mut self, limit: f64) -> Self {
        self.penetration_limit = limit;
        self
    }
    /// The reference tip position (m), reported beside the model's.
    pub fn with_reference_tip(mut self, tip: [f64; 3]) -> Self {
        self.reference_tip = Some(tip);
        self
    }
    /// The reference shape of the (first) rod at the end of the run (m,
    /// base to tip), which every run writes beside its final state and the
    /// report draws the models' centrelines against.
    pub fn with_reference_centreline(mut self, points: Vec<[f64; 3]>) -> Self {
        self.reference_centreline = points;
        self
    }
    /// The reference centreline ([`ScenarioRun::with_reference_centreline`]);
    /// empty when the scenario has none.
    pub fn reference_centreline(&self) -> &[[f64; 3]] {
        &self.reference_centreline
    }
    /// The scene every model runs.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }
    /// A fresh scorer for one run of this scene.
    pub fn scorer(&self) -> Box<dyn Scorer + '_> {
        self.reference.scorer(&self.scene)
    }
    /// Energy scale (J): the energy growth watchdog trips past 10x this.
    pub fn energy_scale(&self) -> f64 {
        self.energy_scale
    }
    /// Length scale (m): a node farther than 10x this from the origin trips
    /// the bounding watchdog.
    pub fn length_scale(&self) -> f64 {
        self.length_scale
    }
    /// Penetration (m) past which the penetration watchdog trips.
    pub fn penetration_limit(&self) -> f64 {
        self.penetration_limit
    }
    /// The reference tip position (m), if the scenario has one.
    pub fn reference_tip(&self) -> Option<[f64; 3]> {
        self.reference_tip
    }
}

/// A scenario's default fidelity sweep, as data.
#[derive(Debug, Clone, Copy)]
pub enum Sweep {
    /// One knob (`segments`, `dt`, ...) over these values.
    Knob(&'static str, &'static [f64]),
    /// Tissue mesh levels `0..=up_to`, each with time step `dt` (s) if
    /// given.
    MeshLevels {
        /// The finest level.
        up_to: usize,
        /// The time step of every level, if the sweep sets one.
        dt: Option<f64>,
    },
}

impl Sweep {
    /// The fidelities of the sweep.
    pub fn fidelities(self) -> Vec<Fidelity> {
        match self {
            Sweep::Knob(knob, values) => sweep_of(knob, values),
            Sweep::MeshLevels { up_to, dt } => (0..=up_to)
                .map(|l| Fidelity {
                    mesh_level: Some(l),
                    dt,
                    ..Default::default()
                })
                .collect(),
        }
    }
}

/// What a scenario is, declared once: shown by `surgbench list`, written
/// into every result row, swept by comparisons.
#[derive(Debug, Clone, Copy)]
pub struct ScenarioInfo {
    /// Stable id, e.g. `cantilever-gravity`.
    pub id: &'static str,
    /// One line.
    pub description: &'static str,
    /// Which model family it exercises.
    pub family: Family,
    /// What the reference is, one line (shown in the report).
    pub reference: &'static str,
    /// Name of the headline error metric (a key of the scorer's metrics).
    pub primary_error: &'static str,
    /// The largest primary error a user of this scene would accept, and
    /// why: the report's verdicts ("accurate enough?") read it; a
    /// comparison may state another (`target = ...` on its scenario).
    pub target: Target,
    /// Parameters with defaults (a `params!` struct's `SPECS`).
    pub params: &'static [ParamSpec],
    /// Default fidelity sweep.
    pub sweep: Sweep,
    /// How many of the sweep's first fidelities `--quick` runs.
    pub quick: usize,
    /// The geometry the scenario can take from a user's file instead of
    /// building its own (`run-one --mesh FILE`); `None` for most.
    pub mesh: Option<MeshKind>,
}

/// An accuracy target: the primary error (in its own unit) a run must not
/// exceed, with where the number comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// `|primary error| <= value` meets the target.
    pub value: f64,
    /// Why this number, one line (shown in the report).
    pub why: &'static str,
}

impl Target {
    /// A target of `value` for the reason `why`.
    pub const fn new(value: f64, why: &'static str) -> Self {
        Self { value, why }
    }
}

/// Everything a scenario's builder reads besides its typed parameters.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// The resolved parameters (e.g. to tell defaults from overrides).
    pub params: &'a Params,
    /// The requested fidelity (tissue scenes build their mesh at its
    /// `mesh_level`).
    pub fidelity: &'a Fidelity,
    /// The folder holding `phantom/` and `reference/` data.
    pub datasets: &'a Path,
    /// The user's geometry (`--mesh`), if given; only scenarios whose
    /// [`ScenarioInfo::mesh`] says they take one are handed one.
    pub mesh: Option<&'a UserMesh>,
}

/// A scenario of the catalogue. [`Declared`] is the usual implementation:
/// a [`ScenarioInfo`] and a builder function.
pub trait Scenario: Send + Sync {
    /// Id, description, family, reference, headline metric, parameters,
    /// sweep.
    fn info(&self) -> &ScenarioInfo;
    /// Validate parameters, build the scene and compute the reference for a
    /// requested fidelity: the harness always calls this one. Scenarios
    /// whose geometry depends on a fidelity knob (tissue meshes built at
    /// `mesh_level`) read it; the others ignore it.
    fn instantiate_at(&self, params: &Params, fidelity: &Fidelity) -> Result<ScenarioRun, UsageError> {
        self.instantiate_with(params, fidelity, None)
    }
    /// [`Scenario::instantiate_at`] on the user's geometry `mesh` (if any)
    /// instead of the scenario's own: a mesh the scenario does not take (see
    /// [`ScenarioInfo::mesh`]) is a [`UsageError`].
    fn instantiate_with(
        &self,
        params: &Params,
        fidelity: &Fidelity,
        mesh: Option<&UserMesh>,
    ) -> Result<ScenarioRun, UsageError>;

    /// [`Scenario::instantiate_at`] at the default fidelity.
    fn instantiate(&self, params: &Params) -> Result<ScenarioRun, UsageError> {
        self.instantiate_at(params, &Fidelity::default())
    }
    /// Stable id ([`ScenarioInfo::id`]).
    fn id(&self) -> &'static str {
        self.info().id
    }
    /// One line ([`ScenarioInfo::description`]).
    fn description(&self) -> &'static str {
        self.info().description
    }
    /// Model family ([`ScenarioInfo::family`]).
    fn family(&self) -> Family {
        self.info().family
    }
    /// The reference, one line ([`ScenarioInfo::reference`]).
    fn reference(&self) -> &'static str {
        self.info().reference
    }
    /// Headline error metric ([`ScenarioInfo::primary_error`]).
    fn primary_error(&self) -> &'static str {
        self.info().primary_error
    }
    /// Accuracy target ([`ScenarioInfo::target`]).
    fn target(&self) -> Target {
        self.info().target
    }
    /// Parameters with defaults ([`ScenarioInfo::params`]).
    fn params(&self) -> &'static [ParamSpec] {
        self.info().params
    }
    /// Default fidelity sweep ([`ScenarioInfo::sweep`]).
    fn sweep(&self) -> Vec<Fidelity> {
        self.info().sweep.fidelities()
    }
    /// The smaller sweep of `--quick` ([`ScenarioInfo::quick`]).
    fn quick_sweep(&self) -> Vec<Fidelity> {
        self.sweep().into_iter().take(self.info().quick).collect()
    }
}

/// A typed parameter struct (declared with `params!`).
pub trait ParamSet: Sized {
    /// Name, default, unit and range of every parameter, in listing order.
    const SPECS: &'static [ParamSpec];
    /// The resolved values.
    fn of(p: &Params) -> Self;
}

/// A scenario declared as data: what it is and how it builds an instance
/// from its typed parameters `P`.
pub struct Declared<P: ParamSet> {
    /// Id, description, reference, parameters, sweep.
    pub info: ScenarioInfo,
    /// Data folder (`None`: [`crate::datasets::datasets_dir`]); a test may
    /// point a scenario at other reference data.
    pub datasets: Option<&'static str>,
    /// Builds the scene and its reference.
    pub build: fn(&P, &Inputs) -> Result<ScenarioRun, UsageError>,
}

impl<P: ParamSet> Scenario for Declared<P> {
    fn info(&self) -> &ScenarioInfo {
        &self.info
    }
    fn instantiate_with(
        &self,
        params: &Params,
        fidelity: &Fidelity,
        mesh: Option<&UserMesh>,
    ) -> Result<ScenarioRun, UsageError> {
        if let Some(m) = mesh {
            crate::user_mesh::check_kind(self.info.id, self.info.mesh, m)?;
        }
        let datasets = self
            .datasets
            .map(PathBuf::from)
            .unwrap_or_else(crate::datasets::datasets_dir);
        let inputs = Inputs {
            params,
            fidelity,
            datasets: &datasets,
            mesh,
        };
        (self.build)(&P::of(params), &inputs)
    }
}

/// Sweep over one fidelity knob.
pub fn sweep_of(knob: &str, values: &[f64]) -> Vec<Fidelity> {
    values
        .iter()
        .map(|v| {
            let mut f = Fidelity::default();
            f.set(knob, *v).expect("static sweep values are valid");
            f
        })
        .collect()
}
