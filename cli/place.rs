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
    /// Memory the run may use, GB (default: the memory available: what the
    /// machine has free, plus what the process holds). A job predicted to
    /// need more is placed in tiles that fit; refused (exit 2) only where
    /// none do.
    #[arg(long, value_name = "GB", value_parser = parse_gb)]
    max_memory_gb: Option<u64>,
}

/// A positive number of GB, as bytes.
fn parse_gb(s: &str) -> std::result::Result<u64, String> {
    match s.parse::<f64>() {
        Ok(g) if g.is_finite() && g > 0.0 && g <= 1e9 => Ok((g * 1e9) as u64),
        _ => Err(format!("expected a positive number of GB, got {s:?}")),
    }
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
    let opts = PlaceOptions {
        prune: a.prune,
        max_memory_bytes: a.max_memory_gb,
        max_memory_name: Some("--max-memory-gb"),
    };
    let output = prepared.place(&opts, &Control::observed(&observer))?;
    drop(progress);
    write_json(a.out.as_deref(), &output.placement)?;
    if let Some(s) = &a.stats {
        write_json(Some(s), &output.stats)?;
    }
    let sum = &output.placement.summary;
    if let Some(t) = &output.stats.tiled_for_memory {
        eprintln!(
            "placed in {} × {} tiles: the whole job needed about {:.2} GB, more than the {:.2} GB {} \
             (set \"partition\" in the job to choose the tiles)",
            t.tiles[0],
            t.tiles[1],
            t.predicted_bytes as f64 / 1e9,
            t.limit_bytes as f64 / 1e9,
            opts.limit_name()
        );
    }
    eprintln!(
        "{} CPVs, {} candidates, {} impostors, {:.3} MB, {} unsolved",
        sum.cpvs,
        sum.candidates,
        sum.impostors,
        sum.memory_bytes as f64 / 1e6,
        sum.unsolved_cpvs
    );
    if sum.unsolved_cpvs > 0 {
        let reasons: Vec<String> = sum
            .unsolved_by_reason
            .iter()
            .map(|(r, n)| format!("{n} {}", r.as_str()))
            .collect();
        eprintln!(
            "unsolved CPVs up to {:.3} ms above the target{}{}",
            sum.max_residual_ms,
            if reasons.is_empty() { "" } else { ": " },
            reasons.join(", ")
        );
        if output.stats.candidates > 0
            && output.stats.exact.is_none()
            && !job.memory.keeps_partial()
        {
            eprintln!(
                "no impostor is kept for unsolved CPVs alone (they draw that geometry; \
                 `memory.keep_partial: true` or a budget spends memory on making them faster)"
            );
        }
    }
    if let Some(b) = sum.budget_bytes {
        eprintln!(
            "memory budget {:.3} MB, {:.1} % used",
            b as f64 / 1e6,
            100.0 * sum.memory_bytes as f64 / (b.max(1) as f64)
        );
    }
    if let Some(p) = output.stats.cpv_precision {
        eprintln!(
            "{} problem views proven by refinement; {:.0} % of {} sampled CPVs have an exact view above the target{}",
            output.stats.cpvs_refined_away,
            p * 100.0,
            output.stats.cpv_precision_sampled,
            if p == 0.0 {
                " (none: the CPVs come from the estimate's excess; a target below the slowest view tests the guarantee)"
            } else {
                ""
            }
        );
    }
    Ok(if sum.unsolved_cpvs > 0 {
        ExitCode::from(3)
    } else {
        ExitCode::SUCCESS
    })
}
