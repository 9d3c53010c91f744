//! What each accept changed, kept compact while the greedy runs: the CPVs'
//! impostor lists are made from it once the greedy's scoring state is gone.

use super::Lineage;
use crate::math::gaps;

/// Per accept, in order: the candidate and the CPVs it made faster
/// (ascending), as gaps in LEB128 bytes ([`gaps`]). CPVs that gain from an accept lie
/// in a few cells, whose CPVs are numbered together, so most gaps take one
/// byte: a fraction of the four bytes (and the room for growth) per entry
/// that per-CPV lists take.
#[derive(Clone, Debug, Default)]
pub(super) struct AcceptLog {
    /// Per accept: its candidate and the end of its CPVs in `bytes`.
    accepts: Vec<(u32, u64)>,
    bytes: Vec<u8>,
}

impl AcceptLog {
    /// Records that candidate `cand` was accepted and made `cpvs`
    /// (ascending) faster.
    pub(super) fn push(&mut self, cand: u32, cpvs: impl IntoIterator<Item = u32>) {
        gaps::push(&mut self.bytes, cpvs);
        self.accepts.push((cand, self.bytes.len() as u64));
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
        let mut start = 0usize;
        for &(cand, end) in &self.accepts {
            let end = end as usize;
            for c in gaps::read(&self.bytes[start..end]) {
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
        assert_eq!(log.bytes.len(), 1 + 1 + 1 + 2 + 1 + 3 + 3 + 1 + 1 + 4);
    }
}
