//! `iboh`: an image-based object hierarchy (Lee, Chen and Lin), every
//! cluster of the object hierarchy with its own view-independent images.
//!
//! Each node gets reference images taken from a sampling circle around it
//! (`iboh.images` of them kept, `iboh.reference_px` texels a side) and is
//! drawn from them, two images warped, wherever the viewpoint lies outside
//! its circle: the circle's radius is the nearest distance at which a
//! reference image frames the node's sphere with at least
//! `memory.texels_per_pixel` texels per output pixel (`2ρ·k/(N_ref·θ)`), and
//! at least `iboh.kappa` node radii. No selection: every node has its
//! images (memory = nodes × images × `N_ref²` × bytes per texel), and the
//! runtime draws the hierarchy's cut of the highest nodes whose circle a
//! view lies outside, their objects as geometry below it.
//!
//! In the placement each node is one impostor whose view cell is the
//! outside of a sphere (a shaft of half-angle 180° around its centre, the
//! circle extended to 3D since our viewpoints are not on a ground plane),
//! costed as two image layers; a CPV's impostors are the cut seen from all
//! of its region. The paper's images are 3D-warped colour and depth, whose
//! error (holes) the layered parallax check does not bound: `evaluate`
//! counts them as view-independent and leaves them out of that check.

use rayon::prelude::*;

use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, SphereJson, ViewCellJson};
use crate::math::enclosing::enclosing_cone;
use crate::methods::env_map::{EnvMapPlacement, with_costs};
use crate::model::impostor::ImpostorModel;
use crate::views::{Context, Counters, ProblemViews};

/// Reference images warped per node and frame (the two that bracket the
/// viewpoint on the sampling circle).
pub const WARPED_IMAGES: u32 = 2;

/// The side of a node's reference images, texels.
pub fn reference_px(job: &Job) -> u32 {
    job.iboh
        .reference_px
        .unwrap_or(job.camera.resolution[1])
        .max(1)
}

/// The radius of the sampling circle of a node of radius `rho`: outside it
/// a reference image has at least `memory.texels_per_pixel` texels per
/// output pixel, and it is at least `iboh.kappa` node radii (and more than
/// one).
pub fn circle_radius(job: &Job, imodel: &ImpostorModel, rho: f64) -> f64 {
    let n_ref = f64::from(reference_px(job));
    let sampled = 2.0 * rho * imodel.texels_per_pixel / (n_ref * imodel.theta);
    sampled
        .max(job.iboh.kappa * rho)
        .max(rho * (1.0 + 1e-9) + 1e-6)
}

/// The memory of one node's images, bytes.
pub fn node_memory(job: &Job, imodel: &ImpostorModel) -> u64 {
    let n = f64::from(reference_px(job));
    (f64::from(job.iboh.images) * n * n * imodel.bytes_per_texel).ceil() as u64
}

/// The `iboh` placement: one impostor per hierarchy node (its id is the
/// node's), and per CPV the cut its region lies outside of.
pub fn place(ctx: &Context, job: &Job, pv: &ProblemViews, counters: &Counters) -> EnvMapPlacement {
    let h = ctx.hierarchy;
    let imodel = ImpostorModel::new(job);
    let memory = node_memory(job, &imodel);
    let radius: Vec<f64> = h
        .nodes
        .iter()
        .map(|n| circle_radius(job, &imodel, n.sphere.radius))
        .collect();
    let impostors: Vec<PlacedImpostor> = h
        .nodes
        .iter()
        .enumerate()
        .map(|(id, n)| {
            let mut objects = h.objects(id as u32).to_vec();
            objects.sort_unstable();
            let cost = ctx
                .model
                .impostor(WARPED_IMAGES, n.sphere.radius, radius[id]);
            PlacedImpostor {
                id: id as u32,
                node: id as u32,
                objects,
                sphere: SphereJson {
                    center: n.sphere.center.to_array(),
                    radius: n.sphere.radius,
                },
                view_cell: ViewCellJson::Shaft {
                    apex: n.sphere.center.to_array(),
                    axis: [0.0, 1.0, 0.0],
                    half_angle_deg: 180.0,
                    min_distance: radius[id],
                },
                layers: WARPED_IMAGES,
                resolution: reference_px(job),
                memory_bytes: memory,
                time_ms: cost.cpu + cost.gpu,
            }
        })
        .collect();
    let cpv_impostors = pv
        .cpvs
        .par_iter()
        .map(|cpv| {
            let cone = enclosing_cone(&cpv.region, &cpv.vdi, &ctx.lens);
            let mut cut = Vec::new();
            h.walk(|id, n| {
                if !cone.intersects_sphere(n.sphere.center, n.sphere.radius) {
                    return false;
                }
                if cpv.region.distance_to_point(n.sphere.center) >= radius[id as usize] {
                    cut.push(id);
                    return false;
                }
                true
            });
            cut.sort_unstable();
            cut
        })
        .collect();
    with_costs(ctx, pv, impostors, cpv_impostors, counters)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{synthetic_city, synthetic_job, with_problem_views};

    #[test]
    fn circle_radius_by_hand() {
        let mut job = synthetic_job(5, 5);
        job.camera.fov_deg = 90.0;
        job.camera.resolution = [256, 256];
        job.iboh.reference_px = Some(256);
        let imodel = ImpostorModel::new(&job);
        // θ = 2·tan 45° / 256: a 256-texel image frames the sphere's
        // diameter at one texel per pixel from one radius (the paper's
        // setting), so κ = 1.5 decides.
        assert!((imodel.theta - 2.0 / 256.0).abs() < 1e-15);
        assert!((circle_radius(&job, &imodel, 4.0) - 6.0).abs() < 1e-9);
        // A quarter of the texels: four radii.
        job.iboh.reference_px = Some(64);
        assert!((circle_radius(&job, &imodel, 4.0) - 16.0).abs() < 1e-9);
        // Nine images of 64² RGBA8 texels with mipmaps (4/3).
        let bpt = imodel.bytes_per_texel;
        assert_eq!(
            node_memory(&job, &imodel),
            (9.0 * 64.0 * 64.0 * bpt).ceil() as u64
        );
    }

    /// Every CPV's impostors are the highest nodes its enclosing frustum
    /// meets whose circle its whole region lies outside of: an antichain,
    /// none with an ancestor that would do, each outside its circle, and
    /// every visible node the frustum meets either in the cut, below it, or
    /// with a descendant path to a leaf that is drawn as geometry.
    #[test]
    fn each_cpv_draws_the_highest_nodes_whose_circle_it_is_outside() {
        let scene = synthetic_city(3, 5, 5);
        let job = synthetic_job(5, 5);
        with_problem_views(&scene, &job, |ctx, pv| {
            let h = ctx.hierarchy;
            let p = place(ctx, &job, pv, &Counters::new());
            assert_eq!(p.impostors.len(), h.nodes.len());
            let imodel = ImpostorModel::new(&job);
            let mut used = 0;
            for (c, cpv) in pv.cpvs.iter().enumerate() {
                let cone = enclosing_cone(&cpv.region, &cpv.vdi, &ctx.lens);
                let cut = &p.cpv_impostors[c];
                used += cut.len();
                for &n in cut {
                    let node = &h.nodes[n as usize];
                    let r = circle_radius(&job, &imodel, node.sphere.radius);
                    assert!(cpv.region.distance_to_point(node.sphere.center) >= r);
                    assert!(cone.intersects_sphere(node.sphere.center, node.sphere.radius));
                    // No ancestor would do.
                    let mut a = node.parent;
                    while a != u32::MAX {
                        let an = &h.nodes[a as usize];
                        let ra = circle_radius(&job, &imodel, an.sphere.radius);
                        assert!(cpv.region.distance_to_point(an.sphere.center) < ra);
                        assert!(!cut.contains(&a));
                        a = an.parent;
                    }
                }
                // Every leaf the frustum meets through all its ancestors is
                // under exactly one node of the cut, or under none and inside
                // every circle of its path.
                for (l, leaf) in h.nodes.iter().enumerate() {
                    if leaf.children.is_some() {
                        continue;
                    }
                    let mut path = vec![l as u32];
                    while let Some(&n) = path.last()
                        && h.nodes[n as usize].parent != u32::MAX
                    {
                        path.push(h.nodes[n as usize].parent);
                    }
                    let seen = path.iter().all(|&n| {
                        let s = &h.nodes[n as usize].sphere;
                        cone.intersects_sphere(s.center, s.radius)
                    });
                    if !seen {
                        continue;
                    }
                    let in_cut = path.iter().filter(|n| cut.contains(n)).count();
                    if in_cut == 0 {
                        assert!(path.iter().all(|&n| {
                            let s = &h.nodes[n as usize].sphere;
                            cpv.region.distance_to_point(s.center)
                                < circle_radius(&job, &imodel, s.radius)
                        }));
                    } else {
                        assert_eq!(in_cut, 1);
                    }
                }
            }
            assert!(used > 0, "no CPV lies outside any circle");
            let memory: u64 = p.impostors.iter().map(|i| i.memory_bytes).sum();
            assert_eq!(memory, h.nodes.len() as u64 * node_memory(&job, &imodel));
        });
    }
}
