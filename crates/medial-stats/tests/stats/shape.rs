//! Procrustes, GPA and PCA against independent computations: Horn's quaternion solution of the
//! rigid alignment, the eigendecomposition of the covariance matrix, and synthetic cohorts with
//! a known mode of variation.

use medial_stats::shape::{centroid_size, generalised_procrustes, pca, procrustes, AtomShape};
use nalgebra::{DMatrix, Matrix3, Matrix4, Rotation3, SymmetricEigen, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::common::noise;

fn random_points(n: usize, rng: &mut ChaCha8Rng) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.gen_range(-10.0..10.0)))
        .collect()
}

fn random_rotation(rng: &mut ChaCha8Rng) -> Matrix3<f64> {
    let axis = Vector3::new(
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
        rng.gen_range(-1.0..1.0),
    );
    Rotation3::new(axis.normalize() * rng.gen_range(0.0..3.0)).into_inner()
}

/// Horn's closed form (1987): the rotation from the unit quaternion of the largest eigenvalue
/// of the 4 × 4 matrix built from the cross-covariance of the centred points.
fn horn(source: &[[f64; 3]], target: &[[f64; 3]]) -> Matrix3<f64> {
    let mean = |p: &[[f64; 3]]| {
        p.iter()
            .fold(Vector3::zeros(), |a, q| a + Vector3::from(*q))
            / p.len() as f64
    };
    let (cs, ct) = (mean(source), mean(target));
    let mut s = Matrix3::zeros();
    for (a, b) in source.iter().zip(target) {
        s += (Vector3::from(*a) - cs) * (Vector3::from(*b) - ct).transpose();
    }
    let (sxx, sxy, sxz) = (s[(0, 0)], s[(0, 1)], s[(0, 2)]);
    let (syx, syy, syz) = (s[(1, 0)], s[(1, 1)], s[(1, 2)]);
    let (szx, szy, szz) = (s[(2, 0)], s[(2, 1)], s[(2, 2)]);
    let n = Matrix4::new(
        sxx + syy + szz,
        syz - szy,
        szx - sxz,
        sxy - syx,
        syz - szy,
        sxx - syy - szz,
        sxy + syx,
        szx + sxz,
        szx - sxz,
        sxy + syx,
        -sxx + syy - szz,
        syz + szy,
        sxy - syx,
        szx + sxz,
        syz + szy,
        -sxx - syy + szz,
    );
    let eigen = SymmetricEigen::new(n);
    let k = eigen.eigenvalues.imax();
    let q = eigen.eigenvectors.column(k);
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    Matrix3::new(
        w * w + x * x - y * y - z * z,
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        w * w - x * x + y * y - z * z,
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        w * w - x * x - y * y + z * z,
    )
}

#[test]
fn procrustes_equals_horns_quaternion_solution_on_noisy_points() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for trial in 0..20 {
        let source = random_points(12, &mut rng);
        let r = random_rotation(&mut rng);
        let jitter = noise(1, 36, trial);
        let target: Vec<[f64; 3]> = source
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let q = r * Vector3::from(*p) + Vector3::new(3.0, -1.0, 2.0);
                [0, 1, 2].map(|d| q[d] + 0.5 * jitter[3 * i + d])
            })
            .collect();
        let map = procrustes(&source, &target, false).unwrap();
        let expected = horn(&source, &target);
        assert!(
            (map.rotation - expected).abs().max() < 1e-9,
            "trial {trial}: {} vs {}",
            map.rotation,
            expected
        );
        assert!((map.rotation.determinant() - 1.0).abs() < 1e-12);
        assert_eq!(map.scale, 1.0);
    }
}

#[test]
fn procrustes_recovers_a_similarity_and_never_reflects() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let source = random_points(10, &mut rng);
    let r = random_rotation(&mut rng);
    let target: Vec<[f64; 3]> = source
        .iter()
        .map(|p| (1.7 * (r * Vector3::from(*p)) + Vector3::new(-4.0, 5.0, 1.0)).into())
        .collect();
    let map = procrustes(&source, &target, true).unwrap();
    assert!((map.scale - 1.7).abs() < 1e-12);
    for (s, t) in source.iter().zip(&target) {
        let m = map.apply(*s);
        assert!((0..3).all(|d| (m[d] - t[d]).abs() < 1e-9));
    }
    // A mirror image is matched by a rotation (det +1), not by the reflection.
    let mirrored: Vec<[f64; 3]> = source.iter().map(|&[x, y, z]| [-x, y, z]).collect();
    let map = procrustes(&source, &mirrored, false).unwrap();
    assert!((map.rotation.determinant() - 1.0).abs() < 1e-12);
    // Coincident points and short sets are refused.
    assert!(procrustes(&[[1.0; 3]; 4], &source[..4], false).is_err());
    assert!(procrustes(&source[..2], &target[..2], false).is_err());
}

fn shape(points: Vec<[f64; 3]>, radii: Vec<f64>) -> AtomShape {
    AtomShape { points, radii }
}

#[test]
fn gpa_of_moved_copies_of_one_shape_has_no_variance() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let base = random_points(15, &mut rng);
    let radii: Vec<f64> = (0..15).map(|i| 1.0 + 0.1 * i as f64).collect();
    let copies: Vec<AtomShape> = (0..5)
        .map(|k| {
            let r = random_rotation(&mut rng);
            let s = 0.8 + 0.1 * k as f64;
            let t = Vector3::new(rng.gen(), rng.gen(), rng.gen()) * 20.0;
            shape(
                base.iter()
                    .map(|p| (s * (r * Vector3::from(*p)) + t).into())
                    .collect(),
                radii.iter().map(|x| x * s).collect(),
            )
        })
        .collect();
    let gpa = generalised_procrustes(&copies, true).unwrap();
    for aligned in &gpa.aligned {
        let d = aligned
            .to_vector()
            .iter()
            .zip(gpa.mean.to_vector())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(d < 1e-8, "aligned shape off the mean by {d}");
    }
    // The mean keeps the cohort's average size; its radii are the base's at that size.
    let average = copies.iter().map(|c| centroid_size(&c.points)).sum::<f64>() / 5.0;
    assert!((centroid_size(&gpa.mean.points) - average).abs() < 1e-9 * average);
    let factor = average / centroid_size(&base);
    for (r, b) in gpa.mean.radii.iter().zip(&radii) {
        assert!((r - b * factor).abs() < 1e-9);
    }
    let rows: Vec<f64> = gpa.aligned.iter().flat_map(|a| a.to_vector()).collect();
    let data = DMatrix::from_row_slice(5, 60, &rows);
    assert!(pca(&data).unwrap().modes.is_empty());
}

#[test]
fn pca_by_svd_equals_the_covariance_eigendecomposition() {
    let (n, p) = (9, 14);
    let values = noise(n, p, 5);
    let data = DMatrix::from_fn(n, p, |i, j| values[i * p + j] * (1.0 + j as f64 * 0.3));
    let result = pca(&data).unwrap();
    // Independent: the covariance matrix and its symmetric eigendecomposition.
    let mean: Vec<f64> = (0..p)
        .map(|j| (0..n).map(|i| data[(i, j)]).sum::<f64>() / n as f64)
        .collect();
    let centred = DMatrix::from_fn(n, p, |i, j| data[(i, j)] - mean[j]);
    let covariance = centred.transpose() * &centred / (n - 1) as f64;
    let eigen = SymmetricEigen::new(covariance.clone());
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    assert_eq!(result.modes.len(), n - 1, "rank n − 1 after centring");
    assert!((result.total_variance - covariance.trace()).abs() < 1e-10 * covariance.trace());
    for (k, &e) in order.iter().take(n - 1).enumerate() {
        assert!(
            (result.variances[k] - eigen.eigenvalues[e]).abs() < 1e-9 * eigen.eigenvalues[order[0]],
            "mode {k}"
        );
        let v = eigen.eigenvectors.column(e);
        let cos: f64 = result.modes[k]
            .iter()
            .zip(v.iter())
            .map(|(a, b)| a * b)
            .sum();
        assert!(
            (cos.abs() - 1.0).abs() < 1e-8,
            "mode {k}: |cos| = {}",
            cos.abs()
        );
        // Scores: the centred rows along the mode; their variance is the mode's.
        let scores = result.scores.column(k);
        let variance = scores.iter().map(|s| s * s).sum::<f64>() / (n - 1) as f64;
        assert!((variance - result.variances[k]).abs() < 1e-9 * result.variances[0]);
    }
    assert!((result.explained().iter().sum::<f64>() - 1.0).abs() < 1e-10);
}

/// A sheet of atoms on a 6 × 5 grid, bent out of its plane by `a` × (x² − mean) and thickened
/// by `a` × x / 10, then moved rigidly: one mode of shape.
fn bent_sheet(a: f64, rng: &mut ChaCha8Rng, jitter: f64) -> AtomShape {
    let r = random_rotation(rng);
    let t = Vector3::new(rng.gen(), rng.gen(), rng.gen()) * 30.0;
    let mut points = Vec::new();
    let mut radii = Vec::new();
    for i in 0..6 {
        for j in 0..5 {
            let x = i as f64 * 2.0 - 5.0;
            let y = j as f64 * 2.0 - 4.0;
            let z = a * (x * x - 35.0 / 3.0) / 10.0 + jitter * rng.gen_range(-1.0..1.0);
            points.push((r * Vector3::new(x, y, z) + t).into());
            radii.push(2.0 + a * x / 10.0 + jitter * rng.gen_range(-1.0..1.0));
        }
    }
    shape(points, radii)
}

#[test]
fn a_known_mode_is_found_after_rigid_gpa() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let amounts: Vec<f64> = (0..12).map(|k| (k as f64 - 5.5) * 0.4).collect();
    let cohort: Vec<AtomShape> = amounts
        .iter()
        .map(|&a| bent_sheet(a, &mut rng, 0.01))
        .collect();
    let gpa = generalised_procrustes(&cohort, false).unwrap();
    let rows: Vec<f64> = gpa.aligned.iter().flat_map(|a| a.to_vector()).collect();
    let data = DMatrix::from_row_slice(12, 120, &rows);
    let result = pca(&data).unwrap();
    let explained = result.explained();
    assert!(explained[0] > 0.99, "first mode explains {}", explained[0]);
    // Its scores follow the planted amounts (up to sign and scale).
    let scores: Vec<f64> = result.scores.column(0).iter().copied().collect();
    let corr = correlation(&scores, &amounts);
    assert!(corr.abs() > 0.999, "correlation {corr}");
    // The mode at +1 SD is the planted shape change: z ∝ x² − mean, r ∝ x, in the mean's frame.
    let unbent = bent_sheet(0.0, &mut ChaCha8Rng::seed_from_u64(0), 0.0);
    let to_mean = procrustes(&unbent.points, &gpa.mean.points, false).unwrap();
    let planted: Vec<f64> = {
        let bent = bent_sheet(1.0, &mut ChaCha8Rng::seed_from_u64(0), 0.0);
        let (a, b) = (bent.transformed(&to_mean), unbent.transformed(&to_mean));
        a.to_vector()
            .iter()
            .zip(b.to_vector())
            .map(|(x, y)| x - y)
            .collect()
    };
    let norm = planted.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos: f64 = result.modes[0]
        .iter()
        .zip(&planted)
        .map(|(m, p)| m * p / norm)
        .sum();
    assert!(
        cos.abs() > 0.99,
        "cos between mode and planted change {cos}"
    );
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}
