//! Placement methods beside the paper's shafts and boxes: per-cell
//! environment maps ([`env_map`]).

pub mod env_map;
