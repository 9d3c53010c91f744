//! The placement pipeline: scene → hierarchy → problem views → candidates →
//! greedy → placement. [`place`] reads as the paper's algorithm outline.

use std::sync::atomic::{AtomicBool, Ordering as AtomicOrdering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use crate::api::job::{Job, Method};
use crate::api::placement::{
    DirectionsJson, PlacedCpv, PlacedImpostor, Placement, RegionJson, SphereJson, Summary,
    ViewCellJson,
};
use crate::api::stats::{StageTime, Stats};
use crate::candidates::{self, Candidates};
pub use crate::evaluate::Shared;
use crate::greedy::{self, Selection};
use crate::input::SceneInput;
use crate::model::impostor::ViewCell;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;
use crate::views::{self, Context, ProblemViews};
use crate::visibility::Visibility;
use crate::{Error, Result};

/// Options of a placement run.
#[derive(Clone, Copy, Debug, Default)]
pub struct PlaceOptions {
    /// Run the pruning pass after the greedy selection.
    pub prune: bool,
    /// Show progress spinners on stderr (hidden when stderr is not a terminal).
    pub progress: bool,
    /// Print each stage's wall time to stderr as it finishes.
    pub verbose: bool,
    /// Budget of (CPV, cluster) pairs; `None` is
    /// [`views::MAX_PAIRS`].
    pub max_pairs: Option<u64>,
}

/// A progress observer: stage name and fraction of the whole run done.
pub type ProgressFn<'a> = &'a (dyn Fn(&str, f64) + Sync);

/// Observes a placement run and may stop it (used by the HTTP service).
#[derive(Clone, Copy, Default)]
pub struct Control<'a> {
    /// When set to true, the run stops at the next check (between stages and
    /// every few greedy choices) with [`Error::Cancelled`].
    pub cancel: Option<&'a AtomicBool>,
    /// Called with the stage name (as in the stats) and the fraction of the
    /// whole run done, in `[0, 1]`.
    pub on_progress: Option<ProgressFn<'a>>,
}

impl Control<'_> {
    fn cancelled(&self) -> bool {
        self.cancel.is_some_and(|c| c.load(AtomicOrdering::Relaxed))
    }

    fn check(&self) -> Result<()> {
        if self.cancelled() {
            Err(Error::Cancelled)
        } else {
            Ok(())
        }
    }

    fn progress(&self, stage: &str, fraction: f64) {
        if let Some(f) = self.on_progress {
            f(stage, fraction.clamp(0.0, 1.0));
        }
    }
}

/// The result of [`place`].
#[derive(Clone, Debug)]
pub struct PlaceOutput {
    /// The placement (deterministic).
    pub placement: Placement,
    /// Timings and counters.
    pub stats: Stats,
}

struct Stages {
    bar: Option<ProgressBar>,
    verbose: bool,
    start: Instant,
    times: Vec<StageTime>,
}

impl Stages {
    fn new(progress: bool, verbose: bool) -> Self {
        let bar = progress.then(|| {
            let b = ProgressBar::new_spinner();
            b.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}")
                    .expect("valid template"),
            );
            b.enable_steady_tick(std::time::Duration::from_millis(120));
            b
        });
        Stages {
            bar,
            verbose,
            start: Instant::now(),
            times: Vec::new(),
        }
    }

    fn begin(&mut self, msg: &str) {
        if let Some(b) = &self.bar {
            b.set_message(msg.to_string());
        }
        self.start = Instant::now();
    }

    fn message(&self, msg: &str) {
        if let Some(b) = &self.bar {
            b.set_message(msg.to_string());
        }
    }

    fn end(&mut self, stage: &str) {
        let seconds = self.start.elapsed().as_secs_f64();
        if self.verbose {
            let line = format!("{stage}: {seconds:.2} s");
            match &self.bar {
                Some(b) if !b.is_hidden() => b.println(line),
                _ => eprintln!("{line}"),
            }
        }
        self.times.push(StageTime {
            stage: stage.into(),
            seconds,
        });
    }
}

impl Drop for Stages {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// Places impostors for `job` over a validated `scene` without geometry (the
/// job must not need any, see [`crate::input::needs_geometry`]). Fails when
/// the job needs more memory than the pair budget allows
/// ([`Error::BadInput`]).
pub fn place(scene: &Scene, job: &Job, opts: &PlaceOptions) -> Result<PlaceOutput> {
    place_controlled(scene, job, opts, &Control::default())
}

/// [`place`] with progress reports and cancellation ([`Error::Cancelled`]).
pub fn place_controlled(
    scene: &Scene,
    job: &Job,
    opts: &PlaceOptions,
    ctl: &Control,
) -> Result<PlaceOutput> {
    let input = SceneInput::from_scene(scene, job)?;
    place_input(&input, job, opts, ctl)
}

/// Places impostors for `job` over a prepared scene (levels of detail,
/// visibility inputs), with progress reports and cancellation.
pub fn place_input(
    input: &SceneInput,
    job: &Job,
    opts: &PlaceOptions,
    ctl: &Control,
) -> Result<PlaceOutput> {
    let scene = &input.scene;
    let start = Instant::now();
    let hierarchy = Hierarchy::build(scene);
    let hierarchy_seconds = start.elapsed().as_secs_f64();
    let visibility = Visibility::new(job, scene, &hierarchy, input.visibility_inputs(job))?;
    let shared = Shared {
        hierarchy: &hierarchy,
        visibility: visibility.as_ref(),
    };
    let mut out = place_shared(input, job, opts, ctl, &shared)?;
    out.stats.seconds.insert(
        input.seconds.len(),
        StageTime {
            stage: "hierarchy".into(),
            seconds: hierarchy_seconds,
        },
    );
    Ok(out)
}

/// [`place_input`] with a shared hierarchy and visibility (built for the
/// same scene and for a job with the same view space, grid and
/// visibility): runs that differ only in their target, method or candidate
/// knobs compute visible sets once.
pub fn place_shared(
    input: &SceneInput,
    job: &Job,
    opts: &PlaceOptions,
    ctl: &Control,
    shared: &Shared,
) -> Result<PlaceOutput> {
    let scene = &input.scene;
    let hierarchy = shared.hierarchy;
    let visibility = shared.visibility;
    let mut st = Stages::new(opts.progress, opts.verbose);
    st.times.extend(input.seconds.iter().cloned());
    ctl.progress("problem_views", 0.01);
    st.begin("approximating the problem view space");
    let mut ctx = Context::new(scene, hierarchy, job);
    ctx.pair_budget = opts.max_pairs.unwrap_or(views::MAX_PAIRS);
    ctx.cancel = ctl.cancel;
    ctx.visibility = visibility;
    let pv = views::approximate(&ctx, job);
    st.end("problem_views");
    if ctx.over_budget() {
        return Err(Error::bad(
            "job",
            format!(
                "the problem view space needs more than {} (problem view, cluster) pairs (about {} GB); \
                 raise target_frame_time_ms, enlarge problem_views.cell_size or min_vdi_deg, or shrink \
                 the view space",
                ctx.pair_budget,
                ctx.pair_budget * views::BYTES_PER_PAIR / 1_000_000_000
            ),
        ));
    }
    ctl.check()?;
    let method = job.method();
    if method == Method::EnvMap {
        ctl.progress("env_map", 0.1);
        st.begin("placing environment maps");
        let em = crate::methods::env_map::place(&ctx, job, &pv);
        st.end("env_map");
        ctl.check()?;
        st.begin("writing the placement");
        let placement = assemble(
            &ctx,
            job,
            &pv,
            em.impostors,
            em.cpv_impostors,
            &em.cpv_cost,
            0,
        );
        st.end("placement");
        let stats = run_stats(&ctx, input, &pv, &placement, std::mem::take(&mut st.times));
        ctl.progress("placement", 1.0);
        return Ok(PlaceOutput { placement, stats });
    }
    ctl.progress("candidates", 0.1);

    st.begin(&format!("generating candidates for {} CPVs", pv.cpvs.len()));
    let cands = candidates::generate(&ctx, job, &pv);
    st.end("candidates");
    ctl.check()?;
    ctl.progress("greedy", 0.2);

    st.begin(&format!(
        "greedy selection over {} candidates",
        cands.list.len()
    ));
    let total = pv.cpvs.len();
    let mut first_unsolved = None;
    let mut sel = greedy::select_lazy(&ctx, &pv, &cands, &mut |unsolved| {
        st.message(&format!(
            "greedy selection over {} candidates: {} of {total} CPVs above the target",
            cands.list.len(),
            unsolved
        ));
        let start = *first_unsolved.get_or_insert(unsolved.max(1));
        ctl.progress(
            "greedy",
            0.2 + 0.75 * (1.0 - unsolved as f64 / start as f64),
        );
        !ctl.cancelled()
    });
    st.end("greedy");
    ctl.check()?;
    if opts.prune || method == Method::ShaftsPrune {
        st.begin("pruning");
        greedy::prune(&ctx, &pv, &cands, &mut sel);
        st.end("prune");
    }

    ctl.progress("placement", 0.97);
    st.begin("writing the placement");
    let placement = build_placement(&ctx, job, &pv, &cands, &sel);
    st.end("placement");

    let stats = Stats {
        candidate_pairs: cands.pairs.len() as u64,
        candidates: cands.list.len() as u64,
        greedy_choices: sel.accepted,
        score_evaluations: sel.evaluations,
        pruned: sel.pruned,
        ..run_stats(&ctx, input, &pv, &placement, std::mem::take(&mut st.times))
    };
    ctl.progress("placement", 1.0);
    Ok(PlaceOutput { placement, stats })
}

/// The counters every method reports (candidate and greedy counters zero).
fn run_stats(
    ctx: &Context,
    input: &SceneInput,
    pv: &ProblemViews,
    placement: &Placement,
    seconds: Vec<StageTime>,
) -> Stats {
    Stats {
        threads: rayon::current_num_threads(),
        objects: ctx.scene.objects.len() as u64,
        triangles: ctx.scene.total_triangles(),
        hierarchy_nodes: ctx.hierarchy.nodes.len() as u64,
        cells: pv.grid.len(),
        regions_visited: pv.regions_visited,
        enclosing_frusta: pv.cone_evaluations,
        cpvs: pv.cpvs.len() as u64,
        impostors: placement.summary.impostors,
        memory_bytes: placement.summary.memory_bytes,
        unsolved_cpvs: placement.summary.unsolved_cpvs,
        seconds,
        peak_rss_bytes: peak_rss_bytes(),
        visibility: ctx.visibility.map(Visibility::stats),
        lod: ctx.lod_stats(input.lod.clone()),
        ..Stats::default()
    }
}

/// Turns the selection into the placement JSON structure.
pub fn build_placement(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    sel: &Selection,
) -> Placement {
    let h = ctx.hierarchy;
    let chosen = sel.impostors();
    let mut new_id = vec![u32::MAX; cands.list.len()];
    let impostors: Vec<PlacedImpostor> = chosen
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            new_id[i as usize] = k as u32;
            let c = &cands.list[i as usize];
            let node = &h.nodes[c.node as usize];
            let mut objects = h.objects(c.node).to_vec();
            objects.sort_unstable();
            let view_cell = match c.cell {
                ViewCell::Shaft {
                    apex,
                    axis,
                    half_angle,
                    min_distance,
                } => ViewCellJson::Shaft {
                    apex: apex.to_array(),
                    axis: axis.to_array(),
                    half_angle_deg: half_angle.to_degrees(),
                    min_distance,
                },
                ViewCell::Box(b) => ViewCellJson::Box {
                    min: b.min.to_array(),
                    max: b.max.to_array(),
                },
            };
            let d = c.cell.closest_distance(node.sphere.center);
            let cost = ctx.model.impostor(c.spec.layers, node.sphere.radius, d);
            PlacedImpostor {
                id: k as u32,
                node: c.node,
                objects,
                sphere: SphereJson {
                    center: node.sphere.center.to_array(),
                    radius: node.sphere.radius,
                },
                view_cell,
                layers: c.spec.layers,
                resolution: c.spec.resolution,
                memory_bytes: c.spec.memory_bytes,
                time_ms: cost.cpu + cost.gpu,
            }
        })
        .collect();
    let cpv_impostors: Vec<Vec<u32>> = sel
        .cpv_impostors
        .iter()
        .map(|imps| imps.iter().map(|&i| new_id[i as usize]).collect())
        .collect();
    assemble(
        ctx,
        job,
        pv,
        impostors,
        cpv_impostors,
        &sel.cpv_cost,
        cands.list.len() as u64,
    )
}

/// The placement JSON of `impostors` (ids are indices) used by the CPVs as
/// `cpv_impostors` says, with the CPVs' final costs.
pub fn assemble(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    impostors: Vec<PlacedImpostor>,
    cpv_impostors: Vec<Vec<u32>>,
    cpv_cost: &[crate::model::cost::Cost],
    candidates: u64,
) -> Placement {
    let mut unsolved = 0u64;
    let cpvs: Vec<PlacedCpv> = pv
        .cpvs
        .iter()
        .zip(cpv_impostors)
        .enumerate()
        .map(|(ci, (c, mut imps))| {
            imps.sort_unstable();
            let final_ms = ctx.model.frame_time(cpv_cost[ci]);
            let solved = final_ms <= job.target_frame_time_ms;
            unsolved += u64::from(!solved);
            PlacedCpv {
                id: ci as u32,
                region: RegionJson {
                    min: c.region.min.to_array(),
                    max: c.region.max.to_array(),
                },
                directions: DirectionsJson {
                    face: c.vdi.face,
                    u: c.vdi.u_range(),
                    v: c.vdi.v_range(),
                },
                time_ms_original: c.time,
                time_ms_final: final_ms,
                solved,
                impostors: imps,
            }
        })
        .collect();
    Placement {
        summary: Summary {
            cpvs: cpvs.len() as u64,
            candidates,
            impostors: impostors.len() as u64,
            memory_bytes: impostors.iter().map(|i| i.memory_bytes).sum(),
            unsolved_cpvs: unsolved,
            target_frame_time_ms: job.target_frame_time_ms,
        },
        impostors,
        cpvs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::job::Method;
    use crate::evaluate::{EvalOptions, evaluate};
    use crate::testutil::{synthetic_city, synthetic_job};

    /// The impostors of CPV `c` represent no object twice.
    fn assert_no_object_twice(p: &Placement, c: &crate::api::placement::PlacedCpv, what: &str) {
        let mut objs: Vec<u32> = c
            .impostors
            .iter()
            .flat_map(|&i| p.impostors[i as usize].objects.clone())
            .collect();
        let n = objs.len();
        objs.sort_unstable();
        objs.dedup();
        assert_eq!(n, objs.len(), "{what}");
    }

    fn run(threads: usize, seed: u64) -> Placement {
        let scene = synthetic_city(seed, 5, 5);
        let job = synthetic_job(5, 5);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            place(&scene, &job, &PlaceOptions::default())
                .unwrap()
                .placement
        })
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let a = serde_json::to_string(&run(1, 3)).unwrap();
        let b = serde_json::to_string(&run(2, 3)).unwrap();
        let c = serde_json::to_string(&run(3, 3)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a, c);
    }

    #[test]
    fn placement_solves_and_evaluation_finds_no_violation() {
        for seed in [1, 2] {
            let scene = synthetic_city(seed, 5, 5);
            let job = synthetic_job(5, 5);
            let out = place(&scene, &job, &PlaceOptions::default()).unwrap();
            let p = &out.placement;
            assert!(p.summary.cpvs > 0);
            assert!(p.summary.impostors > 0, "{:?}", p.summary);
            let eval = evaluate(
                &scene,
                &job,
                p,
                &EvalOptions {
                    views: 3000,
                    seed: 9,
                    ..EvalOptions::default()
                },
                "p.json",
            )
            .unwrap();
            assert_eq!(eval.violations_in_solved, 0, "{eval:?}");
            assert_eq!(eval.impostors_outside_view_cell, 0);
            if p.summary.unsolved_cpvs == 0 {
                assert_eq!(eval.violations, 0);
            }
            // Every CPV's impostors are an antichain: no object twice.
            for c in &p.cpvs {
                assert_no_object_twice(p, c, "");
                assert_eq!(c.solved, c.time_ms_final <= job.target_frame_time_ms);
                assert!(c.time_ms_final <= c.time_ms_original);
            }
        }
    }

    /// The oracle is not blind: with every impostor taken out of a solved
    /// placement, the views that needed them exceed `t_max` again and
    /// `evaluate` must report them as violations among solved CPVs.
    #[test]
    fn evaluation_catches_a_stripped_placement() {
        let scene = synthetic_city(1, 5, 5);
        let job = synthetic_job(5, 5);
        let mut p = place(&scene, &job, &PlaceOptions::default())
            .unwrap()
            .placement;
        let over = p
            .cpvs
            .iter()
            .filter(|c| c.time_ms_original > job.target_frame_time_ms)
            .count();
        assert!(over > 0, "the job must need impostors");
        let opts = EvalOptions {
            views: 3000,
            seed: 5,
            ..EvalOptions::default()
        };
        let honest = evaluate(&scene, &job, &p, &opts, "p.json").unwrap();
        assert_eq!(honest.violations_in_solved, 0);
        for c in &mut p.cpvs {
            c.impostors.clear();
        }
        let stripped = evaluate(&scene, &job, &p, &opts, "p.json").unwrap();
        assert!(
            stripped.violations_in_solved > 0,
            "{over} CPVs exceed t_max without impostors, yet: {stripped:?}"
        );
        assert!(stripped.max_ms > job.target_frame_time_ms);
    }

    #[test]
    fn control_reports_progress_and_cancels() {
        let scene = synthetic_city(1, 5, 5);
        let job = synthetic_job(5, 5);
        let seen = std::sync::Mutex::new(Vec::<(String, f64)>::new());
        let report = |stage: &str, f: f64| seen.lock().unwrap().push((stage.into(), f));
        let ctl = Control {
            cancel: None,
            on_progress: Some(&report),
        };
        let out = place_controlled(&scene, &job, &PlaceOptions::default(), &ctl).unwrap();
        let plain = place(&scene, &job, &PlaceOptions::default()).unwrap();
        assert_eq!(
            serde_json::to_string(&out.placement).unwrap(),
            serde_json::to_string(&plain.placement).unwrap()
        );
        let seen = seen.into_inner().unwrap();
        assert!(seen.windows(2).all(|w| w[0].1 <= w[1].1), "{seen:?}");
        assert_eq!(seen.last().unwrap(), &("placement".to_string(), 1.0));

        let flag = AtomicBool::new(true);
        let ctl = Control {
            cancel: Some(&flag),
            on_progress: None,
        };
        let r = place_controlled(&scene, &job, &PlaceOptions::default(), &ctl);
        assert!(matches!(r, Err(Error::Cancelled)));
    }

    #[test]
    fn jobs_beyond_the_pair_budget_are_refused() {
        let scene = synthetic_city(1, 5, 5);
        let job = synthetic_job(5, 5);
        let opts = PlaceOptions {
            max_pairs: Some(50),
            ..PlaceOptions::default()
        };
        let e = place(&scene, &job, &opts).unwrap_err();
        assert!(e.is_bad_input(), "{e}");
        assert!(e.to_string().contains("target_frame_time_ms"), "{e}");
        // Within the budget the same job places.
        let pairs = place(&scene, &job, &PlaceOptions::default())
            .unwrap()
            .stats
            .candidate_pairs;
        let opts = PlaceOptions {
            max_pairs: Some(pairs),
            ..PlaceOptions::default()
        };
        assert!(place(&scene, &job, &opts).is_ok());
    }

    #[test]
    fn cancelled_stages_stop_early() {
        let scene = synthetic_city(1, 5, 5);
        let job = synthetic_job(5, 5);
        let h = Hierarchy::build(&scene);
        let mut ctx = Context::new(&scene, &h, &job);
        let pv = views::approximate(&ctx, &job);
        assert!(!pv.cpvs.is_empty());
        let flag = AtomicBool::new(true);
        ctx.cancel = Some(&flag);
        assert!(candidates::generate(&ctx, &job, &pv).list.is_empty());
        assert!(views::approximate(&ctx, &job).cpvs.is_empty());
    }

    #[test]
    fn every_method_gives_a_placement_that_passes_the_check() {
        let scene = synthetic_city(3, 5, 5);
        let base = synthetic_job(5, 5);
        let mut memory = Vec::new();
        for m in Method::ALL {
            let mut job = base.clone();
            job.method = Some(m);
            job.env_map.far_m = 60.0;
            job.env_map.cell_m = 40.0;
            let p = place(&scene, &job, &PlaceOptions::default())
                .unwrap()
                .placement;
            assert!(p.summary.cpvs > 0, "{m:?}");
            assert!(p.summary.impostors > 0, "{m:?}: {:?}", p.summary);
            let eval = evaluate(
                &scene,
                &job,
                &p,
                &EvalOptions {
                    views: 2000,
                    seed: 4,
                    ..EvalOptions::default()
                },
                "p.json",
            )
            .unwrap();
            assert_eq!(eval.violations_in_solved, 0, "{m:?}: {eval:?}");
            assert_eq!(eval.impostors_outside_view_cell, 0, "{m:?}");
            // No object twice in one CPV.
            for c in &p.cpvs {
                assert_no_object_twice(&p, c, &format!("{m:?}"));
            }
            memory.push((m, p.summary.memory_bytes));
        }
        let mem = |m: Method| memory.iter().find(|x| x.0 == m).unwrap().1;
        // Pruning never adds memory; per-cell never shares across cells, so
        // it cannot beat boxes, which may use the same cells and more.
        assert!(mem(Method::ShaftsPrune) <= mem(Method::Shafts));
        assert!(mem(Method::Both) <= mem(Method::Shafts).max(mem(Method::Boxes)));
    }

    #[test]
    fn every_candidate_contains_the_regions_it_serves() {
        let scene = synthetic_city(5, 5, 5);
        let mut job = synthetic_job(5, 5);
        job.candidates.view_cells = crate::api::job::ViewCellKind::Both;
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, &job);
        let pv = views::approximate(&ctx, &job);
        let cands = candidates::generate(&ctx, &job, &pv);
        let mut checked = 0;
        for (i, c) in cands.list.iter().enumerate() {
            cands.for_each_served(i as u32, |cpv, idx| {
                let cpv = &pv.cpvs[cpv as usize];
                assert_eq!(cpv.node_ids[idx as usize], c.node);
                assert!(c.cell.contains_box(&cpv.region), "{c:?} {:?}", cpv.region);
                checked += 1;
            });
        }
        assert!(checked > 1000, "{checked}");
    }

    #[test]
    fn per_cell_impostors_serve_one_cell_each() {
        let scene = synthetic_city(2, 5, 5);
        let mut job = synthetic_job(5, 5);
        job.method = Some(Method::PerCell);
        let p = place(&scene, &job, &PlaceOptions::default())
            .unwrap()
            .placement;
        assert!(p.summary.impostors > 0);
        for imp in &p.impostors {
            let cells: std::collections::BTreeSet<String> = p
                .cpvs
                .iter()
                .filter(|c| c.impostors.contains(&imp.id))
                .map(|c| format!("{:?}", c.region.min))
                .collect();
            assert_eq!(cells.len(), 1, "impostor {} serves {cells:?}", imp.id);
        }
    }

    #[test]
    fn lazy_equals_naive_greedy() {
        for seed in [1, 4, 7] {
            let scene = synthetic_city(seed, 4, 3);
            let mut job = synthetic_job(4, 3);
            job.candidates.view_cells = crate::api::job::ViewCellKind::Both;
            let h = Hierarchy::build(&scene);
            let ctx = Context::new(&scene, &h, &job);
            let pv = views::approximate(&ctx, &job);
            let cands = candidates::generate(&ctx, &job, &pv);
            assert!(!cands.list.is_empty());
            let lazy = greedy::select_lazy(&ctx, &pv, &cands, &mut |_| true);
            let naive = greedy::select_naive(&ctx, &pv, &cands);
            assert_eq!(lazy.uses, naive.uses, "seed {seed}");
            assert_eq!(lazy.cpv_impostors, naive.cpv_impostors);
            assert_eq!(lazy.accepted, naive.accepted);
            assert!(lazy.evaluations < naive.evaluations);
        }
    }

    #[test]
    fn pruning_keeps_the_guarantee_and_never_adds_memory() {
        let scene = synthetic_city(2, 5, 5);
        let job = synthetic_job(5, 5);
        let plain = place(&scene, &job, &PlaceOptions::default())
            .unwrap()
            .placement;
        let pruned = place(
            &scene,
            &job,
            &PlaceOptions {
                prune: true,
                ..PlaceOptions::default()
            },
        )
        .unwrap()
        .placement;
        assert!(pruned.summary.memory_bytes <= plain.summary.memory_bytes);
        assert_eq!(pruned.summary.unsolved_cpvs, plain.summary.unsolved_cpvs);
        let eval = evaluate(
            &scene,
            &job,
            &pruned,
            &EvalOptions {
                views: 2000,
                seed: 1,
                ..EvalOptions::default()
            },
            "p.json",
        )
        .unwrap();
        assert_eq!(eval.violations_in_solved, 0);
    }
}

/// Peak resident set size of this process (VmHWM), bytes; 0 when unknown.
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<u64>().ok())
            })
        })
        .map_or(0, |kb| kb * 1024)
}
