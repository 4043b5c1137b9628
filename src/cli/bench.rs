//! `cog-gpu bench [--frame DIR] [--category bed] [--cpu|--gpu|--both] [--json]`: throughput of one
//! category's full sliding window on one frame, for the CPU path and the GPU path side by side.
//! `cog-gpu bench --detect [FRAME|DIR ...]`: the whole `detect` per frame, stage by stage
//! ([`super::bench_detect`]). `cog-gpu bench --compare-normals [FRAME|DIR ...]`: the two normal searches
//! side by side ([`super::bench_normals`]).
//!
//! The weights are a fixed-seed pseudo-random vector (the arithmetic does not depend on their values).
//! `--cpu` is the global flag; without any of the three flags both paths run. `preprocess_s` is the shared
//! CPU preprocessing (gradients, normals, floor, yaw grids, hypotheses); `score_s` the fused scoring of the
//! kept hypotheses, including uploads and read-back on the GPU path.
//!
//! Paths (keys of `paths` in `--json`): `cpu` and `gpu` (exact path), `fast` (fast path on the CPU) and
//! `fast_gpu` (fast path: lattices on the CPU, tables by `gpu::fast_tables` and scoring by `gpu::fast` on the GPU; it also reports
//! `max_relative_difference_vs_fast_cpu` when both ran). `--cpu` runs only the CPU entries, `--gpu` only the
//! GPU ones. For the fast entries `score_s` includes the lattice (`lattice_s`) and the tables.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::bail;
use serde_json::json;

use super::{options, GlobalOptions};
use cog_gpu::backend::Backend;
use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::hypotheses::{DEFAULT_MIN_POINTS, DEFAULT_STEP};
use cog_gpu::features::preprocess::NormalSearch;
use cog_gpu::features::window::{category_sizes, DEFAULT_SIZE_STATS};
use cog_gpu::features::{budget, cpu, FeatureLayout, Hypothesis, PreparedWindow};
use cog_gpu::frame::{DepthSource, Frame};

/// The real frame benchmarked when no `--frame` is given (until the synthetic standard frame exists).
pub const DEFAULT_FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";

#[derive(clap::Args)]
pub struct Args {
    /// Frame directory.
    #[arg(long, default_value = DEFAULT_FRAME)]
    pub frame: PathBuf,
    /// Category whose sizes make the sliding window.
    #[arg(long, default_value = "bed")]
    pub category: String,
    /// Run only the GPU path.
    #[arg(long, conflicts_with = "both")]
    pub gpu: bool,
    /// Run both paths (the default unless --cpu or --gpu is given).
    #[arg(long)]
    pub both: bool,
    /// Score at most this many of the kept hypotheses (evenly spread), for a quick run.
    #[arg(long, value_parser = options::at_least_one)]
    pub limit: Option<usize>,
    /// Size statistics the window's sizes come from (the --category's quantiles).
    #[arg(long, default_value = DEFAULT_SIZE_STATS)]
    pub sizes: PathBuf,
    /// Ground-plane step of the window's hypothesis centres (metres).
    #[arg(long, default_value_t = DEFAULT_STEP, value_parser = options::step)]
    pub step: f32,
    /// Skip hypotheses with fewer points inside.
    #[arg(long, default_value_t = DEFAULT_MIN_POINTS, value_parser = options::min_points)]
    pub min_points: u32,
    /// Which feature path to time: `exact` (the CPU and/or GPU path chosen by --cpu/--gpu/--both),
    /// `fast` (the shared-work approximation, on the CPU and/or GPU likewise), or `all` (both, plus the cosine similarity of the
    /// two paths' feature vectors on up to 300 of the kept hypotheses).
    #[arg(long, value_enum, default_value_t = PathChoice::All)]
    pub features: PathChoice,
    /// Lattice cells per centre step of the fast path.
    #[arg(long, default_value_t = cog_gpu::features::fast::DEFAULT_SUBDIVISIONS, value_parser = options::subdivisions)]
    pub subdivisions: u32,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// End-to-end detection instead of one window: times `detect` stage by stage on these frames (frame
    /// directories or directories of frames; none: the shipped sample frames) with every model of
    /// `--models`, GPU and CPU paths side by side (see `cli::bench_detect`).
    #[arg(long, num_args = 0.., value_name = "FRAME|DIR")]
    pub detect: Option<Vec<PathBuf>>,
    /// The two normal searches (`kdtree`, `window`; see `detect --normals`) instead of one window: on these
    /// frames (frame directories or directories of frames; none: the shipped sample frames), their time and
    /// how far their normals agree (see `cli::bench_normals`).
    #[arg(long, num_args = 0.., value_name = "FRAME|DIR", conflicts_with = "detect")]
    pub compare_normals: Option<Vec<PathBuf>>,
    /// With --detect: the models directory.
    #[arg(long, default_value = super::detect::SHIPPED_MODELS)]
    pub models: PathBuf,
    /// With --detect: overrides every model's window step (as `detect --step`).
    #[arg(long, value_parser = options::step, requires = "detect")]
    pub detect_step: Option<f32>,
    /// With --detect: how the normals find their neighbours (as `detect --normals`; default: the models').
    #[arg(long, value_parser = options::normal_search, requires = "detect")]
    pub normals: Option<NormalSearch>,
    /// With --detect: box voting after the NMS (as `detect --box-voting`: an IoU in (0, 1], or `off`).
    #[arg(long, default_value_t, value_parser = options::box_voting, requires = "detect")]
    pub box_voting: options::BoxVoting,
    /// With --detect: a second floor where the floor is not seen (as `detect --unseen-floor`: `on` or `off`).
    #[arg(long, default_value_t, value_name = "on|off", value_parser = options::unseen_floor, requires = "detect")]
    pub unseen_floor: options::UnseenFloor,
    /// With --detect: timed detections of each frame.
    #[arg(long, default_value_t = 1, value_parser = options::at_least_one)]
    pub repeat: usize,
    /// With --detect: untimed detections of the first frame before timing, per path.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// With --detect: after the stage-by-stage pass (one frame at a time), detect every frame `--repeat`
    /// times again with N frames in flight (as `detect --in-flight N`) and report the wall-clock seconds
    /// per frame of that pass, its detections compared with the first pass's.
    #[arg(long, value_name = "N", value_parser = options::at_least_one, requires = "detect")]
    pub in_flight: Option<usize>,
}

/// Feature paths `bench` can time.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PathChoice {
    Exact,
    Fast,
    All,
}

/// Deterministic weights in [−1, 1) (a 64-bit LCG; no dependency on a random crate).
pub fn bench_weights(dim: usize, seed: u64) -> Vec<f32> {
    let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (0..dim)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

pub fn run(args: Args, options: &GlobalOptions) -> anyhow::Result<()> {
    if args.detect.is_some() {
        return super::bench_detect::run(args, options);
    }
    if let Some(frames) = args.compare_normals.clone() {
        return super::bench_normals::run(args, &frames);
    }
    if options.force_cpu && (args.gpu || args.both) {
        bail!("--cpu cannot be combined with --gpu or --both");
    }
    let (want_cpu, want_gpu) = match (options.force_cpu, args.gpu, args.both) {
        (true, _, _) => (true, false),
        (_, true, _) => (false, true),
        _ => (true, true),
    };
    let frame = Frame::read(&args.frame, DepthSource::Raw)?;
    let sizes = category_sizes(&args.sizes, &args.category)?;
    let window = PreparedWindow::new(&frame, sizes, args.step, args.min_points)?;
    let layout = FeatureLayout::default();
    let weights = vec![bench_weights(layout.dim(), 7)];
    let kept = &window.set.hypotheses;
    let scored: Vec<_> = match args.limit {
        Some(limit) if limit < kept.len() => {
            let stride = kept.len() as f64 / limit as f64;
            (0..limit).map(|n| kept[(n as f64 * stride) as usize]).collect()
        }
        _ => kept.clone(),
    };
    let run_exact = args.features != PathChoice::Fast;
    let run_fast = args.features != PathChoice::Exact;
    let fast_options = FastOptions { subdivisions: args.subdivisions };
    if run_fast {
        budget::check_fast(
            &window.scene.pre,
            &window.scene.yaw_angles(),
            args.step,
            &layout,
            fast_options.subdivisions,
        )?;
    }
    // Both feature paths have a GPU twin (exact: gpu::features, fast: gpu::fast).
    let gpu = if want_gpu { cog_gpu::gpu::acquire(false) } else { None };
    if args.gpu && gpu.is_none() {
        bail!("--gpu: no GPU adapter (see the warning above)");
    }
    let mut backends = Vec::new();
    if let Some(ctx) = &gpu {
        backends.push(Backend::Gpu(ctx));
    }
    if want_cpu {
        backends.push(Backend::Cpu);
    }
    if !run_exact {
        backends.clear();
    }
    let mut paths = serde_json::Map::new();
    // The fast path's CPU scores, kept to report how far the GPU's are from them.
    let mut fast_cpu_scores = None;
    if run_fast && want_cpu {
        let start = Instant::now();
        let engine = FastEngine::new(&window.scene, &layout, fast_options);
        let lattice_s = start.elapsed().as_secs_f64();
        let scores = engine.scores(&scored, &weights);
        let score_s = start.elapsed().as_secs_f64();
        fast_cpu_scores = Some(std::hint::black_box(scores));
        let adapter = format!(
            "CPU, rayon, {} threads (shared-work approximation, subdivisions {})",
            rayon::current_num_threads(),
            fast_options.subdivisions
        );
        paths.insert("fast".into(), fast_entry(adapter, &window, kept.len(), scored.len(), lattice_s, score_s));
    }
    if let (true, Some(ctx)) = (run_fast, &gpu) {
        // Same steps as the CPU entry: lattice, then tables (CPU) and scoring (GPU), uploads and read-back.
        let start = Instant::now();
        let engine = FastEngine::new(&window.scene, &layout, fast_options);
        let lattice_s = start.elapsed().as_secs_f64();
        let scores = cog_gpu::gpu::fast::fast_scores_gpu(ctx, &engine, &scored, &weights)?;
        let score_s = start.elapsed().as_secs_f64();
        // Largest |GPU − CPU| over max(|CPU|, 1): float summation order only (see gpu::fast).
        let difference = fast_cpu_scores.as_ref().map(|cpu_scores| {
            scores.iter().zip(cpu_scores).map(|(&g, &c)| ((g - c).abs() / c.abs().max(1.0)) as f64).fold(0.0, f64::max)
        });
        let adapter = format!(
            "{} (fast path: lattices on the CPU, tables and scores on the GPU, subdivisions {})",
            ctx.adapter_summary(),
            fast_options.subdivisions
        );
        let mut entry = fast_entry(adapter, &window, kept.len(), scored.len(), lattice_s, score_s);
        entry["max_relative_difference_vs_fast_cpu"] = json!(difference);
        paths.insert("fast_gpu".into(), entry);
    }
    let similarity =
        if run_fast && run_exact { Some(cosine_report(&window, &layout, &scored, fast_options)) } else { None };
    for backend in backends {
        let start = Instant::now();
        let (_, updates) = backend.scores(&window.scene, &layout, &scored, &weights)?;
        let score_s = start.elapsed().as_secs_f64();
        let adapter = match backend {
            Backend::Gpu(ctx) => ctx.adapter_summary(),
            Backend::Cpu => format!("CPU, rayon, {} threads", rayon::current_num_threads()),
        };
        paths.insert(
            backend.name().into(),
            json!({
                "adapter": adapter,
                "hypotheses_generated": window.set.generated,
                "hypotheses_kept": kept.len(),
                "hypotheses_scored": scored.len(),
                "preprocess_s": window.preprocess_s,
                "score_s": score_s,
                "hypotheses_per_s": scored.len() as f64 / score_s,
                "point_voxel_updates": updates,
                "point_voxel_updates_per_s": updates as f64 / score_s,
            }),
        );
    }
    let report = json!({
        "frame": frame.name,
        "image": [frame.width(), frame.height()],
        "points": window.scene.pre.len(),
        "category": args.category,
        "layout": layout.id(),
        "paths": paths,
        "fast_vs_exact_cosine": similarity,
    });
    if args.json {
        out!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    out!(
        "{} ({}×{}, {} points), category '{}', layout {}",
        frame.name,
        frame.width(),
        frame.height(),
        window.scene.pre.len(),
        args.category,
        layout.id()
    );
    out!(
        "hypotheses: {} generated, {} kept, {} scored; preprocessing {:.3} s",
        window.set.generated,
        kept.len(),
        scored.len(),
        window.preprocess_s
    );
    if let Some(sim) = &similarity {
        out!(
            "fast vs exact features on {} hypotheses: cosine similarity mean {:.4}, min {:.4}",
            sim["hypotheses"],
            sim["mean"].as_f64().unwrap_or(f64::NAN),
            sim["min"].as_f64().unwrap_or(f64::NAN)
        );
    }
    for (name, p) in &paths {
        // The fast paths count no point·voxel updates (their JSON leaves the figure out): none printed
        // rather than "0.000e0".
        let updates = p["point_voxel_updates_per_s"]
            .as_f64()
            .map(|u| format!(", {u:.3e} point·voxel updates/s"))
            .unwrap_or_default();
        out!(
            "{name:>8}: score {:.3} s, {:.0} hypotheses/s{updates}  [{}]",
            p["score_s"].as_f64().unwrap_or(0.0),
            p["hypotheses_per_s"].as_f64().unwrap_or(0.0),
            p["adapter"].as_str().unwrap_or("?")
        );
    }
    Ok(())
}

/// Cosine similarity of fast and exact feature vectors on up to 300 of `hypotheses` (evenly spread).
fn cosine_report(
    window: &PreparedWindow,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    options: FastOptions,
) -> serde_json::Value {
    let stride = (hypotheses.len() / 300).max(1);
    let sample: Vec<Hypothesis> = hypotheses.iter().step_by(stride).take(300).copied().collect();
    let dim = layout.dim();
    let (exact, _) = cpu::features(&window.scene, layout, &sample);
    let fast = FastEngine::new(&window.scene, layout, options).features(&sample);
    let cosines: Vec<f64> = exact.chunks(dim).zip(fast.chunks(dim)).map(|(a, b)| cosine(a, b)).collect();
    let mean = cosines.iter().sum::<f64>() / cosines.len().max(1) as f64;
    let min = cosines.iter().copied().fold(f64::INFINITY, f64::min);
    json!({"hypotheses": cosines.len(), "mean": mean, "min": min})
}

/// Cosine similarity of two vectors (1 when both are zero).
pub fn cosine(a: &[f32], b: &[f32]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        ab += x as f64 * y as f64;
        aa += x as f64 * x as f64;
        bb += y as f64 * y as f64;
    }
    if aa == 0.0 && bb == 0.0 {
        1.0
    } else {
        ab / (aa.sqrt() * bb.sqrt()).max(f64::MIN_POSITIVE)
    }
}

/// One fast-path entry of the JSON report (`score_s` counts tables and scoring, after the lattice).
fn fast_entry(
    adapter: String,
    window: &PreparedWindow,
    kept: usize,
    scored: usize,
    lattice_s: f64,
    score_s: f64,
) -> serde_json::Value {
    json!({
        "adapter": adapter,
        "hypotheses_generated": window.set.generated,
        "hypotheses_kept": kept,
        "hypotheses_scored": scored,
        "preprocess_s": window.preprocess_s,
        "lattice_s": lattice_s,
        "score_s": score_s,
        "hypotheses_per_s": scored as f64 / score_s,
    })
}
