//! The two-level BVH: 4-wide nodes collapsed from `obvhs` binary BVHs, one
//! per mesh (bottom level) and one over the instances (top level).

use std::time::Duration;

use glam::{DAffine3, DVec3, Vec3, Vec3A, Vec4};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;

use super::ray::Ray32;
use crate::scene::geometry::MeshData;

/// A node's box and either its child node or its leaf range (the root; the
/// other nodes live in [`Quad`]s).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Child {
    pub(super) min: Vec3,
    pub(super) max: Vec3,
    /// Leaf item count; 0 for an inner node.
    pub(super) count: u32,
    /// Inner node: index of its [`Quad`]. Leaf: first item.
    pub(super) first: u32,
}

/// The up to four children of an inner node, boxes laid out so one 4-wide
/// slab test covers all of them. An unused slot has a box at `+∞`, which no
/// ray meets (the tests clamp `tmax` to `f32::MAX`).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Quad {
    /// Per child: min x, y, z, then max x, y, z.
    pub(super) bounds: [Vec4; 6],
    /// Leaf item count per child; 0 for an inner node (or an unused slot).
    pub(super) count: [u32; 4],
    /// Per child: index of its quad (inner) or first item (leaf).
    pub(super) first: [u32; 4],
}

impl Quad {
    const EMPTY: Quad = Quad {
        bounds: [Vec4::INFINITY; 6],
        count: [0; 4],
        first: [0; 4],
    };

    pub(super) fn set(&mut self, slot: usize, c: &Child) {
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
pub(super) struct Tree {
    /// The root, or `None` for no items.
    pub(super) root: Option<Child>,
    /// Inner nodes in depth-first order.
    pub(super) quads: Vec<Quad>,
}

impl Tree {
    /// Builds a tree over boxes; returns it with the item order of its
    /// leaves (leaf `first..first + count` are `order[first..first + count]`).
    pub(super) fn build(boxes: &[Aabb], params: BvhBuildParams) -> (Tree, Vec<u32>) {
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
    pub(super) fn traverse<F>(
        &self,
        ray: &Ray32,
        tmax: &mut f32,
        stack: &mut Stack,
        mut leaf: F,
    ) -> bool
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
pub(super) struct Stack {
    pub(super) inline: [(u32, f32); 64],
    pub(super) len: usize,
    /// Used only while `inline` is full.
    pub(super) spill: Vec<(u32, f32)>,
}

impl Stack {
    pub(super) fn new() -> Stack {
        Stack {
            inline: [(0, 0.0); 64],
            len: 0,
            spill: Vec::new(),
        }
    }

    #[inline(always)]
    pub(super) fn len(&self) -> usize {
        self.len + self.spill.len()
    }

    #[inline(always)]
    pub(super) fn push(&mut self, e: (u32, f32)) {
        if self.len < self.inline.len() {
            self.inline[self.len] = e;
            self.len += 1;
        } else {
            self.spill.push(e);
        }
    }

    /// Pops an entry if the stack holds more than `base`.
    #[inline(always)]
    pub(super) fn pop_above(&mut self, base: usize) -> Option<(u32, f32)> {
        if self.len() <= base {
            return None;
        }
        if let Some(e) = self.spill.pop() {
            return Some(e);
        }
        self.len -= 1;
        Some(self.inline[self.len])
    }

    pub(super) fn truncate(&mut self, n: usize) {
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
pub(super) struct Tri {
    pub(super) v0: Vec3,
    pub(super) v1: Vec3,
    pub(super) v2: Vec3,
}

/// A mesh's bottom-level BVH with its triangles in leaf order.
#[derive(Clone, Debug, Default)]
pub(super) struct Blas {
    pub(super) tree: Tree,
    pub(super) tris: Vec<Tri>,
}

impl Blas {
    pub(super) fn new(mesh: &MeshData) -> Blas {
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
pub(super) fn degenerate(tri: &Tri) -> bool {
    let (v0, v1, v2) = (tri.v0.as_dvec3(), tri.v1.as_dvec3(), tri.v2.as_dvec3());
    if !(v0.is_finite() && v1.is_finite() && v2.is_finite()) {
        return true;
    }
    let (e1, e2) = (v1 - v0, v2 - v0);
    e1.cross(e2).length() <= 1e-7 * e1.length() * e2.length()
}

/// A triangle's box, padded to contain every point the tolerant `f32`
/// intersection test accepts.
pub(super) fn tri_box(tri: &Tri) -> Aabb {
    let min = Vec3A::from(tri.v0.min(tri.v1).min(tri.v2));
    let max = Vec3A::from(tri.v0.max(tri.v1).max(tri.v2));
    let pad = (max - min).max_element() * 1e-5 + min.abs().max(max.abs()).max_element() * 1e-6;
    Aabb::new(min - pad, max + pad)
}

/// The world box of a local box under an affine transform, padded for the
/// rounding to `f32`.
pub(super) fn world_box(transform: &DAffine3, local: &Child) -> Aabb {
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
pub(super) struct InstanceItem {
    pub(super) world_to_local: DAffine3,
    pub(super) object: u32,
    /// Index into [`RayCaster::blas`].
    pub(super) blas: u32,
    /// The transform mirrors (negative determinant): local winding flips.
    pub(super) flip: bool,
    pub(super) double_sided: bool,
}

/// A top-level BVH over instances.
#[derive(Clone, Debug, Default)]
pub(super) struct Tlas {
    pub(super) tree: Tree,
    /// Instances in leaf order.
    pub(super) items: Vec<InstanceItem>,
}

impl Tlas {
    pub(super) fn new(instances: Vec<(Aabb, InstanceItem)>) -> Tlas {
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
