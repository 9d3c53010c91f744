//! Impostor candidate generation (paper §4, DESIGN §2.6).
//!
//! A candidate is a cluster (hierarchy node) with a view cell: a shaft around
//! the cluster centre (apex angle, axis on an angular grid, minimum distance
//! `size·2^(k/steps)`) or a box of the 3D view space hierarchy. Only
//! candidates that serve at least one CPV — the CPV's region lies inside the
//! view cell, the cluster meets the CPV's enclosing frustum and its impostor
//! is cheaper than its geometry there — and whose view cell does not meet
//! the cluster are kept.
//!
//! Enumeration is output-sensitive: it starts from the (CPV, cluster) pairs
//! recorded by the problem view approximation, not from all shafts × all
//! CPVs. For one (cluster, apex angle, axis), the shaft with minimum distance
//! `d_k` serves exactly the CPVs at distance ≥ `d_k`, so only the largest
//! `d_k` below some CPV's distance is generated: a smaller one that serves
//! no additional CPV would cost more memory for the same service.
//!
//! Each shaft is then fitted to the cells it serves: it starts at the
//! nearest of them and narrows to the smallest cone around their corners
//! (Welzl's algorithm on spherical caps, one pass for all the nested
//! candidates of an angle and axis). The grid decides which cells a shaft
//! serves; the fit makes it no larger than those cells need. The paper
//! doubles the minimum distance from step to step (`min_distance_steps` 1);
//! the default takes four steps per doubling, so a shaft can leave out near
//! cells that would force it to more layers and texels.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::api::job::{Job, Method};
use crate::math::IdRange;
use crate::math::geom::Aabb;
use crate::model::cost::Cost;
use crate::model::impostor::{ImpostorModel, ImpostorSpec, ViewCell};
use crate::views::{Context, ProblemViews};

mod pairs;
pub use pairs::{Group, Pairs};

/// One impostor candidate.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// The cluster (hierarchy node id).
    pub node: u32,
    /// The view cell.
    pub cell: ViewCell,
    /// For box cells, the kd node of the 3D view space hierarchy; else `u32::MAX`.
    pub kd: u32,
    /// Layers, resolution, memory.
    pub spec: ImpostorSpec,
    /// The groups it serves: `Candidates::served[served.start..served.end]`.
    pub served: IdRange,
}

/// The generated candidates, ordered by (node, key): ids are indices, and
/// the serving relation at cell granularity: a candidate serves a list of
/// groups (`served`), all of its own cluster (see [`Pairs`]).
#[derive(Clone, Debug, Default)]
pub struct Candidates {
    /// The candidates.
    pub list: Vec<Candidate>,
    /// The (cluster, CPV) pairs, by cluster and cell.
    pub pairs: Pairs,
    /// Group ids served by the candidates (see `Candidate::served`).
    pub served: Vec<u32>,
}

impl Candidates {
    /// Calls `f(cpv id, cost)` for every CPV candidate `i` may serve (its
    /// region lies in the view cell, it lists the cluster, and the impostor
    /// may accelerate its cell), with the cost of the cluster's objects in
    /// the CPV's enclosing set.
    pub fn for_each_served(&self, i: u32, mut f: impl FnMut(u32, Cost)) {
        for &g in &self.served[self.list[i as usize].served.indices()] {
            for (c, cost) in self.pairs.iter(self.pairs.group(g)) {
                f(c, cost);
            }
        }
    }
}

/// Axis grid of shaft directions: azimuth steps always, elevation steps when
/// the view space has height (more than half a cell vertically).
#[derive(Clone, Debug)]
pub struct AxisGrid {
    step: f64,
    n_az: u32,
    max_el: i32,
}

impl AxisGrid {
    /// The grid of a job.
    pub fn new(job: &Job) -> Self {
        let step = job.candidates.direction_step_deg.to_radians();
        let n_az = ((2.0 * PI / step).round() as u32).max(1);
        let height = job.view_space.max[1] - job.view_space.min[1];
        let max_el = if height > 0.5 * job.problem_views.cell_size {
            ((PI / 2.0) / step + 1e-9).floor() as i32
        } else {
            0
        };
        AxisGrid { step, n_az, max_el }
    }

    /// Unit axis for elevation index `m` and azimuth index `j`.
    pub fn axis(&self, m: i32, j: u32) -> DVec3 {
        let el = (f64::from(m) * self.step).clamp(-PI / 2.0, PI / 2.0);
        let az = f64::from(j) * 2.0 * PI / f64::from(self.n_az);
        DVec3::new(el.cos() * az.cos(), el.sin(), el.cos() * az.sin())
    }

    /// Calls `f(m, j)` for every grid axis whose cone of half-angle
    /// `alpha` holds every unit direction of `corners` (a cell's corners
    /// seen from a cluster, `w` the direction of its centre).
    fn holding(&self, w: DVec3, alpha: f64, corners: &[DVec3; 8], mut f: impl FnMut(i32, u32)) {
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
    fn near(&self, w: DVec3, alpha: f64, mut f: impl FnMut(i32, u32)) {
        let el_w = w.y.clamp(-1.0, 1.0).asin();
        let az_w = w.z.atan2(w.x);
        let az_step = 2.0 * PI / f64::from(self.n_az);
        let m_lo = (((el_w - alpha) / self.step).floor() as i32).max(-self.max_el);
        let m_hi = (((el_w + alpha) / self.step).ceil() as i32).min(self.max_el);
        for m in m_lo..=m_hi {
            let el = f64::from(m) * self.step;
            if el.abs() >= PI / 2.0 - 1e-9 {
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
                for j in 0..self.n_az {
                    f(m, j);
                }
                continue;
            }
            let lo = ((az_w - span) / az_step).floor() as i64;
            let hi = ((az_w + span) / az_step).ceil() as i64;
            let n = i64::from(self.n_az);
            let count = (hi - lo + 1).min(n);
            for k in 0..count {
                f(m, (lo + k).rem_euclid(n) as u32);
            }
        }
    }
}

/// The shafts' half-angles (radians, at most 90°), ascending, without
/// repeats.
fn half_angles(job: &Job) -> Vec<f64> {
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

/// An estimate of the served-list entries candidate generation will make,
/// for predicting memory before candidates exist: the CPVs' groups times the
/// mean number of candidate blocks (a shaft angle and axis, or a box) whose
/// view cell holds the cell of a sampled group. The groups are those listed
/// by the first CPV of up to 32 cells spread over the CPVs; a block is
/// counted whether or not its impostor would help there, so the estimate
/// leans high.
pub fn estimate_served(ctx: &Context, job: &Job, pv: &ProblemViews) -> u64 {
    let [_, _, groups] = crate::views::PairCounts::totals(&pv.node_counts);
    if groups == 0 {
        return 0;
    }
    let grid = AxisGrid::new(job);
    let method = job.method();
    let shafts = matches!(method, Method::Shafts | Method::Both | Method::ShaftsPrune);
    let boxes = matches!(method, Method::Boxes | Method::Both | Method::PerCell);
    let alphas = half_angles(job);
    let cells = pv.cells();
    let step = cells.len().div_ceil(32).max(1);
    let firsts: Vec<usize> = cells
        .iter()
        .step_by(step)
        .map(|r| r.start as usize)
        .collect();
    let h = ctx.hierarchy;
    let counts: Vec<(u64, u64)> = firsts
        .par_iter()
        .map(|&i| {
            let c = &pv.cpvs[i];
            let costs = crate::views::RegionCosts::of_kd(
                ctx,
                &pv.kd[c.kd as usize],
                &crate::views::Counters::new(),
            );
            let (_, list) = crate::views::cpv_clusters(ctx, &costs, &c.region, &c.vdi);
            let mut depth = 0u64;
            let mut up = c.kd;
            while up != u32::MAX {
                depth += 1;
                up = pv.kd[up as usize].parent;
            }
            let mut blocks = 0u64;
            for &(n, _) in &list {
                let sphere = h.nodes[n as usize].sphere;
                if boxes {
                    blocks += depth;
                }
                let dist = c.region.distance_to_point(sphere.center);
                if !shafts || sphere.radius <= 0.0 || dist < 2.0 * sphere.radius {
                    continue;
                }
                let corners = c.region.corners().map(|p| (p - sphere.center).normalize());
                let w = (c.region.center() - sphere.center).normalize();
                for &alpha in &alphas {
                    grid.holding(w, alpha, &corners, |_, _| blocks += 1);
                }
            }
            (list.len() as u64, blocks)
        })
        .collect();
    let (sampled, blocks) = counts
        .iter()
        .fold((0u64, 0u64), |(a, b), &(x, y)| (a + x, b + y));
    if sampled == 0 {
        return 0;
    }
    (groups as f64 * blocks as f64 / sampled as f64).ceil() as u64
}

/// Half-angle of the cone around `axis` containing the unit directions
/// `dirs`.
fn cone_half_angle(dirs: &[DVec3], axis: DVec3) -> f64 {
    dirs.iter()
        .map(|w| w.dot(axis))
        .fold(1.0, f64::min)
        .clamp(-1.0, 1.0)
        .acos()
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
fn fit_cones(p: &mut [DVec3], ends: &[usize]) -> Vec<Option<DVec3>> {
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
fn ladder_distance(size: f64, k: u32, steps: u32) -> f64 {
    size * f64::from(1u32 << (k / steps).min(31))
        * 2f64.powf(f64::from(k % steps) / f64::from(steps))
}

/// The largest `k ≤ last_k` whose ladder distance is at most `dist` (0 if
/// none is): from the logarithm, then corrected for its rounding.
fn ladder_index(size: f64, dist: f64, steps: u32, last_k: u32) -> u32 {
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

/// A candidate key, sortable and deduplicated per node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Key {
    Shaft { angle: u8, m: i32, j: u32, k: u32 },
    Box { kd: u32 },
}

/// Generates the candidates for the CPVs of `pv`.
pub fn generate(ctx: &Context, job: &Job, pv: &ProblemViews) -> Candidates {
    let h = ctx.hierarchy;
    let imodel = ImpostorModel::new(job);
    let grid = AxisGrid::new(job);
    let method = job.method();
    let shafts = matches!(method, Method::Shafts | Method::Both | Method::ShaftsPrune);
    let boxes = matches!(method, Method::Boxes | Method::Both | Method::PerCell);
    // Per-cell: one box size only, the cells' ancestors `level` levels up.
    let per_cell = (method == Method::PerCell).then_some(job.per_cell.level);
    let alphas = half_angles(job);
    let steps = job.candidates.min_distance_steps.max(1);
    let last_k = job.candidates.min_distance_doublings.saturating_mul(steps);

    // The (cluster → CPVs) pairs, grouped by cell.
    let pairs = Pairs::collect(ctx, pv);
    if ctx.cancelled() {
        return Candidates::default();
    }

    // Per cluster: the candidates and, for each, the local list of groups it
    // serves.
    let per_node: Vec<(Vec<Candidate>, Vec<u32>)> = (0..h.nodes.len() as u32)
        .into_par_iter()
        .map(|n| {
            let IdRange { start: g0, end: g1 } = pairs.groups_of(n);
            if g0 == g1 || ctx.cancelled() {
                return (Vec::new(), Vec::new());
            }
            let sphere = h.nodes[n as usize].sphere;
            // Directions of each group's cell corners from the cluster.
            let corner_dirs: Vec<[DVec3; 8]> = (g0..g1)
                .map(|g| {
                    let region = pv.cpvs[pairs.first_cpv(pairs.group(g)) as usize].region;
                    region.corners().map(|p| (p - sphere.center).normalize())
                })
                .collect();
            let size = 2.0 * sphere.radius;
            // (key, group) for every cell inside the key's view cell.
            let mut tuples: Vec<(Key, u32)> = Vec::new();
            for g in g0..g1 {
                let gr = pairs.group(g);
                let first = &pv.cpvs[pairs.first_cpv(gr) as usize];
                let region = first.region;
                let dist = gr.dist;
                // Some CPV of the cell is accelerated by an impostor of `spec`.
                let helps = |spec: &ImpostorSpec| {
                    let imp = ctx.model.impostor(spec.layers, sphere.radius, dist);
                    pairs.iter(gr).any(|(c, cost)| {
                        let cur = pv.cpvs[c as usize].cost;
                        ctx.model.frame_time(cur - cost + imp) < ctx.model.frame_time(cur)
                    })
                };
                if shafts && size > 0.0 && dist >= size {
                    let k = ladder_index(size, dist, steps, last_k);
                    let d_k = ladder_distance(size, k, steps);
                    let corners = &corner_dirs[(g - g0) as usize];
                    let w = (region.center() - sphere.center).normalize();
                    for (ai, &alpha) in alphas.iter().enumerate() {
                        let Some(spec) = imodel.shaft(&sphere, alpha, d_k) else {
                            continue;
                        };
                        if !helps(&spec) {
                            continue;
                        }
                        grid.holding(w, alpha, corners, |m, j| {
                            tuples.push((
                                Key::Shaft {
                                    angle: ai as u8,
                                    m,
                                    j,
                                    k,
                                },
                                g,
                            ));
                        });
                    }
                }
                if let Some(level) = per_cell {
                    let mut kd = first.kd;
                    for _ in 0..level {
                        let up = pv.kd[kd as usize].parent;
                        if up == u32::MAX {
                            break;
                        }
                        kd = up;
                    }
                    if let Some(spec) = imodel.boxed(&sphere, &pv.kd[kd as usize].aabb)
                        && helps(&spec)
                    {
                        tuples.push((Key::Box { kd }, g));
                    }
                } else if boxes {
                    let mut kd = first.kd;
                    while kd != u32::MAX {
                        let node = &pv.kd[kd as usize];
                        let Some(spec) = imodel.boxed(&sphere, &node.aabb) else {
                            break;
                        };
                        if helps(&spec) {
                            tuples.push((Key::Box { kd }, g));
                        }
                        kd = node.parent;
                    }
                }
            }
            // Shafts of one (angle, axis) sorted by k descending: the shaft with
            // minimum distance d_k serves every cell whose own k is ≥ k, a
            // prefix of the block. Boxes serve exactly their block.
            tuples.sort_unstable_by(|(ka, ga), (kb, gb)| match (ka, kb) {
                (
                    Key::Shaft {
                        angle: a1,
                        m: m1,
                        j: j1,
                        k: k1,
                    },
                    Key::Shaft {
                        angle: a2,
                        m: m2,
                        j: j2,
                        k: k2,
                    },
                ) => (a1, m1, j1, std::cmp::Reverse(k1), ga).cmp(&(
                    a2,
                    m2,
                    j2,
                    std::cmp::Reverse(k2),
                    gb,
                )),
                _ => (ka, ga).cmp(&(kb, gb)),
            });
            let mut cands: Vec<Candidate> = Vec::new();
            let mut served: Vec<u32> = Vec::with_capacity(tuples.len());
            let mut i = 0;
            while i < tuples.len() {
                // One block: same (angle, axis) for shafts, same kd for boxes.
                let same_block = |a: &Key, b: &Key| match (a, b) {
                    (
                        Key::Shaft {
                            angle: a1,
                            m: m1,
                            j: j1,
                            ..
                        },
                        Key::Shaft {
                            angle: a2,
                            m: m2,
                            j: j2,
                            ..
                        },
                    ) => (a1, m1, j1) == (a2, m2, j2),
                    _ => a == b,
                };
                let mut e = i;
                while e < tuples.len() && same_block(&tuples[i].0, &tuples[e].0) {
                    e += 1;
                }
                let start = served.len() as u32;
                served.extend(tuples[i..e].iter().map(|t| t.1));
                // The block's candidates: one per distinct key, serving the
                // block's prefix up to the end of its key.
                let mut ends: Vec<usize> = Vec::new();
                for t in i + 1..=e {
                    if t == e || tuples[t].0 != tuples[t - 1].0 {
                        ends.push(t);
                    }
                }
                // Shafts: the directions of the served cells' corners from
                // the cluster, eight per cell in block order, and the
                // smallest cone around each candidate's prefix.
                let (dirs, fits) = match tuples[i].0 {
                    Key::Shaft { .. } => {
                        let mut dirs: Vec<DVec3> = tuples[i..e]
                            .iter()
                            .flat_map(|&(_, g)| corner_dirs[(g - g0) as usize])
                            .collect();
                        let corner_ends: Vec<usize> = ends.iter().map(|&t| 8 * (t - i)).collect();
                        let fits = fit_cones(&mut dirs, &corner_ends);
                        (dirs, fits)
                    }
                    Key::Box { .. } => (Vec::new(), Vec::new()),
                };
                let first_in_block = cands.len();
                let mut nearest = f64::INFINITY;
                let mut grid_widest = 0.0f64;
                let mut s = i;
                for (c, &t) in ends.iter().enumerate() {
                    let served_end = start + (t - i) as u32;
                    let cand = match tuples[s].0 {
                        Key::Shaft { angle, m, j, k } => {
                            let alpha = alphas[angle as usize];
                            let grid_axis = grid.axis(m, j);
                            // The shaft starts where its nearest served
                            // cell does (never before `d_k`): the same
                            // cells are served, at the resolution and layer
                            // count their distance needs.
                            for &(_, g) in &tuples[s..t] {
                                nearest = nearest.min(pairs.group(g).dist);
                            }
                            let d = ladder_distance(size, k, steps).max(nearest);
                            // Likewise it narrows to the smallest cone
                            // around the served cells' corners (convex, so
                            // it contains the cells), measured exactly; the
                            // grid axis stands in should the fit fail.
                            let corners = &dirs[..8 * (t - i)];
                            grid_widest = grid_widest
                                .max(cone_half_angle(&dirs[8 * (s - i)..8 * (t - i)], grid_axis));
                            let (axis, widest) = fits[c]
                                .map(|a| (a, cone_half_angle(corners, a)))
                                .filter(|fit| fit.1 < grid_widest)
                                .unwrap_or((grid_axis, grid_widest));
                            let alpha = alpha.min(widest * (1.0 + 1e-9) + 1e-12);
                            imodel.shaft(&sphere, alpha, d).map(|spec| Candidate {
                                node: n,
                                cell: ViewCell::Shaft {
                                    apex: sphere.center,
                                    axis,
                                    half_angle: alpha,
                                    min_distance: d,
                                },
                                kd: u32::MAX,
                                spec,
                                served: IdRange::new(start, served_end),
                            })
                        }
                        Key::Box { kd } => {
                            let aabb: Aabb = pv.kd[kd as usize].aabb;
                            imodel.boxed(&sphere, &aabb).map(|spec| Candidate {
                                node: n,
                                cell: ViewCell::Box(aabb),
                                kd,
                                spec,
                                served: IdRange::new(start, served_end),
                            })
                        }
                    };
                    if let Some(cand) = cand {
                        // A shaft that serves a longer prefix of the block
                        // with the same layers and no more memory is at
                        // least as good in every problem view: it replaces
                        // the previous one.
                        let block_first = cands.len() > first_in_block;
                        if let (true, Some(prev)) = (block_first, cands.last())
                            && prev.kd == u32::MAX
                            && prev.spec.layers == cand.spec.layers
                            && prev.spec.memory_bytes >= cand.spec.memory_bytes
                        {
                            cands.pop();
                        }
                        cands.push(cand);
                    }
                    s = t;
                }
                i = e;
            }
            (cands, served)
        })
        .collect();
    // Moved out cluster by cluster into vectors of their final size, so
    // the candidates are not held twice.
    let mut list = Vec::with_capacity(per_node.iter().map(|p| p.0.len()).sum());
    let mut served = Vec::with_capacity(per_node.iter().map(|p| p.1.len()).sum());
    for (mut cands, local) in per_node {
        let offset = served.len() as u32;
        for c in &mut cands {
            c.served = IdRange::new(c.served.start + offset, c.served.end + offset);
        }
        list.extend(cands);
        served.extend(local);
    }
    Candidates {
        list,
        pairs,
        served,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
