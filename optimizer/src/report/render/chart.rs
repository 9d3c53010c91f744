//! One XY chart as an inline SVG document: `plotters` (SVG backend) draws
//! the frame (title, axes, ticks, grid, axis labels) and maps data to
//! pixels; the series, markers and the legend are written as SVG elements
//! here, which gives dashed lines (`stroke-dasharray`), per-point tooltips
//! and one marker drawing shared by the plot and its legend.

use std::fmt::Write as _;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::prelude::*;

use super::esc;

/// Largest magnitude drawn; larger (and non-finite) values are left out so
/// that axis ranges stay finite.
const MAX_PLOTTED: f64 = 1e15;
/// Smaller magnitudes are drawn as 0.
const MIN_MAGNITUDE: f64 = 1e-200;
/// Most decades a log axis spans (one more for a floor of zeros).
const MAX_DECADES: f64 = 30.0;
/// Width of the whole SVG, pixels.
const WIDTH: u32 = 900;
/// Width of the legend column on the right, pixels.
const LEGEND_WIDTH: u32 = 250;
/// Height of one legend row, pixels.
const LEGEND_ROW: u32 = 18;
/// Smallest chart height, pixels.
const MIN_HEIGHT: u32 = 420;

/// How a series' points are joined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Line {
    /// Not joined.
    None,
    /// A solid line.
    Solid,
    /// A dashed line.
    Dashed,
    /// A dotted line.
    Dotted,
}

/// The mark drawn at each point of a series.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Marker {
    /// No mark.
    None,
    /// A filled disc.
    Circle,
    /// A filled square.
    Square,
    /// A filled triangle.
    Triangle,
    /// A diagonal cross (`×`): values drawn at a log axis' floor.
    Cross,
    /// A hollow ring around the point (highlights, e.g. the Pareto front).
    Ring,
}

/// One data series.
#[derive(Clone, Debug)]
pub(super) struct Series {
    /// Legend text; empty for no legend entry.
    pub name: String,
    /// Stroke and fill colour (`#rrggbb`).
    pub color: &'static str,
    /// How the points are joined (in the given order).
    pub line: Line,
    /// The mark at each point.
    pub marker: Marker,
    /// The points `(x, y)`; non-finite points and magnitudes above 10¹⁵
    /// are left out, magnitudes below 10⁻²⁰⁰ are taken as 0. On a log y
    /// axis, `y <= 0` (and anything below the axis) is drawn at the floor.
    pub points: Vec<(f64, f64)>,
    /// A text beside each point (empty, or one per point).
    pub labels: Vec<String>,
    /// A tooltip for each point (empty, or one per point).
    pub tips: Vec<String>,
    /// A guide (e.g. `y = x`, a target line): drawn, but not data, so a
    /// chart with only guides has no data.
    pub guide: bool,
}

impl Series {
    /// A series without labels or tooltips.
    pub fn new(name: impl Into<String>, color: &'static str, line: Line, marker: Marker) -> Self {
        Self {
            name: name.into(),
            color,
            line,
            marker,
            points: Vec::new(),
            labels: Vec::new(),
            tips: Vec::new(),
            guide: false,
        }
    }
}

/// A chart to draw.
#[derive(Clone, Debug, Default)]
pub(super) struct Chart {
    /// Unique element id (prefix of the SVG's `<title>`/`<desc>` ids).
    pub id: String,
    /// Title drawn above the plot and used as the SVG `<title>`.
    pub title: String,
    /// Longer text description (the SVG `<desc>`).
    pub desc: String,
    /// x axis label, with unit.
    pub x_label: String,
    /// y axis label, with unit.
    pub y_label: String,
    /// Logarithmic y axis.
    pub y_log: bool,
    /// Start the (linear) y axis at 0.
    pub y_from_zero: bool,
    /// Categorical x axis: names of x = 0, 1, 2, ...
    pub x_names: Vec<String>,
    /// The series, drawn in order (later on top).
    pub series: Vec<Series>,
}

/// Whether a value can be placed on an axis.
pub(super) fn plottable(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_PLOTTED
}

/// Distinct data points of a chart that can be drawn (guides excluded).
fn data_points(c: &Chart) -> usize {
    let mut pts: Vec<(u64, u64)> = c
        .series
        .iter()
        .filter(|s| !s.guide)
        .flat_map(|s| s.points.iter())
        .filter(|p| plottable(p.0) && plottable(p.1))
        .map(|p| ((p.0 + 0.0).to_bits(), (p.1 + 0.0).to_bits()))
        .collect();
    pts.sort_unstable();
    pts.dedup();
    pts.len()
}

/// Draws the chart as an `<svg>` element, or `None` when it has fewer than
/// two distinct data points (or the drawing fails).
pub(super) fn render(c: &Chart) -> Option<String> {
    let c = &tame(c);
    if data_points(c) < 2 {
        return None;
    }
    let xs = values(c, |p| p.0, false);
    let ys = values(c, |p| p.1, c.y_log);
    let (x0, x1) = if c.x_names.is_empty() {
        linear_range(&xs, false)?
    } else {
        (-0.5, c.x_names.len() as f64 - 0.5)
    };
    let legend_rows = c.series.iter().filter(|s| !s.name.is_empty()).count() as u32;
    let height = MIN_HEIGHT.max(legend_rows * LEGEND_ROW + 80);
    let mut svg = String::new();
    let body = {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, height)).into_drawing_area();
        let drawn = if c.y_log {
            let zero = c
                .series
                .iter()
                .flat_map(|s| s.points.iter())
                .any(|p| plottable(p.0) && p.1 <= 0.0);
            let (y0, y1) = log_range(&ys, zero);
            frame(&root, c, x0..x1, (y0..y1).log_scale(), y0)
        } else {
            let (y0, y1) = linear_range(&ys, c.y_from_zero)?;
            frame(&root, c, x0..x1, y0..y1, y0)
        };
        let body = drawn.ok()?;
        root.present().ok()?;
        body
    };
    Some(finish(svg, c, &body, height))
}

/// The chart with magnitudes below `MIN_MAGNITUDE` set to 0: plotters'
/// tick searches loop forever on ranges of subnormal size.
fn tame(c: &Chart) -> Chart {
    let mut c = c.clone();
    let t = |v: f64| if v.abs() < MIN_MAGNITUDE { 0.0 } else { v };
    for s in &mut c.series {
        for p in &mut s.points {
            *p = (t(p.0), t(p.1));
        }
    }
    c
}

/// Finite values of one coordinate over all series (positive only when
/// `positive`).
fn values(c: &Chart, f: impl Fn(&(f64, f64)) -> f64, positive: bool) -> Vec<f64> {
    c.series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| plottable(p.0) && plottable(p.1))
        .map(f)
        .filter(|v| !positive || *v > 0.0)
        .collect()
}

/// A padded linear axis range covering `vs` (and 0 when `from_zero`).
fn linear_range(vs: &[f64], from_zero: bool) -> Option<(f64, f64)> {
    let mut lo = vs.iter().copied().fold(f64::INFINITY, f64::min);
    let mut hi = vs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    if from_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let span = hi - lo;
    // A span within a few ulps of its magnitude would make plotters'
    // tick search divide its step forever: treat it as one value.
    let pad = if span > hi.abs().max(lo.abs()) * 1e-6 {
        span * 0.05
    } else {
        (hi.abs() * 0.1).max(1.0)
    };
    let lo = if from_zero && lo >= 0.0 {
        0.0
    } else {
        lo - pad
    };
    Some((lo, hi + pad))
}

/// A log axis range of whole decades covering the positive `vs`; one more
/// decade below when some values are 0 (they are drawn at that floor).
fn log_range(vs: &[f64], zero: bool) -> (f64, f64) {
    let lo = vs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = vs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0) {
        return (1e-3, 1.0);
    }
    let mut b = hi.log10().ceil();
    // At most MAX_DECADES (smaller values sit on the floor): plotters
    // counts decades in an integer and never finishes on ~300 of them.
    let mut a = lo.log10().floor().max(b - MAX_DECADES);
    if b <= a {
        b = a + 1.0;
    }
    if zero {
        a -= 1.0;
    }
    (10f64.powi(a as i32), 10f64.powi(b as i32))
}

/// Draws the frame with `plotters` and returns the SVG of the series and
/// the legend, positioned with the chart's coordinate mapping.
fn frame<Y>(
    root: &DrawingArea<SVGBackend<'_>, Shift>,
    c: &Chart,
    x: std::ops::Range<f64>,
    y: Y,
    y_floor: f64,
) -> Result<String, String>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let err = |e: DrawingAreaErrorKind<_>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let (width, _) = root.dim_in_pixel();
    let (plot, legend) = root.split_horizontally(width.saturating_sub(LEGEND_WIDTH));
    let mut chart = ChartBuilder::on(&plot)
        .caption(&c.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)
        .map_err(err)?;
    let names = &c.x_names;
    let x_fmt = |v: &f64| {
        if names.is_empty() {
            number(*v)
        } else {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 {
                names.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        }
    };
    let y_log = c.y_log;
    let y_fmt = |v: &f64| if y_log { log_tick(*v) } else { number(*v) };
    chart
        .configure_mesh()
        .x_desc(&c.x_label)
        .y_desc(&c.y_label)
        .x_labels(if names.is_empty() { 10 } else { names.len() })
        .y_labels(10)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .axis_desc_style(("sans-serif", 15))
        .label_style(("sans-serif", 13))
        .max_light_lines(4)
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(err)?;
    let map = |p: (f64, f64)| {
        let yv = if y_log && p.1 < y_floor { y_floor } else { p.1 };
        chart.backend_coord(&(p.0, yv))
    };
    let mut out = String::new();
    let floor_used = y_log
        && c.series
            .iter()
            .flat_map(|s| s.points.iter())
            .any(|p| plottable(p.0) && p.1 <= 0.0);
    if floor_used {
        // The floor stands for 0, which a log axis has no place for.
        let (px, py) = chart.plotting_area().get_base_pixel();
        let (_, fy) = map((0.0, 0.0));
        let _ = write!(
            out,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"end\" font-family=\"sans-serif\" \
             font-size=\"11\" fill=\"#b00\">0 ×</text>",
            px - 8,
            fy.max(py) + 4
        );
    }
    for s in &c.series {
        series_svg(&mut out, s, &map);
    }
    let (lx, ly) = legend.get_base_pixel();
    legend_svg(&mut out, c, lx + 8, ly + 40);
    Ok(out)
}

/// Writes one series: its line, then its markers and labels.
fn series_svg(out: &mut String, s: &Series, map: &dyn Fn((f64, f64)) -> (i32, i32)) {
    let pts: Vec<(usize, (i32, i32))> = s
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| plottable(p.0) && plottable(p.1))
        .map(|(i, p)| (i, map(*p)))
        .collect();
    if pts.is_empty() {
        return;
    }
    out.push_str("<g>");
    if !s.name.is_empty() {
        let _ = write!(out, "<title>{}</title>", esc(&s.name));
    }
    if s.line != Line::None && pts.len() > 1 {
        let coords: Vec<String> = pts.iter().map(|(_, (x, y))| format!("{x},{y}")).collect();
        let _ = write!(
            out,
            "<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"{}\"{} points=\"{}\"/>",
            s.color,
            if s.guide { "1.5" } else { "2" },
            dash(s.line),
            coords.join(" ")
        );
    }
    for (i, (x, y)) in &pts {
        let tip = s.tips.get(*i).filter(|t| !t.is_empty());
        if let Some(t) = tip {
            let _ = write!(out, "<g><title>{}</title>", esc(t));
        }
        marker_svg(out, s.marker, s.color, *x, *y);
        if tip.is_some() {
            out.push_str("</g>");
        }
        if let Some(l) = s.labels.get(*i).filter(|l| !l.is_empty()) {
            let _ = write!(
                out,
                "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"11\" fill=\"#333\">{}</text>",
                x + 7,
                y - 7,
                esc(l)
            );
        }
    }
    out.push_str("</g>\n");
}

/// The `stroke-dasharray` attribute of a line kind.
fn dash(line: Line) -> &'static str {
    match line {
        Line::Dashed => " stroke-dasharray=\"8 5\"",
        Line::Dotted => " stroke-dasharray=\"2 4\" stroke-linecap=\"round\"",
        Line::None | Line::Solid => "",
    }
}

/// Writes one marker centred at `(x, y)`.
fn marker_svg(out: &mut String, m: Marker, color: &str, x: i32, y: i32) {
    let _ = match m {
        Marker::None => Ok(()),
        Marker::Circle => write!(
            out,
            "<circle cx=\"{x}\" cy=\"{y}\" r=\"4\" fill=\"{color}\"/>"
        ),
        Marker::Square => write!(
            out,
            "<rect x=\"{}\" y=\"{}\" width=\"8\" height=\"8\" fill=\"{color}\"/>",
            x - 4,
            y - 4
        ),
        Marker::Triangle => write!(
            out,
            "<path d=\"M{} {}L{} {}L{} {}Z\" fill=\"{color}\"/>",
            x,
            y - 5,
            x + 5,
            y + 4,
            x - 5,
            y + 4
        ),
        Marker::Cross => write!(
            out,
            "<path d=\"M{} {}L{} {}M{} {}L{} {}\" stroke=\"{color}\" stroke-width=\"2.5\"/>",
            x - 5,
            y - 5,
            x + 5,
            y + 5,
            x - 5,
            y + 5,
            x + 5,
            y - 5
        ),
        Marker::Ring => write!(
            out,
            "<circle cx=\"{x}\" cy=\"{y}\" r=\"8\" fill=\"none\" stroke=\"{color}\" stroke-width=\"2\"/>"
        ),
    };
}

/// Writes the legend: one row per named series, sample line and marker.
fn legend_svg(out: &mut String, c: &Chart, x: i32, y: i32) {
    out.push_str("<g class=\"legend\">");
    let _ = write!(
        out,
        "<text x=\"{x}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"13\" font-weight=\"bold\">Legend</text>",
        y - 16
    );
    for (row, s) in c.series.iter().filter(|s| !s.name.is_empty()).enumerate() {
        let cy = y + row as i32 * LEGEND_ROW as i32;
        if s.line != Line::None {
            let _ = write!(
                out,
                "<line x1=\"{x}\" y1=\"{cy}\" x2=\"{}\" y2=\"{cy}\" stroke=\"{}\" stroke-width=\"2\"{}/>",
                x + 28,
                s.color,
                dash(s.line)
            );
        }
        marker_svg(out, s.marker, s.color, x + 14, cy);
        let _ = write!(
            out,
            "<text x=\"{}\" y=\"{}\" font-family=\"sans-serif\" font-size=\"12\">{}</text>",
            x + 36,
            cy + 4,
            esc(&s.name)
        );
    }
    out.push_str("</g>\n");
}

/// Adds the accessible name and description and the series to the
/// `plotters` SVG document.
fn finish(svg: String, c: &Chart, body: &str, height: u32) -> String {
    let head = format!(
        "<svg role=\"img\" aria-labelledby=\"{id}-t {id}-d\" class=\"chart\" \
         style=\"max-width:100%;height:auto\" width=\"{WIDTH}\" height=\"{height}\" \
         viewBox=\"0 0 {WIDTH} {height}\" xmlns=\"http://www.w3.org/2000/svg\">\n\
         <title id=\"{id}-t\">{t}</title><desc id=\"{id}-d\">{d}</desc>\n",
        id = esc(&c.id),
        t = esc(&c.title),
        d = esc(&c.desc)
    );
    // Replace plotters' opening tag (its first line) and insert the
    // series before the closing tag.
    let rest = svg.split_once('\n').map_or("", |(_, r)| r);
    let rest = rest.trim_end();
    let rest = rest.strip_suffix("</svg>").unwrap_or(rest);
    format!("{head}{rest}\n{body}</svg>\n")
}

/// A short, deterministic tick label.
pub(super) fn number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.0e}");
    }
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Log axis tick labels: decades and their 2× and 5× multiples, blank for
/// the other minor ticks.
fn log_tick(v: f64) -> String {
    if v <= 0.0 {
        return String::new();
    }
    let m = v / 10f64.powf(v.log10().floor());
    let near = |k: f64| (m - k).abs() < 1e-6 * k;
    if near(1.0) || near(2.0) || near(5.0) || near(10.0) {
        number(v)
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(points: Vec<(f64, f64)>, y_log: bool) -> Chart {
        let mut s = Series::new("a <b>", "#000000", Line::Dashed, Marker::Circle);
        s.points = points;
        Chart {
            id: "c".into(),
            title: "T".into(),
            x_label: "x (s)".into(),
            y_label: "y (MB)".into(),
            y_log,
            series: vec![s],
            ..Chart::default()
        }
    }

    #[test]
    fn draws_svg_with_title_legend_and_dashes() {
        let svg = render(&chart(vec![(1.0, 2.0), (2.0, 30.0)], true)).expect("chart");
        assert_eq!(svg.matches("<svg").count(), 1);
        assert!(svg.contains("<title id=\"c-t\">T</title>"));
        assert!(svg.contains("stroke-dasharray"));
        assert!(svg.contains("a &lt;b&gt;"), "legend text is escaped");
        assert!(svg.contains("y (MB)") && svg.contains("x (s)"));
        assert!(svg.trim_end().ends_with("</svg>"));
    }

    #[test]
    fn too_few_or_unplottable_points_draw_nothing() {
        assert!(render(&chart(vec![(1.0, 2.0)], false)).is_none());
        assert!(render(&chart(vec![(1.0, 2.0), (1.0, 2.0)], false)).is_none());
        assert!(render(&chart(vec![(f64::NAN, 2.0), (1.0, f64::INFINITY)], true)).is_none());
        assert!(render(&chart(vec![(1.0, 1e300), (2.0, 1.0), (3.0, 2.0)], false)).is_some());
    }

    #[test]
    fn degenerate_ranges_still_draw() {
        for log in [false, true] {
            assert!(render(&chart(vec![(1.0, 1.0), (1.0, 2.0)], log)).is_some());
            assert!(render(&chart(vec![(0.0, 0.0), (-0.0, 1.0)], log)).is_some());
            assert!(render(&chart(vec![(0.0, 0.0), (1.0, 0.0)], log)).is_some());
            assert!(render(&chart(vec![(-5.0, 1e-9), (1e12, 1e12)], log)).is_some());
            assert!(render(&chart(vec![(1e15, 1.0), (1e15 - 0.125, 2.0)], log)).is_some());
            assert!(render(&chart(vec![(-1e15, 1e-300), (1e15, 1e15)], log)).is_some());
            assert!(render(&chart(vec![(0.0, 5e-324), (1.0, 1.0)], log)).is_some());
        }
    }

    #[test]
    fn awkward_values_never_hang_or_panic() {
        // Near-equal huge values once sent plotters' tick search into an
        // endless loop; mix them with zeros, extremes and non-finite values.
        let pool = [
            0.0,
            -0.0,
            5e-324,
            1e-300,
            2e-200,
            1e-199,
            1e-9,
            0.125,
            1.0,
            3.0,
            1e12,
            1e15,
            1e15 - 0.125,
            1e15 + 0.25,
            -1e15,
            2e15,
            f64::MAX,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let mut rng = crate::math::rng::Rng::new(7);
        let mut pick = || pool[(rng.next_u64() % pool.len() as u64) as usize];
        let mut drawn = 0;
        for i in 0..300 {
            let n = 2 + i % 4;
            let points = (0..n).map(|_| (pick(), pick())).collect();
            let mut c = chart(points, i % 2 == 0);
            c.y_from_zero = i % 3 == 0;
            if i % 5 == 0 {
                c.x_names = vec!["a".into(), "b".into()];
            }
            if let Some(svg) = render(&c) {
                assert!(!svg.contains("NaN") && !svg.contains("inf"), "{c:?}");
                drawn += 1;
            }
        }
        assert!(drawn > 100, "most charts have data: {drawn}");
    }

    #[test]
    fn log_range_is_whole_decades_with_a_floor_for_zeros() {
        assert_eq!(log_range(&[2.0, 30.0], false), (1.0, 100.0));
        assert_eq!(log_range(&[2.0, 3.0], false), (1.0, 10.0));
        assert_eq!(log_range(&[2.0, 30.0], true), (0.1, 100.0));
        assert_eq!(log_range(&[], true), (1e-3, 1.0));
        assert_eq!(log_range(&[1e-100, 1e15], false), (1e-15, 1e15));
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(number(2.5), "2.5");
        assert_eq!(number(10.0), "10");
        assert_eq!(number(1e7), "1e7");
        assert_eq!(log_tick(20.0), "20");
        assert_eq!(log_tick(30.0), "");
    }
}
