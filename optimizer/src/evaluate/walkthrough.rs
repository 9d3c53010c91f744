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

/// A view: eye and unit direction.
type View = (DVec3, DVec3);

/// The views of the job's own walkthrough: `frames` points evenly spaced
/// along its path, each looking along the path, level; `None` when the
/// job has no path (see [`Prepared::walkthrough_times`], which then tours
/// the problem).
pub fn walkthrough_views(job: &Job) -> Option<Vec<View>> {
    let w = job.walkthrough.as_ref()?;
    let points: Vec<View> = w
        .points
        .iter()
        .map(|p| (DVec3::from_array(*p), DVec3::ZERO))
        .collect();
    Some(resample(&points, w.frames, job.vs_min(), job.vs_max()))
}

/// `frames` views evenly spaced by arc length along the polyline of
/// `points` (eye, direction), kept inside `[lo, hi]`. Each looks in the
/// direction interpolated between its segment's ends, or along the path,
/// level, where those give none.
fn resample(points: &[View], frames: u32, lo: DVec3, hi: DVec3) -> Vec<View> {
    if points.len() < 2 {
        return Vec::new();
    }
    let mut acc = vec![0.0];
    for w in points.windows(2) {
        let l = acc.last().copied().unwrap_or(0.0) + w[0].0.distance(w[1].0);
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
            let (a, b) = (points[k], points[k + 1]);
            let p = a.0.lerp(b.0, t).clamp(lo, hi);
            let mut dir = a.1.lerp(b.1, t);
            if dir.length_squared() < 1e-12 {
                dir = b.0 - a.0;
                dir.y = 0.0;
            }
            if dir.length_squared() < 1e-18 {
                dir = DVec3::X;
            }
            (p, dir.normalize())
        })
        .collect()
}

/// Frame times along a walkthrough.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PathTimes {
    /// With the placement's impostors, ms.
    pub frame_ms: Vec<f64>,
    /// With no impostor, ms.
    pub bare_ms: Vec<f64>,
    /// The placement's estimate (with its impostors) for the problem view
    /// each frame lies in, ms; `None` outside problem views.
    pub estimate_ms: Vec<Option<f64>>,
}

/// Positions sampled for the problem tour, about.
const TOUR_POSITIONS: f64 = 1024.0;
/// Directions per position: yaws, at each of the tour's pitches.
const TOUR_YAWS: u32 = 16;
/// Rounds of the local search that refines each stop (each halves its steps).
const TOUR_REFINE_ROUNDS: u32 = 8;
/// The slowest positions refined before the stops are chosen among them.
const TOUR_REFINED: usize = 64;
/// The most waypoints of the tour.
const TOUR_STOPS: usize = 8;
/// Points of the spline per segment between two waypoints.
const TOUR_SPLINE: u32 = 24;
/// Frames of the tour.
const TOUR_FRAMES: u32 = 1000;

/// The uniform Catmull-Rom point at `t` of the segment `p1`–`p2`.
fn catmull_rom(p0: DVec3, p1: DVec3, p2: DVec3, p3: DVec3, t: f64) -> DVec3 {
    let (t2, t3) = (t * t, t * t * t);
    0.5 * ((2.0 * p1)
        + (p2 - p0) * t
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * t3)
}

impl Prepared<'_> {
    /// The walkthrough of the placement's job and its frame times with the
    /// placement, with no impostor, and as the placement estimates them.
    /// The path is the job's own, or else a tour through the problem: on a
    /// grid of positions over the view space (at mid-height; 16 yaws at the
    /// pitches of [`tour_pitches`]), the slowest without impostors are
    /// refined by a local search (position, height, yaw, pitch) to the
    /// slowest view near each; up to eight of those, apart from each other,
    /// are visited nearest first from the slowest in a closed Catmull-Rom
    /// loop, the frame nearest each stop showing the stop's view and the
    /// camera turning between them. The tour depends on the scene and the
    /// job's view space, visibility, camera and cost model only, not on
    /// the placement, so every run of a report follows the same path (found
    /// once per preparation).
    pub fn walkthrough_times(&self, placement: &Placement, source: &str) -> Result<PathTimes> {
        let job = self.job();
        let scene = self.scene();
        let index = PlacementIndex::new(scene, job, placement, source)?;
        let model = CostModel::new(job);
        let [w, hgt] = job.camera.resolution;
        let aspect = f64::from(w) / f64::from(hgt);
        // A view's time (with its problem view's impostors when `with`),
        // its problem view, and whether impostors were drawn.
        let time = |(eye, dir): View, with: bool| -> (f64, Option<u32>, bool) {
            let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
            let Some(cell) = index.grid.cell_of(eye) else {
                return (f64::NAN, None, false);
            };
            let (cpv, replaced, imps) = if with {
                index.view_cpv(eye, cell, dir)
            } else {
                (None, Vec::new(), &[][..])
            };
            let set = self.visibility().map(|v| &v.cell(cell).set);
            let t = view_time(
                scene,
                self.hierarchy(),
                &model,
                &f,
                &replaced,
                imps,
                &index,
                set.map(|s| &**s),
                None,
            );
            (t, cpv, !imps.is_empty())
        };
        let views = self.walkthrough_path();
        self.prefetch_path(&views);
        let rows: Vec<(f64, f64, Option<f64>)> = views
            .par_iter()
            .map(|&v| {
                let (with, cpv, drawn) = time(v, true);
                // Without impostors drawn, the frame is its own control.
                let bare = if drawn { time(v, false).0 } else { with };
                let estimate = cpv
                    .and_then(|c| placement.cpvs.get(c as usize))
                    .map(|c| c.time_ms_final);
                (with, bare, estimate)
            })
            .collect();
        Ok(PathTimes {
            frame_ms: rows.iter().map(|r| r.0).collect(),
            bare_ms: rows.iter().map(|r| r.1).collect(),
            estimate_ms: rows.iter().map(|r| r.2).collect(),
        })
    }

    /// The job's walkthrough path, or else the tour through the problem
    /// (see [`walkthrough_times`](Self::walkthrough_times)).
    pub fn walkthrough_path(&self) -> Vec<View> {
        match walkthrough_views(self.job()) {
            Some(v) => v,
            None => self
                .cached_tour(|| self.problem_tour(&|v| self.bare_time(v)))
                .to_vec(),
        }
    }

    /// The exact time of a view with no impostor (its cell's visible set
    /// drawn, when the job has visibility); NaN outside the view space.
    pub fn bare_time(&self, (eye, dir): View) -> f64 {
        let job = self.job();
        let Some(cell) = job.grid().cell_of(eye) else {
            return f64::NAN;
        };
        let [w, hgt] = job.camera.resolution;
        let f = ViewFrustum::new(eye, dir, job.camera.fov_deg, f64::from(w) / f64::from(hgt));
        let set = self.visibility().map(|v| &v.cell(cell).set);
        let model = CostModel::new(job);
        let cost = model.view_cost(self.scene(), self.hierarchy(), &f, |o| {
            set.is_none_or(|s| s.contains(o))
        });
        model.frame_time(cost)
    }

    /// Computes, in parallel, the visible sets of the cells `views` pass
    /// through (when the job has visibility).
    pub fn prefetch_path(&self, views: &[View]) {
        if let Some(v) = self.visibility() {
            let grid = self.job().grid();
            let mut cells: Vec<[u32; 3]> = views
                .iter()
                .filter_map(|(eye, _)| grid.cell_of(*eye))
                .collect();
            cells.sort_unstable();
            cells.dedup();
            v.prefetch(&cells);
        }
    }

    /// The tour through the problem (see
    /// [`walkthrough_times`](Self::walkthrough_times)), `bare` timing a view
    /// with no impostor.
    fn problem_tour(&self, bare: &(dyn Fn(View) -> f64 + Sync)) -> Vec<View> {
        let job = self.job();
        let (lo, hi) = (job.vs_min(), job.vs_max());
        let size = hi - lo;
        let ratio = (size.x.max(1e-9) / size.z.max(1e-9)).clamp(1.0 / 256.0, 256.0);
        let nx = (TOUR_POSITIONS * ratio).sqrt().round().clamp(1.0, 256.0) as u32;
        let nz = (TOUR_POSITIONS / f64::from(nx)).round().clamp(1.0, 256.0) as u32;
        let y = (lo.y + hi.y) * 0.5;
        let [p0, p1] = job.view_space.pitch_deg;
        let pitches = tour_pitches(p0, p1);
        let dir_of = |yaw: f64, pitch: f64| {
            let (sp, cp) = pitch.to_radians().sin_cos();
            DVec3::new(cp * yaw.cos(), sp, cp * yaw.sin())
        };
        let positions: Vec<DVec3> = (0..nz)
            .flat_map(|k| {
                (0..nx).map(move |i| {
                    DVec3::new(
                        lo.x + size.x * (f64::from(i) + 0.5) / f64::from(nx),
                        y,
                        lo.z + size.z * (f64::from(k) + 0.5) / f64::from(nz),
                    )
                })
            })
            .collect();
        // Per position: its slowest direction and time.
        let worst: Vec<(f64, f64, f64)> = positions
            .par_iter()
            .map(|&eye| {
                let mut best = (f64::NEG_INFINITY, 0.0, 0.0);
                for &pitch in &pitches {
                    for k in 0..TOUR_YAWS {
                        let yaw = std::f64::consts::TAU * f64::from(k) / f64::from(TOUR_YAWS);
                        let t = bare((eye, dir_of(yaw, pitch)));
                        if t > best.0 {
                            best = (t, yaw, pitch);
                        }
                    }
                }
                best
            })
            .collect();
        let mut order: Vec<usize> = (0..positions.len()).collect();
        order.sort_by(|&a, &b| worst[b].0.total_cmp(&worst[a].0).then(a.cmp(&b)));
        // The slowest positions refined by a local search (position within
        // half a grid step, the height band, yaw and pitch; steps halved
        // each round) to the slowest view near each, which the tour shows.
        let step = DVec3::new(size.x / f64::from(nx), 0.0, size.z / f64::from(nz)) * 0.5;
        let mut refined: Vec<(f64, DVec3, f64, f64)> = order[..order.len().min(TOUR_REFINED)]
            .par_iter()
            .map(|&s| {
                let (t, yaw, pitch) = worst[s];
                let mut best = (t, positions[s], yaw, pitch);
                let (mut d, mut dyaw, mut dpitch) = (
                    step,
                    std::f64::consts::PI / f64::from(TOUR_YAWS),
                    TOUR_PITCH_STEP * 0.5,
                );
                for _ in 0..TOUR_REFINE_ROUNDS {
                    let (_, eye, yaw, pitch) = best;
                    let moves = [
                        (eye + DVec3::X * d.x, yaw, pitch),
                        (eye - DVec3::X * d.x, yaw, pitch),
                        (eye + DVec3::Z * d.z, yaw, pitch),
                        (eye - DVec3::Z * d.z, yaw, pitch),
                        (DVec3::new(eye.x, lo.y, eye.z), yaw, pitch),
                        (DVec3::new(eye.x, hi.y, eye.z), yaw, pitch),
                        (eye, yaw + dyaw, pitch),
                        (eye, yaw - dyaw, pitch),
                        (eye, yaw, (pitch + dpitch).min(p1)),
                        (eye, yaw, (pitch - dpitch).max(p0)),
                    ];
                    for (e, yw, pt) in moves {
                        let e = e.clamp(lo, hi);
                        let t = bare((e, dir_of(yw, pt)));
                        if t > best.0 {
                            best = (t, e, yw, pt);
                        }
                    }
                    d *= 0.5;
                    dyaw *= 0.5;
                    dpitch *= 0.5;
                }
                best
            })
            .collect();
        // Stops: the slowest refined views, spaced apart.
        refined.sort_by(|a, b| b.0.total_cmp(&a.0));
        let spacing = (size.x * size.x + size.z * size.z).sqrt() / TOUR_STOPS as f64;
        let mut chosen: Vec<(f64, DVec3, f64, f64)> = Vec::new();
        for r in refined {
            if chosen.len() == TOUR_STOPS {
                break;
            }
            if chosen.iter().all(|c| c.1.distance(r.1) >= spacing) {
                chosen.push(r);
            }
        }
        let positions: Vec<DVec3> = chosen.iter().map(|r| r.1).collect();
        let worst: Vec<(f64, DVec3)> = chosen.iter().map(|r| (r.0, dir_of(r.2, r.3))).collect();
        // Nearest first from the slowest (stop 0).
        let mut tour = vec![0];
        let mut left: Vec<usize> = (1..positions.len()).collect();
        while !left.is_empty() {
            let here = positions[*tour.last().expect("one stop")];
            let (k, _) = left
                .iter()
                .enumerate()
                .map(|(k, &s)| (k, positions[s].distance_squared(here)))
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
                .expect("not empty");
            tour.push(left.remove(k));
        }
        let n = tour.len();
        let points: Vec<View> = if n == 1 {
            // One stop: a small loop around it, facing its slowest way.
            let c = positions[tour[0]];
            let r = size * 0.1;
            (0..=32)
                .map(|i| {
                    let a = std::f64::consts::TAU * f64::from(i) / 32.0;
                    (
                        DVec3::new(c.x + r.x * a.cos(), y, c.z + r.z * a.sin()),
                        worst[tour[0]].1,
                    )
                })
                .collect()
        } else {
            let at = |k: usize| positions[tour[k % n]];
            let mut pts = Vec::new();
            for k in 0..n {
                let (d1, d2) = (worst[tour[k]].1, worst[tour[(k + 1) % n]].1);
                for j in 0..TOUR_SPLINE {
                    let t = f64::from(j) / f64::from(TOUR_SPLINE);
                    let p = catmull_rom(at(k + n - 1), at(k), at(k + 1), at(k + 2), t);
                    // Facing the stop's slowest way near it, turning between.
                    let s = t * t * (3.0 - 2.0 * t);
                    pts.push((p.clamp(lo, hi), d1.lerp(d2, s)));
                }
            }
            pts.push((at(0), worst[tour[0]].1));
            pts
        };
        let mut frames = resample(&points, TOUR_FRAMES, lo, hi);
        // The frame nearest each stop is the stop's own slowest view, so
        // the tour shows the slowest views it found, not views beside them.
        for &s in &tour {
            let nearest = frames
                .iter()
                .enumerate()
                .map(|(k, f)| (k, f.0.distance_squared(positions[s])))
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
                .map(|(k, _)| k);
            if let Some(k) = nearest {
                frames[k] = (positions[s], worst[s].1);
            }
        }
        frames
    }
}

/// Pitch steps of the problem tour, degrees.
const TOUR_PITCH_STEP: f64 = 20.0;

/// The pitches the problem tour samples in the band `[p0, p1]`: level (or
/// the band's nearest) and every [`TOUR_PITCH_STEP`] up and down from it
/// within the band, at most 60° away, and the band's middle.
fn tour_pitches(p0: f64, p1: f64) -> Vec<f64> {
    let level = 0.0f64.clamp(p0, p1);
    let mut pitches = vec![level, (p0 + p1) * 0.5];
    for k in 1..=3 {
        let d = TOUR_PITCH_STEP * f64::from(k);
        for p in [level - d, level + d] {
            if (p0..=p1).contains(&p) {
                pitches.push(p);
            }
        }
    }
    pitches.sort_by(f64::total_cmp);
    pitches.dedup_by(|a, b| (*a - *b).abs() < 1.0);
    pitches
}

#[cfg(test)]
mod tests {
    use super::tour_pitches;

    #[test]
    fn tour_pitches_cover_the_band_around_level() {
        assert_eq!(
            tour_pitches(-90.0, 90.0),
            [-60.0, -40.0, -20.0, 0.0, 20.0, 40.0, 60.0]
        );
        // A band above the roofs looking down: its top, steps down, its middle.
        assert_eq!(tour_pitches(-90.0, -10.0), [-70.0, -50.0, -30.0, -10.0]);
        assert_eq!(tour_pitches(-5.0, 5.0), [0.0]);
    }
}
