//! Comparisons as data: `comparisons/*.toml` name scenarios, models,
//! fidelity sweeps and parameter overrides.
//!
//! ```toml
//! name = "standard"
//! description = "rod statics"
//! models = "all"            # or ["der", "chainmail"]
//! repeats = 3
//! repeat_budget_s = 10     # further repeats only while under 10 s (optional)
//! timeout_s = 300
//!
//! [[scenario]]
//! id = "cantilever-gravity"
//! params = { length = 0.1 }                  # overrides (optional)
//! sweep = { segments = [10, 20, 40, 80] }    # cartesian product (optional)
//! quick_sweep = { segments = [10, 20] }      # used by --quick (optional)
//! [scenario.models.der]                      # per-model sweep (optional)
//! sweep = { segments = [10, 20], integrator = ["backward-euler", "newmark"] }
//! ```
//!
//! A model's choice takes its name (`surgbench list` shows each key's
//! names); numbers are for numeric knobs and 0/1 switches.
//!
//! A model appears in a comparison by being registered and supporting its
//! scenarios; only a comparison that lists models explicitly names them.

use crate::registry;
use crate::resolve::ResolvedRun;
use crate::scenario::{Params, Scenario, UsageError};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;
use surgbench_core::{Fidelity, ModelFactory, Scene, Setting};
use surgbench_reports::AccuracyTarget;

/// Which models a comparison runs.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum ModelSelection {
    /// `"all"`.
    All(String),
    /// An explicit list of ids.
    List(Vec<String>),
}

/// Per-model settings inside a scenario entry.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ModelEntry {
    /// Replaces the scenario sweep for this model.
    pub sweep: Option<Grid>,
    /// Replaces the quick sweep for this model.
    pub quick_sweep: Option<Grid>,
    /// Points run after the sweep's for this model, expanded like a sweep:
    /// a setting run on part of the sweep only (the meshless seed variant,
    /// whose explicit steps make the finest mesh level too slow). A point
    /// also in the sweep is an error (each point is one run and one
    /// folder).
    pub extra_sweep: Option<Grid>,
    /// `extra_sweep` for `--quick`.
    pub quick_extra_sweep: Option<Grid>,
    /// Fixed knobs added to every sweep point of this model.
    #[serde(default)]
    pub fidelity: BTreeMap<String, Setting>,
}

/// One scenario of a comparison.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioEntry {
    /// Scenario id.
    pub id: String,
    /// Parameter overrides.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// Fidelity sweep (cartesian product); default: the scenario's own.
    pub sweep: Option<Grid>,
    /// Sweep for `--quick`; default: the scenario's quick sweep.
    pub quick_sweep: Option<Grid>,
    /// Per-model settings.
    #[serde(default)]
    pub models: BTreeMap<String, ModelEntry>,
    /// Accuracy target of the scenario's primary error (its unit), in place
    /// of the scenario's own ([`crate::scenario::ScenarioInfo::target`]).
    pub target: Option<f64>,
    /// Whether `target` came from the command line (`--target`), not the file.
    #[serde(skip)]
    pub target_from_cli: bool,
}

fn default_rate() -> f64 {
    1000.0
}
fn default_duration() -> f64 {
    10.0
}
fn default_quick_duration() -> f64 {
    1.0
}

/// A fixed-rate haptic loop to run after the comparison's runs
/// (`[[haptic]]`): the report's "can this model drive a device" table.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HapticEntry {
    /// Model id.
    pub model: String,
    /// Scenario id (its control timeline drives the scripted device).
    pub scenario: String,
    /// Parameter overrides.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    /// Fidelity knobs.
    #[serde(default)]
    pub fidelity: BTreeMap<String, Setting>,
    /// Loop rate (Hz), default 1000.
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
    /// Wall-clock duration (s), default 10.
    #[serde(default = "default_duration")]
    pub duration_s: f64,
    /// Duration under `--quick` (s), default 1.
    #[serde(default = "default_quick_duration")]
    pub quick_duration_s: f64,
}

/// One haptic loop to run, validated.
#[derive(Debug, Clone)]
pub struct HapticJob {
    /// Model id.
    pub model: String,
    /// Scenario id.
    pub scenario: String,
    /// Parameter overrides.
    pub params: Vec<(String, f64)>,
    /// Requested fidelity.
    pub fidelity: Fidelity,
    /// Rate (Hz).
    pub rate_hz: f64,
    /// Duration (s).
    pub duration_s: f64,
    /// Why the model cannot run the scene, if it cannot.
    pub unsupported: Option<String>,
}

/// A comparison file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Comparison {
    /// Name (the report folder is named after it).
    pub name: String,
    /// One line.
    #[serde(default)]
    pub description: String,
    /// Models to run.
    pub models: ModelSelection,
    /// Repeats per run (timings pooled).
    pub repeats: Option<usize>,
    /// A run's further repeats start only while its repeats so far took
    /// less than this wall time (s) (`run-one --repeat-budget`); none: all
    /// `repeats`.
    pub repeat_budget_s: Option<f64>,
    /// Wall-clock limit per run (s).
    pub timeout_s: Option<f64>,
    /// Scenarios.
    pub scenario: Vec<ScenarioEntry>,
    /// Haptic loops (optional).
    #[serde(default)]
    pub haptic: Vec<HapticEntry>,
}

/// One run to do.
#[derive(Debug, Clone)]
pub struct Job {
    /// Scenario id.
    pub scenario: String,
    /// Parameter overrides.
    pub params: Vec<(String, f64)>,
    /// Model id.
    pub model: String,
    /// Requested fidelity (model defaults fill the rest).
    pub fidelity: Fidelity,
    /// Why the model cannot run this scenario, if it cannot: no process is
    /// started, the report shows the reason.
    pub unsupported: Option<String>,
}

/// A fidelity sweep: each knob's values (numbers or choice names).
pub type Grid = BTreeMap<String, Vec<Setting>>;

fn expand(grid: &Grid) -> Result<Vec<Fidelity>, UsageError> {
    let mut out = vec![Fidelity::default()];
    for (k, vals) in grid {
        if vals.is_empty() {
            return Err(UsageError(format!("sweep of `{k}` is empty")));
        }
        if let Some(v) = vals
            .iter()
            .enumerate()
            .find_map(|(i, v)| vals[..i].contains(v).then_some(v))
        {
            return Err(UsageError(format!(
                "sweep of `{k}` lists {v} twice (each value is one run and one folder); list it once"
            )));
        }
        let mut next = Vec::new();
        for f in &out {
            for v in vals {
                let mut g = f.clone();
                g.set_setting(k, v.clone()).map_err(|e| UsageError(e.0))?;
                next.push(g);
            }
        }
        out = next;
    }
    Ok(out)
}

/// One sweep point of model `f` on scenario `sc` (default instance
/// `scene`), checked before anything runs: the instance at its mesh level
/// (geometry may depend on the fidelity), its knobs against the model's
/// declared keys and choices, its step count at the full fidelity's `dt`.
/// `levels`: the mesh levels already instantiated for this scenario entry
/// (scenarios read only `mesh_level` of the fidelity, and building a fine
/// mesh takes seconds: each level is built once per entry).
fn check_point(
    sc: &dyn Scenario,
    params: &Params,
    scene: &Scene,
    f: &dyn ModelFactory,
    fid: &Fidelity,
    levels: &mut std::collections::BTreeSet<usize>,
) -> Result<(), UsageError> {
    let named = |e: String| UsageError(format!("scenario `{}`, model `{}`: {e}", sc.id(), f.id()));
    if let Some(level) = fid.mesh_level
        && !levels.contains(&level)
    {
        sc.instantiate_at(params, fid)?;
        levels.insert(level);
    }
    fid.validate_extras(f.fidelity_keys()).map_err(|e| named(e.0))?;
    if let Some(dt) = f.default_fidelity(scene).merged(fid).dt {
        crate::runner::check_steps(scene.duration, dt).map_err(|e| named(e.0))?;
    }
    Ok(())
}

/// A scenario's own accuracy target, as the report records it.
pub fn default_target(sc: &dyn Scenario) -> AccuracyTarget {
    let t = sc.target();
    AccuracyTarget {
        metric: sc.primary_error().into(),
        value: t.value,
        why: t.why.into(),
    }
}

impl Comparison {
    /// Parse a comparison file; errors name the file and the problem.
    pub fn load(path: &Path) -> Result<Self, UsageError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| UsageError(format!("cannot read comparison {}: {e}", path.display())))?;
        Self::parse(&text).map_err(|e| UsageError(format!("{}: {}", path.display(), e.0)))
    }

    /// Parse comparison TOML text.
    pub fn parse(text: &str) -> Result<Self, UsageError> {
        let c: Comparison =
            toml::from_str(text).map_err(|e| UsageError(format!("malformed comparison TOML: {}", e.message())))?;
        if let ModelSelection::All(s) = &c.models
            && s != "all"
        {
            return Err(UsageError(format!(
                "`models` must be \"all\" or a list of ids, got \"{s}\""
            )));
        }
        if c.scenario.is_empty() {
            return Err(UsageError("comparison has no [[scenario]]".into()));
        }
        if c.repeats == Some(0) {
            return Err(UsageError("repeats must be >= 1".into()));
        }
        if let Some(b) = c.repeat_budget_s
            && !(b > 0.0)
        {
            return Err(UsageError(format!("repeat_budget_s must be > 0, got {b}")));
        }
        if let Some(t) = c.timeout_s
            && !(t > 0.0)
        {
            return Err(UsageError(format!("timeout_s must be > 0, got {t}")));
        }
        for e in &c.scenario {
            if let Some(t) = e.target
                && !(t >= 0.0 && t.is_finite())
            {
                return Err(UsageError(format!(
                    "scenario {}: target must be a finite number >= 0 (the primary error's unit), got {t}",
                    e.id
                )));
            }
        }
        for h in &c.haptic {
            for (name, v) in [
                ("rate_hz", h.rate_hz),
                ("duration_s", h.duration_s),
                ("quick_duration_s", h.quick_duration_s),
            ] {
                if !(v > 0.0 && v.is_finite()) {
                    return Err(UsageError(format!(
                        "[[haptic]] {} on {}: {name} must be > 0, got {v}",
                        h.model, h.scenario
                    )));
                }
            }
        }
        Ok(c)
    }

    /// The accuracy target of each scenario the comparison runs: the
    /// comparison's `target` where it states one, the scenario's own
    /// otherwise. Two entries of one scenario with different targets are a
    /// usage error (the report judges a scenario against one target).
    pub fn targets(&self) -> Result<BTreeMap<String, AccuracyTarget>, UsageError> {
        let mut out: BTreeMap<String, AccuracyTarget> = BTreeMap::new();
        for e in &self.scenario {
            let sc = registry::scenario(&e.id)?;
            let t = match e.target {
                Some(v) => AccuracyTarget {
                    metric: sc.primary_error().into(),
                    value: v,
                    why: if e.target_from_cli {
                        "set on the command line (--target)".into()
                    } else {
                        format!("set by the comparison `{}`", self.name)
                    },
                },
                None => default_target(sc),
            };
            match out.get(&e.id) {
                Some(old) if old.value != t.value => {
                    return Err(UsageError(format!(
                        "scenario {}: two targets ({} and {}); give every entry of a scenario the same target",
                        e.id, old.value, t.value
                    )));
                }
                Some(_) => {}
                None => {
                    out.insert(e.id.clone(), t);
                }
            }
        }
        Ok(out)
    }

    /// The haptic loops to run, validated like the runs (scenario, model,
    /// parameters, fidelity knobs) before anything runs; `only` restricts
    /// the models.
    pub fn haptic_jobs(&self, quick: bool, only: Option<&[String]>) -> Result<Vec<HapticJob>, UsageError> {
        let mut jobs = Vec::new();
        for h in &self.haptic {
            registry::model(&h.model)?;
            if only.is_some_and(|o| !o.iter().any(|m| m == &h.model)) {
                continue;
            }
            let overrides: Vec<(String, f64)> = h.params.iter().map(|(k, v)| (k.clone(), *v)).collect();
            let run = ResolvedRun::from_knobs(&h.scenario, &h.model, &overrides, &h.fidelity)
                .map_err(|e| UsageError(format!("[[haptic]] {}", e.0)))?;
            jobs.push(HapticJob {
                model: h.model.clone(),
                scenario: h.scenario.clone(),
                params: overrides,
                fidelity: run.requested,
                rate_hz: h.rate_hz,
                duration_s: if quick { h.quick_duration_s } else { h.duration_s },
                unsupported: run.support.err(),
            });
        }
        Ok(jobs)
    }

    /// Expand into jobs, validating every scenario, parameter, model and
    /// fidelity knob before anything runs. `only` restricts the models.
    pub fn jobs(&self, quick: bool, only: Option<&[String]>) -> Result<Vec<Job>, UsageError> {
        let all = registry::models();
        let mut ids: Vec<&str> = match &self.models {
            ModelSelection::All(_) => all.iter().map(|r| r.factory.id()).collect(),
            ModelSelection::List(l) => {
                for m in l {
                    registry::model(m)?;
                }
                l.iter().map(|s| s.as_str()).collect()
            }
        };
        if let Some(only) = only {
            for m in only {
                registry::model(m)?;
            }
            ids.retain(|id| only.iter().any(|o| o == id));
        }
        let mut jobs = Vec::new();
        for entry in &self.scenario {
            let sc = registry::scenario(&entry.id)?;
            let overrides: Vec<(String, f64)> = entry.params.iter().map(|(k, v)| (k.clone(), *v)).collect();
            let params = Params::resolve(sc.id(), sc.params(), &overrides)?;
            let inst = sc.instantiate(&params)?;
            let mut levels = std::collections::BTreeSet::new();
            for m in entry.models.keys() {
                registry::model(m)?;
            }
            for id in &ids {
                let f = registry::model(id)?;
                // A tissue model has nothing to say about a rod scene and
                // vice versa: cross-family pairs are left out, unless the
                // comparison names the model for this scenario. Coupled
                // models take part in both families.
                let named = entry.models.contains_key(*id);
                if !named && f.family() != sc.family() && f.family() != surgbench_core::Family::Coupled {
                    continue;
                }
                let me = entry.models.get(*id).cloned().unwrap_or_default();
                if let Err(u) = f.check(inst.scene()) {
                    jobs.push(Job {
                        scenario: sc.id().into(),
                        params: overrides.clone(),
                        model: id.to_string(),
                        fidelity: Fidelity::default(),
                        unsupported: Some(u.reason),
                    });
                    continue;
                }
                let grid = if quick {
                    me.quick_sweep.as_ref().or(entry.quick_sweep.as_ref())
                } else {
                    me.sweep.as_ref().or(entry.sweep.as_ref())
                };
                let mut sweep = match grid {
                    Some(g) => expand(g)?,
                    None if quick => sc.quick_sweep(),
                    None => sc.sweep(),
                };
                let extra = if quick { &me.quick_extra_sweep } else { &me.extra_sweep };
                if let Some(g) = extra {
                    for fid in expand(g)? {
                        if sweep.contains(&fid) {
                            return Err(UsageError(format!(
                                "{}: the extra sweep of {id} repeats the sweep's point {fid} (each point is one run and one folder); list it once",
                                sc.id()
                            )));
                        }
                        sweep.push(fid);
                    }
                }
                let fixed = expand(&me.fidelity.iter().map(|(k, v)| (k.clone(), vec![v.clone()])).collect())?;
                for fid in sweep {
                    let fid = fid.merged(&fixed[0]);
                    check_point(sc, &params, inst.scene(), f, &fid, &mut levels)?;
                    jobs.push(Job {
                        scenario: sc.id().into(),
                        params: overrides.clone(),
                        model: id.to_string(),
                        fidelity: fid,
                        unsupported: None,
                    });
                }
            }
        }
        Ok(jobs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_toml_is_a_usage_error() {
        let e = Comparison::parse("name = \"x\"\nmodels = [1, 2").unwrap_err();
        assert!(e.0.contains("malformed"), "{e}");
        let e = Comparison::parse("name = \"x\"\nmodels = \"some\"\n[[scenario]]\nid = \"a\"").unwrap_err();
        assert!(e.0.contains("\"all\""), "{e}");
        let e = Comparison::parse("name = \"x\"\nmodels = \"all\"\nbogus = 1\n[[scenario]]\nid = \"a\"").unwrap_err();
        assert!(e.0.contains("bogus"), "{e}");
        for bad in ["0", "-1", "nan"] {
            let e = Comparison::parse(&format!(
                "name = \"x\"\nmodels = \"all\"\nrepeat_budget_s = {bad}\n[[scenario]]\nid = \"a\""
            ))
            .unwrap_err();
            assert!(e.0.contains("repeat_budget_s must be > 0"), "{e}");
        }
        let c = Comparison::parse("name = \"x\"\nmodels = \"all\"\nrepeat_budget_s = 10\n[[scenario]]\nid = \"a\"");
        assert_eq!(c.unwrap().repeat_budget_s, Some(10.0));
    }

    #[test]
    fn unknown_scenario_and_parameter_are_named() {
        let c = Comparison::parse("name = \"x\"\nmodels = \"all\"\n[[scenario]]\nid = \"nope\"").unwrap();
        assert!(c.jobs(false, None).unwrap_err().0.contains("unknown scenario `nope`"));
        let c = Comparison::parse(
            "name = \"x\"\nmodels = \"all\"\n[[scenario]]\nid = \"cantilever-gravity\"\nparams = { lenght = 1.0 }",
        )
        .unwrap();
        assert!(c.jobs(false, None).unwrap_err().0.contains("no parameter `lenght`"));
        let c = Comparison::parse(
            "name = \"x\"\nmodels = \"all\"\n[[scenario]]\nid = \"cantilever-gravity\"\nparams = { length = -1.0 }",
        )
        .unwrap();
        assert!(c.jobs(false, None).unwrap_err().0.contains("`length`"));
    }

    #[test]
    fn haptic_entries_are_validated() {
        let base = "name = \"x\"\nmodels = \"all\"\n[[scenario]]\nid = \"cantilever-gravity\"\n";
        let e = Comparison::parse(&format!(
            "{base}[[haptic]]\nmodel = \"der\"\nscenario = \"arch-insertion\"\nrate_hz = 0\n"
        ))
        .unwrap_err();
        assert!(e.0.contains("rate_hz"), "{e}");
        let c = Comparison::parse(&format!(
            "{base}[[haptic]]\nmodel = \"nope\"\nscenario = \"arch-insertion\"\n"
        ))
        .unwrap();
        assert!(c.haptic_jobs(false, None).unwrap_err().0.contains("nope"));
        let c = Comparison::parse(&format!(
            "{base}[[haptic]]\nmodel = \"der\"\nscenario = \"arch-insertion\"\nduration_s = 3\n"
        ))
        .unwrap();
        let j = c.haptic_jobs(true, None).unwrap();
        assert_eq!((j.len(), j[0].duration_s, j[0].rate_hz), (1, 1.0, 1000.0));
        assert_eq!(c.haptic_jobs(false, None).unwrap()[0].duration_s, 3.0);
        assert!(
            c.haptic_jobs(false, Some(&["chainmail".to_string()]))
                .unwrap()
                .is_empty()
        );
    }

    /// Choices are names in sweeps and fixed knobs; a numeric code for a
    /// choice, an unknown name or a value of another type is refused
    /// before anything runs, naming the key and the choices.
    #[test]
    fn model_choices_are_names() {
        let base = "name = \"x\"\nmodels = [\"pbd-rod\"]\n[[scenario]]\nid = \"cantilever-gravity\"\n";
        let jobs = |models: &str| Comparison::parse(&format!("{base}{models}")).and_then(|c| c.jobs(true, None));
        let j = jobs(
            "[scenario.models.pbd-rod]\nquick_sweep = { segments = [10], solver = [\"gauss-seidel\", \"direct\"] }\n",
        )
        .unwrap();
        let f: Vec<String> = j.iter().map(|j| j.fidelity.to_string()).collect();
        assert_eq!(f, ["segments=10;solver=gauss-seidel", "segments=10;solver=direct"]);
        let e = jobs("[scenario.models.pbd-rod]\nquick_sweep = { solver = [0, 1] }\n").unwrap_err();
        assert!(
            e.0.contains("`solver` takes a name, one of: gauss-seidel, direct"),
            "{e}"
        );
        let e = jobs("[scenario.models.pbd-rod]\nfidelity = { solver = \"jacobi\" }\n").unwrap_err();
        assert!(e.0.contains("unknown choice `jacobi`"), "{e}");
        let e = jobs("[scenario.models.pbd-rod]\nfidelity = { solver = true }\n").unwrap_err();
        assert!(e.0.contains("a number or a choice name"), "{e}");
    }

    /// An extra sweep adds its points after the sweep's, for its model only;
    /// one that repeats a sweep point is refused, naming it.
    #[test]
    fn an_extra_sweep_adds_points_after_the_sweep() {
        let base = "name = \"x\"\nmodels = [\"pbd-rod\"]\n[[scenario]]\nid = \"cantilever-gravity\"\n";
        let jobs = |models: &str| Comparison::parse(&format!("{base}{models}")).and_then(|c| c.jobs(false, None));
        let j = jobs(
            "sweep = { segments = [10, 20] }\n[scenario.models.pbd-rod]\nextra_sweep = { segments = [10], solver = [\"direct\"] }\n",
        )
        .unwrap();
        let f: Vec<String> = j.iter().map(|j| j.fidelity.to_string()).collect();
        assert_eq!(f, ["segments=10", "segments=20", "segments=10;solver=direct"]);
        let e = jobs("sweep = { segments = [10, 20] }\n[scenario.models.pbd-rod]\nextra_sweep = { segments = [20] }\n")
            .unwrap_err();
        assert!(e.0.contains("repeats the sweep's point segments=20"), "{e}");
        // The quick run takes the quick extra sweep, not the full one.
        let q = Comparison::parse(&format!(
            "{base}quick_sweep = {{ segments = [10] }}\n[scenario.models.pbd-rod]\nextra_sweep = {{ segments = [40] }}\nquick_extra_sweep = {{ segments = [20] }}\n"
        ))
        .and_then(|c| c.jobs(true, None))
        .unwrap();
        let f: Vec<String> = q.iter().map(|j| j.fidelity.to_string()).collect();
        assert_eq!(f, ["segments=10", "segments=20"]);
    }

    #[test]
    fn sweep_is_a_cartesian_product() {
        let g: Grid = [
            ("segments".to_string(), vec![10.0.into(), 20.0.into()]),
            ("dt".to_string(), vec![1e-3.into(), 1e-4.into()]),
        ]
        .into();
        let f = expand(&g).unwrap();
        assert_eq!(f.len(), 4);
        assert!(expand(&[("dt".to_string(), vec![(-1.0).into()])].into()).is_err());
        assert!(expand(&[("dt".to_string(), vec!["fast".into()])].into()).is_err());
    }
}
