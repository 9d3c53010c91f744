//! The cost of what an enclosing frustum sees from a region: per-region
//! object and cluster costs ([`RegionCosts`]) and the one walk that sums
//! them inside a cone ([`enclosed_cost`]).

use std::collections::VecDeque;

use crate::math::enclosing::{Bounds, Enclosing, Overlap, enclosing_cone};
use crate::math::geom::{Aabb, Sphere, Vdi};
use crate::model::cost::Cost;
use crate::scene::hierarchy::Hierarchy;
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
    /// Per node id, the node an early-exit walk tests in its place: the
    /// node itself, or, where one of its children costs nothing from the
    /// region (e.g. outside the visible set), what the other child tests.
    /// Its cost is the node's, and its sphere lies inside the node's, so
    /// the walk sums the same costs with fewer sphere tests.
    pub down: Vec<u32>,
    /// With a visible set, per node id set in it: a sphere holding the
    /// spheres of the node's objects that cost something from the region,
    /// each inside its parent's (the node's own sphere where that is
    /// smaller); empty without one (the nodes' own spheres).
    spheres: Vec<Sphere>,
    /// With a visible set: the entries set (visible objects, the clusters
    /// above them), cleared again when the buffers go back to [`POOL`].
    sparse: Option<Sparse>,
}

/// What a [`RegionCosts`] of a visible set set in its buffers.
struct Sparse {
    objects: Vec<u32>,
    nodes: Vec<u32>,
    /// Per node id: in `nodes` (all false again once back in the pool).
    marked: Vec<bool>,
}

/// Buffers of [`RegionCosts`] for visible sets, all entries zero (`down`
/// the identity, nothing marked): a region sees a small part of a large
/// scene, so it sets and clears only that part instead of allocating and
/// summing every object and cluster. Shared by every job in the process;
/// a buffer of another scene's sizes is not taken, and at most
/// [`POOL_BUFFERS`] are kept.
static POOL: std::sync::Mutex<Vec<Buffers>> = std::sync::Mutex::new(Vec::new());

/// A [`RegionCosts`]'s buffers in the [`POOL`].
struct Buffers {
    objects: Vec<Cost>,
    nodes: Vec<Cost>,
    down: Vec<u32>,
    spheres: Vec<Sphere>,
    sparse: Sparse,
}

/// Buffers kept in [`POOL`] (a few per worker thread).
const POOL_BUFFERS: usize = 16;

impl Drop for RegionCosts {
    fn drop(&mut self) {
        let Some(mut sp) = self.sparse.take() else {
            return;
        };
        for &o in &sp.objects {
            self.objects[o as usize] = Cost::default();
        }
        for &n in &sp.nodes {
            self.nodes[n as usize] = Cost::default();
            self.down[n as usize] = n;
            sp.marked[n as usize] = false;
        }
        sp.objects.clear();
        sp.nodes.clear();
        let buffers = Buffers {
            objects: std::mem::take(&mut self.objects),
            nodes: std::mem::take(&mut self.nodes),
            down: std::mem::take(&mut self.down),
            spheres: std::mem::take(&mut self.spheres),
            sparse: sp,
        };
        let mut pool = POOL
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if pool.len() >= POOL_BUFFERS {
            pool.remove(0);
        }
        pool.push(buffers);
    }
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
        let cost = |id: usize| {
            let o = &ctx.scene.objects[id];
            let s = &ctx.hierarchy.object_spheres[id];
            let d = region.distance_to_point(s.center);
            if !o.lods.is_empty() {
                let slot = ctx
                    .model
                    .lod_level(o, s.radius, d)
                    .unwrap_or(crate::scene::MAX_LODS);
                counters.count_lod(slot);
            }
            ctx.model.object_region(o, s.radius, d)
        };
        if let Some(v) = visible {
            return Self::sparse(ctx, v, cost);
        }
        let objects: Vec<Cost> = (0..ctx.scene.objects.len()).map(cost).collect();
        let h = ctx.hierarchy;
        let mut nodes = vec![Cost::default(); h.nodes.len()];
        let mut down: Vec<u32> = (0..h.nodes.len() as u32).collect();
        Self::sum(
            h,
            &objects,
            &mut nodes,
            &mut down,
            None,
            0..h.nodes.len() as u32,
        );
        RegionCosts {
            objects,
            nodes,
            down,
            spheres: Vec::new(),
            sparse: None,
        }
    }

    /// [`new`](Self::new) with a visible set: only the visible objects and
    /// the clusters above them are computed, in pooled buffers. The same
    /// values: a cluster with nothing visible costs zero either way.
    fn sparse(ctx: &Context, visible: &ObjectSet, cost: impl Fn(usize) -> Cost) -> RegionCosts {
        let h = ctx.hierarchy;
        let (n_obj, n_nodes) = (ctx.scene.objects.len(), h.nodes.len());
        let taken = {
            let mut pool = POOL
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            pool.iter()
                .position(|b| b.objects.len() == n_obj && b.nodes.len() == n_nodes)
                .map(|k| pool.swap_remove(k))
        };
        let b = taken.unwrap_or_else(|| Buffers {
            objects: vec![Cost::default(); n_obj],
            nodes: vec![Cost::default(); n_nodes],
            down: (0..n_nodes as u32).collect(),
            spheres: vec![h.nodes[0].sphere; n_nodes],
            sparse: Sparse {
                objects: Vec::new(),
                nodes: Vec::new(),
                marked: vec![false; n_nodes],
            },
        });
        let mut out = RegionCosts {
            objects: b.objects,
            nodes: b.nodes,
            down: b.down,
            spheres: b.spheres,
            sparse: None,
        };
        let mut sp = b.sparse;
        sp.objects.extend(visible.iter());
        for &o in &sp.objects {
            out.objects[o as usize] = cost(o as usize);
            let mut n = h.leaf_of[o as usize];
            while n != u32::MAX && !sp.marked[n as usize] {
                sp.marked[n as usize] = true;
                sp.nodes.push(n);
                n = h.nodes[n as usize].parent;
            }
        }
        sp.nodes.sort_unstable();
        Self::sum(
            h,
            &out.objects,
            &mut out.nodes,
            &mut out.down,
            Some(&mut out.spheres),
            sp.nodes.iter().copied(),
        );
        out.sparse = Some(sp);
        out
    }

    /// Sets `nodes` and `down` of the clusters `ids` (ascending; summed
    /// from the last, so children before parents) from the objects' costs
    /// and the clusters' below, and their `spheres` where given.
    fn sum(
        h: &Hierarchy,
        objects: &[Cost],
        nodes: &mut [Cost],
        down: &mut [u32],
        mut spheres: Option<&mut Vec<Sphere>>,
        ids: impl DoubleEndedIterator<Item = u32>,
    ) {
        let zero = Cost::default();
        for id in ids.rev() {
            let id = id as usize;
            let node = &h.nodes[id];
            match node.children {
                None => {
                    nodes[id] = h
                        .objects(id as u32)
                        .iter()
                        .fold(Cost::default(), |acc, &o| acc + objects[o as usize]);
                    if let Some(sp) = spheres.as_deref_mut() {
                        // Merged in the order the hierarchy merges them.
                        let fit = h
                            .objects(id as u32)
                            .iter()
                            .filter(|&&o| objects[o as usize] != zero)
                            .map(|&o| h.object_spheres[o as usize])
                            .reduce(|a, b| a.merge(&b));
                        sp[id] = smaller(fit, node.sphere);
                    }
                }
                Some([l, r]) => {
                    let (cl, cr) = (nodes[l as usize], nodes[r as usize]);
                    nodes[id] = cl + cr;
                    if cl == zero {
                        down[id] = down[r as usize];
                    } else if cr == zero {
                        down[id] = down[l as usize];
                    }
                    if let Some(sp) = spheres.as_deref_mut() {
                        let fit = match (cl != zero, cr != zero) {
                            (true, true) => Some(sp[l as usize].merge(&sp[r as usize])),
                            (true, false) => Some(sp[l as usize]),
                            (false, true) => Some(sp[r as usize]),
                            (false, false) => None,
                        };
                        sp[id] = smaller(fit, node.sphere);
                    }
                }
            }
        }
    }

    /// The sphere the walks of [`exceeds`] test for node `n` (one it set:
    /// costing something from the region).
    #[inline]
    fn sphere(&self, h: &Hierarchy, n: u32) -> Sphere {
        if self.spheres.is_empty() {
            h.nodes[n as usize].sphere
        } else {
            self.spheres[n as usize]
        }
    }

    /// Costs for the region of kd node `node`, with its cells' visible set.
    pub fn of_kd(ctx: &Context, node: &KdNode, counters: &Counters) -> RegionCosts {
        let visible = ctx.visibility.and_then(|v| v.region(node.lo, node.hi));
        RegionCosts::new(ctx, &node.aabb, visible.as_deref(), counters)
    }
}

/// The smaller of a sphere fitted to part of a node's objects (none: it has
/// nothing to fit) and the node's own sphere, which holds them all: both
/// hold the fitted objects, and a parent holds whichever each child took
/// (its fit merges them; its own sphere holds the children's own).
fn smaller(fit: Option<Sphere>, own: Sphere) -> Sphere {
    match fit {
        Some(f) if f.radius < own.radius => f,
        _ => own,
    }
}

/// Cost of the objects of leaf `n` whose spheres meet `cone`, testing the
/// bounds of `mask` (those the leaf's sphere was not inside).
fn leaf_cost(ctx: &Context, costs: &RegionCosts, cone: &Enclosing, n: u32, mask: Bounds) -> Cost {
    objects_cost(ctx, costs, cone, ctx.hierarchy.objects(n), mask)
}

/// Cost of the `objects` whose spheres meet `cone`, testing the bounds of
/// `mask`.
fn objects_cost(
    ctx: &Context,
    costs: &RegionCosts,
    cone: &Enclosing,
    objects: &[u32],
    mask: Bounds,
) -> Cost {
    meeting(ctx, costs, cone, objects, mask).fold(Cost::default(), |sum, (_, c)| sum + c)
}

/// The `objects` that cost something and whose spheres meet `cone`
/// (testing the bounds of `mask`), each with its cost, in their order.
fn meeting<'a>(
    ctx: &'a Context,
    costs: &'a RegionCosts,
    cone: &'a Enclosing,
    objects: &'a [u32],
    mask: Bounds,
) -> impl Iterator<Item = (u32, Cost)> + 'a {
    let h = ctx.hierarchy;
    objects.iter().filter_map(move |&o| {
        let c = costs.objects[o as usize];
        let s = &h.object_spheres[o as usize];
        (c != Cost::default() && cone.meets_within(s.center, s.radius, mask)).then_some((o, c))
    })
}

/// Which clusters a CPV of one region may list where its enclosing set
/// holds them whole: those with something to draw from the region, whose
/// sphere does not meet the region (an impostor is drawn outside its view
/// cell) and whose objects a one-layer impostor could accelerate
/// ([`Listable::may_list`]). Every CPV of a cell shares its region, so the
/// cell computes this once; a cluster the set holds only in part is judged
/// the same way with its cost in the set.
pub struct Listable {
    /// Per node: listed wherever the set holds it whole.
    pub ok: Vec<bool>,
    /// Per node: how many nodes of its subtree are `ok`.
    pub below: Vec<u32>,
}

impl Listable {
    /// The clusters CPVs of `region` may list, with the region's `costs`.
    pub fn new(ctx: &Context, costs: &RegionCosts, region: &Aabb) -> Listable {
        let h = ctx.hierarchy;
        let ok: Vec<bool> = (0..h.nodes.len() as u32)
            .map(|n| Self::may_list(ctx, region, n, costs.nodes[n as usize]))
            .collect();
        let mut below: Vec<u32> = ok.iter().map(|&o| u32::from(o)).collect();
        for n in (1..h.nodes.len()).rev() {
            let p = h.nodes[n].parent as usize;
            below[p] += below[n];
        }
        Listable { ok, below }
    }

    /// True when a CPV of `region` lists cluster `n` whose objects in its
    /// enclosing set cost `cost`: they cost something, the cluster's
    /// sphere does not meet the region, and a one-layer impostor of it
    /// may accelerate a frame that draws them
    /// ([`CostModel::may_accelerate`](crate::model::cost::CostModel::may_accelerate)).
    pub fn may_list(ctx: &Context, region: &Aabb, n: u32, cost: Cost) -> bool {
        let s = ctx.hierarchy.nodes[n as usize].sphere;
        (cost.cpu > 0.0 || cost.gpu > 0.0)
            && !region.intersects_sphere(s.center, s.radius)
            && ctx.model.may_accelerate(
                cost,
                ctx.model
                    .impostor(1, s.radius, region.distance_to_point(s.center)),
            )
    }
}

/// What a CPV lists, as the hierarchy's cut through its enclosing set:
/// every cluster below a node of `cuts` that is [`Listable::ok`] is listed
/// with its whole cost in the cell; the clusters the set holds in part are
/// listed in `explicit` with their cost in the set.
#[derive(Clone, Debug, Default)]
pub struct CpvCut {
    /// The cost of what the enclosing set sees.
    pub cost: Cost,
    /// Clusters the set holds in part (their sphere is not inside it), with
    /// the cost of their objects inside it, by node id.
    pub explicit: Vec<(u32, Cost)>,
    /// The nodes whose sphere lies inside the set, whose parent's does not
    /// and below which some cluster is `ok`, by node id.
    pub cuts: Vec<u32>,
}

impl CpvCut {
    /// How many clusters it lists.
    pub fn listed(&self, listable: &Listable) -> u32 {
        self.explicit.len() as u32
            + self
                .cuts
                .iter()
                .map(|&a| listable.below[a as usize])
                .sum::<u32>()
    }
}

/// The cuts of one cell's CPVs, per cluster: the CPVs (bit `i`: the cell's
/// `i`-th CPV) with a cut node at or above it, which list it whole where
/// it is [`Listable::ok`]. The problem view approximation counts them and
/// candidate generation keeps them with the groups.
pub struct CellCuts {
    /// 64-bit words per cluster.
    pub words: usize,
    /// Per node, `words` words; zero outside the cut nodes' subtrees.
    above: Vec<u64>,
    /// The `ok` clusters below cut nodes (some CPV lists them whole), by
    /// node id.
    pub listed: Vec<u32>,
}

impl CellCuts {
    /// The cuts `cuts` of one cell's CPVs, in CPV order.
    pub fn new(ctx: &Context, listable: &Listable, cuts: &[CpvCut]) -> CellCuts {
        let h = ctx.hierarchy;
        let words = cuts.len().div_ceil(64);
        let mut above = vec![0u64; h.nodes.len() * words];
        let mut at: Vec<(u32, usize)> = cuts
            .iter()
            .enumerate()
            .flat_map(|(i, c)| c.cuts.iter().map(move |&a| (a, i)))
            .collect();
        at.sort_unstable();
        for &(a, i) in &at {
            above[a as usize * words + i / 64] |= 1 << (i % 64);
        }
        // Down each top cut node's subtree in pre-order (a parent before
        // its children): a node's set holds its parent's.
        let mut listed = Vec::new();
        let mut end = 0u32;
        for &(a, _) in &at {
            if a < end {
                continue;
            }
            end = h.nodes[a as usize].subtree_end;
            for m in a..end {
                if m > a {
                    let p = h.nodes[m as usize].parent as usize;
                    for w in 0..words {
                        above[m as usize * words + w] |= above[p * words + w];
                    }
                }
                if listable.ok[m as usize] {
                    listed.push(m);
                }
            }
        }
        CellCuts {
            words,
            above,
            listed,
        }
    }

    /// The CPVs with a cut node at or above cluster `n`.
    pub fn above(&self, n: u32) -> &[u64] {
        &self.above[n as usize * self.words..][..self.words]
    }

    /// How many CPVs have a cut node at or above cluster `n`.
    pub fn count(&self, n: u32) -> u32 {
        self.above(n).iter().map(|w| w.count_ones()).sum()
    }
}

/// Cost of all objects whose bounding sphere meets `cone`. When `emit` is
/// given, also records what a CPV of `region` lists ([`CpvCut`]).
pub fn enclosed_cost(
    ctx: &Context,
    costs: &RegionCosts,
    cone: &Enclosing,
    region: &Aabb,
    mut emit: Option<(&Listable, &mut CpvCut)>,
) -> Cost {
    fn visit(
        ctx: &Context,
        costs: &RegionCosts,
        cone: &Enclosing,
        region: &Aabb,
        (n, mask): (u32, Bounds),
        emit: &mut Option<(&Listable, &mut CpvCut)>,
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
        if overlap == Overlap::Inside {
            if let Some((listable, out)) = emit.as_mut()
                && listable.below[n as usize] > 0
            {
                out.cuts.push(n);
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
        if let Some((_, out)) = emit.as_mut()
            && Listable::may_list(ctx, region, n, c)
        {
            out.explicit.push((n, c));
        }
        c
    }
    let cost = visit(ctx, costs, cone, region, (0, cone.all_bounds()), &mut emit);
    if let Some((_, out)) = emit {
        out.cost = cost;
        out.explicit.sort_unstable_by_key(|&(n, _)| n);
        out.cuts.sort_unstable();
    }
    cost
}

/// True when the objects whose spheres meet `cone` cost more than the
/// target frame time. The walk stops as soon as the sum so far exceeds it
/// (the frame time grows with every cost added), or as soon as the sum so
/// far plus the whole costs of the clusters still to visit (at most what
/// they can add) stays below it by a margin that covers the rounding of
/// that running bound: both answers are the full walk's.
///
/// The hierarchy is walked breadth first: the large clusters near its top
/// are classified before any subtree is followed down to its objects, so
/// either bound is reached after fewer nodes (on a fly-over's problem
/// views, a fifth fewer nodes and two fifths fewer object tests than depth
/// first).
pub fn exceeds_target(ctx: &Context, costs: &RegionCosts, cone: &Enclosing) -> bool {
    exceeds(ctx, costs, cone, ctx.t_max)
}

/// [`exceeds_target`] against the frame time `t` instead of the target.
pub fn exceeds(ctx: &Context, costs: &RegionCosts, cone: &Enclosing, t: f64) -> bool {
    // A node with a child that costs nothing is skipped for its other
    // child ([`RegionCosts::down`]): the same cost in a smaller sphere.
    exceeds_from(ctx, costs, &[(costs.down[0], NO_CUT)], &[], &[], cone, t)
}

/// [`exceeds`] walking from the entries `start` (disjoint subtrees, each
/// with its index in `cuts`, of `objects`, where it is a cut leaf, else
/// [`NO_CUT`]) instead of the root: the objects outside them, and those of
/// a cut leaf not listed in its cut, count nothing.
fn exceeds_from(
    ctx: &Context,
    costs: &RegionCosts,
    start: &[(u32, u32)],
    cuts: &[Cut],
    objects: &[u32],
    cone: &Enclosing,
    t: f64,
) -> bool {
    let h = ctx.hierarchy;
    let model = &ctx.model;
    let mut sum = Cost::default();
    let margin = 1e-9 * model.frame_time(costs.nodes[0]).abs().max(1.0);
    // The whole costs of the clusters in the queue (of a cut leaf, its
    // objects the outer set meets).
    let mut pending = Cost::default();
    let all = cone.all_bounds();
    let whole = |n: u32, cut: u32| entry_cost(costs, cuts, n, cut);
    let mut queue: VecDeque<(u32, u32, Bounds)> = start
        .iter()
        .map(|&(n, cut)| {
            pending += whole(n, cut);
            (n, cut, all)
        })
        .collect();
    while let Some((n, cut, mask)) = queue.pop_front() {
        let w = whole(n, cut);
        pending = pending - w;
        if w == Cost::default() {
            continue;
        }
        let node = &h.nodes[n as usize];
        let s = costs.sphere(h, n);
        match cone.classify_within(s.center, s.radius, mask) {
            (Overlap::Outside, _) => {}
            (Overlap::Inside, _) => sum += w,
            (Overlap::Partial, left) => match (cuts.get(cut as usize), node.children) {
                (Some(c), _) => {
                    let objs = &objects[c.start as usize..c.end as usize];
                    sum += objects_cost(ctx, costs, cone, objs, left);
                }
                (None, None) => sum += leaf_cost(ctx, costs, cone, n, left),
                (None, Some([l, r])) => {
                    queue.push_back((costs.down[l as usize], NO_CUT, left));
                    queue.push_back((costs.down[r as usize], NO_CUT, left));
                    pending += costs.nodes[l as usize] + costs.nodes[r as usize];
                    continue;
                }
            },
        }
        if model.frame_time(sum) > t {
            return true;
        }
        if model.frame_time(sum + pending) + margin < t {
            return false;
        }
    }
    false
}

/// Where only views inside an outer enclosing set matter (the proofs of a
/// problem view's parts and sub-directions, every view of which is a view
/// of the problem view), the clusters a walk starts from: those the outer
/// set holds whole, and the leaves it cuts, with only their objects that
/// meet it. A cluster or object outside the outer set is seen by none of
/// those views, so a walk from here counts what a walk from the root
/// counts, less what the outer set excludes, without testing again every
/// cluster above the outer set's boundary. A frontier narrows to a set
/// inside its own ([`Frontier::narrowed`]): the proofs of one direction
/// from many parts of a cell start from the frontier of that direction
/// from the whole cell.
pub struct Frontier {
    /// Disjoint subtrees, in breadth-first order, each with the index of
    /// its entry in `cuts` where it is a leaf the set cuts, else
    /// [`NO_CUT`].
    nodes: Vec<(u32, u32)>,
    /// The leaves the set cuts: the objects of each that meet it.
    cuts: Vec<Cut>,
    /// The objects of the cut leaves, each leaf's contiguous.
    objects: Vec<u32>,
}

/// A leaf an enclosing set cuts: the range of its objects that meet the set
/// in [`Frontier::objects`] and their summed cost.
#[derive(Clone, Copy)]
pub struct Cut {
    cost: Cost,
    start: u32,
    end: u32,
}

/// No entry in [`Frontier::cuts`].
const NO_CUT: u32 = u32::MAX;

/// What a frontier entry (`n`, `cut`) may add: the whole cost of cluster
/// `n`, or of a cut leaf the cost of its objects in the cut.
fn entry_cost(costs: &RegionCosts, cuts: &[Cut], n: u32, cut: u32) -> Cost {
    cuts.get(cut as usize)
        .map_or(costs.nodes[n as usize], |c| c.cost)
}

impl Frontier {
    /// The clusters `outer` does not exclude, found breadth first as
    /// [`exceeds`] walks (zero-cost clusters skipped, [`RegionCosts::down`]
    /// followed); of a leaf it cuts, only the objects that meet it.
    pub fn within(ctx: &Context, costs: &RegionCosts, outer: &Enclosing) -> Frontier {
        Self::within_from(ctx, costs, &[(costs.down[0], NO_CUT)], &[], &[], outer)
    }

    /// The frontier of `outer` below the entries `start` (disjoint
    /// subtrees, cut leaves in `cuts` of `objects`).
    fn within_from(
        ctx: &Context,
        costs: &RegionCosts,
        start: &[(u32, u32)],
        cuts: &[Cut],
        objects: &[u32],
        outer: &Enclosing,
    ) -> Frontier {
        let h = ctx.hierarchy;
        let all = outer.all_bounds();
        let mut out = Frontier {
            nodes: Vec::new(),
            cuts: Vec::new(),
            objects: Vec::new(),
        };
        // Leaf `n` with only those of `objs` that meet `outer`.
        let cut = |out: &mut Frontier, n: u32, objs: &[u32], mask: Bounds| {
            let start = out.objects.len() as u32;
            let mut cost = Cost::default();
            for (o, c) in meeting(ctx, costs, outer, objs, mask) {
                out.objects.push(o);
                cost += c;
            }
            let end = out.objects.len() as u32;
            if end > start {
                out.nodes.push((n, out.cuts.len() as u32));
                out.cuts.push(Cut { cost, start, end });
            }
        };
        let mut queue: VecDeque<(u32, u32, Bounds)> =
            start.iter().map(|&(n, c)| (n, c, all)).collect();
        while let Some((n, c, mask)) = queue.pop_front() {
            if entry_cost(costs, cuts, n, c) == Cost::default() {
                continue;
            }
            let given = cuts.get(c as usize);
            let s = costs.sphere(h, n);
            // A sphere inside the set has no bound left to test.
            let (inside, left) = match outer.classify_within(s.center, s.radius, mask) {
                (Overlap::Outside, _) => continue,
                (Overlap::Inside, _) => (true, 0),
                (Overlap::Partial, left) => (false, left),
            };
            match (given, h.nodes[n as usize].children) {
                (Some(g), _) => cut(
                    &mut out,
                    n,
                    &objects[g.start as usize..g.end as usize],
                    left,
                ),
                (None, _) if inside => out.nodes.push((n, NO_CUT)),
                (None, None) => cut(&mut out, n, h.objects(n), left),
                (None, Some([l, r])) => {
                    queue.push_back((costs.down[l as usize], NO_CUT, left));
                    queue.push_back((costs.down[r as usize], NO_CUT, left));
                }
            }
        }
        out
    }

    /// The frontier of `inner` (every view of which is a view of this
    /// frontier's set) below this one.
    pub fn narrowed(&self, ctx: &Context, costs: &RegionCosts, inner: &Enclosing) -> Frontier {
        Self::within_from(ctx, costs, &self.nodes, &self.cuts, &self.objects, inner)
    }

    /// [`exceeds`] counting only the objects below the frontier: for a set
    /// whose views are all views of the outer set, an upper bound of every
    /// such view's cost as [`exceeds`]'s is.
    pub fn exceeds(&self, ctx: &Context, costs: &RegionCosts, cone: &Enclosing, t: f64) -> bool {
        exceeds_from(ctx, costs, &self.nodes, &self.cuts, &self.objects, cone, t)
    }

    /// True when object `o` is below the frontier.
    #[cfg(test)]
    fn holds(&self, h: &Hierarchy, o: u32) -> bool {
        let leaf = h.leaf_of[o as usize];
        self.nodes
            .iter()
            .any(|&(a, c)| match self.cuts.get(c as usize) {
                Some(g) => self.objects[g.start as usize..g.end as usize].contains(&o),
                None => a <= leaf && leaf < h.nodes[a as usize].subtree_end,
            })
    }
}

/// What a CPV of (`region`, `vdi`) lists ([`CpvCut`]), `listable` being
/// its region's. The problem view approximation counts these lists;
/// candidate generation computes them again, one cell at a time, instead
/// of holding every CPV's list at once.
pub fn cpv_cut(
    ctx: &Context,
    costs: &RegionCosts,
    listable: &Listable,
    region: &Aabb,
    vdi: &Vdi,
) -> CpvCut {
    let cone = enclosing_cone(region, vdi, &ctx.lens);
    let mut out = CpvCut::default();
    enclosed_cost(ctx, costs, &cone, region, Some((listable, &mut out)));
    out
}

/// The cost of what the enclosing frustum of (`region`, `vdi`) sees, and
/// every cluster a CPV there lists, by node id, each with the cost of its
/// objects inside the frustum: [`cpv_cut`] with the clusters below its cut
/// spelled out.
pub fn cpv_clusters(
    ctx: &Context,
    costs: &RegionCosts,
    region: &Aabb,
    vdi: &Vdi,
) -> (Cost, Vec<(u32, Cost)>) {
    let listable = Listable::new(ctx, costs, region);
    let cut = cpv_cut(ctx, costs, &listable, region, vdi);
    let h = ctx.hierarchy;
    let mut nodes = cut.explicit;
    for &a in &cut.cuts {
        nodes.extend(
            (a..h.nodes[a as usize].subtree_end)
                .filter(|&m| listable.ok[m as usize])
                .map(|m| (m, costs.nodes[m as usize])),
        );
    }
    nodes.sort_unstable_by_key(|&(n, _)| n);
    (cut.cost, nodes)
}

/// Estimated frame time of views in `region` with directions in `vdi`, using
/// the enclosing frustum and every object (for tests and baselines).
pub fn enclosing_time(ctx: &Context, region: &Aabb, vdi: &Vdi) -> f64 {
    let costs = RegionCosts::new(ctx, region, None, &Counters::new());
    let cone = enclosing_cone(region, vdi, &ctx.lens);
    ctx.model
        .frame_time(enclosed_cost(ctx, &costs, &cone, region, None))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Control;
    use crate::math::geom::Vdi;
    use crate::scene::hierarchy::Hierarchy;
    use crate::views::leaf_level;

    /// The early-exit walk answers as the full sum does, for thresholds
    /// on both sides of each set's time and as close to it as a part in a
    /// million: neither exit (the sum past the threshold, or the sum and
    /// everything still queued under it) may stop on a wrong answer,
    /// whatever order the hierarchy is visited in.
    #[test]
    fn exceeds_answers_as_the_full_sum() {
        let (mut above, mut below, mut sets) = (0, 0, 0);
        with_test_cells(|ctx, region, costs, vdi| {
            let cone = enclosing_cone(region, vdi, &ctx.lens);
            let t = ctx
                .model
                .frame_time(enclosed_cost(ctx, costs, &cone, region, None));
            sets += 1;
            for f in [0.5, 0.9, 1.0 - 1e-6, 1.0 + 1e-6, 1.1, 2.0] {
                let threshold = t * f;
                let full = t > threshold;
                assert_eq!(
                    exceeds(ctx, costs, &cone, threshold),
                    full,
                    "{vdi:?} from {region:?}: {t} ms against {threshold}"
                );
                above += usize::from(full);
                below += usize::from(!full);
            }
        });
        assert!(sets > 100 && above > 0 && below > 0);
    }

    /// Calls `f` for every leaf VDI of four cells of a synthetic city (all
    /// its objects potentially visible), with the cell's costs.
    fn with_test_cells(mut f: impl FnMut(&Context, &Aabb, &RegionCosts, &Vdi)) {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let grid = job.grid();
        let level = leaf_level(job.problem_views.min_vdi_deg);
        for (i, j) in [(0, 0), (2, 1), (5, 3), (3, 5)] {
            let region = grid.cell_box([i, 0, j], [i + 1, 1, j + 1]);
            let costs = RegionCosts::new(&ctx, &region, None, &Counters::new());
            for vdi in Vdi::all_at(level) {
                f(&ctx, &region, &costs, &vdi);
            }
        }
    }

    /// A frontier within a cell's enclosing set for a VDI, and one narrowed
    /// from it to each sub-direction, holds every object that costs
    /// something and meets its set (below its parent), hence every object
    /// an exact view from the cell with a direction in its set sees (its
    /// sphere meets the view's frustum), and leaves others out, so the
    /// check could fail: of
    /// the leaves it cuts too (it keeps their objects that meet the set),
    /// and a narrowed frontier holds less than its parent. A walk from
    /// either never finds a part of the cell in a direction of its set
    /// above a threshold where the walk from the root finds it within (it
    /// counts a subset), for thresholds on both sides of each set's time,
    /// both answers occurring.
    #[test]
    fn a_frontier_holds_what_its_views_see() {
        use crate::math::geom::ViewFrustum;
        use glam::DVec3;
        let mut rng = crate::math::rng::Rng::new(7);
        let (mut seen, mut left_out, mut cut_away) = (0usize, 0usize, 0usize);
        let (mut held_outer, mut held_narrowed) = (0usize, 0usize);
        let (mut above, mut below) = (0usize, 0usize);
        with_test_cells(|ctx, region, costs, vdi| {
            if !ctx.pitch_overlaps(vdi) {
                return;
            }
            let h = ctx.hierarchy;
            let n = ctx.scene.objects.len() as u32;
            let outer = enclosing_cone(region, vdi, &ctx.lens);
            let f = Frontier::within(ctx, costs, &outer);
            // Every object that costs something and whose sphere meets the
            // set is held (below the parent frontier, for a narrowed one).
            let complete = |f: &Frontier, set: &Enclosing, parent: Option<&Frontier>| {
                let all = set.all_bounds();
                for o in 0..n {
                    let s = &h.object_spheres[o as usize];
                    if costs.objects[o as usize] != Cost::default()
                        && set.meets_within(s.center, s.radius, all)
                        && parent.is_none_or(|p| p.holds(h, o))
                    {
                        assert!(f.holds(h, o), "object {o} meets the set, not held");
                    }
                }
            };
            complete(&f, &outer, None);
            let mut sets = vec![(*vdi, f)];
            for d in vdi.children() {
                if ctx.pitch_overlaps(&d) {
                    let inner = enclosing_cone(region, &d, &ctx.lens);
                    let g = sets[0].1.narrowed(ctx, costs, &inner);
                    complete(&g, &inner, Some(&sets[0].1));
                    // Narrowed again, to a corner of the cell and finer
                    // directions, as a part's proofs narrow.
                    let corner =
                        Aabb::new(region.min, region.min + (region.max - region.min) * 0.25);
                    for e in d.children() {
                        let innermost = enclosing_cone(&corner, &e, &ctx.lens);
                        complete(&g.narrowed(ctx, costs, &innermost), &innermost, Some(&g));
                    }
                    sets.push((d, g));
                }
            }
            for (k, (set, f)) in sets.iter().enumerate() {
                let held = (0..n).filter(|&o| f.holds(h, o)).count();
                if k == 0 {
                    held_outer += held * (sets.len() - 1);
                } else {
                    held_narrowed += held;
                }
                left_out += n as usize - held;
                for &(leaf, c) in &f.nodes {
                    if let Some(g) = f.cuts.get(c as usize) {
                        cut_away += h.objects(leaf).len() - (g.end - g.start) as usize;
                    }
                }
                let corners = set.corner_dirs();
                for _ in 0..4 {
                    let u = DVec3::new(rng.f64(), rng.f64(), rng.f64());
                    let eye = region.min + (region.max - region.min) * u;
                    // A positive combination of the corners' directions
                    // lies in the set's VDI.
                    let dir = corners
                        .iter()
                        .fold(DVec3::ZERO, |a, &c| a + c * (0.05 + rng.f64()))
                        .normalize();
                    if !ctx.in_pitch(dir) {
                        continue;
                    }
                    let view = ViewFrustum::new(eye, dir, ctx.lens.fov_deg, ctx.lens.aspect);
                    for o in 0..n {
                        let s = &h.object_spheres[o as usize];
                        if view.distance(s.center) <= s.radius {
                            seen += 1;
                            assert!(f.holds(h, o), "object {o} seen from {eye:?} along {dir:?}");
                        }
                    }
                }
                let mut lower = *region;
                lower.max.x = region.center().x;
                for part in [*region, lower] {
                    for d in set.children() {
                        let cone = enclosing_cone(&part, &d, &ctx.lens);
                        let t = ctx
                            .model
                            .frame_time(enclosed_cost(ctx, costs, &cone, &part, None));
                        for k in [0.9, 1.0 - 1e-6, 1.0 + 1e-6, 1.1] {
                            let from_frontier = f.exceeds(ctx, costs, &cone, t * k);
                            assert!(!from_frontier || exceeds(ctx, costs, &cone, t * k));
                            above += usize::from(from_frontier);
                            below += usize::from(!from_frontier);
                        }
                    }
                }
            }
        });
        assert!(
            seen > 1000 && left_out > 1000 && cut_away > 100,
            "{seen} seen, {left_out} left out, {cut_away} cut away"
        );
        assert!(
            held_narrowed < held_outer,
            "narrowed frontiers hold {held_narrowed}, their parents {held_outer}"
        );
        assert!(above > 0 && below > 0, "{above} above, {below} below");
    }

    /// Costs with a visible set, computed in pooled buffers for the visible
    /// objects and the clusters above them only, equal every object's and
    /// cluster's dense costs with the invisible objects zeroed, bit for bit,
    /// also when the buffers come back from a region that saw other
    /// objects; and the early-exit walk, which steps past clusters with a
    /// child that costs nothing and tests spheres fitted to what costs
    /// something, answers as the full sum does.
    #[test]
    fn visible_sets_cost_as_the_dense_sums_with_the_rest_zeroed() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let grid = job.grid();
        let level = leaf_level(job.problem_views.min_vdi_deg);
        let n = scene.objects.len();
        let mut rng = crate::math::rng::Rng::new(3);
        let mut held = Vec::new();
        let (mut answers, mut visible_total, mut tighter) = (0, 0, 0);
        for (k, (i, j)) in [(0, 0), (2, 1), (5, 3), (3, 5), (1, 4), (0, 0)]
            .into_iter()
            .enumerate()
        {
            let region = grid.cell_box([i, 0, j], [i + 1, 1, j + 1]);
            let share = [0.05, 0.3, 0.7, 0.01, 1.0, 0.15][k];
            let mut set = ObjectSet::new(n);
            for o in 0..n as u32 {
                if rng.f64() < share {
                    set.insert(o);
                }
            }
            visible_total += set.count();
            let dense = RegionCosts::new(&ctx, &region, None, &Counters::new());
            let costs = RegionCosts::new(&ctx, &region, Some(&set), &Counters::new());
            let objects: Vec<Cost> = (0..n)
                .map(|o| {
                    if set.contains(o as u32) {
                        dense.objects[o]
                    } else {
                        Cost::default()
                    }
                })
                .collect();
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
            assert!(costs.objects == objects, "objects of set {k}");
            assert!(costs.nodes == nodes, "clusters of set {k}");
            for id in 0..h.nodes.len() {
                let d = costs.down[id] as usize;
                if nodes[id] != Cost::default() {
                    assert!(
                        nodes[d] == nodes[id]
                            && (id..h.nodes[id].subtree_end as usize).contains(&d)
                    );
                }
                // A cluster with a child that costs nothing is stepped past.
                if let Some([l, r]) = h.nodes[id].children
                    && (nodes[l as usize] == Cost::default())
                        != (nodes[r as usize] == Cost::default())
                {
                    assert_ne!(d, id, "cluster {id} of set {k}");
                }
            }
            // The walks' spheres hold every object that costs something,
            // are never larger than the clusters' own, and are smaller where
            // little of a cluster is visible.
            for (id, node) in h.nodes.iter().enumerate() {
                if nodes[id] == Cost::default() {
                    continue;
                }
                let sp = costs.sphere(&h, id as u32);
                assert!(sp.radius <= node.sphere.radius, "cluster {id} of set {k}");
                tighter += usize::from(sp.radius < node.sphere.radius);
                for &o in &h.order[node.objects.0 as usize..node.objects.1 as usize] {
                    let os = h.object_spheres[o as usize];
                    assert!(
                        objects[o as usize] == Cost::default()
                            || sp.center.distance(os.center) + os.radius
                                <= sp.radius * (1.0 + 1e-9) + 1e-9,
                        "object {o} outside the sphere of cluster {id}, set {k}"
                    );
                }
            }
            for vdi in Vdi::all_at(level) {
                let cone = enclosing_cone(&region, &vdi, &ctx.lens);
                let t = ctx
                    .model
                    .frame_time(enclosed_cost(&ctx, &costs, &cone, &region, None));
                for f in [0.9, 1.0 - 1e-6, 1.0 + 1e-6, 1.1] {
                    assert_eq!(exceeds(&ctx, &costs, &cone, t * f), t > t * f);
                    answers += 1;
                }
            }
            // Every other set stays alive, so the next takes fresh buffers
            // or another region's.
            if k % 2 == 0 {
                held.push(costs);
            }
        }
        assert!(answers > 1000 && visible_total > 0 && visible_total < 6 * n);
        assert!(tighter > 0);
    }
}
