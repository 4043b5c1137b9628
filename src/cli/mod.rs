//! Subcommands of the `cog-gpu` binary.

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
