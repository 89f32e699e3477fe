//! Harness (work in progress).
pub mod elastica;
