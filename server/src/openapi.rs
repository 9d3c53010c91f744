//! The OpenAPI 3.1 document of the service (`GET /openapi.json`). Request
//! and result bodies use the JSON Schemas generated from the optimizer's
//! Rust types ([`optimizer::api::schema`]); their `$defs` are hoisted into
//! `components/schemas`.

use serde_json::{Map, Value, json};

/// Moves a generated schema's `$defs` into `defs` and points its references there.
fn hoist(schema: Value, defs: &mut Map<String, Value>) -> Value {
    let text = schema
        .to_string()
        .replace("\"#/$defs/", "\"#/components/schemas/");
    let mut schema: Value = serde_json::from_str(&text).unwrap_or(Value::Null);
    if let Some(o) = schema.as_object_mut() {
        if let Some(Value::Object(d)) = o.remove("$defs") {
            defs.extend(d);
        }
        o.remove("$schema");
    }
    schema
}

fn error_responses(codes: &[&str]) -> Map<String, Value> {
    codes
        .iter()
        .map(|c| {
            (
                (*c).to_string(),
                json!({"description": "error", "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}),
            )
        })
        .collect()
}

fn with(mut base: Map<String, Value>, code: &str, v: Value) -> Value {
    base.insert(code.to_string(), v);
    Value::Object(base)
}

/// The document.
pub fn openapi() -> Value {
    let mut schemas = Map::new();
    for (file, text) in optimizer::api::schema::all() {
        let name = match file {
            "job.schema.json" => "Job",
            "scene.schema.json" => "SceneSummary",
            "placement.schema.json" => "Placement",
            "evaluation.schema.json" => "Evaluation",
            "stats.schema.json" => "Stats",
            "pvs.schema.json" => "PvsFile",
            _ => continue,
        };
        let v: Value = serde_json::from_str(&text).unwrap_or(Value::Null);
        let mut defs = Map::new();
        let s = hoist(v, &mut defs);
        schemas.extend(defs);
        schemas.insert(name.to_string(), s);
    }
    schemas.insert("Error".into(), json!({"type": "object", "required": ["error"], "properties": {"error": {"type": "string", "description": "what is wrong, naming the part or field"}}}));
    schemas.insert("Accepted".into(), json!({"type": "object", "properties": {"id": {"type": "integer"}, "state": {"type": "string"}}}));
    schemas.insert("JobStatus".into(), json!({
        "type": "object",
        "properties": {
            "id": {"type": "integer"},
            "state": {"type": "string", "enum": ["queued", "running", "succeeded", "failed", "cancelled"]},
            "stage": {"type": ["string", "null"], "description": "hierarchy, problem_views, candidates, greedy, placement, evaluate, bake"},
            "progress": {"type": "number", "minimum": 0, "maximum": 1},
            "bake": {"type": "boolean"},
            "created_ms": {"type": "integer"}, "started_ms": {"type": ["integer", "null"]}, "finished_ms": {"type": ["integer", "null"]},
            "summary": {"description": "the placement summary with the evaluation's max_ms, violations_in_solved and parallax_max_px (when there are impostors) and the stage timings, once succeeded"},
            "error": {"type": ["string", "null"]}
        }
    }));
    schemas.insert("JobList".into(), json!({"type": "object", "properties": {"jobs": {"type": "array", "items": {"$ref": "#/components/schemas/JobStatus"}}, "next_after": {"type": ["integer", "null"]}}}));
    let id_param =
        json!([{"name": "id", "in": "path", "required": true, "schema": {"type": "integer"}}]);
    let json_ok = |schema: &str| json!({"description": "ok", "content": {"application/json": {"schema": {"$ref": format!("#/components/schemas/{schema}")}}}});
    json!({
        "openapi": "3.1.0",
        "info": {"title": "impostor placement service", "version": optimizer::VERSION},
        "paths": {
            "/healthz": {"get": {"summary": "liveness", "responses": {"200": {"description": "ok"}}}},
            "/openapi.json": {"get": {"summary": "this document", "responses": {"200": {"description": "ok"}}}},
            "/v1/jobs": {
                "post": {
                    "summary": "submit a job: a GLB upload (multipart parts `scene`, `job`, optional `pvs` (a PVS file, for visibility \"precomputed\") and `bake` = \"true\") or an inline scene summary",
                    "requestBody": {"required": true, "content": {
                        "multipart/form-data": {"schema": {"type": "object", "required": ["scene", "job"], "properties": {
                            "scene": {"type": "string", "format": "binary"},
                            "job": {"$ref": "#/components/schemas/Job"},
                            "pvs": {"$ref": "#/components/schemas/PvsFile"},
                            "bake": {"type": "string", "enum": ["true", "false"]}}}},
                        "application/json": {"schema": {"type": "object", "required": ["scene", "job"], "properties": {
                            "scene": {"$ref": "#/components/schemas/SceneSummary"},
                            "job": {"$ref": "#/components/schemas/Job"},
                            "pvs": {"$ref": "#/components/schemas/PvsFile"},
                            "bake": {"type": "boolean"}}}}
                    }},
                    "responses": with(error_responses(&["400", "413", "415", "422", "429"]), "202", json_ok("Accepted"))
                },
                "get": {
                    "summary": "list jobs, oldest first",
                    "parameters": [
                        {"name": "after", "in": "query", "schema": {"type": "integer"}},
                        {"name": "limit", "in": "query", "schema": {"type": "integer", "minimum": 1, "maximum": 500}}
                    ],
                    "responses": {"200": json_ok("JobList")}
                }
            },
            "/v1/jobs/{id}": {
                "get": {"summary": "job state, stage, progress, summary or error", "parameters": id_param,
                        "responses": with(error_responses(&["404"]), "200", json_ok("JobStatus"))},
                "delete": {"summary": "cancel a queued or running job; delete a finished one with its results", "parameters": id_param,
                           "responses": with(error_responses(&["404"]), "200", json!({"description": "ok"}))}
            },
            "/v1/jobs/{id}/placement": {"get": {"summary": "the placement, byte-identical to `impostor place`", "parameters": id_param,
                "responses": with(error_responses(&["404", "409"]), "200", json_ok("Placement"))}},
            "/v1/jobs/{id}/evaluation": {"get": {"summary": "the independent frame-time check of the placement", "parameters": id_param,
                "responses": with(error_responses(&["404", "409"]), "200", json_ok("Evaluation"))}},
            "/v1/jobs/{id}/impostors.glb": {"get": {"summary": "the baked impostors (jobs submitted with bake)", "parameters": id_param,
                "responses": with(error_responses(&["404", "409"]), "200", json!({"description": "GLB", "content": {"model/gltf-binary": {}}}))}},
            "/v1/jobs/{id}/report": {"get": {"summary": "a self-contained HTML report of the job: its run, evaluation and walkthrough frame times", "parameters": id_param,
                "responses": with(error_responses(&["404", "409"]), "200", json!({"description": "HTML", "content": {"text/html": {}}}))}}
        },
        "components": {"schemas": schemas}
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refs(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Object(o) => {
                if let Some(Value::String(r)) = o.get("$ref") {
                    out.push(r.clone());
                }
                o.values().for_each(|x| refs(x, out));
            }
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }

    #[test]
    fn every_reference_resolves() {
        let doc = openapi();
        let mut all = Vec::new();
        refs(&doc, &mut all);
        assert!(all.len() > 10);
        for r in all {
            let name = r.strip_prefix("#/components/schemas/").expect(&r);
            assert!(doc["components"]["schemas"].get(name).is_some(), "{r}");
        }
        for p in [
            "/v1/jobs",
            "/v1/jobs/{id}",
            "/v1/jobs/{id}/placement",
            "/v1/jobs/{id}/evaluation",
            "/v1/jobs/{id}/impostors.glb",
            "/v1/jobs/{id}/report",
            "/healthz",
        ] {
            assert!(doc["paths"].get(p).is_some(), "{p}");
        }
    }
}
