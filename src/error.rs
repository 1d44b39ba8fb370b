//! One error type for the whole program: a single line meant for the user.
//!
//! Every message names where the problem is (file, line, column, key path when known) and,
//! where it helps, what to do. The CLI prints it and exits with code 1.

use std::fmt;
use std::path::Path;

#[derive(Debug, Clone, PartialEq)]
pub struct Error(pub String);

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn msg(text: impl Into<String>) -> Self {
        Error(text.into())
    }

    /// `file: message` for problems that concern a whole file (missing, unreadable, empty).
    pub fn file(path: &Path, text: impl fmt::Display) -> Self {
        Error(format!("{}: {}", path.display(), text))
    }

    /// `file:line:col: key: message`; line and column are 1-based, key is the dotted path.
    pub fn at(
        path: &Path,
        location: Option<(usize, usize)>,
        key: &str,
        text: impl fmt::Display,
    ) -> Self {
        let place = match location {
            Some((line, col)) => format!("{}:{}:{}", path.display(), line, col),
            None => path.display().to_string(),
        };
        if key.is_empty() {
            Error(format!("{place}: {text}"))
        } else {
            Error(format!("{place}: {key}: {text}"))
        }
    }

    /// `file:line: message` for line-oriented files (CSV, OBJ, instance tables).
    pub fn line(path: &Path, line: usize, text: impl fmt::Display) -> Self {
        Error(format!("{}:{}: {}", path.display(), line, text))
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Error {}

/// Reads a whole text file with an error that names it.
pub fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| Error::file(path, format!("cannot read file: {e}")))
}
