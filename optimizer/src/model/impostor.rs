//! The impostor model (DESIGN §2.5): view cells (shafts and boxes), layer
//! count, texture resolution and memory of layered impostors.
//!
//! Pixel angle `θ = 2·tan(fovy/2)/H`, error budget `ε` pixels, cluster sphere
//! `(c, R)`. The layer count is the smallest that keeps the parallax of the
//! layers the bake draws ([`crate::model::layers`]) within `ε·θ` from every
//! viewpoint of the view cell, by a bound proven below
//! ([`ImpostorModel::shaft`], [`ImpostorModel::boxed`]); far from the
//! cluster it is the design's small-angle formula (shaft `R·sin α / (ε·θ·
//! d_min)`, box `r·(1/z_n − 1/z_f) / (2·ε·θ)`), close in it is more;
//! - resolution `ceil(k·2R / (θ·(d_min − R)))` texels per side per layer
//!   (`k` = `memory.texels_per_pixel`, default 1), with
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
    /// Texels per pixel at the closest viewpoint, per side.
    pub texels_per_pixel: f64,
}

/// Distances from a shaft's apex, as multiples of its minimum distance, at
/// which its parallax bound is evaluated (see [`ImpostorModel::shaft`]).
const SHAFT_RHO: [f64; 14] = [
    1.0, 1.02, 1.05, 1.1, 1.2, 1.35, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0,
];

/// Headroom on the parallax bound for the shaft's distances between the
/// sampled ones (the bound falls with the distance near the apex, where it
/// is largest, and changes by less than this between neighbours).
const SHAFT_BOUND_MARGIN: f64 = 1.03;

/// The smallest layer count `n ≥ first` for which `sin_error(n)`, which
/// falls as `n` grows (about as `1/n`), is at most `budget`; `None` above
/// [`MAX_LAYERS`].
fn layers_for(first: f64, budget: f64, sin_error: impl Fn(f64) -> f64) -> Option<u32> {
    let (mut lo, mut n) = (0.0f64, first.max(1.0).ceil());
    // Counts known too few (`lo`) and a count to try, stepping by the
    // shortfall until one is enough.
    loop {
        if !n.is_finite() || n > f64::from(MAX_LAYERS) {
            return None;
        }
        let s = sin_error(n);
        if s <= budget {
            break;
        }
        lo = n;
        n = (n + 1.0).max((n * s / budget).ceil());
    }
    // Then the smallest enough count between them.
    let mut hi = n;
    while hi - lo > 1.0 {
        let mid = (0.5 * (lo + hi)).floor();
        if sin_error(mid) <= budget {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi as u32)
}

impl ImpostorModel {
    /// The model of `job`.
    pub fn new(job: &Job) -> Self {
        let m = &job.memory;
        ImpostorModel {
            theta: job.pixel_angle(),
            eps: job.max_error_px,
            bytes_per_texel: m.texel_bytes() * if m.mipmaps { 4.0 / 3.0 } else { 1.0 },
            max_res: m.max_texture_size,
            texels_per_pixel: m.texels_per_pixel,
        }
    }

    /// The angle a texel spans seen from an impostor's closest viewpoint:
    /// the pixel angle over `memory.texels_per_pixel`.
    pub fn texel_angle(&self) -> f64 {
        self.theta / self.texels_per_pixel
    }

    /// Texture resolution for a cluster of radius `r` seen no closer than
    /// `d_min`, or `None` when it exceeds the maximum texture size.
    pub fn resolution(&self, r: f64, d_min: f64) -> Option<u32> {
        if d_min <= r {
            return None;
        }
        let res = (2.0 * r / (self.texel_angle() * (d_min - r))).ceil();
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

    /// The sine of the parallax budget `ε·θ`.
    fn budget(&self) -> f64 {
        (self.eps * self.theta)
            .min(std::f64::consts::FRAC_PI_2)
            .sin()
    }

    /// The impostor of `cluster` for a shaft of half-angle `alpha` (radians)
    /// and minimum distance `d_min`.
    ///
    /// The bake draws point `p` of the cluster at `q`, on the ray from the
    /// reference viewpoint `e = c + u·d_min` at its slab's layer depth; the
    /// `n` slabs are `2R/n` thick, so `|pq| ≤ δ = R / (n·cos β)` with `β`
    /// the sphere's angular radius from `e`. Seen from `v`, the segment
    /// `pq` (on a line through `e`) subtends an angle whose sine is
    /// `|pq|·h / (|vp|·|vq|)`, `h` the distance from `v` to that line:
    /// `h ≤ |v − e|`, and `h ≤ ρ·sin α + |v − e|·2·sin(β/2)` for `v` at
    /// distance `ρ` from `c` and at most `α` off the axis (the line is
    /// within `β` of the axis); `|vp| ≥ ρ − R`, `|vq| ≥ ρ − R − δ`. The layer
    /// count is the smallest whose bound, maximised over `ρ ≥ d_min`, is
    /// within `sin(ε·θ)`.
    pub fn shaft(&self, cluster: &Sphere, alpha: f64, d_min: f64) -> Option<ImpostorSpec> {
        let r = cluster.radius;
        let res = self.resolution(r, d_min)?;
        let n = self.shaft_layers(r, alpha, d_min)?;
        self.spec(f64::from(n), res)
    }

    /// The layer count of [`shaft`](Self::shaft).
    pub fn shaft_layers(&self, r: f64, alpha: f64, d: f64) -> Option<u32> {
        if d.partial_cmp(&r) != Some(std::cmp::Ordering::Greater) || !alpha.is_finite() {
            return None;
        }
        let sin_b = r / d;
        let cos_b = (1.0 - sin_b * sin_b).sqrt();
        let chord_b = 2.0 * (0.5 * sin_b.asin()).sin();
        let (sin_a, cos_a) = alpha.clamp(0.0, std::f64::consts::FRAC_PI_2).sin_cos();
        let sin_error = |n: f64| {
            let delta = r / (n * cos_b);
            let worst = SHAFT_RHO
                .iter()
                .map(|&k| {
                    let rho = d * k;
                    let ve = (rho * rho + d * d - 2.0 * rho * d * cos_a).max(0.0).sqrt();
                    let h = ve.min(rho * sin_a + ve * chord_b);
                    let (near, image) = (rho - r, rho - r - delta);
                    if image <= 0.0 {
                        f64::INFINITY
                    } else {
                        delta * h / (near * image)
                    }
                })
                .fold(0.0, f64::max);
            worst * SHAFT_BOUND_MARGIN
        };
        // The small-angle formula: never more than the count needed.
        let first = r * alpha.sin() / (self.eps * self.theta * d);
        layers_for(first, self.budget(), sin_error)
    }

    /// The impostor of `cluster` for a box view cell, or `None` when the box
    /// meets the cluster or no layer count keeps its parallax in budget.
    ///
    /// The reference viewpoint `e` is the box centre; the slabs are equal in
    /// `1/z` over the sphere's depths `[z_n, z_f]`, each slab `[a, b]` drawn
    /// at its layer depth `z_k`, so a point of it moves by at most
    /// `δ = max(z_k − a, b − z_k) / cos β` along its ray from `e`. Seen from
    /// `v` in the box (`|v − e| ≤ r`, the half-diagonal), that shift
    /// subtends an angle whose sine is at most `δ·r / (P·(P − δ))`, with
    /// `P = max(d_min − R, a − s)` a lower bound of `|vp|` (`d_min` the
    /// box's distance to `c`, `s` how far the box reaches ahead of its
    /// centre along the view axis). The layer count is the smallest whose largest
    /// bound over the slabs is within `sin(ε·θ)`.
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
        let half = cell.half_diagonal();
        let cos_b = (1.0 - (r / dist).powi(2)).max(0.0).sqrt();
        if cos_b <= 0.0 {
            return None;
        }
        // How far a viewpoint of the box lies ahead of the centre, along
        // the view axis: the box's support in that direction.
        let fwd = (cluster.center - cell.center()) / dist;
        let ahead = (0.5 * (cell.max - cell.min)).dot(fwd.abs());
        let sin_error = |n: f64| {
            let step = (1.0 / zn - 1.0 / zf) / n;
            let mut worst = 0.0f64;
            let mut w0 = 1.0 / zn;
            for k in 0..n as u32 {
                let w1 = 1.0 / zn - f64::from(k + 1) * step;
                let (a, b, z) = (1.0 / w0, 1.0 / w1, 2.0 / (w0 + w1));
                let delta = (z - a).max(b - z) / cos_b;
                let near = (d_min - r).max(a - ahead);
                let image = near - delta;
                if image <= 0.0 {
                    return f64::INFINITY;
                }
                worst = worst.max(delta * half / (near * image));
                w0 = w1;
            }
            worst
        };
        let first = half * (1.0 / zn - 1.0 / zf) / (2.0 * self.eps * self.theta);
        let n = layers_for(first, self.budget(), sin_error)?;
        self.spec(f64::from(n), res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> ImpostorModel {
        ImpostorModel::new(&Job::with_view_space([0.0; 3], [1.0; 3]))
    }

    /// `memory.texels_per_pixel` scales the resolution's formula by itself:
    /// R = 10 at d_min = 110 is 2·10 / (θ·100) = 123.6 → 124 texels, and
    /// twice that before rounding up at k = 2 (247.2 → 248); the cap holds
    /// on the scaled count.
    #[test]
    fn texels_per_pixel_scales_the_resolution() {
        let mut job = Job::with_view_space([0.0; 3], [1.0; 3]);
        assert_eq!(ImpostorModel::new(&job).resolution(10.0, 110.0), Some(124));
        job.memory.texels_per_pixel = 2.0;
        assert_eq!(ImpostorModel::new(&job).resolution(10.0, 110.0), Some(248));
        job.memory.max_texture_size = 200;
        assert_eq!(ImpostorModel::new(&job).resolution(10.0, 110.0), None);
        job.memory.texels_per_pixel = 0.0;
        let e = job.validate("job.json").unwrap_err().to_string();
        assert!(e.contains("memory.texels_per_pixel"), "{e}");
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
        // d_min = 4R = 40 m, α = 45°: the small-angle formula gives
        // ceil(10·0.7071/(θ·40)) = 110 layers. The bound is largest at the
        // near end, ρ = 40: sin β = 0.25, cos β = 0.96825, |v − e| =
        // 2·40·sin 22.5° = 30.615 (below 40·sin 45° + 30.615·2·sin(β/2) =
        // 35.96), so with δ = 10/(n·cos β) the sine of the error is
        // 1.03·δ·30.615/(30·(30 − δ)): 1.6253e-3 > sin θ = 1.6180e-3 at
        // n = 223, 1.6179e-3 at n = 224. res = ceil(20/(θ·30)) = 413.
        let spec = m.shaft(&s, 45f64.to_radians(), 40.0).unwrap();
        assert_eq!(spec.layers, 224);
        assert_eq!(spec.resolution, 413);
        assert_eq!(
            spec.memory_bytes,
            (224.0f64 * 413.0 * 413.0 * 16.0 / 3.0).ceil() as u64
        );
        // d_min = 2R = 20 m, α = 45°: the formula's 219 layers leave
        // viewpoints 10 m from the sphere; no count up to the cap keeps
        // them within a pixel.
        assert!(m.shaft(&s, 45f64.to_radians(), 20.0).is_none());
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
        // r = √300 = 17.32, z_n = 95, z_f = 105: the small-angle formula
        // gives ceil(17.32·(1/95 − 1/105)/(2θ)) = ceil(5.35) = 6 layers, for
        // viewpoints at the reference distance. The box reaches 10 m closer
        // (d_min = 90, s = 10): with 7 slabs the front one spans
        // 95–96.31 m, its layer at 95.65 m, so δ = 0.6597/cos β = 0.6605
        // (cos β = 0.99875), P = max(90 − 5, 95 − 10) = 85 and the sine of
        // the error is 0.6605·17.32/(85·84.34) = 1.596e-3 < sin θ =
        // 1.618e-3 (the farther slabs are thicker but farther); with 6
        // slabs 1.871e-3.
        // res = ceil(10/(θ·85)) = ceil(72.71) = 73.
        let spec = m.boxed(&s, &cell).unwrap();
        assert_eq!(spec.layers, 7);
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
