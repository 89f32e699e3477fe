//! Issue 23: the plan of a sharded run. A point's id depends on the point
//! alone (adding a point changes no other id or shard), the id is the
//! written-down FNV-1a 64 hash (the same on every machine and build), the
//! shards of N = 1..8 cover every point exactly once, and merge lists the
//! folders that are not one run (another comparison or commit).

use std::collections::BTreeMap;
use std::path::Path;
use surgbench_comparisons::batch;
use surgbench_comparisons::comparison::Comparison;
use surgbench_comparisons::merge;
use surgbench_comparisons::plan::{Plan, PlanSettings, point_id, point_key};
use surgbench_comparisons::shard_run::{POINT_FORMAT, POINTS_DIR, PointRecord, ensure_plan, point_path};
use surgbench_reports::{ResultRow, Status};

const BASE: &str = "name = \"small\"\nmodels = [\"der\", \"chainmail\"]\n\
[[scenario]]\nid = \"cantilever-gravity\"\nquick_sweep = { segments = [10, 20] }\n";

fn settings(shards: usize, commit: &str) -> PlanSettings {
    PlanSettings {
        comparison_hash: "0123456789abcdef".into(),
        commit: commit.into(),
        quick: true,
        models: None,
        repeats: 1,
        timeout_s: 300.0,
        shards,
        budgets_ms: vec![1.0, 16.0, 33.0],
    }
}

fn plan_of(toml: &str, shards: usize, commit: &str) -> Plan {
    let c = Comparison::parse(toml).unwrap();
    let jobs = batch::checked_jobs(&c, true, None).unwrap();
    Plan::new(&c, &jobs, settings(shards, commit)).unwrap()
}

/// id -> shard of every point.
fn shards_by_id(p: &Plan) -> BTreeMap<String, usize> {
    p.points.iter().map(|p| (p.id.clone(), p.shard)).collect()
}

/// Adding a sweep value and a whole scenario entry adds points; every
/// point that was there keeps its id and, for every shard count, its shard.
#[test]
fn ids_and_shards_stay_when_points_are_added() {
    let grown = format!(
        "{}\n[[scenario]]\nid = \"torque-transfer\"\n",
        BASE.replace("segments = [10, 20]", "segments = [10, 15, 20]")
    );
    for n in 1..=8 {
        let before = plan_of(BASE, n, "c1");
        let after = plan_of(&grown, n, "c1");
        assert!(
            after.points.len() > before.points.len() + 2,
            "n={n}: {} points before, {} after",
            before.points.len(),
            after.points.len()
        );
        let (b, a) = (shards_by_id(&before), shards_by_id(&after));
        for (id, shard) in &b {
            assert_eq!(a.get(id), Some(shard), "n={n}: point {id} moved or vanished");
        }
    }
}

/// The id is FNV-1a 64 of the point's canonical text, written down: it
/// must not change with the Rust version, the machine or the build.
#[test]
fn id_is_the_documented_hash_of_the_point() {
    let c = Comparison::parse(BASE).unwrap();
    let jobs = c.jobs(true, None).unwrap();
    let j = &jobs[0];
    assert_eq!(
        (j.model.as_str(), j.fidelity.to_string()),
        ("der", "segments=10".to_string())
    );
    assert_eq!(
        point_key(j),
        "surgbench point 1\nscenario=cantilever-gravity\nparams=\nmodel=der\nfidelity=segments=10\n"
    );
    // FNV-1a 64 of that text, computed by hand once; also the id of this
    // point in the standard comparison's quick plan.
    assert_eq!(point_id(j), "92a48b73c0ff2a15");
    assert_eq!(surgbench_reports::fnv1a(b""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(surgbench_reports::fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
}

/// For N = 1..8 the shards' point lists together hold every point of the
/// standard comparison's quick plan exactly once.
#[test]
fn shards_cover_every_point_exactly_once() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let c = Comparison::load(&root.join("standard.toml")).unwrap();
    let jobs = batch::checked_jobs(&c, true, None).unwrap();
    for n in 1..=8 {
        let p = Plan::new(&c, &jobs, settings(n, "c1")).unwrap();
        let mut times_run = vec![0usize; p.points.len()];
        for k in 0..n {
            for (i, _) in p.shard_points(k) {
                times_run[i] += 1;
            }
        }
        let wrong: Vec<_> = times_run.iter().enumerate().filter(|(_, t)| **t != 1).collect();
        assert!(wrong.is_empty(), "n={n}: points run other than once: {wrong:?}");
        assert_eq!(p.counts().iter().sum::<usize>(), jobs.len(), "n={n}");
        if n > 1 {
            assert!(
                p.counts().iter().all(|c| *c > 0),
                "n={n}: an empty shard: {:?}",
                p.counts()
            );
        }
    }
}

/// A sharded run's folder holding `plan` and a finished `ok` record of
/// each of its points.
fn finished_folder(dir: &Path, plan: &Plan) {
    ensure_plan(dir, plan).unwrap();
    std::fs::create_dir_all(dir.join(POINTS_DIR)).unwrap();
    for p in &plan.points {
        let mut row = ResultRow {
            comparison: plan.comparison.clone(),
            scenario: p.scenario.clone(),
            model: p.model.clone(),
            fidelity: p.fidelity.clone(),
            ..Default::default()
        };
        row.status = Status::Ok;
        let rec = PointRecord {
            format: POINT_FORMAT.into(),
            id: p.id.clone(),
            shard: p.shard,
            shards: plan.shards,
            comparison: plan.comparison.clone(),
            comparison_hash: plan.comparison_hash.clone(),
            commit: plan.commit.clone(),
            host: "node1".into(),
            machine: "cpu".into(),
            cores: 2,
            threads: 1,
            finished: "2026-01-01T00:00:00Z".into(),
            wall_s: 1.0,
            cells: surgbench_reports::row_cells(&row),
        };
        std::fs::write(point_path(dir, &p.id), serde_json::to_string(&rec).unwrap()).unwrap();
    }
}

/// Two folders of one run merge cleanly; folders at two commits, or of
/// two comparisons, are listed as mixed (the CLI refuses them unless
/// told); a point file whose commit differs from its folder's plan too.
#[test]
fn merge_lists_mixed_commits_and_comparisons() {
    let tmp = tempfile::tempdir().unwrap();
    let d = |n: &str| tmp.path().join(n);
    let one = plan_of(BASE, 2, "aaa");
    finished_folder(&d("a"), &one);
    finished_folder(&d("a2"), &one);
    let g = merge::gather(&[d("a"), d("a2")]).unwrap();
    assert!(g.mixed.is_empty(), "{:?}", g.mixed);
    assert!(g.missing.is_empty());
    assert_eq!(g.rows.len(), one.points.len(), "a point finished twice counts once");

    finished_folder(&d("b"), &plan_of(BASE, 2, "bbb"));
    let g = merge::gather(&[d("a"), d("b")]).unwrap();
    assert!(
        g.mixed.iter().any(|m| m.contains("commit: aaa here, bbb there")),
        "{:?}",
        g.mixed
    );

    finished_folder(&d("c"), &plan_of(&BASE.replace("\"small\"", "\"other\""), 2, "aaa"));
    let g = merge::gather(&[d("a"), d("c")]).unwrap();
    assert!(
        g.mixed
            .iter()
            .any(|m| m.contains("comparison: small here, other there")),
        "{:?}",
        g.mixed
    );

    // A shard built from another commit wrote into this folder.
    let p = &one.points[0];
    let path = point_path(&d("a2"), &p.id);
    let text = std::fs::read_to_string(&path).unwrap().replace("\"aaa\"", "\"zzz\"");
    std::fs::write(&path, text).unwrap();
    let g = merge::gather(&[d("a2")]).unwrap();
    assert!(
        g.mixed.iter().any(|m| m.contains(&p.id) && m.contains("commit zzz")),
        "{:?}",
        g.mixed
    );
}

/// A plan written before it kept the time budgets reads with the defaults,
/// and two plans that differ only in their budgets are two runs.
#[test]
fn budgets_default_in_old_plans_and_tell_runs_apart() {
    let p = plan_of(BASE, 2, "c0ffee");
    let mut json: serde_json::Value = serde_json::to_value(&p).unwrap();
    json.as_object_mut().unwrap().remove("budgets_ms").unwrap();
    let old: Plan = serde_json::from_value(json).unwrap();
    assert_eq!(old.budgets_ms, surgbench_reports::DEFAULT_BUDGETS_MS.to_vec());
    let mut other = p.clone();
    other.settings.budgets_ms = vec![5.0];
    let d = p.differences(&other);
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(d[0].starts_with("budgets_ms"), "{d:?}");
}
