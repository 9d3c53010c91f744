//! Small deterministic scenes and jobs for tests and benchmarks (no files).

use glam::DVec3;

use crate::api::job::Job;
use crate::math::rng::Rng;
use crate::scene::{Object, Scene};

/// A block grid of `nx × nz` blocks, 40 m apart, each holding a few objects
/// of varied size, cost and height (buildings and street furniture), with
/// streets free at `x, z ≡ 0 (mod 40)`.
pub fn synthetic_city(seed: u64, nx: u32, nz: u32) -> Scene {
    let mut rng = Rng::new(seed);
    let mut objects = Vec::new();
    for bx in 0..nx {
        for bz in 0..nz {
            let base = DVec3::new(f64::from(bx) * 40.0 + 6.0, 0.0, f64::from(bz) * 40.0 + 6.0);
            let count = 2 + (rng.next_u64() % 5) as usize;
            for _ in 0..count {
                let size = DVec3::new(
                    rng.range(1.0, 12.0),
                    rng.range(1.0, 30.0),
                    rng.range(1.0, 12.0),
                );
                let p = base
                    + DVec3::new(
                        rng.range(0.0, 28.0 - size.x),
                        0.0,
                        rng.range(0.0, 28.0 - size.z),
                    );
                objects.push(Object {
                    name: format!("o{}", objects.len()),
                    min: p,
                    max: p + size,
                    triangles: 50 + rng.next_u64() % 5000,
                    draw_calls: 1 + (rng.next_u64() % 3) as u32,
                    lods: Vec::new(),
                });
            }
        }
    }
    Scene { objects }
}

/// A job over the streets of [`synthetic_city`] at eye height, with a cost
/// model that makes looking along the streets expensive.
pub fn synthetic_job(nx: u32, nz: u32) -> Job {
    let mut job = Job::with_view_space(
        [0.0, 1.5, 0.0],
        [f64::from(nx) * 40.0, 2.0, f64::from(nz) * 40.0],
    );
    job.problem_views.cell_size = 20.0;
    job.cost_model.frame_ms = 1.0;
    job.cost_model.draw_call_us = 40.0;
    job.target_frame_time_ms = 4.0;
    job
}

/// [`synthetic_job`] with costs combined by `combine`; counting primitives
/// alone, its target leaves problem views (40,000 triangles over the frame).
pub fn synthetic_job_combined(nx: u32, nz: u32, combine: crate::api::job::Combine) -> Job {
    let mut job = synthetic_job(nx, nz);
    job.cost_model.combine = combine;
    if combine == crate::api::job::Combine::Primitives {
        job.target_frame_time_ms = 1.0 + 0.5e-6 * 40_000.0;
    }
    job
}

/// Calls `f` with the placement context and problem views of `job` over
/// `scene` (no visibility), the start of most method tests.
pub fn with_problem_views<R>(
    scene: &Scene,
    job: &Job,
    f: impl FnOnce(&crate::views::Context, &crate::views::ProblemViews) -> R,
) -> R {
    let h = crate::scene::hierarchy::Hierarchy::build(scene);
    let ctx = crate::views::Context::new(scene, &h, None, job, crate::control::Control::default());
    let pv = crate::views::approximate(&ctx, job, &crate::views::Counters::new());
    f(&ctx, &pv)
}

/// The geometry of a scene whose objects are solid boxes: each object is a
/// closed, outward-facing cuboid filling its bounds (one mesh per object,
/// one opaque single-sided material).
pub fn box_geometry(scene: &Scene) -> crate::scene::geometry::SceneGeometry {
    use crate::scene::geometry::{Instance, MeshData, SceneGeometry};
    use crate::scene::material::Material;
    use glam::{DAffine3, Vec3};
    let mut meshes = Vec::new();
    let mut instances = Vec::new();
    for (o, ob) in scene.objects.iter().enumerate() {
        let (lo, hi) = (ob.min.as_vec3(), ob.max.as_vec3());
        let c = |x: bool, y: bool, z: bool| {
            Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let (f, t) = (false, true);
        let quads = [
            [c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t)],
            [c(t, f, f), c(f, f, f), c(f, t, f), c(t, t, f)],
            [c(t, f, t), c(t, f, f), c(t, t, f), c(t, t, t)],
            [c(f, f, f), c(f, f, t), c(f, t, t), c(f, t, f)],
            [c(f, t, t), c(t, t, t), c(t, t, f), c(f, t, f)],
            [c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t)],
        ];
        let mut m = MeshData::default();
        for q in quads {
            let n = (q[1] - q[0]).cross(q[3] - q[0]).normalize_or_zero();
            let base = m.positions.len() as u32;
            for p in q {
                m.positions.push(p);
                m.normals.push(n);
            }
            m.indices
                .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
        }
        meshes.push(m);
        instances.push(Instance {
            object: o as u32,
            mesh: o as u32,
            transform: DAffine3::IDENTITY,
        });
    }
    SceneGeometry {
        meshes,
        instances,
        materials: vec![Material::default()],
        textures: Vec::new(),
        objects: scene.objects.len(),
        object_nodes: Vec::new(),
    }
}

/// A synthetic comparison report (no runs behind it) for rendering tests
/// and samples: methods `shafts`, `boxes` and `env-map` over five target
/// frame times (5, 10, 20, 40, 80 ms), base runs at 20 ms, a
/// `problem_views.cell_size` sweep (2, 4, 8) for `shafts` and `boxes`,
/// walkthroughs for `shafts` (10 and 20 ms) and `boxes` (20 ms), and a
/// stability block. `env-map` at 5 ms failed (its error holds a comma),
/// `boxes` at 80 ms needed no impostors (0 bytes), `boxes` at 10 ms has 2
/// views over the target in solved problem views, and the job's text holds
/// markup (`</pre><script>…`) to check escaping.
pub fn sample_report() -> crate::report::Report {
    use crate::api::stats::StageTime;
    use crate::report::{
        EvalSummary, Machine, MethodStability, Perturbed, Report, Run, SceneInfo, Spread,
        Stability, Sweep, Walkthrough,
    };
    let targets = [5.0, 10.0, 20.0, 40.0, 80.0];
    let memory: [(&str, [u64; 5]); 3] = [
        (
            "shafts",
            [12_000_000, 6_000_000, 3_000_000, 1_500_000, 700_000],
        ),
        ("boxes", [30_000_000, 15_000_000, 8_000_000, 4_000_000, 0]),
        ("env-map", [0, 4_000_000, 3_500_000, 3_000_000, 2_500_000]),
    ];
    let run = |method: &str, knob: Option<&str>, value: Option<f64>, t: f64, mem: u64, s: f64| {
        let over = u64::from(method == "boxes" && t == 10.0 && knob.is_some());
        // Per method, how close the evaluation comes to the target.
        let k = match method {
            "shafts" => 0.97,
            "boxes" => 0.9,
            _ => 0.8,
        };
        Run {
            method: method.into(),
            knob: knob.map(String::from),
            value,
            target_frame_time_ms: t,
            status: crate::report::RunStatus::Ok,
            error: None,
            cpvs: 120,
            candidates: 900,
            impostors: mem / 100_000,
            memory_bytes: mem,
            unsolved_cpvs: 0,
            max_residual_ms: 0.0,
            budget_bytes: None,
            seconds: s,
            stage_seconds: vec![StageTime::new("greedy", s / 2.0)],
            eval: Some(EvalSummary {
                views: 1000,
                max_ms: t * if over == 1 { 1.08 } else { k },
                p99_ms: t * k * 0.85,
                p50_ms: t * k * 0.5,
                mean_ms: t * k * 0.55,
                violations: over * 3,
                violations_in_solved: over * 2,
                max_ms_in_solved: t * if over == 1 { 1.08 } else { k * 0.97 },
                cpv_views: 1000,
                violations_in_cpv_views: over,
                control_violations: 40,
                parallax_max_px: Some(0.9 + 0.1 * k),
                estimates: Some(crate::api::evaluation::EstimateCheck {
                    cpvs_sampled: 120,
                    ratio_original_median: 0.8 * k,
                    ratio_final_median: 0.85 * k,
                    cpvs_never_over: 30,
                    points: (0..40u32)
                        .map(|i| {
                            let f = f64::from(i) / 40.0;
                            crate::api::evaluation::EstimatePoint {
                                cpv: i,
                                views: 1 + i % 3,
                                estimate_ms: t * (1.0 + 0.3 * f),
                                exact_max_ms: t * k * (0.7 + 0.4 * f),
                                estimate_final_ms: t * (0.9 + 0.1 * f),
                                exact_final_max_ms: t * k * (0.6 + 0.3 * f),
                            }
                        })
                        .collect(),
                }),
            }),
            exact: None,
            cache: None,
            bake: None,
            image: None,
        }
    };
    let mut runs = Vec::new();
    for (method, mem) in memory {
        for (i, t) in targets.iter().enumerate() {
            let mut r = run(
                method,
                Some("target_frame_time_ms"),
                Some(*t),
                *t,
                mem[i],
                10.0 / t,
            );
            if method == "env-map" && i == 0 {
                r.status = crate::report::RunStatus::Failed;
                r.error = Some("placement failed: 3 CPVs unsolvable, budget exceeded".into());
                r.eval = None;
            }
            runs.push(r);
        }
        runs.push(run(method, None, None, 20.0, mem[2], 0.5));
    }
    let cells = [
        (
            "shafts",
            [(9.0, 2_500_000), (4.0, 3_000_000), (2.0, 4_000_000)],
        ),
        (
            "boxes",
            [(5.0, 7_000_000), (3.0, 8_000_000), (1.5, 9_500_000)],
        ),
    ];
    for (method, pts) in cells {
        for (value, (s, mem)) in [2.0, 4.0, 8.0].into_iter().zip(pts) {
            runs.push(run(
                method,
                Some("problem_views.cell_size"),
                Some(value),
                20.0,
                mem,
                s,
            ));
        }
    }
    // Shafts under budgets of a half and a quarter of their 3 MB at 20 ms.
    for (f, max) in [(0.5, 26.0), (0.25, 33.0)] {
        let budget = (3_000_000.0 * f) as u64;
        let mut r = run(
            "shafts",
            Some("memory.budget_bytes"),
            Some(budget as f64),
            20.0,
            budget - 20_000,
            0.6,
        );
        r.budget_bytes = Some(budget);
        r.unsolved_cpvs = (40.0 / f) as u64;
        r.max_residual_ms = max - 20.0 + 1.0;
        if let Some(e) = &mut r.eval {
            e.max_ms = max;
            e.p99_ms = 0.8 * max;
            e.violations = 50;
        }
        runs.push(r);
    }
    // Without impostors the path peaks at 22 ms, over every target.
    let bare = |i: i32| 10.0 + 12.0 * (f64::from(i) * 0.1).sin().abs();
    let walk = |method: &str, t: f64, bump: bool| Walkthrough {
        method: method.into(),
        target_frame_time_ms: t,
        frame_ms: (0..60)
            .map(|i| {
                let ms = (t * (0.6 + 0.3 * (f64::from(i) * 0.2).sin())).min(bare(i));
                if bump && i == 30 { t * 1.05 } else { ms }
            })
            .collect(),
        bare_ms: (0..60).map(bare).collect(),
        estimate_ms: (0..60).map(|i| (bare(i) > t).then_some(t * 0.98)).collect(),
    };
    let spread = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
        Spread {
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            mean,
            relative_std: if mean > 0.0 { var.sqrt() / mean } else { 0.0 },
        }
    };
    let stable = |method: &str, mem: [u64; 4]| {
        let labels = [
            "base",
            "target +5%",
            "grid shifted 0.5 cell",
            "objects shuffled (seed 2)",
        ];
        let settings: Vec<Perturbed> = labels
            .iter()
            .zip(mem)
            .map(|(l, m)| Perturbed {
                label: (*l).into(),
                status: crate::report::RunStatus::Ok,
                memory_bytes: m,
                impostors: m / 100_000,
                unsolved_cpvs: 0,
                max_ms: 19.0,
            })
            .collect();
        let mems: Vec<f64> = mem.iter().map(|m| *m as f64).collect();
        let imps: Vec<f64> = mem.iter().map(|m| (m / 100_000) as f64).collect();
        MethodStability {
            method: method.into(),
            settings,
            memory: spread(&mems),
            impostors: spread(&imps),
        }
    };
    Report {
        version: env!("CARGO_PKG_VERSION").into(),
        created: "2025-01-01T00:00:00Z".into(),
        machine: Machine {
            os: "linux x86_64".into(),
            threads: 2,
            cpu: "Example CPU".into(),
            memory_bytes: 24_000_000_000,
        },
        scene: SceneInfo {
            name: "city.glb".into(),
            objects: 1200,
            triangles: 2_400_000,
            min: [0.0, 0.0, 0.0],
            max: [400.0, 60.0, 400.0],
        },
        job: serde_json::json!({
            "target_frame_time_ms": 20.0,
            "problem_views": { "cell_size": 4.0 },
            "note": "</pre><script>alert('x')</script>",
        }),
        methods: vec!["shafts".into(), "boxes".into(), "env-map".into()],
        sweeps: vec![
            Sweep {
                knob: "target_frame_time_ms".into(),
                values: targets.to_vec(),
            },
            Sweep {
                knob: "problem_views.cell_size".into(),
                values: vec![2.0, 4.0, 8.0],
            },
        ],
        budgets: vec![0.5, 0.25],
        runs,
        walkthroughs: vec![
            walk("shafts", 10.0, false),
            walk("shafts", 20.0, false),
            walk("boxes", 20.0, true),
        ],
        stability: Some(Stability {
            methods: vec![
                stable("shafts", [3_000_000, 3_100_000, 2_900_000, 3_050_000]),
                stable("boxes", [8_000_000, 8_600_000, 7_200_000, 8_100_000]),
            ],
        }),
    }
}

/// Places `job` over a scene without geometry (the job must need none).
#[cfg(test)]
pub fn try_place(
    scene: &Scene,
    job: &Job,
    opts: &crate::place::PlaceOptions,
    ctl: &crate::control::Control,
) -> crate::Result<crate::place::PlaceOutput> {
    let input = crate::input::SceneInput::from_scene(scene, job)?;
    input.prepare(job, "job")?.place(opts, ctl)
}

/// The placement of `job` over a scene without geometry, default options.
#[cfg(test)]
pub fn place(scene: &Scene, job: &Job) -> crate::api::placement::Placement {
    try_place(
        scene,
        job,
        &crate::place::PlaceOptions::default(),
        &crate::control::Control::default(),
    )
    .expect("the job places")
    .placement
}

/// Evaluates `placement` of `job` over a scene without geometry.
#[cfg(test)]
pub fn evaluate(
    scene: &Scene,
    job: &Job,
    placement: &crate::api::placement::Placement,
    opts: &crate::evaluate::EvalOptions,
) -> crate::Result<crate::api::evaluation::Evaluation> {
    let input = crate::input::SceneInput::from_scene(scene, job)?;
    input
        .prepare(job, "job")?
        .evaluate(placement, opts, "placement")
}
