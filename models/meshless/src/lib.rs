//! Point-primitive (meshless) tissue (work in progress).
