//! The evaluation report (`impostor evaluate`, `schemas/evaluation.schema.json`):
//! what the independent check measured.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::job::VisibilityMode;

impl Evaluation {
    /// True when the check found the guarantee broken: a view over the
    /// target in a solved problem view (uniform or sampled inside one) or
    /// in none, or an impostor used outside its view cell.
    pub fn guarantee_broken(&self) -> bool {
        self.violations_in_solved > 0
            || self.violations_in_cpv_views > 0
            || self.impostors_outside_view_cell > 0
    }

    /// True when the control (the same views with no impostor) breaks the
    /// target where the placement claims to meet it: only then could this
    /// check have failed.
    pub fn control_bites(&self) -> bool {
        self.control.violations_in_solved > 0 || self.control.violations_in_cpv_views > 0
    }
}

/// The evaluation's control: the same views, the same visible sets, every
/// impostor removed (`evaluation.control`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ControlCheck {
    /// Uniform views over the target without impostors.
    pub violations: u64,
    /// Uniform views over the target without impostors whose problem view
    /// is solved (or that lie in none): what `violations_in_solved` would
    /// be if the impostors did nothing.
    pub violations_in_solved: u64,
    /// Views inside solved problem views over the target without
    /// impostors: what `violations_in_cpv_views` would be if the impostors
    /// did nothing.
    pub violations_in_cpv_views: u64,
    /// Largest time of any sampled view without impostors, ms.
    pub max_ms: f64,
}

/// The check of the visible sets (`evaluation.visibility`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VisibilityCheck {
    /// The job's visibility mode.
    pub mode: VisibilityMode,
    /// Grid cells the sampled views lie in.
    pub cells: u64,
    /// Mean size of the visible set of a view's cell.
    pub mean_visible_objects: f64,
    /// Mean share of the scene's objects in a view's visible set.
    pub mean_visible_fraction: f64,
    /// Views whose visible set was checked by ray casting (0 without
    /// geometry).
    pub views_checked: u64,
    /// Rays cast for the check.
    pub rays: u64,
    /// (view, object) pairs where a ray from the view point reached an
    /// object that is not in the view's visible set. Must be 0 in
    /// conservative mode.
    pub missed_objects: u64,
    /// Views with at least one missed object.
    pub views_with_misses: u64,
    /// Missed objects found by the image-grid rays.
    pub missed_by_image_rays: u64,
    /// Missed objects found by rays aimed at culled objects.
    pub missed_by_probe_rays: u64,
    /// The first few misses (by view index).
    pub examples: Vec<MissedObject>,
}

/// An object seen from a view point but missing from the view's visible set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MissedObject {
    /// Index of the sampled view.
    pub view: u64,
    /// The view point.
    pub eye: [f64; 3],
    /// The object id.
    pub object: u32,
}

/// The evaluation report (`eval.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Evaluation {
    /// Views sampled.
    pub views: u64,
    /// Seed of the sampler.
    pub seed: u64,
    /// The target frame time, ms.
    pub target_frame_time_ms: f64,
    /// Largest view time, ms.
    pub max_ms: f64,
    /// Median view time, ms.
    pub p50_ms: f64,
    /// 99th percentile view time, ms.
    pub p99_ms: f64,
    /// Mean view time, ms.
    pub mean_ms: f64,
    /// Views over the target.
    pub violations: u64,
    /// Views over the target whose CPV is solved or that lie in no CPV: must
    /// be 0 for every placement.
    pub violations_in_solved: u64,
    /// Largest view time among views whose CPV is solved or in no CPV, ms.
    pub max_ms_in_solved: f64,
    /// Views that lie in some CPV.
    pub views_in_cpvs: u64,
    /// Views that lie in an unsolved CPV.
    pub views_in_unsolved_cpvs: u64,
    /// Views (uniform or inside problem views) where an impostor of their
    /// CPV was used outside its view cell (must be 0).
    pub impostors_outside_view_cell: u64,
    /// Mean of `target − time` over views within the target, ms
    /// (over-conservativeness).
    pub mean_slack_ms: f64,
    /// Views sampled inside problem views (`--cpv-views`): where the
    /// placement needed impostors.
    pub cpv_views: u64,
    /// Of them, views whose problem view is unsolved.
    pub cpv_views_in_unsolved: u64,
    /// Views inside solved problem views over the target: must be 0.
    pub violations_in_cpv_views: u64,
    /// Largest time among the views inside solved problem views, ms.
    pub max_ms_in_cpv_views: f64,
    /// The same views timed with no impostor: where the control has no
    /// violation either, the check could not have failed and proves
    /// nothing about the impostors.
    pub control: ControlCheck,
    /// Image error of the impostors (`evaluate --images N`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<ImageReport>,
    /// The visibility used and its check (absent without visibility).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility: Option<VisibilityCheck>,
    /// Geometric parallax of the impostors (absent without impostors).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parallax: Option<ParallaxCheck>,
    /// The placement's estimated problem-view times against the exact
    /// times of the views sampled in them (absent when no sampled view
    /// lies in a problem view).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimates: Option<EstimateCheck>,
}

/// Estimate against truth (`evaluation.estimates`): each problem view's
/// estimated time (conservative: no view of it should take longer)
/// against the largest exact time among the sampled views (uniform and
/// inside problem views) that lie in it, without impostors and with the
/// placement's. The gap decides how much memory is spent: impostors are
/// bought for the estimate's excess over the target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstimateCheck {
    /// Problem views with at least one sampled view.
    pub cpvs_sampled: u64,
    /// Median over them of the largest sampled exact time without
    /// impostors over the estimate without impostors (at most 1 where the
    /// estimate is conservative; the smaller, the more memory is spent on
    /// the estimate's excess).
    pub ratio_original_median: f64,
    /// The same ratio with the placement's impostors, against the
    /// estimate with them.
    pub ratio_final_median: f64,
    /// Sampled problem views none of whose sampled views exceeds the
    /// target without impostors: as far as the samples show, their
    /// impostors were bought for the estimate's excess alone.
    pub cpvs_never_over: u64,
    /// Up to 2,000 of the sampled problem views, the most sampled first
    /// (ties by id).
    pub points: Vec<EstimatePoint>,
}

/// One problem view of [`EstimateCheck`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstimatePoint {
    /// The problem view's id.
    pub cpv: u32,
    /// Sampled views in it.
    pub views: u32,
    /// Its estimated time without impostors, ms.
    pub estimate_ms: f64,
    /// The largest exact time of its sampled views without impostors, ms.
    pub exact_max_ms: f64,
    /// Its estimated time with the placement's impostors, ms.
    pub estimate_final_ms: f64,
    /// The largest exact time of its sampled views with them, ms.
    pub exact_final_max_ms: f64,
}

/// The image quality criterion checked geometrically for every impostor
/// (`evaluation.parallax`): how far a point of the cluster and its image
/// on its layer lie apart, seen from viewpoints of the view cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ParallaxCheck {
    /// The job's error budget, pixels.
    pub max_error_px: f64,
    /// Impostors checked.
    pub impostors: u64,
    /// Sphere points per impostor, each seen from every sampled viewpoint.
    pub points: u32,
    /// Viewpoints per impostor.
    pub viewpoints: u32,
    /// Largest error over all impostors, pixels.
    pub max_px: f64,
    /// Mean over impostors of their largest error, pixels.
    pub mean_px: f64,
    /// Impostors whose largest error exceeds the budget.
    pub over_budget: u64,
    /// Impostors whose largest error exceeds 1.5 times the budget.
    pub over_budget_1_5: u64,
    /// The impostor with the largest error.
    pub worst_impostor: u32,
    /// Impostors valid from every direction (view cells with a half-angle
    /// of 180°, such as `iboh`'s warped images), whose error the layered
    /// parallax bound does not describe: not checked.
    #[serde(default)]
    pub view_independent: u64,
}

/// Mean and minimum of a per-view PSNR.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PsnrSpread {
    /// Mean over the views, dB.
    pub mean: f64,
    /// The worst (smallest) view, dB.
    pub min: f64,
}

/// Mean, 95th percentile and maximum of a per-view mismatch fraction.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MismatchSpread {
    /// Mean over the views.
    pub mean: f64,
    /// 95th percentile over the views (nearest rank).
    #[serde(default)]
    pub p95: f64,
    /// The worst (largest) view.
    pub max: f64,
}

/// The worst view of an image comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WorstView {
    /// Index of the view among the sampled ones.
    pub view: u32,
    /// The CPV it lies in.
    pub cpv: u32,
    /// Eye position.
    pub eye: [f64; 3],
    /// Unit view direction.
    pub direction: [f64; 3],
    /// Its mismatch fraction (over its impostor pixels).
    pub mismatch_fraction: f64,
    /// Share of its image covered by impostor pixels.
    pub impostor_pixel_fraction: f64,
    /// Its PSNR over the impostor pixels, dB.
    pub psnr_db: f64,
}

/// The image comparison report (`image` in `eval.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ImageReport {
    /// Views compared: views whose impostor pixels cover at least
    /// `min_coverage` of the image; 0 when no CPV has impostors.
    pub views: u32,
    /// Views sampled but left out because their impostors cover less than
    /// `min_coverage` of the image (they would only dilute the figures).
    pub views_below_coverage: u32,
    /// Seed of the view sampler.
    pub seed: u64,
    /// Per-channel colour tolerance (0–255) of the mismatch test.
    pub tolerance: u8,
    /// Image size, pixels.
    pub resolution: [u32; 2],
    /// The smallest share of the image a view's impostor pixels must cover
    /// for the view to be compared.
    pub min_coverage: f64,
    /// PSNR over RGB of the impostor pixels, dB (capped at 100 for
    /// identical images).
    pub psnr_db: PsnrSpread,
    /// Per view, the share of its footprint pixels — the impostor pixels,
    /// where the replaced geometry was drawn or the layers draw — whose
    /// colour has no match within one pixel in the other image (formerly
    /// `mismatch_fraction`).
    #[serde(alias = "mismatch_fraction")]
    pub footprint_mismatch_fraction: MismatchSpread,
    /// Share of the image covered by impostor pixels, mean over the
    /// compared views.
    pub impostor_pixel_fraction: f64,
    /// The largest share of the image any impostor's bounding disc can
    /// cover from a problem view that uses it (seen from the point of the
    /// view's region nearest to it, as the cost model counts pixels): an
    /// upper bound of what one impostor can show. Below `min_coverage`, no
    /// single impostor can make a view count.
    #[serde(default)]
    pub largest_impostor_fraction: f64,
    /// The control: the same views with every layer texel magenta (its
    /// coverage kept). Where it mismatches no more than the impostors, the
    /// check proves nothing about their images.
    pub control_mismatch_fraction: MismatchSpread,
    /// The compared view with the largest mismatch fraction.
    pub worst_view: Option<WorstView>,
}
