//! The report's data as CSV files (RFC 4180: comma-separated, CRLF line
//! ends, fields with commas, quotes or line breaks quoted, quotes doubled).

use crate::report::{Report, Run};

/// Header of `runs.csv`.
const RUNS_HEADER: [&str; 36] = [
    "method",
    "knob",
    "value",
    "target_frame_time_ms",
    "status",
    "error",
    "cpvs",
    "candidates",
    "impostors",
    "memory_bytes",
    "unsolved_cpvs",
    "max_residual_ms",
    "budget_bytes",
    "seconds",
    "stage_seconds",
    "eval_views",
    "eval_max_ms",
    "eval_p99_ms",
    "eval_p50_ms",
    "eval_mean_ms",
    "eval_violations",
    "eval_violations_in_solved",
    "eval_max_ms_in_solved",
    "eval_parallax_max_px",
    "eval_control_violations",
    "eval_estimate_ratio_median",
    "eval_estimate_ratio_final_median",
    "exact_status",
    "exact_greedy_memory_bytes",
    "exact_lower_bound_bytes",
    "cache_max_ms",
    "cache_p99_ms",
    "cache_over_target",
    "cache_first_ms",
    "cache_mean_bytes",
    "cache_created",
];

/// The report's data as CSV files, `(file name, contents)`: `runs.csv` (one
/// row per run: method, knob, value, status, error and every number; the
/// evaluation's columns are empty when a run has none; `stage_seconds` is
/// `stage=seconds` pairs joined by `;`), `walkthroughs.csv` (one row per
/// frame: method, target, frame index, frame time, the frame's time
/// without impostors and the placement's estimate, empty outside problem
/// views) and, when the report has
/// a stability block, `stability.csv` (one row per method and
/// perturbation). Every file starts with a header row, even when it has no
/// data rows. Numbers are written in Rust's shortest round-trip form
/// (`NaN`, `inf` for non-finite values).
pub fn csv_files(r: &Report) -> Vec<(String, String)> {
    let mut files = vec![
        ("runs.csv".to_string(), runs_csv(&r.runs)),
        ("walkthroughs.csv".to_string(), walkthroughs_csv(r)),
    ];
    if r.stability.is_some() {
        files.push(("stability.csv".to_string(), stability_csv(r)));
    }
    files
}

/// `runs.csv`.
fn runs_csv(runs: &[Run]) -> String {
    let mut out = String::new();
    row(&mut out, RUNS_HEADER.iter().map(|s| s.to_string()));
    for run in runs {
        let stages: Vec<String> = run
            .stage_seconds
            .iter()
            .map(|s| format!("{}={}", s.stage, s.seconds))
            .collect();
        let mut fields = vec![
            run.method.clone(),
            run.knob.clone().unwrap_or_default(),
            run.value.map(|v| v.to_string()).unwrap_or_default(),
            run.target_frame_time_ms.to_string(),
            run.status.as_str().into(),
            run.error.clone().unwrap_or_default(),
            run.cpvs.to_string(),
            run.candidates.to_string(),
            run.impostors.to_string(),
            run.memory_bytes.to_string(),
            run.unsolved_cpvs.to_string(),
            run.max_residual_ms.to_string(),
            run.budget_bytes.map(|b| b.to_string()).unwrap_or_default(),
            run.seconds.to_string(),
            stages.join(";"),
        ];
        match &run.eval {
            Some(e) => fields.extend([
                e.views.to_string(),
                e.max_ms.to_string(),
                e.p99_ms.to_string(),
                e.p50_ms.to_string(),
                e.mean_ms.to_string(),
                e.violations.to_string(),
                e.violations_in_solved.to_string(),
                e.max_ms_in_solved.to_string(),
                e.parallax_max_px.map(|x| x.to_string()).unwrap_or_default(),
                e.control_violations.to_string(),
                e.estimates
                    .as_ref()
                    .map(|x| x.ratio_original_median.to_string())
                    .unwrap_or_default(),
                e.estimates
                    .as_ref()
                    .map(|x| x.ratio_final_median.to_string())
                    .unwrap_or_default(),
            ]),
            None => fields.extend(std::iter::repeat_n(String::new(), 12)),
        }
        match &run.exact {
            Some(x) => fields.extend([
                x.status.clone(),
                x.greedy_memory_bytes.to_string(),
                x.lower_bound_bytes
                    .map(|b| b.to_string())
                    .unwrap_or_default(),
            ]),
            None => fields.extend(std::iter::repeat_n(String::new(), 3)),
        }
        match &run.cache {
            Some(c) => fields.extend([
                c.max_ms.to_string(),
                c.p99_ms.to_string(),
                c.over_target.to_string(),
                c.first_ms.to_string(),
                c.mean_bytes.to_string(),
                c.created.to_string(),
            ]),
            None => fields.extend(std::iter::repeat_n(String::new(), 6)),
        }
        row(&mut out, fields);
    }
    out
}

/// `walkthroughs.csv`.
fn walkthroughs_csv(r: &Report) -> String {
    let mut out = String::new();
    row(
        &mut out,
        [
            "method",
            "target_frame_time_ms",
            "frame",
            "frame_ms",
            "bare_ms",
            "estimate_ms",
        ]
        .map(String::from),
    );
    for w in &r.walkthroughs {
        for (i, ms) in w.frame_ms.iter().enumerate() {
            row(
                &mut out,
                [
                    w.method.clone(),
                    w.target_frame_time_ms.to_string(),
                    i.to_string(),
                    ms.to_string(),
                    w.bare_ms.get(i).map(|v| v.to_string()).unwrap_or_default(),
                    w.estimate_ms
                        .get(i)
                        .copied()
                        .flatten()
                        .map(|v| v.to_string())
                        .unwrap_or_default(),
                ],
            );
        }
    }
    out
}

/// `stability.csv`.
fn stability_csv(r: &Report) -> String {
    let mut out = String::new();
    row(
        &mut out,
        [
            "method",
            "label",
            "status",
            "memory_bytes",
            "impostors",
            "unsolved_cpvs",
            "max_ms",
        ]
        .map(String::from),
    );
    for m in r.stability.iter().flat_map(|s| s.methods.iter()) {
        for p in &m.settings {
            row(
                &mut out,
                [
                    m.method.clone(),
                    p.label.clone(),
                    p.status.as_str().into(),
                    p.memory_bytes.to_string(),
                    p.impostors.to_string(),
                    p.unsolved_cpvs.to_string(),
                    p.max_ms.to_string(),
                ],
            );
        }
    }
    out
}

/// Appends one CSV record.
fn row(out: &mut String, fields: impl IntoIterator<Item = String>) {
    for (i, f) in fields.into_iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        field(out, &f);
    }
    out.push_str("\r\n");
}

/// Appends one field, quoted when it holds a comma, quote or line break.
fn field(out: &mut String, f: &str) {
    if f.contains([',', '"', '\r', '\n']) {
        out.push('"');
        out.push_str(&f.replace('"', "\"\""));
        out.push('"');
    } else {
        out.push_str(f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_quoted_only_when_needed() {
        let mut out = String::new();
        row(
            &mut out,
            ["plain", "a,b", "say \"hi\"", "two\nlines"].map(String::from),
        );
        assert_eq!(out, "plain,\"a,b\",\"say \"\"hi\"\"\",\"two\nlines\"\r\n");
    }

    #[test]
    fn empty_report_has_headers_only() {
        let files = csv_files(&Report::default());
        let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["runs.csv", "walkthroughs.csv"]);
        for (_, text) in &files {
            assert_eq!(text.lines().count(), 1);
        }
        assert!(
            files[0]
                .1
                .starts_with("method,knob,value,target_frame_time_ms,status,error,")
        );
    }
}
