//! The walkthrough section: one panel per target frame time, each with
//! the path's frame times without impostors, with each method's placement
//! and as each placement estimates them, and the target.

use std::fmt::Write as _;

use super::chart::{Chart, Line, Marker, Series};
use super::*;
use crate::report::Walkthrough;

/// The colour of the frames without impostors.
const BARE: &str = "#999999";
/// The colour of the target lines.
const TARGET: &str = "#b00000";

/// `(frame, value)` of the finite values of `v`.
fn points(v: impl Iterator<Item = f64>) -> Vec<(f64, f64)> {
    v.enumerate()
        .filter(|(_, y)| y.is_finite())
        .map(|(f, y)| (f as f64, y))
        .collect()
}

impl Page<'_> {
    pub(super) fn walkthrough_charts(&self, h: &mut String) {
        section_start(h, "walkthrough", "Frame time along the walkthrough");
        let ws = &self.r.walkthroughs;
        h.push_str(
            "<p>The walkthrough follows the job's path or, without one, a tour through the \
             view regions whose frame times without impostors are highest (the camera turns to \
             face each stop's slowest direction). One panel per target frame time: the frames \
             with no impostor (grey), with each method's placement (solid), the placement's \
             estimate for the problem view the camera is in (dotted; none outside problem \
             views) and the target (red, dashed). Rings mark frames over the target. Where \
             methods place no impostor their lines are the no-impostor line, drawn over it \
             in the legend's order.</p>\n",
        );
        let mut targets: Vec<f64> = ws.iter().map(|w| w.target_frame_time_ms).collect();
        targets.sort_by(f64::total_cmp);
        targets.dedup_by(|a, b| a.total_cmp(b).is_eq());
        if ws.is_empty() {
            h.push_str("<p class=\"nodata\">No data: the report has no walkthrough.</p>\n");
        }
        for (i, &t) in targets.iter().enumerate() {
            let mut mine: Vec<&Walkthrough> = ws
                .iter()
                .filter(|w| w.target_frame_time_ms.total_cmp(&t).is_eq())
                .collect();
            mine.sort_by_key(|w| self.methods.iter().position(|m| *m == w.method));
            self.walkthrough_panel(h, i, t, &mine);
        }
        h.push_str("</section>\n");
    }

    /// The panel of target `t` with the walkthroughs `ws` (one per method).
    fn walkthrough_panel(&self, h: &mut String, i: usize, t: f64, ws: &[&Walkthrough]) {
        let frames = ws.iter().map(|w| w.frame_ms.len()).max().unwrap_or(0);
        let mut c = Chart {
            id: format!("chart-walk-{i}"),
            title: format!("Frame time along the walkthrough, target {t} ms"),
            desc: format!(
                "Frame time in ms at each frame of the walkthrough: without impostors, with \
                 each method's placement for the {t} ms target, and the placement's estimate, \
                 with the target as a dashed line."
            ),
            x_label: "frame index".into(),
            y_label: "frame time (ms)".into(),
            y_from_zero: true,
            ..Chart::default()
        };
        let mut notes = Vec::new();
        // Without impostors: the same for every method (the first that has it).
        let bare = ws
            .iter()
            .find(|w| !w.bare_ms.is_empty())
            .map(|w| &w.bare_ms);
        if let Some(b) = bare {
            let mut s = Series::new("no impostors", BARE, Line::Solid, Marker::None);
            s.points = points(b.iter().copied());
            c.series.push(s);
            let over = b.iter().filter(|ms| **ms > t).count();
            notes.push(format!(
                "without impostors {over} of {} frames are over the target",
                b.len()
            ));
            if over == 0 {
                notes.push(
                    "no frame of the path exceeds this target even without impostors, so \
                     this panel cannot show impostors at work"
                        .into(),
                );
            }
        }
        let mut target = Series::new(format!("target {t} ms"), TARGET, Line::Dashed, Marker::None);
        target.points = vec![(0.0, t), (frames.saturating_sub(1).max(1) as f64, t)];
        target.guide = true;
        c.series.push(target);
        for (k, w) in ws.iter().enumerate() {
            let col = self.color(&w.method);
            let mut s = Series::new(w.method.clone(), col, Line::Solid, Marker::None);
            s.points = points(w.frame_ms.iter().copied());
            c.series.push(s);
            // The estimate, one series per stretch inside problem views.
            let mut first = true;
            let mut run: Vec<(f64, f64)> = Vec::new();
            let mut flush = |run: &mut Vec<(f64, f64)>, c: &mut Chart| {
                if run.is_empty() {
                    return;
                }
                let name = if first {
                    format!("{}: estimate", w.method)
                } else {
                    String::new()
                };
                first = false;
                let mut e = Series::new(name, col, Line::Dotted, Marker::None);
                e.points = std::mem::take(run);
                c.series.push(e);
            };
            for (f, e) in w.estimate_ms.iter().enumerate() {
                match e {
                    Some(ms) if ms.is_finite() => run.push((f as f64, *ms)),
                    _ => flush(&mut run, &mut c),
                }
            }
            flush(&mut run, &mut c);
            let mut hot = Series::new("", INK, Line::None, Marker::Ring);
            for (f, ms) in w.frame_ms.iter().enumerate().filter(|(_, ms)| **ms > t) {
                hot.points.push((f as f64, *ms));
                let unsolved = w
                    .estimate_ms
                    .get(f)
                    .copied()
                    .flatten()
                    .is_some_and(|e| e > t);
                hot.tips.push(format!(
                    "{} frame {f}: {ms:.3} ms, over the {t} ms target{}",
                    w.method,
                    if unsolved {
                        " (in an unsolved problem view)"
                    } else {
                        ""
                    }
                ));
            }
            hot.guide = true;
            if !hot.points.is_empty() {
                hot.name = format!("{}: over {t} ms", w.method);
                c.series.push(hot);
            }
            let n = w.frame_ms.iter().filter(|ms| **ms > t).count();
            notes.push(format!(
                "{}: {n} of {} frames over",
                esc(&w.method),
                w.frame_ms.len()
            ));
            // Lines drawn on top of each other are said so.
            for other in &ws[..k] {
                if other.frame_ms == w.frame_ms {
                    notes.push(format!(
                        "{} and {} have the same frame times: one line hides the other",
                        esc(&other.method),
                        esc(&w.method)
                    ));
                }
            }
            if bare.is_some_and(|b| *b == w.frame_ms) {
                notes.push(format!(
                    "{} uses no impostor along the path: its line is the no-impostor line",
                    esc(&w.method)
                ));
            }
        }
        let mut cap = String::new();
        let _ = write!(cap, "Target {t} ms: {}.", notes.join("; "));
        figure(h, &c, &cap);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::sample_report;

    /// One panel per target, each with the no-impostor line, every
    /// method's frames and estimate, and the target; frames over the
    /// target in an unsolved problem view say so; lines that coincide are
    /// named in the caption.
    #[test]
    fn panels_per_target_with_bare_and_estimate_lines() {
        let mut r = sample_report();
        let html = render_html(&r);
        let svg = |id: &str| {
            let fig = &html[html.find(&format!("<figure id=\"{id}\">")).unwrap()..];
            fig[..fig.find("</figure>").unwrap()].to_string()
        };
        // Targets 10 and 20 ms: two panels; the second has both methods.
        let (p10, p20) = (svg("chart-walk-0"), svg("chart-walk-1"));
        assert!(!html.contains("chart-walk-2"));
        for p in [&p10, &p20] {
            assert!(
                p.contains("no impostors") && p.contains("shafts: estimate"),
                "{p}"
            );
        }
        assert!(p10.contains("target 10 ms") && !p10.contains(">boxes"));
        assert!(p20.contains("boxes: estimate") && p20.contains("target 20 ms"));
        assert!(
            p20.contains("without impostors 23 of 60 frames are over the target"),
            "{p20}"
        );
        assert!(!p20.contains("same frame times"));
        // The boxes' bump at frame 30 (21 ms) lies where its estimate is 19.6 ms:
        // solved, so not marked unsolved.
        assert!(p20.contains("boxes frame 30: 21.000 ms, over the 20 ms target<"));
        // Identical lines are said so.
        let shafts = r.walkthroughs[1].frame_ms.clone();
        r.walkthroughs[2].frame_ms = shafts;
        let html = render_html(&r);
        assert!(html.contains("shafts and boxes have the same frame times"));
    }
}
