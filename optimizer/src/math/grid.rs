//! The grid of minimum-size 3D cells over a view space.
//!
//! Cell boundaries lie at `origin + k·cell_size` for whole `k` (the grid is
//! anchored in the world, not at the view space's corner), clipped to the view
//! space: the cells a view space shares with a larger or shifted one are the
//! same cells, so growing it at one side changes only the cells there.

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
    /// The anchor: a boundary lies at `origin + k·cell` on every axis.
    origin: DVec3,
    /// Side of a whole cell.
    cell: f64,
    /// `k` of the first boundary inside the view space (after `min`), per axis.
    first: [f64; 3],
}

impl Grid {
    /// The grid over `min..max` whose inner boundaries are the planes
    /// `origin + k·cell_size` strictly inside the view space (at least 1 cell
    /// per axis; the cells at the view space's sides may be thinner).
    pub fn new(min: DVec3, max: DVec3, cell_size: f64, origin: DVec3) -> Grid {
        let s = cell_size;
        let mut first = [0.0; 3];
        let mut counts = [1u32; 3];
        for a in 0..3 {
            let at = |k: f64| origin[a] + k * s;
            // The first anchored plane strictly above min ... (the floor is
            // off by at most one step; a job's cell is far above the rounding
            // step of its coordinates)
            let mut k0 = ((min[a] - origin[a]) / s).floor() + 1.0;
            for _ in 0..4 {
                if at(k0 - 1.0) <= min[a] {
                    break;
                }
                k0 -= 1.0;
            }
            for _ in 0..4 {
                if at(k0) > min[a] {
                    break;
                }
                k0 += 1.0;
            }
            // ... and the last strictly below max.
            let mut k1 = ((max[a] - origin[a]) / s).ceil() - 1.0;
            for _ in 0..4 {
                if at(k1 + 1.0) >= max[a] {
                    break;
                }
                k1 += 1.0;
            }
            for _ in 0..4 {
                if at(k1) < max[a] {
                    break;
                }
                k1 -= 1.0;
            }
            first[a] = k0;
            counts[a] = if k1 >= k0 { (k1 - k0 + 2.0) as u32 } else { 1 };
        }
        Grid {
            min,
            max,
            counts,
            origin,
            cell: s,
            first,
        }
    }

    /// Coordinate of boundary `i` on `axis` (0 is the view space's minimum,
    /// `counts[axis]` its maximum).
    pub fn boundary(&self, axis: usize, i: u32) -> f64 {
        if i == 0 {
            return self.min[axis];
        }
        if i >= self.counts[axis] {
            return self.max[axis];
        }
        self.origin[axis] + (self.first[axis] + f64::from(i - 1)) * self.cell
    }

    /// The largest cell's side per axis (a whole cell's, or the view space's
    /// extent where it is thinner): what per-cell sampling is sized for.
    pub fn largest_cell(&self) -> DVec3 {
        DVec3::from_array([0, 1, 2].map(|a| {
            let n = self.counts[a];
            [0, 1.min(n - 1), n - 1]
                .into_iter()
                .map(|i| self.boundary(a, i + 1) - self.boundary(a, i))
                .fold(0.0, f64::max)
        }))
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
            let k = ((p[a] - self.origin[a]) / self.cell).floor() - self.first[a] + 1.0;
            let mut i = k.clamp(0.0, f64::from(n - 1)) as u32;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boundaries_are_anchored_planes_clipped_to_the_view_space() {
        let g = Grid::new(
            DVec3::new(-5.0, 1.5, 10.0),
            DVec3::new(50.0, 2.0, 69.0),
            23.0,
            DVec3::ZERO,
        );
        // x: -5 | 0 23 46 | 50; y: one cell; z: 10 | 23 46 | 69 (69 = 3·23 is
        // the maximum, not an inner plane).
        assert_eq!(g.counts, [4, 1, 3]);
        let xs: Vec<f64> = (0..=4).map(|i| g.boundary(0, i)).collect();
        assert_eq!(xs, vec![-5.0, 0.0, 23.0, 46.0, 50.0]);
        let zs: Vec<f64> = (0..=3).map(|i| g.boundary(2, i)).collect();
        assert_eq!(zs, vec![10.0, 23.0, 46.0, 69.0]);
        assert_eq!(g.cell_of(DVec3::new(-5.0, 1.5, 10.0)), Some([0, 0, 0]));
        assert_eq!(g.cell_of(DVec3::new(0.0, 1.7, 22.999)), Some([1, 0, 0]));
        assert_eq!(g.cell_of(DVec3::new(-1e-12, 1.7, 23.0)), Some([0, 0, 1]));
        assert_eq!(g.cell_of(DVec3::new(50.0, 2.0, 69.0)), Some([3, 0, 2]));
        assert_eq!(g.cell_of(DVec3::new(50.1, 2.0, 69.0)), None);
        // An origin moves the planes.
        let h = Grid::new(
            DVec3::new(-5.0, 1.5, 10.0),
            DVec3::new(50.0, 2.0, 69.0),
            23.0,
            DVec3::new(11.5, 0.0, 0.0),
        );
        let xs: Vec<f64> = (0..=h.counts[0]).map(|i| h.boundary(0, i)).collect();
        assert_eq!(xs, vec![-5.0, 11.5, 34.5, 50.0]);
    }

    #[test]
    fn a_grown_view_space_keeps_the_cells_it_shares() {
        let cell_size = 23.0;
        let a = Grid::new(
            DVec3::new(3.0, 1.5, 7.0),
            DVec3::new(700.0, 2.0, 480.0),
            cell_size,
            DVec3::ZERO,
        );
        let b = Grid::new(
            DVec3::new(3.0 - 11.5, 1.5, 7.0 - 11.5),
            DVec3::new(700.0, 2.0, 480.0),
            cell_size,
            DVec3::ZERO,
        );
        // Every inner plane of `a` is a plane of `b`, and every cell of `a`
        // off its grown sides is a cell of `b`, bit for bit.
        for axis in [0, 2] {
            let pa: Vec<f64> = (1..a.counts[axis]).map(|i| a.boundary(axis, i)).collect();
            let pb: Vec<f64> = (0..=b.counts[axis]).map(|i| b.boundary(axis, i)).collect();
            assert!(pa.iter().all(|p| pb.contains(p)), "axis {axis}");
        }
        assert_eq!(a.largest_cell(), DVec3::new(23.0, 0.5, 23.0));
        let thin = Grid::new(DVec3::ZERO, DVec3::new(10.0, 30.0, 50.0), 23.0, DVec3::ZERO);
        assert_eq!(thin.largest_cell(), DVec3::new(10.0, 23.0, 23.0));
        let inner = a.cell_box([1, 0, 1], [2, 1, 2]);
        let c = b.cell_of(inner.center()).unwrap();
        assert_eq!(b.cell_box(c, [c[0] + 1, 1, c[2] + 1]), inner);
        // Cells partition the view space: consecutive boundaries increase and
        // no cell is larger than the cell size.
        for g in [&a, &b] {
            for axis in 0..3 {
                for i in 0..g.counts[axis] {
                    let w = g.boundary(axis, i + 1) - g.boundary(axis, i);
                    assert!(w > 0.0 && w <= cell_size, "axis {axis} cell {i}: {w}");
                }
            }
        }
    }
}
