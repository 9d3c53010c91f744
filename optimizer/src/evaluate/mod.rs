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

mod compare;
mod estimates;
pub mod images;
mod index;
mod parallax;
mod view_time;
mod walkthrough;

pub use parallax::parallax_check;
pub use walkthrough::{PathTimes, walkthrough_views};

use rayon::prelude::*;

use glam::DVec3;

use crate::api::evaluation::{ControlCheck, Evaluation, MissedObject, VisibilityCheck};
use crate::api::placement::Placement;
use crate::error::{Error, Result};
use crate::input::Prepared;
use crate::math::geom::{ViewFrustum, face_direction};
use crate::math::rng::Rng;
use crate::model::cost::CostModel;
use crate::render::raycast::RayCaster;
use crate::visibility::Visibility;
use index::PlacementIndex;
use view_time::{check_view, view_time};

/// Options of an evaluation.
#[derive(Clone, Copy, Debug)]
pub struct EvalOptions {
    /// Number of views sampled uniformly over the view space.
    pub views: u64,
    /// Number of views sampled inside problem views (a problem view drawn
    /// uniformly, then a viewpoint in its region and a direction in its
    /// direction interval and the pitch band): the views that needed
    /// impostors.
    pub cpv_views: u64,
    /// Seed of the view samplers.
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
        if self.cpv_views > 100_000_000 {
            return Err(Error::bad(
                "--cpv-views",
                format!("{} must be at most 100000000", self.cpv_views),
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
            cpv_views: 10_000,
            seed: 1,
            check_rays: 256,
            check_objects: 16,
        }
    }
}

/// One sampled view's outcome.
struct ViewResult {
    /// Time with the impostors of its problem view.
    time: f64,
    /// Time with no impostor (the control).
    bare: f64,
    /// Its problem view, `u32::MAX` for none.
    cpv: u32,
    /// An impostor was used outside its view cell.
    outside: bool,
    /// Size of its visible set.
    visible: usize,
    /// Objects seen but missing from the visible set: `(object, by_probe)`.
    missed: Vec<(u32, bool)>,
    /// Rays cast for the visibility check.
    rays: u64,
    /// The visible set was checked.
    checked: bool,
}

/// What every sampled view is measured with.
struct Viewer<'p> {
    prepared: &'p Prepared<'p>,
    index: PlacementIndex<'p>,
    model: CostModel,
    aspect: f64,
    visibility: Option<&'p Visibility<'p>>,
    caster: Option<&'p RayCaster>,
    ranges: Vec<(usize, usize)>,
    opts: EvalOptions,
}

impl Viewer<'_> {
    /// Measures the view from `eye` along `dir`; with `check`, also casts
    /// the visibility check's rays (drawn from `rng`).
    fn view(&self, eye: DVec3, dir: DVec3, rng: &mut Rng, check: bool) -> ViewResult {
        let job = self.prepared.job();
        let scene = self.prepared.scene();
        let h = self.prepared.hierarchy();
        let index = &self.index;
        let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, self.aspect);
        let cell = index
            .grid
            .cell_of(eye)
            .expect("sampled inside the view space");
        let (cpv, replaced, imps) = index.view_cpv(eye, cell, dir);
        let outside = imps
            .iter()
            .any(|&i| !index.impostors[i as usize].cell.contains_point(eye));
        let set = self.visibility.map(|v| &v.cell(cell).set);
        let caster = self.caster.filter(|_| check);
        let mut culled = Vec::new();
        let time = view_time(
            scene,
            h,
            &self.model,
            &f,
            &replaced,
            imps,
            index,
            set.map(|s| &**s),
            caster.is_some().then_some(&mut culled),
        );
        let bare = if imps.is_empty() {
            time
        } else {
            view_time(
                scene,
                h,
                &self.model,
                &f,
                &[],
                &[],
                index,
                set.map(|s| &**s),
                None,
            )
        };
        let (missed, rays, checked) = match (caster, set, &self.prepared.input().geometry) {
            (Some(c), Some(s), Some(g)) => {
                let (m, r) = check_view(
                    c,
                    g,
                    &self.ranges,
                    &f,
                    job.camera.fov_deg,
                    self.aspect,
                    s,
                    &mut culled,
                    &self.opts,
                    rng,
                );
                (m, r, true)
            }
            _ => (Vec::new(), 0, false),
        };
        ViewResult {
            time,
            bare,
            cpv: cpv.unwrap_or(u32::MAX),
            outside,
            visible: set.map_or(scene.objects.len(), |s| s.count()),
            missed,
            rays,
            checked,
        }
    }
}

/// The `i`-th view sampled uniformly over the view space and the pitch
/// band, with its random stream.
fn uniform_view(prepared: &Prepared, seed: u64, i: u64) -> (DVec3, DVec3, Rng) {
    let job = prepared.job();
    let pitch = job.view_space.pitch_deg.map(f64::to_radians);
    let mut rng = Rng::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ i);
    let eye = rng.in_box(job.vs_min(), job.vs_max());
    let dir = rng.direction_in_pitch(pitch[0], pitch[1]);
    (eye, dir, rng)
}

/// The `i`-th view sampled inside a problem view: a problem view drawn
/// uniformly, a viewpoint uniform in its region and a direction uniform in
/// angle over its direction interval, kept when it lies in the pitch band
/// (up to 64 draws; `None` when none does).
fn cpv_view(
    prepared: &Prepared,
    placement: &Placement,
    seed: u64,
    i: u64,
) -> Option<(DVec3, DVec3, Rng)> {
    let n = placement.cpvs.len() as u64;
    if n == 0 {
        return None;
    }
    let pitch = prepared.job().view_space.pitch_deg.map(f64::to_radians);
    let mut rng = Rng::new(seed.wrapping_mul(0xD1B5_4A32_D192_ED03) ^ i);
    for _ in 0..64 {
        let c = &placement.cpvs[(rng.next_u64() % n) as usize];
        let eye = rng.in_box(
            DVec3::from_array(c.region.min),
            DVec3::from_array(c.region.max),
        );
        let d = &c.directions;
        let u = rng.range(d.u[0].atan(), d.u[1].atan()).tan();
        let v = rng.range(d.v[0].atan(), d.v[1].atan()).tan();
        let dir = face_direction(d.face, u, v).normalize();
        let el = dir.y.clamp(-1.0, 1.0).asin();
        if el >= pitch[0] - 1e-12 && el <= pitch[1] + 1e-12 {
            return Some((eye, dir, rng));
        }
    }
    None
}

impl Prepared<'_> {
    /// Evaluates `placement` for the prepared job: the same levels of detail
    /// and visible sets the placement used. Every view is also timed with no
    /// impostor, the control that shows whether the check could fail.
    /// `source` names the placement in errors.
    pub fn evaluate(
        &self,
        placement: &Placement,
        opts: &EvalOptions,
        source: &str,
    ) -> Result<Evaluation> {
        opts.check()?;
        let job = self.job();
        let scene = self.scene();
        let index = PlacementIndex::new(scene, job, placement, source)?;
        let vis = self.visibility();
        let t_max = job.target_frame_time_ms;
        let [w, hgt] = job.camera.resolution;
        let check = vis.is_some() && (opts.check_rays > 0 || opts.check_objects > 0);
        let caster = if check { self.input().caster() } else { None };
        let ranges = match (&self.input().geometry, caster) {
            (Some(g), Some(_)) => g.instance_ranges(),
            _ => Vec::new(),
        };
        let viewer = Viewer {
            prepared: self,
            index,
            model: CostModel::new(job),
            aspect: f64::from(w) / f64::from(hgt),
            visibility: vis,
            caster,
            ranges,
            opts: *opts,
        };
        let in_cpvs: Vec<(DVec3, DVec3, Rng)> = (0..opts.cpv_views)
            .into_par_iter()
            .filter_map(|i| cpv_view(self, placement, opts.seed, i))
            .collect();
        let mut cells_used: Vec<[u32; 3]> = Vec::new();
        if let Some(v) = vis {
            let cell = |eye| viewer.index.grid.cell_of(eye).expect("inside");
            cells_used = (0..opts.views)
                .into_par_iter()
                .map(|i| cell(uniform_view(self, opts.seed, i).0))
                .collect();
            cells_used.sort_unstable();
            cells_used.dedup();
            let mut all = cells_used.clone();
            all.extend(in_cpvs.iter().map(|(eye, _, _)| cell(*eye)));
            all.sort_unstable();
            all.dedup();
            v.prefetch(&all);
        }
        let samples: Vec<ViewResult> = (0..opts.views)
            .into_par_iter()
            .map(|i| {
                let (eye, dir, mut rng) = uniform_view(self, opts.seed, i);
                viewer.view(eye, dir, &mut rng, true)
            })
            .collect();
        let cpv_samples: Vec<ViewResult> = in_cpvs
            .into_par_iter()
            .map(|(eye, dir, mut rng)| viewer.view(eye, dir, &mut rng, false))
            .collect();
        let mut times: Vec<f64> = samples.iter().map(|s| s.time).collect();
        times.sort_by(f64::total_cmp);
        let pct = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
        let over = |t: f64| t > t_max * (1.0 + 1e-12);
        let solved = |c: u32| c == u32::MAX || viewer.index.cpv_solved[c as usize];
        let count = |v: &[ViewResult], f: &dyn Fn(&ViewResult) -> bool| {
            v.iter().filter(|s| f(s)).count() as u64
        };
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
                            eye: uniform_view(self, opts.seed, i as u64).0.to_array(),
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
                views_checked: count(&samples, &|s| s.checked),
                rays: samples.iter().map(|s| s.rays).sum(),
                missed_objects: samples.iter().map(|s| s.missed.len() as u64).sum(),
                views_with_misses: count(&samples, &|s| !s.missed.is_empty()),
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
        let control = ControlCheck {
            violations: count(&samples, &|s| over(s.bare)),
            violations_in_solved: count(&samples, &|s| solved(s.cpv) && over(s.bare)),
            violations_in_cpv_views: count(&cpv_samples, &|s| solved(s.cpv) && over(s.bare)),
            max_ms: samples
                .iter()
                .chain(&cpv_samples)
                .map(|s| s.bare)
                .fold(0.0, f64::max),
        };
        Ok(Evaluation {
            views: opts.views,
            seed: opts.seed,
            target_frame_time_ms: t_max,
            max_ms: *times.last().expect("at least one view"),
            p50_ms: pct(0.5),
            p99_ms: pct(0.99),
            mean_ms: times.iter().sum::<f64>() / times.len() as f64,
            violations: count(&samples, &|s| over(s.time)),
            violations_in_solved: in_solved.iter().filter(|&&t| over(t)).count() as u64,
            max_ms_in_solved: in_solved.iter().copied().fold(0.0, f64::max),
            views_in_cpvs: count(&samples, &|s| s.cpv != u32::MAX),
            views_in_unsolved_cpvs: count(&samples, &|s| !solved(s.cpv)),
            impostors_outside_view_cell: count(&samples, &|s| s.outside)
                + count(&cpv_samples, &|s| s.outside),
            mean_slack_ms: if within.is_empty() {
                0.0
            } else {
                within.iter().map(|t| t_max - t).sum::<f64>() / within.len() as f64
            },
            cpv_views: cpv_samples.len() as u64,
            cpv_views_in_unsolved: count(&cpv_samples, &|s| !solved(s.cpv)),
            violations_in_cpv_views: count(&cpv_samples, &|s| solved(s.cpv) && over(s.time)),
            max_ms_in_cpv_views: cpv_samples
                .iter()
                .filter(|s| solved(s.cpv))
                .map(|s| s.time)
                .fold(0.0, f64::max),
            control,
            image: None,
            visibility,
            parallax: parallax_check(job, placement, opts.seed),
            estimates: estimates::estimate_check(
                |c| {
                    let p = placement.cpvs.get(c as usize)?;
                    Some((p.time_ms_original, p.time_ms_final))
                },
                samples
                    .iter()
                    .chain(&cpv_samples)
                    .map(|s| (s.cpv, s.time, s.bare)),
                t_max,
            ),
        })
    }
}
