//! `impostor pvs`: the visible set of every view-space cell as a PVS file.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use optimizer::api::job::VisibilityMode;
use optimizer::input::{GeometryUse, Load, SceneInput, Source};
use optimizer::{Error, Result};

use crate::output::write_json;
use crate::{read_job, set_threads};

#[derive(Args)]
pub struct PvsArgs {
    /// Scene: .glb or .gltf.
    scene: PathBuf,
    /// Job JSON.
    #[arg(long)]
    job: PathBuf,
    /// Output PVS JSON (default: standard output).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(a: PvsArgs) -> Result<ExitCode> {
    set_threads(a.threads)?;
    let job_name = a.job.display().to_string();
    let job = read_job(&a.job)?;
    if !matches!(
        job.visibility.mode,
        VisibilityMode::Conservative | VisibilityMode::Sampled
    ) {
        return Err(Error::bad(
            format!("{job_name}: visibility"),
            "must be \"conservative\" or \"sampled\" to compute a PVS",
        ));
    }
    let load = Load::new(Source::File(&a.scene), GeometryUse::WhenNeeded);
    let input = SceneInput::load(&load, &job, &job_name)?;
    let prepared = input.prepare(&job, &job_name)?;
    let start = Instant::now();
    let vis = prepared
        .visibility()
        .ok_or_else(|| Error::Internal("a visibility mode without visibility".into()))?;
    let file = vis.to_pvs_file();
    write_json(a.out.as_deref(), &file)?;
    let st = vis.stats();
    let prep: f64 = input.seconds.iter().map(|s| s.seconds).sum();
    eprintln!(
        "{} cells, {:.1} visible objects per cell ({:.2} % of {}), preparation {:.2} s, \
         sets {:.2} s wall ({:.2} s CPU)",
        st.cells_computed,
        st.mean_visible_objects,
        100.0 * st.mean_visible_fraction,
        input.scene.objects.len(),
        prep,
        start.elapsed().as_secs_f64(),
        st.cpu_seconds
    );
    Ok(ExitCode::SUCCESS)
}
