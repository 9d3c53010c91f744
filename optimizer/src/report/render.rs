//! HTML and CSV rendering of a [`Report`]: one self-contained page (inline
//! CSS and SVG charts, no scripts, no external resources) and the data as
//! CSV files.
//!
//! How runs become charts:
//! - **Memory vs target** and **achieved vs target**: the runs whose knob is
//!   `target_frame_time_ms`, plus each base run (knob `None`) whose method
//!   has no target-sweep run at the base run's target; x is the run's
//!   `target_frame_time_ms`.
//! - **Preprocessing time vs memory**: one chart per other knob (the
//!   report's sweeps in order, then knobs found only in runs), from the runs
//!   with that knob.
//! - **Walkthrough**: one chart per method of `walkthroughs`, one line per
//!   target.
//!
//! Failed runs (status other than `ok`) and values that cannot be placed
//! on an axis are left out of the charts and listed under them; every run
//! is in the table. Memory is in MB (10⁶ bytes).

mod chart;
mod csv;

use std::fmt::Write as _;

use self::chart::{Chart, Line, Marker, Series, number, plottable};
pub use self::csv::csv_files;
use super::{MethodStability, Report, Run, RunStatus};

/// The knob of the target frame time sweep.
const TARGET_KNOB: &str = "target_frame_time_ms";
/// Series colours, by method (or target) index.
const PALETTE: [&str; 10] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
    "#7f7f7f", "#bcbd22",
];
/// Colour of guides and the Pareto front.
const INK: &str = "#222222";

/// The report as one self-contained HTML5 page: the setup (scene, machine,
/// base job, methods, sweeps), the charts (memory vs target frame time,
/// achieved vs target frame time, preprocessing time vs memory per knob,
/// frame time along each method's walkthrough, memory under perturbations),
/// the stability tables and a table of every run. A chart without at least
/// two plottable points is replaced by a "No data" note. All text from the
/// report is HTML-escaped.
pub fn render_html(r: &Report) -> String {
    let p = Page::new(r);
    let mut h = String::with_capacity(64 * 1024);
    let title = if r.scene.name.is_empty() {
        "Impostor placement report".to_string()
    } else {
        format!("Impostor placement report: {}", r.scene.name)
    };
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
        esc(&title),
        esc(&title)
    );
    p.setup(&mut h);
    h.push_str("<nav><a href=\"#memory\">Memory</a> · <a href=\"#achieved\">Frame time</a> · <a href=\"#speed\">Speed vs accuracy</a> · <a href=\"#walkthrough\">Walkthrough</a> · <a href=\"#stability\">Stability</a> · <a href=\"#runs\">Runs</a></nav>\n");
    p.memory_chart(&mut h);
    p.achieved_chart(&mut h);
    p.speed_charts(&mut h);
    p.walkthrough_charts(&mut h);
    p.stability(&mut h);
    p.runs_table(&mut h);
    h.push_str("</body>\n</html>\n");
    h
}

/// Page styles.
const CSS: &str = "body{font-family:system-ui,sans-serif;max-width:1100px;margin:0 auto;padding:1em;color:#222;line-height:1.4}\
h1{font-size:1.6em}h2{margin-top:2em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}\
th,td{border:1px solid #ccc;padding:.2em .5em;text-align:left;vertical-align:top}\
th{background:#f0f0f0}td.n{text-align:right;font-variant-numeric:tabular-nums}\
tr:nth-child(even) td{background:#fafafa}.wide{overflow-x:auto}\
table.runs{font-size:.78em}table.runs th,table.runs td{padding:.2em .35em}table.runs td:nth-child(-n+2){white-space:nowrap}tr.error td{color:#b00;background:#fff4f4}\
.bad{color:#b00;font-weight:bold}.nodata{padding:1em;background:#f6f6f6;border:1px dashed #bbb}\
figure{margin:1em 0}figcaption{font-size:.95em;color:#333}svg.chart{display:block}\
pre{background:#f6f6f6;padding:.5em;overflow:auto;max-height:30em}\
.swatch{display:inline-block;width:.9em;height:.9em;margin-right:.3em;vertical-align:middle}";

/// HTML-escapes text for element content and attribute values.
pub(crate) fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// The report plus what the sections share: the method order (for
/// colours) and the runs of the target sweep.
struct Page<'a> {
    r: &'a Report,
    /// Every method seen, in the report's order, then by first appearance.
    methods: Vec<&'a str>,
    /// The runs at the x of the target charts.
    target_runs: Vec<&'a Run>,
}

impl<'a> Page<'a> {
    fn new(r: &'a Report) -> Self {
        let mut methods: Vec<&str> = Vec::new();
        let seen = r
            .methods
            .iter()
            .chain(r.runs.iter().map(|x| &x.method))
            .chain(r.walkthroughs.iter().map(|w| &w.method))
            .chain(
                r.stability
                    .iter()
                    .flat_map(|s| s.methods.iter().map(|m| &m.method)),
            );
        for m in seen {
            if !methods.contains(&m.as_str()) {
                methods.push(m);
            }
        }
        let sweep: Vec<&Run> = r
            .runs
            .iter()
            .filter(|x| x.knob.as_deref() == Some(TARGET_KNOB))
            .collect();
        let base = r.runs.iter().filter(|b| {
            b.knob.is_none()
                && !sweep.iter().any(|s| {
                    s.method == b.method && s.target_frame_time_ms == b.target_frame_time_ms
                })
        });
        let target_runs = sweep.iter().copied().chain(base).collect();
        Self {
            r,
            methods,
            target_runs,
        }
    }

    /// The colour of a method.
    fn color(&self, method: &str) -> &'static str {
        let i = self.methods.iter().position(|m| *m == method).unwrap_or(0);
        PALETTE[i % PALETTE.len()]
    }

    /// The methods in page order that have some of `runs`.
    fn methods_of(&self, runs: &[&Run]) -> Vec<&'a str> {
        self.methods
            .iter()
            .copied()
            .filter(|m| runs.iter().any(|x| x.method == *m))
            .collect()
    }

    fn setup(&self, h: &mut String) {
        let r = self.r;
        let s = &r.scene;
        h.push_str("<section id=\"setup\"><h2>Setup</h2>\n<table>\n");
        let memory = if r.machine.memory_bytes == 0 {
            "unknown".to_string()
        } else {
            format!("{:.1} GB", r.machine.memory_bytes as f64 / 1e9)
        };
        let rows = [
            ("Scene", s.name.clone()),
            ("Objects", s.objects.to_string()),
            ("Triangles", s.triangles.to_string()),
            ("Bounds (m)", format!("{} to {}", vec3(s.min), vec3(s.max))),
            ("Tool version", r.version.clone()),
            ("Created (UTC)", r.created.clone()),
            ("Operating system", r.machine.os.clone()),
            ("CPU", r.machine.cpu.clone()),
            ("Threads", r.machine.threads.to_string()),
            ("Memory", memory),
        ];
        for (k, v) in rows {
            let _ = writeln!(h, "<tr><th>{k}</th><td>{}</td></tr>", esc(&v));
        }
        h.push_str("</table>\n<h3>Methods</h3>\n");
        if self.methods.is_empty() {
            h.push_str("<p>None.</p>\n");
        } else {
            h.push_str("<ul>");
            for m in &self.methods {
                let _ = write!(
                    h,
                    "<li><span class=\"swatch\" style=\"background:{}\"></span>{}</li>",
                    self.color(m),
                    esc(m)
                );
            }
            h.push_str("</ul>\n");
        }
        h.push_str("<h3>Sweeps</h3>\n");
        if r.sweeps.is_empty() {
            h.push_str("<p>None: only the base job.</p>\n");
        } else {
            h.push_str("<ul>");
            for sw in &r.sweeps {
                let vals: Vec<String> = sw.values.iter().map(|v| v.to_string()).collect();
                let _ = write!(
                    h,
                    "<li><code>{}</code>: {}</li>",
                    esc(&sw.knob),
                    esc(&vals.join(", "))
                );
            }
            h.push_str("</ul>\n");
        }
        let job = serde_json::to_string_pretty(&r.job).unwrap_or_else(|_| r.job.to_string());
        let _ = writeln!(
            h,
            "<details><summary>Base job (every run starts from it)</summary><pre>{}</pre></details>\n</section>",
            esc(&job)
        );
    }

    fn memory_chart(&self, h: &mut String) {
        let runs = &self.target_runs;
        let mut c = Chart {
            id: "chart-memory".into(),
            title: "Impostor memory vs target frame time".into(),
            desc: "Impostor memory in MB on a log scale against the target frame time in ms, one line per method.".into(),
            x_label: "target frame time (ms)".into(),
            y_label: "impostor memory (MB, log scale)".into(),
            y_log: true,
            ..Chart::default()
        };
        let mut zeros = 0;
        for m in self.methods_of(runs) {
            let mut ok: Vec<&Run> = runs
                .iter()
                .copied()
                .filter(|x| x.method == m && is_ok(x))
                .collect();
            ok.sort_by(|a, b| a.target_frame_time_ms.total_cmp(&b.target_frame_time_ms));
            let mut line = Series::new(m, self.color(m), Line::Solid, Marker::Circle);
            let mut zero = Series::new(
                format!("{m}: 0 MB (at axis floor)"),
                self.color(m),
                Line::None,
                Marker::Cross,
            );
            for x in ok {
                let s = if x.memory_bytes == 0 {
                    &mut zero
                } else {
                    &mut line
                };
                s.points.push((x.target_frame_time_ms, mb(x.memory_bytes)));
                s.tips.push(format!(
                    "{m}, {}: target {} ms, {:.3} MB, {} impostors",
                    setting(x),
                    x.target_frame_time_ms,
                    mb(x.memory_bytes),
                    x.impostors
                ));
            }
            zeros += zero.points.len();
            push_nonempty(&mut c, line);
            push_nonempty(&mut c, zero);
        }
        let mut cap = String::from(
            "Impostor memory of each method against the target frame time: the runs of the target \
             sweep, and base runs at their own target. Lower is better.",
        );
        if zeros > 0 {
            let _ = write!(
                cap,
                " {zeros} run(s) needed no impostors (0 MB), which a log axis cannot show: \
                 they are drawn as × on the axis floor, one decade below the smallest memory."
            );
        }
        section_start(h, "memory", "Memory vs target frame time");
        figure(h, &c, &cap);
        self.left_out(h, runs, false, is_ok);
        h.push_str("</section>\n");
    }

    fn achieved_chart(&self, h: &mut String) {
        let runs = &self.target_runs;
        let mut c = Chart {
            id: "chart-achieved".into(),
            title: "Achieved frame time vs target".into(),
            desc: "Evaluated frame time in ms against the target frame time in ms per method: maximum, 99th percentile and maximum in solved problem views, with the guarantee line y = x.".into(),
            x_label: "target frame time (ms)".into(),
            y_label: "achieved frame time (ms)".into(),
            ..Chart::default()
        };
        let evaluated = |x: &Run| is_ok(x) && x.eval.is_some();
        let mut xs = Vec::new();
        for m in self.methods_of(runs) {
            let mut ok: Vec<&Run> = runs
                .iter()
                .copied()
                .filter(|x| x.method == m && evaluated(x))
                .collect();
            ok.sort_by(|a, b| a.target_frame_time_ms.total_cmp(&b.target_frame_time_ms));
            let col = self.color(m);
            let mut max = Series::new(format!("{m}: max"), col, Line::Solid, Marker::Circle);
            let mut p99 = Series::new(format!("{m}: p99"), col, Line::Dashed, Marker::Square);
            let mut sol = Series::new(
                format!("{m}: max in solved"),
                col,
                Line::Dotted,
                Marker::Triangle,
            );
            for x in ok {
                let Some(e) = &x.eval else { continue };
                let t = x.target_frame_time_ms;
                if plottable(t) {
                    xs.push(t);
                }
                let tip = |what: &str, v: f64| format!("{m}, target {t} ms: {what} {v:.3} ms");
                max.points.push((t, e.max_ms));
                max.tips.push(tip("max", e.max_ms));
                p99.points.push((t, e.p99_ms));
                p99.tips.push(tip("p99", e.p99_ms));
                sol.points.push((t, e.max_ms_in_solved));
                sol.tips
                    .push(tip("max in solved problem views", e.max_ms_in_solved));
            }
            push_nonempty(&mut c, max);
            push_nonempty(&mut c, p99);
            push_nonempty(&mut c, sol);
        }
        let mut crossed = Series::new(
            "guarantee crossed (max in solved)",
            INK,
            Line::None,
            Marker::Ring,
        );
        for x in runs.iter().filter(|x| evaluated(x)) {
            if let Some(e) = x.eval.as_ref().filter(|e| e.violations_in_solved > 0) {
                crossed
                    .points
                    .push((x.target_frame_time_ms, e.max_ms_in_solved));
                crossed.tips.push(format!(
                    "{}, target {} ms: {} view(s) over the target in solved problem views",
                    x.method, x.target_frame_time_ms, e.violations_in_solved
                ));
            }
        }
        crossed.guide = true;
        push_nonempty(&mut c, crossed);
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo.is_finite() && hi.is_finite() {
            let (a, b) = if hi > lo {
                (lo, hi)
            } else {
                (lo * 0.9, hi * 1.1)
            };
            let mut g = Series::new("guarantee: y = x", INK, Line::Solid, Marker::None);
            g.points = vec![(a, a), (b, b)];
            g.labels = vec![String::new(), "y = x".into()];
            g.guide = true;
            c.series.push(g);
        }
        section_start(h, "achieved", "Achieved frame time vs target");
        figure(
            h,
            &c,
            "Evaluated frame time against the target: maximum over the sampled views (solid), \
             99th percentile (dashed), and maximum over the views in solved problem views or in \
             none (dotted), the quantity the placement guarantees to stay on or under the line \
             y = x. A ring marks a run that crossed it.",
        );
        let _ = writeln!(h, "<p class=\"verdict\">{}</p>", self.verdict());
        self.left_out(h, runs, true, evaluated);
        h.push_str("</section>\n");
    }

    /// Whether any evaluated run crossed the guarantee in solved problem
    /// views, naming them.
    fn verdict(&self) -> String {
        let evaluated: Vec<&Run> = self.r.runs.iter().filter(|x| x.eval.is_some()).collect();
        if evaluated.is_empty() {
            return "No run was evaluated, so the guarantee was not checked.".into();
        }
        let crossed: Vec<String> = evaluated
            .iter()
            .filter_map(|x| {
                let e = x.eval.as_ref()?;
                (e.violations_in_solved > 0).then(|| {
                    format!(
                        "<strong>{}</strong> ({}, target {} ms: {} view(s) over the target, max {:.3} ms)",
                        esc(&x.method),
                        esc(&setting(x)),
                        x.target_frame_time_ms,
                        e.violations_in_solved,
                        e.max_ms_in_solved
                    )
                })
            })
            .collect();
        if crossed.is_empty() {
            format!(
                "Guarantee: no method crossed the guarantee line in solved problem views \
                 (0 views over the target in all {} evaluated runs).",
                evaluated.len()
            )
        } else {
            format!(
                "<span class=\"bad\">Guarantee crossed</span> in solved problem views by: {}.",
                crossed.join("; ")
            )
        }
    }

    /// Lists the `runs` that `shown` left out of a chart, with the reason.
    fn left_out(
        &self,
        h: &mut String,
        runs: &[&Run],
        needs_eval: bool,
        shown: impl Fn(&Run) -> bool,
    ) {
        let out: Vec<&&Run> = runs.iter().filter(|x| !shown(x)).collect();
        if out.is_empty() {
            return;
        }
        h.push_str("<p>Not in the chart:</p><ul class=\"left-out\">");
        for x in out {
            let why = if x.status != RunStatus::Ok {
                format!(
                    "{}: {}",
                    x.status.as_str(),
                    x.error.as_deref().unwrap_or("no error given")
                )
            } else if needs_eval && x.eval.is_none() {
                "not evaluated".to_string()
            } else {
                "values not finite".to_string()
            };
            let _ = write!(
                h,
                "<li>{} ({}, target {} ms): {}</li>",
                esc(&x.method),
                esc(&setting(x)),
                x.target_frame_time_ms,
                esc(&why)
            );
        }
        h.push_str("</ul>\n");
    }

    fn speed_charts(&self, h: &mut String) {
        section_start(
            h,
            "speed",
            "Preprocessing time vs memory (speed against accuracy)",
        );
        let mut knobs: Vec<&str> = Vec::new();
        let all = self
            .r
            .sweeps
            .iter()
            .map(|s| s.knob.as_str())
            .chain(self.r.runs.iter().filter_map(|x| x.knob.as_deref()));
        for k in all {
            if k != TARGET_KNOB && !knobs.contains(&k) {
                knobs.push(k);
            }
        }
        if knobs.is_empty() {
            h.push_str("<p class=\"nodata\">No data: the report sweeps no knob other than the target frame time.</p>\n");
        }
        for (i, k) in knobs.iter().enumerate() {
            let runs: Vec<&Run> = self
                .r
                .runs
                .iter()
                .filter(|x| x.knob.as_deref() == Some(*k))
                .collect();
            self.speed_chart(h, i, k, &runs);
        }
        h.push_str("</section>\n");
    }

    fn speed_chart(&self, h: &mut String, index: usize, knob: &str, runs: &[&Run]) {
        let mut c = Chart {
            id: format!("chart-speed-{index}"),
            title: format!("Preprocessing time vs memory: {knob}"),
            desc: format!(
                "Impostor memory in MB on a log scale against preprocessing time in seconds for the runs of the {knob} sweep, with the Pareto front."
            ),
            x_label: "preprocessing time (s)".into(),
            y_label: "impostor memory (MB, log scale)".into(),
            y_log: true,
            ..Chart::default()
        };
        let shown = |x: &Run| x.status == RunStatus::Ok && plottable(x.seconds);
        let ok: Vec<&Run> = runs.iter().copied().filter(|x| shown(x)).collect();
        for m in self.methods_of(&ok) {
            let mut pts = Series::new(m, self.color(m), Line::None, Marker::Circle);
            let mut zero = Series::new(
                format!("{m}: 0 MB (at axis floor)"),
                self.color(m),
                Line::None,
                Marker::Cross,
            );
            for x in ok.iter().filter(|x| x.method == m) {
                let s = if x.memory_bytes == 0 {
                    &mut zero
                } else {
                    &mut pts
                };
                s.points.push((x.seconds, mb(x.memory_bytes)));
                s.labels
                    .push(x.value.map(|v| v.to_string()).unwrap_or_default());
                s.tips.push(format!(
                    "{m}, {}: {:.3} s, {:.3} MB",
                    setting(x),
                    x.seconds,
                    mb(x.memory_bytes)
                ));
            }
            push_nonempty(&mut c, pts);
            push_nonempty(&mut c, zero);
        }
        let front = pareto_front(&ok);
        let mut line = Series::new(
            "Pareto front (not dominated)",
            INK,
            Line::Solid,
            Marker::Ring,
        );
        line.points = front
            .iter()
            .map(|x| (x.seconds, mb(x.memory_bytes)))
            .collect();
        line.guide = true;
        if !front.is_empty() {
            c.series.push(line);
        }
        let cap = format!(
            "Preprocessing (placement) time against impostor memory for the runs of the \
             <code>{}</code> sweep; point labels are the knob's values, × marks runs with 0 MB \
             drawn on the axis floor. Ringed points joined by the black line form the Pareto \
             front: no other run is both at most as slow and at most as large, and better in \
             one.",
            esc(knob)
        );
        figure(h, &c, &cap);
        if !front.is_empty() {
            let _ = write!(
                h,
                "<p>Pareto front of <code>{}</code>:</p><ul class=\"pareto\" id=\"pareto-{index}\">",
                esc(knob)
            );
            for x in &front {
                let _ = write!(
                    h,
                    "<li>{} {}: {:.3} s, {:.3} MB</li>",
                    esc(&x.method),
                    esc(&setting(x)),
                    x.seconds,
                    mb(x.memory_bytes)
                );
            }
            h.push_str("</ul>\n");
        }
        self.left_out(h, runs, false, shown);
    }

    fn walkthrough_charts(&self, h: &mut String) {
        section_start(h, "walkthrough", "Frame time along the walkthrough");
        let ws = &self.r.walkthroughs;
        let mut targets: Vec<f64> = ws.iter().map(|w| w.target_frame_time_ms).collect();
        targets.sort_by(f64::total_cmp);
        targets.dedup();
        let color = |t: f64| {
            let i = targets.iter().position(|x| *x == t).unwrap_or(0);
            PALETTE[i % PALETTE.len()]
        };
        let methods: Vec<&str> = self
            .methods
            .iter()
            .copied()
            .filter(|m| ws.iter().any(|w| w.method == *m))
            .collect();
        if methods.is_empty() {
            h.push_str("<p class=\"nodata\">No data: the report has no walkthrough.</p>\n");
        }
        for (i, m) in methods.iter().enumerate() {
            let mut mine: Vec<_> = ws.iter().filter(|w| w.method == *m).collect();
            mine.sort_by(|a, b| a.target_frame_time_ms.total_cmp(&b.target_frame_time_ms));
            let frames = mine.iter().map(|w| w.frame_ms.len()).max().unwrap_or(0);
            let mut c = Chart {
                id: format!("chart-walk-{i}"),
                title: format!("Frame time along the walkthrough: {m}"),
                desc: format!(
                    "Frame time in ms at each frame of the walkthrough path for {m}, one line per target frame time, dashed lines at the targets."
                ),
                x_label: "frame index".into(),
                y_label: "frame time (ms)".into(),
                y_from_zero: true,
                ..Chart::default()
            };
            let mut over = Vec::new();
            for w in &mine {
                let t = w.target_frame_time_ms;
                let col = color(t);
                let mut s = Series::new(
                    format!("frames, target {t} ms"),
                    col,
                    Line::Solid,
                    Marker::None,
                );
                s.points = w
                    .frame_ms
                    .iter()
                    .enumerate()
                    .map(|(f, ms)| (f as f64, *ms))
                    .collect();
                c.series.push(s);
                let mut g = Series::new(format!("target {t} ms"), col, Line::Dashed, Marker::None);
                g.points = vec![(0.0, t), (frames.saturating_sub(1).max(1) as f64, t)];
                g.guide = true;
                c.series.push(g);
                let mut hot = Series::new("", INK, Line::None, Marker::Ring);
                for (f, ms) in w.frame_ms.iter().enumerate().filter(|(_, ms)| **ms > t) {
                    hot.points.push((f as f64, *ms));
                    hot.tips
                        .push(format!("frame {f}: {ms:.3} ms, over the {t} ms target"));
                }
                hot.guide = true;
                if !hot.points.is_empty() {
                    hot.name = format!("over {t} ms");
                    c.series.push(hot);
                }
                let n = w.frame_ms.iter().filter(|ms| **ms > t).count();
                let max = w.frame_ms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                over.push(format!(
                    "target {t} ms: {n} of {} frames over (max {})",
                    w.frame_ms.len(),
                    if max.is_finite() {
                        format!("{max:.3} ms")
                    } else {
                        "n/a".into()
                    }
                ));
            }
            let cap = format!(
                "Frame time of {} at each frame of the walkthrough path, one line per target \
                 frame time; the dashed line of the same colour is the target, rings mark frames over \
                 it. {}.",
                esc(m),
                esc(&over.join("; "))
            );
            figure(h, &c, &cap);
        }
        h.push_str("</section>\n");
    }

    fn stability(&self, h: &mut String) {
        let Some(st) = &self.r.stability else {
            return;
        };
        section_start(h, "stability", "Stability under perturbed inputs");
        let names: Vec<String> = st.methods.iter().map(|m| m.method.clone()).collect();
        let mut c = Chart {
            id: "chart-stability".into(),
            title: "Memory under perturbations".into(),
            desc:
                "Impostor memory in MB on a log scale of each method under each perturbed setting."
                    .into(),
            x_label: "method".into(),
            y_label: "impostor memory (MB, log scale)".into(),
            y_log: true,
            x_names: names,
            ..Chart::default()
        };
        let mut base = Series::new("unperturbed base", INK, Line::None, Marker::Ring);
        for (i, m) in st.methods.iter().enumerate() {
            let x = i as f64;
            let mut ok: Vec<_> = m
                .settings
                .iter()
                .filter(|p| p.status == RunStatus::Ok)
                .collect();
            ok.sort_by_key(|p| p.memory_bytes);
            let mut s = Series::new(
                m.method.clone(),
                self.color(&m.method),
                Line::Solid,
                Marker::Circle,
            );
            for p in ok {
                s.points.push((x, mb(p.memory_bytes)));
                s.tips.push(format!(
                    "{}, {}: {:.3} MB",
                    m.method,
                    p.label,
                    mb(p.memory_bytes)
                ));
            }
            push_nonempty(&mut c, s);
            if let Some(p) = m.settings.first().filter(|p| p.status == RunStatus::Ok) {
                base.points.push((x, mb(p.memory_bytes)));
                base.tips.push(format!(
                    "{}, {}: {:.3} MB",
                    m.method,
                    p.label,
                    mb(p.memory_bytes)
                ));
            }
        }
        base.guide = true;
        push_nonempty(&mut c, base);
        figure(
            h,
            &c,
            "Impostor memory of each method under each perturbed setting: the dots are the \
             settings, the vertical bar spans their range, the ring marks the unperturbed base. \
             Settings with 0 MB are drawn on the axis floor; failed settings are left out.",
        );
        for m in &st.methods {
            stability_table(h, m);
        }
        h.push_str("</section>\n");
    }

    fn runs_table(&self, h: &mut String) {
        section_start(h, "runs", "All runs");
        h.push_str(
            "<div class=\"wide\"><table class=\"runs\">\n<tr><th>method</th><th>setting</th><th>target (ms)</th>\
             <th>CPVs</th><th>candidates</th><th>impostors</th><th>memory (MB)</th>\
             <th>unsolved CPVs</th><th>preprocessing (s)</th><th>eval max (ms)</th>\
             <th>eval p99 (ms)</th><th>max in solved (ms)</th><th>violations in solved</th>\
             <th>parallax max (px)</th><th>status</th></tr>\n",
        );
        if self.r.runs.is_empty() {
            h.push_str("<tr><td colspan=\"15\">No runs.</td></tr>\n");
        }
        for x in &self.r.runs {
            let e = x.eval.as_ref();
            let ms = |f: fn(&super::EvalSummary) -> f64| {
                e.map_or("–".into(), |e| format!("{:.3}", f(e)))
            };
            let viol = e.map_or("–".to_string(), |e| e.violations_in_solved.to_string());
            let bad_viol = e.is_some_and(|e| e.violations_in_solved > 0);
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.3}</td>\
                 <td class=\"n{}\">{}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n{}\">{}</td>\
                 <td class=\"n\">{}</td><td{}>{}</td></tr>",
                esc(&x.method),
                esc(&setting(x)),
                x.target_frame_time_ms,
                x.cpvs,
                x.candidates,
                x.impostors,
                mb(x.memory_bytes),
                if x.unsolved_cpvs > 0 { " bad" } else { "" },
                x.unsolved_cpvs,
                x.seconds,
                ms(|e| e.max_ms),
                ms(|e| e.p99_ms),
                ms(|e| e.max_ms_in_solved),
                if bad_viol { " bad" } else { "" },
                viol,
                e.and_then(|e| e.parallax_max_px)
                    .filter(|v| v.is_finite())
                    .map_or("–".to_string(), |v| format!("{v:.2}")),
                if x.status == RunStatus::Ok {
                    ""
                } else {
                    " class=\"bad\""
                },
                x.status.as_str()
            );
            if let Some(err) = &x.error {
                let _ = writeln!(
                    h,
                    "<tr class=\"error\"><td></td><td colspan=\"14\">error: {}</td></tr>",
                    esc(err)
                );
            }
        }
        h.push_str("</table></div>\n</section>\n");
    }
}

/// One method's stability tables: the settings and the spreads.
fn stability_table(h: &mut String, m: &MethodStability) {
    let _ = write!(
        h,
        "<h3>{}</h3>\n<table>\n<tr><th>setting</th><th>status</th><th>memory (MB)</th>\
         <th>impostors</th><th>unsolved CPVs</th><th>max (ms)</th></tr>\n",
        esc(&m.method)
    );
    for p in &m.settings {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{:.3}</td></tr>",
            esc(&p.label),
            p.status.as_str(),
            mb(p.memory_bytes),
            p.impostors,
            p.unsolved_cpvs,
            p.max_ms
        );
    }
    h.push_str(
        "</table>\n<table>\n<tr><th>spread</th><th>min</th><th>max</th><th>mean</th>\
         <th>relative std</th></tr>\n",
    );
    let mem = &m.memory;
    let imp = &m.impostors;
    let _ = writeln!(
        h,
        "<tr><td>memory (MB)</td><td class=\"n\">{:.3}</td><td class=\"n\">{:.3}</td>\
         <td class=\"n\">{:.3}</td><td class=\"n\">{:.1} %</td></tr>\n\
         <tr><td>impostors</td><td class=\"n\">{:.1}</td><td class=\"n\">{:.1}</td>\
         <td class=\"n\">{:.1}</td><td class=\"n\">{:.1} %</td></tr>",
        mem.min / 1e6,
        mem.max / 1e6,
        mem.mean / 1e6,
        mem.relative_std * 100.0,
        imp.min,
        imp.max,
        imp.mean,
        imp.relative_std * 100.0
    );
    h.push_str("</table>\n");
}

/// The runs not dominated in (preprocessing time, memory): no other run is
/// at most as slow and at most as large and better in one. Sorted by time,
/// then memory, keeping the input order for ties.
fn pareto_front<'a>(runs: &[&'a Run]) -> Vec<&'a Run> {
    let mut front: Vec<&Run> = runs
        .iter()
        .copied()
        .filter(|a| {
            !runs.iter().any(|b| {
                b.seconds <= a.seconds
                    && b.memory_bytes <= a.memory_bytes
                    && (b.seconds < a.seconds || b.memory_bytes < a.memory_bytes)
            })
        })
        .collect();
    front.sort_by(|a, b| {
        a.seconds
            .total_cmp(&b.seconds)
            .then(a.memory_bytes.cmp(&b.memory_bytes))
    });
    front
}

/// Opens a page section.
fn section_start(h: &mut String, id: &str, title: &str) {
    let _ = writeln!(h, "<section id=\"{id}\"><h2>{}</h2>", esc(title));
}

/// Writes a chart with its caption, or a "No data" note in its place.
fn figure(h: &mut String, c: &Chart, caption: &str) {
    let _ = writeln!(h, "<figure id=\"{}\">", esc(&c.id));
    match chart::render(c) {
        Some(svg) => h.push_str(&svg),
        None => {
            let _ = writeln!(
                h,
                "<p class=\"nodata\"><strong>{}</strong>: No data to chart (fewer than two points \
                 with finite values); see the table of runs.</p>",
                esc(&c.title)
            );
        }
    }
    let _ = writeln!(h, "<figcaption>{caption}</figcaption>\n</figure>");
}

/// Adds a series when it has points.
fn push_nonempty(c: &mut Chart, s: Series) {
    if !s.points.is_empty() {
        c.series.push(s);
    }
}

/// Whether a run succeeded and can be placed on a target axis.
fn is_ok(x: &Run) -> bool {
    x.status == RunStatus::Ok && plottable(x.target_frame_time_ms)
}

/// `knob=value`, or `base` for the base job.
fn setting(x: &Run) -> String {
    match (&x.knob, x.value) {
        (None, _) => "base".into(),
        (Some(k), Some(v)) => format!("{k}={v}"),
        (Some(k), None) => format!("{k}=?"),
    }
}

/// Bytes as MB (10⁶ bytes).
fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// `[x, y, z]` with short numbers.
fn vec3(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", number(v[0]), number(v[1]), number(v[2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{EvalSummary, Walkthrough};
    use crate::testutil::sample_report;

    /// The text between `start` (inclusive) and the next `end` after it.
    fn between<'a>(s: &'a str, start: &str, end: &str) -> &'a str {
        let i = s.find(start).unwrap_or_else(|| panic!("no {start:?}"));
        let rest = &s[i..];
        &rest[..rest.find(end).map_or(rest.len(), |j| j + end.len())]
    }

    /// The `<svg>…</svg>` of the figure with this id.
    fn chart_svg<'a>(html: &'a str, id: &str) -> &'a str {
        let fig = between(html, &format!("<figure id=\"{id}\">"), "</figure>");
        between(fig, "<svg", "</svg>")
    }

    #[test]
    fn sample_is_one_document_with_every_chart() {
        let r = sample_report();
        let html = render_html(&r);
        assert!(html.starts_with("<!DOCTYPE html>"));
        assert_eq!(html.matches("<html").count(), 1);
        assert_eq!(html.matches("</html>").count(), 1);
        // Memory, achieved, one speed chart (cell size), two walkthroughs
        // (shafts, boxes), stability.
        assert_eq!(html.matches("<svg").count(), 6);
        assert_eq!(html.matches("</svg>").count(), 6);
        for id in [
            "chart-memory",
            "chart-achieved",
            "chart-speed-0",
            "chart-walk-0",
            "chart-walk-1",
            "chart-stability",
        ] {
            let svg = chart_svg(&html, id);
            assert!(svg.contains(&format!("<title id=\"{id}-t\">")), "{id}");
            assert!(svg.contains("class=\"legend\""), "{id}");
        }
        assert!(!html.contains("No data"), "every sample chart has data");
        for external in ["src=", "<link", "<script", "url(", "@import"] {
            assert!(!html.contains(external), "self-contained: {external}");
        }
        assert_eq!(html, render_html(&r), "deterministic");
    }

    #[test]
    fn axes_are_labelled_with_units() {
        let html = render_html(&sample_report());
        let memory = chart_svg(&html, "chart-memory");
        assert!(memory.contains("target frame time (ms)"));
        assert!(memory.contains("impostor memory (MB, log scale)"));
        let achieved = chart_svg(&html, "chart-achieved");
        assert!(achieved.contains("achieved frame time (ms)"));
        let speed = chart_svg(&html, "chart-speed-0");
        assert!(speed.contains("preprocessing time (s)"));
        assert!(speed.contains("impostor memory (MB, log scale)"));
        let walk = chart_svg(&html, "chart-walk-0");
        assert!(walk.contains("frame index") && walk.contains("frame time (ms)"));
    }

    #[test]
    fn legends_name_every_method() {
        let html = render_html(&sample_report());
        for id in ["chart-memory", "chart-achieved"] {
            let legend = between(chart_svg(&html, id), "<g class=\"legend\">", "</g>\n");
            for m in ["shafts", "boxes", "env-map"] {
                assert!(legend.contains(&format!(">{m}")), "{id} legend lacks {m}");
            }
        }
        let legend = between(
            chart_svg(&html, "chart-achieved"),
            "<g class=\"legend\">",
            "</g>\n",
        );
        assert!(legend.contains("guarantee: y = x"));
        // The zero-memory run has its own legend entry and marker.
        let memory = chart_svg(&html, "chart-memory");
        assert!(memory.contains("boxes: 0 MB (at axis floor)"));
        let cap = between(&html, "<figure id=\"chart-memory\">", "</figure>");
        assert!(cap.contains("needed no impostors (0 MB)"));
    }

    #[test]
    fn verdict_names_methods_that_crossed_the_guarantee() {
        let mut r = sample_report();
        let html = render_html(&r);
        let verdict = between(&html, "<p class=\"verdict\">", "</p>");
        assert!(verdict.contains("Guarantee crossed"));
        assert!(verdict.contains("<strong>boxes</strong>"));
        assert!(!verdict.contains("shafts") && !verdict.contains("env-map"));
        for run in &mut r.runs {
            if let Some(e) = &mut run.eval {
                e.violations_in_solved = 0;
            }
        }
        let html = render_html(&r);
        let verdict = between(&html, "<p class=\"verdict\">", "</p>");
        assert!(verdict.contains("no method crossed the guarantee line"));
        assert!(!verdict.contains("boxes"));
    }

    #[test]
    fn pareto_front_lists_exactly_the_non_dominated_runs() {
        // Cell-size runs (s, MB): shafts 2 (9, 2.5), 4 (4, 3), 8 (2, 4);
        // boxes 2 (5, 7) is dominated by shafts 4, boxes 4 (3, 8) by
        // shafts 8; boxes 8 (1.5, 9.5) is the fastest.
        let html = render_html(&sample_report());
        let list = between(&html, "<ul class=\"pareto\" id=\"pareto-0\">", "</ul>");
        let items: Vec<&str> = list
            .split("<li>")
            .skip(1)
            .map(|x| x.split("</li>").next().unwrap_or(""))
            .collect();
        assert_eq!(
            items,
            [
                "boxes problem_views.cell_size=8: 1.500 s, 9.500 MB",
                "shafts problem_views.cell_size=8: 2.000 s, 4.000 MB",
                "shafts problem_views.cell_size=4: 4.000 s, 3.000 MB",
                "shafts problem_views.cell_size=2: 9.000 s, 2.500 MB",
            ]
        );
    }

    #[test]
    fn pareto_front_keeps_ties_and_drops_dominated_runs() {
        let run = |s: f64, m: u64| Run {
            seconds: s,
            memory_bytes: m,
            ..Run::default()
        };
        let runs = [
            run(1.0, 5),
            run(1.0, 5),
            run(1.0, 6),
            run(2.0, 5),
            run(0.5, 0),
        ];
        let refs: Vec<&Run> = runs.iter().collect();
        let front: Vec<(f64, u64)> = pareto_front(&refs)
            .iter()
            .map(|x| (x.seconds, x.memory_bytes))
            .collect();
        assert_eq!(front, [(0.5, 0)]);
        let front = pareto_front(&refs[..4]);
        assert_eq!(front.len(), 2, "equal runs are both on the front");
        assert!(
            front
                .iter()
                .all(|x| x.seconds == 1.0 && x.memory_bytes == 5)
        );
    }

    #[test]
    fn report_text_is_escaped() {
        let mut r = sample_report();
        r.runs[0].error = Some("<script>alert(2)</script>".into());
        r.runs[0].status = RunStatus::Failed;
        r.methods.push("<b>m</b>".into());
        let html = render_html(&r);
        assert!(!html.contains("<script"), "no raw script from the report");
        assert!(!html.contains("<b>m</b>"));
        assert!(html.contains("&lt;/pre&gt;&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt;"));
        assert!(html.contains("&lt;script&gt;alert(2)&lt;/script&gt;"));
    }

    #[test]
    fn failed_runs_are_listed_under_the_charts() {
        let html = render_html(&sample_report());
        let fig = between(&html, "<section id=\"memory\">", "</section>");
        let left = between(fig, "<ul class=\"left-out\">", "</ul>");
        assert!(left.contains(
            "env-map (target_frame_time_ms=5, target 5 ms): failed: placement failed: 3 CPVs \
             unsolvable, budget exceeded"
        ));
    }

    #[test]
    fn runs_csv_has_a_line_per_run_and_quotes_commas() {
        let r = sample_report();
        let files = csv_files(&r);
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["runs.csv", "walkthroughs.csv", "stability.csv"]);
        let runs = &files[0].1;
        assert_eq!(runs.lines().count(), r.runs.len() + 1);
        assert!(runs.contains(",\"placement failed: 3 CPVs unsolvable, budget exceeded\","));
        assert!(runs.lines().all(|l| !l.is_empty()));
        let walks = &files[1].1;
        let frames: usize = r.walkthroughs.iter().map(|w| w.frame_ms.len()).sum();
        assert_eq!(walks.lines().count(), frames + 1);
        assert!(walks.contains("\r\nboxes,20,30,21\r\n"));
        let stab = &files[2].1;
        assert_eq!(stab.lines().count(), 9);
        assert!(stab.contains("\r\nboxes,target +5%,ok,8600000,86,0,19\r\n"));
    }

    #[test]
    fn empty_report_renders_no_data_notes() {
        let r = Report::default();
        let html = render_html(&r);
        assert_eq!(html.matches("<svg").count(), 0);
        assert!(html.contains("No data to chart"));
        assert!(html.contains("No runs."));
        assert!(html.ends_with("</html>\n"));
    }

    #[test]
    fn non_finite_values_render_no_data_and_never_reach_svg() {
        let mut r = sample_report();
        for (i, run) in r.runs.iter_mut().enumerate() {
            let bad = if i % 2 == 0 { f64::NAN } else { f64::INFINITY };
            run.target_frame_time_ms = bad;
            run.seconds = -bad;
            run.value = Some(bad);
            run.eval = Some(EvalSummary {
                max_ms: bad,
                p99_ms: bad,
                max_ms_in_solved: bad,
                ..EvalSummary::default()
            });
        }
        r.walkthroughs.push(Walkthrough {
            method: "shafts".into(),
            target_frame_time_ms: f64::NAN,
            frame_ms: vec![f64::INFINITY, f64::NAN],
        });
        for w in &mut r.walkthroughs {
            w.frame_ms.iter_mut().for_each(|v| *v = f64::NAN);
        }
        let html = render_html(&r);
        assert!(html.contains("No data to chart"));
        // Only the stability chart (memory is an integer) keeps its data.
        assert_eq!(html.matches("<svg").count(), 1);
        let svg = chart_svg(&html, "chart-stability");
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        let _ = csv_files(&r);
    }

    #[test]
    fn a_single_point_is_no_data_but_one_run_of_three_quantities_is_a_chart() {
        let mut r = sample_report();
        r.runs.truncate(1);
        r.walkthroughs.truncate(1);
        r.walkthroughs[0].frame_ms.truncate(1);
        let html = render_html(&r);
        let memory = between(&html, "<figure id=\"chart-memory\">", "</figure>");
        assert!(memory.contains("No data to chart") && !memory.contains("<svg"));
        let walk = between(&html, "<figure id=\"chart-walk-0\">", "</figure>");
        assert!(walk.contains("No data to chart") && !walk.contains("<svg"));
        // One run still has max, p99 and max in solved against y = x.
        assert!(chart_svg(&html, "chart-achieved").contains("shafts: p99"));
        assert_eq!(html.matches("<svg").count(), 2);
    }
}
