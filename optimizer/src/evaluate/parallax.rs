//! The image criterion checked geometrically for every impostor.

use rayon::prelude::*;

use crate::api::evaluation::ParallaxCheck;
use crate::api::job::Job;
use crate::api::placement::{PlacedImpostor, Placement, ViewCellJson};
use crate::math::rng::Rng;

/// Sphere points and viewpoints per impostor of the parallax check.
const PARALLAX_SAMPLES: u32 = 32;

/// Checks the parallax of every impostor of `placement` (deterministic:
/// each impostor's samples are seeded by `seed` and its id).
pub fn parallax_check(job: &Job, placement: &Placement, seed: u64) -> Option<ParallaxCheck> {
    if placement.impostors.is_empty() {
        return None;
    }
    let theta = job.pixel_angle();
    let checked: Vec<&PlacedImpostor> = placement
        .impostors
        .iter()
        .filter(|imp| !view_independent(imp))
        .collect();
    let errs: Vec<f64> = checked
        .par_iter()
        .map(|imp| {
            let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(imp.id));
            crate::model::layers::parallax(imp, &mut rng, PARALLAX_SAMPLES, PARALLAX_SAMPLES)
                / theta
        })
        .collect();
    let budget = job.max_error_px;
    let (worst, max_px) =
        errs.iter().enumerate().fold(
            (0, 0.0f64),
            |(wi, wm), (i, &e)| if e > wm { (i, e) } else { (wi, wm) },
        );
    Some(ParallaxCheck {
        max_error_px: budget,
        impostors: errs.len() as u64,
        points: PARALLAX_SAMPLES,
        viewpoints: PARALLAX_SAMPLES,
        max_px,
        mean_px: if errs.is_empty() {
            0.0
        } else {
            errs.iter().sum::<f64>() / errs.len() as f64
        },
        over_budget: errs.iter().filter(|&&e| e > budget).count() as u64,
        over_budget_1_5: errs.iter().filter(|&&e| e > 1.5 * budget).count() as u64,
        worst_impostor: checked.get(worst).map_or(0, |imp| imp.id),
        view_independent: (placement.impostors.len() - checked.len()) as u64,
    })
}

/// True for an impostor valid from every direction around it.
fn view_independent(imp: &PlacedImpostor) -> bool {
    matches!(imp.view_cell, ViewCellJson::Shaft { half_angle_deg, .. } if half_angle_deg >= 180.0)
}
