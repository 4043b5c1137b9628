//! `cog-gpu train --data DIR --category C [--out FILE] [--c C] [--eps E] [--resume] ...`: trains one
//! category's detector with the structural SVM (paper eq. 4–5, solved in its 1-slack form; see
//! `cog_gpu::learn`, `cog_gpu::learn::one_slack` and `cog_gpu::learn::detector` for the examples, the
//! oracle and the training loop) and writes a model file.
//!
//! Choices:
//! * instances of the category up to `--positives` (default 100, spread evenly over the dataset) and up
//!   to `--negatives` (default 60) frames without it: hard negatives from many frames are what make scores
//!   comparable across frames (the caps keep a full pass at about 2.5 minutes on 2 cores);
//! * the training sliding window uses a 0.2 m centre step (`--step`); the model is written with the
//!   detection step `--detect-step 0.2` (0.1 m scores 4× more hypotheses for boxes at most 5 cm better
//!   placed; `detect --step 0.1` still gives it; the shipped nightstand, the smallest of the ten, is
//!   written with 0.1, which raised its test AP by 10.5 points: README, "The shipped models");
//! * sizes: quantiles of the training annotations of the category;
//! * features: the fast path (`--features exact` for the exact one, much slower);
//! * a positive's target output is the window's box nearest the annotation, other boxes' losses are
//!   regrets against it (`--target best-window`; `exact` for the annotated cuboid, the paper's choice; see
//!   `cog_gpu::learn::detector::PositiveTarget`);
//! * C = 10 (`--c`): the 1-slack objective weighs the *mean* slack, and C = 1 left the models far from
//!   fitting their training data (README, Training);
//! * the 1-slack cutting-plane algorithm: one aggregated constraint per iteration, so the QP stays small
//!   whatever the number of examples; ε (`--eps`, default 0.02) bounds the mean violation;
//! * each full pass over the sliding windows keeps every example's `--candidates` (100) best hypotheses
//!   with their feature vectors; the iterations in between search only those (dot products); when they
//!   find nothing, a full pass checks the whole window; at most `--max-full-passes` (4) full passes (the
//!   first, at w = 0, scores nothing and caches random hypotheses plus the boxes nearest the truth; the
//!   others mine the hard negatives of the w trained so far);
//! * every instance is a positive candidate, also one the depth sensor did not see (beyond its range:
//!   no hypothesis of the window can fit it); `--skip-unseen` leaves out those whose box holds fewer than
//!   `--min-points` points above the floor slab (off by default: the shipped models were trained on every
//!   instance, and the bookshelf's gain with it was within the noise; README, Training);
//! * `--skip-out-of-view SHARE` leaves out the instances with less than SHARE of their box in the picture
//!   (off by default: the bed and the bathtub trained so gained nothing; README, Training);
//! * a positive example drops the points of the frame's other instances of the category
//!   (`--other-instances removed`, the paper's choice), or keeps them and leaves the boxes that detect
//!   them out of its answers (`ignored`; see `cog_gpu::learn::detector::OtherInstances`);
//! * the window's 16 yaws start at the frame's wall direction (`--yaw-anchor walls`; `camera` for the
//!   fixed `2πk/16`; see `cog_gpu::features::hypotheses`), written into the model so detection searches
//!   the same yaws;
//! * a checkpoint `<out>.ckpt` after every iteration; `--resume` continues from it (same data and options);
//! * at most `--max-iterations 300` cutting-plane iterations;
//! * constraints whose α stayed 0 for `--prune-after 10` solves leave the working set.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

/// Bytes in a GiB (`--cache-gib`).
const GIB: f64 = (1u64 << 30) as f64;

use anyhow::{bail, Context};
use cog_gpu::category::{normalise_name, CATEGORIES};
use cog_gpu::features::fast::{FastOptions, DEFAULT_SUBDIVISIONS};
use cog_gpu::features::hypotheses::DEFAULT_MIN_POINTS;
use cog_gpu::features::surface::{SLICES, SLICE_DIM};
use cog_gpu::features::{budget, FeatureLayout, Groups, LatticePhase, SizeQuantiles, Support, YawAnchor};
use cog_gpu::frame::Dataset;
use cog_gpu::learn::detector::{
    cached_rows_per_example, collect_examples, instances_of, read_all_annotations, train_detector, DetectorOracle,
    ExampleLimits, FeatureEngine, NegativeChoice, OtherInstances, PositiveTarget, SeenRule, TrainingExample,
    TrainingSettings,
};
use cog_gpu::learn::detector::{surface_weights, train_latent_detector, LatentProgress, LatentSettings, SURFACE_DIM};
use cog_gpu::learn::latent::impute;
use cog_gpu::learn::{CuttingPlane, SsvmOptions};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};

use super::{options, GlobalOptions};
use cog_gpu::features::preprocess::NormalSearch;

#[derive(clap::Args)]
pub struct Args {
    /// Training dataset: every frame directory below it (annotations in annotation3Dfinal/index.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Optional split list restricting the dataset (one frame directory per line, relative to --data).
    #[arg(long)]
    pub split: Option<PathBuf>,
    /// Category to train (one of the 19).
    #[arg(long)]
    pub category: String,
    /// Model file to write; default `models/<category>.json`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(value_parser = options::positive)]
    /// Regularisation constant C of eq. 4.
    #[arg(long = "c", default_value_t = 10.0)]
    pub c: f64,
    #[arg(value_parser = options::non_negative)]
    /// Stop when the mean violation over the examples is at most this (loss units; 1-slack ε).
    #[arg(long = "eps", default_value_t = 0.02)]
    pub epsilon: f64,
    #[arg(value_parser = options::iterations)]
    /// Cap on cutting-plane iterations (QP solves), counted across resumes.
    #[arg(long, default_value_t = 300)]
    pub max_iterations: usize,
    /// How the training frames' normals find their plane-fit neighbours: `kdtree` (the 15 nearest; the
    /// default, every shipped model's), `window` (the 15 nearest within the 7×7 pixels around each point;
    /// README, "Normals in an image window") or `kdtree-40` (the 40 nearest, which reach across the depth
    /// steps of structured-light sensors; README, "Normals"). The model file records it and `detect`
    /// preprocesses with it.
    #[arg(long, default_value = "kdtree", value_parser = options::normal_search)]
    pub normals: NormalSearch,
    /// Continue from the checkpoint `<out>.ckpt`.
    #[arg(long)]
    pub resume: bool,
    #[arg(value_parser = options::positives)]
    /// Most instances of the category to train on.
    #[arg(long, default_value_t = 100)]
    pub positives: usize,
    #[arg(value_parser = options::negatives)]
    /// Most frames without the category to train on.
    #[arg(long, default_value_t = 60)]
    pub negatives: usize,
    /// Choose the `--negatives` frames without the category by an earlier detector of it instead of
    /// spreading them evenly: `--hard-share` of them are the frames on which it scored highest, read from
    /// this directory of detection files (`<frame>.json`, as `detect` writes them: one per training
    /// frame; each frame ranked by its best detection of the category, by `raw_score` when present, else
    /// `score`).
    #[arg(long, value_name = "DETECTIONS_DIR")]
    pub hard_negatives: Option<PathBuf>,
    /// With `--hard-negatives`: the share of the `--negatives` frames taken hardest first; the rest are
    /// spread evenly over the other frames without the category (0.5: all hardest lost 8–9 AP points on
    /// the calibration set, README "Training").
    #[arg(long, default_value_t = 0.5, requires = "hard_negatives", value_parser = options::probability)]
    pub hard_share: f32,
    /// Train only on instances the depth sensor saw: an instance whose annotated box holds fewer than
    /// `--min-points` points more than one `--step` above the floor (the window's own keep rule) is not a
    /// positive; `--positives` are spread over the others.
    #[arg(long)]
    pub skip_unseen: bool,
    /// Train only on instances with at least SHARE of their annotated box in the picture (the share of the
    /// box's volume that projects onto the image, as `eval --ignore-out-of-view`); `--positives` are spread
    /// over the others. Off by default.
    #[arg(long, value_name = "SHARE", value_parser = options::share)]
    pub skip_out_of_view: Option<f32>,
    #[arg(value_parser = options::step)]
    /// Centre step of the training sliding window (metres).
    #[arg(long, default_value_t = 0.2)]
    pub step: f32,
    #[arg(value_parser = options::step)]
    /// Centre step written into the model for detection (metres).
    #[arg(long, default_value_t = 0.2)]
    pub detect_step: f32,
    /// Skip hypotheses with fewer points inside.
    #[arg(long, default_value_t = DEFAULT_MIN_POINTS, value_parser = options::min_points)]
    pub min_points: u32,
    /// Feature path: fast (shared-work approximation) or exact.
    #[arg(long, value_enum, default_value_t = PathArg::Fast)]
    pub features: PathArg,
    #[arg(value_parser = options::subdivisions)]
    /// Lattice cells per centre step of the fast path.
    #[arg(long, default_value_t = DEFAULT_SUBDIVISIONS)]
    pub subdivisions: u32,
    /// Feature groups (the paper's ablation): comma-separated of density, normals, cog, view, and geom
    /// (density and normals together); `out-of-view` adds the per-voxel out-of-view indicators (not in
    /// the paper, see README "Out-of-view voxels").
    #[arg(long, default_value = "density,normals,cog,view")]
    pub groups: String,
    /// Do not expand the 5×5×5 grid by a voxel layer (the paper's "+expanded" off).
    #[arg(long)]
    pub no_expand: bool,
    #[arg(value_parser = options::every)]
    /// Also a full pass every this many iterations (0: only when the cached candidates hold no violation).
    #[arg(long, default_value_t = 0)]
    pub full_every: usize,
    #[arg(value_parser = options::iterations)]
    /// Most full passes over every example's sliding window (the first included, which at w = 0 mines
    /// nothing): 4 gives three rounds of hard negatives (with 2, the table model's held-out AP was 19.5;
    /// with 4, 30.9; see the README).
    #[arg(long, default_value_t = 4)]
    pub max_full_passes: usize,
    #[arg(value_parser = options::candidates)]
    /// Candidates (with their feature vectors) cached per example by a full pass.
    #[arg(long, default_value_t = 100)]
    pub candidates: usize,
    #[arg(value_parser = options::cache_gib)]
    /// Memory limit of the candidate cache, in GiB (the cache is sized before training starts and
    /// refused above this; every example's `--candidates` feature vectors).
    #[arg(long, default_value_t = 3.0)]
    pub cache_gib: f64,
    /// Drop constraints whose α stayed 0 for this many solves (at least 1: with 0 every constraint left
    /// the working set as it came in, and the run learnt nothing).
    #[arg(long, default_value_t = 10, value_parser = options::positive_u32)]
    pub prune_after: u32,
    /// A positive's output: the window's hypothesis nearest the annotation (best-window), or the
    /// annotated cuboid itself (exact, the paper's choice).
    #[arg(long, value_enum, default_value_t = TargetArg::BestWindow)]
    pub target: TargetArg,
    /// What a positive example does with the other instances of its category in the frame: `removed`,
    /// their points taken out (the paper's choice), or `ignored`, their points kept and the boxes that
    /// would detect them (IoU ≥ 0.25) left out of the example's answers.
    #[arg(long, value_enum, default_value_t = OthersArg::Removed)]
    pub other_instances: OthersArg,
    /// Where the window's 16 yaws start: the frame's wall direction (walls) or the camera's heading
    /// (camera, `2πk/16`).
    #[arg(long, value_enum, default_value_t = AnchorArg::Walls)]
    pub yaw_anchor: AnchorArg,
    /// Where each yaw's lattice of centres starts: `camera` (multiples of the step from the camera) or
    /// `walls` (a row of centres on the walls seen in the yaw's frame, so that things against a wall are
    /// on the lattice; see README "Hypotheses").
    #[arg(long, value_enum, default_value_t = LatticeArg::Camera)]
    pub lattice: LatticeArg,
    /// Where the boxes stand: `floor` (the sliding window) or `surfaces` (the support surfaces of beds,
    /// tables, desks, dressers, nightstands, sofas and counters: in training the annotated ones', in
    /// detection those of the frame's detections of those categories; for pillows, lamps, monitors, TVs
    /// and sinks), `free` (every bottom height from the floor to 1.5 m at the step: for what stands on
    /// things no model detects, e.g. TVs on walls and cabinets) or `floor+surfaces` (both the floor's
    /// window and the surfaces': for what stands on either, e.g. pedestal sinks and basins on counters);
    /// `resting` (the free window's boxes that rest on the floor or a seen top; the shipped pillow and lamp
    /// detect with it as `--detect-support` after training on `free`).
    #[arg(long, value_enum, default_value_t = SupportArg::Floor)]
    pub support: SupportArg,
    /// The window detection uses, written into the model when it differs from `--support` (as
    /// `--detect-step` for the step): `resting` for a model trained on the `free` window detects only the
    /// free boxes that rest on a seen top or the floor (README, "The free window"). Must search surfaces
    /// exactly when `--support` does (a surface model's supporters are learnt from its training window).
    #[arg(long, value_enum)]
    pub detect_support: Option<SupportArg>,
    #[arg(value_parser = parse_grid)]
    /// The base voxel grid `NXxNYxNZ` (width × depth × height; the paper: 5x5x5 for the large
    /// categories, 3x3x3 for pillows and lamps, 3x1x3 for monitors and TVs).
    #[arg(long, default_value = "5x5x5")]
    pub grid: [u32; 3],
    /// Train with latent support surfaces (paper §4.1; a version-2 model): MODEL is the pre-trained cuboid
    /// model of the same category and features (e.g. assets/models/table.json). Its category and layout are
    /// checked; its weights are read only by `--surface-init centre` (its centre voxel layer, with random
    /// height biases, imputes the first round's slices). Every CCCP round's solve starts from w = 0, so
    /// with the default `upward` the trained model does not depend on MODEL's weights.
    #[arg(long, value_name = "MODEL")]
    pub surfaces_from: Option<PathBuf>,
    /// With --surfaces-from: how the first CCCP round's slices are chosen: `upward`, each ground truth's
    /// slice with the most upward-facing points, or `centre`, the paper's initialisation (surface weights
    /// from the pre-trained model's centre layer, height biases random in [0, 1], slices imputed with them).
    #[arg(long, value_enum, default_value_t = SurfaceInitArg::Upward, requires = "surfaces_from")]
    pub surface_init: SurfaceInitArg,
    #[arg(value_parser = options::iterations)]
    /// With --surfaces-from: most CCCP rounds (each a full S-SVM solve with the slices imputed).
    #[arg(long, default_value_t = 3, requires = "surfaces_from")]
    pub cccp_rounds: usize,
    #[arg(value_parser = options::iterations)]
    /// With --surfaces-from: full passes over the sliding windows allowed to each CCCP round after the first.
    #[arg(long, default_value_t = 2, requires = "surfaces_from")]
    pub round_full_passes: usize,
}

/// `--support` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SupportArg {
    Floor,
    Surfaces,
    Free,
    #[value(name = "floor+surfaces")]
    FloorAndSurfaces,
    Resting,
}

impl From<SupportArg> for Support {
    fn from(arg: SupportArg) -> Support {
        match arg {
            SupportArg::Floor => Support::Floor,
            SupportArg::Surfaces => Support::Surfaces,
            SupportArg::Free => Support::Free,
            SupportArg::FloorAndSurfaces => Support::FloorAndSurfaces,
            SupportArg::Resting => Support::Resting,
        }
    }
}

/// Parses `--grid` (`5x5x5`): three positive voxel counts.
fn parse_grid(text: &str) -> Result<[u32; 3], String> {
    let parts: Vec<&str> = text.split(['x', 'X']).collect();
    let numbers: Vec<u32> = parts.iter().filter_map(|p| p.trim().parse().ok()).filter(|&n| n > 0).collect();
    match numbers.as_slice() {
        &[x, y, z] if parts.len() == 3 => Ok([x, y, z]),
        _ => Err(format!("'{text}' is not a grid like 5x5x5 (three positive voxel counts)")),
    }
}

/// `--surface-init` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SurfaceInitArg {
    Upward,
    Centre,
}

/// `--yaw-anchor` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AnchorArg {
    Walls,
    Camera,
}

impl From<AnchorArg> for YawAnchor {
    fn from(arg: AnchorArg) -> YawAnchor {
        match arg {
            AnchorArg::Walls => YawAnchor::Walls,
            AnchorArg::Camera => YawAnchor::Camera,
        }
    }
}

/// `--lattice` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LatticeArg {
    Camera,
    Walls,
}

impl From<LatticeArg> for LatticePhase {
    fn from(arg: LatticeArg) -> LatticePhase {
        match arg {
            LatticeArg::Camera => LatticePhase::Camera,
            LatticeArg::Walls => LatticePhase::Walls,
        }
    }
}

/// `--target` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TargetArg {
    BestWindow,
    Exact,
}

/// `--other-instances` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OthersArg {
    Removed,
    Ignored,
}

impl From<OthersArg> for OtherInstances {
    fn from(arg: OthersArg) -> OtherInstances {
        match arg {
            OthersArg::Removed => OtherInstances::Removed,
            OthersArg::Ignored => OtherInstances::Ignored,
        }
    }
}

/// `--features` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PathArg {
    Fast,
    Exact,
}

/// The best score of a detection of `category` in every detections file of `dir` (`<frame>.json`), by
/// frame name: `raw_score` when present (a single model's own scale; calibrated probabilities can round
/// to the same value), else `score`; `f32::NEG_INFINITY` for a file without one (`--hard-negatives`).
fn best_scores_by_frame(dir: &std::path::Path, category: &str) -> anyhow::Result<BTreeMap<String, f32>> {
    let files = super::detection_files(dir).context("--hard-negatives")?;
    if files.is_empty() {
        bail!("--hard-negatives: no detection files (*.json) in {}", dir.display());
    }
    let mut best = BTreeMap::new();
    for (frame, path) in files {
        let detections = cog_gpu::eval::FrameDetections::read(&path)?;
        let score = detections
            .detections
            .iter()
            .filter(|d| d.category == category)
            .map(|d| d.raw_score.unwrap_or(d.score))
            .fold(f32::NEG_INFINITY, f32::max);
        best.insert(frame, score);
    }
    Ok(best)
}

/// Drops positive examples without any point inside their box (nothing to learn from; counted in the log)
/// and checks, before any window is built, that every example's sliding window and the candidate cache
/// fit in memory (`cog_gpu::limits`), naming the example that does not.
fn check_examples(
    examples: &mut Vec<TrainingExample>,
    settings: &TrainingSettings,
    candidates: usize,
    cache_gib: f64,
) -> anyhow::Result<()> {
    let before = examples.len();
    examples.retain(|ex| ex.truth.is_none_or(|truth| ex.pre.points.iter().any(|p| truth.contains(*p))));
    if examples.len() < before {
        log::warn!("{} positive examples have no point inside their box; not trained on", before - examples.len());
    }
    if !examples.iter().any(|ex| ex.truth.is_some()) {
        bail!(
            "no positive example left to train on ({} dropped here for having no point inside their box; \
             --skip-unseen, --skip-out-of-view and --support surfaces leave out instances before, as the log \
             says)",
            before - examples.len()
        );
    }
    for ex in examples.iter() {
        let yaws = ex.yaws(settings.yaw_anchor);
        budget::check_window(&ex.pre, &yaws, settings.step, settings.sizes.len())
            .with_context(|| format!("training example {}", ex.name))?;
        if let FeatureEngine::Fast(options) = settings.engine {
            budget::check_fast(&ex.pre, &yaws, settings.step, &settings.layout, options.subdivisions)
                .with_context(|| format!("training example {}", ex.name))?;
        }
    }
    // Each example caches its candidates' feature vectors (plus the boxes nearest a positive's truth).
    let vectors = examples.len() as f64 * cached_rows_per_example(candidates) as f64;
    // with surfaces, each candidate also keeps its seven slices
    let row_bytes = (settings.layout.dim() + if settings.surfaces { SLICES * SLICE_DIM } else { 0 }) as f64 * 4.0;
    cog_gpu::limits::check_memory_within(
        "the candidate cache",
        vectors,
        row_bytes,
        cache_gib * GIB,
        "lower --candidates, --positives or --negatives, or raise --cache-gib",
    )?;
    log::info!(
        "the candidate cache: {} for {} examples (limit {}, --cache-gib)",
        cog_gpu::limits::human_bytes(vectors * row_bytes),
        examples.len(),
        cog_gpu::limits::human_bytes(cache_gib * GIB)
    );
    Ok(())
}

/// The pre-trained cuboid model of `--surfaces-from`: it must be a version-1 model of the category with
/// the layout being trained.
fn pretrained_model(path: &std::path::Path, category: &str, layout: &FeatureLayout) -> anyhow::Result<Model> {
    let model = Model::read(path)?;
    if model.category != category {
        bail!("--surfaces-from {}: a '{}' model, training '{category}'", path.display(), model.category);
    }
    if model.layout != *layout {
        bail!(
            "--surfaces-from {}: its features ({}) are not the ones being trained ({}); match --groups and --no-expand",
            path.display(),
            model.layout_id,
            layout.id()
        );
    }
    if model.surface.is_some() {
        bail!("--surfaces-from {}: already a model with surfaces; give the cuboid model", path.display());
    }
    Ok(model)
}

/// The paper's initialisation of a latent model (§4.1): the pre-trained cuboid weights, the surface weights
/// copied from their centre voxel layer ([`cog_gpu::features::surface::centre_slice_weights`]), and the
/// height biases `u_h` drawn uniformly from [0, 1] by a fixed generator (so that training is repeatable);
/// the first CCCP round's slices are imputed with it.
fn initial_surface_weights(model: &Model, layout: &FeatureLayout) -> anyhow::Result<Vec<f64>> {
    let slice = cog_gpu::features::surface::centre_slice_weights(layout, &model.weights)?;
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let indicator: Vec<f32> = (0..cog_gpu::features::surface::SLICES)
        .map(|_| {
            // xorshift64*: a fixed, documented sequence.
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    let w: Vec<f64> = model.weights.iter().chain(&slice).chain(&indicator).map(|&v| v as f64).collect();
    debug_assert_eq!(w.len(), layout.dim() + SURFACE_DIM);
    Ok(w)
}

/// Parses a comma-separated group list.
pub fn parse_groups(text: &str) -> anyhow::Result<Groups> {
    let mut groups = Groups::NONE;
    for name in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match name {
            "density" => groups.density = true,
            "normals" => groups.normals = true,
            "cog" => groups.cog = true,
            "view" => groups.view = true,
            "out-of-view" => groups.out_of_view = true,
            "geom" => (groups.density, groups.normals) = (true, true),
            other => {
                bail!("unknown feature group '{other}' (expected density, normals, cog, view, out-of-view or geom)")
            }
        }
    }
    if !(groups.density || groups.normals || groups.cog || groups.view) {
        bail!("--groups '{text}' switches every feature group off");
    }
    Ok(groups)
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let started = Instant::now();
    let (category, _) = normalise_name(&args.category);
    if !CATEGORIES.contains(&category.as_str()) {
        bail!("unknown category '{}'; the categories are: {}", args.category, CATEGORIES.join(", "));
    }
    let layout = FeatureLayout::new(args.grid, !args.no_expand, parse_groups(&args.groups)?)?;
    let pretrained =
        args.surfaces_from.as_deref().map(|path| pretrained_model(path, &category, &layout)).transpose()?;
    if pretrained.is_some() && args.features != PathArg::Fast {
        bail!("--surfaces-from needs the fast feature path (--features fast)");
    }
    if let Some(detect) = args.detect_support {
        let (trained, detected) = (Support::from(args.support), Support::from(detect));
        if trained.uses_surfaces() != detected.uses_surfaces() {
            bail!(
                "--detect-support {} with --support {}: a model searches surfaces in detection exactly when it \
                 trained on them",
                detected.name(),
                trained.name()
            );
        }
    }
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("models").join(format!("{category}.json")));
    let checkpoint = PathBuf::from(format!("{}.ckpt", out.display()));
    if args.resume && !checkpoint.is_file() {
        bail!("--resume: no checkpoint at {}", checkpoint.display());
    }
    super::options::writable_output_file(&out)?;

    let mut dataset = Dataset::open(&args.data)?;
    if let Some(split) = &args.split {
        dataset = dataset.with_split(split)?;
    }
    if dataset.is_empty() {
        bail!("no frame directories under {}", args.data.display());
    }
    let annotations = read_all_annotations(&dataset.frames)?;
    let truths: Vec<_> = annotations.iter().flat_map(|objects| instances_of(objects, &category)).collect();
    if truths.is_empty() {
        bail!("{} frames under {} hold no '{category}' to train on", dataset.len(), args.data.display());
    }
    let sizes = SizeQuantiles::from_cuboids(&truths)?;
    cog_gpu::model::check_sizes(&sizes)
        .map_err(|e| anyhow::anyhow!("the '{category}' boxes of {}: {e}", args.data.display()))?;
    let engine = match args.features {
        PathArg::Fast => FeatureEngine::Fast(FastOptions { subdivisions: args.subdivisions.max(1) }),
        PathArg::Exact => FeatureEngine::Exact,
    };
    let target = match args.target {
        TargetArg::BestWindow => PositiveTarget::BestWindow,
        TargetArg::Exact => PositiveTarget::Exact,
    };
    let settings = TrainingSettings {
        layout,
        sizes: sizes.sizes(),
        step: args.step,
        min_points: args.min_points,
        engine,
        target,
        yaw_anchor: args.yaw_anchor.into(),
        lattice: args.lattice.into(),
        support: args.support.into(),
        surfaces: pretrained.is_some(),
    };
    let negative_choice = match &args.hard_negatives {
        Some(dir) => {
            NegativeChoice::Hardest { best_scores: best_scores_by_frame(dir, &category)?, share: args.hard_share }
        }
        None => NegativeChoice::Spread,
    };
    let limits = ExampleLimits {
        positives: args.positives,
        negatives: args.negatives,
        negative_choice,
        others: args.other_instances.into(),
        support: args.support.into(),
        seen: args.skip_unseen.then_some(SeenRule { min_points: args.min_points, floor_slab: args.step }),
        min_in_view: args.skip_out_of_view,
        normals: args.normals,
    };
    log::info!(
        "{category}: {} instances in {} frames; preparing up to {} positive and {} negative examples",
        truths.len(),
        dataset.len(),
        args.positives,
        args.negatives
    );
    let collected = collect_examples(&dataset.frames, &category, limits)?;
    let supporters = collected.supporters;
    let mut examples = collected.examples;
    check_examples(&mut examples, &settings, args.candidates, args.cache_gib)?;
    let positives = examples.iter().filter(|e| e.truth.is_some()).count();
    log::info!(
        "{category}: {positives} positive and {} negative examples, prepared in {:.1} s",
        examples.len() - positives,
        started.elapsed().as_secs_f64()
    );
    let mut oracle = DetectorOracle::new(settings, examples)?;
    oracle.full_every = args.full_every;
    oracle.max_full_passes = args.max_full_passes.max(1);
    oracle.candidate_count = args.candidates.max(1);

    let ssvm = SsvmOptions {
        c: args.c,
        epsilon: args.epsilon,
        max_iterations: args.max_iterations,
        quiet: false,
        checkpoint: Some(checkpoint.clone()),
        prune_after: Some(args.prune_after),
        qp_tolerance: 1e-7,
    };
    // Convergence counts only when found by a full pass (see `DetectorOracle`'s candidate cache). The
    // latent path builds (and resumes) its solver per CCCP round itself.
    let (trained, latent) = match &pretrained {
        None => {
            let mut solver = if args.resume {
                log::info!("resuming from {}", checkpoint.display());
                CuttingPlane::resume(ssvm.clone(), &checkpoint)?
            } else {
                CuttingPlane::new(ssvm.clone())?
            };
            (train_detector(&oracle, &mut solver)?, None)
        }
        Some(model) => {
            let progress_path = PathBuf::from(format!("{}.cccp", out.display()));
            let progress = if args.resume {
                let text = std::fs::read_to_string(&progress_path)
                    .with_context(|| format!("--resume: reading the CCCP progress {}", progress_path.display()))?;
                let progress: LatentProgress = serde_json::from_str(&text)
                    .with_context(|| format!("{}: not a CCCP progress file", progress_path.display()))?;
                if progress.latents.len() != oracle.examples.len() {
                    bail!(
                        "{}: {} slices for {} examples: not this training's progress",
                        progress_path.display(),
                        progress.latents.len(),
                        oracle.examples.len()
                    );
                }
                log::info!("resuming CCCP at round {}", progress.next_round + 1);
                progress
            } else {
                let latents = match args.surface_init {
                    SurfaceInitArg::Upward => oracle.upward_slices(),
                    SurfaceInitArg::Centre => impute(&oracle, &initial_surface_weights(model, &layout)?)?,
                };
                LatentProgress { next_round: 0, latents, rounds: Vec::new(), oracle_state: Vec::new() }
            };
            let settings = LatentSettings {
                max_rounds: args.cccp_rounds.max(1),
                tolerance: 1e-3,
                full_passes_per_round: args.round_full_passes.max(1),
            };
            let save = |progress: &LatentProgress| -> cog_gpu::error::Result<()> {
                let text = serde_json::to_string(progress).map_err(|e| cog_gpu::error::Error::Input(e.to_string()))?;
                cog_gpu::error::write_replacing(&progress_path, text.as_bytes())
            };
            let latent = train_latent_detector(&mut oracle, &ssvm, progress, &settings, args.resume, save)?;
            (latent.last.clone(), Some(latent))
        }
    };
    let solution = trained.solution.clone();
    let seconds = started.elapsed().as_secs_f64();
    let status = match (solution.converged, trained.verified) {
        (true, true) => "converged (verified by a full pass)",
        (true, false) => "converged on the cached candidates (full-pass budget spent)",
        _ => "stopped at the iteration cap",
    };
    log::info!(
        "{category}: {status} after {} iterations and {} full passes, objective {:.4}, mean violation {:.3}, \
         largest example slack {:.3}, {} constraints, loss-augmented inference {:.0} hypotheses/s, {:.0} s",
        solution.iterations,
        trained.full_passes,
        solution.primal,
        solution.max_violation,
        trained.last_pass.max_example_slack,
        solution.num_constraints,
        trained.inference_hypotheses_per_second,
        seconds
    );
    let mut training = serde_json::json!({
        "data": args.data.display().to_string(),
        "split": args.split.as_ref().map(|s| s.display().to_string()),
        "frames": dataset.len(),
        "positives": positives,
        "negatives": oracle.examples.len() - positives,
        "hard_negatives": args.hard_negatives.as_ref().map(|d| d.display().to_string()),
        "hard_share": args.hard_negatives.as_ref().map(|_| args.hard_share),
        "training_step": args.step,
        "training_support": Support::from(args.support).name(),
        "other_instances": match args.other_instances { OthersArg::Removed => "removed", OthersArg::Ignored => "ignored" },
        "skip_unseen": args.skip_unseen,
        "formulation": "1-slack",
        "full_every": args.full_every,
        "full_passes": trained.full_passes,
        "max_full_passes": args.max_full_passes,
        "candidates": args.candidates,
        "c": args.c,
        "epsilon": args.epsilon,
        "iterations": solution.iterations,
        "converged": solution.converged,
        "verified_by_full_pass": trained.verified,
        "objective": solution.primal,
        "mean_violation": solution.max_violation,
        "largest_example_slack": trained.last_pass.max_example_slack,
        "inference_hypotheses_per_second": trained.inference_hypotheses_per_second,
        "constraints": solution.num_constraints,
        "seconds": seconds,
        "cog_gpu_version": env!("CARGO_PKG_VERSION"),
        "surfaces": latent.as_ref().map(|l| serde_json::json!({
            "pretrained": args.surfaces_from.as_ref().map(|p| p.display().to_string()),
            "init": match args.surface_init { SurfaceInitArg::Upward => "upward", SurfaceInitArg::Centre => "centre" },
            "cccp_converged": l.converged,
            "rounds": l.rounds.iter().map(|r| serde_json::json!({
                "ssvm_objective": r.ssvm_objective,
                "cached_latent_objective": r.objective,
                "changed": r.changed,
                "iterations": r.iterations,
                "converged": r.converged,
                "slices": r.histogram,
            })).collect::<Vec<_>>(),
        })),
    });
    // Apart from the literal above, which is at serde_json's macro recursion limit.
    training["skip_out_of_view"] = serde_json::json!(args.skip_out_of_view);
    // The rest of the options that shape the weights, so that a model says how to train it again.
    training["target"] = serde_json::json!(match args.target {
        TargetArg::BestWindow => "best-window",
        TargetArg::Exact => "exact",
    });
    training["prune_after"] = serde_json::json!(args.prune_after);
    training["max_iterations"] = serde_json::json!(args.max_iterations);
    let all_weights: Vec<f32> = solution.w.iter().map(|&v| v as f32).collect();
    let weights = all_weights[..layout.dim()].to_vec();
    let features = FeatureSettings {
        path: match args.features {
            PathArg::Fast => FeaturePath::Fast,
            PathArg::Exact => FeaturePath::Exact,
        },
        subdivisions: args.subdivisions.max(1),
        normals: args.normals,
    };
    let window = WindowSettings {
        step: args.detect_step,
        min_points: args.min_points,
        yaw_anchor: args.yaw_anchor.into(),
        support: args.detect_support.unwrap_or(args.support).into(),
        lattice: args.lattice.into(),
        supporters,
    };
    let mut model = Model::new(&category, layout, sizes, window, features, weights, training)?;
    if latent.is_some() {
        model = model.with_surface(surface_weights(&all_weights[layout.dim()..]))?;
    }
    model.write(&out)?;
    out!(
        "wrote {} ({category}: {positives} positives, {} iterations, {}, {:.0} s)",
        out.display(),
        solution.iterations,
        status,
        seconds
    );
    Ok(())
}
