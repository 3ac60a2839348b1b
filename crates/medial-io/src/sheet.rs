//! Medial sheets ([`MedialSheet`]): a triangle mesh of medial points (mm), possibly non-manifold,
//! with a radius per vertex (mm), read from and written to legacy VTK polydata; and what a
//! sheet of a shape is built from (its medial points, seams and per-sheet lattices) as polydata
//! to look at in ParaView.

use crate::vtk::{read_polydata, write_polydata, DataArray, PolyData, ValueType, WriteOptions};
use crate::{Error, Result};
use medial_core::construction::skeleton::seam::Seam;
use medial_core::construction::skeleton::SheetLattice;
use medial_core::construction::{MedialAxis, MedialSheet};
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
    write_polydata(path, &sheet_polydata(sheet), options)
}

/// A medial sheet as polydata: its points and triangles, and the point array `Radius` (mm).
pub fn sheet_polydata(sheet: &MedialSheet) -> PolyData {
    let mut data = PolyData::from_triangles(sheet.points(), sheet.triangles());
    data.point_data.push(radius(sheet.radius().to_vec()));
    data
}

/// A label per point as an integer point array, −1 where there is none.
pub fn labels(name: &str, labels: &[Option<usize>]) -> DataArray {
    let values = labels.iter().map(|l| l.map_or(-1.0, |k| k as f64));
    DataArray::scalars(name, values.collect(), ValueType::Int)
}

/// A shape's medial points as polydata, one vertex cell each, with the point arrays `Radius`
/// (mm), `Sheet` and `Seam` (the sheet or seam each is on, −1 where it is on none).
pub fn medial_axis_polydata(axis: &MedialAxis) -> PolyData {
    PolyData {
        points: axis.points.iter().map(|p| p.position).collect(),
        vertices: (0..axis.points.len()).map(|i| vec![i]).collect(),
        point_data: vec![
            radius(axis.points.iter().map(|p| p.radius).collect()),
            labels("Sheet", &axis.branches.sheet),
            labels("Seam", &axis.branches.seam),
        ],
        ..PolyData::default()
    }
}

/// Seams as polydata, one polyline each, with the point arrays `Radius` (mm) and `Seam`.
pub fn seams_polydata(seams: &[Seam]) -> PolyData {
    let mut data = PolyData::default();
    let mut seam_of = Vec::new();
    for (k, seam) in seams.iter().enumerate() {
        let first = data.points.len();
        data.points.extend(&seam.points);
        data.lines.push((first..data.points.len()).collect());
        seam_of.extend(seam.points.iter().map(|_| Some(k)));
    }
    let radii = seams.iter().flat_map(|s| s.radius.iter().copied());
    data.point_data = vec![radius(radii.collect()), labels("Seam", &seam_of)];
    data
}

/// Each sheet's lattice as sampled, before the sheets are cut and stitched along their seams,
/// in one polydata: their triangles, with the point arrays `Radius` (mm) and `Sheet`.
pub fn lattices_polydata(lattices: &[SheetLattice]) -> PolyData {
    let mut data = PolyData::default();
    let (mut radii, mut sheet_of) = (Vec::new(), Vec::new());
    for (k, lattice) in lattices.iter().enumerate() {
        let (sheet, first) = (&lattice.sheet, data.points.len());
        data.points.extend(sheet.points());
        let moved = sheet
            .triangles()
            .iter()
            .map(|t| t.map(|v| first + v).to_vec());
        data.polygons.extend(moved);
        radii.extend(sheet.radius());
        sheet_of.extend(sheet.points().iter().map(|_| Some(k)));
    }
    data.point_data = vec![radius(radii), labels("Sheet", &sheet_of)];
    data
}

/// The point array `Radius` (mm).
fn radius(values: Vec<f64>) -> DataArray {
    DataArray::scalars("Radius", values, ValueType::Double)
}
