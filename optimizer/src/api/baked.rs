//! What a baked impostor GLB says about itself (`impostor bake`): the
//! `extras.impostor` of every impostor node and of the scene
//! (`schemas/baked-node.schema.json`, `schemas/baked-scene.schema.json`).
//!
//! Every impostor node draws one mesh with one primitive: its written
//! layers, front to back, four vertices each (top-left, bottom-left,
//! bottom-right, top-right) and two triangles each, all in one atlas. So an
//! engine switches an impostor on by drawing that node and hiding the
//! nodes `source_nodes` names, while the viewer is inside `view_cell`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::job::ViewSpace;
use crate::api::placement::{SphereJson, Summary, ViewCellJson};

/// `extras.impostor` of one impostor node.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BakedImpostor {
    /// The impostor's id in the placement.
    pub id: u32,
    /// The cluster's node id in the object hierarchy.
    pub cluster: u32,
    /// The object ids it replaces (the scene walk's order), ascending.
    pub objects: Vec<u32>,
    /// The glTF node indices, in the baked scene file, of the objects it
    /// replaces (same order as `objects`). Absent when the geometry was not
    /// loaded from a glTF file and has no node indices.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_nodes: Option<Vec<u32>>,
    /// Where it is valid, as in the placement.
    pub view_cell: ViewCellJson,
    /// Bounding sphere of the cluster.
    pub sphere: SphereJson,
    /// The viewpoint the layers were rendered from, world space.
    pub reference_viewpoint: [f64; 3],
    /// Number of layers in the placement.
    pub layers: u32,
    /// The indices (front to back, among `layers`) of the layers written,
    /// in the order of the primitive's quads: quad `k` is vertices
    /// `4k..4k + 4`. Layers without a covered texel are not written.
    pub layers_written: Vec<u32>,
    /// Texels per side of each layer.
    pub resolution: u32,
    /// The atlas (glTF image index) all its layers lie in.
    pub atlas: u32,
}

/// `extras.impostor` of the baked file's scene (`scenes[0]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BakedScene {
    /// The job's view space, when the job was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view_space: Option<ViewSpace>,
    /// The placement's totals.
    pub summary: Summary,
}
