//! Helpers shared by the end-to-end tests of the `medial` binary.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The file `name` of the real data set (`/work/shared/data`, see its README.md).
pub fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data")
        .join(name)
}

/// Runs the built binary with `args`, whatever its exit status.
pub fn medial(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_medial"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// Output bytes as text (invalid UTF-8 replaced).
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Runs the binary, asserts success, parses its JSON output.
pub fn run_json(args: &[&str]) -> Value {
    let o = medial(args);
    assert!(o.status.success(), "{args:?} failed: {}", text(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

/// Runs the binary, asserts failure with a message containing every `needles`; returns the
/// output for further checks.
pub fn run_fails(args: &[&str], needles: &[&str]) -> Output {
    let o = medial(args);
    let err = text(&o.stderr);
    assert!(!o.status.success(), "{args:?} should fail");
    for n in needles {
        assert!(err.contains(n), "{args:?}: message {err:?} lacks {n:?}");
    }
    o
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}

/// A JSON number.
pub fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

/// The hint clap prints after the message of a wrong command line (following a blank line).
const CLAP_HINT: &str = "For more information, try '--help'.";

/// Runs the binary, asserts that it fails with exit code `code` and a message containing every
/// `needles`, printed as exactly one line `error: …` (for a wrong command line, code 2, clap's
/// hint may follow after a blank line); returns that line.
pub fn one_line_error(args: &[&str], code: i32, needles: &[&str]) -> String {
    let o = run_fails(args, needles);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
    let mut lines: Vec<&str> = err.lines().collect();
    if code == 2 && lines.ends_with(&["", CLAP_HINT]) {
        lines.truncate(lines.len() - 2);
    }
    assert!(
        lines.len() == 1 && lines[0].starts_with("error: "),
        "{args:?}: the error is not one line: {err:?}"
    );
    lines[0].to_owned()
}

/// Records the SHA-256 of the files of the fit folder `dir` again in its summary.json, as if
/// the fit had written them as they are now (for tests that change a result file on purpose;
/// a changed file is otherwise refused); a file that is not there keeps its digest.
pub fn reseal(dir: &Path) {
    use sha2::Digest;
    let path = dir.join("summary.json");
    let mut summary: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let sha256 = summary["sha256"]
        .as_object_mut()
        .expect("summary.json has digests");
    for (relative, digest) in sha256.iter_mut() {
        let Ok(bytes) = std::fs::read(dir.join(relative)) else {
            continue;
        };
        let hex: String = (sha2::Sha256::digest(&bytes).iter())
            .map(|b| format!("{b:02x}"))
            .collect();
        *digest = Value::String(hex);
    }
    std::fs::write(&path, summary.to_string()).unwrap();
}
