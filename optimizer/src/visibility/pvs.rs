//! Precomputed visibility from a PVS file ([`crate::api::pvs::PvsFile`]).
//!
//! A region's set is the union of the sets of every file cell that meets it
//! (boundaries included). File cells must not overlap; where they do not
//! cover a region entirely, visibility there is unknown and every object
//! counts as visible.

use super::ObjectSet;
use crate::api::pvs::PvsFile;
use crate::math::geom::Aabb;

/// The union of the sets of the cells that overlap `region` (with
/// positive measure along its axes of positive extent, containing it
/// along the others), or `None` when those cells do not cover it. A
/// cell's set holds for its closed box, and the closed cells that cover
/// a region up to measure zero cover all of it, so cells that merely
/// touch the region need not be counted.
pub fn region_set(file: &PvsFile, region: &Aabb) -> Option<ObjectSet> {
    let mut set = ObjectSet::new(file.objects as usize);
    let axes: Vec<usize> = (0..3).filter(|&a| region.max[a] > region.min[a]).collect();
    let measure = |lo: [f64; 3], hi: [f64; 3]| -> f64 {
        axes.iter().map(|&a| (hi[a] - lo[a]).max(0.0)).product()
    };
    let full = measure(region.min.to_array(), region.max.to_array());
    let mut covered = 0.0;
    for c in &file.cells {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::pvs::PvsCell;
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
            region_set(&f, &r).unwrap().iter().collect::<Vec<_>>(),
            vec![1, 2]
        );
        let r = Aabb::new(DVec3::new(5.0, 0.5, 2.0), DVec3::new(15.0, 1.5, 8.0));
        assert_eq!(
            region_set(&f, &r).unwrap().iter().collect::<Vec<_>>(),
            vec![1, 2, 3]
        );
        // Partly outside the file's cells: unknown.
        let r = Aabb::new(DVec3::new(15.0, 0.5, 2.0), DVec3::new(25.0, 1.5, 8.0));
        assert!(region_set(&f, &r).is_none());
        // A flat region inside.
        let r = Aabb::new(DVec3::new(2.0, 1.0, 2.0), DVec3::new(8.0, 1.0, 8.0));
        assert!(region_set(&f, &r).is_some());
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
