//! The JSON Schemas in `schemas/` are current and the outputs conform.

use crate::util::*;

fn validator(name: &str) -> jsonschema::Validator {
    let schema = read_json(&root().join("schemas").join(name));
    jsonschema::validator_for(&schema).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn assert_valid(name: &str, v: &serde_json::Value) {
    let val = validator(name);
    let errors: Vec<String> = val
        .iter_errors(v)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    assert!(errors.is_empty(), "{name}: {errors:?}");
}

#[test]
fn committed_schemas_are_current() {
    let dir = tmp("schemas");
    let o = run(&["schema", "--out-dir", s(&dir)]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        let committed = std::fs::read_to_string(root().join("schemas").join(&name))
            .unwrap_or_else(|_| panic!("schemas/{name} is missing: run `impostor schema`"));
        assert_eq!(
            committed,
            std::fs::read_to_string(&p).unwrap(),
            "schemas/{name} is stale: run `cargo run --release -- schema`"
        );
    }
}

#[test]
fn fixture_jobs_conform() {
    for entry in std::fs::read_dir(root().join("fixtures/jobs")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "json") {
            assert_valid("job.schema.json", &read_json(&p));
        }
    }
}

#[test]
fn outputs_conform() {
    let dir = tmp("conform");
    let city = city("0.1");
    let job = root().join("fixtures/jobs/city-small.json");
    let (p, e, st, sum) = (
        dir.join("p.json"),
        dir.join("e.json"),
        dir.join("s.json"),
        dir.join("sum.json"),
    );
    let o = place(&city, &job, &p, &["--stats", s(&st)]);
    assert!(matches!(code(&o), 0 | 3), "{}", stderr(&o));
    let o = evaluate(&city, &job, &p, &e, 500);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let o = run(&["gen-city", "--scale", "0.1", "--summary", "-o", s(&sum)]);
    assert_eq!(code(&o), 0);
    assert_valid("placement.schema.json", &read_json(&p));
    assert_valid("evaluation.schema.json", &read_json(&e));
    assert_valid("stats.schema.json", &read_json(&st));
    assert_valid("scene.schema.json", &read_json(&sum));
    // A broken placement does not conform.
    let mut bad = read_json(&p);
    bad["summary"]["cpvs"] = serde_json::json!("many");
    assert!(!validator("placement.schema.json").is_valid(&bad));
}
