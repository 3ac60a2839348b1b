//! Affine matrices as text: the shipped `affine.txt` files round-trip byte for byte, and bad
//! files are refused with the wording the CLI has always used.

use std::path::{Path, PathBuf};

use medial::io::affine::{affine_text, read_affine, write_affine};
use medial::io::Error;
use nalgebra::Matrix4;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");

fn write_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write test file");
    path
}

fn format_message(path: &Path) -> String {
    match read_affine(path) {
        Err(Error::Format { message, .. }) => message,
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn shipped_affine_files_round_trip_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    for case in ["toy", "cup", "t001-bent"] {
        let original = Path::new(EXAMPLES).join(case).join("affine.txt");
        let m = read_affine(&original).unwrap().into_inner();
        let copy = dir.path().join(format!("{case}.txt"));
        write_affine(&copy, &m).unwrap();
        assert_eq!(
            std::fs::read(&copy).unwrap(),
            std::fs::read(&original).unwrap(),
            "{case}"
        );
    }
}

#[test]
fn text_is_four_lines_of_twelve_decimals() {
    let mut m = Matrix4::identity();
    m[(0, 3)] = -0.5;
    m[(1, 2)] = 1.0 / 3.0;
    assert_eq!(
        affine_text(&m),
        "1.000000000000 0.000000000000 0.000000000000 -0.500000000000\n\
         0.000000000000 1.000000000000 0.333333333333 0.000000000000\n\
         0.000000000000 0.000000000000 1.000000000000 0.000000000000\n\
         0.000000000000 0.000000000000 0.000000000000 1.000000000000\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.txt");
    write_affine(&path, &m).unwrap();
    let back = read_affine(&path).unwrap().into_inner();
    assert!((back - m).amax() < 1e-12);
}

#[test]
fn bad_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let m = format_message(&write_file(
        d,
        "word.txt",
        "1 0 0 0 0 1 0 0 0 0 x 0 0 0 0 1",
    ));
    assert_eq!(m, "'x' is not a number");
    let m = format_message(&write_file(d, "short.txt", "1 0 0 0 0 1 0 0 0 0 1 0"));
    assert_eq!(
        m,
        "expected 16 finite numbers (a 4×4 matrix, row by row), found 12"
    );
    let m = format_message(&write_file(
        d,
        "nan.txt",
        "1 0 0 0 0 1 0 0 0 0 1 NaN 0 0 0 1",
    ));
    assert!(m.starts_with("expected 16 finite numbers"), "{m}");
    let m = format_message(&write_file(d, "row.txt", "1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1"));
    assert_eq!(m, "the last row of an affine matrix must be 0 0 0 1");
    let err = read_affine(&d.join("missing.txt")).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
}

#[test]
fn writing_refuses_a_matrix_that_is_not_affine() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = Matrix4::identity();
    m[(3, 0)] = 0.5;
    let err = write_affine(&dir.path().join("p.txt"), &m).unwrap_err();
    assert!(matches!(err, Error::Format { .. }), "{err:?}");
    m[(3, 0)] = 0.0;
    m[(0, 0)] = f64::INFINITY;
    assert!(write_affine(&dir.path().join("inf.txt"), &m).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}
