//! `impostor tiles`: a placement and its baked impostors as a 3D Tiles 1.1
//! tileset, checked for structure in Rust (the 3D Tiles validator is not
//! run): every content file exists and passes the Khronos glTF validator;
//! each group's contents lie in its cluster tile's box and errors do not
//! increase downwards; below each cluster tile (REPLACE) its switch, boxes
//! of viewer positions nested as request volumes, each split into parts
//! that tile it; every leaf draws each of the group's objects exactly once
//! (by an impostor or as geometry), only impostors whose view cells hold
//! the whole leaf and a CPV of a region holding it draws; and from the
//! centre of every CPV's region, descending the request volumes finds a
//! leaf drawing each of the CPV's impostors (or one replacing more of its
//! objects). Each impostor's atlas is sized to its layers.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use serde_json::Value;

use crate::util::*;

type Box3 = ([f64; 3], [f64; 3]);

/// A 3D Tiles box as (min, max) corners, a sphere as its bounding box.
/// Every box written is axis-aligned (diagonal half-axes).
fn aabb(v: &Value) -> Box3 {
    if let Some(s) = v["sphere"].as_array() {
        let s: Vec<f64> = s.iter().map(|x| x.as_f64().unwrap()).collect();
        return (
            [s[0] - s[3], s[1] - s[3], s[2] - s[3]],
            [s[0] + s[3], s[1] + s[3], s[2] + s[3]],
        );
    }
    let b: Vec<f64> = v["box"]
        .as_array()
        .unwrap_or_else(|| panic!("neither box nor sphere: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(b.len(), 12, "{v}");
    let off = [b[4], b[5], b[6], b[8], b[9], b[10]];
    assert!(off.iter().all(|&x| x == 0.0), "not axis-aligned: {v}");
    let h = [b[3].abs(), b[7].abs(), b[11].abs()];
    (
        [b[0] - h[0], b[1] - h[1], b[2] - h[2]],
        [b[0] + h[0], b[1] + h[1], b[2] + h[2]],
    )
}

fn holds(outer: Box3, p: [f64; 3]) -> bool {
    let eps = 1e-6 * (1.0 + p.iter().map(|x| x.abs()).fold(0.0, f64::max));
    (0..3).all(|a| outer.0[a] - eps <= p[a] && p[a] <= outer.1[a] + eps)
}

fn holds_box(outer: Box3, inner: Box3) -> bool {
    holds(outer, inner.0) && holds(outer, inner.1)
}

fn volume(b: Box3) -> f64 {
    (0..3).map(|a| b.1[a] - b.0[a]).product()
}

fn z_up(p: [f64; 3]) -> [f64; 3] {
    [p[0], -p[2], p[1]]
}

/// The corners, y-up, of a z-up box.
fn y_up_corners(b: Box3) -> Vec<[f64; 3]> {
    (0..8)
        .map(|k| {
            let z: [f64; 3] =
                std::array::from_fn(|a| if k >> a & 1 == 0 { b.0[a] } else { b.1[a] });
            [z[0], z[2], -z[1]]
        })
        .collect()
}

fn vec3(v: &Value) -> [f64; 3] {
    std::array::from_fn(|a| v[a].as_f64().unwrap())
}

fn ids(v: &Value) -> Vec<u64> {
    v.as_array()
        .map(|a| a.iter().map(|x| x.as_u64().unwrap()).collect())
        .unwrap_or_default()
}

/// Whether the y-up point `p` lies in the view cell `cell` (within 1 mm
/// or 0.01°).
fn in_cell(cell: &Value, p: [f64; 3]) -> bool {
    if let Some(b) = cell.get("box") {
        let (lo, hi) = (vec3(&b["min"]), vec3(&b["max"]));
        return (0..3).all(|a| lo[a] - 1e-3 <= p[a] && p[a] <= hi[a] + 1e-3);
    }
    let sh = &cell["shaft"];
    let (apex, axis) = (vec3(&sh["apex"]), vec3(&sh["axis"]));
    let d: [f64; 3] = std::array::from_fn(|a| p[a] - apex[a]);
    let dist = d.iter().map(|x| x * x).sum::<f64>().sqrt();
    let len = axis.iter().map(|x| x * x).sum::<f64>().sqrt();
    let cos = d.iter().zip(&axis).map(|(x, y)| x * y).sum::<f64>() / (len * dist);
    dist >= sh["min_distance"].as_f64().unwrap() - 1e-3
        && cos.clamp(-1.0, 1.0).acos().to_degrees() <= sh["half_angle_deg"].as_f64().unwrap() + 0.01
}

/// Checks a switch tile and what is below it (`group`: the group's
/// objects, `bounds`: its cluster tile's box); returns its leaves as
/// (request volume, impostors drawn).
fn check_switch(
    t: &Value,
    group: &BTreeSet<u64>,
    bounds: Box3,
    placement: &Value,
    leaves: &mut Vec<(Box3, Vec<u64>)>,
) -> Result<(), String> {
    let vrv = aabb(&t["viewerRequestVolume"]);
    if t["content"].is_object() || t["refine"] != "ADD" {
        return Err("a switch tile has content or does not add".into());
    }
    let children = t["children"].as_array().cloned().unwrap_or_default();
    let impostors = &placement["impostors"];
    if t["extras"].get("impostors").is_none() {
        // A split: its parts tile its box.
        let parts: Vec<Box3> = children
            .iter()
            .map(|c| aabb(&c["viewerRequestVolume"]))
            .collect();
        if parts.len() != 2 || parts.iter().any(|&p| !holds_box(vrv, p)) {
            return Err(format!(
                "a split's parts {parts:?} are not two boxes in {vrv:?}"
            ));
        }
        if (parts.iter().map(|&p| volume(p)).sum::<f64>() - volume(vrv)).abs() > 1e-6 * volume(vrv)
        {
            return Err(format!("a split's parts {parts:?} do not fill {vrv:?}"));
        }
        for c in &children {
            check_switch(c, group, bounds, placement, leaves)?;
        }
        return Ok(());
    }
    let drawn = ids(&t["extras"]["impostors"]);
    let mut objects: Vec<u64> = Vec::new();
    for c in &children {
        let uri = c["content"]["uri"]
            .as_str()
            .ok_or("a leaf's child without content")?;
        if !holds_box(bounds, aabb(&c["boundingVolume"])) {
            return Err(format!("{uri} leaves its group's box"));
        }
        match c["extras"]["impostor"].as_u64() {
            Some(id) => {
                if uri != format!("impostor-{id}.glb") || !drawn.contains(&id) {
                    return Err(format!("{uri} under a leaf drawing {drawn:?}"));
                }
                objects.extend(ids(&impostors[id as usize]["objects"]));
            }
            None => objects.extend(ids(&c["extras"]["objects"])),
        }
    }
    for &id in &drawn {
        let imp = &impostors[id as usize];
        if let Some(q) = y_up_corners(vrv)
            .into_iter()
            .find(|&q| !in_cell(&imp["view_cell"], q))
        {
            return Err(format!(
                "impostor {id} drawn from {q:?}, outside its view cell"
            ));
        }
        // Points through the leaf (a 3³ grid, 1 % inside its faces) each
        // lie in the region of a CPV drawing it (a leaf may join several).
        for k in 0..27 {
            let t = [k % 3, k / 3 % 3, k / 9].map(|i| 0.01 + 0.49 * f64::from(i));
            let q: [f64; 3] = std::array::from_fn(|a| vrv.0[a] + (vrv.1[a] - vrv.0[a]) * t[a]);
            let from_cpv = placement["cpvs"].as_array().unwrap().iter().any(|c| {
                let r = (
                    z_up(vec3(&c["region"]["min"])),
                    z_up(vec3(&c["region"]["max"])),
                );
                let r = (
                    std::array::from_fn(|a| r.0[a].min(r.1[a])),
                    std::array::from_fn(|a| r.0[a].max(r.1[a])),
                );
                holds(r, q) && ids(&c["impostors"]).contains(&id)
            });
            if !from_cpv {
                return Err(format!(
                    "impostor {id} drawn from {q:?}, where no CPV draws it"
                ));
            }
        }
    }
    objects.sort_unstable();
    let n = objects.len();
    objects.dedup();
    if n != objects.len() || objects.iter().copied().collect::<BTreeSet<_>>() != *group {
        return Err(format!(
            "a leaf drawing {drawn:?} does not draw its group's objects once each"
        ));
    }
    leaves.push((vrv, drawn));
    Ok(())
}

/// The leaf of `switch` holding the z-up point `p`, descending request
/// volumes.
fn leaf_at(switch: &Value, p: [f64; 3]) -> Option<&Value> {
    if !holds(aabb(&switch["viewerRequestVolume"]), p) {
        return None;
    }
    if switch["extras"].get("impostors").is_some() {
        return Some(switch);
    }
    switch["children"]
        .as_array()?
        .iter()
        .find_map(|c| leaf_at(c, p))
}

/// Checks the tileset's structure; returns the content URIs and, per
/// impostor id, in how many leaves it is drawn.
fn check_tileset(ts: &Value, placement: &Value) -> Result<(BTreeSet<String>, Vec<u32>), String> {
    if ts["asset"]["version"] != "1.1" {
        return Err(format!("asset.version {}", ts["asset"]["version"]));
    }
    let root = &ts["root"];
    if root["refine"] != "ADD" {
        return Err("the root must refine by ADD".into());
    }
    let error = |t: &Value| t["geometricError"].as_f64().unwrap_or(f64::NAN);
    if error(root).partial_cmp(&error(ts)) != Some(std::cmp::Ordering::Less) {
        return Err("the root's error is not below the tileset's".into());
    }
    let impostors = placement["impostors"].as_array().unwrap();
    let mut seen = vec![0u32; impostors.len()];
    let mut uris = BTreeSet::new();
    let mut stack = vec![(root, f64::INFINITY)];
    while let Some((tile, above)) = stack.pop() {
        if let Some(uri) = tile["content"]["uri"].as_str() {
            uris.insert(uri.to_string());
        }
        if error(tile)
            .partial_cmp(&above)
            .is_none_or(|o| o == std::cmp::Ordering::Greater)
        {
            return Err(format!(
                "an error {} above its parent's {above}",
                error(tile)
            ));
        }
        for c in tile["children"].as_array().into_iter().flatten() {
            stack.push((c, error(tile)));
        }
    }
    let root_box = aabb(&root["boundingVolume"]);
    let mut switches = Vec::new();
    for g in root["children"].as_array().into_iter().flatten() {
        let bounds = aabb(&g["boundingVolume"]);
        if g["refine"] != "REPLACE"
            || !g["content"]["uri"].is_string()
            || !holds_box(root_box, bounds)
        {
            return Err(
                "a cluster tile that does not replace its geometry in the root's box".into(),
            );
        }
        let group: BTreeSet<u64> = ids(&g["extras"]["objects"]).into_iter().collect();
        let mut leaves = Vec::new();
        for s in g["children"].as_array().into_iter().flatten() {
            check_switch(s, &group, bounds, placement, &mut leaves)?;
            switches.push((s, ids(&g["extras"]["impostors"])));
        }
        for (_, drawn) in &leaves {
            drawn.iter().for_each(|&i| seen[i as usize] += 1);
        }
    }
    // From every CPV's region, the leaf holding its centre draws each of
    // its impostors or one replacing more of its objects.
    for c in placement["cpvs"].as_array().unwrap() {
        let (lo, hi) = (vec3(&c["region"]["min"]), vec3(&c["region"]["max"]));
        let centre = z_up(std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0));
        for id in ids(&c["impostors"]) {
            let (s, _) = switches
                .iter()
                .find(|(_, group)| group.contains(&id))
                .ok_or(format!("impostor {id} in no group"))?;
            let leaf = leaf_at(s, centre)
                .ok_or(format!("CPV {}: no leaf of impostor {id}'s group", c["id"]))?;
            let own = ids(&impostors[id as usize]["objects"]);
            let covered = ids(&leaf["extras"]["impostors"]).iter().any(|&j| {
                let other = ids(&impostors[j as usize]["objects"]);
                j == id || (other.len() >= own.len() && other.iter().any(|o| own.contains(o)))
            });
            if !covered {
                return Err(format!(
                    "CPV {}: its impostor {id} is not drawn from its centre",
                    c["id"]
                ));
            }
        }
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

    let placement = read_placement(&p);
    let ts = read_json(&out.join("tileset.json"));
    let (uris, seen) = check_tileset(&ts, &placement).unwrap_or_else(|e| panic!("{e}"));
    let n = placement["impostors"].as_array().unwrap().len();
    let drawn = seen.iter().filter(|&&k| k > 0).count();
    assert!(
        n > 0 && drawn * 10 > 9 * n,
        "{drawn} of {n} impostors drawn"
    );
    let files: Vec<_> = uris.iter().map(|u| out.join(u)).collect();
    for f in &files {
        assert!(f.is_file(), "{} is referenced but missing", f.display());
    }
    let written = std::fs::read_dir(&out).unwrap().count();
    assert_eq!(written, files.len() + 1, "files besides tileset.json");
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
        let Ok(glb) = std::fs::read(out.join(format!("impostor-{}.glb", imp["id"]))) else {
            continue;
        };
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

    // Controls: the checks fail on a leaf's request volume grown beyond
    // its impostors' cells, a content box grown beyond its group's, an
    // impostor drawn twice in a leaf, and a leaf that lost an impostor.
    fn first_leaf(t: &mut Value) -> Option<&mut Value> {
        if t["extras"]
            .get("impostors")
            .is_some_and(|i| !ids(i).is_empty())
            && t.get("viewerRequestVolume").is_some()
        {
            return Some(t);
        }
        t["children"]
            .as_array_mut()?
            .iter_mut()
            .find_map(first_leaf)
    }
    let mut bad = ts.clone();
    let leaf = first_leaf(&mut bad["root"]).unwrap();
    for k in [3, 7, 11] {
        leaf["viewerRequestVolume"]["box"][k] = 1e5.into();
    }
    assert!(check_tileset(&bad, &placement).is_err());
    let mut bad = ts.clone();
    first_leaf(&mut bad["root"]).unwrap()["children"][0]["boundingVolume"]["box"][3] = 1e6.into();
    assert!(check_tileset(&bad, &placement).is_err());
    let mut bad = ts.clone();
    let leaf = first_leaf(&mut bad["root"]).unwrap();
    let dup = leaf["children"][0].clone();
    leaf["children"].as_array_mut().unwrap().push(dup);
    assert!(check_tileset(&bad, &placement).is_err());
    let mut bad = ts.clone();
    let leaf = first_leaf(&mut bad["root"]).unwrap();
    leaf["children"].as_array_mut().unwrap().remove(0);
    assert!(check_tileset(&bad, &placement).is_err());

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
