//! Mesh files by extension: OBJ and glTF written in the tests, VTK from the shared data.

use std::path::{Path, PathBuf};

use medial::io::mesh::{read_mesh, read_points, write_mesh};
use medial::io::Error;
use medial::{TriMesh, Vec3};

use crate::common::clean;
use crate::common::glb;
use clean::assert_clean;
use glb::{glb, gltf_json, tetra_buffer, tetra_glb, TETRA, TETRA_INDICES};

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data");

fn write_file(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

fn format_message(result: medial::io::Result<TriMesh>) -> String {
    match result {
        Err(Error::Format { message, .. }) => message,
        other => panic!("expected a format error, got {other:?}"),
    }
}

const OBJ_TETRAHEDRON: &str = "# a tetrahedron
mtllib nothing.mtl
o tetra
v 0 0 0
v 1.5 0 0 1.0
v 0 1 0 0.5 0.5 0.5
vn 0 0 -1
vt 0 0
g side
f 1/1/1 3//1 2
f 1 2 4
s off
f -3/1 -1/1 -2/1
f 2 3 4
v 0 0 1e-3
l 1 2
";

#[test]
fn obj_keeps_file_order_and_ignores_the_rest() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mesh = read_mesh(&write_file(&dir, "t.OBJ", OBJ_TETRAHEDRON.as_bytes())).expect("read");
    assert_eq!(
        mesh.points(),
        [
            Vec3::zeros(),
            Vec3::new(1.5, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1e-3)
        ]
    );
    assert_eq!(
        mesh.triangles(),
        [[0, 2, 1], [0, 1, 3], [0, 2, 1], [1, 2, 3]]
    );
}

#[test]
fn obj_quad_is_refused_with_its_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 4\n";
    let message = format_message(read_mesh(&write_file(&dir, "q.obj", text.as_bytes())));
    assert!(
        message.contains("a face with 4 vertices") && message.contains("line 6"),
        "{message}"
    );
    let message = format_message(read_mesh(&write_file(&dir, "b.obj", b"v 0 0\n")));
    assert!(
        message.contains("3 coordinates") && message.contains("line 1"),
        "{message}"
    );
    let message = format_message(read_mesh(&write_file(
        &dir,
        "n.obj",
        b"v 0 0 0\nf 1 -2 x\n",
    )));
    assert!(
        message.contains("face vertex -2 is invalid") && message.contains("line 2"),
        "{message}"
    );
    let err =
        read_mesh(&write_file(&dir, "r.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 3\n")).expect_err("range");
    assert!(matches!(err, Error::Model { .. }), "{err:?}");
}

#[test]
fn obj_and_vtk_round_trip() {
    let dir = tempfile::tempdir().expect("temp dir");
    let source = read_mesh(&Path::new(DATA).join("keops/hippos_reduc_source.vtk")).expect("vtk");
    let points: Vec<Vec3> = source
        .points()
        .iter()
        .map(|p| p * std::f64::consts::PI + Vec3::repeat(1e-9))
        .collect();
    let mesh = TriMesh::new(points, source.triangles().to_vec()).expect("mesh");
    for name in ["m.obj", "m.vtk", "M.VTK"] {
        let path = dir.path().join(name);
        write_mesh(&path, &mesh).expect("write");
        assert_eq!(read_mesh(&path).expect("read back"), mesh, "{name}");
    }
    let obj = std::fs::read_to_string(dir.path().join("m.obj")).expect("obj text");
    let faces = obj.lines().filter(|l| l.starts_with("f ")).count();
    assert_eq!(faces, mesh.triangles().len());
    assert_eq!(obj.lines().filter(|l| l.starts_with("v ")).count(), 662);
}

#[test]
fn unknown_extension_lists_supported_ones() {
    let dir = tempfile::tempdir().expect("temp dir");
    let message = format_message(read_mesh(&write_file(&dir, "m.ply", b"ply\n")));
    assert!(
        message.contains("'.ply'") && message.contains(".vtk, .obj, .gltf, .glb"),
        "{message}"
    );
    let message = format_message(read_mesh(&write_file(&dir, "noext", b"")));
    assert!(message.contains("no extension"), "{message}");
    let mesh =
        TriMesh::new(vec![Vec3::zeros(), Vec3::x(), Vec3::y()], vec![[0, 1, 2]]).expect("mesh");
    let err = write_mesh(&dir.path().join("m.gltf"), &mesh).expect_err("read-only");
    assert!(
        err.to_string().contains("writing glTF is not supported"),
        "{err}"
    );
    assert!(matches!(
        read_mesh(Path::new("/nonexistent/m.obj")),
        Err(Error::Io { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// glTF.

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for (i, shift) in [18, 12, 6, 0].into_iter().enumerate() {
            out.push(if i <= chunk.len() {
                char::from(ALPHABET[(n >> shift) as usize & 63])
            } else {
                '='
            });
        }
    }
    out
}

fn embedded_gltf(scale: [f32; 3], mode: u32) -> String {
    let buffer = format!(
        r#"{{"byteLength": 72, "uri": "data:application/octet-stream;base64,{}"}}"#,
        base64(&tetra_buffer())
    );
    gltf_json(&buffer, scale, mode)
}

fn expected_points(scale: [f64; 3]) -> Vec<Vec3> {
    let tetra = TETRA.map(|p| Vec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])));
    let first = tetra.iter().map(|p| p + Vec3::new(10.0, 0.0, 0.0));
    let second = tetra
        .iter()
        .map(|p| (p + Vec3::new(0.0, 1.0, 0.0)).component_mul(&Vec3::from(scale)));
    first.chain(second).collect()
}

#[test]
fn gltf_with_embedded_buffer_merges_instances() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(&dir, "t.gltf", embedded_gltf([2.0, 2.0, 2.0], 4).as_bytes());
    let mesh = read_mesh(&path).expect("read gltf");
    assert_eq!(mesh.points(), expected_points([2.0, 2.0, 2.0]));
    let expected: Vec<[usize; 3]> = TETRA_INDICES
        .chunks(3)
        .map(|t| [usize::from(t[0]), usize::from(t[1]), usize::from(t[2])])
        .chain(TETRA_INDICES.chunks(3).map(|t| {
            [
                4 + usize::from(t[0]),
                4 + usize::from(t[1]),
                4 + usize::from(t[2]),
            ]
        }))
        .collect();
    assert_eq!(mesh.triangles(), expected);
}

#[test]
fn gltf_mirroring_keeps_orientation() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(
        &dir,
        "m.gltf",
        embedded_gltf([-1.0, 1.0, 1.0], 4).as_bytes(),
    );
    let mesh = read_mesh(&path).expect("read gltf");
    assert_eq!(mesh.points(), expected_points([-1.0, 1.0, 1.0]));
    // Signed volume of each tetrahedron instance: the same sign after mirroring.
    let volume = |offset: usize| -> f64 {
        mesh.triangles()[offset..offset + 4]
            .iter()
            .map(|&[a, b, c]| {
                let p = mesh.points();
                p[a].dot(&p[b].cross(&p[c])) / 6.0
            })
            .sum()
    };
    let (original, mirrored) = (volume(0), volume(4));
    assert!((original.abs() - 1.0 / 6.0).abs() < 1e-12, "{original}");
    assert!(
        (mirrored - original).abs() < 1e-12,
        "{original} vs {mirrored}"
    );
}

#[test]
fn gltf_binary_container() {
    let glb = tetra_glb();
    let dir = tempfile::tempdir().expect("temp dir");
    let mesh = read_mesh(&write_file(&dir, "t.GLB", &glb)).expect("read glb");
    assert_eq!(mesh.points(), expected_points([1.0, 1.0, 1.0]));
    assert_eq!(mesh.triangles().len(), 8);
}

#[test]
fn gltf_external_buffer() {
    let dir = tempfile::tempdir().expect("temp dir");
    write_file(&dir, "tetra.bin", &tetra_buffer());
    let json = gltf_json(
        r#"{"byteLength": 72, "uri": "tetra.bin"}"#,
        [1.0, 1.0, 1.0],
        4,
    );
    let mesh = read_mesh(&write_file(&dir, "ext.gltf", json.as_bytes())).expect("read");
    assert_eq!(mesh.points().len(), 8);
}

#[test]
fn gltf_non_triangle_mode_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(
        &dir,
        "lines.gltf",
        embedded_gltf([1.0, 1.0, 1.0], 1).as_bytes(),
    );
    let message = format_message(read_mesh(&path));
    assert!(
        message.contains("mesh 0 'tetra', primitive 0") && message.contains("only TRIANGLES"),
        "{message}"
    );
    let message = format_message(read_mesh(&write_file(&dir, "bad.gltf", b"{not json")));
    assert!(message.contains("invalid glTF"), "{message}");
}

/// The points of any VTK polydata (whatever its cells), else of a mesh format.
#[test]
fn read_points_of_polydata_and_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let quad = write_file(
        &dir,
        "quad.vtk",
        b"# vtk DataFile Version 4.2\nquad\nASCII\nDATASET POLYDATA\nPOINTS 4 double\n\
          0 0 0 1 0 0 1 1 0 0 1 0\nPOLYGONS 1 5\n4 0 1 2 3\n",
    );
    let points = read_points(&quad).unwrap();
    assert_eq!(points.len(), 4);
    assert_eq!(points[2], Vec3::new(1.0, 1.0, 0.0));
    assert!(read_mesh(&quad).is_err(), "not a triangle mesh");
    let obj = write_file(&dir, "tetra.OBJ", OBJ_TETRAHEDRON.as_bytes());
    assert_eq!(
        read_points(&obj).unwrap(),
        read_mesh(&obj).unwrap().points()
    );
    let sphere = Path::new(DATA).join("cmrep/shooting_test_3d_sphere.vtk");
    assert_eq!(
        read_points(&sphere).unwrap(),
        read_mesh(&sphere).unwrap().points()
    );
    let err = read_points(&dir.path().join("points.txt")).unwrap_err();
    assert!(
        err.to_string().contains("unknown mesh extension '.txt'"),
        "{err}"
    );
}

/// The error of reading the GLB of the tetrahedron document edited by `edit` (a JSON text
/// replacement), checked to be clean.
fn edited_glb_error(edit: (&str, &str)) -> Error {
    let json = gltf_json(r#"{"byteLength": 72}"#, [1.0, 1.0, 1.0], 4);
    assert!(json.contains(edit.0), "{}", edit.0);
    let dir = tempfile::tempdir().expect("temp dir");
    let path = write_file(
        &dir,
        "bad.glb",
        &glb(&json.replace(edit.0, edit.1), &tetra_buffer()),
    );
    let error = read_mesh(&path).expect_err("a bad accessor");
    assert_clean(&error, &path);
    error
}

/// The accessor fields of an error, and its problem.
fn accessor_problem(error: &Error) -> (&'static str, usize, &str) {
    match error {
        Error::Accessor {
            role,
            accessor,
            problem,
            ..
        } => (*role, *accessor, problem),
        other => panic!("expected an accessor error, got {other:?}"),
    }
}

/// An `indices` accessor of floats made the gltf crate panic (`unreachable!`) in `read_mesh`.
#[test]
fn gltf_float_indices_are_refused() {
    let error = edited_glb_error((r#""componentType": 5123"#, r#""componentType": 5126"#));
    let (role, accessor, problem) = accessor_problem(&error);
    assert_eq!((role, accessor), ("indices", 1));
    assert!(
        problem.contains("Scalar of F32") && problem.contains("Scalar of U16"),
        "{problem}"
    );
    assert!(
        error
            .to_string()
            .contains("mesh 0, primitive 0: indices accessor 1"),
        "{error}"
    );
}

/// Element types, counts, offsets and strides that the gltf crate would trust.
#[test]
fn gltf_accessors_outside_their_buffers_are_refused() {
    let cases = [
        // POSITION as 2 floats: read as 3 would run past each element.
        (
            (r#""type": "VEC3""#, r#""type": "VEC2""#),
            "POSITION",
            "Vec2 of F32",
        ),
        // An empty accessor.
        ((r#""count": 4"#, r#""count": 0"#), "POSITION", "count is 0"),
        // More elements than the view holds.
        (
            (r#""count": 12"#, r#""count": 13"#),
            "indices",
            "13 elements of 2 bytes",
        ),
        // A view beyond the buffer.
        (
            (r#""byteLength": 24"#, r#""byteLength": 40"#),
            "indices",
            "outside buffer 0",
        ),
        // A stride below the element size.
        (
            (
                r#""byteLength": 48, "#,
                r#""byteLength": 48, "byteStride": 8, "#,
            ),
            "POSITION",
            "byteStride 8",
        ),
    ];
    for (edit, expected_role, needle) in cases {
        let error = edited_glb_error(edit);
        let (role, _, problem) = accessor_problem(&error);
        assert_eq!(role, expected_role, "{error}");
        assert!(problem.contains(needle), "{needle}: {problem}");
    }
}

/// Sparse positions are read; sparse indices that do not increase are refused.
#[test]
fn gltf_sparse_accessors() {
    let sparse = |count: usize| {
        format!(
            r#""count": 4, "sparse": {{"count": {count}, "indices": {{"bufferView": 1, "componentType": 5123}}, "values": {{"bufferView": 0}}}}"#
        )
    };
    let json = gltf_json(r#"{"byteLength": 72}"#, [1.0, 1.0, 1.0], 4);
    let dir = tempfile::tempdir().expect("temp dir");
    // Indices 0, 2: vertex 0 := TETRA[0], vertex 2 := TETRA[1].
    let path = write_file(
        &dir,
        "sparse.glb",
        &glb(&json.replace(r#""count": 4"#, &sparse(2)), &tetra_buffer()),
    );
    let mesh = read_mesh(&path).expect("sparse positions");
    assert_eq!(mesh.points()[2], Vec3::new(11.0, 0.0, 0.0));
    // Indices 0, 2, 1: not increasing.
    let error = edited_glb_error((r#""count": 4"#, &sparse(3)));
    let (_, _, problem) = accessor_problem(&error);
    assert!(problem.contains("sparse index 2 is 1"), "{problem}");
}

/// A node reached twice (two parents, or a cycle) would be instanced again and again.
#[test]
fn gltf_node_graphs_that_are_not_trees_are_refused() {
    let first = r#"{"mesh": 0, "translation": [10, 0, 0]}"#;
    let second = r#"{"mesh": 0, "translation": [0, 1, 0]}"#;
    for (edit, node) in [
        // Node 2 gets a second parent, node 0.
        (
            (
                first,
                r#"{"mesh": 0, "translation": [10, 0, 0], "children": [2]}"#,
            ),
            2,
        ),
        // Node 2 becomes the parent of its own parent.
        (
            (
                second,
                r#"{"mesh": 0, "translation": [0, 1, 0], "children": [1]}"#,
            ),
            1,
        ),
    ] {
        let error = edited_glb_error(edit);
        let needle = format!("node {node} is reached twice");
        assert!(
            matches!(&error, Error::Format { message, .. } if message.contains(&needle)),
            "{error}"
        );
    }
}
