//! `report.html` of `medial stats` and of `medial pca`: one self-contained page each (the fit
//! report's style, inline SVG and PNG). Stats: the design, and per contrast the maps rendered on
//! the mesh, the permutations' null distributions with the observed value and the 5 % critical
//! value, and the clusters. PCA: the explained variance (scree) and the subjects' scores.

use super::figures::{self, Line, Mark, MarkKind, Panel};
use super::label::number;
use super::page::STYLE;
use super::png;
use super::render::{Camera, Canvas};
use super::table::Table;
use crate::error::CliError;
use maud::{html, Markup, PreEscaped, DOCTYPE};
use medial_core::TriMesh;
use medial_stats::permutation::critical_value;
use medial_stats::{Contrast, ContrastResult, Design, Tail};
use std::path::Path;

/// Side of one rendered view, pixels (drawn at [`SUPERSAMPLE`] times this and shrunk).
const VIEW: (usize, usize) = (300, 250);

/// Supersampling of the rendered views.
const SUPERSAMPLE: usize = 3;

/// The family-wise level of the critical values and of the significance maps.
const ALPHA: f64 = 0.05;

/// Bins of the null distributions' histograms.
const BINS: usize = 30;

/// The ends of the diverging scale of t (negative, positive); 0 is white.
const NEGATIVE: [f64; 3] = [0.23, 0.30, 0.75];
const POSITIVE: [f64; 3] = [0.71, 0.02, 0.15];

/// A significant element, and one that is not (or was not tested).
const SIGNIFICANT: [f64; 3] = [0.84, 0.15, 0.16];
const NOT_SIGNIFICANT: [f64; 3] = [0.82, 0.82, 0.82];

/// The mesh the maps are on: its triangles, and whether the maps are per triangle (else per
/// point).
pub struct MapMesh<'a> {
    /// The mesh.
    pub mesh: &'a TriMesh,
    /// The maps have a value per triangle.
    pub cells: bool,
}

impl MapMesh<'_> {
    /// The value of each triangle of a map: its own, or the mean of its corners' (NaN if one is).
    fn per_triangle(&self, map: &[f64]) -> Vec<f64> {
        if self.cells {
            return map.to_vec();
        }
        self.mesh
            .triangles()
            .iter()
            .map(|t| t.iter().map(|&i| map[i]).sum::<f64>() / 3.0)
            .collect()
    }

    /// Whether each triangle is significant in the map of corrected p-values `p`: its own
    /// p at most [`ALPHA`], or for a map per point, most of its corners' (a mean of p-values
    /// is not a p-value: three corners at 0.01, 0.01 and 0.2 are mostly significant, their
    /// mean 0.073 is not).
    fn significant(&self, p: &[f64]) -> Vec<bool> {
        if self.cells {
            return p.iter().map(|&v| v <= ALPHA).collect();
        }
        (self.mesh.triangles().iter())
            .map(|t| t.iter().filter(|&&i| p[i] <= ALPHA).count() >= 2)
            .collect()
    }

    /// The PNG of two views of the mesh side by side, the front (as [`Camera::framing`] looks)
    /// and the back, triangle `t` in `colour(t)`; `None` where the mesh cannot be framed.
    fn views(&self, colour: impl Fn(usize) -> [f64; 3]) -> Option<Vec<u8>> {
        let (w, h) = (VIEW.0 * SUPERSAMPLE, VIEW.1 * SUPERSAMPLE);
        let front = Camera::framing(self.mesh.points(), w, h)?;
        let back = Camera {
            right: -front.right,
            toward: -front.toward,
            ..front
        };
        // One canvas two views wide: each camera's centre moved by half a view sideways.
        let mut canvas = Canvas::new(2 * w, h);
        for (camera, side) in [(front, -1.0), (back, 1.0)] {
            let shift = camera.right * (camera.scale * w as f64 / 2.0);
            let camera = Camera {
                centre: camera.centre - side * shift,
                ..camera
            };
            canvas.draw(self.mesh, &camera, &colour);
        }
        let (width, height, rgb) = canvas.shrunk(SUPERSAMPLE);
        Some(png::encode(width, height, &rgb))
    }
}

/// The diverging colour of `t` on a scale of ±`limit`.
fn diverging(t: f64, limit: f64) -> [f64; 3] {
    if t.is_nan() {
        return NOT_SIGNIFICANT;
    }
    let s = (t / limit).clamp(-1.0, 1.0);
    let end = if s < 0.0 { NEGATIVE } else { POSITIVE };
    end.map(|c| 1.0 + s.abs() * (c - 1.0))
}

/// A CSS swatch of `rgb`.
fn css(rgb: [f64; 3]) -> String {
    let [r, g, b] = rgb.map(|c| (255.0 * c).round() as u8);
    format!("rgb({r},{g},{b})")
}

/// The maps of one contrast: the statistic on a diverging scale, and where each corrected p
/// (FWER, cluster, TFCE) is at most [`ALPHA`].
fn maps(mesh: &MapMesh, r: &ContrastResult) -> Markup {
    let statistic = if r.rows == 1 { "t" } else { "F" };
    let values = mesh.per_triangle(&r.statistic);
    let limit = values
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let limit = if limit > 0.0 { limit } else { 1.0 };
    let strip = |png: Option<Vec<u8>>, what: &str| {
        png.map(|png| {
            let captions = [format!("{what}, front"), format!("{what}, back")];
            figures::image_strip(&png, VIEW.0, VIEW.1, &captions, None)
        })
    };
    let t_view = strip(mesh.views(|k| diverging(values[k], limit)), statistic);
    let p_maps: Vec<(&str, Vec<f64>)> = [
        ("p_fwer", r.p_fwer.clone()),
        ("p_cluster", r.clusters.as_ref().map(|c| c.element_p())),
        ("p_tfce", r.p_tfce.clone()),
    ]
    .into_iter()
    .filter_map(|(name, p)| Some((name, p?)))
    .collect();
    let p_views: Vec<(String, Option<String>)> = p_maps
        .iter()
        .map(|(name, p)| {
            let found = p.iter().filter(|&&v| v <= ALPHA).count();
            let shown = mesh.significant(p);
            let view = strip(
                mesh.views(|k| {
                    if shown[k] {
                        SIGNIFICANT
                    } else {
                        NOT_SIGNIFICANT
                    }
                }),
                &format!("{name} ≤ {ALPHA}"),
            );
            let elements = if mesh.cells {
                "triangles"
            } else {
                "points (a triangle shown significant where two of its corners are)"
            };
            (format!("{name} ≤ {ALPHA}: {found} {elements}"), view)
        })
        .collect();
    let gradient = format!(
        "display:inline-block;width:240px;height:12px;vertical-align:middle;\
         background:linear-gradient(to right,{},#fff,{})",
        css(NEGATIVE),
        css(POSITIVE)
    );
    html! {
        h3 { "Maps" }
        @if let Some(svg) = &t_view {
            p.note {
                (statistic) " (a triangle's value: " @if mesh.cells { "its own" } @else { "the mean of its corners'" } "): "
                (number(-limit)) " " span style=(gradient) {} " " (number(limit))
            }
            (PreEscaped(svg))
        }
        @for (caption, view) in &p_views {
            @if let Some(svg) = view {
                p.note {
                    (caption) ": " span style={"color:" (css(SIGNIFICANT))} { "■ significant" } ", "
                    span style={"color:" (css(NOT_SIGNIFICANT))} { "■ not" }
                }
                (PreEscaped(svg))
            }
        }
    }
}

/// The outline of a histogram of `null` over `BINS` bins spanning it and `observed`, as a line
/// from the axis up each bin and back.
fn histogram_line(null: &[f64], observed: f64) -> Line {
    let finite = null
        .iter()
        .copied()
        .chain([observed])
        .filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let width = if hi > lo {
        (hi - lo) / BINS as f64
    } else {
        1.0
    };
    let mut counts = [0usize; BINS];
    for v in null.iter().filter(|v| v.is_finite()) {
        counts[(((v - lo) / width) as usize).min(BINS - 1)] += 1;
    }
    let mut points = vec![(lo, 0.0)];
    for (i, &c) in counts.iter().enumerate() {
        let x0 = lo + i as f64 * width;
        points.extend([(x0, c as f64), (x0 + width, c as f64)]);
    }
    points.push((lo + BINS as f64 * width, 0.0));
    Line {
        points,
        dots: false,
    }
}

/// The null distributions of one contrast's permutations (the maximum statistic, the largest
/// cluster area, the largest TFCE), each with the observed maximum (solid) and the critical
/// value at [`ALPHA`] (dashed).
fn null_distributions(r: &ContrastResult) -> Result<Markup, CliError> {
    let Some(permutations) = r.permutations else {
        return Ok(html! {});
    };
    let largest = |values: &mut dyn Iterator<Item = f64>| {
        values
            .filter(|v| !v.is_nan())
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let magnitude = |v: f64| if r.tail == Tail::Both { v.abs() } else { v };
    let statistic = if r.rows == 1 { "t" } else { "F" };
    let observed_area = r
        .clusters
        .as_ref()
        .map(|c| largest(&mut c.found.clusters.iter().map(|c| c.area)).max(0.0));
    let observed_tfce = r
        .tfce
        .as_ref()
        .map(|t| largest(&mut t.iter().map(|v| v.abs())));
    let sets = [
        (
            format!("largest {statistic} per permutation"),
            statistic.to_owned(),
            &r.null.statistic,
            Some(largest(&mut r.statistic.iter().map(|&v| magnitude(v)))),
        ),
        (
            "largest cluster area per permutation".into(),
            "area (mm²)".into(),
            &r.null.area,
            observed_area,
        ),
        (
            "largest TFCE per permutation".into(),
            "TFCE".into(),
            &r.null.tfce,
            observed_tfce,
        ),
    ];
    let panels: Vec<Panel> = sets
        .into_iter()
        .filter_map(|(title, x_label, null, observed)| {
            let observed = observed.filter(|_| !null.is_empty())?;
            let mut marks = vec![Mark {
                x: observed,
                label: format!("observed {}", number(observed)),
                kind: MarkKind::Switch,
            }];
            if let Some(c) = critical_value(null, ALPHA) {
                marks.push(Mark {
                    x: c,
                    label: format!("5 % critical {}", number(c)),
                    kind: MarkKind::Al,
                });
            }
            Some(Panel {
                title,
                x_label,
                lines: vec![histogram_line(null, observed)],
                marks,
            })
        })
        .collect();
    let svg = figures::grid("null distributions", &panels, 2)?;
    Ok(html! {
        h3 { "Null distributions" }
        p.note {
            (permutations.count) " permutations, the identity among them"
            @if permutations.exact { " (every distinct one: exact p)" } @else { " (seed " (permutations.seed) ")" }
            ": the maximum over the mesh of each; solid orange, the observed maximum; dashed grey, \
             the critical value (a p ≤ 0.05 is a value at or above it)."
        }
        @if let Some(svg) = svg { (PreEscaped(svg)) }
    })
}

/// The table of `clusters.csv` (the file's own columns).
fn clusters(csv: &str, path: &Path) -> Result<Markup, CliError> {
    let table = Table::parse(csv.as_bytes(), path)?;
    Ok(html! {
        h3 { "Clusters" }
        @if table.rows.is_empty() {
            p.note { "No cluster above the threshold." }
        } @else {
            table {
                tr { @for c in &table.columns { th { (c) } } }
                @for row in &table.rows { tr { @for v in row { td { (v) } } } }
            }
        }
    })
}

/// The design: its columns, the subjects of each group, the contrasts' weights.
fn design_section(design: &Design, contrasts: &[&Contrast]) -> Markup {
    let groups = design.group_sizes();
    html! {
        h2 { "Design" }
        p { (design.subjects()) " subjects; " (design.names().len()) " columns." }
        @if !groups.is_empty() {
            table {
                tr { th.key { "group" } th { "subjects" } }
                @for (column, level, n) in &groups {
                    tr {
                        td.key { (column) @if !level.is_empty() { " = " (level) } }
                        td { (n) }
                    }
                }
            }
        }
        table {
            tr { th.key { "contrast" } @for name in design.names() { th { (name) } } }
            @for contrast in contrasts {
                @for row in contrast.matrix().row_iter() {
                    tr {
                        td.key { (contrast.name()) }
                        @for w in row.iter() { td { (number(*w)) } }
                    }
                }
            }
        }
    }
}

/// One contrast's results as the page shows them.
pub struct Tested<'a> {
    /// The contrast.
    pub contrast: &'a Contrast,
    /// Its results.
    pub result: &'a ContrastResult,
    /// Its `clusters.csv` (text and path), with a cluster threshold.
    pub clusters: Option<(String, std::path::PathBuf)>,
}

/// The HTML of `medial stats`'s report: `title` (the input), the design after the row mask,
/// and for each contrast its maps on `mesh`, null distributions and clusters.
///
/// Errors: [`CliError::Figure`] when a figure cannot be drawn, [`CliError::File`] for a
/// malformed clusters table.
pub fn stats_page(
    title: &str,
    design: &Design,
    mesh: &MapMesh,
    tested: &[Tested],
) -> Result<String, CliError> {
    let contrasts: Vec<&Contrast> = tested.iter().map(|t| t.contrast).collect();
    let mut sections = Vec::with_capacity(tested.len());
    for t in tested {
        let clusters = match &t.clusters {
            Some((csv, path)) => clusters(csv, path)?,
            None => html! {},
        };
        sections.push(html! {
            h2 { "Contrast " (t.contrast.name()) }
            (maps(mesh, t.result))
            (null_distributions(t.result)?)
            (clusters)
        });
    }
    let body = html! {
        (design_section(design, &contrasts))
        @for section in &sections { (section) }
    };
    Ok(page(&format!("medial stats: {title}"), body))
}

/// A page of `title` with `body`, in the fit report's style.
fn page(title: &str, body: Markup) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { (title) }
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { (title) }
                (body)
            }
        }
    }
    .into_string()
}

/// The HTML of `medial pca`'s report: `title` (the input), the explained variance of each
/// mode found (`explained`, decreasing) and its cumulative sum (the scree plot), and each
/// subject's scores on the first modes against each other (`scores`: subjects × modes written;
/// `subjects` their names, in the table below).
///
/// Errors: [`CliError::Figure`] when a figure cannot be drawn.
pub fn pca_page(
    title: &str,
    explained: &[f64],
    scores: &nalgebra::DMatrix<f64>,
    subjects: &[String],
) -> Result<String, CliError> {
    let modes = |values: &mut dyn Iterator<Item = f64>| Line {
        points: values
            .enumerate()
            .map(|(k, v)| ((k + 1) as f64, 100.0 * v))
            .collect(),
        dots: true,
    };
    let mut cumulative = 0.0;
    let scree = [
        Panel {
            title: "explained variance (%)".into(),
            x_label: "mode".into(),
            lines: vec![modes(&mut explained.iter().copied())],
            marks: Vec::new(),
        },
        Panel {
            title: "cumulative explained variance (%)".into(),
            x_label: "mode".into(),
            lines: vec![modes(&mut explained.iter().map(|v| {
                cumulative += v;
                cumulative
            }))],
            marks: Vec::new(),
        },
    ];
    let scree = figures::grid("scree", &scree, 2)?;
    // Each subject a dot: one line of one point each.
    let pairs: Vec<Panel> = (1..scores.ncols().min(3))
        .map(|m| Panel {
            title: format!("pc{} against pc1 (mm)", m + 1),
            x_label: "pc1 (mm)".into(),
            lines: (0..scores.nrows())
                .map(|i| Line {
                    points: vec![(scores[(i, 0)], scores[(i, m)])],
                    dots: true,
                })
                .collect(),
            marks: Vec::new(),
        })
        .collect();
    let pairs = figures::grid("scores", &pairs, 2)?;
    let body = html! {
        h2 { "Explained variance" }
        @if let Some(svg) = scree { (PreEscaped(svg)) }
        h2 { "Scores" }
        @if let Some(svg) = pairs { (PreEscaped(svg)) }
        table {
            tr { th.key { "subject" } @for m in 0..scores.ncols() { th { "pc" (m + 1) } } }
            @for (i, name) in subjects.iter().enumerate() {
                tr {
                    td.key { (name) }
                    @for m in 0..scores.ncols() { td { (number(scores[(i, m)])) } }
                }
            }
        }
    };
    Ok(page(&format!("medial pca: {title}"), body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_triangle_of_a_point_map_is_significant_where_most_of_its_corners_are() {
        let points = vec![
            medial_core::Vec3::new(0.0, 0.0, 0.0),
            medial_core::Vec3::new(1.0, 0.0, 0.0),
            medial_core::Vec3::new(0.0, 1.0, 0.0),
            medial_core::Vec3::new(1.0, 1.0, 0.0),
        ];
        let mesh = TriMesh::new(points, vec![[0, 1, 2], [1, 3, 2]]).unwrap();
        // Corners 0 and 1 at 0.01, 2 at 0.2 (mean 0.073), 3 at 0.5.
        let p = [0.01, 0.01, 0.2, 0.5];
        let per_point = MapMesh {
            mesh: &mesh,
            cells: false,
        };
        assert_eq!(per_point.significant(&p), vec![true, false]);
        let per_cell = MapMesh {
            mesh: &mesh,
            cells: true,
        };
        assert_eq!(per_cell.significant(&[0.04, 0.06]), vec![true, false]);
    }

    #[test]
    fn a_histogram_line_counts_every_value_and_spans_the_observed() {
        let null = [1.0, 1.5, 2.0, 2.0, 3.0];
        let line = histogram_line(&null, 10.0);
        let total: f64 = line.points[1..line.points.len() - 1]
            .iter()
            .step_by(2)
            .map(|p| p.1)
            .sum();
        assert_eq!(total, 5.0);
        assert_eq!(line.points.first().unwrap().0, 1.0);
        assert!((line.points.last().unwrap().0 - 10.0).abs() < 1e-12);
    }

    #[test]
    fn diverging_colours_are_white_at_zero_and_the_ends_at_the_limit() {
        // `1 + s (c − 1)` is `c` at |s| = 1 up to a rounding of the subtraction.
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-12);
        assert_eq!(diverging(0.0, 2.0), [1.0; 3]);
        assert!(close(diverging(5.0, 2.0), POSITIVE));
        assert!(close(diverging(-2.0, 2.0), NEGATIVE));
        assert!(!close(diverging(1.0, 2.0), POSITIVE));
    }
}
