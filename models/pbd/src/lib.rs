//! Position-based dynamics: Cosserat-PBD rod and tetrahedral tissue (work in progress).
