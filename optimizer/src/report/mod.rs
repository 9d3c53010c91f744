//! Memory-versus-frame-time comparison reports (`impostor report`, DESIGN
//! §1, §2.10, §2.11): several placement methods and knob sweeps on one
//! scene and view space, each run checked by the same evaluation, written
//! as a self-contained HTML page with SVG charts plus JSON and CSV data.
//!
//! This module holds the report's data ([`Report`], written as
//! `report.json`); [`render`] turns it into HTML and CSV.

pub mod render;
pub mod run;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::stats::StageTime;

/// A whole report (`report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Report {
    /// Version of the tool that made it.
    pub version: String,
    /// When it was made (UTC, RFC 3339).
    pub created: String,
    /// The machine it ran on.
    pub machine: Machine,
    /// The scene.
    pub scene: SceneInfo,
    /// The base job (every run starts from it), as given.
    pub job: serde_json::Value,
    /// The methods compared, in the order given.
    pub methods: Vec<String>,
    /// The knob sweeps, in the order given.
    pub sweeps: Vec<Sweep>,
    /// Memory budgets as fractions of each method's unbudgeted memory
    /// (`--budgets`): runs with knob `memory.budget_bytes`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub budgets: Vec<f64>,
    /// Every (method, setting) run.
    pub runs: Vec<Run>,
    /// Frame times along a walkthrough path, per (method, target).
    pub walkthroughs: Vec<Walkthrough>,
    /// Stability under perturbed inputs (`--stability`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stability: Option<Stability>,
}

/// The machine a report ran on.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Machine {
    /// Operating system and architecture, e.g. `linux x86_64`.
    pub os: String,
    /// Worker threads used.
    pub threads: usize,
    /// CPU model, when known.
    pub cpu: String,
    /// Total memory, bytes (0 when unknown).
    pub memory_bytes: u64,
}

/// The scene of a report.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SceneInfo {
    /// File name.
    pub name: String,
    /// Objects.
    pub objects: u64,
    /// Triangles.
    pub triangles: u64,
    /// Bounds minimum.
    pub min: [f64; 3],
    /// Bounds maximum.
    pub max: [f64; 3],
}

/// One knob swept over values (`--sweep knob=v1,v2,...`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Sweep {
    /// The knob: a dotted job field (`target_frame_time_ms`,
    /// `problem_views.cell_size`, ...) or a method knob (`env_map.far_m`).
    pub knob: String,
    /// Its values.
    pub values: Vec<f64>,
}

/// Whether a run produced a placement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// Placed and evaluated.
    #[default]
    Ok,
    /// Refused or stopped (the run's `error` says why).
    Failed,
}

impl RunStatus {
    /// The status as in JSON and CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            RunStatus::Ok => "ok",
            RunStatus::Failed => "failed",
        }
    }
}

/// The outcome of one placement run and its evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Run {
    /// The method (`shafts`, `boxes`, `both`, `per-cell`, `env-map`,
    /// `shafts+prune`, `exact`, `dts96`, `iboh`, `hic96`).
    pub method: String,
    /// The swept knob of this run, or `None` for the base job.
    pub knob: Option<String>,
    /// The knob's value in this run.
    pub value: Option<f64>,
    /// The run's target frame time, ms.
    pub target_frame_time_ms: f64,
    /// `ok`, or `failed` (see `error`).
    pub status: RunStatus,
    /// Why the run failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Conservative problem views.
    pub cpvs: u64,
    /// Candidates.
    pub candidates: u64,
    /// Impostors placed.
    pub impostors: u64,
    /// Impostor memory, bytes.
    pub memory_bytes: u64,
    /// Problem views still above the target.
    pub unsolved_cpvs: u64,
    /// How far the worst unsolved problem view's estimate stays above the
    /// target, ms (0 when all are solved).
    #[serde(default)]
    pub max_residual_ms: f64,
    /// The impostor memory budget of the run, bytes, if it had one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_bytes: Option<u64>,
    /// Preprocessing wall time (placement), seconds.
    pub seconds: f64,
    /// Wall time per stage.
    pub stage_seconds: Vec<StageTime>,
    /// The evaluation (absent when the run failed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eval: Option<EvalSummary>,
    /// The `exact` method's program: how it ended, its memory against the
    /// greedy's, its lower bound (absent for other methods).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact: Option<crate::api::stats::ExactStats>,
    /// A runtime cache's figures along the walkthrough (`hic96`, which
    /// places nothing ahead of time and has no `eval`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cache: Option<crate::methods::hic96::PathSummary>,
    /// The impostors as baked, against the placement's memory estimate
    /// (runs that were baked: `impostor report --bake`, the service's
    /// jobs with `"bake": true`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bake: Option<BakeSummary>,
    /// The image check of the run's impostors (`impostor report --images
    /// N`): their footprint mismatch against the geometry they replace.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<ImageSummary>,
}

/// A run's image check, as the report shows it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ImageSummary {
    /// Views compared (each with impostors covering at least the check's
    /// smallest share of the image).
    pub views: u32,
    /// Per view, the share of its footprint pixels whose colour has no
    /// match within one pixel in the render of the geometry: mean, 95th
    /// percentile, largest.
    pub footprint_mismatch: crate::api::evaluation::MismatchSpread,
    /// The same with every layer texel magenta: where it is no larger, the
    /// check proves nothing.
    pub control_mismatch: crate::api::evaluation::MismatchSpread,
    /// Share of the image covered by impostor pixels, mean over the views.
    pub impostor_pixel_fraction: f64,
}

/// A run's impostors as baked against the placement's estimate.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BakeSummary {
    /// Memory of the baked layers under the job's memory model, bytes.
    pub memory_bytes: u64,
    /// The placement's estimate, bytes.
    pub estimated_bytes: u64,
    /// Layers the placement asked for.
    pub layers: u64,
    /// Layers baked (those with at least one covered texel).
    pub layers_written: u64,
    /// Per impostor (the [`BakeSummary::POINTS`] largest estimates): its
    /// estimated and its baked memory.
    pub points: Vec<BakePoint>,
}

/// One impostor's estimated and baked memory.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BakePoint {
    /// The placement's impostor id.
    pub impostor: u32,
    /// The placement's estimate, bytes.
    pub estimated_bytes: u64,
    /// As baked, bytes.
    pub baked_bytes: u64,
}

impl BakeSummary {
    /// The most impostors a summary lists.
    pub const POINTS: usize = 2000;

    /// The summary of `bake`, a bake of `placement`.
    pub fn new(
        placement: &crate::api::placement::Placement,
        bake: &crate::bake::BakeReport,
    ) -> Self {
        let mut points: Vec<BakePoint> = placement
            .impostors
            .iter()
            .enumerate()
            .map(|(i, imp)| BakePoint {
                impostor: i as u32,
                estimated_bytes: imp.memory_bytes,
                baked_bytes: bake.impostor_memory_bytes.get(i).copied().unwrap_or(0),
            })
            .collect();
        points.sort_by(|a, b| {
            b.estimated_bytes
                .cmp(&a.estimated_bytes)
                .then(a.impostor.cmp(&b.impostor))
        });
        points.truncate(Self::POINTS);
        BakeSummary {
            memory_bytes: bake.memory_bytes,
            estimated_bytes: bake.placement_memory_bytes,
            layers: bake.layers,
            layers_written: bake.layers_written,
            points,
        }
    }
}

/// The independent evaluation of one run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EvalSummary {
    /// Views sampled.
    pub views: u64,
    /// Largest view time, ms.
    pub max_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Median, ms.
    pub p50_ms: f64,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Views over the target.
    pub violations: u64,
    /// Views over the target in solved problem views or in none (must be
    /// 0: the guarantee).
    pub violations_in_solved: u64,
    /// Largest view time among views in solved problem views or in none, ms.
    pub max_ms_in_solved: f64,
    /// Views sampled inside problem views.
    #[serde(default)]
    pub cpv_views: u64,
    /// Views inside solved problem views over the target (must be 0).
    #[serde(default)]
    pub violations_in_cpv_views: u64,
    /// The control: views in solved problem views (or in none, or sampled
    /// inside solved problem views) over the target with every impostor
    /// removed. 0 means the run's check could not have failed.
    #[serde(default)]
    pub control_violations: u64,
    /// Largest measured parallax of an impostor, pixels (none without
    /// impostors).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parallax_max_px: Option<f64>,
    /// The run's estimates against exact times sampled in its problem
    /// views, with at most [`REPORT_ESTIMATE_POINTS`] of them (absent when
    /// no sampled view lay in a problem view).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimates: Option<crate::api::evaluation::EstimateCheck>,
}

/// The most problem views a report keeps per run for its estimate chart
/// (the most sampled ones).
pub const REPORT_ESTIMATE_POINTS: usize = 400;

impl EvalSummary {
    /// Views that broke the guarantee: over the target in solved problem
    /// views (uniform or sampled inside them) or in none.
    pub fn guarantee_violations(&self) -> u64 {
        self.violations_in_solved + self.violations_in_cpv_views
    }
}

impl From<&crate::api::evaluation::Evaluation> for EvalSummary {
    fn from(e: &crate::api::evaluation::Evaluation) -> Self {
        EvalSummary {
            views: e.views,
            max_ms: e.max_ms,
            p99_ms: e.p99_ms,
            p50_ms: e.p50_ms,
            mean_ms: e.mean_ms,
            violations: e.violations,
            violations_in_solved: e.violations_in_solved,
            max_ms_in_solved: e.max_ms_in_solved,
            cpv_views: e.cpv_views,
            violations_in_cpv_views: e.violations_in_cpv_views,
            control_violations: e.control.violations_in_solved + e.control.violations_in_cpv_views,
            parallax_max_px: e.parallax.as_ref().map(|p| p.max_px),
            estimates: e.estimates.clone().map(|mut x| {
                x.points.truncate(REPORT_ESTIMATE_POINTS);
                x
            }),
        }
    }
}

/// Frame times along a walkthrough path.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Walkthrough {
    /// The method.
    pub method: String,
    /// The target frame time, ms.
    pub target_frame_time_ms: f64,
    /// Frame time of each frame along the path, ms.
    pub frame_ms: Vec<f64>,
    /// The same frames with no impostor, ms (empty in reports of older
    /// versions).
    #[serde(default)]
    pub bare_ms: Vec<f64>,
    /// The placement's estimate for the problem view of each frame, ms
    /// (with its impostors; `null` where the frame lies in no problem
    /// view).
    #[serde(default)]
    pub estimate_ms: Vec<Option<f64>>,
}

/// Stability of each method under perturbed inputs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Stability {
    /// Per method.
    pub methods: Vec<MethodStability>,
}

/// One method's results under each perturbation and their spread.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MethodStability {
    /// The method.
    pub method: String,
    /// One entry per perturbation (the first is the unperturbed base).
    pub settings: Vec<Perturbed>,
    /// Spread of impostor memory over the settings, bytes.
    pub memory: Spread,
    /// Spread of the impostor count over the settings.
    pub impostors: Spread,
}

/// A run under one perturbation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Perturbed {
    /// What was perturbed, e.g. `target +5%`, `grid shifted 0.5 cell`,
    /// `objects shuffled (seed 2)`.
    pub label: String,
    /// `ok` or `failed`.
    pub status: RunStatus,
    /// Impostor memory, bytes.
    pub memory_bytes: u64,
    /// Impostors.
    pub impostors: u64,
    /// Unsolved problem views.
    pub unsolved_cpvs: u64,
    /// Largest evaluated view time, ms (0 when not evaluated).
    pub max_ms: f64,
}

/// Minimum, maximum, mean and relative spread of a quantity.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Spread {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Mean.
    pub mean: f64,
    /// Standard deviation over the mean (0 when the mean is 0).
    pub relative_std: f64,
}
