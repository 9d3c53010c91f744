//! The job: view space, camera, frame-time target, cost model and the knobs of
//! every stage (`schemas/job.schema.json`). Every field but `view_space` has
//! the paper's reference value as its default.

use glam::DVec3;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::texture_format::TextureFormat;
use crate::math::grid::Grid;

mod methods;
mod validate;

pub use methods::{
    Al99Params, Dts96Params, EnvMapParams, ExactParams, IbohParams, Method, PerCellParams,
};

/// A placement job.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Job {
    /// The region the camera can move in and the view directions it may take.
    pub view_space: ViewSpace,
    /// Field of view and output resolution, fixed for all views.
    #[serde(default)]
    pub camera: Camera,
    /// Maximum frame time `t_max` every view must meet, milliseconds. Default 16.
    #[serde(default = "default_t_max")]
    pub target_frame_time_ms: f64,
    /// Image quality criterion: maximum screen-space error of an impostor,
    /// pixels. Default 1.
    #[serde(default = "default_max_error")]
    pub max_error_px: f64,
    /// Rendering-time estimation.
    #[serde(default)]
    pub cost_model: CostModelParams,
    /// Problem view space approximation.
    #[serde(default)]
    pub problem_views: ProblemViewParams,
    /// Impostor candidate generation.
    #[serde(default)]
    pub candidates: CandidateParams,
    /// Impostor memory model.
    #[serde(default)]
    pub memory: MemoryParams,
    /// From-region visibility applied before impostors (paper §3.1,
    /// observation 2.3): `"none"` (default), `"conservative"`, `"sampled"` or
    /// `"precomputed"`, or an object with `mode` and the mode's knobs.
    #[serde(default, deserialize_with = "de_visibility")]
    #[schemars(with = "VisibilityWire")]
    pub visibility: VisibilityParams,
    /// Levels of detail applied before impostors.
    #[serde(default)]
    pub lod: LodParams,
    /// The placement method. Default: the paper's, with the view-cell
    /// shapes of `candidates.view_cells` (shafts).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<Method>,
    /// The `per-cell` method's knobs.
    #[serde(default)]
    pub per_cell: PerCellParams,
    /// The `env-map` method's knobs.
    #[serde(default)]
    pub env_map: EnvMapParams,
    /// The `exact` method's knobs.
    #[serde(default)]
    pub exact: ExactParams,
    /// The `dts96` method's knobs.
    #[serde(default)]
    pub dts96: Dts96Params,
    /// The `iboh` method's knobs.
    #[serde(default)]
    pub iboh: IbohParams,
    /// The `al99` method's knobs.
    #[serde(default)]
    pub al99: Al99Params,
    /// A walkthrough path for frame-time plots (`impostor report`); default:
    /// a loop through the view space.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub walkthrough: Option<WalkthroughParams>,
    /// Split the view space into tiles placed one after another (each a job
    /// of its own over its part of the view space, on the same grid) and
    /// merge their placements; absent: one placement of the whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partition: Option<Partition>,
}

/// How a job's view space is split into tiles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Partition {
    /// Tiles along x and z `[nx, nz]`, each 1–64; tile boundaries are grid
    /// boundaries (fewer tiles where the grid has fewer cells).
    pub tiles: [u32; 2],
}

/// A walkthrough path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WalkthroughParams {
    /// Points of the path `[x, y, z]` (at least two); the camera moves along
    /// the polyline looking ahead.
    pub points: Vec<[f64; 3]>,
    /// Frames along the path. Default 1000.
    #[serde(default = "default_frames")]
    pub frames: u32,
}

/// How the visible objects of a view region are found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum VisibilityMode {
    /// Every object may be visible from everywhere.
    #[default]
    None,
    /// Conservative from-region visibility: closed, opaque objects occlude;
    /// nothing visible is ever culled.
    Conservative,
    /// Aggressive visibility by ray sampling: objects no sampled ray reaches
    /// are culled; the expected share of missed objects is reported.
    Sampled,
    /// A precomputed PVS file given with the scene (`--pvs`).
    Precomputed,
}

/// From-region visibility parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VisibilityParams {
    /// The mode. Default `none`.
    #[serde(default)]
    pub mode: VisibilityMode,
    /// Conservative mode: the largest spacing of the sample points in a view
    /// cell, metres; occluders shrink by half the actual spacing per axis.
    /// Default 6.
    #[serde(default = "default_sample_spacing")]
    pub sample_spacing_m: f64,
    /// Sampled mode: rays cast from each view cell. Default 8192.
    #[serde(default = "default_rays")]
    pub rays_per_region: u32,
    /// Sampled mode: rays aimed at each object no uniform ray found, from
    /// random points of the cell to random points on its surface. Default 2.
    #[serde(default = "default_probes")]
    pub probes_per_object: u32,
    /// Sampled mode: seed of the ray sampler. Default 1.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// View regions of at most this many grid cells get a visible set (the
    /// union of their cells'); larger regions count every object. Default 16.
    #[serde(default = "default_region_cells")]
    pub max_region_cells: u32,
}

/// The two accepted forms of the `visibility` field.
#[derive(JsonSchema)]
#[serde(untagged)]
#[allow(dead_code)] // only its schema is used; `de_visibility` parses both forms
enum VisibilityWire {
    /// Just the mode, every knob at its default.
    Mode(VisibilityMode),
    /// The mode and its knobs.
    Params(VisibilityParams),
}

/// Reads `visibility` as a bare mode or as an object.
fn de_visibility<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<VisibilityParams, D::Error> {
    use serde::de::Error as _;
    let v = serde_json::Value::deserialize(d)?;
    if v.is_string() {
        let mode: VisibilityMode = serde_json::from_value(v).map_err(|e| {
            D::Error::custom(format!(
                "visibility: {e} (expected none, conservative, sampled or precomputed)"
            ))
        })?;
        return Ok(VisibilityParams {
            mode,
            ..VisibilityParams::default()
        });
    }
    serde_json::from_value(v).map_err(|e| D::Error::custom(format!("visibility: {e}")))
}

/// Levels-of-detail parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LodParams {
    /// Use the levels of detail the scene carries (glTF `MSFT_lod`). Default true.
    #[serde(default = "default_true")]
    pub enabled: bool,
    /// Generate levels by mesh simplification for objects without levels;
    /// needs a scene with geometry. Default false.
    #[serde(default)]
    pub generate: bool,
    /// Generated levels below the full-detail one. Default 3.
    #[serde(default = "default_lod_levels")]
    pub levels: u32,
    /// Each generated level keeps this fraction of the previous level's
    /// triangles. Default 0.5.
    #[serde(default = "default_lod_ratio")]
    pub ratio: f64,
    /// Objects with fewer triangles get no generated levels. Default 256.
    #[serde(default = "default_lod_min_triangles")]
    pub min_triangles: u64,
}

/// View space: a box of viewpoints and a pitch range of view directions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ViewSpace {
    /// Box minimum `[x, y, z]`, metres.
    pub min: [f64; 3],
    /// Box maximum `[x, y, z]`, metres.
    pub max: [f64; 3],
    /// Allowed elevation of view directions `[lo, hi]`, degrees in −90…90.
    /// Default `[-90, 90]` (the full sphere).
    #[serde(default = "default_pitch")]
    pub pitch_deg: [f64; 2],
}

/// Camera: vertical field of view and output resolution.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Vertical field of view, degrees. Default 45.
    #[serde(default = "default_fov")]
    pub fov_deg: f64,
    /// Output resolution `[width, height]`, pixels. Default `[512, 512]`.
    #[serde(default = "default_resolution")]
    pub resolution: [u32; 2],
}

/// How per-object costs combine into a frame time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Combine {
    /// `frame + Σ (calls + triangles + pixels)`: conservative, the default.
    Sum,
    /// `frame + max(CPU, GPU)` with CPU = draw calls, GPU = triangles + pixels.
    Max,
    /// `frame + triangles · triangle_ns`: a primitive budget.
    Primitives,
}

/// Rendering-time estimation constants (Wimmer & Wonka 2003 style). The
/// defaults describe a draw-call-bound renderer, as in the paper's Vienna test.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CostModelParams {
    /// Fixed cost per frame (clear, swap, setup), milliseconds. Default 2.
    #[serde(default = "default_frame_ms")]
    pub frame_ms: f64,
    /// Cost per draw call, microseconds. Default 1.25.
    #[serde(default = "default_draw_call_us")]
    pub draw_call_us: f64,
    /// Cost per triangle, nanoseconds. Default 0.5.
    #[serde(default = "default_triangle_ns")]
    pub triangle_ns: f64,
    /// Cost per rasterised pixel, nanoseconds. Default 0.02.
    #[serde(default = "default_pixel_ns")]
    pub pixel_ns: f64,
    /// How costs combine. Default `sum`.
    #[serde(default = "default_combine")]
    pub combine: Combine,
}

/// Problem view space approximation (paper §3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProblemViewParams {
    /// Largest side of a CPV's 3D region, metres. Default 23.
    #[serde(default = "default_cell_size")]
    pub cell_size: f64,
    /// Minimum angular size of a view-direction interval, degrees. Default 11.25.
    #[serde(default = "default_min_vdi")]
    pub min_vdi_deg: f64,
    /// How many levels below `min_vdi_deg` a problem view's directions are
    /// refined before it is kept: each level splits its VDI in four. A
    /// problem view all of whose parts meet the target is proven and
    /// dropped; one that is kept keeps its own (coarse) estimate. A problem
    /// view whose estimate is at most 20 % above the target is refined one
    /// level more (where it may still be proven; one far above is a real
    /// problem). 0 turns refinement off. Default 3, at most 4.
    #[serde(default = "default_refine_levels")]
    pub refine_levels: u8,
    /// How many times a problem cell is halved (along its sides at least
    /// half as long as its longest) to find where its problem views may
    /// exceed the target: parts proven within the target (with the
    /// directions refined `refine_levels` levels) are left out, a problem
    /// view all of whose parts are proven is dropped, and the CPVs of a cell
    /// get the smallest box holding its unproven parts as their region.
    /// Needs `refine_levels` above 0; 0 turns it off (regions are cells).
    /// Default 2, at most 3.
    #[serde(default = "default_split_levels")]
    pub split_levels: u8,
    /// Where the cell grid is anchored, metres: cell boundaries lie at
    /// `grid_origin + k·cell_size` on each axis (clipped to the view space),
    /// so a view space grown or shrunk at one side keeps its other cells.
    /// Default `[0, 0, 0]`.
    #[serde(default, skip_serializing_if = "is_zero3")]
    pub grid_origin: [f64; 3],
}

fn is_zero3(v: &[f64; 3]) -> bool {
    *v == [0.0; 3]
}

/// Which view-cell shapes make candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ViewCellKind {
    /// Shafts around the cluster (the paper's reference).
    Shafts,
    /// Boxes of the 3D view space hierarchy.
    Boxes,
    /// Both.
    Both,
}

/// Impostor candidate generation (paper §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CandidateParams {
    /// View-cell shapes. Default `shafts`.
    #[serde(default = "default_view_cells")]
    pub view_cells: ViewCellKind,
    /// Shaft apex angles (full cone angles), degrees. Default `[11.25, 22.5, 45, 90]`.
    #[serde(default = "default_apex")]
    pub apex_angles_deg: Vec<f64>,
    /// Angular step of shaft axis directions (azimuth, and elevation when the
    /// view space has height), degrees. Default 11.25.
    #[serde(default = "default_dir_step")]
    pub direction_step_deg: f64,
    /// Spacing of the axes of a shaft of half-angle `α`, as a fraction of
    /// `α`: axes `max(direction_step_deg, axis_spacing · α)` apart, with
    /// fewer azimuths on rings of higher elevation (equal spacing over the
    /// sphere). Wide shafts on a fine grid overlap their neighbours almost
    /// wholly; spacing them in proportion to their width keeps the choice of
    /// which cells a shaft serves while listing each cell under fewer
    /// shafts. At 1, every direction lies within about `α/√2` of an axis
    /// (at most 0.75 α). 0 puts every angle on the `direction_step_deg`
    /// grid. Default 1.
    #[serde(default = "default_axis_spacing")]
    pub axis_spacing: f64,
    /// Shaft minimum distances range from `size` to `size · 2^doublings`, with
    /// size the cluster's diameter. Default 10.
    #[serde(default = "default_doublings")]
    pub min_distance_doublings: u32,
    /// Shaft minimum distances per doubling: `size · 2^(k/steps)` for
    /// `k = 0..=steps·doublings`. The paper uses 1; finer steps let a shaft
    /// leave out nearer cells it need not serve (less memory, more
    /// candidates). Default 4.
    #[serde(default = "default_distance_steps")]
    pub min_distance_steps: u32,
}

/// Impostor memory model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MemoryParams {
    /// Bytes per texel. Default 4 (RGBA8).
    #[serde(default = "default_bpt")]
    pub bytes_per_texel: f64,
    /// Count a mip chain (× 4/3). Default true.
    #[serde(default = "default_true")]
    pub mipmaps: bool,
    /// Largest texture side per layer, texels; a candidate that needs more
    /// cannot meet the quality criterion and is dropped. Default 2048.
    #[serde(default = "default_max_tex")]
    pub max_texture_size: u32,
    /// Texels per screen pixel at an impostor's closest viewpoint (per
    /// side). Default 1: a texel is a pixel there, as the design's
    /// resolution formula says. More keeps what the geometry shows through
    /// the bilinear resampling of the layers, which the bake's sharpening
    /// only partly offsets (`evaluate --images` measures it), at that
    /// factor squared in memory.
    #[serde(default = "default_texels_per_pixel")]
    pub texels_per_pixel: f64,
    /// The format impostor atlases are baked in (`png` or `ktx2`). When
    /// given, its GPU bytes per texel (png 4, ktx2 1: UASTC as ASTC 4×4 or
    /// BC7) replace `bytes_per_texel` in the memory model, and `bake` writes
    /// it by default. Default: none (`bytes_per_texel` counts, `bake`
    /// writes PNG).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_format: Option<TextureFormat>,
    /// The most impostor memory the placement may use, bytes (`None`: no
    /// limit). The greedy then adds the candidates with the best frame-time
    /// gain per byte that still fit; CPVs it cannot solve within the budget
    /// are reported unsolved (`budget_exhausted`) with their residual times.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_bytes: Option<u64>,
    /// Whether impostors that help only CPVs left above the target are
    /// kept. Such an impostor makes those views faster without bringing any
    /// of them within the target; where most problem views cannot be
    /// solved (display resolutions, where an impostor's texels and fill
    /// grow with the pixels and the geometry's cost does not) they take
    /// most of the memory. Not kept, the greedy is made again with the
    /// CPVs it left above the target given up (where they are more than
    /// 1 % of the CPVs), then every impostor that solves no CPV it is used
    /// in is dropped: the unsolved CPVs draw that geometry again and report
    /// the higher residual times; an impostor also used by a CPV within the
    /// target is always kept. Default: kept with `budget_bytes` (the budget
    /// is spent on frame time), not kept without.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keep_partial: Option<bool>,
}

impl MemoryParams {
    /// Whether impostors that help only unsolved CPVs are kept
    /// (`keep_partial`, by default whether a budget is given).
    pub fn keeps_partial(&self) -> bool {
        self.keep_partial.unwrap_or(self.budget_bytes.is_some())
    }
}

fn default_t_max() -> f64 {
    16.0
}
fn default_max_error() -> f64 {
    1.0
}
fn default_pitch() -> [f64; 2] {
    [-90.0, 90.0]
}
fn default_fov() -> f64 {
    45.0
}
fn default_resolution() -> [u32; 2] {
    [512, 512]
}
fn default_frame_ms() -> f64 {
    2.0
}
fn default_draw_call_us() -> f64 {
    1.25
}
fn default_triangle_ns() -> f64 {
    0.5
}
fn default_pixel_ns() -> f64 {
    0.02
}
fn default_combine() -> Combine {
    Combine::Sum
}
fn default_cell_size() -> f64 {
    23.0
}
fn default_min_vdi() -> f64 {
    11.25
}
fn default_split_levels() -> u8 {
    2
}

fn default_refine_levels() -> u8 {
    3
}
fn default_view_cells() -> ViewCellKind {
    ViewCellKind::Shafts
}
fn default_apex() -> Vec<f64> {
    vec![11.25, 22.5, 45.0, 90.0]
}
fn default_dir_step() -> f64 {
    11.25
}
fn default_axis_spacing() -> f64 {
    1.0
}
fn default_doublings() -> u32 {
    10
}

fn default_distance_steps() -> u32 {
    4
}
fn default_bpt() -> f64 {
    4.0
}
fn default_true() -> bool {
    true
}
fn default_max_tex() -> u32 {
    2048
}
fn default_texels_per_pixel() -> f64 {
    1.0
}
fn default_sample_spacing() -> f64 {
    6.0
}
fn default_rays() -> u32 {
    8192
}
fn default_seed() -> u64 {
    1
}
fn default_probes() -> u32 {
    2
}
fn default_region_cells() -> u32 {
    16
}
fn default_frames() -> u32 {
    1000
}
fn default_lod_levels() -> u32 {
    3
}
fn default_lod_ratio() -> f64 {
    0.5
}
fn default_lod_min_triangles() -> u64 {
    256
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            fov_deg: default_fov(),
            resolution: default_resolution(),
        }
    }
}

impl Default for CostModelParams {
    fn default() -> Self {
        CostModelParams {
            frame_ms: default_frame_ms(),
            draw_call_us: default_draw_call_us(),
            triangle_ns: default_triangle_ns(),
            pixel_ns: default_pixel_ns(),
            combine: default_combine(),
        }
    }
}

impl Default for ProblemViewParams {
    fn default() -> Self {
        ProblemViewParams {
            cell_size: default_cell_size(),
            min_vdi_deg: default_min_vdi(),
            refine_levels: default_refine_levels(),
            split_levels: default_split_levels(),
            grid_origin: [0.0; 3],
        }
    }
}

impl Default for CandidateParams {
    fn default() -> Self {
        CandidateParams {
            view_cells: default_view_cells(),
            apex_angles_deg: default_apex(),
            direction_step_deg: default_dir_step(),
            axis_spacing: default_axis_spacing(),
            min_distance_doublings: default_doublings(),
            min_distance_steps: default_distance_steps(),
        }
    }
}

impl Default for MemoryParams {
    fn default() -> Self {
        MemoryParams {
            bytes_per_texel: default_bpt(),
            mipmaps: default_true(),
            max_texture_size: default_max_tex(),
            texels_per_pixel: default_texels_per_pixel(),
            texture_format: None,
            budget_bytes: None,
            keep_partial: None,
        }
    }
}

impl Default for VisibilityParams {
    fn default() -> Self {
        VisibilityParams {
            mode: VisibilityMode::None,
            sample_spacing_m: default_sample_spacing(),
            rays_per_region: default_rays(),
            probes_per_object: default_probes(),
            seed: default_seed(),
            max_region_cells: default_region_cells(),
        }
    }
}

impl Default for LodParams {
    fn default() -> Self {
        LodParams {
            enabled: true,
            generate: false,
            levels: default_lod_levels(),
            ratio: default_lod_ratio(),
            min_triangles: default_lod_min_triangles(),
        }
    }
}

/// Upper bound on the number of 3D cells of the problem view space grid; more
/// would not finish in reasonable time or memory.
pub const MAX_CELLS: f64 = 1.0e6;

impl Job {
    /// A job with the given view space and every other field at its default.
    pub fn with_view_space(min: [f64; 3], max: [f64; 3]) -> Self {
        Job {
            view_space: ViewSpace {
                min,
                max,
                pitch_deg: default_pitch(),
            },
            camera: Camera::default(),
            target_frame_time_ms: default_t_max(),
            max_error_px: default_max_error(),
            cost_model: CostModelParams::default(),
            problem_views: ProblemViewParams::default(),
            candidates: CandidateParams::default(),
            memory: MemoryParams::default(),
            visibility: VisibilityParams::default(),
            lod: LodParams::default(),
            method: None,
            per_cell: PerCellParams::default(),
            env_map: EnvMapParams::default(),
            exact: ExactParams::default(),
            dts96: Dts96Params::default(),
            iboh: IbohParams::default(),
            al99: Al99Params::default(),
            walkthrough: None,
            partition: None,
        }
    }

    /// The placement method: `method`, or the paper's with the shapes of
    /// `candidates.view_cells`.
    pub fn method(&self) -> Method {
        self.method.unwrap_or(match self.candidates.view_cells {
            ViewCellKind::Shafts => Method::Shafts,
            ViewCellKind::Boxes => Method::Boxes,
            ViewCellKind::Both => Method::Both,
        })
    }

    /// View space minimum as a vector.
    pub fn vs_min(&self) -> DVec3 {
        DVec3::from_array(self.view_space.min)
    }

    /// View space maximum as a vector.
    pub fn vs_max(&self) -> DVec3 {
        DVec3::from_array(self.view_space.max)
    }

    /// The grid of minimum cells over the view space: boundaries at
    /// `grid_origin + k·cell_size` inside it (at least 1 cell per axis).
    pub fn grid(&self) -> Grid {
        Grid::new(
            self.vs_min(),
            self.vs_max(),
            self.problem_views.cell_size,
            DVec3::from_array(self.problem_views.grid_origin),
        )
    }

    /// Angle one pixel subtends at the screen centre, radians:
    /// `θ = 2·tan(fovy/2)/H`.
    pub fn pixel_angle(&self) -> f64 {
        2.0 * (self.camera.fov_deg.to_radians() * 0.5).tan() / f64::from(self.camera.resolution[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> crate::Result<Job> {
        Job::from_json(s.as_bytes(), "job.json")
    }

    #[test]
    fn defaults_are_the_papers_reference_values() {
        let j = parse(r#"{"view_space":{"min":[0,1.5,0],"max":[100,2,100]}}"#).unwrap();
        assert_eq!(j.target_frame_time_ms, 16.0);
        assert_eq!(j.camera.fov_deg, 45.0);
        assert_eq!(j.camera.resolution, [512, 512]);
        assert_eq!(j.problem_views.cell_size, 23.0);
        assert_eq!(j.problem_views.min_vdi_deg, 11.25);
        assert_eq!(j.problem_views.refine_levels, 3);
        assert_eq!(j.problem_views.split_levels, 2);
        assert_eq!(j.candidates.apex_angles_deg, vec![11.25, 22.5, 45.0, 90.0]);
        assert_eq!(j.candidates.min_distance_doublings, 10);
        // The one departure: four minimum distances per doubling (the paper: 1).
        assert_eq!(j.candidates.min_distance_steps, 4);
        assert_eq!(j.max_error_px, 1.0);
        assert_eq!(j.view_space.pitch_deg, [-90.0, 90.0]);
        // θ for 45° and 512 rows.
        assert!((j.pixel_angle() - 2.0 * (22.5f64).to_radians().tan() / 512.0).abs() < 1e-15);
    }

    #[test]
    fn bad_fields_are_named() {
        let cases = [
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"bogus":1}"#,
                "bogus",
            ),
            (
                r#"{"view_space":{"min":[5,0,0],"max":[1,1,1]}}"#,
                "inverted",
            ),
            (
                r#"{"view_space":{"min":[1,1,1],"max":[1,1,1]}}"#,
                "zero size",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"target_frame_time_ms":-3}"#,
                "target_frame_time_ms",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"camera":{"fov_deg":0}}"#,
                "camera.fov_deg",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"candidates":{"min_distance_steps":0}}"#,
                "candidates.min_distance_steps",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1],"pitch_deg":[10,-10]}}"#,
                "pitch_deg",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1e6,1,1e6]},"problem_views":{"cell_size":1}}"#,
                "cell_size",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"problem_views":{"refine_levels":5}}"#,
                "problem_views.refine_levels",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"problem_views":{"split_levels":4}}"#,
                "problem_views.split_levels",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"problem_views":{"grid_origin":[0,2e9,0]}}"#,
                "problem_views.grid_origin",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"problem_views":{"cell_size":1e-9}}"#,
                "problem_views.cell_size",
            ),
            (r#"{"camera":{}}"#, "view_space"),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"partition":{"tiles":[0,2]}}"#,
                "partition.tiles",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"partition":{"tiles":[2,65]}}"#,
                "partition.tiles",
            ),
            (
                r#"{"view_space":{"min":[0,0,0],"max":[1,1,1]},"partition":{"tiles":[2,2]},"memory":{"budget_bytes":1000}}"#,
                "memory.budget_bytes",
            ),
        ];
        for (json, needle) in cases {
            let err = parse(json).unwrap_err().to_string();
            assert!(err.contains(needle), "{json}: {err}");
            assert!(err.starts_with("job.json"), "{err}");
        }
    }
}
