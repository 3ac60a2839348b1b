//! Writing legacy VTK polydata: both encodings, both cell layouts, arrays in their value type.

use std::io::Write as _;
use std::path::Path;

use medial_core::{TriMesh, Vec3};

use super::polydata::{ArrayKind, DataArray, PolyData, ValueType, CELL_SECTIONS};
use super::scalar::Scalar;
use super::text::encode_name;
use crate::atomic::write_atomic;
use crate::{Error, Result};

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

/// Writes a triangle mesh as VTK polydata (points and triangles, no arrays), atomically.
///
/// Errors: [`Error::Io`] when the file cannot be written.
pub fn write_trimesh(path: &Path, mesh: &TriMesh, options: WriteOptions) -> Result<()> {
    write_polydata(path, &PolyData::from_trimesh(mesh), options)
}

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

/// The arrays of one attribute set as they are written: the first `SCALARS`, the first
/// `NORMALS` and the first `VECTORS` array as attributes, in order, and every other array in
/// the `FIELD` block. VTK's legacy reader (`vtkDataReader`) reads only the first array of each
/// attribute kind unless told to read them all (`ReadAllScalarsOn`, ...), but every `FIELD`
/// array: written so, every array is seen by a plain reader and by ParaView, the first
/// `SCALARS` array is the active scalars and the first `NORMALS` the normals (as cmrep reads
/// them).
fn split_attributes(arrays: &[DataArray]) -> (Vec<&DataArray>, Vec<&DataArray>) {
    let mut seen = Vec::new();
    arrays.iter().partition(|array| {
        let attribute = array.kind != ArrayKind::Field && !seen.contains(&array.kind);
        if attribute {
            seen.push(array.kind);
        }
        attribute
    })
}

/// Values per ASCII line for tuples of `components`: whole tuples, about nine values.
fn values_per_line(components: usize) -> usize {
    components * (9 / components).max(1)
}

/// The bytes of a file being written.
struct Writer {
    /// The file so far.
    out: Vec<u8>,
    /// `BINARY` (else `ASCII`).
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

    /// `POINT_DATA`/`CELL_DATA`: the arrays of [`split_attributes`], the attributes first
    /// (`SCALARS`, `NORMALS`, `VECTORS`), then one `FIELD FieldData n` block with the others.
    fn attributes(&mut self, set: &str, arrays: &[DataArray], tuples: usize) {
        if arrays.is_empty() {
            return;
        }
        self.text(&format!("{set} {tuples}\n"));
        let (attributes, fields) = split_attributes(arrays);
        for array in attributes {
            let scalar = file_scalar(array);
            let name = encode_name(&array.name);
            let header = match array.kind {
                ArrayKind::Scalars => format!(
                    "SCALARS {name} {} {}\nLOOKUP_TABLE default\n",
                    scalar.name(),
                    array.components
                ),
                ArrayKind::Normals => format!("NORMALS {name} {}\n", scalar.name()),
                ArrayKind::Vectors => format!("VECTORS {name} {}\n", scalar.name()),
                ArrayKind::Field => unreachable!("split_attributes keeps FIELD arrays apart"),
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
