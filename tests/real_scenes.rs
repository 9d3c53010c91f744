//! Every third-party scene in `../shared/scenes/` loads and places with the
//! job of the same name in `fixtures/jobs/`, and the placement keeps the
//! guarantee where the same views without impostors break it. Each job's
//! target lies just below the slowest of 2,000 sampled views of its scene
//! without impostors (fixtures/jobs/README.md says how it was measured).
//! A scene that is absent is skipped with a message, or fails the test
//! when `IMPOSTOR_REQUIRE_SCENES` is set (as in CI).

use crate::util::*;

fn scene_places_and_keeps_the_guarantee(name: &str) {
    let Some(scene) = shared_scene(name) else {
        return;
    };
    let out = tmp(&format!("real-{name}"));
    let job = root().join(format!("fixtures/jobs/{name}.json"));
    let p = out.join(format!("{name}.json"));
    let o = place(&scene, &job, &p, &[]);
    assert!(
        matches!(code(&o), 0 | 3),
        "{name}: exit {}: {}",
        code(&o),
        stderr(&o)
    );
    let placement = read_json(&p);
    assert!(
        placement["summary"]["impostors"].as_u64().unwrap() > 0,
        "{name}: the job should need impostors: {}",
        placement["summary"]
    );
    let checked = check_guarantee(&scene, &job, &p, 2000, 0.005, &[]);
    eprintln!(
        "{name}: {} / max {} ms, control {} violations",
        placement["summary"], checked.eval["max_ms"], checked.control_violations
    );
}

#[test]
fn den_haag() {
    scene_places_and_keeps_the_guarantee("DenHaag_01");
}

#[test]
fn lyon() {
    scene_places_and_keeps_the_guarantee("lyon1_buildings");
}

#[test]
fn forza() {
    scene_places_and_keeps_the_guarantee("forza");
}

#[test]
fn azure_coast() {
    scene_places_and_keeps_the_guarantee("azure_coast_2p");
}

#[test]
fn duplex_interior() {
    scene_places_and_keeps_the_guarantee("Ifc2x3_Duplex_Architecture");
}
