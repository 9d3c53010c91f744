//! Comparing two renders of a view over the pixels of a mask: PSNR, the
//! one-pixel (half-pixel-step) mismatch map and its share, and the
//! percentile of the per-view figures.

/// PSNR over RGB of the pixels of `mask` of two RGBA8 images, dB, capped
/// at 100 (also for an empty mask).
pub fn psnr_db(a: &[u8], b: &[u8], mask: &[bool]) -> f64 {
    let mut se = 0.0f64;
    let mut n = 0u64;
    for ((p, q), _) in a
        .chunks_exact(4)
        .zip(b.chunks_exact(4))
        .zip(mask)
        .filter(|(_, m)| **m)
    {
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

/// Share of the pixels of `mask` whose colour has no match within one pixel
/// in the other image (in either direction); 0 for an empty mask.
pub fn mismatch_fraction(
    a: &[u8],
    b: &[u8],
    width: u32,
    height: u32,
    tolerance: u8,
    mask: &[bool],
) -> f64 {
    share_of(&mismatch_map(a, b, width, height, tolerance, mask), mask)
}

/// The share of the pixels of `mask` that `bad` marks; 0 for an empty mask.
pub(super) fn share_of(bad: &[bool], mask: &[bool]) -> f64 {
    let counted = mask.iter().filter(|&&m| m).count();
    if counted == 0 {
        0.0
    } else {
        bad.iter().filter(|&&x| x).count() as f64 / counted as f64
    }
}

/// Per pixel: true for the pixels of `mask` whose colour has no match
/// (every channel within `tolerance`) within one pixel in the other image,
/// in either direction. Offsets run in half-pixel steps, the other image
/// read between pixels as the mean of those around the point: in
/// antialiased images an edge moved by part of a pixel (which the
/// one-pixel parallax budget allows) shows blends no whole-pixel neighbour
/// has.
pub fn mismatch_map(
    a: &[u8],
    b: &[u8],
    width: u32,
    height: u32,
    tolerance: u8,
    mask: &[bool],
) -> Vec<bool> {
    let (w, h) = (width as i64, height as i64);
    let px = |img: &[u8], x: i64, y: i64| -> [u8; 4] {
        let i = ((y * w + x) * 4) as usize;
        [img[i], img[i + 1], img[i + 2], img[i + 3]]
    };
    let tol = f32::from(tolerance);
    // The other image at `(x, y) + (hx, hy) / 2`: a pixel, or the mean of
    // the two or four pixels around a point between them (`None` outside).
    let at = |img: &[u8], x: i64, y: i64, hx: i64, hy: i64| -> Option<[f32; 3]> {
        let xs = [x + hx.div_euclid(2), x + (hx + 1).div_euclid(2)];
        let ys = [y + hy.div_euclid(2), y + (hy + 1).div_euclid(2)];
        if xs[0] < 0 || ys[0] < 0 || xs[1] >= w || ys[1] >= h {
            return None;
        }
        let mut sum = [0.0f32; 3];
        for &yy in &ys {
            for &xx in &xs {
                let q = px(img, xx, yy);
                for k in 0..3 {
                    sum[k] += f32::from(q[k]);
                }
            }
        }
        Some(sum.map(|v| v / 4.0))
    };
    let matched = |src: &[u8], other: &[u8], x: i64, y: i64| {
        let p = px(src, x, y);
        for hy in -2..=2 {
            for hx in -2..=2 {
                if let Some(q) = at(other, x, y, hx, hy)
                    && (0..3).all(|k| (f32::from(p[k]) - q[k]).abs() <= tol)
                {
                    return true;
                }
            }
        }
        false
    };
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| mask[(y * w + x) as usize] && (!matched(a, b, x, y) || !matched(b, a, x, y)))
        .collect()
}

/// The `q` quantile of ascending `sorted` values by nearest rank (the
/// smallest value with at least `q` of them at or below it; 0 when empty).
pub(super) fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let rank = (q * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}
