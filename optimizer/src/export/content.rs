//! Tile contents: GLB files of some of a scene's objects, written with the
//! GLB builder ([`crate::scene::glb`]) from the loaded geometry.

use std::collections::BTreeMap;

use glam::DMat4;

use crate::scene::geometry::SceneGeometry;
use crate::scene::glb::{self, GeometryId, GlbBuilder, MeshPrimitive, Node};
use crate::{Error, Result};

/// Per object id, its instance indices.
pub(super) fn instances_by_object(geom: &SceneGeometry) -> Vec<Vec<u32>> {
    let mut by_object: Vec<Vec<u32>> = vec![Vec::new(); geom.object_count()];
    for (i, inst) in geom.instances.iter().enumerate() {
        by_object[inst.object as usize].push(i as u32);
    }
    by_object
}

/// A GLB drawing the objects `objects` of `geom` where the scene draws
/// them: one node per object instance, its world transform as the node's
/// matrix, meshes, materials and textures written once per file (textures
/// re-encoded as PNG); `None` when the objects have no triangles. `what`
/// names the file in errors.
pub(super) fn objects_glb(
    geom: &SceneGeometry,
    by_object: &[Vec<u32>],
    objects: &[u32],
    what: &str,
) -> Result<Option<Vec<u8>>> {
    let mut b = GlbBuilder::new();
    let mut geometries: BTreeMap<u32, GeometryId> = BTreeMap::new();
    let mut materials: BTreeMap<u32, u32> = BTreeMap::new();
    let mut textures: BTreeMap<u32, u32> = BTreeMap::new();
    let mut roots = Vec::new();
    for &o in objects {
        for &ii in &by_object[o as usize] {
            let inst = &geom.instances[ii as usize];
            let mesh = &geom.meshes[inst.mesh as usize];
            if mesh.indices.is_empty() {
                continue;
            }
            let g = match geometries.get(&inst.mesh) {
                Some(&g) => g,
                None => {
                    let positions: Vec<[f32; 3]> =
                        mesh.positions.iter().map(|p| p.to_array()).collect();
                    let normals: Vec<[f32; 3]> =
                        mesh.normals.iter().map(|n| n.to_array()).collect();
                    let uvs: Vec<[f32; 2]> = mesh.uvs.iter().map(|t| t.to_array()).collect();
                    let g = b.add_geometry(&glb::Geometry {
                        positions: &positions,
                        normals: (normals.len() == positions.len()).then_some(&normals[..]),
                        texcoords: (uvs.len() == positions.len()).then_some(&uvs[..]),
                        indices: &mesh.indices,
                    })?;
                    geometries.insert(inst.mesh, g);
                    g
                }
            };
            let material = match materials.get(&mesh.material) {
                Some(&m) => m,
                None => {
                    let mut m = geom
                        .materials
                        .get(mesh.material as usize)
                        .cloned()
                        .unwrap_or_default();
                    if let Some(t) = m.base_color_texture {
                        m.base_color_texture = Some(texture(&mut b, geom, t, &mut textures, what)?);
                    }
                    let index = b.add_material(&m)?;
                    materials.insert(mesh.material, index);
                    index
                }
            };
            let mesh_index = b.add_mesh(
                &format!("object {o}"),
                &[MeshPrimitive {
                    geometry: g,
                    material: Some(material),
                }],
            )?;
            let matrix = DMat4::from(inst.transform).as_mat4().to_cols_array();
            let mut node = Node::new(format!("object {o}")).with_mesh(mesh_index);
            if matrix != glam::Mat4::IDENTITY.to_cols_array() {
                node = node.with_matrix(matrix);
            }
            roots.push(b.add_node(node)?);
        }
    }
    if roots.is_empty() {
        return Ok(None);
    }
    b.set_scene_roots(&roots)?;
    Ok(Some(b.finish()))
}

/// The file's texture for the geometry's texture `t`, written once.
fn texture(
    b: &mut GlbBuilder,
    geom: &SceneGeometry,
    t: u32,
    written: &mut BTreeMap<u32, u32>,
    what: &str,
) -> Result<u32> {
    if let Some(&w) = written.get(&t) {
        return Ok(w);
    }
    let tex = geom
        .textures
        .get(t as usize)
        .ok_or_else(|| Error::Internal(format!("{what}: texture {t} does not exist")))?;
    let index = b.add_loaded_texture(&format!("texture {t}"), tex)?;
    written.insert(t, index);
    Ok(index)
}
