//! Rays in world and local space, and their `f32` box and triangle tests.

use glam::{DVec3, Vec3A, Vec4};

use super::bvh::{Child, InstanceItem, Quad, Tri};

/// Barycentric tolerance of the `f32` triangle test: triangles are grown by
/// this fraction so rays through a shared edge hit one of its triangles.
pub(super) const BARY_EPS: f32 = 4e-6;

/// Relative padding of a ray's box interval, covering the rounding of the
/// slab test.
pub(super) const SLAB_PAD: f32 = 1e-6;

/// A ray for `f32` box and triangle tests.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ray32 {
    pub(super) o: Vec3A,
    pub(super) d: Vec3A,
    /// Reciprocal direction, with zero components replaced by a tiny value
    /// of the same sign so the slab test never computes `0 · ∞`.
    pub(super) inv: Vec3A,
    pub(super) tmin: f32,
    /// Origin and reciprocal direction per axis, splatted for node tests.
    pub(super) splat: [Vec4; 6],
    /// Per axis, the index into [`Quad::bounds`] of the plane the ray
    /// enters by (min for a positive direction) and the one it leaves by.
    pub(super) near: [usize; 3],
    pub(super) far: [usize; 3],
}

impl Ray32 {
    #[inline(always)]
    pub(super) fn new(o: Vec3A, d: Vec3A, tmin: f32) -> Ray32 {
        // Finite, so no ray meets an unused slot's box at +∞.
        let tmin = tmin.max(-f32::MAX);
        let tiny = Vec3A::splat(1e-30);
        let inv = Vec3A::ONE / Vec3A::select(d.abs().cmplt(tiny), tiny.copysign(d), d);
        let neg = |a: usize| usize::from(inv[a] < 0.0) * 3;
        Ray32 {
            o,
            d,
            inv,
            tmin,
            splat: [
                Vec4::splat(o.x),
                Vec4::splat(o.y),
                Vec4::splat(o.z),
                Vec4::splat(inv.x),
                Vec4::splat(inv.y),
                Vec4::splat(inv.z),
            ],
            near: [neg(0), 1 + neg(1), 2 + neg(2)],
            far: [3 - neg(0), 4 - neg(1), 5 - neg(2)],
        }
    }

    /// Whether the ray meets a box within `[tmin, tmax]` (padded for
    /// rounding).
    #[inline(always)]
    pub(super) fn enters(&self, c: &Child, tmax: f32) -> bool {
        let lo = (Vec3A::from(c.min) - self.o) * self.inv;
        let hi = (Vec3A::from(c.max) - self.o) * self.inv;
        let near = lo.min(hi).max_element() * (1.0 - SLAB_PAD);
        let far = lo.max(hi).min_element() * (1.0 + SLAB_PAD);
        near.max(self.tmin) <= far.min(tmax)
    }

    /// The four boxes of a quad at once: the entry `t` of each and a mask of
    /// the boxes met within `[tmin, tmax]`.
    #[inline(always)]
    pub(super) fn enter_quad(&self, q: &Quad, tmax: f32) -> (Vec4, u32) {
        let [ox, oy, oz, ix, iy, iz] = self.splat;
        let b = &q.bounds;
        let near = ((b[self.near[0]] - ox) * ix)
            .max((b[self.near[1]] - oy) * iy)
            .max((b[self.near[2]] - oz) * iz);
        let far = ((b[self.far[0]] - ox) * ix)
            .min((b[self.far[1]] - oy) * iy)
            .min((b[self.far[2]] - oz) * iz);
        let entry = (near * (1.0 - SLAB_PAD)).max(Vec4::splat(self.tmin));
        let exit = (far * (1.0 + SLAB_PAD)).min(Vec4::splat(tmax.min(f32::MAX)));
        (entry, entry.cmple(exit).bitmask())
    }
}

/// A world ray with its query range.
pub(super) struct WorldRay {
    pub(super) origin: DVec3,
    pub(super) dir: DVec3,
    pub(super) tmin: f64,
    pub(super) tmax: f64,
    pub(super) r32: Ray32,
    pub(super) r32_tmax: f32,
}

impl WorldRay {
    pub(super) fn new(origin: DVec3, dir: DVec3, tmin: f64, tmax: f64) -> Option<WorldRay> {
        let valid = origin.is_finite()
            && dir.is_finite()
            && dir != DVec3::ZERO
            && !tmin.is_nan()
            && !tmax.is_nan()
            && tmin < tmax;
        valid.then(|| WorldRay {
            origin,
            dir,
            tmin,
            tmax,
            r32: Ray32::new(origin.as_vec3a(), dir.as_vec3a(), coarse_tmin(tmin)),
            // Slightly beyond `tmax`: the exact comparison is done in `f64`.
            r32_tmax: {
                let t = tmax as f32;
                t + t.abs() * 1e-5
            },
        })
    }

    /// The ray in an instance's local space (same `t`).
    #[inline(always)]
    pub(super) fn to_local(&self, inst: &InstanceItem) -> Option<LocalRay> {
        let o = inst.world_to_local.transform_point3(self.origin);
        let d = inst.world_to_local.transform_vector3(self.dir);
        (o.is_finite() && d.is_finite()).then(|| LocalRay {
            o,
            d,
            r32: Ray32::new(o.as_vec3a(), d.as_vec3a(), coarse_tmin(self.tmin)),
        })
    }
}

/// A `tmin` for the `f32` tests a little below the exact one (the exact
/// comparison is done in `f64`).
pub(super) fn coarse_tmin(tmin: f64) -> f32 {
    let t = tmin as f32;
    t - t.abs() * 1e-4
}

/// A ray in an instance's local space.
pub(super) struct LocalRay {
    pub(super) o: DVec3,
    pub(super) d: DVec3,
    pub(super) r32: Ray32,
}

impl LocalRay {
    /// Möller–Trumbore in `f32` with `t` in `(tmin, tmax]`, then `t` and the
    /// facing recomputed in `f64` against the triangle's plane. Returns
    /// `(t, front)` with `front` in local winding.
    #[inline(always)]
    pub(super) fn intersect(&self, tri: &Tri, tmax: f32) -> Option<(f64, bool)> {
        let r = &self.r32;
        let v0 = Vec3A::from(tri.v0);
        let e1 = Vec3A::from(tri.v1) - v0;
        let e2 = Vec3A::from(tri.v2) - v0;
        let p = r.d.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 {
            return None;
        }
        let inv = 1.0 / det;
        let s = r.o - v0;
        let u = s.dot(p) * inv;
        if !((-BARY_EPS..=1.0 + BARY_EPS).contains(&u)) {
            return None;
        }
        let q = s.cross(e1);
        let v = r.d.dot(q) * inv;
        if !(v >= -BARY_EPS && u + v <= 1.0 + BARY_EPS) {
            return None;
        }
        let t = e2.dot(q) * inv;
        if !(t > r.tmin && t <= tmax) {
            return None;
        }
        // det = −d · (e1 × e2): positive when the ray meets the front side.
        let (v0, v1, v2) = (tri.v0.as_dvec3(), tri.v1.as_dvec3(), tri.v2.as_dvec3());
        let n = (v1 - v0).cross(v2 - v0);
        let dn = self.d.dot(n);
        let t64 = (v0 - self.o).dot(n) / dn;
        if dn != 0.0 && t64.is_finite() {
            Some((t64, dn < 0.0))
        } else {
            Some((f64::from(t), det > 0.0))
        }
    }
}
