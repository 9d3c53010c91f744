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

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::cost::{Cost, CostModel};
use crate::error::{Error, Result};
use crate::geom::{Aabb, Sphere, Vdi, ViewFrustum, face_direction};
use crate::hierarchy::Hierarchy;
use crate::impostor_model::ViewCell;
use crate::job::Job;
use crate::placement::{Placement, ViewCellJson};
use crate::problem_views::{Grid, leaf_level};
use crate::rng::Rng;
use crate::scene::Scene;

/// Options of an evaluation.
#[derive(Clone, Copy, Debug)]
pub struct EvalOptions {
    /// Number of random views.
    pub views: u64,
    /// Seed of the view sampler.
    pub seed: u64,
}

/// The evaluation report (`eval.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Evaluation {
    /// Views sampled.
    pub views: u64,
    /// Seed of the sampler.
    pub seed: u64,
    /// The target frame time, ms.
    pub target_frame_time_ms: f64,
    /// Largest view time, ms.
    pub max_ms: f64,
    /// Median view time, ms.
    pub p50_ms: f64,
    /// 99th percentile view time, ms.
    pub p99_ms: f64,
    /// Mean view time, ms.
    pub mean_ms: f64,
    /// Views over the target.
    pub violations: u64,
    /// Views over the target whose CPV is solved or that lie in no CPV: must
    /// be 0 for every placement.
    pub violations_in_solved: u64,
    /// Largest view time among views whose CPV is solved or in no CPV, ms.
    pub max_ms_in_solved: f64,
    /// Views that lie in some CPV.
    pub views_in_cpvs: u64,
    /// Views that lie in an unsolved CPV.
    pub views_in_unsolved_cpvs: u64,
    /// Views where an impostor of their CPV was used outside its view cell
    /// (must be 0).
    pub impostors_outside_view_cell: u64,
    /// Mean of `target − time` over views within the target, ms
    /// (over-conservativeness).
    pub mean_slack_ms: f64,
    /// Image error of the impostors (`evaluate --images N`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<crate::image_eval::ImageReport>,
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
    let grid = Grid::new(job);
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

/// Exact time of one view.
fn view_time(
    scene: &Scene,
    h: &Hierarchy,
    model: &CostModel,
    f: &ViewFrustum,
    replaced: &[u32],
    impostors: &[u32],
    prepared: &Prepared,
) -> f64 {
    let eye = f.eye();
    let mut cost = Cost::default();
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        let node = &h.nodes[n as usize];
        if !f.intersects_sphere(node.sphere.center, node.sphere.radius) {
            continue;
        }
        match node.children {
            Some([l, r]) => {
                stack.push(r);
                stack.push(l);
            }
            None => {
                for &o in h.objects(n) {
                    let s = &h.object_spheres[o as usize];
                    if replaced.binary_search(&o).is_ok()
                        || !f.intersects_sphere(s.center, s.radius)
                    {
                        continue;
                    }
                    let ob = &scene.objects[o as usize];
                    cost += model.geometry(
                        ob.draw_calls,
                        ob.triangles,
                        s.radius,
                        eye.distance(s.center),
                    );
                }
            }
        }
    }
    for &i in impostors {
        let imp = &prepared.impostors[i as usize];
        let s = imp.sphere;
        if f.intersects_sphere(s.center, s.radius) {
            cost += model.impostor(imp.layers, s.radius, eye.distance(s.center));
        }
    }
    model.frame_time(cost)
}

/// Evaluates `placement` for `job` over `scene`. `source` names the placement
/// file in errors.
pub fn evaluate(
    scene: &Scene,
    job: &Job,
    placement: &Placement,
    opts: &EvalOptions,
    source: &str,
) -> Result<Evaluation> {
    if opts.views == 0 || opts.views > 100_000_000 {
        return Err(Error::bad(
            "--views",
            format!("{} must be between 1 and 100000000", opts.views),
        ));
    }
    let prepared = prepare(scene, job, placement, source)?;
    let h = Hierarchy::build(scene);
    let model = CostModel::new(job);
    let t_max = job.target_frame_time_ms;
    let [w, hgt] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(hgt);
    let (lo, hi) = (job.vs_min(), job.vs_max());
    let pitch = job.view_space.pitch_deg.map(f64::to_radians);
    // (time, cpv or MAX, impostor outside its cell)
    let samples: Vec<(f64, u32, bool)> = (0..opts.views)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::new(opts.seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ i);
            let eye = rng.in_box(lo, hi);
            let dir = rng.direction_in_pitch(pitch[0], pitch[1]);
            let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
            let cell = prepared
                .grid
                .cell_of(eye)
                .expect("sampled inside the view space");
            let vdi = Vdi::containing(dir, prepared.level);
            let cpv = prepared
                .lookup
                .get(&(prepared.grid.linear(cell), vdi))
                .copied();
            let (replaced, imps): (&[u32], &[u32]) = match cpv {
                Some(c) => (
                    &prepared.cpv_replaced[c as usize],
                    &prepared.cpv_impostors[c as usize],
                ),
                None => (&[], &[]),
            };
            let outside = imps
                .iter()
                .any(|&i| !prepared.impostors[i as usize].cell.contains_point(eye));
            let t = view_time(scene, &h, &model, &f, replaced, imps, &prepared);
            (t, cpv.unwrap_or(u32::MAX), outside)
        })
        .collect();
    let mut times: Vec<f64> = samples.iter().map(|s| s.0).collect();
    times.sort_by(f64::total_cmp);
    let pct = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    let over = |t: f64| t > t_max * (1.0 + 1e-12);
    let solved = |c: u32| c == u32::MAX || prepared.cpv_solved[c as usize];
    let in_solved: Vec<f64> = samples
        .iter()
        .filter(|s| solved(s.1))
        .map(|s| s.0)
        .collect();
    let within: Vec<f64> = times.iter().copied().filter(|&t| !over(t)).collect();
    Ok(Evaluation {
        views: opts.views,
        seed: opts.seed,
        target_frame_time_ms: t_max,
        max_ms: *times.last().expect("at least one view"),
        p50_ms: pct(0.5),
        p99_ms: pct(0.99),
        mean_ms: times.iter().sum::<f64>() / times.len() as f64,
        violations: samples.iter().filter(|s| over(s.0)).count() as u64,
        violations_in_solved: in_solved.iter().filter(|&&t| over(t)).count() as u64,
        max_ms_in_solved: in_solved.iter().copied().fold(0.0, f64::max),
        views_in_cpvs: samples.iter().filter(|s| s.1 != u32::MAX).count() as u64,
        views_in_unsolved_cpvs: samples.iter().filter(|s| !solved(s.1)).count() as u64,
        impostors_outside_view_cell: samples.iter().filter(|s| s.2).count() as u64,
        mean_slack_ms: if within.is_empty() {
            0.0
        } else {
            within.iter().map(|t| t_max - t).sum::<f64>() / within.len() as f64
        },
        image: None,
    })
}
