//! Shared mathematics: boxes, spheres, cones, view frusta, view-direction
//! intervals on cube faces, and the seeded random number generator.

pub mod geom;
pub mod grid;
pub mod rng;
