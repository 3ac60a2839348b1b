//! A fit folder as `medial fit` leaves it, read from disk: `summary.json`, `log.csv`,
//! `time_points.csv`, `config.toml` and the time points under `flow/`.

use super::table::Table;
use crate::error::CliError;
use medial_io::vtk::{read_polydata, PolyData};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The two kinds of files under `flow/`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlowKind {
    /// `boundary_tNNN.vtk`.
    Boundary,
    /// `medial_tNNN.vtk`.
    Medial,
}

impl FlowKind {
    /// The file name prefix and the series' name (`boundary`, `medial`).
    pub fn name(self) -> &'static str {
        match self {
            FlowKind::Boundary => "boundary",
            FlowKind::Medial => "medial",
        }
    }
}

/// One time point file under `flow/`.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowFile {
    /// The time point `n`.
    pub index: usize,
    /// Its time `t = n / N`.
    pub time: f64,
    /// The file name, in `flow/`.
    pub name: String,
}

/// What a fit folder holds.
#[derive(Clone, Debug)]
pub struct FitFolder {
    /// The folder.
    pub dir: PathBuf,
    /// The name the report gives the fit: its result folder's.
    pub name: String,
    /// `summary.json`.
    pub summary: Value,
    /// `log.csv`: one row per L-BFGS iteration.
    pub log: Table,
    /// `time_points.csv` (medial templates).
    pub time_points: Option<Table>,
    /// `config.toml`, as text.
    pub config: Option<String>,
    /// `flow/boundary_tNNN.vtk`, by time point.
    pub boundary: Vec<FlowFile>,
    /// `flow/medial_tNNN.vtk`, by time point.
    pub medial: Vec<FlowFile>,
}

impl FitFolder {
    /// Reads the files of the fit folder `dir`, whose results belong to the folder `shown`
    /// (`dir` itself, or the result folder whose staging folder `dir` is).
    ///
    /// Errors: [`CliError::File`] when `summary.json` or `log.csv` is missing or malformed,
    /// `summary.json` lacks a positive `time_steps`, or `time_points.csv` is malformed.
    pub fn read(dir: &Path, shown: &Path) -> Result<Self, CliError> {
        let summary_path = dir.join("summary.json");
        let text = std::fs::read_to_string(&summary_path)
            .map_err(|e| medial_io::Error::io(&summary_path, e))?;
        let format = |m: String| medial_io::Error::format(&summary_path, m);
        let summary: Value = serde_json::from_str(&text).map_err(|e| format(e.to_string()))?;
        let time_steps = summary["time_steps"]
            .as_u64()
            .filter(|&n| n > 0)
            .ok_or_else(|| format("no positive 'time_steps': is this a fit folder?".into()))?;
        let optional = |name: &str| Some(dir.join(name)).filter(|p| p.exists());
        Ok(Self {
            dir: dir.to_path_buf(),
            name: shown.file_name().map_or_else(
                || shown.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            ),
            log: Table::read(&dir.join("log.csv"))?,
            time_points: optional("time_points.csv")
                .map(|p| Table::read(&p))
                .transpose()?,
            config: optional("config.toml")
                .map(|p| std::fs::read_to_string(&p).map_err(|e| medial_io::Error::io(&p, e)))
                .transpose()?,
            boundary: flow_files(dir, FlowKind::Boundary, time_steps as usize)?,
            medial: flow_files(dir, FlowKind::Medial, time_steps as usize)?,
            summary,
        })
    }

    /// The files of `kind`.
    pub fn files(&self, kind: FlowKind) -> &[FlowFile] {
        match kind {
            FlowKind::Boundary => &self.boundary,
            FlowKind::Medial => &self.medial,
        }
    }

    /// Reads a file under `flow/`.
    ///
    /// Errors: as [`read_polydata`].
    pub fn read_flow(&self, file: &FlowFile) -> Result<PolyData, CliError> {
        Ok(read_polydata(&self.dir.join("flow").join(&file.name))?)
    }
}

/// The files `flow/KIND_tNNN.vtk` of `dir` by time point, with `t = n / N`; none without a
/// `flow/` folder.
///
/// Errors: [`CliError::Io`] when the folder cannot be listed.
fn flow_files(dir: &Path, kind: FlowKind, time_steps: usize) -> Result<Vec<FlowFile>, CliError> {
    let flow = dir.join("flow");
    if !flow.is_dir() {
        return Ok(Vec::new());
    }
    let entries = std::fs::read_dir(&flow).map_err(|e| CliError::io(&flow, e))?;
    let prefix = format!("{}_t", kind.name());
    let mut files = Vec::new();
    for entry in entries {
        let name = entry.map_err(|e| CliError::io(&flow, e))?.file_name();
        let Some(name) = name.to_str() else { continue };
        let digits = name
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix(".vtk"));
        if let Some(index) = digits.and_then(|d| d.parse::<usize>().ok()) {
            files.push(FlowFile {
                index,
                time: index as f64 / time_steps as f64,
                name: name.to_owned(),
            });
        }
    }
    files.sort_by_key(|f| f.index);
    Ok(files)
}
