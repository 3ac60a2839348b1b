//! NumPy `.npy`: round trips, files laid out by hand as numpy writes them, errors.

use std::path::Path;

use medial::io::npy::{read_npy, write_npy, NpyArray};
use medial::io::Error;
use proptest::prelude::*;

use crate::common::clean;
use clean::assert_clean;

/// A version 1.0 `.npy` file as `numpy.save` writes it: magic, header dict padded with spaces
/// and a newline to a multiple of 64 bytes, then the raw data.
fn npy_bytes(descr: &str, fortran_order: bool, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let shape_text = match shape {
        [d] => format!("({d},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let order = if fortran_order { "True" } else { "False" };
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape_text}, }}");
    let unpadded = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    dict.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(
        &u16::try_from(dict.len())
            .expect("short header")
            .to_le_bytes(),
    );
    bytes.extend_from_slice(dict.as_bytes());
    assert_eq!(bytes.len() % 64, 0);
    bytes.extend_from_slice(data);
    bytes
}

fn write_file(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

fn format_message(result: medial::io::Result<NpyArray>) -> String {
    match result {
        Err(Error::Format { message, .. }) => message,
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn fortran_order_f32_is_transposed() {
    // a[i, j] = 10 i + j for a 2 × 3 array, stored column by column.
    let fortran: Vec<u8> = [0f32, 10., 1., 11., 2., 12.]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(&dir, "f.npy", &npy_bytes("<f4", true, &[2, 3], &fortran));
    let array = read_npy(&path).expect("read");
    assert_eq!(
        array,
        NpyArray {
            shape: vec![2, 3],
            data: vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0]
        }
    );
}

#[test]
fn fortran_order_3d() {
    let (ni, nj, nk) = (2, 3, 4);
    let value = |i: usize, j: usize, k: usize| (100 * i + 10 * j + k) as f64;
    let mut fortran = Vec::new();
    for k in 0..nk {
        for j in 0..nj {
            for i in 0..ni {
                fortran.extend_from_slice(&value(i, j, k).to_be_bytes());
            }
        }
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(
        &dir,
        "f3.npy",
        &npy_bytes(">f8", true, &[ni, nj, nk], &fortran),
    );
    let array = read_npy(&path).expect("read");
    assert_eq!(array.shape, [ni, nj, nk]);
    for i in 0..ni {
        for j in 0..nj {
            for k in 0..nk {
                assert_eq!(array.data[(i * nj + j) * nk + k], value(i, j, k));
            }
        }
    }
}

#[test]
fn integer_and_bool_dtypes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cases: Vec<(&str, Vec<u8>, Vec<f64>)> = vec![
        (
            ">i8",
            [-3i64, 1 << 40]
                .iter()
                .flat_map(|v| v.to_be_bytes())
                .collect(),
            vec![-3.0, 2f64.powi(40)],
        ),
        (
            "<i4",
            [-7i32, 9].iter().flat_map(|v| v.to_le_bytes()).collect(),
            vec![-7.0, 9.0],
        ),
        (
            "<i2",
            [-7i16, 9].iter().flat_map(|v| v.to_le_bytes()).collect(),
            vec![-7.0, 9.0],
        ),
        ("|i1", vec![0xff, 5], vec![-1.0, 5.0]),
        ("|u1", vec![0xff, 5], vec![255.0, 5.0]),
        (
            ">u2",
            [65535u16, 1].iter().flat_map(|v| v.to_be_bytes()).collect(),
            vec![65535.0, 1.0],
        ),
        (
            "<u4",
            [4_000_000_000u32, 1]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            vec![4e9, 1.0],
        ),
        (
            "<u8",
            [1u64 << 60, 2]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            vec![2f64.powi(60), 2.0],
        ),
        ("|b1", vec![1, 0], vec![1.0, 0.0]),
        (
            "<f8",
            [0.1f64, -2.5]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            vec![0.1, -2.5],
        ),
    ];
    for (descr, bytes, expected) in cases {
        let path = write_file(&dir, "t.npy", &npy_bytes(descr, false, &[2], &bytes));
        let array = read_npy(&path).unwrap_or_else(|e| panic!("{descr}: {e}"));
        assert_eq!(
            array,
            NpyArray {
                shape: vec![2],
                data: expected
            },
            "{descr}"
        );
    }
}

#[test]
fn unsupported_dtype_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(&dir, "c.npy", &npy_bytes("<c16", false, &[1], &[0; 16]));
    let message = format_message(read_npy(&path));
    assert!(
        message.contains("<c16") && message.contains("not supported"),
        "{message}"
    );
    let path = write_file(&dir, "s.npy", &npy_bytes("|S4", false, &[1], b"abcd"));
    assert!(format_message(read_npy(&path)).contains("not supported"));
}

#[test]
fn truncated_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("a.npy");
    let data: Vec<f64> = (0..12).map(f64::from).collect();
    write_npy(&path, &[3, 4], &data).expect("write");
    let bytes = std::fs::read(&path).expect("read");
    let cut = write_file(&dir, "cut.npy", &bytes[..bytes.len() - 5]);
    let err = read_npy(&cut).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                needed: 96,
                available: 91,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("truncated") && err.to_string().contains("96 bytes"));
    // Cut inside the header: its declared length is more than the file holds.
    let header_only = write_file(&dir, "head.npy", &bytes[..20]);
    let err = read_npy(&header_only).unwrap_err();
    assert!(
        matches!(err, Error::Truncated { available: 10, .. }),
        "{err:?}"
    );
}

/// Bytes after the data were ignored: a `.npy` file ends with its data.
#[test]
fn trailing_bytes_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data: Vec<u8> = [1.0f64, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut bytes = npy_bytes("<f8", false, &[2], &data);
    let exact = write_file(&dir, "exact.npy", &bytes);
    assert_eq!(read_npy(&exact).expect("exact").data, vec![1.0, 2.0]);
    bytes.extend_from_slice(b"tail");
    let path = write_file(&dir, "tail.npy", &bytes);
    let err = read_npy(&path).unwrap_err();
    assert_clean(&err, &path);
    let file_len = bytes.len() as u64;
    assert!(
        matches!(err, Error::TrailingBytes { data_end, file_len: n, .. }
            if data_end == file_len - 4 && n == file_len),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("4 bytes after the end of the data"),
        "{err}"
    );
}

#[test]
fn shape_mismatch_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.npy");
    let err = write_npy(&path, &[2, 3], &[1.0; 5]).expect_err("mismatch");
    match err {
        Error::Format { message, .. } => {
            assert!(message.contains("holds 6 values but 5"), "{message}")
        }
        other => panic!("expected a format error, got {other:?}"),
    }
    assert!(!path.exists());
}

#[test]
fn missing_file_is_io_error() {
    let err = read_npy(Path::new("/nonexistent/x.npy")).expect_err("missing");
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
}

#[test]
fn written_file_follows_numpy_conventions() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("w.npy");
    write_npy(&path, &[2, 2], &[1.0, 2.0, 3.0, 4.5]).expect("write");
    let bytes = std::fs::read(&path).expect("read");
    assert!(bytes.starts_with(b"\x93NUMPY"));
    let header_len = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).expect("ascii header");
    assert!(
        header.contains("'descr': '<f8'") && header.contains("'fortran_order': False"),
        "{header}"
    );
    assert!(
        header.contains("'shape': (2, 2") && header.ends_with('\n'),
        "{header}"
    );
    assert_eq!((10 + header_len) % 64, 0, "data is 64-byte aligned");
    let data = &bytes[10 + header_len..];
    assert_eq!(data.len(), 32);
    assert_eq!(data[24..32], 4.5f64.to_le_bytes());
}

fn shaped_array() -> impl Strategy<Value = NpyArray> {
    proptest::collection::vec(0usize..5, 0..4).prop_flat_map(|shape| {
        let count: usize = shape.iter().product();
        proptest::collection::vec(any::<f64>(), count).prop_map(move |data| NpyArray {
            shape: shape.clone(),
            data,
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn round_trip(array in shaped_array()) {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("r.npy");
        write_npy(&path, &array.shape, &array.data).expect("write");
        let back = read_npy(&path).expect("read");
        prop_assert_eq!(&back.shape, &array.shape);
        // Bit for bit, NaN payloads included.
        let bits = |a: &NpyArray| a.data.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
        prop_assert_eq!(bits(&back), bits(&array));
    }
}
