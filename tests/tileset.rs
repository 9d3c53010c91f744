//! `impostor tiles`: a placement and its baked impostors as a 3D Tiles 1.1
//! tileset, checked for structure in Rust (the 3D Tiles validator is not
//! run): every content file exists and passes the Khronos glTF validator,
//! every impostor appears exactly once under a REPLACE cluster tile with a
//! request volume holding its view cell (in the z-up frame), bounding
//! volumes hold their children's and geometric errors decrease downwards,
//! and each impostor's atlas is sized to its layers.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use crate::util::*;

/// A 3D Tiles box as (min, max) corners; `None` for other volumes. Every
/// box written is axis-aligned (diagonal half-axes).
fn aabb(v: &Value) -> Option<([f64; 3], [f64; 3])> {
    let b: Vec<f64> = v["box"]
        .as_array()?
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(b.len(), 12, "{v}");
    let off = [b[4], b[5], b[6], b[8], b[9], b[10]];
    assert!(off.iter().all(|&x| x == 0.0), "not axis-aligned: {v}");
    let h = [b[3].abs(), b[7].abs(), b[11].abs()];
    Some((
        [b[0] - h[0], b[1] - h[1], b[2] - h[2]],
        [b[0] + h[0], b[1] + h[1], b[2] + h[2]],
    ))
}

fn holds(outer: ([f64; 3], [f64; 3]), p: [f64; 3]) -> bool {
    let eps = 1e-6 * (1.0 + p.iter().map(|x| x.abs()).fold(0.0, f64::max));
    (0..3).all(|a| outer.0[a] - eps <= p[a] && p[a] <= outer.1[a] + eps)
}

fn z_up(p: [f64; 3]) -> [f64; 3] {
    [p[0], -p[2], p[1]]
}

/// View-space points (a 12³ grid) inside an impostor's view cell, y-up.
fn cell_points(cell: &Value, job: &Value) -> Vec<[f64; 3]> {
    let f = |v: &Value| -> [f64; 3] {
        let a: Vec<f64> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        [a[0], a[1], a[2]]
    };
    if let Some(b) = cell.get("box") {
        let (lo, hi) = (f(&b["min"]), f(&b["max"]));
        return (0..8)
            .map(|k| {
                [
                    if k & 1 == 0 { lo[0] } else { hi[0] },
                    if k & 2 == 0 { lo[1] } else { hi[1] },
                    if k & 4 == 0 { lo[2] } else { hi[2] },
                ]
            })
            .collect();
    }
    let sh = &cell["shaft"];
    let (apex, axis) = (f(&sh["apex"]), f(&sh["axis"]));
    let len = axis.iter().map(|x| x * x).sum::<f64>().sqrt();
    let cos = sh["half_angle_deg"].as_f64().unwrap().to_radians().cos();
    let dmin = sh["min_distance"].as_f64().unwrap();
    let (lo, hi) = (f(&job["view_space"]["min"]), f(&job["view_space"]["max"]));
    let n = 12;
    let mut out = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            for k in 0..=n {
                let t = [i, j, k].map(|x| x as f64 / n as f64);
                let p: [f64; 3] = std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * t[a]);
                let d: [f64; 3] = std::array::from_fn(|a| p[a] - apex[a]);
                let dist = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                let along = d.iter().zip(&axis).map(|(x, y)| x * y).sum::<f64>() / len;
                if dist >= dmin && along >= cos * dist {
                    out.push(p);
                }
            }
        }
    }
    out
}

/// Checks the tileset's structure; returns the content URIs and, per
/// impostor id, how often it appears.
fn check_tileset(
    ts: &Value,
    placement: &Value,
    job: &Value,
) -> Result<(BTreeSet<String>, Vec<u32>), String> {
    if ts["asset"]["version"] != "1.1" {
        return Err(format!("asset.version {}", ts["asset"]["version"]));
    }
    let root = &ts["root"];
    if root["refine"] != "ADD" {
        return Err("the root must refine by ADD".into());
    }
    let below = |a: Option<f64>, b: Option<f64>| matches!((a, b), (Some(a), Some(b)) if a < b);
    if !below(
        root["geometricError"].as_f64(),
        ts["geometricError"].as_f64(),
    ) {
        return Err("the root's error is not below the tileset's".into());
    }
    let impostors = placement["impostors"].as_array().unwrap();
    let mut seen = vec![0u32; impostors.len()];
    let mut uris = BTreeSet::new();
    let mut cells_with_points = 0;
    let mut stack = vec![(root, None::<&Value>)];
    while let Some((tile, parent)) = stack.pop() {
        let bv = aabb(&tile["boundingVolume"]).ok_or("a bounding volume is not a box")?;
        if let Some(uri) = tile["content"]["uri"].as_str() {
            uris.insert(uri.to_string());
        }
        if let Some(p) = parent {
            let pb = aabb(&p["boundingVolume"]).unwrap();
            if !(holds(pb, bv.0) && holds(pb, bv.1)) {
                return Err(format!("a child's box {bv:?} leaves its parent's {pb:?}"));
            }
            let (e, pe) = (
                tile["geometricError"].as_f64(),
                p["geometricError"].as_f64(),
            );
            if !below(e, pe) {
                return Err(format!(
                    "a child's error {e:?} is not below its parent's {pe:?}"
                ));
            }
        }
        if let Some(id) = tile
            .get("viewerRequestVolume")
            .map(|_| &tile["extras"]["impostor"])
        {
            let id = id
                .as_u64()
                .ok_or("a request volume on a tile that is no impostor")?
                as usize;
            let imp = impostors
                .get(id)
                .ok_or(format!("impostor {id} is not in the placement"))?;
            seen[id] += 1;
            let p = parent.ok_or("an impostor tile at the root")?;
            if p["refine"] != "REPLACE" || p["content"]["uri"].as_str().is_none() {
                return Err(format!("impostor {id} does not replace a geometry tile"));
            }
            let vrv = aabb(&tile["viewerRequestVolume"]).ok_or("request volume not a box")?;
            let points = cell_points(&imp["view_cell"], job);
            cells_with_points += usize::from(!points.is_empty());
            if let Some(q) = points.into_iter().find(|&q| !holds(vrv, z_up(q))) {
                return Err(format!(
                    "impostor {id}: view cell point {q:?} is outside its request volume {vrv:?}"
                ));
            }
        }
        for c in tile["children"].as_array().into_iter().flatten() {
            stack.push((c, Some(tile)));
        }
    }
    if cells_with_points * 2 < impostors.len() {
        return Err(format!(
            "only {cells_with_points} of {} view cells meet the sampled view space: the containment check saw too little",
            impostors.len()
        ));
    }
    Ok((uris, seen))
}

fn validate_all(files: &[&Path]) -> Value {
    let tool = root().join("tools/gltf-validator");
    assert!(
        tool.join("node_modules/gltf-validator").is_dir(),
        "the glTF validator is not installed: run `npm ci --prefix tools/gltf-validator`"
    );
    let o = Command::new("node")
        .arg(tool.join("validate-many.js"))
        .args(files)
        .output()
        .expect("run node");
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("validator output: {e}: {}", stderr(&o)))
}

fn tiles(scene: &Path, job: &Path, p: &Path, glb: &Path, out: &Path) -> std::process::Output {
    run(&[
        "tiles",
        s(scene),
        "--job",
        s(job),
        "--placement",
        s(p),
        "--impostors",
        s(glb),
        "-o",
        s(out),
    ])
}

#[test]
fn tileset_replaces_clusters_by_impostors_inside_their_cells() {
    let dir = tmp("tileset");
    let city = city("0.1");
    let job = root().join("fixtures/jobs/city-small.json");
    let p = dir.join("p.json");
    let o = place(&city, &job, &p, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let glb = dir.join("impostors.glb");
    let o = bake(&city, &p, &job, &glb, &dir.join("bake.json"));
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let out = dir.join("tiles");
    let o = tiles(&city, &job, &p, &glb, &out);
    assert_eq!(code(&o), 0, "{}", stderr(&o));

    let (placement, jobv) = (read_json(&p), read_json(&job));
    let ts = read_json(&out.join("tileset.json"));
    let (uris, seen) = check_tileset(&ts, &placement, &jobv).unwrap_or_else(|e| panic!("{e}"));
    assert!(!placement["impostors"].as_array().unwrap().is_empty());
    assert!(
        seen.iter().all(|&n| n == 1),
        "impostors not exactly once: {seen:?}"
    );
    let files: Vec<_> = uris.iter().map(|u| out.join(u)).collect();
    for f in &files {
        assert!(f.is_file(), "{} is referenced but missing", f.display());
    }
    let refs: Vec<&Path> = files.iter().map(|f| f.as_path()).collect();
    let report = validate_all(&refs);
    for (file, r) in report.as_object().unwrap() {
        assert_eq!(r["numErrors"], 0, "{file}: {r}");
    }
    assert_eq!(report.as_object().unwrap().len(), files.len());
    // Each impostor's content has an atlas of its own, no larger than a
    // square of ⌈√layers⌉ layers a side (resolution and two 4-texel
    // gutters each; the height rounded up to a multiple of 4).
    for imp in placement["impostors"].as_array().unwrap() {
        let glb = std::fs::read(out.join(format!("impostor-{}.glb", imp["id"]))).unwrap();
        let at = glb
            .windows(8)
            .position(|w| w == b"\x89PNG\r\n\x1a\n")
            .expect("a PNG atlas");
        let be = |k: usize| u32::from_be_bytes(glb[at + k..at + k + 4].try_into().unwrap());
        let (w, h) = (be(16), be(20));
        let side = imp["resolution"].as_u64().unwrap() as u32 + 8;
        let per = (imp["layers"].as_u64().unwrap() as f64).sqrt().ceil() as u32;
        assert!(
            w <= per * side && h <= per * side + 3,
            "impostor {}: a {w}×{h} atlas for {} layers of {side} texels",
            imp["id"],
            imp["layers"]
        );
    }

    // Controls: the checks fail on a shrunken request volume, a child box
    // grown beyond its parent, and a duplicated impostor.
    let mut bad = ts.clone();
    let first = &mut bad["root"]["children"][0]["children"][0];
    first["viewerRequestVolume"]["box"][3] = 0.001.into();
    first["viewerRequestVolume"]["box"][7] = 0.001.into();
    assert!(check_tileset(&bad, &placement, &jobv).is_err());
    let mut bad = ts.clone();
    bad["root"]["children"][0]["children"][0]["boundingVolume"]["box"][3] = 1e6.into();
    assert!(check_tileset(&bad, &placement, &jobv).is_err());
    let mut bad = ts.clone();
    let dup = bad["root"]["children"][0]["children"][0].clone();
    bad["root"]["children"][0]["children"]
        .as_array_mut()
        .unwrap()
        .push(dup);
    let (_, seen) = check_tileset(&bad, &placement, &jobv).unwrap();
    assert!(seen.contains(&2));

    // Deterministic: a second export is byte-identical.
    let again = dir.join("tiles-again");
    let o = tiles(&city, &job, &p, &glb, &again);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    for u in uris.iter().map(String::as_str).chain(["tileset.json"]) {
        assert_same_file(&out.join(u), &again.join(u));
    }

    // Bad input: a placement of another scene, a GLB of another placement,
    // an output directory that cannot be made.
    let other = dir.join("other.glb");
    let o = run(&[
        "gen-city",
        "--scale",
        "0.05",
        "--seed",
        "7",
        "-o",
        s(&other),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let o = tiles(&other, &job, &p, &glb, &dir.join("t2"));
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("does not match the scene"),
        "{}",
        stderr(&o)
    );
    let boxes = dir.join("boxes.json");
    let o = place(&city, &job, &boxes, &["--method", "boxes"]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let o = tiles(&city, &job, &boxes, &glb, &dir.join("t3"));
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(
        stderr(&o).contains("not baked from this placement"),
        "{}",
        stderr(&o)
    );
    let file = dir.join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let o = tiles(&city, &job, &p, &glb, &file.join("sub"));
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("a-file"), "{}", stderr(&o));
}
