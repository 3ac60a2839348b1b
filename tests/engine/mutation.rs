//! Bounded mutation tests: bytes of small valid files are overwritten, flipped, inserted,
//! removed or cut, and every reader must return a value or a clean error (one line naming the
//! file), never panic. Each reader gets [`CASES`] mutated files (all of them together take
//! about 20 s on 2 cores). The cargo-fuzz targets in `fuzz/` go much further, outside CI.

use std::fmt::{Debug, Display};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use medial::image::volume::Volume;
use medial::io::cmrep::{read_template, template_to_polydata};
use medial::io::exr_volume::{read_exr_volume, write_exr_volume};
use medial::io::mesh::read_mesh;
use medial::io::nifti_volume::{read_nifti, write_nifti, NiftiType};
use medial::io::npy::{read_npy, write_npy};
use medial::io::vtk::{
    polydata_to_bytes, read_polydata, ArrayKind, DataArray, Encoding, Layout, PolyData, ValueType,
    WriteOptions,
};
use medial_cli::config::Config;
use nalgebra::Matrix4;
use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{TestCaseError, TestRunner};

use crate::common::clean;
use crate::common::glb;

/// Mutated files per reader.
const CASES: u32 = 3000;

/// One change to the bytes of a file; positions are taken modulo the current length.
#[derive(Clone, Debug)]
enum Mutation {
    /// Overwrite a byte.
    Set(Index, u8),
    /// Flip one bit of a byte.
    Flip(Index, u8),
    /// Insert a byte.
    Insert(Index, u8),
    /// Remove a byte.
    Remove(Index),
    /// Cut the file.
    Truncate(Index),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::Set(i, b)),
        4 => (any::<Index>(), 0u8..8).prop_map(|(i, bit)| Mutation::Flip(i, bit)),
        1 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::Insert(i, b)),
        1 => any::<Index>().prop_map(Mutation::Remove),
        1 => any::<Index>().prop_map(Mutation::Truncate),
    ]
}

fn mutations() -> impl Strategy<Value = Vec<Mutation>> {
    proptest::collection::vec(mutation(), 1..=3)
}

fn mutate(valid: &[u8], mutations: &[Mutation]) -> Vec<u8> {
    let mut bytes = valid.to_vec();
    for m in mutations {
        let len = bytes.len();
        match *m {
            _ if len == 0 => {}
            Mutation::Set(ref i, b) => bytes[i.index(len)] = b,
            Mutation::Flip(ref i, bit) => bytes[i.index(len)] ^= 1 << bit,
            Mutation::Insert(ref i, b) => bytes.insert(i.index(len + 1), b),
            Mutation::Remove(ref i) => {
                bytes.remove(i.index(len));
            }
            Mutation::Truncate(ref i) => bytes.truncate(i.index(len)),
        }
    }
    bytes
}

/// Reads [`CASES`] mutations of `valid`, each written to a file named `name`, with `read`: a
/// panic fails the test (with the mutations and the panic message), an error must be clean.
fn never_panics<T: Debug, E: Display>(
    name: &str,
    valid: &[u8],
    read: impl Fn(&Path) -> Result<T, E>,
) {
    never_panics_beside(name, valid, &[], read);
}

/// [`never_panics`], with the files `beside` (name, bytes), unchanged, in the same folder.
fn never_panics_beside<T: Debug, E: Display>(
    name: &str,
    valid: &[u8],
    beside: &[(&str, &[u8])],
    read: impl Fn(&Path) -> Result<T, E>,
) {
    let dir = tempfile::tempdir().expect("temp dir");
    for (other, bytes) in beside {
        std::fs::write(dir.path().join(other), bytes).expect("write a file beside");
    }
    let path = dir.path().join(name);
    let config = ProptestConfig {
        cases: CASES,
        failure_persistence: None,
        ..ProptestConfig::default()
    };
    let result = TestRunner::new(config).run(&mutations(), |mutations| {
        std::fs::write(&path, mutate(valid, &mutations)).expect("write the mutated file");
        match catch_unwind(AssertUnwindSafe(|| read(&path))) {
            Ok(Ok(_)) => Ok(()),
            Ok(Err(error)) => {
                clean::assert_clean(&error, &path);
                Ok(())
            }
            Err(panic) => {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Err(TestCaseError::fail(format!(
                    "{name} panicked on {mutations:?}: {message}"
                )))
            }
        }
    });
    if let Err(failure) = result {
        panic!("{failure}");
    }
}

/// An ASCII 4.2 file with every kind of section the reader skips or keeps.
const VTK_ASCII: &str = "# vtk DataFile Version 4.2
mutation test
ASCII
DATASET POLYDATA
FIELD FieldData 1
TimeValue 1 1 double
0.5
POINTS 4 float
0 0 0 1 0 0 0 1 0
0 0 1
VERTICES 1 2
1 3
LINES 1 3
2 0 3
POLYGONS 2 8
3 0 2 1
3 0 1 3
POINT_DATA 4
SCALARS Label int 1
LOOKUP_TABLE default
1 2 3 4
METADATA
INFORMATION 0

NORMALS Normals float
0 0 1 0 0 1 0 0 1 0 0 1
COLOR_SCALARS Colour 3
1 0 0 0 1 0 0 0 1 0.5 0.5 0.5
FIELD FieldData 1
Radius%20mm 1 4 double
0.25 0.5 0.75 1
CELL_DATA 4
TEXTURE_COORDINATES uv 2 float
0 0 1 0 0 1 1 1
LOOKUP_TABLE table 1
0 0 0 1
";

/// Polydata with point and cell arrays of each value type, for the binary encoding.
fn polydata() -> PolyData {
    let array = |name: &str, components, values: Vec<f64>, kind, value_type| DataArray {
        name: name.into(),
        components,
        values,
        kind,
        value_type,
    };
    let mut data = PolyData::from_triangles(
        &glb::TETRA.map(|p| p.map(f64::from).into()),
        &[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    );
    data.lines = vec![vec![0, 1, 2]];
    data.point_data = vec![
        array(
            "Index",
            1,
            vec![0.0, 1.0, 2.0, 3.0],
            ArrayKind::Scalars,
            ValueType::Int,
        ),
        array(
            "Normals",
            3,
            vec![0.5; 12],
            ArrayKind::Normals,
            ValueType::Float,
        ),
        array(
            "Weight",
            2,
            vec![0.25; 8],
            ArrayKind::Field,
            ValueType::Double,
        ),
    ];
    data.cell_data = vec![array(
        "Area",
        1,
        vec![1.0, 2.0, 3.0, 4.0, 5.0],
        ArrayKind::Field,
        ValueType::Float,
    )];
    data
}

/// An oblique 3×2×2 volume (qform and sform both written).
fn volume() -> Volume {
    let mut m = Matrix4::new_rotation(nalgebra::Vector3::new(0.3, -0.2, 0.5));
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&nalgebra::Vector3::new(-10.0, 4.5, 2.0));
    Volume::new([3, 2, 2], (0..12).map(f64::from).collect(), m).expect("volume")
}

/// The bytes that `write` puts in a file named `name`.
fn written(name: &str, write: impl FnOnce(&Path) -> medial::io::Result<()>) -> Vec<u8> {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join(name);
    write(&path).expect("write the valid file");
    std::fs::read(&path).expect("read the valid file")
}

const OBJ: &str = "# tetrahedron
v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
vn 0 0 1
f 1//1 3//1 2//1
f 1/1 2/1 4/1
f -4 -1 -2
f 2 3 4
";

#[test]
fn vtk_ascii() {
    never_panics("m.vtk", VTK_ASCII.as_bytes(), read_polydata);
}

#[test]
fn vtk_binary() {
    let options = WriteOptions {
        encoding: Encoding::Binary,
        layout: Layout::Offsets,
    };
    never_panics(
        "m.vtk",
        &polydata_to_bytes(&polydata(), options),
        read_polydata,
    );
}

#[test]
fn cmrep() {
    let data = template_to_polydata(&medial::testing::meshes::bipyramid(0.5));
    let valid = polydata_to_bytes(&data, WriteOptions::default());
    never_panics("m.vtk", &valid, read_template);
}

#[test]
fn obj() {
    never_panics("m.obj", OBJ.as_bytes(), read_mesh);
}

#[test]
fn glb() {
    never_panics("m.glb", &glb::tetra_glb(), read_mesh);
}

#[test]
fn gltf_with_external_buffer() {
    let json = glb::gltf_json(r#"{"byteLength": 72, "uri": "m.bin"}"#, [1.0, 2.0, 1.0], 4);
    let buffer = glb::tetra_buffer();
    never_panics_beside("m.gltf", json.as_bytes(), &[("m.bin", &buffer)], read_mesh);
}

#[test]
fn nifti() {
    let valid = written("v.nii", |p| write_nifti(p, &volume(), NiftiType::F32));
    never_panics("m.nii", &valid, read_nifti);
}

#[test]
fn nifti_gz() {
    let valid = written("v.nii.gz", |p| write_nifti(p, &volume(), NiftiType::I16));
    never_panics("m.nii.gz", &valid, read_nifti);
}

#[test]
fn npy() {
    let valid = written("v.npy", |p| {
        write_npy(p, &[2, 3], &[0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    });
    never_panics("m.npy", &valid, read_npy);
}

#[test]
fn exr() {
    let valid = written("v.exr", |p| write_exr_volume(p, &volume()));
    never_panics("m.exr", &valid, read_exr_volume);
}

/// A config with every section and key kind: a Dice and a varifold stage.
const CONFIG: &str = r#"[model]
template = "template.vtk"

[flow]
sigma = 3.5
time_steps = 20
kinetic_weight = 0.005

[output]
every_time_point = false
binary_vtk = true

[[stage]]
name = "dice"
attachment = "dice"
image = "target.nii.gz"
label = 1
image_sigma = 0.2
mu = 0.02
mu_factor = 10.0
mu_max = 2000.0
al_iterations = 6

[[stage]]
name = "surface"
attachment = "varifold"
surface = "target.obj"
varifold_width = 2.0
weight = 50
"#;

#[test]
fn config() {
    Config::parse(CONFIG, Path::new("c.toml"))
        .expect("a valid config")
        .check()
        .expect("valid values");
    never_panics("c.toml", CONFIG.as_bytes(), Config::load);
}
