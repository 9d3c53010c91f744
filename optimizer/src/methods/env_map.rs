//! The environment-map method (paper test 15, after Jeschke et al. 2002):
//! the view space is cut into view cells of `env_map.cell_m` (a whole number
//! of grid cells), and for every cell everything visible that lies entirely
//! beyond `env_map.far_m` becomes layered environment-map impostors; nearer
//! objects stay geometry. No frame-time target steers it: it gives no
//! guarantee, and the placement reports which problem views stay above the
//! target.
//!
//! Per cell and cube face (seen from the cell's centre) the far objects are
//! split into layers evenly spaced in `1/z`, as many as the box view-cell
//! criterion needs (`n = ⌈r·(1/z_n − 1/z_f)/(2εθ)⌉`, `r` the cell's
//! half-diagonal); each (face, layer) holding objects is one impostor of one
//! layer whose texture covers its objects' projection on the face plane at
//! one texel per pixel angle `θ` (tiled where it exceeds the largest texture
//! size). Memory uses the same texel model as every other method.

use glam::DVec3;
use rayon::prelude::*;

use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, SphereJson, ViewCellJson};
use crate::math::enclosing::enclosing_cone;
use crate::math::geom::{Aabb, Sphere, face_coords};
use crate::model::cost::Cost;
use crate::model::impostor::{ImpostorModel, ViewCell};
use crate::views::{Context, Counters, Cpv, ProblemViews, RegionCosts, enclosed_cost};
use crate::visibility::ObjectSet;

/// The impostors of one environment-map cell.
pub(super) struct CellMaps {
    /// `(objects, sphere, memory bytes, largest texture side)` per impostor.
    pub(super) impostors: Vec<(Vec<u32>, Sphere, u64, u32)>,
    pub(super) aabb: Aabb,
}

/// Grid cells per view cell of side `cell_m`, per axis.
pub(super) fn block(cell_m: f64, pv: &ProblemViews) -> [u32; 3] {
    let g = &pv.grid;
    let cell = g.largest_cell();
    [0, 1, 2].map(|a| {
        let ext = cell[a];
        if ext <= 0.0 {
            g.counts[a]
        } else {
            ((cell_m / ext).round().max(1.0) as u32).min(g.counts[a])
        }
    })
}

/// Smallest distance between two boxes (0 when they meet).
fn box_distance(a: &Aabb, b: &Aabb) -> f64 {
    let gap = (a.min - b.max).max(b.min - a.max).max(DVec3::ZERO);
    gap.length()
}

/// Splits the visible objects of one cell entirely beyond `far` into face
/// layers: as many as the parallax criterion needs when `layered`, else one
/// texture per face.
pub(super) fn cell_maps(
    ctx: &Context,
    job: &Job,
    aabb: Aabb,
    visible: Option<&ObjectSet>,
    far: f64,
    layered: bool,
) -> CellMaps {
    let imodel = ImpostorModel::new(job);
    let c = aabb.center();
    let r_cell = aabb.half_diagonal();
    // (face, depth, object) of every visible object entirely beyond `far`.
    let mut per_face: [Vec<(f64, u32)>; 6] = Default::default();
    for (o, s) in ctx.hierarchy.object_spheres.iter().enumerate() {
        if visible.is_some_and(|v| !v.contains(o as u32)) {
            continue;
        }
        let ob = &ctx.scene.objects[o];
        if box_distance(&aabb, &Aabb::new(ob.min, ob.max)) < far {
            continue;
        }
        let d = s.center - c;
        if d.length_squared() == 0.0 {
            continue;
        }
        let (face, _, _) = face_coords(d);
        per_face[face as usize].push((d.length(), o as u32));
    }
    let mut impostors = Vec::new();
    for (face, objs) in per_face.iter().enumerate() {
        if objs.is_empty() {
            continue;
        }
        let spheres = &ctx.hierarchy.object_spheres;
        let zn = objs
            .iter()
            .map(|&(z, o)| z - spheres[o as usize].radius)
            .fold(f64::INFINITY, f64::min)
            .max(far * 0.5);
        let zf = objs
            .iter()
            .map(|&(z, o)| z + spheres[o as usize].radius)
            .fold(0.0, f64::max)
            .max(zn * (1.0 + 1e-9));
        let span = 1.0 / zn - 1.0 / zf;
        let n = if layered {
            ((r_cell * span / (2.0 * imodel.eps * imodel.theta)).ceil() as usize).clamp(1, 4096)
        } else {
            1
        };
        let mut layers: Vec<Vec<u32>> = vec![Vec::new(); n];
        for &(z, o) in objs {
            let t = ((1.0 / zn - 1.0 / z) / span).clamp(0.0, 1.0);
            layers[((t * n as f64) as usize).min(n - 1)].push(o);
        }
        let axis = face / 2;
        let sign = if face % 2 == 0 { 1.0 } else { -1.0 };
        for mut objects in layers.into_iter().filter(|l| !l.is_empty()) {
            objects.sort_unstable();
            // Extent of the objects' boxes projected on the face plane.
            let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            let mut sphere: Option<Sphere> = None;
            for &o in &objects {
                let ob = &ctx.scene.objects[o as usize];
                for p in Aabb::new(ob.min, ob.max).corners() {
                    let d = p - c;
                    let depth = (d[axis] * sign).max(0.25 * d.length());
                    let (a, b) = match axis {
                        0 => (d.y, d.z),
                        1 => (d.x, d.z),
                        _ => (d.x, d.y),
                    };
                    let (u, v) = (a / depth, b / depth);
                    u0 = u0.min(u);
                    u1 = u1.max(u);
                    v0 = v0.min(v);
                    v1 = v1.max(v);
                }
                let s = spheres[o as usize];
                sphere = Some(sphere.map_or(s, |acc| acc.merge(&s)));
            }
            let res_u = ((u1 - u0) / imodel.texel_angle()).ceil().max(4.0);
            let res_v = ((v1 - v0) / imodel.texel_angle()).ceil().max(4.0);
            let memory = (res_u * res_v * imodel.bytes_per_texel).ceil() as u64;
            impostors.push((
                objects,
                sphere.expect("a layer has objects"),
                memory,
                res_u.max(res_v) as u32,
            ));
        }
    }
    CellMaps { impostors, aabb }
}

/// A placement made without candidates (environment maps, far-field
/// textures, image hierarchies): impostors, and per CPV its impostors' ids
/// and its cost with them.
pub struct EnvMapPlacement {
    /// The impostors (ids are indices).
    pub impostors: Vec<PlacedImpostor>,
    /// Per CPV: impostor ids, ascending.
    pub cpv_impostors: Vec<Vec<u32>>,
    /// Per CPV: its cost with the environment maps of its cell.
    pub cpv_cost: Vec<Cost>,
}

/// The blocks of grid cells, `k` cells a side, that tile the view space:
/// per block its grid-cell range `(lo, hi)`, in block order (x fastest).
pub(super) fn tiles(pv: &ProblemViews, k: [u32; 3]) -> Vec<([u32; 3], [u32; 3])> {
    let counts = pv.grid.counts;
    let nb = [0, 1, 2].map(|a| counts[a].div_ceil(k[a]));
    (0..nb[2])
        .flat_map(|z| (0..nb[1]).flat_map(move |y| (0..nb[0]).map(move |x| [x, y, z])))
        .map(|b| {
            let lo = [0, 1, 2].map(|a| b[a] * k[a]);
            let hi = [0, 1, 2].map(|a| ((b[a] + 1) * k[a]).min(counts[a]));
            (lo, hi)
        })
        .collect()
}

/// The block (index in [`tiles`]' order) of each CPV.
pub(super) fn cpv_blocks(pv: &ProblemViews, k: [u32; 3]) -> Vec<usize> {
    let nb = [0, 1, 2].map(|a| pv.grid.counts[a].div_ceil(k[a]));
    pv.cpvs
        .iter()
        .map(|cpv| {
            let cell = pv.kd[cpv.kd as usize].lo;
            let b = [0, 1, 2].map(|a| cell[a] / k[a]);
            ((b[2] * nb[1] + b[1]) * nb[0] + b[0]) as usize
        })
        .collect()
}

/// The cost of a CPV's enclosing frustum with the impostors `maps` (objects,
/// sphere and layers drawn) in place of their objects.
pub(super) fn cpv_cost<'a>(
    ctx: &Context,
    pv: &ProblemViews,
    cpv: &Cpv,
    maps: impl Iterator<Item = (&'a [u32], Sphere, u32)> + Clone,
    counters: &Counters,
) -> Cost {
    let n_obj = ctx.scene.objects.len();
    // The geometry still drawn: visible and in no impostor.
    let kd = &pv.kd[cpv.kd as usize];
    let mut drawn = match ctx.visibility.and_then(|v| v.region(kd.lo, kd.hi)) {
        Some(v) => (*v).clone(),
        None => ObjectSet::full(n_obj),
    };
    for (objects, _, _) in maps.clone() {
        for &o in objects {
            drawn.remove(o);
        }
    }
    let costs = RegionCosts::new(ctx, &cpv.region, Some(&drawn), counters);
    let cone = enclosing_cone(&cpv.region, &cpv.vdi, &ctx.lens);
    let mut cost = enclosed_cost(ctx, &costs, &cone, &cpv.region, None);
    for (_, s, layers) in maps {
        if cone.intersects_sphere(s.center, s.radius) {
            cost += ctx
                .model
                .impostor(layers, s.radius, cpv.region.distance_to_point(s.center));
        }
    }
    cost
}

/// The placement of per-block maps (`maps[b]` for block `b` of [`tiles`]),
/// each CPV served by its block's ([`cpv_blocks`]).
pub(super) fn collect(
    ctx: &Context,
    pv: &ProblemViews,
    maps: &[CellMaps],
    blocks: &[usize],
    counters: &Counters,
) -> EnvMapPlacement {
    // Impostor ids in block order.
    let mut impostors = Vec::new();
    let mut first = Vec::with_capacity(maps.len() + 1);
    for m in maps {
        first.push(impostors.len() as u32);
        for (objects, sphere, memory, res) in &m.impostors {
            let d = m.aabb.distance_to_point(sphere.center);
            let cost = ctx.model.impostor(1, sphere.radius, d);
            impostors.push(PlacedImpostor {
                id: impostors.len() as u32,
                node: u32::MAX,
                objects: objects.clone(),
                sphere: SphereJson {
                    center: sphere.center.to_array(),
                    radius: sphere.radius,
                },
                view_cell: ViewCellJson::from(&ViewCell::Box(m.aabb)),
                layers: 1,
                resolution: *res,
                memory_bytes: *memory,
                time_ms: cost.cpu + cost.gpu,
            });
        }
    }
    first.push(impostors.len() as u32);
    let cpv_impostors = blocks
        .iter()
        .map(|&b| (first[b]..first[b + 1]).collect())
        .collect();
    with_costs(ctx, pv, impostors, cpv_impostors, counters)
}

/// The placement of `impostors` with each CPV's list: each CPV's cost with
/// its impostors ([`cpv_cost`], each drawn with its own layers).
pub(super) fn with_costs(
    ctx: &Context,
    pv: &ProblemViews,
    impostors: Vec<PlacedImpostor>,
    cpv_impostors: Vec<Vec<u32>>,
    counters: &Counters,
) -> EnvMapPlacement {
    let cpv_cost = pv
        .cpvs
        .par_iter()
        .zip(&cpv_impostors)
        .map(|(cpv, ids)| {
            let maps = ids.iter().map(|&i| {
                let imp = &impostors[i as usize];
                let sphere = Sphere {
                    center: DVec3::from_array(imp.sphere.center),
                    radius: imp.sphere.radius,
                };
                (&imp.objects[..], sphere, imp.layers)
            });
            cpv_cost(ctx, pv, cpv, maps, counters)
        })
        .collect();
    EnvMapPlacement {
        impostors,
        cpv_impostors,
        cpv_cost,
    }
}

/// Places environment maps for every view cell of the job's view space.
pub fn place(ctx: &Context, job: &Job, pv: &ProblemViews, counters: &Counters) -> EnvMapPlacement {
    let k = block(job.env_map.cell_m, pv);
    let maps: Vec<CellMaps> = tiles(pv, k)
        .par_iter()
        .map(|&(lo, hi)| {
            let aabb = pv.grid.cell_box(lo, hi);
            let visible = ctx.visibility.and_then(|v| v.region(lo, hi));
            cell_maps(ctx, job, aabb, visible.as_deref(), job.env_map.far_m, true)
        })
        .collect();
    collect(ctx, pv, &maps, &cpv_blocks(pv, k), counters)
}
