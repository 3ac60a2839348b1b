//! The checkpoint of a fit on disk, `DIR/checkpoint.bin`: the engine's
//! [`medial_core::fit::Checkpoint`] (momenta, λ, μ, L-BFGS memory, AL position, counters), the
//! rows of `log.csv` up to it, the seconds spent, and a fingerprint of the config and input
//! files, so that `medial fit … --resume DIR` continues only the fit it was written for.
//!
//! The file is the 8 bytes `MEDIALCK`, a little-endian `u32` format number, the 32 bytes of
//! the SHA-256 digest of the rest, then the [`Saved`] record in postcard (every `f64` as its 8
//! bytes: ±∞ and NaN round-trip exactly). It is written atomically; a file whose digest does
//! not match its record (damaged on disk or in a copy) is refused, never resumed.

use crate::config::Config;
use crate::error::CliError;
use medial_core::fit::Checkpoint;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// The checkpoint's file name in the result folder.
pub const FILE: &str = "checkpoint.bin";

/// The first bytes of a checkpoint file.
const MAGIC: &[u8; 8] = b"MEDIALCK";

/// The layout of the record after [`MAGIC`]; raised whenever [`Saved`] or the engine's
/// checkpoint types in it change. 2: the L-BFGS state as nalgebra vectors and the coarse time
/// steps' restart point (format 1 checkpoints read as damaged before); 3: the L-BFGS state
/// as plain lists (`medial_core::fit::lbfgs_vector`); 4: the SHA-256 digest of the record
/// before it; 5: the stage's last reported violation (`Extend`'s rate).
const FORMAT: u32 = 5;

/// Bytes of the digest after the format number.
const DIGEST: usize = 32;

/// What a fit needs to go on where it paused.
#[derive(Serialize, Deserialize)]
pub struct Saved {
    /// The `medial` version that wrote it (the engine's state is that version's).
    version: String,
    /// The config and inputs it was written for.
    fingerprint: Fingerprint,
    /// `log.csv` up to the checkpoint, header included.
    pub log: String,
    /// Wall-clock seconds of the fit up to the checkpoint.
    pub seconds: f64,
    /// Wall-clock seconds of each stage that ended, then of the stage in progress so far.
    pub stage_seconds: Vec<f64>,
    /// The engine's checkpoint.
    pub fit: Checkpoint,
}

impl Saved {
    /// A checkpoint of the fit of `fingerprint`'s config.
    pub fn new(
        fingerprint: Fingerprint,
        log: String,
        seconds: f64,
        stage_seconds: Vec<f64>,
        fit: Checkpoint,
    ) -> Self {
        Self {
            version: env!("CARGO_PKG_VERSION").into(),
            fingerprint,
            log,
            seconds,
            stage_seconds,
            fit,
        }
    }

    /// Writes the checkpoint to `path`, atomically.
    pub fn write(&self, path: &Path) -> Result<(), CliError> {
        let record =
            postcard::to_stdvec(self).map_err(|e| CliError::io(path, std::io::Error::other(e)))?;
        medial_io::atomic::write_atomic(path, |w| {
            w.write_all(MAGIC)?;
            w.write_all(&FORMAT.to_le_bytes())?;
            w.write_all(&Sha256::digest(&record))?;
            w.write_all(&record)
        })?;
        Ok(())
    }

    /// Reads the checkpoint at `path` and checks that it was written for `fingerprint` (the
    /// config about to be resumed) by this version of `medial`.
    pub fn read_for(path: &Path, fingerprint: &Fingerprint) -> Result<Self, CliError> {
        let error = |message: String| CliError::Checkpoint {
            path: path.into(),
            message,
        };
        let bytes =
            match std::fs::read(path) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(error(
                    "no checkpoint to resume from (a fit writes one when SIGINT or SIGTERM stops \
                     it, or with --checkpoint-every)"
                        .into(),
                )),
                other => other.map_err(|e| CliError::io(path, e))?,
            };
        let body = bytes
            .strip_prefix(MAGIC.as_slice())
            .ok_or_else(|| error("not a checkpoint of medial".into()))?;
        let format = body
            .get(..4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        if format != Some(FORMAT) {
            return Err(error(format!(
                "checkpoint format {} is not this medial's ({FORMAT}): resume with the \
                 version that wrote it, or start afresh without --resume",
                format.map_or_else(|| "?".into(), |f| f.to_string())
            )));
        }
        let (digest, record) = body[4..]
            .split_at_checked(DIGEST)
            .ok_or_else(|| error("damaged checkpoint: it ends inside its header".into()))?;
        if Sha256::digest(record).as_slice() != digest {
            return Err(error(
                "damaged checkpoint: its contents do not match their SHA-256 digest (the file \
                 was changed or cut short); start afresh without --resume"
                    .into(),
            ));
        }
        let saved: Self =
            postcard::from_bytes(record).map_err(|e| error(format!("damaged checkpoint: {e}")))?;
        if saved.version != env!("CARGO_PKG_VERSION") {
            return Err(error(format!(
                "written by medial {}, this is {}: resume with that version, or start afresh \
                 without --resume",
                saved.version,
                env!("CARGO_PKG_VERSION")
            )));
        }
        saved.fingerprint.check(fingerprint).map_err(error)?;
        Ok(saved)
    }
}

/// SHA-256 digests of a fit's settings (the resolved config with its paths left out) and of
/// each input file's bytes: equal fingerprints make the same fit, wherever the files lie.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Fingerprint {
    settings: [u8; 32],
    /// `(what, digest)` of each input file, e.g. `("stage 'dice' image", …)`.
    inputs: Vec<(String, [u8; 32])>,
}

impl Fingerprint {
    /// The fingerprint of `config`: its settings and the files it reads. `start`: the bytes
    /// of an automatic fit's start, the template its config names in the output folder, where
    /// the set writes it only at the end (they stand for that file's).
    pub fn of(config: &Config, start: Option<&[u8]>) -> Result<Self, CliError> {
        let mut settings = config.clone();
        let template = match start {
            Some(bytes) => Sha256::digest(bytes).into(),
            None => digest_of(&settings.model.template)?,
        };
        let mut inputs = vec![("the template".to_string(), template)];
        settings.model.template = PathBuf::new();
        for stage in &mut settings.stages {
            let name = stage.name.clone();
            let paths = [
                ("target", &mut stage.target),
                ("transform", &mut stage.transform),
                ("image", &mut stage.image),
                ("surface", &mut stage.surface),
            ];
            for (key, path) in paths {
                if let Some(p) = path.as_mut() {
                    inputs.push((format!("stage '{name}' {key}"), digest_of(p)?));
                    *p = PathBuf::new();
                }
            }
        }
        let text = settings.to_toml("")?;
        Ok(Self {
            settings: Sha256::digest(text.as_bytes()).into(),
            inputs,
        })
    }

    /// `Err` naming the first difference between the fingerprint a checkpoint was written for
    /// (`self`) and `now`'s.
    fn check(&self, now: &Self) -> Result<(), String> {
        let refuse = |what: &str| {
            Err(format!(
                "{what} differs from the interrupted fit's: resume with the config and input \
                 files it ran with, or start afresh without --resume"
            ))
        };
        if self.settings != now.settings {
            return refuse("the config");
        }
        if self.inputs.len() != now.inputs.len() {
            return refuse("the list of input files");
        }
        match self.inputs.iter().zip(&now.inputs).find(|(a, b)| a != b) {
            Some((_, (what, _))) => refuse(what),
            None => Ok(()),
        }
    }
}

/// The SHA-256 digest of the file at `path`.
pub(crate) fn digest_of(path: &Path) -> Result<[u8; 32], CliError> {
    let mut file = std::fs::File::open(path).map_err(|e| CliError::io(path, e))?;
    let mut hasher = Sha256::new();
    std::io::copy(&mut file, &mut hasher).map_err(|e| CliError::io(path, e))?;
    Ok(hasher.finalize().into())
}
