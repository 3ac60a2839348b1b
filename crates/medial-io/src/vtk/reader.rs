//! Reading legacy VTK polydata: the header, the keywords of the body, `POINTS` and the cell
//! lists in the 3.0/4.x layout (a count before each cell) and the 5.x layout (`OFFSETS` and
//! `CONNECTIVITY`). Attribute arrays are read in [`super::attributes`].

use std::path::Path;

use medial_core::{TriMesh, Vec3};

use super::attributes::{ArrayHeader, AttributeSet};
use super::cursor::Cursor;
use super::polydata::{CellSection, PolyData};
use super::scalar::Scalar;
use super::text::{parse_digits, show};
use crate::{Error, Result};

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

/// Reads a triangle mesh from a VTK polydata file: its points and its polygons, which must all
/// be triangles (vertices and lines cells are ignored, arrays dropped).
///
/// Errors: as [`read_polydata`] and [`PolyData::to_trimesh`].
pub fn read_trimesh(path: &Path) -> Result<TriMesh> {
    read_polydata(path)?.to_trimesh(path)
}

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
pub(super) fn starts_section(word: &[u8]) -> bool {
    section_of(word).is_some_and(|s| s != Section::Metadata)
        || [&b"OFFSETS"[..], b"CONNECTIVITY", b"DATASET"]
            .iter()
            .any(|k| word.eq_ignore_ascii_case(k))
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

/// The body of a file after its header.
pub(super) struct Parser<'a> {
    /// Where the parser is.
    pub(super) cursor: Cursor<'a>,
    /// Whether cells use the 5.x `OFFSETS` layout.
    offsets_layout: bool,
    /// What has been read so far.
    pub(super) data: PolyData,
    /// The attribute set that arrays go to, with its declared number of tuples. Set by the
    /// first `POINT_DATA` or `CELL_DATA`, after which no geometry may follow (as in VTK).
    pub(super) target: Option<(AttributeSet, usize)>,
    /// Whether a `POINTS` section was read.
    seen_points: bool,
}

impl<'a> Parser<'a> {
    fn new(cursor: Cursor<'a>, offsets_layout: bool) -> Self {
        Self {
            cursor,
            offsets_layout,
            data: PolyData::default(),
            target: None,
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

    /// Checks the whole data set.
    fn finish(self) -> Result<PolyData> {
        let Parser { cursor, data, .. } = self;
        data.validate().map_err(|m| Error::format(cursor.path, m))?;
        Ok(data)
    }

    /// Geometry ends at the first `POINT_DATA` or `CELL_DATA`: VTK's reader reads only
    /// attributes after it and refuses a geometry keyword there.
    fn check_geometry_allowed(&self, keyword: &str) -> Result<()> {
        match self.target {
            Some((set, _)) => Err(self.cursor.error(format!(
                "{keyword} after {}: the geometry must come before the point and cell data",
                set.name()
            ))),
            None => Ok(()),
        }
    }

    /// `a × b`, or an error when the declared size overflows.
    pub(super) fn product(&self, a: usize, b: usize) -> Result<usize> {
        a.checked_mul(b)
            .ok_or_else(|| self.cursor.error("declared size is too large"))
    }

    fn points(&mut self) -> Result<()> {
        self.cursor.section = "POINTS".into();
        self.check_geometry_allowed("POINTS")?;
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
        self.check_geometry_allowed(section.name())?;
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
}
