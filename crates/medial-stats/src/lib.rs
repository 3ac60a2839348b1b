//! # medial-stats
//!
//! Statistics on meshes in correspondence: every subject's measure at the same elements (points
//! or triangles of one mesh), a general linear model at every element, and inference corrected
//! over the mesh by permutations (maximum statistic, clusters, TFCE), as cmrep's `meshglm` and
//! FSL's PALM do it. The formulas are in the project's docs/stats.md and in each module.
//!
//! A [`Study`] takes a [`Design`], [`Observations`], the mesh's [`Elements`] and [`Options`];
//! [`Study::test`] gives a [`ContrastResult`] for each [`Contrast`]. Results are the same bits
//! for any number of threads.
//!
//! ## Contents
//!
//! | module | what it holds | entry points |
//! |---|---|---|
//! | [`design`] | the design matrix: CSV tables with named and categorical columns, meshglm's whitespace files; rows matched to subjects by name | [`Design`], [`TableOptions`], [`Design::match_subjects`], [`design::parse_matrix`] |
//! | [`contrast`] | contrasts by name or vector, F-tests | [`Contrast`] |
//! | [`glm`] | least squares at every element, t and F, parametric p, missing values | [`Glm`], [`Observations`], [`Tail`] |
//! | [`permutation`] | Freedman–Lane permutations, seeded or exact, and their maxima | [`Scheme`], [`NullDistributions`] |
//! | [`mesh`] | element areas and adjacency, clusters, TFCE, heat-diffusion smoothing | [`Mesh`], [`Elements`], [`find_clusters`], [`cluster_outlines`], [`tfce()`], [`smooth`] |
//! | [`fdr`] | Benjamini–Hochberg q-values | [`q_values`] |
//! | [`analysis`] | an analysis from data to maps | [`Study`], [`Options`], [`ContrastResult`] |
//! | [`atoms`] | per-atom measures of fitted medial models (thickness, spokes, displacement along the medial normal) | [`AtomMeasure`], [`SheetNormals`], [`atom_values`] |
//! | [`shape`] | Procrustes alignment, generalised Procrustes analysis of medial atoms, principal components | [`procrustes`], [`generalised_procrustes`], [`pca()`] |
//! | [`mean`] | one round of a population template: the fitted models averaged after Procrustes, projected onto the medial constraints | [`mean_template`], [`MeanTemplate`] |
//! | [`modes`] | shape modes of a cohort of fitted models: its atoms or boundaries aligned, their principal components, shapes along a mode | [`shape_modes`], [`ShapeModes`], [`ShapeOf`] |
//! | [`error`] | the one error type | [`StatsError`] |

#![warn(missing_docs)]

pub mod analysis;
pub mod atoms;
pub mod contrast;
pub mod design;
pub mod error;
pub mod fdr;
pub mod glm;
pub mod mean;
pub mod mesh;
pub mod modes;
pub mod permutation;
pub mod shape;

pub use analysis::{ClusterInference, ContrastResult, Options, PermutationSummary, Study};
pub use atoms::{atom_values, Alignment, AtomMeasure, SheetNormals};
pub use contrast::Contrast;
pub use design::{Candidate, Design, Matched, TableOptions};
pub use error::{Result, StatsError};
pub use fdr::q_values;
pub use glm::{Glm, GlmOptions, Observations, Tail};
pub use mean::{mean_template, normal_and_tangential, MeanTemplate};
pub use mesh::{
    cluster_outlines, diffusion_time, find_clusters, smooth, tfce, Cluster, Clusters, Elements,
    Mesh, Support, TfceParameters,
};
pub use modes::{shape_modes, ShapeModes, ShapeOf};
pub use permutation::{NullDistributions, Scheme};
pub use shape::{generalised_procrustes, pca, procrustes, AtomShape, Gpa, Pca, Similarity};
