//! How the report writes numbers and names the columns of the fit's files.

/// A number as the report shows it: an integer as such, at most four significant digits
/// between 10⁻³ and 10⁶ and scientific notation beyond, without trailing zeros (`0.02`,
/// `3.142`, `2.5e-7`); `–` for NaN.
pub fn number(v: f64) -> String {
    if v.is_nan() {
        return "–".into();
    }
    if v == v.trunc() && v.abs() < 1e15 {
        return format!("{v:.0}");
    }
    let magnitude = v.abs().log10().floor();
    if (-3.0..6.0).contains(&magnitude) {
        let decimals = (3.0 - magnitude).max(0.0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_owned()
    } else {
        let text = format!("{v:.3e}");
        let (mantissa, exponent) = text.split_once('e').expect("{:e} has an exponent");
        format!("{}e{exponent}", trim_zeros(mantissa))
    }
}

/// `text` without the trailing zeros of its decimals (and without a trailing point).
fn trim_zeros(text: &str) -> &str {
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.')
    } else {
        text
    }
}

/// The readable name of a column or key of the fit's files, with its unit from the name's
/// suffix (`_deg` °, `_pct` %, `_mm` mm, `_mm2` mm², `_mm3` mm³): `max_spoke_normal_deg` is
/// "max spoke–normal angle (°)"; names the report does not know are spelled out the same way.
pub fn label(name: &str) -> String {
    let known = match name {
        "data" => Some("data term g"),
        "kinetic" => Some("kinetic energy KE"),
        "penalty" => Some("penalty P"),
        "total" => Some("E_AL"),
        "dice" => Some("Dice estimate"),
        "mu" => Some("μ"),
        "grad_norm" => Some("‖∇E‖"),
        "max_abs_constraint" => Some("max |C|"),
        _ => None,
    };
    if let Some(known) = known {
        return known.into();
    }
    let units = [
        ("_deg", "°"),
        ("_pct", "%"),
        ("_mm2", "mm²"),
        ("_mm3", "mm³"),
        ("_mm", "mm"),
    ];
    let (stem, unit) = units
        .iter()
        .find_map(|(suffix, unit)| name.strip_suffix(suffix).map(|stem| (stem, Some(*unit))))
        .unwrap_or((name, None));
    let words = stem
        .replace("spoke_normal", "spoke–normal angle")
        .replace("abs_constraint", "|C|")
        .replace('_', " ");
    match unit {
        Some(unit) => format!("{words} ({unit})"),
        None => words,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers() {
        assert_eq!(number(20.0), "20");
        assert_eq!(number(0.02), "0.02");
        assert_eq!(number(0.2000001), "0.2");
        assert_eq!(number(-1e-4), "-1e-4");
        assert_eq!(number(1234.5678), "1235");
        assert_eq!(number(1.23456), "1.235");
        assert_eq!(number(2.5e-7), "2.5e-7");
        assert_eq!(number(f64::NAN), "–");
    }

    #[test]
    fn labels() {
        assert_eq!(label("max_spoke_normal_deg"), "max spoke–normal angle (°)");
        assert_eq!(label("max_abs_constraint_mm2"), "max |C| (mm²)");
        assert_eq!(label("min_thickness_mm"), "min thickness (mm)");
        assert_eq!(label("mean_ball_residual"), "mean ball residual");
        assert_eq!(label("penalty"), "penalty P");
    }
}
