//! The estimate-against-truth section: per method, each sampled problem
//! view's estimated time against the largest exact time sampled in it,
//! and the ratio for every run; and each run's control.

use std::fmt::Write as _;

use super::chart::{Chart, Line, Marker, Series};
use super::*;

/// A run's control, as the tables show it: how many sampled views break
/// the target with no impostor at all, flagged when none does (the run's
/// check could not have failed).
pub(super) fn control_cell(x: &Run) -> String {
    match &x.eval {
        None => "<td class=\"n\">–</td>".into(),
        Some(e) if e.control_violations == 0 => {
            "<td class=\"n bad\" title=\"no sampled view exceeds the target even without \
             impostors: this run's check could not have failed\">0: not exercised</td>"
                .into()
        }
        Some(e) => format!("<td class=\"n\">{}</td>", e.control_violations),
    }
}

impl Page<'_> {
    /// The run whose estimate chart stands for `method`: its base run
    /// (no swept knob), else its first run with estimates.
    fn estimate_run(&self, method: &str) -> Option<&Run> {
        let with =
            |x: &&Run| x.method == method && x.eval.as_ref().is_some_and(|e| e.estimates.is_some());
        let runs = || self.r.runs.iter().filter(with);
        runs().find(|x| x.knob.is_none()).or_else(|| runs().next())
    }

    pub(super) fn estimate_charts(&self, h: &mut String) {
        section_start(h, "estimates", "Estimate against truth");
        h.push_str(
            "<p>A problem view's time is a conservative estimate: no view of it should take \
             longer. Impostors are bought for the estimate's excess over the target, so the \
             gap to the exact views decides how much memory is spent. Each point is one \
             problem view: its estimated time (x) against the largest exact time of the \
             evaluation's sampled views that lie in it (y). Points on the diagonal are exact \
             estimates; points below it are estimates above every sampled view; points \
             left of the target line needed no impostor as far as the samples show.</p>\n",
        );
        let methods: Vec<&str> = self
            .methods
            .iter()
            .copied()
            .filter(|m| self.estimate_run(m).is_some())
            .collect();
        if methods.is_empty() {
            h.push_str(
                "<p class=\"nodata\">No data: no run's evaluation sampled a view inside a \
                 problem view.</p>\n",
            );
        }
        for (i, m) in methods.iter().enumerate() {
            let Some(x) = self.estimate_run(m) else {
                continue;
            };
            let Some(est) = x.eval.as_ref().and_then(|e| e.estimates.as_ref()) else {
                continue;
            };
            let t = x.target_frame_time_ms;
            let mut c = Chart {
                id: format!("chart-estimate-{i}"),
                title: format!("Estimate against truth: {m}, {}", setting(x)),
                desc: format!(
                    "Per sampled problem view of {m}: estimated time in ms against the largest \
                     exact time sampled in it, without impostors and with the placement's, \
                     with the diagonal y = x and the {t} ms target."
                ),
                x_label: "estimated time (ms)".into(),
                y_label: "largest sampled exact time (ms)".into(),
                y_from_zero: true,
                ..Chart::default()
            };
            let mut bare = Series::new(
                "without impostors",
                self.color(m),
                Line::None,
                Marker::Circle,
            );
            let mut with = Series::new("with the placement", INK, Line::None, Marker::Triangle);
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in &est.points {
                bare.points.push((p.estimate_ms, p.exact_max_ms));
                bare.tips.push(format!(
                    "problem view {}: estimated {:.3} ms, exact at most {:.3} ms ({} views)",
                    p.cpv, p.estimate_ms, p.exact_max_ms, p.views
                ));
                with.points
                    .push((p.estimate_final_ms, p.exact_final_max_ms));
                with.tips.push(format!(
                    "problem view {} with its impostors: estimated {:.3} ms, exact at most {:.3} ms",
                    p.cpv, p.estimate_final_ms, p.exact_final_max_ms
                ));
                for v in [
                    p.estimate_ms,
                    p.exact_max_ms,
                    p.estimate_final_ms,
                    p.exact_final_max_ms,
                ] {
                    if v.is_finite() {
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
            }
            if lo.is_finite() {
                let (lo, hi) = (lo.min(t).max(0.0), hi.max(t));
                let mut diag = Series::new("y = x", "#888888", Line::Dashed, Marker::None);
                diag.points = vec![(lo, lo), (hi, hi)];
                diag.guide = true;
                c.series.push(diag);
                let mut target = Series::new(
                    format!("target {t} ms"),
                    "#b00000",
                    Line::Dotted,
                    Marker::None,
                );
                target.points = vec![(lo, t), (hi, t)];
                target.guide = true;
                c.series.push(target);
            }
            c.series.push(bare);
            c.series.push(with);
            let cap = format!(
                "{} of {} sampled problem views shown (the most sampled). Median ratio of the \
                 largest sampled exact time to the estimate: {:.2} without impostors, {:.2} \
                 with them. {} of the {} sampled problem views have no sampled view over the \
                 {t} ms target without impostors.",
                est.points.len(),
                est.cpvs_sampled,
                est.ratio_original_median,
                est.ratio_final_median,
                est.cpvs_never_over,
                est.cpvs_sampled
            );
            figure(h, &c, &esc(&cap));
        }
        self.estimate_table(h);
        self.baked_charts(h);
        h.push_str("</section>\n");
    }

    /// The estimate figures and the control of every run.
    fn estimate_table(&self, h: &mut String) {
        if self.r.runs.is_empty() {
            return;
        }
        h.push_str(
            "<div class=\"wide\"><table class=\"runs\">\n<tr><th>method</th><th>setting</th>\
             <th>target (ms)</th><th>sampled problem views</th>\
             <th>median exact / estimate, no impostors</th>\
             <th>median exact / estimate, with impostors</th>\
             <th>sampled problem views never over the target</th>\
             <th>control: views over the target with no impostor</th></tr>\n",
        );
        for x in &self.r.runs {
            let est = x.eval.as_ref().and_then(|e| e.estimates.as_ref());
            let cell = |f: &dyn Fn(&crate::api::evaluation::EstimateCheck) -> String| {
                est.map_or("–".to_string(), f)
            };
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>{}</tr>",
                esc(&x.method),
                esc(&setting(x)),
                x.target_frame_time_ms,
                cell(&|e| e.cpvs_sampled.to_string()),
                cell(&|e| format!("{:.2}", e.ratio_original_median)),
                cell(&|e| format!("{:.2}", e.ratio_final_median)),
                cell(&|e| e.cpvs_never_over.to_string()),
                control_cell(x)
            );
        }
        h.push_str("</table></div>\n");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::sample_report;

    /// Every method with estimates gets a scatter with its points, the
    /// diagonal and the target; the table lists every run's ratios; a run
    /// whose control is 0 is flagged as not exercising the guarantee, in
    /// the estimate table and in the table of runs, and one with a
    /// control is not.
    #[test]
    fn estimates_are_charted_and_zero_controls_flagged() {
        let mut r = sample_report();
        let html = render_html(&r);
        let section = &html[html.find("<section id=\"estimates\">").unwrap()..];
        let section = &section[..section.find("</section>").unwrap()];
        for (i, m) in Page::new(&r).methods.iter().enumerate() {
            if Page::new(&r).estimate_run(m).is_none() {
                continue;
            }
            let id = format!("chart-estimate-{i}");
            assert!(section.contains(&id), "{m}: no {id}");
        }
        assert!(section.contains("y = x") && section.contains("without impostors"));
        assert!(section.contains("Median ratio"));
        assert!(
            !html.contains("not exercised"),
            "every sample run has a control"
        );

        let x = r.runs.iter_mut().find(|x| x.eval.is_some()).unwrap();
        x.eval.as_mut().unwrap().control_violations = 0;
        let html = render_html(&r);
        // The estimate table and the table of runs both say so.
        assert_eq!(html.matches("0: not exercised").count(), 2);
        // A report without estimates says there is no data.
        for x in &mut r.runs {
            if let Some(e) = &mut x.eval {
                e.estimates = None;
            }
        }
        let html = render_html(&r);
        assert!(html.contains("no run's evaluation sampled a view inside a problem view"));
    }
}
