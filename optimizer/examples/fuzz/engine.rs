//! The fuzzer's engine, shared by the `fuzz` example (100,000 cases per
//! target) and the test suite (a few thousand): byte mutations of real
//! inputs (a generated city's GLB, its glTF JSON and scene summary, a job,
//! a placement, a PVS file), each parsed and checked as the command line
//! does, inside `catch_unwind`. Deterministic for a seed.

use std::time::Instant;

use optimizer::api::job::Job;
use optimizer::api::placement::Placement;
use optimizer::api::pvs::PvsFile;
use optimizer::math::rng::Rng;
use optimizer::scene::gltf_load::load_scene_bytes;

/// Values that parsers trip over, spliced into inputs.
const TOKENS: &[&[u8]] = &[
    b"0",
    b"-1",
    b"1e308",
    b"-1e308",
    b"NaN",
    b"4294967295",
    b"18446744073709551615",
    b"2147483648",
    b"null",
    b"[]",
    b"{}",
    b"\"\"",
    b"true",
    b"0.0000001",
    b"1e-320",
    b"\"data:application/octet-stream;base64,AAAA\"",
    b"\"../x.bin\"",
    b"\"/dev/zero\"",
];

/// One mutation of `seed`: 1 to 8 edits (bit flips, bytes set to edge
/// values, little-endian u32 fields overwritten, ranges deleted or
/// duplicated, tokens inserted, truncation).
fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut m = seed.to_vec();
    let edits = 1 + rng.next_u64() % 8;
    for _ in 0..edits {
        let len = m.len().max(1);
        let at = (rng.next_u64() % len as u64) as usize;
        match rng.next_u64() % 8 {
            0 => {
                if let Some(b) = m.get_mut(at) {
                    *b ^= 1 << (rng.next_u64() % 8);
                }
            }
            1 => {
                let v = [0u8, 0xff, 0x7f, 0x80, b'"', b'{', b'9', b'-', b'e', b','];
                if let Some(b) = m.get_mut(at) {
                    *b = v[(rng.next_u64() % v.len() as u64) as usize];
                }
            }
            2 => {
                let at = at & !3;
                let v = [
                    0u32,
                    1,
                    u32::MAX,
                    0x8000_0000,
                    len as u32,
                    len as u32 - 1,
                    12,
                ];
                let v = v[(rng.next_u64() % v.len() as u64) as usize].to_le_bytes();
                if at + 4 <= m.len() {
                    m[at..at + 4].copy_from_slice(&v);
                }
            }
            3 => {
                let n = (rng.next_u64() % 64) as usize;
                let end = (at + n).min(m.len());
                m.drain(at.min(end)..end);
            }
            4 => {
                let n = (rng.next_u64() % 64) as usize;
                let end = (at + n).min(m.len());
                let piece = m[at.min(end)..end].to_vec();
                let to = (rng.next_u64() % (m.len() as u64 + 1)) as usize;
                m.splice(to..to, piece);
            }
            5 => {
                let t = TOKENS[(rng.next_u64() % TOKENS.len() as u64) as usize];
                let at = at.min(m.len());
                m.splice(at..at, t.iter().copied());
            }
            6 => {
                // Replace a JSON number or word after `at` with a token.
                let t = TOKENS[(rng.next_u64() % TOKENS.len() as u64) as usize];
                if let Some(start) = m[at.min(m.len())..]
                    .iter()
                    .position(|b| b.is_ascii_digit())
                    .map(|p| p + at)
                {
                    let end = m[start..]
                        .iter()
                        .position(|b| !(b.is_ascii_digit() || b"+-.eE".contains(b)))
                        .map_or(m.len(), |p| p + start);
                    m.splice(start..end, t.iter().copied());
                }
            }
            _ => m.truncate(at),
        }
    }
    m
}

type Target<'a> = (&'static str, Vec<u8>, Box<dyn Fn(&[u8]) + 'a>);

/// What `run` found for one target.
pub struct Outcome {
    /// The target's name.
    pub name: &'static str,
    /// Cases run (up to and including a panic).
    pub cases: u64,
    /// Wall time of the target's cases, seconds.
    pub seconds: f64,
    /// The slowest case, seconds.
    pub slowest: f64,
    /// The first input that panicked, with its case number.
    pub panic: Option<(u64, Vec<u8>)>,
}

/// Runs `cases` mutations of each target's input from `seed`; a target
/// stops at its first panic.
pub fn run(cases: u64, seed: u64) -> Vec<Outcome> {
    // Real inputs: a small generated city and the files of a run over it.
    let glb = optimizer::citygen::generate(&optimizer::citygen::CityParams {
        seed: 1,
        scale: 0.05,
        lod: false,
        ..Default::default()
    })
    .expect("generate a city");
    let scene = load_scene_bytes(&glb, "city").expect("load the city");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let gltf_json = glb[20..20 + json_len].to_vec();
    let summary = serde_json::to_vec(&scene.summary()).unwrap();
    // Relative to this file, which the example and the tests both build.
    let job_bytes = include_bytes!("../../../fixtures/jobs/city-small.json").to_vec();
    let job = Job::from_json(&job_bytes, "job").unwrap();
    let placement = {
        let input = optimizer::input::SceneInput::load(
            &optimizer::input::Load::new(
                optimizer::input::Source::Bytes {
                    bytes: &glb,
                    name: "city",
                },
                optimizer::input::GeometryUse::WhenNeeded,
            ),
            &job,
            "job",
        )
        .unwrap();
        let out = input
            .prepare(&job, "job")
            .unwrap()
            .place(&Default::default(), &Default::default())
            .unwrap();
        serde_json::to_vec(&out.placement).unwrap()
    };
    let n_objects = scene.objects.len();
    let pvs = serde_json::to_vec(&serde_json::json!({
        "objects": n_objects,
        "cells": [
            {"min": [0.0, 0.0, 0.0], "max": [23.0, 2.0, 23.0], "visible": [0, 1, 2]},
            {"min": [23.0, 0.0, 0.0], "max": [46.0, 2.0, 23.0], "visible": []},
            {"min": [0.0, 0.0, 23.0], "max": [23.0, 2.0, 46.0], "visible": [3]},
        ],
    }))
    .unwrap();
    PvsFile::from_json(&pvs, "pvs").expect("the PVS seed parses");

    let parse_scene = |b: &[u8]| {
        let _ = load_scene_bytes(b, "fuzz");
    };
    let check_placement = |b: &[u8]| {
        if let Ok(p) = serde_json::from_slice::<Placement>(b) {
            let _ = p.validate(&scene, "fuzz");
        }
    };
    let targets: Vec<Target<'_>> = vec![
        ("scene GLB", glb.clone(), Box::new(parse_scene)),
        ("glTF JSON", gltf_json, Box::new(parse_scene)),
        ("scene summary", summary, Box::new(parse_scene)),
        (
            "job JSON",
            job_bytes.clone(),
            Box::new(|b: &[u8]| {
                let _ = Job::from_json(b, "fuzz");
            }),
        ),
        ("placement JSON", placement, Box::new(check_placement)),
        (
            "PVS",
            pvs,
            Box::new(move |b: &[u8]| {
                if let Ok(f) = PvsFile::from_json(b, "fuzz") {
                    let _ = f.check(n_objects, "fuzz");
                }
            }),
        ),
    ];
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut out = Vec::new();
    for (name, input, target) in &targets {
        let mut rng = Rng::new(seed);
        let start = Instant::now();
        let mut slowest = 0.0f64;
        let mut panic = None;
        let mut done = 0;
        for case in 0..cases {
            let m = mutate(&mut rng, input);
            let t = Instant::now();
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| target(&m)));
            slowest = slowest.max(t.elapsed().as_secs_f64());
            done = case + 1;
            if r.is_err() {
                panic = Some((case, m));
                break;
            }
        }
        out.push(Outcome {
            name,
            cases: done,
            seconds: start.elapsed().as_secs_f64(),
            slowest,
            panic,
        });
    }
    std::panic::set_hook(hook);
    out
}
