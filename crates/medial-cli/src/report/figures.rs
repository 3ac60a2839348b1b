//! The figures of the report, drawn by plotters as SVG: grids of line panels (a quantity
//! against the iteration or the time point, vertical marks with a label) and histograms.
//! Text is written as SVG `<text>` and laid out by the browser (no font files are read).

use super::label::number;
use crate::error::CliError;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
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

/// A vertical mark across a panel (the start of an AL iteration) with a label (its μ).
#[derive(Clone)]
pub struct Mark {
    /// Where, on the x axis.
    pub x: f64,
    /// The label, drawn at the top of the panel right of the mark.
    pub label: String,
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
    for mark in &panel.marks {
        chart.draw_series(DashedLineSeries::new(
            [(mark.x, y.start), (mark.x, y.end)],
            4,
            3,
            RGBColor(150, 150, 150).stroke_width(1),
        ))?;
        chart.draw_series(std::iter::once(Text::new(
            mark.label.clone(),
            (mark.x, y.end),
            ("sans-serif", 10).into_font().color(&RGBColor(90, 90, 90)),
        )))?;
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
