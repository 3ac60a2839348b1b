//! What every refusal of a bad file must look like.

use std::path::Path;

/// Asserts that `error` is clean: its message is one line that starts with the file's name.
pub fn assert_clean(error: &impl std::fmt::Display, path: &Path) {
    let message = error.to_string();
    assert!(
        message.starts_with(&format!("{}: ", path.display())),
        "the message does not start with the file: {message}"
    );
    assert!(
        !message.contains('\n'),
        "the message has several lines: {message}"
    );
}
