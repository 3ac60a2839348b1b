//! Text in legacy VTK files: integers, array names (`%XX` escapes), tokens quoted in messages.

/// Parses a decimal integer with an optional sign.
pub(super) fn parse_int(token: &[u8]) -> Option<i128> {
    let (negative, digits) = match token.split_first()? {
        (b'-', rest) => (true, rest),
        (b'+', rest) => (false, rest),
        _ => (false, token),
    };
    let magnitude = parse_digits(digits)?;
    Some(if negative {
        -i128::from(magnitude)
    } else {
        i128::from(magnitude)
    })
}

/// Parses a non-empty run of decimal digits.
pub(super) fn parse_digits(digits: &[u8]) -> Option<u64> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u64, |acc, &d| {
        let digit = d.checked_sub(b'0').filter(|&d| d < 10)?;
        acc.checked_mul(10)?.checked_add(u64::from(digit))
    })
}

/// A token for messages: lossy UTF-8, at most 40 characters.
pub(super) fn show(token: &[u8]) -> String {
    String::from_utf8_lossy(token).chars().take(40).collect()
}

/// Decodes VTK's `%XX` escapes in an array name.
pub(super) fn decode_name(token: &[u8]) -> String {
    let mut bytes = Vec::with_capacity(token.len());
    let mut i = 0;
    while i < token.len() {
        let escaped = (token[i] == b'%')
            .then(|| token.get(i + 1..i + 3))
            .flatten()
            .and_then(|hex| u8::from_str_radix(std::str::from_utf8(hex).ok()?, 16).ok());
        match escaped {
            Some(byte) => {
                bytes.push(byte);
                i += 3;
            }
            None => {
                bytes.push(token[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// Encodes an array name as VTK does: blanks, controls, non-ASCII bytes, `%` and `"` as `%XX`.
pub(super) fn encode_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for &b in name.as_bytes() {
        if b <= b' ' || b >= 0x7f || b == b'%' || b == b'"' {
            out.push_str(&format!("%{b:02X}"));
        } else {
            out.push(char::from(b));
        }
    }
    out
}
