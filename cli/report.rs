//! `impostor report`: every method × knob value placed and evaluated, as
//! HTML, JSON and CSV; exit 4 when some run broke the guarantee.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::api::job::{Job, Method};
use optimizer::control::Control;
use optimizer::input::GeometryUse;
use optimizer::report::{self, RunStatus};
use optimizer::{Error, Result};

use crate::output::{write_json, write_output};
use crate::progress::Progress;
use crate::{MethodArg, SceneJob};

#[derive(Args)]
pub struct ReportArgs {
    /// The scene and the base job.
    #[command(flatten)]
    input: SceneJob,
    /// Methods to compare, comma-separated (default: all).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<MethodArg>,
    /// A knob and its values, e.g. `target_frame_time_ms=10,15,20` or
    /// `problem_views.cell_size=46,23,11.5` (repeatable).
    #[arg(long)]
    sweep: Vec<String>,
    /// Also perturb the target (±1 %, ±5 %), shift the grid by half a cell
    /// and shuffle the objects, and report each method's spread.
    #[arg(long)]
    stability: bool,
    /// Memory budgets as fractions of each method's unbudgeted memory,
    /// comma-separated, e.g. `0.5,0.25,0.1`: each runs after the method's
    /// base run and is charted as frame time against memory.
    #[arg(long, value_delimiter = ',')]
    budgets: Vec<f64>,
    /// Views per evaluation.
    #[arg(long, default_value_t = 4000)]
    views: u64,
    /// Also bake the impostors of each run of the base job and its sweeps
    /// and chart their baked memory against the placement's estimate (the
    /// scene needs geometry: a .glb or .gltf).
    #[arg(long)]
    bake: bool,
    /// Image views per run of the base job and its sweeps (at most 10,000;
    /// each takes about a second): the footprint mismatch of its impostors,
    /// charted against preprocessing time beside the worst frame time (the
    /// scene needs geometry).
    #[arg(long, default_value_t = 0)]
    images: u32,
    /// Output directory.
    #[arg(short, long)]
    out: PathBuf,
}

pub fn run(a: ReportArgs) -> Result<ExitCode> {
    let job_name = a.input.job_name();
    let text = optimizer::files::read_file(&a.input.job, optimizer::files::MAX_JOB_BYTES, "job")?;
    let parsed = Job::from_json(&text, &job_name)?;
    let job_value: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| Error::bad(&job_name, format!("invalid job JSON: {e}")))?;
    let methods = if a.methods.is_empty() {
        Method::ALL
            .into_iter()
            .filter(|m| m.in_default_report())
            .collect()
    } else {
        a.methods.iter().map(|m| m.0).collect()
    };
    let sweeps = a
        .sweep
        .iter()
        .map(|s| report::run::parse_sweep(s))
        .collect::<Result<Vec<_>>>()?;
    let budgets = report::run::parse_budgets(&a.budgets)?;
    if a.images > optimizer::evaluate::images::MAX_IMAGE_VIEWS {
        return Err(Error::bad(
            "--images",
            format!(
                "{} views is too many (at most {})",
                a.images,
                optimizer::evaluate::images::MAX_IMAGE_VIEWS
            ),
        ));
    }
    let input = a.input.load(
        &parsed,
        if a.bake || a.images > 0 {
            GeometryUse::Required
        } else {
            GeometryUse::WhenNeeded
        },
    )?;
    std::fs::create_dir_all(&a.out).map_err(|e| Error::io(&a.out, e))?;
    let name = a
        .input
        .scene
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let progress = Progress::bar("runs");
    let observer = |e: optimizer::control::Event<'_>| progress.event(e);
    let r = report::run::run(
        &name,
        &input,
        &job_value,
        &report::run::ReportOptions {
            methods,
            sweeps,
            stability: a.stability,
            budgets,
            views: a.views,
            bake: a.bake,
            images: a.images,
        },
        &Control::observed(&observer),
    )?;
    drop(progress);
    write_json(Some(&a.out.join("report.json")), &r)?;
    write_output(
        Some(&a.out.join("report.html")),
        report::render::render_html(&r).as_bytes(),
    )?;
    for (file, text) in report::render::csv_files(&r) {
        write_output(Some(&a.out.join(file)), text.as_bytes())?;
    }
    let failed = r.runs.iter().filter(|x| x.status != RunStatus::Ok).count();
    let broken = r
        .runs
        .iter()
        .filter(|x| {
            x.eval
                .as_ref()
                .is_some_and(|e| e.guarantee_violations() > 0)
        })
        .count();
    eprintln!(
        "{} runs ({failed} failed, {broken} with a broken guarantee), {} walkthroughs: {}",
        r.runs.len(),
        r.walkthroughs.len(),
        a.out.join("report.html").display()
    );
    Ok(if broken > 0 {
        ExitCode::from(4)
    } else {
        ExitCode::SUCCESS
    })
}
