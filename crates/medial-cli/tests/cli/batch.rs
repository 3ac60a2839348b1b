//! `medial batch`: the subject table's checks (before any fit), fits of a small cohort (the
//! shipped toy bent by `medial synth --from`, short SSD fits from a base config), skipping on a
//! re-run, a failed subject recorded while the others go on, shards that partition the
//! subjects, gathering that is idempotent and whose thickness table is the fitted templates'
//! thickness, and the Slurm scripts.

use crate::common::{medial, one_line_error, run_fails, s, text};
use medial_core::model::{Model, SpokeMetrics};
use std::path::{Path, PathBuf};

const EXAMPLES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples");

pub fn toy_template() -> PathBuf {
    Path::new(EXAMPLES).join("toy/template.vtk")
}

/// A short constrained SSD schedule for the toy (its target replaced per subject), with wide
/// tolerances so that every fit ends sound within them.
pub fn base_config(dir: &Path) -> PathBuf {
    let path = dir.join("base.toml");
    let text = format!(
        "[model]\ntemplate = {:?}\n\n[flow]\nsigma = 2.0\ntime_steps = 5\nkinetic_weight = 0.005\n\n\
         [output]\nevery_time_point = false\n\n[[stage]]\nname = \"ssd\"\nattachment = \"ssd\"\n\
         target = \"replaced.vtk\"\nmu = 20.0\nal_iterations = 1\nmax_iterations = 15\n\
         tolerance_deg = 90.0\ntolerance_pct = 100.0\n",
        s(&toy_template())
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// The toy bent by `bend` degrees, its boundary points written to `dir/bend<bend>/`.
pub fn bent_toy(dir: &Path, bend: i32) -> PathBuf {
    let out = dir.join(format!("bend{bend}"));
    let o = medial(&[
        "synth",
        "--from",
        s(&toy_template()),
        "--bend",
        &bend.to_string(),
        "--spacing",
        "1",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "synth: {}", text(&o.stderr));
    out.join("target_boundary.vtk")
}

/// Writes `SUBJECTS.csv` in `dir` with a `target` column from `(subject, path)` pairs.
pub fn table(dir: &Path, rows: &[(&str, &Path)]) -> PathBuf {
    let mut csv = String::from("subject,target\n");
    for (name, path) in rows {
        csv.push_str(&format!("{name},{}\n", s(path)));
    }
    let path = dir.join("subjects.csv");
    std::fs::write(&path, csv).unwrap();
    path
}

/// `medial batch` with the toy template, `subjects` and `out`, then `extra`.
fn batch(subjects: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let template = toy_template();
    let mut args = vec!["batch", s(&template), s(subjects), "--out", s(out)];
    args.extend(extra);
    medial(&args)
}

/// The rows of `cohort.csv` as maps from column to cell.
fn cohort(out: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let mut reader = csv::Reader::from_path(out.join("cohort.csv")).unwrap();
    let header = reader.headers().unwrap().clone();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .zip(r.iter())
                .map(|(h, v)| (h.to_owned(), v.to_owned()))
                .collect()
        })
        .collect()
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn bad_subject_tables_are_refused_before_any_fit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let target = Path::new(EXAMPLES).join("toy/target_boundary.vtk");
    let image = Path::new(EXAMPLES).join("toy/target.nii.gz");
    let out = d.join("out");
    let template = toy_template();
    let cases: [(&str, &[&str]); 11] = [
        ("name,target\na,x.vtk\n", &["no 'subject' column"]),
        ("subject,image,mask\na,x\n", &["unknown column 'mask'"]),
        ("subject\na\n", &["no target column"]),
        (
            "subject,image,target\na,x,y\n",
            &["more than one target column"],
        ),
        ("subject,target\n", &["no subjects"]),
        (
            "subject,target\ns1,T\nS1,T\n",
            &["line 3", "'S1'", "line 2"],
        ),
        (
            "subject,target\n../up,T\n",
            &["line 2", "'../up'", "safe folder name"],
        ),
        (
            "subject,target\ncohort.csv,T\n",
            &["'cohort.csv'", "medial batch writes"],
        ),
        (
            "subject,target\na,missing.vtk\n",
            &["line 2", "missing.vtk", "not a file"],
        ),
        (
            "subject,image,label\na,I,one\n",
            &["label 'one'", "not a number"],
        ),
        (
            "subject,target,transform\na,T,T\n",
            &["'transform' column needs --config"],
        ),
    ];
    for (csv, needles) in cases {
        let csv = csv
            .replace(",T", &format!(",{}", s(&target)))
            .replace(",I", &format!(",{}", s(&image)));
        let path = d.join("subjects.csv");
        std::fs::write(&path, &csv).unwrap();
        let args = ["batch", s(&template), s(&path), "--out", s(&out)];
        let line = one_line_error(&args, 1, needles);
        assert!(line.contains("subjects.csv"), "{line}");
        assert!(!out.exists(), "{csv}: the output folder was made");
    }
    // A base config whose Dice stage would fit every subject to its own image.
    let table = table(d, &[("a", &target)]);
    let base = Path::new(EXAMPLES).join("toy/fit.toml");
    let args = [
        "batch",
        s(&template),
        s(&table),
        "--out",
        s(&out),
        "--config",
        s(&base),
    ];
    one_line_error(
        &args,
        1,
        &["stage 'affine'", "give SUBJECTS.csv the column 'transform'"],
    );
    assert!(!out.exists());
    one_line_error(
        &[
            "batch",
            s(&template),
            s(&table),
            "--out",
            s(&out),
            "--shard",
            "3/2",
        ],
        2,
        &["1 ≤ I ≤ N"],
    );
}

#[test]
fn a_batch_records_a_failure_goes_on_skips_on_a_rerun_and_gathers_the_thickness() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (b10, b30) = (bent_toy(d, 10), bent_toy(d, 30));
    // t001's boundary points: not in correspondence with the toy's (another count).
    let wrong = Path::new(EXAMPLES).join("t001-bent/target_boundary.vtk");
    let subjects = table(d, &[("s10", &b10), ("bad", &wrong), ("s30", &b30)]);
    let base = base_config(d);
    let out = d.join("cohort");
    let config = ["--config", s(&base)];

    let o = batch(&subjects, &out, &config);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let last = err.lines().last().unwrap();
    assert!(last.contains("1 of 3 subjects failed (bad)"), "{last}");
    let failed: serde_json::Value =
        serde_json::from_slice(&bytes(&out.join("bad/failed.json"))).unwrap();
    assert_eq!(failed["exit_code"], 1);
    assert!(
        failed["error"]
            .as_str()
            .unwrap()
            .contains("target_boundary.vtk"),
        "{failed}"
    );
    for name in ["s10", "s30"] {
        assert!(out.join(name).join("summary.json").is_file(), "{name}");
    }
    let rows = cohort(&out);
    let status: Vec<&str> = rows.iter().map(|r| r["status"].as_str()).collect();
    assert_eq!(status, ["budget", "failed", "budget"], "{rows:?}");
    assert_eq!(rows[1]["exit_code"], "1");
    assert!(rows[0]["mean_distance_mm"].parse::<f64>().unwrap() > 0.0);
    // Figures of other data terms are empty cells of their columns.
    assert_eq!(
        (
            rows[0]["missed_pct"].as_str(),
            rows[0]["surface_distance_mm"].as_str()
        ),
        ("", "")
    );
    assert!(rows[0]["evaluations"].parse::<usize>().unwrap() > 0);
    assert_eq!(rows[0]["error"], "");

    // thickness.npy: one row per sound fit, the thickness of its fitted template's atoms,
    // which is the Thickness array of its medial VTK at t = 1.
    let npy = medial_io::npy::read_npy(&out.join("thickness.npy")).unwrap();
    let atoms = medial_io::model::read_model(&toy_template())
        .unwrap()
        .medial_count();
    assert_eq!(npy.shape, [2, atoms]);
    assert_eq!(
        std::fs::read_to_string(out.join("thickness_subjects.txt")).unwrap(),
        "s10\ns30\n"
    );
    for (row, name) in ["s10", "s30"].iter().enumerate() {
        let Model::Medial(fitted) =
            medial_io::model::read_model(&out.join(name).join("fitted_template.vtk")).unwrap()
        else {
            panic!("not medial")
        };
        let expected = SpokeMetrics::compute(&fitted, fitted.landmarks()).thickness;
        assert_eq!(&npy.data[row * atoms..(row + 1) * atoms], &expected[..]);
        let medial =
            medial_io::vtk::read_polydata(&out.join(name).join("flow/medial_t005.vtk")).unwrap();
        let written = &medial.point_array("Thickness").unwrap().values;
        for (a, b) in written.iter().zip(&expected) {
            assert!((a - b).abs() <= 1e-9 * b.abs(), "{a} against {b}");
        }
    }
    let differs = (0..atoms).any(|a| npy.data[a] != npy.data[atoms + a]);
    assert!(differs, "two bends, the same thickness everywhere");
    let mean = medial_io::vtk::read_polydata(&out.join("thickness_mean.vtk")).unwrap();
    assert_eq!(mean.points.len(), atoms);
    let (m, sd) = (
        &mean.point_array("ThicknessMean").unwrap().values,
        &mean.point_array("ThicknessSD").unwrap().values,
    );
    for a in 0..atoms {
        let (x, y) = (npy.data[a], npy.data[atoms + a]);
        assert!((m[a] - (x + y) / 2.0).abs() < 1e-9, "atom {a}");
        assert!(
            (sd[a] - (x - y).abs() / 2f64.sqrt()).abs() < 1e-9,
            "atom {a}"
        );
    }
    assert_eq!(mean.point_array("Subjects").unwrap().values[0], 2.0);

    // A re-run skips the finished subjects (their files stay byte for byte) and tries the
    // failed one again.
    let kept: Vec<Vec<u8>> = ["s10", "s30"]
        .iter()
        .map(|n| bytes(&out.join(n).join("summary.json")))
        .collect();
    let o = batch(&subjects, &out, &config);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert_eq!(err.matches("fitted earlier, skipped").count(), 2, "{err}");
    assert!(err.contains("subject 'bad' (2 of 3): fitting"), "{err}");
    for (n, before) in ["s10", "s30"].iter().zip(&kept) {
        assert_eq!(&bytes(&out.join(n).join("summary.json")), before, "{n}");
    }

    // Gathering again writes the same bytes.
    let outputs = [
        "cohort.csv",
        "thickness.npy",
        "thickness_subjects.txt",
        "thickness_mean.vtk",
    ];
    let first: Vec<Vec<u8>> = outputs.iter().map(|f| bytes(&out.join(f))).collect();
    let template = toy_template();
    let gather = [
        "batch",
        s(&template),
        s(&subjects),
        "--out",
        s(&out),
        "--gather-only",
    ];
    let o = run_fails(&gather, &["1 of 3 subjects failed"]);
    let printed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(printed["gathered"], 2);
    assert_eq!(printed["failed"], serde_json::json!(["bad"]));
    for (f, before) in outputs.iter().zip(&first) {
        assert_eq!(&bytes(&out.join(f)), before, "{f}");
    }

    // A fitted template changed after its fit is refused by the gathering, naming it.
    let fitted = out.join("s30/fitted_template.vtk");
    let mut damaged = bytes(&fitted);
    let at = damaged.len() / 2;
    damaged[at] ^= 1;
    std::fs::write(&fitted, damaged).unwrap();
    run_fails(&gather, &["s30", "fitted_template.vtk", "SHA-256"]);
}

#[test]
fn shards_and_slurm_array_tasks_partition_the_subjects() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let target = bent_toy(d, 20);
    let subjects = table(d, &[("a", &target), ("b", &target), ("c", &target)]);
    let base = base_config(d);
    let out = d.join("cohort");
    let fitted = |name: &str| out.join(name).join("summary.json").is_file();

    let o = batch(&subjects, &out, &["--config", s(&base), "--shard", "1/2"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!([fitted("a"), fitted("b"), fitted("c")], [true, false, true]);
    let rows = cohort(&out);
    assert_eq!(rows[1]["status"], "pending");

    // The second task of a two-task Slurm array takes the rest.
    let a = bytes(&out.join("a/summary.json"));
    let mut args = vec![
        "batch".to_string(),
        s(&toy_template()).into(),
        s(&subjects).into(),
    ];
    args.extend(["--out", s(&out), "--config", s(&base)].map(String::from));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_medial"))
        .args(&args)
        .env("SLURM_ARRAY_TASK_ID", "8")
        .env("SLURM_ARRAY_TASK_MIN", "7")
        .env("SLURM_ARRAY_TASK_COUNT", "2")
        .output()
        .unwrap();
    let err = text(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("subject 'b' (1 of 1)"), "{err}");
    assert!(fitted("b"));
    assert_eq!(bytes(&out.join("a/summary.json")), a);
    let rows = cohort(&out);
    assert!(rows.iter().all(|r| r["status"] == "budget"), "{rows:?}");
    let npy = medial_io::npy::read_npy(&out.join("thickness.npy")).unwrap();
    assert_eq!(npy.shape[0], 3);
}

#[test]
fn slurm_scripts_run_an_array_and_a_gather_job_after_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let target = Path::new(EXAMPLES).join("toy/target_boundary.vtk");
    let subjects = table(d, &[("a", &target), ("b", &target), ("c", &target)]);
    let base = base_config(d);
    let out = d.join("cohort");
    let o = batch(
        &subjects,
        &out,
        &[
            "--config",
            s(&base),
            "--slurm",
            "--slurm-cpus",
            "4",
            "--slurm-time",
            "00:20:00",
            "--slurm-mem",
            "2G",
        ],
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let printed = text(&o.stdout);
    assert!(
        printed.contains(&format!("sh {}", s(&out.join("submit.sh")))),
        "{printed}"
    );
    let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();
    let batch_script = read("batch.sbatch");
    for line in [
        "#SBATCH --array=1-3",
        "#SBATCH --cpus-per-task=4",
        "#SBATCH --time=00:20:00",
        "#SBATCH --mem=2G",
        &format!("#SBATCH --output={}/slurm/batch-%A_%a.out", s(&out)),
        &format!("medial=${{MEDIAL:-{}}}", env!("CARGO_BIN_EXE_medial")),
        &format!(
            "exec \"$medial\" batch {} {} --out {} --config {} --threads \"${{SLURM_CPUS_PER_TASK:-1}}\"",
            s(&toy_template()),
            s(&subjects),
            s(&out),
            s(&base)
        ),
    ] {
        assert!(batch_script.lines().any(|l| l == line), "no {line:?} in\n{batch_script}");
    }
    let gather = read("gather.sbatch");
    assert!(gather.contains("--gather-only"), "{gather}");
    assert!(!gather.contains("--array"), "{gather}");
    let submit = read("submit.sh");
    assert!(
        submit.contains("sbatch --parsable \"$@\" --dependency=afterany:\"$array\""),
        "{submit}"
    );
    assert!(out.join("slurm").is_dir());
    for script in ["batch.sbatch", "gather.sbatch", "submit.sh"] {
        let o = std::process::Command::new("sh")
            .args(["-n", s(&out.join(script))])
            .output()
            .unwrap();
        assert!(o.status.success(), "{script}: {}", text(&o.stderr));
    }
    assert!(!out.join("a").exists(), "--slurm fitted a subject");
    one_line_error(
        &[
            "batch",
            s(&toy_template()),
            s(&subjects),
            "--out",
            s(&out),
            "--slurm-mem",
            "2 G",
        ],
        2,
        &["#SBATCH"],
    );
}
