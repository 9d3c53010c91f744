//! Geometry shared by every stage: boxes, view-direction intervals on the cube
//! faces, the one conservative enclosing-frustum routine, exact view frusta
//! and the projected-size estimate.
//!
//! Objects are tested by their bounding spheres everywhere (enclosing sets,
//! exact views, impostor clusters), so the enclosing set provably contains
//! every object whose sphere meets an exact view frustum of the region.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

use glam::DVec3;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub min: DVec3,
    /// Maximum corner.
    pub max: DVec3,
}

impl Aabb {
    /// The empty box, which [`union`](Self::union) and
    /// [`add`](Self::add) grow from.
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// A box from its corners.
    pub fn new(min: DVec3, max: DVec3) -> Self {
        Aabb { min, max }
    }

    /// Grows the box to hold `p`.
    pub fn add(&mut self, p: DVec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb::new(self.min.min(o.min), self.max.max(o.max))
    }

    /// True when `p` lies in the box (its faces included).
    pub fn contains_point(&self, p: DVec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Centre.
    pub fn center(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    /// Half the diagonal.
    pub fn half_diagonal(&self) -> f64 {
        (self.max - self.min).length() * 0.5
    }

    /// The eight corners.
    pub fn corners(&self) -> [DVec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            DVec3::new(a.x, a.y, a.z),
            DVec3::new(b.x, a.y, a.z),
            DVec3::new(a.x, b.y, a.z),
            DVec3::new(b.x, b.y, a.z),
            DVec3::new(a.x, a.y, b.z),
            DVec3::new(b.x, a.y, b.z),
            DVec3::new(a.x, b.y, b.z),
            DVec3::new(b.x, b.y, b.z),
        ]
    }

    /// Distance from `p` to the closest point of the box (0 inside).
    pub fn distance_to_point(&self, p: DVec3) -> f64 {
        (self.min - p).max(p - self.max).max(DVec3::ZERO).length()
    }

    /// Distance from `p` to the farthest point of the box.
    pub fn max_distance_to_point(&self, p: DVec3) -> f64 {
        (p - self.min).abs().max((p - self.max).abs()).length()
    }

    /// True when `other` lies inside this box (boundaries included).
    pub fn contains_box(&self, other: &Aabb) -> bool {
        self.min.cmple(other.min).all() && other.max.cmple(self.max).all()
    }

    /// True when the sphere `(c, r)` meets the box.
    pub fn intersects_sphere(&self, c: DVec3, r: f64) -> bool {
        self.distance_to_point(c) <= r
    }
}

/// A bounding sphere.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub center: DVec3,
    /// Radius.
    pub radius: f64,
}

impl Sphere {
    /// The smallest sphere containing both spheres.
    pub fn merge(&self, other: &Sphere) -> Sphere {
        let d = other.center - self.center;
        let dist = d.length();
        if dist + other.radius <= self.radius {
            return *self;
        }
        if dist + self.radius <= other.radius {
            return *other;
        }
        let radius = (dist + self.radius + other.radius) * 0.5;
        let center = self.center + d * ((radius - self.radius) / dist);
        // Guard against rounding: grow until both spheres are inside.
        let need = (center.distance(self.center) + self.radius)
            .max(center.distance(other.center) + other.radius);
        Sphere {
            center,
            radius: radius.max(need) * (1.0 + 1e-12),
        }
    }
}

/// A view-direction interval (VDI): a rectangle `[u_lo,u_hi] × [v_lo,v_hi]`
/// on one cube face, from a quadtree whose splits are uniform in angle.
///
/// Face `f = 2·axis + (0 if positive else 1)`; a direction on face `f` has
/// `d[axis] = ±1` and `(u, v)` are its other two coordinates in x, y, z order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Vdi {
    /// Cube face 0..6.
    pub face: u8,
    /// Quadtree level (0 = the whole face).
    pub level: u8,
    /// Column index in `0..2^level` (along u).
    pub iu: u32,
    /// Row index in `0..2^level` (along v).
    pub iv: u32,
}

/// Face coordinate of boundary `k` at quadtree `level` (angle-uniform splits).
fn boundary(level: u8, k: u32) -> f64 {
    let n = f64::from(1u32 << level);
    let a = -FRAC_PI_4 + f64::from(k) * FRAC_PI_2 / n;
    if k == 0 {
        -1.0
    } else if f64::from(k) == n {
        1.0
    } else {
        a.tan()
    }
}

/// The direction (not normalised) with face coordinates `(u, v)` on `face`.
pub fn face_direction(face: u8, u: f64, v: f64) -> DVec3 {
    let axis = face / 2;
    let s = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    match axis {
        0 => DVec3::new(s, u, v),
        1 => DVec3::new(u, s, v),
        _ => DVec3::new(u, v, s),
    }
}

/// The face and face coordinates of a non-zero direction. A direction on a
/// face edge belongs to the face with the lower index.
pub fn face_coords(d: DVec3) -> (u8, f64, f64) {
    let a = d.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    let m = a[axis];
    let face = 2 * axis as u8 + u8::from(d[axis] < 0.0);
    let (u, v) = match axis {
        0 => (d.y / m, d.z / m),
        1 => (d.x / m, d.z / m),
        _ => (d.x / m, d.y / m),
    };
    (face, u.clamp(-1.0, 1.0), v.clamp(-1.0, 1.0))
}

/// Index of the interval containing face coordinate `x` at `level`
/// (half-open intervals, the last one closed).
fn interval_index(level: u8, x: f64) -> u32 {
    let n = 1u32 << level;
    let t = (x.clamp(-1.0, 1.0).atan() + FRAC_PI_4) / FRAC_PI_2 * f64::from(n);
    let mut i = (t.floor().max(0.0) as u32).min(n - 1);
    // Correct the rare rounding disagreement with the stored boundaries.
    if i > 0 && x < boundary(level, i) {
        i -= 1;
    } else if i + 1 < n && x >= boundary(level, i + 1) {
        i += 1;
    }
    i
}

impl Vdi {
    /// The whole face.
    pub fn face(face: u8) -> Vdi {
        Vdi {
            face,
            level: 0,
            iu: 0,
            iv: 0,
        }
    }

    /// The VDI at `level` containing direction `d`.
    pub fn containing(d: DVec3, level: u8) -> Vdi {
        let (face, u, v) = face_coords(d);
        Vdi {
            face,
            level,
            iu: interval_index(level, u),
            iv: interval_index(level, v),
        }
    }

    /// `[u_lo, u_hi]`.
    pub fn u_range(&self) -> [f64; 2] {
        [
            boundary(self.level, self.iu),
            boundary(self.level, self.iu + 1),
        ]
    }

    /// `[v_lo, v_hi]`.
    pub fn v_range(&self) -> [f64; 2] {
        [
            boundary(self.level, self.iv),
            boundary(self.level, self.iv + 1),
        ]
    }

    /// The four children of the quadtree.
    pub fn children(&self) -> [Vdi; 4] {
        let c = |du, dv| Vdi {
            face: self.face,
            level: self.level + 1,
            iu: self.iu * 2 + du,
            iv: self.iv * 2 + dv,
        };
        [c(0, 0), c(1, 0), c(0, 1), c(1, 1)]
    }

    /// Every VDI of quadtree level `level`, face by face, row by row.
    pub fn all_at(level: u8) -> Vec<Vdi> {
        let n = 1u32 << level;
        (0..6u8)
            .flat_map(|face| {
                (0..n).flat_map(move |iv| {
                    (0..n).map(move |iu| Vdi {
                        face,
                        level,
                        iu,
                        iv,
                    })
                })
            })
            .collect()
    }

    /// True when `leaf` (at a deeper or equal level) lies inside this VDI.
    pub fn contains(&self, leaf: &Vdi) -> bool {
        if leaf.face != self.face || leaf.level < self.level {
            return false;
        }
        let shift = leaf.level - self.level;
        leaf.iu >> shift == self.iu && leaf.iv >> shift == self.iv
    }

    /// Unit directions of the four corners.
    pub fn corner_dirs(&self) -> [DVec3; 4] {
        let [u0, u1] = self.u_range();
        let [v0, v1] = self.v_range();
        [(u0, v0), (u1, v0), (u0, v1), (u1, v1)]
            .map(|(u, v)| face_direction(self.face, u, v).normalize())
    }

    /// Unit centre direction (angle midpoints) and angular radius, radians:
    /// every direction of the VDI lies within the radius of the centre.
    pub fn center_and_radius(&self) -> (DVec3, f64) {
        let mid = |[a, b]: [f64; 2]| ((a.atan() + b.atan()) * 0.5).tan();
        let c = face_direction(self.face, mid(self.u_range()), mid(self.v_range())).normalize();
        // The VDI is a spherical quadrilateral bounded by great circles and
        // lies within 90° of its centre, so its farthest point is a corner.
        let min_dot = self
            .corner_dirs()
            .iter()
            .map(|d| d.dot(c))
            .fold(1.0f64, f64::min);
        (c, min_dot.clamp(-1.0, 1.0).acos())
    }

    /// Elevation range `[lo, hi]` of the VDI's directions, radians.
    pub fn elevation_range(&self) -> [f64; 2] {
        let [u0, u1] = self.u_range();
        let [v0, v1] = self.v_range();
        let closest0 = |[a, b]: [f64; 2]| {
            if a <= 0.0 && b >= 0.0 {
                0.0
            } else {
                a.abs().min(b.abs())
            }
        };
        let farthest = |[a, b]: [f64; 2]| a.abs().max(b.abs());
        let axis = self.face / 2;
        let positive = self.face.is_multiple_of(2);
        match axis {
            // Side faces: y is the u (x faces) or v (z faces) coordinate.
            0 | 2 => {
                let (y, other) = if axis == 0 {
                    ([u0, u1], [v0, v1])
                } else {
                    ([v0, v1], [u0, u1])
                };
                let elev = |y: f64| {
                    let den = if y >= 0.0 {
                        closest0(other)
                    } else {
                        farthest(other)
                    };
                    let den_hi = if y >= 0.0 {
                        farthest(other)
                    } else {
                        closest0(other)
                    };
                    (
                        y.atan2((1.0 + den * den).sqrt()),
                        y.atan2((1.0 + den_hi * den_hi).sqrt()),
                    )
                };
                let (hi, _) = elev(y[1]);
                let (_, lo) = elev(y[0]);
                [lo.min(hi), hi.max(lo)]
            }
            _ => {
                let rmin = (closest0([u0, u1]).powi(2) + closest0([v0, v1]).powi(2)).sqrt();
                let rmax = (farthest([u0, u1]).powi(2) + farthest([v0, v1]).powi(2)).sqrt();
                let hi = 1.0f64.atan2(rmin);
                let lo = 1.0f64.atan2(rmax);
                if positive { [lo, hi] } else { [-hi, -lo] }
            }
        }
    }
}

/// Half-angle of the view frustum's diagonal, radians: the frustum lies in the
/// cone of this half-angle around the view direction.
pub fn frustum_half_diagonal(fov_deg: f64, aspect: f64) -> f64 {
    let tv = (fov_deg.to_radians() * 0.5).tan();
    (tv * (1.0 + aspect * aspect).sqrt()).atan()
}

/// An infinite cone with apex, unit axis and half-angle; `all` marks a cone
/// of half-angle ≥ 90°, treated as all of space.
#[derive(Clone, Copy, Debug)]
pub struct Cone {
    /// Apex.
    pub apex: DVec3,
    /// Unit axis.
    pub axis: DVec3,
    cos: f64,
    sin: f64,
    /// `cos²` and `sin²` of the half-angle, for [`Cone::sphere_side`].
    cos2: f64,
    sin2: f64,
    /// True when the cone covers all of space.
    pub all: bool,
    /// Points with `(p − apex)·axis < floor` are outside (a plane cutting
    /// off the apex; 0 keeps the whole cone).
    pub floor: f64,
}

impl Cone {
    /// A cone; a half-angle of 90° or more covers all of space.
    pub fn new(apex: DVec3, axis: DVec3, half_angle: f64) -> Cone {
        let (sin, cos) = (half_angle.sin(), half_angle.cos());
        Cone {
            apex,
            axis,
            cos,
            sin,
            cos2: cos * cos,
            sin2: sin * sin,
            all: half_angle >= FRAC_PI_2 - 1e-9,
            floor: 0.0,
        }
    }

    /// The cone cut by the plane `(p − apex)·axis = floor` (keeping the side
    /// away from the apex).
    pub fn with_floor(mut self, floor: f64) -> Cone {
        self.floor = floor;
        self
    }

    /// Signed distance of `p` to the cone's surface (negative inside),
    /// ignoring the floor plane.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        let v = p - self.apex;
        let par = v.dot(self.axis);
        let perp = (v - self.axis * par).length();
        let s = perp * self.cos - par * self.sin;
        if s <= 0.0 {
            return s;
        }
        let t = par * self.cos + perp * self.sin;
        if t >= 0.0 { s } else { v.length() }
    }

    /// Where the sphere `(c, r)`, `r ≥ 0`, lies against the cone's mantle
    /// (ignoring the floor plane), as [`signed_distance`](Self::signed_distance)
    /// compared with `±r` but without a square root: `(within, beyond)`,
    /// `within` when the signed distance of `c` is at most `−r` (the sphere
    /// lies in the cone), `beyond` when it is above `r` (at least `r` with
    /// `or_equal`: the sphere lies outside). Both sides of each comparison
    /// are squared where they are not negative; the results differ from
    /// the distance's only by rounding. For half-angles in (0°, 90°).
    #[inline]
    pub fn sphere_side(&self, c: DVec3, r: f64, or_equal: bool) -> (bool, bool) {
        let (par, perp2) = self.axial(c);
        if self.within_at(par, perp2, r) {
            return (true, false);
        }
        let above = |a: f64, b: f64| if or_equal { a >= b } else { a > b };
        // Behind the apex (par·cos + perp·sin < 0, so par < 0) the distance
        // is |c − apex|.
        if par < 0.0 && perp2 * self.sin2 < par * par * self.cos2 {
            return (false, above(par * par + perp2, r * r));
        }
        // Elsewhere it is perp·cos − par·sin, above r where perp·cos is
        // above q' = r + par·sin (always when q' < 0).
        let q = r + par * self.sin;
        (false, q < 0.0 || above(perp2 * self.cos2, q * q))
    }

    /// The first answer of [`sphere_side`](Self::sphere_side) with
    /// `or_equal`: the sphere lies inside the cone (distance at most −r).
    #[inline]
    pub fn sphere_within(&self, c: DVec3, r: f64) -> bool {
        let (par, perp2) = self.axial(c);
        self.within_at(par, perp2, r)
    }

    /// The distance of `c` along the axis from the apex, and the square of
    /// its distance from the axis.
    #[inline]
    fn axial(&self, c: DVec3) -> (f64, f64) {
        let v = c - self.apex;
        let par = v.dot(self.axis);
        let w = v - self.axis * par;
        (par, w.dot(w))
    }

    /// True when a sphere of radius `r` at `par` along the axis and
    /// `perp2` squared from it lies inside the cone: the distance is at
    /// most −r ≤ 0 only where it is perp·cos − par·sin (a positive one is
    /// positive), so perp·cos ≤ q = par·sin − r.
    #[inline]
    fn within_at(&self, par: f64, perp2: f64, r: f64) -> bool {
        let q = par * self.sin - r;
        q >= 0.0 && perp2 * self.cos2 <= q * q
    }

    /// True when the sphere `(c, r)` may meet the cone: it meets the cone
    /// and reaches the floor plane's far side (conservative: a sphere that
    /// meets both only outside their intersection is also accepted).
    pub fn intersects_sphere(&self, c: DVec3, r: f64) -> bool {
        self.all
            || (self.signed_distance(c) <= r && (c - self.apex).dot(self.axis) + r >= self.floor)
    }

    /// True when the sphere `(c, r)` lies entirely inside the cone and on the
    /// far side of the floor plane.
    pub fn contains_sphere(&self, c: DVec3, r: f64) -> bool {
        self.all
            || (self.signed_distance(c) <= -r && (c - self.apex).dot(self.axis) - r >= self.floor)
    }
}

/// An exact view frustum: an infinite pyramid with apex at the eye.
#[derive(Clone, Copy, Debug)]
pub struct ViewFrustum {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    fwd: DVec3,
    normals: [DVec3; 4],
    edges: [DVec3; 4],
}

impl ViewFrustum {
    /// The frustum of a camera at `eye` looking along `dir` (any length), with
    /// vertical field of view `fov_deg`, aspect width/height, no roll (up is +y
    /// projected; looking straight up or down uses +x as right).
    pub fn new(eye: DVec3, dir: DVec3, fov_deg: f64, aspect: f64) -> ViewFrustum {
        let fwd = dir.normalize();
        let r = fwd.cross(DVec3::Y);
        let right = if r.length_squared() < 1e-18 {
            DVec3::X
        } else {
            r.normalize()
        };
        let up = right.cross(fwd);
        let tv = (fov_deg.to_radians() * 0.5).tan();
        let th = tv * aspect;
        // Camera coordinates (a, b, c) = (right, up, forward).
        let normals = [
            DVec3::new(-1.0, 0.0, th).normalize(),
            DVec3::new(1.0, 0.0, th).normalize(),
            DVec3::new(0.0, -1.0, tv).normalize(),
            DVec3::new(0.0, 1.0, tv).normalize(),
        ];
        let edges = [
            DVec3::new(th, tv, 1.0).normalize(),
            DVec3::new(-th, tv, 1.0).normalize(),
            DVec3::new(th, -tv, 1.0).normalize(),
            DVec3::new(-th, -tv, 1.0).normalize(),
        ];
        ViewFrustum {
            eye,
            right,
            up,
            fwd,
            normals,
            edges,
        }
    }

    /// The four side planes' unit normals in world coordinates, pointing
    /// into the frustum (left, right, bottom, top).
    pub fn side_normals(&self) -> [DVec3; 4] {
        self.normals
            .map(|n| self.right * n.x + self.up * n.y + self.fwd * n.z)
    }

    /// The eye position.
    pub fn eye(&self) -> DVec3 {
        self.eye
    }

    /// The camera basis: right, up and forward unit vectors.
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        (self.right, self.up, self.fwd)
    }

    /// Exact Euclidean distance from `p` to the frustum (0 inside).
    pub fn distance(&self, p: DVec3) -> f64 {
        let w = p - self.eye;
        let x = DVec3::new(w.dot(self.right), w.dot(self.up), w.dot(self.fwd));
        let dots = self.normals.map(|n| n.dot(x));
        if dots.iter().all(|&d| d >= 0.0) {
            return 0.0;
        }
        let mut best = x.length();
        for e in &self.edges {
            let t = x.dot(*e);
            if t > 0.0 {
                best = best.min((x - *e * t).length());
            }
        }
        let tol = 1e-12 * (1.0 + x.length());
        for (i, n) in self.normals.iter().enumerate() {
            if dots[i] >= 0.0 {
                continue;
            }
            let proj = x - *n * dots[i];
            if self
                .normals
                .iter()
                .enumerate()
                .all(|(j, m)| j == i || m.dot(proj) >= -tol)
            {
                best = best.min(-dots[i]);
            }
        }
        best
    }

    /// True when the sphere `(c, r)` meets the frustum (exact).
    pub fn intersects_sphere(&self, c: DVec3, r: f64) -> bool {
        self.distance(c) <= r
    }

    /// True when the sphere `(c, r)` lies inside the frustum with a margin
    /// of `1e-9·(1 + r)`: every point within that margin of the sphere is
    /// inside too (a sphere within it whose containment was rounded).
    pub fn contains_sphere(&self, c: DVec3, r: f64) -> bool {
        let w = c - self.eye;
        let x = DVec3::new(w.dot(self.right), w.dot(self.up), w.dot(self.fwd));
        let r = r + 1e-9 * (1.0 + r);
        self.normals.iter().all(|n| n.dot(x) >= r)
    }
}

/// Projected area of a sphere of radius `r` at distance `d` from the eye,
/// pixels, as seen on the view axis (`π f² r² / (d² − r²)`), clamped to the
/// screen. Non-increasing in `d`, so the closest distance over a region bounds
/// every view of the region.
pub fn projected_area_px(r: f64, d: f64, focal_px: f64, screen_px: f64) -> f64 {
    if d <= r {
        return screen_px;
    }
    let a = std::f64::consts::PI * focal_px * focal_px * r * r / (d * d - r * r);
    a.min(screen_px)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;

    #[test]
    fn sphere_side_agrees_with_the_signed_distance() {
        let mut rng = Rng::new(7);
        let mut u = || rng.range(-1.0, 1.0);
        let (mut within, mut beyond) = (0, 0);
        for i in 0..20_000 {
            let axis = DVec3::new(u(), u(), u()).normalize();
            let apex = DVec3::new(u(), u(), u()) * 10.0;
            let half = 0.05 + 1.45 * (0.5 + 0.5 * u());
            let cone = Cone::new(apex, axis, half);
            let c = apex + DVec3::new(u(), u(), u()) * 20.0;
            let r = if i % 10 == 0 {
                0.0
            } else {
                5.0 * (0.5 + 0.5 * u())
            };
            let d = cone.signed_distance(c);
            // Away from ties, where rounding may decide either way.
            if (d.abs() - r).abs() < 1e-9 * (1.0 + d.abs()) {
                continue;
            }
            for or_equal in [false, true] {
                let (w, b) = cone.sphere_side(c, r, or_equal);
                assert_eq!(cone.sphere_within(c, r), w);
                assert_eq!(w, d <= -r, "within: d {d}, r {r}");
                assert_eq!(b, d > r, "beyond: d {d}, r {r}");
                within += usize::from(w);
                beyond += usize::from(b);
            }
        }
        // Both answers occur often enough to mean something.
        assert!(within > 2_000 && beyond > 2_000, "{within} {beyond}");
    }

    #[test]
    fn face_coords_round_trip_and_edge_rule() {
        for face in 0..6u8 {
            let d = face_direction(face, 0.3, -0.7);
            let (f, u, v) = face_coords(d);
            assert_eq!(f, face);
            assert!((u - 0.3).abs() < 1e-12 && (v + 0.7).abs() < 1e-12);
        }
        // On the edge between +x (face 0) and +y (face 2): lower index wins.
        assert_eq!(face_coords(DVec3::new(1.0, 1.0, 0.0)).0, 0);
        assert_eq!(face_coords(DVec3::new(0.0, -1.0, -1.0)).0, 3);
    }

    #[test]
    fn vdi_quadtree_partitions_directions() {
        let mut rng = Rng::new(7);
        for _ in 0..2000 {
            let d = rng.unit_vector();
            let leaf = Vdi::containing(d, 3);
            let (_, u, v) = face_coords(d);
            let [u0, u1] = leaf.u_range();
            let [v0, v1] = leaf.v_range();
            assert!(u >= u0 && u <= u1 && v >= v0 && v <= v1);
            assert!(Vdi::face(leaf.face).contains(&leaf));
            let (c, rho) = leaf.center_and_radius();
            assert!(d.normalize().dot(c).clamp(-1.0, 1.0).acos() <= rho + 1e-12);
            // At 11.25° the radius is about half the diagonal of an 11.25° cell.
            assert!(rho < 11.25f64.to_radians());
            let [lo, hi] = leaf.elevation_range();
            let e = (d.y / d.length()).asin();
            assert!(
                e >= lo - 1e-12 && e <= hi + 1e-12,
                "{e} not in [{lo}, {hi}] for {leaf:?}"
            );
        }
    }

    #[test]
    fn half_diagonal_matches_hand_value() {
        // 45° vertical fov, square: atan(tan(22.5°)·√2) = 30.36°.
        let b = frustum_half_diagonal(45.0, 1.0).to_degrees();
        assert!((b - 30.361).abs() < 1e-3, "{b}");
    }

    #[test]
    fn frustum_distance_matches_brute_force() {
        let mut rng = Rng::new(3);
        for _ in 0..200 {
            let eye = rng.in_box(DVec3::splat(-5.0), DVec3::splat(5.0));
            let f = ViewFrustum::new(eye, rng.unit_vector(), 60.0, 1.5);
            let p = rng.in_box(DVec3::splat(-20.0), DVec3::splat(20.0));
            let d = f.distance(p);
            // Brute force: sample the frustum surface densely near p.
            let mut best = f64::INFINITY;
            let tv = 30f64.to_radians().tan();
            let th = tv * 1.5;
            for i in 0..=200 {
                for j in 0..=200 {
                    let a = -th + 2.0 * th * f64::from(i) / 200.0;
                    let b = -tv + 2.0 * tv * f64::from(j) / 200.0;
                    let dir = f.right * a + f.up * b + f.fwd;
                    // Closest point on the ray eye + t·dir.
                    let t = ((p - eye).dot(dir) / dir.length_squared()).max(0.0);
                    best = best.min((eye + dir * t).distance(p));
                }
            }
            assert!(d <= best + 1e-9, "exact {d} > sampled {best}");
            assert!(
                best - d < 0.2 + 0.02 * best,
                "exact {d} far below sampled {best}"
            );
        }
    }

    #[test]
    fn cone_sphere_tests() {
        let c = Cone::new(DVec3::ZERO, DVec3::Z, 30f64.to_radians());
        assert!(c.intersects_sphere(DVec3::new(0.0, 0.0, 10.0), 0.1));
        assert!(c.contains_sphere(DVec3::new(0.0, 0.0, 10.0), 1.0));
        // A point at 45° off axis, 10 m away: distance to the mantle = 10·sin 15°.
        let p = DVec3::new(0.0, 45f64.to_radians().sin(), 45f64.to_radians().cos()) * 10.0;
        let d = 10.0 * 15f64.to_radians().sin();
        assert!(c.intersects_sphere(p, d + 1e-9));
        assert!(!c.intersects_sphere(p, d - 1e-6));
        // Behind the apex: the distance is to the apex.
        assert!(!c.intersects_sphere(DVec3::new(0.0, 0.0, -2.0), 1.9));
        assert!(c.intersects_sphere(DVec3::new(0.0, 0.0, -2.0), 2.0));
    }

    #[test]
    fn projected_area_hand_values() {
        // r = 1 at d = 10 with f = 100 px: π·10⁴/99.
        let a = projected_area_px(1.0, 10.0, 100.0, 1e9);
        assert!((a - std::f64::consts::PI * 1e4 / 99.0).abs() < 1e-9);
        assert_eq!(
            projected_area_px(1.0, 0.5, 100.0, 512.0 * 512.0),
            512.0 * 512.0
        );
    }
}
