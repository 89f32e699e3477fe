//! Issue 23: rows from several machines. A row survives `row_cells` /
//! `row_from_cells` bit for bit (a shard's point file stores it so); the
//! optional `host` column is written only when a row names a host and is
//! read back; a report whose rows come from two machines says so, names the
//! machine of every run and never draws two machines into one Pareto front.

mod common;

use std::fs;
use surgbench_reports::{read_results_csv, render, row_cells, row_from_cells, write_results_csv};

#[test]
fn cells_round_trip_bit_for_bit() {
    for mut row in common::rows() {
        row.metrics.insert("awkward_m".into(), 0.1 + 0.2);
        row.metrics.insert("tiny_m".into(), 1.234_567_890_123_456_7e-300);
        row.host = "node-7".into();
        let back = row_from_cells(&row_cells(&row)).unwrap();
        assert_eq!(back, row, "{} / {}", row.scenario, row.model);
    }
    let mut cells = row_cells(&common::rows()[0]);
    cells.remove("status");
    assert!(row_from_cells(&cells).unwrap_err().contains("status"));
}

#[test]
fn host_column_only_when_some_row_has_a_host() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("results.csv");
    let mut rows = common::rows();
    write_results_csv(&path, &rows).unwrap();
    let header = fs::read_to_string(&path).unwrap().lines().next().unwrap().to_string();
    assert!(!header.split(',').any(|c| c == "host"), "{header}");
    rows[0].host = "a".into();
    write_results_csv(&path, &rows).unwrap();
    let back = read_results_csv(&path).unwrap();
    assert_eq!(back, rows);
    assert!(!back[0].metrics.contains_key("host"));
    rows[1].metrics.insert("host".into(), 1.0);
    assert!(
        write_results_csv(&path, &rows).is_err(),
        "a metric named host is refused"
    );
}

#[test]
fn two_machines_are_named_and_kept_apart() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut rows = common::rows();
    for (i, r) in rows.iter_mut().enumerate() {
        r.host = if i % 2 == 0 { "node-a" } else { "node-b" }.into();
    }
    common::write_series(dir, &rows);
    render(dir, &rows, &common::info()).unwrap();
    let md = fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(
        md.contains("Timings come from 2 machines (node-a, node-b): speed figures are grouped by machine"),
        "{md}"
    );
    assert!(
        md.contains("| model | fidelity | machine | status | tip\\_error\\_rel"),
        "{md}"
    );
    assert!(md.contains("| node-a | ok |") && md.contains("| node-b | ok |"), "{md}");
    assert!(
        md.contains("ms/step on node-b ("),
        "the summary names the machine: {md}"
    );
    assert!(md.contains("a Pareto front per machine"), "{md}");

    let one = tempfile::tempdir().unwrap();
    let mut rows = common::rows();
    for r in &mut rows {
        r.host = "node-a".into();
    }
    common::write_series(one.path(), &rows);
    render(one.path(), &rows, &common::info()).unwrap();
    let md = fs::read_to_string(one.path().join("report.md")).unwrap();
    assert!(!md.contains("Timings come from"), "one machine: no grouping: {md}");
    assert!(md.contains("| model | fidelity | status | tip\\_error\\_rel"), "{md}");
}
