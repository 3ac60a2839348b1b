//! References and fixtures for tests and benchmarks: an independent dense implementation of
//! the flow and its gradient ([`dense`]), and small meshes and templates with known
//! properties ([`meshes`]). Not needed to fit anything.

pub mod dense;
pub mod meshes;
pub mod varifold_dense;
