//! `results.csv`, `summary.json` and `observables.csv`: round trips are exact,
//! malformed files give errors naming file, line and column, never a panic.

mod common;

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use surgbench_reports::{
    FIXED_COLUMNS, Outcome, ReportError, ResultRow, read_results_csv, read_run_info, read_series, write_results_csv,
    write_run_info,
};

#[test]
fn round_trip_is_exact_with_none_and_metric_columns() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    let mut rows = common::rows();
    // Awkward text and floats at the edges of the format.
    let mut odd = ResultRow {
        scenario: "a,b \"quoted\"".into(),
        model: "m".into(),
        segments: Some(0.1 + 0.2),
        dt: Some(5e-324),
        iterations: Some(1.7976931348623157e308),
        outcome: Outcome {
            reason: "line one\nline two, with comma".into(),
            steps: Some(-0.0),
            sim_time_s: Some(1e-5),
            ms_per_step_median: Some(123456789012345680.0),
            stable: Some(false),
            ..Outcome::default()
        },
        ..ResultRow::default()
    };
    odd.metrics.insert("only_here_m".into(), 2.5e-17);
    rows.push(odd);
    rows.push(ResultRow::default());
    write_results_csv(&path, &rows).unwrap();
    let back = read_results_csv(&path).unwrap();
    assert_eq!(back.len(), rows.len());
    for (i, (a, b)) in rows.iter().zip(&back).enumerate() {
        assert_eq!(a, b, "row {i} differs after the round trip");
    }
    // Bit-identical, not just equal (-0.0 == 0.0 would hide a sign loss).
    let last_numbers = |r: &ResultRow| {
        [
            r.segments,
            r.dt,
            r.iterations,
            r.steps,
            r.sim_time_s,
            r.ms_per_step_median,
        ]
        .map(|v| v.map(f64::to_bits))
    };
    let n = rows.len() - 2;
    assert_eq!(last_numbers(&rows[n]), last_numbers(&back[n]));

    // Header: fixed columns in order, then the union of metric names, sorted.
    let text = fs::read_to_string(&path).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert_eq!(&header[..FIXED_COLUMNS.len()], &FIXED_COLUMNS[..]);
    assert_eq!(
        &header[FIXED_COLUMNS.len()..],
        &[
            "displacement_error_l2_m",
            "only_here_m",
            "rms_node_error_m",
            "tip_error_rel"
        ]
    );
    // Absent metrics and None are empty cells, not zeros.
    let default_line = text.lines().last().unwrap();
    assert_eq!(
        default_line,
        ",".repeat(header.len() - 1),
        "default row: {default_line:?}"
    );
}

#[test]
fn nan_and_infinities_survive() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    let mut r = ResultRow {
        dt: Some(f64::INFINITY),
        ..ResultRow::default()
    };
    r.metrics.insert("e".into(), f64::NAN);
    r.metrics.insert("f".into(), f64::NEG_INFINITY);
    write_results_csv(&path, &[r]).unwrap();
    let back = read_results_csv(&path).unwrap();
    assert_eq!(back[0].dt, Some(f64::INFINITY));
    assert!(
        back[0].metrics["e"].is_nan(),
        "NaN read back as {:?}",
        back[0].metrics["e"]
    );
    assert_eq!(back[0].metrics["f"], f64::NEG_INFINITY);
}

#[test]
fn columns_are_found_by_name_and_extra_columns_are_metrics() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    // Reverse the column order of a written file.
    write_results_csv(&path, &common::rows()).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    let mut rd = csv::ReaderBuilder::new().from_reader(text.as_bytes());
    let header: Vec<String> = rd.headers().unwrap().iter().rev().map(String::from).collect();
    let mut w = csv::Writer::from_path(&path).unwrap();
    w.write_record(&header).unwrap();
    for rec in rd.records() {
        let rec = rec.unwrap();
        w.write_record(rec.iter().rev()).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    assert_eq!(read_results_csv(&path).unwrap(), common::rows());
}

/// Writes `lines` to a file and returns the read error's message.
fn error_of(lines: &[String]) -> (String, ReportError) {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("bad.csv");
    fs::write(&path, lines.join("\n") + "\n").unwrap();
    let err = read_results_csv(&path).expect_err("malformed file must not read");
    (err.to_string(), err)
}

fn good_file() -> Vec<String> {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    write_results_csv(&path, &common::rows()[..3]).unwrap();
    fs::read_to_string(&path).unwrap().lines().map(String::from).collect()
}

fn set_cell(line: &str, col: usize, value: &str) -> String {
    let mut cells: Vec<String> = line.split(',').map(String::from).collect();
    cells[col] = value.into();
    cells.join(",")
}

#[test]
fn missing_fixed_column_is_named() {
    let mut lines = good_file();
    // Drop the `dt` column from every line (the synthetic rows have no quoted commas).
    let col = FIXED_COLUMNS.iter().position(|c| *c == "dt").unwrap();
    for l in &mut lines {
        let mut cells: Vec<&str> = l.split(',').collect();
        cells.remove(col);
        *l = cells.join(",");
    }
    let (msg, err) = error_of(&lines);
    assert!(
        msg.contains("bad.csv") && msg.contains("line 1") && msg.contains("`dt`"),
        "{msg}"
    );
    assert!(matches!(err, ReportError::Parse { line: 1, .. }), "{err:?}");
}

#[test]
fn non_numeric_value_is_named_with_line_and_column() {
    let mut lines = good_file();
    let col = FIXED_COLUMNS.iter().position(|c| *c == "ms_per_step_median").unwrap();
    lines[2] = set_cell(&lines[2], col, "fast");
    let (msg, _) = error_of(&lines);
    assert!(
        msg.contains("bad.csv")
            && msg.contains("line 3")
            && msg.contains("`ms_per_step_median`")
            && msg.contains("\"fast\""),
        "{msg}"
    );
    // In a metric column too.
    let mut lines = good_file();
    let last = lines[1].split(',').count() - 1;
    lines[1] = set_cell(&lines[1], last, "1e-3m");
    let header_last = lines[0].rsplit(',').next().unwrap().to_string();
    let (msg, _) = error_of(&lines);
    assert!(
        msg.contains("line 2") && msg.contains(&format!("`{header_last}`")),
        "{msg}"
    );
    // And a bad boolean.
    let mut lines = good_file();
    let col = FIXED_COLUMNS.iter().position(|c| *c == "stable").unwrap();
    lines[3] = set_cell(&lines[3], col, "maybe");
    let (msg, _) = error_of(&lines);
    assert!(
        msg.contains("line 4") && msg.contains("`stable`") && msg.contains("maybe"),
        "{msg}"
    );
}

#[test]
fn ragged_row_is_named() {
    let mut lines = good_file();
    lines[2] = lines[2].rsplit_once(',').unwrap().0.to_string();
    let (msg, _) = error_of(&lines);
    assert!(msg.contains("line 3") && msg.contains("ragged"), "{msg}");
    let mut lines = good_file();
    lines[1].push_str(",extra");
    let (msg, _) = error_of(&lines);
    assert!(msg.contains("line 2") && msg.contains("ragged"), "{msg}");
}

#[test]
fn duplicate_and_empty_files_are_errors() {
    let mut lines = good_file();
    lines[0].push_str(",dt");
    for l in lines.iter_mut().skip(1) {
        l.push_str(",0.1");
    }
    let (msg, _) = error_of(&lines);
    assert!(msg.contains("line 1") && msg.contains("duplicate"), "{msg}");
    let (msg, _) = error_of(&[]);
    assert!(msg.contains("missing required column"), "{msg}");
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope.csv");
    let msg = read_results_csv(&missing).unwrap_err().to_string();
    assert!(msg.contains("nope.csv"), "{msg}");
}

#[test]
fn metric_named_like_a_fixed_column_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let mut r = ResultRow::default();
    r.metrics.insert("dt".into(), 1.0);
    let err = write_results_csv(&tmp.path().join("r.csv"), &[r]).unwrap_err();
    assert!(matches!(err, ReportError::Invalid { .. }), "{err:?}");
}

#[test]
fn run_info_round_trip_and_partial_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("summary.json");
    write_run_info(&path, &common::info()).unwrap();
    assert_eq!(read_run_info(&path).unwrap(), common::info());
    // The harness's summary may lack fields or carry more.
    fs::write(&path, r#"{"commit": "abc", "cores": 2, "errors": {"x": 1}}"#).unwrap();
    let info = read_run_info(&path).unwrap();
    assert_eq!((info.commit.as_str(), info.cores, info.threads), ("abc", 2, 0));
    fs::write(&path, r#"{"cores": "two"}"#).unwrap();
    let msg = read_run_info(&path).unwrap_err().to_string();
    assert!(msg.contains("summary.json") && msg.contains("line 1"), "{msg}");
}

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    fs::write(&p, text).unwrap();
    p
}

#[test]
fn series_reader_fills_gaps_with_nan_and_names_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let p = write(
        tmp.path(),
        "observables.csv",
        "t,tip_x,tip_y,tip_z,hand_fx,hand_fy,hand_fz,hand_tx,hand_ty,hand_tz,energy,error\n\
         0,0.3,0,0,0,0,0,0,0,0,1,0.5\n\
         0.001,0.3,0,-1e-3,0,0,0.2,0,0,0,1,\n",
    );
    let s = read_series(&p).unwrap();
    assert_eq!(s.t, vec![0.0, 0.001]);
    assert_eq!(s.tip_z, vec![0.0, -1e-3]);
    assert_eq!(s.hand_fz, vec![0.0, 0.2]);
    assert_eq!(s.error[0], 0.5);
    assert!(s.error[1].is_nan(), "empty cell read as {}", s.error[1]);
    // Only t and error: the rest is NaN; unknown columns are ignored.
    let p = write(tmp.path(), "short.csv", "error,t,note\n1e-3,0.5,x\n");
    let s = read_series(&p).unwrap();
    assert_eq!((s.t[0], s.error[0]), (0.5, 1e-3));
    assert!(s.energy[0].is_nan() && s.tip_x[0].is_nan());
    // Errors name file, line, column.
    let p = write(tmp.path(), "bad.csv", "t,error\n0,1\nx,2\n");
    let msg = read_series(&p).unwrap_err().to_string();
    assert!(
        msg.contains("bad.csv") && msg.contains("line 3") && msg.contains("`t`"),
        "{msg}"
    );
    let p = write(tmp.path(), "no_t.csv", "time,error\n0,1\n");
    let msg = read_series(&p).unwrap_err().to_string();
    assert!(msg.contains("line 1") && msg.contains("`t`"), "{msg}");
    let msg = read_series(&tmp.path().join("missing.csv")).unwrap_err().to_string();
    assert!(msg.contains("missing.csv"), "{msg}");
}

#[test]
fn metrics_map_is_sorted_union() {
    // Two rows with disjoint metrics: each reads back only its own.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("r.csv");
    let mut a = ResultRow::default();
    a.metrics.insert("z_m".into(), 1.0);
    let mut b = ResultRow::default();
    b.metrics.insert("a_rel".into(), 2.0);
    write_results_csv(&path, &[a.clone(), b.clone()]).unwrap();
    let back = read_results_csv(&path).unwrap();
    assert_eq!(back[0].metrics, BTreeMap::from([("z_m".to_string(), 1.0)]));
    assert_eq!(back[1].metrics, BTreeMap::from([("a_rel".to_string(), 2.0)]));
}

/// The optional columns (`host`, `ms_per_step_max`) are written only when
/// some row fills them, read back exactly, and absent from an older file
/// without harm (`None`, `""`).
#[test]
fn optional_columns_round_trip_and_may_be_absent() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    let mut rows = common::rows();
    rows[0].outcome.ms_per_step_max = Some(0.1 + 0.2);
    rows[1].host = "node1".into();
    write_results_csv(&path, &rows).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert_eq!(
        &header[FIXED_COLUMNS.len()..FIXED_COLUMNS.len() + 2],
        &["host", "ms_per_step_max"]
    );
    let back = read_results_csv(&path).unwrap();
    assert_eq!(back, rows);
    assert_eq!(
        back[0].outcome.ms_per_step_max.map(f64::to_bits),
        Some((0.1f64 + 0.2).to_bits())
    );
    // The cells a sharded run stores, and back.
    for r in &rows {
        assert_eq!(
            &surgbench_reports::row_from_cells(&surgbench_reports::row_cells(r)).unwrap(),
            r
        );
    }
    // Without either: no such columns, and reading gives None / "".
    let plain = common::rows();
    write_results_csv(&path, &plain).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    assert!(!text.lines().next().unwrap().contains("ms_per_step_max"));
    let back = read_results_csv(&path).unwrap();
    assert!(
        back.iter()
            .all(|r| r.outcome.ms_per_step_max.is_none() && r.host.is_empty())
    );
    // A malformed slowest step is named like any numeric cell.
    let bad = text.replacen('\n', ",ms_per_step_max\n", 1);
    let bad: String = bad
        .lines()
        .enumerate()
        .map(|(i, l)| if i == 0 { l.to_string() } else { format!("{l},fast") })
        .collect::<Vec<_>>()
        .join("\n");
    fs::write(&path, bad + "\n").unwrap();
    let err = read_results_csv(&path).unwrap_err().to_string();
    assert!(err.contains("ms_per_step_max"), "{err}");
}
