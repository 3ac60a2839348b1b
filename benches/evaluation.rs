//! One value + gradient evaluation of the objective (flow, kinetic energy, SSD, adjoint) with
//! N = 40 time steps on real shapes: the t001 medial template (k = 503), and the KeOps
//! hippocampus (k = 2,000 of its points, and all 6,611). The dense textbook implementation
//! ([`medial::testing::dense`]) is measured in the same run as the baseline the ratios are
//! stated against (up to k = 2,000: it holds `N` dense `k × k` matrices). The throughput is stated in pair-steps,
//! `N·k(k−1)/2` per evaluation, so criterion also reports the time per pair and step.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use medial::attachment::ssd::Ssd;
use medial::attachment::Attachment;
use medial::fit::objective::Objective;
use medial::flow::{Flow, FlowParams};
use medial::testing::dense;
use medial::Vec3;
use std::path::Path;

const STEPS: usize = 40;

fn data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(name)
}

/// (name, landmarks, kernel width σ in mm).
fn cases() -> Vec<(&'static str, Vec<Vec3>, f64)> {
    let t001 = medial::io::cmrep::read_template(&data("cmrep/t001_template_bcmrep.vtk"))
        .expect("t001 template");
    let hippo = medial::io::vtk::read_polydata(&data("keops/hippos_source.vtk"))
        .expect("hippocampus")
        .points;
    let hippo_2000: Vec<Vec3> = (0..2000).map(|m| hippo[m * hippo.len() / 2000]).collect();
    vec![
        ("t001", t001.landmarks().to_vec(), 2.0),
        ("hippo2000", hippo_2000, 5.0),
        ("hippo6611", hippo, 5.0),
    ]
}

/// Smooth momenta: every landmark pushed along a slowly varying field.
fn momenta(q: &[Vec3]) -> Vec<f64> {
    (0..STEPS)
        .flat_map(|n| {
            q.iter()
                .flat_map(move |p| [(0.1 * p.y).sin(), (0.1 * p.z + n as f64 * 0.01).cos(), 0.3])
        })
        .collect()
}

fn evaluation(c: &mut Criterion) {
    let mut group = c.benchmark_group("value_and_gradient_N40");
    group.sample_size(10);
    for (name, q, sigma) in cases() {
        let k = q.len();
        group.throughput(Throughput::Elements((STEPS * k * (k - 1) / 2) as u64));
        let flow = Flow::new(
            FlowParams {
                sigma,
                time_steps: STEPS,
                kinetic_weight: 0.05,
            },
            k,
        )
        .expect("flow");
        let targets: Vec<Vec3> = q.iter().map(|p| p + Vec3::new(1.0, -0.5, 0.25)).collect();
        let ssd = Ssd::new(targets).expect("targets");
        let objective = Objective::new(&flow, &q, &ssd, 1.0);
        let u = momenta(&q);
        let mut grad = vec![0.0; u.len()];
        group.bench_function(BenchmarkId::new("fused", format!("{name}_k{k}")), |b| {
            b.iter(|| {
                objective
                    .evaluate(&u, Some(&mut grad))
                    .expect("evaluation")
                    .total
            })
        });
        if k <= 2000 {
            group.bench_function(
                BenchmarkId::new("dense_baseline", format!("{name}_k{k}")),
                |b| {
                    b.iter(|| {
                        dense::objective(&q, &u, sigma, STEPS, 0.05, |n, q| {
                            if n < STEPS {
                                return (0.0, vec![Vec3::zeros(); q.len()]);
                            }
                            let mut g = vec![Vec3::zeros(); q.len()];
                            (ssd.evaluate(q, Some(&mut g)).expect("ssd").value, g)
                        })
                        .0
                    })
                },
            );
        }
    }
    group.finish();
}

criterion_group!(benches, evaluation);
criterion_main!(benches);
