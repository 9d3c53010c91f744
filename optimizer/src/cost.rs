//! Rendering-time estimation (DESIGN §2.3, Wimmer & Wonka 2003 style).
//!
//! Costs are kept as a pair (CPU, GPU) in milliseconds so that the `max`
//! combination can be formed after summing: CPU = draw calls, GPU = triangles
//! and pixels. The frame time is `frame_ms + CPU + GPU` (`sum`),
//! `frame_ms + max(CPU, GPU)` (`max`) or `frame_ms + triangles·triangle_ns`
//! (`primitives`, where CPU and pixels are zero).

use crate::geom::projected_area_px;
use crate::job::{Combine, Job};

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

    /// Cost of an impostor of `layers` quads over a cluster sphere of `radius`
    /// at `distance`: one draw call, two triangles per layer, and every layer
    /// rasterises the cluster's projected area (`c_call + c_tri·2n + c_pix·n·area`).
    pub fn impostor(&self, layers: u32, radius: f64, distance: f64) -> Cost {
        let n = f64::from(layers);
        match self.combine {
            Combine::Primitives => Cost {
                cpu: 0.0,
                gpu: self.tri_ms * 2.0 * n,
            },
            _ => Cost {
                cpu: self.call_ms,
                gpu: self.tri_ms * 2.0 * n + self.pix_ms * n * self.pixels(radius, distance),
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
