//! Image error of a placement's impostors (DESIGN §2.10): render sampled
//! views twice with the same rasterizer — all geometry, and geometry with
//! the view's CPV's impostors swapped in — and compare.
//!
//! Views are sampled where impostors are used: a CPV that has impostors is
//! chosen uniformly, then a position uniformly in its region and a direction
//! in its direction interval (within the job's pitch range) aimed at one of
//! its impostors as far as the interval allows. A view whose CPV has no
//! impostors, or that looks away from them, renders identically and would
//! only dilute the figures.
//!
//! Per view: PSNR over RGB, and the mismatch fraction — the share of pixels
//! whose colour is matched (every channel within `tolerance`) by no pixel of
//! the other image within one pixel, in either direction (the paper's
//! one-pixel criterion).

use std::collections::HashMap;

use glam::DVec3;
use rayon::prelude::*;

use crate::api::evaluation::{ImageReport, MismatchSpread, PsnrSpread, WorstView};
use crate::api::job::Job;
use crate::api::placement::Placement;
use crate::bake::{Layer, cluster_triangles, geom_objects, surface};
use crate::input::Prepared;
use crate::math::geom::{ViewFrustum, face_direction};
use crate::math::rng::Rng;
use crate::render::raster::{Raster, Surface, TextureRef, Vertex, View};
use crate::scene::geometry::SceneGeometry;
use crate::scene::material::Wrap;
use crate::{Error, Result};

/// Options of the image comparison.
#[derive(Clone, Copy, Debug)]
pub struct ImageOptions {
    /// Views to render (each twice).
    pub views: u32,
    /// Seed of the view sampler.
    pub seed: u64,
    /// Largest per-channel difference (0–255) of matching colours.
    pub tolerance: u8,
}

impl Default for ImageOptions {
    fn default() -> Self {
        ImageOptions {
            views: 64,
            seed: 1,
            tolerance: 24,
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
}

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
        for (o, &(c, r)) in self.spheres.iter().enumerate() {
            let o = o as u32;
            if r < 0.0 || skip.binary_search(&o).is_ok() || !frustum.intersects_sphere(c, r) {
                continue;
            }
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

/// PSNR over RGB of two RGBA8 images, dB, capped at 100.
pub fn psnr_db(a: &[u8], b: &[u8]) -> f64 {
    let mut se = 0.0f64;
    let mut n = 0u64;
    for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for k in 0..3 {
            let d = f64::from(p[k]) - f64::from(q[k]);
            se += d * d;
        }
        n += 3;
    }
    if se == 0.0 || n == 0 {
        return 100.0;
    }
    (10.0 * (255.0f64.powi(2) / (se / n as f64)).log10()).min(100.0)
}

/// Share of pixels whose colour has no match within one pixel in the other
/// image (in either direction).
pub fn mismatch_fraction(a: &[u8], b: &[u8], width: u32, height: u32, tolerance: u8) -> f64 {
    let (w, h) = (width as i64, height as i64);
    let px = |img: &[u8], x: i64, y: i64| -> [u8; 4] {
        let i = ((y * w + x) * 4) as usize;
        [img[i], img[i + 1], img[i + 2], img[i + 3]]
    };
    let close = |p: [u8; 4], q: [u8; 4]| (0..3).all(|k| p[k].abs_diff(q[k]) <= tolerance);
    let matched = |src: &[u8], other: &[u8], x: i64, y: i64| {
        let p = px(src, x, y);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (nx, ny) = (x + dx, y + dy);
                if nx >= 0 && ny >= 0 && nx < w && ny < h && close(p, px(other, nx, ny)) {
                    return true;
                }
            }
        }
        false
    };
    let mut bad = 0u64;
    for y in 0..h {
        for x in 0..w {
            if !matched(a, b, x, y) || !matched(b, a, x, y) {
                bad += 1;
            }
        }
    }
    bad as f64 / (w * h).max(1) as f64
}

/// Compares geometry-only and impostor renders at views sampled in the CPVs
/// that use impostors. `layers` are the placement's rendered layers (from
/// [`crate::bake::render_layers`] or read back from a baked GLB).
pub fn image_error(
    geom: &SceneGeometry,
    job: &Job,
    placement: &Placement,
    layers: &[Layer],
    opts: &ImageOptions,
) -> Result<(ImageReport, Option<ImagePair>)> {
    if opts.views > 100_000 {
        return Err(Error::bad(
            "--images",
            format!("{} views is too many (at most 100000)", opts.views),
        ));
    }
    let [w, h] = job.camera.resolution;
    let aspect = f64::from(w) / f64::from(h);
    let pitch = job.view_space.pitch_deg.map(f64::to_radians);
    let mut by_impostor: Vec<Vec<&Layer>> = vec![Vec::new(); placement.impostors.len()];
    for l in layers {
        if let Some(v) = by_impostor.get_mut(l.impostor as usize) {
            v.push(l);
        }
    }
    let with_impostors: Vec<u32> = placement
        .cpvs
        .iter()
        .filter(|c| !c.impostors.is_empty())
        .map(|c| c.id)
        .collect();
    let renderer = Renderer::new(geom);
    let empty = ImageReport {
        views: 0,
        seed: opts.seed,
        tolerance: opts.tolerance,
        resolution: [w, h],
        psnr_db: PsnrSpread {
            mean: 100.0,
            min: 100.0,
        },
        mismatch_fraction: MismatchSpread {
            mean: 0.0,
            max: 0.0,
        },
        impostor_pixel_fraction: 0.0,
        worst_view: None,
    };
    if with_impostors.is_empty() || opts.views == 0 {
        return Ok((empty, None));
    }
    // (mismatch, psnr, view info, images of this view, impostor pixels)
    let results: Vec<(f64, f64, WorstView, ImagePair, f64)> = (0..opts.views)
        .into_par_iter()
        .filter_map(|i| {
            let mut rng = Rng::new(opts.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(i));
            // A CPV with impostors and a view inside it within the pitch band.
            let mut found = None;
            for _ in 0..256 {
                let c = with_impostors[(rng.next_u64() % with_impostors.len() as u64) as usize];
                let cpv = &placement.cpvs[c as usize];
                let eye = rng.in_box(
                    DVec3::from_array(cpv.region.min),
                    DVec3::from_array(cpv.region.max),
                );
                let d = &cpv.directions;
                let (mut u, mut v) = (rng.range(d.u[0], d.u[1]), rng.range(d.v[0], d.v[1]));
                // Aim at one of the CPV's impostors, as far as the CPV's
                // direction interval allows.
                let k = cpv.impostors[(rng.next_u64() % cpv.impostors.len() as u64) as usize];
                let target = DVec3::from_array(placement.impostors[k as usize].sphere.center) - eye;
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
                if el >= pitch[0] - 1e-9 && el <= pitch[1] + 1e-9 {
                    found = Some((c, eye, dir));
                    break;
                }
            }
            let (c, eye, dir) = found?;
            let cpv = &placement.cpvs[c as usize];
            let view = View::perspective(eye, dir, job.camera.fov_deg, w, h);
            let frustum = ViewFrustum::new(eye, dir, job.camera.fov_deg, aspect);
            let mut skip: Vec<u32> = cpv
                .impostors
                .iter()
                .flat_map(|&k| placement.impostors[k as usize].objects.iter().copied())
                .collect();
            skip.sort_unstable();
            let quads: Vec<&Layer> = cpv
                .impostors
                .iter()
                .flat_map(|&k| by_impostor[k as usize].iter().copied())
                .collect();
            let mut raster = Raster::new(w, h);
            renderer.render(&mut raster, &view, &frustum, &[], &[]);
            let a = raster.rgba_bytes();
            renderer.render(&mut raster, &view, &frustum, &skip, &[]);
            let holes = raster.rgba_bytes();
            renderer.render(&mut raster, &view, &frustum, &skip, &quads);
            let b = raster.rgba_bytes();
            let drawn = holes
                .chunks_exact(4)
                .zip(b.chunks_exact(4))
                .filter(|(p, q)| p != q)
                .count() as f64
                / f64::from(w * h).max(1.0);
            let mismatch = mismatch_fraction(&a, &b, w, h, opts.tolerance);
            let psnr = psnr_db(&a, &b);
            Some((
                mismatch,
                psnr,
                WorstView {
                    view: i,
                    cpv: c,
                    eye: eye.to_array(),
                    direction: dir.to_array(),
                    mismatch_fraction: mismatch,
                    psnr_db: psnr,
                },
                ImagePair {
                    width: w,
                    height: h,
                    geometry: a,
                    impostors: b,
                },
                drawn,
            ))
        })
        .collect();
    if results.is_empty() {
        return Ok((empty, None));
    }
    let n = results.len() as f64;
    let worst = results
        .iter()
        .enumerate()
        .max_by(|x, y| x.1.0.total_cmp(&y.1.0).then(y.0.cmp(&x.0)))
        .map(|(i, _)| i)
        .expect("non-empty");
    let report = ImageReport {
        views: results.len() as u32,
        seed: opts.seed,
        tolerance: opts.tolerance,
        resolution: [w, h],
        psnr_db: PsnrSpread {
            mean: results.iter().map(|r| r.1).sum::<f64>() / n,
            min: results.iter().map(|r| r.1).fold(f64::INFINITY, f64::min),
        },
        mismatch_fraction: MismatchSpread {
            mean: results.iter().map(|r| r.0).sum::<f64>() / n,
            max: results[worst].0,
        },
        impostor_pixel_fraction: results.iter().map(|r| r.4).sum::<f64>() / n,
        worst_view: Some(results[worst].2.clone()),
    };
    let pair = results.into_iter().nth(worst).map(|r| r.3);
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
        let layers = match layers {
            LayerSource::Bake => {
                crate::bake::render_layers(&self.input().scene, geom, placement, source)?
            }
            LayerSource::Glb { bytes, name } => crate::bake::read_layers(bytes, name)?,
        };
        image_error(geom, self.job(), placement, &layers, opts)
    }
}

impl ImagePair {
    /// The two renders side by side (geometry left, impostors right) with a
    /// 4-pixel gap, as PNG.
    pub fn side_by_side_png(&self) -> Result<Vec<u8>> {
        let (w, h, gap) = (self.width as usize, self.height as usize, 4usize);
        let out_w = 2 * w + gap;
        let mut out = vec![255u8; out_w * h * 4];
        for y in 0..h {
            let row = &mut out[y * out_w * 4..(y + 1) * out_w * 4];
            row[..w * 4].copy_from_slice(&self.geometry[y * w * 4..(y + 1) * w * 4]);
            row[(w + gap) * 4..].copy_from_slice(&self.impostors[y * w * 4..(y + 1) * w * 4]);
        }
        crate::bake::encode_png(&out, out_w as u32, h as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_known_difference() {
        let a = vec![10u8, 10, 10, 255, 20, 20, 20, 255];
        assert_eq!(psnr_db(&a, &a), 100.0);
        let b = vec![20u8, 10, 10, 255, 20, 20, 20, 255];
        // MSE = 100 / 6.
        let expect = 10.0 * (255.0f64 * 255.0 / (100.0 / 6.0)).log10();
        assert!((psnr_db(&a, &b) - expect).abs() < 1e-9);
    }

    #[test]
    fn one_pixel_shift_is_not_a_mismatch_but_a_hole_is() {
        let (w, h) = (8u32, 8u32);
        let img = |f: &dyn Fn(u32, u32) -> bool| -> Vec<u8> {
            (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .flat_map(|(x, y)| if f(x, y) { [200, 0, 0, 255] } else { SKY })
                .collect()
        };
        let a = img(&|x, _| x < 4);
        let shifted = img(&|x, _| x < 5);
        assert_eq!(mismatch_fraction(&a, &shifted, w, h, 8), 0.0);
        let moved = img(&|x, _| x < 6);
        // Column 5 is red in `moved` with no red within one pixel in `a`, and
        // column 4 is sky in `a` with no sky within one pixel in `moved`.
        assert_eq!(mismatch_fraction(&a, &moved, w, h, 8), 16.0 / 64.0);
        // Small colour noise within the tolerance matches.
        let mut noisy = a.clone();
        noisy[0] = 190;
        assert_eq!(mismatch_fraction(&a, &noisy, w, h, 16), 0.0);
    }
}
