//! The haptic-loop table (`haptic.csv`): one row per model x scenario driven
//! at a fixed rate against the wall clock, and the report section that shows
//! it. Answers "can this model drive a haptic device at 1 kHz?".
//!
//! Times are in milliseconds where the column says `ms`, seconds where it
//! says `s`; rates in Hz.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::doc::{Block, Cell};
use crate::format::fmt_sig;
use crate::{ReportError, Status};

/// What one fixed-rate haptic loop measured (see the harness's
/// `haptic::run_haptic_loop` for the definitions of latency and jitter).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct HapticRow {
    /// Model id.
    pub model: String,
    /// Scenario id.
    pub scenario: String,
    /// Fidelity as the model ran it (`key=value;...`).
    pub fidelity: String,
    /// [`Status::Ok`] (the loop ran to its end), [`Status::Stopped`] (a
    /// model error ended it early), `Unsupported`, `Failed` or `Timeout`.
    pub status: Status,
    /// Why it is not `ok`.
    pub reason: String,
    /// Loop rate (Hz).
    pub rate_hz: f64,
    /// Requested duration (s).
    pub duration_s: f64,
    /// Ticks run.
    pub ticks: Option<f64>,
    /// Model steps per tick.
    pub substeps: Option<f64>,
    /// Ticks whose render came after the next tick's deadline.
    pub deadline_misses: Option<f64>,
    /// Median latency, scheduled tick start to render (ms).
    pub latency_p50_ms: Option<f64>,
    /// 99th percentile latency (ms).
    pub latency_p99_ms: Option<f64>,
    /// Largest latency (ms).
    pub latency_max_ms: Option<f64>,
    /// Largest lateness of a tick start (ms).
    pub jitter_max_ms: Option<f64>,
}

/// The columns of `haptic.csv`, in order (the [`HapticRow`] fields).
pub const HAPTIC_COLUMNS: [&str; 14] = [
    "model",
    "scenario",
    "fidelity",
    "status",
    "reason",
    "rate_hz",
    "duration_s",
    "ticks",
    "substeps",
    "deadline_misses",
    "latency_p50_ms",
    "latency_p99_ms",
    "latency_max_ms",
    "jitter_max_ms",
];

/// Writes `rows` to `path` (header = the [`HapticRow`] field names).
pub fn write_haptic_csv(path: &Path, rows: &[HapticRow]) -> Result<(), ReportError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| ReportError::csv(path, e))?;
    for r in rows {
        w.serialize(r).map_err(|e| ReportError::csv(path, e))?;
    }
    w.flush().map_err(|e| ReportError::io(path, e))
}

/// Reads a `haptic.csv` written by [`write_haptic_csv`]; a missing column or
/// a bad number is an error naming the file and line.
pub fn read_haptic_csv(path: &Path) -> Result<Vec<HapticRow>, ReportError> {
    let mut rd = csv::Reader::from_path(path).map_err(|e| ReportError::csv(path, e))?;
    let header = rd.headers().map_err(|e| ReportError::csv(path, e))?.clone();
    // serde would read an absent optional column as "not measured": refuse it.
    for name in HAPTIC_COLUMNS {
        if !header.iter().any(|h| h.trim() == name) {
            return Err(ReportError::parse(path, 1, name, "missing required column"));
        }
    }
    rd.deserialize()
        .map(|r| r.map_err(|e| ReportError::csv(path, e)))
        .collect()
}

/// The report section: one table row per loop, with the miss ratio.
pub(crate) fn section(rows: &[HapticRow]) -> Vec<Block> {
    let mut b = vec![
        Block::Anchored(2, "Haptic loop: can the model drive a device?".into(), "haptic".into()),
        Block::Para(
            "Each model steps on its own thread against the wall clock at the given rate; a deadline miss is a tick \
             whose force was rendered after the next tick began (the device would render a stale force). Latency \
             runs from a tick's scheduled start to its render. Wall-clock numbers depend on the machine and its \
             load (see the header); the simulated forces do not."
                .into(),
        ),
    ];
    let header = [
        "model",
        "scenario",
        "fidelity",
        "rate (Hz)",
        "duration (s)",
        "substeps",
        "deadline misses",
        "latency p50 (ms)",
        "p99 (ms)",
        "max (ms)",
        "jitter max (ms)",
        "status",
    ];
    let num = |v: Option<f64>| v.map(|v| fmt_sig(v, 3)).unwrap_or_else(|| "-".into());
    let table = rows
        .iter()
        .map(|r| {
            let misses = match (r.deadline_misses, r.ticks) {
                (Some(m), Some(t)) if t > 0.0 => format!("{m} of {t} ({:.2} %)", 100.0 * m / t),
                _ => "-".into(),
            };
            let status = if r.status == Status::Ok {
                Cell::plain("ok")
            } else {
                Cell {
                    text: format!("{}: {}", r.status, r.reason),
                    warn: true,
                    ..Cell::default()
                }
            };
            vec![
                Cell::plain(&r.model),
                Cell::plain(&r.scenario),
                Cell::plain(&r.fidelity),
                Cell::plain(fmt_sig(r.rate_hz, 4)),
                Cell::plain(fmt_sig(r.duration_s, 3)),
                Cell::plain(num(r.substeps)),
                Cell::plain(misses),
                Cell::plain(num(r.latency_p50_ms)),
                Cell::plain(num(r.latency_p99_ms)),
                Cell::plain(num(r.latency_max_ms)),
                Cell::plain(num(r.jitter_max_ms)),
                status,
            ]
        })
        .collect();
    b.push(Block::Table {
        header: header.iter().map(|s| s.to_string()).collect(),
        rows: table,
    });
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text_header(p: &Path) -> String {
        std::fs::read_to_string(p).unwrap().lines().next().unwrap().to_string()
    }

    #[test]
    fn roundtrip_and_missing_column() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("haptic.csv");
        let rows = vec![
            HapticRow {
                model: "der".into(),
                scenario: "arch-insertion".into(),
                fidelity: "segments=99".into(),
                status: Status::Ok,
                rate_hz: 1000.0,
                duration_s: 10.0,
                ticks: Some(10000.0),
                substeps: Some(1.0),
                deadline_misses: Some(3.0),
                latency_p50_ms: Some(0.21),
                latency_p99_ms: Some(0.5),
                latency_max_ms: Some(1.7),
                jitter_max_ms: Some(0.9),
                ..Default::default()
            },
            HapticRow {
                model: "pbd-rod".into(),
                scenario: "arch-insertion".into(),
                status: Status::Unsupported,
                reason: "no, because".into(),
                rate_hz: 1000.0,
                duration_s: 10.0,
                ..Default::default()
            },
        ];
        write_haptic_csv(&p, &rows).unwrap();
        assert_eq!(read_haptic_csv(&p).unwrap(), rows);
        let header = text_header(&p);
        assert_eq!(
            header,
            HAPTIC_COLUMNS.join(","),
            "the constant names the written columns"
        );
        let text = std::fs::read_to_string(&p).unwrap();
        let cut: String = text
            .lines()
            .map(|l| l.rsplit_once(',').map(|x| x.0).unwrap_or(l).to_string() + "\n")
            .collect();
        std::fs::write(&p, cut).unwrap();
        let e = read_haptic_csv(&p).unwrap_err().to_string();
        assert!(e.contains("haptic.csv") && e.contains("jitter_max_ms"), "{e}");
    }
}
