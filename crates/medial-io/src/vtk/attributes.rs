//! The attribute arrays of legacy VTK polydata: `POINT_DATA`/`CELL_DATA` sections, `FIELD`
//! blocks, `SCALARS`, `NORMALS`, `VECTORS` and the kinds read as `FIELD` arrays, lookup tables.

use super::polydata::{ArrayKind, DataArray, ValueType};
use super::reader::Parser;
use super::scalar::Scalar;
use super::text::{decode_name, parse_digits, show};
use crate::Result;

/// Which attribute set (`POINT_DATA` or `CELL_DATA`) arrays currently go to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum AttributeSet {
    /// `POINT_DATA`.
    Point,
    /// `CELL_DATA`.
    Cell,
}

impl AttributeSet {
    /// The section's keyword.
    pub(super) fn name(self) -> &'static str {
        match self {
            AttributeSet::Point => "POINT_DATA",
            AttributeSet::Cell => "CELL_DATA",
        }
    }
}

/// Attribute arrays other than `FIELD`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ArrayHeader {
    /// `SCALARS`.
    Scalars,
    /// `COLOR_SCALARS`.
    ColorScalars,
    /// `VECTORS`.
    Vectors,
    /// `NORMALS`.
    Normals,
    /// `TEXTURE_COORDINATES`.
    TextureCoordinates,
    /// `TENSORS`.
    Tensors,
    /// `TENSORS6`.
    Tensors6,
    /// `GLOBAL_IDS`.
    GlobalIds,
    /// `PEDIGREE_IDS`.
    PedigreeIds,
}

impl ArrayHeader {
    /// The section's keyword.
    pub(super) fn keyword(self) -> &'static str {
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

impl Parser<'_> {
    /// `POINT_DATA n` or `CELL_DATA n`: where the following arrays go.
    ///
    /// As in VTK's legacy reader (`vtkPolyDataReader`), the first of them ends the geometry
    /// and must count every point, or every cell of all kinds (vertices, lines, polygons and
    /// strips); a later one is not checked against the geometry, so an empty section may
    /// declare any count, but the arrays it holds must fit the data set (see
    /// [`Self::target`]).
    pub(super) fn attribute_set(&mut self, set: AttributeSet) -> Result<()> {
        self.cursor.section = set.name().into();
        let n = self.cursor.count("the number of tuples")?;
        if self.target.is_none() {
            let (have, what) = self.tuples_in_geometry(set);
            if n != have {
                return Err(self.cursor.error(format!(
                    "{} declares {n} tuples but the file has {have} {what}",
                    set.name()
                )));
            }
        }
        self.target = Some((set, n));
        Ok(())
    }

    /// The number of points, or of cells of all kinds, and what they are called.
    fn tuples_in_geometry(&self, set: AttributeSet) -> (usize, &'static str) {
        match set {
            AttributeSet::Point => (self.data.points.len(), "points"),
            AttributeSet::Cell => (
                self.data.cell_count(),
                "cells (vertices, lines, polygons and strips)",
            ),
        }
    }

    /// The current attribute set and its number of tuples, which must fit the data set for
    /// an array to go there: VTK would read the array but give an inconsistent data set.
    fn target(&self, keyword: &str) -> Result<(AttributeSet, usize)> {
        let (set, n) = self.target.ok_or_else(|| {
            self.cursor
                .error(format!("{keyword} before POINT_DATA or CELL_DATA"))
        })?;
        let (have, what) = self.tuples_in_geometry(set);
        if n != have {
            return Err(self.cursor.error(format!(
                "{keyword} in {} {n}, but the file has {have} {what}: an array needs one tuple \
                 each",
                set.name()
            )));
        }
        Ok((set, n))
    }

    fn arrays_mut(&mut self, set: AttributeSet) -> &mut Vec<DataArray> {
        match set {
            AttributeSet::Point => &mut self.data.point_data,
            AttributeSet::Cell => &mut self.data.cell_data,
        }
    }

    /// `FIELD name n` then n arrays `name components tuples type` (or `NULL_ARRAY`). Before
    /// any `POINT_DATA`/`CELL_DATA` it is data of the whole data set, which is dropped.
    pub(super) fn field(&mut self) -> Result<()> {
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
            if target.is_some() {
                self.target("a FIELD array")?;
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
    pub(super) fn lookup_table(&mut self) -> Result<()> {
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
    pub(super) fn array(&mut self, header: ArrayHeader) -> Result<()> {
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
