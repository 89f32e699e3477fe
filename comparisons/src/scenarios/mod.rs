//! The scenario catalogue.

pub mod rod;
