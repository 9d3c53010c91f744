//! The sections of a report page: the charts (memory, achieved frame time,
//! preprocessing time against memory), the stability tables and the table
//! of runs.

use std::fmt::Write as _;

use super::chart::{Chart, Line, Marker, Series, plottable};
use super::*;

impl<'a> Page<'a> {
    pub(super) fn memory_chart(&self, h: &mut String) {
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

    pub(super) fn achieved_chart(&self, h: &mut String) {
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
            if let Some(e) = x.eval.as_ref().filter(|e| e.guarantee_violations() > 0) {
                crossed
                    .points
                    .push((x.target_frame_time_ms, e.max_ms_in_solved));
                crossed.tips.push(format!(
                    "{}, target {} ms: {} view(s) over the target in solved problem views",
                    x.method,
                    x.target_frame_time_ms,
                    e.guarantee_violations()
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
    pub(super) fn verdict(&self) -> String {
        let evaluated: Vec<&Run> = self.r.runs.iter().filter(|x| x.eval.is_some()).collect();
        if evaluated.is_empty() {
            return "No run was evaluated, so the guarantee was not checked.".into();
        }
        let crossed: Vec<String> = evaluated
            .iter()
            .filter_map(|x| {
                let e = x.eval.as_ref()?;
                (e.guarantee_violations() > 0).then(|| {
                    format!(
                        "<strong>{}</strong> ({}, target {} ms: {} view(s) over the target, max {:.3} ms)",
                        esc(&x.method),
                        esc(&setting(x)),
                        x.target_frame_time_ms,
                        e.guarantee_violations(),
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
    pub(super) fn left_out(
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
            } else if needs_eval && x.cache.is_some() {
                "a cache built along the walkthrough, with no placement to evaluate (see \
                 Methods side by side)"
                    .to_string()
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

    /// Frame time against memory under budgets (`--budgets`): per method,
    /// its unbudgeted base run and its budget runs, the evaluated maximum
    /// and 99th percentile and the placement's own estimate of its worst
    /// problem view, against the memory used, with the target. Nothing
    /// when the report has no budget run.
    pub(super) fn budget_chart(&self, h: &mut String) {
        let budgeted: Vec<&Run> = self
            .r
            .runs
            .iter()
            .filter(|x| x.knob.as_deref() == Some(BUDGET_KNOB))
            .collect();
        if budgeted.is_empty() {
            return;
        }
        let mut c = Chart {
            id: "chart-budget".into(),
            title: "Frame time vs memory budget".into(),
            desc: "Frame time in ms against impostor memory in MB per method, from the unbudgeted                    placement down the memory budgets: evaluated maximum, 99th percentile and the                    placement's estimate for its worst problem view, with the target."
                .into(),
            x_label: "impostor memory (MB)".into(),
            y_label: "frame time (ms)".into(),
            ..Chart::default()
        };
        let mut targets: Vec<f64> = Vec::new();
        let mut xs: Vec<f64> = Vec::new();
        for m in self.methods_of(&budgeted) {
            let mut runs: Vec<&Run> = self
                .r
                .runs
                .iter()
                .filter(|x| {
                    x.method == m
                        && is_ok(x)
                        && x.eval.is_some()
                        && (x.knob.is_none() || x.knob.as_deref() == Some(BUDGET_KNOB))
                })
                .collect();
            runs.sort_by_key(|x| x.memory_bytes);
            let col = self.color(m);
            let mut max = Series::new(format!("{m}: max"), col, Line::Solid, Marker::Circle);
            let mut p99 = Series::new(format!("{m}: p99"), col, Line::Dashed, Marker::Square);
            let mut est = Series::new(
                format!("{m}: estimated worst problem view"),
                col,
                Line::Dotted,
                Marker::Triangle,
            );
            for x in runs {
                let Some(e) = &x.eval else { continue };
                let mem = mb(x.memory_bytes);
                let t = x.target_frame_time_ms;
                if !targets.contains(&t) {
                    targets.push(t);
                }
                xs.push(mem);
                let budget = x.budget_bytes.map_or_else(
                    || "no budget".to_string(),
                    |b| format!("budget {:.3} MB", mb(b)),
                );
                let tip = |what: &str, v: f64| {
                    format!(
                        "{m}, {budget}: {mem:.3} MB used, {what} {v:.3} ms, {} problem views unsolved",
                        x.unsolved_cpvs
                    )
                };
                max.points.push((mem, e.max_ms));
                max.tips.push(tip("max", e.max_ms));
                p99.points.push((mem, e.p99_ms));
                p99.tips.push(tip("p99", e.p99_ms));
                let worst = t + x.max_residual_ms;
                est.points.push((mem, worst));
                est.tips.push(tip("estimated worst problem view", worst));
            }
            push_nonempty(&mut c, max);
            push_nonempty(&mut c, p99);
            push_nonempty(&mut c, est);
        }
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo.is_finite() && hi.is_finite() {
            for t in targets {
                let mut g = Series::new(format!("target {t} ms"), INK, Line::Dashed, Marker::None);
                g.points = vec![(lo, t), (hi.max(lo + 1e-9), t)];
                g.guide = true;
                c.series.push(g);
            }
        }
        let fractions: Vec<String> = self
            .r
            .budgets
            .iter()
            .map(|f| format!("{:.0} %", f * 100.0))
            .collect();
        let cap = format!(
            "What a memory budget costs in frame time: each method's unbudgeted placement and              its placements under budgets{} of that memory. Solid: maximum over the sampled              views; dashed: 99th percentile; dotted: the placement's own estimate for its worst              problem view (the target plus the largest residual of the problem views the budget              left unsolved). Views in solved problem views stay within the target at every budget              (see the table of runs).",
            if fractions.is_empty() {
                String::new()
            } else {
                format!(" ({})", fractions.join(", "))
            }
        );
        section_start(h, "budget", "Frame time vs memory budget");
        figure(h, &c, &cap);
        self.left_out(h, &budgeted, true, |x| is_ok(x) && x.eval.is_some());
        h.push_str(
            "</section>
",
        );
    }

    pub(super) fn speed_charts(&self, h: &mut String) {
        section_start(
            h,
            "speed",
            "Speed against accuracy: preprocessing time, memory and worst frame time",
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
            self.accuracy_chart(h, i, k, &runs);
        }
        h.push_str("</section>\n");
    }

    pub(super) fn speed_chart(&self, h: &mut String, index: usize, knob: &str, runs: &[&Run]) {
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
        pareto_list(
            h,
            &format!("pareto-{index}"),
            &format!("Pareto front of <code>{}</code>", esc(knob)),
            &front,
            |x| format!("{:.3} s, {:.3} MB", x.seconds, mb(x.memory_bytes)),
        );
        self.left_out(h, runs, false, shown);
    }

    pub(super) fn stability(&self, h: &mut String) {
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

    pub(super) fn runs_table(&self, h: &mut String) {
        section_start(h, "runs", "All runs");
        h.push_str(
            "<div class=\"wide\"><table class=\"runs\">\n<tr><th>method</th><th>setting</th><th>target (ms)</th>\
             <th>CPVs</th><th>candidates</th><th>impostors</th><th>memory (MB)</th>\
             <th>unsolved CPVs</th><th>preprocessing (s)</th><th>eval max (ms)</th>\
             <th>eval p99 (ms)</th><th>max in solved (ms)</th><th>violations in solved</th>\
             <th>control: over the target with no impostor</th>\
             <th>parallax max (px)</th><th>status</th></tr>\n",
        );
        if self.r.runs.is_empty() {
            h.push_str("<tr><td colspan=\"16\">No runs.</td></tr>\n");
        }
        for x in &self.r.runs {
            let e = x.eval.as_ref();
            let ms = |f: fn(&crate::report::EvalSummary) -> f64| {
                e.map_or("–".into(), |e| format!("{:.3}", f(e)))
            };
            let viol = e.map_or("–".to_string(), |e| e.guarantee_violations().to_string());
            let bad_viol = e.is_some_and(|e| e.guarantee_violations() > 0);
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{:.3}</td>\
                 <td class=\"n{}\">{}</td><td class=\"n\">{:.3}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n{}\">{}</td>{}\
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
                super::truth::control_cell(x),
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
                    "<tr class=\"error\"><td></td><td colspan=\"15\">error: {}</td></tr>",
                    esc(err)
                );
            }
        }
        h.push_str("</table></div>\n</section>\n");
    }
}

/// One method's stability tables: the settings and the spreads.
pub(super) fn stability_table(h: &mut String, m: &MethodStability) {
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
pub(super) fn pareto_front<'a>(runs: &[&'a Run]) -> Vec<&'a Run> {
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
