//! `cog-gpu eval --data DIR --detections DIR [--iou 0.25] [--categories a,b,...] [--split LIST] [--json]
//! [--plots DIR]`: average precision of detection files against a dataset's ground truth with the SUN
//! RGB-D benchmark's rules (see [`cog_gpu::eval`]).
//!
//! Choices:
//! * Categories: without `--categories`, the ten large categories of the SUN RGB-D benchmark
//!   ([`LARGE_CATEGORIES`]), so that the mAP means the same thing on every dataset and matches the
//!   benchmark's (and the paper's) 10-class mAP; `--categories all` takes all 19. A requested category
//!   without ground truth in the evaluated frames has no AP: it shows as `-` in the table, as `null` in
//!   the JSON, and is left out of the mAP. Detections of other categories are ignored.
//! * Detection files: `DIR/<frame directory name>.json`. A frame without one counts as a frame without
//!   detections (the count is reported); a `.json` file naming no evaluated frame is reported as a
//!   warning and ignored. Two evaluated frames with the same directory name are an error (their
//!   detection files would be the same file).
//! * Plots are written only when `--plots DIR` is given (one `<category>.png` per category with ground
//!   truth); nothing is written next to the inputs unasked.
//! * APs in the JSON are fractions in [0, 1]; the table prints percentages.
//! * `--diagnose [--models DIR] [--step S]` replaces the AP report with the diagnosis of
//!   [`cog_gpu::diagnose`] (window recall only with `--models`: frames with ground truth of a category that
//!   has a model are read, preprocessed and windowed as `detect` does; evaluated categories without a model
//!   get no window numbers and a warning). `--models` and `--step` need `--diagnose`; so do
//!   `--overlay-top` and `--overlay-min-score`, the rule of the "overlay as drawn" line (`detect`'s), and
//!   `--objects`, the list of every ground-truth box ([`cog_gpu::diagnose::object_outcomes`]).
//! * `--ignore-out-of-view SHARE` takes the boxes with less than SHARE of their volume in view out of
//!   everything reported ([`cog_gpu::eval::ignore_boxes`], PASCAL VOC's "difficult" rule), after the
//!   frames are read and before anything is evaluated; the `--versus` set loses its detections on them by
//!   the same rule. Only boxes of evaluated categories are looked at (their frames are read for cameras).

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use cog_gpu::category::{CATEGORIES, LARGE_CATEGORIES};
use cog_gpu::detect::{DEFAULT_OVERLAY_MIN_PROBABILITY, DEFAULT_OVERLAY_TOP};
use cog_gpu::diagnose::{
    diagnose_categories, frame_window_best_ious, object_outcomes, overlay_precision, reliability, CategoryDiagnosis,
    FalseKindCounts, ObjectOutcome, OverlayPrecision, OverlayRule, Reliability, FOUND_AHEAD_PRECISION,
    MOSTLY_OUT_OF_VIEW, TOUCH_IOU,
};
use cog_gpu::draw::category_colour;
use cog_gpu::eval::{
    bootstrap_aps, evaluate_categories, ignore_boxes, mean_ap, percentile_interval, surface_accuracy, Bootstrap,
    CategoryEvaluation, Detection, FrameDetections, IgnoredCounts, SurfaceAccuracy, WithoutIgnored,
};
use cog_gpu::features::Preprocessed;
use cog_gpu::frame::{
    frame_name, read_positioned_annotations, unique_frame_names, Dataset, DepthSource, Frame, Object, PositionedObjects,
};
use cog_gpu::geometry::{in_view_share, Camera};
use cog_gpu::model::{read_models_dir, Model};
use cog_gpu::nms::DEFAULT_NMS_IOU;
use cog_gpu::synth::{read_support_heights, SUPPORT_FILE};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;

use super::{detection_files, options, GlobalOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Dataset directory: every frame directory below it is evaluated (ground truth from
    /// annotation3Dfinal/index.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Directory of detection files, one `<frame name>.json` per frame.
    #[arg(long)]
    pub detections: PathBuf,
    /// 3D IoU a detection needs with a ground-truth box to count as correct.
    #[arg(long, default_value_t = 0.25, value_parser = options::iou)]
    pub iou: f32,
    /// Comma-separated categories to evaluate, or `all` for the 19 [default: the 10 large ones].
    #[arg(long, value_delimiter = ',')]
    pub categories: Option<Vec<String>>,
    /// Evaluate only the frames listed in this file (one frame directory per line, relative to --data).
    #[arg(long)]
    pub split: Option<PathBuf>,
    /// Print one JSON object `{"iou", "ap": {category: AP or null}, "map", ...}` instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write a precision-recall PNG per category into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Print a diagnosis of where AP is lost (window recall ceiling, in-frame ranking, rank AP, overlay
    /// precision) instead of the AP report.
    #[arg(long)]
    pub diagnose: bool,
    /// Also report how close the detections' support surfaces (`surface_z`: measured from the points for
    /// the surface categories, in the latent slice for other models with latent surfaces) lie to the true
    /// ones of synthetic frames (their `synth_support.json`): per category, of the true positives, the
    /// share within 5 cm of the nearest and of the main (top) true surface.
    #[arg(long, conflicts_with_all = ["diagnose", "layout"])]
    pub surfaces: bool,
    /// With --diagnose: models directory (`<category>.json`) whose sliding windows give the window recall
    /// ceiling (reads and preprocesses every frame with ground truth of a modelled category).
    #[arg(long, requires = "diagnose")]
    pub models: Option<PathBuf>,
    /// Stop at the first frame whose annotations or detections file cannot be read (default: report it,
    /// evaluate the other frames and fail at the end with the list).
    #[arg(long)]
    pub fail_fast: bool,
    /// With --diagnose --models: overrides every model's window step (metres), as `detect --step`.
    #[arg(long, requires = "models", value_parser = options::step)]
    pub step: Option<f32>,
    /// With --diagnose --models: where a frame's floor is not seen, the window recall counts the second
    /// floor's boxes too (`on`, as `detect --unseen-floor` by default) or the lowest points' floor alone (`off`).
    #[arg(long, default_value_t, value_name = "on|off", value_parser = options::unseen_floor, requires = "models")]
    pub unseen_floor: options::UnseenFloor,
    /// With --diagnose: the "overlay as drawn" line measures the boxes `detect` draws with this
    /// `--overlay-top` (the same default as `detect`'s).
    #[arg(long, requires = "diagnose", default_value_t = DEFAULT_OVERLAY_TOP)]
    pub overlay_top: usize,
    /// With --diagnose: the "overlay as drawn" line measures the boxes `detect` draws with this
    /// `--overlay-min-score` (the same default as `detect`'s).
    #[arg(long, requires = "diagnose", default_value_t = DEFAULT_OVERLAY_MIN_PROBABILITY, value_parser = options::probability)]
    pub overlay_min_score: f32,
    /// With --diagnose: both overlay lines skip a box overlapping a better one of its own category at 3D IoU
    /// at least this — the detections' `detect --nms-iou` (the same default as `detect`'s).
    #[arg(long, requires = "diagnose", default_value_t = DEFAULT_NMS_IOU, value_parser = options::iou)]
    pub nms_iou: f32,
    /// With --diagnose: also list every ground-truth box of the evaluated categories — its frame, size,
    /// distance from the camera and share of its volume in the picture (reads each such frame's camera),
    /// the true positive that found it (score, IoU, the precision and the false positives before it in the
    /// category's ranking) or, when missed, the best IoU of the category's detections in its frame, and the
    /// most confident other category's detection on it; then per category the boxes mostly out of view.
    #[arg(long, requires = "diagnose")]
    pub objects: bool,
    /// Evaluate room layouts instead of detections: per-frame and mean free-space IoU of the `layout`
    /// files (or `detect` files with a "layout") in --detections against each frame's room annotation
    /// (see `eval_layout`).
    #[arg(long, conflicts_with_all = ["diagnose", "plots", "categories"])]
    pub layout: bool,
    /// Add a 90 % bootstrap interval to every AP and the mAP (with --layout: to the mean free-space IoU):
    /// N resamples of the evaluated frames with replacement (percentile intervals; see
    /// `cog_gpu::eval::bootstrap_aps`). 1 000 is a good N.
    #[arg(long, value_name = "N", conflicts_with = "diagnose", value_parser = clap::value_parser!(u32).range(2..=100_000))]
    pub bootstrap: Option<u32>,
    /// Seed of the bootstrap's resampling (same seed, same frames drawn, same interval).
    #[arg(long, default_value_t = 0, requires = "bootstrap")]
    pub bootstrap_seed: u64,
    /// With --bootstrap: a second detections directory of the same frames (e.g. another model); prints
    /// its APs and the paired 90 % interval of the difference (--detections minus --versus), both sets
    /// evaluated on the same resamples. With --layout: a second directory of layout files, and the paired
    /// interval of the difference of the mean free-space IoUs.
    #[arg(long, value_name = "DIR", requires = "bootstrap")]
    pub versus: Option<PathBuf>,
    /// Ignore the ground-truth boxes with less than SHARE of their volume in the picture, as PASCAL VOC
    /// ignores its "difficult" objects: such a box is no longer a positive, and a detection whose best box
    /// of its category is one (at IoU ≥ --iou) is dropped instead of counted false
    /// (`cog_gpu::eval::ignore_boxes`; the share is `cog_gpu::geometry::in_view_share`, which reads the
    /// camera of every frame with ground truth of an evaluated category). 0.25 is the diagnosis's "mostly
    /// out of view". Off by default: the benchmark counts every annotated box.
    #[arg(long, value_name = "SHARE", value_parser = options::share, conflicts_with_all = ["layout", "surfaces"])]
    pub ignore_out_of_view: Option<f32>,
}

/// A (low, high) bootstrap interval of an AP or of a difference of APs (fractions).
type Interval = (f32, f32);

/// The central probability of the `--bootstrap` intervals.
pub(super) const BOOTSTRAP_LEVEL: f32 = 0.9;

/// The `--bootstrap` part of the report.
#[derive(Serialize)]
struct BootstrapSummary {
    resamples: usize,
    seed: u64,
    level: f32,
    /// Per category, the interval of its AP (fractions); `null` without ground truth.
    ap_interval: BTreeMap<String, Option<(f32, f32)>>,
    /// The interval of the mAP (each resample's mean of its defined APs).
    map_interval: Option<(f32, f32)>,
    #[serde(skip_serializing_if = "Option::is_none")]
    versus: Option<VersusSummary>,
}

/// `--versus`: the second set's APs and the paired intervals of the differences.
#[derive(Serialize)]
struct VersusSummary {
    detections: PathBuf,
    ap: BTreeMap<String, Option<f32>>,
    map: Option<f32>,
    /// Per category, the interval of AP(--detections) − AP(--versus) over the shared resamples.
    difference_interval: BTreeMap<String, Option<(f32, f32)>>,
    map_difference_interval: Option<(f32, f32)>,
}

/// One frame's ground truth and its detections (`None`: no detections file).
/// A frame's objects with their positions in its annotation file, and its detections (`None`: no file).
type FrameInputs = (PositionedObjects, Option<Vec<Detection>>);

/// The `--diagnose --json` document.
#[derive(Serialize)]
struct DiagnosisReport {
    diagnosis: BTreeMap<String, CategoryDiagnosis>,
    /// k boxes a frame, k = its ground-truth boxes ([`OverlayRule::GroundTruthCount`]).
    overlay_precision: OverlayPrecision,
    /// The boxes `detect`'s overlay draws ([`OverlayRule::Drawn`]), with the rule's two numbers.
    overlay_drawn: DrawnOverlay,
    /// The scores as probabilities, in ten bins ([`reliability`]).
    reliability: Reliability,
    /// `--objects`: every ground-truth box of the evaluated categories.
    #[serde(skip_serializing_if = "Option::is_none")]
    objects: Option<Vec<NamedOutcome>>,
    /// `--ignore-out-of-view`: what was taken out.
    #[serde(skip_serializing_if = "Option::is_none")]
    ignored: Option<IgnoredReport>,
}

/// One `--objects` entry: the frame's directory name, the share of the box in view ([`in_view_share`]),
/// then [`ObjectOutcome`]'s fields.
#[derive(Serialize)]
struct NamedOutcome {
    frame: String,
    in_view: f32,
    #[serde(flatten)]
    outcome: ObjectOutcome,
}

#[derive(Serialize)]
struct DrawnOverlay {
    top: usize,
    min_probability: f32,
    #[serde(flatten)]
    precision: OverlayPrecision,
}

/// The `--json` document.
#[derive(Serialize)]
struct Report {
    iou: f32,
    /// AP per requested category, `null` without ground truth.
    ap: BTreeMap<String, Option<f32>>,
    /// Mean of the non-null APs; `null` when none is defined.
    map: Option<f32>,
    frames: usize,
    /// Frames without a detections file (counted as no detections).
    missing_detection_files: usize,
    ground_truth: BTreeMap<String, usize>,
    detections: BTreeMap<String, usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bootstrap: Option<BootstrapSummary>,
    /// `--surfaces`: the support-surface accuracy of each category with inferred surfaces.
    #[serde(skip_serializing_if = "Option::is_none")]
    surfaces: Option<Vec<SurfaceAccuracy>>,
    /// `--surfaces` with two or more such categories: theirs together (`"category": "all"`).
    #[serde(skip_serializing_if = "Option::is_none")]
    surfaces_pooled: Option<SurfaceAccuracy>,
    /// `--ignore-out-of-view`: what was taken out.
    #[serde(skip_serializing_if = "Option::is_none")]
    ignored: Option<IgnoredReport>,
}

/// `--ignore-out-of-view` in the JSON: the share, and per evaluated category the boxes with less of it in
/// view and the detections whose best box they are, both taken out of the evaluation.
#[derive(Clone, Serialize)]
struct IgnoredReport {
    min_in_view: f32,
    ignored: BTreeMap<String, IgnoredCounts>,
}

/// The requested categories, checked against the 19 known ones.
fn categories(requested: &Option<Vec<String>>) -> anyhow::Result<Vec<String>> {
    let Some(list) = requested else {
        return Ok(LARGE_CATEGORIES.iter().map(|c| c.to_string()).collect());
    };
    if list.len() > 1 {
        options::names("--categories", list)?;
    }
    let names: Vec<&str> = list.iter().map(|c| c.trim()).filter(|c| !c.is_empty()).collect();
    if names == ["all"] {
        return Ok(CATEGORIES.iter().map(|c| c.to_string()).collect());
    }
    if names.is_empty() {
        bail!("--categories is empty");
    }
    let mut out: Vec<String> = Vec::new();
    for name in names {
        if !CATEGORIES.contains(&name) {
            bail!("unknown category '{name}' in --categories (known: {}, or 'all')", CATEGORIES.join(", "));
        }
        if !out.iter().any(|c| c == name) {
            out.push(name.to_string());
        }
    }
    Ok(out)
}

fn progress(len: usize, what: &str) -> anyhow::Result<ProgressBar> {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template(&format!("{{spinner}} [{{elapsed_precise}}] {{bar:40}} {{pos}}/{{len}} {what}"))
            .context("progress bar template")?,
    );
    Ok(bar)
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    if args.layout {
        let mut dataset = Dataset::open(&args.data)?;
        if let Some(split) = &args.split {
            dataset = dataset.with_split(split)?;
        }
        let bootstrap = args.bootstrap.map(|resamples| super::eval_layout::LayoutBootstrap {
            settings: Bootstrap { resamples: resamples as usize, seed: args.bootstrap_seed },
            versus: args.versus.clone(),
        });
        return super::eval_layout::run(&dataset.frames, &args.detections, args.json, args.fail_fast, bootstrap);
    }
    let categories = categories(&args.categories)?;
    let models = match &args.models {
        Some(dir) => Some(diagnosis_models(dir, args.step, &categories)?),
        None => None,
    };
    let mut dataset = Dataset::open(&args.data)?;
    if let Some(split) = &args.split {
        dataset = dataset.with_split(split)?;
    }
    if dataset.is_empty() {
        bail!("{}: no frame directories to evaluate", args.data.display());
    }
    let names = unique_frame_names(&dataset.frames)?;

    let files = detection_files(&args.detections)?;
    let known: HashSet<&str> = names.iter().map(String::as_str).collect();
    let mut unknown: Vec<&String> = files.keys().filter(|stem| !known.contains(stem.as_str())).collect();
    unknown.sort();
    // A detect run over a whole dataset evaluated on a split leaves many such files: name a few, count all.
    const NAMED: usize = 5;
    for stem in unknown.iter().take(NAMED) {
        log::warn!("{}: names no evaluated frame; ignored", files[*stem].display());
    }
    if unknown.len() > NAMED {
        log::warn!("... and {} more detection files that name no evaluated frame", unknown.len() - NAMED);
    }

    let bar = progress(dataset.len(), "frames")?;
    let read: Vec<anyhow::Result<FrameInputs>> = dataset
        .frames
        .par_iter()
        .zip(&names)
        .map(|(dir, name)| -> anyhow::Result<_> {
            let (objects, _layout) = read_positioned_annotations(dir)?;
            let detections = match files.get(name) {
                Some(path) => {
                    let file = FrameDetections::read(path)?;
                    if file.frame != *name {
                        log::warn!(
                            "{}: its \"frame\" is '{}', not '{name}'; used for {name}",
                            path.display(),
                            file.frame
                        );
                    }
                    Some(file.detections)
                }
                None => None,
            };
            bar.inc(1);
            Ok((objects, detections))
        })
        .collect();
    bar.finish_and_clear();
    // A frame that cannot be read is left out of the evaluation (its ground truth and its detections).
    let mut per_frame = Vec::new();
    let mut failures = Vec::new();
    let mut frames = Vec::new();
    for (result, dir) in read.into_iter().zip(&dataset.frames) {
        match result {
            Ok(frame) => {
                per_frame.push(frame);
                frames.push(dir.clone());
            }
            Err(err) if args.fail_fast => return Err(err),
            Err(err) => {
                log::error!("{}: skipped: {}", dir.display(), super::error_text(&err));
                failures.push((dir.clone(), err));
            }
        }
    }
    let evaluated = frames.len();

    let missing = per_frame.iter().filter(|(_, d)| d.is_none()).count();
    // `positions[image][o]`: object o's position in its annotation file's `objects` array, which
    // `--objects` prints (it counts the null entries and room structure that the reader skips).
    let (positioned, detections): (Vec<PositionedObjects>, Vec<Vec<Detection>>) =
        per_frame.into_iter().map(|(t, d)| (t, d.unwrap_or_default())).unzip();
    let positions: Vec<Vec<usize>> =
        positioned.iter().map(|objects| objects.iter().map(|(p, _)| *p).collect()).collect();
    let truth: Vec<Vec<Object>> =
        positioned.into_iter().map(|objects| objects.into_iter().map(|(_, o)| o).collect()).collect();
    no_frame_detected(missing, evaluated, &args.detections)?;
    if missing > 0 {
        log::warn!(
            "{missing} of {evaluated} frames have no detections file in {}; counted as no detections",
            args.detections.display()
        );
    }
    let out_of_view = match args.ignore_out_of_view {
        Some(share) => Some(OutOfView::mark(&frames, &truth, &categories, share)?),
        None => None,
    };
    // `annotation_index`: each kept box's index in its frame's annotation, which `--objects` prints.
    let (truth, detections, ignored, annotation_index) = match &out_of_view {
        Some(marks) => {
            let kept = marks.apply(&detections, args.iou);
            let report = marks.report(&kept.counts, &categories);
            (kept.truth, kept.detections, Some(report), Some(kept.annotation_index))
        }
        None => (truth, detections, None, None),
    };
    if args.diagnose {
        let window = match &models {
            Some(models) => Some(window_recall(&frames, &truth, models, args.unseen_floor.0)?),
            None => None,
        };
        let diagnosis = diagnose_categories(&truth, &detections, &categories, args.iou, window.as_ref());
        let overlay_of = |rule| overlay_precision(&truth, &detections, &categories, args.iou, rule, args.nms_iou);
        let overlay = overlay_of(OverlayRule::GroundTruthCount);
        let drawn = overlay_of(OverlayRule::Drawn { top: args.overlay_top, min_probability: args.overlay_min_score });
        let reliability = reliability(&truth, &detections, &categories, args.iou);
        let objects = if args.objects {
            let index = ObjectIndex { kept: annotation_index.as_deref(), positions: &positions };
            Some(named_outcomes(&frames, &truth, index, &detections, &categories, args.iou)?)
        } else {
            None
        };
        if args.json {
            let report = DiagnosisReport {
                diagnosis: diagnosis.iter().map(|d| (d.category.clone(), d.clone())).collect(),
                overlay_precision: overlay,
                overlay_drawn: DrawnOverlay {
                    top: args.overlay_top,
                    min_probability: args.overlay_min_score,
                    precision: drawn,
                },
                reliability,
                objects,
                ignored,
            };
            out!("{}", serde_json::to_string_pretty(&report)?);
        } else {
            print_diagnosis(&args, &diagnosis, &overlay, &drawn, evaluated, missing)?;
            print_reliability(&reliability)?;
            if let Some(ignored) = &ignored {
                print_ignored(ignored)?;
            }
            if let Some(objects) = &objects {
                print_objects(objects, args.iou)?;
            }
        }
        return super::batch_result(&failures, names.len());
    }
    let results = evaluate_categories(&truth, &detections, &categories, args.iou);
    let map = mean_ap(results.iter().map(|r| &r.pr.ap));
    let bootstrap = match args.bootstrap {
        Some(resamples) => {
            let versus = match &args.versus {
                Some(dir) => {
                    let other = read_detection_dir(dir, &frames)?;
                    // The same boxes ignored, and the other set's detections on them dropped by the same rule.
                    let other = match &out_of_view {
                        Some(marks) => marks.apply(&other, args.iou).detections,
                        None => other,
                    };
                    Some((dir.clone(), other))
                }
                None => None,
            };
            let settings = Bootstrap { resamples: resamples as usize, seed: args.bootstrap_seed };
            Some(bootstrap_summary(&truth, &detections, versus, &categories, args.iou, settings))
        }
        None => None,
    };

    if let Some(dir) = &args.plots {
        write_plots(dir, &results)?;
    }
    let (surfaces, surfaces_pooled) = if args.surfaces {
        let (each, pooled) = surface_report(&frames, &truth, &detections, &categories, args.iou)?;
        (Some(each), pooled)
    } else {
        (None, None)
    };
    if args.json {
        let report = Report {
            iou: args.iou,
            ap: results.iter().map(|r| (r.category.clone(), r.pr.ap)).collect(),
            map,
            frames: evaluated,
            missing_detection_files: missing,
            ground_truth: results.iter().map(|r| (r.category.clone(), r.ground_truth)).collect(),
            detections: results.iter().map(|r| (r.category.clone(), r.detections)).collect(),
            bootstrap,
            surfaces,
            surfaces_pooled,
            ignored,
        };
        out!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&args, &results, map, evaluated, missing)?;
        if let Some(ignored) = &ignored {
            print_ignored(ignored)?;
        }
        if let Some(summary) = &bootstrap {
            print_bootstrap(&results, map, summary)?;
        }
        if let Some(surfaces) = &surfaces {
            print_surfaces(surfaces, surfaces_pooled.as_ref())?;
        }
    }
    super::batch_result(&failures, names.len())
}

/// Tolerance of the support-surface report (the 5 cm).
const SURFACE_TOLERANCE_M: f32 = 0.05;

/// `--surfaces`: [`surface_accuracy`] of every category whose detections carry a surface, against the true
/// surfaces of the frames' support files (frames without one are counted in a warning and give none), and
/// [`SurfaceAccuracy::pooled`] of those categories when there are two or more.
fn surface_report(
    frames: &[PathBuf],
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    categories: &[String],
    iou: f32,
) -> anyhow::Result<(Vec<SurfaceAccuracy>, Option<SurfaceAccuracy>)> {
    let supports: Vec<Vec<Vec<f32>>> = frames
        .par_iter()
        .zip(truth)
        .map(|(dir, objects)| Ok(read_support_heights(dir, objects.len())?.unwrap_or_default()))
        .collect::<anyhow::Result<_>>()?;
    let without = supports.iter().zip(truth).filter(|(s, t)| s.is_empty() && !t.is_empty()).count();
    if without > 0 {
        log::warn!("{without} frames with objects have no {SUPPORT_FILE} (not synthetic): no true surfaces there");
    }
    let each: Vec<SurfaceAccuracy> = categories
        .iter()
        .filter(|c| detections.iter().flatten().any(|d| &d.category == *c && d.surface_z.is_some()))
        .map(|c| surface_accuracy(truth, &supports, detections, c, iou, SURFACE_TOLERANCE_M))
        .collect();
    let pooled = (each.len() >= 2).then(|| SurfaceAccuracy::pooled(&each));
    Ok((each, pooled))
}

fn print_surfaces(surfaces: &[SurfaceAccuracy], pooled: Option<&SurfaceAccuracy>) -> anyhow::Result<()> {
    if surfaces.is_empty() {
        out!("support surfaces: no detection carries an inferred surface (no model with surfaces)");
        return Ok(());
    }
    out!(
        "support surfaces of the true positives (inferred surface_z against the true support heights, ≤ {} cm; \
         nearest and main of those measured, main also of all true positives):",
        SURFACE_TOLERANCE_M * 100.0
    );
    out!(
        "{:<12} {:>8} {:>9} {:>15} {:>13} {:>13} {:>14}",
        "category",
        "TP",
        "measured",
        "nearest ≤ tol",
        "main ≤ tol",
        "main, all TP",
        "median error"
    );
    let share =
        |n: usize, of: usize| if of > 0 { format!("{:.1} %", 100.0 * n as f32 / of as f32) } else { "-".into() };
    for s in surfaces.iter().chain(pooled) {
        out!(
            "{:<12} {:>8} {:>9} {:>15} {:>13} {:>13} {:>14}",
            s.category,
            s.true_positives,
            s.measured,
            share(s.within_nearest, s.measured),
            share(s.within_main, s.measured),
            share(s.within_main, s.true_positives),
            s.median_error_m.map_or("-".into(), |e| format!("{:.1} cm", 100.0 * e))
        );
    }
    // The rules that gave the surfaces, where more than one did: a front edge or a latent slice is a guess
    // where the points show no face.
    for s in surfaces.iter().chain(pooled).filter(|s| s.by_source.len() > 1) {
        let parts: Vec<String> = s
            .by_source
            .iter()
            .map(|(source, c)| {
                format!("{source} {} of {} ({})", c.within_main, c.measured, share(c.within_main, c.measured))
            })
            .collect();
        out!("  {}: main ≤ tol by rule: {}", s.category, parts.join(", "));
    }
    Ok(())
}

fn percent(ap: Option<f32>) -> String {
    ap.map(|a| format!("{:.1}", 100.0 * a)).unwrap_or_else(|| "-".into())
}

fn print_table(
    args: &Args,
    results: &[CategoryEvaluation],
    map: Option<f32>,
    frames: usize,
    missing: usize,
) -> anyhow::Result<()> {
    out!(
        "{frames} frames from {}, detections from {} ({missing} frames without a file), 3D IoU ≥ {}",
        args.data.display(),
        args.detections.display(),
        args.iou
    );
    out!("{:<12} {:>7} {:>11} {:>7}", "category", "#GT", "#detections", "AP");
    for r in results {
        out!("{:<12} {:>7} {:>11} {:>7}", r.category, r.ground_truth, r.detections, percent(r.pr.ap));
    }
    let defined = results.iter().filter(|r| r.pr.ap.is_some()).count();
    out!("{:<12} {:>27}", format!("mAP ({defined})"), percent(map));
    Ok(())
}

/// The detections of `frames` read from another detections directory (`--versus`): a frame without a
/// file has no detections (counted in a warning); an unreadable file is an error naming it.
fn read_detection_dir(dir: &Path, frames: &[PathBuf]) -> anyhow::Result<Vec<Vec<Detection>>> {
    let files = detection_files(dir)?;
    let mut missing = 0;
    let mut out = Vec::with_capacity(frames.len());
    for frame in frames {
        match files.get(&frame_name(frame)) {
            Some(path) => out.push(FrameDetections::read(path)?.detections),
            None => {
                missing += 1;
                out.push(Vec::new());
            }
        }
    }
    no_frame_detected(missing, frames.len(), dir)?;
    if missing > 0 {
        log::warn!(
            "{missing} of {} frames have no detections file in {}; counted as no detections",
            frames.len(),
            dir.display()
        );
    }
    Ok(out)
}

/// A detections directory that holds something but no file for any evaluated frame is an error, not an AP
/// of 0: `detect` writes a file for every frame, even one without detections, so it is another directory
/// than the one meant (the data set itself, another set's detections, swapped arguments). An empty
/// directory is a detector that found nothing (a baseline for `--versus`, or `--diagnose --models` for the
/// window's recall alone), and some frames without a file are a warning (a run interrupted, a frame that
/// failed).
fn no_frame_detected(missing: usize, frames: usize, dir: &Path) -> anyhow::Result<()> {
    let empty = std::fs::read_dir(dir).map(|mut entries| entries.next().is_none()).unwrap_or(false);
    if frames > 0 && missing == frames && !empty {
        bail!(
            "{}: no detections file for any of the {frames} evaluated frames (detect writes <frame>.json for \
             each; is this the detections directory of this data set?)",
            dir.display()
        );
    }
    Ok(())
}

/// The percentile intervals of every category's AP and of the mAP over the resamples (and, with a
/// `versus` set, its APs and the paired intervals of the differences).
fn bootstrap_summary(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    versus: Option<(PathBuf, Vec<Vec<Detection>>)>,
    categories: &[String],
    iou: f32,
    settings: Bootstrap,
) -> BootstrapSummary {
    let mut sets: Vec<&[Vec<Detection>]> = vec![detections];
    if let Some((_, other)) = &versus {
        sets.push(other);
    }
    let aps = bootstrap_aps(truth, &sets, categories, iou, settings);
    let interval_of = |values: Vec<f32>| percentile_interval(&values, BOOTSTRAP_LEVEL);
    // Per resample of one set: its category APs and its mAP.
    let column = |set: usize, c: usize| -> Vec<Option<f32>> { aps[set].iter().map(|r| r[c]).collect() };
    let maps = |set: usize| -> Vec<Option<f32>> { aps[set].iter().map(mean_ap).collect() };
    let ap_interval = categories
        .iter()
        .enumerate()
        .map(|(c, name)| (name.clone(), interval_of(column(0, c).into_iter().flatten().collect())))
        .collect();
    let map_interval = interval_of(maps(0).into_iter().flatten().collect());
    let differences = |a: Vec<Option<f32>>, b: Vec<Option<f32>>| -> Vec<f32> {
        a.into_iter().zip(b).filter_map(|(x, y)| Some(x? - y?)).collect()
    };
    let versus = versus.map(|(dir, other)| {
        let results = evaluate_categories(truth, &other, categories, iou);
        VersusSummary {
            detections: dir,
            map: mean_ap(results.iter().map(|r| &r.pr.ap)),
            ap: results.iter().map(|r| (r.category.clone(), r.pr.ap)).collect(),
            difference_interval: categories
                .iter()
                .enumerate()
                .map(|(c, name)| (name.clone(), interval_of(differences(column(0, c), column(1, c)))))
                .collect(),
            map_difference_interval: interval_of(differences(maps(0), maps(1))),
        }
    });
    BootstrapSummary {
        resamples: settings.resamples,
        seed: settings.seed,
        level: BOOTSTRAP_LEVEL,
        ap_interval,
        map_interval,
        versus,
    }
}

fn interval_text(interval: Option<(f32, f32)>) -> String {
    interval.map(|(lo, hi)| format!("[{:.1}, {:.1}]", 100.0 * lo, 100.0 * hi)).unwrap_or_else(|| "-".into())
}

fn print_bootstrap(results: &[CategoryEvaluation], map: Option<f32>, summary: &BootstrapSummary) -> anyhow::Result<()> {
    out!(
        "bootstrap: {} resamples of the frames (seed {}), {:.0} % percentile intervals",
        summary.resamples,
        summary.seed,
        100.0 * summary.level
    );
    let difference = |name: &str| {
        summary
            .versus
            .as_ref()
            .map(|v| (v.ap.get(name).copied().flatten(), v.difference_interval.get(name).copied().flatten()))
    };
    match &summary.versus {
        None => out!("{:<12} {:>7} {:>16}", "category", "AP", "interval"),
        Some(v) => {
            out!("versus: {} (difference = --detections minus --versus, paired resamples)", v.detections.display());
            out!(
                "{:<12} {:>7} {:>16} {:>8} {:>7} {:>16}",
                "category",
                "AP",
                "interval",
                "versus",
                "diff",
                "interval of diff"
            );
        }
    }
    let row = |name: &str,
               ap: Option<f32>,
               interval: Option<Interval>,
               other: Option<(Option<f32>, Option<Interval>)>|
     -> anyhow::Result<()> {
        let mut line = format!("{:<12} {:>7} {:>16}", name, percent(ap), interval_text(interval));
        if let Some((other_ap, diff_interval)) = other {
            let diff = ap.zip(other_ap).map(|(a, b)| a - b);
            line += &format!(" {:>8} {:>7} {:>16}", percent(other_ap), percent(diff), interval_text(diff_interval));
        }
        out!("{line}");
        Ok(())
    };
    for r in results {
        row(&r.category, r.pr.ap, summary.ap_interval.get(&r.category).copied().flatten(), difference(&r.category))?;
    }
    let map_other = summary.versus.as_ref().map(|v| (v.map, v.map_difference_interval));
    row("mAP", map, summary.map_interval, map_other)?;
    Ok(())
}

fn write_plots(dir: &Path, results: &[CategoryEvaluation]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create the plots directory", dir.display()))?;
    for r in results.iter().filter(|r| r.pr.ap.is_some()) {
        let title = format!("{} AP={}", r.category, percent(r.pr.ap));
        let img = cog_gpu::eval::precision_recall_plot(&r.pr, &title, plot_colour(&r.category));
        let path = dir.join(format!("{}.png", r.category));
        cog_gpu::frame::write_png(&img, &path)?;
    }
    Ok(())
}

/// The category's palette colour, darkened when it is too pale to read on the plot's white background.
fn plot_colour(category: &str) -> cog_gpu::draw::Colour {
    let c = category_colour(category);
    let luma = 0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32;
    if luma > 170.0 {
        c.map(|v| (v as f32 * 0.6) as u8)
    } else {
        c
    }
}

/// The models of `dir` for the evaluated categories (with `step` overriding their window step); a warning
/// names the evaluated categories without a model.
fn diagnosis_models(dir: &Path, step: Option<f32>, categories: &[String]) -> anyhow::Result<Vec<Model>> {
    let mut models = read_models_dir(dir, None).with_context(|| format!("--models {}", dir.display()))?;
    models.retain(|m| categories.contains(&m.category));
    if models.is_empty() {
        bail!("--models {}: no model for any evaluated category ({})", dir.display(), categories.join(", "));
    }
    let without: Vec<&str> =
        categories.iter().filter(|c| !models.iter().any(|m| &m.category == *c)).map(String::as_str).collect();
    if !without.is_empty() {
        log::warn!("--models {}: no model for {}; no window recall for them", dir.display(), without.join(", "));
    }
    if let Some(step) = step {
        for model in &mut models {
            model.window.step = step;
        }
    }
    Ok(models)
}

/// The best window IoU of every ground-truth box of each modelled category, over the frames (in frame
/// order), reading only the frames with ground truth of a modelled category.
fn window_recall(
    frames: &[PathBuf],
    truth: &[Vec<Object>],
    models: &[Model],
    unseen_floor: bool,
) -> anyhow::Result<BTreeMap<String, Vec<f32>>> {
    let needed: Vec<usize> = (0..frames.len())
        .filter(|&i| truth[i].iter().any(|o| models.iter().any(|m| m.category == o.category)))
        .collect();
    let bar = progress(needed.len(), "frames windowed")?;
    let per_frame: Vec<BTreeMap<String, Vec<f32>>> = needed
        .par_iter()
        .map(|&i| -> anyhow::Result<_> {
            let dir = &frames[i];
            let frame = Frame::read(dir, DepthSource::Raw)?;
            let pre = Preprocessed::from_frame(&frame).with_context(|| format!("{}: preprocessing", dir.display()))?;
            cog_gpu::detect::check_budget(&pre, models)
                .with_context(|| format!("{}: sliding window", dir.display()))?;
            let best = frame_window_best_ious(&pre, models, &truth[i], unseen_floor);
            bar.inc(1);
            Ok(best)
        })
        .collect::<anyhow::Result<_>>()?;
    bar.finish_and_clear();
    let mut all: BTreeMap<String, Vec<f32>> = models.iter().map(|m| (m.category.clone(), Vec::new())).collect();
    for frame in per_frame {
        for (category, best) in frame {
            all.entry(category).or_default().extend(best);
        }
    }
    // A modelled category without any ground truth has no window numbers.
    all.retain(|_, best| !best.is_empty());
    Ok(all)
}

/// How `--objects` names a box: its position in its frame's annotation file.
struct ObjectIndex<'a> {
    /// With boxes left out (`--ignore-out-of-view`), `kept[image][o]`: kept box `o`'s index among the
    /// frame's objects as read.
    kept: Option<&'a [Vec<usize>]>,
    /// `positions[image][r]`: read object `r`'s position in the file's `objects` array.
    positions: &'a [Vec<usize>],
}

/// `--objects`: every ground-truth box of `categories` ([`object_outcomes`]) with its frame's name and its
/// share in view, which reads each frame with such a box (its camera and image size). The outcome names
/// the box by its position in the frame's annotation file ([`ObjectIndex`]), with or without boxes left out.
fn named_outcomes(
    frames: &[PathBuf],
    truth: &[Vec<Object>],
    index: ObjectIndex,
    detections: &[Vec<Detection>],
    categories: &[String],
    iou: f32,
) -> anyhow::Result<Vec<NamedOutcome>> {
    let outcomes: Vec<ObjectOutcome> =
        categories.iter().flat_map(|c| object_outcomes(truth, detections, c, iou)).collect();
    let needed: HashSet<usize> = outcomes.iter().map(|o| o.image).collect();
    let cameras = frame_cameras(frames, &needed, "--objects")?;
    Ok(outcomes
        .into_iter()
        .map(|outcome| {
            let (camera, width, height) = &cameras[&outcome.image];
            let box_ = &truth[outcome.image][outcome.object].cuboid;
            let in_view = in_view_share(box_, camera, *width, *height);
            let read = index.kept.map_or(outcome.object, |kept| kept[outcome.image][outcome.object]);
            let object = index.positions[outcome.image][read];
            NamedOutcome {
                frame: frame_name(&frames[outcome.image]),
                in_view,
                outcome: ObjectOutcome { object, ..outcome },
            }
        })
        .collect())
}

/// The camera and image size (pixels) of each frame in `needed` (indices into `frames`), each frame read
/// in full; an unreadable frame is an error naming it and `flag`, the option that needed it.
fn frame_cameras(
    frames: &[PathBuf],
    needed: &HashSet<usize>,
    flag: &str,
) -> anyhow::Result<BTreeMap<usize, (Camera, u32, u32)>> {
    frames
        .par_iter()
        .enumerate()
        .filter(|(i, _)| needed.contains(i))
        .map(|(i, dir)| {
            let frame = Frame::read(dir, DepthSource::Raw)
                .with_context(|| format!("{}: reading the frame for {flag}", dir.display()))?;
            Ok((i, (Camera::new(frame.intrinsics(), frame.rtilt()), frame.width(), frame.height())))
        })
        .collect()
}

/// `--ignore-out-of-view SHARE`: the frames' ground truth and, per box, whether it is ignored — a box of
/// an evaluated category with less than `share` of its volume in view ([`in_view_share`]); boxes of the
/// other categories are never marked (no evaluated detection can take them).
struct OutOfView {
    share: f32,
    truth: Vec<Vec<Object>>,
    marked: Vec<Vec<bool>>,
}

impl OutOfView {
    fn mark(frames: &[PathBuf], truth: &[Vec<Object>], categories: &[String], share: f32) -> anyhow::Result<Self> {
        let evaluated = |o: &Object| categories.contains(&o.category);
        let needed: HashSet<usize> = (0..truth.len()).filter(|&i| truth[i].iter().any(evaluated)).collect();
        let cameras = frame_cameras(frames, &needed, "--ignore-out-of-view")?;
        let marked = truth
            .iter()
            .enumerate()
            .map(|(i, objects)| {
                objects
                    .iter()
                    .map(|o| {
                        evaluated(o) && {
                            let (camera, width, height) = &cameras[&i];
                            in_view_share(&o.cuboid, camera, *width, *height) < share
                        }
                    })
                    .collect()
            })
            .collect();
        Ok(OutOfView { share, truth: truth.to_vec(), marked })
    }

    /// [`ignore_boxes`] of these marks on `detections` (of the same frames).
    fn apply(&self, detections: &[Vec<Detection>], iou: f32) -> WithoutIgnored {
        ignore_boxes(&self.truth, &self.marked, detections, iou)
    }

    /// What was taken out, per evaluated category (zeros included).
    fn report(&self, counts: &BTreeMap<String, IgnoredCounts>, categories: &[String]) -> IgnoredReport {
        IgnoredReport {
            min_in_view: self.share,
            ignored: categories.iter().map(|c| (c.clone(), counts.get(c).copied().unwrap_or_default())).collect(),
        }
    }
}

/// `--ignore-out-of-view` (text): what the table above left out.
fn print_ignored(report: &IgnoredReport) -> anyhow::Result<()> {
    let (boxes, detections) = report.ignored.values().fold((0, 0), |(b, d), c| (b + c.boxes, d + c.detections));
    out!(
        "ignored (--ignore-out-of-view {}): {boxes} ground-truth boxes with less than {:.0} % of their volume in \
         the picture and the {detections} detections whose best box they are (as PASCAL VOC's difficult objects); \
         per category, boxes/detections:",
        report.min_in_view,
        100.0 * report.min_in_view
    );
    let parts: Vec<String> = report.ignored.iter().map(|(c, n)| format!("{c} {}/{}", n.boxes, n.detections)).collect();
    out!("  {}", parts.join(", "));
    Ok(())
}

/// `--objects` (text): one line per ground-truth box, then per category the boxes mostly out of view.
fn print_objects(objects: &[NamedOutcome], iou: f32) -> anyhow::Result<()> {
    out!("every ground-truth box (size w×d×h m, distance from the camera on the ground, m):");
    for NamedOutcome { frame, in_view, outcome: o } in objects {
        let what = match &o.found {
            Some(f) => format!(
                "found at {:.3} (IoU {:.2}; precision {:.2}, {} false positives before it)",
                f.score, f.iou, f.precision, f.false_positives_before
            ),
            None => format!("missed (best IoU of its category's detections {:.2})", o.best_iou),
        };
        let other = match &o.other {
            Some(d) => format!("; {} at {:.3} on it (IoU {:.2} ≥ {iou})", d.category, d.score, d.iou),
            None => String::new(),
        };
        let [w, d, h] = o.size;
        out!(
            "{frame} #{} {:<12} {w:.2}×{d:.2}×{h:.2} at {:.1} m, {:.0} % in view: {what}{other}",
            o.object,
            o.category,
            o.distance_m,
            100.0 * in_view
        );
    }
    out!(
        "boxes mostly out of view (less than {:.0} % of the box in the picture), and how many of them are found:",
        100.0 * MOSTLY_OUT_OF_VIEW
    );
    let mut by_category: BTreeMap<&str, (usize, usize, usize)> = BTreeMap::new();
    for NamedOutcome { in_view, outcome: o, .. } in objects {
        let entry = by_category.entry(o.category.as_str()).or_default();
        entry.0 += 1;
        if *in_view < MOSTLY_OUT_OF_VIEW {
            entry.1 += 1;
            entry.2 += o.found.is_some() as usize;
        }
    }
    // In the evaluated categories' order (the listing's).
    let mut seen = HashSet::new();
    for o in objects.iter().map(|n| &n.outcome).filter(|o| seen.insert(o.category.as_str())) {
        let (boxes, out, found) = by_category[o.category.as_str()];
        out!("{:<12} {out} of {boxes} mostly out of view, {found} of them found", o.category);
    }
    Ok(())
}

fn print_diagnosis(
    args: &Args,
    diagnosis: &[CategoryDiagnosis],
    overlay: &OverlayPrecision,
    drawn: &OverlayPrecision,
    frames: usize,
    missing: usize,
) -> anyhow::Result<()> {
    out!(
        "{frames} frames from {}, detections from {} ({missing} frames without a file), 3D IoU ≥ {}",
        args.data.display(),
        args.detections.display(),
        args.iou
    );
    match &args.models {
        Some(dir) => out!(
            "window recall: hypotheses of the models in {}{}",
            dir.display(),
            args.step.map(|s| format!(" at step {s} m")).unwrap_or_default()
        ),
        None => out!("window recall: - (give --models DIR)"),
    }
    out!(
        "{:<12} {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>7}",
        "category",
        "#GT",
        "win≥.25",
        "win≥.50",
        "winIoU",
        "#frames",
        "#w/dets",
        "best=TP",
        "AP",
        "rankAP"
    );
    for d in diagnosis {
        out!(
            "{:<12} {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>7} {:>7}",
            d.category,
            d.gt_boxes,
            percent(d.window_recall_25),
            percent(d.window_recall_50),
            percent(d.window_mean_best_iou),
            d.frames_with_category,
            d.frames_with_detections,
            percent(d.best_is_tp),
            percent(d.ap),
            percent(d.rank_ap)
        );
    }
    out!("highest-scoring false positives (as many as #GT), by kind (% of those examined):");
    out!(
        "{:<12} {:>8} {:>6} {:>6} {:>6} {:>12} {:>8} {:>8}",
        "category",
        "examined",
        "dup",
        "loc",
        "conf",
        "conf. with",
        "bg here",
        "bg else"
    );
    for d in diagnosis {
        let fp = &d.false_positives;
        let share = |n: usize| percent((fp.examined > 0).then(|| n as f32 / fp.examined as f32));
        out!(
            "{:<12} {:>8} {:>6} {:>6} {:>6} {:>12} {:>8} {:>8}",
            d.category,
            fp.examined,
            share(fp.duplicate),
            share(fp.localisation),
            share(fp.confusion),
            fp.most_confused_with.as_deref().unwrap_or("-"),
            share(fp.background_in_frame),
            share(fp.background_elsewhere)
        );
    }
    out!("AP without the false positives of a kind (an oracle: every false positive, the kinds above):");
    out!(
        "{:<12} {:>7} {:>7} {:>7} {:>7} {:>7} {:>11} {:>7}",
        "category",
        "AP",
        "-dup",
        "-loc",
        "-conf",
        "-bg",
        "-loc/conf/bg",
        "-allFP"
    );
    let row = |name: &str, values: [Option<f32>; 7]| -> anyhow::Result<()> {
        let [ap, dup, loc, conf, bg, lcb, all] = values.map(percent);
        out!("{name:<12} {ap:>7} {dup:>7} {loc:>7} {conf:>7} {bg:>7} {lcb:>11} {all:>7}");
        Ok(())
    };
    let columns = |d: &CategoryDiagnosis| {
        let o = &d.oracle_ap;
        [
            d.ap,
            o.without_duplicates,
            o.without_localisation,
            o.without_confusion,
            o.without_background,
            o.without_localisation_confusion_background,
            o.without_false_positives,
        ]
    };
    for d in diagnosis {
        row(&d.category, columns(d))?;
    }
    let all: Vec<[Option<f32>; 7]> = diagnosis.iter().map(columns).collect();
    row("mean", std::array::from_fn(|c| mean_ap(all.iter().map(|v| &v[c]))))?;
    out!(
        "ground-truth boxes: found ahead (a true positive at precision ≥ {FOUND_AHEAD_PRECISION}) or behind, missed \
         near (a detection at IoU ≥ {TOUCH_IOU}) or far; missed with another category's detection on it (IoU ≥ {}):",
        args.iou
    );
    out!(
        "{:<12} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7}",
        "category",
        "#GT",
        "ahead",
        "behind",
        "m.near",
        "m.far",
        "m.other"
    );
    for d in diagnosis {
        let o = &d.objects;
        out!(
            "{:<12} {:>6} {:>7} {:>7} {:>7} {:>7} {:>7}",
            d.category,
            d.gt_boxes,
            o.found_ahead,
            o.found_behind,
            o.missed_near,
            o.missed_far,
            o.missed_with_other
        );
    }
    out!(
        "overlay precision (per frame the top k detections, k = its ground-truth boxes): {}/{} = {}",
        overlay.true_positives,
        overlay.shown,
        percent(overlay.precision)
    );
    out!("  {}", false_kinds_line(&overlay.false_kinds, args.iou));
    let per_frame = |n: usize| if drawn.frames > 0 { n as f32 / drawn.frames as f32 } else { 0.0 };
    out!(
        "overlay as drawn (at most {} boxes, calibrated ones with probability ≥ {}): {}/{} = {}; {:.2} boxes per \
         frame, {} of {} frames without a box",
        args.overlay_top,
        args.overlay_min_score,
        drawn.true_positives,
        drawn.shown,
        percent(drawn.precision),
        per_frame(drawn.shown),
        drawn.frames_without_boxes,
        drawn.frames
    );
    out!("  {}", false_kinds_line(&drawn.false_kinds, args.iou));
    Ok(())
}

/// The reliability table: per bin of the score its detections, true positives, the true positives its
/// scores expect, their mean score and the bin's precision; then the expected calibration error.
pub fn print_reliability(r: &Reliability) -> anyhow::Result<()> {
    out!("scores as probabilities (every detection, labelled by the AP's matching), by bin of the score:");
    out!("{:<12} {:>8} {:>7} {:>9} {:>6} {:>9}", "score", "#dets", "#TP", "expected", "mean", "precision");
    let last = r.bins.len().saturating_sub(1);
    for (n, b) in r.bins.iter().enumerate() {
        let upper = if n == last { ']' } else { ')' };
        let number = |v: Option<f64>| v.map(|v| format!("{v:.3}")).unwrap_or_else(|| "-".into());
        out!(
            "{:<12} {:>8} {:>7} {:>9.1} {:>6} {:>9}",
            format!("[{:.1}, {:.1}{upper}", b.lower, b.upper),
            b.detections,
            b.true_positives,
            b.expected_true_positives,
            number(b.mean_score()),
            number(b.precision())
        );
    }
    let binned: usize = r.bins.iter().map(|b| b.detections).sum();
    let ece = r.expected_calibration_error.map(|e| format!("{e:.4}")).unwrap_or_else(|| "-".into());
    out!(
        "expected calibration error {ece} over {binned} detections ({} with a score outside [0, 1]: raw scores, not \
         binned)",
        r.outside_unit_interval
    );
    Ok(())
}

/// The overlay's false boxes by kind (`iou`: the true positives' IoU), on one line: the three most frequent
/// confusions named.
fn false_kinds_line(k: &FalseKindCounts, iou: f32) -> String {
    let named: Vec<String> =
        k.confused.iter().take(3).map(|c| format!("{} on {} {}", c.shown, c.object, c.count)).collect();
    let confused = if named.is_empty() {
        String::new()
    } else {
        format!(" ({}{})", named.join(", "), if k.confused.len() > 3 { ", …" } else { "" })
    };
    format!(
        "false ones: {} duplicates, {} poorly placed (IoU {TOUCH_IOU}–{iou} with one of their category), {} on another \
         category's object{confused}, {} on background ({} in frames with their category, {} without)",
        k.duplicate,
        k.localisation,
        k.confusion,
        k.background_in_frame + k.background_elsewhere,
        k.background_in_frame,
        k.background_elsewhere
    )
}
