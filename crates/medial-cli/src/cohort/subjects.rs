//! The subject table of a cohort, `SUBJECTS.csv`: a header row, a `subject` column (the name of
//! the subject's folder), exactly one of the target columns `image` (a segmentation, Dice),
//! `target` (corresponding points, SSD) or `surface` (a mesh, varifold), and optionally `label`
//! (with `image`: the foreground label) and `transform` (a 4×4 map of the template towards the
//! subject for the SSD stages of a base config that align by a transform). Paths are relative to
//! the CSV file's folder. Every row is checked, and every file it names must exist, before any
//! fit starts.

use super::RESERVED;
use crate::config::{AttachmentKind, Config};
use crate::error::CliError;
use crate::fitting::{Inputs, Resolved};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The columns a subject table may have.
const COLUMNS: [&str; 6] = [
    "subject",
    "image",
    "target",
    "surface",
    "label",
    "transform",
];

/// The target columns; a table has exactly one of them.
const TARGETS: [&str; 3] = ["image", "target", "surface"];

/// One row of the table.
#[derive(Debug)]
pub struct Subject {
    /// The subject's name: its folder in the cohort folder.
    pub name: String,
    /// Its target (absolute path) and label, as the flags of `medial fit` give them, with the
    /// cohort's template.
    pub inputs: Inputs,
    /// Its transform (absolute path), for the SSD stages of a base config that align by one.
    pub transform: Option<PathBuf>,
}

impl Subject {
    /// The config of this subject's fit: `base` with the subject's template and target in
    /// place of the base's, and its transform in place of the base's SSD transforms (see
    /// [`crate::fitting::resolve`]); without a base, the automatic schedule, written to
    /// `out`.
    pub fn config(&self, base: Option<&Path>, out: &Path) -> Result<Resolved, CliError> {
        let mut resolved = crate::fitting::resolve(base, &self.inputs, out)?;
        if let Some(transform) = &self.transform {
            for stage in &mut resolved.config.stages {
                if stage.transform.is_some() {
                    stage.transform = Some(transform.clone());
                }
            }
        }
        Ok(resolved)
    }
}

/// The subject table `path`, checked, in file order; every subject is fitted from `template`.
pub fn read(path: &Path, template: &Path) -> Result<Vec<Subject>, CliError> {
    let bad = |message: String| CliError::Subjects {
        path: path.into(),
        message,
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| bad(csv_message(&e)))?;
    let header = reader.headers().map_err(|e| bad(csv_message(&e)))?.clone();
    let columns = Columns::of(&header).map_err(bad)?;
    // A bare file name's folder is the current one ("" cannot be made absolute).
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    let folder =
        std::path::absolute(parent.unwrap_or(Path::new("."))).map_err(|e| CliError::io(path, e))?;
    let template = std::path::absolute(template).map_err(|e| CliError::io(template, e))?;
    let mut subjects: Vec<Subject> = Vec::new();
    let mut seen: HashMap<String, u64> = HashMap::new();
    for record in reader.records() {
        let record = record.map_err(|e| bad(csv_message(&e)))?;
        let line = record.position().map_or(0, |p| p.line());
        let row = Row {
            record: &record,
            line,
            folder: &folder,
        };
        let subject = columns.subject(&row, &template).map_err(bad)?;
        if let Some(first) = seen.insert(subject.name.to_lowercase(), line) {
            return Err(bad(format!(
                "line {line}: subject '{}' is already on line {first} (names must differ, \
                 also in letter case: they are folder names)",
                subject.name
            )));
        }
        subjects.push(subject);
    }
    if subjects.is_empty() {
        return Err(bad("no subjects: the table has a header and no rows".into()));
    }
    Ok(subjects)
}

/// Checks that a base config takes every datum of the table from the subjects, and takes all
/// of them: a stage whose target would stay the base config's own file would fit every subject
/// to the same data.
pub fn check_base(base: &Config, base_path: &Path, subjects: &[Subject]) -> Result<(), CliError> {
    let first = &subjects[0];
    let given = |column: &str| match column {
        "image" => first.inputs.image.is_some(),
        "target" => first.inputs.target.is_some(),
        "surface" => first.inputs.surface.is_some(),
        _ => first.transform.is_some(),
    };
    let mut used = Vec::new();
    for stage in &base.stages {
        let column = match stage.attachment {
            AttachmentKind::Dice => "image",
            AttachmentKind::Varifold => "surface",
            AttachmentKind::Ssd if stage.transform.is_some() => "transform",
            AttachmentKind::Ssd => "target",
        };
        if !given(column) {
            return Err(CliError::Config {
                path: base_path.into(),
                message: format!(
                    "stage '{}' takes its {column} from the base config, the same for every \
                     subject: give SUBJECTS.csv the column '{column}', or remove the stage",
                    stage.name
                ),
            });
        }
        used.push(column);
    }
    if let Some(unused) = ["image", "target", "surface", "transform"]
        .into_iter()
        .find(|c| given(c) && !used.contains(c))
    {
        return Err(CliError::Config {
            path: base_path.into(),
            message: format!(
                "no stage uses the '{unused}' column of SUBJECTS.csv (a Dice stage takes \
                 'image', an SSD stage 'target' or 'transform', a varifold stage 'surface')"
            ),
        });
    }
    Ok(())
}

/// Where each column of the table is.
struct Columns {
    subject: usize,
    /// The target column's name and position.
    target: (&'static str, usize),
    label: Option<usize>,
    transform: Option<usize>,
}

/// A record with what its messages and paths need.
struct Row<'a> {
    record: &'a csv::StringRecord,
    line: u64,
    folder: &'a Path,
}

impl Row<'_> {
    /// The value at `column`, empty if the row is short.
    fn get(&self, column: usize) -> &str {
        self.record.get(column).unwrap_or("")
    }

    /// The file named at `column` under the heading `name`, absolute; it must exist.
    fn file(&self, column: usize, name: &str, subject: &str) -> Result<PathBuf, String> {
        let value = self.get(column);
        if value.is_empty() {
            return Err(format!(
                "line {}: subject '{subject}' has no {name}",
                self.line
            ));
        }
        let path = self.folder.join(value);
        if !path.is_file() {
            return Err(format!(
                "line {}: the {name} of subject '{subject}', {}, is not a file",
                self.line,
                path.display()
            ));
        }
        Ok(path)
    }
}

impl Columns {
    fn of(header: &csv::StringRecord) -> Result<Self, String> {
        let names: Vec<&str> = header.iter().collect();
        let position = |name: &str| names.iter().position(|n| *n == name);
        let subject = position("subject").ok_or_else(|| {
            format!(
                "no 'subject' column (the header is: {}); the first row must name the columns",
                names.join(", ")
            )
        })?;
        if let Some(unknown) = names.iter().find(|n| !COLUMNS.contains(n)) {
            return Err(format!(
                "unknown column '{unknown}' (the columns are {})",
                COLUMNS.join(", ")
            ));
        }
        if let Some(twice) = COLUMNS
            .iter()
            .find(|c| names.iter().filter(|n| *n == *c).count() > 1)
        {
            return Err(format!("the column '{twice}' appears twice"));
        }
        let targets: Vec<(&'static str, usize)> = TARGETS
            .iter()
            .filter_map(|t| position(t).map(|p| (*t, p)))
            .collect();
        let target = match targets[..] {
            [one] => one,
            [] => return Err("no target column: give one of 'image', 'target', 'surface'".into()),
            _ => {
                return Err(format!(
                    "more than one target column ({}): give one of 'image', 'target', 'surface'",
                    targets.iter().map(|t| t.0).collect::<Vec<_>>().join(", ")
                ))
            }
        };
        let label = position("label");
        if label.is_some() && target.0 != "image" {
            return Err("the 'label' column needs the 'image' column".into());
        }
        Ok(Self {
            subject,
            target,
            label,
            transform: position("transform"),
        })
    }

    /// The subject of `row`.
    fn subject(&self, row: &Row<'_>, template: &Path) -> Result<Subject, String> {
        let name = row.get(self.subject);
        check_name(name).map_err(|why| format!("line {}: subject '{name}' {why}", row.line))?;
        let (target_name, column) = self.target;
        let target = Some(row.file(column, target_name, name)?);
        let label = match self.label.map(|c| row.get(c)).filter(|v| !v.is_empty()) {
            None => None,
            Some(text) => Some(
                text.parse::<f64>()
                    .ok()
                    .filter(|l| l.is_finite())
                    .ok_or_else(|| {
                        format!(
                            "line {}: label '{text}' of subject '{name}' is not a number",
                            row.line
                        )
                    })?,
            ),
        };
        let transform = self
            .transform
            .map(|c| row.file(c, "transform", name))
            .transpose()?;
        let pick = |t: &str| (target_name == t).then(|| target.clone()).flatten();
        Ok(Subject {
            name: name.into(),
            inputs: Inputs {
                template: Some(template.into()),
                image: pick("image"),
                label,
                target: pick("target"),
                surface: pick("surface"),
            },
            transform,
        })
    }
}

/// Why `name` cannot be a subject's folder: empty, more than 100 characters, characters other
/// than ASCII letters, digits, `.`, `_` and `-`, not starting with a letter or digit (no hidden
/// folders, `.` or `..`), or a name the cohort folder already uses ([`RESERVED`]).
fn check_name(name: &str) -> Result<(), &'static str> {
    let allowed = |c: char| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-');
    if name.is_empty() {
        Err("is empty")
    } else if name.len() > 100 {
        Err("is longer than 100 characters")
    } else if !name.chars().all(allowed) || !name.starts_with(|c: char| c.is_ascii_alphanumeric()) {
        Err(
            "is not a safe folder name: use ASCII letters, digits, '.', '_' and '-', starting \
             with a letter or digit",
        )
    } else if RESERVED.contains(&name) {
        Err("is the name of a file medial batch writes in the cohort folder")
    } else {
        Ok(())
    }
}

/// The csv crate's message without its own position prefix where it has one.
fn csv_message(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::Io(io) => io.to_string(),
        _ => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn safe_names_pass_and_others_say_why() {
        for ok in ["s01", "Sub-1.a_b", "9"] {
            assert_eq!(check_name(ok), Ok(()), "{ok}");
        }
        for bad in [
            "",
            ".",
            "..",
            ".hidden",
            "a/b",
            "a b",
            "-x",
            "ü",
            "cohort.csv",
        ] {
            assert!(check_name(bad).is_err(), "{bad}");
        }
        assert!(check_name(&"a".repeat(101)).is_err());
    }
}
