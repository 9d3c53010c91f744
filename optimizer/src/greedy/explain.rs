//! Why CPVs are left above `t_max` when the greedy ends.

use rayon::prelude::*;

use super::State;
use super::marks::Mark;
use crate::api::job::Job;
use crate::api::placement::UnsolvedReason;
use crate::candidates::{Outlook, outlook};
use crate::model::impostor::ImpostorModel;

impl State<'_> {
    /// Per CPV, why it is still above `t_max` (`None` when solved; an
    /// empty list when every CPV is). When the greedy ends, no candidate
    /// within the budget gains anything, so:
    ///
    /// - a CPV that some candidate left out by the budget would still make
    ///   faster is [`UnsolvedReason::BudgetExhausted`];
    /// - any other is judged by what it still draws as geometry: each leaf
    ///   cluster not represented by an impostor there weighs its time in
    ///   the CPV, under the [`Outlook`] of the smallest view cell the
    ///   generator would build for it from the CPV's cell (too close for
    ///   any; none within `max_error_px`; an impostor exists but was not
    ///   faster). The heaviest outlook names the reason; a CPV that draws
    ///   no geometry, or whose geometry could all have impostors, is
    ///   [`UnsolvedReason::ImpostorsNotFaster`].
    ///
    /// Only cells with unsolved CPVs are visited; the result does not
    /// depend on the thread count.
    pub(super) fn explain_unsolved(&self, job: &Job) -> Vec<Option<UnsolvedReason>> {
        if self.unsolved() == 0 {
            return Vec::new();
        }
        let n = self.pv.cpvs.len();
        let all = self.all;
        let mut reasons: Vec<Option<UnsolvedReason>> = vec![None; n];
        if self.budget.is_some() {
            let blocked: Vec<Vec<u32>> = (0..self.cands.len() as u32)
                .into_par_iter()
                .filter(|&i| !self.fits(i))
                .map(|i| {
                    let mut out = Vec::new();
                    self.for_each_unsolved_effect(i, |c, e| {
                        if e.accelerates && self.is_unsolved(c) {
                            out.push(c);
                        }
                    });
                    out
                })
                .collect();
            for c in blocked.into_iter().flatten() {
                reasons[c as usize] = Some(UnsolvedReason::BudgetExhausted);
            }
        }
        // Per unsolved CPV not explained by the budget: the time of the
        // geometry it draws, by outlook.
        let h = self.ctx.hierarchy;
        let imodel = ImpostorModel::new(job);
        let leaves: Vec<u32> = (0..h.nodes.len() as u32)
            .filter(|&l| h.nodes[l as usize].children.is_none())
            .collect();
        let weighed: Vec<Vec<(u32, usize, f64)>> = leaves
            .par_iter()
            .map(|&l| {
                let sphere = h.nodes[l as usize].sphere;
                let mut out = Vec::new();
                for g in all.pairs.groups_of(l).indices() {
                    let gr = &all.pairs.group(g as u32);
                    if self.unsolved_in_cell[gr.kd as usize] == 0 {
                        continue;
                    }
                    let mut seen: Option<Outlook> = None;
                    for (c, orig) in all.pairs.iter(gr) {
                        if !self.is_unsolved(c)
                            || reasons[c as usize].is_some()
                            || matches!(self.marks.get(c, l), Mark::Covered)
                        {
                            continue;
                        }
                        let o = *seen.get_or_insert_with(|| {
                            let region = self.pv.cpvs[c as usize].region;
                            outlook(
                                job,
                                &imodel,
                                &sphere,
                                &region,
                                all.pairs.dist(gr, sphere.center),
                            )
                        });
                        out.push((c, o as usize, orig.cpu + orig.gpu));
                    }
                }
                out
            })
            .collect();
        let mut weight = vec![[0.0f64; 3]; n];
        for (c, k, t) in weighed.into_iter().flatten() {
            weight[c as usize][k] += t;
        }
        for c in 0..n as u32 {
            if !self.is_unsolved(c) || reasons[c as usize].is_some() {
                continue;
            }
            let w = weight[c as usize];
            let heaviest = (0..3).fold(0, |b, k| if w[k] > w[b] { k } else { b });
            reasons[c as usize] = Some(match heaviest {
                0 if w[0] > 0.0 => UnsolvedReason::ClusterContainsRegion,
                1 => UnsolvedReason::NoCandidateMeetsMaxErrorPx,
                _ => UnsolvedReason::ImpostorsNotFaster,
            });
        }
        reasons
    }
}
