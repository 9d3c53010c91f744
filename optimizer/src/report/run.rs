//! Running a report: every (method × knob value) placement with its
//! evaluation, walkthrough frame times, and the stability runs.

use std::time::Instant;

use serde_json::Value;

use super::{
    BakeSummary, EvalSummary, ImageSummary, Machine, MethodStability, Perturbed, Report, Run,
    RunStatus, SceneInfo, Spread, Stability, Sweep, Walkthrough,
};
use crate::api::evaluation::Evaluation;
use crate::api::job::{Job, Method};
use crate::control::Control;
use crate::evaluate::{EvalOptions, PathTimes};
use crate::input::{Prepared, SceneInput};
use crate::place::{PlaceOptions, PlaceOutput};
use crate::{Error, Result};

/// What a report runs.
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// Methods to compare.
    pub methods: Vec<Method>,
    /// Knob sweeps.
    pub sweeps: Vec<Sweep>,
    /// Also run the stability perturbations.
    pub stability: bool,
    /// Memory budgets, as fractions of each method's unbudgeted memory
    /// (its base run's), each run and evaluated after the base runs.
    pub budgets: Vec<f64>,
    /// Views per evaluation.
    pub views: u64,
    /// Also bake each run of the base job, its sweeps and its budgets
    /// (not the stability runs), and report its baked memory against the
    /// placement's estimate (needs geometry).
    pub bake: bool,
    /// Image views per run of the base job, its sweeps and its budgets
    /// (0: none): the footprint mismatch of its impostors (needs geometry).
    pub images: u32,
}

/// The knob that sweeps the target frame time.
pub const TARGET: &str = "target_frame_time_ms";

/// The knob of the budget runs (`--budgets`).
pub const BUDGET: &str = "memory.budget_bytes";

/// Parses `--budgets`: fractions in (0, 1] of the unbudgeted memory.
pub fn parse_budgets(values: &[f64]) -> Result<Vec<f64>> {
    if values.len() > 64 {
        return Err(Error::bad("--budgets", "give at most 64 fractions"));
    }
    for &f in values {
        if !(f.is_finite() && f > 0.0 && f <= 1.0) {
            return Err(Error::bad(
                "--budgets",
                format!("{f} must be a fraction of the unbudgeted memory in (0, 1]"),
            ));
        }
    }
    Ok(values.to_vec())
}

/// Knobs that change the prepared scene (levels of detail, the visibility
/// mode) cannot be swept: each value would need its own preparation.
fn sweepable(knob: &str) -> bool {
    !(knob.starts_with("lod.")
        || knob == "lod"
        || knob == "visibility.mode"
        || knob == "visibility")
}

/// `job` (a full job as JSON) with the dotted field `knob` set to `value`.
fn with_knob(job: &Value, knob: &str, value: f64) -> Result<Value> {
    let mut v = job.clone();
    let mut cur = &mut v;
    let parts: Vec<&str> = knob.split('.').collect();
    for (i, p) in parts.iter().enumerate() {
        let obj = cur.as_object_mut().ok_or_else(|| {
            Error::bad(
                "--sweep",
                format!("{knob}: {} is not an object", parts[..i].join(".")),
            )
        })?;
        if i + 1 == parts.len() {
            // A field the job leaves out (an optional one, such as
            // `memory.budget_bytes`) is added: the job's parser rejects
            // names it does not know.
            let absent = !obj.contains_key(*p);
            let old = obj.get(*p).cloned().unwrap_or(Value::from(0u64));
            if !old.is_number() {
                return Err(Error::bad(
                    "--sweep",
                    format!("{knob} is not a number in the job (it is {old})"),
                ));
            }
            let num = if old.is_u64() && value >= 0.0 && value.fract() == 0.0 {
                Value::from(value as u64)
            } else {
                serde_json::Number::from_f64(value)
                    .map(Value::Number)
                    .ok_or_else(|| Error::bad("--sweep", format!("{knob}={value} is not finite")))?
            };
            obj.insert((*p).to_string(), num);
            if absent && serde_json::from_value::<Job>(v.clone()).is_err() {
                return Err(Error::bad(
                    "--sweep",
                    format!("{knob}: the job has no field `{p}`"),
                ));
            }
            return Ok(v);
        }
        cur = obj
            .get_mut(*p)
            .ok_or_else(|| Error::bad("--sweep", format!("{knob}: the job has no field `{p}`")))?;
    }
    Err(Error::bad("--sweep", "empty knob name"))
}

/// Parses `knob=v1,v2,...`.
pub fn parse_sweep(text: &str) -> Result<Sweep> {
    let (knob, values) = text
        .split_once('=')
        .ok_or_else(|| Error::bad("--sweep", format!("{text:?} must look like knob=v1,v2,...")))?;
    let knob = knob.trim().to_string();
    if knob.is_empty() {
        return Err(Error::bad("--sweep", format!("{text:?} names no knob")));
    }
    if !sweepable(&knob) {
        return Err(Error::bad(
            "--sweep",
            format!(
                "{knob} changes the scene's preparation and cannot be swept; make one report per value"
            ),
        ));
    }
    let values = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| Error::bad("--sweep", format!("{knob}: {v:?} is not a number")))
        })
        .collect::<Result<Vec<f64>>>()?;
    if values.is_empty() || values.len() > 64 {
        return Err(Error::bad(
            "--sweep",
            format!("{knob}: give 1 to 64 values"),
        ));
    }
    Ok(Sweep { knob, values })
}

/// The machine this runs on.
pub fn machine() -> Machine {
    let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
    let cpu = read("/proc/cpuinfo")
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map(|s| s.trim().to_string())
        .unwrap_or_default();
    let memory_bytes = read("/proc/meminfo")
        .lines()
        .find(|l| l.starts_with("MemTotal:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024);
    Machine {
        os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
        threads: rayon::current_num_threads(),
        cpu,
        memory_bytes,
    }
}

/// The current time, UTC, RFC 3339 (seconds).
pub fn now_rfc3339() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// One placement, its evaluation and, when asked, its walkthrough: the
/// unit of work of a report and of a job of the HTTP service.
pub struct RunOutput {
    /// The placement and its stats.
    pub place: PlaceOutput,
    /// Its evaluation.
    pub eval: Evaluation,
    /// The run as the report lists it.
    pub run: Run,
    /// Frame times along the walkthrough (the job's path, or a tour
    /// through the problem).
    pub frames: Option<PathTimes>,
}

impl RunOutput {
    /// Bakes the placement (the scene's geometry is needed), records the
    /// baked memory against the estimate in the run, and returns the GLB.
    pub fn bake(
        &mut self,
        prepared: &Prepared,
        opts: &crate::bake::BakeOptions,
    ) -> Result<Vec<u8>> {
        let (glb, report) = prepared.bake(&self.place.placement, opts, "placement")?;
        self.run.bake = Some(BakeSummary::new(&self.place.placement, &report));
        Ok(glb)
    }
}

/// Places `prepared`'s job with `opts`, evaluates the placement with `eval` and, with
/// `walk`, follows the walkthrough (the job's path, or a tour through the
/// problem).
pub fn place_and_evaluate(
    prepared: &Prepared,
    opts: &PlaceOptions,
    eval: &EvalOptions,
    walk: bool,
    ctl: &Control,
) -> Result<RunOutput> {
    let start = Instant::now();
    let out = prepared.place(opts, ctl)?;
    let seconds = start.elapsed().as_secs_f64();
    evaluate_placed(prepared, out, seconds, eval, walk, ctl)
}

/// [`place_and_evaluate`] for a placement made already (`out`, in
/// `seconds`): e.g. the merge of a tiled job's tiles placed elsewhere.
pub fn evaluate_placed(
    prepared: &Prepared,
    out: PlaceOutput,
    seconds: f64,
    eval: &EvalOptions,
    walk: bool,
    ctl: &Control,
) -> Result<RunOutput> {
    let job = prepared.job();
    ctl.check()?;
    let p = &out.placement;
    ctl.progress("evaluate", 0.98, "evaluating the placement");
    let evaluation = prepared.evaluate(p, eval, "placement")?;
    let frames = if walk {
        Some(prepared.walkthrough_times(p, "placement")?)
    } else {
        None
    };
    let run = Run {
        method: job.method().name().into(),
        knob: None,
        value: None,
        target_frame_time_ms: job.target_frame_time_ms,
        status: RunStatus::Ok,
        error: None,
        cpvs: p.summary.cpvs,
        candidates: p.summary.candidates,
        impostors: p.summary.impostors,
        memory_bytes: p.summary.memory_bytes,
        unsolved_cpvs: p.summary.unsolved_cpvs,
        max_residual_ms: p.summary.max_residual_ms,
        budget_bytes: p.summary.budget_bytes,
        seconds,
        stage_seconds: out.stats.seconds.clone(),
        eval: Some(EvalSummary::from(&evaluation)),
        exact: out.stats.exact.clone(),
        cache: None,
        bake: None,
        image: None,
    };
    Ok(RunOutput {
        place: out,
        eval: evaluation,
        run,
        frames,
    })
}

/// The preparations of a report's jobs: one visibility per (view space,
/// grid, visibility parameters), shared by the runs that agree on them.
struct Preparations<'a> {
    list: Vec<Prepared<'a>>,
}

impl<'a> Preparations<'a> {
    fn for_job(&mut self, input: &'a SceneInput, job: &Job) -> Result<Prepared<'a>> {
        if let Some(p) = self.list.iter().find(|p| p.shares_visibility_with(job)) {
            return p.with_job(job);
        }
        let p = input.prepare(job, "job")?;
        let out = p.with_job(job)?;
        self.list.push(p);
        Ok(out)
    }
}

/// What a run does besides placing and evaluating.
#[derive(Clone, Copy, Debug)]
struct Extras {
    /// Bake its impostors.
    bake: bool,
    /// Image views of its impostors (0: none).
    images: u32,
}

impl Extras {
    const NONE: Extras = Extras {
        bake: false,
        images: 0,
    };
}

impl ReportOptions {
    /// The extras of the runs of the base job, its sweeps and its budgets.
    fn extras(&self) -> Extras {
        Extras {
            bake: self.bake,
            images: self.images,
        }
    }
}

/// One run of a report: its placement and evaluation (and walkthrough with
/// `walk`, bake and images as `extras` ask) without the visibility check's
/// rays, which the report does not show.
fn one_run<'a>(
    preps: &mut Preparations<'a>,
    input: &'a SceneInput,
    job: &Job,
    views: u64,
    walk: bool,
    extras: Extras,
) -> Result<(Run, Option<PathTimes>)> {
    let prepared = preps.for_job(input, job)?;
    if !job.method().places() {
        return Ok(cache_run(&prepared));
    }
    let eval = EvalOptions {
        views,
        cpv_views: views,
        seed: 1,
        check_rays: 0,
        check_objects: 0,
    };
    let mut out = place_and_evaluate(
        &prepared,
        &PlaceOptions::default(),
        &eval,
        walk,
        &Control::default(),
    )?;
    let glb = if extras.bake {
        Some(out.bake(
            &prepared,
            &crate::bake::BakeOptions::for_memory(&prepared.job().memory),
        )?)
    } else {
        None
    };
    if extras.images > 0 && out.place.placement.summary.impostors > 0 {
        use crate::evaluate::images::LayerSource;
        // The layers as baked when the run was baked (not rendered again).
        let layers = match &glb {
            Some(bytes) => LayerSource::Glb {
                bytes,
                name: "the baked impostors",
            },
            None => LayerSource::Bake,
        };
        let (rep, _) = prepared.image_error(
            &out.place.placement,
            layers,
            &crate::evaluate::images::ImageOptions {
                views: extras.images,
                ..Default::default()
            },
            "placement",
        )?;
        out.run.image = Some(ImageSummary {
            views: rep.views,
            footprint_mismatch: rep.footprint_mismatch_fraction,
            control_mismatch: rep.control_mismatch_fraction,
            impostor_pixel_fraction: rep.impostor_pixel_fraction,
        });
    }
    Ok((out.run, out.frames))
}

/// The run of a method that places nothing ahead of time (`hic96`): its
/// cache replayed along the job's walkthrough (or the tour through the
/// problem). Its memory is the largest resident texture memory along the
/// path, its impostors the images it created.
fn cache_run(prepared: &Prepared) -> (Run, Option<PathTimes>) {
    let job = prepared.job();
    let start = Instant::now();
    let views = prepared.walkthrough_path();
    prepared.prefetch_path(&views);
    let grid = job.grid();
    let visible = |eye| {
        let cell = grid.cell_of(eye)?;
        prepared.visibility().map(|v| &*v.cell(cell).set)
    };
    let frames = crate::methods::hic96::replay(
        prepared.scene(),
        prepared.hierarchy(),
        job,
        &views,
        &visible,
    );
    let cache = crate::methods::hic96::PathSummary::of(&frames, job.target_frame_time_ms);
    let run = Run {
        method: job.method().name().into(),
        target_frame_time_ms: job.target_frame_time_ms,
        status: RunStatus::Ok,
        impostors: cache.created,
        memory_bytes: cache.peak_bytes,
        seconds: start.elapsed().as_secs_f64(),
        cache: Some(cache),
        ..Run::default()
    };
    let times = PathTimes {
        frame_ms: frames.iter().map(|f| f.frame_ms).collect(),
        bare_ms: frames.iter().map(|f| f.bare_ms).collect(),
        estimate_ms: vec![None; frames.len()],
    };
    (run, Some(times))
}

/// A run's outcome, with a refused or cancelled run recorded as failed
/// (no frames); any other error stops the report.
fn or_failed(job: &Job, r: Result<(Run, Option<PathTimes>)>) -> Result<(Run, Option<PathTimes>)> {
    match r {
        Err(e @ (Error::BadInput { .. } | Error::Cancelled)) => Ok((failed(job, &e), None)),
        r => r,
    }
}

fn failed(job: &Job, e: &Error) -> Run {
    Run {
        method: job.method().name().into(),
        target_frame_time_ms: job.target_frame_time_ms,
        status: RunStatus::Failed,
        error: Some(e.to_string()),
        ..Run::default()
    }
}

fn spread(values: &[f64]) -> Spread {
    if values.is_empty() {
        return Spread::default();
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    Spread {
        min: values.iter().copied().fold(f64::INFINITY, f64::min),
        max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        mean,
        relative_std: if mean > 0.0 { var.sqrt() / mean } else { 0.0 },
    }
}

/// Runs a report of `opts.methods × (base + sweeps)` on a prepared scene.
/// `job_text` is the base job as given (for the report); `name` names the
/// scene. Individual runs that fail (e.g. a job beyond the memory budget)
/// are recorded as failed; only bad input stops the report.
pub fn run(
    name: &str,
    input: &SceneInput,
    job_text: &Value,
    opts: &ReportOptions,
    ctl: &Control,
) -> Result<Report> {
    let base: Job = serde_json::from_value(job_text.clone())
        .map_err(|e| Error::bad("job", format!("invalid job JSON: {e}")))?;
    base.validate("job")?;
    if opts.methods.is_empty() {
        return Err(Error::bad("--methods", "names no method"));
    }
    if opts.views == 0 || opts.views > 10_000_000 {
        return Err(Error::bad(
            "--views",
            format!("{} must be between 1 and 10000000", opts.views),
        ));
    }
    let full = serde_json::to_value(&base).map_err(|e| Error::Internal(e.to_string()))?;
    // Every job of the report, checked before anything runs.
    let mut plan: Vec<(Option<(String, f64)>, Job)> = Vec::new();
    for &m in &opts.methods {
        let mut j = base.clone();
        j.method = Some(m);
        plan.push((None, j));
        for sw in &opts.sweeps {
            for &v in &sw.values {
                let value = with_knob(&full, &sw.knob, v)?;
                let mut j: Job = serde_json::from_value(value)
                    .map_err(|e| Error::bad("--sweep", format!("{}={v}: {e}", sw.knob)))?;
                j.validate(&format!("--sweep {}={v}", sw.knob))?;
                j.method = Some(m);
                plan.push((Some((sw.knob.clone(), v)), j));
            }
        }
    }
    let has_target_sweep = opts.sweeps.iter().any(|s| s.knob == TARGET);
    // Per method: the base, four targets, the shifted grid, two shuffles.
    let perturbations = if opts.stability { 8 } else { 0 };
    let total = plan.len() + opts.methods.len() * (perturbations + opts.budgets.len());
    let mut done = 0usize;
    let mut step = |message: &str| -> Result<()> {
        ctl.progress("report", done as f64 / total as f64, message);
        done += 1;
        ctl.check()
    };
    let mut preps = Preparations { list: Vec::new() };
    let mut runs = Vec::new();
    let mut walkthroughs = Vec::new();
    for (setting, job) in &plan {
        step(&match setting {
            Some((k, v)) => format!("{} {k}={v}", job.method().name()),
            None => job.method().name().to_string(),
        })?;
        let is_target = setting.as_ref().is_some_and(|(k, _)| k == TARGET);
        let walk = is_target || (!has_target_sweep && setting.is_none());
        let (mut run, frames) = or_failed(
            job,
            one_run(&mut preps, input, job, opts.views, walk, opts.extras()),
        )?;
        // (A cache's run always follows the path, for its figures; its
        // frames are charted where the other methods' are.)
        if let Some(t) = frames.filter(|_| walk) {
            walkthroughs.push(Walkthrough {
                method: job.method().name().into(),
                target_frame_time_ms: job.target_frame_time_ms,
                frame_ms: t.frame_ms,
                bare_ms: t.bare_ms,
                estimate_ms: t.estimate_ms,
            });
        }
        if let Some((k, v)) = setting {
            run.knob = Some(k.clone());
            run.value = Some(*v);
        }
        runs.push(run);
    }
    // Budgets: fractions of each placing method's unbudgeted memory.
    for &m in opts.methods.iter().filter(|m| m.places()) {
        let Some(free) = runs
            .iter()
            .find(|x| x.knob.is_none() && x.method == m.name() && x.status == RunStatus::Ok)
            .map(|x| x.memory_bytes)
        else {
            continue;
        };
        for &f in &opts.budgets {
            let budget = (free as f64 * f).floor() as u64;
            let mut j = base.clone();
            j.method = Some(m);
            j.memory.budget_bytes = Some(budget);
            step(&format!("{} budget {:.0} %", m.name(), f * 100.0))?;
            let (mut run, _) = or_failed(
                &j,
                one_run(&mut preps, input, &j, opts.views, false, opts.extras()),
            )?;
            run.knob = Some(BUDGET.into());
            run.value = Some(budget as f64);
            runs.push(run);
        }
    }
    let stability = if opts.stability {
        let mut methods = Vec::new();
        for &m in opts.methods.iter().filter(|m| m.places()) {
            let mut j = base.clone();
            j.method = Some(m);
            let mut settings = Vec::new();
            let mut record = |label: String, r: Result<(Run, Option<PathTimes>)>| {
                settings.push(match r {
                    Ok((run, _)) => Perturbed {
                        label,
                        status: RunStatus::Ok,
                        memory_bytes: run.memory_bytes,
                        impostors: run.impostors,
                        unsolved_cpvs: run.unsolved_cpvs,
                        max_ms: run.eval.map_or(0.0, |e| e.max_ms),
                    },
                    Err(e) => Perturbed {
                        label: format!("{label}: {e}"),
                        status: RunStatus::Failed,
                        ..Perturbed::default()
                    },
                });
            };
            let views = (opts.views / 4).max(100);
            step(&format!("{} stability", m.name()))?;
            record(
                "base".into(),
                one_run(&mut preps, input, &j, views, false, Extras::NONE),
            );
            for f in [0.95, 0.99, 1.01, 1.05] {
                let mut p = j.clone();
                p.target_frame_time_ms *= f;
                let label = format!("target {:+.0}%", (f - 1.0) * 100.0);
                step(&format!("{} stability: {label}", m.name()))?;
                record(
                    label,
                    one_run(&mut preps, input, &p, views, false, Extras::NONE),
                );
            }
            // The grid's planes shifted by half a cell along x and z (its
            // phase against the scene; the view space stays as it is).
            let mut shifted = j.clone();
            let half = 0.5 * j.problem_views.cell_size;
            shifted.problem_views.grid_origin[0] += half;
            shifted.problem_views.grid_origin[2] += half;
            step(&format!("{} stability: grid shifted", m.name()))?;
            record(
                "grid shifted by half a cell".into(),
                one_run(&mut preps, input, &shifted, views, false, Extras::NONE),
            );
            for seed in [1u64, 2] {
                step(&format!("{} stability: objects shuffled", m.name()))?;
                let shuffled = input.shuffled(seed);
                let mut own = Preparations { list: Vec::new() };
                record(
                    format!("objects shuffled (seed {seed})"),
                    one_run(&mut own, &shuffled, &j, views, false, Extras::NONE),
                );
            }
            let ok: Vec<&Perturbed> = settings
                .iter()
                .filter(|s| s.status == RunStatus::Ok)
                .collect();
            let memory = spread(&ok.iter().map(|s| s.memory_bytes as f64).collect::<Vec<_>>());
            let impostors = spread(&ok.iter().map(|s| s.impostors as f64).collect::<Vec<_>>());
            methods.push(MethodStability {
                method: m.name().into(),
                settings,
                memory,
                impostors,
            });
        }
        Some(Stability { methods })
    } else {
        None
    };
    Ok(Report {
        version: crate::VERSION.into(),
        created: now_rfc3339(),
        machine: machine(),
        scene: scene_info(name, input),
        job: job_text.clone(),
        methods: opts.methods.iter().map(|m| m.name().into()).collect(),
        sweeps: opts.sweeps.clone(),
        budgets: opts.budgets.clone(),
        runs,
        walkthroughs,
        stability,
    })
}

fn scene_info(name: &str, input: &SceneInput) -> SceneInfo {
    let (lo, hi) = input.scene.bounds();
    SceneInfo {
        name: name.into(),
        objects: input.scene.objects.len() as u64,
        triangles: input.scene.total_triangles(),
        min: lo.to_array(),
        max: hi.to_array(),
    }
}

/// The report of a single run (one job of the HTTP service): its run, its
/// evaluation and its walkthrough when `out` has one.
pub fn single_run_report(
    name: &str,
    input: &SceneInput,
    job_text: &Value,
    out: &RunOutput,
) -> Report {
    Report {
        version: crate::VERSION.into(),
        created: now_rfc3339(),
        machine: machine(),
        scene: scene_info(name, input),
        job: job_text.clone(),
        methods: vec![out.run.method.clone()],
        sweeps: Vec::new(),
        budgets: Vec::new(),
        runs: vec![out.run.clone()],
        walkthroughs: out
            .frames
            .iter()
            .map(|t| Walkthrough {
                method: out.run.method.clone(),
                target_frame_time_ms: out.run.target_frame_time_ms,
                frame_ms: t.frame_ms.clone(),
                bare_ms: t.bare_ms.clone(),
                estimate_ms: t.estimate_ms.clone(),
            })
            .collect(),
        stability: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knobs_are_set_and_bad_ones_named() {
        let job = serde_json::to_value(Job::with_view_space([0.0; 3], [10.0; 3])).unwrap();
        let j = with_knob(&job, "problem_views.cell_size", 11.5).unwrap();
        assert_eq!(j["problem_views"]["cell_size"], 11.5);
        let j = with_knob(&job, "candidates.min_distance_doublings", 8.0).unwrap();
        assert_eq!(j["candidates"]["min_distance_doublings"], 8);
        assert!(with_knob(&job, "problem_views.nope", 1.0).is_err());
        // An optional field the job leaves out is added.
        let j = with_knob(&job, "memory.budget_bytes", 1e6).unwrap();
        assert_eq!(j["memory"]["budget_bytes"], 1_000_000);
        assert_eq!(parse_budgets(&[0.5, 0.1]).unwrap(), vec![0.5, 0.1]);
        for bad in [0.0, 1.5, -0.2, f64::NAN] {
            assert!(parse_budgets(&[bad]).is_err(), "{bad}");
        }
        assert!(with_knob(&job, "camera.resolution", 1.0).is_err());
        let s = parse_sweep("target_frame_time_ms=10, 15,20").unwrap();
        assert_eq!(s.values, vec![10.0, 15.0, 20.0]);
        assert!(parse_sweep("target_frame_time_ms").is_err());
        assert!(parse_sweep("lod.ratio=0.5").is_err());
        assert!(parse_sweep("x=a").is_err());
    }

    #[test]
    fn dates_are_rfc3339() {
        let d = now_rfc3339();
        assert_eq!(d.len(), 20, "{d}");
        assert!(d.starts_with("20") && d.ends_with('Z'), "{d}");
    }

    #[test]
    fn spreads_are_hand_computed() {
        let s = spread(&[1.0, 3.0]);
        assert_eq!((s.min, s.max, s.mean), (1.0, 3.0, 2.0));
        assert!((s.relative_std - 0.5).abs() < 1e-12);
        assert_eq!(spread(&[0.0, 0.0]).relative_std, 0.0);
    }
}
