//! The greedy's per-(CPV, cluster) marks.

use crate::math::IdRange;
use crate::model::cost::Cost;

/// Two bits per (CPV, hierarchy node), covered and adjusted (see
/// [`State`]), stored by node, with a rank directory over the adjusted
/// bits: an adjusted (CPV, cluster)'s adjustment sits at its rank in the
/// cluster's [`Adjustments`]. Per node and 64 CPVs, three adjacent words
/// (covered, adjusted, adjusted bits before them in the node's row).
/// Scoring walks one cluster's pairs, whose CPVs are contiguous ids within
/// a cell, so consecutive lookups share cache lines, in the marks and in
/// the adjustments: 3/8 byte per (CPV, node).
pub(super) struct NodeMarks {
    /// Words per node.
    pub(super) row: usize,
    pub(super) bits: Vec<u64>,
}

/// One cluster's adjustments: per CPV where it is adjusted (by rank), the
/// index of its value. Sums that come out equal bit for bit share a value
/// (a value is never changed in place: a new sum is a new value), so the
/// CPVs of a cell that gained the same impostors hold one value between
/// them: measured 9 times fewer values than adjusted CPVs on a quarter of
/// the fly-over. Values no CPV refers to any more are dropped once they
/// outnumber the rest.
#[derive(Clone, Debug, Default)]
pub(super) struct Adjustments {
    idx: Vec<u32>,
    values: Vec<Cost>,
    /// Values kept by the last compaction.
    kept: usize,
}

/// No value yet (a CPV not adjusted before).
const NO_VALUE: u32 = u32::MAX;

impl Adjustments {
    /// The adjustment at rank `k`.
    #[inline]
    pub(super) fn get(&self, k: usize) -> Cost {
        self.values[self.idx[k] as usize]
    }

    /// The value `sum(old value)` for a saving with bits `bits`: the one
    /// made last (`made`) when it had the same old value and saving (the
    /// changes of one call come in CPV order, so a cell's CPVs that gain
    /// alike follow each other), else a new one.
    #[inline]
    fn value_of(
        &mut self,
        made: &mut Option<((u32, [u64; 2]), u32)>,
        old: u32,
        bits: [u64; 2],
        sum: impl FnOnce(Cost) -> Cost,
    ) -> u32 {
        if let Some((key, v)) = *made
            && key == (old, bits)
        {
            return v;
        }
        let v = if old == NO_VALUE {
            sum(Cost::default())
        } else {
            sum(self.values[old as usize])
        };
        self.values.push(v);
        let i = (self.values.len() - 1) as u32;
        *made = Some(((old, bits), i));
        i
    }

    /// Drops the values no CPV refers to once the values have doubled
    /// since the last time (amortised: each value is moved a bounded
    /// number of times).
    fn compact(&mut self) {
        if self.values.len() <= 2 * self.kept + 64 {
            return;
        }
        let mut map = vec![NO_VALUE; self.values.len()];
        let mut kept = Vec::new();
        for i in &mut self.idx {
            if map[*i as usize] == NO_VALUE {
                map[*i as usize] = kept.len() as u32;
                kept.push(self.values[*i as usize]);
            }
            *i = map[*i as usize];
        }
        self.kept = kept.len();
        self.values = kept;
    }

    /// Adjustments held (adjusted CPVs) and distinct values kept.
    #[cfg(test)]
    pub(super) fn sizes(&self) -> (usize, usize) {
        (self.idx.len(), self.values.len())
    }
}

/// What [`NodeMarks`] says of a (CPV, cluster).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mark {
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
    pub(super) fn new(cpvs: usize, nodes: usize) -> Self {
        let row = 3 * cpvs.div_ceil(64);
        NodeMarks {
            row,
            bits: vec![0; nodes * row],
        }
    }

    pub(super) fn get(&self, c: u32, n: u32) -> Mark {
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

    /// Adds `saving` to the adjustment of each cluster of `nodes`
    /// (ascending ids; their adjustments are `adjustments`, by node id) in
    /// each CPV of `changes` (ascending CPV ids), marking it adjusted where
    /// it was not: one pass over each node's row and adjustments, the
    /// nodes in parallel (each has its own).
    pub(super) fn adjust_all(
        &mut self,
        nodes: &[u32],
        changes: &[(u32, Cost)],
        adjustments: &mut [Adjustments],
    ) {
        use rayon::prelude::*;
        let mut work: Vec<(&mut [u64], &mut Adjustments)> = Vec::with_capacity(nodes.len());
        let (mut bits, mut adj) = (&mut self.bits[..], adjustments);
        let mut at = 0usize;
        for &n in nodes {
            let skip = n as usize - at;
            let (row, rest) = std::mem::take(&mut bits)[skip * self.row..].split_at_mut(self.row);
            let (a, rest_adj) = std::mem::take(&mut adj)[skip..]
                .split_first_mut()
                .expect("a node id within the hierarchy");
            work.push((row, a));
            bits = rest;
            adj = rest_adj;
            at = n as usize + 1;
        }
        work.into_par_iter()
            .for_each(|(row, a)| adjust_row(row, changes, a));
    }

    /// Marks nodes `a..b` covered in each CPV of `cpvs` (ascending): the
    /// CPVs' bits gathered into words once, then each node's row, the rows
    /// in parallel (a row is a few kilobytes apart from the next, so CPV by
    /// CPV every node would be a cache miss).
    pub(super) fn cover_all(&mut self, a: u32, b: u32, cpvs: impl IntoIterator<Item = u32>) {
        use rayon::prelude::*;
        let mut masks: Vec<(usize, u64)> = Vec::new();
        for c in cpvs {
            let (word, bit) = (3 * (c as usize / 64), c % 64);
            match masks.last_mut() {
                Some((w, m)) if *w == word => *m |= 1 << bit,
                _ => masks.push((word, 1 << bit)),
            }
        }
        if masks.is_empty() {
            return;
        }
        let rows = &mut self.bits[a as usize * self.row..b as usize * self.row];
        // Rows at a time enough to outweigh handing them to another thread.
        let min_rows = (4096 / masks.len()).max(1);
        rows.par_chunks_mut(self.row)
            .with_min_len(min_rows)
            .for_each(|row| {
                for &(w, m) in &masks {
                    row[w] |= m;
                }
            });
    }
}

/// [`NodeMarks::adjust_all`] on one node's row.
fn adjust_row(row: &mut [u64], changes: &[(u32, Cost)], adjustments: &mut Adjustments) {
    let rank = |row: &[u64], c: u32| {
        let at = 3 * (c as usize / 64);
        let below = row[at + 1] & ((1u64 << (c % 64)) - 1);
        row[at + 2] as usize + below.count_ones() as usize
    };
    // Existing adjustments first, while the ranks are unchanged; the
    // new ones with the rank they get among the old ones. Equal sums
    // (the same saving added to the same value, as in the CPVs of a
    // cell that held the cluster whole) share one value.
    let mut made: Option<((u32, [u64; 2]), u32)> = None;
    let mut new: Vec<(usize, u32)> = Vec::new();
    for &(c, saving) in changes {
        let k = rank(row, c);
        let bits = [saving.cpu.to_bits(), saving.gpu.to_bits()];
        if row[3 * (c as usize / 64) + 1] >> (c % 64) & 1 == 1 {
            let old = adjustments.idx[k];
            adjustments.idx[k] = adjustments.value_of(&mut made, old, bits, |v| v + saving);
        } else {
            new.push((
                k,
                adjustments.value_of(&mut made, NO_VALUE, bits, |_| saving),
            ));
        }
    }
    if !new.is_empty() {
        for &(c, _) in changes {
            row[3 * (c as usize / 64) + 1] |= 1 << (c % 64);
        }
        let idx = &adjustments.idx;
        let mut merged = Vec::with_capacity(idx.len() + new.len());
        let mut from = 0;
        for (k, v) in new {
            merged.extend_from_slice(&idx[from..k]);
            merged.push(v);
            from = k;
        }
        merged.extend_from_slice(&idx[from..]);
        adjustments.idx = merged;
        let mut before = 0u64;
        for w in row.chunks_exact_mut(3) {
            w[2] = before;
            before += u64::from(w[1].count_ones());
        }
    }
    adjustments.compact();
}

/// The bits of word `w` of a CPV bitset that belong to the CPV range `r`.
#[inline]
pub(super) fn cell_word_mask(r: IdRange, w: usize) -> u64 {
    let (lo, hi) = (w * 64, w * 64 + 64);
    let mut m = u64::MAX;
    if (r.start as usize) > lo {
        m &= u64::MAX << (r.start as usize - lo);
    }
    if (r.end as usize) < hi {
        m &= u64::MAX >> (hi - r.end as usize);
    }
    m
}
