//! Safe scene loading: glTF (`.glb` / `.gltf`) and JSON scene summaries.
//!
//! A glTF scene becomes one [`Object`] per node that draws a mesh (DESIGN §5):
//! object ids follow a depth-first pre-order walk of the default scene
//! (`scene`, else scene 0), children in array order, and every instance of a
//! shared mesh is its own object. Only what placement needs is read: the
//! vertex positions (for bounds) and the indices (for triangle counts and a
//! range check). Images, materials and animations are never touched.
//!
//! # Quantized and compressed geometry
//!
//! Files as `gltfpack` writes them load: `KHR_mesh_quantization`
//! attributes (8- and 16-bit integers, normalized or not, read by
//! [`quantized`]; the node transforms that dequantize them are ordinary
//! transforms) and `EXT_meshopt_compression` buffer views (decoded by
//! [`meshopt`] before any accessor is read, within
//! [`MAX_DECODED_BYTES`]). Draco-compressed primitives
//! (`KHR_draco_mesh_compression`) are decoded by [`draco`] into one more
//! buffer their accessors then read. Unknown required extensions are
//! refused with an error naming them.
//!
//! # GPU instancing (`EXT_mesh_gpu_instancing`)
//!
//! A node that draws its mesh once per instance (game maps' forests and
//! props, `gltfpack -mi`, `gltf-transform instance`) is one object per
//! instance, in instance order where the node's object would be, placed by
//! the node's world transform × the instance's translation, rotation and
//! scale (float or normalized-integer accessors). Its objects are named
//! `name#k`. Attributes of other counts, missing accessors, rotations that
//! are not unit quaternions and instances with `MSFT_lod` levels are
//! errors naming the node.
//!
//! # Levels of detail (`MSFT_lod`)
//!
//! A node with `"extensions": {"MSFT_lod": {"ids": [n1, n2, …]}}` names
//! coarser versions of itself, in decreasing detail; its
//! `"extras": {"MSFT_screencoverage": [c0, c1, …]}` says when each is
//! drawn: level `i` (level 0 is the node itself) while the screen coverage
//! is in `[c_i, c_{i−1})` (with `c_{−1} = 1`), nothing below the last value.
//! Screen coverage is read in this tool's convention: the projected area of
//! the object's bounding sphere over the screen area
//! ([`crate::model::cost::CostModel::coverage`]). The rules:
//!
//! * Nodes named in some node's `MSFT_lod.ids` are levels of detail, not
//!   objects: wherever they appear in the scene, they and their subtrees are
//!   skipped, so object ids (DESIGN §5) count real objects only. Both this
//!   loader and [`crate::scene::geometry`] walk the scene with the same function, so
//!   their ids agree.
//! * A level node takes the object's place: its world transform is the
//!   object node's parent world transform × the level node's local
//!   transform. Its mesh gives the level's triangles and draw calls (its
//!   children are ignored), and the object's bounds are the union of all
//!   levels' world bounds, so every level lies within them.
//! * `MSFT_screencoverage` with `ids.len() + 1` values gives every level's
//!   [`LodLevel::min_coverage`]; with `ids.len()` values the last level has 0
//!   (it is never culled). Without `MSFT_screencoverage` there is no switching
//!   rule, so the levels are ignored: the object is always drawn in full
//!   detail (its level nodes are still not objects). A node with `MSFT_lod`
//!   but no mesh is not an object; its level nodes are skipped too.
//! * Errors naming the node: `ids` missing, empty, not node indices, naming
//!   the node itself or a node twice, more than 31 entries; coverage values
//!   of another count, not numbers in `[0, 1]` or not strictly decreasing; a
//!   level node without a mesh.
//! * `MSFT_lod` on materials is ignored (placement never reads materials).
//!
//! Levels are always loaded; a job with `lod.enabled = false` clears them
//! with [`crate::scene::lod::strip_lods`].
//!
//! The input is untrusted (HTTP uploads), so the loader
//!
//! * resolves buffers itself: the GLB `BIN` chunk and base64 `data:` URIs,
//!   plus relative file URIs only when a base directory is given (the CLI on a
//!   local file), never absolute paths, other schemes or `..` components;
//! * checks every accessor it reads with checked arithmetic before touching
//!   the bytes, and reads them itself (little-endian), so the malformed inputs
//!   that make `gltf` 1.4 panic are reported as errors instead;
//! * walks the node graph iteratively (deep chains are fine) and rejects
//!   cycles, nodes reachable twice and non-finite transforms;
//! * wraps everything in `catch_unwind` as a last line of defence.

mod accessors;
mod buffers;
mod document;
mod draco;
mod meshopt;
mod quantized;
mod walk;

pub(crate) use accessors::*;
pub(crate) use buffers::*;
pub(crate) use document::*;
pub(crate) use draco::{KHR_DRACO, decode_draco_primitives};
pub use meshopt::MAX_DECODED_BYTES;
pub(crate) use meshopt::{EXT_MESHOPT, decode_compressed_views, is_fallback};
pub(crate) use quantized::*;
pub(crate) use walk::*;

use std::borrow::Cow;
use std::collections::BTreeSet;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Component, Path};

use base64::Engine as _;
use glam::{DAffine3, DMat3, DQuat, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use rayon::prelude::*;

use crate::api::scene::LodLevel;
use crate::error::{Error, Result};
use crate::scene::{Object, Scene};

/// Largest number of glTF nodes (and so of objects) a scene may have.
pub const MAX_NODES: usize = 10_000_000;

/// Largest vertex stride glTF allows (`bufferView.byteStride`).
const MAX_STRIDE: usize = 252;

/// Extensions that only affect appearance (materials, textures, lights):
/// placement ignores them, so a file that requires them still loads.
const APPEARANCE_EXTENSIONS: &[&str] = &[
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
    "KHR_lights_punctual",
    "KHR_materials_unlit",
    "KHR_materials_pbrSpecularGlossiness",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_materials_volume",
    "KHR_materials_specular",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_iridescence",
    "KHR_materials_anisotropy",
    "KHR_materials_dispersion",
    "KHR_materials_variants",
];

/// Loads a scene file: a GLB (by its `glTF` magic), a JSON scene summary (a
/// `.json` extension, or JSON whose top level has `"objects"`), or a `.gltf`
/// JSON file whose relative buffer URIs are resolved next to the file.
///
/// Errors name the file as given.
pub fn load_scene_file(path: &Path) -> Result<Scene> {
    let bytes = crate::files::read_file(path, crate::files::MAX_SCENE_BYTES, "scene")?;
    load_scene_file_bytes(&bytes, path)
}

/// [`load_scene_file`] of bytes already read from `path`.
pub fn load_scene_file_bytes(bytes: &[u8], path: &Path) -> Result<Scene> {
    let source = path.display().to_string();
    if is_summary_file(bytes, path) {
        return Scene::from_summary_json(bytes, &source);
    }
    dispatch(bytes, &source, Some(base_dir_of(path)))
}

/// True when a file's bytes are a JSON scene summary rather than glTF: not
/// a GLB, and a `.json` extension or a top-level `"objects"` key.
pub fn is_summary_file(bytes: &[u8], path: &Path) -> bool {
    let json_ext = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    (json_ext && !bytes.starts_with(b"glTF")) || is_summary(bytes)
}

/// True when uploaded bytes are a JSON scene summary (JSON whose top level
/// has `"objects"`), not a GLB or glTF JSON document.
pub fn is_summary(bytes: &[u8]) -> bool {
    /// Top-level keys that tell a scene summary from a glTF document.
    #[derive(serde::Deserialize)]
    struct Probe {
        #[serde(default)]
        objects: Option<serde::de::IgnoredAny>,
    }
    !bytes.starts_with(b"glTF")
        && matches!(
            serde_json::from_slice::<Probe>(bytes),
            Ok(Probe { objects: Some(_) })
        )
}

/// The directory relative resources of a local glTF file are read from.
pub(crate) fn base_dir_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Loads a scene from bytes (an upload): a GLB, a JSON scene summary (JSON
/// whose top level has `"objects"`) or a `.gltf` JSON document. External
/// buffer files are not allowed; buffers must be embedded (GLB `BIN` chunk or
/// base64 `data:` URIs). `source` names the input in errors.
pub fn load_scene_bytes(bytes: &[u8], source: &str) -> Result<Scene> {
    dispatch(bytes, source, None)
}

/// Dispatches by content: GLB magic, JSON summary or glTF JSON.
fn dispatch(bytes: &[u8], source: &str, base_dir: Option<&Path>) -> Result<Scene> {
    if bytes.starts_with(b"glTF") {
        return load_gltf(bytes, source, base_dir);
    }
    /// Top-level keys that tell a scene summary from a glTF document.
    #[derive(serde::Deserialize)]
    struct Probe {
        #[serde(default)]
        objects: Option<serde::de::IgnoredAny>,
    }
    match serde_json::from_slice::<Probe>(bytes) {
        Ok(Probe { objects: Some(_) }) => Scene::from_summary_json(bytes, source),
        Ok(Probe { objects: None }) => load_gltf(bytes, source, base_dir),
        Err(e) => Err(Error::bad(
            source,
            format!(
                "not a scene: neither a GLB file (no `glTF` magic) nor valid JSON (glTF or scene \
                 summary): {e}"
            ),
        )),
    }
}

/// Loads a glTF 2.0 document (`.glb` or `.gltf` bytes) as a [`Scene`].
///
/// Buffers come from the GLB `BIN` chunk and base64 `data:` URIs
/// (`application/octet-stream` or `application/gltf-buffer`). Relative file
/// URIs are read from `base_dir` only when it is `Some` (a local file); with
/// `None` (an upload) every non-`data:` URI is an error. Absolute paths, other
/// URI schemes and `..` components are always rejected.
///
/// Every node of the default scene (`scene`, else scene 0) that carries a
/// mesh becomes one object, in depth-first pre-order with children in array
/// order. Its bounds are the world-space box of the 8 transformed corners of
/// the mesh's local box (computed from the vertex data, not from the accessor
/// `min`/`max`); its draw calls are the mesh's primitive count and its
/// triangles the triangle-list index count / 3 (strips and fans count − 2,
/// points and lines 0). Malformed input of any kind gives
/// [`Error::BadInput`] naming `source` and the offending field.
pub fn load_gltf(bytes: &[u8], source: &str, base_dir: Option<&Path>) -> Result<Scene> {
    guarded(source, || load_gltf_inner(bytes, source, base_dir))
}

/// Runs `f`, turning a panic (inside `gltf` or elsewhere) into a bad-input
/// error for `source`.
pub(crate) fn guarded<T>(source: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let message = if let Some(s) = payload.downcast_ref::<&str>() {
                (*s).to_string()
            } else if let Some(s) = payload.downcast_ref::<String>() {
                s.clone()
            } else {
                "unknown panic".to_string()
            };
            Err(Error::bad(
                source,
                format!("malformed glTF (the parser failed: {message})"),
            ))
        }
    }
}

/// Per-mesh facts shared by all instances of the mesh.
#[derive(Clone, Copy, Debug)]
struct MeshInfo {
    /// Local bounding box minimum (from the vertex data).
    min: DVec3,
    /// Local bounding box maximum.
    max: DVec3,
    /// Triangles over all primitives.
    triangles: u64,
    /// Primitive count.
    draw_calls: u32,
}

/// One node of the scene that draws a mesh, or one GPU instance of such a
/// node: an object.
pub(crate) struct Instance {
    pub(crate) node: usize,
    pub(crate) mesh: usize,
    pub(crate) world: DAffine3,
    /// Its coarser levels of detail, when the file gives them.
    pub(crate) lods: Option<LodChain>,
    /// Which instance of the node's `EXT_mesh_gpu_instancing` it is.
    pub(crate) gpu_instance: Option<u32>,
}

fn load_gltf_inner(bytes: &[u8], source: &str, base_dir: Option<&Path>) -> Result<Scene> {
    check_glb_header(bytes, source)?;
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| gltf_error(source, e))?;
    let mut root = document.into_json();
    precheck_root(&mut root, source)?;
    let doc = gltf::Document::from_json(root).map_err(|e| gltf_error(source, e))?;

    let mut buffers = resolve_buffers(&doc, blob.as_deref(), source, base_dir)?;
    let doc = decode_compressed_views(doc, &mut buffers, source)?;
    let doc = decode_draco_primitives(doc, &mut buffers, source)?;
    let mut instances = walk_scene(&doc, source)?;
    place_gpu_instances(&doc, &buffers, &mut instances, source)?;

    // Read every mesh the scene uses once, in parallel; report the error of
    // the lowest mesh index so the message does not depend on scheduling.
    let used: Vec<usize> = instances
        .iter()
        .flat_map(|i| {
            let levels = i.lods.as_ref().map_or(&[][..], |c| &c.levels[..]);
            std::iter::once(i.mesh).chain(levels.iter().map(|l| l.mesh))
        })
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let meshes: Vec<gltf::Mesh> = doc.meshes().collect();
    let infos: Vec<Result<MeshInfo>> = used
        .par_iter()
        .map(|&m| mesh_info(&meshes[m], &buffers, source))
        .collect();
    let mut mesh_infos: Vec<Option<MeshInfo>> = vec![None; meshes.len()];
    for (&m, info) in used.iter().zip(infos) {
        mesh_infos[m] = Some(info?);
    }

    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    let mut objects = Vec::with_capacity(instances.len());
    let mut total: u64 = 0;
    let info_of = |mesh: usize| {
        mesh_infos[mesh].ok_or_else(|| Error::Internal(format!("mesh {mesh} was not read")))
    };
    for inst in &instances {
        let info = info_of(inst.mesh)?;
        total = total.checked_add(info.triangles).ok_or_else(|| {
            Error::bad(source, "the total triangle count does not fit in 64 bits")
        })?;
        let (mut min, mut max) = transform_box(&inst.world, info.min, info.max);
        let mut lods = Vec::new();
        if let Some(chain) = &inst.lods {
            lods.push(LodLevel {
                min_coverage: chain.min_coverage[0],
                triangles: info.triangles,
                draw_calls: info.draw_calls,
            });
            for (level, &min_coverage) in chain.levels.iter().zip(&chain.min_coverage[1..]) {
                let li = info_of(level.mesh)?;
                let (lo, hi) = transform_box(&level.world, li.min, li.max);
                min = min.min(lo);
                max = max.max(hi);
                lods.push(LodLevel {
                    min_coverage,
                    triangles: li.triangles,
                    draw_calls: li.draw_calls,
                });
            }
        }
        let node = &nodes[inst.node];
        let mut name = match (node.name(), meshes[inst.mesh].name()) {
            (Some(n), _) if !n.is_empty() => n.to_string(),
            (_, Some(n)) if !n.is_empty() => n.to_string(),
            _ => format!("node_{}", inst.node),
        };
        if let Some(k) = inst.gpu_instance {
            name = format!("{name}#{k}");
        }
        objects.push(Object {
            name,
            min,
            max,
            triangles: info.triangles,
            draw_calls: info.draw_calls,
            lods,
        });
    }
    let scene = Scene { objects };
    scene.validate(source)?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;
    use base64::engine::general_purpose::STANDARD;
    use serde_json::{Value, json};

    /// A glTF document under construction: JSON plus one binary buffer.
    struct Doc {
        json: Value,
        bin: Vec<u8>,
    }

    impl Doc {
        fn new() -> Self {
            Doc {
                json: json!({
                    "asset": {"version": "2.0"},
                    "scene": 0,
                    "scenes": [{"nodes": []}],
                    "nodes": [],
                    "meshes": [],
                    "accessors": [],
                    "bufferViews": [],
                }),
                bin: Vec::new(),
            }
        }

        fn push(&mut self, key: &str, value: Value) -> usize {
            let array = self.json[key].as_array_mut().unwrap();
            array.push(value);
            array.len() - 1
        }

        fn view(&mut self, bytes: &[u8], stride: Option<usize>) -> usize {
            while !self.bin.len().is_multiple_of(4) {
                self.bin.push(0);
            }
            let mut v =
                json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
            if let Some(s) = stride {
                v["byteStride"] = json!(s);
            }
            self.bin.extend_from_slice(bytes);
            self.push("bufferViews", v)
        }

        fn positions(&mut self, points: &[[f32; 3]]) -> usize {
            let bytes: Vec<u8> = points
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let view = self.view(&bytes, None);
            let mut lo = [f32::MAX; 3];
            let mut hi = [f32::MIN; 3];
            for p in points {
                for i in 0..3 {
                    if p[i].is_finite() {
                        lo[i] = lo[i].min(p[i]);
                        hi[i] = hi[i].max(p[i]);
                    }
                }
            }
            self.push(
                "accessors",
                json!({"bufferView": view, "componentType": 5126, "count": points.len(),
                       "type": "VEC3", "min": lo, "max": hi}),
            )
        }

        fn indices_u16(&mut self, indices: &[u16]) -> usize {
            let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
            let view = self.view(&bytes, None);
            self.push(
                "accessors",
                json!({"bufferView": view, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}),
            )
        }

        /// A mesh of one primitive.
        fn mesh(
            &mut self,
            name: &str,
            position: usize,
            indices: Option<usize>,
            mode: u32,
        ) -> usize {
            let mut prim = json!({"attributes": {"POSITION": position}, "mode": mode});
            if let Some(i) = indices {
                prim["indices"] = json!(i);
            }
            self.push("meshes", json!({"name": name, "primitives": [prim]}))
        }

        /// A unit cube [0, 1]³ of 12 indexed triangles.
        fn cube(&mut self) -> usize {
            let p = self.positions(&CUBE);
            let i = self.indices_u16(&CUBE_INDICES);
            self.mesh("cube", p, Some(i), 4)
        }

        fn node(&mut self, node: Value) -> usize {
            self.push("nodes", node)
        }

        fn roots(&mut self, roots: &[usize]) {
            self.json["scenes"][0]["nodes"] = json!(roots);
        }

        fn finish_json(&self, uri: Option<String>) -> Value {
            let mut json = self.json.clone();
            let mut buffer = json!({"byteLength": self.bin.len().max(1)});
            if let Some(uri) = uri {
                buffer["uri"] = json!(uri);
            }
            json["buffers"] = json!([buffer]);
            json
        }

        fn glb(&self) -> Vec<u8> {
            let mut bin = self.bin.clone();
            if bin.is_empty() {
                bin.push(0);
            }
            glb(&self.finish_json(None), &bin)
        }

        fn gltf(&self) -> Vec<u8> {
            let mut bin = self.bin.clone();
            if bin.is_empty() {
                bin.push(0);
            }
            let uri = format!(
                "data:application/octet-stream;base64,{}",
                STANDARD.encode(&bin)
            );
            serde_json::to_vec(&self.finish_json(Some(uri))).unwrap()
        }
    }

    const CUBE: [[f32; 3]; 8] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0],
    ];
    const CUBE_INDICES: [u16; 36] = [
        0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 3, 6, 2, 3, 7, 6, 0, 4, 7, 0, 7, 3,
        1, 2, 6, 1, 6, 5,
    ];

    /// Assembles a GLB: header, JSON chunk (space-padded), BIN chunk (zero-padded).
    fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
        let mut j = serde_json::to_vec(json).unwrap();
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut b = bin.to_vec();
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        let total = 12 + 8 + j.len() + 8 + b.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
        out.extend_from_slice(&j);
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(&0x004E_4942u32.to_le_bytes());
        out.extend_from_slice(&b);
        out
    }

    /// Loads without a base directory; a panic fails the test.
    fn load(bytes: &[u8]) -> Result<Scene> {
        std::panic::catch_unwind(|| load_gltf(bytes, "t.glb", None)).expect("the loader panicked")
    }

    /// Loads, expects an error, and returns its message; checks that the
    /// problem was found by validation, not by the panic safety net.
    fn load_err(bytes: &[u8]) -> String {
        let err = load(bytes).expect_err("malformed input was accepted");
        let message = err.to_string();
        assert!(err.is_bad_input(), "{message}");
        assert!(message.starts_with("t.glb"), "{message}");
        assert!(!message.contains("parser failed"), "{message}");
        message
    }

    fn assert_vec(a: DVec3, b: [f64; 3]) {
        assert!(
            (a - DVec3::from_array(b)).abs().max_element() < 1e-9,
            "{a:?} != {b:?}"
        );
    }

    #[test]
    fn cube_instanced_by_two_transformed_nodes() {
        let mut d = Doc::new();
        let cube = d.cube();
        let a = d.node(json!({"name": "a", "mesh": cube, "translation": [10.0, 0.0, 0.0]}));
        // 90° about z, then scale 2: x ↦ y, y ↦ −x.
        let s = std::f32::consts::FRAC_1_SQRT_2;
        let b =
            d.node(json!({"mesh": cube, "rotation": [0.0, 0.0, s, s], "scale": [2.0, 2.0, 2.0]}));
        d.roots(&[a, b]);
        for bytes in [d.glb(), d.gltf()] {
            let scene = load(&bytes).unwrap();
            assert_eq!(scene.objects.len(), 2);
            let (oa, ob) = (&scene.objects[0], &scene.objects[1]);
            assert_eq!(oa.name, "a");
            assert_eq!(ob.name, "cube", "falls back to the mesh name");
            assert_vec(oa.min, [10.0, 0.0, 0.0]);
            assert_vec(oa.max, [11.0, 1.0, 1.0]);
            assert!((ob.min - DVec3::new(-2.0, 0.0, 0.0)).abs().max_element() < 1e-6);
            assert!((ob.max - DVec3::new(0.0, 2.0, 2.0)).abs().max_element() < 1e-6);
            for o in &scene.objects {
                assert_eq!(o.triangles, 12);
                assert_eq!(o.draw_calls, 1);
            }
        }
    }

    #[test]
    fn draw_calls_count_primitives() {
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        let i = d.indices_u16(&CUBE_INDICES);
        let strip = d.positions(&[
            [0.0, 0.0, 5.0],
            [1.0, 0.0, 5.0],
            [0.0, 1.0, 5.0],
            [1.0, 1.0, 5.0],
        ]);
        let m = d.push(
            "meshes",
            json!({"primitives": [
                {"attributes": {"POSITION": p}, "indices": i},
                {"attributes": {"POSITION": strip}, "mode": 5},
                {"attributes": {"POSITION": p}, "mode": 1},
            ]}),
        );
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        let scene = load(&d.glb()).unwrap();
        let o = &scene.objects[0];
        assert_eq!(o.name, "node_0");
        assert_eq!(o.draw_calls, 3);
        assert_eq!(o.triangles, 12 + 2);
        assert_vec(o.min, [0.0, 0.0, 0.0]);
        assert_vec(o.max, [1.0, 1.0, 5.0]);
    }

    #[test]
    fn child_composes_with_parent_transform() {
        let mut d = Doc::new();
        let cube = d.cube();
        let child = d.node(json!({"name": "child", "mesh": cube, "translation": [1.0, 0.0, 0.0], "scale": [1.0, 3.0, 1.0]}));
        let parent =
            d.node(json!({"name": "parent", "translation": [0.0, 5.0, 0.0], "children": [child]}));
        d.roots(&[parent]);
        let scene = load(&d.glb()).unwrap();
        assert_eq!(scene.objects.len(), 1);
        assert_vec(scene.objects[0].min, [1.0, 5.0, 0.0]);
        assert_vec(scene.objects[0].max, [2.0, 8.0, 1.0]);

        // The same with a column-major matrix on the parent.
        let mut d2 = Doc::new();
        let cube = d2.cube();
        let child = d2.node(json!({"mesh": cube, "translation": [1.0, 0.0, 0.0]}));
        let parent = d2.node(json!({"matrix": [2.0,0.0,0.0,0.0, 0.0,1.0,0.0,0.0, 0.0,0.0,1.0,0.0, 0.0,5.0,0.0,1.0], "children": [child]}));
        d2.roots(&[parent]);
        let scene = load(&d2.glb()).unwrap();
        assert_vec(scene.objects[0].min, [2.0, 5.0, 0.0]);
        assert_vec(scene.objects[0].max, [4.0, 6.0, 1.0]);
    }

    #[test]
    fn object_ids_follow_pre_order_with_children_in_array_order() {
        let mut d = Doc::new();
        let cube = d.cube();
        // Node indices deliberately differ from the walk order.
        let n0 = d.node(json!({"name": "r1", "mesh": cube, "children": [3, 1]}));
        let n1 = d.node(json!({"name": "r1.b", "mesh": cube}));
        let n2 = d.node(json!({"name": "r2", "mesh": cube}));
        let n3 = d.node(json!({"name": "r1.a (no mesh)", "children": [4]}));
        let n4 = d.node(json!({"name": "r1.a.x", "mesh": cube}));
        let _unreached = d.node(json!({"name": "not in the scene", "mesh": cube}));
        assert_eq!((n0, n1, n2, n3, n4), (0, 1, 2, 3, 4));
        d.roots(&[n0, n2]);
        let names: Vec<String> = load(&d.glb())
            .unwrap()
            .objects
            .into_iter()
            .map(|o| o.name)
            .collect();
        assert_eq!(names, ["r1", "r1.a.x", "r1.b", "r2"]);
    }

    #[test]
    fn default_scene_is_scene_property_else_scene_0() {
        let mut d = Doc::new();
        let cube = d.cube();
        let a = d.node(json!({"name": "in0", "mesh": cube}));
        let b = d.node(json!({"name": "in1", "mesh": cube}));
        d.roots(&[a]);
        d.push("scenes", json!({"nodes": [b]}));
        d.json["scene"] = json!(1);
        assert_eq!(load(&d.glb()).unwrap().objects[0].name, "in1");
        d.json.as_object_mut().unwrap().remove("scene");
        assert_eq!(load(&d.glb()).unwrap().objects[0].name, "in0");
    }

    #[test]
    fn strips_fans_and_lines() {
        let mut d = Doc::new();
        let pts: Vec<[f32; 3]> = (0..7).map(|k| [k as f32, (k % 2) as f32, 0.0]).collect();
        let p = d.positions(&pts);
        let strip = d.mesh("strip", p, None, 5);
        let idx = d.indices_u16(&[0, 1, 2, 3, 4, 5]);
        let fan = d.mesh("fan", p, Some(idx), 6);
        let lines = d.mesh("lines", p, None, 1);
        let points = d.mesh("points", p, None, 0);
        let list = d.mesh("list", p, None, 4);
        let nodes: Vec<usize> = [strip, fan, lines, points, list]
            .iter()
            .map(|&m| d.node(json!({"mesh": m})))
            .collect();
        d.roots(&nodes);
        let tris: Vec<u64> = load(&d.glb())
            .unwrap()
            .objects
            .iter()
            .map(|o| o.triangles)
            .collect();
        assert_eq!(tris, [5, 4, 0, 0, 2]);
    }

    fn one_cube_glb() -> Vec<u8> {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        d.glb()
    }

    #[test]
    fn truncated_or_corrupt_glb_is_an_error_naming_the_file() {
        let good = one_cube_glb();
        assert!(load(&good).is_ok());
        for cut in [4, 11, 12, 19, 20, 40, good.len() / 2, good.len() - 1] {
            let message = load_err(&good[..cut]);
            assert!(
                message.contains("GLB") || message.contains("glTF"),
                "{message}"
            );
        }
        // Header length smaller than the header itself.
        let mut bad = good.clone();
        bad[8..12].copy_from_slice(&5u32.to_le_bytes());
        load_err(&bad);
        // Wrong version.
        let mut bad = good.clone();
        bad[4..8].copy_from_slice(&1u32.to_le_bytes());
        assert!(load_err(&bad).contains("version"));
        // JSON chunk length beyond the file.
        let mut bad = good.clone();
        bad[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        load_err(&bad);
        // BIN chunk shorter than the buffer's byteLength.
        let mut bad = good.clone();
        let json_len = u32::from_le_bytes(bad[12..16].try_into().unwrap()) as usize;
        let bin_at = 20 + json_len;
        bad[bin_at..bin_at + 4].copy_from_slice(&4u32.to_le_bytes());
        assert!(load_err(&bad).contains("byteLength"));
        // Not glTF at all.
        load_err(b"");
        load_err(b"hello");
        load_err(b"{\"asset\": 5}");
    }

    #[test]
    fn non_finite_vertex_is_an_error() {
        let mut d = Doc::new();
        let mut pts = CUBE;
        pts[5][1] = f32::NAN;
        let p = d.positions(&pts);
        let m = d.mesh("m", p, None, 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        let message = load_err(&d.glb());
        assert!(message.contains("mesh 0 primitive 0 POSITION"), "{message}");
        assert!(message.contains("vertex 5 is not finite"), "{message}");

        let mut d = Doc::new();
        let mut pts = CUBE;
        pts[0][2] = f32::INFINITY;
        let p = d.positions(&pts);
        let m = d.mesh("m", p, None, 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("not finite"));
    }

    #[test]
    fn float_indices_are_an_error() {
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        let bytes: Vec<u8> = [0.0f32, 1.0, 2.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let view = d.view(&bytes, None);
        let i = d.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5126, "count": 3, "type": "SCALAR"}),
        );
        let m = d.mesh("m", p, Some(i), 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        let message = load_err(&d.glb());
        assert!(message.contains("indices"), "{message}");
        assert!(message.contains("SCALAR FLOAT"), "{message}");
    }

    #[test]
    fn out_of_range_index_is_an_error() {
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        let i = d.indices_u16(&[0, 1, 2, 3, 8, 5]);
        let m = d.mesh("m", p, Some(i), 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        let message = load_err(&d.glb());
        assert!(message.contains("indices"), "{message}");
        assert!(
            message.contains("index 4 is 8, out of range for 8 vertices"),
            "{message}"
        );
    }

    #[test]
    fn node_cycles_and_shared_children_are_errors() {
        // 0 → 1 → 2 → 1
        let mut d = Doc::new();
        let cube = d.cube();
        d.node(json!({"mesh": cube, "children": [1]}));
        d.node(json!({"children": [2]}));
        d.node(json!({"mesh": cube, "children": [1]}));
        d.roots(&[0]);
        assert!(load_err(&d.glb()).contains("cycle"));

        // Self-cycle.
        let mut d = Doc::new();
        let cube = d.cube();
        d.node(json!({"mesh": cube, "children": [0]}));
        d.roots(&[0]);
        assert!(load_err(&d.glb()).contains("cycle"));

        // Two parents.
        let mut d = Doc::new();
        let cube = d.cube();
        d.node(json!({"children": [2]}));
        d.node(json!({"children": [2]}));
        d.node(json!({"mesh": cube}));
        d.roots(&[0, 1]);
        let message = load_err(&d.glb());
        assert!(
            message.contains("node 2") && message.contains("reachable twice"),
            "{message}"
        );

        // A root listed twice.
        let mut d = Doc::new();
        let cube = d.cube();
        d.node(json!({"mesh": cube}));
        d.roots(&[0, 0]);
        assert!(load_err(&d.glb()).contains("listed twice"));
    }

    #[test]
    fn deep_node_chain_loads_without_recursion() {
        const DEPTH: usize = 200_000;
        let mut d = Doc::new();
        let cube = d.cube();
        let nodes: Vec<Value> = (0..DEPTH)
            .map(|k| {
                if k + 1 < DEPTH {
                    json!({"children": [k + 1], "translation": [0.0, 0.0, 1.0]})
                } else {
                    json!({"mesh": cube})
                }
            })
            .collect();
        d.json["nodes"] = Value::Array(nodes);
        d.roots(&[0]);
        let scene = load(&d.glb()).unwrap();
        assert_eq!(scene.objects.len(), 1);
        assert_vec(scene.objects[0].min, [0.0, 0.0, (DEPTH - 1) as f64]);
    }

    #[test]
    fn scene_without_mesh_nodes_has_no_objects() {
        let mut d = Doc::new();
        d.cube();
        let n = d.node(json!({"name": "empty"}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("no objects"));
        // No scenes at all.
        let mut d = Doc::new();
        d.json.as_object_mut().unwrap().remove("scene");
        d.json["scenes"] = json!([]);
        assert!(load_err(&d.glb()).contains("no objects"));
    }

    /// A cube whose buffer has the given uri (no GLB BIN chunk).
    fn cube_with_uri(uri: &str) -> (Vec<u8>, Vec<u8>) {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        let json = serde_json::to_vec(&d.finish_json(Some(uri.to_string()))).unwrap();
        (json, d.bin)
    }

    #[test]
    fn external_uris_without_base_dir_are_errors() {
        for uri in [
            "cube.bin",
            "file:///etc/hostname",
            "https://example.com/a.bin",
            "%FF.bin",
            "../x.bin",
        ] {
            let (json, _) = cube_with_uri(uri);
            let message = load_err(&json);
            assert!(message.contains("buffer 0"), "{message}");
            assert!(message.contains("not allowed"), "{message}");
        }
        // Uploads go through load_scene_bytes.
        let (json, _) = cube_with_uri("cube.bin");
        let message = load_scene_bytes(&json, "up.gltf").unwrap_err().to_string();
        assert!(
            message.contains("external buffer URIs are not allowed"),
            "{message}"
        );
    }

    #[test]
    fn data_uri_variants() {
        let (_, bin) = cube_with_uri("x");
        for prefix in [
            "data:application/octet-stream;base64,",
            "data:application/gltf-buffer;base64,",
        ] {
            let (json, _) = cube_with_uri(&format!("{prefix}{}", STANDARD.encode(&bin)));
            assert_eq!(load(&json).unwrap().objects[0].triangles, 12);
        }
        let (json, _) = cube_with_uri(&format!("data:image/png;base64,{}", STANDARD.encode(&bin)));
        assert!(load_err(&json).contains("media type"));
        let (json, _) = cube_with_uri("data:application/octet-stream;base64,@@@@");
        assert!(load_err(&json).contains("base64"));
        let (json, _) = cube_with_uri("data:application/octet-stream,abc");
        assert!(load_err(&json).contains("base64"));
        // Too short for the declared byteLength.
        let (json, _) = cube_with_uri(&format!(
            "data:application/octet-stream;base64,{}",
            STANDARD.encode(&bin[..10])
        ));
        assert!(load_err(&json).contains("byteLength"));
    }

    fn temp_dir(tag: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("gltf_load_test_{tag}_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn relative_uris_with_base_dir() {
        let dir = temp_dir("rel");
        let (_, bin) = cube_with_uri("x");
        std::fs::create_dir_all(dir.join("sub dir")).unwrap();
        std::fs::write(dir.join("sub dir").join("cube.bin"), &bin).unwrap();

        let (json, _) = cube_with_uri("sub%20dir/cube.bin");
        let scene = load_gltf(&json, "t.gltf", Some(&dir)).unwrap();
        assert_eq!(scene.objects[0].triangles, 12);
        // The same through load_scene_file.
        let file = dir.join("scene.gltf");
        std::fs::write(&file, &json).unwrap();
        assert_eq!(load_scene_file(&file).unwrap().objects.len(), 1);

        for (uri, expect) in [
            ("../cube.bin", ".."),
            ("sub%20dir/../../cube.bin", ".."),
            ("sub dir/..\\..\\cube.bin", ".."),
            ("%2E%2E/cube.bin", ".."),
            ("/etc/hostname", "absolute"),
            ("\\etc\\hostname", "absolute"),
            ("file:///etc/hostname", "scheme"),
            ("C:/Windows/win.ini", "scheme"),
            ("http://example.com/cube.bin", "scheme"),
            ("%FF.bin", "percent"),
            ("%4", "percent"),
        ] {
            let (json, _) = cube_with_uri(uri);
            let err = std::panic::catch_unwind(|| load_gltf(&json, "t.gltf", Some(&dir)))
                .expect("panicked")
                .expect_err(uri);
            assert!(err.to_string().contains(expect), "{uri}: {err}");
        }
        // A missing file is an I/O error naming the path.
        let (json, _) = cube_with_uri("missing.bin");
        let err = load_gltf(&json, "t.gltf", Some(&dir)).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
        assert!(err.to_string().contains("missing.bin"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_accessors_are_errors_not_panics() {
        // byteStride smaller than the element.
        let mut d = Doc::new();
        let bytes: Vec<u8> = CUBE
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let view = d.view(&bytes, Some(4));
        let p = d.push(
            "accessors",
            json!({"bufferView": view, "componentType": 5126, "count": 2, "type": "VEC3",
                   "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]}),
        );
        let m = d.mesh("m", p, None, 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("byteStride 4 is smaller"));

        // Variations of one valid POSITION accessor: fields to set (null
        // removes the field) and the expected part of the message.
        let variants = [
            (json!({"count": 0}), "count 0"),
            (json!({"count": 1u64 << 62}), "does not fit"),
            (json!({"byteOffset": 4}), "does not fit"),
            (
                json!({"componentType": 5125}),
                "is VEC3 UNSIGNED_INT, expected VEC3",
            ),
            (json!({"type": "SCALAR"}), "is SCALAR FLOAT, expected VEC3"),
            (json!({"bufferView": null}), "bufferView"),
            (
                json!({"sparse": {"count": 1,
                    "indices": {"bufferView": 0, "componentType": 5121},
                    "values": {"bufferView": 0}}}),
                "sparse",
            ),
        ];
        for (patch, expect) in variants {
            let mut d = Doc::new();
            let p = d.positions(&CUBE);
            let accessor = d.json["accessors"][p].as_object_mut().unwrap();
            for (key, value) in patch.as_object().unwrap() {
                if value.is_null() {
                    accessor.remove(key);
                } else {
                    accessor.insert(key.clone(), value.clone());
                }
            }
            let m = d.mesh("m", p, None, 4);
            let n = d.node(json!({"mesh": m}));
            d.roots(&[n]);
            let message = load_err(&d.glb());
            assert!(message.contains(expect), "{patch}: {message}");
        }

        // bufferView past the end of the buffer.
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        d.json["bufferViews"][0]["byteOffset"] = json!(1000);
        let m = d.mesh("m", p, None, 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("lies outside buffer 0"));

        // Indices as VEC3.
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        let i = d.indices_u16(&[0, 1, 2]);
        d.json["accessors"][i]["type"] = json!("VEC3");
        d.json["accessors"][i]["count"] = json!(1);
        let m = d.mesh("m", p, Some(i), 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("SCALAR"));

        // POSITION refers to an accessor that does not exist.
        let mut d = Doc::new();
        let m = d.mesh("m", 7, None, 4);
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("accessor 7 does not exist"));

        // POSITION missing.
        let mut d = Doc::new();
        let m = d.push("meshes", json!({"primitives": [{"attributes": {}}]}));
        let n = d.node(json!({"mesh": m}));
        d.roots(&[n]);
        assert!(load_err(&d.glb()).contains("POSITION"));
    }

    #[test]
    fn bad_transforms_are_errors() {
        let cases = [
            // Beyond f32: the JSON parser rejects the number with its position.
            (json!({"translation": [1e39, 0.0, 0.0]}), "out of range"),
            (json!({"scale": [1.0, 1e39, 1.0]}), "out of range"),
            (json!({"rotation": [0.0, 0.0, 0.0, 0.0]}), "rotation"),
            (
                json!({"matrix": [1.0,0.0,0.0,0.5, 0.0,1.0,0.0,0.0, 0.0,0.0,1.0,0.0, 0.0,0.0,0.0,1.0]}),
                "not affine",
            ),
            (
                json!({"matrix": [1e39,0.0,0.0,0.0, 0.0,1.0,0.0,0.0, 0.0,0.0,1.0,0.0, 0.0,0.0,0.0,1.0]}),
                "out of range",
            ),
        ];
        for (node, expect) in cases {
            let mut d = Doc::new();
            let cube = d.cube();
            let mut node = node;
            node["mesh"] = json!(cube);
            d.node(node);
            d.roots(&[0]);
            let message = load_err(&d.glb());
            assert!(message.contains(expect), "{message}");
        }
        // Scales that overflow only when composed.
        let mut d = Doc::new();
        let cube = d.cube();
        let chain: Vec<Value> = (0..12)
            .map(|k| {
                if k < 11 {
                    json!({"children": [k + 1], "scale": [1e30, 1e30, 1e30]})
                } else {
                    json!({"mesh": cube})
                }
            })
            .collect();
        d.json["nodes"] = Value::Array(chain);
        d.roots(&[0]);
        load_err(&d.glb());
    }

    #[test]
    fn images_are_ignored() {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        // An image bufferView without mimeType, and one past the buffer end.
        d.json["bufferViews"]
            .as_array_mut()
            .unwrap()
            .push(json!({"buffer": 0, "byteOffset": 100000, "byteLength": 16}));
        d.json["images"] = json!([{"bufferView": 0}, {"bufferView": 2}, {"uri": "%FF.png"}]);
        d.json["textures"] = json!([{"source": 0}, {"source": 1}]);
        d.json["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
        d.json["meshes"][0]["primitives"][0]["material"] = json!(0);
        let scene = load(&d.glb()).unwrap();
        assert_eq!(scene.objects.len(), 1);
    }

    #[test]
    fn ktx2_textures_without_source_are_ignored() {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        d.json["extensionsUsed"] = json!(["KHR_texture_basisu"]);
        d.json["extensionsRequired"] = json!(["KHR_texture_basisu"]);
        d.json["images"] = json!([{"uri": "t.ktx2", "mimeType": "image/ktx2"}]);
        d.json["textures"] = json!([{"extensions": {"KHR_texture_basisu": {"source": 0}}}]);
        d.json["materials"] = json!([{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]);
        d.json["meshes"][0]["primitives"][0]["material"] = json!(0);
        assert_eq!(load(&d.glb()).unwrap().objects.len(), 1);
    }

    /// `EXT_mesh_gpu_instancing`: each instance is an object, in instance
    /// order where the node's object would be, placed by the node's
    /// transform × its own (translation, rotation, scale); malformed
    /// instancing is an error naming the node.
    #[test]
    fn gpu_instances_are_objects() {
        let build = |attributes: Value, lod: bool| {
            let mut d = Doc::new();
            let cube = d.cube();
            let t = d.positions(&[[10.0, 0.0, 0.0], [0.0, 5.0, 0.0]]);
            let h = std::f32::consts::FRAC_1_SQRT_2;
            // Identity, then 90° about y; the third is not a rotation.
            let quats: [[f32; 4]; 3] = [[0.0, 0.0, 0.0, 1.0], [0.0, h, 0.0, h], [0.0; 4]];
            let bytes: Vec<u8> = quats
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let view = d.view(&bytes, None);
            let r = d.push(
                "accessors",
                json!({"bufferView": view, "componentType": 5126, "count": 2, "type": "VEC4"}),
            );
            let zero = d.push(
                "accessors",
                json!({"bufferView": view, "byteOffset": 16, "componentType": 5126, "count": 2,
                       "type": "VEC4"}),
            );
            let sc = d.positions(&[[1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]);
            let one = d.positions(&[[1.0, 1.0, 1.0]]);
            let mut attributes = attributes.to_string();
            for (name, id) in [("T", t), ("R", r), ("Z", zero), ("S", sc), ("ONE", one)] {
                attributes = attributes.replace(&format!("\"@{name}\""), &id.to_string());
            }
            let attributes: Value = serde_json::from_str(&attributes).unwrap();
            let a = d.node(json!({"mesh": cube, "name": "a"}));
            let mut trees = json!({"mesh": cube, "name": "trees", "translation": [0.0, 0.0, 100.0],
                "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}});
            let level = d.node(json!({"mesh": cube}));
            if lod {
                trees["extensions"]["MSFT_lod"] = json!({"ids": [level]});
                trees["extras"] = json!({"MSFT_screencoverage": [0.5, 0.1]});
            }
            let trees = d.node(trees);
            let b = d.node(json!({"mesh": cube, "name": "b"}));
            d.roots(&[a, trees, b]);
            d.json["extensionsUsed"] = json!(["EXT_mesh_gpu_instancing"]);
            d.json["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing"]);
            d.glb()
        };
        let all = json!({"TRANSLATION": "@T", "ROTATION": "@R", "SCALE": "@S"});
        let scene = load(&build(all.clone(), false)).unwrap();
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["a", "trees#0", "trees#1", "b"]);
        assert_vec(scene.objects[1].min, [10.0, 0.0, 100.0]);
        assert_vec(scene.objects[1].max, [11.0, 1.0, 101.0]);
        // Scaled to [0, 2]³, turned about y ((x, y, z) -> (z, y, -x)),
        // moved by (0, 5, 0), then by the node's (0, 0, 100).
        assert_vec(scene.objects[2].min, [0.0, 5.0, 98.0]);
        assert_vec(scene.objects[2].max, [2.0, 7.0, 100.0]);
        assert_eq!(scene.objects[2].triangles, 12);
        // Attributes left out are the identity's.
        let only_t = load(&build(json!({"TRANSLATION": "@T"}), false)).unwrap();
        assert_vec(only_t.objects[2].min, [0.0, 5.0, 100.0]);
        // The geometry loader (what bakes render) places them alike.
        let g = crate::scene::geometry::load_geometry_bytes(&build(all.clone(), false), "t.glb")
            .unwrap();
        assert_eq!(g.objects, 4);
        assert_eq!(g.object_nodes, [0, 2, 2, 3]);
        let corner = g.instances[2]
            .transform
            .transform_point3(DVec3::new(1.0, 1.0, 1.0));
        assert_vec(corner, [2.0, 7.0, 98.0]);

        for (attributes, lod, expected) in [
            (
                json!({"TRANSLATION": "@T", "SCALE": "@ONE"}),
                false,
                "holds 1 instances",
            ),
            (json!({"TRANSLATION": 99}), false, "not an accessor index"),
            (json!({}), false, "names none of"),
            (json!({"ROTATION": "@Z"}), false, "not a unit quaternion"),
            (all, true, "MSFT_lod"),
        ] {
            let message = load_err(&build(attributes, lod));
            assert!(
                message.contains("node 2") && message.contains(expected),
                "{message}"
            );
        }
    }

    /// A Draco extension object that is malformed, or whose view holds no
    /// Draco stream, is an error naming the primitive, never a panic.
    #[test]
    fn bad_draco_primitives_are_named() {
        for (ext, expected) in [
            (
                json!({"attributes": {"POSITION": 0}}),
                "malformed extension object",
            ),
            (
                json!({"bufferView": 0, "attributes": {"POSITION": 0}}),
                "does not decode",
            ),
            (
                json!({"bufferView": 99, "attributes": {}}),
                "bufferView 99 does not exist",
            ),
        ] {
            let mut d = Doc::new();
            let cube = d.cube();
            d.json["meshes"][cube]["primitives"][0]["extensions"] =
                json!({"KHR_draco_mesh_compression": ext});
            let n = d.node(json!({"mesh": cube}));
            d.roots(&[n]);
            d.json["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
            let message = load_err(&d.glb());
            assert!(
                message.contains("mesh 0 primitive 0 KHR_draco_mesh_compression")
                    && message.contains(expected),
                "{message}"
            );
        }
    }

    #[test]
    fn required_extensions() {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        d.json["extensionsRequired"] = json!(["KHR_texture_transform", "KHR_materials_unlit"]);
        d.json["extensionsUsed"] = json!(["KHR_texture_transform", "KHR_materials_unlit"]);
        assert!(load(&d.glb()).is_ok());
        // Read since quantized and meshopt-compressed files load.
        d.json["extensionsRequired"] = json!(["KHR_mesh_quantization", "EXT_meshopt_compression"]);
        assert!(load(&d.glb()).is_ok());
        // Read: primitives without the extension load as before (Draco
        // streams themselves: tests/packed.rs, from Google's encoder).
        d.json["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
        assert_eq!(load(&d.glb()).unwrap().objects.len(), 1);
        // Read: a node without the extension is one object as before.
        d.json["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing"]);
        assert_eq!(load(&d.glb()).unwrap().objects.len(), 1);
        d.json["extensionsRequired"] = json!(["VENDOR_unknown"]);
        assert!(load_err(&d.glb()).contains("VENDOR_unknown"));
    }

    /// The cube's corners quantized as `component_type` (normalized or
    /// not) with the largest coordinate stored as `q`, and the node scale
    /// that dequantizes them to a cube of side 2 at x = 10.
    fn quantized_cube(component_type: u32, normalized: bool, q: f32) -> Doc {
        let mut d = Doc::new();
        let bytes: Vec<u8> = CUBE
            .iter()
            .flat_map(|p| {
                let c = p.map(|v| v * q);
                // Padded to 4-byte elements, as glTF requires.
                let mut e: Vec<u8> = match component_type {
                    5120 => c.iter().map(|&v| (v as i8) as u8).collect(),
                    5121 => c.iter().map(|&v| v as u8).collect(),
                    5122 => c.iter().flat_map(|&v| (v as i16).to_le_bytes()).collect(),
                    _ => c.iter().flat_map(|&v| (v as u16).to_le_bytes()).collect(),
                };
                e.resize(if component_type < 5122 { 4 } else { 8 }, 0);
                e
            })
            .collect();
        let stride = if component_type < 5122 { 4 } else { 8 };
        let view = d.view(&bytes, Some(stride));
        let p = d.push(
            "accessors",
            json!({"bufferView": view, "componentType": component_type, "count": 8,
                   "type": "VEC3", "normalized": normalized,
                   "min": [0, 0, 0], "max": [q, q, q]}),
        );
        let i = d.indices_u16(&CUBE_INDICES);
        let m = d.mesh("cube", p, Some(i), 4);
        let unit = if normalized {
            match component_type {
                5120 => q / 127.0,
                5121 => q / 255.0,
                5122 => q / 32767.0,
                _ => q / 65535.0,
            }
        } else {
            q
        };
        let scale = 2.0 / unit;
        let n = d.node(json!({"mesh": m, "translation": [10.0, 0.0, 0.0],
                              "scale": [scale, scale, scale]}));
        d.roots(&[n]);
        d.json["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
        d.json["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
        d
    }

    #[test]
    fn quantized_positions_of_every_component_type_load() {
        for (t, normalized, q) in [
            (5120, false, 100.0),
            (5120, true, 127.0),
            (5121, false, 200.0),
            (5121, true, 255.0),
            (5122, false, 30000.0),
            (5122, true, 16384.0),
            (5123, false, 60000.0),
            (5123, true, 65535.0),
        ] {
            let scene = load(&quantized_cube(t, normalized, q).glb()).unwrap();
            let o = &scene.objects[0];
            let close = |a: DVec3, b: DVec3| (a - b).abs().max_element() < 1e-4;
            assert!(
                close(o.min, DVec3::new(10.0, 0.0, 0.0))
                    && close(o.max, DVec3::new(12.0, 2.0, 2.0)),
                "{t} normalized {normalized}: {:?} … {:?}",
                o.min,
                o.max
            );
            assert_eq!(o.triangles, 12);
        }
        // Control: read as plain integers, the normalized short cube would
        // be 32767 times larger.
        let mut d = quantized_cube(5122, true, 16384.0);
        d.json["accessors"][0]["normalized"] = json!(false);
        let o = &load(&d.glb()).unwrap().objects[0];
        assert!(o.max.x > 1000.0, "{:?}", o.max);
        // Unsigned int positions are not a quantized type.
        let mut d = quantized_cube(5123, false, 60000.0);
        d.json["accessors"][0]["componentType"] = json!(5125);
        d.json["accessors"][0]["count"] = json!(4);
        let message = load_err(&d.glb());
        assert!(message.contains("VEC3 UNSIGNED_INT"), "{message}");
    }

    /// The cube with its positions and indices meshopt-compressed into
    /// buffer 0, decoded into views of the fallback buffer 1 (no data).
    fn compressed_cube() -> (Value, Vec<u8>) {
        let points: Vec<[f32; 3]> = CUBE.to_vec();
        let pos = ::meshopt::encode_vertex_buffer(&points).unwrap();
        let idx: Vec<u32> = CUBE_INDICES.iter().map(|&i| u32::from(i)).collect();
        let idx = ::meshopt::encode_index_buffer(&idx, 8).unwrap();
        let mut bin = pos.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let idx_at = bin.len();
        bin.extend_from_slice(&idx);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let json = json!({
            "asset": {"version": "2.0"},
            "extensionsUsed": ["EXT_meshopt_compression"],
            "extensionsRequired": ["EXT_meshopt_compression"],
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 1]},
                {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}
            ],
            "bufferViews": [
                {"buffer": 1, "byteOffset": 0, "byteLength": 96, "byteStride": 12,
                 "extensions": {"EXT_meshopt_compression": {
                    "buffer": 0, "byteOffset": 0, "byteLength": pos.len(), "byteStride": 12,
                    "mode": "ATTRIBUTES", "count": 8}}},
                {"buffer": 1, "byteOffset": 96, "byteLength": 72,
                 "extensions": {"EXT_meshopt_compression": {
                    "buffer": 0, "byteOffset": idx_at, "byteLength": idx.len(), "byteStride": 2,
                    "mode": "TRIANGLES", "count": 36}}}
            ],
            "buffers": [
                {"byteLength": bin.len()},
                {"byteLength": 168, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}
            ]
        });
        (json, bin)
    }

    #[test]
    fn meshopt_compressed_views_load() {
        let (json, bin) = compressed_cube();
        let scene = load(&glb(&json, &bin)).unwrap();
        let o = &scene.objects[0];
        assert_eq!((o.min, o.max), (DVec3::ZERO, DVec3::ONE));
        assert_eq!(o.triangles, 12);
        // Control: without the extension the views read the fallback
        // buffer, which has no data.
        let mut plain = json.clone();
        for v in plain["bufferViews"].as_array_mut().unwrap() {
            v.as_object_mut().unwrap().remove("extensions");
        }
        let message = load_err(&glb(&plain, &bin));
        assert!(
            message.contains("lies outside buffer 1 (0 bytes)"),
            "{message}"
        );
        // A fallback buffer naming a file is not read either (here it
        // would be refused: uploads may not name files).
        let mut named = json.clone();
        named["buffers"][1]["uri"] = json!("city.fallback.bin");
        assert_eq!(load(&glb(&named, &bin)).unwrap().objects[0].triangles, 12);
    }

    #[test]
    fn corrupt_or_hostile_compressed_views_are_clear_errors() {
        let (json, mut bin) = compressed_cube();
        // The vertex stream's header byte broken.
        bin[0] = 0;
        let message = load_err(&glb(&json, &bin));
        assert!(
            message.contains("bufferView 0 EXT_meshopt_compression")
                && message.contains("ATTRIBUTES data is corrupt"),
            "{message}"
        );
        // 2^40 bytes claimed: refused before any allocation.
        let (mut json, bin) = compressed_cube();
        let huge = 1u64 << 40;
        json["buffers"][1]["byteLength"] = json!(huge + 72);
        json["bufferViews"][0]["byteLength"] = json!(huge);
        json["bufferViews"][0]["byteStride"] = json!(4);
        json["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteStride"] = json!(4);
        json["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(huge / 4);
        let message = load_err(&glb(&json, &bin));
        assert!(
            message.contains("more than the limit of 4294967296 bytes")
                && message.contains("1099511627776"),
            "{message}"
        );
        // A count that does not match the view.
        let (mut json, bin) = compressed_cube();
        json["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(9);
        let message = load_err(&glb(&json, &bin));
        assert!(
            message.contains("= 108 bytes, but the bufferView's byteLength is 96"),
            "{message}"
        );
        // A compressed range outside its buffer.
        let (mut json, bin) = compressed_cube();
        json["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["byteOffset"] =
            json!(1 << 20);
        let message = load_err(&glb(&json, &bin));
        assert!(message.contains("lies outside buffer 0"), "{message}");
    }

    #[test]
    fn mutated_compressed_streams_never_panic() {
        let (json, bin) = compressed_cube();
        let (mut ok, mut refused) = (0, 0);
        for at in 0..bin.len() {
            for flip in [0x01u8, 0x80, 0xff] {
                let mut b = bin.clone();
                b[at] ^= flip;
                match load(&glb(&json, &b)) {
                    Ok(scene) => {
                        assert_eq!(scene.objects.len(), 1);
                        ok += 1;
                    }
                    Err(e) => {
                        let m = e.to_string();
                        // A clear error, not a caught panic.
                        assert!(!m.contains("the parser failed"), "byte {at}: {m}");
                        refused += 1;
                    }
                }
            }
        }
        // Both outcomes happen: the streams are read, not skipped.
        assert!(ok > 0 && refused > 0, "{ok} loaded, {refused} refused");
    }

    /// A scene with one object of three levels: parent node 0 (translation
    /// x = 100) → base node 1 (cube at x + 1, `MSFT_lod` ids [2, 3]); node 2
    /// a one-triangle mesh at y + 5, node 3 the cube scaled by 2; node 4 an
    /// ordinary cube at z = 50. Nodes 2 and 3 are in no scene.
    fn lod_doc(coverage: Option<Value>) -> Doc {
        let mut d = Doc::new();
        let cube = d.cube();
        let p = d.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let tri = d.mesh("tri", p, None, 4);
        let mut base = json!({"name": "base", "mesh": cube, "translation": [1.0, 0.0, 0.0],
                              "extensions": {"MSFT_lod": {"ids": [2, 3]}}});
        if let Some(c) = coverage {
            base["extras"] = json!({"other": [1, 2], "MSFT_screencoverage": c});
        }
        d.node(json!({"translation": [100.0, 0.0, 0.0], "children": [1]}));
        d.node(base);
        d.node(json!({"name": "lod1", "mesh": tri, "translation": [0.0, 5.0, 0.0]}));
        d.node(json!({"name": "lod2", "mesh": cube, "scale": [2.0, 2.0, 2.0]}));
        d.node(json!({"name": "plain", "mesh": cube, "translation": [0.0, 0.0, 50.0]}));
        d.roots(&[0, 4]);
        d.json["extensionsUsed"] = json!(["MSFT_lod"]);
        d
    }

    #[test]
    fn msft_lod_levels_costs_and_bounds() {
        let d = lod_doc(Some(json!([0.5, 0.2, 0.01])));
        for bytes in [d.glb(), d.gltf()] {
            let scene = load(&bytes).unwrap();
            assert_eq!(scene.objects.len(), 2, "level nodes are not objects");
            let o = &scene.objects[0];
            assert_eq!(o.name, "base");
            assert_eq!((o.triangles, o.draw_calls), (12, 1));
            let l = |min_coverage, triangles| LodLevel {
                min_coverage,
                triangles,
                draw_calls: 1,
            };
            assert_eq!(o.lods, vec![l(0.5, 12), l(0.2, 1), l(0.01, 12)]);
            // Level 0 [101, 102] × [0, 1]²; level 1 the triangle at
            // (100, 5, 0) … (101, 6, 0); level 2 [100, 102]³ − … (scale 2 at
            // the parent's x = 100): the union.
            assert_vec(o.min, [100.0, 0.0, 0.0]);
            assert_vec(o.max, [102.0, 6.0, 2.0]);
            assert_eq!(scene.objects[1].name, "plain");
            assert!(scene.objects[1].lods.is_empty());
            assert_vec(scene.objects[1].min, [0.0, 0.0, 50.0]);
        }
        // The summary round trip keeps the levels.
        let scene = load(&d.glb()).unwrap();
        let json = serde_json::to_vec(&scene.summary()).unwrap();
        let back = Scene::from_summary_json(&json, "s.json").unwrap();
        assert_eq!(back.objects, scene.objects);

        // `ids.len()` values: the last level is never culled.
        let scene = load(&lod_doc(Some(json!([0.5, 0.2]))).glb()).unwrap();
        let c: Vec<f64> = scene.objects[0]
            .lods
            .iter()
            .map(|l| l.min_coverage)
            .collect();
        assert_eq!(c, [0.5, 0.2, 0.0]);
        // No screen coverage: no switching rule, full detail only, but the
        // level nodes are still not objects and do not widen the bounds.
        let scene = load(&lod_doc(None).glb()).unwrap();
        assert_eq!(scene.objects.len(), 2);
        assert!(scene.objects[0].lods.is_empty());
        assert_vec(scene.objects[0].min, [101.0, 0.0, 0.0]);
        assert_vec(scene.objects[0].max, [102.0, 1.0, 1.0]);
        // extensionsRequired may name MSFT_lod.
        let mut d = lod_doc(Some(json!([0.5, 0.2])));
        d.json["extensionsRequired"] = json!(["MSFT_lod"]);
        assert_eq!(load(&d.glb()).unwrap().objects[0].lods.len(), 3);
    }

    #[test]
    fn msft_lod_errors_name_the_node() {
        let cases: Vec<(Option<Value>, Value, &str, &str)> = vec![
            (
                Some(json!([0.5])),
                json!([2, 3]),
                "node 1 extras",
                "expected 3",
            ),
            (
                Some(json!([0.5, 0.6, 0.1])),
                json!([2, 3]),
                "node 1 extras",
                "strictly decreasing",
            ),
            (
                Some(json!([0.5, 0.5])),
                json!([2, 3]),
                "node 1 extras",
                "strictly decreasing",
            ),
            (
                Some(json!([0.5, 0.0])),
                json!([2, 3]),
                "node 1 extras",
                "never be drawn",
            ),
            (
                Some(json!([1.5, 0.2, 0.1])),
                json!([2, 3]),
                "node 1 extras",
                "[0, 1]",
            ),
            (
                Some(json!([0.5, "x", 0.1])),
                json!([2, 3]),
                "node 1 extras",
                "[0, 1]",
            ),
            (
                Some(json!({"a": 1})),
                json!([2, 3]),
                "node 1 extras",
                "not an array",
            ),
            (
                Some(json!([0.5, 0.2])),
                json!([2, 99]),
                "node 1 extensions",
                "not a node index",
            ),
            (
                Some(json!([0.5, 0.2])),
                json!([2, -1]),
                "node 1 extensions",
                "not a node index",
            ),
            (
                Some(json!([0.5, 0.2])),
                json!([2, 1]),
                "node 1 extensions",
                "itself",
            ),
            (
                Some(json!([0.5, 0.2])),
                json!([2, 2]),
                "node 1 extensions",
                "repeats",
            ),
            (Some(json!([0.5])), json!([]), "node 1 extensions", "empty"),
            (
                Some(json!([0.5, 0.2])),
                json!("2"),
                "node 1 extensions",
                "not an array",
            ),
        ];
        for (coverage, ids, at, says) in cases {
            let mut d = lod_doc(coverage);
            d.json["nodes"][1]["extensions"]["MSFT_lod"]["ids"] = ids.clone();
            for message in [
                load_err(&d.glb()),
                crate::scene::geometry::load_geometry_bytes(&d.glb(), "t.glb")
                    .unwrap_err()
                    .to_string(),
            ] {
                assert!(
                    message.contains(at) && message.contains(says),
                    "{ids} {message}"
                );
            }
        }
        // A level node without a mesh.
        let mut d = lod_doc(Some(json!([0.5, 0.2])));
        d.json["nodes"][3].as_object_mut().unwrap().remove("mesh");
        let message = load_err(&d.glb());
        assert!(
            message.contains("node 3") && message.contains("level 2 of node 1"),
            "{message}"
        );
    }

    #[test]
    fn level_nodes_are_skipped_wherever_they_appear_and_both_loaders_agree() {
        // Roots: level node 2 (with a child cube, node 5) first, then the
        // parent of the base, then a plain cube. Objects: base, plain.
        let mut d = lod_doc(Some(json!([0.5, 0.2])));
        let cube = 0;
        let child = d.node(json!({"name": "under_level", "mesh": cube}));
        d.json["nodes"][2]["children"] = json!([child]);
        d.roots(&[2, 0, 4]);
        let glb = d.glb();
        let scene = load(&glb).unwrap();
        let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["base", "plain"]);
        let geom = crate::scene::geometry::load_geometry_bytes(&glb, "t.glb").unwrap();
        assert_eq!(geom.object_count(), 2);
        // Level 0 geometry only: one cube primitive per object, placed at the
        // object's own node.
        let placed: Vec<(u32, glam::DVec3)> = geom
            .instances
            .iter()
            .map(|i| (i.object, i.transform.translation))
            .collect();
        assert_eq!(
            placed,
            [
                (0, glam::DVec3::new(101.0, 0.0, 0.0)),
                (1, glam::DVec3::new(0.0, 0.0, 50.0))
            ]
        );
        assert!(
            geom.instances
                .iter()
                .all(|i| geom.meshes[i.mesh as usize].indices.len() == 36)
        );
        for (o, ob) in scene.objects.iter().enumerate() {
            let tris: u64 = geom
                .instances
                .iter()
                .filter(|i| i.object as usize == o)
                .map(|i| geom.meshes[i.mesh as usize].indices.len() as u64 / 3)
                .sum();
            assert_eq!(tris, ob.triangles);
        }
    }

    #[test]
    fn mesh_names_fall_back_to_node_index() {
        let mut d = Doc::new();
        let p = d.positions(&CUBE);
        let m = d.push(
            "meshes",
            json!({"primitives": [{"attributes": {"POSITION": p}}]}),
        );
        d.node(json!({"name": "", "mesh": m}));
        d.node(json!({"name": "x", "mesh": m}));
        d.roots(&[1, 0]);
        let names: Vec<String> = load(&d.glb())
            .unwrap()
            .objects
            .into_iter()
            .map(|o| o.name)
            .collect();
        assert_eq!(names, ["x", "node_0"]);
    }

    #[test]
    fn dispatch_by_content() {
        let glb = one_cube_glb();
        assert_eq!(load_scene_bytes(&glb, "a").unwrap().objects.len(), 1);

        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        assert_eq!(
            load_scene_bytes(&d.gltf(), "a.gltf").unwrap().objects.len(),
            1
        );

        let summary = json!({"objects": [
            {"name": "box", "min": [0.0, 0.0, 0.0], "max": [1.0, 2.0, 3.0], "triangles": 7, "draw_calls": 2}
        ]});
        let bytes = serde_json::to_vec(&summary).unwrap();
        let scene = load_scene_bytes(&bytes, "s.json").unwrap();
        assert_eq!(scene.objects[0].triangles, 7);
        assert_eq!(scene.objects[0].draw_calls, 2);

        let message = load_scene_bytes(b"\x00\x01garbage", "g.bin")
            .unwrap_err()
            .to_string();
        assert!(
            message.starts_with("g.bin") && message.contains("not a scene"),
            "{message}"
        );

        // Files: GLB magic wins over the extension; .json means a summary.
        let dir = temp_dir("dispatch");
        let glb_path = dir.join("scene.json");
        std::fs::write(&glb_path, &glb).unwrap();
        assert_eq!(load_scene_file(&glb_path).unwrap().objects[0].triangles, 12);
        let summary_path = dir.join("summary.json");
        std::fs::write(&summary_path, &bytes).unwrap();
        assert_eq!(
            load_scene_file(&summary_path).unwrap().objects[0].triangles,
            7
        );
        let bad_summary = dir.join("bad.json");
        std::fs::write(&bad_summary, b"{\"asset\": {\"version\": \"2.0\"}}").unwrap();
        let message = load_scene_file(&bad_summary).unwrap_err().to_string();
        assert!(message.contains("bad.json"), "{message}");
        let missing = dir.join("missing.glb");
        let err = load_scene_file(&missing).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn deeply_nested_extras_do_not_break_dispatch() {
        let mut d = Doc::new();
        let cube = d.cube();
        let n = d.node(json!({"mesh": cube}));
        d.roots(&[n]);
        let mut json = d.finish_json(Some(format!(
            "data:application/octet-stream;base64,{}",
            STANDARD.encode(&d.bin)
        )));
        json["extras"] = json!("PLACEHOLDER");
        let deep = format!("{}{}", "[".repeat(10_000), "]".repeat(10_000));
        let text = serde_json::to_string(&json)
            .unwrap()
            .replace("\"PLACEHOLDER\"", &deep);
        let scene = load_scene_bytes(text.as_bytes(), "deep.gltf").unwrap();
        assert_eq!(scene.objects.len(), 1);
    }

    /// Many instances of a few meshes (the shape of a generated city).
    fn instanced_city(meshes: usize, nodes: usize, tris_per_mesh: usize) -> Vec<u8> {
        let mut d = Doc::new();
        let side = (tris_per_mesh as f64 / 2.0).sqrt().ceil() as usize;
        for m in 0..meshes {
            // A (side+1)² grid of vertices, 2·side² triangles.
            let pts: Vec<[f32; 3]> = (0..=side)
                .flat_map(|i| (0..=side).map(move |j| [i as f32, (m % 7) as f32, j as f32]))
                .collect();
            let mut idx: Vec<u32> = Vec::with_capacity(side * side * 6);
            let w = (side + 1) as u32;
            for i in 0..side as u32 {
                for j in 0..side as u32 {
                    let a = i * w + j;
                    idx.extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
                }
            }
            let p = d.positions(&pts);
            let bytes: Vec<u8> = idx.iter().flat_map(|v| v.to_le_bytes()).collect();
            let view = d.view(&bytes, None);
            let i = d.push(
                "accessors",
                json!({"bufferView": view, "componentType": 5125, "count": idx.len(), "type": "SCALAR"}),
            );
            d.mesh(&format!("m{m}"), p, Some(i), 4);
        }
        let roots: Vec<usize> = (0..nodes)
            .map(|k| {
                d.node(json!({"mesh": k % meshes,
                              "translation": [(k % 100) as f32 * 20.0, 0.0, (k / 100) as f32 * 20.0]}))
            })
            .collect();
        d.roots(&roots);
        d.glb()
    }

    #[test]
    fn instanced_meshes_are_read_once_and_counted_per_instance() {
        let bytes = instanced_city(10, 500, 200);
        let scene = load(&bytes).unwrap();
        assert_eq!(scene.objects.len(), 500);
        let per_mesh = 2 * 10 * 10;
        assert!(scene.objects.iter().all(|o| o.triangles == per_mesh));
        assert_eq!(scene.total_triangles(), 500 * per_mesh);
        assert_vec(scene.objects[101].min, [20.0, 1.0, 20.0]);
        assert_vec(scene.objects[101].max, [30.0, 1.0, 30.0]);
    }

    #[test]
    fn panics_become_bad_input_errors() {
        let err = guarded::<()>("p.glb", || panic!("boom {}", 42)).unwrap_err();
        assert!(err.is_bad_input());
        assert_eq!(
            err.to_string(),
            "p.glb: malformed glTF (the parser failed: boom 42)"
        );
        let err = guarded::<()>("p.glb", || std::panic::panic_any(7u8)).unwrap_err();
        assert!(err.to_string().contains("unknown panic"));
    }

    /// Corrupting any single byte of a valid GLB gives a scene or a clean
    /// error, never a panic.
    #[test]
    fn single_byte_corruptions_never_panic() {
        let mut d = Doc::new();
        let cube = d.cube();
        let strip = d.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        d.mesh("strip", strip, None, 5);
        let child = d.node(json!({"mesh": 1, "translation": [1.0, 2.0, 3.0]}));
        let n =
            d.node(json!({"mesh": cube, "children": [child], "rotation": [0.0, 0.0, 0.0, 1.0]}));
        d.roots(&[n]);
        let good = d.glb();
        for at in 0..good.len() {
            for value in [0u8, 0xFF, b'9', b'-', b'[', b'"', b'0', b'e'] {
                let mut bad = good.clone();
                bad[at] = value;
                if let Err(e) = load(&bad) {
                    let message = e.to_string();
                    assert!(
                        !message.contains("parser failed"),
                        "byte {at} = {value}: {message}"
                    );
                }
            }
        }
    }

    /// Replacing any single number of a valid document by an extreme value
    /// gives a scene or a clean error, never a panic.
    #[test]
    fn extreme_numbers_never_panic() {
        fn numbers(v: &Value, path: String, out: &mut Vec<String>) {
            match v {
                Value::Number(_) => out.push(path),
                Value::Array(a) => a
                    .iter()
                    .enumerate()
                    .for_each(|(i, x)| numbers(x, format!("{path}/{i}"), out)),
                Value::Object(o) => o
                    .iter()
                    .for_each(|(k, x)| numbers(x, format!("{path}/{k}"), out)),
                _ => {}
            }
        }
        let mut d = Doc::new();
        let cube = d.cube();
        let strip = d.positions(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        d.mesh("strip", strip, None, 5);
        let child = d.node(json!({"mesh": 1, "translation": [1.0, 2.0, 3.0]}));
        let n = d.node(
            json!({"mesh": cube, "children": [child], "rotation": [0.0, 0.0, 0.0, 1.0],
                              "scale": [1.0, 1.0, 1.0]}),
        );
        d.roots(&[n]);
        d.json["images"] = json!([{"bufferView": 0, "mimeType": "image/png"}]);
        let mut bin = d.bin.clone();
        bin.resize(bin.len().max(1), 0);
        let json = d.finish_json(None);
        let mut paths = Vec::new();
        numbers(&json, String::new(), &mut paths);
        let extremes = [
            json!(-1),
            json!(0),
            json!(1),
            json!(2),
            json!(3),
            json!(5121),
            json!(5126),
            json!(255),
            json!(253),
            json!(1u64 << 32),
            json!(1u64 << 62),
            json!(u64::MAX),
            json!(0.5),
            json!(1e39),
            json!(-1e39),
        ];
        for path in &paths {
            for x in &extremes {
                let mut j = json.clone();
                *j.pointer_mut(path).unwrap() = x.clone();
                if let Err(e) = load(&glb(&j, &bin)) {
                    let message = e.to_string();
                    assert!(
                        !message.contains("parser failed"),
                        "{path} = {x}: {message}"
                    );
                }
            }
        }
    }
}
