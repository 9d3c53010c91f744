//! The impostor model (DESIGN §2.5): view cells (shafts and boxes), layer
//! count, texture resolution and memory of layered impostors.
//!
//! Pixel angle `θ = 2·tan(fovy/2)/H`, error budget `ε` pixels, cluster sphere
//! `(c, R)`:
//! - shaft `(c, u, α, d_min)`: `n = max(1, ceil(R·sin α / (ε·θ·d_min)))`;
//! - box `B` (disjoint from the cluster), reference point its centre, `r` its
//!   half-diagonal, `z_n, z_f = |c − ref| ∓ R`:
//!   `n = max(1, ceil(r·(1/z_n − 1/z_f) / (2·ε·θ)))`;
//! - resolution `ceil(2R / (θ·(d_min − R)))` texels per side per layer, with
//!   `d_min` the closest distance from the view cell to `c`, clamped to
//!   `[4, max_res]`; a cell that needs more than `max_res` is invalid;
//! - memory `n · res² · bytes_per_texel · (4/3 with mipmaps)`.

use glam::DVec3;

use crate::api::job::Job;
use crate::api::placement::ViewCellJson;
use crate::math::geom::{Aabb, Cone, Sphere};

/// Most layers an impostor may have; more means the view cell is far too
/// close for a layered impostor to be worth its memory.
pub const MAX_LAYERS: u32 = 1024;

/// The region of viewpoints an impostor is valid for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ViewCell {
    /// `{v : |v − apex| ≥ min_distance, ∠(v − apex, axis) ≤ half_angle}`.
    Shaft {
        /// The cluster centre.
        apex: DVec3,
        /// Unit axis.
        axis: DVec3,
        /// Half the apex angle, radians (at most 90°).
        half_angle: f64,
        /// Minimum distance from the apex, metres.
        min_distance: f64,
    },
    /// A box of the 3D view space hierarchy.
    Box(Aabb),
}

impl ViewCell {
    /// True when every point of `b` lies in the view cell.
    pub fn contains_box(&self, b: &Aabb) -> bool {
        match *self {
            ViewCell::Box(cell) => cell.contains_box(b),
            ViewCell::Shaft {
                apex,
                axis,
                half_angle,
                min_distance,
            } => {
                // The cone of half-angle ≤ 90° is convex: corners inside ⇒ box
                // inside; the box must also avoid the ball of radius d_min.
                if b.distance_to_point(apex) < min_distance {
                    return false;
                }
                let cos = half_angle.cos() - 1e-12;
                b.corners().iter().all(|&p| {
                    let d = p - apex;
                    d.dot(axis) >= cos * d.length()
                })
            }
        }
    }

    /// False only when `b` certainly does not meet the view cell (a cheap,
    /// conservative pruning test).
    pub fn may_intersect_box(&self, b: &Aabb) -> bool {
        match *self {
            ViewCell::Box(cell) => cell.min.cmple(b.max).all() && b.min.cmple(cell.max).all(),
            ViewCell::Shaft {
                apex,
                axis,
                half_angle,
                min_distance,
            } => {
                b.max_distance_to_point(apex) >= min_distance
                    && Cone::new(apex, axis, half_angle)
                        .intersects_sphere(b.center(), b.half_diagonal())
            }
        }
    }

    /// True when the point lies in the view cell.
    pub fn contains_point(&self, p: DVec3) -> bool {
        self.contains_box(&Aabb::new(p, p))
    }

    /// Closest distance from the view cell to `c`.
    pub fn closest_distance(&self, c: DVec3) -> f64 {
        match *self {
            ViewCell::Box(b) => b.distance_to_point(c),
            ViewCell::Shaft { min_distance, .. } => min_distance,
        }
    }
}

impl From<&ViewCell> for ViewCellJson {
    /// The placement JSON of a view cell (angles in degrees).
    fn from(cell: &ViewCell) -> ViewCellJson {
        match *cell {
            ViewCell::Shaft {
                apex,
                axis,
                half_angle,
                min_distance,
            } => ViewCellJson::Shaft {
                apex: apex.to_array(),
                axis: axis.to_array(),
                half_angle_deg: half_angle.to_degrees(),
                min_distance,
            },
            ViewCell::Box(b) => ViewCellJson::Box {
                min: b.min.to_array(),
                max: b.max.to_array(),
            },
        }
    }
}

impl From<&ViewCellJson> for ViewCell {
    /// The view cell of a placement's JSON (its axis normalised; check it
    /// first with [`crate::api::placement::PlacedImpostor::check_view_cell`]).
    fn from(cell: &ViewCellJson) -> ViewCell {
        match *cell {
            ViewCellJson::Shaft {
                apex,
                axis,
                half_angle_deg,
                min_distance,
            } => ViewCell::Shaft {
                apex: DVec3::from_array(apex),
                axis: DVec3::from_array(axis).normalize_or_zero(),
                half_angle: half_angle_deg.to_radians(),
                min_distance,
            },
            ViewCellJson::Box { min, max } => {
                ViewCell::Box(Aabb::new(DVec3::from_array(min), DVec3::from_array(max)))
            }
        }
    }
}

/// Layers, resolution and memory of one impostor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpostorSpec {
    /// Number of layers.
    pub layers: u32,
    /// Texels per side of each layer.
    pub resolution: u32,
    /// Texture memory, bytes.
    pub memory_bytes: u64,
}

/// The impostor model of a job.
#[derive(Clone, Copy, Debug)]
pub struct ImpostorModel {
    /// Pixel angle θ, radians.
    pub theta: f64,
    /// Error budget ε, pixels.
    pub eps: f64,
    /// Bytes per texel, including the mip chain factor.
    pub bytes_per_texel: f64,
    /// Largest texture side.
    pub max_res: u32,
}

impl ImpostorModel {
    /// The model of `job`.
    pub fn new(job: &Job) -> Self {
        let m = &job.memory;
        ImpostorModel {
            theta: job.pixel_angle(),
            eps: job.max_error_px,
            bytes_per_texel: m.bytes_per_texel * if m.mipmaps { 4.0 / 3.0 } else { 1.0 },
            max_res: m.max_texture_size,
        }
    }

    /// Texture resolution for a cluster of radius `r` seen no closer than
    /// `d_min`, or `None` when it exceeds the maximum texture size.
    pub fn resolution(&self, r: f64, d_min: f64) -> Option<u32> {
        if d_min <= r {
            return None;
        }
        let res = (2.0 * r / (self.theta * (d_min - r))).ceil();
        if !res.is_finite() || res > f64::from(self.max_res) {
            return None;
        }
        Some((res as u32).max(4))
    }

    fn spec(&self, layers: f64, res: u32) -> Option<ImpostorSpec> {
        let layers = layers.max(1.0);
        if !layers.is_finite() || layers > f64::from(MAX_LAYERS) {
            return None;
        }
        let layers = layers as u32;
        let texels = f64::from(layers) * f64::from(res) * f64::from(res);
        Some(ImpostorSpec {
            layers,
            resolution: res,
            memory_bytes: (texels * self.bytes_per_texel).ceil() as u64,
        })
    }

    /// The impostor of `cluster` for a shaft of half-angle `alpha` (radians)
    /// and minimum distance `d_min`.
    pub fn shaft(&self, cluster: &Sphere, alpha: f64, d_min: f64) -> Option<ImpostorSpec> {
        let r = cluster.radius;
        let res = self.resolution(r, d_min)?;
        let n = (r * alpha.sin() / (self.eps * self.theta * d_min)).ceil();
        self.spec(n, res)
    }

    /// The impostor of `cluster` for a box view cell, or `None` when the box
    /// meets the cluster.
    pub fn boxed(&self, cluster: &Sphere, cell: &Aabb) -> Option<ImpostorSpec> {
        let r = cluster.radius;
        let d_min = cell.distance_to_point(cluster.center);
        if d_min <= r {
            return None;
        }
        let res = self.resolution(r, d_min)?;
        let dist = cell.center().distance(cluster.center);
        let (zn, zf) = (dist - r, dist + r);
        if zn <= 0.0 {
            return None;
        }
        let n =
            (cell.half_diagonal() * (1.0 / zn - 1.0 / zf) / (2.0 * self.eps * self.theta)).ceil();
        self.spec(n, res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> ImpostorModel {
        ImpostorModel::new(&Job::with_view_space([0.0; 3], [1.0; 3]))
    }

    #[test]
    fn shaft_hand_computed() {
        let m = model();
        let theta = 2.0 * 22.5f64.to_radians().tan() / 512.0; // 1.6180e-3
        assert!((m.theta - theta).abs() < 1e-15);
        let s = Sphere {
            center: DVec3::ZERO,
            radius: 10.0,
        };
        // d_min = 64·R·2 = 1280 m, α = 5.625°: n = ceil(10·sin 5.625° / (θ·1280)) = 1,
        // res = ceil(20 / (θ·1270)) = ceil(9.733) = 10, memory = 100·4·4/3 → 534 bytes.
        let spec = m.shaft(&s, 5.625f64.to_radians(), 1280.0).unwrap();
        assert_eq!(spec.layers, 1);
        assert_eq!(spec.resolution, 10);
        assert_eq!(spec.memory_bytes, 534);
        // d_min = 2R = 20 m, α = 45°: n = ceil(10·0.7071/(θ·20)) = ceil(218.5) = 219,
        // res = ceil(20/(θ·10)) = ceil(1236.07) = 1237.
        let spec = m.shaft(&s, 45f64.to_radians(), 20.0).unwrap();
        assert_eq!(spec.layers, 219);
        assert_eq!(spec.resolution, 1237);
        assert_eq!(
            spec.memory_bytes,
            (219.0f64 * 1237.0 * 1237.0 * 16.0 / 3.0).ceil() as u64
        );
        // Too close: the view cell would meet the cluster.
        assert!(m.shaft(&s, 0.1, 10.0).is_none());
        // Resolution floor of 4 texels.
        assert_eq!(m.shaft(&s, 0.01, 1e6).unwrap().resolution, 4);
    }

    #[test]
    fn box_hand_computed() {
        let m = model();
        let s = Sphere {
            center: DVec3::new(100.0, 0.0, 0.0),
            radius: 5.0,
        };
        let cell = Aabb::new(
            DVec3::new(-10.0, -10.0, -10.0),
            DVec3::new(10.0, 10.0, 10.0),
        );
        // r = √300 = 17.32, z_n = 95, z_f = 105: n = ceil(17.32·(1/95 − 1/105)/(2θ)) = ceil(5.35) = 6.
        // d_min = 90: res = ceil(10/(θ·85)) = ceil(72.71) = 73.
        let spec = m.boxed(&s, &cell).unwrap();
        assert_eq!(spec.layers, 6);
        assert_eq!(spec.resolution, 73);
        let near = Sphere {
            center: DVec3::new(12.0, 0.0, 0.0),
            radius: 5.0,
        };
        assert!(m.boxed(&near, &cell).is_none());
    }

    #[test]
    fn shaft_containment() {
        let cell = ViewCell::Shaft {
            apex: DVec3::ZERO,
            axis: DVec3::X,
            half_angle: 10f64.to_radians(),
            min_distance: 50.0,
        };
        let inside = Aabb::new(DVec3::new(100.0, -1.0, -1.0), DVec3::new(102.0, 1.0, 1.0));
        assert!(cell.contains_box(&inside));
        assert!(cell.may_intersect_box(&inside));
        let too_close = Aabb::new(DVec3::new(40.0, -1.0, -1.0), DVec3::new(42.0, 1.0, 1.0));
        assert!(!cell.contains_box(&too_close));
        let off_axis = Aabb::new(DVec3::new(100.0, 30.0, -1.0), DVec3::new(102.0, 32.0, 1.0));
        assert!(!cell.contains_box(&off_axis));
        let behind = Aabb::new(DVec3::new(-102.0, -1.0, -1.0), DVec3::new(-100.0, 1.0, 1.0));
        assert!(!cell.may_intersect_box(&behind));
    }
}
