//! The figures of the report, drawn by plotters as SVG: grids of line panels (a quantity
//! against the iteration or the time point, vertical marks with a label) and histograms.
//! Text is written as SVG `<text>` and laid out by the browser (no font files are read).

use super::label::number;
use crate::error::CliError;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;

/// Width and height of one panel, pixels.
const PANEL: (u32, u32) = (460, 270);

/// The colour of the lines of the figures.
pub const LINE: RGBColor = RGBColor(31, 119, 180);

/// The colour of the first data set of a histogram (template).
pub const FIRST: RGBColor = RGBColor(140, 140, 140);

/// A polyline of a panel.
pub struct Line {
    /// The points `(x, y)`; non-finite ones are left out (and, on a log axis, non-positive y).
    pub points: Vec<(f64, f64)>,
    /// Draw a dot at each point.
    pub dots: bool,
}

/// What a vertical mark marks (its line style).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarkKind {
    /// The start of an AL iteration: dashed grey.
    Al,
    /// A change of the flow's time steps (coarse to fine): solid orange.
    Switch,
    /// A fresh start of the minimiser within an AL iteration: dotted red.
    Restart,
}

/// A vertical mark across a panel (the start of an AL iteration, the switch to finer time
/// steps, a restart) with a label (its μ, the steps).
#[derive(Clone)]
pub struct Mark {
    /// Where, on the x axis.
    pub x: f64,
    /// The label, drawn at the top of the panel right of the mark (consecutive labels on two
    /// alternating lines).
    pub label: String,
    /// What it marks.
    pub kind: MarkKind,
}

/// One panel: a quantity against x.
pub struct Panel {
    /// The caption (the quantity and its unit).
    pub title: String,
    /// What x is.
    pub x_label: String,
    /// The lines.
    pub lines: Vec<Line>,
    /// Vertical marks.
    pub marks: Vec<Mark>,
}

impl Panel {
    /// The finite points of every line.
    fn finite(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.lines
            .iter()
            .flat_map(|l| l.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    }

    /// Whether the panel has a point to draw.
    pub fn has_points(&self) -> bool {
        self.finite().next().is_some()
    }

    /// Whether y is drawn on a log scale: every value positive and the values spanning two
    /// decades or more, within [`LOG_LIMITS`] (plotters' tick loop on a log axis down to a
    /// subnormal value never ends; such an axis is drawn linear).
    pub fn log_y(&self) -> bool {
        let (lo, hi) = span(self.finite().map(|p| p.1));
        lo >= LOG_LIMITS.0 && hi <= LOG_LIMITS.1 && hi / lo >= 100.0
    }
}

/// The smallest and largest of `values` (`(∞, −∞)` for none).
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

/// The values a log axis may span.
const LOG_LIMITS: (f64, f64) = (1e-100, 1e100);

/// The largest magnitude a linear axis spans: beyond, its width overflows and plotters' tick
/// loop never ends. Points beyond are clipped.
const LINEAR_LIMIT: f64 = 1e300;

/// A range around `[lo, hi]` that is never empty: 5 % more on each side on a linear axis,
/// within ±[`LINEAR_LIMIT`].
fn padded(lo: f64, hi: f64) -> Range<f64> {
    let (lo, hi) = (
        lo.clamp(-LINEAR_LIMIT, LINEAR_LIMIT),
        hi.clamp(-LINEAR_LIMIT, LINEAR_LIMIT),
    );
    if hi > lo {
        let pad = 0.05 * (hi - lo);
        lo - pad..hi + pad
    } else {
        let pad = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        lo - pad..hi + pad
    }
}

/// An error of plotters as the report's error.
fn figure_error(what: &str) -> impl Fn(DrawingAreaErrorKind<std::io::Error>) -> CliError + '_ {
    move |e| CliError::Figure {
        figure: what.to_owned(),
        message: e.to_string(),
    }
}

/// Panels with points in a grid `columns` wide, as one SVG element; `None` when no panel has a
/// point. `what` names the figure in errors.
///
/// Errors: [`CliError::Figure`] when plotters fails.
pub fn grid(what: &str, panels: &[Panel], columns: usize) -> Result<Option<String>, CliError> {
    let panels: Vec<&Panel> = panels.iter().filter(|p| p.has_points()).collect();
    if panels.is_empty() {
        return Ok(None);
    }
    let columns = columns.clamp(1, panels.len());
    let rows = panels.len().div_ceil(columns);
    let size = (PANEL.0 * columns as u32, PANEL.1 * rows as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(figure_error(what))?;
        for (area, panel) in root.split_evenly((rows, columns)).iter().zip(panels) {
            draw_panel(area, panel).map_err(figure_error(what))?;
        }
        root.present().map_err(figure_error(what))?;
    }
    Ok(Some(svg))
}

/// Draws one panel, on a log y axis where [`Panel::log_y`] says so.
fn draw_panel(
    area: &DrawingArea<SVGBackend, Shift>,
    panel: &Panel,
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    let (x_lo, x_hi) = span(panel.finite().map(|p| p.0));
    let (y_lo, y_hi) = span(panel.finite().map(|p| p.1));
    let x = padded(x_lo, x_hi);
    if panel.log_y() {
        let y = y_lo / 1.5..y_hi * 1.5;
        draw_on(area, panel, x, y.clone().log_scale(), y, true)
    } else {
        let y = padded(y_lo, y_hi);
        draw_on(area, panel, x, y.clone(), y, false)
    }
}

/// Draws `panel` on axes `x` and `y_axis` (whose values span `y`).
fn draw_on<Y>(
    area: &DrawingArea<SVGBackend, Shift>,
    panel: &Panel,
    x: Range<f64>,
    y_axis: Y,
    y: Range<f64>,
    log: bool,
) -> Result<(), DrawingAreaErrorKind<std::io::Error>>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let title = if log {
        format!("{} (log scale)", panel.title)
    } else {
        panel.title.clone()
    };
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 15))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(62)
        .build_cartesian_2d(x.clone(), y_axis)?;
    let format = |v: &f64| number(*v);
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&format)
        .y_label_formatter(&format)
        .light_line_style(RGBColor(235, 235, 235))
        .label_style(("sans-serif", 11))
        .axis_desc_style(("sans-serif", 12))
        .draw()?;
    for (k, mark) in panel.marks.iter().enumerate() {
        let ends = [(mark.x, y.start), (mark.x, y.end)];
        let colour = match mark.kind {
            MarkKind::Al => RGBColor(150, 150, 150),
            MarkKind::Switch => RGBColor(230, 120, 0),
            MarkKind::Restart => RGBColor(214, 39, 40),
        };
        match mark.kind {
            MarkKind::Switch => chart.draw_series(LineSeries::new(ends, colour.stroke_width(2))),
            MarkKind::Al => chart.draw_series(DashedLineSeries::new(ends, 4, 3, colour.into())),
            MarkKind::Restart => {
                chart.draw_series(DashedLineSeries::new(ends, 1, 3, colour.into()))
            }
        }?;
        let text = match mark.kind {
            MarkKind::Al => RGBColor(90, 90, 90),
            _ => colour,
        };
        chart.draw_series(std::iter::once(
            EmptyElement::at((mark.x, y.end))
                + Text::new(
                    mark.label.clone(),
                    (3, 2 + 11 * (k as i32 % 2)),
                    ("sans-serif", 10).into_font().color(&text),
                ),
        ))?;
    }
    // Only points on the axes: plotters' pixel arithmetic overflows far beyond them.
    let keep = |&(px, py): &(f64, f64)| x.contains(&px) && py >= y.start && py <= y.end;
    for line in &panel.lines {
        let points: Vec<(f64, f64)> = line.points.iter().copied().filter(keep).collect();
        chart.draw_series(LineSeries::new(
            points.iter().copied(),
            LINE.stroke_width(2),
        ))?;
        if line.dots {
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 2, LINE.filled())))?;
        }
    }
    Ok(())
}

/// One data set of a histogram.
pub struct Counted<'a> {
    /// The legend.
    pub label: String,
    /// The values.
    pub values: &'a [f64],
    /// Its colour.
    pub colour: RGBColor,
}

/// A histogram of the finite values of each data set over common bins, the first data set
/// drawn as an outline, the others filled and translucent; `None` without a finite value.
///
/// Errors: [`CliError::Figure`] when plotters fails.
pub fn histogram(
    title: &str,
    x_label: &str,
    sets: &[Counted<'_>],
    bins: usize,
) -> Result<Option<String>, CliError> {
    let finite = || {
        sets.iter()
            .flat_map(|s| s.values.iter().copied())
            .filter(|v| v.is_finite())
    };
    let (lo, hi) = span(finite());
    if !lo.is_finite() {
        return Ok(None);
    }
    let range = padded(lo, hi);
    let width = (range.end - range.start) / bins as f64;
    let counts: Vec<Vec<usize>> = sets
        .iter()
        .map(|s| {
            let mut c = vec![0; bins];
            for v in s.values.iter().filter(|v| v.is_finite()) {
                c[(((v - range.start) / width) as usize).min(bins - 1)] += 1;
            }
            c
        })
        .collect();
    let top = counts.iter().flatten().copied().max().unwrap_or(1) as f64 * 1.1;
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (2 * PANEL.0, PANEL.1 + 40)).into_drawing_area();
        let fail = figure_error(title);
        root.fill(&WHITE).map_err(&fail)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(range.clone(), 0.0..top)
            .map_err(&fail)?;
        let format = |v: &f64| number(*v);
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc("count")
            .x_label_formatter(&format)
            .light_line_style(RGBColor(235, 235, 235))
            .label_style(("sans-serif", 11))
            .axis_desc_style(("sans-serif", 12))
            .draw()
            .map_err(&fail)?;
        for (k, (set, counts)) in sets.iter().zip(&counts).enumerate() {
            let style = if k == 0 {
                set.colour.stroke_width(2)
            } else {
                set.colour.mix(0.55).filled()
            };
            let bar = |(i, &c): (usize, &usize)| {
                let x0 = range.start + i as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width, c as f64)], style)
            };
            let colour = set.colour;
            chart
                .draw_series(counts.iter().enumerate().filter(|(_, &c)| c > 0).map(bar))
                .map_err(&fail)?
                .label(set.label.as_str())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 14, y + 5)], colour.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(200, 200, 200))
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(&fail)?;
        root.present().map_err(&fail)?;
    }
    Ok(Some(svg))
}

/// Width and height of one slice panel, pixels.
const PLANE: (u32, u32) = (330, 330);

/// The grey of an image's foreground in a slice.
const MASK: RGBColor = RGBColor(200, 200, 200);

/// The colour of the model's boundary in a slice (`#d62728`).
pub const BOUNDARY: RGBColor = RGBColor(214, 39, 40);

/// The colour of the medial sheet in a slice (`#1f77b4`).
pub const MEDIAL: RGBColor = RGBColor(31, 119, 180);

/// What a slice panel draws, in the plane's coordinates `(u, v)` (mm).
#[derive(Default)]
pub struct Curves {
    /// The image's foreground, as rectangles `[u0, v0, u1, v1]`.
    pub mask: Vec<[f64; 4]>,
    /// The target surface's section.
    pub target: Vec<Vec<(f64, f64)>>,
    /// Target points near the plane.
    pub points: Vec<(f64, f64)>,
    /// The model's boundary's section.
    pub boundary: Vec<Vec<(f64, f64)>>,
    /// The medial sheet's section.
    pub medial: Vec<Vec<(f64, f64)>>,
}

/// One slice: a plane with what it cuts, on axes of equal scale.
pub struct PlanePanel {
    /// The caption (the plane and the time point).
    pub title: String,
    /// The horizontal axis.
    pub u_label: String,
    /// The vertical axis.
    pub v_label: String,
    /// The horizontal range to show, mm (widened to equal scale).
    pub u_range: Range<f64>,
    /// The vertical range to show, mm (widened to equal scale).
    pub v_range: Range<f64>,
    /// What is drawn.
    pub curves: Curves,
}

/// Builds the chart of a slice panel on `area`.
fn plane_chart<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    title: &str,
    u: Range<f64>,
    v: Range<f64>,
) -> Result<
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    DrawingAreaErrorKind<std::io::Error>,
> {
    ChartBuilder::on(area)
        .caption(title, ("sans-serif", 12))
        .margin(6)
        .x_label_area_size(34)
        .y_label_area_size(46)
        .build_cartesian_2d(u, v)
}

/// `u` and `v` widened about their centres so that a mm is as long across as up on a plot of
/// `pixels` (width, height).
fn equal_scale(u: Range<f64>, v: Range<f64>, pixels: (u32, u32)) -> (Range<f64>, Range<f64>) {
    let (du, dv) = (u.end - u.start, v.end - v.start);
    let aspect = f64::from(pixels.0.max(1)) / f64::from(pixels.1.max(1));
    let widen = |r: Range<f64>, to: f64| {
        let c = (r.start + r.end) / 2.0;
        c - to / 2.0..c + to / 2.0
    };
    if du / dv < aspect {
        (widen(u, dv * aspect), v)
    } else {
        (u, widen(v, du / aspect))
    }
}

/// Slice panels in a grid `columns` wide, as one SVG element: on axes of equal scale, the
/// image's foreground in grey, the target's section in black, the model's boundary in
/// [`BOUNDARY`] and its medial sheet in [`MEDIAL`]. `what` names the figure in errors.
///
/// Errors: [`CliError::Figure`] when plotters fails.
pub fn planes(what: &str, panels: &[PlanePanel], columns: usize) -> Result<String, CliError> {
    let fail = figure_error(what);
    // The plotting area of a panel, from a chart built on a throwaway canvas.
    let plot = {
        let mut scratch = String::new();
        let root = SVGBackend::with_string(&mut scratch, PLANE).into_drawing_area();
        let chart = plane_chart(&root, "x", 0.0..1.0, 0.0..1.0).map_err(&fail)?;
        chart.plotting_area().dim_in_pixel()
    };
    let columns = columns.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(columns).max(1);
    let mut svg = String::new();
    {
        let size = (PLANE.0 * columns as u32, PLANE.1 * rows as u32);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(&fail)?;
        for (area, panel) in root.split_evenly((rows, columns)).iter().zip(panels) {
            draw_plane(area, panel, plot).map_err(&fail)?;
        }
        root.present().map_err(&fail)?;
    }
    Ok(svg)
}

/// Draws one slice panel whose plotting area is `plot` pixels.
fn draw_plane(
    area: &DrawingArea<SVGBackend, Shift>,
    panel: &PlanePanel,
    plot: (u32, u32),
) -> Result<(), DrawingAreaErrorKind<std::io::Error>> {
    let (u, v) = equal_scale(panel.u_range.clone(), panel.v_range.clone(), plot);
    let mut chart = plane_chart(area, &panel.title, u, v)?;
    let format = |v: &f64| number(*v);
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(panel.u_label.as_str())
        .y_desc(panel.v_label.as_str())
        .x_labels(5)
        .y_labels(5)
        .x_label_formatter(&format)
        .y_label_formatter(&format)
        .label_style(("sans-serif", 10))
        .axis_desc_style(("sans-serif", 11))
        .draw()?;
    let c = &panel.curves;
    chart.draw_series(
        c.mask
            .iter()
            .map(|r| Rectangle::new([(r[0], r[1]), (r[2], r[3])], MASK.filled())),
    )?;
    let paths = |lines: &[Vec<(f64, f64)>], colour: RGBColor| {
        lines
            .iter()
            .map(move |l| PathElement::new(l.clone(), colour.stroke_width(2)))
            .collect::<Vec<_>>()
    };
    chart.draw_series(paths(&c.target, BLACK))?;
    chart.draw_series(c.points.iter().map(|&p| Circle::new(p, 2, BLACK.filled())))?;
    chart.draw_series(paths(&c.boundary, BOUNDARY))?;
    chart.draw_series(paths(&c.medial, MEDIAL))?;
    Ok(())
}

/// Text safe in XML.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A PNG of views side by side, each `width × height` pixels, in one SVG element with a caption
/// above each view and, where `scale` gives its range (mm), the viridis colour scale below.
pub fn image_strip(
    png: &[u8],
    width: usize,
    height: usize,
    captions: &[String],
    scale: Option<(f64, f64)>,
) -> String {
    use std::fmt::Write;
    let total = width * captions.len();
    let top = 22;
    let bottom = if scale.is_some() { 44 } else { 6 };
    let h = top + height + bottom;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{total}\" height=\"{h}\" \
         viewBox=\"0 0 {total} {h}\" font-family=\"sans-serif\">"
    );
    for (k, caption) in captions.iter().enumerate() {
        let _ = write!(
            svg,
            "<text x=\"{}\" y=\"15\" font-size=\"13\" text-anchor=\"middle\">{}</text>",
            k * width + width / 2,
            escape(caption)
        );
    }
    let _ = write!(
        svg,
        "<image x=\"0\" y=\"{top}\" width=\"{total}\" height=\"{height}\" \
         href=\"data:image/png;base64,{}\"/>",
        super::png::base64(png)
    );
    if let Some((lo, hi)) = scale {
        let (x0, bar, y) = (total / 2 - 150, 300, top + height + 6);
        for k in 0..60 {
            let [r, g, b] =
                super::render::viridis((k as f64 + 0.5) / 60.0).map(|c| (255.0 * c).round() as u8);
            let _ = write!(
                svg,
                "<rect x=\"{}\" y=\"{y}\" width=\"5.5\" height=\"12\" fill=\"rgb({r},{g},{b})\"/>",
                x0 + k * bar / 60
            );
        }
        let ty = y + 26;
        let _ = write!(
            svg,
            "<text x=\"{x0}\" y=\"{ty}\" font-size=\"11\" text-anchor=\"middle\">{}</text>\
             <text x=\"{}\" y=\"{ty}\" font-size=\"11\" text-anchor=\"middle\">{}</text>\
             <text x=\"{}\" y=\"{ty}\" font-size=\"11\" text-anchor=\"middle\">thickness (mm)</text>",
            number(lo),
            x0 + bar,
            number(hi),
            x0 + bar / 2
        );
    }
    svg.push_str("</svg>");
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panel(ys: &[f64]) -> Panel {
        Panel {
            title: "data term".into(),
            x_label: "iteration".into(),
            lines: vec![Line {
                points: ys.iter().enumerate().map(|(i, &y)| (i as f64, y)).collect(),
                dots: false,
            }],
            marks: vec![Mark {
                x: 1.0,
                label: "μ = 0.02".into(),
                kind: MarkKind::Al,
            }],
        }
    }

    #[test]
    fn log_scale_where_positive_values_span_two_decades() {
        assert!(panel(&[1.0, 0.1, 0.01]).log_y());
        assert!(!panel(&[1.0, 0.1, 0.02]).log_y());
        assert!(!panel(&[1.0, 0.0, 0.001]).log_y());
        assert!(!panel(&[f64::NAN, 3.0]).log_y());
    }

    #[test]
    fn a_grid_is_one_svg_with_the_captions_and_marks() {
        let svg = grid("test", &[panel(&[1.0, 0.1, 1e-4]), panel(&[2.0, 3.0])], 2)
            .unwrap()
            .unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("data term (log scale)") && svg.contains("μ = 0.02"));
        assert_eq!(svg.matches("<svg").count(), 1);
        assert!(grid("empty", &[panel(&[f64::NAN])], 2).unwrap().is_none());
    }

    /// Issue 33, item 6: values at and below the smallest normal number (`log.csv`'s
    /// `data = 1e-310`) are drawn, not a tick loop that never ends.
    #[test]
    fn subnormal_and_tiny_values_are_drawn() {
        for ys in [
            &[1e-310, 1e-310][..],
            &[1e-310, 2e-310, 3e-310],
            &[0.0, 1e-310],
            &[-1e-310, 1e-310],
            &[1.0, 1e-310],
            &[1e-100, 1.0],
            &[1e-99, 1e99],
            &[1e-300, 1e-310, 1e-320],
            &[f64::MIN_POSITIVE, 5e-324],
            &[5e-324],
            &[1e300, -1e300],
            &[f64::MAX, -f64::MAX],
        ] {
            let svg = grid("test", &[panel(ys)], 1).unwrap().unwrap();
            assert!(svg.contains("data term"), "{ys:?}");
            let counted = Counted {
                label: "t = 0".into(),
                values: ys,
                colour: FIRST,
            };
            assert!(histogram("h", "mm", &[counted], 5).unwrap().is_some());
        }
    }

    #[test]
    fn a_histogram_counts_every_value() {
        let a = [1.0, 1.1, 2.0, 3.0];
        let svg = histogram(
            "spoke lengths",
            "mm",
            &[Counted {
                label: "t = 0".into(),
                values: &a,
                colour: FIRST,
            }],
            3,
        )
        .unwrap()
        .unwrap();
        assert!(svg.contains("spoke lengths") && svg.contains("t = 0"));
        assert!(histogram("none", "mm", &[], 3).unwrap().is_none());
    }
}
