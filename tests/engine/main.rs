//! The integration tests of the engine and its file formats, one module per subject (one
//! test binary, so the whole stack links once).

mod common;

mod affine;
mod al_gradient;
mod cmrep;
mod dice;
mod fidelity;
mod flow_gradient;
mod fuzz_regressions;
mod gltf_flow;
mod inflate;
mod medial_model;
mod mesh;
mod mutation;
mod npy;
mod project_synth;
mod retime;
mod step_strain;
mod template;
mod truncated_kernel;
mod varifold;
mod volumes;
mod vtk;
