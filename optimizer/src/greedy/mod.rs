//! Greedy selection with lazy recalculation (paper §5, DESIGN §2.7).
//!
//! `Δt_{i,CPV} = max(0, t_CPV − max(t^i_CPV, t_max))` where `t^i_CPV` is the
//! CPV's time with the cluster's current representation (its geometry, or
//! descendant impostors already placed there) replaced by impostor `i`;
//! `s_i = Σ_CPV Δt_{i,CPV} / m_i`. A max-heap holds scores stamped with the
//! state version they were computed in; a stale top is recomputed (with a
//! fixed-size batch of the stale keys below it) and re-pushed, a fresh top is
//! accepted. Scores are computed a block at a time: the shafts of one cluster,
//! angle and axis serve growing prefixes of the same cells, so a run of them
//! with the same layer count shares one walk over the cells (the sums are the
//! same, bit for bit, as scoring each alone); a block's fresh keys make its
//! older keys outdated, and outdated keys are dropped when popped. In exact
//! arithmetic no score increases when an impostor is added (`sum` and
//! `primitives` modes), so a fresh top is the greedy choice; in
//! `max` mode, and by rounding, lazy recalculation is a heuristic. Ties are
//! broken by the lower candidate id and the batch never depends on the
//! thread count, so the result is deterministic.
//!
//! Accepting `i` adds it to every CPV it accelerates, replacing descendant
//! impostors there; an impostor left in no CPV is deleted and its memory
//! regained.

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::ops::Range;

use rayon::prelude::*;

use crate::candidates::{Candidate, Candidates};
use crate::math::IdRange;
use crate::model::cost::Cost;
use crate::views::{Context, Cpv, ProblemViews};

/// The selection: which candidates are impostors and where they are used.
#[derive(Clone, Debug)]
pub struct Selection {
    /// Per CPV: the candidate ids of its impostors (an antichain of clusters).
    pub cpv_impostors: Vec<Vec<u32>>,
    /// Per CPV: the cost after replacement.
    pub cpv_cost: Vec<Cost>,
    /// Per candidate: the number of CPVs using it (0 = not an impostor).
    pub uses: Vec<u32>,
    /// Greedy choices made (including impostors later replaced).
    pub accepted: u64,
    /// Score evaluations.
    pub evaluations: u64,
    /// Impostors removed by the pruning pass.
    pub pruned: u64,
}

impl Selection {
    /// Candidate ids of the final impostors, ascending.
    pub fn impostors(&self) -> Vec<u32> {
        (0..self.uses.len() as u32)
            .filter(|&i| self.uses[i as usize] > 0)
            .collect()
    }
}

/// Heap key: higher score first, then lower candidate id.
#[derive(Clone, Copy, Debug)]
struct Key {
    score: f64,
    id: u32,
}

impl PartialEq for Key {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Key {
    fn cmp(&self, o: &Self) -> Ordering {
        self.score.total_cmp(&o.score).then(o.id.cmp(&self.id))
    }
}

/// The optimisation state shared by the lazy and naive variants.
struct State<'a> {
    ctx: &'a Context<'a>,
    pv: &'a ProblemViews,
    cands: &'a [Candidate],
    all: &'a Candidates,
    /// Per cluster: for the CPVs where it is adjusted, in CPV order, what
    /// the impostors placed below it there save against its objects.
    adjustments: Vec<Vec<Cost>>,
    /// Per (CPV, cluster): covered when an impostor of the cluster or an
    /// ancestor is placed there (a subtree is a range of pre-order ids),
    /// adjusted when one of a descendant is, so its representation is its
    /// objects' cost minus its adjustment (set on the whole ancestor chain
    /// of every impostor).
    marks: NodeMarks,
    /// Per kd node (cell): how many of its CPVs are still above `t_max`. A
    /// solved CPV adds nothing to any score, so cells without unsolved CPVs
    /// are skipped when scoring.
    unsolved_in_cell: Vec<u32>,
    /// Per kd node (cell): the number of choices after which one of its
    /// CPVs last changed (0: never). A score depends only on the CPVs it
    /// serves, so a key computed after choice `v` is still exact while no
    /// cell it serves changed after `v`.
    cell_changed: Vec<u64>,
    /// Per CPV: its frame time less `t_max` (solved when not above 0),
    /// kept with `sel.cpv_cost`.
    excess: Vec<f64>,
    sel: Selection,
}

/// Two bits per (CPV, hierarchy node), covered and adjusted (see
/// [`State`]), stored by node, with a rank directory over the adjusted
/// bits: an adjusted (CPV, cluster)'s adjustment sits at its rank in the
/// cluster's `adjustments`. Per node and 64 CPVs, three adjacent words
/// (covered, adjusted, adjusted bits before them in the node's row).
/// Scoring walks one cluster's pairs, whose CPVs are contiguous ids within
/// a cell, so consecutive lookups share cache lines, in the marks and in
/// the adjustments: 3/8 byte per (CPV, node).
struct NodeMarks {
    /// Words per node.
    row: usize,
    bits: Vec<u64>,
}

/// What [`NodeMarks`] says of a (CPV, cluster).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mark {
    /// Neither covered nor adjusted: represented by its objects.
    Plain,
    Covered,
    /// Adjusted, with the rank of its adjustment.
    Adjusted(usize),
}

/// Bytes of the greedy's marks for `cpvs` CPVs over a hierarchy of `nodes`
/// nodes (part of the memory `place` predicts).
pub fn marks_bytes(cpvs: usize, nodes: usize) -> u64 {
    (nodes * 3 * cpvs.div_ceil(64) * 8) as u64
}

impl NodeMarks {
    fn new(cpvs: usize, nodes: usize) -> Self {
        let row = 3 * cpvs.div_ceil(64);
        NodeMarks {
            row,
            bits: vec![0; nodes * row],
        }
    }

    fn get(&self, c: u32, n: u32) -> Mark {
        let at = n as usize * self.row + 3 * (c as usize / 64);
        let b = c % 64;
        let (cov, adj) = (self.bits[at], self.bits[at + 1]);
        if cov >> b & 1 == 1 {
            Mark::Covered
        } else if adj >> b & 1 == 1 {
            let below = adj & ((1u64 << b) - 1);
            Mark::Adjusted(self.bits[at + 2] as usize + below.count_ones() as usize)
        } else {
            Mark::Plain
        }
    }

    /// Adds `saving` to cluster `n`'s adjustment in each CPV of `changes`
    /// (ascending CPV ids), marking it adjusted where it was not: one pass
    /// over the node's row and its `adjustments`.
    fn adjust(&mut self, n: u32, changes: &[(u32, Cost)], adjustments: &mut Vec<Cost>) {
        let row = &mut self.bits[n as usize * self.row..][..self.row];
        let rank = |row: &[u64], c: u32| {
            let at = 3 * (c as usize / 64);
            let below = row[at + 1] & ((1u64 << (c % 64)) - 1);
            row[at + 2] as usize + below.count_ones() as usize
        };
        // Existing adjustments first, while the ranks are unchanged; the
        // new ones with the rank they get among the old ones.
        let mut new: Vec<(usize, Cost)> = Vec::new();
        for &(c, saving) in changes {
            let k = rank(row, c);
            if row[3 * (c as usize / 64) + 1] >> (c % 64) & 1 == 1 {
                adjustments[k] += saving;
            } else {
                new.push((k, saving));
            }
        }
        if new.is_empty() {
            return;
        }
        for &(c, _) in changes {
            row[3 * (c as usize / 64) + 1] |= 1 << (c % 64);
        }
        let mut merged = Vec::with_capacity(adjustments.len() + new.len());
        let mut from = 0;
        for (k, saving) in new {
            merged.extend_from_slice(&adjustments[from..k]);
            merged.push(saving);
            from = k;
        }
        merged.extend_from_slice(&adjustments[from..]);
        *adjustments = merged;
        let mut before = 0u64;
        for w in row.chunks_exact_mut(3) {
            w[2] = before;
            before += u64::from(w[1].count_ones());
        }
    }

    /// Marks `a..b` covered in CPV `c`.
    fn cover(&mut self, c: u32, a: u32, b: u32) {
        let (word, bit) = (3 * (c as usize / 64), c % 64);
        for n in a..b {
            self.bits[n as usize * self.row + word] |= 1 << bit;
        }
    }
}

/// The effect of impostor `i` on one CPV.
struct Effect {
    accelerates: bool,
    new_cost: Cost,
    /// What the impostor saves against the cluster's current
    /// representation.
    saving: Cost,
}

impl<'a> State<'a> {
    fn new(ctx: &'a Context<'a>, pv: &'a ProblemViews, cands: &'a Candidates) -> Self {
        State {
            ctx,
            pv,
            cands: &cands.list,
            all: cands,
            adjustments: vec![Vec::new(); ctx.hierarchy.nodes.len()],
            marks: NodeMarks::new(pv.cpvs.len(), ctx.hierarchy.nodes.len()),
            unsolved_in_cell: {
                let mut v = vec![0u32; pv.kd.len()];
                for c in &pv.cpvs {
                    v[c.kd as usize] += u32::from(c.time > ctx.t_max);
                }
                v
            },
            cell_changed: vec![0; pv.kd.len()],
            excess: pv.cpvs.iter().map(|c| c.time - ctx.t_max).collect(),
            sel: Selection {
                cpv_impostors: vec![Vec::new(); pv.cpvs.len()],
                cpv_cost: pv.cpvs.iter().map(|c| c.cost).collect(),
                uses: vec![0; cands.list.len()],
                accepted: 0,
                evaluations: 0,
                pruned: 0,
            },
        }
    }

    /// CPVs still above `t_max`.
    fn unsolved(&self) -> u64 {
        self.unsolved_in_cell.iter().map(|&n| u64::from(n)).sum()
    }

    /// Cost of impostor `j` in CPV `cpv`.
    fn impostor_cost(&self, j: u32, cpv: &Cpv) -> Cost {
        let cand = &self.cands[j as usize];
        let s = self.ctx.hierarchy.nodes[cand.node as usize].sphere;
        self.ctx.model.impostor(
            cand.spec.layers,
            s.radius,
            cpv.region.distance_to_point(s.center),
        )
    }

    /// The cost of cluster `node`'s current representation in CPV `c`,
    /// whose objects there cost `orig`: `None` when an impostor of it or an
    /// ancestor already represents it.
    fn representation(&self, c: u32, node: u32, orig: Cost) -> Option<Cost> {
        match self.marks.get(c, node) {
            Mark::Covered => None,
            Mark::Plain => Some(orig),
            Mark::Adjusted(rank) => Some(orig - self.adjustments[node as usize][rank]),
        }
    }

    /// The effect on CPV `c` of replacing cluster `node`, whose objects
    /// in the CPV's enclosing set cost `orig`, by an impostor costing `imp`.
    fn effect(&self, c: u32, node: u32, orig: Cost, imp: Cost) -> Option<Effect> {
        let rep = self.representation(c, node, orig)?;
        let cur = self.sel.cpv_cost[c as usize];
        let new_cost = cur - rep + imp;
        let m = &self.ctx.model;
        Some(Effect {
            accelerates: m.frame_time(new_cost) < m.frame_time(cur),
            new_cost,
            saving: rep - imp,
        })
    }

    /// `Δt` of replacing cluster `node`, whose objects in CPV `c`'s
    /// enclosing set cost `orig`, by an impostor costing `imp`, in a CPV
    /// `excess` above `t_max`: the time saved against the cluster's
    /// current representation, capped by the excess (0 where an impostor
    /// of it or an ancestor already represents it). Where times add up,
    /// the time saved is computed from the saving itself, not as a
    /// difference of two frame times, so it does not drift by a rounding
    /// step when the CPV's cost changes: scores then never grow, which the
    /// lazy greedy relies on.
    #[inline]
    fn gain(&self, c: u32, node: u32, orig: Cost, imp: Cost, excess: f64) -> f64 {
        let Some(rep) = self.representation(c, node, orig) else {
            return 0.0;
        };
        let m = &self.ctx.model;
        let saved = m.time_saved(rep - imp).unwrap_or_else(|| {
            let cur = self.sel.cpv_cost[c as usize];
            m.frame_time(cur) - m.frame_time(cur - rep + imp)
        });
        saved.min(excess).max(0.0)
    }

    /// Calls `f(cpv, effect)` for every CPV candidate `i` may serve.
    fn for_each_effect(&self, i: u32, mut f: impl FnMut(u32, Effect)) {
        let all = self.all;
        let cand = &self.cands[i as usize];
        let s = self.ctx.hierarchy.nodes[cand.node as usize].sphere;
        for &g in &all.served[cand.served.indices()] {
            let gr = all.pairs.group(g);
            // All CPVs of a group share their region, hence the impostor's cost.
            let imp = self.ctx.model.impostor(cand.spec.layers, s.radius, gr.dist);
            for (c, orig) in all.pairs.iter(gr) {
                if let Some(e) = self.effect(c, cand.node, orig, imp) {
                    f(c, e);
                }
            }
        }
    }

    fn score(&self, i: u32) -> f64 {
        let c = &self.cands[i as usize];
        let mut sum = 0.0;
        self.add_gains(c.node, c.spec.layers, c.served.indices(), &mut sum);
        sum / c.spec.memory_bytes.max(1) as f64
    }

    /// Adds to `sum` the gains of the groups `served[groups]` for an
    /// impostor of `layers` layers of cluster `node`, counting only CPVs
    /// still above `t_max`.
    fn add_gains(&self, node: u32, layers: u32, groups: Range<usize>, sum: &mut f64) {
        let all = self.all;
        let s = self.ctx.hierarchy.nodes[node as usize].sphere;
        for &g in &all.served[groups] {
            let gr = all.pairs.group(g);
            if self.unsolved_in_cell[gr.kd as usize] == 0 {
                continue;
            }
            let imp = self.ctx.model.impostor(layers, s.radius, gr.dist);
            for (c, orig) in all.pairs.iter(gr) {
                let excess = self.excess[c as usize];
                if excess > 0.0 {
                    *sum += self.gain(c, node, orig, imp, excess);
                }
            }
        }
    }

    /// The scores of the candidates `first..end` of one block, which serve
    /// growing prefixes of the same groups (see [`blocks`]). Equal to
    /// [`score`](Self::score) of each, bit for bit, but a run of candidates
    /// with the same layer count walks the groups once.
    fn score_block(&self, block: IdRange) -> Vec<f64> {
        let end = block.end;
        let mut out = Vec::with_capacity(block.len() as usize);
        let mut j = block.start as usize;
        while j < end as usize {
            let c0 = &self.cands[j];
            let (mut sum, mut pos) = (0.0, c0.served.start as usize);
            let mut k = j;
            while k < end as usize && self.cands[k].spec.layers == c0.spec.layers {
                let end = self.cands[k].served.end as usize;
                self.add_gains(c0.node, c0.spec.layers, pos..end, &mut sum);
                pos = end;
                out.push(sum / self.cands[k].spec.memory_bytes.max(1) as f64);
                k += 1;
            }
            j = k;
        }
        out
    }

    fn accept(&mut self, i: u32) {
        let mut changes: Vec<(u32, Cost, Cost)> = Vec::new();
        self.for_each_effect(i, |c, e| {
            if e.accelerates {
                changes.push((c, e.new_cost, e.saving));
            }
        });
        // The impostor replaces the cluster's representation: every
        // ancestor's gets cheaper by the difference.
        changes.sort_unstable_by_key(|x| x.0);
        let h = self.ctx.hierarchy;
        let node = self.cands[i as usize].node;
        let end = h.nodes[node as usize].subtree_end;
        let savings: Vec<(u32, Cost)> = changes.iter().map(|&(c, _, s)| (c, s)).collect();
        let mut up = h.nodes[node as usize].parent;
        while up != u32::MAX {
            self.marks
                .adjust(up, &savings, &mut self.adjustments[up as usize]);
            up = h.nodes[up as usize].parent;
        }
        for (c, cost, _) in changes {
            let cu = c as usize;
            let cpv = &self.pv.cpvs[cu];
            // Only a cluster adjusted in the CPV has impostors below it there.
            let below = matches!(self.marks.get(c, node), Mark::Adjusted(_));
            self.marks.cover(c, node, end);
            let imps = &mut self.sel.cpv_impostors[cu];
            if below {
                let cands = self.cands;
                let uses = &mut self.sel.uses;
                imps.retain(|&j| {
                    let replaced = h.is_descendant(cands[j as usize].node, node);
                    if replaced {
                        uses[j as usize] -= 1;
                    }
                    !replaced
                });
            }
            imps.push(i);
            self.sel.uses[i as usize] += 1;
            let excess = self.ctx.model.frame_time(cost) - self.ctx.t_max;
            if self.excess[cu] > 0.0 && excess <= 0.0 {
                self.unsolved_in_cell[cpv.kd as usize] -= 1;
            }
            self.sel.cpv_cost[cu] = cost;
            self.excess[cu] = excess;
            self.cell_changed[cpv.kd as usize] = self.sel.accepted + 1;
        }
        self.sel.accepted += 1;
    }

    /// True when no cell candidate `i` serves changed after choice
    /// `stamp`: a score computed then is still exact.
    fn unchanged_since(&self, i: u32, stamp: u64) -> bool {
        let all = self.all;
        all.served[self.cands[i as usize].served.indices()]
            .iter()
            .all(|&g| self.cell_changed[all.pairs.group(g).kd as usize] <= stamp)
    }
}

/// Per candidate, the candidates of its block: the candidates of one
/// cluster that serve growing prefixes of the same served groups (one shaft
/// angle and axis); a box is a block of its own.
fn blocks(cands: &[Candidate]) -> Vec<IdRange> {
    let mut out = vec![IdRange::default(); cands.len()];
    let mut i = 0;
    while i < cands.len() {
        let mut e = i + 1;
        while e < cands.len()
            && cands[e].node == cands[i].node
            && cands[e].served.start == cands[i].served.start
            && cands[e].served.end >= cands[e - 1].served.end
        {
            e += 1;
        }
        for o in &mut out[i..e] {
            *o = IdRange::new(i as u32, e as u32);
        }
        i = e;
    }
    out
}

/// Blocks of stale keys refreshed together in [`select_lazy`].
pub const LAZY_BATCH: usize = 32;

/// Lazy greedy selection.
///
/// Keys carry the state version they were computed in; a key popped with the
/// current version is exact and, being the largest of upper bounds, is the
/// greedy choice. Stale keys are recomputed, with their whole blocks, a batch
/// of [`LAZY_BATCH`] blocks at a time in parallel. Scores can rise (memory
/// regained by hierarchy replacement), so which stale keys get refreshed may
/// change the choice: the batch is a constant, never derived from the thread
/// count, so the result is the same for any number of threads.
///
/// `progress(unsolved)` is called now and then with the number of CPVs still
/// above `t_max`; when it returns false the selection stops early (the
/// caller discards the incomplete selection).
pub fn select_lazy(
    ctx: &Context,
    pv: &ProblemViews,
    cands: &Candidates,
    progress: &mut dyn FnMut(u64) -> bool,
) -> Selection {
    select_lazy_with(ctx, pv, cands, progress, None)
}

/// [`select_lazy`] removing outdated heap keys first when the heap holds
/// more than `first_compaction` keys (default: twice the initial keys, at
/// least 2,048), then whenever it doubles. Tests lower it so that the
/// removal runs on small inputs; the selection is the same either way.
pub(crate) fn select_lazy_with(
    ctx: &Context,
    pv: &ProblemViews,
    cands: &Candidates,
    progress: &mut dyn FnMut(u64) -> bool,
    first_compaction: Option<usize>,
) -> Selection {
    let mut st = State::new(ctx, pv, cands);
    if !progress(st.unsolved()) {
        return st.sel;
    }
    // Scores are computed a block at a time (its candidates share most of
    // the work); a block's fresh keys make its older keys outdated.
    let blocks = blocks(&cands.list);
    let firsts: Vec<u32> = (0..cands.list.len() as u32)
        .filter(|&i| blocks[i as usize].start == i)
        .collect();
    let initial: Vec<f64> = firsts
        .par_iter()
        .flat_map_iter(|&b| st.score_block(blocks[b as usize]))
        .collect();
    st.sel.evaluations = initial.len() as u64;
    let mut latest = vec![0u64; cands.list.len()];
    let mut heap: BinaryHeap<(Key, u64)> = initial
        .into_iter()
        .enumerate()
        .filter(|&(_, s)| s > 0.0)
        .map(|(i, score)| {
            (
                Key {
                    score,
                    id: i as u32,
                },
                0,
            )
        })
        .collect();
    let mut compact_at = first_compaction.unwrap_or(2 * heap.len().max(1024));
    let batch = LAZY_BATCH;
    let mut version = 0u64;
    let mut stale: Vec<u32> = Vec::with_capacity(batch);
    while let Some(&(top, stamp)) = heap.peek() {
        if stamp < latest[top.id as usize] {
            heap.pop();
            continue;
        }
        if stamp == version || st.unchanged_since(top.id, stamp) {
            heap.pop();
            st.accept(top.id);
            version += 1;
            if version.is_multiple_of(64) && !progress(st.unsolved()) {
                break;
            }
            continue;
        }
        // Recompute the stale keys at the top, up to a batch, in parallel;
        // a key whose cells did not change since it was computed is exact
        // and ends the batch.
        stale.clear();
        while stale.len() < batch {
            match heap.peek() {
                Some(&(k, s)) if s < latest[k.id as usize] => {
                    heap.pop();
                }
                Some(&(k, s)) if s != version && !st.unchanged_since(k.id, s) => {
                    heap.pop();
                    let b = blocks[k.id as usize].start;
                    if !stale.contains(&b) {
                        stale.push(b);
                    }
                }
                _ => break,
            }
        }
        let fresh: Vec<Vec<f64>> = stale
            .par_iter()
            .map(|&b| st.score_block(blocks[b as usize]))
            .collect();
        for (&b, scores) in stale.iter().zip(fresh) {
            st.sel.evaluations += scores.len() as u64;
            for (id, score) in (b..).zip(scores) {
                latest[id as usize] = version;
                if score > 0.0 {
                    heap.push((Key { score, id }, version));
                }
            }
        }
        // Outdated keys are dropped when popped; should they make up half
        // the heap, they go at once (the pop order of the others does not
        // change: keys are totally ordered), so the heap stays within about
        // twice the candidates it ranks.
        if heap.len() > compact_at {
            heap.retain(|&(k, s)| s >= latest[k.id as usize]);
            compact_at = compact_at.max(2 * heap.len());
        }
    }
    st.sel
}

/// Naive greedy selection: recomputes every score after each choice. Only
/// for testing the lazy variant on small inputs.
pub fn select_naive(ctx: &Context, pv: &ProblemViews, cands: &Candidates) -> Selection {
    let mut st = State::new(ctx, pv, cands);
    let mut alive: Vec<u32> = (0..cands.list.len() as u32).collect();
    loop {
        let mut best: Option<Key> = None;
        let mut next_alive = Vec::with_capacity(alive.len());
        for &i in &alive {
            let score = st.score(i);
            st.sel.evaluations += 1;
            if score <= 0.0 {
                continue;
            }
            next_alive.push(i);
            let k = Key { score, id: i };
            if best.is_none_or(|b| k > b) {
                best = Some(k);
            }
        }
        alive = next_alive;
        match best {
            Some(b) => st.accept(b.id),
            None => break,
        }
    }
    st.sel
}

/// Removes impostors that are not needed to keep every CPV within `t_max`,
/// largest memory first (ties: lower id). Removing an impostor from a CPV
/// draws its cluster's objects as geometry there again; a removal is kept
/// only if every CPV using the impostor stays within `t_max`.
pub fn prune(ctx: &Context, pv: &ProblemViews, cands: &Candidates, sel: &mut Selection) {
    let mut st = State::new(ctx, pv, cands);
    st.sel = sel.clone();
    let mut order = st.sel.impostors();
    order.sort_by_key(|&i| {
        (
            std::cmp::Reverse(cands.list[i as usize].spec.memory_bytes),
            i,
        )
    });
    let mut users: Vec<Vec<u32>> = vec![Vec::new(); cands.list.len()];
    for (c, list) in sel.cpv_impostors.iter().enumerate() {
        for &i in list {
            users[i as usize].push(c as u32);
        }
    }
    for i in order {
        let mut new_costs = Vec::with_capacity(users[i as usize].len());
        let mut ok = true;
        for &c in &users[i as usize] {
            let cpv = &pv.cpvs[c as usize];
            let Some(orig) = cands.pairs.cost_of(cands.list[i as usize].node, c) else {
                ok = false;
                break;
            };
            let cost = st.sel.cpv_cost[c as usize] - st.impostor_cost(i, cpv) + orig;
            if ctx.model.frame_time(cost) > ctx.t_max {
                ok = false;
                break;
            }
            new_costs.push((c, cost));
        }
        if !ok {
            continue;
        }
        for (c, cost) in new_costs {
            st.sel.cpv_cost[c as usize] = cost;
            st.sel.cpv_impostors[c as usize].retain(|&j| j != i);
        }
        st.sel.uses[i as usize] = 0;
        st.sel.pruned += 1;
    }
    *sel = st.sel;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Control;
    use crate::scene::hierarchy::Hierarchy;
    use crate::testutil::{synthetic_city, synthetic_job};
    use crate::views;
    use crate::views::Counters;

    /// The node-major marks with their batched rank directory agree with
    /// a plain map of (CPV, cluster) to adjustment.
    #[test]
    fn marks_and_adjustments_match_a_map() {
        use std::collections::BTreeMap;
        let (cpvs, nodes) = (300usize, 9usize);
        let mut marks = NodeMarks::new(cpvs, nodes);
        let mut adjustments = vec![Vec::new(); nodes];
        let mut want: BTreeMap<(u32, u32), f64> = BTreeMap::new();
        let mut covered = std::collections::BTreeSet::new();
        let mut rng = crate::math::rng::Rng::new(5);
        for round in 0..200 {
            let n = (rng.next_u64() % nodes as u64) as u32;
            let mut cs: Vec<u32> = (0..1 + rng.next_u64() % 40)
                .map(|_| (rng.next_u64() % cpvs as u64) as u32)
                .collect();
            cs.sort_unstable();
            cs.dedup();
            let changes: Vec<(u32, Cost)> = cs
                .iter()
                .map(|&c| {
                    let x = f64::from(round) + f64::from(c) * 1e-3;
                    (c, Cost { cpu: x, gpu: 0.0 })
                })
                .collect();
            marks.adjust(n, &changes, &mut adjustments[n as usize]);
            for &(c, s) in &changes {
                *want.entry((c, n)).or_default() += s.cpu;
            }
            if round % 17 == 0 {
                let c = cs[0];
                marks.cover(c, n, n + 1);
                covered.insert((c, n));
            }
        }
        for c in 0..cpvs as u32 {
            for n in 0..nodes as u32 {
                match marks.get(c, n) {
                    Mark::Covered => assert!(covered.contains(&(c, n))),
                    Mark::Plain => assert!(!want.contains_key(&(c, n))),
                    Mark::Adjusted(rank) => {
                        assert!(!covered.contains(&(c, n)));
                        assert_eq!(adjustments[n as usize][rank].cpu, want[&(c, n)]);
                    }
                }
            }
        }
    }

    #[test]
    fn block_scores_equal_single_scores_bit_for_bit() {
        let scene = synthetic_city(3, 5, 5);
        let job = synthetic_job(5, 5);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = views::approximate(&ctx, &job, &Counters::new());
        let cands = crate::candidates::generate(&ctx, &job, &pv);
        let mut st = State::new(&ctx, &pv, &cands);
        let blocks = blocks(&cands.list);
        // Blocks with several candidates exist (nested shafts).
        assert!(blocks.iter().any(|b| b.len() > 2));
        let check = |st: &State| {
            for (i, &b) in blocks.iter().enumerate() {
                if i as u32 == b.start {
                    let single: Vec<u64> =
                        (b.start..b.end).map(|k| st.score(k).to_bits()).collect();
                    let block: Vec<u64> = st.score_block(b).iter().map(|s| s.to_bits()).collect();
                    assert_eq!(single, block, "block {b:?}");
                }
            }
        };
        check(&st);
        // And after some choices, when cells are solved and clusters covered.
        for _ in 0..5 {
            let best = (0..cands.list.len() as u32)
                .max_by(|&x, &y| st.score(x).total_cmp(&st.score(y)).then(y.cmp(&x)))
                .unwrap();
            st.accept(best);
        }
        check(&st);
    }
}
