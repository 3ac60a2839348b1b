//! What a person looks at in a fit folder, written from the folder's own files (so that
//! `medial report DIR` can write it again for any fit folder):
//!
//! | file | what |
//! |---|---|
//! | `flow/boundary.vtk.series`, `flow/medial.vtk.series` | ParaView's index of the time point files with their times `t = n / N` |
//! | `flow.glb` | the boundary and the medial sheet animated over `t`, coloured by thickness ([`animation`]) |
//! | `report.html` | the figures and tables of the fit, self-contained ([`page`]) |
//!
//! [`folder`] reads the fit folder, [`table`] its CSV files, [`figures`] draws with plotters,
//! [`label`] names columns and writes numbers; [`overlay`] draws the model on the data (slices
//! of the target with the model's sections, a 3-D view rendered by [`render`] and written by
//! [`png`]).

mod animation;
mod figures;
mod folder;
mod label;
mod overlay;
mod page;
mod png;
mod render;
pub mod study;
mod table;

use crate::error::CliError;
use crate::output::write_text;
use folder::{FitFolder, FlowKind};
use medial_io::vtk::{write_series, SeriesFile};
use std::path::Path;

/// Whether the file `relative` of a fit folder is one of the views [`write`] makes.
pub fn is_view(relative: &str) -> bool {
    let series = |kind: FlowKind| relative == format!("flow/{}.vtk.series", kind.name());
    matches!(relative, "flow.glb" | "report.html")
        || series(FlowKind::Boundary)
        || series(FlowKind::Medial)
}

/// Writes the series, `flow.glb` and `report.html` of the fit folder `dir` from its files and
/// returns their paths relative to `dir` (`/`-separated), in the order written; the report
/// names the fit by the folder `shown` (`dir`, or the result folder `dir` stages for).
///
/// Errors: [`CliError::File`] when `summary.json` or `log.csv` is missing or malformed, a
/// file under `flow/` cannot be read, or an output cannot be written; [`CliError::Figure`] when
/// a figure cannot be drawn.
pub fn write(dir: &Path, shown: &Path) -> Result<Vec<String>, CliError> {
    let folder = FitFolder::read(dir, shown)?;
    let mut written = Vec::new();
    for kind in [FlowKind::Boundary, FlowKind::Medial] {
        let files: Vec<SeriesFile> = folder
            .files(kind)
            .iter()
            .map(|f| SeriesFile {
                name: f.name.clone(),
                time: f.time,
            })
            .collect();
        if !files.is_empty() {
            let relative = format!("flow/{}.vtk.series", kind.name());
            write_series(&dir.join(&relative), &files)?;
            written.push(relative);
        }
    }
    animation::write(&folder, &dir.join("flow.glb"))?;
    write_text(&dir.join("report.html"), &page::render(&folder)?)?;
    written.extend(["flow.glb".into(), "report.html".into()]);
    Ok(written)
}
