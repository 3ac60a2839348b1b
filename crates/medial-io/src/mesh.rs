//! Triangle meshes in the formats users bring, chosen by file extension (case-insensitive):
//! legacy VTK polydata (`.vtk`), Wavefront OBJ (`.obj`) and glTF 2.0 (`.gltf`, `.glb`).
//!
//! Vertex order is kept as in the file, so that vertex `i` of a subject can correspond to
//! vertex `i` of a template: the OBJ reader therefore parses `v` and `f` statements itself
//! (`tobj` renumbers vertices in order of first use). Non-triangle faces are refused, never
//! triangulated behind the user's back.

use std::collections::HashSet;
use std::fmt::Display;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use gltf::accessor::{DataType, Dimensions};
use medial_core::{TriMesh, Vec3};
use nalgebra::{Matrix4, Point3};

use crate::atomic::write_atomic;
use crate::vtk::{self, WriteOptions};
use crate::{Error, Result};

/// The mesh formats, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MeshFormat {
    Vtk,
    Obj,
    Gltf,
}

const SUPPORTED: &str = "supported: .vtk, .obj, .gltf, .glb";

impl MeshFormat {
    fn of(path: &Path) -> Result<Self> {
        let extension = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .ok_or_else(|| {
                Error::format(
                    path,
                    format!("the file name has no extension ({SUPPORTED})"),
                )
            })?;
        match extension.as_str() {
            "vtk" => Ok(MeshFormat::Vtk),
            "obj" => Ok(MeshFormat::Obj),
            "gltf" | "glb" => Ok(MeshFormat::Gltf),
            other => Err(Error::format(
                path,
                format!("unknown mesh extension '.{other}' ({SUPPORTED})"),
            )),
        }
    }
}

/// Reads a triangle mesh, the format chosen by the extension:
/// - `.vtk`: [`vtk::read_trimesh`] (polygons must all be triangles);
/// - `.obj`: the `v` (first three coordinates) and `f` statements, in file order, with
///   `i`, `i/t`, `i//n`, `i/t/n` and negative (relative) indices; everything else (normals,
///   texture coordinates, groups, materials, lines) is ignored; faces must be triangles;
/// - `.gltf`/`.glb`: the `TRIANGLES` primitives of every mesh instance of the default scene
///   (else the first scene; else of every root node; else of every mesh, untransformed),
///   node transforms applied (winding reversed under mirroring transforms), merged in document
///   order without welding vertices; buffers may be embedded, in the GLB chunk, or external
///   files beside the glTF.
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Format`] for an unknown
/// extension (listing the supported ones), a malformed file, a non-triangle face or primitive
/// mode; [`Error::Model`] when [`TriMesh::new`] refuses the mesh (index out of range, repeated
/// corner, non-finite point).
pub fn read_mesh(path: &Path) -> Result<TriMesh> {
    match MeshFormat::of(path)? {
        MeshFormat::Vtk => vtk::read_trimesh(path),
        MeshFormat::Obj => parse_obj(&read_bytes(path)?, path),
        MeshFormat::Gltf => parse_gltf(&read_bytes(path)?, path),
    }
}

/// Reads the points of a mesh or point set, in file order: those of any legacy VTK polydata
/// (`.vtk`, whatever its cells: a point cloud is fine), else those of [`read_mesh`].
///
/// Errors: as [`vtk::read_polydata`] for `.vtk`, else as [`read_mesh`].
pub fn read_points(path: &Path) -> Result<Vec<Vec3>> {
    Ok(match MeshFormat::of(path) {
        Ok(MeshFormat::Vtk) => vtk::read_polydata(path)?.points,
        _ => read_mesh(path)?.into_parts().0,
    })
}

/// Writes a triangle mesh atomically, the format chosen by the extension: `.vtk` (ASCII,
/// `# vtk DataFile Version 4.2` layout, points as `double`) or `.obj` (`v x y z` lines then
/// 1-based `f a b c` lines). Coordinates are written in the shortest form that reads back to
/// the same `f64`.
///
/// Errors: [`Error::Format`] for other extensions (glTF is read-only); [`Error::Io`] when the
/// file cannot be written.
pub fn write_mesh(path: &Path, mesh: &TriMesh) -> Result<()> {
    match MeshFormat::of(path)? {
        MeshFormat::Vtk => vtk::write_trimesh(path, mesh, WriteOptions::default()),
        MeshFormat::Obj => {
            let bytes = obj_bytes(mesh);
            write_atomic(path, |w| w.write_all(&bytes))
        }
        MeshFormat::Gltf => Err(Error::format(
            path,
            "writing glTF is not supported; write the mesh as .vtk or .obj",
        )),
    }
}

fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

// ---------------------------------------------------------------------------------------------
// OBJ.

/// Parses the bytes of a Wavefront OBJ file as [`read_mesh`] reads `.obj` (`path` is only used
/// in error messages).
///
/// Errors: [`Error::Format`] for a malformed `v` or `f` statement or a non-triangle face
/// (naming the line); [`Error::Model`] when [`TriMesh::new`] refuses the mesh.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    let mut points = Vec::new();
    let mut triangles = Vec::new();
    for (number, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let error =
            |message: String| Error::format(path, format!("{message} (line {})", number + 1));
        let content = line.split(|&b| b == b'#').next().unwrap_or_default();
        let mut words = content
            .split(|b| b.is_ascii_whitespace())
            .filter(|w| !w.is_empty());
        match words.next() {
            Some(b"v") => points.push(obj_vertex(words).map_err(error)?),
            Some(b"f") => triangles.push(obj_face(words, points.len()).map_err(error)?),
            _ => {}
        }
    }
    TriMesh::new(points, triangles).map_err(|e| Error::model(path, e))
}

/// `v x y z [w | r g b]`: the first three coordinates.
fn obj_vertex<'a>(words: impl Iterator<Item = &'a [u8]>) -> std::result::Result<Vec3, String> {
    let coordinates = words
        .take(3)
        .map(|w| {
            std::str::from_utf8(w)
                .ok()
                .and_then(|t| t.parse::<f64>().ok())
                .ok_or_else(|| format!("'{}' is not a number", String::from_utf8_lossy(w)))
        })
        .collect::<std::result::Result<Vec<f64>, String>>()?;
    match coordinates.as_slice() {
        &[x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!(
            "a vertex needs 3 coordinates, found {}",
            coordinates.len()
        )),
    }
}

/// `f a b c` with `a` = `i`, `i/t`, `i//n` or `i/t/n`; `i` 1-based, or negative counting back
/// from the last vertex defined so far.
fn obj_face<'a>(
    words: impl Iterator<Item = &'a [u8]>,
    defined: usize,
) -> std::result::Result<[usize; 3], String> {
    let corners = words
        .map(|w| obj_index(w, defined))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    match corners.as_slice() {
        &[a, b, c] => Ok([a, b, c]),
        _ => Err(format!(
            "a face with {} vertices; only triangles are supported (triangulate the mesh first)",
            corners.len()
        )),
    }
}

fn obj_index(word: &[u8], defined: usize) -> std::result::Result<usize, String> {
    let text = String::from_utf8_lossy(word);
    let position = text.split('/').next().unwrap_or_default();
    let index: i64 = position
        .parse()
        .map_err(|_| format!("'{text}' is not a face vertex"))?;
    let resolved = match index {
        0 => None,
        i if i > 0 => usize::try_from(i - 1).ok(),
        i => usize::try_from(i.unsigned_abs())
            .ok()
            .and_then(|back| defined.checked_sub(back)),
    };
    resolved.ok_or_else(|| {
        format!("face vertex {index} is invalid ({defined} vertices defined so far)")
    })
}

fn obj_bytes(mesh: &TriMesh) -> Vec<u8> {
    let mut out = Vec::new();
    // Writing to a Vec<u8> cannot fail.
    let _ = writeln!(
        out,
        "# written by medial: {} vertices, {} triangles",
        mesh.points().len(),
        mesh.triangles().len()
    );
    for p in mesh.points() {
        out.push(b'v');
        for c in [p.x, p.y, p.z] {
            out.push(b' ');
            vtk::push_f64(&mut out, c);
        }
        out.push(b'\n');
    }
    for [a, b, c] in mesh.triangles() {
        let _ = writeln!(out, "f {} {} {}", a + 1, b + 1, c + 1);
    }
    out
}

// ---------------------------------------------------------------------------------------------
// glTF.

/// Parses the bytes of a glTF 2.0 file (JSON `.gltf` or binary `.glb`, told apart by the GLB
/// magic) as [`read_mesh`] reads it; external buffers are resolved against the folder of
/// `path`, which error messages name.
///
/// Errors: as [`read_mesh`] for `.gltf`/`.glb`, and [`Error::Accessor`] for an accessor that
/// cannot be read as what its primitive uses it for.
pub fn parse_gltf(bytes: &[u8], path: &Path) -> Result<TriMesh> {
    let invalid = |e: gltf::Error| Error::format(path, format!("invalid glTF: {e}"));
    check_glb_length(bytes, path)?;
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    // The crate's validation itself indexes the POSITION accessors without a check.
    check_position_indices(document.as_json(), path)?;
    let document = gltf::Document::from_json(document.into_json()).map_err(invalid)?;
    check_buffer_files(&document, path)?;
    let buffers = gltf::import_buffers(&document, path.parent(), blob)
        .map_err(|e| Error::format(path, format!("cannot load the glTF buffers: {e}")))?;
    let mut points = Vec::new();
    let mut triangles = Vec::new();
    for (mesh, transform) in mesh_instances(&document, path)? {
        for primitive in mesh.primitives() {
            let at = PrimitiveAt {
                path,
                mesh: &mesh,
                primitive: &primitive,
            };
            add_primitive(&mut points, &mut triangles, &at, &buffers, &transform)?;
        }
    }
    TriMesh::new(points, triangles).map_err(|e| Error::model(path, e))
}

/// The magic number that opens a GLB file.
const GLB_MAGIC: &[u8] = b"glTF";

/// Bytes of the GLB header: magic, version and the length of the whole file (u32 each).
const GLB_HEADER_BYTES: u32 = 12;

/// Refuses a GLB header whose length is below the header's own 12 bytes (the `gltf` crate
/// subtracts them without a check).
fn check_glb_length(bytes: &[u8], path: &Path) -> Result<()> {
    let declared = bytes
        .strip_prefix(GLB_MAGIC)
        .and_then(|rest| rest.get(4..8))
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    match declared {
        Some(length) if length < GLB_HEADER_BYTES => Err(Error::format(
            path,
            format!(
                "invalid glTF: the GLB header declares {length} bytes in all, fewer than the \
                 {GLB_HEADER_BYTES} of the header itself"
            ),
        )),
        _ => Ok(()),
    }
}

/// Refuses a `POSITION` attribute that names an accessor the document does not have.
fn check_position_indices(root: &gltf::json::Root, path: &Path) -> Result<()> {
    let positions = gltf::json::validation::Checked::Valid(gltf::json::mesh::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            match primitive.attributes.get(&positions) {
                Some(index) if index.value() >= root.accessors.len() => {
                    return Err(Error::Accessor {
                        path: path.into(),
                        mesh: m,
                        primitive: p,
                        role: "POSITION",
                        accessor: index.value(),
                        problem: format!(
                            "no such accessor (the document has {})",
                            root.accessors.len()
                        ),
                    })
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// Refuses an external buffer that the `gltf` crate cannot load safely (it resolves `file:`
/// and relative URIs against the folder of `path`, as done here): a relative URI that is not
/// UTF-8 once percent-decoded (the crate panics) and a file that is not a regular file (a
/// device or a pipe such as `/dev/zero` would be read without end). Data URIs, other schemes
/// and missing files are left to the crate's own errors.
fn check_buffer_files(document: &gltf::Document, path: &Path) -> Result<()> {
    let Some(folder) = path.parent() else {
        return Ok(());
    };
    for buffer in document.buffers() {
        let gltf::buffer::Source::Uri(uri) = buffer.source() else {
            continue;
        };
        let file = if uri.contains(':') {
            match uri
                .strip_prefix("file://")
                .or_else(|| uri.strip_prefix("file:"))
            {
                Some(file) => PathBuf::from(file),
                None => continue,
            }
        } else {
            let decoded = urlencoding::decode(uri).map_err(|_| {
                Error::format(
                    path,
                    format!(
                        "buffer {}: the uri {uri:?} is not UTF-8 once percent-decoded",
                        buffer.index()
                    ),
                )
            })?;
            folder.join(&*decoded)
        };
        if std::fs::metadata(&file).is_ok_and(|m| !m.is_file()) {
            return Err(Error::format(
                path,
                format!(
                    "buffer {}: {} is not a regular file",
                    buffer.index(),
                    file.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Every mesh instance with its world transform, in document (depth-first) order.
fn mesh_instances<'a>(
    document: &'a gltf::Document,
    path: &Path,
) -> Result<Vec<(gltf::Mesh<'a>, Matrix4<f64>)>> {
    let roots: Vec<gltf::Node> = match document
        .default_scene()
        .or_else(|| document.scenes().next())
    {
        Some(scene) => scene.nodes().collect(),
        None => {
            let children: HashSet<usize> = document
                .nodes()
                .flat_map(|n| n.children().map(|c| c.index()))
                .collect();
            document
                .nodes()
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    };
    let mut stack: Vec<(gltf::Node, Matrix4<f64>)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Matrix4::identity()))
        .collect();
    let mut visited = HashSet::new();
    let mut instances = Vec::new();
    while let Some((node, parent)) = stack.pop() {
        // A node reached twice would be instanced again and again (or forever, in a cycle).
        if !visited.insert(node.index()) {
            return Err(Error::format(
                path,
                format!(
                    "the glTF node hierarchy has a cycle or a node with several parents: node \
                     {} is reached twice",
                    node.index()
                ),
            ));
        }
        let columns = node.transform().matrix();
        let world = parent * Matrix4::from_fn(|r, c| f64::from(columns[c][r]));
        if let Some(mesh) = node.mesh() {
            instances.push((mesh, world));
        }
        stack.extend(
            node.children()
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .map(|c| (c, world)),
        );
    }
    if instances.is_empty() {
        instances = document
            .meshes()
            .map(|m| (m, Matrix4::identity()))
            .collect();
    }
    Ok(instances)
}

/// A primitive of a glTF file, for error messages.
struct PrimitiveAt<'a> {
    /// The file.
    path: &'a Path,
    /// The mesh holding the primitive.
    mesh: &'a gltf::Mesh<'a>,
    /// The primitive.
    primitive: &'a gltf::Primitive<'a>,
}

impl PrimitiveAt<'_> {
    /// A format error naming the mesh (and its name) and the primitive.
    fn format_error(&self, message: impl Display) -> Error {
        let name = self
            .mesh
            .name()
            .map(|n| format!(" '{n}'"))
            .unwrap_or_default();
        Error::format(
            self.path,
            format!(
                "mesh {}{name}, primitive {}: {message}",
                self.mesh.index(),
                self.primitive.index()
            ),
        )
    }

    /// Checks that `accessor`, used as `role`, has one of the element `types` and lies in its
    /// buffers (see [`accessor_problem`]).
    fn check_accessor(
        &self,
        role: &'static str,
        accessor: &gltf::Accessor,
        types: &[ElementType],
        buffers: &[gltf::buffer::Data],
    ) -> Result<()> {
        match accessor_problem(accessor, types, buffers) {
            None => Ok(()),
            Some(problem) => Err(Error::Accessor {
                path: self.path.into(),
                mesh: self.mesh.index(),
                primitive: self.primitive.index(),
                role,
                accessor: accessor.index(),
                problem,
            }),
        }
    }
}

/// The component type and the number of components of an accessor's elements.
type ElementType = (DataType, Dimensions);

/// What a `POSITION` accessor may hold: 3 floats.
const POSITION_TYPES: [ElementType; 1] = [(DataType::F32, Dimensions::Vec3)];

/// What an `indices` accessor may hold: unsigned integers of 8, 16 or 32 bits.
const INDEX_TYPES: [ElementType; 3] = [
    (DataType::U8, Dimensions::Scalar),
    (DataType::U16, Dimensions::Scalar),
    (DataType::U32, Dimensions::Scalar),
];

/// Appends the vertices (transformed) and triangles of one `TRIANGLES` primitive.
///
/// The accessors are checked before the `gltf` crate reads them: its reader panics on an
/// element type it does not expect and trusts counts, offsets and strides.
fn add_primitive(
    points: &mut Vec<Vec3>,
    triangles: &mut Vec<[usize; 3]>,
    at: &PrimitiveAt,
    buffers: &[gltf::buffer::Data],
    transform: &Matrix4<f64>,
) -> Result<()> {
    let primitive = at.primitive;
    let mode = primitive.mode();
    if mode != gltf::mesh::Mode::Triangles {
        return Err(at.format_error(format!("mode {mode:?} is not supported, only TRIANGLES")));
    }
    let position = primitive
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| at.format_error("no POSITION attribute"))?;
    at.check_accessor("POSITION", &position, &POSITION_TYPES, buffers)?;
    if let Some(indices) = primitive.indices() {
        at.check_accessor("indices", &indices, &INDEX_TYPES, buffers)?;
    }
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| d.0.as_slice()));
    let positions = reader
        .read_positions()
        .ok_or_else(|| at.format_error("no POSITION attribute"))?;
    let base = points.len();
    points.extend(positions.map(|[x, y, z]| {
        let p = Point3::new(f64::from(x), f64::from(y), f64::from(z));
        transform.transform_point(&p).coords
    }));
    let count = points.len() - base;
    let indices: Vec<usize> = match reader.read_indices() {
        Some(indices) => indices.into_u32().map(|i| i as usize).collect(),
        None => (0..count).collect(),
    };
    if indices.len() % 3 != 0 {
        return Err(at.format_error(format!("{} indices, not a multiple of 3", indices.len())));
    }
    if let Some(bad) = indices.iter().find(|&&i| i >= count) {
        return Err(at.format_error(format!(
            "index {bad} but the primitive has {count} vertices"
        )));
    }
    let mirrored = transform.fixed_view::<3, 3>(0, 0).determinant() < 0.0;
    triangles.extend(indices.chunks_exact(3).map(|t| {
        let [a, b, c] = [base + t[0], base + t[1], base + t[2]];
        if mirrored {
            [a, c, b]
        } else {
            [a, b, c]
        }
    }));
    Ok(())
}

/// Why the `gltf` crate cannot safely read `accessor` as one of `types`, if it cannot: another
/// element type, no element, no data (neither a buffer view nor sparse values), elements
/// outside their buffer view or a view outside its buffer, a stride below the element size, or
/// sparse indices that do not strictly increase below the count.
fn accessor_problem(
    accessor: &gltf::Accessor,
    types: &[ElementType],
    buffers: &[gltf::buffer::Data],
) -> Option<String> {
    let element = (accessor.data_type(), accessor.dimensions());
    if !types.contains(&element) {
        let expected: Vec<String> = types
            .iter()
            .map(|(t, d)| format!("{d:?} of {t:?}"))
            .collect();
        return Some(format!(
            "elements are {:?} of {:?}; expected {}",
            element.1,
            element.0,
            expected.join(", ")
        ));
    }
    let count = accessor.count();
    if count == 0 {
        return Some("count is 0".into());
    }
    let size = accessor.size();
    let sparse = accessor.sparse();
    match accessor.view() {
        Some(view) => {
            if let Err(problem) = elements(&view, accessor.offset(), count, size, buffers) {
                return Some(problem);
            }
        }
        None if sparse.is_none() => {
            return Some("no bufferView and no sparse values: no data".into());
        }
        None => {}
    }
    let sparse = sparse?;
    let n = sparse.count();
    if n == 0 || n > count {
        return Some(format!(
            "{n} sparse values for {count} elements (1 to {count} allowed)"
        ));
    }
    let values = sparse.values();
    if let Err(problem) = elements(&values.view(), values.offset(), n, size, buffers) {
        return Some(format!("sparse values: {problem}"));
    }
    let indices = sparse.indices();
    let index_size = indices.index_type().size();
    let (bytes, stride) = match elements(&indices.view(), indices.offset(), n, index_size, buffers)
    {
        Ok(found) => found,
        Err(problem) => return Some(format!("sparse indices: {problem}")),
    };
    let index = |i: usize| {
        let b = &bytes[i * stride..i * stride + index_size];
        b.iter()
            .rev()
            .fold(0usize, |v, &byte| v << 8 | usize::from(byte))
    };
    let mut previous = None;
    for i in 0..n {
        let current = index(i);
        if current >= count || previous.is_some_and(|p| current <= p) {
            return Some(format!(
                "sparse index {i} is {current}: sparse indices must increase strictly and stay \
                 below the count {count}"
            ));
        }
        previous = Some(current);
    }
    None
}

/// The bytes of `count ≥ 1` elements of `size` bytes from byte `offset` of `view` (each
/// `view.stride()` bytes apart, or packed), from the first to the end of the last, and the
/// stride; or why they do not lie in the view, or the view in its buffer.
fn elements<'a>(
    view: &gltf::buffer::View,
    offset: usize,
    count: usize,
    size: usize,
    buffers: &'a [gltf::buffer::Data],
) -> std::result::Result<(&'a [u8], usize), String> {
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "buffer view {} has byteStride {stride}, below the element size {size}",
            view.index()
        ));
    }
    let buffer = view.buffer().index();
    let view_bytes = buffers
        .get(buffer)
        .and_then(|data| {
            data.0
                .get(view.offset()..view.offset().checked_add(view.length())?)
        })
        .ok_or_else(|| {
            format!(
                "buffer view {} (bytes {} to {}) lies outside buffer {buffer} ({} bytes)",
                view.index(),
                view.offset(),
                view.offset().saturating_add(view.length()),
                buffers.get(buffer).map_or(0, |d| d.0.len())
            )
        })?;
    (count - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(size))
        .and_then(|n| n.checked_add(offset))
        .and_then(|end| view_bytes.get(offset..end))
        .map(|bytes| (bytes, stride))
        .ok_or_else(|| {
            format!(
                "{count} elements of {size} bytes (stride {stride}) from byte {offset} do not fit \
                 buffer view {} ({} bytes)",
                view.index(),
                view_bytes.len()
            )
        })
}
