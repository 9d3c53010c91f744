//! The cost of what an enclosing frustum sees from a region: per-region
//! object and cluster costs ([`RegionCosts`]) and the one walk that sums
//! them inside a cone ([`enclosed_cost`]).

use crate::math::enclosing::{Bounds, Enclosing, Overlap, enclosing_cone};
use crate::math::geom::{Aabb, Vdi};
use crate::model::cost::Cost;
use crate::views::KdNode;
use crate::views::context::{Context, Counters};
use crate::visibility::ObjectSet;

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
    /// The level of detail chosen for each object is counted in `counters`.
    pub fn new(
        ctx: &Context,
        region: &Aabb,
        visible: Option<&ObjectSet>,
        counters: &Counters,
    ) -> RegionCosts {
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
                    counters.count_lod(slot);
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

    /// Costs for the region of kd node `node`, with its cells' visible set.
    pub fn of_kd(ctx: &Context, node: &KdNode, counters: &Counters) -> RegionCosts {
        let visible = ctx.visibility.and_then(|v| v.region(node.lo, node.hi));
        RegionCosts::new(ctx, &node.aabb, visible.as_deref(), counters)
    }
}

/// Cost of the objects of leaf `n` whose spheres meet `cone`, testing the
/// bounds of `mask` (those the leaf's sphere was not inside).
fn leaf_cost(ctx: &Context, costs: &RegionCosts, cone: &Enclosing, n: u32, mask: Bounds) -> Cost {
    let h = ctx.hierarchy;
    let mut c = Cost::default();
    for &o in h.objects(n) {
        if costs.objects[o as usize] == Cost::default() {
            continue;
        }
        let s = &h.object_spheres[o as usize];
        if cone.classify_within(s.center, s.radius, mask).0 != Overlap::Outside {
            c += costs.objects[o as usize];
        }
    }
    c
}

/// Cost of all objects whose bounding sphere meets `cone`. When `emit` is
/// given, also lists every cluster meeting the cone whose sphere does not meet
/// `region`, with the cost of its objects inside the cone.
pub fn enclosed_cost(
    ctx: &Context,
    costs: &RegionCosts,
    cone: &Enclosing,
    region: &Aabb,
    mut emit: Option<&mut Vec<(u32, Cost)>>,
) -> Cost {
    fn visit(
        ctx: &Context,
        costs: &RegionCosts,
        cone: &Enclosing,
        region: &Aabb,
        (n, mask): (u32, Bounds),
        emit: &mut Option<&mut Vec<(u32, Cost)>>,
    ) -> Cost {
        let h = ctx.hierarchy;
        // A cluster with nothing to draw from the region (culled by
        // visibility) adds nothing and lists nothing below it.
        if costs.nodes[n as usize] == Cost::default() {
            return Cost::default();
        }
        let node = &h.nodes[n as usize];
        let s = node.sphere;
        let (overlap, left) = cone.classify_within(s.center, s.radius, mask);
        if overlap == Overlap::Outside {
            return Cost::default();
        }
        let replaceable = |m: u32| {
            let s = h.nodes[m as usize].sphere;
            !region.intersects_sphere(s.center, s.radius)
        };
        if overlap == Overlap::Inside {
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
            None => leaf_cost(ctx, costs, cone, n, left),
            Some([l, r]) => {
                visit(ctx, costs, cone, region, (l, left), emit)
                    + visit(ctx, costs, cone, region, (r, left), emit)
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
    visit(ctx, costs, cone, region, (0, cone.all_bounds()), &mut emit)
}

/// True when the objects whose spheres meet `cone` cost more than the
/// target frame time. The walk stops as soon as the sum so far exceeds it
/// (the frame time grows with every cost added), or as soon as the sum so
/// far plus the whole costs of the clusters still to visit (at most what
/// they can add) stays below it by a margin that covers the rounding of
/// that running bound: both answers are the full walk's.
pub fn exceeds_target(ctx: &Context, costs: &RegionCosts, cone: &Enclosing) -> bool {
    let h = ctx.hierarchy;
    let model = &ctx.model;
    let mut sum = Cost::default();
    // The whole costs of the clusters on the stack.
    let mut pending = costs.nodes[0];
    let margin = 1e-9 * model.frame_time(pending).abs().max(1.0);
    let mut stack = vec![(0u32, cone.all_bounds())];
    while let Some((n, mask)) = stack.pop() {
        let whole = costs.nodes[n as usize];
        pending = pending - whole;
        if whole == Cost::default() {
            continue;
        }
        let node = &h.nodes[n as usize];
        let s = node.sphere;
        match cone.classify_within(s.center, s.radius, mask) {
            (Overlap::Outside, _) => {}
            (Overlap::Inside, _) => sum += whole,
            (Overlap::Partial, left) => match node.children {
                None => sum += leaf_cost(ctx, costs, cone, n, left),
                Some([l, r]) => {
                    stack.push((r, left));
                    stack.push((l, left));
                    pending += costs.nodes[l as usize] + costs.nodes[r as usize];
                    continue;
                }
            },
        }
        if model.frame_time(sum) > ctx.t_max {
            return true;
        }
        if model.frame_time(sum + pending) + margin < ctx.t_max {
            return false;
        }
    }
    false
}

/// The cost of what the enclosing frustum of (`region`, `vdi`) sees, and
/// the clusters a CPV there may replace, sorted by node id, each with the
/// cost of its objects inside the frustum: they meet the frustum, do not
/// meet the region, and a one-layer impostor of them would be cheaper than
/// their objects there. The problem view approximation counts these lists;
/// candidate generation computes them again, one cell at a time, instead of
/// holding every CPV's list at once.
pub fn cpv_clusters(
    ctx: &Context,
    costs: &RegionCosts,
    region: &Aabb,
    vdi: &Vdi,
) -> (Cost, Vec<(u32, Cost)>) {
    let cone = enclosing_cone(region, vdi, &ctx.lens);
    let mut nodes = Vec::new();
    let cost = enclosed_cost(ctx, costs, &cone, region, Some(&mut nodes));
    let t = ctx.model.frame_time(cost);
    let h = ctx.hierarchy;
    // Keep the clusters some impostor could accelerate: an impostor has at
    // least one layer.
    nodes.retain(|&(n, orig)| {
        let s = h.nodes[n as usize].sphere;
        let imp = ctx
            .model
            .impostor(1, s.radius, region.distance_to_point(s.center));
        ctx.model.frame_time(cost - orig + imp) < t
    });
    nodes.sort_unstable_by_key(|&(n, _)| n);
    (cost, nodes)
}

/// Estimated frame time of views in `region` with directions in `vdi`, using
/// the enclosing frustum and every object (for tests and baselines).
pub fn enclosing_time(ctx: &Context, region: &Aabb, vdi: &Vdi) -> f64 {
    let costs = RegionCosts::new(ctx, region, None, &Counters::new());
    let cone = enclosing_cone(region, vdi, &ctx.lens);
    ctx.model
        .frame_time(enclosed_cost(ctx, &costs, &cone, region, None))
}
