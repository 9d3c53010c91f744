//! Conservative occluders: axis-aligned boxes that lie inside closed, opaque
//! solids of the scene.
//!
//! A box is an occluder only when every line segment from outside the solid
//! to a point inside the box must cross a surface the renderer draws. That
//! holds for a box strictly inside a solid bounded by a closed, consistently
//! oriented triangle surface whose triangles are opaque and face outwards (or
//! are double-sided): the segment enters the solid through a front face. So:
//!
//! 1. Each object's triangles are welded by position and split into
//!    connected components. A component qualifies when every edge is shared
//!    by exactly two of its triangles with opposite directions (closed and
//!    oriented), or when its only open edges all lie in the horizontal plane
//!    of its lowest point (an *open bottom*, as buildings without a ground
//!    face have; such a solid is closed by a virtual cap, and it is only used
//!    for view regions that lie strictly above that plane, from where no
//!    segment can enter through the cap). Its materials must be opaque.
//! 2. Inside means generalised winding number +1 (outward-facing triangles;
//!    −1 is accepted only when every material is double-sided). Any value
//!    not within 0.01 of an integer rejects the component: its surface is not
//!    what it claims to be.
//! 3. A component whose triangles all lie in the faces of its bounding box
//!    is that box. Otherwise its box is voxelised; voxels that no triangle
//!    touches inherit the winding number of their connected region, and up
//!    to three largest boxes of inside voxels become occluders.
//! 4. Where two occluder boxes touch or overlap, the box spanning both along
//!    one axis and their common extent along the other two lies inside their
//!    union: it is added as a *bridge*, so that a row of adjacent buildings
//!    still occludes after every box is shrunk (occluder fusion).
//!
//! Objects with levels of detail are never occluders: the level drawn varies
//! with distance and need not contain the full-detail solid.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::api::stats::OccluderStats;
use crate::math::geom::Aabb;
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::material::AlphaMode;

/// Voxels along the longest axis of a component's box.
const VOXELS: usize = 16;
/// Boxes kept per component.
const BOXES_PER_COMPONENT: usize = 3;

/// One occluder: a box inside a closed solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OccluderBox {
    /// The box (world space), inside the solid(s).
    pub aabb: Aabb,
    /// Bounds of the solid(s) the box lies in: a view region that meets them
    /// may contain viewpoints inside the solid, where its faces are culled.
    pub support: Aabb,
    /// Height of the open bottom of the solid(s), or `-inf` for closed ones:
    /// the box occludes only for view regions strictly above it.
    pub open_below: f64,
}

/// The occluders of a scene.
#[derive(Clone, Debug, Default)]
pub struct Occluders {
    /// Boxes and bridges.
    pub boxes: Vec<OccluderBox>,
    /// Counters.
    pub stats: OccluderStats,
}

/// A component of one object's surface in world space.
struct Component {
    tris: Vec<[DVec3; 3]>,
    /// Directed open edges (open-bottom components only).
    open_edges: Vec<[DVec3; 2]>,
    double_sided: bool,
}

/// A qualifying component in local space: its triangles, its open edges and
/// whether every material is double-sided.
type LocalComponent = (Vec<[Vec3; 3]>, Vec<[Vec3; 2]>, bool);

/// Topology of one mesh set, in local space (shared by every instance).
#[derive(Default)]
struct LocalSolids {
    /// Per qualifying component.
    components: Vec<LocalComponent>,
    rejected: u64,
}

/// Welds positions exactly and finds the closed or open components of a
/// triangle soup (`tris` with a per-triangle flag "opaque" and
/// "double-sided").
fn analyse(tris: &[([Vec3; 3], bool, bool)]) -> LocalSolids {
    let mut out = LocalSolids::default();
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut vid = |p: Vec3| -> u32 {
        // -0.0 and 0.0 weld together.
        let key = [p.x + 0.0, p.y + 0.0, p.z + 0.0].map(f32::to_bits);
        let n = ids.len() as u32;
        *ids.entry(key).or_insert(n)
    };
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(tris.len());
    let mut keep: Vec<usize> = Vec::with_capacity(tris.len());
    for (i, (t, _, _)) in tris.iter().enumerate() {
        let f = [vid(t[0]), vid(t[1]), vid(t[2])];
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            continue; // degenerate: no area, no edges
        }
        faces.push(f);
        keep.push(i);
    }
    let nv = ids.len();
    // Union-find over faces that share an edge (not merely a vertex: a
    // decoration touching a solid at its corners stays apart from it).
    let mut parent: Vec<u32> = (0..faces.len() as u32).collect();
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let mut first_face: HashMap<(u32, u32), u32> = HashMap::new();
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match first_face.get(&key) {
                None => {
                    first_face.insert(key, fi as u32);
                }
                Some(&g) => {
                    let (x, y) = (find(&mut parent, fi as u32), find(&mut parent, g));
                    if x != y {
                        parent[x.max(y) as usize] = x.min(y);
                    }
                }
            }
        }
    }
    let mut by_root: HashMap<u32, Vec<usize>> = HashMap::new();
    for fi in 0..faces.len() {
        let r = find(&mut parent, fi as u32);
        by_root.entry(r).or_default().push(fi);
    }
    let mut roots: Vec<u32> = by_root.keys().copied().collect();
    roots.sort_unstable();
    for r in roots {
        let members = &by_root[&r];
        // Directed edge counts.
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut opaque = true;
        let mut double_sided = true;
        for &fi in members {
            let f = faces[fi];
            let (_, op, ds) = tris[keep[fi]];
            opaque &= op;
            double_sided &= ds;
            for k in 0..3 {
                *edges.entry((f[k], f[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        if !opaque || members.len() < 4 {
            out.rejected += 1;
            continue;
        }
        let mut ok = true;
        let mut open = Vec::new();
        for (&(a, b), &n) in &edges {
            let back = edges.get(&(b, a)).copied().unwrap_or(0);
            if n != 1 || back > 1 {
                ok = false;
                break;
            }
            if back == 0 {
                open.push((a, b));
            }
        }
        if !ok {
            out.rejected += 1;
            continue;
        }
        open.sort_unstable();
        let local: Vec<[Vec3; 3]> = members.iter().map(|&fi| tris[keep[fi]].0).collect();
        let mut pos = vec![Vec3::ZERO; nv];
        for &fi in members {
            for (k, &v) in faces[fi].iter().enumerate() {
                pos[v as usize] = tris[keep[fi]].0[k];
            }
        }
        let open_edges: Vec<[Vec3; 2]> = open
            .iter()
            .map(|&(a, b)| [pos[a as usize], pos[b as usize]])
            .collect();
        out.components.push((local, open_edges, double_sided));
    }
    out
}

/// Signed solid angle of triangle `t` seen from `p` (Van Oosterom &
/// Strackee): positive when `p` lies behind the triangle's front side, so
/// the sum over an outward-oriented closed surface is `4π` inside.
fn solid_angle(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let (a, b, c) = (t[0] - p, t[1] - p, t[2] - p);
    let (la, lb, lc) = (a.length(), b.length(), c.length());
    let num = a.dot(b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// Generalised winding number of `p` for a component (with its cap).
fn winding(p: DVec3, comp: &Component, cap_center: DVec3) -> f64 {
    let mut w: f64 = comp.tris.iter().map(|t| solid_angle(p, t)).sum();
    // The cap closes the open edges: a fan from the centre, reversed.
    for e in &comp.open_edges {
        w += solid_angle(p, &[cap_center, e[1], e[0]]);
    }
    w / (4.0 * std::f64::consts::PI)
}

/// Triangle–box overlap (separating axis test, Akenine-Möller).
fn tri_box_overlap(center: DVec3, half: DVec3, t: &[DVec3; 3]) -> bool {
    let v = [t[0] - center, t[1] - center, t[2] - center];
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    // Box face normals.
    for a in 0..3 {
        let lo = v[0][a].min(v[1][a]).min(v[2][a]);
        let hi = v[0][a].max(v[1][a]).max(v[2][a]);
        if lo > half[a] || hi < -half[a] {
            return false;
        }
    }
    // Triangle normal.
    let n = e[0].cross(e[1]);
    let r = half.x * n.x.abs() + half.y * n.y.abs() + half.z * n.z.abs();
    if n.dot(v[0]).abs() > r {
        return false;
    }
    // Edge cross products.
    for ed in e {
        for a in 0..3 {
            let mut axis = DVec3::ZERO;
            axis[a] = 1.0;
            let ax = axis.cross(ed);
            if ax.length_squared() < 1e-30 {
                continue;
            }
            let p = [ax.dot(v[0]), ax.dot(v[1]), ax.dot(v[2])];
            let lo = p[0].min(p[1]).min(p[2]);
            let hi = p[0].max(p[1]).max(p[2]);
            let r = half.x * ax.x.abs() + half.y * ax.y.abs() + half.z * ax.z.abs();
            if lo > r || hi < -r {
                return false;
            }
        }
    }
    true
}

/// Largest box of `true` cells in a 3D grid (`dims` = x, y, z; index
/// `(z·ny + y)·nx + x`), by volume; ties keep the first found.
fn largest_box(mask: &[bool], dims: [usize; 3]) -> Option<([usize; 3], [usize; 3])> {
    let [nx, ny, nz] = dims;
    let mut best: Option<([usize; 3], [usize; 3], usize)> = None;
    let mut and = vec![false; nx * nz];
    let mut heights = vec![0usize; nx];
    for y0 in 0..ny {
        and.iter_mut().for_each(|a| *a = true);
        for y1 in y0..ny {
            let mut any = false;
            for z in 0..nz {
                for x in 0..nx {
                    let m = &mut and[z * nx + x];
                    *m = *m && mask[(z * ny + y1) * nx + x];
                    any |= *m;
                }
            }
            if !any {
                break;
            }
            let dy = y1 - y0 + 1;
            // Largest rectangle in the xz mask: histogram per z row.
            heights.iter_mut().for_each(|h| *h = 0);
            for z in 0..nz {
                for x in 0..nx {
                    heights[x] = if and[z * nx + x] { heights[x] + 1 } else { 0 };
                }
                let mut stack: Vec<usize> = Vec::new();
                for x in 0..=nx {
                    let h = if x < nx { heights[x] } else { 0 };
                    while let Some(&top) = stack.last() {
                        if heights[top] <= h {
                            break;
                        }
                        stack.pop();
                        let left = stack.last().map_or(0, |&l| l + 1);
                        let (w, hh) = (x - left, heights[top]);
                        let vol = w * hh * dy;
                        if best.as_ref().is_none_or(|b| vol > b.2) {
                            best = Some(([left, y0, z + 1 - hh], [x, y1 + 1, z + 1], vol));
                        }
                    }
                    stack.push(x);
                }
            }
        }
    }
    best.map(|(lo, hi, _)| (lo, hi))
}

/// Grows a voxel box face by face while the new layer is all `true`.
fn grow(mask: &[bool], dims: [usize; 3], lo: &mut [usize; 3], hi: &mut [usize; 3]) {
    let [nx, ny, _] = dims;
    let at = |x: usize, y: usize, z: usize| mask[(z * ny + y) * nx + x];
    let layer_ok = |lo: &[usize; 3], hi: &[usize; 3], axis: usize, i: usize| {
        let (mut l, mut h) = (*lo, *hi);
        l[axis] = i;
        h[axis] = i + 1;
        (l[2]..h[2]).all(|z| (l[1]..h[1]).all(|y| (l[0]..h[0]).all(|x| at(x, y, z))))
    };
    let mut changed = true;
    while changed {
        changed = false;
        for axis in 0..3 {
            if lo[axis] > 0 && layer_ok(lo, hi, axis, lo[axis] - 1) {
                lo[axis] -= 1;
                changed = true;
            }
            if hi[axis] < dims[axis] && layer_ok(lo, hi, axis, hi[axis]) {
                hi[axis] += 1;
                changed = true;
            }
        }
    }
}

/// True when every triangle lies in one face plane of `b`.
fn on_box_faces(tris: &[[DVec3; 3]], b: &Aabb, tol: f64) -> bool {
    tris.iter().all(|t| {
        (0..3).any(|a| {
            let on = |v: f64| t.iter().all(|p| (p[a] - v).abs() <= tol);
            on(b.min[a]) || on(b.max[a])
        })
    })
}

fn bounds(tris: &[[DVec3; 3]]) -> Aabb {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for t in tris {
        for p in t {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    Aabb::new(lo, hi)
}

/// The occluder boxes of one world-space component (empty if it is not a
/// proper solid), and whether it was rejected.
fn component_boxes(comp: &Component) -> (Vec<OccluderBox>, bool) {
    let b = bounds(&comp.tris);
    let ext = b.max - b.min;
    let size = ext.max_element();
    if !(size.is_finite() && size > 0.0) || ext.min_element() <= 0.0 {
        return (Vec::new(), true);
    }
    let tol = 1e-6 * size + 1e-9;
    let open_below = if comp.open_edges.is_empty() {
        f64::NEG_INFINITY
    } else {
        if !comp
            .open_edges
            .iter()
            .all(|e| (e[0].y - b.min.y).abs() <= tol && (e[1].y - b.min.y).abs() <= tol)
        {
            return (Vec::new(), true);
        }
        b.min.y
    };
    let cap_center = if comp.open_edges.is_empty() {
        b.center()
    } else {
        let s: DVec3 = comp.open_edges.iter().map(|e| e[0]).sum();
        s / comp.open_edges.len() as f64
    };
    let sign = if comp.double_sided { None } else { Some(1.0) };
    let inside = |w: f64| -> Option<bool> {
        let r = w.round();
        if (w - r).abs() > 0.01 {
            return None; // not an integer: the surface is not closed as claimed
        }
        Some(match sign {
            Some(s) => r == s,
            None => r.abs() == 1.0,
        })
    };
    let support = b;
    let mk = |aabb: Aabb| OccluderBox {
        aabb,
        support,
        open_below,
    };
    if comp.open_edges.is_empty() && on_box_faces(&comp.tris, &b, tol) {
        return match inside(winding(b.center(), comp, cap_center)) {
            Some(true) => (vec![mk(b)], false),
            _ => (Vec::new(), true),
        };
    }
    // Voxelise.
    let h = size / VOXELS as f64;
    let dims = [0, 1, 2].map(|a| ((ext[a] / h).ceil() as usize).clamp(1, VOXELS));
    let cell = DVec3::new(
        ext.x / dims[0] as f64,
        ext.y / dims[1] as f64,
        ext.z / dims[2] as f64,
    );
    let [nx, ny, nz] = dims;
    let idx = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    let mut surface = vec![false; nx * ny * nz];
    let half = cell * 0.5 * (1.0 + 1e-6);
    for t in &comp.tris {
        let tb = bounds(std::slice::from_ref(t));
        let r = |a: usize, v: f64| {
            (((v - b.min[a]) / cell[a]).floor().max(0.0) as usize).min(dims[a] - 1)
        };
        for z in r(2, tb.min.z)..=r(2, tb.max.z) {
            for y in r(1, tb.min.y)..=r(1, tb.max.y) {
                for x in r(0, tb.min.x)..=r(0, tb.max.x) {
                    let i = idx(x, y, z);
                    if surface[i] {
                        continue;
                    }
                    let c =
                        b.min + cell * DVec3::new(x as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5);
                    if tri_box_overlap(c, half, t) {
                        surface[i] = true;
                    }
                }
            }
        }
    }
    // Regions of untouched voxels share one winding number.
    let mut label = vec![u32::MAX; nx * ny * nz];
    let mut inside_mask = vec![false; nx * ny * nz];
    let mut stack = Vec::new();
    for start in 0..label.len() {
        if surface[start] || label[start] != u32::MAX {
            continue;
        }
        let (sx, sy, sz) = (start % nx, (start / nx) % ny, start / (nx * ny));
        let c = b.min + cell * DVec3::new(sx as f64 + 0.5, sy as f64 + 0.5, sz as f64 + 0.5);
        let Some(is_in) = inside(winding(c, comp, cap_center)) else {
            return (Vec::new(), true);
        };
        label[start] = start as u32;
        stack.push(start);
        while let Some(i) = stack.pop() {
            inside_mask[i] = is_in;
            let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
            let mut push = |x: usize, y: usize, z: usize| {
                let j = idx(x, y, z);
                if !surface[j] && label[j] == u32::MAX {
                    label[j] = start as u32;
                    stack.push(j);
                }
            };
            if x > 0 {
                push(x - 1, y, z);
            }
            if x + 1 < nx {
                push(x + 1, y, z);
            }
            if y > 0 {
                push(x, y - 1, z);
            }
            if y + 1 < ny {
                push(x, y + 1, z);
            }
            if z > 0 {
                push(x, y, z - 1);
            }
            if z + 1 < nz {
                push(x, y, z + 1);
            }
        }
    }
    let mut boxes = Vec::new();
    let mut free = inside_mask.clone();
    let mut first_volume = 0usize;
    for _ in 0..BOXES_PER_COMPONENT {
        let Some((mut lo, mut hi)) = largest_box(&free, dims) else {
            break;
        };
        grow(&inside_mask, dims, &mut lo, &mut hi);
        let vol = (0..3).map(|a| hi[a] - lo[a]).product::<usize>();
        if first_volume == 0 {
            first_volume = vol;
        } else if vol * 10 < first_volume {
            break;
        }
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                for x in lo[0]..hi[0] {
                    free[idx(x, y, z)] = false;
                }
            }
        }
        let to_world =
            |v: [usize; 3]| b.min + cell * DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        boxes.push(mk(Aabb::new(to_world(lo), to_world(hi))));
    }
    (boxes, false)
}

/// Adds bridges between touching or overlapping boxes (see the module docs).
pub(crate) fn bridges(boxes: &[OccluderBox]) -> Vec<OccluderBox> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| boxes[a].aabb.min.x.total_cmp(&boxes[b].aabb.min.x));
    let mut out = Vec::new();
    for (k, &i) in order.iter().enumerate() {
        let a = &boxes[i];
        for &j in &order[k + 1..] {
            let b = &boxes[j];
            if b.aabb.min.x > a.aabb.max.x {
                break;
            }
            let touch = (0..3)
                .all(|ax| a.aabb.min[ax] <= b.aabb.max[ax] && b.aabb.min[ax] <= a.aabb.max[ax]);
            if !touch {
                continue;
            }
            for axis in 0..3 {
                let mut lo = a.aabb.min.max(b.aabb.min);
                let mut hi = a.aabb.max.min(b.aabb.max);
                lo[axis] = a.aabb.min[axis].min(b.aabb.min[axis]);
                hi[axis] = a.aabb.max[axis].max(b.aabb.max[axis]);
                if (0..3).any(|ax| hi[ax] <= lo[ax]) {
                    continue;
                }
                let bridge = Aabb::new(lo, hi);
                if a.aabb.contains_box(&bridge) || b.aabb.contains_box(&bridge) {
                    continue;
                }
                out.push(OccluderBox {
                    aabb: bridge,
                    support: Aabb::new(
                        a.support.min.min(b.support.min),
                        a.support.max.max(b.support.max),
                    ),
                    open_below: a.open_below.max(b.open_below),
                });
            }
        }
    }
    out
}

/// Extracts the occluders of a scene from its geometry (see the module docs).
/// Deterministic.
pub fn extract(geom: &SceneGeometry, scene: &Scene) -> Occluders {
    // Instances of one object are contiguous and share its transform.
    let mut per_object: Vec<(u32, usize, usize)> = Vec::new();
    let mut i = 0;
    while i < geom.instances.len() {
        let o = geom.instances[i].object;
        let mut j = i;
        while j < geom.instances.len() && geom.instances[j].object == o {
            j += 1;
        }
        per_object.push((o, i, j));
        i = j;
    }
    // Local topology per distinct mesh set, computed once.
    let mut sets: Vec<Vec<u32>> = per_object
        .iter()
        .map(|&(_, a, b)| geom.instances[a..b].iter().map(|x| x.mesh).collect())
        .collect();
    sets.sort();
    sets.dedup();
    let analysed: Vec<LocalSolids> = sets
        .par_iter()
        .map(|meshes| {
            let mut tris = Vec::new();
            for &m in meshes {
                let mesh = &geom.meshes[m as usize];
                let mat = &geom.materials[mesh.material as usize];
                let opaque = mat.alpha_mode == AlphaMode::Opaque;
                for t in mesh.indices.chunks_exact(3) {
                    let p = |k: usize| mesh.positions[t[k] as usize];
                    tris.push(([p(0), p(1), p(2)], opaque, mat.double_sided));
                }
            }
            analyse(&tris)
        })
        .collect();
    let results: Vec<(Vec<OccluderBox>, u64, u64)> = per_object
        .par_iter()
        .map(|&(o, a, b)| {
            let obj = &scene.objects[o as usize];
            if !obj.lods.is_empty() {
                return (Vec::new(), 0, 0);
            }
            let meshes: Vec<u32> = geom.instances[a..b].iter().map(|x| x.mesh).collect();
            let local = &analysed[sets.binary_search(&meshes).expect("listed")];
            let tf = geom.instances[a].transform;
            let w = |p: Vec3| tf.transform_point3(p.as_dvec3());
            let mut boxes = Vec::new();
            let (mut solid, mut rejected) = (0u64, local.rejected);
            for (tris, open, ds) in &local.components {
                let comp = Component {
                    tris: tris.iter().map(|t| [w(t[0]), w(t[1]), w(t[2])]).collect(),
                    open_edges: open.iter().map(|e| [w(e[0]), w(e[1])]).collect(),
                    double_sided: *ds,
                };
                let (bx, rej) = component_boxes(&comp);
                if rej {
                    rejected += 1;
                } else {
                    solid += 1;
                }
                boxes.extend(bx);
            }
            (boxes, solid, rejected)
        })
        .collect();
    let mut stats = OccluderStats::default();
    let mut boxes = Vec::new();
    for (bx, solid, rejected) in results {
        stats.occluder_objects += u64::from(!bx.is_empty());
        stats.solid_components += solid;
        stats.rejected_components += rejected;
        boxes.extend(bx);
    }
    stats.boxes = boxes.len() as u64;
    let extra = bridges(&boxes);
    stats.bridges = extra.len() as u64;
    boxes.extend(extra);
    Occluders { boxes, stats }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cuboid(lo: DVec3, hi: DVec3) -> Vec<[DVec3; 3]> {
        let c = |x: bool, y: bool, z: bool| {
            DVec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        // Outward-facing quads as two triangles each.
        let quads = [
            [
                c(false, false, true),
                c(true, false, true),
                c(true, true, true),
                c(false, true, true),
            ],
            [
                c(true, false, false),
                c(false, false, false),
                c(false, true, false),
                c(true, true, false),
            ],
            [
                c(true, false, true),
                c(true, false, false),
                c(true, true, false),
                c(true, true, true),
            ],
            [
                c(false, false, false),
                c(false, false, true),
                c(false, true, true),
                c(false, true, false),
            ],
            [
                c(false, true, true),
                c(true, true, true),
                c(true, true, false),
                c(false, true, false),
            ],
            [
                c(false, false, false),
                c(true, false, false),
                c(true, false, true),
                c(false, false, true),
            ],
        ];
        quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect()
    }

    fn comp(tris: Vec<[DVec3; 3]>) -> Component {
        Component {
            tris,
            open_edges: Vec::new(),
            double_sided: false,
        }
    }

    #[test]
    fn winding_is_one_inside_a_cuboid_and_zero_outside() {
        let c = comp(cuboid(DVec3::ZERO, DVec3::new(2.0, 3.0, 4.0)));
        let w = |p: DVec3| winding(p, &c, DVec3::ZERO);
        assert!((w(DVec3::new(1.0, 1.5, 2.0)) - 1.0).abs() < 1e-9);
        assert!(w(DVec3::new(5.0, 1.0, 1.0)).abs() < 1e-9);
        assert!(w(DVec3::new(1.0, -0.5, 1.0)).abs() < 1e-9);
    }

    #[test]
    fn a_cuboid_is_its_own_occluder() {
        let lo = DVec3::new(1.0, 0.0, 2.0);
        let hi = DVec3::new(4.0, 10.0, 7.0);
        let (boxes, rej) = component_boxes(&comp(cuboid(lo, hi)));
        assert!(!rej);
        assert_eq!(boxes.len(), 1);
        assert_eq!(boxes[0].aabb, Aabb::new(lo, hi));
        assert_eq!(boxes[0].open_below, f64::NEG_INFINITY);
        // Inverted orientation (inward faces, single-sided) is no occluder.
        let inverted: Vec<_> = cuboid(lo, hi)
            .into_iter()
            .map(|t| [t[0], t[2], t[1]])
            .collect();
        let (boxes, rej) = component_boxes(&comp(inverted.clone()));
        assert!(boxes.is_empty() && rej);
        // ... unless double-sided.
        let (boxes, _) = component_boxes(&Component {
            tris: inverted,
            open_edges: Vec::new(),
            double_sided: true,
        });
        assert_eq!(boxes.len(), 1);
    }

    #[test]
    fn analysis_finds_closed_and_open_bottom_components_and_rejects_open_ones() {
        let f = |v: DVec3| v.as_vec3();
        let cube: Vec<([Vec3; 3], bool, bool)> = cuboid(DVec3::ZERO, DVec3::ONE)
            .into_iter()
            .map(|t| ([f(t[0]), f(t[1]), f(t[2])], true, false))
            .collect();
        let s = analyse(&cube);
        assert_eq!(s.components.len(), 1);
        assert!(s.components[0].1.is_empty());
        // Without the bottom (-y) face: open edges at y = 0 only.
        let open: Vec<_> = cube[..10].to_vec();
        let s = analyse(&open);
        assert_eq!(s.components.len(), 1);
        assert_eq!(s.components[0].1.len(), 4);
        assert!(
            s.components[0]
                .1
                .iter()
                .all(|e| e[0].y == 0.0 && e[1].y == 0.0)
        );
        // Without a side face: open edges not at the bottom → rejected later.
        let side: Vec<_> = cube[2..].to_vec();
        let s = analyse(&side);
        let c = &s.components[0];
        let comp = Component {
            tris: c.0.iter().map(|t| t.map(|p| p.as_dvec3())).collect(),
            open_edges: c.1.iter().map(|e| e.map(|p| p.as_dvec3())).collect(),
            double_sided: false,
        };
        assert!(component_boxes(&comp).0.is_empty());
        // A transparent cube is no solid.
        let glass: Vec<_> = cube.iter().map(|&(t, _, d)| (t, false, d)).collect();
        assert!(analyse(&glass).components.is_empty());
    }

    #[test]
    fn an_open_bottom_prism_gets_an_inner_box_with_its_open_plane() {
        // An L-shaped prism without a floor: voxel path.
        let l = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(10.0, 0.0, 0.0),
            DVec3::new(10.0, 0.0, 4.0),
            DVec3::new(4.0, 0.0, 4.0),
            DVec3::new(4.0, 0.0, 10.0),
            DVec3::new(0.0, 0.0, 10.0),
        ];
        let h = DVec3::new(0.0, 8.0, 0.0);
        let mut tris = Vec::new();
        for i in 0..l.len() {
            let (a, b) = (l[i], l[(i + 1) % l.len()]);
            // Walls facing outwards.
            tris.push([a, a + h, b + h]);
            tris.push([a, b + h, b]);
        }
        // Roof (faces +y): fan, reversed footprint order.
        let roof: Vec<DVec3> = l.iter().map(|p| *p + h).collect();
        // Triangulate the L: two rectangles.
        let quad = |a: DVec3, b: DVec3, c: DVec3, d: DVec3, t: &mut Vec<[DVec3; 3]>| {
            t.push([a, b, c]);
            t.push([a, c, d]);
        };
        quad(roof[0], roof[5], roof[4], roof[3], &mut tris);
        quad(roof[0], roof[3], roof[2], roof[1], &mut tris);
        let local: Vec<([Vec3; 3], bool, bool)> = tris
            .iter()
            .map(|t| (t.map(|p| p.as_vec3()), true, false))
            .collect();
        let s = analyse(&local);
        assert_eq!(s.components.len(), 1, "one component");
        let c = &s.components[0];
        let comp = Component {
            tris: c.0.iter().map(|t| t.map(|p| p.as_dvec3())).collect(),
            open_edges: c.1.iter().map(|e| e.map(|p| p.as_dvec3())).collect(),
            double_sided: false,
        };
        // Walls and roof face outwards (counter-clockwise footprint in x, z).
        let (boxes, rej) = component_boxes(&comp);
        assert!(!rej);
        assert!(!boxes.is_empty());
        for b in &boxes {
            assert_eq!(b.open_below, 0.0);
            // Inside the L: within the bounds and not in the notch.
            assert!(
                b.aabb.min.cmpge(DVec3::ZERO).all()
                    && b.aabb.max.cmple(DVec3::new(10.0, 8.0, 10.0)).all()
            );
            let notch = Aabb::new(DVec3::new(4.0, 0.0, 4.0), DVec3::new(10.0, 8.0, 10.0));
            let overlap = (0..3).all(|a| {
                b.aabb.min[a] < notch.max[a] - 1e-9 && notch.min[a] + 1e-9 < b.aabb.max[a]
            });
            assert!(!overlap, "{:?} overlaps the notch", b.aabb);
        }
        let vol: f64 = boxes
            .iter()
            .map(|b| (b.aabb.max - b.aabb.min).element_product())
            .max_by(f64::total_cmp)
            .unwrap();
        assert!(vol > 0.5 * 4.0 * 10.0 * 8.0, "largest box {vol}");
    }

    #[test]
    fn bridges_span_touching_boxes() {
        let mk = |lo: [f64; 3], hi: [f64; 3]| OccluderBox {
            aabb: Aabb::new(DVec3::from_array(lo), DVec3::from_array(hi)),
            support: Aabb::new(DVec3::from_array(lo), DVec3::from_array(hi)),
            open_below: f64::NEG_INFINITY,
        };
        let a = mk([0.0, 0.0, 0.0], [10.0, 20.0, 12.0]);
        let b = mk([10.0, 0.0, 0.0], [25.0, 15.0, 14.0]);
        let far = mk([40.0, 0.0, 0.0], [50.0, 5.0, 5.0]);
        let br = bridges(&[a, b, far]);
        let along_x = Aabb::new(DVec3::ZERO, DVec3::new(25.0, 15.0, 12.0));
        assert!(br.iter().any(|x| x.aabb == along_x), "{br:?}");
        assert!(
            br.iter()
                .all(|x| x.support.max.x == 25.0 && x.support.min.x == 0.0)
        );
    }

    #[test]
    fn largest_box_in_a_grid() {
        let dims = [4, 3, 2];
        let mut m = vec![false; 24];
        for z in 0..2 {
            for y in 0..3 {
                for x in 1..4 {
                    m[(z * 3 + y) * 4 + x] = true;
                }
            }
        }
        m[(3) * 4 + 3] = false; // z=1, y=0, x=3
        let (lo, hi) = largest_box(&m, dims).unwrap();
        let vol = (0..3).map(|a| hi[a] - lo[a]).product::<usize>();
        assert_eq!(vol, 12, "{lo:?} {hi:?}");
    }
}
