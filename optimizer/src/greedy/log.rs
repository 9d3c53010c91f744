//! What each accept changed, kept compact while the greedy runs: the CPVs'
//! impostor lists are made from it once the greedy's scoring state is gone.

use super::Lineage;
use crate::math::gaps;

/// Per accept, in order: the candidate and the CPVs it made faster
/// (ascending), as gaps in LEB128 bytes ([`gaps`]). CPVs that gain from an accept lie
/// in a few cells, whose CPVs are numbered together, so most gaps take one
/// byte: a fraction of the four bytes (and the room for growth) per entry
/// that per-CPV lists take. The bytes are held in chunks of a few
/// megabytes, filled one after the other: a vector that doubles would
/// hold up to twice the bytes (the log reaches half a gigabyte on the
/// scale-4 city).
#[derive(Clone, Debug, Default)]
pub(super) struct AcceptLog {
    /// Per accept: its candidate, its chunk and the end of its CPVs there
    /// (they start where the accept before it in the chunk ended).
    accepts: Vec<(u32, u32, u32)>,
    chunks: Vec<Vec<u8>>,
    /// One accept's bytes before they go into a chunk.
    scratch: Vec<u8>,
}

/// The least size of a chunk of [`AcceptLog`]'s bytes.
const CHUNK_BYTES: usize = 4 << 20;

impl AcceptLog {
    /// Records that candidate `cand` was accepted and made `cpvs`
    /// (ascending) faster.
    pub(super) fn push(&mut self, cand: u32, cpvs: impl IntoIterator<Item = u32>) {
        self.scratch.clear();
        gaps::push(&mut self.scratch, cpvs);
        let n = self.scratch.len();
        if self
            .chunks
            .last()
            .is_none_or(|c| c.capacity() - c.len() < n)
        {
            self.chunks.push(Vec::with_capacity(CHUNK_BYTES.max(n)));
        }
        let at = self.chunks.len() - 1;
        let chunk = &mut self.chunks[at];
        chunk.extend_from_slice(&self.scratch);
        self.accepts.push((cand, at as u32, chunk.len() as u32));
    }

    /// Per CPV (of `cpvs`), the candidates accepted in it, in accept order,
    /// less some that an impostor of an ancestor cluster accepted later
    /// replaces there: a list is looked through for those
    /// ([`Lineage::drop_replaced`]) whenever it is full, and then keeps at
    /// least half its room free, so each entry is looked at a bounded number
    /// of times and a list is not much longer than what it keeps.
    /// [`super::Selection::drop_replaced`] drops the rest.
    pub(super) fn lists(&self, cpvs: usize, lineage: &Lineage) -> Vec<Vec<u32>> {
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); cpvs];
        let mut seen = vec![u32::MAX; lineage.up.len()];
        let mut stamp = 0u32;
        let (mut start, mut chunk) = (0usize, 0u32);
        for &(cand, at, end) in &self.accepts {
            if at != chunk {
                (start, chunk) = (0, at);
            }
            let end = end as usize;
            for c in gaps::read(&self.chunks[at as usize][start..end]) {
                let list = &mut lists[c as usize];
                if list.len() == list.capacity() && !list.is_empty() {
                    stamp = stamp.wrapping_add(1);
                    if stamp == u32::MAX {
                        seen.iter_mut().for_each(|s| *s = u32::MAX);
                        stamp = 0;
                    }
                    lineage.drop_replaced(list, &mut seen, stamp);
                    if list.len() > list.capacity() / 2 {
                        list.reserve(list.len());
                    }
                }
                list.push(cand);
            }
            start = end;
        }
        lists
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gaps of every byte length read back as written, in accept order, a
    /// CPV listed by several accepts getting each.
    #[test]
    fn lists_read_back_what_was_pushed() {
        // No cluster has an ancestor with candidates: nothing is replaced.
        let lineage = Lineage {
            up: vec![u32::MAX; 4],
            node: vec![0, 1, 2, 3],
        };
        let mut log = AcceptLog::default();
        let far = [0u32, 127, 128, 16_383, 16_384, 2_097_152, 3_000_000];
        log.push(2, far);
        log.push(0, []);
        log.push(1, [5, 127, 3_000_000]);
        let lists = log.lists(3_000_001, &lineage);
        let mut expect: Vec<Vec<u32>> = vec![Vec::new(); 3_000_001];
        for c in far {
            expect[c as usize].push(2);
        }
        for c in [5, 127, 3_000_000] {
            expect[c as usize].push(1);
        }
        assert_eq!(lists, expect);
        // Gaps 0, 127, 1, 16,255, 1, 2,080,768, 902,848 and 5, 122,
        // 2,999,873: a byte per seven bits.
        let bytes: usize = log.chunks.iter().map(Vec::len).sum();
        assert_eq!(bytes, 1 + 1 + 1 + 2 + 1 + 3 + 3 + 1 + 1 + 4);
    }

    /// Accepts whose bytes fill more than one chunk read back as written,
    /// none split between chunks.
    #[test]
    fn accepts_across_chunks_read_back_what_was_pushed() {
        let lineage = Lineage {
            up: vec![u32::MAX; 8],
            node: (0..8).collect(),
        };
        let cpvs = 2_000_000u32;
        let mut log = AcceptLog::default();
        // Every third CPV from a shifting start: 0.67 MB an accept, six to
        // a chunk (the first gap of the last five takes two bytes).
        let ids = |k: u32| (k..cpvs).step_by(3);
        for k in 0..8u32 {
            log.push(k, ids(k * 40));
        }
        assert_eq!(log.chunks.len(), 2);
        assert!(log.chunks.iter().all(|c| c.capacity() == CHUNK_BYTES));
        let lists = log.lists(cpvs as usize, &lineage);
        let mut expect: Vec<Vec<u32>> = vec![Vec::new(); cpvs as usize];
        for k in 0..8u32 {
            for c in ids(k * 40) {
                expect[c as usize].push(k);
            }
        }
        assert_eq!(lists, expect);
    }
}
