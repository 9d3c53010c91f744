//! `impostor lod`: the scene written with its generated levels of detail as
//! `MSFT_lod` nodes — valid glTF, the same objects when read back, coarser
//! levels with fewer triangles, the cost model's switching coverages.

use std::path::Path;

use serde_json::Value;

use crate::bake::validate;
use crate::util::*;

/// The JSON chunk of a GLB.
fn glb_json(path: &Path) -> Value {
    let b = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes([b[12], b[13], b[14], b[15]]) as usize;
    serde_json::from_slice(&b[20..20 + n]).unwrap()
}

/// Triangles of mesh `m` (triangle-list primitives, as the writer writes
/// them).
fn mesh_triangles(json: &Value, m: &Value) -> u64 {
    json["meshes"][m.as_u64().unwrap() as usize]["primitives"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let a = p["indices"].as_u64().unwrap() as usize;
            json["accessors"][a]["count"].as_u64().unwrap() / 3
        })
        .sum()
}

fn info(scene: &Path) -> Value {
    let o = run(&["info", s(scene)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn lod_writes_valid_msft_lod_levels_of_the_same_objects() {
    let dir = tmp("lod");
    let city = city("0.1");
    let out = dir.join("city-lod.glb");
    let job = root().join("fixtures/jobs/city-small.json");
    let o = run(&["lod", s(&city), "--job", s(&job), "-o", s(&out)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));

    let issues = validate(&out);
    assert_eq!(issues["numErrors"], 0, "{issues}");

    // Read back: the same objects (the level nodes are not objects), the
    // same full-detail triangles and draw calls, the same bounds up to the
    // f32 node transforms.
    let (a, b) = (info(&city), info(&out));
    for key in ["objects", "triangles", "draw_calls"] {
        assert_eq!(a[key], b[key], "{key}");
    }
    for k in ["min", "max"] {
        for i in 0..3 {
            let (x, y) = (
                a["bounds"][k][i].as_f64().unwrap(),
                b["bounds"][k][i].as_f64().unwrap(),
            );
            assert!((x - y).abs() < 1e-3, "bounds {k}[{i}]: {x} vs {y}");
        }
    }

    // Every chain: strictly fewer triangles level by level, one coverage
    // per level, strictly decreasing, the last 0.
    let json = glb_json(&out);
    let nodes = json["nodes"].as_array().unwrap();
    let mut chains = 0;
    for n in nodes {
        let Some(ids) = n["extensions"]["MSFT_lod"]["ids"].as_array() else {
            continue;
        };
        chains += 1;
        let mut last = mesh_triangles(&json, &n["mesh"]);
        for id in ids {
            let level = &nodes[id.as_u64().unwrap() as usize];
            let t = mesh_triangles(&json, &level["mesh"]);
            assert!(t < last, "{}: {t} ≥ {last}", level["name"]);
            last = t;
        }
        let cov: Vec<f64> = n["extras"]["MSFT_screencoverage"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(cov.len(), ids.len() + 1, "{}", n["name"]);
        assert!(cov.windows(2).all(|w| w[0] > w[1]), "{cov:?}");
        assert_eq!(*cov.last().unwrap(), 0.0);
    }
    // Control: the city's buildings are large enough to get levels.
    assert!(chains > 10, "only {chains} objects with levels");
    let roots = json["scenes"][0]["nodes"].as_array().unwrap().len() as u64;
    assert_eq!(roots, a["objects"].as_u64().unwrap());

    // Deterministic.
    let again = dir.join("again.glb");
    let o = run(&["lod", s(&city), "--job", s(&job), "-o", s(&again)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&again).unwrap());
}

#[test]
fn absurd_lod_options_are_clear_errors() {
    let dir = tmp("lod-bad");
    let city = city("0.1");
    let out = dir.join("x.glb");
    for (args, expect) in [
        (
            &["--levels", "1000"][..],
            "lod.levels: 1000 must be at most 31",
        ),
        (&["--ratio", "1.5"][..], "lod.ratio: 1.5 must be in (0, 1)"),
        (&["--ratio", "NaN"][..], "lod.ratio: NaN must be in (0, 1)"),
    ] {
        let mut all = vec!["lod", s(&city), "-o", s(&out)];
        all.extend_from_slice(args);
        let o = run(&all);
        assert_eq!(code(&o), 2, "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert!(!out.exists(), "{args:?} wrote a file");
    }
    // A scene summary has no geometry to simplify.
    let summary = dir.join("summary.json");
    let o = run(&["gen-city", "--scale", "0.1", "--summary", "-o", s(&summary)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let o = run(&["lod", s(&summary), "-o", s(&out)]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("has no geometry"), "{}", stderr(&o));
}
