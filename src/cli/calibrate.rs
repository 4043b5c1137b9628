//! `cog-gpu calibrate --data DIR --detections DIR [--models assets/models] [--out DIR] [--iou 0.25]
//! [--categories a,b,...]`: fits each model's score calibration ([`cog_gpu::calibration`]) on held-out
//! frames and writes it into the model files.
//!
//! The detections are those of `cog-gpu detect --min-score -3` (or lower) on the held-out frames, with
//! the same models: the fit needs the low-scoring false positives too. Files whose detections already
//! carry a `raw_score` (calibrated models) are fitted on the raw score. Frames used here must not be
//! training or test frames. Choices: `--out` defaults to the models directory itself (the models are
//! rewritten in place, through a temporary file); a category with no true or no false positive among
//! the detections is an error naming it, since no calibration can be fitted, and then no model is
//! written (a models directory is never left half calibrated).
//!
//! `cog-gpu calibrate --cascade CASCADE.json --data DIR --detections DIR [--models assets/models] [--out
//! FILE]`: fits the calibration of the context cascade's stages instead ([`Cascade::recalibrated`]), on
//! held-out frames' **first-stage** detections (`detect --no-cascade --min-score -3` with the models the
//! cascade was trained with); `--out` is then the cascade file to write (default: the cascade itself).
//! The stages' weights stay, so every category's AP stays; only the probabilities change.
//!
//! `cog-gpu calibrate --cascade CASCADE.json --exclusion --data DIR --detections DIR [--out FILE | --check]`:
//! fits the cascade's cross-category exclusion ([`cog_gpu::exclusion`]) on the same kind of held-out
//! first-stage detections: the grid's mean APs (over --categories; default every category with ground
//! truth), the chosen parameters' per-category APs, and the cascade written with them.
//!
//! `cog-gpu calibrate --cascade CASCADE.json --final --data DIR --detections DIR [--out FILE | --check]`:
//! fits the cascade's final calibration ([`cog_gpu::calibration::final_calibration`]: one map of every
//! category's score after the stages and the exclusion) on the same kind of held-out
//! first-stage detections, over --categories (default every category with ground truth); reports the log
//! loss, the expected true positives and the scores' reliability bins ([`cog_gpu::diagnose::reliability`])
//! on these frames without a map, with the file's own map (when it has one) and with the fitted one;
//! writes the cascade with it.
//! Refitting the stages' calibrations or the exclusion drops a cascade's final calibration (it was fitted
//! on their scores), and says so.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use cog_gpu::calibration::final_calibration::{fit_final_calibration, FinalCalibration, ScoreSummary};
use cog_gpu::calibration::{fit_logistic, label_detections, Calibration};
use cog_gpu::cascade::{Cascade, HeldOutFrame};
use cog_gpu::category::{category_index, normalise_name, CATEGORIES};
use cog_gpu::eval::Detection;
use cog_gpu::exclusion::{fit_exclusion, ExclusionTrial, IOU_GRID, WEIGHT_GRID};
use cog_gpu::frame::{read_annotations, unique_frame_names, Dataset, Object};
use cog_gpu::model::read_models_dir;

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub held_out: HeldOutArgs,
    /// Where to write the calibrated models (a directory); default: over the models themselves. With
    /// --cascade, the calibrated cascade file; default: over the cascade itself.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Calibrate this context cascade's stages instead of the models: --detections are then first-stage
    /// detections (`detect --no-cascade`) by the models the cascade was trained with (--models).
    #[arg(long)]
    pub cascade: Option<PathBuf>,
    /// With --cascade: only report how the cascade's calibrations hold on the held-out frames (expected
    /// against found true positives, log loss as stored and refitted); write nothing.
    #[arg(long, requires = "cascade", conflicts_with = "out")]
    pub check: bool,
    /// With --cascade: fit the cascade's cross-category exclusion (its IoU and weight, on a grid, by the
    /// mean AP of --categories) instead of the stages' calibrations, and write the cascade with it (with
    /// --check: only report).
    #[arg(long, requires = "cascade")]
    pub exclusion: bool,
    /// With --cascade: fit the cascade's final calibration (one map of every category's score after the
    /// stages and the exclusion, beta calibration logit p' = a·ln p − b·ln(1 − p) + c, increasing: no AP
    /// changes) instead of the stages' calibrations, and write the cascade with it (with --check: only
    /// report).
    #[arg(long, requires = "cascade", conflicts_with = "exclusion")]
    pub r#final: bool,
}

/// What `calibrate` and `cascade` learn from: held-out frames, their detections by a models directory's
/// models, the IoU of a true positive and the categories.
#[derive(clap::Args)]
pub struct HeldOutArgs {
    /// Held-out frames (ground truth in annotation3Dfinal/index.json).
    #[arg(long)]
    pub data: PathBuf,
    /// Detections of those frames: one `<frame name>.json` per frame, from `cog-gpu detect --min-score -3`
    /// with the models of --models (`--no-cascade` for `cascade`).
    #[arg(long)]
    pub detections: PathBuf,
    /// The models (`<category>.json`) that made the detections.
    #[arg(long, default_value = super::detect::SHIPPED_MODELS)]
    pub models: PathBuf,
    /// 3D IoU that makes a detection a true positive.
    #[arg(long, default_value_t = 0.25, value_parser = super::options::iou)]
    pub iou: f32,
    /// Only these categories (comma-separated); default: every model in --models (with --cascade and
    /// --exclusion or --final: every category with ground truth).
    #[arg(long, value_delimiter = ',')]
    pub categories: Vec<String>,
}

impl HeldOutArgs {
    /// The categories of --categories, normalised (empty: all); a name that is not one of the 19 is an
    /// error that names it (for every command that takes these arguments).
    pub fn categories(&self) -> anyhow::Result<Vec<String>> {
        let categories: Vec<String> =
            super::options::names("--categories", &self.categories)?.iter().map(|c| normalise_name(c).0).collect();
        if let Some(unknown) = categories.iter().find(|c| category_index(c).is_none()) {
            bail!("--categories: '{unknown}' is not one of cog-gpu's 19 categories ({})", CATEGORIES.join(", "));
        }
        Ok(categories)
    }

    /// The models of --models (only --categories when given).
    pub fn models(&self) -> anyhow::Result<Vec<cog_gpu::model::Model>> {
        let categories = self.categories()?;
        Ok(read_models_dir(&self.models, (!categories.is_empty()).then_some(categories.as_slice()))?)
    }
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    if let Some(cascade) = &args.cascade {
        if args.exclusion {
            return fit_cascade_exclusion(&args.held_out, cascade, args.out.as_deref(), args.check);
        }
        if args.r#final {
            return fit_cascade_final_calibration(&args.held_out, cascade, args.out.as_deref(), args.check);
        }
        return calibrate_cascade(&args.held_out, cascade, args.out.as_deref(), args.check);
    }
    let held_out = &args.held_out;
    let mut models = held_out.models()?;
    let LabelledDetections { frames, truth, detections, .. } =
        read_labelled_detections(&held_out.data, &held_out.detections)?;
    let out_dir = args.out.clone().unwrap_or_else(|| held_out.models.clone());
    // Fit every model first, and check that every model file can be written: a category that cannot be
    // fitted, or a file that cannot be written (a directory in its place, no permission), stops the run
    // before any file is written, so a models directory is never left half calibrated.
    let mut failures = Vec::new();
    for model in &mut models {
        let samples = label_detections(&detections, &truth, &model.category, held_out.iou);
        match fit_logistic(&samples) {
            Ok((a, b)) => {
                model.calibration = Some(Calibration {
                    a,
                    b,
                    detections: samples.len(),
                    true_positives: samples.iter().filter(|s| s.1).count(),
                    iou: held_out.iou,
                    data: held_out.data.display().to_string(),
                    frames,
                })
            }
            Err(err) => failures.push(format!("{}: {err}", model.category)),
        }
    }
    if !failures.is_empty() {
        bail!(
            "cannot calibrate on the detections in {} (nothing written; add held-out frames that hold these \
             categories):\n  {}",
            held_out.detections.display(),
            failures.join("\n  ")
        );
    }
    let paths: Vec<PathBuf> = models.iter().map(|m| out_dir.join(format!("{}.json", m.category))).collect();
    for path in &paths {
        super::options::writable_output_file(path).context("nothing written")?;
    }
    out!("{:<12} {:>10} {:>6} {:>9} {:>9} {:>8} {:>8}", "category", "detections", "TP", "a", "b", "p(0)", "p(1)");
    for model in &models {
        let Some(calibration) = &model.calibration else { continue };
        out!(
            "{:<12} {:>10} {:>6} {:>9.4} {:>9.4} {:>8.4} {:>8.4}",
            model.category,
            calibration.detections,
            calibration.true_positives,
            calibration.a,
            calibration.b,
            calibration.probability(0.0),
            calibration.probability(1.0)
        );
        if let Some(shortage) = calibration.shortage() {
            log::warn!("{}: calibration {shortage}", model.category);
        }
    }
    for (model, path) in models.iter().zip(&paths) {
        model.write(path)?;
    }
    out!("wrote {} calibrated model(s) to {}", models.len(), out_dir.display());
    Ok(())
}

/// `calibrate --cascade`: the cascade's stages calibrated on the held-out frames, a report per stage, the
/// file written (only when every stage could be fitted, and not with `check`).
fn calibrate_cascade(held_out: &HeldOutArgs, path: &Path, out: Option<&Path>, check: bool) -> anyhow::Result<()> {
    let (cascade, categories, LabelledDetections { frames, truth, detections, rooms, .. }) =
        cascade_and_held_out(held_out, path)?;
    let held_out_frames: Vec<HeldOutFrame> = (0..frames)
        .map(|f| HeldOutFrame { detections: &detections[f], room: rooms[f].as_ref(), truth: &truth[f] })
        .collect();
    let (calibrated, report) = cascade
        .recalibrated(&held_out_frames, &categories, held_out.iou, &held_out.data.display().to_string())
        .with_context(|| format!("calibrating {} on {}", path.display(), held_out.detections.display()))?;
    out!(
        "{:<12} {:>10} {:>6} {:>11} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9}",
        "category",
        "detections",
        "TP",
        "expected TP",
        "a before",
        "b before",
        "a",
        "b",
        "loss befor",
        "loss"
    );
    for r in &report {
        out!(
            "{:<12} {:>10} {:>6} {:>11.1} {:>9.4} {:>9.4} {:>9.4} {:>9.4} {:>10.4} {:>9.4}",
            r.category,
            r.after.detections,
            r.after.true_positives,
            r.expected_true_positives_before,
            r.before.a,
            r.before.b,
            r.after.a,
            r.after.b,
            r.log_loss_before,
            r.log_loss_after
        );
        if let Some(shortage) = r.after.shortage() {
            log::warn!("{}: cascade stage calibration {shortage}", r.category);
        }
    }
    if check {
        let found: usize = report.iter().map(|r| r.after.true_positives).sum();
        let expected: f64 = report.iter().map(|r| r.expected_true_positives_before).sum();
        out!("all stages: {found} true positives found, {expected:.1} expected by the stored calibrations; nothing written");
        return Ok(());
    }
    let out = out.unwrap_or(path);
    calibrated.write(out)?;
    out!(
        "wrote the cascade with {} stage calibration(s) fitted on {} frames to {}",
        report.len(),
        frames,
        out.display()
    );
    say_final_calibration_dropped(&cascade)?;
    Ok(())
}

/// What both `calibrate --cascade` modes read: the cascade at `path` (checked against every model of
/// `--models`, not only `--categories`': each stage reads every context category's probabilities), the
/// `--categories`, and the held-out frames with their labels and detections.
fn cascade_and_held_out(
    held_out: &HeldOutArgs,
    path: &Path,
) -> anyhow::Result<(Cascade, Vec<String>, LabelledDetections)> {
    let categories = held_out.categories()?;
    let cascade = Cascade::read(path)?;
    cascade.check_models(&read_models_dir(&held_out.models, None)?)?;
    let labelled = read_labelled_detections(&held_out.data, &held_out.detections)?;
    Ok((cascade, categories, labelled))
}

/// `calibrate --cascade --exclusion`: the cascade's cross-category exclusion fitted on the held-out frames
/// ([`fit_exclusion`]), the grid's mean APs and the chosen parameters' per-category APs reported, the file
/// written with it (not with `check`; without a gain, the cascade is written without an exclusion).
fn fit_cascade_exclusion(held_out: &HeldOutArgs, path: &Path, out: Option<&Path>, check: bool) -> anyhow::Result<()> {
    let (cascade, categories, LabelledDetections { frames, truth, mut detections, rooms, .. }) =
        cascade_and_held_out(held_out, path)?;
    for (f, frame) in detections.iter_mut().enumerate() {
        cascade.rescore_stages(frame, rooms[f].as_ref()).with_context(|| {
            format!("rescoring the detections of frame {} of {}", f + 1, held_out.detections.display())
        })?;
    }
    let fit = fit_exclusion(&detections, &truth, &categories, held_out.iou);
    if fit.without().mean_ap.is_none() {
        bail!(
            "{}: no ground-truth box of {} in these frames, so no AP to fit the exclusion by (nothing written)",
            held_out.data.display(),
            if categories.is_empty() { "any category".to_string() } else { categories.join(", ") }
        );
    }
    let map = |t: &ExclusionTrial| t.mean_ap.map_or("-".to_string(), |m| format!("{:.2}", 100.0 * m));
    out!(
        "mean AP ({} categories, {frames} frames, IoU {}) by exclusion weight (rows) and IoU (columns); without: {}",
        fit.categories.len(),
        held_out.iou,
        map(fit.without())
    );
    out_part!("{:>7}", "weight");
    for iou in IOU_GRID {
        out_part!(" {iou:>7}");
    }
    out!();
    for &weight in &WEIGHT_GRID[1..] {
        out_part!("{weight:>7}");
        for t in fit.trials.iter().filter(|t| t.exclusion.weight == weight) {
            out_part!(" {:>7}", map(t));
        }
        out!();
    }
    let best = fit.best();
    let ap = |a: Option<f32>| a.map_or("-".to_string(), |a| format!("{:.1}", 100.0 * a));
    out!("{:<12} {:>8} {:>8}", "category", "without", "with");
    for (n, category) in fit.categories.iter().enumerate() {
        out!("{category:<12} {:>8} {:>8}", ap(fit.without().aps[n]), ap(best.aps[n]));
    }
    match fit.chosen {
        Some(e) => {
            out!("chosen: IoU {}, weight {} (mean AP {} → {})", e.iou, e.weight, map(fit.without()), map(best))
        }
        None => out!("chosen: no exclusion (no weight above 0 raises the mean AP)"),
    }
    if check {
        out!("nothing written");
        return Ok(());
    }
    let out = out.unwrap_or(path);
    Cascade { exclusion: fit.chosen, final_calibration: None, ..cascade.clone() }.write(out)?;
    out!(
        "wrote the cascade with {} to {}",
        fit.chosen.map_or("no exclusion".into(), |e| format!("exclusion IoU {}, weight {}", e.iou, e.weight)),
        out.display()
    );
    say_final_calibration_dropped(&cascade)?;
    Ok(())
}

/// After refitting what a final calibration was fitted on: says that the written cascade has none.
fn say_final_calibration_dropped(cascade: &Cascade) -> anyhow::Result<()> {
    if cascade.final_calibration.is_some() {
        out!(
            "the cascade's final calibration was fitted on the scores before this fit and is not kept: fit it \
             again (calibrate --cascade --final)"
        );
    }
    Ok(())
}

/// `calibrate --cascade --final`: the cascade's final calibration fitted on the held-out frames
/// ([`fit_final_calibration`]; their first-stage detections rescored by the stages and the exclusion, any
/// stored final calibration left out), reported with the scores' log loss, expected true positives and
/// reliability without a map, with the file's own map (when it has one) and with the fitted one, and the
/// file written with it (not with `check`).
fn fit_cascade_final_calibration(
    held_out: &HeldOutArgs,
    path: &Path,
    out: Option<&Path>,
    check: bool,
) -> anyhow::Result<()> {
    let (cascade, categories, LabelledDetections { frames, truth, mut detections, rooms, .. }) =
        cascade_and_held_out(held_out, path)?;
    for (f, frame) in detections.iter_mut().enumerate() {
        cascade.rescore_before_final_calibration(frame, rooms[f].as_ref()).with_context(|| {
            format!("rescoring the detections of frame {} of {}", f + 1, held_out.detections.display())
        })?;
    }
    let data = held_out.data.display().to_string();
    let stored = cascade.final_calibration.as_ref();
    let fit = fit_final_calibration(&detections, &truth, &categories, held_out.iou, &data, stored)
        .with_context(|| format!("fitting the final calibration on {}", held_out.detections.display()))?;
    let c = &fit.calibration;
    out!(
        "final calibration logit p' = a·ln p − b·ln(1 − p) + c: a = {:.4}, b = {:.4}, c = {:.4} ({} categories, \
         {frames} frames, {} detections, {} true positives at IoU {})",
        c.a,
        c.b,
        c.c,
        fit.categories.len(),
        c.detections,
        c.true_positives,
        held_out.iou
    );
    let summary = |name: &str, s: &ScoreSummary| -> anyhow::Result<()> {
        out!("{name:<34} mean log loss {:.5}, expected true positives {:.1}", s.log_loss, s.expected_true_positives);
        Ok(())
    };
    summary("before (no map):", &fit.before)?;
    if let (Some(map), Some(s)) = (stored, &fit.stored) {
        summary(&format!("the file's map (a = {:.4}, b = {:.4}, c = {:.4}):", map.a, map.b, map.c), s)?;
    }
    summary("after (the fitted map):", &fit.after)?;
    let mapped_by = |map: &FinalCalibration| {
        let mut mapped = detections.clone();
        for frame in &mut mapped {
            map.apply(frame);
        }
        mapped
    };
    let print_bins = |name: &str, scored: &[Vec<Detection>]| -> anyhow::Result<()> {
        let reliability = cog_gpu::diagnose::reliability(&truth, scored, &fit.categories, held_out.iou);
        out!("{name}, on these frames:");
        super::eval::print_reliability(&reliability)
    };
    print_bins("before (no map)", &detections)?;
    if let Some(map) = stored {
        print_bins("with the file's map", &mapped_by(map))?;
    }
    print_bins("after (the fitted map)", &mapped_by(c))?;
    if check {
        out!("nothing written");
        return Ok(());
    }
    let out = out.unwrap_or(path);
    let replaced = if stored.is_some() { " (the map it had replaced)" } else { "" };
    Cascade { final_calibration: Some(fit.calibration), ..cascade.clone() }.write(out)?;
    out!("wrote the cascade with its final calibration to {}{replaced}", out.display());
    Ok(())
}

/// The held-out frames of `data` with their annotations and their detections from `detections`
/// (`<frame name>.json` each; a frame without a file counts as one without detections, with a warning;
/// no file at all is an error).
pub fn read_labelled_detections(
    data: &std::path::Path,
    detections_dir: &std::path::Path,
) -> anyhow::Result<LabelledDetections> {
    let dataset = Dataset::open(data)?;
    if dataset.is_empty() {
        bail!("{}: no frame directories", data.display());
    }
    if !detections_dir.is_dir() {
        bail!("{}: detections directory not found", detections_dir.display());
    }
    let names = unique_frame_names(&dataset.frames)?;
    let mut truth = Vec::new();
    let mut detections: Vec<Vec<Detection>> = Vec::new();
    let mut rooms = Vec::new();
    let mut missing = 0;
    for (dir, name) in dataset.frames.iter().zip(&names) {
        truth.push(read_annotations(dir)?.0);
        let path = detections_dir.join(format!("{name}.json"));
        if path.is_file() {
            let (file, room) = cog_gpu::cascade::read_detections_and_room(&path)?;
            detections.push(file.detections);
            rooms.push(room);
        } else {
            missing += 1;
            detections.push(Vec::new());
            rooms.push(None);
        }
    }
    if missing == dataset.len() {
        bail!(
            "{}: no detections file for any of the {} frames of {} (run cog-gpu detect on them first)",
            detections_dir.display(),
            dataset.len(),
            data.display()
        );
    }
    if missing > 0 {
        log::warn!(
            "{missing} of {} frames have no detections file; counted as frames without detections",
            dataset.len()
        );
    }
    Ok(LabelledDetections { frames: dataset.len(), names, truth, detections, rooms })
}

/// Held-out frames' annotations and detections, frame by frame.
pub struct LabelledDetections {
    pub frames: usize,
    /// Each frame's name (its detections file is `<name>.json`).
    pub names: Vec<String>,
    pub truth: Vec<Vec<Object>>,
    /// The predicted room of each frame's detections file (`"layout"`), when it has one.
    pub rooms: Vec<Option<cog_gpu::cascade::Room>>,
    pub detections: Vec<Vec<Detection>>,
}
