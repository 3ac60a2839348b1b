//! The GLM against dense least squares computed another way (QR of X per element, (XᵀX)⁻¹ by
//! inversion), and its invariants.

use approx::assert_relative_eq;
use medial_stats::{Contrast, Design, Glm, GlmOptions, Observations, Tail};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

use crate::common::{data, design};

/// t, F, Cβ̂ and df of one element by QR least squares.
fn dense(x: &DMatrix<f64>, c: &DMatrix<f64>, y: &[f64]) -> (f64, Vec<f64>, usize) {
    let (n, p) = x.shape();
    let y = DVector::from_column_slice(y);
    let qr = x.clone().qr();
    let beta = qr
        .r()
        .solve_upper_triangular(&(qr.q().transpose() * &y))
        .unwrap();
    let residual = &y - x * &beta;
    let df = n - p;
    let s2 = residual.norm_squared() / df as f64;
    let xtx_inv = (x.transpose() * x).try_inverse().unwrap();
    let cb = c * &beta;
    let middle = (c * &xtx_inv * c.transpose()).try_inverse().unwrap();
    let statistic = if c.nrows() == 1 {
        cb[0] / (s2 * (c * &xtx_inv * c.transpose())[(0, 0)]).sqrt()
    } else {
        (cb.transpose() * middle * &cb)[(0, 0)] / (c.nrows() as f64 * s2)
    };
    (statistic, cb.iter().copied().collect(), df)
}

#[test]
fn t_and_f_equal_dense_least_squares() {
    let d = design(23, 1);
    let y = data(&d, 50, 0.8, 2);
    for spec in ["group", "age - 0.5 group", "group; age"] {
        let c = Contrast::parse(spec, &d).unwrap();
        let glm = Glm::new(&d, &c, &y, &GlmOptions::default()).unwrap();
        let statistic = glm.statistic();
        for (e, &t) in statistic.iter().enumerate() {
            let (expected, estimate, df) = dense(d.matrix(), c.matrix(), y.element(e));
            assert_relative_eq!(t, expected, max_relative = 1e-9, epsilon = 1e-12);
            let rows = &glm.estimate()[e * c.rows()..(e + 1) * c.rows()];
            for (a, b) in rows.iter().zip(&estimate) {
                assert_relative_eq!(*a, *b, max_relative = 1e-9, epsilon = 1e-12);
            }
            assert_eq!(glm.degrees_of_freedom()[e], df as f64);
        }
    }
}

#[test]
fn f_of_one_row_is_t_squared_and_p_agree() {
    let d = design(17, 3);
    let y = data(&d, 30, 0.5, 4);
    let c = Contrast::parse("group", &d).unwrap();
    let glm = Glm::new(&d, &c, &y, &GlmOptions::default()).unwrap();
    let t = glm.statistic();
    // The F of one row, computed by the dense path as a quadratic form.
    for (e, &te) in t.iter().enumerate() {
        let x = d.matrix();
        let yy = DVector::from_column_slice(y.element(e));
        let beta = (x.transpose() * x).try_inverse().unwrap() * x.transpose() * &yy;
        let s2 = (&yy - x * &beta).norm_squared() / 14.0;
        let cb = beta[1];
        let f = cb * cb / ((x.transpose() * x).try_inverse().unwrap()[(1, 1)] * s2);
        assert_relative_eq!(f, te * te, max_relative = 1e-9);
    }
    let two = glm.p_values(&t, Tail::Both);
    let one = glm.p_values(&t, Tail::Positive);
    for e in 0..t.len() {
        let expected = if t[e] > 0.0 {
            two[e] / 2.0
        } else {
            1.0 - two[e] / 2.0
        };
        assert_relative_eq!(one[e], expected, max_relative = 1e-12);
    }
}

#[test]
fn missing_values_fit_the_subjects_present() {
    let d = design(20, 5);
    let full = data(&d, 6, 1.0, 6);
    let mut values = full.values().to_vec();
    // Element 2 misses subjects 3 and 11; element 4 has only 3 subjects.
    values[2 * 20 + 3] = f64::NAN;
    values[2 * 20 + 11] = f64::NAN;
    for i in 3..20 {
        values[4 * 20 + i] = f64::NAN;
    }
    let y = Observations::new(20, values).unwrap();
    let c = Contrast::parse("group", &d).unwrap();
    let options = GlmOptions {
        min_observations: 10,
        exclude: Some(vec![false, true, false, false, false, false]),
    };
    let glm = Glm::new(&d, &c, &y, &options).unwrap();
    let t = glm.statistic();
    assert!(t[1].is_nan(), "excluded");
    assert!(t[4].is_nan(), "too few subjects");
    assert_eq!(glm.observed(), [20, 0, 18, 20, 0, 20]);
    let keep: Vec<usize> = (0..20).filter(|&i| i != 3 && i != 11).collect();
    let x = d.matrix().select_rows(keep.iter());
    let y2: Vec<f64> = keep.iter().map(|&i| full.element(2)[i]).collect();
    let (expected, _, df) = dense(&x, c.matrix(), &y2);
    assert_relative_eq!(t[2], expected, max_relative = 1e-9);
    assert_eq!(glm.degrees_of_freedom()[2], df as f64);
    let (expected, _, _) = dense(d.matrix(), c.matrix(), full.element(3));
    assert_relative_eq!(t[3], expected, max_relative = 1e-9);
}

#[test]
fn rank_deficient_designs_and_unestimable_contrasts() {
    // A column repeated: rank 2 of 3 columns; the contrast on the repeated pair is not estimable.
    let x = DMatrix::from_fn(10, 3, |i, j| match j {
        0 => 1.0,
        _ => f64::from(u8::from(i >= 5)),
    });
    let d = Design::new(vec!["one".into(), "a".into(), "b".into()], x).unwrap();
    let y = data(&d, 4, 1.0, 8);
    let bad = Contrast::parse("a", &d).unwrap();
    let message = Glm::new(&d, &bad, &y, &GlmOptions::default())
        .unwrap_err()
        .to_string();
    assert!(message.contains("not estimable"), "{message}");
    let good = Contrast::parse("a + b", &d).unwrap();
    let glm = Glm::new(&d, &good, &y, &GlmOptions::default()).unwrap();
    let two_columns = Design::new(
        vec!["one".into(), "ab".into()],
        d.matrix().columns(0, 2).into_owned(),
    )
    .unwrap();
    let reference = Glm::new(
        &two_columns,
        &Contrast::parse("ab", &two_columns).unwrap(),
        &y,
        &GlmOptions::default(),
    )
    .unwrap();
    for (a, b) in glm.statistic().iter().zip(reference.statistic()) {
        assert_relative_eq!(*a, b, max_relative = 1e-9);
    }
    assert_eq!(glm.degrees_of_freedom()[0], 8.0);
}

#[test]
fn standardised_estimates_are_the_refit_on_scaled_variables() {
    let d = design(15, 9);
    let y = data(&d, 5, 1.0, 10);
    let c = Contrast::parse("age", &d).unwrap();
    let glm = Glm::new(&d, &c, &y, &GlmOptions::default()).unwrap();
    let sd = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
    };
    let age: Vec<f64> = d.matrix().column(2).iter().copied().collect();
    let mut x = d.matrix().clone();
    x.column_mut(2).iter_mut().for_each(|v| *v /= sd(&age));
    let scaled = Design::new(d.names().to_vec(), x).unwrap();
    for e in 0..5 {
        let ys: Vec<f64> = y.element(e).iter().map(|v| v / sd(y.element(e))).collect();
        let (_, estimate, _) = dense(scaled.matrix(), c.matrix(), &ys);
        assert_relative_eq!(
            glm.standardised_estimate()[e],
            estimate[0],
            max_relative = 1e-9
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Reordering the subjects (design rows and data together) leaves t as it is; scaling the
    /// data scales Cβ̂ and not t; adding a multiple of a nuisance column changes neither.
    #[test]
    fn invariants(seed in 0u64..1000, scale in 0.1..10.0f64, shift in -5.0..5.0f64) {
        let n = 12;
        let d = design(n, seed);
        let y = data(&d, 8, 0.7, seed + 1);
        let c = Contrast::parse("group", &d).unwrap();
        let glm = Glm::new(&d, &c, &y, &GlmOptions::default()).unwrap();
        let t = glm.statistic();

        let order: Vec<usize> = (0..n).map(|i| (i * 5 + seed as usize) % n).collect();
        let x = d.matrix().select_rows(order.iter());
        let moved = Design::new(d.names().to_vec(), x).unwrap();
        let values: Vec<f64> = (0..8).flat_map(|e| order.iter().map(move |&i| (e, i))).map(|(e, i)| y.element(e)[i]).collect();
        let moved_glm = Glm::new(&moved, &c, &Observations::new(n, values).unwrap(), &GlmOptions::default()).unwrap();
        for (a, b) in t.iter().zip(moved_glm.statistic()) {
            prop_assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0));
        }

        let values: Vec<f64> = y.values().iter().enumerate().map(|(k, v)| scale * v + shift * d.matrix()[(k % n, 2)]).collect();
        let scaled = Glm::new(&d, &c, &Observations::new(n, values).unwrap(), &GlmOptions::default()).unwrap();
        for (e, (a, b)) in t.iter().zip(scaled.statistic()).enumerate() {
            prop_assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0));
            let (ea, eb) = (glm.estimate()[e], scaled.estimate()[e]);
            prop_assert!((scale * ea - eb).abs() <= 1e-9 * eb.abs().max(1.0));
        }
    }
}
