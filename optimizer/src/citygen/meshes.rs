//! The generator's prototype shapes — buildings, trees, lamps, benches,
//! cars, litter bins, kiosks — built from flat-shaded faces.

use std::f32::consts::{PI, TAU};

use glam::Vec3;

use crate::Result;
use crate::scene::geometry::MeshData;
use crate::scene::glb::{Geometry, GeometryId, GlbBuilder, MeshPrimitive};

/// `v` divided by its length (at least `1e-12`, so that a degenerate face
/// gets a zero normal rather than NaN). glam's `normalize` multiplies by
/// the reciprocal length instead, which rounds differently and would
/// change the normals the generator writes.
fn unit(v: Vec3) -> Vec3 {
    v / v.length().max(1e-12)
}

/// Flat-shaded faces appended to a mesh: every face gets vertices of its
/// own carrying the face's normal, so edges stay sharp.
pub(super) trait FlatFaces {
    /// A planar quad `a b c d` (counter-clockwise seen from its front).
    fn quad(&mut self, a: Vec3, b: Vec3, c: Vec3, d: Vec3);
    /// A triangle `a b c` (counter-clockwise seen from its front).
    fn tri(&mut self, a: Vec3, b: Vec3, c: Vec3);
    /// An axis-aligned box (12 triangles).
    fn cuboid(&mut self, lo: Vec3, hi: Vec3);
    /// A vertical cylinder with `sides` around and `segments` up, capped.
    fn cylinder(&mut self, c: Vec3, r: f32, h: f32, sides: u32, segments: u32);
    /// An ellipsoid of `rings × sides` quads (triangles at the poles).
    fn ellipsoid(&mut self, c: Vec3, r: Vec3, rings: u32, sides: u32);
}

impl FlatFaces for MeshData {
    fn quad(&mut self, a: Vec3, b: Vec3, c: Vec3, d: Vec3) {
        let n = unit((b - a).cross(d - a));
        let base = self.positions.len() as u32;
        for p in [a, b, c, d] {
            self.positions.push(p);
            self.normals.push(n);
        }
        self.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }

    fn tri(&mut self, a: Vec3, b: Vec3, c: Vec3) {
        let n = unit((b - a).cross(c - a));
        let base = self.positions.len() as u32;
        for p in [a, b, c] {
            self.positions.push(p);
            self.normals.push(n);
        }
        self.indices.extend([base, base + 1, base + 2]);
    }

    fn cuboid(&mut self, lo: Vec3, hi: Vec3) {
        let [x0, y0, z0] = lo.to_array();
        let [x1, y1, z1] = hi.to_array();
        let v = Vec3::new;
        self.quad(v(x0, y0, z1), v(x1, y0, z1), v(x1, y1, z1), v(x0, y1, z1)); // +z
        self.quad(v(x1, y0, z0), v(x0, y0, z0), v(x0, y1, z0), v(x1, y1, z0)); // -z
        self.quad(v(x1, y0, z1), v(x1, y0, z0), v(x1, y1, z0), v(x1, y1, z1)); // +x
        self.quad(v(x0, y0, z0), v(x0, y0, z1), v(x0, y1, z1), v(x0, y1, z0)); // -x
        self.quad(v(x0, y1, z1), v(x1, y1, z1), v(x1, y1, z0), v(x0, y1, z0)); // +y
        self.quad(v(x0, y0, z0), v(x1, y0, z0), v(x1, y0, z1), v(x0, y0, z1)); // -y
    }

    fn cylinder(&mut self, c: Vec3, r: f32, h: f32, sides: u32, segments: u32) {
        let p = |i: u32, y: f32| {
            let a = TAU * i as f32 / sides as f32;
            Vec3::new(c.x + r * a.cos(), y, c.z - r * a.sin())
        };
        for s in 0..segments {
            let (y0, y1) = (
                c.y + h * s as f32 / segments as f32,
                c.y + h * (s + 1) as f32 / segments as f32,
            );
            for i in 0..sides {
                self.quad(p(i, y0), p(i + 1, y0), p(i + 1, y1), p(i, y1));
            }
        }
        for i in 0..sides {
            self.tri(
                Vec3::new(c.x, c.y + h, c.z),
                p(i, c.y + h),
                p(i + 1, c.y + h),
            );
            self.tri(c, p(i + 1, c.y), p(i, c.y));
        }
    }

    fn ellipsoid(&mut self, c: Vec3, r: Vec3, rings: u32, sides: u32) {
        let p = |ring: u32, i: u32| {
            let phi = PI * ring as f32 / rings as f32;
            let a = TAU * i as f32 / sides as f32;
            Vec3::new(
                c.x + r.x * phi.sin() * a.cos(),
                c.y + r.y * phi.cos(),
                c.z - r.z * phi.sin() * a.sin(),
            )
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
}

/// Writes a mesh's positions, normals and triangles (its material is the
/// primitive's, not the mesh's) and returns the geometry's handle.
pub(super) fn add_geometry(b: &mut GlbBuilder, m: &MeshData) -> Result<GeometryId> {
    let positions: Vec<[f32; 3]> = m.positions.iter().map(|p| p.to_array()).collect();
    let normals: Vec<[f32; 3]> = m.normals.iter().map(|n| n.to_array()).collect();
    b.add_geometry(&Geometry {
        positions: &positions,
        normals: Some(&normals),
        texcoords: None,
        indices: &m.indices,
    })
}

/// Writes the parts and adds a mesh with one primitive per `(part,
/// material)`; returns the mesh index.
pub(super) fn add_mesh(b: &mut GlbBuilder, name: &str, parts: &[(&MeshData, u32)]) -> Result<u32> {
    let mut primitives = Vec::with_capacity(parts.len());
    for &(part, material) in parts {
        primitives.push(MeshPrimitive {
            geometry: add_geometry(b, part)?,
            material: Some(material),
        });
    }
    b.add_mesh(name, &primitives)
}

/// One facade of a unit building: the plane spanned by `origin + s·right +
/// t·up` for `s, t ∈ [0, 1]`: a wall frame around a grid of window boxes
/// standing out along `out` (the wall plane itself is the building's closed
/// core, see [`building`]).
#[allow(clippy::too_many_arguments)] // a facade is its frame plus its window grid
fn facade(
    m: &mut MeshData,
    origin: Vec3,
    right: Vec3,
    up: Vec3,
    out: Vec3,
    nx: u32,
    ny: u32,
    sills: bool,
) {
    let at = |s: f32, t: f32, depth: f32| origin + right * s + up * t - out * depth;
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
pub(super) fn building(nx: u32, ny: u32, sills: bool, pitched: bool) -> (MeshData, MeshData) {
    let v = Vec3::new;
    let mut walls = MeshData::default();
    let sides = [
        (v(0.0, 0.0, 1.0), v(1.0, 0.0, 0.0), v(0.0, 0.0, 1.0)),
        (v(1.0, 0.0, 0.0), v(-1.0, 0.0, 0.0), v(0.0, 0.0, -1.0)),
        (v(1.0, 0.0, 1.0), v(0.0, 0.0, -1.0), v(1.0, 0.0, 0.0)),
        (v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(-1.0, 0.0, 0.0)),
    ];
    for (origin, right, out) in sides {
        facade(&mut walls, origin, right, Vec3::Y, out, nx, ny, sills);
    }
    walls.cuboid(v(0.0, 0.0, 0.0), v(1.0, 0.97, 1.0));
    let mut roof = MeshData::default();
    roof.cuboid(v(-0.02, 0.97, -0.02), v(1.02, 1.0, 1.02));
    if pitched {
        let (a, b, c, d) = (
            v(0.0, 1.0, 0.0),
            v(1.0, 1.0, 0.0),
            v(1.0, 1.0, 1.0),
            v(0.0, 1.0, 1.0),
        );
        let (r0, r1) = (v(0.0, 1.12, 0.5), v(1.0, 1.12, 0.5));
        roof.quad(d, c, r1, r0);
        roof.quad(b, a, r0, r1);
        roof.tri(a, d, r0);
        roof.tri(c, b, r1);
    }
    (walls, roof)
}

/// Tree crown radii (an ellipsoid).
pub(super) const CROWN: Vec3 = Vec3::new(2.6, 3.0, 2.6);
/// Trunk radius.
pub(super) const TRUNK_R: f32 = 0.25;

/// A tree: its trunk and its crown.
pub(super) fn tree(
    rings: u32,
    sides: u32,
    trunk_sides: u32,
    trunk_segments: u32,
) -> (MeshData, MeshData) {
    let mut trunk = MeshData::default();
    trunk.cylinder(Vec3::ZERO, TRUNK_R, 3.5, trunk_sides, trunk_segments);
    let mut crown = MeshData::default();
    crown.ellipsoid(Vec3::new(0.0, 5.5, 0.0), CROWN, rings, sides);
    (trunk, crown)
}

/// Lamp pole radius.
pub(super) const POLE_R: f32 = 0.09;
/// Lamp head radius.
pub(super) const HEAD_R: f32 = 0.3;

/// A street lamp: its pole (with the arm) and its head.
pub(super) fn lamp(sides: u32, pole_segments: u32, head_segments: u32) -> (MeshData, MeshData) {
    let mut pole = MeshData::default();
    pole.cylinder(Vec3::ZERO, POLE_R, 6.0, sides, pole_segments);
    pole.cuboid(Vec3::new(-0.05, 5.8, -0.05), Vec3::new(1.2, 5.9, 0.05));
    let mut head = MeshData::default();
    head.cylinder(Vec3::new(1.2, 5.4, 0.0), HEAD_R, 0.5, sides, head_segments);
    (pole, head)
}

/// A bench: level 0 has five seat slats, four back slats, two legs and an
/// arm on each side; level 1 merges the slats into one seat slab and one
/// back slab; level 2 is the two slabs alone.
pub(super) fn bench(level: u32) -> MeshData {
    let v = Vec3::new;
    let mut m = MeshData::default();
    if level == 0 {
        for i in 0..5 {
            let z = i as f32 * 0.09;
            m.cuboid(v(0.0, 0.42, z), v(1.8, 0.46, z + 0.07));
        }
        for i in 0..4 {
            let y = 0.55 + i as f32 * 0.11;
            m.cuboid(v(0.0, y, 0.46), v(1.8, y + 0.08, 0.5));
        }
    } else {
        m.cuboid(v(0.0, 0.42, 0.0), v(1.8, 0.46, 0.43));
        m.cuboid(v(0.0, 0.55, 0.46), v(1.8, 0.96, 0.5));
    }
    if level < 2 {
        for x in [0.1, 1.6] {
            m.cuboid(v(x, 0.0, 0.0), v(x + 0.1, 0.42, 0.1));
            m.cuboid(v(x, 0.0, 0.36), v(x + 0.1, 0.95, 0.5));
            m.cuboid(v(x, 0.6, 0.0), v(x + 0.1, 0.66, 0.5));
        }
    }
    m
}

/// Car body radii.
pub(super) const BODY: Vec3 = Vec3::new(2.2, 0.5, 0.9);
/// Car glass radii.
pub(super) const GLASS: Vec3 = Vec3::new(1.2, 0.45, 0.8);
/// Wheel radius.
pub(super) const WHEEL_R: f32 = 0.35;

/// A car: its body, its glass and its wheels.
pub(super) fn car(rings: u32, sides: u32, wheel_segments: u32) -> (MeshData, MeshData, MeshData) {
    let mut body = MeshData::default();
    body.ellipsoid(Vec3::new(0.0, 0.75, 0.0), BODY, rings, sides);
    let mut glass = MeshData::default();
    glass.ellipsoid(Vec3::new(-0.2, 1.2, 0.0), GLASS, rings / 2 + 2, sides);
    let mut wheels = MeshData::default();
    for (x, z) in [(-1.4, 0.8), (1.4, 0.8), (-1.4, -0.8), (1.4, -0.8)] {
        // Wheels as short vertical cylinders lying on their side are not
        // needed for placement; upright discs keep the code simple.
        wheels.cylinder(
            Vec3::new(x, 0.0, z),
            WHEEL_R,
            0.6,
            sides / 2,
            wheel_segments,
        );
    }
    (body, glass, wheels)
}

/// Litter bin radius.
pub(super) const BIN_R: f32 = 0.3;

/// A litter bin.
pub(super) fn bin(sides: u32, segments: u32) -> MeshData {
    let mut m = MeshData::default();
    m.cylinder(Vec3::ZERO, BIN_R, 0.9, sides, segments);
    m
}

/// A kiosk: its walls (with a row of windows in front) and its roof.
pub(super) fn kiosk() -> (MeshData, MeshData) {
    let mut walls = MeshData::default();
    walls.cuboid(Vec3::ZERO, Vec3::new(2.5, 2.6, 2.0));
    facade(
        &mut walls,
        Vec3::new(0.0, 0.3, 2.001),
        Vec3::new(2.5, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::Z,
        3,
        1,
        false,
    );
    let mut roof = MeshData::default();
    roof.cuboid(Vec3::new(-0.2, 2.6, -0.2), Vec3::new(2.7, 2.8, 2.2));
    (walls, roof)
}
