//! The placement methods and the knobs of those that have their own.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A placement method (DESIGN §2.11): every method writes the same
/// placement JSON and is judged by the same evaluation, cost and memory
/// model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum Method {
    /// The paper's reference: shaft view cells around each cluster.
    #[serde(rename = "shafts")]
    Shafts,
    /// Box view cells from the 3D view space hierarchy (paper test 13).
    #[serde(rename = "boxes")]
    Boxes,
    /// Shafts and boxes.
    #[serde(rename = "both")]
    Both,
    /// Box view cells of one size only (the grid cells, or their ancestors
    /// `per_cell.level` levels up): one placement per cell, no sharing
    /// between cells (paper test 14).
    #[serde(rename = "per-cell")]
    PerCell,
    /// Per view cell, everything visible beyond `env_map.far_m` becomes
    /// layered environment-map impostors (paper test 15); no frame-time
    /// guarantee.
    #[serde(rename = "env-map")]
    EnvMap,
    /// Shafts, then the pruning pass that removes impostors not needed to
    /// keep every problem view within the target.
    #[serde(rename = "shafts+prune")]
    ShaftsPrune,
    /// The optimum of the shafts' problem (every problem view within the
    /// target, least memory) as an integer program, seeded with the
    /// greedy's selection; for small instances (`exact`'s limits).
    #[serde(rename = "exact")]
    Exact,
    /// Far-field textures per view cell (Aliaga 1996, automated): in each
    /// cell with problem views, everything beyond the largest distance at
    /// which they meet the target becomes one texture per cube face.
    #[serde(rename = "dts96")]
    Dts96,
    /// An image-based object hierarchy (Lee, Chen and Lin): every cluster
    /// has view-independent images, drawn wherever the viewpoint is outside
    /// its sampling circle; no selection and no frame-time guarantee.
    #[serde(rename = "iboh")]
    Iboh,
    /// A hierarchical image cache (Shade et al. 1996) replayed along the
    /// walkthrough: no placement ahead of time, so `place` refuses it and
    /// `impostor report` reports its path figures (frame times with their
    /// spikes, resident memory, images created).
    #[serde(rename = "hic96")]
    Hic96,
    /// Images per view-space grid point (Aliaga and Lastra 1999): per grid
    /// cell, each view above the target gets at most one image of a
    /// contiguous subset found by the paper's cost-benefit search; no
    /// sharing between cells.
    #[serde(rename = "al99")]
    Al99,
}

impl Method {
    /// Every method, in the order reports list them.
    pub const ALL: [Method; 11] = [
        Method::Shafts,
        Method::Boxes,
        Method::Both,
        Method::PerCell,
        Method::EnvMap,
        Method::ShaftsPrune,
        Method::Exact,
        Method::Dts96,
        Method::Iboh,
        Method::Hic96,
        Method::Al99,
    ];

    /// The method's name as in JSON and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Shafts => "shafts",
            Method::Boxes => "boxes",
            Method::Both => "both",
            Method::PerCell => "per-cell",
            Method::EnvMap => "env-map",
            Method::ShaftsPrune => "shafts+prune",
            Method::Exact => "exact",
            Method::Dts96 => "dts96",
            Method::Iboh => "iboh",
            Method::Hic96 => "hic96",
            Method::Al99 => "al99",
        }
    }

    /// Whether the method's candidates include shafts.
    pub fn builds_shafts(self) -> bool {
        matches!(
            self,
            Method::Shafts | Method::Both | Method::ShaftsPrune | Method::Exact
        )
    }

    /// Whether the method's candidates include boxes of the view-space
    /// hierarchy (`per-cell`: its one box level).
    pub fn builds_boxes(self) -> bool {
        matches!(self, Method::Boxes | Method::Both | Method::PerCell)
    }

    /// Whether `impostor report` runs the method when none are named: all
    /// but `exact`, whose program outgrows all but small instances.
    pub fn in_default_report(self) -> bool {
        self != Method::Exact
    }

    /// Whether the method makes a placement ahead of time (all but
    /// `hic96`, a runtime cache replayed along a path).
    pub fn places(self) -> bool {
        self != Method::Hic96
    }

    /// Refuses a method that makes no placement (`source` names the job).
    pub fn check_places(self, source: &str) -> crate::error::Result<()> {
        if self.places() {
            return Ok(());
        }
        Err(crate::error::Error::bad(
            format!("{source}: method"),
            format!(
                "{} is an image cache built at run time along a path, not a placement made \
                 ahead of time: compare it with the other methods with `impostor report --methods \
                 shafts,{}` (its frame times, resident memory and images created along the \
                 job's walkthrough)",
                self.name(),
                self.name()
            ),
        ))
    }

    /// The method of a name.
    pub fn parse(name: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// The `per-cell` method's knobs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PerCellParams {
    /// View cells are the grid cells' kd ancestors this many levels up (0:
    /// the cells themselves; each level up doubles a cell). Default 0.
    #[serde(default)]
    pub level: u32,
}

/// The `env-map` method's knobs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EnvMapParams {
    /// Side of a view cell, metres, rounded to a whole number of grid cells.
    /// Default 25.
    #[serde(default = "default_env_cell")]
    pub cell_m: f64,
    /// Objects entirely beyond this distance from a view cell become its
    /// environment map. Default 300.
    #[serde(default = "default_env_far")]
    pub far_m: f64,
}

impl Default for EnvMapParams {
    fn default() -> Self {
        EnvMapParams {
            cell_m: default_env_cell(),
            far_m: default_env_far(),
        }
    }
}

fn default_env_cell() -> f64 {
    25.0
}
fn default_env_far() -> f64 {
    300.0
}

/// The `dts96` method's knobs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Dts96Params {
    /// Side of a view cell, metres, rounded to a whole number of grid cells.
    /// Default 25.
    #[serde(default = "default_env_cell")]
    pub cell_m: f64,
}

impl Default for Dts96Params {
    fn default() -> Self {
        Dts96Params {
            cell_m: default_env_cell(),
        }
    }
}

/// The `al99` method's knobs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Al99Params {
    /// The optimisation budget's margin: a view's image brings it within the
    /// target less this share of the drawing time the target allows (above
    /// `cost_model.frame_ms`). Default 0.1 (the paper: P − P_opt of 5–10 %
    /// of the model's primitives, 20 % of P in its worked example).
    #[serde(default = "default_al99_gap")]
    pub gap: f64,
    /// Moves searched ahead before each step of the subset search. Default
    /// 2 (the paper: "a few").
    #[serde(default = "default_al99_lookahead")]
    pub lookahead: u32,
    /// The first grid's spacing: grid points are the view-space hierarchy's
    /// nodes no longer than this a side, subdivided where a view finds no
    /// valid image, down to the problem views' cells. Metres, default 100.
    #[serde(default = "default_al99_grid")]
    pub grid_m: f64,
}

impl Default for Al99Params {
    fn default() -> Self {
        Al99Params {
            gap: default_al99_gap(),
            lookahead: default_al99_lookahead(),
            grid_m: default_al99_grid(),
        }
    }
}

fn default_al99_gap() -> f64 {
    0.1
}
fn default_al99_lookahead() -> u32 {
    2
}
fn default_al99_grid() -> f64 {
    100.0
}

/// The `iboh` method's knobs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IbohParams {
    /// Reference images kept per node. Default 9 (the paper kept 492
    /// images of 18 sampled per node over 53 nodes).
    #[serde(default = "default_iboh_images")]
    pub images: u32,
    /// Side of a reference image, texels. Default: the output's height (the
    /// paper: 256 for a 256-pixel output).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_px: Option<u32>,
    /// A node's sampling circle is at least this many node radii. Default
    /// 1.5.
    #[serde(default = "default_iboh_kappa")]
    pub kappa: f64,
}

impl Default for IbohParams {
    fn default() -> Self {
        IbohParams {
            images: default_iboh_images(),
            reference_px: None,
            kappa: default_iboh_kappa(),
        }
    }
}

fn default_iboh_images() -> u32 {
    9
}
fn default_iboh_kappa() -> f64 {
    1.5
}

/// The `exact` method's knobs: the size of program it takes on and when the
/// solver stops (keeping the best selection found and its lower bound).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExactParams {
    /// Branch-and-bound nodes before the solver stops (deterministic).
    /// Default 20000.
    #[serde(default = "default_exact_nodes")]
    pub max_nodes: u64,
    /// Wall time before the solver stops, seconds (a run it stops depends
    /// on the machine). Default 300.
    #[serde(default = "default_exact_seconds")]
    pub max_seconds: f64,
    /// Largest program taken on, in variables (one per candidate and one
    /// per useful (candidate, problem view) pair); a larger one is refused
    /// before it is built. Default 200000.
    #[serde(default = "default_exact_variables")]
    pub max_variables: u64,
}

impl Default for ExactParams {
    fn default() -> Self {
        ExactParams {
            max_nodes: default_exact_nodes(),
            max_seconds: default_exact_seconds(),
            max_variables: default_exact_variables(),
        }
    }
}

fn default_exact_nodes() -> u64 {
    20_000
}
fn default_exact_seconds() -> f64 {
    300.0
}
fn default_exact_variables() -> u64 {
    200_000
}
