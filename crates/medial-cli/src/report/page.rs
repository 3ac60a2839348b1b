//! `report.html`: one self-contained page (inline CSS, SVG and PNG, no script, nothing loaded) with
//! the figures and tables of a fit folder.

use super::figures::{self, Counted, Line, Mark, MarkKind, Panel};
use super::folder::{FitFolder, FlowKind};
use super::label::{label, number};
use super::overlay;
use super::table::Table;
use crate::error::CliError;
use maud::{html, Markup, PreEscaped, DOCTYPE};
use serde_json::Value;

/// The columns of `log.csv` drawn for each stage, in the order of the paper's Figs. 2–3.
const STAGE_COLUMNS: [&str; 6] = [
    "data",
    "kinetic",
    "penalty",
    "max_spoke_normal_deg",
    "max_spoke_mismatch_pct",
    "dice",
];

/// Bins of the thickness histogram.
const BINS: usize = 30;

/// The page's style sheet.
pub(crate) const STYLE: &str =
    "body{font-family:sans-serif;margin:2em auto;max-width:1000px;color:#222}\
h1{font-size:1.6em}h2{margin-top:1.8em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ddd;padding:3px 8px;\
text-align:right;font-size:0.9em}th{background:#f4f4f4}td.key,th.key{text-align:left}\
svg{max-width:100%;height:auto;display:block;margin:0.5em 0}\
pre{background:#f7f7f7;padding:1em;overflow-x:auto;font-size:0.85em}\
.status{padding:2px 8px;border-radius:4px;background:#eee}\
.converged,.budget{background:#d4edda}.constraints_not_met,.misses_target{background:#fff3cd}\
.unsound{background:#f8d7da}p.note{color:#555;font-size:0.9em}";

/// The HTML of the report of `folder`.
///
/// Errors: [`CliError::Figure`] when a figure cannot be drawn.
pub fn render(folder: &FitFolder) -> Result<String, CliError> {
    let name = &folder.name;
    let status = folder.summary["status"].as_str().unwrap_or("unknown");
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { "medial fit: " (name) }
                style { (PreEscaped(STYLE)) }
            }
            body {
                h1 { "medial fit: " (name) }
                p { "Status: " span class={"status " (status)} { (status) } }
                (overlay::section_markup(folder)?)
                (alignment(folder))
                (summary_tables(&folder.summary))
                (stages(folder)?)
                (over_time(folder)?)
                (thickness(folder)?)
                (files(folder))
                @if let Some(config) = &folder.config {
                    h2 { "Resolved config" }
                    pre { (config) }
                }
            }
        }
    };
    Ok(page.into_string())
}

/// A JSON value as a table cell.
fn cell(value: &Value) -> String {
    match value {
        Value::Number(n) => n.as_f64().map(number).unwrap_or_else(|| n.to_string()),
        Value::Bool(b) => if *b { "yes" } else { "no" }.into(),
        Value::String(s) => s.clone(),
        Value::Null => "–".into(),
        Value::Array(items) => runs(items.iter().map(cell)),
        Value::Object(map) => map
            .iter()
            .map(|(k, v)| format!("{}: {}", label(k), cell(v)))
            .collect::<Vec<_>>()
            .join("; "),
    }
}

/// Items joined by `; `, a run of equal items written once with its count (`x (×6)`).
fn runs(items: impl Iterator<Item = String>) -> String {
    let mut grouped: Vec<(String, usize)> = Vec::new();
    for item in items {
        match grouped.last_mut() {
            Some((last, count)) if *last == item => *count += 1,
            _ => grouped.push((item, 1)),
        }
    }
    grouped
        .into_iter()
        .map(|(item, count)| match count {
            1 => item,
            _ => format!("{item} (×{count})"),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// A two-column table of the entries of `map` (all but `skip`).
fn key_values(map: &serde_json::Map<String, Value>, skip: &[&str]) -> Markup {
    html! {
        table {
            @for (key, value) in map.iter().filter(|(k, _)| !skip.contains(&k.as_str())) {
                tr { td.key { (label(key)) } td { (cell(value)) } }
            }
        }
    }
}

/// The heading of an object of `summary.json`.
fn object_title(key: &str) -> String {
    match key {
        "final" => "Final figures".into(),
        "over_time" => "Worst over time points 1 … N".into(),
        _ => label(key),
    }
}

/// The fit's scalar entries (but the list of files), then one table per object of `summary.json` (`final`,
/// `over_time`, and whatever else it holds), then the stages side by side.
fn summary_tables(summary: &Value) -> Markup {
    let Some(map) = summary.as_object() else {
        return html! {};
    };
    // `files` and `sha256` describe the set, not the fit (and a report made in the staging
    // folder is made before they are final).
    let of_the_set = ["files", "sha256"];
    let objects: Vec<&String> = map
        .iter()
        .filter(|(k, v)| v.is_object() && !of_the_set.contains(&k.as_str()))
        .map(|(k, _)| k)
        .collect();
    let stages = summary["stages"].as_array().cloned().unwrap_or_default();
    let mut keys: Vec<&String> = Vec::new();
    for key in stages
        .iter()
        .filter_map(Value::as_object)
        .flat_map(|s| s.keys())
    {
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let skip: Vec<&str> = objects
        .iter()
        .map(|k| k.as_str())
        .chain(["stages", "status", "alignment"])
        .chain(of_the_set)
        .collect();
    html! {
        h2 { "Fit" }
        (key_values(map, &skip))
        @for key in &objects {
            h2 { (object_title(key)) }
            @if let Some(object) = map[key.as_str()].as_object() { (key_values(object, &[])) }
        }
        @if !stages.is_empty() {
            h2 { "Stages" }
            table {
                tr { th.key {} @for s in &stages { th { (cell(&s["name"])) } } }
                @for key in keys.iter().filter(|k| k.as_str() != "name") {
                    tr {
                        td.key { (label(key)) }
                        @for s in &stages { td { (cell(s.get(key.as_str()).unwrap_or(&Value::Null))) } }
                    }
                }
            }
        }
    }
}

/// The initial alignment of an automatic fit: what each step did (`summary.json`'s
/// `alignment`: one line per step, `step: figures`, or an object of named figures) and the map
/// (`alignment.txt`); nothing for a fit without one.
fn alignment(folder: &FitFolder) -> Markup {
    let steps = &folder.summary["alignment"];
    let matrix = std::fs::read_to_string(folder.dir.join("alignment.txt"))
        .ok()
        .map(|text| {
            text.lines()
                .map(|l| l.split_whitespace().map(str::to_owned).collect::<Vec<_>>())
                .filter(|row| !row.is_empty())
                .collect::<Vec<_>>()
        })
        .filter(|rows| !rows.is_empty());
    if steps.is_null() && matrix.is_none() {
        return html! {};
    }
    html! {
        h2 { "Initial alignment" }
        p.note {
            "An automatic fit first moves the template onto the target (a similarity, an affine              map where the target calls for one, then a projection back onto the medial              constraints); the flow starts from the result (aligned_template.vtk, t = 0 above)."
        }
        @match steps {
            Value::Array(lines) => {
                table {
                    tr { th.key { "step" } th.key { "what it did" } }
                    @for line in lines {
                        @let text = cell(line);
                        @let (step, figures) = text.split_once(": ").unwrap_or(("", &text));
                        tr { td.key { (step) } td.key { (figures) } }
                    }
                }
            }
            Value::Object(map) => { (key_values(map, &[])) }
            Value::Null => {}
            other => { p { (cell(other)) } }
        }
        @if let Some(rows) = &matrix {
            p.note { "alignment.txt, the initial map (template → subject, RAS mm, homogeneous):" }
            table {
                @for row in rows {
                    tr { @for v in row { td { (v.parse::<f64>().map(number).unwrap_or_else(|_| v.clone())) } } }
                }
            }
        }
    }
}

/// The rows of `log` in runs of one stage, in order: `(name, first row, end row)`.
fn stage_runs(log: &Table) -> Vec<(String, usize, usize)> {
    let names = log.text("stage").unwrap_or_default();
    let mut runs: Vec<(String, usize, usize)> = Vec::new();
    for (i, name) in names.iter().enumerate() {
        match runs.last_mut() {
            Some(run) if run.0 == *name => run.2 = i + 1,
            _ => runs.push(((*name).to_owned(), i, i + 1)),
        }
    }
    runs
}

/// Where a minimisation starts within the rows `start..end` of `log`, as marks at its row
/// (relative to `start`): a row whose iteration does not follow the one before (0: a fresh
/// start). A new AL iteration is labelled with its number and μ (in constrained stages), a
/// change of the flow's time steps (coarse to fine) with the steps, and a fresh start within
/// the same AL iteration and time steps a restart.
fn minimisation_marks(log: &Table, start: usize, end: usize) -> Vec<Mark> {
    let column = |name| log.numbers(name).unwrap_or_default();
    let (al, mu, iteration, steps) = (
        column("al_iteration"),
        column("mu"),
        column("iteration"),
        column("time_steps"),
    );
    let at = |v: &[f64], i: usize| v.get(i).copied().filter(|x| x.is_finite());
    let mut marks = Vec::new();
    for i in start..end {
        let first = i == start;
        let fresh = first
            || at(&iteration, i)
                .zip(at(&iteration, i - 1))
                .is_some_and(|(a, b)| a <= b);
        let new_al = first || at(&al, i) != at(&al, i - 1);
        let switch = !first && at(&steps, i) != at(&steps, i - 1);
        if !(fresh || new_al || switch) {
            continue;
        }
        let mut parts = Vec::new();
        let constrained = at(&mu, i).is_some_and(|m| m > 0.0);
        if new_al && constrained {
            let n = at(&al, i).map_or(String::new(), |a| format!("AL {}, ", a + 1.0));
            parts.push(format!("{n}μ = {}", number(mu[i])));
        }
        if switch {
            let show = |v: Option<f64>| v.map_or("?".into(), number);
            parts.push(format!(
                "{} → {} time steps",
                show(at(&steps, i - 1)),
                show(at(&steps, i))
            ));
        }
        let kind = if switch {
            MarkKind::Switch
        } else if new_al {
            MarkKind::Al
        } else {
            parts.push("restart".into());
            MarkKind::Restart
        };
        if !parts.is_empty() {
            marks.push(Mark {
                x: (i - start) as f64,
                label: parts.join(", "),
                kind,
            });
        }
    }
    marks
}

/// The rows `start..end` cut where a minimisation starts afresh (its iteration does not follow
/// the row before), as `(first, end)` row ranges.
fn minimisations(log: &Table, start: usize, end: usize) -> Vec<(usize, usize)> {
    let iteration = log.numbers("iteration").unwrap_or_default();
    let mut pieces: Vec<(usize, usize)> = Vec::new();
    for i in start..end {
        let fresh = i == start
            || matches!((iteration.get(i), iteration.get(i - 1)), (Some(a), Some(b)) if a <= b);
        match pieces.last_mut() {
            Some(piece) if !fresh => piece.1 = i + 1,
            _ => pieces.push((i, i + 1)),
        }
    }
    pieces
}

/// The L-BFGS and AL iterations of stage `name` as the summary's table counts them (its
/// `iterations` and `al_iterations`), else from the log: the rows after each minimisation's
/// start, and the distinct AL iterations.
fn iteration_counts(folder: &FitFolder, name: &str, start: usize, end: usize) -> (usize, usize) {
    let stage = folder.summary["stages"]
        .as_array()
        .and_then(|stages| stages.iter().find(|s| s["name"].as_str() == Some(name)));
    let count = |key: &str| stage.and_then(|s| s[key].as_u64()).map(|n| n as usize);
    let from_log = || {
        let pieces = minimisations(&folder.log, start, end);
        let rows = end - start - pieces.len();
        let mut al = folder.log.numbers("al_iteration").unwrap_or_default()[start..end].to_vec();
        al.dedup();
        (rows, al.len().max(1))
    };
    match (count("iterations"), count("al_iterations")) {
        (Some(i), Some(a)) => (i, a),
        _ => from_log(),
    }
}

/// Per stage, the paper's Figs. 2–3: each column of [`STAGE_COLUMNS`] against the row of the
/// log, the start of each AL iteration marked with its μ, the switch from coarse to fine time
/// steps and every restart marked and labelled, the line broken where a minimisation starts.
fn stages(folder: &FitFolder) -> Result<Markup, CliError> {
    let log = &folder.log;
    let mut figures = Vec::new();
    for (name, start, end) in stage_runs(log) {
        let marks = minimisation_marks(log, start, end);
        let pieces = minimisations(log, start, end);
        let panels: Vec<Panel> = STAGE_COLUMNS
            .iter()
            .filter_map(|column| {
                let values = log.numbers(column)?;
                Some(Panel {
                    title: label(column),
                    x_label:
                        "row of log.csv in the stage (L-BFGS iterations of all its minimisations)"
                            .into(),
                    lines: pieces
                        .iter()
                        .map(|&(a, b)| Line {
                            points: (a..b).map(|i| ((i - start) as f64, values[i])).collect(),
                            dots: false,
                        })
                        .collect(),
                    marks: marks.clone(),
                })
            })
            .collect();
        let svg = figures::grid(&format!("stage '{name}'"), &panels, 2)?;
        let (iterations, al) = iteration_counts(folder, &name, start, end);
        figures.push((name, iterations, al, svg));
    }
    Ok(html! {
        h2 { "Convergence per stage" }
        p.note {
            "As the paper's Figs. 2–3: the data term, the kinetic energy, the penalty and the \
             medial figures at each L-BFGS iteration (from log.csv, one row per iteration and \
             one for the start of each minimisation). Dashed grey lines mark the start of each \
             augmented-Lagrangian iteration with its μ; solid orange lines the switch from the \
             coarse flow to the stage's time steps (the penalty and the medial figures jump there: \
             the constraints now hold at the new time points too, which were not constrained \
             before); dotted red lines a fresh start of \
             L-BFGS within an AL iteration. The line is broken at each start. Axes spanning two \
             decades or more are logarithmic."
        }
        @for (name, iterations, al, svg) in &figures {
            h3 { "Stage '" (name) "' (" (iterations) " L-BFGS iterations in " (al) " AL iteration" @if *al != 1 { "s" } ")" }
            @if let Some(svg) = svg { (PreEscaped(svg)) }
        }
    })
}

/// Every column of `time_points.csv` but the time point and t, against t, and the table.
fn over_time(folder: &FitFolder) -> Result<Markup, CliError> {
    let Some(table) = &folder.time_points else {
        return Ok(html! {});
    };
    let t = table
        .numbers("t")
        .or_else(|| table.numbers("time_point"))
        .unwrap_or_default();
    let panels: Vec<Panel> = table
        .columns
        .iter()
        .filter(|c| !matches!(c.as_str(), "t" | "time_point"))
        .filter_map(|c| {
            let values = table.numbers(c)?;
            Some(Panel {
                title: label(c),
                x_label: "t".into(),
                lines: vec![Line {
                    points: t.iter().copied().zip(values).collect(),
                    dots: true,
                }],
                marks: Vec::new(),
            })
        })
        .collect();
    let svg = figures::grid("time points", &panels, 2)?;
    Ok(html! {
        h2 { "Medial figures over the flow" }
        p.note {
            "Each column of time_points.csv against the time t of the flow (t = 0: the template, \
             t = 1: the fitted model)."
        }
        @if let Some(svg) = svg { (PreEscaped(svg)) }
        details {
            summary { "time_points.csv" }
            table {
                tr { @for c in &table.columns { th { (c) } } }
                @for row in &table.rows {
                    tr { @for v in row { td { (v.parse::<f64>().map(number).unwrap_or_else(|_| v.clone())) } } }
                }
            }
        }
    })
}

/// The spoke lengths (`Radius` of the boundary files) of the template and the fitted model.
fn thickness(folder: &FitFolder) -> Result<Markup, CliError> {
    let files = folder.files(FlowKind::Boundary);
    let (Some(first), Some(last)) = (files.first(), files.last()) else {
        return Ok(html! {});
    };
    let radius = |f| -> Result<Option<Vec<f64>>, CliError> {
        Ok(folder
            .read_flow(f)?
            .point_array("Radius")
            .map(|a| a.values.clone()))
    };
    let (Some(template), Some(fitted)) = (radius(first)?, radius(last)?) else {
        return Ok(html! {});
    };
    let sets = [
        Counted {
            label: format!("template (t = {})", number(first.time)),
            values: &template,
            colour: figures::FIRST,
        },
        Counted {
            label: format!("fitted (t = {})", number(last.time)),
            values: &fitted,
            colour: figures::LINE,
        },
    ];
    let title = "spoke lengths of the model (half the local thickness)";
    let svg = figures::histogram(title, "spoke length r (mm)", &sets, BINS)?;
    Ok(html! {
        h2 { "Thickness" }
        p.note { "One spoke per boundary point (flow/boundary_tNNN.vtk, Radius); the local thickness is about 2r." }
        @if let Some(svg) = svg { (PreEscaped(svg)) }
    })
}

/// What else the folder holds for viewing.
fn files(folder: &FitFolder) -> Markup {
    let series: Vec<(&str, usize)> = [FlowKind::Boundary, FlowKind::Medial]
        .into_iter()
        .map(|k| (k.name(), folder.files(k).len()))
        .filter(|&(_, n)| n > 0)
        .collect();
    html! {
        h2 { "Viewing the flow" }
        ul {
            @for (name, n) in &series {
                li {
                    a href={"flow/" (name) ".vtk.series"} { "flow/" (name) ".vtk.series" }
                    ": open in ParaView as one time series (" (n) " time points at their times t)"
                }
            }
            @if !series.is_empty() {
                li {
                    a href="flow.glb" { "flow.glb" }
                    ": the boundary (translucent) and the medial sheet animated over t, coloured \
                     by thickness, for any glTF viewer"
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_of_json_values() {
        let stops = serde_json::json!(["budget", "budget", "gradient", "budget"]);
        assert_eq!(cell(&stops), "budget (×2); gradient; budget");
        assert_eq!(cell(&serde_json::json!(0.25)), "0.25");
        assert_eq!(cell(&serde_json::json!(true)), "yes");
        assert_eq!(cell(&Value::Null), "–");
    }

    #[test]
    fn stage_runs_follow_the_log() {
        let log = Table {
            columns: vec!["stage".into()],
            rows: [["a"], ["a"], ["b"], ["b"], ["b"]]
                .iter()
                .map(|r| r.iter().map(|s| s.to_string()).collect())
                .collect(),
        };
        assert_eq!(
            stage_runs(&log),
            [("a".to_owned(), 0, 2), ("b".to_owned(), 2, 5)]
        );
    }
}
