//! Frame times along a path: the walkthrough curves of the reports.

use glam::DVec3;
use rayon::prelude::*;

use crate::Result;
use crate::api::job::Job;
use crate::api::placement::Placement;
use crate::evaluate::index::PlacementIndex;
use crate::evaluate::view_time::view_time;
use crate::input::Prepared;
use crate::math::geom::ViewFrustum;
use crate::model::cost::CostModel;

/// The views of a walkthrough: `frames` points evenly spaced along the
/// job's path (or, without one, a closed loop through the view space at
/// mid-height: an ellipse over 80 % of its extent), each looking along the
/// path, level.
pub fn walkthrough_views(job: &Job) -> Vec<(DVec3, DVec3)> {
    let (lo, hi) = (job.vs_min(), job.vs_max());
    let (points, frames): (Vec<DVec3>, u32) = match &job.walkthrough {
        Some(w) => (
            w.points.iter().map(|p| DVec3::from_array(*p)).collect(),
            w.frames,
        ),
        None => {
            let c = (lo + hi) * 0.5;
            let r = (hi - lo) * 0.4;
            let n = 256;
            (
                (0..=n)
                    .map(|i| {
                        let a = std::f64::consts::TAU * f64::from(i) / f64::from(n);
                        DVec3::new(c.x + r.x * a.cos(), c.y, c.z + r.z * a.sin())
                    })
                    .collect(),
                1000,
            )
        }
    };
    // Arc length along the polyline.
    let mut acc = vec![0.0];
    for w in points.windows(2) {
        let l = acc.last().copied().unwrap_or(0.0) + w[0].distance(w[1]);
        acc.push(l);
    }
    let total = acc.last().copied().unwrap_or(0.0);
    (0..frames)
        .map(|f| {
            let s = total * f64::from(f) / f64::from(frames.max(2) - 1);
            let k = acc
                .partition_point(|&a| a <= s)
                .saturating_sub(1)
                .min(points.len() - 2);
            let seg = acc[k + 1] - acc[k];
            let t = if seg > 0.0 { (s - acc[k]) / seg } else { 0.0 };
            let p = points[k].lerp(points[k + 1], t).clamp(lo, hi);
            let mut dir = points[k + 1] - points[k];
            dir.y = 0.0;
            if dir.length_squared() < 1e-18 {
                dir = DVec3::X;
            }
            (p, dir.normalize())
        })
        .collect()
}

impl Prepared<'_> {
    /// Frame time of each given view `(eye, direction)` with `placement`'s
    /// impostors (the views' problem views' impostors swapped in) and the
    /// visible sets of their cells: the frame-time curve of a walkthrough.
    /// `source` names the placement in errors.
    pub fn frame_times(
        &self,
        placement: &Placement,
        views: &[(DVec3, DVec3)],
        source: &str,
    ) -> Result<Vec<f64>> {
        let job = self.job();
        let scene = self.scene();
        let index = PlacementIndex::new(scene, job, placement, source)?;
        let model = CostModel::new(job);
        let [w, hgt] = job.camera.resolution;
        let aspect = f64::from(w) / f64::from(hgt);
        Ok(views
            .par_iter()
            .map(|&(eye, dir)| {
                let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
                let Some(cell) = index.grid.cell_of(eye) else {
                    return f64::NAN;
                };
                let (_, replaced, imps) = index.view_cpv(eye, cell, dir);
                let set = self.visibility().map(|v| &v.cell(cell).set);
                view_time(
                    scene,
                    self.hierarchy(),
                    &model,
                    &f,
                    replaced,
                    imps,
                    &index,
                    set.map(|s| &**s),
                    None,
                )
            })
            .collect())
    }
}
