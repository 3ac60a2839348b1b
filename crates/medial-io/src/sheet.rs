//! Medial sheets ([`MedialSheet`]): a triangle mesh of medial points (mm), possibly non-manifold,
//! with a radius per vertex (mm), read from legacy VTK polydata.

use crate::vtk::read_polydata;
use crate::{Error, Result};
use medial_core::build::MedialSheet;
use std::path::Path;

/// Reads a medial sheet: the points and triangles of VTK polydata, and its point array named
/// `radius_array` (matched ignoring case, one component: the radius of each medial point, mm).
pub fn read_sheet(path: &Path, radius_array: &str) -> Result<MedialSheet> {
    let data = read_polydata(path)?;
    let triangles = data.triangles().map_err(|m| Error::format(path, m))?;
    let radius = data.point_array_ci(radius_array).ok_or_else(|| {
        let names: Vec<&str> = data.point_data.iter().map(|a| a.name.as_str()).collect();
        Error::format(
            path,
            format!(
                "no point array '{radius_array}' (the radius of each medial point, mm); the file \
                 has: [{}]; choose one with --radius-array",
                names.join(", ")
            ),
        )
    })?;
    if radius.components != 1 {
        return Err(Error::format(
            path,
            format!(
                "point array '{}' has {} components; a radius has 1",
                radius.name, radius.components
            ),
        ));
    }
    MedialSheet::new(data.points.clone(), triangles, radius.values.clone())
        .map_err(|e| Error::model(path, e))
}
