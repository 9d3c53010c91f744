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

/// The geometry of a scene whose objects are solid boxes: each object is a
/// closed, outward-facing cuboid filling its bounds (one mesh per object,
/// one opaque single-sided material).
pub fn box_geometry(scene: &Scene) -> crate::geometry::SceneGeometry {
    use crate::geometry::{Instance, Material, MeshData, SceneGeometry};
    use glam::{DAffine3, Vec3};
    let mut meshes = Vec::new();
    let mut instances = Vec::new();
    for (o, ob) in scene.objects.iter().enumerate() {
        let (lo, hi) = (ob.min.as_vec3(), ob.max.as_vec3());
        let c = |x: bool, y: bool, z: bool| {
            Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let (f, t) = (false, true);
        let quads = [
            [c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t)],
            [c(t, f, f), c(f, f, f), c(f, t, f), c(t, t, f)],
            [c(t, f, t), c(t, f, f), c(t, t, f), c(t, t, t)],
            [c(f, f, f), c(f, f, t), c(f, t, t), c(f, t, f)],
            [c(f, t, t), c(t, t, t), c(t, t, f), c(f, t, f)],
            [c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t)],
        ];
        let mut m = MeshData::default();
        for q in quads {
            let n = (q[1] - q[0]).cross(q[3] - q[0]).normalize_or_zero();
            let base = m.positions.len() as u32;
            for p in q {
                m.positions.push(p);
                m.normals.push(n);
            }
            m.indices
                .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        meshes.push(m);
        instances.push(Instance {
            object: o as u32,
            mesh: o as u32,
            transform: DAffine3::IDENTITY,
        });
    }
    SceneGeometry {
        meshes,
        instances,
        materials: vec![Material::default()],
        textures: Vec::new(),
        objects: scene.objects.len(),
    }
}
