//! Placement methods beside the paper's shafts and boxes: per-cell
//! environment maps ([`env_map`]), the exact optimum of the shafts'
//! problem ([`exact`]), and the systems the paper was built to beat:
//! far-field textures ([`dts96`]) and image-based object hierarchies
//! ([`iboh`]).

pub mod dts96;
pub mod env_map;
pub mod iboh;
pub mod exact;
