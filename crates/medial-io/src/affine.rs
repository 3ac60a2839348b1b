//! 4×4 affine maps of world space (RAS, mm): the text file of an SSD stage's `transform`, and
//! the one way this crate completes the three rows stored by NIfTI and OpenEXR headers.
//!
//! **Text format.** 16 numbers separated by white space, row by row; the last row must be
//! `0 0 0 1`. The matrix maps a point `p` (homogeneous `(x, y, z, 1)`) to `M · p`.
//! [`write_affine`] writes 4 lines of 4 numbers with 12 decimals, separated by single spaces.

use std::path::Path;

use nalgebra::{Affine3, Matrix3x4, Matrix4, RowVector4};

use crate::atomic::write_atomic;
use crate::{Error, Result};

/// The 4×4 affine map whose first three rows are `top` (last row `0 0 0 1`).
pub(crate) fn from_top_rows(top: &Matrix3x4<f64>) -> Matrix4<f64> {
    let mut m = top.insert_row(3, 0.0);
    m[(3, 3)] = 1.0;
    m
}

/// The numbers of a whitespace-separated list; `Err` holds the first word that is not one.
pub(crate) fn parse_numbers(text: &str) -> std::result::Result<Vec<f64>, &str> {
    text.split_whitespace()
        .map(|w| w.parse::<f64>().map_err(|_| w))
        .collect()
}

/// Whether the last row of `m` is `0 0 0 1`.
fn has_affine_last_row(m: &Matrix4<f64>) -> bool {
    m.row(3) == RowVector4::new(0.0, 0.0, 0.0, 1.0)
}

/// Reads a 4×4 affine matrix from a text file (see the module doc for the format).
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Format`] for a word that is
/// not a number, a count other than 16 or a non-finite number, or a last row other than
/// `0 0 0 1`.
pub fn read_affine(path: &Path) -> Result<Affine3<f64>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let bad = |m: String| Error::format(path, m);
    let numbers = parse_numbers(&text).map_err(|w| bad(format!("'{w}' is not a number")))?;
    if numbers.len() != 16 || numbers.iter().any(|x| !x.is_finite()) {
        return Err(bad(format!(
            "expected 16 finite numbers (a 4×4 matrix, row by row), found {}",
            numbers.len()
        )));
    }
    let m = Matrix4::from_row_slice(&numbers);
    if !has_affine_last_row(&m) {
        return Err(bad(
            "the last row of an affine matrix must be 0 0 0 1".into()
        ));
    }
    Ok(Affine3::from_matrix_unchecked(m))
}

/// The text of `m` as [`write_affine`] writes it: 4 lines of 4 numbers with 12 decimals.
pub fn affine_text(m: &Matrix4<f64>) -> String {
    m.row_iter()
        .map(|row| {
            let cells: Vec<String> = row.iter().map(|v| format!("{v:.12}")).collect();
            cells.join(" ") + "\n"
        })
        .collect()
}

/// Writes `m` as [`affine_text`], atomically; [`read_affine`] reads it back to 12 decimals.
///
/// Errors: [`Error::Format`] (nothing written) when a value is not finite or the last row is
/// not `0 0 0 1`; [`Error::Io`] when the file cannot be written.
pub fn write_affine(path: &Path, m: &Matrix4<f64>) -> Result<()> {
    if m.iter().any(|x| !x.is_finite()) || !has_affine_last_row(m) {
        return Err(Error::format(
            path,
            "cannot write the matrix: an affine matrix has finite values and the last row 0 0 0 1",
        ));
    }
    let text = affine_text(m);
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn top_rows_get_the_affine_last_row() {
        let top = Matrix3x4::from_fn(|r, c| (4 * r + c) as f64);
        let m = from_top_rows(&top);
        assert_eq!(m.fixed_view::<3, 4>(0, 0), top);
        assert!(has_affine_last_row(&m));
    }

    #[test]
    fn numbers_or_the_first_bad_word() {
        assert_eq!(parse_numbers(" 1 -2.5\n3e2 "), Ok(vec![1.0, -2.5, 300.0]));
        assert_eq!(parse_numbers("1 x 2 y"), Err("x"));
    }
}
