//! Where a cluster group's impostors are drawn, as boxes of viewer
//! positions: the part of the placement's switch that 3D Tiles can carry.
//!
//! The placement switches per CPV, a box of eye positions (its region)
//! and an interval of view directions; a 3D Tiles runtime knows only the
//! viewer's position. So, per group, the position space is cut into boxes
//! (*leaves*) none of the group's CPV regions crosses: every region either
//! holds a leaf or misses it. A leaf draws the impostors the placement
//! draws in any CPV whose region holds it, whichever its direction; where
//! two of those replace common objects (a cluster in one direction, one of
//! its sub-clusters in another) the one replacing more objects is drawn
//! (then the lower id), so no object is drawn twice. The group's objects
//! no drawn impostor replaces are drawn as geometry. Every impostor a leaf
//! draws is one the placement draws for a view from that leaf, so inside
//! its view cell.
//!
//! The cut is a k-d tree over the faces of the regions, so a runtime that
//! honours `viewerRequestVolume` finds the leaf holding the viewer by
//! descending boxes; neighbouring leaves drawing the same impostors are
//! merged.

use std::collections::HashMap;

use glam::DVec3;

use serde_json::json;

use super::tiles::{Content, Refine, Tile, tiles_box, tiles_sphere};
use crate::Result;
use crate::api::placement::Placement;
use crate::math::geom::Aabb;
use crate::scene::Scene;

/// A box of viewer positions and what the group draws there.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Switch {
    /// The impostors drawn throughout `bounds`, ascending (empty: the
    /// group's geometry).
    Leaf { bounds: Aabb, impostors: Vec<u32> },
    /// `bounds` cut in two.
    Split {
        bounds: Aabb,
        parts: Box<[Switch; 2]>,
    },
}

impl Switch {
    /// The box this node covers.
    pub(super) fn bounds(&self) -> Aabb {
        match self {
            Switch::Leaf { bounds, .. } | Switch::Split { bounds, .. } => *bounds,
        }
    }

    /// Its leaves, in order.
    pub(super) fn leaves(&self) -> Vec<(&Aabb, &[u32])> {
        match self {
            Switch::Leaf { bounds, impostors } => vec![(bounds, impostors.as_slice())],
            Switch::Split { parts, .. } => parts.iter().flat_map(Switch::leaves).collect(),
        }
    }
}

/// The switch of the group of `impostors` (ids ascending) of `placement`
/// over the box of the CPV regions that draw any of them; `None` when no
/// CPV draws one (the group is then drawn as geometry everywhere).
#[cfg(test)]
pub(super) fn group_switch(placement: &Placement, impostors: &[u32]) -> Option<Switch> {
    group_switches(placement, &[impostors]).pop().flatten()
}

/// [`group_switch`] of every group of `groups` (disjoint sets of impostor
/// ids, each ascending), the placement's CPVs read once.
pub(super) fn group_switches(placement: &Placement, groups: &[&[u32]]) -> Vec<Option<Switch>> {
    let mut group_of: Vec<Option<usize>> = vec![None; placement.impostors.len()];
    for (g, ids) in groups.iter().enumerate() {
        for &i in *ids {
            if let Some(slot) = group_of.get_mut(i as usize) {
                *slot = Some(g);
            }
        }
    }
    // Per group, the regions drawing some of its impostors, each once, with
    // the group's impostors drawn in any of its CPVs.
    // (A region is found again by its corners' bits, `+ 0.0` making the
    // two zeros one, as `==` on the coordinates would.)
    let mut regions: Vec<Vec<(Aabb, Vec<u32>)>> = vec![Vec::new(); groups.len()];
    let mut index: Vec<HashMap<[u64; 6], usize>> = vec![HashMap::new(); groups.len()];
    for cpv in &placement.cpvs {
        let b = Aabb {
            min: DVec3::from_array(cpv.region.min),
            max: DVec3::from_array(cpv.region.max),
        };
        let key: [u64; 6] = std::array::from_fn(|k| {
            let v = if k < 3 { b.min[k] } else { b.max[k - 3] };
            (v + 0.0).to_bits()
        });
        for &i in &cpv.impostors {
            let Some(g) = group_of.get(i as usize).copied().flatten() else {
                continue;
            };
            let at = *index[g].entry(key).or_insert_with(|| {
                regions[g].push((b, Vec::new()));
                regions[g].len() - 1
            });
            regions[g][at].1.push(i);
        }
    }
    regions
        .into_iter()
        .map(|regions| {
            let first = regions.first()?.0;
            let bounds = regions.iter().fold(first, |u, (r, _)| u.union(r));
            let all: Vec<usize> = (0..regions.len()).collect();
            Some(cut(placement, &regions, bounds, &all))
        })
        .collect()
}

/// The switch over `bounds` of the regions `live` (those meeting it).
fn cut(
    placement: &Placement,
    regions: &[(Aabb, Vec<u32>)],
    bounds: Aabb,
    live: &[usize],
) -> Switch {
    let crosses = |r: &Aabb, a: usize, c: f64| r.min[a] < c && c < r.max[a];
    // A face of a region inside the box, nearest the middle of the box's
    // longest side that has one.
    let mut best: Option<(f64, usize, f64)> = None;
    for &k in live {
        let r = &regions[k].0;
        for a in 0..3 {
            for c in [r.min[a], r.max[a]] {
                if crosses(&bounds, a, c) {
                    let extent = bounds.max[a] - bounds.min[a];
                    let off = (c - 0.5 * (bounds.min[a] + bounds.max[a])).abs() / extent;
                    // Longest side first, then balance, then axis and
                    // coordinate for a deterministic choice.
                    let key = off - extent * 1e6;
                    let better = match best {
                        None => true,
                        Some((bk, ba, bc)) => {
                            key < bk || (key == bk && (a, c.to_bits()) < (ba, bc.to_bits()))
                        }
                    };
                    if better {
                        best = Some((key, a, c));
                    }
                }
            }
        }
    }
    let Some((_, a, c)) = best else {
        // No region crosses the box: each holds it or misses it.
        let mut drawn: Vec<u32> = live
            .iter()
            .filter(|&&k| regions[k].0.contains_box(&bounds))
            .flat_map(|&k| regions[k].1.iter().copied())
            .collect();
        drawn.sort_unstable();
        drawn.dedup();
        return Switch::Leaf {
            bounds,
            impostors: resolve(placement, drawn),
        };
    };
    let (mut lo, mut hi) = (bounds, bounds);
    lo.max[a] = c;
    hi.min[a] = c;
    let meets = |r: &Aabb, b: &Aabb| (0..3).all(|x| r.min[x] < b.max[x] && b.min[x] < r.max[x]);
    let parts = [lo, hi].map(|b| {
        let live: Vec<usize> = live
            .iter()
            .copied()
            .filter(|&k| meets(&regions[k].0, &b))
            .collect();
        cut(placement, regions, b, &live)
    });
    match &parts {
        [
            Switch::Leaf { impostors: x, .. },
            Switch::Leaf { impostors: y, .. },
        ] if x == y => Switch::Leaf {
            bounds,
            impostors: x.clone(),
        },
        _ => Switch::Split {
            bounds,
            parts: Box::new(parts),
        },
    }
}

/// Of impostors `ids` (ascending), the ones drawn together: by objects
/// replaced, most first (then lower id), each unless it shares an object
/// with one taken before; ascending.
fn resolve(placement: &Placement, mut ids: Vec<u32>) -> Vec<u32> {
    let imp = |i: u32| &placement.impostors[i as usize];
    ids.sort_by_key(|&i| (std::cmp::Reverse(imp(i).objects.len()), i));
    let mut taken: Vec<u32> = Vec::new();
    let mut objects: Vec<u32> = Vec::new();
    for i in ids {
        let own = &imp(i).objects;
        if own.iter().any(|o| objects.binary_search(o).is_ok()) {
            continue;
        }
        taken.push(i);
        objects.extend_from_slice(own);
        objects.sort_unstable();
    }
    taken.sort_unstable();
    taken
}

/// Writes a group's [`Switch`] as tiles (see the module documentation of
/// [`super::tiles`]).
pub(super) struct GroupTiles<'a> {
    /// The group's number, for file names.
    pub group: usize,
    /// The scene, for the objects' boxes.
    pub scene: &'a Scene,
    /// The group's objects, ascending.
    pub objects: &'a [u32],
    /// The box of the group's contents (objects and impostor layers).
    pub bounds: Aabb,
    /// The geometric error of every tile of the switch.
    pub error: f64,
    /// The content drawing all the group's objects.
    pub cluster_content: Option<Content>,
    /// Per impostor, its content and the box of its layers (`None`: no
    /// layer drew anything).
    pub impostor_content: &'a [Option<(Content, Aabb)>],
    /// The contents of objects left as geometry where impostors are drawn,
    /// by their objects.
    pub rests: Vec<(Vec<u32>, Option<Content>)>,
}

impl GroupTiles<'_> {
    /// The tile of `s`: request volume its box, refinement ADD; a split's
    /// children are its parts, a leaf's its impostors and the content of
    /// the objects they leave. `write(name, objects)` writes a content
    /// file of `objects` and says whether it drew anything.
    pub(super) fn switch_tile(
        &mut self,
        s: &Switch,
        placement: &Placement,
        write: &mut dyn FnMut(&str, &[u32]) -> Result<bool>,
    ) -> Result<Tile> {
        let (children, extras) = match s {
            Switch::Split { parts, .. } => (
                parts
                    .iter()
                    .map(|p| self.switch_tile(p, placement, write))
                    .collect::<Result<Vec<_>>>()?,
                None,
            ),
            Switch::Leaf { impostors, .. } => {
                let mut children = Vec::new();
                let mut covered: Vec<u32> = Vec::new();
                for &id in impostors {
                    let imp = &placement.impostors[id as usize];
                    covered.extend_from_slice(&imp.objects);
                    if let Some((content, quads)) = &self.impostor_content[id as usize] {
                        children.push(Tile {
                            bounding_volume: tiles_box(quads),
                            viewer_request_volume: None,
                            geometric_error: 0.0,
                            refine: None,
                            content: Some(content.clone()),
                            children: Vec::new(),
                            extras: Some(json!({ "impostor": id, "cluster": imp.node })),
                        });
                    }
                }
                covered.sort_unstable();
                let rest: Vec<u32> = self
                    .objects
                    .iter()
                    .copied()
                    .filter(|o| covered.binary_search(o).is_err())
                    .collect();
                let content = if rest.is_empty() {
                    None
                } else if impostors.is_empty() {
                    self.cluster_content.clone()
                } else {
                    self.rest_content(&rest, write)?
                };
                if let Some(content) = content {
                    let bounds = rest.iter().fold(Aabb::EMPTY, |b, &o| {
                        let ob = &self.scene.objects[o as usize];
                        b.union(&Aabb {
                            min: ob.min,
                            max: ob.max,
                        })
                    });
                    children.push(Tile {
                        bounding_volume: tiles_box(&bounds),
                        viewer_request_volume: None,
                        geometric_error: 0.0,
                        refine: None,
                        content: Some(content),
                        children: Vec::new(),
                        extras: Some(json!({ "objects": rest })),
                    });
                }
                (children, Some(json!({ "impostors": impostors })))
            }
        };
        Ok(Tile {
            // A sphere, not the cluster tile's box: CesiumJS (its
            // `cullWithChildrenBounds`, on by default) culls a REPLACE tile
            // whose children's boxes lie within its own when none of them
            // may be drawn, a child outside its request volume included;
            // it does not do so for spheres, so outside the switch the
            // cluster tile's geometry is drawn.
            bounding_volume: tiles_sphere(&self.bounds),
            viewer_request_volume: Some(tiles_box(&s.bounds())),
            geometric_error: self.error,
            refine: Some(Refine::Add),
            content: None,
            children,
            extras,
        })
    }

    /// The content of the group's objects `rest`, written once per set.
    fn rest_content(
        &mut self,
        rest: &[u32],
        write: &mut dyn FnMut(&str, &[u32]) -> Result<bool>,
    ) -> Result<Option<Content>> {
        if let Some((_, c)) = self.rests.iter().find(|(r, _)| r == rest) {
            return Ok(c.clone());
        }
        let name = format!("cluster-{}-rest-{}.glb", self.group, self.rests.len());
        let content = write(&name, rest)?.then_some(Content { uri: name });
        self.rests.push((rest.to_vec(), content.clone()));
        Ok(content)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    /// A placement of impostors with the given objects and CPVs of the
    /// given regions (x and z ranges; y is 0..1) drawing the given
    /// impostors.
    fn placement(objects: &[&[u32]], cpvs: &[([f64; 4], &[u32])]) -> Placement {
        let impostors: Vec<Value> = objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                json!({"id": i, "node": i, "objects": o,
                    "sphere": {"center": [0.0, 0.0, 0.0], "radius": 1.0},
                    "view_cell": {"box": {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}},
                    "layers": 1, "resolution": 8, "memory_bytes": 0, "time_ms": 0.0})
            })
            .collect();
        let cpvs: Vec<Value> = cpvs
            .iter()
            .enumerate()
            .map(|(i, ([x0, x1, z0, z1], imps))| {
                json!({"id": i, "region": {"min": [x0, 0.0, z0], "max": [x1, 1.0, z1]},
                    "directions": {"face": 0, "u": [-1.0, 1.0], "v": [-1.0, 1.0]},
                    "time_ms_original": 1.0, "time_ms_final": 1.0, "solved": true,
                    "impostors": imps})
            })
            .collect();
        serde_json::from_value(json!({
            "summary": {"cpvs": cpvs.len(), "candidates": 0, "impostors": impostors.len(),
                "memory_bytes": 0, "unsolved_cpvs": 0, "target_frame_time_ms": 1.0},
            "impostors": impostors,
            "cpvs": cpvs,
        }))
        .unwrap()
    }

    /// What the switch draws at `(x, z)`.
    fn at(s: &Switch, x: f64, z: f64) -> Vec<u32> {
        let hits: Vec<&[u32]> = s
            .leaves()
            .into_iter()
            .filter(|(b, _)| b.min.x < x && x < b.max.x && b.min.z < z && z < b.max.z)
            .map(|(_, i)| i)
            .collect();
        assert_eq!(hits.len(), 1, "({x}, {z}) in {} leaves", hits.len());
        hits[0].to_vec()
    }

    #[test]
    fn leaves_draw_the_impostors_of_every_cpv_holding_them_without_drawing_an_object_twice() {
        // Impostor 0 is a cluster of objects 0..3, 1 and 2 sub-clusters of
        // it, 3 another object of the group.
        let p = placement(
            &[&[0, 1, 2], &[0], &[1, 2], &[3]],
            &[
                // Two directions of one region: the cluster in one, a
                // sub-cluster in the other; the cluster is drawn.
                ([0.0, 10.0, 0.0, 10.0], &[0]),
                ([0.0, 10.0, 0.0, 10.0], &[1]),
                // Beside it both sub-clusters, and in a box inside that
                // region (a split CPV's region) also impostor 3.
                ([10.0, 20.0, 0.0, 10.0], &[1, 2]),
                ([12.0, 18.0, 2.0, 8.0], &[3]),
                // A region drawing none of them is outside the switch.
                ([0.0, 10.0, 10.0, 20.0], &[]),
            ],
        );
        let s = group_switch(&p, &[0, 1, 2, 3]).unwrap();
        let b = s.bounds();
        assert_eq!((b.min, b.max), (DVec3::ZERO, DVec3::new(20.0, 1.0, 10.0)));
        assert_eq!(at(&s, 5.0, 5.0), vec![0]);
        assert_eq!(at(&s, 0.1, 9.9), vec![0]);
        assert_eq!(at(&s, 11.0, 5.0), vec![1, 2]);
        assert_eq!(at(&s, 15.0, 9.0), vec![1, 2]);
        assert_eq!(at(&s, 15.0, 5.0), vec![1, 2, 3]);
        // The leaves tile the box: their volumes add up to its own.
        let leaves = s.leaves();
        let volume = |b: &Aabb| (b.max - b.min).x * (b.max - b.min).y * (b.max - b.min).z;
        let sum: f64 = leaves.iter().map(|(b, _)| volume(b)).sum();
        assert!((sum - volume(&b)).abs() < 1e-9, "{sum} vs {}", volume(&b));
        // Cut only where a region's face is: the cluster's region is one
        // leaf, the ring around the inner box at most four.
        assert!(leaves.len() <= 6, "{} leaves: {leaves:?}", leaves.len());
        // A group no CPV draws has no switch.
        assert_eq!(group_switch(&p, &[5]), None);
        // Deterministic: the same tree again.
        assert_eq!(group_switch(&p, &[0, 1, 2, 3]), Some(s));
    }

    #[test]
    fn a_cut_merges_parts_drawing_the_same_impostors() {
        // Two regions side by side drawing the same impostor: one leaf.
        let p = placement(
            &[&[0]],
            &[
                ([0.0, 10.0, 0.0, 10.0], &[0]),
                ([10.0, 20.0, 0.0, 10.0], &[0]),
            ],
        );
        let s = group_switch(&p, &[0]).unwrap();
        assert_eq!(s.leaves().len(), 1, "{s:?}");
        assert_eq!(at(&s, 15.0, 5.0), vec![0]);
    }
}
