//! Building templates: the medial sheet of a shape ([`skeleton`]), inflation of a medial sheet
//! into a closed boundary with spokes ([`inflate`](mod@inflate)), and projection of a template
//! onto its medial constraints ([`project`](mod@project)).

pub mod inflate;
pub mod project;
pub mod skeleton;

pub use inflate::{inflate, Inflated, MedialSheet};
pub use project::{project, ProjectOptions, Projection};
pub use skeleton::{sheet_of_mask, Sampling, ShapeSheet};
