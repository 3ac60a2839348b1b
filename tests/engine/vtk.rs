//! Legacy VTK polydata: real files, round trips, hand-written VTK 9 files, errors.

use std::path::{Path, PathBuf};

use medial::io::vtk::{
    parse_polydata, polydata_to_bytes, read_polydata, read_trimesh, write_polydata, write_trimesh,
    ArrayKind, DataArray, Encoding, Layout, PolyData, ValueType, WriteOptions,
};
use medial::io::Error;
use medial::Vec3;
use proptest::prelude::*;

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data");

fn data_file(name: &str) -> PathBuf {
    Path::new(DATA).join(name)
}

fn all_options() -> [WriteOptions; 4] {
    let mut options = [WriteOptions::default(); 4];
    let combos = [Encoding::Ascii, Encoding::Binary]
        .into_iter()
        .flat_map(|e| [Layout::Legacy, Layout::Offsets].map(|l| (e, l)));
    for (slot, (encoding, layout)) in options.iter_mut().zip(combos) {
        *slot = WriteOptions { encoding, layout };
    }
    options
}

fn parse_str(text: &str) -> medial::io::Result<PolyData> {
    parse_polydata(text.as_bytes(), Path::new("test.vtk"))
}

fn format_message(result: medial::io::Result<PolyData>) -> String {
    match result {
        Err(Error::Format { message, .. }) => message,
        other => panic!("expected a format error, got {other:?}"),
    }
}

fn array<'a>(arrays: &'a [DataArray], name: &str) -> &'a DataArray {
    arrays
        .iter()
        .find(|a| a.name == name)
        .unwrap_or_else(|| panic!("no array {name}"))
}

// ---------------------------------------------------------------------------------------------
// Real data.

#[test]
fn t001_template() {
    let data = read_polydata(&data_file("cmrep/t001_template_bcmrep.vtk")).expect("read t001");
    assert_eq!(data.points.len(), 314);
    assert_eq!(data.triangles().expect("triangles").len(), 624);
    let names: Vec<&str> = data.point_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["normals", "MedialIndex", "Tangency", "Radius"]);

    let normals = data.point_array_ci("Normals").expect("normals");
    assert_eq!(
        (normals.kind, normals.components, normals.value_type),
        (ArrayKind::Normals, 3, ValueType::Float)
    );
    assert_eq!(
        normals.values[..3],
        [-0.993313f32, 0.0249269, 0.11273].map(f64::from)
    );
    for n in normals.values.chunks(3) {
        let norm = Vec3::new(n[0], n[1], n[2]).norm();
        assert!((norm - 1.0).abs() < 1e-4, "normal of norm {norm}");
    }
    let index = data.point_array("MedialIndex").expect("MedialIndex");
    assert_eq!(
        (index.kind, index.value_type),
        (ArrayKind::Field, ValueType::Int)
    );
    assert_eq!(
        index.values[..9],
        [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
    );
    let atoms = index.values.iter().fold(0.0f64, |m, &v| m.max(v)) as usize + 1;
    assert_eq!(atoms, 189);
    let radius = data.point_array("Radius").expect("Radius");
    assert_eq!(radius.value_type, ValueType::Float);
    assert!(radius.values.iter().all(|&r| r > 0.0 && r < 10.0));
    assert!(data.point_array("radius").is_none());
    assert!(data.point_array_ci("radius").is_some());
    assert_eq!(
        data.points[0],
        Vec3::new(
            f64::from(111.815f32),
            f64::from(101.932f32),
            f64::from(62.5238f32)
        )
    );
}

#[test]
fn placenta_sheet() {
    let path = data_file("cmrep/placenta_template_anterioralign3.vtk");
    let data = read_polydata(&path).expect("read sheet");
    assert_eq!((data.points.len(), data.polygons.len()), (115, 204));
    assert!(data.point_array("Label").is_some() && data.point_array("Radius").is_some());
    let tri_label = array(&data.cell_data, "TriLabel");
    assert_eq!(
        (tri_label.values.len(), tri_label.value_type),
        (204, ValueType::Double)
    );
}

#[test]
fn hippocampus_meshes_and_speed() {
    for (name, points, triangles) in [
        ("keops/hippos_source.vtk", 6611, 13218),
        ("keops/hippos_target.vtk", 6611, 13218),
        ("keops/hippos_reduc_source.vtk", 662, 1320),
        ("keops/hippos_reduc_target.vtk", 662, 1320),
    ] {
        let mesh = read_trimesh(&data_file(name)).expect(name);
        assert_eq!(
            (mesh.points().len(), mesh.triangles().len()),
            (points, triangles),
            "{name}"
        );
    }
}

#[test]
fn every_shared_file_reads_and_round_trips() {
    let mut count = 0;
    for dir in ["cmrep", "keops"] {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(Path::new(DATA).join(dir))
            .expect("data dir")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "vtk"))
            .collect();
        entries.sort();
        for path in entries {
            let data = read_polydata(&path).unwrap_or_else(|e| panic!("{e}"));
            assert!(
                !data.points.is_empty() && !data.polygons.is_empty(),
                "{}",
                path.display()
            );
            for options in all_options() {
                let back = parse_polydata(&polydata_to_bytes(&data, options), &path)
                    .unwrap_or_else(|e| panic!("{options:?}: {e}"));
                assert_eq!(back, as_written(&data), "{} {options:?}", path.display());
            }
            count += 1;
        }
    }
    assert_eq!(count, 11);
}

#[test]
fn vtk9_files_with_metadata_and_texture_coordinates() {
    let box_mesh = read_polydata(&data_file("cmrep/shooting_test_3d_box.vtk")).expect("box");
    assert_eq!((box_mesh.points.len(), box_mesh.polygons.len()), (150, 192));
    assert_eq!(box_mesh.triangles().expect("triangles").len(), 192);
    let normals = array(&box_mesh.point_data, "Normals");
    assert_eq!(
        (normals.kind, normals.values[..3].to_vec()),
        (ArrayKind::Normals, vec![-1.0, 0.0, 0.0])
    );
    let tcoords = array(&box_mesh.point_data, "TCoords");
    assert_eq!((tcoords.kind, tcoords.components), (ArrayKind::Field, 2));
    assert_eq!(tcoords.values[..4], [-0.5, 0.0, 1.5, 0.0]);
    let sphere = read_trimesh(&data_file("cmrep/shooting_test_3d_sphere.vtk")).expect("sphere");
    assert_eq!(
        (sphere.points().len(), sphere.triangles().len()),
        (162, 320)
    );
}

#[test]
fn percent_encoded_names() {
    let data =
        read_polydata(&data_file("cmrep/placenta_template_def_to_target.vtk")).expect("read");
    assert!(data.cell_data.iter().any(|a| a.name == "Cell Jacobian"));
    assert!(data.point_data.iter().any(|a| a.name == "Point Area"));
    let text = String::from_utf8(polydata_to_bytes(&data, WriteOptions::default())).expect("utf8");
    assert!(
        text.contains("\nCell%20Jacobian 1 1632 float\n"),
        "names are re-encoded"
    );
}

// ---------------------------------------------------------------------------------------------
// Hand-written files.

/// A tetrahedron as VTK 9.x writes it: 5.1 layout, METADATA blocks (component names that spell
/// keywords, information keys, string values), FIELD arrays, a CELL_DATA SCALARS array.
const VTK9_TETRAHEDRON: &str = "# vtk DataFile Version 5.1
vtk output
ASCII
DATASET POLYDATA
FIELD FieldData 1
TimeValue 1 1 double
4.5
POINTS 4 float
0 0 0 1 0 0 0 1 0 
0 0 1 

METADATA
INFORMATION 2
NAME L2_NORM_RANGE LOCATION vtkDataArray
DATA 2 0 1 
NAME L2_NORM_FINITE_RANGE LOCATION vtkDataArray
DATA 2 0 1 

POLYGONS 5 12
OFFSETS vtktypeint64
0 3 6 9 12 
CONNECTIVITY vtktypeint64
0 2 1 0 1 3 0 3 2 1 2 3 

POINT_DATA 4
NORMALS Normals float
-0.57735 -0.57735 -0.57735 1 0 0 0 1 0 
0 0 1 
METADATA
COMPONENT_NAMES
Normals
Points
Z%20axis
INFORMATION 1
NAME L2_NORM_RANGE LOCATION vtkDataArray
DATA 2 1 1 

FIELD FieldData 2
Radius 1 4 double
0.5 0.25 0.125 1e-3 
METADATA
INFORMATION 1
NAME UNITS LOCATION vtkDataArray
DATA 1
mm

Label%20Id 1 4 vtktypeint64
0 1 2 3 

CELL_DATA 4
scalars Area FLOAT 1
lookup_table default
0.5 0.5 0.5 0.866
";

#[test]
fn vtk9_hand_written() {
    let data = parse_str(VTK9_TETRAHEDRON).expect("parse");
    assert_eq!(data.points.len(), 4);
    assert_eq!(
        data.polygons,
        vec![vec![0, 2, 1], vec![0, 1, 3], vec![0, 3, 2], vec![1, 2, 3]]
    );
    let names: Vec<&str> = data.point_data.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["Normals", "Radius", "Label Id"]);
    assert_eq!(
        array(&data.point_data, "Radius").values,
        [0.5, 0.25, 0.125, 1e-3]
    );
    let label = array(&data.point_data, "Label Id");
    assert_eq!(
        (label.value_type, label.values.clone()),
        (ValueType::Int, vec![0.0, 1.0, 2.0, 3.0])
    );
    let area = array(&data.cell_data, "Area");
    assert_eq!(
        (area.kind, area.values[3]),
        (ArrayKind::Scalars, f64::from(0.866f32))
    );
}

#[test]
fn binary_with_metadata_and_whitespace_like_bytes() {
    // A coordinate whose big-endian bytes are all '\n' and one whose first byte is ' ': the
    // reader must not skip whitespace before binary data.
    let newline_bytes = f64::from_bits(0x0A0A_0A0A_0A0A_0A0A);
    let space_first = f64::from_bits(0x2020_0000_0000_0001);
    let points = vec![
        Vec3::new(newline_bytes, space_first, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, newline_bytes),
    ];
    let mut bytes =
        b"# vtk DataFile Version 5.1\ntitle\nBINARY\nDATASET POLYDATA\nPOINTS 3 double\n".to_vec();
    for p in &points {
        for c in [p.x, p.y, p.z] {
            bytes.extend_from_slice(&c.to_be_bytes());
        }
    }
    bytes.extend_from_slice(
        b"\nMETADATA\nINFORMATION 1\nNAME L2_NORM_RANGE LOCATION vtkDataArray\nDATA 2 0 1\n\n",
    );
    bytes.extend_from_slice(b"POLYGONS 2 3\nOFFSETS vtktypeint32\n");
    for v in [0i32, 3] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes.extend_from_slice(b"\nCONNECTIVITY vtktypeint64\n");
    for v in [0i64, 1, 2] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes.extend_from_slice(
        b"\nPOINT_DATA 3\nSCALARS Code unsigned_char\nLOOKUP_TABLE default\n\n\x20\x0A\n",
    );
    let data = parse_polydata(&bytes, Path::new("binary.vtk")).expect("parse");
    assert_eq!(data.points, points);
    assert_eq!(data.polygons, vec![vec![0, 1, 2]]);
    assert_eq!(array(&data.point_data, "Code").values, [10.0, 32.0, 10.0]);
}

#[test]
fn legacy_binary_int_arrays_and_lookup_table() {
    let mut bytes =
        b"# vtk DataFile Version 3.0\nt\nBINARY\nDATASET POLYDATA\nPOINTS 3 float\n".to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes.extend_from_slice(b"\nPOLYGONS 1 4\n");
    for v in [3i32, 0, 1, 2] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes.extend_from_slice(b"\nCELL_DATA 1\nSCALARS s short 2\nLOOKUP_TABLE my_table\n");
    bytes.extend_from_slice(&(-2i16).to_be_bytes());
    bytes.extend_from_slice(&7i16.to_be_bytes());
    bytes.extend_from_slice(b"\nLOOKUP_TABLE my_table 2\n");
    bytes.extend_from_slice(&[255, 0, 0, 255, 0, 255, 0, 255]);
    bytes.extend_from_slice(b"\nPOINT_DATA 3\nVECTORS v double\n");
    for v in [1.5f64, -2.0, 3.0, 0.0, 0.0, 0.0, 1e300, -1e-300, 0.0] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let data = parse_polydata(&bytes, Path::new("legacy.vtk")).expect("parse");
    let s = array(&data.cell_data, "s");
    assert_eq!(
        (s.components, s.value_type, s.values.clone()),
        (2, ValueType::Int, vec![-2.0, 7.0])
    );
    let v = array(&data.point_data, "v");
    assert_eq!(
        (v.kind, v.values[6], v.values[7]),
        (ArrayKind::Vectors, 1e300, -1e-300)
    );
}

// ---------------------------------------------------------------------------------------------
// Round trips.

/// `data` as it comes back: in each attribute set the first SCALARS, NORMALS and VECTORS
/// array keep their kind, every other array comes back as a FIELD array, after them.
fn as_written(data: &PolyData) -> PolyData {
    let order = |arrays: &[DataArray]| {
        let mut seen = Vec::new();
        let (mut first, fields): (Vec<_>, Vec<_>) = arrays.iter().cloned().partition(|a| {
            let attribute = a.kind != ArrayKind::Field && !seen.contains(&a.kind);
            seen.push(a.kind);
            attribute
        });
        first.extend(fields.into_iter().map(|a| DataArray {
            kind: ArrayKind::Field,
            ..a
        }));
        first
    };
    PolyData {
        point_data: order(&data.point_data),
        cell_data: order(&data.cell_data),
        ..data.clone()
    }
}

fn value_strategy(value_type: ValueType) -> BoxedStrategy<f64> {
    match value_type {
        ValueType::Int => prop_oneof![
            4 => any::<i32>().prop_map(f64::from),
            1 => (-(1i64 << 53)..=(1i64 << 53)).prop_map(|v| v as f64),
        ]
        .boxed(),
        ValueType::Float => any::<f32>()
            .prop_filter("finite", |v| v.is_finite())
            .prop_map(f64::from)
            .boxed(),
        ValueType::Double => any::<f64>()
            .prop_filter("finite", |v| v.is_finite())
            .boxed(),
    }
}

fn array_strategy(tuples: usize) -> impl Strategy<Value = DataArray> {
    let kinds = prop_oneof![
        Just(ArrayKind::Scalars),
        Just(ArrayKind::Normals),
        Just(ArrayKind::Vectors),
        Just(ArrayKind::Field)
    ];
    let types = prop_oneof![
        Just(ValueType::Int),
        Just(ValueType::Float),
        Just(ValueType::Double)
    ];
    ("[A-Za-z][A-Za-z0-9 %_\"é]{0,8}", kinds, types, 1usize..5).prop_flat_map(
        move |(name, kind, value_type, components)| {
            let components = match kind {
                ArrayKind::Normals | ArrayKind::Vectors => 3,
                _ => components,
            };
            proptest::collection::vec(value_strategy(value_type), tuples * components).prop_map(
                move |values| DataArray {
                    name: name.clone(),
                    components,
                    values,
                    kind,
                    value_type,
                },
            )
        },
    )
}

fn polydata_strategy() -> impl Strategy<Value = PolyData> {
    (1usize..15).prop_flat_map(|n| {
        let coordinate = any::<f64>().prop_filter("finite", |v| v.is_finite());
        let point = [coordinate.clone(), coordinate.clone(), coordinate]
            .prop_map(|[x, y, z]| Vec3::new(x, y, z));
        let cells = move |sizes: std::ops::Range<usize>| {
            proptest::collection::vec(proptest::collection::vec(0..n, sizes), 0..6)
        };
        (
            proptest::collection::vec(point, n),
            cells(1..2),
            cells(2..5),
            cells(3..7),
            cells(3..7),
        )
            .prop_flat_map(move |(points, vertices, lines, polygons, strips)| {
                let cell_count = vertices.len() + lines.len() + polygons.len() + strips.len();
                let shape = PolyData {
                    points,
                    vertices,
                    lines,
                    polygons,
                    strips,
                    ..PolyData::default()
                };
                (
                    Just(shape),
                    proptest::collection::vec(array_strategy(n), 0..4),
                    proptest::collection::vec(array_strategy(cell_count), 0..3),
                )
                    .prop_map(|(shape, point_data, cell_data)| PolyData {
                        point_data,
                        cell_data,
                        ..shape
                    })
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn round_trip(data in polydata_strategy()) {
        prop_assert_eq!(data.validate(), Ok(()));
        let expected = as_written(&data);
        for options in all_options() {
            let bytes = polydata_to_bytes(&data, options);
            let back = parse_polydata(&bytes, Path::new("random.vtk"));
            prop_assert!(back.is_ok(), "{:?}: {:?}", options, back);
            prop_assert_eq!(back.ok(), Some(expected.clone()), "{:?}", options);
        }
    }
}

#[test]
fn write_read_files() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = read_polydata(&data_file("cmrep/t001_template_bcmrep.vtk")).expect("read");
    for options in all_options() {
        let path = dir
            .path()
            .join(format!("{:?}{:?}.vtk", options.encoding, options.layout));
        write_polydata(&path, &data, options).expect("write");
        assert_eq!(
            read_polydata(&path).expect("read back"),
            data,
            "{options:?}"
        );
        let text = std::fs::read(&path).expect("bytes");
        let version: &[u8] = match options.layout {
            Layout::Legacy => b"# vtk DataFile Version 4.2\n",
            Layout::Offsets => b"# vtk DataFile Version 5.1\n",
        };
        assert!(text.starts_with(version));
    }
    let mesh = read_trimesh(&data_file("keops/hippos_reduc_source.vtk")).expect("mesh");
    let path = dir.path().join("mesh.vtk");
    write_trimesh(
        &path,
        &mesh,
        WriteOptions {
            encoding: Encoding::Binary,
            layout: Layout::Legacy,
        },
    )
    .expect("write mesh");
    assert_eq!(read_trimesh(&path).expect("read mesh"), mesh);
}

/// VTK's legacy reader sees only the first SCALARS (NORMALS, VECTORS) array of an attribute
/// set unless told to read them all, but every FIELD array: the writer keeps one of each kind
/// and puts the others in one FIELD block.
#[test]
fn one_array_of_each_attribute_kind_the_others_in_one_field_block() {
    let mut data = PolyData {
        points: vec![Vec3::zeros(); 2],
        ..PolyData::default()
    };
    let array = |name: &str, kind, components| DataArray {
        name: name.into(),
        components,
        values: vec![1.0; 2 * components],
        kind,
        value_type: ValueType::Double,
    };
    data.point_data = vec![
        array("Angle", ArrayKind::Scalars, 1),
        array("Normals", ArrayKind::Normals, 3),
        array("Mismatch", ArrayKind::Scalars, 1),
        array("Other normals", ArrayKind::Normals, 3),
        array("Index", ArrayKind::Field, 1),
    ];
    let text = String::from_utf8(polydata_to_bytes(&data, WriteOptions::default())).expect("utf8");
    let headers: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with(|c: char| c.is_ascii_uppercase()))
        .skip_while(|l| !l.starts_with("POINT_DATA"))
        .collect();
    assert_eq!(
        headers,
        [
            "POINT_DATA 2",
            "SCALARS Angle double 1",
            "LOOKUP_TABLE default",
            "NORMALS Normals double",
            "FIELD FieldData 3",
            "Mismatch 1 2 double",
            "Other%20normals 3 2 double",
            "Index 1 2 double",
        ],
        "{text}"
    );
    let back = parse_str(&text).expect("parse");
    assert_eq!(back, as_written(&data));
    let kinds: Vec<ArrayKind> = back.point_data.iter().map(|a| a.kind).collect();
    assert_eq!(
        kinds,
        [
            ArrayKind::Scalars,
            ArrayKind::Normals,
            ArrayKind::Field,
            ArrayKind::Field,
            ArrayKind::Field
        ]
    );
}

#[test]
fn int_arrays_widen_when_needed() {
    let mut data = PolyData {
        points: vec![Vec3::zeros(); 3],
        ..PolyData::default()
    };
    let int = |name: &str, values: Vec<f64>| DataArray {
        name: name.into(),
        components: 1,
        values,
        kind: ArrayKind::Field,
        value_type: ValueType::Int,
    };
    data.add_point_array(int("small", vec![-1.0, 0.0, 2147483647.0]));
    data.add_point_array(int("large", vec![-1.0, 0.0, 2147483648.0]));
    data.add_point_array(int("fraction", vec![0.5, 0.0, 1.0]));
    let text = String::from_utf8(polydata_to_bytes(&data, WriteOptions::default())).expect("utf8");
    assert!(text.contains("small 1 3 int\n"), "{text}");
    assert!(text.contains("large 1 3 vtktypeint64\n"), "{text}");
    assert!(text.contains("fraction 1 3 double\n"), "{text}");
    let back = parse_str(&text).expect("parse");
    assert_eq!(
        back.point_array("large").expect("large").values[2],
        2147483648.0
    );
    assert_eq!(
        back.point_array("fraction").expect("fraction").values[0],
        0.5
    );
}

// ---------------------------------------------------------------------------------------------
// Helpers.

#[test]
fn polydata_helpers() {
    let mut data = PolyData {
        points: vec![Vec3::zeros(); 4],
        polygons: vec![vec![0, 1, 2], vec![0, 1, 2, 3]],
        ..PolyData::default()
    };
    assert_eq!(
        data.triangles().expect_err("quad"),
        "polygon 1 has 4 vertices; only triangles are supported"
    );
    data.polygons.pop();
    assert_eq!(data.triangles(), Ok(vec![[0, 1, 2]]));
    data.strips.push(vec![0, 1, 2, 3]);
    assert!(data
        .triangles()
        .expect_err("strips")
        .contains("TRIANGLE_STRIPS"));
    assert_eq!(data.cell_count(), 2);

    let radius = |v: f64| DataArray {
        name: "Radius".into(),
        components: 1,
        values: vec![v; 4],
        kind: ArrayKind::Scalars,
        value_type: ValueType::Double,
    };
    data.add_point_array(radius(1.0));
    data.add_point_array(radius(2.0));
    assert_eq!(data.point_data.len(), 1);
    assert_eq!(data.point_array("Radius").expect("radius").values[0], 2.0);
    assert!(data.point_array("RADIUS").is_none());
    assert_eq!(data.point_array_ci("RADIUS").expect("ci").values[0], 2.0);
}

// ---------------------------------------------------------------------------------------------
// Errors.

const TRIANGLE: &str = "# vtk DataFile Version 3.0
triangle
ASCII
DATASET POLYDATA
POINTS 3 float
0 0 0
1 0 0
0 1 0
POLYGONS 1 4
3 0 1 2
";

#[test]
fn truncated_files() {
    let text = std::fs::read_to_string(data_file("cmrep/t001_template_bcmrep.vtk")).expect("read");
    let message = format_message(parse_str(&text[..text.len() / 2]));
    assert!(message.contains("unexpected end of file"), "{message}");
    assert!(message.contains("line "), "{message}");

    let data = read_polydata(&data_file("cmrep/t001_template_bcmrep.vtk")).expect("read");
    let options = WriteOptions {
        encoding: Encoding::Binary,
        layout: Layout::Legacy,
    };
    let bytes = polydata_to_bytes(&data, options);
    let message = format_message(parse_polydata(
        &bytes[..bytes.len() - 100],
        Path::new("b.vtk"),
    ));
    assert!(
        message.contains("unexpected end of file") && message.contains("byte "),
        "{message}"
    );
    assert!(
        message.contains("Radius"),
        "names the array being read: {message}"
    );
}

#[test]
fn nan_point() {
    let text = TRIANGLE.replace("1 0 0\n", "1 nan 0\n");
    let message = format_message(parse_str(&text));
    assert!(message.contains("point 1 is not finite"), "{message}");
}

#[test]
fn index_out_of_range() {
    let text = TRIANGLE.replace("3 0 1 2", "3 0 7 2");
    let message = format_message(parse_str(&text));
    assert!(
        message.contains("POLYGONS cell 0 uses point 7 but there are 3 points"),
        "{message}"
    );
}

#[test]
fn bad_counts_and_values() {
    let message = format_message(parse_str(&TRIANGLE.replace("POLYGONS 1 4", "POLYGONS 1 5")));
    assert!(
        message.contains("POLYGONS") && message.contains("end of file"),
        "{message}"
    );
    let message = format_message(parse_str(&TRIANGLE.replace("POLYGONS 1 4", "POLYGONS 2 4")));
    assert!(
        message.contains("the cell list (4 values) ends before cell 1 of 2"),
        "{message}"
    );
    let message = format_message(parse_str(&TRIANGLE.replace("1 0 0\n", "1 zero 0\n")));
    assert!(
        message.contains("'zero' is not a valid float value") && message.contains("line 7"),
        "{message}"
    );
    let message = format_message(parse_str(&format!(
        "{TRIANGLE}POINT_DATA 2\nSCALARS s int 1\nLOOKUP_TABLE default\n1 2\n"
    )));
    assert!(
        message.contains("POINT_DATA declares 2 tuples but the file has 3 points"),
        "{message}"
    );
    let message = format_message(parse_str(&format!(
        "{TRIANGLE}POINT_DATA 3\nSCALARS s bit 1\n1 0 1\n"
    )));
    assert!(message.contains("'bit' are not supported"), "{message}");
    let message = format_message(parse_str(&format!(
        "{TRIANGLE}POINT_DATA 3\nFIELD f 1\nx 1 2 float\n1 2\n"
    )));
    assert!(
        message.contains("2 tuples but POINT_DATA has 3"),
        "{message}"
    );
    let message = format_message(parse_str(&format!("{TRIANGLE}SPLINES 3\n")));
    assert!(
        message.contains("unknown keyword 'SPLINES'") && message.contains("line 11"),
        "{message}"
    );
    let message = format_message(parse_str(&TRIANGLE.replace("3.0", "6.0")));
    assert!(
        message.contains("unsupported VTK file version 6.0"),
        "{message}"
    );
    let message = format_message(parse_str(&TRIANGLE.replace("ASCII", "TEXT")));
    assert!(
        message.contains("expected ASCII or BINARY") && message.contains("line 3"),
        "{message}"
    );
    let message = format_message(parse_str(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\">\n",
    ));
    assert!(message.contains("XML VTK file"), "{message}");
}

#[test]
fn non_triangle_polygon_for_trimesh() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("quad.vtk");
    let text = TRIANGLE
        .replace("POINTS 3 float", "POINTS 4 float")
        .replace("0 1 0\n", "0 1 0\n1 1 0\n");
    std::fs::write(
        &path,
        text.replace("POLYGONS 1 4\n3 0 1 2", "POLYGONS 2 9\n3 0 1 2\n4 0 1 3 2"),
    )
    .expect("write");
    match read_trimesh(&path) {
        Err(Error::Format { message, path: p }) => {
            assert_eq!(p, path);
            assert!(message.contains("polygon 1 has 4 vertices"), "{message}");
        }
        other => panic!("expected a format error, got {other:?}"),
    }
}

#[test]
fn unknown_dataset_type() {
    let text = TRIANGLE.replace("POLYDATA", "UNSTRUCTURED_GRID");
    let message = format_message(parse_str(&text));
    assert!(message.contains("only POLYDATA is supported"), "{message}");
    assert!(message.contains("UNSTRUCTURED_GRID"), "{message}");
}

#[test]
fn missing_file_is_io_error() {
    let err = read_polydata(Path::new("/nonexistent/dir/mesh.vtk")).expect_err("missing");
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("/nonexistent/dir/mesh.vtk"));
}

#[test]
fn invalid_data_is_not_written() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.vtk");
    let data = PolyData {
        points: vec![Vec3::zeros(); 2],
        polygons: vec![vec![0, 1, 2]],
        ..PolyData::default()
    };
    let err = write_polydata(&path, &data, WriteOptions::default()).expect_err("invalid");
    assert!(
        err.to_string().contains("POLYGONS cell 0 uses point 2"),
        "{err}"
    );
    assert!(!path.exists());
}

// ---------------------------------------------------------------------------------------------
// Tolerance as VTK's legacy reader (vtkDataReader / vtkPolyDataReader): what it accepts is read,
// what it refuses is refused.

/// Two triangles and three lines: 5 cells of two kinds, 4 points.
const MIXED: &str = "# vtk DataFile Version 3.0
mixed cells
ASCII
DATASET POLYDATA
POINTS 4 float
0 0 0
1 0 0
0 1 0
1 1 0
LINES 3 9
2 0 1
2 1 3
2 3 2
POLYGONS 2 8
3 0 1 2
3 1 3 2
";

#[test]
fn lowercase_keywords_as_cmrep_writes_them() {
    let text = "# vtk DataFile Version 3.0
cmrep
ascii
dataset polydata
points 4 float
0 0 0 1 0 0 0 1 0 1 1 0
lines 3 9
2 0 1 2 1 3 2 3 2
polygons 2 8
3 0 1 2 3 1 3 2
point_data 4
scalars Radius double 1
lookup_table default
1 2 3 4
field FieldData 1
Rho 1 4 float
0.5 0.5 0.5 0.5
cell_data 5
scalars Label int
lookup_table default
1 1 2 2 2
lookup_table mine 1
0 0 0 1
";
    let data = parse_str(text).expect("lowercase keywords");
    assert_eq!((data.points.len(), data.cell_count()), (4, 5));
    assert_eq!(
        array(&data.point_data, "Radius").values,
        [1.0, 2.0, 3.0, 4.0]
    );
    assert_eq!(array(&data.point_data, "Rho").values, [0.5; 4]);
    assert_eq!(
        array(&data.cell_data, "Label").values,
        [1.0, 1.0, 2.0, 2.0, 2.0]
    );
}

#[test]
fn cell_data_counts_every_cell_kind() {
    let data = parse_str(&format!(
        "{MIXED}CELL_DATA 5\nSCALARS k float\nLOOKUP_TABLE default\n0 1 2 3 4\n"
    ))
    .expect("lines and polygons");
    assert_eq!(array(&data.cell_data, "k").values.len(), 5);
    // Counting the polygons alone is what VTK refuses as the first data section.
    let message = format_message(parse_str(&format!("{MIXED}CELL_DATA 2\n")));
    assert!(
        message.contains(
            "CELL_DATA declares 2 tuples but the file has 5 cells (vertices, lines, polygons \
             and strips)"
        ),
        "{message}"
    );
}

#[test]
fn empty_data_sections() {
    // Empty sections of the right size, and a later empty section of any size: VTK checks only
    // the first data section against the geometry, and an empty one holds nothing to misfit.
    for tail in [
        "POINT_DATA 4\n",
        "CELL_DATA 5\n",
        "POINT_DATA 4\nCELL_DATA 5\n",
        "point_data 4\nscalars r float\nlookup_table default\n1 1 1 1\ncell_data 2\n",
        "CELL_DATA 5\nPOINT_DATA 9\n",
        "POINT_DATA 4\nCELL_DATA 7\nFIELD FieldData 0\n",
    ] {
        let data = parse_str(&format!("{MIXED}{tail}")).unwrap_or_else(|e| panic!("{tail}: {e}"));
        assert!(data.cell_data.is_empty(), "{tail}");
    }
}

#[test]
fn what_vtk_refuses_is_refused() {
    let refused = [
        // The first data section must count the geometry before it.
        (
            "POINT_DATA 3\n",
            "POINT_DATA declares 3 tuples but the file has 4 points",
        ),
        // Geometry after the data: VTK reads only attributes there.
        (
            "POINT_DATA 4\nPOLYGONS 1 4\n3 0 1 3\n",
            "POLYGONS after POINT_DATA: the geometry must come before",
        ),
        (
            "CELL_DATA 5\nPOINTS 1 float\n0 0 0\n",
            "POINTS after CELL_DATA",
        ),
        // A later section of the wrong size may be empty, not hold arrays (VTK would read
        // them into an inconsistent data set).
        (
            "POINT_DATA 4\nCELL_DATA 2\nSCALARS s float\nLOOKUP_TABLE default\n1 2\n",
            "SCALARS in CELL_DATA 2, but the file has 5 cells",
        ),
        (
            "POINT_DATA 4\nCELL_DATA 2\nFIELD f 1\nx 1 2 float\n1 2\n",
            "a FIELD array in CELL_DATA 2, but the file has 5 cells",
        ),
        // Keywords VTK does not know, in any case.
        ("point_data 4\nsplines 1\n", "unknown keyword 'splines'"),
    ];
    for (tail, want) in refused {
        let message = format_message(parse_str(&format!("{MIXED}{tail}")));
        assert!(message.contains(want), "{tail}: {message}");
    }
}

#[test]
fn real_cmrep_sheets_read() {
    for (name, points, triangles) in [
        ("cmrep/real/caudate_pde_model.vtk", 310, 558),
        ("cmrep/real/t002_hipp-prob_template.vtk", 853, 1584),
    ] {
        let data = read_polydata(&data_file(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(data.points.len(), points, "{name}");
        assert_eq!(
            data.triangles().expect("triangles").len(),
            triangles,
            "{name}"
        );
        let radius = data.point_array_ci("radius").expect("Radius");
        assert_eq!(radius.values.len(), points, "{name}");
        assert!(radius.values.iter().all(|&r| r > 0.0), "{name}");
    }
}
