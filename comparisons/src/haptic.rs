//! The fixed-rate haptic loop runner (work in progress).
