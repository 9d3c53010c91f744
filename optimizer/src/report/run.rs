//! Running a report: every (method × knob value) placement with its
//! evaluation, walkthrough frame times, and the stability runs.

use std::collections::HashMap;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use serde_json::Value;

use super::{
    EvalSummary, Machine, MethodStability, Perturbed, Report, Run, SceneInfo, Spread, Stability,
    Sweep, Walkthrough,
};
use crate::api::job::{Job, Method};
use crate::evaluate::{EvalOptions, Shared, evaluate_shared, frame_times, walkthrough_views};
use crate::input::SceneInput;
use crate::place::{Control, PlaceOptions, place_shared};
use crate::scene::hierarchy::Hierarchy;
use crate::visibility::Visibility;
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
    /// Views per evaluation.
    pub views: u64,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// The knob that sweeps the target frame time.
pub const TARGET: &str = "target_frame_time_ms";

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
            let old = obj.get(*p).ok_or_else(|| {
                Error::bad("--sweep", format!("{knob}: the job has no field `{p}`"))
            })?;
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

/// Everything one report run needs to share: the hierarchy and one
/// visibility per (view space, grid, visibility parameters).
struct Context<'a> {
    input: &'a SceneInput,
    hierarchy: &'a Hierarchy,
    visibility: HashMap<String, Option<Visibility<'a>>>,
}

impl<'a> Context<'a> {
    fn key(job: &Job) -> String {
        serde_json::json!([job.view_space, job.problem_views.cell_size, job.visibility]).to_string()
    }

    fn shared(&mut self, job: &Job) -> Result<Shared<'_>> {
        let key = Context::key(job);
        if !self.visibility.contains_key(&key) {
            let v = Visibility::new(
                job,
                &self.input.scene,
                self.hierarchy,
                self.input.visibility_inputs(job),
            )?;
            self.visibility.insert(key.clone(), v);
        }
        Ok(Shared {
            hierarchy: self.hierarchy,
            visibility: self.visibility[&key].as_ref(),
        })
    }
}

/// One placement and its evaluation; `walk` also returns the frame times
/// along the walkthrough.
fn one_run(cx: &mut Context, job: &Job, views: u64, walk: bool) -> Result<(Run, Option<Vec<f64>>)> {
    let input = cx.input;
    let shared = cx.shared(job)?;
    let start = Instant::now();
    let out = place_shared(
        input,
        job,
        &PlaceOptions::default(),
        &Control::default(),
        &shared,
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let p = &out.placement;
    let eval = evaluate_shared(
        input,
        job,
        p,
        &EvalOptions {
            views,
            seed: 1,
            check_rays: 0,
            check_objects: 0,
        },
        "placement",
        &shared,
    )?;
    let walk = if walk {
        Some(frame_times(
            input,
            job,
            p,
            &walkthrough_views(job),
            "placement",
            &shared,
        )?)
    } else {
        None
    };
    Ok((
        Run {
            method: job.method().name().into(),
            knob: None,
            value: None,
            target_frame_time_ms: job.target_frame_time_ms,
            status: "ok".into(),
            error: None,
            cpvs: p.summary.cpvs,
            candidates: p.summary.candidates,
            impostors: p.summary.impostors,
            memory_bytes: p.summary.memory_bytes,
            unsolved_cpvs: p.summary.unsolved_cpvs,
            seconds,
            stage_seconds: out.stats.seconds,
            eval: Some(EvalSummary::from(&eval)),
        },
        walk,
    ))
}

fn failed(job: &Job, e: &Error) -> Run {
    Run {
        method: job.method().name().into(),
        target_frame_time_ms: job.target_frame_time_ms,
        status: "failed".into(),
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
    let perturbations = if opts.stability { 7 } else { 0 };
    let total = plan.len() + opts.methods.len() * perturbations;
    let bar = opts.progress.then(|| {
        let b = ProgressBar::new(total as u64);
        b.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} runs [{elapsed_precise}] {msg}")
                .expect("valid template"),
        );
        b
    });
    let hierarchy = Hierarchy::build(&input.scene);
    let mut cx = Context {
        input,
        hierarchy: &hierarchy,
        visibility: HashMap::new(),
    };
    let mut runs = Vec::new();
    let mut walkthroughs = Vec::new();
    for (setting, job) in &plan {
        if let Some(b) = &bar {
            b.set_message(match setting {
                Some((k, v)) => format!("{} {k}={v}", job.method().name()),
                None => job.method().name().to_string(),
            });
        }
        let is_target = setting.as_ref().is_some_and(|(k, _)| k == TARGET);
        let walk = is_target || (!has_target_sweep && setting.is_none());
        let mut run = match one_run(&mut cx, job, opts.views, walk) {
            Ok((run, frames)) => {
                if let Some(frame_ms) = frames {
                    walkthroughs.push(Walkthrough {
                        method: job.method().name().into(),
                        target_frame_time_ms: job.target_frame_time_ms,
                        frame_ms,
                    });
                }
                run
            }
            Err(e @ (Error::BadInput { .. } | Error::Cancelled)) => failed(job, &e),
            Err(e) => return Err(e),
        };
        if let Some((k, v)) = setting {
            run.knob = Some(k.clone());
            run.value = Some(*v);
        }
        runs.push(run);
        if let Some(b) = &bar {
            b.inc(1);
        }
    }
    let stability = if opts.stability {
        let mut methods = Vec::new();
        for &m in &opts.methods {
            let mut j = base.clone();
            j.method = Some(m);
            let mut settings = Vec::new();
            let mut record = |label: String, r: Result<(Run, Option<Vec<f64>>)>| {
                settings.push(match r {
                    Ok((run, _)) => Perturbed {
                        label,
                        status: "ok".into(),
                        memory_bytes: run.memory_bytes,
                        impostors: run.impostors,
                        unsolved_cpvs: run.unsolved_cpvs,
                        max_ms: run.eval.map_or(0.0, |e| e.max_ms),
                    },
                    Err(e) => Perturbed {
                        label: format!("{label}: {e}"),
                        status: "failed".into(),
                        ..Perturbed::default()
                    },
                });
            };
            let views = (opts.views / 4).max(100);
            record("base".into(), one_run(&mut cx, &j, views, false));
            for f in [0.95, 0.99, 1.01, 1.05] {
                let mut p = j.clone();
                p.target_frame_time_ms *= f;
                let label = format!("target {:+.0}%", (f - 1.0) * 100.0);
                record(label, one_run(&mut cx, &p, views, false));
                if let Some(b) = &bar {
                    b.inc(1);
                }
            }
            // The grid shifted by half a cell (the view space grows by half
            // a cell at its low side along x and z).
            let mut p = j.clone();
            let half = 0.5 * p.problem_views.cell_size;
            p.view_space.min[0] -= half;
            p.view_space.min[2] -= half;
            record(
                "grid shifted by half a cell".into(),
                one_run(&mut cx, &p, views, false),
            );
            if let Some(b) = &bar {
                b.inc(1);
            }
            for seed in [1u64, 2] {
                let shuffled = input.shuffled(seed);
                let h2 = Hierarchy::build(&shuffled.scene);
                let mut cx2 = Context {
                    input: &shuffled,
                    hierarchy: &h2,
                    visibility: HashMap::new(),
                };
                record(
                    format!("objects shuffled (seed {seed})"),
                    one_run(&mut cx2, &j, views, false),
                );
                if let Some(b) = &bar {
                    b.inc(1);
                }
            }
            let ok: Vec<&Perturbed> = settings.iter().filter(|s| s.status == "ok").collect();
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
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let (lo, hi) = input.scene.bounds();
    Ok(Report {
        version: crate::VERSION.into(),
        created: now_rfc3339(),
        machine: machine(),
        scene: SceneInfo {
            name: name.into(),
            objects: input.scene.objects.len() as u64,
            triangles: input.scene.total_triangles(),
            min: lo.to_array(),
            max: hi.to_array(),
        },
        job: job_text.clone(),
        methods: opts.methods.iter().map(|m| m.name().into()).collect(),
        sweeps: opts.sweeps.clone(),
        runs,
        walkthroughs,
        stability,
    })
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
