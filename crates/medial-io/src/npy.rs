//! NumPy `.npy` arrays (format versions 1.0 to 3.0), read into `f64` and written as `f64`.
//!
//! Reading accepts the numeric dtypes `f8`, `f4`, `i1`..`i8`, `u1`..`u8` and `b1` (bool), little
//! or big endian, in C or Fortran order; the values come back in C (row-major) order. 64-bit
//! integers beyond 2^53 in magnitude are rounded to the nearest `f64`. Other dtypes (complex,
//! strings, records, dates) are refused. Writing produces little-endian `f64` (`<f8`) in
//! C order, atomically.

use std::path::Path;

use npyz::{DType, NpyFile, NpyHeader, Order, TypeChar, TypeStr, WriterBuilder};

use crate::atomic::write_atomic;
use crate::{Error, Result};

/// The magic string that opens a `.npy` file.
const MAGIC: &[u8] = b"\x93NUMPY";

/// The deepest nesting of brackets read in a header: a numeric array's header nests 2 deep
/// (`{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }`), record dtypes a few more;
/// the header parser of `npyz` takes a time exponential in the depth.
pub const MAX_HEADER_DEPTH: usize = 8;

/// An n-dimensional array: `data[i_0 · s_0 + … + i_{k−1} · s_{k−1}]` holds element
/// `(i_0, …, i_{k−1})` with C-order strides `s_j = shape[j+1] · … · shape[k−1]`;
/// `data.len()` is the product of `shape` (1 for a 0-dimensional array).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The size of each axis, slowest first.
    pub shape: Vec<usize>,
    /// The values in C (row-major) order.
    pub data: Vec<f64>,
}

/// Reads a `.npy` file (see the module documentation for the accepted dtypes).
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Format`] for a malformed header
/// or an unsupported dtype; [`Error::Truncated`] for a header or data shorter than declared,
/// [`Error::TrailingBytes`] for bytes after them (a `.npy` file ends with its data).
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_npy(&bytes, path)
}

/// Writes `data` (C order) with `shape` as a little-endian `f64` `.npy` file, atomically.
///
/// Errors: [`Error::Format`] when the product of `shape` differs from `data.len()` (nothing is
/// written); [`Error::Io`] when the file cannot be written.
pub fn write_npy(path: &Path, shape: &[usize], data: &[f64]) -> Result<()> {
    let count = element_count(shape);
    if count != Some(data.len()) {
        return Err(Error::format(
            path,
            format!(
                "shape {shape:?} holds {} values but {} were given",
                count.map_or("too many".to_string(), |n| n.to_string()),
                data.len()
            ),
        ));
    }
    let dtype = "<f8"
        .parse::<TypeStr>()
        .map(DType::Plain)
        .map_err(|e| Error::format(path, e.to_string()))?;
    let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    write_atomic(path, |w| {
        let mut writer = npyz::WriteOptions::<f64>::new()
            .dtype(dtype)
            .shape(&shape)
            .writer(w)
            .begin_nd()?;
        writer.extend(data.iter().copied())?;
        writer.finish()
    })
}

/// The product of `shape`, `None` on overflow.
fn element_count(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d))
}

/// Parses the bytes of a `.npy` file as [`read_npy`] does (`path` is only used in error
/// messages).
///
/// Errors: as [`read_npy`], but for [`Error::Io`].
pub fn parse_npy(bytes: &[u8], path: &Path) -> Result<NpyArray> {
    let format_error = |message: String| Error::format(path, message);
    check_header_text(bytes, path)?;
    let mut data_bytes = bytes;
    let header = NpyHeader::from_reader(&mut data_bytes)
        .map_err(|e| format_error(format!("invalid .npy header: {e}")))?;
    let shape = header
        .shape()
        .iter()
        .map(|&d| usize::try_from(d).ok())
        .collect::<Option<Vec<usize>>>()
        .ok_or_else(|| format_error(format!("shape {:?} is too large", header.shape())))?;
    let type_str = match header.dtype() {
        DType::Plain(type_str) => type_str,
        other => {
            return Err(format_error(format!(
                "dtype {} is not supported (expected a numeric array)",
                other.descr()
            )))
        }
    };
    let needed = element_count(&shape)
        .and_then(|n| n.checked_mul(type_str.size_field() as usize))
        .and_then(|n| u64::try_from(n).ok())
        .unwrap_or(u64::MAX);
    let available = data_bytes.len() as u64;
    if needed > available {
        return Err(Error::Truncated {
            path: path.into(),
            what: format!("shape {shape:?} of {type_str}"),
            needed,
            available,
        });
    }
    if needed < available {
        let file_len = bytes.len() as u64;
        return Err(Error::TrailingBytes {
            path: path.into(),
            data_end: file_len - (available - needed),
            file_len,
        });
    }
    let order = header.order();
    let file = NpyFile::with_header(header, data_bytes);
    let values = read_values(file, &type_str)
        .map_err(|e| format_error(format!("cannot read the {type_str} data: {e}")))?;
    let data = match order {
        Order::C => values,
        Order::Fortran => fortran_to_c(&shape, &values),
    };
    Ok(NpyArray { shape, data })
}

/// Checks what `npyz` trusts in the header of a file that opens with the magic string of a
/// known version: that the declared header length lies in the file (`npyz` allocates it
/// first), and that its text nests brackets at most [`MAX_HEADER_DEPTH`] deep. Anything else
/// is left to `npyz`'s own errors.
///
/// Errors: [`Error::Truncated`] for a header longer than the file; [`Error::Format`] for a
/// header nested too deep.
fn check_header_text(bytes: &[u8], path: &Path) -> Result<()> {
    let Some(rest) = bytes.strip_prefix(MAGIC) else {
        return Ok(());
    };
    // Version (2 bytes), then the header length: u16 in version 1, u32 in versions 2 and 3.
    let (length, start) = match (rest.first(), rest.get(2..6)) {
        (Some(1), Some(b)) => (usize::from(u16::from_le_bytes([b[0], b[1]])), 10),
        (Some(2 | 3), Some(b)) => (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize, 12),
        _ => return Ok(()),
    };
    let text = bytes
        .get(start..)
        .and_then(|b| b.get(..length))
        .ok_or_else(|| Error::Truncated {
            path: path.into(),
            what: "the .npy header".into(),
            needed: length as u64,
            available: bytes.len().saturating_sub(start) as u64,
        })?;
    let depth = text
        .iter()
        .scan(0usize, |depth, b| {
            match b {
                b'(' | b'[' | b'{' => *depth += 1,
                b')' | b']' | b'}' => *depth = depth.saturating_sub(1),
                _ => {}
            }
            Some(*depth)
        })
        .max()
        .unwrap_or(0);
    if depth > MAX_HEADER_DEPTH {
        return Err(Error::format(
            path,
            format!(
                "the .npy header nests brackets {depth} deep (at most {MAX_HEADER_DEPTH} are read)"
            ),
        ));
    }
    Ok(())
}

/// The values of a numeric dtype, converted to `f64`.
fn read_values(file: NpyFile<&[u8]>, type_str: &TypeStr) -> std::io::Result<Vec<f64>> {
    match (type_str.type_char(), type_str.size_field()) {
        (TypeChar::Float, 8) => convert(file, |v: f64| v),
        (TypeChar::Float, 4) => convert(file, |v: f32| f64::from(v)),
        (TypeChar::Int, 1) => convert(file, |v: i8| f64::from(v)),
        (TypeChar::Int, 2) => convert(file, |v: i16| f64::from(v)),
        (TypeChar::Int, 4) => convert(file, |v: i32| f64::from(v)),
        (TypeChar::Int, 8) => convert(file, |v: i64| v as f64),
        (TypeChar::Uint, 1) => convert(file, |v: u8| f64::from(v)),
        (TypeChar::Uint, 2) => convert(file, |v: u16| f64::from(v)),
        (TypeChar::Uint, 4) => convert(file, |v: u32| f64::from(v)),
        (TypeChar::Uint, 8) => convert(file, |v: u64| v as f64),
        (TypeChar::Bool, 1) => convert(file, |v: bool| f64::from(u8::from(v))),
        _ => Err(std::io::Error::other(format!(
            "dtype {type_str} is not supported (expected f8, f4, i1-i8, u1-u8 or b1)"
        ))),
    }
}

fn convert<T: npyz::Deserialize>(
    file: NpyFile<&[u8]>,
    to_f64: impl Fn(T) -> f64,
) -> std::io::Result<Vec<f64>> {
    Ok(file.into_vec::<T>()?.into_iter().map(to_f64).collect())
}

/// Reorders Fortran-order values (first axis fastest) into C order (last axis fastest).
fn fortran_to_c(shape: &[usize], values: &[f64]) -> Vec<f64> {
    // Fortran stride of axis k: shape[0] · … · shape[k−1].
    let strides: Vec<usize> = shape
        .iter()
        .scan(1, |stride, &d| {
            let current = *stride;
            *stride *= d;
            Some(current)
        })
        .collect();
    let mut index = vec![0usize; shape.len()];
    let mut offset = 0;
    let mut out = Vec::with_capacity(values.len());
    for _ in 0..values.len() {
        out.push(values[offset]);
        // Advance the C-order multi-index (last axis fastest), tracking the Fortran offset.
        for axis in (0..shape.len()).rev() {
            index[axis] += 1;
            offset += strides[axis];
            if index[axis] < shape[axis] {
                break;
            }
            offset -= strides[axis] * shape[axis];
            index[axis] = 0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fortran_to_c_matches_index_formula() {
        let shape = [2, 3, 4];
        // Fortran storage of a[i, j, k] = 100 i + 10 j + k.
        let mut fortran = Vec::new();
        for k in 0..4 {
            for j in 0..3 {
                for i in 0..2 {
                    fortran.push(f64::from(100 * i + 10 * j + k));
                }
            }
        }
        let c = fortran_to_c(&shape, &fortran);
        let expected: Vec<f64> = (0..2)
            .flat_map(|i| {
                (0..3).flat_map(move |j| (0..4).map(move |k| f64::from(100 * i + 10 * j + k)))
            })
            .collect();
        assert_eq!(c, expected);
        assert_eq!(fortran_to_c(&[], &[7.0]), vec![7.0]);
        assert_eq!(fortran_to_c(&[0, 3], &[]), Vec::<f64>::new());
    }
}
