//! The whole augmented-Lagrangian objective with the medial constraints of a real template
//! (cmrep's t001, k = 503, L = 753): its exact gradient against central finite differences.

use medial::attachment::ssd::Ssd;
use medial::fit::objective::{Objective, Penalty};
use medial::flow::{Flow, FlowParams};
use medial::model::constraints::{ConstraintUnits, MedialConstraints};
use medial::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

#[test]
fn al_objective_gradient_matches_central_differences_on_t001() {
    check(ConstraintUnits::Absolute);
}

#[test]
fn al_objective_gradient_in_relative_units_matches_central_differences_on_t001() {
    check(ConstraintUnits::Relative);
}

fn check(units: ConstraintUnits) {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/cmrep/t001_template_bcmrep.vtk");
    let template = medial::io::cmrep::read_template(&path).unwrap();
    let constraints = MedialConstraints::with_units(&template, units).unwrap();
    assert_eq!(constraints.len(), 753);
    let q0 = template.landmarks();
    let steps = 4;
    let flow = Flow::new(
        FlowParams {
            sigma: 3.0,
            time_steps: steps,
            kinetic_weight: 0.05,
        },
        q0.len(),
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let targets: Vec<Vec3> = q0[..template.boundary_count()]
        .iter()
        .map(|p| {
            p + Vec3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
            )
        })
        .collect();
    let ssd = Ssd::new(targets).unwrap();
    let lambda: Vec<f64> = (0..steps * constraints.len())
        .map(|_| rng.gen_range(-0.3..0.3))
        .collect();
    let objective = Objective::new(&flow, q0, &ssd, 1.0)
        .with_penalty(Penalty {
            constraints: &constraints,
            mu: 2.0,
            lambda: &lambda,
        })
        .unwrap();
    let u: Vec<f64> = (0..flow.momenta_len())
        .map(|_| rng.gen_range(-0.5..0.5))
        .collect();
    let mut grad = vec![0.0; u.len()];
    let e = objective.evaluate(&u, Some(&mut grad)).unwrap();
    assert!(e.penalty != 0.0 && e.max_abs_constraint > 0.0);
    for trial in 0..4 {
        let dir: Vec<f64> = (0..u.len()).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let h = 1e-5;
        let at = |s: f64| -> f64 {
            let v: Vec<f64> = u.iter().zip(&dir).map(|(u, d)| u + s * d).collect();
            objective.evaluate(&v, None).unwrap().total
        };
        let fd = (at(h) - at(-h)) / (2.0 * h);
        let exact: f64 = grad.iter().zip(&dir).map(|(g, d)| g * d).sum();
        let rel = (fd - exact).abs() / exact.abs();
        assert!(
            rel <= 1e-6,
            "{units:?}, trial {trial}: exact {exact} vs finite difference {fd} (relative error {rel:e})"
        );
    }
}
