//! The end-to-end tests of the `medial` binary, one module per command or subject (one test
//! binary, so the whole stack links once).

mod common;

mod acceptance;
mod apply;
mod apply_exact;
mod auto;
mod bad_input;
mod batch;
mod check;
mod fit;
mod guards;
mod inflate;
mod mean;
mod pca;
mod reliability;
mod resume;
mod stats;
mod stats_cohort;
mod stats_report;
mod template;
mod templates;
mod transform;
mod varifold;
mod views;
