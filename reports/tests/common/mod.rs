//! Synthetic rows shared by the integration tests: two scenarios, several
//! models, with ok, unstable, failed and unsupported runs.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::fs;
use std::path::Path;

use surgbench_reports::{End, Outcome, ResultRow, RunInfo, Status};

/// The workspace's seeded generator for test data.
pub use surgbench_core::rng::SplitMix64 as SplitMix;

pub const UNSUPPORTED_REASON: &str = "chainmail has no bending stiffness under distributed gravity load";
pub const FAILED_REASON: &str = "build failed: segments=5 is below the minimum of 8, \"rod too coarse\"";
pub const UNSTABLE_REASON: &str = "energy grew by 1e6 at t = 0.12 s";
pub const TISSUE_UNSUPPORTED: &str = "pbd-tissue cannot apply a pressure load";

fn rod_row(model: &str, segments: f64, dt: f64, err: f64, ms: f64) -> ResultRow {
    let mut metrics = BTreeMap::new();
    metrics.insert("tip_error_rel".to_string(), err);
    metrics.insert("rms_node_error_m".to_string(), err * 0.01);
    ResultRow {
        comparison: "standard".into(),
        scenario: "cantilever-gravity".into(),
        model: model.into(),
        family: "rod".into(),
        fidelity: format!("segments={segments};dt={dt}"),
        params: String::new(),
        segments: Some(segments),
        dt: Some(dt),
        primary_error: "tip_error_rel".into(),
        run_dir: format!("runs/cantilever-gravity/{model}/segments-{segments}-dt-{dt}"),
        metrics,
        outcome: Outcome {
            status: Status::Ok,
            end: End::Settled,
            steps: Some(2000.0),
            sim_time_s: Some(2000.0 * dt),
            ms_per_step_median: Some(ms),
            ms_per_step_p95: Some(ms * 1.3),
            steps_per_s: Some(1000.0 / ms),
            real_time_factor: Some(dt * 1000.0 / ms),
            solver_iters_mean: Some(3.5),
            solver_iters_max: Some(7.0),
            peak_rss_mb: Some(12.5),
            build_ms: Some(0.4),
            stable: Some(true),
            ..Outcome::default()
        },
        ..ResultRow::default()
    }
}

/// The synthetic comparison. `der` converges with order 2 in segments,
/// `pbd-rod` with order 1, `fem` with order 2 in cells per side.
pub fn rows() -> Vec<ResultRow> {
    let mut rng = SplitMix(42);
    let mut rows = Vec::new();
    for &dt in &[1e-3, 5e-4] {
        for &n in &[10.0, 20.0, 40.0, 80.0] {
            if n == 80.0 && dt == 1e-3 {
                let mut r = rod_row("der", n, dt, 0.0, 0.0);
                r.status = Status::Unstable;
                r.reason = UNSTABLE_REASON.into();
                r.stable = Some(false);
                r.watchdog = "energy".into();
                r.watchdog_t = Some(0.12);
                r.end = End::Unset;
                r.metrics.clear();
                r.ms_per_step_median = Some(0.21);
                r.ms_per_step_p95 = Some(0.3);
                r.real_time_factor = None;
                r.run_dir = String::new();
                rows.push(r);
                continue;
            }
            // Exact power laws so the fitted orders are known.
            let err = 0.3 * n.powi(-2);
            let ms = 0.0021 * n * (1.0 + 0.1 * rng.unit()) * (1e-3 / dt);
            rows.push(rod_row("der", n, dt, err, ms));
        }
    }
    for &n in &[10.0, 20.0, 40.0, 80.0] {
        let err = 0.05 / n;
        let ms = 0.0009 * n * (1.0 + 0.1 * rng.unit());
        rows.push(rod_row("pbd-rod", n, 1e-3, err, ms));
    }
    let mut failed = rod_row("pbd-rod", 5.0, 1e-3, 0.0, 0.0);
    failed.status = Status::Failed;
    failed.reason = FAILED_REASON.into();
    failed.metrics.clear();
    failed.ms_per_step_median = None;
    failed.ms_per_step_p95 = None;
    failed.real_time_factor = None;
    failed.steps = None;
    failed.stable = None;
    failed.end = End::Unset;
    failed.run_dir = String::new();
    rows.push(failed);
    let unsupported = ResultRow {
        comparison: "standard".into(),
        scenario: "cantilever-gravity".into(),
        model: "chainmail".into(),
        family: "rod".into(),
        fidelity: "segments=20;dt=0.001".into(),
        segments: Some(20.0),
        dt: Some(1e-3),
        primary_error: "tip_error_rel".into(),
        outcome: Outcome {
            status: Status::Unsupported,
            reason: UNSUPPORTED_REASON.into(),
            ..Outcome::default()
        },
        ..ResultRow::default()
    };
    rows.push(unsupported);

    for level in 1..=4 {
        let l = level as f64;
        let cells = 2f64.powi(level);
        let mut metrics = BTreeMap::new();
        metrics.insert("displacement_error_l2_m".to_string(), 2e-3 / (cells * cells));
        rows.push(ResultRow {
            comparison: "standard".into(),
            scenario: "lame-tube".into(),
            model: "fem".into(),
            family: "tissue".into(),
            fidelity: format!("mesh_level={level};dt=0.01"),
            params: "pressure=2000".into(),
            mesh_level: Some(l),
            dt: Some(0.01),
            primary_error: "displacement_error_l2_m".into(),
            metrics,
            outcome: Outcome {
                status: Status::Ok,
                end: End::Settled,
                ms_per_step_median: Some(0.05 * cells.powi(3)),
                ms_per_step_p95: Some(0.06 * cells.powi(3)),
                real_time_factor: Some(0.01 / (0.05e-3 * cells.powi(3))),
                stable: Some(true),
                ..Outcome::default()
            },
            ..ResultRow::default()
        });
    }
    rows.push(ResultRow {
        comparison: "standard".into(),
        scenario: "lame-tube".into(),
        model: "pbd-tissue".into(),
        family: "tissue".into(),
        fidelity: "mesh_level=2;dt=0.01".into(),
        params: "pressure=2000".into(),
        mesh_level: Some(2.0),
        dt: Some(0.01),
        primary_error: "displacement_error_l2_m".into(),
        outcome: Outcome {
            status: Status::Unsupported,
            reason: TISSUE_UNSUPPORTED.into(),
            ..Outcome::default()
        },
        ..ResultRow::default()
    });
    rows
}

pub fn info() -> RunInfo {
    let mut crate_versions = BTreeMap::new();
    crate_versions.insert("surgbench-der".to_string(), "0.1.0".to_string());
    RunInfo {
        comparison: "standard".into(),
        date: "2025-01-01T00:00:00Z".into(),
        commit: "0123abcd".into(),
        machine: "test machine".into(),
        cores: 2,
        threads: 1,
        rustc: "rustc 1.95.0".into(),
        crate_versions,
        command: "surgbench run standard".into(),
        quick: true,
        wall_s: 12.5,
        python_models: BTreeMap::new(),
        fitted: BTreeMap::new(),
        ..RunInfo::default()
    }
}

/// Writes `observables.csv` for the finest ok runs of `der` and `pbd-rod`
/// (error decaying from 1e-1 towards the converged value, one empty cell).
pub fn write_series(dir: &Path, rows: &[ResultRow]) {
    for (model, seg, dt, floor) in [("der", 80.0, 5e-4, 0.3 / 6400.0), ("pbd-rod", 80.0, 1e-3, 0.05 / 80.0)] {
        let r = rows
            .iter()
            .find(|r| r.model == model && r.segments == Some(seg) && r.dt == Some(dt))
            .expect("synthetic row exists");
        let d = dir.join(&r.run_dir);
        fs::create_dir_all(&d).unwrap();
        let mut text =
            String::from("t,tip_x,tip_y,tip_z,hand_fx,hand_fy,hand_fz,hand_tx,hand_ty,hand_tz,energy,error\n");
        for i in 0..=200 {
            let t = i as f64 * 0.005;
            let e = floor + 0.1 * (-t / 0.1).exp();
            let cell = if i == 7 { String::new() } else { format!("{e}") };
            text.push_str(&format!("{t},0.3,0,-0.01,0,0,0.5,0,0,0,1e-3,{cell}\n"));
        }
        fs::write(d.join("observables.csv"), text).unwrap();
    }
}
