//! `cog-gpu bench --detect [FRAME|DIR ...]`: end-to-end detection time per frame, stage by stage, for the
//! GPU and the CPU path side by side in one run.
//!
//! Per path (`gpu` when an adapter is found and `--cpu` is not given; `cpu` unless `--gpu`), after
//! `--warmup` untimed detections of the first frame (pipelines, allocator, caches: the figures are the
//! steady state of a long-running process), each frame is detected `--repeat` times, as `cog-gpu detect`
//! does it, with every model of `--models` (the layout model and the cascade too when the directory holds
//! them), timing each stage:
//!
//! | stage | what |
//! |---|---|
//! | `read_s` | reading the frame's files (`Frame::read`) |
//! | `preprocess_s` | upright points, gradients, normals, floor (`Preprocessed::from_frame`) |
//! | `yaw_grids_s`, `window_s`, `lattices_s`, `score_s`, `select_s`, `nms_s`, `cross_scores_s` | [`DetectStages`] (`cross_scores_s`: 0 unless the cascade reads them) |
//! | `cascade_s` | the context cascade's rescoring (0 without `cascade.json`) |
//! | `layout_s` | the room layout (0 without `layout.json`) |
//! | `output_s` | the detections file's JSON text and the overlay drawn in memory (no PNG encoding, no disk) |
//!
//! With `--in-flight N`, a second pass detects the frames (each `--repeat` times) with `N` frames in flight
//! (`cli::in_flight`, as `detect --in-flight N`): stage times overlap there, so only its wall-clock
//! seconds per frame are reported (`in_flight.s_per_frame`, beside the first pass's `mean.total_s`), and
//! its detections are compared with the first pass's (`in_flight.same_as_one_at_a_time`).
//!
//! Beside each stage's wall-clock seconds, the process's CPU seconds over the same interval (user + system,
//! all threads, `detect::process_cpu_seconds`): `preprocess_cpu_s` (reading included), `yaw_grids_cpu_s`,
//! `window_cpu_s`, `lattices_cpu_s`, `score_cpu_s`, `select_cpu_s`, `nms_cpu_s`, `cross_scores_cpu_s`,
//! `layout_cpu_s`, and `cpu_s`
//! for the whole frame: how much of the machine a stage uses (on the GPU path, the CPU work beside the
//! GPU's, which bounds how many frames per second the machine can detect with frames in flight).
//!
//! `total_s` is the sum of the stages; `tables_thread_s` is the part of `score_s`'s work spent building the
//! fast path's tables, summed over threads. On the GPU path the read-back is inside `score_s`. The two
//! paths' detections are compared frame by frame (same categories and boxes, scores within a relative
//! tolerance): the GPU path must not change what is detected.
//!
//! On the GPU path, `pooled_mb` gives the GPU memory the context's buffer pools hold after each timed frame
//! (`max` and `last`; `GpuContext::pooled_bytes`, after the frame's trim, `gpu::BufferPool::trim`).

use std::path::Path;

use anyhow::{bail, Context};
use serde_json::json;

use super::bench::Args;
use super::detect::{
    best_of, cascade_for, frame_dirs, lay_out, overlay_picture, rescore_in_room, shipped_or, FrameReport,
};
use super::GlobalOptions;
use cog_gpu::backend::Backend;
use cog_gpu::detect::{
    compare_paths, detect_preprocessed_timed, DetectOptions, DetectStages, Stopwatch, DEFAULT_OVERLAY_MIN_PROBABILITY,
    DEFAULT_OVERLAY_TOP,
};
use cog_gpu::eval::Detection;
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::gpu::fast::use_kernel_on;
use cog_gpu::model::read_models_dir;

/// One frame's stage times on one path.
#[derive(Clone, Debug, Default, serde::Serialize)]
struct FrameTimes {
    frame: String,
    read_s: f64,
    preprocess_s: f64,
    #[serde(flatten)]
    stages: DetectStages,
    cascade_s: f64,
    layout_s: f64,
    output_s: f64,
    total_s: f64,
    /// Process CPU seconds (all threads) of reading and preprocessing, of the room layout, and of the
    /// whole frame (the detection stages' own are in `stages`).
    preprocess_cpu_s: f64,
    layout_cpu_s: f64,
    cpu_s: f64,
    detections: usize,
}

pub fn run(args: Args, options: &GlobalOptions) -> anyhow::Result<()> {
    let frames_args = args.detect.clone().unwrap_or_default();
    if options.force_cpu && (args.gpu || args.both) {
        bail!("--cpu cannot be combined with --gpu or --both");
    }
    let frames = frame_dirs(&frames_args)?;
    let models_dir = shipped_or(&args.models, super::detect::SHIPPED_MODELS);
    let mut models = read_models_dir(&models_dir, None)?;
    if models.is_empty() {
        bail!("{}: no detector models (<category>.json) to benchmark", models_dir.display());
    }
    if let Some(step) = args.detect_step {
        for model in &mut models {
            model.window.step = step;
        }
    }
    super::detect::warn_if_no_supporters(&models_dir, &models);
    let cascade = cascade_for(&models_dir, &models, false)?;
    let layout_model = super::layout::model_in_dir(&models_dir)?;
    let gpu = if options.force_cpu { None } else { cog_gpu::gpu::acquire(false) };
    if args.gpu && gpu.is_none() {
        bail!("--gpu: no GPU adapter (see the warning above)");
    }
    let mut backends = Vec::new();
    if let Some(ctx) = &gpu {
        backends.push(Backend::Gpu(ctx));
    }
    if !args.gpu {
        backends.push(Backend::Cpu);
    }
    let normals = super::detect::normal_search_for(&models_dir, &models, args.normals)?;
    let detect_options = DetectOptions {
        normals,
        box_voting: args.box_voting.0,
        unseen_floor: args.unseen_floor.0,
        cross_scores: cascade.as_ref().is_some_and(cog_gpu::cascade::Cascade::reads_cross_scores),
        ..DetectOptions::default()
    };
    let bench = Bench { models: &models, cascade: cascade.as_ref(), layout_model: layout_model.as_ref() };
    let mut paths = serde_json::Map::new();
    let mut detections_per_path = Vec::new();
    for backend in &backends {
        let first = frames.first().context("no frames")?;
        for _ in 0..args.warmup {
            bench.frame(first, *backend, &detect_options)?;
        }
        let mut times = Vec::new();
        let mut detections = Vec::new();
        // GPU memory kept in the context's pools after each frame (trimmed at each frame's end).
        let mut pooled_mb = Vec::new();
        for dir in &frames {
            for _ in 0..args.repeat {
                let (frame_times, found) = bench.frame(dir, *backend, &detect_options)?;
                times.push(frame_times);
                detections.push(found);
                if let Backend::Gpu(ctx) = backend {
                    pooled_mb.push(ctx.pooled_bytes() as f64 * 1e-6);
                }
            }
        }
        let pipelined = match args.in_flight {
            Some(n) => Some(bench.in_flight(&frames, args.repeat, n, *backend, &detect_options, &detections)?),
            None => None,
        };
        let adapter = match backend {
            Backend::Gpu(ctx) => ctx.adapter_summary(),
            Backend::Cpu => format!("CPU, rayon, {} threads", rayon::current_num_threads()),
        };
        // On a software adapter the fast path stays on the CPU (backend::Backend::fast_scores).
        let fast_kernel = match backend {
            Backend::Gpu(ctx) => use_kernel_on(ctx),
            Backend::Cpu => false,
        };
        paths.insert(
            backend.name().into(),
            json!({
                "adapter": adapter,
                "fast_kernel": fast_kernel,
                "mean": mean_times(&times),
                "frames": times,
                "in_flight": pipelined,
                "pooled_mb": match backend {
                    Backend::Gpu(_) => json!({
                        "max": pooled_mb.iter().copied().fold(0.0, f64::max),
                        "last": pooled_mb.last().copied().unwrap_or(0.0),
                    }),
                    Backend::Cpu => serde_json::Value::Null,
                },
            }),
        );
        detections_per_path.push(detections);
    }
    let agreement = match detections_per_path.as_slice() {
        [gpu_found, cpu_found] => Some(json!(compare_paths(gpu_found, cpu_found))),
        _ => None,
    };
    let report = json!({
        "frames": frames.len(),
        "repeat": args.repeat,
        "warmup": args.warmup,
        "models": models.iter().map(|m| m.category.as_str()).collect::<Vec<_>>(),
        "steps": models.iter().map(|m| m.window.step).collect::<Vec<_>>(),
        "normals": detect_options.normals.name(),
        // The IoU as the option is written ("0.3", not the f32's 0.30000001192092896), null when off.
        "box_voting": detect_options.box_voting.map(|iou| iou.to_string()),
        "unseen_floor": detect_options.unseen_floor,
        "layout_model": layout_model.is_some(),
        "cascade": cascade.is_some(),
        "paths": paths,
        "gpu_vs_cpu": agreement,
    });
    if args.json {
        out!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report)?;
    }
    for (name, path) in report["paths"].as_object().into_iter().flatten() {
        if path["in_flight"]["same_as_one_at_a_time"] == json!(false) {
            bail!(
                "{name} path: frames in flight detected other boxes or scores than one at a time: {}",
                path["in_flight"]["vs_one_at_a_time"]
            );
        }
    }
    if let Some(agreement) = &agreement {
        if agreement["same"] == json!(false) {
            bail!("the GPU and CPU paths detected different boxes or scores: {agreement}");
        }
    }
    Ok(())
}

/// What one benchmarked detection needs besides the frame.
struct Bench<'a> {
    models: &'a [cog_gpu::model::Model],
    cascade: Option<&'a cog_gpu::cascade::Cascade>,
    layout_model: Option<&'a cog_gpu::room_layout::model::LayoutModel>,
}

impl Bench<'_> {
    /// Detects in the frame at `dir` as `cog-gpu detect` does, timing each stage.
    fn frame(
        &self,
        dir: &Path,
        backend: Backend,
        detect_options: &DetectOptions,
    ) -> anyhow::Result<(FrameTimes, Vec<Detection>)> {
        let mut clock = Stopwatch::start();
        let mut lap = || clock.lap();
        let mut times = FrameTimes::default();
        let mut cpu_s = 0.0;
        let frame = Frame::read(dir, DepthSource::Raw)?;
        times.frame = frame.name.clone();
        let read = lap();
        times.read_s = read.wall_s;
        let pre = backend
            .preprocess(&frame, detect_options.normals)
            .with_context(|| format!("preprocessing {}", dir.display()))?;
        let preprocess = lap();
        (times.preprocess_s, times.preprocess_cpu_s) = (preprocess.wall_s, read.cpu_s + preprocess.cpu_s);
        let mut detections =
            detect_preprocessed_timed(&frame.name, pre, self.models, backend, detect_options, &mut times.stages)
                .with_context(|| format!("detecting in {}", dir.display()))?;
        cpu_s += lap().cpu_s;
        let layout = lay_out(&frame, self.layout_model, backend)?;
        let laid_out = lap();
        (times.layout_s, times.layout_cpu_s) = (laid_out.wall_s, laid_out.cpu_s);
        rescore_in_room(self.cascade, &mut detections, layout.as_ref())?;
        let rescored = lap();
        times.cascade_s = rescored.wall_s;
        let found = detections.detections.clone();
        let report = FrameReport { detections, layout: layout.as_ref().map(|(_, record)| record.clone()), run: None };
        let text = serde_json::to_string_pretty(&report)?;
        let picture = overlay_picture(
            &frame,
            &best_of(&report, DEFAULT_OVERLAY_TOP, DEFAULT_OVERLAY_MIN_PROBABILITY, detect_options.nms_iou),
            layout.as_ref().map(|(p, _)| &p.room),
        );
        std::hint::black_box((text, picture));
        let output = lap();
        times.output_s = output.wall_s;
        times.detections = found.len();
        times.total_s = times.read_s
            + times.preprocess_s
            + times.stages.total_s()
            + times.cascade_s
            + times.layout_s
            + times.output_s;
        // The whole frame: its laps, the detection (whose stages `stages` splits) as one of them.
        times.cpu_s = times.preprocess_cpu_s + cpu_s + laid_out.cpu_s + rescored.cpu_s + output.cpu_s;
        Ok((times, found))
    }

    /// The `--in-flight` pass: every frame `repeat` times (in the first pass's order), `in_flight` at a
    /// time; its wall-clock seconds per frame and whether its detections equal `one_at_a_time`'s.
    fn in_flight(
        &self,
        frames: &[std::path::PathBuf],
        repeat: usize,
        in_flight: usize,
        backend: Backend,
        detect_options: &DetectOptions,
        one_at_a_time: &[Vec<Detection>],
    ) -> anyhow::Result<serde_json::Value> {
        let work: Vec<&std::path::PathBuf> = frames.iter().flat_map(|f| std::iter::repeat_n(f, repeat)).collect();
        let started = std::time::Instant::now();
        let outcomes = super::in_flight::in_flight(
            &work,
            in_flight,
            |_, dir| self.frame(dir, backend, detect_options).map(|(_, found)| found),
            |outcome| outcome.is_err(),
        );
        let wall_s = started.elapsed().as_secs_f64();
        let mut found = Vec::new();
        for outcome in outcomes.into_iter().flatten() {
            found.push(outcome?);
        }
        let agreement = compare_paths(&found, one_at_a_time);
        Ok(json!({
            "frames_in_flight": in_flight,
            "detections": work.len(),
            "wall_s": wall_s,
            "s_per_frame": wall_s / work.len() as f64,
            "same_as_one_at_a_time": agreement.same,
            "vs_one_at_a_time": agreement,
        }))
    }
}

/// The mean over the frames (and repeats) of every number of [`FrameTimes`], and the scoring throughput.
fn mean_times(times: &[FrameTimes]) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = times.iter().map(|t| json!(t)).collect();
    let mut mean = serde_json::Map::new();
    if let Some(first) = rows.first().and_then(|r| r.as_object()) {
        for key in first.keys().filter(|k| first[*k].is_number()) {
            let sum: f64 = rows.iter().filter_map(|r| r[key].as_f64()).sum();
            mean.insert(key.clone(), json!(sum / rows.len() as f64));
        }
    }
    let hypotheses: f64 = times.iter().map(|t| t.stages.hypotheses as f64).sum();
    let score_s: f64 = times.iter().map(|t| t.stages.score_s).sum();
    mean.insert("hypotheses_per_s".into(), json!(hypotheses / score_s.max(f64::MIN_POSITIVE)));
    // Each model's window per frame, as `hypotheses` is (categories whose window scored nothing over the
    // run — without a model, or a surface model with no surface to search — left out).
    let per_category: serde_json::Map<String, serde_json::Value> = cog_gpu::category::CATEGORIES
        .iter()
        .enumerate()
        .map(|(c, name)| (name, times.iter().map(|t| t.stages.hypotheses_per_category[c] as f64).sum::<f64>()))
        .filter(|&(_, total)| total > 0.0)
        .map(|(name, total)| (name.to_string(), json!(total / times.len().max(1) as f64)))
        .collect();
    mean.insert("hypotheses_per_category".into(), serde_json::Value::Object(per_category));
    serde_json::Value::Object(mean)
}

/// The text report: one row of mean stage seconds per path, and the GPU/CPU ratio.
fn print_report(report: &serde_json::Value) -> anyhow::Result<()> {
    out!(
        "{} frame(s) × {} repeat(s) after {} warm-up detection(s); models: {}; layout model: {}; cascade: {}; box voting: {}",
        report["frames"],
        report["repeat"],
        report["warmup"],
        report["models"]
            .as_array()
            .map(|m| m.iter().filter_map(|c| c.as_str()).collect::<Vec<_>>().join(","))
            .unwrap_or_default(),
        report["layout_model"],
        report["cascade"],
        report["box_voting"].as_str().map_or("off".to_string(), |iou| format!("IoU {iou}"))
    );
    let columns = [
        "read_s",
        "preprocess_s",
        "yaw_grids_s",
        "window_s",
        "lattices_s",
        "score_s",
        "select_s",
        "nms_s",
        "cross_scores_s",
        "cascade_s",
        "layout_s",
        "output_s",
        "total_s",
    ];
    out!("mean seconds per frame:");
    out!("{:>5} {}", "path", columns.iter().map(|c| format!(" {:>10}", c.trim_end_matches("_s"))).collect::<String>());
    let paths = report["paths"].as_object().cloned().unwrap_or_default();
    for (name, path) in &paths {
        let values: String =
            columns.iter().map(|c| format!(" {:>10.4}", path["mean"][c].as_f64().unwrap_or(f64::NAN))).collect();
        out!("{name:>5} {values}");
    }
    // Every per-stage CPU figure of the JSON (select, nms and cross_scores were left out of this table).
    let cpu_columns = [
        "preprocess_cpu_s",
        "yaw_grids_cpu_s",
        "window_cpu_s",
        "lattices_cpu_s",
        "score_cpu_s",
        "select_cpu_s",
        "nms_cpu_s",
        "cross_scores_cpu_s",
        "layout_cpu_s",
        "cpu_s",
    ];
    out!("mean process CPU seconds per frame (all threads):");
    out!(
        "{:>5} {}",
        "path",
        cpu_columns
            .iter()
            .map(|c| format!(" {:>10}", c.trim_end_matches("_s").trim_end_matches("_cpu")))
            .collect::<String>()
    );
    for (name, path) in &paths {
        let values: String =
            cpu_columns.iter().map(|c| format!(" {:>10.4}", path["mean"][c].as_f64().unwrap_or(f64::NAN))).collect();
        out!("{name:>5} {values}");
    }
    for (name, path) in &paths {
        out!(
            "{name:>5}: {:.0} hypotheses/s in scoring; tables {:.3} thread-s per frame; fast kernel: {}  [{}]",
            path["mean"]["hypotheses_per_s"].as_f64().unwrap_or(0.0),
            path["mean"]["tables_thread_s"].as_f64().unwrap_or(0.0),
            path["fast_kernel"],
            path["adapter"].as_str().unwrap_or("?")
        );
    }
    for (name, path) in &paths {
        if let Some(per_category) = path["mean"]["hypotheses_per_category"].as_object() {
            let mut counts: Vec<(&String, f64)> =
                per_category.iter().map(|(category, n)| (category, n.as_f64().unwrap_or(0.0))).collect();
            counts.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(b.0)));
            let listed: Vec<String> = counts.iter().map(|(category, n)| format!("{category} {n:.0}")).collect();
            out!("{name:>5}: hypotheses per frame by model, most first: {}", listed.join(", "));
        }
    }
    for (name, path) in &paths {
        if let Some(pooled) = path["pooled_mb"].as_object() {
            out!(
                "{name:>5}: GPU memory kept in the buffer pools after a frame: {:.1} MB at most, {:.1} MB after the \
                 last",
                pooled["max"].as_f64().unwrap_or(0.0),
                pooled["last"].as_f64().unwrap_or(0.0)
            );
        }
    }
    for (name, path) in &paths {
        if let Some(pass) = path["in_flight"].as_object() {
            out!(
                "{name:>5}: {} frames in flight: {:.4} s per frame wall-clock ({} detections in {:.3} s; one at a \
                 time: {:.4} s per frame); same detections: {}",
                pass["frames_in_flight"],
                pass["s_per_frame"].as_f64().unwrap_or(f64::NAN),
                pass["detections"],
                pass["wall_s"].as_f64().unwrap_or(f64::NAN),
                path["mean"]["total_s"].as_f64().unwrap_or(f64::NAN),
                pass["same_as_one_at_a_time"]
            );
        }
    }
    if let (Some(gpu), Some(cpu)) = (paths.get("gpu"), paths.get("cpu")) {
        let ratio = |c: &str| cpu["mean"][c].as_f64().unwrap_or(f64::NAN) / gpu["mean"][c].as_f64().unwrap_or(f64::NAN);
        out!("GPU speed-up (CPU time / GPU time): total {:.2}×, scoring {:.2}×", ratio("total_s"), ratio("score_s"));
        out!("gpu vs cpu detections: {}", report["gpu_vs_cpu"]);
    }
    Ok(())
}
