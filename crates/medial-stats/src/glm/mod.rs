//! The general linear model at every element: y_e = X β_e + ε, least squares, the contrast's
//! estimate, t or F, and parametric p-values.
//!
//! Elements with missing values (NaN) are fitted on the subjects they have, if at least
//! [`GlmOptions::min_observations`]; elements are grouped by which subjects they have, and each
//! group has its own least-squares model. The statistics of a batch of permutations are
//! computed group by group and block by block of elements as one matrix product: that is the
//! whole cost of a permutation test.
//!
//! | file | what it holds |
//! |---|---|
//! | `model` | the least-squares model of one design and contrast (bases, nuisance space) |
//! | `distribution` | t and F tail probabilities through the regularized incomplete beta function |

mod distribution;
mod model;

pub use distribution::{f_upper_tail, incomplete_beta, t_two_sided, t_upper_tail};

use std::collections::BTreeMap;

use nalgebra::DMatrix;

use crate::{Contrast, Design, Result, StatsError};
use model::Model;

/// Elements of a block: the statistics of a batch are computed this many elements at a time,
/// so that a block of residuals and of products stays in cache.
const BLOCK: usize = 512;

/// One measure at every element for every subject.
#[derive(Clone, Debug, PartialEq)]
pub struct Observations {
    subjects: usize,
    values: Vec<f64>,
}

impl Observations {
    /// `values` element after element, each element's `subjects` values together (the layout of
    /// a VTK array with one component per subject). NaN marks a missing value; infinities are
    /// refused.
    pub fn new(subjects: usize, values: Vec<f64>) -> Result<Self> {
        if subjects == 0 || values.is_empty() || values.len() % subjects != 0 {
            return Err(StatsError::Shape {
                what: "observations (a multiple of the subjects)",
                expected: subjects.max(1) * (values.len() / subjects.max(1)).max(1),
                found: values.len(),
            });
        }
        if values.iter().any(|v| v.is_infinite()) {
            return Err(StatsError::Data("an observation is infinite".into()));
        }
        Ok(Self { subjects, values })
    }

    /// Subjects.
    pub fn subjects(&self) -> usize {
        self.subjects
    }

    /// Elements.
    pub fn elements(&self) -> usize {
        self.values.len() / self.subjects
    }

    /// The values of element `e`, one per subject.
    pub fn element(&self, e: usize) -> &[f64] {
        &self.values[e * self.subjects..(e + 1) * self.subjects]
    }

    /// All values, element-major.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The observations of the subjects whose `keep` is true.
    pub fn select_subjects(&self, keep: &[bool]) -> Result<Self> {
        if keep.len() != self.subjects {
            return Err(StatsError::Shape {
                what: "row mask entries",
                expected: self.subjects,
                found: keep.len(),
            });
        }
        let values = self
            .values
            .chunks(self.subjects)
            .flat_map(|y| y.iter().zip(keep).filter(|(_, &k)| k).map(|(v, _)| *v))
            .collect();
        Self::new(keep.iter().filter(|&&k| k).count(), values)
    }

    pub(crate) fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }
}

/// Which side of the t distribution counts as evidence.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tail {
    /// cᵀβ > 0 (and F, which has one side).
    #[default]
    Positive,
    /// cᵀβ ≠ 0: inference on |t|.
    Both,
}

/// How the model is fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct GlmOptions {
    /// Fewest subjects with a value for an element to be fitted (raised to the design's rank
    /// plus one).
    pub min_observations: usize,
    /// Elements left out of the analysis (true: excluded), or `None`.
    pub exclude: Option<Vec<bool>>,
}

impl Default for GlmOptions {
    fn default() -> Self {
        Self {
            min_observations: 1,
            exclude: None,
        }
    }
}

/// Elements with the same subjects observed, and their model.
#[derive(Debug)]
pub(crate) struct Group {
    /// The subjects observed, increasing.
    rows: Vec<usize>,
    model: Model,
    /// The elements, increasing.
    elements: Vec<usize>,
    /// The residuals on the nuisance space, one column per element (rows × elements).
    residuals: DMatrix<f64>,
    /// |residual|² of each element.
    squared_norms: Vec<f64>,
}

/// The model fitted at every element, ready for permutations.
#[derive(Debug)]
pub struct Glm {
    subjects: usize,
    elements: usize,
    rows: usize,
    groups: Vec<Group>,
    estimate: Vec<f64>,
    standardised: Vec<f64>,
    df: Vec<f64>,
    observed: Vec<usize>,
}

impl Glm {
    /// Fits `contrast` of `design` at every element of `data`.
    ///
    /// ```
    /// use medial_stats::{Contrast, Design, Glm, GlmOptions, Observations};
    /// use nalgebra::dmatrix;
    ///
    /// let x = dmatrix![1.0, 0.0; 1.0, 0.0; 1.0, 0.0; 1.0, 1.0; 1.0, 1.0; 1.0, 1.0];
    /// let design = Design::new(vec!["intercept".into(), "patient".into()], x)?;
    /// let contrast = Contrast::parse("patient", &design)?;
    /// // Two elements of six subjects: the second is higher in patients.
    /// let y = vec![1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    /// let glm = Glm::new(&design, &contrast, &Observations::new(6, y)?, &GlmOptions::default())?;
    /// let t = glm.statistic();
    /// assert!(t[0].abs() < 1e-12 && t[1] > 3.0);
    /// assert!((glm.estimate()[1] - 3.0).abs() < 1e-12);
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn new(
        design: &Design,
        contrast: &Contrast,
        data: &Observations,
        options: &GlmOptions,
    ) -> Result<Self> {
        let n = design.subjects();
        if data.subjects() != n {
            return Err(StatsError::Shape {
                what: "subjects in the data",
                expected: n,
                found: data.subjects(),
            });
        }
        let m = data.elements();
        if let Some(exclude) = &options.exclude {
            if exclude.len() != m {
                return Err(StatsError::Shape {
                    what: "exclusion mask entries",
                    expected: m,
                    found: exclude.len(),
                });
            }
        }
        let x = design.matrix();
        let complete = Model::new(x, contrast.matrix(), contrast.name())?;
        // One residual degree of freedom at least.
        let minimum = options
            .min_observations
            .max(complete.width() - complete.q + 1);
        // Elements by the subjects they have.
        let mut patterns: BTreeMap<Vec<bool>, Vec<usize>> = BTreeMap::new();
        for e in 0..m {
            if options.exclude.as_ref().is_some_and(|x| x[e]) {
                continue;
            }
            let present: Vec<bool> = data.element(e).iter().map(|v| !v.is_nan()).collect();
            if present.iter().filter(|&&p| p).count() >= minimum {
                patterns.entry(present).or_default().push(e);
            }
        }
        let q = contrast.rows();
        let mut glm = Self {
            subjects: n,
            elements: m,
            rows: q,
            groups: Vec::new(),
            estimate: vec![f64::NAN; m * q],
            standardised: vec![f64::NAN; m * q],
            df: vec![f64::NAN; m],
            observed: vec![0; m],
        };
        for (present, elements) in patterns {
            let rows: Vec<usize> = (0..n).filter(|&i| present[i]).collect();
            let model = if rows.len() == n {
                complete.clone()
            } else {
                // A subset may lose the contrast (a whole group missing): its elements are left
                // out, as if excluded.
                match Model::new(
                    &x.select_rows(rows.iter()),
                    contrast.matrix(),
                    contrast.name(),
                ) {
                    Ok(model) => model,
                    Err(_) => continue,
                }
            };
            let y = DMatrix::from_fn(rows.len(), elements.len(), |i, j| {
                data.element(elements[j])[rows[i]]
            });
            glm.record_estimates(
                &model,
                contrast.matrix(),
                &x.select_rows(rows.iter()),
                &y,
                &elements,
            );
            let mut residuals = y;
            model.remove_nuisance(&mut residuals);
            let squared_norms = residuals.column_iter().map(|c| c.norm_squared()).collect();
            glm.groups.push(Group {
                rows,
                model,
                elements,
                residuals,
                squared_norms,
            });
        }
        if glm.groups.is_empty() {
            return Err(StatsError::Data(format!(
                "no element can be fitted (none has {minimum} subjects with values and is not excluded)"
            )));
        }
        Ok(glm)
    }

    /// Cβ̂ and the standardised C β̂ˢ at the elements of a group: β̂ˢⱼ = β̂ⱼ sd(xⱼ)/sd(y), with
    /// sd(xⱼ) taken as 1 for a constant column (the coefficients of the model refitted to y and
    /// the non-constant columns scaled to unit standard deviation).
    fn record_estimates(
        &mut self,
        model: &Model,
        c: &DMatrix<f64>,
        x: &DMatrix<f64>,
        y: &DMatrix<f64>,
        elements: &[usize],
    ) {
        let sd = |v: &[f64]| {
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            (v.iter().map(|a| (a - mean) * (a - mean)).sum::<f64>() / (n - 1.0)).sqrt()
        };
        let column_sd = x.column_iter().map(|col| {
            let s = sd(col.as_slice());
            if s > 0.0 {
                s
            } else {
                1.0
            }
        });
        let c_scaled =
            c * DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(x.ncols(), column_sd));
        let beta = &model.pinv * y;
        let estimate = c * &beta;
        let scaled = c_scaled * &beta;
        let q = self.rows;
        for (j, &e) in elements.iter().enumerate() {
            let y_sd = sd(y.column(j).as_slice());
            self.df[e] = model.df as f64;
            self.observed[e] = x.nrows();
            for r in 0..q {
                self.estimate[e * q + r] = estimate[(r, j)];
                self.standardised[e * q + r] = scaled[(r, j)] / y_sd;
            }
        }
    }

    /// The statistic (t, or F for a contrast of several rows) at every element for each
    /// permutation of the batch: `out[k × elements + e]`, NaN at elements not fitted. A
    /// permutation π gives subject i the residual of subject π(i) (residuals on the nuisance
    /// space: Freedman–Lane); an element missing some subjects takes π's order of the subjects
    /// it has.
    pub(crate) fn statistics<P: AsRef<[u32]>>(&self, permutations: &[P], out: &mut [f64]) {
        let batch = permutations.len();
        debug_assert_eq!(out.len(), batch * self.elements);
        out.fill(f64::NAN);
        let mut position = vec![usize::MAX; self.subjects];
        for group in &self.groups {
            let model = &group.model;
            let w = model.width();
            position.fill(usize::MAX);
            for (k, &i) in group.rows.iter().enumerate() {
                position[i] = k;
            }
            // [Bᵀ; Uᵀ] with its columns moved by each permutation, stacked.
            let mut moved = DMatrix::zeros(batch * w, group.rows.len());
            for (b, permutation) in permutations.iter().enumerate() {
                let targets = permutation
                    .as_ref()
                    .iter()
                    .map(|&j| position[j as usize])
                    .filter(|&k| k != usize::MAX);
                for (k, target) in targets.enumerate() {
                    for r in 0..w {
                        moved[(b * w + r, target)] = model.g[(r, k)];
                    }
                }
            }
            let count = group.elements.len();
            let mut products = DMatrix::zeros(batch * w, BLOCK.min(count));
            for start in (0..count).step_by(BLOCK) {
                let width = BLOCK.min(count - start);
                products.columns_mut(0, width).gemm(
                    1.0,
                    &moved,
                    &group.residuals.columns(start, width),
                    0.0,
                );
                let all = products.as_slice();
                for j in 0..width {
                    let column = &all[j * batch * w..(j + 1) * batch * w];
                    let e = group.elements[start + j];
                    let norm = group.squared_norms[start + j];
                    for (b, g) in column.chunks_exact(w).enumerate() {
                        out[b * self.elements + e] = model.statistic(g, norm);
                    }
                }
            }
        }
    }

    /// The statistic of the data as they are (t, or F for a contrast of several rows); NaN at
    /// elements not fitted.
    pub fn statistic(&self) -> Vec<f64> {
        let identity: Vec<u32> = (0..self.subjects as u32).collect();
        let mut out = vec![0.0; self.elements];
        self.statistics(&[identity], &mut out);
        out
    }

    /// Parametric p-values of `statistic` (as [`Glm::statistic`] gives it): t on the side(s)
    /// of `tail`, F on its upper tail.
    pub fn p_values(&self, statistic: &[f64], tail: Tail) -> Vec<f64> {
        statistic
            .iter()
            .zip(&self.df)
            .map(|(&s, &df)| match (self.rows, tail) {
                (1, Tail::Positive) => t_upper_tail(s, df),
                (1, Tail::Both) => t_two_sided(s, df),
                (q, _) => f_upper_tail(s, q as f64, df),
            })
            .collect()
    }

    /// Cβ̂ at every element, `rows()` values per element (NaN where not fitted).
    pub fn estimate(&self) -> &[f64] {
        &self.estimate
    }

    /// Cβ̂ˢ, the contrast of the standardised coefficients (β̂ⱼ sd(xⱼ)/sd(y), sd of a constant
    /// column taken as 1), `rows()` values per element.
    pub fn standardised_estimate(&self) -> &[f64] {
        &self.standardised
    }

    /// Residual degrees of freedom at every element (NaN where not fitted).
    pub fn degrees_of_freedom(&self) -> &[f64] {
        &self.df
    }

    /// Subjects with a value at every element (0 where not fitted).
    pub fn observed(&self) -> &[usize] {
        &self.observed
    }

    /// Contrast rows q: 1 for t, more for F.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Subjects.
    pub fn subjects(&self) -> usize {
        self.subjects
    }

    /// Elements.
    pub fn elements(&self) -> usize {
        self.elements
    }
}
