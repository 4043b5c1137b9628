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
//!   placed; `detect --step 0.1` still gives it);
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
//!   find nothing, a full pass checks the whole window; at most `--max-full-passes` (2) full passes (the
//!   first, at w = 0, scores nothing and caches random hypotheses plus the boxes nearest the truth; the
//!   second mines the hard negatives of the trained w);
//! * the window's 16 yaws start at the frame's wall direction (`--yaw-anchor walls`; `camera` for the
//!   fixed `2πk/16`; see `cog_gpu::features::hypotheses`), written into the model so detection searches
//!   the same yaws;
//! * a checkpoint `<out>.ckpt` after every iteration; `--resume` continues from it (same data and options);
//! * at most `--max-iterations 300` cutting-plane iterations;
//! * constraints whose α stayed 0 for `--prune-after 10` solves leave the working set.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context};
use cog_gpu::category::{normalise_name, CATEGORIES};
use cog_gpu::features::fast::{FastOptions, DEFAULT_SUBDIVISIONS};
use cog_gpu::features::hypotheses::DEFAULT_MIN_POINTS;
use cog_gpu::features::{budget, FeatureLayout, Groups, SizeQuantiles, YawAnchor};
use cog_gpu::frame::Dataset;
use cog_gpu::learn::detector::{
    cached_rows_per_example, collect_examples, instances_of, read_all_annotations, train_detector, DetectorOracle,
    ExampleLimits, FeatureEngine, PositiveTarget, TrainingExample, TrainingSettings,
};
use cog_gpu::learn::{CuttingPlane, SsvmOptions};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};

use super::{options, GlobalOptions};

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
    #[arg(value_parser = options::step)]
    /// Centre step of the training sliding window (metres).
    #[arg(long, default_value_t = 0.2)]
    pub step: f32,
    #[arg(value_parser = options::step)]
    /// Centre step written into the model for detection (metres).
    #[arg(long, default_value_t = 0.2)]
    pub detect_step: f32,
    /// Skip hypotheses with fewer points inside.
    #[arg(long, default_value_t = DEFAULT_MIN_POINTS)]
    pub min_points: u32,
    /// Feature path: fast (shared-work approximation) or exact.
    #[arg(long, value_enum, default_value_t = PathArg::Fast)]
    pub features: PathArg,
    #[arg(value_parser = options::subdivisions)]
    /// Lattice cells per centre step of the fast path.
    #[arg(long, default_value_t = DEFAULT_SUBDIVISIONS)]
    pub subdivisions: u32,
    /// Feature groups (the paper's ablation): comma-separated of density, normals, cog, view.
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
    /// Drop constraints whose α stayed 0 for this many solves.
    #[arg(long, default_value_t = 10)]
    pub prune_after: u32,
    /// A positive's output: the window's hypothesis nearest the annotation (best-window), or the
    /// annotated cuboid itself (exact, the paper's choice).
    #[arg(long, value_enum, default_value_t = TargetArg::BestWindow)]
    pub target: TargetArg,
    /// Where the window's 16 yaws start: the frame's wall direction (walls) or the camera's heading
    /// (camera, `2πk/16`).
    #[arg(long, value_enum, default_value_t = AnchorArg::Walls)]
    pub yaw_anchor: AnchorArg,
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

/// `--target` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TargetArg {
    BestWindow,
    Exact,
}

/// `--features` values.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PathArg {
    Fast,
    Exact,
}

/// Drops positive examples without any point inside their box (nothing to learn from; counted in the log)
/// and checks, before any window is built, that every example's sliding window and the candidate cache
/// fit in memory (`cog_gpu::limits`), naming the example that does not.
fn check_examples(
    examples: &mut Vec<TrainingExample>,
    settings: &TrainingSettings,
    candidates: usize,
) -> anyhow::Result<()> {
    let before = examples.len();
    examples.retain(|ex| ex.truth.is_none_or(|truth| ex.pre.points.iter().any(|p| truth.contains(*p))));
    if examples.len() < before {
        log::warn!("{} positive examples have no point inside their box; not trained on", before - examples.len());
    }
    if !examples.iter().any(|ex| ex.truth.is_some()) {
        bail!("no positive example has points inside its box: nothing to train on");
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
    cog_gpu::limits::check_memory(
        "the candidate cache",
        vectors,
        settings.layout.dim() as f64 * 4.0,
        "lower --candidates, --positives or --negatives",
    )?;
    Ok(())
}

/// Parses a comma-separated group list.
pub fn parse_groups(text: &str) -> anyhow::Result<Groups> {
    let mut groups = Groups { density: false, normals: false, cog: false, view: false };
    for name in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match name {
            "density" => groups.density = true,
            "normals" => groups.normals = true,
            "cog" => groups.cog = true,
            "view" => groups.view = true,
            "geom" => (groups.density, groups.normals) = (true, true),
            other => bail!("unknown feature group '{other}' (expected density, normals, cog, view or geom)"),
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
    let layout = FeatureLayout::new([5, 5, 5], !args.no_expand, parse_groups(&args.groups)?)?;
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("models").join(format!("{category}.json")));
    let checkpoint = PathBuf::from(format!("{}.ckpt", out.display()));
    if args.resume && !checkpoint.is_file() {
        bail!("--resume: no checkpoint at {}", checkpoint.display());
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating the model directory {}", dir.display()))?;
    }

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
    };
    let limits = ExampleLimits { positives: args.positives, negatives: args.negatives };
    log::info!(
        "{category}: {} instances in {} frames; preparing up to {} positive and {} negative examples",
        truths.len(),
        dataset.len(),
        args.positives,
        args.negatives
    );
    let mut examples = collect_examples(&dataset.frames, &category, limits)?;
    check_examples(&mut examples, &settings, args.candidates)?;
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
    let mut solver = if args.resume {
        log::info!("resuming from {}", checkpoint.display());
        CuttingPlane::resume(ssvm, &checkpoint)?
    } else {
        CuttingPlane::new(ssvm)?
    };
    // Convergence counts only when found by a full pass (see `DetectorOracle`'s candidate cache).
    let trained = train_detector(&oracle, &mut solver)?;
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
    let training = serde_json::json!({
        "data": args.data.display().to_string(),
        "split": args.split.as_ref().map(|s| s.display().to_string()),
        "frames": dataset.len(),
        "positives": positives,
        "negatives": oracle.examples.len() - positives,
        "training_step": args.step,
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
    });
    let weights: Vec<f32> = solution.w.iter().map(|&v| v as f32).collect();
    let features = FeatureSettings {
        path: match args.features {
            PathArg::Fast => FeaturePath::Fast,
            PathArg::Exact => FeaturePath::Exact,
        },
        subdivisions: args.subdivisions.max(1),
    };
    let window =
        WindowSettings { step: args.detect_step, min_points: args.min_points, yaw_anchor: args.yaw_anchor.into() };
    let model = Model::new(&category, layout, sizes, window, features, weights, training)?;
    model.write(&out)?;
    println!(
        "wrote {} ({category}: {positives} positives, {} iterations, {}, {:.0} s)",
        out.display(),
        solution.iterations,
        status,
        seconds
    );
    Ok(())
}
