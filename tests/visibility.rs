//! From-region visibility and levels of detail end to end: the conservative
//! mode misses nothing on the generated city, PVS files round-trip, the
//! check finds what a broken PVS hides, the sampled mode works on a real
//! interior, and levels of detail cut impostor memory.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::util::*;

fn vis_job() -> PathBuf {
    root().join("fixtures/jobs/city-small-visibility.json")
}

/// Writes `job` with its `visibility` field replaced.
fn job_with(dir: &Path, name: &str, base: &Path, visibility: Value) -> PathBuf {
    let mut j = read_json(base);
    j["visibility"] = visibility;
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_vec_pretty(&j).unwrap()).unwrap();
    p
}

fn run_ok(args: &[&str]) {
    let o = run(args);
    assert!(
        matches!(code(&o), 0 | 3),
        "{args:?}: exit {}: {}",
        code(&o),
        stderr(&o)
    );
}

#[test]
fn conservative_visibility_misses_nothing_and_keeps_the_guarantee() {
    let dir = tmp("vis-cons");
    let city = city("0.1");
    let (p, st) = (dir.join("p.json"), dir.join("s.json"));
    let o = place(&city, &vis_job(), &p, &["--stats", s(&st)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    // The guarantee with culled sets, where the same views without
    // impostors break it.
    let eval = check_guarantee(&city, &vis_job(), &p, 10_000, 0.01, &[]).eval;
    assert_eq!(eval["violations"], 0, "{eval}");
    let v = &eval["visibility"];
    assert_eq!(v["mode"], "conservative");
    assert_eq!(v["views_checked"], 10_000, "{v}");
    assert!(v["rays"].as_u64().unwrap() > 1_000_000, "{v}");
    assert_eq!(v["missed_objects"], 0, "{v}");
    // It culls for real: most of the city is hidden from a street cell.
    assert!(v["mean_visible_fraction"].as_f64().unwrap() < 0.6, "{v}");
    let stats = read_json(&st);
    let sv = &stats["visibility"];
    assert!(
        sv["occluders"]["occluder_objects"].as_u64().unwrap() > 100,
        "{sv}"
    );
    assert!(sv["occluders"]["bridges"].as_u64().unwrap() > 0, "{sv}");

    // The same job without visibility has far more problem views.
    let none = job_with(&dir, "none.json", &vis_job(), Value::from("none"));
    let p0 = dir.join("p0.json");
    let o = place(&city, &none, &p0, &[]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let (with, without) = (read_json(&p), read_json(&p0));
    let cpvs = |p: &Value| p["summary"]["cpvs"].as_u64().unwrap();
    let mem = |p: &Value| p["summary"]["memory_bytes"].as_u64().unwrap();
    assert!(
        cpvs(&with) > 0,
        "the visibility job must still have problems"
    );
    assert!(
        cpvs(&with) * 5 < cpvs(&without),
        "{} vs {}",
        cpvs(&with),
        cpvs(&without)
    );
    assert!(
        mem(&with) * 5 < mem(&without),
        "{} vs {}",
        mem(&with),
        mem(&without)
    );
}

#[test]
fn visibility_placements_are_the_same_for_any_thread_count() {
    let dir = tmp("vis-threads");
    let city = city("0.1");
    let sampled = job_with(
        &dir,
        "sampled.json",
        &vis_job(),
        serde_json::json!({"mode": "sampled", "rays_per_region": 2048}),
    );
    for job in [vis_job(), sampled] {
        let (a, b) = (dir.join("a.json"), dir.join("b.json"));
        run_ok(&[
            "place",
            s(&city),
            "--job",
            s(&job),
            "-o",
            s(&a),
            "--threads",
            "1",
        ]);
        run_ok(&[
            "place",
            s(&city),
            "--job",
            s(&job),
            "-o",
            s(&b),
            "--threads",
            "2",
        ]);
        assert_same_file(&a, &b);
    }
}

#[test]
fn a_pvs_file_round_trips_and_the_check_catches_a_broken_one() {
    let dir = tmp("vis-pvs");
    let city = city("0.1");
    let pvs = dir.join("pvs.json");
    run_ok(&["pvs", s(&city), "--job", s(&vis_job()), "-o", s(&pvs)]);
    let file = read_json(&pvs);
    let cells = file["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 21 * 14, "one entry per grid cell");
    // Placing from the file gives the same placement as computing it.
    let pre = job_with(&dir, "pre.json", &vis_job(), Value::from("precomputed"));
    let (a, b) = (dir.join("a.json"), dir.join("b.json"));
    run_ok(&["place", s(&city), "--job", s(&vis_job()), "-o", s(&a)]);
    run_ok(&[
        "place",
        s(&city),
        "--job",
        s(&pre),
        "-o",
        s(&b),
        "--pvs",
        s(&pvs),
    ]);
    assert_same_file(&a, &b);
    let e = dir.join("e.json");
    let o = run(&[
        "evaluate",
        s(&city),
        "--job",
        s(&pre),
        "--placement",
        s(&b),
        "--pvs",
        s(&pvs),
        "-o",
        s(&e),
        "--views",
        "2000",
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert_eq!(read_json(&e)["visibility"]["missed_objects"], 0);

    // Drop every other visible object: the check must notice.
    let mut broken = file.clone();
    for c in broken["cells"].as_array_mut().unwrap() {
        let v: Vec<Value> = c["visible"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
            .filter(|(i, _)| i % 2 == 0)
            .map(|(_, x)| x.clone())
            .collect();
        c["visible"] = Value::from(v);
    }
    let bad = dir.join("broken.json");
    std::fs::write(&bad, serde_json::to_vec(&broken).unwrap()).unwrap();
    let (p, e) = (dir.join("pb.json"), dir.join("eb.json"));
    run_ok(&[
        "place",
        s(&city),
        "--job",
        s(&pre),
        "-o",
        s(&p),
        "--pvs",
        s(&bad),
    ]);
    let o = run(&[
        "evaluate",
        s(&city),
        "--job",
        s(&pre),
        "--placement",
        s(&p),
        "--pvs",
        s(&bad),
        "-o",
        s(&e),
        "--views",
        "2000",
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let v = &read_json(&e)["visibility"];
    assert!(v["missed_objects"].as_u64().unwrap() > 100, "{v}");
    assert!(v["missed_by_image_rays"].as_u64().unwrap() > 0, "{v}");
    assert!(v["missed_by_probe_rays"].as_u64().unwrap() > 0, "{v}");
    assert!(!v["examples"].as_array().unwrap().is_empty());
}

#[test]
fn visibility_inputs_that_are_missing_or_wrong_are_named() {
    let dir = tmp("vis-bad");
    let city = city("0.1");
    let summary = dir.join("summary.json");
    let o = run(&["gen-city", "--scale", "0.1", "--summary", "-o", s(&summary)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let out = dir.join("p.json");
    // Conservative visibility needs triangles.
    let o = place(&summary, &vis_job(), &out, &[]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("geometry"), "{}", stderr(&o));
    // Precomputed needs a file, and the right one.
    let pre = job_with(&dir, "pre.json", &vis_job(), Value::from("precomputed"));
    let o = place(&city, &pre, &out, &[]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("--pvs"), "{}", stderr(&o));
    let other = dir.join("other.json");
    std::fs::write(&other, br#"{"objects": 3, "cells": []}"#).unwrap();
    let o = place(&city, &pre, &out, &["--pvs", s(&other)]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("does not match"), "{}", stderr(&o));
    let garbage = dir.join("garbage.json");
    std::fs::write(&garbage, b"{\"cells\": 5").unwrap();
    let o = place(&city, &pre, &out, &["--pvs", s(&garbage)]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("garbage.json"), "{}", stderr(&o));
    // Bad knobs are named.
    let bad = job_with(
        &dir,
        "bad.json",
        &vis_job(),
        serde_json::json!({"mode": "conservative", "sample_spacing_m": -1}),
    );
    let o = place(&city, &bad, &out, &[]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("sample_spacing_m"), "{}", stderr(&o));
    let bad = job_with(&dir, "bad2.json", &vis_job(), Value::from("everything"));
    let o = place(&city, &bad, &out, &[]);
    assert_eq!(code(&o), 2);
    assert!(stderr(&o).contains("visibility"), "{}", stderr(&o));
    assert!(!out.exists(), "no output after bad input");
}

#[test]
fn sampled_visibility_on_a_real_interior_reports_its_misses() {
    let Some(scene) = shared_scene("Ifc2x3_Duplex_Architecture") else {
        return;
    };
    let dir = tmp("vis-interior");
    // 3.5 ms: below the slowest views of the apartment with sampled sets
    // (4.1 ms over 3,000 views), so the job has problem views.
    let mut base = read_json(&root().join("fixtures/jobs/Ifc2x3_Duplex_Architecture.json"));
    base["target_frame_time_ms"] = Value::from(3.5);
    let plain = dir.join("plain.json");
    std::fs::write(&plain, serde_json::to_vec(&base).unwrap()).unwrap();
    let job = job_with(&dir, "sampled.json", &plain, Value::from("sampled"));
    let (p, st, e) = (dir.join("p.json"), dir.join("s.json"), dir.join("e.json"));
    run_ok(&[
        "place",
        s(&scene),
        "--job",
        s(&job),
        "-o",
        s(&p),
        "--stats",
        s(&st),
    ]);
    let v = &read_json(&st)["visibility"];
    assert_eq!(v["mode"], "sampled");
    assert!(v["missing_mass_mean"].as_f64().is_some(), "{v}");
    assert!(v["mean_visible_fraction"].as_f64().unwrap() < 0.8, "{v}");
    // The rays leave visible objects unfound, and say so.
    let rate = v["missed_object_rate"].as_f64().unwrap();
    assert!(rate > 0.0 && rate < 0.5, "{v}");
    let placement = read_json(&p);
    let cpvs = placement["summary"]["cpvs"].as_u64().unwrap();
    assert!(cpvs > 0, "the job must have problem views");
    let o = evaluate(&scene, &job, &p, &e, 3000);
    assert!(matches!(code(&o), 0 | 4), "{}", stderr(&o));
    let ev = read_json(&e);
    let check = &ev["visibility"];
    assert_eq!(check["views_checked"], 3000, "{ev}");
    // Where the estimate expects misses, the check finds them: the
    // evaluation's rays see objects the sets lack.
    assert!(check["missed_objects"].as_u64().unwrap() > 0, "{check}");
    assert!(check["views_with_misses"].as_u64().unwrap() > 0, "{check}");
    assert!(ev["views_in_unsolved_cpvs"].as_u64().unwrap() + ev["cpv_views"].as_u64().unwrap() > 0);
    // Without visibility the same job has more problem views.
    let p0 = dir.join("p0.json");
    run_ok(&["place", s(&scene), "--job", s(&plain), "-o", s(&p0)]);
    let cpvs0 = read_json(&p0)["summary"]["cpvs"].as_u64().unwrap();
    assert!(cpvs < cpvs0, "{cpvs} vs {cpvs0}");
}

#[test]
fn levels_of_detail_are_chosen_and_save_impostor_memory() {
    let dir = tmp("lod");
    let plain = city("0.1");
    let lod = dir.join("city-lod.glb");
    run_ok(&[
        "gen-city",
        "--scale",
        "0.1",
        "--seed",
        "1",
        "--lod",
        "-o",
        s(&lod),
    ]);
    let job = root().join("fixtures/jobs/city-small.json");
    let (a, b, st) = (dir.join("a.json"), dir.join("b.json"), dir.join("s.json"));
    run_ok(&["place", s(&plain), "--job", s(&job), "-o", s(&a)]);
    run_ok(&[
        "place",
        s(&lod),
        "--job",
        s(&job),
        "-o",
        s(&b),
        "--stats",
        s(&st),
    ]);
    let mem = |p: &Path| read_json(p)["summary"]["memory_bytes"].as_u64().unwrap();
    assert!(
        mem(&b) < mem(&a),
        "with levels {} vs without {}",
        mem(&b),
        mem(&a)
    );
    let l = &read_json(&st)["lod"];
    assert!(l["objects_with_lods"].as_u64().unwrap() > 100, "{l}");
    let chosen: Vec<u64> = l["chosen_levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap())
        .collect();
    assert!(chosen.iter().filter(|&&c| c > 0).count() >= 2, "{chosen:?}");
    // The evaluation counts the level drawn at each view: still no violation.
    check_guarantee(&lod, &job, &b, 3000, 0.01, &[]);
    // Levels switched off: the same as the plain city.
    let off = dir.join("off.json");
    let mut j = read_json(&job);
    j["lod"] = serde_json::json!({"enabled": false});
    std::fs::write(&off, serde_json::to_vec(&j).unwrap()).unwrap();
    let c = dir.join("c.json");
    run_ok(&["place", s(&lod), "--job", s(&off), "-o", s(&c)]);
    assert_same_file(&a, &c);
}
