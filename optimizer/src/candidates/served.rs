//! The groups each candidate serves, held as offsets from its cluster's
//! first group: two bytes an entry where no cluster has more than 65,536
//! groups (a group per cell whose CPVs list the cluster), four otherwise.
//! The served lists are the largest part of the candidates (421 M entries
//! on the scale-4 city), so their width counts.

use std::ops::Range;

/// The served lists of every candidate, one after another (see
/// `Candidate::served`), each entry a group id less the first group id of
/// the candidate's cluster.
#[derive(Clone, Debug, Default)]
pub struct Served {
    /// The offsets when every one fits in 16 bits, else empty.
    narrow: Vec<u16>,
    /// The offsets otherwise, else empty.
    wide: Vec<u32>,
}

/// The most groups a cluster may have for every served list to be held in
/// two bytes an entry.
pub const NARROW_GROUPS: u32 = 1 << 16;

impl Served {
    /// The lists `offsets` (each entry a group id less its cluster's first;
    /// `total` entries in all), one after another, narrow when `widest`,
    /// the largest number of groups of a cluster, allows it. Each list is
    /// dropped once copied, so they are not held twice.
    pub(super) fn new(
        offsets: impl IntoIterator<Item = Vec<u32>>,
        total: usize,
        widest: u32,
    ) -> Served {
        let mut out = Served::default();
        if widest <= NARROW_GROUPS {
            out.narrow.reserve_exact(total);
            for list in offsets {
                out.narrow.extend(list.iter().map(|&x| x as u16));
            }
        } else {
            out.wide.reserve_exact(total);
            for list in offsets {
                out.wide.extend(list);
            }
        }
        out
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.narrow.len().max(self.wide.len())
    }

    /// True when no candidate serves a group.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        (2 * self.narrow.len() + 4 * self.wide.len()) as u64
    }

    /// The group ids of entries `range`, which belong to a cluster whose
    /// first group is `base`.
    #[inline]
    pub fn ids(&self, base: u32, range: Range<usize>) -> ServedIds<'_> {
        if self.wide.is_empty() {
            ServedIds::Narrow(base, self.narrow[range].iter())
        } else {
            ServedIds::Wide(base, self.wide[range].iter())
        }
    }

    /// The same lists held four bytes an entry (for tests of the wide form).
    #[cfg(test)]
    pub fn widened(&self) -> Served {
        if self.narrow.is_empty() {
            return self.clone();
        }
        Served {
            narrow: Vec::new(),
            wide: self.narrow.iter().map(|&x| u32::from(x)).collect(),
        }
    }
}

/// The group ids of a range of [`Served`] entries.
#[derive(Clone, Debug)]
pub enum ServedIds<'a> {
    /// The cluster's first group and two-byte offsets.
    Narrow(u32, std::slice::Iter<'a, u16>),
    /// The cluster's first group and four-byte offsets.
    Wide(u32, std::slice::Iter<'a, u32>),
}

impl Iterator for ServedIds<'_> {
    type Item = u32;

    #[inline]
    fn next(&mut self) -> Option<u32> {
        match self {
            ServedIds::Narrow(base, it) => it.next().map(|&x| *base + u32::from(x)),
            ServedIds::Wide(base, it) => it.next().map(|&x| *base + x),
        }
    }

    #[inline]
    fn size_hint(&self) -> (usize, Option<usize>) {
        match self {
            ServedIds::Narrow(_, it) => it.size_hint(),
            ServedIds::Wide(_, it) => it.size_hint(),
        }
    }
}

impl ExactSizeIterator for ServedIds<'_> {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_come_back_as_group_ids_in_either_width() {
        let lists = vec![vec![0, 3, 65_535], vec![7, 1]];
        let narrow = Served::new(lists.clone(), 5, 65_536);
        assert_eq!(narrow.bytes(), 10);
        let wide = Served::new(lists, 5, 65_537);
        assert_eq!(wide.bytes(), 20);
        for s in [&narrow, &wide, &narrow.widened()] {
            assert_eq!(s.len(), 5);
            assert_eq!(s.ids(100, 0..3).collect::<Vec<_>>(), vec![100, 103, 65_635]);
            assert_eq!(s.ids(10, 3..5).collect::<Vec<_>>(), vec![17, 11]);
        }
    }
}
