//! The (cluster, CPV) pairs, held once, grouped by cluster and cell.
//!
//! A *pair* is a cluster listed by a CPV (see [`crate::views::cpv_clusters`])
//! with the cost of the cluster's objects inside the CPV's enclosing set. A
//! *group* is the pairs of one cluster in one cell. Where the cluster lies
//! wholly inside the enclosing set (its sphere, or an ancestor's, is inside;
//! or every object of it is), its cost there is its whole cost in the cell,
//! which every CPV of the cell shares: the group holds it once. Only the
//! pairs of clusters partly outside the set store their own cost. A pair is
//! then its CPV id (4 bytes), plus 16 bytes for the minority that store a
//! cost: the hierarchy's sums stand for the clusters below a node wholly
//! inside, as the enclosing walk's cut does.

use rayon::prelude::*;

use crate::math::IdRange;
use crate::model::cost::Cost;
use crate::views::{Context, Counters, PairCounts, ProblemViews, RegionCosts, cpv_clusters};

/// Set in a pair's CPV id when its cost is stored.
const STORED: u32 = 1 << 31;

/// One cell's CPVs that list one cluster.
#[derive(Clone, Copy, Debug)]
pub struct Group {
    /// Its pairs: `pairs.start..pairs.end` of the pairs.
    pub pairs: IdRange,
    /// The cell (kd leaf) of the CPVs.
    pub kd: u32,
    /// Index of the group's first stored cost.
    stored: u32,
    /// Distance from the cell's region to the cluster's sphere centre; all
    /// CPVs of the group share it, hence an impostor's cost there.
    pub dist: f64,
    /// The cluster's whole cost seen from the cell: its cost in the CPVs
    /// whose pairs store none.
    pub whole: Cost,
}

/// The pairs of every CPV, grouped by cluster (node id) and, within a
/// cluster, by cell, CPV ids ascending.
#[derive(Clone, Debug, Default)]
pub struct Pairs {
    /// Per pair: the CPV id, with [`STORED`] set when its cost is stored.
    cpv: Vec<u32>,
    /// The stored costs, in pair order.
    stored: Vec<Cost>,
    /// The groups, by cluster and cell.
    groups: Vec<Group>,
    /// Per cluster: its groups are `node_groups[n]..node_groups[n + 1]`.
    node_groups: Vec<u32>,
}

impl Pairs {
    /// Number of pairs.
    pub fn len(&self) -> u64 {
        self.cpv.len() as u64
    }

    /// True when no CPV lists a cluster.
    pub fn is_empty(&self) -> bool {
        self.cpv.is_empty()
    }

    /// Number of pairs whose cost is stored.
    pub fn stored_len(&self) -> u64 {
        self.stored.len() as u64
    }

    /// Number of groups.
    pub fn groups_len(&self) -> u64 {
        self.groups.len() as u64
    }

    /// Group `g`.
    pub fn group(&self, g: u32) -> &Group {
        &self.groups[g as usize]
    }

    /// The group ids of cluster `n`, by cell.
    pub fn groups_of(&self, n: u32) -> IdRange {
        IdRange::new(
            self.node_groups[n as usize],
            self.node_groups[n as usize + 1],
        )
    }

    /// The first CPV of group `g` (all share its cell's region).
    pub fn first_cpv(&self, g: &Group) -> u32 {
        self.cpv[g.pairs.start as usize] & !STORED
    }

    /// The (CPV id, cost) of every pair of `g`, CPV ids ascending.
    pub fn iter<'a>(&'a self, g: &'a Group) -> impl Iterator<Item = (u32, Cost)> + 'a {
        let mut k = g.stored as usize;
        self.cpv[g.pairs.indices()].iter().map(move |&x| {
            if x & STORED == 0 {
                (x, g.whole)
            } else {
                k += 1;
                (x & !STORED, self.stored[k - 1])
            }
        })
    }

    /// The cost of cluster `node`'s objects in CPV `cpv`'s enclosing set,
    /// if the CPV lists the cluster.
    pub fn cost_of(&self, node: u32, cpv: u32) -> Option<Cost> {
        let gs = &self.groups[self.groups_of(node).indices()];
        let (a, b) = match (gs.first(), gs.last()) {
            (Some(f), Some(l)) => (f.pairs.start as usize, l.pairs.end as usize),
            _ => return None,
        };
        let p = a + self.cpv[a..b]
            .binary_search_by_key(&cpv, |&x| x & !STORED)
            .ok()?;
        let g = &gs[gs.partition_point(|g| g.pairs.end as usize <= p)];
        if self.cpv[p] & STORED == 0 {
            return Some(g.whole);
        }
        let before = self.cpv[g.pairs.start as usize..p]
            .iter()
            .filter(|&&x| x & STORED != 0)
            .count();
        Some(self.stored[g.stored as usize + before])
    }

    /// The pairs of `pv`: the CPVs' cluster lists are computed again a few
    /// cells at a time (in parallel) and scattered into place with the
    /// counts the approximation recorded, so no more than those few cells'
    /// lists are held besides the pairs.
    pub fn collect(ctx: &Context, pv: &ProblemViews) -> Pairs {
        let counts = &pv.node_counts;
        let [n_pairs, n_stored, n_groups] = PairCounts::totals(counts);
        assert!(
            n_pairs < u64::from(u32::MAX) && (pv.cpvs.len() as u64) < u64::from(STORED),
            "the memory check caps the pairs below 2^32"
        );
        // Per cluster: where its next pair, stored cost and group go.
        let mut fill = Vec::with_capacity(counts.len());
        let mut at = [0u32; 3];
        let mut node_groups = Vec::with_capacity(counts.len() + 1);
        for c in counts {
            fill.push(at);
            node_groups.push(at[2]);
            at = [at[0] + c.pairs, at[1] + c.partial, at[2] + c.cells];
        }
        node_groups.push(at[2]);
        let mut cpv = vec![0u32; n_pairs as usize];
        let mut stored = vec![Cost::default(); n_stored as usize];
        let mut groups = vec![
            Group {
                pairs: IdRange::default(),
                kd: 0,
                stored: 0,
                dist: 0.0,
                whole: Cost::default(),
            };
            n_groups as usize
        ];
        let cells = pv.cells();
        let h = ctx.hierarchy;
        let lods = Counters::new();
        for chunk in cells.chunks(16) {
            if ctx.cancelled() {
                break;
            }
            // Per cell: its CPVs' lists, each pair with its cost when that
            // is not the cluster's whole cost, and the whole costs of the
            // clusters listed, by node id.
            type CellLists = (Vec<Vec<(u32, Option<Cost>)>>, Vec<(u32, Cost)>);
            let lists: Vec<CellLists> = chunk
                .par_iter()
                .map(|r| {
                    let kd = &pv.kd[pv.cpvs[r.start as usize].kd as usize];
                    let costs = RegionCosts::of_kd(ctx, kd, &lods);
                    let mut listed: Vec<u32> = Vec::new();
                    let lists = pv.cpvs[r.indices()]
                        .iter()
                        .map(|c| {
                            let (cost, list) = cpv_clusters(ctx, &costs, &c.region, &c.vdi);
                            debug_assert_eq!((cost, list.len()), (c.cost, c.listed as usize));
                            listed.extend(list.iter().map(|p| p.0));
                            list.into_iter()
                                .map(|(n, c)| (n, (c != costs.nodes[n as usize]).then_some(c)))
                                .collect()
                        })
                        .collect();
                    listed.sort_unstable();
                    listed.dedup();
                    let whole = listed
                        .into_iter()
                        .map(|n| (n, costs.nodes[n as usize]))
                        .collect();
                    (lists, whole)
                })
                .collect();
            for (r, (lists, whole)) in chunk.iter().zip(lists) {
                let first = &pv.cpvs[r.start as usize];
                for &(n, cost) in &whole {
                    let f = fill[n as usize];
                    groups[f[2] as usize] = Group {
                        pairs: IdRange::new(f[0], f[0]),
                        kd: first.kd,
                        stored: f[1],
                        dist: first
                            .region
                            .distance_to_point(h.nodes[n as usize].sphere.center),
                        whole: cost,
                    };
                }
                for (ci, list) in r.indices().zip(lists) {
                    for (n, cost) in list {
                        let f = &mut fill[n as usize];
                        cpv[f[0] as usize] = ci as u32;
                        if let Some(c) = cost {
                            cpv[f[0] as usize] |= STORED;
                            stored[f[1] as usize] = c;
                            f[1] += 1;
                        }
                        f[0] += 1;
                    }
                }
                for &(n, _) in &whole {
                    let f = &mut fill[n as usize];
                    groups[f[2] as usize].pairs.end = f[0];
                    f[2] += 1;
                }
            }
        }
        Pairs {
            cpv,
            stored,
            groups,
            node_groups,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Control;
    use crate::scene::hierarchy::Hierarchy;
    use crate::testutil::{synthetic_city, synthetic_job};
    use crate::views;

    /// Every CPV's cluster list comes back from the pairs with the same
    /// costs, bit for bit, whether stored or derived from the cell's whole
    /// costs; clusters a CPV does not list have no pair.
    #[test]
    fn pairs_give_back_every_cpv_list() {
        let scene = synthetic_city(5, 6, 6);
        let job = synthetic_job(6, 6);
        let h = Hierarchy::build(&scene);
        let ctx = Context::new(&scene, &h, None, &job, Control::default());
        let pv = views::approximate(&ctx, &job, &Counters::new());
        let pairs = Pairs::collect(&ctx, &pv);
        let listed: u64 = pv.cpvs.iter().map(|c| u64::from(c.listed)).sum();
        assert_eq!(pairs.len(), listed);
        assert!(pairs.stored_len() > 0, "no cluster is partly outside");
        assert!(
            pairs.stored_len() * 2 < pairs.len(),
            "{} of {} pairs store their cost",
            pairs.stored_len(),
            pairs.len()
        );
        let mut checked = 0;
        for (i, c) in pv.cpvs.iter().enumerate().step_by(7) {
            let kd = &pv.kd[c.kd as usize];
            assert!(kd.children.is_none());
            let costs = RegionCosts::new(&ctx, &c.region, None, &Counters::new());
            let (_, list) = cpv_clusters(&ctx, &costs, &c.region, &c.vdi);
            let mut next = 0;
            for n in 0..h.nodes.len() as u32 {
                let want = match list.get(next) {
                    Some(&(m, cost)) if m == n => {
                        next += 1;
                        Some(cost)
                    }
                    _ => None,
                };
                let got = pairs.cost_of(n, i as u32);
                assert_eq!(
                    got.map(|x| (x.cpu.to_bits(), x.gpu.to_bits())),
                    want.map(|x| (x.cpu.to_bits(), x.gpu.to_bits())),
                    "CPV {i} cluster {n}"
                );
                checked += usize::from(want.is_some());
            }
        }
        assert!(checked > 100, "{checked}");
        // Walking each cluster's groups gives its pairs in CPV order, each
        // group within one cell.
        for n in 0..h.nodes.len() as u32 {
            let mut last = None;
            for g in pairs.groups_of(n).indices() {
                let gr = pairs.group(g as u32);
                for (c, cost) in pairs.iter(gr) {
                    assert!(last < Some(c));
                    last = Some(c);
                    assert_eq!(pv.cpvs[c as usize].kd, gr.kd);
                    assert_eq!(pairs.cost_of(n, c), Some(cost));
                }
            }
        }
    }
}
