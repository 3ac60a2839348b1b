//! Smoothing on the mesh by heat diffusion, u̇ = −M⁻¹L u, with L the cotangent Laplacian on
//! points (the finite-volume Laplacian of the triangle adjacency on cells: edge length over the
//! distance of the centroids) and M the lumped areas. On a plane the diffusion during a time T
//! is a Gaussian of variance 2T per axis, hence of FWHM √(16 ln 2 · T): the time used for a FWHM
//! in mm is T = FWHM² / (16 ln 2). Explicit Euler steps, as many as stability asks (a step of at
//! most the inverse of Gershgorin's bound on M⁻¹L's eigenvalues), keep every subject's integral
//! Σ mₐuₐ.

use super::Elements;
use crate::{Result, StatsError};

/// The diffusion time T (mm²) of a FWHM (mm): FWHM² / (16 ln 2).
pub fn diffusion_time(fwhm: f64) -> f64 {
    fwhm * fwhm / (16.0 * std::f64::consts::LN_2)
}

/// Smooths `values` (element after element, each element's `subjects` values together) on the
/// mesh with a Gaussian of `fwhm` mm. Values must be finite (smooth before leaving subjects out,
/// not after marking them missing).
pub fn smooth(values: &mut [f64], subjects: usize, fwhm: f64, elements: &Elements) -> Result<()> {
    if !(fwhm >= 0.0 && fwhm.is_finite()) {
        return Err(StatsError::parameter(
            "fwhm",
            fwhm,
            "must be finite and ≥ 0 (mm)",
        ));
    }
    if values.len() != subjects * elements.len() {
        return Err(StatsError::Shape {
            what: "values to smooth",
            expected: subjects * elements.len(),
            found: values.len(),
        });
    }
    if values.iter().any(|v| !v.is_finite()) {
        return Err(StatsError::Data(
            "smoothing needs a value at every element for every subject (found NaN)".into(),
        ));
    }
    let time = diffusion_time(fwhm);
    if time == 0.0 {
        return Ok(());
    }
    let nodes = elements.mass.len();
    // Node values: the area-weighted mean of the elements at the node.
    let mut u = vec![0.0; nodes * subjects];
    let mut weight = vec![0.0; nodes];
    for (e, &node) in elements.node.iter().enumerate() {
        let a = elements.areas()[e];
        weight[node] += a;
        for i in 0..subjects {
            u[node * subjects + i] += a * values[e * subjects + i];
        }
    }
    for (node, &w) in weight.iter().enumerate() {
        if w > 0.0 {
            u[node * subjects..(node + 1) * subjects]
                .iter_mut()
                .for_each(|v| *v /= w);
        }
    }
    let mut bound = vec![0.0; nodes];
    for &(a, b, w) in &elements.couplings {
        bound[a] += 2.0 * w.abs();
        bound[b] += 2.0 * w.abs();
    }
    let rate = (0..nodes)
        .filter(|&a| elements.mass[a] > 0.0)
        .map(|a| bound[a] / elements.mass[a])
        .fold(0.0, f64::max);
    let steps = (time * rate).ceil().max(1.0) as usize;
    let dt = time / steps as f64;
    let mut change = vec![0.0; nodes * subjects];
    for _ in 0..steps {
        change.fill(0.0);
        for &(a, b, w) in &elements.couplings {
            for i in 0..subjects {
                let flux = w * (u[b * subjects + i] - u[a * subjects + i]);
                change[a * subjects + i] += flux;
                change[b * subjects + i] -= flux;
            }
        }
        for a in 0..nodes {
            let m = elements.mass[a];
            if m > 0.0 {
                for i in 0..subjects {
                    u[a * subjects + i] += dt * change[a * subjects + i] / m;
                }
            }
        }
    }
    for (e, &node) in elements.node.iter().enumerate() {
        values[e * subjects..(e + 1) * subjects]
            .copy_from_slice(&u[node * subjects..(node + 1) * subjects]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{Mesh, Support};

    /// A flat regular grid of 2·n² right triangles of side h, centred on the origin.
    fn flat(n: usize, h: f64) -> Mesh {
        let half = n as f64 * h / 2.0;
        Mesh::grid(n, |i, j| [i as f64 * h - half, j as f64 * h - half, 0.0]).unwrap()
    }

    /// A spike at the centre spreads into a Gaussian of the FWHM asked for: its second moment
    /// Σ m u |x|² / Σ m u is 4T, and its integral is kept.
    #[test]
    fn a_spike_becomes_a_gaussian_of_the_fwhm() {
        let (n, h, fwhm) = (60, 0.5, 4.0);
        let mesh = flat(n, h);
        for support in [Support::Points, Support::Cells] {
            let elements = Elements::new(&mesh, support);
            let centre_of = |e: usize| -> [f64; 2] {
                match support {
                    Support::Points => [mesh.points()[e][0], mesh.points()[e][1]],
                    Support::Cells => {
                        let t = mesh.triangles()[e];
                        [0, 1].map(|d| t.iter().map(|&k| mesh.points()[k][d]).sum::<f64>() / 3.0)
                    }
                }
            };
            let centre = (0..elements.len())
                .min_by(|&a, &b| {
                    let (pa, pb) = (centre_of(a), centre_of(b));
                    (pa[0].hypot(pa[1])).total_cmp(&pb[0].hypot(pb[1]))
                })
                .unwrap();
            let mut u = vec![0.0; elements.len()];
            u[centre] = 1.0 / elements.areas()[centre];
            smooth(&mut u, 1, fwhm, &elements).unwrap();
            let integral: f64 = u.iter().zip(elements.areas()).map(|(v, a)| v * a).sum();
            assert!(
                (integral - 1.0).abs() < 1e-12,
                "{support:?}: integral {integral}"
            );
            let c0 = centre_of(centre);
            let moment: f64 = (0..elements.len())
                .map(|e| {
                    let c = centre_of(e);
                    u[e] * elements.areas()[e] * ((c[0] - c0[0]).powi(2) + (c[1] - c0[1]).powi(2))
                })
                .sum();
            let expected = 4.0 * diffusion_time(fwhm);
            assert!(
                (moment / expected - 1.0).abs() < 0.05,
                "{support:?}: {moment} vs {expected}"
            );
        }
    }

    #[test]
    fn constants_stay_and_bad_input_is_refused() {
        let elements = Elements::new(&flat(4, 1.0), Support::Points);
        let mut u = vec![2.5; elements.len() * 3];
        smooth(&mut u, 3, 2.0, &elements).unwrap();
        assert!(u.iter().all(|v| (v - 2.5).abs() < 1e-12));
        assert!(smooth(&mut u, 3, -1.0, &elements).is_err());
        u[4] = f64::NAN;
        assert!(smooth(&mut u, 3, 1.0, &elements).is_err());
        assert!(smooth(&mut u[..6], 3, 1.0, &elements).is_err());
    }
}
