//! Minimal GLB writer (work in progress).
