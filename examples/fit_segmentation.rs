//! Fit a medial template to a segmentation with the library: the shipped toy (three sheets
//! meeting along a seam) against its target image, Dice with the medial constraints on and μ
//! rising tenfold over six augmented-Lagrangian iterations.
//!
//! `cargo run --release --example fit_segmentation` (about 5 s on 2 cores).

use medial::attachment::dice::{DiceAttachment, DiceParams};
use medial::fit::{run_stages, AlSchedule, FitEvent, Guard, LbfgsOptions, PlannedStage, Stage};
use medial::flow::{Flow, FlowParams};
use medial::model::{ConstraintUnits, MedialConstraints, SpokeMetrics};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/toy");
    let template = medial::io::cmrep::read_template(&folder.join("template.vtk"))?;
    let mask = medial::io::nifti_volume::read_nifti(&folder.join("target.nii.gz"))?;
    let image = mask.foreground(None).smoothed(0.2)?;

    // The flow of the template's landmarks: σ about the wall's half thickness (mm).
    let params = FlowParams {
        sigma: 2.0,
        time_steps: 20,
        kinetic_weight: 0.005,
    };
    let flow = Flow::new(params, template.landmark_count())?;
    let medial_of: Vec<usize> = template
        .medial_index()
        .iter()
        .map(|&atom| template.atom_landmark(atom))
        .collect();
    let dice = DiceAttachment::new(
        template.boundary_triangles(),
        &medial_of,
        template.landmark_count(),
        image,
        DiceParams::default(),
    )?;
    let constraints = MedialConstraints::with_units(&template, ConstraintUnits::Relative)?;

    let stage = PlannedStage {
        stage: Stage {
            flow: &flow,
            initial: template.landmarks(),
            attachment: &dice,
            data_weight: 100.0,
            constraints: Some(&constraints),
            guard: Some(&Guard::of_template(&template)),
        },
        schedule: AlSchedule {
            mu: 0.02,
            iterations: 6,
            ..AlSchedule::default()
        },
        lbfgs: LbfgsOptions {
            max_iterations: 150,
            ..LbfgsOptions::default()
        },
    };
    let outcomes = run_stages(&[stage], |event| {
        if let FitEvent::StageEnd { outcome, .. } = event {
            println!(
                "{} evaluations, stop: {:?}",
                outcome.evaluations, outcome.stops
            );
        }
    })?;

    let fitted = flow.shoot(template.landmarks(), &outcomes[0].momenta)?;
    let metrics = SpokeMetrics::compute(&template, fitted.final_positions());
    println!(
        "Dice {:.3}, max spoke–normal {:.2}°, max spoke mismatch {:.2} %",
        outcomes[0].evaluation.dice.unwrap_or(f64::NAN),
        metrics.max_spoke_normal_deg,
        100.0 * metrics.max_spoke_mismatch
    );
    Ok(())
}
