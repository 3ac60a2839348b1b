//! NIfTI-1 volumes (`.nii`, `.nii.gz`) ↔ [`Volume`].
//!
//! **Reading** (any integer or floating-point datatype; `scl_slope`/`scl_inter` applied when
//! the slope is not 0). The voxel-to-world map follows the NIfTI-1 standard (`nifti1.h`, and
//! `nifti1_io.c`, its reference reader), in RAS+ millimetres:
//! - `sform_code > 0`: the rows `srow_x`, `srow_y`, `srow_z` (method 3);
//! - else `qform_code > 0`: `R · diag(dx, dy, qfac·dz)` and offset `(qoffset_x, y, z)`, with `R`
//!   the rotation of the unit quaternion `(a, b, c, d)`, `a = √(1 − b² − c² − d²)` (if
//!   `1 − b² − c² − d² < 10⁻⁷`, `a = 0` and `(b, c, d)` is normalised), `qfac = −1` if
//!   `pixdim[0] < 0` else `+1` (method 2);
//! - else `diag(dx, dy, dz)` with no offset (method 1).
//!
//! Refused, as they can only give garbage: a voxel spacing `pixdim[1..=3]` that is not a
//! positive finite number where the map is built from it (methods 1 and 2; `nifti1_io.c` takes
//! it as 1), a grid that [`check_grid`] refuses (voxel sizes outside 10⁻⁴ … 10⁴ mm, coplanar
//! axes, non-finite entries), images that are not 3-D (`dim[0] < 3`, or a fourth to seventh
//! dimension above 1: a 4-D file with one volume is fine), a dimension below 1, a `vox_offset`
//! that does not place the data in the file, and data shorter than the header declares. A
//! 1×1×1 volume is read. The data start at `vox_offset` (at least 352, after the header and
//! its 4-byte extender); the file may be gzip-compressed whatever its name.
//!
//! **Writing** ([`write_nifti`]): the sform holds the affine map with `sform_code = 1`
//! (`NIFTI_XFORM_SCANNER_ANAT`); when the voxel axes are orthogonal the qform holds the same
//! map (quaternion, `qfac` for a left-handed grid) with `qform_code = 1`, else `qform_code = 0`.
//! `pixdim[1..=3]` are the column norms of the affine map, units are mm. Header fields are
//! 32-bit floats, so the map is stored to about 7 significant digits. The file is written to a
//! temporary file beside the destination and renamed into place; a `.gz` name is compressed.

use std::io::Read as _;
use std::ops::Range;
use std::path::Path;

use medial_core::image::volume::Volume;
use medial_core::Vec3;
use nalgebra::{Matrix3, Matrix3x4, Matrix4, Quaternion, UnitQuaternion};
use nifti::writer::WriterOptions;
use nifti::{Endianness, IntoNdArray, NiftiHeader, XForm};

use crate::affine::from_top_rows;
use crate::atomic::write_atomic_via_path;
use crate::error::Geometry;
use crate::volume::check_grid;
use crate::{Error, Result};

/// `NIFTI_UNITS_MM` in `xyzt_units`.
const UNITS_MM: u8 = 2;

/// Bytes of a NIfTI-1 header (`sizeof_hdr`).
const HEADER_BYTES: usize = 348;

/// The earliest start of the voxel data of a single-file NIfTI-1: after the header and its
/// 4-byte extender.
const MIN_DATA_OFFSET: usize = 352;

/// The first two bytes of a gzip stream.
const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// Tolerance on `|DᵀD − I|` (D the normalised direction matrix) for writing a qform.
const ORTHOGONAL_TOLERANCE: f64 = 1e-6;

/// The voxel types [`write_nifti`] can store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NiftiType {
    /// `DT_UINT8`: integers 0 … 255 (masks and label maps).
    U8,
    /// `DT_INT16`: integers −32768 … 32767.
    I16,
    /// `DT_INT32`: integers −2³¹ … 2³¹ − 1 (label maps with many labels).
    I32,
    /// `DT_FLOAT32`: values rounded to single precision.
    F32,
    /// `DT_FLOAT64`: values stored exactly.
    F64,
}

/// Reads a `.nii` or `.nii.gz` volume (see the module doc for the world coordinates and what
/// is refused).
///
/// Errors: [`Error::Io`] if the file cannot be read; [`Error::Format`] for a file that is not
/// NIfTI-1 (or not valid gzip), a header-only file (magic `ni1`), an unsupported datatype
/// (complex, RGB, …) or a `dim[0]` above 7; [`Error::Truncated`] for a file shorter than its
/// header or data; [`Error::DataOffset`] for a `vox_offset` outside the file;
/// [`Error::Geometry`] for a grid that cannot place voxels in the world; [`Error::Model`] for
/// values the engine refuses (NaN voxels).
pub fn read_nifti(path: &Path) -> Result<Volume> {
    Ok(read_nifti_file(path)?.volume)
}

/// A volume read from a NIfTI-1 file, with what its voxel type says about its values.
#[derive(Clone, Debug)]
pub struct NiftiFile {
    /// The volume.
    pub volume: Volume,
    /// Whether the values are labels: an integer datatype, scaled (if at all) by an integer
    /// `scl_slope` and `scl_inter`.
    pub labels: bool,
    /// The type [`write_nifti`] stores such values in without loss: the file's own for `uint8`,
    /// `int16`, `float32` and `float64`, `int16` for `int8`, `int32` for `uint16` and `int32`,
    /// `float64` for the wider integers and scaled values.
    pub datatype: NiftiType,
}

/// Reads a `.nii` or `.nii.gz` volume as [`read_nifti`], with its voxel type.
///
/// Errors: as [`read_nifti`].
pub fn read_nifti_file(path: &Path) -> Result<NiftiFile> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let decoded = decode(bytes, path, Voxel::Scalar)?;
    let (labels, datatype) = stored_type(&decoded.header, decoded.datatype);
    let volume = Volume::new(decoded.dims, decoded.data, decoded.voxel_to_world)
        .map_err(|e| Error::model(path, e))?;
    Ok(NiftiFile {
        volume,
        labels,
        datatype,
    })
}

/// Whether values of `datatype` scaled by the header are labels, and the type that stores them
/// (see [`NiftiFile`]).
fn stored_type(header: &NiftiHeader, datatype: nifti::NiftiType) -> (bool, NiftiType) {
    use nifti::NiftiType as T;
    let scaled = header.scl_slope != 0.0 && (header.scl_slope != 1.0 || header.scl_inter != 0.0);
    let integral_scale = header.scl_slope.fract() == 0.0 && header.scl_inter.fract() == 0.0;
    let integer = !matches!(datatype, T::Float32 | T::Float64);
    let stored = match datatype {
        _ if scaled => NiftiType::F64,
        T::Uint8 => NiftiType::U8,
        T::Int8 | T::Int16 => NiftiType::I16,
        T::Uint16 | T::Int32 => NiftiType::I32,
        T::Float32 => NiftiType::F32,
        _ => NiftiType::F64,
    };
    (integer && (!scaled || integral_scale), stored)
}

/// Parses the bytes of a `.nii` or `.nii.gz` file (gzip by its magic number, not the name) as
/// [`read_nifti`] does (`path` is only used in error messages).
///
/// Errors: as [`read_nifti`], but for [`Error::Io`].
pub fn parse_nifti(bytes: Vec<u8>, path: &Path) -> Result<Volume> {
    let decoded = decode(bytes, path, Voxel::Scalar)?;
    Volume::new(decoded.dims, decoded.data, decoded.voxel_to_world)
        .map_err(|e| Error::model(path, e))
}

/// What a voxel of a file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Voxel {
    /// One value: a 3-D image (or 4-D with one volume).
    Scalar,
    /// A 3-vector: a 5-D image of dimensions `[nx, ny, nz, 1, 3]` (components along `dim[5]`).
    Vector,
}

impl Voxel {
    /// Values per voxel.
    fn values(self) -> usize {
        match self {
            Voxel::Scalar => 1,
            Voxel::Vector => 3,
        }
    }
}

/// The content of a NIfTI-1 file, checked: its header and datatype, grid, voxel-to-world map
/// (RAS mm) and values as `f64`, `x` fastest then (for vectors) the component.
pub(crate) struct Decoded {
    pub(crate) header: NiftiHeader,
    pub(crate) datatype: nifti::NiftiType,
    pub(crate) dims: [usize; 3],
    pub(crate) voxel_to_world: Matrix4<f64>,
    pub(crate) data: Vec<f64>,
}

/// Decodes the bytes of a `.nii` or `.nii.gz` file whose voxels hold `voxel` (module doc). A
/// gzip stream is inflated only as far as the header declares (header, then `vox_offset` and
/// the voxel data), so that a small file cannot fill the memory; the rest of the stream is
/// checked without being kept.
pub(crate) fn decode(bytes: Vec<u8>, path: &Path, voxel: Voxel) -> Result<Decoded> {
    if !bytes.starts_with(&GZIP_MAGIC) {
        return decode_from(bytes, path, voxel, |_, _| Ok(()));
    }
    let mut decoder = flate2::read::GzDecoder::new(bytes.as_slice());
    let mut head = Vec::new();
    inflate(&mut decoder, &mut head, HEADER_BYTES, path)?;
    decode_from(head, path, voxel, |file, end| {
        inflate(&mut decoder, file, end, path)?;
        // The end of the stream (and its checksum) is checked, what follows the data dropped.
        std::io::copy(&mut decoder, &mut std::io::sink())
            .map(drop)
            .map_err(|e| gzip_error(path, e))
    })
}

/// The content of a NIfTI-1 file whose first bytes are `bytes`; `more(bytes, end)` appends
/// the file's next bytes up to `end` in all (fewer where the file ends), once the header told
/// where its voxel data end.
fn decode_from(
    mut bytes: Vec<u8>,
    path: &Path,
    voxel: Voxel,
    mut more: impl FnMut(&mut Vec<u8>, usize) -> Result<()>,
) -> Result<Decoded> {
    let header = parse_header(&bytes, path)?;
    let datatype = check_datatype(&header).map_err(|m| Error::format(path, m))?;
    let dims = spatial_dims(&header, path, voxel)?;
    let voxel_to_world = voxel_to_world(&header).map_err(|problem| Error::Geometry {
        path: path.into(),
        problem,
    })?;
    check_grid(path, dims, &voxel_to_world)?;
    let values = dims.iter().product::<usize>() * voxel.values();
    more(&mut bytes, data_end(&header, values, datatype))?;
    let data = voxel_data_range(&header, bytes.len(), dims, values, datatype, path)?;
    bytes.truncate(data.end);
    bytes.drain(..data.start);
    let volume = nifti::InMemNiftiVolume::from_raw_fields(
        header.dim,
        datatype,
        header.scl_slope,
        header.scl_inter,
        bytes,
        header.endianness,
    )
    .map_err(|e| nifti_error(path, e))?;
    let array = volume
        .into_ndarray::<f64>()
        .map_err(|e| nifti_error(path, e))?;
    // NIfTI data are in Fortran order (x fastest), as are the arrays the crate builds: the
    // array's own buffer is the voxel data, taken without a copy.
    let contiguous = array.as_slice_memory_order().map(<[f64]>::len);
    let (data, offset) = array.into_raw_vec_and_offset();
    if contiguous != Some(data.len()) || offset.unwrap_or(0) != 0 {
        return Err(Error::format(path, "voxel data are not contiguous"));
    }
    Ok(Decoded {
        header,
        datatype,
        dims,
        voxel_to_world,
        data,
    })
}

/// Appends the bytes of `decoder` to `out` until it holds `end` bytes or the stream ends.
fn inflate(
    decoder: &mut impl std::io::Read,
    out: &mut Vec<u8>,
    end: usize,
    path: &Path,
) -> Result<()> {
    let wanted = end.saturating_sub(out.len()) as u64;
    decoder
        .take(wanted)
        .read_to_end(out)
        .map(drop)
        .map_err(|e| gzip_error(path, e))
}

fn gzip_error(path: &Path, error: std::io::Error) -> Error {
    Error::format(path, format!("invalid gzip data: {error}"))
}

/// The header of a single-file NIfTI-1 image.
fn parse_header(bytes: &[u8], path: &Path) -> Result<NiftiHeader> {
    if bytes.len() < HEADER_BYTES {
        return Err(Error::Truncated {
            path: path.into(),
            what: "a NIfTI-1 header".into(),
            needed: HEADER_BYTES as u64,
            available: bytes.len() as u64,
        });
    }
    let header = NiftiHeader::from_reader(bytes).map_err(|e| nifti_error(path, e))?;
    if header.magic != *b"n+1\0" {
        return Err(Error::format(
            path,
            "the header keeps its voxels in a separate .img file (magic 'ni1'); only \
             single-file NIfTI-1 (.nii) is read",
        ));
    }
    Ok(header)
}

/// Where the voxel data end, bytes from the start of the (decompressed) file, if `vox_offset`
/// places them in it: `max(vox_offset, 352) + values·size`, saturating.
fn data_end(header: &NiftiHeader, values: usize, datatype: nifti::NiftiType) -> usize {
    data_start(header).saturating_add(values * datatype.size_of())
}

/// `max(vox_offset, 352)` (saturating; a negative or NaN offset gives 352).
fn data_start(header: &NiftiHeader) -> usize {
    (header.vox_offset as usize).max(MIN_DATA_OFFSET)
}

/// Where the voxel data lie in the (decompressed) file of `len` bytes: from `vox_offset` (at
/// least [`MIN_DATA_OFFSET`]) for `values` values of `datatype` (`nx·ny·nz` per component; at
/// most 3·32767³ · 16 bytes: no overflow).
fn voxel_data_range(
    header: &NiftiHeader,
    len: usize,
    dims: [usize; 3],
    values: usize,
    datatype: nifti::NiftiType,
    path: &Path,
) -> Result<Range<usize>> {
    let vox_offset = header.vox_offset;
    if !(vox_offset >= 0.0 && f64::from(vox_offset) <= len as f64) {
        return Err(Error::DataOffset {
            path: path.into(),
            field: "vox_offset",
            offset: f64::from(vox_offset),
            file_len: len as u64,
        });
    }
    let start = data_start(header);
    let needed = values * datatype.size_of();
    let available = len.saturating_sub(start);
    if available < needed {
        let [nx, ny, nz] = dims;
        return Err(Error::Truncated {
            path: path.into(),
            what: format!(
                "a {nx}×{ny}×{nz}{} volume of {datatype:?} from byte {start}",
                if values > nx * ny * nz { "×3" } else { "" }
            ),
            needed: needed as u64,
            available: available as u64,
        });
    }
    Ok(start..start + needed)
}

/// Writes `volume` as `.nii` or `.nii.gz` (by the file name) with voxel type `datatype` (see
/// the module doc for the header).
///
/// Errors: [`Error::Format`] for another extension, a dimension above 32767, or a value that
/// the datatype cannot hold (non-integer or out of range for the integer types, beyond the `f32` range
/// for `F32`); [`Error::Io`] if the file cannot be written.
pub fn write_nifti(path: &Path, volume: &Volume, datatype: NiftiType) -> Result<()> {
    let header = header_for(volume, datatype);
    write_raw(path, header, volume.dims(), volume.data(), datatype)
}

/// Writes `values` (`x` fastest, then along `dim[4…]` as `header.dim` says) with the fields of
/// `header` as `.nii` or `.nii.gz` (by the file name): `header.dim[1..=3]` are set from `dims`.
///
/// Errors: as [`write_nifti`].
pub(crate) fn write_raw(
    path: &Path,
    mut header: NiftiHeader,
    dims: [usize; 3],
    values: &[f64],
    datatype: NiftiType,
) -> Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let suffix = [".nii.gz", ".nii"]
        .into_iter()
        .find(|s| name.ends_with(s) && name.len() > s.len())
        .ok_or_else(|| Error::format(path, "a NIfTI file name must end in .nii or .nii.gz"))?;
    let spatial = raw_dims(dims).map_err(|m| Error::format(path, m))?;
    header.dim[1..4].copy_from_slice(&spatial[1..4]);
    header.dim[0] = header.dim[0].max(3);
    let bytes = encode(values, datatype).map_err(|m| Error::format(path, m))?;
    let raw = nifti::InMemNiftiVolume::from_raw_fields(
        header.dim,
        crate_type(datatype),
        0.0,
        0.0,
        bytes,
        Endianness::native(),
    )
    .map_err(|e| nifti_error(path, e))?;
    write_atomic_via_path(path, suffix, |temp| {
        let options = WriterOptions::new(temp).reference_header(&header);
        // The crate writes `ndarray`s; its own volume type converts the raw bytes to one.
        let written = match datatype {
            NiftiType::U8 => raw
                .into_ndarray::<u8>()
                .and_then(|a| options.write_nifti(&a)),
            NiftiType::I16 => raw
                .into_ndarray::<i16>()
                .and_then(|a| options.write_nifti(&a)),
            NiftiType::I32 => raw
                .into_ndarray::<i32>()
                .and_then(|a| options.write_nifti(&a)),
            NiftiType::F32 => raw
                .into_ndarray::<f32>()
                .and_then(|a| options.write_nifti(&a)),
            NiftiType::F64 => raw
                .into_ndarray::<f64>()
                .and_then(|a| options.write_nifti(&a)),
        };
        written.map_err(|e| nifti_error(path, e))
    })
}

/// The voxel-to-world map of a header: sform, else qform, else the spacings (module doc).
///
/// Errors: [`Geometry::Spacing`] for a spacing `pixdim[1..=3]` that the map is built from
/// (qform or spacings) and that is not a positive finite number.
fn voxel_to_world(header: &NiftiHeader) -> std::result::Result<Matrix4<f64>, Geometry> {
    if header.sform_code > 0 {
        let rows = [header.srow_x, header.srow_y, header.srow_z];
        return Ok(from_top_rows(&Matrix3x4::from_fn(|r, c| {
            f64::from(rows[r][c])
        })));
    }
    let spacing = |axis: usize| match header.pixdim[axis] {
        d if d.is_finite() && d > 0.0 => Ok(f64::from(d)),
        value => Err(Geometry::Spacing { axis, value }),
    };
    let scale = Vec3::new(spacing(1)?, spacing(2)?, spacing(3)?);
    let (linear, offset) = if header.qform_code > 0 {
        let qfac = if header.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let rotation = quaternion_rotation(header.quatern_b, header.quatern_c, header.quatern_d);
        let offset = nalgebra::Vector3::new(header.quatern_x, header.quatern_y, header.quatern_z)
            .map(f64::from);
        let scale = Vec3::new(scale.x, scale.y, qfac * scale.z);
        (rotation * Matrix3::from_diagonal(&scale), offset)
    } else {
        (Matrix3::from_diagonal(&scale), Vec3::zeros())
    };
    let mut top = linear.insert_column(3, 0.0);
    top.set_column(3, &offset);
    Ok(from_top_rows(&top))
}

/// The rotation of the NIfTI quaternion `(a, b, c, d)`, `a = √(1 − b² − c² − d²)` implied; when
/// `1 − b² − c² − d² < 10⁻⁷`, `a = 0` and `(b, c, d)` is normalised (a 180° rotation), as in
/// `nifti_quatern_to_mat44`.
fn quaternion_rotation(b: f32, c: f32, d: f32) -> Matrix3<f64> {
    let bcd = nalgebra::Vector3::new(b, c, d).map(f64::from);
    let rest = 1.0 - bcd.norm_squared();
    let a = if rest < 1e-7 { 0.0 } else { rest.sqrt() };
    let q = Quaternion::from_parts(a, bcd);
    UnitQuaternion::from_quaternion(q)
        .to_rotation_matrix()
        .into_inner()
}

/// `[nx, ny, nz]` from `dim`: at least 3 dimensions, none below 1, the fourth to seventh of
/// size 1 — but for `Voxel::Vector` the fifth, which must hold the 3 components. Sizes are the
/// header's signed 16-bit integers.
///
/// Errors: [`Error::Format`] for a `dim[0]` above 7, else [`Error::Geometry`].
fn spatial_dims(header: &NiftiHeader, path: &Path, voxel: Voxel) -> Result<[usize; 3]> {
    let ndim = usize::from(header.dim[0]);
    if ndim > 7 {
        return Err(Error::format(
            path,
            format!("dim[0] is {ndim}: a NIfTI-1 image has 1 to 7 dimensions"),
        ));
    }
    let size = |axis: usize| i64::from(header.dim[axis] as i16);
    let components = |axis| voxel == Voxel::Vector && axis == 5;
    let problem = if ndim < 3 {
        Some(Geometry::TooFewDimensions { ndim })
    } else if let Some(axis) = (1..=ndim).find(|&a| size(a) < 1) {
        Some(Geometry::EmptyDimension {
            axis,
            size: size(axis),
        })
    } else if voxel == Voxel::Vector && (ndim < 5 || size(5) != 3) {
        Some(Geometry::NotVectors {
            ndim,
            components: if ndim < 5 { 1 } else { size(5) as usize },
        })
    } else {
        (4..=ndim)
            .find(|&a| size(a) > 1 && !components(a))
            .map(|axis| Geometry::ExtraDimension {
                axis,
                size: size(axis) as usize,
            })
    };
    match problem {
        Some(problem) => Err(Error::Geometry {
            path: path.into(),
            problem,
        }),
        None => Ok([1, 2, 3].map(|a| size(a) as usize)),
    }
}

/// The datatype, refusing those that are not real scalars.
fn check_datatype(header: &NiftiHeader) -> std::result::Result<nifti::NiftiType, String> {
    use nifti::NiftiType as T;
    match header.data_type() {
        Ok(
            t @ (T::Uint8
            | T::Int8
            | T::Uint16
            | T::Int16
            | T::Uint32
            | T::Int32
            | T::Uint64
            | T::Int64
            | T::Float32
            | T::Float64),
        ) => Ok(t),
        Ok(other) => Err(format!(
            "unsupported voxel type {other:?}: need integers or reals"
        )),
        Err(_) => Err(format!("unknown datatype code {}", header.datatype)),
    }
}

/// `dim[0..8]` of a 3-D volume, refusing sizes a NIfTI-1 header (16-bit signed) cannot hold.
fn raw_dims(dims: [usize; 3]) -> std::result::Result<[u16; 8], String> {
    let mut dim = [3, 1, 1, 1, 1, 1, 1, 1];
    for (a, &n) in dims.iter().enumerate() {
        dim[a + 1] = u16::try_from(n)
            .ok()
            .filter(|&n| n <= i16::MAX as u16)
            .ok_or_else(|| {
                format!(
                    "dimension {} of size {n} exceeds the NIfTI-1 limit 32767",
                    a + 1
                )
            })?;
    }
    Ok(dim)
}

fn crate_type(datatype: NiftiType) -> nifti::NiftiType {
    match datatype {
        NiftiType::U8 => nifti::NiftiType::Uint8,
        NiftiType::I16 => nifti::NiftiType::Int16,
        NiftiType::I32 => nifti::NiftiType::Int32,
        NiftiType::F32 => nifti::NiftiType::Float32,
        NiftiType::F64 => nifti::NiftiType::Float64,
    }
}

/// The values as native-endian bytes of `datatype`, refusing values it cannot hold.
fn encode(values: &[f64], datatype: NiftiType) -> std::result::Result<Vec<u8>, String> {
    let check = |range: (f64, f64), integer: bool| match values
        .iter()
        .position(|&v| !(v >= range.0 && v <= range.1) || (integer && v.fract() != 0.0))
    {
        Some(n) => Err(format!(
            "voxel {n} has value {}, which {datatype:?} cannot hold (use a wider or floating type)",
            values[n]
        )),
        None => Ok(()),
    };
    Ok(match datatype {
        NiftiType::U8 => {
            check((0.0, 255.0), true)?;
            values.iter().map(|&v| v as u8).collect()
        }
        NiftiType::I16 => {
            check((-32768.0, 32767.0), true)?;
            values
                .iter()
                .flat_map(|&v| (v as i16).to_ne_bytes())
                .collect()
        }
        NiftiType::I32 => {
            check((f64::from(i32::MIN), f64::from(i32::MAX)), true)?;
            values
                .iter()
                .flat_map(|&v| (v as i32).to_ne_bytes())
                .collect()
        }
        NiftiType::F32 => {
            check((-f64::from(f32::MAX), f64::from(f32::MAX)), false)?;
            values
                .iter()
                .flat_map(|&v| (v as f32).to_ne_bytes())
                .collect()
        }
        NiftiType::F64 => values.iter().flat_map(|&v| v.to_ne_bytes()).collect(),
    })
}

/// The header fields this writer sets (the crate fills `dim`, `datatype`, `bitpix`,
/// `vox_offset`, `scl_*` and the magic from the data).
pub(crate) fn header_for(volume: &Volume, datatype: NiftiType) -> NiftiHeader {
    let m = volume.voxel_to_world();
    let a: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let spacing = volume.spacing();
    let mut header = NiftiHeader {
        datatype: crate_type(datatype) as i16,
        xyzt_units: UNITS_MM,
        sform_code: XForm::ScannerAnat as i16,
        qform_code: XForm::Unknown as i16,
        ..NiftiHeader::default()
    };
    header.pixdim[..4].copy_from_slice(&[
        1.0,
        spacing.x as f32,
        spacing.y as f32,
        spacing.z as f32,
    ]);
    let row = |r: usize| std::array::from_fn(|c| m[(r, c)] as f32);
    (header.srow_x, header.srow_y, header.srow_z) = (row(0), row(1), row(2));
    let direction = a * Matrix3::from_diagonal(&spacing.map(|s| 1.0 / s));
    if (direction.transpose() * direction - Matrix3::identity()).amax() < ORTHOGONAL_TOLERANCE {
        let (qfac, q) = nifti_quaternion(&direction);
        header.qform_code = XForm::ScannerAnat as i16;
        header.pixdim[0] = qfac as f32;
        (header.quatern_b, header.quatern_c, header.quatern_d) =
            (q.i as f32, q.j as f32, q.k as f32);
        (header.quatern_x, header.quatern_y, header.quatern_z) =
            (m[(0, 3)] as f32, m[(1, 3)] as f32, m[(2, 3)] as f32);
    }
    header
}

/// `qfac` and the unit quaternion (with `a ≥ 0`) of an orthogonal direction matrix: a
/// left-handed matrix gets `qfac = −1` and its third column negated (`nifti_mat44_to_quatern`).
fn nifti_quaternion(direction: &Matrix3<f64>) -> (f64, Quaternion<f64>) {
    let mut r = *direction;
    let qfac = if r.determinant() > 0.0 { 1.0 } else { -1.0 };
    if qfac < 0.0 {
        r.set_column(2, &(-r.column(2)));
    }
    let rotation = nalgebra::Rotation3::from_matrix_unchecked(r);
    let q = UnitQuaternion::from_rotation_matrix(&rotation).into_inner();
    (qfac, if q.w < 0.0 { -q } else { q })
}

/// An error of the `nifti` crate for `path`: I/O errors stay I/O errors.
fn nifti_error(path: &Path, error: nifti::NiftiError) -> Error {
    match error {
        nifti::NiftiError::Io(e) => Error::io(path, e),
        other => Error::format(path, format!("NIfTI: {other}")),
    }
}
