//! The one error type of the engine.

use crate::mesh::topology::MeshDefect;
use crate::mesh::Bounds;

/// Everything that can go wrong inside the engine. Messages say what and where, so that the
/// command-line tool can print them as they are.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A triangle mesh is not a valid closed, consistently and outwardly oriented surface: an
    /// index out of range, an open, non-manifold or inconsistently oriented edge, a pinched
    /// vertex, an inward orientation (see [`MeshDefect`]).
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshDefect),
    /// A triangle mesh is unusable for a particular purpose, said in that purpose's words (a
    /// medial sheet with a degenerate triangle, a mesh to rasterize that is open).
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// A medial template is inconsistent (medial indices, spokes, radii, medial points).
    #[error("invalid medial template: {0}")]
    InvalidTemplate(String),
    /// A volume (image) is unusable: empty, degenerate affine, wrong voxel count.
    #[error("invalid volume: {0}")]
    InvalidVolume(String),
    /// Two inputs that must agree in size do not.
    #[error("{what}: expected {expected}, found {found}")]
    ShapeMismatch {
        /// What was being compared.
        what: String,
        /// The size that was required.
        expected: usize,
        /// The size that was given.
        found: usize,
    },
    /// A NaN or infinite number where a finite one is required.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// A parameter outside its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// A map of space cannot be inverted where it was asked to be (the inverse flow of a point
    /// did not converge).
    #[error("not invertible: {0}")]
    NotInvertible(String),
    /// A shape whose medial points form several sheets that no seam joins (templates are built
    /// of one sheet or of sheets meeting at seams).
    #[error(
        "the shape's medial axis falls apart: {sheets} sheets meeting at {seams} seam{}; a \
         template is built of one sheet or of sheets meeting at seams",
        if *seams == 1 { "" } else { "s" }
    )]
    Branching {
        /// Sheets found.
        sheets: usize,
        /// Seams found (lines where three or more sheets meet).
        seams: usize,
    },
    /// No initial map between corresponding point sets ([`crate::fit::align::AlignmentFailure`]).
    #[error("{0}")]
    Alignment(#[from] crate::fit::align::AlignmentFailure),
    /// A run would need more memory than its limit ([`crate::memory`]).
    #[error("{what} would need {estimate}, more than the memory limit of {}", crate::memory::human(*limit))]
    Memory {
        /// What would need it.
        what: String,
        /// The estimate, in words ([`crate::memory::Estimate`]'s display).
        estimate: String,
        /// The limit, bytes.
        limit: f64,
    },
    /// A stage's attachment does not take this kind of target ([`crate::fit::Target`]).
    #[error("the {attachment} attachment cannot fit {target}")]
    WrongTarget {
        /// The attachment's name.
        attachment: &'static str,
        /// The target's kind ([`crate::fit::Target::kind`]).
        target: &'static str,
    },
    /// What needs a medial template (constraints, Dice sampling) got a plain mesh.
    #[error("{0} needs a medial template (a VTK file with a MedialIndex array)")]
    NeedsMedial(&'static str),
    /// SSD targets that are not one per boundary point.
    #[error(
        "the target has {found} points but the template boundary has {expected}; an SSD \
         target needs the same points in the same order"
    )]
    PointCount {
        /// Boundary points of the template.
        expected: usize,
        /// Target points.
        found: usize,
    },
    /// An image's foreground and a template's interior do not overlap at all: no gradient
    /// could bring them together.
    #[error(
        "the image does not overlap the template: its foreground spans {} mm, the template's \
         boundary {} mm (world coordinates); check the image's origin and orientation against \
         the template's coordinates",
        foreground.span(),
        template.span()
    )]
    NoOverlap {
        /// The foreground's bounds, mm.
        foreground: Box<Bounds>,
        /// The template boundary's bounds, mm.
        template: Box<Bounds>,
    },
    /// Target points that do not correspond to the template boundary's, one for one: the
    /// least-squares similarity explains too little of their spread
    /// ([`crate::fit::initial::MIN_EXPLAINED_SPREAD`]).
    #[error(
        "the points do not seem to correspond to the template boundary's, point for point: the \
         best similarity between them accounts for {:.0} % of the points' spread (at least {:.0} \
         % expected)",
        100.0 * explained,
        100.0 * minimum
    )]
    NoCorrespondence {
        /// The fraction explained.
        explained: f64,
        /// The least fraction accepted.
        minimum: f64,
    },
    /// A setting that cannot be used, with the engine's reason.
    #[error("{setting}: {source}")]
    Setting {
        /// The setting's name.
        setting: &'static str,
        /// Why.
        source: Box<Error>,
    },
    /// The optimiser failed (not merely stopped early).
    #[error("optimisation failed: {0}")]
    Optimisation(String),
}

/// Result alias of the engine.
pub type Result<T, E = Error> = std::result::Result<T, E>;
