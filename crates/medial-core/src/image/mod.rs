//! Images: scalar volumes placed in world space by an affine map, sampled trilinearly
//! ([`volume`]), exact binary rasterization of closed meshes ([`rasterize`]), and the exact
//! Euclidean distance and feature transform of a mask ([`distance`]).

pub mod distance;
pub mod rasterize;
pub mod slice;
pub mod volume;

pub use volume::Volume;
