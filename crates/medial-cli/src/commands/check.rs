//! `medial check`: the inscribed-ball fidelity ([`medial_core::model::fidelity`]) of a template,
//! or of a fit at every time point of its flow; prints the figures as JSON and fails when the
//! sheet atoms' mean residual passes a threshold.

use crate::error::CliError;
use crate::output::print_json;
use crate::time_points::BallFigures;
use medial_core::model::fidelity::POKE_TOLERANCE;
use medial_core::model::{BallFidelity, MedialTemplate};
use medial_core::Vec3;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Check that the medial points stay the centres of inscribed balls.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// A cmrep template (legacy VTK with a MedialIndex array, mm), or the output folder of
    /// `medial fit` (its fitted_template.vtk gives the structure, flow/boundary_tNNN.vtk and
    /// flow/medial_tNNN.vtk the positions at every time point written).
    #[arg(value_name = "TEMPLATE.vtk|DIR")]
    pub path: PathBuf,
    /// Largest mean inscribed-ball residual |d − r| / r of the sheet atoms that counts as
    /// medial, in percent; past it (at any time point after the first, for a fit) the command
    /// prints its figures and exits with code 5.
    #[arg(long, value_name = "PERCENT", default_value_t = DEFAULT_MAX_RESIDUAL_PCT, value_parser = positive_percent)]
    pub max_residual: f64,
}

/// Default `--max-residual`, %: above the shipped templates' 0.1–1.8 % and their constrained
/// fits' (measured in the README), far below fits without constraints (tens of per cent).
pub const DEFAULT_MAX_RESIDUAL_PCT: f64 = 5.0;

/// What `medial check` prints.
#[derive(Serialize)]
struct CheckReport {
    /// The template or fit folder checked.
    source: PathBuf,
    /// A residual above this counts as a ball poking out, %.
    poke_tolerance_pct: f64,
    /// `--max-residual`, %.
    max_residual_pct: f64,
    /// Every configuration checked: the template alone, or each time point of the fit.
    time_points: Vec<TimePointFigures>,
    /// The figures judged: the template's, or for a fit the worst over time points 1 … N
    /// (all time points written if only the first is).
    judged: BallFigures,
    /// Whether the mean residual of the sheet atoms is within `max_residual_pct`.
    medial: bool,
    /// A fit folder: the `status` its summary.json gives (`converged`, `budget`,
    /// `constraints_not_met`, `misses_target`, `unsound`, `interrupted`); a fit that `medial
    /// fit` did not end as sound and within its tolerances fails the check whatever its balls.
    #[serde(skip_serializing_if = "Option::is_none")]
    fit_status: Option<String>,
}

/// The fidelity of one configuration.
#[derive(Serialize)]
struct TimePointFigures {
    /// `NNN` of flow/…_tNNN.vtk (0 for a template).
    time_point: usize,
    #[serde(flatten)]
    figures: BallFigures,
}

/// Measures, prints the figures, and fails (exit code 5) when the sheet atoms' mean residual
/// passes `--max-residual`.
pub fn run(args: &CheckArgs) -> Result<(), CliError> {
    let (template, configurations) = if args.path.is_dir() {
        fit_folder(&args.path)?
    } else {
        let template = medial_io::cmrep::read_template(&args.path)?;
        let q = template.landmarks().to_vec();
        (template, vec![(0, q)])
    };
    let meter = BallFidelity::new(&template);
    let time_points: Vec<TimePointFigures> = configurations
        .iter()
        .map(|(n, q)| TimePointFigures {
            time_point: *n,
            figures: BallFigures::of(&meter.measure(q).summary),
        })
        .collect();
    let later = time_points.iter().filter(|p| p.time_point > 0);
    let judged = if later.clone().next().is_some() {
        worst(later)
    } else {
        worst(time_points.iter())
    };
    let medial = judged.sheet.mean_residual_pct <= args.max_residual;
    let fit_status = if args.path.is_dir() {
        Some(fit_status(&args.path)?)
    } else {
        None
    };
    let report = CheckReport {
        source: args.path.clone(),
        poke_tolerance_pct: 100.0 * POKE_TOLERANCE,
        max_residual_pct: args.max_residual,
        time_points,
        judged,
        medial,
        fit_status: fit_status.clone(),
    };
    print_json(&report)?;
    let said = |what: &str| {
        format!(
            "{}: summary.json says the fit {what}: `medial fit` did not accept it, whatever its \
             inscribed balls",
            args.path.display()
        )
    };
    match fit_status.as_deref() {
        Some("unsound") => return Err(CliError::Unsound(said("ended unsound (status \"unsound\")"))),
        Some("constraints_not_met") => {
            return Err(CliError::ConstraintsNotMet(said(
                "ended with its constraints above their tolerance (status \"constraints_not_met\")",
            )))
        }
        Some("misses_target") => {
            return Err(CliError::MissesTarget(said(
                "missed a part of its target (status \"misses_target\")",
            )))
        }
        Some("interrupted") => {
            return Err(CliError::Input(said(
                "was stopped before its end (status \"interrupted\"; resume it with medial fit --resume)",
            )))
        }
        _ => {}
    }
    if medial {
        return Ok(());
    }
    Err(CliError::NotMedial(format!(
        "{}: the medial points are not the centres of inscribed balls: the sheet atoms' mean \
         residual |d − r| / r reaches {:.1} % (threshold {} %, --max-residual); {} of {} sheet \
         balls poke out of the boundary",
        args.path.display(),
        judged.sheet.mean_residual_pct,
        args.max_residual,
        judged.sheet.poking_out,
        judged.sheet.atoms
    )))
}

/// The `status` of the fit folder `dir`'s summary.json, its files checked against their
/// digests.
fn fit_status(dir: &Path) -> Result<String, CliError> {
    crate::results::verify(dir, "summary.json", |_| false)?;
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).map_err(|e| CliError::io(&path, e))?;
    let summary: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| CliError::Input(format!("{}: not JSON: {e}", path.display())))?;
    summary["status"]
        .as_str()
        .map(str::to_owned)
        .ok_or_else(|| CliError::Input(format!("{}: no \"status\"", path.display())))
}

/// The worst of each figure over `points` (not empty).
fn worst<'a>(points: impl Iterator<Item = &'a TimePointFigures>) -> BallFigures {
    points
        .map(|p| p.figures)
        .reduce(BallFigures::worse)
        .expect("at least one configuration")
}

/// Landmarks (boundary points, then medial points) at a numbered time point.
type Configuration = (usize, Vec<Vec3>);

/// The structure of a fit folder (its fitted_template.vtk) and its landmarks at every time
/// point written under flow/ (boundary points, then medial points), in time order; the fitted
/// template alone if flow/ holds none.
fn fit_folder(dir: &Path) -> Result<(MedialTemplate, Vec<Configuration>), CliError> {
    let template = medial_io::cmrep::read_template(&dir.join("fitted_template.vtk"))?;
    let flow = dir.join("flow");
    let mut configurations = Vec::new();
    for n in time_point_numbers(&flow)? {
        let boundary = points_of(&flow.join(format!("boundary_t{n:03}.vtk")))?;
        let medial = points_of(&flow.join(format!("medial_t{n:03}.vtk")))?;
        let q: Vec<Vec3> = boundary.into_iter().chain(medial).collect();
        if q.len() != template.landmark_count() {
            return Err(CliError::Input(format!(
                "{}: time point {n} has {} boundary and medial points, the fitted template {} \
                 landmarks: the folder holds files of different fits",
                flow.display(),
                q.len(),
                template.landmark_count()
            )));
        }
        configurations.push((n, q));
    }
    if configurations.is_empty() {
        configurations.push((0, template.landmarks().to_vec()));
    }
    Ok((template, configurations))
}

/// The `NNN` of every flow/boundary_tNNN.vtk that has its flow/medial_tNNN.vtk, ascending;
/// none without a flow/ folder.
fn time_point_numbers(flow: &Path) -> Result<Vec<usize>, CliError> {
    if !flow.is_dir() {
        return Ok(Vec::new());
    }
    let entries = std::fs::read_dir(flow).map_err(|e| CliError::io(flow, e))?;
    let mut numbers = Vec::new();
    for entry in entries {
        let name = entry.map_err(|e| CliError::io(flow, e))?.file_name();
        let number = name.to_str().and_then(|s| {
            s.strip_prefix("boundary_t")?
                .strip_suffix(".vtk")?
                .parse()
                .ok()
        });
        if let Some(n) = number.filter(|n| flow.join(format!("medial_t{n:03}.vtk")).is_file()) {
            numbers.push(n);
        }
    }
    numbers.sort_unstable();
    Ok(numbers)
}

/// The points of a VTK file.
fn points_of(path: &Path) -> Result<Vec<Vec3>, CliError> {
    Ok(medial_io::vtk::read_polydata(path)?.points)
}

/// Parses `--max-residual`: a positive, finite percentage.
fn positive_percent(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!(
            "the residual threshold must be a positive number of per cent, got '{text}'"
        )),
    }
}
