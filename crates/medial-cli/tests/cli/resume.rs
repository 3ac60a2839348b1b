//! Fits that are stopped and resumed, through the built binary: real SIGTERM / SIGINT / SIGKILL
//! sent to a running `medial fit` once its `log.csv.part` has a given number of rows, the results
//! as a set (`summary.json` lists them; no leftovers), and `--resume` ending with the bytes of
//! a fit that was never stopped.
//!
//! The fits are the shipped toy shortened (N = 6, three stages: SSD towards the affine part,
//! Dice over three AL iterations, constrained SSD to the warped points, its tolerances wide
//! so that the fit ends with exit code 0), a second or two each.

use crate::common::{one_line_error, s, text};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// A file of the shipped toy case.
fn toy(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/toy")
        .join(name)
}

/// The three stages of the resume tests.
fn three_stages() -> String {
    format!(
        r#"
[[stage]]
name = "affine"
attachment = "ssd"
transform = "{}"
mu = 20.0
max_iterations = 40

[[stage]]
name = "dice"
attachment = "dice"
image = "{}"
mu = 0.02
al_iterations = 3
max_iterations = 25

[[stage]]
name = "points"
attachment = "ssd"
target = "{}"
mu = 2.0
al_iterations = 2
max_iterations = 25
tolerance_deg = 90.0
tolerance_pct = 100.0
"#,
        toy("affine.txt").display(),
        toy("target.nii.gz").display(),
        toy("target_boundary.vtk").display()
    )
}

/// One short SSD stage without constraints.
fn one_stage() -> String {
    format!(
        "[[stage]]\nname = \"affine\"\nattachment = \"ssd\"\ntransform = \"{}\"\n\
         constraints = false\nmax_iterations = 15\n",
        toy("affine.txt").display()
    )
}

/// Writes `dir/fit.toml`: the toy template, `time_steps` steps, `stages`.
fn write_config(dir: &Path, time_steps: usize, stages: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let config = format!(
        "[model]\ntemplate = \"{}\"\n[flow]\nsigma = 2.0\ntime_steps = {time_steps}\n\
         kinetic_weight = 0.005\n{stages}",
        toy("template.vtk").display()
    );
    let path = dir.join("fit.toml");
    std::fs::write(&path, config).unwrap();
    path
}

/// Starts `medial fit ARGS -q` (with `--threads 2` unless ARGS name the threads).
fn spawn(args: &[&str]) -> Child {
    let threads: &[&str] = if args.contains(&"--threads") {
        &[]
    } else {
        &["--threads", "2"]
    };
    Command::new(env!("CARGO_BIN_EXE_medial"))
        .args(["fit", "-q"])
        .args(threads)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary starts")
}

/// Runs `medial fit ARGS` to its end and asserts success.
fn fit(args: &[&str]) {
    let o = spawn(args).wait_with_output().unwrap();
    assert!(o.status.success(), "fit {args:?}: {}", text(&o.stderr));
}

/// The running fit's log in `dir`, `.medial-<pid>-<n>-log.csv.part` (its `log.csv` as it goes).
fn log_part(dir: &Path) -> Option<PathBuf> {
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            let name = p.file_name().unwrap_or_default().to_string_lossy();
            name.starts_with(".medial-") && name.ends_with("-log.csv.part")
        })
}

/// Rows of the running fit's log in `dir` (0 before it exists).
fn rows(dir: &Path) -> usize {
    log_part(dir)
        .and_then(|p| std::fs::read_to_string(p).ok())
        .map(|t| t.lines().count().saturating_sub(1))
        .unwrap_or(0)
}

/// Sends `signal` (TERM, INT, KILL) to `child` once `ready` holds, and waits for its end.
fn signal_when(mut child: Child, signal: &str, ready: impl Fn() -> bool) -> Output {
    let start = Instant::now();
    while !ready() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the fit ended before the signal"
        );
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "the fit never got there"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let pid = child.id().to_string();
    let sent = Command::new("kill").args(["-s", signal, &pid]).status();
    assert!(sent.unwrap().success(), "kill -s {signal} {pid}");
    child.wait_with_output().unwrap()
}

/// Starts `medial fit CONFIG --out OUT ARGS…` and sends `signal` once its log has `at` rows.
fn stop_at(config: &Path, out: &Path, at: usize, signal: &str, args: &[&str]) -> Output {
    let mut all = vec![s(config), "--out", s(out)];
    all.extend(args);
    signal_when(spawn(&all), signal, || rows(out) >= at)
}

/// Every file under `dir` (links followed, the generations' folder `.medial-sets` left out),
/// as sorted relative paths.
fn files(dir: &Path) -> Vec<String> {
    let mut all = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.file_name().is_some_and(|n| n == ".medial-sets") {
                continue;
            }
            if path.is_dir() {
                folders.push(path);
            } else {
                let rel = path.strip_prefix(dir).unwrap();
                all.push(rel.to_string_lossy().into_owned());
            }
        }
    }
    all.sort();
    all
}

fn summary(dir: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap()
}

/// Asserts that `dir` holds exactly one set: `summary.json` and the files it lists, nothing
/// else (no staging folder, temporary or `.part` file); returns the summary.
fn complete_set(dir: &Path) -> Value {
    let summary = summary(dir);
    let mut listed: Vec<String> = summary["files"]
        .as_array()
        .expect("summary.json lists its files")
        .iter()
        .map(|f| f.as_str().unwrap().to_owned())
        .collect();
    listed.push("summary.json".into());
    listed.sort();
    // The views (report.html, flow.glb, the ParaView series) belong to the set.
    for view in ["report.html", "flow.glb", "flow/boundary.vtk.series"] {
        assert!(listed.iter().any(|f| f == view), "{view} not listed");
    }
    assert_eq!(files(dir), listed, "{}", dir.display());
    // Of one generation, which the set's links lead into (decision 0300).
    let sets = std::fs::read_dir(dir.join(".medial-sets")).unwrap().count();
    assert_eq!(sets, 2, "one generation and `current`");
    for file in &listed {
        let link = std::fs::read_link(dir.join(file)).unwrap();
        assert!(
            link.to_string_lossy().contains(".medial-sets/current/"),
            "{link:?}"
        );
    }
    summary
}

/// `v` without its timings (every `seconds`) and the number of threads it ran on.
fn without_seconds(mut v: Value) -> Value {
    match &mut v {
        Value::Object(map) => {
            map.remove("seconds");
            map.remove("threads");
            // The digests cover log.csv and the report, which hold timings.
            map.remove("sha256");
            for value in map.values_mut() {
                *value = without_seconds(value.take());
            }
        }
        Value::Array(items) => {
            for item in items {
                *item = without_seconds(item.take());
            }
        }
        _ => {}
    }
    v
}

/// `log.csv` without its `seconds` column.
fn log_without_seconds(dir: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("log.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let seconds = header.iter().position(|h| *h == "seconds").unwrap();
    text.lines()
        .map(|line| {
            let mut fields: Vec<&str> = line.split(',').collect();
            fields.remove(seconds);
            fields.join(",")
        })
        .collect()
}

/// The uninterrupted fit of the three-stage config (run once per test process).
struct Baseline {
    config: PathBuf,
    out: PathBuf,
    /// `(stage, al_iteration)` of each row of its log.
    rows: Vec<(String, usize)>,
}

impl Baseline {
    fn get() -> &'static Baseline {
        static BASELINE: OnceLock<Baseline> = OnceLock::new();
        BASELINE.get_or_init(|| {
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli_resume_baseline");
            let _ = std::fs::remove_dir_all(&dir);
            let config = write_config(&dir, 6, &three_stages());
            let out = dir.join("out");
            fit(&[s(&config), "--out", s(&out)]);
            let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
            let rows = log
                .lines()
                .skip(1)
                .map(|l| {
                    let f: Vec<&str> = l.split(',').collect();
                    (f[0].to_owned(), f[1].parse().unwrap())
                })
                .collect();
            Baseline { config, out, rows }
        })
    }

    /// The row `offset` rows after the first of `stage`'s AL iteration `al`.
    fn row(&self, stage: &str, al: usize, offset: usize) -> usize {
        let first = self.rows.iter().position(|(s, a)| s == stage && *a == al);
        first.expect("the stage and AL iteration ran") + offset
    }

    /// Asserts that the fit in `out` ended with the baseline's bits: momenta.npy and lambda.npy
    /// byte for byte, summary.json and log.csv except timings.
    fn assert_same(&self, out: &Path) {
        for file in [
            "momenta.npy",
            "lambda.npy",
            "time_points.csv",
            "fitted_template.vtk",
        ] {
            let (a, b) = (self.out.join(file), out.join(file));
            assert!(
                std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
                "{file} differs from the uninterrupted fit's"
            );
        }
        assert_eq!(
            without_seconds(summary(out)),
            without_seconds(summary(&self.out))
        );
        assert_eq!(log_without_seconds(out), log_without_seconds(&self.out));
    }
}

/// Asserts that `o` is the end of a fit stopped by a signal: exit `code`, one line saying so,
/// and an interrupted set with its checkpoint.
fn assert_interrupted(o: &Output, code: i32, out: &Path) -> Value {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "{err}");
    let line = err.lines().last().unwrap_or_default();
    assert!(line.starts_with("error: interrupted by SIG"), "{err}");
    assert!(line.contains("--resume"), "{line}");
    let summary = complete_set(out);
    assert_eq!(summary["status"], "interrupted");
    let files = summary["files"].as_array().unwrap();
    for name in ["checkpoint.bin", "log.csv", "momenta.npy", "config.toml"] {
        assert!(files.iter().any(|f| f == name), "{name} not in {files:?}");
    }
    let stages = summary["stages"].as_array().unwrap();
    let stops = stages.last().unwrap()["stop"].as_array().unwrap();
    assert_eq!(stops.last().unwrap(), "paused at a checkpoint");
    summary
}

#[test]
fn a_fit_stopped_by_a_signal_and_resumed_ends_with_the_same_bits() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    // Early in the first stage; in the Dice stage's second AL iteration; in the third stage.
    let points = [
        (5, "TERM", 143, "affine"),
        (base.row("dice", 1, 8), "INT", 130, "dice"),
        (base.row("points", 0, 8), "TERM", 143, "points"),
    ];
    for (i, (at, signal, code, stage)) in points.into_iter().enumerate() {
        let out = dir.path().join(format!("out{i}"));
        let o = stop_at(&base.config, &out, at, signal, &[]);
        let summary = assert_interrupted(&o, code, &out);
        let last = summary["stages"].as_array().unwrap().last().unwrap();
        assert_eq!(last["name"], stage, "stopped at row {at}");
        // Without the config, --resume reads DIR/config.toml; the reductions do not depend on
        // the number of threads, so a resume on one thread ends with the same bits.
        match i {
            1 => fit(&["--resume", s(&out)]),
            2 => fit(&[s(&base.config), "--resume", s(&out), "--threads", "1"]),
            _ => fit(&[s(&base.config), "--resume", s(&out)]),
        }
        complete_set(&out);
        base.assert_same(&out);
    }
}

#[test]
fn a_second_signal_while_stopping_corrupts_nothing() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let child = spawn(&[s(&base.config), "--out", s(&out)]);
    let pid = child.id().to_string();
    let o = signal_when(child, "TERM", || {
        let ready = rows(&out) >= base.row("dice", 0, 5);
        if ready {
            // A first SIGTERM now, the second (from signal_when) right after it.
            let _ = Command::new("kill").args(["-s", "TERM", &pid]).status();
        }
        ready
    });
    assert_interrupted(&o, 143, &out);
    fit(&["--resume", s(&out)]);
    complete_set(&out);
    base.assert_same(&out);
}

#[test]
fn periodic_checkpoints_do_not_change_the_bits_and_survive_a_hard_kill() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let args = [
        s(&base.config),
        "--out",
        s(&out),
        "--checkpoint-every",
        "0.2",
    ];
    let checkpoint = out.join("checkpoint.bin");
    let o = signal_when(spawn(&args), "KILL", || {
        checkpoint.exists() && rows(&out) >= base.row("dice", 1, 0)
    });
    assert_eq!(o.status.code(), None, "killed");
    assert!(log_part(&out).is_some());
    assert!(!out.join("summary.json").exists(), "no set was written");
    // Resumed with checkpoints at every few iterations: each is a pause and a resume in the
    // running process, which must not change a bit either.
    fit(&[
        s(&base.config),
        "--resume",
        s(&out),
        "--checkpoint-every",
        "0.01",
    ]);
    complete_set(&out);
    assert!(!checkpoint.exists(), "a completed fit leaves no checkpoint");
    base.assert_same(&out);
}

#[test]
fn a_second_fit_into_a_folder_being_written_is_refused() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let child = spawn(&[s(&base.config), "--out", s(&out)]);
    let o = signal_when(child, "TERM", || {
        if rows(&out) < 3 {
            return false;
        }
        let second = spawn(&[s(&base.config), "--out", s(&out)])
            .wait_with_output()
            .unwrap();
        assert_eq!(second.status.code(), Some(1));
        let err = text(&second.stderr);
        assert!(
            err.starts_with("error: ") && err.trim_end().lines().count() == 1,
            "{err}"
        );
        assert!(err.contains("another medial process"), "{err}");
        true
    });
    // The first fit was not disturbed: it stops on the signal with its checkpoint.
    assert_interrupted(&o, 143, &out);
}

#[test]
fn a_completed_fit_replaces_the_earlier_set_and_cleans_what_interrupted_runs_left() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let long = write_config(&dir.path().join("long"), 8, &one_stage());
    fit(&[s(&long), "--out", s(&out)]);
    assert_eq!(complete_set(&out)["time_steps"], 8);
    assert!(out.join("flow/boundary_t008.vtk").exists());
    // What a killed run leaves.
    std::fs::create_dir_all(out.join(".medial-staging-1/flow")).unwrap();
    std::fs::write(out.join(".medial-staging-1/flow/boundary_t000.vtk"), "x").unwrap();
    std::fs::write(out.join(".medial-4194305-momenta_npy-Ab12Cd.tmp"), "x").unwrap();
    std::fs::write(
        out.join("flow/.medial-4194305-boundary_t003_vtk-Xy98Zw.tmp"),
        "x",
    )
    .unwrap();
    std::fs::write(out.join(".medial-4194305-log.csv.part"), "x").unwrap();
    let short = write_config(&dir.path().join("short"), 5, &one_stage());
    fit(&[s(&short), "--out", s(&out)]);
    let summary = complete_set(&out);
    assert_eq!(summary["time_steps"], 5);
    assert_eq!(summary["status"], "budget");
    let flow: Vec<String> = files(&out)
        .into_iter()
        .filter(|f| f.starts_with("flow/") && f.ends_with(".vtk"))
        .collect();
    assert_eq!(flow.len(), 12, "boundary and medial at t = 0 … 5: {flow:?}");
}

#[test]
fn a_killed_fit_leaves_the_earlier_set_byte_identical() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let short = write_config(&dir.path().join("short"), 5, &one_stage());
    fit(&[s(&short), "--out", s(&out)]);
    let before: Vec<(String, Vec<u8>)> = files(&out)
        .into_iter()
        .map(|f| (f.clone(), std::fs::read(out.join(&f)).unwrap()))
        .collect();
    let o = stop_at(&base.config, &out, 20, "KILL", &[]);
    assert_eq!(o.status.code(), None, "killed");
    for (name, bytes) in &before {
        assert!(
            std::fs::read(out.join(name)).unwrap() == *bytes,
            "{name} changed"
        );
    }
    // The killed run's leftovers, removed by the next run.
    assert!(log_part(&out).is_some());
    fit(&[s(&short), "--out", s(&out)]);
    complete_set(&out);
}

#[test]
fn a_resume_with_another_config_or_input_is_refused() {
    let base = Baseline::get();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = stop_at(&base.config, &out, 10, "TERM", &[]);
    assert_interrupted(&o, 143, &out);
    let checkpoint = std::fs::read(out.join("checkpoint.bin")).unwrap();
    let config_text = std::fs::read_to_string(&base.config).unwrap();
    // Another setting.
    let other = dir.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    let edited = other.join("fit.toml");
    std::fs::write(
        &edited,
        config_text.replace("kinetic_weight = 0.005", "kinetic_weight = 0.006"),
    )
    .unwrap();
    one_line_error(
        &["fit", s(&edited), "--resume", s(&out)],
        1,
        &["checkpoint.bin", "the config differs"],
    );
    // Another transform file (the same name elsewhere, one number changed).
    let affine = std::fs::read_to_string(toy("affine.txt")).unwrap();
    let moved = other.join("affine.txt");
    std::fs::write(&moved, affine.replacen('1', "2", 1)).unwrap();
    let toy_affine = toy("affine.txt").display().to_string();
    std::fs::write(
        &edited,
        config_text.replace(&toy_affine, &moved.display().to_string()),
    )
    .unwrap();
    one_line_error(
        &["fit", s(&edited), "--resume", s(&out)],
        1,
        &["stage 'affine' transform differs"],
    );
    // A checkpoint of an earlier format (the 4 bytes after the magic).
    let mut earlier = checkpoint.clone();
    earlier[8..12].copy_from_slice(&2u32.to_le_bytes());
    std::fs::write(out.join("checkpoint.bin"), &earlier).unwrap();
    one_line_error(
        &["fit", s(&base.config), "--resume", s(&out)],
        1,
        &["checkpoint format 2 is not this medial's"],
    );
    // A damaged checkpoint, and none.
    std::fs::write(
        out.join("checkpoint.bin"),
        &checkpoint[..checkpoint.len() / 2],
    )
    .unwrap();
    one_line_error(
        &["fit", s(&base.config), "--resume", s(&out)],
        1,
        &["damaged checkpoint"],
    );
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    one_line_error(
        &["fit", s(&base.config), "--resume", s(&empty)],
        1,
        &["no checkpoint"],
    );
    // The same files elsewhere are the same fit.
    std::fs::write(out.join("checkpoint.bin"), &checkpoint).unwrap();
    std::fs::copy(toy("affine.txt"), &moved).unwrap();
    fit(&[s(&edited), "--resume", s(&out)]);
    base.assert_same(&out);
}

/// An automatic fit (no config) killed after a periodic checkpoint, before it wrote any result:
/// its folder holds the checkpoint alone, no `config.toml`, and its start (the aligned template)
/// exists only in memory. Resumed with the flags it was started with, it chooses the same start
/// and ends with the bytes of the fit never stopped. (Before, the first periodic checkpoint of
/// such a fit failed: its fingerprint read the aligned template from a folder that had none.)
#[test]
fn an_automatic_fit_killed_after_a_checkpoint_resumes_from_its_flags_to_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let (template, image) = (toy("template.vtk"), toy("target.nii.gz"));
    let flags = ["--template", s(&template), "--image", s(&image)];
    let whole = dir.path().join("whole");
    fit(&[&flags[..], &["--out", s(&whole)]].concat());
    let out = dir.path().join("out");
    let checkpoint = out.join("checkpoint.bin");
    let args = [&flags[..], &["--out", s(&out), "--checkpoint-every", "0.2"]].concat();
    let o = signal_when(spawn(&args), "KILL", || {
        checkpoint.exists() && rows(&out) >= 40
    });
    assert_eq!(o.status.code(), None, "killed");
    assert!(!out.join("config.toml").exists() && !out.join("summary.json").exists());
    fit(&[&flags[..], &["--resume", s(&out)]].concat());
    complete_set(&out);
    assert!(!checkpoint.exists(), "a completed fit leaves no checkpoint");
    for file in ["momenta.npy", "aligned_template.vtk", "fitted_template.vtk"] {
        let read = |d: &Path| std::fs::read(d.join(file)).unwrap();
        assert!(read(&out) == read(&whole), "{file} differs");
    }
}
