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
//!   with that knob, each followed by its accuracy: worst evaluated frame
//!   time against preprocessing time, with the Pareto front over time,
//!   memory and worst frame time.
//! - **Walkthrough**: one panel per target of `walkthroughs`: the frames
//!   without impostors, with each method's placement and as it estimates
//!   them, and the target; lines that coincide are said so in the caption.
//! - **Estimate against truth**: one scatter per method (its base run, else
//!   its first run with estimates): each sampled problem view's estimate
//!   against the largest exact time sampled in it; a table of every run's
//!   ratios and control (views over the target with no impostor; a run
//!   whose control is 0 is flagged: its check could not have failed).
//! - **The greedy against the exact optimum** (only with `exact` runs): a
//!   table of each such run's solver outcome, the greedy's memory, the
//!   optimum's (or the best found and its lower bound) and their ratio.
//!
//! Failed runs (status other than `ok`) and values that cannot be placed
//! on an axis are left out of the charts and listed under them; every run
//! is in the table. Memory is in MB (10⁶ bytes).

mod accuracy;
mod baked;
mod chart;
mod csv;
mod exact;
mod sections;
mod sideby;
mod truth;
mod walk;

use std::fmt::Write as _;

use self::chart::{Chart, Series, number, plottable};
pub use self::csv::csv_files;
use super::{MethodStability, Report, Run, RunStatus, Walkthrough};

/// The knob of the target frame time sweep.
const TARGET_KNOB: &str = "target_frame_time_ms";

/// The knob of the memory budget runs.
const BUDGET_KNOB: &str = super::run::BUDGET;
/// Series colours, by method (or target) index.
const PALETTE: [&str; 10] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
    "#393b79", "#bcbd22",
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
    let budget_link = if r
        .runs
        .iter()
        .any(|x| x.knob.as_deref() == Some(BUDGET_KNOB))
    {
        " · <a href=\"#budget\">Budget</a>"
    } else {
        ""
    };
    let _ = writeln!(
        h,
        "<nav><a href=\"#memory\">Memory</a> · <a href=\"#achieved\">Frame time</a> · <a href=\"#methods\">Methods side by side</a>{budget_link} · <a href=\"#speed\">Speed vs accuracy</a> · <a href=\"#walkthrough\">Walkthrough</a> · <a href=\"#estimates\">Estimates</a> · <a href=\"#stability\">Stability</a> · <a href=\"#runs\">Runs</a></nav>"
    );
    p.memory_chart(&mut h);
    p.achieved_chart(&mut h);
    p.side_by_side(&mut h);
    p.budget_chart(&mut h);
    p.speed_charts(&mut h);
    p.walkthrough_charts(&mut h);
    p.estimate_charts(&mut h);
    p.exact_table(&mut h);
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
}

/// The list of the runs of a Pareto `front` (nothing when empty), under
/// `heading` (HTML), one item per run: method, setting and `figures(run)`.
fn pareto_list(
    h: &mut String,
    id: &str,
    heading: &str,
    front: &[&Run],
    figures: impl Fn(&Run) -> String,
) {
    if front.is_empty() {
        return;
    }
    let _ = write!(h, "<p>{heading}:</p><ul class=\"pareto\" id=\"{id}\">");
    for x in front {
        let _ = write!(
            h,
            "<li>{} {}: {}</li>",
            esc(&x.method),
            esc(&setting(x)),
            figures(x)
        );
    }
    h.push_str("</ul>\n");
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
    use super::sections::pareto_front;
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
        // Memory, achieved, budget, two speed charts (cell size, budget)
        // each with its accuracy chart, two walkthroughs (targets 10 and
        // 20 ms), three estimate charts (one per method), stability, and
        // per target (five) the methods' memory and achieved frame time.
        assert_eq!(html.matches("<svg").count(), 23);
        assert_eq!(html.matches("</svg>").count(), 23);
        for id in [
            "chart-methods-memory-0",
            "chart-methods-time-0",
            "chart-methods-memory-4",
            "chart-methods-time-4",
            "chart-memory",
            "chart-achieved",
            "chart-budget",
            "chart-speed-0",
            "chart-speed-1",
            "chart-accuracy-0",
            "chart-accuracy-1",
            "chart-walk-0",
            "chart-walk-1",
            "chart-estimate-0",
            "chart-estimate-1",
            "chart-estimate-2",
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
                e.violations_in_cpv_views = 0;
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
        // Frame 30 of the boxes at 20 ms: 21 ms, 10 + 12·|sin 3| ms without
        // impostors, no estimate (in no problem view).
        let row: Vec<&str> = walks
            .lines()
            .find(|l| l.starts_with("boxes,20,30,"))
            .unwrap()
            .split(',')
            .collect();
        assert_eq!(row.len(), 6);
        assert_eq!(row[3], "21");
        let bare: f64 = row[4].parse().unwrap();
        assert!(
            (bare - (10.0 + 12.0 * 3f64.sin().abs())).abs() < 1e-12,
            "{bare}"
        );
        assert_eq!(row[5], "");
        let row = walks
            .lines()
            .find(|l| l.starts_with("boxes,20,15,"))
            .unwrap();
        // 10 + 12·|sin 1.5| = 21.97 ms without impostors: over 20, estimated 19.6.
        assert!(row.ends_with(",19.6"), "{row}");
        let stab = &files[2].1;
        assert_eq!(stab.lines().count(), 9);
        assert!(stab.contains("\r\nboxes,target +5%,ok,8600000,86,0,19\r\n"));
    }

    /// The budget chart draws, per budgeted method, its base and budget
    /// runs by memory (max, p99, the estimated worst problem view) with the
    /// target; a report without budget runs has no such section.
    #[test]
    fn budget_chart_shows_frame_time_against_memory() {
        let r = sample_report();
        let html = render_html(&r);
        let svg = chart_svg(&html, "chart-budget");
        assert!(svg.contains("impostor memory (MB)") && svg.contains("frame time (ms)"));
        for s in [
            "shafts: max",
            "shafts: p99",
            "shafts: estimated worst problem view",
            "target 20 ms",
        ] {
            assert!(svg.contains(s), "{s}");
        }
        // Only shafts has budget runs.
        assert!(!svg.contains("boxes: max"));
        // Base (3 MB), half and quarter budgets: three points per series.
        assert!(svg.contains("budget 0.750 MB") && svg.contains("budget 1.500 MB"));
        assert!(svg.contains("no budget"));
        let cap = between(&html, "<figure id=\"chart-budget\">", "</figure>");
        assert!(cap.contains("(50 %, 25 %)"), "{cap}");
        assert!(html.contains("href=\"#budget\""));
        let mut plain = r.clone();
        plain
            .runs
            .retain(|x| x.knob.as_deref() != Some(BUDGET_KNOB));
        let html = render_html(&plain);
        assert!(!html.contains("chart-budget") && !html.contains("#budget"));
    }

    #[test]
    fn exact_runs_get_the_gap_table_and_others_none() {
        let r = sample_report();
        assert!(!render_html(&r).contains("id=\"exact\""));
        let mut with = sample_report();
        let mut run = with.runs[0].clone();
        run.method = "exact".into();
        run.exact = Some(crate::api::stats::ExactStats {
            status: "node_limit".into(),
            nodes: 20_000,
            seconds: 12.5,
            memory_bytes: 700_000,
            greedy_memory_bytes: 770_000,
            lower_bound_bytes: Some(650_000),
            greedy_over_exact: 1.1,
            ..Default::default()
        });
        with.runs.push(run);
        let html = render_html(&with);
        let table = between(&html, "id=\"exact\"", "</table>");
        assert_eq!(table.matches("<tr>").count(), 2, "{table}");
        for want in ["node_limit", "0.7700", "0.7000", "0.6500", "1.100"] {
            assert!(table.contains(want), "{want}: {table}");
        }
        let csv = csv::csv_files(&with).remove(0).1;
        assert!(
            csv.lines()
                .last()
                .unwrap()
                .ends_with(",node_limit,770000,650000,,,,,,"),
            "{csv}"
        );
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
            ..Walkthrough::default()
        });
        for w in &mut r.walkthroughs {
            w.frame_ms.iter_mut().for_each(|v| *v = f64::NAN);
            w.bare_ms.iter_mut().for_each(|v| *v = f64::INFINITY);
            w.estimate_ms.iter_mut().for_each(|v| *v = Some(f64::NAN));
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
        // (a report of an older version: no frames without impostors)
        r.walkthroughs[0].bare_ms.clear();
        r.walkthroughs[0].estimate_ms.clear();
        let html = render_html(&r);
        let memory = between(&html, "<figure id=\"chart-memory\">", "</figure>");
        assert!(memory.contains("No data to chart") && !memory.contains("<svg"));
        let walk = between(&html, "<figure id=\"chart-walk-0\">", "</figure>");
        assert!(walk.contains("No data to chart") && !walk.contains("<svg"));
        // One run still has max, p99 and max in solved against y = x.
        assert!(chart_svg(&html, "chart-achieved").contains("shafts: p99"));
        // And its estimate chart.
        assert!(chart_svg(&html, "chart-estimate-0").contains("y = x"));
        // And its sampled maximum and 99th percentile beside the target.
        assert!(chart_svg(&html, "chart-methods-time-0").contains("p99, sampled views"));
        assert_eq!(html.matches("<svg").count(), 4);
    }
}
