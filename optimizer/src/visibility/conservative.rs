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
//!   only to bins that lie entirely inside its angular interval.
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

use super::ObjectSet;
use super::occluders::OccluderBox;
use crate::math::geom::Aabb;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;

/// Azimuth bins around a sample point.
pub const BINS: usize = 512;

/// The diamond angle runs over `[0, PERIOD)`.
const PERIOD: f64 = 4.0;

const BIN: f64 = PERIOD / BINS as f64;

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
        let usable: Vec<bool> = self
            .occluders
            .iter()
            .map(|o| !closed_meets(&o.support, cell) && cell.min.y > o.open_below)
            .collect();
        let mut visible = ObjectSet::new(scene.objects.len());
        // Per cluster, its objects not yet known to be visible: a cluster
        // with none left needs no test from later samples.
        let mut hidden: Vec<u32> = h.nodes.iter().map(|n| n.objects.1 - n.objects.0).collect();
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
                    horizon.build(s, self, &usable);
                    mark_visible(&horizon, cell, scene, h, &mut visible, &mut hidden);
                }
            }
        }
        visible
    }
}

/// A distance ordered with `total_cmp` (for the traversal heap).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Dist(f64);

impl Eq for Dist {}

impl PartialOrd for Dist {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Dist {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
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

/// An occluder's slope interval in one bin.
#[derive(Clone, Copy, Debug)]
struct Entry {
    r_key: f64,
    lo: f64,
    hi: f64,
}

/// What occludes around one sample point.
struct Horizon {
    /// Reciprocal components `(1/x, 1/z)` of the unit direction of every
    /// bin boundary `k·BIN`, `k = 0..=BINS` (infinite for a zero component).
    dirs: Vec<(f64, f64)>,
    s: DVec3,
    /// Lowest and highest point of the scene.
    y_range: [f64; 2],
    bins: Vec<Vec<Entry>>,
    /// Per bin, a distance beyond which every point of the scene's height
    /// range is hidden by a single entry of the bin (`inf`: none).
    closed: Vec<f64>,
    touched: Vec<u32>,
    /// Scratch: a footprint leaf's occluders by distance.
    leaf: Vec<(f64, u32)>,
    /// `(σ_c, b)`: blocks `σ ≥ σ_c` for targets with bottom ≥ `b`.
    ceilings: Vec<(f64, f64)>,
    /// `(σ_f, h)`: blocks `σ ≤ σ_f` for targets with top ≤ `h`.
    floors: Vec<(f64, f64)>,
}

/// Diamond angle of `(dx, dz)` in `[0, 4)`: a monotone stand-in for the
/// azimuth (`atan2`) that needs one division.
fn azimuth(dx: f64, dz: f64) -> f64 {
    if dx == 0.0 && dz == 0.0 {
        return 0.0;
    }
    if dz >= 0.0 {
        if dx >= 0.0 {
            dz / (dx + dz)
        } else {
            1.0 - dx / (-dx + dz)
        }
    } else if dx < 0.0 {
        2.0 - dz / (-dx - dz)
    } else {
        3.0 + dx / (dx - dz)
    }
}

/// The unit direction `(x, z)` of diamond angle `p`.
fn direction(p: f64) -> (f64, f64) {
    let p = p.rem_euclid(PERIOD);
    let q = p.floor();
    let f = p - q;
    let (x, z) = match q as u32 {
        0 => (1.0 - f, f),
        1 => (-f, 1.0 - f),
        2 => (f - 1.0, -f),
        _ => (f, f - 1.0),
    };
    let l = x.hypot(z);
    (x / l, z / l)
}

/// Angular interval `[lo, hi]` (diamond angle, `hi − lo < 2`, `lo` may be
/// below 0) of a footprint rectangle seen from outside it.
fn angular_interval(s: DVec3, x0: f64, x1: f64, z0: f64, z1: f64) -> (f64, f64) {
    // Seen from outside, two corners bound the rectangle's directions:
    // the first clockwise-most, the second counter-clockwise-most.
    let ((ax, az), (bx, bz)) = if s.x < x0 {
        if s.z < z0 {
            ((x1, z0), (x0, z1))
        } else if s.z > z1 {
            ((x0, z0), (x1, z1))
        } else {
            ((x0, z0), (x0, z1))
        }
    } else if s.x > x1 {
        if s.z < z0 {
            ((x1, z1), (x0, z0))
        } else if s.z > z1 {
            ((x0, z1), (x1, z0))
        } else {
            ((x1, z1), (x1, z0))
        }
    } else if s.z < z0 {
        ((x1, z0), (x0, z0))
    } else if s.z > z1 {
        ((x0, z1), (x1, z1))
    } else {
        // Inside (callers treat this case apart): every direction.
        return (0.0, PERIOD);
    };
    let lo = azimuth(ax - s.x, az - s.z);
    let hi = azimuth(bx - s.x, bz - s.z);
    if hi < lo { (lo - PERIOD, hi) } else { (lo, hi) }
}

/// Horizontal distance from `s` to a footprint rectangle (0 inside) and to
/// its farthest corner.
fn rect_distances(s: DVec3, x0: f64, x1: f64, z0: f64, z1: f64) -> (f64, f64) {
    (
        rect_near2(s, x0, x1, z0, z1).sqrt(),
        rect_far(s, x0, x1, z0, z1),
    )
}

/// Squared horizontal distance from `s` to a footprint rectangle.
#[inline]
fn rect_near2(s: DVec3, x0: f64, x1: f64, z0: f64, z1: f64) -> f64 {
    let dx = (x0 - s.x).max(s.x - x1).max(0.0);
    let dz = (z0 - s.z).max(s.z - z1).max(0.0);
    dx * dx + dz * dz
}

/// Horizontal distance from `s` to a footprint rectangle's farthest corner.
#[inline]
fn rect_far(s: DVec3, x0: f64, x1: f64, z0: f64, z1: f64) -> f64 {
    let fx = (s.x - x0).abs().max((s.x - x1).abs());
    let fz = (s.z - z0).abs().max((s.z - z1).abs());
    (fx * fx + fz * fz).sqrt()
}

/// `x.floor() as i64` without a libm call (saturating like the cast).
#[inline]
fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `x.ceil() as i64` without a libm call (saturating like the cast).
#[inline]
fn ceil_i64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) < x {
        i.saturating_add(1)
    } else {
        i
    }
}

fn bin_of(k: i64) -> usize {
    k.rem_euclid(BINS as i64) as usize
}

impl Horizon {
    fn new(y_range: [f64; 2]) -> Horizon {
        Horizon {
            dirs: (0..=BINS)
                .map(|k| {
                    let (x, z) = direction(k as f64 * BIN);
                    (1.0 / x, 1.0 / z)
                })
                .collect(),
            s: DVec3::ZERO,
            y_range,
            bins: vec![Vec::new(); BINS],
            closed: vec![f64::INFINITY; BINS],
            touched: Vec::new(),
            leaf: Vec::new(),
            ceilings: Vec::new(),
            floors: Vec::new(),
        }
    }

    /// The horizon of sample `s` from the usable occluders of `c`, visited
    /// front to back through the footprint hierarchy; a group whose every
    /// bin is already closed nearer than the group is skipped whole.
    fn build(&mut self, s: DVec3, c: &Conservative, usable: &[bool]) {
        for &t in &self.touched {
            self.bins[t as usize].clear();
            self.closed[t as usize] = f64::INFINITY;
        }
        self.touched.clear();
        self.ceilings.clear();
        self.floors.clear();
        self.s = s;
        if c.tree.is_empty() {
            return;
        }
        // Ordered by squared distance (the same order, one root per pop).
        let near = |r: &[f64; 4]| rect_near2(s, r[0], r[1], r[2], r[3]);
        // Min-heap on distance (ties by node id: deterministic).
        let mut heap = std::collections::BinaryHeap::new();
        heap.push(std::cmp::Reverse((Dist(near(&c.tree[0].rect)), 0u32)));
        while let Some(std::cmp::Reverse((Dist(near2), id))) = heap.pop() {
            let r_near = near2.sqrt();
            let node = &c.tree[id as usize];
            let [x0, x1, z0, z1] = node.rect;
            let outside = s.x < x0 || s.x > x1 || s.z < z0 || s.z > z1;
            if outside && r_near > 0.0 && self.dominated(node.rect, node.y, r_near) {
                continue;
            }
            if node.left == u32::MAX {
                // Nearest first: nearer occluders make farther ones useless.
                let mut leaf = std::mem::take(&mut self.leaf);
                leaf.clear();
                leaf.extend(
                    c.order[node.first as usize..(node.first + node.count) as usize]
                        .iter()
                        .filter(|&&o| usable[o as usize])
                        .map(|&o| {
                            let b = &c.occluders[o as usize].b;
                            (rect_near2(s, b.min.x, b.max.x, b.min.z, b.max.z), o)
                        }),
                );
                leaf.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                for &(_, o) in &leaf {
                    self.add(&c.occluders[o as usize]);
                }
                self.leaf = leaf;
            } else {
                for ch in [node.left, node.right] {
                    heap.push(std::cmp::Reverse((
                        Dist(near(&c.tree[ch as usize].rect)),
                        ch,
                    )));
                }
            }
        }
        for &t in &self.touched {
            self.bins[t as usize].sort_by(|a, b| a.lo.total_cmp(&b.lo));
        }
    }

    /// True when nothing inside footprint `rect` with heights `y`, at least
    /// `r_near` away and seen from outside, could add a useful entry: in
    /// every bin its angular interval touches, the bin is closed nearer
    /// than `r_near` or an entry keyed nearer covers the loosest interval
    /// any occluder there could get. (Skipping dominated entries changes
    /// nothing: insertion discards them anyway.)
    fn dominated(&self, rect: [f64; 4], y: [f64; 2], r_near: f64) -> bool {
        let s = self.s;
        let [x0, x1, z0, z1] = rect;
        let r_far = rect_far(s, x0, x1, z0, z1);
        let lo = (y[0] - s.y) / if y[0] <= s.y { r_near } else { r_far };
        let hi = (y[1] - s.y) / if y[1] >= s.y { r_near } else { r_far };
        let (a0, a1) = angular_interval(s, x0, x1, z0, z1);
        let first = floor_i64(a0 / BIN);
        let last = floor_i64(a1 / BIN);
        (first..=last).all(|k| {
            let b = bin_of(k);
            self.closed[b] <= r_near
                || self.bins[b]
                    .iter()
                    .any(|f| f.r_key <= r_near && f.lo <= lo && f.hi >= hi)
        })
    }

    /// Adds one shrunk occluder to the horizon (see the module docs).
    fn add(&mut self, o: &Shrunk) {
        let s = self.s;
        {
            let (x0, x1, z0, z1) = (o.b.min.x, o.b.max.x, o.b.min.z, o.b.max.z);
            let (bot, top) = (o.b.min.y, o.b.max.y);
            let in_x = s.x > x0 && s.x < x1;
            let in_z = s.z > z0 && s.z < z1;
            if in_x && in_z {
                let r_exit = (s.x - x0).min(x1 - s.x).min(s.z - z0).min(z1 - s.z);
                if bot > s.y {
                    self.ceilings.push(((bot - s.y) / r_exit, bot));
                } else if top < s.y {
                    self.floors.push(((top - s.y) / r_exit, top));
                }
                return;
            }
            if s.x >= x0 && s.x <= x1 && s.z >= z0 && s.z <= z1 {
                return; // on the footprint's border
            }
            let (r_near, r_far) = rect_distances(s, x0, x1, z0, z1);
            let (a0, a1) = angular_interval(s, x0, x1, z0, z1);
            // Bins entirely inside [a0, a1], with a hair of safety.
            let first = ceil_i64(a0 / BIN + 1e-9);
            let last = floor_i64(a1 / BIN - 1e-9); // exclusive
            // The loosest interval it can get in any bin.
            let loose_lo = (bot - s.y) / if bot <= s.y { r_near } else { r_far };
            let loose_hi = (top - s.y) / if top >= s.y { r_near } else { r_far };
            let useless = |h: &Horizon, b: usize| {
                h.closed[b] <= r_near
                    || h.bins[b]
                        .iter()
                        .any(|f| f.r_key <= r_near && f.lo <= loose_lo && f.hi >= loose_hi)
            };
            if (first..last).all(|k| useless(self, bin_of(k))) {
                return; // everything behind it is hidden already
            }
            // The front chain's corners (their distance bounds the entry
            // distance over any azimuth range that contains them).
            let mut corners: [(f64, f64); 3] = [(0.0, 0.0); 3];
            let mut nc = 0;
            let mut r_front: f64 = 0.0;
            let mut front = |x: f64, z: f64| {
                let r = ((x - s.x) * (x - s.x) + (z - s.z) * (z - s.z)).sqrt();
                r_front = r_front.max(r);
                let a = azimuth(x - s.x, z - s.z);
                if !corners[..nc].iter().any(|c| c.1 == r && c.0 == a) && nc < 3 {
                    corners[nc] = (a, r);
                    nc += 1;
                }
            };
            if s.x < x0 {
                front(x0, z0);
                front(x0, z1);
            }
            if s.x > x1 {
                front(x1, z0);
                front(x1, z1);
            }
            if s.z < z0 {
                front(x0, z0);
                front(x1, z0);
            }
            if s.z > z1 {
                front(x0, z1);
                front(x1, z1);
            }
            // Entry distance of the ray along bin boundary `k`: where it
            // crosses the last of the front edges' lines (the rays of bins
            // inside the occluder's interval all hit it).
            let dirs = &self.dirs;
            let entry = |k: i64| -> f64 {
                let (ix, iz) = dirs[k.rem_euclid(BINS as i64) as usize];
                let tx = if s.x < x0 {
                    (x0 - s.x) * ix
                } else if s.x > x1 {
                    (x1 - s.x) * ix
                } else {
                    0.0
                };
                let tz = if s.z < z0 {
                    (z0 - s.z) * iz
                } else if s.z > z1 {
                    (z1 - s.z) * iz
                } else {
                    0.0
                };
                let t = tx.max(tz);
                // A ray grazing past (negative or infinite parameter)
                // falls back to the chain's farthest corner.
                if t.is_finite() && t > 0.0 {
                    t
                } else {
                    f64::INFINITY
                }
            };
            let [y_lo, y_hi] = self.y_range;
            let corner_bins: [i64; 3] = [0, 1, 2].map(|i| {
                if i < nc {
                    floor_i64(corners[i].0 / BIN)
                } else {
                    i64::MIN
                }
            });
            let mut r_next = entry(first);
            for k in first..last {
                let r_here = r_next;
                r_next = entry(k + 1);
                let b = bin_of(k);
                if useless(self, b) {
                    continue; // behind what already hides everything here
                }
                // Largest entry distance over the bin: at its ends or at a
                // chain corner inside it (convex per edge).
                let mut r_key = r_here.max(r_next);
                for i in 0..nc {
                    if corner_bins[i].rem_euclid(BINS as i64) == b as i64 {
                        r_key = r_key.max(corners[i].1);
                    }
                }
                let r_key = r_key.min(r_front) * (1.0 + 1e-12);
                let (inv_key, inv_near) = (1.0 / r_key, 1.0 / r_near);
                let lo = (bot - s.y) * if bot <= s.y { inv_key } else { inv_near };
                let hi = (top - s.y) * if top >= s.y { inv_key } else { inv_near };
                if lo.is_nan() || hi.is_nan() || lo > hi {
                    continue;
                }
                let e = Entry { r_key, lo, hi };
                let list = &mut self.bins[b];
                if list
                    .iter()
                    .any(|f| f.r_key <= e.r_key && f.lo <= e.lo && f.hi >= e.hi)
                {
                    continue;
                }
                if list.is_empty() {
                    self.touched.push(b as u32);
                }
                list.retain(|f| !(e.r_key <= f.r_key && e.lo <= f.lo && e.hi >= f.hi));
                list.push(e);
                // Beyond which distance does this entry alone hide every
                // slope a scene point can have, `(y − y_s)/r` for y in the
                // scene's height range?
                let (a, b_) = (y_hi - s.y, y_lo - s.y);
                let up = if a <= 0.0 {
                    if e.hi >= 0.0 { 0.0 } else { f64::INFINITY }
                } else if e.hi > 0.0 {
                    a / e.hi
                } else {
                    f64::INFINITY
                };
                let down = if b_ >= 0.0 {
                    if e.lo <= 0.0 { 0.0 } else { f64::INFINITY }
                } else if e.lo < 0.0 {
                    b_ / e.lo
                } else {
                    f64::INFINITY
                };
                let c = e.r_key.max(up).max(down) * (1.0 + 1e-12);
                if c < self.closed[b] {
                    self.closed[b] = c;
                }
            }
        }
    }

    /// True when every segment from the sample to every point of `x` is
    /// blocked (see the module docs).
    fn hides(&self, x: &Aabb) -> bool {
        let s = self.s;
        let (x0, x1, z0, z1) = (x.min.x, x.max.x, x.min.z, x.max.z);
        let (r_min, r_max) = rect_distances(s, x0, x1, z0, z1);
        let r_max = r_max.max(1e-12);
        let sig_max = if x.max.y >= s.y {
            if r_min > 0.0 {
                (x.max.y - s.y) / r_min
            } else {
                f64::INFINITY
            }
        } else {
            (x.max.y - s.y) / r_max
        };
        let sig_min = if x.min.y <= s.y {
            if r_min > 0.0 {
                (x.min.y - s.y) / r_min
            } else {
                f64::NEG_INFINITY
            }
        } else {
            (x.min.y - s.y) / r_max
        };
        let ceiling = self
            .ceilings
            .iter()
            .filter(|c| c.1 <= x.min.y)
            .map(|c| c.0)
            .fold(f64::INFINITY, f64::min);
        let floor = self
            .floors
            .iter()
            .filter(|f| f.1 >= x.max.y)
            .map(|f| f.0)
            .fold(f64::NEG_INFINITY, f64::max);
        if ceiling <= sig_min || floor >= sig_max {
            return true;
        }
        let start = sig_min.max(floor);
        let covered = |b: usize| {
            if self.closed[b] <= r_min {
                return true;
            }
            let list = &self.bins[b];
            let mut cur = start;
            for e in list {
                if cur >= sig_max || cur >= ceiling {
                    return true;
                }
                if e.r_key > r_min {
                    continue;
                }
                if e.lo > cur {
                    return false;
                }
                cur = cur.max(e.hi);
            }
            cur >= sig_max || cur >= ceiling
        };
        if r_min <= 0.0 {
            return (0..BINS).all(covered);
        }
        let (a0, a1) = angular_interval(s, x0, x1, z0, z1);
        let first = floor_i64(a0 / BIN);
        let last = floor_i64(a1 / BIN);
        (first..=last).all(|k| covered(bin_of(k)))
    }
}

/// Marks the objects not hidden from the horizon's sample.
/// `hidden` counts, per cluster, its objects not yet in `visible`.
fn mark_visible(
    hz: &Horizon,
    cell: &Aabb,
    scene: &Scene,
    h: &Hierarchy,
    visible: &mut ObjectSet,
    hidden: &mut [u32],
) {
    let meets = |b: &Aabb| b.min.cmple(cell.max).all() && cell.min.cmple(b.max).all();
    h.walk(|n, node| {
        if hidden[n as usize] == 0 || (!meets(&node.aabb) && hz.hides(&node.aabb)) {
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
                        hidden[k as usize] -= 1;
                        k = h.nodes[k as usize].parent;
                    }
                }
            }
        }
        true
    });
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
        hz.build(
            DVec3::new(0.0, 1.7, 0.0),
            &c,
            &vec![true; c.occluders.len()],
        );
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
            hz.build(s, &c, &vec![true; c.occluders.len()]);
            hz.hides(&target)
        };
        let bridged = super::super::occluders::bridges(&[a, b]);
        assert_eq!(bridged.len(), 1);
        assert!(hides(&[a, b, bridged[0]]));
        assert!(!hides(&[a, b]));
        assert!(!hides(&[a]));
    }

    #[test]
    fn ceilings_hide_what_is_above_them() {
        let slab = occ([-20.0, 3.0, -20.0], [20.0, 3.5, 20.0]);
        let c = Conservative::new(&[slab], DVec3::splat(1e-6), 1.0);
        let mut hz = Horizon::new([-1.0, 1000.0]);
        hz.build(
            DVec3::new(0.0, 1.5, 0.0),
            &c,
            &vec![true; c.occluders.len()],
        );
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

    /// True when the open segment `a → b` passes through the interior of
    /// box `o` (shrunk by a hair so that grazing does not count).
    fn blocks(o: &Aabb, a: DVec3, b: DVec3) -> bool {
        let d = b - a;
        let (mut t0, mut t1): (f64, f64) = (1e-9, 1.0 - 1e-9);
        for k in 0..3 {
            let (lo, hi) = (o.min[k] + 1e-7, o.max[k] - 1e-7);
            if d[k].abs() < 1e-15 {
                if a[k] <= lo || a[k] >= hi {
                    return false;
                }
            } else {
                let (mut u, mut v) = ((lo - a[k]) / d[k], (hi - a[k]) / d[k]);
                if u > v {
                    std::mem::swap(&mut u, &mut v);
                }
                t0 = t0.max(u);
                t1 = t1.min(v);
                if t0 >= t1 {
                    return false;
                }
            }
        }
        true
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
