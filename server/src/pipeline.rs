//! The one module that calls the optimizer's job API: it checks a
//! submission before it is accepted, and runs an accepted job (place,
//! evaluate, report, bake) from its files in the artifact store.

use std::sync::atomic::AtomicBool;

use axum::http::StatusCode;
use serde_json::Value;

use optimizer::api::job::{Job, VisibilityMode};
use optimizer::api::placement::Placement;
use optimizer::control::{Control, Event};
use optimizer::evaluate::EvalOptions;
use optimizer::input::{GeometryUse, Load, Prepared, SceneInput, Source};
use optimizer::place::PlaceOptions;
use optimizer::report::render::render_html;
use optimizer::report::run::{RunOutput, evaluate_placed, place_and_evaluate, single_run_report};

use crate::api::types::JobSummary;
use crate::artifacts::JobFiles;
use crate::error::ApiError;
use crate::store::{JOB, PVS, SCENE};

/// Checks that a submission can run: the job and the scene parse, the
/// scene has geometry where the job or baking needs it, and a PVS file is
/// given (and fits the scene) when the job asks for precomputed visibility.
/// Bad input is answered with 422.
pub(crate) fn check_submission(
    scene: &[u8],
    job: &[u8],
    pvs: Option<&[u8]>,
    bake: bool,
) -> Result<(), ApiError> {
    let unprocessable = |e: optimizer::Error| {
        if e.is_bad_input() {
            ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, e.to_string())
        } else {
            ApiError::internal(e)
        }
    };
    let parsed = Job::from_json(job, "job").map_err(unprocessable)?;
    parsed.method().check_places("job").map_err(unprocessable)?;
    let objects = optimizer::scene::gltf_load::load_scene_bytes(scene, "scene")
        .map_err(unprocessable)?
        .objects
        .len();
    if optimizer::input::needs_geometry(&parsed) && !scene.starts_with(b"glTF") {
        // A summary (or glTF JSON): check it has geometry at all.
        optimizer::scene::geometry::load_geometry_bytes(scene, "scene").map_err(|e| {
            ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                format!("the job's visibility or lod.generate needs the scene's geometry: {e}"),
            )
        })?;
    }
    match (parsed.visibility.mode, pvs) {
        (VisibilityMode::Precomputed, None) => {
            return Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "job: visibility \"precomputed\" needs a `pvs` part (a PVS file)",
            ));
        }
        (_, Some(bytes)) => {
            optimizer::api::pvs::PvsFile::from_json(bytes, "pvs")
                .and_then(|f| f.check(objects, "pvs"))
                .map_err(unprocessable)?;
        }
        _ => {}
    }
    if bake && !scene.starts_with(b"glTF") && scene.first() == Some(&b'{') {
        // A summary (or glTF JSON); baking needs geometry.
        optimizer::scene::geometry::load_geometry_bytes(scene, "scene").map_err(unprocessable)?;
    }
    Ok(())
}

/// What a run needs besides the job's files.
pub(crate) struct RunOptions<'a> {
    /// Whether to bake the impostors after the placement.
    pub bake: bool,
    /// Views of the evaluation (uniform, and again inside problem views).
    pub eval_views: u64,
    /// Set to stop the run at its next check.
    pub cancel: &'a AtomicBool,
    /// The server's per-job memory limit (`--job-max-memory`), bytes.
    pub max_memory_bytes: Option<u64>,
    /// Called with the stage name and the fraction of the run done.
    pub progress: &'a (dyn Fn(&str, f64) + Sync),
}

/// Runs the job of `files` (`scene`, `job.json`, optional `pvs.json`) and
/// writes its results there, each atomically: `placement.json`,
/// `report.html`, `evaluation.json` and, when baking, `impostors.glb`.
/// Returns the JSON text of the job's [`JobSummary`].
pub(crate) fn run_job(files: JobFiles<'_>, opts: &RunOptions<'_>) -> optimizer::Result<String> {
    run_with(files, opts, |prepared, place, eval, ctl| {
        place_and_evaluate(prepared, place, eval, true, ctl)
    })
}

/// The jobs of the tiles of a job with `"partition"` (each over its part
/// of the view space, on the same grid), as JSON; empty for any other job.
pub(crate) fn tile_jobs(job: &[u8]) -> Result<Vec<Vec<u8>>, ApiError> {
    let job = Job::from_json(job, "job")
        .map_err(|e| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))?;
    let Some(p) = &job.partition else {
        return Ok(Vec::new());
    };
    optimizer::place::tiles::tile_jobs(&job, p.tiles)
        .iter()
        .map(|t| serde_json::to_vec(t).map_err(ApiError::internal))
        .collect()
}

/// The merge of the tiled job of `files` whose tiles were run as jobs of
/// their own (`tiles`, in tile order): their placements merged as
/// `impostor place` merges them in one process (the same bytes), then
/// evaluated, reported and baked over the whole job like [`run_job`].
pub(crate) fn merge_job(
    files: JobFiles<'_>,
    tiles: &[JobFiles<'_>],
    opts: &RunOptions<'_>,
) -> optimizer::Result<String> {
    run_with(files, opts, |prepared, _, eval, ctl| {
        let start = std::time::Instant::now();
        let mut parts = Vec::with_capacity(tiles.len());
        for (k, t) in tiles.iter().enumerate() {
            let bytes = t.read_required("placement.json")?;
            let p: Placement = serde_json::from_slice(&bytes).map_err(|e| {
                optimizer::Error::Internal(format!("tile {}'s placement.json: {e}", k + 1))
            })?;
            parts.push(p);
        }
        let placement = optimizer::place::tiles::merge(prepared.job(), parts)?;
        let stats = optimizer::api::stats::Stats {
            cpvs: placement.summary.cpvs,
            impostors: placement.summary.impostors,
            memory_bytes: placement.summary.memory_bytes,
            unsolved_cpvs: placement.summary.unsolved_cpvs,
            ..Default::default()
        };
        let out = optimizer::place::PlaceOutput { placement, stats };
        let seconds = start.elapsed().as_secs_f64();
        evaluate_placed(prepared, out, seconds, eval, true, ctl)
    })
}

/// A job's inputs, loaded.
struct Loaded {
    job_bytes: Vec<u8>,
    job: Job,
    input: SceneInput,
}

/// Loads the job of `files` with its scene's geometry as `geometry` asks.
fn load(files: JobFiles<'_>, geometry: GeometryUse) -> optimizer::Result<Loaded> {
    let scene_bytes = files.read_required(SCENE)?;
    let job_bytes = files.read_required(JOB)?;
    let pvs_bytes = files.read(PVS)?;
    let job = Job::from_json(&job_bytes, "job")?;
    let load = Load::new(
        Source::Bytes {
            bytes: &scene_bytes,
            name: "scene",
        },
        geometry,
    )
    .with_pvs(
        pvs_bytes
            .as_deref()
            .map(|bytes| Source::Bytes { bytes, name: "pvs" }),
    );
    let input = SceneInput::load(&load, &job, "job")?;
    Ok(Loaded {
        job_bytes,
        job,
        input,
    })
}

/// Calls `f` with the control of a run: `opts`' cancel flag and progress.
fn controlled<T>(
    opts: &RunOptions<'_>,
    f: impl FnOnce(&Control) -> optimizer::Result<T>,
) -> optimizer::Result<T> {
    let observer = |e: Event<'_>| {
        if let Event::Progress {
            stage, fraction, ..
        } = e
        {
            (opts.progress)(stage, fraction);
        }
    };
    let ctl = Control {
        cancel: Some(opts.cancel),
        observer: Some(&observer),
    };
    f(&ctl)
}

/// The placement options of a run under `opts`.
fn placement_options(opts: &RunOptions<'_>) -> PlaceOptions {
    PlaceOptions {
        max_memory_bytes: opts.max_memory_bytes,
        max_memory_name: Some("the server's --job-max-memory"),
        ..PlaceOptions::default()
    }
}

/// Places the tile of a tiled job stored in `files` and writes its
/// `placement.json` only: the merge of the tiles is evaluated, reported
/// and baked over the whole job. Returns the JSON text of its
/// [`JobSummary`] (its evaluation's figures 0: not evaluated).
pub(crate) fn run_tile(files: JobFiles<'_>, opts: &RunOptions<'_>) -> optimizer::Result<String> {
    let l = load(files, GeometryUse::WhenNeeded)?;
    let prepared = l.input.prepare(&l.job, "job")?;
    let out = controlled(opts, |ctl| {
        ctl.check()?;
        let out = prepared.place(&placement_options(opts), ctl)?;
        ctl.check()?;
        Ok(out)
    })?;
    files.write("placement.json", optimizer::to_json_bytes(&out.placement)?)?;
    summary_text(&JobSummary {
        placement: out.placement.summary.clone(),
        max_ms: 0.0,
        violations_in_solved: 0,
        violations_in_cpv_views: 0,
        control_violations_in_solved: 0,
        parallax_max_px: None,
        seconds: out.stats.seconds.clone(),
    })
}

/// Loads the job of `files`, runs `place` (which places, or merges, and
/// evaluates) and writes the results.
fn run_with(
    files: JobFiles<'_>,
    opts: &RunOptions<'_>,
    place: impl FnOnce(&Prepared, &PlaceOptions, &EvalOptions, &Control) -> optimizer::Result<RunOutput>,
) -> optimizer::Result<String> {
    // Geometry when the job needs it, for the evaluation's check of the
    // visible sets when the scene has any, and always when baking.
    let l = load(
        files,
        if opts.bake {
            GeometryUse::Required
        } else {
            GeometryUse::ForChecks
        },
    )?;
    let prepared = l.input.prepare(&l.job, "job")?;
    controlled(opts, |ctl| {
        // Loading a large scene takes a while: a cancel during it stops here.
        ctl.check()?;
        let eval = EvalOptions {
            views: opts.eval_views,
            cpv_views: opts.eval_views,
            seed: 1,
            ..EvalOptions::default()
        };
        let out = place(&prepared, &placement_options(opts), &eval, ctl)?;
        finish_run(files, opts, &prepared, &l, out, ctl)
    })
}

/// Bakes (when asked), writes the results of the run of `loaded` and
/// returns the JSON text of its [`JobSummary`].
fn finish_run(
    files: JobFiles<'_>,
    opts: &RunOptions<'_>,
    prepared: &Prepared,
    loaded: &Loaded,
    mut out: RunOutput,
    ctl: &Control,
) -> optimizer::Result<String> {
    ctl.check()?;
    // Baked before the report, which then shows the baked memory against
    // the placement's estimate.
    let glb = if opts.bake {
        ctl.progress("bake", 0.99, "baking the impostors");
        let glb = out.bake(
            prepared,
            &optimizer::bake::BakeOptions::for_memory(&prepared.job().memory),
        )?;
        // The bake does not stop part-way: a cancel during it is honoured
        // here (and by the worker, which ends a cancelled job `cancelled`).
        ctl.check()?;
        Some(glb)
    } else {
        None
    };
    files.write(
        "placement.json",
        optimizer::to_json_bytes(&out.place.placement)?,
    )?;
    let job_text: Value = serde_json::from_slice(&loaded.job_bytes).unwrap_or(Value::Null);
    let report = single_run_report("scene", &loaded.input, &job_text, &out);
    files.write("report.html", render_html(&report).into_bytes())?;
    files.write("evaluation.json", optimizer::to_json_bytes(&out.eval)?)?;
    if let Some(glb) = glb {
        files.write("impostors.glb", glb)?;
    }
    let summary = JobSummary {
        placement: out.place.placement.summary.clone(),
        max_ms: out.eval.max_ms,
        violations_in_solved: out.eval.violations_in_solved,
        violations_in_cpv_views: out.eval.violations_in_cpv_views,
        control_violations_in_solved: out.eval.control.violations_in_solved,
        parallax_max_px: out.eval.parallax.as_ref().map(|x| x.max_px),
        seconds: out.place.stats.seconds.clone(),
    };
    summary_text(&summary)
}

/// The stored text of `summary`: through a JSON value, whose keys are
/// sorted, so it lists the fields in the same order as the status answer.
fn summary_text(summary: &JobSummary) -> optimizer::Result<String> {
    serde_json::to_value(summary)
        .map(|v| v.to_string())
        .map_err(|e| optimizer::Error::Internal(e.to_string()))
}
