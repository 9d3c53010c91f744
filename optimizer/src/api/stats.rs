//! Timings and counters of a run (`--stats`, `schemas/stats.schema.json`):
//! not deterministic, never part of the placement.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::job::VisibilityMode;

/// Timings and counters of a run (`--stats`); not deterministic.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
pub struct Stats {
    /// Worker threads.
    pub threads: usize,
    /// Objects in the scene.
    pub objects: u64,
    /// Triangles in the scene.
    pub triangles: u64,
    /// Object hierarchy nodes.
    pub hierarchy_nodes: u64,
    /// 3D view space cells.
    pub cells: u64,
    /// kd regions visited by the subdivision.
    pub regions_visited: u64,
    /// Enclosing frusta evaluated.
    pub enclosing_frusta: u64,
    /// CPVs.
    pub cpvs: u64,
    /// Problem views of minimum size that refinement of their directions
    /// (`problem_views.refine_levels`) proved within the target, so they are
    /// not CPVs.
    #[serde(default)]
    pub cpvs_refined_away: u64,
    /// Share of CPVs in which some exact view (no impostor) exceeds the
    /// target: 1 when every CPV is a real problem view, near 0 when the
    /// estimate finds problems no view has (absent without CPVs). Measured
    /// on `cpv_precision_sampled` CPVs spread over the list, each searched
    /// for its slowest view (32 uniform views, the 32 extreme views of its
    /// region and directions, then a local search from the slowest); a
    /// search may miss a CPV's slowest view, so it is a lower bound.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpv_precision: Option<f64>,
    /// CPVs sampled for `cpv_precision`.
    #[serde(default)]
    pub cpv_precision_sampled: u64,
    /// (CPV, cluster) pairs examined by candidate generation.
    pub candidate_pairs: u64,
    /// Of those, the pairs held one by one (their cluster is partly
    /// outside the CPV's enclosing set); the others lie below a node of the
    /// hierarchy's cut through the set and are held as a bit per CPV in
    /// their group.
    #[serde(default)]
    pub explicit_pairs: u64,
    /// Costs stored for explicit pairs: those of the pairs whose cost is
    /// not the cluster's whole cost in the cell (held once per group), each
    /// once for a run of a group's CPVs that hold the same.
    #[serde(default)]
    pub stored_pair_costs: u64,
    /// Groups: one cluster's pairs in one cell.
    #[serde(default)]
    pub pair_groups: u64,
    /// Entries of the candidates' served lists (group ids).
    #[serde(default)]
    pub served_entries: u64,
    /// Candidates.
    pub candidates: u64,
    /// Greedy choices.
    pub greedy_choices: u64,
    /// Score evaluations: candidates whose exact score the greedy computed.
    pub score_evaluations: u64,
    /// Score bounds: candidates whose score the greedy bounded from the
    /// cells' summed excess before computing it (cheaper: no pair walked).
    #[serde(default)]
    pub score_bounds: u64,
    /// Impostors removed by pruning.
    pub pruned: u64,
    /// Impostors dropped because every CPV using them stays above the
    /// target (`memory.keep_partial`).
    #[serde(default)]
    pub partial_dropped: u64,
    /// Impostors placed.
    pub impostors: u64,
    /// Impostor memory, bytes.
    pub memory_bytes: u64,
    /// Unsolved CPVs.
    pub unsolved_cpvs: u64,
    /// Seconds per stage, in pipeline order.
    pub seconds: Vec<StageTime>,
    /// Peak resident memory of the process, bytes (Linux only; 0 elsewhere).
    pub peak_rss_bytes: u64,
    /// Peak memory predicted once the problem views are known (before the
    /// candidates and the greedy, which hold the (CPV, cluster) pairs), bytes.
    #[serde(default)]
    pub predicted_peak_bytes: u64,
    /// Score evaluations per greedy choice.
    #[serde(default)]
    pub evaluations_per_choice: f64,
    /// From-region visibility (absent when the job's mode is `none`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility: Option<crate::api::stats::VisibilityStats>,
    /// Levels of detail (absent when no object has any).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lod: Option<LodStats>,
    /// The `exact` method's program (absent for other methods).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact: Option<ExactStats>,
    /// Per tile of a tiled job (`partition`), in order; the counters above
    /// are then the tiles' sums (impostors and memory: the merged
    /// placement's, each shared impostor once).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tiles: Vec<TileStats>,
    /// Set when the job, without a `partition`, was placed in tiles because
    /// its prediction exceeded the memory limit (`tiles` then lists them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tiled_for_memory: Option<TiledForMemory>,
}

/// Why and how a job was placed in tiles it did not ask for.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TiledForMemory {
    /// `[nx, nz]` tiles (a tile still above the limit was split again by
    /// its own run, within its entry of `tiles`).
    pub tiles: [u32; 2],
    /// The whole job's predicted peak memory, bytes.
    pub predicted_bytes: u64,
    /// The memory limit it exceeded, bytes (`--max-memory-gb`, the
    /// server's per-job limit, or the memory available).
    pub limit_bytes: u64,
    /// Seconds the whole job's problem views took before the split (the
    /// tiles take theirs from them; included in `seconds`' problem views).
    pub problem_views_seconds: f64,
}

/// The `exact` method's integer program and how far the greedy is from it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ExactStats {
    /// `optimal` (proven), or the limit that stopped the solver with the
    /// best selection found: `node_limit` (`exact.max_nodes`),
    /// `time_limit` (`exact.max_seconds`), `gap_limit`.
    pub status: String,
    /// Binary variables: candidates and useful (candidate, CPV) pairs.
    pub variables: u64,
    /// Constraints.
    pub constraints: u64,
    /// Branch-and-bound nodes solved.
    pub nodes: u64,
    /// Solver wall time, seconds.
    pub seconds: f64,
    /// Memory of the exact selection, bytes.
    pub memory_bytes: u64,
    /// Memory of the greedy's selection (of the same candidates), bytes.
    pub greedy_memory_bytes: u64,
    /// The best proven lower bound on the optimum's memory, bytes (equal to
    /// `memory_bytes` when optimal; absent when the solver proved none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lower_bound_bytes: Option<u64>,
    /// `greedy_memory_bytes / memory_bytes` (1 when both are 0).
    pub greedy_over_exact: f64,
}

/// Levels of detail in a run.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
pub struct LodStats {
    /// Objects with levels of detail.
    pub objects_with_lods: u64,
    /// Per level, how often the problem view approximation chose it for a
    /// (region, object) pair of an object with levels; the last entry counts
    /// the pairs where the object was too small on screen to be drawn.
    pub chosen_levels: Vec<u64>,
    /// Levels generated by mesh simplification (`lod.generate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generated: Option<LodReport>,
}

/// Wall time of one stage and, for the placement's stages, the process's
/// resident memory when it ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct StageTime {
    /// Stage name.
    pub stage: String,
    /// Seconds.
    pub seconds: f64,
    /// Resident memory of the process when the stage ended (`VmRSS`), bytes;
    /// absent where not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rss_bytes: Option<u64>,
    /// Peak resident memory of the process up to the stage's end (`VmHWM`),
    /// bytes: the stage whose value first reaches the run's peak is where
    /// the peak happened. Absent where not measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rss_bytes: Option<u64>,
}

/// One tile of a tiled run.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TileStats {
    /// Its view space's minimum corner.
    pub min: [f64; 3],
    /// Its view space's maximum corner.
    pub max: [f64; 3],
    /// Its CPVs.
    pub cpvs: u64,
    /// Its impostors (some may be shared with other tiles).
    pub impostors: u64,
    /// Its impostors' memory, bytes.
    pub memory_bytes: u64,
    /// Its stages' summed wall time, seconds.
    pub seconds: f64,
    /// The process's peak resident memory when it ended, bytes.
    pub peak_rss_bytes: u64,
}

impl StageTime {
    /// A stage's time without memory figures.
    pub fn new(stage: &str, seconds: f64) -> Self {
        StageTime {
            stage: stage.into(),
            seconds,
            rss_bytes: None,
            peak_rss_bytes: None,
        }
    }
}

/// Visibility counters (`stats.visibility`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct VisibilityStats {
    /// The mode.
    pub mode: VisibilityMode,
    /// Grid cells whose set was computed.
    pub cells_computed: u64,
    /// Mean size of a computed cell's set.
    pub mean_visible_objects: f64,
    /// Mean share of the scene's objects in a computed cell's set.
    pub mean_visible_fraction: f64,
    /// Largest share of the scene's objects in a computed cell's set.
    pub max_visible_fraction: f64,
    /// CPU time spent computing cell sets, seconds (summed over threads).
    pub cpu_seconds: f64,
    /// Conservative mode: occluder extraction counters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occluders: Option<OccluderStats>,
    /// Conservative mode: occluders left after shrinking.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shrunk_occluders: Option<u64>,
    /// Conservative mode: sample points per cell per axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples_per_axis: Option<[u32; 3]>,
    /// Conservative mode: how far occluders shrink per axis, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shrink_m: Option<[f64; 3]>,
    /// Conservative mode: cells whose coarse set was computed (regions of
    /// several cells use them; a cell's final set is its fine and coarse
    /// sets intersected).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_cells_computed: Option<u64>,
    /// Conservative mode: the coarse tier's sample points per cell per axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coarse_samples_per_axis: Option<[u32; 3]>,
    /// Sampled mode: rays per cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rays_per_cell: Option<u32>,
    /// Sampled mode: mean over cells of the Good–Turing missing mass (the
    /// chance that one more ray finds an object no ray found).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing_mass_mean: Option<f64>,
    /// Sampled mode: largest missing mass over cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missing_mass_max: Option<f64>,
    /// Sampled mode: mean over cells of the objects found only by the
    /// aimed probes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub found_by_probes_mean: Option<f64>,
    /// Sampled mode: mean over cells of the estimated visible objects no
    /// ray found (Chao1 over the uniform rays, less the probes' finds).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unseen_objects_mean: Option<f64>,
    /// Sampled mode: estimated share of a cell's visible objects that the
    /// rays missed, `unseen / (found + unseen)`, averaged over cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub missed_object_rate: Option<f64>,
    /// Precomputed mode: cells the file does not cover.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncovered_cells: Option<u64>,
}

/// Occluder extraction counters (reported in the placement stats).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct OccluderStats {
    /// Objects with at least one occluder box.
    pub occluder_objects: u64,
    /// Closed (or open-bottom) opaque components found.
    pub solid_components: u64,
    /// Components rejected (open, non-manifold, not opaque, inconsistent winding).
    pub rejected_components: u64,
    /// Boxes inside single solids.
    pub boxes: u64,
    /// Bridges between touching boxes.
    pub bridges: u64,
}

/// What [`generate`] did; part of the placement statistics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LodReport {
    /// Objects given generated levels.
    pub objects: u64,
    /// Objects that already had levels (from the file); left unchanged.
    pub objects_with_file_levels: u64,
    /// Objects with fewer than `min_triangles` triangles; given none.
    pub objects_too_small: u64,
    /// `levels_per_object[k]`: objects with enough triangles and no levels
    /// of their own that were given `k` levels below the full-detail one
    /// (`k = 0` when simplification gave no usable level).
    pub levels_per_object: Vec<u64>,
    /// `triangles[k]`: triangles of the objects given levels, summed, at
    /// level `k` (`k = 0`: full detail, before simplification); an object
    /// with fewer levels counts its coarsest.
    pub triangles: Vec<u64>,
    /// Distinct mesh primitives simplified.
    pub meshes_simplified: u64,
}
