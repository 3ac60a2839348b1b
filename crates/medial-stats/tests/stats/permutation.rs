//! Permutation inference against brute force: every one of the n! permutations of the
//! subjects, the statistic by dense least squares, clusters by breadth-first search.

use medial_stats::{
    tfce, Contrast, ContrastResult, Design, Elements, Mesh, Observations, Options, Study, Support,
    Tail, TfceParameters,
};
use nalgebra::{DMatrix, DVector};

use crate::common::{design, noise};

/// A 3 × 3 grid of squares cut into 18 triangles, its points moved off the lattice.
fn small_mesh() -> Mesh {
    Mesh::grid(3, |i, j| {
        let (x, y) = (i as f64, j as f64);
        [x + 0.15 * (2.0 * y + x).sin(), y + 0.1 * x.cos(), 0.0]
    })
    .unwrap()
}

/// All permutations of 0..n (Heap's algorithm).
fn all_permutations(n: usize) -> Vec<Vec<usize>> {
    let mut p: Vec<usize> = (0..n).collect();
    let mut c = vec![0; n];
    let mut out = vec![p.clone()];
    let mut i = 0;
    while i < n {
        if c[i] < i {
            if i % 2 == 0 {
                p.swap(0, i)
            } else {
                p.swap(c[i], i)
            }
            out.push(p.clone());
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    out
}

/// t by the normal equations.
fn dense_t(x: &DMatrix<f64>, c: &DVector<f64>, y: &DVector<f64>) -> f64 {
    let xtx_inv = (x.transpose() * x).try_inverse().unwrap();
    let beta = &xtx_inv * x.transpose() * y;
    let s2 = (y - x * &beta).norm_squared() / (x.nrows() - x.ncols()) as f64;
    c.dot(&beta) / (s2 * (c.transpose() * &xtx_inv * c)[(0, 0)]).sqrt()
}

/// Connected components of the active elements, their areas.
fn component_areas(active: &[bool], elements: &Elements) -> Vec<f64> {
    let mut seen = vec![false; active.len()];
    let mut areas = Vec::new();
    for start in 0..active.len() {
        if active[start] && !seen[start] {
            seen[start] = true;
            let (mut stack, mut area) = (vec![start], 0.0);
            while let Some(e) = stack.pop() {
                area += elements.areas()[e];
                for &nb in elements.neighbours(e) {
                    if active[nb] && !seen[nb] {
                        seen[nb] = true;
                        stack.push(nb);
                    }
                }
            }
            areas.push(area);
        }
    }
    areas
}

fn fraction_at_least(null: &[f64], v: f64) -> f64 {
    null.iter()
        .filter(|&&m| m >= v - 1e-9 * v.abs().max(1.0))
        .count() as f64
        / null.len() as f64
}

/// Every p of an analysis of `design` against the brute-force enumeration of all n!
/// permutations with Freedman–Lane: y* = P r + Z γ̂ with r, γ̂ the fit on the nuisance Z.
fn check_against_brute_force(design: &Design, nuisance: &[usize], contrast: &str, tail: Tail) {
    let n = design.subjects();
    let elements = Elements::new(&small_mesh(), Support::Cells);
    let m = elements.len();
    let mut values = noise(n, m, 11);
    // An effect on cells 0..6 in the second group.
    for e in 0..6 {
        for i in 0..n {
            values[e * n + i] += 1.5 * design.matrix()[(i, 1)];
        }
    }
    let y = Observations::new(n, values).unwrap();
    let c = Contrast::parse(contrast, design).unwrap();
    let threshold = 1.0;
    let parameters = TfceParameters::default();
    let options = Options {
        tail,
        permutations: 100_000,
        cluster_threshold: Some(threshold),
        tfce: Some(parameters),
        ..Options::default()
    };
    let result = Study::new(design, &y, Some(&elements), options)
        .unwrap()
        .test(&c)
        .unwrap();
    let summary = result.permutations.unwrap();
    assert!(summary.exact);

    let x = design.matrix();
    let z = x.select_columns(nuisance.iter());
    let hat_z = &z * (z.transpose() * &z).try_inverse().unwrap() * z.transpose();
    let cv = DVector::from_iterator(x.ncols(), c.matrix().row(0).iter().copied());
    let (mut max_t, mut max_area, mut max_tfce) = (Vec::new(), Vec::new(), Vec::new());
    let fitted: Vec<(DVector<f64>, DVector<f64>)> = (0..m)
        .map(|e| {
            let ye = DVector::from_column_slice(y.element(e));
            let part = &hat_z * &ye;
            (&ye - &part, part)
        })
        .collect();
    let side = |t: f64| if tail == Tail::Both { t.abs() } else { t };
    for p in all_permutations(n) {
        let t: Vec<f64> = fitted
            .iter()
            .map(|(r, part)| {
                let moved = DVector::from_iterator(n, (0..n).map(|i| r[p[i]])) + part;
                dense_t(x, &cv, &moved)
            })
            .collect();
        max_t.push(t.iter().map(|&v| side(v)).fold(f64::NEG_INFINITY, f64::max));
        let mut largest = 0.0_f64;
        for sign in if tail == Tail::Both {
            vec![1.0, -1.0]
        } else {
            vec![1.0]
        } {
            let active: Vec<bool> = t.iter().map(|&v| sign * v > threshold).collect();
            largest = component_areas(&active, &elements)
                .into_iter()
                .fold(largest, f64::max);
        }
        max_area.push(largest);
        max_tfce.push(
            tfce(&t, &parameters, tail, &elements)
                .iter()
                .map(|v| v.abs())
                .fold(0.0, f64::max),
        );
    }
    let p_fwer = result.p_fwer.as_ref().unwrap();
    let tfce_values = result.tfce.as_ref().unwrap();
    let p_tfce = result.p_tfce.as_ref().unwrap();
    for e in 0..m {
        let (r, part) = &fitted[e];
        let t = dense_t(x, &cv, &(r + part));
        assert!((result.statistic[e] - t).abs() < 1e-9 * t.abs().max(1.0));
        assert_eq!(p_fwer[e], fraction_at_least(&max_t, side(t)), "element {e}");
        assert_eq!(
            p_tfce[e],
            fraction_at_least(&max_tfce, tfce_values[e].abs()),
            "element {e}"
        );
    }
    let clusters = result.clusters.as_ref().unwrap();
    assert!(!clusters.found.clusters.is_empty());
    for (cluster, &p) in clusters.found.clusters.iter().zip(&clusters.p_area) {
        assert_eq!(p, fraction_at_least(&max_area, cluster.area));
    }
    // The smallest p an exact test can give.
    assert!(p_fwer.iter().all(|&p| p >= 1.0 / summary.count as f64));
}

#[test]
fn exact_p_values_of_two_groups_equal_brute_force() {
    // 7 subjects, groups of 3 and 4: 35 distinct permutations, 7! = 5040 in the brute force.
    let x = DMatrix::from_fn(7, 2, |i, j| {
        if j == 0 {
            1.0
        } else {
            f64::from(u8::from(i % 2 == 1))
        }
    });
    let d = Design::new(vec!["intercept".into(), "group".into()], x).unwrap();
    check_against_brute_force(&d, &[0], "group", Tail::Positive);
    check_against_brute_force(&d, &[0], "group", Tail::Both);
}

#[test]
fn exact_freedman_lane_with_a_covariate_equals_brute_force() {
    // 6 subjects with a continuous covariate: 720 distinct permutations.
    let d = design(6, 21);
    check_against_brute_force(&d, &[0, 2], "group", Tail::Positive);
}

/// Every float of a result, as bits.
fn bits(r: &ContrastResult) -> Vec<u64> {
    let mut all: Vec<f64> = [&r.estimate, &r.standardised, &r.statistic, &r.p]
        .into_iter()
        .flatten()
        .copied()
        .collect();
    for v in [&r.p_fwer, &r.tfce, &r.p_tfce].into_iter().flatten() {
        all.extend(v);
    }
    let clusters = r.clusters.as_ref().unwrap();
    all.extend(&clusters.p_area);
    all.extend(&clusters.p_mass);
    all.extend(
        clusters
            .found
            .clusters
            .iter()
            .flat_map(|c| [c.area, c.mass, c.peak]),
    );
    for v in [&r.null.statistic, &r.null.area, &r.null.mass, &r.null.tfce] {
        all.extend(v);
    }
    all.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn the_same_bits_for_one_and_two_threads() {
    let d = design(14, 31);
    let elements = Elements::new(&small_mesh(), Support::Points);
    let y = Observations::new(14, noise(14, elements.len(), 32)).unwrap();
    let c = Contrast::parse("group", &d).unwrap();
    let options = Options {
        tail: Tail::Both,
        permutations: 333,
        seed: 5,
        cluster_threshold: Some(1.5),
        tfce: Some(TfceParameters::default()),
        fdr: true,
        ..Options::default()
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            Study::new(&d, &y, Some(&elements), options.clone())
                .unwrap()
                .test(&c)
                .unwrap()
        })
    };
    let (one, two) = (run(1), run(2));
    assert!(!one.permutations.unwrap().exact);
    assert_eq!(one.null.statistic.len(), 334);
    assert_eq!(bits(&one), bits(&two));
    // Another seed draws other permutations.
    let other = Study::new(
        &d,
        &y,
        Some(&elements),
        Options {
            seed: 6,
            ..options.clone()
        },
    )
    .unwrap()
    .test(&c)
    .unwrap();
    assert_ne!(other.null.statistic, one.null.statistic);
}

#[test]
fn a_design_that_no_permutation_changes_is_refused() {
    let x = DMatrix::from_element(6, 1, 1.0);
    let d = Design::new(vec!["intercept".into()], x).unwrap();
    let y = Observations::new(6, noise(6, 3, 1)).unwrap();
    let c = Contrast::parse("intercept", &d).unwrap();
    let options = Options {
        permutations: 100,
        ..Options::default()
    };
    let message = Study::new(&d, &y, None, options.clone())
        .unwrap()
        .test(&c)
        .unwrap_err()
        .to_string();
    assert!(message.contains("sign flips"), "{message}");
    // Parametric inference is fine.
    let r = Study::new(
        &d,
        &y,
        None,
        Options {
            permutations: 0,
            ..options
        },
    )
    .unwrap()
    .test(&c)
    .unwrap();
    assert!(r.p.iter().all(|p| (0.0..=1.0).contains(p)));
}

/// The critical value is the smallest value significant at α by the p-values' own count.
#[test]
fn the_critical_value_is_the_smallest_significant_value() {
    use medial_stats::permutation::critical_value;
    let null: Vec<f64> = (0..201).map(|k| ((k * 37) % 201) as f64 * 0.1).collect();
    let p = |v: f64| null.iter().filter(|&&x| x >= v).count() as f64 / null.len() as f64;
    for alpha in [0.05, 0.01, 0.5] {
        let c = critical_value(&null, alpha).unwrap();
        assert!(p(c) <= alpha, "alpha {alpha}: p({c}) = {}", p(c));
        let below = null
            .iter()
            .copied()
            .filter(|&x| x < c)
            .fold(f64::MIN, f64::max);
        assert!(
            p(below) > alpha,
            "alpha {alpha}: {below} is significant too"
        );
    }
    assert_eq!(critical_value(&[], 0.05), None);
    // Too few maxima for p ≤ 0.05 (the smallest p is 1/19); ties at the rank are passed over.
    assert_eq!(critical_value(&[1.0; 19], 0.05), None);
    let tied: Vec<f64> = (0..20)
        .map(|k| if k >= 18 { 50.0 } else { k as f64 })
        .collect();
    assert_eq!(critical_value(&tied, 0.05), None);
    let mut tied = tied;
    tied.push(60.0);
    assert_eq!(critical_value(&tied, 0.05), Some(60.0));
}
