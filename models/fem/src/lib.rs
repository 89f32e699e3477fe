//! Corotational FEM tissue (work in progress).
