//! A small CPU rasterizer: perspective triangles, a linear depth buffer,
//! perspective-correct attributes, base colour factor × base colour texture
//! (bilinear, sRGB-aware), a fixed directional light, RGBA8 output.
//!
//! It serves impostor baking (one render per impostor layer, keeping only
//! the fragments whose depth falls in the layer's slab) and the image-error
//! evaluation (the same renderer for geometry and impostors, so differences
//! are the impostors' and not the renderers'). A [`Raster`] owns reusable
//! colour and depth buffers; callers parallelise across renders.
//!
//! Conventions: the camera looks down its forward axis; pixel `(x, y)` has
//! its centre at `(x + 0.5, y + 0.5)`, row 0 at the top; a pixel is covered
//! when its centre is inside the triangle or on a top or left edge. Depth is
//! the view-space distance along the forward axis.

use glam::{DVec3, Vec2, Vec3};

use crate::scene::material::Wrap;

/// An RGBA8 texture (sRGB-encoded colour, linear alpha), borrowed.
#[derive(Clone, Copy, Debug)]
pub struct TextureRef<'a> {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width × height × 4` bytes, rows from the top.
    pub rgba: &'a [u8],
    /// Wrapping of `u`.
    pub wrap_s: Wrap,
    /// Wrapping of `v`.
    pub wrap_t: Wrap,
}

/// How a triangle's surface is coloured.
#[derive(Clone, Copy, Debug)]
pub struct Surface<'a> {
    /// Linear RGBA factor.
    pub base_color: [f32; 4],
    /// Base colour texture, multiplied with the factor.
    pub texture: Option<TextureRef<'a>>,
    /// Fragments with alpha below the cutoff are discarded (glTF `MASK`;
    /// `BLEND` is drawn as a mask at 0.5 by callers).
    pub alpha_cutoff: Option<f32>,
    /// Draw back faces too (with the normal flipped).
    pub double_sided: bool,
    /// Apply the fixed light; false draws the colour unlit (impostor quads
    /// are drawn unlit: their texels already carry the lighting).
    pub lit: bool,
    /// With an alpha cutoff, on a raster of [`Raster::samples`]² samples
    /// per pixel: each sample of a pixel compares alpha with its own
    /// threshold, evenly spread over `(0, 1)`, so a fragment covers a share
    /// of the pixel equal to its alpha (what a GPU's alpha to coverage does
    /// under multisampling) instead of all or nothing at the cutoff.
    pub alpha_to_coverage: bool,
}

impl Default for Surface<'_> {
    fn default() -> Self {
        Surface {
            base_color: [1.0; 4],
            texture: None,
            alpha_cutoff: None,
            double_sided: false,
            lit: true,
            alpha_to_coverage: false,
        }
    }
}

/// A vertex in world space.
#[derive(Clone, Copy, Debug, Default)]
pub struct Vertex {
    /// Position, metres.
    pub pos: DVec3,
    /// Normal (need not be unit length; zero means "use the face normal").
    pub normal: Vec3,
    /// Texture coordinate.
    pub uv: Vec2,
}

/// The direction towards the fixed light (world space, unit).
pub fn light_dir() -> Vec3 {
    Vec3::new(0.35, 0.85, 0.4).normalize()
}

/// Ambient share of the fixed lighting.
const AMBIENT: f32 = 0.35;

/// A pinhole camera with a possibly off-centre rectangular window.
#[derive(Clone, Copy, Debug)]
pub struct View {
    /// Eye position.
    pub eye: DVec3,
    /// Unit right axis.
    pub right: DVec3,
    /// Unit up axis.
    pub up: DVec3,
    /// Unit forward axis.
    pub forward: DVec3,
    /// The window at unit depth: `x/w ∈ [left, right_edge]`, `y/w ∈ [bottom, top]`.
    pub window: [f64; 4],
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Near clipping depth (> 0).
    pub near: f64,
}

impl View {
    /// A camera at `eye` looking along `dir` with vertical field of view
    /// `fov_y_deg`, no roll (up is +y projected; straight up or down uses
    /// −z or +z as the up hint).
    pub fn perspective(eye: DVec3, dir: DVec3, fov_y_deg: f64, width: u32, height: u32) -> View {
        let forward = dir.normalize();
        let hint = if forward.cross(DVec3::Y).length_squared() < 1e-12 {
            if forward.y > 0.0 { DVec3::Z } else { -DVec3::Z }
        } else {
            DVec3::Y
        };
        let right = forward.cross(hint).normalize();
        let up = right.cross(forward);
        let t = (fov_y_deg.to_radians() * 0.5).tan();
        let a = f64::from(width) / f64::from(height.max(1));
        View {
            eye,
            right,
            up,
            forward,
            window: [-t * a, t * a, -t, t],
            width,
            height,
            near: 0.01,
        }
    }

    /// A square camera at `eye` whose window exactly encloses the sphere
    /// `(center, radius)` (the eye must lie outside the sphere).
    pub fn enclosing_sphere(eye: DVec3, center: DVec3, radius: f64, res: u32) -> View {
        let d = (center - eye).length();
        let s = (radius / d).clamp(1e-9, 0.999_999);
        let t = s / (1.0 - s * s).sqrt();
        let fov = 2.0 * t.atan().to_degrees();
        let mut v = View::perspective(eye, center - eye, fov, res, res);
        v.near = ((d - radius) * 0.5).max(1e-4);
        v
    }

    /// View-space coordinates `(x, y, depth)` of a world point.
    pub fn to_view(&self, p: DVec3) -> DVec3 {
        let d = p - self.eye;
        DVec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// Pixel coordinates `(px, py)` of a view-space point with depth > 0.
    pub fn to_pixel(&self, v: DVec3) -> (f64, f64) {
        let [l, r, b, t] = self.window;
        let (x, y) = (v.x / v.z, v.y / v.z);
        (
            (x - l) / (r - l) * f64::from(self.width),
            (t - y) / (t - b) * f64::from(self.height),
        )
    }

    /// The world point at pixel coordinates `(px, py)` and depth `w`.
    pub fn unproject(&self, px: f64, py: f64, w: f64) -> DVec3 {
        let [l, r, b, t] = self.window;
        let x = l + px / f64::from(self.width) * (r - l);
        let y = t - py / f64::from(self.height) * (t - b);
        self.eye + (self.right * x + self.up * y + self.forward) * w
    }
}

/// Colour and depth buffers, reused across renders.
#[derive(Clone, Debug)]
pub struct Raster {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA8 per pixel (sRGB colour, alpha = coverage), rows from the top.
    pub color: Vec<[u8; 4]>,
    /// View depth per pixel; `f32::INFINITY` where nothing was drawn.
    pub depth: Vec<f32>,
    /// Samples per side of an output pixel (1: every raster pixel is one):
    /// the raster is drawn at that many times the output resolution and
    /// [`Raster::resolve`]d to it, and alpha to coverage spreads its
    /// thresholds over each block of samples.
    pub samples: u32,
}

impl Raster {
    /// Buffers of `width × height`, cleared.
    pub fn new(width: u32, height: u32) -> Raster {
        let n = width as usize * height as usize;
        Raster {
            width,
            height,
            color: vec![[0; 4]; n],
            depth: vec![f32::INFINITY; n],
            samples: 1,
        }
    }

    /// Buffers for an output of `width × height` pixels with `samples`²
    /// samples per pixel (the raster is `samples` times larger per side).
    pub fn supersampled(width: u32, height: u32, samples: u32) -> Raster {
        let s = samples.max(1);
        let mut r = Raster::new(width * s, height * s);
        r.samples = s;
        r
    }

    /// The output pixels, each the box-filtered average of its samples: the
    /// colour is the mean of its covered samples (alpha above 0) in linear
    /// light, and alpha the share of them covered. Rows from the top.
    pub fn resolve(&self) -> Vec<[u8; 4]> {
        let s = self.samples.max(1) as usize;
        if s == 1 {
            return self.color.clone();
        }
        let (w, h) = (self.width as usize / s, self.height as usize / s);
        let mut out = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (mut sum, mut covered) = ([0.0f32; 3], 0u32);
                for sy in 0..s {
                    let row = (y * s + sy) * self.width as usize;
                    for sx in 0..s {
                        let p = self.color[row + x * s + sx];
                        if p[3] > 0 {
                            covered += 1;
                            for k in 0..3 {
                                sum[k] += srgb8_to_linear(p[k]);
                            }
                        }
                    }
                }
                out.push(if covered == 0 {
                    [0; 4]
                } else {
                    let c = sum.map(|v| linear_to_srgb8(v / covered as f32));
                    let a = (255 * covered as usize + s * s / 2) / (s * s);
                    [c[0], c[1], c[2], a as u8]
                });
            }
        }
        out
    }

    /// Resizes (reusing the allocation) and clears to transparent black.
    pub fn reset(&mut self, width: u32, height: u32) {
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        self.color.clear();
        self.color.resize(n, [0; 4]);
        self.depth.clear();
        self.depth.resize(n, f32::INFINITY);
    }

    /// Fills the colour buffer with `rgba` (depth stays cleared).
    pub fn fill(&mut self, rgba: [u8; 4]) {
        self.color.fill(rgba);
    }

    /// The colour buffer as bytes.
    pub fn rgba_bytes(&self) -> Vec<u8> {
        self.color.iter().flatten().copied().collect()
    }

    /// Draws one triangle seen from `view`, keeping only fragments whose
    /// depth lies in `[slab.0, slab.1)` (use `(0, ∞)` for all).
    pub fn draw(&mut self, view: &View, tri: &[Vertex; 3], surface: &Surface, slab: (f64, f64)) {
        debug_assert_eq!((self.width, self.height), (view.width, view.height));
        let vs = tri.map(|v| view.to_view(v.pos));
        let near = view.near.max(slab.0 * 0.999);
        if vs.iter().all(|v| v.z < near) || vs.iter().all(|v| v.z >= slab.1) {
            return;
        }
        // Face normal in world space, for back-face handling and as a
        // fallback vertex normal.
        let face = (tri[1].pos - tri[0].pos).cross(tri[2].pos - tri[0].pos);
        if face.length_squared() == 0.0 || !face.is_finite() {
            return;
        }
        let to_eye = view.eye - tri[0].pos;
        let back = face.dot(to_eye) < 0.0;
        if back && !surface.double_sided {
            return;
        }
        let face_n = face.normalize().as_vec3() * if back { -1.0 } else { 1.0 };
        // Clip against the near plane (Sutherland–Hodgman on one plane).
        let mut poly: [(DVec3, Vertex); 4] = [(DVec3::ZERO, Vertex::default()); 4];
        let mut n = 0;
        for i in 0..3 {
            let (a, b) = ((vs[i], tri[i]), (vs[(i + 1) % 3], tri[(i + 1) % 3]));
            let (ina, inb) = (a.0.z >= near, b.0.z >= near);
            if ina {
                poly[n] = a;
                n += 1;
            }
            if ina != inb {
                let t = (near - a.0.z) / (b.0.z - a.0.z);
                let tf = t as f32;
                poly[n] = (
                    a.0 + (b.0 - a.0) * t,
                    Vertex {
                        pos: a.1.pos + (b.1.pos - a.1.pos) * t,
                        normal: a.1.normal + (b.1.normal - a.1.normal) * tf,
                        uv: a.1.uv + (b.1.uv - a.1.uv) * tf,
                    },
                );
                n += 1;
            }
        }
        for k in 1..n.saturating_sub(1) {
            self.fill_triangle(
                view,
                [poly[0], poly[k], poly[k + 1]],
                surface,
                face_n,
                back,
                slab,
            );
        }
    }

    fn fill_triangle(
        &mut self,
        view: &View,
        p: [(DVec3, Vertex); 3],
        surface: &Surface,
        face_n: Vec3,
        back: bool,
        slab: (f64, f64),
    ) {
        let px = p.map(|(v, _)| view.to_pixel(v));
        let area = edge(px[0], px[1], px[2]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let min_x = px.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let max_x = px.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let min_y = px.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let max_y = px.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        if max_x <= 0.0 || max_y <= 0.0 || min_x >= w || min_y >= h {
            return;
        }
        let x0 = (min_x - 0.5).ceil().max(0.0) as u32;
        let x1 = ((max_x - 0.5).floor().min(w - 1.0)) as i64;
        let y0 = (min_y - 0.5).ceil().max(0.0) as u32;
        let y1 = ((max_y - 0.5).floor().min(h - 1.0)) as i64;
        if x1 < i64::from(x0) || y1 < i64::from(y0) {
            return;
        }
        // Orient so that inside means all edge functions ≥ 0.
        let sign = area.signum();
        let inv_area = 1.0 / area.abs();
        let iw = p.map(|(v, _)| 1.0 / v.z);
        let normals = p.map(|(_, v)| {
            if v.normal.length_squared() > 0.0 {
                let n = v.normal.normalize();
                if back { -n } else { n }
            } else {
                face_n
            }
        });
        let uvs = p.map(|(_, v)| v.uv);
        let edges = [(1usize, 2usize), (2, 0), (0, 1)];
        // Top-left rule. With y down and the edges oriented so that inside
        // is positive, a top edge runs in +x with dy = 0 and a left edge runs
        // in −y; pixel centres exactly on other edges belong to the
        // neighbouring triangle.
        let top_left = edges.map(|(a, b)| {
            let dx = (px[b].0 - px[a].0) * sign;
            let dy = (px[b].1 - px[a].1) * sign;
            dy < 0.0 || (dy == 0.0 && dx > 0.0)
        });
        let light = light_dir();
        for y in y0..=y1 as u32 {
            let cy = f64::from(y) + 0.5;
            for x in x0..=x1 as u32 {
                let c = (f64::from(x) + 0.5, cy);
                let mut b = [0.0f64; 3];
                let mut inside = true;
                for (k, &(a, bb)) in edges.iter().enumerate() {
                    let e = edge(px[a], px[bb], c) * sign;
                    if e < 0.0 || (e == 0.0 && !top_left[k]) {
                        inside = false;
                        break;
                    }
                    b[k] = e * inv_area;
                }
                if !inside {
                    continue;
                }
                // Perspective-correct weights.
                let q = [b[0] * iw[0], b[1] * iw[1], b[2] * iw[2]];
                let sum = q[0] + q[1] + q[2];
                let depth = 1.0 / sum;
                if depth < slab.0 || depth >= slab.1 {
                    continue;
                }
                let i = y as usize * self.width as usize + x as usize;
                if depth as f32 >= self.depth[i] {
                    continue;
                }
                let wq = [
                    (q[0] / sum) as f32,
                    (q[1] / sum) as f32,
                    (q[2] / sum) as f32,
                ];
                let uv = uvs[0] * wq[0] + uvs[1] * wq[1] + uvs[2] * wq[2];
                let mut rgba = surface.base_color;
                if let Some(t) = &surface.texture {
                    let s = sample_bilinear(t, uv);
                    for k in 0..4 {
                        rgba[k] *= s[k];
                    }
                }
                if let Some(cut) = surface.alpha_cutoff {
                    let s = self.samples;
                    let cut = if surface.alpha_to_coverage && s > 1 {
                        let rank = (y % s) * s + x % s;
                        (rank as f32 + 0.5) / (s * s) as f32
                    } else {
                        cut
                    };
                    if rgba[3] < cut {
                        continue;
                    }
                }
                if surface.lit {
                    let n = (normals[0] * wq[0] + normals[1] * wq[1] + normals[2] * wq[2])
                        .normalize_or(face_n);
                    let l = AMBIENT + (1.0 - AMBIENT) * n.dot(light).max(0.0);
                    for c in &mut rgba[..3] {
                        *c *= l;
                    }
                }
                self.depth[i] = depth as f32;
                self.color[i] = [
                    linear_to_srgb8(rgba[0]),
                    linear_to_srgb8(rgba[1]),
                    linear_to_srgb8(rgba[2]),
                    255,
                ];
            }
        }
    }
}

/// Twice the signed area of `(a, b, c)`.
fn edge(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// Wraps an integer texel coordinate into `[0, n)`.
fn wrap(i: i64, n: u32, mode: Wrap) -> usize {
    let n = i64::from(n.max(1));
    (match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m < n { m } else { 2 * n - 1 - m }
        }
    }) as usize
}

/// Bilinear sample of a texture at `uv` (glTF: `(0, 0)` is the top-left
/// corner of the image); linear RGBA.
pub fn sample_bilinear(t: &TextureRef, uv: Vec2) -> [f32; 4] {
    if t.width == 0 || t.height == 0 || t.rgba.len() < t.width as usize * t.height as usize * 4 {
        return [1.0; 4];
    }
    let x = f64::from(uv.x) * f64::from(t.width) - 0.5;
    let y = f64::from(uv.y) * f64::from(t.height) - 0.5;
    if !(x.is_finite() && y.is_finite()) {
        return [1.0; 4];
    }
    let (fx, fy) = (x.floor(), y.floor());
    let (ax, ay) = ((x - fx) as f32, (y - fy) as f32);
    let (ix, iy) = (fx as i64, fy as i64);
    let texel = |i: i64, j: i64| -> [f32; 4] {
        let (u, v) = (wrap(i, t.width, t.wrap_s), wrap(j, t.height, t.wrap_t));
        let o = (v * t.width as usize + u) * 4;
        let p = &t.rgba[o..o + 4];
        [
            srgb8_to_linear(p[0]),
            srgb8_to_linear(p[1]),
            srgb8_to_linear(p[2]),
            f32::from(p[3]) / 255.0,
        ]
    };
    let (a, b, c, d) = (
        texel(ix, iy),
        texel(ix + 1, iy),
        texel(ix, iy + 1),
        texel(ix + 1, iy + 1),
    );
    let mut out = [0.0; 4];
    for k in 0..4 {
        let top = a[k] + (b[k] - a[k]) * ax;
        let bottom = c[k] + (d[k] - c[k]) * ax;
        out[k] = top + (bottom - top) * ay;
    }
    out
}

/// sRGB-encoded byte to linear (a table of [`srgb8_to_linear_exact`]).
pub fn srgb8_to_linear(v: u8) -> f32 {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb8_to_linear_exact(i as u8)))[v as usize]
}

/// sRGB-encoded byte to linear, by the formula.
fn srgb8_to_linear_exact(v: u8) -> f32 {
    let c = f32::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear value to an sRGB-encoded byte (clamped): how many of the 255
/// thresholds of [`linear_to_srgb8_exact`] (the least value giving each
/// byte from 1 up, found once by bisection) lie at or below it. The
/// formula rises with its argument, so this is its value without a
/// `powf` per call.
pub fn linear_to_srgb8(v: f32) -> u8 {
    static THRESHOLDS: std::sync::OnceLock<[f32; 255]> = std::sync::OnceLock::new();
    let t = THRESHOLDS.get_or_init(|| {
        std::array::from_fn(|k| {
            let byte = k as u8 + 1;
            // The least non-negative f32 (by bit pattern, which orders
            // them) at which the formula reaches `byte`.
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while lo < hi {
                let mid = lo + (hi - lo) / 2;
                if linear_to_srgb8_exact(f32::from_bits(mid)) >= byte {
                    hi = mid;
                } else {
                    lo = mid + 1;
                }
            }
            f32::from_bits(lo)
        })
    });
    t.partition_point(|&x| x <= v) as u8
}

/// Linear value to an sRGB-encoded byte (clamped), by the formula.
fn linear_to_srgb8_exact(v: f32) -> u8 {
    let c = v.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// FNV-1a 64 of bytes (golden-image hashes in tests).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vertex {
        Vertex {
            pos: DVec3::new(x, y, z),
            ..Vertex::default()
        }
    }

    /// A 16×16 camera at the origin looking down −z with a 90° field of view:
    /// at depth 1 the window is [−1, 1]², one pixel = 0.125.
    fn cam() -> View {
        View::perspective(DVec3::ZERO, -DVec3::Z, 90.0, 16, 16)
    }

    const ALL: (f64, f64) = (0.0, f64::INFINITY);

    fn unlit(c: [f32; 4]) -> Surface<'static> {
        Surface {
            base_color: c,
            lit: false,
            double_sided: true,
            ..Surface::default()
        }
    }

    #[test]
    fn known_triangle_covers_the_expected_pixels() {
        let view = cam();
        let mut r = Raster::new(16, 16);
        // A right triangle over the left half of the top half of the image:
        // corners at pixels (0, 0), (8, 0), (0, 8) at depth 1.
        let tri = [v(-1.0, 1.0, -1.0), v(0.0, 1.0, -1.0), v(-1.0, 0.0, -1.0)];
        r.draw(&view, &tri, &unlit([1.0, 0.0, 0.0, 1.0]), ALL);
        let covered: Vec<(u32, u32)> = (0..16)
            .flat_map(|y| (0..16).map(move |x| (x, y)))
            .filter(|&(x, y)| r.color[(y * 16 + x) as usize][3] == 255)
            .collect();
        // Pixel centres (x + 0.5, y + 0.5) with x + y + 1 < 8 are strictly
        // inside; those with x + y + 1 == 8 lie on the hypotenuse.
        let inside = |x: u32, y: u32| x + y + 1 < 8;
        for y in 0..16 {
            for x in 0..16 {
                if inside(x, y) {
                    assert!(covered.contains(&(x, y)), "({x}, {y}) missing");
                } else if x + y + 1 > 8 {
                    assert!(!covered.contains(&(x, y)), "({x}, {y}) extra");
                }
            }
        }
        assert!((28..=36).contains(&covered.len()), "{}", covered.len());
        assert_eq!(r.color[0], [255, 0, 0, 255]);
        assert!((r.depth[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn shared_edges_cover_each_pixel_once() {
        // Two triangles forming the full-screen quad at depth 1; a counting
        // pass with additive alpha would show doubles: draw with a slab
        // and count fragments through the depth buffer instead.
        let view = cam();
        let quad = [
            [v(-1.0, -1.0, -1.0), v(1.0, -1.0, -1.0), v(1.0, 1.0, -1.0)],
            [v(-1.0, -1.0, -1.0), v(1.0, 1.0, -1.0), v(-1.0, 1.0, -1.0)],
        ];
        let mut hits = [0u32; 256];
        for tri in &quad {
            let mut r = Raster::new(16, 16);
            r.draw(&view, tri, &unlit([1.0; 4]), ALL);
            for (i, c) in r.color.iter().enumerate() {
                hits[i] += u32::from(c[3] == 255);
            }
        }
        assert!(hits.iter().all(|&h| h == 1), "{hits:?}");
    }

    #[test]
    fn nearer_triangle_wins_whatever_the_order() {
        let view = cam();
        let near = [v(-1.0, -1.0, -2.0), v(1.0, -1.0, -2.0), v(0.0, 1.0, -2.0)];
        let far = [v(-3.0, -3.0, -4.0), v(3.0, -3.0, -4.0), v(0.0, 3.0, -4.0)];
        let (red, blue) = (unlit([1.0, 0.0, 0.0, 1.0]), unlit([0.0, 0.0, 1.0, 1.0]));
        let mut a = Raster::new(16, 16);
        a.draw(&view, &near, &red, ALL);
        a.draw(&view, &far, &blue, ALL);
        let mut b = Raster::new(16, 16);
        b.draw(&view, &far, &blue, ALL);
        b.draw(&view, &near, &red, ALL);
        assert_eq!(a.color, b.color);
        let centre = (8 * 16 + 8) as usize;
        assert_eq!(a.color[centre], [255, 0, 0, 255]);
        assert!((a.depth[centre] - 2.0).abs() < 1e-5);
        // The slab [3, 5) keeps only the far triangle.
        let mut c = Raster::new(16, 16);
        c.draw(&view, &near, &red, (3.0, 5.0));
        c.draw(&view, &far, &blue, (3.0, 5.0));
        assert_eq!(c.color[centre], [0, 0, 255, 255]);
    }

    #[test]
    fn back_faces_are_culled_unless_double_sided() {
        let view = cam();
        // Clockwise as seen from the camera: its normal points away.
        let tri = [v(-1.0, -1.0, -2.0), v(0.0, 1.0, -2.0), v(1.0, -1.0, -2.0)];
        let mut r = Raster::new(16, 16);
        let one = Surface {
            double_sided: false,
            ..unlit([1.0; 4])
        };
        r.draw(&view, &tri, &one, ALL);
        assert!(r.color.iter().all(|c| c[3] == 0));
        r.draw(&view, &tri, &unlit([1.0; 4]), ALL);
        assert!(r.color.iter().any(|c| c[3] == 255));
    }

    /// On a raster of 3×3 samples per pixel a texture of alpha 0.3 under
    /// alpha to coverage covers 3 of the 9 samples of each pixel (thresholds
    /// 0.06, 0.17, 0.28, 0.39, …), resolved to alpha 1/3; tested at the
    /// cutoff 0.5 instead, it covers nothing. A whole pixel covered is
    /// resolved to alpha 1.
    #[test]
    fn alpha_to_coverage_covers_the_share_of_a_pixel_its_alpha_says() {
        let texels = [200u8, 40, 40, 77];
        let tex = TextureRef {
            width: 1,
            height: 1,
            rgba: &texels,
            wrap_s: Wrap::ClampToEdge,
            wrap_t: Wrap::ClampToEdge,
        };
        let draw = |a2c: bool| {
            let s = Surface {
                texture: Some(tex),
                alpha_cutoff: Some(0.5),
                alpha_to_coverage: a2c,
                ..unlit([1.0; 4])
            };
            let view = View::perspective(DVec3::ZERO, -DVec3::Z, 90.0, 12, 12);
            let v = |x: f64, y: f64| Vertex {
                pos: DVec3::new(x, y, -1.0),
                normal: Vec3::Z,
                uv: Vec2::new(0.5, 0.5),
            };
            // One triangle over the whole window.
            let mut r = Raster::supersampled(4, 4, 3);
            r.draw(&view, &[v(-4.0, -4.0), v(8.0, -4.0), v(-4.0, 8.0)], &s, ALL);
            r.resolve()
        };
        for p in draw(true) {
            assert_eq!(p[3], 85, "{p:?}"); // 3 of 9 samples: alpha 0.3 → 1/3
            assert!(p[0] > p[1], "{p:?}");
        }
        assert!(draw(false).iter().all(|p| p[3] == 0));
        let opaque = Surface {
            alpha_cutoff: Some(0.5),
            alpha_to_coverage: true,
            ..unlit([0.5, 0.5, 0.5, 1.0])
        };
        let view = View::perspective(DVec3::ZERO, -DVec3::Z, 90.0, 12, 12);
        let v = |x: f64, y: f64| Vertex {
            pos: DVec3::new(x, y, -1.0),
            normal: Vec3::Z,
            uv: Vec2::ZERO,
        };
        let mut r = Raster::supersampled(4, 4, 3);
        r.draw(
            &view,
            &[v(-4.0, -4.0), v(8.0, -4.0), v(-4.0, 8.0)],
            &opaque,
            ALL,
        );
        assert!(r.resolve().iter().all(|p| p[3] == 255));
    }

    #[test]
    fn perspective_correct_texture_sampling() {
        // A 2×1 texture: left half red, right half green, on a quad that
        // recedes in depth. With perspective correction the colour boundary
        // is at the projection of the quad's 3D midpoint, not at the middle
        // of the screen-space span.
        let texels = [255u8, 0, 0, 255, 0, 255, 0, 255];
        let tex = TextureRef {
            width: 2,
            height: 1,
            rgba: &texels,
            wrap_s: Wrap::ClampToEdge,
            wrap_t: Wrap::ClampToEdge,
        };
        let s = Surface {
            texture: Some(tex),
            ..unlit([1.0; 4])
        };
        let view = View::perspective(DVec3::ZERO, -DVec3::Z, 90.0, 64, 64);
        let corner = |x: f64, z: f64, y: f64, u: f32| Vertex {
            pos: DVec3::new(x, y, z),
            normal: Vec3::Z,
            uv: Vec2::new(u, 0.5),
        };
        // From x = −1 at depth 1 to x = 3 at depth 3.
        let a = corner(-1.0, -1.0, -0.5, 0.0);
        let b = corner(3.0, -3.0, -0.5, 1.0);
        let c = corner(3.0, -3.0, 0.5, 1.0);
        let d = corner(-1.0, -1.0, 0.5, 0.0);
        let mut r = Raster::new(64, 64);
        r.draw(&view, &[a, b, c], &s, ALL);
        r.draw(&view, &[a, c, d], &s, ALL);
        // 3D midpoint (1, −2) projects to x/w = 0.5 → pixel 48; the screen
        // midpoint of the span [−1, 1] would be pixel 32.
        let row = 32usize * 64;
        let red_to_green = (0..64)
            .find(|&x| {
                let p = r.color[row + x];
                p[3] == 255 && p[1] > p[0]
            })
            .unwrap();
        assert!((46..=50).contains(&red_to_green), "{red_to_green}");
    }

    #[test]
    fn bilinear_sampling_and_wrapping() {
        let texels = [0u8, 0, 0, 255, 255, 255, 255, 255];
        let t = TextureRef {
            width: 2,
            height: 1,
            rgba: &texels,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
        };
        // Texel centres at u = 0.25 (black) and 0.75 (white).
        assert_eq!(sample_bilinear(&t, Vec2::new(0.25, 0.5))[0], 0.0);
        assert_eq!(sample_bilinear(&t, Vec2::new(0.75, 0.5))[0], 1.0);
        assert!((sample_bilinear(&t, Vec2::new(0.5, 0.5))[0] - 0.5).abs() < 1e-6);
        // Repeat: u = 1.25 is u = 0.25.
        assert_eq!(sample_bilinear(&t, Vec2::new(1.25, 0.5))[0], 0.0);
        // Clamp: far right stays white, mirrored: u = 1.25 is u = 0.75.
        let c = TextureRef {
            wrap_s: Wrap::ClampToEdge,
            ..t
        };
        assert_eq!(sample_bilinear(&c, Vec2::new(7.0, 0.5))[0], 1.0);
        let m = TextureRef {
            wrap_s: Wrap::MirroredRepeat,
            ..t
        };
        assert_eq!(sample_bilinear(&m, Vec2::new(1.25, 0.5))[0], 1.0);
    }

    #[test]
    fn srgb_round_trip() {
        for b in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(b)), b);
            assert_eq!(srgb8_to_linear(b), srgb8_to_linear_exact(b));
        }
    }

    /// The thresholds give the formula's byte: at every 97th f32 of
    /// [0, 1], one ulp either side of each threshold, and outside [0, 1].
    #[test]
    fn srgb_encoding_by_thresholds_is_the_formula() {
        let one = 1.0f32.to_bits();
        let check = |v: f32| assert_eq!(linear_to_srgb8(v), linear_to_srgb8_exact(v), "{v:e}");
        for bits in (0..=one).step_by(97) {
            check(f32::from_bits(bits));
        }
        for b in 0..=255u8 {
            let v = srgb8_to_linear(b);
            for d in [-2i64, -1, 0, 1, 2] {
                check(f32::from_bits((i64::from(v.to_bits()) + d).max(0) as u32));
            }
        }
        for v in [
            -1.0,
            -0.0,
            1.0,
            1.5,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ] {
            check(v);
        }
    }

    #[test]
    fn near_plane_clipping_keeps_the_visible_part() {
        // A floor triangle passing under and behind the camera.
        let view = View::perspective(DVec3::new(0.0, 1.0, 0.0), -DVec3::Z, 90.0, 16, 16);
        let tri = [v(-50.0, 0.0, 10.0), v(50.0, 0.0, 10.0), v(0.0, 0.0, -50.0)];
        let mut r = Raster::new(16, 16);
        r.draw(&view, &tri, &unlit([1.0; 4]), ALL);
        // The lower half of the image sees the floor, the upper half sky.
        let bottom = r.color[15 * 16 + 8];
        let top = r.color[8];
        assert_eq!(bottom[3], 255);
        assert_eq!(top[3], 0);
    }

    #[test]
    fn enclosing_sphere_view_frames_the_sphere() {
        let c = DVec3::new(3.0, 2.0, -10.0);
        let view = View::enclosing_sphere(DVec3::ZERO, c, 2.0, 32);
        let (x, y) = view.to_pixel(view.to_view(c));
        assert!((x - 16.0).abs() < 1e-9 && (y - 16.0).abs() < 1e-9);
        // A point on the sphere's silhouette lands on the image border.
        let d = c.length();
        let side = view.right * 2.0 * d / (d * d - 4.0).sqrt();
        let edge_point = c + side * ((d * d - 4.0) / (d * d)).sqrt();
        let (ex, _) = view.to_pixel(view.to_view(edge_point));
        assert!((0.0..=32.5).contains(&ex), "{ex}");
        let p = view.unproject(20.0, 7.0, 4.0);
        let back = view.to_pixel(view.to_view(p));
        assert!((back.0 - 20.0).abs() < 1e-9 && (back.1 - 7.0).abs() < 1e-9);
    }

    #[test]
    fn golden_render() {
        // A lit, textured, depth-tested little scene; any change to
        // rasterisation rules, sampling or shading changes the hash.
        let texels: Vec<u8> = (0..16u8)
            .flat_map(|i| [i * 16, 255 - i * 16, (i * 37) % 255, 255])
            .collect();
        let tex = TextureRef {
            width: 4,
            height: 4,
            rgba: &texels,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
        };
        let view = View::perspective(
            DVec3::new(0.5, 2.0, 4.0),
            DVec3::new(-0.1, -0.4, -1.0),
            50.0,
            48,
            32,
        );
        let mut r = Raster::new(48, 32);
        let lit = Surface {
            texture: Some(tex),
            ..Surface::default()
        };
        let vert = |x: f64, y: f64, z: f64, n: Vec3, u: f32, w: f32| Vertex {
            pos: DVec3::new(x, y, z),
            normal: n,
            uv: Vec2::new(u, w),
        };
        // Floor.
        r.draw(
            &view,
            &[
                vert(-3.0, 0.0, 3.0, Vec3::Y, 0.0, 0.0),
                vert(3.0, 0.0, 3.0, Vec3::Y, 3.0, 0.0),
                vert(3.0, 0.0, -3.0, Vec3::Y, 3.0, 3.0),
            ],
            &lit,
            ALL,
        );
        r.draw(
            &view,
            &[
                vert(-3.0, 0.0, 3.0, Vec3::Y, 0.0, 0.0),
                vert(3.0, 0.0, -3.0, Vec3::Y, 3.0, 3.0),
                vert(-3.0, 0.0, -3.0, Vec3::Y, 0.0, 3.0),
            ],
            &lit,
            ALL,
        );
        // A standing wall, partly behind the floor's far edge.
        let wall = Surface {
            base_color: [0.8, 0.5, 0.2, 1.0],
            ..Surface::default()
        };
        r.draw(
            &view,
            &[
                vert(-1.0, 0.0, -1.0, Vec3::Z, 0.0, 0.0),
                vert(1.0, 0.0, -1.0, Vec3::Z, 0.0, 0.0),
                vert(0.0, 1.5, -1.0, Vec3::Z, 0.0, 0.0),
            ],
            &wall,
            ALL,
        );
        let bytes = r.rgba_bytes();
        if let Ok(path) = std::env::var("RASTER_DUMP") {
            std::fs::write(path, &bytes).unwrap();
        }
        let covered = r.color.iter().filter(|c| c[3] == 255).count();
        assert!(covered > 600, "{covered}");
        assert_eq!(
            fnv1a64(&bytes),
            GOLDEN,
            "golden hash changed: {:#x}",
            fnv1a64(&bytes)
        );
    }

    const GOLDEN: u64 = 0xa042_f3c8_04d1_5af1;
}
