//! The medial model (docs/method.md §2, §4, §8): a cmrep template of boundary points with spokes to
//! medial atoms ([`template`]), the Loop tangents of its boundary ([`loop_tangent`]), the medial
//! constraints that keep it medial under a flow ([`constraints`]), how well a configuration
//! of its landmarks satisfies them ([`metrics`]), whether its medial points stay the centres of
//! inscribed balls ([`fidelity`]), and the [`Model`] a fit deforms: a medial template or a plain
//! mesh ([`deformable`]); its summary ([`summary`]).

pub mod constraints;
pub mod deformable;
pub mod fidelity;
pub mod loop_tangent;
pub mod metrics;
pub mod summary;
pub mod template;

pub use constraints::{ConstraintUnits, MedialConstraints};
pub use deformable::Model;
pub use fidelity::{BallFidelity, Fidelity};
pub use loop_tangent::LoopTangents;
pub use metrics::SpokeMetrics;
pub use summary::TemplateSummary;
pub use template::MedialTemplate;
