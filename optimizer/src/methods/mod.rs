//! Placement methods beside the paper's shafts and boxes: per-cell
//! environment maps ([`env_map`]), the exact optimum of the shafts'
//! problem ([`exact`]), and the systems the paper was built to beat:
//! images per viewpoint ([`al99`]), far-field textures ([`dts96`]),
//! image-based object hierarchies ([`iboh`]) and a hierarchical image
//! cache replayed along a path ([`hic96`]).

pub mod al99;
pub mod dts96;
pub mod env_map;
pub mod exact;
pub mod hic96;
pub mod iboh;
