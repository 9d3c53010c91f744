//! The grid of minimum-size 3D cells over a view space.

use glam::DVec3;

use crate::math::geom::Aabb;

/// The grid of minimum-size 3D cells over the view space.
#[derive(Clone, Debug)]
pub struct Grid {
    /// View space minimum.
    pub min: DVec3,
    /// View space maximum.
    pub max: DVec3,
    /// Cells per axis.
    pub counts: [u32; 3],
}

impl Grid {
    /// The grid over `min..max` with `ceil(extent / cell_size)` cells per
    /// axis (at least 1).
    pub fn new(min: DVec3, max: DVec3, cell_size: f64) -> Grid {
        let s = cell_size;
        let counts = [0, 1, 2].map(|a| ((max[a] - min[a]) / s).ceil().max(1.0) as u32);
        Grid { min, max, counts }
    }

    /// Coordinate of boundary `i` on `axis`.
    pub fn boundary(&self, axis: usize, i: u32) -> f64 {
        let n = self.counts[axis];
        if i >= n {
            return self.max[axis];
        }
        self.min[axis] + (self.max[axis] - self.min[axis]) * (f64::from(i) / f64::from(n))
    }

    /// The box of cells `lo..hi` (exclusive) per axis.
    pub fn cell_box(&self, lo: [u32; 3], hi: [u32; 3]) -> Aabb {
        Aabb::new(
            DVec3::new(
                self.boundary(0, lo[0]),
                self.boundary(1, lo[1]),
                self.boundary(2, lo[2]),
            ),
            DVec3::new(
                self.boundary(0, hi[0]),
                self.boundary(1, hi[1]),
                self.boundary(2, hi[2]),
            ),
        )
    }

    /// The cell containing `p` (half-open cells; the view-space maximum belongs
    /// to the last cell), or `None` outside the view space.
    pub fn cell_of(&self, p: DVec3) -> Option<[u32; 3]> {
        let mut c = [0u32; 3];
        for (a, slot) in c.iter_mut().enumerate() {
            if !(p[a] >= self.min[a] && p[a] <= self.max[a]) {
                return None;
            }
            let n = self.counts[a];
            let ext = self.max[a] - self.min[a];
            let mut i = if ext > 0.0 {
                (((p[a] - self.min[a]) / ext) * f64::from(n))
                    .floor()
                    .max(0.0) as u32
            } else {
                0
            };
            i = i.min(n - 1);
            // Agree exactly with the stored boundaries.
            if i > 0 && p[a] < self.boundary(a, i) {
                i -= 1;
            } else if i + 1 < n && p[a] >= self.boundary(a, i + 1) {
                i += 1;
            }
            *slot = i;
        }
        Some(c)
    }

    /// Linear index of a cell.
    pub fn linear(&self, c: [u32; 3]) -> u32 {
        (c[2] * self.counts[1] + c[1]) * self.counts[0] + c[0]
    }

    /// Total number of cells.
    pub fn len(&self) -> u64 {
        self.counts.iter().map(|&c| u64::from(c)).product()
    }

    /// True when the grid has no cells (never for a valid job).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
