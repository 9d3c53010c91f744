//! Potentially visible set files (`schemas/pvs.schema.json`): view cells
//! (boxes) with the ids of the objects that may be visible from them.
//!
//! A region's set is the union of the sets of every file cell that meets it
//! (boundaries included). File cells must not overlap; where they do not
//! cover a region entirely, visibility there is unknown and every object
//! counts as visible. `impostor pvs` writes the grid cells of a job in this
//! format, so a PVS computed once (or by another tool) can be reused with
//! `"visibility": "precomputed"`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::ObjectSet;
use crate::math::geom::Aabb;
use crate::{Error, Result};

/// A PVS file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PvsFile {
    /// Number of objects of the scene the file was made for.
    pub objects: u64,
    /// The view cells.
    pub cells: Vec<PvsCell>,
}

/// One view cell of a PVS file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PvsCell {
    /// Box minimum `[x, y, z]`, metres.
    pub min: [f64; 3],
    /// Box maximum `[x, y, z]`, metres.
    pub max: [f64; 3],
    /// Ids of the objects that may be visible from the cell.
    pub visible: Vec<u32>,
}

impl PvsFile {
    /// Parses a PVS file; `source` names it in errors.
    pub fn from_json(bytes: &[u8], source: &str) -> Result<PvsFile> {
        let f: PvsFile = serde_json::from_slice(bytes)
            .map_err(|e| Error::bad(source, format!("invalid PVS JSON: {e}")))?;
        f.check_shape(source)?;
        Ok(f)
    }

    fn check_shape(&self, source: &str) -> Result<()> {
        for (i, c) in self.cells.iter().enumerate() {
            let what = || format!("{source}: cells[{i}]");
            if c.min
                .iter()
                .chain(&c.max)
                .any(|v| !v.is_finite() || v.abs() > 1e9)
            {
                return Err(Error::bad(what(), "box is not finite"));
            }
            if (0..3).any(|a| c.min[a] > c.max[a]) {
                return Err(Error::bad(what(), "box is inverted (min above max)"));
            }
            if let Some(&o) = c.visible.iter().find(|&&o| u64::from(o) >= self.objects) {
                return Err(Error::bad(
                    format!("{}.visible", what()),
                    format!(
                        "object id {o} is not below the file's object count {}",
                        self.objects
                    ),
                ));
            }
        }
        // No two cells may overlap (positive-volume intersection).
        let mut order: Vec<usize> = (0..self.cells.len()).collect();
        order.sort_by(|&a, &b| self.cells[a].min[0].total_cmp(&self.cells[b].min[0]));
        for (k, &i) in order.iter().enumerate() {
            let a = &self.cells[i];
            for &j in &order[k + 1..] {
                let b = &self.cells[j];
                if b.min[0] >= a.max[0] {
                    break;
                }
                let overlap = (0..3).all(|ax| {
                    let lo = a.min[ax].max(b.min[ax]);
                    let hi = a.max[ax].min(b.max[ax]);
                    hi > lo || (a.min[ax] == a.max[ax] && b.min[ax] == b.max[ax] && lo == hi)
                });
                if overlap {
                    return Err(Error::bad(
                        format!("{source}: cells[{}] and cells[{}]", i.min(j), i.max(j)),
                        "overlap; PVS cells must not overlap",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Checks that the file was made for a scene of `objects` objects.
    pub fn check(&self, objects: usize, source: &str) -> Result<()> {
        if self.objects != objects as u64 {
            return Err(Error::bad(
                source,
                format!(
                    "the PVS file is for {} objects but the scene has {objects}: it does not match the scene",
                    self.objects
                ),
            ));
        }
        self.check_shape(source)
    }

    /// The union of the sets of the cells that overlap `region` (with
    /// positive measure along its axes of positive extent, containing it
    /// along the others), or `None` when those cells do not cover it. A
    /// cell's set holds for its closed box, and the closed cells that cover
    /// a region up to measure zero cover all of it, so cells that merely
    /// touch the region need not be counted.
    pub fn region_set(&self, region: &Aabb) -> Option<ObjectSet> {
        let mut set = ObjectSet::new(self.objects as usize);
        let axes: Vec<usize> = (0..3).filter(|&a| region.max[a] > region.min[a]).collect();
        let measure = |lo: [f64; 3], hi: [f64; 3]| -> f64 {
            axes.iter().map(|&a| (hi[a] - lo[a]).max(0.0)).product()
        };
        let full = measure(region.min.to_array(), region.max.to_array());
        let mut covered = 0.0;
        for c in &self.cells {
            let lo = [0, 1, 2].map(|a| c.min[a].max(region.min[a]));
            let hi = [0, 1, 2].map(|a| c.max[a].min(region.max[a]));
            let overlaps = axes.iter().all(|&a| hi[a] > lo[a])
                && (0..3)
                    .filter(|a| !axes.contains(a))
                    .all(|a| c.min[a] <= region.min[a] && region.max[a] <= c.max[a]);
            if !overlaps {
                continue;
            }
            for &o in &c.visible {
                set.insert(o);
            }
            covered += measure(lo, hi);
        }
        (covered >= full * (1.0 - 1e-9)).then_some(set)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn file() -> PvsFile {
        PvsFile {
            objects: 10,
            cells: vec![
                PvsCell {
                    min: [0.0, 0.0, 0.0],
                    max: [10.0, 2.0, 10.0],
                    visible: vec![1, 2],
                },
                PvsCell {
                    min: [10.0, 0.0, 0.0],
                    max: [20.0, 2.0, 10.0],
                    visible: vec![3],
                },
            ],
        }
    }

    #[test]
    fn regions_take_the_union_of_the_cells_they_meet() {
        let f = file();
        let r = Aabb::new(DVec3::new(2.0, 0.5, 2.0), DVec3::new(8.0, 1.5, 8.0));
        assert_eq!(
            f.region_set(&r).unwrap().iter().collect::<Vec<_>>(),
            vec![1, 2]
        );
        let r = Aabb::new(DVec3::new(5.0, 0.5, 2.0), DVec3::new(15.0, 1.5, 8.0));
        assert_eq!(
            f.region_set(&r).unwrap().iter().collect::<Vec<_>>(),
            vec![1, 2, 3]
        );
        // Partly outside the file's cells: unknown.
        let r = Aabb::new(DVec3::new(15.0, 0.5, 2.0), DVec3::new(25.0, 1.5, 8.0));
        assert!(f.region_set(&r).is_none());
        // A flat region inside.
        let r = Aabb::new(DVec3::new(2.0, 1.0, 2.0), DVec3::new(8.0, 1.0, 8.0));
        assert!(f.region_set(&r).is_some());
    }

    #[test]
    fn bad_files_are_named() {
        let mut f = file();
        f.cells[1].min[0] = 5.0;
        let e = f.check(10, "p.json").unwrap_err().to_string();
        assert!(e.contains("overlap"), "{e}");
        let mut f = file();
        f.cells[0].visible.push(10);
        let e = f.check(10, "p.json").unwrap_err().to_string();
        assert!(e.contains("cells[0].visible"), "{e}");
        let e = file().check(11, "p.json").unwrap_err().to_string();
        assert!(e.contains("does not match"), "{e}");
        let e = PvsFile::from_json(b"{\"objects\": 1}", "p.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("p.json"), "{e}");
    }
}
