//! `dts96`: far-field textures around each view cell (Aliaga 1996,
//! automated as the "common viewpoint and constant distance" variant of its
//! §4): the view space is cut into cells of `dts96.cell_m`, and in each cell
//! that holds problem views everything visible entirely beyond a distance
//! `d` becomes one screen-parallel texture per cube face, seen from the
//! cell's centre; nearer objects, and those that straddle `d`, stay
//! geometry. `d` is the largest of a ladder of distances (from beyond the
//! scene down to twice the cell's half-diagonal, each 0.8 of the one
//! before) at which every problem view of the cell meets the target; where
//! none does, the one whose slowest problem view is fastest (those views
//! stay unsolved). Cells without problem views get no texture.
//!
//! The paper places its textures by hand and bounds no error ("the error
//! introduced is proportional to the viewpoint's distance from the original
//! texture sample point"): one layer per face, whose parallax `evaluate`
//! reports like any other impostor's. Memory uses the texel model of every
//! other method.

use rayon::prelude::*;

use crate::api::job::Job;
use crate::math::geom::Aabb;
use crate::methods::env_map::{
    CellMaps, EnvMapPlacement, block, cell_maps, collect, cpv_blocks, cpv_cost, tiles,
};
use crate::views::{Context, Counters, ProblemViews};
use crate::visibility::ObjectSet;

/// Each distance of the ladder is this fraction of the one before.
pub const LADDER_RATIO: f64 = 0.8;

/// The far distances tried for a cell: from the farthest point of `scene`
/// seen from the cell's centre down to twice the cell's half-diagonal (the
/// texture planes stay in front of every viewpoint of the cell), each
/// [`LADDER_RATIO`] of the one before, descending.
pub fn ladder(cell: &Aabb, scene: &Aabb) -> Vec<f64> {
    let near = 2.0 * cell.half_diagonal();
    let far = scene.max_distance_to_point(cell.center());
    let mut out = Vec::new();
    let mut d = far;
    while d > near && out.len() < 256 {
        out.push(d);
        d *= LADDER_RATIO;
    }
    out.push(near.min(far.max(near)));
    out
}

/// The textures of one cell whose CPVs (ids) are `cpvs`, and the chosen
/// far distance (`None`: no CPV, no texture).
fn cell_textures(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    (aabb, visible): (Aabb, Option<&ObjectSet>),
    cpvs: &[u32],
    scene: &Aabb,
) -> (CellMaps, Option<f64>) {
    if cpvs.is_empty() {
        let none = CellMaps {
            impostors: Vec::new(),
            aabb,
        };
        return (none, None);
    }
    // Trials count their levels of detail apart: only the chosen maps'
    // costs are the placement's (computed again by `collect`).
    let trial = Counters::new();
    let mut best: Option<(f64, CellMaps, f64)> = None;
    let mut last_objects = usize::MAX;
    for d in ladder(&aabb, scene) {
        let maps = cell_maps(ctx, job, aabb, visible, d, false);
        let objects: usize = maps.impostors.iter().map(|i| i.0.len()).sum();
        if objects == 0 || objects == last_objects {
            // Nothing beyond `d`, or the same objects as the distance
            // before (whose maps were no worse: nearer planes only add).
            continue;
        }
        last_objects = objects;
        let worst = cpvs
            .iter()
            .map(|&c| {
                let cost = cpv_cost(
                    ctx,
                    pv,
                    &pv.cpvs[c as usize],
                    maps.impostors.iter().map(|i| (&i.0[..], i.1, 1)),
                    &trial,
                );
                ctx.model.frame_time(cost)
            })
            .fold(0.0f64, f64::max);
        if worst <= job.target_frame_time_ms {
            return (maps, Some(d));
        }
        if best.as_ref().is_none_or(|b| worst < b.0) {
            best = Some((worst, maps, d));
        }
    }
    match best {
        Some((_, maps, d)) => (maps, Some(d)),
        None => (
            CellMaps {
                impostors: Vec::new(),
                aabb,
            },
            None,
        ),
    }
}

/// The `dts96` placement, and per cell the far distance chosen (`None`:
/// no texture).
pub fn place(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    counters: &Counters,
) -> (EnvMapPlacement, Vec<Option<f64>>) {
    let k = block(job.dts96.cell_m, pv);
    let tiles = tiles(pv, k);
    let blocks = cpv_blocks(pv, k);
    let mut per_block: Vec<Vec<u32>> = vec![Vec::new(); tiles.len()];
    for (c, &b) in blocks.iter().enumerate() {
        per_block[b].push(c as u32);
    }
    let root = &ctx.hierarchy.nodes[0].aabb;
    let chosen: Vec<(CellMaps, Option<f64>)> = tiles
        .par_iter()
        .zip(&per_block)
        .map(|(&(lo, hi), cpvs)| {
            let aabb = pv.grid.cell_box(lo, hi);
            let visible = if cpvs.is_empty() {
                None
            } else {
                ctx.visibility.and_then(|v| v.region(lo, hi))
            };
            cell_textures(ctx, job, pv, (aabb, visible.as_deref()), cpvs, root)
        })
        .collect();
    let (maps, far): (Vec<CellMaps>, Vec<Option<f64>>) = chosen.into_iter().unzip();
    (collect(ctx, pv, &maps, &blocks, counters), far)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Control;
    use crate::scene::hierarchy::Hierarchy;
    use crate::testutil::{synthetic_city, synthetic_job};
    use crate::views;
    use glam::DVec3;

    /// Per cell, the chosen distance is the largest of the ladder at which
    /// all its problem views meet the target: at every larger distance
    /// (that changes what is textured) one of them does not. Cells without
    /// problem views get no texture, and every CPV is charged its own
    /// cell's textures.
    #[test]
    fn each_cell_takes_the_largest_distance_that_meets_the_target() {
        let scene = synthetic_city(3, 5, 5);
        for target in [0.0, 1.0] {
            let mut job = synthetic_job(5, 5);
            job.dts96.cell_m = 40.0;
            let h = Hierarchy::build(&scene);
            let ctx = Context::new(&scene, &h, None, &job, Control::default());
            let pv = views::approximate(&ctx, &job, &Counters::new());
            assert!(!pv.cpvs.is_empty());
            // A target between the CPVs' times (the job's) or below all
            // of them (nothing meets it: the best distance is kept).
            let job = Job {
                target_frame_time_ms: if target == 0.0 {
                    job.target_frame_time_ms
                } else {
                    0.001
                },
                ..job
            };
            let (em, far) = place(&ctx, &job, &pv, &Counters::new());
            let k = block(job.dts96.cell_m, &pv);
            let tiles = tiles(&pv, k);
            let blocks = cpv_blocks(&pv, k);
            let root = ctx.hierarchy.nodes[0].aabb;
            let mut textured = 0;
            for (b, &(lo, hi)) in tiles.iter().enumerate() {
                let cpvs: Vec<u32> = (0..pv.cpvs.len() as u32)
                    .filter(|&c| blocks[c as usize] == b)
                    .collect();
                let Some(d) = far[b] else {
                    assert!(cpvs.is_empty() || target == 1.0);
                    continue;
                };
                assert!(!cpvs.is_empty());
                textured += 1;
                let aabb = pv.grid.cell_box(lo, hi);
                let visible = ctx.visibility.and_then(|v| v.region(lo, hi));
                let worst = |d: f64| {
                    let maps = cell_maps(&ctx, &job, aabb, visible.as_deref(), d, false);
                    let objects: Vec<u32> =
                        maps.impostors.iter().flat_map(|i| i.0.clone()).collect();
                    let t = cpvs
                        .iter()
                        .map(|&c| {
                            let cost = cpv_cost(
                                &ctx,
                                &pv,
                                &pv.cpvs[c as usize],
                                maps.impostors.iter().map(|i| (&i.0[..], i.1, 1)),
                                &Counters::new(),
                            );
                            ctx.model.frame_time(cost)
                        })
                        .fold(0.0f64, f64::max);
                    (t, objects)
                };
                let (at_d, objects_d) = worst(d);
                for e in ladder(&aabb, &root).into_iter().filter(|&e| e > d) {
                    let (at_e, objects_e) = worst(e);
                    if objects_e.is_empty() || objects_e == objects_d {
                        continue;
                    }
                    if target == 0.0 {
                        assert!(at_d <= job.target_frame_time_ms);
                        assert!(at_e > job.target_frame_time_ms, "{e} > {d} also meets it");
                    } else {
                        assert!(at_e >= at_d, "{e}: {at_e} ms, better than {d}: {at_d} ms");
                    }
                }
                // Its CPVs are charged with its textures.
                for &c in &cpvs {
                    let ids = &em.cpv_impostors[c as usize];
                    assert_eq!(
                        ids.iter()
                            .map(|&i| em.impostors[i as usize].objects.len())
                            .sum::<usize>(),
                        objects_d.len()
                    );
                }
            }
            assert!(textured > 0);
        }
    }

    #[test]
    fn ladder_descends_by_its_ratio_to_twice_the_half_diagonal() {
        let cell = Aabb::new(DVec3::ZERO, DVec3::splat(10.0));
        let scene = Aabb::new(DVec3::splat(-100.0), DVec3::splat(100.0));
        let l = ladder(&cell, &scene);
        // Farthest scene corner from (5, 5, 5): (-100, -100, -100).
        let far = (3.0f64 * 105.0 * 105.0).sqrt();
        assert!((l[0] - far).abs() < 1e-9, "{l:?}");
        for w in l.windows(2).take(l.len() - 2) {
            assert!((w[1] / w[0] - LADDER_RATIO).abs() < 1e-12, "{l:?}");
        }
        let near = 2.0 * cell.half_diagonal();
        assert!((l.last().unwrap() - near).abs() < 1e-9);
        assert!(l[l.len() - 2] > near && l[l.len() - 2] * LADDER_RATIO <= near);
        // A cell larger than the scene: the one distance that keeps the
        // planes in front of it.
        let big = Aabb::new(DVec3::splat(-1000.0), DVec3::splat(1000.0));
        assert_eq!(ladder(&big, &scene), vec![2.0 * big.half_diagonal()]);
    }
}
