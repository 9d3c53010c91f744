//! Reading back what the writer attaches to objects: node `extras`, through
//! the same safe glTF loading as every other input.

use serde_json::Value;

use crate::scene::gltf_load::{check_glb_header, gltf_error, guarded, precheck_root, walk_scene};
use crate::{Error, Result};

/// The `extras` of every object of a glTF file (GLB or glTF JSON), `None`
/// for an object without them. Objects are the nodes that draw a mesh, in
/// the scene walk's order, so entry `i` belongs to object `i` of
/// [`crate::scene::gltf_load::load_scene_bytes`] and
/// [`crate::scene::geometry::load_geometry_bytes`] on the same bytes.
/// Malformed input gives [`Error::BadInput`] naming `source`.
pub(crate) fn object_extras(bytes: &[u8], source: &str) -> Result<Vec<Option<Value>>> {
    guarded(source, || {
        check_glb_header(bytes, source)?;
        let gltf::Gltf { document, .. } =
            gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_error(source, e))?;
        let mut root = document.into_json();
        precheck_root(&mut root, source)?;
        let doc = gltf::Document::from_json(root).map_err(|e| gltf_error(source, e))?;
        let json_nodes = &doc.as_json().nodes;
        walk_scene(&doc, source)?
            .iter()
            .map(|inst| {
                let Some(raw) = &json_nodes[inst.node].extras else {
                    return Ok(None);
                };
                serde_json::from_str(raw.get()).map(Some).map_err(|e| {
                    Error::bad(
                        format!("{source}: node {} extras", inst.node),
                        format!("unreadable JSON: {e}"),
                    )
                })
            })
            .collect()
    })
}

/// The `extras` of a glTF file's default scene (else its first), `None`
/// when it has none. Malformed input gives [`Error::BadInput`] naming
/// `source`.
pub(crate) fn scene_extras(bytes: &[u8], source: &str) -> Result<Option<Value>> {
    guarded(source, || {
        check_glb_header(bytes, source)?;
        let gltf::Gltf { document, .. } =
            gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_error(source, e))?;
        let mut root = document.into_json();
        precheck_root(&mut root, source)?;
        let doc = gltf::Document::from_json(root).map_err(|e| gltf_error(source, e))?;
        let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
            return Ok(None);
        };
        let Some(raw) = &doc.as_json().scenes[scene.index()].extras else {
            return Ok(None);
        };
        serde_json::from_str(raw.get()).map(Some).map_err(|e| {
            Error::bad(
                format!("{source}: scene {} extras", scene.index()),
                format!("unreadable JSON: {e}"),
            )
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::glb::{Geometry, GlbBuilder, Node};
    use serde_json::json;

    fn two_objects() -> Vec<u8> {
        let mut b = GlbBuilder::new();
        let g = Geometry {
            positions: &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: None,
            texcoords: None,
            indices: &[0, 1, 2],
        };
        let mesh = b.add_mesh_from("tri", &[(g, None)]).unwrap();
        let a = b
            .add_node(
                Node::new("a")
                    .with_mesh(mesh)
                    .with_extras(json!({ "impostor": 4 })),
            )
            .unwrap();
        let empty = b.add_node(Node::new("group")).unwrap();
        let c = b.add_node(Node::new("c").with_mesh(mesh)).unwrap();
        b.add_child(empty, c).unwrap();
        b.set_scene_roots(&[a, empty]).unwrap();
        b.finish()
    }

    #[test]
    fn extras_follow_the_object_order() {
        let extras = object_extras(&two_objects(), "two.glb").unwrap();
        assert_eq!(extras, vec![Some(json!({ "impostor": 4 })), None]);
    }

    #[test]
    fn bad_bytes_are_bad_input_naming_the_file() {
        let glb = two_objects();
        for bytes in [
            &b"glTF"[..],
            &glb[..glb.len() / 2],
            b"{ not json",
            &[0u8; 64][..],
        ] {
            let e = object_extras(bytes, "x.glb").unwrap_err();
            assert!(e.is_bad_input() && e.to_string().contains("x.glb"), "{e}");
        }
        let mut rng = crate::math::rng::Rng::new(11);
        for _ in 0..300 {
            let mut b = glb.clone();
            let i = (rng.next_u64() % b.len() as u64) as usize;
            b[i] ^= 1 << (rng.next_u64() % 8);
            if let Err(e) = object_extras(&b, "x.glb") {
                assert!(e.is_bad_input(), "{e}");
            }
        }
    }
}
