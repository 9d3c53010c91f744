//! The placement JSON of a selection: impostors with their view cells and
//! the problem views with their final times.

use std::collections::BTreeMap;

use crate::api::job::Job;
use crate::api::placement::{
    DirectionsJson, PlacedCpv, PlacedImpostor, Placement, RegionJson, SphereJson, Summary,
    UnsolvedReason, ViewCellJson,
};
use crate::candidates::Candidates;
use crate::greedy::Selection;
use crate::model::cost::Cost;
use crate::views::{Context, ProblemViews};

/// Turns the selection into the placement JSON structure.
pub fn build_placement(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    sel: &Selection,
) -> Placement {
    let h = ctx.hierarchy;
    let chosen = sel.impostors();
    let mut new_id = vec![u32::MAX; cands.list.len()];
    let impostors: Vec<PlacedImpostor> = chosen
        .iter()
        .enumerate()
        .map(|(k, &i)| {
            new_id[i as usize] = k as u32;
            let c = &cands.list[i as usize];
            let node = &h.nodes[c.node as usize];
            let mut objects = h.objects(c.node).to_vec();
            objects.sort_unstable();
            let cell = c.cell(h, pv);
            let view_cell = ViewCellJson::from(&cell);
            let d = cell.closest_distance(node.sphere.center);
            let cost = ctx.model.impostor(c.spec.layers, node.sphere.radius, d);
            PlacedImpostor {
                id: k as u32,
                node: c.node,
                objects,
                sphere: SphereJson {
                    center: node.sphere.center.to_array(),
                    radius: node.sphere.radius,
                },
                view_cell,
                layers: c.spec.layers,
                resolution: c.spec.resolution,
                memory_bytes: c.spec.memory_bytes,
                time_ms: cost.cpu + cost.gpu,
            }
        })
        .collect();
    let cpv_impostors: Vec<Vec<u32>> = sel
        .cpv_impostors
        .iter()
        .map(|imps| imps.iter().map(|&i| new_id[i as usize]).collect())
        .collect();
    assemble(
        ctx,
        job,
        pv,
        impostors,
        cpv_impostors,
        &sel.cpv_cost,
        &sel.reasons,
        cands.list.len() as u64,
    )
}

/// The placement JSON of `impostors` (ids are indices) used by the CPVs as
/// `cpv_impostors` says, with the CPVs' final costs and, where the method
/// explains them, why unsolved CPVs are (`reasons`, per CPV, or empty).
#[allow(clippy::too_many_arguments)]
pub fn assemble(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    impostors: Vec<PlacedImpostor>,
    cpv_impostors: Vec<Vec<u32>>,
    cpv_cost: &[Cost],
    reasons: &[Option<UnsolvedReason>],
    candidates: u64,
) -> Placement {
    let mut unsolved = 0u64;
    let mut max_residual_ms = 0.0f64;
    let mut unsolved_by_reason = BTreeMap::new();
    let cpvs: Vec<PlacedCpv> = pv
        .cpvs
        .iter()
        .zip(cpv_impostors)
        .enumerate()
        .map(|(ci, (c, mut imps))| {
            imps.sort_unstable();
            let final_ms = ctx.model.frame_time(cpv_cost[ci]);
            let solved = final_ms <= job.target_frame_time_ms;
            let reason = if solved {
                None
            } else {
                unsolved += 1;
                max_residual_ms = max_residual_ms.max(final_ms - job.target_frame_time_ms);
                reasons.get(ci).copied().flatten()
            };
            if let Some(r) = reason {
                *unsolved_by_reason.entry(r).or_insert(0u64) += 1;
            }
            PlacedCpv {
                id: ci as u32,
                region: RegionJson {
                    min: c.region.min.to_array(),
                    max: c.region.max.to_array(),
                },
                directions: DirectionsJson {
                    face: c.vdi.face,
                    u: c.vdi.u_range(),
                    v: c.vdi.v_range(),
                },
                time_ms_original: c.time,
                time_ms_final: final_ms,
                solved,
                unsolved_reason: reason,
                impostors: imps,
            }
        })
        .collect();
    Placement {
        summary: Summary {
            cpvs: cpvs.len() as u64,
            candidates,
            impostors: impostors.len() as u64,
            memory_bytes: impostors.iter().map(|i| i.memory_bytes).sum(),
            unsolved_cpvs: unsolved,
            target_frame_time_ms: job.target_frame_time_ms,
            max_residual_ms,
            unsolved_by_reason,
            budget_bytes: job.memory.budget_bytes,
        },
        impostors,
        cpvs,
    }
}
