//! One value + gradient evaluation (flow, kinetic energy, SSD, adjoint) with the truncated
//! kernel on a real heart surface: the CAP left ventricle's ED endocardium and epicardium
//! subdivided twice (25,868 points), σ = 4 mm, N = 10, ε = 1e-10, the target
//! case. Before the criterion samples it prints the relative difference of the value and of
//! the gradient (2-norm) from the exact kernel's, and the time of one evaluation at k = 102,776
//! (three subdivisions; timed twice by hand, as criterion would take minutes).

#[path = "../tests/engine/common/heart.rs"]
mod heart;

use criterion::{criterion_group, criterion_main, Criterion};
use medial::attachment::ssd::Ssd;
use medial::fit::objective::Objective;
use medial::flow::{Flow, FlowParams};
use medial::Vec3;
use std::time::Instant;

const STEPS: usize = 10;
const SIGMA: f64 = 4.0;
const TOLERANCE: f64 = 1e-10;

/// A flow, targets and momenta on the heart subdivided `levels` times.
struct Case {
    q: Vec<Vec3>,
    ssd: Ssd,
    u: Vec<f64>,
    flow: Flow,
}

impl Case {
    fn new(levels: usize) -> Self {
        let q = heart::heart_points(levels);
        let params = FlowParams {
            sigma: SIGMA,
            time_steps: STEPS,
            kinetic_weight: 0.05,
        };
        let flow = (Flow::new(params, q.len()).expect("flow"))
            .with_kernel_tolerance(TOLERANCE)
            .expect("tolerance");
        let ssd =
            Ssd::new(q.iter().map(|p| p + Vec3::new(1.0, -0.5, 0.25)).collect()).expect("targets");
        let u = heart::smooth_momenta(&q, STEPS);
        Self { q, ssd, u, flow }
    }

    /// Value and gradient with `flow`.
    fn evaluate(&self, flow: &Flow) -> (f64, Vec<f64>) {
        let mut grad = vec![0.0; self.u.len()];
        let value = (Objective::new(flow, &self.q, &self.ssd, 1.0))
            .evaluate(&self.u, Some(&mut grad))
            .expect("evaluation")
            .total;
        (value, grad)
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn truncated(c: &mut Criterion) {
    let case = Case::new(2);
    let k = case.q.len();
    let (value, grad) = case.evaluate(&case.flow);
    let exact = case.flow.clone().with_kernel_tolerance(0.0).expect("exact");
    let start = Instant::now();
    let (exact_value, exact_grad) = case.evaluate(&exact);
    let exact_time = start.elapsed().as_secs_f64();
    let diff: Vec<f64> = grad.iter().zip(&exact_grad).map(|(a, b)| a - b).collect();
    println!(
        "heart k = {k}: exact kernel {exact_time:.2} s; truncated vs exact: value {:.1e}, gradient {:.1e} relative",
        ((value - exact_value) / exact_value).abs(),
        norm(&diff) / norm(&exact_grad),
    );
    let large = Case::new(3);
    for _ in 0..2 {
        let start = Instant::now();
        large.evaluate(&large.flow);
        println!(
            "heart k = {}: truncated {:.2} s per value + gradient",
            large.q.len(),
            start.elapsed().as_secs_f64()
        );
    }
    let mut group = c.benchmark_group("truncated_N10");
    group.sample_size(10);
    group.bench_function(format!("heart_k{k}"), |b| {
        b.iter(|| case.evaluate(&case.flow).0)
    });
    group.finish();
}

criterion_group!(benches, truncated);
criterion_main!(benches);
