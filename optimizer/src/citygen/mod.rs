//! A seeded, Vienna-like procedural city (`impostor gen-city`).
//!
//! A street grid with blocks of irregular size; perimeter-block buildings of
//! varied height and facade detail; parks; street objects (trees, lamps,
//! benches, cars, kiosks) along the sidewalks and parking lanes; one ground
//! object. Every object is a node instancing one of a few dozen prototype
//! meshes, so the file stays small. The city spans `x ∈ [0, W]`,
//! `z ∈ [0, D]` with the ground at `y = 0`; the full city (scale 1) is about
//! 1500 × 1000 m with about 5,300 objects and 10 M triangles, like the
//! paper's Vienna model. The street centre lines are free of objects.
//!
//! # Levels of detail (`lod`, `gen-city --lod`)
//!
//! With [`CityParams::lod`] the street objects — trees, lamps, benches, cars
//! and litter bins — get two coarser levels (glTF `MSFT_lod`), built by the
//! same prototype functions with fewer rings and sides (tree crowns half
//! the rings and 3/8 of the sides, then a quarter and 3/16, e.g. 16 × 32 →
//! 8 × 12 → 4 × 6; trunks 6 then 4 sides; lamps and bins 6 then 3 sides;
//! cars half then a quarter of the rings (at least 3) and sides; straight
//! cylinders one segment; benches merge their slats, then drop legs and
//! arms). The levels are extra nodes with
//! the object's transform, neither scene roots nor children, named
//! `<object>_lod1` and `<object>_lod2`; their meshes come after every
//! full-detail mesh. Buildings, kiosks and the ground get none: buildings
//! are the occluders of the visibility stage, and an object with levels is
//! never an occluder. Every level lies within the full-detail level's box,
//! so objects, their ids, bounds and full-detail geometry are those of the
//! city without levels (same seed and scale); without `lod` the file holds
//! no level nodes, level meshes or `MSFT_lod` extensions at all.
//!
//! `MSFT_screencoverage` comes from each level's geometric error `e_k`: a
//! bound on the distance between its surface and level 0's, in local metres
//! (per part, the sum of both tessellations' chord errors against the smooth
//! surface; for the bench, the largest gap closed or part dropped), times
//! the instance's largest scale. Level `k` may be drawn from the distance
//! `d_k = e_k · f / ε` at which that error projects to `ε = 1` pixel with the
//! default camera (512 pixels high, 45° field of view: `f = 256 / tan 22.5°`);
//! level `k − 1`'s value is the screen coverage of the object's bounding
//! sphere at `d_k` (projected area over 512², as
//! [`crate::math::geom::projected_area_px`]). The last level's value is 0: it is
//! never culled, so levels change cost, never visibility.
//!
//! The prototype shapes are in `meshes`, the street prototypes' levels in
//! `streets`, the failure scene of the comparison reports
//! ([`generate_failure`]) in `failure`, and the long-track stress scene
//! ([`generate_track`]) in `track`.

mod failure;
mod meshes;
mod streets;
mod terrain;
mod track;

pub use failure::generate_failure;
pub use track::{TRACK_LENGTH, generate_track, track_z};

use std::collections::BTreeMap;
use std::f32::consts::PI;

use glam::Vec3;
use serde_json::json;

use crate::error::{Error, Result};
use crate::math::rng::Rng;
use crate::scene::geometry::MeshData;
use crate::scene::glb::{GeometryId, GlbBuilder, MeshPrimitive, Node};
use crate::scene::material::Material;
use meshes::{FlatFaces, add_geometry, add_mesh, bench, bin, building, car, kiosk, lamp, tree};
use streets::{ProtoLod, Street};
use terrain::Terrain;

/// Generator parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CityParams {
    /// Seed: the same seed, scale and `lod` give byte-identical output.
    pub seed: u64,
    /// Fraction of the full city's area, in `(0, 16]`; lengths scale by its
    /// square root.
    pub scale: f64,
    /// Give street objects `MSFT_lod` levels of detail (see the module
    /// docs). Objects, their ids and their full-detail geometry do not
    /// change.
    pub lod: bool,
    /// Height of the hills, metres (0: flat). The city then stands on
    /// seeded hills (`terrain`); objects and ids are those of the flat city,
    /// lifted onto the ground.
    pub hills: f64,
}

impl Default for CityParams {
    fn default() -> Self {
        CityParams {
            seed: 1,
            scale: 1.0,
            lod: false,
            hills: 0.0,
        }
    }
}

/// Width (x) and depth (z) of the city for a scale, metres.
pub fn city_size(scale: f64) -> [f64; 2] {
    let k = scale.sqrt();
    [1500.0 * k, 1000.0 * k]
}

/// Prototype mesh indices by kind.
struct Prototypes {
    buildings: Vec<u32>,
    trees: Vec<u32>,
    lamps: Vec<u32>,
    benches: Vec<u32>,
    cars: Vec<u32>,
    kiosks: Vec<u32>,
    bins: Vec<u32>,
    ground: u32,
    /// Levels of detail by full-detail mesh (empty without `lod`).
    lods: BTreeMap<u32, ProtoLod>,
}

fn prototypes(
    b: &mut GlbBuilder,
    rng: &mut Rng,
    size: [f64; 2],
    lod: bool,
    terrain: Option<&Terrain>,
) -> Result<Prototypes> {
    let mat = |b: &mut GlbBuilder, name: &str, c: [f32; 3]| {
        b.add_material(&Material::new(name, [c[0], c[1], c[2], 1.0]))
    };
    let facade_colours: [[f32; 3]; 6] = [
        [0.86, 0.80, 0.66],
        [0.92, 0.88, 0.78],
        [0.78, 0.62, 0.50],
        [0.70, 0.72, 0.70],
        [0.95, 0.90, 0.70],
        [0.82, 0.70, 0.62],
    ];
    let mut facades = Vec::new();
    for (i, c) in facade_colours.iter().enumerate() {
        facades.push(mat(b, &format!("facade_{i}"), *c)?);
    }
    let roof_mat = mat(b, "roof", [0.55, 0.25, 0.18])?;
    let flat_roof = mat(b, "roof_flat", [0.35, 0.35, 0.37])?;
    let bark = mat(b, "bark", [0.35, 0.24, 0.15])?;
    let leaves = mat(b, "leaves", [0.22, 0.45, 0.18])?;
    let metal = mat(b, "metal", [0.2, 0.22, 0.25])?;
    let light = mat(b, "lamp_glass", [0.95, 0.93, 0.8])?;
    let wood = mat(b, "wood", [0.55, 0.38, 0.22])?;
    let glass = mat(b, "car_glass", [0.15, 0.2, 0.25])?;
    let tyre = mat(b, "tyre", [0.08, 0.08, 0.08])?;
    let asphalt = mat(b, "ground", [0.3, 0.3, 0.3])?;
    let paints: Vec<u32> = [
        [0.7, 0.1, 0.1],
        [0.1, 0.2, 0.6],
        [0.85, 0.85, 0.85],
        [0.1, 0.1, 0.1],
        [0.2, 0.5, 0.3],
    ]
    .iter()
    .enumerate()
    .map(|(i, c)| mat(b, &format!("paint_{i}"), *c))
    .collect::<Result<_>>()?;

    let mut buildings = Vec::new();
    for i in 0..36u32 {
        // Detail from a few hundred to about 13,000 triangles.
        let nx = 2 + (rng.next_u64() % 11) as u32;
        let ny = 2 + (rng.next_u64() % 9) as u32;
        let sills = i % 3 != 0;
        let pitched = i % 2 == 0;
        let (walls, roof) = building(nx, ny, sills, pitched);
        let fm = facades[i as usize % facades.len()];
        let rm = if pitched { roof_mat } else { flat_roof };
        buildings.push(add_mesh(
            b,
            &format!("building_proto_{i}"),
            &[(&walls, fm), (&roof, rm)],
        )?);
    }
    // Street prototypes that get levels of detail, with their materials.
    let mut street: Vec<(u32, Street, Vec<u32>)> = Vec::new();
    let mut trees = Vec::new();
    for (i, (r, s)) in [(16, 32), (24, 40), (28, 56)].into_iter().enumerate() {
        let (trunk, crown) = tree(r, s, 8, 4);
        let full = Street::Tree {
            rings: r,
            sides: s,
            trunk_sides: 8,
            trunk_segments: 4,
        };
        street.push((b.mesh_count() as u32, full, vec![bark, leaves]));
        trees.push(add_mesh(
            b,
            &format!("tree_proto_{i}"),
            &[(&trunk, bark), (&crown, leaves)],
        )?);
    }
    let mut lamps = Vec::new();
    for (i, s) in [10u32, 14].into_iter().enumerate() {
        let (pole, head) = lamp(s, 10, 3);
        let full = Street::Lamp {
            sides: s,
            pole_segments: 10,
            head_segments: 3,
        };
        street.push((b.mesh_count() as u32, full, vec![metal, light]));
        lamps.push(add_mesh(
            b,
            &format!("lamp_proto_{i}"),
            &[(&pole, metal), (&head, light)],
        )?);
    }
    street.push((
        b.mesh_count() as u32,
        Street::Bench { level: 0 },
        vec![wood],
    ));
    let benches = vec![add_mesh(b, "bench_proto", &[(&bench(0), wood)])?];
    let mut cars = Vec::new();
    for (i, (r, s)) in [(10u32, 24u32), (14, 32), (18, 40)].into_iter().enumerate() {
        for (j, &paint) in paints.iter().enumerate().take(2 + i) {
            let (body, win, wheels) = car(r, s, 2);
            let full = Street::Car {
                rings: r,
                sides: s,
                wheel_segments: 2,
            };
            street.push((b.mesh_count() as u32, full, vec![paint, glass, tyre]));
            cars.push(add_mesh(
                b,
                &format!("car_proto_{i}_{j}"),
                &[(&body, paint), (&win, glass), (&wheels, tyre)],
            )?);
        }
    }
    let (kw, kr) = kiosk();
    let kiosks = vec![add_mesh(
        b,
        "kiosk_proto",
        &[(&kw, facades[4]), (&kr, metal)],
    )?];
    street.push((
        b.mesh_count() as u32,
        Street::Bin {
            sides: 12,
            segments: 2,
        },
        vec![metal],
    ));
    let bins = vec![add_mesh(b, "bin_proto", &[(&bin(12, 2), metal)])?];
    let g = match terrain {
        Some(t) => t.ground(size),
        None => {
            let mut g = MeshData::default();
            g.cuboid(
                Vec3::new(0.0, -0.2, 0.0),
                Vec3::new(size[0] as f32, 0.0, size[1] as f32),
            );
            g
        }
    };
    let ground = add_mesh(b, "ground", &[(&g, asphalt)])?;
    // Levels of detail come after every full-detail mesh, so those keep
    // their indices; a level's geometry is written once and shared by the
    // colour variants.
    let mut lods = BTreeMap::new();
    let mut written: Vec<(Street, Vec<GeometryId>)> = Vec::new();
    for (mesh, full, materials) in street.into_iter().filter(|_| lod) {
        let coarser = full.coarser();
        let mut meshes = [0u32; 2];
        for (k, level) in coarser.into_iter().enumerate() {
            let geometry = match written.iter().find(|(l, _)| *l == level) {
                Some((_, ids)) => ids.clone(),
                None => {
                    let ids = level
                        .parts()
                        .iter()
                        .map(|part| add_geometry(b, part))
                        .collect::<Result<Vec<_>>>()?;
                    written.push((level, ids.clone()));
                    ids
                }
            };
            let primitives: Vec<MeshPrimitive> = geometry
                .into_iter()
                .zip(&materials)
                .map(|(geometry, &m)| MeshPrimitive {
                    geometry,
                    material: Some(m),
                })
                .collect();
            meshes[k] = b.add_mesh(&format!("lod{}_of_mesh_{mesh}", k + 1), &primitives)?;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in full.parts().iter().flat_map(|part| part.positions.iter()) {
            for i in 0..3 {
                lo[i] = lo[i].min(f64::from(p[i]));
                hi[i] = hi[i].max(f64::from(p[i]));
            }
        }
        let errors = coarser.map(|level| level.error_from(full));
        lods.insert(
            mesh,
            ProtoLod {
                meshes,
                errors,
                lo,
                hi,
            },
        );
    }
    Ok(Prototypes {
        buildings,
        trees,
        lamps,
        benches,
        cars,
        kiosks,
        bins,
        ground,
        lods,
    })
}

/// Splits `[0, len]` into alternating streets and blocks, starting and
/// ending with a street; returns the blocks as `[lo, hi]`.
fn blocks_along(rng: &mut Rng, len: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let mut blocks = Vec::new();
    let mut streets = Vec::new();
    let mut x = 0.0;
    loop {
        let street = rng.range(15.0, 30.0);
        streets.push([x, x + street]);
        x += street;
        let width = rng.range(60.0, 140.0);
        if x + width + 15.0 > len {
            streets.last_mut().expect("one street")[1] = len.max(x);
            break;
        }
        blocks.push([x, x + width]);
        x += width;
    }
    (blocks, streets)
}

/// y-rotation quaternion `[x, y, z, w]`.
fn yaw(angle: f32) -> [f32; 4] {
    [0.0, (angle * 0.5).sin(), 0.0, (angle * 0.5).cos()]
}

/// Puts objects into the city: one scene root per object, named by kind
/// and count, with its levels of detail when its mesh has them.
struct Placer<'a> {
    b: &'a mut GlbBuilder,
    roots: Vec<u32>,
    counter: BTreeMap<&'static str, u32>,
    lods: &'a BTreeMap<u32, ProtoLod>,
    terrain: Option<&'a Terrain>,
}

impl Placer<'_> {
    fn put(
        &mut self,
        kind: &'static str,
        mesh: u32,
        t: [f64; 3],
        rot: f32,
        scale: [f32; 3],
    ) -> Result<()> {
        let n = self.counter.entry(kind).or_insert(0);
        let name = format!("{kind}_{:04}", *n);
        *n += 1;
        // On hills: a building on the lowest point of its footprint (its
        // origin is a corner, its scale the footprint), anything else on
        // the ground at its origin; the ground is the terrain itself.
        let lift = match self.terrain {
            Some(_) if kind == "ground" => 0.0,
            Some(terrain) if kind == "building" => terrain.lowest(
                t[0],
                t[0] + f64::from(scale[0]),
                t[2],
                t[2] + f64::from(scale[2]),
            ),
            Some(terrain) => terrain.height(t[0], t[2]),
            None => 0.0,
        };
        let translation = [t[0] as f32, (t[1] + lift) as f32, t[2] as f32];
        let mut node = Node::new(&name)
            .with_mesh(mesh)
            .with_trs(translation, yaw(rot), scale);
        if let Some(lod) = self.lods.get(&mesh) {
            // The levels: extra nodes at the same place, neither roots nor
            // children, named by the object's node.
            let mut ids = Vec::with_capacity(lod.meshes.len());
            for (k, &m) in lod.meshes.iter().enumerate() {
                ids.push(
                    self.b.add_node(
                        Node::new(format!("{name}_lod{}", k + 1))
                            .with_mesh(m)
                            .with_trs(translation, yaw(rot), scale),
                    )?,
                );
            }
            let coverage = lod.screen_coverage(rot, scale);
            if !(coverage[0] > coverage[1] && coverage[1] > coverage[2]) {
                return Err(Error::Internal(format!(
                    "{name}: screen coverages {coverage:?} are not strictly decreasing"
                )));
            }
            node = node
                .with_extension("MSFT_lod", json!({ "ids": ids }))
                .with_extras(json!({ "MSFT_screencoverage": coverage }));
        }
        let id = self.b.add_node(node)?;
        self.roots.push(id);
        Ok(())
    }
}

/// Generates the city as GLB bytes.
pub fn generate(params: &CityParams) -> Result<Vec<u8>> {
    let scale = params.scale;
    if !(scale.is_finite() && scale > 0.0 && scale <= 16.0) {
        return Err(Error::bad("--scale", format!("{scale} must be in (0, 16]")));
    }
    let hills = params.hills;
    if !(hills.is_finite() && (0.0..=500.0).contains(&hills)) {
        return Err(Error::bad(
            "--hills",
            format!("{hills} must be between 0 and 500 metres"),
        ));
    }
    let size = city_size(scale);
    let terrain = (hills > 0.0).then(|| Terrain::new(params.seed, size, hills));
    let mut rng = Rng::new(params.seed);
    let mut b = GlbBuilder::new();
    let protos = prototypes(&mut b, &mut rng, size, params.lod, terrain.as_ref())?;
    let (xblocks, xstreets) = blocks_along(&mut rng, size[0]);
    let (zblocks, zstreets) = blocks_along(&mut rng, size[1]);
    let mut p = Placer {
        b: &mut b,
        roots: Vec::new(),
        counter: Default::default(),
        lods: &protos.lods,
        terrain: terrain.as_ref(),
    };
    p.put("ground", protos.ground, [0.0; 3], 0.0, [1.0; 3])?;
    let pick = |rng: &mut Rng, v: &[u32]| v[(rng.next_u64() % v.len() as u64) as usize];

    for xb in &xblocks {
        for zb in &zblocks {
            let park = rng.f64() < 0.1;
            if park {
                // A park: a loose grid of trees and a few benches.
                let mut x = xb[0] + 6.0;
                while x < xb[1] - 6.0 {
                    let mut z = zb[0] + 6.0;
                    while z < zb[1] - 6.0 {
                        if rng.f64() < 0.5 {
                            let s = rng.range(0.8, 1.3) as f32;
                            let t = [x + rng.range(-2.0, 2.0), 0.0, z + rng.range(-2.0, 2.0)];
                            p.put(
                                "tree",
                                pick(&mut rng, &protos.trees),
                                t,
                                rng.range(0.0, std::f64::consts::TAU) as f32,
                                [s; 3],
                            )?;
                        } else if rng.f64() < 0.1 {
                            p.put(
                                "bench",
                                protos.benches[0],
                                [x, 0.0, z],
                                rng.range(0.0, std::f64::consts::TAU) as f32,
                                [1.0; 3],
                            )?;
                        }
                        z += 15.0;
                    }
                    x += 15.0;
                }
                continue;
            }
            // Perimeter buildings: full-width rows on the z sides, inset rows
            // on the x sides.
            let depth_n = rng.range(12.0, 18.0);
            let depth_s = rng.range(12.0, 18.0);
            let row = |p: &mut Placer,
                       rng: &mut Rng,
                       start: f64,
                       end: f64,
                       fixed: f64,
                       depth: f64,
                       along_x: bool,
                       front_low: bool|
             -> Result<()> {
                let mut s = start;
                while end - s > 6.0 {
                    let mut w = rng.range(12.0, 30.0);
                    if end - (s + w) < 8.0 {
                        w = end - s;
                    }
                    let tower = rng.f64() < 0.03;
                    let h = if tower {
                        rng.range(40.0, 60.0)
                    } else {
                        rng.range(8.0, 35.0)
                    };
                    let mesh = pick(rng, &protos.buildings);
                    let (t, scale_v) = if along_x {
                        let z0 = if front_low { fixed } else { fixed - depth };
                        ([s, 0.0, z0], [w as f32, h as f32, depth as f32])
                    } else {
                        let x0 = if front_low { fixed } else { fixed - depth };
                        ([x0, 0.0, s], [depth as f32, h as f32, w as f32])
                    };
                    p.put("building", mesh, t, 0.0, scale_v)?;
                    s += w;
                }
                Ok(())
            };
            row(&mut p, &mut rng, xb[0], xb[1], zb[0], depth_n, true, true)?;
            row(&mut p, &mut rng, xb[0], xb[1], zb[1], depth_s, true, false)?;
            let (z0, z1) = (zb[0] + depth_n, zb[1] - depth_s);
            if z1 - z0 > 10.0 {
                let dw = rng.range(12.0, 18.0);
                let de = rng.range(12.0, 18.0);
                row(&mut p, &mut rng, z0, z1, xb[0], dw, false, true)?;
                row(&mut p, &mut rng, z0, z1, xb[1], de, false, false)?;
                // A courtyard tree now and then.
                if rng.f64() < 0.4 && xb[1] - xb[0] > 2.0 * (dw + de) {
                    let t = [(xb[0] + xb[1]) * 0.5, 0.0, (z0 + z1) * 0.5];
                    p.put("tree", pick(&mut rng, &protos.trees), t, 0.0, [1.2; 3])?;
                }
            }
        }
    }

    // Street objects along both kerbs of every street: sidewalk objects 2.5 m
    // and parked cars 5 m from the block edge, the centre line kept free.
    let kerb = |p: &mut Placer,
                rng: &mut Rng,
                along_x: bool,
                fixed: f64,
                dir: f64,
                len: f64,
                blocks: &[[f64; 2]]|
     -> Result<()> {
        for blk in blocks {
            let mut s = blk[0] + 3.0;
            while s < blk[1] - 3.0 {
                let side = fixed + dir * 2.5;
                let park = fixed + dir * 5.0;
                let at = |c: f64, s: f64| if along_x { [s, 0.0, c] } else { [c, 0.0, s] };
                let rot = if along_x { 0.0 } else { PI / 2.0 };
                let r = rng.f64();
                if r < 0.22 {
                    let sc = rng.range(0.8, 1.2) as f32;
                    p.put(
                        "tree",
                        pick(rng, &protos.trees),
                        at(side, s),
                        rng.range(0.0, std::f64::consts::TAU) as f32,
                        [sc; 3],
                    )?;
                } else if r < 0.37 {
                    p.put(
                        "lamp",
                        pick(rng, &protos.lamps),
                        at(side, s),
                        rot + if dir > 0.0 { 0.0 } else { PI },
                        [1.0; 3],
                    )?;
                } else if r < 0.41 {
                    p.put("bench", protos.benches[0], at(side, s), rot, [1.0; 3])?;
                } else if r < 0.43 {
                    p.put("bin", protos.bins[0], at(side, s), 0.0, [1.0; 3])?;
                } else if r < 0.435 {
                    p.put("kiosk", protos.kiosks[0], at(side, s), rot, [1.0; 3])?;
                }
                if rng.f64() < 0.2 {
                    p.put(
                        "car",
                        pick(rng, &protos.cars),
                        at(park, s + 2.0),
                        rot,
                        [1.0; 3],
                    )?;
                }
                s += 6.5;
            }
        }
        let _ = len;
        Ok(())
    };
    for st in &zstreets {
        if st[1] - st[0] < 14.0 {
            continue;
        }
        kerb(&mut p, &mut rng, true, st[0], 1.0, size[0], &xblocks)?;
        kerb(&mut p, &mut rng, true, st[1], -1.0, size[0], &xblocks)?;
    }
    for st in &xstreets {
        if st[1] - st[0] < 14.0 {
            continue;
        }
        kerb(&mut p, &mut rng, false, st[0], 1.0, size[1], &zblocks)?;
        kerb(&mut p, &mut rng, false, st[1], -1.0, size[1], &zblocks)?;
    }
    let roots = std::mem::take(&mut p.roots);
    b.set_scene_roots(&roots)?;
    Ok(b.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::geometry::load_geometry_bytes;
    use crate::scene::gltf_load::load_scene_bytes;

    fn city(seed: u64, scale: f64, lod: bool) -> Vec<u8> {
        generate(&CityParams {
            seed,
            scale,
            lod,
            hills: 0.0,
        })
        .unwrap()
    }

    /// FNV-1a, 64 bits, of a GLB's content: its glTF document as
    /// `gltf-json` reads and writes it, then its binary chunk. It covers
    /// every field value and every buffer byte, not the JSON writer's
    /// spacing or key order.
    fn content_fnv(glb: &[u8]) -> u64 {
        let g = gltf::binary::Glb::from_slice(glb).unwrap();
        let root: gltf::json::Root = serde_json::from_slice(&g.json).unwrap();
        let document = serde_json::to_vec(&root).unwrap();
        let bin = g.bin.as_deref().unwrap_or_default();
        document
            .iter()
            .chain(bin)
            .fold(0xcbf2_9ce4_8422_2325, |h, &b| {
                (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
            })
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let a = city(3, 0.05, false);
        assert_eq!(a, city(3, 0.05, false));
        assert_ne!(a, city(4, 0.05, false));
        let l = city(3, 0.05, true);
        assert_eq!(l, city(3, 0.05, true));
        assert_ne!(a, l);
    }

    #[test]
    fn output_without_lod_is_unchanged() {
        // Content hashes of cities without levels: levels of detail must
        // leave them untouched.
        assert_eq!(content_fnv(&city(3, 0.05, false)), 0x5457_fb3c_0d4b_ff6a);
        assert_eq!(content_fnv(&city(1, 0.1, false)), 0x39d3_4d2d_8a43_49be);
    }

    fn is_street(name: &str) -> bool {
        ["tree_", "lamp_", "bench_", "car_", "bin_"]
            .iter()
            .any(|k| name.starts_with(k))
    }

    #[test]
    fn lod_city_adds_levels_only() {
        let (plain, lod) = (city(2, 0.05, false), city(2, 0.05, true));
        let (a, b) = (
            load_scene_bytes(&plain, "plain").unwrap(),
            load_scene_bytes(&lod, "lod").unwrap(),
        );
        assert_eq!(a.objects.len(), b.objects.len());
        let mut with_levels = 0;
        for (id, (x, y)) in a.objects.iter().zip(&b.objects).enumerate() {
            assert_eq!(
                (&x.name, x.triangles, x.draw_calls, x.min, x.max),
                (&y.name, y.triangles, y.draw_calls, y.min, y.max),
                "object {id}"
            );
            assert!(x.lods.is_empty());
            if is_street(&y.name) {
                with_levels += 1;
                assert_eq!(y.lods.len(), 3, "{}", y.name);
                assert_eq!(y.lods[0].triangles, y.triangles);
                assert!(y.lods[1].triangles < y.lods[0].triangles);
                assert!(y.lods[2].triangles < y.lods[1].triangles);
                assert!(y.lods.iter().all(|l| l.draw_calls == y.draw_calls));
                assert!(y.lods[0].min_coverage < 1.0 && y.lods[1].min_coverage > 0.0);
                assert_eq!(y.lods[2].min_coverage, 0.0);
            } else {
                // Buildings (the occluders), kiosks and the ground.
                assert!(y.lods.is_empty(), "{}", y.name);
            }
        }
        assert!(with_levels > 20, "{with_levels}");
        // The geometry (level 0) is the same, object by object.
        let (ga, gb) = (
            load_geometry_bytes(&plain, "plain").unwrap(),
            load_geometry_bytes(&lod, "lod").unwrap(),
        );
        assert_eq!(ga.object_count(), gb.object_count());
        assert_eq!(ga.instances.len(), gb.instances.len());
        for (ia, ib) in ga.instances.iter().zip(&gb.instances) {
            assert_eq!(ia.object, ib.object);
            assert_eq!(ia.transform, ib.transform);
            let (ma, mb) = (&ga.meshes[ia.mesh as usize], &gb.meshes[ib.mesh as usize]);
            assert_eq!(ma.positions, mb.positions);
            assert_eq!(ma.indices, mb.indices);
            assert_eq!(
                ga.materials[ma.material as usize],
                gb.materials[mb.material as usize]
            );
        }
    }

    #[test]
    fn bin_levels_hand_computed() {
        let scene = load_scene_bytes(&city(1, 0.1, true), "lod").unwrap();
        let bin = scene
            .objects
            .iter()
            .find(|o| o.name.starts_with("bin_"))
            .expect("a bin");
        // A 12-sided cylinder of 2 segments with caps (72 triangles), then 6
        // sides (24) and 3 sides (12), one segment each.
        let tris: Vec<u64> = bin.lods.iter().map(|l| l.triangles).collect();
        assert_eq!(tris, [72, 24, 12]);
        // Box 0.6 × 0.9 × 0.6: r = √1.53 / 2 = 0.618466.
        assert!((bin.radius() - 0.618_466).abs() < 1e-5, "{}", bin.radius());
        // Level k's error: r (1 − cos(π/n_k)) + r (1 − cos(π/12)) with
        // r = 0.3: level 1 (n = 6) 0.0504146 m, level 2 (n = 3) 0.160222 m;
        // d_k = e_k · f at 1 px, f = 256 / tan 22.5° = 618.0387 px.
        let f = 618.038_7;
        let r = 0.618_466f64;
        for (k, e) in [(1, 0.050_414_6), (2, 0.160_222_2)] {
            let d: f64 = e * f;
            let coverage = std::f64::consts::PI * f * f * r * r / (d * d - r * r) / 262_144.0;
            let got = bin.lods[k - 1].min_coverage;
            assert!(
                (got / coverage - 1.0).abs() < 1e-4,
                "level {k}: {got} vs {coverage}"
            );
        }
    }

    #[test]
    fn small_city_counts_and_bounds() {
        let glb = city(1, 0.1, false);
        let scene = load_scene_bytes(&glb, "city").unwrap();
        let n = scene.objects.len();
        assert!((350..=900).contains(&n), "{n} objects");
        let tris = scene.total_triangles();
        assert!((500_000..=2_000_000).contains(&tris), "{tris} triangles");
        let (lo, hi) = scene.bounds();
        let [w, d] = city_size(0.1);
        assert!(
            lo.x >= -3.0 && lo.z >= -3.0 && hi.x <= w + 3.0 && hi.z <= d + 3.0,
            "{lo} {hi}"
        );
    }

    #[test]
    fn bad_scale_is_rejected() {
        let error = |p: CityParams| generate(&p).map(|_| ()).unwrap_err().to_string();
        for s in [0.0, -1.0, f64::NAN, 16.5] {
            let e = error(CityParams {
                scale: s,
                ..Default::default()
            });
            assert!(e.contains("--scale"), "{e}");
        }
        for h in [-1.0, f64::INFINITY, 501.0] {
            let e = error(CityParams {
                scale: 0.01,
                hills: h,
                ..Default::default()
            });
            assert!(e.contains("--hills"), "{e}");
        }
    }

    #[test]
    fn hills_lift_every_object_onto_the_ground() {
        let flat = load_scene_bytes(&city(2, 0.05, false), "flat").unwrap();
        let glb = generate(&CityParams {
            seed: 2,
            scale: 0.05,
            hills: 40.0,
            ..Default::default()
        })
        .unwrap();
        let hilly = load_scene_bytes(&glb, "hilly").unwrap();
        assert_eq!(hilly.objects.len(), flat.objects.len());
        let size = city_size(0.05);
        let terrain = Terrain::new(2, size, 40.0);
        let mut lifted = 0;
        for (h, f) in hilly.objects.iter().zip(&flat.objects) {
            // Same footprint, raised by a ground height under it (the
            // lowest point of a building's footprint, the height at any
            // other object's origin).
            assert!((h.min.x - f.min.x).abs() < 1e-3 && (h.min.z - f.min.z).abs() < 1e-3);
            let lift = h.min.y - f.min.y;
            let under = [f.min.x, 0.5 * (f.min.x + f.max.x), f.max.x]
                .into_iter()
                .flat_map(|x| {
                    [f.min.z, 0.5 * (f.min.z + f.max.z), f.max.z].map(|z| terrain.height(x, z))
                });
            let highest = under.fold(0.0, f64::max);
            assert!(lift > 0.0 && lift <= highest + 1e-3, "{}: {lift}", f.name);
            lifted += 1;
        }
        assert!(lifted > 100);
        load_geometry_bytes(&glb, "hilly").unwrap();
    }

    #[test]
    fn full_city_matches_the_papers_size() {
        let glb = generate(&CityParams::default()).unwrap();
        assert_eq!(
            content_fnv(&glb),
            0x30bc_3a5e_4bcc_43e9,
            "unchanged without --lod"
        );
        let scene = load_scene_bytes(&glb, "city").unwrap();
        assert!(scene.objects.len() >= 5000, "{}", scene.objects.len());
        assert!(
            scene.total_triangles() >= 8_000_000,
            "{}",
            scene.total_triangles()
        );
        assert!(glb.len() < 30 << 20, "{} bytes", glb.len());
    }
}
