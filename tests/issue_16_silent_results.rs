//! Issue 16, item 7: silent or misleading results. Each test is one of the
//! issue's reproductions, now a clear error or a correct result:
//!
//! - folder names over 255 bytes from long numbers (`dt = [1e300]`) made a
//!   run "failed ... no message": now run folders are short, unique names;
//! - a 1e308 coordinate in phantom data gave inf/NaN errors that
//!   `summary.json` stored as null with status ok: now the run is `failed`
//!   and says why;
//! - `run --quick` did not validate the full sweep: now it does;
//! - a binary `results.csv` printed a Rust debug dump: now a sentence;
//! - a repeated `--param` (or `--fidelity`) silently kept the last: now a
//!   usage error naming the key;
//! - a sweep listing one value twice wrote one run folder twice: now a
//!   usage error;
//! - `--timeout` did not bound `[[haptic]]` jobs: now it does;
//! - run from outside the checkout, the binary resolved comparisons,
//!   datasets and the default `--out` to the build tree's path: now to the
//!   current directory's project (see `datasets::project_root`);
//! - at E = 1e20 a static run said "settled" after 10 steps with a 5.5 %
//!   error: the rod was settled (run on, it stays), and the 5.5 % was the
//!   elastica reference's own rounding (it summed x along the rod); it now
//!   integrates the foreshortening, and the error is the model's.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use surgbench_reports::{ResultRow, RunSummary, Status, read_results_csv};

mod common;

/// Every command here finishes in seconds; this is for a regression that
/// hangs (e.g. a haptic job waiting out its old two-minute limit).
const LIMIT: Duration = Duration::from_secs(90);

fn surgbench() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_surgbench"));
    c.env("SURGBENCH_FAULTY_MODELS", "1");
    c
}

fn run(mut cmd: Command, what: &str) -> Output {
    cmd.env("RUST_BACKTRACE", "0");
    common::output_within(cmd, LIMIT, what)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit 2, a one-line message holding every needle, and no Rust debug dump.
fn assert_usage_error(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "expected exit 2, stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr should mention `{n}`: {err}");
    }
    assert!(!err.contains("panicked") && !err.contains(" { "), "a debug dump: {err}");
}

/// `surgbench run <toml> --out <dir>/report` of the comparison `text`,
/// plus `extra`.
fn run_comparison(dir: &Path, text: &str, extra: &[&str]) -> Output {
    let toml = dir.join("cmp.toml");
    std::fs::write(&toml, text).unwrap();
    let mut cmd = surgbench();
    cmd.arg("run")
        .arg(&toml)
        .arg("--out")
        .arg(dir.join("report"))
        .arg("--quiet");
    cmd.args(extra);
    run(cmd, "surgbench run")
}

/// A one-scenario comparison of `model` on the cantilever, with `sweep`.
fn cantilever(model: &str, sweep: &str) -> String {
    format!("name = \"c\"\nmodels = [\"{model}\"]\n[[scenario]]\nid = \"cantilever-gravity\"\n{sweep}\n")
}

fn rows(dir: &Path) -> Vec<ResultRow> {
    read_results_csv(&dir.join("report/results.csv")).unwrap()
}

#[test]
fn a_dt_of_1e300_runs_in_a_short_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run_comparison(
        tmp.path(),
        &cantilever("der", "sweep = { segments = [10], dt = [1e300] }"),
        &[],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = rows(tmp.path());
    assert_eq!(rows.len(), 1);
    let r = &rows[0];
    assert!(
        r.status != Status::Failed && !r.reason.contains("no message"),
        "the run itself must run: {} ({})",
        r.status,
        r.reason
    );
    let dir = tmp.path().join("report").join(&r.run_dir);
    assert!(dir.join("summary.json").is_file(), "no summary in {}", dir.display());
    for c in Path::new(&r.run_dir).components() {
        let n = c.as_os_str().len();
        assert!(n <= 100, "folder name of {n} bytes: {}", r.run_dir);
    }
    assert!(
        r.run_dir.contains("dt-1e300"),
        "the value stays readable: {}",
        r.run_dir
    );
}

/// Names past the cap end in a hash of the whole: distinct, stable.
#[test]
fn long_folder_names_stay_distinct() {
    use surgbench_comparisons::batch::folder_name;
    let a = format!("dt={}", "1".repeat(300));
    let b = format!("dt={}2", "1".repeat(299));
    let (na, nb) = (folder_name(&a), folder_name(&b));
    assert!(na.len() <= 100 && nb.len() <= 100, "{na} / {nb}");
    assert_ne!(na, nb);
    assert_eq!(na, folder_name(&a), "deterministic");
    assert_eq!(
        folder_name("segments=10;dt=0.001"),
        "segments-10_dt-0.001",
        "short names unchanged"
    );
}

/// The Truth Cube with one measured bead at 1e308 mm: the model's state is
/// finite, its error against the data is not.
#[test]
fn a_non_finite_error_is_a_failed_run_not_ok() {
    let tmp = tempfile::tempdir().unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/phantom/truth-cube/truth-cube-uniaxial.csv");
    let text = std::fs::read_to_string(&src).unwrap();
    // Bead (1,1,1) at 12.5 % strain (strain_level 2): x2 = -31.04 mm.
    let row = "1,1,1,-29.69,-28.86,12.62,-30.33,-29.38,12.96,-31.04,";
    assert!(text.contains(row), "the data changed; update this test");
    let spoiled = text.replacen(row, "1,1,1,-29.69,-28.86,12.62,-30.33,-29.38,12.96,1e308,", 1);
    let data = tmp.path().join("datasets/phantom/truth-cube");
    std::fs::create_dir_all(&data).unwrap();
    std::fs::write(data.join("truth-cube-uniaxial.csv"), spoiled).unwrap();
    let out = tmp.path().join("one");
    let mut cmd = surgbench();
    cmd.args(["run-one", "--scenario", "truth-cube", "--model", "fem", "--quiet"])
        .args([
            "--param",
            "strain_level=2",
            "--fidelity",
            "mesh_level=1",
            "--fidelity",
            "integrator=quasi-static",
        ])
        .arg("--out")
        .arg(&out)
        .env("SURGBENCH_DATASETS", tmp.path().join("datasets"));
    let o = run(cmd, "run-one truth-cube");
    assert!(o.status.success(), "{}", stderr(&o));
    let s = RunSummary::read(&out.join("summary.json")).unwrap();
    assert_eq!(s.status, Status::Failed, "reason: {}", s.reason);
    assert!(
        s.reason.contains("not finite") && s.reason.contains("reference data"),
        "{}",
        s.reason
    );
}

#[test]
fn quick_validates_the_full_sweep() {
    let tmp = tempfile::tempdir().unwrap();
    let cmp = cantilever(
        "der",
        "sweep = { segments = [10], dt = [-1.0] }\nquick_sweep = { segments = [10] }",
    );
    let o = run_comparison(tmp.path(), &cmp, &["--quick"]);
    assert_usage_error(&o, &["dt"]);
    assert!(!tmp.path().join("report").exists(), "nothing written");
}

#[test]
fn a_binary_results_csv_is_a_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let bytes: Vec<u8> = (0..=255u8).cycle().take(600).map(|b| b.wrapping_mul(37)).collect();
    std::fs::write(tmp.path().join("results.csv"), bytes).unwrap();
    let mut cmd = surgbench();
    cmd.arg("report").arg(tmp.path());
    let o = run(cmd, "surgbench report");
    assert_usage_error(&o, &["results.csv", "not UTF-8"]);
    assert!(!stderr(&o).contains("Utf8"), "{}", stderr(&o));
}

#[test]
fn a_repeated_param_or_fidelity_is_a_usage_error() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("one");
    for (flag, a, b, key) in [
        ("--param", "length=0.1", "length=0.2", "`length` is given twice"),
        ("--fidelity", "segments=10", "segments=20", "`segments` is given twice"),
    ] {
        let mut cmd = surgbench();
        cmd.args(["run-one", "--scenario", "cantilever-gravity", "--model", "der"])
            .args([flag, a, flag, b, "--out"])
            .arg(&out);
        assert_usage_error(&run(cmd, "run-one"), &[key]);
        assert!(!out.exists(), "nothing written");
    }
}

#[test]
fn a_sweep_listing_a_value_twice_is_a_usage_error() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run_comparison(
        tmp.path(),
        &cantilever("der", "sweep = { segments = [10, 20, 10] }"),
        &[],
    );
    assert_usage_error(&o, &["`segments`", "10 twice"]);
    // The same run reached twice through two entries of one scenario.
    let twice = format!(
        "{}[[scenario]]\nid = \"cantilever-gravity\"\nsweep = {{ segments = [10] }}\n",
        cantilever("der", "sweep = { segments = [10] }")
    );
    let o = run_comparison(tmp.path(), &twice, &[]);
    assert_usage_error(&o, &["one run twice", "segments-10"]);
    assert!(!tmp.path().join("report").exists(), "nothing written");
}

/// A hanging model in a `[[haptic]]` loop of 1 s: with `--timeout 3` it is
/// killed at 3 s (it used to wait out `2 x duration + 120 s`).
#[test]
fn timeout_bounds_haptic_jobs() {
    let tmp = tempfile::tempdir().unwrap();
    let cmp = format!(
        "{}[[haptic]]\nmodel = \"faulty-hang\"\nscenario = \"cantilever-gravity\"\nduration_s = 1\n",
        cantilever("der", "sweep = { segments = [10] }")
    );
    let o = run_comparison(tmp.path(), &cmp, &["--timeout", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let h = surgbench_reports::read_haptic_csv(&tmp.path().join("report/haptic.csv")).unwrap();
    assert_eq!(h.len(), 1);
    assert_eq!(h[0].status, Status::Timeout, "{}", h[0].reason);
    assert!(h[0].reason.contains("killed after 3."), "{}", h[0].reason);
}

/// A folder outside any checkout: comparisons, datasets and the default
/// report are looked for and written there, never in the build tree.
#[test]
fn paths_resolve_from_the_current_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let here = tmp.path().join("work");
    std::fs::create_dir_all(&here).unwrap();
    let build_tree = env!("CARGO_MANIFEST_DIR");
    let in_here = |args: &[&str]| {
        let mut cmd = surgbench();
        cmd.args(args)
            .current_dir(&here)
            .env_remove("SURGBENCH_ROOT")
            .env_remove("SURGBENCH_DATASETS");
        run(cmd, "surgbench outside the checkout")
    };

    let o = in_here(&["run", "--quick"]);
    assert_usage_error(&o, &[&here.join("comparisons/standard.toml").display().to_string()]);
    assert!(!stderr(&o).contains(build_tree), "{}", stderr(&o));

    let o = in_here(&["run-one", "--scenario", "truth-cube", "--model", "fem", "--out", "one"]);
    assert_usage_error(&o, &[&here.join("datasets").display().to_string()]);
    assert!(!stderr(&o).contains(build_tree), "{}", stderr(&o));

    std::fs::create_dir_all(here.join("comparisons")).unwrap();
    std::fs::write(
        here.join("comparisons/mine.toml"),
        cantilever("der", "sweep = { segments = [10] }"),
    )
    .unwrap();
    std::fs::create_dir_all(here.join("sub")).unwrap();
    let mut cmd = surgbench();
    cmd.args(["run", "mine", "--quiet"])
        .current_dir(here.join("sub"))
        .env_remove("SURGBENCH_ROOT");
    let o = run(cmd, "surgbench run mine");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        here.join("reports/out/latest/results.csv").is_file(),
        "the default report goes to the project found from the current directory"
    );
}

/// DER on the cantilever at E = 1e20 Pa stops "settled" after 16 steps
/// (10 until the settle rule became relative to the deflection as well,
/// `v t <= 1e-3 |u|`, issue 20). The settling is not false: run on for 700
/// steps (settle_tol = 1e-300, never settles) the tip moves by under 0.2 %
/// of its deflection. The
/// 5.5 % tip error it used to report was the elastica reference's rounding
/// at a deflection of 1e-13 m (x summed over 4000 RK4 steps); with the
/// foreshortening integrated instead, the error is what the model makes.
#[test]
fn a_very_stiff_rod_settles_where_it_stays() {
    let tmp = tempfile::tempdir().unwrap();
    let summary = |name: &str, extra: &[&str]| -> RunSummary {
        let out: PathBuf = tmp.path().join(name);
        let mut cmd = surgbench();
        cmd.args([
            "run-one",
            "--scenario",
            "cantilever-gravity",
            "--model",
            "der",
            "--quiet",
        ])
        .args(["--param", "youngs_modulus=1e20"])
        .args(extra)
        .arg("--out")
        .arg(&out);
        let o = run(cmd, "run-one cantilever-gravity");
        assert!(o.status.success(), "{}", stderr(&o));
        RunSummary::read(&out.join("summary.json")).unwrap()
    };
    let settled = summary("settled", &[]);
    let on = summary("on", &["--param", "settle_tol=1e-300", "--param", "duration=1e-4"]);
    assert_eq!((settled.end.as_str(), settled.steps), ("settled", Some(16.0)));
    assert_eq!(on.end.as_str(), "time-limit");
    assert!(on.steps.unwrap() > 600.0, "{:?}", on.steps);
    let (a, b) = (settled.tip.unwrap()[2], on.tip.unwrap()[2]);
    assert!(
        b < 0.0 && (a - b).abs() <= 2e-3 * b.abs(),
        "tip z {a:e} m settled vs {b:e} m run on"
    );
    let tip_error = |s: &RunSummary| s.errors["tip_error_rel"];
    eprintln!(
        "tip_error_rel settled {:e}, run on {:e}",
        tip_error(&settled),
        tip_error(&on)
    );
    assert!(
        // Measured: 6.25e-4 run on (DER's O(h^2) error at 40 segments,
        // 1/40^2) and 6.7e-4 settled at step 16 (2.29e-3 at step 10 under
        // the absolute rule alone: 0.17 % of the deflection left, the
        // bound the tip test above allows).
        (tip_error(&settled) - tip_error(&on)).abs() < 2e-3 && tip_error(&on) < 1e-3,
        "the error is small either way: {} vs {}",
        tip_error(&settled),
        tip_error(&on)
    );
}

/// Every shipped comparison expands, full and quick, into valid runs with
/// a folder each (what `run` and `run --quick` now check first).
#[test]
fn shipped_comparisons_validate_in_full() {
    use surgbench_comparisons::batch::run_dir_of;
    use surgbench_comparisons::comparison::Comparison;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("comparisons");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let p = e.path();
        if p.extension().is_none_or(|x| x != "toml") || p.ends_with("Cargo.toml") {
            continue;
        }
        let c = Comparison::load(&p).unwrap();
        for quick in [false, true] {
            let start = std::time::Instant::now();
            let jobs = c.jobs(quick, None).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            c.haptic_jobs(quick, None).unwrap();
            let mut seen = std::collections::BTreeSet::new();
            for j in jobs.iter().filter(|j| j.unsupported.is_none()) {
                assert!(seen.insert(run_dir_of(j)), "{}: {:?} twice", p.display(), run_dir_of(j));
            }
            eprintln!(
                "{} quick={quick}: {} jobs validated in {:?}",
                p.display(),
                jobs.len(),
                start.elapsed()
            );
        }
        n += 1;
    }
    assert!(n >= 4, "found {n} comparisons");
}

/// A comparison's `repeat_budget_s` reaches each run (`run-one
/// --repeat-budget`): with a budget no run can stay under, a run repeats
/// once, not `repeats` times, and its summary.json says so.
#[test]
fn a_comparisons_repeat_budget_reaches_its_runs() {
    for (budget, expected) in [("", 3), ("repeat_budget_s = 1e-9\n", 1)] {
        let tmp = tempfile::tempdir().unwrap();
        let text = format!(
            "repeats = 3\n{budget}{}",
            cantilever("der", "sweep = { segments = [10] }")
        );
        let o = run_comparison(tmp.path(), &text, &[]);
        assert!(o.status.success(), "{}", stderr(&o));
        let row = &rows(tmp.path())[0];
        let s = RunSummary::read(&tmp.path().join("report").join(&row.run_dir).join("summary.json")).unwrap();
        assert_eq!(s.repeats, expected, "{budget}");
    }
}
