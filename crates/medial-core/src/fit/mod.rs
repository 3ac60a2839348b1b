//! Fitting: the objective of one stage and its exact gradient ([`objective`]), its minimisation
//! with L-BFGS ([`optimize`]), and the augmented-Lagrangian schedule of a stage
//! ([`augmented_lagrangian`]).

pub mod augmented_lagrangian;
pub mod objective;
pub mod optimize;

pub use augmented_lagrangian::{run_stage, AlSchedule, MuUpdate, Stage, StageOutcome};
pub use objective::{ConstraintSet, Evaluation, Objective, Penalty};
pub use optimize::{minimize, LbfgsOptions, StopReason};
