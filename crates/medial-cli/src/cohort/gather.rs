//! Gathering a cohort folder into tables: `cohort.csv` (one row per subject of the table, in
//! its order, whatever its state), `thickness.npy` (float64 `[subjects × atoms]`, the local
//! thickness `2 × mean spoke length` of every atom at t = 1, read from each
//! `SUBJECT/fitted_template.vtk`), `thickness_subjects.txt` (the subjects of its rows, one a
//! line) and `thickness_mean.vtk` (the template's medial sheet with the point arrays
//! `ThicknessMean`, `ThicknessSD` and `Subjects`).
//!
//! A subject is read only through a complete set of results: its `summary.json`, which a fit
//! moves in last ([`crate::results`]), so gathering while other jobs still fit is safe; the
//! thickness rows are the subjects whose fit ended sound and within its tolerances (status
//! `converged` or `budget`). Every output is written atomically and depends only on the
//! subjects' files, so gathering again gives the same bytes.

use super::FAILED_JSON;
use crate::error::CliError;
use crate::output::{write_options, write_text};
use crate::summary::{Figures, Status};
use crate::time_points::OverTime;
use medial_core::model::{MedialTemplate, Model, SpokeMetrics};
use medial_io::vtk::{self, DataArray, PolyData, ValueType};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The cohort table.
pub const COHORT_CSV: &str = "cohort.csv";
/// The thickness of every gathered subject and atom.
pub const THICKNESS_NPY: &str = "thickness.npy";
/// The subjects of the rows of [`THICKNESS_NPY`].
pub const THICKNESS_SUBJECTS: &str = "thickness_subjects.txt";
/// Mean and SD thickness on the template's medial sheet.
pub const THICKNESS_MEAN: &str = "thickness_mean.vtk";

/// What a subject's `summary.json` says that the cohort table needs.
#[derive(Deserialize)]
struct Record {
    status: Status,
    seconds: f64,
    evaluations: usize,
    #[serde(rename = "final")]
    figures: Figures,
    over_time: Option<OverTime>,
}

/// A subject's `failed.json`.
#[derive(Serialize, Deserialize)]
pub struct Failure {
    /// The subject.
    pub subject: String,
    /// The one-line message of the failure.
    pub error: String,
    /// The exit code `medial fit` would have ended with.
    pub exit_code: u8,
}

/// How a subject stands in its folder.
pub struct Standing {
    summary: Option<Record>,
    failure: Option<Failure>,
}

impl Standing {
    /// Reads `summary.json` and `failed.json` of the subject folder `dir` (either may be
    /// missing; one that cannot be read as such counts as missing).
    pub fn read(dir: &Path) -> Self {
        fn json<T: for<'a> Deserialize<'a>>(path: &Path) -> Option<T> {
            serde_json::from_slice(&std::fs::read(path).ok()?).ok()
        }
        Self {
            summary: json(&dir.join("summary.json")),
            failure: json(&dir.join(FAILED_JSON)),
        }
    }

    /// The status of a fit that ran to its end (not interrupted).
    fn ended(&self) -> Option<Status> {
        self.summary
            .as_ref()
            .map(|r| r.status)
            .filter(|s| *s != Status::Interrupted)
    }

    /// Whether the fit ran to its end (whatever its status): a batch does not run it again.
    pub fn finished(&self) -> bool {
        self.ended().is_some()
    }

    /// Whether a signal stopped the fit: a batch resumes it from its checkpoint.
    pub fn interrupted(&self) -> bool {
        self.summary
            .as_ref()
            .is_some_and(|r| r.status == Status::Interrupted)
            && self.failure.is_none()
    }

    /// Whether the fit failed: it ended unsound, with its constraints not met or missing its
    /// target, or it stopped with an error.
    pub fn failed(&self) -> bool {
        match self.ended() {
            Some(status) => matches!(
                status,
                Status::Unsound | Status::ConstraintsNotMet | Status::MissesTarget
            ),
            None => self.failure.is_some(),
        }
    }

    /// Whether its thickness is gathered: a sound fit within its tolerances.
    fn gathered(&self) -> bool {
        matches!(self.ended(), Some(Status::Converged | Status::Budget))
    }

    /// The status column: the fit's status, or `failed` (an error before its end), or
    /// `pending` (not fitted yet, or being fitted).
    fn status(&self) -> RowStatus {
        match (&self.summary, &self.failure) {
            (Some(r), _) if r.status != Status::Interrupted => RowStatus::Fit(r.status),
            (_, Some(_)) => RowStatus::Other("failed"),
            (Some(r), None) => RowStatus::Fit(r.status),
            (None, None) => RowStatus::Other("pending"),
        }
    }
}

/// A cell of the status column.
#[derive(Serialize)]
#[serde(untagged)]
enum RowStatus {
    Fit(Status),
    Other(&'static str),
}

/// One row of `cohort.csv`; cells of figures a subject does not have are empty.
#[derive(Serialize)]
struct Row<'a> {
    subject: &'a str,
    /// `converged`, `budget`, `constraints_not_met`, `misses_target`, `unsound`, `interrupted`,
    /// `failed` or `pending`.
    status: RowStatus,
    /// Of a failed fit: what `medial fit` would have exited with.
    exit_code: Option<u8>,
    /// Dice estimate at the end (Dice stages).
    dice: Option<f64>,
    /// Voxel overlap of the rasterized model with the image (Dice stages).
    voxel_dice: Option<f64>,
    /// The share of the target the model missed, % (Dice and varifold stages; above 2 % the
    /// fit misses its target).
    missed_pct: Option<f64>,
    /// Mean distance to the SSD targets, mm (SSD stages).
    mean_distance_mm: Option<f64>,
    /// Mean distance of the model's boundary to the target surface, mm (varifold stages).
    surface_distance_mm: Option<f64>,
    /// Largest spoke–normal angle at t = 1, degrees.
    max_spoke_normal_deg: Option<f64>,
    /// Largest spoke-length mismatch at t = 1, %.
    max_spoke_mismatch_pct: Option<f64>,
    /// The inscribed-ball residual of the sheet atoms, mean, %, at the worst time point.
    ball_residual_sheet_pct: Option<f64>,
    /// Sheet atoms whose ball pokes out, at the worst time point.
    balls_poking_out_sheet: Option<usize>,
    /// Kinetic energy of the flow (unweighted).
    kinetic_energy: Option<f64>,
    /// Value + gradient evaluations.
    evaluations: Option<usize>,
    /// Wall-clock seconds of the fit.
    seconds: Option<f64>,
    /// Of a failed fit: its one-line message.
    error: Option<&'a str>,
}

impl<'a> Row<'a> {
    fn of(subject: &'a str, s: &'a Standing) -> Self {
        let r = s.summary.as_ref();
        let f = r.map(|r| &r.figures);
        let ball = r.and_then(|r| r.over_time).map(|o| o.ball_fidelity.sheet);
        Self {
            subject,
            status: s.status(),
            exit_code: s.failure.as_ref().map(|f| f.exit_code),
            dice: f.and_then(|f| f.dice),
            voxel_dice: f.and_then(|f| f.voxel_dice),
            missed_pct: f.and_then(|f| f.missed_pct),
            mean_distance_mm: f.and_then(|f| f.mean_distance),
            surface_distance_mm: f.and_then(|f| f.surface_distance),
            max_spoke_normal_deg: f.and_then(|f| f.max_spoke_normal_deg),
            max_spoke_mismatch_pct: f.and_then(|f| f.max_spoke_mismatch_pct),
            ball_residual_sheet_pct: ball.map(|b| b.mean_residual_pct),
            balls_poking_out_sheet: ball.map(|b| b.poking_out),
            kinetic_energy: f.map(|f| f.kinetic),
            evaluations: r.map(|r| r.evaluations),
            seconds: r.map(|r| r.seconds),
            error: s.failure.as_ref().map(|f| f.error.as_str()),
        }
    }
}

/// What a gathering found, as `medial batch` prints it.
#[derive(Serialize)]
pub struct Gathered {
    /// Subjects in the table.
    pub subjects: usize,
    /// Subjects whose thickness was gathered (the rows of `thickness.npy`).
    pub gathered: usize,
    /// Subjects whose fit failed.
    pub failed: Vec<String>,
    /// Subjects not fitted yet (or being fitted, or interrupted).
    pub pending: Vec<String>,
    /// The files written, relative to the cohort folder.
    pub files: Vec<&'static str>,
}

/// Gathers the subjects `names` (in table order) of the cohort folder `dir`, all fitted from
/// `template`, into the files of this module.
pub fn gather(dir: &Path, template: &Model, names: &[&str]) -> Result<Gathered, CliError> {
    let standings: Vec<Standing> = names.iter().map(|n| Standing::read(&dir.join(n))).collect();
    write_cohort_csv(&dir.join(COHORT_CSV), names, &standings)?;
    let mut files = vec![COHORT_CSV];
    let fitted: Vec<&str> = names
        .iter()
        .zip(&standings)
        .filter(|(_, s)| s.gathered())
        .map(|(n, _)| *n)
        .collect();
    if let Some(t) = template.medial() {
        write_thickness(dir, t, &fitted)?;
        files.extend([THICKNESS_NPY, THICKNESS_SUBJECTS]);
        if !fitted.is_empty() {
            files.push(THICKNESS_MEAN);
        }
    } else {
        tracing::info!("a plain template has no medial atoms: no thickness to gather");
    }
    let pick = |keep: fn(&Standing) -> bool| -> Vec<String> {
        names
            .iter()
            .zip(&standings)
            .filter(|(_, s)| keep(s))
            .map(|(n, _)| n.to_string())
            .collect()
    };
    Ok(Gathered {
        subjects: names.len(),
        gathered: fitted.len(),
        failed: pick(Standing::failed),
        pending: pick(|s| !s.finished() && !s.failed()),
        files,
    })
}

/// Writes `cohort.csv`: a header and one [`Row`] per subject.
fn write_cohort_csv(path: &Path, names: &[&str], standings: &[Standing]) -> Result<(), CliError> {
    medial_io::atomic::write_atomic(path, |w| {
        let mut table = csv::Writer::from_writer(w);
        for (name, standing) in names.iter().zip(standings) {
            table
                .serialize(Row::of(name, standing))
                .map_err(std::io::Error::other)?;
        }
        table.flush()
    })?;
    Ok(())
}

/// Writes `thickness.npy`, `thickness_subjects.txt` and, with at least one subject,
/// `thickness_mean.vtk` (removed without one) for the subjects `fitted` of `template`.
fn write_thickness(dir: &Path, template: &MedialTemplate, fitted: &[&str]) -> Result<(), CliError> {
    let atoms = template.medial_count();
    let rows = fitted
        .iter()
        .map(|name| {
            let subject = dir.join(name);
            // The file read, checked against the digest its fit recorded.
            crate::results::verify(&subject, "summary.json", |r| r != FITTED)?;
            thickness_at_end(&subject.join(FITTED), atoms)
        })
        .collect::<Result<Vec<_>, _>>()?;
    medial_io::npy::write_npy(
        &dir.join(THICKNESS_NPY),
        &[rows.len(), atoms],
        &rows.concat(),
    )?;
    let listed: String = fitted.iter().map(|n| format!("{n}\n")).collect();
    write_text(&dir.join(THICKNESS_SUBJECTS), &listed)?;
    let mean_path = dir.join(THICKNESS_MEAN);
    if rows.is_empty() {
        return match std::fs::remove_file(&mean_path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(CliError::io(&mean_path, e)),
            _ => Ok(()),
        };
    }
    let (mean, sd) = mean_and_sd(&rows, atoms);
    let mut sheet = PolyData::from_triangles(template.medial_points(), template.medial_triangles());
    sheet.point_data = vec![
        DataArray::scalars("ThicknessMean", mean, ValueType::Double),
        DataArray::scalars("ThicknessSD", sd, ValueType::Double),
        DataArray::scalars("Subjects", vec![rows.len() as f64; atoms], ValueType::Int),
    ];
    vtk::write_polydata(&mean_path, &sheet, write_options(false))?;
    Ok(())
}

/// A subject's fitted template, the file the thickness is read from.
const FITTED: &str = "fitted_template.vtk";

/// The thickness of every atom of the fitted template `path`, which must have `atoms` atoms:
/// [`SpokeMetrics`]' `thickness`, as the `Thickness` array of the medial VTK files.
fn thickness_at_end(path: &Path, atoms: usize) -> Result<Vec<f64>, CliError> {
    let fitted = match medial_io::model::read_model(path)? {
        Model::Medial(t) if t.medial_count() == atoms => t,
        model => {
            return Err(CliError::Input(format!(
                "{}: {} medial atoms where the cohort's template has {atoms}: was it fitted \
                 from another template?",
                path.display(),
                model.medial_count()
            )))
        }
    };
    Ok(SpokeMetrics::compute(&fitted, fitted.landmarks()).thickness)
}

/// Per atom, the mean over `rows` (each `atoms` long) and the sample standard deviation
/// `sqrt(Σ (x − mean)² / (n − 1))` (0 for a single row). Summed in row order.
fn mean_and_sd(rows: &[Vec<f64>], atoms: usize) -> (Vec<f64>, Vec<f64>) {
    let n = rows.len() as f64;
    let mean: Vec<f64> = (0..atoms)
        .map(|a| rows.iter().map(|r| r[a]).sum::<f64>() / n)
        .collect();
    let sd = (0..atoms)
        .map(|a| {
            let squares: f64 = rows.iter().map(|r| (r[a] - mean[a]).powi(2)).sum();
            if rows.len() > 1 {
                (squares / (n - 1.0)).sqrt()
            } else {
                0.0
            }
        })
        .collect();
    (mean, sd)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_sd_per_atom() {
        let rows = vec![vec![1.0, 2.0], vec![3.0, 2.0], vec![5.0, 2.0]];
        let (mean, sd) = mean_and_sd(&rows, 2);
        assert_eq!(mean, [3.0, 2.0]);
        assert_eq!(sd, [2.0, 0.0]);
        assert_eq!(mean_and_sd(&rows[..1], 2).1, [0.0, 0.0]);
    }
}
