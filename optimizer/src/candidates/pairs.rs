//! The (cluster, CPV) pairs, held once, grouped by cluster and cell.
//!
//! A *pair* is a cluster listed by a CPV (see [`crate::views::cpv_cut`])
//! with the cost of the cluster's objects inside the CPV's enclosing set. A
//! *group* is the pairs of one cluster in one cell. A CPV's list is held as
//! the hierarchy's cut through its enclosing set: the nodes whose sphere
//! lies inside the set (*cut nodes*) stand for every listed cluster below
//! them, each at its whole cost in the cell, which every CPV of the cell
//! shares and the group holds once, with the set of the cell's CPVs that
//! have a cut node above the cluster (a bit per CPV of the cell, held with
//! the group so that walking a cluster's groups reads memory in order).
//! Only the clusters the set holds in part are listed one by one
//! (*explicit* pairs: a CPV id, and a stored cost where it is not the
//! whole cost). Memory then follows the cut, not every cluster a CPV sees:
//! seen from above, a tenth of the pairs are explicit.

use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;

use crate::math::geom::Aabb;
use crate::math::{IdRange, f32_down};
use crate::model::cost::Cost;
use crate::views::{
    CellCuts, Context, CpvCut, Listable, PairCounts, ProblemViews, RegionCosts, cpv_cut,
};

/// Set in an explicit pair's CPV id when its cost is stored.
const STORED: u32 = 1 << 31;
/// Set with [`STORED`] when the stored cost is the group's previous one,
/// which is then not stored again (CPVs next to each other often hold the
/// same part of a cluster: 40 % of the stored costs on the city).
const REPEAT: u32 = 1 << 30;
/// The CPV id of an explicit pair.
const ID: u32 = REPEAT - 1;
/// No CPV (the first CPV of a group with no pairs).
const NONE: u32 = u32::MAX;

/// A pair's cost as held: each time rounded down to an `f32` (half the
/// memory of a [`Cost`]; a relative step below 6e-8). A cost that is too
/// low keeps the greedy conservative: what a CPV's frame time loses when a
/// cluster's objects give way to an impostor is at most their true cost,
/// so the time it then counts is at least the true one. A cost stored for
/// part of a cluster is held at most at the cluster's whole cost, as the
/// greedy's bounds need, whatever the order of their sums left.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Cost32 {
    cpu: f32,
    gpu: f32,
}

impl Cost32 {
    fn down(c: Cost) -> Cost32 {
        Cost32 {
            cpu: f32_down(c.cpu),
            gpu: f32_down(c.gpu),
        }
    }

    /// The least of `self` and `o`, time by time.
    fn min(self, o: Cost32) -> Cost32 {
        Cost32 {
            cpu: self.cpu.min(o.cpu),
            gpu: self.gpu.min(o.gpu),
        }
    }

    #[inline]
    fn get(self) -> Cost {
        Cost {
            cpu: f64::from(self.cpu),
            gpu: f64::from(self.gpu),
        }
    }
}

/// One cell's CPVs that list one cluster, as [`Pairs::group`] gives it.
#[derive(Clone, Copy, Debug)]
pub struct Group {
    /// Its explicit pairs: `explicit.start..explicit.end` of the entries.
    explicit: IdRange,
    /// First of its words in `bits`, one per 64 CPVs of the cell (bit `i`
    /// of its `w`-th word: the cell's `64 w + i`-th CPV lists the cluster
    /// below a cut node); `NONE` when no CPV does.
    bits: u32,
    /// The cell (kd leaf) of the CPVs.
    pub kd: u32,
    /// Index of the group's first stored cost.
    stored: u32,
    /// The cluster's whole cost seen from the cell: its cost in the CPVs
    /// whose pairs store none.
    pub whole: Cost,
}

impl Group {
    /// Its number of pairs, explicit or below a cut node (a CPV lists a
    /// cluster one way or the other, never both).
    pub fn len(&self, pairs: &Pairs) -> u32 {
        let below: u32 = pairs.bits_of(self).iter().map(|w| w.count_ones()).sum();
        self.explicit.len() + below
    }
}

/// A group as held: where its explicit pairs and stored costs start (each
/// ends where the next group's start), its CPV set's first word, its cell
/// and its whole cost (see [`Group`]). The groups are the largest part of
/// the pairs (66 M on the scale-4 city), so their size counts.
#[derive(Clone, Copy, Debug, Default)]
struct Rec {
    explicit: u32,
    stored: u32,
    bits: u32,
    kd: u32,
    whole: Cost32,
}

const _: () = assert!(std::mem::size_of::<Rec>() == 24);

/// The pairs of every CPV, grouped by cluster (node id) and, within a
/// cluster, by cell, CPV ids ascending.
#[derive(Clone, Debug, Default)]
pub struct Pairs {
    /// Per explicit pair: the CPV id, with [`STORED`] set when its cost is
    /// stored, [`REPEAT`] too when it is the group's previous stored cost
    /// stored.
    explicit: Vec<u32>,
    /// The stored costs, in explicit pair order.
    stored: Vec<Cost32>,
    /// The groups' CPV sets below cut nodes, cell by cell, each distinct
    /// set of a cell once: the clusters below one cut node share theirs
    /// (a twentieth of the groups' sets are distinct on the city).
    bits: Vec<u64>,
    /// Per kd node: its CPVs (empty for all but cells with CPVs).
    cells: Vec<IdRange>,
    /// Per kd node: the region its CPVs share (empty for all but cells
    /// with CPVs).
    regions: Vec<Aabb>,
    /// The groups, by cluster and cell, and one past the last (where the
    /// arrays end).
    recs: Vec<Rec>,
    /// Per cluster: its groups are `node_groups[n]..node_groups[n + 1]`.
    node_groups: Vec<u32>,
    /// Number of pairs.
    len: u64,
}

/// The pairs of one group in CPV order (see [`Pairs::iter`]).
pub struct PairIter<'a> {
    pairs: &'a Pairs,
    group: Group,
    /// The cell's CPVs.
    cell: IdRange,
    /// The next word of the cell to read.
    word: u32,
    /// The CPVs of the current word not yet returned, those of them with
    /// explicit pairs, and the word's first CPV.
    mask: u64,
    explicit: u64,
    base: u32,
    /// The next explicit pair, the next stored cost and the last one.
    next: usize,
    stored: usize,
    last: Cost,
}

impl Iterator for PairIter<'_> {
    type Item = (u32, Cost);

    #[inline]
    fn next(&mut self) -> Option<(u32, Cost)> {
        let p = self.pairs;
        while self.mask == 0 {
            let lo = self.cell.start + 64 * self.word;
            if lo >= self.cell.end {
                return None;
            }
            let (m, e) = p.word(&self.group, lo, self.word, self.next);
            self.mask = m;
            self.explicit = e;
            self.base = lo;
            self.word += 1;
        }
        let b = self.mask.trailing_zeros();
        self.mask &= self.mask - 1;
        let c = self.base + b;
        if self.explicit >> b & 1 == 1 {
            let x = p.explicit[self.next];
            self.next += 1;
            if x & STORED != 0 {
                if x & REPEAT == 0 {
                    self.last = p.stored[self.stored].get();
                    self.stored += 1;
                }
                return Some((c, self.last));
            }
        }
        Some((c, self.group.whole))
    }
}

impl Pairs {
    /// Number of pairs.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// True when no CPV lists a cluster.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Number of costs stored (a run of a group's CPVs with the same one
    /// stores it once).
    pub fn stored_len(&self) -> u64 {
        self.stored.len() as u64
    }

    /// Number of pairs listed one by one (the rest lie below cut nodes).
    pub fn explicit_len(&self) -> u64 {
        self.explicit.len() as u64
    }

    /// Number of words of the groups' CPV sets below cut nodes.
    pub fn bits_len(&self) -> u64 {
        self.bits.len() as u64
    }

    /// Number of groups.
    pub fn groups_len(&self) -> u64 {
        self.recs.len() as u64 - 1
    }

    /// Group `g`.
    #[inline]
    pub fn group(&self, g: u32) -> Group {
        let (a, b) = (&self.recs[g as usize], &self.recs[g as usize + 1]);
        Group {
            explicit: IdRange::new(a.explicit, b.explicit),
            bits: a.bits,
            kd: a.kd,
            stored: a.stored,
            whole: a.whole.get(),
        }
    }

    /// The cell (kd leaf) of group `g`'s CPVs.
    #[inline]
    pub fn kd(&self, g: u32) -> u32 {
        self.recs[g as usize].kd
    }

    /// The words of `g`'s CPV set below cut nodes (none when no CPV of the
    /// cell lists the cluster below one).
    fn bits_of(&self, g: &Group) -> &[u64] {
        if g.bits == NONE {
            return &[];
        }
        let words = self.cells[g.kd as usize].len().div_ceil(64);
        &self.bits[g.bits as usize..(g.bits + words) as usize]
    }

    /// Distance from the region of group `g`'s CPVs to `center` (that of
    /// the group's cluster's sphere): all CPVs of a group share it, hence
    /// an impostor's cost there. Computed where needed rather than held
    /// by each group.
    #[inline]
    pub fn dist(&self, g: &Group, center: DVec3) -> f64 {
        self.regions[g.kd as usize].distance_to_point(center)
    }

    /// The group ids of cluster `n`, by cell.
    pub fn groups_of(&self, n: u32) -> IdRange {
        IdRange::new(
            self.node_groups[n as usize],
            self.node_groups[n as usize + 1],
        )
    }

    /// The first CPV of group `g` (all share its cell's region).
    pub fn first_cpv(&self, g: &Group) -> u32 {
        self.iter(g).next().map_or(NONE, |(c, _)| c)
    }

    /// The (CPV id, cost) of every pair of `g`, CPV ids ascending.
    pub fn iter(&self, g: &Group) -> PairIter<'_> {
        PairIter {
            pairs: self,
            group: *g,
            cell: self.cells[g.kd as usize],
            word: 0,
            mask: 0,
            explicit: 0,
            base: 0,
            next: g.explicit.start as usize,
            stored: g.stored as usize,
            last: g.whole,
        }
    }

    /// Calls `f(CPV id, cost)` for every pair of `g`, CPV ids ascending:
    /// [`iter`](Self::iter) as one loop, for the greedy's inner loops.
    #[inline]
    pub fn for_each(&self, g: &Group, mut f: impl FnMut(u32, Cost)) {
        let mut k = g.stored as usize;
        let mut last = g.whole;
        let cell = self.cells[g.kd as usize];
        let mut next = g.explicit.start as usize;
        for w in 0..cell.len().div_ceil(64) {
            let lo = cell.start + 64 * w;
            let (mut m, e) = self.word(g, lo, w, next);
            while m != 0 {
                let b = m.trailing_zeros();
                m &= m - 1;
                let mut cost = g.whole;
                if e >> b & 1 == 1 {
                    let x = self.explicit[next];
                    if x & STORED != 0 {
                        if x & REPEAT == 0 {
                            last = self.stored[k].get();
                            k += 1;
                        }
                        cost = last;
                    }
                    next += 1;
                }
                f(lo + b, cost);
            }
        }
    }

    /// The CPVs of group `g` in word `w` of its cell (whose first CPV is
    /// `lo`), and those of them with explicit pairs (from `next` on).
    #[inline]
    fn word(&self, g: &Group, lo: u32, w: u32, next: usize) -> (u64, u64) {
        let m = if g.bits == NONE {
            0
        } else {
            self.bits[(g.bits + w) as usize]
        };
        let mut e = 0u64;
        let mut j = next;
        let end = g.explicit.end as usize;
        while j < end && (self.explicit[j] & ID) < lo + 64 {
            e |= 1 << ((self.explicit[j] & ID) - lo);
            j += 1;
        }
        (m | e, e)
    }

    /// The cost of cluster `node`'s objects in CPV `cpv`'s enclosing set
    /// as held (each time rounded down to an `f32`), if the CPV lists the
    /// cluster.
    pub fn cost_of(&self, node: u32, cpv: u32) -> Option<Cost> {
        let gs = self.groups_of(node);
        let recs = &self.recs[gs.indices()];
        let k = recs.partition_point(|r| self.cells[r.kd as usize].end <= cpv);
        if k == recs.len() {
            return None;
        }
        let g = self.group(gs.start + k as u32);
        let cell = self.cells[g.kd as usize];
        if cpv < cell.start {
            return None;
        }
        let ex = &self.explicit[g.explicit.indices()];
        if let Ok(p) = ex.binary_search_by_key(&cpv, |&x| x & ID) {
            if ex[p] & STORED == 0 {
                return Some(g.whole);
            }
            // A repeat's cost is the last one stored before it.
            let upto = ex[..=p]
                .iter()
                .filter(|&&x| x & (STORED | REPEAT) == STORED)
                .count();
            return Some(self.stored[g.stored as usize + upto - 1].get());
        }
        let (w, b) = ((cpv - cell.start) / 64, (cpv - cell.start) % 64);
        (g.bits != NONE && self.bits[(g.bits + w) as usize] >> b & 1 == 1).then_some(g.whole)
    }

    /// The pairs of `pv`: the CPVs' cuts are computed again a few cells at
    /// a time (in parallel) and put into place with the counts the
    /// approximation recorded, so no more than those few cells' cuts are
    /// held besides the pairs.
    pub fn collect(ctx: &Context, pv: &ProblemViews) -> Pairs {
        let counts = &pv.node_counts;
        let t = PairCounts::totals(counts);
        assert!(
            t.explicit.max(t.bit_words).max(t.cells) < u64::from(u32::MAX)
                && (pv.cpvs.len() as u64) < u64::from(REPEAT),
            "the memory check caps the pairs below 2^32"
        );
        // Per cluster: where its next explicit pair, stored cost and group
        // go.
        let mut fill = Vec::with_capacity(counts.len());
        let mut at = [0u32; 3];
        let mut node_groups = Vec::with_capacity(counts.len() + 1);
        for c in counts {
            fill.push(at);
            node_groups.push(at[2]);
            at = [at[0] + c.explicit, at[1] + c.partial, at[2] + c.cells];
        }
        node_groups.push(at[2]);
        let mut explicit = vec![0u32; t.explicit as usize];
        let mut stored = vec![Cost32::default(); t.partial as usize];
        let mut bits: Vec<u64> = Vec::new();
        // The last is one past the last group: the arrays' ends.
        let mut recs = vec![Rec::default(); t.cells as usize + 1];
        recs[t.cells as usize] = Rec {
            explicit: at[0],
            stored: at[1],
            bits: NONE,
            kd: 0,
            whole: Cost32::default(),
        };
        let mut cells = vec![IdRange::default(); pv.kd.len()];
        let mut regions = vec![Aabb::EMPTY; pv.kd.len()];
        let cell_ranges = pv.cells();
        for r in &cell_ranges {
            let first = &pv.cpvs[r.start as usize];
            cells[first.kd as usize] = *r;
            regions[first.kd as usize] = first.region;
        }
        let mut len = 0u64;
        for chunk in cell_ranges.chunks(16) {
            if ctx.cancelled() {
                return Pairs::default();
            }
            let outs: Vec<CellPairs> = chunk
                .par_iter()
                .map(|&r| CellPairs::of(ctx, pv, r))
                .collect();
            for out in outs {
                let first = &pv.cpvs[out.cell.start as usize];
                let base = bits.len() as u32;
                bits.extend_from_slice(&out.bits);
                let mut e = 0;
                for gr in &out.groups {
                    let f = &mut fill[gr.node as usize];
                    let (start, stored_at) = (f[0], f[1]);
                    while e < out.explicit.len() && out.explicit[e].0 == gr.node {
                        let (_, c, cost) = out.explicit[e];
                        explicit[f[0] as usize] = c;
                        if let Some(cost) = cost {
                            let same = |a: Cost32| {
                                (a.cpu.to_bits(), a.gpu.to_bits())
                                    == (cost.cpu.to_bits(), cost.gpu.to_bits())
                            };
                            if f[1] > stored_at && same(stored[f[1] as usize - 1]) {
                                explicit[f[0] as usize] |= STORED | REPEAT;
                            } else {
                                explicit[f[0] as usize] |= STORED;
                                stored[f[1] as usize] = cost;
                                f[1] += 1;
                            }
                        }
                        f[0] += 1;
                        e += 1;
                    }
                    recs[f[2] as usize] = Rec {
                        explicit: start,
                        stored: stored_at,
                        bits: gr.bits.map_or(NONE, |b| base + b),
                        kd: first.kd,
                        whole: gr.whole,
                    };
                    f[2] += 1;
                    len += u64::from(gr.len);
                }
                debug_assert_eq!(e, out.explicit.len());
            }
        }
        bits.shrink_to_fit();
        // The stored costs were placed by the counts, which include the
        // repeats: each cluster's moved down to close the gaps.
        let mut to = 0u32;
        for (n, f) in fill.iter().enumerate() {
            let gs = node_groups[n] as usize..node_groups[n + 1] as usize;
            if gs.is_empty() {
                continue;
            }
            let from = recs[gs.start].stored;
            stored.copy_within(from as usize..f[1] as usize, to as usize);
            for r in &mut recs[gs] {
                r.stored -= from - to;
            }
            to += f[1] - from;
        }
        recs[t.cells as usize].stored = to;
        stored.truncate(to as usize);
        stored.shrink_to_fit();
        Pairs {
            explicit,
            stored,
            bits,
            cells,
            regions,
            recs,
            node_groups,
            len,
        }
    }
}

/// One group of a cell, as [`CellPairs`] finds it.
struct CellGroup {
    node: u32,
    len: u32,
    /// Where its CPV set below cut nodes starts in the cell's `bits`.
    bits: Option<u32>,
    whole: Cost32,
}

/// The pairs of one cell, before they are put into place.
struct CellPairs {
    cell: IdRange,
    /// The groups' CPV sets below cut nodes, each distinct set once.
    bits: Vec<u64>,
    /// The groups, by node id.
    groups: Vec<CellGroup>,
    /// The explicit pairs: (cluster, CPV id, cost when stored), by cluster
    /// and CPV.
    explicit: Vec<(u32, u32, Option<Cost32>)>,
}

impl CellPairs {
    /// The cuts of the CPVs `r` (one cell's) and the groups they make.
    fn of(ctx: &Context, pv: &ProblemViews, r: IdRange) -> CellPairs {
        let first = &pv.cpvs[r.start as usize];
        let costs = RegionCosts::of_kd(
            ctx,
            &pv.kd[first.kd as usize],
            &crate::views::Counters::new(),
        );
        let listable = Listable::new(ctx, &costs, &first.region);
        let mut explicit: Vec<(u32, u32, Option<Cost32>)> = Vec::new();
        let mut cuts: Vec<CpvCut> = Vec::with_capacity(r.len() as usize);
        for (i, c) in pv.cpvs[r.indices()].iter().enumerate() {
            let cut = cpv_cut(ctx, &costs, &listable, &c.region, &c.vdi);
            debug_assert_eq!((cut.cost, cut.listed(&listable)), (c.cost, c.listed));
            let ci = r.start + i as u32;
            explicit.extend(cut.explicit.iter().map(|&(n, cost)| {
                let whole = Cost32::down(costs.nodes[n as usize]);
                let cost = Cost32::down(cost).min(whole);
                (n, ci, (cost != whole).then_some(cost))
            }));
            cuts.push(cut);
        }
        // Stable: each cluster's pairs stay in CPV order.
        explicit.sort_by_key(|e| e.0);
        let below = CellCuts::new(ctx, &listable, &cuts);
        // The groups: clusters listed explicitly or below a cut node.
        let mut groups: Vec<CellGroup> = Vec::new();
        let mut bits: Vec<u64> = Vec::new();
        // Where each distinct set went: the clusters below a cut node
        // mostly share one.
        let mut sets: HashMap<&[u64], u32> = HashMap::new();
        let (mut e, mut k) = (0usize, 0usize);
        loop {
            let en = explicit.get(e).map(|x| x.0);
            let kn = below.listed.get(k).copied();
            let node = match (en, kn) {
                (None, None) => break,
                (Some(a), Some(b)) => a.min(b),
                (Some(a), None) => a,
                (None, Some(b)) => b,
            };
            let mut n = 0u32;
            while explicit.get(e).is_some_and(|x| x.0 == node) {
                n += 1;
                e += 1;
            }
            let mut group_bits = None;
            if kn == Some(node) {
                k += 1;
                let above = below.above(node);
                group_bits = Some(*sets.entry(above).or_insert_with(|| {
                    bits.extend_from_slice(above);
                    (bits.len() - above.len()) as u32
                }));
                n += below.count(node);
            }
            groups.push(CellGroup {
                node,
                len: n,
                bits: group_bits,
                whole: Cost32::down(costs.nodes[node as usize]),
            });
        }
        CellPairs {
            cell: r,
            bits,
            groups,
            explicit,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Control;
    use crate::scene::hierarchy::Hierarchy;
    use crate::testutil::{synthetic_city, synthetic_job};
    use crate::views::{self, Counters, cpv_clusters};

    /// Every CPV's cluster list (spelled out by [`cpv_clusters`]) comes
    /// back from the pairs with the same costs as held ([`Cost32`]), bit
    /// for bit, whether
    /// stored, explicit or below a cut node; clusters a CPV does not list
    /// have no pair; the iterator and `for_each` agree; and the cut stands
    /// for a share of the pairs (small on this small city, 89 % of them on
    /// the fly-over).
    #[test]
    fn pairs_give_back_every_cpv_list() {
        let scene = synthetic_city(5, 6, 6);
        let job = synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = views::approximate(&ctx, &job, &Counters::new());
        let pairs = Pairs::collect(&ctx, &pv);
        let listed: u64 = pv.cpvs.iter().map(|c| u64::from(c.listed)).sum();
        assert_eq!(pairs.len(), listed);
        assert!(pairs.stored_len() > 0, "no cluster is partly outside");
        // Some CPVs hold the same part of a cluster as the CPV before them,
        // whose stored cost they share (their costs are checked below).
        let repeats = pairs.explicit.iter().filter(|&&x| x & REPEAT != 0).count();
        assert!(repeats > 0, "no repeated stored cost");
        assert!(
            pairs.stored_len() * 2 < pairs.len(),
            "{} of {} pairs store their cost",
            pairs.stored_len(),
            pairs.len()
        );
        assert!(
            pairs.explicit_len() * 10 < pairs.len() * 9 && pairs.bits_len() > 0,
            "{} of {} pairs explicit",
            pairs.explicit_len(),
            pairs.len()
        );
        let mut checked = 0;
        for (i, c) in pv.cpvs.iter().enumerate().step_by(7) {
            let kd = &pv.kd[c.kd as usize];
            assert!(kd.children.is_none());
            let costs = RegionCosts::new(&ctx, &c.region, None, &Counters::new());
            let (_, list) = cpv_clusters(&ctx, &costs, &c.region, &c.vdi);
            let mut next = 0;
            for n in 0..h.nodes.len() as u32 {
                // As held: rounded down, at most the whole cost.
                let want = match list.get(next) {
                    Some(&(m, cost)) if m == n => {
                        next += 1;
                        let whole = Cost32::down(costs.nodes[n as usize]);
                        Some(Cost32::down(cost).min(whole).get())
                    }
                    _ => None,
                };
                let got = pairs.cost_of(n, i as u32);
                assert_eq!(
                    got.map(|x| (x.cpu.to_bits(), x.gpu.to_bits())),
                    want.map(|x| (x.cpu.to_bits(), x.gpu.to_bits())),
                    "CPV {i} cluster {n}"
                );
                checked += usize::from(want.is_some());
            }
        }
        assert!(checked > 100, "{checked}");
        // The clusters below one cut node share their cell's CPV set (a
        // twentieth of the sets are distinct on the city, most here).
        let words: u64 = (0..pairs.groups_len() as u32)
            .map(|g| pairs.bits_of(&pairs.group(g)).len() as u64)
            .sum();
        assert!(
            pairs.bits_len() < words,
            "{} words held for {words}",
            pairs.bits_len()
        );
        // Walking each cluster's groups gives its pairs in CPV order, each
        // group within one cell.
        for n in 0..h.nodes.len() as u32 {
            let mut last = None;
            for g in pairs.groups_of(n).indices() {
                let gr = pairs.group(g as u32);
                let mut each = Vec::new();
                pairs.for_each(&gr, |c, cost| each.push((c, cost)));
                assert_eq!(each, pairs.iter(&gr).collect::<Vec<_>>());
                assert_eq!(each.len(), gr.len(&pairs) as usize);
                for (c, cost) in pairs.iter(&gr) {
                    assert!(last < Some(c));
                    last = Some(c);
                    assert_eq!(pv.cpvs[c as usize].kd, gr.kd);
                    assert_eq!(pairs.cost_of(n, c), Some(cost));
                }
            }
        }
    }
}
