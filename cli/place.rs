//! `impostor place`: the placement of a job, written as JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::Result;
use optimizer::control::Control;
use optimizer::input::{GeometryUse, Load, SceneInput, Source};
use optimizer::place::PlaceOptions;

use crate::output::write_json;
use crate::progress::Progress;
use crate::{MethodArg, read_job, set_threads};

#[derive(Args)]
pub struct PlaceArgs {
    /// Scene: .glb, .gltf or a JSON scene summary.
    scene: PathBuf,
    /// Job JSON (schemas/job.schema.json).
    #[arg(long)]
    job: PathBuf,
    /// Output placement JSON (default: standard output).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Write timings and counters to this JSON file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Remove impostors not needed to keep every problem view within the target.
    #[arg(long)]
    prune: bool,
    /// Print each stage's wall time to stderr.
    #[arg(short, long)]
    verbose: bool,
    /// Precomputed PVS file (for `"visibility": "precomputed"`).
    #[arg(long)]
    pvs: Option<PathBuf>,
    /// Placement method (overrides the job's `method`).
    #[arg(long)]
    method: Option<MethodArg>,
}

pub fn run(a: PlaceArgs) -> Result<ExitCode> {
    set_threads(a.threads)?;
    let job_name = a.job.display().to_string();
    let mut job = read_job(&a.job)?;
    if let Some(m) = a.method {
        job.method = Some(m.0);
    }
    let load = Load::new(Source::File(&a.scene), GeometryUse::WhenNeeded)
        .with_pvs(a.pvs.as_deref().map(Source::File));
    let input = SceneInput::load(&load, &job, &job_name)?;
    let prepared = input.prepare(&job, &job_name)?;
    let progress = Progress::spinner(a.verbose);
    let observer = |e: optimizer::control::Event<'_>| progress.event(e);
    let output = prepared.place(
        &PlaceOptions {
            prune: a.prune,
            max_pairs: None,
        },
        &Control::observed(&observer),
    )?;
    drop(progress);
    write_json(a.out.as_deref(), &output.placement)?;
    if let Some(s) = &a.stats {
        write_json(Some(s), &output.stats)?;
    }
    let sum = &output.placement.summary;
    eprintln!(
        "{} CPVs, {} candidates, {} impostors, {:.3} MB, {} unsolved",
        sum.cpvs,
        sum.candidates,
        sum.impostors,
        sum.memory_bytes as f64 / 1e6,
        sum.unsolved_cpvs
    );
    Ok(if sum.unsolved_cpvs > 0 {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    })
}
