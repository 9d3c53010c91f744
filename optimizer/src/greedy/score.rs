//! Scoring: a candidate's exact score, a block's scores in one walk, and
//! a block's bounds from per-cell figures and what earlier exact walks
//! found per group ([`Walked`]).

use std::ops::Range;

use super::State;
use crate::candidates::Group;
use crate::math::{IdRange, f32_up};
use crate::model::cost::Cost;

/// A time of 0 or more, rounded up to a 16-bit float with `f32`'s exponent
/// (bfloat16: the upper half of the `f32`'s bits, a step up where the
/// lower half is not zero): an upper bound in half an `f32`'s memory, at
/// most 1/128 above the time. Ordered as its bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Up16(u16);

impl Up16 {
    pub(super) const INFINITY: Up16 = Up16(0x7f80);

    /// The least such value not below `x` (0 below 0).
    pub(super) fn up(x: f64) -> Up16 {
        if x.is_nan() || x <= 0.0 {
            return Up16(0);
        }
        let b = f32_up(x).to_bits();
        // A carry out of the mantissa steps the exponent: still the next
        // value up (at most infinity).
        Up16((b >> 16) as u16 + u16::from(b & 0xffff != 0))
    }

    pub(super) fn get(self) -> f64 {
        f64::from(f32::from_bits(u32::from(self.0) << 16))
    }
}

/// What an exact scoring found in one group (one cluster in one cell),
/// over the CPVs still open to the cluster there (above `t_max`, cluster
/// not covered), as times rounded up ([`Up16`]: held for each of the 66 M
/// groups of the scale-4 city; infinity: not walked yet). Both only fall
/// as the greedy goes on: a representation only loses the savings of
/// impostors placed below, an excess only falls, and a CPV once solved or
/// covered stays so. So a figure found at any time still bounds what any
/// impostor of the cluster gains in the group.
#[derive(Clone, Copy, Debug)]
pub(super) struct Walked {
    /// The costliest representation of the cluster in an open CPV: no
    /// impostor saves more in one CPV than it less the impostor's cost.
    /// Impostors placed below leave it far under the cluster's whole cost,
    /// the bound's figure before.
    rep: Up16,
    /// The sum over the open CPVs of the least of the CPV's excess and
    /// what a one-layer impostor of the cluster saves against the
    /// representation: no impostor gains more in the group (one of more
    /// layers costs more, its saving is less).
    gain: Up16,
}

impl Walked {
    pub(super) const NONE: Walked = Walked {
        rep: Up16::INFINITY,
        gain: Up16::INFINITY,
    };
}

impl State<'_> {
    pub(super) fn score(&self, i: u32) -> f64 {
        let c = &self.cands[i as usize];
        let mut sum = 0.0;
        self.add_gains(c.node, c.spec.layers, c.served.indices(), &mut sum);
        sum / c.spec.memory_bytes.max(1) as f64
    }

    /// Adds to `sum` the gains of the groups `served[groups]` for an
    /// impostor of `layers` layers of cluster `node`, counting only CPVs
    /// still above `t_max`.
    pub(super) fn add_gains(&self, node: u32, layers: u32, groups: Range<usize>, sum: &mut f64) {
        let all = self.all;
        let s = self.ctx.hierarchy.nodes[node as usize].sphere;
        for g in all.served_range(node, groups) {
            let gr = &all.pairs.group(g);
            if self.unsolved_in_cell[gr.kd as usize] == 0 {
                continue;
            }
            let imp = self
                .ctx
                .model
                .impostor(layers, s.radius, all.pairs.dist(gr, s.center));
            all.pairs.for_each(gr, |c, orig| {
                let excess = self.excess[c as usize];
                if excess > 0.0 {
                    *sum += self.gain(c, node, orig, imp, excess);
                }
            });
        }
    }

    /// Walks the groups served by the candidates of one block, which serve
    /// growing prefixes of the same groups (see [`blocks`]), once for all
    /// of them: `add(id, group, layers, active, sums)` adds each group's terms
    /// for the layer counts `layers[l]`, `l` in `active`, to `sums[l]`.
    /// Returns each candidate's sum for its layer count: the terms of its
    /// own groups, in its served order, as a walk for it alone would add
    /// them. A layer count no later candidate has leaves `active`.
    pub(super) fn walk_block(
        &self,
        block: IdRange,
        mut add: impl FnMut(u32, &Group, &[u32], &[usize], &mut [f64]),
    ) -> Vec<f64> {
        let cands = &self.cands[block.indices()];
        let mut layers: Vec<u32> = cands.iter().map(|c| c.spec.layers).collect();
        layers.sort_unstable();
        layers.dedup();
        let idx: Vec<usize> = cands
            .iter()
            .map(|c| layers.partition_point(|&l| l < c.spec.layers))
            .collect();
        let mut last = vec![0usize; layers.len()];
        for (k, &l) in idx.iter().enumerate() {
            last[l] = k;
        }
        let mut active: Vec<usize> = (0..layers.len()).collect();
        let mut sums = vec![0.0f64; layers.len()];
        let mut out = Vec::with_capacity(cands.len());
        let mut pos = cands[0].served.start as usize;
        let node = cands[0].node;
        for (k, c) in cands.iter().enumerate() {
            let end = c.served.end as usize;
            for g in self.all.served_range(node, pos..end) {
                add(g, &self.all.pairs.group(g), &layers, &active, &mut sums);
            }
            pos = end;
            out.push(sums[idx[k]]);
            active.retain(|&l| last[l] > k);
        }
        out
    }

    /// The scores of the candidates of one block. Equal to
    /// [`score`](Self::score) of each, bit for bit, but the groups are
    /// walked once for the whole block. Also returns what the walk found in
    /// each group, for [`note_walked`](Self::note_walked) (nothing in `max`
    /// mode, whose bounds do not use it).
    pub(super) fn score_block(&self, block: IdRange) -> (Vec<f64>, Vec<(u32, Walked)>) {
        let node = self.cands[block.start as usize].node;
        let s = self.ctx.hierarchy.nodes[node as usize].sphere;
        let r = s.radius;
        let m = &self.ctx.model;
        let adds = m.time_saved(Cost::default()).is_some();
        let mut imps: Vec<Cost> = Vec::new();
        let mut found: Vec<(u32, Walked)> = Vec::new();
        let sums = self.walk_block(block, |g, gr, layers, active, sums| {
            if !self.any_open_in_cell(node, gr.kd) {
                if adds {
                    found.push((
                        g,
                        Walked {
                            rep: Up16(0),
                            gain: Up16(0),
                        },
                    ));
                }
                return;
            }
            let (mut most, mut gain) = (0.0f64, 0.0f64);
            let px = self.ctx.model.pixels(r, self.all.pairs.dist(gr, s.center));
            // The cheapest impostor of the cluster here, for `gain`.
            let least = m.impostor_covering(1, px);
            imps.clear();
            imps.extend(
                active
                    .iter()
                    .map(|&l| self.ctx.model.impostor_covering(layers[l], px)),
            );
            self.all.pairs.for_each(gr, |c, orig| {
                let excess = self.excess[c as usize];
                if excess <= 0.0 {
                    return;
                }
                let Some(rep) = self.representation(c, node, orig) else {
                    return;
                };
                if adds {
                    most = most.max(m.time_saved(rep).unwrap_or(0.0));
                    gain += self.gain_over(c, rep, least, excess);
                }
                for (&l, &imp) in active.iter().zip(&imps) {
                    sums[l] += self.gain_over(c, rep, imp, excess);
                }
            });
            if adds {
                // The sum in another order than a bound's: the slack covers
                // the rounding.
                let gain = gain.max(0.0) * (1.0 + 1e-9);
                found.push((
                    g,
                    Walked {
                        rep: Up16::up(most),
                        gain: Up16::up(gain),
                    },
                ));
            }
        });
        (self.per_byte(block, sums, 1.0), found)
    }

    /// Keeps what an exact scoring found in its groups
    /// ([`score_block`](Self::score_block)), where lower than what is held.
    /// Applied between batches, in batch order, so a bound never depends on
    /// which thread ran first.
    pub(super) fn note_walked(&mut self, found: &[(u32, Walked)]) {
        for &(g, f) in found {
            let w = &mut self.walked[g as usize];
            w.rep = w.rep.min(f.rep);
            w.gain = w.gain.min(f.gain);
        }
    }

    /// Divides each candidate's sum by its memory, after scaling by `scale`.
    pub(super) fn per_byte(&self, block: IdRange, sums: Vec<f64>, scale: f64) -> Vec<f64> {
        sums.into_iter()
            .zip(&self.cands[block.indices()])
            .map(|(s, c)| s * scale / c.spec.memory_bytes.max(1) as f64)
            .collect()
    }

    /// Upper bounds of the scores of the candidates of one block, from
    /// per-cell figures alone, without walking any pair: a CPV of group
    /// `g` gains nothing where the cluster is already covered or the CPV
    /// solved, at most its excess elsewhere, and at most what the impostor
    /// saves against the cluster's whole cost in the cell (its cost in a
    /// CPV, less any descendant impostors' savings, is never more where
    /// times add up). So the group gains at most `min(E, n·T)`, `E` the
    /// cell's summed excess, `n` the number of its open CPVs (above
    /// `t_max`, cluster not covered; [`open_in_cell`](Self::open_in_cell)),
    /// at most the group's pairs, and `T` that saving; in `max` mode only `E`
    /// bounds it. Where an exact scoring has walked the group, `T` is the
    /// saving against the costliest representation it found in an open CPV
    /// instead, if less, and the group gains at most the sum it found
    /// ([`Walked`]). Exact sums of these terms bound the scores; the
    /// floating-point sums are raised by a relative 1e-9, far above their
    /// rounding.
    pub(super) fn bound_block(&self, block: IdRange) -> Vec<f64> {
        let node = self.cands[block.start as usize].node;
        let s = self.ctx.hierarchy.nodes[node as usize].sphere;
        let r = s.radius;
        let m = &self.ctx.model;
        let sums = self.walk_block(block, |g, gr, layers, active, sums| {
            let n = self.open_in_cell(node, gr.kd);
            if n == 0 {
                return;
            }
            let e = self.cell_excess[gr.kd as usize];
            let Some(whole) = m.time_saved(gr.whole) else {
                for &l in active {
                    sums[l] += e;
                }
                return;
            };
            let walked = self.walked[g as usize];
            let whole = whole.min(walked.rep.get());
            let e = e.min(walked.gain.get());
            let n = f64::from(gr.len(&self.all.pairs).min(n));
            let px = m.pixels(r, self.all.pairs.dist(gr, s.center));
            for &l in active {
                let imp = m
                    .time_saved(m.impostor_covering(layers[l], px))
                    .unwrap_or(0.0);
                // A CPV's representation is the whole cost less savings,
                // summed in another order: the slack covers the rounding.
                let t = whole - imp + 1e-9 * (whole.abs() + imp.abs());
                sums[l] += (n * t).min(e).max(0.0);
            }
        });
        self.per_byte(block, sums, 1.0 + 1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::Up16;
    use crate::math::rng::Rng;

    /// A rounded-up time is never below the time, at most a step of 1/128
    /// above it, and orders as the times do.
    #[test]
    fn times_rounded_up_to_16_bits_bound_the_time_closely() {
        let mut rng = Rng::new(3);
        let mut xs: Vec<f64> = (0..20_000)
            .map(|_| 10f64.powf(rng.range(-6.0, 4.0)))
            .collect();
        xs.extend([0.0, -1.0, 1.0, 0.75, 3.0e38, 4.0e38, f64::INFINITY]);
        for &x in &xs {
            let u = Up16::up(x);
            assert!(u.get() >= x, "{x} rounded to {}", u.get());
            if x > 0.0 && x < 1e38 {
                assert!(
                    u.get() <= x * (1.0 + 1.0 / 128.0),
                    "{x} rounded to {}",
                    u.get()
                );
            }
        }
        assert_eq!(Up16::up(0.75).get(), 0.75);
        assert_eq!(Up16::up(-1.0).get(), 0.0);
        assert_eq!(Up16::INFINITY.get(), f64::INFINITY);
        xs.sort_by(f64::total_cmp);
        for w in xs.windows(2) {
            assert!(Up16::up(w[0]) <= Up16::up(w[1]), "{} {}", w[0], w[1]);
        }
    }
}
