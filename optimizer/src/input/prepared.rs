//! A scene input prepared for one job: the job and its visibility.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::Result;
use crate::api::job::{Camera, CostModelParams, Job};
use crate::api::stats::StageTime;
use crate::input::SceneInput;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;
use crate::visibility::Visibility;

/// A [`SceneInput`] prepared for a job: what placing, evaluating and baking
/// it share. Runs that differ only in their target, method or candidate
/// knobs share one visibility ([`Prepared::with_job`]), so visible sets are
/// computed once.
pub struct Prepared<'a> {
    input: &'a SceneInput,
    job: Job,
    job_name: String,
    visibility: Option<Arc<Visibility<'a>>>,
    seconds: Vec<StageTime>,
    /// The problem tours found for this view space and visibility, by the
    /// camera and cost model they were timed with (shared with the
    /// preparations made by [`Prepared::with_job`]).
    tours: Tours,
}

/// Problem tours by (camera, cost model).
type Tours = Arc<Mutex<Vec<(Camera, CostModelParams, Arc<Vec<View>>)>>>;

/// A viewpoint and a viewing direction.
type View = (glam::DVec3, glam::DVec3);

impl<'a> Prepared<'a> {
    /// Prepares `input` for `job` (named `job_name` in errors). Fails when
    /// the job's visibility mode lacks its ingredient (geometry, a PVS file).
    pub fn new(input: &'a SceneInput, job: &Job, job_name: &str) -> Result<Self> {
        job.validate(job_name)?;
        let start = Instant::now();
        let visibility = Visibility::new(
            job,
            &input.scene,
            &input.hierarchy,
            input.visibility_inputs(job),
        )?
        .map(Arc::new);
        let mut seconds = input.seconds.clone();
        if visibility.is_some() {
            seconds.push(StageTime::new(
                "visibility_setup",
                start.elapsed().as_secs_f64(),
            ));
        }
        Ok(Prepared {
            input,
            job: job.clone(),
            job_name: job_name.into(),
            visibility,
            seconds,
            tours: Tours::default(),
        })
    }

    /// The same input prepared for `job`: shares this visibility when the
    /// view space, its grid and the visibility parameters are the same,
    /// prepares a new one otherwise.
    pub fn with_job(&self, job: &Job) -> Result<Prepared<'a>> {
        if self.shares_visibility_with(job) {
            job.validate(&self.job_name)?;
            Ok(Prepared {
                input: self.input,
                job: job.clone(),
                job_name: self.job_name.clone(),
                visibility: self.visibility.clone(),
                seconds: self.seconds.clone(),
                tours: self.tours.clone(),
            })
        } else {
            Prepared::new(self.input, job, &self.job_name)
        }
    }

    /// True when `job` has the same visible sets as this preparation's job:
    /// the same view space, grid and visibility parameters.
    pub fn shares_visibility_with(&self, job: &Job) -> bool {
        let a = &self.job;
        a.view_space == job.view_space
            && a.problem_views.cell_size == job.problem_views.cell_size
            && a.problem_views.grid_origin == job.problem_views.grid_origin
            && a.visibility == job.visibility
    }

    /// The problem tour for this job's camera and cost model: `find`'s,
    /// found once per preparation sharing this visibility.
    pub(crate) fn cached_tour(&self, find: impl FnOnce() -> Vec<View>) -> Arc<Vec<View>> {
        let key = (&self.job.camera, &self.job.cost_model);
        let mut tours = self.tours.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, _, t)) = tours.iter().find(|(c, m, _)| (c, m) == key) {
            return t.clone();
        }
        let tour = Arc::new(find());
        tours.push((key.0.clone(), key.1.clone(), tour.clone()));
        tour
    }

    /// The scene input.
    pub fn input(&self) -> &'a SceneInput {
        self.input
    }

    /// The scene (with the job's levels of detail).
    pub fn scene(&self) -> &'a Scene {
        &self.input.scene
    }

    /// The object hierarchy.
    pub fn hierarchy(&self) -> &'a Hierarchy {
        &self.input.hierarchy
    }

    /// The job.
    pub fn job(&self) -> &Job {
        &self.job
    }

    /// How errors name the job.
    pub fn job_name(&self) -> &str {
        &self.job_name
    }

    /// The visibility, `None` for mode `none`.
    pub fn visibility(&self) -> Option<&Visibility<'a>> {
        self.visibility.as_deref()
    }

    /// Wall time of the preparation steps (loading, levels of detail,
    /// occluders, ray caster, hierarchy, visibility), in order.
    pub fn seconds(&self) -> &[StageTime] {
        &self.seconds
    }
}
