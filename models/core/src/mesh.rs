//! Tetrahedral meshing, mesh quality and mesh file readers (work in progress).
