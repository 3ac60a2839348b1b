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
        let earlier = listed_files(&self.dir.join(marker));
        remove_if_present(&self.dir.join(marker))?;
        for relative in &files {
            let to = self.dir.join(relative);
            if let Some(parent) = to.parent() {
                create_dir(parent)?;
            }
            let from = self.staging.join(relative);
            std::fs::rename(&from, &to).map_err(|e| CliError::io(&to, e))?;
        }
        let kept: BTreeSet<&String> = files.iter().collect();
        for stale in earlier.iter().chain(&self.retired) {
            if !kept.contains(stale) && is_relative_inside(stale) {
                remove_if_present(&self.dir.join(stale))?;
            }
        }
        let to = self.dir.join(marker);
        std::fs::rename(self.staging.join(marker), &to).map_err(|e| CliError::io(&to, e))?;
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
/// (`.medial-staging-*`), the temporary files of atomic writes (`.*.tmp`) and unfinished files
/// (`*.part`). Refuses (`Busy`), before removing anything, when another running process owns a
/// staging folder there: its unfinished files (its `log.csv.part`) are its own, and a folder
/// lists them in no set order (removing as they came once deleted a running fit's log before
/// its staging folder was reached).
pub fn clean(dir: &Path) -> Result<(), CliError> {
    let folders = std::iter::once(dir.to_path_buf()).chain(SUBFOLDERS.iter().map(|s| dir.join(s)));
    let entries: Vec<(String, PathBuf, bool)> = folders
        .filter_map(|folder| std::fs::read_dir(folder).ok())
        .flat_map(|entries| entries.flatten())
        .map(|entry| {
            let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
            (
                entry.file_name().to_string_lossy().into_owned(),
                entry.path(),
                is_dir,
            )
        })
        .collect();
    let staging = |name: &str, is_dir: bool| is_dir && name.starts_with(STAGING_PREFIX);
    for (name, _, is_dir) in &entries {
        if staging(name, *is_dir) {
            if let Some(pid) = writer_running(&name[STAGING_PREFIX.len()..]) {
                return Err(CliError::Busy {
                    dir: dir.into(),
                    pid,
                });
            }
        }
    }
    for (name, path, is_dir) in &entries {
        if staging(name, *is_dir) {
            std::fs::remove_dir_all(path).map_err(|e| CliError::io(path, e))?;
        } else if !is_dir && is_leftover(name) {
            remove_if_present(path)?;
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

/// A file name an interrupted write leaves: a temporary file of [`medial_io::atomic`]
/// (`.<name>-<random>.tmp`) or an unfinished `*.part` file.
fn is_leftover(name: &str) -> bool {
    (name.starts_with('.') && name.ends_with(".tmp")) || name.ends_with(".part")
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

/// A relative path that stays inside the result folder (no root, no `..`): a marker from
/// elsewhere must not make a commit remove files outside it.
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
        for leftover in [
            ".a_txt-x1y2z3.tmp",
            "log.csv.part",
            "flow/.b_vtk-abcdef.tmp",
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
}
