//! Generalized 3D chain-mail guidewire (work in progress).
