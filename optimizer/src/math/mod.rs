//! Shared mathematics: boxes, spheres, cones, view frusta, view-direction
//! intervals on cube faces, the conservative enclosing set of a problem
//! view, and the seeded random number generator.

pub mod enclosing;
pub mod gaps;
pub mod geom;
pub mod grid;
pub mod rng;

use std::ops::Range;

/// Ids `start..end`: a range of `u32` indices that is `Copy` (unlike
/// [`std::ops::Range`]), for compact per-item spans of shared arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IdRange {
    /// First id.
    pub start: u32,
    /// One past the last id.
    pub end: u32,
}

impl IdRange {
    /// `start..end`.
    pub fn new(start: u32, end: u32) -> Self {
        debug_assert!(start <= end);
        IdRange { start, end }
    }

    /// Number of ids.
    pub fn len(self) -> u32 {
        self.end - self.start
    }

    /// True when the range holds no id.
    pub fn is_empty(self) -> bool {
        self.start == self.end
    }

    /// The range as slice indices.
    pub fn indices(self) -> Range<usize> {
        self.start as usize..self.end as usize
    }
}
