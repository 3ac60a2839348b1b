//! The [`Model`] a fit deforms, as VTK: read from a template file, and written at any
//! configuration of its landmarks with the medial figures as point arrays, for ParaView.

use crate::cmrep::template_from_polydata;
use crate::vtk::{read_polydata, DataArray, PolyData, ValueType};
use crate::{Error, Result};
use medial_core::model::fidelity::Fidelity;
use medial_core::model::{Model, SpokeMetrics};
use medial_core::{TriMesh, Vec3};
use std::path::Path;

/// Reads a VTK template: with a `MedialIndex` point array it is a cmrep medial template
/// ([`crate::cmrep`]), otherwise a plain triangle mesh or point set.
pub fn read_model(path: &Path) -> Result<Model> {
    let data = read_polydata(path)?;
    if data.point_array_ci("MedialIndex").is_some() {
        return Ok(Model::Medial(Box::new(template_from_polydata(
            &data, path,
        )?)));
    }
    let triangles = data.triangles().map_err(|m| Error::format(path, m))?;
    let mesh = TriMesh::new(data.points, triangles).map_err(|e| Error::model(path, e))?;
    if mesh.points().is_empty() {
        return Err(Error::format(path, "the template has no points"));
    }
    Ok(Model::Plain(mesh))
}

/// The model as its template file holds it, the inverse of [`read_model`]: a medial template as
/// cmrep polydata ([`crate::cmrep::template_to_polydata`]), a plain mesh as its triangles.
pub fn model_polydata(model: &Model) -> PolyData {
    match model {
        Model::Medial(t) => crate::cmrep::template_to_polydata(t),
        Model::Plain(mesh) => PolyData::from_trimesh(mesh),
    }
}

/// The boundary at landmarks `q`; for a medial template with the point arrays
/// `SpokeNormalAngle` (degrees), `SpokeMismatch` (%), `Radius` (spoke length, mm) and
/// `MedialIndex`. A point set is written as vertices.
pub fn boundary_polydata(model: &Model, q: &[Vec3]) -> PolyData {
    let nb = model.boundary_count();
    let mut data = PolyData {
        points: q[..nb].to_vec(),
        ..PolyData::default()
    };
    match model {
        Model::Plain(mesh) if mesh.triangles().is_empty() => {
            data.vertices = (0..nb).map(|i| vec![i]).collect();
        }
        Model::Plain(mesh) => data.polygons = cells(mesh.triangles()),
        Model::Medial(t) => {
            data.polygons = cells(t.boundary_triangles());
            let m = SpokeMetrics::compute(t, q);
            let atom = t.medial_index();
            data.point_data = vec![
                DataArray::scalars(
                    "SpokeNormalAngle",
                    m.spoke_normal_deg.clone(),
                    ValueType::Double,
                ),
                DataArray::scalars(
                    "SpokeMismatch",
                    atom.iter().map(|&a| 100.0 * m.mismatch[a]).collect(),
                    ValueType::Double,
                ),
                DataArray::scalars("Radius", m.spoke_length.clone(), ValueType::Double),
                DataArray::scalars(
                    "MedialIndex",
                    atom.iter().map(|&a| a as f64).collect(),
                    ValueType::Int,
                ),
            ];
        }
    }
    data
}

/// The medial triangle mesh at landmarks `q` with the point arrays `Thickness` (2 × mean spoke
/// length, mm), `SpokeMismatch` (%), `BallResidual` (the inscribed-ball residual
/// `|d − r| / r`, a fraction) and `BallPokesOut` (1 where the ball pokes out of the boundary,
/// else 0; see [`medial_core::model::fidelity`]), for a medial template; `fidelity` is
/// [`medial_core::model::BallFidelity::measure`] at `q`, measured once by the caller.
pub fn medial_polydata(model: &Model, q: &[Vec3], fidelity: &Fidelity) -> Option<PolyData> {
    let t = model.medial()?;
    let m = SpokeMetrics::compute(t, q);
    let nb = t.boundary_count();
    let pokes_out = fidelity.pokes_out.iter().map(|&p| f64::from(u8::from(p)));
    Some(PolyData {
        points: q[nb..].to_vec(),
        polygons: cells(t.medial_triangles()),
        point_data: vec![
            DataArray::scalars("Thickness", m.thickness, ValueType::Double),
            DataArray::scalars(
                "SpokeMismatch",
                m.mismatch.iter().map(|x| 100.0 * x).collect(),
                ValueType::Double,
            ),
            DataArray::scalars("BallResidual", fidelity.residual.clone(), ValueType::Double),
            DataArray::scalars("BallPokesOut", pokes_out.collect(), ValueType::Int),
        ],
        ..PolyData::default()
    })
}

fn cells(triangles: &[[usize; 3]]) -> Vec<Vec<usize>> {
    triangles.iter().map(|t| t.to_vec()).collect()
}
