//! Impostors that help only CPVs left above the target.

use super::Selection;
use crate::api::job::Job;
use crate::candidates::Candidates;
use crate::views::{Context, ProblemViews};

/// Drops every impostor all of whose CPVs stay above `t_max`: it makes
/// those views faster without bringing any of them within the target.
/// Where most problem views cannot be solved (display resolutions, where
/// an impostor's texels and fill grow with the pixels and the geometry's
/// cost does not) such impostors take most of the memory. Each CPV that
/// used a dropped impostor draws its cluster's objects as geometry again
/// (its cost rises by what the impostor saved there); an impostor also
/// used by a CPV within the target stays everywhere it is used (it costs
/// no memory more), so no CPV within the target changes. Returns how many
/// impostors were dropped (`sel.partial_dropped` counts them as well).
pub fn drop_partial(
    ctx: &Context,
    pv: &ProblemViews,
    cands: &Candidates,
    sel: &mut Selection,
) -> u64 {
    let solved: Vec<bool> = sel
        .cpv_cost
        .iter()
        .map(|&c| ctx.model.frame_time(c) <= ctx.t_max)
        .collect();
    let mut keep = vec![false; cands.list.len()];
    for (c, list) in sel.cpv_impostors.iter().enumerate() {
        if solved[c] {
            for &i in list {
                keep[i as usize] = true;
            }
        }
    }
    let mut dropped = 0;
    for (c, list) in sel.cpv_impostors.iter_mut().enumerate() {
        if solved[c] {
            continue;
        }
        let cpv = &pv.cpvs[c];
        let mut cost = sel.cpv_cost[c];
        list.retain(|&i| {
            if keep[i as usize] {
                return true;
            }
            let cand = &cands.list[i as usize];
            // A pair without a stored cost cannot be restored: the impostor
            // stays there (no pair of a placed impostor lacks one).
            let Some(orig) = cands.pairs.cost_of(cand.node, c as u32) else {
                return true;
            };
            cost = cost - super::impostor_cost(ctx, cand, cpv) + orig;
            let uses = &mut sel.uses[i as usize];
            *uses -= 1;
            if *uses == 0 {
                dropped += 1;
            }
            false
        });
        sel.cpv_cost[c] = cost;
    }
    sel.partial_dropped += dropped;
    dropped
}

/// The greedy selection again with the CPVs `first` left above `t_max`
/// given up: where the first selection spent memory on partial gains in
/// CPVs it could not solve, this one spends it only on the others (the
/// given-up CPVs still use every impostor chosen that makes them faster).
/// Made only where more than 1 % of the CPVs are left above `t_max` (a
/// second greedy costs as much as the first; below, [`drop_partial`]
/// alone removes what solves nothing).
/// Each given-up CPV keeps its reason from `first`; a CPV the second
/// selection leaves above `t_max` gets its own. The counters add up both
/// selections'.
pub fn reselect_solvable(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    first: Selection,
    progress: &mut dyn FnMut(u64) -> bool,
) -> Selection {
    let unsolved = first.reasons.iter().filter(|r| r.is_some()).count();
    if unsolved * 100 <= pv.cpvs.len() {
        return first;
    }
    let mut given_up = vec![0u64; pv.cpvs.len().div_ceil(64)];
    for (c, r) in first.reasons.iter().enumerate() {
        if r.is_some() {
            given_up[c / 64] |= 1 << (c % 64);
        }
    }
    let mut sel = super::select_lazy_giving_up(ctx, job, pv, cands, &given_up, progress);
    let mut reasons = std::mem::take(&mut sel.reasons);
    reasons.resize(pv.cpvs.len(), None);
    for (r, f) in reasons.iter_mut().zip(first.reasons) {
        if f.is_some() {
            *r = f;
        }
    }
    sel.reasons = reasons;
    sel.accepted += first.accepted;
    sel.evaluations += first.evaluations;
    sel.bounds += first.bounds;
    sel
}
