//! Fit a medial template to a segmentation with the library, as `medial fit --template
//! examples/toy/template.vtk --image examples/toy/target.nii.gz --out DIR` does: the automatic
//! plan and initial alignment chosen from the data, then the fit with the medial constraints
//! on. It prints the figures the command prints (the same bits).
//!
//! `cargo run --release --example fit_segmentation` (a few seconds on 2 cores).

use medial::fit::{run::automatic, FitEvent, Target};
use medial::memory::MemoryLimit;
use medial::model::Model;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/toy");
    let template = medial::io::cmrep::read_template(&folder.join("template.vtk"))?;
    let volume = medial::io::volume::read_volume(&folder.join("target.nii.gz"))?;
    let target = Target::Image {
        volume,
        label: None,
    };

    // The plan (kernel width, time steps, μ schedule, image smoothing) and the initial
    // alignment, chosen from the template and the image.
    let start = automatic(
        &Model::Medial(Box::new(template)),
        &target,
        MemoryLimit::none(),
    )?;
    for note in &start.notes {
        println!("{note}");
    }
    let fit = start.fit(target, MemoryLimit::none())?;
    let outcomes = fit.run(|event| {
        if let FitEvent::StageEnd { outcome, .. } = event {
            println!(
                "{} evaluations, stop: {:?}",
                outcome.evaluations, outcome.stops
            );
        }
    })?;

    let last = outcomes.last().expect("a fit has a stage");
    let fitted = fit.flow().shoot(fit.model().landmarks(), &last.momenta)?;
    let q = fitted.final_positions();
    let metrics = fit.model().metrics(q).expect("a medial template");
    let overlap = fit.stages()[0]
        .disagreement(fit.model(), q)?
        .expect("a Dice stage of a medial template");
    println!(
        "Dice {:.3}, voxel Dice {:.3}, max spoke–normal {:.2}°, max spoke mismatch {:.2} %",
        last.evaluation.dice.unwrap_or(f64::NAN),
        overlap.voxel_dice().unwrap_or(f64::NAN),
        metrics.max_spoke_normal_deg,
        100.0 * metrics.max_spoke_mismatch
    );
    // A part of the segmentation the model never reached fails the fit (decision 0203).
    if let Some(miss) = overlap.miss(fit.flow().kernel().sigma()) {
        println!("the model misses its target: {miss}");
    }
    Ok(())
}
