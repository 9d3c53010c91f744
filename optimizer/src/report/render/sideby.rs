//! Methods side by side: per target, each method's memory and the frame
//! times it achieves over the sampled views and along the walkthrough,
//! charted and tabled, with what kind of guarantee the method gives.

use std::fmt::Write as _;

use super::chart::{Chart, Line, Marker, Series, plottable};
use super::*;

/// What a method promises about frame time, by name.
pub(super) fn guarantee(method: &str) -> &'static str {
    match method {
        "env-map" | "iboh" => "none (placed without the target)",
        "hic96" => "none (a cache built along the path)",
        "dts96" => "estimated, per cell's problem views",
        _ => "estimated, every problem view",
    }
}

/// Largest and 99th-percentile (nearest rank) of finite values.
pub(super) fn max_p99(values: &[f64]) -> Option<(f64, f64)> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let rank = ((0.99 * n as f64).ceil() as usize).clamp(1, n);
    Some((v[n - 1], v[rank - 1]))
}

impl Page<'_> {
    /// The walkthrough of `x`'s method at its target, if the report has one.
    fn walk_of(&self, x: &Run) -> Option<&Walkthrough> {
        self.r.walkthroughs.iter().find(|w| {
            w.method == x.method
                && w.target_frame_time_ms
                    .total_cmp(&x.target_frame_time_ms)
                    .is_eq()
        })
    }

    /// Per target: a chart of each method's memory, one of its achieved
    /// frame times (largest and 99th percentile over the sampled views and
    /// over the walkthrough), and a table of both.
    pub(super) fn side_by_side(&self, h: &mut String) {
        section_start(h, "methods", "Methods side by side");
        h.push_str(
            "<p>Each method at each target: impostor memory (for <code>hic96</code>, a cache \
             built at run time, the largest texture memory it holds along the walkthrough) and \
             the frame times it achieves, largest and 99th percentile, over the evaluation's \
             sampled views and over the walkthrough's frames. Methods without a frame-time \
             guarantee are judged by the same figures; <code>hic96</code> places nothing ahead \
             of time, so it has walkthrough figures only.</p>\n",
        );
        let mut targets: Vec<f64> = self
            .target_runs
            .iter()
            .filter(|x| is_ok(x))
            .map(|x| x.target_frame_time_ms)
            .collect();
        targets.sort_by(f64::total_cmp);
        targets.dedup_by(|a, b| a.total_cmp(b).is_eq());
        if targets.is_empty() {
            h.push_str("<p class=\"nodata\">No data: no run succeeded.</p>\n");
        }
        for (i, &t) in targets.iter().enumerate() {
            let mut runs: Vec<&Run> = self
                .target_runs
                .iter()
                .copied()
                .filter(|x| is_ok(x) && x.target_frame_time_ms.total_cmp(&t).is_eq())
                .collect();
            runs.sort_by_key(|x| self.methods.iter().position(|m| *m == x.method));
            self.side_by_side_at(h, i, t, &runs);
        }
        h.push_str("</section>\n");
    }

    fn side_by_side_at(&self, h: &mut String, index: usize, t: f64, runs: &[&Run]) {
        let names: Vec<String> = runs.iter().map(|x| x.method.clone()).collect();
        let mut memory = Chart {
            id: format!("chart-methods-memory-{index}"),
            title: format!("Memory per method at {} ms", number(t)),
            desc: format!(
                "Impostor memory in MB of each method at the {} ms target, on a log axis.",
                number(t)
            ),
            x_label: "method".into(),
            y_label: "impostor memory (MB)".into(),
            y_log: true,
            x_names: names.clone(),
            ..Chart::default()
        };
        let mut bars = Series::new("memory", INK, Line::None, Marker::Circle);
        for (k, x) in runs.iter().enumerate() {
            bars.points.push((k as f64, mb(x.memory_bytes)));
            bars.tips
                .push(format!("{}: {:.4} MB", x.method, mb(x.memory_bytes)));
        }
        push_nonempty(&mut memory, bars);
        figure(
            h,
            &memory,
            &format!(
                "Impostor memory at {} ms (log scale; <code>hic96</code>: the most it holds at \
                 once along the walkthrough).",
                number(t)
            ),
        );
        let mut times = Chart {
            id: format!("chart-methods-time-{index}"),
            title: format!("Achieved frame time per method at {} ms", number(t)),
            desc: format!(
                "Largest and 99th-percentile frame time in ms over the sampled views and over \
                 the walkthrough, per method, with the {} ms target.",
                number(t)
            ),
            x_label: "method".into(),
            y_label: "frame time (ms)".into(),
            y_from_zero: true,
            x_names: names,
            ..Chart::default()
        };
        let mut target = Series::new(
            format!("target {} ms", number(t)),
            "#b00000",
            Line::Dashed,
            Marker::None,
        );
        target.points = vec![(0.0, t), ((runs.len().max(2) - 1) as f64, t)];
        target.guide = true;
        times.series.push(target);
        let stats: [(&str, &'static str, Marker); 4] = [
            ("max, sampled views", PALETTE[0], Marker::Circle),
            ("p99, sampled views", PALETTE[0], Marker::Cross),
            ("max, walkthrough", PALETTE[1], Marker::Circle),
            ("p99, walkthrough", PALETTE[1], Marker::Cross),
        ];
        let mut rows = String::new();
        let mut series: Vec<Series> = stats
            .iter()
            .map(|(n, c, m)| Series::new(*n, c, Line::None, *m))
            .collect();
        for (k, x) in runs.iter().enumerate() {
            let sampled = x.eval.as_ref().map(|e| (e.max_ms, e.p99_ms));
            let walk = self.walk_of(x).and_then(|w| max_p99(&w.frame_ms));
            let over = self.walk_of(x).map(|w| {
                w.frame_ms
                    .iter()
                    .filter(|&&f| f > x.target_frame_time_ms)
                    .count()
            });
            let vals = [
                sampled.map(|s| s.0),
                sampled.map(|s| s.1),
                walk.map(|w| w.0),
                walk.map(|w| w.1),
            ];
            for (s, v) in series.iter_mut().zip(vals) {
                if let Some(v) = v.filter(|v| plottable(*v)) {
                    s.points.push((k as f64, v));
                    s.tips.push(format!("{}: {} {v:.3} ms", x.method, s.name));
                }
            }
            let cell = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.3}"));
            let cache = x.cache.as_ref().map_or(String::new(), |c| {
                format!(
                    "{} images created ({:.1} a frame), mean {:.3} MB held, first frame {:.2} ms, \
                     {} frames over the target while creating images",
                    c.created,
                    c.created as f64 / c.frames.max(1) as f64,
                    c.mean_bytes / 1e6,
                    c.first_ms,
                    c.over_target_creating
                )
            });
            let unsolved = if x.unsolved_cpvs > 0 {
                format!("{} problem views unsolved", x.unsolved_cpvs)
            } else {
                String::new()
            };
            let _ = writeln!(
                rows,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{:.4}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td>{}</td></tr>",
                esc(&x.method),
                guarantee(&x.method),
                mb(x.memory_bytes),
                cell(vals[0]),
                cell(vals[1]),
                cell(vals[2]),
                cell(vals[3]),
                over.map_or("–".to_string(), |o| o.to_string()),
                esc([unsolved, cache].join(" ").trim()),
            );
        }
        for s in series {
            push_nonempty(&mut times, s);
        }
        figure(
            h,
            &times,
            &format!(
                "Achieved frame time at {} ms: largest (dots) and 99th percentile (crosses) over \
                 the sampled views and over the walkthrough; the target dashed.",
                number(t)
            ),
        );
        let _ = writeln!(
            h,
            "<table><tr><th>method</th><th>frame-time guarantee</th><th>memory, MB</th>\
             <th>max, sampled (ms)</th><th>p99, sampled (ms)</th><th>max, walkthrough (ms)</th>\
             <th>p99, walkthrough (ms)</th><th>walkthrough frames over the target</th>\
             <th>notes</th></tr>\n{rows}</table>"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_and_p99_by_nearest_rank() {
        let v: Vec<f64> = (1..=200).map(f64::from).collect();
        // Rank ⌈0.99 · 200⌉ = 198.
        assert_eq!(max_p99(&v), Some((200.0, 198.0)));
        assert_eq!(max_p99(&[3.0, f64::NAN, 1.0]), Some((3.0, 3.0)));
        assert_eq!(max_p99(&[f64::NAN]), None);
    }
}
