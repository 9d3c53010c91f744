//! The exact optimum of the greedy's problem, as an integer program.
//!
//! Choose candidates so that every CPV meets the target, minimising the
//! impostors' memory: binary `x_i` (candidate `i` is an impostor) and uses
//! `y_ic` (it represents its cluster in CPV `c`; fractional where times add
//! up, binary where they must be, see [`solve`]), with
//!
//! - `y_ic ≤ x_i`;
//! - per CPV, at most one impostor on any chain of the hierarchy (an
//!   impostor of a cluster replaces its descendants' there, as in the
//!   greedy): for each cluster with a candidate in `c` and none below it,
//!   the `y` of its own candidates and its ancestors' sum to at most 1;
//! - per CPV, the time saved reaches its excess: `Σ_i y_ic·s_ic ≥
//!   t(cost_c) − limit_c`, `s_ic` the time the impostor saves against the
//!   cluster's objects there (the greedy's saving). Where the cost model takes
//!   the larger of CPU and GPU time (`combine: max`), each of the two has its
//!   own constraint. Times add over an antichain of clusters, so the
//!   program is exact for the cost model the greedy uses;
//! - within `memory.budget_bytes`, when the job has one;
//!
//! and the objective `Σ_i m_i·x_i`. A CPV the greedy leaves above the
//! target is held to the time the greedy reached there (`limit_c`), so the
//! greedy's selection is always feasible: it seeds the search, and the
//! optimum never uses more memory than it. Pairs whose impostor saves
//! nothing are left out (using them never helps).
//!
//! The program is solved with `microlp` (pure Rust branch and bound):
//! deterministically within `exact.max_nodes` branch-and-bound nodes, and
//! within `exact.max_seconds` (a limit of wall time, so a run stopped by it
//! depends on the machine); either stop keeps the best selection found and
//! reports the best proven lower bound.

use std::time::{Duration, Instant};

use microlp::{ComparisonOp, OptimizationDirection, Problem, SolveOptions, TerminationReason};

use crate::api::job::{Combine, Job};
use crate::api::stats::ExactStats;
use crate::candidates::Candidates;
use crate::error::{Error, Result};
use crate::greedy::Selection;
use crate::model::cost::Cost;
use crate::views::{Context, ProblemViews};

/// One `y_ic`: candidate `cand` represents its cluster in CPV `cpv`,
/// saving `saving` against the cluster's objects there.
#[derive(Clone, Copy, Debug)]
pub struct Use {
    /// The candidate id.
    pub cand: u32,
    /// The CPV id.
    pub cpv: u32,
    /// What the impostor saves against the cluster's objects there.
    pub saving: Cost,
}

/// The integer program's data, before it is handed to the solver.
#[derive(Clone, Debug, Default)]
pub struct Instance {
    /// Candidate ids with at least one useful pair, ascending.
    pub cands: Vec<u32>,
    /// The useful pairs, by CPV then candidate id.
    pub uses: Vec<Use>,
    /// Per CPV: the frame time it must reach (`t_max`, or the greedy's
    /// time where the greedy stayed above it; `+∞` for a CPV within the
    /// target without impostors).
    pub limit: Vec<f64>,
    /// Per CPV: `uses[cpv_uses[c]..cpv_uses[c + 1]]` are its pairs.
    pub cpv_uses: Vec<u32>,
    /// The candidates left out as dominated, each with the one that
    /// dominates it, by the first's id.
    pub dominated: Vec<(u32, u32)>,
}

impl Instance {
    /// The instance of `pv` and `cands`, restricted to the candidates
    /// `allowed` says yes to, with the limits `limit`. A candidate is left
    /// out when another of its cluster dominates it: no more memory, no
    /// more layers (so it saves at least as much in every CPV: the same
    /// cluster, the same cells' distances) and every CPV it is useful in.
    /// Any selection using it does as well with the other instead.
    pub fn build(
        ctx: &Context,
        pv: &ProblemViews,
        cands: &Candidates,
        limit: Vec<f64>,
        allowed: impl Fn(u32) -> bool,
    ) -> Instance {
        let m = &ctx.model;
        let h = ctx.hierarchy;
        // Per candidate: its useful pairs, CPV ids ascending.
        let mut own: Vec<(u32, Vec<(u32, Cost)>)> = Vec::new();
        for (i, cand) in cands.list.iter().enumerate() {
            let i = i as u32;
            if !allowed(i) {
                continue;
            }
            let s = h.nodes[cand.node as usize].sphere;
            let r = s.radius;
            let mut list = Vec::new();
            for g in cands.groups_served(i) {
                let gr = &cands.pairs.group(g);
                let imp = m.impostor(cand.spec.layers, r, cands.pairs.dist(gr, s.center));
                for (c, orig) in cands.pairs.iter(gr) {
                    if !limit[c as usize].is_finite() {
                        continue;
                    }
                    let saving = orig - imp;
                    let useful = match m.time_saved(saving) {
                        Some(t) => t > 0.0,
                        None => saving.cpu > 0.0 || saving.gpu > 0.0,
                    };
                    if useful {
                        list.push((c, saving));
                    }
                }
            }
            if !list.is_empty() {
                list.sort_unstable_by_key(|x| x.0);
                own.push((i, list));
            }
        }
        // Dominance within each cluster (candidates are ordered by cluster).
        let spec = |i: u32| {
            let c = &cands.list[i as usize];
            (c.spec.memory_bytes, c.spec.layers)
        };
        let mut keep = vec![true; own.len()];
        let mut dominated = Vec::new();
        let mut a = 0;
        while a < own.len() {
            let node = cands.list[own[a].0 as usize].node;
            let b = a + own[a..]
                .iter()
                .take_while(|o| cands.list[o.0 as usize].node == node)
                .count();
            // Cheapest first, then fewest layers, then most CPVs, then id:
            // a dominating candidate comes before those it dominates.
            let mut order: Vec<usize> = (a..b).collect();
            order.sort_by_key(|&k| {
                let (mem, layers) = spec(own[k].0);
                (mem, layers, std::cmp::Reverse(own[k].1.len()), own[k].0)
            });
            let mut kept: Vec<usize> = Vec::new();
            for k in order {
                let (mem, layers) = spec(own[k].0);
                let by = kept.iter().find(|&&j| {
                    let (mj, lj) = spec(own[j].0);
                    mj <= mem && lj <= layers && covers(&own[j].1, &own[k].1)
                });
                match by {
                    Some(&j) => {
                        keep[k] = false;
                        dominated.push((own[k].0, own[j].0));
                    }
                    None => kept.push(k),
                }
            }
            a = b;
        }
        let mut uses: Vec<Use> = own
            .iter()
            .zip(&keep)
            .filter(|x| *x.1)
            .flat_map(|((i, list), _)| {
                list.iter().map(|&(cpv, saving)| Use {
                    cand: *i,
                    cpv,
                    saving,
                })
            })
            .collect();
        uses.sort_unstable_by_key(|u| (u.cpv, u.cand));
        let cands_used: Vec<u32> = own
            .iter()
            .zip(&keep)
            .filter(|x| *x.1)
            .map(|x| x.0.0)
            .collect();
        let mut cpv_uses = vec![0u32; pv.cpvs.len() + 1];
        for u in &uses {
            cpv_uses[u.cpv as usize + 1] += 1;
        }
        for c in 0..pv.cpvs.len() {
            cpv_uses[c + 1] += cpv_uses[c];
        }
        dominated.sort_unstable();
        Instance {
            cands: cands_used,
            uses,
            limit,
            cpv_uses,
            dominated,
        }
    }

    /// The candidate that stands for `i` in the program: itself, or the
    /// one that dominates it.
    pub fn standing_for(&self, i: u32) -> u32 {
        match self.dominated.binary_search_by_key(&i, |d| d.0) {
            Ok(k) => self.dominated[k].1,
            Err(_) => i,
        }
    }

    /// The pairs of CPV `c`.
    pub fn of_cpv(&self, c: usize) -> &[Use] {
        &self.uses[self.cpv_uses[c] as usize..self.cpv_uses[c + 1] as usize]
    }

    /// Per CPV, the chains of the hierarchy through its pairs, as index
    /// lists into [`of_cpv`](Self::of_cpv) (only chains of two or more).
    pub fn chains(&self, ctx: &Context, c: usize, cands: &Candidates) -> Vec<Vec<usize>> {
        let h = ctx.hierarchy;
        let here = self.of_cpv(c);
        let node = |k: usize| cands.list[here[k].cand as usize].node;
        let mut nodes: Vec<u32> = (0..here.len()).map(node).collect();
        nodes.sort_unstable();
        nodes.dedup();
        // A node whose subtree holds no other listed node is minimal.
        let minimal = nodes.iter().enumerate().filter(|&(k, &n)| {
            let end = h.nodes[n as usize].subtree_end;
            nodes.get(k + 1).is_none_or(|&next| next >= end)
        });
        let mut out = Vec::new();
        for (_, &lo) in minimal {
            let chain: Vec<usize> = (0..here.len())
                .filter(|&k| {
                    let a = node(k);
                    a <= lo && lo < h.nodes[a as usize].subtree_end
                })
                .collect();
            if chain.len() > 1 {
                out.push(chain);
            }
        }
        out
    }

    /// The antichain of CPV `c`'s pairs whose candidates `on` accepts that
    /// saves the most (`value` of each pair's saving), as indices into
    /// [`of_cpv`](Self::of_cpv): per cluster, the better of its own best
    /// pair and the best of the clusters below it, from the leaves up.
    pub fn best_antichain(
        &self,
        ctx: &Context,
        c: usize,
        cands: &Candidates,
        on: impl Fn(u32) -> bool,
        value: impl Fn(Cost) -> f64,
    ) -> Vec<usize> {
        let h = ctx.hierarchy;
        let here = self.of_cpv(c);
        // Per listed cluster (pre-order): its best own pair.
        let mut nodes: Vec<(u32, usize, f64)> = Vec::new();
        for (k, u) in here.iter().enumerate() {
            if !on(u.cand) {
                continue;
            }
            let n = cands.list[u.cand as usize].node;
            let v = value(u.saving);
            match nodes.iter_mut().find(|e| e.0 == n) {
                Some(e) if v > e.2 => *e = (n, k, v),
                Some(_) => {}
                None => nodes.push((n, k, v)),
            }
        }
        nodes.sort_unstable_by_key(|e| e.0);
        // From the last in pre-order back: the best below each cluster is
        // the sum over the listed clusters directly below it.
        let len = nodes.len();
        let mut best = vec![0.0f64; len];
        let mut own = vec![false; len];
        let below = |a: usize| {
            let end = h.nodes[nodes[a].0 as usize].subtree_end;
            let mut out = Vec::new();
            let mut b = a + 1;
            while b < len && nodes[b].0 < end {
                out.push(b);
                let skip = h.nodes[nodes[b].0 as usize].subtree_end;
                while b < len && nodes[b].0 < skip {
                    b += 1;
                }
            }
            out
        };
        for a in (0..len).rev() {
            let sub: f64 = below(a).iter().map(|&b| best[b]).sum();
            own[a] = nodes[a].2 >= sub;
            best[a] = nodes[a].2.max(sub);
        }
        // Take the top-level clusters, then descend where a cluster's own
        // pair is not the better.
        let mut out = Vec::new();
        let mut stack: Vec<usize> = Vec::new();
        let mut a = 0;
        while a < len {
            stack.push(a);
            let skip = h.nodes[nodes[a].0 as usize].subtree_end;
            while a < len && nodes[a].0 < skip {
                a += 1;
            }
        }
        while let Some(a) = stack.pop() {
            if own[a] {
                out.push(nodes[a].1);
            } else {
                stack.extend(below(a));
            }
        }
        out.sort_unstable();
        out
    }

    /// The cost CPV `c` has with the pairs `chosen` (indices into
    /// [`of_cpv`](Self::of_cpv)) used, from its cost without impostors.
    pub fn cost_with(&self, pv: &ProblemViews, c: usize, chosen: &[usize]) -> Cost {
        let here = self.of_cpv(c);
        let mut cost = pv.cpvs[c].cost;
        for &k in chosen {
            cost = cost - here[k].saving;
        }
        cost
    }
}

/// True when every CPV of `small` is in `big` (both ascending).
fn covers(big: &[(u32, Cost)], small: &[(u32, Cost)]) -> bool {
    if small.len() > big.len() {
        return false;
    }
    let mut it = big.iter().map(|x| x.0);
    small.iter().all(|&(c, _)| it.any(|b| b == c))
}

/// How many times `exact.max_variables` the pairs listed before dominance
/// may be (pairs that save nothing and dominated candidates are most of
/// them: a program of the limit's size is never refused by this).
const EARLY_REFUSAL: u64 = 20;

/// What a refusal for size tells the user.
const SMALL_ONLY: &str = "the exact method is for small instances (raise exact.max_variables, \
                          or use a smaller view space or a looser target)";

/// How the program ended.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Per pair of the instance: used.
    pub used: Vec<bool>,
    /// The program's size, how the solver ended, the two memories.
    pub stats: ExactStats,
}

/// Rounding slack of the time constraints, ms: the solver's answer must
/// meet each limit by this much, so that the costs summed again in the
/// greedy's arithmetic stay within it.
const SLACK_MS: f64 = 1e-9;

/// The program of `inst`, its `x` (per listed candidate) and `y` (per
/// pair) variables and its number of constraints; `y` is binary in the
/// CPVs `whole` marks, fractional elsewhere (see [`solve`]).
struct Program {
    prob: Problem,
    x: Vec<microlp::Variable>,
    y: Vec<microlp::Variable>,
    constraints: u64,
}

impl Program {
    fn new(
        ctx: &Context,
        job: &Job,
        pv: &ProblemViews,
        cands: &Candidates,
        inst: &Instance,
        whole: &[bool],
    ) -> Program {
        let m = &ctx.model;
        let mut prob = Problem::new(OptimizationDirection::Minimize);
        let mb = |i: u32| cands.list[i as usize].spec.memory_bytes as f64 / 1e6;
        let x: Vec<microlp::Variable> = inst
            .cands
            .iter()
            .map(|&i| prob.add_binary_var(mb(i)))
            .collect();
        let y: Vec<microlp::Variable> = inst
            .uses
            .iter()
            .map(|u| {
                if whole[u.cpv as usize] {
                    prob.add_binary_var(0.0)
                } else {
                    prob.add_var(0.0, (0.0, 1.0))
                }
            })
            .collect();
        let mut constraints = 0u64;
        for (k, u) in inst.uses.iter().enumerate() {
            let xi = x[inst.cands.binary_search(&u.cand).expect("listed")];
            prob.add_constraint([(y[k], 1.0), (xi, -1.0)], ComparisonOp::Le, 0.0);
            constraints += 1;
        }
        for c in 0..pv.cpvs.len() {
            let here = inst.of_cpv(c);
            if here.is_empty() {
                continue;
            }
            let base = inst.cpv_uses[c] as usize;
            for chain in inst.chains(ctx, c, cands) {
                let terms: Vec<_> = chain.iter().map(|&k| (y[base + k], 1.0)).collect();
                prob.add_constraint(terms.as_slice(), ComparisonOp::Le, 1.0);
                constraints += 1;
            }
            for (need, part) in time_parts(ctx, job, inst, pv, c) {
                let terms: Vec<_> = here
                    .iter()
                    .enumerate()
                    .map(|(k, u)| (y[base + k], part(m, u.saving)))
                    .filter(|t| t.1 != 0.0)
                    .collect();
                if need <= 0.0 && terms.iter().all(|t| t.1 >= 0.0) {
                    continue;
                }
                prob.add_constraint(terms.as_slice(), ComparisonOp::Ge, need);
                constraints += 1;
            }
        }
        if let Some(b) = job.memory.budget_bytes {
            let terms: Vec<_> = inst
                .cands
                .iter()
                .zip(&x)
                .map(|(&i, &v)| (v, mb(i)))
                .collect();
            prob.add_constraint(terms.as_slice(), ComparisonOp::Le, b as f64 / 1e6);
            constraints += 1;
        }
        Program {
            prob,
            x,
            y,
            constraints,
        }
    }
}

/// A part of a frame time that a CPV's savings must lower.
type Part = fn(&crate::model::cost::CostModel, Cost) -> f64;

/// CPV `c`'s time constraints: per part of the frame time (the sum where
/// times add up; CPU and GPU where the larger counts), how much its pairs
/// must save of it and what each saving counts.
fn time_parts(
    ctx: &Context,
    job: &Job,
    inst: &Instance,
    pv: &ProblemViews,
    c: usize,
) -> Vec<(f64, Part)> {
    let m = &ctx.model;
    let cost = pv.cpvs[c].cost;
    let limit = inst.limit[c] - SLACK_MS;
    match job.cost_model.combine {
        Combine::Sum | Combine::Primitives => vec![(m.frame_time(cost) - limit, |m, s| {
            m.time_saved(s).unwrap_or(0.0)
        })],
        Combine::Max => {
            let room = limit - m.frame_time(Cost::default());
            vec![
                (cost.cpu - room, |_, s| s.cpu),
                (cost.gpu - room, |_, s| s.gpu),
            ]
        }
    }
}

/// Solves `inst` with `seed` (per pair: used by the greedy) as the first
/// incumbent. The stats' greedy figures are left to the caller.
///
/// The uses `y` start fractional: branching is on the candidates `x` alone.
/// Where times add up that is exact: with `x` fixed, a CPV's chain
/// constraints form an interval matrix (a chain per minimal cluster, each
/// cluster's chains consecutive in pre-order), totally unimodular, so the
/// most a CPV can save is reached by whole uses, and a fractional answer to
/// its one time constraint means a whole one exists, which
/// [`Instance::best_antichain`] finds. With two constraints per CPV
/// (`combine: max`) that can fail: a CPV whose whole uses miss its limit
/// gets binary uses and the program is solved again, until every CPV's
/// uses are whole. A relaxation's optimum is a lower bound, so the last
/// round's selection is the optimum.
pub fn solve(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    inst: &Instance,
    seed: &[bool],
) -> Result<Outcome> {
    let p = &job.exact;
    let m = &ctx.model;
    let variables = (inst.cands.len() + inst.uses.len()) as u64;
    if variables > p.max_variables {
        return Err(Error::bad(
            "exact.max_variables",
            format!(
                "the exact program has {variables} variables ({} candidates, {} (candidate, CPV) \
                 pairs), more than {}; {SMALL_ONLY}",
                inst.cands.len(),
                inst.uses.len(),
                p.max_variables
            ),
        ));
    }
    let start = Instant::now();
    let mut whole = vec![false; pv.cpvs.len()];
    let mut nodes = 0u64;
    loop {
        let prog = Program::new(ctx, job, pv, cands, inst, &whole);
        let mut chosen = vec![false; prog.x.len()];
        let mut warm: Vec<(microlp::Variable, f64)> = Vec::new();
        for (k, u) in inst.uses.iter().enumerate() {
            warm.push((prog.y[k], f64::from(u8::from(seed[k]))));
            if seed[k] {
                chosen[inst.cands.binary_search(&u.cand).expect("listed")] = true;
            }
        }
        warm.extend(
            prog.x
                .iter()
                .zip(&chosen)
                .map(|(&v, &c)| (v, f64::from(u8::from(c)))),
        );
        let left = Duration::from_secs_f64(p.max_seconds).saturating_sub(start.elapsed());
        let mut opts = SolveOptions::default();
        opts.time_limit = Some(left.max(Duration::from_millis(1)));
        opts.node_limit = Some(p.max_nodes.saturating_sub(nodes).max(1));
        opts.warm_start = Some(warm);
        let outcome = prog
            .prob
            .solve_with(opts)
            .map_err(|e| Error::Internal(format!("the exact program's solver failed: {e}")))?;
        let stats = outcome.stats();
        nodes += stats.nodes_solved;
        let status = match outcome.termination_reason() {
            TerminationReason::ProvenOptimal => "optimal",
            TerminationReason::NodeLimit => "node_limit",
            TerminationReason::TimeLimit => "time_limit",
            TerminationReason::MipGap => "gap_limit",
            _ => "stopped",
        };
        let finish = |used: Vec<bool>, status: &str| {
            let to_bytes = |v: f64| (v * 1e6).round().max(0.0) as u64;
            Outcome {
                used,
                stats: ExactStats {
                    status: status.to_string(),
                    variables,
                    constraints: prog.constraints,
                    nodes,
                    seconds: start.elapsed().as_secs_f64(),
                    lower_bound_bytes: stats.best_bound.map(to_bytes),
                    ..ExactStats::default()
                },
            }
        };
        let Some(sol) = outcome.solution() else {
            // Stopped before any incumbent (the greedy's was not accepted):
            // the greedy's selection stands.
            return Ok(finish(seed.to_vec(), status));
        };
        let on: Vec<bool> = prog.x.iter().map(|&v| sol.var_value(v) > 0.5).collect();
        let is_on = |i: u32| on[inst.cands.binary_search(&i).expect("listed")];
        let mut used = vec![false; inst.uses.len()];
        let mut missed = false;
        for (c, whole_c) in whole.iter_mut().enumerate() {
            let base = inst.cpv_uses[c] as usize;
            let n = inst.of_cpv(c).len();
            let picked: Vec<usize> = if *whole_c {
                (0..n)
                    .filter(|&k| sol.var_value(prog.y[base + k]) > 0.5)
                    .collect()
            } else {
                let best = inst.best_antichain(ctx, c, cands, is_on, |s| s.cpu + s.gpu);
                let meets = time_parts(ctx, job, inst, pv, c)
                    .iter()
                    .all(|(need, part)| {
                        let saved: f64 = best
                            .iter()
                            .map(|&k| part(m, inst.of_cpv(c)[k].saving))
                            .sum();
                        saved >= need - 1e-9 * (1.0 + need.abs())
                    });
                if !meets && n > 0 {
                    *whole_c = true;
                    missed = true;
                }
                best
            };
            for k in picked {
                used[base + k] = true;
            }
        }
        if !missed {
            return Ok(finish(used, status));
        }
        if status != "optimal" {
            // Stopped with CPVs whose whole uses miss their limits: the
            // greedy's selection stands.
            return Ok(finish(seed.to_vec(), status));
        }
    }
}

/// The exact method: the greedy's selection `greedy` (for the same
/// candidates) seeds the program, whose optimum replaces it.
pub fn select(
    ctx: &Context,
    job: &Job,
    pv: &ProblemViews,
    cands: &Candidates,
    greedy: &Selection,
) -> Result<(Selection, ExactStats)> {
    let m = &ctx.model;
    let limit: Vec<f64> = pv
        .cpvs
        .iter()
        .enumerate()
        .map(|(c, cpv)| {
            if cpv.time <= ctx.t_max {
                f64::INFINITY
            } else {
                ctx.t_max.max(m.frame_time(greedy.cpv_cost[c]))
            }
        })
        .collect();
    // The pairs before dominance bound the program's size: far above the
    // limit, it is refused before the pairs are listed.
    let listed: u64 = (0..cands.list.len() as u32)
        .flat_map(|i| cands.groups_served(i))
        .map(|g| u64::from(cands.pairs.group(g).len(&cands.pairs)))
        .sum();
    let cap = job.exact.max_variables;
    if listed > cap.saturating_mul(EARLY_REFUSAL) {
        return Err(Error::bad(
            "exact.max_variables",
            format!(
                "the exact program would list {listed} (candidate, CPV) pairs before removing \
                 dominated candidates, more than {EARLY_REFUSAL} × {cap}; {SMALL_ONLY}"
            ),
        ));
    }
    let inst = Instance::build(ctx, pv, cands, limit, |_| true);
    // The greedy's selection, each impostor by the candidate standing for
    // it.
    let seed: Vec<bool> = inst
        .uses
        .iter()
        .map(|u| {
            greedy.cpv_impostors[u.cpv as usize]
                .iter()
                .any(|&i| inst.standing_for(i) == u.cand)
        })
        .collect();
    let mut out = solve(ctx, job, pv, cands, &inst, &seed)?;
    let mut sel = Selection::empty(&pv.cpvs, cands.list.len());
    for c in 0..pv.cpvs.len() {
        let base = inst.cpv_uses[c] as usize;
        let chosen: Vec<usize> = (0..inst.of_cpv(c).len())
            .filter(|&k| out.used[base + k])
            .collect();
        for &k in &chosen {
            let i = inst.uses[base + k].cand;
            sel.cpv_impostors[c].push(i);
            sel.uses[i as usize] += 1;
        }
        sel.cpv_cost[c] = inst.cost_with(pv, c, &chosen);
    }
    sel.accepted = sel.uses.iter().filter(|&&u| u > 0).count() as u64;
    let exact_bytes = sel.memory_bytes(&cands.list);
    let greedy_bytes = greedy.memory_bytes(&cands.list);
    out.stats.memory_bytes = exact_bytes;
    out.stats.greedy_memory_bytes = greedy_bytes;
    out.stats.greedy_over_exact = if exact_bytes > 0 {
        greedy_bytes as f64 / exact_bytes as f64
    } else {
        1.0
    };
    // A CPV left above the target is held to the greedy's time there: the
    // greedy's reason stands.
    if !greedy.reasons.is_empty() {
        sel.reasons = (0..pv.cpvs.len())
            .map(|c| {
                (m.frame_time(sel.cpv_cost[c]) > ctx.t_max)
                    .then(|| greedy.reasons[c])
                    .flatten()
            })
            .collect();
    }
    Ok((sel, out.stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::job::Combine;
    use crate::control::Control;
    use crate::math::rng::Rng;
    use crate::scene::hierarchy::Hierarchy;
    use crate::testutil::{synthetic_city, synthetic_job_combined};
    use crate::views::{self, Counters};

    /// True when the pairs `chosen` of CPV `c` (indices into `of_cpv`)
    /// are an antichain of clusters and bring it within its limit less
    /// `slack`.
    fn within(
        ctx: &Context,
        pv: &ProblemViews,
        cands: &Candidates,
        inst: &Instance,
        c: usize,
        chosen: &[usize],
        slack: f64,
    ) -> bool {
        let h = ctx.hierarchy;
        let here = inst.of_cpv(c);
        let node = |k: usize| cands.list[here[k].cand as usize].node;
        let antichain = chosen.iter().all(|&a| {
            chosen.iter().all(|&b| {
                a == b || {
                    let (na, nb) = (node(a), node(b));
                    na != nb && !h.is_descendant(na, nb) && !h.is_descendant(nb, na)
                }
            })
        });
        let cost = inst.cost_with(pv, c, chosen);
        antichain && ctx.model.frame_time(cost) <= inst.limit[c] - slack
    }

    /// Per CPV, every subset of its pairs (bit `k`: pair `k` of
    /// `of_cpv(c)`) that is an antichain and meets its limit, as a mask
    /// over the candidates `ids`.
    fn feasible_masks(
        ctx: &Context,
        pv: &ProblemViews,
        cands: &Candidates,
        inst: &Instance,
        c: usize,
        ids: &[u32],
    ) -> Vec<u32> {
        let here = inst.of_cpv(c);
        let mut out = Vec::new();
        for set in 0u32..1 << here.len() {
            let chosen: Vec<usize> = (0..here.len()).filter(|&k| set >> k & 1 == 1).collect();
            // As the program asks: within the limit by its slack.
            if within(ctx, pv, cands, inst, c, &chosen, SLACK_MS) {
                let mask = chosen.iter().fold(0u32, |acc, &k| {
                    acc | 1 << ids.binary_search(&here[k].cand).unwrap()
                });
                out.push(mask);
            }
        }
        out
    }

    /// The least memory over every subset of the candidates `ids` that
    /// gives each CPV an antichain within its limit.
    fn brute_force(
        ctx: &Context,
        pv: &ProblemViews,
        cands: &Candidates,
        inst: &Instance,
        ids: &[u32],
    ) -> Option<u64> {
        let per_cpv: Vec<Vec<u32>> = (0..pv.cpvs.len())
            .filter(|&c| inst.limit[c].is_finite())
            .map(|c| feasible_masks(ctx, pv, cands, inst, c, ids))
            .collect();
        (0u32..1 << ids.len())
            .filter(|&x| per_cpv.iter().all(|ms| ms.iter().any(|&m| m & !x == 0)))
            .map(|x| {
                (0..ids.len())
                    .filter(|&k| x >> k & 1 == 1)
                    .map(|k| cands.list[ids[k] as usize].spec.memory_bytes)
                    .sum()
            })
            .min()
    }

    /// A limit per CPV: 0 for those above the target (every use listed),
    /// none for the others.
    fn open_above_target(ctx: &Context, pv: &ProblemViews) -> Vec<f64> {
        pv.cpvs
            .iter()
            .map(|c| {
                if c.time > ctx.t_max {
                    0.0
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// On tiny instances (a few candidates drawn from the small city's,
    /// with clusters nested, each CPV asked for half or nine tenths of what
    /// they can save there at best), the
    /// program's optimum equals the least memory found by trying every
    /// subset of candidates and every antichain of each CPV; in both cost
    /// combinations, with nested clusters in some CPVs.
    #[test]
    fn optimum_equals_brute_force_on_tiny_instances() {
        let mut chains_seen = 0;
        let mut instances = 0;
        // With two time constraints per CPV (`max`) the uses are binary and
        // the search is longer: fewer candidates.
        for (combine, n) in [
            (Combine::Sum, 12),
            (Combine::Primitives, 12),
            (Combine::Max, 5),
        ] {
            let scene = synthetic_city(3, 5, 5);
            let job = synthetic_job_combined(5, 5, combine);
            let h = Hierarchy::build(&scene);
            let ctx = Context::new(&scene, &h, None, &job, Control::default());
            let pv = views::approximate(&ctx, &job, &Counters::new());
            let cands = crate::candidates::generate(&ctx, &job, &pv);
            let open = open_above_target(&ctx, &pv);
            let full = Instance::build(&ctx, &pv, &cands, open.clone(), |_| true);
            let mut rng = Rng::new(11);
            for round in 0..4 {
                // `n` of the program's candidates: half at random, the rest
                // of clusters above those, so that nested clusters compete.
                let mut ids: Vec<u32> = Vec::new();
                let list = &cands.list;
                let of_node = |n: u32| -> Vec<u32> {
                    full.cands
                        .iter()
                        .copied()
                        .filter(|&i| list[i as usize].node == n)
                        .collect()
                };
                while ids.len() < n {
                    let i = full.cands[(rng.next_u64() % full.cands.len() as u64) as usize];
                    if ids.contains(&i) {
                        continue;
                    }
                    ids.push(i);
                    let mut up = h.nodes[cands.list[i as usize].node as usize].parent;
                    while up != u32::MAX && ids.len() < n {
                        let mut above = of_node(up);
                        above.retain(|j| !ids.contains(j));
                        if let Some(&j) =
                            above.get((rng.next_u64() % 4) as usize % above.len().max(1))
                        {
                            ids.push(j);
                            break;
                        }
                        up = h.nodes[up as usize].parent;
                    }
                }
                ids.sort_unstable();
                let probe = Instance::build(&ctx, &pv, &cands, open.clone(), |i| {
                    ids.binary_search(&i).is_ok()
                });
                let ids = probe.cands.clone();
                // Each CPV's limit: half way from its time to the best its
                // candidates reach.
                let limit: Vec<f64> = (0..pv.cpvs.len())
                    .map(|c| {
                        if !open[c].is_finite() || probe.of_cpv(c).is_empty() {
                            return f64::INFINITY;
                        }
                        let masks = {
                            let mut all = probe.clone();
                            all.limit[c] = f64::MAX;
                            feasible_masks(&ctx, &pv, &cands, &all, c, &ids)
                        };
                        let here = probe.of_cpv(c);
                        let best = masks
                            .iter()
                            .map(|&mask| {
                                let chosen: Vec<usize> = (0..here.len())
                                    .filter(|&k| {
                                        let b = ids.binary_search(&here[k].cand).unwrap();
                                        mask >> b & 1 == 1
                                    })
                                    .collect();
                                ctx.model.frame_time(probe.cost_with(&pv, c, &chosen))
                            })
                            .fold(f64::INFINITY, f64::min);
                        let t = pv.cpvs[c].time;
                        // Half way, or nearly all the way (where only the
                        // best antichains do and nesting binds).
                        let f = if round % 2 == 0 { 0.5 } else { 0.9 };
                        ctx.t_max.max(t - f * (t - best))
                    })
                    .collect();
                let inst =
                    Instance::build(&ctx, &pv, &cands, limit, |i| ids.binary_search(&i).is_ok());
                if inst.uses.is_empty() {
                    continue;
                }
                chains_seen += (0..pv.cpvs.len())
                    .filter(|&c| !inst.chains(&ctx, c, &cands).is_empty())
                    .count();
                let want = brute_force(&ctx, &pv, &cands, &inst, &inst.cands);
                let seed = vec![false; inst.uses.len()];
                let out = solve(&ctx, &job, &pv, &cands, &inst, &seed).unwrap();
                assert_eq!(out.stats.status, "optimal", "{combine:?}");
                let got: u64 = inst
                    .cands
                    .iter()
                    .filter(|&&i| {
                        inst.uses
                            .iter()
                            .zip(&out.used)
                            .any(|(u, &on)| on && u.cand == i)
                    })
                    .map(|&i| cands.list[i as usize].spec.memory_bytes)
                    .sum();
                assert_eq!(Some(got), want, "{combine:?} {ids:?}");
                // The uses the solver returns are themselves a solution:
                // in every CPV an antichain within its limit (the slack
                // absorbs the solver's tolerance).
                for c in (0..pv.cpvs.len()).filter(|&c| inst.limit[c].is_finite()) {
                    let base = inst.cpv_uses[c] as usize;
                    let chosen: Vec<usize> = (0..inst.of_cpv(c).len())
                        .filter(|&k| out.used[base + k])
                        .collect();
                    assert!(
                        within(&ctx, &pv, &cands, &inst, c, &chosen, 0.0),
                        "{combine:?} CPV {c}: {chosen:?}"
                    );
                }
                instances += 1;
            }
        }
        assert!(instances >= 10, "{instances}");
        assert!(chains_seen > 0, "no instance had nested clusters in a CPV");
    }

    /// The chain constraints bind: a CPV whose limit only counting nested
    /// clusters' savings together (an impostor and one inside it, or two of
    /// one cluster) could reach has no solution, while a limit its best
    /// antichain reaches is met. Without the chains both would be met.
    #[test]
    fn nested_savings_are_not_counted_twice() {
        let scene = synthetic_city(3, 5, 5);
        let job = synthetic_job_combined(5, 5, Combine::Sum);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = views::approximate(&ctx, &job, &Counters::new());
        let cands = crate::candidates::generate(&ctx, &job, &pv);
        // Every CPV above the target open to every use (a limit of 0 lists
        // them all), to find the chains; then one CPV limited at a time.
        let open = open_above_target(&ctx, &pv);
        let free = vec![f64::INFINITY; pv.cpvs.len()];
        let all = Instance::build(&ctx, &pv, &cands, open, |_| true);
        let saved = |s: Cost| ctx.model.time_saved(s).unwrap();
        // A CPV with a chain, whose uses all together save clearly more
        // than its best antichain.
        let (c, best, total) = (0..pv.cpvs.len())
            .filter(|&c| !all.chains(&ctx, c, &cands).is_empty())
            .map(|c| {
                let here = all.of_cpv(c);
                let best: f64 = all
                    .best_antichain(&ctx, c, &cands, |_| true, saved)
                    .iter()
                    .map(|&k| saved(here[k].saving))
                    .sum();
                let total: f64 = here.iter().map(|u| saved(u.saving)).sum();
                (c, best, total)
            })
            .max_by(|a, b| (a.2 - a.1).total_cmp(&(b.2 - b.1)))
            .expect("a CPV with nested clusters");
        assert!(total > best * 1.01 + 1e-6, "{total} vs {best}");
        let t = ctx.model.frame_time(pv.cpvs[c].cost);
        let seed = vec![false; all.uses.len()];
        let with_limit = |need: f64| {
            let mut limit = free.clone();
            limit[c] = t - need;
            Instance::build(&ctx, &pv, &cands, limit, |_| true)
        };
        // Within the best antichain's reach: met, by an antichain.
        let inst = with_limit(0.99 * best);
        let out = solve(&ctx, &job, &pv, &cands, &inst, &seed).unwrap();
        assert_eq!(out.stats.status, "optimal");
        let base = inst.cpv_uses[c] as usize;
        let chosen: Vec<usize> = (0..inst.of_cpv(c).len())
            .filter(|&k| out.used[base + k])
            .collect();
        assert!(within(&ctx, &pv, &cands, &inst, c, &chosen, 0.0));
        // Beyond it, below what double counting reaches: no solution.
        let inst = with_limit(0.5 * (best + total));
        match solve(&ctx, &job, &pv, &cands, &inst, &seed) {
            Ok(out) => assert_ne!(out.stats.status, "optimal", "{:?}", out.stats),
            Err(e) => assert!(e.to_string().contains("solver"), "{e}"),
        }
    }
}
