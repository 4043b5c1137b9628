//! `cog-gpu eval --layout --data DIR --detections DIR [--split LIST] [--json]`: free-space IoU
//! (`cog_gpu::room_layout::free_space`) of each frame's predicted room against its annotation.
//!
//! Choices: frames without a room annotation are not evaluated (counted); an annotated frame without a
//! layout file in --detections, or whose file has no layout, scores 0 (counted as missing), so a method
//! cannot gain by skipping hard frames. The mean is over the annotated frames. The JSON gives IoUs as
//! fractions; the table as percentages.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
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
}

#[derive(Serialize)]
struct Report {
    frames: usize,
    /// Mean free-space IoU over the annotated frames (missing layouts count 0).
    mean_iou: f64,
    missing_layouts: usize,
    unannotated_frames: usize,
    per_frame: Vec<FrameIou>,
}

/// One frame's IoU: `Ok(None)` without annotation, `Ok(Some(None))` without a layout file.
fn frame_iou(dir: &Path, layouts: &Path) -> anyhow::Result<Option<FrameIou>> {
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let Some(truth) = frame.layout.as_ref() else { return Ok(None) };
    let path = layouts.join(format!("{}.json", frame.name));
    if !path.is_file() {
        return Ok(Some(FrameIou { frame: frame.name.clone(), iou: None }));
    }
    let predicted = LayoutFile::read(&path)?;
    let camera = Camera::new(frame.intrinsics(), frame.rtilt());
    let iou = free_space_iou(&predicted.layout.room(), truth, &camera, [frame.width(), frame.height()]);
    Ok(Some(FrameIou { frame: frame.name.clone(), iou: Some(iou) }))
}

pub fn run(frames: &[PathBuf], layouts: &Path, json: bool, fail_fast: bool) -> anyhow::Result<()> {
    if !layouts.is_dir() {
        bail!("{}: no such directory of layout files", layouts.display());
    }
    let results: Vec<(PathBuf, anyhow::Result<Option<FrameIou>>)> = frames
        .par_iter()
        .map(|dir| (dir.clone(), frame_iou(dir, layouts).with_context(|| format!("evaluating {}", dir.display()))))
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
    if json {
        let report = Report {
            frames: per_frame.len(),
            mean_iou: mean,
            missing_layouts: missing,
            unannotated_frames: unannotated,
            per_frame,
        };
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        for f in &per_frame {
            match f.iou {
                Some(iou) => println!("{:<40} {:6.2}", f.frame, 100.0 * iou),
                None => println!("{:<40}      - (no layout file, counted 0)", f.frame),
            }
        }
        println!(
            "mean free-space IoU {:.2} over {} annotated frames ({missing} without a layout, {unannotated} \
             frames without annotation not evaluated)",
            100.0 * mean,
            per_frame.len()
        );
    }
    super::batch_result(&failures, frames.len())
}
