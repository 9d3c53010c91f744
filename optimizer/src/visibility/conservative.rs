//! Conservative from-region visibility with shrunk occluders and point
//! sampling (after Wonka, Wimmer and Schmalstieg 2000).
//!
//! # Why it never culls a visible object
//!
//! Let `R` be a view region (a grid cell) and `O` an occluder box inside a
//! closed, opaque solid that does not meet `R` ([`super::occluders`]). `R`
//! is sampled with `n_a` points per axis at the centres of a regular
//! subdivision, so every point `p ∈ R` has a sample `s` with
//! `|p_a − s_a| ≤ ε_a = extent_a / (2·n_a)` on each axis. Every occluder is
//! shrunk by `ε_a` on each axis (plus a small margin), giving `O_ε`.
//!
//! *Claim*: if the segment `s → x` meets `O_ε` at a point `q`, then the
//! segment `p → x` meets the interior of `O`. Parametrise both from `x`:
//! `q = x + t·(s − x)` for some `t ∈ [0, 1]`; the point `q' = x + t·(p − x)`
//! lies on `p → x` and `|q'_a − q_a| = t·|p_a − s_a| ≤ ε_a`, so `q'` lies in
//! `O` (strictly inside, thanks to the margin). `p` lies outside the solid,
//! so `p → q'` crosses its surface through a front face (or a double-sided
//! one): the renderer draws something there and `x` is hidden from `p`.
//! This holds for each point `x` separately, so the segments to different
//! points of an object may be stopped by different occluders: occluder
//! fusion comes for free.
//!
//! So an object is culled from `R` when, for every sample, every segment
//! from the sample to every point of the object's bounding box meets some
//! shrunk occluder. The test per sample is itself conservative:
//!
//! * Around the sample, azimuth is cut into [`BINS`] bins (uniform in a
//!   cheap monotone "diamond" angle rather than in radians; the argument
//!   only needs bins to be ranges of directions). A shrunk occluder
//!   seen from the side (the sample outside its footprint) is entered by the
//!   ray of every azimuth inside its angular interval at a horizontal
//!   distance `r_in(φ)` between `r_near` (closest point of the footprint) and
//!   `r_front` (farthest corner of the footprint's front edges). A ray of
//!   slope `σ` (rise over horizontal run) is inside the box at `r_in(φ)` when
//!   `b ≤ y_s + σ·r_in ≤ h`, so it is blocked for every `σ ∈ [L, U]` with
//!   `L = (b − y_s) / (b ≤ y_s ? r_front : r_near)` and
//!   `U = (h − y_s) / (h ≥ y_s ? r_front : r_near)`, for every target point
//!   farther than `r_front`. The occluder adds `[L, U]` (keyed by `r_front`)
//!   to bins that lie entirely inside its angular interval. The two bins
//!   its interval ends in are covered only in part; each part is kept and
//!   fused with a part of another occluder that covers the rest of the
//!   bin from its other end: every ray of the bin then meets one of the
//!   two, so the bin gets `[max L, min U]` keyed by the larger `r_front`
//!   (the far skyline's occluders each cover a bin or two; without the
//!   fusion the bins at their edges would let rays pass).
//! * A shrunk occluder straight above the sample (footprint around it,
//!   bottom `b > y_s`) blocks every ray with `σ ≥ (b − y_s)/r_exit` towards
//!   targets whose bottom is at least `b` (`r_exit`: distance to the
//!   footprint's border); one straight below works alike.
//! * A target box is hidden from the sample when, in every bin its azimuth
//!   range touches, the union of the intervals of occluders closer than the
//!   box's nearest horizontal distance (plus the ceilings and floors that
//!   apply) covers the box's whole slope range.
//!
//! Targets that meet the region are always visible. Objects are tested
//! through the object hierarchy: a hidden cluster hides all its objects.

use glam::DVec3;

mod horizon;

pub use horizon::BINS;
use horizon::Horizon;
#[cfg(test)]
use horizon::{BIN, angular_interval, azimuth, direction};

use super::ObjectSet;
use super::occluders::OccluderBox;
use crate::math::geom::Aabb;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;

/// Extra shrinking beyond the sample spacing, metres: puts the points `q'`
/// of the argument strictly inside the occluders.
const MARGIN: f64 = 1e-3;

/// A shrunk occluder.
#[derive(Clone, Copy, Debug)]
struct Shrunk {
    b: Aabb,
    support: Aabb,
    open_below: f64,
}

/// The conservative visibility of one job: shrunk occluders and the sample
/// pattern of a grid cell.
pub struct Conservative {
    occluders: Vec<Shrunk>,
    /// A 2D bounding volume hierarchy over the occluders' footprints,
    /// traversed front to back so that whole groups hidden behind nearer
    /// occluders are skipped.
    tree: Vec<TreeNode>,
    /// Occluder indices in tree order; leaves hold ranges of it.
    order: Vec<u32>,
    /// Samples per axis in a cell.
    pub samples: [u32; 3],
    /// Shrinking per axis, metres.
    pub epsilon: DVec3,
}

impl Conservative {
    /// Prepares the occluders for cells of size `cell` (all grid cells have
    /// one size) sampled at most `spacing` apart.
    pub fn new(occluders: &[OccluderBox], cell: DVec3, spacing: f64) -> Conservative {
        let samples = [0, 1, 2].map(|a| ((cell[a] / spacing).ceil().max(1.0)) as u32);
        let epsilon = DVec3::new(
            cell.x / (2.0 * f64::from(samples[0])),
            cell.y / (2.0 * f64::from(samples[1])),
            cell.z / (2.0 * f64::from(samples[2])),
        );
        let shrink = epsilon + DVec3::splat(MARGIN);
        let occluders = occluders
            .iter()
            .filter_map(|o| {
                let b = Aabb::new(o.aabb.min + shrink, o.aabb.max - shrink);
                (b.min.cmplt(b.max).all()).then_some(Shrunk {
                    b,
                    support: o.support,
                    open_below: o.open_below,
                })
            })
            .collect::<Vec<Shrunk>>();
        let (tree, order) = build_tree(&occluders);
        Conservative {
            occluders,
            tree,
            order,
            samples,
            epsilon,
        }
    }

    /// Occluders that survive shrinking.
    pub fn occluder_count(&self) -> usize {
        self.occluders.len()
    }

    /// The objects that may be visible from `cell`.
    pub fn cell_pvs(&self, cell: &Aabb, scene: &Scene, h: &Hierarchy) -> ObjectSet {
        let closed_meets =
            |a: &Aabb, b: &Aabb| a.min.cmple(b.max).all() && b.min.cmple(a.max).all();
        // Occluders whose solids meet the cell may contain viewpoints; those
        // with an open bottom need the cell strictly above it.
        // (Tested where a leaf of the footprint tree is visited, not for
        // every occluder of the scene per cell.)
        let usable = |o: u32| {
            let o = &self.occluders[o as usize];
            !closed_meets(&o.support, cell) && cell.min.y > o.open_below
        };
        let mut visible = ObjectSet::new(scene.objects.len());
        // Per cluster, its objects known to be visible: a cluster with all
        // of them needs no test from later samples. Kept per thread and
        // cleared where it was set, not allocated per cell over the whole
        // hierarchy.
        let mut seen = SEEN.with_borrow_mut(std::mem::take);
        seen.resize(h.nodes.len(), 0);
        let root = h.nodes[0].aabb;
        let mut horizon = Horizon::new([root.min.y, root.max.y]);
        let n = self.samples;
        let ext = cell.max - cell.min;
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let s = cell.min
                        + ext
                            * DVec3::new(
                                (f64::from(i) + 0.5) / f64::from(n[0]),
                                (f64::from(j) + 0.5) / f64::from(n[1]),
                                (f64::from(k) + 0.5) / f64::from(n[2]),
                            );
                    horizon.build(s, self, usable);
                    mark_visible(&horizon, cell, scene, h, &mut visible, &mut seen);
                }
            }
        }
        // Only the clusters above visible objects were counted.
        for o in visible.iter() {
            let mut k = h.leaf_of[o as usize];
            while k != u32::MAX && seen[k as usize] != 0 {
                seen[k as usize] = 0;
                k = h.nodes[k as usize].parent;
            }
        }
        SEEN.with_borrow_mut(|s| *s = seen);
        visible
    }
}

thread_local! {
    /// [`Conservative::cell_pvs`]'s per-cluster counts of visible objects,
    /// all zero between calls.
    static SEEN: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A node of the occluder footprint hierarchy.
#[derive(Clone, Copy, Debug)]
struct TreeNode {
    /// Footprint bounds `[x0, x1, z0, z1]`.
    rect: [f64; 4],
    /// Lowest bottom and highest top of its occluders.
    y: [f64; 2],
    /// Children, or `u32::MAX` for a leaf.
    left: u32,
    right: u32,
    /// Leaf: range of `order`.
    first: u32,
    count: u32,
}

const LEAF_SIZE: usize = 16;

/// Builds the footprint hierarchy by median splits (deterministic).
fn build_tree(occ: &[Shrunk]) -> (Vec<TreeNode>, Vec<u32>) {
    let mut order: Vec<u32> = (0..occ.len() as u32).collect();
    let mut nodes = Vec::new();
    if occ.is_empty() {
        return (nodes, order);
    }
    fn rect_of(occ: &[Shrunk], ids: &[u32]) -> [f64; 4] {
        let mut r = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for &i in ids {
            let b = &occ[i as usize].b;
            r[0] = r[0].min(b.min.x);
            r[1] = r[1].max(b.max.x);
            r[2] = r[2].min(b.min.z);
            r[3] = r[3].max(b.max.z);
        }
        r
    }
    fn rec(occ: &[Shrunk], order: &mut [u32], offset: usize, nodes: &mut Vec<TreeNode>) -> u32 {
        let id = nodes.len() as u32;
        let rect = rect_of(occ, order);
        let y = order
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |y, &i| {
                let b = &occ[i as usize].b;
                [y[0].min(b.min.y), y[1].max(b.max.y)]
            });
        nodes.push(TreeNode {
            rect,
            y,
            left: u32::MAX,
            right: u32::MAX,
            first: offset as u32,
            count: order.len() as u32,
        });
        if order.len() > LEAF_SIZE {
            let axis_x = rect[1] - rect[0] >= rect[3] - rect[2];
            let key = |i: &u32| {
                let b = &occ[*i as usize].b;
                if axis_x {
                    b.min.x + b.max.x
                } else {
                    b.min.z + b.max.z
                }
            };
            order.sort_by(|a, b| key(a).total_cmp(&key(b)).then(a.cmp(b)));
            let mid = order.len() / 2;
            let (l, r) = order.split_at_mut(mid);
            let left = rec(occ, l, offset, nodes);
            let right = rec(occ, r, offset + mid, nodes);
            let n = &mut nodes[id as usize];
            n.left = left;
            n.right = right;
        }
        id
    }
    rec(occ, &mut order, 0, &mut nodes);
    (nodes, order)
}

/// Marks the objects not hidden from the horizon's sample.
/// `seen` counts, per cluster, its objects in `visible`.
fn mark_visible(
    hz: &Horizon,
    cell: &Aabb,
    scene: &Scene,
    h: &Hierarchy,
    visible: &mut ObjectSet,
    seen: &mut [u32],
) {
    let meets = |b: &Aabb| b.min.cmple(cell.max).all() && cell.min.cmple(b.max).all();
    h.walk(|n, node| {
        if seen[n as usize] == node.objects.1 - node.objects.0
            || (!meets(&node.aabb) && hz.hides(&node.aabb))
        {
            return false;
        }
        if node.children.is_none() {
            for &o in h.objects(n) {
                if visible.contains(o) {
                    continue;
                }
                let ob = &scene.objects[o as usize];
                let b = Aabb::new(ob.min, ob.max);
                if meets(&b) || !hz.hides(&b) {
                    visible.insert(o);
                    let mut k = n;
                    while k != u32::MAX {
                        seen[k as usize] += 1;
                        k = h.nodes[k as usize].parent;
                    }
                }
            }
        }
        true
    });
}

/// True when the segment `a → b` meets box `o` grown by `pad` on every side
/// (shrunk when negative): the brute force the tests check horizons with.
#[cfg(test)]
fn segment_meets(o: &Aabb, a: DVec3, b: DVec3, pad: f64) -> bool {
    let d = b - a;
    let (mut t0, mut t1): (f64, f64) = (0.0, 1.0);
    for k in 0..3 {
        let (lo, hi) = (o.min[k] - pad, o.max[k] + pad);
        if d[k].abs() < 1e-15 {
            if a[k] < lo || a[k] > hi {
                return false;
            }
        } else {
            let (mut u, mut v) = ((lo - a[k]) / d[k], (hi - a[k]) / d[k]);
            if u > v {
                std::mem::swap(&mut u, &mut v);
            }
            t0 = t0.max(u);
            t1 = t1.min(v);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn occ(lo: [f64; 3], hi: [f64; 3]) -> OccluderBox {
        let b = Aabb::new(DVec3::from_array(lo), DVec3::from_array(hi));
        OccluderBox {
            aabb: b,
            support: b,
            open_below: f64::NEG_INFINITY,
        }
    }

    #[test]
    fn angular_interval_straddles_the_seam() {
        // A box straight ahead along +x spans the wrap-around at 0.
        let (a0, a1) = angular_interval(DVec3::ZERO, 10.0, 12.0, -1.0, 1.0);
        assert!(a0 < 0.0 && a1 > 0.0 && a1 - a0 < 0.5, "{a0} {a1}");
        assert!((a0 + a1).abs() < 1e-12);
        // Diamond angles are monotone in the true angle and invert.
        let mut last = -1.0;
        for i in 0..720 {
            let t = f64::from(i) * std::f64::consts::TAU / 720.0;
            let p = azimuth(t.cos(), t.sin());
            assert!(p > last, "{i}");
            last = p;
            let (x, z) = direction(p);
            assert!((x - t.cos()).abs() < 1e-9 && (z - t.sin()).abs() < 1e-9);
        }
    }

    #[test]
    fn a_wall_hides_what_is_behind_it_and_not_what_is_beside_it() {
        // A wall 20 m tall, 40 m wide, 10 m in front of the sample.
        let wall = occ([10.0, 0.0, -20.0], [12.0, 20.0, 20.0]);
        let c = Conservative::new(&[wall], DVec3::splat(1e-6), 1.0);
        let mut hz = Horizon::new([-1.0, 1000.0]);
        hz.build(DVec3::new(0.0, 1.7, 0.0), &c, |_| true);
        // Behind the wall, low: hidden.
        assert!(hz.hides(&Aabb::new(
            DVec3::new(20.0, 0.0, -1.0),
            DVec3::new(22.0, 3.0, 1.0)
        )));
        // Behind the wall but tall enough to stick out over it: visible.
        assert!(!hz.hides(&Aabb::new(
            DVec3::new(20.0, 0.0, -1.0),
            DVec3::new(22.0, 60.0, 1.0)
        )));
        // Beside the wall (outside its ±63° angular interval): visible.
        assert!(!hz.hides(&Aabb::new(
            DVec3::new(20.0, 0.0, 60.0),
            DVec3::new(22.0, 3.0, 62.0)
        )));
        // At 50° the wall is still in front: hidden.
        assert!(hz.hides(&Aabb::new(
            DVec3::new(20.0, 0.0, 25.0),
            DVec3::new(22.0, 3.0, 27.0)
        )));
        // In front of the wall: visible.
        assert!(!hz.hides(&Aabb::new(
            DVec3::new(5.0, 0.0, -1.0),
            DVec3::new(6.0, 3.0, 1.0)
        )));
        // Hand-computed edge: straight ahead the rays of the bins next to
        // azimuth 0 enter the (shrunk) wall at most 10.001 / cos(bin) away,
        // where its top is 20 − 0.001.
        let (x, _) = direction(BIN);
        let r_in = (10.0 + MARGIN) / x;
        let u = (20.0 - MARGIN - 1.7) / r_in;
        // A target at distance 100 whose top rises just below / above slope u.
        let below = 1.7 + u * 100.0 - 0.5;
        let above = 1.7 + u * 100.0 + 0.5;
        assert!(hz.hides(&Aabb::new(
            DVec3::new(100.0, 0.0, -0.1),
            DVec3::new(100.2, below, 0.1)
        )));
        assert!(!hz.hides(&Aabb::new(
            DVec3::new(100.0, 0.0, -0.1),
            DVec3::new(100.2, above, 0.1)
        )));
    }

    #[test]
    fn touching_walls_fuse_through_their_bridge() {
        // Two walls side by side with no gap: once shrunk they part, and
        // seen straight along the seam a target behind it is hidden only
        // with the bridge over both.
        let a = occ([10.0, 0.0, -20.0], [12.0, 20.0, 0.0]);
        let b = occ([10.0, 0.0, 0.0], [12.0, 20.0, 20.0]);
        let target = Aabb::new(DVec3::new(30.0, 0.0, -2.0), DVec3::new(31.0, 3.0, 2.0));
        let s = DVec3::new(0.0, 1.7, 0.0);
        let hides = |boxes: &[OccluderBox]| {
            let c = Conservative::new(boxes, DVec3::splat(1e-6), 1.0);
            let mut hz = Horizon::new([-1.0, 1000.0]);
            hz.build(s, &c, |_| true);
            hz.hides(&target)
        };
        let bridged = super::super::occluders::bridges(&[a, b]);
        assert_eq!(bridged.len(), 1);
        assert!(hides(&[a, b, bridged[0]]));
        assert!(!hides(&[a, b]));
        assert!(!hides(&[a]));
    }

    #[test]
    fn occluders_covering_a_bin_from_its_two_ends_hide_what_is_behind_it() {
        // Two walls at different distances, not touching: the near one's
        // interval ends 0.6 of the way into bin 7, the far one's starts
        // 0.4 of the way in, so neither covers the bin. A narrow target far
        // behind, in the middle of the bin, is hidden by the two together.
        let p = |f: f64| f * BIN;
        // Diamond angle z / (x + z) in the first quadrant.
        let z_at = |x: f64, a: f64| x * a / (1.0 - a);
        let near = occ([10.0, 0.0, -20.0], [11.0, 20.0, z_at(10.0, p(7.6))]);
        let far = occ([20.0, 0.0, z_at(21.0, p(7.4))], [21.0, 20.0, 40.0]);
        let (dx, dz) = direction(p(7.5));
        let (cx, cz) = (100.0 * dx, 100.0 * dz);
        let target = Aabb::new(
            DVec3::new(cx - 0.05, 0.0, cz - 0.05),
            DVec3::new(cx + 0.05, 3.0, cz + 0.05),
        );
        let (a0, a1) = angular_interval(
            DVec3::new(0.0, 1.7, 0.0),
            cx - 0.05,
            cx + 0.05,
            cz - 0.05,
            cz + 0.05,
        );
        assert!(a0 > p(7.0) && a1 < p(8.0), "the target lies in bin 7");
        let hides = |boxes: &[OccluderBox]| {
            let c = Conservative::new(boxes, DVec3::splat(1e-6), 1.0);
            let mut hz = Horizon::new([-1.0, 1000.0]);
            hz.build(DVec3::new(0.0, 1.7, 0.0), &c, |_| true);
            hz.hides(&target)
        };
        assert!(super::super::occluders::bridges(&[near, far]).is_empty());
        assert!(hides(&[near, far]));
        assert!(!hides(&[near]));
        assert!(!hides(&[far]));
        // Parts from the same end do not fuse: a second wall ending where
        // the near one does leaves the bin open.
        let beside = occ([30.0, 0.0, -20.0], [31.0, 20.0, z_at(30.0, p(7.6))]);
        assert!(!hides(&[near, beside]));
    }

    #[test]
    fn ceilings_hide_what_is_above_them() {
        let slab = occ([-20.0, 3.0, -20.0], [20.0, 3.5, 20.0]);
        let c = Conservative::new(&[slab], DVec3::splat(1e-6), 1.0);
        let mut hz = Horizon::new([-1.0, 1000.0]);
        hz.build(DVec3::new(0.0, 1.5, 0.0), &c, |_| true);
        assert!(hz.hides(&Aabb::new(
            DVec3::new(-1.0, 5.0, -1.0),
            DVec3::new(1.0, 6.0, 1.0)
        )));
        // Far off to the side it is seen under the slab's edge.
        assert!(!hz.hides(&Aabb::new(
            DVec3::new(100.0, 5.0, -1.0),
            DVec3::new(101.0, 6.0, 1.0)
        )));
    }
}

#[cfg(test)]
mod property {
    //! The claim of the module docs, checked against brute force: every
    //! object that some unobstructed segment from the region reaches is in
    //! the region's set.
    use super::*;
    use crate::math::rng::Rng;
    use crate::scene::{Object, Scene};
    use crate::visibility::occluders;

    /// True when the segment `a → b` passes through the interior of box
    /// `o` (shrunk by a hair so that grazing does not count).
    fn blocks(o: &Aabb, a: DVec3, b: DVec3) -> bool {
        segment_meets(o, a, b, -1e-7)
    }

    fn random_scene(rng: &mut Rng) -> Scene {
        let mut objects = Vec::new();
        let push = |lo: DVec3, hi: DVec3, objects: &mut Vec<Object>| {
            objects.push(Object {
                name: String::new(),
                min: lo,
                max: hi,
                triangles: 12,
                draw_calls: 1,
                lods: Vec::new(),
            })
        };
        // Rows of touching buildings along x and z.
        for row in 0..4 {
            let z = rng.range(-80.0, 80.0);
            let mut x = rng.range(-100.0, -60.0);
            let depth = rng.range(8.0, 16.0);
            for _ in 0..(3 + rng.next_u64() % 4) {
                let w = rng.range(6.0, 20.0);
                let h = rng.range(4.0, 30.0);
                let (lo, hi) = if row % 2 == 0 {
                    (DVec3::new(x, 0.0, z), DVec3::new(x + w, h, z + depth))
                } else {
                    (DVec3::new(z, 0.0, x), DVec3::new(z + depth, h, x + w))
                };
                push(lo, hi, &mut objects);
                x += w;
            }
        }
        // Small things on the ground and some floating slabs.
        for _ in 0..40 {
            let p = rng.in_box(
                DVec3::new(-120.0, 0.0, -120.0),
                DVec3::new(120.0, 0.0, 120.0),
            );
            let s = DVec3::new(
                rng.range(0.3, 3.0),
                rng.range(0.3, 6.0),
                rng.range(0.3, 3.0),
            );
            let lift = if rng.f64() < 0.2 {
                rng.range(3.0, 10.0)
            } else {
                0.0
            };
            push(p + DVec3::Y * lift, p + s + DVec3::Y * lift, &mut objects);
        }
        Scene { objects }
    }

    #[test]
    fn no_visible_object_is_culled() {
        let mut rng = Rng::new(77);
        let mut culled_total = 0usize;
        for case in 0..40 {
            let scene = random_scene(&mut rng);
            let h = Hierarchy::build(&scene);
            let geom = crate::testutil::box_geometry(&scene);
            let occ = occluders::extract(&geom, &scene);
            assert!(occ.stats.boxes > 10, "{:?}", occ.stats);
            let lo = rng.in_box(DVec3::new(-60.0, 1.0, -60.0), DVec3::new(40.0, 1.0, 40.0));
            let cell = Aabb::new(lo, lo + DVec3::new(20.0, 1.0, 20.0));
            let cons = Conservative::new(&occ.boxes, cell.max - cell.min, 4.0);
            let pvs = cons.cell_pvs(&cell, &scene, &h);
            let solids: Vec<Aabb> = scene
                .objects
                .iter()
                .map(|o| Aabb::new(o.min, o.max))
                .collect();
            culled_total += scene.objects.len() - pvs.count();
            for _ in 0..300 {
                let p = rng.in_box(cell.min, cell.max);
                if solids
                    .iter()
                    .any(|s| s.min.cmplt(p).all() && p.cmplt(s.max).all())
                {
                    continue; // inside a solid: faces culled, nothing to check
                }
                for (o, target) in solids.iter().enumerate() {
                    if pvs.contains(o as u32) {
                        continue;
                    }
                    for _ in 0..12 {
                        // A point on the target's surface.
                        let mut x = rng.in_box(target.min, target.max);
                        let k = (rng.next_u64() % 3) as usize;
                        x[k] = if rng.f64() < 0.5 {
                            target.min[k]
                        } else {
                            target.max[k]
                        };
                        let seen = !solids
                            .iter()
                            .enumerate()
                            .any(|(j, s)| j != o && blocks(s, p, x));
                        assert!(
                            !seen,
                            "case {case}: object {o} {target:?} is visible from {p} at {x} but culled"
                        );
                    }
                }
            }
        }
        assert!(culled_total > 0, "the scenes must cull something to test");
    }
}
