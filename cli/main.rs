//! The `impostor` command-line tool: a thin shell over the `optimizer`
//! library, one file per subcommand. Exit codes: 0 done, 3 placed with
//! unsolved problem views, 4 a check found a broken guarantee, 2 bad input,
//! 1 internal error.

mod bake;
mod evaluate;
mod gen_city;
mod info;
mod lod;
mod output;
mod place;
mod progress;
mod pvs;
mod report;
mod schema;
mod tiles;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::builder::PossibleValue;
use clap::{Parser, Subcommand, ValueEnum};
use optimizer::api::job::{Job, Method};
use optimizer::input::{GeometryUse, Load, SceneInput, Source};
use optimizer::{Error, Result};

/// Automatic impostor placement for guaranteed frame rates and low memory.
#[derive(Parser)]
#[command(name = "impostor", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Place impostors: exit 0 when every problem view is solved, 3 when some
    /// stay unsolved (the placement is still written), 2 for bad input.
    Place(place::PlaceArgs),
    /// Check a placement independently with random views and exact frusta.
    Evaluate(evaluate::EvaluateArgs),
    /// Compare placement methods on one scene: every method × knob value is
    /// placed and evaluated; writes DIR/report.html (charts of memory against
    /// frame time, the guarantee, speed against accuracy, walkthroughs),
    /// report.json and CSV files.
    Report(report::ReportArgs),
    /// Compute the potentially visible set of every view-space cell of a job
    /// (its `visibility` mode: conservative or sampled) and write it as a PVS
    /// file, reusable with `"visibility": "precomputed"`.
    Pvs(pvs::PvsArgs),
    /// Render a placement's impostors into layered, alpha-masked quads and
    /// write them as one GLB with texture atlases.
    Bake(bake::BakeArgs),
    /// Export a placement and its baked impostors as a 3D Tiles 1.1
    /// tileset: cluster geometry tiles refined (REPLACE) into boxes of
    /// viewer positions (request volumes) drawing the placement's
    /// impostors there.
    Tiles(tiles::TilesArgs),
    /// Generate a seeded, Vienna-like procedural city.
    GenCity(gen_city::GenCityArgs),
    /// Print a scene's statistics: objects, triangles, draw calls, bounds.
    Info(info::InfoArgs),
    /// Write the scene as one GLB with generated levels of detail as
    /// `MSFT_lod` nodes (the levels and switching coverages the cost model
    /// uses with the job's `lod` options).
    Lod(lod::LodArgs),
    /// Write the JSON Schemas of the job, scene summary, placement and
    /// evaluation files.
    Schema(schema::SchemaArgs),
}

/// A placement method on the command line (the names of the job's
/// `method`).
#[derive(Clone, Copy, Debug)]
struct MethodArg(Method);

impl ValueEnum for MethodArg {
    fn value_variants<'a>() -> &'a [Self] {
        const ALL: [MethodArg; Method::ALL.len()] = {
            let mut out = [MethodArg(Method::Shafts); Method::ALL.len()];
            let mut i = 0;
            while i < out.len() {
                out[i] = MethodArg(Method::ALL[i]);
                i += 1;
            }
            out
        };
        &ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(PossibleValue::new(self.0.name()))
    }
}

/// The scene and job a placing command reads, with its PVS file and thread
/// count.
#[derive(clap::Args)]
struct SceneJob {
    /// Scene: .glb, .gltf or a JSON scene summary.
    scene: PathBuf,
    /// Job JSON (schemas/job.schema.json).
    #[arg(long)]
    job: PathBuf,
    /// Precomputed PVS file (for `"visibility": "precomputed"`).
    #[arg(long)]
    pvs: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

impl SceneJob {
    /// How errors name the job.
    fn job_name(&self) -> String {
        self.job.display().to_string()
    }

    /// Sets the thread count, then loads the scene (with its geometry as
    /// `geometry` says, and the PVS file) for `job`.
    fn load(&self, job: &Job, geometry: GeometryUse) -> Result<SceneInput> {
        set_threads(self.threads)?;
        let load = Load::new(Source::File(&self.scene), geometry)
            .with_pvs(self.pvs.as_deref().map(Source::File));
        SceneInput::load(&load, job, &self.job_name())
    }
}

/// Reads and validates a job file.
fn read_job(path: &Path) -> Result<Job> {
    let bytes = optimizer::files::read_file(path, optimizer::files::MAX_JOB_BYTES, "job")?;
    Job::from_json(&bytes, &path.display().to_string())
}

/// Sets the number of worker threads (all cores when not given).
fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 || n > 1024 {
            return Err(Error::bad(
                "--threads",
                format!("{n} must be between 1 and 1024"),
            ));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    }
    Ok(())
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Place(a) => place::run(a),
        Command::Evaluate(a) => evaluate::run(a),
        Command::Report(a) => report::run(a),
        Command::Pvs(a) => pvs::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Tiles(a) => tiles::run(a),
        Command::GenCity(a) => gen_city::run(a),
        Command::Info(a) => info::run(a),
        Command::Lod(a) => lod::run(a),
        Command::Schema(a) => schema::run(a),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match std::panic::catch_unwind(|| run(cli)) {
        Ok(Ok(code)) => code,
        Ok(Err(e)) => {
            eprintln!("error: {e}");
            match e {
                Error::BadInput { .. } | Error::Io { .. } => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
        Err(_) => {
            eprintln!("error: internal error (a bug): the program panicked");
            ExitCode::from(1)
        }
    }
}
