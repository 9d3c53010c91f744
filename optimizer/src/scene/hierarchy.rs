//! The object hierarchy (paper §2.3, DESIGN §2.2): a BVH over object bounds
//! built with `obvhs`, flattened into pre-order node arrays. Every node is an
//! object cluster; clusters nest, so two clusters are disjoint or one
//! contains the other.

use std::time::Duration;

use glam::Vec3A;
use obvhs::{BvhBuildParams, aabb::Aabb as BAabb, bvh2::builder::build_bvh2};

use crate::math::geom::{Aabb, Sphere};
use crate::scene::Scene;

/// Largest number of objects in a leaf cluster.
pub const MAX_OBJECTS_PER_LEAF: u32 = 8;

/// One cluster.
#[derive(Clone, Debug)]
pub struct Node {
    /// Bounding box of the cluster's objects.
    pub aabb: Aabb,
    /// Bounding sphere containing every object sphere of the cluster.
    pub sphere: Sphere,
    /// Children (inner nodes), or `None` for a leaf.
    pub children: Option<[u32; 2]>,
    /// The cluster's objects: `order[objects.0 .. objects.1]`.
    pub objects: (u32, u32),
    /// One past the last node id of this node's subtree (pre-order ids).
    pub subtree_end: u32,
    /// Parent node id (`u32::MAX` for the root).
    pub parent: u32,
    /// Depth (root = 0).
    pub depth: u32,
    /// Total draw calls of the cluster.
    pub draw_calls: u64,
    /// Total triangles of the cluster.
    pub triangles: u64,
}

/// The hierarchy: nodes in pre-order (root = 0), and object ids in the
/// matching depth-first order.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Nodes; the index is the node id.
    pub nodes: Vec<Node>,
    /// Object ids in depth-first order; a node's objects are a range of it.
    pub order: Vec<u32>,
    /// Bounding sphere of each object, indexed by object id.
    pub object_spheres: Vec<Sphere>,
    /// The leaf cluster of each object, indexed by object id.
    pub leaf_of: Vec<u32>,
}

impl Hierarchy {
    /// Builds the hierarchy of a validated, non-empty scene. Deterministic.
    pub fn build(scene: &Scene) -> Hierarchy {
        let object_spheres: Vec<Sphere> = scene
            .objects
            .iter()
            .map(|o| Sphere {
                center: o.center(),
                radius: o.radius(),
            })
            .collect();
        // The builder sees the objects in a canonical order, by their
        // bounds (then triangles and draw calls; the id only between
        // identical objects), so the tree depends on the geometry alone and
        // not on the order of the scene's nodes.
        let mut canon: Vec<u32> = (0..scene.objects.len() as u32).collect();
        canon.sort_unstable_by(|&a, &b| {
            let (oa, ob) = (&scene.objects[a as usize], &scene.objects[b as usize]);
            let key =
                |o: &crate::scene::Object| [o.min.x, o.min.y, o.min.z, o.max.x, o.max.y, o.max.z];
            key(oa)
                .iter()
                .zip(key(ob).iter())
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(oa.triangles.cmp(&ob.triangles))
                .then(oa.draw_calls.cmp(&ob.draw_calls))
                .then(a.cmp(&b))
        });
        // Boxes for the builder only, in canonical order. A tiny
        // deterministic offset per position breaks ties between identical
        // boxes, which otherwise make the clustering quadratic and the tree
        // a chain; the tree's own bounds are recomputed exactly below.
        let boxes: Vec<BAabb> = canon
            .iter()
            .enumerate()
            .map(|(i, &id)| {
                let o = &scene.objects[id as usize];
                let size = (o.max - o.min).max_element().max(1e-3);
                let h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                let jitter = |shift: u32| ((h >> shift) & 0xFFFF) as f64 / 65535.0 - 0.5;
                let off = glam::DVec3::new(jitter(0), jitter(16), jitter(32)) * (size * 1e-3);
                BAabb::new(
                    Vec3A::from((o.min + off).as_vec3()),
                    Vec3A::from((o.max + off).as_vec3()),
                )
            })
            .collect();
        let params = BvhBuildParams {
            max_prims_per_leaf: MAX_OBJECTS_PER_LEAF,
            ..BvhBuildParams::medium_build()
        };
        let mut build_time = Duration::ZERO;
        let bvh = build_bvh2(&boxes, params, &mut build_time);

        // Pre-order walk; a leaf keeps its objects in canonical order so the
        // tree does not depend on the builder's leaf order.
        let mut nodes: Vec<Node> = Vec::with_capacity(bvh.nodes.len());
        let mut order: Vec<u32> = Vec::with_capacity(scene.objects.len());
        // (bvh node, parent id, depth)
        let mut stack: Vec<(u32, u32, u32)> = vec![(0, u32::MAX, 0)];
        while let Some((bi, parent, depth)) = stack.pop() {
            let id = nodes.len() as u32;
            let b = &bvh.nodes[bi as usize];
            let mut node = Node {
                aabb: Aabb::new(glam::DVec3::ZERO, glam::DVec3::ZERO),
                sphere: Sphere {
                    center: glam::DVec3::ZERO,
                    radius: 0.0,
                },
                children: None,
                objects: (order.len() as u32, order.len() as u32),
                subtree_end: id + 1,
                parent,
                depth,
                draw_calls: 0,
                triangles: 0,
            };
            if b.is_leaf() {
                let mut objs: Vec<u32> = (b.first_index..b.first_index + b.prim_count)
                    .map(|p| bvh.primitive_indices[p as usize])
                    .collect();
                objs.sort_unstable();
                let objs: Vec<u32> = objs.iter().map(|&k| canon[k as usize]).collect();
                order.extend_from_slice(&objs);
                node.objects.1 = order.len() as u32;
            } else {
                stack.push((b.first_index + 1, id, depth + 1));
                stack.push((b.first_index, id, depth + 1));
            }
            if parent != u32::MAX {
                let p = &mut nodes[parent as usize];
                match &mut p.children {
                    None => p.children = Some([id, u32::MAX]),
                    Some(c) => c[1] = id,
                }
            }
            nodes.push(node);
        }
        // Bottom-up: children have larger ids than their parent.
        for id in (0..nodes.len()).rev() {
            let (aabb, sphere, range, end, calls, tris) = match nodes[id].children {
                None => {
                    let (s, e) = nodes[id].objects;
                    let objs = &order[s as usize..e as usize];
                    let mut aabb = Aabb::new(
                        scene.objects[objs[0] as usize].min,
                        scene.objects[objs[0] as usize].max,
                    );
                    let mut sphere = object_spheres[objs[0] as usize];
                    let (mut calls, mut tris) = (0u64, 0u64);
                    for &o in objs {
                        let ob = &scene.objects[o as usize];
                        aabb.min = aabb.min.min(ob.min);
                        aabb.max = aabb.max.max(ob.max);
                        sphere = sphere.merge(&object_spheres[o as usize]);
                        calls += u64::from(ob.draw_calls);
                        tris += ob.triangles;
                    }
                    (aabb, sphere, (s, e), id as u32 + 1, calls, tris)
                }
                Some([l, r]) => {
                    let (a, b) = (&nodes[l as usize], &nodes[r as usize]);
                    let aabb = Aabb::new(a.aabb.min.min(b.aabb.min), a.aabb.max.max(b.aabb.max));
                    (
                        aabb,
                        a.sphere.merge(&b.sphere),
                        (a.objects.0.min(b.objects.0), a.objects.1.max(b.objects.1)),
                        b.subtree_end.max(a.subtree_end),
                        a.draw_calls + b.draw_calls,
                        a.triangles + b.triangles,
                    )
                }
            };
            let n = &mut nodes[id];
            n.aabb = aabb;
            n.sphere = sphere;
            n.objects = range;
            n.subtree_end = end;
            n.draw_calls = calls;
            n.triangles = tris;
        }
        let mut leaf_of = vec![0u32; order.len()];
        for (id, n) in nodes.iter().enumerate() {
            if n.children.is_none() {
                for &o in &order[n.objects.0 as usize..n.objects.1 as usize] {
                    leaf_of[o as usize] = id as u32;
                }
            }
        }
        Hierarchy {
            nodes,
            order,
            object_spheres,
            leaf_of,
        }
    }

    /// The object ids of node `n`.
    pub fn objects(&self, n: u32) -> &[u32] {
        let (s, e) = self.nodes[n as usize].objects;
        &self.order[s as usize..e as usize]
    }

    /// Visits the nodes depth first, left before right, from the root:
    /// `f(id, node)` is called for every node reached and says whether to go
    /// into its children (ignored for leaves, whose objects the caller reads
    /// with [`Hierarchy::objects`]).
    pub fn walk(&self, mut f: impl FnMut(u32, &Node) -> bool) {
        self.walk_with((), |n, node, ()| f(n, node).then_some(()));
    }

    /// [`Hierarchy::walk`] passing state down: `f(id, node, s)` gets the
    /// state its parent returned (`root` for the root) and returns the
    /// state for its children, or `None` not to go into them.
    pub fn walk_with<S: Copy>(&self, root: S, mut f: impl FnMut(u32, &Node, S) -> Option<S>) {
        let mut stack = vec![(0u32, root)];
        while let Some((n, s)) = stack.pop() {
            let node = &self.nodes[n as usize];
            if let Some(down) = f(n, node, s)
                && let Some([l, r]) = node.children
            {
                stack.push((r, down));
                stack.push((l, down));
            }
        }
    }

    /// True when `d` is a strict descendant of `a`.
    pub fn is_descendant(&self, d: u32, a: u32) -> bool {
        d > a && d < self.nodes[a as usize].subtree_end
    }

    /// Checks the structural invariants; returns a description of the first
    /// violation. Used by tests and debug builds.
    pub fn validate(&self, scene: &Scene) -> Result<(), String> {
        let mut seen = vec![false; scene.objects.len()];
        for &o in &self.order {
            if std::mem::replace(&mut seen[o as usize], true) {
                return Err(format!("object {o} appears twice"));
            }
        }
        if seen.iter().any(|s| !s) {
            return Err("an object is missing".into());
        }
        for (id, n) in self.nodes.iter().enumerate() {
            for &o in self.objects(id as u32) {
                let s = &self.object_spheres[o as usize];
                if s.center.distance(n.sphere.center) + s.radius
                    > n.sphere.radius * (1.0 + 1e-9) + 1e-9
                {
                    return Err(format!("object {o} sphere outside node {id} sphere"));
                }
            }
            if let Some([l, r]) = n.children {
                if self.nodes[l as usize].parent != id as u32
                    || self.nodes[r as usize].parent != id as u32
                {
                    return Err(format!("node {id}: broken parent links"));
                }
                if !(self.is_descendant(l, id as u32) && self.is_descendant(r, id as u32)) {
                    return Err(format!("node {id}: children outside the subtree range"));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Object;
    use glam::DVec3;

    fn grid_scene(n: usize, duplicate: bool) -> Scene {
        let objects = (0..n)
            .map(|i| {
                let p = if duplicate {
                    DVec3::ZERO
                } else {
                    DVec3::new((i % 10) as f64 * 7.0, 0.0, (i / 10) as f64 * 5.0)
                };
                Object {
                    name: format!("o{i}"),
                    min: p,
                    max: p + DVec3::new(2.0, 3.0, 2.0),
                    triangles: 100 + i as u64,
                    draw_calls: 1 + (i % 3) as u32,
                    lods: Vec::new(),
                }
            })
            .collect();
        Scene { objects }
    }

    #[test]
    fn clusters_nest_and_sum() {
        let scene = grid_scene(137, false);
        let h = Hierarchy::build(&scene);
        h.validate(&scene).unwrap();
        assert_eq!(h.objects(0).len(), 137);
        assert_eq!(h.nodes[0].triangles, scene.total_triangles());
        let calls: u64 = scene.objects.iter().map(|o| u64::from(o.draw_calls)).sum();
        assert_eq!(h.nodes[0].draw_calls, calls);
        assert!(
            h.nodes.iter().all(
                |n| n.children.is_some() || (n.objects.1 - n.objects.0) <= MAX_OBJECTS_PER_LEAF
            )
        );
        // Deterministic.
        let h2 = Hierarchy::build(&scene);
        assert_eq!(h.order, h2.order);
    }

    #[test]
    fn identical_boxes_do_not_make_a_chain() {
        let scene = grid_scene(3000, true);
        let h = Hierarchy::build(&scene);
        h.validate(&scene).unwrap();
        let depth = h.nodes.iter().map(|n| n.depth).max().unwrap();
        assert!(depth < 64, "depth {depth}");
    }

    /// The tree depends on the objects' geometry, not on their order in
    /// the scene: a shuffled scene gives the same nodes, holding the same
    /// objects under their new ids.
    #[test]
    fn the_tree_does_not_depend_on_the_object_order() {
        let scene = grid_scene(300, false);
        let h = Hierarchy::build(&scene);
        let n = scene.objects.len();
        let mut rng = crate::math::rng::Rng::new(7);
        let mut perm: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            perm.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        // perm[new] = old.
        let shuffled = Scene {
            objects: perm.iter().map(|&o| scene.objects[o].clone()).collect(),
        };
        let hs = Hierarchy::build(&shuffled);
        assert_eq!(h.nodes.len(), hs.nodes.len());
        for (a, b) in h.nodes.iter().zip(&hs.nodes) {
            assert_eq!(a.children, b.children);
            assert_eq!(a.objects, b.objects);
            assert_eq!(a.sphere.center, b.sphere.center);
            assert_eq!(a.sphere.radius, b.sphere.radius);
        }
        let back: Vec<u32> = hs.order.iter().map(|&o| perm[o as usize] as u32).collect();
        assert_eq!(h.order, back);
    }

    #[test]
    fn single_object() {
        let scene = grid_scene(1, false);
        let h = Hierarchy::build(&scene);
        assert_eq!(h.nodes.len(), 1);
        h.validate(&scene).unwrap();
    }
}
