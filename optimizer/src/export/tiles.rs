//! 3D Tiles 1.1 export of a placement (`impostor tiles`): a `tileset.json`
//! whose contents are GLB files (glTF content, as 3D Tiles 1.1 allows
//! without extension).
//!
//! The hierarchy carries the placement's switch in request volumes and
//! refinement, as a runtime that honours `viewerRequestVolume` (CesiumJS)
//! reads them:
//!
//! - the root (refinement ADD) draws the objects no impostor replaces;
//! - per *cluster group* (impostors whose object sets meet, joined: a
//!   cluster's impostors for its several view cells and those of its
//!   nested sub-clusters), a *cluster tile* (refinement REPLACE) draws the
//!   group's geometry; its one child, the *switch*, has no content and
//!   the box of the CPV regions that draw any of the group's impostors as
//!   request volume;
//! - below it, a k-d tree of boxes of viewer positions
//!   ([`super::switch`]; refinement ADD, no content, each box its request
//!   volume) whose leaves hold what the group draws from there: the
//!   impostors the placement draws in CPVs whose regions hold the leaf, and
//!   a content with the group's objects none of them replaces (or the
//!   whole group's geometry where none is drawn).
//!
//! Inside the switch's box the viewer is in exactly one leaf (up to shared
//! faces), so the group draws that leaf's contents; outside it the switch
//! is outside its request volume, the cluster tile does not refine (a
//! REPLACE tile refines only when all its children may be drawn) and draws
//! the group's geometry. A leaf lies inside the regions of the CPVs it
//! takes impostors from, so inside those impostors' view cells. What 3D
//! Tiles cannot carry is the view direction: a leaf draws the impostors of
//! every CPV of its region, whichever way the viewer looks (where two
//! replace common objects, the one replacing more). An impostor's content
//! is one file, referenced by every leaf drawing it; the geometry of a
//! group's objects left beside impostors is one file per distinct set.
//!
//! Not every runtime honours request volumes. NASA-AMMOS's
//! `3d-tiles-renderer` (0.5.3; `server/tests/tiles_client.rs` loads the
//! small city's tileset in it) ignores them (its issue #74) and refines by
//! screen-space error alone: within reach of a group (the geometric errors
//! below) it draws every leaf's contents at once; farther away it draws the
//! group's geometry and none of its impostors. `server/tests/cesium_client.rs`
//! runs the tileset in CesiumJS and checks the switch view by view.
//!
//! Each impostor's content has an atlas of its own, just large enough for
//! its layers.
//!
//! Geometric errors are chosen so that refinement follows the request
//! volumes alone: with the job's camera and the customary 16-pixel
//! screen-space error limit, every cluster tile and every tile of its
//! switch asks to be refined from anywhere the switch reaches; the
//! contents below the leaves have error 0 and the root's error is twice
//! the largest below it, so errors do not increase downwards.
//!
//! Coordinates: glTF content is y-up; 3D Tiles is z-up and runtimes turn
//! glTF content from y-up to z-up (a rotation of +90° about x, `(x, y, z)
//! ↦ (x, −z, y)`), so every bounding and request volume here is written in
//! that z-up frame, and no tile carries a transform of its own.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::content::{instances_by_object, objects_glb};
use super::switch::{GroupTiles, Switch, group_switches};
use crate::api::job::Job;
use crate::api::placement::{Placement, Summary};
use crate::bake::{BakeOptions, Layer, read_layers, write_glb};
use crate::math::geom::Aabb;
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
    /// What the tile is: `{"impostors": [ids], "objects": [ids]}` for
    /// cluster tiles, `{"impostors": [ids]}` for switch leaves (the
    /// impostors drawn there), `{"impostor": id, "cluster": node}` for an
    /// impostor's content, `{"objects": [ids]}` for geometry left beside
    /// impostors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extras: Option<Value>,
}

/// A bounding volume, z-up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BoundingVolume {
    /// Centre, then the x, y and z half-axis vectors.
    Box([f64; 12]),
    /// Centre, then radius.
    Sphere([f64; 4]),
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

/// The 3D Tiles box of a y-up (glTF) box, in the z-up frame. Half-axes
/// are at least a millimetre, so flat contents get a proper box.
pub fn tiles_box(b: &Aabb) -> BoundingVolume {
    let (min, max) = (z_up(b.min), z_up(b.max));
    let (lo, hi) = (min.min(max), min.max(max));
    let c = (lo + hi) * 0.5;
    let h = ((hi - lo) * 0.5).max(DVec3::splat(1e-3));
    BoundingVolume::Box([c.x, c.y, c.z, h.x, 0.0, 0.0, 0.0, h.y, 0.0, 0.0, 0.0, h.z])
}

/// The 3D Tiles sphere around a y-up box, in the z-up frame (radius at
/// least a millimetre).
pub fn tiles_sphere(b: &Aabb) -> BoundingVolume {
    let c = z_up(b.center());
    let r = (0.5 * b.min.distance(b.max)).max(1e-3);
    BoundingVolume::Sphere([c.x, c.y, c.z, r])
}

/// A y-up (glTF) point in the z-up frame of 3D Tiles.
pub fn z_up(p: DVec3) -> DVec3 {
    DVec3::new(p.x, -p.z, p.y)
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
    let group_ids: Vec<&[u32]> = groups.iter().map(|(_, ids)| ids.as_slice()).collect();
    let switches: Vec<Option<Switch>> = group_switches(placement, &group_ids);
    let mut drawn = vec![false; placement.impostors.len()];
    for s in switches.iter().flatten() {
        for (_, ids) in s.leaves() {
            ids.iter().for_each(|&i| drawn[i as usize] = true);
        }
    }
    // Each impostor some leaf draws as one content, written once however
    // many leaves draw it.
    let mut impostor_content: Vec<Option<(Content, Aabb)>> = vec![None; placement.impostors.len()];
    for (id, own) in layers.iter().enumerate() {
        if own.is_empty() || !drawn[id] {
            continue;
        }
        let mut quads = Aabb::EMPTY;
        for l in own {
            l.corners.iter().for_each(|&c| quads.add(c));
        }
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
        impostor_content[id] = Some((Content { uri: name }, quads));
    }
    for (g, (objects, impostors)) in groups.iter().enumerate() {
        for &o in objects {
            replaced[o as usize] = true;
        }
        let group_box = |objects: &[u32]| {
            objects
                .iter()
                .fold(Aabb::EMPTY, |b, &o| b.union(&object_box(o)))
        };
        let mut tile_box = group_box(objects);
        for &id in impostors {
            if let Some((_, quads)) = &impostor_content[id as usize] {
                tile_box = tile_box.union(quads);
            }
        }
        let switch = &switches[g];
        let reach = switch
            .as_ref()
            .map_or(tile_box, |s| tile_box.union(&s.bounds()));
        // The farthest a viewer in any of its leaves is from it.
        let error = refining_error(job, reach.min.distance(reach.max));
        let name = format!("cluster-{g}.glb");
        let cluster_content = objects_glb(geom, &by_object, objects, &name)?.map(|glb| {
            files.push((name.clone(), glb));
            Content { uri: name }
        });
        let mut group = GroupTiles {
            group: g,
            scene,
            objects,
            bounds: tile_box,
            error,
            cluster_content: cluster_content.clone(),
            impostor_content: &impostor_content,
            rests: Vec::new(),
        };
        let below = match switch {
            Some(s) => vec![group.switch_tile(s, placement, &mut |name, rest| {
                objects_glb(geom, &by_object, rest, name).map(|glb| {
                    glb.map(|glb| {
                        files.push((name.to_string(), glb));
                    })
                    .is_some()
                })
            })?],
            None => Vec::new(),
        };
        all = all.union(&reach);
        child_boxes.push(tile_box);
        children.push(Tile {
            bounding_volume: tiles_box(&tile_box),
            viewer_request_volume: None,
            geometric_error: error,
            refine: Some(Refine::Replace),
            content: cluster_content,
            children: below,
            extras: Some(json!({ "impostors": impostors, "objects": objects })),
        });
    }
    let rest: Vec<u32> = (0..scene.objects.len() as u32)
        .filter(|&o| !replaced[o as usize])
        .collect();
    let mut root_box = Aabb::EMPTY;
    for &o in &rest {
        root_box = root_box.union(&object_box(o));
    }
    for &b in &child_boxes {
        root_box = root_box.union(&b);
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
            bounding_volume: tiles_box(&root_box),
            viewer_request_volume: None,
            geometric_error: root_error,
            refine: Some(Refine::Add),
            content: root_content,
            children,
            extras: None,
        },
    };
    let mut json =
        serde_json::to_vec(&tileset).map_err(|e| Error::Internal(format!("tileset JSON: {e}")))?;
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
    use crate::api::placement::{PlacedImpostor, SphereJson, ViewCellJson};

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

    #[test]
    fn z_up_turns_y_into_z() {
        let b = Aabb {
            min: DVec3::new(1.0, 2.0, 3.0),
            max: DVec3::new(4.0, 5.0, 6.0),
        };
        assert_eq!(z_up(DVec3::new(1.0, 2.0, 3.0)), DVec3::new(1.0, -3.0, 2.0));
        let BoundingVolume::Box(t) = tiles_box(&b) else {
            panic!("a box")
        };
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
