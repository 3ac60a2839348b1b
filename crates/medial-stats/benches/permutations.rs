//! The cost of permutation inference at the size of issue 31: 10,000 permutations of 40
//! subjects at 20,000 elements (the cells of a 100 × 100 grid cut into triangles), maximum t
//! alone, and with clusters and TFCE (1,000 permutations). Figures in
//! docs/decisions/0100-stats-validation.md.

use criterion::{criterion_group, criterion_main, Criterion};
use medial_stats::{
    Contrast, Design, Elements, Mesh, Observations, Options, Study, Support, TfceParameters,
};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn grid(n: usize) -> Mesh {
    Mesh::grid(n, |i, j| [i as f64, j as f64, 0.0]).unwrap()
}

fn bench(c: &mut Criterion) {
    let (n, side) = (40, 100);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let x = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => f64::from(u8::from(i < n / 2)),
        1 => f64::from(u8::from(i >= n / 2)),
        _ => rng.gen(),
    });
    let design = Design::new(vec!["g1".into(), "g2".into(), "age".into()], x).unwrap();
    let contrast = Contrast::parse("g2 - g1", &design).unwrap();
    let elements = Elements::new(&grid(side), Support::Cells);
    let values: Vec<f64> = (0..n * elements.len())
        .map(|_| rng.gen_range(-1.0..1.0))
        .collect();
    let y = Observations::new(n, values).unwrap();
    let mut group = c.benchmark_group("permutations");
    group.sample_size(10);
    group.bench_function("max-t, 10000 x 40 x 20000", |b| {
        let options = Options {
            permutations: 10_000,
            ..Options::default()
        };
        let study = Study::new(&design, &y, Some(&elements), options).unwrap();
        b.iter(|| study.test(&contrast).unwrap())
    });
    group.bench_function("max-t, clusters and TFCE, 1000 x 40 x 20000", |b| {
        let options = Options {
            permutations: 1000,
            cluster_threshold: Some(2.0),
            tfce: Some(TfceParameters::default()),
            ..Options::default()
        };
        let study = Study::new(&design, &y, Some(&elements), options).unwrap();
        b.iter(|| study.test(&contrast).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
