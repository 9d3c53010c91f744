//! Accuracy beside speed: for each swept knob, the runs' worst evaluated
//! frame time against their preprocessing time, and the Pareto front over
//! time, memory and worst frame time; where the runs' images were checked
//! (`report --images`), their image error against preprocessing time and
//! the Pareto front over time, memory, worst frame time and image error.

use super::chart::{Chart, Line, Marker, Series, plottable};
use super::*;

/// The worst evaluated frame time of a run, ms (`None` without a finite
/// one).
fn worst_ms(x: &Run) -> Option<f64> {
    x.eval.as_ref().map(|e| e.max_ms).filter(|v| plottable(*v))
}

/// The mean footprint mismatch of a run's image check (`None` without one
/// that compared a view).
fn image_error(x: &Run) -> Option<f64> {
    x.image
        .as_ref()
        .filter(|i| i.views > 0)
        .map(|i| i.footprint_mismatch.mean)
        .filter(|v| plottable(*v))
}

/// The runs no other run beats in preprocessing time, memory and worst
/// evaluated frame time at once (at most as much in all three and less in
/// one), by time then memory. Runs without a finite time or worst frame
/// time take no part.
pub(super) fn pareto_front_3<'a>(runs: &[&'a Run]) -> Vec<&'a Run> {
    pareto_front(runs, |x| Some(vec![worst_ms(x)?]))
}

/// [`pareto_front_3`] with the image error as a fourth goal: runs without
/// an image check take no part.
pub(super) fn pareto_front_4<'a>(runs: &[&'a Run]) -> Vec<&'a Run> {
    pareto_front(runs, |x| Some(vec![worst_ms(x)?, image_error(x)?]))
}

/// The runs no other run beats in preprocessing time, memory and the goals
/// `more` gives (all smaller is better), by time then memory; runs without
/// a finite time or without `more` take no part.
fn pareto_front<'a>(runs: &[&'a Run], more: impl Fn(&Run) -> Option<Vec<f64>>) -> Vec<&'a Run> {
    let ok: Vec<(&Run, Vec<f64>)> = runs
        .iter()
        .filter(|x| plottable(x.seconds))
        .filter_map(|x| Some((*x, more(x)?)))
        .collect();
    let goals = |x: &Run, m: &[f64]| {
        let mut g = vec![x.seconds, x.memory_bytes as f64];
        g.extend_from_slice(m);
        g
    };
    let mut front: Vec<&Run> = ok
        .iter()
        .filter(|(a, ma)| {
            let ga = goals(a, ma);
            !ok.iter().any(|(b, mb)| {
                let gb = goals(b, mb);
                gb.iter().zip(&ga).all(|(b, a)| b <= a) && gb.iter().zip(&ga).any(|(b, a)| b < a)
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

/// Rings the runs of `front` on chart `c` at (preprocessing time, `y`),
/// as the series `name`; nothing for an empty front.
fn push_front(c: &mut Chart, name: &str, front: &[&Run], y: fn(&Run) -> Option<f64>) {
    if front.is_empty() {
        return;
    }
    let mut ring = Series::new(name, INK, Line::None, Marker::Ring);
    ring.points = front
        .iter()
        .filter_map(|x| Some((x.seconds, y(x)?)))
        .collect();
    ring.guide = true;
    c.series.push(ring);
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
        push_front(
            &mut c,
            "Pareto front (time, memory, worst)",
            &front,
            worst_ms,
        );
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
        self.image_chart(h, index, knob, &ok);
    }

    /// The image facet of the accuracy of `knob`'s runs `ok`: each checked
    /// run's mean footprint mismatch against its preprocessing time, and
    /// the Pareto front over time, memory, worst frame time and image
    /// error. Nothing when no run's images were checked.
    fn image_chart(&self, h: &mut String, index: usize, knob: &str, ok: &[&Run]) {
        let checked: Vec<&Run> = ok
            .iter()
            .copied()
            .filter(|x| image_error(x).is_some())
            .collect();
        if checked.is_empty() {
            return;
        }
        let mut c = Chart {
            id: format!("chart-image-{index}"),
            title: format!("Image error vs preprocessing time: {knob}"),
            desc: format!(
                "The mean footprint mismatch of the impostors' image check against                  preprocessing time in seconds for the runs of the {knob} sweep, with the                  Pareto front over time, memory, worst frame time and image error."
            ),
            x_label: "preprocessing time (s)".into(),
            y_label: "footprint mismatch (mean share)".into(),
            y_from_zero: true,
            ..Chart::default()
        };
        for m in self.methods_of(&checked) {
            let mut pts = Series::new(m, self.color(m), Line::None, Marker::Circle);
            for x in checked.iter().filter(|x| x.method == m) {
                let Some(i) = &x.image else {
                    continue;
                };
                pts.points.push((x.seconds, i.footprint_mismatch.mean));
                pts.labels
                    .push(x.value.map(|v| v.to_string()).unwrap_or_default());
                pts.tips.push(format!(
                    "{m}, {}: {:.3} s, footprint mismatch {:.4} (p95 {:.4}, control {:.4}) \
                     over {} views, {:.3} MB",
                    setting(x),
                    x.seconds,
                    i.footprint_mismatch.mean,
                    i.footprint_mismatch.p95,
                    i.control_mismatch.mean,
                    i.views,
                    mb(x.memory_bytes)
                ));
            }
            push_nonempty(&mut c, pts);
        }
        let front = pareto_front_4(&checked);
        push_front(
            &mut c,
            "Pareto front (time, memory, worst, image error)",
            &front,
            image_error,
        );
        let cap = format!(
            "Image accuracy beside speed for the <code>{}</code> sweep ({} of {} runs with \
             their images checked): per run, the mean share of its impostors' footprint \
             pixels whose colour has no match within a pixel in the render of the geometry. \
             Ringed runs form the Pareto front over preprocessing time, impostor memory, \
             worst frame time and image error.",
            esc(knob),
            checked.len(),
            ok.len()
        );
        figure(h, &c, &cap);
        pareto_list(
            h,
            &format!("pareto4-{index}"),
            &format!(
                "Pareto front of <code>{}</code> over time, memory, worst frame time and image \
                 error",
                esc(knob)
            ),
            &front,
            |x| {
                format!(
                    "{:.3} s, {:.3} MB, worst {:.3} ms, mismatch {:.4}",
                    x.seconds,
                    mb(x.memory_bytes),
                    worst_ms(x).unwrap_or(f64::NAN),
                    image_error(x).unwrap_or(f64::NAN)
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

    fn checked(mut x: Run, mismatch: f64) -> Run {
        x.image = Some(crate::report::ImageSummary {
            views: 8,
            footprint_mismatch: crate::api::evaluation::MismatchSpread {
                mean: mismatch,
                p95: mismatch,
                max: mismatch,
            },
            ..Default::default()
        });
        x
    }

    /// Hand-made, four goals: a run worse in time, memory and frame time
    /// but with the smallest image error stays; one beaten in all four
    /// goes; a run whose images were not checked takes no part. The page
    /// draws the image facet and its front only when some run was checked.
    #[test]
    fn the_front_over_four_quantities_by_hand_and_the_image_facet() {
        let a = checked(run(1.0, 100, 10.0), 0.05);
        let b = checked(run(2.0, 200, 12.0), 0.06); // dominated by a
        let c = checked(run(3.0, 300, 12.0), 0.01); // only its images are better
        let d = run(0.5, 50, 9.0); // better in three, but not checked
        let front = pareto_front_4(&[&a, &b, &c, &d]);
        let ids: Vec<*const Run> = front.iter().map(|x| *x as *const Run).collect();
        assert_eq!(ids, vec![&a as *const Run, &c as *const Run]);
        // Without the image error, c is beaten by a.
        assert_eq!(pareto_front_3(&[&a, &c]).len(), 1);

        let mut r = crate::testutil::sample_report();
        assert!(!render_html(&r).contains("Image error vs preprocessing time"));
        let knob = r
            .runs
            .iter()
            .find_map(|x| x.knob.clone().filter(|k| k != TARGET_KNOB))
            .unwrap();
        for (k, x) in r
            .runs
            .iter_mut()
            .filter(|x| x.knob.as_ref() == Some(&knob))
            .enumerate()
        {
            *x = checked(x.clone(), 0.03 + 0.01 * k as f64);
        }
        let html = render_html(&r);
        assert!(html.contains(&format!("Image error vs preprocessing time: {knob}")));
        assert!(html.contains("footprint mismatch 0.0300"));
        assert!(html.contains("over time, memory, worst frame time and image"));
    }
}
