//! `impostor tiles`: a placement and its baked impostors as a 3D Tiles 1.1
//! tileset (`tileset.json` and GLB contents in one directory).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::export::tiles::{self, TilesInput};
use optimizer::files::{MAX_SCENE_BYTES, read_file};
use optimizer::scene::geometry;
use optimizer::{Error, Result};

use crate::evaluate::read_placement;
use crate::output::write_output;
use crate::{read_job, set_threads};

#[derive(Args)]
pub struct TilesArgs {
    /// Scene with geometry: .glb or .gltf (a JSON scene summary has none).
    scene: PathBuf,
    /// Job JSON the placement was made with (view space, camera).
    #[arg(long)]
    job: PathBuf,
    /// Placement JSON written by `place` for this scene.
    #[arg(long)]
    placement: PathBuf,
    /// The GLB `bake` wrote for this placement.
    #[arg(long)]
    impostors: PathBuf,
    /// Output directory (created if missing): tileset.json and GLB contents.
    #[arg(short, long)]
    out: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(a: TilesArgs) -> Result<ExitCode> {
    set_threads(a.threads)?;
    let job = read_job(&a.job)?;
    let placement = read_placement(&a.placement)?;
    let baked = read_file(&a.impostors, MAX_SCENE_BYTES, "GLB of impostors")?;
    let scene = optimizer::scene::gltf_load::load_scene_file(&a.scene)?;
    let geom = geometry::load_geometry_file(&a.scene)?;
    let files = tiles::export(
        &scene,
        &geom,
        &TilesInput {
            job: &job,
            placement: &placement,
            placement_source: &a.placement.display().to_string(),
            baked: &baked,
            baked_source: &a.impostors.display().to_string(),
        },
    )?;
    std::fs::create_dir_all(&a.out).map_err(|e| Error::io(&a.out, e))?;
    for (name, bytes) in &files {
        write_output(Some(&a.out.join(name)), bytes)?;
    }
    eprintln!(
        "{} files ({} impostors) in {}",
        files.len(),
        placement.impostors.len(),
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
