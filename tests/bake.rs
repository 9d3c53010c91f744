//! Baking impostors end to end: `place` → `bake` → the Khronos glTF
//! validator → `evaluate --images` against the baked GLB.

use std::process::Command;

use crate::util::*;

/// Runs the Khronos validator (installed by the README's test command with
/// `npm ci --prefix tools/gltf-validator`) and returns its issues report.
pub fn validate(glb: &std::path::Path) -> serde_json::Value {
    let tool = root().join("tools/gltf-validator");
    assert!(
        tool.join("node_modules/gltf-validator").is_dir(),
        "the glTF validator is not installed: run `npm ci --prefix tools/gltf-validator`"
    );
    let o = Command::new("node")
        .arg(tool.join("validate.js"))
        .arg(glb)
        .output()
        .expect("run node");
    let report: serde_json::Value = serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("validator output: {e}: {}", stderr(&o)));
    report
}

#[test]
fn bake_validates_and_looks_like_the_geometry() {
    let dir = tmp("bake");
    let city = city("0.1");
    // Flown over: impostors close enough to cover a share of the image.
    let job = root().join("fixtures/jobs/city-small-flyover.json");
    let p = dir.join("p.json");
    let o = place(&city, &job, &p, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let glb = dir.join("impostors.glb");
    let report = dir.join("bake.json");
    let o = bake(&city, &p, &job, &glb, &report);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let rep = read_json(&report);
    let placement = read_json(&p);
    assert_eq!(rep["impostors"], placement["summary"]["impostors"]);
    assert!(rep["layers_written"].as_u64().unwrap() > 0, "{rep}");
    // Baked memory never exceeds the estimate (empty layers are dropped).
    assert!(rep["memory_bytes"].as_u64() <= placement["summary"]["memory_bytes"].as_u64());

    let issues = validate(&glb);
    assert_eq!(issues["numErrors"], 0, "{issues}");

    let eval = dir.join("e.json");
    let o = run(&[
        "evaluate",
        s(&city),
        "--job",
        s(&job),
        "--placement",
        s(&p),
        "-o",
        s(&eval),
        "--views",
        "200",
        "--images",
        "24",
        "--impostors",
        s(&glb),
        "--dump",
        s(&dir),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let e = read_json(&eval);
    let image = &e["image"];
    let f = |k: &str| image[k].as_f64().unwrap();
    let views = image["views"].as_u64().unwrap();
    // Views are chosen for the impostors they show unoccluded: at least
    // half of them show impostors on 1 % of the image (a third did when
    // the choice ignored occlusion).
    assert!(
        views >= 12,
        "only {views} of 24 views show impostors on 1 % of the image: {image}"
    );
    assert!(f("impostor_pixel_fraction") >= 0.01, "{image}");
    let mean = image["footprint_mismatch_fraction"]["mean"]
        .as_f64()
        .unwrap();
    let p95 = image["footprint_mismatch_fraction"]["p95"]
        .as_f64()
        .unwrap();
    let max = image["footprint_mismatch_fraction"]["max"]
        .as_f64()
        .unwrap();
    assert!(mean <= p95 && p95 <= max, "{image}");
    // Antialiased on both sides, the layers sharpened against the lookup's
    // blur (0.0227 / 0.0476 measured; unsharpened 0.0286 / 0.0471;
    // point-sampled images and layers, which keep or lose sub-pixel
    // features by chance, give 0.049 / 0.081 with the same half-pixel
    // matching, 0.074 / 0.130 without it).
    assert!(
        mean <= 0.026,
        "mean mismatch {mean} over impostor pixels: {image}"
    );
    assert!(
        max <= 0.07,
        "worst mismatch {max} over impostor pixels: {image}"
    );
    // The control (the same views, every layer texel magenta) must fail
    // the same check by far, or the check looked at nothing.
    let control = image["control_mismatch_fraction"]["mean"].as_f64().unwrap();
    assert!(
        control >= 0.5 && control >= 5.0 * mean,
        "the magenta control mismatches {control} (impostors {mean}): the check proves nothing"
    );
    assert!(dir.join("worst_view.png").exists());
    // The placement holds the frame-time guarantee where it could fail.
    check_guarantee(&city, &job, &p, 2000, 0.01, &[]);
}

#[test]
fn gen_city_lod_validates_and_carries_levels() {
    let dir = tmp("gen-city-lod");
    let glb = dir.join("lod.glb");
    let o = run(&["gen-city", "--scale", "0.02", "--lod", "-o", s(&glb)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let issues = validate(&glb);
    assert_eq!(issues["numErrors"], 0, "{issues}");
    assert_eq!(issues["numWarnings"], 0, "{issues}");
    let summary = dir.join("lod.json");
    let o = run(&[
        "gen-city",
        "--scale",
        "0.02",
        "--lod",
        "--summary",
        "-o",
        s(&summary),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let objects = read_json(&summary)["objects"].as_array().unwrap().clone();
    let with_levels = objects.iter().filter(|o| o.get("lods").is_some()).count();
    assert!(
        with_levels > 0 && with_levels < objects.len(),
        "{with_levels}"
    );
}

#[test]
fn bake_rejects_scenes_without_geometry_and_foreign_placements() {
    let dir = tmp("bake-bad");
    let job = root().join("fixtures/jobs/city-small.json");
    let summary = dir.join("city.json");
    let o = run(&["gen-city", "--scale", "0.1", "--summary", "-o", s(&summary)]);
    assert_eq!(code(&o), 0);
    let p = dir.join("p.json");
    let o = place(&summary, &job, &p, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let out = dir.join("i.glb");
    let o = run(&["bake", s(&summary), "--placement", s(&p), "-o", s(&out)]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("no geometry"), "{}", stderr(&o));
    assert!(!out.exists());

    // A placement for the city baked over a one-object scene.
    let tiny = dir.join("tiny.glb");
    let o = run(&["gen-city", "--scale", "0.001", "-o", s(&tiny)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let o = run(&["bake", s(&tiny), "--placement", s(&p), "-o", s(&out)]);
    assert_eq!(code(&o), 2, "{}", stderr(&o));
    assert!(stderr(&o).contains("object id"), "{}", stderr(&o));
    assert!(!out.exists());
}
