//! The least-squares model of one design and contrast, in the form that makes a permutation a
//! small matrix product.
//!
//! With X = U S Vᵀ (rank r, U the n × r basis of its columns), X⁺ = V S⁻¹ Uᵀ and A = X⁺ᵀ Cᵀ
//! (n × q), the contrast's estimate is Cβ̂ = Aᵀy and its covariance factor
//! C(XᵀX)⁻¹Cᵀ = AᵀA. With B an orthonormal basis of A's columns (B = a/|a| for one row),
//! t = bᵀy / s and F = |Bᵀy|² / (q s²), s² = rss/(n − r). The nuisance space is X's columns
//! under the null hypothesis, span(X N) with N a basis of C's null space, of dimension r − q;
//! A's columns are orthogonal to it and complete it to X's columns. With W an orthonormal basis
//! of it, the statistic of any data vector y needs only g = [Bᵀ; Wᵀ] y (r numbers) and |y|²:
//! rss = |y|² − |g|². Data are permuted after their nuisance part is removed (Freedman–Lane),
//! which leaves the statistic of the unpermuted data unchanged because Cβ̂ and the residuals
//! ignore that part.

use nalgebra::{DMatrix, DVector};

use crate::{Result, StatsError};

/// The indices of the singular values `s` of an `n` × `p` matrix above the usual tolerance
/// (`scale` × max(n, p) × ε, `scale` the largest singular value of the design): those that count
/// in its rank.
fn significant(s: &DVector<f64>, n: usize, p: usize, scale: f64) -> Vec<usize> {
    let tolerance = scale * (n.max(p) as f64) * f64::EPSILON;
    (0..s.len())
        .filter(|&k| s[k] > tolerance && s[k] > 0.0)
        .collect()
}

/// An orthonormal basis of the columns of `m`, whose singular values count against `scale`.
fn column_basis(m: &DMatrix<f64>, scale: f64) -> DMatrix<f64> {
    if m.ncols() == 0 {
        return DMatrix::zeros(m.nrows(), 0);
    }
    let svd = m.clone().svd(true, false);
    let keep = significant(&svd.singular_values, m.nrows(), m.ncols(), scale);
    svd.u.expect("requested U").select_columns(keep.iter())
}

/// A design and contrast ready for many data vectors.
#[derive(Clone, Debug)]
pub(crate) struct Model {
    /// r × n: the rows of Bᵀ, then those of Wᵀ.
    pub(crate) g: DMatrix<f64>,
    /// Contrast rows.
    pub(crate) q: usize,
    /// Residual degrees of freedom n − r.
    pub(crate) df: usize,
    /// X⁺ (p × n): β̂ = X⁺y.
    pub(crate) pinv: DMatrix<f64>,
    /// An orthonormal basis of the nuisance space (n × r₀).
    nuisance: DMatrix<f64>,
}

impl Model {
    /// The model of design `x` (n × p) and contrast `c` (q × p). Fails when the contrast is not
    /// estimable (not in the row space of X) or no degree of freedom is left.
    pub(crate) fn new(x: &DMatrix<f64>, c: &DMatrix<f64>, name: &str) -> Result<Self> {
        let (n, p) = x.shape();
        let q = c.nrows();
        let svd = x.clone().svd(true, true);
        let (u, v_t) = (svd.u.expect("requested U"), svd.v_t.expect("requested V"));
        let s = &svd.singular_values;
        let keep = significant(s, n, p, s.max());
        let rank = keep.len();
        if rank == 0 {
            return Err(StatsError::Data("the design matrix is zero".into()));
        }
        let u = u.select_columns(keep.iter());
        let v = v_t.select_rows(keep.iter()).transpose();
        let s_inv = DMatrix::from_diagonal(&DVector::from_iterator(
            rank,
            keep.iter().map(|&k| 1.0 / s[k]),
        ));
        let pinv = &v * s_inv * u.transpose();
        for i in 0..q {
            let row = c.row(i).transpose();
            let in_rows = &v * (v.transpose() * &row);
            if (&row - in_rows).norm() > 1e-8 * row.norm() {
                return Err(StatsError::contrast(
                    name,
                    "is not estimable: the design's columns are collinear along it",
                ));
            }
        }
        if n <= rank {
            return Err(StatsError::Data(format!(
                "{n} subjects leave no degree of freedom for a design of rank {rank}"
            )));
        }
        let a = pinv.transpose() * c.transpose();
        let b = if q == 1 {
            let norm = a.norm();
            a / norm
        } else {
            a.qr().q()
        };
        // The projector on C's null space, I − C⁺C (C has full row rank: checked by the
        // contrast); X times it spans the model under the null hypothesis.
        let c_pinv = c
            .clone()
            .pseudo_inverse(1e-12)
            .expect("a non-negative tolerance");
        let null_of_c = DMatrix::identity(p, p) - c_pinv * c;
        let nuisance = column_basis(&(x * null_of_c), s.max());
        if nuisance.ncols() + q != rank {
            return Err(StatsError::contrast(
                name,
                "is numerically at the edge of estimability: its nuisance space does not \
                 complete it to the design's columns",
            ));
        }
        let mut g = DMatrix::zeros(rank, n);
        g.rows_mut(0, q).copy_from(&b.transpose());
        g.rows_mut(q, rank - q).copy_from(&nuisance.transpose());
        Ok(Self {
            g,
            q,
            df: n - rank,
            pinv,
            nuisance,
        })
    }

    /// Rows of g: the rank of X.
    pub(crate) fn width(&self) -> usize {
        self.g.nrows()
    }

    /// The residuals of data (columns of `y`, n × m) on the nuisance space, in place.
    pub(crate) fn remove_nuisance(&self, y: &mut DMatrix<f64>) {
        if self.nuisance.ncols() > 0 {
            let part = &self.nuisance * (self.nuisance.transpose() * &*y);
            *y -= part;
        }
    }

    /// The statistic (t for one contrast row, F for more) from g = [Bᵀ; Wᵀ] y and |y|²; NaN
    /// when the residual variance is zero.
    pub(crate) fn statistic(&self, g: &[f64], squared_norm: f64) -> f64 {
        let projection: f64 = g.iter().map(|v| v * v).sum();
        let variance = (squared_norm - projection) / self.df as f64;
        if variance.is_nan() || variance <= 0.0 {
            return f64::NAN;
        }
        if self.q == 1 {
            g[0] / variance.sqrt()
        } else {
            g[..self.q].iter().map(|v| v * v).sum::<f64>() / (self.q as f64 * variance)
        }
    }
}
