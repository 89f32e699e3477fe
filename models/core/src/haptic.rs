//! Haptic device interface and recorded sessions (work in progress).
