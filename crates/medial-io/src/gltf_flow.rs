//! A flow of surfaces as one animated binary glTF 2.0 file (`.glb`), for any glTF viewer (a
//! browser viewer, Blender, a phone).
//!
//! Each [`AnimatedSurface`] (the boundary, the medial sheet) is a node with one child node per
//! frame; each child holds that frame's triangle mesh, its vertex colours (a value per vertex,
//! such as the local thickness, through the viridis colormap over [`FlowAnimation::value_range`])
//! and a material (double-sided; translucent when [`AnimatedSurface::opacity`] < 1). One
//! animation, `flow`, shows frame `n` from its time `t_n` until the next frame's time, and the
//! last frame for one more interval `t_N − t_{N−1}` (a looping viewer would otherwise show it
//! only at the instant it wraps to the start): each child's `scale` is animated with `STEP`
//! interpolation over the real times, `(1, 1, 1)` while its frame is shown and `(0, 0, 0)`
//! otherwise, and every frame but the first starts hidden, so that a viewer without animations
//! shows the first frame. Keyframe times are the flow times `t` themselves (a flow over
//! `t ∈ [0, 1]` in N steps plays in 1 + 1/N seconds; viewers can slow it down).
//!
//! The buffer holds `float` positions and linear-RGB colours, `unsigned int` indices shared by
//! the frames of a surface, the keyframe times and the scale keys, each in its own 4-byte
//! aligned buffer view; every accessor has its `min` and `max`. The JSON structure is built with
//! `gltf-json` and the container with the `gltf` crate's GLB writer (chunks padded to 4 bytes).

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

use gltf::json::{self, validation::Checked::Valid, validation::USize64, Index};
use medial_core::Vec3;

use crate::atomic::write_atomic;
use crate::{Error, Result};

/// One surface over the frames of a flow: fixed triangles, moving vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct AnimatedSurface {
    /// The node's name (`boundary`, `medial`).
    pub name: String,
    /// Triangles, as vertex indices.
    pub triangles: Vec<[usize; 3]>,
    /// The vertices at each frame (all frames have the same number of vertices).
    pub frames: Vec<Vec<Vec3>>,
    /// A value per vertex at each frame, shown as vertex colours; empty: no vertex colours.
    pub values: Vec<Vec<f64>>,
    /// Opacity of the material, in `(0, 1]` (1: opaque).
    pub opacity: f32,
}

/// Surfaces animated over the same frames.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowAnimation {
    /// The time of each frame, increasing (the keyframe times, seconds in a viewer).
    pub times: Vec<f64>,
    /// The surfaces.
    pub surfaces: Vec<AnimatedSurface>,
    /// The values mapped to the two ends of the colormap, `[low, high]` (the same for every
    /// surface, so that a colour means one value everywhere).
    pub value_range: [f64; 2],
    /// What the values are, with their unit (`thickness, mm`): named in the scene's name with
    /// the range and the colormap.
    pub value_name: String,
}

/// Writes `animation` as a binary glTF file, atomically (see the module documentation).
///
/// Errors: [`Error::Format`] for an animation [`glb_bytes`] refuses (nothing is written),
/// [`Error::Io`] when the file cannot be written.
pub fn write_flow_glb(path: &Path, animation: &FlowAnimation) -> Result<()> {
    let bytes = glb_bytes(animation)
        .map_err(|m| Error::format(path, format!("cannot write the animation: {m}")))?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The bytes of the binary glTF file of `animation`.
///
/// Errors (as text): no frame or no surface, times not finite or not increasing, a surface
/// whose frames or values do not match the times or each other in number, a surface without
/// triangles or with a triangle naming a missing vertex, a coordinate or value that is not finite, an opacity outside `(0, 1]`.
pub fn glb_bytes(animation: &FlowAnimation) -> std::result::Result<Vec<u8>, String> {
    check(animation)?;
    let mut doc = Document::default();
    let mut roots = Vec::new();
    let mut frame_nodes = Vec::new();
    for surface in &animation.surfaces {
        let frames = doc.surface(surface, animation);
        roots.push(doc.root.push(json::Node {
            name: Some(surface.name.clone()),
            children: Some(frames.clone()),
            ..json::Node::default()
        }));
        frame_nodes.push(frames);
    }
    if animation.times.len() > 1 {
        let flow = doc.animation(&animation.times, &frame_nodes);
        doc.root.animations.push(flow);
    }
    let [low, high] = animation.value_range;
    let scene = doc.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some(if animation.surfaces.iter().any(|s| !s.values.is_empty()) {
            format!(
                "flow; colours: {} from {low:.4} (dark purple) to {high:.4} (yellow), viridis",
                animation.value_name
            )
        } else {
            "flow".into()
        }),
        nodes: roots,
    });
    doc.root.scene = Some(scene);
    doc.finish()
}

/// The keyframe times of frames at `times` (two or more): the times, then the last one plus
/// the last interval, where the last frame is still shown.
fn keyframe_times(times: &[f64]) -> Vec<f64> {
    let mut keys = times.to_vec();
    if let [.., before, last] = *times {
        keys.push(last + (last - before));
    }
    keys
}

/// The checks of [`glb_bytes`].
fn check(animation: &FlowAnimation) -> std::result::Result<(), String> {
    let times = &animation.times;
    if times.is_empty() || animation.surfaces.is_empty() {
        return Err("an animation needs a frame and a surface".into());
    }
    if !times.iter().all(|t| t.is_finite()) || times.windows(2).any(|w| w[1] <= w[0]) {
        return Err(format!("the times must increase: {times:?}"));
    }
    if !animation.value_range.iter().all(|v| v.is_finite()) {
        return Err(format!(
            "the value range {:?} is not finite",
            animation.value_range
        ));
    }
    animation.surfaces.iter().try_for_each(|s| {
        check_surface(s, times.len()).map_err(|m| format!("surface '{}': {m}", s.name))
    })
}

/// The checks of one surface with `frames` frames.
fn check_surface(s: &AnimatedSurface, frames: usize) -> std::result::Result<(), String> {
    if s.frames.len() != frames || !(s.values.is_empty() || s.values.len() == frames) {
        return Err(format!(
            "{} frames and {} frames of values for {frames} times",
            s.frames.len(),
            s.values.len()
        ));
    }
    let n = s.frames[0].len();
    if let Some(k) = (0..frames)
        .find(|&k| s.frames[k].len() != n || s.values.get(k).is_some_and(|v| v.len() != n))
    {
        return Err(format!(
            "frame {k} has another number of vertices or values than frame 0 ({n})"
        ));
    }
    if s.triangles.is_empty() {
        return Err("no triangles".into());
    }
    if let Some(t) = s.triangles.iter().find(|t| t.iter().any(|&v| v >= n)) {
        return Err(format!(
            "triangle {t:?} names a vertex beyond the {n} vertices"
        ));
    }
    let finite = |p: &Vec3| p.iter().all(|c| c.is_finite());
    if !s.frames.iter().flatten().all(finite) || !s.values.iter().flatten().all(|v| v.is_finite()) {
        return Err("a coordinate or value is not finite".into());
    }
    if !(s.opacity > 0.0 && s.opacity <= 1.0) {
        return Err(format!("opacity {} is not in (0, 1]", s.opacity));
    }
    Ok(())
}

/// The colour of `value` on the viridis colormap over `[low, high]`, in linear RGB (glTF's
/// vertex colours are linear; the colormap is defined in sRGB).
pub fn colour(value: f64, [low, high]: [f64; 2]) -> [f32; 3] {
    let x = if high > low {
        ((value - low) / (high - low)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let c = colorous::VIRIDIS.eval_continuous(x);
    [c.r, c.g, c.b].map(|u| srgb_to_linear(f32::from(u) / 255.0))
}

/// The sRGB transfer function inverted: an sRGB component in [0, 1] as linear light.
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The glTF document being built and its binary buffer.
#[derive(Default)]
struct Document {
    root: json::Root,
    bin: Vec<u8>,
}

impl Document {
    /// Appends `bytes` as a new buffer view (4-byte aligned).
    fn view(
        &mut self,
        bytes: &[u8],
        target: Option<json::buffer::Target>,
    ) -> Index<json::buffer::View> {
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// An accessor of `f32` tuples of `type_` (`values.len()` a multiple of its size), with
    /// the component-wise `min` and `max`.
    fn floats(
        &mut self,
        values: &[f32],
        type_: json::accessor::Type,
        target: Option<json::buffer::Target>,
    ) -> Index<json::Accessor> {
        let width = type_.multiplicity();
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let bound = |pick: fn(f32, f32) -> f32| {
            let init = values[..width].to_vec();
            let b = values.chunks_exact(width).fold(init, |acc, tuple| {
                acc.iter().zip(tuple).map(|(&a, &v)| pick(a, v)).collect()
            });
            json::Value::from(b)
        };
        self.accessor(
            view,
            values.len() / width,
            json::accessor::ComponentType::F32,
            type_,
            [bound(f32::min), bound(f32::max)],
        )
    }

    fn accessor(
        &mut self,
        view: Index<json::buffer::View>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        [min, max]: [json::Value; 2],
    ) -> Index<json::Accessor> {
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: Some(USize64(0)),
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min: Some(min),
            max: Some(max),
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// The animation `flow` of the frame nodes of each surface (`frame_nodes[s][n]`, frame
    /// `n` at `times[n]`): one `STEP` sampler of the scale per frame, shared by the surfaces.
    fn animation(
        &mut self,
        times: &[f64],
        frame_nodes: &[Vec<Index<json::Node>>],
    ) -> json::Animation {
        let keys = keyframe_times(times);
        let input = self.times(&keys);
        let samplers = (0..times.len())
            .map(|n| json::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Valid(json::animation::Interpolation::Step),
                output: self.visibility(keys.len(), n),
            })
            .collect();
        let channel = |(n, &node): (usize, &Index<json::Node>)| json::animation::Channel {
            sampler: Index::new(n as u32),
            target: json::animation::Target {
                extensions: None,
                extras: Default::default(),
                node,
                path: Valid(json::animation::Property::Scale),
            },
            extensions: None,
            extras: Default::default(),
        };
        json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: frame_nodes
                .iter()
                .flat_map(|frames| frames.iter().enumerate().map(channel))
                .collect(),
            name: Some("flow".into()),
            samplers,
        }
    }

    /// The keyframe times.
    fn times(&mut self, times: &[f64]) -> Index<json::Accessor> {
        let t: Vec<f32> = times.iter().map(|&t| t as f32).collect();
        self.floats(&t, json::accessor::Type::Scalar, None)
    }

    /// The scale keys of frame `n` at `keys` keyframes (one per frame and the hold of the last
    /// frame, see [`keyframe_times`]): 1 at its keyframe (the last frame also at the hold), 0
    /// at the others.
    fn visibility(&mut self, keys: usize, n: usize) -> Index<json::Accessor> {
        let last = keys - 2;
        let keys: Vec<f32> = (0..keys)
            .flat_map(|k| {
                [if k == n || (n == last && k > last) {
                    1.0
                } else {
                    0.0
                }; 3]
            })
            .collect();
        self.floats(&keys, json::accessor::Type::Vec3, None)
    }

    /// The triangle indices of a surface.
    fn indices(&mut self, triangles: &[[usize; 3]]) -> Index<json::Accessor> {
        let ids: Vec<u32> = triangles.iter().flatten().map(|&v| v as u32).collect();
        let bytes: Vec<u8> = ids.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        let min = ids.iter().copied().min().unwrap_or(0);
        let max = ids.iter().copied().max().unwrap_or(0);
        self.accessor(
            view,
            ids.len(),
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            [json::Value::from(vec![min]), json::Value::from(vec![max])],
        )
    }

    /// The material of a surface.
    fn material(&mut self, surface: &AnimatedSurface) -> Index<json::Material> {
        let coloured = !surface.values.is_empty();
        let grey = if coloured { 1.0 } else { 0.6 };
        self.root.push(json::Material {
            name: Some(surface.name.clone()),
            double_sided: true,
            alpha_mode: Valid(if surface.opacity < 1.0 {
                json::material::AlphaMode::Blend
            } else {
                json::material::AlphaMode::Opaque
            }),
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor([
                    grey,
                    grey,
                    grey,
                    surface.opacity,
                ]),
                metallic_factor: json::material::StrengthFactor(0.0),
                roughness_factor: json::material::StrengthFactor(0.8),
                ..Default::default()
            },
            ..Default::default()
        })
    }

    /// The frame nodes of `surface` (frame 0 shown, the others hidden until animated).
    fn surface(
        &mut self,
        surface: &AnimatedSurface,
        animation: &FlowAnimation,
    ) -> Vec<Index<json::Node>> {
        let indices = self.indices(&surface.triangles);
        let material = self.material(surface);
        (0..surface.frames.len())
            .map(|n| {
                let mut attributes = BTreeMap::new();
                let positions: Vec<f32> = surface.frames[n]
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                    .collect();
                let array = Some(json::buffer::Target::ArrayBuffer);
                attributes.insert(
                    Valid(json::mesh::Semantic::Positions),
                    self.floats(&positions, json::accessor::Type::Vec3, array),
                );
                if let Some(values) = surface.values.get(n) {
                    let colours: Vec<f32> = values
                        .iter()
                        .flat_map(|&v| colour(v, animation.value_range))
                        .collect();
                    attributes.insert(
                        Valid(json::mesh::Semantic::Colors(0)),
                        self.floats(&colours, json::accessor::Type::Vec3, array),
                    );
                }
                let mesh = self.root.push(json::Mesh {
                    extensions: None,
                    extras: Default::default(),
                    name: Some(format!("{} t={}", surface.name, animation.times[n])),
                    primitives: vec![json::mesh::Primitive {
                        attributes,
                        extensions: None,
                        extras: Default::default(),
                        indices: Some(indices),
                        material: Some(material),
                        mode: Valid(json::mesh::Mode::Triangles),
                        targets: None,
                    }],
                    weights: None,
                });
                self.root.push(json::Node {
                    name: Some(format!("{} t={}", surface.name, animation.times[n])),
                    mesh: Some(mesh),
                    scale: (n > 0).then_some([0.0; 3]),
                    ..json::Node::default()
                })
            })
            .collect()
    }

    /// The GLB bytes: the JSON chunk and the binary chunk.
    fn finish(mut self) -> std::result::Result<Vec<u8>, String> {
        self.root.asset = json::Asset {
            generator: Some(format!("medial {}", env!("CARGO_PKG_VERSION"))),
            ..json::Asset::default()
        };
        self.root.buffers.push(json::Buffer {
            byte_length: USize64::from(self.bin.len()),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let text = json::serialize::to_string(&self.root).map_err(|e| e.to_string())?;
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                // Set by the writer from the chunks.
                length: 0,
            },
            json: Cow::Owned(text.into_bytes()),
            bin: Some(Cow::Owned(self.bin)),
        };
        glb.to_vec().map_err(|e| e.to_string())
    }
}
