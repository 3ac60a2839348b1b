//! Atomic file output: write to a temporary file beside the destination, flush it to disk,
//! then rename it over the destination.
//!
//! A reader of the destination sees either the old file or the complete new one, never a
//! half-written file, and a failure (a write error, a full disk, an error returned by the
//! caller's writer) leaves an existing destination untouched and creates nothing at it.

use std::io::{BufWriter, Write};
use std::path::Path;

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
    let temp = temp_file_beside(path).map_err(io_error)?;
    {
        let mut writer = BufWriter::new(temp.as_file());
        write(&mut writer).map_err(io_error)?;
        writer.flush().map_err(io_error)?;
    }
    temp.as_file().sync_all().map_err(io_error)?;
    temp.persist(path).map_err(|e| io_error(e.error))?;
    Ok(())
}

/// A temporary file named `.<destination name>.<random>.tmp` in the destination's directory.
fn temp_file_beside(path: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
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
