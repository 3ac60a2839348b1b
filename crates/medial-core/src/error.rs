//! The one error type of the engine.

use crate::mesh::topology::MeshDefect;

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
    /// The optimiser failed (not merely stopped early).
    #[error("optimisation failed: {0}")]
    Optimisation(String),
}

/// Result alias of the engine.
pub type Result<T, E = Error> = std::result::Result<T, E>;
