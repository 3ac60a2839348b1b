//! A small glTF document (two instances of a tetrahedron) and its GLB container, shared by the
//! mesh tests and the mutation tests.

/// The tetrahedron's vertices.
pub const TETRA: [[f32; 3]; 4] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
];

/// Its outward triangles.
pub const TETRA_INDICES: [u16; 12] = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];

/// Positions (48 bytes) then u16 indices (24 bytes).
pub fn tetra_buffer() -> Vec<u8> {
    let mut bytes: Vec<u8> = TETRA
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    bytes.extend(TETRA_INDICES.iter().flat_map(|i| i.to_le_bytes()));
    bytes
}

/// A glTF document: node 0 = mesh translated by (10, 0, 0); node 1 = scale `scale`, with
/// child node 2 = mesh translated by (0, 1, 0). `buffer` is the buffer object's JSON.
pub fn gltf_json(buffer: &str, scale: [f32; 3], mode: u32) -> String {
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0, "translation": [10, 0, 0]}},
    {{"children": [2], "scale": [{}, {}, {}]}},
    {{"mesh": 0, "translation": [0, 1, 0]}}
  ],
  "meshes": [{{"name": "tetra", "primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "mode": {mode}}}]}}],
  "buffers": [{buffer}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 24, "target": 34963}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]}},
    {{"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}}
  ]
}}"#,
        scale[0], scale[1], scale[2]
    )
}

/// The GLB container of `json` with the binary chunk `bin`: header, JSON chunk padded with
/// spaces to 4 bytes, BIN chunk.
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = b"glTF".to_vec();
    for word in [2u32, total as u32, json.len() as u32, 0x4E4F_534A] {
        glb.extend_from_slice(&word.to_le_bytes());
    }
    glb.extend_from_slice(&json);
    for word in [bin.len() as u32, 0x004E_4942] {
        glb.extend_from_slice(&word.to_le_bytes());
    }
    glb.extend_from_slice(bin);
    glb
}

/// The document of [`gltf_json`] (unit scale, triangles) in a GLB container.
pub fn tetra_glb() -> Vec<u8> {
    glb(
        &gltf_json(r#"{"byteLength": 72}"#, [1.0, 1.0, 1.0], 4),
        &tetra_buffer(),
    )
}
