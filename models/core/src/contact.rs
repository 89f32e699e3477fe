//! Contact and Coulomb friction response shared by rod models (work in progress).
