//! Impostor candidate generation (paper §4, DESIGN §2.6).
//!
//! A candidate is a cluster (hierarchy node) with a view cell: a shaft around
//! the cluster centre (apex angle, axis on an angular grid, minimum distance
//! `size·2^k`) or a box of the 3D view space hierarchy. Only candidates that
//! serve at least one CPV — the CPV's region lies inside the view cell, the
//! cluster meets the CPV's enclosing frustum and its impostor is cheaper than
//! its geometry there — and whose view cell does not meet the cluster are
//! kept.
//!
//! Enumeration is output-sensitive: it starts from the (CPV, cluster) pairs
//! recorded by the problem view approximation, not from all shafts × all
//! CPVs. For one (cluster, apex angle, axis), the shaft with minimum distance
//! `d_k` serves exactly the CPVs at distance ≥ `d_k`, so only the largest
//! `d_k` below some CPV's distance is generated: a smaller one that serves
//! no additional CPV would cost more memory for the same service.

use std::f64::consts::PI;

use glam::DVec3;
use rayon::prelude::*;

use crate::geom::Aabb;
use crate::impostor_model::{ImpostorModel, ImpostorSpec, ViewCell};
use crate::job::{Job, Method};
use crate::problem_views::{Context, ProblemViews};

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
    /// The cells it serves: `Candidates::served[served.0 .. served.0 + served.1]`.
    pub served: (u32, u32),
}

/// The generated candidates, ordered by (node, key): ids are indices, and
/// the serving relation at cell granularity.
///
/// A *group* is one cell's CPVs that list one cluster: a range of `pairs`,
/// each pair a CPV id and the cluster's index in that CPV's `node_ids`. A
/// candidate serves a list of groups (`served`), all of its own cluster.
#[derive(Clone, Debug, Default)]
pub struct Candidates {
    /// The candidates.
    pub list: Vec<Candidate>,
    /// (CPV id, index of the cluster in the CPV's `node_ids`), grouped by
    /// cluster and then by cell.
    pub pairs: Vec<(u32, u32)>,
    /// Groups: ranges of `pairs`, each with its cell and distance.
    pub groups: Vec<Group>,
    /// Group ids served by the candidates (see `Candidate::served`).
    pub served: Vec<u32>,
}

/// One cell's CPVs that list one cluster.
#[derive(Clone, Copy, Debug)]
pub struct Group {
    /// The range `pairs[start..end]`.
    pub start: u32,
    /// End of the range.
    pub end: u32,
    /// The cell (kd leaf) of the CPVs.
    pub kd: u32,
    /// Distance from the cell's region to the cluster's sphere centre; all
    /// CPVs of the group share it, hence an impostor's cost there.
    pub dist: f64,
}

impl Candidates {
    /// Calls `f(cpv id, index of the cluster in the CPV's node_ids)` for every
    /// CPV candidate `i` may serve (its region lies in the view cell, it lists
    /// the cluster, and the impostor may accelerate its cell).
    pub fn for_each_served(&self, i: u32, mut f: impl FnMut(u32, u32)) {
        let (s, n) = self.list[i as usize].served;
        for &g in &self.served[s as usize..(s + n) as usize] {
            let gr = self.groups[g as usize];
            for &(c, idx) in &self.pairs[gr.start as usize..gr.end as usize] {
                f(c, idx);
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

/// Half-angle of the cone around `axis` containing the spheres seen in
/// unit directions `dirs` with angular radii `radii`.
fn cone_half_angle(dirs: &[DVec3], radii: &[f64], axis: DVec3) -> f64 {
    dirs.iter()
        .zip(radii)
        .map(|(w, r)| w.dot(axis).clamp(-1.0, 1.0).acos() + r)
        .fold(0.0, f64::max)
}

/// An axis for a narrow cone around unit directions `dirs`, from `axis`:
/// a few steps of moving it towards the farthest direction (Bădoiu and
/// Clarkson's core-set iteration on the sphere).
fn fit_cone(dirs: &[DVec3], axis: DVec3) -> DVec3 {
    let mut a = axis;
    for k in 1..=8 {
        let Some(far) = dirs
            .iter()
            .copied()
            .min_by(|x, y| x.dot(a).total_cmp(&y.dot(a)))
        else {
            break;
        };
        let next = (a + (far - a) / (f64::from(k) + 1.0)).normalize_or_zero();
        if next == DVec3::ZERO {
            break;
        }
        a = next;
    }
    a
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
    let mut alphas: Vec<f64> = job
        .candidates
        .apex_angles_deg
        .iter()
        .map(|a| (a * 0.5).to_radians().min(PI / 2.0))
        .collect();
    alphas.sort_by(f64::total_cmp);
    alphas.dedup();
    let doublings = job.candidates.min_distance_doublings;

    // Invert the (CPV → clusters) lists into (cluster → CPVs), then split
    // each cluster's list into groups of one cell (CPVs of one cell are
    // contiguous, so the groups are too).
    let mut count = vec![0u32; h.nodes.len() + 1];
    for c in &pv.cpvs {
        for &n in &c.node_ids {
            count[n as usize + 1] += 1;
        }
    }
    for i in 1..count.len() {
        count[i] += count[i - 1];
    }
    let mut pairs: Vec<(u32, u32)> = vec![(0, 0); count[h.nodes.len()] as usize];
    let mut fill = count.clone();
    for (ci, c) in pv.cpvs.iter().enumerate() {
        for (idx, &n) in c.node_ids.iter().enumerate() {
            pairs[fill[n as usize] as usize] = (ci as u32, idx as u32);
            fill[n as usize] += 1;
        }
    }
    drop(fill);
    let mut groups: Vec<Group> = Vec::new();
    let mut node_groups = vec![(0u32, 0u32); h.nodes.len()];
    for n in 0..h.nodes.len() {
        let g0 = groups.len() as u32;
        let (a, b) = (count[n] as usize, count[n + 1] as usize);
        let center = h.nodes[n].sphere.center;
        let mut s = a;
        for k in a + 1..=b {
            if k == b || pv.cpvs[pairs[k].0 as usize].kd != pv.cpvs[pairs[s].0 as usize].kd {
                let first = &pv.cpvs[pairs[s].0 as usize];
                groups.push(Group {
                    start: s as u32,
                    end: k as u32,
                    kd: first.kd,
                    dist: first.region.distance_to_point(center),
                });
                s = k;
            }
        }
        node_groups[n] = (g0, groups.len() as u32);
    }

    // Per cluster: the candidates and, for each, the local list of groups it
    // serves.
    let per_node: Vec<(Vec<Candidate>, Vec<u32>)> = (0..h.nodes.len() as u32)
        .into_par_iter()
        .map(|n| {
            let (g0, g1) = node_groups[n as usize];
            if g0 == g1 || ctx.cancelled() {
                return (Vec::new(), Vec::new());
            }
            let sphere = h.nodes[n as usize].sphere;
            let size = 2.0 * sphere.radius;
            // (key, group) for every cell inside the key's view cell.
            let mut tuples: Vec<(Key, u32)> = Vec::new();
            for g in g0..g1 {
                let gr = groups[g as usize];
                let group = &pairs[gr.start as usize..gr.end as usize];
                let first = &pv.cpvs[group[0].0 as usize];
                let region = first.region;
                let dist = gr.dist;
                // Some CPV of the cell is accelerated by an impostor of `spec`.
                let helps = |spec: &ImpostorSpec| {
                    let imp = ctx.model.impostor(spec.layers, sphere.radius, dist);
                    group.iter().any(|&(ci, idx)| {
                        let c = &pv.cpvs[ci as usize];
                        let cur = c.cost;
                        ctx.model.frame_time(cur - c.node_costs[idx as usize] + imp)
                            < ctx.model.frame_time(cur)
                    })
                };
                if shafts && size > 0.0 && dist >= size {
                    // Largest k with size·2^k ≤ dist.
                    let mut k = 0u32;
                    while k < doublings && size * f64::from(1u32 << (k + 1).min(31)) <= dist {
                        k += 1;
                    }
                    let d_k = size * f64::from(1u32 << k.min(31));
                    let corners = region.corners().map(|p| (p - sphere.center).normalize());
                    let w = (region.center() - sphere.center).normalize();
                    for (ai, &alpha) in alphas.iter().enumerate() {
                        let Some(spec) = imodel.shaft(&sphere, alpha, d_k) else {
                            continue;
                        };
                        if !helps(&spec) {
                            continue;
                        }
                        let cos = alpha.cos() - 1e-12;
                        grid.near(w, alpha, |m, j| {
                            let u = grid.axis(m, j);
                            if corners.iter().all(|c| c.dot(u) >= cos) {
                                tuples.push((
                                    Key::Shaft {
                                        angle: ai as u8,
                                        m,
                                        j,
                                        k,
                                    },
                                    g,
                                ));
                            }
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
            let mut cands = Vec::new();
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
                // Shafts: the served cells' directions and angular radii
                // from the cluster, and an axis fitted to the whole block
                // (its candidates serve prefixes of it).
                let (dirs, radii, block_axis) = match tuples[i].0 {
                    Key::Shaft { m, j, .. } => {
                        let (dirs, radii): (Vec<DVec3>, Vec<f64>) = tuples[i..e]
                            .iter()
                            .map(|&(_, g)| {
                                let b = pv.kd[groups[g as usize].kd as usize].aabb;
                                let v = b.center() - sphere.center;
                                let l = v.length();
                                let rho = (b.half_diagonal() / l).min(1.0).asin();
                                (v / l, rho)
                            })
                            .unzip();
                        let axis = fit_cone(&dirs, grid.axis(m, j));
                        (dirs, radii, axis)
                    }
                    Key::Box { .. } => (Vec::new(), Vec::new(), DVec3::ZERO),
                };
                // One candidate per distinct key of the block, serving the
                // block's prefix up to the end of its key.
                let mut s = i;
                while s < e {
                    let mut t = s;
                    while t < e && tuples[t].0 == tuples[s].0 {
                        t += 1;
                    }
                    let len = (t - i) as u32;
                    let cand = match tuples[s].0 {
                        Key::Shaft { angle, m, j, k } => {
                            let alpha = alphas[angle as usize];
                            // The shaft starts where its nearest served
                            // cell does (never before `size·2^k`): the same
                            // cells are served, at the resolution and layer
                            // count their distance needs.
                            let nearest = tuples[i..t]
                                .iter()
                                .map(|&(_, g)| groups[g as usize].dist)
                                .fold(f64::INFINITY, f64::min);
                            let d = (size * f64::from(1u32 << k.min(31))).max(nearest);
                            // Likewise it narrows, around an axis re-aimed
                            // at the served cells, to the widest angle of
                            // their corners.
                            let n_served = t - i;
                            let (axis, widest) = [grid.axis(m, j), block_axis]
                                .into_iter()
                                .map(|a| {
                                    (a, cone_half_angle(&dirs[..n_served], &radii[..n_served], a))
                                })
                                .min_by(|x, y| x.1.total_cmp(&y.1))
                                .expect("two axes");
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
                                served: (start, len),
                            })
                        }
                        Key::Box { kd } => {
                            let aabb: Aabb = pv.kd[kd as usize].aabb;
                            imodel.boxed(&sphere, &aabb).map(|spec| Candidate {
                                node: n,
                                cell: ViewCell::Box(aabb),
                                kd,
                                spec,
                                served: (start, len),
                            })
                        }
                    };
                    cands.extend(cand);
                    s = t;
                }
                i = e;
            }
            (cands, served)
        })
        .collect();
    let mut list = Vec::new();
    let mut served = Vec::new();
    for (mut cands, local) in per_node {
        let offset = served.len() as u32;
        for c in &mut cands {
            c.served.0 += offset;
        }
        list.extend(cands);
        served.extend(local);
    }
    Candidates {
        list,
        pairs,
        groups,
        served,
    }
}
