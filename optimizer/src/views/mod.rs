//! Problem view space approximation (paper §3, DESIGN §2.4).
//!
//! The 3D view space is a grid of cells no larger than `cell_size`, organised
//! as a binary kd tree that splits the axis with the most cells at its middle
//! cell boundary. Each kd region runs a direction subdivision: six cube faces,
//! each a quadtree of view-direction intervals (VDIs) split uniformly in
//! angle down to `min_vdi_deg`. A (region, VDI) whose enclosing-frustum time
//! `t_enc` is within `t_max` is proven; otherwise the VDI is split, and at the
//! minimum VDI size the region is split. A problem VDI of a minimum-size
//! region is a conservative problem view (CPV). Regions are processed in
//! parallel; results are collected in kd order, so the output does not depend
//! on the thread count.

use crate::model::cost::{Cost, CostModel};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering as AtomicOrdering};

use crate::api::job::Job;
use crate::math::geom::{Aabb, Cone, Vdi, enclosing_cone, frustum_half_diagonal};
use crate::math::grid::Grid;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;
use crate::visibility::{ObjectSet, Visibility};

/// A node of the 3D view space hierarchy (pre-order ids, root 0).
#[derive(Clone, Debug)]
pub struct KdNode {
    /// First cell per axis.
    pub lo: [u32; 3],
    /// One past the last cell per axis.
    pub hi: [u32; 3],
    /// The region.
    pub aabb: Aabb,
    /// Children, `None` for a single cell.
    pub children: Option<[u32; 2]>,
    /// Parent (`u32::MAX` for the root).
    pub parent: u32,
    /// The CPVs inside this region: ids `cpvs.0 .. cpvs.1`.
    pub cpvs: (u32, u32),
}

/// A conservative problem view: a minimum-size region and a minimum-size VDI
/// whose enclosing-frustum time exceeds `t_max`.
#[derive(Clone, Debug)]
pub struct Cpv {
    /// The kd leaf (cell) of the region.
    pub kd: u32,
    /// The 3D region.
    pub region: Aabb,
    /// The view-direction interval.
    pub vdi: Vdi,
    /// Cost of the objects in the enclosing frustum.
    pub cost: Cost,
    /// Estimated frame time `t_enc`, ms.
    pub time: f64,
    /// The clusters that may become impostors here, sorted by node id: they
    /// meet the enclosing frustum, do not meet the region, and a one-layer
    /// impostor of them would be cheaper than their objects in the frustum.
    pub node_ids: Vec<u32>,
    /// For each of `node_ids`, the cost of the cluster's objects inside the
    /// enclosing frustum.
    pub node_costs: Vec<Cost>,
}

impl Cpv {
    /// Index of cluster `node` in `node_ids`, if it may be replaced here.
    pub fn node_index(&self, node: u32) -> Option<usize> {
        self.node_ids.binary_search(&node).ok()
    }

    /// Original cost of cluster `node`'s objects in this CPV, if it may be
    /// replaced here.
    pub fn node_cost(&self, node: u32) -> Option<Cost> {
        self.node_index(node).map(|i| self.node_costs[i])
    }
}

/// The result of the approximation.
#[derive(Clone, Debug)]
pub struct ProblemViews {
    /// The cell grid.
    pub grid: Grid,
    /// The 3D view space hierarchy.
    pub kd: Vec<KdNode>,
    /// The CPVs, in kd order (each kd node's CPVs are contiguous).
    pub cpvs: Vec<Cpv>,
    /// Quadtree level of minimum-size VDIs.
    pub leaf_level: u8,
    /// Enclosing frusta evaluated (a work counter for statistics).
    pub cone_evaluations: u64,
    /// kd regions visited.
    pub regions_visited: u64,
}

/// Quadtree level whose VDIs span at most `min_vdi_deg` (a face spans 90°).
pub fn leaf_level(min_vdi_deg: f64) -> u8 {
    let mut l = 0u8;
    while 90.0 / f64::from(1u32 << l) > min_vdi_deg * (1.0 + 1e-9) {
        l += 1;
    }
    l
}

/// Everything the per-region work needs, shared read-only across threads.
pub struct Context<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The object hierarchy.
    pub hierarchy: &'a Hierarchy,
    /// The cost model.
    pub model: CostModel,
    /// `t_max`, ms.
    pub t_max: f64,
    /// Frustum diagonal half-angle, radians.
    pub half_diagonal: f64,
    /// Pitch range, radians.
    pub pitch: [f64; 2],
    /// (CPV, cluster) pairs recorded so far; the approximation stops early
    /// once it exceeds `pair_budget`.
    pub pairs: AtomicU64,
    /// The most (CPV, cluster) pairs a run may hold (see [`MAX_PAIRS`]).
    pub pair_budget: u64,
    /// When set to true, the approximation and candidate generation stop
    /// early (the caller reports the cancellation).
    pub cancel: Option<&'a AtomicBool>,
    /// From-region visibility: regions count only their potentially
    /// visible objects.
    pub visibility: Option<&'a Visibility<'a>>,
    /// Per level of detail, how often it was chosen for a (region, object)
    /// pair; the last slot counts objects too small to be drawn.
    pub lod_levels: Vec<AtomicU64>,
}

/// The default budget of (CPV, cluster) pairs. Every pair costs about 50
/// bytes through candidate generation and the greedy, so 300 M pairs need
/// about 15 GB; a job beyond it is refused instead of exhausting memory.
pub const MAX_PAIRS: u64 = 300_000_000;

/// Bytes held per (CPV, cluster) pair from the approximation to the greedy.
pub const BYTES_PER_PAIR: u64 = 49;

impl<'a> Context<'a> {
    /// The context of a job.
    pub fn new(scene: &'a Scene, hierarchy: &'a Hierarchy, job: &Job) -> Self {
        let [w, h] = job.camera.resolution;
        Context {
            scene,
            hierarchy,
            model: CostModel::new(job),
            t_max: job.target_frame_time_ms,
            half_diagonal: frustum_half_diagonal(job.camera.fov_deg, f64::from(w) / f64::from(h)),
            pitch: job.view_space.pitch_deg.map(f64::to_radians),
            pairs: AtomicU64::new(0),
            pair_budget: MAX_PAIRS,
            cancel: None,
            visibility: None,
            lod_levels: (0..=crate::scene::MAX_LODS)
                .map(|_| AtomicU64::new(0))
                .collect(),
        }
    }

    /// Level-of-detail counters (`None` when no object has levels).
    pub fn lod_stats(
        &self,
        generated: Option<crate::api::stats::LodReport>,
    ) -> Option<crate::api::stats::LodStats> {
        let with = self
            .scene
            .objects
            .iter()
            .filter(|o| !o.lods.is_empty())
            .count();
        if with == 0 && generated.is_none() {
            return None;
        }
        let levels = self
            .scene
            .objects
            .iter()
            .map(|o| o.lods.len())
            .max()
            .unwrap_or(0);
        let mut chosen: Vec<u64> = self.lod_levels[..levels]
            .iter()
            .map(|a| a.load(AtomicOrdering::Relaxed))
            .collect();
        chosen.push(self.lod_levels[crate::scene::MAX_LODS].load(AtomicOrdering::Relaxed));
        Some(crate::api::stats::LodStats {
            objects_with_lods: with as u64,
            chosen_levels: chosen,
            generated,
        })
    }

    /// True once the recorded pairs exceed the budget.
    pub fn over_budget(&self) -> bool {
        self.pairs.load(AtomicOrdering::Relaxed) > self.pair_budget
    }

    /// True once the run was cancelled.
    pub fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(AtomicOrdering::Relaxed))
    }

    /// True when some direction of `vdi` lies in the pitch range.
    pub fn pitch_overlaps(&self, vdi: &Vdi) -> bool {
        let [lo, hi] = vdi.elevation_range();
        hi >= self.pitch[0] - 1e-12 && lo <= self.pitch[1] + 1e-12
    }
}

/// Per-region costs: every object's cost seen from the region's closest point
/// and every cluster's sum. Objects outside the region's potentially visible
/// set cost nothing.
pub struct RegionCosts {
    /// Per object id.
    pub objects: Vec<Cost>,
    /// Per node id.
    pub nodes: Vec<Cost>,
}

impl RegionCosts {
    /// Costs for `region`, counting only the objects of `visible` (all when
    /// `None`).
    pub fn new(ctx: &Context, region: &Aabb, visible: Option<&ObjectSet>) -> RegionCosts {
        let objects: Vec<Cost> = ctx
            .scene
            .objects
            .iter()
            .zip(&ctx.hierarchy.object_spheres)
            .enumerate()
            .map(|(id, (o, s))| {
                if visible.is_some_and(|v| !v.contains(id as u32)) {
                    return Cost::default();
                }
                let d = region.distance_to_point(s.center);
                if !o.lods.is_empty() {
                    let slot = ctx
                        .model
                        .lod_level(o, s.radius, d)
                        .unwrap_or(crate::scene::MAX_LODS);
                    ctx.lod_levels[slot].fetch_add(1, AtomicOrdering::Relaxed);
                }
                ctx.model.object_region(o, s.radius, d)
            })
            .collect();
        let h = ctx.hierarchy;
        let mut nodes = vec![Cost::default(); h.nodes.len()];
        for id in (0..h.nodes.len()).rev() {
            nodes[id] = match h.nodes[id].children {
                None => h
                    .objects(id as u32)
                    .iter()
                    .fold(Cost::default(), |acc, &o| acc + objects[o as usize]),
                Some([l, r]) => nodes[l as usize] + nodes[r as usize],
            };
        }
        RegionCosts { objects, nodes }
    }
}

/// Cost of all objects whose bounding sphere meets `cone`. When `emit` is
/// given, also lists every cluster meeting the cone whose sphere does not meet
/// `region`, with the cost of its objects inside the cone.
pub fn enclosed_cost(
    ctx: &Context,
    costs: &RegionCosts,
    cone: &Cone,
    region: &Aabb,
    mut emit: Option<&mut Vec<(u32, Cost)>>,
) -> Cost {
    fn visit(
        ctx: &Context,
        costs: &RegionCosts,
        cone: &Cone,
        region: &Aabb,
        n: u32,
        emit: &mut Option<&mut Vec<(u32, Cost)>>,
    ) -> Cost {
        let h = ctx.hierarchy;
        let node = &h.nodes[n as usize];
        let s = node.sphere;
        if !cone.intersects_sphere(s.center, s.radius) {
            return Cost::default();
        }
        let replaceable = |m: u32| {
            let s = h.nodes[m as usize].sphere;
            !region.intersects_sphere(s.center, s.radius)
        };
        if cone.contains_sphere(s.center, s.radius) {
            if let Some(out) = emit.as_deref_mut() {
                for m in n..node.subtree_end {
                    let c = costs.nodes[m as usize];
                    if (c.cpu > 0.0 || c.gpu > 0.0) && replaceable(m) {
                        out.push((m, costs.nodes[m as usize]));
                    }
                }
            }
            return costs.nodes[n as usize];
        }
        let c = match node.children {
            None => {
                let mut c = Cost::default();
                for &o in h.objects(n) {
                    let os = &h.object_spheres[o as usize];
                    if cone.intersects_sphere(os.center, os.radius) {
                        c += costs.objects[o as usize];
                    }
                }
                c
            }
            Some([l, r]) => {
                visit(ctx, costs, cone, region, l, emit) + visit(ctx, costs, cone, region, r, emit)
            }
        };
        if let Some(out) = emit.as_deref_mut()
            && (c.cpu > 0.0 || c.gpu > 0.0)
            && replaceable(n)
        {
            out.push((n, c));
        }
        c
    }
    visit(ctx, costs, cone, region, 0, &mut emit)
}

/// Builds the kd tree over the grid (pre-order).
fn build_kd(grid: &Grid) -> Vec<KdNode> {
    let mut kd = Vec::new();
    let mut stack = vec![([0u32; 3], grid.counts, u32::MAX)];
    while let Some((lo, hi, parent)) = stack.pop() {
        let id = kd.len() as u32;
        if parent != u32::MAX {
            let p: &mut KdNode = &mut kd[parent as usize];
            match &mut p.children {
                None => p.children = Some([id, u32::MAX]),
                Some(c) => c[1] = id,
            }
        }
        let sizes = [0, 1, 2].map(|a| hi[a] - lo[a]);
        let axis = if sizes[0] >= sizes[1] && sizes[0] >= sizes[2] {
            0
        } else if sizes[1] >= sizes[2] {
            1
        } else {
            2
        };
        if sizes[axis] > 1 {
            let mid = lo[axis] + sizes[axis] / 2;
            let (mut hi_l, mut lo_r) = (hi, lo);
            hi_l[axis] = mid;
            lo_r[axis] = mid;
            stack.push((lo_r, hi, id));
            stack.push((lo, hi_l, id));
        }
        kd.push(KdNode {
            lo,
            hi,
            aabb: grid.cell_box(lo, hi),
            children: None,
            parent,
            cpvs: (0, 0),
        });
    }
    kd
}

/// Sorted list of every quadtree ancestor (including itself) of the given
/// leaves, for "does this VDI contain a parent problem" queries.
fn ancestors(leaves: &[Vdi]) -> Vec<Vdi> {
    let mut out = Vec::with_capacity(leaves.len() * 4);
    for l in leaves {
        for up in 0..=l.level {
            out.push(Vdi {
                face: l.face,
                level: l.level - up,
                iu: l.iu >> up,
                iv: l.iv >> up,
            });
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

struct RegionResult {
    cpvs: Vec<Cpv>,
    cones: u64,
    regions: u64,
}

fn process(
    ctx: &Context,
    kd: &[KdNode],
    id: u32,
    parent_problems: &[Vdi],
    leaf_level: u8,
) -> RegionResult {
    let node = &kd[id as usize];
    if ctx.over_budget() || ctx.cancelled() {
        return RegionResult {
            cpvs: Vec::new(),
            cones: 0,
            regions: 0,
        };
    }
    let region = node.aabb;
    let visible = ctx.visibility.and_then(|v| v.region(node.lo, node.hi));
    let costs = RegionCosts::new(ctx, &region, visible.as_deref());
    let open = ancestors(parent_problems);
    let mut problems: Vec<(Vdi, f64)> = Vec::new();
    let mut cones = 0u64;
    let mut stack: Vec<Vdi> = (0..6u8).rev().map(Vdi::face).collect();
    while let Some(vdi) = stack.pop() {
        if open.binary_search(&vdi).is_err() || !ctx.pitch_overlaps(&vdi) {
            continue;
        }
        let cone = enclosing_cone(&region, &vdi, ctx.half_diagonal);
        cones += 1;
        let t = ctx
            .model
            .frame_time(enclosed_cost(ctx, &costs, &cone, &region, None));
        if t <= ctx.t_max {
            continue;
        }
        if vdi.level == leaf_level {
            problems.push((vdi, t));
        } else {
            stack.extend(vdi.children().into_iter().rev());
        }
    }
    if problems.is_empty() {
        return RegionResult {
            cpvs: Vec::new(),
            cones,
            regions: 1,
        };
    }
    match node.children {
        None => {
            let cpvs = problems
                .into_iter()
                .map(|(vdi, _)| {
                    let cone = enclosing_cone(&region, &vdi, ctx.half_diagonal);
                    let mut nodes = Vec::new();
                    let cost = enclosed_cost(ctx, &costs, &cone, &region, Some(&mut nodes));
                    let t = ctx.model.frame_time(cost);
                    let h = ctx.hierarchy;
                    // Keep the clusters some impostor could accelerate: an
                    // impostor has at least one layer.
                    nodes.retain(|&(n, orig)| {
                        let s = h.nodes[n as usize].sphere;
                        let imp =
                            ctx.model
                                .impostor(1, s.radius, region.distance_to_point(s.center));
                        ctx.model.frame_time(cost - orig + imp) < t
                    });
                    nodes.sort_unstable_by_key(|&(n, _)| n);
                    Cpv {
                        kd: id,
                        region,
                        vdi,
                        cost,
                        time: t,
                        node_ids: nodes.iter().map(|&(n, _)| n).collect(),
                        node_costs: nodes.iter().map(|&(_, c)| c).collect(),
                    }
                })
                .collect::<Vec<Cpv>>();
            let pairs: usize = cpvs.iter().map(|c| c.node_ids.len()).sum();
            ctx.pairs.fetch_add(pairs as u64, AtomicOrdering::Relaxed);
            RegionResult {
                cpvs,
                cones,
                regions: 1,
            }
        }
        Some([l, r]) => {
            drop(costs);
            let leaves: Vec<Vdi> = problems.into_iter().map(|(v, _)| v).collect();
            let (mut a, b) = rayon::join(
                || process(ctx, kd, l, &leaves, leaf_level),
                || process(ctx, kd, r, &leaves, leaf_level),
            );
            a.cpvs.extend(b.cpvs);
            RegionResult {
                cpvs: a.cpvs,
                cones: cones + a.cones + b.cones,
                regions: 1 + a.regions + b.regions,
            }
        }
    }
}

/// Approximates the problem view space of `job` over `scene`.
pub fn approximate(ctx: &Context, job: &Job) -> ProblemViews {
    let grid = job.grid();
    let mut kd = build_kd(&grid);
    let level = leaf_level(job.problem_views.min_vdi_deg);
    let n = 1u32 << level;
    let all: Vec<Vdi> = (0..6u8)
        .flat_map(|face| {
            (0..n).flat_map(move |iv| {
                (0..n).map(move |iu| Vdi {
                    face,
                    level,
                    iu,
                    iv,
                })
            })
        })
        .collect();
    let res = process(ctx, &kd, 0, &all, level);
    // CPV ranges per kd node: CPVs come in kd pre-order, so every subtree's
    // CPVs are contiguous.
    let mut first = vec![u32::MAX; kd.len()];
    let mut last = vec![0u32; kd.len()];
    for (i, c) in res.cpvs.iter().enumerate() {
        let mut k = c.kd;
        loop {
            let kn = k as usize;
            first[kn] = first[kn].min(i as u32);
            last[kn] = last[kn].max(i as u32 + 1);
            k = kd[kn].parent;
            if k == u32::MAX {
                break;
            }
        }
    }
    for (i, node) in kd.iter_mut().enumerate() {
        node.cpvs = if first[i] == u32::MAX {
            (0, 0)
        } else {
            (first[i], last[i])
        };
    }
    ProblemViews {
        grid,
        kd,
        cpvs: res.cpvs,
        leaf_level: level,
        cone_evaluations: res.cones,
        regions_visited: res.regions,
    }
}

/// Estimated frame time of views in `region` with directions in `vdi`, using
/// the enclosing frustum and every object (for tests and baselines).
pub fn enclosing_time(ctx: &Context, region: &Aabb, vdi: &Vdi) -> f64 {
    let costs = RegionCosts::new(ctx, region, None);
    let cone = enclosing_cone(region, vdi, ctx.half_diagonal);
    ctx.model
        .frame_time(enclosed_cost(ctx, &costs, &cone, region, None))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;
    use crate::math::geom::{ViewFrustum, face_direction};
    use crate::math::rng::Rng;
    use crate::scene::Object;

    /// Property: every object hit by an exact view frustum at a sampled
    /// position and direction of (region, VDI) is in the enclosing set.
    #[test]
    fn enclosing_frustum_contains_every_exact_frustum() {
        let mut rng = Rng::new(11);
        for case in 0..300 {
            let lo = rng.in_box(DVec3::splat(-50.0), DVec3::splat(50.0));
            let ext = DVec3::new(
                rng.range(0.0, 30.0),
                rng.range(0.0, 10.0),
                rng.range(0.0, 30.0),
            );
            let region = Aabb::new(lo, lo + ext);
            let level = (rng.next_u64() % 5) as u8;
            let n = 1u32 << level;
            let vdi = Vdi {
                face: (rng.next_u64() % 6) as u8,
                level,
                iu: (rng.next_u64() % u64::from(n)) as u32,
                iv: (rng.next_u64() % u64::from(n)) as u32,
            };
            let fov = [30.0, 45.0, 60.0, 90.0][case % 4];
            let aspect = [1.0, 1.5, 0.75][case % 3];
            let cone = enclosing_cone(&region, &vdi, frustum_half_diagonal(fov, aspect));
            let [u0, u1] = vdi.u_range();
            let [v0, v1] = vdi.v_range();
            for _ in 0..20 {
                let eye = rng.in_box(region.min, region.max);
                let dir = face_direction(vdi.face, rng.range(u0, u1), rng.range(v0, v1));
                let f = ViewFrustum::new(eye, dir, fov, aspect);
                for _ in 0..50 {
                    let c = rng.in_box(DVec3::splat(-300.0), DVec3::splat(300.0));
                    let r = rng.range(0.0, 20.0);
                    if f.intersects_sphere(c, r) {
                        assert!(
                            cone.intersects_sphere(c, r),
                            "case {case}: sphere {c} r {r} seen from {eye} dir {dir}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn grid_cells_are_at_most_cell_size_and_partition() {
        let mut job = Job::with_view_space([0.0, 1.5, 0.0], [1500.0, 2.0, 1000.0]);
        job.problem_views.cell_size = 23.0;
        let g = job.grid();
        assert_eq!(g.counts, [66, 1, 44]);
        let b = g.cell_box([65, 0, 43], [66, 1, 44]);
        assert_eq!(b.max, DVec3::new(1500.0, 2.0, 1000.0));
        assert_eq!(
            g.cell_of(DVec3::new(1500.0, 2.0, 1000.0)),
            Some([65, 0, 43])
        );
        let x = g.boundary(0, 10);
        assert_eq!(g.cell_of(DVec3::new(x, 1.7, 0.0)).unwrap()[0], 10);
        assert_eq!(g.cell_of(DVec3::new(x - 1e-9, 1.7, 0.0)).unwrap()[0], 9);
        assert!(g.cell_of(DVec3::new(-1.0, 1.7, 0.0)).is_none());
        assert_eq!(leaf_level(11.25), 3);
        assert_eq!(leaf_level(90.0), 0);
        assert_eq!(leaf_level(10.0), 4);
    }

    #[test]
    fn cpv_regions_are_cells_and_times_exceed_target() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, &job);
        let pv = approximate(&ctx, &job);
        assert!(
            !pv.cpvs.is_empty(),
            "the synthetic job must have problem views"
        );
        for c in &pv.cpvs {
            assert!(c.time > job.target_frame_time_ms);
            assert!(pv.kd[c.kd as usize].children.is_none());
            let ext = c.region.max - c.region.min;
            assert!(ext.max_element() <= job.problem_views.cell_size + 1e-9);
            // The recorded time equals a fresh enclosing estimate.
            assert_eq!(c.time, enclosing_time(&ctx, &c.region, &c.vdi));
        }
        // Views with no problem: a far object set with a tiny cost.
        let tiny = Scene {
            objects: vec![Object {
                name: "x".into(),
                min: DVec3::splat(500.0),
                max: DVec3::splat(501.0),
                triangles: 1,
                draw_calls: 1,
                lods: Vec::new(),
            }],
        };
        let h2 = Hierarchy::build(&tiny);
        let ctx2 = Context::new(&tiny, &h2, &job);
        assert!(approximate(&ctx2, &job).cpvs.is_empty());
    }
}
