//! From-region visibility (paper §3.1, observation 2.3): which objects may be
//! visible from a region of the 3D view space.
//!
//! Every grid cell gets a potentially visible set (PVS), computed on first
//! use and cached; a kd region of at most `max_region_cells` cells uses the
//! union of its cells' sets (a superset of what any of its viewpoints sees),
//! larger regions count every object. The problem view approximation filters
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
    Conservative(conservative::Conservative),
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
                Source::Conservative(conservative::Conservative::new(
                    &occ.boxes,
                    cell_ext,
                    params.sample_spacing_m,
                ))
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
        Ok(Some(Visibility {
            mode: params.mode,
            scene,
            hierarchy,
            grid,
            max_region_cells: u64::from(params.max_region_cells),
            source,
            cells: (0..n).map(|_| OnceLock::new()).collect(),
            nanos: AtomicU64::new(0),
            occluder_stats,
        }))
    }

    /// The grid the cells belong to.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The visibility of grid cell `c` (computed once).
    pub fn cell(&self, c: [u32; 3]) -> &CellVisibility {
        let i = self.grid.linear(c) as usize;
        self.cells[i].get_or_init(|| {
            let start = Instant::now();
            let b = self.grid.cell_box(c, c.map(|x| x + 1));
            let r = self.compute(&b, u64::from(self.grid.linear(c)));
            self.nanos
                .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
            r
        })
    }

    fn compute(&self, b: &Aabb, index: u64) -> CellVisibility {
        match &self.source {
            Source::Conservative(c) => CellVisibility {
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

    /// The potentially visible set of the kd region of cells `lo..hi`: the
    /// union of its cells' sets, or `None` (every object) when the region has
    /// more than `max_region_cells` cells.
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
        self.prefetch(&cells);
        let mut set = ObjectSet::new(self.scene.objects.len());
        for c in cells {
            set.union_with(&self.cell(c).set);
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
            Source::Conservative(c) => {
                s.shrunk_occluders = Some(c.occluder_count() as u64);
                s.samples_per_axis = Some(c.samples);
                s.shrink_m = Some(c.epsilon.to_array());
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
    }
}
