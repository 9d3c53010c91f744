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

use glam::DVec3;
use rayon::prelude::*;

use crate::api::job::{Job, Method};
use crate::math::IdRange;
use crate::math::geom::Aabb;
use crate::model::cost::Cost;
use crate::model::impostor::{ImpostorModel, ImpostorSpec, ViewCell};
use crate::scene::hierarchy::Hierarchy;
use crate::views::{Context, ProblemViews};

mod pairs;
mod served;
mod shaft;
pub use pairs::{Group, Pairs};
pub use served::{NARROW_GROUPS, Served, ServedIds};
pub use shaft::AxisGrid;
use shaft::{
    cone_half_angle, distinct_corners, fit_cones, half_angles, ladder_distance, ladder_index,
    min_cos,
};

/// One impostor candidate. Its view cell is held in what the cluster and
/// the view space hierarchy do not give (see [`Candidate::cell`]): there
/// are millions of candidates on the large cities.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// The cluster (hierarchy node id).
    pub node: u32,
    /// For box cells, the kd node of the 3D view space hierarchy (the box
    /// is its bounds); else `u32::MAX`.
    pub kd: u32,
    /// For shaft cells, the shaft but for its apex, the cluster's centre.
    shaft: Shaft,
    /// Layers, resolution, memory.
    pub spec: ImpostorSpec,
    /// The groups it serves: `Candidates::served[served.start..served.end]`.
    pub served: IdRange,
}

/// A shaft view cell but for its apex (see [`ViewCell::Shaft`]).
#[derive(Clone, Copy, Debug, Default)]
struct Shaft {
    axis: DVec3,
    half_angle: f64,
    min_distance: f64,
}

const _: () = assert!(std::mem::size_of::<Candidate>() == 72);

impl Candidate {
    /// Its view cell: a shaft from the centre of its cluster's sphere in
    /// `h`, or the bounds of its kd node in `pv`.
    pub fn cell(&self, h: &Hierarchy, pv: &ProblemViews) -> ViewCell {
        if self.kd == u32::MAX {
            ViewCell::Shaft {
                apex: h.nodes[self.node as usize].sphere.center,
                axis: self.shaft.axis,
                half_angle: self.shaft.half_angle,
                min_distance: self.shaft.min_distance,
            }
        } else {
            ViewCell::Box(pv.kd[self.kd as usize].aabb)
        }
    }
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
    /// The groups served by the candidates (see `Candidate::served`).
    pub served: Served,
}

impl Candidates {
    /// Calls `f(cpv id, cost)` for every CPV candidate `i` may serve (its
    /// region lies in the view cell, it lists the cluster, and the impostor
    /// may accelerate its cell), with the cost of the cluster's objects in
    /// the CPV's enclosing set.
    pub fn for_each_served(&self, i: u32, mut f: impl FnMut(u32, Cost)) {
        for g in self.groups_served(i) {
            for (c, cost) in self.pairs.iter(&self.pairs.group(g)) {
                f(c, cost);
            }
        }
    }

    /// The group ids candidate `i` serves.
    #[inline]
    pub fn groups_served(&self, i: u32) -> ServedIds<'_> {
        let c = &self.list[i as usize];
        self.served_range(c.node, c.served.indices())
    }

    /// The group ids of served entries `range`, which belong to candidates
    /// of cluster `node`.
    #[inline]
    pub fn served_range(&self, node: u32, range: std::ops::Range<usize>) -> ServedIds<'_> {
        self.served.ids(self.pairs.groups_of(node).start, range)
    }
}

/// An estimate of the served-list entries candidate generation will make,
/// for predicting memory before candidates exist: the CPVs' groups times the
/// mean number of candidate blocks (a shaft angle and axis, or a box) whose
/// view cell holds the cell of a sampled group. The groups are those listed
/// by the first CPV of up to 32 cells spread over the CPVs; a block is
/// counted whether or not its impostor would help there, so the estimate
/// leans high.
pub fn estimate_served(ctx: &Context, job: &Job, pv: &ProblemViews) -> u64 {
    let groups = crate::views::PairCounts::totals(&pv.node_counts).cells;
    if groups == 0 {
        return 0;
    }
    let method = job.method();
    let (shafts, boxes) = (method.builds_shafts(), method.builds_boxes());
    let alphas = half_angles(job);
    let grids: Vec<AxisGrid> = alphas.iter().map(|&a| AxisGrid::new(job, a)).collect();
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
                for (&alpha, grid) in alphas.iter().zip(&grids) {
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

/// A candidate key, deduplicated per node: a shaft's angle, grid axis
/// (its index in the angle's [`AxisGrid`]) and distance step, or a box's
/// kd node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Key {
    Shaft { angle: u8, axis: u32, k: u32 },
    Box { kd: u32 },
}

/// A (key, served group) of one cluster packed so that integer order is
/// block order: shafts by angle, axis, distance step descending (the shaft
/// with the smallest distance step serves a prefix of its block), then
/// group; boxes after them by kd node, then group. Every field keeps its
/// full width (105 bits).
fn pack(key: Key, g: u32) -> u128 {
    match key {
        Key::Shaft { angle, axis, k } => {
            u128::from(angle) << 96
                | u128::from(axis) << 64
                | u128::from(u32::MAX - k) << 32
                | u128::from(g)
        }
        Key::Box { kd } => 1 << 104 | u128::from(kd) << 64 | u128::from(g),
    }
}

/// The inverse of [`pack`].
fn unpack(p: u128) -> (Key, u32) {
    let g = p as u32;
    let key = if p >> 104 == 0 {
        Key::Shaft {
            angle: (p >> 96) as u8,
            axis: (p >> 64) as u32,
            k: u32::MAX - (p >> 32) as u32,
        }
    } else {
        Key::Box {
            kd: (p >> 64) as u32,
        }
    };
    (key, g)
}

/// Generates the candidates for the CPVs of `pv`.
pub fn generate(ctx: &Context, job: &Job, pv: &ProblemViews) -> Candidates {
    let h = ctx.hierarchy;
    let imodel = ImpostorModel::new(job);
    let method = job.method();
    let (shafts, boxes) = (method.builds_shafts(), method.builds_boxes());
    // Per-cell: one box size only, the cells' ancestors `level` levels up.
    let per_cell = (method == Method::PerCell).then_some(job.per_cell.level);
    let alphas = half_angles(job);
    let grids: Vec<AxisGrid> = alphas.iter().map(|&a| AxisGrid::new(job, a)).collect();
    let (steps, last_k) = ladder(job);

    // The (cluster → CPVs) pairs, grouped by cell.
    let pairs = Pairs::collect(ctx, pv);
    if ctx.cancelled() {
        return Candidates::default();
    }

    // The distinct corners of the cells' regions (all CPVs of a cell share
    // its region), found once for every cluster, and per kd node its
    // cell's eight.
    let cells = pv.cells();
    let (points, cell_corners) =
        distinct_corners(cells.iter().map(|r| pv.cpvs[r.start as usize].region));
    let mut corners_of_kd = vec![[0u32; 8]; pv.kd.len()];
    for (r, ids) in cells.iter().zip(cell_corners) {
        corners_of_kd[pv.cpvs[r.start as usize].kd as usize] = ids;
    }

    // Per cluster: the candidates and, for each, the local list of groups it
    // serves (as offsets from the cluster's first group).
    let per_node: Vec<(Vec<Candidate>, Vec<u32>)> = (0..h.nodes.len() as u32)
        .into_par_iter()
        .map_init(
            || {
                (
                    vec![0u32; points.len()],
                    vec![DVec3::ZERO; points.len()],
                    vec![0u64; points.len()],
                    0u64,
                )
            },
            |(dir_of, dirs_at, seen, block_no), n| {
                let IdRange { start: g0, end: g1 } = pairs.groups_of(n);
                if g0 == g1 || ctx.cancelled() {
                    return (Vec::new(), Vec::new());
                }
                let sphere = h.nodes[n as usize].sphere;
                // The direction of corner `id` from the cluster, computed once
                // per cluster (`dir_of[id]`: the cluster it was computed for,
                // plus one).
                let mut corner_dir = |id: u32| {
                    let id = id as usize;
                    if dir_of[id] != n + 1 {
                        dir_of[id] = n + 1;
                        dirs_at[id] = (points[id] - sphere.center).normalize();
                    }
                    dirs_at[id]
                };
                let size = 2.0 * sphere.radius;
                // (key, group) for every cell inside the key's view cell,
                // packed ([`pack`]).
                let mut packed: Vec<u128> = Vec::new();
                let mut grid_specs: Vec<Option<Option<ImpostorSpec>>> =
                    vec![None; alphas.len() * (last_k as usize + 1)];
                for g in g0..g1 {
                    let gr = &pairs.group(g);
                    let first = &pv.cpvs[pairs.first_cpv(gr) as usize];
                    let region = first.region;
                    let dist = pairs.dist(gr, sphere.center);
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
                        let corners = corners_of_kd[gr.kd as usize].map(&mut corner_dir);
                        let corners = &corners;
                        let w = (region.center() - sphere.center).normalize();
                        for (ai, &alpha) in alphas.iter().enumerate() {
                            // The grid shaft's impostor, once per cluster, angle
                            // and distance step.
                            let slot = &mut grid_specs[ai * (last_k as usize + 1) + k as usize];
                            let Some(spec) =
                                *slot.get_or_insert_with(|| imodel.shaft(&sphere, alpha, d_k))
                            else {
                                continue;
                            };
                            if !helps(&spec) {
                                continue;
                            }
                            let grid = &grids[ai];
                            grid.holding(w, alpha, corners, |m, j| {
                                let key = Key::Shaft {
                                    angle: ai as u8,
                                    axis: grid.index(m, j),
                                    k,
                                };
                                packed.push(pack(key, g));
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
                            packed.push(pack(Key::Box { kd }, g));
                        }
                    } else if boxes {
                        let mut kd = first.kd;
                        while kd != u32::MAX {
                            let node = &pv.kd[kd as usize];
                            let Some(spec) = imodel.boxed(&sphere, &node.aabb) else {
                                break;
                            };
                            if helps(&spec) {
                                packed.push(pack(Key::Box { kd }, g));
                            }
                            kd = node.parent;
                        }
                    }
                }
                // In block order (see [`pack`]).
                packed.sort_unstable();
                let tuples: Vec<(Key, u32)> = packed.into_iter().map(unpack).collect();
                let mut cands: Vec<Candidate> = Vec::new();
                let mut served: Vec<u32> = Vec::with_capacity(tuples.len());
                let mut i = 0;
                while i < tuples.len() {
                    // One block: same (angle, axis) for shafts, same kd for boxes.
                    let same_block = |a: &Key, b: &Key| match (a, b) {
                        (
                            Key::Shaft {
                                angle: a1,
                                axis: x1,
                                ..
                            },
                            Key::Shaft {
                                angle: a2,
                                axis: x2,
                                ..
                            },
                        ) => (a1, x1) == (a2, x2),
                        _ => a == b,
                    };
                    let mut e = i;
                    while e < tuples.len() && same_block(&tuples[i].0, &tuples[e].0) {
                        e += 1;
                    }
                    let start = served.len() as u32;
                    served.extend(tuples[i..e].iter().map(|t| t.1 - g0));
                    // The block's candidates: one per distinct key, serving the
                    // block's prefix up to the end of its key.
                    let mut ends: Vec<usize> = Vec::new();
                    for t in i + 1..=e {
                        if t == e || tuples[t].0 != tuples[t - 1].0 {
                            ends.push(t);
                        }
                    }
                    // Shafts: the directions of the served cells' corners from
                    // the cluster in block order, each distinct corner where it
                    // first appears (so every prefix of cells has its corners in
                    // a prefix), and the smallest cone around each candidate's.
                    // `corner_end[t - i]`: the corners of the first `t - i` cells.
                    let (dirs, corner_end, fits) = match tuples[i].0 {
                        Key::Shaft { .. } => {
                            *block_no += 1;
                            let mut dirs: Vec<DVec3> = Vec::with_capacity(8 * (e - i));
                            let mut corner_end = Vec::with_capacity(e - i + 1);
                            corner_end.push(0);
                            for &(_, g) in &tuples[i..e] {
                                for id in corners_of_kd[pairs.group(g).kd as usize] {
                                    if seen[id as usize] != *block_no {
                                        seen[id as usize] = *block_no;
                                        dirs.push(corner_dir(id));
                                    }
                                }
                                corner_end.push(dirs.len());
                            }
                            let prefix_ends: Vec<usize> =
                                ends.iter().map(|&t| corner_end[t - i]).collect();
                            let fits = fit_cones(&mut dirs, &prefix_ends);
                            (dirs, corner_end, fits)
                        }
                        Key::Box { .. } => (Vec::new(), Vec::new(), Vec::new()),
                    };
                    // The last fitted axis and the smallest cosine of its prefix's
                    // corners to it: a prefix whose fit keeps the axis is measured
                    // on its new corners only.
                    let mut measured: Option<(DVec3, usize, f64)> = None;
                    let first_in_block = cands.len();
                    let mut nearest = f64::INFINITY;
                    let mut grid_widest = 0.0f64;
                    let mut s = i;
                    for (c, &t) in ends.iter().enumerate() {
                        let served_end = start + (t - i) as u32;
                        let cand = match tuples[s].0 {
                            Key::Shaft { angle, axis, k } => {
                                let alpha = alphas[angle as usize];
                                let grid_axis = grids[angle as usize].axis_at(axis);
                                // The shaft starts where its nearest served
                                // cell does (never before `d_k`): the same
                                // cells are served, at the resolution and layer
                                // count their distance needs.
                                for &(_, g) in &tuples[s..t] {
                                    nearest =
                                        nearest.min(pairs.dist(&pairs.group(g), sphere.center));
                                }
                                let d = ladder_distance(size, k, steps).max(nearest);
                                // Likewise it narrows to the smallest cone
                                // around the served cells' corners (convex, so
                                // it contains the cells), measured exactly; the
                                // grid axis stands in should the fit fail.
                                let (from, to) = (corner_end[s - i], corner_end[t - i]);
                                grid_widest =
                                    grid_widest.max(cone_half_angle(&dirs[from..to], grid_axis));
                                let (axis, widest) = fits[c]
                                    .map(|a| {
                                        let min_cos = match measured {
                                            Some((b, len, m)) if b == a => {
                                                min_cos(&dirs[len..to], a).min(m)
                                            }
                                            _ => min_cos(&dirs[..to], a),
                                        };
                                        measured = Some((a, to, min_cos));
                                        (a, min_cos.clamp(-1.0, 1.0).acos())
                                    })
                                    .filter(|fit| fit.1 < grid_widest)
                                    .unwrap_or((grid_axis, grid_widest));
                                let alpha = alpha.min(widest * (1.0 + 1e-9) + 1e-12);
                                imodel.shaft(&sphere, alpha, d).map(|spec| Candidate {
                                    node: n,
                                    shaft: Shaft {
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
                                    shaft: Shaft::default(),
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
                // Each cluster's list is kept until all are joined: without
                // the room its doubling left.
                cands.shrink_to_fit();
                (cands, served)
            },
        )
        .collect();
    // Moved out cluster by cluster into vectors of their final size, so
    // the candidates are not held twice.
    let mut list = Vec::with_capacity(per_node.iter().map(|p| p.0.len()).sum());
    let total = per_node.iter().map(|p| p.1.len()).sum();
    let mut offset = 0u32;
    let mut locals = Vec::with_capacity(per_node.len());
    for (mut cands, local) in per_node {
        for c in &mut cands {
            c.served = IdRange::new(c.served.start + offset, c.served.end + offset);
        }
        offset += local.len() as u32;
        list.extend(cands);
        locals.push(local);
    }
    let widest = (0..h.nodes.len() as u32)
        .map(|n| pairs.groups_of(n).len())
        .max()
        .unwrap_or(0);
    let served = Served::new(locals, total, widest);
    Candidates {
        list,
        pairs,
        served,
    }
}

/// The minimum-distance ladder of `job`'s shafts: distances per doubling
/// and the last ladder index.
fn ladder(job: &Job) -> (u32, u32) {
    let steps = job.candidates.min_distance_steps.max(1);
    (
        steps,
        job.candidates.min_distance_doublings.saturating_mul(steps),
    )
}

/// What view cells a cluster can have from a cell, judged on the smallest
/// the generator builds for it there (the narrowest shaft at the cell's
/// distance step; the cell's own box): see [`outlook`].
/// The discriminants index per-outlook tallies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outlook {
    /// No view cell can hold the cell: the cluster's sphere is nearer than
    /// its diameter (shafts) and meets the cell (boxes).
    TooClose = 0,
    /// A view cell can hold the cell, but no impostor of the cluster keeps
    /// the parallax within `max_error_px` (layer cap, texture size).
    OverErrorBudget = 1,
    /// An impostor exists.
    Possible = 2,
}

/// The [`Outlook`] of the cluster of bounding sphere `sphere` from the cell
/// `region`, at `dist` from its centre, for `job`'s method.
pub fn outlook(
    job: &Job,
    imodel: &ImpostorModel,
    sphere: &crate::math::geom::Sphere,
    region: &Aabb,
    dist: f64,
) -> Outlook {
    let method = job.method();
    let (shafts, boxes) = (method.builds_shafts(), method.builds_boxes());
    let size = 2.0 * sphere.radius;
    let shaft_fits = shafts && size > 0.0 && dist >= size;
    let box_fits = boxes && region.distance_to_point(sphere.center) > sphere.radius;
    if !shaft_fits && !box_fits {
        return Outlook::TooClose;
    }
    let shaft = || {
        let (steps, last_k) = ladder(job);
        let k = ladder_index(size, dist, steps, last_k);
        let alpha = half_angles(job).first().copied()?;
        imodel.shaft(sphere, alpha, ladder_distance(size, k, steps))
    };
    let possible =
        (box_fits && imodel.boxed(sphere, region).is_some()) || (shaft_fits && shaft().is_some());
    if possible {
        Outlook::Possible
    } else {
        Outlook::OverErrorBudget
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::geom::Sphere;
    use crate::testutil::synthetic_job;

    /// Packed keys sort in block order: shafts by (angle, axis), distance
    /// step descending, then group; boxes after every shaft, by kd node
    /// then group; and unpack gives back what was packed, fields at their
    /// extremes included.
    #[test]
    fn packed_keys_sort_in_block_order_and_round_trip() {
        let shaft = |angle, axis, k| Key::Shaft { angle, axis, k };
        let order = [
            (shaft(0, 0, u32::MAX), 0),
            (shaft(0, 0, 5), 0),
            (shaft(0, 0, 5), 7),
            (shaft(0, 0, 0), u32::MAX),
            (shaft(0, 1, 9), 0),
            (shaft(0, u32::MAX, 3), 2),
            (shaft(1, 0, 3), 1),
            (shaft(u8::MAX, 0, 0), 0),
            (Key::Box { kd: 0 }, 5),
            (Key::Box { kd: 3 }, 0),
            (Key::Box { kd: u32::MAX }, u32::MAX),
        ];
        let packed: Vec<u128> = order.iter().map(|&(k, g)| pack(k, g)).collect();
        assert!(packed.windows(2).all(|w| w[0] < w[1]));
        for (&p, &t) in packed.iter().zip(&order) {
            assert_eq!(unpack(p), t);
        }
    }

    /// The outlook names what stops an impostor: a cell the cluster
    /// reaches into, an error budget no texture can meet, or nothing.
    #[test]
    fn outlook_names_what_stops_an_impostor() {
        let mut job = synthetic_job(5, 5);
        job.candidates.view_cells = crate::api::job::ViewCellKind::Both;
        let sphere = Sphere {
            center: DVec3::ZERO,
            radius: 10.0,
        };
        let cell = |x: f64| Aabb::new(DVec3::new(x, -2.0, -2.0), DVec3::new(x + 4.0, 2.0, 2.0));
        let look = |job: &Job, x: f64| {
            let region = cell(x);
            let dist = region.distance_to_point(sphere.center);
            outlook(job, &ImpostorModel::new(job), &sphere, &region, dist)
        };
        // 5 m from the centre: inside the sphere, no shaft, no box.
        assert_eq!(look(&job, 5.0), Outlook::TooClose);
        assert_eq!(look(&job, 200.0), Outlook::Possible);
        // 15 m: outside the sphere but nearer than its diameter: a box
        // could hold the cell, a shaft could not.
        assert_ne!(look(&job, 15.0), Outlook::TooClose);
        job.candidates.view_cells = crate::api::job::ViewCellKind::Shafts;
        assert_eq!(look(&job, 15.0), Outlook::TooClose);
        assert_eq!(look(&job, 200.0), Outlook::Possible);
        job.candidates.view_cells = crate::api::job::ViewCellKind::Boxes;
        assert_eq!(look(&job, 60.0), Outlook::Possible);
        // No texture of 4 texels a side keeps 1 px.
        job.memory.max_texture_size = 4;
        assert_eq!(look(&job, 200.0), Outlook::OverErrorBudget);
    }
}
