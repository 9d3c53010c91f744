//! Witnesses: the clusters a walk last found inside an enclosing set along
//! a direction, tried first when a set along the same direction is tested
//! again.
//!
//! A problem view's proofs test the same directions from one cell after
//! another (neighbours on a thread), and from the parts of one cell. Where a
//! set exceeds the target, the clusters it holds whole are mostly the same
//! from one such test to the next. [`exceeds_from`](super::costs) records,
//! per direction, the uncut clusters it found inside the set before it
//! answered yes; the next test along that direction first sums the cost of
//! those of them that lie inside its own set and below its own starting
//! entries. Where that sum alone exceeds the target by more than the walk's
//! rounding margin, the answer is yes without the walk: the walk would sum
//! every such cluster whole (each is disjoint from the others and below an
//! uncut entry, so the walk either meets it, inside, or one of its
//! ancestors, inside and costing at least as much), and its sum only grows.
//! Otherwise the walk runs as before. The answers are the walk's in every
//! case, so the witnesses change the time, never a placement, and what a
//! thread happens to hold does not matter.

use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::math::enclosing::{Enclosing, Overlap};
use crate::math::geom::Vdi;
use crate::model::cost::Cost;
use crate::views::context::Context;
use crate::views::costs::RegionCosts;

/// At most this many witnesses are kept per direction (the first a walk
/// found: breadth first, the largest clusters).
const MAX_WITNESSES: usize = 1024;

/// The bit that marks a witness as an object, not a cluster.
pub const OBJECT: u32 = 1 << 31;

/// A fresh number per run, so that a thread's witnesses from another run
/// (another scene and hierarchy) are dropped, not read.
pub static PROBE: [AtomicU64; 8] = [const { AtomicU64::new(0) }; 8];
pub fn next_run() -> u64 {
    eprintln!("WPROBE {:?}", PROBE.iter().map(|a| a.load(Ordering::Relaxed)).collect::<Vec<_>>());
    static RUNS: AtomicU64 = AtomicU64::new(0);
    RUNS.fetch_add(1, Ordering::Relaxed)
}

/// The key of a direction.
pub fn key(v: &Vdi) -> u64 {
    u64::from(v.face) | u64::from(v.level) << 8 | u64::from(v.iu) << 16 | u64::from(v.iv) << 40
}

/// One thread's witnesses: per direction key, the clusters last found
/// inside, for the run `run`.
#[derive(Default)]
struct Held {
    run: u64,
    by_key: HashMap<u64, Vec<u32>>,
}

thread_local! {
    static HELD: RefCell<Held> = RefCell::new(Held::default());
}

/// Where a walk's witnesses may lie: below one of the uncut entries it
/// starts from, as sorted pre-order ranges `[first, end)` of node ids
/// (`None`: anywhere, a walk from the root).
pub type Spans<'a> = Option<&'a [(u32, u32)]>;

fn below(spans: Spans, n: u32) -> bool {
    let Some(spans) = spans else {
        return true;
    };
    let k = spans.partition_point(|&(first, _)| first <= n);
    k > 0 && n < spans[k - 1].1
}

/// True when the witnesses held for `key` prove that the walk of `cone`
/// from the entries of `spans` sums more than frame time `t` (the walk's
/// rounding `margin` above it).
pub fn prove(
    ctx: &Context,
    costs: &RegionCosts,
    spans: Spans,
    cone: &Enclosing,
    (t, margin): (f64, f64),
    key: u64,
) -> bool {
    HELD.with(|held| {
        let held = held.borrow();
        if held.run != ctx.run {
            return false;
        }
        let Some(nodes) = held.by_key.get(&key).filter(|n| !n.is_empty()) else {
            PROBE[0].fetch_add(1, Ordering::Relaxed);
            return false;
        };
        PROBE[1].fetch_add(1, Ordering::Relaxed);
        let h = ctx.hierarchy;
        let all = cone.all_bounds();
        let mut sum = Cost::default();
        for &n in nodes {
            // An object of a leaf the walk cut: counted where it meets the
            // set; a cluster: counted whole where the set holds it.
            let (meets, w) = if n & OBJECT != 0 {
                let o = (n & !OBJECT) as usize;
                if o >= h.leaf_of.len() || !below(spans, h.leaf_of[o]) {
                    PROBE[4].fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                let w = costs.objects[o];
                if w == Cost::default() {
                    continue;
                }
                let s = &h.object_spheres[o];
                PROBE[3].fetch_add(1, Ordering::Relaxed);
                (cone.meets_within(s.center, s.radius, all), w)
            } else {
                if n as usize >= h.nodes.len() || !below(spans, n) {
                    PROBE[4].fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                let w = costs.nodes[n as usize];
                if w == Cost::default() {
                    continue;
                }
                let s = costs.sphere(h, n);
                PROBE[3].fetch_add(1, Ordering::Relaxed);
                let inside = cone.classify_within(s.center, s.radius, all).0 == Overlap::Inside;
                (inside, w)
            };
            if meets {
                sum += w;
                PROBE[5].fetch_add(1, Ordering::Relaxed);
                if ctx.model.frame_time(sum) > t + margin {
                    PROBE[2].fetch_add(1, Ordering::Relaxed);
                    return true;
                }
            }
        }
        false
    })
}

/// Keeps `found` (disjoint clusters a walk found inside its set, in the
/// order found) as the witnesses of `key`.
pub fn record(ctx: &Context, key: u64, found: &[u32]) {
    HELD.with(|held| {
        let mut held = held.borrow_mut();
        if held.run != ctx.run {
            held.run = ctx.run;
            held.by_key.clear();
        }
        let kept = held.by_key.entry(key).or_default();
        kept.clear();
        kept.extend_from_slice(&found[..found.len().min(MAX_WITNESSES)]);
        PROBE[6].fetch_add(1, Ordering::Relaxed);
        PROBE[7].fetch_add(found.len() as u64, Ordering::Relaxed);
    });
}

/// Drops the witnesses of `key` (a walk along it answered no).
pub fn forget(ctx: &Context, key: u64) {
    HELD.with(|held| {
        let mut held = held.borrow_mut();
        if held.run == ctx.run
            && let Some(kept) = held.by_key.get_mut(&key)
        {
            kept.clear();
        }
    });
}
