//! Whitespace-separated numbers, one row per line (meshglm's design and contrast files, as
//! MATLAB's `save -ascii` writes them). Blank lines and lines starting with `#` or `%` are
//! skipped; commas and brackets are read as spaces.

/// The rows of a numeric matrix written as text; every row has the same length. On failure,
/// the place (line) and the problem.
pub fn parse_matrix(text: &str) -> std::result::Result<Vec<Vec<f64>>, (String, String)> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with('%') {
            continue;
        }
        let place = || format!("line {}", k + 1);
        let row = line
            .split(|c: char| c.is_whitespace() || matches!(c, ',' | '[' | ']'))
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| (place(), format!("`{s}` is not a finite number")))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if row.is_empty() {
            continue;
        }
        if let Some(first) = rows.first() {
            if first.len() != row.len() {
                return Err((
                    place(),
                    format!("{} numbers, the first row has {}", row.len(), first.len()),
                ));
            }
        }
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(("text".into(), "no numbers".into()));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_matlab_ascii() {
        let rows = parse_matrix("  1.0e+00  0.0 7.27e-01\n\n 0 1 2.5\n").unwrap();
        assert_eq!(rows, vec![vec![1.0, 0.0, 0.727], vec![0.0, 1.0, 2.5]]);
    }

    #[test]
    fn ragged_and_bad_numbers_are_refused_with_their_line() {
        assert_eq!(parse_matrix("1 2\n3\n").unwrap_err().0, "line 2");
        let (place, problem) = parse_matrix("1 x\n").unwrap_err();
        assert_eq!(place, "line 1");
        assert!(problem.contains("`x`"));
        assert!(parse_matrix("# only a comment\n").is_err());
        assert!(parse_matrix("1 NaN\n").is_err());
    }
}
