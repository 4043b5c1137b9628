//! `cog-gpu info FRAME_DIR [--json] [--filled-depth]`: what a frame holds and how its point cloud sits in
//! the room.

use std::path::PathBuf;

use anyhow::Context;
use cog_gpu::features::preprocess::{floor_height, NotFloor, Preprocessed, NORMAL_NEIGHBOURS};
use cog_gpu::frame::{DepthSource, Frame, PointCloud};
use serde::Serialize;

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// A SUN RGB-D frame directory (with image/, depth/, intrinsics.txt, extrinsics/).
    pub frame: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Read the filled depth in depth_bfx/ instead of the raw depth in depth/.
    #[arg(long)]
    pub filled_depth: bool,
}

#[derive(Serialize)]
struct ObjectInfo {
    category: String,
    label: Option<String>,
    centre: [f32; 3],
    size: [f32; 3],
    yaw_deg: f32,
    points_inside: usize,
}

#[derive(Serialize)]
struct LayoutInfo {
    corners: Vec<[f32; 2]>,
    floor: f32,
    ceiling: f32,
    /// Fraction of the frame's points inside the room polygon between floor and ceiling.
    fraction_inside: f32,
}

/// The `--json` document; the text output prints the same fields.
#[derive(Serialize)]
struct FrameInfo {
    name: String,
    scene: Option<String>,
    width: u32,
    height: u32,
    k: [[f64; 3]; 3],
    rtilt: [[f64; 3]; 3],
    valid_depth: usize,
    bounds_min: Option<[f32; 3]>,
    bounds_max: Option<[f32; 3]>,
    /// 0.001 quantile of point heights (the paper's floor estimate), as the sliding window takes it
    /// (`features::preprocess::floor_height`, an order statistic: the floor `detect` puts its boxes on).
    floor: Option<f32>,
    /// 0.999 quantile of point heights (the paper's ceiling estimate).
    ceiling: Option<f32>,
    /// Ground cells of 0.2 m holding upward-facing points within 0.1 m above `floor`
    /// (`Preprocessed::floor_plane_cells`): at least 10 for a floor the camera sees; `None` with fewer points
    /// than the normals need.
    floor_plane_cells: Option<usize>,
    /// The second floor `detect` searches because the floor is not seen (`Preprocessed::unseen_floor`);
    /// `None` where the floor is seen (or the frame has too few points).
    unseen_floor: Option<f32>,
    /// Why the lowest points are no floor seen, for the text (`Preprocessed::lowest_points_not_floor`).
    #[serde(skip)]
    not_floor: Option<NotFloor>,
    objects: Vec<ObjectInfo>,
    layout: Option<LayoutInfo>,
}

fn describe(frame: &Frame, cloud: &PointCloud, pre: Option<&Preprocessed>) -> FrameInfo {
    let bounds = cloud.bounds();
    let objects = frame
        .objects
        .iter()
        .map(|o| ObjectInfo {
            category: o.category.clone(),
            label: o.label.clone(),
            centre: o.cuboid.centre.to_array(),
            size: o.cuboid.size.to_array(),
            yaw_deg: o.cuboid.yaw.to_degrees(),
            points_inside: cloud.points.iter().filter(|p| o.cuboid.contains(**p)).count(),
        })
        .collect();
    let layout = frame.layout.as_ref().map(|l| {
        let inside = cloud.points.iter().filter(|p| l.contains(**p)).count();
        LayoutInfo {
            corners: l.corners.iter().map(|c| c.to_array()).collect(),
            floor: l.floor,
            ceiling: l.ceiling,
            fraction_inside: if cloud.is_empty() { 0.0 } else { inside as f32 / cloud.len() as f32 },
        }
    });
    let rtilt = frame.rtilt_f64().transpose().to_cols_array_2d();
    FrameInfo {
        name: frame.name.clone(),
        scene: frame.scene.clone(),
        width: frame.width(),
        height: frame.height(),
        k: frame.k,
        rtilt,
        valid_depth: cloud.len(),
        bounds_min: bounds.map(|b| b.0.to_array()),
        bounds_max: bounds.map(|b| b.1.to_array()),
        floor: (!cloud.points.is_empty()).then(|| floor_height(&cloud.points)),
        ceiling: cloud.height_quantile(0.999),
        floor_plane_cells: pre.map(Preprocessed::floor_plane_cells),
        unseen_floor: pre.and_then(Preprocessed::unseen_floor),
        not_floor: pre.and_then(Preprocessed::lowest_points_not_floor),
        objects,
        layout,
    }
}

fn fmt_opt_vec(v: Option<[f32; 3]>) -> String {
    v.map(|v| format!("({:.3}, {:.3}, {:.3})", v[0], v[1], v[2])).unwrap_or_else(|| "-".into())
}

fn fmt_opt(v: Option<f32>) -> String {
    v.map(|v| format!("{v:.3} m")).unwrap_or_else(|| "-".into())
}

fn print_text(info: &FrameInfo) -> anyhow::Result<()> {
    out!("frame        {}{}", info.name, info.scene.as_ref().map(|s| format!(" ({s})")).unwrap_or_default());
    out!("image        {} × {}", info.width, info.height);
    for (i, row) in info.k.iter().enumerate() {
        let label = if i == 0 { "K" } else { "" };
        out!("{label:<12} [{:10.4} {:10.4} {:10.4}]", row[0], row[1], row[2]);
    }
    for (i, row) in info.rtilt.iter().enumerate() {
        let label = if i == 0 { "Rtilt" } else { "" };
        out!("{label:<12} [{:8.5} {:8.5} {:8.5}]", row[0], row[1], row[2]);
    }
    let pixels = (info.width * info.height) as f32;
    out!("valid depth  {} pixels ({:.1}%)", info.valid_depth, 100.0 * info.valid_depth as f32 / pixels);
    out!(
        "bounds       {} … {}  (upright: x right, y forward, z up; m)",
        fmt_opt_vec(info.bounds_min),
        fmt_opt_vec(info.bounds_max)
    );
    out!("floor        {}  (0.001 quantile of height)", fmt_opt(info.floor));
    out!("ceiling      {}  (0.999 quantile of height)", fmt_opt(info.ceiling));
    match (info.floor_plane_cells, info.unseen_floor) {
        (Some(cells), None) => {
            out!("floor seen   yes ({cells} cells of 0.2 m of upward points within 0.1 m of it)")
        }
        (Some(cells), Some(z)) => {
            let why = info.not_floor.map(|why| format!("the lowest points {why}: ")).unwrap_or_default();
            out!(
                "floor seen   no ({why}{cells} cells of 0.2 m of upward points within 0.1 m of them); `detect` also \
                 searches a floor at {z:.3} m"
            )
        }
        (None, _) => out!("floor seen   - (too few points for normals)"),
    }
    if info.objects.is_empty() {
        out!("objects      none annotated");
    } else {
        out!("objects      {}", info.objects.len());
        out!("  {:<16} {:>24} {:>22} {:>8} {:>8}", "category", "centre (m)", "size w×d×h (m)", "yaw°", "points");
        for o in &info.objects {
            out!(
                "  {:<16} ({:6.3}, {:6.3}, {:6.3}) {:6.3}×{:6.3}×{:6.3} {:8.1} {:8}",
                o.category,
                o.centre[0],
                o.centre[1],
                o.centre[2],
                o.size[0],
                o.size[1],
                o.size[2],
                o.yaw_deg,
                o.points_inside
            );
        }
    }
    match &info.layout {
        Some(l) => out!(
            "layout       {} corners, floor {:.3} m, ceiling {:.3} m, {:.2}% of points inside",
            l.corners.len(),
            l.floor,
            l.ceiling,
            100.0 * l.fraction_inside
        ),
        None => out!("layout       none annotated"),
    }
    Ok(())
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let source = if args.filled_depth { DepthSource::Filled } else { DepthSource::Raw };
    let frame =
        Frame::read(&args.frame, source).with_context(|| format!("cannot read frame {}", args.frame.display()))?;
    let cloud = frame.point_cloud();
    // The floor test needs the normals (as `detect` computes them); a frame with too few points has none.
    let pre = (cloud.len() >= NORMAL_NEIGHBOURS).then(|| Preprocessed::from_frame(&frame)).transpose()?;
    let info = describe(&frame, &cloud, pre.as_ref());
    if args.json {
        out!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        print_text(&info)?;
    }
    Ok(())
}
