//! The scenario catalogue.

pub mod rod;
pub mod tissue;
pub mod vessel;
