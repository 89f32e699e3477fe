//! The run plan of a sharded comparison: every point (one run of one
//! scenario x parameters x model x fidelity) with a stable id and the shard
//! that runs it.
//!
//! A point's id is the FNV-1a 64-bit hash ([`surgbench_reports::fnv1a`]) of
//! its canonical text ([`point_key`]): the scenario id, the parameter
//! overrides, the model id and the requested fidelity, each in the stable
//! `k=v;k=v` form `results.csv` uses (keys sorted, numbers in Rust's
//! shortest round-trip form). It depends on nothing else, so it is the same
//! on every machine and build, and adding a point to a comparison never
//! changes another point's id. A point's shard is its id modulo the shard
//! count ([`shard_of`]): adding a point never moves another point to a
//! different shard either.
//!
//! Settings of the whole run (quick or full sweeps, repeats, time limit, the
//! comparison file's hash and the commit) are recorded in the [`Plan`], not
//! in the ids: `surgbench merge` refuses to mix plans that differ in them.
//!
//! ```
//! use surgbench_comparisons::comparison::Comparison;
//! use surgbench_comparisons::plan::{point_id, shard_of};
//! let c = Comparison::parse(
//!     "name = \"x\"\nmodels = [\"der\"]\n[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [10, 20] }",
//! )
//! .unwrap();
//! let jobs = c.jobs(true, None).unwrap();
//! let id = point_id(&jobs[0]);
//! assert_eq!(id.len(), 16);
//! assert!(shard_of(&id, 4) < 4);
//! ```

use crate::UsageError;
use crate::comparison::{Comparison, Job};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use surgbench_reports::AccuracyTarget;

/// The plan's file inside a sharded run's folder.
pub const PLAN_FILE: &str = "plan.json";

/// The `format` a plan file carries.
pub const PLAN_FORMAT: &str = "surgbench-plan/1";

/// Most shards a plan may have.
pub const MAX_SHARDS: usize = 100_000;

/// The canonical text a point's id hashes: one `name=value` line each for
/// the scenario, the parameter overrides, the model and the fidelity.
pub fn point_key(job: &Job) -> String {
    let params: Vec<String> = job.params.iter().map(|(k, v)| format!("{k}={v}")).collect();
    format!(
        "surgbench point 1\nscenario={}\nparams={}\nmodel={}\nfidelity={}\n",
        job.scenario,
        params.join(";"),
        job.model,
        job.fidelity
    )
}

/// A point's id: [`point_key`] hashed with FNV-1a 64, as 16 hex digits.
pub fn point_id(job: &Job) -> String {
    format!("{:016x}", surgbench_reports::fnv1a(point_key(job).as_bytes()))
}

/// The shard (`0..shards`) that runs the point with this id: the id's
/// 64-bit value modulo `shards` (an id that is not 16 hex digits goes to
/// shard 0). `shards` must be at least 1.
pub fn shard_of(id: &str, shards: usize) -> usize {
    let v = u64::from_str_radix(id, 16).unwrap_or(0);
    (v % shards.max(1) as u64) as usize
}

/// The FNV-1a 64 hash of a comparison file's bytes, as 16 hex digits: two
/// shards that read different comparison files have different hashes.
pub fn file_hash(path: &Path) -> Result<String, UsageError> {
    let bytes =
        std::fs::read(path).map_err(|e| UsageError(format!("cannot read comparison {}: {e}", path.display())))?;
    Ok(format!("{:016x}", surgbench_reports::fnv1a(&bytes)))
}

/// One point of a plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanPoint {
    /// Stable id ([`point_id`]).
    pub id: String,
    /// The shard that runs it ([`shard_of`]).
    pub shard: usize,
    /// Scenario id.
    pub scenario: String,
    /// Parameter overrides, `k=v;k=v` (`""`: the scenario's defaults).
    pub params: String,
    /// Model id.
    pub model: String,
    /// Requested fidelity, `k=v;k=v`.
    pub fidelity: String,
    /// Why the model cannot run the scene, if it cannot (no process runs).
    pub unsupported: Option<String>,
}

/// The run plan of a sharded comparison (`plan.json`). Deterministic: the
/// same comparison, options, commit and shard count give the same bytes,
/// so shards that start at once may each write it. Its settings read
/// directly on the plan (`plan.shards`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// [`PLAN_FORMAT`].
    pub format: String,
    /// Comparison name.
    pub comparison: String,
    /// What the plan was made with besides the comparison.
    #[serde(flatten)]
    pub settings: PlanSettings,
    /// Every point, in the comparison's order (the order of `results.csv`).
    pub points: Vec<PlanPoint>,
    /// The comparison's accuracy targets by scenario, for the merged
    /// report's verdicts (absent in plans written before targets existed).
    #[serde(default)]
    pub targets: BTreeMap<String, AccuracyTarget>,
}

impl std::ops::Deref for Plan {
    type Target = PlanSettings;

    fn deref(&self) -> &PlanSettings {
        &self.settings
    }
}

/// What a plan is made from besides the comparison's jobs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanSettings {
    /// [`file_hash`] of the comparison file.
    pub comparison_hash: String,
    /// Commit of the code ([`crate::batch::git_commit`]).
    pub commit: String,
    /// Quick sweeps.
    pub quick: bool,
    /// Only these models (`None`: the comparison's own selection).
    pub models: Option<Vec<String>>,
    /// Repeats per run.
    pub repeats: usize,
    /// Wall-clock limit per run (s).
    pub timeout_s: f64,
    /// Shard count.
    pub shards: usize,
    /// Time budgets per step (ms) the merged report's verdicts name
    /// (`--budget-ms`; the defaults in plans written before they were kept).
    #[serde(default = "default_budgets_ms")]
    pub budgets_ms: Vec<f64>,
}

/// [`PlanSettings::budgets_ms`] of a plan that has none.
fn default_budgets_ms() -> Vec<f64> {
    surgbench_reports::DEFAULT_BUDGETS_MS.to_vec()
}

impl Plan {
    /// The plan of comparison `c`'s `jobs` (validated, in order) under
    /// `settings`. Two jobs with one id (a comparison that lists a point
    /// twice) or a shard count outside `1..=`[`MAX_SHARDS`] is a usage error.
    pub fn new(c: &Comparison, jobs: &[Job], settings: PlanSettings) -> Result<Plan, UsageError> {
        check_shard_count(settings.shards)?;
        let mut seen = std::collections::BTreeMap::new();
        let mut points = Vec::with_capacity(jobs.len());
        for job in jobs {
            let id = point_id(job);
            let params: Vec<String> = job.params.iter().map(|(k, v)| format!("{k}={v}")).collect();
            let point = PlanPoint {
                shard: shard_of(&id, settings.shards),
                id: id.clone(),
                scenario: job.scenario.clone(),
                params: params.join(";"),
                model: job.model.clone(),
                fidelity: job.fidelity.to_string(),
                unsupported: job.unsupported.clone(),
            };
            if let Some(other) = seen.insert(id.clone(), describe(&point)) {
                return Err(UsageError(format!(
                    "two points share the id {id} ({other}; {}): list each run once",
                    describe(&point)
                )));
            }
            points.push(point);
        }
        Ok(Plan {
            format: PLAN_FORMAT.into(),
            comparison: c.name.clone(),
            settings,
            points,
            targets: c.targets()?,
        })
    }

    /// The points shard `k` runs, each with its index in [`Plan::points`]
    /// (the index of its job), in plan order.
    pub fn shard_points(&self, k: usize) -> impl Iterator<Item = (usize, &PlanPoint)> {
        self.points.iter().enumerate().filter(move |(_, p)| p.shard == k)
    }

    /// How many points each shard runs, by shard index.
    pub fn counts(&self) -> Vec<usize> {
        let mut n = vec![0; self.shards];
        for p in &self.points {
            n[p.shard] += 1;
        }
        n
    }

    /// How `self` differs from `other` in what makes two plans one run (the
    /// comparison, its file, the commit, sweeps, models, repeats, time
    /// limit, shard count, time budgets and points): one line per difference, empty when
    /// they are the same run.
    pub fn differences(&self, other: &Plan) -> Vec<String> {
        let mut d = Vec::new();
        let mut cmp = |what: &str, a: String, b: String| {
            if a != b {
                d.push(format!("{what}: {a} here, {b} there"));
            }
        };
        cmp("comparison", self.comparison.clone(), other.comparison.clone());
        cmp(
            "comparison file hash",
            self.comparison_hash.clone(),
            other.comparison_hash.clone(),
        );
        cmp("commit", self.commit.clone(), other.commit.clone());
        cmp("quick", self.quick.to_string(), other.quick.to_string());
        cmp("models", format!("{:?}", self.models), format!("{:?}", other.models));
        cmp("repeats", self.repeats.to_string(), other.repeats.to_string());
        cmp("timeout_s", self.timeout_s.to_string(), other.timeout_s.to_string());
        cmp("shards", self.shards.to_string(), other.shards.to_string());
        cmp(
            "budgets_ms",
            format!("{:?}", self.budgets_ms),
            format!("{:?}", other.budgets_ms),
        );
        let ids = |p: &Plan| p.points.iter().map(|p| p.id.clone()).collect::<Vec<_>>();
        if ids(self) != ids(other) {
            d.push(format!(
                "points: {} here, {} there (not the same ids)",
                self.points.len(),
                other.points.len()
            ));
        }
        d
    }

    /// Reads `dir/plan.json`; `Ok(None)` when there is none.
    pub fn load(dir: &Path) -> Result<Option<Plan>, UsageError> {
        let path = dir.join(PLAN_FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(UsageError(format!("cannot read {}: {e}", path.display()))),
        };
        let plan: Plan = serde_json::from_str(&text)
            .map_err(|e| UsageError(format!("{} is not a surgbench plan: {e}", path.display())))?;
        if plan.format != PLAN_FORMAT {
            return Err(UsageError(format!(
                "{} has format `{}`; this surgbench reads `{PLAN_FORMAT}`",
                path.display(),
                plan.format
            )));
        }
        check_shard_count(plan.shards).map_err(|e| UsageError(format!("{}: {}", path.display(), e.0)))?;
        if let Some(p) = plan.points.iter().find(|p| p.shard >= plan.shards) {
            return Err(UsageError(format!(
                "{}: point {} is in shard {} of {}",
                path.display(),
                p.id,
                p.shard,
                plan.shards
            )));
        }
        Ok(Some(plan))
    }

    /// Writes `dir/plan.json` atomically (a temporary file renamed into place).
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)? + "\n";
        write_atomic(&dir.join(PLAN_FILE), text.as_bytes())
    }
}

/// `scenario [params] / model [fidelity]`: a point for people.
pub fn describe(p: &PlanPoint) -> String {
    let params = if p.params.is_empty() {
        String::new()
    } else {
        format!(" [{}]", p.params)
    };
    let fid = if p.fidelity.is_empty() { "default" } else { &p.fidelity };
    format!("{}{params} / {} [{fid}]", p.scenario, p.model)
}

fn check_shard_count(n: usize) -> Result<(), UsageError> {
    if (1..=MAX_SHARDS).contains(&n) {
        Ok(())
    } else {
        Err(UsageError(format!(
            "the shard count must be 1 to {MAX_SHARDS}, got {n}"
        )))
    }
}

/// Writes `bytes` to `path` through a temporary file beside it (named after
/// this host and process, so writers on several machines sharing the folder
/// never write into one temporary file) renamed into place: a reader sees
/// the old file or the whole new one. The temporary file is removed on error.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("file");
    let tmp = path.with_file_name(format!(".{name}.{}-{}.tmp", host_name(), std::process::id()));
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// This machine's host name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`,
/// else `unknown`), with anything but letters, digits, `.`, `-` and `_`
/// replaced by `_` so it can stand in a file name.
pub fn host_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown".into());
    raw.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Which shard this process runs, and where that was read.
#[derive(Debug, Clone, PartialEq)]
pub struct ShardIndex {
    /// Index, `0..count`.
    pub index: usize,
    /// Count, when the source gives one.
    pub count: Option<usize>,
    /// Where it came from (`--shard`, or the environment variables).
    pub source: String,
}

/// The array-job index variables surgbench reads, each with its count
/// variable: Slurm job arrays, Kubernetes Indexed Jobs (no count variable:
/// pass `--shards`), AWS Batch array jobs, Google Cloud Batch.
pub const INDEX_VARS: [(&str, Option<&str>); 4] = [
    ("SLURM_ARRAY_TASK_ID", Some("SLURM_ARRAY_TASK_COUNT")),
    ("JOB_COMPLETION_INDEX", None),
    ("AWS_BATCH_JOB_ARRAY_INDEX", Some("AWS_BATCH_JOB_ARRAY_SIZE")),
    ("BATCH_TASK_INDEX", Some("BATCH_TASK_COUNT")),
];

/// `K/N` of `--shard`: `0 <= K < N`.
pub fn parse_shard(text: &str) -> Result<ShardIndex, UsageError> {
    let bad = || UsageError(format!("--shard takes K/N with 0 <= K < N (e.g. 0/4), got `{text}`"));
    let (k, n) = text.split_once('/').ok_or_else(bad)?;
    let k: usize = k.trim().parse().map_err(|_| bad())?;
    let n: usize = n.trim().parse().map_err(|_| bad())?;
    if k >= n {
        return Err(bad());
    }
    check_shard_count(n)?;
    Ok(ShardIndex {
        index: k,
        count: Some(n),
        source: "--shard".into(),
    })
}

/// The shard index from the first of [`INDEX_VARS`] that `env` sets, or
/// `None` when none is set. A value that is not a whole number is a usage
/// error naming the variable.
pub fn shard_from_env(env: &dyn Fn(&str) -> Option<String>) -> Result<Option<ShardIndex>, UsageError> {
    let number = |var: &str, text: String| {
        text.trim()
            .parse::<usize>()
            .map_err(|_| UsageError(format!("{var}={text:?} is not a whole number")))
    };
    for (index_var, count_var) in INDEX_VARS {
        let Some(text) = env(index_var).filter(|t| !t.trim().is_empty()) else {
            continue;
        };
        let index = number(index_var, text)?;
        let count = match count_var.and_then(|v| env(v).map(|t| (v, t))) {
            Some((v, t)) => Some(number(v, t)?),
            None => None,
        };
        let source = match count_var {
            Some(c) if count.is_some() => format!("{index_var}/{c}"),
            _ => index_var.to_string(),
        };
        return Ok(Some(ShardIndex { index, count, source }));
    }
    Ok(None)
}

/// The shard count of a run: `--shards` when given, else the plan already
/// in the run's folder, else the count the index's source gave. A
/// `--shards` or `--shard K/N` that disagrees with the plan is a usage
/// error; an environment count that disagrees with the plan yields to it
/// (a resubmitted subset of an array has a smaller count), with a note in
/// the returned `Option<String>`. No count at all, or an index not below
/// the count, is a usage error.
pub fn resolve_count(
    index: &ShardIndex,
    flag: Option<usize>,
    plan: Option<&Plan>,
) -> Result<(usize, Option<String>), UsageError> {
    let from_flag = index.source == "--shard";
    let mut note = None;
    let count = match (flag, plan) {
        (Some(n), Some(p)) if n != p.shards => {
            return Err(UsageError(format!(
                "--shards {n} disagrees with the plan in the run's folder ({} shards): use that count or another --out",
                p.shards
            )));
        }
        (Some(n), _) => n,
        (None, Some(p)) => {
            if let Some(c) = index.count.filter(|c| *c != p.shards) {
                if from_flag {
                    return Err(UsageError(format!(
                        "--shard {}/{c} disagrees with the plan in the run's folder ({} shards)",
                        index.index, p.shards
                    )));
                }
                note = Some(format!(
                    "{} gives {c} shards, the plan in the run's folder {}: using the plan's",
                    index.source, p.shards
                ));
            }
            p.shards
        }
        (None, None) => index.count.ok_or_else(|| {
            UsageError(format!(
                "{} gives the shard index but not the count: pass --shards N (or run `surgbench plan --shards N` into --out first)",
                index.source
            ))
        })?,
    };
    check_shard_count(count)?;
    if index.index >= count {
        return Err(UsageError(format!(
            "shard index {} (from {}) is not below the shard count {count}: indices count from 0 (Slurm: --array=0-{})",
            index.index,
            index.source,
            count - 1
        )));
    }
    Ok((count, note))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_text_and_environment_are_read() {
        assert_eq!(parse_shard("2/4").unwrap().index, 2);
        for bad in ["4/4", "1", "a/4", "0/0", "-1/3"] {
            assert!(parse_shard(bad).is_err(), "{bad}");
        }
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
        };
        let s = shard_from_env(&env(&[("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_COUNT", "8")]))
            .unwrap()
            .unwrap();
        assert_eq!((s.index, s.count), (3, Some(8)));
        let s = shard_from_env(&env(&[("JOB_COMPLETION_INDEX", "5")])).unwrap().unwrap();
        assert_eq!((s.index, s.count), (5, None));
        let e = resolve_count(&s, None, None).unwrap_err().0;
        assert!(e.contains("--shards"), "{e}");
        assert_eq!(resolve_count(&s, Some(6), None).unwrap().0, 6);
        assert!(resolve_count(&s, Some(5), None).unwrap_err().0.contains("from 0"));
        let s = shard_from_env(&env(&[
            ("AWS_BATCH_JOB_ARRAY_INDEX", "1"),
            ("AWS_BATCH_JOB_ARRAY_SIZE", "2"),
        ]))
        .unwrap()
        .unwrap();
        assert_eq!((s.index, s.count), (1, Some(2)));
        let s = shard_from_env(&env(&[("BATCH_TASK_INDEX", "0"), ("BATCH_TASK_COUNT", "3")]))
            .unwrap()
            .unwrap();
        assert_eq!((s.index, s.count), (0, Some(3)));
        assert!(shard_from_env(&env(&[("SLURM_ARRAY_TASK_ID", "x")])).is_err());
        assert!(shard_from_env(&env(&[])).unwrap().is_none());
    }
}
