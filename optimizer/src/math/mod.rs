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

/// The least `f32` not below `x`: a bound held in half an `f64`'s memory.
pub fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x { f.next_up() } else { f }
}

/// The greatest `f32` not above `x`.
pub fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x { f.next_down() } else { f }
}

#[cfg(test)]
mod rounding_tests {
    use super::{f32_down, f32_up};

    /// Each rounds the way it says, to a neighbouring `f32`.
    #[test]
    fn f32_rounding_goes_the_way_it_says() {
        for x in [0.1, 1.0 / 3.0, 2.5, 1e-7, 12_345.678_9, 3.0e38] {
            let (d, u) = (f32_down(x), f32_up(x));
            assert!(f64::from(d) <= x && x <= f64::from(u), "{x}");
            assert!(d == u || d.next_up() == u, "{x}");
        }
    }
}
