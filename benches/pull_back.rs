//! The pull-back of an image through a fitted flow (issue 32): the displacement on every voxel
//! of a grid, by the control grid ([`GridMap`], tolerance 0.01 voxel) against the exact map of
//! every voxel, in the same run. The flow: examples/t001-bent's template (503 landmarks) under
//! smooth momenta that bend it by a few millimetres, σ = 1.41 mm, N = 20 (the settings of a fit
//! of t001); the grid: 64 × 96 × 64 voxels of 0.5 mm about it, the exact map on 4 slices of it
//! (per voxel, it costs the same everywhere near the template).

use criterion::{criterion_group, criterion_main, Criterion};
use medial::flow::ambient::grid::{GridMap, GridOptions, Lattice};
use medial::flow::ambient::AmbientFlow;
use medial::flow::{Flow, FlowParams};
use medial::Vec3;
use nalgebra::Matrix4;

fn case() -> (AmbientFlow, Lattice) {
    let template = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/t001-bent/template.vtk"
    );
    let model = medial_io::model::read_model(std::path::Path::new(template)).expect("template");
    let q0 = model.landmarks().to_vec();
    let centre = q0.iter().sum::<Vec3>() / q0.len() as f64;
    let steps = 20;
    let u: Vec<f64> = (0..steps)
        .flat_map(|_| q0.iter())
        .flat_map(|q| {
            let p = q - centre;
            let d = Vec3::new(0.02 * p.y * p.y / 10.0, 0.5, 0.3 * (0.1 * p.y).sin());
            [d.x, d.y, d.z]
        })
        .collect();
    let params = FlowParams {
        sigma: 1.41,
        time_steps: steps,
        kinetic_weight: 0.005,
    };
    let flow = Flow::new(params, q0.len()).expect("flow");
    let trajectory = flow.shoot(&q0, &u).expect("shoot");
    let ambient = AmbientFlow::new(&flow, &trajectory, &u).expect("ambient");
    let dims = [64, 96, 64];
    let mut m = Matrix4::new_scaling(0.5);
    m[(3, 3)] = 1.0;
    let corner = centre - Vec3::new(16.0, 24.0, 16.0);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&corner);
    (
        ambient,
        Lattice {
            dims,
            voxel_to_world: m,
        },
    )
}

fn bench(c: &mut Criterion) {
    let (flow, lattice) = case();
    let [nx, ny, nz] = lattice.dims;
    let options = GridOptions::voxels(&lattice, 0.01);
    let mut group = c.benchmark_group("pull_back");
    group.sample_size(10);
    for inverse in [false, true] {
        let name = if inverse { "inverse" } else { "forward" };
        group.bench_function(format!("{name}/grid/{nx}x{ny}x{nz}"), |b| {
            b.iter(|| {
                let map = GridMap::new(&flow, &lattice, inverse, &options).expect("grid");
                map.displacements(0..nz).expect("displacements")
            })
        });
        let slab = lattice.centres(nz / 2..nz / 2 + 4);
        group.bench_function(format!("{name}/exact/{nx}x{ny}x4"), |b| {
            b.iter(|| {
                if inverse {
                    flow.inverse(&slab).expect("inverse")
                } else {
                    flow.forward(&slab).expect("forward")
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
