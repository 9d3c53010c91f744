//! Image error of a placement's impostors (DESIGN §2.10): render sampled
//! views with the same rasterizer — all geometry, and geometry with the
//! view's CPV's impostors swapped in — and compare where the impostors are.
//!
//! Views are sampled where impostors are used: per view, candidates are
//! drawn in CPVs that have impostors (a position in the region, uniform,
//! pulled towards one of its impostors or at the region's point nearest to
//! it, where it is largest, and a direction in its direction
//! interval within the job's pitch range, aimed at that impostor as far as
//! the interval allows), and the candidate whose impostor spheres cover the
//! most of the image is rendered, each sphere weighted by the share of rays
//! from the eye that reach its cluster's objects before anything else.
//! Views close to impostors are where their errors show.
//!
//! Only the impostor pixels count: those where the replaced geometry is
//! drawn or the layers draw. A view whose impostor pixels cover less than
//! `min_coverage` of the image is left out (and counted). Per view: PSNR
//! over those pixels, and the mismatch fraction — the share of them whose
//! colour is matched (every channel within `tolerance`) by no pixel of the
//! other image within one pixel, in either direction (the paper's
//! one-pixel criterion). The control renders the same views with every
//! layer texel magenta: a check whose control does not mismatch far more
//! than the impostors looked at nothing.

use std::collections::HashMap;
use std::sync::Mutex;

use glam::DVec3;
use rayon::prelude::*;

use crate::api::evaluation::{ImageReport, MismatchSpread, PsnrSpread, WorstView};
use crate::api::job::Job;
use crate::api::placement::Placement;
use crate::bake::{Layer, cluster_triangles, geom_objects, surface};
use crate::input::Prepared;
use crate::math::geom::{ViewFrustum, face_direction};
use crate::math::rng::Rng;
use crate::model::cost::CostModel;
use crate::render::raster::{Raster, Surface, TextureRef, Vertex, View};
use crate::render::raycast::RayCaster;
use crate::scene::geometry::SceneGeometry;
use crate::scene::material::Wrap;
use crate::{Error, Result};

pub use super::compare::{mismatch_fraction, mismatch_map, psnr_db};
use super::compare::{percentile, share_of};

/// Options of the image comparison.
#[derive(Clone, Copy, Debug)]
pub struct ImageOptions {
    /// Views to render (each twice).
    pub views: u32,
    /// Seed of the view sampler.
    pub seed: u64,
    /// Largest per-channel difference (0–255) of matching colours.
    pub tolerance: u8,
    /// Smallest share of the image a view's impostor pixels must cover for
    /// the view to be compared.
    pub min_coverage: f64,
}

impl Default for ImageOptions {
    fn default() -> Self {
        ImageOptions {
            views: 64,
            seed: 1,
            tolerance: 24,
            min_coverage: 0.01,
        }
    }
}

/// The two renders of the worst view, RGBA8.
#[derive(Clone, Debug)]
pub struct ImagePair {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// All geometry.
    pub geometry: Vec<u8>,
    /// Geometry with the impostors.
    pub impostors: Vec<u8>,
    /// Per pixel: drawn by the impostors or by the geometry they replace.
    pub footprint: Vec<bool>,
    /// Per pixel: a footprint pixel with no colour match within one pixel.
    pub mismatched: Vec<bool>,
}

/// Samples per side of a pixel: both images are drawn at this many times
/// their resolution and box-filtered, so a feature thinner than a pixel
/// shows as the share of the pixel it covers in both (point samples of the
/// geometry and of the layers' texels would each keep or lose it by chance).
const SAMPLES: u32 = 3;

/// Sky colour behind everything.
const SKY: [u8; 4] = [168, 196, 224, 255];

/// Renders `objects` (all when `None`, except `skip`) and `layers` from `view`.
struct Renderer<'a> {
    geom: &'a SceneGeometry,
    by_object: Vec<Vec<u32>>,
    /// World bounding sphere per object.
    spheres: Vec<(DVec3, f64)>,
}

impl<'a> Renderer<'a> {
    fn new(geom: &'a SceneGeometry) -> Self {
        let by_object = geom_objects(geom);
        let spheres = by_object
            .iter()
            .map(|insts| {
                let mut lo = DVec3::splat(f64::INFINITY);
                let mut hi = DVec3::splat(f64::NEG_INFINITY);
                for &i in insts {
                    let inst = &geom.instances[i as usize];
                    for p in &geom.meshes[inst.mesh as usize].positions {
                        let w = inst.transform.transform_point3(p.as_dvec3());
                        lo = lo.min(w);
                        hi = hi.max(w);
                    }
                }
                if lo.x > hi.x {
                    (DVec3::ZERO, -1.0)
                } else {
                    ((lo + hi) * 0.5, (hi - lo).length() * 0.5)
                }
            })
            .collect();
        Renderer {
            geom,
            by_object,
            spheres,
        }
    }

    fn render(
        &self,
        raster: &mut Raster,
        view: &View,
        frustum: &ViewFrustum,
        skip: &[u32],
        layers: &[&Layer],
    ) {
        raster.reset(view.width, view.height);
        let all = (0.0, f64::INFINITY);
        let mut surfaces: HashMap<u32, Surface> = HashMap::new();
        // Nearest first, so that hidden fragments fail the depth test before
        // they are shaded.
        let mut order: Vec<(f64, u32)> = self
            .spheres
            .iter()
            .enumerate()
            .filter(|&(o, &(c, r))| {
                r >= 0.0
                    && skip.binary_search(&(o as u32)).is_err()
                    && frustum.intersects_sphere(c, r)
            })
            .map(|(o, &(c, r))| ((c - view.eye).length() - r, o as u32))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (_, o) in order {
            for t in cluster_triangles(self.geom, &self.by_object, &[o]) {
                let s = *surfaces
                    .entry(t.material)
                    .or_insert_with(|| surface(self.geom, t.material));
                raster.draw(view, &t.v, &s, all);
            }
        }
        for l in layers {
            let s = Surface {
                base_color: [1.0; 4],
                texture: Some(TextureRef {
                    width: l.res,
                    height: l.res,
                    rgba: &l.rgba,
                    wrap_s: Wrap::ClampToEdge,
                    wrap_t: Wrap::ClampToEdge,
                }),
                alpha_cutoff: Some(0.5),
                double_sided: true,
                lit: false,
                alpha_to_coverage: true,
            };
            let uv = [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)];
            let v = |k: usize| Vertex {
                pos: l.corners[k],
                normal: l.normal,
                uv: glam::Vec2::new(uv[k].0, uv[k].1),
            };
            raster.draw(view, &[v(0), v(1), v(2)], &s, all);
            raster.draw(view, &[v(0), v(2), v(3)], &s, all);
        }
        for p in &mut raster.color {
            if p[3] == 0 {
                *p = SKY;
            }
        }
    }
}

/// The layers with every texel's colour magenta (coverage kept): the image
/// check's control.
fn magenta(layers: &[Layer]) -> Vec<Layer> {
    layers
        .iter()
        .map(|l| {
            let mut l = l.clone();
            for p in l.rgba.chunks_exact_mut(4) {
                p[..3].copy_from_slice(&[255, 0, 255]);
            }
            l
        })
        .collect()
}

/// Candidate views drawn per compared view.
const CANDIDATES: u32 = 32;

/// A view chosen for the comparison.
struct Chosen {
    /// Index among the sampled views.
    index: u32,
    cpv: u32,
    eye: DVec3,
    dir: DVec3,
}

/// Share of the image covered by the discs of `spheres` seen from
/// `frustum`, each as the cost model counts its pixels (an estimate:
/// overlaps are counted twice; at most 1).
fn sphere_coverage(
    spheres: impl IntoIterator<Item = (DVec3, f64)>,
    frustum: &ViewFrustum,
    cost: &CostModel,
) -> f64 {
    let covered: f64 = spheres
        .into_iter()
        .filter(|&(c, r)| frustum.intersects_sphere(c, r))
        .map(|(c, r)| cost.pixels(r, (c - frustum.eye()).length()))
        .sum();
    (covered / cost.screen_px).min(1.0)
}

/// The largest share of the image one impostor's disc covers from the
/// problem views that use it: from the point of the CPV's region nearest
/// to its centre (capped at 1).
fn largest_impostor_fraction(job: &Job, placement: &Placement) -> f64 {
    let cost = CostModel::new(job);
    placement
        .cpvs
        .iter()
        .flat_map(|c| {
            let (lo, hi) = (
                DVec3::from_array(c.region.min),
                DVec3::from_array(c.region.max),
            );
            c.impostors.iter().map(move |&k| (lo, hi, k))
        })
        .filter_map(|(lo, hi, k)| {
            let s = &placement.impostors.get(k as usize)?.sphere;
            let centre = DVec3::from_array(s.center);
            let d = centre.clamp(lo, hi).distance(centre);
            Some(cost.pixels(s.radius, d) / cost.screen_px)
        })
        .fold(0.0, f64::max)
        .min(1.0)
}

/// Rays cast from a candidate view to each impostor in it, to estimate how
/// much of the impostor is not hidden behind other objects.
const OCCLUSION_RAYS: usize = 9;

/// The share of the rays from `eye` to points of the sphere's disc (its
/// centre and eight points at half its radius, across the view line) whose
/// first hit is one of `objects` (sorted): how much of a cluster is not
/// hidden behind other objects.
fn unoccluded(caster: &RayCaster, eye: DVec3, centre: DVec3, radius: f64, objects: &[u32]) -> f64 {
    let axis = centre - eye;
    let len = axis.length();
    if len.is_nan() || len <= 0.0 {
        return 1.0;
    }
    let w = axis / len;
    let u = if w.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let (a, b) = (w.cross(u).normalize(), w.cross(w.cross(u)).normalize());
    let seen = (0..OCCLUSION_RAYS)
        .filter(|&k| {
            let target = if k == 0 {
                centre
            } else {
                let t = std::f64::consts::TAU * (k - 1) as f64 / (OCCLUSION_RAYS - 1) as f64;
                centre + (a * t.cos() + b * t.sin()) * (0.5 * radius)
            };
            caster
                .first_hit(eye, target - eye, 0.0, 2.0)
                .is_some_and(|h| objects.binary_search(&h.object).is_ok())
        })
        .count();
    seen as f64 / OCCLUSION_RAYS as f64
}

/// Draws the views to compare: per view, the candidate (of [`CANDIDATES`])
/// whose CPV's impostor spheres cover the most of the image, each sphere
/// weighted, when a ray caster is given, by the share of rays to it that
/// reach its objects unoccluded.
fn choose_views(
    job: &Job,
    placement: &Placement,
    with_impostors: &[u32],
    opts: &ImageOptions,
    caster: Option<&RayCaster>,
) -> Vec<Chosen> {
    let [w, h] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(h);
    let cost = CostModel::new(job);
    let pitch = job.view_space.pitch_deg.map(f64::to_radians);
    (0..opts.views)
        .into_par_iter()
        .filter_map(|i| {
            let mut rng = Rng::new(opts.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(i));
            let mut best: Option<(f64, Chosen)> = None;
            for attempt in 0..CANDIDATES * 8 {
                if attempt >= CANDIDATES && best.is_some() {
                    break;
                }
                let c = with_impostors[(rng.next_u64() % with_impostors.len() as u64) as usize];
                let cpv = &placement.cpvs[c as usize];
                let k = cpv.impostors[(rng.next_u64() % cpv.impostors.len() as u64) as usize];
                let centre = DVec3::from_array(placement.impostors[k as usize].sphere.center);
                let (lo, hi) = (
                    DVec3::from_array(cpv.region.min),
                    DVec3::from_array(cpv.region.max),
                );
                // Half the candidates are pulled towards the impostor: a
                // quarter at the region's point nearest to it (where it is
                // largest), a quarter between that point and a uniform one.
                let uniform = rng.in_box(lo, hi);
                let nearest = centre.clamp(lo, hi);
                let eye = match attempt % 4 {
                    1 => uniform.lerp(nearest, rng.range(0.0, 1.0)),
                    3 => nearest,
                    _ => uniform,
                };
                let d = &cpv.directions;
                let (mut u, mut v) = (rng.range(d.u[0], d.u[1]), rng.range(d.v[0], d.v[1]));
                let target = centre - eye;
                let axis = usize::from(d.face / 2);
                let sign = if d.face.is_multiple_of(2) { 1.0 } else { -1.0 };
                let along = target[axis] * sign;
                if along > 0.0 {
                    let others: Vec<f64> = (0..3)
                        .filter(|&a| a != axis)
                        .map(|a| target[a] / along)
                        .collect();
                    u = others[0].clamp(d.u[0], d.u[1]);
                    v = others[1].clamp(d.v[0], d.v[1]);
                }
                let dir = face_direction(d.face, u, v).normalize();
                let el = dir.y.clamp(-1.0, 1.0).asin();
                if el < pitch[0] - 1e-9 || el > pitch[1] + 1e-9 {
                    continue;
                }
                let frustum = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
                let estimate: f64 = cpv
                    .impostors
                    .iter()
                    .map(|&k| {
                        let imp = &placement.impostors[k as usize];
                        let (c, r) = (DVec3::from_array(imp.sphere.center), imp.sphere.radius);
                        let disc = sphere_coverage([(c, r)], &frustum, &cost);
                        match caster {
                            Some(rc) if disc > 0.0 => {
                                disc * unoccluded(rc, eye, c, r, &imp.objects)
                            }
                            _ => disc,
                        }
                    })
                    .sum();
                if best.as_ref().is_none_or(|(b, _)| estimate > *b) {
                    best = Some((
                        estimate,
                        Chosen {
                            index: i,
                            cpv: c,
                            eye,
                            dir,
                        },
                    ));
                }
            }
            best.map(|(_, chosen)| chosen)
        })
        .collect()
}

/// The layers per impostor id (`n` impostors).
fn by_impostor(layers: &[Layer], n: usize) -> Vec<Vec<&Layer>> {
    let mut by: Vec<Vec<&Layer>> = vec![Vec::new(); n];
    for l in layers {
        if let Some(v) = by.get_mut(l.impostor as usize) {
            v.push(l);
        }
    }
    by
}

/// The layers of `impostors`.
fn layers_of<'l>(by: &[Vec<&'l Layer>], impostors: &[u32]) -> Vec<&'l Layer> {
    impostors
        .iter()
        .flat_map(|&k| by[k as usize].iter().copied())
        .collect()
}

/// Pixel `i` of an RGBA8 image.
fn px(img: &[u8], i: usize) -> &[u8] {
    &img[4 * i..4 * i + 4]
}

/// One compared view.
struct Compared {
    mismatch: f64,
    control: f64,
    psnr: f64,
    coverage: f64,
}

/// Most views `--images` may compare: each is rendered four times at 3×3
/// samples a pixel (about a second at 1280×720); only the worst view's
/// images are held, so memory does not grow with the count.
pub const MAX_IMAGE_VIEWS: u32 = 10_000;

/// Compares geometry-only and impostor renders at views sampled in the CPVs
/// that use impostors, over the impostor pixels, with the magenta control.
/// `layers` gives the layers of the impostors it is asked for (`ids`,
/// sorted and distinct): rendered from the placement, or read back from a
/// baked GLB. With a ray caster over the same geometry, views are chosen
/// for the impostors they show unoccluded.
pub fn image_error(
    geom: &SceneGeometry,
    job: &Job,
    placement: &Placement,
    layers: impl FnOnce(&[u32]) -> Result<Vec<Layer>>,
    opts: &ImageOptions,
    caster: Option<&RayCaster>,
) -> Result<(ImageReport, Option<ImagePair>)> {
    if opts.views > MAX_IMAGE_VIEWS {
        return Err(Error::bad(
            "--images",
            format!(
                "{} views is too many (at most {MAX_IMAGE_VIEWS}; each takes about a second)",
                opts.views
            ),
        ));
    }
    if !(0.0..=1.0).contains(&opts.min_coverage) {
        return Err(Error::bad(
            "--min-coverage",
            format!("{} must be between 0 and 1", opts.min_coverage),
        ));
    }
    let [w, h] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(h);
    let with_impostors: Vec<u32> = placement
        .cpvs
        .iter()
        .filter(|c| !c.impostors.is_empty())
        .map(|c| c.id)
        .collect();
    let mut report = ImageReport {
        views: 0,
        views_below_coverage: 0,
        seed: opts.seed,
        tolerance: opts.tolerance,
        resolution: [w, h],
        min_coverage: opts.min_coverage,
        psnr_db: PsnrSpread {
            mean: 100.0,
            min: 100.0,
        },
        footprint_mismatch_fraction: MismatchSpread::default(),
        impostor_pixel_fraction: 0.0,
        largest_impostor_fraction: largest_impostor_fraction(job, placement),
        control_mismatch_fraction: MismatchSpread::default(),
        worst_view: None,
    };
    if with_impostors.is_empty() || opts.views == 0 {
        return Ok((report, None));
    }
    let chosen = choose_views(job, placement, &with_impostors, opts, caster);
    // Only the layers of the impostors the chosen views use.
    let mut ids: Vec<u32> = chosen
        .iter()
        .flat_map(|c| placement.cpvs[c.cpv as usize].impostors.iter().copied())
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let layers = layers(&ids)?;
    let control = magenta(&layers);
    let n = placement.impostors.len();
    let (real_by, control_by) = (by_impostor(&layers, n), by_impostor(&control, n));
    let renderer = Renderer::new(geom);
    // The worst view (the largest mismatch, the earliest of equal ones,
    // whatever the order views finish in) is the only one whose images are
    // kept.
    let worst: Mutex<Option<(f64, usize, WorstView, ImagePair)>> = Mutex::new(None);
    let results: Vec<Option<Compared>> = chosen
        .par_iter()
        .enumerate()
        .map(|(k, c)| {
            let cpv = &placement.cpvs[c.cpv as usize];
            let view =
                View::perspective(c.eye, c.dir, job.camera.fov_deg, w * SAMPLES, h * SAMPLES);
            let frustum = ViewFrustum::new(c.eye, c.dir, job.camera.fov_deg, aspect);
            let mut skip: Vec<u32> = cpv
                .impostors
                .iter()
                .flat_map(|&k| placement.impostors[k as usize].objects.iter().copied())
                .collect();
            skip.sort_unstable();
            let mut raster = Raster::supersampled(w, h, SAMPLES);
            let mut draw = |skip: &[u32], layers: &[&Layer]| {
                renderer.render(&mut raster, &view, &frustum, skip, layers);
                raster.resolve().concat()
            };
            let a = draw(&[], &[]);
            let holes = draw(&skip, &[]);
            let b = draw(&skip, &layers_of(&real_by, &cpv.impostors));
            let m = draw(&skip, &layers_of(&control_by, &cpv.impostors));
            let mask: Vec<bool> = (0..(w * h) as usize)
                .map(|i| {
                    px(&a, i) != px(&holes, i)
                        || px(&b, i) != px(&holes, i)
                        || px(&m, i) != px(&holes, i)
                })
                .collect();
            let coverage = mask.iter().filter(|&&x| x).count() as f64 / f64::from(w * h).max(1.0);
            if coverage < opts.min_coverage || coverage == 0.0 {
                return None;
            }
            let mismatched = mismatch_map(&a, &b, w, h, opts.tolerance, &mask);
            let mismatch = share_of(&mismatched, &mask);
            let psnr = psnr_db(&a, &b, &mask);
            let control = mismatch_fraction(&a, &m, w, h, opts.tolerance, &mask);
            let mut kept = worst.lock().unwrap_or_else(|e| e.into_inner());
            if kept.as_ref().is_none_or(|(x, j, ..)| {
                mismatch.total_cmp(x).then(j.cmp(&k)) == std::cmp::Ordering::Greater
            }) {
                let view = WorstView {
                    view: c.index,
                    cpv: c.cpv,
                    eye: c.eye.to_array(),
                    direction: c.dir.to_array(),
                    mismatch_fraction: mismatch,
                    impostor_pixel_fraction: coverage,
                    psnr_db: psnr,
                };
                let pair = ImagePair {
                    width: w,
                    height: h,
                    geometry: a,
                    impostors: b,
                    footprint: mask,
                    mismatched,
                };
                *kept = Some((mismatch, k, view, pair));
            }
            Some(Compared {
                mismatch,
                control,
                psnr,
                coverage,
            })
        })
        .collect();
    report.views_below_coverage = (opts.views as usize - results.iter().flatten().count()) as u32;
    let results: Vec<Compared> = results.into_iter().flatten().collect();
    if results.is_empty() {
        return Ok((report, None));
    }
    let n = results.len() as f64;
    let mean = |f: fn(&Compared) -> f64| results.iter().map(f).sum::<f64>() / n;
    report.views = results.len() as u32;
    report.psnr_db = PsnrSpread {
        mean: mean(|r| r.psnr),
        min: results.iter().map(|r| r.psnr).fold(f64::INFINITY, f64::min),
    };
    let spread = |f: fn(&Compared) -> f64| {
        let mut v: Vec<f64> = results.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        MismatchSpread {
            mean: v.iter().sum::<f64>() / n,
            p95: percentile(&v, 0.95),
            max: v.last().copied().unwrap_or(0.0),
        }
    };
    report.footprint_mismatch_fraction = spread(|r| r.mismatch);
    report.control_mismatch_fraction = spread(|r| r.control);
    report.impostor_pixel_fraction = mean(|r| r.coverage);
    let (worst_view, pair) = worst
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .map(|(_, _, view, pair)| (view, pair))
        .unzip();
    report.worst_view = worst_view;
    Ok((report, pair))
}

/// Where the impostor layers of an image check come from.
#[derive(Clone, Copy, Debug)]
pub enum LayerSource<'b> {
    /// Baked in memory from the placement.
    Bake,
    /// Read from a GLB written by `impostor bake`, named `name` in errors.
    Glb {
        /// The GLB.
        bytes: &'b [u8],
        /// How errors name it.
        name: &'b str,
    },
}

impl Prepared<'_> {
    /// Renders `opts.views` views in problem views with impostors twice (all
    /// geometry; geometry with the impostor layers) and reports the image
    /// error, with the worst view's pair. Needs the scene's geometry
    /// ([`GeometryUse::Required`](crate::input::GeometryUse)). `source`
    /// names the placement in errors.
    pub fn image_error(
        &self,
        placement: &Placement,
        layers: LayerSource<'_>,
        opts: &ImageOptions,
        source: &str,
    ) -> Result<(ImageReport, Option<ImagePair>)> {
        let geom = self.input().geometry.as_ref().ok_or_else(|| {
            Error::bad(
                source,
                "the image check needs the scene's geometry (a .glb/.gltf scene)",
            )
        })?;
        let scene = &self.input().scene;
        let layers = |ids: &[u32]| match layers {
            LayerSource::Bake => crate::bake::render_layers_of(scene, geom, placement, ids, source),
            LayerSource::Glb { bytes, name } => {
                placement.validate(scene, source)?;
                crate::bake::read_layers(bytes, name)
            }
        };
        image_error(
            geom,
            self.job(),
            placement,
            layers,
            opts,
            self.input().caster(),
        )
    }
}

impl ImagePair {
    /// The difference image: mismatching pixels red, the rest of the
    /// impostors' footprint in the geometry's colours, everything else
    /// faded to a light grey, so the footprint and its errors stand out.
    pub fn difference(&self) -> Vec<u8> {
        self.geometry
            .chunks_exact(4)
            .zip(self.footprint.iter().zip(&self.mismatched))
            .flat_map(|(p, (&inside, &bad))| {
                if bad {
                    [255, 0, 0, 255]
                } else if inside {
                    [p[0], p[1], p[2], 255]
                } else {
                    let grey = (u32::from(p[0]) + u32::from(p[1]) + u32::from(p[2])) / 3;
                    let g = (176 + grey / 4) as u8;
                    [g, g, g, 255]
                }
            })
            .collect()
    }

    /// The two renders and their difference side by side (geometry left,
    /// impostors in the middle, [`ImagePair::difference`] right) with
    /// 4-pixel gaps, as PNG.
    pub fn side_by_side_png(&self) -> Result<Vec<u8>> {
        let (w, h, gap) = (self.width as usize, self.height as usize, 4usize);
        let panels = [&self.geometry, &self.impostors, &self.difference()];
        let out_w = panels.len() * w + (panels.len() - 1) * gap;
        let mut out = vec![255u8; out_w * h * 4];
        for y in 0..h {
            let row = &mut out[y * out_w * 4..(y + 1) * out_w * 4];
            for (k, img) in panels.iter().enumerate() {
                let x0 = k * (w + gap) * 4;
                row[x0..x0 + w * 4].copy_from_slice(&img[y * w * 4..(y + 1) * w * 4]);
            }
        }
        crate::bake::encode_png(&out, out_w as u32, h as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `largest_impostor_fraction` bounds what one impostor's disc covers
    /// from any eye in a problem view that uses it, and is reached at the
    /// region's point nearest to the impostor.
    #[test]
    fn largest_impostor_fraction_bounds_every_view() {
        let scene = crate::testutil::synthetic_city(2, 5, 5);
        let job = crate::testutil::synthetic_job(5, 5);
        let p = crate::testutil::place(&scene, &job);
        assert!(p.summary.impostors > 0);
        let bound = largest_impostor_fraction(&job, &p);
        assert!(bound > 0.0 && bound <= 1.0);
        let cost = CostModel::new(&job);
        let mut rng = Rng::new(3);
        let mut reached = 0.0f64;
        for c in p.cpvs.iter().filter(|c| !c.impostors.is_empty()) {
            let (lo, hi) = (
                DVec3::from_array(c.region.min),
                DVec3::from_array(c.region.max),
            );
            for &k in &c.impostors {
                let s = &p.impostors[k as usize].sphere;
                let centre = DVec3::from_array(s.center);
                for eye in [rng.in_box(lo, hi), centre.clamp(lo, hi)] {
                    let f = cost.pixels(s.radius, eye.distance(centre)) / cost.screen_px;
                    assert!(f.min(1.0) <= bound, "{f} > {bound}");
                    reached = reached.max(f.min(1.0));
                }
            }
        }
        assert_eq!(reached, bound);
    }

    /// Nearest-rank percentiles, by hand: of 1..=20 the 95th is the 19th
    /// value, of ten values the largest, of one value itself.
    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.95), 19.0);
        assert_eq!(percentile(&v, 0.5), 10.0);
        assert_eq!(percentile(&v[..10], 0.95), 10.0);
        assert_eq!(percentile(&[0.25], 0.95), 0.25);
        assert_eq!(percentile(&[], 0.95), 0.0);
    }

    #[test]
    fn psnr_of_known_difference() {
        let a = vec![10u8, 10, 10, 255, 20, 20, 20, 255];
        assert_eq!(psnr_db(&a, &a, &[true; 2]), 100.0);
        let b = vec![20u8, 10, 10, 255, 20, 20, 20, 255];
        // MSE = 100 / 6.
        let expect = 10.0 * (255.0f64 * 255.0 / (100.0 / 6.0)).log10();
        assert!((psnr_db(&a, &b, &[true; 2]) - expect).abs() < 1e-9);
        // Over the first pixel only: MSE = 100 / 3.
        let first = 10.0 * (255.0f64 * 255.0 / (100.0 / 3.0)).log10();
        assert!((psnr_db(&a, &b, &[true, false]) - first).abs() < 1e-9);
        assert_eq!(psnr_db(&a, &b, &[false, true]), 100.0);
    }

    /// An antialiased edge moved by half a pixel blends its pixel half-way
    /// between the two sides, a colour no whole pixel of the other image
    /// has: it matches between two pixels. A whole-pixel blend two pixels
    /// away still does not.
    #[test]
    fn antialiased_edge_moved_by_part_of_a_pixel_matches() {
        let (w, h) = (8u32, 8u32);
        let row = |cols: [[u8; 4]; 8]| -> Vec<u8> { (0..h).flat_map(|_| cols.concat()).collect() };
        let (d, l) = ([40, 40, 40, 255], [220, 220, 220, 255]);
        let mid = [130, 130, 130, 255];
        let a = row([d, d, d, d, l, l, l, l]);
        let half = row([d, d, d, d, mid, l, l, l]);
        let all = vec![true; 64];
        assert_eq!(mismatch_fraction(&a, &half, w, h, 24, &all), 0.0);
        // The blend three pixels over: nothing within one pixel is half-way.
        let far = row([d, d, d, d, l, l, l, mid]);
        assert_eq!(mismatch_fraction(&a, &far, w, h, 24, &all), 8.0 / 64.0);
    }

    /// A `w × h` RGBA8 image: `colour` where `f` holds, sky elsewhere.
    fn painted(w: u32, h: u32, colour: [u8; 4], f: &dyn Fn(u32, u32) -> bool) -> Vec<u8> {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .flat_map(|(x, y)| if f(x, y) { colour } else { SKY })
            .collect()
    }

    #[test]
    fn one_pixel_shift_is_not_a_mismatch_but_a_hole_is() {
        let (w, h) = (8u32, 8u32);
        let img = |f: &dyn Fn(u32, u32) -> bool| painted(w, h, [200, 0, 0, 255], f);
        let all = vec![true; 64];
        let a = img(&|x, _| x < 4);
        let shifted = img(&|x, _| x < 5);
        assert_eq!(mismatch_fraction(&a, &shifted, w, h, 8, &all), 0.0);
        let moved = img(&|x, _| x < 6);
        // Column 5 is red in `moved` with no red within one pixel in `a`, and
        // column 4 is sky in `a` with no sky within one pixel in `moved`.
        assert_eq!(mismatch_fraction(&a, &moved, w, h, 8, &all), 16.0 / 64.0);
        // Over the columns 3 to 6 only (the pixels that changed and their
        // neighbours): the same 16 bad pixels of 32.
        let band: Vec<bool> = (0..64).map(|i| (3..7).contains(&(i % 8))).collect();
        assert_eq!(mismatch_fraction(&a, &moved, w, h, 8, &band), 0.5);
        assert_eq!(mismatch_fraction(&a, &moved, w, h, 8, &[false; 64]), 0.0);
        // Small colour noise within the tolerance matches.
        let mut noisy = a.clone();
        noisy[0] = 190;
        assert_eq!(mismatch_fraction(&a, &noisy, w, h, 16, &all), 0.0);
    }

    /// The difference panel marks exactly the mismatching footprint pixels
    /// red, keeps the rest of the footprint in the geometry's colours and
    /// fades the others; the dump is the three panels side by side.
    #[test]
    fn difference_marks_the_mismatching_footprint_pixels() {
        let (w, h) = (8u32, 8u32);
        let img = |f: &dyn Fn(u32, u32) -> bool| painted(w, h, [20, 90, 40, 255], f);
        let a = img(&|x, _| x < 4);
        let b = img(&|x, _| x < 6);
        let footprint: Vec<bool> = (0..64).map(|i| (2..7).contains(&(i % 8))).collect();
        let mismatched = mismatch_map(&a, &b, w, h, 8, &footprint);
        // Columns 4 and 5 (see the one-pixel test above), inside the footprint.
        let expected: Vec<bool> = (0..64).map(|i| (4..6).contains(&(i % 8))).collect();
        assert_eq!(mismatched, expected);
        let pair = ImagePair {
            width: w,
            height: h,
            geometry: a.clone(),
            impostors: b,
            footprint: footprint.clone(),
            mismatched,
        };
        let d = pair.difference();
        for i in 0..64 {
            let p = &d[4 * i..4 * i + 4];
            if expected[i] {
                assert_eq!(p, [255, 0, 0, 255]);
            } else if footprint[i] {
                assert_eq!(p, &a[4 * i..4 * i + 4]);
            } else {
                assert!(p[0] == p[1] && p[1] == p[2] && p[0] >= 176, "{p:?}");
            }
        }
        let png = pair.side_by_side_png().unwrap();
        let (width, height) = (
            u32::from_be_bytes(png[16..20].try_into().unwrap()),
            u32::from_be_bytes(png[20..24].try_into().unwrap()),
        );
        assert_eq!((width, height), (3 * w + 8, h));
    }

    #[test]
    fn coverage_estimate_is_the_projected_disc() {
        let frustum = ViewFrustum::new(DVec3::ZERO, DVec3::Z, 90.0, 1.0);
        let mut cost = CostModel::new(&Job::with_view_space([0.0; 3], [1.0; 3]));
        cost.focal_px = 100.0;
        cost.screen_px = 4e4;
        // A sphere of radius 1 at distance 10: pi f^2 r^2 / (d^2 - r^2).
        let disc = std::f64::consts::PI * 1e4 / 99.0;
        let got = sphere_coverage([(DVec3::new(0.0, 0.0, 10.0), 1.0)], &frustum, &cost);
        assert!((got - disc / 4e4).abs() < 1e-12, "{got}");
        // Behind the camera: nothing; around the eye: everything.
        let behind = sphere_coverage([(DVec3::new(0.0, 0.0, -10.0), 1.0)], &frustum, &cost);
        assert_eq!(behind, 0.0);
        assert_eq!(sphere_coverage([(DVec3::ZERO, 1.0)], &frustum, &cost), 1.0);
    }
}
