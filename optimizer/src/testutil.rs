//! Small deterministic scenes and jobs for tests and benchmarks (no files).

use glam::DVec3;

use crate::job::Job;
use crate::rng::Rng;
use crate::scene::{Object, Scene};

/// A block grid of `nx × nz` blocks, 40 m apart, each holding a few objects
/// of varied size, cost and height (buildings and street furniture), with
/// streets free at `x, z ≡ 0 (mod 40)`.
pub fn synthetic_city(seed: u64, nx: u32, nz: u32) -> Scene {
    let mut rng = Rng::new(seed);
    let mut objects = Vec::new();
    for bx in 0..nx {
        for bz in 0..nz {
            let base = DVec3::new(f64::from(bx) * 40.0 + 6.0, 0.0, f64::from(bz) * 40.0 + 6.0);
            let count = 2 + (rng.next_u64() % 5) as usize;
            for _ in 0..count {
                let size = DVec3::new(
                    rng.range(1.0, 12.0),
                    rng.range(1.0, 30.0),
                    rng.range(1.0, 12.0),
                );
                let p = base
                    + DVec3::new(
                        rng.range(0.0, 28.0 - size.x),
                        0.0,
                        rng.range(0.0, 28.0 - size.z),
                    );
                objects.push(Object {
                    name: format!("o{}", objects.len()),
                    min: p,
                    max: p + size,
                    triangles: 50 + rng.next_u64() % 5000,
                    draw_calls: 1 + (rng.next_u64() % 3) as u32,
                    lods: Vec::new(),
                });
            }
        }
    }
    Scene { objects }
}

/// A job over the streets of [`synthetic_city`] at eye height, with a cost
/// model that makes looking along the streets expensive.
pub fn synthetic_job(nx: u32, nz: u32) -> Job {
    let mut job = Job::with_view_space(
        [0.0, 1.5, 0.0],
        [f64::from(nx) * 40.0, 2.0, f64::from(nz) * 40.0],
    );
    job.problem_views.cell_size = 20.0;
    job.cost_model.frame_ms = 1.0;
    job.cost_model.draw_call_us = 40.0;
    job.target_frame_time_ms = 4.0;
    job
}
