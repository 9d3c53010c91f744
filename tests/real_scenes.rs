//! Every third-party scene in `../shared/scenes/` loads and places with the
//! job of the same name in `fixtures/jobs/`, and the placement passes the
//! independent check. Skipped, with a message, when the folder is absent.

use crate::util::*;

const SCENES: [&str; 5] = [
    "DenHaag_01",
    "lyon1_buildings",
    "forza",
    "azure_coast_2p",
    "Ifc2x3_Duplex_Architecture",
];

#[test]
fn real_scenes_place_and_pass_the_check() {
    let dir = root().join("../shared/scenes");
    if !dir.is_dir() {
        eprintln!("skipped: {} is absent", dir.display());
        return;
    }
    let out = tmp("real");
    for name in SCENES {
        let scene = dir.join(format!("{name}.glb"));
        if !scene.exists() {
            eprintln!("skipped: {} is absent", scene.display());
            continue;
        }
        let job = root().join(format!("fixtures/jobs/{name}.json"));
        let p = out.join(format!("{name}.placement.json"));
        let o = place(&scene, &job, &p, &[]);
        assert!(
            matches!(code(&o), 0 | 3),
            "{name}: exit {}: {}",
            code(&o),
            stderr(&o)
        );
        let placement = read_json(&p);
        assert!(
            placement["summary"]["cpvs"].as_u64().unwrap() > 0,
            "{name}: the job should have problem views"
        );
        let e = out.join(format!("{name}.eval.json"));
        let o = evaluate(&scene, &job, &p, &e, 2000);
        assert_eq!(code(&o), 0, "{name}: {}", stderr(&o));
        let eval = read_json(&e);
        assert_eq!(eval["violations_in_solved"], 0, "{name}: {eval}");
        eprintln!("{name}: {} / {}", placement["summary"], eval["max_ms"]);
    }
}
