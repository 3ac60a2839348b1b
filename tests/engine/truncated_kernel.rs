//! The truncated kernel on a real heart surface: the value and gradient of one evaluation
//! within 1e-8 relative of the exact kernel's, at the σ = 4 mm and ε = 1e-10 (the
//! once-subdivided CAP left ventricle, 6,552 points; the benchmark `truncated` runs the
//! twice-subdivided one, 25,868 points).

use crate::common::heart;

use medial::attachment::ssd::Ssd;
use medial::fit::objective::Objective;
use medial::flow::{Flow, FlowParams};
use medial::Vec3;

#[test]
fn truncated_heart_evaluation_is_within_1e8_of_exact() {
    let q = heart::heart_points(1);
    let steps = 4;
    let params = FlowParams {
        sigma: 4.0,
        time_steps: steps,
        kinetic_weight: 0.05,
    };
    let ssd = Ssd::new(q.iter().map(|p| p + Vec3::new(1.0, -0.5, 0.25)).collect()).unwrap();
    let u = heart::smooth_momenta(&q, steps);
    let evaluate = |flow: &Flow| {
        let mut grad = vec![0.0; u.len()];
        let value = (Objective::new(flow, &q, &ssd, 1.0).evaluate(&u, Some(&mut grad)))
            .unwrap()
            .total;
        (value, grad)
    };
    let exact_flow = Flow::new(params, q.len()).unwrap();
    let (value, grad) = evaluate(&exact_flow.clone().with_kernel_tolerance(1e-10).unwrap());
    let (exact_value, exact_grad) = evaluate(&exact_flow);
    let norm = |g: &[f64]| g.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff: Vec<f64> = grad.iter().zip(&exact_grad).map(|(a, b)| a - b).collect();
    assert!((value - exact_value).abs() <= 1e-8 * exact_value.abs());
    let rel = norm(&diff) / norm(&exact_grad);
    assert!(rel <= 1e-8, "gradient differs by {rel:e} relative");
    assert_ne!(value, exact_value, "the truncated kernel skipped no pair");
}
