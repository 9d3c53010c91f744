//! The placement: the output of `impostor place`
//! (`schemas/placement.schema.json`). Deterministic and diffable; timings and
//! counters go to [`Stats`] only.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

mod cpv_lists;
pub use cpv_lists::{CpvJson, whole_lists};

/// A placement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Totals.
    pub summary: Summary,
    /// The impostors; `id` is the index.
    pub impostors: Vec<PlacedImpostor>,
    /// The conservative problem views, solved and unsolved; `id` is the
    /// index. In JSON a CPV's impostor list may be written as its change
    /// from the list of the CPV before it ([`CpvJson`]).
    #[serde(with = "cpv_lists")]
    #[schemars(with = "Vec<CpvJson>")]
    pub cpvs: Vec<PlacedCpv>,
}

/// Placement totals.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Summary {
    /// Number of CPVs.
    pub cpvs: u64,
    /// Number of impostor candidates generated.
    pub candidates: u64,
    /// Number of impostors placed.
    pub impostors: u64,
    /// Total impostor memory, bytes.
    pub memory_bytes: u64,
    /// CPVs whose estimated time still exceeds the target.
    pub unsolved_cpvs: u64,
    /// The target frame time the placement was made for, ms.
    pub target_frame_time_ms: f64,
    /// The largest estimated time of an unsolved CPV above the target, ms
    /// (0 when every CPV is solved).
    #[serde(default)]
    pub max_residual_ms: f64,
    /// Unsolved CPVs by the reason they could not be solved.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub unsolved_by_reason: BTreeMap<UnsolvedReason, u64>,
    /// The job's impostor memory budget, bytes, if it set one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_bytes: Option<u64>,
}

/// Why a CPV is still above the target after the placement.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum UnsolvedReason {
    /// A candidate that would have made it faster did not fit in
    /// `memory.budget_bytes`.
    BudgetExhausted,
    /// Most of what it still draws is geometry whose cluster is too close
    /// to (or reaches into) the CPV's region for any view cell: its sphere
    /// is nearer than its diameter and meets the region (the paper's
    /// failure case: small, expensive objects close to the viewer).
    ClusterContainsRegion,
    /// Most of what it still draws is geometry far enough for a view cell,
    /// but no impostor of it keeps the parallax within `max_error_px` with
    /// at most 1,024 layers and `memory.max_texture_size` texels.
    NoCandidateMeetsMaxErrorPx,
    /// Impostors exist for what it draws, but none would render faster than
    /// what it replaces (or everything is an impostor already and the
    /// impostors alone exceed the target).
    ImpostorsNotFaster,
}

impl UnsolvedReason {
    /// The reason as the placement writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            UnsolvedReason::BudgetExhausted => "budget_exhausted",
            UnsolvedReason::ClusterContainsRegion => "cluster_contains_region",
            UnsolvedReason::NoCandidateMeetsMaxErrorPx => "no_candidate_meets_max_error_px",
            UnsolvedReason::ImpostorsNotFaster => "impostors_not_faster",
        }
    }
}

/// A bounding sphere.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SphereJson {
    /// Centre `[x, y, z]`.
    pub center: [f64; 3],
    /// Radius, metres.
    pub radius: f64,
}

/// A view cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum ViewCellJson {
    /// `{v : |v − apex| ≥ min_distance, ∠(v − apex, axis) ≤ half_angle}`.
    Shaft {
        /// Apex (the cluster centre).
        apex: [f64; 3],
        /// Unit axis.
        axis: [f64; 3],
        /// Half the apex angle, degrees.
        half_angle_deg: f64,
        /// Minimum distance from the apex, metres.
        min_distance: f64,
    },
    /// An axis-aligned box of viewpoints.
    Box {
        /// Minimum corner.
        min: [f64; 3],
        /// Maximum corner.
        max: [f64; 3],
    },
}

/// One impostor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlacedImpostor {
    /// Index in `impostors`.
    pub id: u32,
    /// The cluster's node id in the object hierarchy.
    pub node: u32,
    /// The object ids it represents, ascending.
    pub objects: Vec<u32>,
    /// Bounding sphere of the cluster (contains every object's sphere).
    pub sphere: SphereJson,
    /// Where it is valid.
    pub view_cell: ViewCellJson,
    /// Number of layers.
    pub layers: u32,
    /// Texels per side of each layer.
    pub resolution: u32,
    /// Texture memory, bytes.
    pub memory_bytes: u64,
    /// Estimated render time from the view cell's closest point, ms.
    pub time_ms: f64,
}

impl PlacedImpostor {
    /// Checks that the view cell can be a view cell of this impostor: finite,
    /// a shaft with a non-zero axis, a half-angle in (0°, 180°] and a
    /// minimum distance beyond the cluster's sphere, a box with
    /// `min ≤ max`. `Err((field, problem))`.
    pub fn check_view_cell(&self) -> Result<(), (&'static str, String)> {
        match self.view_cell {
            ViewCellJson::Shaft {
                apex,
                axis,
                half_angle_deg,
                min_distance,
            } => {
                let finite = apex.iter().chain(&axis).all(|x| x.is_finite());
                if !finite || axis.iter().all(|&x| x == 0.0) {
                    return Err((
                        "view_cell.shaft",
                        "apex and axis must be finite and the axis non-zero".into(),
                    ));
                }
                if !(half_angle_deg > 0.0 && half_angle_deg <= 180.0) {
                    return Err((
                        "view_cell.shaft.half_angle_deg",
                        format!("{half_angle_deg} must be in (0, 180]"),
                    ));
                }
                if !(min_distance.is_finite() && min_distance > self.sphere.radius) {
                    return Err((
                        "view_cell.shaft.min_distance",
                        format!(
                            "{min_distance} must exceed the cluster's radius {} (the view cell may not meet the cluster)",
                            self.sphere.radius
                        ),
                    ));
                }
            }
            ViewCellJson::Box { min, max } => {
                let ok =
                    (0..3).all(|a| min[a].is_finite() && max[a].is_finite() && min[a] <= max[a]);
                if !ok {
                    return Err((
                        "view_cell.box",
                        "corners must be finite with min ≤ max on every axis".into(),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// A 3D region.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RegionJson {
    /// Minimum corner.
    pub min: [f64; 3],
    /// Maximum corner.
    pub max: [f64; 3],
}

/// A view-direction interval on a cube face.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DirectionsJson {
    /// Cube face `2·axis + (0 if positive else 1)`.
    pub face: u8,
    /// `[u_lo, u_hi]` face coordinates.
    pub u: [f64; 2],
    /// `[v_lo, v_hi]` face coordinates.
    pub v: [f64; 2],
}

/// One conservative problem view (in JSON, a [`CpvJson`], whose fields
/// document these).
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedCpv {
    /// Index in `cpvs`.
    pub id: u32,
    /// Its 3D region.
    pub region: RegionJson,
    /// Its view directions.
    pub directions: DirectionsJson,
    /// Estimated time without impostors, ms.
    pub time_ms_original: f64,
    /// Estimated time with its impostors, ms.
    pub time_ms_final: f64,
    /// True when `time_ms_final` is within the target.
    pub solved: bool,
    /// Why an unsolved CPV could not be solved.
    pub unsolved_reason: Option<UnsolvedReason>,
    /// Ids of the impostors to draw in this CPV, ascending.
    pub impostors: Vec<u32>,
}
