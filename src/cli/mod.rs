//! Subcommands of the `cog-gpu` binary.
//!
//! Reports go to standard output through [`out!`] and [`out_part!`], never `println!`: a write that fails
//! (a full disk, `> /dev/full`, a file system error) is the command's error,
//! `error: writing standard output: <why>` with status 1, where `println!` panics (status 101).

/// Writes one line of a command's report to standard output, as `println!` does, and returns from the
/// enclosing function (which returns `anyhow::Result`) with [`write_stdout`]'s error when the write fails.
macro_rules! out {
    () => {
        $crate::cli::write_stdout(format_args!("\n"))?
    };
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!("{}\n", format_args!($($arg)*)))?
    };
}

/// Writes part of a line of a command's report to standard output, as `print!` does; errors as [`out!`].
macro_rules! out_part {
    ($($arg:tt)*) => {
        $crate::cli::write_stdout(format_args!($($arg)*))?
    };
}

pub mod bench;
pub mod bench_detect;
pub mod bench_normals;
pub mod calibrate;
pub mod cascade;
pub mod detect;
pub mod eval;
pub mod eval_layout;
pub mod in_flight;
pub mod info;
pub mod layout;
pub mod merge_cascades;
pub mod merge_detections;
pub mod options;
pub mod rescore;
pub mod score;
pub mod synth;
pub mod train;
pub mod train_layout;

/// An error and its causes on one line, each cause once: a library error that already quotes its source
/// (an I/O error's OS message) does not get it repeated.
pub fn error_text(err: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in err.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

/// The end of a batch command (`detect`, `eval`) that went on past failed frames: an error listing them,
/// or `Ok` when every frame succeeded.
pub fn batch_result(failures: &[(std::path::PathBuf, anyhow::Error)], frames: usize) -> anyhow::Result<()> {
    if failures.is_empty() {
        return Ok(());
    }
    let list: Vec<String> =
        failures.iter().map(|(dir, err)| format!("  {}: {}", dir.display(), error_text(err))).collect();
    anyhow::bail!("{} of {frames} frames failed (skipped):\n{}", failures.len(), list.join("\n"))
}

/// Writes formatted text to standard output (locked for the one write): the error, if any, says it was
/// standard output that could not be written.
pub fn write_stdout(text: std::fmt::Arguments) -> anyhow::Result<()> {
    use std::io::Write;
    std::io::stdout().lock().write_fmt(text).map_err(|e| anyhow::anyhow!("writing standard output: {e}"))
}

/// Flushes what standard output still buffers (a report's last part without a line end): called at the
/// end of every command, so that a failed flush is the command's error, not lost at exit.
pub fn flush_stdout() -> anyhow::Result<()> {
    use std::io::Write;
    std::io::stdout().lock().flush().map_err(|e| anyhow::anyhow!("writing standard output: {e}"))
}

/// Options shared by every subcommand.
pub struct GlobalOptions {
    /// `--cpu`: never ask for a GPU adapter.
    pub force_cpu: bool,
}

/// `.json` files of a detections directory by file stem (a frame's name, [`cog_gpu::frame::frame_name`]).
pub fn detection_files(dir: &std::path::Path) -> anyhow::Result<std::collections::HashMap<String, std::path::PathBuf>> {
    use anyhow::Context;
    if !dir.is_dir() {
        anyhow::bail!("{}: detections directory not found", dir.display());
    }
    let entries = std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))?;
    let mut files = std::collections::HashMap::new();
    for entry in entries {
        let path = entry.with_context(|| format!("{}: cannot list", dir.display()))?.path();
        if path.is_file() && path.extension().is_some_and(|e| e == "json") {
            if let Some(stem) = path.file_stem() {
                files.insert(stem.to_string_lossy().into_owned(), path);
            }
        }
    }
    Ok(files)
}
