//! `impostor gen-city`: the seeded procedural city (or the failure scene).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::citygen;
use optimizer::scene::gltf_load;
use optimizer::{Error, Result};

use crate::output::{write_json, write_output};

#[derive(Args)]
pub struct GenCityArgs {
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Fraction of the full city's area (1 ≈ 1500 × 1000 m, ≥ 5,000 objects;
    /// at most 16).
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Put the city on seeded hills up to this many metres high (0: flat).
    /// Objects and their ids are those of the flat city, lifted onto the
    /// ground.
    #[arg(long, default_value_t = 0.0)]
    hills: f64,
    /// Write the JSON scene summary instead of the GLB.
    #[arg(long)]
    summary: bool,
    /// Give street objects (trees, lamps, benches, cars, bins) two coarser
    /// levels of detail (glTF MSFT_lod with MSFT_screencoverage); objects
    /// and their full-detail geometry are unchanged.
    #[arg(long)]
    lod: bool,
    /// Generate the failure scene of the comparison reports instead: a
    /// street lined with small, expensive statues next to the view space
    /// (use with fixtures/jobs/failure.json).
    #[arg(long)]
    failure: bool,
    /// Generate the long-track stress scene instead: a 4.2 km race track
    /// lined by about 4,400 small objects (use with fixtures/jobs/track.json).
    #[arg(long, conflicts_with = "failure")]
    track: bool,
    /// Output file (default: standard output for --summary; required for GLB).
    #[arg(short, long)]
    out: Option<PathBuf>,
}

pub fn run(a: GenCityArgs) -> Result<ExitCode> {
    let glb = if a.failure {
        citygen::generate_failure(a.seed)?
    } else if a.track {
        citygen::generate_track(a.seed)?
    } else {
        citygen::generate(&citygen::CityParams {
            seed: a.seed,
            scale: a.scale,
            lod: a.lod,
            hills: a.hills,
        })?
    };
    if a.summary {
        let scene = gltf_load::load_scene_bytes(&glb, "generated city")?;
        write_json(a.out.as_deref(), &scene.summary())?;
    } else {
        let out = a.out.ok_or_else(|| {
            Error::bad(
                "gen-city",
                "-o FILE is required for the GLB (or use --summary)",
            )
        })?;
        write_output(Some(&out), &glb)?;
    }
    Ok(ExitCode::SUCCESS)
}
