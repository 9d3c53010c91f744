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

/// A view direction of `cpv`'s VDI inside the pitch range, with its face
/// coordinates (`None` when `tries` draws found none).
fn sample_direction(
    ctx: &Context,
    cpv: &Cpv,
    rng: &mut Rng,
    tries: u32,
) -> Option<(DVec3, [f64; 2])> {
    let [u0, u1] = cpv.vdi.u_range();
    let [v0, v1] = cpv.vdi.v_range();
    (0..tries).find_map(|_| {
        let (u, v) = (rng.range(u0, u1), rng.range(v0, v1));
        let d = face_direction(cpv.vdi.face, u, v).normalize();
        ctx.in_pitch(d).then_some((d, [u, v]))
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
        if let Some((dir, _)) = sample_direction(ctx, cpv, &mut rng, 16) {
            worst = worst.max(exact_view_time(ctx, visible.as_deref(), eye, dir));
        }
    }
    worst
}

/// Moves of the local search in [`slowest_view_search`]: step sizes as
/// fractions of each coordinate's range, and moves per step size.
const SEARCH_STEPS: [f64; 2] = [0.25, 0.06];
const SEARCH_MOVES: usize = 2;

/// Searches `cpv` for its slowest exact view, stopping as soon as one is
/// slower than `stop_above`: the [`PRECISION_VIEWS`] uniform views of
/// [`slowest_sampled_view`] with the same seed, the extreme views (each
/// corner of the region looking along each corner direction of the VDI),
/// then a local search from the slowest of them (moves of the
/// eye along each axis and of the direction along each face coordinate,
/// with shrinking steps, while they find a slower view). A frame time
/// peaks where the view takes in most of the scene, which uniform samples
/// of a five-dimensional cell rarely hit. Returns the slowest time found.
pub fn slowest_view_search(
    ctx: &Context,
    pv: &ProblemViews,
    cpv: &Cpv,
    stop_above: f64,
    seed: u64,
) -> f64 {
    let kd = &pv.kd[cpv.kd as usize];
    let visible = ctx.visibility.and_then(|v| v.region(kd.lo, kd.hi));
    let (lo, hi) = (cpv.region.min, cpv.region.max);
    let ([u0, u1], [v0, v1]) = (cpv.vdi.u_range(), cpv.vdi.v_range());
    let low = [lo.x, lo.y, lo.z, u0, v0];
    let high = [hi.x, hi.y, hi.z, u1, v1];
    let time = |p: &[f64; 5]| -> Option<f64> {
        let d = face_direction(cpv.vdi.face, p[3], p[4]).normalize();
        ctx.in_pitch(d)
            .then(|| exact_view_time(ctx, visible.as_deref(), DVec3::new(p[0], p[1], p[2]), d))
    };
    let mut best: Option<(f64, [f64; 5])> = None;
    let consider = |p: [f64; 5], best: &mut Option<(f64, [f64; 5])>| {
        if let Some(t) = time(&p)
            && best.is_none_or(|b| t > b.0)
        {
            *best = Some((t, p));
        }
        best.is_some_and(|b| b.0 > stop_above)
    };
    // The uniform views of `slowest_sampled_view` with the same seed first,
    // so the search never finds less than they do.
    let mut rng = Rng::new(seed);
    for _ in 0..PRECISION_VIEWS {
        let eye = rng.in_box(lo, hi);
        if let Some((_, [u, v])) = sample_direction(ctx, cpv, &mut rng, 16)
            && consider([eye.x, eye.y, eye.z, u, v], &mut best)
        {
            return best.map_or(0.0, |b| b.0);
        }
    }
    for corner in 0..32u32 {
        let p: [f64; 5] = std::array::from_fn(|k| {
            if corner >> k & 1 == 1 {
                high[k]
            } else {
                low[k]
            }
        });
        if consider(p, &mut best) {
            return best.map_or(0.0, |b| b.0);
        }
    }
    let Some((_, mut at)) = best else {
        return 0.0;
    };
    for step in SEARCH_STEPS {
        for _ in 0..SEARCH_MOVES {
            let before = best.map_or(0.0, |b| b.0);
            for k in 0..5 {
                for sign in [-1.0, 1.0] {
                    let mut p = at;
                    p[k] = (p[k] + sign * step * (high[k] - low[k])).clamp(low[k], high[k]);
                    if consider(p, &mut best) {
                        return best.map_or(0.0, |b| b.0);
                    }
                }
            }
            let (t, p) = best.expect("a view was found");
            if t <= before {
                break;
            }
            at = p;
        }
    }
    best.map_or(0.0, |b| b.0)
}

/// The share of CPVs in which some exact view exceeds the target, over up
/// to [`PRECISION_CPVS`] CPVs spread evenly over the list, each searched
/// for its slowest view ([`slowest_view_search`]); `(precision, CPVs
/// sampled)`, `None` when there is no CPV. A search can miss a CPV's
/// slowest view, so this is a lower bound of the share of real problem
/// views. Once the run is cancelled the remaining CPVs are skipped (the
/// figure is then not reported).
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
            if ctx.cancelled() {
                return false;
            }
            let seed = 0x9e37_79b9_7f4a_7c15 ^ i as u64;
            slowest_view_search(ctx, pv, &pv.cpvs[i], ctx.t_max, seed) > ctx.t_max
        })
        .count();
    Some((real as f64 / sampled.len() as f64, sampled.len() as u64))
}
