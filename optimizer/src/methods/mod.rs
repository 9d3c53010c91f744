//! Placement methods beside the paper's shafts and boxes: per-cell
//! environment maps ([`env_map`]) and the exact optimum of the shafts'
//! problem ([`exact`]).

pub mod env_map;
pub mod exact;
