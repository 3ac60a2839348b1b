//! 4×4 affine maps of world space (RAS, mm): the text file of an SSD stage's `transform`, and
//! the one way this crate completes the three rows stored by NIfTI and OpenEXR headers.
//!
//! **Convention.** A map is about the world origin (not an image centre), in the world
//! coordinates of the template and the images (NIfTI's RAS+: x to the right, y anterior, z
//! superior, mm), and forward: it carries a template point `p` (homogeneous `(x, y, z, 1)`) to
//! `M · p` in the subject.
//!
//! **Text format.** 16 numbers separated by white space, row by row; the last row must be
//! `0 0 0 1`. [`write_affine`] writes 4 lines of 4 numbers with 12 decimals, separated by single
//! spaces. A matrix in ITK's LPS+ coordinates (x to the left, y posterior) reads as
//! [`Convention::Lps`]: `M_RAS = D M_LPS D`, `D = diag(−1, −1, 1, 1)`.
//!
//! **ITK transform files** (`#Insight Transform File V1.0`, as ANTs and `c3d_affine_tool -oitk`
//! write them) are recognised by their first line and are always LPS: `AffineTransform` or
//! `MatrixOffsetTransformBase` (`double` or `float`, 3-D) with `Parameters: a11 a12 a13 a21 …
//! a33 t1 t2 t3` and `FixedParameters: c1 c2 c3` map `x ↦ A (x − c) + t + c`. ITK and greedy
//! maps go from the fixed image to the moving one: to carry a template registered as the moving
//! image onto a fixed subject, invert them (an SSD stage's `transform_invert = true`).

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

/// The coordinates a plain 4×4 matrix file is written in (in a config: `ras`, `lps`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Convention {
    /// RAS+ world coordinates (NIfTI's, greedy's): read as is.
    #[default]
    Ras,
    /// LPS+ world coordinates (ITK's, ANTs'): converted, `M_RAS = D M_LPS D`.
    Lps,
}

/// `D M D`, `D = diag(−1, −1, 1, 1)`: the same map in RAS for a matrix in LPS, and back.
pub fn flip_lps_ras(m: &Matrix4<f64>) -> Matrix4<f64> {
    let d = Matrix4::from_diagonal(&nalgebra::Vector4::new(-1.0, -1.0, 1.0, 1.0));
    d * m * d
}

/// Reads a 4×4 RAS affine matrix from a text file (see the module doc for the format).
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Format`] for a word that is
/// not a number, a count other than 16 or a non-finite number, or a last row other than
/// `0 0 0 1`.
pub fn read_affine(path: &Path) -> Result<Affine3<f64>> {
    read_affine_as(path, Convention::Ras)
}

/// Reads an affine map, in RAS, from a plain 4×4 matrix written in `convention` or from an ITK
/// transform file (LPS whatever `convention` says; see the module doc).
///
/// Errors: as [`read_affine`]; for an ITK file also an unsupported transform type or a wrong
/// number of parameters.
pub fn read_affine_as(path: &Path, convention: Convention) -> Result<Affine3<f64>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let m = if text.starts_with("#Insight Transform File") {
        flip_lps_ras(&itk_matrix(&text).map_err(|m| Error::format(path, m))?)
    } else {
        let m = plain_matrix(&text).map_err(|m| Error::format(path, m))?;
        match convention {
            Convention::Ras => m,
            Convention::Lps => flip_lps_ras(&m),
        }
    };
    regular(&m).map_err(|m| Error::format(path, m))?;
    Ok(Affine3::from_matrix_unchecked(m))
}

/// The least and the most a map may scale a direction (mm per mm): a map outside shrinks or
/// magnifies a direction a millionfold, carrying a template of centimetres below a
/// nanometre or beyond a kilometre, which no registration of anatomy means.
const SCALE_LIMITS: (f64, f64) = (1e-6, 1e6);

/// The largest ratio of the most to the least a map scales a direction (its linear part's
/// condition number): beyond, it is singular to within rounding.
const MAX_CONDITION: f64 = 1e8;

/// `Err` for a map whose linear part is singular, or nearly so in a way that does not depend
/// on its scale alone: its singular values beyond [`SCALE_LIMITS`] or their ratio beyond
/// [`MAX_CONDITION`] (a determinant test alone accepts a map scaled by 1e-12, which carries
/// every point onto one). Reflections are the caller's to judge.
fn regular(m: &Matrix4<f64>) -> std::result::Result<(), String> {
    let linear = m.fixed_view::<3, 3>(0, 0).into_owned();
    let sv = linear.singular_values();
    let (least, most) = (sv.min(), sv.max());
    let within = least >= SCALE_LIMITS.0 && most <= SCALE_LIMITS.1;
    if within && most <= MAX_CONDITION * least {
        return Ok(());
    }
    Err(format!(
        "the map is singular or nearly so: it scales directions by {least:.3e} to {most:.3e} \
         (each must lie within {:.0e} to {:.0e}, their ratio at most {MAX_CONDITION:.0e})",
        SCALE_LIMITS.0, SCALE_LIMITS.1
    ))
}

/// The transform types of an ITK file read by [`itk_matrix`].
const ITK_AFFINE_TYPES: [&str; 4] = [
    "AffineTransform_double_3_3",
    "AffineTransform_float_3_3",
    "MatrixOffsetTransformBase_double_3_3",
    "MatrixOffsetTransformBase_float_3_3",
];

/// The LPS matrix of the one affine transform of an ITK transform file's text.
fn itk_matrix(text: &str) -> std::result::Result<Matrix4<f64>, String> {
    let field = |key: &str| {
        text.lines()
            .find_map(|l| l.trim().strip_prefix(key))
            .map(str::trim)
            .ok_or_else(|| format!("ITK transform file without a '{key}' line"))
    };
    let transforms = text
        .lines()
        .filter(|l| l.trim().starts_with("Transform:"))
        .count();
    if transforms > 1 {
        return Err(format!(
            "the ITK transform file holds {transforms} transforms; only a file of one affine \
             transform is read (ITK applies a file's transforms as a stack): compose them into \
             one first (e.g. antsApplyTransforms -t … -o Linear[out.txt])"
        ));
    }
    let kind = field("Transform:")?;
    if !ITK_AFFINE_TYPES.contains(&kind) {
        return Err(format!(
            "ITK transform type '{kind}' is not read (only {}); convert it to an affine \
             transform first (ConvertTransformFile 3 in out --convertToAffineType)",
            ITK_AFFINE_TYPES.join(", ")
        ));
    }
    let numbers = |key: &str, n: usize| -> std::result::Result<Vec<f64>, String> {
        let values = parse_numbers(field(key)?).map_err(|w| format!("'{w}' is not a number"))?;
        if values.len() != n || values.iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "ITK '{key}' needs {n} finite numbers, found {}",
                values.len()
            ));
        }
        Ok(values)
    };
    let p = numbers("Parameters:", 12)?;
    let c = nalgebra::Vector3::from_row_slice(&numbers("FixedParameters:", 3)?);
    let a = nalgebra::Matrix3::from_row_slice(&p[..9]);
    let t = nalgebra::Vector3::from_row_slice(&p[9..]);
    let mut m = a.to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&(t + c - a * c));
    Ok(m)
}

/// The matrix of the plain text format (16 numbers, last row `0 0 0 1`).
fn plain_matrix(text: &str) -> std::result::Result<Matrix4<f64>, String> {
    let numbers = parse_numbers(text).map_err(|w| format!("'{w}' is not a number"))?;
    if numbers.len() != 16 || numbers.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "expected 16 finite numbers (a 4×4 matrix, row by row), found {}",
            numbers.len()
        ));
    }
    let m = Matrix4::from_row_slice(&numbers);
    if !has_affine_last_row(&m) {
        return Err("the last row of an affine matrix must be 0 0 0 1".into());
    }
    Ok(m)
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
    fn an_itk_affine_is_read_about_its_centre_in_lps() {
        let text = "#Insight Transform File V1.0\n#Transform 0\nTransform: \
                    AffineTransform_double_3_3\nParameters: 0 -1 0 1 0 0 0 0 1 1 2 3\n\
                    FixedParameters: 10 0 0\n";
        let m = itk_matrix(text).unwrap();
        // x ↦ A (x − c) + t + c at the centre c: c + t.
        let at_centre = m * nalgebra::Vector4::new(10.0, 0.0, 0.0, 1.0);
        assert_eq!(at_centre, nalgebra::Vector4::new(11.0, 2.0, 3.0, 1.0));
        // In RAS the same physical point is (−10, 0, 0) and lands on (−11, −2, 3).
        let ras = flip_lps_ras(&m) * nalgebra::Vector4::new(-10.0, 0.0, 0.0, 1.0);
        assert_eq!(ras, nalgebra::Vector4::new(-11.0, -2.0, 3.0, 1.0));
        assert_eq!(flip_lps_ras(&flip_lps_ras(&m)), m);
        let euler = text.replace("AffineTransform_double_3_3", "Euler3DTransform_double_3_3");
        assert!(itk_matrix(&euler).unwrap_err().contains("Euler3DTransform"));
        let short = text.replace(" 1 2 3\n", "\n");
        assert!(itk_matrix(&short).unwrap_err().contains("12"));
    }

    /// Issue 33, item 8: a map scaled by 1e-12 (positive determinant 1e-36) and a rank-2 map
    /// are singular; a second ITK transform in a file is refused, not ignored.
    #[test]
    fn singular_maps_and_a_second_itk_transform_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.txt");
        let read = |text: &str| {
            std::fs::write(&path, text).unwrap();
            read_affine(&path)
        };
        assert!(read("2 0 0 1 0 3 0 2 0 0 0.5 3 0 0 0 1").is_ok());
        for text in [
            "1e-12 0 0 0 0 1e-12 0 0 0 0 1e-12 0 0 0 0 1",
            "1 0 0 0 0 1 0 0 0 0 0 0 0 0 0 1",
            "1 0 0 0 0 1 0 0 1 1 1e-12 0 0 0 0 1",
            "1e7 0 0 0 0 1e7 0 0 0 0 1e7 0 0 0 0 1",
        ] {
            let message = read(text).unwrap_err().to_string();
            assert!(
                message.contains("singular") && message.contains("m.txt"),
                "{message}"
            );
        }
        let one = "#Insight Transform File V1.0\n#Transform 0\nTransform: \
                   AffineTransform_double_3_3\nParameters: 1 0 0 0 1 0 0 0 1 1 2 3\n\
                   FixedParameters: 0 0 0\n";
        assert!(read(one).is_ok());
        let two = format!(
            "{one}{}",
            one.replace("#Insight Transform File V1.0\n", "")
                .replace("#Transform 0", "#Transform 1")
        );
        let message = read(&two).unwrap_err().to_string();
        assert!(message.contains("holds 2 transforms"), "{message}");
    }

    #[test]
    fn numbers_or_the_first_bad_word() {
        assert_eq!(parse_numbers(" 1 -2.5\n3e2 "), Ok(vec![1.0, -2.5, 300.0]));
        assert_eq!(parse_numbers("1 x 2 y"), Err("x"));
    }
}
