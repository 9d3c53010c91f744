//! The greedy's per-(CPV, cluster) marks.

use crate::math::IdRange;
use crate::model::cost::Cost;

/// Two bits per (CPV, hierarchy node), covered and adjusted (see
/// [`State`]), stored by node, with a rank directory over the adjusted
/// bits: an adjusted (CPV, cluster)'s adjustment sits at its rank in the
/// cluster's `adjustments`. Per node and 64 CPVs, three adjacent words
/// (covered, adjusted, adjusted bits before them in the node's row).
/// Scoring walks one cluster's pairs, whose CPVs are contiguous ids within
/// a cell, so consecutive lookups share cache lines, in the marks and in
/// the adjustments: 3/8 byte per (CPV, node).
pub(super) struct NodeMarks {
    /// Words per node.
    pub(super) row: usize,
    pub(super) bits: Vec<u64>,
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

    /// Adds `saving` to cluster `n`'s adjustment in each CPV of `changes`
    /// (ascending CPV ids), marking it adjusted where it was not: one pass
    /// over the node's row and its `adjustments`.
    pub(super) fn adjust(&mut self, n: u32, changes: &[(u32, Cost)], adjustments: &mut Vec<Cost>) {
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
    pub(super) fn cover(&mut self, c: u32, a: u32, b: u32) {
        let (word, bit) = (3 * (c as usize / 64), c % 64);
        for n in a..b {
            self.bits[n as usize * self.row + word] |= 1 << bit;
        }
    }
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
