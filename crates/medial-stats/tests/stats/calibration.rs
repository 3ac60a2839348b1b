//! Calibration on null data (run in release: `cargo test -p medial-stats --release --test stats
//! -- --ignored calibration --nocapture`): over 1,000 data sets of seeded Gaussian noise smoothed
//! on meshglm's mesh (FWHM 4 mm, 40 subjects, meshglm's design and contrast), the fraction of
//! data sets with any FWER-corrected p ≤ 0.05 is 0.05 within Monte-Carlo error (0.035–0.065)
//! for the maximum t, clusters (t > 2.5, by area) and TFCE. 199 permutations and the identity:
//! p ≤ 0.05 is a rank among the 10 largest of 200, exactly 5 % under exchangeability. Figures
//! in docs/decisions/0100-stats-validation.md.

use medial_stats::{smooth, Elements, Observations, Options, Study, Support, TfceParameters};

use crate::common::noise;
use crate::meshglm::load;

#[test]
#[ignore = "minutes in release: the calibration of docs/decisions/0100-stats-validation.md"]
fn family_wise_error_rates_on_null_data() {
    let data_sets = 1000;
    let d = load(Support::Points);
    let elements = Elements::new(&d.mesh, Support::Points);
    let (n, m) = (d.design.subjects(), elements.len());
    let options = Options {
        permutations: 199,
        seed: 3,
        cluster_threshold: Some(2.5),
        tfce: Some(TfceParameters::default()),
        ..Options::default()
    };
    let (mut max_t, mut cluster, mut tfce) = (0, 0, 0);
    for k in 0..data_sets {
        let mut values = noise(n, m, 1_000_000 + k);
        smooth(&mut values, n, 4.0, &elements).unwrap();
        let y = Observations::new(n, values).unwrap();
        let options = Options {
            seed: k,
            ..options.clone()
        };
        let r = Study::new(&d.design, &y, Some(&elements), options)
            .unwrap()
            .test(&d.contrast)
            .unwrap();
        let any = |p: &[f64]| p.iter().any(|&p| p <= 0.05);
        max_t += usize::from(any(r.p_fwer.as_ref().unwrap()));
        cluster += usize::from(any(&r.clusters.as_ref().unwrap().p_area));
        tfce += usize::from(any(r.p_tfce.as_ref().unwrap()));
    }
    let rate = |count: usize| count as f64 / data_sets as f64;
    println!(
        "null data sets: {data_sets}; FWER at 0.05: max-t {:.3}, cluster {:.3}, TFCE {:.3}",
        rate(max_t),
        rate(cluster),
        rate(tfce)
    );
    for (name, count) in [("max-t", max_t), ("cluster", cluster), ("TFCE", tfce)] {
        assert!(
            (0.035..=0.065).contains(&rate(count)),
            "{name}: {}",
            rate(count)
        );
    }
}
