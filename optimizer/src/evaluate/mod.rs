//! Independent frame-time check (DESIGN §2.10): the oracle for the guarantee.
//!
//! Samples random views (position uniform in the view space, direction
//! uniform over the allowed pitch band), finds each view's CPV from the
//! placement, and computes the view's time with its exact frustum: every
//! object whose bounding sphere meets the frustum is drawn as geometry at its
//! actual distance, unless an impostor of the view's CPV represents it, in
//! which case the impostor is drawn instead (if its cluster sphere meets the
//! frustum). It does not use the enclosing frusta, the candidates or the
//! greedy state: only the scene, the job and the placement.
//!
//! With visibility, each view counts only the objects of its grid cell's
//! potentially visible set (the same set the placement used), and the set
//! itself is checked: rays cast from the view point through a grid over the
//! image, and rays aimed at points on the nearest objects the set culled,
//! find objects that are actually visible; any such object missing from the
//! set is counted in `visibility.missed_objects` (0 in conservative mode).

pub mod images;
mod index;
mod parallax;
mod view_time;
mod walkthrough;

pub use parallax::parallax_check;
pub use walkthrough::walkthrough_views;

use rayon::prelude::*;

use crate::api::evaluation::{Evaluation, MissedObject, VisibilityCheck};
use crate::api::placement::Placement;
use crate::error::{Error, Result};
use crate::input::Prepared;
use crate::math::geom::ViewFrustum;
use crate::math::rng::Rng;
use crate::model::cost::CostModel;
use index::PlacementIndex;
use view_time::{check_view, view_time};

/// Options of an evaluation.
#[derive(Clone, Copy, Debug)]
pub struct EvalOptions {
    /// Number of random views.
    pub views: u64,
    /// Seed of the view sampler.
    pub seed: u64,
    /// Visibility check: rays per view through a grid over the image (0: none).
    pub check_rays: u32,
    /// Visibility check: culled objects in the view frustum, nearest first,
    /// probed per view with rays aimed at points of their surfaces.
    pub check_objects: u32,
}

impl EvalOptions {
    /// Checks the sample counts.
    pub fn check(&self) -> Result<()> {
        if self.views == 0 || self.views > 100_000_000 {
            return Err(Error::bad(
                "--views",
                format!("{} must be between 1 and 100000000", self.views),
            ));
        }
        if self.check_rays > 1_000_000 || self.check_objects > 100_000 {
            return Err(Error::bad(
                "--check-rays/--check-objects",
                "at most 1000000 rays and 100000 objects per view",
            ));
        }
        Ok(())
    }
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            views: 10_000,
            seed: 1,
            check_rays: 256,
            check_objects: 16,
        }
    }
}

/// One sampled view's outcome.
struct ViewResult {
    time: f64,
    cpv: u32,
    outside: bool,
    visible: usize,
    missed: Vec<(u32, bool)>,
    rays: u64,
    checked: bool,
}

impl Prepared<'_> {
    /// Evaluates `placement` for the prepared job: the same levels of detail
    /// and visible sets the placement used. `source` names the placement in
    /// errors.
    pub fn evaluate(
        &self,
        placement: &Placement,
        opts: &EvalOptions,
        source: &str,
    ) -> Result<Evaluation> {
        opts.check()?;
        let job = self.job();
        let input = self.input();
        let scene = self.scene();
        let prepared = PlacementIndex::new(scene, job, placement, source)?;
        let h = self.hierarchy();
        let vis = self.visibility();
        let model = CostModel::new(job);
        let t_max = job.target_frame_time_ms;
        let [w, hgt] = job.camera.resolution;
        let aspect = f64::from(w) / f64::from(hgt);
        let (lo, hi) = (job.vs_min(), job.vs_max());
        let pitch = job.view_space.pitch_deg.map(f64::to_radians);
        let view_of = |i: u64| {
            let mut rng = Rng::new(opts.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ i);
            let eye = rng.in_box(lo, hi);
            let dir = rng.direction_in_pitch(pitch[0], pitch[1]);
            (eye, dir, rng)
        };
        let mut cells_used: Vec<[u32; 3]> = Vec::new();
        if let Some(v) = vis {
            cells_used = (0..opts.views)
                .into_par_iter()
                .map(|i| prepared.grid.cell_of(view_of(i).0).expect("inside"))
                .collect();
            cells_used.sort_unstable();
            cells_used.dedup();
            v.prefetch(&cells_used);
        }
        let check = vis.is_some() && (opts.check_rays > 0 || opts.check_objects > 0);
        let caster = if check { input.caster() } else { None };
        let ranges = match (&input.geometry, caster) {
            (Some(g), Some(_)) => g.instance_ranges(),
            _ => Vec::new(),
        };
        let samples: Vec<ViewResult> = (0..opts.views)
            .into_par_iter()
            .map(|i| {
                let (eye, dir, mut rng) = view_of(i);
                let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
                let cell = prepared
                    .grid
                    .cell_of(eye)
                    .expect("sampled inside the view space");
                let (cpv, replaced, imps) = prepared.view_cpv(cell, dir);
                let outside = imps
                    .iter()
                    .any(|&i| !prepared.impostors[i as usize].cell.contains_point(eye));
                let set = vis.map(|v| &v.cell(cell).set);
                let mut culled = Vec::new();
                let t = view_time(
                    scene,
                    h,
                    &model,
                    &f,
                    replaced,
                    imps,
                    &prepared,
                    set.map(|s| &**s),
                    caster.is_some().then_some(&mut culled),
                );
                let (missed, rays, checked) = match (caster, set, &input.geometry) {
                    (Some(c), Some(s), Some(g)) => {
                        let (m, r) = check_view(
                            c,
                            g,
                            &ranges,
                            &f,
                            job.camera.fov_deg,
                            aspect,
                            s,
                            &mut culled,
                            opts,
                            &mut rng,
                        );
                        (m, r, true)
                    }
                    _ => (Vec::new(), 0, false),
                };
                ViewResult {
                    time: t,
                    cpv: cpv.unwrap_or(u32::MAX),
                    outside,
                    visible: set.map_or(scene.objects.len(), |s| s.count()),
                    missed,
                    rays,
                    checked,
                }
            })
            .collect();
        let mut times: Vec<f64> = samples.iter().map(|s| s.time).collect();
        times.sort_by(f64::total_cmp);
        let pct = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
        let over = |t: f64| t > t_max * (1.0 + 1e-12);
        let solved = |c: u32| c == u32::MAX || prepared.cpv_solved[c as usize];
        let in_solved: Vec<f64> = samples
            .iter()
            .filter(|s| solved(s.cpv))
            .map(|s| s.time)
            .collect();
        let within: Vec<f64> = times.iter().copied().filter(|&t| !over(t)).collect();
        let visibility = vis.map(|_| {
            let n = samples.len() as f64;
            let objects = scene.objects.len().max(1) as f64;
            let mean_visible = samples.iter().map(|s| s.visible as f64).sum::<f64>() / n;
            let mut examples = Vec::new();
            for (i, s) in samples.iter().enumerate() {
                for &(o, _) in &s.missed {
                    if examples.len() < 10 {
                        examples.push(MissedObject {
                            view: i as u64,
                            eye: view_of(i as u64).0.to_array(),
                            object: o,
                        });
                    }
                }
            }
            VisibilityCheck {
                mode: job.visibility.mode,
                cells: cells_used.len() as u64,
                mean_visible_objects: mean_visible,
                mean_visible_fraction: mean_visible / objects,
                views_checked: samples.iter().filter(|s| s.checked).count() as u64,
                rays: samples.iter().map(|s| s.rays).sum(),
                missed_objects: samples.iter().map(|s| s.missed.len() as u64).sum(),
                views_with_misses: samples.iter().filter(|s| !s.missed.is_empty()).count() as u64,
                missed_by_image_rays: samples
                    .iter()
                    .map(|s| s.missed.iter().filter(|m| !m.1).count() as u64)
                    .sum(),
                missed_by_probe_rays: samples
                    .iter()
                    .map(|s| s.missed.iter().filter(|m| m.1).count() as u64)
                    .sum(),
                examples,
            }
        });
        Ok(Evaluation {
            views: opts.views,
            seed: opts.seed,
            target_frame_time_ms: t_max,
            max_ms: *times.last().expect("at least one view"),
            p50_ms: pct(0.5),
            p99_ms: pct(0.99),
            mean_ms: times.iter().sum::<f64>() / times.len() as f64,
            violations: samples.iter().filter(|s| over(s.time)).count() as u64,
            violations_in_solved: in_solved.iter().filter(|&&t| over(t)).count() as u64,
            max_ms_in_solved: in_solved.iter().copied().fold(0.0, f64::max),
            views_in_cpvs: samples.iter().filter(|s| s.cpv != u32::MAX).count() as u64,
            views_in_unsolved_cpvs: samples.iter().filter(|s| !solved(s.cpv)).count() as u64,
            impostors_outside_view_cell: samples.iter().filter(|s| s.outside).count() as u64,
            mean_slack_ms: if within.is_empty() {
                0.0
            } else {
                within.iter().map(|t| t_max - t).sum::<f64>() / within.len() as f64
            },
            image: None,
            visibility,
            parallax: parallax_check(job, placement, opts.seed),
        })
    }
}
