//! An analysis from data to maps: the options in one place, the subjects' row mask and the
//! smoothing applied once ([`Study::new`]), then each contrast tested ([`Study::test`]): the GLM,
//! parametric p, FDR q, and with permutations the FWER-corrected p of the statistic, of
//! clusters and of TFCE.

use crate::mesh::{find_clusters, smooth, tfce, Clusters, Elements, TfceParameters};
use crate::permutation::{exceedance, magnitude, run, NullDistributions, Scheme, Spatial};
use crate::{q_values, Contrast, Design, Glm, GlmOptions, Observations, Result, StatsError, Tail};

/// Everything an analysis can be asked for.
#[derive(Clone, Debug, PartialEq)]
pub struct Options {
    /// One-sided (cᵀβ > 0) or two-sided t-tests; F-tests are one-sided.
    pub tail: Tail,
    /// Random permutations (the identity comes on top; all distinct ones when they are fewer);
    /// 0: parametric inference only.
    pub permutations: usize,
    /// The seed of the permutations.
    pub seed: u64,
    /// Cluster-forming threshold on the statistic (|t| when two-sided), or no clusters.
    pub cluster_threshold: Option<f64>,
    /// TFCE, or none.
    pub tfce: Option<TfceParameters>,
    /// Benjamini–Hochberg q-values of the parametric p.
    pub fdr: bool,
    /// Fewest subjects with a value (not NaN) for an element to be fitted.
    pub min_observations: usize,
    /// Elements left out (true), or none.
    pub exclude: Option<Vec<bool>>,
    /// Subjects kept (true), or all.
    pub rows: Option<Vec<bool>>,
    /// Smoothing of every subject's map by heat diffusion on the mesh, FWHM in mm.
    pub fwhm: Option<f64>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            tail: Tail::Positive,
            permutations: 0,
            seed: 0,
            cluster_threshold: None,
            tfce: None,
            fdr: false,
            min_observations: 1,
            exclude: None,
            rows: None,
            fwhm: None,
        }
    }
}

/// Design, data and mesh, checked against each other, the row mask applied and the data
/// smoothed: ready for contrasts.
#[derive(Debug)]
pub struct Study<'a> {
    design: Design,
    data: Observations,
    elements: Option<&'a Elements>,
    options: Options,
}

/// The permutations an analysis used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PermutationSummary {
    /// Permutations in all, the identity included.
    pub count: usize,
    /// Whether they were every distinct permutation.
    pub exact: bool,
    /// The seed (of random permutations).
    pub seed: u64,
}

/// Clusters of the observed map and their corrected p-values.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterInference {
    /// The cluster-forming threshold.
    pub threshold: f64,
    /// The clusters and every element's cluster id.
    pub found: Clusters,
    /// Each cluster's FWER p by its area (NaN without permutations).
    pub p_area: Vec<f64>,
    /// Each cluster's FWER p by its mass (NaN without permutations).
    pub p_mass: Vec<f64>,
}

impl ClusterInference {
    /// Each element's cluster p by area: its cluster's, 1 outside every cluster.
    pub fn element_p(&self) -> Vec<f64> {
        self.found
            .labels
            .iter()
            .map(|&id| if id == 0 { 1.0 } else { self.p_area[id - 1] })
            .collect()
    }
}

/// The maps and tables of one contrast. Maps have one value per element (`rows` per element for
/// the estimates); NaN where an element was not fitted.
#[derive(Clone, Debug, PartialEq)]
pub struct ContrastResult {
    /// The contrast's name.
    pub name: String,
    /// Contrast rows: 1 (t) or more (F).
    pub rows: usize,
    /// The sides tested.
    pub tail: Tail,
    /// Cβ̂.
    pub estimate: Vec<f64>,
    /// Cβ̂ of the standardised coefficients.
    pub standardised: Vec<f64>,
    /// t (or F).
    pub statistic: Vec<f64>,
    /// Residual degrees of freedom.
    pub df: Vec<f64>,
    /// Subjects with a value.
    pub observed: Vec<usize>,
    /// Parametric p.
    pub p: Vec<f64>,
    /// Benjamini–Hochberg q of `p`, if asked for.
    pub q: Option<Vec<f64>>,
    /// The permutations, if any.
    pub permutations: Option<PermutationSummary>,
    /// FWER-corrected p of the statistic (maximum statistic), with permutations.
    pub p_fwer: Option<Vec<f64>>,
    /// Clusters, with a threshold.
    pub clusters: Option<ClusterInference>,
    /// TFCE, if asked for.
    pub tfce: Option<Vec<f64>>,
    /// FWER-corrected p of TFCE, with permutations.
    pub p_tfce: Option<Vec<f64>>,
    /// The maxima of every permutation (empty without permutations).
    pub null: NullDistributions,
}

impl<'a> Study<'a> {
    /// Checks the inputs against each other and the options, keeps the subjects of the row mask
    /// and smooths the data.
    ///
    /// ```
    /// use medial_stats::{Contrast, Design, Elements, Mesh, Observations, Options, Study, Support};
    /// use nalgebra::DMatrix;
    ///
    /// // Eight subjects, two groups; a strip of four triangles, cells 0 and 1 higher in group 2.
    /// let x = DMatrix::from_fn(8, 2, |i, j| if j == 0 { 1.0 } else { f64::from(u8::from(i >= 4)) });
    /// let design = Design::new(vec!["intercept".into(), "group2".into()], x)?;
    /// let mesh = Mesh::new(
    ///     (0..6).map(|i| [f64::from(i / 2), f64::from(i % 2), 0.0]).collect(),
    ///     vec![[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]],
    /// )?;
    /// let cells = Elements::new(&mesh, Support::Cells);
    /// let y: Vec<f64> = (0..4)
    ///     .flat_map(|e| (0..8).map(move |i| {
    ///         let noise = ((i * 7 + e * 3) % 5) as f64 * 0.1;
    ///         noise + if e < 2 && i >= 4 { 3.0 } else { 0.0 }
    ///     }))
    ///     .collect();
    /// let options = Options { permutations: 1000, cluster_threshold: Some(2.0), ..Options::default() };
    /// let study = Study::new(&design, &Observations::new(8, y)?, Some(&cells), options)?;
    /// let result = study.test(&Contrast::parse("group2", &design)?)?;
    /// // 70 distinct permutations: enumerated; the smallest p is 1/70.
    /// assert_eq!(result.permutations.unwrap().count, 70);
    /// assert_eq!(result.p_fwer.as_ref().unwrap()[0], 1.0 / 70.0);
    /// assert_eq!(result.clusters.as_ref().unwrap().found.labels, [1, 1, 0, 0]);
    /// # Ok::<(), medial_stats::StatsError>(())
    /// ```
    pub fn new(
        design: &Design,
        data: &Observations,
        elements: Option<&'a Elements>,
        options: Options,
    ) -> Result<Self> {
        if data.subjects() != design.subjects() {
            return Err(StatsError::Shape {
                what: "subjects in the data (one per design row)",
                expected: design.subjects(),
                found: data.subjects(),
            });
        }
        if let Some(elements) = elements {
            if elements.len() != data.elements() {
                return Err(StatsError::Shape {
                    what: "elements of the mesh",
                    expected: data.elements(),
                    found: elements.len(),
                });
            }
        }
        if let Some(h) = options.cluster_threshold {
            if !(h >= 0.0 && h.is_finite()) {
                return Err(StatsError::parameter(
                    "threshold",
                    h,
                    "must be finite and ≥ 0",
                ));
            }
        }
        if let Some(parameters) = &options.tfce {
            parameters.validate()?;
        }
        if elements.is_none() {
            let needs_mesh = [
                ("threshold", options.cluster_threshold.is_some()),
                ("tfce", options.tfce.is_some()),
                ("fwhm", options.fwhm.is_some()),
            ];
            if let Some((name, _)) = needs_mesh.iter().find(|(_, asked)| *asked) {
                return Err(StatsError::parameter(
                    name,
                    "given",
                    "needs a mesh (elements with areas and neighbours)",
                ));
            }
        }
        let (design, mut data) = match &options.rows {
            Some(keep) => (design.select_rows(keep)?, data.select_subjects(keep)?),
            None => (design.clone(), data.clone()),
        };
        if let (Some(fwhm), Some(elements)) = (options.fwhm, elements) {
            let subjects = data.subjects();
            smooth(data.values_mut(), subjects, fwhm, elements)?;
        }
        Ok(Self {
            design,
            data,
            elements,
            options,
        })
    }

    /// The design after the row mask.
    pub fn design(&self) -> &Design {
        &self.design
    }

    /// The data after the row mask and smoothing.
    pub fn data(&self) -> &Observations {
        &self.data
    }

    /// Tests `contrast` (made on the same design's columns).
    pub fn test(&self, contrast: &Contrast) -> Result<ContrastResult> {
        let options = &self.options;
        if contrast.matrix().ncols() != self.design.names().len() {
            return Err(StatsError::Shape {
                what: "contrast weights (one per design column)",
                expected: self.design.names().len(),
                found: contrast.matrix().ncols(),
            });
        }
        let tail = options.tail;
        if contrast.rows() > 1 && tail == Tail::Both {
            return Err(StatsError::parameter(
                "two-sided",
                contrast.name(),
                "applies to t-contrasts; an F-test has one side",
            ));
        }
        let glm_options = GlmOptions {
            min_observations: options.min_observations,
            exclude: options.exclude.clone(),
        };
        let glm = Glm::new(&self.design, contrast, &self.data, &glm_options)?;
        let spatial = self.elements.map(|elements| Spatial {
            elements,
            threshold: options.cluster_threshold,
            tfce: options.tfce,
        });
        let (statistic, tfce_values, null, permutations) = if options.permutations > 0 {
            let scheme = Scheme::choose(self.design.matrix(), options.permutations, options.seed);
            if scheme.len() == 1 {
                return Err(StatsError::Data(format!(
                    "contrast `{}`: every subject has the same design row, so no permutation \
                     changes the statistic (a one-sample test needs sign flips)",
                    contrast.name()
                )));
            }
            let permuted = run(&glm, &scheme, tail, spatial);
            let summary = PermutationSummary {
                count: scheme.len(),
                exact: scheme.is_exact(),
                seed: options.seed,
            };
            (
                permuted.statistic,
                permuted.tfce,
                permuted.null,
                Some(summary),
            )
        } else {
            let statistic = glm.statistic();
            let tfce_values = match (&options.tfce, spatial) {
                (Some(parameters), Some(spatial)) => {
                    Some(tfce(&statistic, parameters, tail, spatial.elements))
                }
                _ => None,
            };
            (statistic, tfce_values, NullDistributions::default(), None)
        };
        let p = glm.p_values(&statistic, tail);
        let q = options.fdr.then(|| q_values(&p));
        let permuted = permutations.is_some();
        let p_fwer = permuted.then(|| {
            exceedance(
                statistic.iter().map(|&s| magnitude(s, tail)),
                &null.statistic,
            )
        });
        let clusters = match (options.cluster_threshold, spatial) {
            (Some(threshold), Some(spatial)) => {
                let found = find_clusters(&statistic, threshold, tail, spatial.elements);
                let p_of = |values: Vec<f64>, null: &[f64]| {
                    if permuted {
                        exceedance(values.into_iter(), null)
                    } else {
                        vec![f64::NAN; found.clusters.len()]
                    }
                };
                let p_area = p_of(found.clusters.iter().map(|c| c.area).collect(), &null.area);
                let p_mass = p_of(found.clusters.iter().map(|c| c.mass).collect(), &null.mass);
                Some(ClusterInference {
                    threshold,
                    found,
                    p_area,
                    p_mass,
                })
            }
            _ => None,
        };
        let p_tfce = match (&tfce_values, permuted) {
            (Some(values), true) => Some(exceedance(values.iter().map(|v| v.abs()), &null.tfce)),
            _ => None,
        };
        Ok(ContrastResult {
            name: contrast.name().to_string(),
            rows: contrast.rows(),
            tail,
            estimate: glm.estimate().to_vec(),
            standardised: glm.standardised_estimate().to_vec(),
            statistic,
            df: glm.degrees_of_freedom().to_vec(),
            observed: glm.observed().to_vec(),
            p,
            q,
            permutations,
            p_fwer,
            clusters,
            tfce: tfce_values,
            p_tfce,
            null,
        })
    }
}
