//! The wire types: every JSON file the tool reads or writes (job, scene
//! summary, placement, stats, evaluation, PVS, the extras of a baked GLB) and their JSON Schemas.
//! Imports no pipeline stage.

pub mod baked;
pub mod evaluation;
pub mod job;
pub mod placement;
pub mod pvs;
pub mod scene;
pub mod schema;
pub mod stats;
pub mod texture_format;
