//! # medial
//!
//! Diffeomorphic medial modeling (Yushkevich et al., *Diffeomorphic Medial Modeling*, IPMI
//! 2019): a medial template of a sheet-like structure (heart wall, placenta, valve leaflet,
//! cartilage) is fitted to a subject by a smooth invertible flow of space, while
//! augmented-Lagrangian constraints keep its medial axis medial at every time point.
//!
//! This crate is the one dependency a library user adds. It re-exports the engine
//! ([`medial_core`]: everything at the top level) and the file formats ([`io`]).
//!
//! | to … | use |
//! |---|---|
//! | read a cmrep template, a mesh, a segmentation | [`io::cmrep::read_template`], [`io::mesh::read_mesh`], [`io::nifti_volume::read_nifti`] |
//! | build a template from a medial sheet | [`construction::inflate()`], [`construction::project()`] |
//! | fit as `medial fit` does without a config | [`fit::run::automatic`] (the plan and the initial alignment), then [`fit::run::Fit::run`] |
//! | describe a fit yourself | [`fit::FitSpec`] of [`fit::StageSpec`]s, prepared against [`fit::Target`]s by [`fit::run::Fit::prepare`] |
//! | set up the flow | [`flow::Flow`] with [`flow::FlowParams`] |
//! | choose a data term | [`attachment::ssd::Ssd`] (corresponding points), [`attachment::dice::DiceAttachment`] (an image) |
//! | keep the model medial | [`model::MedialConstraints`] |
//! | run stages of your own | [`fit::run_stages`] of [`fit::PlannedStage`]s |
//! | look at the result | [`flow::Flow::shoot`], [`model::SpokeMetrics`], [`io::model::boundary_polydata`] |
//!
//! `examples/fit_segmentation.rs` fits the shipped toy template to its segmentation as `medial
//! fit` does, in a few lines: `cargo run --release --example fit_segmentation`.

#![warn(missing_docs)]

pub use medial_core::*;
pub use medial_io as io;
