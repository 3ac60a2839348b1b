//! Atomic file output: write to a temporary file beside the destination, flush it to disk,
//! then rename it over the destination.
//!
//! A reader of the destination sees either the old file or the complete new one, never a
//! half-written file, and a failure (a write error, a full disk, an error returned by the
//! caller's writer) leaves an existing destination untouched and creates nothing at it.
//!
//! Every file of this crate is written this way: through a writer ([`write_atomic`]) or, for
//! libraries that open the file themselves, through a temporary path
//! ([`write_atomic_via_path`]).

use std::io::{BufWriter, Write};
use std::path::Path;

use tempfile::NamedTempFile;

use crate::{Error, Result};

/// Writes a file atomically.
///
/// `write` receives a buffered writer on a temporary file created in the destination's
/// directory (so that the final rename never crosses file systems). When it returns `Ok`, the
/// buffer is flushed, the file is synced to disk (`fsync`) and renamed to `path`, replacing any
/// existing file there. When it returns `Err`, or any step fails, the temporary file is removed,
/// nothing is created at `path` and an existing file there is left as it was.
///
/// On Unix the new file gets the permissions of an ordinary `File::create` (`0o666` minus the
/// process umask), not the private `0o600` of temporary files.
///
/// Errors: [`Error::Io`] naming `path` (directory missing or not writable, disk full, or the
/// error returned by `write`).
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let io_error = |e: std::io::Error| Error::io(path, e);
    commit(path, ".tmp", |temp| {
        let mut writer = BufWriter::new(temp.as_file());
        write(&mut writer).map_err(io_error)?;
        writer.flush().map_err(io_error)
    })
}

/// Writes a file atomically through a library that needs a path to write to.
///
/// `write` receives the path of an empty temporary file in the destination's directory whose
/// name ends in `suffix` (e.g. `.nii.gz`, for libraries that choose the format by the name),
/// and must write the whole file there, creating or truncating it in place (not replacing it by
/// another file). When it returns `Ok`, the file is synced to disk and renamed to `path`; when
/// it returns `Err`, or any step fails, the temporary file is removed, nothing is created at
/// `path` and an existing file there is left as it was. Permissions are as for
/// [`write_atomic`].
///
/// Errors: the error returned by `write`; [`Error::Io`] naming `path` when the temporary file
/// cannot be created, synced or renamed.
pub fn write_atomic_via_path(
    path: &Path,
    suffix: &str,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    commit(path, suffix, |temp| write(temp.path()))
}

/// The one rule of both writers: a temporary file beside `path` (see [`temp_file_beside`]),
/// filled by `fill`, synced and renamed to `path`; removed on any failure (when `temp` drops).
fn commit(
    path: &Path,
    suffix: &str,
    fill: impl FnOnce(&NamedTempFile) -> Result<()>,
) -> Result<()> {
    let io_error = |e: std::io::Error| Error::io(path, e);
    check_destination(path)?;
    let temp = temp_file_beside(path, suffix).map_err(io_error)?;
    fill(&temp)?;
    temp.as_file().sync_all().map_err(io_error)?;
    temp.persist(path).map_err(|e| io_error(e.error))?;
    Ok(())
}

/// `Ok` when `path` may be replaced by a regular file: nothing is there, or a regular file, or
/// a symbolic link (the rename replaces the link, never what it leads to). A folder, a device,
/// a FIFO or a socket there is refused with [`Error::Format`] (one line naming the path):
/// replacing `/dev/null` by a file, or a FIFO another program reads, is never what was meant.
pub fn check_destination(path: &Path) -> Result<()> {
    let kind = match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::io(path, e)),
        Ok(meta) => meta.file_type(),
    };
    if kind.is_file() || kind.is_symlink() {
        return Ok(());
    }
    let what = if kind.is_dir() {
        "a folder"
    } else {
        special_kind(&kind)
    };
    Err(Error::format(
        path,
        format!(
            "is {what}, not a regular file: refused to replace it by an output (give the path \
             of a file)"
        ),
    ))
}

/// What a file that is neither a regular file, a link nor a folder is.
fn special_kind(kind: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_char_device() || kind.is_block_device() {
            return "a device";
        }
        if kind.is_fifo() {
            return "a FIFO";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    let _ = kind;
    "not a regular file"
}

/// The start of the name of every temporary file this process makes: `.medial-<pid>-`. The
/// process id makes it the tool's and tells whose it is ([`temp_owner`]), so that a later run
/// removes exactly the temporary files that interrupted runs left and never a user's file.
pub fn temp_prefix() -> String {
    format!("{TEMP_START}{}-", std::process::id())
}

const TEMP_START: &str = ".medial-";

/// The process id of the run that made the temporary file `name` (a name that starts with
/// [`temp_prefix`]'s pattern, `.medial-<digits>-`), or `None` for any other name.
pub fn temp_owner(name: &str) -> Option<u32> {
    let (pid, _) = name.strip_prefix(TEMP_START)?.split_once('-')?;
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// A temporary file named `.medial-<pid>-<destination name>-<random><suffix>` in the
/// destination's directory, dots of the destination name replaced by `_`, with the permissions
/// of an ordinary new file. Only `suffix` has dots (besides the leading one): a library that
/// reads the format from the last extension(s), or swaps the last extension to name its output
/// (the `nifti` crate does), sees `suffix` and writes at this very path.
fn temp_file_beside(path: &Path, suffix: &str) -> std::io::Result<NamedTempFile> {
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!("{}{}-", temp_prefix(), name.replace('.', "_"));
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("read test dir")
            .map(|e| {
                e.expect("dir entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        names.sort();
        names
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("out.txt");
        write_atomic(&path, |w| w.write_all(b"first")).expect("first write");
        assert_eq!(std::fs::read(&path).expect("read"), b"first");
        write_atomic(&path, |w| w.write_all(b"second, longer")).expect("second write");
        assert_eq!(std::fs::read(&path).expect("read"), b"second, longer");
        assert_eq!(leftovers(dir.path()), vec!["out.txt".to_string()]);
    }

    #[test]
    fn failure_leaves_nothing_new() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("new.txt");
        let err = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk on fire"))
        })
        .expect_err("the writer failed");
        assert!(err.to_string().contains("disk on fire"), "{err}");
        assert!(err.to_string().contains("new.txt"), "{err}");
        assert!(!path.exists());
        assert!(
            leftovers(dir.path()).is_empty(),
            "{:?}",
            leftovers(dir.path())
        );
    }

    #[test]
    fn failure_keeps_existing_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("keep.txt");
        std::fs::write(&path, b"precious").expect("seed");
        let result = write_atomic(&path, |w| {
            w.write_all(&[b'x'; 100_000])?;
            Err(std::io::Error::other("stop"))
        });
        assert!(result.is_err());
        assert_eq!(std::fs::read(&path).expect("read"), b"precious");
        assert_eq!(leftovers(dir.path()), vec!["keep.txt".to_string()]);
    }

    #[test]
    fn missing_directory_is_an_io_error() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("no/such/dir/out.txt");
        let err = write_atomic(&path, |w| w.write_all(b"x")).expect_err("no directory");
        assert!(matches!(err, Error::Io { .. }), "{err:?}");
    }

    #[test]
    fn via_path_writes_a_file_named_with_the_suffix() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("image.nii.gz");
        write_atomic_via_path(&path, ".nii.gz", |temp| {
            let name = temp.file_name().expect("name").to_string_lossy();
            assert!(
                name.starts_with(&format!("{}image_nii_gz-", temp_prefix())),
                "{name}"
            );
            assert_eq!(temp_owner(&name), Some(std::process::id()));
            assert!(name.ends_with(".nii.gz"), "{name}");
            assert_eq!(name.matches('.').count(), 3, "{name}");
            std::fs::write(temp, b"data").map_err(|e| Error::io(temp, e))
        })
        .expect("write");
        assert_eq!(std::fs::read(&path).expect("read"), b"data");
        assert_eq!(leftovers(dir.path()), vec!["image.nii.gz".to_string()]);
    }

    #[test]
    fn via_path_failure_keeps_existing_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("keep.nii");
        std::fs::write(&path, b"precious").expect("seed");
        let err = write_atomic_via_path(&path, ".nii", |temp| {
            std::fs::write(temp, b"partial").map_err(|e| Error::io(temp, e))?;
            Err(Error::format(&path, "refused"))
        })
        .expect_err("the writer failed");
        assert!(matches!(err, Error::Format { .. }), "{err:?}");
        assert_eq!(std::fs::read(&path).expect("read"), b"precious");
        assert_eq!(leftovers(dir.path()), vec!["keep.nii".to_string()]);
    }

    /// Issue 33, item 3: a device, a FIFO or a folder at the output path is refused and left
    /// as it was.
    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_folders_are_never_replaced() {
        let dir = tempfile::tempdir().expect("temp dir");
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo runs");
        assert!(made.success());
        let folder = dir.path().join("folder");
        std::fs::create_dir(&folder).expect("folder");
        for (path, what) in [
            (Path::new("/dev/null"), "a device"),
            (fifo.as_path(), "a FIFO"),
            (folder.as_path(), "a folder"),
        ] {
            let err = write_atomic(path, |w| w.write_all(b"x")).expect_err("refused");
            let message = err.to_string();
            assert!(message.contains(what), "{message}");
            assert!(message.contains(&path.display().to_string()), "{message}");
            assert_eq!(message.lines().count(), 1);
            let err = write_atomic_via_path(path, ".nii", |_| Ok(())).expect_err("refused");
            assert!(err.to_string().contains(what), "{err}");
        }
        use std::os::unix::fs::FileTypeExt;
        let kind = std::fs::symlink_metadata(&fifo).expect("fifo").file_type();
        assert!(kind.is_fifo(), "the FIFO was replaced");
        assert!(folder.is_dir());
        assert_eq!(leftovers(dir.path()), ["fifo", "folder"]);
    }

    #[test]
    fn only_the_tools_temporary_names_have_an_owner() {
        assert_eq!(temp_owner(".medial-123-a_vtk-x1y2z3.tmp"), Some(123));
        assert_eq!(temp_owner(".medial-123-log.csv.part"), Some(123));
        for name in [
            ".a_vtk-x1y2z3.tmp",
            "log.csv.part",
            ".medial-staging-123",
            ".medial--x.tmp",
            ".medial-12a-x.tmp",
            "medial-123-x.tmp",
        ] {
            assert_eq!(temp_owner(name), None, "{name}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn permissions_are_not_private() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("perm.txt");
        write_atomic(&path, |w| w.write_all(b"x")).expect("write");
        let mode = std::fs::metadata(&path).expect("meta").permissions().mode();
        // Owner read+write always; group/other bits follow the umask, unlike a 0o600 temp file.
        assert_eq!(mode & 0o600, 0o600);
        let umask_allows_group_read = {
            let probe = dir.path().join("probe");
            std::fs::File::create(&probe).expect("probe");
            std::fs::metadata(&probe)
                .expect("meta")
                .permissions()
                .mode()
                & 0o077
        };
        assert_eq!(mode & 0o077, umask_allows_group_read);
    }
}
