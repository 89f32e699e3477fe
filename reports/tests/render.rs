//! `render` on a small synthetic comparison: two scenarios, ok, unstable,
//! failed and unsupported runs. Checks the files, what the pages say, and
//! that rendering is deterministic and reproducible from `results.csv`.

mod common;

use std::fs;
use std::path::Path;

use surgbench_reports::{Status, read_results_csv, render, render_dir, write_results_csv, write_run_info};

fn read(p: &Path) -> String {
    fs::read_to_string(p).unwrap_or_else(|e| panic!("reading {}: {e}", p.display()))
}

/// Renders the synthetic set into a fresh folder; set `SURGBENCH_KEEP_REPORT=dir`
/// to also keep a copy for looking at the pictures.
fn rendered() -> (tempfile::TempDir, Vec<std::path::PathBuf>) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows = common::rows();
    write_results_csv(&dir.join("results.csv"), &rows).unwrap();
    write_run_info(&dir.join("summary.json"), &common::info()).unwrap();
    common::write_series(dir, &rows);
    let files = render(dir, &rows, &common::info()).unwrap();
    if let Ok(keep) = std::env::var("SURGBENCH_KEEP_REPORT") {
        let keep = Path::new(&keep);
        fs::create_dir_all(keep.join("plots")).unwrap();
        for f in &files {
            let rel = f.strip_prefix(dir).unwrap();
            fs::copy(f, keep.join(rel)).unwrap();
        }
    }
    (tmp, files)
}

#[test]
fn writes_every_expected_file_non_empty() {
    let (tmp, files) = rendered();
    let dir = tmp.path();
    let expected = [
        "plots/cantilever-gravity-pareto",
        "plots/cantilever-gravity-convergence",
        "plots/cantilever-gravity-error-time",
        "plots/cantilever-gravity-stability",
        "plots/lame-tube--pressure_2000-pareto",
        "plots/lame-tube--pressure_2000-convergence",
    ];
    for stem in expected {
        for ext in ["svg", "png"] {
            let p = dir.join(format!("{stem}.{ext}"));
            assert!(files.contains(&p), "{} not in the returned list {files:?}", p.display());
            let bytes = fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert!(bytes.len() > 1000, "{} has only {} bytes", p.display(), bytes.len());
            if ext == "png" {
                assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{} is not a PNG", p.display());
            } else {
                let s = String::from_utf8_lossy(&bytes);
                assert!(
                    s.contains("<svg") && s.contains("</svg>"),
                    "{} is not an SVG",
                    p.display()
                );
            }
        }
    }
    // lame-tube varies only the mesh level (one dt): no stability map; fem has no run_dir: no time series.
    for stem in [
        "lame-tube--pressure_2000-stability",
        "lame-tube--pressure_2000-error-time",
    ] {
        assert!(
            !dir.join(format!("plots/{stem}.svg")).exists(),
            "{stem} should not exist"
        );
    }
    for page in ["report.md", "index.html"] {
        assert!(files.contains(&dir.join(page)), "{page} not returned");
        assert!(read(&dir.join(page)).len() > 1000, "{page} is short");
    }
    assert_eq!(files.len(), 2 * expected.len() + 2, "returned: {files:?}");
}

#[test]
fn pages_show_reasons_orders_and_header() {
    let (tmp, _) = rendered();
    let md = read(&tmp.path().join("report.md"));
    let html = read(&tmp.path().join("index.html"));
    // Reasons appear where the numbers would be (markdown escapes `_`, HTML escapes quotes).
    for reason in [
        common::UNSUPPORTED_REASON,
        common::UNSTABLE_REASON,
        common::TISSUE_UNSUPPORTED,
    ] {
        assert!(md.contains(reason), "report.md lacks reason {reason:?}");
        assert!(html.contains(reason), "index.html lacks reason {reason:?}");
    }
    assert!(
        html.contains("build failed: segments=5 is below the minimum of 8, &quot;rod too coarse&quot;"),
        "index.html lacks the escaped failure reason"
    );
    // Orders: der exactly 2 in segments, pbd-rod exactly 1, fem 2 in cells
    // per side: exact power laws, so the confidence interval is 0 and R^2 1.
    let orders: Vec<&str> = md
        .lines()
        .filter(|l| l.contains(": p = ") || l.contains("no order"))
        .collect();
    for needle in [
        "der: p = 2.00 ± 0.00 (95 %), R² = 1.0000 vs segments",
        "pbd-rod: p = 1.00 ± 0.00 (95 %), R² = 1.0000 vs segments",
        "fem: p = 2.00 ± 0.00 (95 %), R² = 1.0000 vs cells per side (2^mesh\\_level)",
    ] {
        assert!(
            md.contains(needle),
            "report.md lacks {needle:?}; its orders: {orders:#?}"
        );
    }
    assert!(
        html.contains("fem: p = 2.00 ± 0.00 (95 %), R² = 1.0000 vs cells per side (2^mesh_level)"),
        "index.html lacks the fem order"
    );
    // Header and the quick-run warning.
    for needle in ["0123abcd", "test machine", "2 / 1", "quick run"] {
        assert!(md.contains(needle), "report.md lacks {needle:?}");
    }
    // Best values bold: der's finest ok error 0.3/80^2 = 4.69e-5.
    assert!(
        md.contains("**4.69e-5**"),
        "report.md does not bold the lowest error 4.69e-5"
    );
    // Images embedded by relative path.
    assert!(
        html.contains("<img src=\"plots/cantilever-gravity-pareto.svg\""),
        "no pareto img"
    );
    assert!(
        md.contains("](plots/cantilever-gravity-convergence.svg)"),
        "no convergence image in md"
    );
    // What the plots leave out is said: the run without a time series, unsupported runs.
    assert!(md.contains("unsupported runs are not drawn"), "stability note missing");
    assert!(
        html.contains("<td class=\"warn\">unsupported</td>"),
        "unsupported status not flagged"
    );
}

#[test]
fn missing_time_series_is_noted_not_fatal() {
    let tmp = tempfile::tempdir().unwrap();
    let rows = common::rows();
    // No observables.csv written at all.
    let files = render(tmp.path(), &rows, &common::info()).unwrap();
    assert!(!tmp.path().join("plots/cantilever-gravity-error-time.svg").exists());
    assert!(files.iter().any(|f| f.ends_with("report.md")));
    let md = read(&tmp.path().join("report.md"));
    assert!(
        md.contains("Error over time: no curve for der segments=80;dt=0.0005"),
        "missing series not noted; report.md:\n{md}"
    );
}

#[test]
fn deterministic_and_reproducible_from_csv() {
    let (tmp, files) = rendered();
    let dir = tmp.path();
    let snapshot: Vec<(std::path::PathBuf, Vec<u8>)> =
        files.iter().map(|f| (f.clone(), fs::read(f).unwrap())).collect();
    // Re-render from the files alone (what `surgbench report DIR` does).
    let again = render_dir(dir).unwrap();
    assert_eq!(again, files, "a re-render writes a different set of files");
    for (f, bytes) in &snapshot {
        let now = fs::read(f).unwrap();
        assert!(
            now == *bytes,
            "{} differs after re-rendering from results.csv",
            f.display()
        );
    }
    assert_eq!(read_results_csv(&dir.join("results.csv")).unwrap(), common::rows());
}

#[test]
fn stale_plots_are_removed_and_empty_input_renders() {
    let (tmp, _) = rendered();
    let dir = tmp.path();
    let files = render(dir, &[], &Default::default()).unwrap();
    assert_eq!(files.len(), 2, "only the pages for no rows: {files:?}");
    let left: Vec<_> = fs::read_dir(dir.join("plots")).unwrap().collect();
    assert!(left.is_empty(), "stale plots left behind: {left:?}");
    assert!(read(&dir.join("report.md")).contains("0 runs"));
}

#[test]
fn long_names_and_colliding_stems_render() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rows = Vec::new();
    for params in [
        "length=0.3;youngs_modulus=5e10;radius=4.5e-4",
        "length=0.3 youngs_modulus=5e10 radius=4.5e-4",
    ] {
        for r in common::rows().into_iter().filter(|r| r.model == "der") {
            rows.push(surgbench_reports::ResultRow {
                scenario: "tortuous-coronary-multi-point-contact-long-name".into(),
                params: params.into(),
                fidelity: format!("{};iterations=10;extra_knob=abc", r.fidelity),
                ..r
            });
        }
    }
    let files = render(tmp.path(), &rows, &common::info()).unwrap();
    let stems: Vec<String> = files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "svg"))
        .map(|f| f.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    // Two parameter sets whose slugs collide: two distinct, bounded file names.
    let pareto: Vec<&String> = stems.iter().filter(|s| s.ends_with("-pareto")).collect();
    assert_eq!(pareto.len(), 2, "{stems:?}");
    assert_ne!(pareto[0], pareto[1]);
    for s in &pareto {
        assert!(
            s.starts_with("tortuous-coronary-multi-point") && s.len() <= 100,
            "stem {s:?}"
        );
    }
    if let Ok(keep) = std::env::var("SURGBENCH_KEEP_REPORT") {
        let keep = Path::new(&keep).join("long");
        fs::create_dir_all(&keep).unwrap();
        for f in &files {
            fs::copy(f, keep.join(f.file_name().unwrap())).unwrap();
        }
    }
}

/// Static scenes compare models by wall time to the solution when every ok
/// run has one (models settle with different dt and step counts); rows from
/// older results.csv files without it keep ms/step.
#[test]
fn static_speed_axis_is_time_to_solution() {
    let axis_of = |with_solve: bool| {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let mut rows = common::rows();
        for r in rows.iter_mut() {
            r.solve_wall_s = with_solve.then(|| r.steps.unwrap_or(1.0) * r.ms_per_step_median.unwrap_or(1.0) / 1e3);
        }
        write_results_csv(&dir.join("results.csv"), &rows).unwrap();
        write_run_info(&dir.join("summary.json"), &common::info()).unwrap();
        common::write_series(dir, &rows);
        render(dir, &rows, &common::info()).unwrap();
        read(&dir.join("plots/cantilever-gravity-pareto.svg"))
    };
    let with = axis_of(true);
    assert!(
        with.contains("wall time to solution"),
        "static group with solve_wall_s should plot time to solution"
    );
    let without = axis_of(false);
    assert!(
        without.contains("median wall time per step"),
        "rows without solve_wall_s should keep ms/step"
    );
}

/// An ok run of `model` at `n` segments with settings `fidelity`, scored
/// `tip_error_rel = err`, without a run folder (from the synthetic der row).
fn segment_run(model: &str, n: f64, fidelity: String, err: f64) -> surgbench_reports::ResultRow {
    let mut r = common::rows()
        .into_iter()
        .find(|r| r.model == "der" && r.status == Status::Ok)
        .unwrap();
    r.model = model.into();
    r.segments = Some(n);
    r.fidelity = fidelity;
    r.run_dir = String::new();
    r.metrics.insert("tip_error_rel".into(), err);
    r
}

/// Issue 22, item 4: two points and non-monotone errors give "no order"
/// with the reason, never a slope (the chain-mail's 5.29 -> 0.00145 ->
/// 0.862 had been printed as p = 1.31).
#[test]
fn convergence_without_an_order_says_why() {
    let mut rows = Vec::new();
    for (model, pts) in [
        ("chainmail", vec![(10.0, 5.29), (20.0, 0.00145), (40.0, 0.862)]),
        ("pbd-rod", vec![(10.0, 1e-2), (20.0, 2.5e-3)]),
    ] {
        for (n, e) in pts {
            rows.push(segment_run(model, n, format!("segments={n}"), e));
        }
    }
    let tmp = tempfile::tempdir().unwrap();
    render(tmp.path(), &rows, &common::info()).unwrap();
    let md = read(&tmp.path().join("report.md"));
    for needle in [
        "chainmail: no order vs segments: the error does not fall steadily with refinement (5.29 → 0.00145 → 0.862)",
        "pbd-rod: no order vs segments: 2 distinct value(s) with an ok, positive error; a fit needs 3",
    ] {
        assert!(md.contains(needle), "report.md lacks {needle:?}");
    }
    assert!(!md.contains(": p = "), "no slope is printed for these");
}

/// A knob the model sets per resolution (the meshless seed variant's dt,
/// chosen per mesh level by a Courant rule) joins the runs of one variant
/// into one curve with an order, while a knob swept at fixed resolution
/// (two dt values at every segment count) still splits the curves.
#[test]
fn a_knob_that_follows_the_refinement_does_not_split_a_curve() {
    let mut rows = Vec::new();
    let mut push = |model: &str, n: f64, fid: String, e: f64| rows.push(segment_run(model, n, fid, e));
    for n in [10.0, 20.0, 40.0] {
        // Order 2 for the harness variant at a fixed dt, order 1 for the
        // seed variant whose dt halves with every refinement.
        push(
            "meshless",
            n,
            format!("segments={n};dt=0.001;variant=harness"),
            1.0 / (n * n),
        );
        push(
            "meshless",
            n,
            format!("segments={n};dt={};variant=seed", 0.1 / n),
            1.0 / n,
        );
        for dt in [1e-3, 5e-4] {
            push("pbd-rod", n, format!("segments={n};dt={dt}"), dt / (n * n));
        }
    }
    let tmp = tempfile::tempdir().unwrap();
    render(tmp.path(), &rows, &common::info()).unwrap();
    let md = read(&tmp.path().join("report.md"));
    let orders: Vec<&str> = md.lines().filter(|l| l.contains(": p = ")).collect();
    let has = |model: &str, with: &str, p: &str| {
        orders
            .iter()
            .any(|l| l.contains(&format!("{model}: p = {p}")) && l.contains("3 ok runs") && l.contains(with))
    };
    // Exact power laws: the least-squares order is the exponent to the printed digits.
    assert!(has("meshless", "variant=harness", "2.00"), "{orders:#?}");
    assert!(has("meshless", "variant=seed", "1.00"), "{orders:#?}");
    assert!(has("pbd-rod", "dt=0.001", "2.00"), "{orders:#?}");
    assert!(has("pbd-rod", "dt=0.0005", "2.00"), "{orders:#?}");
    assert_eq!(orders.len(), 4, "one order per curve: {orders:#?}");
    assert!(
        md.contains("meshless: dt takes one value per segments among runs otherwise alike"),
        "the merge is explained"
    );
    assert!(
        !md.contains("pbd-rod: dt takes one value"),
        "a swept dt is not a follower"
    );
}

/// An ok tissue-or-coupled run of `model` on `scenario` at mesh level
/// `level`, its folder `runs/<dir>`, built from the synthetic der row.
fn mesh_run(scenario: &str, family: &str, model: &str, level: u32, dir: &str) -> surgbench_reports::ResultRow {
    let mut r = common::rows()
        .into_iter()
        .find(|r| r.model == "der" && r.status == Status::Ok)
        .unwrap();
    r.scenario = scenario.into();
    r.family = family.into();
    r.model = model.into();
    r.segments = None;
    r.mesh_level = Some(level.into());
    r.fidelity = format!("mesh_level={level}");
    r.run_dir = format!("runs/{dir}");
    r
}

/// Issue 22, item 5: a scene scored at measured points (the Truth Cube's
/// beads) gets a point-error figure from each best ok run's `markers.csv`:
/// the layer profile and a map classed by the scene's accuracy target.
#[test]
fn measured_points_get_a_layer_profile_and_a_map() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut rows = Vec::new();
    for (model, scale) in [("fem", 1.0), ("meshless", 2.0)] {
        let mut r = mesh_run("truth-cube", "tissue", model, 1, model);
        r.primary_error = "rms_bead_error_m".into();
        r.metrics = [("rms_bead_error_m".to_string(), 1e-3 * scale)].into();
        // A 3 x 3 x 3 lattice, 10 mm apart, each point off by scale x its
        // layer's height in mm (1, 2, 3 mm for fem).
        let mut text = format!("{}\n", surgbench_reports::MARKER_COLUMNS.join(","));
        for i in 0..27 {
            let p = [(i % 3) as f64 * 0.01, (i / 3 % 3) as f64 * 0.01, (i / 9) as f64 * 0.01];
            let e = scale * 1e-3 * (i / 9 + 1) as f64;
            text.push_str(&format!(
                "{},{},{},{},{},{},{},{},{}\n",
                p[0],
                p[1],
                p[2],
                p[0] + e,
                p[1],
                p[2],
                p[0],
                p[1],
                p[2]
            ));
        }
        fs::create_dir_all(dir.join(&r.run_dir)).unwrap();
        fs::write(dir.join(&r.run_dir).join("markers.csv"), text).unwrap();
        rows.push(r);
    }
    let mut info = common::info();
    info.targets.insert(
        "truth-cube".into(),
        surgbench_reports::AccuracyTarget {
            metric: "rms_bead_error_m".into(),
            value: 1e-3,
            why: "test".into(),
        },
    );
    render(dir, &rows, &info).unwrap();
    let svg = read(&dir.join("plots/truth-cube-points.svg"));
    for label in [
        "fem: central slice, 9 points",
        "meshless: central slice, 9 points",
        "error ≤ 0.5 mm",
        "0.5 to 1 mm",
        // The SVG escapes the ">".
        "error &gt; 4 mm",
    ] {
        assert!(svg.contains(label), "points plot lacks {label:?}");
    }
    let md = read(&dir.join("report.md"));
    assert!(
        md.contains("classes of the accuracy target (rms\\_bead\\_error\\_m = 1 mm)"),
        "the note names the class unit"
    );
    // The measured points never moved: their motion is zero in every layer.
    assert!(md.contains("moves the layers by 0, 0, 0 mm RMS"), "motion for scale");
    // A malformed markers.csv is named in a note, not a failed render.
    fs::write(dir.join("runs/fem/markers.csv"), "x0,y0\n1,2\n").unwrap();
    render(dir, &rows, &info).unwrap();
    assert!(read(&dir.join("report.md")).contains("Point errors: none for fem"));
}

/// A scene scored on a tip path's shape gets the path of every ok run in
/// its bend plane with the run's fitted arc, from `tip_path.csv`.
#[test]
fn tip_paths_are_drawn_with_their_fitted_arcs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut rows = Vec::new();
    for level in [0, 1] {
        let r = mesh_run("needle-bevel", "coupled", "needle", level, &format!("level-{level}"));
        let mut text = String::from("x,s,arc_s\n");
        for k in 0..=30 {
            let x = k as f64 * 5e-4;
            let s = x * x * (level + 1) as f64;
            // The arc is fitted from 2 mm on: empty before.
            let fit = if x >= 2e-3 {
                format!("{}", 0.99 * s)
            } else {
                String::new()
            };
            text.push_str(&format!("{x},{s},{fit}\n"));
        }
        fs::create_dir_all(dir.join(&r.run_dir)).unwrap();
        fs::write(dir.join(&r.run_dir).join("tip_path.csv"), text).unwrap();
        rows.push(r);
    }
    render(dir, &rows, &common::info()).unwrap();
    let svg = read(&dir.join("plots/needle-bevel-tip-path.svg"));
    for label in ["needle mesh_level=0", "needle mesh_level=1", "best-fit arc of each run"] {
        assert!(svg.contains(label), "tip path plot lacks {label:?}");
    }
    assert!(read(&dir.join("report.md")).contains("tip path of 2 ok run(s) in the bend plane"));
    // A malformed file is named in a note; the other run is still drawn.
    fs::write(dir.join("runs/level-0/tip_path.csv"), "x,s\n1,2\n").unwrap();
    render(dir, &rows, &common::info()).unwrap();
    let md = read(&dir.join("report.md"));
    assert!(md.contains("Tip path: none for needle mesh\\_level=0"), "note");
    assert!(md.contains("tip path of 1 ok run(s)"));
}

/// Issue 22, item 2: the summary shows each model by its best ok run (most
/// accurate, then fastest), names its settings and counts the runs that
/// were not ok; an unstable finest run is no longer the model's face.
#[test]
fn summary_shows_the_best_ok_run_and_counts_the_rest() {
    let base = common::rows()
        .into_iter()
        .find(|r| r.model == "der" && r.status == Status::Ok)
        .unwrap();
    let run = |model: &str, fid: &str, seg: f64, status: Status, err: f64, ms: f64| {
        let mut r = base.clone();
        r.model = model.into();
        r.fidelity = fid.into();
        r.segments = Some(seg);
        r.run_dir = String::new();
        r.status = status;
        r.reason = if status == Status::Ok {
            String::new()
        } else {
            "energy grew".into()
        };
        r.ms_per_step_median = Some(ms);
        r.metrics.insert("tip_error_rel".into(), err);
        r
    };
    let rows = vec![
        run("pbd-rod", "segments=10", 10.0, Status::Ok, 1e-2, 0.1),
        run("pbd-rod", "segments=20;solver=gs", 20.0, Status::Ok, 2e-3, 0.5),
        run("pbd-rod", "segments=20;solver=direct", 20.0, Status::Ok, 2e-3, 0.2),
        run(
            "pbd-rod",
            "segments=40;dt=0.006418358500335569",
            40.0,
            Status::Unstable,
            9.0,
            0.3,
        ),
        run("chainmail", "segments=10", 10.0, Status::Unstable, 9.0, 0.1),
        run("chainmail", "segments=20", 20.0, Status::Unstable, 9.0, 0.1),
    ];
    let tmp = tempfile::tempdir().unwrap();
    render(tmp.path(), &rows, &common::info()).unwrap();
    let md = read(&tmp.path().join("report.md"));
    for needle in [
        "0.002 at 0.2 ms/step (segments=20;solver=direct; also 1 unstable)",
        "no ok run (2 unstable); finest: unstable: energy grew (segments=20)",
        // The scenario table prints the fidelity to 4 significant digits.
        "segments=40;dt=0.006418 |",
    ] {
        assert!(md.contains(needle), "report.md lacks {needle:?}:\n{md}");
    }
}

/// Rod models' (and coupled models') final shapes are drawn in side and
/// top view, against the reference centreline their runs wrote; a run
/// folder without its final state gives a note, not a failure.
#[test]
fn rod_centrelines_are_drawn_against_the_reference() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows: Vec<_> = common::rows()
        .into_iter()
        .filter(|r| r.scenario == "cantilever-gravity")
        .collect();
    for r in rows.iter().filter(|r| r.status == Status::Ok) {
        let d = dir.join(&r.run_dir);
        fs::create_dir_all(&d).unwrap();
        let mut state = String::from("body,node,x0,y0,z0,x,y,z\n");
        let mut reference = String::from("x,y,z\n");
        for k in 0..=10 {
            let x = 0.01 * k as f64;
            state.push_str(&format!("0,{k},{x},0,0,{x},0,{}\n", -0.1 * x * x));
            reference.push_str(&format!("{x},0,{}\n", -0.11 * x * x));
        }
        fs::write(d.join("final_state.csv"), state).unwrap();
        fs::write(d.join("reference_centreline.csv"), reference).unwrap();
    }
    render(dir, &rows, &common::info()).unwrap();
    assert!(dir.join("plots/cantilever-gravity-centreline.svg").is_file());
    let md = read(&dir.join("report.md"));
    // Planar shapes: the side view only.
    assert!(
        md.contains("final rod centreline in side view (x–z), with the reference shape"),
        "{md}"
    );
    // A coupled model's first body is its needle or catheter: drawn too;
    // a tissue model's first body is no rod: not drawn.
    for (family, drawn) in [("coupled", true), ("tissue", false)] {
        let other: Vec<_> = rows
            .iter()
            .cloned()
            .map(|mut r| {
                r.family = family.into();
                r
            })
            .collect();
        render(dir, &other, &common::info()).unwrap();
        assert_eq!(
            dir.join("plots/cantilever-gravity-centreline.svg").is_file(),
            drawn,
            "{family}"
        );
    }
    // Without the final states: no plot, and the page says why per model.
    for r in rows.iter().filter(|r| r.status == Status::Ok) {
        fs::remove_file(dir.join(&r.run_dir).join("final_state.csv")).unwrap();
    }
    render(dir, &rows, &common::info()).unwrap();
    assert!(!dir.join("plots/cantilever-gravity-centreline.svg").exists());
    assert!(read(&dir.join("report.md")).contains("Centreline: no shape for der"));
}

/// A run whose series records the scored force and its reference gets the
/// force-over-time plot; runs without those columns get none.
#[test]
fn force_over_time_is_drawn_where_the_series_has_a_reference_force() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows = common::rows();
    common::write_series(dir, &rows);
    render(dir, &rows, &common::info()).unwrap();
    assert!(!dir.join("plots/cantilever-gravity-force-time.svg").exists());
    for r in rows.iter().filter(|r| r.status == Status::Ok && !r.run_dir.is_empty()) {
        let d = dir.join(&r.run_dir);
        fs::create_dir_all(&d).unwrap();
        let mut text = String::from("t,error,force,ref_force\n");
        for i in 0..=50 {
            let t = i as f64 * 0.01;
            text.push_str(&format!("{t},1e-3,{},{}\n", 2.0 * t * 1.01, 2.0 * t));
        }
        fs::write(d.join("observables.csv"), text).unwrap();
    }
    render(dir, &rows, &common::info()).unwrap();
    assert!(dir.join("plots/cantilever-gravity-force-time.svg").is_file());
    assert!(read(&dir.join("report.md")).contains("best ok run is scored on, over simulated time"));
    // No depth column: no force-depth plot.
    assert!(!dir.join("plots/cantilever-gravity-force-depth.svg").exists());
}

/// A run whose series also records the indenter's depth gets the
/// force-against-depth plot beside the one over time; its page text names
/// the depth.
#[test]
fn force_against_depth_is_drawn_where_the_series_has_a_depth() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows = common::rows();
    common::write_series(dir, &rows);
    for r in rows.iter().filter(|r| r.status == Status::Ok && !r.run_dir.is_empty()) {
        let d = dir.join(&r.run_dir);
        fs::create_dir_all(&d).unwrap();
        // A Hertz-like curve F = d^(3/2) sampled at a static solve's two
        // load increments (depth empty before the ramp: not plotted).
        let text = "t,error,force,ref_force,depth\n0,,,,\n0.125,1e-3,3.6e-4,3.5e-4,5e-3\n0.25,1e-3,1.02e-3,1e-3,1e-2\n";
        fs::write(d.join("observables.csv"), text).unwrap();
    }
    render(dir, &rows, &common::info()).unwrap();
    assert!(dir.join("plots/cantilever-gravity-force-time.svg").is_file());
    assert!(dir.join("plots/cantilever-gravity-force-depth.svg").is_file());
    assert!(read(&dir.join("report.md")).contains("against the indenter's depth"));
}

/// A model whose settings rest on a fitted constant is named in the run
/// table with what was fitted; a report without one has no such row.
#[test]
fn fitted_constants_are_stated_in_the_run_table() {
    let tmp = tempfile::tempdir().unwrap();
    let rows = common::rows();
    let mut info = common::info();
    render(tmp.path(), &rows, &info).unwrap();
    assert!(!read(&tmp.path().join("index.html")).contains("fitted, not derived"));
    info.fitted.insert(
        "chainmail".into(),
        "C = 1214.297 fitted on a calibration cantilever".into(),
    );
    render(tmp.path(), &rows, &info).unwrap();
    let html = read(&tmp.path().join("index.html"));
    assert!(html.contains("fitted, not derived"), "no fitted row");
    assert!(html.contains("chainmail: C = 1214.297 fitted on a calibration cantilever"));
}

/// A needle run's diagnostics fill the seed's Table 3 (LCP trials) and
/// Table 2 (frame time by phase) under its scenario, its cycle metrics the
/// mesh table, a dash where a run
/// lacks a column (remesh without `coupling=remesh`); runs without them
/// get neither table.
#[test]
fn needle_diagnostics_fill_the_seeds_tables_2_and_3() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rows = common::rows();
    render(tmp.path(), &rows, &common::info()).unwrap();
    let md = read(&tmp.path().join("report.md"));
    assert!(!md.contains("the needle seed's Table 2") && !md.contains("the needle seed's Table 3"));
    assert!(!md.contains("Tissue mesh over the cycles"));
    let r = rows.iter_mut().find(|r| r.status == Status::Ok).expect("an ok row");
    for (k, v) in [
        ("diag_lcp_trials_mean", 1.04),
        ("diag_frame_ms_mean", 24.5),
        ("diag_lcp_ms_mean", 3.25),
        ("diag_tissue_ms_mean", 17.5),
        ("diag_needle_ms_mean", 0.625),
        ("dihedral_min_deg", 0.398),
        ("dihedral_max_deg", 120.0),
        ("withdrawals", 5.0),
        ("unrestored_withdrawals", 0.0),
    ] {
        r.metrics.insert(k.into(), v);
    }
    render(tmp.path(), &rows, &common::info()).unwrap();
    let md = read(&tmp.path().join("report.md"));
    assert!(
        md.contains("Frame time by phase (the needle seed's Table 2)"),
        "no Table 2"
    );
    assert!(
        md.contains("Friction-state LCP per run (the needle seed's Table 3)"),
        "no Table 3"
    );
    let cycles = &md[md.find("Tissue mesh over the cycles").expect("no cycles table")..];
    let row = cycles
        .lines()
        .find(|l| l.contains("0.398"))
        .expect("the run's cycles row");
    assert!(row.contains("| 120 | 5 | 0 |"), "{row}");
    let table2 = &md[md.find("Frame time by phase").unwrap()..];
    let row = table2
        .lines()
        .find(|l| l.contains("24.5"))
        .expect("the run's row in Table 2");
    for cell in ["24.5", "3.25", "17.5", "0.625", "—"] {
        assert!(row.contains(cell), "{cell} missing from {row}");
    }
}

#[test]
fn a_series_without_errors_is_named_relative_to_the_report() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows = common::rows();
    common::write_series(dir, &rows);
    // der's series with every error cell zero (a run whose reference is
    // absent writes no positive error).
    let der = rows
        .iter()
        .find(|r| r.model == "der" && r.segments == Some(80.0) && r.dt == Some(5e-4))
        .unwrap();
    let obs = dir.join(&der.run_dir).join("observables.csv");
    let zeroed: String = fs::read_to_string(&obs)
        .unwrap()
        .lines()
        .enumerate()
        .map(|(i, l)| match i {
            0 => format!("{l}\n"),
            _ => format!("{},0\n", &l[..l.rfind(',').unwrap()]),
        })
        .collect();
    fs::write(&obs, zeroed).unwrap();
    render(dir, &rows, &common::info()).unwrap();
    let md = read(&dir.join("report.md"));
    let note = md
        .lines()
        .find(|l| l.contains("has no positive error sample"))
        .unwrap_or_else(|| panic!("no note; report.md:\n{md}"));
    // The report may be rendered in a staging folder and renamed: its own
    // folder must not appear, the run's path relative to it must.
    assert!(!note.contains(&dir.display().to_string()), "{note}");
    assert!(note.contains("runs/cantilever-gravity/der/"), "{note}");
}
