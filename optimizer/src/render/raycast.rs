//! Ray casting against a scene's triangles with a renderer's rules: back
//! faces of single-sided materials are culled, non-opaque (mask, blend)
//! surfaces are seen but do not block, everything else blocks.
//!
//! A two-level BVH: one bottom-level BVH per distinct mesh in its local space
//! (built in parallel), one top-level BVH over the world boxes of the
//! instances (one instance per leaf). Both are built as binary BVHs with
//! `obvhs` and collapsed to 4-wide nodes whose boxes are tested together,
//! visited nearest first while the search range shrinks with each hit. Rays
//! enter an instance through its inverse transform; the direction is
//! transformed without normalising, so the ray parameter `t` is the same in
//! world and local space. Opaque and non-opaque instances have separate
//! top-level BVHs: only opaque ones are searched for the blocking hit, only
//! non-opaque ones for what is seen through.
//!
//! Intersections are found in `f32` in local space (Möller–Trumbore, with a
//! tiny barycentric tolerance so rays do not leak through shared edges); each
//! accepted hit's `t` and facing are then recomputed in `f64` against the
//! triangle's plane, so the reported `t` and the range checks against
//! `tmin`/`tmax` do not suffer from `f32` cancellation far from the origin.
//!
//! Facing follows the winding: the front side is the side
//! `cross(v1 − v0, v2 − v0)` points to, in world space (an instance whose
//! transform has a negative determinant flips it).

use std::time::Duration;

use glam::{DAffine3, DVec3, Vec3, Vec3A, Vec4};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use rayon::prelude::*;

use crate::scene::geometry::{MeshData, SceneGeometry};
use crate::scene::material::{AlphaMode, Material};

/// A ray's hit on a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Object id of the surface.
    pub object: u32,
    /// Ray parameter: the hit is at `origin + t · dir`.
    pub t: f64,
    /// Whether the ray hit the front side (in world space).
    pub front: bool,
}

/// A ray caster over the triangles of a [`SceneGeometry`], built once and
/// shared between threads (`&self` queries only).
#[derive(Clone, Debug, Default)]
pub struct RayCaster {
    /// Bottom-level BVHs, by mesh index (empty for unused or empty meshes).
    blas: Vec<Blas>,
    /// Instances whose material is opaque.
    opaque: Tlas,
    /// Instances whose material is non-opaque (mask or blend).
    see_through: Tlas,
    /// World triangles over all instances.
    triangles: u64,
}

impl RayCaster {
    /// Builds the BVHs of a scene. Degenerate (zero-area or non-finite)
    /// triangles, empty meshes and instances with a singular or non-finite
    /// transform or an unknown mesh are left out: they are never hit.
    pub fn new(geom: &SceneGeometry) -> RayCaster {
        let mut used = vec![false; geom.meshes.len()];
        for inst in &geom.instances {
            if let Some(u) = used.get_mut(inst.mesh as usize) {
                *u = true;
            }
        }
        let blas: Vec<Blas> = geom
            .meshes
            .par_iter()
            .zip(used.par_iter())
            .map(|(mesh, &used)| {
                if used {
                    Blas::new(mesh)
                } else {
                    Blas::default()
                }
            })
            .collect();

        let mut triangles = 0;
        let mut opaque = Vec::new();
        let mut see_through = Vec::new();
        for inst in &geom.instances {
            let Some(mesh) = geom.meshes.get(inst.mesh as usize) else {
                continue;
            };
            triangles += mesh.indices.len() as u64 / 3;
            let Some(root) = blas[inst.mesh as usize].tree.root else {
                continue;
            };
            let det = inst.transform.matrix3.determinant();
            let inv = inst.transform.inverse();
            if !(det != 0.0 && det.is_finite() && inv.is_finite()) {
                continue;
            }
            let default_material = Material::default();
            let material = geom
                .materials
                .get(mesh.material as usize)
                .unwrap_or(&default_material);
            let item = InstanceItem {
                world_to_local: inv,
                object: inst.object,
                blas: inst.mesh,
                flip: det < 0.0,
                double_sided: material.double_sided,
            };
            let bounds = world_box(&inst.transform, &root);
            match material.alpha_mode {
                AlphaMode::Opaque => opaque.push((bounds, item)),
                AlphaMode::Mask { .. } | AlphaMode::Blend => see_through.push((bounds, item)),
            }
        }
        RayCaster {
            blas,
            opaque: Tlas::new(opaque),
            see_through: Tlas::new(see_through),
            triangles,
        }
    }

    /// The nearest blocking hit with `t` in `(tmin, tmax]`, or `None`.
    ///
    /// `dir` need not be a unit vector: `t` is in units of `|dir|`. A ray
    /// with a zero or non-finite direction or origin, or an empty or NaN
    /// range, hits nothing.
    pub fn first_hit(&self, origin: DVec3, dir: DVec3, tmin: f64, tmax: f64) -> Option<Hit> {
        let ray = WorldRay::new(origin, dir, tmin, tmax)?;
        self.blocking(&ray, &mut Stack::new(), false)
    }

    /// Calls `visible(object)` for every object the ray reaches up to and
    /// including its first blocking hit (with `t` in `(tmin, tmax]`): the
    /// blocking one and those seen on non-opaque surfaces in front of it
    /// (not culled as single-sided back faces). Returns the blocking hit, as
    /// [`RayCaster::first_hit`] does.
    ///
    /// The order of the calls is unspecified and an object may be reported
    /// more than once (once per instance that shows it); callers dedupe.
    /// Non-opaque surfaces exactly at the blocking hit's `t` are reported.
    pub fn trace(
        &self,
        origin: DVec3,
        dir: DVec3,
        tmin: f64,
        tmax: f64,
        visible: &mut impl FnMut(u32),
    ) -> Option<Hit> {
        let ray = WorldRay::new(origin, dir, tmin, tmax)?;
        let mut stack = Stack::new();
        let hit = self.blocking(&ray, &mut stack, false);
        if let Some(h) = hit {
            visible(h.object);
        }
        let limit = hit.map_or(tmax, |h| h.t);
        // Coarse `f32` bound, slightly beyond the limit so a surface coplanar
        // with the blocking one is still tested; the exact test is in `f64`.
        let mut coarse = limit as f32;
        coarse += coarse.abs() * 1e-5;
        let tlas = &self.see_through;
        tlas.tree.traverse(
            &ray.r32,
            &mut coarse,
            &mut stack,
            |first, count, tcur, stack| {
                for inst in &tlas.items[first..first + count] {
                    let Some(local) = ray.to_local(inst) else {
                        continue;
                    };
                    let blas = &self.blas[inst.blas as usize];
                    let mut seen = false;
                    let mut t_inst = *tcur;
                    blas.tree
                        .traverse(&local.r32, &mut t_inst, stack, |f, c, t_inst, _| {
                            for tri in &blas.tris[f..f + c] {
                                if let Some((t, front)) = local.intersect(tri, *t_inst)
                                    && (front != inst.flip || inst.double_sided)
                                    && t > ray.tmin
                                    && t <= limit
                                {
                                    seen = true;
                                    return false;
                                }
                            }
                            true
                        });
                    if seen {
                        visible(inst.object);
                    }
                }
                true
            },
        );
        hit
    }

    /// True when nothing blocks the segment from `a` to `b` away from its
    /// ends: no blocking hit with segment parameter in `(1e-5, 1 − 1e-5]`.
    /// A surface through `a` or `b` itself (such as the point of an object
    /// tested for visibility from `a`) does not block. Stops at the first
    /// blocking hit found, so it is cheaper than [`RayCaster::first_hit`].
    pub fn segment_clear(&self, a: DVec3, b: DVec3) -> bool {
        const EPS: f64 = 1e-5;
        let Some(ray) = WorldRay::new(a, b - a, EPS, 1.0 - EPS) else {
            return true;
        };
        self.blocking(&ray, &mut Stack::new(), true).is_none()
    }

    /// World triangles: the sum over instances of their mesh's triangles
    /// (degenerate ones included, as [`SceneGeometry::triangle_count`]).
    pub fn triangle_count(&self) -> u64 {
        self.triangles
    }

    /// Approximate heap footprint of the BVHs and triangles, bytes.
    pub fn memory_bytes(&self) -> u64 {
        let blas: usize = self
            .blas
            .iter()
            .map(|b| {
                std::mem::size_of::<Blas>()
                    + b.tree.quads.capacity() * std::mem::size_of::<Quad>()
                    + b.tris.capacity() * std::mem::size_of::<Tri>()
            })
            .sum();
        let tlas = |t: &Tlas| {
            t.tree.quads.capacity() * std::mem::size_of::<Quad>()
                + t.items.capacity() * std::mem::size_of::<InstanceItem>()
        };
        (blas + tlas(&self.opaque) + tlas(&self.see_through)) as u64
    }

    /// The nearest blocking hit; with `any`, the first one found (for
    /// occlusion tests, whose caller only needs to know whether one exists).
    fn blocking(&self, ray: &WorldRay, stack: &mut Stack, any: bool) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tcur = ray.r32_tmax;
        let tlas = &self.opaque;
        tlas.tree
            .traverse(&ray.r32, &mut tcur, stack, |first, count, tcur, stack| {
                for inst in &tlas.items[first..first + count] {
                    let Some(local) = ray.to_local(inst) else {
                        continue;
                    };
                    let blas = &self.blas[inst.blas as usize];
                    let go_on = blas
                        .tree
                        .traverse(&local.r32, tcur, stack, |f, c, tcur, _| {
                            for tri in &blas.tris[f..f + c] {
                                let Some((t, front_local)) = local.intersect(tri, *tcur) else {
                                    continue;
                                };
                                let front = front_local != inst.flip;
                                if !(front || inst.double_sided)
                                    || !(t > ray.tmin && t <= ray.tmax)
                                    || best.is_some_and(|b| t >= b.t)
                                {
                                    continue;
                                }
                                best = Some(Hit {
                                    object: inst.object,
                                    t,
                                    front,
                                });
                                *tcur = tcur.min(t as f32);
                                if any {
                                    return false;
                                }
                            }
                            true
                        });
                    if !go_on {
                        return false;
                    }
                }
                true
            });
        best
    }
}

/// Barycentric tolerance of the `f32` triangle test: triangles are grown by
/// this fraction so rays through a shared edge hit one of its triangles.
const BARY_EPS: f32 = 4e-6;

/// Relative padding of a ray's box interval, covering the rounding of the
/// slab test.
const SLAB_PAD: f32 = 1e-6;

/// A node's box and either its child node or its leaf range (the root; the
/// other nodes live in [`Quad`]s).
#[derive(Clone, Copy, Debug, Default)]
struct Child {
    min: Vec3,
    max: Vec3,
    /// Leaf item count; 0 for an inner node.
    count: u32,
    /// Inner node: index of its [`Quad`]. Leaf: first item.
    first: u32,
}

/// The up to four children of an inner node, boxes laid out so one 4-wide
/// slab test covers all of them. An unused slot has a box at `+∞`, which no
/// ray meets (the tests clamp `tmax` to `f32::MAX`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Quad {
    /// Per child: min x, y, z, then max x, y, z.
    bounds: [Vec4; 6],
    /// Leaf item count per child; 0 for an inner node (or an unused slot).
    count: [u32; 4],
    /// Per child: index of its quad (inner) or first item (leaf).
    first: [u32; 4],
}

impl Quad {
    const EMPTY: Quad = Quad {
        bounds: [Vec4::INFINITY; 6],
        count: [0; 4],
        first: [0; 4],
    };

    fn set(&mut self, slot: usize, c: &Child) {
        for axis in 0..3 {
            self.bounds[axis][slot] = c.min[axis];
            self.bounds[axis + 3][slot] = c.max[axis];
        }
        self.count[slot] = c.count;
        self.first[slot] = c.first;
    }
}

/// A 4-wide BVH (collapsed from an `obvhs` binary one); leaves address a
/// reordered item array.
#[derive(Clone, Debug, Default)]
struct Tree {
    /// The root, or `None` for no items.
    root: Option<Child>,
    /// Inner nodes in depth-first order.
    quads: Vec<Quad>,
}

impl Tree {
    /// Builds a tree over boxes; returns it with the item order of its
    /// leaves (leaf `first..first + count` are `order[first..first + count]`).
    fn build(boxes: &[Aabb], params: BvhBuildParams) -> (Tree, Vec<u32>) {
        if boxes.is_empty() {
            return (Tree::default(), Vec::new());
        }
        let bvh = build_bvh2(boxes, params, &mut Duration::default());
        let nodes = &bvh.nodes;
        let mut quads: Vec<Quad> = Vec::with_capacity(nodes.len() / 3 + 1);
        let mut order = Vec::with_capacity(boxes.len());
        let mut root = Child::default();
        // (obvhs node, destination: None = root, Some((quad, slot))).
        let mut work: Vec<(u32, Option<(usize, usize)>)> = vec![(0, None)];
        while let Some((index, dest)) = work.pop() {
            let node = &nodes[index as usize];
            let aabb = node.aabb();
            let mut child = Child {
                min: aabb.min.into(),
                max: aabb.max.into(),
                ..Child::default()
            };
            if node.is_leaf() {
                let range =
                    node.first_index as usize..(node.first_index + node.prim_count) as usize;
                child.count = node.prim_count;
                child.first = order.len() as u32;
                order.extend_from_slice(&bvh.primitive_indices[range]);
            } else {
                // Open the largest inner descendants until there are four.
                let mut kids = vec![node.first_index, node.first_index + 1];
                while kids.len() < 4 {
                    let widest = kids
                        .iter()
                        .enumerate()
                        .filter(|(_, k)| !nodes[**k as usize].is_leaf())
                        .max_by(|a, b| {
                            let area = |k: &u32| nodes[*k as usize].aabb().half_area();
                            area(a.1).total_cmp(&area(b.1))
                        })
                        .map(|(i, _)| i);
                    let Some(i) = widest else { break };
                    let first = nodes[kids[i] as usize].first_index;
                    kids[i] = first;
                    kids.push(first + 1);
                }
                child.first = quads.len() as u32;
                quads.push(Quad::EMPTY);
                // Slot 0 popped first: each subtree's quads are contiguous.
                for (slot, &k) in kids.iter().enumerate().rev() {
                    work.push((k, Some((child.first as usize, slot))));
                }
            }
            match dest {
                None => root = child,
                Some((quad, slot)) => quads[quad].set(slot, &child),
            }
        }
        (
            Tree {
                root: Some(root),
                quads,
            },
            order,
        )
    }

    /// Visits the leaves the ray enters before `tmax`, nearest entry first
    /// within each node, calling `leaf(first, count, tmax, stack)`; `leaf`
    /// may lower `tmax`, and returns false to stop. Returns false when
    /// stopped. The stack is shared with nested traversals and left as found.
    #[inline(always)]
    fn traverse<F>(&self, ray: &Ray32, tmax: &mut f32, stack: &mut Stack, mut leaf: F) -> bool
    where
        F: FnMut(usize, usize, &mut f32, &mut Stack) -> bool,
    {
        let Some(root) = &self.root else {
            return true;
        };
        if !ray.enters(root, *tmax) {
            return true;
        }
        if root.count > 0 {
            return leaf(root.first as usize, root.count as usize, tmax, stack);
        }
        let base = stack.len();
        let mut current = root.first;
        loop {
            let quad = &self.quads[current as usize];
            let (entry, mask) = ray.enter_quad(quad, *tmax);
            let entry = entry.to_array();
            let mut next: Option<(f32, u32)> = None;
            macro_rules! leaf {
                ($slot:expr) => {
                    let (first, count) = (quad.first[$slot] as usize, quad.count[$slot] as usize);
                    if !leaf(first, count, tmax, stack) {
                        stack.truncate(base);
                        return false;
                    }
                };
            }
            if mask & mask.wrapping_sub(1) == 0 {
                // At most one child met: the common case.
                if mask != 0 {
                    let slot = mask.trailing_zeros() as usize;
                    if quad.count[slot] > 0 {
                        leaf!(slot);
                    } else {
                        next = Some((entry[slot], quad.first[slot]));
                    }
                }
            } else {
                // The children met, sorted by entry (insertion sort of ≤ 4).
                let mut hits = [(0f32, 0usize); 4];
                let mut n = 0;
                let mut bits = mask;
                while bits != 0 {
                    let slot = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let t = entry[slot];
                    let mut i = n;
                    while i > 0 && hits[i - 1].0 > t {
                        hits[i] = hits[i - 1];
                        i -= 1;
                    }
                    hits[i] = (t, slot);
                    n += 1;
                }
                // Leaves first, nearest first (they may lower `tmax`); then
                // inner nodes: the nearest next, the others on the stack.
                for &(t, slot) in &hits[..n] {
                    if t > *tmax {
                        break;
                    }
                    if quad.count[slot] > 0 {
                        leaf!(slot);
                    }
                }
                for &(t, slot) in hits[..n].iter().rev() {
                    if quad.count[slot] == 0
                        && t <= *tmax
                        && let Some((t_far, q_far)) = next.replace((t, quad.first[slot]))
                    {
                        stack.push((q_far, t_far));
                    }
                }
            }
            match next {
                Some((_, q)) => current = q,
                None => loop {
                    match stack.pop_above(base) {
                        Some((q, t)) if t <= *tmax => {
                            current = q;
                            break;
                        }
                        Some(_) => {}
                        None => return true,
                    }
                },
            }
        }
    }
}

/// A traversal stack: inline for the usual depths, spilling to the heap for
/// deep (degenerate) trees.
struct Stack {
    inline: [(u32, f32); 64],
    len: usize,
    /// Used only while `inline` is full.
    spill: Vec<(u32, f32)>,
}

impl Stack {
    fn new() -> Stack {
        Stack {
            inline: [(0, 0.0); 64],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    fn len(&self) -> usize {
        self.len + self.spill.len()
    }

    #[inline(always)]
    fn push(&mut self, e: (u32, f32)) {
        if self.len < self.inline.len() {
            self.inline[self.len] = e;
            self.len += 1;
        } else {
            self.spill.push(e);
        }
    }

    /// Pops an entry if the stack holds more than `base`.
    #[inline(always)]
    fn pop_above(&mut self, base: usize) -> Option<(u32, f32)> {
        if self.len() <= base {
            return None;
        }
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }

    fn truncate(&mut self, n: usize) {
        if n < self.inline.len() {
            self.spill.clear();
            self.len = self.len.min(n);
        } else {
            self.spill.truncate(n - self.inline.len());
        }
    }
}

/// A triangle in local space.
#[derive(Clone, Copy, Debug)]
struct Tri {
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
}

/// A mesh's bottom-level BVH with its triangles in leaf order.
#[derive(Clone, Debug, Default)]
struct Blas {
    tree: Tree,
    tris: Vec<Tri>,
}

impl Blas {
    fn new(mesh: &MeshData) -> Blas {
        let p = &mesh.positions;
        let mut tris = Vec::with_capacity(mesh.indices.len() / 3);
        for ids in mesh.indices.chunks_exact(3) {
            let (Some(&a), Some(&b), Some(&c)) = (
                p.get(ids[0] as usize),
                p.get(ids[1] as usize),
                p.get(ids[2] as usize),
            ) else {
                continue;
            };
            let tri = Tri {
                v0: a,
                v1: b,
                v2: c,
            };
            if !degenerate(&tri) {
                tris.push(tri);
            }
        }
        let boxes: Vec<Aabb> = tris.iter().map(tri_box).collect();
        let (tree, order) = Tree::build(&boxes, BvhBuildParams::medium_build());
        let tris = order.iter().map(|&i| tris[i as usize]).collect();
        Blas { tree, tris }
    }
}

/// Zero-area (to `f32` precision) or non-finite: never hit.
fn degenerate(tri: &Tri) -> bool {
    let (v0, v1, v2) = (tri.v0.as_dvec3(), tri.v1.as_dvec3(), tri.v2.as_dvec3());
    if !(v0.is_finite() && v1.is_finite() && v2.is_finite()) {
        return true;
    }
    let (e1, e2) = (v1 - v0, v2 - v0);
    e1.cross(e2).length() <= 1e-7 * e1.length() * e2.length()
}

/// A triangle's box, padded to contain every point the tolerant `f32`
/// intersection test accepts.
fn tri_box(tri: &Tri) -> Aabb {
    let min = Vec3A::from(tri.v0.min(tri.v1).min(tri.v2));
    let max = Vec3A::from(tri.v0.max(tri.v1).max(tri.v2));
    let pad = (max - min).max_element() * 1e-5 + min.abs().max(max.abs()).max_element() * 1e-6;
    Aabb::new(min - pad, max + pad)
}

/// The world box of a local box under an affine transform, padded for the
/// rounding to `f32`.
fn world_box(transform: &DAffine3, local: &Child) -> Aabb {
    let (lo, hi) = (local.min.as_dvec3(), local.max.as_dvec3());
    let mut min = DVec3::INFINITY;
    let mut max = DVec3::NEG_INFINITY;
    for k in 0..8 {
        let corner = DVec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let w = transform.transform_point3(corner);
        min = min.min(w);
        max = max.max(w);
    }
    let pad = (max - min).max_element() * 1e-5 + min.abs().max(max.abs()).max_element() * 1e-6;
    Aabb::new((min - pad).as_vec3a(), (max + pad).as_vec3a())
}

/// An instance in a top-level BVH.
#[derive(Clone, Copy, Debug)]
struct InstanceItem {
    world_to_local: DAffine3,
    object: u32,
    /// Index into [`RayCaster::blas`].
    blas: u32,
    /// The transform mirrors (negative determinant): local winding flips.
    flip: bool,
    double_sided: bool,
}

/// A top-level BVH over instances.
#[derive(Clone, Debug, Default)]
struct Tlas {
    tree: Tree,
    /// Instances in leaf order.
    items: Vec<InstanceItem>,
}

impl Tlas {
    fn new(instances: Vec<(Aabb, InstanceItem)>) -> Tlas {
        let boxes: Vec<Aabb> = instances.iter().map(|(b, _)| *b).collect();
        // One instance per leaf, so each instance's box is tested before its
        // ray is transformed; a thorough build pays off (instances are few).
        let params = BvhBuildParams {
            max_prims_per_leaf: 1,
            ..BvhBuildParams::very_slow_build()
        };
        let (tree, order) = Tree::build(&boxes, params);
        let items = order.iter().map(|&i| instances[i as usize].1).collect();
        Tlas { tree, items }
    }
}

/// A ray for `f32` box and triangle tests.
#[derive(Clone, Copy, Debug)]
struct Ray32 {
    o: Vec3A,
    d: Vec3A,
    /// Reciprocal direction, with zero components replaced by a tiny value
    /// of the same sign so the slab test never computes `0 · ∞`.
    inv: Vec3A,
    tmin: f32,
    /// Origin and reciprocal direction per axis, splatted for node tests.
    splat: [Vec4; 6],
    /// Per axis, the index into [`Quad::bounds`] of the plane the ray
    /// enters by (min for a positive direction) and the one it leaves by.
    near: [usize; 3],
    far: [usize; 3],
}

impl Ray32 {
    #[inline(always)]
    fn new(o: Vec3A, d: Vec3A, tmin: f32) -> Ray32 {
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
    fn enters(&self, c: &Child, tmax: f32) -> bool {
        let lo = (Vec3A::from(c.min) - self.o) * self.inv;
        let hi = (Vec3A::from(c.max) - self.o) * self.inv;
        let near = lo.min(hi).max_element() * (1.0 - SLAB_PAD);
        let far = lo.max(hi).min_element() * (1.0 + SLAB_PAD);
        near.max(self.tmin) <= far.min(tmax)
    }

    /// The four boxes of a quad at once: the entry `t` of each and a mask of
    /// the boxes met within `[tmin, tmax]`.
    #[inline(always)]
    fn enter_quad(&self, q: &Quad, tmax: f32) -> (Vec4, u32) {
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
struct WorldRay {
    origin: DVec3,
    dir: DVec3,
    tmin: f64,
    tmax: f64,
    r32: Ray32,
    r32_tmax: f32,
}

impl WorldRay {
    fn new(origin: DVec3, dir: DVec3, tmin: f64, tmax: f64) -> Option<WorldRay> {
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
    fn to_local(&self, inst: &InstanceItem) -> Option<LocalRay> {
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
fn coarse_tmin(tmin: f64) -> f32 {
    let t = tmin as f32;
    t - t.abs() * 1e-4
}

/// A ray in an instance's local space.
struct LocalRay {
    o: DVec3,
    d: DVec3,
    r32: Ray32,
}

impl LocalRay {
    /// Möller–Trumbore in `f32` with `t` in `(tmin, tmax]`, then `t` and the
    /// facing recomputed in `f64` against the triangle's plane. Returns
    /// `(t, front)` with `front` in local winding.
    #[inline(always)]
    fn intersect(&self, tri: &Tri, tmax: f32) -> Option<(f64, bool)> {
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

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use glam::{DQuat, Vec3};

    use super::*;
    use crate::math::rng::Rng;
    use crate::scene::geometry::Instance;

    fn mesh(positions: Vec<Vec3>, indices: Vec<u32>, material: u32) -> MeshData {
        MeshData {
            positions,
            indices,
            material,
            ..MeshData::default()
        }
    }

    fn material(alpha_mode: AlphaMode, double_sided: bool) -> Material {
        Material {
            alpha_mode,
            double_sided,
            ..Material::default()
        }
    }

    /// Unit quad in the plane z = 0, normal `+z`.
    fn quad(material: u32) -> MeshData {
        mesh(
            vec![
                Vec3::new(-0.5, -0.5, 0.0),
                Vec3::new(0.5, -0.5, 0.0),
                Vec3::new(0.5, 0.5, 0.0),
                Vec3::new(-0.5, 0.5, 0.0),
            ],
            vec![0, 1, 2, 0, 2, 3],
            material,
        )
    }

    /// Cube `[-0.5, 0.5]³`, outward normals.
    fn cube(material: u32) -> MeshData {
        let mut positions = Vec::new();
        for k in 0..8 {
            positions.push(Vec3::new(
                if k & 1 == 0 { -0.5 } else { 0.5 },
                if k & 2 == 0 { -0.5 } else { 0.5 },
                if k & 4 == 0 { -0.5 } else { 0.5 },
            ));
        }
        // Faces as quads (a, b, c, d) counter-clockwise seen from outside.
        let faces = [
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
        ];
        let mut indices = Vec::new();
        for [a, b, c, d] in faces {
            indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
        mesh(positions, indices, material)
    }

    fn scene(
        meshes: Vec<MeshData>,
        materials: Vec<Material>,
        inst: Vec<Instance>,
    ) -> SceneGeometry {
        let objects = inst
            .iter()
            .map(|i| i.object as usize + 1)
            .max()
            .unwrap_or(0);
        SceneGeometry {
            meshes,
            instances: inst,
            materials,
            textures: Vec::new(),
            objects,
        }
    }

    fn at(object: u32, mesh: u32, transform: DAffine3) -> Instance {
        Instance {
            object,
            mesh,
            transform,
        }
    }

    #[test]
    fn cube_faces_point_outward() {
        let m = cube(0);
        for t in m.indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| m.positions[t[k] as usize]);
            let n = (b - a).cross(c - a);
            let centre = (a + b + c) / 3.0;
            assert!(n.dot(centre) > 0.0, "inward face {t:?}");
        }
    }

    #[test]
    fn quad_hand_computed() {
        // The quad at z = 5 with its normal turned to −z: it faces the origin.
        let facing_origin = DAffine3::from_translation(DVec3::new(0.0, 0.0, 5.0))
            * DAffine3::from_rotation_x(std::f64::consts::PI);
        for double_sided in [false, true] {
            let geom = scene(
                vec![quad(0)],
                vec![material(AlphaMode::Opaque, double_sided)],
                vec![at(7, 0, facing_origin)],
            );
            let rc = RayCaster::new(&geom);
            assert_eq!(rc.triangle_count(), 2);
            let hit = rc
                .first_hit(DVec3::ZERO, DVec3::Z, 0.0, f64::INFINITY)
                .expect("front hit");
            assert_eq!(hit.object, 7);
            assert!(hit.front);
            assert!((hit.t - 5.0).abs() < 1e-9, "t = {}", hit.t);
            // A non-unit direction: t is in units of |dir|.
            let hit = rc.first_hit(DVec3::ZERO, DVec3::Z * 2.0, 0.0, f64::INFINITY);
            assert!((hit.unwrap().t - 2.5).abs() < 1e-9);
            // tmax before the quad.
            assert_eq!(rc.first_hit(DVec3::ZERO, DVec3::Z, 0.0, 4.9), None);
            // Seen from behind (from z = 10 looking down −z).
            let back = rc.first_hit(DVec3::new(0.0, 0.0, 10.0), -DVec3::Z, 0.0, f64::INFINITY);
            if double_sided {
                let back = back.expect("double-sided back face blocks");
                assert!(!back.front);
                assert!((back.t - 5.0).abs() < 1e-9);
            } else {
                assert_eq!(back, None);
            }
            // An unbounded range: the hit behind the origin counts too.
            let behind = rc.first_hit(
                DVec3::new(0.0, 0.0, 8.0),
                DVec3::Z,
                f64::NEG_INFINITY,
                f64::INFINITY,
            );
            assert!((behind.unwrap().t + 3.0).abs() < 1e-9);
            // Missing beside the quad.
            let beside = rc.first_hit(DVec3::new(0.6, 0.0, 0.0), DVec3::Z, 0.0, f64::INFINITY);
            assert_eq!(beside, None);
        }
    }

    #[test]
    fn mirrored_instance_flips_facing() {
        // Local normal −z at z = 5, then mirrored in x: the world winding
        // flips, so the quad now faces +z, away from the origin.
        let t = DAffine3::from_translation(DVec3::new(0.0, 0.0, 5.0))
            * DAffine3::from_scale(DVec3::new(-1.0, 1.0, 1.0))
            * DAffine3::from_rotation_x(std::f64::consts::PI);
        let geom = scene(
            vec![quad(0)],
            vec![material(AlphaMode::Opaque, false)],
            vec![at(0, 0, t)],
        );
        let rc = RayCaster::new(&geom);
        assert_eq!(
            rc.first_hit(DVec3::ZERO, DVec3::Z, 0.0, f64::INFINITY),
            None
        );
        let hit = rc.first_hit(DVec3::new(0.0, 0.0, 10.0), -DVec3::Z, 0.0, f64::INFINITY);
        assert!(hit.unwrap().front);
    }

    #[test]
    fn see_through_surfaces_are_reported_but_do_not_block() {
        // Object 1: masked quad at z = 2 facing the origin; object 2: blended
        // single-sided quad at z = 3 facing away (culled); object 3: opaque
        // cube at z = 6; object 4: masked quad behind the cube (hidden).
        let facing = |z: f64| {
            DAffine3::from_translation(DVec3::new(0.0, 0.0, z))
                * DAffine3::from_rotation_x(std::f64::consts::PI)
        };
        let away = |z: f64| DAffine3::from_translation(DVec3::new(0.0, 0.0, z));
        let geom = scene(
            vec![quad(0), quad(1), cube(2)],
            vec![
                material(AlphaMode::Mask { cutoff: 0.5 }, false),
                material(AlphaMode::Blend, false),
                material(AlphaMode::Opaque, false),
            ],
            vec![
                at(1, 0, facing(2.0)),
                at(2, 1, away(3.0)),
                at(3, 2, away(6.0)),
                at(4, 0, facing(9.0)),
            ],
        );
        let rc = RayCaster::new(&geom);
        let mut seen = BTreeSet::new();
        let hit = rc.trace(DVec3::ZERO, DVec3::Z, 0.0, f64::INFINITY, &mut |o| {
            seen.insert(o);
        });
        let hit = hit.expect("cube blocks");
        assert_eq!(hit.object, 3);
        assert!((hit.t - 5.5).abs() < 1e-9);
        assert_eq!(seen, BTreeSet::from([1, 3]));
        assert_eq!(
            rc.first_hit(DVec3::ZERO, DVec3::Z, 0.0, f64::INFINITY),
            Some(hit)
        );
        // Without a blocker within tmax, everything see-through up to tmax.
        seen.clear();
        let hit = rc.trace(DVec3::ZERO, DVec3::Z, 0.0, 4.0, &mut |o| {
            seen.insert(o);
        });
        assert_eq!(hit, None);
        assert_eq!(seen, BTreeSet::from([1]));
    }

    #[test]
    fn segment_clear_cases() {
        // Target: cube at x = 10; wall: double-sided quad in the plane x = 5
        // spanning y, z ∈ [-1, 1].
        let wall = DAffine3::from_translation(DVec3::new(5.0, 0.0, 0.0))
            * DAffine3::from_rotation_y(std::f64::consts::FRAC_PI_2)
            * DAffine3::from_scale(DVec3::splat(2.0));
        let target = DAffine3::from_translation(DVec3::new(10.0, 0.0, 0.0));
        let materials = vec![
            material(AlphaMode::Opaque, false),
            material(AlphaMode::Opaque, true),
        ];
        let with_wall = scene(
            vec![cube(0), quad(1)],
            materials.clone(),
            vec![at(0, 0, target), at(1, 1, wall)],
        );
        let without = scene(vec![cube(0)], materials, vec![at(0, 0, target)]);
        let a = DVec3::ZERO;
        // A point on the target's face towards `a`, and one on its far face.
        let near_face = DVec3::new(9.5, 0.1, -0.2);
        let far_face = DVec3::new(10.5, 0.1, -0.2);
        let rc = RayCaster::new(&with_wall);
        assert!(!rc.segment_clear(a, near_face), "the wall is in between");
        assert!(!rc.segment_clear(near_face, a), "and from the other side");
        let beside = DVec3::new(0.0, 3.0, 0.0);
        let target_side = DVec3::new(10.0, 3.0, 0.0);
        assert!(
            rc.segment_clear(beside, target_side),
            "passes beside the wall"
        );
        let rc = RayCaster::new(&without);
        assert!(
            rc.segment_clear(a, near_face),
            "the target face itself does not block"
        );
        assert!(rc.segment_clear(near_face, a));
        assert!(
            !rc.segment_clear(a, far_face),
            "the near face hides the far face"
        );
        assert!(rc.segment_clear(a, a));
    }

    #[test]
    fn empty_scenes_hit_nothing() {
        let empty_mesh = mesh(Vec::new(), Vec::new(), 0);
        let degenerate = mesh(
            vec![Vec3::ZERO, Vec3::ONE, Vec3::ONE * 2.0],
            vec![0, 1, 2, 0, 0, 1],
            0,
        );
        let geoms = [
            SceneGeometry::default(),
            scene(
                vec![empty_mesh, degenerate],
                vec![Material::default()],
                vec![
                    at(0, 0, DAffine3::IDENTITY),
                    at(1, 1, DAffine3::IDENTITY),
                    at(2, 7, DAffine3::IDENTITY),
                ],
            ),
            // A singular transform flattens the cube: never hit.
            scene(
                vec![cube(0)],
                vec![Material::default()],
                vec![at(0, 0, DAffine3::from_scale(DVec3::new(1.0, 0.0, 1.0)))],
            ),
        ];
        for geom in &geoms {
            let rc = RayCaster::new(geom);
            let mut rng = Rng::new(5);
            for _ in 0..100 {
                let o = rng.in_box(DVec3::splat(-3.0), DVec3::splat(3.0));
                let d = rng.unit_vector();
                assert_eq!(rc.first_hit(o, d, 0.0, f64::INFINITY), None);
                let mut calls = 0;
                assert_eq!(
                    rc.trace(o, d, 0.0, f64::INFINITY, &mut |_| calls += 1),
                    None
                );
                assert_eq!(calls, 0);
                assert!(rc.segment_clear(o, o + d * 10.0));
            }
            assert!(rc.memory_bytes() < 100_000);
        }
        assert_eq!(RayCaster::new(&geoms[0]).triangle_count(), 0);
        assert_eq!(RayCaster::new(&geoms[1]).triangle_count(), 2);
        // Invalid rays hit nothing.
        let rc = RayCaster::new(&scene(
            vec![cube(0)],
            vec![Material::default()],
            vec![at(0, 0, DAffine3::IDENTITY)],
        ));
        let o = DVec3::new(0.0, 0.0, -5.0);
        assert!(rc.first_hit(o, DVec3::Z, 0.0, f64::INFINITY).is_some());
        assert_eq!(rc.first_hit(o, DVec3::ZERO, 0.0, f64::INFINITY), None);
        assert_eq!(rc.first_hit(o, DVec3::NAN, 0.0, f64::INFINITY), None);
        assert_eq!(rc.first_hit(o, DVec3::Z, 0.0, f64::NAN), None);
    }

    // ---- brute-force oracle ----

    struct WorldTri {
        v: [DVec3; 3],
        object: u32,
        opaque: bool,
        double_sided: bool,
    }

    fn world_tris(geom: &SceneGeometry) -> Vec<WorldTri> {
        let mut out = Vec::new();
        for inst in &geom.instances {
            let Some(m) = geom.meshes.get(inst.mesh as usize) else {
                continue;
            };
            let mat = &geom.materials[m.material as usize];
            for t in m.indices.chunks_exact(3) {
                let v = [0, 1, 2].map(|k| {
                    inst.transform
                        .transform_point3(m.positions[t[k] as usize].as_dvec3())
                });
                let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
                if e1.cross(e2).length() <= 1e-6 * e1.length() * e2.length() {
                    continue;
                }
                out.push(WorldTri {
                    v,
                    object: inst.object,
                    opaque: mat.alpha_mode == AlphaMode::Opaque,
                    double_sided: mat.double_sided,
                });
            }
        }
        out
    }

    /// What the ray should report, or `None` when a hit lies too close to
    /// an edge, a range end or another hit for the answer to be certain.
    struct Expected {
        hit: Option<Hit>,
        seen: BTreeSet<u32>,
    }

    fn brute(tris: &[WorldTri], o: DVec3, d: DVec3, tmin: f64, tmax: f64) -> Option<Expected> {
        const M: f64 = 1e-4;
        let close = |a: f64, b: f64| {
            a.is_finite() && b.is_finite() && (a - b).abs() <= M * a.abs().max(b.abs()).max(1.0)
        };
        // (t, object, front, blocks) of every counted hit.
        let mut hits = Vec::new();
        for tri in tris {
            let [v0, v1, v2] = tri.v;
            let (e1, e2) = (v1 - v0, v2 - v0);
            let n = e1.cross(e2);
            let dn = d.dot(n);
            if dn.abs() < 1e-3 * d.length() * n.length() {
                // Grazing: any answer would be uncertain if it could hit.
                let p = d.cross(e2);
                let det = e1.dot(p);
                if det != 0.0 {
                    let s = o - v0;
                    let (u, v) = (s.dot(p) / det, d.dot(s.cross(e1)) / det);
                    if u > -M && v > -M && u + v < 1.0 + M {
                        return None;
                    }
                }
                continue;
            }
            let t = (v0 - o).dot(n) / dn;
            let x = o + t * d;
            // Barycentrics of x.
            let nn = n.length_squared();
            let b1 = (x - v0).cross(e2).dot(n) / nn;
            let b2 = e1.cross(x - v0).dot(n) / nn;
            let b0 = 1.0 - b1 - b2;
            let margin = b0.min(b1).min(b2);
            if margin < -M {
                continue;
            }
            if margin < M {
                return None;
            }
            if close(t, tmin) || close(t, tmax) {
                return None;
            }
            if !(t > tmin && t <= tmax) {
                continue;
            }
            let front = dn < 0.0;
            if !front && !tri.double_sided {
                continue;
            }
            hits.push((t, tri.object, front, tri.opaque));
        }
        let block = hits
            .iter()
            .filter(|h| h.3)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .copied();
        let limit = block.map_or(tmax, |b| b.0);
        let mut seen = BTreeSet::new();
        for &(t, object, front, opaque) in &hits {
            if let Some(b) = block
                && (t, object, front, opaque) != b
                && close(t, b.0)
            {
                return None;
            }
            if !opaque && t <= limit {
                seen.insert(object);
            }
        }
        let hit = block.map(|(t, object, front, _)| {
            seen.insert(object);
            Hit { object, t, front }
        });
        Some(Expected { hit, seen })
    }

    fn random_transform(rng: &mut Rng, mirror: bool) -> DAffine3 {
        let mut scale = DVec3::new(
            rng.range(0.3, 2.0),
            rng.range(0.3, 2.0),
            rng.range(0.3, 2.0),
        );
        if mirror || rng.f64() < 0.2 {
            scale.x = -scale.x;
        }
        let rotation = DQuat::from_axis_angle(rng.unit_vector(), rng.range(0.0, 6.3));
        let translation = rng.in_box(DVec3::splat(-5.0), DVec3::splat(5.0));
        DAffine3::from_scale_rotation_translation(scale, rotation, translation)
    }

    /// A random scene: cubes, a quad, an empty mesh and a soup of `soup`
    /// random triangles (plus a zero-area one), placed by `instances`
    /// instances (the first one mirrored) of `instances * 5 / 7` objects.
    fn random_scene(rng: &mut Rng, soup: usize, instances: usize) -> SceneGeometry {
        let materials = vec![
            material(AlphaMode::Opaque, false),
            material(AlphaMode::Opaque, true),
            material(AlphaMode::Mask { cutoff: 0.5 }, false),
            material(AlphaMode::Blend, true),
            material(AlphaMode::Mask { cutoff: 0.3 }, true),
            material(AlphaMode::Blend, false),
        ];
        // Mostly opaque (materials 0 and 1), so most rays are blocked.
        let pick = |rng: &mut Rng| {
            let k = (rng.f64() * 10.0) as u32;
            if k < 6 { k % 2 } else { k - 4 }
        };
        let mut soup_mesh = mesh(Vec::new(), Vec::new(), pick(rng));
        // Triangle size shrinks with their number so the soup stays sparse.
        let size = 0.8 / (soup as f64 / 10.0).cbrt();
        for _ in 0..soup {
            let c = rng.in_box(DVec3::splat(-1.0), DVec3::splat(1.0));
            for _ in 0..3 {
                let v = c + rng.unit_vector() * rng.range(0.25, 1.0) * size;
                soup_mesh.indices.push(soup_mesh.positions.len() as u32);
                soup_mesh.positions.push(v.as_vec3());
            }
        }
        // A zero-area triangle.
        let k = soup_mesh.positions.len() as u32;
        soup_mesh
            .positions
            .extend([Vec3::ZERO, Vec3::new(0.5, 0.5, 0.5), Vec3::ONE]);
        soup_mesh.indices.extend([k, k + 1, k + 2]);
        let meshes = vec![
            cube(pick(rng)),
            soup_mesh,
            quad(pick(rng)),
            mesh(Vec::new(), Vec::new(), 0),
            cube(pick(rng)),
        ];
        let objects = (instances * 5 / 7).max(1);
        let placed = (0..instances)
            .map(|i| {
                // Some objects get two instances.
                let object = (i % objects) as u32;
                let m = (rng.f64() * meshes.len() as f64) as u32;
                at(object, m, random_transform(rng, i == 0))
            })
            .collect();
        scene(meshes, materials, placed)
    }

    /// Counts from [`check_against_brute_force`].
    #[derive(Default)]
    struct Stats {
        checked: usize,
        skipped: usize,
        hits: usize,
        mirrored_hits: usize,
        see_through: usize,
    }

    /// Random rays aimed near the instances: `first_hit`, `trace` and
    /// `segment_clear` must agree with the brute-force oracle.
    fn check_against_brute_force(geom: &SceneGeometry, rng: &mut Rng, rays: usize, s: &mut Stats) {
        let tris = world_tris(geom);
        let rc = RayCaster::new(geom);
        assert_eq!(rc.triangle_count(), geom.triangle_count());
        for _ in 0..rays {
            let o = rng.in_box(DVec3::splat(-12.0), DVec3::splat(12.0));
            let inst = &geom.instances[(rng.f64() * geom.instances.len() as f64) as usize];
            let target =
                inst.transform.translation + rng.in_box(DVec3::splat(-0.4), DVec3::splat(0.4));
            let d = (target - o) * rng.range(0.2, 3.0);
            let (tmin, tmax) = if rng.f64() < 0.5 {
                (0.0, f64::INFINITY)
            } else {
                (rng.range(0.0, 0.5), rng.range(0.5, 2.0))
            };
            let Some(want) = brute(&tris, o, d, tmin, tmax) else {
                s.skipped += 1;
                continue;
            };
            s.checked += 1;
            let got = rc.first_hit(o, d, tmin, tmax);
            match (got, want.hit) {
                (None, None) => {}
                (Some(g), Some(w)) => {
                    s.hits += 1;
                    if geom
                        .instances
                        .iter()
                        .any(|i| i.object == w.object && i.transform.matrix3.determinant() < 0.0)
                    {
                        s.mirrored_hits += 1;
                    }
                    assert_eq!(g.object, w.object, "ray {o} {d}");
                    assert_eq!(g.front, w.front, "ray {o} {d}");
                    assert!((g.t - w.t).abs() <= 1e-4 * w.t.abs(), "{} vs {}", g.t, w.t);
                }
                _ => panic!(
                    "ray {o} {d} [{tmin}, {tmax}]: got {got:?}, want {:?}",
                    want.hit
                ),
            }
            let mut seen = BTreeSet::new();
            let traced = rc.trace(o, d, tmin, tmax, &mut |obj| {
                seen.insert(obj);
            });
            assert_eq!(traced, got);
            assert_eq!(seen, want.seen, "ray {o} {d} [{tmin}, {tmax}]");
            if seen.len() > usize::from(got.is_some()) {
                s.see_through += 1;
            }
            // The segment over the same range as an occlusion test.
            if tmax.is_finite() && tmin == 0.0 {
                let clear = rc.segment_clear(o, o + d * tmax);
                if let Some(b) = brute(&tris, o, d * tmax, 1e-5, 1.0 - 1e-5) {
                    assert_eq!(clear, b.hit.is_none(), "segment {o} {d} × {tmax}");
                }
            }
        }
    }

    #[test]
    fn matches_brute_force() {
        let mut rng = Rng::new(42);
        let mut s = Stats::default();
        for _ in 0..40 {
            let geom = random_scene(&mut rng, 10, 14);
            check_against_brute_force(&geom, &mut rng, 300, &mut s);
        }
        assert!(
            s.skipped * 20 < s.checked,
            "{} ambiguous of {}",
            s.skipped,
            s.checked
        );
        assert!(
            s.hits > s.checked / 4,
            "only {} hits of {}",
            s.hits,
            s.checked
        );
        assert!(
            s.mirrored_hits > 100,
            "only {} mirrored hits",
            s.mirrored_hits
        );
        assert!(
            s.see_through > 100,
            "only {} see-through rays",
            s.see_through
        );
    }

    #[test]
    fn matches_brute_force_on_deep_trees() {
        // Several levels of 4-wide nodes in both the top and bottom levels.
        let mut rng = Rng::new(7);
        let mut s = Stats::default();
        for _ in 0..2 {
            let geom = random_scene(&mut rng, 2000, 150);
            check_against_brute_force(&geom, &mut rng, 400, &mut s);
        }
        assert!(
            s.skipped * 10 < s.checked,
            "{} ambiguous of {}",
            s.skipped,
            s.checked
        );
        assert!(
            s.hits > s.checked / 4,
            "only {} hits of {}",
            s.hits,
            s.checked
        );
        assert!(
            s.see_through > 20,
            "only {} see-through rays",
            s.see_through
        );
    }

    #[test]
    fn unbounded_ranges_skip_unused_node_slots() {
        // Three cubes: the top-level root has an unused slot.
        let geom = scene(
            vec![cube(0)],
            vec![Material::default()],
            (0..3)
                .map(|i| {
                    let z = 5.0 * f64::from(i + 1);
                    at(i, 0, DAffine3::from_translation(DVec3::new(0.0, 0.0, z)))
                })
                .collect(),
        );
        let rc = RayCaster::new(&geom);
        let (lo, hi) = (f64::NEG_INFINITY, f64::INFINITY);
        let hit = rc.first_hit(DVec3::ZERO, DVec3::Z, lo, hi).unwrap();
        assert_eq!((hit.object, hit.t), (0, 4.5));
        // Looking down −z, the front faces are the cubes' +z faces, all
        // behind the origin; the farthest back comes first.
        let hit = rc.first_hit(DVec3::ZERO, -DVec3::Z, lo, hi).unwrap();
        assert_eq!((hit.object, hit.t), (2, -15.5));
        assert_eq!(rc.first_hit(DVec3::ZERO, -DVec3::Z, 0.0, hi), None);
        assert_eq!(rc.first_hit(DVec3::X, DVec3::Y, lo, hi), None);
    }

    #[test]
    fn deep_degenerate_trees_do_not_overflow() {
        // Many instances with bit-identical boxes.
        let instances = (0..3000)
            .map(|i| at(i, 0, DAffine3::from_translation(DVec3::new(0.0, 0.0, 5.0))))
            .collect();
        let geom = scene(vec![cube(0)], vec![Material::default()], instances);
        let rc = RayCaster::new(&geom);
        let hit = rc
            .first_hit(DVec3::ZERO, DVec3::Z, 0.0, f64::INFINITY)
            .unwrap();
        assert!((hit.t - 4.5).abs() < 1e-9);
        assert!(hit.object < 3000);
    }
}
