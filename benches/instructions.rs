//! The workloads whose instructions `benches/instructions.sh` counts with callgrind: one value and
//! gradient evaluation of the objective at k = 503 (t001, N = 40, SSD), and one value +
//! gradient of the Dice attachment (t001 against its own rasterization, 0.5 mm voxels, the
//! default sampling). `instructions CASE` sets the case up, then runs it once inside the
//! function `measured`, the only one callgrind counts (`--toggle-collect`); run it with one
//! rayon thread, as idle worker threads spin for a varying number of instructions.

use medial::attachment::dice::{DiceAttachment, DiceParams};
use medial::attachment::ssd::Ssd;
use medial::fit::objective::Objective;
use medial::flow::{Flow, FlowParams};
use medial::image::rasterize::{grid_around, rasterize};
use medial::{MedialTemplate, TriMesh, Vec3};
use std::hint::black_box;
use std::path::Path;

const STEPS: usize = 40;

fn t001() -> MedialTemplate {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/cmrep/t001_template_bcmrep.vtk");
    medial::io::cmrep::read_template(&path).expect("t001 template")
}

/// Runs `work` on a thread of the rayon pool, inside [`measured`]: callgrind follows the call
/// stack of each thread, and the parallel sweeps run on the pool's threads.
fn run_measured<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| measured(work))
}

/// The work callgrind counts.
#[inline(never)]
fn measured<R>(work: impl FnOnce() -> R) -> R {
    black_box(work())
}

/// One value + gradient of the objective on t001 with smooth momenta.
fn evaluation() {
    let template = t001();
    let q = template.landmarks();
    let flow = Flow::new(
        FlowParams {
            sigma: 2.0,
            time_steps: STEPS,
            kinetic_weight: 0.05,
        },
        q.len(),
    )
    .expect("flow");
    let ssd =
        Ssd::new(q.iter().map(|p| p + Vec3::new(1.0, -0.5, 0.25)).collect()).expect("targets");
    let objective = Objective::new(&flow, q, &ssd, 1.0);
    let u: Vec<f64> = (0..STEPS)
        .flat_map(|n| {
            q.iter()
                .flat_map(move |p| [(0.1 * p.y).sin(), (0.1 * p.z + n as f64 * 0.01).cos(), 0.3])
        })
        .collect();
    let mut grad = vec![0.0; u.len()];
    run_measured(|| {
        objective
            .evaluate(&u, Some(&mut grad))
            .expect("evaluation")
            .total
    });
}

/// One value + gradient of the Dice attachment of t001 against its own rasterization.
fn dice() {
    let template = t001();
    let q = template.landmarks();
    let nb = template.boundary_count();
    let boundary =
        TriMesh::new(q[..nb].to_vec(), template.boundary_triangles().to_vec()).expect("boundary");
    let (dims, grid) = grid_around(&boundary, 0.5, 3.0).expect("grid");
    let image = rasterize(&boundary, dims, grid)
        .expect("mask")
        .smoothed(0.2)
        .expect("image");
    let dice =
        DiceAttachment::for_template(&template, image, DiceParams::default()).expect("attachment");
    let mut grad = vec![Vec3::zeros(); q.len()];
    run_measured(|| dice.dice(q, Some(&mut grad)).expect("dice").dice);
}

fn main() {
    // `cargo bench` runs every bench binary with `--bench`: nothing to do then.
    match std::env::args().nth(1).as_deref() {
        Some("evaluation") => evaluation(),
        Some("dice") => dice(),
        Some("--bench") | None => {}
        Some(other) => {
            eprintln!("unknown case '{other}': evaluation or dice");
            std::process::exit(2);
        }
    }
}
