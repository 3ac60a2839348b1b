//! Building templates: inflation of a medial sheet into a closed boundary with spokes
//! ([`inflate`](mod@inflate)), and projection of a template onto its medial constraints
//! ([`project`](mod@project)).

pub mod inflate;
pub mod project;

pub use inflate::{inflate, Inflated, MedialSheet};
pub use project::{project, ProjectOptions, Projection};
