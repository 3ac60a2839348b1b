//! Legacy VTK polydata (`.vtk`): ASCII and binary (big-endian), the 3.0/4.x cell layout
//! (`POLYGONS n size` with a count before each cell) and the 5.1 layout
//! (`POLYGONS n+1 size` followed by `OFFSETS` and `CONNECTIVITY`), point and cell arrays as
//! `FIELD`, `SCALARS`, `NORMALS` or `VECTORS`.
//!
//! Reading follows VTK's own legacy reader (`vtkDataReader`): keywords are case-insensitive,
//! every VTK numeric type is accepted (`bit` and text arrays are refused), array names are
//! `%XX`-decoded, `METADATA` blocks (written by VTK 9 after arrays) and `LOOKUP_TABLE` sections
//! are skipped, and dataset-level `FIELD` data (before `POINT_DATA`/`CELL_DATA`) is dropped.
//! Attribute kinds without an [`ArrayKind`] of their own (`TEXTURE_COORDINATES`, `TENSORS`,
//! `TENSORS6`, `COLOR_SCALARS`, `GLOBAL_IDS`, `PEDIGREE_IDS`) are read as
//! [`ArrayKind::Field`] arrays. ASCII values declared `float` are parsed as `f32` (as VTK
//! does), so ASCII and binary files with the same content give the same numbers.
//!
//! Everything is validated: counts agree with their headers, cell indices are below the number
//! of points, points are finite, arrays have one tuple per point (or cell). Errors name the
//! file, the section and the line (ASCII) or byte offset (binary).
//!
//! Writing is lossless for what a [`PolyData`] holds: points as `double`, arrays in their
//! [`ValueType`] (an `Int` array is written as `int`, or as `vtktypeint64`/`double` when its
//! values do not fit). In each attribute set the first `SCALARS`, `NORMALS` and `VECTORS`
//! array are written as those attributes and every other array in one `FIELD FieldData n`
//! block after them, so that VTK's own reader, which reads only the first array of each
//! attribute kind by default but every `FIELD` array, sees them all. Files are written
//! atomically. [`write_series`] writes ParaView's `.vtk.series` index of a time series.
//!
//! | file | what it holds |
//! |---|---|
//! | `polydata` | [`PolyData`], [`DataArray`] and their checks |
//! | `reader` | [`read_polydata`], [`parse_polydata`], [`read_trimesh`]: header, `POINTS`, cells in both layouts |
//! | `attributes` | `POINT_DATA`/`CELL_DATA` arrays, `FIELD` blocks, lookup tables |
//! | `cursor` | tokens, lines, ASCII and binary values, `METADATA` blocks |
//! | `scalar`, `text` | VTK's numeric types, integers and array names as text |
//! | `writer` | [`write_polydata`], [`polydata_to_bytes`], [`write_trimesh`], [`WriteOptions`] |
//! | `series` | [`write_series`], [`SeriesFile`]: ParaView's JSON index of a time series of files |

mod attributes;
mod cursor;
mod polydata;
mod reader;
mod scalar;
mod series;
mod text;
mod writer;

pub use polydata::{scalars, ArrayKind, DataArray, PolyData, ValueType};
pub use reader::{parse_polydata, read_polydata, read_trimesh};
pub(crate) use scalar::push_f64;
pub use series::{series_json, write_series, SeriesFile};
pub use writer::{
    polydata_to_bytes, write_polydata, write_trimesh, Encoding, Layout, WriteOptions,
};
