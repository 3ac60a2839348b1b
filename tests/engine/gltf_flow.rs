//! The animated glTF of a flow (`medial::io::gltf_flow`): read back with the `gltf` crate, every
//! frame's positions and colours, the accessors' bounds, the visibility animation; refusals.

use medial::io::gltf_flow::{colour, glb_bytes, AnimatedSurface, FlowAnimation};
use medial::Vec3;

/// A tetrahedron moving along x and growing, with a value per vertex rising over the frames,
/// and a triangle without values; three frames at t = 0, 0.25, 1.
fn animation() -> FlowAnimation {
    let tetra = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let frame = |k: f64| -> Vec<Vec3> {
        tetra
            .iter()
            .map(|p| Vec3::new(p[0] * (1.0 + k) + 2.0 * k, p[1], p[2] - 0.5 * k))
            .collect()
    };
    let values = |k: f64| (0..4).map(|v| f64::from(v) + k).collect::<Vec<_>>();
    FlowAnimation {
        times: vec![0.0, 0.25, 1.0],
        surfaces: vec![
            AnimatedSurface {
                name: "boundary".into(),
                triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
                frames: [0.0, 1.0, 2.0].map(frame).to_vec(),
                values: [0.0, 1.0, 2.0].map(values).to_vec(),
                opacity: 0.4,
            },
            AnimatedSurface {
                name: "medial".into(),
                triangles: vec![[0, 1, 2]],
                frames: [0.0, 1.0, 2.0].map(|k| frame(k)[..3].to_vec()).to_vec(),
                values: Vec::new(),
                opacity: 1.0,
            },
        ],
        value_range: [0.0, 5.0],
        value_name: "thickness, mm".into(),
    }
}

fn f32s(points: &[Vec3]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

#[test]
fn every_frame_reads_back_with_its_colours_and_bounds() {
    let animation = animation();
    let bytes = glb_bytes(&animation).expect("glb");
    assert_eq!(bytes.len() % 4, 0);
    let gltf = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
    let blob = gltf.blob.clone().expect("binary chunk");
    let scene = gltf.default_scene().expect("a default scene");
    assert!(scene.name().unwrap().contains("thickness, mm from 0.0000"));
    let roots: Vec<gltf::Node> = scene.nodes().collect();
    assert_eq!(roots.len(), 2);
    for (root, surface) in roots.iter().zip(&animation.surfaces) {
        assert_eq!(root.name(), Some(surface.name.as_str()));
        let frames: Vec<gltf::Node> = root.children().collect();
        assert_eq!(frames.len(), 3);
        for (n, node) in frames.iter().enumerate() {
            let scale = node.transform().decomposed().2;
            assert_eq!(scale, if n == 0 { [1.0; 3] } else { [0.0; 3] });
            let primitive = node.mesh().expect("mesh").primitives().next().unwrap();
            let reader = primitive.reader(|_| Some(&blob));
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            assert_eq!(positions, f32s(&surface.frames[n]));
            let bounds = primitive.bounding_box();
            for axis in 0..3 {
                let column = positions.iter().map(|p| p[axis]);
                assert_eq!(bounds.min[axis], column.clone().fold(f32::MAX, f32::min));
                assert_eq!(bounds.max[axis], column.fold(f32::MIN, f32::max));
            }
            let triangles: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            let expected: Vec<u32> = surface
                .triangles
                .iter()
                .flatten()
                .map(|&v| v as u32)
                .collect();
            assert_eq!(triangles, expected);
            let colours = reader
                .read_colors(0)
                .map(|c| c.into_rgb_f32().collect::<Vec<_>>());
            let expected = surface.values.get(n).map(|values| {
                values
                    .iter()
                    .map(|&v| colour(v, animation.value_range))
                    .collect::<Vec<_>>()
            });
            assert_eq!(colours, expected, "{} frame {n}", surface.name);
            let material = primitive.material();
            assert!(material.double_sided());
            let blend = material.alpha_mode() == gltf::material::AlphaMode::Blend;
            assert_eq!(blend, surface.opacity < 1.0);
        }
    }
    // One STEP sampler per frame over the real times: frame n is shown (scale 1) from t_n on,
    // the last frame for one more interval (0.75).
    let flow = gltf.animations().next().expect("an animation");
    let channels: Vec<gltf::animation::Channel> = flow.channels().collect();
    assert_eq!(channels.len(), 6);
    for channel in &channels {
        let node = channel.target().node();
        let n = roots
            .iter()
            .find_map(|r| r.children().position(|c| c.index() == node.index()))
            .expect("the channel animates a frame node");
        assert_eq!(
            channel.sampler().interpolation(),
            gltf::animation::Interpolation::Step
        );
        let reader = channel.reader(|_| Some(&blob));
        let times: Vec<f32> = reader.read_inputs().unwrap().collect();
        assert_eq!(times, [0.0, 0.25, 1.0, 1.75]);
        let Some(gltf::animation::util::ReadOutputs::Scales(scales)) = reader.read_outputs() else {
            panic!("scale outputs");
        };
        let shown: Vec<bool> = scales.map(|s| s == [1.0; 3]).collect();
        let expected: Vec<bool> = (0..4).map(|k| k == n || (n == 2 && k == 3)).collect();
        assert_eq!(shown, expected);
    }
}

#[test]
fn viridis_in_linear_rgb() {
    // Viridis runs from dark purple-blue (68, 1, 84) to yellow (253, 231, 37) in sRGB.
    let low = colour(-1.0, [0.0, 2.0]);
    let high = colour(2.0, [0.0, 2.0]);
    let linear = |c: f32| ((c / 255.0 + 0.055) / 1.055).powf(2.4);
    assert!(
        (low[0] - linear(68.0)).abs() < 0.01 && low[1] < 0.001,
        "{low:?}"
    );
    assert!(
        (high[0] - linear(253.0)).abs() < 0.01 && high[2] < 0.03,
        "{high:?}"
    );
    assert_eq!(colour(7.0, [3.0, 3.0]), colour(0.5, [0.0, 1.0]));
}

/// A change that makes an animation inconsistent.
type Spoil = fn(&mut FlowAnimation);

#[test]
fn refuses_inconsistent_animations() {
    let cases: [(Spoil, &str); 6] = [
        (
            |a| a.surfaces[1].triangles.clear(),
            "'medial': no triangles",
        ),
        (|a| a.times[1] = 0.0, "the times must increase"),
        (|a| a.surfaces[0].frames.truncate(2), "2 frames"),
        (
            |a| a.surfaces[1].frames[2].truncate(2),
            "frame 2 has another",
        ),
        (
            |a| a.surfaces[1].triangles.push([0, 1, 3]),
            "beyond the 3 vertices",
        ),
        (|a| a.surfaces[0].values[1][0] = f64::NAN, "not finite"),
    ];
    for (spoil, needle) in cases {
        let mut a = animation();
        spoil(&mut a);
        let err = glb_bytes(&a).expect_err(needle);
        assert!(err.contains(needle), "{err} lacks {needle}");
    }
}

#[test]
fn one_frame_is_a_still_model() {
    let mut a = animation();
    a.times.truncate(1);
    for s in &mut a.surfaces {
        s.frames.truncate(1);
        s.values.truncate(1);
    }
    let gltf = gltf::Gltf::from_slice(&glb_bytes(&a).expect("glb")).expect("valid glTF");
    assert_eq!(gltf.animations().count(), 0);
    let scene = gltf.default_scene().unwrap();
    assert!(scene.nodes().all(|n| n.children().count() == 1));
    // Every accessor is used: positions, colours of the boundary and the indices of each.
    assert_eq!(gltf.accessors().count(), 5);
}
