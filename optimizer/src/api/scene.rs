//! The JSON scene summary (`schemas/scene.schema.json`): objects with bounds
//! and rendering costs, no geometry.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// One level of detail of an object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LodLevel {
    /// Smallest screen coverage (projected bounding-sphere area over screen
    /// area, in `[0, 1]`) at which this level is drawn.
    pub min_coverage: f64,
    /// Triangles of this level.
    pub triangles: u64,
    /// Draw calls of this level.
    pub draw_calls: u32,
}

/// JSON scene summary (`schemas/scene.schema.json`): objects with bounds and
/// costs, no geometry. Object ids are array indices.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneSummary {
    /// The objects; the array index is the object id.
    pub objects: Vec<SummaryObject>,
}

/// One object of a JSON scene summary.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SummaryObject {
    /// Optional name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// World bounding box minimum `[x, y, z]`, metres.
    pub min: [f64; 3],
    /// World bounding box maximum `[x, y, z]`, metres.
    pub max: [f64; 3],
    /// Triangle count.
    pub triangles: u64,
    /// Draw calls.
    pub draw_calls: u32,
    /// Levels of detail, finest first (level 0 is the object itself); empty
    /// when the object has none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lods: Vec<LodLevel>,
}
