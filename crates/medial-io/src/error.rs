//! The one error type of the file layer.

use std::path::PathBuf;

/// What can go wrong reading or writing a file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The operating system refused (missing file, permissions, full disk).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not what its format requires; `message` says what and where (line, section).
    #[error("{}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
    /// The data of the file are shorter than its header declares.
    #[error(
        "{}: truncated: {what} needs {needed} bytes of data, the file has {available}",
        path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What the header declares (shape and type of the data, where they start).
        what: String,
        /// Bytes the header declares.
        needed: u64,
        /// Bytes the file has there.
        available: u64,
    },
    /// The file goes on after the end of the data its header declares.
    #[error(
        "{}: {} bytes after the end of the data (the header declares {data_end} bytes in all, \
         the file has {file_len})",
        path.display(),
        file_len - data_end
    )]
    TrailingBytes {
        /// The file.
        path: PathBuf,
        /// Where the declared data end (bytes from the start of the file).
        data_end: u64,
        /// The size of the file.
        file_len: u64,
    },
    /// The header places the data outside the file (beyond its end, or at a negative or
    /// non-finite offset).
    #[error(
        "{}: {field} = {offset} does not place the data in the file ({file_len} bytes)",
        path.display()
    )]
    DataOffset {
        /// The file.
        path: PathBuf,
        /// The header field that holds the offset (`vox_offset`).
        field: &'static str,
        /// The declared offset, in bytes.
        offset: f64,
        /// The size of the file.
        file_len: u64,
    },
    /// The voxel grid of a volume cannot place voxels in the world: see [`Geometry`].
    #[error("{}: {problem}", path.display())]
    Geometry {
        /// The file.
        path: PathBuf,
        /// What is wrong with the grid.
        problem: Geometry,
    },
    /// A glTF accessor that cannot be read as what its primitive uses it for.
    #[error(
        "{}: mesh {mesh}, primitive {primitive}: {role} accessor {accessor}: {problem}",
        path.display()
    )]
    Accessor {
        /// The file.
        path: PathBuf,
        /// Index of the mesh in the document.
        mesh: usize,
        /// Index of the primitive in the mesh.
        primitive: usize,
        /// What the primitive uses the accessor for (`POSITION`, `indices`).
        role: &'static str,
        /// Index of the accessor in the document.
        accessor: usize,
        /// What is wrong (component type, count, byte range).
        problem: String,
    },
    /// The file is well formed but its content is refused by the engine (open mesh, NaN, ...).
    #[error("{}: {}", path.display(), one_line(source.to_string()))]
    Model {
        /// The file.
        path: PathBuf,
        /// The engine's reason.
        source: medial_core::Error,
    },
}

/// Why a volume's grid cannot place voxels in the world (RAS mm): the problems a reader refuses
/// instead of returning a volume whose world coordinates would be garbage. Axes and dimensions
/// are numbered from 1, as in NIfTI's `dim[1..=7]` and `pixdim[1..=3]`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Geometry {
    /// Fewer than 3 dimensions (NIfTI `dim[0]`): a 1-D or 2-D image.
    #[error("the image is {ndim}-D: only 3-D volumes are supported")]
    TooFewDimensions {
        /// The number of dimensions.
        ndim: usize,
    },
    /// A dimension after the third with more than one sample (several volumes or time points).
    #[error(
        "dimension {axis} has size {size}: only 3-D volumes (or 4-D with one volume) are supported"
    )]
    ExtraDimension {
        /// The dimension, 4 to 7.
        axis: usize,
        /// Its size.
        size: usize,
    },
    /// A displacement field whose dimensions are not `[nx, ny, nz, 1, 3]` (NIfTI `dim[5]`
    /// holds the 3 components of a vector).
    #[error(
        "the image is {ndim}-D with {components} value(s) per voxel: a displacement field has \
         dimensions [nx, ny, nz, 1, 3]"
    )]
    NotVectors {
        /// The number of dimensions.
        ndim: usize,
        /// The values per voxel (`dim[5]`, 1 below 5 dimensions).
        components: usize,
    },
    /// A dimension of size 0 (or negative).
    #[error("dimension {axis} has size {size}: every dimension needs at least one voxel")]
    EmptyDimension {
        /// The dimension, from 1.
        axis: usize,
        /// Its size.
        size: i64,
    },
    /// A voxel spacing that the voxel-to-world map is built from (NIfTI `pixdim[1..=3]`, used
    /// when there is no sform) is not a positive finite number of mm.
    #[error("pixdim[{axis}] is {value}: a voxel spacing must be a positive number of mm")]
    Spacing {
        /// The axis, 1 to 3.
        axis: usize,
        /// The stored spacing.
        value: f32,
    },
    /// An entry of the voxel-to-world map (or of what it is built from) is not finite.
    #[error(
        "the voxel-to-world map has the non-finite entry {value} at row {row}, column {column}"
    )]
    NonFiniteMap {
        /// Row, from 1.
        row: usize,
        /// Column, from 1.
        column: usize,
        /// The entry.
        value: f64,
    },
    /// A voxel edge (a column of the voxel-to-world map) of a length outside
    /// [`MIN_VOXEL_SIZE_MM`](crate::volume::MIN_VOXEL_SIZE_MM) ..=
    /// [`MAX_VOXEL_SIZE_MM`](crate::volume::MAX_VOXEL_SIZE_MM).
    #[error(
        "voxel axis {axis} is {size_mm:.3e} mm long: voxel sizes from {min:e} to {max:e} mm are \
         accepted",
        min = crate::volume::MIN_VOXEL_SIZE_MM,
        max = crate::volume::MAX_VOXEL_SIZE_MM
    )]
    VoxelSize {
        /// The voxel axis, 1 to 3.
        axis: usize,
        /// Its length, mm.
        size_mm: f64,
    },
    /// The voxel axes are (nearly) coplanar: the map is singular.
    #[error(
        "the voxel-to-world map is singular: the voxel axes are coplanar (|det| / product of the \
         voxel sizes = {sine:.1e}, below {min:e})",
        min = crate::volume::MIN_AXIS_SINE
    )]
    Singular {
        /// `|det A| / (|a₁| |a₂| |a₃|)` of the 3×3 part `A`: 1 for orthogonal axes.
        sine: f64,
    },
}

/// Result alias of the file layer.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A format error for `path`; a message of several lines (as some libraries write them) is
    /// joined into one.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            message: one_line(message.into()),
        }
    }

    /// An I/O error for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// An engine error about the content of `path`.
    pub fn model(path: impl Into<PathBuf>, source: medial_core::Error) -> Self {
        Error::Model {
            path: path.into(),
            source,
        }
    }
}

/// `text` on one line: when it has several, their words joined by single spaces.
fn one_line(text: String) -> String {
    if text.contains(['\n', '\r']) {
        text.split_whitespace().collect::<Vec<_>>().join(" ")
    } else {
        text
    }
}
