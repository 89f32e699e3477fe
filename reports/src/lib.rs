//! Report rendering (work in progress).
