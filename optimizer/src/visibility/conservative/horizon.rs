//! The horizon of one sample point: per azimuth bin, the slope intervals
//! the shrunk occluders block beyond a distance (the per-sample test of
//! [`super`]'s module docs).

use glam::DVec3;

use super::{Conservative, Shrunk};
use crate::math::geom::Aabb;

/// Azimuth bins around a sample point.
pub const BINS: usize = 1024;

/// The diamond angle runs over `[0, PERIOD)`.
const PERIOD: f64 = 4.0;

pub(super) const BIN: f64 = PERIOD / BINS as f64;

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

/// An occluder's slope interval in one bin.
#[derive(Clone, Copy, Debug)]
struct Entry {
    r_key: f64,
    lo: f64,
    hi: f64,
}

/// Parts kept per bin (see [`Horizon::add_part`]).
const MAX_PARTS: usize = 8;

/// An occluder covering part of a bin: from `cut` (diamond angle from the
/// bin's start) to the bin's end when `from`, else from its start to
/// `cut`; every ray of that part is blocked as [`Entry`] says.
#[derive(Clone, Copy, Debug)]
struct Part {
    cut: f64,
    from: bool,
    e: Entry,
}

/// Reciprocal components `(1/x, 1/z)` of the unit direction of every bin
/// boundary `k·BIN`, `k = 0..=BINS` (infinite for a zero component): one
/// table for every horizon.
static DIRS: std::sync::LazyLock<Vec<(f64, f64)>> = std::sync::LazyLock::new(|| {
    (0..=BINS)
        .map(|k| {
            let (x, z) = direction(k as f64 * BIN);
            (1.0 / x, 1.0 / z)
        })
        .collect()
});

/// What occludes around one sample point.
pub(super) struct Horizon {
    s: DVec3,
    /// Lowest and highest point of the scene.
    y_range: [f64; 2],
    bins: Vec<Vec<Entry>>,
    /// Per bin, a distance beyond which every point of the scene's height
    /// range is hidden by a single entry of the bin (`inf`: none).
    closed: Vec<f64>,
    touched: Vec<u32>,
    /// Per bin, the occluders that cover only part of it at one end of
    /// their angular interval, kept to be fused with one covering the rest
    /// from the other end.
    parts: Vec<Vec<Part>>,
    parts_touched: Vec<u32>,
    /// Scratch: a footprint leaf's occluders by distance.
    leaf: Vec<(f64, u32)>,
    /// `(σ_c, b)`: blocks `σ ≥ σ_c` for targets with bottom ≥ `b`.
    ceilings: Vec<(f64, f64)>,
    /// `(σ_f, h)`: blocks `σ ≤ σ_f` for targets with top ≤ `h`.
    floors: Vec<(f64, f64)>,
}

/// Diamond angle of `(dx, dz)` in `[0, 4)`: a monotone stand-in for the
/// azimuth (`atan2`) that needs one division.
pub(super) fn azimuth(dx: f64, dz: f64) -> f64 {
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
pub(super) fn direction(p: f64) -> (f64, f64) {
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
pub(super) fn angular_interval(s: DVec3, x0: f64, x1: f64, z0: f64, z1: f64) -> (f64, f64) {
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
    pub(super) fn new(y_range: [f64; 2]) -> Horizon {
        Horizon {
            s: DVec3::ZERO,
            y_range,
            bins: vec![Vec::new(); BINS],
            closed: vec![f64::INFINITY; BINS],
            touched: Vec::new(),
            parts: vec![Vec::new(); BINS],
            parts_touched: Vec::new(),
            leaf: Vec::new(),
            ceilings: Vec::new(),
            floors: Vec::new(),
        }
    }

    /// The horizon of sample `s` from the usable occluders of `c`, visited
    /// front to back through the footprint hierarchy; a group whose every
    /// bin is already closed nearer than the group is skipped whole.
    pub(super) fn build(&mut self, s: DVec3, c: &Conservative, usable: impl Fn(u32) -> bool) {
        for &t in &self.touched {
            self.bins[t as usize].clear();
            self.closed[t as usize] = f64::INFINITY;
        }
        self.touched.clear();
        for &t in &self.parts_touched {
            self.parts[t as usize].clear();
        }
        self.parts_touched.clear();
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
                        .filter(|&&o| usable(o))
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
    }

    /// True when nothing inside footprint `rect` with heights `y`, at least
    /// `r_near` away and seen from outside, could change what the horizon
    /// hides: in every bin its angular interval touches, the entries keyed
    /// nearer than `r_near` together block the whole slope range of the
    /// box (see [`Horizon::covers`]).
    fn dominated(&self, rect: [f64; 4], y: [f64; 2], r_near: f64) -> bool {
        let s = self.s;
        let [x0, x1, z0, z1] = rect;
        let r_far = rect_far(s, x0, x1, z0, z1);
        let lo = (y[0] - s.y) / if y[0] <= s.y { r_near } else { r_far };
        let hi = (y[1] - s.y) / if y[1] >= s.y { r_near } else { r_far };
        let (a0, a1) = angular_interval(s, x0, x1, z0, z1);
        let first = floor_i64(a0 / BIN);
        let last = floor_i64(a1 / BIN);
        (first..=last).all(|k| self.covers(bin_of(k), r_near, lo, hi))
    }

    /// True when in bin `b` the entries keyed at most `r` together block
    /// every slope of `[lo, hi]` (or the bin is closed by `r`).
    ///
    /// Then an occluder at least `r` away whose slopes seen from the
    /// sample lie in `[lo, hi]` adds nothing to what the horizon hides:
    /// each entry it could add (or fuse with another's part) blocks a
    /// sub-interval of `[lo, hi]` keyed beyond `r`, already blocked for
    /// every target that entry would apply to (and a bin it would close
    /// beyond some distance is covered there already). So skipping it
    /// changes no answer of [`Horizon::hides`], only the time.
    fn covers(&self, b: usize, r: f64, lo: f64, hi: f64) -> bool {
        if self.closed[b] <= r {
            return true;
        }
        // Entries are kept sorted by their lower slope.
        let mut cur = lo;
        for e in &self.bins[b] {
            if e.r_key > r {
                continue;
            }
            if e.lo > cur {
                return false;
            }
            cur = cur.max(e.hi);
            if cur >= hi {
                return true;
            }
        }
        false
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
            let useless = |h: &Horizon, b: usize| h.covers(b, r_near, loose_lo, loose_hi);
            // Everything behind it hidden already, in the bins its interval
            // covers whole and in the two its ends fall in: nothing to add.
            if (first - 1..=last).all(|k| useless(self, bin_of(k))) {
                return;
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
            let dirs: &[(f64, f64)] = &DIRS;
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
            let corner_bins: [i64; 3] = [0, 1, 2].map(|i| {
                if i < nc {
                    floor_i64(corners[i].0 / BIN)
                } else {
                    i64::MIN
                }
            });
            // The slopes blocked beyond `r_key` (at least every entry
            // distance of the rays at hand): `None` when none are.
            let blocked = |r_key: f64| {
                let (inv_key, inv_near) = (1.0 / r_key, 1.0 / r_near);
                let lo = (bot - s.y) * if bot <= s.y { inv_key } else { inv_near };
                let hi = (top - s.y) * if top >= s.y { inv_key } else { inv_near };
                (!(lo.is_nan() || hi.is_nan() || lo > hi)).then_some(Entry { r_key, lo, hi })
            };
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
                if let Some(e) = blocked(r_key.min(r_front) * (1.0 + 1e-12)) {
                    self.insert(b, e);
                }
            }
            // The bins its interval's ends fall in, covered only in part:
            // from the farthest corner of the front chain on (no ray of the
            // interval enters farther), each part is fused with a part of
            // another occluder covering the rest of the bin.
            // (The bins just outside the full ones: each holds an end.)
            let (k0, k1) = (first - 1, last);
            if k0 < k1
                && r_front > 0.0
                && let Some(e) = blocked(r_front * (1.0 + 1e-12))
            {
                if !useless(self, bin_of(k0)) {
                    self.add_part(bin_of(k0), a0 - k0 as f64 * BIN, true, e);
                }
                if !useless(self, bin_of(k1)) {
                    self.add_part(bin_of(k1), a1 - k1 as f64 * BIN, false, e);
                }
            }
        }
    }

    /// Adds a part of bin `b` blocked by `e` (see [`Part`]); where a part
    /// of another occluder from the other end reaches over it, the bin is
    /// blocked whole beyond both parts' distances for the slopes both
    /// block.
    fn add_part(&mut self, b: usize, cut: f64, from: bool, e: Entry) {
        // A hair of safety on each side of the cuts.
        const HAIR: f64 = 1e-9;
        // At most a few fusions per part (fewer only hide less).
        let mut fused = [e; 4];
        let mut n = 0;
        for p in &self.parts[b] {
            if p.from == from {
                continue;
            }
            let (start, end) = if from { (cut, p.cut) } else { (p.cut, cut) };
            if start + 2.0 * HAIR > end {
                continue;
            }
            let f = Entry {
                r_key: e.r_key.max(p.e.r_key),
                lo: e.lo.max(p.e.lo),
                hi: e.hi.min(p.e.hi),
            };
            if f.lo <= f.hi {
                fused[n] = f;
                n += 1;
                if n == fused.len() {
                    break;
                }
            }
        }
        // The nearest few parts are kept (occluders come front to back;
        // a part dropped only fuses less).
        if self.parts[b].is_empty() {
            self.parts_touched.push(b as u32);
        }
        if self.parts[b].len() < MAX_PARTS {
            self.parts[b].push(Part { cut, from, e });
        }
        for &f in &fused[..n] {
            self.insert(b, f);
        }
    }

    /// Adds entry `e` to bin `b`, unless an entry there hides more.
    fn insert(&mut self, b: usize, e: Entry) {
        let s = self.s;
        let [y_lo, y_hi] = self.y_range;
        let list = &mut self.bins[b];
        if list
            .iter()
            .any(|f| f.r_key <= e.r_key && f.lo <= e.lo && f.hi >= e.hi)
        {
            return;
        }
        if list.is_empty() {
            self.touched.push(b as u32);
        }
        list.retain(|f| !(e.r_key <= f.r_key && e.lo <= f.lo && e.hi >= f.hi));
        // Sorted by the lower slope (short lists: a linear search).
        let at = list.iter().position(|f| f.lo > e.lo).unwrap_or(list.len());
        list.insert(at, e);
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

    /// True when every segment from the sample to every point of `x` is
    /// blocked (see the module docs).
    pub(super) fn hides(&self, x: &Aabb) -> bool {
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
        // Above `floor` and below `ceiling`, the bins' entries must block
        // the rest (an empty rest, a flat box at the sample's height, has
        // no slope to block).
        let (start, end) = (sig_min.max(floor), sig_max.min(ceiling));
        if start >= end {
            return true;
        }
        let covered = |b: usize| self.covers(b, r_min, start, end);
        if r_min <= 0.0 {
            return (0..BINS).all(covered);
        }
        let (a0, a1) = angular_interval(s, x0, x1, z0, z1);
        let first = floor_i64(a0 / BIN);
        let last = floor_i64(a1 / BIN);
        (first..=last).all(|k| covered(bin_of(k)))
    }
}

#[cfg(test)]
mod ends {
    //! The horizon against brute force where it is most easily wrong: at
    //! the angular ends of occluders, inside the bins they cover in part.
    use super::*;
    use crate::math::rng::Rng;
    use crate::visibility::occluders::OccluderBox;

    /// True when the segment `a → b` meets the closed box `o` (grown by a
    /// hair: the horizon's own hairs are far smaller than the margin).
    fn meets(o: &Aabb, a: DVec3, b: DVec3) -> bool {
        super::super::segment_meets(o, a, b, 1e-6)
    }

    #[test]
    fn what_it_hides_at_occluders_ends_is_hidden() {
        // Walls whose angular ends crowd a window of a few bins, so that
        // many bins are covered in part, from one end or both, by near and
        // far walls; targets far behind them at random azimuths in the
        // window. Every ray to a hidden target must meet a shrunk wall:
        // counting an end bin as wholly covered, or fusing two parts from
        // the same end, lets some through.
        let mut rng = Rng::new(2005);
        let (mut hidden, mut shown) = (0usize, 0usize);
        for case in 0..60 {
            let centre = rng.range(-0.3, 0.3);
            let width = 4.0 * BIN;
            // One of the four axis turns, so that every quadrant's corners
            // and the seam at 0 are exercised.
            let turn = rng.next_u64() % 4;
            let rot = |x: f64, z: f64| match turn {
                0 => (x, z),
                1 => (-z, x),
                2 => (-x, -z),
                _ => (z, -x),
            };
            let s = DVec3::new(0.0, rng.range(0.5, 6.0), 0.0);
            let mut walls = Vec::new();
            for _ in 0..(2 + rng.next_u64() % 6) {
                let x0 = rng.range(8.0, 150.0);
                let x1 = x0 + rng.range(0.2, 3.0);
                let a = centre + rng.range(-width, width);
                let b = if rng.f64() < 0.5 {
                    centre + rng.range(-width, width)
                } else if rng.f64() < 0.5 {
                    a + rng.range(-2.0, 2.0) * BIN
                } else {
                    centre + 3.0 * width * (if rng.f64() < 0.5 { -1.0 } else { 1.0 })
                };
                let z_at = |p: f64| {
                    let (dx, dz) = direction(p);
                    x0 * dz / dx
                };
                let (za, zb) = (z_at(a), z_at(b));
                let bottom = if rng.f64() < 0.3 {
                    rng.range(1.0, 8.0)
                } else {
                    -1.0
                };
                let top = bottom.max(0.0) + rng.range(2.0, 30.0);
                let (lx, lz) = rot(x0, za.min(zb));
                let (hx, hz) = rot(x1, za.max(zb));
                let b = Aabb::new(
                    DVec3::new(lx.min(hx), bottom, lz.min(hz)),
                    DVec3::new(lx.max(hx), top, lz.max(hz)),
                );
                walls.push(OccluderBox {
                    aabb: b,
                    support: b,
                    open_below: f64::NEG_INFINITY,
                });
            }
            let c = Conservative::new(&walls, DVec3::splat(1e-6), 1.0);
            let shrunk: Vec<Aabb> = c.occluders.iter().map(|o| o.b).collect();
            let mut hz = Horizon::new([-1.0, 1000.0]);
            hz.build(s, &c, |_| true);
            for _ in 0..400 {
                let p = centre + rng.range(-1.5, 1.5) * width;
                let (dx, dz) = direction(p);
                let r = rng.range(10.0, 400.0);
                let (x, z) = rot(r * dx, r * dz);
                let y = rng.range(-1.0, 20.0);
                let t = Aabb::new(
                    DVec3::new(x - 0.01, y, z - 0.01),
                    DVec3::new(x + 0.01, y + 0.02, z + 0.01),
                );
                if !hz.hides(&t) {
                    shown += 1;
                    continue;
                }
                hidden += 1;
                for i in 0..9 {
                    let q = if i == 8 {
                        (t.min + t.max) * 0.5
                    } else {
                        DVec3::new(
                            if i & 1 == 0 { t.min.x } else { t.max.x },
                            if i & 2 == 0 { t.min.y } else { t.max.y },
                            if i & 4 == 0 { t.min.z } else { t.max.z },
                        )
                    };
                    assert!(
                        shrunk.iter().any(|o| meets(o, s, q)),
                        "case {case}: the ray from {s} to {q} passes every wall but {t:?} is hidden"
                    );
                }
            }
        }
        // Both answers are common: the check is not vacuous.
        assert!(
            hidden > 2000 && shown > 2000,
            "{hidden} hidden, {shown} shown"
        );
    }
}
