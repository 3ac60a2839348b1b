//! A position in the bytes of a legacy VTK file: tokens, lines, ASCII and binary values, and
//! the `METADATA` blocks that VTK 9 writes after arrays.

use std::fmt::Display;
use std::path::Path;

use super::reader::starts_section;
use super::scalar::Scalar;
use super::text::{parse_digits, show};
use crate::{Error, Result};

/// A position in the file, with the line and section for messages.
pub(super) struct Cursor<'a> {
    /// The whole file.
    bytes: &'a [u8],
    /// The byte offset of the next byte to read.
    pub(super) pos: usize,
    /// The 1-based line of `pos`.
    line: usize,
    /// Whether values are binary (`BINARY` in the header), else ASCII.
    pub(super) binary: bool,
    /// The file, for messages.
    pub(super) path: &'a Path,
    /// The section being read, for messages.
    pub(super) section: String,
}

impl<'a> Cursor<'a> {
    pub(super) fn new(bytes: &'a [u8], path: &'a Path) -> Self {
        Self {
            bytes,
            pos: 0,
            line: 1,
            binary: false,
            path,
            section: "header".into(),
        }
    }

    /// A format error at the current position.
    pub(super) fn error(&self, message: impl Display) -> Error {
        let place = if self.binary {
            format!("byte {}", self.pos)
        } else {
            format!("line {}", self.line)
        };
        Error::format(
            self.path,
            format!("{message} (in {}, {place})", self.section),
        )
    }

    fn skip_space(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            if b == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token, `None` at the end of the file.
    pub(super) fn token(&mut self) -> Option<&'a [u8]> {
        self.skip_space();
        let bytes = self.bytes;
        let start = self.pos;
        let len = bytes[start..]
            .iter()
            .take_while(|b| !b.is_ascii_whitespace())
            .count();
        self.pos += len;
        (len > 0).then(|| &bytes[start..start + len])
    }

    /// The next token without consuming it.
    pub(super) fn peek_token(&self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let start = self.pos
            + bytes[self.pos..]
                .iter()
                .take_while(|b| b.is_ascii_whitespace())
                .count();
        let len = bytes[start..]
            .iter()
            .take_while(|b| !b.is_ascii_whitespace())
            .count();
        (len > 0).then(|| &bytes[start..start + len])
    }

    /// The next token; at the end of the file an error saying `what` was expected.
    pub(super) fn expect(&mut self, what: &str) -> Result<&'a [u8]> {
        self.token()
            .ok_or_else(|| self.error(format!("unexpected end of file: expected {what}")))
    }

    /// Consumes the keyword `keyword` (case-insensitive) or fails.
    pub(super) fn keyword(&mut self, keyword: &str) -> Result<()> {
        let token = self.expect(keyword)?;
        if token.eq_ignore_ascii_case(keyword.as_bytes()) {
            Ok(())
        } else {
            Err(self.error(format!("expected {keyword}, found '{}'", show(token))))
        }
    }

    /// A non-negative integer (a count or size).
    pub(super) fn count(&mut self, what: &str) -> Result<usize> {
        let token = self.expect(what)?;
        parse_digits(token)
            .and_then(|v| usize::try_from(v).ok())
            .ok_or_else(|| {
                self.error(format!(
                    "expected {what} (a non-negative integer), found '{}'",
                    show(token)
                ))
            })
    }

    /// A numeric type name.
    pub(super) fn scalar(&mut self) -> Result<Scalar> {
        let token = self.expect("a data type")?;
        Scalar::parse(token).map_err(|m| self.error(m))
    }

    /// The next token if it is on the current line.
    pub(super) fn same_line_token(&mut self) -> Option<&'a [u8]> {
        let blanks = self.bytes[self.pos..]
            .iter()
            .take_while(|b| matches!(b, b' ' | b'\t' | b'\r'))
            .count();
        match self.bytes.get(self.pos + blanks) {
            None | Some(b'\n') => None,
            Some(_) => self.token(),
        }
    }

    /// Ends a header line before binary data: only blanks may remain; consumes the newline.
    pub(super) fn end_header_line(&mut self) -> Result<()> {
        if let Some(token) = self.same_line_token() {
            return Err(self.error(format!("unexpected '{}' before binary data", show(token))));
        }
        self.line();
        Ok(())
    }

    /// The rest of the current line (without `\n` or `\r\n`), `None` at the end of the file.
    pub(super) fn line(&mut self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let rest = bytes.get(self.pos..).filter(|r| !r.is_empty())?;
        let text = match rest.iter().position(|&b| b == b'\n') {
            Some(end) => {
                self.pos += end + 1;
                self.line += 1;
                &rest[..end]
            }
            None => {
                self.pos = bytes.len();
                rest
            }
        };
        Some(text.strip_suffix(b"\r").unwrap_or(text))
    }

    /// The next `n` bytes.
    pub(super) fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let left = self.bytes.len() - self.pos;
        if n > left {
            return Err(self.error(format!(
                "unexpected end of file: {what} needs {n} bytes, {left} left"
            )));
        }
        let bytes = self.bytes;
        self.pos += n;
        Ok(&bytes[self.pos - n..self.pos])
    }

    /// `count` values of type `scalar` (ASCII or binary), then any `METADATA` block.
    pub(super) fn values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        let values = if self.binary {
            self.binary_values(scalar, count, what)?
        } else {
            self.ascii_values(scalar, count, what)?
        };
        self.skip_metadata();
        Ok(values)
    }

    fn binary_values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        self.end_header_line()?;
        let n = count
            .checked_mul(scalar.size())
            .ok_or_else(|| self.error(format!("{what}: {count} values is too many")))?;
        Ok(scalar.decode(self.take(n, what)?))
    }

    fn ascii_values(&mut self, scalar: Scalar, count: usize, what: &str) -> Result<Vec<f64>> {
        // Each value takes at least two bytes: do not trust `count` for the allocation.
        let mut values = Vec::with_capacity(count.min((self.bytes.len() - self.pos) / 2 + 1));
        for i in 0..count {
            let Some(token) = self.token() else {
                return Err(self.error(format!(
                    "unexpected end of file: {what} needs {count} values, found {i}"
                )));
            };
            let Some(value) = scalar.parse_ascii(token) else {
                return Err(self.error(format!(
                    "'{}' is not a valid {} value ({what}, value {i})",
                    show(token),
                    scalar.name()
                )));
            };
            values.push(value);
        }
        Ok(values)
    }

    /// Skips a `METADATA` block if one comes next.
    pub(super) fn skip_metadata(&mut self) {
        if self
            .peek_token()
            .is_some_and(|t| t.eq_ignore_ascii_case(b"METADATA"))
        {
            self.token();
            self.line();
            self.skip_metadata_body();
        }
    }

    /// Skips the lines of a `METADATA` block (`COMPONENT_NAMES` and `INFORMATION n` entries,
    /// as VTK 9 writes them after an array) up to its closing blank line, the end of the file,
    /// or a line that starts a new section.
    pub(super) fn skip_metadata_body(&mut self) {
        loop {
            let (pos, line) = (self.pos, self.line);
            let Some(text) = self.line() else { return };
            let mut words = text
                .split(|b| b.is_ascii_whitespace())
                .filter(|w| !w.is_empty());
            match (words.next(), words.next()) {
                (None, _) => return,
                // Section headers have two words or more; component names and string values
                // inside the block are single (%-encoded) words, whatever they spell.
                (Some(word), Some(_)) if starts_section(word) => {
                    (self.pos, self.line) = (pos, line);
                    return;
                }
                _ => {}
            }
        }
    }
}
