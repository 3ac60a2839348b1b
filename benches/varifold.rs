//! One value + gradient evaluation of the varifold attachment (each kind) on real surfaces:
//! the reduced KeOps hippocampi (1,320 source and 1,320 target triangles) and the t001 cmrep
//! template (624 boundary triangles) against its own surface subdivided (2,496 triangles). The
//! dense reference ([`medial::testing::varifold_dense`]) is measured in the same run as the
//! baseline. The throughput is stated in the pairs the sweep passes over,
//! `(F_S + F_T)(F_S + F_T − 1)/2`, so criterion also reports the time per pair.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use medial::attachment::varifold::{Kind, Varifold, VarifoldParams, DEFAULT_NORMAL_WIDTH};
use medial::attachment::Attachment;
use medial::testing::varifold_dense::{self, subdivided};
use medial::{TriMesh, Vec3};
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(name)
}

/// A surface fitted to a target.
struct Case {
    name: &'static str,
    landmarks: Vec<Vec3>,
    triangles: Vec<[usize; 3]>,
    target: TriMesh,
}

fn cases() -> Vec<Case> {
    let read = |name: &str| medial::io::vtk::read_trimesh(&data(name)).expect("a hippocampus");
    let hippo = read("keops/hippos_reduc_source.vtk");
    let t001 = medial::io::cmrep::read_template(&data("cmrep/t001_template_bcmrep.vtk"))
        .expect("t001 template");
    let t001_boundary = TriMesh::new(
        t001.boundary_points().to_vec(),
        t001.boundary_triangles().to_vec(),
    )
    .expect("t001 boundary");
    vec![
        Case {
            name: "hippo1320_to_1320",
            landmarks: hippo.points().to_vec(),
            triangles: hippo.triangles().to_vec(),
            target: read("keops/hippos_reduc_target.vtk"),
        },
        Case {
            name: "t001_624_to_2496",
            landmarks: (t001.landmarks().iter())
                .map(|p| p + Vec3::new(1.0, -0.5, 0.25))
                .collect(),
            triangles: t001.boundary_triangles().to_vec(),
            target: subdivided(&t001_boundary),
        },
    ]
}

fn evaluation(c: &mut Criterion) {
    let mut group = c.benchmark_group("varifold_value_and_gradient");
    group.sample_size(10);
    let kinds = [
        ("varifold", Kind::Varifold),
        (
            "oriented",
            Kind::OrientedVarifold {
                normal_width: DEFAULT_NORMAL_WIDTH,
            },
        ),
        ("current", Kind::Current),
    ];
    for Case {
        name,
        landmarks: q,
        triangles,
        target,
    } in cases()
    {
        let faces = triangles.len() + target.triangles().len();
        group.throughput(Throughput::Elements((faces * (faces - 1) / 2) as u64));
        for (kind_name, kind) in kinds {
            let params = VarifoldParams { kind, width: None };
            let attachment =
                Varifold::new(&triangles, q.len(), &target, params).expect("attachment");
            let mut grad = vec![Vec3::zeros(); q.len()];
            group.bench_function(BenchmarkId::new(kind_name, name), |b| {
                b.iter(|| {
                    (attachment.evaluate(&q, Some(&mut grad)))
                        .expect("evaluation")
                        .value
                })
            });
            if kind == Kind::Varifold {
                group.bench_function(BenchmarkId::new("dense_baseline", name), |b| {
                    b.iter(|| {
                        varifold_dense::attachment(
                            &q,
                            &triangles,
                            target.points(),
                            target.triangles(),
                            kind,
                            attachment.width(),
                        )
                        .0
                    })
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, evaluation);
criterion_main!(benches);
