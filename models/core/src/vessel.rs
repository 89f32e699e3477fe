//! Procedural vessels and vessel mesh loading (work in progress).
