//! Legacy VTK polydata (`.vtk`): ASCII and binary (big-endian), the 3.0/4.x cell layout
//! (`POLYGONS n size` with a count before each cell) and the 5.1 layout
//! (`POLYGONS n+1 size` followed by `OFFSETS` and `CONNECTIVITY`), point and cell arrays as
//! `FIELD`, `SCALARS`, `NORMALS` or `VECTORS`.

use medial_core::Vec3;

/// How a data array was (or will be) stored in the file.
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
    /// Any integer type (`int`, `long`, `vtkIdType`, `unsigned_char`, ...); written as `int`.
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

/// Text or big-endian binary.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Encoding {
    /// `ASCII`.
    #[default]
    Ascii,
    /// `BINARY` (big-endian, as legacy VTK requires).
    Binary,
}

/// Which cell layout to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Layout {
    /// `# vtk DataFile Version 4.2`, counts before each cell: read by every VTK and ParaView.
    #[default]
    Legacy,
    /// `# vtk DataFile Version 5.1`, `OFFSETS`/`CONNECTIVITY`.
    Offsets,
}

/// Options of [`write_polydata`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct WriteOptions {
    /// Text or binary.
    pub encoding: Encoding,
    /// Cell layout.
    pub layout: Layout,
}
