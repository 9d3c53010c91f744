//! Measures the ray caster on the generated city: build time, memory and
//! rays per second (all cores) for `first_hit`, `trace` and `segment_clear`.
//!
//! `cargo run --release -p optimizer --example raycast_bench [scale] [rays] [only]`
//! (`only`: run just the phase whose name starts with it).

use std::time::Instant;

use glam::DVec3;
use optimizer::citygen::{CityParams, generate};
use optimizer::math::rng::Rng;
use optimizer::render::raycast::RayCaster;
use optimizer::scene::geometry::load_geometry_bytes;
use rayon::prelude::*;

fn main() -> optimizer::Result<()> {
    let scale = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let t = Instant::now();
    let glb = generate(&CityParams {
        seed: 1,
        scale,
        lod: false,
        ..Default::default()
    })?;
    let geom = load_geometry_bytes(&glb, "city")?;
    println!(
        "city: {} objects, {} meshes, {} instances, {:.2} M world triangles, {:.2} M distinct ({:.1} s)",
        geom.object_count(),
        geom.meshes.len(),
        geom.instances.len(),
        geom.triangle_count() as f64 / 1e6,
        geom.meshes
            .iter()
            .map(|m| m.indices.len() / 3)
            .sum::<usize>() as f64
            / 1e6,
        t.elapsed().as_secs_f64()
    );
    let t = Instant::now();
    let rc = RayCaster::new(&geom);
    println!(
        "build: {:.3} s, {:.1} MB, {} threads",
        t.elapsed().as_secs_f64(),
        rc.memory_bytes() as f64 / 1e6,
        rayon::current_num_threads()
    );

    // Scene extent from the instance origins.
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for i in &geom.instances {
        lo = lo.min(i.transform.translation);
        hi = hi.max(i.transform.translation);
    }
    // Eye points 1.7–40 m above the ground (y up), directions from 30° down
    // to 30° up: the views of a walk or a drive through the city.
    let mut rng = Rng::new(7);
    let n = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2_000_000);
    let rays: Vec<(DVec3, DVec3)> = (0..n)
        .map(|_| {
            let mut o = rng.in_box(lo, hi);
            o.y = lo.y + rng.range(1.7, 40.0);
            let d = rng.direction_in_pitch((-30f64).to_radians(), 30f64.to_radians());
            (o, d)
        })
        .collect();

    let only = std::env::args().nth(3).unwrap_or_default();
    let run = |phase: &str| phase.starts_with(&only);

    if run("first_hit") {
        let t = Instant::now();
        let hits = rays
            .par_iter()
            .filter(|(o, d)| rc.first_hit(*o, *d, 0.0, f64::INFINITY).is_some())
            .count();
        report("first_hit", n, hits, t);
    }
    if run("trace") {
        let t = Instant::now();
        let seen: usize = rays
            .par_iter()
            .map(|(o, d)| {
                let mut k = 0;
                rc.trace(*o, *d, 0.0, f64::INFINITY, &mut |_| k += 1);
                k
            })
            .sum();
        report("trace", n, seen, t);
    }
    if run("segment_clear") {
        let t = Instant::now();
        let clear = rays
            .par_iter()
            .filter(|(o, d)| rc.segment_clear(*o, *o + *d * 200.0))
            .count();
        report("segment_clear (200 m)", n, clear, t);
    }
    Ok(())
}

fn report(what: &str, n: usize, count: usize, t: Instant) {
    let s = t.elapsed().as_secs_f64();
    println!(
        "{what}: {:.2} M rays/s ({n} rays in {s:.2} s; count {count})",
        n as f64 / s / 1e6
    );
}
