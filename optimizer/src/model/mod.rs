//! The paper's two models: the frame-time cost of objects and impostors
//! ([`cost`]), and the impostor's view cells, layers, resolution and memory
//! ([`impostor`]).

pub mod cost;
pub mod impostor;
pub mod validate;
