//! `cog-gpu bench --compare-normals [FRAME|DIR ...]`: the two normal searches of
//! [`NormalSearch`](cog_gpu::features::preprocess::NormalSearch) on each frame — their time (the search and
//! the plane fits, on the frame's points; the rest of preprocessing is shared) and how far their normals
//! agree ([`normal_agreement`]: the share of (point, yaw) pairs with the same 25-bin code over the 16
//! hypothesis yaws, the median angle, the share within 10°). With no frame argument the shipped sample
//! frames.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use cog_gpu::features::hypotheses::default_yaws;
use cog_gpu::features::preprocess::{estimate_normals, normal_agreement, window_normals, NormalAgreement};
use cog_gpu::frame::{DepthSource, Frame};
use serde_json::json;

use super::bench::Args;
use super::detect::frame_dirs;

/// One frame's comparison.
struct FrameComparison {
    frame: String,
    kdtree_s: f64,
    window_s: f64,
    agreement: NormalAgreement,
}

fn compare(dir: &PathBuf) -> anyhow::Result<FrameComparison> {
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let cloud = frame.point_cloud();
    let started = Instant::now();
    let kdtree = estimate_normals(&cloud.points);
    let kdtree_s = started.elapsed().as_secs_f64();
    let started = Instant::now();
    let window = window_normals([frame.width(), frame.height()], &cloud.points, &cloud.pixels);
    let window_s = started.elapsed().as_secs_f64();
    let agreement = normal_agreement(&kdtree, &window, &default_yaws());
    Ok(FrameComparison { frame: frame.name, kdtree_s, window_s, agreement })
}

pub fn run(args: Args, frames_args: &[PathBuf]) -> anyhow::Result<()> {
    let frames = frame_dirs(frames_args)?;
    let mut rows = Vec::new();
    for dir in &frames {
        rows.push(compare(dir).with_context(|| format!("comparing the normal searches on {}", dir.display()))?);
    }
    let n = rows.len().max(1) as f64;
    let mean = |f: &dyn Fn(&FrameComparison) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let report = json!({
        "frames": rows.iter().map(|r| json!({
            "frame": r.frame,
            "points": r.agreement.points,
            "kdtree_s": r.kdtree_s,
            "window_s": r.window_s,
            "same_code": r.agreement.same_code,
            "median_angle_deg": r.agreement.median_angle_deg,
            "within_10_deg": r.agreement.within_10_deg,
        })).collect::<Vec<_>>(),
        "mean": {
            "kdtree_s": mean(&|r| r.kdtree_s),
            "window_s": mean(&|r| r.window_s),
            "same_code": mean(&|r| r.agreement.same_code),
            "median_angle_deg": mean(&|r| r.agreement.median_angle_deg),
            "within_10_deg": mean(&|r| r.agreement.within_10_deg),
        },
        "threads": rayon::current_num_threads(),
    });
    if args.json {
        out!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    out!("normal searches: kdtree (15 nearest of all points) against window (15 nearest in the 7×7 pixels)");
    out!(
        "{:<32} {:>8} {:>10} {:>10} {:>10} {:>12} {:>10}",
        "frame",
        "points",
        "kdtree_s",
        "window_s",
        "same_code",
        "median_deg",
        "within_10"
    );
    for r in &rows {
        out!(
            "{:<32} {:>8} {:>10.4} {:>10.4} {:>9.1}% {:>12.2} {:>9.1}%",
            r.frame,
            r.agreement.points,
            r.kdtree_s,
            r.window_s,
            100.0 * r.agreement.same_code,
            r.agreement.median_angle_deg,
            100.0 * r.agreement.within_10_deg
        );
    }
    let m = &report["mean"];
    out!(
        "{:<32} {:>8} {:>10.4} {:>10.4} {:>9.1}% {:>12.2} {:>9.1}%",
        "mean",
        "",
        m["kdtree_s"].as_f64().unwrap_or(0.0),
        m["window_s"].as_f64().unwrap_or(0.0),
        100.0 * m["same_code"].as_f64().unwrap_or(0.0),
        m["median_angle_deg"].as_f64().unwrap_or(0.0),
        100.0 * m["within_10_deg"].as_f64().unwrap_or(0.0)
    );
    Ok(())
}
