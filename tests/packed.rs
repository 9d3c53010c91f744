//! Scenes from a real glTF pipeline: the generated city through `gltfpack`
//! (its WebAssembly build, installed by the README's test command with
//! `npm ci --prefix tools/gltfpack`) — unquantized (`-noq`), quantized
//! (`KHR_mesh_quantization`, the default) and quantized with meshopt
//! compression (`-cc`, `EXT_meshopt_compression`) — loads and places like
//! the original.
//!
//! `gltfpack` splits every multi-material mesh into one node per material,
//! so a packed city has more objects (nodes with a mesh) than the original;
//! `-kn` keeps the named nodes (and so the same split in every packing), and
//! the `-noq -kn` packing is the reference the quantized ones are compared
//! with object for object.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::*;

/// Runs `gltfpack -i input -o output args…`.
fn gltfpack(input: &Path, output: &Path, args: &[&str]) {
    let cli = root().join("tools/gltfpack/node_modules/gltfpack/cli.js");
    assert!(
        cli.is_file(),
        "gltfpack is not installed: run `npm ci --prefix tools/gltfpack`"
    );
    let o = Command::new("node")
        .arg(cli)
        .args(["-i", s(input), "-o", s(output)])
        .args(args)
        .output()
        .expect("run node");
    assert!(o.status.success(), "gltfpack {args:?}: {}", stderr(&o));
}

/// `impostor info` of a scene as JSON.
fn info(scene: &Path) -> serde_json::Value {
    let o = run(&["info", s(scene)]);
    assert_eq!(code(&o), 0, "{}: {}", scene.display(), stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The JSON chunk of a GLB.
fn glb_json(path: &Path) -> serde_json::Value {
    let b = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes([b[12], b[13], b[14], b[15]]) as usize;
    serde_json::from_slice(&b[20..20 + n]).unwrap()
}

/// The largest `scale` component of the file's nodes (1 without any).
fn max_node_scale(json: &serde_json::Value) -> f64 {
    json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|n| n["scale"].as_array())
        .flatten()
        .map(|v| v.as_f64().unwrap().abs())
        .fold(1.0, f64::max)
}

/// Largest difference between two scenes' bounds corners.
fn bounds_gap(a: &serde_json::Value, b: &serde_json::Value) -> f64 {
    ["min", "max"]
        .iter()
        .flat_map(|k| (0..3).map(move |i| (k, i)))
        .map(|(k, i)| {
            (a["bounds"][k][i].as_f64().unwrap() - b["bounds"][k][i].as_f64().unwrap()).abs()
        })
        .fold(0.0, f64::max)
}

fn facts(i: &serde_json::Value) -> (u64, u64, u64) {
    let n = |k: &str| i[k].as_u64().unwrap();
    (n("objects"), n("triangles"), n("draw_calls"))
}

/// Asserts that `keys` of two placements' summaries differ by at most 3 %
/// of the larger (`name_a`, `name_b` name them in the message).
fn assert_summaries_close(
    a: &serde_json::Value,
    b: &serde_json::Value,
    keys: &[&str],
    name_a: &str,
    name_b: &str,
) {
    for key in keys {
        let (x, y) = (
            a["summary"][key].as_f64().unwrap(),
            b["summary"][key].as_f64().unwrap(),
        );
        assert!(
            (x - y).abs() <= 0.03 * x.max(y),
            "{key}: {x} {name_a} vs {y} {name_b}"
        );
    }
}

#[test]
fn gltfpack_output_loads_and_places_like_the_original() {
    let dir = tmp("packed");
    let city = city("0.1");
    let pack = |name: &str, args: &[&str]| -> PathBuf {
        let out = dir.join(name);
        gltfpack(&city, &out, args);
        out
    };
    let noq = pack("noq.glb", &["-noq", "-kn"]);
    let q = pack("q.glb", &["-kn"]);
    let cc = pack("cc.glb", &["-cc", "-kn"]);
    let required = |p: &Path| glb_json(p)["extensionsRequired"].clone();
    assert!(required(&noq).is_null());
    assert_eq!(required(&q), serde_json::json!(["KHR_mesh_quantization"]));
    assert_eq!(
        required(&cc),
        serde_json::json!(["KHR_mesh_quantization", "EXT_meshopt_compression"])
    );

    let (orig, i_noq, i_q, i_cc) = (info(&city), info(&noq), info(&q), info(&cc));
    // Unquantized, gltfpack only regroups: the same triangles and draw
    // calls, and the same scene bounds to float precision.
    let (objects, triangles, draw_calls) = facts(&orig);
    let (packed_objects, t, d) = facts(&i_noq);
    assert_eq!((t, d), (triangles, draw_calls));
    assert!(packed_objects >= objects, "{packed_objects} < {objects}");
    assert!(bounds_gap(&orig, &i_noq) < 1e-4, "{orig} vs {i_noq}");
    // Quantized: the same objects; meshopt compression is lossless, so the
    // compressed file reads exactly as the quantized one.
    assert_eq!(facts(&i_q), facts(&i_noq));
    assert_eq!(i_cc, i_q);
    // Positions are snapped to a grid whose step is the scale of the
    // dequantizing node transforms gltfpack adds (14 bits over the scene:
    // ~0.03 m here) in each mesh's own space, so a corner moves by at most
    // half a step times the largest scale of the original nodes above it.
    let q_json = glb_json(&q);
    let step = q_json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n.get("mesh").is_some())
        .filter_map(|n| n["scale"][0].as_f64())
        .fold(0.0, f64::max);
    assert!(step > 0.0 && step < 0.1, "quantization step {step}");
    let tolerance = 0.5 * step * max_node_scale(&glb_json(&city)) + 1e-4;
    let gap = bounds_gap(&i_noq, &i_q);
    assert!(gap <= tolerance, "bounds moved {gap} > {tolerance}");
    // Control: the quantized bounds are not simply the original ones (the
    // dequantization transforms were read, yet positions did move).
    assert!(gap > 0.0);

    // Placement: the original places; the packings place the same objects,
    // the compressed file exactly as the quantized one.
    let job = root().join("fixtures/jobs/city-small.json");
    let placed = |scene: &Path, name: &str| {
        let out = dir.join(name);
        let o = place(scene, &job, &out, &[]);
        assert!(
            matches!(code(&o), 0 | 3),
            "{}: {}",
            scene.display(),
            stderr(&o)
        );
        out
    };
    let p_orig = read_json(&placed(&city, "p-orig.json"));
    assert!(p_orig["summary"]["cpvs"].as_u64().unwrap() > 0);
    let p_noq = placed(&noq, "p-noq.json");
    let p_q = placed(&q, "p-q.json");
    let p_cc = placed(&cc, "p-cc.json");
    assert_same_file(&p_q, &p_cc);
    // Moving bounds by up to a few decimetres shifts where the view-cell
    // hierarchy splits and which candidates pay off, so the discrete
    // placement changes a little; 3 % on the CPV count and the impostor
    // memory is well above the ~1 % seen and well below what a lost
    // dequantization transform does (objects 34× too large: the placement
    // of a different scene).
    let (a, b) = (read_json(&p_noq), read_json(&p_q));
    assert_summaries_close(
        &a,
        &b,
        &["cpvs", "memory_bytes"],
        "unquantized",
        "quantized",
    );
    assert_eq!(b["summary"]["unsolved_cpvs"], a["summary"]["unsolved_cpvs"]);
}

/// A real third-party scene (the race-track park of `../shared/scenes/`,
/// 3,856 named nodes) through `gltfpack` with meshopt compression: without
/// quantization (`-noq -kn -cc`) it is the same scene object for object and
/// places byte for byte as the original; quantized (`-kn -cc`) it has the
/// same objects in the same order, each moved by less than the quantization
/// step, and a placement within 3 % of the original's.
#[test]
fn a_packed_real_scene_places_like_the_original() {
    let Some(forza) = shared_scene("forza") else {
        return;
    };
    let dir = tmp("packed-forza");
    let job = root().join("fixtures/jobs/forza.json");
    let noq = dir.join("noq.glb");
    let q = dir.join("q.glb");
    gltfpack(&forza, &noq, &["-noq", "-kn", "-cc"]);
    gltfpack(&forza, &q, &["-kn", "-cc"]);
    assert_eq!(
        glb_json(&noq)["extensionsRequired"],
        serde_json::json!(["EXT_meshopt_compression"])
    );
    assert_eq!(
        glb_json(&q)["extensionsRequired"],
        serde_json::json!(["KHR_mesh_quantization", "EXT_meshopt_compression"])
    );
    // The compressed files are not the original in disguise.
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&q) * 2 < size(&forza),
        "{} vs {}",
        size(&q),
        size(&forza)
    );

    let load = |p: &Path| optimizer::scene::gltf_load::load_scene_file(p).unwrap();
    let (orig, s_noq, s_q) = (load(&forza), load(&noq), load(&q));
    assert_eq!(orig.objects.len(), 3856);
    let (lo, hi) = orig.bounds();
    let extent = (hi - lo).max_element();
    for (packed, tolerance) in [(&s_noq, 1e-4), (&s_q, extent / (1 << 14) as f64)] {
        assert_eq!(packed.objects.len(), orig.objects.len());
        for (i, (a, b)) in orig.objects.iter().zip(&packed.objects).enumerate() {
            // Quantized, each mesh hangs from an unnamed child node of
            // its named node (the dequantization transform).
            if std::ptr::eq(packed, &s_noq) {
                assert_eq!(a.name, b.name, "object {i}");
            }
            assert_eq!(
                (a.triangles, a.draw_calls),
                (b.triangles, b.draw_calls),
                "object {i} ({})",
                a.name
            );
            let moved = (a.min - b.min)
                .abs()
                .max((a.max - b.max).abs())
                .max_element();
            assert!(
                moved <= tolerance,
                "object {i} ({}) moved {moved} > {tolerance}",
                a.name
            );
        }
    }
    // Placement: byte for byte without quantization, close with it.
    let placed = |scene: &Path, name: &str| {
        let out = dir.join(name);
        let o = place(scene, &job, &out, &[]);
        assert_eq!(code(&o), 0, "{}: {}", scene.display(), stderr(&o));
        out
    };
    let p_orig = placed(&forza, "p-orig.json");
    assert_same_file(&p_orig, &placed(&noq, "p-noq.json"));
    let (a, b) = (read_json(&p_orig), read_json(&placed(&q, "p-q.json")));
    assert!(a["summary"]["impostors"].as_u64().unwrap() > 100);
    assert_summaries_close(
        &a,
        &b,
        &["cpvs", "impostors", "memory_bytes"],
        "original",
        "quantized",
    );
    assert_eq!(b["summary"]["unsolved_cpvs"], 0);
}

/// Area-weighted moments of a scene's world-space triangles, as the
/// geometry loader (which the bake renders) places them: total area, the
/// area-weighted centroid and second moments about it. The same for the
/// same triangles in any order and grouping; moved or turned instances
/// change them.
fn moments(bytes: &[u8]) -> [f64; 10] {
    let g = optimizer::scene::geometry::load_geometry_bytes(bytes, "t.glb").unwrap();
    let mut m = [0.0f64; 10];
    for inst in &g.instances {
        let mesh = &g.meshes[inst.mesh as usize];
        for t in mesh.indices.chunks_exact(3) {
            let p: Vec<_> = t
                .iter()
                .map(|&i| {
                    inst.transform
                        .transform_point3(mesh.positions[i as usize].as_dvec3())
                })
                .collect();
            let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            let c = (p[0] + p[1] + p[2]) / 3.0;
            let v = [
                1.0,
                c.x,
                c.y,
                c.z,
                c.x * c.x,
                c.y * c.y,
                c.z * c.z,
                c.x * c.y,
                c.x * c.z,
                c.y * c.z,
            ];
            for (acc, x) in m.iter_mut().zip(v) {
                *acc += area * x;
            }
        }
    }
    let a = m[0];
    let c = [m[1] / a, m[2] / a, m[3] / a];
    [
        a,
        c[0],
        c[1],
        c[2],
        m[4] / a - c[0] * c[0],
        m[5] / a - c[1] * c[1],
        m[6] / a - c[2] * c[2],
        m[7] / a - c[0] * c[1],
        m[8] / a - c[0] * c[2],
        m[9] / a - c[1] * c[2],
    ]
}

/// Largest difference between two sets of moments, relative to each
/// moment's magnitude (at least 1).
fn moments_gap(a: &[f64; 10], b: &[f64; 10]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / x.abs().max(1.0))
        .fold(0.0, f64::max)
}

/// A GLB with the same binary chunk and `edit` applied to its JSON.
fn with_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let b = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes([b[12], b[13], b[14], b[15]]) as usize;
    let mut json = glb_json(path);
    edit(&mut json);
    let mut j = serde_json::to_vec(&json).unwrap();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let bin = &b[20 + n..];
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + j.len() + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
    out.extend_from_slice(&j);
    out.extend_from_slice(bin);
    out
}

/// The city through `gltfpack -mi`, which draws repeated meshes as GPU
/// instances (`EXT_mesh_gpu_instancing`: one node, one translation,
/// rotation and scale per instance): every instance is an object, placed
/// where the uninstanced packing has the same triangles (same area-weighted
/// moments, same bounds); quantized and compressed on top, where the
/// uninstanced quantized packing has them, within its rounding. The file places and keeps the guarantee, and bakes.
/// Control: the same file read as if the instances were not there (the
/// extension removed from its nodes) loses geometry.
#[test]
fn gpu_instanced_scenes_load_every_instance() {
    let dir = tmp("instanced");
    let city = city("0.1");
    let noq = dir.join("noq.glb");
    let mi = dir.join("mi.glb");
    let miq = dir.join("miq.glb");
    gltfpack(&city, &noq, &["-noq"]);
    gltfpack(&city, &mi, &["-noq", "-mi"]);
    gltfpack(&city, &miq, &["-mi", "-cc"]);
    let json = glb_json(&mi);
    assert_eq!(
        json["extensionsRequired"],
        serde_json::json!(["EXT_mesh_gpu_instancing"])
    );
    let instanced_nodes = json["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n["extensions"]["EXT_mesh_gpu_instancing"].is_object())
        .count();

    let (i_noq, i_mi, i_miq) = (info(&noq), info(&mi), info(&miq));
    let (objects, triangles, draw_calls) = facts(&i_mi);
    assert_eq!((triangles, draw_calls), (facts(&i_noq).1, facts(&i_noq).2));
    assert!(
        objects > 2 * instanced_nodes as u64 && instanced_nodes > 10,
        "{objects} objects from {instanced_nodes} instanced nodes"
    );
    assert!(bounds_gap(&i_noq, &i_mi) < 1e-3, "{i_noq} vs {i_mi}");
    assert_eq!((facts(&i_miq).1, facts(&i_miq).2), (triangles, draw_calls));

    let read = |p: &Path| std::fs::read(p).unwrap();
    let reference = moments(&read(&noq));
    let gap = moments_gap(&reference, &moments(&read(&mi)));
    assert!(gap < 1e-5, "instanced geometry differs by {gap}");
    // Quantized (rotations as normalized 16-bit integers), against the
    // same quantization without instancing (quantizing alone moves the
    // moments by up to 6 %: area 813 k -> 792 k m² here).
    let q = dir.join("q.glb");
    gltfpack(&city, &q, &["-cc"]);
    let gap_q = moments_gap(&moments(&read(&q)), &moments(&read(&miq)));
    assert!(
        gap_q < 1e-3,
        "quantized instanced geometry differs by {gap_q}"
    );
    // Control: without reading the instances the geometry is another.
    let stripped = with_json(&mi, |j| {
        for n in j["nodes"].as_array_mut().unwrap() {
            if let Some(e) = n.get_mut("extensions").and_then(|e| e.as_object_mut()) {
                e.remove("EXT_mesh_gpu_instancing");
            }
        }
        j.as_object_mut().unwrap().remove("extensionsRequired");
    });
    let lost = moments_gap(&reference, &moments(&stripped));
    assert!(lost > 1e-2, "the instances did not matter ({lost})");

    // The instanced file places, keeps the guarantee and bakes.
    let job = root().join("fixtures/jobs/city-small.json");
    let p = dir.join("p.json");
    let o = place(&mi, &job, &p, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let placement = read_json(&p);
    assert!(placement["summary"]["impostors"].as_u64().unwrap() > 0);
    let e = dir.join("e.json");
    let o = run(&[
        "evaluate",
        s(&mi),
        "--job",
        s(&job),
        "--placement",
        s(&p),
        "--views",
        "2000",
        "-o",
        s(&e),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert_eq!(read_json(&e)["violations_in_solved"], 0);
    let baked = dir.join("baked.glb");
    let o = run(&[
        "bake",
        s(&mi),
        "--job",
        s(&job),
        "--placement",
        s(&p),
        "-o",
        s(&baked),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(std::fs::metadata(&baked).unwrap().len() > 0);
}

/// Runs `tools/gltf-draco` (glTF Transform with Google's Draco encoder) on
/// `input` with `method`.
fn draco(input: &Path, output: &Path, method: &str) {
    let script = root().join("tools/gltf-draco/draco.mjs");
    assert!(
        root().join("tools/gltf-draco/node_modules").is_dir(),
        "the Draco encoder is not installed: run `npm ci --prefix tools/gltf-draco`"
    );
    let o = Command::new("node")
        .arg(script)
        .args([s(input), s(output), method])
        .output()
        .expect("run node");
    assert!(o.status.success(), "draco {method}: {}", stderr(&o));
}

/// The city compressed with Draco (`KHR_draco_mesh_compression`, Google's
/// encoder, EdgeBreaker and sequential connectivity) is the same scene:
/// the same objects in the same order with the same triangles and draw
/// calls, each object's box within the positions' quantization step, the
/// same world geometry (area-weighted moments); it places within 3 % of the
/// original and bakes. A stream cut short is an error naming the
/// primitive, and corrupted streams never panic.
#[test]
fn draco_compressed_scenes_load_as_the_original() {
    let dir = tmp("draco");
    let city = city("0.1");
    let orig = optimizer::scene::gltf_load::load_scene_file(&city).unwrap();
    let reference = moments(&std::fs::read(&city).unwrap());
    let job = root().join("fixtures/jobs/city-small.json");
    let p_orig = dir.join("p-orig.json");
    assert!(matches!(code(&place(&city, &job, &p_orig, &[])), 0 | 3));
    for method in ["edgebreaker", "sequential"] {
        let packed = dir.join(format!("{method}.glb"));
        draco(&city, &packed, method);
        let json = glb_json(&packed);
        assert_eq!(
            json["extensionsRequired"],
            serde_json::json!(["KHR_draco_mesh_compression"])
        );
        let size = std::fs::metadata(&packed).unwrap().len();
        assert!(
            size * 5 < std::fs::metadata(&city).unwrap().len(),
            "{size} bytes"
        );

        let scene = optimizer::scene::gltf_load::load_scene_file(&packed).unwrap();
        assert_eq!(scene.objects.len(), orig.objects.len());
        for (i, (a, b)) in orig.objects.iter().zip(&scene.objects).enumerate() {
            assert_eq!(
                (&a.name, a.triangles, a.draw_calls),
                (&b.name, b.triangles, b.draw_calls),
                "object {i}"
            );
            // 14 bits over a mesh's bounds, times the node's scale.
            let step = (a.max - a.min).max_element() / f64::from(1 << 14);
            let moved = (a.min - b.min)
                .abs()
                .max((a.max - b.max).abs())
                .max_element();
            assert!(
                moved <= step + 1e-4,
                "object {i} ({}) moved {moved}",
                a.name
            );
        }
        let gap = moments_gap(&reference, &moments(&std::fs::read(&packed).unwrap()));
        assert!(gap < 1e-3, "{method}: geometry differs by {gap}");

        let p = dir.join(format!("p-{method}.json"));
        let o = place(&packed, &job, &p, &[]);
        assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
        assert_summaries_close(
            &read_json(&p_orig),
            &read_json(&p),
            &["cpvs", "memory_bytes"],
            "original",
            method,
        );
    }
    let packed = dir.join("edgebreaker.glb");
    let baked = dir.join("baked.glb");
    let o = run(&[
        "bake",
        s(&packed),
        "--placement",
        s(&dir.join("p-edgebreaker.json")),
        "-o",
        s(&baked),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));

    // Bad streams: cut short, or bytes changed inside the compressed view.
    let json = glb_json(&packed);
    let view =
        json["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["bufferView"]
            .as_u64()
            .unwrap() as usize;
    let v = &json["bufferViews"][view];
    let (offset, length) = (
        v["byteOffset"].as_u64().unwrap_or(0) as usize,
        v["byteLength"].as_u64().unwrap() as usize,
    );
    let bytes = std::fs::read(&packed).unwrap();
    let n = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let bin = 20 + n + 8;
    let load = |b: &[u8]| {
        std::panic::catch_unwind(|| optimizer::scene::gltf_load::load_scene_bytes(b, "d.glb"))
            .expect("the loader panicked")
    };
    let short = with_json(&packed, |j| {
        j["bufferViews"][view]["byteLength"] = serde_json::json!(length / 2);
    });
    let e = load(&short).unwrap_err().to_string();
    assert!(
        e.contains("mesh 0 primitive 0 KHR_draco_mesh_compression"),
        "{e}"
    );
    let mut errors = 0;
    for k in 0..200usize {
        let mut b = bytes.clone();
        let at = bin + offset + (k * 7919) % length;
        b[at] ^= 1 << (k % 8);
        errors += usize::from(load(&b).is_err());
    }
    eprintln!("draco: {errors} of 200 corrupted streams refused");
}
