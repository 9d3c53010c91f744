//! Exports of a placement to other formats: 3D Tiles ([`tiles`]).

mod content;
pub mod tiles;
