//! Shaft geometry for candidate generation: the axis grid of each
//! half-angle, the ladder of minimum distances, and the smallest cone
//! around the directions of the cells a shaft serves.

use std::f64::consts::PI;

use glam::DVec3;

use crate::api::job::Job;
use crate::math::geom::Aabb;

/// Axis grid of the shafts of one half-angle: rings of elevation (only the
/// horizontal one when the view space is flat, under half a cell high),
/// each with azimuths at about the rings' spacing along it, so axes are
/// spread evenly over the sphere. The spacing is the job's direction step,
/// or a fraction of the half-angle for wide shafts (`axis_spacing`).
#[derive(Clone, Debug)]
pub struct AxisGrid {
    /// Elevation step between rings.
    step: f64,
    /// Highest ring index (0: the horizontal ring only).
    max_el: i32,
    /// Per ring from `-max_el`: the index of its first axis in `axes`, and
    /// one past the last ring's.
    ring_start: Vec<u32>,
    /// The unit axes, ring by ring.
    axes: Vec<DVec3>,
}

impl AxisGrid {
    /// The grid of the job's shafts of half-angle `alpha`.
    pub fn new(job: &Job, alpha: f64) -> Self {
        let cp = &job.candidates;
        let spacing = cp
            .direction_step_deg
            .to_radians()
            .max(cp.axis_spacing * alpha);
        let n_az = ((2.0 * PI / spacing).round() as u32).max(1);
        let step = 2.0 * PI / f64::from(n_az);
        let height = job.view_space.max[1] - job.view_space.min[1];
        let max_el = if height > 0.5 * job.problem_views.cell_size {
            ((PI / 2.0) / step + 1e-9).floor() as i32
        } else {
            0
        };
        // Ring `m` has azimuths in proportion to its circumference, one
        // at a pole; its axes are computed once here, not per test.
        let mut ring_start = vec![0u32];
        let mut axes = Vec::new();
        for m in -max_el..=max_el {
            let el = Self::ring_elevation(step, m);
            let n = if el.cos() < 1e-9 {
                1
            } else {
                ((f64::from(n_az) * el.cos()).round() as u32).max(1)
            };
            axes.extend((0..n).map(|j| {
                let az = f64::from(j) * 2.0 * PI / f64::from(n);
                DVec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin())
            }));
            ring_start.push(axes.len() as u32);
        }
        AxisGrid {
            step,
            max_el,
            ring_start,
            axes,
        }
    }

    /// Elevation of ring `m` on a grid of elevation step `step`.
    fn ring_elevation(step: f64, m: i32) -> f64 {
        (f64::from(m) * step).clamp(-PI / 2.0, PI / 2.0)
    }

    /// Elevation of ring `m`.
    fn elevation(&self, m: i32) -> f64 {
        Self::ring_elevation(self.step, m)
    }

    /// Index in `ring_start` of ring `m`.
    fn ring_index(&self, m: i32) -> usize {
        (m + self.max_el) as usize
    }

    /// Azimuths on ring `m`.
    fn ring(&self, m: i32) -> u32 {
        let r = self.ring_index(m);
        self.ring_start[r + 1] - self.ring_start[r]
    }

    /// Unit axis for ring `m` and azimuth index `j`.
    pub fn axis(&self, m: i32, j: u32) -> DVec3 {
        self.axis_at(self.index(m, j))
    }

    /// Index of the axis of ring `m` and azimuth index `j` among all the
    /// grid's axes, ring by ring (so ordered by `(m, j)`).
    pub fn index(&self, m: i32, j: u32) -> u32 {
        self.ring_start[self.ring_index(m)] + j
    }

    /// The unit axis of index `i` ([`index`](Self::index)).
    pub fn axis_at(&self, i: u32) -> DVec3 {
        self.axes[i as usize]
    }

    /// Calls `f(m, j)` for every grid axis whose cone of half-angle
    /// `alpha` holds every unit direction of `corners` (a cell's corners
    /// seen from a cluster, `w` the direction of its centre).
    pub(super) fn holding(
        &self,
        w: DVec3,
        alpha: f64,
        corners: &[DVec3; 8],
        mut f: impl FnMut(i32, u32),
    ) {
        let cos = alpha.cos() - 1e-12;
        self.near(w, alpha, |m, j| {
            let u = self.axis(m, j);
            if corners.iter().all(|c| c.dot(u) >= cos) {
                f(m, j);
            }
        });
    }

    /// Calls `f(m, j)` for every grid axis within `alpha` of unit `w` (and
    /// possibly a few more; callers check exactly).
    pub(super) fn near(&self, w: DVec3, alpha: f64, mut f: impl FnMut(i32, u32)) {
        let el_w = w.y.clamp(-1.0, 1.0).asin();
        let az_w = w.z.atan2(w.x);
        let m_lo = (((el_w - alpha) / self.step).floor() as i32).max(-self.max_el);
        let m_hi = (((el_w + alpha) / self.step).ceil() as i32).min(self.max_el);
        for m in m_lo..=m_hi {
            let el = self.elevation(m);
            let n_ring = self.ring(m);
            if n_ring == 1 {
                f(m, 0);
                continue;
            }
            let den = el.cos() * el_w.cos();
            let rhs = if den > 1e-12 {
                (alpha.cos() - el.sin() * el_w.sin()) / den
            } else {
                -2.0
            };
            if rhs > 1.0 + 1e-12 {
                continue;
            }
            let span = if rhs <= -1.0 { PI } else { rhs.min(1.0).acos() };
            if span >= PI - 1e-9 {
                for j in 0..n_ring {
                    f(m, j);
                }
                continue;
            }
            let az_step = 2.0 * PI / f64::from(n_ring);
            let lo = ((az_w - span) / az_step).floor() as i64;
            let hi = ((az_w + span) / az_step).ceil() as i64;
            let n = i64::from(n_ring);
            let count = (hi - lo + 1).min(n);
            for k in 0..count {
                f(m, (lo + k).rem_euclid(n) as u32);
            }
        }
    }
}

/// The shafts' half-angles (radians, at most 90°), ascending, without
/// repeats.
pub(super) fn half_angles(job: &Job) -> Vec<f64> {
    let mut alphas: Vec<f64> = job
        .candidates
        .apex_angles_deg
        .iter()
        .map(|a| (a * 0.5).to_radians().min(PI / 2.0))
        .collect();
    alphas.sort_by(f64::total_cmp);
    alphas.dedup();
    alphas
}

/// Half-angle of the cone around `axis` containing the unit directions
/// `dirs`.
pub(super) fn cone_half_angle(dirs: &[DVec3], axis: DVec3) -> f64 {
    min_cos(dirs, axis).clamp(-1.0, 1.0).acos()
}

/// The smallest cosine between `axis` and the unit directions `dirs` (1 for
/// none): [`cone_half_angle`] before the arccosine, so that it can be
/// taken over a prefix in parts.
pub(super) fn min_cos(dirs: &[DVec3], axis: DVec3) -> f64 {
    dirs.iter().map(|w| w.dot(axis)).fold(1.0, f64::min)
}

/// The distinct corners of `regions`, and each region's eight corners as
/// indices into them. Corners are the same when their coordinates are, bit
/// for bit (neighbouring cells share corners, which the grid computes bit
/// for bit alike).
pub(super) fn distinct_corners(regions: impl Iterator<Item = Aabb>) -> (Vec<DVec3>, Vec<[u32; 8]>) {
    let corners: Vec<[DVec3; 8]> = regions.map(|r| r.corners()).collect();
    let bits = |p: DVec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let mut order: Vec<([u64; 3], u32)> = (0..8 * corners.len() as u32)
        .map(|i| (bits(corners[i as usize / 8][i as usize % 8]), i))
        .collect();
    order.sort_unstable();
    let mut ids = vec![[0u32; 8]; corners.len()];
    let mut points: Vec<DVec3> = Vec::new();
    for (n, &(b, i)) in order.iter().enumerate() {
        if n == 0 || order[n - 1].0 != b {
            points.push(corners[i as usize / 8][i as usize % 8]);
        }
        ids[i as usize / 8][i as usize % 8] = points.len() as u32 - 1;
    }
    (points, ids)
}

/// Axes of the smallest cones around prefixes of unit directions `dirs`:
/// entry `k` of the result is for `dirs[..ends[k]]` (`ends` ascending).
/// Reorders `dirs` within each segment between two ends, so every prefix
/// still holds the same directions.
///
/// Welzl's algorithm on spherical caps (a cap through two directions is
/// centred on their midpoint, through three on their plane's normal) is
/// incremental: after the first `m` directions its cap is the smallest
/// around them, so one pass answers every prefix. Each segment between two
/// ends is shuffled with a fixed seed, which keeps the expected time linear
/// and the answer the same on every run. The directions must lie in a
/// half-space through the origin (cones up to 90°); if they do not, or
/// rounding makes a cap degenerate, an entry may be a wider cone or `None`
/// but never a wrong one: callers measure the half-angle around the axis.
pub(super) fn fit_cones(p: &mut [DVec3], ends: &[usize]) -> Vec<Option<DVec3>> {
    const TOL: f64 = 1e-12;
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    let mut seg_start = 0;
    for &end in ends {
        // Fisher–Yates with a fixed xorshift seed, within the segment.
        for i in (seg_start + 1..end).rev() {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let r = seg_start + (state % (i - seg_start + 1) as u64) as usize;
            p.swap(i, r);
        }
        seg_start = seg_start.max(end);
    }
    let cap2 = |a: DVec3, b: DVec3| {
        let axis = (a + b).normalize_or_zero();
        (axis, axis.dot(a))
    };
    let cap3 = |a: DVec3, b: DVec3, c: DVec3| {
        let n = (b - a).cross(c - a).normalize_or_zero();
        let n = if n.dot(a) < 0.0 { -n } else { n };
        (n, n.dot(a))
    };
    let inside = |(axis, cos): (DVec3, f64), x: DVec3| x.dot(axis) >= cos - TOL;
    let valid = |(axis, cos): (DVec3, f64)| {
        (axis != DVec3::ZERO && cos > 0.0 && axis.is_finite()).then_some(axis)
    };
    let mut out = Vec::with_capacity(ends.len());
    let mut cap = (DVec3::ZERO, 2.0);
    let mut next_end = ends.iter().peekable();
    for i in 0..=p.len() {
        while next_end.next_if(|&&e| e <= i).is_some() {
            out.push(if i == 0 { None } else { valid(cap) });
        }
        if i == p.len() {
            break;
        }
        if i > 0 && inside(cap, p[i]) {
            continue;
        }
        cap = (p[i], 1.0);
        for j in 0..i {
            if inside(cap, p[j]) {
                continue;
            }
            cap = cap2(p[i], p[j]);
            for k in 0..j {
                if inside(cap, p[k]) {
                    continue;
                }
                let c3 = cap3(p[i], p[j], p[k]);
                // Nearly collinear triples: keep the widest pair's cap.
                cap = if c3.0 == DVec3::ZERO {
                    [cap2(p[i], p[k]), cap2(p[j], p[k])]
                        .into_iter()
                        .min_by(|x, y| x.1.total_cmp(&y.1))
                        .expect("two caps")
                } else {
                    c3
                };
            }
        }
    }
    out.resize(ends.len(), None);
    out
}

/// Minimum distance `k` of the ladder for a cluster of diameter `size`:
/// `size·2^(k/steps)`, exact at whole doublings.
pub(super) fn ladder_distance(size: f64, k: u32, steps: u32) -> f64 {
    size * f64::from(1u32 << (k / steps).min(31))
        * 2f64.powf(f64::from(k % steps) / f64::from(steps))
}

/// The largest `k ≤ last_k` whose ladder distance is at most `dist` (0 if
/// none is): from the logarithm, then corrected for its rounding.
pub(super) fn ladder_index(size: f64, dist: f64, steps: u32, last_k: u32) -> u32 {
    let guess = (f64::from(steps) * (dist / size).log2()).floor();
    let mut k = if guess.is_nan() {
        0
    } else {
        guess.clamp(0.0, f64::from(last_k)) as u32
    };
    while k > 0 && ladder_distance(size, k, steps) > dist {
        k -= 1;
    }
    while k < last_k && ladder_distance(size, k + 1, steps) <= dist {
        k += 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every axis of a grid, by brute force over its rings.
    fn all_axes(grid: &AxisGrid) -> Vec<(i32, u32)> {
        (-grid.max_el..=grid.max_el)
            .flat_map(|m| (0..grid.ring(m)).map(move |j| (m, j)))
            .collect()
    }

    #[test]
    fn distinct_corners_are_shared_between_neighbouring_cells() {
        // A 3 x 2 x 1 row of grid cells: 4 x 3 x 2 distinct corners.
        let (lo, hi) = (DVec3::new(0.3, 1.5, 0.7), DVec3::new(70.1, 5.0, 47.3));
        let grid = crate::math::grid::Grid::new(lo, hi, 23.3, DVec3::ZERO);
        let cells: Vec<Aabb> = (0..3)
            .flat_map(|x| (0..2).map(move |z| (x, z)))
            .map(|(x, z)| grid.cell_box([x, 0, z], [x + 1, 1, z + 1]))
            .collect();
        let (points, ids) = distinct_corners(cells.iter().copied());
        assert_eq!(points.len(), 24);
        for (cell, ids) in cells.iter().zip(&ids) {
            for (p, &id) in cell.corners().iter().zip(ids) {
                assert_eq!(points[id as usize], *p);
            }
        }
        let dirs = &points;
        let mut used: Vec<u32> = ids.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        assert_eq!(
            used.len(),
            dirs.len(),
            "every direction belongs to a corner"
        );
    }

    #[test]
    fn axis_grids_are_even_and_find_every_axis_near_a_direction() {
        let mut rng = crate::math::rng::Rng::new(11);
        for (top, spacing) in [
            (2.0, 0.0),
            (2.0, 0.5),
            (30.0, 0.0),
            (30.0, 0.5),
            (30.0, 1.0),
        ] {
            let mut job = Job::with_view_space([0.0, 1.0, 0.0], [100.0, top, 100.0]);
            job.candidates.axis_spacing = spacing;
            for alpha in [5.625f64, 22.5, 45.0, 90.0].map(f64::to_radians) {
                let grid = AxisGrid::new(&job, alpha);
                let expected = 11.25f64.to_radians().max(spacing * alpha);
                let axes = all_axes(&grid);
                // Flat view spaces: the horizontal ring at the direction
                // step (32 azimuths by default), or wider for wide shafts.
                if top < 5.0 {
                    assert_eq!(grid.max_el, 0);
                    assert_eq!(axes.len() as u32, grid.ring(0));
                    assert_eq!(grid.ring(0), (2.0 * PI / expected).round() as u32);
                }
                assert!((grid.step - expected).abs() < 0.05 * expected);
                for _ in 0..200 {
                    let el = if top < 5.0 {
                        0.0
                    } else {
                        rng.range(-PI / 2.0, PI / 2.0)
                    };
                    let az = rng.range(0.0, 2.0 * PI);
                    let w = DVec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin());
                    let mut found = Vec::new();
                    grid.near(w, alpha, |m, j| found.push((m, j)));
                    let cos = alpha.cos();
                    for &(m, j) in &axes {
                        if grid.axis(m, j).dot(w) >= cos + 1e-12 {
                            assert!(found.contains(&(m, j)), "missed ({m}, {j})");
                        }
                    }
                    // Even: some axis lies within about half the grid's
                    // diagonal (step/√2, at most 0.75 step) of any direction
                    // the grid spans, so at `axis_spacing` 1 within 0.75 α
                    // (rings no denser than the horizontal one, so the grid
                    // grows with the sphere's area, not with its rings).
                    let nearest = axes
                        .iter()
                        .map(|&(m, j)| grid.axis(m, j).dot(w).clamp(-1.0, 1.0).acos())
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        nearest <= 0.75 * grid.step,
                        "{} > 0.75 x {}",
                        nearest,
                        grid.step
                    );
                }
                if top > 5.0 {
                    let sphere = 4.0 * PI / (grid.step * grid.step);
                    assert!((axes.len() as f64) < 1.2 * sphere, "{} axes", axes.len());
                }
            }
        }
    }

    #[test]
    fn fitted_cones_are_close_to_the_smallest() {
        // Directions on a 10° circle around `c`: the cone found is 10°.
        let c = DVec3::new(1.0, 0.2, -0.5).normalize();
        let e1 = c.cross(DVec3::Y).normalize();
        let e2 = c.cross(e1);
        let r = 10f64.to_radians();
        let dirs: Vec<DVec3> = (0..12)
            .map(|k| {
                let t = f64::from(k) * PI / 6.0;
                (c * r.cos() + (e1 * t.cos() + e2 * t.sin()) * r.sin()).normalize()
            })
            .collect();
        let a = fit_cones(&mut dirs.clone(), &[12])[0].unwrap();
        let half = cone_half_angle(&dirs, a);
        assert!((half - r).abs() < 1e-9, "{}", half.to_degrees());
        // Inner points change nothing; a single direction is its own axis.
        let mut more = vec![c, (c + e1 * 0.05).normalize()];
        more.extend(&dirs);
        let fits = fit_cones(&mut more.clone(), &[0, 1, 14]);
        assert_eq!(fits[0], None);
        assert!(fits[1].unwrap().dot(c) > 1.0 - 1e-12);
        assert!((cone_half_angle(&more, fits[2].unwrap()) - r).abs() < 1e-9);
    }

    /// The smallest half-angle around an axis through a pair's midpoint
    /// or a triple's plane normal (the smallest cone is one of them).
    fn brute_force(dirs: &[DVec3]) -> f64 {
        let n = dirs.len();
        let mut best = f64::INFINITY;
        for i in 0..n {
            for j in i..n {
                for k in j..n {
                    let axis = if k == j {
                        (dirs[i] + dirs[j]).normalize()
                    } else {
                        let a = (dirs[j] - dirs[i]).cross(dirs[k] - dirs[i]).normalize();
                        if a.dot(dirs[i]) < 0.0 { -a } else { a }
                    };
                    if axis.is_finite() {
                        best = best.min(cone_half_angle(dirs, axis));
                    }
                }
            }
        }
        best
    }

    #[test]
    fn fitted_cones_match_brute_force() {
        // Random directions in a 40° cap; every prefix answered at once.
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..200 {
            let n = 3 + (next() * 9.0) as usize;
            let dirs: Vec<DVec3> = (0..n)
                .map(|_| {
                    let t = next() * 2.0 * PI;
                    let r = next() * 40f64.to_radians();
                    DVec3::new(r.sin() * t.cos(), r.sin() * t.sin(), r.cos())
                })
                .collect();
            let ends = [1, n / 2, n];
            let fits = fit_cones(&mut dirs.clone(), &ends);
            for (&end, fit) in ends.iter().zip(&fits) {
                let prefix = &dirs[..end];
                let half = cone_half_angle(prefix, fit.unwrap());
                let best = brute_force(prefix);
                assert!((half - best).abs() < 1e-7, "{half} vs {best}");
            }
        }
    }

    #[test]
    fn ladder_indices_are_exact_at_the_rungs() {
        for steps in [1, 3, 4] {
            let last = 10 * steps;
            for size in [0.37, 2.0, 31.4] {
                for k in 0..=last {
                    let d = ladder_distance(size, k, steps);
                    assert_eq!(ladder_index(size, d, steps, last), k);
                    if k > 0 {
                        assert_eq!(ladder_index(size, d * (1.0 - 1e-12), steps, last), k - 1);
                    }
                }
                // Whole doublings are exact; beyond the ladder, its last rung.
                assert_eq!(ladder_distance(size, 2 * steps, steps), size * 4.0);
                assert_eq!(ladder_index(size, size * 1e6, steps, last), last);
                assert_eq!(ladder_index(size, size * 0.5, steps, last), 0);
            }
        }
    }
}
