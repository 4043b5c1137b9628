//! `cog-gpu layout [FRAME_DIR|DIR ...] [--model FILE | --heuristic] [--out DIR] [--ply] [--no-overlay]`:
//! the room layout of each frame (see `cog_gpu::room_layout`): `<out>/<frame>.json` (format in
//! `cog_gpu::room_layout::output`), `<out>/<frame>.png` (the RGB image with the room's edges) and, with
//! `--ply`, `<out>/<frame>.ply` (the coloured upright point cloud with the room as a line set).
//!
//! Defaults: the frames of `assets/sample/`, the model `assets/models/layout.json`, output `layout/`. A
//! frame that fails is reported and skipped; the run exits with an error listing the failures at the end
//! (`--fail-fast`: stop at the first).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use cog_gpu::backend::Backend;
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::model::LAYOUT_MODEL_FILE;
use cog_gpu::room_layout::model::LayoutModel;
use cog_gpu::room_layout::output::{draw_room, room_line_set, LayoutFile, LayoutRecord};
use cog_gpu::room_layout::{predict, predict_heuristic, LayoutScene, PredictedLayout};

use super::detect::{frame_dirs, shipped_or};
use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// Frame directories, or directories searched recursively for frames; default: `assets/sample/`.
    pub frames: Vec<PathBuf>,
    /// Layout model file.
    #[arg(long, default_value = super::detect::SHIPPED_LAYOUT)]
    pub model: PathBuf,
    /// Use the plane-fitting heuristic baseline instead of a model.
    #[arg(long, conflicts_with = "model")]
    pub heuristic: bool,
    /// Output directory.
    #[arg(long, default_value = "layout")]
    pub out: PathBuf,
    /// Also write `<frame>.ply`: the coloured point cloud with the room's edges.
    #[arg(long)]
    pub ply: bool,
    /// Do not write the overlay pictures.
    #[arg(long)]
    pub no_overlay: bool,
    /// Stop at the first frame that fails.
    #[arg(long)]
    pub fail_fast: bool,
}

/// The layout of one frame with a model (on `backend`) or the heuristic, and its method name.
pub fn frame_layout(
    frame: &Frame,
    model: Option<&LayoutModel>,
    backend: Backend,
) -> anyhow::Result<(PredictedLayout, LayoutRecord)> {
    let scene = LayoutScene::from_frame(frame)?;
    let predicted = match model {
        Some(model) => predict(&scene, model, &|cells, tables, boxes| backend.layout_scores(cells, tables, boxes))?,
        None => predict_heuristic(&scene),
    };
    let method = model.map_or_else(|| "heuristic".to_string(), |m| m.descriptor.name());
    let record = LayoutRecord::new(&method, &predicted);
    Ok((predicted, record))
}

/// The layout model of a models directory, when it holds one.
pub fn model_in_dir(dir: &Path) -> anyhow::Result<Option<LayoutModel>> {
    let path = dir.join(LAYOUT_MODEL_FILE);
    Ok(if path.is_file() { Some(LayoutModel::read(&path)?) } else { None })
}

/// Writes the frame's coloured upright point cloud, the line sets and the room's edges as a PLY file.
pub fn write_scene_ply(
    path: &Path,
    frame: &Frame,
    mut lines: Vec<cog_gpu::ply::LineSet>,
    room: Option<&cog_gpu::frame::RoomLayout>,
) -> anyhow::Result<()> {
    let cloud = frame.point_cloud();
    if let Some(room) = room {
        lines.push(room_line_set(room));
    }
    let comment = format!("cog-gpu {} upright frame (x right, y forward, z up, metres)", frame.name);
    cog_gpu::ply::write_ply(path, &comment, &cloud.points, &cloud.colours, &lines)?;
    Ok(())
}

fn layout_one(dir: &Path, model: Option<&LayoutModel>, backend: Backend, args: &Args) -> anyhow::Result<f64> {
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let started = Instant::now();
    let (predicted, record) =
        frame_layout(&frame, model, backend).with_context(|| format!("layout of {}", dir.display()))?;
    let seconds = started.elapsed().as_secs_f64();
    LayoutFile { frame: frame.name.clone(), layout: record.clone() }
        .write(&args.out.join(format!("{}.json", frame.name)))?;
    if !args.no_overlay {
        let mut img = frame.rgb.clone();
        let camera = cog_gpu::geometry::Camera::new(frame.intrinsics(), frame.rtilt());
        draw_room(&mut img, &camera, &predicted.room, 2);
        let png = args.out.join(format!("{}.png", frame.name));
        cog_gpu::frame::write_png(&img, &png).context("writing the overlay")?;
    }
    if args.ply {
        write_scene_ply(&args.out.join(format!("{}.ply", frame.name)), &frame, Vec::new(), Some(&predicted.room))?;
    }
    out!(
        "{}: {} room, yaw {:.0}°, {:.2} × {:.2} m, floor {:.2}, ceiling {:.2}, {} hypotheses, {seconds:.3} s",
        frame.name,
        record.method,
        record.yaw_deg,
        (predicted.room_box.u1 - predicted.room_box.u0) as f32 / 1000.0,
        (predicted.room_box.v1 - predicted.room_box.v0) as f32 / 1000.0,
        record.floor,
        record.ceiling,
        record.hypotheses
    );
    Ok(seconds)
}

pub fn run(args: Args, options: &GlobalOptions) -> anyhow::Result<()> {
    let model = if args.heuristic {
        None
    } else {
        let path = shipped_or(&args.model, super::detect::SHIPPED_LAYOUT);
        Some(LayoutModel::read(&path)?)
    };
    let frames = frame_dirs(&args.frames)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let gpu = if model.is_some() { cog_gpu::gpu::acquire(options.force_cpu) } else { None };
    let backend = Backend::of(gpu.as_ref());
    let mut failures = Vec::new();
    let mut seconds = Vec::new();
    for dir in &frames {
        match layout_one(dir, model.as_ref(), backend, &args) {
            Ok(s) => seconds.push(s),
            Err(err) if args.fail_fast => return Err(err),
            Err(err) => {
                log::error!("{}: skipped: {}", dir.display(), super::error_text(&err));
                failures.push((dir.clone(), err));
            }
        }
    }
    if !seconds.is_empty() {
        let mean = seconds.iter().sum::<f64>() / seconds.len() as f64;
        out!(
            "wrote {} layout(s) to {} ({} path); layout time per frame (after reading it): mean {mean:.3} s, max {:.3} s",
            seconds.len(),
            args.out.display(),
            backend.name(),
            seconds.iter().cloned().fold(0.0, f64::max)
        );
    }
    super::batch_result(&failures, frames.len())
}
