//! `impostor place`: the placement of a job, written as JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::Result;
use optimizer::control::Control;
use optimizer::input::GeometryUse;
use optimizer::place::PlaceOptions;

use crate::output::write_json;
use crate::progress::Progress;
use crate::{MethodArg, SceneJob, read_job};

#[derive(Args)]
pub struct PlaceArgs {
    #[command(flatten)]
    input: SceneJob,
    /// Output placement JSON (default: standard output).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Write timings and counters to this JSON file.
    #[arg(long)]
    stats: Option<PathBuf>,
    /// Remove impostors not needed to keep every problem view within the target.
    #[arg(long)]
    prune: bool,
    /// Print each stage's wall time to stderr.
    #[arg(short, long)]
    verbose: bool,
    /// Placement method (overrides the job's `method`).
    #[arg(long)]
    method: Option<MethodArg>,
}

pub fn run(a: PlaceArgs) -> Result<ExitCode> {
    let mut job = read_job(&a.input.job)?;
    if let Some(m) = a.method {
        job.method = Some(m.0);
    }
    let input = a.input.load(&job, GeometryUse::WhenNeeded)?;
    let prepared = input.prepare(&job, &a.input.job_name())?;
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
