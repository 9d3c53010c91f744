//! Hilly terrain for the generated city (`gen-city --hills H`): a smooth
//! height field of seeded Gaussian hills, the ground as a mesh over it, and
//! every object lifted onto it.
//!
//! Hills have heights in `[0.4 H, H]` and radii of 120–350 m, about one per
//! 250 × 250 m of city, so a city seen from above shows slopes of up to
//! about `H / 150 m`. A building stands on the lowest point of its footprint
//! (its base reaches into the slope above it, as on a real hillside); any
//! other object stands on the height at its origin.

use glam::Vec3;

use crate::math::rng::Rng;
use crate::scene::geometry::MeshData;

/// Grid spacing of the ground mesh, metres.
const SPACING: f64 = 10.0;

/// A smooth height field over the city.
pub(super) struct Terrain {
    /// (centre x, centre z, radius, height) per hill.
    hills: Vec<[f64; 4]>,
}

impl Terrain {
    /// Hills of up to `amplitude` metres over a `size[0] × size[1]` city,
    /// drawn from their own stream of `seed` (the flat city's objects do
    /// not change).
    pub(super) fn new(seed: u64, size: [f64; 2], amplitude: f64) -> Terrain {
        let mut rng = Rng::new(seed ^ 0x6869_6c6c_7300_0001);
        let count = ((size[0] * size[1]) / (250.0 * 250.0)).ceil().max(3.0) as usize;
        let hills = (0..count)
            .map(|_| {
                [
                    rng.range(0.0, size[0]),
                    rng.range(0.0, size[1]),
                    rng.range(120.0, 350.0),
                    rng.range(0.4, 1.0) * amplitude,
                ]
            })
            .collect();
        Terrain { hills }
    }

    /// Height of the ground at `(x, z)`, metres.
    pub(super) fn height(&self, x: f64, z: f64) -> f64 {
        self.hills
            .iter()
            .map(|&[cx, cz, r, h]| {
                let d2 = (x - cx).powi(2) + (z - cz).powi(2);
                h * (-d2 / (r * r)).exp()
            })
            .sum()
    }

    /// The lowest ground height over the box `[x0, x1] × [z0, z1]` (its
    /// corners, centre and edge midpoints).
    pub(super) fn lowest(&self, x0: f64, x1: f64, z0: f64, z1: f64) -> f64 {
        let xs = [x0, 0.5 * (x0 + x1), x1];
        let zs = [z0, 0.5 * (z0 + z1), z1];
        xs.iter()
            .flat_map(|&x| zs.iter().map(move |&z| (x, z)))
            .map(|(x, z)| self.height(x, z))
            .fold(f64::INFINITY, f64::min)
    }

    /// The ground: a grid of about [`SPACING`] metres over the city, with
    /// the normals of the height field.
    pub(super) fn ground(&self, size: [f64; 2]) -> MeshData {
        let nx = (size[0] / SPACING).ceil().max(1.0) as u32;
        let nz = (size[1] / SPACING).ceil().max(1.0) as u32;
        let mut m = MeshData::default();
        for j in 0..=nz {
            for i in 0..=nx {
                let x = size[0] * f64::from(i) / f64::from(nx);
                let z = size[1] * f64::from(j) / f64::from(nz);
                let e = 0.5;
                let dx = (self.height(x + e, z) - self.height(x - e, z)) / (2.0 * e);
                let dz = (self.height(x, z + e) - self.height(x, z - e)) / (2.0 * e);
                m.positions
                    .push(Vec3::new(x as f32, self.height(x, z) as f32, z as f32));
                m.normals
                    .push(Vec3::new(-dx as f32, 1.0, -dz as f32).normalize());
            }
        }
        let at = |i: u32, j: u32| j * (nx + 1) + i;
        for j in 0..nz {
            for i in 0..nx {
                // Counter-clockwise seen from above (+y).
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                m.indices.extend_from_slice(&[a, c, b, a, d, c]);
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_are_bounded_smooth_and_seeded() {
        let size = [1500.0, 1000.0];
        let t = Terrain::new(1, size, 40.0);
        assert_eq!(t.hills.len(), 24);
        let mut top: f64 = 0.0;
        for k in 0..200 {
            let (x, z) = (7.5 * f64::from(k), 5.0 * f64::from(k));
            let h = t.height(x, z);
            assert!((0.0..=40.0 * 24.0).contains(&h));
            // Slope: no hill is steeper than h / r * sqrt(2 / e) per metre.
            let slope = (t.height(x + 1.0, z) - h).abs();
            assert!(slope < 24.0 * 40.0 / 120.0, "{slope}");
            top = top.max(h);
        }
        assert!(top > 10.0, "the city is not hilly: {top}");
        assert_eq!(
            t.height(300.0, 400.0),
            Terrain::new(1, size, 40.0).height(300.0, 400.0)
        );
        assert_ne!(
            t.height(300.0, 400.0),
            Terrain::new(2, size, 40.0).height(300.0, 400.0)
        );
        assert!(t.lowest(100.0, 130.0, 200.0, 220.0) <= t.height(115.0, 210.0));
    }

    #[test]
    fn ground_follows_the_heights_and_faces_up() {
        let size = [100.0, 60.0];
        let t = Terrain::new(3, size, 30.0);
        let g = t.ground(size);
        assert_eq!(g.positions.len(), 11 * 7);
        assert_eq!(g.indices.len(), 10 * 6 * 6);
        for p in &g.positions {
            let h = t.height(f64::from(p.x), f64::from(p.z));
            assert!((f64::from(p.y) - h).abs() < 1e-3);
        }
        for tri in g.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|k| g.positions[tri[k] as usize]);
            assert!((b - a).cross(c - a).y > 0.0, "a ground triangle faces down");
        }
        assert!(
            g.normals
                .iter()
                .all(|n| n.y > 0.0 && (n.length() - 1.0).abs() < 1e-5)
        );
    }
}
