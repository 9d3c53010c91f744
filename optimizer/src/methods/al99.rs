//! `al99`: automatic image placement per viewpoint (Aliaga and Lastra
//! 1999), in our terms. Grid points are nodes of the view-space hierarchy:
//! first those no longer than `al99.grid_m` a side, each subdivided (its
//! images discarded) where one of its views finds no valid image, down to
//! the problem views' cells (the paper's adaptive grid; its star shape is
//! the node's box, from every point of which an image must be valid). The
//! views of a grid point are its problem views (the paper's yaw ranges
//! extended to our direction intervals, as its own "5D" reading suggests);
//! a view gets at most one image; images are never shared between grid
//! points.
//!
//! Per grid point, the view slowest with the images made so far (each view
//! taking the one image that helps it most) gets a new image while it is
//! above the target: the subset of its objects the image replaces is found
//! by the paper's binary search over contiguous subsets: starting from every
//! object the view may image, each step moves one of five borders (near,
//! top, bottom, right, left: the far one never) halfway through the
//! subset's objects, choosing the move whose best cost-benefit within
//! `al99.lookahead` further steps is largest (ties in that order), until no
//! move culls enough for the optimisation budget (the target less
//! `al99.gap` of the drawing time it allows, [`optimisation_budget`]); the
//! image is the last subset on the way valid from the whole grid point.
//! Cost-benefit as printed:
//! `CB = C·(1 − g/G) + B·(B₁·(1 − max(I_w, I_h)/max(S_w, S_h)) + B₂·d/A)` with
//! `C, B, B₁, B₂ = 0.4, 0.6, 0.1, 0.9`, `g` the view's time with the subset
//! imaged, `G` without, `I` the subset's screen extent, `S` the screen's,
//! `d` the subset's nearest distance and `A` the scene's longest side.
//!
//! Where the paper counts primitives we count estimated time (its own
//! "time mode"; `cost_model.combine: "primitives"` counts triangles); its
//! objects are octree cells, ours the scene's objects; an image is a
//! layered impostor with the grid point's box as its view cell, layers and
//! texels by the same image criterion as every other method (the paper's
//! nine-image LDIs are not modelled). A view no subset brings within the
//! budget at the finest grid point stays unsolved.

use rayon::prelude::*;

use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, SphereJson, ViewCellJson};
use crate::math::enclosing::enclosing_cone;
use crate::math::geom::{Aabb, Sphere};
use crate::methods::env_map::{EnvMapPlacement, with_costs};
use crate::model::cost::Cost;
use crate::model::impostor::{ImpostorModel, ViewCell};
use crate::views::{Context, Counters, Cpv, ProblemViews, RegionCosts};

/// The paper's cost-benefit weights `C, B, B₁, B₂`.
pub const CB_WEIGHTS: [f64; 4] = [0.4, 0.6, 0.1, 0.9];

/// An object a view may image: its screen extent (tangents along the
/// view's right and up axes), its nearest depth and its cost.
#[derive(Clone, Copy, Debug)]
struct Item {
    object: u32,
    /// Left, right, bottom, top, near.
    borders: [f64; 5],
    cost: Cost,
}

/// A contiguous subset: the items within the borders (left, right,
/// bottom, top, near), sorted.
#[derive(Clone, Debug, PartialEq)]
struct Subset {
    bounds: [f64; 5],
    members: Vec<u32>,
}

/// An image: the objects it replaces (ascending), their sphere, and its
/// layers, memory and texels a side.
#[derive(Clone, Debug)]
struct Image {
    objects: Vec<u32>,
    sphere: Sphere,
    layers: u32,
    memory: u64,
    resolution: u32,
}

/// One view's search: its items, its cost, and what the figures of merit
/// need.
struct View<'a> {
    ctx: &'a Context<'a>,
    imodel: ImpostorModel,
    cell: Aabb,
    region: Aabb,
    items: Vec<Item>,
    /// Cost of the view's enclosing frustum with no image.
    base: Cost,
    /// Screen extent, tangents: `max(S_w, S_h)`.
    screen: f64,
    /// The scene's longest side.
    longest: f64,
}

impl View<'_> {
    fn within(&self, b: &[f64; 5], it: &Item) -> bool {
        let x = &it.borders;
        x[0] >= b[0] && x[1] <= b[1] && x[2] >= b[2] && x[3] <= b[3] && x[4] >= b[4]
    }

    fn subset(&self, bounds: [f64; 5], of: &[u32]) -> Subset {
        let members = of
            .iter()
            .copied()
            .filter(|&i| self.within(&bounds, &self.items[i as usize]))
            .collect();
        Subset { bounds, members }
    }

    /// The image of a subset (`None`: no image of it is valid from the
    /// whole cell).
    fn image(&self, s: &Subset) -> Option<Image> {
        let h = self.ctx.hierarchy;
        let sphere = s
            .members
            .iter()
            .map(|&i| h.object_spheres[self.items[i as usize].object as usize])
            .reduce(|a, b| a.merge(&b))?;
        let spec = self.imodel.boxed(&sphere, &self.cell)?;
        let mut objects: Vec<u32> = s
            .members
            .iter()
            .map(|&m| self.items[m as usize].object)
            .collect();
        objects.sort_unstable();
        Some(Image {
            objects,
            sphere,
            layers: spec.layers,
            memory: spec.memory_bytes,
            resolution: spec.resolution,
        })
    }

    /// The view's frame time with `image` drawn for its objects (those of
    /// the view's items among them).
    fn time_with_image(&self, image: &Image) -> f64 {
        let saved = self
            .items
            .iter()
            .filter(|it| image.objects.binary_search(&it.object).is_ok())
            .fold(Cost::default(), |acc, it| acc + it.cost);
        let drawn = self.ctx.model.impostor(
            image.layers,
            image.sphere.radius,
            self.region.distance_to_point(image.sphere.center),
        );
        self.ctx.model.frame_time(self.base - saved + drawn)
    }

    /// The view's frame time with the subset imaged (`None`: no image is
    /// valid from the whole cell).
    fn time_with(&self, s: &Subset) -> Option<f64> {
        Some(self.time_with_image(&self.image(s)?))
    }

    /// The view's frame time with the one of `images` that helps it most,
    /// and which (`None`: none helps).
    fn best(&self, images: &[Image]) -> (f64, Option<usize>) {
        let mut out = (self.ctx.model.frame_time(self.base), None);
        for (k, img) in images.iter().enumerate() {
            let t = self.time_with_image(img);
            if t < out.0 {
                out = (t, Some(k));
            }
        }
        out
    }

    /// The cost of the subset's objects in the view.
    fn saved(&self, s: &Subset) -> Cost {
        s.members
            .iter()
            .fold(Cost::default(), |acc, &i| acc + self.items[i as usize].cost)
    }

    /// The time that decides whether a subset culls enough: with its image
    /// where one is valid, else with its objects culled (the paper's test
    /// counts the geometry left; an image's validity is checked after).
    fn culled_time(&self, s: &Subset) -> f64 {
        self.time_with(s)
            .unwrap_or_else(|| self.ctx.model.frame_time(self.base - self.saved(s)))
    }

    /// The paper's cost-benefit of a subset whose view time is `g`.
    fn cb(&self, s: &Subset, g: f64) -> f64 {
        let [c, b, b1, b2] = CB_WEIGHTS;
        let total = self.ctx.model.frame_time(self.base);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut near = f64::INFINITY;
        for &i in &s.members {
            let x = &self.items[i as usize].borders;
            lo = [lo[0].min(x[0]), lo[1].min(x[2])];
            hi = [hi[0].max(x[1]), hi[1].max(x[3])];
            near = near.min(x[4]);
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let size = (1.0 - extent / self.screen).clamp(0.0, 1.0);
        let depth = (near / self.longest).clamp(0.0, 1.0);
        c * (1.0 - (g / total).min(1.0)) + b * (b1 * size + b2 * depth)
    }

    /// The five moves of a subset, in the paper's order of preference:
    /// near back, top down, bottom up, right left, left right, each
    /// halfway through its members' values of that border. Moves that
    /// change nothing are left out.
    fn moves(&self, s: &Subset) -> Vec<Subset> {
        let mut out = Vec::with_capacity(5);
        // (border, moves up (raising a lower bound))
        for (k, raise) in [(4, true), (3, false), (2, true), (1, false), (0, true)] {
            let mut v: Vec<f64> = s
                .members
                .iter()
                .map(|&i| self.items[i as usize].borders[k])
                .collect();
            v.sort_by(f64::total_cmp);
            if v.len() < 2 {
                continue;
            }
            let mid = v[v.len() / 2];
            let mut b = s.bounds;
            if raise {
                // Strictly past the lower half.
                b[k] = if mid > v[0] { mid } else { next_up(v[0]) };
            } else {
                let m = v[(v.len() - 1) / 2];
                b[k] = if m < v[v.len() - 1] {
                    m
                } else {
                    next_down(v[v.len() - 1])
                };
            }
            let child = self.subset(b, &s.members);
            if !child.members.is_empty() && child.members.len() < s.members.len() {
                out.push(child);
            }
        }
        out
    }

    /// The best cost-benefit among `s` (when it culls enough for
    /// `budget`) and its descendants within `depth` moves.
    fn lookahead(&self, s: &Subset, depth: u32, budget: f64) -> f64 {
        let g = self.culled_time(s);
        let own = if g <= budget {
            self.cb(s, g)
        } else {
            f64::NEG_INFINITY
        };
        if depth == 0 {
            return own;
        }
        self.moves(s)
            .iter()
            .map(|c| self.lookahead(c, depth - 1, budget))
            .fold(own, f64::max)
    }

    /// The paper's search from every item, stepping while a move still
    /// culls enough for `budget`: the last subset on the way whose image is
    /// valid from the whole cell and brings the view within `budget`
    /// (`None` when there is none).
    fn search(&self, budget: f64, depth: u32) -> Option<Subset> {
        let all: Vec<u32> = (0..self.items.len() as u32).collect();
        let mut bounds = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
        ];
        for it in &self.items {
            bounds[0] = bounds[0].min(it.borders[0]);
            bounds[1] = bounds[1].max(it.borders[1]);
            bounds[2] = bounds[2].min(it.borders[2]);
            bounds[3] = bounds[3].max(it.borders[3]);
            bounds[4] = bounds[4].min(it.borders[4]);
        }
        let mut s = self.subset(bounds, &all);
        if s.members.is_empty() || self.culled_time(&s) > budget {
            return None;
        }
        let ok = |s: &Subset| self.time_with(s).is_some_and(|g| g <= budget);
        let mut last = ok(&s).then(|| s.clone());
        loop {
            let mut best: Option<(f64, Subset)> = None;
            for c in self.moves(&s) {
                if self.culled_time(&c) > budget {
                    continue;
                }
                let v = self.lookahead(&c, depth, budget);
                if best.as_ref().is_none_or(|b| v > b.0) {
                    best = Some((v, c));
                }
            }
            match best {
                Some((_, c)) => {
                    s = c;
                    if ok(&s) {
                        last = Some(s.clone());
                    }
                }
                None => return last,
            }
        }
    }
}

fn next_up(x: f64) -> f64 {
    x + x.abs().max(1e-12) * 1e-12
}
fn next_down(x: f64) -> f64 {
    x - x.abs().max(1e-12) * 1e-12
}

/// The search of CPV `c` from the grid point of box `cell` (holding its
/// region): the objects it may image (visible, in its enclosing frustum,
/// ahead of the grid point and apart from its box).
fn view<'a>(
    ctx: &'a Context<'a>,
    job: &Job,
    pv: &ProblemViews,
    c: &Cpv,
    cell: Aabb,
    counters: &Counters,
) -> View<'a> {
    let h = ctx.hierarchy;
    let kd = &pv.kd[c.kd as usize];
    let visible = ctx.visibility.and_then(|v| v.region(kd.lo, kd.hi));
    let costs = RegionCosts::new(ctx, &c.region, visible.as_deref(), counters);
    let cone = enclosing_cone(&c.region, &c.vdi, &ctx.lens);
    let base = crate::views::enclosed_cost(ctx, &costs, &cone, &c.region, None);
    let (axis, _) = c.vdi.center_and_radius();
    let up0 = if axis.y.abs() > 0.9 {
        glam::DVec3::X
    } else {
        glam::DVec3::Y
    };
    let right = axis.cross(up0).normalize();
    let up = right.cross(axis);
    let g = cell.center();
    let items = h
        .object_spheres
        .iter()
        .enumerate()
        .filter_map(|(o, s)| {
            let cost = costs.objects[o];
            if (cost.cpu <= 0.0 && cost.gpu <= 0.0)
                || !cone.intersects_sphere(s.center, s.radius)
                || cell.intersects_sphere(s.center, s.radius)
            {
                return None;
            }
            let p = s.center - g;
            let z = p.dot(axis);
            if z <= s.radius {
                return None;
            }
            let (x, y) = (p.dot(right) / z, p.dot(up) / z);
            let e = s.radius / (z - s.radius);
            Some(Item {
                object: o as u32,
                borders: [x - e, x + e, y - e, y + e, z - s.radius],
                cost,
            })
        })
        .collect();
    let tan = (job.camera.fov_deg.to_radians() * 0.5).tan();
    let [w, hgt] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(hgt);
    let (lo, hi) = (h.nodes[0].aabb.min, h.nodes[0].aabb.max);
    View {
        ctx,
        imodel: ImpostorModel::new(job),
        cell,
        region: c.region,
        items,
        base,
        screen: 2.0 * tan * aspect.max(1.0),
        longest: (hi - lo).max_element().max(1e-9),
    }
}

/// The optimisation budget, ms: the target less `al99.gap` of the time a
/// frame may spend drawing (the target above the cost model's fixed frame
/// time), as the paper's budget less a share of the primitives.
pub fn optimisation_budget(job: &Job) -> f64 {
    let fixed = job.cost_model.frame_ms.min(job.target_frame_time_ms);
    job.target_frame_time_ms - job.al99.gap * (job.target_frame_time_ms - fixed)
}

/// A grid point's outcome: its images (valid from its box), the box, and
/// per CPV of it the image it takes.
type GridPoint = (Vec<Image>, Aabb, Vec<(u32, Option<usize>)>);

/// The images of the grid point of kd node `n` for its CPVs `cpvs`: each
/// round gives the slowest view an image, or finds it cannot have one.
/// Where a view finds none and the node has children, the grid point is
/// subdivided (its images discarded, as the paper's), down to the cells.
#[allow(clippy::too_many_arguments)] // one grid point of one job
fn grid_point(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    n: u32,
    cpvs: Vec<u32>,
    budget: f64,
    trial: &Counters,
    out: &mut Vec<GridPoint>,
) {
    let kd = &pv.kd[n as usize];
    let cell = pv.grid.cell_box(kd.lo, kd.hi);
    let views: Vec<View> = cpvs
        .iter()
        .map(|&c| view(ctx, job, pv, &pv.cpvs[c as usize], cell, trial))
        .collect();
    let mut images: Vec<Image> = Vec::new();
    let mut failed = vec![false; views.len()];
    for _ in 0..views.len() {
        let worst = views
            .iter()
            .enumerate()
            .filter(|(i, _)| !failed[*i])
            .map(|(i, v)| (i, v.best(&images).0))
            .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)));
        let Some((i, t)) = worst else { break };
        if t <= job.target_frame_time_ms {
            break;
        }
        let v = &views[i];
        match v.search(budget, job.al99.lookahead) {
            Some(s) => images.push(v.image(&s).expect("searched subsets have images")),
            None => failed[i] = true,
        }
    }
    if let Some(children) = kd.children.filter(|_| failed.contains(&true)) {
        drop(views);
        for ch in children {
            let k = &pv.kd[ch as usize];
            let mine: Vec<u32> = cpvs.iter().copied().filter(|&c| inside(pv, c, k)).collect();
            if !mine.is_empty() {
                grid_point(ctx, job, pv, ch, mine, budget, trial, out);
            }
        }
        return;
    }
    let picks = cpvs
        .iter()
        .zip(&views)
        .map(|(&c, v)| (c, v.best(&images).1))
        .collect();
    out.push((images, cell, picks));
}

/// Whether CPV `c`'s cell lies in kd node `k`.
fn inside(pv: &ProblemViews, c: u32, k: &crate::views::KdNode) -> bool {
    let leaf = &pv.kd[pv.cpvs[c as usize].kd as usize];
    (0..3).all(|a| leaf.lo[a] >= k.lo[a] && leaf.hi[a] <= k.hi[a])
}

/// The `al99` placement: grid points from the view-space hierarchy's
/// nodes no longer than `al99.grid_m` a side, subdivided where a view
/// finds no valid image; per grid point its images, and per CPV the one
/// image that helps it most.
pub fn place(ctx: &Context, job: &Job, pv: &ProblemViews, counters: &Counters) -> EnvMapPlacement {
    let budget = optimisation_budget(job);
    let trial = Counters::new();
    // The first grid: the highest kd nodes within `grid_m` a side.
    let mut starts: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut stack = vec![0u32];
    while let Some(n) = stack.pop() {
        let k = &pv.kd[n as usize];
        let b = pv.grid.cell_box(k.lo, k.hi);
        match k.children {
            Some([l, r]) if (b.max - b.min).max_element() > job.al99.grid_m => {
                stack.push(r);
                stack.push(l);
            }
            _ => {
                let mine: Vec<u32> = (0..pv.cpvs.len() as u32)
                    .filter(|&c| inside(pv, c, k))
                    .collect();
                if !mine.is_empty() {
                    starts.push((n, mine));
                }
            }
        }
    }
    let cells: Vec<GridPoint> = starts
        .into_par_iter()
        .flat_map_iter(|(n, cpvs)| {
            let mut out = Vec::new();
            grid_point(ctx, job, pv, n, cpvs, budget, &trial, &mut out);
            out
        })
        .collect();
    let mut impostors = Vec::new();
    let mut pick = vec![None; pv.cpvs.len()];
    for (images, cell, picks) in cells {
        let first = impostors.len() as u32;
        for img in images {
            let s = img.sphere;
            let cost = ctx
                .model
                .impostor(img.layers, s.radius, cell.distance_to_point(s.center));
            impostors.push(PlacedImpostor {
                id: impostors.len() as u32,
                node: u32::MAX,
                objects: img.objects,
                sphere: SphereJson {
                    center: s.center.to_array(),
                    radius: s.radius,
                },
                view_cell: ViewCellJson::from(&ViewCell::Box(cell)),
                layers: img.layers,
                resolution: img.resolution,
                memory_bytes: img.memory,
                time_ms: cost.cpu + cost.gpu,
            });
        }
        for (c, k) in picks {
            pick[c as usize] = k.map(|k| first + k as u32);
        }
    }
    let cpv_impostors = pick.into_iter().map(|k| k.into_iter().collect()).collect();
    with_costs(ctx, pv, impostors, cpv_impostors, counters)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{synthetic_city, synthetic_job, with_problem_views};

    /// The cost-benefit of a hand-made subset, the search's result meeting
    /// the budget with a valid image, and each move shrinking its subset
    /// along one border only.
    #[test]
    fn cost_benefit_by_hand_and_the_search_meets_its_budget() {
        let scene = synthetic_city(3, 5, 5);
        let job = synthetic_job(5, 5);
        with_problem_views(&scene, &job, |ctx, pv| {
            let budget = optimisation_budget(&job);
            let fixed = job.cost_model.frame_ms;
            let t = job.target_frame_time_ms;
            assert!((budget - (t - 0.1 * (t - fixed))).abs() < 1e-12);
            let mut found = 0;
            for c in &pv.cpvs {
                let kd = &pv.kd[c.kd as usize];
                let cell = pv.grid.cell_box(kd.lo, kd.hi);
                let v = view(ctx, &job, pv, c, cell, &Counters::new());
                let all: Vec<u32> = (0..v.items.len() as u32).collect();
                if all.len() < 4 {
                    continue;
                }
                // By hand: two items.
                let sub = Subset {
                    bounds: [0.0; 5],
                    members: vec![0, 1],
                };
                let (a, b) = (v.items[0].borders, v.items[1].borders);
                let extent = (a[1].max(b[1]) - a[0].min(b[0])).max(a[3].max(b[3]) - a[2].min(b[2]));
                let g = 0.8 * v.ctx.model.frame_time(v.base);
                let expected = 0.4 * 0.2
                    + 0.6
                        * (0.1 * (1.0 - extent / v.screen).clamp(0.0, 1.0)
                            + 0.9 * (a[4].min(b[4]) / v.longest).clamp(0.0, 1.0));
                assert!((v.cb(&sub, g) - expected).abs() < 1e-12);
                // Moves: strictly smaller, within the parent's bounds, one
                // border changed.
                let whole = v.subset(
                    [
                        f64::NEG_INFINITY,
                        f64::INFINITY,
                        f64::NEG_INFINITY,
                        f64::INFINITY,
                        f64::NEG_INFINITY,
                    ],
                    &all,
                );
                assert_eq!(whole.members, all);
                for m in v.moves(&whole) {
                    assert!(m.members.len() < whole.members.len() && !m.members.is_empty());
                    let changed = (0..5).filter(|&k| m.bounds[k] != whole.bounds[k]).count();
                    assert_eq!(changed, 1);
                    assert!(m.members.iter().all(|x| whole.members.contains(x)));
                }
                if let Some(s) = v.search(budget, 2) {
                    found += 1;
                    let g = v.time_with(&s).expect("a valid image");
                    assert!(g <= budget, "{g} > {budget}");
                    let img = v.image(&s).expect("an image");
                    assert!((v.time_with_image(&img) - g).abs() < 1e-12);
                }
            }
            assert!(found > 0, "no view found a subset");
        });
    }

    /// At most one image per problem view, valid from its whole region;
    /// grid points' boxes never overlap, so no image serves two; some views
    /// are solved.
    #[test]
    fn one_image_per_view_and_none_shared_between_grid_points() {
        let scene = synthetic_city(3, 5, 5);
        let job = synthetic_job(5, 5);
        with_problem_views(&scene, &job, |ctx, pv| {
            let p = place(ctx, &job, pv, &Counters::new());
            assert!(!p.impostors.is_empty());
            let boxes: Vec<Aabb> = p
                .impostors
                .iter()
                .map(|imp| match ViewCell::from(&imp.view_cell) {
                    ViewCell::Box(b) => b,
                    ViewCell::Shaft { .. } => panic!("al99 images have box view cells"),
                })
                .collect();
            for (a, x) in boxes.iter().enumerate() {
                for y in &boxes[a + 1..] {
                    let apart = (0..3).any(|k| x.max[k] <= y.min[k] || y.max[k] <= x.min[k]);
                    assert!(x == y || apart, "grid points overlap: {x:?} {y:?}");
                }
            }
            // Grid points no longer than `grid_m` (here every one is subdivided
            // to a cell: this city's views find no image valid from more).
            let longest = |b: &Aabb| (b.max - b.min).max_element();
            assert!(boxes.iter().all(|b| longest(b) <= job.al99.grid_m + 1e-9));
            let mut solved = 0;
            for (c, cpv) in pv.cpvs.iter().enumerate() {
                let ids = &p.cpv_impostors[c];
                assert!(ids.len() <= 1);
                for &i in ids {
                    assert!(boxes[i as usize].contains_box(&cpv.region));
                }
                if ctx.model.frame_time(p.cpv_cost[c]) <= job.target_frame_time_ms {
                    solved += 1;
                }
            }
            assert!(solved > 0);
        });
    }
}
