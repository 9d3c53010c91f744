//! Aggressive from-region visibility by ray sampling, for any triangle soup.
//!
//! Rays start at uniformly random points of the cell and go in uniformly
//! random directions of the band of elevations any view can see (the pitch
//! range widened by the frustum's half-diagonal). Every object a ray reaches
//! before its first blocking surface (see [`crate::render::raycast`]) is visible;
//! objects that meet the cell always are. Objects no ray reaches are culled,
//! so the set may miss objects that are visible through small gaps: the
//! result is an estimate, reported with two measures of what was missed:
//!
//! * the Good–Turing *missing mass* `f1 / N` (objects seen by exactly one
//!   ray over all `N` object observations): the chance that one more ray
//!   would find an object not yet found;
//! * the Chao1 estimate of the *number* of visible objects not found,
//!   `f1² / (2·f2)` (`f1·(f1 − 1) / 2` when no object was seen twice).
//!
//! Uniform rays rarely hit small, distant objects, so a second phase aims
//! rays at them: for every object not found yet, `probes_per_object`
//! segments run from random points of the cell to random points on the
//! object's surfaces that face them (reverse sampling); an unobstructed one
//! makes the object visible. The estimates above describe the uniform
//! phase; the report also says how many objects the probes added, and the
//! residual estimate is the Chao1 count minus those.

use std::sync::Arc;

use glam::DVec3;

use super::{CellVisibility, ObjectSet};
use crate::api::job::Job;
use crate::math::geom::{Aabb, frustum_half_diagonal};
use crate::math::rng::Rng;
use crate::render::raycast::RayCaster;
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;

/// Sampled visibility of one job.
pub struct Sampled<'a> {
    caster: &'a RayCaster,
    geometry: &'a SceneGeometry,
    /// Per object, its range of instances in the geometry.
    ranges: Vec<(usize, usize)>,
    probes: u32,
    rays: u32,
    seed: u64,
    /// `sin` of the lowest and highest elevation a view can see.
    band: [f64; 2],
}

impl<'a> Sampled<'a> {
    /// The sampler of `job` over `caster` (built from `geometry`).
    pub fn new(caster: &'a RayCaster, geometry: &'a SceneGeometry, job: &Job) -> Sampled<'a> {
        let [w, h] = job.camera.resolution;
        let hd = frustum_half_diagonal(job.camera.fov_deg, f64::from(w) / f64::from(h));
        let half_pi = std::f64::consts::FRAC_PI_2;
        let [lo, hi] = job.view_space.pitch_deg.map(f64::to_radians);
        let ranges = geometry.instance_ranges();
        Sampled {
            caster,
            geometry,
            ranges,
            probes: job.visibility.probes_per_object,
            rays: job.visibility.rays_per_region,
            seed: job.visibility.seed,
            band: [
                (lo - hd).clamp(-half_pi, half_pi).sin(),
                (hi + hd).clamp(-half_pi, half_pi).sin(),
            ],
        }
    }

    /// Rays per cell.
    pub fn rays(&self) -> u32 {
        self.rays
    }

    /// The sampled set of `cell` (`index` seeds its rays).
    pub fn cell_pvs(&self, cell: &Aabb, index: u64, scene: &Scene) -> CellVisibility {
        let n = scene.objects.len();
        let mut hits = vec![0u32; n];
        let mut seen_by_ray: Vec<u32> = Vec::new();
        let mut rng = Rng::new(self.seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut observations = 0u64;
        for _ in 0..self.rays {
            let origin = rng.in_box(cell.min, cell.max);
            let y = rng.range(self.band[0], self.band[1]);
            let a = rng.range(0.0, std::f64::consts::TAU);
            let r = (1.0 - y * y).max(0.0).sqrt();
            let dir = DVec3::new(r * a.cos(), y, r * a.sin());
            seen_by_ray.clear();
            self.caster
                .trace(origin, dir, 0.0, f64::INFINITY, &mut |o| {
                    seen_by_ray.push(o)
                });
            seen_by_ray.sort_unstable();
            seen_by_ray.dedup();
            for &o in &seen_by_ray {
                if let Some(h) = hits.get_mut(o as usize) {
                    *h += 1;
                    observations += 1;
                }
            }
        }
        let mut set = ObjectSet::new(n);
        let (mut f1, mut f2) = (0u64, 0u64);
        for (o, &h) in hits.iter().enumerate() {
            if h > 0 {
                set.insert(o as u32);
            }
            f1 += u64::from(h == 1);
            f2 += u64::from(h == 2);
        }
        for (o, ob) in scene.objects.iter().enumerate() {
            if ob.min.cmple(cell.max).all() && cell.min.cmple(ob.max).all() {
                set.insert(o as u32);
            }
        }
        // Reverse sampling towards the objects not found yet.
        let mut probed = 0u64;
        for o in 0..n as u32 {
            if set.contains(o) {
                continue;
            }
            for _ in 0..self.probes {
                let p = rng.in_box(cell.min, cell.max);
                let Some(x) =
                    self.geometry
                        .surface_point(self.ranges[o as usize], p, 4, &mut rng, |_| true)
                else {
                    continue;
                };
                if self.caster.segment_clear(p, x) {
                    set.insert(o);
                    probed += 1;
                    break;
                }
            }
        }
        let (f1, f2) = (f1 as f64, f2 as f64);
        let chao1 = if f2 > 0.0 {
            f1 * f1 / (2.0 * f2)
        } else {
            f1 * (f1 - 1.0).max(0.0) / 2.0
        };
        CellVisibility {
            set: Arc::new(set),
            missing_mass: if observations > 0 {
                f1 / observations as f64
            } else {
                0.0
            },
            unseen_objects: (chao1 - probed as f64).max(0.0),
            found_by_probes: probed,
            covered: true,
        }
    }
}
