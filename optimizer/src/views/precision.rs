//! How many problem views are real: exact views sampled inside a sample of
//! CPVs, none of which the conservative estimate may miss, and the share of
//! CPVs in which some sampled view exceeds the target (`cpv_precision`).

use glam::DVec3;
use rayon::prelude::*;

use crate::math::geom::{ViewFrustum, face_direction};
use crate::math::rng::Rng;
use crate::views::{Context, Cpv, ProblemViews};
use crate::visibility::ObjectSet;

/// CPVs sampled for the precision.
pub const PRECISION_CPVS: usize = 256;
/// Exact views sampled per CPV.
pub const PRECISION_VIEWS: usize = 32;

/// The exact frame time of the view from `eye` along `dir`, drawing only
/// the objects of `visible` (all when `None`), without impostors.
pub fn exact_view_time(ctx: &Context, visible: Option<&ObjectSet>, eye: DVec3, dir: DVec3) -> f64 {
    let f = ViewFrustum::new(eye, dir, ctx.lens.fov_deg, ctx.lens.aspect);
    let cost = ctx.model.view_cost(ctx.scene, ctx.hierarchy, &f, |o| {
        visible.is_none_or(|v| v.contains(o))
    });
    ctx.model.frame_time(cost)
}

/// A view direction of `cpv`'s VDI inside the pitch range (`None` when
/// `tries` draws found none).
fn sample_direction(ctx: &Context, cpv: &Cpv, rng: &mut Rng, tries: u32) -> Option<DVec3> {
    let [u0, u1] = cpv.vdi.u_range();
    let [v0, v1] = cpv.vdi.v_range();
    (0..tries).find_map(|_| {
        let d = face_direction(cpv.vdi.face, rng.range(u0, u1), rng.range(v0, v1)).normalize();
        let pitch = d.y.clamp(-1.0, 1.0).asin();
        (pitch >= ctx.pitch[0] && pitch <= ctx.pitch[1]).then_some(d)
    })
}

/// The slowest of `views` exact views sampled in `cpv` (uniform eyes in its
/// region, uniform face coordinates in its VDI, within the pitch range).
pub fn slowest_sampled_view(
    ctx: &Context,
    pv: &ProblemViews,
    cpv: &Cpv,
    views: usize,
    seed: u64,
) -> f64 {
    let kd = &pv.kd[cpv.kd as usize];
    let visible = ctx.visibility.and_then(|v| v.region(kd.lo, kd.hi));
    let mut rng = Rng::new(seed);
    let mut worst = 0.0f64;
    for _ in 0..views {
        let eye = rng.in_box(cpv.region.min, cpv.region.max);
        if let Some(dir) = sample_direction(ctx, cpv, &mut rng, 16) {
            worst = worst.max(exact_view_time(ctx, visible.as_deref(), eye, dir));
        }
    }
    worst
}

/// The share of CPVs in which some sampled exact view exceeds the target,
/// over up to [`PRECISION_CPVS`] CPVs spread evenly over the list, with
/// [`PRECISION_VIEWS`] views each; `(precision, CPVs sampled)`, `None` when
/// there is no CPV. Sampling can miss a CPV's slowest view, so this is a
/// lower bound of the share of real problem views.
pub fn cpv_precision(ctx: &Context, pv: &ProblemViews) -> Option<(f64, u64)> {
    let n = pv.cpvs.len();
    if n == 0 {
        return None;
    }
    let step = n.div_ceil(PRECISION_CPVS);
    let sampled: Vec<usize> = (0..n).step_by(step).collect();
    let real = sampled
        .par_iter()
        .filter(|&&i| {
            let seed = 0x9e37_79b9_7f4a_7c15 ^ i as u64;
            slowest_sampled_view(ctx, pv, &pv.cpvs[i], PRECISION_VIEWS, seed) > ctx.t_max
        })
        .count();
    Some((real as f64 / sampled.len() as f64, sampled.len() as u64))
}
