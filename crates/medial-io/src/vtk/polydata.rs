//! The content of a polydata file: points, the four cell lists and the point and cell arrays,
//! with the checks every file must pass.

use std::path::Path;

use medial_core::{TriMesh, Vec3};

use crate::{Error, Result};

/// How a data array was (or will be) stored in the file. The writer stores only the first
/// `Scalars`, `Normals` and `Vectors` array of an attribute set as that attribute and the
/// others as `FIELD` arrays (VTK's legacy reader sees only the first of each attribute kind).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArrayKind {
    /// `SCALARS name type ncomp` (with `LOOKUP_TABLE default`).
    Scalars,
    /// `NORMALS name type` (3 components).
    Normals,
    /// `VECTORS name type` (3 components).
    Vectors,
    /// An array of a `FIELD` block.
    Field,
}

/// The element type of an array in the file; values are held as `f64` in memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueType {
    /// Any integer type (`int`, `long`, `vtkIdType`, `unsigned_char`, ...); written as `int`,
    /// or `vtktypeint64` when a value does not fit, or `double` when one is not an integer.
    Int,
    /// `float` (32 bits).
    Float,
    /// `double` (64 bits).
    Double,
}

/// A named point or cell array: `values.len() == components × count`, tuple-major.
#[derive(Clone, Debug, PartialEq)]
pub struct DataArray {
    /// The array's name as in the file (case preserved).
    pub name: String,
    /// Components per tuple.
    pub components: usize,
    /// The values, tuple after tuple.
    pub values: Vec<f64>,
    /// How it is stored.
    pub kind: ArrayKind,
    /// Its element type in the file.
    pub value_type: ValueType,
}

/// A one-component array of scalars named `name`.
pub fn scalars(name: &str, values: Vec<f64>, value_type: ValueType) -> DataArray {
    DataArray {
        name: name.into(),
        components: 1,
        values,
        kind: ArrayKind::Scalars,
        value_type,
    }
}

/// Legacy VTK `DATASET POLYDATA`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyData {
    /// `POINTS`.
    pub points: Vec<Vec3>,
    /// `VERTICES` cells.
    pub vertices: Vec<Vec<usize>>,
    /// `LINES` cells.
    pub lines: Vec<Vec<usize>>,
    /// `POLYGONS` cells (a triangle mesh has only triangles here).
    pub polygons: Vec<Vec<usize>>,
    /// `TRIANGLE_STRIPS` cells.
    pub strips: Vec<Vec<usize>>,
    /// `POINT_DATA` arrays.
    pub point_data: Vec<DataArray>,
    /// `CELL_DATA` arrays.
    pub cell_data: Vec<DataArray>,
}

/// The four cell sections of polydata, in file (and `CELL_DATA`) order.
pub(super) const CELL_SECTIONS: [&str; 4] = ["VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"];

impl PolyData {
    /// Polydata holding a triangle mesh: its points and one polygon per triangle, no arrays.
    pub fn from_trimesh(mesh: &TriMesh) -> Self {
        Self::from_triangles(mesh.points(), mesh.triangles())
    }

    /// Polydata holding `points` and one polygon per triangle, no arrays.
    pub fn from_triangles(points: &[Vec3], triangles: &[[usize; 3]]) -> Self {
        Self {
            points: points.to_vec(),
            polygons: triangles.iter().map(|t| t.to_vec()).collect(),
            ..Self::default()
        }
    }

    /// The triangle mesh of the points and polygons (vertices and lines cells are ignored,
    /// arrays dropped); `path` names the file in errors.
    ///
    /// Errors: [`Error::Format`] naming the first polygon that is not a triangle (or the
    /// presence of triangle strips), see [`Self::triangles`]; [`Error::Model`] when
    /// [`TriMesh::new`] refuses the mesh.
    pub fn to_trimesh(&self, path: &Path) -> Result<TriMesh> {
        let triangles = self.triangles().map_err(|m| Error::format(path, m))?;
        TriMesh::new(self.points.clone(), triangles).map_err(|e| Error::model(path, e))
    }

    /// The number of cells, `vertices + lines + polygons + strips`: the number of tuples of
    /// every `CELL_DATA` array (whose tuples follow the cells in this order).
    pub fn cell_count(&self) -> usize {
        self.cell_lists().iter().map(|cells| cells.len()).sum()
    }

    /// The polygons as triangles.
    ///
    /// Errors (as text, for the caller to wrap with the file name): the first polygon that is
    /// not a triangle, with its index and vertex count; triangle strips, which are refused too.
    pub fn triangles(&self) -> std::result::Result<Vec<[usize; 3]>, String> {
        if !self.strips.is_empty() {
            return Err(format!(
                "the mesh has {} TRIANGLE_STRIPS cells; only triangles stored as POLYGONS are \
                 supported",
                self.strips.len()
            ));
        }
        self.polygons
            .iter()
            .enumerate()
            .map(|(i, cell)| match *cell.as_slice() {
                [a, b, c] => Ok([a, b, c]),
                _ => Err(format!(
                    "polygon {i} has {} vertices; only triangles are supported",
                    cell.len()
                )),
            })
            .collect()
    }

    /// The point array named exactly `name`.
    pub fn point_array(&self, name: &str) -> Option<&DataArray> {
        self.point_data.iter().find(|a| a.name == name)
    }

    /// The first point array whose name equals `name` ignoring ASCII case (`normals` finds
    /// `Normals`).
    pub fn point_array_ci(&self, name: &str) -> Option<&DataArray> {
        self.point_data
            .iter()
            .find(|a| a.name.eq_ignore_ascii_case(name))
    }

    /// Adds a point array, replacing the one with the same (exact) name if there is one.
    pub fn add_point_array(&mut self, array: DataArray) {
        match self.point_data.iter_mut().find(|a| a.name == array.name) {
            Some(slot) => *slot = array,
            None => self.point_data.push(array),
        }
    }

    /// Checks what a file must satisfy: finite points, cell indices below the number of
    /// points, arrays with a name, at least one component (exactly 3 for `NORMALS` and
    /// `VECTORS`) and `components × tuples` values, with one tuple per point (`point_data`) or
    /// per cell (`cell_data`, see [`Self::cell_count`]).
    ///
    /// Errors: a message naming the first offending point, cell or array.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if let Some((i, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(format!(
                "point {i} is not finite: ({}, {}, {})",
                p.x, p.y, p.z
            ));
        }
        let n = self.points.len();
        for (section, cells) in CELL_SECTIONS.iter().zip(self.cell_lists()) {
            for (c, cell) in cells.iter().enumerate() {
                if let Some(&v) = cell.iter().find(|&&v| v >= n) {
                    return Err(format!(
                        "{section} cell {c} uses point {v} but there are {n} points"
                    ));
                }
            }
        }
        check_arrays("POINT_DATA", &self.point_data, n)?;
        check_arrays("CELL_DATA", &self.cell_data, self.cell_count())
    }

    pub(super) fn cell_lists(&self) -> [&Vec<Vec<usize>>; 4] {
        [&self.vertices, &self.lines, &self.polygons, &self.strips]
    }

    pub(super) fn cell_list_mut(&mut self, section: CellSection) -> &mut Vec<Vec<usize>> {
        match section {
            CellSection::Vertices => &mut self.vertices,
            CellSection::Lines => &mut self.lines,
            CellSection::Polygons => &mut self.polygons,
            CellSection::Strips => &mut self.strips,
        }
    }
}

/// Checks the arrays of one attribute set (`POINT_DATA` or `CELL_DATA`) against its number of
/// tuples (see [`PolyData::validate`]).
fn check_arrays(set: &str, arrays: &[DataArray], tuples: usize) -> std::result::Result<(), String> {
    for a in arrays {
        if a.name.is_empty() {
            return Err(format!("{set} has an array without a name"));
        }
        if a.components == 0 {
            return Err(format!("{set} array '{}' has 0 components", a.name));
        }
        if matches!(a.kind, ArrayKind::Normals | ArrayKind::Vectors) && a.components != 3 {
            return Err(format!(
                "{set} array '{}' is stored as {:?} but has {} components (3 required)",
                a.name, a.kind, a.components
            ));
        }
        if tuples.checked_mul(a.components) != Some(a.values.len()) {
            return Err(format!(
                "{set} array '{}' has {} values, expected {tuples} tuples × {} components",
                a.name,
                a.values.len(),
                a.components
            ));
        }
    }
    Ok(())
}

/// One of the four cell lists, in [`CELL_SECTIONS`] order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum CellSection {
    Vertices,
    Lines,
    Polygons,
    Strips,
}

impl CellSection {
    /// The section's keyword.
    pub(super) fn name(self) -> &'static str {
        CELL_SECTIONS[self as usize]
    }
}
