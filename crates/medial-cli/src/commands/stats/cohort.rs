//! A `medial batch` folder as the input of `medial stats` and `medial pca`: `DIR/cohort.csv`
//! (every subject and the status of its fit), each subject's fitted model
//! `DIR/SUBJECT/fitted_template.vtk` and table `DIR/SUBJECT/atoms.csv`, and the template they
//! were all fitted from.

use crate::error::CliError;
use medial_core::model::Model;
use medial_core::MedialTemplate;
use medial_stats::design::Candidate;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The subjects of a cohort folder and the status of each one's fit.
pub struct Cohort {
    /// The folder.
    pub dir: PathBuf,
    /// Every subject of `cohort.csv`, in its order: name and status.
    pub subjects: Vec<(String, String)>,
}

/// A subject of the cohort whose fit is not used, and why.
#[derive(Serialize)]
pub struct LeftOut {
    /// The subject's name.
    pub subject: String,
    /// Why its fit is not used.
    pub why: String,
}

impl LeftOut {
    /// The subject `subject`, left out because `why`, noted on stderr.
    pub fn noted(subject: String, why: String) -> Self {
        eprintln!("subject '{subject}' left out: {why}");
        Self { subject, why }
    }
}

/// The statuses of the fits whose models are used (sound and within their tolerances, as
/// `medial batch` gathers them).
const USABLE: [&str; 2] = ["converged", "budget"];

impl Cohort {
    /// Whether `path` is a cohort folder (holds `cohort.csv`).
    pub fn is_cohort(path: &Path) -> bool {
        path.join("cohort.csv").is_file()
    }

    /// Reads `DIR/cohort.csv`.
    pub fn read(dir: &Path) -> Result<Self, CliError> {
        let path = dir.join("cohort.csv");
        let bad = |m: String| CliError::Input(format!("{}: {m}", path.display()));
        let mut table = csv::Reader::from_path(&path).map_err(|e| bad(e.to_string()))?;
        let header = table.headers().map_err(|e| bad(e.to_string()))?.clone();
        let column = |name: &str| {
            header
                .iter()
                .position(|h| h == name)
                .ok_or_else(|| bad(format!("no `{name}` column: not written by `medial batch`")))
        };
        let (subject, status) = (column("subject")?, column("status")?);
        let mut subjects = Vec::new();
        for record in table.records() {
            let record = record.map_err(|e| bad(e.to_string()))?;
            subjects.push((
                record.get(subject).unwrap_or_default().to_string(),
                record.get(status).unwrap_or_default().to_string(),
            ));
        }
        if subjects.is_empty() {
            return Err(bad("no subjects".into()));
        }
        Ok(Self {
            dir: dir.into(),
            subjects,
        })
    }

    /// Every subject, usable (a sound fit within its tolerances) or not, and why not.
    pub fn candidates(&self) -> Vec<Candidate<'_>> {
        self.subjects
            .iter()
            .map(|(name, status)| Candidate {
                name,
                unusable: (!USABLE.contains(&status.as_str())).then_some(match status.as_str() {
                    "failed" => "its fit failed (see its failed.json)",
                    "pending" => "it has not been fitted yet",
                    "interrupted" => "its fit was interrupted (run the batch again)",
                    "unsound" => "its fit ended unsound",
                    "constraints_not_met" => "its fit ended with its constraints not met",
                    "misses_target" => "its fit missed a part of its target",
                    _ => "its fit has no usable status in cohort.csv",
                }),
            })
            .collect()
    }

    /// The usable subjects in the table's order, and the others (each noted on stderr).
    pub fn usable(&self) -> (Vec<&str>, Vec<LeftOut>) {
        self.usable_of(|_| true)
    }

    /// [`Self::usable`] among the subjects `keep` takes.
    pub fn usable_of(&self, keep: impl Fn(&str) -> bool) -> (Vec<&str>, Vec<LeftOut>) {
        let mut usable = Vec::new();
        let mut left_out = Vec::new();
        for c in self.candidates().into_iter().filter(|c| keep(c.name)) {
            match c.unusable {
                None => usable.push(c.name),
                Some(why) => left_out.push(LeftOut::noted(c.name.into(), why.into())),
            }
        }
        (usable, left_out)
    }

    /// The folder of subject `name`.
    pub fn subject_dir(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The fitted model of subject `name` (`fitted_template.vtk`, the model at t = 1).
    pub fn fitted(&self, name: &str) -> Result<MedialTemplate, CliError> {
        self.verified(name, "fitted_template.vtk")?;
        medial_template(&self.subject_dir(name).join("fitted_template.vtk"))
    }

    /// The template the cohort was fitted from: `template` if given, else the first of
    /// `subjects` that has one: its `template.vtk` (the template as given to an automatic fit),
    /// or the `[model] template` of its `config.toml`.
    pub fn template(
        &self,
        template: Option<&Path>,
        subjects: &[&str],
    ) -> Result<(PathBuf, MedialTemplate), CliError> {
        if let Some(path) = template {
            return Ok((path.into(), medial_template(path)?));
        }
        let first = subjects.first().ok_or_else(|| {
            CliError::Input(format!("{}: no subject to test", self.dir.display()))
        })?;
        let dir = self.subject_dir(first);
        let given = dir.join("template.vtk");
        let path = if given.is_file() {
            given
        } else {
            let config = dir.join("config.toml");
            let text = std::fs::read_to_string(&config).map_err(|e| CliError::io(&config, e))?;
            let value: toml::Value = toml::from_str(&text)
                .map_err(|e| CliError::Input(format!("{}: {e}", config.display())))?;
            match value
                .get("model")
                .and_then(|m| m.get("template"))
                .and_then(|t| t.as_str())
            {
                Some(t) => dir.join(t),
                None => {
                    return Err(CliError::Input(format!(
                        "{}: no [model] template; name the cohort's template with --template",
                        config.display()
                    )))
                }
            }
        };
        Ok((path.clone(), medial_template(&path)?))
    }

    /// Refuses subject `name`'s result file `file` when its bytes differ from the SHA-256
    /// its fit's summary.json records ([`crate::results::verify`]).
    fn verified(&self, name: &str, file: &str) -> Result<(), CliError> {
        crate::results::verify(&self.subject_dir(name), "summary.json", |r| r != file)
    }

    /// The column `column` of subject `name`'s `atoms.csv`, one value per atom (`atoms` of
    /// them); empty cells and `NaN` are missing values.
    pub fn atoms_column(
        &self,
        name: &str,
        column: &str,
        atoms: usize,
    ) -> Result<Vec<f64>, CliError> {
        self.verified(name, "atoms.csv")?;
        let path = self.subject_dir(name).join("atoms.csv");
        let bad = |m: String| CliError::Input(format!("{}: {m}", path.display()));
        let mut table = csv::Reader::from_path(&path).map_err(|e| bad(e.to_string()))?;
        let header = table.headers().map_err(|e| bad(e.to_string()))?.clone();
        let j = header.iter().position(|h| h == column).ok_or_else(|| {
            bad(format!(
                "no column `{column}` (its columns: {}; or a measure: thickness, spoke_pos, \
                 spoke_neg, spoke1, spoke2, spoke3, displacement, ball_residual)",
                header.iter().collect::<Vec<_>>().join(", ")
            ))
        })?;
        let mut values = Vec::with_capacity(atoms);
        for (line, record) in table.records().enumerate() {
            let record = record.map_err(|e| bad(e.to_string()))?;
            let cell = record.get(j).unwrap_or_default().trim();
            let value = if cell.is_empty() || cell.eq_ignore_ascii_case("nan") {
                f64::NAN
            } else {
                cell.parse::<f64>().map_err(|_| {
                    bad(format!(
                        "line {}, column `{column}`: '{cell}' is not a number",
                        line + 2
                    ))
                })?
            };
            if value.is_infinite() {
                return Err(bad(format!(
                    "line {}, column `{column}`: infinite",
                    line + 2
                )));
            }
            values.push(value);
        }
        if values.len() != atoms {
            return Err(bad(format!(
                "{} rows where the template has {atoms} atoms: was it fitted from another template?",
                values.len()
            )));
        }
        Ok(values)
    }
}

/// The medial template in `path` (a plain mesh refused).
pub fn medial_template(path: &Path) -> Result<MedialTemplate, CliError> {
    match medial_io::model::read_model(path)? {
        Model::Medial(t) => Ok(*t),
        Model::Plain(_) => Err(CliError::Input(format!(
            "{}: a plain mesh, not a medial template (no atoms to test)",
            path.display()
        ))),
    }
}
