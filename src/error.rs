//! One error type for the whole program, printed as a single line meant for the user.
//!
//! Every message names where the problem is (file, line, column, key path when known) and,
//! where it helps, what to do. Its [`Kind`] says whose move it is: the user's input, the
//! system (I/O), or a damaged file lidarsim itself wrote. The CLI prints it and exits with 1.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What to do when the system refuses a write (nothing half-written is left under a final
/// name).
pub const WRITE_ADVICE: &str = "check the free space and the permissions of its folder";

/// [`WRITE_ADVICE`] for a run's own files: a run stopped by it continues where it stopped.
pub const RUN_WRITE_ADVICE: &str =
    "check the free space and the permissions of that folder (a run resumes with --resume)";

/// Whose move an error is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A file or flag the user gave is wrong: the message says what to change.
    Input,
    /// The system refused a read or write (missing file, permissions, full disk).
    Io,
    /// A file lidarsim reads back (a run folder's parts, manifest, products) is damaged or
    /// not its own: redo it (`run --resume` redoes what it cannot trust).
    Data,
    /// A signal (SIGINT, SIGTERM) stopped the work at a boundary, everything written kept:
    /// a failed run for the exit code (1), its message naming the signal.
    Interrupted(i32),
}

/// One error: boxed, so that a `Result` stays two words wide on the happy path.
#[derive(Debug, Clone)]
pub struct Error(Box<Details>);

/// What an error knows; read through the error (`e.kind`, `e.key`).
#[derive(Debug, Clone)]
pub struct Details {
    pub kind: Kind,
    pub file: Option<PathBuf>,
    /// 1-based line and column, when the file is text and the place is known.
    pub line: Option<usize>,
    pub column: Option<usize>,
    /// Dotted key path (`platform.scanner.prf_hz`), when the problem is one key's value.
    pub key: Option<String>,
    pub message: String,
    /// What to do about it, when the message alone does not say.
    pub advice: Option<String>,
    /// Where the file was reached from (`scene.yaml: objects.tree.mesh`), when it matters.
    pub within: Option<String>,
    source: Option<Arc<dyn std::error::Error + Send + Sync + 'static>>,
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    fn new(kind: Kind, file: Option<&Path>, message: String) -> Self {
        Error(Box::new(Details {
            kind,
            file: file.map(Path::to_path_buf),
            line: None,
            column: None,
            key: None,
            message,
            advice: None,
            within: None,
            source: None,
        }))
    }

    /// A problem with a flag or with no file to name.
    pub fn msg(text: impl Into<String>) -> Self {
        Error::new(Kind::Input, None, text.into())
    }

    /// `file: message` for problems that concern a whole file (missing, unreadable, empty).
    pub fn file(path: &Path, text: impl fmt::Display) -> Self {
        Error::new(Kind::Input, Some(path), text.to_string())
    }

    /// `file:line:col: key: message`; line and column are 1-based, key is the dotted path.
    pub fn at(
        path: &Path,
        location: Option<(usize, usize)>,
        key: &str,
        text: impl fmt::Display,
    ) -> Self {
        let mut e = Error::new(Kind::Input, Some(path), text.to_string());
        if let Some((line, col)) = location {
            e.0.line = Some(line);
            e.0.column = Some(col);
        }
        if !key.is_empty() {
            e.0.key = Some(key.to_string());
        }
        e
    }

    /// `file:line: message` for line-oriented files (CSV, OBJ, instance tables).
    pub fn line(path: &Path, line: usize, text: impl fmt::Display) -> Self {
        let mut e = Error::new(Kind::Input, Some(path), text.to_string());
        e.0.line = Some(line);
        e
    }

    /// `file: what: cause` for a read or write the system refused; the cause is chained.
    pub fn io<E>(path: &Path, what: &str, cause: E) -> Self
    where
        E: std::error::Error + Send + Sync + 'static,
    {
        let mut e = Error::new(Kind::Io, Some(path), format!("{what}: {cause}"));
        e.0.source = Some(Arc::new(cause));
        e
    }

    /// `file: what: cause` for a file lidarsim reads back and cannot trust.
    pub fn data(path: &Path, text: impl fmt::Display) -> Self {
        Error::new(Kind::Data, Some(path), text.to_string())
    }

    /// Work stopped by `signal` at a boundary; `done` says what was kept.
    pub fn interrupted(signal: i32, done: impl fmt::Display) -> Self {
        Error::new(
            Kind::Interrupted(signal),
            None,
            format!(
                "stopped by {}: {done}; run again with --resume to finish",
                crate::interrupt::name(signal)
            ),
        )
    }

    /// The same error with what to do about it.
    pub fn advise(mut self, advice: impl Into<String>) -> Self {
        self.0.advice = Some(advice.into());
        self
    }

    /// The same error met within a run: a write's advice says the run resumes where it
    /// stopped (see [`RUN_WRITE_ADVICE`]).
    pub fn in_run(mut self) -> Self {
        if self.0.advice.as_deref() == Some(WRITE_ADVICE) {
            self.0.advice = Some(RUN_WRITE_ADVICE.into());
        }
        self
    }

    /// The same error about the argument or key `key` (a host's argument: `threads`).
    pub fn for_key(mut self, key: impl Into<String>) -> Self {
        self.0.key = Some(key.into());
        self
    }

    /// The same error, saying where its file was reached from (a scene file's key, a sweep
    /// entry): `mesh.obj:12: bad face (scene.yaml: objects.tree.mesh)`.
    pub fn within(mut self, place: impl Into<String>) -> Self {
        self.0.within = Some(place.into());
        self
    }
}

impl std::ops::Deref for Error {
    type Target = Details;
    fn deref(&self) -> &Details {
        &self.0
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{}", file.display())?;
            if let Some(line) = self.line {
                write!(f, ":{line}")?;
                if let Some(col) = self.column {
                    write!(f, ":{col}")?;
                }
            }
            f.write_str(": ")?;
        }
        if let Some(key) = &self.key {
            write!(f, "{key}: ")?;
        }
        f.write_str(&self.message)?;
        if let Some(within) = &self.within {
            write!(f, " ({within})")?;
        }
        if let Some(advice) = &self.advice {
            write!(f, "; {advice}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source
            .as_deref()
            .map(|e| e as &(dyn std::error::Error + 'static))
    }
}

/// Reads a whole text file with an error that names it.
pub fn read_text(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        if path.is_dir() {
            Error::file(path, not_a_file(path))
        } else {
            Error::io(path, "cannot read file", e)
        }
    })?;
    // a byte-order mark (some Windows editors write one) is no part of the text
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Why a path named as an input file is not one: the end of "FILE ..." messages.
pub fn not_a_file(path: &Path) -> &'static str {
    if path.is_dir() {
        "is a folder, not a file"
    } else if path.exists() {
        "is not a regular file"
    } else {
        "does not exist"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_place_and_chain_the_cause() {
        let p = Path::new("c.yaml");
        let e = Error::at(p, Some((3, 5)), "platform.prf_hz", "must be > 0");
        assert_eq!(e.to_string(), "c.yaml:3:5: platform.prf_hz: must be > 0");
        assert_eq!(e.kind, Kind::Input);
        let e = Error::line(Path::new("t.csv"), 2, "column 2 (y): not a number")
            .within("scene.yaml: instances");
        assert_eq!(
            e.to_string(),
            "t.csv:2: column 2 (y): not a number (scene.yaml: instances)"
        );
        let io = std::io::Error::new(std::io::ErrorKind::StorageFull, "no space left");
        let e = Error::io(Path::new("out/part.parquet"), "cannot write", io)
            .advise("free some space, then run again with --resume");
        assert_eq!(e.kind, Kind::Io);
        assert_eq!(
            e.to_string(),
            "out/part.parquet: cannot write: no space left; free some space, then run again \
             with --resume"
        );
        let cause = std::error::Error::source(&e).expect("the I/O error is chained");
        assert_eq!(cause.to_string(), "no space left");
        assert_eq!(
            Error::msg("--seeds 0: expected at least 1").to_string(),
            "--seeds 0: expected at least 1"
        );
    }
}
