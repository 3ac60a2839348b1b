//! Results as a set: the files of a run are written into a staging folder inside the output
//! folder, `DIR/.medial-staging-<pid>/`, then moved into `DIR` one by one, the set's marker
//! (`summary.json` for a fit) last and listing every other file of the set.
//!
//! A reader of `DIR` tells a complete set from a partial one by the marker: present, it names
//! the files of one run, all of them in place; absent, a set is being (or was being) moved in.
//! The marker of the set it replaces is removed before the first file moves, so a kill during
//! the moves never leaves an old marker beside new files. Until then the earlier run's files
//! stay byte-identical; files of the earlier set that the new one does not have are removed
//! before the new marker moves in. What an interrupted run leaves (staging folders, the
//! temporary files of atomic writes, `*.part` files) is removed when the next run starts
//! ([`ResultSet::begin`]). One run at a time may write into a folder.

use crate::error::CliError;
use serde::Deserialize;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The name of a staging folder starts so, followed by the process id.
const STAGING_PREFIX: &str = ".medial-staging-";

/// Sub-folders of a result folder that hold files of a set (cleaned like the folder itself).
const SUBFOLDERS: [&str; 1] = ["flow"];

/// A set of result files being written into its staging folder.
pub struct ResultSet {
    dir: PathBuf,
    staging: PathBuf,
    files: BTreeSet<String>,
    retired: Vec<String>,
}

impl ResultSet {
    /// Starts a set in `dir` (created if needed): removes what interrupted runs left there
    /// ([`clean`]) and creates the staging folder.
    pub fn begin(dir: &Path) -> Result<Self, CliError> {
        create_dir(dir)?;
        clean(dir)?;
        let staging = dir.join(format!("{STAGING_PREFIX}{}", std::process::id()));
        create_dir(&staging)?;
        Ok(Self {
            dir: dir.into(),
            staging,
            files: BTreeSet::new(),
            retired: Vec::new(),
        })
    }

    /// Adds the file `relative` (a path relative to the result folder, `/`-separated, e.g.
    /// `flow/boundary_t000.vtk`) to the set and returns where to write it: its path in the
    /// staging folder, whose folders exist.
    pub fn file(&mut self, relative: &str) -> Result<PathBuf, CliError> {
        let path = self.staging.join(relative);
        if let Some(parent) = path.parent() {
            create_dir(parent)?;
        }
        self.files.insert(relative.into());
        Ok(path)
    }

    /// The staging folder: the set's files so far, at their relative paths.
    pub fn staging(&self) -> &Path {
        &self.staging
    }

    /// Adds the file `relative`, already written at its path in the staging folder, to the set.
    pub fn include(&mut self, relative: &str) {
        self.files.insert(relative.into());
    }

    /// Moves the finished file `from` (on the same file system) into the set as `relative`.
    pub fn adopt(&mut self, from: &Path, relative: &str) -> Result<(), CliError> {
        let to = self.file(relative)?;
        std::fs::rename(from, &to).map_err(|e| CliError::io(from, e))
    }

    /// Removes `relative` from the result folder when the set is committed: a file that no
    /// earlier set lists but that the new set makes obsolete.
    pub fn retire(&mut self, relative: &str) {
        self.retired.push(relative.into());
    }

    /// The relative paths of the files of the set so far, sorted.
    pub fn files(&self) -> Vec<String> {
        self.files.iter().cloned().collect()
    }

    /// Moves the set into the result folder. `write_marker` writes the marker file `marker`
    /// at the staging path it is given, from the sorted list of the set's other files; then
    /// the earlier marker is removed, every other file moves in, the earlier set's files that
    /// this one lacks (and the retired ones) are removed, the new marker moves in last, and the
    /// staging folder goes.
    pub fn commit(
        mut self,
        marker: &str,
        write_marker: impl FnOnce(&Path, Vec<String>) -> Result<(), CliError>,
    ) -> Result<(), CliError> {
        let files = self.files();
        write_marker(&self.file(marker)?, files.clone())?;
        let root = canonical(&self.dir)?;
        // Every destination is checked before anything changes: a refusal leaves the earlier
        // set as it was.
        let destinations = files
            .iter()
            .chain(std::iter::once(&marker.to_string()))
            .map(|relative| Ok((relative.clone(), destination(&root, &self.dir, relative)?)))
            .collect::<Result<Vec<_>, CliError>>()?;
        let earlier = listed_files(&self.dir.join(marker));
        remove_own(&root, &self.dir, marker)?;
        for (relative, to) in &destinations[..files.len()] {
            let from = self.staging.join(relative);
            std::fs::rename(&from, to).map_err(|e| CliError::io(to, e))?;
        }
        let kept: BTreeSet<&String> = files.iter().collect();
        for stale in earlier.iter().chain(&self.retired) {
            if !kept.contains(stale) {
                remove_own(&root, &self.dir, stale)?;
            }
        }
        let to = &destinations[files.len()].1;
        std::fs::rename(self.staging.join(marker), to).map_err(|e| CliError::io(to, e))?;
        sync_dir(&self.dir);
        Ok(())
    }
}

impl Drop for ResultSet {
    /// Removes the staging folder: whatever was not moved in is dropped (best effort; the next
    /// run's [`clean`] removes what stays).
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// Removes from `dir` and its set sub-folders what interrupted runs leave: staging folders
/// (`.medial-staging-<pid>`) and the temporary files of the tool (`.medial-<pid>-…`: those of
/// atomic writes, [`medial_io::atomic::temp_owner`], and the unfinished `log.csv`,
/// [`crate::progress::part_name`]) whose process no longer runs. Only regular files and
/// folders of the folder itself are removed (a symbolic link is never followed), and no
/// other name: a user's `*.part` or `.*.tmp` file stays. Refuses (`Busy`), before removing
/// anything, when another running process owns a staging folder there: its unfinished files
/// are its own.
pub fn clean(dir: &Path) -> Result<(), CliError> {
    let folders = std::iter::once(dir.to_path_buf()).chain(
        SUBFOLDERS
            .iter()
            .map(|s| dir.join(s))
            .filter(|sub| std::fs::symlink_metadata(sub).is_ok_and(|m| m.is_dir())),
    );
    let entries: Vec<(String, PathBuf, std::fs::FileType)> = folders
        .filter_map(|folder| std::fs::read_dir(folder).ok())
        .flat_map(|entries| entries.flatten())
        .filter_map(|entry| {
            let kind = entry.file_type().ok()?;
            Some((
                entry.file_name().to_string_lossy().into_owned(),
                entry.path(),
                kind,
            ))
        })
        .collect();
    let staging = |name: &str, kind: &std::fs::FileType| {
        kind.is_dir()
            && name
                .strip_prefix(STAGING_PREFIX)
                .is_some_and(|pid| pid.parse::<u32>().is_ok())
    };
    for (name, _, kind) in &entries {
        if staging(name, kind) {
            if let Some(pid) = writer_running(&name[STAGING_PREFIX.len()..]) {
                return Err(CliError::Busy {
                    dir: dir.into(),
                    pid,
                });
            }
        }
    }
    for (name, path, kind) in &entries {
        if staging(name, kind) {
            std::fs::remove_dir_all(path).map_err(|e| CliError::io(path, e))?;
        } else if kind.is_file() {
            let owner = medial_io::atomic::temp_owner(name);
            if owner.is_some_and(|pid| writer_running(&pid.to_string()).is_none()) {
                remove_if_present(path)?;
            }
        }
    }
    Ok(())
}

/// The process id `pid` of a staging folder's name when that process still runs as a program
/// of this one's name (on Linux, by `/proc/PID/comm`; elsewhere, or for this process's own id,
/// a staging folder is taken as left over by an interrupted run).
fn writer_running(pid: &str) -> Option<u32> {
    let pid: u32 = pid.parse().ok()?;
    let command = |process: &str| std::fs::read_to_string(format!("/proc/{process}/comm")).ok();
    (pid != std::process::id() && command(&pid.to_string())? == command("self")?).then_some(pid)
}

/// The canonical path of the folder `dir` (links resolved).
fn canonical(dir: &Path) -> Result<PathBuf, CliError> {
    std::fs::canonicalize(dir).map_err(|e| CliError::io(dir, e))
}

/// The path the set's file `relative` moves to: in `dir` (canonical `root`), its folders
/// created, and refused with one line when it would leave the folder (a `..`, a root, or a
/// folder on its way that is a link to elsewhere) or when something other than a regular file
/// is there (a folder, a link, a device, a FIFO). The path returned has its folders resolved,
/// so the rename cannot follow a link.
fn destination(root: &Path, dir: &Path, relative: &str) -> Result<PathBuf, CliError> {
    let path = dir.join(relative);
    let refuse = |what: &str| CliError::io(&path, std::io::Error::other(what.to_string()));
    if !is_relative_inside(relative) {
        return Err(refuse("not a path inside the output folder"));
    }
    let (Some(parent), Some(name)) = (path.parent(), path.file_name()) else {
        return Err(refuse("not a path inside the output folder"));
    };
    create_dir(parent)?;
    let parent = canonical(parent)?;
    if !parent.starts_with(root) {
        return Err(refuse(&format!(
            "its folder leads out of the output folder {} (a symbolic link?): refused to \
             write there",
            dir.display()
        )));
    }
    let resolved = parent.join(name);
    match std::fs::symlink_metadata(&resolved) {
        Ok(meta) if !meta.is_file() => Err(refuse(
            "exists and is not a regular file (a folder, a symbolic link, a device or a FIFO): \
             refused to replace it; move it away or give another output folder",
        )),
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(CliError::io(&path, e)),
        _ => Ok(resolved),
    }
}

/// Removes the file `relative` of an earlier set from `dir` (canonical `root`) when it is the
/// tool's to remove, as proven by where it is: a regular file (not a link, which is never
/// followed) whose folder, links resolved, is inside the output folder. Anything else is left
/// where it is.
fn remove_own(root: &Path, dir: &Path, relative: &str) -> Result<(), CliError> {
    if !is_relative_inside(relative) {
        return Ok(());
    }
    let path = dir.join(relative);
    let (Some(parent), Some(name)) = (path.parent(), path.file_name()) else {
        return Ok(());
    };
    let Ok(parent) = std::fs::canonicalize(parent) else {
        return Ok(());
    };
    let resolved = parent.join(name);
    let regular = std::fs::symlink_metadata(&resolved).is_ok_and(|m| m.is_file());
    if parent.starts_with(root) && regular {
        remove_if_present(&resolved)?;
    } else if regular || std::fs::symlink_metadata(&resolved).is_ok() {
        tracing::warn!(
            "{}: listed by the earlier set but not a regular file inside the output folder: \
             left as it is",
            path.display()
        );
    }
    Ok(())
}

/// The `files` a marker lists (empty when it is missing or lists none).
fn listed_files(marker: &Path) -> Vec<String> {
    #[derive(Deserialize)]
    struct Listed {
        #[serde(default)]
        files: Vec<String>,
    }
    std::fs::read(marker)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<Listed>(&bytes).ok())
        .map_or_else(Vec::new, |l| l.files)
}

/// A relative path that stays inside the result folder by its text (no root, no `..`; the
/// folders on its way are checked apart, [`destination`] and [`remove_own`]).
fn is_relative_inside(relative: &str) -> bool {
    Path::new(relative)
        .components()
        .all(|c| matches!(c, std::path::Component::Normal(_)))
}

fn remove_if_present(path: &Path) -> Result<(), CliError> {
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(CliError::io(path, e)),
        _ => Ok(()),
    }
}

/// Creates the folder `path` and its parents as needed.
pub fn create_dir(path: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(path).map_err(|e| CliError::io(path, e))
}

/// Flushes the renames in `dir` to disk (best effort: not every platform opens folders).
fn sync_dir(dir: &Path) {
    if let Ok(folder) = std::fs::File::open(dir) {
        let _ = folder.sync_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut all = Vec::new();
        for folder in [dir.to_path_buf(), dir.join("flow")] {
            for e in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
                let rel = e
                    .path()
                    .strip_prefix(dir)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                all.push(rel);
            }
        }
        all.sort();
        all
    }

    fn write_set(dir: &Path, files: &[(&str, &str)]) {
        let mut set = ResultSet::begin(dir).unwrap();
        for (name, text) in files {
            std::fs::write(set.file(name).unwrap(), text).unwrap();
        }
        set.commit("summary.json", |path, files| {
            let text = serde_json::json!({ "files": files }).to_string();
            std::fs::write(path, text).map_err(|e| CliError::io(path, e))
        })
        .unwrap();
    }

    #[test]
    fn a_set_replaces_the_earlier_one_and_its_stale_files() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_set(
            d,
            &[("a.txt", "1"), ("flow/t0.vtk", "1"), ("flow/t1.vtk", "1")],
        );
        std::fs::write(d.join("mine.txt"), "not of a set").unwrap();
        write_set(d, &[("a.txt", "2"), ("flow/t0.vtk", "2")]);
        assert_eq!(
            names(d),
            ["a.txt", "flow", "flow/t0.vtk", "mine.txt", "summary.json"]
        );
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "2");
        let summary = std::fs::read_to_string(d.join("summary.json")).unwrap();
        assert_eq!(summary, r#"{"files":["a.txt","flow/t0.vtk"]}"#);
    }

    #[test]
    fn leftovers_of_interrupted_runs_are_cleaned_and_a_dropped_set_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_set(d, &[("a.txt", "1")]);
        std::fs::create_dir_all(d.join(".medial-staging-1/flow")).unwrap();
        std::fs::create_dir_all(d.join("flow")).unwrap();
        // A process id that runs no medial: the largest a Linux pid can be, plus one.
        let dead = 4_194_305;
        for leftover in [
            format!(".medial-{dead}-a_txt-x1y2z3.tmp"),
            format!(".medial-{dead}-log.csv.part"),
            format!("flow/.medial-{dead}-b_vtk-abcdef.tmp"),
        ] {
            std::fs::write(d.join(leftover), "").unwrap();
        }
        let mut set = ResultSet::begin(d).unwrap();
        std::fs::write(set.file("a.txt").unwrap(), "2").unwrap();
        assert_eq!(names(d).len(), 4, "{:?}", names(d)); // a.txt, flow, staging, summary
        drop(set);
        assert_eq!(names(d), ["a.txt", "flow", "summary.json"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "1");
    }

    #[test]
    fn a_marker_never_makes_a_commit_remove_files_outside_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(dir.path().join("precious"), "x").unwrap();
        std::fs::write(
            out.join("summary.json"),
            r#"{"files":["../precious","/etc/x"]}"#,
        )
        .unwrap();
        write_set(&out, &[("a.txt", "1")]);
        assert!(dir.path().join("precious").exists());
    }

    /// Issue 33, items 2 and 9: the user's `*.part` and `.*.tmp` files, and the files behind a
    /// link in the folder, stay; so does a file listed by a forged marker through a link.
    #[test]
    fn only_the_tools_own_files_are_removed_never_through_a_link() {
        let dir = tempfile::tempdir().unwrap();
        let (d, out) = (dir.path(), dir.path().join("out"));
        let elsewhere = d.join("elsewhere");
        std::fs::create_dir_all(out.join("flow")).unwrap();
        std::fs::create_dir_all(&elsewhere).unwrap();
        std::os::unix::fs::symlink(&elsewhere, out.join("lnk")).unwrap();
        let mine = [
            "precious.txt",
            "notes.part",
            ".draft.tmp",
            ".medial-staging-x.tmp",
            "log.csv.part",
        ];
        for name in mine {
            std::fs::write(elsewhere.join(name), "x").unwrap();
            std::fs::write(out.join(name), "x").unwrap();
            std::fs::write(out.join("flow").join(name), "x").unwrap();
        }
        std::os::unix::fs::symlink(elsewhere.join("precious.txt"), out.join("link.txt")).unwrap();
        std::fs::write(
            out.join("summary.json"),
            r#"{"files":["lnk/precious.txt","lnk/notes.part","link.txt","precious.txt"]}"#,
        )
        .unwrap();
        write_set(&out, &[("a.txt", "1")]);
        for name in mine {
            assert!(elsewhere.join(name).exists(), "{name} behind the link went");
            assert!(out.join("flow").join(name).exists(), "flow/{name} went");
            // precious.txt was listed by the earlier marker and is a regular file inside:
            // the earlier set's, replaced.
            assert_eq!(out.join(name).exists(), name != "precious.txt", "{name}");
        }
        assert!(std::fs::symlink_metadata(out.join("link.txt")).is_ok());
        // A flow folder that is a link to elsewhere is neither cleaned nor written through.
        let flow = out.join("flow");
        std::fs::rename(&flow, d.join("flow-real")).unwrap();
        std::os::unix::fs::symlink(d.join("flow-real"), &flow).unwrap();
        std::fs::write(d.join("flow-real/.medial-4194305-x.tmp"), "x").unwrap();
        let mut set = ResultSet::begin(&out).unwrap();
        std::fs::write(set.file("flow/t0.vtk").unwrap(), "1").unwrap();
        let error = set
            .commit("summary.json", |path, _| {
                std::fs::write(path, "{}").map_err(|e| CliError::io(path, e))
            })
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("flow/t0.vtk") && error.contains("leads out"),
            "{error}"
        );
        assert!(d.join("flow-real/.medial-4194305-x.tmp").exists());
        assert!(!d.join("flow-real/t0.vtk").exists());
        assert_eq!(
            std::fs::read_to_string(out.join("summary.json")).unwrap(),
            r#"{"files":["a.txt"]}"#,
            "the refused set changed the earlier one"
        );
    }
}
