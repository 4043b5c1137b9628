//! `cog-gpu train-layout --data DIR --out FILE [--discretisation manhattan|cubical] [--cog] [--edges] [--c C] [--eps E]
//! [--max-iterations N] [--limit N] [--resume]`: trains a room-layout model (`cog_gpu::room_layout::learn`) on
//! every frame under DIR with a room annotation and writes it with its provenance (the command line, the
//! data directory and its `manifest.json` seed when it has one, frame and hypothesis counts, solver
//! figures). A checkpoint `<out>.ckpt` is written after every iteration, as `train` writes one; `--resume`
//! continues from it (the same examples and options: the checkpoint's data hash and C are checked) to the
//! weights an uninterrupted run reaches.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use cog_gpu::frame::{Dataset, DepthSource, Frame};
use cog_gpu::learn::{CuttingPlane, SsvmOptions};
use cog_gpu::room_layout::learn::{LayoutExample, LayoutOracle};
use cog_gpu::room_layout::model::LayoutModel;
use cog_gpu::room_layout::voxels::{Descriptor, Discretisation};
use cog_gpu::room_layout::LayoutScene;
use rayon::prelude::*;
use serde_json::json;

use super::{options, GlobalOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset directory (frames with annotation3Dlayout/index.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Model file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Feature cells: the paper's Manhattan voxels or the cubical comparison.
    #[arg(long, value_enum, default_value = "manhattan")]
    pub discretisation: DiscretisationArg,
    /// Add COG histograms (image gradients on the wall planes) to every voxel cell (README, "Room layout").
    #[arg(long)]
    pub cog: bool,
    /// Add the edge-orientation features (image edges aligned with the room's projected axes; README,
    /// "Room layout").
    #[arg(long)]
    pub edges: bool,
    /// Regularisation constant C of eq. 4.
    #[arg(long, default_value_t = 10.0, value_parser = options::positive)]
    pub c: f64,
    /// Cutting-plane tolerance (loss units).
    #[arg(long, default_value_t = 0.001, value_parser = options::non_negative)]
    pub eps: f64,
    /// Cap on QP solves.
    #[arg(long, default_value_t = 300, value_parser = options::iterations)]
    pub max_iterations: usize,
    /// Use only the first N frames (in path order).
    #[arg(long, value_parser = options::at_least_one)]
    pub limit: Option<usize>,
    /// Continue from the checkpoint `<out>.ckpt` (same data and options; --max-iterations counts the
    /// interrupted run's QP solves too).
    #[arg(long)]
    pub resume: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum DiscretisationArg {
    Manhattan,
    Cubical,
}

impl From<DiscretisationArg> for Discretisation {
    fn from(d: DiscretisationArg) -> Self {
        match d {
            DiscretisationArg::Manhattan => Discretisation::Manhattan,
            DiscretisationArg::Cubical => Discretisation::Cubical,
        }
    }
}

/// One training example from a frame directory, or `None` without a room annotation.
fn example(dir: &std::path::Path, descriptor: Descriptor) -> anyhow::Result<Option<LayoutExample>> {
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let Some(truth) = frame.layout.clone() else { return Ok(None) };
    let scene = LayoutScene::from_frame(&frame)?;
    Ok(Some(LayoutExample::new(&frame.name, &scene, &truth, descriptor)?))
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let descriptor = Descriptor::new(args.discretisation.into(), args.cog, args.edges);
    // The model's file checked before the training, as `train` does: not a failure after it.
    super::options::writable_output_file(&args.out)?;
    let checkpoint = PathBuf::from(format!("{}.ckpt", args.out.display()));
    if args.resume && !checkpoint.is_file() {
        bail!("--resume: no checkpoint at {}", checkpoint.display());
    }
    let mut frames = Dataset::open(&args.data)?.frames;
    if let Some(limit) = args.limit {
        frames.truncate(limit);
    }
    let started = Instant::now();
    let results: Vec<anyhow::Result<Option<LayoutExample>>> =
        frames.par_iter().map(|dir| example(dir, descriptor).with_context(|| dir.display().to_string())).collect();
    let mut examples = Vec::new();
    let mut skipped = 0usize;
    for result in results {
        match result {
            Ok(Some(e)) => examples.push(e),
            Ok(None) => continue,
            // A frame the layout cannot use (no depth, no height extent) is no training example.
            Err(err) => {
                log::warn!("skipped: {}", super::error_text(&err));
                skipped += 1;
            }
        }
    }
    if examples.is_empty() {
        bail!("{}: no frame with a room annotation (annotation3Dlayout/index.json)", args.data.display());
    }
    for e in &examples {
        log::debug!("{}: {} hypotheses, best free-space IoU {:.4}", e.name, e.boxes.len(), e.ious[e.truth]);
    }
    let counts: Vec<usize> = examples.iter().map(|e| e.boxes.len()).collect();
    let ceiling: f64 = examples.iter().map(|e| e.ious[e.truth] as f64).sum::<f64>() / examples.len() as f64;
    let (min, max) = (counts.iter().min().copied().unwrap_or(0), counts.iter().max().copied().unwrap_or(0));
    let mean = counts.iter().sum::<usize>() as f64 / counts.len() as f64;
    eprintln!(
        "{} examples ({} frames) prepared in {:.1} s: hypotheses per frame min {min}, mean {mean:.0}, max {max}; \
         best-hypothesis free-space IoU (the ceiling) mean {:.4}",
        examples.len(),
        frames.len(),
        started.elapsed().as_secs_f64(),
        ceiling
    );
    let oracle = LayoutOracle { descriptor, examples };
    let options = SsvmOptions {
        c: args.c,
        epsilon: args.eps,
        max_iterations: args.max_iterations,
        checkpoint: Some(checkpoint.clone()),
        ..SsvmOptions::default()
    };
    let mut solver = if args.resume {
        log::info!("resuming from {}", checkpoint.display());
        CuttingPlane::resume(options, &checkpoint)?
    } else {
        CuttingPlane::new(options)?
    };
    let solution = solver.train(&oracle)?;
    eprintln!(
        "trained in {:.1} s: {} QP solves, converged {}, primal {:.5}, dual {:.5}",
        started.elapsed().as_secs_f64(),
        solution.iterations,
        solution.converged,
        solution.primal,
        solution.dual
    );
    let manifest_seed = std::fs::read_to_string(args.data.join("manifest.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|m| m.get("seed").cloned());
    let provenance = json!({
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "data": args.data.display().to_string(),
        "data_seed": manifest_seed,
        "frames": frames.len(),
        "examples": oracle.examples.len(),
        "skipped_frames": skipped,
        "hypotheses_per_frame": {"min": min, "mean": mean, "max": max},
        "best_hypothesis_mean_iou": ceiling,
        "c": args.c,
        "eps": args.eps,
        "qp_solves": solution.iterations,
        "converged": solution.converged,
        "primal": solution.primal,
        "dual": solution.dual,
        "version": env!("CARGO_PKG_VERSION"),
    });
    let weights = solution.w.iter().map(|&w| w as f32).collect();
    LayoutModel::new(descriptor, weights, provenance).write(&args.out)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}
