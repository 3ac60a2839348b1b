//! One job's share of a cohort: shard `i` of `n` takes the subjects at positions `i, i + n,
//! i + 2n, …` of the subject table (0-based positions), so that `n` jobs take every subject
//! exactly once. Given as `--shard I/N` with `I` counted from 1 (`1/4` … `4/4`), or, inside a
//! Slurm job array, from `SLURM_ARRAY_TASK_ID`, `SLURM_ARRAY_TASK_MIN`,
//! `SLURM_ARRAY_TASK_STEP` (default 1) and `SLURM_ARRAY_TASK_COUNT`: shard
//! `(ID − MIN) / STEP` of `COUNT`.

use crate::error::CliError;
use std::str::FromStr;

/// Shard `index` (0-based) of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    index: usize,
    count: usize,
}

impl Shard {
    /// Whether this shard takes the subject at `position` (0-based) of the table.
    pub fn takes(self, position: usize) -> bool {
        position % self.count == self.index
    }

    /// The shard of a Slurm array task, from the environment variables read by `var`; `None`
    /// outside an array job (no `SLURM_ARRAY_TASK_ID`).
    pub fn from_slurm(var: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, CliError> {
        let Some(id) = var("SLURM_ARRAY_TASK_ID") else {
            return Ok(None);
        };
        let number = |name: &str, default: Option<usize>| -> Result<usize, CliError> {
            match var(name) {
                Some(text) => text
                    .trim()
                    .parse()
                    .map_err(|_| CliError::Usage(format!("{name}={text:?} is not a whole number"))),
                None => default.ok_or_else(|| {
                    CliError::Usage(format!(
                        "SLURM_ARRAY_TASK_ID={id} is set but not {name}: give --shard I/N"
                    ))
                }),
            }
        };
        let id = number("SLURM_ARRAY_TASK_ID", None)?;
        let (min, step) = (
            number("SLURM_ARRAY_TASK_MIN", None)?,
            number("SLURM_ARRAY_TASK_STEP", Some(1))?.max(1),
        );
        let count = number("SLURM_ARRAY_TASK_COUNT", None)?;
        let offset = id.checked_sub(min).filter(|o| o % step == 0);
        match offset.map(|o| o / step) {
            Some(index) if index < count => Ok(Some(Self { index, count })),
            _ => Err(CliError::Usage(format!(
                "the Slurm array task {id} (min {min}, step {step}, count {count}) is not one \
                 of a regular array: give --shard I/N"
            ))),
        }
    }
}

impl FromStr for Shard {
    type Err = String;

    /// `I/N` with `1 ≤ I ≤ N`.
    fn from_str(text: &str) -> Result<Self, String> {
        let bad = || format!("a shard is I/N with 1 ≤ I ≤ N (e.g. 1/4), got '{text}'");
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let (i, n): (usize, usize) = (
            i.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if i == 0 || i > n {
            return Err(bad());
        }
        Ok(Self {
            index: i - 1,
            count: n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn env(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let map: HashMap<String, String> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k| map.get(k).cloned()
    }

    #[test]
    fn shards_partition_the_positions() {
        let n = 3;
        let shards: Vec<Shard> = (1..=n)
            .map(|i| format!("{i}/{n}").parse().unwrap())
            .collect();
        for position in 0..10 {
            assert_eq!(shards.iter().filter(|s| s.takes(position)).count(), 1);
        }
        assert!(shards[0].takes(0) && shards[0].takes(3) && shards[2].takes(5));
    }

    #[test]
    fn bad_shards_are_refused() {
        for bad in ["0/3", "4/3", "1", "a/b", "1/0", "-1/2", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }

    #[test]
    fn slurm_array_tasks_are_shards() {
        assert_eq!(Shard::from_slurm(env(&[])).unwrap(), None);
        let task = |id: &str, step: &str| {
            Shard::from_slurm(env(&[
                ("SLURM_ARRAY_TASK_ID", id),
                ("SLURM_ARRAY_TASK_MIN", "1"),
                ("SLURM_ARRAY_TASK_STEP", step),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ]))
        };
        assert_eq!(task("1", "1").unwrap(), Some("1/3".parse().unwrap()));
        assert_eq!(task("3", "1").unwrap(), Some("3/3".parse().unwrap()));
        assert_eq!(task("5", "2").unwrap(), Some("3/3".parse().unwrap()));
        assert!(task("4", "1").is_err());
        assert!(task("2", "2").is_err());
        assert!(Shard::from_slurm(env(&[("SLURM_ARRAY_TASK_ID", "1")])).is_err());
    }
}
