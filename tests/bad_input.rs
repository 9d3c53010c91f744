//! Bad input of every kind: exit 2 with one message naming the problem, never
//! a panic, and no output file written.

use std::path::Path;

use crate::util::*;

/// A GLB with one triangle whose positions are `pos` (9 floats).
fn triangle_glb(pos: [f32; 9]) -> Vec<u8> {
    let mut bin: Vec<u8> = pos.iter().flat_map(|f| f.to_le_bytes()).collect();
    bin.extend([0u16, 1, 2, 0].iter().flat_map(|i| i.to_le_bytes()));
    let json = format!(
        concat!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"#,
            r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"#,
            r#""accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}},"#,
            r#"{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}],"#,
            r#""bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],"#,
            r#""buffers":[{{"byteLength":{}}}]}}"#
        ),
        bin.len()
    );
    let mut j = json.into_bytes();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let total = 12 + 8 + j.len() + 8 + bin.len();
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes());
    out.extend(&j);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes());
    out.extend(&bin);
    out
}

fn job_json(extra: &str) -> String {
    format!(r#"{{"view_space":{{"min":[0,1.5,0],"max":[50,2,50]}}{extra}}}"#)
}

/// Runs `place` and checks exit 2, a message containing every needle, and no
/// output file.
fn expect_bad(dir: &Path, scene: &Path, job: &str, needles: &[&str]) {
    let job_path = dir.join("job.json");
    std::fs::write(&job_path, job).unwrap();
    let out = dir.join("placement.json");
    let _ = std::fs::remove_file(&out);
    let o = run(&["place", s(scene), "--job", s(&job_path), "-o", s(&out)]);
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "expected exit 2, got {}: {err}", code(&o));
    for n in needles {
        assert!(err.contains(n), "message does not name {n:?}: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one message: {err}");
    assert!(!out.exists(), "no placement must be written for bad input");
}

#[test]
fn truncated_glb() {
    let dir = tmp("truncated");
    let good = triangle_glb([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let p = dir.join("cut.glb");
    std::fs::write(&p, &good[..good.len() - 10]).unwrap();
    expect_bad(&dir, &p, &job_json(""), &["cut.glb", "truncated"]);
}

#[test]
fn nan_vertex() {
    let dir = tmp("nan");
    let p = dir.join("nan.glb");
    std::fs::write(
        &p,
        triangle_glb([0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0, 0.0, 1.0, 0.0]),
    )
    .unwrap();
    expect_bad(&dir, &p, &job_json(""), &["nan.glb", "not finite"]);
}

#[test]
fn empty_scenes() {
    let dir = tmp("empty");
    let p = dir.join("empty.json");
    std::fs::write(&p, r#"{"objects":[]}"#).unwrap();
    expect_bad(&dir, &p, &job_json(""), &["empty.json", "no objects"]);
    let g = dir.join("nomesh.gltf");
    std::fs::write(
        &g,
        r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{}]}"#,
    )
    .unwrap();
    expect_bad(&dir, &g, &job_json(""), &["nomesh.gltf", "no objects"]);
}

#[test]
fn bad_jobs_name_the_field() {
    let dir = tmp("badjob");
    let scene = dir.join("tri.glb");
    std::fs::write(
        &scene,
        triangle_glb([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    )
    .unwrap();
    let cases: [(String, &[&str]); 6] = [
        (
            r#"{"view_space":{"min":[10,1.5,0],"max":[0,2,50]}}"#.into(),
            &["job.json", "view_space", "inverted"],
        ),
        (
            job_json(r#","target_frame_time_ms":-5"#),
            &["job.json", "target_frame_time_ms"],
        ),
        (job_json(r#","colour":"red""#), &["job.json", "colour"]),
        (
            r#"{"view_space":{"min":[1,1,1],"max":[1,1,1]}}"#.into(),
            &["job.json", "view_space", "zero size"],
        ),
        (
            job_json(r#","camera":{"resolution":[0,512]}"#),
            &["job.json", "camera.resolution"],
        ),
        ("{not json".into(), &["job.json"]),
    ];
    for (job, needles) in cases {
        expect_bad(&dir, &scene, &job, needles);
    }
}

#[test]
fn missing_files_and_bad_arguments() {
    let dir = tmp("missing");
    let job = dir.join("job.json");
    std::fs::write(&job, job_json("")).unwrap();
    let o = run(&["place", "/nonexistent/scene.glb", "--job", s(&job)]);
    assert_eq!(code(&o), 2);
    assert!(
        stderr(&o).contains("/nonexistent/scene.glb"),
        "{}",
        stderr(&o)
    );
    let o = run(&["gen-city", "--scale=-1", "-o", s(&dir.join("c.glb"))]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("scale"), "{}", stderr(&o));
    let o = run(&["place", s(&job), "--job", s(&job), "--threads", "0"]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("--threads"), "{}", stderr(&o));
}

/// Runs `evaluate` on a one-triangle scene with the given placement JSON.
fn evaluate_placement(dir: &Path, name: &str, placement_json: &str) -> std::process::Output {
    let scene = dir.join("tri.glb");
    std::fs::write(
        &scene,
        triangle_glb([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]),
    )
    .unwrap();
    let job = dir.join("job.json");
    std::fs::write(&job, job_json("")).unwrap();
    let placement = dir.join(name);
    std::fs::write(&placement, placement_json).unwrap();
    run(&[
        "evaluate",
        s(&scene),
        "--job",
        s(&job),
        "--placement",
        s(&placement),
        "--views",
        "10",
    ])
}

#[test]
fn placement_of_another_scene_is_rejected() {
    let o = evaluate_placement(
        &tmp("mismatch"),
        "p.json",
        r#"{"summary":{"cpvs":0,"candidates":0,"impostors":1,"memory_bytes":1,"unsolved_cpvs":0,"target_frame_time_ms":16},
           "impostors":[{"id":0,"node":0,"objects":[42],"sphere":{"center":[0,0,0],"radius":1},
           "view_cell":{"box":{"min":[0,0,0],"max":[1,1,1]}},"layers":1,"resolution":4,"memory_bytes":1,"time_ms":0}],"cpvs":[]}"#,
    );
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("object id 42"), "{}", stderr(&o));
}

#[test]
fn impossible_view_cells_are_rejected() {
    let dir = tmp("viewcells");
    let cases = [
        (
            r#"{"shaft":{"apex":[0,0,0],"axis":[0,0,0],"half_angle_deg":10,"min_distance":50}}"#,
            1,
            "axis non-zero",
        ),
        (
            r#"{"shaft":{"apex":[0,0,0],"axis":[0,0,1],"half_angle_deg":0,"min_distance":50}}"#,
            1,
            "half_angle_deg",
        ),
        (
            r#"{"shaft":{"apex":[0,0,0],"axis":[0,0,1],"half_angle_deg":10,"min_distance":1}}"#,
            1,
            "may not meet the cluster",
        ),
        (r#"{"box":{"min":[0,0,0],"max":[-1,1,1]}}"#, 1, "min ≤ max"),
        (
            r#"{"box":{"min":[10,0,0],"max":[11,1,1]}}"#,
            0,
            "layers (0)",
        ),
    ];
    for (k, (cell, layers, needle)) in cases.iter().enumerate() {
        let o = evaluate_placement(
            &dir,
            &format!("p{k}.json"),
            &format!(
                r#"{{"summary":{{"cpvs":0,"candidates":0,"impostors":1,"memory_bytes":1,"unsolved_cpvs":0,"target_frame_time_ms":16}},
                   "impostors":[{{"id":0,"node":0,"objects":[0],"sphere":{{"center":[0.3,0.3,0],"radius":2}},
                   "view_cell":{cell},"layers":{layers},"resolution":4,"memory_bytes":1,"time_ms":0}}],"cpvs":[]}}"#
            ),
        );
        assert_eq!(code(&o), 2, "case {k}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "case {k}: {}", stderr(&o));
    }
}

#[test]
fn jobs_predicted_beyond_the_memory_limit_are_tiled_or_refused() {
    let dir = tmp("memory-limit");
    let scene = city("0.1");
    let job = root().join("fixtures/jobs/city-small.json");
    let out = dir.join("placement.json");
    let o = place(&scene, &job, &out, &["--max-memory-gb", "0.001"]);
    let err = stderr(&o);
    assert_eq!(code(&o), 2, "{err}");
    for needle in [
        "city-small.json",
        "GB",
        "problem views",
        "objects",
        "target_frame_time_ms",
    ] {
        assert!(
            err.contains(needle),
            "message does not name {needle:?}: {err}"
        );
    }
    assert!(!out.exists(), "no placement for a refused job");
    // With room for its prediction the same job places.
    let stats = dir.join("stats.json");
    let o = place(
        &scene,
        &job,
        &out,
        &["--max-memory-gb", "24", "--stats", s(&stats)],
    );
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let whole = read_json(&stats);
    let predicted = whole["predicted_peak_bytes"].as_u64().unwrap();
    assert!(
        predicted > 1_000_000 && predicted < 24_000_000_000,
        "{predicted}"
    );
    assert!(whole.get("tiled_for_memory").is_none(), "{whole}");
    let cpvs = read_json(&out)["summary"]["cpvs"].as_u64().unwrap();
    // A limit between what the run holds after its problem views and its
    // prediction: the job is placed in tiles, each holding a share of the
    // pairs, whose CPVs are the whole job's.
    let held = whole["seconds"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["stage"] == "problem_views")
        .and_then(|t| t["rss_bytes"].as_u64())
        .expect("the problem views' resident memory");
    let limit = (held + predicted) / 2;
    let gb = format!("{}", limit as f64 / 1e9);
    let o = place(
        &scene,
        &job,
        &out,
        &["--max-memory-gb", &gb, "--stats", s(&stats)],
    );
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(stderr(&o).contains("tiles"), "{}", stderr(&o));
    let tiled = read_json(&stats);
    let t = &tiled["tiled_for_memory"];
    let n = t["tiles"][0].as_u64().unwrap() * t["tiles"][1].as_u64().unwrap();
    assert!(n >= 2, "{t}");
    assert!(t["predicted_bytes"].as_u64().unwrap() > limit, "{t}");
    assert!(
        tiled["tiles"].as_array().unwrap().len() as u64 >= n,
        "{tiled}"
    );
    assert_eq!(read_json(&out)["summary"]["cpvs"].as_u64(), Some(cpvs));
    // Tiles the job chose are kept: one tile ([1, 1]) at that limit is
    // refused, naming the partition, and writes nothing.
    let mut chosen = read_json(&job);
    chosen["partition"] = serde_json::json!({"tiles": [1, 1]});
    let chosen_job = dir.join("one-tile.json");
    std::fs::write(&chosen_job, chosen.to_string()).unwrap();
    let one = dir.join("one-tile-placement.json");
    let o = place(&scene, &chosen_job, &one, &["--max-memory-gb", &gb]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("\"partition\""), "{}", stderr(&o));
    assert!(!one.exists());
    // Nonsense limits are argument errors.
    for bad in ["0", "-1", "NaN", "lots"] {
        let o = place(&scene, &job, &out, &["--max-memory-gb", bad]);
        assert_eq!(code(&o), 2, "--max-memory-gb {bad}: {}", stderr(&o));
    }
}
