//! # surgbench-comparisons: the harness
//!
//! Scenarios with their references ([`scenarios`], [`elastica`]), the model
//! registry ([`registry`]), the single-run runner with timing and watchdogs
//! ([`runner`]), comparisons as data ([`comparison`]) and the batch runner
//! that isolates each run in a child process ([`batch`]).

pub mod batch;
pub mod comparison;
pub mod elastica;
pub mod faulty;
pub mod gate;
pub mod haptic;
pub mod outdir;
pub mod registry;
pub mod resolve;
pub mod runner;
pub mod scenario;
pub mod scenarios;

pub use scenario::{Params, Scenario, ScenarioRun, UsageError};
