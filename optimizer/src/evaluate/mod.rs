//! Independent frame-time check (DESIGN §2.10): the oracle for the guarantee.
//!
//! Samples random views (position uniform in the view space, direction
//! uniform over the allowed pitch band), finds each view's CPV from the
//! placement, and computes the view's time with its exact frustum: every
//! object whose bounding sphere meets the frustum is drawn as geometry at its
//! actual distance, unless an impostor of the view's CPV represents it, in
//! which case the impostor is drawn instead (if its cluster sphere meets the
//! frustum). It does not use the enclosing frusta, the candidates or the
//! greedy state: only the scene, the job and the placement.
//!
//! With visibility, each view counts only the objects of its grid cell's
//! potentially visible set (the same set the placement used), and the set
//! itself is checked: rays cast from the view point through a grid over the
//! image, and rays aimed at points on the nearest objects the set culled,
//! find objects that are actually visible; any such object missing from the
//! set is counted in `visibility.missed_objects` (0 in conservative mode).

pub mod images;

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use crate::api::evaluation::{Evaluation, MissedObject, ParallaxCheck, VisibilityCheck};
use crate::api::job::Job;
use crate::api::placement::{Placement, ViewCellJson};
use crate::error::{Error, Result};
use crate::input::SceneInput;
use crate::math::geom::{Aabb, Sphere, Vdi, ViewFrustum, face_direction};
use crate::math::grid::Grid;
use crate::math::rng::Rng;
use crate::model::cost::{Cost, CostModel};
use crate::model::impostor::ViewCell;
use crate::render::raycast::RayCaster;
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::hierarchy::Hierarchy;
use crate::views::leaf_level;
use crate::visibility::{ObjectSet, Visibility};

/// Options of an evaluation.
#[derive(Clone, Copy, Debug)]
pub struct EvalOptions {
    /// Number of random views.
    pub views: u64,
    /// Seed of the view sampler.
    pub seed: u64,
    /// Visibility check: rays per view through a grid over the image (0: none).
    pub check_rays: u32,
    /// Visibility check: culled objects in the view frustum, nearest first,
    /// probed per view with rays aimed at points of their surfaces.
    pub check_objects: u32,
}

impl EvalOptions {
    /// Checks the sample counts.
    pub fn check(&self) -> Result<()> {
        if self.views == 0 || self.views > 100_000_000 {
            return Err(Error::bad(
                "--views",
                format!("{} must be between 1 and 100000000", self.views),
            ));
        }
        if self.check_rays > 1_000_000 || self.check_objects > 100_000 {
            return Err(Error::bad(
                "--check-rays/--check-objects",
                "at most 1000000 rays and 100000 objects per view",
            ));
        }
        Ok(())
    }
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            views: 10_000,
            seed: 1,
            check_rays: 256,
            check_objects: 16,
        }
    }
}

/// Sphere points and viewpoints per impostor of the parallax check.
const PARALLAX_SAMPLES: u32 = 32;

/// Checks the parallax of every impostor of `placement` (deterministic:
/// each impostor's samples are seeded by `seed` and its id).
pub fn parallax_check(job: &Job, placement: &Placement, seed: u64) -> Option<ParallaxCheck> {
    if placement.impostors.is_empty() {
        return None;
    }
    let theta = job.pixel_angle();
    let errs: Vec<f64> = placement
        .impostors
        .par_iter()
        .map(|imp| {
            let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(imp.id));
            crate::model::layers::parallax(imp, &mut rng, PARALLAX_SAMPLES, PARALLAX_SAMPLES)
                / theta
        })
        .collect();
    let budget = job.max_error_px;
    let (worst, max_px) =
        errs.iter().enumerate().fold(
            (0, 0.0f64),
            |(wi, wm), (i, &e)| if e > wm { (i, e) } else { (wi, wm) },
        );
    Some(ParallaxCheck {
        max_error_px: budget,
        impostors: errs.len() as u64,
        points: PARALLAX_SAMPLES,
        viewpoints: PARALLAX_SAMPLES,
        max_px,
        mean_px: errs.iter().sum::<f64>() / errs.len() as f64,
        over_budget: errs.iter().filter(|&&e| e > budget).count() as u64,
        over_budget_1_5: errs.iter().filter(|&&e| e > 1.5 * budget).count() as u64,
        worst_impostor: placement.impostors[worst].id,
    })
}

struct PreparedImpostor {
    sphere: Sphere,
    layers: u32,
    cell: ViewCell,
}

/// Checks that the placement refers to the scene and the job, and prepares
/// the lookups.
struct Prepared {
    impostors: Vec<PreparedImpostor>,
    /// Per CPV: sorted represented object ids and the impostor ids.
    cpv_replaced: Vec<Vec<u32>>,
    cpv_impostors: Vec<Vec<u32>>,
    cpv_solved: Vec<bool>,
    lookup: HashMap<(u32, Vdi), u32>,
    grid: Grid,
    level: u8,
}

fn prepare(scene: &Scene, job: &Job, placement: &Placement, source: &str) -> Result<Prepared> {
    let n_obj = scene.objects.len() as u32;
    let mut impostors = Vec::with_capacity(placement.impostors.len());
    for (k, imp) in placement.impostors.iter().enumerate() {
        let what = format!("{source}: impostors[{k}]");
        if imp.id as usize != k {
            return Err(Error::bad(what, format!("id {} is not its index", imp.id)));
        }
        let center = DVec3::from_array(imp.sphere.center);
        let sphere = Sphere {
            center,
            radius: imp.sphere.radius,
        };
        if !(center.is_finite() && sphere.radius.is_finite() && sphere.radius >= 0.0) {
            return Err(Error::bad(what, "sphere is not finite"));
        }
        if imp.objects.is_empty() {
            return Err(Error::bad(what, "represents no objects"));
        }
        for &o in &imp.objects {
            if o >= n_obj {
                return Err(Error::bad(
                    format!("{what}.objects"),
                    format!(
                        "object id {o} does not exist in the scene ({n_obj} objects): the placement does not match the scene"
                    ),
                ));
            }
            let ob = &scene.objects[o as usize];
            if center.distance(ob.center()) + ob.radius() > sphere.radius * (1.0 + 1e-9) + 1e-6 {
                return Err(Error::bad(
                    format!("{what}.sphere"),
                    format!("does not contain object {o}: the placement does not match the scene"),
                ));
            }
        }
        if imp.layers == 0 || imp.resolution == 0 {
            return Err(Error::bad(
                what,
                format!(
                    "layers ({}) and resolution ({}) must be positive",
                    imp.layers, imp.resolution
                ),
            ));
        }
        if let Err((field, problem)) = imp.check_view_cell() {
            return Err(Error::bad(format!("{what}.{field}"), problem));
        }
        let cell = match imp.view_cell {
            ViewCellJson::Shaft {
                apex,
                axis,
                half_angle_deg,
                min_distance,
            } => ViewCell::Shaft {
                apex: DVec3::from_array(apex),
                axis: DVec3::from_array(axis).normalize_or_zero(),
                half_angle: half_angle_deg.to_radians(),
                min_distance,
            },
            ViewCellJson::Box { min, max } => {
                ViewCell::Box(Aabb::new(DVec3::from_array(min), DVec3::from_array(max)))
            }
        };
        impostors.push(PreparedImpostor {
            sphere,
            layers: imp.layers,
            cell,
        });
    }
    let grid = job.grid();
    let level = leaf_level(job.problem_views.min_vdi_deg);
    let mut lookup = HashMap::with_capacity(placement.cpvs.len());
    let mut cpv_replaced = Vec::with_capacity(placement.cpvs.len());
    let mut cpv_impostors = Vec::with_capacity(placement.cpvs.len());
    let mut cpv_solved = Vec::with_capacity(placement.cpvs.len());
    for (k, c) in placement.cpvs.iter().enumerate() {
        let what = format!("{source}: cpvs[{k}]");
        let region = Aabb::new(
            DVec3::from_array(c.region.min),
            DVec3::from_array(c.region.max),
        );
        let cell = grid
            .cell_of(region.center())
            .ok_or_else(|| Error::bad(&what, "region lies outside the job's view space"))?;
        let expect = grid.cell_box(cell, cell.map(|i| i + 1));
        if expect.min.distance(region.min) + expect.max.distance(region.max)
            > 1e-6 * (1.0 + expect.half_diagonal())
        {
            return Err(Error::bad(
                &what,
                "region is not a cell of the job's view space grid: the placement does not match the job",
            ));
        }
        let d = &c.directions;
        if d.face > 5 {
            return Err(Error::bad(
                format!("{what}.directions.face"),
                format!("{} is not in 0..6", d.face),
            ));
        }
        let mid = |[a, b]: [f64; 2]| ((a.atan() + b.atan()) * 0.5).tan();
        let vdi = Vdi::containing(face_direction(d.face, mid(d.u), mid(d.v)), level);
        if (vdi.u_range()[0] - d.u[0]).abs() > 1e-9 || (vdi.v_range()[1] - d.v[1]).abs() > 1e-9 {
            return Err(Error::bad(
                format!("{what}.directions"),
                "is not a minimum-size VDI of the job: the placement does not match the job",
            ));
        }
        if lookup.insert((grid.linear(cell), vdi), k as u32).is_some() {
            return Err(Error::bad(&what, "duplicate CPV"));
        }
        let mut replaced = Vec::new();
        for &i in &c.impostors {
            let imp = placement.impostors.get(i as usize).ok_or_else(|| {
                Error::bad(
                    format!("{what}.impostors"),
                    format!("impostor {i} does not exist"),
                )
            })?;
            replaced.extend_from_slice(&imp.objects);
        }
        replaced.sort_unstable();
        let before = replaced.len();
        replaced.dedup();
        if replaced.len() != before {
            return Err(Error::bad(
                format!("{what}.impostors"),
                "two impostors represent the same object",
            ));
        }
        cpv_replaced.push(replaced);
        cpv_impostors.push(c.impostors.clone());
        cpv_solved.push(c.time_ms_final <= job.target_frame_time_ms && c.solved);
    }
    Ok(Prepared {
        impostors,
        cpv_replaced,
        cpv_impostors,
        cpv_solved,
        lookup,
        grid,
        level,
    })
}

impl Prepared {
    /// The CPV of a view (its cell and direction), with the objects its
    /// impostors replace and the impostors; empty lists outside CPVs.
    fn view_cpv(&self, cell: [u32; 3], dir: DVec3) -> (Option<u32>, &[u32], &[u32]) {
        let vdi = Vdi::containing(dir, self.level);
        match self.lookup.get(&(self.grid.linear(cell), vdi)).copied() {
            Some(c) => (
                Some(c),
                &self.cpv_replaced[c as usize],
                &self.cpv_impostors[c as usize],
            ),
            None => (None, &[], &[]),
        }
    }
}

/// Exact time of one view. Objects outside `visible` (when given) are not
/// drawn; those of them in the frustum are listed in `culled` with their
/// distance, when asked.
#[allow(clippy::too_many_arguments)] // one view: its frustum and its CPV's data
fn view_time(
    scene: &Scene,
    h: &Hierarchy,
    model: &CostModel,
    f: &ViewFrustum,
    replaced: &[u32],
    impostors: &[u32],
    prepared: &Prepared,
    visible: Option<&ObjectSet>,
    mut culled: Option<&mut Vec<(f64, u32)>>,
) -> f64 {
    let eye = f.eye();
    let mut cost = Cost::default();
    h.walk(|n, node| {
        if !f.intersects_sphere(node.sphere.center, node.sphere.radius) {
            return false;
        }
        if node.children.is_none() {
            for &o in h.objects(n) {
                let s = &h.object_spheres[o as usize];
                if replaced.binary_search(&o).is_ok() || !f.intersects_sphere(s.center, s.radius) {
                    continue;
                }
                if visible.is_some_and(|v| !v.contains(o)) {
                    if let Some(c) = culled.as_deref_mut() {
                        c.push((eye.distance(s.center) - s.radius, o));
                    }
                    continue;
                }
                let ob = &scene.objects[o as usize];
                cost += model.object_view(ob, s.radius, eye.distance(s.center));
            }
        }
        true
    });
    for &i in impostors {
        let imp = &prepared.impostors[i as usize];
        let s = imp.sphere;
        if f.intersects_sphere(s.center, s.radius) {
            cost += model.impostor(imp.layers, s.radius, eye.distance(s.center));
        }
    }
    model.frame_time(cost)
}

/// Objects visible from the view point (rays through the image and at the
/// nearest culled objects) that `visible` lacks: `(object, by_probe)`.
#[allow(clippy::too_many_arguments)] // one view and its check budget
fn check_view(
    caster: &RayCaster,
    geom: &SceneGeometry,
    ranges: &[(usize, usize)],
    f: &ViewFrustum,
    fov_deg: f64,
    aspect: f64,
    visible: &ObjectSet,
    culled: &mut [(f64, u32)],
    opts: &EvalOptions,
    rng: &mut Rng,
) -> (Vec<(u32, bool)>, u64) {
    let mut missed: Vec<(u32, bool)> = Vec::new();
    let mut rays = 0u64;
    let (right, up, fwd) = f.basis();
    let tv = (fov_deg.to_radians() * 0.5).tan();
    let th = tv * aspect;
    let side = f64::from(opts.check_rays).sqrt().ceil() as u32;
    for j in 0..side {
        for i in 0..side {
            if u64::from(j * side + i) >= u64::from(opts.check_rays) {
                break;
            }
            let x = ((f64::from(i) + rng.f64()) / f64::from(side) * 2.0 - 1.0) * th;
            let y = ((f64::from(j) + rng.f64()) / f64::from(side) * 2.0 - 1.0) * tv;
            let dir = fwd + right * x + up * y;
            rays += 1;
            caster.trace(f.eye(), dir, 0.0, f64::INFINITY, &mut |o| {
                if !visible.contains(o) && !missed.iter().any(|m| m.0 == o) {
                    missed.push((o, false));
                }
            });
        }
    }
    culled.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for &(_, o) in culled.iter().take(opts.check_objects as usize) {
        if missed.iter().any(|m| m.0 == o) {
            continue;
        }
        for _ in 0..2 {
            let Some(p) = geom.surface_point(ranges[o as usize], f.eye(), 8, rng, |p| {
                f.distance(p) <= 0.0
            }) else {
                break;
            };
            rays += 1;
            if caster.segment_clear(f.eye(), p) {
                missed.push((o, true));
                break;
            }
        }
    }
    (missed, rays)
}

/// Evaluates `placement` for `job` over a `scene` without geometry (the job
/// must not need any). `source` names the placement file in errors.
pub fn evaluate(
    scene: &Scene,
    job: &Job,
    placement: &Placement,
    opts: &EvalOptions,
    source: &str,
) -> Result<Evaluation> {
    let input = SceneInput::from_scene(scene, job)?;
    evaluate_input(&input, job, placement, opts, source)
}

/// One sampled view's outcome.
struct ViewResult {
    time: f64,
    cpv: u32,
    outside: bool,
    visible: usize,
    missed: Vec<(u32, bool)>,
    rays: u64,
    checked: bool,
}

/// Evaluates `placement` for `job` over a prepared scene (the same levels of
/// detail and visibility the placement used). `source` names the placement
/// file in errors.
pub fn evaluate_input(
    input: &SceneInput,
    job: &Job,
    placement: &Placement,
    opts: &EvalOptions,
    source: &str,
) -> Result<Evaluation> {
    opts.check()?;
    let scene = &input.scene;
    let h = Hierarchy::build(scene);
    let vis = Visibility::new(job, scene, &h, input.visibility_inputs(job))?;
    evaluate_shared(
        input,
        job,
        placement,
        opts,
        source,
        &Shared {
            hierarchy: &h,
            visibility: vis.as_ref(),
        },
    )
}

/// What evaluations of one scene and view-space grid can share: the object
/// hierarchy and the visibility (whose cells are computed once).
#[derive(Clone, Copy)]
pub struct Shared<'a> {
    /// The object hierarchy of the scene.
    pub hierarchy: &'a Hierarchy,
    /// The job's visibility, `None` for mode `none`.
    pub visibility: Option<&'a Visibility<'a>>,
}

/// [`evaluate_input`] with a shared hierarchy and visibility (built for the
/// same scene and for a job with the same view space, grid and visibility).
pub fn evaluate_shared(
    input: &SceneInput,
    job: &Job,
    placement: &Placement,
    opts: &EvalOptions,
    source: &str,
    shared: &Shared,
) -> Result<Evaluation> {
    opts.check()?;
    let scene = &input.scene;
    let prepared = prepare(scene, job, placement, source)?;
    let h = shared.hierarchy;
    let vis = shared.visibility;
    let model = CostModel::new(job);
    let t_max = job.target_frame_time_ms;
    let [w, hgt] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(hgt);
    let (lo, hi) = (job.vs_min(), job.vs_max());
    let pitch = job.view_space.pitch_deg.map(f64::to_radians);
    let view_of = |i: u64| {
        let mut rng = Rng::new(opts.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ i);
        let eye = rng.in_box(lo, hi);
        let dir = rng.direction_in_pitch(pitch[0], pitch[1]);
        (eye, dir, rng)
    };
    let mut cells_used: Vec<[u32; 3]> = Vec::new();
    if let Some(v) = vis {
        cells_used = (0..opts.views)
            .into_par_iter()
            .map(|i| prepared.grid.cell_of(view_of(i).0).expect("inside"))
            .collect();
        cells_used.sort_unstable();
        cells_used.dedup();
        v.prefetch(&cells_used);
    }
    let check = vis.is_some() && (opts.check_rays > 0 || opts.check_objects > 0);
    let caster = if check { input.caster() } else { None };
    let ranges = match (&input.geometry, caster) {
        (Some(g), Some(_)) => g.instance_ranges(),
        _ => Vec::new(),
    };
    let samples: Vec<ViewResult> = (0..opts.views)
        .into_par_iter()
        .map(|i| {
            let (eye, dir, mut rng) = view_of(i);
            let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
            let cell = prepared
                .grid
                .cell_of(eye)
                .expect("sampled inside the view space");
            let (cpv, replaced, imps) = prepared.view_cpv(cell, dir);
            let outside = imps
                .iter()
                .any(|&i| !prepared.impostors[i as usize].cell.contains_point(eye));
            let set = vis.map(|v| &v.cell(cell).set);
            let mut culled = Vec::new();
            let t = view_time(
                scene,
                h,
                &model,
                &f,
                replaced,
                imps,
                &prepared,
                set.map(|s| &**s),
                caster.is_some().then_some(&mut culled),
            );
            let (missed, rays, checked) = match (caster, set, &input.geometry) {
                (Some(c), Some(s), Some(g)) => {
                    let (m, r) = check_view(
                        c,
                        g,
                        &ranges,
                        &f,
                        job.camera.fov_deg,
                        aspect,
                        s,
                        &mut culled,
                        opts,
                        &mut rng,
                    );
                    (m, r, true)
                }
                _ => (Vec::new(), 0, false),
            };
            ViewResult {
                time: t,
                cpv: cpv.unwrap_or(u32::MAX),
                outside,
                visible: set.map_or(scene.objects.len(), |s| s.count()),
                missed,
                rays,
                checked,
            }
        })
        .collect();
    let mut times: Vec<f64> = samples.iter().map(|s| s.time).collect();
    times.sort_by(f64::total_cmp);
    let pct = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    let over = |t: f64| t > t_max * (1.0 + 1e-12);
    let solved = |c: u32| c == u32::MAX || prepared.cpv_solved[c as usize];
    let in_solved: Vec<f64> = samples
        .iter()
        .filter(|s| solved(s.cpv))
        .map(|s| s.time)
        .collect();
    let within: Vec<f64> = times.iter().copied().filter(|&t| !over(t)).collect();
    let visibility = vis.map(|_| {
        let n = samples.len() as f64;
        let objects = scene.objects.len().max(1) as f64;
        let mean_visible = samples.iter().map(|s| s.visible as f64).sum::<f64>() / n;
        let mut examples = Vec::new();
        for (i, s) in samples.iter().enumerate() {
            for &(o, _) in &s.missed {
                if examples.len() < 10 {
                    examples.push(MissedObject {
                        view: i as u64,
                        eye: view_of(i as u64).0.to_array(),
                        object: o,
                    });
                }
            }
        }
        VisibilityCheck {
            mode: job.visibility.mode,
            cells: cells_used.len() as u64,
            mean_visible_objects: mean_visible,
            mean_visible_fraction: mean_visible / objects,
            views_checked: samples.iter().filter(|s| s.checked).count() as u64,
            rays: samples.iter().map(|s| s.rays).sum(),
            missed_objects: samples.iter().map(|s| s.missed.len() as u64).sum(),
            views_with_misses: samples.iter().filter(|s| !s.missed.is_empty()).count() as u64,
            missed_by_image_rays: samples
                .iter()
                .map(|s| s.missed.iter().filter(|m| !m.1).count() as u64)
                .sum(),
            missed_by_probe_rays: samples
                .iter()
                .map(|s| s.missed.iter().filter(|m| m.1).count() as u64)
                .sum(),
            examples,
        }
    });
    Ok(Evaluation {
        views: opts.views,
        seed: opts.seed,
        target_frame_time_ms: t_max,
        max_ms: *times.last().expect("at least one view"),
        p50_ms: pct(0.5),
        p99_ms: pct(0.99),
        mean_ms: times.iter().sum::<f64>() / times.len() as f64,
        violations: samples.iter().filter(|s| over(s.time)).count() as u64,
        violations_in_solved: in_solved.iter().filter(|&&t| over(t)).count() as u64,
        max_ms_in_solved: in_solved.iter().copied().fold(0.0, f64::max),
        views_in_cpvs: samples.iter().filter(|s| s.cpv != u32::MAX).count() as u64,
        views_in_unsolved_cpvs: samples.iter().filter(|s| !solved(s.cpv)).count() as u64,
        impostors_outside_view_cell: samples.iter().filter(|s| s.outside).count() as u64,
        mean_slack_ms: if within.is_empty() {
            0.0
        } else {
            within.iter().map(|t| t_max - t).sum::<f64>() / within.len() as f64
        },
        image: None,
        visibility,
        parallax: parallax_check(job, placement, opts.seed),
    })
}

/// The views of a walkthrough: `frames` points evenly spaced along the
/// job's path (or, without one, a closed loop through the view space at
/// mid-height: an ellipse over 80 % of its extent), each looking along the
/// path, level.
pub fn walkthrough_views(job: &Job) -> Vec<(DVec3, DVec3)> {
    let (lo, hi) = (job.vs_min(), job.vs_max());
    let (points, frames): (Vec<DVec3>, u32) = match &job.walkthrough {
        Some(w) => (
            w.points.iter().map(|p| DVec3::from_array(*p)).collect(),
            w.frames,
        ),
        None => {
            let c = (lo + hi) * 0.5;
            let r = (hi - lo) * 0.4;
            let n = 256;
            (
                (0..=n)
                    .map(|i| {
                        let a = std::f64::consts::TAU * f64::from(i) / f64::from(n);
                        DVec3::new(c.x + r.x * a.cos(), c.y, c.z + r.z * a.sin())
                    })
                    .collect(),
                1000,
            )
        }
    };
    // Arc length along the polyline.
    let mut acc = vec![0.0];
    for w in points.windows(2) {
        let l = acc.last().copied().unwrap_or(0.0) + w[0].distance(w[1]);
        acc.push(l);
    }
    let total = acc.last().copied().unwrap_or(0.0);
    (0..frames)
        .map(|f| {
            let s = total * f64::from(f) / f64::from(frames.max(2) - 1);
            let k = acc
                .partition_point(|&a| a <= s)
                .saturating_sub(1)
                .min(points.len() - 2);
            let seg = acc[k + 1] - acc[k];
            let t = if seg > 0.0 { (s - acc[k]) / seg } else { 0.0 };
            let p = points[k].lerp(points[k + 1], t).clamp(lo, hi);
            let mut dir = points[k + 1] - points[k];
            dir.y = 0.0;
            if dir.length_squared() < 1e-18 {
                dir = DVec3::X;
            }
            (p, dir.normalize())
        })
        .collect()
}

/// Frame time of each given view `(eye, direction)` with `placement`'s
/// impostors (the views' problem views' impostors swapped in) and the
/// visible sets of their cells: the frame-time curve of a walkthrough.
pub fn frame_times(
    input: &SceneInput,
    job: &Job,
    placement: &Placement,
    views: &[(DVec3, DVec3)],
    source: &str,
    shared: &Shared,
) -> Result<Vec<f64>> {
    let scene = &input.scene;
    let prepared = prepare(scene, job, placement, source)?;
    let model = CostModel::new(job);
    let [w, hgt] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(hgt);
    Ok(views
        .par_iter()
        .map(|&(eye, dir)| {
            let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
            let Some(cell) = prepared.grid.cell_of(eye) else {
                return f64::NAN;
            };
            let (_, replaced, imps) = prepared.view_cpv(cell, dir);
            let set = shared.visibility.map(|v| &v.cell(cell).set);
            view_time(
                scene,
                shared.hierarchy,
                &model,
                &f,
                replaced,
                imps,
                &prepared,
                set.map(|s| &**s),
                None,
            )
        })
        .collect())
}
