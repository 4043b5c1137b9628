//! `cog-gpu eval --layout --data DIR --detections DIR [--split LIST] [--json] [--bootstrap N [--versus DIR]]`:
//! free-space IoU (`cog_gpu::room_layout::free_space`) of each frame's predicted room against its
//! annotation.
//!
//! Choices: frames without a room annotation are not evaluated (counted); an annotated frame without a
//! layout file in --detections, or whose file has no layout, scores 0 (counted as missing), so a method
//! cannot gain by skipping hard frames. The mean is over the annotated frames. The JSON gives IoUs as
//! fractions; the table as percentages. `--bootstrap N`: the 90 % percentile interval of the mean over N
//! resamples of the annotated frames with replacement (`cog_gpu::eval::bootstrap_frames`, the resampling
//! of the detection intervals); with `--versus DIR`, the other directory's mean and interval and the paired
//! interval of the difference (--detections minus --versus; each resample draws the same frames for both).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use cog_gpu::eval::{bootstrap_frames, percentile_interval, Bootstrap};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::Camera;
use cog_gpu::room_layout::free_space::free_space_iou;
use cog_gpu::room_layout::output::LayoutFile;
use rayon::prelude::*;
use serde::Serialize;

#[derive(Serialize)]
struct FrameIou {
    frame: String,
    /// `None`: no layout file for this frame (scored 0 in the mean).
    iou: Option<f64>,
    /// With `--versus`: the other directory's IoU (`None`: no layout file there).
    #[serde(skip_serializing_if = "Option::is_none")]
    versus_iou: Option<Option<f64>>,
}

/// `--bootstrap N [--versus DIR]` of `eval --layout`.
pub struct LayoutBootstrap {
    pub settings: Bootstrap,
    pub versus: Option<PathBuf>,
}

/// The `--bootstrap` part of the report (fractions).
#[derive(Serialize)]
struct BootstrapReport {
    resamples: usize,
    seed: u64,
    level: f32,
    mean_iou_interval: (f32, f32),
    #[serde(skip_serializing_if = "Option::is_none")]
    versus: Option<VersusReport>,
}

#[derive(Serialize)]
struct VersusReport {
    layouts: PathBuf,
    mean_iou: f64,
    mean_iou_interval: (f32, f32),
    /// Mean IoU of --detections minus that of --versus, and its paired interval.
    difference: f64,
    difference_interval: (f32, f32),
}

#[derive(Serialize)]
struct Report {
    frames: usize,
    /// Mean free-space IoU over the annotated frames (missing layouts count 0).
    mean_iou: f64,
    missing_layouts: usize,
    unannotated_frames: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    bootstrap: Option<BootstrapReport>,
    per_frame: Vec<FrameIou>,
}

/// One frame's IoU (and the `--versus` directory's): `Ok(None)` without annotation, an IoU of `None`
/// without a layout file.
fn frame_iou(dir: &Path, layouts: &Path, versus: Option<&Path>) -> anyhow::Result<Option<FrameIou>> {
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let Some(truth) = frame.layout.as_ref() else { return Ok(None) };
    let camera = Camera::new(frame.intrinsics(), frame.rtilt());
    let iou_in = |layouts: &Path| -> anyhow::Result<Option<f64>> {
        let path = layouts.join(format!("{}.json", frame.name));
        if !path.is_file() {
            return Ok(None);
        }
        let predicted = LayoutFile::read(&path)?;
        if predicted.frame != frame.name {
            log::warn!(
                "{}: its \"frame\" is '{}', not '{}'; used for {}",
                path.display(),
                predicted.frame,
                frame.name,
                frame.name
            );
        }
        Ok(Some(free_space_iou(&predicted.layout.room(), truth, &camera, [frame.width(), frame.height()])))
    };
    let versus_iou = match versus {
        Some(dir) => Some(iou_in(dir)?),
        None => None,
    };
    Ok(Some(FrameIou { frame: frame.name.clone(), iou: iou_in(layouts)?, versus_iou }))
}

/// Mean of `values` over each resample's frames, and the 90 % interval of those means.
fn resampled_means(values: &[f64], draws: &[Vec<usize>]) -> (f32, f32) {
    let means: Vec<f32> =
        draws.iter().map(|draw| (draw.iter().map(|&f| values[f]).sum::<f64>() / draw.len() as f64) as f32).collect();
    percentile_interval(&means, super::eval::BOOTSTRAP_LEVEL).unwrap_or((f32::NAN, f32::NAN))
}

/// The `--bootstrap` report over the annotated frames' IoUs (missing layouts count 0).
fn bootstrap_report(per_frame: &[FrameIou], bootstrap: &LayoutBootstrap) -> BootstrapReport {
    let ious: Vec<f64> = per_frame.iter().map(|f| f.iou.unwrap_or(0.0)).collect();
    let draws = bootstrap_frames(ious.len(), bootstrap.settings);
    let mean = |values: &[f64]| values.iter().sum::<f64>() / values.len() as f64;
    let versus = bootstrap.versus.as_ref().map(|dir| {
        let other: Vec<f64> = per_frame.iter().map(|f| f.versus_iou.flatten().unwrap_or(0.0)).collect();
        let differences: Vec<f64> = ious.iter().zip(&other).map(|(a, b)| a - b).collect();
        VersusReport {
            layouts: dir.clone(),
            mean_iou: mean(&other),
            mean_iou_interval: resampled_means(&other, &draws),
            difference: mean(&differences),
            difference_interval: resampled_means(&differences, &draws),
        }
    });
    BootstrapReport {
        resamples: bootstrap.settings.resamples,
        seed: bootstrap.settings.seed,
        level: super::eval::BOOTSTRAP_LEVEL,
        mean_iou_interval: resampled_means(&ious, &draws),
        versus,
    }
}

pub fn run(
    frames: &[PathBuf],
    layouts: &Path,
    json: bool,
    fail_fast: bool,
    bootstrap: Option<LayoutBootstrap>,
) -> anyhow::Result<()> {
    // One layout file per frame name: frames of one name would all be scored against the one file.
    cog_gpu::frame::unique_frame_names(frames)?;
    let versus = bootstrap.as_ref().and_then(|b| b.versus.as_deref());
    for dir in std::iter::once(layouts).chain(versus) {
        if !dir.is_dir() {
            bail!("{}: no such directory of layout files", dir.display());
        }
    }
    let results: Vec<(PathBuf, anyhow::Result<Option<FrameIou>>)> = frames
        .par_iter()
        .map(|dir| {
            (dir.clone(), frame_iou(dir, layouts, versus).with_context(|| format!("evaluating {}", dir.display())))
        })
        .collect();
    let mut per_frame = Vec::new();
    let mut unannotated = 0;
    let mut failures = Vec::new();
    for (dir, result) in results {
        match result {
            Ok(Some(f)) => per_frame.push(f),
            Ok(None) => unannotated += 1,
            Err(err) if fail_fast => return Err(err),
            Err(err) => {
                log::error!("{}: skipped: {}", dir.display(), super::error_text(&err));
                failures.push((dir, err));
            }
        }
    }
    if per_frame.is_empty() {
        bail!("no evaluated frame has a room annotation (annotation3Dlayout/index.json)");
    }
    let missing = per_frame.iter().filter(|f| f.iou.is_none()).count();
    let mean = per_frame.iter().map(|f| f.iou.unwrap_or(0.0)).sum::<f64>() / per_frame.len() as f64;
    let bootstrap = bootstrap.as_ref().map(|b| bootstrap_report(&per_frame, b));
    if json {
        let report = Report {
            frames: per_frame.len(),
            mean_iou: mean,
            missing_layouts: missing,
            unannotated_frames: unannotated,
            bootstrap,
            per_frame,
        };
        out!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        for f in &per_frame {
            match f.iou {
                Some(iou) => out!("{:<40} {:6.2}", f.frame, 100.0 * iou),
                None => out!("{:<40}      - (no layout file, counted 0)", f.frame),
            }
        }
        out!(
            "mean free-space IoU {:.2} over {} annotated frames ({missing} without a layout, {unannotated} \
             frames without annotation not evaluated)",
            100.0 * mean,
            per_frame.len()
        );
        if let Some(b) = &bootstrap {
            print_bootstrap(b)?;
        }
    }
    super::batch_result(&failures, frames.len())
}

fn print_bootstrap(b: &BootstrapReport) -> anyhow::Result<()> {
    let pct = |(lo, hi): (f32, f32)| format!("[{:.2}, {:.2}]", 100.0 * lo, 100.0 * hi);
    out!(
        "{:.0} % bootstrap interval of the mean ({} resamples of the annotated frames, seed {}): {}",
        100.0 * b.level,
        b.resamples,
        b.seed,
        pct(b.mean_iou_interval)
    );
    if let Some(v) = &b.versus {
        out!(
            "versus {}: mean free-space IoU {:.2} {}; difference {:+.2} {} (paired)",
            v.layouts.display(),
            100.0 * v.mean_iou,
            pct(v.mean_iou_interval),
            100.0 * v.difference,
            pct(v.difference_interval)
        );
    }
    Ok(())
}
