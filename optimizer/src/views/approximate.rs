//! The approximation itself: the kd tree over the grid, the direction
//! quadtrees per region, and the recursion that keeps problem views.

use rayon::prelude::*;

use crate::api::job::Job;
use crate::math::enclosing::{Enclosing, enclosing_cone};
use crate::math::geom::{Aabb, Vdi};
use crate::math::grid::Grid;
use crate::views::context::{Context, Counters};
use crate::views::costs::{
    CellCuts, CpvCut, Frontier, Listable, RegionCosts, cpv_cut, exceeds_target,
};
use crate::views::{Cpv, KdNode, PairCounts, ProblemViews, leaf_level};

/// How far above the target (a fraction of it: 20 %) a minimum-size problem
/// view's estimate may be for it to be refined one level deeper than
/// `problem_views.refine_levels`.
const NEAR_TARGET: f64 = 0.2;

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
            // At the grid plane nearest the box's middle (the lower of
            // two as near): the view space's side cells are cut by the
            // grid's phase, so half the cell count would put a box's sides
            // up to a cell off its middle at every level, differently for
            // each phase.
            let centre = 0.5 * (grid.boundary(axis, lo[axis]) + grid.boundary(axis, hi[axis]));
            let off = |m: u32| (grid.boundary(axis, m) - centre).abs();
            let mid = (lo[axis] + 1..hi[axis])
                .min_by(|&a, &b| off(a).total_cmp(&off(b)))
                .expect("a range of two cells or more has an inner boundary");
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
        });
    }
    kd
}

/// A set of VDIs of quadtree levels up to `leaf`, one bit each (level by
/// level, face by face, row by row): a region's open directions, the
/// problem views of its parent region and all their ancestors.
struct VdiSet {
    bits: Vec<u64>,
}

impl VdiSet {
    /// The bit of `v`.
    fn index(v: &Vdi) -> usize {
        let per_face = 1usize << (2 * u32::from(v.level));
        6 * (per_face - 1) / 3
            + usize::from(v.face) * per_face
            + ((v.iv as usize) << v.level)
            + v.iu as usize
    }

    /// The VDIs of `leaves` (of level at most `leaf`) and every quadtree
    /// ancestor of them.
    fn with_ancestors(leaves: &[Vdi], leaf: u8) -> VdiSet {
        let all = 6 * ((1usize << (2 * u32::from(leaf) + 2)) - 1) / 3;
        let mut bits = vec![0u64; all.div_ceil(64)];
        for l in leaves {
            for up in 0..=l.level {
                let i = Self::index(&Vdi {
                    face: l.face,
                    level: l.level - up,
                    iu: l.iu >> up,
                    iv: l.iv >> up,
                });
                bits[i / 64] |= 1 << (i % 64);
            }
        }
        VdiSet { bits }
    }

    fn contains(&self, v: &Vdi) -> bool {
        let i = Self::index(v);
        self.bits
            .get(i / 64)
            .is_some_and(|w| w >> (i % 64) & 1 == 1)
    }
}

struct RegionResult {
    cpvs: Vec<Cpv>,
    /// Per cluster, how often `cpvs` list it (empty when there are none).
    node_counts: Vec<PairCounts>,
    cones: u64,
    regions: u64,
    /// Problem views of minimum size proven by refinement.
    refined: u64,
}

impl RegionResult {
    fn empty(cones: u64, regions: u64, refined: u64) -> RegionResult {
        RegionResult {
            cpvs: Vec::new(),
            node_counts: Vec::new(),
            cones,
            regions,
            refined,
        }
    }
}

/// What the proofs of one minimum-size problem view's sub-directions and
/// parts share: its cell's costs (closest distances, levels of detail,
/// visible set: conservative for every part) and the clusters the problem
/// view's own enclosing set does not exclude ([`Frontier`]): every view of
/// a part in a sub-direction is a view of the problem view, so the others
/// are seen by none, and each proof starts below the clusters that set
/// cuts instead of at the root.
struct Proofs<'a, 'c> {
    ctx: &'a Context<'c>,
    costs: &'a RegionCosts,
    /// The problem view's own enclosing set.
    outer: Enclosing,
    frontier: Frontier,
}

impl<'a, 'c> Proofs<'a, 'c> {
    fn new(ctx: &'a Context<'c>, costs: &'a RegionCosts, region: &Aabb, vdi: &Vdi) -> Self {
        let outer = enclosing_cone(region, vdi, &ctx.lens);
        let frontier = Frontier::within(ctx, costs, &outer);
        Proofs {
            ctx,
            costs,
            outer,
            frontier,
        }
    }

    /// True when the problem view's own enclosing time exceeds `t` (the
    /// frontier holds everything its set does not exclude).
    fn exceeds_own(&self, t: f64) -> bool {
        self.frontier.exceeds(self.ctx, self.costs, &self.outer, t)
    }

    /// True when the enclosing time of (`region`, `d`), `region` in the
    /// problem view's cell and `d` in its VDI, exceeds the target.
    fn exceed(&self, region: &Aabb, d: &Vdi) -> bool {
        let cone = enclosing_cone(region, d, &self.ctx.lens);
        self.frontier
            .exceeds(self.ctx, self.costs, &cone, self.ctx.t_max)
    }
}

/// True when every part of (`region`, `vdi`) `levels` levels down (the VDI
/// split in four per level, parts outside the pitch range skipped) has an
/// enclosing time within the target, so no view of (`region`, `vdi`)
/// exceeds it. Stops at the first part that exceeds the target at the
/// deepest level. The region's costs (closest distances, levels of detail,
/// visible set) are its cell's.
fn proven_by_refinement(
    p: &Proofs,
    region: &Aabb,
    vdi: &Vdi,
    levels: u8,
    cones: &mut u64,
    hint: &mut Hint,
) -> bool {
    levels > 0 && !first_unproven(p, region, vdi, levels, cones, hint)
}

/// Per quadtree level, the child (0..4) through which the last search of
/// [`first_unproven`] found an unproven direction: tried first next time
/// (neighbouring problem views are often unproven the same way).
type Hint = [u8; 32];

/// [`unproven_directions`] stopping at the first unproven finest direction,
/// trying first at each level the child `hint` names, which it updates.
fn first_unproven(
    p: &Proofs,
    region: &Aabb,
    vdi: &Vdi,
    levels: u8,
    cones: &mut u64,
    hint: &mut Hint,
) -> bool {
    let children = vdi.children();
    let level = usize::from(children[0].level).min(hint.len() - 1);
    let first = usize::from(hint[level]);
    for k in (0..4).map(|k| (k + first) % 4) {
        let child = &children[k];
        if !p.ctx.pitch_overlaps(child) {
            continue;
        }
        *cones += 1;
        if !p.exceed(region, child) {
            continue;
        }
        if levels == 1 || first_unproven(p, region, child, levels - 1, cones, hint) {
            hint[level] = k as u8;
            return true;
        }
    }
    false
}

/// The halves of `b` along each axis at least half as long as its longest
/// (2, 4 or 8 boxes), in a fixed order.
fn halves(b: &Aabb) -> Vec<Aabb> {
    let ext = b.max - b.min;
    let longest = ext.max_element();
    let c = b.center();
    let mut out = vec![*b];
    for a in 0..3 {
        if ext[a] < 0.5 * longest || ext[a] <= 0.0 {
            continue;
        }
        out = out
            .into_iter()
            .flat_map(|x| {
                let (mut lo, mut hi) = (x, x);
                lo.max[a] = c[a];
                hi.min[a] = c[a];
                [lo, hi]
            })
            .collect();
    }
    out
}

/// Whether refinement leaves some finest part of `vdi` (refined `levels`
/// times, parts outside the pitch range skipped) unproven from `region`: a
/// part whose enclosing time, and each of whose coarser ancestors' below
/// `vdi`, exceeds the target. Lists them all in `out` ([`first_unproven`]
/// stops at the first).
fn unproven_directions(
    p: &Proofs,
    region: &Aabb,
    vdi: &Vdi,
    levels: u8,
    cones: &mut u64,
    out: &mut Vec<Vdi>,
) -> bool {
    let mut any = false;
    for child in vdi.children() {
        if !p.ctx.pitch_overlaps(&child) {
            continue;
        }
        *cones += 1;
        if !p.exceed(region, &child) {
            continue;
        }
        any |= if levels > 1 {
            unproven_directions(p, region, &child, levels - 1, cones, out)
        } else {
            out.push(child);
            true
        };
    }
    any
}

/// What the search for a cell's unproven parts keeps from one problem view
/// to the next: the smallest box holding every unproven part so far; and,
/// for the VDI at hand, the finest directions refinement leaves unproven
/// from the whole cell, each with its frontier once a part has tested it.
struct Parts {
    union: Option<Aabb>,
    directions: Vec<(Vdi, Option<Frontier>)>,
    hint: Hint,
}

impl Parts {
    fn new() -> Parts {
        Parts {
            union: None,
            directions: Vec::new(),
            hint: [0; 32],
        }
    }

    fn covers(&self, b: &Aabb) -> bool {
        self.union.is_some_and(|a| a.contains_box(b))
    }

    fn record(&mut self, part: Aabb) {
        self.union = Some(self.union.map_or(part, |a| a.union(&part)));
    }

    /// True when no view from `part` along the VDI at hand exceeds the
    /// target: every finest direction the whole cell leaves unproven has an
    /// enclosing time within the target from the part (the others are
    /// proven from the cell, which holds the part). Stops at the first that
    /// exceeds it. (Testing the coarser directions above them first, as
    /// refinement does, took more cones: from the cell they exceed.)
    ///
    /// Each direction's walks start from its own frontier, narrowed from
    /// the problem view's to the direction's set from the whole cell when
    /// a part first tests it: every view from a part along the direction
    /// is a view of that set, and the cell's halves and quarters test the
    /// same direction again and again (on a fly-over's quarter, about three
    /// fifths fewer sphere tests in these walks, building the frontiers
    /// included).
    ///
    /// A direction that exceeds the target from one part often does from
    /// the next: it moves to the front of the list, so an unproven part is
    /// found unproven after fewer walks (the answer does not depend on the
    /// order).
    fn proven(&mut self, p: &Proofs, cell: &Aabb, part: &Aabb, cones: &mut u64) -> bool {
        let exceeding = self.directions.iter_mut().position(|(d, frontier)| {
            *cones += 1;
            let frontier = frontier.get_or_insert_with(|| {
                let set = enclosing_cone(cell, d, &p.ctx.lens);
                p.frontier.narrowed(p.ctx, p.costs, &set)
            });
            let cone = enclosing_cone(part, d, &p.ctx.lens);
            frontier.exceeds(p.ctx, p.costs, &cone, p.ctx.t_max)
        });
        match exceeding {
            None => true,
            Some(k) => {
                self.directions[..=k].rotate_right(1);
                false
            }
        }
    }

    /// Adds every part of `region` (the cell), halved `levels.split` times,
    /// from which some view in `vdi` may exceed the target (parts proven
    /// with the VDI's finest directions left out); true when there is one,
    /// false when refinement proves the VDI from the whole cell or every
    /// part is proven, so the VDI can be dropped. The costs stay the cell's
    /// (closest distances, levels of detail and the visible set of the whole
    /// cell), which are conservative for its parts.
    ///
    /// Once the union of unproven parts is the whole cell, a VDI is only
    /// refined from the cell (splitting could only drop it: conservative).
    /// Otherwise the finest directions the cell leaves unproven are found
    /// once, by the same refinement (a part only has to prove those), and
    /// the parts are searched from the halves down: a proven part proves
    /// every part inside it, and a part inside the union is skipped once
    /// the VDI is known to keep a problem (it cannot grow the union).
    /// (Trying the cell's corner parts and the last unproven part first,
    /// to grow the union sooner where the problem is real, gave the same
    /// placements after more walks: most parts are proven.)
    fn add(
        &mut self,
        p: &Proofs,
        region: &Aabb,
        vdi: &Vdi,
        levels: Levels,
        cones: &mut u64,
    ) -> bool {
        let depth = levels.split;
        if self.covers(region) {
            // Only whether refinement proves the VDI matters now.
            return !proven_by_refinement(p, region, vdi, levels.refine, cones, &mut self.hint);
        }
        let mut unproven = Vec::new();
        if !unproven_directions(p, region, vdi, levels.refine, cones, &mut unproven) {
            // Refinement proves it from the whole cell.
            return false;
        }
        self.directions.clear();
        self.directions
            .extend(unproven.into_iter().map(|d| (d, None)));
        let mut found = false;
        self.walk(p, region, region, depth, &mut found, cones);
        found
    }

    /// Searches the halves of `region`, a part of `cell`, `depth` levels
    /// down.
    fn walk(
        &mut self,
        p: &Proofs,
        cell: &Aabb,
        region: &Aabb,
        depth: u8,
        found: &mut bool,
        cones: &mut u64,
    ) {
        for part in halves(region) {
            if *found && self.covers(&part) {
                continue;
            }
            if self.proven(p, cell, &part, cones) {
                continue;
            }
            if depth > 1 {
                self.walk(p, cell, &part, depth - 1, found, cones);
            } else {
                *found = true;
                self.record(part);
            }
        }
    }
}

/// The quadtree level of minimum-size VDIs, how many levels below it
/// problem views are refined, how far above the target (a fraction of it)
/// a problem view is refined one level more, and how many times a problem
/// cell is halved.
#[derive(Clone, Copy)]
struct Levels {
    leaf: u8,
    refine: u8,
    near_target: f64,
    split: u8,
}

/// Per cluster, what the lists `cuts` of one cell's CPVs hold of it
/// ([`PairCounts`]): a cluster below a cut node of a CPV is listed there
/// when [`Listable::ok`].
fn cell_pair_counts(
    ctx: &Context,
    costs: &RegionCosts,
    listable: &Listable,
    cuts: &[CpvCut],
) -> Vec<PairCounts> {
    let mut counts = vec![PairCounts::default(); ctx.hierarchy.nodes.len()];
    for cut in cuts {
        for &(m, c) in &cut.explicit {
            let e = &mut counts[m as usize];
            e.pairs += 1;
            e.explicit += 1;
            e.partial += u32::from(c != costs.nodes[m as usize]);
            e.cells = 1;
        }
    }
    let below = CellCuts::new(ctx, listable, cuts);
    for &m in &below.listed {
        let e = &mut counts[m as usize];
        e.pairs += below.count(m);
        e.bit_words += below.words as u32;
        e.cells = 1;
    }
    counts
}

/// The lists of one cell's CPVs, (`region`, each of `vdis`): what may be
/// listed there, each CPV's cut, and per cluster what the lists hold of it
/// ([`cell_pair_counts`]).
fn cell_lists(
    ctx: &Context,
    costs: &RegionCosts,
    region: &Aabb,
    vdis: &[Vdi],
) -> (Listable, Vec<CpvCut>, Vec<PairCounts>) {
    let listable = Listable::new(ctx, costs, region);
    let cuts: Vec<CpvCut> = vdis
        .iter()
        .map(|vdi| cpv_cut(ctx, costs, &listable, region, vdi))
        .collect();
    let counts = cell_pair_counts(ctx, costs, &listable, &cuts);
    (listable, cuts, counts)
}

/// Per-cluster counts `a` and `b` summed (an empty list counts nothing).
fn sum_counts(a: Vec<PairCounts>, b: Vec<PairCounts>) -> Vec<PairCounts> {
    if a.is_empty() {
        return b;
    }
    let mut sum = a;
    for (x, y) in sum.iter_mut().zip(b) {
        *x += y;
    }
    sum
}

/// The minimum-size VDIs of `open` (and within the pitch range) whose
/// enclosing cones from `region` exceed the target with `costs`, found top
/// down; `None` once the run is cancelled.
fn problem_vdis(
    ctx: &Context,
    costs: &RegionCosts,
    region: &Aabb,
    open: &VdiSet,
    levels: Levels,
    cones: &mut u64,
) -> Option<Vec<Vdi>> {
    let mut problems: Vec<Vdi> = Vec::new();
    let mut stack: Vec<Vdi> = (0..6u8).rev().map(Vdi::face).collect();
    while let Some(vdi) = stack.pop() {
        // A region near the kd tree's root sees most of the scene in every
        // direction: its walks take a while, so a cancel is heard here too.
        if ctx.cancelled() {
            return None;
        }
        if !open.contains(&vdi) || !ctx.pitch_overlaps(&vdi) {
            continue;
        }
        *cones += 1;
        if !exceeds_target(ctx, costs, &enclosing_cone(region, &vdi, &ctx.lens)) {
            continue;
        }
        if vdi.level == levels.leaf {
            problems.push(vdi);
        } else {
            stack.extend(vdi.children().into_iter().rev());
        }
    }
    Some(problems)
}

fn process(
    ctx: &Context,
    counters: &Counters,
    kd: &[KdNode],
    id: u32,
    parent_problems: &[Vdi],
    levels: Levels,
) -> RegionResult {
    let node = &kd[id as usize];
    if ctx.cancelled() {
        return RegionResult::empty(0, 0, 0);
    }
    let region = node.aabb;
    let mut cones = 0u64;
    let mut open = VdiSet::with_ancestors(parent_problems, levels.leaf);
    // A single cell with a coarse visibility tier: its coarse set first,
    // and only the problem views it leaves are tested with the final set.
    let coarse = match node.children {
        None => ctx.visibility.and_then(|v| v.coarse_cell(node.lo)),
        Some(_) => None,
    };
    if let Some(set) = coarse {
        let costs = RegionCosts::new(ctx, &region, Some(&set), counters);
        let Some(problems) = problem_vdis(ctx, &costs, &region, &open, levels, &mut cones) else {
            return RegionResult::empty(cones, 1, 0);
        };
        if problems.is_empty() {
            return RegionResult::empty(cones, 1, 0);
        }
        open = VdiSet::with_ancestors(&problems, levels.leaf);
    }
    let costs = RegionCosts::of_kd(ctx, node, counters);
    let Some(mut problems) = problem_vdis(ctx, &costs, &region, &open, levels, &mut cones) else {
        return RegionResult::empty(cones, 1, 0);
    };
    if problems.is_empty() {
        return RegionResult::empty(cones, 1, 0);
    }
    match node.children {
        None => {
            // Problem views of minimum size that a finer subdivision proves
            // are dropped.
            // The cell's parts where each remaining problem view may still
            // exceed the target; the CPVs of the cell share the smallest box
            // holding them all as their region, so where a problem ends
            // inside a cell the grid's phase matters less.
            let before = problems.len() as u64;
            let mut parts = Parts::new();
            // A problem view whose estimate is just above the target is
            // refined one level deeper: there refinement may still prove
            // it, where one far above is a real problem (the deeper level
            // would cost four times the cones for nothing).
            let deeper = |p: &Proofs, cones: &mut u64| {
                *cones += 1;
                let near = ctx.t_max * (1.0 + levels.near_target);
                let refine = if !p.exceeds_own(near) {
                    levels.refine + 1
                } else {
                    levels.refine
                };
                Levels { refine, ..levels }
            };
            // Without refinement nothing is proven here.
            if levels.refine > 0 && levels.split > 0 {
                // The problem views far above the target first: their
                // problems are real and soon fill the cell, after which a
                // near-target one is only refined from the cell (no listing
                // of its finest directions, no part walks). Each keeps or
                // drops its VDI by a proof either way; the CPVs stay in VDI
                // order.
                let proofs: Vec<(Proofs, Levels)> = problems
                    .iter()
                    .map(|vdi| {
                        let p = Proofs::new(ctx, &costs, &region, vdi);
                        let l = deeper(&p, &mut cones);
                        (p, l)
                    })
                    .collect();
                let mut order: Vec<usize> = (0..problems.len()).collect();
                order.sort_by_key(|&k| proofs[k].1.refine);
                let mut keep = vec![false; problems.len()];
                for k in order {
                    let (p, l) = &proofs[k];
                    keep[k] = parts.add(p, &region, &problems[k], *l, &mut cones);
                }
                drop(proofs);
                let mut k = 0;
                problems.retain(|_| {
                    k += 1;
                    keep[k - 1]
                });
            } else if levels.refine > 0 {
                let mut hint = [0; 32];
                problems.retain(|vdi| {
                    let p = Proofs::new(ctx, &costs, &region, vdi);
                    let l = deeper(&p, &mut cones);
                    !proven_by_refinement(&p, &region, vdi, l.refine, &mut cones, &mut hint)
                });
            }
            let refined = before - problems.len() as u64;
            if problems.is_empty() {
                return RegionResult::empty(cones, 1, refined);
            }
            let region = parts.union.unwrap_or(region);
            // Each CPV keeps only how many clusters it lists; the lists are
            // counted per cluster here and computed again, a cell at a
            // time, by candidate generation.
            let (listable, cuts, node_counts) = cell_lists(ctx, &costs, &region, &problems);
            let cpvs = problems
                .into_iter()
                .zip(cuts)
                .map(|(vdi, cut)| Cpv {
                    kd: id,
                    region,
                    vdi,
                    cost: cut.cost,
                    time: ctx.model.frame_time(cut.cost),
                    listed: cut.listed(&listable),
                })
                .collect::<Vec<Cpv>>();
            let pairs: u64 = cpvs.iter().map(|c| u64::from(c.listed)).sum();
            counters.add_pairs(pairs);
            RegionResult {
                cpvs,
                node_counts,
                cones,
                regions: 1,
                refined,
            }
        }
        Some([l, r]) => {
            drop(costs);
            let (mut a, b) = rayon::join(
                || process(ctx, counters, kd, l, &problems, levels),
                || process(ctx, counters, kd, r, &problems, levels),
            );
            a.cpvs.extend(b.cpvs);
            RegionResult {
                cpvs: a.cpvs,
                node_counts: sum_counts(a.node_counts, b.node_counts),
                cones: cones + a.cones + b.cones,
                regions: 1 + a.regions + b.regions,
                refined: a.refined + b.refined,
            }
        }
    }
}

/// Approximates the problem view space of `job`, counting its work in
/// `counters`; stops early (with what it found so far) once the run is
/// cancelled.
pub fn approximate(ctx: &Context, job: &Job, counters: &Counters) -> ProblemViews {
    approximate_near(ctx, job, counters, NEAR_TARGET)
}

/// [`approximate`] with problem views at most `near_target` (a fraction of
/// the target) above the target refined one level deeper.
pub(super) fn approximate_near(
    ctx: &Context,
    job: &Job,
    counters: &Counters,
    near_target: f64,
) -> ProblemViews {
    let grid = job.grid();
    let kd = build_kd(&grid);
    let level = leaf_level(job.problem_views.min_vdi_deg);
    let all = Vdi::all_at(level);
    let levels = Levels {
        leaf: level,
        refine: job.problem_views.refine_levels,
        near_target,
        split: job.problem_views.split_levels,
    };
    let res = process(ctx, counters, &kd, 0, &all, levels);
    ProblemViews {
        grid,
        kd,
        cpvs: res.cpvs,
        node_counts: if res.node_counts.is_empty() {
            vec![PairCounts::default(); ctx.hierarchy.nodes.len()]
        } else {
            res.node_counts
        },
        leaf_level: level,
        cone_evaluations: res.cones,
        regions_visited: res.regions,
        refined_away: res.refined,
    }
}

/// The problem views of `job`, a part of the job whose problem views are
/// `whole` on the same grid (a tile: its view space's sides on the grid's
/// planes), taken from `whole` instead of approximated again: a cell's CPVs
/// depend on the cell alone (a direction proven for a region is proven for
/// every cell in it, so the kd tree above a cell only saves work), so they
/// are `whole`'s CPVs of the cells inside `job`'s view space, in the order of
/// `job`'s kd tree; the per-cluster counts are made again from their lists.
/// The work counters are zero (the work was `whole`'s).
pub fn restrict(
    ctx: &Context,
    job: &Job,
    whole: &ProblemViews,
    counters: &Counters,
) -> ProblemViews {
    let grid = job.grid();
    let kd = build_kd(&grid);
    // The kd leaf of each cell (ids are in depth-first order, the order
    // `process` gives its CPVs).
    let mut leaf_of = vec![u32::MAX; grid.len() as usize];
    for (id, n) in kd.iter().enumerate() {
        if n.children.is_none() {
            leaf_of[grid.linear(n.lo) as usize] = id as u32;
        }
    }
    let mut cpvs: Vec<Cpv> = whole
        .cpvs
        .iter()
        .filter_map(|c| {
            let cell = grid.cell_of(whole.kd[c.kd as usize].aabb.center())?;
            Some(Cpv {
                kd: leaf_of[grid.linear(cell) as usize],
                ..c.clone()
            })
        })
        .collect();
    // Stable: a cell's CPVs keep `whole`'s order.
    cpvs.sort_by_key(|c| c.kd);
    let cells = ProblemViews::cells_of(&cpvs);
    let node_counts = cells
        .par_iter()
        .fold(Vec::new, |sum: Vec<PairCounts>, r| {
            let cell = &cpvs[r.start as usize..r.end as usize];
            let costs = RegionCosts::of_kd(ctx, &kd[cell[0].kd as usize], counters);
            let vdis: Vec<Vdi> = cell.iter().map(|c| c.vdi).collect();
            sum_counts(sum, cell_lists(ctx, &costs, &cell[0].region, &vdis).2)
        })
        .reduce(Vec::new, sum_counts);
    ProblemViews {
        grid,
        kd,
        cpvs,
        node_counts: if node_counts.is_empty() {
            vec![PairCounts::default(); ctx.hierarchy.nodes.len()]
        } else {
            node_counts
        },
        leaf_level: whole.leaf_level,
        cone_evaluations: 0,
        regions_visited: 0,
        refined_away: 0,
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// A tile's problem views taken from the whole job's are the ones the
    /// tile's own approximation finds: the same CPVs (cell, region,
    /// direction, cost), in the same order, and the same per-cluster counts;
    /// the tiles together hold the whole's CPVs.
    #[test]
    fn restricted_problem_views_are_the_tiles_own() {
        use crate::control::Control;
        use crate::scene::hierarchy::Hierarchy;
        use crate::testutil::{synthetic_city, synthetic_job};
        let scene = synthetic_city(3, 6, 5);
        let mut job = synthetic_job(6, 5);
        job.target_frame_time_ms = 3.0;
        job.problem_views.grid_origin = [10.0, 0.0, 10.0];
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let whole = approximate(&ctx, &job, &Counters::new());
        assert!(whole.cpvs.len() > 100, "{}", whole.cpvs.len());
        for tiles in [[2, 2], [3, 1], [1, 4]] {
            let mut found = 0;
            for t in crate::place::tiles::tile_jobs(&job, tiles) {
                let ctx = Context::new(&scene, &h, None, &t, Control::default());
                let own = approximate(&ctx, &t, &Counters::new());
                let taken = restrict(&ctx, &t, &whole, &Counters::new());
                assert_eq!(
                    format!("{:?}", taken.cpvs),
                    format!("{:?}", own.cpvs),
                    "{tiles:?}"
                );
                assert_eq!(taken.node_counts, own.node_counts, "{tiles:?}");
                assert_eq!(taken.kd.len(), own.kd.len());
                found += taken.cpvs.len();
            }
            assert_eq!(found, whole.cpvs.len(), "{tiles:?}");
        }
    }

    /// A kd node splits at the grid plane nearest its middle, wherever the
    /// grid's phase puts the thin cells at the view space's sides.
    #[test]
    fn kd_nodes_split_at_the_plane_nearest_their_middle() {
        // 100 × 1 × 1 m, cells of 23 m anchored at 11.5: planes at 11.5,
        // 34.5, 57.5, 80.5, so five cells; half the count would split at
        // 34.5, 15.5 m off the middle, the nearest plane is 57.5.
        let grid = Grid::new(
            DVec3::ZERO,
            DVec3::new(100.0, 1.0, 1.0),
            23.0,
            DVec3::splat(11.5),
        );
        assert_eq!(grid.counts, [5, 1, 1]);
        let kd = build_kd(&grid);
        let [l, r] = kd[0].children.expect("five cells split");
        assert_eq!(kd[l as usize].aabb.max.x, 57.5);
        assert_eq!(kd[r as usize].aabb.min.x, 57.5);
        // Its left part, 0..57.5 (planes 11.5, 34.5): the middle 28.75 is
        // nearest 34.5; its right part, 57.5..100: 80.5.
        let [ll, _] = kd[l as usize].children.unwrap();
        assert_eq!(kd[ll as usize].aabb.max.x, 34.5);
        let [rl, _] = kd[r as usize].children.unwrap();
        assert_eq!(kd[rl as usize].aabb.max.x, 80.5);
        // Every leaf is one cell, each cell one leaf.
        let leaves: Vec<&KdNode> = kd.iter().filter(|n| n.children.is_none()).collect();
        assert_eq!(leaves.len(), 5);
        assert!(leaves.iter().all(|n| n.hi[0] - n.lo[0] == 1));
    }

    /// The search that stops at the first unproven sub-direction answers as
    /// the full listing does, whichever child its hint tries first, fresh
    /// or carried from one problem view to the next: a proof never depends
    /// on the order in which sub-directions are tried. Both answers occur
    /// (so the comparison could fail).
    #[test]
    fn first_unproven_agrees_with_the_listing_for_every_hint() {
        use crate::control::Control;
        use crate::scene::hierarchy::Hierarchy;
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let kd = build_kd(&job.grid());
        let level = leaf_level(job.problem_views.min_vdi_deg);
        let (mut proven, mut unproven) = (0, 0);
        for node in kd.iter().filter(|k| k.children.is_none()).step_by(3) {
            let costs = RegionCosts::of_kd(&ctx, node, &Counters::new());
            let region = node.aabb;
            let mut carried: Hint = [0; 32];
            for vdi in Vdi::all_at(level) {
                let cone = enclosing_cone(&region, &vdi, &ctx.lens);
                if !ctx.pitch_overlaps(&vdi) || !exceeds_target(&ctx, &costs, &cone) {
                    continue;
                }
                let p = Proofs::new(&ctx, &costs, &region, &vdi);
                for levels in 1..=2u8 {
                    let cones = &mut 0;
                    let mut listed = Vec::new();
                    let any = unproven_directions(&p, &region, &vdi, levels, cones, &mut listed);
                    assert_eq!(any, !listed.is_empty());
                    for start in 0..4u8 {
                        let mut hint = [start; 32];
                        let first = first_unproven(&p, &region, &vdi, levels, cones, &mut hint);
                        assert_eq!(first, any, "{vdi:?}, {levels} levels, hint {start}");
                    }
                    let first = first_unproven(&p, &region, &vdi, levels, cones, &mut carried);
                    assert_eq!(first, any, "{vdi:?}, {levels} levels, carried hint");
                    if any {
                        unproven += 1;
                    } else {
                        proven += 1;
                    }
                }
            }
        }
        assert!(
            proven > 0 && unproven > 0,
            "{proven} proven, {unproven} not"
        );
    }

    /// Every VDI down to the leaf level has a bit of its own, and a set
    /// holds exactly its leaves and their ancestors.
    #[test]
    fn vdi_set_holds_leaves_and_ancestors_only() {
        let leaf = 3u8;
        let mut all = Vec::new();
        for level in 0..=leaf {
            for face in 0..6u8 {
                for iv in 0..1u32 << level {
                    for iu in 0..1u32 << level {
                        all.push(Vdi {
                            face,
                            level,
                            iu,
                            iv,
                        });
                    }
                }
            }
        }
        let mut idx: Vec<usize> = all.iter().map(VdiSet::index).collect();
        idx.sort_unstable();
        idx.dedup();
        assert_eq!(idx.len(), all.len());
        assert_eq!(*idx.last().unwrap(), all.len() - 1);
        let leaves = [
            Vdi {
                face: 4,
                level: 3,
                iu: 5,
                iv: 2,
            },
            Vdi {
                face: 1,
                level: 2,
                iu: 0,
                iv: 3,
            },
        ];
        let set = VdiSet::with_ancestors(&leaves, leaf);
        let expected = |v: &Vdi| {
            leaves.iter().any(|l| {
                l.face == v.face
                    && l.level >= v.level
                    && l.iu >> (l.level - v.level) == v.iu
                    && l.iv >> (l.level - v.level) == v.iv
            })
        };
        let held = all.iter().filter(|v| set.contains(v)).count();
        assert_eq!(held, 4 + 3);
        for v in &all {
            assert_eq!(set.contains(v), expected(v), "{v:?}");
        }
    }
}
