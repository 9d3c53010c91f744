//! Mip chains of baked atlases that keep their alpha coverage.
//!
//! A layer is drawn with an alpha cutoff (`AlphaMode::Mask`, 0.5). Box
//! filtering averages thin features (a one-texel branch, a fence wire) into
//! alpha below the cutoff, so the coarser levels lose them and impostors
//! thin out with distance. Each level here is box-filtered from the previous
//! one (colour in linear light, weighted by alpha as the rasterizer's
//! resolve does; alpha averaged; kept unrounded between levels) and its
//! alpha is then scaled so that the share of texels passing the cutoff
//! equals level 0's: the scale is found by bisection, coverage being
//! monotone in it (Castaño's alpha-to-coverage-preserving mipmaps). Levels
//! are filtered from the unscaled previous level, so scales do not compound,
//! and scaled alpha is rounded with a 4 × 4 ordered dither of under one
//! step, so that texels of equal alpha need not pass or fail together.

use crate::render::raster::{linear_to_srgb8, srgb8_to_linear};

/// One level: width, height and `width × height` RGBA8 texels (sRGB colour,
/// straight alpha), rows from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct MipLevel {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height` RGBA8 texels.
    pub rgba: Vec<u8>,
}

/// Number of levels of a full chain down to 1 × 1.
pub fn level_count(width: u32, height: u32) -> u32 {
    32 - width.max(height).max(1).leading_zeros()
}

/// Share of texels whose alpha passes `cutoff` (alpha / 255 ≥ cutoff, as a
/// masked material draws them).
pub fn coverage(rgba: &[u8], cutoff: f32) -> f64 {
    let n = rgba.len() / 4;
    if n == 0 {
        return 0.0;
    }
    let min = alpha_threshold(cutoff);
    let passing = rgba
        .chunks_exact(4)
        .filter(|p| u16::from(p[3]) >= min)
        .count();
    passing as f64 / n as f64
}

/// The smallest alpha byte that passes `cutoff` (256 when none does).
fn alpha_threshold(cutoff: f32) -> u16 {
    (0..=255u16)
        .find(|&a| f32::from(a) / 255.0 >= cutoff)
        .unwrap_or(256)
}

/// A level while the chain is built: colour in linear light, alpha in
/// [0, 255], both unrounded, so that levels are filtered from exact means
/// and nearly equal alphas stay apart for the coverage search.
#[derive(Clone)]
struct Linear {
    width: u32,
    height: u32,
    px: Vec<[f32; 4]>,
}

impl Linear {
    fn from_rgba(rgba: &[u8], width: u32, height: u32) -> Self {
        let px = rgba
            .chunks_exact(4)
            .map(|p| {
                [
                    srgb8_to_linear(p[0]),
                    srgb8_to_linear(p[1]),
                    srgb8_to_linear(p[2]),
                    f32::from(p[3]),
                ]
            })
            .collect();
        Linear { width, height, px }
    }

    /// One box-filter step: each texel of the next level is the mean of
    /// the (up to) 2 × 2 texels it covers, colour weighted by alpha (the
    /// plain mean where all are transparent, so dilated colour survives).
    fn down(&self) -> Self {
        let (w, h) = (self.width as usize, self.height as usize);
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let mut px = Vec::with_capacity(nw * nh);
        for y in 0..nh {
            for x in 0..nw {
                let (mut weighted, mut plain) = ([0f32; 3], [0f32; 3]);
                let (mut alpha, mut count) = (0f32, 0f32);
                for sy in (2 * y)..(2 * y + 2).min(h) {
                    for sx in (2 * x)..(2 * x + 2).min(w) {
                        let p = self.px[sy * w + sx];
                        for k in 0..3 {
                            weighted[k] += p[k] * p[3];
                            plain[k] += p[k];
                        }
                        alpha += p[3];
                        count += 1.0;
                    }
                }
                let c = if alpha > 0.0 {
                    weighted.map(|c| c / alpha)
                } else {
                    plain.map(|c| c / count)
                };
                px.push([c[0], c[1], c[2], alpha / count]);
            }
        }
        Linear {
            width: nw as u32,
            height: nh as u32,
            px,
        }
    }

    /// The level as RGBA8 with every alpha multiplied by `scale`, rounded
    /// with `dither` (or to nearest).
    fn to_level(&self, scale: f32, dither: bool) -> MipLevel {
        let mut rgba = Vec::with_capacity(self.px.len() * 4);
        for (i, p) in self.px.iter().enumerate() {
            rgba.extend([p[0], p[1], p[2]].map(linear_to_srgb8));
            let d = if dither {
                bayer(i as u32 % self.width, i as u32 / self.width)
            } else {
                0.0
            };
            rgba.push(alpha_byte(p[3], scale, d));
        }
        MipLevel {
            width: self.width,
            height: self.height,
            rgba,
        }
    }
}

/// An alpha in [0, 255] times `scale`, offset by `dither` (less than half
/// a step either way), rounded and clamped to a byte.
fn alpha_byte(alpha: f32, scale: f32, dither: f32) -> u8 {
    (alpha * scale + dither).round().clamp(0.0, 255.0) as u8
}

/// The 4 × 4 ordered-dither offset of texel `(x, y)`, in (−0.5, 0.5).
/// Filtered thin features give many texels the very same alpha, which one
/// scale can only keep or drop together; offsets below one alpha step let
/// the coverage search keep a share of them.
fn bayer(x: u32, y: u32) -> f32 {
    const M: [[u8; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];
    (f32::from(M[(y % 4) as usize][(x % 4) as usize]) + 0.5) / 16.0 - 0.5
}

/// One box-filter step of an RGBA8 level (colour in linear light weighted
/// by alpha, alpha averaged), rounded back to RGBA8.
pub fn downsample(level: &MipLevel) -> MipLevel {
    Linear::from_rgba(&level.rgba, level.width, level.height)
        .down()
        .to_level(1.0, false)
}

/// The alpha scale of a level whose coverage at `cutoff` is closest to
/// `target`, found by bisection (coverage grows with the scale); 1 when the
/// unscaled level is as close.
fn coverage_scale(level: &Linear, cutoff: f32, target: f64) -> f32 {
    let min = alpha_threshold(cutoff);
    let n = level.px.len().max(1) as f64;
    let w = level.width;
    let cov = |s: f32| {
        level
            .px
            .iter()
            .enumerate()
            .filter(|&(i, p)| {
                let d = bayer(i as u32 % w, i as u32 / w);
                u16::from(alpha_byte(p[3], s, d)) >= min
            })
            .count() as f64
            / n
    };
    let (mut lo, mut hi) = (0.0f32, 256.0f32);
    let mut best = ((cov(1.0) - target).abs(), 1.0f32);
    for _ in 0..32 {
        let mid = 0.5 * (lo + hi);
        let c = cov(mid);
        if (c - target).abs() < best.0 {
            best = ((c - target).abs(), mid);
        }
        if c < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    best.1
}

/// The full mip chain of an RGBA8 image down to 1 × 1. With
/// `keep_coverage`, the alpha of every level below 0 is scaled so that its
/// coverage at `cutoff` matches level 0's as closely as its texels allow.
pub fn mip_chain(
    rgba: &[u8],
    width: u32,
    height: u32,
    cutoff: f32,
    keep_coverage: bool,
) -> Vec<MipLevel> {
    let target = coverage(rgba, cutoff);
    let mut filtered = Linear::from_rgba(rgba, width, height);
    let mut out = vec![MipLevel {
        width,
        height,
        rgba: rgba.to_vec(),
    }];
    for _ in 1..level_count(width, height) {
        filtered = filtered.down();
        out.push(if keep_coverage {
            filtered.to_level(coverage_scale(&filtered, cutoff, target), true)
        } else {
            filtered.to_level(1.0, false)
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `n × n` transparent image whose alpha at each texel is `alpha(x, y)`.
    fn image(n: u32, alpha: impl Fn(u32, u32) -> u8) -> Vec<u8> {
        let mut px = vec![0u8; (n * n * 4) as usize];
        for y in 0..n {
            for x in 0..n {
                let i = ((y * n + x) * 4) as usize;
                px[i..i + 4].copy_from_slice(&[90, 160, 40, alpha(x, y)]);
            }
        }
        px
    }

    /// Share of a texel's 4 × 4 samples within half a texel of the line
    /// `y = slope · x + y0`: a one-texel-wide line drawn as the bake draws
    /// (supersampled, alpha = coverage).
    fn line_alpha(x: u32, y: u32, slope: f64, y0: f64) -> u8 {
        let mut inside = 0;
        for s in 0..16 {
            let (px, py) = (
                f64::from(x) + (f64::from(s % 4) + 0.5) / 4.0,
                f64::from(y) + (f64::from(s / 4) + 0.5) / 4.0,
            );
            let d = (py - slope * px - y0).abs() / (1.0 + slope * slope).sqrt();
            if d <= 0.5 {
                inside += 1;
            }
        }
        (inside * 255 / 16) as u8
    }

    /// Largest gap between a level's coverage and level 0's, over the levels
    /// still at least `min_side` texels wide.
    fn worst_gap(chain: &[MipLevel], min_side: u32) -> f64 {
        let c0 = coverage(&chain[0].rgba, 0.5);
        chain
            .iter()
            .filter(|l| l.width >= min_side)
            .map(|l| (coverage(&l.rgba, 0.5) - c0).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn thin_features_keep_their_coverage_where_a_box_chain_loses_it() {
        let n = 128;
        let mut rng = crate::math::rng::Rng::new(11);
        let dots: Vec<u8> = (0..n * n)
            .map(|_| {
                let r = rng.next_u64();
                if r % 100 < 12 {
                    128 + (r >> 32) as u8 % 128
                } else {
                    0
                }
            })
            .collect();
        let images = [
            // A one-texel-wide slanted line.
            image(n, |x, y| line_alpha(x, y, 0.37, 9.0)),
            // Three one-texel lines (grass blades, wires).
            image(n, |x, y| {
                [(0.05, 3.0), (0.8, 40.0), (-0.3, 100.0)]
                    .iter()
                    .map(|&(k, y0)| line_alpha(x, y, k, y0))
                    .max()
                    .unwrap_or(0)
            }),
            // A dotted pattern: 12 % of texels, each partly covered.
            image(n, |x, y| dots[(y * n + x) as usize]),
        ];
        for (i, px) in images.iter().enumerate() {
            let c0 = coverage(px, 0.5);
            assert!(c0 > 0.0);
            let plain = mip_chain(px, n, n, 0.5, false);
            let kept = mip_chain(px, n, n, 0.5, true);
            assert_eq!((plain.len(), kept.len()), (8, 8));
            // The control: box filtering alone erodes the features away.
            assert!(
                worst_gap(&plain, 8) > 0.5 * c0,
                "image {i}: the plain chain keeps coverage ({}, level 0 {c0})",
                worst_gap(&plain, 8)
            );
            // Coverage within 10 % of level 0's, or one texel's share of the
            // level when that is coarser, down to 8 × 8 texels.
            for l in kept.iter().filter(|l| l.width >= 8) {
                let c = coverage(&l.rgba, 0.5);
                let tol = (0.1 * c0).max(1.0 / f64::from(l.width * l.height));
                assert!(
                    (c - c0).abs() <= tol,
                    "image {i}, level {}²: coverage {c}, level 0 {c0}",
                    l.width
                );
            }
            // Colour is untouched by the alpha scale.
            for (p, k) in plain.iter().zip(&kept) {
                assert!(
                    p.rgba
                        .chunks_exact(4)
                        .zip(k.rgba.chunks_exact(4))
                        .all(|(a, b)| a[..3] == b[..3])
                );
            }
        }
    }

    #[test]
    fn downsampling_averages_in_linear_light_weighted_by_alpha() {
        // Black and white texels, both opaque: the mean in linear light is
        // sRGB 188, not 128.
        let level = MipLevel {
            width: 2,
            height: 1,
            rgba: vec![0, 0, 0, 255, 255, 255, 255, 255],
        };
        let d = downsample(&level);
        assert_eq!((d.width, d.height), (1, 1));
        assert_eq!(d.rgba, vec![188, 188, 188, 255]);
        // A transparent texel does not pull colour: only alpha halves.
        let level = MipLevel {
            width: 2,
            height: 1,
            rgba: vec![0, 0, 0, 0, 200, 100, 50, 255],
        };
        assert_eq!(downsample(&level).rgba, vec![200, 100, 50, 128]);
    }

    #[test]
    fn chains_reach_one_texel_for_any_shape() {
        assert_eq!(level_count(1, 1), 1);
        assert_eq!(level_count(4096, 1024), 13);
        assert_eq!(level_count(600, 12), 10);
        let chain = mip_chain(&[255; 6 * 3 * 4], 6, 3, 0.5, true);
        let sizes: Vec<(u32, u32)> = chain.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, vec![(6, 3), (3, 1), (1, 1)]);
        // Fully opaque stays fully opaque, scale or not.
        assert!(chain.iter().all(|l| l.rgba.iter().all(|&v| v == 255)));
    }
}
