//! The scenario catalogue.

pub mod rod;
pub mod vessel;
pub mod tissue;
