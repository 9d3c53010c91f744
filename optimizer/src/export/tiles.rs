//! 3D Tiles 1.1 export of a placement (`impostor tiles`): a `tileset.json`
//! whose contents are GLB files (glTF content, as 3D Tiles 1.1 allows
//! without extension).
//!
//! The hierarchy makes REPLACE refinement carry the placement's switch:
//!
//! - the root (refinement ADD) draws the objects no impostor replaces;
//! - per *cluster group* (impostors whose object sets meet, joined: a
//!   cluster's impostors for its several view cells and those of its
//!   nested sub-clusters), a *cluster tile* (refinement REPLACE) draws the
//!   group's geometry, each object once;
//! - each impostor is one child of its group's cluster tile, an *impostor
//!   tile* whose content is its layers and whose `viewerRequestVolume` is
//!   a box around its view cell (the cell itself for box cells; for shafts
//!   the box bounding the shaft's part inside the view space).
//!
//! Where a runtime honours request volumes, a child outside its request
//! volume is neither requested nor refined into, so outside the view cells
//! the cluster's geometry is drawn and inside a group's only view cell its
//! impostor replaces it: the placement's switch exactly. A REPLACE tile
//! refines into its children only where all of them may be drawn, so for a
//! group of several impostors 3D Tiles cannot say "the geometry unless
//! inside any one of the cells" (volumes cannot be unions or complements).
//! CesiumJS's base traversal (read from its source, not run here) then
//! keeps the geometry, and as it selects no child of a REPLACE tile that
//! does not refine, draws none of the group's impostors. The grouping
//! guarantees no object's geometry is written twice and every impostor
//! appears exactly once.
//!
//! Not every runtime honours request volumes. NASA-AMMOS's
//! `3d-tiles-renderer` (0.5.3; `server/tests/tiles_client.rs` loads the
//! small city's tileset in it) ignores them (its issue #74) and refines by
//! screen-space error alone: within reach of a group (the geometric errors
//! below) it draws every impostor of the group whose box is in view,
//! whichever view cell holds the viewer, and not the group's geometry;
//! farther away it draws the geometry and none of the impostors. The test
//! asserts exactly that, so a change on either side shows.
//!
//! Each impostor's content has an atlas of its own, just large enough for
//! its layers.
//!
//! Geometric errors are chosen so that refinement follows the request
//! volumes alone: with the job's camera and the customary 16-pixel
//! screen-space error limit, every cluster tile asks to be refined from
//! anywhere its volumes reach; the impostor tiles are leaves (error 0) and
//! the root's error is twice the largest below it, so errors decrease
//! downwards.
//!
//! Coordinates: glTF content is y-up; 3D Tiles is z-up and runtimes turn
//! glTF content from y-up to z-up (a rotation of +90° about x, `(x, y, z)
//! ↦ (x, −z, y)`), so every bounding and request volume here is written in
//! that z-up frame, and no tile carries a transform of its own.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::content::{instances_by_object, objects_glb};
use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, Placement, Summary, ViewCellJson};
use crate::bake::{BakeOptions, Layer, read_layers, write_glb};
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::glb::scene_extras;
use crate::{Error, Result};

/// The screen-space error, in pixels, above which runtimes refine a tile
/// (CesiumJS's default `maximumScreenSpaceError`).
pub const MAX_SCREEN_SPACE_ERROR_PX: f64 = 16.0;

/// A tileset JSON document (the subset this export writes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Tileset {
    /// The asset.
    pub asset: Asset,
    /// The error, metres, when the tileset is not drawn at all.
    pub geometric_error: f64,
    /// The root tile.
    pub root: Tile,
}

/// `asset`: the 3D Tiles version.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Asset {
    /// `"1.1"`.
    pub version: String,
}

/// A tile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Tile {
    /// Encloses the tile's content and its children's volumes.
    pub bounding_volume: BoundingVolume,
    /// The viewer must be inside it for the tile to be requested and drawn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viewer_request_volume: Option<BoundingVolume>,
    /// The error, metres, when this tile is drawn and its children are not.
    pub geometric_error: f64,
    /// How children refine this tile.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refine: Option<Refine>,
    /// The tile's content.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub content: Option<Content>,
    /// Children.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub children: Vec<Tile>,
    /// What the tile is: `{"impostor": id}` for impostor tiles,
    /// `{"cluster": node, "impostor": id, "objects": [...]}` for cluster
    /// tiles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extras: Option<Value>,
}

/// A bounding volume, z-up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BoundingVolume {
    /// Centre, then the x, y and z half-axis vectors.
    Box([f64; 12]),
}

/// Refinement.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Refine {
    /// Children are drawn with the tile.
    Add,
    /// Children are drawn instead of the tile.
    Replace,
}

/// A tile's content.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Content {
    /// Relative to the tileset JSON.
    pub uri: String,
}

/// An axis-aligned box, y-up (glTF) world coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: DVec3,
    /// Maximum corner.
    pub max: DVec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    fn add(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    fn is_empty(&self) -> bool {
        (0..3).any(|a| self.min[a] > self.max[a])
    }

    fn intersection(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.max(o.min),
            max: self.max.min(o.max),
        }
    }

    /// The 3D Tiles box of this y-up box, in the z-up frame. Half-axes are
    /// at least a millimetre, so flat contents get a proper box.
    pub fn to_tiles(self) -> BoundingVolume {
        let (min, max) = (z_up(self.min), z_up(self.max));
        let (lo, hi) = (min.min(max), min.max(max));
        let c = (lo + hi) * 0.5;
        let h = ((hi - lo) * 0.5).max(DVec3::splat(1e-3));
        BoundingVolume::Box([c.x, c.y, c.z, h.x, 0.0, 0.0, 0.0, h.y, 0.0, 0.0, 0.0, h.z])
    }
}

/// A y-up (glTF) point in the z-up frame of 3D Tiles.
pub fn z_up(p: DVec3) -> DVec3 {
    DVec3::new(p.x, -p.z, p.y)
}

/// The box (y-up) a runtime should request an impostor from: the view cell
/// for box cells; for shafts, the box of the shaft's part inside the view
/// space (the shaft, truncated where it leaves the view space's farthest
/// corner, bounded by its apex and its cap disc, and clipped to the view
/// space).
pub fn request_box(imp: &PlacedImpostor, view_space: Aabb) -> Aabb {
    match imp.view_cell {
        ViewCellJson::Box { min, max } => Aabb {
            min: DVec3::from_array(min),
            max: DVec3::from_array(max),
        },
        ViewCellJson::Shaft {
            apex,
            axis,
            half_angle_deg,
            ..
        } => {
            let apex = DVec3::from_array(apex);
            let axis = DVec3::from_array(axis).normalize();
            let corners = (0..8).map(|k| {
                DVec3::new(
                    if k & 1 == 0 {
                        view_space.min.x
                    } else {
                        view_space.max.x
                    },
                    if k & 2 == 0 {
                        view_space.min.y
                    } else {
                        view_space.max.y
                    },
                    if k & 4 == 0 {
                        view_space.min.z
                    } else {
                        view_space.max.z
                    },
                )
            });
            let reach = corners.map(|c| c.distance(apex)).fold(0.0, f64::max);
            let mut cone = Aabb::EMPTY;
            if half_angle_deg < 89.0 {
                // Every point of the shaft within `reach` of the apex lies
                // in the cone up to axial distance `reach`: the convex hull
                // of the apex and the cap disc.
                let cap = apex + axis * reach;
                let r = reach * half_angle_deg.to_radians().tan();
                let spread = DVec3::new(
                    (1.0 - axis.x * axis.x).max(0.0).sqrt(),
                    (1.0 - axis.y * axis.y).max(0.0).sqrt(),
                    (1.0 - axis.z * axis.z).max(0.0).sqrt(),
                ) * r;
                cone.add(apex);
                cone.add(cap - spread);
                cone.add(cap + spread);
            } else {
                cone.add(apex - DVec3::splat(reach));
                cone.add(apex + DVec3::splat(reach));
            }
            let clipped = cone.intersection(view_space);
            if clipped.is_empty() { cone } else { clipped }
        }
    }
}

/// The geometric error at which a tile at most `distance` metres from the
/// viewer still asks to be refined under the job's camera, with a margin
/// of two.
fn refining_error(job: &Job, distance: f64) -> f64 {
    let fov = job.camera.fov_deg.to_radians();
    let height = f64::from(job.camera.resolution[1].max(1));
    2.0 * MAX_SCREEN_SPACE_ERROR_PX * distance.max(1.0) * 2.0 * (fov * 0.5).tan() / height
}

/// The files of a tileset: `tileset.json` first, then the GLB contents, by
/// name (relative paths).
pub type TilesetFiles = Vec<(String, Vec<u8>)>;

/// The inputs of [`export`] besides the scene.
pub struct TilesInput<'a> {
    /// The job the placement was made with (view space and camera).
    pub job: &'a Job,
    /// The placement.
    pub placement: &'a Placement,
    /// Names the placement in errors.
    pub placement_source: &'a str,
    /// The GLB `impostor bake` wrote for the placement.
    pub baked: &'a [u8],
    /// Names the baked GLB in errors.
    pub baked_source: &'a str,
}

/// Builds the tileset of `input.placement` over `scene` and its geometry
/// `geom` (see the module documentation).
pub fn export(scene: &Scene, geom: &SceneGeometry, input: &TilesInput<'_>) -> Result<TilesetFiles> {
    let TilesInput {
        job,
        placement,
        placement_source,
        baked,
        baked_source,
    } = *input;
    if geom.object_count() != scene.objects.len() {
        return Err(Error::Internal(format!(
            "tiles: the geometry has {} objects, the scene {}",
            geom.object_count(),
            scene.objects.len()
        )));
    }
    placement.validate(scene, placement_source)?;
    let layers = baked_layers(placement, baked, baked_source)?;

    let groups = cluster_groups(placement, scene.objects.len());
    let mut replaced = vec![false; scene.objects.len()];
    let object_box = |o: u32| Aabb {
        min: scene.objects[o as usize].min,
        max: scene.objects[o as usize].max,
    };
    let view_space = Aabb {
        min: DVec3::from_array(job.view_space.min),
        max: DVec3::from_array(job.view_space.max),
    };
    let by_object = instances_by_object(geom);
    let mut files: TilesetFiles = vec![(String::new(), Vec::new())];
    let mut all = view_space;
    let mut children = Vec::with_capacity(groups.len());
    let mut child_boxes = Vec::with_capacity(groups.len());
    // A content holds one impostor: its atlas just holds its layers
    // (⌈√n⌉ a side), not the bake's 4096-texel-wide shared page, which
    // would leave most of every impostor's texture empty.
    let opts = BakeOptions {
        atlas_size: 0,
        ..BakeOptions::default()
    };
    for (g, (objects, impostors)) in groups.iter().enumerate() {
        for &o in objects {
            replaced[o as usize] = true;
        }
        let mut tile_box = objects
            .iter()
            .fold(Aabb::EMPTY, |b, &o| b.union(object_box(o)));
        let mut reach = tile_box;
        let mut impostor_tiles = Vec::with_capacity(impostors.len());
        for &id in impostors {
            let imp = &placement.impostors[id as usize];
            let own = &layers[id as usize];
            let mut quads = Aabb::EMPTY;
            for l in own {
                l.corners.iter().for_each(|&c| quads.add(c));
            }
            let content = if own.is_empty() {
                None
            } else {
                let name = format!("impostor-{id}.glb");
                files.push((
                    name.clone(),
                    write_glb(
                        placement,
                        own,
                        &geom.object_nodes,
                        Some(&job.view_space),
                        &opts,
                    )?
                    .glb,
                ));
                Some(Content { uri: name })
            };
            let quads = if quads.is_empty() {
                imp.objects
                    .iter()
                    .fold(Aabb::EMPTY, |b, &o| b.union(object_box(o)))
            } else {
                quads
            };
            let request = request_box(imp, view_space);
            tile_box = tile_box.union(quads);
            reach = reach.union(quads).union(request);
            impostor_tiles.push(Tile {
                bounding_volume: quads.to_tiles(),
                viewer_request_volume: Some(request.to_tiles()),
                geometric_error: 0.0,
                refine: None,
                content,
                children: Vec::new(),
                extras: Some(json!({ "impostor": id, "cluster": imp.node })),
            });
        }
        let name = format!("cluster-{g}.glb");
        let cluster_content = objects_glb(geom, &by_object, objects, &name)?.map(|glb| {
            files.push((name.clone(), glb));
            Content { uri: name }
        });
        all = all.union(reach);
        child_boxes.push(tile_box);
        children.push(Tile {
            bounding_volume: tile_box.to_tiles(),
            viewer_request_volume: None,
            // The farthest a viewer in any of its volumes is from it.
            geometric_error: refining_error(job, reach.min.distance(reach.max)),
            refine: Some(Refine::Replace),
            content: cluster_content,
            children: impostor_tiles,
            extras: Some(json!({ "impostors": impostors, "objects": objects })),
        });
    }
    let rest: Vec<u32> = (0..scene.objects.len() as u32)
        .filter(|&o| !replaced[o as usize])
        .collect();
    let mut root_box = Aabb::EMPTY;
    for &o in &rest {
        root_box = root_box.union(object_box(o));
    }
    for &b in &child_boxes {
        root_box = root_box.union(b);
    }
    let name = "scene.glb".to_string();
    let root_content = objects_glb(geom, &by_object, &rest, &name)?.map(|glb| {
        files.push((name.clone(), glb));
        Content { uri: name }
    });
    let below = children
        .iter()
        .map(|c| c.geometric_error)
        .fold(0.0, f64::max);
    let root_error = 2.0 * below.max(refining_error(job, all.min.distance(all.max)));
    let tileset = Tileset {
        asset: Asset {
            version: "1.1".into(),
        },
        geometric_error: 2.0 * root_error,
        root: Tile {
            bounding_volume: root_box.to_tiles(),
            viewer_request_volume: None,
            geometric_error: root_error,
            refine: Some(Refine::Add),
            content: root_content,
            children,
            extras: None,
        },
    };
    let mut json = serde_json::to_vec_pretty(&tileset)
        .map_err(|e| Error::Internal(format!("tileset JSON: {e}")))?;
    json.push(b'\n');
    files[0] = ("tileset.json".into(), json);
    Ok(files)
}

/// The impostors grouped by shared objects (connected components of "has
/// an object in common"), each group as (its objects ascending, its
/// impostor ids ascending), ordered by their first impostor.
fn cluster_groups(placement: &Placement, objects: usize) -> Vec<(Vec<u32>, Vec<u32>)> {
    let n = placement.impostors.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut first: Vec<Option<usize>> = vec![None; objects];
    for imp in &placement.impostors {
        for &o in &imp.objects {
            match first[o as usize] {
                None => first[o as usize] = Some(imp.id as usize),
                Some(other) => {
                    let (a, b) = (find(&mut parent, other), find(&mut parent, imp.id as usize));
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut groups: Vec<(Vec<u32>, Vec<u32>)> = Vec::new();
    let mut index_of: Vec<Option<usize>> = vec![None; n];
    for i in 0..n {
        let r = find(&mut parent, i);
        let g = *index_of[r].get_or_insert_with(|| {
            groups.push((Vec::new(), Vec::new()));
            groups.len() - 1
        });
        groups[g].1.push(i as u32);
        groups[g]
            .0
            .extend_from_slice(&placement.impostors[i].objects);
    }
    for (objects, _) in &mut groups {
        objects.sort_unstable();
        objects.dedup();
    }
    groups
}

/// The layers of `baked`, per impostor of `placement`, checked to belong
/// to it: every impostor named exists with the placement's resolution, and
/// an impostor without layers is one whose layers were all empty (the file
/// names the placement's summary), else it is missing.
fn baked_layers(placement: &Placement, baked: &[u8], source: &str) -> Result<Vec<Vec<Layer>>> {
    let layers = read_layers(baked, source)?;
    let mut per: Vec<Vec<Layer>> = vec![Vec::new(); placement.impostors.len()];
    for l in layers {
        let Some(imp) = placement.impostors.get(l.impostor as usize) else {
            return Err(Error::bad(
                source,
                format!(
                    "names impostor {}, which the placement does not have: it was not baked from this placement",
                    l.impostor
                ),
            ));
        };
        if l.res != imp.resolution {
            return Err(Error::bad(
                source,
                format!(
                    "impostor {} has {}-texel layers, the placement {}: it was not baked from this placement",
                    l.impostor, l.res, imp.resolution
                ),
            ));
        }
        per[l.impostor as usize].push(l);
    }
    let summary: Option<Summary> = scene_extras(baked, source)?
        .and_then(|e| e.get("impostor").and_then(|i| i.get("summary")).cloned())
        .and_then(|s| serde_json::from_value(s).ok());
    match summary {
        Some(s) if s != placement.summary => Err(Error::bad(
            source,
            "its placement summary differs from the placement's: it was not baked from this placement",
        )),
        Some(_) => Ok(per),
        None => match per.iter().position(Vec::is_empty) {
            Some(k) => Err(Error::bad(
                source,
                format!("impostor {k} of the placement is missing from the file"),
            )),
            None => Ok(per),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::placement::SphereJson;

    fn imp(id: u32, objects: Vec<u32>, view_cell: ViewCellJson) -> PlacedImpostor {
        PlacedImpostor {
            id,
            node: id,
            objects,
            sphere: SphereJson {
                center: [0.0; 3],
                radius: 1.0,
            },
            view_cell,
            layers: 1,
            resolution: 8,
            memory_bytes: 0,
            time_ms: 0.0,
        }
    }

    fn shaft(axis: [f64; 3], half_angle_deg: f64) -> ViewCellJson {
        ViewCellJson::Shaft {
            apex: [1.0, 2.0, 3.0],
            axis,
            half_angle_deg,
            min_distance: 5.0,
        }
    }

    #[test]
    fn shaft_request_boxes_hold_the_shaft_inside_the_view_space() {
        let vs = Aabb {
            min: DVec3::new(-50.0, -5.0, -40.0),
            max: DVec3::new(60.0, 30.0, 45.0),
        };
        let mut rng = crate::math::rng::Rng::new(9);
        let mut inside = 0;
        for k in 0..40 {
            let a = DVec3::new(rng.f64() - 0.5, rng.f64() - 0.5, rng.f64() - 0.5).normalize();
            let angle = [5.0, 20.0, 45.0, 80.0, 120.0][k % 5];
            let i = imp(0, vec![0], shaft(a.to_array(), angle));
            let b = request_box(&i, vs);
            for _ in 0..400 {
                let p = vs.min + (vs.max - vs.min) * DVec3::new(rng.f64(), rng.f64(), rng.f64());
                let d = p - DVec3::new(1.0, 2.0, 3.0);
                if d.length() >= 5.0 && d.angle_between(a).to_degrees() <= angle {
                    inside += 1;
                    let held = (0..3).all(|x| b.min[x] - 1e-9 <= p[x] && p[x] <= b.max[x] + 1e-9);
                    assert!(held, "{p} outside {b:?} (axis {a}, {angle}°)");
                }
            }
            // Clipped to the view space.
            assert!((0..3).all(|x| b.min[x] >= vs.min[x] && b.max[x] <= vs.max[x]));
        }
        assert!(inside > 1000, "the shafts met only {inside} sample points");
        // A narrow shaft along +x gets a box narrower than the view space.
        let b = request_box(&imp(0, vec![0], shaft([1.0, 0.0, 0.0], 5.0)), vs);
        assert!(b.max.y - b.min.y < 0.5 * (vs.max.y - vs.min.y), "{b:?}");
        assert!(b.min.x >= 1.0, "{b:?}");
    }

    #[test]
    fn box_cells_are_their_own_request_box_and_z_up_turns_y_into_z() {
        let cell = ViewCellJson::Box {
            min: [1.0, 2.0, 3.0],
            max: [4.0, 5.0, 6.0],
        };
        let vs = Aabb {
            min: DVec3::ZERO,
            max: DVec3::splat(2.0),
        };
        let b = request_box(&imp(0, vec![0], cell), vs);
        assert_eq!(
            (b.min, b.max),
            (DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 5.0, 6.0))
        );
        assert_eq!(z_up(DVec3::new(1.0, 2.0, 3.0)), DVec3::new(1.0, -3.0, 2.0));
        let BoundingVolume::Box(t) = b.to_tiles();
        // Centre (2.5, 3.5, 4.5) y-up is (2.5, −4.5, 3.5) z-up; half sizes
        // (1.5, 1.5, 1.5).
        assert_eq!(
            t,
            [2.5, -4.5, 3.5, 1.5, 0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 1.5]
        );
    }

    #[test]
    fn impostors_sharing_objects_form_one_group() {
        let cell = || ViewCellJson::Box {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let mut p = Placement {
            summary: serde_json::from_value(json!({
                "cpvs": 0, "candidates": 0, "impostors": 4, "memory_bytes": 0,
                "unsolved_cpvs": 0, "target_frame_time_ms": 1.0
            }))
            .unwrap(),
            impostors: vec![
                imp(0, vec![0, 1, 2], cell()),
                imp(1, vec![5], cell()),
                imp(2, vec![2], cell()),
                imp(3, vec![0, 1, 2], cell()),
            ],
            cpvs: Vec::new(),
        };
        let groups = cluster_groups(&p, 6);
        assert_eq!(
            groups,
            vec![(vec![0, 1, 2], vec![0, 2, 3]), (vec![5], vec![1])]
        );
        // A chain through a shared object joins groups.
        p.impostors.push(imp(4, vec![2, 5], cell()));
        let groups = cluster_groups(&p, 6);
        assert_eq!(groups, vec![(vec![0, 1, 2, 5], vec![0, 1, 2, 3, 4])]);
    }
}
