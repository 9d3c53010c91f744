//! The CPVs of a placement as JSON: each CPV's impostor list whole, or as
//! its change from the list of the CPV before it, whichever lists fewer ids.
//!
//! Neighbouring CPVs (the directions of one cell, the cells next to it) draw
//! mostly the same impostors, so on large maps most of a placement's size
//! was the same ids written again and again. Readers rebuild every list
//! while reading (the [`PlacedCpv`]s in memory always hold whole lists).

use std::borrow::Cow;
use std::fmt;

use schemars::JsonSchema;
use serde::de::{Error as _, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{DirectionsJson, PlacedCpv, RegionJson, UnsolvedReason};

/// One conservative problem view as a placement file holds it. Its impostor
/// list is given by exactly one of two forms:
/// - `impostors`: the ids of the impostors to draw in this CPV, ascending;
/// - `impostors_added` and `impostors_removed` (each ascending, possibly
///   empty): the list is the list of the CPV before it in `cpvs` (whole or
///   itself rebuilt this way) without the removed ids and with the added
///   ones, ascending. The first CPV always has the first form.
///
/// Writers use the second form where it lists fewer ids.
#[derive(Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, rename = "PlacedCpv")]
#[schemars(extend("oneOf" = [
    {"required": ["impostors"]},
    {"required": ["impostors_added", "impostors_removed"]},
]))]
pub struct CpvJson<'a> {
    /// Index in `cpvs`.
    pub id: u32,
    /// Its 3D region: its grid cell, or the box of the parts of that cell
    /// where a view may exceed the target (`problem_views.split_levels`); a
    /// view belongs to the CPV when its eye lies in the region and its
    /// direction in `directions`. Views of the cell outside the region are
    /// within the target without impostors.
    pub region: Cow<'a, RegionJson>,
    /// Its view directions.
    pub directions: Cow<'a, DirectionsJson>,
    /// Estimated time without impostors, ms.
    pub time_ms_original: f64,
    /// Estimated time with its impostors, ms.
    pub time_ms_final: f64,
    /// True when `time_ms_final` is within the target.
    pub solved: bool,
    /// Why an unsolved CPV could not be solved (absent when solved, and for
    /// methods that do not explain it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unsolved_reason: Option<UnsolvedReason>,
    /// Ids of the impostors to draw in this CPV, ascending (or the next two
    /// fields instead).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impostors: Option<Cow<'a, [u32]>>,
    /// Ids drawn in this CPV and not in the CPV before it, ascending.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impostors_added: Option<Vec<u32>>,
    /// Ids drawn in the CPV before it and not in this one, ascending.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impostors_removed: Option<Vec<u32>>,
}

fn ascending(l: &[u32]) -> bool {
    l.windows(2).all(|w| w[0] < w[1])
}

/// `(added, removed)` taking `prev` to `cur` when both are ascending and the
/// two list fewer ids than `cur`; `None` otherwise (write `cur` whole).
fn change(prev: &[u32], cur: &[u32]) -> Option<(Vec<u32>, Vec<u32>)> {
    if !ascending(prev) || !ascending(cur) {
        return None;
    }
    let (mut added, mut removed) = (Vec::new(), Vec::new());
    let (mut i, mut j) = (0, 0);
    while i < prev.len() || j < cur.len() {
        if added.len() + removed.len() >= cur.len() {
            return None;
        }
        match (prev.get(i), cur.get(j)) {
            (Some(&p), Some(&c)) if p == c => {
                i += 1;
                j += 1;
            }
            (Some(&p), Some(&c)) if p < c => {
                removed.push(p);
                i += 1;
            }
            (Some(&p), None) => {
                removed.push(p);
                i += 1;
            }
            (_, Some(&c)) => {
                added.push(c);
                j += 1;
            }
            (None, None) => unreachable!("the loop runs while either list has ids left"),
        }
    }
    (added.len() + removed.len() < cur.len()).then_some((added, removed))
}

/// `prev` without `removed` and with `added` (all ascending), or what is
/// wrong with them.
fn apply(prev: &[u32], added: &[u32], removed: &[u32]) -> Result<Vec<u32>, String> {
    if !ascending(prev) {
        return Err(
            "the CPV before it lists its impostors out of order, so no change \
                    can be applied to them"
                .into(),
        );
    }
    for (name, l) in [("impostors_added", added), ("impostors_removed", removed)] {
        if !ascending(l) {
            return Err(format!("{name} is not ascending"));
        }
    }
    let not_drawn =
        |x: u32| format!("impostors_removed holds {x}, which the CPV before it does not draw");
    let mut kept = Vec::with_capacity(prev.len());
    let mut r = 0;
    for &p in prev {
        match removed.get(r) {
            // Every id of `prev` below `p` has been passed.
            Some(&x) if x < p => return Err(not_drawn(x)),
            Some(&x) if x == p => r += 1,
            _ => kept.push(p),
        }
    }
    if let Some(&x) = removed.get(r) {
        return Err(not_drawn(x));
    }
    let mut out = Vec::with_capacity(kept.len() + added.len());
    let mut k = kept.iter().peekable();
    for &a in added {
        while let Some(&&x) = k.peek() {
            if x >= a {
                break;
            }
            out.push(x);
            k.next();
        }
        if prev.binary_search(&a).is_ok() {
            return Err(format!(
                "impostors_added holds {a}, which the CPV before it draws already"
            ));
        }
        out.push(a);
    }
    out.extend(k);
    Ok(out)
}

/// Writes `cpvs` as [`CpvJson`]s.
pub fn serialize<S: Serializer>(cpvs: &[PlacedCpv], s: S) -> Result<S::Ok, S::Error> {
    let mut seq = s.serialize_seq(Some(cpvs.len()))?;
    let mut prev: Option<&[u32]> = None;
    for c in cpvs {
        let (impostors, impostors_added, impostors_removed) =
            match prev.and_then(|p| change(p, &c.impostors)) {
                Some((a, r)) => (None, Some(a), Some(r)),
                None => (Some(Cow::Borrowed(&c.impostors[..])), None, None),
            };
        seq.serialize_element(&CpvJson {
            id: c.id,
            region: Cow::Borrowed(&c.region),
            directions: Cow::Borrowed(&c.directions),
            time_ms_original: c.time_ms_original,
            time_ms_final: c.time_ms_final,
            solved: c.solved,
            unsolved_reason: c.unsolved_reason,
            impostors,
            impostors_added,
            impostors_removed,
        })?;
        prev = Some(&c.impostors);
    }
    seq.end()
}

/// Reads [`CpvJson`]s, rebuilding each CPV's list, within half the memory
/// the machine has available.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<PlacedCpv>, D::Error> {
    // Half of it: what reads the placement needs memory of its own.
    let available =
        crate::sysmem::machine_memory_bytes().saturating_sub(crate::sysmem::current_rss_bytes());
    read(d, available / 2)
}

/// Reads [`CpvJson`]s, rebuilding each CPV's list; refuses them once the
/// rebuilt lists take more than `budget` bytes (a list written as a change
/// can be long however short its file: a file of many CPVs that each
/// change nothing repeats one list for each).
fn read<'de, D: Deserializer<'de>>(d: D, budget: u64) -> Result<Vec<PlacedCpv>, D::Error> {
    struct Cpvs {
        budget: u64,
    }
    impl<'de> Visitor<'de> for Cpvs {
        type Value = Vec<PlacedCpv>;

        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("an array of CPVs")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let mut out: Vec<PlacedCpv> = Vec::new();
            let mut bytes = 0u64;
            while let Some(j) = seq.next_element::<CpvJson>()? {
                let k = out.len();
                let bad = |m: String| A::Error::custom(format!("cpvs[{k}]: {m}"));
                let impostors = match (j.impostors, j.impostors_added, j.impostors_removed) {
                    (Some(l), None, None) => l.into_owned(),
                    (None, None, None) => {
                        return Err(bad("no impostor list: give \"impostors\", or \
                                        \"impostors_added\" and \"impostors_removed\""
                            .into()));
                    }
                    (None, added, removed) => {
                        let prev = out.last().ok_or_else(|| {
                            bad("the first CPV lists its impostors whole (\"impostors\"): \
                                 there is no CPV before it to change"
                                .into())
                        })?;
                        apply(
                            &prev.impostors,
                            added.as_deref().unwrap_or_default(),
                            removed.as_deref().unwrap_or_default(),
                        )
                        .map_err(bad)?
                    }
                    (Some(_), _, _) => {
                        return Err(bad("\"impostors\" together with \"impostors_added\" or \
                                        \"impostors_removed\": give one form"
                            .into()));
                    }
                };
                bytes += (std::mem::size_of::<PlacedCpv>() + 4 * impostors.len()) as u64;
                if bytes > self.budget {
                    return Err(bad(format!(
                        "the CPVs' impostor lists rebuilt up to here take {:.2} GB, more than the \
                         {:.2} GB of memory they may use (half of what is available; a list \
                         written as its change from the one before it is as long as the list it \
                         rebuilds, however short the file)",
                        bytes as f64 * 1e-9,
                        self.budget as f64 * 1e-9
                    )));
                }
                out.push(PlacedCpv {
                    id: j.id,
                    region: j.region.into_owned(),
                    directions: j.directions.into_owned(),
                    time_ms_original: j.time_ms_original,
                    time_ms_final: j.time_ms_final,
                    solved: j.solved,
                    unsolved_reason: j.unsolved_reason,
                    impostors,
                });
            }
            Ok(out)
        }
    }
    d.deserialize_seq(Cpvs { budget })
}

/// A placement file's JSON with every CPV's impostor list whole
/// (`impostors`), for code that reads the JSON itself rather than a
/// [`super::Placement`]; an error names what a list's change got wrong.
pub fn whole_lists(placement: &mut serde_json::Value) -> Result<(), serde_json::Error> {
    let rebuilt = deserialize(&placement["cpvs"])?;
    let cpvs = placement["cpvs"]
        .as_array_mut()
        .expect("a list of CPVs was read from it");
    for (c, whole) in cpvs.iter_mut().zip(rebuilt) {
        if let Some(c) = c.as_object_mut() {
            c.remove("impostors_added");
            c.remove("impostors_removed");
            c.insert("impostors".into(), whole.impostors.into());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{Value, json};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Wrap {
        #[serde(with = "super")]
        cpvs: Vec<PlacedCpv>,
    }

    fn cpv(id: u32, impostors: Vec<u32>) -> PlacedCpv {
        PlacedCpv {
            id,
            region: RegionJson {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            directions: DirectionsJson {
                face: 0,
                u: [0.0, 1.0],
                v: [0.0, 1.0],
            },
            time_ms_original: 5.0,
            time_ms_final: 3.0,
            solved: true,
            unsolved_reason: None,
            impostors,
        }
    }

    /// The list fields of each CPV as written.
    fn forms(v: &Value) -> Vec<Value> {
        v["cpvs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                json!([
                    c.get("impostors"),
                    c.get("impostors_added"),
                    c.get("impostors_removed")
                ])
            })
            .collect()
    }

    #[test]
    fn lists_are_written_as_changes_where_shorter_and_read_back_whole() {
        let lists = [
            vec![1, 2, 3, 5, 7],
            vec![1, 2, 3, 5, 8],    // 7 → 8: two ids instead of five
            vec![1, 2, 3, 5, 8, 9], // one added
            vec![],                 // empty: whole (nothing is shorter)
            vec![4],                // one id whole, as short as the change
            vec![9, 3],             // out of order: whole, and the next one too
            vec![3, 9, 10],
            vec![3, 10, 11, 12, 13], // 9 removed, 11..13 added: four of five
            vec![20, 21],            // everything changed: whole
        ];
        let w = Wrap {
            cpvs: lists
                .iter()
                .enumerate()
                .map(|(i, l)| cpv(i as u32, l.clone()))
                .collect(),
        };
        let v = serde_json::to_value(&w).unwrap();
        assert_eq!(
            forms(&v),
            vec![
                json!([[1, 2, 3, 5, 7], null, null]),
                json!([null, [8], [7]]),
                json!([null, [9], []]),
                json!([[], null, null]),
                json!([[4], null, null]),
                json!([[9, 3], null, null]),
                json!([[3, 9, 10], null, null]),
                json!([null, [11, 12, 13], [9]]),
                json!([[20, 21], null, null]),
            ]
        );
        let back: Wrap = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(back, w);
        // The same lists written whole, as plain JSON.
        let mut whole = v;
        whole_lists(&mut whole).unwrap();
        for (c, l) in whole["cpvs"].as_array().unwrap().iter().zip(&lists) {
            assert_eq!(c["impostors"], json!(l));
            assert!(c.get("impostors_added").is_none() && c.get("impostors_removed").is_none());
        }
    }

    #[test]
    fn a_change_is_applied_to_the_list_before_it() {
        let c = |extra: Value| {
            let mut o = json!({"id": 0, "region": {"min": [0, 0, 0], "max": [1, 1, 1]},
                "directions": {"face": 0, "u": [0, 1], "v": [0, 1]},
                "time_ms_original": 5.0, "time_ms_final": 3.0, "solved": true});
            o.as_object_mut()
                .unwrap()
                .extend(extra.as_object().unwrap().clone());
            o
        };
        let read = |cpvs: Vec<Value>| {
            serde_json::from_value::<Wrap>(json!({ "cpvs": cpvs }))
                .map(|w| w.cpvs.into_iter().map(|c| c.impostors).collect::<Vec<_>>())
                .map_err(|e| e.to_string())
        };
        let first = c(json!({"impostors": [2, 4, 6, 8]}));
        assert_eq!(
            read(vec![
                first.clone(),
                c(json!({"impostors_added": [1, 5, 9], "impostors_removed": [4, 8]})),
                c(json!({"impostors_added": [], "impostors_removed": [1, 2, 5, 6, 9]})),
                c(json!({"impostors_added": [7]})),
            ]),
            Ok(vec![vec![2, 4, 6, 8], vec![1, 2, 5, 6, 9], vec![], vec![7]])
        );
        let fails = |second: Value, says: &str| {
            let e = read(vec![first.clone(), c(second)]).unwrap_err();
            assert!(e.contains("cpvs[1]") && e.contains(says), "{e}");
        };
        fails(
            json!({"impostors_removed": [5]}),
            "holds 5, which the CPV before it does not draw",
        );
        fails(json!({"impostors_removed": [8, 9]}), "holds 9, which");
        fails(
            json!({"impostors_added": [4]}),
            "holds 4, which the CPV before it draws already",
        );
        fails(
            json!({"impostors_added": [5, 3]}),
            "impostors_added is not ascending",
        );
        fails(json!({}), "no impostor list");
        fails(
            json!({"impostors": [1], "impostors_added": [2]}),
            "give one form",
        );
        let e = read(vec![c(json!({"impostors_added": [1]}))]).unwrap_err();
        assert!(
            e.contains("cpvs[0]") && e.contains("no CPV before it"),
            "{e}"
        );
        let e = read(vec![
            c(json!({"impostors": [3, 1]})),
            c(json!({"impostors_added": [4]})),
        ])
        .unwrap_err();
        assert!(e.contains("out of order"), "{e}");
    }

    /// A file of many CPVs that each change nothing repeats the first list
    /// for each: reading stops, naming the memory, once the rebuilt lists
    /// pass the budget, not once the machine runs out.
    #[test]
    fn lists_rebuilt_beyond_the_memory_budget_are_refused() {
        let first = cpv(0, (0..1000).collect());
        let mut cpvs =
            vec![serde_json::to_value(Wrap { cpvs: vec![first] }).unwrap()["cpvs"][0].clone()];
        for id in 1..100u32 {
            let mut c = cpvs[0].clone();
            let c_ = c.as_object_mut().unwrap();
            c_.remove("impostors");
            c_.insert("id".into(), json!(id));
            c_.insert("impostors_added".into(), json!([]));
            c_.insert("impostors_removed".into(), json!([]));
            cpvs.push(c);
        }
        let text = serde_json::to_string(&cpvs).unwrap();
        let within = |budget: u64| {
            read(&mut serde_json::Deserializer::from_str(&text), budget).map_err(|e| e.to_string())
        };
        // 100 lists of 1,000 ids: about 400 kB.
        let all = within(1 << 20).unwrap();
        assert_eq!(all.len(), 100);
        assert!(all.iter().all(|c| c.impostors.len() == 1000));
        let e = within(200_000).unwrap_err();
        // The first CPV past it: `k + 1` lists take more than the budget.
        let each = std::mem::size_of::<PlacedCpv>() + 4000;
        let k = 200_000 / each;
        assert!(
            e.contains("of memory they may use") && e.contains(&format!("cpvs[{k}]:")),
            "{e}"
        );
    }
}
