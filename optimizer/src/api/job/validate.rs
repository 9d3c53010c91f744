//! Reading and checking a job: every bad value named with its file and
//! field.

use crate::api::job::{Combine, Job, MAX_CELLS, ViewCellKind, VisibilityMode};
use crate::error::{Error, Result};

/// Deepest refinement of a problem view below the minimum sizes.
const MAX_REFINE_LEVELS: u8 = 4;

/// Deepest halving of a problem cell (8³ parts of a cube at most).
const MAX_SPLIT_LEVELS: u8 = 3;

/// Largest coordinate magnitude a job may use, metres.
const MAX_COORD: f64 = 1e9;

/// Smallest cell side, metres (far above the rounding step of `MAX_COORD`).
const MIN_CELL_SIZE: f64 = 1e-3;

impl Job {
    /// Parses and validates a job; `source` names the file in errors.
    pub fn from_json(bytes: &[u8], source: &str) -> Result<Job> {
        let job: Job = serde_json::from_slice(bytes).map_err(|e| {
            // serde names unknown and missing fields in its message.
            Error::bad(source, format!("invalid job JSON: {e}"))
        })?;
        job.validate(source)?;
        Ok(job)
    }

    /// Checks every field's range; the error names `source` and the field.
    pub fn validate(&self, source: &str) -> Result<()> {
        let bad = |field: &str, msg: String| Error::bad(format!("{source}: {field}"), msg);
        let vs = &self.view_space;
        for (name, v) in [("view_space.min", vs.min), ("view_space.max", vs.max)] {
            if v.iter().any(|c| !c.is_finite() || c.abs() > MAX_COORD) {
                return Err(bad(
                    name,
                    format!("{v:?} is not a finite coordinate (|c| ≤ 1e9)"),
                ));
            }
        }
        for axis in 0..3 {
            if vs.min[axis] > vs.max[axis] {
                return Err(bad(
                    "view_space",
                    format!(
                        "inverted: min[{axis}] = {} is greater than max[{axis}] = {}",
                        vs.min[axis], vs.max[axis]
                    ),
                ));
            }
        }
        if (0..3).all(|a| vs.max[a] - vs.min[a] <= 0.0) {
            return Err(bad(
                "view_space",
                "has zero size (min equals max on every axis); give it an extent".into(),
            ));
        }
        let [lo, hi] = vs.pitch_deg;
        if !(lo.is_finite()
            && hi.is_finite()
            && (-90.0..=90.0).contains(&lo)
            && (-90.0..=90.0).contains(&hi)
            && lo <= hi)
        {
            return Err(bad(
                "view_space.pitch_deg",
                format!("[{lo}, {hi}] must satisfy -90 ≤ lo ≤ hi ≤ 90"),
            ));
        }
        let cam = &self.camera;
        if !(cam.fov_deg.is_finite() && cam.fov_deg > 0.0 && cam.fov_deg < 170.0) {
            return Err(bad(
                "camera.fov_deg",
                format!("{} must be in (0, 170)", cam.fov_deg),
            ));
        }
        let [w, h] = cam.resolution;
        if w == 0 || h == 0 || w > 16384 || h > 16384 {
            return Err(bad(
                "camera.resolution",
                format!("[{w}, {h}] must be between 1 and 16384 pixels per side"),
            ));
        }
        let t = self.target_frame_time_ms;
        if !(t.is_finite() && t > 0.0 && t <= 1e6) {
            return Err(bad(
                "target_frame_time_ms",
                format!("{t} must be a positive number of milliseconds"),
            ));
        }
        let e = self.max_error_px;
        if !(e.is_finite() && e > 0.0 && e <= 1e4) {
            return Err(bad("max_error_px", format!("{e} must be positive")));
        }
        let c = &self.cost_model;
        for (name, v) in [
            ("cost_model.frame_ms", c.frame_ms),
            ("cost_model.draw_call_us", c.draw_call_us),
            ("cost_model.triangle_ns", c.triangle_ns),
            ("cost_model.pixel_ns", c.pixel_ns),
        ] {
            if !(v.is_finite() && (0.0..=1e9).contains(&v)) {
                return Err(bad(
                    name,
                    format!("{v} must be a finite non-negative number"),
                ));
            }
        }
        if c.combine == Combine::Primitives && c.triangle_ns <= 0.0 {
            return Err(bad(
                "cost_model.triangle_ns",
                "must be positive in the primitives mode".into(),
            ));
        }
        let pv = &self.problem_views;
        if !(pv.cell_size.is_finite() && pv.cell_size >= MIN_CELL_SIZE) {
            return Err(bad(
                "problem_views.cell_size",
                format!("{} must be at least {MIN_CELL_SIZE} m", pv.cell_size),
            ));
        }
        if !pv
            .grid_origin
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_COORD)
        {
            return Err(bad(
                "problem_views.grid_origin",
                format!("{:?} must be finite coordinates", pv.grid_origin),
            ));
        }
        // The anchored grid has at most one cell more per axis than the
        // extent over the cell size.
        let cells: f64 = (0..3)
            .map(|a| ((vs.max[a] - vs.min[a]) / pv.cell_size).ceil() + 1.0)
            .product();
        if cells > MAX_CELLS {
            return Err(bad(
                "problem_views.cell_size",
                format!(
                    "{} m makes {cells:.0} cells over the view space (at most {MAX_CELLS:.0}); use larger cells",
                    pv.cell_size
                ),
            ));
        }
        if !(pv.min_vdi_deg.is_finite() && (0.5..=90.0).contains(&pv.min_vdi_deg)) {
            return Err(bad(
                "problem_views.min_vdi_deg",
                format!("{} must be in [0.5, 90]", pv.min_vdi_deg),
            ));
        }
        if pv.refine_levels > MAX_REFINE_LEVELS {
            return Err(bad(
                "problem_views.refine_levels",
                format!("{} must be at most {MAX_REFINE_LEVELS}", pv.refine_levels),
            ));
        }
        if pv.split_levels > MAX_SPLIT_LEVELS {
            return Err(bad(
                "problem_views.split_levels",
                format!("{} must be at most {MAX_SPLIT_LEVELS}", pv.split_levels),
            ));
        }
        let cp = &self.candidates;
        if cp.apex_angles_deg.is_empty() && cp.view_cells != ViewCellKind::Boxes {
            return Err(bad(
                "candidates.apex_angles_deg",
                "needs at least one angle for shafts".into(),
            ));
        }
        if cp.apex_angles_deg.len() > 16 {
            return Err(bad(
                "candidates.apex_angles_deg",
                "at most 16 angles".into(),
            ));
        }
        for &a in &cp.apex_angles_deg {
            if !(a.is_finite() && a > 0.0 && a <= 180.0) {
                return Err(bad(
                    "candidates.apex_angles_deg",
                    format!("{a} must be in (0, 180]"),
                ));
            }
        }
        if !(cp.direction_step_deg.is_finite() && (1.0..=90.0).contains(&cp.direction_step_deg)) {
            return Err(bad(
                "candidates.direction_step_deg",
                format!("{} must be in [1, 90]", cp.direction_step_deg),
            ));
        }
        if !(cp.axis_spacing.is_finite() && (0.0..=2.0).contains(&cp.axis_spacing)) {
            return Err(bad(
                "candidates.axis_spacing",
                format!("{} must be in [0, 2]", cp.axis_spacing),
            ));
        }
        if cp.min_distance_doublings > 30 {
            return Err(bad(
                "candidates.min_distance_doublings",
                format!("{} must be at most 30", cp.min_distance_doublings),
            ));
        }
        if !(1..=16).contains(&cp.min_distance_steps) {
            return Err(bad(
                "candidates.min_distance_steps",
                format!("{} must be in [1, 16]", cp.min_distance_steps),
            ));
        }
        let m = &self.memory;
        if !(m.bytes_per_texel.is_finite() && m.bytes_per_texel > 0.0 && m.bytes_per_texel <= 64.0)
        {
            return Err(bad(
                "memory.bytes_per_texel",
                format!("{} must be in (0, 64]", m.bytes_per_texel),
            ));
        }
        if !(m.texels_per_pixel.is_finite() && (0.25..=8.0).contains(&m.texels_per_pixel)) {
            return Err(bad(
                "memory.texels_per_pixel",
                format!("{} must be in [0.25, 8]", m.texels_per_pixel),
            ));
        }
        if !(4..=16384).contains(&m.max_texture_size) {
            return Err(bad(
                "memory.max_texture_size",
                format!("{} must be in [4, 16384]", m.max_texture_size),
            ));
        }
        let v = &self.visibility;
        if !(v.sample_spacing_m.is_finite() && v.sample_spacing_m >= 0.05) {
            return Err(bad(
                "visibility.sample_spacing_m",
                format!("{} must be at least 0.05 m", v.sample_spacing_m),
            ));
        }
        let samples: f64 = (0..3)
            .map(|a| {
                let cell = (vs.max[a] - vs.min[a])
                    / ((vs.max[a] - vs.min[a]) / pv.cell_size).ceil().max(1.0);
                (cell / v.sample_spacing_m).ceil().max(1.0)
            })
            .product();
        if v.mode == VisibilityMode::Conservative && samples > 4096.0 {
            return Err(bad(
                "visibility.sample_spacing_m",
                format!(
                    "{} m makes {samples:.0} sample points per view cell (at most 4096); use a larger spacing",
                    v.sample_spacing_m
                ),
            ));
        }
        if !(1..=10_000_000).contains(&v.rays_per_region) {
            return Err(bad(
                "visibility.rays_per_region",
                format!("{} must be between 1 and 10000000", v.rays_per_region),
            ));
        }
        if v.probes_per_object > 1000 {
            return Err(bad(
                "visibility.probes_per_object",
                format!("{} must be at most 1000", v.probes_per_object),
            ));
        }
        if !(1..=1_000_000).contains(&v.max_region_cells) {
            return Err(bad(
                "visibility.max_region_cells",
                format!("{} must be between 1 and 1000000", v.max_region_cells),
            ));
        }
        if self.per_cell.level > 30 {
            return Err(bad(
                "per_cell.level",
                format!("{} must be at most 30", self.per_cell.level),
            ));
        }
        let e = &self.env_map;
        if !(e.cell_m.is_finite() && e.cell_m > 0.0 && e.cell_m <= 1e7) {
            return Err(bad(
                "env_map.cell_m",
                format!("{} must be a positive number of metres", e.cell_m),
            ));
        }
        if !(e.far_m.is_finite() && e.far_m > 0.0 && e.far_m <= 1e9) {
            return Err(bad(
                "env_map.far_m",
                format!("{} must be a positive number of metres", e.far_m),
            ));
        }
        if let Some(p) = &self.partition {
            if p.tiles.iter().any(|&n| !(1..=64).contains(&n)) {
                return Err(bad(
                    "partition.tiles",
                    format!("{:?} must be two tile counts in 1..=64", p.tiles),
                ));
            }
            if self.memory.budget_bytes.is_some() {
                return Err(bad(
                    "partition",
                    "tiles cannot share a memory budget (memory.budget_bytes): give one or \
                     the other"
                        .into(),
                ));
            }
        }
        let c = self.dts96.cell_m;
        if !(c.is_finite() && c > 0.0 && c <= 1e7) {
            return Err(bad(
                "dts96.cell_m",
                format!("{c} must be a positive number of metres"),
            ));
        }
        let a = &self.al99;
        if !(a.gap.is_finite() && (0.0..=0.9).contains(&a.gap)) {
            return Err(bad(
                "al99.gap",
                format!("{} must be between 0 and 0.9", a.gap),
            ));
        }
        if !(a.grid_m.is_finite() && a.grid_m > 0.0 && a.grid_m <= 1e7) {
            return Err(bad(
                "al99.grid_m",
                format!("{} must be a positive number of metres", a.grid_m),
            ));
        }
        if a.lookahead > 4 {
            return Err(bad(
                "al99.lookahead",
                format!("{} must be at most 4", a.lookahead),
            ));
        }
        let i = &self.iboh;
        if !(1..=1024).contains(&i.images) {
            return Err(bad(
                "iboh.images",
                format!("{} must be between 1 and 1024", i.images),
            ));
        }
        if let Some(n) = i.reference_px
            && !(1..=16384).contains(&n)
        {
            return Err(bad(
                "iboh.reference_px",
                format!("{n} must be between 1 and 16384"),
            ));
        }
        if !(i.kappa.is_finite() && (1.0..=1e6).contains(&i.kappa)) {
            return Err(bad(
                "iboh.kappa",
                format!("{} must be a number of node radii, at least 1", i.kappa),
            ));
        }
        let x = &self.exact;
        if !(1..=100_000_000).contains(&x.max_nodes) {
            return Err(bad(
                "exact.max_nodes",
                format!("{} must be between 1 and 100000000", x.max_nodes),
            ));
        }
        if !(x.max_seconds.is_finite() && x.max_seconds > 0.0 && x.max_seconds <= 1e6) {
            return Err(bad(
                "exact.max_seconds",
                format!("{} must be a positive number of seconds", x.max_seconds),
            ));
        }
        if !(1..=100_000_000).contains(&x.max_variables) {
            return Err(bad(
                "exact.max_variables",
                format!("{} must be between 1 and 100000000", x.max_variables),
            ));
        }
        if let Some(w) = &self.walkthrough {
            if w.points.len() < 2 || w.points.len() > 100_000 {
                return Err(bad(
                    "walkthrough.points",
                    format!("{} points; give between 2 and 100000", w.points.len()),
                ));
            }
            if let Some(p) = w
                .points
                .iter()
                .find(|p| p.iter().any(|c| !c.is_finite() || c.abs() > MAX_COORD))
            {
                return Err(bad(
                    "walkthrough.points",
                    format!("{p:?} is not a finite point"),
                ));
            }
            if !(2..=1_000_000).contains(&w.frames) {
                return Err(bad(
                    "walkthrough.frames",
                    format!("{} must be between 2 and 1000000", w.frames),
                ));
            }
        }
        let l = &self.lod;
        if l.levels > 8 {
            return Err(bad("lod.levels", format!("{} must be at most 8", l.levels)));
        }
        if !(l.ratio.is_finite() && l.ratio > 0.0 && l.ratio < 1.0) {
            return Err(bad("lod.ratio", format!("{} must be in (0, 1)", l.ratio)));
        }
        Ok(())
    }
}
