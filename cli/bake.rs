//! `impostor bake`: a placement's impostors rendered into one GLB.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::Result;
use optimizer::api::job::MemoryParams;
use optimizer::api::texture_format::TextureFormat;
use optimizer::bake::{self, BakeOptions};
use optimizer::scene::geometry;

use crate::evaluate::read_placement;
use crate::output::{write_json, write_output};
use crate::{read_job, set_threads};

#[derive(Args)]
pub struct BakeArgs {
    /// Scene with geometry: .glb or .gltf (a JSON scene summary has none).
    scene: PathBuf,
    /// Placement JSON written by `place` for this scene.
    #[arg(long)]
    placement: PathBuf,
    /// Job JSON (its memory model is used for the baked-memory report and
    /// its view space is written into the GLB's scene extras; default: the
    /// reference memory model, no view space).
    #[arg(long)]
    job: Option<PathBuf>,
    /// Output GLB.
    #[arg(short, long)]
    out: PathBuf,
    /// Write the bake report (layers, atlases, texels, memory) to this JSON file.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Atlas texture format: png, or ktx2 (Basis Universal UASTC with a
    /// coverage-keeping mip chain, `KHR_texture_basisu`; 1 GPU byte per
    /// texel). Default: the job's `memory.texture_format`, else png.
    #[arg(long, value_parser = parse_texture_format)]
    textures: Option<TextureFormat>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

fn parse_texture_format(s: &str) -> std::result::Result<TextureFormat, String> {
    s.parse()
}

pub fn run(a: BakeArgs) -> Result<ExitCode> {
    set_threads(a.threads)?;
    let job = a.job.as_deref().map(read_job).transpose()?;
    let memory = job
        .as_ref()
        .map_or_else(MemoryParams::default, |j| j.memory.clone());
    let p = read_placement(&a.placement)?;
    let scene = optimizer::scene::gltf_load::load_scene_file(&a.scene)?;
    let geom = geometry::load_geometry_file(&a.scene)?;
    let defaults = BakeOptions::for_memory(&memory);
    let start = std::time::Instant::now();
    let (glb, rep) = bake::bake(
        &scene,
        &geom,
        &memory,
        job.as_ref().map(|j| &j.view_space),
        &p,
        &BakeOptions {
            textures: a.textures.unwrap_or(defaults.textures),
            ..defaults
        },
        &a.placement.display().to_string(),
    )?;
    write_output(Some(&a.out), &glb)?;
    if let Some(r) = &a.report {
        write_json(Some(r), &rep)?;
    }
    eprintln!(
        "{} impostors, {} of {} layers written, {} {} atlases ({:.3} MB), {} texels, \
         {:.3} MB baked (placement estimate {:.3} MB), {:.1} s",
        rep.impostors,
        rep.layers_written,
        rep.layers,
        rep.atlases,
        rep.texture_format,
        rep.texture_bytes as f64 / 1e6,
        rep.texels,
        rep.memory_bytes as f64 / 1e6,
        rep.placement_memory_bytes as f64 / 1e6,
        start.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
