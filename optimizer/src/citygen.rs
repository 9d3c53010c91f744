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

use std::f32::consts::{PI, TAU};

use crate::error::{Error, Result};
use crate::glb::{Geometry, GlbBuilder, Material, Node};
use crate::rng::Rng;

/// Generator parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CityParams {
    /// Seed: the same seed and scale give byte-identical output.
    pub seed: u64,
    /// Fraction of the full city's area, in `(0, 4]`; lengths scale by its
    /// square root.
    pub scale: f64,
}

impl Default for CityParams {
    fn default() -> Self {
        CityParams {
            seed: 1,
            scale: 1.0,
        }
    }
}

/// Width (x) and depth (z) of the city for a scale, metres.
pub fn city_size(scale: f64) -> [f64; 2] {
    let k = scale.sqrt();
    [1500.0 * k, 1000.0 * k]
}

/// A triangle mesh under construction: flat-shaded faces.
#[derive(Default)]
struct MeshData {
    positions: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    indices: Vec<u32>,
}

type V3 = [f32; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: V3) -> V3 {
    let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(1e-12);
    [a[0] / l, a[1] / l, a[2] / l]
}

impl MeshData {
    /// A planar quad `a b c d` (counter-clockwise seen from its front).
    fn quad(&mut self, a: V3, b: V3, c: V3, d: V3) {
        let n = normalize(cross(sub(b, a), sub(d, a)));
        let base = self.positions.len() as u32;
        for p in [a, b, c, d] {
            self.positions.push(p);
            self.normals.push(n);
        }
        self.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    fn tri(&mut self, a: V3, b: V3, c: V3) {
        let n = normalize(cross(sub(b, a), sub(c, a)));
        let base = self.positions.len() as u32;
        for p in [a, b, c] {
            self.positions.push(p);
            self.normals.push(n);
        }
        self.indices.extend([base, base + 1, base + 2]);
    }

    /// An axis-aligned box (12 triangles).
    fn cuboid(&mut self, lo: V3, hi: V3) {
        let [x0, y0, z0] = lo;
        let [x1, y1, z1] = hi;
        self.quad([x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]); // +z
        self.quad([x1, y0, z0], [x0, y0, z0], [x0, y1, z0], [x1, y1, z0]); // -z
        self.quad([x1, y0, z1], [x1, y0, z0], [x1, y1, z0], [x1, y1, z1]); // +x
        self.quad([x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]); // -x
        self.quad([x0, y1, z1], [x1, y1, z1], [x1, y1, z0], [x0, y1, z0]); // +y
        self.quad([x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]); // -y
    }

    /// A vertical cylinder with `sides` around and `segments` up, capped.
    fn cylinder(&mut self, c: V3, r: f32, h: f32, sides: u32, segments: u32) {
        let p = |i: u32, y: f32| {
            let a = TAU * i as f32 / sides as f32;
            [c[0] + r * a.cos(), y, c[2] - r * a.sin()]
        };
        for s in 0..segments {
            let (y0, y1) = (
                c[1] + h * s as f32 / segments as f32,
                c[1] + h * (s + 1) as f32 / segments as f32,
            );
            for i in 0..sides {
                self.quad(p(i, y0), p(i + 1, y0), p(i + 1, y1), p(i, y1));
            }
        }
        for i in 0..sides {
            self.tri([c[0], c[1] + h, c[2]], p(i, c[1] + h), p(i + 1, c[1] + h));
            self.tri([c[0], c[1], c[2]], p(i + 1, c[1]), p(i, c[1]));
        }
    }

    /// An ellipsoid of `rings × sides` quads.
    fn ellipsoid(&mut self, c: V3, r: V3, rings: u32, sides: u32) {
        let p = |ring: u32, i: u32| {
            let phi = PI * ring as f32 / rings as f32;
            let a = TAU * i as f32 / sides as f32;
            [
                c[0] + r[0] * phi.sin() * a.cos(),
                c[1] + r[1] * phi.cos(),
                c[2] - r[2] * phi.sin() * a.sin(),
            ]
        };
        for ring in 0..rings {
            for i in 0..sides {
                let (a, b, cc, d) = (
                    p(ring + 1, i),
                    p(ring + 1, i + 1),
                    p(ring, i + 1),
                    p(ring, i),
                );
                if ring == 0 {
                    self.tri(a, b, cc);
                } else if ring + 1 == rings {
                    self.tri(a, cc, d);
                } else {
                    self.quad(a, b, cc, d);
                }
            }
        }
    }

    fn geometry(&self) -> Geometry<'_> {
        Geometry {
            positions: &self.positions,
            normals: Some(&self.normals),
            texcoords: None,
            indices: &self.indices,
        }
    }
}

/// One facade of a unit building: the plane spanned by `origin + s·right +
/// t·up` for `s, t ∈ [0, 1]`: a wall frame around a grid of window boxes
/// standing out along `out` (the wall plane itself is the building's closed
/// core, see [`building`]).
#[allow(clippy::too_many_arguments)] // a facade is its frame plus its window grid
fn facade(m: &mut MeshData, origin: V3, right: V3, up: V3, out: V3, nx: u32, ny: u32, sills: bool) {
    let at = |s: f32, t: f32, depth: f32| {
        [
            origin[0] + right[0] * s + up[0] * t - out[0] * depth,
            origin[1] + right[1] * s + up[1] * t - out[1] * depth,
            origin[2] + right[2] * s + up[2] * t - out[2] * depth,
        ]
    };
    // Negative depth is in front of the wall: panes stand out by 0.01.
    let inset = -0.01;
    for iy in 0..ny {
        for ix in 0..nx {
            let (s0, s1) = (ix as f32 / nx as f32, (ix + 1) as f32 / nx as f32);
            let (t0, t1) = (iy as f32 / ny as f32, (iy + 1) as f32 / ny as f32);
            let (ws, wt) = ((s1 - s0) * 0.25, (t1 - t0) * 0.22);
            let (a0, a1, b0, b1) = (s0 + ws, s1 - ws, t0 + wt, t1 - wt);
            // Wall around the window.
            m.quad(
                at(s0, t0, 0.0),
                at(a0, t0, 0.0),
                at(a0, t1, 0.0),
                at(s0, t1, 0.0),
            );
            m.quad(
                at(a1, t0, 0.0),
                at(s1, t0, 0.0),
                at(s1, t1, 0.0),
                at(a1, t1, 0.0),
            );
            m.quad(
                at(a0, t0, 0.0),
                at(a1, t0, 0.0),
                at(a1, b0, 0.0),
                at(a0, b0, 0.0),
            );
            m.quad(
                at(a0, b1, 0.0),
                at(a1, b1, 0.0),
                at(a1, t1, 0.0),
                at(a0, t1, 0.0),
            );
            // The pane standing out of the wall and its four sides.
            m.quad(
                at(a0, b0, inset),
                at(a1, b0, inset),
                at(a1, b1, inset),
                at(a0, b1, inset),
            );
            m.quad(
                at(a0, b0, 0.0),
                at(a0, b0, inset),
                at(a0, b1, inset),
                at(a0, b1, 0.0),
            );
            m.quad(
                at(a1, b0, inset),
                at(a1, b0, 0.0),
                at(a1, b1, 0.0),
                at(a1, b1, inset),
            );
            m.quad(
                at(a0, b0, inset),
                at(a0, b0, 0.0),
                at(a1, b0, 0.0),
                at(a1, b0, inset),
            );
            m.quad(
                at(a0, b1, 0.0),
                at(a0, b1, inset),
                at(a1, b1, inset),
                at(a1, b1, 0.0),
            );
            if sills {
                // A sill: a thin slab standing out below the window.
                let h = (t1 - t0) * 0.04;
                m.quad(
                    at(a0, b0 - h, -0.015),
                    at(a1, b0 - h, -0.015),
                    at(a1, b0, -0.015),
                    at(a0, b0, -0.015),
                );
                m.quad(
                    at(a0, b0, -0.015),
                    at(a1, b0, -0.015),
                    at(a1, b0, 0.0),
                    at(a0, b0, 0.0),
                );
                m.quad(
                    at(a0, b0 - h, 0.0),
                    at(a1, b0 - h, 0.0),
                    at(a1, b0 - h, -0.015),
                    at(a0, b0 - h, -0.015),
                );
            }
        }
    }
}

/// A unit building prototype (footprint `[0,1]²`, height 1): a closed core
/// box (the building's solid volume, as in CityGML LOD1 solids), facades with
/// a window grid on all four sides, and a roof with a cornice. The facade's
/// wall frame lies in the core's side planes with the same material and
/// normals, so the two draw identically; the closed core is what makes the
/// building usable as a conservative occluder (`crate::visibility`).
fn building(nx: u32, ny: u32, sills: bool, pitched: bool) -> (MeshData, MeshData) {
    let mut walls = MeshData::default();
    facade(
        &mut walls,
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        nx,
        ny,
        sills,
    );
    facade(
        &mut walls,
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, -1.0],
        nx,
        ny,
        sills,
    );
    facade(
        &mut walls,
        [1.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        nx,
        ny,
        sills,
    );
    facade(
        &mut walls,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 1.0, 0.0],
        [-1.0, 0.0, 0.0],
        nx,
        ny,
        sills,
    );
    walls.cuboid([0.0, 0.0, 0.0], [1.0, 0.97, 1.0]);
    let mut roof = MeshData::default();
    roof.cuboid([-0.02, 0.97, -0.02], [1.02, 1.0, 1.02]);
    if pitched {
        let (a, b, c, d) = (
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        );
        let (r0, r1) = ([0.0, 1.12, 0.5], [1.0, 1.12, 0.5]);
        roof.quad(d, c, r1, r0);
        roof.quad(b, a, r0, r1);
        roof.tri(a, d, r0);
        roof.tri(c, b, r1);
    }
    (walls, roof)
}

fn tree(rings: u32, sides: u32) -> (MeshData, MeshData) {
    let mut trunk = MeshData::default();
    trunk.cylinder([0.0, 0.0, 0.0], 0.25, 3.5, 8, 4);
    let mut crown = MeshData::default();
    crown.ellipsoid([0.0, 5.5, 0.0], [2.6, 3.0, 2.6], rings, sides);
    (trunk, crown)
}

fn lamp(sides: u32) -> (MeshData, MeshData) {
    let mut pole = MeshData::default();
    pole.cylinder([0.0, 0.0, 0.0], 0.09, 6.0, sides, 10);
    pole.cuboid([-0.05, 5.8, -0.05], [1.2, 5.9, 0.05]);
    let mut head = MeshData::default();
    head.cylinder([1.2, 5.4, 0.0], 0.3, 0.5, sides, 3);
    (pole, head)
}

fn bench() -> MeshData {
    let mut m = MeshData::default();
    for i in 0..5 {
        let z = i as f32 * 0.09;
        m.cuboid([0.0, 0.42, z], [1.8, 0.46, z + 0.07]);
    }
    for i in 0..4 {
        let y = 0.55 + i as f32 * 0.11;
        m.cuboid([0.0, y, 0.46], [1.8, y + 0.08, 0.5]);
    }
    for x in [0.1, 1.6] {
        m.cuboid([x, 0.0, 0.0], [x + 0.1, 0.42, 0.1]);
        m.cuboid([x, 0.0, 0.36], [x + 0.1, 0.95, 0.5]);
        m.cuboid([x, 0.6, 0.0], [x + 0.1, 0.66, 0.5]);
    }
    m
}

fn car(rings: u32, sides: u32) -> (MeshData, MeshData, MeshData) {
    let mut body = MeshData::default();
    body.ellipsoid([0.0, 0.75, 0.0], [2.2, 0.5, 0.9], rings, sides);
    let mut glass = MeshData::default();
    glass.ellipsoid([-0.2, 1.2, 0.0], [1.2, 0.45, 0.8], rings / 2 + 2, sides);
    let mut wheels = MeshData::default();
    for (x, z) in [(-1.4, 0.8), (1.4, 0.8), (-1.4, -0.8), (1.4, -0.8)] {
        // Wheels as short vertical cylinders lying on their side are not
        // needed for placement; upright discs keep the code simple.
        wheels.cylinder([x, 0.0, z], 0.35, 0.6, sides / 2, 2);
    }
    (body, glass, wheels)
}

fn kiosk() -> (MeshData, MeshData) {
    let mut walls = MeshData::default();
    walls.cuboid([0.0, 0.0, 0.0], [2.5, 2.6, 2.0]);
    facade(
        &mut walls,
        [0.0, 0.3, 2.001],
        [2.5, 0.0, 0.0],
        [0.0, 2.0, 0.0],
        [0.0, 0.0, 1.0],
        3,
        1,
        false,
    );
    let mut roof = MeshData::default();
    roof.cuboid([-0.2, 2.6, -0.2], [2.7, 2.8, 2.2]);
    (walls, roof)
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
}

fn prototypes(b: &mut GlbBuilder, rng: &mut Rng, size: [f64; 2]) -> Result<Prototypes> {
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
        buildings.push(b.add_mesh_from(
            &format!("building_proto_{i}"),
            &[(walls.geometry(), Some(fm)), (roof.geometry(), Some(rm))],
        )?);
    }
    let mut trees = Vec::new();
    for (i, (r, s)) in [(16, 32), (24, 40), (28, 56)].into_iter().enumerate() {
        let (trunk, crown) = tree(r, s);
        trees.push(b.add_mesh_from(
            &format!("tree_proto_{i}"),
            &[
                (trunk.geometry(), Some(bark)),
                (crown.geometry(), Some(leaves)),
            ],
        )?);
    }
    let mut lamps = Vec::new();
    for (i, s) in [10u32, 14].into_iter().enumerate() {
        let (pole, head) = lamp(s);
        lamps.push(b.add_mesh_from(
            &format!("lamp_proto_{i}"),
            &[
                (pole.geometry(), Some(metal)),
                (head.geometry(), Some(light)),
            ],
        )?);
    }
    let benches = vec![b.add_mesh_from("bench_proto", &[(bench().geometry(), Some(wood))])?];
    let mut cars = Vec::new();
    for (i, (r, s)) in [(10u32, 24u32), (14, 32), (18, 40)].into_iter().enumerate() {
        for (j, &paint) in paints.iter().enumerate().take(2 + i) {
            let (body, win, wheels) = car(r, s);
            cars.push(b.add_mesh_from(
                &format!("car_proto_{i}_{j}"),
                &[
                    (body.geometry(), Some(paint)),
                    (win.geometry(), Some(glass)),
                    (wheels.geometry(), Some(tyre)),
                ],
            )?);
        }
    }
    let (kw, kr) = kiosk();
    let kiosks = vec![b.add_mesh_from(
        "kiosk_proto",
        &[
            (kw.geometry(), Some(facades[4])),
            (kr.geometry(), Some(metal)),
        ],
    )?];
    let mut bin = MeshData::default();
    bin.cylinder([0.0, 0.0, 0.0], 0.3, 0.9, 12, 2);
    let bins = vec![b.add_mesh_from("bin_proto", &[(bin.geometry(), Some(metal))])?];
    let mut g = MeshData::default();
    g.cuboid([0.0, -0.2, 0.0], [size[0] as f32, 0.0, size[1] as f32]);
    let ground = b.add_mesh_from("ground", &[(g.geometry(), Some(asphalt))])?;
    Ok(Prototypes {
        buildings,
        trees,
        lamps,
        benches,
        cars,
        kiosks,
        bins,
        ground,
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

struct Placer<'a> {
    b: &'a mut GlbBuilder,
    roots: Vec<u32>,
    counter: std::collections::BTreeMap<&'static str, u32>,
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
        let id = self.b.add_node(Node::new(name).with_mesh(mesh).with_trs(
            [t[0] as f32, t[1] as f32, t[2] as f32],
            yaw(rot),
            scale,
        ))?;
        self.roots.push(id);
        Ok(())
    }
}

/// Generates the city as GLB bytes.
pub fn generate(params: &CityParams) -> Result<Vec<u8>> {
    let scale = params.scale;
    if !(scale.is_finite() && scale > 0.0 && scale <= 4.0) {
        return Err(Error::bad("--scale", format!("{scale} must be in (0, 4]")));
    }
    let size = city_size(scale);
    let mut rng = Rng::new(params.seed);
    let mut b = GlbBuilder::new();
    let protos = prototypes(&mut b, &mut rng, size)?;
    let (xblocks, xstreets) = blocks_along(&mut rng, size[0]);
    let (zblocks, zstreets) = blocks_along(&mut rng, size[1]);
    let mut p = Placer {
        b: &mut b,
        roots: Vec::new(),
        counter: Default::default(),
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
    use crate::gltf_load::load_scene_bytes;

    #[test]
    fn deterministic_and_seed_dependent() {
        let a = generate(&CityParams {
            seed: 3,
            scale: 0.05,
        })
        .unwrap();
        let b = generate(&CityParams {
            seed: 3,
            scale: 0.05,
        })
        .unwrap();
        let c = generate(&CityParams {
            seed: 4,
            scale: 0.05,
        })
        .unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn small_city_counts_and_bounds() {
        let glb = generate(&CityParams {
            seed: 1,
            scale: 0.1,
        })
        .unwrap();
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
        for s in [0.0, -1.0, f64::NAN, 5.0] {
            let e = generate(&CityParams { seed: 1, scale: s })
                .unwrap_err()
                .to_string();
            assert!(e.contains("--scale"), "{e}");
        }
    }

    #[test]
    fn full_city_matches_the_papers_size() {
        let glb = generate(&CityParams::default()).unwrap();
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
