//! The greedy's per-(CPV, cluster) marks.

use crate::math::IdRange;
use crate::model::cost::Cost;

/// Per (CPV, hierarchy node) two bits, covered and adjusted (see
/// [`State`]), and a third where an adjusted (CPV, cluster) starts a run:
/// the adjusted CPVs of a cluster, in CPV order, fall into runs of equal
/// adjustments (the CPVs of a cell that gained the same impostors), each
/// run's value held once in the cluster's [`Adjustments`]. Stored by node;
/// per node and 64 CPVs, four adjacent words: covered, adjusted, run
/// starts, and the runs started before them in the node's row (a rank
/// directory: an adjusted CPV's value is at the number of run starts up to
/// it, less one). Scoring walks one cluster's pairs, whose CPVs are
/// contiguous ids within a cell, so consecutive lookups share cache lines,
/// in the marks and in the values: half a byte per (CPV, node).
pub(super) struct NodeMarks {
    /// Words per node.
    pub(super) row: usize,
    pub(super) bits: Vec<u64>,
}

/// Words per 64 CPVs in a node's row of [`NodeMarks`]: covered, adjusted,
/// run starts, runs before.
pub(super) const WORDS: usize = 4;

/// One cluster's adjustments: the value of each run of its adjusted CPVs
/// ([`NodeMarks`]), in CPV order. Neighbouring runs differ bit for bit (a
/// change that makes them equal merges them): on the scale-4 city about ten
/// adjusted CPVs share a run, so a run's value in place of an index per
/// CPV into shared values holds less than half the bytes.
#[derive(Clone, Debug, Default)]
pub(super) struct Adjustments {
    values: Vec<Cost>,
}

impl Adjustments {
    /// The value of run `k`.
    #[inline]
    pub(super) fn get(&self, k: usize) -> Cost {
        self.values[k]
    }

    /// The runs held.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.values.len()
    }

    /// Replaces the values of runs `range` by `new`, growing the room by
    /// an eighth at least when it must grow (the values are the largest
    /// thing the greedy adds as it goes: doubling would leave up to half
    /// of it unused).
    fn splice(&mut self, range: std::ops::Range<usize>, new: Vec<Cost>) {
        let len = self.values.len() - range.len() + new.len();
        if len > self.values.capacity() {
            let more = (len - self.values.len()).max(self.values.len() / 8);
            self.values.reserve_exact(more);
        }
        self.values.splice(range, new);
    }
}

/// Two adjustments that are one value: equal bit for bit.
#[inline]
fn same(a: Cost, b: Cost) -> bool {
    a.cpu.to_bits() == b.cpu.to_bits() && a.gpu.to_bits() == b.gpu.to_bits()
}

/// What [`NodeMarks`] says of a (CPV, cluster).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mark {
    /// Neither covered nor adjusted: represented by its objects.
    Plain,
    Covered,
    /// Adjusted, with the run of its adjustment.
    Adjusted(usize),
}

/// Bytes of the greedy's marks for `cpvs` CPVs over a hierarchy of `nodes`
/// nodes (part of the memory `place` predicts).
pub fn marks_bytes(cpvs: usize, nodes: usize) -> u64 {
    (nodes * WORDS * cpvs.div_ceil(64) * 8) as u64
}

impl NodeMarks {
    pub(super) fn new(cpvs: usize, nodes: usize) -> Self {
        let row = WORDS * cpvs.div_ceil(64);
        NodeMarks {
            row,
            bits: vec![0; nodes * row],
        }
    }

    pub(super) fn get(&self, c: u32, n: u32) -> Mark {
        let at = n as usize * self.row + WORDS * (c as usize / 64);
        let b = c % 64;
        let (cov, adj) = (self.bits[at], self.bits[at + 1]);
        if cov >> b & 1 == 1 {
            Mark::Covered
        } else if adj >> b & 1 == 1 {
            // A run starts at or before any adjusted CPV of the row.
            let upto = self.bits[at + 2] & (u64::MAX >> (63 - b));
            Mark::Adjusted(self.bits[at + 3] as usize + upto.count_ones() as usize - 1)
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
            let (word, bit) = (WORDS * (c as usize / 64), c % 64);
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

    /// Checks node `n`'s runs against its adjustments: every run starts at
    /// an adjusted CPV, one starts at the row's first, the directory counts
    /// the starts before each word, there is a value per run and
    /// neighbouring runs differ. Returns the adjusted CPVs and the runs.
    #[cfg(test)]
    pub(super) fn check_runs(&self, n: u32, adj: &Adjustments) -> (usize, usize) {
        let row = &self.bits[n as usize * self.row..][..self.row];
        let (mut adjusted, mut runs) = (0usize, 0usize);
        for w in row.chunks_exact(WORDS) {
            assert_eq!(w[2] & !w[1], 0, "a run starts at a CPV not adjusted");
            assert_eq!(w[3] as usize, runs, "directory");
            if adjusted == 0 && w[1] != 0 {
                assert_eq!(
                    w[1] & w[1].wrapping_neg() & w[2],
                    w[1] & w[1].wrapping_neg()
                );
            }
            adjusted += w[1].count_ones() as usize;
            runs += w[2].count_ones() as usize;
        }
        assert_eq!(runs, adj.len(), "a value per run");
        for k in 1..runs {
            assert!(
                !same(adj.get(k - 1), adj.get(k)),
                "runs {k} and before equal"
            );
        }
        (adjusted, runs)
    }
}

/// [`NodeMarks::adjust_all`] on one node's row. The runs of each word with
/// a change are made again (each adjusted CPV there keeps its value or
/// gains its saving; a new run starts wherever the value differs from the
/// one before); between such words and after the last, only the first
/// adjusted CPV can change: it starts a run unless the run before goes on
/// with it (equal values). The values of the runs from the first changed
/// word to the last are replaced, and the directory is counted again from
/// the first changed word.
fn adjust_row(row: &mut [u64], changes: &[(u32, Cost)], adjustments: &mut Adjustments) {
    let (Some(first), Some(last)) = (changes.first(), changes.last()) else {
        return;
    };
    let (w0, w1) = (first.0 as usize / 64, last.0 as usize / 64);
    let words = row.len() / WORDS;
    let values = &adjustments.values;
    // Runs started before word `w` (the old directory: it is counted again
    // only at the end).
    let dir = |row: &[u64], w: usize| row[WORDS * w + 3] as usize;
    // The values of runs `base..end` are made again; the run before them
    // may go on.
    let base = dir(row, w0);
    let mut end = dir(row, w1) + row[WORDS * w1 + 2].count_ones() as usize;
    let mut prev = base.checked_sub(1).map(|r| values[r]);
    // The old run of the CPV at hand (`usize::MAX`: none yet).
    let mut run = base.wrapping_sub(1);
    let mut made: Vec<Cost> = Vec::new();
    // The first adjusted CPV of word `x` (the first of its stretch of
    // words without changes): its value (its own run's, or the run going
    // on) starts a run unless the last one goes on with it. Returns
    // whether it started a run before.
    let boundary =
        |row: &mut [u64], x: usize, run: usize, prev: &mut Option<Cost>, made: &mut Vec<Cost>| {
            let at = WORDS * x;
            let bit = row[at + 1] & row[at + 1].wrapping_neg();
            let started = row[at + 2] & bit != 0;
            let v = if started {
                values[dir(row, x)]
            } else {
                values[run]
            };
            if prev.is_some_and(|p| same(p, v)) {
                row[at + 2] &= !bit;
            } else {
                row[at + 2] |= bit;
                made.push(v);
                *prev = Some(v);
            }
            started
        };
    let (mut next, mut w) = (0usize, w0);
    while next < changes.len() {
        let cw = changes[next].0 as usize / 64;
        if let Some(x) = (w..cw).find(|&x| row[WORDS * x + 1] != 0) {
            // Words `w..cw` hold no change: past the first adjusted CPV,
            // their runs stay as they were.
            let started = boundary(row, x, run, &mut prev, &mut made);
            let (from, to) = (dir(row, x) + usize::from(started), dir(row, cw));
            if to > from {
                made.extend_from_slice(&values[from..to]);
                prev = Some(values[to - 1]);
            }
            run = if to > from || started { to - 1 } else { run };
        }
        let at = WORDS * cw;
        let (adjusted, starts) = (row[at + 1], row[at + 2]);
        let lo = (64 * cw) as u32;
        let n = changes[next..].partition_point(|&(c, _)| c < lo + 64);
        let mine = &changes[next..next + n];
        next += n;
        let all = mine.iter().fold(adjusted, |m, &(c, _)| m | 1 << (c - lo));
        let (mut m, mut new_starts, mut k) = (all, 0u64, 0usize);
        while m != 0 {
            let b = m.trailing_zeros();
            m &= m - 1;
            let bit = 1u64 << b;
            if starts & bit != 0 {
                run = run.wrapping_add(1);
            }
            let changed = mine.get(k).filter(|&&(c, _)| c == lo + b);
            let v = match (adjusted & bit != 0, changed) {
                (true, Some(&(_, saving))) => values[run] + saving,
                (false, Some(&(_, saving))) => saving,
                (true, None) => values[run],
                (false, None) => unreachable!("a CPV of the word is adjusted or changed"),
            };
            k += usize::from(changed.is_some());
            if prev.is_none_or(|p| !same(p, v)) {
                new_starts |= bit;
                made.push(v);
                prev = Some(v);
            }
        }
        row[at + 1] = all;
        row[at + 2] = new_starts;
        w = cw + 1;
    }
    // After the last changed word, up to the first adjusted CPV: the
    // runs after it stay, but its own is made again.
    if let Some(x) = (w1 + 1..words).find(|&x| row[WORDS * x + 1] != 0) {
        let started = boundary(row, x, run, &mut prev, &mut made);
        if started {
            end += 1;
        }
    }
    adjustments.splice(base..end, made);
    let mut before = base as u64;
    for w in row[WORDS * w0..].chunks_exact_mut(WORDS) {
        w[3] = before;
        before += u64::from(w[2].count_ones());
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The adjustment of CPV `c` in node 0, if adjusted.
    fn value(marks: &NodeMarks, adj: &Adjustments, c: u32) -> Option<f64> {
        match marks.get(c, 0) {
            Mark::Adjusted(k) => Some(adj.get(k).cpu),
            _ => None,
        }
    }

    /// CPVs that gain alike share one run, across CPVs not adjusted and
    /// across words; a change inside a run splits it in three, and the
    /// change that makes the values equal again merges them back.
    #[test]
    fn runs_split_and_merge() {
        let mut marks = NodeMarks::new(300, 1);
        let mut adj = vec![Adjustments::default()];
        let c = |x: f64| Cost { cpu: x, gpu: 0.0 };
        let alike = |cpvs: std::ops::Range<u32>, x: f64| -> Vec<(u32, Cost)> {
            cpvs.map(|k| (k, c(x))).collect()
        };
        marks.adjust_all(&[0], &alike(10..150, 1.0), &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (140, 1));
        // New CPVs after a gap, with the same value: still one run.
        marks.adjust_all(&[0], &alike(200..210, 1.0), &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (150, 1));
        marks.adjust_all(&[0], &[(70, c(1.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (150, 3));
        assert_eq!(value(&marks, &adj[0], 70), Some(2.0));
        assert_eq!(value(&marks, &adj[0], 71), Some(1.0));
        assert_eq!(value(&marks, &adj[0], 205), Some(1.0));
        assert_eq!(value(&marks, &adj[0], 160), None);
        // A run starting in an earlier word: the change in word 1 splits
        // the run that began in word 0 and goes on into word 3.
        marks.adjust_all(&[0], &[(64, c(3.0)), (130, c(-1.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (150, 7));
        assert_eq!(value(&marks, &adj[0], 64), Some(4.0));
        assert_eq!(value(&marks, &adj[0], 130), Some(0.0));
        assert_eq!(value(&marks, &adj[0], 131), Some(1.0));
        // Back to equal: merged into one run again.
        marks.adjust_all(
            &[0],
            &[(64, c(-3.0)), (70, c(-1.0)), (130, c(1.0))],
            &mut adj,
        );
        assert_eq!(marks.check_runs(0, &adj[0]), (150, 1));
        // A change at the very first adjusted CPV, one before it and one
        // at the end of the word.
        marks.adjust_all(&[0], &[(3, c(1.0)), (10, c(0.5)), (63, c(2.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (151, 5));
        assert_eq!(value(&marks, &adj[0], 63), Some(3.0));
        assert_eq!(value(&marks, &adj[0], 3), Some(1.0));
        assert_eq!(value(&marks, &adj[0], 10), Some(1.5));
        assert_eq!(value(&marks, &adj[0], 11), Some(1.0));
        // The run going on into the next word keeps its value there.
        assert_eq!(value(&marks, &adj[0], 64), Some(1.0));
        assert_eq!(value(&marks, &adj[0], 299), None);

        // The first adjusted CPV after the changed words starts a run of
        // the value the changes end with: the two runs become one.
        let mut marks = NodeMarks::new(300, 1);
        let mut adj = vec![Adjustments::default()];
        marks.adjust_all(&[0], &alike(10..150, 1.0), &mut adj);
        marks.adjust_all(&[0], &[(128, c(1.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (140, 3));
        marks.adjust_all(&[0], &alike(64..128, 1.0), &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (140, 3));
        assert_eq!(value(&marks, &adj[0], 128), Some(2.0));
        assert_eq!(value(&marks, &adj[0], 129), Some(1.0));

        // Words without changes between changed ones keep their runs; the
        // first adjusted CPV of such a stretch joins the run before it
        // when their values are equal.
        let mut marks = NodeMarks::new(300, 1);
        let mut adj = vec![Adjustments::default()];
        marks.adjust_all(&[0], &alike(0..256, 1.0), &mut adj);
        marks.adjust_all(&[0], &[(10, c(1.0)), (200, c(1.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (256, 5));
        assert_eq!(value(&marks, &adj[0], 150), Some(1.0));
        marks.adjust_all(&[0], &[(64, c(1.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (256, 7));
        marks.adjust_all(&[0], &[(63, c(1.0)), (130, c(5.0))], &mut adj);
        assert_eq!(marks.check_runs(0, &adj[0]), (256, 9));
        let want = [
            (62, 1.0),
            (63, 2.0),
            (64, 2.0),
            (65, 1.0),
            (130, 6.0),
            (131, 1.0),
            (200, 2.0),
        ];
        for (k, x) in want {
            assert_eq!(value(&marks, &adj[0], k), Some(x), "CPV {k}");
        }
    }
}
