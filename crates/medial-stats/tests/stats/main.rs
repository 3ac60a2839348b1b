//! The tests of medial-stats against independent computations: dense least squares, brute-force
//! enumeration of permutations, and meshglm's test data.

mod atoms;
mod calibration;
mod common;
mod glm;
mod meshglm;
mod modes;
mod permutation;
mod shape;
