//! Helpers shared by the modules of the engine's integration tests.

pub mod clean;
pub mod glb;
pub mod heart;
