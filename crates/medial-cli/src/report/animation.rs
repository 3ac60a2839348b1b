//! `flow.glb`: the boundary and the medial sheet of the time point files under `flow/`,
//! animated over their times, coloured by the local thickness.

use super::folder::{FitFolder, FlowFile, FlowKind};
use crate::error::CliError;
use medial_core::Vec3;
use medial_io::gltf_flow::{AnimatedSurface, FlowAnimation};
use medial_io::vtk::PolyData;
use std::path::Path;

/// Opacity of the boundary when the medial sheet is shown inside it.
const BOUNDARY_OPACITY: f32 = 0.35;

/// The frames of one kind of file: its triangles, the points and the point arrays of each.
struct Frames {
    triangles: Vec<[usize; 3]>,
    data: Vec<PolyData>,
}

impl Frames {
    fn read(folder: &FitFolder, files: &[FlowFile]) -> Result<Self, CliError> {
        let data = files
            .iter()
            .map(|f| folder.read_flow(f))
            .collect::<Result<Vec<_>, _>>()?;
        let first = folder.dir.join("flow").join(&files[0].name);
        let triangles = data[0]
            .triangles()
            .map_err(|m| medial_io::Error::format(&first, m))?;
        Ok(Self { triangles, data })
    }

    fn points(&self) -> Vec<Vec<Vec3>> {
        self.data.iter().map(|d| d.points.clone()).collect()
    }

    /// The values of point array `name` in each frame, if every frame has it.
    fn array(&self, name: &str) -> Option<Vec<Vec<f64>>> {
        self.data
            .iter()
            .map(|d| d.point_array(name).map(|a| a.values.clone()))
            .collect()
    }
}

/// The animation of the fit folder's flow: the boundary and, for a medial template whose
/// medial files are at the same time points, the medial sheet inside it, both coloured by the
/// thickness of the atoms (2 × mean spoke length, mm; a boundary point takes its atom's);
/// `None` without boundary files or triangles.
///
/// Errors: as [`FitFolder::read_flow`]; [`CliError::File`] when a file's polygons are not
/// triangles.
pub fn flow_animation(folder: &FitFolder) -> Result<Option<FlowAnimation>, CliError> {
    let files = folder.files(FlowKind::Boundary);
    if files.is_empty() {
        return Ok(None);
    }
    let boundary = Frames::read(folder, files)?;
    if boundary.triangles.is_empty() {
        return Ok(None);
    }
    let same_times = |m: &[FlowFile]| m.iter().map(|f| f.index).eq(files.iter().map(|f| f.index));
    let medial_files = folder.files(FlowKind::Medial);
    let medial = if !medial_files.is_empty() && same_times(medial_files) {
        Some(Frames::read(folder, medial_files)?)
    } else {
        None
    };
    let thickness = medial.as_ref().and_then(|m| m.array("Thickness"));
    let atoms = boundary.array("MedialIndex");
    let boundary_values = match (&thickness, &atoms) {
        (Some(thickness), Some(atoms)) => thickness
            .iter()
            .zip(atoms)
            .map(|(t, atoms)| {
                atoms
                    .iter()
                    .map(|&a| t.get(a as usize).copied().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect(),
        _ => Vec::new(),
    };
    let mut surfaces = vec![AnimatedSurface {
        name: FlowKind::Boundary.name().into(),
        triangles: boundary.triangles.clone(),
        frames: boundary.points(),
        values: boundary_values,
        opacity: if medial.is_some() {
            BOUNDARY_OPACITY
        } else {
            1.0
        },
    }];
    if let Some(medial) = &medial {
        surfaces.push(AnimatedSurface {
            name: FlowKind::Medial.name().into(),
            triangles: medial.triangles.clone(),
            frames: medial.points(),
            values: thickness.clone().unwrap_or_default(),
            opacity: 1.0,
        });
    }
    let values = thickness
        .iter()
        .flatten()
        .flatten()
        .copied()
        .filter(|v| v.is_finite());
    let value_range = values.fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], v| {
        [lo.min(v), hi.max(v)]
    });
    Ok(Some(FlowAnimation {
        times: files.iter().map(|f| f.time).collect(),
        surfaces,
        value_range: if value_range[0].is_finite() {
            value_range
        } else {
            [0.0, 1.0]
        },
        value_name: "thickness (mm)".into(),
    }))
}

/// Writes `DIR/flow.glb` from the fit folder's flow (nothing without one).
///
/// Errors: as [`flow_animation`] and [`medial_io::gltf_flow::write_flow_glb`].
pub fn write(folder: &FitFolder, path: &Path) -> Result<(), CliError> {
    if let Some(animation) = flow_animation(folder)? {
        medial_io::gltf_flow::write_flow_glb(path, &animation)?;
    }
    Ok(())
}
