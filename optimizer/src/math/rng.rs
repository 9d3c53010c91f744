//! A small seeded random number generator (SplitMix64): deterministic across
//! platforms and thread counts, no dependency.

use glam::DVec3;

/// SplitMix64.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }

    /// Uniform in the box.
    pub fn in_box(&mut self, lo: DVec3, hi: DVec3) -> DVec3 {
        DVec3::new(
            self.range(lo.x, hi.x),
            self.range(lo.y, hi.y),
            self.range(lo.z, hi.z),
        )
    }

    /// Uniform on the unit sphere.
    pub fn unit_vector(&mut self) -> DVec3 {
        self.direction_in_pitch(-90f64.to_radians(), 90f64.to_radians())
    }

    /// Uniform on the part of the unit sphere with elevation in `[lo, hi]`
    /// (radians).
    pub fn direction_in_pitch(&mut self, lo: f64, hi: f64) -> DVec3 {
        let y = self.range(lo.sin(), hi.sin());
        let az = self.range(0.0, std::f64::consts::TAU);
        let r = (1.0 - y * y).max(0.0).sqrt();
        DVec3::new(r * az.cos(), y, r * az.sin())
    }
}
