//! The long-track stress scene (`impostor gen-city --track`): a race track
//! about 4.2 km long lined by thousands of small, cheap objects.

use std::collections::BTreeMap;

use glam::Vec3;

use super::Placer;
use super::meshes::{FlatFaces, add_mesh, building, tree};
use crate::Result;
use crate::math::rng::Rng;
use crate::scene::geometry::MeshData;
use crate::scene::glb::GlbBuilder;
use crate::scene::material::Material;

/// Length of the track along `x`, metres.
pub const TRACK_LENGTH: f64 = 4200.0;

/// The track's centre line: `z` at `x` (gentle S-bends within ±35 m).
pub fn track_z(x: f64) -> f64 {
    use std::f64::consts::TAU;
    25.0 * (TAU * x / 900.0).sin() + 10.0 * (TAU * x / 370.0).sin()
}

/// A race track along `x ∈ [0, 4200]` winding around `z = 0` (see
/// [`track_z`]), the stand-in for long tracks of racing games: barrier
/// segments every 6 m on both sides, a marker board every 12 m, trees in
/// bands 15–150 m from the track, grandstands every 300 m, one ground
/// object; about 4,400 objects of 12 to 200 triangles.
/// `fixtures/jobs/track.json` puts a 4,000 × 100 m view space on it: what a
/// view costs is dominated by draw calls along long sight lines.
pub fn generate_track(seed: u64) -> Result<Vec<u8>> {
    let mut rng = Rng::new(seed);
    let mut b = GlbBuilder::new();
    let concrete = b.add_material(&Material::new("barrier", [0.75, 0.75, 0.72, 1.0]))?;
    let board_m = b.add_material(&Material::new("board", [0.85, 0.2, 0.15, 1.0]))?;
    let bark = b.add_material(&Material::new("bark", [0.35, 0.25, 0.15, 1.0]))?;
    let leaves = b.add_material(&Material::new("leaves", [0.2, 0.45, 0.18, 1.0]))?;
    let stand_m = b.add_material(&Material::new("grandstand", [0.6, 0.62, 0.7, 1.0]))?;
    let grass = b.add_material(&Material::new("ground", [0.3, 0.5, 0.25, 1.0]))?;
    let mut m = MeshData::default();
    m.cuboid(Vec3::new(0.0, 0.0, -0.3), Vec3::new(6.0, 0.9, 0.3));
    let barrier = add_mesh(&mut b, "barrier", &[(&m, concrete)])?;
    let mut m = MeshData::default();
    m.cuboid(Vec3::new(-0.05, 0.0, -0.05), Vec3::new(0.05, 1.5, 0.05));
    m.cuboid(Vec3::new(-0.6, 1.5, -0.04), Vec3::new(0.6, 2.3, 0.04));
    let board = add_mesh(&mut b, "board", &[(&m, board_m)])?;
    let (trunk, crown) = tree(6, 10, 5, 1);
    let tree_mesh = add_mesh(&mut b, "tree", &[(&trunk, bark), (&crown, leaves)])?;
    let (walls, _) = building(8, 3, false, false);
    let stand = add_mesh(&mut b, "grandstand", &[(&walls, stand_m)])?;
    let mut g = MeshData::default();
    g.cuboid(
        Vec3::new(-200.0, -0.2, -250.0),
        Vec3::new(TRACK_LENGTH as f32 + 200.0, 0.0, 250.0),
    );
    let ground = add_mesh(&mut b, "ground", &[(&g, grass)])?;
    let no_lods = BTreeMap::new();
    let mut p = Placer {
        b: &mut b,
        roots: Vec::new(),
        counter: Default::default(),
        lods: &no_lods,
        terrain: None,
    };
    p.put("ground", ground, [0.0; 3], 0.0, [1.0; 3])?;
    // The heading of the track at `x` (rotation about y from +x).
    let heading = |x: f64| -((track_z(x + 1.0) - track_z(x - 1.0)) / 2.0).atan() as f32;
    for side in [-1.0f64, 1.0] {
        let mut x = 0.0;
        while x < TRACK_LENGTH {
            p.put(
                "barrier",
                barrier,
                [x, 0.0, track_z(x + 3.0) + side * 7.5],
                heading(x + 3.0),
                [1.0; 3],
            )?;
            x += 6.0;
        }
    }
    let mut x = 3.0;
    let mut side = 1.0;
    while x < TRACK_LENGTH {
        p.put(
            "board",
            board,
            [x, 0.0, track_z(x) + side * 9.0],
            heading(x),
            [1.0; 3],
        )?;
        side = -side;
        x += 12.0;
    }
    for k in 0..2650 {
        let x = rng.range(0.0, TRACK_LENGTH);
        let side = if k % 2 == 0 { -1.0 } else { 1.0 };
        let off = rng.range(15.0, 150.0);
        let s = rng.range(0.7, 1.3) as f32;
        p.put(
            "tree",
            tree_mesh,
            [x, 0.0, track_z(x) + side * off],
            rng.range(0.0, 6.2) as f32,
            [s; 3],
        )?;
    }
    let mut x = 150.0;
    while x < TRACK_LENGTH {
        let side = if ((x / 300.0) as u32).is_multiple_of(2) {
            -1.0
        } else {
            1.0
        };
        let z0 = track_z(x) + side * 12.0 + if side < 0.0 { -10.0 } else { 0.0 };
        p.put("grandstand", stand, [x, 0.0, z0], 0.0, [60.0, 12.0, 10.0])?;
        x += 300.0;
    }
    let roots = std::mem::take(&mut p.roots);
    b.set_scene_roots(&roots)?;
    Ok(b.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::gltf_load::load_scene_bytes;

    #[test]
    fn the_track_is_long_with_thousands_of_small_objects() {
        let glb = generate_track(3).unwrap();
        assert_eq!(glb, generate_track(3).unwrap(), "deterministic");
        let scene = load_scene_bytes(&glb, "track").unwrap();
        let n = scene.objects.len();
        assert!((4000..5000).contains(&n), "{n} objects");
        let small = scene
            .objects
            .iter()
            .filter(|o| (o.max - o.min).max_element() < 15.0)
            .count();
        assert!(small as f64 > 0.95 * n as f64, "{small} of {n} small");
        // Barriers stay off the centre line, where the view space is.
        for o in scene
            .objects
            .iter()
            .filter(|o| o.name.starts_with("barrier"))
        {
            let c = 0.5 * (o.min + o.max);
            let off = (c.z - track_z(c.x)).abs();
            assert!(
                (5.5..9.5).contains(&off),
                "{}: {off} m off the centre",
                o.name
            );
            assert!(o.min.x >= -1.0 && o.max.x <= TRACK_LENGTH + 7.0);
        }
    }
}
