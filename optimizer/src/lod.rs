//! Levels of detail (temporary stub).
#![allow(missing_docs)]
use crate::{Result, geometry::SceneGeometry, job::Job, scene::Scene};
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
pub struct LodReport {}
pub fn generate_for_job(_s: &mut Scene, _g: &SceneGeometry, _j: &Job) -> Result<LodReport> {
    Ok(LodReport {})
}
