//! The `impostor` command-line tool: a thin shell over the `optimizer` library.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use optimizer::api::job::{Job, MemoryParams, Method, VisibilityMode};
use optimizer::api::placement::Placement;
use optimizer::api::pvs::{PvsCell, PvsFile};
use optimizer::api::schema;
use optimizer::evaluate::images as image_eval;
use optimizer::evaluate::{EvalOptions, evaluate_input};
use optimizer::input::{SceneInput, needs_geometry};
use optimizer::place::{Control, PlaceOptions, place_input};
use optimizer::scene::{geometry, gltf_load};
use optimizer::{Error, Result, bake, citygen, report};

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
    Place {
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
        /// Placement method (overrides the job's `method`): shafts, boxes,
        /// both, per-cell, env-map or shafts+prune.
        #[arg(long)]
        method: Option<String>,
    },
    /// Check a placement independently with random views and exact frusta.
    Evaluate {
        /// Scene: .glb, .gltf or a JSON scene summary.
        scene: PathBuf,
        /// Job JSON.
        #[arg(long)]
        job: PathBuf,
        /// Placement JSON written by `place`.
        #[arg(long)]
        placement: PathBuf,
        /// Output evaluation JSON (default: standard output).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Number of random views.
        #[arg(long, default_value_t = 10_000)]
        views: u64,
        /// Seed of the view sampler.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Also render this many views in CPVs with impostors twice (all
        /// geometry; geometry with the impostors) and report the image error.
        #[arg(long, default_value_t = 0)]
        images: u32,
        /// Baked impostors (GLB from `bake`) for --images; default: bake in memory.
        #[arg(long)]
        impostors: Option<PathBuf>,
        /// Per-channel colour tolerance (0–255) of the image mismatch test.
        #[arg(long, default_value_t = 24)]
        tolerance: u8,
        /// Write the worst view's renders side by side as a PNG into this directory.
        #[arg(long)]
        dump: Option<PathBuf>,
        /// Precomputed PVS file (for `"visibility": "precomputed"`).
        #[arg(long)]
        pvs: Option<PathBuf>,
        /// Visibility check: rays per view through the image (0: none).
        #[arg(long, default_value_t = 256)]
        check_rays: u32,
        /// Visibility check: culled objects in the view probed per view.
        #[arg(long, default_value_t = 16)]
        check_objects: u32,
    },
    /// Compare placement methods on one scene: every method × knob value is
    /// placed and evaluated; writes DIR/report.html (charts of memory against
    /// frame time, the guarantee, speed against accuracy, walkthroughs),
    /// report.json and CSV files.
    Report {
        /// Scene: .glb, .gltf or a JSON scene summary.
        scene: PathBuf,
        /// The base job JSON.
        #[arg(long)]
        job: PathBuf,
        /// Methods to compare, comma-separated (default: all of shafts, boxes,
        /// both, per-cell, env-map, shafts+prune).
        #[arg(long, value_delimiter = ',')]
        methods: Vec<String>,
        /// A knob and its values, e.g. `target_frame_time_ms=10,15,20` or
        /// `problem_views.cell_size=46,23,11.5` (repeatable).
        #[arg(long)]
        sweep: Vec<String>,
        /// Also perturb the target (±1 %, ±5 %), shift the grid by half a cell
        /// and shuffle the objects, and report each method's spread.
        #[arg(long)]
        stability: bool,
        /// Views per evaluation.
        #[arg(long, default_value_t = 4000)]
        views: u64,
        /// Precomputed PVS file (for `"visibility": "precomputed"`).
        #[arg(long)]
        pvs: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Output directory.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Compute the potentially visible set of every view-space cell of a job
    /// (its `visibility` mode: conservative or sampled) and write it as a PVS
    /// file, reusable with `"visibility": "precomputed"`.
    Pvs {
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
    },
    /// Render a placement's impostors into layered, alpha-masked quads and
    /// write them as one GLB with texture atlases.
    Bake {
        /// Scene with geometry: .glb or .gltf (a JSON scene summary has none).
        scene: PathBuf,
        /// Placement JSON written by `place` for this scene.
        #[arg(long)]
        placement: PathBuf,
        /// Job JSON (its memory model is used for the baked-memory report;
        /// default: the reference memory model).
        #[arg(long)]
        job: Option<PathBuf>,
        /// Output GLB.
        #[arg(short, long)]
        out: PathBuf,
        /// Write the bake report (layers, atlases, texels, memory) to this JSON file.
        #[arg(long)]
        report: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Generate a seeded, Vienna-like procedural city.
    GenCity {
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Fraction of the full city's area (1 ≈ 1500 × 1000 m, ≥ 5,000 objects).
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
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
        /// Output file (default: standard output for --summary; required for GLB).
        #[arg(short, long)]
        out: Option<PathBuf>,
    },
    /// Print a scene's statistics: objects, triangles, draw calls, bounds.
    Info {
        /// Scene: .glb, .gltf or a JSON scene summary.
        scene: PathBuf,
    },
    /// Write the JSON Schemas of the job, scene summary, placement and
    /// evaluation files.
    Schema {
        /// Output directory.
        #[arg(long, default_value = "schemas")]
        out_dir: PathBuf,
    },
}

/// Writes `bytes` to `path` atomically (temporary file + rename), or to
/// standard output.
fn write_output(path: Option<&Path>, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    match path {
        None => std::io::stdout()
            .write_all(bytes)
            .map_err(|e| Error::io("<stdout>", e)),
        Some(p) => {
            // Through a symbolic link to its target; into anything that is
            // not a regular file (a device such as /dev/null, a pipe) write
            // directly: replacing it would destroy it.
            // Special files (/dev/stdout, /dev/null, /proc/self/fd/N) are
            // written into, whatever they lead to.
            if p.starts_with("/dev") || p.starts_with("/proc") {
                return std::fs::OpenOptions::new()
                    .append(true)
                    .open(p)
                    .and_then(|mut f| f.write_all(bytes))
                    .map_err(|e| Error::io(p, e));
            }
            let resolved = match std::fs::metadata(p) {
                Ok(m) if m.is_dir() => {
                    return Err(Error::bad(p.display().to_string(), "is a directory"));
                }
                Ok(m) if !m.is_file() => {
                    return std::fs::OpenOptions::new()
                        .write(true)
                        .open(p)
                        .and_then(|mut f| f.write_all(bytes))
                        .map_err(|e| Error::io(p, e));
                }
                Ok(_) => std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf()),
                // Not there yet: a dangling link is followed to where its
                // target will be.
                Err(_) => {
                    let mut r = p.to_path_buf();
                    for _ in 0..32 {
                        match std::fs::read_link(&r) {
                            Ok(target) => {
                                r = match r.parent() {
                                    Some(dir) if target.is_relative() => dir.join(target),
                                    _ => target,
                                }
                            }
                            Err(_) => break,
                        }
                    }
                    r
                }
            };
            let p = resolved.as_path();
            let dir = p
                .parent()
                .filter(|d| !d.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            let name = p
                .file_name()
                .ok_or_else(|| Error::bad(p.display().to_string(), "not a file path"))?;
            let tmp = dir.join(format!(
                ".{}.tmp{}",
                name.to_string_lossy(),
                std::process::id()
            ));
            std::fs::write(&tmp, bytes).map_err(|e| Error::io(p, e))?;
            std::fs::rename(&tmp, p).map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                Error::io(p, e)
            })
        }
    }
}

fn read_job(path: &Path) -> Result<Job> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    Job::from_json(&bytes, &path.display().to_string())
}

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

/// The worst view's two renders side by side (geometry left, impostors
/// right) with a 4-pixel gap, as PNG.
fn side_by_side_png(pair: &image_eval::ImagePair) -> Result<Vec<u8>> {
    let (w, h, gap) = (pair.width as usize, pair.height as usize, 4usize);
    let out_w = 2 * w + gap;
    let mut out = vec![255u8; out_w * h * 4];
    for y in 0..h {
        let row = &mut out[y * out_w * 4..(y + 1) * out_w * 4];
        row[..w * 4].copy_from_slice(&pair.geometry[y * w * 4..(y + 1) * w * 4]);
        row[(w + gap) * 4..].copy_from_slice(&pair.impostors[y * w * 4..(y + 1) * w * 4]);
    }
    bake::encode_png(&out, out_w as u32, h as u32)
}

fn read_placement(path: &Path) -> Result<Placement> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| {
        Error::bad(
            path.display().to_string(),
            format!("invalid placement JSON: {e}"),
        )
    })
}

fn json(value: &impl serde::Serialize) -> Result<Vec<u8>> {
    optimizer::to_json_bytes(value)
}

fn parse_method(name: &str) -> Result<Method> {
    Method::parse(name).ok_or_else(|| {
        Error::bad(
            "--method",
            format!(
                "unknown method {name:?}; expected one of {}",
                Method::ALL.map(Method::name).join(", ")
            ),
        )
    })
}

fn is_gltf(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
}

/// Loads the scene (and its geometry and a PVS file when the job needs
/// them) and prepares it for `job`. With `geometry_if_gltf`, a glTF
/// scene's geometry is loaded even if the job could do without it (the
/// evaluation's visibility check uses it). Errors about the job name
/// `job_path`.
fn load_input(
    scene: &Path,
    pvs: Option<&Path>,
    job: &Job,
    job_path: &str,
    geometry_if_gltf: bool,
) -> Result<SceneInput> {
    let s = gltf_load::load_scene_file(scene)?;
    let geometry = if needs_geometry(job) || (geometry_if_gltf && is_gltf(scene)) {
        Some(geometry::load_geometry_file(scene)?)
    } else {
        None
    };
    let pvs = match pvs {
        Some(p) => {
            let bytes = std::fs::read(p).map_err(|e| Error::io(p, e))?;
            Some(PvsFile::from_json(&bytes, &p.display().to_string())?)
        }
        None => None,
    };
    SceneInput::new(s, geometry, pvs, job).map_err(|e| match e {
        Error::BadInput { what, message } if what == "job" => Error::bad(job_path, message),
        e => e,
    })
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Place {
            scene,
            job,
            out,
            threads,
            stats,
            prune,
            verbose,
            pvs,
            method,
        } => {
            set_threads(threads)?;
            let job_path = job.display().to_string();
            let mut job = read_job(&job)?;
            if let Some(m) = method {
                job.method = Some(parse_method(&m)?);
            }
            let input = load_input(&scene, pvs.as_deref(), &job, &job_path, false)?;
            let output = place_input(
                &input,
                &job,
                &PlaceOptions {
                    prune,
                    progress: true,
                    verbose,
                    max_pairs: None,
                },
                &Control::default(),
            )
            .map_err(|e| match e {
                Error::BadInput { what, message } if what == "job" => Error::bad(job_path, message),
                e => e,
            })?;
            write_output(out.as_deref(), &json(&output.placement)?)?;
            if let Some(s) = stats {
                write_output(Some(&s), &json(&output.stats)?)?;
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
        Command::Evaluate {
            scene,
            job,
            placement,
            out,
            views,
            seed,
            threads,
            images,
            impostors,
            tolerance,
            dump,
            pvs,
            check_rays,
            check_objects,
        } => {
            set_threads(threads)?;
            let job_path = job.display().to_string();
            let job = read_job(&job)?;
            let scene_path = scene;
            let check = job.visibility.mode != VisibilityMode::None;
            let input = load_input(&scene_path, pvs.as_deref(), &job, &job_path, check)?;
            let name = placement.display().to_string();
            let p = read_placement(&placement)?;
            let opts = EvalOptions {
                views,
                seed,
                check_rays,
                check_objects,
            };
            let mut eval = evaluate_input(&input, &job, &p, &opts, &name)?;
            if let Some(v) = &eval.visibility {
                eprintln!(
                    "visibility {:?}: {} cells, {:.1} visible objects per view ({:.2} %), \
                     {} missed objects over {} checked views ({} rays)",
                    v.mode,
                    v.cells,
                    v.mean_visible_objects,
                    100.0 * v.mean_visible_fraction,
                    v.missed_objects,
                    v.views_checked,
                    v.rays
                );
            }
            if let Some(x) = &eval.parallax {
                eprintln!(
                    "parallax of {} impostors: max {:.2} px (impostor {}), mean {:.2} px, \
                     {} over the {} px budget ({} over 1.5 times it)",
                    x.impostors,
                    x.max_px,
                    x.worst_impostor,
                    x.mean_px,
                    x.over_budget,
                    x.max_error_px,
                    x.over_budget_1_5
                );
            }
            if images > 0 {
                let geom = geometry::load_geometry_file(&scene_path)?;
                let layers = match &impostors {
                    Some(path) => {
                        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
                        bake::read_layers(&bytes, &path.display().to_string())?
                    }
                    None => bake::render_layers(&geom, &p, &name)?,
                };
                let opts = image_eval::ImageOptions {
                    views: images,
                    seed,
                    tolerance,
                };
                let (report, pair) = image_eval::image_error(&geom, &job, &p, &layers, &opts)?;
                eprintln!(
                    "{} image views: PSNR mean {:.2} dB (min {:.2}), mismatch mean {:.4} (max {:.4})",
                    report.views,
                    report.psnr_db.mean,
                    report.psnr_db.min,
                    report.mismatch_fraction.mean,
                    report.mismatch_fraction.max
                );
                if let (Some(dir), Some(pair)) = (&dump, pair) {
                    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
                    let png = side_by_side_png(&pair)?;
                    write_output(Some(&dir.join("worst_view.png")), &png)?;
                }
                eval.image = Some(report);
            }
            write_output(out.as_deref(), &json(&eval)?)?;
            eprintln!(
                "{} views: max {:.3} ms, p99 {:.3} ms, {} violations ({} in solved)",
                eval.views, eval.max_ms, eval.p99_ms, eval.violations, eval.violations_in_solved
            );
            Ok(
                if eval.violations_in_solved > 0 || eval.impostors_outside_view_cell > 0 {
                    ExitCode::from(4)
                } else {
                    ExitCode::SUCCESS
                },
            )
        }
        Command::Bake {
            scene,
            placement,
            job,
            out,
            report,
            threads,
        } => {
            set_threads(threads)?;
            let memory = match job {
                Some(j) => read_job(&j)?.memory,
                None => MemoryParams::default(),
            };
            let p = read_placement(&placement)?;
            let geom = geometry::load_geometry_file(&scene)?;
            let start = std::time::Instant::now();
            let (glb, rep) = bake::bake(
                &geom,
                &memory,
                &p,
                &bake::BakeOptions::default(),
                &placement.display().to_string(),
            )?;
            write_output(Some(&out), &glb)?;
            if let Some(r) = report {
                write_output(Some(&r), &json(&rep)?)?;
            }
            eprintln!(
                "{} impostors, {} of {} layers written, {} atlases, {} texels, {:.3} MB baked \
                 (placement estimate {:.3} MB), {:.1} s",
                rep.impostors,
                rep.layers_written,
                rep.layers,
                rep.atlases,
                rep.texels,
                rep.memory_bytes as f64 / 1e6,
                rep.placement_memory_bytes as f64 / 1e6,
                start.elapsed().as_secs_f64()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Report {
            scene,
            job,
            methods,
            sweep,
            stability,
            views,
            pvs,
            threads,
            out,
        } => {
            set_threads(threads)?;
            let job_path = job.display().to_string();
            let text = std::fs::read(&job).map_err(|e| Error::io(&job, e))?;
            let parsed = Job::from_json(&text, &job_path)?;
            let job_value: serde_json::Value = serde_json::from_slice(&text)
                .map_err(|e| Error::bad(&job_path, format!("invalid job JSON: {e}")))?;
            let methods = if methods.is_empty() {
                Method::ALL.to_vec()
            } else {
                methods
                    .iter()
                    .map(|m| parse_method(m.trim()))
                    .collect::<Result<Vec<_>>>()?
            };
            let sweeps = sweep
                .iter()
                .map(|s| report::run::parse_sweep(s))
                .collect::<Result<Vec<_>>>()?;
            let input = load_input(&scene, pvs.as_deref(), &parsed, &job_path, false)?;
            std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;
            let name = scene
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let r = report::run::run(
                &name,
                &input,
                &job_value,
                &report::run::ReportOptions {
                    methods,
                    sweeps,
                    stability,
                    views,
                    progress: true,
                },
            )?;
            write_output(Some(&out.join("report.json")), &json(&r)?)?;
            write_output(
                Some(&out.join("report.html")),
                report::render::render_html(&r).as_bytes(),
            )?;
            for (file, text) in report::render::csv_files(&r) {
                write_output(Some(&out.join(file)), text.as_bytes())?;
            }
            let failed = r.runs.iter().filter(|x| x.status != "ok").count();
            let broken = r
                .runs
                .iter()
                .filter(|x| x.eval.as_ref().is_some_and(|e| e.violations_in_solved > 0))
                .count();
            eprintln!(
                "{} runs ({failed} failed, {broken} with a broken guarantee), {} walkthroughs: {}",
                r.runs.len(),
                r.walkthroughs.len(),
                out.join("report.html").display()
            );
            Ok(if broken > 0 {
                ExitCode::from(4)
            } else {
                ExitCode::SUCCESS
            })
        }
        Command::Pvs {
            scene,
            job,
            out,
            threads,
        } => {
            set_threads(threads)?;
            let job_path = job.display().to_string();
            let job = read_job(&job)?;
            if !matches!(
                job.visibility.mode,
                VisibilityMode::Conservative | VisibilityMode::Sampled
            ) {
                return Err(Error::bad(
                    format!("{job_path}: visibility"),
                    "must be \"conservative\" or \"sampled\" to compute a PVS",
                ));
            }
            let input = load_input(&scene, None, &job, &job_path, false)?;
            let start = std::time::Instant::now();
            let h = optimizer::scene::hierarchy::Hierarchy::build(&input.scene);
            let vis = optimizer::visibility::Visibility::new(
                &job,
                &input.scene,
                &h,
                input.visibility_inputs(&job),
            )?
            .expect("a visibility mode");
            let grid = vis.grid().clone();
            let cells: Vec<[u32; 3]> = (0..grid.counts[2])
                .flat_map(|z| {
                    (0..grid.counts[1])
                        .flat_map(move |y| (0..grid.counts[0]).map(move |x| [x, y, z]))
                })
                .collect();
            vis.prefetch(&cells);
            let file = PvsFile {
                objects: input.scene.objects.len() as u64,
                cells: cells
                    .iter()
                    .map(|&c| {
                        let b = grid.cell_box(c, c.map(|x| x + 1));
                        PvsCell {
                            min: b.min.to_array(),
                            max: b.max.to_array(),
                            visible: vis.cell(c).set.iter().collect(),
                        }
                    })
                    .collect(),
            };
            write_output(out.as_deref(), &json(&file)?)?;
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
        Command::GenCity {
            seed,
            scale,
            summary,
            lod,
            failure,
            out,
        } => {
            let glb = if failure {
                citygen::generate_failure(seed)?
            } else {
                citygen::generate(&citygen::CityParams { seed, scale, lod })?
            };
            if summary {
                let scene = gltf_load::load_scene_bytes(&glb, "generated city")?;
                write_output(out.as_deref(), &json(&scene.summary())?)?;
            } else {
                let out = out.ok_or_else(|| {
                    Error::bad(
                        "gen-city",
                        "-o FILE is required for the GLB (or use --summary)",
                    )
                })?;
                write_output(Some(&out), &glb)?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Info { scene } => {
            let scene = gltf_load::load_scene_file(&scene)?;
            let (lo, hi) = scene.bounds();
            let calls: u64 = scene.objects.iter().map(|o| u64::from(o.draw_calls)).sum();
            let info = serde_json::json!({
                "objects": scene.objects.len(),
                "triangles": scene.total_triangles(),
                "draw_calls": calls,
                "bounds": { "min": lo.to_array(), "max": hi.to_array() },
            });
            write_output(None, &json(&info)?)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Schema { out_dir } => {
            std::fs::create_dir_all(&out_dir).map_err(|e| Error::io(&out_dir, e))?;
            for (name, text) in schema::all() {
                write_output(Some(&out_dir.join(name)), text.as_bytes())?;
            }
            Ok(ExitCode::SUCCESS)
        }
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
