//! Fitting: the objective of one stage and its exact gradient ([`objective`]), its minimisation
//! with L-BFGS ([`optimize`], on vectors whose algebra runs in parallel: [`lbfgs_vector`]) with every iterate checked for soundness ([`guard`]), the
//! augmented-Lagrangian schedule of a stage ([`augmented_lagrangian`]), and a whole fit of
//! several stages in a row ([`stages`]), which can pause after any accepted iterate and resume
//! from a serialisable [`Checkpoint`] to the same bits; and the initial alignment, a similarity
//! then an affine map ([`align`]), with the candidate starts of an automatic fit judged by a
//! short trial of the flow ([`trial`]); and where a fitted model and its target disagree, the
//! rule that tells a part of the target missed from a boundary placed off ([`agreement`]).

pub mod agreement;
pub mod align;
pub mod augmented_lagrangian;
pub mod guard;
pub mod initial;
pub mod lbfgs_vector;
pub mod objective;
pub mod optimize;
pub mod plan;
pub mod prepare;
pub mod run;
pub mod spec;
pub mod stages;
pub mod trial;

pub use agreement::{Disagreement, Miss};
pub use align::{
    affine_between, align_affine, align_similarity, anisotropy, explained_spread,
    similarity_between, Alignment, AlignmentFailure,
};
pub use augmented_lagrangian::{
    run_stage, AlSchedule, CoarseTime, Constraints, Extend, MuUpdate, Progress, Settle, Stage,
    StageCheckpoint, StageOutcome, StageRun, StageStart, UnsoundStop,
};
pub use guard::{Guard, Unsound};
pub use objective::{ConstraintSet, Evaluation, Objective, Penalty};
pub use optimize::{
    minimize, LbfgsOptions, Minimization, MinimizerCheckpoint, ProgressRule, Start, StopReason,
};
pub use prepare::{PreparedStage, Target};
pub use spec::{
    AttachmentSpec, DiceSpec, FitSpec, FlowSettings, MedialTolerance, StageSpec, VarifoldSpec,
};
pub use stages::{run_stages, run_stages_resumable, Checkpoint, FitEvent, FitRun, PlannedStage};
