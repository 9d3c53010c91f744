//! Sharpening a layer's texels against the blur of drawing it.
//!
//! A texel holds the box-filtered mean of its area (4 × 4 samples) and a
//! viewer reads the layer bilinearly: at one texel per pixel a drawn edge is
//! the scene's edge blurred by the texel's box and the lookup's tent, which
//! the geometry, box-filtered over a pixel only, does not show (window lines
//! and small far clusters lose their contrast; a silhouette's alpha ramps
//! over two texels where the geometry's coverage steps in one). Each axis is
//! filtered with `[-S, 1 + 2S, -S]`, `S` = [`STRENGTH`]: its gain, `1 + 2S
//! (1 - cos ω)`, follows the inverse of box and tent (`((ω/2) / sin(ω/2))³`)
//! over the band a magnified layer shows (1.5 at half the texel frequency,
//! where the inverse is 1.37) and stops at 2 at the texel frequency (where
//! the inverse, 3.9, would ring).
//!
//! Colour is filtered in linear light among covered texels only (a
//! transparent neighbour counts as the texel itself, so no background is
//! pulled into a silhouette); alpha among all texels (outside the layer is
//! transparent), clamped to `[0, 1]`, so a silhouette's ramp steepens and a
//! thin feature's share grows while a layer's most covered texel keeps its
//! coverage. Texels whose alpha falls to 0 become transparent.

use crate::render::raster::{linear_to_srgb8, srgb8_to_linear};

/// The filter's side taps, `S` (the centre tap is `1 + 2S`).
pub const STRENGTH: f32 = 0.25;

/// `rgba` (`res × res` texels, sRGB colour, alpha the covered share, rows
/// from the top) filtered along rows, then columns.
pub fn sharpen(rgba: &[[u8; 4]], res: u32) -> Vec<[u8; 4]> {
    let n = res as usize;
    debug_assert_eq!(rgba.len(), n * n);
    let lin: Vec<[f32; 4]> = rgba
        .iter()
        .map(|p| {
            [
                srgb8_to_linear(p[0]),
                srgb8_to_linear(p[1]),
                srgb8_to_linear(p[2]),
                f32::from(p[3]) / 255.0,
            ]
        })
        .collect();
    let rows = filter(&lin, n, 1, n);
    let both = filter(&rows, n, n, 1);
    both.iter()
        .map(|p| {
            let a = (p[3] * 255.0).round() as u8;
            if a == 0 {
                [0; 4]
            } else {
                [
                    linear_to_srgb8(p[0]),
                    linear_to_srgb8(p[1]),
                    linear_to_srgb8(p[2]),
                    a,
                ]
            }
        })
        .collect()
}

/// One pass of the filter over the `n × n` texels of `src`, along the axis
/// whose neighbours are `step` apart (`line` apart are the lines across
/// it).
fn filter(src: &[[f32; 4]], n: usize, step: usize, line: usize) -> Vec<[f32; 4]> {
    let mut out = src.to_vec();
    for l in 0..n {
        for k in 0..n {
            let i = l * line + k * step;
            let c = src[i];
            if c[3] <= 0.0 {
                continue;
            }
            let before = (k > 0).then(|| src[i - step]);
            let after = (k + 1 < n).then(|| src[i + step]);
            let o = &mut out[i];
            for ch in 0..3 {
                let colour =
                    |q: Option<[f32; 4]>| q.filter(|q| q[3] > 0.0).map_or(c[ch], |q| q[ch]);
                o[ch] = ((1.0 + 2.0 * STRENGTH) * c[ch]
                    - STRENGTH * (colour(before) + colour(after)))
                .clamp(0.0, 1.0);
            }
            let alpha = |q: Option<[f32; 4]>| q.map_or(0.0, |q| q[3]);
            o[3] = ((1.0 + 2.0 * STRENGTH) * c[3] - STRENGTH * (alpha(before) + alpha(after)))
                .clamp(0.0, 1.0);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `res × res` layer with texel `(x, y)` = `f(x, y)`.
    fn layer(res: usize, f: impl Fn(usize, usize) -> [u8; 4]) -> Vec<[u8; 4]> {
        (0..res * res).map(|i| f(i % res, i / res)).collect()
    }

    #[test]
    fn a_thin_line_gains_the_share_the_lookup_blurs_away() {
        // A vertical line covering 30 % of its texels, transparent around:
        // rows give 1.5 × 0.3 = 0.45; columns, whose neighbours are equal,
        // 1.5 × 0.45 − 0.25 × 0.9 = 0.45.
        let l = layer(5, |x, _| if x == 2 { [200, 100, 50, 77] } else { [0; 4] });
        let s = sharpen(&l, 5);
        for y in 0..5 {
            let a = f32::from(s[y * 5 + 2][3]) / 255.0;
            // The top and bottom texels have one transparent neighbour
            // beyond the layer: 1.5 × 0.45 − 0.25 × 0.45 = 0.5625.
            let want = if y == 0 || y == 4 { 0.5625 } else { 0.45 };
            assert!((a - want).abs() < 0.005, "row {y}: alpha {a}, want {want}");
            // Its colour has no covered neighbour across the line and equal
            // ones along it: unchanged.
            assert_eq!(s[y * 5 + 2][..3], [200, 100, 50]);
        }
        assert!(
            s.iter()
                .enumerate()
                .all(|(i, p)| i % 5 == 2 || *p == [0; 4])
        );
    }

    #[test]
    fn a_silhouette_steepens_and_keeps_its_colour() {
        // Left half covered in one colour, a half-covered column between.
        let l = layer(8, |x, _| match x {
            0..=3 => [90, 160, 30, 255],
            4 => [90, 160, 30, 128],
            _ => [0; 4],
        });
        let s = sharpen(&l, 8);
        for y in 1..7 {
            let row = &s[y * 8..y * 8 + 8];
            // Full texels stay full, the edge texel between 1 and 0 keeps
            // its share (1.5 × 0.5 − 0.25 × 1), nothing spreads outwards.
            assert_eq!(row[3][3], 255);
            assert!((i32::from(row[4][3]) - 128).abs() <= 1, "{row:?}");
            assert!(row[5..].iter().all(|p| *p == [0; 4]), "{row:?}");
            // A uniform colour is kept exactly: no background pulled in.
            assert!(row[..5].iter().all(|p| p[..3] == [90, 160, 30]), "{row:?}");
        }
    }

    #[test]
    fn contrast_grows_in_linear_light_and_flat_areas_keep_their_values() {
        // A covered layer with one brighter column.
        let l = layer(6, |x, _| {
            if x == 3 {
                [180, 180, 180, 255]
            } else {
                [100, 100, 100, 255]
            }
        });
        let s = sharpen(&l, 6);
        let (lo, hi) = (srgb8_to_linear(100), srgb8_to_linear(180));
        let want_hi = linear_to_srgb8(1.5 * hi - 0.5 * lo);
        let want_lo = linear_to_srgb8(1.25 * lo - 0.25 * hi);
        let near = |a: u8, b: u8| a.abs_diff(b) <= 1;
        for y in 0..6 {
            assert!(near(s[y * 6 + 3][0], want_hi), "{:?}", s[y * 6 + 3]);
            assert!(near(s[y * 6 + 2][0], want_lo), "{:?}", s[y * 6 + 2]);
            assert!(near(s[y * 6][0], 100), "{:?}", s[y * 6]);
            assert!(s[y * 6..y * 6 + 6].iter().all(|p| p[3] == 255));
        }
        assert!(want_hi > 180 && want_lo < 100);
    }
}
