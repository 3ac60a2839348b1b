//! The numeric types of legacy VTK files and their ASCII and big-endian binary encodings.

use std::io::Write as _;

use super::polydata::ValueType;
use super::text::{parse_int, show};

/// A numeric type as named in a legacy VTK file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    /// `char`, `signed_char`, `vtktypeint8`.
    I8,
    /// `unsigned_char`, `vtktypeuint8`.
    U8,
    /// `short`, `vtktypeint16`.
    I16,
    /// `unsigned_short`, `vtktypeuint16`.
    U16,
    /// `int`, `vtktypeint32`, `vtkIdType`.
    I32,
    /// `unsigned_int`, `vtktypeuint32`.
    U32,
    /// `long`, `vtktypeint64`.
    I64,
    /// `unsigned_long`, `vtktypeuint64`.
    U64,
    /// `float`, `vtktypefloat32`.
    F32,
    /// `double`, `vtktypefloat64`.
    F64,
}

impl Scalar {
    /// The type named `name` (case-insensitive), with all of VTK's spellings.
    pub(super) fn parse(name: &[u8]) -> std::result::Result<Self, String> {
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
    pub(super) fn name(self) -> &'static str {
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
    pub(super) fn size(self) -> usize {
        use Scalar::*;
        match self {
            I8 | U8 => 1,
            I16 | U16 => 2,
            I32 | U32 | F32 => 4,
            I64 | U64 | F64 => 8,
        }
    }

    /// Whether the type is an integer type.
    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// How arrays of this type are kept in a [`super::DataArray`].
    pub(super) fn value_type(self) -> ValueType {
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
    pub(super) fn parse_ascii(self, token: &[u8]) -> Option<f64> {
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
    pub(super) fn decode(self, bytes: &[u8]) -> Vec<f64> {
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
    pub(super) fn encode(self, value: f64, out: &mut Vec<u8>) {
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
    pub(super) fn format(self, value: f64, out: &mut Vec<u8>) {
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

/// Decodes every `N`-byte chunk of `bytes` with `convert`.
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
