//! Building templates: the medial sheet of a shape ([`skeleton`]), inflation of a medial sheet
//! into a closed boundary with spokes ([`inflate`](mod@inflate)), and projection of a template
//! onto its medial constraints ([`project`](mod@project)), and the whole pipeline from a
//! shape to a template ([`from_shape`]).

pub mod from_shape;
pub mod inflate;
pub mod project;
pub mod skeleton;

pub use inflate::{inflate, Inflated, MedialSheet};
pub use project::{project, ProjectOptions, Projection};
pub use skeleton::{sheet_of_mask, MedialAxis, Sampling, ShapeSheet};
