//! One value + gradient evaluation of the objective (flow, kinetic energy, SSD, adjoint) with
//! N = 40 time steps on real shapes: the t001 medial template (k = 503), and the KeOps
//! hippocampus (k = 2,000 of its points, and all 6,611). The dense textbook implementation
//! ([`medial::testing::dense`]) is measured in the same run as the baseline the ratios are
//! stated against (up to k = 2,000: it holds `N` dense `k × k` matrices). The throughput is stated in pair-steps,
//! `N·k(k−1)/2` per evaluation, so criterion also reports the time per pair and step.
//!
//! The group `peak` measures, in the same run, the machine's f64 multiply-add peak on all
//! threads of the pool: independent chains of fused multiply-adds on AVX2 and on AVX-512
//! registers (where the CPU has them), its throughput stated in flops (2 per multiply-add).
//! The kernel's flops per pair and step (53 forward, 77 backward, see
//! `medial::flow::kernel`) over its time give the fraction of that peak it reaches.

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

/// With `MEDIAL_BENCH_CASES=DIR` in the environment, writes each case's landmarks to
/// `DIR/NAME.csv` (`x,y,z` per line after a `# sigma = σ` line), for `benches/side_by_side.py`.
fn write_cases(cases: &[(&str, Vec<Vec3>, f64)]) {
    let Some(dir) = std::env::var_os("MEDIAL_BENCH_CASES") else {
        return;
    };
    for (name, q, sigma) in cases {
        let lines: String = q
            .iter()
            .map(|p| format!("{},{},{}\n", p.x, p.y, p.z))
            .collect();
        let path = Path::new(&dir).join(format!("{name}.csv"));
        std::fs::write(&path, format!("# sigma = {sigma}\n{lines}")).expect("a case file");
    }
}

fn evaluation(c: &mut Criterion) {
    let mut group = c.benchmark_group("value_and_gradient_N40");
    group.sample_size(10);
    let cases = cases();
    write_cases(&cases);
    for (name, q, sigma) in cases {
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

/// Independent multiply-add chains per thread: enough to fill two multiply-add units of
/// 4-cycle latency, few enough to stay in registers.
const CHAINS: usize = 12;

/// Multiply-adds per chain in one call of a peak loop.
const CHAIN_LENGTH: usize = 100_000;

/// `CHAINS × CHAIN_LENGTH` fused multiply-adds on AVX2 registers; returns a sum of the chains.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn fma_chains_avx2(seed: f64) -> f64 {
    use std::arch::x86_64::*;
    let (a, b) = (_mm256_set1_pd(0.999_999), _mm256_set1_pd(1e-7));
    let mut acc = [_mm256_set1_pd(seed); CHAINS];
    for _ in 0..CHAIN_LENGTH {
        for x in acc.iter_mut() {
            *x = _mm256_fmadd_pd(*x, a, b);
        }
    }
    let mut out = [0.0; 4];
    _mm256_storeu_pd(
        out.as_mut_ptr(),
        acc.iter()
            .fold(_mm256_set1_pd(0.0), |s, &x| _mm256_add_pd(s, x)),
    );
    out.iter().sum()
}

/// [`fma_chains_avx2`] on AVX-512 registers.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::incompatible_msrv)] // AVX-512 intrinsics: stable since 1.89, as in the kernel.
unsafe fn fma_chains_avx512(seed: f64) -> f64 {
    use std::arch::x86_64::*;
    let (a, b) = (_mm512_set1_pd(0.999_999), _mm512_set1_pd(1e-7));
    let mut acc = [_mm512_set1_pd(seed); CHAINS];
    for _ in 0..CHAIN_LENGTH {
        for x in acc.iter_mut() {
            *x = _mm512_fmadd_pd(*x, a, b);
        }
    }
    _mm512_reduce_add_pd(
        acc.iter()
            .fold(_mm512_set1_pd(0.0), |s, &x| _mm512_add_pd(s, x)),
    )
}

/// A peak loop: [`fma_chains_avx2`] or [`fma_chains_avx512`].
#[cfg(target_arch = "x86_64")]
type PeakLoop = unsafe fn(f64) -> f64;

/// The f64 multiply-add peak: [`fma_chains_avx2`] and [`fma_chains_avx512`] on every thread of
/// the pool at once.
#[cfg(target_arch = "x86_64")]
fn peak(c: &mut Criterion) {
    use rayon::prelude::*;
    let threads = rayon::current_num_threads();
    let mut group = c.benchmark_group("peak");
    group.sample_size(10);
    let kinds: [(&str, usize, bool, PeakLoop); 2] = [
        (
            "fma_avx2",
            4,
            is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"),
            fma_chains_avx2,
        ),
        (
            "fma_avx512",
            8,
            is_x86_feature_detected!("avx512f"),
            fma_chains_avx512,
        ),
    ];
    for (name, lanes, supported, chains) in kinds {
        if !supported {
            continue;
        }
        group.throughput(Throughput::Elements(
            (threads * CHAINS * CHAIN_LENGTH * lanes * 2) as u64,
        ));
        group.bench_function(format!("{name}_{threads}_threads"), |b| {
            b.iter(|| {
                (0..threads)
                    .into_par_iter()
                    // SAFETY: the CPU has the instructions, checked above.
                    .map(|t| unsafe { chains(1.0 + t as f64) })
                    .sum::<f64>()
            })
        });
    }
    group.finish();
}

#[cfg(not(target_arch = "x86_64"))]
fn peak(_: &mut Criterion) {}

criterion_group!(benches, evaluation, peak);
criterion_main!(benches);
