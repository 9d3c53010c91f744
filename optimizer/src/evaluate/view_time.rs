//! One view's exact frame time, and the ray-cast check of its visible set.

use crate::evaluate::EvalOptions;
use crate::evaluate::index::PlacementIndex;
use crate::math::geom::ViewFrustum;
use crate::math::rng::Rng;
use crate::model::cost::CostModel;
use crate::render::raycast::RayCaster;
use crate::scene::Scene;
use crate::scene::geometry::SceneGeometry;
use crate::scene::hierarchy::Hierarchy;
use crate::visibility::ObjectSet;

/// Exact time of one view. Objects outside `visible` (when given) are not
/// drawn; those of them in the frustum are listed in `culled` with their
/// distance, when asked.
#[allow(clippy::too_many_arguments)] // one view: its frustum and its CPV's data
pub(super) fn view_time(
    scene: &Scene,
    h: &Hierarchy,
    model: &CostModel,
    f: &ViewFrustum,
    replaced: &[u32],
    impostors: &[u32],
    index: &PlacementIndex,
    visible: Option<&ObjectSet>,
    mut culled: Option<&mut Vec<(f64, u32)>>,
) -> f64 {
    let eye = f.eye();
    let mut cost = model.view_cost(scene, h, f, |o| {
        if replaced.binary_search(&o).is_ok() {
            return false;
        }
        if visible.is_some_and(|v| !v.contains(o)) {
            if let Some(c) = culled.as_deref_mut() {
                let s = &h.object_spheres[o as usize];
                c.push((eye.distance(s.center) - s.radius, o));
            }
            return false;
        }
        true
    });
    for &i in impostors {
        let imp = &index.impostors[i as usize];
        let s = imp.sphere;
        if f.intersects_sphere(s.center, s.radius) {
            cost += model.impostor(imp.layers, s.radius, eye.distance(s.center));
        }
    }
    model.frame_time(cost)
}

/// Objects visible from the view point (rays through the image and at the
/// nearest culled objects) that `visible` lacks: `(object, by_probe)`.
#[allow(clippy::too_many_arguments)] // one view and its check budget
pub(super) fn check_view(
    caster: &RayCaster,
    geom: &SceneGeometry,
    ranges: &[(usize, usize)],
    f: &ViewFrustum,
    fov_deg: f64,
    aspect: f64,
    visible: &ObjectSet,
    culled: &mut [(f64, u32)],
    opts: &EvalOptions,
    rng: &mut Rng,
) -> (Vec<(u32, bool)>, u64) {
    let mut missed: Vec<(u32, bool)> = Vec::new();
    let mut rays = 0u64;
    let (right, up, fwd) = f.basis();
    let tv = (fov_deg.to_radians() * 0.5).tan();
    let th = tv * aspect;
    let side = f64::from(opts.check_rays).sqrt().ceil() as u32;
    for j in 0..side {
        for i in 0..side {
            if u64::from(j * side + i) >= u64::from(opts.check_rays) {
                break;
            }
            let x = ((f64::from(i) + rng.f64()) / f64::from(side) * 2.0 - 1.0) * th;
            let y = ((f64::from(j) + rng.f64()) / f64::from(side) * 2.0 - 1.0) * tv;
            let dir = fwd + right * x + up * y;
            rays += 1;
            caster.trace(f.eye(), dir, 0.0, f64::INFINITY, &mut |o| {
                if !visible.contains(o) && !missed.iter().any(|m| m.0 == o) {
                    missed.push((o, false));
                }
            });
        }
    }
    culled.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    for &(_, o) in culled.iter().take(opts.check_objects as usize) {
        if missed.iter().any(|m| m.0 == o) {
            continue;
        }
        for _ in 0..2 {
            let Some(p) = geom.surface_point(ranges[o as usize], f.eye(), 8, rng, |p| {
                f.distance(p) <= 0.0
            }) else {
                break;
            };
            rays += 1;
            if caster.segment_clear(f.eye(), p) {
                missed.push((o, true));
                break;
            }
        }
    }
    (missed, rays)
}
