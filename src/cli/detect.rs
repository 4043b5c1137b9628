//! `cog-gpu detect [FRAME_DIR...] [--models DIR] [--out DIR] [--categories a,b,...] ...`: detects objects
//! with trained models and writes, per frame, `<out>/<frame>.json` (detections) and `<out>/<frame>.png`
//! (overlay). See `cog_gpu::detect` for what happens per frame. When the models directory also holds
//! `layout.json` (`cog_gpu::room_layout`), the room is laid out too: its record goes under `"layout"` in
//! `<frame>.json` (and in the frame's entry of the `--json` array on stdout) and its edges on the overlay. `--ply` writes `<out>/<frame>.ply`: the coloured upright
//! point cloud with the overlay's cuboids and the room as line sets (`cog_gpu::ply`).
//!
//! Defaults: every frame under `assets/sample/`, the models of `assets/models/`, output `detections/`.
//! When a default `assets/...` path does not exist relative to the current directory, the crate's own
//! `assets/` is used, so `cargo run --release -- detect` works from anywhere in a checkout. A frame that
//! cannot be read or detected in is reported and skipped; the run goes on with the other frames and exits
//! with an error listing the failed frames at the end (`--fail-fast`: stop at the first one; files
//! already written are kept either way).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use cog_gpu::backend::Backend;
use cog_gpu::cascade::Cascade;
use cog_gpu::category::{normalise_name, SURFACE_CATEGORIES};
use cog_gpu::detect::{
    detect_frame, overlay, overlay_selection, DetectOptions, DEFAULT_OVERLAY_MIN_PROBABILITY, DEFAULT_OVERLAY_TOP,
    DEFAULT_SUPPORT_MIN_SCORE, REVOTE_DEMOTION,
};
use cog_gpu::draw::category_colour;
use cog_gpu::eval::FrameDetections;
use cog_gpu::features::preprocess::NormalSearch;
use cog_gpu::frame::RoomLayout;
use cog_gpu::frame::{is_frame_dir, DepthSource, Frame};
use cog_gpu::gpu::fast::use_kernel_on;
use cog_gpu::model::{common_normal_search, read_models_dir, Model};
use cog_gpu::nms::DEFAULT_NMS_IOU;
use cog_gpu::room_layout::output::LayoutRecord;
use cog_gpu::room_layout::PredictedLayout;
use image::RgbImage;
use indicatif::{ProgressBar, ProgressStyle};

use super::{options, GlobalOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Frame directories, or directories searched recursively for frames; default: `assets/sample/`.
    pub frames: Vec<PathBuf>,
    /// Directory of model files (`<category>.json`).
    #[arg(long, default_value = SHIPPED_MODELS)]
    pub models: PathBuf,
    /// Output directory for `<frame>.json` and `<frame>.png`.
    #[arg(long, default_value = "detections")]
    pub out: PathBuf,
    /// Only these categories (comma-separated); default: every model in --models. A category searched on
    /// support surfaces (a model with `"support": "surfaces"` or `"floor+surfaces"`: in the shipped models
    /// the monitor and the sink) brings the models of its supporters among the surface categories (bed,
    /// table, desk, dresser, nightstand, sofa, counter; the shipped monitor's desks, the sink's counters)
    /// with it, whose detections carry the surfaces; their detections are reported too.
    #[arg(long, value_delimiter = ',')]
    pub categories: Vec<String>,
    /// IoU above which 3D NMS suppresses a lower-scoring box of the same category.
    #[arg(long, default_value_t = DEFAULT_NMS_IOU)]
    pub nms_iou: f32,
    /// Box voting after the NMS: each kept box becomes the weighted mean of the window's boxes whose 3D IoU
    /// with it is at least this IoU (in (0, 1]; weights: each box's odds of being right against the kept
    /// box's), then the NMS again over the voted boxes (one that moved onto a better one is demoted, its
    /// odds 400 times lower), or
    /// `off`: the kept boxes as the window made them. README, "Box voting"
    #[arg(long, default_value_t, value_parser = options::box_voting)]
    pub box_voting: options::BoxVoting,
    /// Where the camera does not see the floor (the lowest points are no horizontal plane), the floor's
    /// models also search a second floor 1.3 m below the camera, their boxes of both floors through one
    /// NMS (`on`), or only the lowest points' floor (`off`, as before 2026-12-07). README, "The floor where
    /// it is not seen"
    #[arg(long, default_value_t, value_name = "on|off", value_parser = options::unseen_floor)]
    pub unseen_floor: options::UnseenFloor,
    /// Detections kept per category and frame.
    #[arg(long, default_value_t = 20, value_parser = options::at_least_one)]
    pub max_per_category: usize,
    /// Drop detections whose raw score (w·φ + bias, before calibration) is below this, for every model
    /// (instead of the default cut, see --min-probability).
    #[arg(long, allow_hyphen_values = true, conflicts_with = "min_probability")]
    pub min_score: Option<f32>,
    /// Keep the detections whose first-stage calibrated probability (the reported `score` before the
    /// cascade) is at least P, in (0, 1); every model must be calibrated. Default: 0.001 for every
    /// calibrated model (all shipped ones; README, "Detection"), a model without a calibration cut at its
    /// own raw `threshold`.
    #[arg(long, value_name = "P")]
    pub min_probability: Option<f32>,
    /// Small objects are searched on the support surfaces of the detections of the surface categories
    /// (bed, table, desk, dresser, nightstand, sofa, counter) whose calibrated score is at least this.
    #[arg(long, default_value_t = DEFAULT_SUPPORT_MIN_SCORE, value_parser = options::probability)]
    pub support_min_score: f32,
    /// Overrides every model's sliding-window centre step (metres; each model's file has its own: 0.2 for
    /// the shipped models but the nightstand, box, pillow, lamp and monitor, 0.1): finer is slower (4× the
    /// hypotheses at 0.1) and places boxes more precisely.
    #[arg(long, value_parser = options::step)]
    pub step: Option<f32>,
    /// How each point's normal finds its plane-fit neighbours: `kdtree` (the 15 nearest of all points, by a
    /// k-d tree; the shipped models were trained so), `window` (the 15 nearest within the 7×7 pixels around
    /// it; README, "Normals in an image window") or `kdtree-40` (the 40 nearest, by the k-d tree).
    /// Default: the one the models were trained with (`features.normals` in their files; every shipped
    /// model's is `kdtree`).
    #[arg(long, value_parser = options::normal_search)]
    pub normals: Option<NormalSearch>,
    /// Do not write the overlay pictures.
    #[arg(long)]
    pub no_overlay: bool,
    /// Boxes drawn on an overlay: the frame's best this many detections over all categories (the JSON keeps
    /// all of them); a picture with every box above the threshold is unreadable.
    #[arg(long, default_value_t = DEFAULT_OVERLAY_TOP)]
    pub overlay_top: usize,
    /// The overlay (and `--ply`'s boxes) leaves out calibrated detections whose probability (`score`) is
    /// below this: by default it draws only boxes more likely right than wrong, so a frame where nothing is
    /// found shows no box; 0 draws the best `--overlay-top` whatever their probability. Detections of
    /// uncalibrated models (raw scores) are not cut. The JSON keeps every detection.
    #[arg(long, default_value_t = DEFAULT_OVERLAY_MIN_PROBABILITY, value_parser = options::probability)]
    pub overlay_min_score: f32,
    /// Print the detections of all frames as one JSON array on stdout (each entry as the frame's detections
    /// file, with the room under "layout" when there is a layout model).
    #[arg(long)]
    pub json: bool,
    /// Do not apply the context cascade (`<models>/cascade.json`) even when the models directory has one:
    /// report the first-stage detections (as `cog-gpu cascade` needs for training), each of the ten large
    /// categories and the counter with its cross scores (`cog_gpu::detect::cross_scores`).
    #[arg(long)]
    pub no_cascade: bool,
    /// Also write `<frame>.ply`: the coloured upright point cloud with the overlay's cuboids (and the room,
    /// when there is a layout model) as line sets.
    #[arg(long)]
    pub ply: bool,
    /// Stop at the first frame that cannot be read or detected in (default: report it, go on with the
    /// others and fail at the end).
    #[arg(long)]
    pub fail_fast: bool,
    /// Keep the frames already detected in --out (a `<frame>.json` that reads as that frame's detections
    /// file) and detect only the others: an interrupted run over many frames goes on where it stopped. The
    /// kept files must come from the same models and options (their `"run"` fingerprint; a mismatch stops
    /// the run before anything is detected); the kept frames' overlays and PLY files are not drawn again.
    #[arg(long)]
    pub resume: bool,
    /// Frames detected at once, so that one frame's CPU stages overlap another's GPU work (same
    /// detections; each frame in flight adds ~0.5 GB of memory at step 0.1). Default: 3 when the GPU
    /// scores the fast path, else 1 (on the CPU path every core is already busy).
    #[arg(long, value_name = "N", value_parser = options::at_least_one)]
    pub in_flight: Option<usize>,
}

/// Default of `detect --in-flight` when the GPU scores the fast path. Measured on an H200 with 16 cores
/// (README, "End to end"), seconds per frame at step 0.1: 0.74–0.79 one at a time, 0.66 with two in
/// flight, 0.605–0.615 with three, 0.64–0.68 with four (two runs); three, for ~1 GB more host memory than
/// one.
pub const GPU_IN_FLIGHT: usize = 3;

/// The shipped models directory: the default of `--models` wherever a command reads models, one constant
/// for the flag and for [`shipped_or`].
pub(super) const SHIPPED_MODELS: &str = "assets/models";
/// The shipped layout model (`layout --model`).
pub(super) const SHIPPED_LAYOUT: &str = "assets/models/layout.json";
/// The shipped cascade (`rescore --cascade`).
pub(super) const SHIPPED_CASCADE: &str = "assets/models/cascade.json";

/// `given`, unless it is the flag's `default` (a path under `assets/`): then [`resolve_default`]'s, so that
/// the shipped models and frames are found from any directory. Only flags that read use it (`detect`,
/// `bench`, `layout`, `rescore`, `merge-detections`); `calibrate` and `cascade` write into their models
/// directory, which stays relative to the working directory.
pub(super) fn shipped_or(given: &Path, default: &str) -> PathBuf {
    if given == Path::new(default) {
        resolve_default(given)
    } else {
        given.to_path_buf()
    }
}

/// `path` if it exists, else the same relative path inside the crate's checkout (for the defaults).
pub(super) fn resolve_default(path: &Path) -> PathBuf {
    if path.exists() || path.is_absolute() {
        return path.to_path_buf();
    }
    let in_crate = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
    if in_crate.exists() {
        in_crate
    } else {
        path.to_path_buf()
    }
}

/// Frame directories of the arguments (each a frame, or searched recursively).
pub(super) fn frame_dirs(args: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let roots = if args.is_empty() { vec![resolve_default(Path::new("assets/sample"))] } else { args.to_vec() };
    let mut frames = Vec::new();
    for root in roots {
        if is_frame_dir(&root) {
            frames.push(root);
            continue;
        }
        if !root.is_dir() {
            bail!("{}: not a frame directory (intrinsics.txt and image/) nor a directory of frames", root.display());
        }
        let found = cog_gpu::frame::Dataset::open(&root)?.frames;
        if found.is_empty() {
            bail!("{}: no frame directories found", root.display());
        }
        frames.extend(found);
    }
    // One output file per frame name: two frames with the same directory name would overwrite each other.
    cog_gpu::frame::unique_frame_names(&frames)?;
    Ok(frames)
}

/// Warns when `models` (read from `models_dir`) hold models searched on support surfaces but none of the
/// models of their supporters: those models then find nothing on surfaces (`detect` and `bench --detect`).
pub(super) fn warn_if_no_supporters(models_dir: &Path, models: &[Model]) {
    let supporters = supporters_of(models);
    let has_surface_models = models.iter().any(|m| m.window.support.uses_surfaces());
    if has_surface_models && !models.iter().any(|m| supporters.contains(&m.category.as_str())) {
        log::warn!(
            "{} has models searched on support surfaces but none of {}: they will find nothing on surfaces",
            models_dir.display(),
            supporters.join(", ")
        );
    }
}

/// Why an uncalibrated model's detections under box voting are not comparable with a calibrated one's, or
/// `None` when voting is off or every model is calibrated. The NMS after the vote demotes a box it would
/// drop by [`REVOTE_DEMOTION`] log-odds, i.e. that many raw units over the model's calibration slope — 1
/// without a calibration, so an uncalibrated model's demoted boxes fall 6 raw units, mostly under the cut,
/// where a calibrated model's (slopes 5.9–20.7 for the shipped ones) fall 0.3–1.0 and are kept.
pub(super) fn uncalibrated_voting_warning(models: &[Model], box_voting: Option<f32>) -> Option<String> {
    box_voting?;
    let uncalibrated: Vec<&str> =
        models.iter().filter(|m| m.calibration.is_none()).map(|m| m.category.as_str()).collect();
    (!uncalibrated.is_empty()).then(|| {
        format!(
            "not calibrated: {}; box voting demotes the boxes its second NMS would drop by {REVOTE_DEMOTION} raw \
             units for such a model (by {REVOTE_DEMOTION} log-odds for a calibrated one), so they mostly fall \
             under the cut: calibrate it (cog-gpu calibrate) before comparing its detections with a calibrated \
             model's, or detect both with --box-voting off",
            uncalibrated.join(", ")
        )
    })
}

/// The normal search a run preprocesses with: `flag` (`--normals`) when given — with a warning when a model
/// was trained with another —, else the one the models share ([`common_normal_search`]; an error when they
/// differ).
pub(super) fn normal_search_for(
    models_dir: &Path,
    models: &[Model],
    flag: Option<NormalSearch>,
) -> anyhow::Result<NormalSearch> {
    let shared = common_normal_search(models);
    match (flag, shared) {
        (None, shared) => Ok(shared.with_context(|| models_dir.display().to_string())?),
        (Some(search), Ok(trained)) if search == trained => Ok(search),
        (Some(search), trained) => {
            let trained = match trained {
                Ok(trained) => format!("the {} normals", trained.name()),
                Err(_) => "different normal searches".to_string(),
            };
            log::warn!(
                "--normals {}: the models in {} were trained with {trained}; their scores will differ from \
                 those they were trained and calibrated on",
                search.name(),
                models_dir.display()
            );
            Ok(search)
        }
    }
}

/// The surface categories whose detections' surfaces some surface model of `models` searches.
fn supporters_of(models: &[Model]) -> Vec<&'static str> {
    SURFACE_CATEGORIES
        .iter()
        .copied()
        .filter(|c| models.iter().any(|m| m.window.support.uses_surfaces() && m.window.supporters.contains(c)))
        .collect()
}

/// The folders of a frame in the SUN RGB-D layout (README "Frames"), which `detect --out` must not write
/// into.
const FRAME_FOLDERS: [&str; 9] = [
    "image",
    "depth",
    "depth_bfx",
    "extrinsics",
    "annotation",
    "annotation2Dfinal",
    "annotation3D",
    "annotation3Dfinal",
    "annotation3Dlayout",
];

pub fn run(args: Args, options: &GlobalOptions) -> anyhow::Result<()> {
    let detect_options = DetectOptions {
        nms_iou: args.nms_iou,
        max_per_category: args.max_per_category,
        min_score: args.min_score,
        min_probability: args.min_probability,
        support_min_score: args.support_min_score,
        box_voting: args.box_voting.0,
        unseen_floor: args.unseen_floor.0,
        ..DetectOptions::default()
    };
    detect_options.validate()?;
    let categories: Vec<String> =
        options::names("--categories", &args.categories)?.iter().map(|c| normalise_name(c).0).collect();
    let models_dir = shipped_or(&args.models, SHIPPED_MODELS);
    let mut models = read_models_dir(&models_dir, (!categories.is_empty()).then_some(categories.as_slice()))?;
    let has_surface_models = models.iter().any(|m| m.window.support.uses_surfaces());
    // The surface models search the surfaces of their supporters' detections.
    let supporters = supporters_of(&models);
    if has_surface_models && !categories.is_empty() {
        let missing: Vec<String> = supporters
            .iter()
            .filter(|c| !models.iter().any(|m| m.category == **c) && models_dir.join(format!("{c}.json")).is_file())
            .map(|c| c.to_string())
            .collect();
        if !missing.is_empty() {
            log::info!("the support surfaces come from the detections of {}; detecting them too", missing.join(", "));
            models.extend(read_models_dir(&models_dir, Some(missing.as_slice()))?);
        }
    }
    warn_if_no_supporters(&models_dir, &models);
    let detect_options =
        DetectOptions { normals: normal_search_for(&models_dir, &models, args.normals)?, ..detect_options };
    if let Some(step) = args.step {
        for model in &mut models {
            model.window.step = step;
        }
    }
    for warning in models.iter().filter_map(|m| m.step_mismatch()) {
        log::warn!("{warning}");
    }
    // Every model's cut up front (a probability cut needs a calibration), so that a bad model stops the run
    // with its file named instead of failing every frame.
    for model in &models {
        detect_options
            .threshold(model)
            .with_context(|| models_dir.join(format!("{}.json", model.category)).display().to_string())?;
    }
    if let Some(warning) = uncalibrated_voting_warning(&models, detect_options.box_voting) {
        log::warn!("{}: {warning}", models_dir.display());
    }
    let cascade = cascade_for(&models_dir, &models, args.no_cascade)?;
    // First-stage files may train a cascade; a cascade with a cross stage reads them.
    let detect_options = DetectOptions {
        cross_scores: args.no_cascade || cascade.as_ref().is_some_and(Cascade::reads_cross_scores),
        ..detect_options
    };
    // The room layout comes with the detections when the models directory holds a layout model.
    let layout_model = super::layout::model_in_dir(&models_dir)?;
    let frames = frame_dirs(&args.frames)?;
    // Files written into a frame's own directory or its data folders would change the frame (`image/`
    // with two pictures is an error of every reader): refused before anything is written. A folder of its
    // own inside the frame (`detect .` from the frame's directory, `--out detections`) is fine.
    let out = super::options::resolved(&args.out);
    let writes_into = |frame: &PathBuf| match out.strip_prefix(super::options::resolved(frame)) {
        Ok(below) => {
            below.components().next().is_none_or(|first| FRAME_FOLDERS.iter().any(|f| first.as_os_str() == *f))
        }
        Err(_) => false,
    };
    if let Some(frame) = frames.iter().find(|f| writes_into(f)) {
        bail!(
            "--out {}: writes into the frame {} (its directory or one of its data folders); write the detections \
             elsewhere",
            args.out.display(),
            frame.display()
        );
    }
    let run = run_fingerprint(&models, cascade.as_ref(), layout_model.as_ref(), &detect_options)?;
    let finished =
        if args.resume { finished_reports(&args.out, &frames, &run)? } else { frames.iter().map(|_| None).collect() };
    let kept = finished.iter().flatten().count();
    // Each taken (once) by its frame's job below, which may run on another thread.
    let finished: Vec<std::sync::Mutex<Option<FrameReport>>> =
        finished.into_iter().map(std::sync::Mutex::new).collect();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    // Both feature paths score on the GPU when there is one (fast: gpu::fast, exact: gpu::features).
    let gpu = if models.is_empty() { None } else { cog_gpu::gpu::acquire(options.force_cpu) };
    let backend = Backend::of(gpu.as_ref());
    log::info!(
        "{} frame(s), models: {}",
        frames.len(),
        models.iter().map(|m| m.category.as_str()).collect::<Vec<_>>().join(", ")
    );
    let progress = if frames.len() > 1 { ProgressBar::new(frames.len() as u64) } else { ProgressBar::hidden() };
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} frames, {elapsed_precise} (eta {eta}) {msg}")
    {
        progress.set_style(style);
    }
    let started = Instant::now();
    let in_flight = args.in_flight.unwrap_or(match backend {
        Backend::Gpu(ctx) if use_kernel_on(ctx) => GPU_IN_FLIGHT,
        _ => 1,
    });
    if in_flight > 1 && frames.len() > 1 {
        log::info!("{in_flight} frames in flight");
    }
    let job = DetectRun {
        models: &models,
        cascade: cascade.as_ref(),
        layout_model: layout_model.as_ref(),
        backend,
        detect_options: &detect_options,
        args: &args,
        fingerprint: &run,
    };
    let outcomes = super::in_flight::in_flight(
        &frames,
        in_flight,
        |n, dir| {
            progress.set_message(cog_gpu::frame::frame_name(dir));
            if let Some(report) = finished[n].lock().ok().and_then(|mut f| f.take()) {
                progress.inc(1);
                return Ok(report);
            }
            let outcome = detect_one(dir, &job);
            if let (Err(err), false) = (&outcome, args.fail_fast) {
                progress.suspend(|| log::error!("{}: skipped: {}", dir.display(), super::error_text(err)));
            }
            progress.inc(1);
            outcome
        },
        |outcome| args.fail_fast && outcome.is_err(),
    );
    let mut results = Vec::new();
    let mut failures = Vec::new();
    for (dir, outcome) in frames.iter().zip(outcomes) {
        match outcome {
            Some(Ok(detections)) => results.push(detections),
            // The first failed frame in frame order (with several in flight, a later one may fail first).
            Some(Err(err)) if args.fail_fast => return Err(err),
            Some(Err(err)) => failures.push((dir.clone(), err)),
            None => {}
        }
    }
    progress.finish_and_clear();
    if kept > 0 {
        log::info!("--resume: kept {kept} frame(s) already detected in {}", args.out.display());
    }
    if args.json {
        out!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        print_summary(&results, &args, started.elapsed().as_secs_f64())?;
    }
    super::batch_result(&failures, frames.len())
}

/// The cascade to apply: `<models>/cascade.json` unless `--no-cascade` or absent. Its context categories
/// must all have a loaded model (the second stage was trained on their detections): with `--categories`
/// leaving one out, the cascade is skipped with a warning.
pub(super) fn cascade_for(
    models_dir: &Path,
    models: &[cog_gpu::model::Model],
    no_cascade: bool,
) -> anyhow::Result<Option<Cascade>> {
    let path = models_dir.join(cog_gpu::cascade::FILE_NAME);
    if no_cascade || !path.is_file() {
        return Ok(None);
    }
    let cascade = Cascade::read(&path)?;
    if let Some(model) = models.iter().find(|m| m.calibration.is_none()) {
        log::warn!(
            "{}: not applied, the '{}' model is not calibrated (the cascade reads calibrated scores)",
            path.display(),
            model.category
        );
        return Ok(None);
    }
    if let Err(mismatch) = cascade.check_models(models) {
        log::warn!("{}: not applied (first-stage scores reported): {mismatch}", path.display());
        return Ok(None);
    }
    let missing: Vec<&str> =
        cascade.categories.iter().filter(|c| !models.iter().any(|m| &m.category == *c)).map(String::as_str).collect();
    if !missing.is_empty() {
        log::warn!(
            "{}: not applied, its context categories {} have no loaded model (first-stage scores reported)",
            path.display(),
            missing.join(", ")
        );
        return Ok(None);
    }
    let exclusion = cascade
        .exclusion
        .map(|e| format!(", cross-category exclusion IoU {} weight {}", e.iou, e.weight))
        .unwrap_or_default();
    let map = cascade
        .final_calibration
        .as_ref()
        .map(|c| format!(", final calibration a = {:.4}, b = {:.4}, c = {:.4}", c.a, c.b, c.c))
        .unwrap_or_default();
    log::info!("context cascade: {} ({} stages{exclusion}{map})", path.display(), cascade.stages.len());
    Ok(Some(cascade))
}

/// What `detect` reports of one frame: the detections file `{"frame", "detections"}`, plus `"layout"` (the
/// layout file's record) when the room was laid out. Written to `<frame>.json` and, with `--json`, as one
/// entry of the array on stdout.
#[derive(serde::Serialize, serde::Deserialize)]
pub(super) struct FrameReport {
    #[serde(flatten)]
    pub detections: FrameDetections,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layout: Option<LayoutRecord>,
    /// [`run_fingerprint`] of the run that wrote the file (absent in files of cog-gpu before it was
    /// recorded, and in `bench --detect`'s reports, which are not written).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
}

/// The `"run"` of a detections file: a 64-bit FNV-1a fingerprint (16 hex digits) of everything that
/// decides a frame's detections besides the frame — every model as loaded (after `--step`; their JSON,
/// in category order), the context cascade when one is applied, the layout model, and the detection
/// options (NMS IoU, detections per category, the cut, the support surfaces' cut, the normals' search) — so
/// that `--resume` keeps only files that this run would have written. Options that change only the pictures
/// (`--overlay-*`, `--no-overlay`, `--ply`) and the backend are left out; the GPU and CPU paths give the
/// same detections.
/// A cog-gpu build that serialises a model differently gives another fingerprint (such files are refused
/// by `--resume`, which is the safe side).
fn run_fingerprint(
    models: &[cog_gpu::model::Model],
    cascade: Option<&Cascade>,
    layout_model: Option<&cog_gpu::room_layout::model::LayoutModel>,
    options: &DetectOptions,
) -> anyhow::Result<String> {
    let mut sorted: Vec<&cog_gpu::model::Model> = models.iter().collect();
    sorted.sort_by(|a, b| a.category.cmp(&b.category));
    let mut parts = Vec::new();
    for model in sorted {
        parts.push(serde_json::to_string(model)?);
    }
    parts.push(cascade.map(serde_json::to_string).transpose()?.unwrap_or_default());
    parts.push(layout_model.map(serde_json::to_string).transpose()?.unwrap_or_default());
    // The options as they printed before `normals` existed (the default search adds nothing); another
    // search is a part of its own.
    // So is box voting.
    let earlier = format!(
        "{:?}",
        DetectOptions {
            normals: NormalSearch::KdTree,
            box_voting: None,
            cross_scores: false,
            unseen_floor: false,
            ..*options
        }
    );
    parts.push(
        earlier
            .replace(", normals: KdTree", "")
            .replace(", box_voting: None", "")
            .replace(", cross_scores: false", "")
            .replace(", unseen_floor: false", ""),
    );
    if options.normals != NormalSearch::KdTree {
        parts.push(format!("normals: {}", options.normals.name()));
    }
    // Since 2026-12-05 the voted boxes go through the NMS again, and since 2026-12-06 the boxes it would
    // drop are demoted instead: files voted before then (a part without it) do not resume.
    if let Some(iou) = options.box_voting {
        parts.push(format!("box voting: {iou}, then NMS demoting by {}", cog_gpu::detect::REVOTE_DEMOTION));
    }
    // Since 2026-12-05 first-stage files carry the cross scores: those written before do not resume.
    if options.cross_scores {
        parts.push("cross scores".to_string());
    }
    // Since 2026-12-07 a frame whose floor is not seen is searched on a second floor too.
    if options.unseen_floor {
        parts.push(format!(
            "unseen floor: a second floor {} m below the camera",
            cog_gpu::features::preprocess::UNSEEN_FLOOR_CAMERA_HEIGHT_M
        ));
    }
    let hash = parts.iter().fold(cog_gpu::learn::checkpoint::FNV_OFFSET, |hash, part| {
        // Each part's length first, so that no two different lists of parts hash the same bytes.
        let hash = cog_gpu::learn::checkpoint::fnv1a(hash, &(part.len() as u64).to_le_bytes());
        cog_gpu::learn::checkpoint::fnv1a(hash, part.as_bytes())
    });
    Ok(format!("{hash:016x}"))
}

/// `--resume`: the report of every frame of `frames` whose `<frame>.json` an earlier run wrote to `out`
/// ([`finished_report`], `None` for the frames to detect), each file read once. Refuses to go on when one
/// was written by a run with another fingerprint (other models or options); warns about files without one
/// (written by an older cog-gpu), which are kept unchecked.
fn finished_reports(out: &Path, frames: &[PathBuf], run: &str) -> anyhow::Result<Vec<Option<FrameReport>>> {
    let reports: Vec<Option<(PathBuf, FrameReport)>> = frames.iter().map(|dir| finished_report(out, dir)).collect();
    let other: Vec<(&PathBuf, &str)> = reports
        .iter()
        .flatten()
        .filter_map(|(path, report)| report.run.as_deref().filter(|written| *written != run).map(|w| (path, w)))
        .collect();
    if let Some((path, written)) = other.first() {
        bail!(
            "--resume: {} of the detections files in {} were written with other models or options than this \
             run's (e.g. {}: run {written}, this run {run}); resume with the models and options of the run that \
             wrote them, or drop --resume to detect every frame again",
            other.len(),
            out.display(),
            path.display()
        );
    }
    let unchecked = reports.iter().flatten().filter(|(_, report)| report.run.is_none()).count();
    if unchecked > 0 {
        log::warn!(
            "--resume: {unchecked} detections file(s) in {} carry no run fingerprint (written by an older \
             cog-gpu): kept without checking their models and options",
            out.display()
        );
    }
    Ok(reports.into_iter().map(|r| r.map(|(_, report)| report)).collect())
}

/// `--resume`: the path and report of the frame in `dir` that an earlier run wrote to `out`, when
/// `<frame>.json` is there and reads as that frame's detections file (with a readable room when it has
/// one); else `None`, and the frame is detected again.
fn finished_report(out: &Path, dir: &Path) -> Option<(PathBuf, FrameReport)> {
    let name = cog_gpu::frame::frame_name(dir);
    let path = out.join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).ok()?;
    let detections = FrameDetections::parse(&path, &text).ok().filter(|d| d.frame == name)?;
    let file: serde_json::Value = serde_json::from_str(&text).ok()?;
    let layout = match file.get("layout") {
        None => None,
        Some(record) => Some(serde_json::from_value::<LayoutRecord>(record.clone()).ok()?),
    };
    let run = file.get("run").and_then(|r| r.as_str()).map(str::to_string);
    Some((path, FrameReport { detections, layout, run }))
}

/// What every frame of a `detect` run is detected with.
#[derive(Clone, Copy)]
struct DetectRun<'a> {
    models: &'a [cog_gpu::model::Model],
    cascade: Option<&'a Cascade>,
    layout_model: Option<&'a cog_gpu::room_layout::model::LayoutModel>,
    backend: Backend<'a>,
    detect_options: &'a DetectOptions,
    args: &'a Args,
    /// [`run_fingerprint`] of all of the above.
    fingerprint: &'a str,
}

/// Reads one frame, detects (rescores with `cascade`, lays out the room with `layout_model`), and writes
/// its detections file, overlay and PLY.
fn detect_one(dir: &Path, run: &DetectRun) -> anyhow::Result<FrameReport> {
    let DetectRun { models, cascade, layout_model, backend, detect_options, args, fingerprint } = *run;
    let frame = Frame::read(dir, DepthSource::Raw)?;
    let mut detections = detect_frame(&frame, models, backend, detect_options)
        .with_context(|| format!("detecting in {}", dir.display()))?;
    let layout = lay_out(&frame, layout_model, backend)?;
    rescore_in_room(cascade, &mut detections, layout.as_ref())?;
    let report = FrameReport {
        detections,
        layout: layout.as_ref().map(|(_, record)| record.clone()),
        run: Some(fingerprint.to_string()),
    };
    let json_path = args.out.join(format!("{}.json", frame.name));
    // Written beside and renamed into place: an interrupted run leaves no truncated `<frame>.json` that
    // `--resume` would have to tell from a finished one.
    cog_gpu::error::write_whole(&json_path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    let best = best_of(&report, args.overlay_top, args.overlay_min_score, args.nms_iou);
    let room = layout.as_ref().map(|(predicted, _)| &predicted.room);
    if !args.no_overlay {
        let png_path = args.out.join(format!("{}.png", frame.name));
        let img = overlay_picture(&frame, &best, room);
        cog_gpu::frame::write_png(&img, &png_path).context("writing the overlay")?;
    }
    if args.ply {
        let boxes = best
            .detections
            .iter()
            .map(|d| cog_gpu::ply::LineSet::from_box_corners(&d.cuboid().corners(), category_colour(&d.category)))
            .collect();
        super::layout::write_scene_ply(&args.out.join(format!("{}.ply", frame.name)), &frame, boxes, room)?;
    }
    Ok(report)
}

/// The frame's room with `layout_model` (none without one).
pub(super) fn lay_out(
    frame: &Frame,
    layout_model: Option<&cog_gpu::room_layout::model::LayoutModel>,
    backend: Backend,
) -> anyhow::Result<Option<(PredictedLayout, LayoutRecord)>> {
    let Some(model) = layout_model else { return Ok(None) };
    match super::layout::frame_layout(frame, Some(model), backend) {
        Ok(layout) => Ok(Some(layout)),
        // A frame the layout has no room for keeps its detections: no room in its file, the cascade's
        // no-room input (since 2026-12-08; the frame was skipped before).
        Err(error)
            if matches!(error.downcast_ref::<cog_gpu::error::Error>(), Some(cog_gpu::error::Error::NoRoom(_))) =>
        {
            log::warn!("{}: no room laid out ({error}); its detections are written without a room", frame.name);
            Ok(None)
        }
        Err(error) => {
            Err(error
                .context(format!("laying out the room of {} (the layout model of the models directory)", frame.name)))
        }
    }
}

/// Rescores the detections with `cascade` (when there is one), whose layout features read the room.
pub(super) fn rescore_in_room(
    cascade: Option<&Cascade>,
    detections: &mut FrameDetections,
    layout: Option<&(PredictedLayout, LayoutRecord)>,
) -> anyhow::Result<()> {
    if let Some(cascade) = cascade {
        let room = layout.map(|(predicted, _)| cog_gpu::cascade::Room {
            corners: predicted.room.corners.clone(),
            floor: predicted.room.floor,
        });
        cascade
            .rescore(&mut detections.detections, room.as_ref())
            .with_context(|| format!("rescoring the detections of {}", detections.frame))?;
    }
    Ok(())
}

/// The best `top` detections over all categories, one box per object (a box within `nms_iou` of a better
/// one of its category, or within the cross-category IoU of one of another, is not drawn), none of them a
/// calibrated one below `min_probability` (what the overlay draws: [`overlay_selection`]).
pub(super) fn best_of(report: &FrameReport, top: usize, min_probability: f32, nms_iou: f32) -> FrameDetections {
    FrameDetections {
        frame: report.detections.frame.clone(),
        detections: overlay_selection(&report.detections.detections, top, min_probability, nms_iou),
    }
}

/// The overlay picture: `best` drawn on the RGB, and the room's edges when there is a room.
pub(super) fn overlay_picture(frame: &Frame, best: &FrameDetections, room: Option<&RoomLayout>) -> RgbImage {
    let mut img = overlay(frame, best);
    if let Some(room) = room {
        let camera = cog_gpu::geometry::Camera::new(frame.intrinsics(), frame.rtilt());
        cog_gpu::room_layout::output::draw_room(&mut img, &camera, room, 2);
    }
    img
}

/// One line per frame: detections per category and the best score, and how many boxes the overlay drew
/// (so that a picture without a box is explained: nothing reached `--overlay-min-score`).
fn print_summary(results: &[FrameReport], args: &Args, seconds: f64) -> anyhow::Result<()> {
    for report in results {
        let r = &report.detections;
        let mut counts: Vec<(String, usize, f32)> = Vec::new();
        for d in &r.detections {
            match counts.iter_mut().find(|c| c.0 == d.category) {
                Some(c) => c.1 += 1,
                None => counts.push((d.category.clone(), 1, d.score)),
            }
        }
        let text: Vec<String> = counts.iter().map(|(c, n, best)| format!("{c} {n} (best {best:.2})")).collect();
        let drawn = if args.no_overlay {
            String::new()
        } else {
            let boxes = best_of(report, args.overlay_top, args.overlay_min_score, args.nms_iou).detections.len();
            format!("; overlay: {boxes} box(es) (calibrated score ≥ {})", args.overlay_min_score)
        };
        out!("{}: {} detections: {}{drawn}", r.frame, r.detections.len(), text.join(", "));
    }
    out!("wrote {} frame(s) to {} in {seconds:.1} s", results.len(), args.out.display());
    Ok(())
}
