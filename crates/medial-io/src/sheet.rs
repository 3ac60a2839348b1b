//! Medial sheets ([`MedialSheet`]): a triangle mesh of medial points (mm), possibly non-manifold,
//! with a radius per vertex (mm), read from and written to legacy VTK polydata.

use crate::vtk::{read_polydata, write_polydata, DataArray, PolyData, ValueType, WriteOptions};
use crate::{Error, Result};
use medial_core::construction::MedialSheet;
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

/// Writes a medial sheet as VTK polydata: its points and triangles, and its radii as the point
/// array `Radius` (mm), the file [`read_sheet`] reads and `medial inflate` takes.
pub fn write_sheet(path: &Path, sheet: &MedialSheet, options: WriteOptions) -> Result<()> {
    let mut data = PolyData::from_triangles(sheet.points(), sheet.triangles());
    data.point_data.push(DataArray::scalars(
        "Radius",
        sheet.radius().to_vec(),
        ValueType::Double,
    ));
    write_polydata(path, &data, options)
}
