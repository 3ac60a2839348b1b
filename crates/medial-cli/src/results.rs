//! Results as a set, committed so that a SIGKILL at any instant leaves the output folder showing
//! the earlier set or the new one whole, every file byte-identical to one of them (decision
//! 0300).
//!
//! A result folder `DIR` holds
//! - `DIR/.medial-sets/<n>/`: the files of a set (generation `n`) at their relative paths;
//! - `DIR/.medial-sets/current`: a symbolic link to `<n>`, the set the folder shows;
//! - `DIR/<file>` (and `DIR/flow/<file>`): a symbolic link `.medial-sets/current/<file>`
//!   (`../.medial-sets/current/flow/<file>`), the same for every set that has the file.
//!
//! A run writes its files into a staging folder, `DIR/.medial-staging-<pid>/`, the set's
//! marker (`summary.json` for a fit) last, listing every other file. The commit
//! ([`ResultSet::commit`]): every destination is checked (nothing changes on a refusal); the
//! regular files the folder shows at the set's paths or as files of the earlier set (a folder
//! of the layout before, `medial report` run again, a periodic checkpoint) are hard-linked
//! into the shown generation and replaced by their links, each showing the same bytes all
//! along; the staging folder becomes generation `n + 1`; the links of its new files are made
//! (dangling until the switch); one rename of a new `current` link switches every link at
//! once; then the links of files the new set lacks and the earlier generations are removed,
//! only the tool's own, proven by place: a link whose text is exactly its own
//! `.medial-sets/current/…` pattern, a generation folder under `DIR/.medial-sets`. What an
//! interrupted run leaves (staging folders, temporary files and links, `*.part` files) is
//! removed when the next run starts ([`ResultSet::begin`]); generations a kill left behind, by
//! the next commit. One run at a time may write into a folder.

use crate::error::CliError;
use serde::Deserialize;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The names the tool gives its own files and folders start so (temporary files, staging
/// folders, the generations' folder).
const TOOL_NAMESPACE: &str = ".medial-";

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

    /// Puts the file `relative` the result folder shows now (through its link, if it is one)
    /// into the set unchanged: a hard link in the staging folder (a copy where the file system
    /// has none). For a command that writes a set from the earlier one (`medial report`).
    pub fn carry(&mut self, relative: &str) -> Result<(), CliError> {
        let root = canonical(&self.dir)?;
        if !is_plain_file(&root, relative) && !is_own_link(&root, relative) {
            return Err(CliError::io(
                &self.dir.join(relative),
                std::io::Error::other(
                    "listed by the set but not a file of the tool inside the output folder",
                ),
            ));
        }
        let from = canonical(&root.join(relative))?;
        let to = self.file(relative)?;
        adopt_file(&from, &to, &mut Steps(0))
    }

    /// Commits the set into the result folder (the module's layout and steps).
    /// `write_marker` writes the marker file `marker` at the staging path it is given, from the
    /// set's other files and their SHA-256 ([`Listing`]). Refused with one line, before
    /// anything changes, when a destination leads out of the folder or holds something else
    /// than a regular file or the tool's own link. On a file system without symbolic links the
    /// set is moved in file by file instead, with a warning ([`ResultSet::commit_plain`]).
    pub fn commit(
        mut self,
        marker: &str,
        write_marker: impl FnOnce(&Path, Listing) -> Result<(), CliError>,
    ) -> Result<(), CliError> {
        let listing = Listing::of(&self.staging, self.files())?;
        write_marker(&self.file(marker)?, listing)?;
        let all = self.files.clone();
        let root = canonical(&self.dir)?;
        for relative in &all {
            check_destination(&root, &self.dir, relative)?;
        }
        if !makes_links(&self.staging) {
            tracing::warn!(
                "{}: the file system makes no symbolic links: the results are moved in file by \
                 file, {marker} last (a crash while they move can leave a mix of the earlier \
                 and the new files; {marker} then lists the earlier set's)",
                self.dir.display()
            );
            return self.commit_plain(&root, marker);
        }
        let sets = sets_folder(&root, &self.dir)?;
        let earlier = listed_files(&root.join(marker));
        let mut steps = Steps(0);
        // The regular files the folder shows (the earlier set's, and whatever is at the new
        // set's paths): hard-linked into the shown generation, then replaced by their links.
        let plain: BTreeSet<String> = (earlier.iter().chain(&self.retired).chain(&all))
            .filter(|relative| is_plain_file(&root, relative))
            .cloned()
            .collect();
        for relative in &earlier {
            let path = root.join(relative);
            let own = is_plain_file(&root, relative) || is_own_link(&root, relative);
            if !own && std::fs::symlink_metadata(&path).is_ok() {
                tracing::warn!(
                    "{}: listed by the earlier set but not a file of the tool inside the output \
                     folder: left as it is",
                    self.dir.join(relative).display()
                );
            }
        }
        if !plain.is_empty() {
            let shown = current_generation(&sets);
            let generation = match shown {
                Some(n) => n,
                None => next_generation(&sets),
            };
            for relative in &plain {
                let to = sets.join(generation.to_string()).join(relative);
                adopt_file(&root.join(relative), &to, &mut steps)?;
            }
            if shown.is_none() {
                switch(&sets, generation, &mut steps)?;
            }
            for relative in &plain {
                make_link(&root, relative, &mut steps)?;
            }
        }
        // The new set becomes a generation; the links of its new files dangle until the switch.
        let generation = next_generation(&sets);
        let folder = sets.join(generation.to_string());
        steps.next();
        std::fs::rename(&self.staging, &folder).map_err(|e| CliError::io(&folder, e))?;
        // An empty staging folder again: another run still sees this one writing.
        steps.next();
        create_dir(&self.staging)?;
        for relative in &all {
            if !is_own_link(&root, relative) {
                make_link(&root, relative, &mut steps)?;
            }
        }
        for synced in [folder.join("flow"), folder, root.join("flow"), root.clone()] {
            sync_dir(&synced);
        }
        switch(&sets, generation, &mut steps)?;
        // The switch is made: what the earlier sets had and this one lacks goes.
        let stale: BTreeSet<String> = (earlier.into_iter().chain(self.retired.clone()))
            .chain(plain)
            .chain(links_in(&root))
            .filter(|relative| !all.contains(relative))
            .collect();
        // The new set is shown whatever happens now: what cannot be removed is only warned of
        // (the next commit removes it).
        let warn = |e: CliError| tracing::warn!("{e}: left for the next fit to remove");
        for relative in &stale {
            if is_own_link(&root, relative) {
                steps.next();
                remove_if_present(&root.join(relative)).unwrap_or_else(warn);
            }
        }
        for earlier in generations(&sets).into_iter().filter(|&n| n != generation) {
            remove_tree(&sets.join(earlier.to_string()), &mut steps).unwrap_or_else(warn);
        }
        for synced in [root.join("flow"), root.clone(), sets] {
            sync_dir(&synced);
        }
        Ok(())
    }
}

impl ResultSet {
    /// The commit where no symbolic link can be made: the earlier marker removed first (so a
    /// folder whose marker lists a set never shows a mix), each file of the set renamed over
    /// its path, the marker last, then the earlier set's files the new one lacks removed (only
    /// the tool's regular files inside the folder, proven by place).
    fn commit_plain(self, root: &Path, marker: &str) -> Result<(), CliError> {
        let earlier = listed_files(&root.join(marker));
        if is_plain_file(root, marker) {
            remove_if_present(&root.join(marker))?;
        }
        sync_dir(root);
        let others = self.files.iter().filter(|r| r.as_str() != marker);
        for relative in others.chain(std::iter::once(&marker.to_string())) {
            let to = root.join(relative);
            if let Some(parent) = to.parent() {
                create_dir(parent)?;
            }
            std::fs::rename(self.staging.join(relative), &to).map_err(|e| CliError::io(&to, e))?;
        }
        for synced in [root.join("flow"), root.to_path_buf()] {
            sync_dir(&synced);
        }
        let stale = (earlier.iter().chain(&self.retired)).filter(|r| !self.files.contains(*r));
        for relative in stale {
            if is_plain_file(root, relative) {
                remove_if_present(&root.join(relative))
                    .unwrap_or_else(|e| tracing::warn!("{e}: left for the next fit to remove"));
            }
        }
        Ok(())
    }
}

/// What a set's marker records of the set's other files.
#[derive(Debug, Default, Deserialize)]
pub struct Listing {
    /// Their paths relative to the result folder, sorted.
    #[serde(default)]
    pub files: Vec<String>,
    /// The SHA-256 of each (lowercase hex), by path: what [`verify`] checks.
    #[serde(default)]
    pub sha256: std::collections::BTreeMap<String, String>,
}

impl Listing {
    /// The listing of `files`, at their relative paths in `folder`.
    fn of(folder: &Path, files: Vec<String>) -> Result<Self, CliError> {
        let sha256 = files
            .iter()
            .map(|relative| Ok((relative.clone(), sha256_hex(&folder.join(relative))?)))
            .collect::<Result<_, CliError>>()?;
        Ok(Self { files, sha256 })
    }
}

/// The SHA-256 of the file at `path` ([`crate::checkpoint::digest_of`]), in lowercase hex.
fn sha256_hex(path: &Path) -> Result<String, CliError> {
    let digest = crate::checkpoint::digest_of(path)?;
    Ok(digest.iter().map(|b| format!("{b:02x}")).collect())
}

/// Checks the files of the set the folder `dir` shows against the SHA-256 its marker
/// records. Refused with one line naming the first file that is missing or differs (damaged,
/// or changed after the set was written); a marker that records no digests (a set of an
/// earlier version) is taken as it is; the files `skip` names are not checked (those the
/// caller makes again). The marker itself is the caller's to read.
pub fn verify(dir: &Path, marker: &str, skip: impl Fn(&str) -> bool) -> Result<(), CliError> {
    let path = dir.join(marker);
    let Ok(bytes) = std::fs::read(&path) else {
        return Ok(());
    };
    let Ok(listing) = serde_json::from_slice::<Listing>(&bytes) else {
        return Ok(());
    };
    for (relative, recorded) in listing.sha256.iter().filter(|(r, _)| !skip(r)) {
        let file = dir.join(relative);
        let refuse = |what: String| CliError::File(medial_io::Error::format(&file, what));
        if !is_relative_inside(relative) {
            return Err(refuse(format!(
                "{marker} records a path outside the folder: refused"
            )));
        }
        if !file.is_file() {
            return Err(refuse(format!(
                "listed by {} but missing: the set of results is not whole",
                path.display()
            )));
        }
        if &sha256_hex(&file)? != recorded {
            return Err(refuse(format!(
                "its bytes differ from the SHA-256 that {} records (damaged, or changed after \
                 the results were written): refused",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Refuses `out` as the output folder of `medial COMMAND` (whose summary.json records
/// `"command": COMMAND`) when it holds another command's results, which this one's files
/// (summary.json, report.html, …) would overwrite: a batch folder (`cohort.csv`) or a
/// summary.json that is not this command's (a fit's or a report's result set, or another
/// analysis). A folder of this command's own results is written over, as a re-run expects.
pub fn refuse_other_results(out: &Path, command: &str) -> Result<(), CliError> {
    let refuse = |what: &str| {
        CliError::Input(format!(
            "{}: holds {what}, which `medial {command}` would overwrite: give another --out",
            out.display()
        ))
    };
    if out.join("cohort.csv").is_file() {
        return Err(refuse("a `medial batch` folder's results (cohort.csv)"));
    }
    let Ok(bytes) = std::fs::read(out.join("summary.json")) else {
        return Ok(());
    };
    let written_by = serde_json::from_slice::<serde_json::Value>(&bytes)
        .ok()
        .and_then(|v| v.get("command").and_then(|c| c.as_str()).map(str::to_owned));
    match written_by {
        Some(c) if c == command => Ok(()),
        Some(c) => Err(refuse(&format!(
            "the results of `medial {c}` (summary.json)"
        ))),
        None => Err(refuse(
            "another command's results (summary.json, a fit's or a report's)",
        )),
    }
}

/// Whether a symbolic link can be made in `folder` (tried and removed).
fn makes_links(folder: &Path) -> bool {
    let probe = folder.join(format!(
        "{}probe-link.tmp",
        medial_io::atomic::temp_prefix()
    ));
    let made = symlink("probe", &probe).is_ok();
    let _ = std::fs::remove_file(&probe);
    made
}

impl Drop for ResultSet {
    /// Removes the staging folder: whatever was not moved in is dropped (best effort; the next
    /// run's [`clean`] removes what stays).
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// The folder of the generations of a result folder, under `DIR/` (canonical `root`).
const SETS: &str = ".medial-sets";

/// The link in [`SETS`] to the generation the result folder shows.
const CURRENT: &str = "current";

/// The test hook of [`before_each_step`].
static STEP_HOOK: std::sync::OnceLock<fn(usize)> = std::sync::OnceLock::new();

/// Calls `hook` with 1, 2, … before each file operation of a commit in this process (for the
/// kill-anywhere test, which kills its process at the n-th; the binary never sets one).
pub fn before_each_step(hook: fn(usize)) {
    let _ = STEP_HOOK.set(hook);
}

/// The file operations of a commit so far ([`before_each_step`]).
struct Steps(usize);

impl Steps {
    /// Counts the operation about to be made.
    fn next(&mut self) {
        self.0 += 1;
        if let Some(hook) = STEP_HOOK.get() {
            hook(self.0);
        }
    }
}

/// Removes from `dir` and its set sub-folders what interrupted runs leave: staging folders
/// (`.medial-staging-<pid>`) and the temporary files and links of the tool (`.medial-<pid>-…`:
/// those of atomic writes, [`medial_io::atomic::temp_owner`], of a commit's links, and the
/// unfinished `log.csv`, [`crate::progress::part_name`]) whose process no longer runs; in
/// `DIR/.medial-sets`, the temporary links only. Only regular files, links and folders of the
/// folder itself are removed (a symbolic link is never followed), and no other name: a user's
/// `*.part` or `.*.tmp` file stays. Refuses (`Busy`), before removing anything, when another
/// running process owns a staging folder there: its unfinished files are its own.
pub fn clean(dir: &Path) -> Result<(), CliError> {
    let folders = std::iter::once(dir.to_path_buf()).chain(
        SUBFOLDERS
            .iter()
            .chain(&[SETS])
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
    let staging = |name: &str, path: &Path, kind: &std::fs::FileType| {
        kind.is_dir()
            && path.parent() == Some(dir)
            && name
                .strip_prefix(STAGING_PREFIX)
                .is_some_and(|pid| pid.parse::<u32>().is_ok())
    };
    for (name, path, kind) in &entries {
        if staging(name, path, kind) {
            if let Some(pid) = writer_running(&name[STAGING_PREFIX.len()..]) {
                return Err(CliError::Busy {
                    dir: dir.into(),
                    pid,
                });
            }
        }
    }
    for (name, path, kind) in &entries {
        if staging(name, path, kind) {
            std::fs::remove_dir_all(path).map_err(|e| CliError::io(path, e))?;
        } else if kind.is_file() || kind.is_symlink() {
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

/// Checks the path of the set's file `relative` in `dir` (canonical `root`), its folders
/// created: refused with one line when it would leave the folder (a `..`, a root, or a folder
/// on its way that is a link), names the tool's own files (`.medial-…`), or holds something
/// else than a regular file or the tool's own link (a folder, another link, a device, a FIFO).
fn check_destination(root: &Path, dir: &Path, relative: &str) -> Result<(), CliError> {
    let path = dir.join(relative);
    let refuse = |what: &str| CliError::io(&path, std::io::Error::other(what.to_string()));
    if !is_relative_inside(relative) {
        return Err(refuse("not a path inside the output folder"));
    }
    let Some(parent) = path.parent() else {
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
    if !folder_is_real(root, relative) {
        return Err(refuse(&format!(
            "its folder is a symbolic link inside the output folder {}: refused to write there",
            dir.display()
        )));
    }
    match std::fs::symlink_metadata(root.join(relative)) {
        Ok(meta) if !meta.is_file() && !is_own_link(root, relative) => Err(refuse(
            "exists and is not a regular file (a folder, a symbolic link, a device or a FIFO): \
             refused to replace it; move it away or give another output folder",
        )),
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(CliError::io(&path, e)),
        _ => Ok(()),
    }
}

/// `DIR/.medial-sets` (canonical `root`), created: a folder, not a link.
fn sets_folder(root: &Path, dir: &Path) -> Result<PathBuf, CliError> {
    let sets = root.join(SETS);
    create_dir(&sets)?;
    match std::fs::symlink_metadata(&sets) {
        Ok(meta) if meta.is_dir() => Ok(sets),
        _ => Err(CliError::io(
            &dir.join(SETS),
            std::io::Error::other("is not a folder (a symbolic link?): refused to write there"),
        )),
    }
}

/// The generation `DIR/.medial-sets/current` leads to, when it is a link to a folder there.
fn current_generation(sets: &Path) -> Option<u64> {
    let text = std::fs::read_link(sets.join(CURRENT)).ok()?;
    let n = generation_number(text.to_str()?)?;
    let is_dir = std::fs::symlink_metadata(sets.join(text)).is_ok_and(|m| m.is_dir());
    is_dir.then_some(n)
}

/// The number of a generation folder's name (a number as the tool writes it: digits, no
/// leading zero).
fn generation_number(name: &str) -> Option<u64> {
    let n: u64 = name.parse().ok()?;
    (n.to_string() == name).then_some(n)
}

/// The generation folders in `sets` (folders, not links, named by digits).
fn generations(sets: &Path) -> Vec<u64> {
    let entries = std::fs::read_dir(sets).into_iter().flatten().flatten();
    entries
        .filter(|e| e.file_type().is_ok_and(|k| k.is_dir()))
        .filter_map(|e| generation_number(e.file_name().to_str()?))
        .collect()
}

/// A number above every generation's in `sets` (and above the current one's).
fn next_generation(sets: &Path) -> u64 {
    let highest = generations(sets)
        .into_iter()
        .chain(current_generation(sets))
        .max();
    highest.map_or(1, |n| n + 1)
}

/// Points `DIR/.medial-sets/current` at `generation`: a new link renamed over it (atomic).
fn switch(sets: &Path, generation: u64, steps: &mut Steps) -> Result<(), CliError> {
    let temp = sets.join(format!(
        "{}{CURRENT}-link.tmp",
        medial_io::atomic::temp_prefix()
    ));
    replace_by_link(&temp, &generation.to_string(), &sets.join(CURRENT), steps)?;
    sync_dir(sets);
    Ok(())
}

/// The text of the link `DIR/<relative>`: into the current generation, relative to its folder.
fn link_text(relative: &str) -> String {
    let depth = relative.matches('/').count();
    format!("{}{SETS}/{CURRENT}/{relative}", "../".repeat(depth))
}

/// Replaces `DIR/<relative>` (canonical `root`; its folders real) by its link
/// ([`link_text`]), in one rename.
fn make_link(root: &Path, relative: &str, steps: &mut Steps) -> Result<(), CliError> {
    let path = root.join(relative);
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let temp = path.with_file_name(format!(
        "{}{}-link.tmp",
        medial_io::atomic::temp_prefix(),
        name.replace('.', "_")
    ));
    replace_by_link(&temp, &link_text(relative), &path, steps)
}

/// Makes the link `temp` with `text` and renames it to `path`.
fn replace_by_link(
    temp: &Path,
    text: &str,
    path: &Path,
    steps: &mut Steps,
) -> Result<(), CliError> {
    if std::fs::symlink_metadata(temp).is_ok() {
        steps.next();
        remove_if_present(temp)?;
    }
    steps.next();
    symlink(text, temp).map_err(|e| CliError::io(temp, e))?;
    steps.next();
    std::fs::rename(temp, path).map_err(|e| CliError::io(path, e))
}

#[cfg(unix)]
fn symlink(text: &str, path: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(text, path)
}

#[cfg(not(unix))]
fn symlink(_: &str, _: &Path) -> std::io::Result<()> {
    Err(std::io::Error::other(
        "result folders need symbolic links (Unix)",
    ))
}

/// Puts the regular file `from` into a generation folder as `to`: a hard link (a copy where
/// the file system has none), replacing what is there.
fn adopt_file(from: &Path, to: &Path, steps: &mut Steps) -> Result<(), CliError> {
    if let Some(parent) = to.parent().filter(|p| !p.is_dir()) {
        steps.next();
        create_dir(parent)?;
    }
    if std::fs::symlink_metadata(to).is_ok() {
        steps.next();
        remove_if_present(to)?;
    }
    steps.next();
    if std::fs::hard_link(from, to).is_err() {
        std::fs::copy(from, to).map_err(|e| CliError::io(to, e))?;
        let copy = std::fs::File::open(to).and_then(|f| f.sync_all());
        copy.map_err(|e| CliError::io(to, e))?;
    }
    Ok(())
}

/// Removes the folder `path` (a generation of the tool's) file by file, links not followed.
fn remove_tree(path: &Path, steps: &mut Steps) -> Result<(), CliError> {
    let entries = std::fs::read_dir(path).map_err(|e| CliError::io(path, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| CliError::io(path, e))?;
        let kind = entry
            .file_type()
            .map_err(|e| CliError::io(&entry.path(), e))?;
        if kind.is_dir() {
            remove_tree(&entry.path(), steps)?;
        } else {
            steps.next();
            remove_if_present(&entry.path())?;
        }
    }
    steps.next();
    std::fs::remove_dir(path).map_err(|e| CliError::io(path, e))
}

/// Whether the folders on the way to `DIR/<relative>` (canonical `root`) are folders of the
/// result folder itself, no link among them.
fn folder_is_real(root: &Path, relative: &str) -> bool {
    let path = root.join(relative);
    path.parent()
        .and_then(|parent| std::fs::canonicalize(parent).ok().map(|c| c == parent))
        .unwrap_or(false)
}

/// A path of the set's kind: inside the folder by its text and not in the tool's own
/// namespace (`.medial-…`).
fn is_set_path(relative: &str) -> bool {
    is_relative_inside(relative)
        && Path::new(relative)
            .components()
            .all(|c| !c.as_os_str().to_string_lossy().starts_with(TOOL_NAMESPACE))
}

/// Whether `DIR/<relative>` is a regular file inside the output folder (by place: its folders
/// real, no link on the way), not of the tool's namespace.
fn is_plain_file(root: &Path, relative: &str) -> bool {
    is_set_path(relative)
        && folder_is_real(root, relative)
        && std::fs::symlink_metadata(root.join(relative)).is_ok_and(|m| m.is_file())
}

/// Whether `DIR/<relative>` is the tool's own link: in a real folder of the output folder, its
/// text exactly [`link_text`].
fn is_own_link(root: &Path, relative: &str) -> bool {
    is_set_path(relative)
        && folder_is_real(root, relative)
        && std::fs::read_link(root.join(relative))
            .is_ok_and(|text| text.as_os_str() == link_text(relative).as_str())
}

/// The relative paths of the links in `DIR` and its set sub-folders (canonical `root`).
fn links_in(root: &Path) -> Vec<String> {
    let mut links = Vec::new();
    for prefix in std::iter::once("").chain(SUBFOLDERS) {
        let folder = root.join(prefix);
        for entry in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
            if entry.file_type().is_ok_and(|k| k.is_symlink()) {
                let name = entry.file_name().to_string_lossy().into_owned();
                links.push(match prefix {
                    "" => name,
                    sub => format!("{sub}/{name}"),
                });
            }
        }
    }
    links
}

/// The `files` a marker lists (empty when it is missing or lists none).
pub fn listed_files(marker: &Path) -> Vec<String> {
    std::fs::read(marker)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<Listing>(&bytes).ok())
        .map_or_else(Vec::new, |l| l.files)
}

/// A relative path that stays inside the result folder by its text (no root, no `..`; the
/// folders on its way are checked apart, [`folder_is_real`]).
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

    /// The entries of `dir` and `dir/flow`, but the generations' folder.
    fn names(dir: &Path) -> Vec<String> {
        let mut all = Vec::new();
        for folder in [dir.to_path_buf(), dir.join("flow")] {
            for e in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
                if e.file_name() == SETS {
                    continue;
                }
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
        set.commit("summary.json", |path, listing| {
            let text = serde_json::json!({ "files": listing.files }).to_string();
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
        // The layout: links into the one generation left.
        let sets = d.join(SETS);
        assert_eq!(generations(&sets), [current_generation(&sets).unwrap()]);
        for (file, text) in [
            ("a.txt", ".medial-sets/current/a.txt"),
            ("flow/t0.vtk", "../.medial-sets/current/flow/t0.vtk"),
            ("summary.json", ".medial-sets/current/summary.json"),
        ] {
            assert_eq!(std::fs::read_link(d.join(file)).unwrap(), Path::new(text));
        }
        assert!(std::fs::symlink_metadata(d.join("mine.txt"))
            .unwrap()
            .is_file());
    }

    /// A folder of the layout before generations (regular files), and regular files at the
    /// set's paths, are taken over: the new set replaces them, the earlier one's stale files go.
    #[test]
    fn a_set_of_regular_files_is_replaced_and_its_stale_files_go() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir_all(d.join("flow")).unwrap();
        for (file, text) in [("a.txt", "1"), ("flow/t0.vtk", "1"), ("flow/t1.vtk", "1")] {
            std::fs::write(d.join(file), text).unwrap();
        }
        std::fs::write(
            d.join("summary.json"),
            r#"{"files":["a.txt","flow/t0.vtk","flow/t1.vtk"]}"#,
        )
        .unwrap();
        std::fs::write(d.join("checkpoint.bin"), "periodic").unwrap();
        let mut set = ResultSet::begin(d).unwrap();
        std::fs::write(set.file("a.txt").unwrap(), "2").unwrap();
        std::fs::write(set.file("b.txt").unwrap(), "2").unwrap();
        set.retire("checkpoint.bin");
        set.commit("summary.json", |path, listing| {
            let text = serde_json::json!({ "files": listing.files }).to_string();
            std::fs::write(path, text).map_err(|e| CliError::io(path, e))
        })
        .unwrap();
        assert_eq!(names(d), ["a.txt", "b.txt", "flow", "summary.json"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "2");
        assert!(std::fs::symlink_metadata(d.join("a.txt"))
            .unwrap()
            .is_symlink());
        assert_eq!(generations(&d.join(SETS)).len(), 1);
    }

    /// A link at a path of the set that is not the tool's own is refused, and stays.
    #[test]
    fn another_link_at_a_path_of_the_set_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_set(d, &[("a.txt", "1")]);
        std::fs::remove_file(d.join("a.txt")).unwrap();
        std::os::unix::fs::symlink("summary.json", d.join("a.txt")).unwrap();
        let mut set = ResultSet::begin(d).unwrap();
        std::fs::write(set.file("a.txt").unwrap(), "2").unwrap();
        let error = set
            .commit("summary.json", |path, _| {
                std::fs::write(path, "{}").map_err(|e| CliError::io(path, e))
            })
            .unwrap_err()
            .to_string();
        assert!(error.contains("a.txt") && error.contains("not a regular file"));
        assert_eq!(
            std::fs::read_link(d.join("a.txt")).unwrap(),
            Path::new("summary.json")
        );
    }

    #[test]
    fn generations_are_named_by_numbers_as_the_tool_writes_them() {
        assert_eq!(generation_number("7"), Some(7));
        assert_eq!(generation_number("10"), Some(10));
        for name in [
            "",
            "007",
            "+7",
            "-1",
            "7a",
            "current",
            "99999999999999999999999",
        ] {
            assert_eq!(generation_number(name), None, "{name}");
        }
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

    /// Writes a set whose marker records the files' digests, through `commit` or, where `plain`,
    /// the commit of a file system without symbolic links.
    fn write_checked_set(dir: &Path, files: &[(&str, &str)], plain: bool) {
        let mut set = ResultSet::begin(dir).unwrap();
        for (name, text) in files {
            std::fs::write(set.file(name).unwrap(), text).unwrap();
        }
        let marker = |path: &Path, listing: Listing| {
            let text = serde_json::json!({ "files": listing.files, "sha256": listing.sha256 });
            std::fs::write(path, text.to_string()).map_err(|e| CliError::io(path, e))
        };
        if plain {
            let listing = Listing::of(&set.staging, set.files()).unwrap();
            marker(&set.file("summary.json").unwrap(), listing).unwrap();
            let root = canonical(dir).unwrap();
            set.commit_plain(&root, "summary.json").unwrap();
        } else {
            set.commit("summary.json", marker).unwrap();
        }
    }

    #[test]
    fn a_damaged_or_missing_file_of_a_set_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_checked_set(d, &[("a.txt", "1"), ("flow/t0.vtk", "vtk")], false);
        verify(d, "summary.json", |_| false).unwrap();
        // Written through its link: the generation's file changes.
        std::fs::write(d.join("flow/t0.vtk"), "vtK").unwrap();
        let e = verify(d, "summary.json", |_| false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("t0.vtk") && e.contains("SHA-256"), "{e}");
        std::fs::write(d.join("flow/t0.vtk"), "vtk").unwrap();
        verify(d, "summary.json", |_| false).unwrap();
        std::fs::remove_file(d.join(".medial-sets/current/a.txt")).unwrap();
        let e = verify(d, "summary.json", |_| false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.txt") && e.contains("missing"), "{e}");
        // A marker of an earlier version (no digests) is taken as it is.
        std::fs::write(d.join("old.json"), r#"{"files":["gone.txt"]}"#).unwrap();
        verify(d, "old.json", |_| false).unwrap();
    }

    /// Without symbolic links the set is moved in file by file: the folder holds regular files
    /// only, the earlier set's stale files go, a user's file stays, and a later commit with
    /// links takes the folder over.
    #[test]
    fn a_set_is_moved_in_file_by_file_where_no_link_can_be_made() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_checked_set(
            d,
            &[("a.txt", "1"), ("b.txt", "1"), ("flow/t0.vtk", "1")],
            true,
        );
        std::fs::write(d.join("mine.txt"), "not of a set").unwrap();
        write_checked_set(d, &[("a.txt", "2"), ("c.txt", "2")], true);
        assert_eq!(
            names(d),
            ["a.txt", "c.txt", "flow", "mine.txt", "summary.json"]
        );
        for name in ["a.txt", "c.txt", "summary.json"] {
            let meta = std::fs::symlink_metadata(d.join(name)).unwrap();
            assert!(meta.is_file(), "{name}");
        }
        assert!(!d.join(SETS).exists());
        verify(d, "summary.json", |_| false).unwrap();
        write_checked_set(d, &[("a.txt", "3")], false);
        assert_eq!(names(d), ["a.txt", "flow", "mine.txt", "summary.json"]);
        assert_eq!(std::fs::read_to_string(d.join("a.txt")).unwrap(), "3");
        verify(d, "summary.json", |_| false).unwrap();
    }

    /// A set made from the one shown (`medial report`): the carried files keep their bytes,
    /// the new one joins, and the earlier generation goes.
    #[test]
    fn files_carried_into_a_new_set_keep_their_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        write_checked_set(d, &[("a.txt", "1"), ("flow/t0.vtk", "vtk")], false);
        let mut set = ResultSet::begin(d).unwrap();
        for relative in listed_files(&d.join("summary.json")) {
            set.carry(&relative).unwrap();
        }
        std::fs::write(set.file("report.html").unwrap(), "<html>").unwrap();
        set.commit("summary.json", |path, listing| {
            let text = serde_json::json!({ "files": listing.files, "sha256": listing.sha256 });
            std::fs::write(path, text.to_string()).map_err(|e| CliError::io(path, e))
        })
        .unwrap();
        assert_eq!(
            names(d),
            [
                "a.txt",
                "flow",
                "flow/t0.vtk",
                "report.html",
                "summary.json"
            ]
        );
        assert_eq!(
            std::fs::read_to_string(d.join("flow/t0.vtk")).unwrap(),
            "vtk"
        );
        assert_eq!(generations(&d.join(SETS)).len(), 1);
        verify(d, "summary.json", |_| false).unwrap();
        // Only the tool's files are carried.
        std::fs::write(d.join("mine.txt"), "x").unwrap();
        let mut set = ResultSet::begin(d).unwrap();
        std::os::unix::fs::symlink("/etc/hostname", d.join("other")).unwrap();
        assert!(set.carry("other").is_err());
        set.carry("mine.txt").unwrap();
    }
}
