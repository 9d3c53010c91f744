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
/// the fly-over. Each value counts the CPVs that refer to it; one no CPV
/// refers to any more is free, and the next new value takes its place, so
/// the values are never searched for the dead ones among the indices
/// (which outnumber them eleven to one on the scale-4 city) unless most
/// are free.
#[derive(Clone, Debug, Default)]
pub(super) struct Adjustments {
    idx: Indices,
    values: Vec<Cost>,
    /// Per value: how many CPVs refer to it (0: free).
    refs: Vec<u32>,
    /// The free values.
    free: Vec<u32>,
}

/// No value yet (a CPV not adjusted before).
const NO_VALUE: u32 = u32::MAX;

impl Adjustments {
    /// The adjustment at rank `k`.
    #[inline]
    pub(super) fn get(&self, k: usize) -> Cost {
        self.values[self.idx.get(k) as usize]
    }

    /// The value `sum(old value)` for a saving with bits `bits`: the one
    /// made last (`made`) when it had the same old value and saving (the
    /// changes of one call come in CPV order, so a cell's CPVs that gain
    /// alike follow each other), else a new one, in a free place if there
    /// is one. The caller refers to it ([`refer`](Self::refer)). (A place
    /// freed in a call may hold a new value in the same call: `made` names
    /// an old value only while a CPV still to come refers to it.)
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
        let i = match self.free.pop() {
            Some(i) => {
                self.values[i as usize] = v;
                i
            }
            None => {
                if self.values.len() == self.values.capacity() {
                    // A quarter more, not twice: the values are among the
                    // greedy's largest parts on large maps.
                    let more = self.values.len() / 4 + 16;
                    self.values.reserve_exact(more);
                    self.refs.reserve_exact(more);
                }
                self.values.push(v);
                self.refs.push(0);
                (self.values.len() - 1) as u32
            }
        };
        *made = Some(((old, bits), i));
        i
    }

    /// One more CPV refers to value `v`.
    #[inline]
    fn refer(&mut self, v: u32) {
        self.refs[v as usize] += 1;
    }

    /// The adjustment at rank `k` becomes value `v`; its old value is
    /// freed when no other CPV refers to it.
    #[inline]
    fn replace(&mut self, k: usize, v: u32) {
        self.refer(v);
        let old = self.idx.get(k);
        self.idx.set(k, v);
        let r = &mut self.refs[old as usize];
        *r -= 1;
        if *r == 0 {
            self.free.push(old);
        }
    }

    /// Once most values are free, renumbers the others in the order the
    /// indices first name them and drops the free ones (amortised: at
    /// least as many values were freed since as are kept), narrowing wide
    /// indices where every kept value fits in two bytes.
    fn compact(&mut self) {
        if self.free.len() <= self.values.len() / 2 + 32 {
            return;
        }
        let mut map = vec![NO_VALUE; self.values.len()];
        let live = self.values.len() - self.free.len();
        let (mut kept, mut refs) = (Vec::with_capacity(live), Vec::with_capacity(live));
        let (values, counts) = (&self.values, &self.refs);
        let mut renumber = |i: u32| {
            let m = &mut map[i as usize];
            if *m == NO_VALUE {
                *m = kept.len() as u32;
                kept.push(values[i as usize]);
                refs.push(counts[i as usize]);
            }
            *m
        };
        // In place, at the indices' own width: narrow indices keep
        // fitting (no more values are kept than they referred to); wide
        // ones narrow where every kept value fits.
        match &mut self.idx {
            Indices::Narrow(v) => v
                .iter_mut()
                .for_each(|x| *x = renumber(u32::from(*x)) as u16),
            Indices::Wide(v) => v.iter_mut().for_each(|x| *x = renumber(*x)),
        }
        if let Indices::Wide(v) = &self.idx
            && kept.len() <= 1 << 16
        {
            self.idx = Indices::Narrow(v.iter().map(|&i| i as u16).collect());
        }
        self.values = kept;
        self.refs = refs;
        self.free = Vec::new();
    }

    /// Adjustments held (adjusted CPVs), values in use and the places
    /// for values (free or not), after checking that each value counts
    /// the CPVs that refer to it and the free ones are those none does.
    #[cfg(test)]
    pub(super) fn sizes(&self) -> (usize, usize, usize) {
        let mut refs = vec![0u32; self.values.len()];
        for k in 0..self.idx.len() {
            refs[self.idx.get(k) as usize] += 1;
        }
        assert_eq!(refs, self.refs, "reference counts");
        let mut free: Vec<u32> = (0..refs.len() as u32)
            .filter(|&i| refs[i as usize] == 0)
            .collect();
        let mut held_free = self.free.clone();
        held_free.sort_unstable();
        free.sort_unstable();
        assert_eq!(held_free, free, "free values");
        (
            self.idx.len(),
            self.values.len() - self.free.len(),
            self.values.len(),
        )
    }
}

/// The value indices of a cluster's adjustments, two bytes each while the
/// cluster has no more than 65,536 values (nearly all do: a cell's CPVs
/// share values), four once it has more: the adjustments are the largest
/// thing the greedy adds as it goes.
#[derive(Clone, Debug)]
enum Indices {
    Narrow(Vec<u16>),
    Wide(Vec<u32>),
}

impl Default for Indices {
    fn default() -> Self {
        Indices::Narrow(Vec::new())
    }
}

#[cfg(test)]
impl From<Vec<u32>> for Indices {
    /// Narrow when every index fits in two bytes.
    fn from(v: Vec<u32>) -> Self {
        if v.iter().all(|&i| i <= u32::from(u16::MAX)) {
            Indices::Narrow(v.into_iter().map(|i| i as u16).collect())
        } else {
            Indices::Wide(v)
        }
    }
}

impl Indices {
    #[inline]
    fn get(&self, k: usize) -> u32 {
        match self {
            Indices::Narrow(v) => u32::from(v[k]),
            Indices::Wide(v) => v[k],
        }
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        match self {
            Indices::Narrow(v) => v.len(),
            Indices::Wide(v) => v.len(),
        }
    }

    /// Sets index `k` to `i`, widening every index first where `i` does
    /// not fit in two bytes.
    #[inline]
    fn set(&mut self, k: usize, i: u32) {
        if i > u32::from(u16::MAX) {
            self.widen();
        }
        match self {
            Indices::Narrow(v) => v[k] = i as u16,
            Indices::Wide(v) => v[k] = i,
        }
    }

    fn widen(&mut self) {
        if let Indices::Narrow(v) = self {
            *self = Indices::Wide(v.iter().map(|&i| u32::from(i)).collect());
        }
    }

    /// Inserts each `(k, i)` of `new` (ascending `k`, positions among the
    /// indices held) before the index at `k`.
    fn insert_sorted(&mut self, new: &[(usize, u32)]) {
        if new.iter().any(|&(_, i)| i > u32::from(u16::MAX)) {
            self.widen();
        }
        fn merged<T: Copy>(old: &[T], new: impl Iterator<Item = (usize, T)>) -> Vec<T> {
            let mut out = Vec::with_capacity(old.len() + new.size_hint().0);
            let mut from = 0;
            for (k, v) in new {
                out.extend_from_slice(&old[from..k]);
                out.push(v);
                from = k;
            }
            out.extend_from_slice(&old[from..]);
            out
        }
        match self {
            Indices::Narrow(v) => {
                *v = merged(v, new.iter().map(|&(k, i)| (k, i as u16)));
            }
            Indices::Wide(v) => *v = merged(v, new.iter().copied()),
        }
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
            let old = adjustments.idx.get(k);
            let v = adjustments.value_of(&mut made, old, bits, |v| v + saving);
            adjustments.replace(k, v);
        } else {
            let v = adjustments.value_of(&mut made, NO_VALUE, bits, |_| saving);
            adjustments.refer(v);
            new.push((k, v));
        }
    }
    if !new.is_empty() {
        for &(c, _) in changes {
            row[3 * (c as usize / 64) + 1] |= 1 << (c % 64);
        }
        adjustments.idx.insert_sorted(&new);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Indices read back what was set and inserted, across the widening
    /// the first index above two bytes makes, and narrow again when
    /// renumbered within two bytes.
    #[test]
    fn indices_keep_their_values_across_widths() {
        let mut idx = Indices::from(vec![5, 7, 65_535]);
        assert!(matches!(idx, Indices::Narrow(_)));
        let mut want = vec![5u32, 7, 65_535];
        idx.insert_sorted(&[(0, 1), (2, 9)]);
        want.insert(0, 1);
        want.insert(3, 9);
        assert!(matches!(idx, Indices::Narrow(_)));
        idx.set(1, 65_536);
        want[1] = 65_536;
        assert!(matches!(idx, Indices::Wide(_)));
        idx.insert_sorted(&[(5, 70_000)]);
        want.push(70_000);
        assert_eq!((0..idx.len()).map(|k| idx.get(k)).collect::<Vec<_>>(), want);
        let narrow = Indices::from(vec![0, 65_535]);
        assert!(matches!(narrow, Indices::Narrow(_)));
        let mut n2 = narrow.clone();
        n2.insert_sorted(&[(1, 100_000)]);
        assert_eq!(
            (0..3).map(|k| n2.get(k)).collect::<Vec<_>>(),
            [0, 100_000, 65_535]
        );
    }

    /// A value no CPV refers to any more holds the next new one: the
    /// places for values do not grow while the values in use do not.
    #[test]
    fn a_freed_value_holds_the_next() {
        let mut a = Adjustments::default();
        let c = |x: f64| Cost { cpu: x, gpu: 0.0 };
        let v0 = a.value_of(&mut None, NO_VALUE, [1, 0], |_| c(1.0));
        a.refer(v0);
        a.idx.insert_sorted(&[(0, v0)]);
        for round in 0..100u64 {
            let old = a.idx.get(0);
            let v = a.value_of(&mut None, old, [round + 2, 0], |x| x + c(1.0));
            a.replace(0, v);
            a.compact();
            let (held, values, places) = a.sizes();
            assert_eq!((held, values), (1, 1));
            assert!(places <= 2, "{places} places");
        }
        assert_eq!(a.get(0).cpu, 101.0);
    }

    /// A cluster with more than 65,536 distinct adjustments keeps each
    /// (the indices widen) and compacts back to two bytes once most are
    /// dropped.
    #[test]
    fn adjustments_past_two_bytes_of_values() {
        let n = 70_000usize;
        let mut a = Adjustments::default();
        let mut made = None;
        let new: Vec<(usize, u32)> = (0..n)
            .map(|k| {
                let c = Cost {
                    cpu: k as f64,
                    gpu: 0.0,
                };
                let bits = [c.cpu.to_bits(), 0];
                // Inserted into none held: every position is 0.
                let v = a.value_of(&mut made, NO_VALUE, bits, |_| c);
                a.refer(v);
                (0, v)
            })
            .collect();
        a.idx.insert_sorted(&new);
        assert!(matches!(a.idx, Indices::Wide(_)));
        for k in [0, 1, 65_535, 65_536, n - 1] {
            assert_eq!(a.get(k).cpu, k as f64);
        }
        // Every CPV given the same new value: the old ones are dropped.
        let same = Cost { cpu: 1.5, gpu: 0.0 };
        let v = a.value_of(&mut None, NO_VALUE, [1, 1], |_| same);
        for k in 0..n {
            a.replace(k, v);
        }
        a.compact();
        let (held, values, places) = a.sizes();
        assert_eq!((held, values, places), (n, 1, 1));
        assert!(matches!(a.idx, Indices::Narrow(_)));
        assert_eq!(a.get(n - 1).cpu, 1.5);
    }
}
