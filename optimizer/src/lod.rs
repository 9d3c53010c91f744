//! Levels of detail (placeholder; see the module being written).
