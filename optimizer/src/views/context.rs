//! What the per-region work of the approximation, the candidate generation
//! and the greedy share: the scene, its hierarchy and visibility, the cost
//! model and the job's limits ([`Context`], read-only), and the work
//! counters ([`Counters`]).

use std::sync::atomic::{AtomicU64, Ordering};

use glam::DVec3;

use crate::api::job::Job;
use crate::api::stats::{LodReport, LodStats};
use crate::control::Control;
use crate::math::enclosing::Lens;
use crate::math::geom::Vdi;
use crate::model::cost::CostModel;
use crate::scene::hierarchy::Hierarchy;
use crate::scene::{MAX_LODS, Scene};
use crate::visibility::Visibility;

/// Everything the per-region work needs, shared read-only across threads.
pub struct Context<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The object hierarchy.
    pub hierarchy: &'a Hierarchy,
    /// From-region visibility: regions count only their potentially
    /// visible objects (`None`: every object).
    pub visibility: Option<&'a Visibility<'a>>,
    /// The cost model.
    pub model: CostModel,
    /// `t_max`, ms.
    pub t_max: f64,
    /// The camera's lens.
    pub lens: Lens,
    /// Pitch range, radians.
    pub pitch: [f64; 2],
    /// Cancellation (checked per kd region and per cluster) and progress.
    pub control: Control<'a>,
}

impl<'a> Context<'a> {
    /// The context of `job` over a scene, its hierarchy and visibility.
    pub fn new(
        scene: &'a Scene,
        hierarchy: &'a Hierarchy,
        visibility: Option<&'a Visibility<'a>>,
        job: &Job,
        control: Control<'a>,
    ) -> Self {
        let [w, h] = job.camera.resolution;
        Context {
            scene,
            hierarchy,
            visibility,
            model: CostModel::new(job),
            t_max: job.target_frame_time_ms,
            lens: Lens {
                fov_deg: job.camera.fov_deg,
                aspect: f64::from(w) / f64::from(h),
            },
            pitch: job.view_space.pitch_deg.map(f64::to_radians),
            control,
        }
    }

    /// True once the run was cancelled.
    pub fn cancelled(&self) -> bool {
        self.control.cancelled()
    }

    /// True when some direction of `vdi` lies in the pitch range.
    pub fn pitch_overlaps(&self, vdi: &Vdi) -> bool {
        let [lo, hi] = vdi.elevation_range();
        hi >= self.pitch[0] - 1e-12 && lo <= self.pitch[1] + 1e-12
    }

    /// True when the unit direction `d` lies in the pitch range.
    pub fn in_pitch(&self, d: DVec3) -> bool {
        let pitch = d.y.clamp(-1.0, 1.0).asin();
        pitch >= self.pitch[0] && pitch <= self.pitch[1]
    }
}

/// Work counters of one run, safe to update from any thread.
pub struct Counters {
    /// (CPV, cluster) pairs recorded so far.
    pairs: AtomicU64,
    /// Per level of detail, how often it was chosen for a (region, object)
    /// pair; the last slot counts objects too small to be drawn.
    lod_levels: Vec<AtomicU64>,
}

impl Default for Counters {
    fn default() -> Self {
        Counters::new()
    }
}

impl Counters {
    /// Zero counters.
    pub fn new() -> Self {
        Counters {
            pairs: AtomicU64::new(0),
            lod_levels: (0..=MAX_LODS).map(|_| AtomicU64::new(0)).collect(),
        }
    }

    /// (CPV, cluster) pairs recorded so far.
    pub fn pairs(&self) -> u64 {
        self.pairs.load(Ordering::Relaxed)
    }

    /// Records `n` more (CPV, cluster) pairs.
    pub fn add_pairs(&self, n: u64) {
        self.pairs.fetch_add(n, Ordering::Relaxed);
    }

    /// Counts one choice of level `slot` ([`MAX_LODS`]: not drawn).
    pub fn count_lod(&self, slot: usize) {
        self.lod_levels[slot].fetch_add(1, Ordering::Relaxed);
    }

    /// Level-of-detail counters of `scene` (`None` when no object has
    /// levels and none were generated).
    pub fn lod_stats(&self, scene: &Scene, generated: Option<LodReport>) -> Option<LodStats> {
        let with = scene.objects.iter().filter(|o| !o.lods.is_empty()).count();
        if with == 0 && generated.is_none() {
            return None;
        }
        let levels = scene
            .objects
            .iter()
            .map(|o| o.lods.len())
            .max()
            .unwrap_or(0);
        let mut chosen: Vec<u64> = self.lod_levels[..levels]
            .iter()
            .map(|a| a.load(Ordering::Relaxed))
            .collect();
        chosen.push(self.lod_levels[MAX_LODS].load(Ordering::Relaxed));
        Some(LodStats {
            objects_with_lods: with as u64,
            chosen_levels: chosen,
            generated,
        })
    }
}
