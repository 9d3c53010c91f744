//! Problem view space approximation (paper §3, DESIGN §2.4).
//!
//! The 3D view space is a grid of cells no larger than `cell_size`, organised
//! as a binary kd tree that splits the axis with the most cells at its middle
//! cell boundary. Each kd region runs a direction subdivision: six cube faces,
//! each a quadtree of view-direction intervals (VDIs) split uniformly in
//! angle down to `min_vdi_deg`. A (region, VDI) whose enclosing-frustum time
//! `t_enc` is within `t_max` is proven; otherwise the VDI is split, and at the
//! minimum VDI size the region is split. A problem VDI of a minimum-size
//! region is a conservative problem view (CPV), unless refining its
//! directions (`refine_levels`) and halving its cell (`split_levels`) proves
//! every part of it; its region is then the box of the unproven parts (with
//! the whole cell's costs, conservative for its parts). Regions are processed in
//! parallel; results are collected in kd order, so the output does not depend
//! on the thread count.

mod approximate;
mod context;
mod costs;
mod precision;

#[cfg(test)]
use approximate::approximate_near;
pub use approximate::{approximate, restrict};
pub use context::{Context, Counters};
pub use costs::{
    CellCuts, CpvCut, Listable, RegionCosts, cpv_clusters, cpv_cut, enclosed_cost, enclosing_time,
    exceeds_target,
};
pub use precision::{cpv_precision, exact_view_time, slowest_sampled_view, slowest_view_search};

use crate::math::geom::{Aabb, Vdi};
use crate::math::grid::Grid;
use crate::model::cost::Cost;

/// A node of the 3D view space hierarchy (pre-order ids, root 0).
#[derive(Clone, Debug)]
pub struct KdNode {
    /// First cell per axis.
    pub lo: [u32; 3],
    /// One past the last cell per axis.
    pub hi: [u32; 3],
    /// The region.
    pub aabb: Aabb,
    /// Children, `None` for a single cell.
    pub children: Option<[u32; 2]>,
    /// Parent (`u32::MAX` for the root).
    pub parent: u32,
}

/// A conservative problem view: a region inside a minimum-size cell and a
/// minimum-size VDI whose enclosing-frustum time exceeds `t_max`.
#[derive(Clone, Debug)]
pub struct Cpv {
    /// The kd leaf (cell) of the region.
    pub kd: u32,
    /// The 3D region: the cell, or (with `problem_views.split_levels`) the
    /// smallest box holding the parts of it where some view of the cell's
    /// CPVs may exceed the target; every CPV of a cell has the same region.
    /// Views of the cell outside it are proven within the target.
    pub region: Aabb,
    /// The view-direction interval.
    pub vdi: Vdi,
    /// Cost of the objects in the enclosing frustum.
    pub cost: Cost,
    /// Estimated frame time `t_enc`, ms.
    pub time: f64,
    /// How many clusters may become impostors here: they meet the enclosing
    /// frustum, do not meet the region, and a one-layer impostor of them
    /// would be cheaper than their objects in the frustum
    /// ([`cpv_clusters`] lists them, [`cpv_cut`] as the hierarchy's cut).
    pub listed: u32,
}

/// How often one cluster is listed by CPVs (see [`Cpv::listed`]), and what
/// the pairs hold of it ([`crate::candidates::Pairs`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairCounts {
    /// CPVs that list the cluster: its (CPV, cluster) pairs.
    pub pairs: u32,
    /// Of those, the pairs listed one by one: the enclosing set holds the
    /// cluster in part ([`CpvCut::explicit`]); the others lie below a node
    /// of the CPV's cut.
    pub explicit: u32,
    /// Of the explicit pairs, those whose cost differs from the cluster's
    /// whole cost in the CPV's cell: their costs are stored, the others
    /// derive from the cell's.
    pub partial: u32,
    /// Cells with a CPV listing the cluster (its groups).
    pub cells: u32,
    /// 64-bit words of its groups' sets of CPVs that list it below a cut
    /// node ([`CpvCut::cuts`]).
    pub bit_words: u32,
}

impl std::ops::AddAssign for PairCounts {
    fn add_assign(&mut self, o: PairCounts) {
        self.pairs += o.pairs;
        self.explicit += o.explicit;
        self.partial += o.partial;
        self.cells += o.cells;
        self.bit_words += o.bit_words;
    }
}

/// The totals of [`PairCounts`] over every cluster, as 64-bit sums.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairTotals {
    /// Pairs.
    pub pairs: u64,
    /// Explicit pairs.
    pub explicit: u64,
    /// Pairs whose cost is stored.
    pub partial: u64,
    /// Groups.
    pub cells: u64,
    /// Words of the groups' CPV sets below cut nodes.
    pub bit_words: u64,
}

impl PairCounts {
    /// The totals over every cluster of `counts`.
    pub fn totals(counts: &[PairCounts]) -> PairTotals {
        counts
            .iter()
            .fold(PairTotals::default(), |t, n| PairTotals {
                pairs: t.pairs + u64::from(n.pairs),
                explicit: t.explicit + u64::from(n.explicit),
                partial: t.partial + u64::from(n.partial),
                cells: t.cells + u64::from(n.cells),
                bit_words: t.bit_words + u64::from(n.bit_words),
            })
    }
}

/// The result of the approximation.
#[derive(Clone, Debug)]
pub struct ProblemViews {
    /// The cell grid.
    pub grid: Grid,
    /// The 3D view space hierarchy.
    pub kd: Vec<KdNode>,
    /// The CPVs, in kd order (each kd node's CPVs are contiguous).
    pub cpvs: Vec<Cpv>,
    /// Per cluster (node id): how many CPVs list it, in how many cells,
    /// and how many of those pairs need their own cost.
    pub node_counts: Vec<PairCounts>,
    /// Quadtree level of minimum-size VDIs.
    pub leaf_level: u8,
    /// Enclosing frusta evaluated (a work counter for statistics).
    pub cone_evaluations: u64,
    /// kd regions visited.
    pub regions_visited: u64,
    /// Problem views of minimum size that refinement proved within the
    /// target (not CPVs).
    pub refined_away: u64,
}

impl ProblemViews {
    /// The cells with CPVs, as ranges of CPV ids (a cell's CPVs are
    /// contiguous), in kd order.
    pub fn cells(&self) -> Vec<crate::math::IdRange> {
        Self::cells_of(&self.cpvs)
    }

    /// [`Self::cells`] of a list of CPVs in kd order.
    pub fn cells_of(cpvs: &[Cpv]) -> Vec<crate::math::IdRange> {
        let mut cells: Vec<crate::math::IdRange> = Vec::new();
        for (i, c) in cpvs.iter().enumerate() {
            match cells.last_mut() {
                Some(r) if cpvs[r.start as usize].kd == c.kd => r.end = i as u32 + 1,
                _ => cells.push(crate::math::IdRange::new(i as u32, i as u32 + 1)),
            }
        }
        cells
    }
}

/// Quadtree level whose VDIs span at most `min_vdi_deg` (a face spans 90°).
pub fn leaf_level(min_vdi_deg: f64) -> u8 {
    let mut l = 0u8;
    while 90.0 / f64::from(1u32 << l) > min_vdi_deg * (1.0 + 1e-9) {
        l += 1;
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::job::Job;
    use crate::control::Control;
    use crate::math::enclosing::{Lens, enclosing_cone};
    use crate::math::geom::{ViewFrustum, face_direction};
    use crate::math::rng::Rng;
    use crate::scene::Object;
    use crate::scene::Scene;
    use crate::scene::hierarchy::Hierarchy;
    use glam::DVec3;

    /// Property: every object hit by an exact view frustum at a sampled
    /// position and direction of (region, VDI) is in the enclosing set.
    #[test]
    fn enclosing_frustum_contains_every_exact_frustum() {
        let mut rng = Rng::new(11);
        for case in 0..300 {
            let lo = rng.in_box(DVec3::splat(-50.0), DVec3::splat(50.0));
            let ext = DVec3::new(
                rng.range(0.0, 30.0),
                rng.range(0.0, 10.0),
                rng.range(0.0, 30.0),
            );
            let region = Aabb::new(lo, lo + ext);
            let level = (rng.next_u64() % 5) as u8;
            let n = 1u32 << level;
            let vdi = Vdi {
                face: (rng.next_u64() % 6) as u8,
                level,
                iu: (rng.next_u64() % u64::from(n)) as u32,
                iv: (rng.next_u64() % u64::from(n)) as u32,
            };
            let fov = [30.0, 45.0, 60.0, 90.0][case % 4];
            let aspect = [1.0, 1.5, 0.75, 16.0 / 9.0, 2.4][case % 5];
            let cone = enclosing_cone(
                &region,
                &vdi,
                &Lens {
                    fov_deg: fov,
                    aspect,
                },
            );
            let [u0, u1] = vdi.u_range();
            let [v0, v1] = vdi.v_range();
            for k in 0..28 {
                // The first views take the region's and the VDI's corners,
                // where the enclosing set is tightest.
                let (eye, dir) = if k < 8 {
                    let corner = region.corners()[k];
                    let (u, v) = ([u0, u1][k % 2], [v0, v1][(k / 2) % 2]);
                    (corner, face_direction(vdi.face, u, v))
                } else {
                    let eye = rng.in_box(region.min, region.max);
                    (
                        eye,
                        face_direction(vdi.face, rng.range(u0, u1), rng.range(v0, v1)),
                    )
                };
                let f = ViewFrustum::new(eye, dir, fov, aspect);
                // Small spheres just inside the frustum's edges and sides.
                let (right, up, fwd) = f.basis();
                let tv = (fov.to_radians() * 0.5).tan() * (1.0 - 1e-6);
                let th = tv * aspect;
                for _ in 0..50 {
                    let (a, b) = match rng.next_u64() % 3 {
                        0 => (
                            [-th, th][rng.next_u64() as usize % 2],
                            [-tv, tv][rng.next_u64() as usize % 2],
                        ),
                        1 => ([-th, th][rng.next_u64() as usize % 2], rng.range(-tv, tv)),
                        _ => (rng.range(-th, th), [-tv, tv][rng.next_u64() as usize % 2]),
                    };
                    let p = eye + (fwd + right * a + up * b) * rng.range(0.1, 200.0);
                    assert!(
                        cone.intersects_sphere(p, 1e-6),
                        "case {case}: edge point {p} seen from {eye} dir {dir}"
                    );
                }
                for _ in 0..50 {
                    let c = rng.in_box(DVec3::splat(-300.0), DVec3::splat(300.0));
                    let r = rng.range(0.0, 20.0);
                    if f.intersects_sphere(c, r) {
                        assert!(
                            cone.intersects_sphere(c, r),
                            "case {case}: sphere {c} r {r} seen from {eye} dir {dir}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn grid_cells_are_at_most_cell_size_and_partition() {
        let mut job = Job::with_view_space([0.0, 1.5, 0.0], [1500.0, 2.0, 1000.0]);
        job.problem_views.cell_size = 23.0;
        let g = job.grid();
        assert_eq!(g.counts, [66, 1, 44]);
        let b = g.cell_box([65, 0, 43], [66, 1, 44]);
        assert_eq!(b.max, DVec3::new(1500.0, 2.0, 1000.0));
        assert_eq!(
            g.cell_of(DVec3::new(1500.0, 2.0, 1000.0)),
            Some([65, 0, 43])
        );
        let x = g.boundary(0, 10);
        assert_eq!(g.cell_of(DVec3::new(x, 1.7, 0.0)).unwrap()[0], 10);
        assert_eq!(g.cell_of(DVec3::new(x - 1e-9, 1.7, 0.0)).unwrap()[0], 9);
        assert!(g.cell_of(DVec3::new(-1.0, 1.7, 0.0)).is_none());
        assert_eq!(leaf_level(11.25), 3);
        assert_eq!(leaf_level(90.0), 0);
        assert_eq!(leaf_level(10.0), 4);
    }

    #[test]
    fn cpv_regions_are_cells_and_times_exceed_target() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = approximate(&ctx, &job, &Counters::new());
        assert!(
            !pv.cpvs.is_empty(),
            "the synthetic job must have problem views"
        );
        for c in &pv.cpvs {
            assert!(c.time > job.target_frame_time_ms);
            assert!(pv.kd[c.kd as usize].children.is_none());
            let ext = c.region.max - c.region.min;
            assert!(ext.max_element() <= job.problem_views.cell_size + 1e-9);
            // The recorded time equals a fresh enclosing estimate.
            assert_eq!(c.time, enclosing_time(&ctx, &c.region, &c.vdi));
        }
        // Views with no problem: a far object set with a tiny cost.
        let tiny = Scene {
            objects: vec![Object {
                name: "x".into(),
                min: DVec3::splat(500.0),
                max: DVec3::splat(501.0),
                triangles: 1,
                draw_calls: 1,
                lods: Vec::new(),
            }],
        };
        let h2 = Hierarchy::build(&tiny);
        let ctx2 = Context::new(&tiny, &h2, None, &job, Control::default());
        assert!(approximate(&ctx2, &job, &Counters::new()).cpvs.is_empty());
    }

    /// Refinement only drops problem views, and every one it drops is
    /// within the target in sampled exact views; without refinement the
    /// same job keeps problem views no sampled view confirms (so the test
    /// could fail), and the precision counts them.
    #[test]
    fn refinement_drops_only_views_within_the_target() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let mut job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        job.problem_views.refine_levels = 0;
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let coarse = approximate(&ctx, &job, &Counters::new());
        job.problem_views.refine_levels = 3;
        let fine = approximate(&ctx, &job, &Counters::new());
        assert_eq!(coarse.refined_away, 0);
        assert_eq!(
            coarse.cpvs.len() as u64,
            fine.cpvs.len() as u64 + fine.refined_away
        );
        assert!(fine.refined_away > 0, "refinement proved nothing");
        let kept: std::collections::HashSet<(u32, Vdi)> =
            fine.cpvs.iter().map(|c| (c.kd, c.vdi)).collect();
        let mut dropped = 0;
        for (i, c) in coarse.cpvs.iter().enumerate() {
            if kept.contains(&(c.kd, c.vdi)) {
                continue;
            }
            dropped += 1;
            let worst = slowest_view_search(&ctx, &coarse, c, f64::INFINITY, i as u64);
            assert!(
                worst <= job.target_frame_time_ms,
                "a dropped problem view has an exact view of {worst} ms"
            );
        }
        assert_eq!(dropped, fine.refined_away);
        let (p_coarse, _) = cpv_precision(&ctx, &coarse).unwrap();
        let (p_fine, _) = cpv_precision(&ctx, &fine).unwrap();
        assert!(
            p_coarse < 1.0,
            "every coarse CPV is real: nothing to refine"
        );
        assert!(p_fine >= p_coarse, "{p_fine} < {p_coarse}");
    }

    /// A problem view whose estimate is at most `near_target` above the
    /// target is refined one level deeper than `refine_levels`, and only
    /// such a one: each minimum-size problem view is kept exactly where the
    /// same job without the rule keeps it at the view's own level
    /// (`refine_levels` + 1 near the target, `refine_levels` otherwise),
    /// and the deeper level proves near views the shallower one keeps (so
    /// the comparison could fail).
    #[test]
    fn problem_views_near_the_target_are_refined_one_level_deeper() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let mut job = crate::testutil::synthetic_job(6, 6);
        job.problem_views.split_levels = 0;
        job.problem_views.refine_levels = 0;
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let all = approximate(&ctx, &job, &Counters::new());
        let kept = |refine: u8, near: f64| -> std::collections::HashSet<(u32, Vdi)> {
            let mut j = job.clone();
            j.problem_views.refine_levels = refine;
            approximate_near(&ctx, &j, &Counters::new(), near)
                .cpvs
                .iter()
                .map(|c| (c.kd, c.vdi))
                .collect()
        };
        let near = 0.2;
        let rule = kept(1, near);
        let shallow = kept(1, 0.0);
        let deep = kept(2, 0.0);
        let (mut near_views, mut far_views, mut proven_deeper) = (0, 0, 0);
        for c in &all.cpvs {
            let key = (c.kd, c.vdi);
            let is_near = c.time <= job.target_frame_time_ms * (1.0 + near);
            let expected = if is_near {
                deep.contains(&key)
            } else {
                shallow.contains(&key)
            };
            assert_eq!(
                rule.contains(&key),
                expected,
                "{key:?}: estimate {} ms, target {} ms",
                c.time,
                job.target_frame_time_ms
            );
            near_views += usize::from(is_near);
            far_views += usize::from(!is_near);
            proven_deeper += usize::from(is_near && shallow.contains(&key) && !deep.contains(&key));
        }
        assert!(
            near_views > 0 && far_views > 0,
            "{near_views} near, {far_views} far"
        );
        assert!(proven_deeper > 0, "the deeper level proved nothing more");
    }

    /// Halving problem cells only drops problem views and shrinks regions
    /// where no view exceeds the target: the CPVs of a cell share one region
    /// inside the cell; every quarter (in x and z) of a cell that the region
    /// leaves out holds no sampled exact view over the target (searched for
    /// its slowest view), while the regions themselves do hold such views
    /// (so the search could have failed).
    #[test]
    fn split_regions_leave_out_only_views_within_the_target() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let mut job = crate::testutil::synthetic_job(6, 6);
        // A target where some cells hold problems in part of them only.
        job.target_frame_time_ms = 8.0;
        let h = Hierarchy::build(&scene);
        job.problem_views.split_levels = 0;
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let whole = approximate(&ctx, &job, &Counters::new());
        job.problem_views.split_levels = 2;
        let split = approximate(&ctx, &job, &Counters::new());
        let before: std::collections::HashSet<(u32, Vdi)> =
            whole.cpvs.iter().map(|c| (c.kd, c.vdi)).collect();
        assert!(
            split.cpvs.len() < whole.cpvs.len(),
            "splitting dropped nothing"
        );
        assert!(split.cpvs.iter().all(|c| before.contains(&(c.kd, c.vdi))));
        let mut shrunk = 0;
        let mut real = 0;
        let mut cells: std::collections::HashMap<u32, Aabb> = Default::default();
        for (i, c) in split.cpvs.iter().enumerate() {
            let cell = split.kd[c.kd as usize].aabb;
            assert!(cell.contains_box(&c.region), "{c:?}");
            assert_eq!(*cells.entry(c.kd).or_insert(c.region), c.region);
            if i % 4 == 0 {
                let worst =
                    slowest_view_search(&ctx, &split, c, job.target_frame_time_ms, i as u64);
                real += usize::from(worst > job.target_frame_time_ms);
            }
            if c.region == cell {
                continue;
            }
            shrunk += 1;
            let (lo, hi) = (cell.min, cell.max);
            for (x, z) in (0..4).flat_map(|x| (0..4).map(move |z| (x, z))) {
                let at = |a: f64, b: f64, k: u32| a + (b - a) * f64::from(k) / 4.0;
                let quarter = Aabb::new(
                    DVec3::new(at(lo.x, hi.x, x), lo.y, at(lo.z, hi.z, z)),
                    DVec3::new(at(lo.x, hi.x, x + 1), hi.y, at(lo.z, hi.z, z + 1)),
                );
                let c2 = &c.region;
                let overlaps = (0..3).all(|a| {
                    quarter.min[a] < c2.max[a] && c2.min[a] < quarter.max[a]
                        || quarter.min[a] == quarter.max[a]
                });
                if overlaps {
                    continue;
                }
                let left_out = Cpv {
                    region: quarter,
                    ..c.clone()
                };
                let worst = slowest_view_search(&ctx, &split, &left_out, f64::INFINITY, i as u64);
                assert!(
                    worst <= job.target_frame_time_ms,
                    "CPV {i}: {worst} ms in {quarter:?}, outside its region {:?}",
                    c.region
                );
            }
        }
        assert!(shrunk > 0, "no region was smaller than its cell");
        assert!(real > 0, "no region holds a view over the target");
    }

    /// The search for a CPV's slowest view finds at least what uniform
    /// samples find, never more than the conservative estimate, and in some
    /// CPVs a slower view than the samples.
    #[test]
    fn search_finds_slower_views_than_samples() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let mut job = crate::testutil::synthetic_job(6, 6);
        job.problem_views.refine_levels = 0;
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = approximate(&ctx, &job, &Counters::new());
        assert!(pv.cpvs.len() > 20);
        let mut slower = 0;
        for (i, c) in pv.cpvs.iter().enumerate().step_by(3) {
            let sampled = slowest_sampled_view(&ctx, &pv, c, precision::PRECISION_VIEWS, i as u64);
            let searched = slowest_view_search(&ctx, &pv, c, f64::INFINITY, i as u64);
            assert!(sampled <= searched, "CPV {i}: {searched} < {sampled}");
            assert!(
                searched <= c.time + 1e-9,
                "CPV {i}: {searched} above its estimate {}",
                c.time
            );
            slower += usize::from(searched > sampled + 1e-6);
        }
        assert!(slower > 0, "the search never beat the samples");
    }

    /// The precision is 0 when no view can exceed the target and 1 when
    /// every view does.
    #[test]
    fn precision_counts_confirmed_problem_views() {
        let scene = crate::testutil::synthetic_city(5, 6, 6);
        let mut job = crate::testutil::synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        // Every view takes at least frame_ms: a target below it makes
        // every (region, direction) a real problem view.
        job.target_frame_time_ms = job.cost_model.frame_ms * 0.5;
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let all = approximate(&ctx, &job, &Counters::new());
        assert_eq!(cpv_precision(&ctx, &all).unwrap().0, 1.0);
        // The same problem views judged against a target no exact view
        // reaches.
        let mut loose = job.clone();
        loose.target_frame_time_ms = 1e6;
        let ctx2 = Context::new(&scene, &h, None, &loose, Control::default());
        assert_eq!(cpv_precision(&ctx2, &all).unwrap().0, 0.0);
        assert!(cpv_precision(&ctx2, &approximate(&ctx2, &loose, &Counters::new())).is_none());
    }
}
