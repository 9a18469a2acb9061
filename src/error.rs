//! Library error type. Every variant carries enough context (file, line, key, value) to be
//! printed as a one-paragraph message by the command line.

use std::path::PathBuf;

/// Errors of the meshdeco library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A mesh (or other input) file is malformed. `line` is 1-based when known.
    #[error("{path}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse { path: PathBuf, line: Option<usize>, message: String },
    /// A frame of a sequence does not match the first frame (vertex count or faces).
    #[error("{path}: {message}")]
    Mismatch { path: PathBuf, message: String },
    /// A configuration key has an invalid value.
    #[error("config key `{key}`: {message}")]
    Config { key: String, message: String },
    /// An argument or hyperparameter is out of its valid range (message carries the value).
    #[error("{0}")]
    Invalid(String),
    /// A numerical failure (factorisation failed, non-finite values appeared).
    #[error("numerical error: {0}")]
    Numerical(String),
}

/// Result alias of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// A parse error at a known (1-based) line.
    pub fn parse(path: impl Into<PathBuf>, line: Option<usize>, message: impl Into<String>) -> Self {
        Error::Parse { path: path.into(), line, message: message.into() }
    }
    /// A bad config value.
    pub fn config(key: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Config { key: key.into(), message: message.into() }
    }
}
