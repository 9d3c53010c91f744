//! From-region visibility (paper §3.1, observation 2.3): which objects may be
//! visible from a region of the 3D view space.
//!
//! Every grid cell gets a potentially visible set (PVS), computed on first
//! use and cached; a kd region of at most `max_region_cells` cells uses the
//! union of its cells' sets (a superset of what any of its viewpoints sees),
//! larger regions count every object.
//!
//! Conservative mode has two tiers. Each cell also has a *coarse* set,
//! sampled half as densely per axis (a quarter of the horizons in a cell of
//! 4 × 4 samples, occluders shrunk twice as much), and a kd region of several
//! cells uses the union of its cells' coarse sets. Most of a city's view
//! space has no problem view, and the coarse sets prove that at a quarter
//! of the price; a single cell whose coarse set leaves a problem view is
//! tested again with its final set, the coarse and fine sets intersected
//! (both conservative, so their intersection is). Every set a test uses
//! holds the final set of each of its cells, so an evaluation that counts
//! a view's final set never counts more than a test proved.
//!
//! The problem view approximation filters
//! the objects of each region by its set before estimating times, and the
//! independent evaluation filters each view by its cell's set, so a view's
//! time never exceeds its problem view's estimate.
//!
//! Modes:
//! * `conservative` ([`conservative`]): shrunk occluders and point sampling;
//!   never culls a visible object (the argument is in that module).
//! * `sampled` ([`sampled`]): rays from random points of the cell in random
//!   directions over any triangle soup; objects no ray reaches are culled, so
//!   it may miss some, and it reports an estimate of how many.
//! * `precomputed` ([`pvs`]): a PVS file of view cells and visible objects.

pub mod conservative;
pub mod occluders;
pub mod pvs;
pub mod sampled;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use rayon::prelude::*;

use crate::api::job::{Job, VisibilityMode};
use crate::api::pvs::{PvsCell, PvsFile};
use crate::api::stats::{OccluderStats, VisibilityStats};
use crate::math::geom::Aabb;
use crate::math::grid::Grid;
use crate::render::raycast::RayCaster;
use crate::scene::Scene;
use crate::scene::hierarchy::Hierarchy;
use crate::{Error, Result};

/// A set of object ids (a bit set).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjectSet {
    words: Vec<u64>,
    len: usize,
}

impl ObjectSet {
    /// The empty set over `n` objects.
    pub fn new(n: usize) -> ObjectSet {
        ObjectSet {
            words: vec![0; n.div_ceil(64)],
            len: n,
        }
    }

    /// The set of all `n` objects.
    pub fn full(n: usize) -> ObjectSet {
        let mut s = ObjectSet::new(n);
        for i in 0..n as u32 {
            s.insert(i);
        }
        s
    }

    /// Number of objects the set ranges over.
    pub fn universe(&self) -> usize {
        self.len
    }

    /// True when `o` is in the set.
    #[inline]
    pub fn contains(&self, o: u32) -> bool {
        self.words
            .get(o as usize / 64)
            .is_some_and(|w| w >> (o % 64) & 1 == 1)
    }

    /// Adds `o` (ignored when out of range).
    #[inline]
    pub fn insert(&mut self, o: u32) {
        if let Some(w) = self.words.get_mut(o as usize / 64) {
            *w |= 1 << (o % 64);
        }
    }

    /// Takes `o` out (ignored when out of range).
    #[inline]
    pub fn remove(&mut self, o: u32) {
        if let Some(w) = self.words.get_mut(o as usize / 64) {
            *w &= !(1 << (o % 64));
        }
    }

    /// Adds every member of `other`.
    pub fn union_with(&mut self, other: &ObjectSet) {
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a |= b;
        }
    }

    /// Keeps only the members of `other`.
    pub fn intersect_with(&mut self, other: &ObjectSet) {
        for (a, b) in self.words.iter_mut().zip(&other.words) {
            *a &= b;
        }
    }

    /// Number of members.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The members in increasing order.
    pub fn iter(&self) -> impl Iterator<Item = u32> + '_ {
        self.words.iter().enumerate().flat_map(|(i, &w)| {
            (0..64u32)
                .filter(move |b| w >> b & 1 == 1)
                .map(move |b| i as u32 * 64 + b)
        })
    }
}

/// What the visibility of one cell found.
#[derive(Clone, Debug)]
pub struct CellVisibility {
    /// The potentially visible objects.
    pub set: Arc<ObjectSet>,
    /// Sampled mode: Good–Turing estimate of the probability that one more
    /// ray would reach an object no ray reached (objects seen by exactly one
    /// ray over all observations); 0 otherwise.
    pub missing_mass: f64,
    /// Sampled mode: Chao1 estimate of visible objects the uniform rays
    /// missed, less those the aimed probes then found.
    pub unseen_objects: f64,
    /// Sampled mode: objects found only by the aimed probes.
    pub found_by_probes: u64,
    /// Precomputed mode: false when the file's cells do not cover this cell
    /// (every object then counts as visible).
    pub covered: bool,
}

/// The ingredients a mode needs, prepared from the scene's geometry or given.
#[derive(Clone, Copy, Default)]
pub struct VisibilityInputs<'a> {
    /// Occluders (conservative mode).
    pub occluders: Option<&'a occluders::Occluders>,
    /// Ray caster (sampled mode).
    pub caster: Option<&'a RayCaster>,
    /// The geometry the caster was built from (sampled mode's aimed rays).
    pub geometry: Option<&'a crate::scene::geometry::SceneGeometry>,
    /// A PVS file (precomputed mode).
    pub pvs: Option<&'a PvsFile>,
}

enum Source<'a> {
    /// The fine sampling and, where it samples less, the coarse tier.
    Conservative(
        conservative::Conservative,
        Option<conservative::Conservative>,
    ),
    Sampled(sampled::Sampled<'a>),
    Precomputed(&'a PvsFile),
}

/// The visibility of one job: cached per grid cell, computed on demand,
/// safe to share across threads. Deterministic: a cell's set depends only
/// on the scene, the job and the cell.
pub struct Visibility<'a> {
    mode: VisibilityMode,
    scene: &'a Scene,
    hierarchy: &'a Hierarchy,
    grid: Grid,
    max_region_cells: u64,
    source: Source<'a>,
    cells: Vec<OnceLock<CellVisibility>>,
    /// Conservative mode's coarse sets (empty without a coarse tier).
    coarse: Vec<OnceLock<Arc<ObjectSet>>>,
    nanos: AtomicU64,
    occluder_stats: Option<OccluderStats>,
}

impl<'a> Visibility<'a> {
    /// The visibility of `job`, or `None` when its mode is `none`. Fails
    /// when the mode's ingredient is missing (e.g. a JSON scene summary has
    /// no geometry to find occluders in).
    pub fn new(
        job: &Job,
        scene: &'a Scene,
        hierarchy: &'a Hierarchy,
        inputs: VisibilityInputs<'a>,
    ) -> Result<Option<Visibility<'a>>> {
        let params = &job.visibility;
        let grid = job.grid();
        // Sampled for the largest cell; smaller (edge) cells get the same
        // sample counts, so finer spacing, and the occluders' shrinking
        // stays conservative for them.
        let cell_ext = grid.largest_cell();
        let missing = |what: &str| {
            Error::bad(
                "visibility",
                format!(
                    "mode \"{}\" needs {what}",
                    serde_json::to_value(params.mode)
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_owned))
                        .unwrap_or_default()
                ),
            )
        };
        let mut occluder_stats = None;
        let source = match params.mode {
            VisibilityMode::None => return Ok(None),
            VisibilityMode::Conservative => {
                let occ = inputs.occluders.ok_or_else(|| {
                    missing("the scene's geometry (a .glb/.gltf scene; a JSON scene summary has none — precompute a PVS and use \"precomputed\")")
                })?;
                occluder_stats = Some(occ.stats.clone());
                let fine =
                    conservative::Conservative::new(&occ.boxes, cell_ext, params.sample_spacing_m);
                let coarse = conservative::Conservative::new(
                    &occ.boxes,
                    cell_ext,
                    2.0 * params.sample_spacing_m,
                );
                let tier = coarse.samples != fine.samples;
                Source::Conservative(fine, tier.then_some(coarse))
            }
            VisibilityMode::Sampled => {
                let (Some(caster), Some(geometry)) = (inputs.caster, inputs.geometry) else {
                    return Err(missing(
                        "the scene's geometry (a .glb/.gltf scene; a JSON scene summary has none)",
                    ));
                };
                Source::Sampled(sampled::Sampled::new(caster, geometry, job))
            }
            VisibilityMode::Precomputed => {
                let file = inputs.pvs.ok_or_else(|| {
                    missing("a PVS file (--pvs FILE, or the service's `pvs` part)")
                })?;
                file.check(scene.objects.len(), "pvs")?;
                Source::Precomputed(file)
            }
        };
        let n = grid.len() as usize;
        let tiers = matches!(source, Source::Conservative(_, Some(_)));
        Ok(Some(Visibility {
            mode: params.mode,
            scene,
            hierarchy,
            grid,
            max_region_cells: u64::from(params.max_region_cells),
            source,
            cells: (0..n).map(|_| OnceLock::new()).collect(),
            coarse: (0..if tiers { n } else { 0 })
                .map(|_| OnceLock::new())
                .collect(),
            nanos: AtomicU64::new(0),
            occluder_stats,
        }))
    }

    /// The grid the cells belong to.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The visibility of grid cell `c` (computed once): its final set.
    pub fn cell(&self, c: [u32; 3]) -> &CellVisibility {
        let i = self.grid.linear(c) as usize;
        self.cells[i].get_or_init(|| {
            // The coarse set first (timed on its own).
            let coarse = self.coarse_cell(c);
            let start = Instant::now();
            let b = self.grid.cell_box(c, c.map(|x| x + 1));
            let mut r = self.compute(&b, u64::from(self.grid.linear(c)));
            if let Some(coarse) = coarse {
                let mut set = Arc::unwrap_or_clone(r.set);
                set.intersect_with(&coarse);
                r.set = Arc::new(set);
            }
            self.nanos
                .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
            r
        })
    }

    /// True when regions of several cells use the cells' coarse sets (see
    /// the module docs).
    pub fn has_coarse_tier(&self) -> bool {
        matches!(self.source, Source::Conservative(_, Some(_)))
    }

    /// The coarse set of grid cell `c` (computed once), or `None` without a
    /// coarse tier.
    pub fn coarse_cell(&self, c: [u32; 3]) -> Option<Arc<ObjectSet>> {
        let Source::Conservative(_, Some(coarse)) = &self.source else {
            return None;
        };
        let i = self.grid.linear(c) as usize;
        Some(
            self.coarse[i]
                .get_or_init(|| {
                    let start = Instant::now();
                    let b = self.grid.cell_box(c, c.map(|x| x + 1));
                    let set = coarse.cell_pvs(&b, self.scene, self.hierarchy);
                    self.nanos
                        .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
                    Arc::new(set)
                })
                .clone(),
        )
    }

    fn compute(&self, b: &Aabb, index: u64) -> CellVisibility {
        match &self.source {
            Source::Conservative(c, _) => CellVisibility {
                set: Arc::new(c.cell_pvs(b, self.scene, self.hierarchy)),
                missing_mass: 0.0,
                unseen_objects: 0.0,
                found_by_probes: 0,
                covered: true,
            },
            Source::Sampled(s) => s.cell_pvs(b, index, self.scene),
            Source::Precomputed(f) => match pvs::region_set(f, b) {
                Some(set) => CellVisibility {
                    set: Arc::new(set),
                    missing_mass: 0.0,
                    unseen_objects: 0.0,
                    found_by_probes: 0,
                    covered: true,
                },
                None => CellVisibility {
                    set: Arc::new(ObjectSet::full(self.scene.objects.len())),
                    missing_mass: 0.0,
                    unseen_objects: 0.0,
                    found_by_probes: 0,
                    covered: false,
                },
            },
        }
    }

    /// The potentially visible set of every grid cell, as a PVS file that
    /// `"visibility": "precomputed"` can reuse (cells computed in parallel).
    pub fn to_pvs_file(&self) -> PvsFile {
        let g = &self.grid;
        let cells: Vec<[u32; 3]> = (0..g.counts[2])
            .flat_map(|z| {
                (0..g.counts[1]).flat_map(move |y| (0..g.counts[0]).map(move |x| [x, y, z]))
            })
            .collect();
        self.prefetch(&cells);
        PvsFile {
            objects: self.scene.objects.len() as u64,
            cells: cells
                .iter()
                .map(|&c| {
                    let b = g.cell_box(c, c.map(|x| x + 1));
                    PvsCell {
                        min: b.min.to_array(),
                        max: b.max.to_array(),
                        visible: self.cell(c).set.iter().collect(),
                    }
                })
                .collect(),
        }
    }

    /// Computes the given cells in parallel (so that later lookups do not
    /// wait on each other).
    pub fn prefetch(&self, cells: &[[u32; 3]]) {
        cells.par_iter().for_each(|&c| {
            self.cell(c);
        });
    }

    /// The potentially visible set of the kd region of cells `lo..hi`: a
    /// single cell's final set, the union of several cells' sets (coarse
    /// where there is a coarse tier), or `None` (every object) when the
    /// region has more than `max_region_cells` cells.
    pub fn region(&self, lo: [u32; 3], hi: [u32; 3]) -> Option<Arc<ObjectSet>> {
        let count: u64 = (0..3).map(|a| u64::from(hi[a] - lo[a])).product();
        if count > self.max_region_cells {
            return None;
        }
        let cells: Vec<[u32; 3]> = (lo[2]..hi[2])
            .flat_map(|z| (lo[1]..hi[1]).flat_map(move |y| (lo[0]..hi[0]).map(move |x| [x, y, z])))
            .collect();
        if cells.len() == 1 {
            return Some(self.cell(cells[0]).set.clone());
        }
        // Computed in parallel; the union does not depend on the order.
        let sets: Vec<Arc<ObjectSet>> = cells
            .par_iter()
            .map(|&c| {
                self.coarse_cell(c)
                    .unwrap_or_else(|| self.cell(c).set.clone())
            })
            .collect();
        let mut set = ObjectSet::new(self.scene.objects.len());
        for s in &sets {
            set.union_with(s);
        }
        Some(Arc::new(set))
    }

    /// Counters over the cells computed so far.
    pub fn stats(&self) -> VisibilityStats {
        let done: Vec<&CellVisibility> = self.cells.iter().filter_map(OnceLock::get).collect();
        let n = done.len().max(1) as f64;
        let objects = self.scene.objects.len().max(1) as f64;
        let sizes: Vec<f64> = done.iter().map(|c| c.set.count() as f64).collect();
        let mut s = VisibilityStats {
            mode: self.mode,
            cells_computed: done.len() as u64,
            mean_visible_objects: sizes.iter().sum::<f64>() / n,
            mean_visible_fraction: sizes.iter().sum::<f64>() / n / objects,
            max_visible_fraction: sizes.iter().copied().fold(0.0, f64::max) / objects,
            cpu_seconds: self.nanos.load(Ordering::Relaxed) as f64 * 1e-9,
            occluders: self.occluder_stats.clone(),
            ..VisibilityStats::default()
        };
        match &self.source {
            Source::Conservative(c, coarse) => {
                s.shrunk_occluders = Some(c.occluder_count() as u64);
                s.samples_per_axis = Some(c.samples);
                s.shrink_m = Some(c.epsilon.to_array());
                if let Some(coarse) = coarse {
                    s.coarse_cells_computed =
                        Some(self.coarse.iter().filter(|c| c.get().is_some()).count() as u64);
                    s.coarse_samples_per_axis = Some(coarse.samples);
                }
            }
            Source::Sampled(sm) => {
                s.rays_per_cell = Some(sm.rays());
                s.found_by_probes_mean =
                    Some(done.iter().map(|c| c.found_by_probes as f64).sum::<f64>() / n);
                s.missing_mass_mean = Some(done.iter().map(|c| c.missing_mass).sum::<f64>() / n);
                s.missing_mass_max = Some(done.iter().map(|c| c.missing_mass).fold(0.0, f64::max));
                s.unseen_objects_mean =
                    Some(done.iter().map(|c| c.unseen_objects).sum::<f64>() / n);
                s.missed_object_rate = Some(
                    done.iter()
                        .map(|c| {
                            let found = c.set.count() as f64;
                            c.unseen_objects / (found + c.unseen_objects).max(1.0)
                        })
                        .sum::<f64>()
                        / n,
                );
            }
            Source::Precomputed(_) => {
                s.uncovered_cells = Some(done.iter().filter(|c| !c.covered).count() as u64);
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_set_basics() {
        let mut s = ObjectSet::new(130);
        assert_eq!(s.count(), 0);
        for o in [0, 63, 64, 129] {
            s.insert(o);
        }
        s.insert(500); // out of range: ignored
        assert!(s.contains(63) && s.contains(64) && !s.contains(65) && !s.contains(500));
        assert_eq!(s.iter().collect::<Vec<_>>(), vec![0, 63, 64, 129]);
        let mut t = ObjectSet::new(130);
        t.insert(1);
        t.union_with(&s);
        assert_eq!(t.count(), 5);
        assert_eq!(ObjectSet::full(130).count(), 130);
        t.intersect_with(&s);
        assert_eq!(t.iter().collect::<Vec<_>>(), vec![0, 63, 64, 129]);
    }

    /// With a coarse tier, a cell's final set is its fine set (what one
    /// sampling at the job's spacing finds) intersected with its coarse set
    /// (twice the spacing), so it never holds an object the coarse set
    /// culled (a proof made with the coarse sets holds for it); a region of
    /// several cells counts the union of their coarse sets. The tiers
    /// differ (so the comparisons could fail).
    #[test]
    fn cells_intersect_their_tiers_and_regions_use_the_coarse_sets() {
        use crate::testutil;
        let scene = testutil::synthetic_city(3, 8, 8);
        let h = Hierarchy::build(&scene);
        let occ = occluders::extract(&testutil::box_geometry(&scene), &scene);
        let mut job = testutil::synthetic_job(8, 8);
        job.visibility.mode = VisibilityMode::Conservative;
        job.visibility.sample_spacing_m = 5.0;
        let inputs = VisibilityInputs {
            occluders: Some(&occ),
            ..VisibilityInputs::default()
        };
        let vis = Visibility::new(&job, &scene, &h, inputs).unwrap().unwrap();
        assert!(vis.has_coarse_tier());
        let grid = vis.grid().clone();
        let fine = conservative::Conservative::new(&occ.boxes, grid.largest_cell(), 5.0);
        let mut tiers_differ = 0;
        for x in 0..grid.counts[0] {
            for z in 0..grid.counts[2] {
                let c = [x, 0, z];
                let coarse = vis.coarse_cell(c).unwrap();
                let mut both = fine.cell_pvs(&grid.cell_box(c, [x + 1, 1, z + 1]), &scene, &h);
                tiers_differ += usize::from(coarse.count() != both.count());
                both.intersect_with(&coarse);
                let last = &vis.cell(c).set;
                assert_eq!(
                    last.iter().collect::<Vec<_>>(),
                    both.iter().collect::<Vec<_>>()
                );
            }
        }
        assert!(tiers_differ > 0);
        let region = vis.region([0, 0, 0], [2, 1, 2]).unwrap();
        let mut union = ObjectSet::new(scene.objects.len());
        for c in [[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]] {
            union.union_with(&vis.coarse_cell(c).unwrap());
        }
        assert_eq!(
            region.iter().collect::<Vec<_>>(),
            union.iter().collect::<Vec<_>>()
        );
        let stats = vis.stats();
        assert_eq!(stats.samples_per_axis, Some([4, 1, 4]));
        assert_eq!(stats.coarse_samples_per_axis, Some([2, 1, 2]));
        assert_eq!(stats.coarse_cells_computed, Some(grid.len()));
    }
}
