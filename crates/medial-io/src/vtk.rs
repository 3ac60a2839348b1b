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
//! values do not fit), one `FIELD` block per attribute set after the `SCALARS`/`NORMALS`/
//! `VECTORS` arrays. Files are written atomically.

use std::fmt::Display;
use std::io::Write as _;
use std::path::Path;

use medial_core::TriMesh;

use crate::atomic::write_atomic;
use crate::{Error, Result};
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

/// The four cell sections of polydata, in file (and `CELL_DATA`) order.
const CELL_SECTIONS: [&str; 4] = ["VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"];

impl PolyData {
    /// Polydata holding a triangle mesh: its points and one polygon per triangle, no arrays.
    pub fn from_trimesh(mesh: &TriMesh) -> Self {
        Self {
            points: mesh.points().to_vec(),
            polygons: mesh.triangles().iter().map(|t| t.to_vec()).collect(),
            ..Self::default()
        }
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

    fn cell_lists(&self) -> [&Vec<Vec<usize>>; 4] {
        [&self.vertices, &self.lines, &self.polygons, &self.strips]
    }

    fn cell_list_mut(&mut self, section: CellSection) -> &mut Vec<Vec<usize>> {
        match section {
            CellSection::Vertices => &mut self.vertices,
            CellSection::Lines => &mut self.lines,
            CellSection::Polygons => &mut self.polygons,
            CellSection::Strips => &mut self.strips,
        }
    }
}

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

/// Reads a legacy VTK polydata file (see the module documentation for what is accepted).
///
/// Errors: [`Error::Io`] when the file cannot be read, [`Error::Format`] naming the line (or
/// byte offset) and section of the first problem.
pub fn read_polydata(path: &Path) -> Result<PolyData> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_polydata(&bytes, path)
}

/// Parses the bytes of a legacy VTK polydata file; `path` is only used in error messages.
///
/// Errors: [`Error::Format`] as for [`read_polydata`].
pub fn parse_polydata(bytes: &[u8], path: &Path) -> Result<PolyData> {
    let mut cursor = Cursor::new(bytes, path);
    let offsets_layout = read_header(&mut cursor)?;
    let mut parser = Parser::new(cursor, offsets_layout);
    parser.run()?;
    parser.finish()
}

/// Writes polydata atomically (see [`polydata_to_bytes`] for the layout).
///
/// Errors: [`Error::Format`] when `data` fails [`PolyData::validate`] (nothing is written),
/// [`Error::Io`] when the file cannot be written.
pub fn write_polydata(path: &Path, data: &PolyData, options: WriteOptions) -> Result<()> {
    data.validate()
        .map_err(|m| Error::format(path, format!("cannot write polydata: {m}")))?;
    let bytes = polydata_to_bytes(data, options);
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The bytes of a legacy VTK file holding `data`.
///
/// Header `# vtk DataFile Version 4.2` ([`Layout::Legacy`]) or `5.1` ([`Layout::Offsets`],
/// 64-bit offsets and ids); the legacy layout switches to the offsets layout when an index or
/// a cell list does not fit the 32-bit integers it requires. Points are written as `double`;
/// arrays as their [`ValueType`]: `Float` values are rounded to `f32`, `Int` values are written
/// as `int` when they are integers of 32 bits, as `vtktypeint64` when they are integers below
/// 2^53 in magnitude, else as `double`. ASCII numbers are written in their shortest form that
/// reads back to the same value. `data` should satisfy [`PolyData::validate`]; if it does not,
/// the result is a file that readers refuse.
pub fn polydata_to_bytes(data: &PolyData, options: WriteOptions) -> Vec<u8> {
    let layout = match options.layout {
        Layout::Legacy if !fits_legacy_layout(data) => Layout::Offsets,
        layout => layout,
    };
    let mut writer = Writer {
        out: Vec::new(),
        binary: options.encoding == Encoding::Binary,
    };
    writer.header(layout);
    writer.points(&data.points);
    for (section, cells) in CELL_SECTIONS.iter().zip(data.cell_lists()) {
        if !cells.is_empty() {
            writer.cells(section, cells, layout);
        }
    }
    writer.attributes("POINT_DATA", &data.point_data, data.points.len());
    writer.attributes("CELL_DATA", &data.cell_data, data.cell_count());
    writer.out
}

/// Reads a triangle mesh from a VTK polydata file: its points and its polygons, which must all
/// be triangles (vertices and lines cells are ignored, arrays dropped).
///
/// Errors: as [`read_polydata`]; [`Error::Format`] naming the first non-triangle polygon (or
/// the presence of triangle strips); [`Error::Model`] when [`TriMesh::new`] refuses the mesh.
pub fn read_trimesh(path: &Path) -> Result<TriMesh> {
    polydata_into_trimesh(read_polydata(path)?, path)
}

/// Writes a triangle mesh as VTK polydata (points and triangles, no arrays), atomically.
///
/// Errors: [`Error::Io`] when the file cannot be written.
pub fn write_trimesh(path: &Path, mesh: &TriMesh, options: WriteOptions) -> Result<()> {
    write_polydata(path, &PolyData::from_trimesh(mesh), options)
}

/// The triangle mesh of polydata read from `path` (named in errors).
fn polydata_into_trimesh(data: PolyData, path: &Path) -> Result<TriMesh> {
    let triangles = data.triangles().map_err(|m| Error::format(path, m))?;
    TriMesh::new(data.points, triangles).map_err(|e| Error::model(path, e))
}

// ---------------------------------------------------------------------------------------------
// Numeric types of the file.

/// A numeric type as named in a legacy VTK file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// The type named `name` (case-insensitive), with all of VTK's spellings.
    fn parse(name: &[u8]) -> std::result::Result<Self, String> {
        use Scalar::*;
        Ok(match name.to_ascii_lowercase().as_slice() {
            b"char" | b"signed_char" | b"vtktypeint8" => I8,
            b"unsigned_char" | b"vtktypeuint8" => U8,
            b"short" | b"vtktypeint16" => I16,
            b"unsigned_short" | b"vtktypeuint16" => U16,
            // VTK writes vtkIdType arrays as 32-bit ints.
            b"int" | b"vtktypeint32" | b"vtkidtype" => I32,
            b"unsigned_int" | b"vtktypeuint32" => U32,
            b"long" | b"vtktypeint64" => I64,
            b"unsigned_long" | b"vtktypeuint64" => U64,
            b"float" | b"vtktypefloat32" => F32,
            b"double" | b"vtktypefloat64" => F64,
            b"bit" => return Err("arrays of type 'bit' are not supported".into()),
            b"string" | b"utf8_string" | b"variant" => {
                return Err(format!(
                    "arrays of type '{}' (text) are not supported",
                    show(name)
                ))
            }
            _ => return Err(format!("unknown data type '{}'", show(name))),
        })
    }

    /// The name written for this type (and used in messages).
    fn name(self) -> &'static str {
        use Scalar::*;
        match self {
            I8 => "char",
            U8 => "unsigned_char",
            I16 => "short",
            U16 => "unsigned_short",
            I32 => "int",
            U32 => "unsigned_int",
            I64 => "vtktypeint64",
            U64 => "vtktypeuint64",
            F32 => "float",
            F64 => "double",
        }
    }

    /// Bytes per value in a binary file.
    fn size(self) -> usize {
        use Scalar::*;
        match self {
            I8 | U8 => 1,
            I16 | U16 => 2,
            I32 | U32 | F32 => 4,
            I64 | U64 | F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    fn value_type(self) -> ValueType {
        match self {
            Scalar::F32 => ValueType::Float,
            Scalar::F64 => ValueType::Double,
            _ => ValueType::Int,
        }
    }

    /// The range of an integer type (`None` for floating types).
    fn int_range(self) -> Option<(i128, i128)> {
        use Scalar::*;
        match self {
            I8 => Some((i8::MIN.into(), i8::MAX.into())),
            U8 => Some((0, u8::MAX.into())),
            I16 => Some((i16::MIN.into(), i16::MAX.into())),
            U16 => Some((0, u16::MAX.into())),
            I32 => Some((i32::MIN.into(), i32::MAX.into())),
            U32 => Some((0, u32::MAX.into())),
            I64 => Some((i64::MIN.into(), i64::MAX.into())),
            U64 => Some((0, u64::MAX.into())),
            F32 | F64 => None,
        }
    }

    /// Parses one ASCII value; integers must be in the type's range.
    fn parse_ascii(self, token: &[u8]) -> Option<f64> {
        let text = std::str::from_utf8(token).ok()?;
        match self.int_range() {
            None if self == Scalar::F32 => text.parse::<f32>().ok().map(f64::from),
            None => text.parse::<f64>().ok(),
            Some((lo, hi)) => parse_int(token)
                .filter(|v| (lo..=hi).contains(v))
                .map(|v| v as f64),
        }
    }

    /// Decodes big-endian binary values (`bytes.len()` a multiple of [`Self::size`]).
    fn decode(self, bytes: &[u8]) -> Vec<f64> {
        use Scalar::*;
        match self {
            I8 => decode_all(bytes, |b: [u8; 1]| f64::from(i8::from_be_bytes(b))),
            U8 => decode_all(bytes, |b: [u8; 1]| f64::from(b[0])),
            I16 => decode_all(bytes, |b| f64::from(i16::from_be_bytes(b))),
            U16 => decode_all(bytes, |b| f64::from(u16::from_be_bytes(b))),
            I32 => decode_all(bytes, |b| f64::from(i32::from_be_bytes(b))),
            U32 => decode_all(bytes, |b| f64::from(u32::from_be_bytes(b))),
            I64 => decode_all(bytes, |b| i64::from_be_bytes(b) as f64),
            U64 => decode_all(bytes, |b| u64::from_be_bytes(b) as f64),
            F32 => decode_all(bytes, |b| f64::from(f32::from_be_bytes(b))),
            F64 => decode_all(bytes, f64::from_be_bytes),
        }
    }

    /// Appends `value` as big-endian binary.
    fn encode(self, value: f64, out: &mut Vec<u8>) {
        use Scalar::*;
        match self {
            I8 => out.extend_from_slice(&(value as i8).to_be_bytes()),
            U8 => out.extend_from_slice(&(value as u8).to_be_bytes()),
            I16 => out.extend_from_slice(&(value as i16).to_be_bytes()),
            U16 => out.extend_from_slice(&(value as u16).to_be_bytes()),
            I32 => out.extend_from_slice(&(value as i32).to_be_bytes()),
            U32 => out.extend_from_slice(&(value as u32).to_be_bytes()),
            I64 => out.extend_from_slice(&(value as i64).to_be_bytes()),
            U64 => out.extend_from_slice(&(value as u64).to_be_bytes()),
            F32 => out.extend_from_slice(&(value as f32).to_be_bytes()),
            F64 => out.extend_from_slice(&value.to_be_bytes()),
        }
    }

    /// Appends `value` as ASCII text: integers as integers, floating values in the shortest
    /// form that reads back to the same `f32`/`f64`.
    fn format(self, value: f64, out: &mut Vec<u8>) {
        // Writing to a Vec<u8> cannot fail.
        let _ = match self {
            Scalar::F64 if use_exponent(value) => write!(out, "{value:e}"),
            Scalar::F64 => write!(out, "{value}"),
            Scalar::F32 if use_exponent(value) => write!(out, "{:e}", value as f32),
            Scalar::F32 => write!(out, "{}", value as f32),
            _ => write!(out, "{}", value as i64),
        };
    }
}

/// Appends `value` in the shortest decimal form that reads back to the same `f64` (exponent
/// notation below 1e-5 and from 1e15 in magnitude).
pub(crate) fn push_f64(out: &mut Vec<u8>, value: f64) {
    Scalar::F64.format(value, out);
}

fn decode_all<const N: usize>(bytes: &[u8], convert: impl Fn([u8; N]) -> f64) -> Vec<f64> {
    bytes
        .chunks_exact(N)
        .map(|chunk| {
            let mut array = [0u8; N];
            array.copy_from_slice(chunk);
            convert(array)
        })
        .collect()
}

/// Whether a floating value reads better in exponent notation (very small or large).
fn use_exponent(value: f64) -> bool {
    let magnitude = value.abs();
    magnitude.is_finite() && magnitude != 0.0 && !(1e-5..1e15).contains(&magnitude)
}

/// Parses a decimal integer with an optional sign.
fn parse_int(token: &[u8]) -> Option<i128> {
    let (negative, digits) = match token.split_first()? {
        (b'-', rest) => (true, rest),
        (b'+', rest) => (false, rest),
        _ => (false, token),
    };
    let magnitude = parse_digits(digits)?;
    Some(if negative {
        -i128::from(magnitude)
    } else {
        i128::from(magnitude)
    })
}

/// Parses a non-empty run of decimal digits.
fn parse_digits(digits: &[u8]) -> Option<u64> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u64, |acc, &d| {
        let digit = d.checked_sub(b'0').filter(|&d| d < 10)?;
        acc.checked_mul(10)?.checked_add(u64::from(digit))
    })
}

/// A token for messages: lossy UTF-8, at most 40 characters.
fn show(token: &[u8]) -> String {
    String::from_utf8_lossy(token).chars().take(40).collect()
}

/// Decodes VTK's `%XX` escapes in an array name.
fn decode_name(token: &[u8]) -> String {
    let mut bytes = Vec::with_capacity(token.len());
    let mut i = 0;
    while i < token.len() {
        let escaped = (token[i] == b'%')
            .then(|| token.get(i + 1..i + 3))
            .flatten()
            .and_then(|hex| u8::from_str_radix(std::str::from_utf8(hex).ok()?, 16).ok());
        match escaped {
            Some(byte) => {
                bytes.push(byte);
                i += 3;
            }
            None => {
                bytes.push(token[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// Encodes an array name as VTK does: blanks, controls, non-ASCII bytes, `%` and `"` as `%XX`.
fn encode_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for &b in name.as_bytes() {
        if b <= b' ' || b >= 0x7f || b == b'%' || b == b'"' {
            out.push_str(&format!("%{b:02X}"));
        } else {
            out.push(char::from(b));
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Reading.

/// The sections that a keyword opens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Section {
    Points,
    Cells(CellSection),
    PointData,
    CellData,
    Metadata,
    Field,
    LookupTable,
    Array(ArrayHeader),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum CellSection {
    Vertices,
    Lines,
    Polygons,
    Strips,
}

impl CellSection {
    fn name(self) -> &'static str {
        CELL_SECTIONS[self as usize]
    }
}

/// Attribute arrays other than `FIELD`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ArrayHeader {
    Scalars,
    ColorScalars,
    Vectors,
    Normals,
    TextureCoordinates,
    Tensors,
    Tensors6,
    GlobalIds,
    PedigreeIds,
}

impl ArrayHeader {
    fn keyword(self) -> &'static str {
        match self {
            ArrayHeader::Scalars => "SCALARS",
            ArrayHeader::ColorScalars => "COLOR_SCALARS",
            ArrayHeader::Vectors => "VECTORS",
            ArrayHeader::Normals => "NORMALS",
            ArrayHeader::TextureCoordinates => "TEXTURE_COORDINATES",
            ArrayHeader::Tensors => "TENSORS",
            ArrayHeader::Tensors6 => "TENSORS6",
            ArrayHeader::GlobalIds => "GLOBAL_IDS",
            ArrayHeader::PedigreeIds => "PEDIGREE_IDS",
        }
    }
}

/// The section opened by `keyword` (case-insensitive), if it is one.
fn section_of(keyword: &[u8]) -> Option<Section> {
    Some(match keyword.to_ascii_lowercase().as_slice() {
        b"points" => Section::Points,
        b"vertices" => Section::Cells(CellSection::Vertices),
        b"lines" => Section::Cells(CellSection::Lines),
        b"polygons" => Section::Cells(CellSection::Polygons),
        b"triangle_strips" => Section::Cells(CellSection::Strips),
        b"point_data" => Section::PointData,
        b"cell_data" => Section::CellData,
        b"metadata" => Section::Metadata,
        b"field" => Section::Field,
        b"lookup_table" => Section::LookupTable,
        b"scalars" => Section::Array(ArrayHeader::Scalars),
        b"color_scalars" => Section::Array(ArrayHeader::ColorScalars),
        b"vectors" => Section::Array(ArrayHeader::Vectors),
        b"normals" => Section::Array(ArrayHeader::Normals),
        b"texture_coordinates" => Section::Array(ArrayHeader::TextureCoordinates),
        b"tensors" => Section::Array(ArrayHeader::Tensors),
        b"tensors6" => Section::Array(ArrayHeader::Tensors6),
        b"global_ids" => Section::Array(ArrayHeader::GlobalIds),
        b"pedigree_ids" => Section::Array(ArrayHeader::PedigreeIds),
        _ => return None,
    })
}

/// Whether a line starting with `word` (and more words) starts a new part of the file: it ends
/// a `METADATA` block that lacks its closing blank line.
fn starts_section(word: &[u8]) -> bool {
    section_of(word).is_some_and(|s| s != Section::Metadata)
        || [&b"OFFSETS"[..], b"CONNECTIVITY", b"DATASET"]
            .iter()
            .any(|k| word.eq_ignore_ascii_case(k))
}

/// A position in the file, with the line and section for messages.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    binary: bool,
    path: &'a Path,
    section: String,
}

impl<'a> Cursor<'a> {
    fn new(bytes: &'a [u8], path: &'a Path) -> Self {
        Self {
            bytes,
            pos: 0,
            line: 1,
            binary: false,
            path,
            section: "header".into(),
        }
    }

    /// A format error at the current position.
    fn error(&self, message: impl Display) -> Error {
        let place = if self.binary {
            format!("byte {}", self.pos)
        } else {
            format!("line {}", self.line)
        };
        Error::format(
            self.path,
            format!("{message} (in {}, {place})", self.section),
        )
    }

    fn skip_space(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            if b == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token, `None` at the end of the file.
    fn token(&mut self) -> Option<&'a [u8]> {
        self.skip_space();
        let bytes = self.bytes;
        let start = self.pos;
        let len = bytes[start..]
            .iter()
            .take_while(|b| !b.is_ascii_whitespace())
            .count();
        self.pos += len;
        (len > 0).then(|| &bytes[start..start + len])
    }

    /// The next token without consuming it.
    fn peek_token(&self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let start = self.pos
            + bytes[self.pos..]
                .iter()
                .take_while(|b| b.is_ascii_whitespace())
                .count();
        let len = bytes[start..]
            .iter()
            .take_while(|b| !b.is_ascii_whitespace())
            .count();
        (len > 0).then(|| &bytes[start..start + len])
    }

    /// The next token; at the end of the file an error saying `what` was expected.
    fn expect(&mut self, what: &str) -> Result<&'a [u8]> {
        self.token()
            .ok_or_else(|| self.error(format!("unexpected end of file: expected {what}")))
    }

    /// Consumes the keyword `keyword` (case-insensitive) or fails.
    fn keyword(&mut self, keyword: &str) -> Result<()> {
        let token = self.expect(keyword)?;
        if token.eq_ignore_ascii_case(keyword.as_bytes()) {
            Ok(())
        } else {
            Err(self.error(format!("expected {keyword}, found '{}'", show(token))))
        }
    }

    /// A non-negative integer (a count or size).
    fn count(&mut self, what: &str) -> Result<usize> {
        let token = self.expect(what)?;
        parse_digits(token)
            .and_then(|v| usize::try_from(v).ok())
            .ok_or_else(|| {
                self.error(format!(
                    "expected {what} (a non-negative integer), found '{}'",
                    show(token)
                ))
            })
    }

    /// A numeric type name.
    fn scalar(&mut self) -> Result<Scalar> {
        let token = self.expect("a data type")?;
        Scalar::parse(token).map_err(|m| self.error(m))
    }

    /// The next token if it is on the current line.
    fn same_line_token(&mut self) -> Option<&'a [u8]> {
        let blanks = self.bytes[self.pos..]
            .iter()
            .take_while(|b| matches!(b, b' ' | b'\t' | b'\r'))
            .count();
        match self.bytes.get(self.pos + blanks) {
            None | Some(b'\n') => None,
            Some(_) => self.token(),
        }
    }

    /// Ends a header line before binary data: only blanks may remain; consumes the newline.
    fn end_header_line(&mut self) -> Result<()> {
        if let Some(token) = self.same_line_token() {
            return Err(self.error(format!("unexpected '{}' before binary data", show(token))));
        }
        self.line();
        Ok(())
    }

    /// The rest of the current line (without `\n` or `\r\n`), `None` at the end of the file.
    fn line(&mut self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let rest = bytes.get(self.pos..).filter(|r| !r.is_empty())?;
        let text = match rest.iter().position(|&b| b == b'\n') {
            Some(end) => {
                self.pos += end + 1;
                self.line += 1;
                &rest[..end]
            }
            None => {
                self.pos = bytes.len();
                rest
            }
        };
        Some(text.strip_suffix(b"\r").unwrap_or(text))
    }

    /// The next `n` bytes.
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let left = self.bytes.len() - self.pos;
        if n > left {
            return Err(self.error(format!(
                "unexpected end of file: {what} needs {n} bytes, {left} left"
            )));
        }
        let bytes = self.bytes;
        self.pos += n;
        Ok(&bytes[self.pos - n..self.pos])
    }

    /// `count` values of type `scalar` (ASCII or binary), then any `METADATA` block.
    fn values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        let values = if self.binary {
            self.binary_values(scalar, count, what)?
        } else {
            self.ascii_values(scalar, count, what)?
        };
        self.skip_metadata();
        Ok(values)
    }

    fn binary_values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        self.end_header_line()?;
        let n = count
            .checked_mul(scalar.size())
            .ok_or_else(|| self.error(format!("{what}: {count} values is too many")))?;
        Ok(scalar.decode(self.take(n, what)?))
    }

    fn ascii_values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        // Each value takes at least two bytes: do not trust `count` for the allocation.
        let mut values = Vec::with_capacity(count.min((self.bytes.len() - self.pos) / 2 + 1));
        for i in 0..count {
            let Some(token) = self.token() else {
                return Err(self.error(format!(
                    "unexpected end of file: {what} needs {count} values, found {i}"
                )));
            };
            let Some(value) = scalar.parse_ascii(token) else {
                return Err(self.error(format!(
                    "'{}' is not a valid {} value ({what}, value {i})",
                    show(token),
                    scalar.name()
                )));
            };
            values.push(value);
        }
        Ok(values)
    }

    /// Skips a `METADATA` block if one comes next.
    fn skip_metadata(&mut self) {
        if self
            .peek_token()
            .is_some_and(|t| t.eq_ignore_ascii_case(b"METADATA"))
        {
            self.token();
            self.line();
            self.skip_metadata_body();
        }
    }

    /// Skips the lines of a `METADATA` block (`COMPONENT_NAMES` and `INFORMATION n` entries,
    /// as VTK 9 writes them after an array) up to its closing blank line, the end of the file,
    /// or a line that starts a new section.
    fn skip_metadata_body(&mut self) {
        loop {
            let (pos, line) = (self.pos, self.line);
            let Some(text) = self.line() else { return };
            let mut words = text
                .split(|b| b.is_ascii_whitespace())
                .filter(|w| !w.is_empty());
            match (words.next(), words.next()) {
                (None, _) => return,
                // Section headers have two words or more; component names and string values
                // inside the block are single (%-encoded) words, whatever they spell.
                (Some(word), Some(_)) if starts_section(word) => {
                    (self.pos, self.line) = (pos, line);
                    return;
                }
                _ => {}
            }
        }
    }
}

/// Reads the four header lines; returns whether cells use the 5.x `OFFSETS` layout.
fn read_header(cursor: &mut Cursor) -> Result<bool> {
    let path = cursor.path;
    let header_error = |line: usize, message: String| {
        Error::format(path, format!("{message} (in header, line {line})"))
    };
    let first = cursor.line().unwrap_or_default();
    let (major, _) = parse_version(first).map_err(|m| header_error(1, m))?;
    if cursor.line().is_none() {
        return Err(header_error(
            2,
            "unexpected end of file: expected the title line".into(),
        ));
    }
    let encoding = cursor.line().map(|l| l.trim_ascii()).unwrap_or_default();
    cursor.binary = if encoding.eq_ignore_ascii_case(b"BINARY") {
        true
    } else if encoding.eq_ignore_ascii_case(b"ASCII") {
        false
    } else {
        return Err(header_error(
            3,
            format!("expected ASCII or BINARY, found '{}'", show(encoding)),
        ));
    };
    cursor.keyword("DATASET")?;
    let kind = cursor.expect("a dataset type")?;
    if !kind.eq_ignore_ascii_case(b"POLYDATA") {
        return Err(cursor.error(format!(
            "only POLYDATA is supported, this file holds {}",
            show(kind)
        )));
    }
    Ok(major >= 5)
}

/// Parses `# vtk DataFile Version x.y`; versions 1.0 to 5.x are accepted.
fn parse_version(line: &[u8]) -> std::result::Result<(u64, u64), String> {
    let text = String::from_utf8_lossy(line);
    let text = text.trim();
    if text.starts_with("<?xml") || text.starts_with("<VTKFile") {
        return Err(
            "this is an XML VTK file; only legacy VTK ('# vtk DataFile Version x.y') \
                    is supported"
                .into(),
        );
    }
    let not_vtk = || {
        format!(
            "not a legacy VTK file: the first line must be '# vtk DataFile Version x.y', found \
             '{}'",
            show(text.as_bytes())
        )
    };
    let lower = text.to_ascii_lowercase();
    let version = lower
        .strip_prefix("# vtk datafile version")
        .ok_or_else(not_vtk)?
        .trim();
    let (major, minor) = version.split_once('.').unwrap_or((version, "0"));
    let major = parse_digits(major.as_bytes()).ok_or_else(not_vtk)?;
    let minor = parse_digits(minor.as_bytes()).ok_or_else(not_vtk)?;
    if !(1..=5).contains(&major) {
        return Err(format!(
            "unsupported VTK file version {major}.{minor} (1.0 to 5.x are read)"
        ));
    }
    Ok((major, minor))
}

/// Which attribute set (`POINT_DATA` or `CELL_DATA`) arrays currently go to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum AttributeSet {
    Point,
    Cell,
}

impl AttributeSet {
    fn name(self) -> &'static str {
        match self {
            AttributeSet::Point => "POINT_DATA",
            AttributeSet::Cell => "CELL_DATA",
        }
    }
}

/// The body of a file after its header.
struct Parser<'a> {
    cursor: Cursor<'a>,
    offsets_layout: bool,
    data: PolyData,
    /// The attribute set that arrays go to, with its number of tuples.
    target: Option<(AttributeSet, usize)>,
    point_tuples: Option<usize>,
    cell_tuples: Option<usize>,
    seen_points: bool,
}

impl<'a> Parser<'a> {
    fn new(cursor: Cursor<'a>, offsets_layout: bool) -> Self {
        Self {
            cursor,
            offsets_layout,
            data: PolyData::default(),
            target: None,
            point_tuples: None,
            cell_tuples: None,
            seen_points: false,
        }
    }

    fn run(&mut self) -> Result<()> {
        while let Some(token) = self.cursor.token() {
            let Some(section) = section_of(token) else {
                return Err(self.cursor.error(format!(
                    "unknown keyword '{}' (expected POINTS, VERTICES, LINES, POLYGONS, \
                     TRIANGLE_STRIPS, POINT_DATA, CELL_DATA or an attribute array)",
                    show(token)
                )));
            };
            match section {
                Section::Points => self.points()?,
                Section::Cells(cells) => self.cells(cells)?,
                Section::PointData => self.attribute_set(AttributeSet::Point)?,
                Section::CellData => self.attribute_set(AttributeSet::Cell)?,
                Section::Metadata => {
                    self.cursor.line();
                    self.cursor.skip_metadata_body();
                }
                Section::Field => self.field()?,
                Section::LookupTable => self.lookup_table()?,
                Section::Array(header) => self.array(header)?,
            }
        }
        Ok(())
    }

    /// Checks the declared attribute counts and the whole data set.
    fn finish(self) -> Result<PolyData> {
        let Parser {
            cursor,
            data,
            point_tuples,
            cell_tuples,
            ..
        } = self;
        let error = |m: String| Error::format(cursor.path, m);
        if let Some(n) = point_tuples.filter(|&n| n != data.points.len()) {
            return Err(error(format!(
                "POINT_DATA declares {n} tuples but the file has {} points",
                data.points.len()
            )));
        }
        if let Some(n) = cell_tuples.filter(|&n| n != data.cell_count()) {
            return Err(error(format!(
                "CELL_DATA declares {n} tuples but the file has {} cells",
                data.cell_count()
            )));
        }
        data.validate().map_err(error)?;
        Ok(data)
    }

    fn product(&self, a: usize, b: usize) -> Result<usize> {
        a.checked_mul(b)
            .ok_or_else(|| self.cursor.error("declared size is too large"))
    }

    fn points(&mut self) -> Result<()> {
        self.cursor.section = "POINTS".into();
        if self.seen_points {
            return Err(self.cursor.error("a second POINTS section"));
        }
        self.seen_points = true;
        let n = self.cursor.count("the number of points")?;
        let scalar = self.cursor.scalar()?;
        let values = self.cursor.values(scalar, self.product(n, 3)?, "POINTS")?;
        self.data.points = values
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
        Ok(())
    }

    fn cells(&mut self, section: CellSection) -> Result<()> {
        self.cursor.section = section.name().into();
        let first = self.cursor.count("the number of cells")?;
        let size = self.cursor.count("the size of the cell list")?;
        let cells = if self.offsets_layout {
            self.cells_with_offsets(first, size)?
        } else {
            self.cells_with_counts(first, size)?
        };
        let slot = self.data.cell_list_mut(section);
        if !slot.is_empty() {
            return Err(self
                .cursor
                .error(format!("a second {} section", section.name())));
        }
        *slot = cells;
        Ok(())
    }

    /// The 3.0/4.x layout: `n size`, then each cell as its vertex count and vertex ids.
    fn cells_with_counts(&mut self, n: usize, size: usize) -> Result<Vec<Vec<usize>>> {
        let list = self.cursor.values(Scalar::I32, size, "the cell list")?;
        let mut cells = Vec::with_capacity(n.min(size));
        let mut at = 0;
        for c in 0..n {
            let Some(&count) = list.get(at) else {
                return Err(self.cursor.error(format!(
                    "the cell list ({size} values) ends before cell {c} of {n}"
                )));
            };
            let end = at + 1 + self.non_negative(count, c)?;
            let Some(ids) = list.get(at + 1..end) else {
                return Err(self.cursor.error(format!(
                    "cell {c} has {count} vertices but the cell list ({size} values) ends first"
                )));
            };
            cells.push(self.cell_ids(ids, c)?);
            at = end;
        }
        if at != size {
            return Err(self.cursor.error(format!(
                "the header declares {size} values but the {n} cells use {at}"
            )));
        }
        Ok(cells)
    }

    /// The 5.x layout: `n+1 m`, `OFFSETS type` with n+1 offsets, `CONNECTIVITY type` with m ids.
    fn cells_with_offsets(&mut self, offsets: usize, size: usize) -> Result<Vec<Vec<usize>>> {
        if offsets == 0 {
            return Ok(Vec::new());
        }
        self.cursor.keyword("OFFSETS")?;
        let scalar = self.integer_scalar()?;
        let offsets = self.cursor.values(scalar, offsets, "OFFSETS")?;
        self.cursor.keyword("CONNECTIVITY")?;
        let scalar = self.integer_scalar()?;
        let ids = self.cursor.values(scalar, size, "CONNECTIVITY")?;
        let offsets = offsets
            .iter()
            .enumerate()
            .map(|(i, &v)| self.non_negative(v, i))
            .collect::<Result<Vec<usize>>>()?;
        if offsets.first() != Some(&0) || offsets.last() != Some(&size) {
            return Err(self.cursor.error(format!(
                "OFFSETS must run from 0 to the CONNECTIVITY size {size}, found {:?} to {:?}",
                offsets.first(),
                offsets.last()
            )));
        }
        offsets
            .windows(2)
            .enumerate()
            .map(|(c, w)| match ids.get(w[0]..w[1]) {
                Some(cell) => self.cell_ids(cell, c),
                None => Err(self.cursor.error(format!("OFFSETS decrease at cell {c}"))),
            })
            .collect()
    }

    fn integer_scalar(&mut self) -> Result<Scalar> {
        let scalar = self.cursor.scalar()?;
        if scalar.is_integer() {
            Ok(scalar)
        } else {
            Err(self.cursor.error(format!(
                "cell arrays must be integers, found {}",
                scalar.name()
            )))
        }
    }

    /// A non-negative integer value of a cell list (count, offset or id) of cell `cell`.
    fn non_negative(&self, value: f64, cell: usize) -> Result<usize> {
        if value >= 0.0 && value <= usize::MAX as f64 {
            Ok(value as usize)
        } else {
            Err(self.cursor.error(format!(
                "negative value {value} in the cell list (cell {cell})"
            )))
        }
    }

    fn cell_ids(&self, ids: &[f64], cell: usize) -> Result<Vec<usize>> {
        ids.iter().map(|&v| self.non_negative(v, cell)).collect()
    }

    fn attribute_set(&mut self, set: AttributeSet) -> Result<()> {
        self.cursor.section = set.name().into();
        let n = self.cursor.count("the number of tuples")?;
        let declared = match set {
            AttributeSet::Point => &mut self.point_tuples,
            AttributeSet::Cell => &mut self.cell_tuples,
        };
        if let Some(old) = declared.replace(n).filter(|&old| old != n) {
            return Err(self.cursor.error(format!(
                "{} {n} contradicts the earlier {} {old}",
                set.name(),
                set.name()
            )));
        }
        self.target = Some((set, n));
        Ok(())
    }

    /// The current attribute set and its number of tuples.
    fn target(&self, keyword: &str) -> Result<(AttributeSet, usize)> {
        self.target.ok_or_else(|| {
            self.cursor
                .error(format!("{keyword} before POINT_DATA or CELL_DATA"))
        })
    }

    fn arrays_mut(&mut self, set: AttributeSet) -> &mut Vec<DataArray> {
        match set {
            AttributeSet::Point => &mut self.data.point_data,
            AttributeSet::Cell => &mut self.data.cell_data,
        }
    }

    /// `FIELD name n` then n arrays `name components tuples type` (or `NULL_ARRAY`). Before
    /// any `POINT_DATA`/`CELL_DATA` it is data of the whole data set, which is dropped.
    fn field(&mut self) -> Result<()> {
        let target = self.target;
        let prefix = target.map_or("dataset", |(set, _)| set.name());
        let field_name = decode_name(self.cursor.expect("a field name")?);
        self.cursor.section = format!("{prefix} FIELD {field_name}");
        let n = self.cursor.count("the number of arrays")?;
        let mut arrays = Vec::new();
        for _ in 0..n {
            let token = self.cursor.expect("a field array name")?;
            if token == b"NULL_ARRAY" {
                continue;
            }
            let name = decode_name(token);
            self.cursor.section = format!("{prefix} FIELD {field_name} array '{name}'");
            let components = self.components("the number of components")?;
            let tuples = self.cursor.count("the number of tuples")?;
            if let Some((set, expected)) = target.filter(|&(_, t)| t != tuples) {
                return Err(self.cursor.error(format!(
                    "the array has {tuples} tuples but {} has {expected}",
                    set.name()
                )));
            }
            let scalar = self.cursor.scalar()?;
            let values = self
                .cursor
                .values(scalar, self.product(tuples, components)?, "FIELD")?;
            let value_type = scalar.value_type();
            arrays.push(DataArray {
                name,
                components,
                values,
                kind: ArrayKind::Field,
                value_type,
            });
        }
        if let Some((set, _)) = target {
            self.arrays_mut(set).extend(arrays);
        }
        Ok(())
    }

    /// A component count, at least 1.
    fn components(&mut self, what: &str) -> Result<usize> {
        match self.cursor.count(what)? {
            0 => Err(self.cursor.error(format!("{what} must be at least 1"))),
            n => Ok(n),
        }
    }

    /// `LOOKUP_TABLE name size` with `size` RGBA entries: skipped.
    fn lookup_table(&mut self) -> Result<()> {
        let name = decode_name(self.cursor.expect("a lookup table name")?);
        self.cursor.section = format!("LOOKUP_TABLE {name}");
        let size = self.cursor.count("the lookup table size")?;
        let n = self.product(size, 4)?;
        if self.cursor.binary {
            self.cursor.end_header_line()?;
            self.cursor.take(n, "the lookup table")?;
        } else {
            self.cursor.values(Scalar::F32, n, "the lookup table")?;
        }
        Ok(())
    }

    /// An attribute array: `SCALARS`, `NORMALS`, `VECTORS` and the kinds read as `FIELD` arrays.
    fn array(&mut self, header: ArrayHeader) -> Result<()> {
        let (set, tuples) = self.target(header.keyword())?;
        let name = decode_name(self.cursor.expect("an array name")?);
        self.cursor.section = format!("{} {} '{name}'", set.name(), header.keyword());
        let array = match header {
            ArrayHeader::ColorScalars => self.color_scalars(name, tuples)?,
            _ => {
                let (kind, scalar, components) = self.array_layout(header)?;
                let n = self.product(tuples, components)?;
                let values = self.cursor.values(scalar, n, header.keyword())?;
                DataArray {
                    name,
                    components,
                    values,
                    kind,
                    value_type: scalar.value_type(),
                }
            }
        };
        self.arrays_mut(set).push(array);
        Ok(())
    }

    /// The rest of an array header: how the array is kept, its type and components.
    fn array_layout(&mut self, header: ArrayHeader) -> Result<(ArrayKind, Scalar, usize)> {
        Ok(match header {
            ArrayHeader::Scalars => {
                let scalar = self.cursor.scalar()?;
                let components = match self.cursor.same_line_token() {
                    Some(token) => parse_digits(token)
                        .and_then(|n| usize::try_from(n).ok())
                        .filter(|&n| n >= 1)
                        .ok_or_else(|| {
                            self.cursor.error(format!(
                                "expected a number of components, found '{}'",
                                show(token)
                            ))
                        })?,
                    None => 1,
                };
                if self
                    .cursor
                    .peek_token()
                    .is_some_and(|t| t.eq_ignore_ascii_case(b"LOOKUP_TABLE"))
                {
                    self.cursor.token();
                    self.cursor.expect("a lookup table name")?;
                }
                (ArrayKind::Scalars, scalar, components)
            }
            ArrayHeader::Vectors => (ArrayKind::Vectors, self.cursor.scalar()?, 3),
            ArrayHeader::Normals => (ArrayKind::Normals, self.cursor.scalar()?, 3),
            ArrayHeader::TextureCoordinates => {
                let dimension = self.components("the texture dimension")?;
                (ArrayKind::Field, self.cursor.scalar()?, dimension)
            }
            ArrayHeader::Tensors => (ArrayKind::Field, self.cursor.scalar()?, 9),
            ArrayHeader::Tensors6 => (ArrayKind::Field, self.cursor.scalar()?, 6),
            ArrayHeader::GlobalIds | ArrayHeader::PedigreeIds | ArrayHeader::ColorScalars => {
                (ArrayKind::Field, self.cursor.scalar()?, 1)
            }
        })
    }

    /// `COLOR_SCALARS name n`: bytes in binary files, values in [0, 1] in ASCII ones, both
    /// kept as integers 0..=255 as VTK does.
    fn color_scalars(&mut self, name: String, tuples: usize) -> Result<DataArray> {
        let components = self.components("the number of color components")?;
        let n = self.product(tuples, components)?;
        let values = if self.cursor.binary {
            self.cursor.values(Scalar::U8, n, "COLOR_SCALARS")?
        } else {
            let unit = self.cursor.values(Scalar::F32, n, "COLOR_SCALARS")?;
            unit.iter()
                .map(|v| (255.0 * v + 0.5).floor().clamp(0.0, 255.0))
                .collect()
        };
        Ok(DataArray {
            name,
            components,
            values,
            kind: ArrayKind::Field,
            value_type: ValueType::Int,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Writing.

/// Whether every cell list fits the 32-bit integers of the legacy layout.
fn fits_legacy_layout(data: &PolyData) -> bool {
    let limit = i32::MAX as usize;
    data.cell_lists().iter().all(|cells| {
        let size: usize = cells.iter().map(|c| c.len() + 1).sum();
        size <= limit && cells.iter().flatten().all(|&v| v <= limit)
    })
}

/// The file type an array is written with (see [`polydata_to_bytes`]).
fn file_scalar(array: &DataArray) -> Scalar {
    match array.value_type {
        ValueType::Float => Scalar::F32,
        ValueType::Double => Scalar::F64,
        ValueType::Int => {
            let integral = |v: &f64| v.fract() == 0.0;
            let int32 = |v: &f64| (f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(v);
            let exact = |v: &f64| v.abs() <= 2f64.powi(53);
            if array.values.iter().all(|v| integral(v) && int32(v)) {
                Scalar::I32
            } else if array.values.iter().all(|v| integral(v) && exact(v)) {
                Scalar::I64
            } else {
                Scalar::F64
            }
        }
    }
}

/// Values per ASCII line for tuples of `components`: whole tuples, about nine values.
fn values_per_line(components: usize) -> usize {
    components * (9 / components).max(1)
}

struct Writer {
    out: Vec<u8>,
    binary: bool,
}

impl Writer {
    fn text(&mut self, text: &str) {
        self.out.extend_from_slice(text.as_bytes());
    }

    fn header(&mut self, layout: Layout) {
        let version = match layout {
            Layout::Legacy => "4.2",
            Layout::Offsets => "5.1",
        };
        let encoding = if self.binary { "BINARY" } else { "ASCII" };
        self.text(&format!(
            "# vtk DataFile Version {version}\nwritten by medial\n{encoding}\nDATASET POLYDATA\n"
        ));
    }

    /// A block of values: ASCII lines of `per_line` values, or binary; then a newline.
    fn block(&mut self, scalar: Scalar, values: &[f64], per_line: usize) {
        for (i, &value) in values.iter().enumerate() {
            if self.binary {
                scalar.encode(value, &mut self.out);
            } else {
                if i > 0 {
                    self.out.push(if i % per_line == 0 { b'\n' } else { b' ' });
                }
                scalar.format(value, &mut self.out);
            }
        }
        self.out.push(b'\n');
    }

    fn points(&mut self, points: &[Vec3]) {
        self.text(&format!("POINTS {} double\n", points.len()));
        let flat: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        self.block(Scalar::F64, &flat, 9);
    }

    fn cells(&mut self, section: &str, cells: &[Vec<usize>], layout: Layout) {
        match layout {
            Layout::Legacy => self.cells_with_counts(section, cells),
            Layout::Offsets => self.cells_with_offsets(section, cells),
        }
    }

    fn cells_with_counts(&mut self, section: &str, cells: &[Vec<usize>]) {
        let size: usize = cells.iter().map(|c| c.len() + 1).sum();
        self.text(&format!("{section} {} {size}\n", cells.len()));
        for cell in cells {
            let values = std::iter::once(cell.len()).chain(cell.iter().copied());
            for (i, value) in values.enumerate() {
                if self.binary {
                    Scalar::I32.encode(value as f64, &mut self.out);
                } else {
                    if i > 0 {
                        self.out.push(b' ');
                    }
                    // Writing into a Vec<u8> cannot fail.
                    let _ = write!(self.out, "{value}");
                }
            }
            if !self.binary {
                self.out.push(b'\n');
            }
        }
        if self.binary {
            self.out.push(b'\n');
        }
    }

    fn cells_with_offsets(&mut self, section: &str, cells: &[Vec<usize>]) {
        let offsets: Vec<f64> = std::iter::once(0)
            .chain(cells.iter().scan(0, |end, cell| {
                *end += cell.len();
                Some(*end)
            }))
            .map(|v| v as f64)
            .collect();
        let ids: Vec<f64> = cells.iter().flatten().map(|&v| v as f64).collect();
        self.text(&format!("{section} {} {}\n", offsets.len(), ids.len()));
        self.text("OFFSETS vtktypeint64\n");
        self.block(Scalar::I64, &offsets, 9);
        self.text("CONNECTIVITY vtktypeint64\n");
        self.block(Scalar::I64, &ids, 9);
    }

    /// `POINT_DATA`/`CELL_DATA`: `SCALARS`, `NORMALS` and `VECTORS` arrays in order, then one
    /// `FIELD` block with the `Field` arrays.
    fn attributes(&mut self, set: &str, arrays: &[DataArray], tuples: usize) {
        if arrays.is_empty() {
            return;
        }
        self.text(&format!("{set} {tuples}\n"));
        let mut fields = Vec::new();
        for array in arrays {
            let scalar = file_scalar(array);
            let name = encode_name(&array.name);
            let header = match array.kind {
                ArrayKind::Field => {
                    fields.push(array);
                    continue;
                }
                ArrayKind::Scalars => format!(
                    "SCALARS {name} {} {}\nLOOKUP_TABLE default\n",
                    scalar.name(),
                    array.components
                ),
                ArrayKind::Normals => format!("NORMALS {name} {}\n", scalar.name()),
                ArrayKind::Vectors => format!("VECTORS {name} {}\n", scalar.name()),
            };
            self.text(&header);
            self.block(scalar, &array.values, values_per_line(array.components));
        }
        if fields.is_empty() {
            return;
        }
        self.text(&format!("FIELD FieldData {}\n", fields.len()));
        for array in fields {
            let scalar = file_scalar(array);
            self.text(&format!(
                "{} {} {tuples} {}\n",
                encode_name(&array.name),
                array.components,
                scalar.name()
            ));
            self.block(scalar, &array.values, values_per_line(array.components));
        }
    }
}
