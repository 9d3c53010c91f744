//! The paper's two models: the frame-time cost of objects and impostors
//! ([`cost`]), and the impostor's view cells, layers, resolution and memory
//! ([`impostor`]); with the geometry of an impostor's layers ([`layers`]).

pub mod cost;
pub mod impostor;
pub mod layers;
pub mod validate;
