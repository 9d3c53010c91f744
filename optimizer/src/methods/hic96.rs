//! `hic96`: a hierarchical image cache (Shade et al. 1996), replayed along
//! a walkthrough. No placement is made ahead of time: at every frame the
//! object hierarchy is traversed (`UpdateCaches` of the paper), a node's
//! cached image is drawn while the viewpoint stays in its safety zone, and a
//! node without a valid image gets one when its amortised cost (creation
//! over its life span, plus drawing the quad) is below the cost of drawing
//! its contents. The result is not a static placement but what a runtime
//! cache needs along the path: frame times with their spikes (a frame pays
//! for the images it creates), resident texture memory, images created.
//!
//! Choices where the paper leaves room (each as the paper's own "known
//! path" variant, or stated):
//! - the hierarchy is our object hierarchy (the paper's is a BSP tree with
//!   inflated leaves; ours needs neither: clusters hold whole objects);
//! - an image is a quad through the node's centre, facing the viewpoint it
//!   was made from, of the node's projected size in texels
//!   (`memory.texels_per_pixel` per pixel); none is made for a node whose
//!   projection exceeds the viewport or that holds the viewpoint;
//! - the safety zone is the cube inscribed in the sphere of radius `d`
//!   (Eq. 3–4 of the paper, with the sign per corner that keeps it
//!   conservative) over the corners of the node's box and its children's,
//!   for an error of `max_error_px` pixels;
//! - the life span `k` is found by searching the path ahead (the paper's
//!   offline-path option): the frames until the viewpoint first leaves the
//!   zone;
//! - creating an image costs drawing its contents plus reading back its
//!   pixels (the cost of drawing a quad of that size); drawing it costs an
//!   impostor of one layer;
//! - an image is released when its node is culled or the viewpoint leaves
//!   its zone (the paper releases culled nodes' images; a stale image is
//!   of no further use).

use glam::DVec3;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::api::job::Job;
use crate::math::geom::{Aabb, ViewFrustum};
use crate::model::cost::{Cost, CostModel};
use crate::model::impostor::ImpostorModel;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;
use crate::visibility::ObjectSet;

/// A view along the path: eye and unit direction.
pub type View = (DVec3, DVec3);

/// One frame of the replay.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Frame {
    /// Frame time with the cache, including the images created in it, ms.
    pub frame_ms: f64,
    /// The same view with every object drawn as geometry, ms.
    pub bare_ms: f64,
    /// Texture memory of the images held after the frame, bytes.
    pub resident_bytes: u64,
    /// Images created in the frame.
    pub created: u32,
    /// Images drawn in the frame.
    pub drawn: u32,
}

/// A cached image.
#[derive(Clone, Copy, Debug)]
struct Cache {
    /// The viewpoint it was made from.
    v0: DVec3,
    /// Half the side of its safety cube.
    half: f64,
    bytes: u64,
}

/// The radius of the safety sphere around `v0` of a box whose image is a
/// quad through `c` facing `v0`: the distance from `v0` at which some
/// corner's angular error reaches `eps` (Eq. 3–4 of the paper; for a corner
/// behind the quad the nearer of the two circles).
pub fn safety_radius(v0: DVec3, c: DVec3, b: &Aabb, eps: f64) -> f64 {
    let axis = c - v0;
    let depth = axis.length();
    if depth <= 0.0 {
        return 0.0;
    }
    let n = axis / depth;
    let (s, _) = eps.sin_cos();
    b.corners()
        .iter()
        .map(|&a| {
            let along = (a - v0).dot(n);
            if along <= 0.0 {
                // A corner beside or behind the viewpoint: no safe motion.
                return 0.0;
            }
            // The corner's image on the quad, seen from `v0`.
            let proj = v0 + (a - v0) * (depth / along);
            let chord = a.distance(proj);
            if chord <= 0.0 {
                return f64::INFINITY;
            }
            let h = v0.distance(a);
            let r = chord / (2.0 * s);
            // In front of the quad (its image farther than it): Eq. 4; behind
            // it: the other sign, the nearer circle.
            let sign = if along < depth { 1.0 } else { -1.0 };
            ((h * h + r * r + sign * 2.0 * h * r * s).max(0.0)).sqrt() - r
        })
        .fold(f64::INFINITY, f64::min)
        .max(0.0)
}

/// Replays the cache along `views`. `visible(eye)` gives the objects that
/// may be seen from `eye` (`None`: all).
pub fn replay<'v>(
    scene: &Scene,
    h: &Hierarchy,
    job: &Job,
    views: &[View],
    visible: &dyn Fn(DVec3) -> Option<&'v ObjectSet>,
) -> Vec<Frame> {
    let model = CostModel::new(job);
    let imodel = ImpostorModel::new(job);
    let eps = job.max_error_px * imodel.theta;
    let [w, hgt] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(hgt);
    let viewport = f64::from(w.max(hgt));
    let mut caches: Vec<Option<Cache>> = vec![None; h.nodes.len()];
    let scalar = |c: Cost| c.cpu + c.gpu;
    let mut frames = Vec::with_capacity(views.len());
    for (f, &(eye, dir)) in views.iter().enumerate() {
        let fr = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
        let vis = visible(eye);
        let bare = model.view_cost(scene, h, &fr, |o| vis.is_none_or(|v| v.contains(o)));
        let mut frame = Frame {
            bare_ms: model.frame_time(bare),
            ..Frame::default()
        };
        let mut total = Cost::default();
        // Post-order over the nodes in view: per node its drawing cost
        // (as the paper's `drawingCost`), computed after its children's.
        let mut drawing = vec![Cost::default(); h.nodes.len()];
        // (node, children done)
        let mut stack = vec![(0u32, false)];
        // Nodes whose cost is final and counted by a drawn ancestor or the
        // frame: the frame total is summed at the root.
        while let Some((n, done)) = stack.pop() {
            let node = &h.nodes[n as usize];
            let s = node.sphere;
            if !done {
                if !fr.intersects_sphere(s.center, s.radius) {
                    // Culled: its images (and its subtree's) are released.
                    for c in &mut caches[n as usize..node.subtree_end as usize] {
                        *c = None;
                    }
                    drawing[n as usize] = Cost::default();
                    continue;
                }
                if let Some(c) = caches[n as usize] {
                    if (eye - c.v0).abs().max_element() <= c.half {
                        drawing[n as usize] = model.impostor(1, s.radius, eye.distance(s.center));
                        frame.drawn += 1;
                        continue;
                    }
                    caches[n as usize] = None;
                }
                if let Some([l, r]) = node.children {
                    stack.push((n, true));
                    stack.push((r, false));
                    stack.push((l, false));
                    continue;
                }
            }
            // UpdateNode: the contents' cost (geometry for a leaf, the
            // children's drawing costs otherwise).
            let contents = match node.children {
                None => h
                    .objects(n)
                    .iter()
                    .filter(|&&o| vis.is_none_or(|v| v.contains(o)))
                    .fold(Cost::default(), |acc, &o| {
                        let os = &h.object_spheres[o as usize];
                        if fr.intersects_sphere(os.center, os.radius) {
                            let ob = &scene.objects[o as usize];
                            acc + model.object_view(ob, os.radius, eye.distance(os.center))
                        } else {
                            acc
                        }
                    }),
                Some([l, r]) => drawing[l as usize] + drawing[r as usize],
            };
            drawing[n as usize] = contents;
            let dist = eye.distance(s.center);
            let texels = 2.0 * s.radius / (dist * imodel.theta);
            if node.aabb.contains_point(eye) || dist <= s.radius || texels > viewport {
                continue;
            }
            let mut zone = safety_radius(eye, node.aabb.center(), &node.aabb, eps);
            if let Some([l, r]) = node.children {
                for ch in [l, r] {
                    let b = &h.nodes[ch as usize].aabb;
                    zone = zone.min(safety_radius(eye, node.aabb.center(), b, eps));
                }
            }
            let half = zone / 3f64.sqrt();
            let life = views[f..]
                .iter()
                .take_while(|(e, _)| (*e - eye).abs().max_element() <= half)
                .count()
                .max(1);
            let draw = model.impostor(1, s.radius, dist);
            let pixels = model.pixels(s.radius, dist);
            let create = contents + model.impostor_covering(1, pixels);
            if scalar(create) / life as f64 + scalar(draw) < scalar(contents) {
                let side = (texels * imodel.texels_per_pixel)
                    .ceil()
                    .clamp(4.0, f64::from(imodel.max_res));
                caches[n as usize] = Some(Cache {
                    v0: eye,
                    half,
                    bytes: (side * side * imodel.bytes_per_texel).ceil() as u64,
                });
                total += create;
                frame.created += 1;
                frame.drawn += 1;
                drawing[n as usize] = draw;
            }
        }
        total += drawing[0];
        frame.frame_ms = model.frame_time(total);
        frame.resident_bytes = caches.iter().flatten().map(|c| c.bytes).sum();
        frames.push(frame);
    }
    frames
}

/// What a runtime cache needs along a path.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PathSummary {
    /// Frames.
    pub frames: u64,
    /// Largest frame time, ms.
    pub max_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Frames over the target.
    pub over_target: u64,
    /// Frames over the target that create images (the cache's spikes).
    pub over_target_creating: u64,
    /// The first frame's time, ms (every image made at once).
    pub first_ms: f64,
    /// Largest resident texture memory, bytes.
    pub peak_bytes: u64,
    /// Mean resident texture memory, bytes.
    pub mean_bytes: f64,
    /// Images created over the path.
    pub created: u64,
}

impl PathSummary {
    /// The figures of `frames` against a target of `target_ms`.
    pub fn of(frames: &[Frame], target_ms: f64) -> PathSummary {
        if frames.is_empty() {
            return PathSummary::default();
        }
        let mut times: Vec<f64> = frames.iter().map(|f| f.frame_ms).collect();
        times.sort_by(f64::total_cmp);
        let n = times.len();
        // Nearest rank.
        let p99 = times[((0.99 * n as f64).ceil() as usize).clamp(1, n) - 1];
        PathSummary {
            frames: n as u64,
            max_ms: times[n - 1],
            p99_ms: p99,
            mean_ms: times.iter().sum::<f64>() / n as f64,
            over_target: frames.iter().filter(|f| f.frame_ms > target_ms).count() as u64,
            over_target_creating: frames
                .iter()
                .filter(|f| f.frame_ms > target_ms && f.created > 0)
                .count() as u64,
            first_ms: frames[0].frame_ms,
            peak_bytes: frames.iter().map(|f| f.resident_bytes).max().unwrap_or(0),
            mean_bytes: frames.iter().map(|f| f.resident_bytes as f64).sum::<f64>() / n as f64,
            created: frames.iter().map(|f| u64::from(f.created)).sum(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;
    use crate::testutil::{synthetic_city, synthetic_job};

    /// Angle at `v` between a point and its image on the quad.
    fn angle(v: DVec3, a: DVec3, image: DVec3) -> f64 {
        (a - v).angle_between(image - v)
    }

    /// Within the safety sphere no corner's error exceeds `ε` (sampled
    /// eyes; boxes around the quad, and wholly in front of or behind it as
    /// a child's box may be); just outside it, in the worst direction
    /// found, some corner's does.
    #[test]
    fn the_safety_sphere_bounds_every_corner_error() {
        let mut rng = Rng::new(5);
        for _ in 0..50 {
            let c = DVec3::new(
                rng.range(-5.0, 5.0),
                rng.range(-5.0, 5.0),
                rng.range(20.0, 60.0),
            );
            let half = DVec3::new(
                rng.range(0.5, 4.0),
                rng.range(0.5, 4.0),
                rng.range(0.5, 4.0),
            );
            // The box around the quad's centre, or (as a child's box) wholly
            // in front of or behind the quad.
            let shift = c.normalize() * rng.range(-1.0, 1.0) * (half.length() + 2.0);
            let b = Aabb::new(c + shift - half, c + shift + half);
            let eps = rng.range(0.0005, 0.01);
            let v0 = DVec3::ZERO;
            let d = safety_radius(v0, c, &b, eps);
            assert!(d > 0.0 && d.is_finite());
            let n = c.normalize();
            let images: Vec<(DVec3, DVec3)> = b
                .corners()
                .iter()
                .map(|&a| (a, a * (c.length() / a.dot(n))))
                .collect();
            let worst = |v: DVec3| {
                images
                    .iter()
                    .map(|&(a, i)| angle(v, a, i))
                    .fold(0.0f64, f64::max)
            };
            let mut outside = 0.0f64;
            for _ in 0..400 {
                let u = rng.unit_vector();
                assert!(worst(u * d * rng.f64().cbrt()) <= eps * (1.0 + 1e-6));
                outside = outside.max(worst(u * d * 1.05));
            }
            assert!(
                outside > eps,
                "the sphere is far from tight: {outside} vs {eps}"
            );
        }
    }

    /// A camera that does not move makes its images once: later frames
    /// create none, cost no more than drawing everything, and hold the same
    /// memory. With an error budget too small for any image to live past its
    /// frame, nothing is cached and every frame is the bare frame.
    #[test]
    fn a_still_camera_caches_once_and_a_zero_budget_never() {
        let scene = synthetic_city(3, 5, 5);
        let h = Hierarchy::build(&scene);
        let mut job = synthetic_job(5, 5);
        let (lo, hi) = (job.vs_min(), job.vs_max());
        let eye = (lo + hi) * 0.5;
        let views = vec![(eye, DVec3::new(1.0, 0.0, 0.3).normalize()); 20];
        let frames = replay(&scene, &h, &job, &views, &|_| None);
        assert!(frames[0].created > 0, "{:?}", frames[0]);
        assert!(frames[0].frame_ms > frames[1].frame_ms);
        for f in &frames[1..] {
            assert_eq!(f.created, 0);
            assert!(f.frame_ms < f.bare_ms, "{f:?}");
            assert_eq!(f.resident_bytes, frames[0].resident_bytes);
            assert_eq!(f.frame_ms, frames[1].frame_ms);
        }
        let s = PathSummary::of(&frames, 1e9);
        assert_eq!(s.created, u64::from(frames[0].created));
        assert_eq!(s.first_ms, frames[0].frame_ms);
        assert_eq!(s.max_ms, frames[0].frame_ms);
        job.max_error_px = 1e-9;
        // A moving camera leaves every zone at once.
        let moving: Vec<View> = (0..20)
            .map(|i| (lo.lerp(hi, f64::from(i) / 19.0), DVec3::X))
            .collect();
        for f in replay(&scene, &h, &job, &moving, &|_| None) {
            assert_eq!((f.created, f.drawn, f.resident_bytes), (0, 0, 0));
            // The same objects, summed in another order.
            assert!((f.frame_ms - f.bare_ms).abs() <= 1e-9 * f.bare_ms, "{f:?}");
        }
    }
}
