//! End-to-end tests of the `impostor` command line: the pipeline on generated
//! and real scenes, bad input, determinism and the JSON Schemas.

mod architecture;
mod bad_input;
mod bake;
mod bake_ktx2;
mod cli;
mod corpus;
mod fuzz;
mod golden;
mod lod;
mod packed;
mod real_scenes;
mod report;
mod schemas;
mod tiles;
mod tileset;
mod util;
mod visibility;
