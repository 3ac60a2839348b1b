//! An independent dense implementation of the flow, the kinetic energy and the adjoint
//! gradient, written with whole matrices (nalgebra) and `f64::exp` for every ordered pair.
//!
//! It is the baseline of the benchmarks and the reference the fused implementation of
//! [`crate::flow`] is tested against. The adjoint is written in matrix form:
//! `S = A Uᵀ + U Aᵀ + w U Uᵀ`, `M = K ∘ S`, `a^n = a^{n+1} + ∇Φ^n − (dt/σ²)(diag(M 1) Q − M Q)`,
//! `∂E/∂U^n = dt K (A + w U)`.

use crate::Vec3;
use nalgebra::DMatrix;

/// `E = w_kin·KE + Σ_{n=1..N} Φ(n, q^n)` and its gradient with respect to the controls (flat,
/// `u[(n·k + i)·3 + c]`). `phi(n, q)` returns `Φ` at time point `n` and its gradient in `q`.
pub fn objective(
    q0: &[Vec3],
    u: &[f64],
    sigma: f64,
    steps: usize,
    kinetic_weight: f64,
    phi: impl Fn(usize, &[Vec3]) -> (f64, Vec<Vec3>),
) -> (f64, Vec<f64>) {
    let k = q0.len();
    let dt = 1.0 / steps as f64;
    let controls: Vec<DMatrix<f64>> = (0..steps)
        .map(|n| DMatrix::from_row_slice(k, 3, &u[n * k * 3..(n + 1) * k * 3]))
        .collect();
    let mut qs = vec![DMatrix::from_fn(k, 3, |i, c| q0[i][c])];
    let mut kernels = Vec::with_capacity(steps);
    let mut kinetic = 0.0;
    for un in &controls {
        let kmat = gaussian_matrix(qs.last().expect("q^0 is there"), sigma);
        kinetic += 0.5 * dt * (un.transpose() * &kmat * un).trace();
        qs.push(qs.last().expect("q^0 is there") + dt * &kmat * un);
        kernels.push(kmat);
    }
    let mut value = kinetic_weight * kinetic;
    let mut phi_grads = Vec::with_capacity(steps + 1);
    phi_grads.push(DMatrix::zeros(k, 3));
    for (n, q) in qs.iter().enumerate().skip(1) {
        let (v, g) = phi(n, &to_points(q));
        value += v;
        phi_grads.push(DMatrix::from_fn(k, 3, |i, c| g[i][c]));
    }
    let mut a = phi_grads[steps].clone();
    let mut grad = vec![0.0; u.len()];
    for n in (0..steps).rev() {
        let (kmat, un, q) = (&kernels[n], &controls[n], &qs[n]);
        let g = dt * kmat * (&a + kinetic_weight * un);
        for i in 0..k {
            for c in 0..3 {
                grad[(n * k + i) * 3 + c] = g[(i, c)];
            }
        }
        let s = &a * un.transpose() + un * a.transpose() + kinetic_weight * un * un.transpose();
        let m = kmat.component_mul(&s);
        let row_sums = &m * DMatrix::from_element(k, 1, 1.0);
        let diag_q = DMatrix::from_fn(k, 3, |i, c| row_sums[i] * q[(i, c)]);
        a = &a - (dt / (sigma * sigma)) * (diag_q - &m * q) + &phi_grads[n];
    }
    (value, grad)
}

/// `K_ij = exp(−|q_i − q_j|² / (2σ²))` with `f64::exp` for every ordered pair.
fn gaussian_matrix(q: &DMatrix<f64>, sigma: f64) -> DMatrix<f64> {
    let k = q.nrows();
    DMatrix::from_fn(k, k, |i, j| {
        let d2 = (q.row(i) - q.row(j)).norm_squared();
        (-d2 / (2.0 * sigma * sigma)).exp()
    })
}

fn to_points(q: &DMatrix<f64>) -> Vec<Vec3> {
    (0..q.nrows())
        .map(|i| Vec3::new(q[(i, 0)], q[(i, 1)], q[(i, 2)]))
        .collect()
}
