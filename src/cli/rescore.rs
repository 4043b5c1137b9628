//! `cog-gpu rescore --detections DIR --out DIR [--cascade assets/models/cascade.json]`: applies a context
//! cascade ([`cog_gpu::cascade`]) to first-stage detections files (from `detect --no-cascade`) without
//! detecting again, writing one rescored `<frame>.json` per input file. Compares the first stage with the
//! cascade on the same detections (`eval` both directories). `--out` may not be `--detections`: the
//! first-stage files are the input of `cog-gpu cascade` and of `rescore` itself, so they are kept.

use std::path::PathBuf;

use anyhow::{bail, Context};
use cog_gpu::cascade::Cascade;
use cog_gpu::eval::FrameDetections;

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// First-stage detections (`<frame>.json` files from `detect --no-cascade`).
    #[arg(long)]
    pub detections: PathBuf,
    /// Output directory for the rescored files.
    #[arg(long)]
    pub out: PathBuf,
    /// The cascade file.
    #[arg(long, default_value = super::detect::SHIPPED_CASCADE)]
    pub cascade: PathBuf,
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let cascade = Cascade::read(&super::detect::shipped_or(&args.cascade, super::detect::SHIPPED_CASCADE))?;
    if !args.detections.is_dir() {
        bail!("{}: detections directory not found", args.detections.display());
    }
    if super::options::same_path(&args.detections, &args.out) {
        bail!("{}: --out must differ from --detections (the first-stage files are kept)", args.out.display());
    }
    let inputs = super::options::json_files(&args.detections)?;
    if inputs.is_empty() {
        bail!("{}: no detections files (<frame>.json)", args.detections.display());
    }
    // Every file rescored in memory first: a file the cascade refuses stops the run before any is
    // written, so --out never holds part of a run (it held the files before the refused one).
    let mut rescored = Vec::with_capacity(inputs.len());
    for path in &inputs {
        // One read: the detections, the room the cascade reads, and every other field, kept as it was.
        let text = cog_gpu::frame::read_text(path)?;
        let mut frame = FrameDetections::parse(path, &text)?;
        let room = cog_gpu::cascade::room_in(path, &text)?;
        cascade.rescore(&mut frame.detections, room.as_ref()).with_context(|| format!("{}", path.display()))?;
        let file = super::options::with_detections(&text, path, &frame.detections)?;
        let name = path.file_name().context("a detections file without a name")?;
        rescored.push((args.out.join(name), serde_json::to_string_pretty(&file)?));
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    for (out, text) in &rescored {
        cog_gpu::error::write_whole(out, text.as_bytes())?;
    }
    out!("rescored {} file(s) from {} into {}", inputs.len(), args.detections.display(), args.out.display());
    Ok(())
}
