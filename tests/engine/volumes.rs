//! NIfTI and OpenEXR volumes: round trips of every datatype, hand-built headers (sform only,
//! qform only, neither, scaling, 4-D) read to the right world coordinates, refusals.

use std::io::Write;
use std::path::{Path, PathBuf};

use flate2::write::GzEncoder;
use medial::image::volume::Volume;
use medial::io::error::Geometry;
use medial::io::exr_volume::{read_exr_volume, write_exr_volume, AFFINE_ATTRIBUTE, DIMS_ATTRIBUTE};
use medial::io::nifti_volume::{read_nifti, write_nifti, NiftiType};
use medial::io::volume::read_volume;
use medial::io::Error;
use medial::Vec3;

use crate::common::clean;
use clean::assert_clean;
use nalgebra::{Matrix3, Matrix4, Rotation3, Unit, Vector4};

/// An oblique grid: rotation × anisotropic spacing, with an offset.
fn oblique(left_handed: bool) -> Matrix4<f64> {
    let r = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::new(1.0, 2.0, -0.5)), 0.7);
    let flip = if left_handed { -1.0 } else { 1.0 };
    let a = r.matrix() * Matrix3::from_diagonal(&Vec3::new(0.9, 1.2, 2.5 * flip));
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vec3::new(-91.5, 12.25, 40.0));
    m
}

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples");

fn volume(values: impl Fn(usize) -> f64, affine: Matrix4<f64>) -> Volume {
    let dims = [5, 4, 3];
    Volume::new(dims, (0..60).map(values).collect(), affine).unwrap()
}

fn world(v: &Volume, i: f64, j: f64, k: f64) -> Vec3 {
    (v.voxel_to_world() * Vector4::new(i, j, k, 1.0)).xyz()
}

fn assert_affine_close(a: &Matrix4<f64>, b: &Matrix4<f64>, tolerance: f64) {
    assert!((a - b).amax() <= tolerance, "affine maps differ:{a}{b}");
}

#[test]
fn nifti_round_trips_every_datatype() {
    let dir = tempfile::tempdir().unwrap();
    type Values = fn(usize) -> f64;
    let cases: [(NiftiType, Values, f64); 4] = [
        (NiftiType::U8, |n| (n * 4 % 256) as f64, 0.0),
        (NiftiType::I16, |n| n as f64 * 517.0 - 15000.0, 0.0),
        (NiftiType::F32, |n| (n as f64 * 0.37).sin() * 1e3, 1e-4),
        (NiftiType::F64, |n| (n as f64 * 0.37).sin() / 3.0, 0.0),
    ];
    for (datatype, values, tolerance) in cases {
        for (name, left) in [("a.nii", false), ("b.nii.gz", true)] {
            let original = volume(values, oblique(left));
            let path = dir.path().join(format!("{datatype:?}-{name}"));
            write_nifti(&path, &original, datatype).unwrap();
            let back = read_nifti(&path).unwrap();
            assert_eq!(back.dims(), original.dims());
            for (a, b) in back.data().iter().zip(original.data()) {
                assert!(
                    (a - b).abs() <= tolerance * b.abs().max(1.0),
                    "{datatype:?}: {a} vs {b}"
                );
            }
            // Header fields are f32: about 7 significant digits of the 100 mm offsets.
            assert_affine_close(back.voxel_to_world(), original.voxel_to_world(), 2e-5);
        }
    }
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 8, "no temporary files left: {names:?}");
}

/// The written qform (read with the sform disabled) is the same map as the sform, also for a
/// left-handed grid; a sheared grid gets no qform.
#[test]
fn written_qform_matches_the_sform() {
    let dir = tempfile::tempdir().unwrap();
    for left in [false, true] {
        let original = volume(|n| n as f64, oblique(left));
        let path = dir.path().join("q.nii");
        write_nifti(&path, &original, NiftiType::U8).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        assert_eq!(
            i16::from_le_bytes([bytes[252], bytes[253]]),
            1,
            "qform_code"
        );
        assert_eq!(
            i16::from_le_bytes([bytes[254], bytes[255]]),
            1,
            "sform_code"
        );
        bytes[254..256].copy_from_slice(&0i16.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let from_qform = read_nifti(&path).unwrap();
        assert_affine_close(from_qform.voxel_to_world(), original.voxel_to_world(), 2e-5);
    }
    let mut sheared = oblique(false);
    sheared[(0, 1)] += 0.3;
    let path = dir.path().join("s.nii");
    write_nifti(&path, &volume(|n| n as f64, sheared), NiftiType::F32).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(
        i16::from_le_bytes([bytes[252], bytes[253]]),
        0,
        "no qform for a sheared grid"
    );
    assert_affine_close(read_nifti(&path).unwrap().voxel_to_world(), &sheared, 2e-5);
}

/// The fields of a hand-built NIfTI-1 header (little-endian, single file).
struct Header {
    dim: [i16; 8],
    datatype: i16,
    bitpix: i16,
    pixdim: [f32; 8],
    scl: (f32, f32),
    qform_code: i16,
    sform_code: i16,
    quatern: [f32; 6],
    srow: [[f32; 4]; 3],
    vox_offset: f32,
}

impl Header {
    fn new(dims: [i16; 3]) -> Self {
        Self {
            dim: [3, dims[0], dims[1], dims[2], 1, 1, 1, 1],
            datatype: 2,
            bitpix: 8,
            pixdim: [1.0; 8],
            scl: (0.0, 0.0),
            qform_code: 0,
            sform_code: 0,
            quatern: [0.0; 6],
            srow: [[0.0; 4]; 3],
            vox_offset: 352.0,
        }
    }

    /// The 348-byte header, the 4-byte empty extension and `data`, at the NIfTI-1 offsets
    /// (`data` follows the extension, whatever `vox_offset` says).
    fn file(&self, data: &[u8]) -> Vec<u8> {
        let mut b = vec![0u8; 352];
        let put = |b: &mut Vec<u8>, at: usize, bytes: &[u8]| {
            b[at..at + bytes.len()].copy_from_slice(bytes)
        };
        put(&mut b, 0, &348i32.to_le_bytes());
        for (n, d) in self.dim.iter().enumerate() {
            put(&mut b, 40 + 2 * n, &d.to_le_bytes());
        }
        put(&mut b, 70, &self.datatype.to_le_bytes());
        put(&mut b, 72, &self.bitpix.to_le_bytes());
        for (n, p) in self.pixdim.iter().enumerate() {
            put(&mut b, 76 + 4 * n, &p.to_le_bytes());
        }
        put(&mut b, 108, &self.vox_offset.to_le_bytes());
        put(&mut b, 112, &self.scl.0.to_le_bytes());
        put(&mut b, 116, &self.scl.1.to_le_bytes());
        put(&mut b, 123, &[2]); // xyzt_units: mm
        put(&mut b, 252, &self.qform_code.to_le_bytes());
        put(&mut b, 254, &self.sform_code.to_le_bytes());
        for (n, q) in self.quatern.iter().enumerate() {
            put(&mut b, 256 + 4 * n, &q.to_le_bytes());
        }
        for (r, row) in self.srow.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                put(&mut b, 280 + 16 * r + 4 * c, &v.to_le_bytes());
            }
        }
        put(&mut b, 344, b"n+1\0");
        b.extend_from_slice(data);
        b
    }

    fn write(&self, dir: &Path, name: &str, data: &[u8]) -> PathBuf {
        let path = dir.join(name);
        let bytes = self.file(data);
        if name.ends_with(".gz") {
            let mut gz = GzEncoder::new(
                std::fs::File::create(&path).unwrap(),
                flate2::Compression::default(),
            );
            gz.write_all(&bytes).unwrap();
            gz.finish().unwrap();
        } else {
            std::fs::write(&path, bytes).unwrap();
        }
        path
    }
}

#[test]
fn sform_only_header_gives_its_rows() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = Header::new([3, 4, 5]);
    h.sform_code = 2;
    h.srow = [
        [0.0, -1.5, 0.2, 10.0],
        [2.0, 0.0, 0.0, -20.0],
        [0.1, 0.3, 3.0, 5.5],
    ];
    let path = h.write(dir.path(), "sform.nii.gz", &[0u8; 60]);
    let v = read_nifti(&path).unwrap();
    assert_eq!(v.dims(), [3, 4, 5]);
    // Voxel (2, 3, 4) by hand: x = −1.5·3 + 0.2·4 + 10 = 6.3, y = 2·2 − 20 = −16,
    // z = 0.1·2 + 0.3·3 + 3·4 + 5.5 = 18.6.
    assert!((world(&v, 2.0, 3.0, 4.0) - Vec3::new(6.3, -16.0, 18.6)).norm() < 1e-5);
}

#[test]
fn qform_only_header_gives_the_quaternion_map() {
    let dir = tempfile::tempdir().unwrap();
    // 90° about z: (a, b, c, d) = (cos 45°, 0, 0, sin 45°); qfac = −1 flips the k axis.
    let mut h = Header::new([3, 4, 5]);
    h.qform_code = 1;
    h.pixdim[..4].copy_from_slice(&[-1.0, 2.0, 3.0, 4.0]);
    h.quatern = [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2, 10.0, 20.0, 30.0];
    let v = read_nifti(&h.write(dir.path(), "q90.nii", &[0u8; 60])).unwrap();
    // R = [[0, −1, 0], [1, 0, 0], [0, 0, 1]]; columns 2·(0, 1, 0), 3·(−1, 0, 0), −4·(0, 0, 1):
    // voxel (1, 2, 3) → (10 − 6, 20 + 2, 30 − 12) = (4, 22, 18).
    assert!(
        (world(&v, 1.0, 2.0, 3.0) - Vec3::new(4.0, 22.0, 18.0)).norm() < 1e-5,
        "{}",
        world(&v, 1.0, 2.0, 3.0)
    );

    // An oblique rotation, checked against Rodrigues' formula for the same axis and angle.
    let (axis, angle) = (Vec3::new(0.3, -0.5, 0.8).normalize(), 0.9f64);
    let bcd = axis * (angle / 2.0).sin();
    h.pixdim[..4].copy_from_slice(&[1.0, 0.7, 1.1, 1.9]);
    h.quatern = [bcd.x as f32, bcd.y as f32, bcd.z as f32, -5.0, 7.5, 1.25];
    let v = read_nifti(&h.write(dir.path(), "oblique.nii", &[0u8; 60])).unwrap();
    let k = Matrix3::new(
        0.0, -axis.z, axis.y, axis.z, 0.0, -axis.x, -axis.y, axis.x, 0.0,
    );
    let r = Matrix3::identity() * angle.cos()
        + k * angle.sin()
        + axis * axis.transpose() * (1.0 - angle.cos());
    let expected = Vec3::new(-5.0, 7.5, 1.25) + r * Vec3::new(0.7 * 2.0, 1.1 * 1.0, 1.9 * 4.0);
    assert!((world(&v, 2.0, 1.0, 4.0) - expected).norm() < 1e-5);
}

#[test]
fn sform_wins_over_qform_and_spacing_is_the_fallback() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = Header::new([2, 2, 2]);
    h.pixdim[..4].copy_from_slice(&[1.0, 0.5, 1.0, 2.0]);
    let v = read_nifti(&h.write(dir.path(), "plain.nii", &[0u8; 8])).unwrap();
    assert!((world(&v, 1.0, 1.0, 1.0) - Vec3::new(0.5, 1.0, 2.0)).norm() < 1e-12);
    h.qform_code = 1;
    h.quatern = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    h.sform_code = 1;
    h.srow = [
        [3.0, 0.0, 0.0, 0.0],
        [0.0, 3.0, 0.0, 0.0],
        [0.0, 0.0, 3.0, 0.0],
    ];
    let v = read_nifti(&h.write(dir.path(), "both.nii", &[0u8; 8])).unwrap();
    assert!((world(&v, 1.0, 1.0, 1.0) - Vec3::repeat(3.0)).norm() < 1e-12);
}

#[test]
fn datatypes_scaling_and_four_dimensions() {
    let dir = tempfile::tempdir().unwrap();
    // int16 with scl_slope 2, scl_inter −1, stored as a 4-D volume with one time point.
    let mut h = Header::new([2, 1, 1]);
    h.dim = [4, 2, 1, 1, 1, 1, 1, 1];
    (h.datatype, h.bitpix, h.scl) = (4, 16, (2.0, -1.0));
    let data: Vec<u8> = [-3i16, 7].iter().flat_map(|v| v.to_le_bytes()).collect();
    let v = read_nifti(&h.write(dir.path(), "scaled.nii", &data)).unwrap();
    assert_eq!(v.data(), &[-7.0, 13.0]);
    // uint16 and float64.
    let mut h = Header::new([2, 1, 1]);
    (h.datatype, h.bitpix) = (512, 16);
    let v = read_nifti(&h.write(dir.path(), "u16.nii", &[0xff, 0xff, 1, 0])).unwrap();
    assert_eq!(v.data(), &[65535.0, 1.0]);
    (h.datatype, h.bitpix) = (64, 64);
    let data: Vec<u8> = [0.25f64, -1e10]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    assert_eq!(
        read_nifti(&h.write(dir.path(), "f64.nii", &data))
            .unwrap()
            .data(),
        &[0.25, -1e10]
    );
    // Two time points: refused.
    let mut h = Header::new([2, 1, 1]);
    h.dim = [4, 2, 1, 1, 2, 1, 1, 1];
    let err = read_nifti(&h.write(dir.path(), "t2.nii", &[0; 4])).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Geometry {
                problem: Geometry::ExtraDimension { axis: 4, size: 2 },
                ..
            }
        ) && err.to_string().contains("dimension 4 has size 2"),
        "{err}"
    );
    // Complex voxels: refused.
    let mut h = Header::new([1, 1, 1]);
    (h.datatype, h.bitpix) = (32, 64);
    let err = read_nifti(&h.write(dir.path(), "complex.nii", &[0; 8])).unwrap_err();
    assert!(err.to_string().contains("unsupported voxel type"), "{err}");
}

#[test]
fn degenerate_or_invalid_content_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = Header::new([2, 2, 2]);
    h.sform_code = 1;
    h.srow = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    let err = read_nifti(&h.write(dir.path(), "flat.nii", &[0; 8])).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Geometry {
                problem: Geometry::VoxelSize { axis: 2, .. },
                ..
            }
        ),
        "{err}"
    );
    let mut h = Header::new([1, 1, 1]);
    (h.datatype, h.bitpix) = (16, 32);
    let err = read_nifti(&h.write(dir.path(), "nan.nii", &f32::NAN.to_le_bytes())).unwrap_err();
    assert!(matches!(err, Error::Model { .. }), "{err}");
    let missing = read_nifti(&dir.path().join("missing.nii")).unwrap_err();
    assert!(matches!(missing, Error::Io { .. }), "{missing}");
    std::fs::write(dir.path().join("junk.nii"), b"not a nifti file").unwrap();
    assert!(read_nifti(&dir.path().join("junk.nii")).is_err());
}

#[test]
fn writing_refuses_unrepresentable_values_and_names() {
    let dir = tempfile::tempdir().unwrap();
    let v = volume(|n| n as f64 - 1.0, oblique(false));
    let err = write_nifti(&dir.path().join("u8.nii"), &v, NiftiType::U8).unwrap_err();
    assert!(err.to_string().contains("voxel 0 has value -1"), "{err}");
    let half = volume(|n| n as f64 + 0.5, oblique(false));
    assert!(write_nifti(&dir.path().join("i16.nii"), &half, NiftiType::I16).is_err());
    assert!(write_nifti(&dir.path().join("volume.img"), &v, NiftiType::F32).is_err());
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(names.is_empty(), "nothing written on refusal");
}

#[test]
fn exr_round_trip_keeps_values_and_the_exact_map() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("volume.exr");
    let original = volume(|n| ((n * 7) % 11) as f64 * 0.25 - 1.0, oblique(true));
    write_exr_volume(&path, &original).unwrap();
    let back = read_exr_volume(&path).unwrap();
    assert_eq!(back.dims(), original.dims());
    assert_eq!(
        back.data(),
        original.data(),
        "quarter-integers are exact in f32"
    );
    assert_eq!(
        back.voxel_to_world(),
        original.voxel_to_world(),
        "the map round-trips exactly"
    );
    // The convention: a 5 × (4·3) single-channel image with the two attributes.
    let image = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
    let layer = &image.layer_data;
    assert_eq!((layer.size.width(), layer.size.height()), (5, 12));
    assert_eq!(layer.channel_data.list.len(), 1);
    assert_eq!(layer.channel_data.list[0].name.to_string(), "Y");
    let voxel = |i: usize, j: usize, k: usize| {
        layer.channel_data.list[0]
            .sample_data
            .value_by_flat_index(i + 5 * (j + 4 * k))
            .to_f32()
    };
    assert_eq!(f64::from(voxel(3, 2, 1)), original.data()[3 + 5 * (2 + 4)]);
    for name in [DIMS_ATTRIBUTE, AFFINE_ATTRIBUTE] {
        assert!(
            layer
                .attributes
                .other
                .contains_key(&exr::prelude::Text::from(name)),
            "{name}"
        );
    }
}

#[test]
fn exr_without_attributes_is_one_slice() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.exr");
    exr::prelude::write_rgb_file(&path, 3, 2, |x, y| (x as f32, y as f32, 0.5)).unwrap();
    let err = read_exr_volume(&path).unwrap_err();
    assert!(err.to_string().contains("none named Y"), "{err}");
    let channel = exr::prelude::AnyChannel::new(
        "Y",
        exr::prelude::FlatSamples::F32(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]),
    );
    let channels = exr::prelude::AnyChannels::sort(exr::prelude::SmallVec::from_vec(vec![channel]));
    let image = exr::prelude::Image::from_channels((3, 2), channels);
    exr::prelude::WritableImage::write(&image)
        .to_file(&path)
        .unwrap();
    let v = read_exr_volume(&path).unwrap();
    assert_eq!(v.dims(), [3, 2, 1]);
    assert_eq!(v.data(), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert_eq!(v.voxel_to_world(), &Matrix4::identity());
}

#[test]
fn read_volume_chooses_the_format_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let original = volume(|n| n as f64, oblique(false));
    for name in ["v.nii", "v.nii.gz"] {
        let path = dir.path().join(name);
        write_nifti(&path, &original, NiftiType::U8).unwrap();
        let gzip = std::fs::read(&path).unwrap().starts_with(&[0x1f, 0x8b]);
        assert_eq!(gzip, name.ends_with(".gz"), "{name}");
        let back = read_volume(&path).unwrap();
        assert_eq!(back.data(), original.data(), "{name}");
        let upper = dir.path().join(format!("upper-{}", name.to_uppercase()));
        std::fs::copy(&path, &upper).unwrap();
        assert_eq!(
            read_volume(&upper).unwrap().data(),
            original.data(),
            "{name}"
        );
    }
    let path = dir.path().join("v.exr");
    write_exr_volume(&path, &original).unwrap();
    assert_eq!(read_volume(&path).unwrap().data(), original.data());
    let err = read_volume(&dir.path().join("v.img")).unwrap_err();
    assert!(matches!(err, Error::Format { .. }), "{err:?}");
    assert!(
        err.to_string()
            .ends_with("v.img: unknown image format: expected .nii, .nii.gz or .exr"),
        "{err}"
    );
}

/// The shipped targets hold the same map as sform and as qform (quaternion): read with the
/// sform disabled, the quaternion gives the sform's map to the precision of the f32 fields.
#[test]
fn shipped_targets_read_the_same_from_qform_and_sform() {
    let dir = tempfile::tempdir().unwrap();
    for case in ["toy", "cup", "t001-bent"] {
        let path = Path::new(EXAMPLES).join(case).join("target.nii.gz");
        let from_sform = read_nifti(&path).unwrap();
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(
            &mut flate2::read::GzDecoder::new(std::fs::File::open(&path).unwrap()),
            &mut bytes,
        )
        .unwrap();
        assert_eq!(
            i16::from_le_bytes([bytes[252], bytes[253]]),
            1,
            "{case}: qform_code"
        );
        bytes[254..256].copy_from_slice(&0i16.to_le_bytes());
        let copy = dir.path().join(format!("{case}.nii"));
        std::fs::write(&copy, &bytes).unwrap();
        let from_qform = read_nifti(&copy).unwrap();
        assert_eq!(from_qform.data(), from_sform.data());
        let scale = from_sform.voxel_to_world().abs().max();
        assert_affine_close(
            from_qform.voxel_to_world(),
            from_sform.voxel_to_world(),
            1e-6 * scale,
        );
    }
}

/// A quaternion with `b² + c² + d² = 1` is a 180° rotation (`a = 0`).
#[test]
fn half_turn_quaternion() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = Header::new([2, 2, 2]);
    h.qform_code = 1;
    h.quatern = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let v = read_nifti(&h.write(dir.path(), "half.nii", &[0u8; 8])).unwrap();
    let expected = Matrix4::from_diagonal(&Vector4::new(1.0, -1.0, -1.0, 1.0));
    assert_affine_close(v.voxel_to_world(), &expected, 1e-15);
}

/// The geometry problem of reading `h` with 8 voxels of data, checked to be a clean error.
fn geometry_problem(dir: &Path, name: &str, h: &Header) -> Geometry {
    let path = h.write(dir, name, &[0u8; 8]);
    match read_nifti(&path) {
        Err(error @ Error::Geometry { .. }) => {
            assert_clean(&error, &path);
            let Error::Geometry { problem, .. } = error else {
                unreachable!()
            };
            problem
        }
        other => panic!("{name}: expected a geometry error, got {other:?}"),
    }
}

/// A 2×2×2 header with the sform `diag(x, y, z)`.
fn diagonal_sform(x: f32, y: f32, z: f32) -> Header {
    let mut h = Header::new([2, 2, 2]);
    h.sform_code = 1;
    h.srow = [[x, 0.0, 0.0, 0.0], [0.0, y, 0.0, 0.0], [0.0, 0.0, z, 0.0]];
    h
}

/// A `vox_offset` beyond the end of the file was ignored (the data were read after the
/// header); the data now start at `vox_offset`, which must lie in the file.
#[test]
fn vox_offset_places_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = Header::new([2, 1, 1]);
    h.vox_offset = 356.0;
    let v = read_nifti(&h.write(dir.path(), "padded.nii", &[9, 9, 9, 9, 1, 2])).unwrap();
    assert_eq!(v.data(), &[1.0, 2.0], "the data start at vox_offset");
    for offset in [1000.0, -16.0, f32::NAN] {
        h.vox_offset = offset;
        let path = h.write(dir.path(), "offset.nii", &[1, 2]);
        let err = read_nifti(&path).unwrap_err();
        assert_clean(&err, &path);
        assert!(
            matches!(
                err,
                Error::DataOffset {
                    field: "vox_offset",
                    file_len: 354,
                    ..
                }
            ),
            "{offset}: {err:?}"
        );
    }
    h.vox_offset = 352.0;
    let path = h.write(dir.path(), "short.nii", &[1]);
    let err = read_nifti(&path).unwrap_err();
    assert_clean(&err, &path);
    assert!(
        matches!(
            err,
            Error::Truncated {
                needed: 2,
                available: 1,
                ..
            }
        ),
        "{err:?}"
    );
    let path = dir.path().join("header.nii");
    std::fs::write(&path, &h.file(&[])[..200]).unwrap();
    let err = read_nifti(&path).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Truncated {
                needed: 348,
                available: 200,
                ..
            }
        ),
        "{err:?}"
    );
}

/// Spacings and voxel-to-world maps that can only give garbage world coordinates.
#[test]
fn garbage_geometry_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // pixdim 0 with no qform or sform (it used to be taken as 1 mm).
    let mut h = Header::new([2, 2, 2]);
    h.pixdim[2] = 0.0;
    let problem = geometry_problem(d, "zero.nii", &h);
    assert_eq!(
        problem,
        Geometry::Spacing {
            axis: 2,
            value: 0.0
        }
    );
    // Negative or non-finite pixdim, with no xform or with a qform.
    h.pixdim[2] = 1.0;
    h.pixdim[1] = -0.5;
    let problem = geometry_problem(d, "negative.nii", &h);
    assert_eq!(
        problem,
        Geometry::Spacing {
            axis: 1,
            value: -0.5
        }
    );
    h.pixdim[1] = 1.0;
    h.pixdim[3] = f32::INFINITY;
    h.qform_code = 1;
    let problem = geometry_problem(d, "infinite.nii", &h);
    assert_eq!(
        problem,
        Geometry::Spacing {
            axis: 3,
            value: f32::INFINITY
        }
    );
    // The sform wins: the spacings are not used.
    h.sform_code = 1;
    h.srow = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ];
    assert!(read_nifti(&h.write(d, "sform.nii", &[0u8; 8])).is_ok());
    // Absurd voxel sizes.
    for (name, h, axis) in [
        ("tiny.nii", diagonal_sform(1e-39, 1.0, 1.0), 1),
        ("negative-tiny.nii", diagonal_sform(1.0, -1e-8, 1.0), 2),
        ("huge.nii", diagonal_sform(1.0, 1.0, 2e4), 3),
    ] {
        match geometry_problem(d, name, &h) {
            Geometry::VoxelSize { axis: a, .. } => assert_eq!(a, axis, "{name}"),
            other => panic!("{name}: {other:?}"),
        }
    }
    // Coplanar voxel axes, and a NaN entry.
    let mut h = diagonal_sform(1.0, 1.0, 1.0);
    h.srow[0][1] = 1.0;
    h.srow[1][1] = 0.0;
    assert!(matches!(
        geometry_problem(d, "singular.nii", &h),
        Geometry::Singular { sine } if sine < 1e-6
    ));
    let mut h = diagonal_sform(1.0, 1.0, 1.0);
    h.srow[2][3] = f32::NAN;
    assert!(matches!(
        geometry_problem(d, "nan.nii", &h),
        Geometry::NonFiniteMap {
            row: 3,
            column: 4,
            ..
        }
    ));
    // The same grid check applies to OpenEXR volumes.
    let mut tiny = Matrix4::identity();
    tiny[(0, 0)] = 1e-39;
    let path = d.join("tiny.exr");
    write_exr_volume(&path, &Volume::new([1, 1, 1], vec![0.0], tiny).unwrap()).unwrap();
    let err = read_exr_volume(&path).unwrap_err();
    assert_clean(&err, &path);
    assert!(
        matches!(
            err,
            Error::Geometry {
                problem: Geometry::VoxelSize { axis: 1, .. },
                ..
            }
        ),
        "{err:?}"
    );
}

/// Images that are not 3-D, or have an empty dimension, are refused; 1×1×1 is a legal file.
#[test]
fn images_that_are_not_volumes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut h = Header::new([2, 2, 2]);
    h.dim = [2, 4, 2, 1, 1, 1, 1, 1];
    assert_eq!(
        geometry_problem(d, "2d.nii", &h),
        Geometry::TooFewDimensions { ndim: 2 }
    );
    h.dim = [4, 2, 2, 1, 2, 1, 1, 1];
    assert_eq!(
        geometry_problem(d, "4d.nii", &h),
        Geometry::ExtraDimension { axis: 4, size: 2 }
    );
    h.dim = [3, 8, 0, 1, 1, 1, 1, 1];
    assert_eq!(
        geometry_problem(d, "empty.nii", &h),
        Geometry::EmptyDimension { axis: 2, size: 0 }
    );
    h.dim = [3, -8, 1, 1, 1, 1, 1, 1];
    assert_eq!(
        geometry_problem(d, "negative.nii", &h),
        Geometry::EmptyDimension { axis: 1, size: -8 }
    );
    let one = Header::new([1, 1, 1]);
    let v = read_nifti(&one.write(d, "one.nii", &[7])).unwrap();
    assert_eq!((v.dims(), v.data()), ([1, 1, 1], &[7.0][..]));
}

/// `v = (i − 5.3)/2` along the first axis of an oblique 12×5×4 grid: a signed level set whose
/// zero crossing lies between voxel centres.
fn ramp() -> Volume {
    let dims = [12, 5, 4];
    let data = (0..240).map(|n| ((n % 12) as f64 - 5.3) / 2.0).collect();
    Volume::new(dims, data, oblique(false)).unwrap()
}

#[test]
fn a_refined_signed_image_follows_its_zero_crossing_between_voxel_centres() {
    let coarse = ramp();
    assert!(coarse.is_graded_signed());
    let fine = coarse.refined(3, 1).unwrap();
    // Positive voxels i = 6 … 11, one voxel of margin: i = 5 … 11; all of j and k.
    assert_eq!(fine.dims(), [21, 15, 12]);
    assert_eq!(coarse.refined_dims(3, 1), fine.dims());
    let [nx, ny, _] = fine.dims();
    for (n, &v) in fine.data().iter().enumerate() {
        let index = [n % nx, (n / nx) % ny, n / (nx * ny)];
        // The fine centre in coarse indices: lo + (j − 1)/3 along each axis.
        let [i, j, k] = index.map(|i| i as f64);
        let at = coarse.world_to_voxel() * world(&fine, i, j, k).push(1.0);
        let expected = [5.0, 0.0, 0.0]
            .iter()
            .zip(index)
            .map(|(lo, j)| lo + (j as f64 - 1.0) / 3.0);
        for (a, e) in at.iter().zip(expected) {
            assert!((a - e).abs() < 1e-9, "fine voxel {index:?}: {a} vs {e}");
        }
        // Inside the grid the interpolant of a linear ramp is the ramp.
        if (0.0..=4.0).contains(&at.y) && (0.0..=3.0).contains(&at.z) && at.x <= 11.0 {
            assert!((v - (at.x - 5.3) / 2.0).abs() < 1e-12, "{index:?}: {v}");
        }
    }
    // The foreground's extent along the ramp: the staircase at 6 voxels becomes the crossing
    // at 5.3 to within a third of a voxel.
    let inside = |v: &Volume| v.data().iter().filter(|&&v| v > 0.0).count();
    assert_eq!(inside(&coarse), 6 * 5 * 4);
    let fine_extent = inside(&fine) as f64 / (27 * 5 * 4) as f64;
    assert!(
        (fine_extent - (11.5 - 5.3)).abs() <= 1.0 / 3.0,
        "{fine_extent}"
    );
}

#[test]
fn only_graded_signed_images_are_refined_meaningfully() {
    let binary = volume(|n| (n % 2) as f64, oblique(false));
    let two_signs = volume(|n| if n % 2 == 0 { -1.0 } else { 1.0 }, oblique(false));
    let positive = volume(|n| n as f64 * 0.1, oblique(false));
    for v in [&binary, &two_signs, &positive] {
        assert!(!v.is_graded_signed());
    }
    assert!(ramp().is_graded_signed());
    assert!(ramp().refined(0, 1).is_err());
    let empty = volume(|_| -1.0, oblique(false));
    assert_eq!(empty.refined(3, 1).unwrap(), empty);
}
