//! Ray casting against the scene's triangles (placeholder; see the module
//! being written).
