//! Reliability and security regressions (issue 33): no shell injection through generated
//! scripts, no deletion outside the output folder or of the user's files, outputs only as
//! regular files, damaged checkpoints refused, no hang, meaningless results never exit 0, and
//! a commit that a SIGKILL at any instant leaves with the old or the new set whole.

use crate::common::{s, text};
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
