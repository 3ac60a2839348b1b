//! The varifold, oriented-varifold and current attachments on real surfaces (the t001 cmrep
//! template, the KeOps hippocampi): gradient against central finite differences, value and
//! gradient against the dense reference, invariants (g ≥ 0, zero at the target, no
//! correspondence needed, rigid motions, orientation), determinism across thread counts, the
//! width rule and the errors.

use std::sync::OnceLock;

use medial::attachment::varifold::{
    default_width, Kind, Varifold, VarifoldParams, DEFAULT_NORMAL_WIDTH,
};
use medial::attachment::Attachment;
use medial::testing::varifold_dense::{self, subdivided};
use medial::{Error, MedialTemplate, TriMesh, Vec3};
use nalgebra::{Rotation3, Unit};
use proptest::prelude::*;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/");

const KINDS: [Kind; 3] = [
    Kind::Varifold,
    Kind::OrientedVarifold {
        normal_width: DEFAULT_NORMAL_WIDTH,
    },
    Kind::Current,
];

fn t001() -> &'static MedialTemplate {
    static T001: OnceLock<MedialTemplate> = OnceLock::new();
    T001.get_or_init(|| {
        let path = format!("{DATA}cmrep/t001_template_bcmrep.vtk");
        medial::io::cmrep::read_template(path.as_ref()).expect("the t001 template")
    })
}

/// The reduced KeOps hippocampi (1,320 triangles each): source and target.
fn hippos() -> &'static (TriMesh, TriMesh) {
    static HIPPOS: OnceLock<(TriMesh, TriMesh)> = OnceLock::new();
    HIPPOS.get_or_init(|| {
        let read = |name: &str| {
            let path = format!("{DATA}keops/hippos_reduc_{name}.vtk");
            medial::io::vtk::read_trimesh(path.as_ref()).expect("a hippocampus")
        };
        (read("source"), read("target"))
    })
}

/// The t001 boundary as a mesh at the landmark positions `q`.
fn boundary(q: &[Vec3]) -> TriMesh {
    let t = t001();
    TriMesh::new(
        q[..t.boundary_count()].to_vec(),
        t.boundary_triangles().to_vec(),
    )
    .unwrap()
}

/// A smooth deformation of amplitude `amplitude` (mm) and wavelength about 30 mm.
fn warp(p: &Vec3, amplitude: f64, phase: f64) -> Vec3 {
    let w = 0.2;
    p + amplitude
        * Vec3::new(
            (w * p.y + phase).sin(),
            (w * p.z - phase).cos(),
            (w * p.x + 2.0 * phase).sin(),
        )
}

fn warped(mesh: &TriMesh, amplitude: f64, phase: f64) -> TriMesh {
    let points = mesh.points().iter().map(|p| warp(p, amplitude, phase));
    TriMesh::new(points.collect(), mesh.triangles().to_vec()).unwrap()
}

/// The same surface with its points and triangles shuffled and each triangle's corners rotated
/// (orientation kept).
fn reindexed(mesh: &TriMesh, seed: u64) -> TriMesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut order: Vec<usize> = (0..mesh.points().len()).collect();
    order.shuffle(&mut rng);
    let mut new_index = vec![0; order.len()];
    for (new, &old) in order.iter().enumerate() {
        new_index[old] = new;
    }
    let points = order.iter().map(|&old| mesh.points()[old]).collect();
    let mut triangles: Vec<[usize; 3]> = (mesh.triangles().iter())
        .map(|t| {
            let mut t = t.map(|v| new_index[v]);
            t.rotate_left(rng.gen_range(0..3));
            t
        })
        .collect();
    triangles.shuffle(&mut rng);
    TriMesh::new(points, triangles).unwrap()
}

fn flipped(mesh: &TriMesh) -> TriMesh {
    let triangles = mesh.triangles().iter().map(|&[a, b, c]| [a, c, b]);
    TriMesh::new(mesh.points().to_vec(), triangles.collect()).unwrap()
}

/// The attachment of the t001 boundary (over all its landmarks) to `target`.
fn t001_attachment(target: &TriMesh, kind: Kind, width: Option<f64>) -> Varifold {
    let t = t001();
    let params = VarifoldParams { kind, width };
    Varifold::new(t.boundary_triangles(), t.landmark_count(), target, params).unwrap()
}

/// The t001 target of the gradient tests: its boundary warped by 2 mm, subdivided (2,496
/// triangles) and reindexed.
fn t001_target() -> TriMesh {
    reindexed(
        &subdivided(&warped(&boundary(t001().landmarks()), 2.0, 0.3)),
        7,
    )
}

fn value_and_gradient(a: &Varifold, q: &[Vec3]) -> (f64, Vec<Vec3>) {
    let mut grad = vec![Vec3::zeros(); q.len()];
    let value = a.evaluate(q, Some(&mut grad)).unwrap().value;
    (value, grad)
}

fn value(a: &Varifold, q: &[Vec3]) -> f64 {
    a.evaluate(q, None).unwrap().value
}

/// `max_i |a_i − b_i| / max_i |b_i|`.
fn relative_difference(a: &[Vec3], b: &[Vec3]) -> f64 {
    let scale = b.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let diff = a.iter().zip(b).map(|(x, y)| (x - y).norm());
    diff.fold(0.0, f64::max) / scale
}

#[test]
fn gradient_matches_central_differences() {
    let t = t001();
    let nb = t.boundary_count();
    let target = t001_target();
    // The model 1 mm off the target and warped otherwise, so that no term vanishes.
    let q: Vec<Vec3> = (t.landmarks().iter())
        .map(|p| warp(p, 1.0, 1.1) + Vec3::new(0.5, -0.3, 0.2))
        .collect();
    let h = 1e-4;
    for kind in KINDS {
        let a = t001_attachment(&target, kind, None);
        let (g, grad) = value_and_gradient(&a, &q);
        assert!(g > 0.0);
        assert!(grad[nb..].iter().all(|v| *v == Vec3::zeros()));
        let central = |dir: &dyn Fn(usize) -> Vec3| {
            let moved = |s: f64| -> Vec<Vec3> {
                (q.iter().enumerate())
                    .map(|(i, p)| p + s * dir(i))
                    .collect()
            };
            (value(&a, &moved(h)) - value(&a, &moved(-h))) / (2.0 * h)
        };
        // Along random directions of all the boundary points …
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..3 {
            let dirs: Vec<Vec3> = (0..q.len())
                .map(|i| match i < nb {
                    true => Vec3::from_fn(|_, _| rng.gen_range(-1.0..1.0)),
                    false => Vec3::zeros(),
                })
                .collect();
            let fd = central(&|i| dirs[i]);
            let exact: f64 = grad.iter().zip(&dirs).map(|(g, d)| g.dot(d)).sum();
            let err = (fd - exact).abs() / exact.abs();
            assert!(
                err < 1e-6,
                "{kind:?}: directional {fd} vs {exact} ({err:.1e})"
            );
        }
        // … and along each coordinate of the points with the largest gradients.
        let mut by_size: Vec<usize> = (0..nb).collect();
        by_size.sort_by(|&i, &j| grad[j].norm().total_cmp(&grad[i].norm()));
        for &i in &by_size[..6] {
            for c in 0..3 {
                let fd = central(&|j| {
                    if j == i {
                        Vec3::ith(c, 1.0)
                    } else {
                        Vec3::zeros()
                    }
                });
                let err = (fd - grad[i][c]).abs() / grad[i].norm();
                assert!(
                    err < 1e-6,
                    "{kind:?}: ∂g/∂q[{i}][{c}] {fd} vs {}",
                    grad[i][c]
                );
            }
        }
    }
}

#[test]
fn matches_the_dense_reference() {
    let (source, target) = hippos();
    let q = source.points();
    for kind in KINDS {
        let a = Varifold::new(
            source.triangles(),
            q.len(),
            target,
            VarifoldParams { kind, width: None },
        )
        .unwrap();
        let (g, grad) = value_and_gradient(&a, q);
        let (dense_g, dense_grad) = varifold_dense::attachment(
            q,
            source.triangles(),
            target.points(),
            target.triangles(),
            kind,
            a.width(),
        );
        let value_err = (g - dense_g).abs() / dense_g;
        assert!(value_err < 1e-10, "{kind:?}: g = {g} vs {dense_g}");
        let grad_err = relative_difference(&grad, &dense_grad);
        assert!(grad_err < 1e-10, "{kind:?}: gradient off by {grad_err:.1e}");
        let (tt, _) = varifold_dense::attachment(
            target.points(),
            &[],
            target.points(),
            target.triangles(),
            kind,
            a.width(),
        );
        assert!(
            (a.target_norm2() - tt).abs() < 1e-10 * tt,
            "{kind:?}: ⟨T,T⟩"
        );
    }
}

#[test]
fn same_bits_with_one_and_two_threads() {
    let (source, target) = hippos();
    for kind in KINDS {
        let params = VarifoldParams { kind, width: None };
        let a = Varifold::new(source.triangles(), source.points().len(), target, params).unwrap();
        let with_threads = |n| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap();
            pool.install(|| value_and_gradient(&a, source.points()))
        };
        let (one, two) = (with_threads(1), with_threads(2));
        assert_eq!(one.0.to_bits(), two.0.to_bits(), "{kind:?}");
        assert_eq!(one.1, two.1, "{kind:?}");
    }
}

#[test]
fn zero_with_a_critical_point_at_the_target_in_any_order() {
    let q = t001().landmarks();
    let target = reindexed(&boundary(q), 11);
    for kind in KINDS {
        let a = t001_attachment(&target, kind, None);
        let (g, grad) = value_and_gradient(&a, q);
        let tt = a.target_norm2();
        assert!(g.abs() < 1e-12 * tt, "{kind:?}: g = {g}, ⟨T,T⟩ = {tt}");
        // The gradient vanishes to the round-off of its terms, of the size of ∇⟨S,S⟩ (the
        // gradient with the target far away).
        let far = TriMesh::new(
            target
                .points()
                .iter()
                .map(|p| p + Vec3::repeat(1e4))
                .collect(),
            target.triangles().to_vec(),
        )
        .unwrap();
        let (_, self_grad) = value_and_gradient(&t001_attachment(&far, kind, None), q);
        let largest = grad.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let scale = self_grad.iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(
            largest < 1e-12 * scale,
            "{kind:?}: |∇g| = {largest} vs {scale}"
        );
    }
}

#[test]
fn a_target_of_another_resolution_attracts_the_model() {
    // The template against its own surface sampled four times as finely: small g, and a
    // translated template is pulled back.
    let q = t001().landmarks();
    let fine = reindexed(&subdivided(&boundary(q)), 3);
    let shift = Vec3::new(1.0, -0.5, 0.25);
    let moved: Vec<Vec3> = q.iter().map(|p| p + shift).collect();
    for kind in KINDS {
        let a = t001_attachment(&fine, kind, None);
        let at_target = value(&a, q);
        let (off, grad) = value_and_gradient(&a, &moved);
        assert!(at_target < 0.01 * off, "{kind:?}: {at_target} vs {off}");
        let pull: Vec3 = grad.iter().sum();
        assert!(
            pull.dot(&shift) > 0.5 * pull.norm() * shift.norm(),
            "{kind:?}: {pull:?}"
        );
    }
}

#[test]
fn orientation_of_the_target_matters_to_oriented_kinds_only() {
    let t = t001();
    let target = warped(&boundary(t.landmarks()), 1.5, 0.7);
    let q = t.landmarks();
    for kind in KINDS {
        let g = value(&t001_attachment(&target, kind, None), q);
        let g_flipped = value(&t001_attachment(&flipped(&target), kind, None), q);
        let change = (g_flipped - g).abs() / g;
        match kind {
            Kind::Varifold => assert!(change < 1e-12, "{change:.1e}"),
            _ => assert!(change > 1.0, "{kind:?}: {g} → {g_flipped}"),
        }
    }
}

#[test]
fn default_width_follows_the_rule() {
    let mesh = boundary(t001().landmarks());
    let (lo, hi) = mesh.points().iter().fold(
        (Vec3::repeat(f64::MAX), Vec3::repeat(f64::MIN)),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    );
    let edges: Vec<f64> = (mesh.triangles().iter())
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .map(|(a, b)| (mesh.points()[a] - mesh.points()[b]).norm())
        .collect();
    let mean_edge = edges.iter().sum::<f64>() / edges.len() as f64;
    let expected = (0.1 * (hi - lo).norm()).max(2.0 * mean_edge);
    let width = default_width(&mesh).unwrap();
    assert!((width - expected).abs() < 1e-12 * expected);
    assert_eq!(t001_attachment(&mesh, Kind::Current, None).width(), width);
    assert_eq!(
        t001_attachment(&mesh, Kind::Current, Some(3.0)).width(),
        3.0
    );
    // Twice as large a mesh, twice the width; a coarse mesh gets twice its edge length.
    let doubled = TriMesh::new(
        mesh.points().iter().map(|p| 2.0 * p).collect(),
        mesh.triangles().to_vec(),
    )
    .unwrap();
    assert!((default_width(&doubled).unwrap() - 2.0 * width).abs() < 1e-12 * width);
    let (points, triangles) = medial::testing::meshes::octahedron();
    let octahedron = TriMesh::new(points, triangles).unwrap();
    assert!((default_width(&octahedron).unwrap() - 2.0 * 2f64.sqrt()).abs() < 1e-15);
}

#[test]
fn refuses_bad_input() {
    let t = t001();
    let (k, tris) = (t.landmark_count(), t.boundary_triangles());
    let target = boundary(t.landmarks());
    let ok = VarifoldParams::default();
    let new =
        |tris: &[[usize; 3]], target: &TriMesh, params| Varifold::new(tris, k, target, params);
    let empty = TriMesh::new(vec![Vec3::zeros(); 3], vec![]).unwrap();
    let flat = TriMesh::new(
        vec![Vec3::zeros(), Vec3::x(), 2.0 * Vec3::x()],
        vec![[0, 1, 2]],
    );
    let mesh_errors = [
        new(&[], &target, ok),
        new(&[[0, 1, k]], &target, ok),
        new(&[[0, 1, 1]], &target, ok),
        new(tris, &empty, ok),
        new(
            tris,
            &empty,
            VarifoldParams {
                width: Some(1.0),
                ..ok
            },
        ),
        new(tris, &flat.unwrap(), ok),
    ];
    for e in mesh_errors {
        assert!(matches!(e, Err(Error::InvalidMesh(_))), "{e:?}");
    }
    let bad = [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-200];
    for w in bad {
        let width = VarifoldParams {
            width: Some(w),
            ..ok
        };
        let oriented = VarifoldParams {
            kind: Kind::OrientedVarifold { normal_width: w },
            ..ok
        };
        for params in [width, oriented] {
            let e = new(tris, &target, params);
            assert!(matches!(e, Err(Error::InvalidParameter(_))), "{e:?}");
        }
    }
    let a = new(tris, &target, ok).unwrap();
    let q = t.landmarks().to_vec();
    let e = a.evaluate(&q[1..], None);
    assert!(matches!(e, Err(Error::ShapeMismatch { .. })), "{e:?}");
    let e = a.evaluate(&q, Some(&mut vec![Vec3::zeros(); k + 1]));
    assert!(matches!(e, Err(Error::ShapeMismatch { .. })), "{e:?}");
    let mut bad_q = q.clone();
    bad_q[5].y = f64::NAN;
    assert!(matches!(a.evaluate(&bad_q, None), Err(Error::NonFinite(_))));
    assert_eq!(a.landmark_count(), k);
    assert_eq!(a.kind(), Kind::Varifold);
}

/// A random rotation and translation.
fn rigid(seed: u64) -> impl Fn(&Vec3) -> Vec3 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let axis = Unit::new_normalize(Vec3::from_fn(|_, _| rng.gen_range(-1.0..1.0)));
    let rotation = Rotation3::from_axis_angle(&axis, rng.gen_range(0.0..std::f64::consts::TAU));
    let shift = Vec3::from_fn(|_, _| rng.gen_range(-50.0..50.0));
    move |p| rotation * p + shift
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn nonnegative_and_free_of_correspondence(
        kind in 0usize..3,
        amplitude in 0.0f64..3.0,
        phase in 0.0f64..6.3,
        seed in 0u64..1000,
    ) {
        let t = t001();
        let kind = KINDS[kind];
        let target = t001_target();
        let a = t001_attachment(&target, kind, None);
        let q: Vec<Vec3> = t.landmarks().iter().map(|p| warp(p, amplitude, phase)).collect();
        let (g, grad) = value_and_gradient(&a, &q);
        let scale = a.target_norm2();
        prop_assert!(g >= -1e-12 * scale, "g = {g}");
        // The target's points and triangles in another order: the same g and gradient.
        let shuffled = t001_attachment(&reindexed(&target, seed), kind, None);
        let (g2, grad2) = value_and_gradient(&shuffled, &q);
        prop_assert!((g2 - g).abs() <= 1e-12 * scale, "{g} vs {g2}");
        prop_assert!(relative_difference(&grad2, &grad) < 1e-9);
        // Both moved rigidly: the same g, the gradient rotated.
        let motion = rigid(seed);
        let moved_target = TriMesh::new(
            target.points().iter().map(&motion).collect(),
            target.triangles().to_vec(),
        ).unwrap();
        let moved = t001_attachment(&moved_target, kind, Some(a.width()));
        let moved_q: Vec<Vec3> = q.iter().map(&motion).collect();
        let (g3, grad3) = value_and_gradient(&moved, &moved_q);
        prop_assert!((g3 - g).abs() <= 1e-10 * scale, "{g} vs {g3}");
        let origin = motion(&Vec3::zeros());
        let rotated: Vec<Vec3> = grad.iter().map(|v| motion(v) - origin).collect();
        prop_assert!(relative_difference(&grad3, &rotated) < 1e-8);
    }
}
