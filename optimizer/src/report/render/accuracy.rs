//! Accuracy beside speed: for each swept knob, the runs' worst evaluated
//! frame time against their preprocessing time, and the Pareto front over
//! time, memory and worst frame time.

use super::chart::{Chart, Line, Marker, Series, plottable};
use super::*;

/// The worst evaluated frame time of a run, ms (`None` without a finite
/// one).
fn worst_ms(x: &Run) -> Option<f64> {
    x.eval.as_ref().map(|e| e.max_ms).filter(|v| plottable(*v))
}

/// The runs no other run beats in preprocessing time, memory and worst
/// evaluated frame time at once (at most as much in all three and less in
/// one), by time then memory. Runs without a finite time or worst frame
/// time take no part.
pub(super) fn pareto_front_3<'a>(runs: &[&'a Run]) -> Vec<&'a Run> {
    let ok: Vec<(&Run, f64)> = runs
        .iter()
        .filter(|x| plottable(x.seconds))
        .filter_map(|x| Some((*x, worst_ms(x)?)))
        .collect();
    let mut front: Vec<&Run> = ok
        .iter()
        .filter(|(a, wa)| {
            !ok.iter().any(|(b, wb)| {
                b.seconds <= a.seconds
                    && b.memory_bytes <= a.memory_bytes
                    && wb <= wa
                    && (b.seconds < a.seconds || b.memory_bytes < a.memory_bytes || wb < wa)
            })
        })
        .map(|(a, _)| *a)
        .collect();
    front.sort_by(|a, b| {
        a.seconds
            .total_cmp(&b.seconds)
            .then(a.memory_bytes.cmp(&b.memory_bytes))
    });
    front
}

impl Page<'_> {
    /// The accuracy companion of the speed chart of `knob`: worst
    /// evaluated frame time against preprocessing time, the targets, and
    /// the Pareto front over (time, memory, worst frame time).
    pub(super) fn accuracy_chart(&self, h: &mut String, index: usize, knob: &str, runs: &[&Run]) {
        let mut c = Chart {
            id: format!("chart-accuracy-{index}"),
            title: format!("Worst frame time vs preprocessing time: {knob}"),
            desc: format!(
                "The largest evaluated frame time in ms against preprocessing time in seconds \
                 for the runs of the {knob} sweep, with their targets and the Pareto front over \
                 time, memory and worst frame time."
            ),
            x_label: "preprocessing time (s)".into(),
            y_label: "worst evaluated frame time (ms)".into(),
            y_from_zero: true,
            ..Chart::default()
        };
        let ok: Vec<&Run> = runs
            .iter()
            .copied()
            .filter(|x| x.status == RunStatus::Ok && plottable(x.seconds) && worst_ms(x).is_some())
            .collect();
        let (lo, hi) = ok
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
                (l.min(x.seconds), h.max(x.seconds))
            });
        let mut targets: Vec<f64> = ok.iter().map(|x| x.target_frame_time_ms).collect();
        targets.sort_by(f64::total_cmp);
        targets.dedup();
        if lo.is_finite() {
            for t in &targets {
                let mut g = Series::new(
                    format!("target {t} ms"),
                    "#b00000",
                    Line::Dashed,
                    Marker::None,
                );
                g.points = vec![(lo, *t), (hi.max(lo + 1e-9), *t)];
                g.guide = true;
                c.series.push(g);
            }
        }
        for m in self.methods_of(&ok) {
            let mut pts = Series::new(m, self.color(m), Line::None, Marker::Circle);
            for x in ok.iter().filter(|x| x.method == m) {
                let w = worst_ms(x).unwrap_or(f64::NAN);
                pts.points.push((x.seconds, w));
                pts.labels
                    .push(x.value.map(|v| v.to_string()).unwrap_or_default());
                pts.tips.push(format!(
                    "{m}, {}: {:.3} s, worst {w:.3} ms (target {} ms), {:.3} MB",
                    setting(x),
                    x.seconds,
                    x.target_frame_time_ms,
                    mb(x.memory_bytes)
                ));
            }
            push_nonempty(&mut c, pts);
        }
        let front = pareto_front_3(&ok);
        let mut ring = Series::new(
            "Pareto front (time, memory, worst)",
            INK,
            Line::None,
            Marker::Ring,
        );
        ring.points = front
            .iter()
            .filter_map(|x| Some((x.seconds, worst_ms(x)?)))
            .collect();
        ring.guide = true;
        if !front.is_empty() {
            c.series.push(ring);
        }
        let cap = format!(
            "Accuracy beside speed for the <code>{}</code> sweep: each run's largest evaluated \
             frame time (the guarantee holds where it stays at or below the run's target, dashed) \
             against its preprocessing time; labels are the knob's values. Ringed runs form the \
             Pareto front over preprocessing time, impostor memory and worst frame time: no \
             other run is at most as slow, as large and as slow to draw, and better in one.",
            esc(knob)
        );
        figure(h, &c, &cap);
        pareto_list(
            h,
            &format!("pareto3-{index}"),
            &format!(
                "Pareto front of <code>{}</code> over time, memory and worst frame time",
                esc(knob)
            ),
            &front,
            |x| {
                format!(
                    "{:.3} s, {:.3} MB, worst {:.3} ms",
                    x.seconds,
                    mb(x.memory_bytes),
                    worst_ms(x).unwrap_or(f64::NAN)
                )
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::EvalSummary;

    fn run(seconds: f64, memory_bytes: u64, worst: f64) -> Run {
        Run {
            method: "shafts".into(),
            seconds,
            memory_bytes,
            eval: Some(EvalSummary {
                max_ms: worst,
                ..EvalSummary::default()
            }),
            ..Run::default()
        }
    }

    /// Hand-made: a run dominated in all three goes; one that is slower
    /// and larger but draws faster stays (it would leave the 2-D front);
    /// ties stay; a run without an evaluation takes no part.
    #[test]
    fn the_front_over_three_quantities_by_hand() {
        let a = run(1.0, 100, 10.0);
        let b = run(2.0, 200, 12.0); // dominated by a
        let c = run(3.0, 300, 8.0); // slower, larger, but faster frames
        let d = run(1.0, 100, 10.0); // a tie with a
        let mut e = run(0.5, 50, 1.0);
        e.eval = None;
        let runs = [&a, &b, &c, &d, &e];
        let front = pareto_front_3(&runs);
        let ids: Vec<*const Run> = front.iter().map(|x| *x as *const Run).collect();
        assert_eq!(
            ids,
            vec![&a as *const Run, &d as *const Run, &c as *const Run]
        );
        // The time-memory front keeps only a and d.
        let two = super::super::sections::pareto_front(&[&a, &b, &c, &d]);
        assert_eq!(two.len(), 2);
    }
}
