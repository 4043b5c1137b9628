//! Library errors. Every error that concerns a file names it.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: cannot decode image: {source}")]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    /// A file that exists but whose content is wrong (bad numbers, wrong shape, wrong size).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// A required file or directory is absent.
    #[error("{path}: missing ({what})")]
    Missing { path: PathBuf, what: String },
    /// Bad input that is not tied to one file (an argument, a parameter).
    #[error("{0}")]
    Input(String),
    #[error("GPU: {0}")]
    Gpu(String),
    /// The learning solver failed (QP not solved, corrupt checkpoint content).
    #[error("solver: {0}")]
    Solver(String),
}

impl Error {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Invalid { path: path.into(), message: message.into() }
    }
    pub fn missing(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Error::Missing { path: path.into(), what: what.into() }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
