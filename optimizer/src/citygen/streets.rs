//! Levels of detail of the street prototypes (trees, lamps, benches, cars,
//! litter bins): the coarser versions of each, the bound on their distance
//! from full detail, and the screen coverages at which they switch.

use glam::{DVec3, Vec3};

use super::meshes::{
    BIN_R, BODY, CROWN, FlatFaces, GLASS, HEAD_R, POLE_R, TRUNK_R, WHEEL_R, bench, bin, car, lamp,
    tree,
};
use crate::scene::geometry::MeshData;

/// One level of a street prototype: the arguments of its prototype function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Street {
    Tree {
        rings: u32,
        sides: u32,
        trunk_sides: u32,
        trunk_segments: u32,
    },
    Lamp {
        sides: u32,
        pole_segments: u32,
        head_segments: u32,
    },
    Bench {
        level: u32,
    },
    Car {
        rings: u32,
        sides: u32,
        wheel_segments: u32,
    },
    Bin {
        sides: u32,
        segments: u32,
    },
}

/// A bound on the distance between a `rings × sides` tessellation of an
/// ellipsoid of radii `r` and the ellipsoid, both ways. Before the scaling
/// `A = diag(r)` every face is a planar polygon inscribed in the unit sphere
/// at distance `h` from the centre. A point `p` of a face and its radial
/// projection `p/|p|` on the sphere map to points `(1/|p| − 1)·|A p| ≤
/// (1/h − 1)·max_v |A v|` apart (`v` the face's vertices, `|p| ≥ h`); a
/// point `q` of the sphere and the face point `p` in its direction, likewise.
/// They are also at most `(1 − h)·max(r)` apart (`A` stretches distances
/// by at most `max(r)`). The bound is the largest over the faces of the
/// smaller of the two.
fn ellipsoid_chord(r: Vec3, rings: u32, sides: u32) -> f64 {
    let mut unit = MeshData::default();
    unit.ellipsoid(Vec3::ZERO, Vec3::ONE, rings, sides);
    let radii = r.as_dvec3();
    let p = |i: u32| unit.positions[i as usize].as_dvec3();
    unit.indices
        .chunks_exact(3)
        .map(|t| {
            let v = [p(t[0]), p(t[1]), p(t[2])];
            let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero();
            let h = n.dot(v[0]).abs();
            let far = v.iter().map(|v| (*v * radii).length()).fold(0.0, f64::max);
            let stretched = if h > 1e-9 { (1.0 / h - 1.0) * far } else { far };
            stretched.min((1.0 - h) * radii.max_element())
        })
        .fold(0.0, f64::max)
}

/// Largest distance of a regular `sides`-gon inscribed in a circle of
/// radius `r` from the circle (the sagitta); a straight cylinder's segments
/// add none.
fn circle_chord(r: f32, sides: u32) -> f64 {
    f64::from(r) * (1.0 - (std::f64::consts::PI / f64::from(sides)).cos())
}

impl Street {
    /// The two coarser levels of a full-detail prototype: fewer rings and
    /// sides, one segment per straight cylinder; merged, then fewer boxes
    /// for the bench.
    pub(super) fn coarser(self) -> [Street; 2] {
        match self {
            Street::Tree { rings, sides, .. } => [
                Street::Tree {
                    rings: rings / 2,
                    sides: sides * 3 / 8,
                    trunk_sides: 6,
                    trunk_segments: 1,
                },
                Street::Tree {
                    rings: rings / 4,
                    sides: sides * 3 / 16,
                    trunk_sides: 4,
                    trunk_segments: 1,
                },
            ],
            Street::Lamp { .. } => [6, 3].map(|sides| Street::Lamp {
                sides,
                pole_segments: 1,
                head_segments: 1,
            }),
            Street::Bench { .. } => [1, 2].map(|level| Street::Bench { level }),
            Street::Car { rings, sides, .. } => [
                Street::Car {
                    rings: (rings / 2).max(3),
                    sides: sides / 2,
                    wheel_segments: 1,
                },
                Street::Car {
                    rings: (rings / 4).max(3),
                    sides: sides / 4,
                    wheel_segments: 1,
                },
            ],
            Street::Bin { .. } => [6, 3].map(|sides| Street::Bin { sides, segments: 1 }),
        }
    }

    /// The parts, one per primitive, in the prototype's primitive order.
    pub(super) fn parts(self) -> Vec<MeshData> {
        match self {
            Street::Tree {
                rings,
                sides,
                trunk_sides,
                trunk_segments,
            } => {
                let (trunk, crown) = tree(rings, sides, trunk_sides, trunk_segments);
                vec![trunk, crown]
            }
            Street::Lamp {
                sides,
                pole_segments,
                head_segments,
            } => {
                let (pole, head) = lamp(sides, pole_segments, head_segments);
                vec![pole, head]
            }
            Street::Bench { level } => vec![bench(level)],
            Street::Car {
                rings,
                sides,
                wheel_segments,
            } => {
                let (body, glass, wheels) = car(rings, sides, wheel_segments);
                vec![body, glass, wheels]
            }
            Street::Bin { sides, segments } => vec![bin(sides, segments)],
        }
    }

    /// Per part: the largest distance of the part's surface from the smooth
    /// surface it approximates (local metres; boxes are exact). For the
    /// bench, whose levels remove boxes, the bound on the distance to level
    /// 0 instead: level 1's slabs lie within 0.02 m (half a slab's
    /// thickness) of the slats, and level 2 also drops the legs and arms,
    /// whose farthest points (the feet) are 0.43 m from the seat slab.
    pub(super) fn chords(self) -> Vec<f64> {
        match self {
            Street::Tree {
                rings,
                sides,
                trunk_sides,
                ..
            } => vec![
                circle_chord(TRUNK_R, trunk_sides),
                ellipsoid_chord(CROWN, rings, sides),
            ],
            Street::Lamp { sides, .. } => {
                vec![circle_chord(POLE_R, sides), circle_chord(HEAD_R, sides)]
            }
            Street::Bench { level } => vec![[0.0, 0.02, 0.45][level.min(2) as usize]],
            Street::Car { rings, sides, .. } => vec![
                ellipsoid_chord(BODY, rings, sides),
                ellipsoid_chord(GLASS, rings / 2 + 2, sides),
                circle_chord(WHEEL_R, sides / 2),
            ],
            Street::Bin { sides, .. } => vec![circle_chord(BIN_R, sides)],
        }
    }

    /// A bound on the distance between this level's surface and the
    /// full-detail level's (local metres): per part, both lie within their
    /// chords of the same smooth surface, so within the sum; the largest
    /// over the parts.
    pub(super) fn error_from(self, full: Street) -> f64 {
        self.chords()
            .iter()
            .zip(full.chords())
            .map(|(a, b)| a + b)
            .fold(0.0, f64::max)
    }
}

/// Focal length of the default camera (512 px high, 45° vertical field of
/// view), pixels: the camera the generated screen coverages assume.
fn default_focal_px() -> f64 {
    256.0 / 22.5f64.to_radians().tan()
}

/// Screen area of the default camera (512 × 512), pixels.
const SCREEN_PX: f64 = 512.0 * 512.0;

/// Largest projected geometric error of a level where it is drawn, pixels.
const LOD_ERROR_PX: f64 = 1.0;

/// The levels of detail of one street prototype mesh.
#[derive(Clone, Debug)]
pub(super) struct ProtoLod {
    /// Meshes of levels 1 and 2.
    pub(super) meshes: [u32; 2],
    /// Errors of levels 1 and 2 against level 0, local metres.
    pub(super) errors: [f64; 2],
    /// Local bounding box of level 0 (every level lies within it): minimum.
    pub(super) lo: [f64; 3],
    /// Local bounding box of level 0: maximum.
    pub(super) hi: [f64; 3],
}

impl ProtoLod {
    /// `MSFT_screencoverage` of an instance rotated by `rot` about +y and
    /// scaled by `scale`: level `k` (`k = 1, 2`) may be drawn from the
    /// distance where its error, scaled to the instance, projects to
    /// [`LOD_ERROR_PX`] (`d_k = e_k · f / ε`), so level `k − 1`'s threshold is
    /// the coverage of the instance's bounding sphere (the circumsphere of
    /// its world box, as the loader computes it) at `d_k`; level 2 is never
    /// culled (0).
    pub(super) fn screen_coverage(&self, rot: f32, scale: [f32; 3]) -> [f64; 3] {
        let (sin, cos) = f64::from(rot).sin_cos();
        let s = scale.map(f64::from);
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for corner in 0..8 {
            let pick = |axis: usize| {
                if corner >> axis & 1 == 0 {
                    self.lo[axis]
                } else {
                    self.hi[axis]
                }
            };
            let (x, y, z) = (pick(0) * s[0], pick(1) * s[1], pick(2) * s[2]);
            let w = DVec3::new(x * cos + z * sin, y, -x * sin + z * cos);
            lo = lo.min(w);
            hi = hi.max(w);
        }
        let radius = (hi - lo).length() * 0.5;
        let grow = s.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let f = default_focal_px();
        let coverage = |e: f64| {
            let d = e * grow * f / LOD_ERROR_PX;
            crate::math::geom::projected_area_px(radius, d, f, SCREEN_PX) / SCREEN_PX
        };
        [coverage(self.errors[0]), coverage(self.errors[1]), 0.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use DVec3;

    /// Closest distance from `p` to triangle `abc` (Ericson, Real-Time
    /// Collision Detection, 5.1.5).
    fn point_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
        let (ab, ac, ap) = (b - a, c - a, p - a);
        let (d1, d2) = (ab.dot(ap), ac.dot(ap));
        if d1 <= 0.0 && d2 <= 0.0 {
            return (p - a).length();
        }
        let bp = p - b;
        let (d3, d4) = (ab.dot(bp), ac.dot(bp));
        if d3 >= 0.0 && d4 <= d3 {
            return (p - b).length();
        }
        let vc = d1 * d4 - d3 * d2;
        if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
            return (p - (a + ab * (d1 / (d1 - d3)))).length();
        }
        let cp = p - c;
        let (d5, d6) = (ab.dot(cp), ac.dot(cp));
        if d6 >= 0.0 && d5 <= d6 {
            return (p - c).length();
        }
        let vb = d5 * d2 - d1 * d6;
        if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
            return (p - (a + ac * (d2 / (d2 - d6)))).length();
        }
        let va = d3 * d6 - d5 * d4;
        if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
            let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
            return (p - (b + (c - b) * w)).length();
        }
        let denom = 1.0 / (va + vb + vc);
        let (v, w) = (vb * denom, vc * denom);
        (p - (a + ab * v + ac * w)).length()
    }

    fn triangles(parts: &[MeshData]) -> Vec<[DVec3; 3]> {
        parts
            .iter()
            .flat_map(|m| {
                m.indices
                    .chunks_exact(3)
                    .map(|t| [0, 1, 2].map(|k| m.positions[t[k] as usize].as_dvec3()))
            })
            .collect()
    }

    /// Largest distance from sample points of `from` (corners, edge thirds,
    /// centroids) to the surface `to`.
    fn one_sided(from: &[[DVec3; 3]], to: &[[DVec3; 3]]) -> f64 {
        let mut worst = 0.0f64;
        for t in from {
            for (i, j) in [
                (0, 0),
                (3, 0),
                (0, 3),
                (1, 1),
                (2, 1),
                (1, 2),
                (2, 0),
                (0, 2),
            ] {
                let (u, v) = (f64::from(i) / 3.0, f64::from(j) / 3.0);
                let p = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                let d = to
                    .iter()
                    .map(|s| point_triangle(p, s[0], s[1], s[2]))
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(d);
            }
        }
        worst
    }

    #[test]
    fn level_errors_bound_the_distance_to_full_detail() {
        let fulls = [
            Street::Tree {
                rings: 16,
                sides: 32,
                trunk_sides: 8,
                trunk_segments: 4,
            },
            Street::Tree {
                rings: 28,
                sides: 56,
                trunk_sides: 8,
                trunk_segments: 4,
            },
            Street::Lamp {
                sides: 14,
                pole_segments: 10,
                head_segments: 3,
            },
            Street::Bench { level: 0 },
            Street::Car {
                rings: 10,
                sides: 24,
                wheel_segments: 2,
            },
            Street::Car {
                rings: 18,
                sides: 40,
                wheel_segments: 2,
            },
            Street::Bin {
                sides: 12,
                segments: 2,
            },
        ];
        for full in fulls {
            let f = triangles(&full.parts());
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for p in f.iter().flatten() {
                (lo, hi) = (lo.min(*p), hi.max(*p));
            }
            let mut last = 0.0;
            for level in full.coarser() {
                let e = level.error_from(full);
                assert!(e > last, "{level:?}: errors grow");
                last = e;
                let l = triangles(&level.parts());
                assert!(l.len() < f.len());
                // Every level lies within the full level's box.
                for p in l.iter().flatten() {
                    assert!(p.cmpge(lo).all() && p.cmple(hi).all(), "{level:?} {p}");
                }
                // The error bounds the distance both ways, and is not
                // loose by more than a factor 3.
                let measured = one_sided(&l, &f).max(one_sided(&f, &l));
                assert!(measured <= e + 1e-5, "{level:?}: {measured} > {e}");
                assert!(measured >= e / 3.0, "{level:?}: {measured} ≪ {e}");
            }
        }
    }
}
