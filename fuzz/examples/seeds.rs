//! Writes the seed corpora of the fuzz targets into `seeds/<target>/`: small shipped files
//! (the examples and `../shared/data`) and files written by medial-io's own writers.
//!
//! Run from `fuzz/`: `cargo run --example seeds` (the shipped data are looked up at
//! `../examples` and `../../shared/data`, as in a checkout with `shared/` beside it).

use std::fs;
use std::path::{Path, PathBuf};

use base64::Engine as _;
use medial_core::image::volume::Volume;
use medial_core::testing::meshes::bipyramid;
use medial_io::cmrep::template_to_polydata;
use medial_io::exr_volume::write_exr_volume;
use medial_io::mesh::{read_mesh, write_mesh};
use medial_io::nifti_volume::{write_nifti, NiftiType};
use medial_io::npy::write_npy;
use medial_io::vtk::{polydata_to_bytes, read_polydata, Encoding, Layout, WriteOptions};
use nalgebra::{Matrix4, Vector3};

/// Shipped VTK files small enough to seed with (meshes, and one real cmrep template).
const SHIPPED_VTK: [&str; 4] = [
    "../../shared/data/cmrep/shooting_test_3d_sphere_reduced.vtk",
    "../../shared/data/cmrep/shooting_test_3d_box.vtk",
    "../../shared/data/cmrep/placenta_template_anterioralign3.vtk",
    "../../shared/data/cmrep/t001_template_bcmrep.vtk",
];

/// The tetrahedron document and GLB container of the tests (`tests/common/glb.rs`).
#[allow(dead_code)]
#[path = "../../tests/common/glb.rs"]
mod glb;

fn main() {
    let root = PathBuf::from("seeds");
    vtk_seeds(&root);
    mesh_seeds(&root);
    volume_seeds(&root);
    npy_seeds(&root);
    config_seeds(&root);
}

/// Creates `seeds/<target>/` and writes `bytes` as `name` in it.
fn put(root: &Path, target: &str, name: &str, bytes: &[u8]) {
    let dir = root.join(target);
    fs::create_dir_all(&dir).expect("create the seed folder");
    fs::write(dir.join(name), bytes).expect("write a seed");
}

/// The bytes that `write` puts in a file named `name`.
fn written(name: &str, write: impl FnOnce(&Path) -> medial_io::Result<()>) -> Vec<u8> {
    let dir = std::env::temp_dir().join(format!("medial-seeds-{}", std::process::id()));
    fs::create_dir_all(&dir).expect("create a temp folder");
    let path = dir.join(name);
    write(&path).expect("write a seed file");
    let bytes = fs::read(&path).expect("read a seed file");
    fs::remove_dir_all(&dir).expect("remove the temp folder");
    bytes
}

/// ASCII: the shipped files and a written template in both layouts; binary: all of them
/// rewritten in binary, both layouts.
fn vtk_seeds(root: &Path) {
    let mut polydata = vec![(
        "bipyramid".to_string(),
        template_to_polydata(&bipyramid(0.5)),
    )];
    for file in SHIPPED_VTK {
        let path = Path::new(file);
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        put(
            root,
            "vtk_ascii",
            &format!("{stem}.vtk"),
            &fs::read(path).expect("shipped VTK"),
        );
        polydata.push((stem, read_polydata(path).expect("a valid shipped VTK")));
    }
    for (stem, data) in &polydata {
        for (layout, tag) in [(Layout::Legacy, "legacy"), (Layout::Offsets, "offsets")] {
            for (encoding, target) in [
                (Encoding::Ascii, "vtk_ascii"),
                (Encoding::Binary, "vtk_binary"),
            ] {
                let bytes = polydata_to_bytes(data, WriteOptions { encoding, layout });
                if target == "vtk_binary" || stem == "bipyramid" {
                    put(root, target, &format!("{stem}_{tag}.vtk"), &bytes);
                }
            }
        }
    }
}

/// OBJ: a written mesh and a hand-written one with every face-vertex form; glTF: the
/// tetrahedron in two nodes, its buffer as a data URI; GLB: the same in a GLB container.
fn mesh_seeds(root: &Path) {
    let sphere = read_mesh(Path::new(SHIPPED_VTK[0])).expect("a shipped mesh");
    put(
        root,
        "obj",
        "sphere.obj",
        &written("m.obj", |p| write_mesh(p, &sphere)),
    );
    let forms = "# forms\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1 1\nvn 0 0 1\nvt 0 0\n\
                 f 1//1 3//1 2//1\nf 1/1 2/1 4/1\nf -4 -1 -2\nf 2/1/1 3/1/1 4/1/1\n";
    put(root, "obj", "forms.obj", forms.as_bytes());
    let buffer = glb::tetra_buffer();
    // A mirroring scale on the second instance: the reader must flip its triangles.
    let document = |buffer: &str| glb::gltf_json(buffer, [-1.0, 1.0, 1.0], 4);
    let uri = base64::engine::general_purpose::STANDARD.encode(&buffer);
    let embedded =
        format!(r#"{{"byteLength": 72, "uri": "data:application/octet-stream;base64,{uri}"}}"#);
    put(root, "gltf", "tetra.gltf", document(&embedded).as_bytes());
    put(
        root,
        "glb",
        "tetra.glb",
        &glb::glb(&document(r#"{"byteLength": 72}"#), &buffer),
    );
}

/// Small volumes: an oblique 3×2×2 grid and a 4×3×2 mask with a reflecting axis.
fn volumes() -> [(&'static str, Volume); 2] {
    let mut oblique = Matrix4::new_rotation(Vector3::new(0.3, -0.2, 0.5));
    oblique
        .fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::new(-10.0, 4.5, 2.0));
    let mirrored = Matrix4::from_diagonal(&nalgebra::Vector4::new(0.5, -0.5, 2.0, 1.0));
    let mask = (0..24).map(|i| f64::from(u8::from(i % 3 == 0))).collect();
    [
        (
            "oblique",
            Volume::new([3, 2, 2], (0..12).map(f64::from).collect(), oblique).unwrap(),
        ),
        ("mask", Volume::new([4, 3, 2], mask, mirrored).unwrap()),
    ]
}

/// NIfTI in every written voxel type, plain and gzip; the smallest shipped segmentation
/// (gzip); EXR of the same volumes.
fn volume_seeds(root: &Path) {
    let types = [
        (NiftiType::U8, "u8"),
        (NiftiType::I16, "i16"),
        (NiftiType::F32, "f32"),
        (NiftiType::F64, "f64"),
    ];
    for (name, volume) in volumes() {
        for (datatype, tag) in types {
            for (suffix, target) in [("nii", "nifti"), ("nii.gz", "nifti_gz")] {
                let file = format!("{name}_{tag}.{suffix}");
                put(
                    root,
                    target,
                    &file,
                    &written(&file, |p| write_nifti(p, &volume, datatype)),
                );
            }
        }
        let file = format!("{name}.exr");
        put(
            root,
            "exr",
            &file,
            &written(&file, |p| write_exr_volume(p, &volume)),
        );
    }
    let shipped = fs::read("../examples/t001-bent/target.nii.gz").expect("shipped image");
    put(root, "nifti_gz", "t001-bent.nii.gz", &shipped);
}

/// `.npy` of several shapes (0-D, empty, 1-D, 3-D).
fn npy_seeds(root: &Path) {
    let arrays: [(&str, &[usize], Vec<f64>); 4] = [
        ("scalar", &[], vec![1.5]),
        ("empty", &[0, 3], vec![]),
        ("vector", &[5], vec![0.0, -1.0, 2.5, 1e300, -0.0]),
        ("momenta", &[2, 3, 3], (0..18).map(f64::from).collect()),
    ];
    for (name, shape, data) in arrays {
        let file = format!("{name}.npy");
        put(
            root,
            "npy",
            &file,
            &written(&file, |p| write_npy(p, shape, &data)),
        );
    }
}

/// The shipped configs.
fn config_seeds(root: &Path) {
    for case in ["cup", "hippocampus", "t001", "toy"] {
        let text = fs::read(format!("../examples/{case}/fit.toml")).expect("shipped config");
        put(root, "config", &format!("{case}.toml"), &text);
    }
    let text = fs::read("../examples/t001-bent/fit_boundary.toml").expect("shipped config");
    put(root, "config", "t001-bent_boundary.toml", &text);
}
