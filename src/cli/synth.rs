//! `cog-gpu synth`: synthetic indoor RGB-D frames in the SUN RGB-D layout.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use cog_gpu::synth::{self, AnnotationRule, RoomType, SensorChoice, SynthOptions};
use indicatif::{ProgressBar, ProgressStyle};

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// Output directory (created if missing); frames go to DIR/synth-NNNNNN/.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Number of frames (at most 1 000 000: frame names have six digits).
    #[arg(long, value_name = "N")]
    pub frames: u64,
    /// Random seed: the same seed and options give byte-identical files.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,
    /// Sensor: kv1, kv2, realsense, xtion, or mixed (SUN RGB-D's proportions).
    #[arg(long, default_value = "mixed")]
    pub sensor: String,
    /// Image width (with --height; overrides the sensor's size, intrinsics scaled to keep its field of view).
    #[arg(long, requires = "height")]
    pub width: Option<u32>,
    /// Image height (with --width).
    #[arg(long, requires = "width")]
    pub height: Option<u32>,
    /// Comma-separated room types: bedroom, office, living_room, bathroom, dining_room, classroom, kitchen.
    #[arg(long, value_delimiter = ',')]
    pub rooms: Vec<String>,
    /// Which labelled objects get a 3D box: `depth` (at least max(12, 0.0004·W·H) visible pixels with a
    /// sensor depth, as SUN RGB-D's boxes drawn on the point cloud) or `visible` (that many visible pixels,
    /// depth or not: generator synth-1, the shipped models' data). The images do not depend on it.
    #[arg(long, value_name = "RULE", default_value = "depth")]
    pub annotate: String,
    /// Also write DIR/preview/synth-NNNNNN.png: cuboids on the RGB, depth colour map beside it.
    #[arg(long)]
    pub preview: bool,
}

/// Turns the command line into generator options, with errors naming the bad value.
pub fn options(args: &Args) -> anyhow::Result<SynthOptions> {
    let Some(sensor) = SensorChoice::parse(&args.sensor) else {
        bail!("unknown sensor '{}': expected kv1, kv2, realsense, xtion or mixed", args.sensor);
    };
    let mut rooms = Vec::new();
    if args.rooms.iter().all(|n| n.trim().is_empty()) && !args.rooms.is_empty() {
        bail!("--rooms '{}' names no room type (leave --rooms out for the default mix)", args.rooms.join(","));
    }
    for name in super::options::names("--rooms", &args.rooms)? {
        let name = name.as_str();
        let Some(r) = RoomType::parse(name) else {
            let known: Vec<&str> = RoomType::ALL.iter().map(|r| r.name()).collect();
            bail!("unknown room type '{name}': expected one of {}", known.join(", "));
        };
        if !rooms.contains(&r) {
            rooms.push(r);
        }
    }
    let size = match (args.width, args.height) {
        (Some(w), Some(h)) => Some((w, h)),
        _ => None,
    };
    let Some(annotate) = AnnotationRule::parse(&args.annotate) else {
        bail!("unknown --annotate rule '{}': expected depth or visible", args.annotate);
    };
    let options = SynthOptions { sensor, size, rooms, annotate };
    options.validate()?;
    Ok(options)
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    if !(1..=synth::MAX_FRAMES).contains(&args.frames) {
        bail!(
            "--frames must be at least 1 and at most {} (frame names have six digits), got {}",
            synth::MAX_FRAMES,
            args.frames
        );
    }
    let options = options(&args)?;
    let bar = ProgressBar::new(args.frames);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} frames ({per_sec}, eta {eta})",
        )
        .context("progress bar template")?,
    );
    let start = Instant::now();
    let summary = synth::generate_dataset(&args.out, args.seed, args.frames, &options, args.preview, &|| bar.inc(1))
        .with_context(|| format!("generating frames into {}", args.out.display()))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    out!(
        "wrote {} frames to {} in {:.1} s ({:.2} s per frame, {} threads)",
        summary.frames,
        args.out.display(),
        seconds,
        seconds / summary.frames.max(1) as f64,
        rayon::current_num_threads()
    );
    let total: usize = summary.objects.values().sum();
    out!("annotated objects: {total}");
    for cat in cog_gpu::category::CATEGORIES {
        out!("  {:<12} {}", cat, summary.objects.get(cat).copied().unwrap_or(0));
    }
    let list = |m: &std::collections::BTreeMap<String, usize>| {
        m.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ")
    };
    out!("sensors: {}", list(&summary.sensors));
    out!("rooms: {}", list(&summary.rooms));
    Ok(())
}
