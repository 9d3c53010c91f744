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

use glam::DVec3;
use rayon::prelude::*;

mod bvh;
mod ray;

use bvh::{Blas, InstanceItem, Quad, Stack, Tlas, Tri, world_box};
use ray::WorldRay;

use crate::scene::geometry::SceneGeometry;
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

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use glam::{DAffine3, DQuat, Vec3};

    use super::*;
    use crate::math::rng::Rng;
    use crate::scene::geometry::{Instance, MeshData};

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
            object_nodes: Vec::new(),
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
