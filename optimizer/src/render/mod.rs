//! Rendering on the CPU: the rasterizer that bakes impostors and draws the
//! image-error views ([`raster`]), and the ray caster of the visibility
//! modes and checks ([`raycast`]).

pub mod raster;
pub mod raycast;
