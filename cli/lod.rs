//! `impostor lod`: the scene written back as one GLB with generated levels
//! of detail as `MSFT_lod` nodes, the levels the cost model uses.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use optimizer::Result;
use optimizer::api::job::Job;
use optimizer::model::cost::CostModel;
use optimizer::scene::{geometry, gltf_load, lod_write};

use crate::output::write_output;
use crate::{read_job, set_threads};

#[derive(Args)]
pub struct LodArgs {
    /// Scene with geometry: .glb or .gltf (a JSON scene summary has none).
    scene: PathBuf,
    /// Output GLB.
    #[arg(short, long)]
    out: PathBuf,
    /// Job JSON: its `lod` options, camera and `max_error_px` decide the
    /// levels and their switching coverages (default: the job defaults).
    #[arg(long)]
    job: Option<PathBuf>,
    /// Generated levels below the full-detail one (overrides `lod.levels`;
    /// at most 31).
    #[arg(long)]
    levels: Option<u32>,
    /// Fraction of triangles each level keeps (overrides `lod.ratio`; in
    /// (0, 1)).
    #[arg(long)]
    ratio: Option<f64>,
    /// Objects with fewer triangles get no levels (overrides
    /// `lod.min_triangles`).
    #[arg(long)]
    min_triangles: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(a: LodArgs) -> Result<ExitCode> {
    set_threads(a.threads)?;
    let mut job = match &a.job {
        Some(j) => read_job(j)?,
        None => Job::with_view_space([0.0; 3], [1.0; 3]),
    };
    if let Some(n) = a.levels {
        job.lod.levels = n;
    }
    if let Some(r) = a.ratio {
        job.lod.ratio = r;
    }
    if let Some(t) = a.min_triangles {
        job.lod.min_triangles = t;
    }
    let scene = gltf_load::load_scene_file(&a.scene)?;
    let geom = geometry::load_geometry_file(&a.scene)?;
    let model = CostModel::new(&job);
    let written = lod_write::write_lod_glb(
        &scene,
        &geom,
        &job.lod,
        model.focal_px,
        model.screen_px,
        job.max_error_px,
    )?;
    write_output(Some(&a.out), &written.glb)?;
    eprintln!(
        "{} objects, {} with levels ({} level nodes), {} bytes",
        scene.objects.len(),
        written.objects_with_levels,
        written.level_nodes,
        written.glb.len()
    );
    Ok(ExitCode::SUCCESS)
}
