//! The lazy greedy: a heap of blocks ranked by bounds and scores.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use rayon::prelude::*;

use super::{Key, Selection, State, Walked};
use crate::api::job::Job;
use crate::candidates::{Candidate, Candidates};
use crate::math::IdRange;
use crate::views::{Context, ProblemViews};

/// A heap entry: a candidate's key, the sequence number of the refresh
/// that made it (older than its block's newest: outdated), the choice
/// count when it was computed, whether it is the exact score or an upper
/// bound of it, and its block's number (blocks numbered in candidate
/// order).
#[derive(Clone, Copy, Debug)]
struct Entry {
    key: Key,
    seq: u64,
    stamp: u64,
    exact: bool,
    block: u32,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    /// By key; of equal keys the exact one first (a bound equal to an exact
    /// score adds nothing), then the newer.
    fn cmp(&self, o: &Self) -> Ordering {
        self.key
            .cmp(&o.key)
            .then(self.exact.cmp(&o.exact))
            .then(self.seq.cmp(&o.seq))
    }
}

/// Per candidate, the candidates of its block: the candidates of one
/// cluster that serve growing prefixes of the same served groups (one shaft
/// angle and axis); a box is a block of its own.
pub(super) fn blocks(cands: &[Candidate]) -> Vec<IdRange> {
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

/// A block's keys computed again: whether they are exact scores (else
/// bounds), the keys, and what an exact scoring found in its groups.
type Refreshed = (bool, Vec<f64>, Vec<(u32, Walked)>);

/// Blocks of stale keys refreshed together in [`select_lazy`].
pub const LAZY_BATCH: usize = 32;

/// Lazy greedy selection.
///
/// The heap holds one key per block: its best candidate's score or an upper
/// bound of it, with the choice count it was computed at. A key is current
/// when no cell the candidate serves changed since; a current exact key at
/// the top, the largest of upper bounds, is the greedy choice. Keys at the
/// top that are not are recomputed, a batch of [`LAZY_BATCH`] blocks at a
/// time in parallel: a current bound becomes the block's exact scores, any
/// other key a current bound. Scores can rise (memory regained by
/// hierarchy replacement, rounding), so which keys get refreshed may change
/// the choice: the batch is a constant, never derived from the thread
/// count, so the result is the same for any number of threads.
///
/// `progress(unsolved)` is called now and then with the number of CPVs still
/// above `t_max`; when it returns false the selection stops early (the
/// caller discards the incomplete selection).
pub fn select_lazy(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    progress: &mut dyn FnMut(u64) -> bool,
) -> Selection {
    select_lazy_with(ctx, job, pv, cands, progress, None, &[])
}

/// [`select_lazy`] with the CPVs `given_up` (one bit per CPV) given up: no
/// gain in them counts, so no impostor is chosen for them, though they use
/// every chosen impostor that makes them faster. Their reasons are left
/// `None` (the caller knows why it gave them up).
pub fn select_lazy_giving_up(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    given_up: &[u64],
    progress: &mut dyn FnMut(u64) -> bool,
) -> Selection {
    select_lazy_with(ctx, job, pv, cands, progress, None, given_up)
}

/// [`select_lazy`] removing outdated heap keys first when the heap holds
/// more than `first_compaction` keys (default: twice the initial keys, at
/// least 2,048), then whenever it doubles. Tests lower it so that the
/// removal runs on small inputs; the selection is the same either way.
pub(crate) fn select_lazy_with(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    progress: &mut dyn FnMut(u64) -> bool,
    first_compaction: Option<usize>,
    given_up: &[u64],
) -> Selection {
    let mut st = State::giving_up(ctx, pv, cands, job.memory.budget_bytes, given_up);
    if !progress(st.unsolved()) {
        return st.sel;
    }
    // The heap ranks blocks by their best candidate's key: the greedy
    // choice is the best candidate of the best block. Keys start as
    // bounds (cheap: no pair is walked).
    // Each block's candidates, by block number.
    let blocks: Vec<IdRange> = {
        let per_candidate = blocks(&cands.list);
        (0..cands.list.len() as u32)
            .filter(|&i| per_candidate[i as usize].start == i)
            .map(|i| per_candidate[i as usize])
            .collect()
    };
    // The best candidate of block `b` that fits in the memory budget
    // (one that does not never will: the budget's spending only grows).
    let best = |st: &State, b: u32, scores: &[f64]| {
        scores
            .iter()
            .enumerate()
            .map(|(k, &score)| Key {
                score,
                id: b + k as u32,
            })
            .filter(|k| k.score > 0.0 && st.fits(k.id))
            .max()
    };
    let initial: Vec<Option<Key>> = blocks
        .par_iter()
        .map(|&block| {
            let scores = st.bound_block(block);
            (scores.len() as u64, best(&st, block.start, &scores))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .map(|(n, k)| {
            st.sel.bounds += n;
            k
        })
        .collect();
    // Per block, the sequence number of its newest key.
    let mut latest = vec![0u64; blocks.len()];
    let mut heap: BinaryHeap<Entry> = initial
        .into_iter()
        .enumerate()
        .filter_map(|(b, key)| {
            Some(Entry {
                key: key?,
                seq: 0,
                stamp: 0,
                exact: false,
                block: b as u32,
            })
        })
        .collect();
    let mut seq = 0u64;
    let mut compact_at = first_compaction.unwrap_or(2 * heap.len().max(1024));
    let batch = LAZY_BATCH;
    let mut version = 0u64;
    let block_of = |e: &Entry| e.block as usize;
    // The keys to refresh: a current key becomes exact scores, any other
    // a current bound.
    let mut stale: Vec<Entry> = Vec::with_capacity(batch);
    while let Some(&top) = heap.peek() {
        if top.seq < latest[block_of(&top)] {
            heap.pop();
            continue;
        }
        let current = |e: &Entry| e.stamp == version || st.unchanged_since(e.key.id, e.stamp);
        if top.exact && current(&top) && st.fits(top.key.id) {
            heap.pop();
            st.accept(top.key.id);
            // The block's other candidates keep the key as a bound, out
            // of date: they serve the cells just changed.
            heap.push(Entry {
                exact: false,
                ..top
            });
            version += 1;
            if version.is_multiple_of(64) && !progress(st.unsolved()) {
                break;
            }
            continue;
        }
        // The blocks at the top whose keys are not exact now, up to a
        // batch, computed again in parallel: a current key becomes exact
        // scores (a current exact one whose candidate no longer fits in the
        // budget: its block's others), anything older a current bound. An
        // exact current key that fits ends the batch.
        stale.clear();
        while stale.len() < batch {
            match heap.peek() {
                Some(e) if e.seq < latest[block_of(e)] => {
                    heap.pop();
                }
                Some(e) if !(e.exact && current(e) && st.fits(e.key.id)) => {
                    stale.push(*e);
                    heap.pop();
                }
                _ => break,
            }
        }
        // Whether a key is current is found in parallel too: it walks the
        // cells the candidate serves.
        let fresh: Vec<Refreshed> = stale
            .par_iter()
            .map(|e| {
                let block = blocks[block_of(e)];
                if current(e) {
                    let (scores, found) = st.score_block(block);
                    (true, scores, found)
                } else {
                    (false, st.bound_block(block), Vec::new())
                }
            })
            .collect();
        for (e, (exact, scores, found)) in stale.iter().zip(fresh) {
            if exact {
                st.sel.evaluations += scores.len() as u64;
                st.note_walked(&found);
            } else {
                st.sel.bounds += scores.len() as u64;
            }
            seq += 1;
            latest[block_of(e)] = seq;
            if let Some(key) = best(&st, blocks[block_of(e)].start, &scores) {
                heap.push(Entry {
                    key,
                    seq,
                    stamp: version,
                    exact,
                    block: e.block,
                });
            }
        }
        // Outdated keys are dropped when popped; should they make up half
        // the heap, they go at once (the pop order of the others does not
        // change: keys are totally ordered), so the heap stays within about
        // twice the blocks it ranks.
        if heap.len() > compact_at {
            heap.retain(|e| e.seq >= latest[block_of(e)]);
            compact_at = compact_at.max(2 * heap.len());
        }
    }
    if !ctx.cancelled() {
        st.sel.reasons = st.explain_unsolved(job);
    }
    drop((heap, latest, stale));
    st.into_selection()
}
