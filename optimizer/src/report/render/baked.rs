//! Estimated against baked memory: for runs whose impostors were baked,
//! each impostor's estimated memory against the memory of the layers the
//! bake wrote, and every baked run's totals.

use std::fmt::Write as _;

use super::chart::{Chart, Line, Marker, Series};
use super::*;

impl Page<'_> {
    /// The baked run whose chart stands for `method`: its base run, else
    /// its first baked run.
    fn baked_run(&self, method: &str) -> Option<&Run> {
        let runs = || {
            self.r
                .runs
                .iter()
                .filter(move |x| x.method == method && x.bake.is_some())
        };
        runs().find(|x| x.knob.is_none()).or_else(|| runs().next())
    }

    /// The charts and table of estimated against baked memory; nothing
    /// when no run was baked.
    pub(super) fn baked_charts(&self, h: &mut String) {
        if !self.r.runs.iter().any(|x| x.bake.is_some()) {
            return;
        }
        h.push_str(
            "<h3>Estimated against baked memory</h3>\n<p>A placement's memory is an \
             estimate: every layer at the resolution its view cell needs. The bake writes \
             only the layers in which some texel is covered, so an impostor's baked memory \
             is at most its estimate. Each point is one impostor: its estimated memory (x) \
             against the memory of its baked layers under the same memory model (y).</p>\n",
        );
        for (i, m) in self.methods.iter().enumerate() {
            let Some(x) = self.baked_run(m) else {
                continue;
            };
            let Some(b) = &x.bake else {
                continue;
            };
            let mut c = Chart {
                id: format!("chart-baked-{i}"),
                title: format!("Estimated against baked memory: {m}, {}", setting(x)),
                desc: format!(
                    "Per impostor of {m}: estimated memory in MB against the memory of its \
                     baked layers in MB, with the diagonal y = x."
                ),
                x_label: "estimated memory (MB)".into(),
                y_label: "baked memory (MB)".into(),
                y_from_zero: true,
                ..Chart::default()
            };
            let mut pts = Series::new("impostors", self.color(m), Line::None, Marker::Circle);
            let mut hi = 0.0f64;
            for p in &b.points {
                let (e, k) = (mb(p.estimated_bytes), mb(p.baked_bytes));
                pts.points.push((e, k));
                pts.tips.push(format!(
                    "impostor {}: estimated {e:.3} MB, baked {k:.3} MB",
                    p.impostor
                ));
                hi = hi.max(e).max(k);
            }
            if hi > 0.0 {
                let mut diag = Series::new("y = x", "#888888", Line::Dashed, Marker::None);
                diag.points = vec![(0.0, 0.0), (hi, hi)];
                diag.guide = true;
                c.series.push(diag);
            }
            c.series.push(pts);
            let cap = format!(
                "{} of {} impostors shown (the largest estimates). Baked {:.3} MB of the \
                 {:.3} MB estimated ({}); {} of {} layers written.",
                b.points.len(),
                x.impostors,
                mb(b.memory_bytes),
                mb(b.estimated_bytes),
                ratio(b.memory_bytes, b.estimated_bytes),
                b.layers_written,
                b.layers
            );
            figure(h, &c, &esc(&cap));
        }
        h.push_str(
            "<div class=\"wide\"><table class=\"runs\">\n<tr><th>method</th><th>setting</th>\
             <th>target (ms)</th><th>estimated (MB)</th><th>baked (MB)</th>\
             <th>baked / estimated</th><th>layers written / asked</th></tr>\n",
        );
        for x in &self.r.runs {
            let Some(b) = &x.bake else {
                continue;
            };
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{:.3}</td>\
                 <td class=\"n\">{:.3}</td><td class=\"n\">{}</td><td class=\"n\">{} / {}</td></tr>",
                esc(&x.method),
                esc(&setting(x)),
                x.target_frame_time_ms,
                mb(b.estimated_bytes),
                mb(b.memory_bytes),
                ratio(b.memory_bytes, b.estimated_bytes),
                b.layers_written,
                b.layers
            );
        }
        h.push_str("</table></div>\n");
    }
}

/// `a / b` with two decimals, or a dash when `b` is 0.
fn ratio(a: u64, b: u64) -> String {
    if b == 0 {
        "–".into()
    } else {
        format!("{:.2}", a as f64 / b as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{BakePoint, BakeSummary};
    use crate::testutil::sample_report;

    /// Without a baked run there is no chart; with one, its method gets a
    /// scatter with the diagonal and a point per impostor listed, and the
    /// table gives the ratio computed by hand (600 of 800 bytes: 0.75).
    #[test]
    fn baked_memory_is_charted_against_the_estimate() {
        let mut r = sample_report();
        assert!(!render_html(&r).contains("Estimated against baked memory"));
        let x = r.runs.iter_mut().find(|x| x.knob.is_none()).unwrap();
        let method = x.method.clone();
        x.bake = Some(BakeSummary {
            memory_bytes: 600,
            estimated_bytes: 800,
            layers: 6,
            layers_written: 5,
            points: vec![
                BakePoint {
                    impostor: 0,
                    estimated_bytes: 500,
                    baked_bytes: 400,
                },
                BakePoint {
                    impostor: 1,
                    estimated_bytes: 300,
                    baked_bytes: 200,
                },
            ],
        });
        let html = render_html(&r);
        let at = html.find("Estimated against baked memory").unwrap();
        let part = &html[at..];
        assert!(part.contains(&format!("Estimated against baked memory: {method}")));
        assert!(part.contains("impostor 1: estimated 0.000 MB, baked 0.000 MB"));
        assert!(part.contains("y = x"));
        assert!(part.contains("<td class=\"n\">0.75</td><td class=\"n\">5 / 6</td>"));
        assert!(part.contains("2 of"));
    }
}
