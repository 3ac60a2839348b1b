//! Images: scalar volumes placed in world space by an affine map, sampled trilinearly
//! ([`volume`]), and exact binary rasterization of closed meshes ([`rasterize`]).

pub mod rasterize;
pub mod volume;

pub use volume::Volume;
