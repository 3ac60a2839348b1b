//! # medial-io
//!
//! The file formats of `medial`: legacy VTK polydata, cmrep medial templates, meshes (VTK, OBJ,
//! glTF), NumPy `.npy` arrays, NIfTI and OpenEXR volumes, and affine matrices as text.
//!
//! Conventions shared by every module: world coordinates are RAS+ millimetres; a volume's
//! voxels are stored with `x` fastest (`i + nx·(j + ny·k)`) and its voxel-to-world map takes a
//! voxel index to world millimetres; mesh vertices keep their file order. Everything is written
//! to a temporary file first and renamed into place ([`atomic`]), so that a failure never
//! leaves a half-written result. Every failure is an [`Error`] naming the file.
//!
//! ## Contents
//!
//! | module | what it holds | entry points |
//! |---|---|---|
//! | [`vtk`] | legacy VTK polydata: ASCII and binary, 3.0/4.x and 5.1 layouts, point and cell arrays; ParaView's `.vtk.series` | [`vtk::read_polydata`], [`vtk::write_polydata`], [`vtk::PolyData`], [`vtk::write_series`] |
//! | [`gltf_flow`] | surfaces animated over the frames of a flow, with vertex colours, as binary glTF | [`gltf_flow::write_flow_glb`], [`gltf_flow::FlowAnimation`] |
//! | [`cmrep`] | cmrep boundary medial templates ⇄ [`MedialTemplate`](medial_core::MedialTemplate) | [`cmrep::read_template`], [`cmrep::write_template`] |
//! | [`mesh`] | triangle meshes chosen by extension: `.vtk`, `.obj`, `.gltf`/`.glb`; point sets | [`mesh::read_mesh`], [`mesh::write_mesh`], [`mesh::read_points`] |
//! | [`volume`] | a volume in any supported format, by file name; the grid checks every volume reader applies | [`volume::read_volume`], [`volume::check_grid`] |
//! | [`nifti_volume`] | NIfTI-1 volumes (`.nii`, `.nii.gz`), with their voxel type | [`nifti_volume::read_nifti`], [`nifti_volume::read_nifti_file`], [`nifti_volume::write_nifti`] |
//! | [`exr_volume`] | volumes as OpenEXR images (a column of slices) | [`exr_volume::read_exr_volume`], [`exr_volume::write_exr_volume`] |
//! | [`warp`] | displacement fields as NIfTI warps (5-D, vector intent, LPS) for ITK, ANTs and greedy | [`warp::write_warp`], [`warp::read_warp`] |
//! | [`npy`] | NumPy `.npy` arrays as `f64` | [`npy::read_npy`], [`npy::write_npy`] |
//! | [`affine`] | 4×4 affine matrices as text | [`affine::read_affine`], [`affine::write_affine`] |
//! | [`model`] | the model a fit deforms (medial template or plain mesh) and its VTK at a configuration of its landmarks | [`model::read_model`], [`model::boundary_polydata`], [`model::medial_polydata`] |
//! | [`sheet`] | medial sheets with a radius per vertex, the input of inflation | [`sheet::read_sheet`] |
//! | [`atomic`] | writing through a temporary file and a rename | [`atomic::write_atomic`], [`atomic::write_atomic_via_path`] |
//! | [`error`] | the one error type, with typed variants for each kind of bad input | [`Error`], [`error::Geometry`], [`Result`] |

#![warn(missing_docs)]

pub mod affine;
pub mod atomic;
pub mod cmrep;
pub mod error;
pub mod exr_volume;
pub mod gltf_flow;
pub mod mesh;
pub mod model;
pub mod nifti_volume;
pub mod npy;
pub mod sheet;
pub mod volume;
pub mod vtk;
pub mod warp;

pub use error::{Error, Result};
