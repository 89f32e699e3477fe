//! # surgbench-comparisons: the harness
//!
//! Scenarios ([`scenarios`]) with their references ([`references`], data in [`datasets`]), the model
//! registry ([`registry`]), the single-run runner with timing and watchdogs
//! ([`runner`]), comparisons as data ([`comparison`]) and the batch runner
//! that isolates each run in a child process ([`batch`], with [`child`] and
//! [`interrupt`] so that no child or temporary folder outlives it). A
//! user's own geometry reaches the scenarios that take one through
//! [`user_mesh`]. A comparison too large for one machine is split into
//! shards by its [`plan`], run shard by shard on a cluster's array jobs
//! ([`shard_run`]) and gathered into one report ([`merge`]).

pub mod batch;
pub mod child;
pub mod comparison;
pub mod conformance;
pub mod datasets;
pub mod error;
pub mod faulty;
pub mod gate;
pub mod haptic;
pub mod interrupt;
pub mod merge;
pub mod outdir;
pub mod plan;
pub mod progress;
pub mod references;
pub mod registry;
pub mod resolve;
pub mod runner;
pub mod scenario;
pub mod scenarios;
pub mod shard_run;
pub mod user_mesh;

pub use scenario::{Metrics, Params, Scenario, ScenarioInfo, ScenarioRun, Scorer, UsageError};
