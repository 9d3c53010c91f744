//! The conservative enclosing set of a problem view: a convex set that
//! contains every exact view frustum with its eye in a region and its
//! direction in a view-direction interval. Problem views, their cluster
//! lists, candidate service and the baselines all test spheres against it.

use std::f64::consts::FRAC_PI_2;

use glam::DVec3;

use crate::math::geom::{Aabb, Cone, Vdi, ViewFrustum, frustum_half_diagonal};

/// The camera's lens: vertical field of view and aspect (width / height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    /// Vertical field of view, degrees.
    pub fov_deg: f64,
    /// Width over height.
    pub aspect: f64,
}

impl Lens {
    /// Half-angle of the frustum's diagonal, radians: the frustum lies in the
    /// cone of this half-angle around the view direction.
    pub fn half_diagonal(&self) -> f64 {
        frustum_half_diagonal(self.fov_deg, self.aspect)
    }
}

/// How many side planes bound an [`Enclosing`] set besides its cone.
const SIDE_PLANES: usize = 12;

/// Below this half-angle (radians) a frustum plane's excluded cone is not
/// worth testing: the VDI's frames spread too much.
const MIN_EXCLUDED_HALF_ANGLE: f64 = 0.35;

/// The conservative enclosing set of (region, VDI): every view frustum with
/// its eye in the region and its direction in the VDI lies inside it.
///
/// It is the intersection of three supersets of the views:
/// - **the cone**: the views' directions lie within γ = the VDI's angular
///   radius + the frustum's diagonal half-angle of the VDI's centre, so they
///   lie in `region ⊕ K` for the circular cone `K` of half-angle γ; the set's
///   cone has half-angle γ and its apex pushed back until it contains the
///   region, cut by the plane through the region's rearmost corner;
/// - **side planes** supporting `region ⊕ K` beside the region (normals at
///   90° + γ from the axis, at evenly spaced azimuths, through the region's
///   corner farthest along them), which cut off what the cone holds beside
///   and behind the region;
/// - **the frustum's own planes**: a camera has no roll, so its frame is a
///   yaw rotation after a pitch rotation, and two directions of the VDI have
///   frames at most δ = (yaw range + pitch range) / 2 apart from the frame
///   at the middle yaw and pitch. Every view ray is then within δ of the
///   middle frustum, so it is not strictly inside the cone of half-angle
///   90° − δ around any of that frustum's outward plane normals, with its
///   apex moved forward until every eye of the region sees the cone as
///   excluded. These cut the corners of the circular cone that a
///   rectangular frustum never reaches.
#[derive(Clone, Copy, Debug)]
pub struct Enclosing {
    /// The cone (with its floor plane).
    pub cone: Cone,
    /// The side planes `n·x ≤ h`, by component; unused when the cone is
    /// all of space.
    sides: SidePlanes,
    /// Cones no view ray enters (one per frustum plane), when the VDI's
    /// frames are close enough for them to help.
    excluded: Option<[Cone; 4]>,
}

/// Side planes `(x, y, z)·p ≤ h` by component.
#[derive(Clone, Copy, Debug, Default)]
struct SidePlanes {
    x: [f64; SIDE_PLANES],
    y: [f64; SIDE_PLANES],
    z: [f64; SIDE_PLANES],
    h: [f64; SIDE_PLANES],
}

impl SidePlanes {
    fn new(planes: &[(DVec3, f64); SIDE_PLANES]) -> SidePlanes {
        SidePlanes {
            x: planes.map(|(n, _)| n.x),
            y: planes.map(|(n, _)| n.y),
            z: planes.map(|(n, _)| n.z),
            h: planes.map(|(_, h)| h),
        }
    }

    /// The planes the sphere `(c, r)` lies wholly beyond, and those it lies
    /// wholly within, as bit masks: every plane at once, without branches
    /// (the loop vectorises, in the arithmetic of `n.dot(c) - h`), the
    /// caller reading only those it needs (less work than visiting them
    /// one by one with a branch each).
    #[inline]
    fn masks(&self, c: DVec3, r: f64) -> (u32, u32) {
        let (mut beyond, mut within) = (0u32, 0u32);
        for k in 0..SIDE_PLANES {
            let d = self.distance(k, c);
            beyond |= u32::from(d > r) << k;
            within |= u32::from(d <= -r) << k;
        }
        (beyond, within)
    }

    /// The first of [`masks`](Self::masks) alone.
    #[inline]
    fn beyond(&self, c: DVec3, r: f64) -> u32 {
        let mut beyond = 0u32;
        for k in 0..SIDE_PLANES {
            beyond |= u32::from(self.distance(k, c) > r) << k;
        }
        beyond
    }

    /// Signed distance of `c` beyond plane `k`.
    #[inline]
    fn distance(&self, k: usize, c: DVec3) -> f64 {
        self.x[k] * c.x + self.y[k] * c.y + self.z[k] * c.z - self.h[k]
    }
}

/// Where a sphere lies with respect to an [`Enclosing`] set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Overlap {
    /// It does not meet the set.
    Outside,
    /// It may meet the set.
    Partial,
    /// It lies entirely inside the set.
    Inside,
}

/// Bit of the floor plane in a [`Bounds`] mask (the side planes are bits
/// `0..SIDE_PLANES`).
const FLOOR_BIT: u32 = SIDE_PLANES as u32;
/// The side planes' bits.
const SIDE_MASK: u32 = (1 << SIDE_PLANES) - 1;
/// Bit of the cone's mantle.
const CONE_BIT: u32 = FLOOR_BIT + 1;
/// First bit of the excluded cones.
const EXCLUDED_BIT: u32 = CONE_BIT + 1;

/// The bounds of an [`Enclosing`] set a sphere still has to be tested
/// against: a sphere inside a parent sphere that lies inside some bound
/// lies inside it too, so a hierarchy walk passes the parent's mask down.
pub type Bounds = u32;

impl Enclosing {
    /// Every bound of the set (start of a walk).
    pub fn all_bounds(&self) -> Bounds {
        let n = if self.excluded.is_some() {
            EXCLUDED_BIT + 4
        } else {
            EXCLUDED_BIT
        };
        (1u32 << n) - 1
    }

    /// Where the sphere `(c, r)` lies, testing only the bounds of `mask`
    /// (those a containing sphere did not lie inside), the cheap planes
    /// first; also the bounds the sphere does not lie inside.
    pub fn classify_within(&self, c: DVec3, r: f64, mask: Bounds) -> (Overlap, Bounds) {
        if self.cone.all {
            return (Overlap::Inside, 0);
        }
        // Only the bounds of `mask` count: deep in a walk a sphere has few
        // left to test.
        let mut left = mask;
        let side = mask & SIDE_MASK;
        if side != 0 {
            let (beyond, within) = self.sides.masks(c, r);
            if beyond & side != 0 {
                return (Overlap::Outside, 0);
            }
            left &= !(within & side);
        }
        if mask & (1 << FLOOR_BIT) != 0 {
            let f = self.floor_distance(c);
            if f + r < 0.0 {
                return (Overlap::Outside, 0);
            }
            if f - r >= 0.0 {
                left &= !(1 << FLOOR_BIT);
            }
        }
        if mask & (1 << CONE_BIT) != 0 {
            let (within, beyond) = self.cone.sphere_side(c, r, false);
            if beyond {
                return (Overlap::Outside, 0);
            }
            if within {
                left &= !(1 << CONE_BIT);
            }
        }
        if let Some(excluded) = &self.excluded {
            let mut m = mask >> EXCLUDED_BIT;
            while m != 0 {
                let k = m.trailing_zeros();
                m &= m - 1;
                let (within, beyond) = excluded[k as usize].sphere_side(c, r, true);
                if within {
                    return (Overlap::Outside, 0);
                }
                if beyond {
                    left &= !(1 << (EXCLUDED_BIT + k));
                }
            }
        }
        if left == 0 {
            (Overlap::Inside, 0)
        } else {
            (Overlap::Partial, left)
        }
    }

    /// True when the sphere `(c, r)` may meet the set, testing only the
    /// bounds of `mask`: exactly when [`classify_within`](Self::classify_within)
    /// does not answer [`Overlap::Outside`], without working out which
    /// bounds the sphere lies inside.
    pub fn meets_within(&self, c: DVec3, r: f64, mask: Bounds) -> bool {
        if self.cone.all {
            return true;
        }
        if mask & SIDE_MASK != 0 && self.sides.beyond(c, r) & mask & SIDE_MASK != 0 {
            return false;
        }
        if mask & (1 << FLOOR_BIT) != 0 && self.floor_distance(c) + r < 0.0 {
            return false;
        }
        if mask & (1 << CONE_BIT) != 0 && self.cone.sphere_side(c, r, false).1 {
            return false;
        }
        if let Some(excluded) = &self.excluded {
            let mut m = mask >> EXCLUDED_BIT;
            while m != 0 {
                let k = m.trailing_zeros();
                m &= m - 1;
                if excluded[k as usize].sphere_within(c, r) {
                    return false;
                }
            }
        }
        true
    }

    /// Signed distance of `c` beyond the floor plane, into the set.
    #[inline]
    fn floor_distance(&self, c: DVec3) -> f64 {
        (c - self.cone.apex).dot(self.cone.axis) - self.cone.floor
    }

    /// Where the sphere `(c, r)` lies, in one pass over the set's bounds.
    pub fn classify(&self, c: DVec3, r: f64) -> Overlap {
        self.classify_within(c, r, self.all_bounds()).0
    }

    /// True when the sphere `(c, r)` may meet the set (conservative).
    pub fn intersects_sphere(&self, c: DVec3, r: f64) -> bool {
        self.meets_within(c, r, self.all_bounds())
    }
}

/// The direction of the middle yaw and pitch of `vdi` and the largest angle
/// between the camera frame there and the frame of any direction of the VDI
/// (half the yaw range plus half the pitch range); `None` when the VDI
/// touches a pole (its yaw range is then a quadrant or more).
fn frame_spread(vdi: &Vdi) -> Option<(DVec3, f64)> {
    let [u0, u1] = vdi.u_range();
    let [v0, v1] = vdi.v_range();
    if vdi.face / 2 == 1 && u0 <= 0.0 && u1 >= 0.0 && v0 <= 0.0 && v1 >= 0.0 {
        return None;
    }
    let (centre, _) = vdi.center_and_radius();
    let yaw_m = centre.z.atan2(centre.x);
    // Yaw of each corner relative to the centre's: the VDI is convex and
    // away from the poles, so its yaw range is that of its corners.
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for d in vdi.corner_dirs() {
        let mut a = d.z.atan2(d.x) - yaw_m;
        if a > std::f64::consts::PI {
            a -= std::f64::consts::TAU;
        } else if a < -std::f64::consts::PI {
            a += std::f64::consts::TAU;
        }
        lo = lo.min(a);
        hi = hi.max(a);
    }
    let [p0, p1] = vdi.elevation_range();
    let (yaw, pitch) = (yaw_m + 0.5 * (lo + hi), 0.5 * (p0 + p1));
    let dir = DVec3::new(
        pitch.cos() * yaw.cos(),
        pitch.sin(),
        pitch.cos() * yaw.sin(),
    );
    Some((dir, 0.5 * (hi - lo) + 0.5 * (p1 - p0)))
}

/// How far along `axis` from the region's centre the apex of a cone of
/// half-angle `alpha` must move back so that the cone contains the region
/// (negative: it may move forward by that much).
fn push_back(region: &Aabb, axis: DVec3, alpha: f64) -> f64 {
    let q = region.center();
    let tan = alpha.tan();
    region
        .corners()
        .iter()
        .map(|&corner| {
            let y = corner - q;
            let par = y.dot(axis);
            let perp = (y - axis * par).length();
            perp / tan - par
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The conservative enclosing set of (region, VDI) ([`Enclosing`]). It
/// contains every view frustum with apex in `region` and direction in `vdi`
/// seen through `lens`. This is the only such routine: CPV times, candidate
/// service and baselines all call it.
pub fn enclosing_cone(region: &Aabb, vdi: &Vdi, lens: &Lens) -> Enclosing {
    let (axis, rho) = vdi.center_and_radius();
    // A small margin absorbs rounding in the containment tests.
    let gamma = rho + lens.half_diagonal() + 1e-9;
    let pad = 1e-9 * (1.0 + region.half_diagonal());
    if gamma >= FRAC_PI_2 - 1e-9 {
        return Enclosing {
            cone: Cone::new(region.center(), axis, FRAC_PI_2),
            sides: SidePlanes::default(),
            excluded: None,
        };
    }
    let q = region.center();
    let push = push_back(region, axis, gamma).max(0.0);
    let apex = q - axis * (push + pad);
    // Every frustum of the CPV lies in front of its eye (γ < 90°), so nothing
    // behind the plane through the region's rearmost corner is seen: cut the
    // apex off there.
    let floor = region
        .corners()
        .iter()
        .map(|&c| (c - apex).dot(axis))
        .fold(f64::INFINITY, f64::min);
    let cone = Cone::new(apex, axis, gamma).with_floor((floor - pad).max(0.0));
    // Side planes: a normal n at 90° + γ from the axis has n·k ≤ 0 for every
    // direction k of the cone K, so region ⊕ K lies in n·x ≤ max over the
    // region's corners of n·corner.
    let e1 = if axis.x.abs() < 0.9 {
        axis.cross(DVec3::X)
    } else {
        axis.cross(DVec3::Y)
    }
    .normalize();
    let e2 = axis.cross(e1);
    let (sin_g, cos_g) = gamma.sin_cos();
    let planes = std::array::from_fn(|k| {
        let phi = std::f64::consts::TAU * k as f64 / SIDE_PLANES as f64;
        let (s, c) = phi.sin_cos();
        let n = (e1 * c + e2 * s) * cos_g - axis * sin_g;
        let h = region
            .corners()
            .iter()
            .map(|&p| n.dot(p))
            .fold(f64::NEG_INFINITY, f64::max);
        (n, h + pad)
    });
    // The frustum's planes: a ray within δ of the middle frustum has
    // m·x̂ ≤ sin δ for each inward normal m, so it is not strictly inside the
    // cone of half-angle 90° − δ around −m. The cone's apex moves forward
    // from the region's centre until it lies inside that cone as seen from
    // every corner, so it is excluded from every eye of the region.
    let excluded = frame_spread(vdi).and_then(|(dir, delta)| {
        let alpha = FRAC_PI_2 - delta - 1e-9;
        (alpha >= MIN_EXCLUDED_HALF_ANGLE).then(|| {
            let f = ViewFrustum::new(q, dir, lens.fov_deg, lens.aspect);
            f.side_normals().map(|m| {
                // The box is symmetric about its centre, so the push back
                // along −o is also the push forward along o.
                let o = -m;
                Cone::new(q + o * (push_back(region, o, alpha) + pad), o, alpha)
            })
        })
    });
    Enclosing {
        cone,
        sides: SidePlanes::new(&planes),
        excluded,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Rng;

    /// A walk passes the bounds a sphere straddles down to the spheres
    /// inside it: classifying a sphere inside another with those bounds
    /// answers as testing every bound does, and so does asking only
    /// whether it meets the set.
    #[test]
    fn bounds_passed_down_answer_as_every_bound_and_meeting_as_classifying() {
        let mut rng = Rng::new(5);
        let lens = Lens {
            fov_deg: 45.0,
            aspect: 1.5,
        };
        let mut seen = [0usize; 3];
        let mut meets_seen = [0usize; 2];
        for _ in 0..200 {
            let lo = rng.in_box(DVec3::splat(-50.0), DVec3::splat(50.0));
            let ext = DVec3::new(
                rng.range(1.0, 30.0),
                rng.range(0.0, 5.0),
                rng.range(1.0, 30.0),
            );
            let level = 2 + (rng.next_u64() % 3) as u8;
            let n = 1u64 << level;
            let vdi = Vdi {
                face: (rng.next_u64() % 6) as u8,
                level,
                iu: (rng.next_u64() % n) as u32,
                iv: (rng.next_u64() % n) as u32,
            };
            let set = enclosing_cone(&Aabb::new(lo, lo + ext), &vdi, &lens);
            for _ in 0..200 {
                let c = rng.in_box(DVec3::splat(-300.0), DVec3::splat(300.0));
                let r = rng.range(1.0, 60.0);
                let (overlap, left) = set.classify_within(c, r, set.all_bounds());
                let cr = r * rng.range(0.0, 0.9);
                let off = rng.in_box(DVec3::splat(-1.0), DVec3::splat(1.0));
                let child = c + off.normalize_or_zero() * (r - cr) * rng.range(0.0, 0.99);
                let full = set.classify(child, cr);
                let passed = match overlap {
                    Overlap::Outside => Overlap::Outside,
                    Overlap::Inside => Overlap::Inside,
                    Overlap::Partial => set.classify_within(child, cr, left).0,
                };
                assert_eq!(passed, full, "sphere {child} r {cr} in {c} r {r}");
                // The test of whether a sphere meets the set answers as the
                // classification does, with every bound and with those
                // passed down.
                assert_eq!(
                    set.meets_within(c, r, set.all_bounds()),
                    overlap != Overlap::Outside
                );
                if overlap == Overlap::Partial {
                    let meets = set.meets_within(child, cr, left);
                    assert_eq!(meets, full != Overlap::Outside, "sphere {child} r {cr}");
                    meets_seen[usize::from(meets)] += 1;
                }
                seen[overlap as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&k| k > 100), "{seen:?}");
        assert!(meets_seen.iter().all(|&k| k > 100), "{meets_seen:?}");
    }
}
