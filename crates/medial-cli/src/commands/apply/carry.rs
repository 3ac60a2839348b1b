//! Points and meshes carried by a fitted map: a legacy VTK file keeps its cells and arrays (but
//! its normals, which the map turns), other meshes are read and written as triangle meshes.

use super::fitted::FittedMap;
use crate::error::CliError;
use medial_io::vtk::{self, ArrayKind, WriteOptions};
use std::path::Path;

/// Whether `path` names a legacy VTK file (by its extension, in any case).
fn is_vtk(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vtk"))
}

/// Carries the points of the mesh or point set `input` by `map` (by its inverse with
/// `inverse`) into `out`; returns the points before and after.
///
/// A `.vtk` written as `.vtk` keeps every cell and every point and cell array but its `NORMALS`
/// (no longer normal once the map bends the surface: ParaView computes them again); any other
/// pair of formats goes through a triangle mesh ([`medial_io::mesh`]: `.vtk`, `.obj`, `.gltf`,
/// `.glb` read, `.vtk` and `.obj` written).
pub fn carry_mesh(
    map: &FittedMap,
    input: &Path,
    out: &Path,
    inverse: bool,
) -> Result<(Vec<medial_core::Vec3>, Vec<medial_core::Vec3>), CliError> {
    if is_vtk(input) && is_vtk(out) {
        let mut data = vtk::read_polydata(input)?;
        let moved = map.carry(&data.points, inverse)?;
        let before = std::mem::replace(&mut data.points, moved.clone());
        let normals = |a: &vtk::DataArray| a.kind == ArrayKind::Normals;
        if data.point_data.iter().chain(&data.cell_data).any(normals) {
            tracing::info!("the NORMALS arrays of {} are not carried", input.display());
        }
        data.point_data.retain(|a| !normals(a));
        data.cell_data.retain(|a| !normals(a));
        vtk::write_polydata(out, &data, WriteOptions::default())?;
        return Ok((before, moved));
    }
    let (points, triangles) = medial_io::mesh::read_mesh(input)?.into_parts();
    let moved = map.carry(&points, inverse)?;
    let mesh = medial_core::TriMesh::new(moved.clone(), triangles)?;
    medial_io::mesh::write_mesh(out, &mesh)?;
    Ok((points, moved))
}
