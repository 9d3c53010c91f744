//! Estimate against truth: each problem view's estimated times against the
//! largest exact times of the views sampled in it.

use std::collections::BTreeMap;

use crate::api::evaluation::{EstimateCheck, EstimatePoint};

/// The most problem views [`EstimateCheck::points`] lists.
pub const MAX_POINTS: usize = 2_000;

/// The estimate check of a placement whose problem view `c` is estimated
/// at `estimates(c)` = (without impostors, with them), ms (`None`: no
/// such problem view), from sampled views, each given as `(cpv, time with
/// impostors, time without)`, `cpv` `u32::MAX` for views in no problem
/// view; `None` when no view lies in one.
pub fn estimate_check(
    estimates: impl Fn(u32) -> Option<(f64, f64)>,
    views: impl Iterator<Item = (u32, f64, f64)>,
    t_max: f64,
) -> Option<EstimateCheck> {
    // Per problem view: (views, max time with impostors, max without).
    let mut per: BTreeMap<u32, (u32, f64, f64)> = BTreeMap::new();
    for (c, time, bare) in views {
        if c == u32::MAX || estimates(c).is_none() {
            continue;
        }
        let e = per
            .entry(c)
            .or_insert((0, f64::NEG_INFINITY, f64::NEG_INFINITY));
        e.0 += 1;
        e.1 = e.1.max(time);
        e.2 = e.2.max(bare);
    }
    if per.is_empty() {
        return None;
    }
    let mut points: Vec<EstimatePoint> = per
        .iter()
        .filter_map(|(&c, &(views, time, bare))| {
            let (original, after) = estimates(c)?;
            Some(EstimatePoint {
                cpv: c,
                views,
                estimate_ms: original,
                exact_max_ms: bare,
                estimate_final_ms: after,
                exact_final_max_ms: time,
            })
        })
        .collect();
    let median = |mut r: Vec<f64>| {
        r.sort_by(f64::total_cmp);
        r[(r.len() - 1) / 2]
    };
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { 0.0 };
    let ratio_original_median = median(
        points
            .iter()
            .map(|p| ratio(p.exact_max_ms, p.estimate_ms))
            .collect(),
    );
    let ratio_final_median = median(
        points
            .iter()
            .map(|p| ratio(p.exact_final_max_ms, p.estimate_final_ms))
            .collect(),
    );
    let over = |t: f64| t > t_max * (1.0 + 1e-12);
    let cpvs_never_over = points.iter().filter(|p| !over(p.exact_max_ms)).count() as u64;
    let cpvs_sampled = points.len() as u64;
    points.sort_by(|a, b| b.views.cmp(&a.views).then(a.cpv.cmp(&b.cpv)));
    points.truncate(MAX_POINTS);
    Some(EstimateCheck {
        cpvs_sampled,
        ratio_original_median,
        ratio_final_median,
        cpvs_never_over,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-computed: two problem views sampled (the third not), the
    /// largest sampled times per view, the median ratios and the view
    /// never over the target without impostors; views in none are left
    /// out, and the most sampled view comes first.
    #[test]
    fn ratios_and_never_over_by_hand() {
        let table = [(20.0, 9.0), (12.0, 10.0), (30.0, 8.0)];
        let p = |c: u32| table.get(c as usize).copied();
        let views = [
            (0, 8.0, 15.0),
            (0, 7.0, 18.0),
            (1, 6.0, 9.0),
            (u32::MAX, 50.0, 50.0),
        ];
        let e = estimate_check(p, views.into_iter(), 10.0).unwrap();
        assert_eq!(e.cpvs_sampled, 2);
        assert_eq!(e.cpvs_never_over, 1, "view 1 peaks at 9 ms < 10 ms");
        // Ratios without impostors: 18/20 = 0.9 and 9/12 = 0.75; the
        // lower median of two is the smaller.
        assert_eq!(e.ratio_original_median, 0.75);
        // With impostors: 8/9 and 6/10.
        assert_eq!(e.ratio_final_median, 0.6);
        assert_eq!(e.points[0].cpv, 0);
        assert_eq!(e.points[0].views, 2);
        assert_eq!(e.points[0].exact_max_ms, 18.0);
        assert_eq!(e.points[0].exact_final_max_ms, 8.0);
        assert_eq!(e.points[1].estimate_ms, 12.0);
        assert!(estimate_check(p, [(u32::MAX, 1.0, 1.0)].into_iter(), 10.0).is_none());
    }
}
