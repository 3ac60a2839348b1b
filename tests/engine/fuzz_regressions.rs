//! The inputs on which the cargo-fuzz targets (`fuzz/`) found a panic, a hang or an
//! unbounded allocation, minimised, and those found while reading the libraries the readers
//! trust: each must now give a clean one-line error.

use std::path::Path;

use medial::image::volume::Volume;
use medial::io::mesh::{parse_gltf, read_mesh};
use medial::io::nifti_volume::{parse_nifti, write_nifti, NiftiType};
use medial::io::npy::{parse_npy, MAX_HEADER_DEPTH};
use medial::io::Error;

use crate::common::clean;

/// A `.npy` file of format `version` whose header (padded as numpy pads it) is `text`,
/// followed by `data`.
fn npy(version: u8, text: &str, data: &[u8]) -> Vec<u8> {
    let mut bytes = b"\x93NUMPY".to_vec();
    bytes.extend([version, 0]);
    match version {
        1 => bytes.extend((text.len() as u16).to_le_bytes()),
        _ => bytes.extend((text.len() as u32).to_le_bytes()),
    }
    bytes.extend(text.as_bytes());
    bytes.extend(data);
    bytes
}

/// The fuzzer's hang: `npyz` parses a header of nested brackets in a time exponential in the
/// depth (30 levels took more than 10 s).
#[test]
fn npy_header_nested_deep_is_refused_at_once() {
    let path = Path::new("deep.npy");
    let nested = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': {}{}, }}\n",
        "[".repeat(30),
        "]".repeat(30)
    );
    let error = parse_npy(&npy(1, &nested, &[]), path).unwrap_err();
    clean::assert_clean(&error, path);
    assert!(
        error.to_string().contains("nests brackets 31 deep"),
        "{error}"
    );
    // The deepest nesting read still reaches the header parser (and its own error).
    let depth = MAX_HEADER_DEPTH - 1;
    let nested = format!("{{'shape': {}{}}}\n", "[".repeat(depth), "]".repeat(depth));
    let error = parse_npy(&npy(1, &nested, &[]), path).unwrap_err();
    assert!(error.to_string().contains("invalid .npy header"), "{error}");
}

/// A version 2 header declaring 4 GiB of header text in a 12-byte file: `npyz` allocates the
/// declared length before reading it.
#[test]
fn npy_header_longer_than_the_file_is_truncated() {
    let path = Path::new("long.npy");
    let mut bytes = npy(2, "", &[]);
    bytes[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    let error = parse_npy(&bytes, path).unwrap_err();
    clean::assert_clean(&error, path);
    assert!(
        matches!(
            error,
            Error::Truncated {
                needed: 0xFFFF_FFFF,
                available: 0,
                ..
            }
        ),
        "{error}"
    );
}

/// The fuzzer's panic: a GLB header whose total length is below its own 12 bytes (the `gltf`
/// crate subtracts 12 with an overflow).
#[test]
fn glb_length_below_its_header_is_refused() {
    let path = Path::new("short.glb");
    let mut bytes = b"glTF".to_vec();
    bytes.extend(2u32.to_le_bytes());
    bytes.extend(11u32.to_le_bytes());
    let error = parse_gltf(&bytes, path).unwrap_err();
    clean::assert_clean(&error, path);
    assert!(error.to_string().contains("declares 11 bytes"), "{error}");
}

/// A glTF document with one buffer at `uri`.
fn gltf_with_buffer(uri: &str) -> String {
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "buffers": [{{"byteLength": 4, "uri": "{uri}"}}],
            "meshes": []}}"#
    )
}

/// A relative buffer URI that is not UTF-8 once percent-decoded: the `gltf` crate unwraps
/// the decoding.
#[test]
fn gltf_buffer_uri_not_utf8_is_refused() {
    let path = Path::new("/nonexistent/m.gltf");
    let error = parse_gltf(gltf_with_buffer("%FF%FE.bin").as_bytes(), path).unwrap_err();
    clean::assert_clean(&error, path);
    assert!(error.to_string().contains("buffer 0"), "{error}");
}

/// A buffer that is a device or a folder, not a file: `/dev/zero` would be read without end.
#[test]
fn gltf_buffer_that_is_no_regular_file_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("m.gltf");
    for uri in ["/dev/zero", "file:///dev/zero", "."] {
        std::fs::write(&path, gltf_with_buffer(uri)).expect("write the glTF");
        let error = read_mesh(&path).unwrap_err();
        clean::assert_clean(&error, &path);
        assert!(
            error.to_string().contains("is not a regular file"),
            "{uri}: {error}"
        );
    }
}

/// A gzip NIfTI is inflated only as far as its header declares, yet checked to the end of the
/// stream: data followed by a long tail of zeros read as the volume, and a checksum broken
/// after the data is still refused.
#[test]
fn gzip_nifti_is_read_to_its_data_and_checked_to_its_end() {
    use std::io::Write as _;
    let dir = tempfile::tempdir().expect("temp dir");
    let plain = dir.path().join("v.nii");
    let affine = nalgebra::Matrix4::new_scaling(0.5);
    let volume = Volume::new([3, 2, 2], (0..12).map(f64::from).collect(), affine).unwrap();
    write_nifti(&plain, &volume, NiftiType::F32).expect("write the volume");
    let mut file = std::fs::read(&plain).expect("read it back");
    file.resize(file.len() + (1 << 20), 0);
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    encoder.write_all(&file).expect("compress");
    let mut gz = encoder.finish().expect("compress");
    let path = Path::new("v.nii.gz");
    let read = parse_nifti(gz.clone(), path).expect("a valid gzip NIfTI");
    assert_eq!(read.data(), volume.data());
    let crc = gz.len() - 8;
    gz[crc] ^= 1;
    let error = parse_nifti(gz, path).unwrap_err();
    clean::assert_clean(&error, path);
    assert!(error.to_string().contains("invalid gzip data"), "{error}");
}
