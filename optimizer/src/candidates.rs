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

use crate::cost::Cost;
use crate::geom::Aabb;
use crate::impostor_model::{ImpostorModel, ImpostorSpec, ViewCell};
use crate::job::{Job, ViewCellKind};
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
}

/// The generated candidates, ordered by (node, key): ids are indices.
#[derive(Clone, Debug, Default)]
pub struct Candidates {
    /// The candidates.
    pub list: Vec<Candidate>,
    /// (CPV, cluster) pairs examined.
    pub pairs: u64,
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
    let kinds = job.candidates.view_cells;
    let shafts = matches!(kinds, ViewCellKind::Shafts | ViewCellKind::Both);
    let boxes = matches!(kinds, ViewCellKind::Boxes | ViewCellKind::Both);
    let mut alphas: Vec<f64> = job
        .candidates
        .apex_angles_deg
        .iter()
        .map(|a| (a * 0.5).to_radians().min(PI / 2.0))
        .collect();
    alphas.sort_by(f64::total_cmp);
    alphas.dedup();
    let doublings = job.candidates.min_distance_doublings;

    // Invert the (CPV → clusters) lists into (cluster → CPVs).
    let mut count = vec![0u32; h.nodes.len() + 1];
    for c in &pv.cpvs {
        for &(n, _) in &c.nodes {
            count[n as usize + 1] += 1;
        }
    }
    for i in 1..count.len() {
        count[i] += count[i - 1];
    }
    let mut pairs: Vec<(u32, Cost)> = vec![(0, Cost::default()); count[h.nodes.len()] as usize];
    let mut fill = count.clone();
    for (ci, c) in pv.cpvs.iter().enumerate() {
        for &(n, cost) in &c.nodes {
            pairs[fill[n as usize] as usize] = (ci as u32, cost);
            fill[n as usize] += 1;
        }
    }

    let per_node: Vec<Vec<Candidate>> = (0..h.nodes.len() as u32)
        .into_par_iter()
        .map(|n| {
            let list = &pairs[count[n as usize] as usize..count[n as usize + 1] as usize];
            if list.is_empty() {
                return Vec::new();
            }
            let sphere = h.nodes[n as usize].sphere;
            let size = 2.0 * sphere.radius;
            let mut keys: Vec<Key> = Vec::new();
            for &(ci, orig) in list {
                let cpv = &pv.cpvs[ci as usize];
                let region = cpv.region;
                let helps = |spec: &ImpostorSpec, d: f64| {
                    let imp = ctx.model.impostor(spec.layers, sphere.radius, d);
                    let cur = cpv.cost;
                    ctx.model.frame_time(cur - orig + imp) < ctx.model.frame_time(cur)
                };
                let dist = region.distance_to_point(sphere.center);
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
                        if !helps(&spec, dist) {
                            continue;
                        }
                        let cos = alpha.cos() - 1e-12;
                        grid.near(w, alpha, |m, j| {
                            let u = grid.axis(m, j);
                            if corners.iter().all(|c| c.dot(u) >= cos) {
                                keys.push(Key::Shaft {
                                    angle: ai as u8,
                                    m,
                                    j,
                                    k,
                                });
                            }
                        });
                    }
                }
                if boxes {
                    let mut kd = cpv.kd;
                    while kd != u32::MAX {
                        let node = &pv.kd[kd as usize];
                        let Some(spec) = imodel.boxed(&sphere, &node.aabb) else {
                            break;
                        };
                        if helps(&spec, dist) {
                            keys.push(Key::Box { kd });
                        }
                        kd = node.parent;
                    }
                }
            }
            keys.sort_unstable();
            keys.dedup();
            keys.into_iter()
                .filter_map(|key| match key {
                    Key::Shaft { angle, m, j, k } => {
                        let alpha = alphas[angle as usize];
                        let d = size * f64::from(1u32 << k.min(31));
                        let spec = imodel.shaft(&sphere, alpha, d)?;
                        Some(Candidate {
                            node: n,
                            cell: ViewCell::Shaft {
                                apex: sphere.center,
                                axis: grid.axis(m, j),
                                half_angle: alpha,
                                min_distance: d,
                            },
                            kd: u32::MAX,
                            spec,
                        })
                    }
                    Key::Box { kd } => {
                        let aabb: Aabb = pv.kd[kd as usize].aabb;
                        let spec = imodel.boxed(&sphere, &aabb)?;
                        Some(Candidate {
                            node: n,
                            cell: ViewCell::Box(aabb),
                            kd,
                            spec,
                        })
                    }
                })
                .collect()
        })
        .collect();
    Candidates {
        list: per_node.into_iter().flatten().collect(),
        pairs: pairs.len() as u64,
    }
}

/// Calls `f(cpv id)` for every CPV whose region lies inside the candidate's
/// view cell (the CPVs it may serve), in increasing id order.
pub fn for_each_contained(pv: &ProblemViews, cand: &Candidate, mut f: impl FnMut(u32)) {
    if cand.kd != u32::MAX {
        let (s, e) = pv.kd[cand.kd as usize].cpvs;
        (s..e).for_each(f);
        return;
    }
    let mut stack = vec![0u32];
    while let Some(k) = stack.pop() {
        let node = &pv.kd[k as usize];
        if node.cpvs.0 == node.cpvs.1 || !cand.cell.may_intersect_box(&node.aabb) {
            continue;
        }
        if cand.cell.contains_box(&node.aabb) {
            (node.cpvs.0..node.cpvs.1).for_each(&mut f);
            continue;
        }
        if let Some([l, r]) = node.children {
            stack.push(r);
            stack.push(l);
        }
    }
}
