//! Library errors. Every error that concerns a file names it.

use std::io::Write;
use std::path::{Path, PathBuf};

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
    /// The room layout has no room to offer for a frame (no hypothesis meets its rules: a view from close
    /// to a wall, too few points): a property of the frame, which `detect` answers with no room rather
    /// than with no detections.
    #[error("{0}")]
    NoRoom(String),
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

/// Replaces `path` with `bytes` atomically: written to `<file name>.tmp` beside it (the rename stays within
/// one file system), synced, then renamed over it, so an interruption never leaves a half-written file (model files, checkpoints, training
/// progress). Errors name the file that failed.
pub fn write_replacing(path: &Path, bytes: &[u8]) -> Result<()> {
    write_through_temporary(path, bytes, true)
}

/// [`write_replacing`] without the sync, for outputs a run makes again cheaply (pictures, per-frame
/// detection and layout files, synthetic images): an interrupted or failed write still leaves no
/// half-written file at `path` (only, at worst, its `.tmp`), but a crash of the whole machine may lose the
/// last files — the sync would cost about 10 ms a file, 40 % of `synth`'s time.
pub fn write_whole(path: &Path, bytes: &[u8]) -> Result<()> {
    write_through_temporary(path, bytes, false)
}

fn write_through_temporary(path: &Path, bytes: &[u8], sync: bool) -> Result<()> {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".tmp");
    let temporary = path.with_file_name(name);
    let write = || -> std::io::Result<()> {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(bytes)?;
        if sync {
            file.sync_all()?;
        }
        Ok(())
    };
    write().map_err(|e| Error::io(&temporary, e))?;
    std::fs::rename(&temporary, path).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_replacing_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.json");
        write_whole(&path, b"first").unwrap();
        write_replacing(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("model.json")], "no model.json.tmp left behind");
        // A directory that does not exist: the error names the temporary file it could not create.
        let missing = dir.path().join("absent").join("model.json");
        let message = write_replacing(&missing, b"x").unwrap_err().to_string();
        assert!(message.contains("absent/model.json.tmp"), "{message}");
    }
}
