//! Rendering-time estimation (DESIGN §2.3, Wimmer & Wonka 2003 style).
//!
//! Costs are kept as a pair (CPU, GPU) in milliseconds so that the `max`
//! combination can be formed after summing: CPU = draw calls, GPU = triangles
//! and pixels. The frame time is `frame_ms + CPU + GPU` (`sum`),
//! `frame_ms + max(CPU, GPU)` (`max`) or `frame_ms + triangles·triangle_ns`
//! (`primitives`, where CPU and pixels are zero).
//!
//! Objects with levels of detail ([`Object::lods`]) cost the level drawn at
//! the eye distance ([`CostModel::object_view`]); over a view region the
//! estimate uses the closest distance ([`CostModel::object_region`]). The
//! screen coverage that selects a level is the projected bounding-sphere
//! area over the screen area, [`CostModel::coverage`]; the pixel term always
//! uses the object's bounding sphere, whatever the level.

use crate::api::job::{Combine, Job};
use crate::math::geom::{ViewFrustum, projected_area_px};
use crate::scene::hierarchy::Hierarchy;
use crate::scene::{Object, Scene};

/// A cost in milliseconds, split into CPU and GPU parts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cost {
    /// Draw-call (CPU) time, ms.
    pub cpu: f64,
    /// Triangle and pixel (GPU) time, ms.
    pub gpu: f64,
}

impl std::ops::Add for Cost {
    type Output = Cost;
    fn add(self, o: Cost) -> Cost {
        Cost {
            cpu: self.cpu + o.cpu,
            gpu: self.gpu + o.gpu,
        }
    }
}

impl std::ops::AddAssign for Cost {
    fn add_assign(&mut self, o: Cost) {
        self.cpu += o.cpu;
        self.gpu += o.gpu;
    }
}

impl std::ops::Sub for Cost {
    type Output = Cost;
    fn sub(self, o: Cost) -> Cost {
        Cost {
            cpu: self.cpu - o.cpu,
            gpu: self.gpu - o.gpu,
        }
    }
}

/// The cost model of a job: constants converted to milliseconds plus the
/// camera quantities the pixel estimate needs.
#[derive(Clone, Copy, Debug)]
pub struct CostModel {
    /// Fixed frame cost, ms.
    pub frame_ms: f64,
    /// Per draw call, ms.
    pub call_ms: f64,
    /// Per triangle, ms.
    pub tri_ms: f64,
    /// Per pixel, ms.
    pub pix_ms: f64,
    /// How costs combine.
    pub combine: Combine,
    /// Focal length in pixels (`(H/2)/tan(fovy/2)`).
    pub focal_px: f64,
    /// Screen area in pixels.
    pub screen_px: f64,
}

impl CostModel {
    /// The cost model of `job`.
    pub fn new(job: &Job) -> CostModel {
        let c = &job.cost_model;
        let [w, h] = job.camera.resolution;
        CostModel {
            frame_ms: c.frame_ms,
            call_ms: c.draw_call_us * 1e-3,
            tri_ms: c.triangle_ns * 1e-6,
            pix_ms: c.pixel_ns * 1e-6,
            combine: c.combine,
            focal_px: f64::from(h) * 0.5 / (job.camera.fov_deg.to_radians() * 0.5).tan(),
            screen_px: f64::from(w) * f64::from(h),
        }
    }

    /// Frame time of a frame whose drawn objects sum to `c`.
    pub fn frame_time(&self, c: Cost) -> f64 {
        match self.combine {
            Combine::Sum | Combine::Primitives => self.frame_ms + c.cpu + c.gpu,
            Combine::Max => self.frame_ms + c.cpu.max(c.gpu),
        }
    }

    /// The cost of the objects whose bounding spheres meet the exact view
    /// frustum `f` and that `draw` accepts (called once per such object, in
    /// hierarchy order), each at its distance from the eye.
    pub fn view_cost(
        &self,
        scene: &Scene,
        h: &Hierarchy,
        f: &ViewFrustum,
        mut draw: impl FnMut(u32) -> bool,
    ) -> Cost {
        let eye = f.eye();
        let mut cost = Cost::default();
        // A node whose sphere lies inside the frustum holds only objects
        // inside it (their spheres lie in the node's, up to rounding the
        // containment test's margin covers): they are not tested again.
        h.walk_with(false, |n, node, inside| {
            let s = node.sphere;
            let inside = inside || f.contains_sphere(s.center, s.radius);
            if !inside && !f.intersects_sphere(s.center, s.radius) {
                return None;
            }
            if node.children.is_none() {
                for &o in h.objects(n) {
                    let s = &h.object_spheres[o as usize];
                    if (inside || f.intersects_sphere(s.center, s.radius)) && draw(o) {
                        let ob = &scene.objects[o as usize];
                        cost += self.object_view(ob, s.radius, eye.distance(s.center));
                    }
                }
            }
            Some(inside)
        });
        cost
    }

    /// The frame time saved by a cost change of `saving`, when times add up
    /// (`sum` and `primitives`); `None` for `max`, where it depends on the
    /// whole cost.
    pub fn time_saved(&self, saving: Cost) -> Option<f64> {
        match self.combine {
            Combine::Sum | Combine::Primitives => Some(saving.cpu + saving.gpu),
            Combine::Max => None,
        }
    }

    /// True when replacing objects that cost `orig` by something costing
    /// `imp` can lower some frame time: where times add up, when it costs
    /// less in total; in `max` mode, when it costs less on either side
    /// (which side decides depends on the rest of the frame). It depends
    /// on the two costs alone, not on the frame they are part of.
    pub fn may_accelerate(&self, orig: Cost, imp: Cost) -> bool {
        match self.combine {
            Combine::Sum | Combine::Primitives => imp.cpu + imp.gpu < orig.cpu + orig.gpu,
            Combine::Max => imp.cpu < orig.cpu || imp.gpu < orig.gpu,
        }
    }

    /// Projected pixels of a sphere of `radius` seen from `distance`.
    pub fn pixels(&self, radius: f64, distance: f64) -> f64 {
        projected_area_px(radius, distance, self.focal_px, self.screen_px)
    }

    /// Cost of drawing geometry: `calls` draw calls, `triangles`, and a
    /// bounding sphere of `radius` at `distance` from the eye (or the closest
    /// distance over a view region).
    pub fn geometry(&self, calls: u32, triangles: u64, radius: f64, distance: f64) -> Cost {
        match self.combine {
            Combine::Primitives => Cost {
                cpu: 0.0,
                gpu: self.tri_ms * triangles as f64,
            },
            _ => Cost {
                cpu: self.call_ms * f64::from(calls),
                gpu: self.tri_ms * triangles as f64 + self.pix_ms * self.pixels(radius, distance),
            },
        }
    }

    /// Screen coverage of a sphere of `radius` seen from `distance`: its
    /// projected area over the screen area, in `[0, 1]` (1 from inside the
    /// sphere). This is the quantity [`crate::api::scene::LodLevel::min_coverage`]
    /// is compared with.
    pub fn coverage(&self, radius: f64, distance: f64) -> f64 {
        (self.pixels(radius, distance) / self.screen_px).clamp(0.0, 1.0)
    }

    /// The level of detail of `o` drawn when its bounding sphere (`radius`)
    /// is at `distance` from the eye: the first level whose `min_coverage`
    /// the coverage reaches, or `None` when the coverage is below every
    /// threshold (the object is culled). Always `Some(0)` for an object
    /// without levels.
    pub fn lod_level(&self, o: &Object, radius: f64, distance: f64) -> Option<usize> {
        if o.lods.is_empty() {
            return Some(0);
        }
        let c = self.coverage(radius, distance);
        o.lods.iter().position(|l| c >= l.min_coverage)
    }

    /// Draw calls and triangles of level `level` of `o` (level 0 is the
    /// object itself, also when it has no levels).
    fn level_counts(o: &Object, level: usize) -> (u32, u64) {
        match o.lods.get(level) {
            Some(l) => (l.draw_calls, l.triangles),
            None => (o.draw_calls, o.triangles),
        }
    }

    /// Exact cost of `o` seen from an eye at `distance` from its bounding
    /// sphere's centre: the cost of the level drawn there ([`Self::lod_level`]),
    /// zero when it is culled. The pixel term uses the bounding sphere of
    /// `radius` whatever the level, as [`Self::geometry`] does.
    pub fn object_view(&self, o: &Object, radius: f64, distance: f64) -> Cost {
        match self.lod_level(o, radius, distance) {
            None => Cost::default(),
            Some(level) => {
                let (calls, triangles) = Self::level_counts(o, level);
                self.geometry(calls, triangles, radius, distance)
            }
        }
    }

    /// A conservative cost of `o` over a view region whose closest distance
    /// to the bounding sphere's centre is `closest`. Coverage is largest at
    /// `closest`, so every point of the region draws a level at least as
    /// coarse as `lod_level(closest)` (or nothing); the result is the
    /// component-wise maximum (CPU and GPU separately) over those levels of
    /// each level's cost at `closest`. It bounds [`Self::object_view`] at
    /// every distance `≥ closest`, even when a coarser level has more draw
    /// calls or triangles than a finer one. Zero when the object is culled at
    /// `closest` (it is then culled everywhere in the region).
    pub fn object_region(&self, o: &Object, radius: f64, closest: f64) -> Cost {
        let Some(first) = self.lod_level(o, radius, closest) else {
            return Cost::default();
        };
        let levels = o.lods.len().max(1);
        let mut out = Cost::default();
        for level in first..levels {
            let (calls, triangles) = Self::level_counts(o, level);
            let c = self.geometry(calls, triangles, radius, closest);
            out.cpu = out.cpu.max(c.cpu);
            out.gpu = out.gpu.max(c.gpu);
        }
        out
    }

    /// Cost of an impostor of `layers` quads over a cluster sphere of `radius`
    /// at `distance`: one draw call, two triangles per layer, and every layer
    /// rasterises the cluster's projected area (`c_call + c_tri·2n + c_pix·n·area`).
    pub fn impostor(&self, layers: u32, radius: f64, distance: f64) -> Cost {
        self.impostor_covering(layers, self.pixels(radius, distance))
    }

    /// Cost of an impostor of `layers` layers, each rasterising `pixels`
    /// (its sphere's [`pixels`](Self::pixels)): [`impostor`](Self::impostor)
    /// with the projection computed once for several layer counts.
    pub fn impostor_covering(&self, layers: u32, pixels: f64) -> Cost {
        let n = f64::from(layers);
        match self.combine {
            Combine::Primitives => Cost {
                cpu: 0.0,
                gpu: self.tri_ms * 2.0 * n,
            },
            _ => Cost {
                cpu: self.call_ms,
                gpu: self.tri_ms * 2.0 * n + self.pix_ms * n * pixels,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(combine: Combine) -> Job {
        let mut j = Job::with_view_space([0.0; 3], [1.0; 3]);
        j.cost_model.frame_ms = 1.0;
        j.cost_model.draw_call_us = 10.0;
        j.cost_model.triangle_ns = 2.0;
        j.cost_model.pixel_ns = 0.5;
        j.cost_model.combine = combine;
        j
    }

    #[test]
    fn sum_mode_hand_computed() {
        let m = CostModel::new(&job(Combine::Sum));
        // f = 256 / tan(22.5°); sphere r = 1 at d = 100: π f² / (10⁴ − 1) px.
        let f = 256.0 / 22.5f64.to_radians().tan();
        let px = std::f64::consts::PI * f * f / 9999.0;
        let c = m.geometry(3, 1000, 1.0, 100.0);
        assert!((c.cpu - 0.03).abs() < 1e-12);
        assert!((c.gpu - (0.002 + 0.5e-6 * px)).abs() < 1e-12);
        assert!((m.frame_time(c) - (1.0 + 0.03 + 0.002 + 0.5e-6 * px)).abs() < 1e-12);
        let i = m.impostor(4, 1.0, 100.0);
        assert!((i.cpu - 0.01).abs() < 1e-12);
        assert!((i.gpu - (2e-6 * 8.0 + 0.5e-6 * 4.0 * px)).abs() < 1e-12);
    }

    #[test]
    fn max_and_primitive_modes() {
        let m = CostModel::new(&job(Combine::Max));
        let c = Cost { cpu: 5.0, gpu: 3.0 };
        assert_eq!(m.frame_time(c), 6.0);
        let p = CostModel::new(&job(Combine::Primitives));
        let g = p.geometry(7, 1_000_000, 1.0, 1.0);
        assert_eq!(g.cpu, 0.0);
        assert!((p.frame_time(g) - 3.0).abs() < 1e-12);
        assert!((p.impostor(3, 1.0, 1.0).gpu - 12e-6).abs() < 1e-18);
    }

    /// An object of 1000 triangles and 3 calls with two coarser levels; the
    /// last has more draw calls than the others.
    fn lod_object() -> Object {
        use crate::api::scene::LodLevel;
        let level = |min_coverage, triangles, draw_calls| LodLevel {
            min_coverage,
            triangles,
            draw_calls,
        };
        Object {
            name: "o".into(),
            min: glam::DVec3::ZERO,
            max: glam::DVec3::ONE,
            triangles: 1000,
            draw_calls: 3,
            lods: vec![
                level(0.01, 1000, 3),
                level(0.001, 200, 1),
                level(0.0001, 50, 4),
            ],
        }
    }

    #[test]
    fn lod_selection_hand_computed() {
        let m = CostModel::new(&job(Combine::Sum));
        let o = lod_object();
        // Coverage of r = 1 at d: π f² / (d² − 1) / 512² = 4.5775 / (d² − 1).
        let f = 256.0 / 22.5f64.to_radians().tan();
        let k = std::f64::consts::PI * f * f / (512.0 * 512.0);
        assert!((k - 4.5775).abs() < 1e-3);
        assert!((m.coverage(1.0, 30.0) - k / 899.0).abs() < 1e-15);
        assert_eq!(m.coverage(1.0, 0.5), 1.0, "inside the sphere");
        // d = 10: 0.0462 ≥ 0.01; d = 30: 0.00509; d = 100: 0.000458;
        // d = 300: 0.0000509 < 0.0001, culled.
        assert_eq!(m.lod_level(&o, 1.0, 10.0), Some(0));
        assert_eq!(m.lod_level(&o, 1.0, 30.0), Some(1));
        assert_eq!(m.lod_level(&o, 1.0, 100.0), Some(2));
        assert_eq!(m.lod_level(&o, 1.0, 300.0), None);
        // Thresholds are inclusive: exactly at level 1's coverage, level 1.
        let d1 = (k / 0.001 + 1.0).sqrt();
        let at = m.lod_level(&o, 1.0, d1 * (1.0 - 1e-12));
        assert_eq!(at, Some(1));
        // Without levels, always full detail.
        let mut plain = lod_object();
        plain.lods.clear();
        assert_eq!(m.lod_level(&plain, 1.0, 1e9), Some(0));
        assert_eq!(
            m.object_view(&plain, 1.0, 30.0),
            m.geometry(3, 1000, 1.0, 30.0)
        );

        // Sum mode: call 0.01 ms, triangle 2e-6 ms, pixel 5e-7 ms.
        let px30 = std::f64::consts::PI * f * f / 899.0;
        let v = m.object_view(&o, 1.0, 30.0);
        assert!((v.cpu - 0.01).abs() < 1e-15, "{v:?}");
        assert!(
            (v.gpu - (200.0 * 2e-6 + 5e-7 * px30)).abs() < 1e-15,
            "{v:?}"
        );
        assert_eq!(m.object_view(&o, 1.0, 300.0), Cost::default());
        // Region from 30 m: levels 1 and 2 may be drawn; level 2 has the most
        // calls (4), level 1 the most triangles (200).
        let r = m.object_region(&o, 1.0, 30.0);
        assert!((r.cpu - 0.04).abs() < 1e-15, "{r:?}");
        assert!(
            (r.gpu - (200.0 * 2e-6 + 5e-7 * px30)).abs() < 1e-15,
            "{r:?}"
        );
        let px10 = std::f64::consts::PI * f * f / 99.0;
        let r = m.object_region(&o, 1.0, 10.0);
        assert!((r.cpu - 0.04).abs() < 1e-15, "{r:?}");
        assert!(
            (r.gpu - (1000.0 * 2e-6 + 5e-7 * px10)).abs() < 1e-15,
            "{r:?}"
        );
        assert_eq!(m.object_region(&o, 1.0, 300.0), Cost::default());
        // Primitives: triangles only.
        let p = CostModel::new(&job(Combine::Primitives));
        let r = p.object_region(&o, 1.0, 30.0);
        assert_eq!(r.cpu, 0.0);
        assert!((r.gpu - 200.0 * 2e-6).abs() < 1e-18, "{r:?}");
        let v = p.object_view(&o, 1.0, 100.0);
        assert!((v.gpu - 50.0 * 2e-6).abs() < 1e-18, "{v:?}");
    }

    #[test]
    fn region_cost_bounds_every_farther_view() {
        use crate::api::scene::LodLevel;
        use crate::math::rng::Rng;
        let mut rng = Rng::new(11);
        for combine in [Combine::Sum, Combine::Max, Combine::Primitives] {
            let m = CostModel::new(&job(combine));
            for _ in 0..2000 {
                let n = (rng.next_u64() % 6) as usize;
                let mut thresholds: Vec<f64> = (0..n).map(|_| rng.f64().powi(4)).collect();
                thresholds.sort_by(|a, b| b.total_cmp(a));
                thresholds.dedup();
                let triangles = rng.next_u64() % 100_000;
                let draw_calls = 1 + (rng.next_u64() % 8) as u32;
                let mut lods: Vec<LodLevel> = thresholds
                    .iter()
                    .map(|&min_coverage| LodLevel {
                        min_coverage,
                        triangles: rng.next_u64() % 100_000,
                        draw_calls: 1 + (rng.next_u64() % 8) as u32,
                    })
                    .collect();
                if let Some(first) = lods.first_mut() {
                    first.triangles = triangles;
                    first.draw_calls = draw_calls;
                }
                let o = Object {
                    name: String::new(),
                    min: glam::DVec3::ZERO,
                    max: glam::DVec3::ONE,
                    triangles,
                    draw_calls,
                    lods,
                };
                let radius = rng.range(0.1, 20.0);
                let closest = rng.range(0.0, 500.0);
                let bound = m.object_region(&o, radius, closest);
                for _ in 0..20 {
                    let d = closest + rng.f64().powi(2) * 2000.0;
                    let v = m.object_view(&o, radius, d);
                    assert!(
                        v.cpu <= bound.cpu && v.gpu <= bound.gpu,
                        "{combine:?} {o:?} r {radius} closest {closest} d {d}: {v:?} > {bound:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn closer_is_never_cheaper() {
        let m = CostModel::new(&job(Combine::Sum));
        let mut last = f64::INFINITY;
        for d in [0.5, 1.0, 2.0, 5.0, 50.0, 500.0] {
            let t = m.frame_time(m.geometry(1, 10, 1.0, d));
            assert!(t <= last);
            last = t;
        }
    }
}
