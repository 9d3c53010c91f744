//! Exports of a placement to other formats: 3D Tiles ([`tiles`]).

mod content;
mod switch;
pub mod tiles;
