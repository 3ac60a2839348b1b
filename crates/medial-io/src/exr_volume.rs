//! OpenEXR volumes ↔ [`Volume`].
//!
//! **Convention.** A volume of `nx × ny × nz` voxels is one EXR layer named `volume` with one
//! channel `Y` of 32-bit floats, `nx` pixels wide and `ny · nz` rows high: voxel `(i, j, k)` is
//! pixel `(i, j + ny · k)`, i.e. the `z` slices are stacked from the top row down (any EXR
//! viewer shows the volume as a column of slices). Two custom layer attributes place it in space:
//! - `medialVolumeDims` (`v3i`): `(nx, ny, nz)`;
//! - `medialVoxelToWorld` (`string`): the first three rows of the 4×4 voxel-to-world map
//!   (voxel index → RAS mm), row-major, as 12 decimal numbers separated by spaces, each in the
//!   shortest form that reads back to the same `f64` (the map round-trips exactly).
//!
//! Values are stored as 32-bit floats (masks and labels below 2²⁴ exactly), compressed with
//! ZIP (lossless). Reading also accepts `f16` and `u32` channels; a file without the attributes
//! is read as a single slice (`nz = 1`) with unit spacing at the origin; a file with several
//! channels must have one named `Y`. Writing goes through a temporary file renamed into place.

use std::io::Cursor;
use std::path::Path;

use exr::meta::MetaData;
use exr::prelude::traits::*;
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Image, Layer, LayerAttributes,
    SmallVec, Text,
};
use medial_core::image::volume::Volume;
use nalgebra::{Matrix3x4, Matrix4};

use crate::affine::{from_top_rows, parse_numbers};
use crate::atomic::write_atomic;
use crate::volume::check_grid;
use crate::{Error, Result};

/// Name of the `v3i` attribute holding `(nx, ny, nz)`.
pub const DIMS_ATTRIBUTE: &str = "medialVolumeDims";
/// Name of the `string` attribute holding the voxel-to-world map (12 numbers, row-major).
pub const AFFINE_ATTRIBUTE: &str = "medialVoxelToWorld";
/// Name of the one channel.
pub const CHANNEL: &str = "Y";

/// The largest ratio of the sample bytes a header declares to the size of the file that is
/// read: no EXR compression packs pixels much beyond deflate's limit of about 1032:1.
pub const MAX_COMPRESSION_RATIO: u64 = 4096;

/// Reads a volume written by [`write_exr_volume`] (or a single-channel EXR image as one slice).
///
/// Errors: [`Error::Io`] when the file cannot be read; [`Error::Format`] for an invalid EXR
/// file, several channels none of which is `Y`, attributes of the wrong type or inconsistent
/// with the image size; [`Error::Truncated`] for a header that declares more samples than the
/// file can hold (see [`MAX_COMPRESSION_RATIO`]);
/// [`Error::Geometry`] for a map that [`check_grid`] refuses (voxel sizes, coplanar axes);
/// [`Error::Model`] for values the engine refuses (NaN).
pub fn read_exr_volume(path: &Path) -> Result<Volume> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_exr_volume(&bytes, path)
}

/// Parses the bytes of an OpenEXR file as [`read_exr_volume`] does (`path` is only used in
/// error messages).
///
/// Errors: as [`read_exr_volume`], but for [`Error::Io`].
pub fn parse_exr_volume(bytes: &[u8], path: &Path) -> Result<Volume> {
    check_declared_size(bytes, path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| exr_error(path, e))?;
    let layer = &image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let channels = &layer.channel_data.list;
    let channel = match channels.iter().find(|c| c.name.to_string() == CHANNEL) {
        Some(c) => c,
        None if channels.len() == 1 => &channels[0],
        None => {
            return Err(Error::format(
                path,
                format!("{} channels and none named {CHANNEL}", channels.len()),
            ))
        }
    };
    let data: Vec<f64> = match &channel.sample_data {
        FlatSamples::F16(v) => v.iter().map(|x| x.to_f64()).collect(),
        FlatSamples::F32(v) => v.iter().map(|&x| f64::from(x)).collect(),
        FlatSamples::U32(v) => v.iter().map(|&x| f64::from(x)).collect(),
    };
    let attribute = |name: &str| layer.attributes.other.get(&Text::from(name));
    let dims = match attribute(DIMS_ATTRIBUTE) {
        Some(AttributeValue::IntVec3((x, y, z))) => {
            let dims = [*x, *y, *z].map(|n| usize::try_from(n).unwrap_or(0));
            if dims[0] != width || dims[1].checked_mul(dims[2]) != Some(height) {
                return Err(Error::format(path, format!(
                    "{DIMS_ATTRIBUTE} {dims:?} does not match the {width}×{height} image (need nx × ny·nz)"
                )));
            }
            dims
        }
        Some(other) => {
            return Err(Error::format(
                path,
                format!("{DIMS_ATTRIBUTE} is {other:?}, not a v3i"),
            ))
        }
        None => [width, height, 1],
    };
    let affine = match attribute(AFFINE_ATTRIBUTE) {
        Some(AttributeValue::Text(text)) => {
            parse_affine(&text.to_string()).map_err(|m| Error::format(path, m))?
        }
        Some(other) => {
            return Err(Error::format(
                path,
                format!("{AFFINE_ATTRIBUTE} is {other:?}, not a string"),
            ))
        }
        None => Matrix4::identity(),
    };
    check_grid(path, dims, &affine)?;
    Volume::new(dims, data, affine).map_err(|e| Error::model(path, e))
}

/// Writes `volume` with the convention of the module doc.
///
/// Errors: [`Error::Format`] if a dimension or `ny · nz` exceeds the EXR limit (2³¹ − 1) or a
/// value is beyond the `f32` range; [`Error::Io`] if the file cannot be written.
pub fn write_exr_volume(path: &Path, volume: &Volume) -> Result<()> {
    let [nx, ny, nz] = volume.dims();
    let too_large = |n: usize| i32::try_from(n).is_err();
    if too_large(nx) || ny.checked_mul(nz).map_or(true, too_large) {
        return Err(Error::format(
            path,
            format!("a {nx}×{ny}×{nz} volume exceeds the EXR image size limit"),
        ));
    }
    if let Some(n) = volume
        .data()
        .iter()
        .position(|v| v.abs() > f64::from(f32::MAX))
    {
        return Err(Error::format(
            path,
            format!(
                "voxel {n} value {} is beyond the f32 range",
                volume.data()[n]
            ),
        ));
    }
    let samples = FlatSamples::F32(volume.data().iter().map(|&v| v as f32).collect());
    let mut attributes = LayerAttributes::named("volume");
    attributes.other.insert(
        Text::from(DIMS_ATTRIBUTE),
        AttributeValue::IntVec3((nx as i32, ny as i32, nz as i32)),
    );
    attributes.other.insert(
        Text::from(AFFINE_ATTRIBUTE),
        AttributeValue::Text(Text::from(format_affine(volume.voxel_to_world()).as_str())),
    );
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![AnyChannel::new(CHANNEL, samples)]));
    let image = Image::from_layer(Layer::new(
        (nx, ny * nz),
        attributes,
        Encoding::SMALL_LOSSLESS,
        channels,
    ));
    let mut bytes = Cursor::new(Vec::new());
    image
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| exr_error(path, e))?;
    write_atomic(path, |w| w.write_all(bytes.get_ref()))
}

/// The first three rows of `m`, row-major, shortest round-trip decimals.
fn format_affine(m: &Matrix4<f64>) -> String {
    let numbers: Vec<String> = (0..3)
        .flat_map(|r| (0..4).map(move |c| (r, c)))
        .map(|(r, c)| format!("{:?}", m[(r, c)]))
        .collect();
    numbers.join(" ")
}

/// Parses 12 numbers (three rows of four) into a 4×4 affine map.
fn parse_affine(text: &str) -> std::result::Result<Matrix4<f64>, String> {
    let numbers =
        parse_numbers(text).map_err(|t| format!("{AFFINE_ATTRIBUTE}: {t:?} is not a number"))?;
    if numbers.len() != 12 {
        return Err(format!(
            "{AFFINE_ATTRIBUTE} has {} numbers, expected 12 (3 rows of 4)",
            numbers.len()
        ));
    }
    Ok(from_top_rows(&Matrix3x4::from_row_slice(&numbers)))
}

/// Refuses a header whose layers declare more sample bytes than [`MAX_COMPRESSION_RATIO`]
/// times the size of the file: the `exr` crate allocates them before reading any pixel.
fn check_declared_size(bytes: &[u8], path: &Path) -> Result<()> {
    let meta = MetaData::read_from_buffered(bytes, false).map_err(|e| exr_error(path, e))?;
    for header in &meta.headers {
        let (width, height) = (header.layer_size.width(), header.layer_size.height());
        let declared = width as u128 * height as u128 * header.channels.bytes_per_pixel as u128;
        let needed = declared / u128::from(MAX_COMPRESSION_RATIO);
        if needed > bytes.len() as u128 {
            return Err(Error::Truncated {
                path: path.into(),
                what: format!(
                    "the {width}×{height} image of {} channels in its header (packed at most \
                     {MAX_COMPRESSION_RATIO}:1)",
                    header.channels.list.len()
                ),
                needed: u64::try_from(needed).unwrap_or(u64::MAX),
                available: bytes.len() as u64,
            });
        }
    }
    Ok(())
}

/// An error of the `exr` crate for `path`. Files are read from memory, so even its I/O errors
/// (an unexpected end) are about the content.
fn exr_error(path: &Path, error: exr::error::Error) -> Error {
    Error::format(path, format!("OpenEXR: {error}"))
}
