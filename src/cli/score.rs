//! `cog-gpu score FRAME_DIR --weights FILE [--top K]`: the best-scoring sliding-window hypotheses of one
//! frame for a weights file (format: `cog_gpu::features::weights`).

use std::path::PathBuf;

use anyhow::Context;

use super::{options, GlobalOptions};
use cog_gpu::backend::Backend;
use cog_gpu::features::hypotheses::{DEFAULT_MIN_POINTS, DEFAULT_STEP};
use cog_gpu::features::window::{category_sizes, DEFAULT_SIZE_STATS};
use cog_gpu::features::{PreparedWindow, WeightsFile};
use cog_gpu::frame::{DepthSource, Frame};

#[derive(clap::Args)]
pub struct Args {
    /// Frame directory (SUN RGB-D layout).
    pub frame: PathBuf,
    /// Weights file (JSON, see `features::weights`).
    #[arg(long)]
    pub weights: PathBuf,
    /// How many hypotheses to print (at least 1: 0 scored the whole window to print nothing).
    #[arg(long, default_value_t = 10, value_parser = options::at_least_one)]
    pub top: usize,
    /// Size statistics the hypotheses' sizes come from (the weights' category is looked up in it).
    #[arg(long, default_value = DEFAULT_SIZE_STATS)]
    pub sizes: PathBuf,
    /// Ground-plane step of the hypothesis centres (metres).
    #[arg(long, default_value_t = DEFAULT_STEP, value_parser = options::step)]
    pub step: f32,
    /// Skip hypotheses with fewer points inside.
    #[arg(long, default_value_t = DEFAULT_MIN_POINTS, value_parser = options::min_points)]
    pub min_points: u32,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args, options: &GlobalOptions) -> anyhow::Result<()> {
    let model = WeightsFile::read(&args.weights)?;
    let frame = Frame::read(&args.frame, DepthSource::Raw)?;
    let sizes = category_sizes(&args.sizes, &model.category)?;
    let window = PreparedWindow::new(&frame, sizes, args.step, args.min_points)?;
    let gpu = cog_gpu::gpu::acquire(options.force_cpu);
    let backend = Backend::of(gpu.as_ref());
    let hypotheses = &window.set.hypotheses;
    let (scores, _) = backend
        .scores(&window.scene, &model.layout, hypotheses, std::slice::from_ref(&model.weights))
        .context("scoring the hypotheses")?;
    let mut order: Vec<usize> = (0..hypotheses.len()).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
    let rows: Vec<serde_json::Value> = order
        .iter()
        .take(args.top)
        .enumerate()
        .map(|(rank, &n)| {
            let c = hypotheses[n].cuboid(&window.scene);
            serde_json::json!({
                "rank": rank + 1,
                "score": scores[n] + model.bias,
                "centre": c.centre.to_array(),
                "size": c.size.to_array(),
                "yaw_deg": c.yaw.to_degrees(),
            })
        })
        .collect();
    if args.json {
        let out = serde_json::json!({
            "frame": frame.name, "category": model.category, "path": backend.name(),
            "hypotheses_generated": window.set.generated, "hypotheses_kept": hypotheses.len(), "top": rows,
        });
        out!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    out!(
        "{}: {} '{}' hypotheses generated, {} kept, scored on the {}",
        frame.name,
        window.set.generated,
        model.category,
        hypotheses.len(),
        backend.name()
    );
    out!("{:>4} {:>10}  {:>24}  {:>20}  {:>7}", "rank", "score", "centre (m)", "size w×d×h (m)", "yaw°");
    for row in &rows {
        let v = |key: &str, i: usize| row[key][i].as_f64().unwrap_or(f64::NAN);
        out!(
            "{:>4} {:>10.4}  ({:>6.2}, {:>6.2}, {:>6.2})  {:>5.2}×{:>5.2}×{:>5.2}  {:>7.1}",
            row["rank"],
            row["score"].as_f64().unwrap_or(f64::NAN),
            v("centre", 0),
            v("centre", 1),
            v("centre", 2),
            v("size", 0),
            v("size", 1),
            v("size", 2),
            row["yaw_deg"].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}
