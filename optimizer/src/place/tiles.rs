//! Tiled placement (`"partition": {"tiles": [nx, nz]}`): the view space
//! split along x and z at grid boundaries into tiles, each placed as a job
//! of its own (its problem views, candidates and greedy; candidates' view
//! cells may reach beyond it), and the placements merged. Tiles share the
//! job's grid (boundaries are anchored planes), so their cells, hence their
//! CPVs, partition the job's; an impostor chosen by two tiles (same
//! cluster, view cell, layers and resolution) is stored once.

use std::collections::HashMap;

use crate::api::job::Job;
use crate::api::placement::{Placement, Summary};
use crate::api::stats::{StageTime, Stats, TileStats};
use crate::control::{Control, Event, Observer};
use crate::input::Prepared;
use crate::math::gaps;
use crate::place::{PlaceOptions, PlaceOutput};
use crate::views::ProblemViews;
use crate::{Error, Result};

/// The tiles' view spaces: `[nx, nz]` tiles (at most one per grid cell
/// along an axis) with boundaries on the job's grid, x-major.
pub fn tile_jobs(job: &Job, tiles: [u32; 2]) -> Vec<Job> {
    let grid = job.grid();
    let cuts = |axis: usize, n: u32| -> Vec<f64> {
        let cells = grid.counts[axis];
        let n = n.clamp(1, cells);
        (0..=n)
            .map(|k| {
                grid.boundary(
                    axis,
                    (u64::from(k) * u64::from(cells) / u64::from(n)) as u32,
                )
            })
            .collect()
    };
    let (xs, zs) = (cuts(0, tiles[0]), cuts(2, tiles[1]));
    let mut out = Vec::new();
    for x in xs.windows(2) {
        for z in zs.windows(2) {
            let mut t = job.clone();
            t.partition = None;
            t.view_space.min[0] = x[0];
            t.view_space.max[0] = x[1];
            t.view_space.min[2] = z[0];
            t.view_space.max[2] = z[1];
            out.push(t);
        }
    }
    out
}

impl Prepared<'_> {
    /// [`Prepared::place`] tile by tile, merged (see the module docs); with
    /// `whole`, the job's problem views, each tile takes its own from them
    /// and may be split again for memory; without (the job's `partition`),
    /// the tiles are the job's choice and a tile above the limit is refused.
    pub(crate) fn place_tiled(
        &self,
        tiles: [u32; 2],
        opts: &PlaceOptions,
        ctl: &Control,
        whole: Option<&ProblemViews>,
    ) -> Result<PlaceOutput> {
        let jobs = tile_jobs(self.job(), tiles);
        let n = jobs.len() as f64;
        // Progress from here on (the whole's problem views, when given, came
        // first); a tile's run reports within its share.
        let from = if whole.is_some() { 0.05 } else { 0.0 };
        let mut outs = Vec::with_capacity(jobs.len());
        for (k, t) in jobs.iter().enumerate() {
            ctl.check()?;
            let share = |f: f64| from + (1.0 - from) * (k as f64 + f) / n;
            let tile = format!("tile {} of {}", k + 1, jobs.len());
            ctl.progress("tiles", share(0.0), &tile);
            let outer = *ctl;
            let observe = |e: Event<'_>| match e {
                Event::Progress {
                    stage,
                    fraction,
                    message,
                } => outer.progress(stage, share(fraction), &format!("{tile}: {message}")),
                Event::StageDone { stage, seconds } => outer.stage_done(stage, seconds),
            };
            let inner = Control {
                cancel: ctl.cancel,
                observer: ctl.observer.is_some().then_some(&observe as Observer),
            };
            let name = format!("{} (tile {})", self.job_name(), k + 1);
            let out = self.input().prepare(t, &name)?.place_within(
                opts,
                &inner,
                whole,
                whole.is_some(),
            )?;
            // Held packed until the merge: a finished tile's CPV lists
            // would otherwise add to every later tile's peak.
            outs.push((t, out.stats, Packed::pack(out.placement)));
            // The next tile's memory check reads what the process holds.
            crate::place::release_memory();
        }
        let mut stats = Stats::default();
        for (t, o, p) in &outs {
            let summary = &p.placement.summary;
            stats.add_tile(o);
            stats.tiles.push(TileStats {
                min: t.view_space.min,
                max: t.view_space.max,
                cpvs: summary.cpvs,
                impostors: summary.impostors,
                memory_bytes: summary.memory_bytes,
                seconds: o.seconds.iter().map(|s| s.seconds).sum(),
                peak_rss_bytes: o.peak_rss_bytes,
            });
        }
        stats.seconds.retain(|s| s.seconds > 0.0);
        let placement = merge(self.job(), outs.into_iter().map(|(_, _, p)| p.unpack()))?;
        stats.impostors = placement.summary.impostors;
        stats.memory_bytes = placement.summary.memory_bytes;
        stats.unsolved_cpvs = placement.summary.unsolved_cpvs;
        Ok(PlaceOutput { placement, stats })
    }
}

/// A placement whose CPVs' impostor lists are packed into one buffer, each
/// sorted and written as the gaps between its ids, seven bits a byte
/// (LEB128, [`gaps`]): about a byte an id where a CPV draws many of the tile's
/// impostors, instead of four. [`merge`] sorts the lists anyway.
struct Packed {
    /// The placement with every CPV's list emptied.
    placement: Placement,
    lists: Vec<u8>,
    /// Where each CPV's list ends in `lists`.
    ends: Vec<usize>,
}

impl Packed {
    fn pack(mut placement: Placement) -> Packed {
        let mut lists = Vec::new();
        let mut ends = Vec::with_capacity(placement.cpvs.len());
        for c in &mut placement.cpvs {
            let mut ids = std::mem::take(&mut c.impostors);
            ids.sort_unstable();
            gaps::push(&mut lists, ids);
            ends.push(lists.len());
        }
        lists.shrink_to_fit();
        Packed {
            placement,
            lists,
            ends,
        }
    }

    fn unpack(self) -> Placement {
        let Packed {
            mut placement,
            lists,
            ends,
        } = self;
        let mut start = 0;
        for (c, end) in placement.cpvs.iter_mut().zip(ends) {
            c.impostors.extend(gaps::read(&lists[start..end]));
            start = end;
        }
        placement
    }
}

/// The placements of a job's tiles as one: CPVs in tile order, impostors in
/// order of first use, each distinct one once. The parts are moved, not
/// copied: on a large job their CPVs' impostor lists are most of what the
/// run holds at its end.
pub fn merge(job: &Job, parts: impl IntoIterator<Item = Placement>) -> Result<Placement> {
    let mut impostors = Vec::new();
    let mut cpvs = Vec::new();
    let mut seen: HashMap<String, u32> = HashMap::new();
    let mut summary = Summary {
        cpvs: 0,
        candidates: 0,
        impostors: 0,
        memory_bytes: 0,
        unsolved_cpvs: 0,
        target_frame_time_ms: job.target_frame_time_ms,
        max_residual_ms: 0.0,
        unsolved_by_reason: Default::default(),
        budget_bytes: None,
    };
    for p in parts {
        let mut ids = Vec::with_capacity(p.impostors.len());
        for mut imp in p.impostors {
            imp.id = 0;
            let key = serde_json::to_string(&imp)
                .map_err(|e| Error::Internal(format!("an impostor's key: {e}")))?;
            let next = impostors.len() as u32;
            let id = *seen.entry(key).or_insert_with(|| {
                imp.id = next;
                summary.memory_bytes += imp.memory_bytes;
                impostors.push(imp);
                next
            });
            ids.push(id);
        }
        for mut c in p.cpvs {
            c.id = cpvs.len() as u32;
            for j in &mut c.impostors {
                *j = ids[*j as usize];
            }
            c.impostors.sort_unstable();
            c.impostors.dedup();
            cpvs.push(c);
        }
        summary.candidates += p.summary.candidates;
        summary.unsolved_cpvs += p.summary.unsolved_cpvs;
        summary.max_residual_ms = summary.max_residual_ms.max(p.summary.max_residual_ms);
        for (r, n) in &p.summary.unsolved_by_reason {
            *summary.unsolved_by_reason.entry(*r).or_default() += n;
        }
    }
    summary.cpvs = cpvs.len() as u64;
    summary.impostors = impostors.len() as u64;
    Ok(Placement {
        summary,
        impostors,
        cpvs,
    })
}

impl Stats {
    /// Adds a tile's counters and stage times to these (a tiled run's).
    fn add_tile(&mut self, t: &Stats) {
        self.threads = t.threads;
        self.objects = t.objects;
        self.triangles = t.triangles;
        self.hierarchy_nodes = t.hierarchy_nodes;
        self.cells += t.cells;
        self.regions_visited += t.regions_visited;
        self.enclosing_frusta += t.enclosing_frusta;
        self.cpvs += t.cpvs;
        self.cpvs_refined_away += t.cpvs_refined_away;
        if let Some(p) = t.cpv_precision {
            let (a, b) = (self.cpv_precision_sampled, t.cpv_precision_sampled);
            let before = self.cpv_precision.unwrap_or(0.0) * a as f64;
            self.cpv_precision = Some((before + p * b as f64) / (a + b).max(1) as f64);
        }
        self.cpv_precision_sampled += t.cpv_precision_sampled;
        self.candidate_pairs += t.candidate_pairs;
        self.stored_pair_costs += t.stored_pair_costs;
        self.pair_groups += t.pair_groups;
        self.served_entries += t.served_entries;
        self.candidates += t.candidates;
        self.greedy_choices += t.greedy_choices;
        self.score_evaluations += t.score_evaluations;
        self.score_bounds += t.score_bounds;
        self.pruned += t.pruned;
        self.evaluations_per_choice =
            self.score_evaluations as f64 / self.greedy_choices.max(1) as f64;
        for s in &t.seconds {
            match self.seconds.iter_mut().find(|x| x.stage == s.stage) {
                Some(x) => x.seconds += s.seconds,
                None => self.seconds.push(StageTime::new(&s.stage, s.seconds)),
            }
        }
        self.peak_rss_bytes = self.peak_rss_bytes.max(t.peak_rss_bytes);
        self.predicted_peak_bytes = self.predicted_peak_bytes.max(t.predicted_peak_bytes);
        if self.visibility.is_none() {
            self.visibility.clone_from(&t.visibility);
        }
        if self.lod.is_none() {
            self.lod.clone_from(&t.lod);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::placement::{
        DirectionsJson, PlacedCpv, PlacedImpostor, RegionJson, SphereJson, ViewCellJson,
    };

    fn job(min: [f64; 3], max: [f64; 3], cell: f64) -> Job {
        let mut j = Job::from_json(
            br#"{"view_space": {"min": [0, 0, 0], "max": [1, 1, 1]}}"#,
            "job",
        )
        .unwrap();
        j.view_space.min = min;
        j.view_space.max = max;
        j.problem_views.cell_size = cell;
        j.problem_views.grid_origin = [0.0; 3];
        j
    }

    /// Tiles cover the view space exactly, x-major, their sides on the
    /// job's grid (anchored planes), y untouched; more tiles than cells
    /// give one tile per cell.
    #[test]
    fn tiles_partition_the_view_space_on_grid_boundaries() {
        // x: 5..105 with cells of 20 anchored at 0: boundaries 5, 20, 40,
        // 60, 80, 100, 105 (6 cells); z: 0..40 (2 cells).
        let j = job([5.0, 1.0, 0.0], [105.0, 2.0, 40.0], 20.0);
        let t = tile_jobs(&j, [2, 4]);
        let xs: Vec<[f64; 2]> = t
            .iter()
            .map(|t| [t.view_space.min[0], t.view_space.max[0]])
            .collect();
        let zs: Vec<[f64; 2]> = t
            .iter()
            .map(|t| [t.view_space.min[2], t.view_space.max[2]])
            .collect();
        assert_eq!(t.len(), 4, "z clamps to its 2 cells");
        // Three cells each: boundary 3 of 6 is 60.
        assert_eq!(xs, [[5.0, 60.0], [5.0, 60.0], [60.0, 105.0], [60.0, 105.0]]);
        assert_eq!(zs, [[0.0, 20.0], [20.0, 40.0], [0.0, 20.0], [20.0, 40.0]]);
        for t in &t {
            assert_eq!([t.view_space.min[1], t.view_space.max[1]], [1.0, 2.0]);
            assert!(t.partition.is_none());
            // The tile's cells are the job's cells within it.
            let g = t.grid();
            let full = j.grid();
            for a in [0, 2] {
                for i in 0..=g.counts[a] {
                    let b = g.boundary(a, i);
                    assert!(
                        (0..=full.counts[a]).any(|k| full.boundary(a, k) == b),
                        "{b} is not a boundary of the job's grid"
                    );
                }
            }
        }
        let cells: u64 = t.iter().map(|t| t.grid().len()).sum();
        assert_eq!(cells, j.grid().len());
    }

    fn imp(node: u32, x: f64) -> PlacedImpostor {
        PlacedImpostor {
            id: 0,
            node,
            objects: vec![node],
            sphere: SphereJson {
                center: [x, 0.0, 0.0],
                radius: 1.0,
            },
            view_cell: ViewCellJson::Box {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            layers: 1,
            resolution: 8,
            memory_bytes: 100 + u64::from(node),
            time_ms: 0.1,
        }
    }

    fn cpv(x: f64, impostors: Vec<u32>, solved: bool) -> PlacedCpv {
        PlacedCpv {
            id: 0,
            region: RegionJson {
                min: [x, 0.0, 0.0],
                max: [x + 1.0, 1.0, 1.0],
            },
            directions: DirectionsJson {
                face: 0,
                u: [0.0, 1.0],
                v: [0.0, 1.0],
            },
            time_ms_original: 5.0,
            time_ms_final: if solved { 3.0 } else { 4.5 },
            solved,
            unsolved_reason: None,
            impostors,
        }
    }

    fn placement(impostors: Vec<PlacedImpostor>, cpvs: Vec<PlacedCpv>) -> Placement {
        let mut p = Placement {
            summary: Summary {
                cpvs: cpvs.len() as u64,
                candidates: 10,
                impostors: impostors.len() as u64,
                memory_bytes: impostors.iter().map(|i| i.memory_bytes).sum(),
                unsolved_cpvs: cpvs.iter().filter(|c| !c.solved).count() as u64,
                target_frame_time_ms: 4.0,
                max_residual_ms: if cpvs.iter().all(|c| c.solved) {
                    0.0
                } else {
                    0.5
                },
                unsolved_by_reason: Default::default(),
                budget_bytes: None,
            },
            impostors,
            cpvs,
        };
        for (i, x) in p.impostors.iter_mut().enumerate() {
            x.id = i as u32;
        }
        for (i, x) in p.cpvs.iter_mut().enumerate() {
            x.id = i as u32;
        }
        p
    }

    /// Packed lists come back as they went in, sorted: empty lists, ids
    /// of every width (gaps of one to five bytes), duplicates kept.
    #[test]
    fn packed_lists_unpack_to_the_sorted_lists() {
        let lists = [
            vec![5, 0, 3],
            vec![],
            vec![u32::MAX, 127, 128, 16_383, 16_384, 2_097_152, 0],
            vec![7, 7],
            vec![300],
        ];
        let cpvs = lists
            .iter()
            .enumerate()
            .map(|(k, l)| cpv(k as f64, l.clone(), true))
            .collect();
        let p = placement(vec![imp(1, 0.0)], cpvs);
        let packed = Packed::pack(p.clone());
        // Gaps below 128 take a byte; the third list's gaps 0, 127, 1,
        // 16,255, 1, 2,080,768 and 4,292,870,143 take 1, 1, 1, 2, 1, 3, 5.
        assert_eq!(packed.lists.len(), 3 + 14 + 2 + 2);
        let back = packed.unpack();
        let mut want = p;
        for c in &mut want.cpvs {
            c.impostors.sort_unstable();
        }
        assert_eq!(back, want);
    }

    /// Merging: CPVs in tile order with new ids, an impostor both tiles
    /// chose stored once (its memory counted once), ids remapped, totals
    /// summed.
    #[test]
    fn merged_tiles_store_a_shared_impostor_once() {
        let j = job([0.0; 3], [4.0, 1.0, 1.0], 1.0);
        let a = placement(
            vec![imp(7, 0.0), imp(9, 0.0)],
            vec![cpv(0.0, vec![0, 1], true), cpv(1.0, vec![1], true)],
        );
        // Tile b chose node 9's impostor too (same everything), and one of
        // its own; its ids are its own.
        let b = placement(
            vec![imp(3, 5.0), imp(9, 0.0)],
            vec![cpv(2.0, vec![1, 0], true), cpv(3.0, vec![1], false)],
        );
        let m = merge(&j, [a.clone(), b]).unwrap();
        let nodes: Vec<u32> = m.impostors.iter().map(|i| i.node).collect();
        assert_eq!(nodes, [7, 9, 3]);
        assert!(
            m.impostors
                .iter()
                .enumerate()
                .all(|(i, x)| x.id == i as u32)
        );
        let uses: Vec<Vec<u32>> = m.cpvs.iter().map(|c| c.impostors.clone()).collect();
        assert_eq!(uses, [vec![0, 1], vec![1], vec![1, 2], vec![1]]);
        assert!(m.cpvs.iter().enumerate().all(|(i, c)| c.id == i as u32));
        assert_eq!(m.summary.cpvs, 4);
        assert_eq!(m.summary.impostors, 3);
        assert_eq!(m.summary.memory_bytes, 107 + 109 + 103);
        assert_eq!(m.summary.candidates, 20);
        assert_eq!(m.summary.unsolved_cpvs, 1);
        assert_eq!(m.summary.max_residual_ms, 0.5);
        // A different view cell is a different impostor.
        let mut other = imp(9, 0.0);
        other.view_cell = ViewCellJson::Box {
            min: [0.0; 3],
            max: [2.0, 1.0, 1.0],
        };
        let c = placement(vec![other], vec![cpv(4.0, vec![0], true)]);
        let m = merge(&j, [a, c]).unwrap();
        assert_eq!(m.summary.impostors, 3);
    }
}
