//! JSON Schemas of the wire types, generated from the Rust types. The files
//! in `schemas/` are these texts; a test checks they are current.

use schemars::schema_for;

use crate::api::baked::{BakedImpostor, BakedScene};
use crate::api::evaluation::Evaluation;
use crate::api::job::Job;
use crate::api::placement::Placement;
use crate::api::pvs::PvsFile;
use crate::api::scene::SceneSummary;
use crate::api::stats::Stats;

/// `(file name, schema text)` of every wire type.
pub fn all() -> Vec<(&'static str, String)> {
    let pretty = |v: schemars::Schema| {
        let mut s = serde_json::to_string_pretty(&v).expect("schemas serialize");
        s.push('\n');
        s
    };
    vec![
        ("job.schema.json", pretty(schema_for!(Job))),
        ("scene.schema.json", pretty(schema_for!(SceneSummary))),
        ("placement.schema.json", pretty(schema_for!(Placement))),
        ("evaluation.schema.json", pretty(schema_for!(Evaluation))),
        ("stats.schema.json", pretty(schema_for!(Stats))),
        ("pvs.schema.json", pretty(schema_for!(PvsFile))),
        ("baked-node.schema.json", pretty(schema_for!(BakedImpostor))),
        ("baked-scene.schema.json", pretty(schema_for!(BakedScene))),
    ]
}
