//! Reliability and security regressions (issue 33): no shell injection through generated
//! scripts, no deletion outside the output folder or of the user's files, outputs only as
//! regular files, damaged checkpoints refused, no hang, meaningless results never exit 0, and
//! a commit that a SIGKILL at any instant leaves with the old or the new set whole.

use crate::common::{one_line_error, s, text};
use std::path::{Path, PathBuf};
use std::process::Command;

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");

/// Runs the binary under test (`MEDIAL_UNDER_TEST` names another one, e.g. a build from
/// before a fix, to see a regression test fail) with `args`.
fn medial(args: &[&str]) -> std::process::Output {
    binary().args(args).output().expect("the binary runs")
}

/// The command of the binary under test.
fn binary() -> Command {
    Command::new(
        std::env::var_os("MEDIAL_UNDER_TEST").unwrap_or(env!("CARGO_BIN_EXE_medial").into()),
    )
}

/// A short SSD fit of the shipped toy to itself bent by 10° (`medial synth --from`, written
/// into `dir`), a second or two, as a config in `dir`.
fn quick_config(dir: &Path) -> PathBuf {
    let bent = dir.join("bent");
    let o = medial(&[
        "synth",
        "--from",
        s(&toy("template.vtk")),
        "--bend",
        "10",
        "--spacing",
        "1",
        "--out",
        s(&bent),
    ]);
    assert!(o.status.success(), "synth: {}", text(&o.stderr));
    let path = dir.join("quick.toml");
    let text = format!(
        "[model]\ntemplate = {:?}\n\n[flow]\nsigma = 2.0\ntime_steps = 5\nkinetic_weight = 0.005\n\n\
         [output]\nevery_time_point = false\n\n[[stage]]\nname = \"ssd\"\nattachment = \"ssd\"\n\
         target = {:?}\nmu = 20.0\nal_iterations = 1\nmax_iterations = 15\n\
         tolerance_deg = 90.0\ntolerance_pct = 100.0\n",
        s(&toy("template.vtk")),
        s(&bent.join("target_boundary.vtk")),
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs `medial fit CONFIG --out OUT` and asserts success.
fn fit(config: &Path, out: &Path) {
    let o = medial(&["fit", s(config), "--out", s(out), "--quiet"]);
    assert!(o.status.success(), "fit: {}", text(&o.stderr));
}

fn toy(name: &str) -> PathBuf {
    Path::new(EXAMPLES).join("toy").join(name)
}

/// Writes an executable shell script `name` into `dir`.
fn script(dir: &Path, name: &str, body: &str) -> PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// Item 1: the Slurm scripts of a cohort folder whose path holds `$(…)` and backticks run
/// (with a fake `sbatch` and a fake `medial`) without executing them.
#[test]
fn slurm_scripts_never_execute_the_output_path() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin = d.join("bin");
    std::fs::create_dir(&bin).unwrap();
    script(&bin, "sbatch", "echo 42\n");
    let fake_medial = script(&bin, "fake-medial", "exit 0\n");
    let csv = d.join("subjects.csv");
    std::fs::write(
        &csv,
        format!("subject,target\na,{}\n", s(&toy("target_boundary.vtk"))),
    )
    .unwrap();
    for hostile in [
        "DIR$(touch${IFS}pwned1)",
        "DIR`touch${IFS}pwned2`",
        "DIR';touch${IFS}pwned3;'",
        "DIR\\$(touch${IFS}pwned4)",
    ] {
        let out = d.join(hostile);
        let o = medial(&[
            "batch",
            s(&toy("template.vtk")),
            s(&csv),
            "--out",
            s(&out),
            "--slurm",
        ]);
        assert!(o.status.success(), "{hostile}: {}", text(&o.stderr));
        let path = format!("{}:{}", s(&bin), std::env::var("PATH").unwrap_or_default());
        for (shell, name) in [
            ("sh", "submit.sh"),
            ("bash", "batch.sbatch"),
            ("bash", "gather.sbatch"),
        ] {
            let o = Command::new(shell)
                .arg(out.join(name))
                .current_dir(d)
                .env("PATH", &path)
                .env("MEDIAL", &fake_medial)
                .env("SLURM_CPUS_PER_TASK", "1")
                .output()
                .unwrap();
            assert!(o.status.success(), "{hostile} {name}: {}", text(&o.stderr));
            if name == "submit.sh" {
                let printed = text(&o.stdout);
                assert!(
                    printed.contains(&format!("results: {}/cohort.csv", s(&out))),
                    "{hostile}: {printed}"
                );
            }
        }
        for n in 1..=4 {
            assert!(!d.join(format!("pwned{n}")).exists(), "{hostile}: executed");
        }
    }
}

/// Items 2 and 9: a fit into a folder whose earlier `summary.json` lists a file behind a
/// link, beside the user's `*.part` and `.*.tmp` files (in the folder and in `flow/`), removes
/// none of them.
#[test]
fn a_fit_removes_nothing_behind_a_link_nor_the_users_part_and_tmp_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (out, elsewhere) = (d.join("out"), d.join("elsewhere"));
    std::fs::create_dir_all(out.join("flow")).unwrap();
    std::fs::create_dir_all(&elsewhere).unwrap();
    std::fs::write(elsewhere.join("precious.txt"), "keep").unwrap();
    std::os::unix::fs::symlink(&elsewhere, out.join("lnk")).unwrap();
    std::fs::write(
        out.join("summary.json"),
        r#"{"files":["lnk/precious.txt"]}"#,
    )
    .unwrap();
    let users = [
        "notes.part",
        ".draft.tmp",
        "flow/mine.part",
        "flow/.x.tmp",
        "log.csv.part",
    ];
    for name in users {
        std::fs::write(out.join(name), "mine").unwrap();
    }
    fit(&quick_config(d), &out);
    assert!(
        elsewhere.join("precious.txt").exists(),
        "deleted through the link"
    );
    for name in users {
        assert!(out.join(name).exists(), "{name} was deleted");
    }
}

/// Item 9: a batch subject named like a folder of the user's beside the outputs is refused
/// before any fit; nothing in that folder changes.
#[test]
fn a_batch_never_writes_into_a_folder_that_is_not_a_result_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("cohort");
    std::fs::create_dir_all(out.join("images")).unwrap();
    std::fs::write(out.join("images/scan.part"), "mine").unwrap();
    let csv = d.join("subjects.csv");
    let target = toy("target_boundary.vtk");
    std::fs::write(
        &csv,
        format!("subject,target\na,{0}\nimages,{0}\n", s(&target)),
    )
    .unwrap();
    let o = medial(&[
        "batch",
        s(&toy("template.vtk")),
        s(&csv),
        "--out",
        s(&out),
        "--config",
        s(&quick_config(d)),
    ]);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("subject 'images'") && err.contains("no fit wrote"),
        "{err}"
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        !out.join("a").exists(),
        "a subject was fitted before the refusal"
    );
    let names: Vec<_> = std::fs::read_dir(out.join("images"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(names, ["scan.part"]);
}

/// Makes a FIFO at `path`.
fn mkfifo(path: &Path) {
    let made = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(made.success());
}

/// Item 3: a FIFO or a folder at an output path is refused with one line and stays; so is a
/// FIFO at a path of a fit's result set, before the earlier set changes.
#[test]
fn fifos_and_folders_at_output_paths_are_refused_and_left_as_they_are() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (fifo, folder) = (d.join("mask.nii.gz"), d.join("folder.nii.gz"));
    mkfifo(&fifo);
    std::fs::create_dir(&folder).unwrap();
    for (out, what) in [(&fifo, "a FIFO"), (&folder, "a folder")] {
        let o = medial(&[
            "rasterize",
            s(&toy("template.vtk")),
            "--spacing",
            "2",
            "--out",
            s(out),
        ]);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{what} replaced");
        assert!(err.contains(s(out)) && err.contains(what), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    assert!(folder.is_dir());
    let out = d.join("fit");
    let config = quick_config(d);
    fit(&config, &out);
    let summary = std::fs::read(out.join("summary.json")).unwrap();
    std::fs::remove_file(out.join("config.toml")).unwrap();
    mkfifo(&out.join("config.toml"));
    let o = medial(&["fit", s(&config), "--out", s(&out), "--quiet"]);
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("config.toml") && err.contains("not a regular file"),
        "{err}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), summary);
    let kind = std::fs::symlink_metadata(out.join("config.toml"))
        .unwrap()
        .file_type();
    assert!(kind.is_fifo());
}

/// Rows of the running fit's log in `dir` (`.medial-<pid>-log.csv.part`; 0 before it exists).
fn rows(dir: &Path) -> usize {
    let part = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .find(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            // (`log.csv.part`: the name before issue 33, for MEDIAL_UNDER_TEST.)
            name.starts_with(".medial-") && name.ends_with("-log.csv.part")
                || name == "log.csv.part"
        });
    part.and_then(|e| std::fs::read_to_string(e.path()).ok())
        .map_or(0, |t| t.lines().count().saturating_sub(1))
}

/// Runs `medial fit CONFIG --out OUT` and stops it by SIGTERM once its log has 3 rows: the
/// results so far and `checkpoint.bin` in `out`.
fn interrupted_fit(config: &Path, out: &Path) {
    let mut child = binary()
        .args(["fit", s(config), "--out", s(out), "--quiet"])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while rows(out) < 3 {
        assert!(child.try_wait().unwrap().is_none(), "the fit ended first");
        assert!(start.elapsed().as_secs() < 120, "the fit never got there");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    assert_eq!(child.wait().unwrap().code(), Some(143));
    assert!(out.join("checkpoint.bin").exists());
}

/// Item 4: a checkpoint with any one byte changed (every byte of its header and digest, and
/// bytes spread over its record) is refused with one line naming it, never resumed.
#[test]
fn a_checkpoint_with_any_byte_flipped_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let config = quick_config(d);
    interrupted_fit(&config, &out);
    let path = out.join("checkpoint.bin");
    let good = std::fs::read(&path).unwrap();
    let spread = (0..160).map(|i| 48 + i * (good.len() - 49) / 159);
    let offsets: Vec<usize> = (0..48).chain(spread).collect();
    assert!(offsets.len() >= 200 && *offsets.last().unwrap() == good.len() - 1);
    for (n, &offset) in offsets.iter().enumerate() {
        let mut bad = good.clone();
        bad[offset] ^= [0x01, 0x80, 0xff, 0x10][n % 4];
        std::fs::write(&path, &bad).unwrap();
        let o = medial(&["fit", s(&config), "--resume", s(&out), "--quiet"]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "byte {offset}: resumed: {err}");
        assert!(
            err.starts_with("error: ") && err.contains(s(&path)),
            "{err}"
        );
        assert_eq!(err.lines().count(), 1, "byte {offset}: {err}");
    }
    // The undamaged checkpoint still resumes.
    std::fs::write(&path, &good).unwrap();
    let o = medial(&["fit", s(&config), "--resume", s(&out), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// Runs the binary with `args` for at most `seconds`; `None` when it had to be killed.
fn within(args: &[&str], seconds: u64) -> Option<std::process::Output> {
    let mut child = binary()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed().as_secs() >= seconds {
            child.kill().unwrap();
            child.wait().unwrap();
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    Some(child.wait_with_output().unwrap())
}

/// Item 6: `medial report` on a fit whose `log.csv` holds a subnormal value ends (it spun for
/// ever in plotters' tick loop), and `medial template --atoms 100000000` fails at once.
#[test]
fn a_subnormal_log_value_and_a_huge_atom_count_end_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    fit(&quick_config(d), &out);
    let log = std::fs::read_to_string(out.join("log.csv")).unwrap();
    let data = log
        .lines()
        .next()
        .unwrap()
        .split(',')
        .position(|c| c == "data");
    let data = data.expect("a data column");
    let mut lines: Vec<String> = log.lines().map(str::to_owned).collect();
    let last = lines.len() - 1;
    let mut cells: Vec<&str> = lines[last].split(',').collect();
    cells[data] = "1e-310";
    lines[last] = cells.join(",");
    std::fs::write(out.join("log.csv"), lines.join("\n") + "\n").unwrap();
    let o = within(&["report", s(&out)], 60).expect("medial report hung");
    assert!(o.status.success(), "{}", text(&o.stderr));
    let start = std::time::Instant::now();
    let o = within(
        &[
            "template",
            s(&toy("template.vtk")),
            "--no-fit",
            "--atoms",
            "100000000",
            "--out",
            s(&d.join("t.vtk")),
        ],
        60,
    )
    .expect("medial template hung");
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--atoms") && err.contains("100000"), "{err}");
    assert!(start.elapsed().as_secs() < 5, "{:?}", start.elapsed());
}

/// Item 10: `medial batch T.vtk subjects.csv …` with the table named without a folder (run
/// from its folder) reads it ("cannot make an empty path absolute" before).
#[test]
fn a_subject_table_named_without_a_folder_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::copy(toy("target_boundary.vtk"), d.join("a.vtk")).unwrap();
    std::fs::write(d.join("subjects.csv"), "subject,target\na,a.vtk\n").unwrap();
    let o = binary()
        .args([
            "batch",
            s(&toy("template.vtk")),
            "subjects.csv",
            "--out",
            "cohort",
            "--slurm",
        ])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let script = std::fs::read_to_string(d.join("cohort/batch.sbatch")).unwrap();
    assert!(script.contains(s(&d.join("subjects.csv"))), "{script}");
}

/// The toy template with its points, radii and medial points scaled by `factor` (about the
/// origin), written to `path`.
fn scaled_toy(path: &Path, factor: f64) {
    let text = std::fs::read_to_string(toy("template.vtk")).unwrap();
    let mut scaling = false;
    let mut out = String::new();
    for line in text.lines() {
        let head = line.split_whitespace().next().unwrap_or("");
        if head.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
            scaling = ["POINTS", "Radius", "MedialPoint"].contains(&head);
            out += line;
        } else if scaling {
            let cells: Vec<String> = line
                .split_whitespace()
                .map(|v| format!("{:e}", v.parse::<f64>().unwrap() * factor))
                .collect();
            out += &cells.join(" ");
        } else {
            out += line;
        }
        out.push('\n');
    }
    std::fs::write(path, out).unwrap();
}

/// Item 8: results the tool can tell are meaningless are never exit 0: a Dice fit of the toy
/// scaled by 1e-6 (voxel Dice 0), a degenerate mesh rasterized (an empty mask), an SSD
/// transform scaled by 1e-12, an ITK file of two transforms.
#[test]
fn meaningless_results_are_never_exit_0() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tiny = d.join("tiny.vtk");
    scaled_toy(&tiny, 1e-6);
    let config = d.join("dice.toml");
    let stage = |keys: &str| {
        format!(
            "[model]\ntemplate = {:?}\n\n[flow]\nsigma = 2.0\ntime_steps = 5\n\
             kinetic_weight = 0.005\n\n[output]\nevery_time_point = false\n\n[[stage]]\n\
             name = \"s\"\n{keys}\nmu = 20.0\nal_iterations = 1\nmax_iterations = 5\n",
            s(&tiny)
        )
    };
    let dice = format!(
        "attachment = \"dice\"\nimage = {:?}",
        s(&toy("target.nii.gz"))
    );
    std::fs::write(&config, stage(&dice)).unwrap();
    let o = medial(&["fit", s(&config), "--out", s(&d.join("fit")), "--quiet"]);
    let err = text(&o.stderr);
    assert!(!o.status.success(), "a fit to voxel Dice 0 exited 0");
    assert!(err.contains("Dice 0") || err.contains("overlap"), "{err}");
    // A mesh of coincident points.
    let flat = d.join("flat.vtk");
    let mesh = "# vtk DataFile Version 4.2\nflat\nASCII\nDATASET POLYDATA\nPOINTS 4 double\n\
                1 1 1 1 1 1 1 1 1 1 1 1\nPOLYGONS 4 16\n3 0 1 2\n3 0 2 3\n3 0 3 1\n3 1 3 2\n";
    std::fs::write(&flat, mesh).unwrap();
    let (mask, like) = (d.join("mask.nii.gz"), toy("target.nii.gz"));
    let args = ["rasterize", s(&flat), "--like", s(&like), "--out", s(&mask)];
    let line = one_line_error(&args, 1, &["flat.vtk", "no voxel"]);
    assert!(!mask.exists(), "{line}");
    // Transforms: scaled by 1e-12, and an ITK file of two.
    let small = d.join("small.txt");
    std::fs::write(&small, "1e-12 0 0 0\n0 1e-12 0 0\n0 0 1e-12 0\n0 0 0 1\n").unwrap();
    let one = "#Transform 0\nTransform: AffineTransform_double_3_3\n\
               Parameters: 1 0 0 0 1 0 0 0 1 0 0 0\nFixedParameters: 0 0 0\n";
    let itk = d.join("two.txt");
    let two = format!(
        "#Insight Transform File V1.0\n{one}{}",
        one.replace("#Transform 0", "#Transform 1")
    );
    std::fs::write(&itk, two).unwrap();
    let ssd = d.join("ssd");
    for (path, needle) in [(&small, "singular"), (&itk, "holds 2 transforms")] {
        let keys = format!("attachment = \"ssd\"\ntransform = {:?}", s(path));
        std::fs::write(
            &config,
            stage(&keys).replace(s(&tiny), s(&toy("template.vtk"))),
        )
        .unwrap();
        let args = ["fit", s(&config), "--out", s(&ssd), "--quiet"];
        one_line_error(&args, 1, &[s(path), needle]);
    }
}

/// Item 7: under a file-size limit (`ulimit -f`), a write beyond it is a one-line error
/// naming the file, not death by SIGXFSZ.
#[test]
fn a_file_size_limit_is_an_error_not_a_signal() {
    let dir = tempfile::tempdir().unwrap();
    let mask = dir.path().join("mask.nii");
    let bin = std::env::var("MEDIAL_UNDER_TEST").unwrap_or(env!("CARGO_BIN_EXE_medial").into());
    let o = Command::new("sh")
        .arg("-c")
        .arg("ulimit -f 4 && exec \"$0\" \"$@\"")
        .args([&bin, "rasterize", s(&toy("template.vtk"))])
        .args(["--spacing", "0.3", "--out", s(&mask)])
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "killed by a signal? {o:?}");
    assert!(err.starts_with("error: ") && err.contains("mask"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!mask.exists());
}
